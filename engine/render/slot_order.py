"""The transparent slot's order: in which order a view blends its transparent batches
(glass, water, see-through mirrors and portals), and which of them a tree's view blends
before its claims (``split_slot``).  Drawn by ``engine/render/scene_pass.py``.

Back to front by the batches' centres, decals' cut meshes first (they lie on opaque
surfaces: glass that covers one on screen is in front of it), except where a see-through
surface's plane says otherwise: a batch on the far side of a pond or a see-through mirror, seen from the eye,
blends before it, one on the near side after (for pairs whose boxes overlap on the view's
screen); where planes and centres make a cycle, the centres give way.  What a view needs is
worked out once while the glass stands (``SlotGeometry``); up to ``FEW_BATCHES`` batches are
ordered pair by pair, more on arrays (``SlotOrder``: its cost grows with the pairs that
overlap on screen, not with every pair).
"""
from __future__ import annotations

import heapq
import math
from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from pyglm import glm

from engine.core.material_slots import ReflectVariant
from engine.render.views import View

if TYPE_CHECKING:
    from engine.render.instances import InstanceBatch

_PLANAR = int(ReflectVariant.PLANAR)


class SlotGeometry:
    """What ordering the transparent slot needs of its batches, worked out once for as long
    as they stand (``ScenePass._slot_geometry``: the batch list, the see-through surfaces'
    planes, each batch's uploads, instances and variants), not once a view: each batch's centre
    (what back-to-front sorting compares: its instances' mean position), its world box's
    corners (glm vectors, and float32 rows for ``_screen_rects``), whether it is a see-through
    surface and its plane (``InstanceBatch.plane``), and on which side of each such plane
    every other batch lies (``_side``: the eye moves from view to view, the boxes do not).
    ``splits``: the views' ``split_slot`` answers, kept from a view's ``draw`` to its
    ``draw_transparent`` (``split_slot``)."""

    __slots__ = ("batches", "states", "centres", "corners", "planes", "see_through", "decals", "sides", "planar",
                 "corner_columns", "boxed", "planar_at", "splits")

    def __init__(self, batches: Sequence[InstanceBatch]) -> None:
        self.batches = list(batches)
        self.states = [(batch.uploads, batch.count, batch.variants) for batch in self.batches]
        self.centres = [batch.centre() for batch in self.batches]
        self.see_through = [see_through_surface(batch) for batch in self.batches]
        self.decals = [batch.decal_order if batch.decal else None for batch in self.batches]  # None: no decal
        self.planes = [batch.plane if batch.surface else None for batch in self.batches]
        self.planar = any(plane is not None for plane in self.planes) and len(self.batches) > 1
        boxes = [box_floats(batch) for batch in self.batches]
        count = len(self.batches)
        # Each box's 8 corners, x, y, z as float32 (what a glm.vec4 of them holds), 8 rows a batch.
        rows = np.zeros((count * 8, 3), np.float32)
        for i, box in enumerate(boxes):
            if box is not None:
                lo, hi = box
                rows[8 * i:8 * i + 8] = [(x, y, z) for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                                         for z in (lo[2], hi[2])]
        self.corner_columns = (rows[:, 0:1], rows[:, 1:2], rows[:, 2:3])
        self.boxed = np.array([box is not None for box in boxes], bool)
        self.corners = [None if box is None else [glm.vec4(*corner, 1.0) for corner in rows[8 * i:8 * i + 8].tolist()]
                        for i, box in enumerate(boxes)]
        self.sides = [None if plane is None else [0 if j == i else _side(plane, boxes[j], self.centres[j])
                                                  for j in range(count)]
                      for i, plane in enumerate(self.planes)] if self.planar else None
        self.planar_at = [i for i, plane in enumerate(self.planes) if plane is not None] if self.planar else []
        self.splits: dict[int, tuple[View, SlotSplit]] = {}

    def matches(self, batches: list[InstanceBatch]) -> bool:
        """Whether ``batches`` are still those this was worked out for, with the same planes,
        instances (``InstanceBatch.uploads``: rows sent or measured since) and variants."""
        return len(batches) == len(self.batches) and all(
            a is b and (b.plane if b.surface else None) is plane and b.uploads == state[0] and b.count == state[1]
            and b.variants == state[2]
            for a, b, plane, state in zip(batches, self.batches, self.planes, self.states, strict=True))

    def back_to_front(self, eye: glm.vec3) -> list[int]:
        """The batches' indices by their centres' distance from ``eye``, the farthest first;
        decals' cut meshes before all else (each lies on an opaque surface, so whatever glass
        covers it on screen is in front of it, wherever the boxes' centres are), by their
        ``Decal.order`` (a higher one blended over a lower), then the farthest first."""
        centres, decals = self.centres, self.decals
        return sorted(range(len(centres)), key=lambda k: (decals[k] is None, decals[k] or 0,
                                                           -glm.distance(centres[k], eye)))


def box_floats(batch: InstanceBatch) -> tuple[list[float], list[float]] | None:
    """``batch``'s world box as two lists of floats; None: empty or not measured yet."""
    box = batch.box
    if box is None:
        return None
    lo, hi = box[0].tolist(), box[1].tolist()
    return None if lo[0] != lo[0] else (lo, hi)


def back_to_front(batches: list[InstanceBatch], eye: glm.vec3, view: View | None = None,
                   geometry: SlotGeometry | None = None) -> list:
    """Transparent batches in the order they blend, the farthest first: by their instances'
    centre, except where a see-through surface's plane (water, a see-through mirror or
    portal: ``InstanceBatch.plane``) says which of two is in front (``slot_order``), so a
    pane standing on a pond blends over it and a pane under it under it, wherever the
    pond's centre is.  ``view``: only batches whose boxes overlap on its screen are ordered
    against each other (None: all are, as from a probe's centre for six faces).
    ``geometry``: ``batches``' (``SlotGeometry``), else worked out here."""
    if len(batches) < 2:
        return list(batches)
    geometry = geometry or SlotGeometry(batches)
    ordered = geometry.back_to_front(eye)
    if geometry.planar:
        # A few batches: every pair first (the view's screen only drops edges: where that
        # keeps the centres' order, so does the screen's, and no rectangle is worked out).
        order = slot_order(geometry, ordered, eye, None).order \
            if view is None or len(ordered) <= FEW_BATCHES else None
        if view is not None and (order is None or any(i != at for at, i in enumerate(order))):
            order = slot_order(geometry, ordered, eye, view).order
        ordered = [ordered[i] for i in order]
    return [geometry.batches[k] for k in ordered]


# Up to this many batches in a slot, its order is worked out pair by pair in Python (what a
# numpy call costs, about a microsecond, a few pairs cost), and a view orders every pair
# first, working out its screen rectangles only where that answer may differ (split_slot);
# more, in arrays (SlotOrder).  A view's split, on the glass_N benchmark's views (1 pond and
# N panes), interleaved, pairwise against arrays: 9 batches 27 / 35 us, 11: 34 / 35, 13:
# 40 / 37, 17: 53 / 45, 51: 231 / 89, 101: 893 / 176.
FEW_BATCHES = 10
# How far (m) a box may reach past a plane and still count as on one side of it: what
# float32 corners of a batch lying on the plane (a mirror's own quad) are off by.
PLANE_EPS = 1e-4


def _side(plane: glm.vec4, box: tuple[list[float], list[float]] | None, centre: glm.vec3) -> int:
    """Which side of ``plane`` a batch's world ``box`` lies on: 1 (where its normal points)
    or -1 wholly, else the side of its ``centre`` (a pane standing in the water: by where
    most of it is), 0 on the plane (coplanar, or no box and the centre on it)."""
    n = glm.vec3(plane)
    if box is not None:
        lo, hi = box
        low = high = float(plane.w)
        for axis in range(3):
            a, b = n[axis] * lo[axis], n[axis] * hi[axis]
            low += a if a < b else b
            high += b if a < b else a
        if low > -PLANE_EPS and high > PLANE_EPS:
            return 1
        if high < PLANE_EPS and low < -PLANE_EPS:
            return -1
        if high - low < 2.0 * PLANE_EPS:
            return 0  # on the plane: no side
    d = glm.dot(n, centre) + plane.w
    return 1 if d > PLANE_EPS else -1 if d < -PLANE_EPS else 0


def screen_rect(corners: list[glm.vec4] | None, view_proj: glm.mat4) -> tuple[float, float, float, float] | None:
    """The rectangle (NDC x0, y0, x1, y1) holding a batch's world box (its ``corners``) on
    a view's screen; None where a corner is at or behind the eye, or there is no box (the
    whole screen, conservatively)."""
    if corners is None:
        return None
    xs, ys = [], []
    for corner in corners:
        clip = view_proj * corner
        if clip.w <= 1e-6:
            return None
        xs.append(clip.x / clip.w)
        ys.append(clip.y / clip.w)
    return min(xs), min(ys), max(xs), max(ys)


def _screen_rects(geometry: SlotGeometry, view: View, ordered: list[int]) -> tuple[list[float], ...]:
    """``screen_rect`` of every batch of ``ordered`` in one set of numpy calls: x0, y0, x1,
    y1, a list each (by position), the whole plane (-inf to inf) for None.  The corners go
    through the matrix in float32 summed pairwise as glm sums a matrix times a vector (the
    same bits), divided in float64 as there."""
    m = np.array(view.view_proj, np.float32).T  # m[c]: column c
    x, y, z = geometry.corner_columns
    clip = ((x * m[0] + y * m[1]) + (z * m[2] + m[3])).astype(np.float64)
    w = clip[:, 3:4]
    whole = (w.reshape(-1, 8).min(axis=1) <= 1e-6) | ~geometry.boxed
    xy = (clip[:, 0:2] / np.maximum(w, 1e-6)).reshape(-1, 8, 2)
    rects = np.concatenate([xy.min(axis=1), xy.max(axis=1)], axis=1)
    if whole.any():
        rects[whole] = _WHOLE_PLANE
    return tuple(rects[ordered].T.tolist())


_WHOLE_PLANE = (-math.inf, -math.inf, math.inf, math.inf)


def rects_overlap(a: tuple[float, float, float, float] | None, b: tuple[float, float, float, float] | None) -> bool:
    if a is None or b is None:
        return True
    return a[0] <= b[2] and b[0] <= a[2] and a[1] <= b[3] and b[1] <= a[3]


def slot_order(geometry: SlotGeometry, ordered: list[int], eye: glm.vec3, view: View | None) -> SlotOrder:
    """The blending order of ``ordered`` (``geometry``'s indices, farthest centre first) seen
    from ``eye``, and the graph it keeps (``SlotOrder``): the order both kinds of edge
    allow, the lowest position first among those free to go (so the centres' order where
    nothing says otherwise); where they make a cycle the planes' alone (a centre gives way
    to a plane: a pane under a pond before the pond, and the pond before a pane standing
    on it, whatever the panes' centres say); where those do too, the order breaking their
    cycles (``_topological``).  Which edges: two batches are ordered only where they can
    cover the same pixels (their boxes' rectangles on ``view``'s screen overlap; None:
    always): by a see-through surface's plane where one has it (a batch on the eye's side
    of it is in front of it; one wholly on the other side, behind: the painter's test of a
    BSP), both planes agreeing where both have one; else, or where they disagree, by
    their centres, the farther first.  A few batches (``FEW_BATCHES``): every pair in
    Python; more: in arrays, the panes' pairs only where needed (``SlotOrder``)."""
    if len(ordered) > FEW_BATCHES:
        return SlotOrder(geometry, ordered, eye, view)
    planes, centres = _slot_graph(geometry, ordered, eye, view)
    both = [a | b for a, b in zip(planes, centres, strict=True)]
    order = _topological(both)
    if order is not None:
        return _PairOrder(order, both, False)
    order = _topological(planes)
    return _PairOrder(_topological(planes, cycles=True) if order is None else order, planes, True)


def _slot_graph(geometry: SlotGeometry, ordered: list[int], eye: glm.vec3,
                view: View | None) -> tuple[list[set[int]], list[set[int]]]:
    """For each position of ``ordered`` the positions of those that must blend before it
    (``slot_order``'s edges), by planes and by centres (the second list: what gives way
    where the two make a cycle), every pair tested in turn."""
    count = len(ordered)
    planes, sides = geometry.planes, geometry.sides
    eye_side = [0 if plane is None else (1 if glm.dot(glm.vec3(plane), eye) + plane.w > 0.0 else -1)
                for plane in planes]
    rects = None
    if view is not None:
        view_proj, corners = view.view_proj, geometry.corners
        rects = [screen_rect(corners[k], view_proj) for k in ordered]
    before: list[set[int]] = [set() for _ in range(count)]
    by_centre: list[set[int]] = [set() for _ in range(count)]
    for i in range(count):
        a = ordered[i]
        plane_a = planes[a]
        rect = None if rects is None else rects[i]
        for j in range(i + 1, count):
            if rect is not None and not rects_overlap(rect, rects[j]):
                continue
            b = ordered[j]
            if plane_a is None and planes[b] is None:  # two panes: their centres
                by_centre[j].add(i)
                continue
            verdicts = set()  # True: i first (as the centres say), False: j first
            if plane_a is not None:
                side = sides[a][b]
                if side:
                    verdicts.add(side == eye_side[a])  # j on the eye's side of i: i behind it, first
            if planes[b] is not None:
                side = sides[b][a]
                if side:
                    verdicts.add(side != eye_side[b])  # i behind j's plane: i first
            if verdicts == {True}:
                before[j].add(i)
            elif verdicts == {False}:
                before[i].add(j)
            else:
                by_centre[j].add(i)
    return before, by_centre


class _PairOrder:
    """``slot_order`` of a few batches: the order, the edges it keeps (``before``: for each
    position those that must blend before it), and whether the centres gave way."""

    __slots__ = ("order", "planes_only", "_before", "_after")

    def __init__(self, order: list[int], before: list[set[int]], planes_only: bool) -> None:
        self.order, self._before, self.planes_only = order, before, planes_only
        self._after: list[list[int]] | None = None

    def before_any(self, seeds: list[int]) -> set[int]:
        """``seeds`` and every position that must blend before one of them, and before
        that, and so on."""
        before = self._before
        return _reach(seeds, lambda j: before[j])

    def torn(self, seeds: list[int], needed: set[int]) -> int:
        """How many of ``needed`` (``before_any(seeds)``), not seeds, must blend after one of
        ``seeds`` too (a path from a seed to one lies in ``needed``: all of it is before it)."""
        if self._after is None:
            self._after = [[] for _ in self._before]
            for j, names in enumerate(self._before):
                for i in names:
                    self._after[i].append(j)
        after = self._after
        return _after_seeds(seeds, needed, lambda i: after[i])


def _reach(seeds: list[int], preds: Callable[[int], Iterable[int]]) -> set[int]:
    """``seeds`` and every position ``preds`` names for one of them, and for those, and so on."""
    needed, stack = set(seeds), list(seeds)
    while stack:
        for j in preds(stack.pop()):
            if j not in needed:
                needed.add(j)
                stack.append(j)
    return needed


def _after_seeds(seeds: list[int], needed: set[int], succs: Callable[[int], Iterable[int]]) -> int:
    """How many of ``needed``, not ``seeds``, a path of ``succs`` reaches from a seed."""
    reached: set[int] = set()
    stack = list(seeds)
    while stack:
        for j in succs(stack.pop()):
            if j in needed and j not in reached:
                reached.add(j)
                stack.append(j)
    return len(reached.difference(seeds))


class SlotOrder:
    """``slot_order`` of more than a few batches: ``order`` (positions, as there),
    ``planes_only`` (the centres gave way), and what must blend before what (``before_any``,
    ``torn``), at a cost that grows with the pairs that overlap, not with every pair.  The
    screen rectangles are one set of numpy calls (``_screen_rects``); the pairs with a
    plane, the see-through surfaces' (few) x the batches, are tested each; the pairs of two
    panes (no plane) are only ever the centres' order, so where no plane puts a batch before
    one with a farther centre the order is the centres' own without them, and they are
    found only where something needs them (``_pane_edges``: a sort and sweep of the
    rectangles, and where many overlap one another only the edges that keep what reaches
    what, which is all the order and the parts depend on)."""

    __slots__ = ("order", "planes_only", "_count", "_pane", "_rects", "_plane_edges", "_centre_edges",
                 "_lists", "_pane_lists")

    def __init__(self, geometry: SlotGeometry, ordered: list[int], eye: glm.vec3, view: View | None) -> None:
        count = self._count = len(ordered)
        rects = self._rects = None if view is None else _screen_rects(geometry, view, ordered)
        pane = self._pane = [True] * count
        plane_src: list[int] = []
        plane_dst: list[int] = []
        centre_src: list[int] = []
        centre_dst: list[int] = []
        backward = False
        if geometry.planar_at:
            where = [0] * count  # each batch's position
            for at, k in enumerate(ordered):
                where[k] = at
            planes, sides = geometry.planes, geometry.sides
            for a in geometry.planar_at:
                pane[where[a]] = False
            x0, y0, x1, y1 = rects if rects is not None else (None,) * 4
            for a in geometry.planar_at:
                i = where[a]
                plane = planes[a]
                # From its plane: where the other batch lies on the eye's side, the surface first.
                eye_side = 1 if glm.dot(glm.vec3(plane), eye) + plane.w > 0.0 else -1
                own = sides[a]
                if rects is not None:
                    ax0, ay0, ax1, ay1 = x0[i], y0[i], x1[i], y1[i]
                for j, b in enumerate(ordered):
                    if j == i or (not pane[j] and j < i):  # (a pair of surfaces once)
                        continue
                    if rects is not None and not (ax0 <= x1[j] and x0[j] <= ax1 and ay0 <= y1[j] and y0[j] <= ay1):
                        continue
                    first = own[b] * eye_side  # 1: a first, -1: b first, 0: no verdict
                    if not pane[j]:  # both planes: where they disagree, no verdict
                        theirs = -sides[b][a] * (1 if glm.dot(glm.vec3(planes[b]), eye) + planes[b].w > 0.0 else -1)
                        if not first:
                            first = theirs
                        elif theirs and theirs != first:
                            first = 0
                    lo, hi = (i, j) if i < j else (j, i)
                    if not first:
                        centre_src.append(lo)
                        centre_dst.append(hi)
                    elif (first > 0) == (i < j):  # the farther by centre first
                        plane_src.append(lo)
                        plane_dst.append(hi)
                    else:
                        plane_src.append(hi)
                        plane_dst.append(lo)
                        backward = True
        self._plane_edges, self._centre_edges = (plane_src, plane_dst), (centre_src, centre_dst)
        self._lists: tuple[list[list[int]], list[list[int]]] | None = None
        self._pane_lists: tuple[list[list[int]], list[list[int]]] | None = None
        self.planes_only = False
        if not backward:  # every edge keeps the centres' order
            self.order = list(range(count))
            return
        # Those before the first a plane holds back, and those after the last a plane puts
        # first, keep their places (no path leaves the span between and comes back): the
        # order is worked out between them, of the edges there.
        low = min(j for i, j in zip(plane_src, plane_dst, strict=True) if i > j)
        high = max(i for i, j in zip(plane_src, plane_dst, strict=True) if i > j)
        src, dst = [], []
        for i, j in zip(plane_src + centre_src, plane_dst + centre_dst, strict=True):
            if low <= i <= high and low <= j <= high:
                src.append(i - low)
                dst.append(j - low)
        pane_src, pane_dst = _pane_edges(pane[low:high + 1], None if rects is None else
                                         tuple(part[low:high + 1] for part in rects))
        order = _lowest_first(high + 1 - low, src + pane_src, dst + pane_dst)
        if order is not None:
            order = [*range(low), *(low + i for i in order), *range(high + 1, count)]
        else:  # a cycle: the centres give way to the planes
            self.planes_only = True
            before: list[set[int]] = [set() for _ in range(count)]
            for i, j in zip(plane_src, plane_dst, strict=True):
                before[j].add(i)
            order = _topological(before)
            if order is None:
                order = _topological(before, cycles=True)
        self.order = order

    def _edge_lists(self, *edges: tuple[list[int], list[int]]) -> tuple[list[list[int]], list[list[int]]]:
        preds: list[list[int]] = [[] for _ in range(self._count)]
        succs: list[list[int]] = [[] for _ in range(self._count)]
        for src, dst in edges:
            for i, j in zip(src, dst, strict=True):
                preds[j].append(i)
                succs[i].append(j)
        return preds, succs

    def _neighbours(self, which: int) -> Callable[[int], list[int]]:
        """A position's edges' sources (``which`` 0) or targets (1): those with a plane,
        and a pane's with other panes (found the first time a pane asks)."""
        if self._lists is None:
            self._lists = self._edge_lists(self._plane_edges) if self.planes_only \
                else self._edge_lists(self._plane_edges, self._centre_edges)
        kept, pane = self._lists[which], self._pane
        if self.planes_only:
            return kept.__getitem__

        def neighbours(j: int) -> list[int]:
            if not pane[j]:
                return kept[j]
            if self._pane_lists is None:
                self._pane_lists = self._edge_lists(_pane_edges(pane, self._rects))
            return kept[j] + self._pane_lists[which][j]
        return neighbours

    def before_any(self, seeds: list[int]) -> set[int]:
        """``seeds`` and every position that must blend before one of them, and before
        that, and so on."""
        return _reach(seeds, self._neighbours(0))

    def torn(self, seeds: list[int], needed: set[int]) -> int:
        """As ``_PairOrder.torn``."""
        return _after_seeds(seeds, needed, self._neighbours(1))


def _pane_edges(pane: list[bool], rects: tuple | None) -> tuple[list[int], list[int]]:
    """The centres' edges between two panes (``pane``: which positions have no plane): the
    farther first, for each pair whose rectangles overlap (``rects``, by position; None:
    every pair).  Only the edges that keep what reaches what: panes that all overlap one
    another are a chain in their order, so every pane (no view), and those whose rectangle
    is the whole plane, are joined each to the next such alone, and each other pane to the
    nearest of those before and after it; the other pairs, of rectangles that overlap, are
    found by a sort and sweep along x in arrays (a broad phase's sweep and prune)."""
    panes = [i for i, is_pane in enumerate(pane) if is_pane]
    if rects is None or len(panes) < 2:
        return panes[:-1], panes[1:]
    x0, y0, x1, y1 = rects
    chain = [i for i in panes if x0[i] == -math.inf]
    some = [i for i in panes if x0[i] != -math.inf]
    src, dst = chain[:-1], chain[1:]
    if chain:
        at = 0  # of the chain, how many are before the pane
        for i in some:
            while at < len(chain) and chain[at] < i:
                at += 1
            if at:
                src.append(chain[at - 1])
                dst.append(i)
            if at < len(chain):
                src.append(i)
                dst.append(chain[at])
    if len(some) > 1:
        some_at = np.array(some)
        sx0, sy0, sx1, sy1 = (np.array(part)[some_at] for part in rects)
        by_x = np.argsort(sx0, kind="stable")
        ends = np.searchsorted(sx0[by_x], sx1[by_x], side="right")  # those starting within each one's width
        counts = ends - np.arange(1, len(some) + 1)
        a = np.repeat(np.arange(len(some)), counts)
        b = np.arange(len(a)) - np.repeat(np.cumsum(counts) - counts, counts) + a + 1
        a, b = by_x[a], by_x[b]
        keep = (sy0[a] <= sy1[b]) & (sy0[b] <= sy1[a])
        a, b = some_at[a[keep]], some_at[b[keep]]
        src += np.minimum(a, b).tolist()
        dst += np.maximum(a, b).tolist()
    return src, dst


def _lowest_first(count: int, src: list[int], dst: list[int]) -> list[int] | None:
    """The order of ``count`` positions in which each comes after its edges' sources
    (``src[k]`` before ``dst[k]``), the lowest position first among those free to go (Kahn's
    algorithm with a heap, as ``_topological``: the least such order, which depends only
    on what reaches what); None where a cycle leaves none free."""
    waiting = [0] * count
    succs: list[list[int]] = [[] for _ in range(count)]
    for i, j in zip(src, dst, strict=True):
        succs[i].append(j)
        waiting[j] += 1
    free = [i for i in range(count) if not waiting[i]]  # rising: a heap
    order: list[int] = []
    while free:
        i = heapq.heappop(free)
        order.append(i)
        for k in succs[i]:
            waiting[k] -= 1
            if not waiting[k]:
                heapq.heappush(free, k)
    return order if len(order) == count else None


def _topological(before: list[set[int]], cycles: bool = False) -> list[int] | None:
    """An order of ``len(before)`` indices in which each comes after those ``before`` names,
    the lowest index first among those free to go (so the centres' order where nothing
    says otherwise); None where a cycle leaves none free, or with ``cycles``, the lowest
    index left goes."""
    count = len(before)
    waiting = [len(names) for names in before]
    after: list[list[int]] = [[] for _ in range(count)]
    for i, names in enumerate(before):
        for j in names:
            after[j].append(i)
    free = [i for i in range(count) if not waiting[i]]  # a heap (Kahn's algorithm, the lowest first)
    placed = [False] * count
    order: list[int] = []
    while len(order) < count:
        if free:
            i = heapq.heappop(free)
            if placed[i]:
                continue  # (placed to break a cycle before it was free)
        elif cycles:
            i = placed.index(False)
        else:
            return None
        placed[i] = True
        order.append(i)
        for k in after[i]:
            waiting[k] -= 1
            if not waiting[k] and not placed[k]:
                heapq.heappush(free, k)
    return order


def see_through_surface(batch: InstanceBatch) -> bool:
    """Whether a transparent ``batch`` is a mirror or a portal (water, a see-through
    portal; ``InstanceBatch.surface``, a switched-off mirror too): a view tree's claims and
    fallbacks find its pixels by the ids it writes and its composite paints over them, so it
    is drawn before them (so is a batch drawn as a mirror or portal, or of mixed variants)."""
    if batch.surface:
        return True
    variants = batch.variants
    return variants is None or variants[2] in _SURFACE_VARIANTS


_SURFACE_VARIANTS = frozenset({_PLANAR, int(ReflectVariant.PORTAL)})


class SlotSplit(NamedTuple):
    """A tree's view's transparent slot in two (``split_slot``), and how many of the first
    part are torn between two see-through surfaces."""

    first: list    # blended with the opaque batches, before the claims
    rest: list     # blended after the levels below are composited into the view
    torn: int      # batches of ``first`` that must blend after one of its surfaces too


def split_slot(transparent: list, view: View, geometry: SlotGeometry | None = None) -> SlotSplit:
    """A tree's view's transparent slot in two, each in blending order (``back_to_front``):
    what ``draw`` blends with the opaque batches, before the view tree claims the view's
    pixels (the see-through surfaces the view draws, not its own mirror, and every batch
    that must blend before one of them: what is behind a surface and on its pixels, and so
    on back), and the rest, which ``draw_transparent`` blends after the levels below are
    composited into the view (glass in front of every surface it covers blends over their
    reflections; all of the slot where the view draws no see-through surface).
    ``geometry``: ``transparent``'s (``SlotGeometry``), else worked out here; a view's
    answer is kept in its ``splits`` for the view's second call (its ``draw_transparent``:
    a View is not changed after it is made).

    The limit of one claim a pixel: a batch that must blend before one surface and after
    another (a pane under a near pond and in front of a far see-through mirror, covering
    both on the screen) is blended before the claims, so where it covers the far surface
    it takes its pixels from its claim and blends over its own colour, not its reflection
    (the surfaces' composites would have to be drawn apart, each after what lies behind
    it); each such batch counts in ``torn`` (``RenderStats.glass_between_surfaces``).
    Likewise a see-through surface behind another shows its own colour, not its
    reflection, where the nearer one covers it."""
    geometry = geometry or SlotGeometry(transparent)
    kept = geometry.splits.get(id(view))
    if kept is not None and kept[0] is view:
        return kept[1]
    if len(geometry.splits) >= _SPLITS_KEPT:
        geometry.splits.clear()
    split = geometry.splits[id(view)] = (view, _split_now(geometry, view))
    return split[1]


# Views whose split a SlotGeometry keeps at most (a frame's trees have a few dozen; the
# dictionary is emptied when full: a view's two calls are a few passes apart).
_SPLITS_KEPT = 256


def _split_now(geometry: SlotGeometry, view: View) -> SlotSplit:
    batches = geometry.batches
    ordered = geometry.back_to_front(view.sorting_eye)
    skipped = (view.skip, view.hide)
    seeds = [i for i, k in enumerate(ordered) if geometry.see_through[k]
             and not (batches[k].count == 1 and batches[k].entity_at[0] in skipped)]
    if not seeds:
        return SlotSplit([], [batches[k] for k in ordered], 0)
    if len(ordered) == 1:
        return SlotSplit([batches[ordered[0]]], [], 0)
    # A few batches: every pair ordered first, as if all covered the same pixels; where that
    # keeps the centres' order, with both kinds of edge, and puts nothing but the surfaces
    # before the claims, so does the view's screen (a subset of the same edges), and no
    # rectangle is worked out.  (Where the centres gave way to the planes, the screen's
    # fewer edges may keep the centres' and put more before the claims.)
    slot = None
    if len(ordered) <= FEW_BATCHES:
        slot = slot_order(geometry, ordered, view.sorting_eye, None)
        needed = slot.before_any(seeds)
        if slot.planes_only or len(needed) > len(seeds) or any(i != at for at, i in enumerate(slot.order)):
            slot = None
    if slot is None:
        slot = slot_order(geometry, ordered, view.sorting_eye, view)
        needed = slot.before_any(seeds)
    torn = slot.torn(seeds, needed) if len(needed) > len(seeds) else 0
    order = slot.order
    return SlotSplit([batches[ordered[i]] for i in order if i in needed],
                     [batches[ordered[i]] for i in order if i not in needed], torn)


def slot_groups(transparent: list, views: Sequence[View],
                 geometry: SlotGeometry | None = None) -> list[tuple[list[View], list, list, int]]:
    """A batched level's ``views`` grouped by their ``split_slot`` (the same batches in
    the same order in both parts): each group's views draw their slot in one draw per
    batch (most levels are one group), with the sum of their splits' ``torn``."""
    geometry = geometry or SlotGeometry(transparent)
    groups: dict[tuple, list] = {}
    for view in views:
        first, rest, torn = split_slot(transparent, view, geometry)
        key = (tuple(map(id, first)), tuple(map(id, rest)))
        group = groups.get(key)
        if group is None:
            groups[key] = [[view], first, rest, torn]
        else:
            group[0].append(view)
            group[3] += torn
    return [tuple(group) for group in groups.values()]
