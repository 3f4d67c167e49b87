"""The debug overlay: drawn over the finished frame (its region changes, nothing else), its
numbers are the frame's own, its toggles write the engine's settings, and the next frame
is drawn as if it had never been there.  Headless, through the runner's ``--overlay`` and
through the window shell under moderngl-window's headless window."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from components import Material, MeshRef, ReflectionProbe, Transform
from engine.assets.mesh import sphere
from engine.render.resample import RENDER_SCALE_RANGE, render_size

pytest.importorskip("imgui_bundle", reason="the debug overlay needs imgui-bundle (not installed here)")
from shell.overlay import POSITION, DebugOverlay  # noqa: E402
from shell.overlay_text import overlay_lines  # noqa: E402
from tests import test_hot_reload
from tests.support import FunctionGame
from tests.test_hot_reload import room

ROOT = Path(__file__).resolve().parents[1]
SIZE = (400, 300)
shader_copy = test_hot_reload.shader_copy  # the fixture: a copy of shaders/ the engine reads


def room_with_probe(world) -> None:
    """One mirror facing the camera (so views per level are 1 / 1) and one chrome sphere whose
    probe captures every frame (so a frame has 1 probe capture of 6 faces)."""
    room(world)
    world.spawn(Transform(position=(-0.9, 0.5, 0.6)), MeshRef(sphere(0.4)), Material(metallic=1.0, roughness=0.05),
                ReflectionProbe(resolution=16, refresh="every_frame"))


def test_the_overlay_shows_the_frames_numbers_over_its_own_region_only(scene, ctx):
    runner = scene(room_with_probe, SIZE)
    runner.engine.stages["probes"].path = "six_pass"
    runner.frame()
    plain = runner.frame()
    overlay = DebugOverlay(ctx)
    try:
        overlay.record(0.02)
        overlay.draw(runner.engine, runner.capture.framebuffer, SIZE)
        shown = runner.capture.read_rgb()
        stats = runner.stats
        lines = overlay.lines
        assert lines == overlay_lines(runner.engine, [0.02])
        # The numbers, from the scene (one mirror in view, one probe capturing every frame)...
        assert "50.0 fps, 20.00 ms a frame" in lines
        assert "views per level 1 / 1" in lines
        # Six faces due; a face showing the sky alone, as at its last drawing, is kept, not drawn.
        kept = runner.engine.renderer.probes.faces_kept
        assert 1 <= stats.probe_faces <= 6 and stats.probe_faces + kept == 6  # the first frame drew all six
        assert any(line.startswith(f"probe captures 1 ({stats.probe_faces} faces); shadow maps") for line in lines)
        assert "reflection views 1, dropped 0, capped 0, faded 0, fallbacks 0" in lines
        # ...and as RenderStats counted them in this frame.
        assert f"passes {stats.passes}, draw calls {stats.draw_calls}" in lines and stats.draw_calls > 0
        assert f"reflection path {stats.reflection_path} (set: auto, budget none)" in lines
        assert stats.reflection_path in ("per_mirror", "batched")
        assert "probe path six_pass (set: six_pass)" in lines
        checks = runner.engine.renderer.path_checks
        verified, refused = ", ".join(checks.verified()), ", ".join(checks.refused()) or "-"  # a GPU may refuse some
        assert stats.paths_verified and f"GL paths verified: {verified}; refused: {refused}" in lines

        x, y, w, h = overlay.region
        assert (x, y) == POSITION and 100 < w < SIZE[0] and 100 < h < SIZE[1]
        changed = np.any(shown != plain, axis=2)
        inside = np.zeros_like(changed)
        inside[y:y + h, x:x + w] = True
        assert not changed[~inside].any(), "the overlay drew outside its window"
        assert changed[inside].mean() > 0.5, changed[inside].mean()

        assert np.array_equal(runner.frame(), plain), "a frame after the overlay must not see it"
        overlay.visible = False
        overlay.draw(runner.engine, runner.capture.framebuffer, SIZE)
        assert np.array_equal(runner.capture.read_rgb(), plain)
    finally:
        overlay.release()


def test_the_overlay_shows_a_shader_error_from_hot_reload(scene, ctx, shader_copy):
    size = (480, 620)  # (room below the window for the error's lines)
    runner = scene(room, size)
    runner.frame()
    overlay = DebugOverlay(ctx)
    try:
        overlay.draw(runner.engine, runner.capture.framebuffer, size)
        before = overlay.region[3]
        path = shader_copy / "scene.frag"
        path.write_text(path.read_text().replace("void main() {", "void main() {\n    broken_for_the_overlay;", 1))
        assert runner.engine.renderer.shaders.poll(now=1e6)
        for _ in range(2):  # an auto-sized window takes its new size in the frame after
            runner.frame()
            overlay.draw(runner.engine, runner.capture.framebuffer, size)
        errors = list(runner.engine.renderer.shaders.errors.values())
        assert errors and overlay.shown_errors == errors and "broken_for_the_overlay" in errors[0]
        assert overlay.region[3] > before + 3 * 13  # the error's lines of text (13-pixel font)
        # First, at the top (issue 41 item 6): the error's red text starts in the window's
        # first line, above the stats (white text) below it.
        shown = runner.capture.read_rgb().astype(int)
        x, y, w, h = overlay.region
        window = shown[y:y + h, x:x + w]
        red = (window[..., 0] > 180) & (window[..., 1] < 140) & (window[..., 2] < 140)
        white = (window > 200).all(axis=2)
        rows_red, rows_white = np.flatnonzero(red.any(axis=1)), np.flatnonzero(white.any(axis=1))
        body = rows_white[rows_white > 20]  # below the title bar's white "Speculum (F1)"
        assert len(rows_red) and len(body)
        assert rows_red[0] < 40 and rows_red[0] < body[0], (rows_red[:3], body[:3])
    finally:
        overlay.release()


def test_window_f1_shows_the_overlay_and_its_toggles_change_the_paths(tmp_path):
    import moderngl_window as mglw

    from engine import spawn_camera
    from shell.window import make_window_config

    def build(world):
        room(world)
        spawn_camera(world, position=(0.0, 1.4, 4.0))  # a FlyController: a click in the world captures

    config = mglw.create_window_config_instance(
        make_window_config(FunctionGame(build)), args=["--window", "headless", "--backend", "egl",
                                                       "--size", "480x640"])
    try:
        keys = config.wnd.keys

        class Mods:
            shift = False
            ctrl = False

        f1 = keys.F1 if isinstance(keys.F1, int) else "F1"  # the headless backend has no key codes
        config.on_render(0.0, 1 / 60)
        hidden = np.frombuffer(config.wnd.fbo.read(components=3), np.uint8).copy()
        assert not config.overlay.visible
        config.on_key_event(f1, keys.ACTION_PRESS, Mods())
        config.on_key_event(f1, keys.ACTION_RELEASE, Mods())
        assert config.overlay.visible and "f1" not in config.input.pressed
        config.on_render(0.0, 1 / 60)
        shown = np.frombuffer(config.wnd.fbo.read(components=3), np.uint8)
        assert (shown != hidden).mean() > 0.1

        def click(widget: str) -> None:
            x, y = config.overlay.widgets[widget]
            config.on_mouse_position_event(int(x), int(y), 0, 0)
            config.on_render(0.0, 1 / 60)
            config.on_mouse_press_event(int(x), int(y), 1)
            config.on_render(0.0, 1 / 60)
            config.on_mouse_release_event(int(x), int(y), 1)
            config.on_render(0.0, 1 / 60)

        assert config.engine.reflection_system.path == "auto"
        click("reflection batched")
        assert config.engine.reflection_system.path == "batched"
        click("probe layered")
        assert config.engine.stages["probes"].path == "layered"
        click("aa taa")
        assert config.engine.renderer.antialias == "taa"
        click("aa off")
        assert config.engine.renderer.antialias == "off"
        config.engine.renderer.render_scale = RENDER_SCALE_RANGE[0]   # (its grab at the left, off the middle)
        config.on_render(0.0, 1 / 60)
        click("render scale")   # (the slider's middle: the range's, 1.125, supersampled)
        assert config.engine.renderer.render_scale == pytest.approx(sum(RENDER_SCALE_RANGE) / 2, abs=0.05)
        drawn = render_size((480, 640), config.engine.renderer.render_scale)
        assert config.engine.renderer.targets.size == drawn
        config.on_render(0.0, 1 / 60)  # the overlay's lines are written before its widgets act
        assert any(line.startswith("post: ") and f"; drawn {drawn[0]}x{drawn[1]} of 480x640 by a box filter" in line
                   for line in config.overlay.lines), [line for line in config.overlay.lines if "post" in line]
        click("shadows")
        assert not config.engine.stages["shadows"].enabled
        config.on_render(0.0, 1 / 60)  # the overlay's lines are written before its widgets act
        assert any("shadow maps" in line and line.endswith("(off)") for line in config.overlay.lines)
        assert not config.mouse_captured, "a click on the overlay is not a click in the world"
        assert any(line.startswith("reflection path batched") for line in config.overlay.lines)

        config.on_key_event(f1, keys.ACTION_PRESS, Mods())
        assert not config.overlay.visible
        assert config.ctx.error == "GL_NO_ERROR"
    finally:
        config.on_close()
        config.wnd.destroy()


LEVEL = """
from components import DirectionalLight, Material, MeshRef, Skybox, Transform
from engine import Game, spawn_camera
from shell import run
from engine.assets.mesh import box, plane


class Still(Game):
    def build(self, world):
        spawn_camera(world, position=(0, 1.2, 4), pitch=-10)
        world.spawn(Skybox())
        world.spawn(DirectionalLight(direction=(-0.3, -1, -0.5), intensity=2.0))
        world.spawn(Transform(), MeshRef(plane(8, 8)), Material(color=(0.5, 0.5, 0.5)))
        world.spawn(Transform(position=(0.5, 0.5, 0)), MeshRef(box()), Material(color=(0.8, 0.2, 0.1)))


run(Still())
"""


def test_headless_overlay_flag_draws_into_the_png_and_nothing_else(tmp_path):
    level = tmp_path / "still.py"
    level.write_text(LEVEL)
    frames = {}
    for name, extra in (("plain", []), ("overlay", ["--overlay"])):
        out = tmp_path / name
        # 560 rows: the overlay's window (with its post-processing, screen, views-kept and smallest-view
        # lines, the grade, AO and curve row and the screen reflections' row) ends inside the frame.
        result = subprocess.run([sys.executable, str(level), "--headless", "--frames", "1", "--size", "480x600",
                                 "--out", str(out), *extra], cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)},
                                capture_output=True, text=True, timeout=120)
        assert result.returncode == 0, result.stderr
        frames[name] = np.asarray(Image.open(out / "frame_0000.png").convert("RGB"))
    changed = np.any(frames["plain"] != frames["overlay"], axis=2)
    rows, columns = np.nonzero(changed)
    assert (columns.min(), rows.min()) == POSITION  # the overlay window's corner, nothing before it
    box = changed[rows.min():rows.max() + 1, columns.min():columns.max() + 1]
    assert box.mean() > 0.5 and columns.max() < 470 and rows.max() < 590, (box.mean(), columns.max(), rows.max())


RELEASE_TWICE = """
from imgui_bundle import imgui

from engine.render.gl_context import create_headless_context
from shell.overlay import DebugOverlay

ctx = create_headless_context()
a, b = DebugOverlay(ctx), DebugOverlay(ctx)  # a is current (ImGui makes only the first one current)
a.release()
assert imgui.get_current_context() is None  # not the destroyed a
a.release()  # a second release does nothing (destroying an ImGui context twice aborts)
b.release()
assert imgui.get_current_context() is None  # a, current before b, is not restored: destroyed
b.release()
c, d = DebugOverlay(ctx), DebugOverlay(ctx)
d.release()
assert imgui.get_current_context() == c.context  # c stays current
c.release()
print("released")
"""


def test_an_overlay_released_twice_or_out_of_order_does_not_abort_the_process():
    """Esc in a window released the overlay twice: "double free or corruption (!prev)" and
    exit status 134 (in a subprocess, so an abort fails this test rather than the run)."""
    result = subprocess.run([sys.executable, "-c", RELEASE_TWICE], cwd=ROOT,
                            env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0 and result.stdout.strip() == "released", (result.returncode, result.stderr[-2000:])
