"""The windowed shell in a real X window (Xvfb, moderngl-window's pyglet backend): F12 writes
the frame on screen to a PNG and the frames after it run with no GL error.

The test starts its own Xvfb and runs the window in a subprocess (pyglet and a GLX context
stay out of the test process).  It is skipped, saying why, only when Xvfb or pyglet is
missing (``apt-get install xvfb``; pyglet comes with moderngl-window's extras)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
SIZE = (160, 90)
FRAMES_BEFORE = 3

WINDOW_SCRIPT = r'''
import json, sys
from pathlib import Path

import moderngl_window as mglw
import pyglet

from shell.window import make_window_config
from games.hall_of_mirrors import HallOfMirrors

shots, before, after, size = Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
config = mglw.create_window_config_instance(make_window_config(HallOfMirrors()),
                                            args=["--window", "pyglet", "--size", size])
errors = []

def frame():
    config.on_render(0.0, 1 / 60)  # the engine's debug mode raises on any GL error here
    config.wnd.swap_buffers()
    errors.append(config.ctx.error)

config.screenshots = shots
for _ in range(before):
    frame()
# Press F12 as the X server would deliver it: through pyglet's event queue and
# moderngl-window's key handler to the shell's on_key_event.
config.wnd._window.dispatch_event("on_key_press", pyglet.window.key.F12, 0)
config.wnd._window.dispatch_events()
written = sorted(str(p) for p in shots.glob("*.png"))
for _ in range(after):
    frame()
print(json.dumps({"errors": errors, "screenshots": written, "buffer_size": list(config.wnd.buffer_size),
                  "renderer": config.ctx.info["GL_RENDERER"]}))
config.on_close()
config.wnd.destroy()
'''


def test_f12_in_a_real_window_writes_the_frame_and_later_frames_have_no_gl_error(x_display, tmp_path):
    shots, reference = tmp_path / "shots", tmp_path / "headless"
    size = f"{SIZE[0]}x{SIZE[1]}"
    env = {**os.environ, "DISPLAY": x_display, "PYTHONPATH": str(ROOT), "SPECULUM_DEBUG": "1"}
    result = subprocess.run([sys.executable, "-c", WINDOW_SCRIPT, str(shots), str(FRAMES_BEFORE), "10", size],
                            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads(result.stdout.strip().splitlines()[-1])
    assert report["buffer_size"] == list(SIZE)
    assert report["errors"] == ["GL_NO_ERROR"] * (FRAMES_BEFORE + 10), report["errors"]
    assert len(report["screenshots"]) == 1, report
    shot = np.asarray(Image.open(report["screenshots"][0]))
    assert shot.shape == (SIZE[1], SIZE[0], 3)
    assert shot.mean() > 20 and shot.std() > 20  # a picture, not a black or flat frame

    # The same frame rendered headless (same size, same number of 1/60 s steps, the camera
    # held at the level's start pose instead of touring) is the picture the window showed
    # when F12 was pressed.
    headless = subprocess.run([sys.executable, "-m", "games.hall_of_mirrors", "--headless", "--frames",
                               str(FRAMES_BEFORE), "--size", size, "--out", str(reference),
                               "--camera", "0,1.7,6.5,0,-8"],
                              cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert headless.returncode == 0, headless.stderr
    expected = np.asarray(Image.open(reference / f"frame_{FRAMES_BEFORE - 1:04d}.png"))
    difference = np.abs(shot.astype(int) - expected.astype(int))
    assert difference.max() <= 2 and (difference > 0).mean() < 0.001, (difference.max(), (difference > 0).mean())


# Runs ``python -m <game> ARGS`` as a player would, and presses Esc as the X server delivers
# it: a KeyPress event sent to the game's window (XSendEvent) after a few frames, read back
# by pyglet's event loop and handed to the shell's key handler.
ESC_SCRIPT = r'''
import runpy, sys
from ctypes import byref

from pyglet.libs.x11 import xlib

import shell.window as shell

module, after = sys.argv[1], int(sys.argv[2])
make_window_config = shell.make_window_config


def pressing_esc(game, args=None):
    base = make_window_config(game, args)

    class PressingEsc(base):
        frames = 0

        def on_render(self, time_s, frametime):
            super().on_render(time_s, frametime)
            PressingEsc.frames += 1
            if PressingEsc.frames == after:
                window = self.wnd._window
                event = xlib.XEvent()
                event.xkey.type = xlib.KeyPress
                event.xkey.display = window._x_display
                event.xkey.window = window._window
                event.xkey.root = xlib.XDefaultRootWindow(window._x_display)
                event.xkey.keycode = xlib.XKeysymToKeycode(window._x_display, 0xFF1B)  # XK_Escape
                event.xkey.same_screen = 1
                xlib.XSendEvent(window._x_display, window._window, 1, xlib.KeyPressMask, byref(event))
                xlib.XFlush(window._x_display)

    return PressingEsc


shell.make_window_config = pressing_esc
sys.argv = [module] + sys.argv[3:]
runpy.run_module(module, run_name="__main__")
'''
GAMES = ("games.hall_of_mirrors", "games.mirror_beam", "games.portal_run")


def _windowed(x_display, cwd, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "DISPLAY": x_display, "PYTHONPATH": str(ROOT), "SPECULUM_DEBUG": "1"}
    return subprocess.run([sys.executable, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("module", GAMES)
def test_esc_in_every_game_closes_its_window_with_exit_status_0(x_display, tmp_path, module):
    """Esc released the debug overlay twice (moderngl-window's exit key closed the window and
    called on_close, then the shell's own Esc handler closed it again): "double free or
    corruption (!prev)", exit status 134.  Now the shell releases once, with the window's GL
    context current, and the process ends with 0.  moderngl-window's INFO lines are off."""
    result = _windowed(x_display, tmp_path, "-c", ESC_SCRIPT, module, "3", "--size", "160x90")
    assert result.returncode == 0, (result.returncode, result.stderr[-3000:])
    assert "double free" not in result.stderr and "Traceback" not in result.stderr, result.stderr[-3000:]
    assert " - INFO - " not in result.stderr, result.stderr[-3000:]


def test_windowed_frames_closes_the_window_and_export_scene_is_written_as_it_closes(x_display, tmp_path):
    scene = tmp_path / "scene" / "hall.glb"
    result = _windowed(x_display, ROOT, "-m", "games.hall_of_mirrors", "--frames", "3", "--size", "160x90",
                       "--export-scene", str(scene))
    assert result.returncode == 0, result.stderr[-3000:]
    assert scene.is_file() and scene.with_suffix(".json").is_file()
    assert f"speculum: wrote {scene}, {scene.with_suffix('.json')}" in result.stdout


@pytest.mark.parametrize("flags", [["--gif", "x.gif"], ["--ids"], ["--ids", "--gif", "x.gif"]])
def test_a_window_refuses_the_headless_outputs_with_one_line(x_display, tmp_path, flags):
    result = _windowed(x_display, tmp_path, "-m", "games.hall_of_mirrors", "--frames", "1", "--size", "160x90",
                       *flags)
    assert result.returncode == 2, result.stderr[-3000:]
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("speculum: error:"), result.stderr
    assert all(flag in lines[0] for flag in flags if flag.startswith("--")) and "--headless" in lines[0]
    assert not (tmp_path / "x.gif").exists()
