"""End views: where the depth limits cut a view tree, a view shows its surface's image from
the previous frame instead of one more level (``EndImages``, engine/render/end_images.py,
draws and keeps the images).

This is the tree's bookkeeping for them: which surfaces may get end views this frame
(``EndSurfaces``: an end image, and a view last frame), for each view the view that saw
each surface last up its chain (``child_seers``, ``end_seers``: the image an end view
repeats is that view's, shrunk), a level's end views as nodes with the matrix to their
seer's eye and the fallbacks of the pixels their images do not hold (``end_views``), and
the main view's finished image kept for the next frame (``keep_end_images``).
"""
from __future__ import annotations

import weakref

import numpy as np

from engine.render.end_images import EndImages
from engine.render.level_nodes import level_nodes
from engine.render.plan_rows import Candidates
from engine.render.targets import LevelStack
from engine.render.tree_walk import TreeLevel, TreeWalk, fallbacks_at, seen_surfaces
from engine.render.view_plan import SurfaceTable
from engine.render.views import View


class EndSurfaces:
    """The surfaces that may get end views this frame (an end image, and a view last frame)
    and the first level where one can, for the tree whose end images are ``ends`` (None: a
    probe's tree, which draws no end views)."""

    def __init__(self, ends: EndImages | None) -> None:
        self.ends = ends
        # what ``find`` found last, and for what (table, surfaces seen, cap)
        self._cache: tuple[tuple, tuple[np.ndarray, int] | None] | None = None

    def find(self, surfaces: SurfaceTable, root: View, depth_cap: int) -> tuple[np.ndarray, int] | None:
        """The surfaces of ``surfaces`` that may get end views below ``root`` (a bool per
        surface row), and the first level where one can (None: no end views, as in a
        probe's tree, on the first frame or after a resize).  Kept while the table, the
        surfaces seen last frame and the cap are the same (a still scene: every frame)."""
        if self.ends is None or not surfaces.has_end_images or not self.ends.ready(root.size):
            return None
        seen = self.ends.seen
        key = (weakref.ref(surfaces), seen, depth_cap)  # the table named weakly: it goes with its surfaces
        cached = self._cache
        if cached is not None and cached[0][0]() is surfaces and cached[0][1:] == key[1:]:
            return cached[1]
        ends = surfaces.end_image & np.array([entity in seen for entity in surfaces.entities.tolist()], bool)
        found = (ends, int(np.minimum(surfaces.max_depth[ends], depth_cap).min()) + 1) if ends.any() else None
        self._cache = (key, found)
        return found


def child_seers(seers: list[list[int]], chosen: Candidates, parent_at: list[int]) -> list[list[int]]:
    """Each chosen view's row of seers (``end_seers``): its parent's, where its own
    surface was last seen by its parent (``parent_at``: each parent row's index in the
    tree's views).  Lists, a level's worth of copies: a few numpy calls cost more."""
    rows = []
    for p, s in zip(chosen.parent.tolist(), chosen.surface.tolist(), strict=True):
        row = seers[p].copy()
        row[s] = parent_at[p]
        rows.append(row)
    return rows


def end_seers(candidates: Candidates | None, seers: list[list[int]] | None
              ) -> tuple[Candidates | None, list[int] | None, list[tuple[int, int]]]:
    """For each end view among ``candidates`` (a pair the depth limits cut), the index in
    the tree's views of the view that saw its surface the last time up its chain (the end
    image repeats that view's image, shrunk: ``EndImages``; -1 for the other candidates),
    from ``seers`` (a row of surfaces per row of the level).  An end view whose surface
    is not up its chain (a mirror of the pair seen first at the depth limit, as in a
    ring of mirrors) has no image to repeat: it is dropped, and returned as a (parent
    row, surface row) pair, whose pixels show the fallback, as a view the limits cut
    without an end image does (``SurfaceTable.unviewed`` leaves end candidates out)."""
    if candidates is None or candidates.end is None or seers is None:
        return candidates, None, []
    ends = candidates.end.tolist()
    if not any(ends):
        return candidates, None, []
    parents, surfaces = candidates.parent.tolist(), candidates.surface.tolist()
    found = [seers[p][s] if end else -1 for p, s, end in zip(parents, surfaces, ends, strict=True)]
    kept = [i for i, (end, seer) in enumerate(zip(ends, found, strict=True)) if not end or seer >= 0]
    dropped = [(parents[i], surfaces[i]) for i, (end, seer) in enumerate(zip(ends, found, strict=True))
               if end and seer < 0]
    if len(kept) < len(found):
        if not kept:
            return None, None, dropped
        rows, box = np.array(kept, np.int64), candidates.__dict__.get("box")
        candidates, found = candidates.select(rows), [found[i] for i in kept]
        if box is not None:  # the plan's unrounded rectangles (claim_cull), kept with their rows
            candidates.__dict__["box"] = box.take(rows, axis=0)
    return candidates, found, dropped


def end_views(walk: TreeWalk, step: TreeLevel, end_rows: list[int]) -> None:
    """A level's end views (rows ``end_rows`` of its candidates): their nodes, the matrix
    to the eye of the view that saw each surface last, and their fallbacks (the pixels
    their images do not hold)."""
    candidates = step.candidates  # (all of them: their nodes as kept with them, if they are: ahead_columns)
    chosen_ends = candidates if len(end_rows) == len(candidates) else \
        candidates.select(np.asarray(end_rows, np.int64))
    step.end_views, step.ended = level_nodes(walk.surfaces, chosen_ends, walk.nodes, walk.level + 1,
                                             walk.root.hide)
    inverse_carry, views = walk.surfaces.inv_carry_glm, walk.result.views
    step.end_matrices = [views[walk.end_seers[i]].view.view * inverse_carry[s] for i, s in
                         zip(end_rows, chosen_ends.surface.tolist(), strict=True)]
    walk.result.end_views.extend(step.ended)
    fallbacks_at(walk.fallbacks, walk.level, walk.surfaces).add(
        walk.nodes, chosen_ends.parent, chosen_ends.surface, end=[node.index for node in step.ended])


def keep_end_images(ends: EndImages | None, walk: TreeWalk, levels: LevelStack, check_history: bool) -> None:
    """The main view's image kept in ``ends`` for next frame's end views, with the surfaces
    it shows (an unseen view's may well not be in it; a candidate known empty is no view, so
    a surface only such candidates saw is not kept as shown, as in exact visibility), and
    compared with the history where ``check_history`` (the reflect stage's still frame)."""
    if ends is None:
        return
    if walk.surfaces.has_end_images:
        result = walk.result
        ends.keep(levels[0], walk.root, seen_surfaces(result),
                       compare=check_history and bool(result.end_views))
    else:
        ends.forget()
