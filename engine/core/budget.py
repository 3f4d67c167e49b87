"""The frame's one view budget (``ViewBudget``), plain data a game or a level file sets as a
world resource; the stages that spend it and ``RenderStats`` report against it.  Kept in the
core (not with ``engine.resources``, which re-exports it) so level files can make one.

Two rules every spender shares are defined here once: the order a budget spends on what
competes for it (``spending_order``: the view tree's candidates, the probes' due captures,
the virtual lights), and a level's coverage at the screen's resolution
(``screen_coverage``), which the pixel budget's downscale decision reads."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from engine.core.errors import SpeculumError

# The render scales dynamic resolution may go down to (Renderer.render_scale's range:
# engine/render/resample.py RENDER_SCALE_RANGE, which the core cannot import).
MIN_RENDER_SCALE_RANGE = (0.25, 1.0)


class ViewBudgetError(SpeculumError, ValueError):
    """A ``ViewBudget`` that cannot be spent: a field out of range, or something else (the
    class itself, a dict) where the world's ``ViewBudget`` resource should be."""


MAX_MIN_PIXELS = 2 ** 53  # ViewBudget.min_pixels: counts of pixels exact in a float (no view is near it)


@dataclass(frozen=True)
class ViewBudget:
    """The frame's one view budget (a world resource; none: no limit), shared by every view
    the frame draws besides the main one: mirror and portal views of every tree and probe
    cube faces.  Views are spent in the order they are drawn: first captures of probes (an
    object sampling a probe needs one), then the main view's tree level by level (within a
    level the surfaces with the highest ``priority`` first, then those covering the most
    pixels: what does not fit is skipped, so the deepest levels go first), then the probes'
    recaptures.  ``probe_ms`` is a separate budget of time for the probe captures, spent by
    each probe's measured cost a face (``ProbeStates.face_ms``) in the scheduler's order:
    first captures, then a probe's own ``priority``, then nearest the camera.  Every such
    order is ``spending_order``'s (the virtual lights' too: priority, then brightness).  A probe that
    does not fit waits (its faces stay pending) and goes first later frames; one probe a
    frame is always captured, so none starves.  ``RenderStats`` reports what was spent and
    cut (``views_spent``, ``views_cut``, ``probe_ms_spent``, ``probe_faces_deferred``).

    ``pixels`` caps the reflection pixels a frame draws (each view's claimed pixels, at the
    resolution its level is drawn at) by drawing levels at a lower resolution rather than
    skipping views: a level whose coverage last frame would overrun what is left is drawn
    at the scale that fits (down to ``MIN_LEVEL_SCALE``; past that its views are skipped).
    The decision must precede the level's claims, so it is made on last frame's coverage of
    that level (Valve's Portal downgrades its views the same way).  ``RenderStats``:
    ``pixels_spent``, ``levels_downscaled``.

    ``min_pixels`` is the smallest view worth a pass: a mirror or portal view that would
    show fewer pixels than this (its claim, counted at the resolution of the picture its
    tree is drawn into: the screen, or a probe's face) is not drawn, and its surface shows
    its fallback there, as a view the budget cut (a level of detail, as engines cull a mesh
    under a screen size: a scene pass for a sliver a few pixels across costs a whole pass's
    CPU and shows what the fallback shows).  ``RenderStats.views_small`` counts them.

    ``frame_ms`` is the GPU's time a frame may take: the main view (and so every reflection
    level and post image sized from it) is drawn at a lower render scale while the GPU's
    measured frame runs over it, down to ``min_render_scale``, and raised again, up to
    ``Renderer.render_scale``, when it has room (dynamic resolution,
    ``engine/render/dynamic_resolution.py``).  ``RenderStats``: ``render_scale``,
    ``gpu_frame_ms``."""

    views: int | None = None
    probe_ms: float | None = None
    pixels: int | None = None
    min_pixels: int | None = None
    frame_ms: float | None = None
    min_render_scale: float = 0.5

    def __post_init__(self) -> None:
        self.check()

    def check(self) -> None:
        """Refuse fields out of range with a ``ViewBudgetError`` naming the field."""
        if self.views is not None and (not isinstance(self.views, int) or isinstance(self.views, bool)
                                       or self.views < 0):
            raise ViewBudgetError(f"ViewBudget.views must be None or an int >= 0, got {self.views!r}")
        if self.pixels is not None and (not isinstance(self.pixels, int) or isinstance(self.pixels, bool)
                                        or self.pixels < 0):
            raise ViewBudgetError(f"ViewBudget.pixels must be None or an int >= 0, got {self.pixels!r}")
        if self.min_pixels is not None and (not isinstance(self.min_pixels, int) or isinstance(self.min_pixels, bool)
                                            or self.min_pixels < 1):
            raise ViewBudgetError(f"ViewBudget.min_pixels must be None or an int >= 1, got {self.min_pixels!r}")
        if self.min_pixels is not None and self.min_pixels > MAX_MIN_PIXELS:
            # (Past a float's range the coverage test, in floats, overflowed frames later.)
            raise ViewBudgetError(f"ViewBudget.min_pixels must be at most 2**53 (a count of pixels), got "
                                  f"{self.min_pixels!r}")
        if self.probe_ms is not None and (isinstance(self.probe_ms, bool) or not isinstance(self.probe_ms, (int, float))
                                          or not 0.0 < self.probe_ms < float("inf")):
            raise ViewBudgetError(f"ViewBudget.probe_ms must be None or a finite number > 0, got {self.probe_ms!r}")
        if self.frame_ms is not None and (isinstance(self.frame_ms, bool) or not isinstance(self.frame_ms, (int, float))
                                          or not 0.0 < self.frame_ms < float("inf")):
            raise ViewBudgetError(f"ViewBudget.frame_ms must be None or a finite number > 0 (the GPU's milliseconds "
                                  f"a frame), got {self.frame_ms!r}")
        low, high = MIN_RENDER_SCALE_RANGE
        if isinstance(self.min_render_scale, bool) or not isinstance(self.min_render_scale, (int, float)) \
                or not low <= self.min_render_scale <= high:
            raise ViewBudgetError(f"ViewBudget.min_render_scale must be a number in [{low:g}, {high:g}] (the least "
                                  f"share of the output's size dynamic resolution draws at), got "
                                  f"{self.min_render_scale!r}")

    @staticmethod
    def of(world_resources: dict) -> ViewBudget | None:
        """The world's budget (None: no limit), checked: the resource must be a ViewBudget
        instance with fields in range; the class itself (``= ViewBudget``, the call
        forgotten) or another object is a ``ViewBudgetError`` saying so."""
        budget = world_resources.get(ViewBudget)
        if budget is None:
            return None
        if budget is ViewBudget or isinstance(budget, type):
            raise ViewBudgetError(f"world.resources[ViewBudget] holds the class {budget.__name__}, not a budget: "
                                  "make one, e.g. ViewBudget(views=24)")
        if not isinstance(budget, ViewBudget):
            raise ViewBudgetError(f"world.resources[ViewBudget] must be a ViewBudget(views=..., pixels=..., "
                                  f"probe_ms=..., min_pixels=..., frame_ms=...), got "
                                  f"{type(budget).__name__} {budget!r}")
        return budget


def spending_order(priority: Sequence[float] | np.ndarray, worth: Sequence[float] | np.ndarray,
                   *ties: Sequence[float] | np.ndarray,
                   first: Sequence[bool] | np.ndarray | None = None) -> np.ndarray:
    """The indices of competitors in the order a budget spends on them: those ``first``
    (a probe's first capture: an object sampling it needs one) before the rest, then the
    highest ``priority`` (``Mirror.priority``, ``Portal.priority``, a probe's priority plus
    the frames it waited), then the greatest ``worth`` (a surface's claimed pixels, a virtual
    light's brightness, a probe's nearness as its negated distance), then the smallest of
    each of ``ties`` in turn, then the order given.  What does not fit a budget is the tail,
    so the spenders cut from the end."""
    count = len(priority)
    if count < 2:  # most frames: nothing or one thing competes (a few microseconds of numpy saved)
        return np.arange(count)
    keys = [np.arange(count), *(np.asarray(tie) for tie in reversed(ties)), -np.asarray(worth, np.float64),
            -np.asarray(priority, np.float64)]
    if first is not None:
        keys.append(~np.asarray(first, bool))
    return np.lexsort(keys)


def screen_coverage(claimed: int, level_size: tuple[int, int], screen: tuple[int, int]) -> int:
    """A level's claimed pixels (``claimed``, at its own resolution ``level_size``) at the
    screen's resolution: what the pixel budget compares with the pixels left to decide the
    level's scale next frame.  Rounded to the nearest pixel: a level drawn at a scale is
    an estimate of its full-resolution coverage, and truncating it (``int``) would bias it
    low, by a whole pixel where float error leaves 1.9999 for 2, letting a level that does
    not fit pass as fitting; at full resolution the count is exact either way.  The claims
    are summed as integers first, so every caller gets the same number from the same claims."""
    width, height = level_size
    return round(int(claimed) * screen[0] * screen[1] / (width * height))
