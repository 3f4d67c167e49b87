"""Dynamic resolution: the main view's render scale lowered when the GPU's frame runs over the
frame's time budget (``ViewBudget.frame_ms``) and raised again when it has room, between
``ViewBudget.min_render_scale`` and ``Renderer.render_scale`` (the most it is drawn at), as
Unreal's dynamic resolution and Unity's dynamic resolution scaler do.

Measured, not guessed: ``GpuFrameTimer`` puts a GPU timestamp where the frame's GL work
starts (the extract stage) and another where it ends (after the recaptures that follow
present), a ring of ``TIMER_FRAMES`` pairs, each read only once the GPU says it is
available (never a wait: the reading is a few frames old).  Only the GPU's time counts:
a frame bound by the CPU is not helped by fewer pixels, and its GPU time stays under
budget, so its scale is left alone.

``ResolutionController`` turns the readings into the next scale: their exponential mean
(a frame's hitch is not a trend), a change only ``COOLDOWN`` frames after the last (the
readings lag the frames they time, so each change is judged on frames drawn at it), aimed
at ``HEADROOM`` of the budget with the pixels (the scale squared) in proportion to the time,
down at once when over budget and up only when well under (``RAISE_BELOW``), by at most
``MAX_RAISE`` a step, and in steps of ``SCALE_STEP`` (each change makes the main view's
targets again; steps keep them few).  With temporal AA the history is the output's size,
so a change does not start it again.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import moderngl

from engine.core.errors import GLLimitError
from engine.render.raw_gl import TimestampQueries

TIMER_FRAMES = 4      # timestamp pairs in flight: a reading is read about this many frames late at most
COOLDOWN = 8          # frames after a change before the next (the readings' lag, and then some)
HEADROOM = 0.9        # the share of the budget a change aims the frame at
RAISE_BELOW = 0.75    # the share of the budget the frame must stay under before the scale goes up
MAX_RAISE = 1.15      # the most a step raises the scale by
SCALE_STEP = 1.0 / 32.0
SMOOTHING = 0.3       # the newest reading's share of the mean


class GpuFrameTimer:
    """The GPU's time over each frame's GL work, from timestamps (``begin``, ``end``);
    ``latest_ms`` the newest reading (None before the first)."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self._queries = TimestampQueries(ctx)
        self._pairs: list[tuple[int, int]] = []
        self._marked: list[bool] = []     # by pair: both ends marked and not yet read
        self._next = 0
        self._open: int | None = None     # the pair begun this frame
        self.latest_ms: float | None = None
        self.readings = 0

    @property
    def available(self) -> bool:
        return not self._queries.missing

    def require(self) -> None:
        """Raise naming what is missing where this context cannot time its frames."""
        if self._queries.missing:
            raise GLLimitError(f"ViewBudget.frame_ms needs GPU timestamps, and this OpenGL's loader lacks "
                               f"{', '.join(self._queries.missing)} (core since OpenGL 3.3)")

    def begin(self) -> None:
        """Mark where the frame's GL work starts (reading any finished pair first)."""
        self.poll()
        if not self._pairs:
            names = self._queries.make(2 * TIMER_FRAMES)
            self._pairs = list(zip(names[::2], names[1::2], strict=True))
            self._marked = [False] * TIMER_FRAMES
        index = self._next
        if self._marked[index]:   # (still unread after a ring's turn: let it go, the GPU is that far behind)
            self._marked[index] = False
        self._queries.mark(self._pairs[index][0])
        self._open = index

    def end(self) -> None:
        """Mark where the frame's GL work ends."""
        if self._open is None:
            return
        self._queries.mark(self._pairs[self._open][1])
        self._marked[self._open] = True
        self._next = (self._open + 1) % TIMER_FRAMES
        self._open = None

    def poll(self) -> None:
        """Read every pair the GPU has finished, oldest first."""
        for step in range(TIMER_FRAMES):
            index = (self._next + step) % TIMER_FRAMES
            if not self._marked or not self._marked[index]:
                continue
            start, end = (self._queries.nanoseconds(query) for query in self._pairs[index])
            if start is None or end is None:
                break   # (later pairs finish later)
            self._marked[index] = False
            self.latest_ms = max(end - start, 0) / 1e6
            self.readings += 1

    def release(self) -> None:
        self._queries.release([query for pair in self._pairs for query in pair])
        self._pairs, self._marked, self._open = [], [], None


@dataclass
class ResolutionController:
    """The next frame's render scale from the GPU's frame times (plain arithmetic: tested
    with readings given)."""

    scale: float = 1.0
    mean_ms: float | None = None
    waited: int = COOLDOWN   # frames since the last change

    def update(self, reading_ms: float | None, budget_ms: float, low: float, high: float) -> float:
        """Take a frame's newest reading (None: none new) and return the scale to draw the
        next frame at, in [``low``, ``high``]."""
        clamped = min(max(self.scale, low), high)
        if clamped != self.scale:   # (the bounds moved: follow at once)
            self.scale, self.waited = clamped, 0
        if reading_ms is not None:
            self.mean_ms = reading_ms if self.mean_ms is None else \
                self.mean_ms + SMOOTHING * (reading_ms - self.mean_ms)
        self.waited += 1
        if self.mean_ms is None or self.waited < COOLDOWN:
            return self.scale
        over = self.mean_ms > budget_ms
        if not over and self.mean_ms > RAISE_BELOW * budget_ms:
            return self.scale   # (in the band: no change, no oscillation)
        wanted = self.scale * math.sqrt(HEADROOM * budget_ms / max(self.mean_ms, 1e-6))
        wanted = min(wanted, self.scale * MAX_RAISE)
        stepped = math.floor(wanted / SCALE_STEP) * SCALE_STEP if over else \
            math.floor(wanted / SCALE_STEP + 1e-9) * SCALE_STEP
        stepped = min(max(stepped, low), high)
        if stepped != self.scale:
            self.scale, self.waited = stepped, 0
            self.mean_ms = None   # (the next readings are of frames at the new scale)
        return self.scale
