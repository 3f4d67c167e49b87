"""What the app shell and the systems exchange each frame: the player's input and where the
frame goes.  Both are world resources (``world.resources[Input]``, ``[Output]``), written
by the shell (window, runner, tests) and read by systems, so neither side imports the other."""
from __future__ import annotations

from dataclasses import dataclass, field

import moderngl


@dataclass
class Input:
    """Keys held (by name: 'w', 'a', 's', 'd', 'q', 'e', 'shift') and mouse motion this frame."""

    held: set[str] = field(default_factory=set)
    mouse_dx: float = 0.0
    mouse_dy: float = 0.0


@dataclass
class Output:
    """Where the frame goes: a window's framebuffer or a capture target, and its size."""

    framebuffer: moderngl.Framebuffer
    size: tuple[int, int]
