"""A level's chosen candidates as the scene pass's planned views and the tree's nodes.

The planner (``SurfaceTable.plan``) leaves a level's candidates as rows of numbers
(``LevelRows``: rectangle, scissor, fade, packed Camera block, ...); the scene pass draws
``PlannedView``s and the tree keeps ``ReflectionView``s.  ``level_nodes`` makes both for
the candidates a level chose, in one pass over its columns (one ``tolist`` a column, not a
conversion a view), and keeps what they are made of with a kept plan's candidates, so a
still camera's or a probe face's later frames make only the nodes.  The levels planned
ahead make theirs for all of them at once (``plan_ahead.ahead_columns``), with the same
columns.
"""
from __future__ import annotations

import numpy as np

from engine.render.plan_rows import BLOCK, ROW, Candidates
from engine.render.tree_walk import ReflectionView
from engine.render.view_plan import SurfaceTable
from engine.render.views import CAMERA_BLOCK_BYTES, PlannedView

# The LevelRows columns a level's nodes read (level_nodes), as whole numbers: the rectangle, mirrored, node.
NODE_COLUMNS = np.array([*range(ROW["rect"].start, ROW["rect"].stop), ROW["mirrored"].start, ROW["node"].start])
# Its int64 columns (plan_ahead.ahead_columns): the parent row, the surface row, the scissor.
INT_COLUMNS = np.array([ROW["parent"].start, ROW["surface"].start, *range(ROW["scissor"].start, ROW["scissor"].stop)])


def level_nodes(surfaces: SurfaceTable, chosen: Candidates, parents: list[ReflectionView], level: int,
                hide: int) -> tuple[list[PlannedView], list[ReflectionView]]:
    """The planned views of a level's chosen candidates (what the scene pass and the
    composite read: each with its Camera block already packed, its matrices read from the
    block only if something asks) and their tree nodes, in one pass: one ``tolist`` per
    column, not one conversion per view.  A kept plan's candidates (read-only: a still
    camera's, a probe face's) keep their views (a View is not changed after it is made)
    and what their nodes are made of, so the frames that find the plan again make only
    the nodes."""
    kept = chosen.derived.get(("nodes", hide))
    if kept is not None:  # a kept plan's, or one planned ahead: its views, and what its nodes are made of
        views, rows = kept
        return views, [ReflectionView(node, level, view, rect, state, parents[p], fade)
                       for view, (node, rect, state, p, fade) in zip(views, rows, strict=True)]
    states = surfaces.states
    size = chosen.size
    chosen.rows.finish()  # a lazy plan's cameras: those of the views chosen
    blocks = chosen.rows.data[:, BLOCK].tobytes()  # the float32 blocks' bytes (Candidates.blocks')
    step = CAMERA_BLOCK_BYTES
    columns = chosen.rows.data.take(NODE_COLUMNS, axis=1).astype(np.int64)
    views, nodes = [], []
    at = 0
    for (x0, y0, x1, y1, mirrored, node), s, p, scissor, fade in zip(  # x1, y1: negated (LEVEL_ROW)
            columns.tolist(), chosen.surface.tolist(), chosen.parent.tolist(), chosen.scissor.tolist(),
            chosen.fade.tolist(), strict=True):
        state = states[s]
        view = PlannedView(blocks[at:at + step], size, state.kind, state.entity, state.exit_plane, mirrored == 1,
                           tuple(scissor), node, state.exit_entity, hide)
        at += step
        views.append(view)
        nodes.append(ReflectionView(node, level, view, (x0, y0, -x1 - x0, -y1 - y0), state, parents[p], fade))
    if not chosen.rows.data.flags.writeable:
        chosen.derived[("nodes", hide)] = (views, [(n.index, n.rect, n.surface, p, n.fade) for n, p in
                                                   zip(nodes, chosen.parent.tolist(), strict=True)])
    return views, nodes


def parent_and_surface(candidates: Candidates) -> tuple[int, int]:
    """The parent row and surface row of a level's one candidate, as Python numbers (those
    ``plan_ahead.ahead_columns`` read already, else from its rows)."""
    found = candidates.derived.get("one")
    if found is None:
        found = candidates.derived["one"] = (int(candidates.parent[0]), int(candidates.surface[0]))
    return found
