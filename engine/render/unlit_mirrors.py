"""Mirrors drawn unlit: less pixel work where a view's pixels are painted over anyway.

A mirror whose reflection (or its fallback) the view tree composites over every pixel of it
at weight 1 never shows its own shading (``shading_replaced`` says which,
``SceneOptions.unlit`` carries them), so the scene pass (``engine/render/scene_pass.py``)
draws a batch of such mirrors (``unlit_batches``) with the ``UNLIT_SURFACE`` build of
``scene.frag``: depth and ids as ever, a constant colour, no lighting (at 8 mirrors and
640x360 about 7% of the main view's shaded pixels on llvmpipe, which shades every pixel of
every 2 x 4 group it touches), except in a view whose see-through surfaces, drawn before
the composites, may blend over one of the batch's mirrors (``_UnlitViews``, made by
``UnlitBoxes.views``).

Apart from the pass because it is geometry on the CPU (boxes, planes, screen rectangles),
worked out once a pass and kept while the scene stands, with no GL call: the pass only asks
which batches a view keeps unlit."""
from __future__ import annotations

import math
from collections.abc import Iterable
from typing import TYPE_CHECKING

from pyglm import glm

from engine.core.material_slots import ReflectVariant
from engine.render.slot_order import box_floats, rects_overlap, screen_rect
from engine.render.views import View

if TYPE_CHECKING:
    from engine.render.instances import InstanceBatch
    from engine.resources import SurfaceState

_PLANAR = int(ReflectVariant.PLANAR)


def shading_replaced(mirrors: Iterable[SurfaceState], pixel_budget: bool = False) -> frozenset[int]:
    """The mirrors whose own shading no pixel of the finished frame shows, wherever a view
    tree draws them: the tree composites each one's reflection, its end view or its fallback
    (no view: cut by a budget, faded out, past the depth limits or the tree's cap, or an end
    view's pixels last frame's image does not hold) over every pixel of it a view shows,
    blending reflection x weight + own x (1 - weight) with a weight of exactly 1.  That holds
    for an enabled mirror with a reflect rate of 1, no fade (a partly faded mirror's weights
    are a quotient of floats), not water (weighted by Fresnel), drawn at the screen's
    resolution (a level drawn smaller misses pixels at the mirror's edges, whose own shading
    then shows), at any depth: since an end candidate with nothing to repeat gets the
    fallback too (ViewTree._plan), a mirror at or past its depth limits is painted over like
    any other (tests/test_unlit_mirrors.py compares rings of 8 and 16 at max_depth 1-3, end
    images on and off, with the all-lit path).  None under a pixel budget
    (``ViewBudget.pixels``: the tree decides later which levels it draws smaller).  A scene
    pass draws these mirrors' batches unlit (``SceneOptions.unlit``), with glass in front of
    them too: a view tree draws its views' glass after compositing into them
    (``ScenePass.draw_transparent``), so it blends over the reflection, never over a
    mirror's own colour; not in a view where a see-through mirror or portal (water), or
    what lies behind it, can blend over the mirror (``_UnlitViews``: those are drawn with
    the opaque batches, before the composites)."""
    if pixel_budget:
        return frozenset()
    return frozenset(state.entity for state in mirrors
                     if state.kind == "mirror" and state.enabled and state.reflect_rate == 1.0 and state.fade is None
                     and state.water is None and state.resolution_scale == 1.0)


def unlit_batches(opaque: Iterable[InstanceBatch], mirrors: frozenset[int]) -> set:
    """The batches of ``opaque`` a pass may draw unlit: those whose instances are all in
    ``mirrors`` (``SceneOptions.unlit``), worked out once a pass, not once a view; a view
    keeps of them those no transparent batch it draws before the composites can blend over
    (``_UnlitViews``)."""
    if not mirrors:
        return _NO_BATCHES
    return {batch for batch in opaque if may_be_unlit(batch) and batch.row_of.keys() <= mirrors}


class UnlitBoxes:
    """The unlit candidates' instances' boxes (``_instance_boxes``) and how far they reach
    past each see-through surface's plane (``beyond``), kept while the scene stands (the
    Gpu's ``scene_version``, given to ``views``): one a scene pass."""

    def __init__(self) -> None:
        self._boxes: dict[InstanceBatch, list | None] = {}
        self._beyond: dict[tuple, tuple] = {}  # (surface, batch) -> its plane, beyond()
        self._boxes_at = -1

    def views(self, unlit: set, version: int) -> _UnlitViews:
        """What says which of a pass's ``unlit`` candidates (``unlit_batches``) each view
        keeps (``_UnlitViews``), the boxes worked out again only when the scene's
        ``version`` is another."""
        if self._boxes_at != version:
            self._boxes.clear()
            self._beyond.clear()
            self._boxes_at = version
        return _UnlitViews(unlit, self)

    def instance_boxes(self, batch: InstanceBatch) -> list[tuple[float, ...]] | None:
        """``_instance_boxes`` of ``batch``, kept while the scene stands (``views``)."""
        boxes = self._boxes.get(batch, _UNKNOWN)
        if boxes is _UNKNOWN:
            boxes = self._boxes[batch] = _instance_boxes(batch)
        return boxes

    def beyond(self, surface: InstanceBatch, batch: InstanceBatch) -> list[tuple[float, float, float]]:
        """For each instance of ``batch``, how far its box reaches past ``surface``'s plane on
        the side its normal points to and on the other (0: not at all), and the gap between
        its box and the surface's: kept while the scene stands and the plane is the same."""
        key = (surface, batch)
        kept = self._beyond.get(key)
        if kept is None or kept[0] is not surface.plane:
            kept = self._beyond[key] = (surface.plane, _beyond(surface, batch))
        return kept[1]


class _UnlitViews:
    """Which of a pass's unlit candidates (``_unlit_batches``) each view may draw unlit
    (``keep``), given the transparent batches it blends before the composites (a tree's
    see-through surfaces and what is behind them: ``_drawn_now``, ``split_slot``): those
    no such batch can blend over.  One that does would blend over the mirror's constant
    colour, and take its pixels from the mirror's claim (its ids), so the colour would
    show.  A drawn batch covers a point of a mirror only if it is nearer on the ray from the
    eye; so, instance by instance (a ring's mirrors are one batch), a candidate stays unlit
    unless

    - for a see-through surface (planar): the instance reaches beyond the surface's plane,
      seen from the eye, and not so far from the surface's box that no ray from the eye
      could cross the plane within it (the ray to a point a depth d beyond the plane, the
      eye a height h before it, crosses it within d / (d + h) of its length of the point:
      worked out once while the scene stands, the depth and the gap, and a view's height
      and farthest distance: a few operations an instance); and then
    - the drawn batch comes nearer the eye than the instance box's farthest corner, and its
      box's screen rectangle (``screen_rect``) meets the instance box's (bounded first by
      interval arithmetic on the projection, then by its eight corners).

    A pond at the centre of a ring of mirrors, below their tops and above their feet, keeps
    them unlit in nearly every view (it turned every mirror lit, in every view, before).
    Conservative throughout (a margin wider and nearer; a box reaching behind the eye covers
    the screen), so the image is the all-lit path's, bit for bit (tests/test_unlit_mirrors.py)."""

    __slots__ = ("unlit", "boxes")

    def __init__(self, unlit: set, boxes: UnlitBoxes) -> None:
        self.unlit, self.boxes = unlit, boxes

    def keep(self, view: View, drawn: list) -> set:
        """What of ``unlit`` ``view`` may draw unlit where it blends ``drawn`` before the
        composites."""
        unlit = self.unlit
        if not unlit or not drawn:
            return unlit
        eye = view.sorting_eye
        ex, ey, ez = eye.x, eye.y, eye.z
        fronts = []  # [batch, box, the eye's height over its plane (None: no plane), rectangle, nearest]
        for batch in drawn:
            box = box_floats(batch)
            if box is None:
                continue  # empty: draws nothing
            plane = batch.plane if batch.surface and batch.count == 1 else None
            height = None
            if plane is not None:
                length = glm.length(glm.vec3(plane))
                height = (plane.x * ex + plane.y * ey + plane.z * ez + plane.w) / length if length > 0.0 else 0.0
            fronts.append([batch, box, height, _UNKNOWN, _UNKNOWN])
        if not fronts:
            return unlit
        kept = set()
        kept_boxes = self.boxes
        for batch in unlit:
            boxes = kept_boxes.instance_boxes(batch)
            if boxes is None:
                continue  # a row not measured yet: lit
            lo, hi = box_floats(batch)
            farthest = math.sqrt(sum(max(abs(lo[axis] - eye[axis]), abs(hi[axis] - eye[axis])) ** 2
                                     for axis in range(3)))
            covered = False
            for front in fronts:
                height = front[2]
                if height is None or abs(height) <= 1e-6:
                    covered = any(self._covers(front, instance, view) for instance in boxes)
                else:  # by the surface's plane first
                    side, reach = (1, height) if height > 0.0 else (0, -height)  # the depth past it, the eye's height
                    for i, past in enumerate(kept_boxes.beyond(front[0], batch)):
                        depth = past[side]  # how far the instance reaches past the plane, seen from the eye
                        if depth > 0.0 and past[2] <= farthest * depth / (depth + reach) + _DEPTH_MARGIN \
                                and self._covers(front, boxes[i], view):
                            covered = True
                            break
                if covered:
                    break
            if not covered:
                kept.add(batch)
        return kept

    def _covers(self, front: list, instance: tuple, view: View) -> bool:
        """Whether ``front`` (a drawn batch) may blend over ``instance`` (centre, half sizes):
        nearer the eye than its box's farthest corner, and their screen rectangles meeting."""
        eye = view.sorting_eye
        cx, cy, cz, hx, hy, hz = instance
        far = math.sqrt((abs(cx - eye.x) + hx) ** 2 + (abs(cy - eye.y) + hy) ** 2 + (abs(cz - eye.z) + hz) ** 2)
        if front[4] is _UNKNOWN:
            lo, hi = front[1]
            front[4] = math.sqrt(sum(max(lo[axis] - eye[axis], 0.0, eye[axis] - hi[axis]) ** 2
                                     for axis in range(3))) - _DEPTH_MARGIN
        if front[4] >= far:
            return False
        view_proj = view.view_proj
        if front[3] is _UNKNOWN:
            front[3] = _widened(screen_rect(_box_corners(front[1]), view_proj))
        rect = front[3]
        if rect is None:
            return True
        # The projection's rows (x, y, w): over a box each is row . c + row[3], give or take
        # |row| . h, exactly; x and y (their quotients by w) lie within the four quotients of
        # those ends (w above 0: the box before the eye).
        ends = []
        for r in (0, 1, 3):
            a, b, c = view_proj[0][r], view_proj[1][r], view_proj[2][r]
            middle, spread = a * cx + b * cy + c * cz + view_proj[3][r], abs(a) * hx + abs(b) * hy + abs(c) * hz
            ends.append((middle - spread, middle + spread))
        (nx0, nx1), (ny0, ny1), (d0, d1) = ends
        if d0 <= 1e-6:
            return True  # reaching behind the eye: anywhere on the screen
        if (max(nx1 / d0, nx1 / d1) < rect[0] or min(nx0 / d0, nx0 / d1) > rect[2]
                or max(ny1 / d0, ny1 / d1) < rect[1] or min(ny0 / d0, ny0 / d1) > rect[3]):
            return False
        # Then by the box's eight corners (where its depth varies, much tighter).
        corners = _box_corners(((cx - hx, cy - hy, cz - hz), (cx + hx, cy + hy, cz + hz)))
        return rects_overlap(rect, screen_rect(corners, view_proj))


_UNKNOWN = object()  # (not worked out yet)


def _beyond(surface: InstanceBatch, batch: InstanceBatch) -> list[tuple[float, float, float]]:
    """``UnlitBoxes.beyond`` worked out: each instance box's corners' distances to the
    surface's (unit) plane, the farthest on either side, and the boxes' gap."""
    plane = surface.plane
    normal = glm.vec3(plane)
    length = glm.length(normal)
    nx, ny, nz, w = (plane.x / length, plane.y / length, plane.z / length, plane.w / length) if length > 0.0 \
        else (0.0, 0.0, 0.0, 0.0)
    box = box_floats(surface)
    out = []
    for lo, hi in batch.row_boxes.tolist():
        low = high = w
        for n, a, b in ((nx, lo[0], hi[0]), (ny, lo[1], hi[1]), (nz, lo[2], hi[2])):
            low += min(n * a, n * b)
            high += max(n * a, n * b)
        gap = 0.0 if box is None else math.sqrt(sum(max(lo[axis] - box[1][axis], box[0][axis] - hi[axis], 0.0) ** 2
                                                    for axis in range(3)))
        if length == 0.0:
            low, high, gap = -math.inf, math.inf, 0.0
        out.append((max(high, 0.0), max(-low, 0.0), gap))
    return out


def _instance_boxes(batch: InstanceBatch) -> list[tuple[float, ...]] | None:
    """Each instance's world box (``InstanceBatch.row_boxes``) as its centre and half sizes
    (a hair larger: what float32 rows are off by); None where a row is not measured yet."""
    boxes = []
    for lo, hi in batch.row_boxes.tolist():
        if lo[0] != lo[0]:
            return None
        boxes.append((*((l + h) * 0.5 for l, h in zip(lo, hi, strict=True)),
                      *((h - l) * 0.5 * (1.0 + 1e-6) + 1e-6 for l, h in zip(lo, hi, strict=True))))
    return boxes


# How much nearer (m) and wider (NDC) a drawn batch counts than its box, in _UnlitViews:
# what float32 corners and a vertex's own transform may be off by.
_DEPTH_MARGIN = 1e-3
_RECT_MARGIN = 1e-3


def _widened(rect: tuple[float, float, float, float] | None) -> tuple[float, float, float, float] | None:
    if rect is None:
        return None
    return rect[0] - _RECT_MARGIN, rect[1] - _RECT_MARGIN, rect[2] + _RECT_MARGIN, rect[3] + _RECT_MARGIN


def _box_corners(box: tuple) -> list[glm.vec4]:
    lo, hi = box
    return [glm.vec4(x, y, z, 1.0) for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]


_NO_BATCHES: frozenset = frozenset()


def may_be_unlit(batch: InstanceBatch) -> bool:
    """Whether ``batch`` is drawn with an ``UNLIT_SURFACE`` build when its mirrors are
    ``shading_replaced`` (an opaque batch of mirrors' variants)."""
    variants = batch.variants
    return variants is not None and variants[2] == _PLANAR and not batch.transparent
