"""The windowed shell: a moderngl-window WindowConfig that drives an Engine.

WASD + mouse fly camera (Q/E down/up, Shift faster), Esc quits (exit status 0), F12 writes a
screenshot, F1 shows or hides the debug overlay (``shell/overlay.py``; the mouse is the overlay's while
it is over it).  Each frame the shell also polls the shader library, so an edited file
under ``shaders/`` is rebuilt while the game runs (hot reload; errors printed once and shown
in the overlay), and a game's level file is reloaded when it is saved (``shell/level_reload.py``;
the same: its error printed once and shown in the overlay, the old level kept).  The same
class runs under moderngl-window's headless window, which the tests use.

Closing: everything the shell made (the engine's GL objects, the overlay's ImGui context)
is released once, while the window's GL context is still current, and the window is
closed after the main loop.  Esc is the shell's key, not moderngl-window's exit key: that
one closes the pyglet window (destroying its GL context) inside the event dispatch before
it calls ``on_close``, and a second close from the shell's own Esc handler released the
overlay twice ("double free or corruption", exit 134).  ``--frames N`` closes
the window the same way after N frames; ``--export-scene`` is written as the window closes;
``--gif`` and ``--ids`` are headless outputs and are refused for a window.  moderngl-window
logs only warnings (its INFO lines, the GL context's description and the frame rate at the
end, are off).
"""
from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import moderngl_window as mglw

from components import FlyController
from engine.core.errors import SpeculumError
from engine.core.frame_io import Input, Output
from engine.core.game import Game
from engine.render.targets import CaptureTarget
from shell.app import Engine
from shell.capture import save_png

if TYPE_CHECKING:
    import moderngl
    from moderngl_window.context.base import BaseKeys, KeyModifiers

    from shell.overlay import DebugOverlay  # imported when the overlay is made: it needs imgui-bundle

_NAMED_KEYS = {"SPACE": "space", "ENTER": "enter", "TAB": "tab", "BACKSPACE": "backspace", "LEFT": "left",
               "RIGHT": "right", "UP": "up", "DOWN": "down", **{f"F{n}": f"f{n}" for n in range(1, 12)},
               **{chr(c): chr(c).lower() for c in range(ord("A"), ord("Z") + 1)},
               **{f"NUMBER_{n}": str(n) for n in range(10)}}
_BUTTONS = {1: "left", 2: "right", 3: "middle"}


def key_names(keys: type[BaseKeys]) -> dict:
    """moderngl-window key code -> the ``Input`` name of that key (the backend's codes differ).
    The headless backend has no key codes (every one reads "undefined"): there a key is sent
    by its attribute name ("W", "SPACE"), as the tests do."""
    codes = {attr: getattr(keys, attr, None) for attr in _NAMED_KEYS}
    return {code if isinstance(code, int) else attr: _NAMED_KEYS[attr] for attr, code in codes.items()}


def key_attributes(keys: type[BaseKeys]) -> dict:
    """moderngl-window key code -> its attribute name on the backend's keys ("BACKSPACE",
    "A"): what the overlay's fields and the editor's shortcuts read.  The headless backend
    has no codes: there a key is sent by its name, which maps to itself."""
    names = [attr for attr in dir(keys) if attr.isupper() and not attr.startswith("ACTION")]
    found = {getattr(keys, attr): attr for attr in names if isinstance(getattr(keys, attr, None), int)}
    return {**{attr: attr for attr in names}, **found}


class NoOverlay:
    """Stands in for the debug overlay where imgui-bundle is not installed (it is a
    dependency, but a machine may lack its native wheel): F1 says why once, nothing is drawn."""

    visible = False
    wants_mouse = False
    wants_keyboard = False

    def __init__(self) -> None:
        self._said = False

    def toggle(self) -> None:
        if not self._said:
            print("speculum: the debug overlay needs imgui-bundle (pip install imgui-bundle)", file=sys.stderr)
            self._said = True

    def __getattr__(self, name: str):
        return lambda *args, **kwargs: None  # record, draw, mouse and key forwarding, release


def make_overlay(ctx: moderngl.Context, visible: bool) -> DebugOverlay | NoOverlay:
    """The debug overlay, or ``NoOverlay`` where imgui-bundle cannot be imported."""
    try:
        from shell.overlay import DebugOverlay
    except ImportError:
        if visible:
            print("speculum: --overlay needs imgui-bundle (pip install imgui-bundle): drawing none", file=sys.stderr)
        return NoOverlay()
    return DebugOverlay(ctx, visible=visible)


class SpeculumWindow(mglw.WindowConfig):
    """The window that runs an Engine: ``make_window_config`` makes the subclass bound to a
    game and its command line (moderngl-window makes the instance itself, from a class)."""

    game: Game  # the game the window runs (set on the subclass)
    options: argparse.Namespace | None = None  # the command line (``--frames``, ``--aa``, ...), if any
    gl_version = (4, 1)
    aspect_ratio = None
    resizable = True
    vsync = True
    log_level = logging.WARNING  # moderngl-window's INFO lines (context description, frame rate) off

    def __init__(self, **kwargs: Any) -> None:  # ctx, wnd, timer: moderngl-window's
        super().__init__(**kwargs)
        # Esc is handled by the shell (``quit``), which releases before the window closes;
        # moderngl-window's own exit key would close first and call on_close after.
        self.wnd.exit_key = None
        self.frames_left: int | None = getattr(self.options, "frames", None)
        self.export_scene: Path | None = getattr(self.options, "export_scene", None)
        self.written: list[Path] = []  # what release wrote (the scene export)
        self.released = False
        args = self.options
        self.engine = Engine(self.game, self.ctx)
        # The game's error stops the game, not the window: a level being edited is not lost
        # (the traceback printed, the title and the overlay say so, F5 resumes).
        self.engine.game_guard.contain = True
        if args is not None:
            self.engine.start_from(args)
        self.input: Input = self.engine.world.resources[Input]
        self.screenshots = Path(args.out) if args is not None and args.out else Path("screenshots")
        self.mouse_captured = False
        self.key_names = key_names(self.wnd.keys)
        self.key_attributes = key_attributes(self.wnd.keys)
        self.overlay = make_overlay(self.ctx, visible=bool(getattr(args, "overlay", False)))
        self.overlay.set_scale(self.wnd.pixel_ratio)  # a high-DPI screen: the overlay at its usual size
        self.shown_title = self.wnd.title = self.game.title  # build may have named the level
        from engine.assets.level_file import LevelGame

        if isinstance(self.game, LevelGame):  # a level file reloads when saved (shell/level_reload.py)
            self.engine.watch_level()

    def on_render(self, time_s: float, frametime: float) -> None:
        if self.released:
            return  # closed (Esc, --frames): nothing is left to draw with
        size = self.wnd.buffer_size
        for message in self.engine.renderer.shaders.poll():  # hot reload: at most every 0.5 s
            print(f"speculum: {message}", file=sys.stderr, flush=True)
        if self.engine.level_reload is not None:  # the level file saved: rebuilt, or its error said once
            for message in self.engine.level_reload.poll():
                print(f"speculum: {message}", file=sys.stderr, flush=True)
        self.overlay.record(frametime)
        self.engine.frame(min(frametime, 0.1), Output(self.wnd.fbo, size))
        title = self.game.title if self.engine.game_guard.stopped is None else \
            f"{self.game.title} (game stopped: F5 resumes)"
        if title != self.shown_title:  # a game that changed level ('n') renames its window; a stopped one says so
            self.shown_title = self.wnd.title = title
        self.overlay.draw(self.engine, self.wnd.fbo, size)
        if self.frames_left is not None:
            self.frames_left -= 1
            if self.frames_left <= 0:
                self.quit()

    def on_resize(self, width: int, height: int) -> None:
        # The render system sizes its targets from the framebuffer each frame (0x0 skips); a
        # window moved to a screen of another pixel ratio draws the overlay at that ratio.
        self.overlay.set_scale(self.wnd.pixel_ratio)

    def on_key_event(self, key: int | str, action: int | str, modifiers: KeyModifiers) -> None:
        if self.released:
            return  # events queued behind Esc
        keys = self.wnd.keys
        name = self.key_names.get(key)
        if self.overlay.visible and name != "f1":
            ctrl, shift = bool(getattr(modifiers, "ctrl", False)), bool(getattr(modifiers, "shift", False))
            attribute = self.key_attributes.get(key, "")
            # A modifier key itself: held from its press to its release, whatever the backend's
            # modifiers say at that moment (some report the state before the event).
            if attribute in ("LEFT_CTRL", "RIGHT_CTRL"):
                ctrl = action == keys.ACTION_PRESS
            elif attribute in ("LEFT_SHIFT", "RIGHT_SHIFT"):
                shift = action == keys.ACTION_PRESS
            self.overlay.key(attribute, action == keys.ACTION_PRESS, ctrl, shift)
            if self.overlay.wants_keyboard:  # typing in a field: the keys are its (Esc too)
                return
            if action == keys.ACTION_PRESS and self.overlay.shortcut(self.engine, attribute, ctrl, shift):
                return
        if self.engine.game_guard.stopped is not None and self.key_attributes.get(key, "") == "F5":
            if action == keys.ACTION_PRESS:
                self.engine.game_guard.resume()  # the game's code runs again from the next frame
            return
        if name == "f1":  # the overlay's key, not the game's
            if action == keys.ACTION_PRESS:
                self.overlay.toggle()
                if self.overlay.visible and self.mouse_captured:  # give the pointer back to use it
                    self.mouse_captured = False
                    self.wnd.mouse_exclusivity = False
                    self.wnd.cursor = True
            return
        if action == keys.ACTION_PRESS:
            if name:
                self.input.press(name)
            elif key == getattr(keys, "F12", None):
                self.screenshot()
            elif key == keys.ESCAPE:
                self.quit()
        elif action == keys.ACTION_RELEASE and name:
            self.input.release(name)
        for modifier in ("shift", "ctrl"):
            if getattr(modifiers, modifier, False):
                self.input.held.add(modifier)
            else:
                self.input.held.discard(modifier)

    def on_mouse_scroll_event(self, x_offset: float, y_offset: float) -> None:
        if not self.released and self.overlay.visible:
            self.overlay.scroll(x_offset, y_offset)  # the entity list, the inspector
        else:  # the game's: a fly camera flies, an orthographic one zooms (systems/fly_camera_system.py)
            self.input.wheel += float(y_offset)

    def _in_pixels(self, x: float, y: float) -> tuple[float, float]:
        """A window position (points) in the output's pixels, the overlay's units (its display
        is the framebuffer: on a high-DPI screen pixel_ratio times the window's points)."""
        ratio = float(getattr(self.wnd, "pixel_ratio", 1.0) or 1.0)
        return float(x) * ratio, float(y) * ratio

    def on_unicode_char_entered(self, char: str) -> None:
        if not self.released and self.overlay.visible:
            self.overlay.text(char)  # a field being typed in takes it (ImGui ignores it otherwise)

    def on_mouse_press_event(self, x: int, y: int, button: int) -> None:
        if self.released:
            return  # events queued behind Esc
        if self.overlay.visible:
            self.overlay.mouse_moved(*self._in_pixels(x, y))
            self.overlay.mouse_button(button, True)
            if self.overlay.wants_mouse:
                return
            # With the overlay shown a click in the world is the level editor's: it selects what
            # is seen there (Ctrl: the mirror or portal it is seen through; Shift: puts the
            # selection on the surface seen there), see shell/editor.py.
            ratio = float(getattr(self.wnd, "pixel_ratio", 1.0) or 1.0)
            modifiers = getattr(self.wnd, "modifiers", None)
            ctrl, shift = bool(getattr(modifiers, "ctrl", False)), bool(getattr(modifiers, "shift", False))
            if self.overlay.click(self.engine, float(x) * ratio, float(y) * ratio, surface=ctrl, place=shift):
                return
        # In the output's pixels (what Output.size and the main view measure): on a
        # high-DPI screen the framebuffer has pixel_ratio times the window's pixels.
        ratio = float(getattr(self.wnd, "pixel_ratio", 1.0) or 1.0)
        self.input.mouse = (float(x) * ratio, float(y) * ratio)
        if getattr(self.game, "mouse_look", False) and not self.mouse_captured:
            # A game that looks with the mouse (its own controller, no FlyController):
            # the click that takes the pointer is not a game click (no portal fired).
            self.mouse_captured = True
            self.wnd.mouse_exclusivity = True
            self.wnd.cursor = False
            return
        self.input.clicks.add(_BUTTONS.get(button, str(button)))
        if self.engine.world.query_one(FlyController):  # mouse look; a game without it keeps the pointer
            self.mouse_captured = True
            self.wnd.mouse_exclusivity = True
            self.wnd.cursor = False

    def on_mouse_release_event(self, x: int, y: int, button: int) -> None:
        if self.released:
            return  # events queued behind Esc
        if self.overlay.visible:
            self.overlay.mouse_moved(*self._in_pixels(x, y))
            self.overlay.mouse_button(button, False)

    def on_mouse_position_event(self, x: int, y: int, dx: int, dy: int) -> None:
        if self.released:
            return  # events queued behind Esc
        if self.overlay.visible and not self.mouse_captured:
            self.overlay.mouse_moved(*self._in_pixels(x, y))
        # In the output's pixels (what Output.size and the main view measure): on a
        # high-DPI screen the framebuffer has pixel_ratio times the window's pixels.
        ratio = float(getattr(self.wnd, "pixel_ratio", 1.0) or 1.0)
        self.input.mouse = (float(x) * ratio, float(y) * ratio)
        if self.mouse_captured:
            self.input.mouse_dx += dx
            self.input.mouse_dy += dy

    def on_mouse_drag_event(self, x: int, y: int, dx: int, dy: int) -> None:
        if self.released:
            return  # events queued behind Esc
        if self.overlay.visible:
            self.overlay.mouse_moved(*self._in_pixels(x, y))
            if self.overlay.wants_mouse:  # dragging the depth-cap slider, not looking around
                return
        # In the output's pixels (what Output.size and the main view measure): on a
        # high-DPI screen the framebuffer has pixel_ratio times the window's pixels.
        ratio = float(getattr(self.wnd, "pixel_ratio", 1.0) or 1.0)
        self.input.mouse = (float(x) * ratio, float(y) * ratio)
        self.input.mouse_dx += dx
        self.input.mouse_dy += dy

    def screenshot(self) -> Path:
        """Write the last frame drawn to a PNG, by presenting it again into an offscreen
        capture target (the headless runs' path).  Why not read the window: moderngl reads
        a framebuffer through GL_COLOR_ATTACHMENT0, which a window's default framebuffer
        does not have, so under a real window (GLX) that read leaves GL_INVALID_OPERATION
        behind and the next frame's error check fails."""
        renderer = self.engine.renderer
        if renderer.targets is None:
            raise SpeculumError("screenshot: no frame has been drawn yet")
        size = renderer.targets.size
        capture = CaptureTarget(self.ctx, size)
        try:
            self.engine.stages["present"].present_into(capture.framebuffer, size)  # as the frame was
            if len(renderer.screen_quads):  # the game's screen text, drawn over the frame as it was
                renderer.text().draw(renderer.screen_quads, capture.framebuffer, size, renderer.screen_pictures,
                                     renderer.present_pass.look)
            rgb = capture.read_rgb()
        finally:
            capture.release()
        self.screenshots.mkdir(parents=True, exist_ok=True)
        stamp = time.strftime("%Y%m%d_%H%M%S")
        path = self.screenshots / f"screenshot_{stamp}.png"
        n = 1
        while path.exists():  # two presses within a second keep both pictures
            path = self.screenshots / f"screenshot_{stamp}_{n}.png"
            n += 1
        save_png(rgb, path)
        print(f"speculum: screenshot {path}", flush=True)
        return path

    def quit(self) -> None:
        """End the run: release everything now (the window's GL context is current) and
        let the main loop stop; ``run_windowed`` closes the window after it.  Not closed
        here: a key arrives inside pyglet's event dispatch, and a window closed under it
        breaks the rest of that dispatch."""
        self.release()
        self.wnd.is_closing = True

    def release(self) -> None:
        """Write ``--export-scene`` and release the overlay and the engine, once."""
        if self.released:
            return
        self.released = True
        try:
            if self.export_scene is not None:
                from shell.capture import write_scene

                self.written += write_scene(self.engine, self.export_scene, self.wnd.buffer_size)
                print(f"speculum: wrote {', '.join(str(p) for p in self.written)}", flush=True)
        finally:
            try:
                self.overlay.release()
            finally:
                self.engine.close()

    def on_close(self) -> None:
        # The window's close button (its GL context is still there) or ``quit`` (done).
        self.release()


def make_window_config(game: Game, args: argparse.Namespace | None = None) -> type[mglw.WindowConfig]:
    """A ``SpeculumWindow`` class bound to ``game`` and its command line (moderngl-window
    instantiates it itself)."""
    return type("SpeculumWindow", (SpeculumWindow,), {
        "game": game, "options": args, "title": game.title, "window_size": args.size if args else game.size})


WINDOW_REFUSES = {"gif": "--gif", "ids": "--ids"}


def run_windowed(game: Game, args: argparse.Namespace) -> None:
    """Open the window and run until it is closed (Esc, its close button, ``--frames N``).
    ``--gif`` and ``--ids`` write headless frames: a window refuses them (a SpeculumError,
    the runner's one error line) rather than ignoring them; a game that stopped at an error
    and was not resumed by the close ends the run with one too (exit status 2)."""
    given = [flag for name, flag in WINDOW_REFUSES.items() if getattr(args, name, None)]
    if given:
        raise SpeculumError(f"{' and '.join(given)} {'write' if len(given) > 1 else 'writes'} the frames of a "
                            "headless run: add --headless (a window writes screenshots with F12, and the scene "
                            "with --export-scene when it closes)")
    if getattr(args, "export_scene", None) is not None:
        from shell.capture import prepare_out

        prepare_out(args.export_scene.parent, "--export-scene folder")
    w, h = args.size
    config_cls = make_window_config(game, args)
    config = mglw.create_window_config_instance(config_cls, args=["--size", f"{w}x{h}"])
    try:
        try:
            mglw.run_window_config_instance(config)
        except BaseException:
            try:
                config.release()  # a frame raised: give back what is left, and report the frame's error
            except Exception:
                pass
            raise
        config.release()  # closed by Esc or --frames: done already; by the close button: done in on_close
    finally:
        config.wnd.close()  # after the loop, outside any event dispatch (on_close finds it released)
    stopped = config.engine.game_guard.stopped
    if stopped is not None:  # a run (say with --frames) whose game failed does not end as a clean one
        raise SpeculumError(f"the game stopped in {stopped}, and was not resumed before the window closed "
                            "(its traceback is above)")
