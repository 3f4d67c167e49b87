"""Text and panels on the screen: plain data a game puts on any entity (it needs no Transform).

They are drawn over the finished picture, after the present stage (``engine/render/text.py``),
so no mirror, portal or probe shows them and the id image does not hold them.  Positions are
output pixels: ``anchor`` picks a point of the output (a corner, an edge's middle, the
centre) and the same point of the text's (or panel's) box, and ``position`` moves the box
from there, x to the right and y down: ``ScreenText("3.2 s", anchor="top_right",
position=(-16, 16))`` puts the text's top-right corner 16 pixels in from the output's.

Text is ASCII: the printable characters (space to ``~``) and ``\\n`` for a new line; any
other character draws as ``?``.  ``scale`` multiplies the font's pixels (1: the atlas's
``FONT_SIZE`` pixels; 2 doubles each texel, crisp).  What is drawn first is under what is
drawn after: ascending ``order``, a panel before a text of the same order, then by entity.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pyglm import glm

from components.tracking import TrackedComponent, _fail, color, finite, integer

# The anchor names and the point of the output (and of the box) each names, as fractions
# of its width and height from the top-left.
SCREEN_ANCHORS: dict[str, tuple[float, float]] = {
    "top_left": (0.0, 0.0), "top": (0.5, 0.0), "top_right": (1.0, 0.0),
    "left": (0.0, 0.5), "center": (0.5, 0.5), "right": (1.0, 0.5),
    "bottom_left": (0.0, 1.0), "bottom": (0.5, 1.0), "bottom_right": (1.0, 1.0),
}
MAX_TEXT_LENGTH = 4096    # characters in one ScreenText (a frame draws at most text.MAX_QUADS quads)
MAX_TEXT_SCALE = 16
MAX_SCREEN_PIXELS = 1e5   # |position| and a panel's size, pixels
MAX_ORDER = 1 << 20


def _pixels(owner: object, name: str, value: Any, *, low: float) -> glm.vec2:
    parts = list(value) if isinstance(value, (list, tuple, glm.vec2)) else None
    if parts is None or len(parts) != 2 or any(isinstance(p, bool) for p in parts):
        raise _fail(owner, name, value, "must be two numbers (pixels)")
    x = finite(owner, name, parts[0], low=low, high=MAX_SCREEN_PIXELS)
    y = finite(owner, name, parts[1], low=low, high=MAX_SCREEN_PIXELS)
    return glm.vec2(x, y)


def _anchor(owner: object, name: str, value: Any) -> str:
    if not isinstance(value, str) or value not in SCREEN_ANCHORS:
        raise _fail(owner, name, value, f"must be one of {tuple(SCREEN_ANCHORS)}")
    return value


@dataclass(eq=False)
class ScreenText(TrackedComponent):
    """A line (or lines) of text on the screen, in ``color`` (linear RGBA: alpha fades it).

    ``text`` (ASCII, ``\\n`` for new lines; at most ``MAX_TEXT_LENGTH`` characters),
    ``position`` (pixels from the ``anchor``), ``anchor`` (one of ``SCREEN_ANCHORS``),
    ``scale`` (whole texels per font pixel, 1 to ``MAX_TEXT_SCALE``), ``order`` (drawn over
    lower orders), ``background`` (None, or a linear RGBA colour: a panel the text's box
    plus ``padding`` pixels a side, drawn just under the text: a caption that needs no
    measuring)."""

    text: str = ""
    position: Any = field(default_factory=lambda: glm.vec2(16.0, 16.0))
    anchor: str = "top_left"
    color: Any = field(default_factory=lambda: glm.vec4(1.0, 1.0, 1.0, 1.0))
    scale: int = 1
    order: int = 0
    background: Any = None
    padding: float = 6.0

    def _validate(self, name: str, value: Any) -> Any:
        if name == "background":
            return None if value is None else color(self, name, value)
        if name == "padding":
            return finite(self, name, value, low=0.0, high=MAX_SCREEN_PIXELS)
        if name == "text":
            if not isinstance(value, str):
                raise _fail(self, name, value, "must be a string")
            if len(value) > MAX_TEXT_LENGTH:
                raise _fail(self, name, f"{value[:20]}...", f"must be at most {MAX_TEXT_LENGTH} characters, "
                                                            f"got {len(value)}")
            return value
        if name == "position":
            return _pixels(self, name, value, low=-MAX_SCREEN_PIXELS)
        if name == "anchor":
            return _anchor(self, name, value)
        if name == "color":
            return color(self, name, value)
        if name == "scale":
            return integer(self, name, value, low=1, high=MAX_TEXT_SCALE)
        if name == "order":
            return integer(self, name, value, low=-MAX_ORDER, high=MAX_ORDER)
        return value


@dataclass(eq=False)
class ScreenPanel(TrackedComponent):
    """A filled rectangle on the screen (behind text, a bar, a fade): ``size`` pixels, placed
    as ``ScreenText`` is (``position`` from the ``anchor``), in ``color`` (linear RGBA; alpha
    lets the picture show through).  With a ``Monitor`` on its entity it is filled with the
    monitor's picture times ``color`` (a rear-view mirror, a minimap)."""

    size: Any = field(default_factory=lambda: glm.vec2(200.0, 40.0))
    position: Any = field(default_factory=lambda: glm.vec2(0.0, 0.0))
    anchor: str = "top_left"
    color: Any = field(default_factory=lambda: glm.vec4(0.0, 0.0, 0.0, 0.6))
    order: int = 0

    def _validate(self, name: str, value: Any) -> Any:
        if name == "size":
            return _pixels(self, name, value, low=0.0)
        if name == "position":
            return _pixels(self, name, value, low=-MAX_SCREEN_PIXELS)
        if name == "anchor":
            return _anchor(self, name, value)
        if name == "color":
            return color(self, name, value)
        if name == "order":
            return integer(self, name, value, low=-MAX_ORDER, high=MAX_ORDER)
        return value
