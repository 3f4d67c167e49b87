"""What the app shell and the systems exchange each frame: the player's input and where the
frame goes.  Both are world resources (``world.resources[Input]``, ``[Output]``), written
by the shell (window, runner, tests) and read by systems, so neither side imports the other."""
from __future__ import annotations

from dataclasses import dataclass, field

import moderngl


@dataclass
class Input:
    """The player's input this frame, by key name.

    Names: letters and digits in lower case ('w', 'r', '1'), 'space', 'enter', 'tab',
    'backspace', 'left', 'right', 'up', 'down', 'shift', 'ctrl', 'f1'..'f11' (F12 and Esc
    belong to the shell: screenshot, quit).  ``held`` is what is down now; ``pressed`` what
    went down since the last frame (an edge: one frame per press, for toggles and actions);
    ``clicks`` the mouse buttons pressed since the last frame ('left', 'right', 'middle') and
    ``mouse`` the pointer's last position in the output's pixels (x right, y down;
    the window shell scales a high-DPI window's points by its pixel ratio); ``wheel`` the
    mouse wheel's steps since the last frame (away from the player: positive).  The engine
    empties ``pressed``, ``clicks``, the mouse motion and the wheel after every frame; the
    shell (a window, a test, a scripted player) fills them before the next."""

    held: set[str] = field(default_factory=set)
    pressed: set[str] = field(default_factory=set)
    clicks: set[str] = field(default_factory=set)
    mouse: tuple[float, float] = (0.0, 0.0)
    mouse_dx: float = 0.0
    mouse_dy: float = 0.0
    wheel: float = 0.0

    def press(self, *names: str) -> None:
        """Keys go down this frame (a scripted player's or a window's key press)."""
        self.held.update(names)
        self.pressed.update(names)

    def release(self, *names: str) -> None:
        """Keys go up."""
        self.held.difference_update(names)

    def end_frame(self) -> None:
        """Forget this frame's edges and motion (held keys stay held)."""
        self.pressed.clear()
        self.clicks.clear()
        self.mouse_dx = self.mouse_dy = 0.0
        self.wheel = 0.0


@dataclass
class Output:
    """Where the frame goes: a window's framebuffer or a capture target, and its size."""

    framebuffer: moderngl.Framebuffer
    size: tuple[int, int]
