"""Which of a view-tree level's candidates have pixels, and which of those it draws.

Each candidate's claim counts its pixels in a samples query (``MirrorPasses.prepare_level``).
How a level learns them (``VISIBILITY_MODES``): "exact" reads this frame's counts (the CPU
waits for the GPU once a level) and a candidate with none gets no view; "predicted" uses
last frame's (nothing waits): every candidate becomes a view drawn on its claim's condition,
and only those that had pixels last frame grow views below (``chosen_by_prediction``).
The counts are kept per root and keyed by the claim's chain of surfaces from the root
(``RootVisibility``, ``TreeVisibility``), so a root's next render reads them when the GPU
has long drawn them.  The budgets (a level's view budget, the frame's view and pixel
budgets: ``BudgetLedger``) keep the views with pixels that fit, ranked by
``spending_order`` (``within_budgets``), and draw a level at a lower resolution where last
frame's coverage does not fit the pixels left (``level_scale``); any budget waits for the
counts, which it ranks by.

``ViewTree`` (``engine/render/view_tree.py``) runs the levels in order; these say, for one
level, which of its candidates become views and what that spends.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import moderngl
import numpy as np

from engine.core.budget import screen_coverage, spending_order
from engine.frame_stats import BudgetLedger
from engine.render.gpu import Gpu
from engine.render.mirror_passes import MirrorPasses, give_samples_queries, take_samples_queries
from engine.render.plan_rows import Candidates
from engine.render.view_plan import SurfaceTable
from engine.render.views import View

MIN_LEVEL_SCALE = 0.25  # the lowest resolution factor the pixel budget draws a level at
# How a level learns which candidates have pixels: "exact" reads this frame's claim counts
# (the CPU waits for the GPU once a level), "predicted" uses last frame's (nothing waits), and
# "auto" is exact on a software rasteriser (the CPU draws anyway: waiting costs nothing and
# the counts save views) and predicted on a GPU.
VISIBILITY_MODES = ("auto", "exact", "predicted")


@dataclass
class RootVisibility:
    """One root's claim queries and, for predicted visibility, its claim counts, each keyed by
    the claim's chain of surface entities from the root: ``seen``, last frame's; ``pending``,
    this frame's keys in the order of ``queries``, read at the root's next render, when the
    GPU has long drawn them.  An exact frame counts nothing for the next: after it, nothing
    is predicted."""

    queries: list[moderngl.Query] = field(default_factory=list)
    used: int = 0                 # queries taken this frame
    pending: list[tuple[int, ...]] = field(default_factory=list)
    counted: list[moderngl.Query] = field(default_factory=list)  # what counts each of ``pending``
    seen: dict[tuple[int, ...], int] = field(default_factory=dict)
    frame: int = -1               # the ViewTree frame it was last drawn in

    def take(self, count: int, ctx: moderngl.Context) -> list[moderngl.Query]:
        """The next ``count`` of this frame's queries (the root's pool grows as needed)."""
        if len(self.queries) < self.used + count:
            self.queries += take_samples_queries(ctx, self.used + count - len(self.queries))
        self.used += count
        return self.queries[self.used - count:self.used]


class TreeVisibility:
    """One tree's ``RootVisibility`` of each root it draws (the main camera; a probe's faces),
    by root (its name and skipped entity), from frame to frame."""

    def __init__(self, renderer: Gpu, passes: MirrorPasses) -> None:
        self.renderer = renderer
        self.passes = passes
        self.roots: dict[tuple[str, int], RootVisibility] = {}
        self._frame = 0                   # frames this tree has drawn in (a new RenderStats: a new frame)
        self._frame_stats: object | None = None

    def of(self, root: View) -> RootVisibility:
        """``root``'s claim counts, with last frame's read (``RootVisibility.seen``: empty
        where the root was not drawn last frame, and nothing is predicted from them).  At a
        tree's first render in a frame, roots it did not draw last frame hand their queries
        back to the context's pool."""
        stats = self.renderer.stats
        if stats is not self._frame_stats:
            self._frame_stats = stats
            self._frame += 1
            for key, old in list(self.roots.items()):
                if old.frame < self._frame - 1:
                    give_samples_queries(self.renderer.ctx, old.queries)
                    del self.roots[key]
        key = (root.name, root.skip)
        record = self.roots.get(key)
        if record is None:
            record = self.roots[key] = RootVisibility()
        # Last frame's counts, drawn by the GPU a frame ago (reading them waits for nothing
        # more); none where the root was not drawn last frame, or was drawn exactly.
        fresh = record.pending and record.frame == self._frame - 1
        record.seen = dict(zip(record.pending, claimed_pixels(self.passes, record.counted),
                               strict=True)) if fresh else {}
        record.pending, record.counted = [], []
        record.frame, record.used = self._frame, 0
        return record

    def forget(self) -> None:
        """A camera cut: what last frame's claims counted no longer says what this frame's
        views see (the camera went through a portal, or jumped), so the next render predicts
        nothing: every candidate is drawn and grows views, as on a first frame (the image
        is exact; the frame draws more views)."""
        for record in self.roots.values():
            record.seen, record.pending, record.counted = {}, [], []

    def release(self) -> None:
        """Every root's queries back to the context's pool."""
        for record in self.roots.values():
            give_samples_queries(self.renderer.ctx, record.queries)
        self.roots.clear()


def waits_for_counts(visibility: str, level_budget: int | None, stats: BudgetLedger, software: bool) -> bool:
    """Whether the levels read this frame's claim counts (the CPU waits for the GPU once
    a level), for a tree of ``visibility`` (``VISIBILITY_MODES``).  Budgets rank views by
    this frame's pixels, so any budget waits.  "auto" waits on a ``software`` rasteriser
    only: on a GPU, not waiting made a 16-mirror frame at 1080p 22-28% faster (an H200)."""
    if level_budget is not None or stats.view_budget is not None or stats.pixel_budget is not None:
        return True
    if visibility == "auto":
        return software
    return visibility == "exact"


def claimed_pixels(passes: MirrorPasses, queries: list[moderngl.Query]) -> list[int]:
    """Each claim's pixels (the CPU waits for the GPU, if they are this frame's), 0 for
    one known empty (``MirrorPasses.no_pixels``: never claimed, so never read)."""
    none = passes.no_pixels
    if none not in queries:
        return passes.claimed_pixels(queries)
    counted = iter(passes.claimed_pixels([query for query in queries if query is not none]))
    return [0 if query is none else next(counted) for query in queries]


def chosen_by_prediction(candidates: Candidates, queries: list[moderngl.Query], none: moderngl.Query,
                         is_end: list[bool], keys: list[tuple[int, ...]], record: RootVisibility,
                         entities: list[int], stats: BudgetLedger, coverage: dict[int, int], level: int,
                         screen: tuple[int, int]
                         ) -> tuple[list[int], list[int], list[int], list[tuple[int, ...]], list[moderngl.Query],
                                    list[int]]:
    """Predicted visibility: every candidate of the level becomes a view (or an end
    view), drawn on the GPU only if its claim counts pixels (conditional rendering: the
    returned conditions), except those known empty (``claim_cull``: their query in
    ``queries`` is ``none``, ``MirrorPasses.no_pixels``), which get no view, as in exact
    visibility: no claim, no draw, no views below, no composite; only those that had pixels
    last frame (or were not claimed then) get views below them.  Returns (views, those of
    them that grow, end views) as rows of ``candidates``, each candidate's key (its chain of
    surface ``entities``, from its parent's in ``keys``), whose count the GPU keeps in
    ``record`` for next frame (a known-empty one's counted 0: the next frame predicts it
    hidden), and the views' conditions.  The frame's spending (``stats``) and the level's
    ``coverage`` go by last frame's counts (0 for a known-empty one: it spends nothing); so
    does ``min_pixels``: a candidate last frame counted under it gets no view (its claim
    is counted again for the next frame), and is returned last, for its fallback."""
    claim_keys = [keys[p] + (entities[s],) for p, s in
                  zip(candidates.parent.tolist(), candidates.surface.tolist(), strict=True)]
    record.pending.extend(claim_keys)
    record.counted.extend(queries)
    seen = [record.seen.get(key) for key in claim_keys]
    if none in queries:  # the views and the end views, less the known empty
        claimed = [query is not none for query in queries]
        keep = [i for i, (end, has) in enumerate(zip(is_end, claimed, strict=True)) if has and not end]
        ends = [i for i, (end, has) in enumerate(zip(is_end, claimed, strict=True)) if has and end]
    else:
        keep = [i for i, end in enumerate(is_end) if not end]
        ends = [i for i, end in enumerate(is_end) if end]
    small = []
    smallest = stats.min_view_pixels
    if smallest is not None:
        small = [i for i in keep if seen[i] and screen_coverage(seen[i], candidates.size, screen) < smallest]
        if small:
            stats.views_small += len(small)
            keep = [i for i in keep if i not in small]
    # A view hidden last frame is drawn (it may show now) but its own surfaces wait for
    # a frame that counts pixels for it.
    grow = [at for at, i in enumerate(keep) if seen[i] != 0]
    drawn = sum(seen[i] or 0 for i in keep)
    coverage[level] = screen_coverage(drawn, candidates.size, screen)
    stats.views_spent += len(keep)
    stats.pixels_spent += drawn
    return keep, grow, ends, claim_keys, [queries[i] for i in keep], small


def within_budgets(surfaces: SurfaceTable, candidates: Candidates, pixels: list[int], level_budget: int | None,
                   stats: BudgetLedger, coverage: dict[int, int], level: int,
                   screen: tuple[int, int]) -> tuple[list[int] | np.ndarray, int]:
    """The candidates with pixels that the level's (``level_budget``) and the frame's
    budgets keep (highest priority first, then the most pixels), in claim order, and how
    many with pixels the level's budget dropped; spends the frame's budgets and records the
    level's ``coverage`` for the next frame's pixel budget.  A view with fewer pixels than
    the budget's ``min_pixels`` at the ``screen``'s resolution is left out first, and
    counted (``views_small``).  Without a budget, in Python: a level's claims are a list,
    and a few numpy calls cost more than it."""
    pixel_budget = stats.pixels_left()
    smallest = stats.min_view_pixels
    if level_budget is None and stats.view_budget is None and pixel_budget is None and smallest is None:
        keep = [i for i, n in enumerate(pixels) if n]  # no budget: every view with pixels
        drawn = sum(pixels)
        coverage[level] = screen_coverage(drawn, candidates.size, screen)
        stats.views_spent += len(keep)
        stats.pixels_spent += drawn
        return keep, 0
    pixels = np.asarray(pixels, np.int64)
    shown = pixels > 0
    if smallest is not None:
        (width, height), area = candidates.size, screen[0] * screen[1]
        small = shown & (np.rint(pixels * area / (width * height)) < smallest)  # as screen_coverage rounds
        stats.views_small += int(small.sum())
        shown &= ~small
    keep = np.flatnonzero(shown)
    dropped = 0
    coverage[level] = screen_coverage(pixels.sum(), candidates.size, screen)
    if len(keep) > 1:
        # Budgets keep the surfaces of highest priority, then those covering the most
        # pixels (this frame's claims), in claim order after.
        keep = keep[spending_order(surfaces.priority[candidates.surface[keep]], pixels[keep])]
    if level_budget is not None and len(keep) > level_budget:
        dropped = len(keep) - level_budget
        keep = keep[:level_budget]
    left = stats.views_left()
    if left is not None and len(keep) > left:
        stats.views_cut += len(keep) - left
        keep = keep[:left]
    if pixel_budget is not None:  # spent by the pixels drawn, at the level's resolution
        fits = np.cumsum(pixels[keep]) <= pixel_budget
        stats.views_cut += int(len(keep) - fits.sum())
        keep = keep[fits]
    stats.views_spent += len(keep)
    stats.pixels_spent += int(pixels[keep].sum())
    return np.sort(keep), dropped


def level_scale(stats: BudgetLedger, coverage: dict[int, int], level: int) -> float:
    """The resolution factor of ``level`` under the frame's pixel budget: 1, or the scale
    at which last frame's ``coverage`` of the level (its pixels at the screen's resolution)
    fits in the pixels left (at least ``MIN_LEVEL_SCALE``; what still does not fit is cut
    after the claims)."""
    left, needed = stats.pixels_left(), coverage.get(level)
    if left is None or not needed or needed <= left:
        return 1.0
    # In steps of a square root of two (1, 0.71, 0.5, 0.35, 0.25): a level's size changes
    # only when its coverage crosses a step, not with every pixel.
    step = math.ceil(-2.0 * math.log2(max(math.sqrt(left / needed), MIN_LEVEL_SCALE)) - 1e-9)
    return 2.0 ** (-step / 2.0)
