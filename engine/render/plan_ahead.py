"""Levels of a view tree planned ahead: below a level whose candidates all became views that
grew in the root's last render, the next levels are planned at once, back to back, before
its claims are drawn.

Exact visibility plans each level after its parent's claims and draws, and in a frame a
numpy call made among GL calls costs about half as much again as one made after another
(measured: 44 against 30 us a level of one view).  So where the root's last render made
every candidate of a level a view that grew (``TreeWalk.whole_before``), ``plan_ahead``
plans the levels below it as if that holds again, each from the rows of the one above,
and ``ViewTree._plan`` takes a level planned ahead only where its parents are those very
rows (else it plans afresh: the result is the same either way).  A chain of levels of one
view each (a facing pair) is planned in one run through the surfaces it went through
(``plan_chain``, ``SurfaceTable.plan_chain``), and the Camera blocks, nodes and claims of
the levels planned ahead are worked out for all of them at once (``ahead_columns``).
Predicted visibility plans every level before any claim anyway; there what this saves is
the level-by-level plan's own calls (a swaying portal pair at depth 8, its levels on the
lean path too: 0.76 of the frame without them, measured interleaved in one process).
"""
from __future__ import annotations

import numpy as np

from engine.render.level_nodes import INT_COLUMNS, NODE_COLUMNS
from engine.render.mirror_passes import Claims
from engine.render.plan_rows import BLOCK, ROW, Candidates, LevelRows
from engine.render.tree_visibility import level_scale
from engine.render.tree_walk import TreeWalk, ends_at
from engine.render.view_plan import SurfaceTable
from engine.render.views import CAMERA_BLOCK_BYTES, PlannedView


def plan_chain(walk: TreeWalk, depth: int, parents: LevelRows, first_index: int) -> list[Candidates]:
    """The levels below ``parents`` (one view of level ``depth``) that were a chain of one
    view a level in the root's last render (``TreeWalk.singles``; below the first, each
    grew), planned in one run through the surfaces they went through then
    (``SurfaceTable.plan_chain``: as far as each level finds the same one), each kept for
    ``ViewTree._plan`` in ``walk.ahead`` with its unviewed pairs; their Camera blocks are
    left to ``plan_ahead``'s ``finish_blocks``.  At portal depth 8 with a swaying camera, seven
    levels of ~30 numpy calls each became one run of about as many."""
    surfaces, settings, root = walk.surfaces, walk.settings, walk.root
    whole, singles = walk.whole_before, walk.singles_before
    through, level = [], depth
    while (level == depth or whole.get(level)) and singles.get(level + 1, -1) >= 0:
        level += 1
        through.append(singles[level])
    if len(through) < 2:
        return []
    ends = [ends_at(walk.ends, depth + 1 + i) for i in range(len(through))]
    levels = surfaces.plan_chain(parents, depth, through, root, walk.root_proj, settings.depth_cap, root.hide,
                                 ends, first_index)
    for i, planned in enumerate(levels):
        rows = parents if i == 0 else levels[i - 1].rows
        walk.ahead[depth + 1 + i] = (rows.data, first_index + i, 1.0, (planned, 0),
                                     surfaces.unviewed(rows, depth + 1 + i, walk.root_proj, root.size,
                                                       settings.depth_cap, ends[i]))
    return levels


def plan_ahead(walk: TreeWalk, depth: int, candidates: Candidates, coverage: dict[int, int], chains: bool,
               deferred: list[Candidates] | None = None) -> None:
    """The levels below ``depth`` planned now, back to back, as if every candidate of
    each became a view that grows (what the root's last render's levels did:
    ``TreeWalk.whole_before``), each from the rows of the one above: ``ViewTree._plan``
    takes one where its parents are those very rows (and its first index and scale are
    those it was planned with), else plans afresh; ``coverage``: the levels' for the pixel
    budget's scale (``level_scale``), ``chains``: ``ViewTree.plan_chains``.
    In a frame, a numpy call made among GL calls costs about half as much again as one
    made after another (measured: 44 against 30 us a level of one view), and exact
    visibility plans each level after its parent's claims and draws.  The pairs the
    level's parents see without a view there (``SurfaceTable.unviewed``, its fallbacks:
    a cull at the depth limit) are found with it, and the levels' Camera blocks, which
    no plan below reads, are worked out for all of them at once at the end
    (``SurfaceTable.finish_blocks``: one run of its operations, not one a level).  A
    swaying portal pair at depth 8, 32x18: about 10% off the frame.  Levels of one view
    each last render are planned as a chain in one run (``plan_chain``); ``deferred``:
    such a chain's levels, planned already (``depth`` the last's): the levels below it
    planned on from there."""
    settings, surfaces, root = walk.settings, walk.surfaces, walk.root
    whole = walk.whole_before
    if deferred is None:
        deferred = []
        if chains and len(candidates) == 1 and whole.get(depth) and \
                (candidates.end is None or not candidates.end.any()):
            deferred = plan_chain(walk, depth, candidates.rows, int(candidates.rows.node[-1]) + 1)
            if deferred:
                depth, candidates = depth + len(deferred), deferred[-1]
    else:
        deferred = list(deferred)
    while whole.get(depth) and (candidates.end is None or not candidates.end.any()):
        depth += 1
        rows, first_index = candidates.rows, int(candidates.rows.node[-1]) + 1
        scale = level_scale(walk.renderer.stats, coverage, depth)
        ends = ends_at(walk.ends, depth)
        # Blocks left to one run for the levels planned ahead where there are two or more
        # (a kept plan's rows, read-only: its plans are kept whole).
        defer = rows.data.flags.writeable and bool(deferred or whole.get(depth))
        planned = surfaces.plan(rows, depth, root, walk.root_proj, walk.inv_root_proj, first_index,
                                settings.depth_cap, root.hide, ends=ends, scale=scale, defer=defer)
        walk.ahead[depth] = (rows.data, first_index, scale, planned,
                             surfaces.unviewed(rows, depth, walk.root_proj, root.size, settings.depth_cap, ends))
        candidates = planned[0]
        if candidates is None:
            break
        if defer:
            deferred.append(candidates)
    if deferred:
        surfaces.finish_blocks(deferred, walk.root_proj)
        ahead_columns(surfaces, deferred, root.hide)


def ahead_columns(surfaces: SurfaceTable, levels: list[Candidates], hide: int) -> None:
    """What ``level_nodes`` and ``ViewTree._claim`` make of each level planned ahead (their
    rows final once their blocks are: nothing writes them after), made for all of them at
    once and kept with each (``Candidates.derived``, as for a kept plan's): the columns
    read as Python numbers in one conversion each for every level (a chain at portal
    depth 8: seven levels of one view), not each level's own few; a level of one
    candidate's straight from them, with its parent and surface rows
    (``level_nodes.parent_and_surface``), and the views of all such levels, whose Camera blocks
    the first of them to draw uploads together (``Gpu.upload_run``).  With three levels
    or more, the claims of every level
    below the first as one run (``MirrorPasses.prepare_level``'s ``run``: written to the
    GPU once, by the first of them that draws): a parent's node is its row's one level
    up (the levels planned ahead are used only where every candidate of the level above
    became a view that grew, in its rows' order)."""
    rows = np.concatenate([candidates.rows.data for candidates in levels])
    ints = rows.view(np.int64)
    blocks = rows[:, BLOCK].tobytes()
    step = CAMERA_BLOCK_BYTES
    columns = rows.take(NODE_COLUMNS, axis=1).astype(np.int64).tolist()
    numbers = ints.take(INT_COLUMNS, axis=1).tolist()
    fades = rows[:, ROW["fade"].start].tolist()
    states, entities = surfaces.states, surfaces.entity_list
    at = 0
    for candidates in levels:
        size = candidates.size
        derived = candidates.derived
        if len(candidates) == 1:  # (a chain's level: one view, its columns as they are)
            x0, y0, x1, y1, mirrored, node = columns[at]
            p, s, *scissor = numbers[at]
            state = states[s]
            derived[("nodes", hide)] = ([PlannedView(blocks[at * step:(at + 1) * step], size, state.kind,
                                                     state.entity, state.exit_plane, mirrored == 1, tuple(scissor),
                                                     node, state.exit_entity, hide)],
                                        [(node, (x0, y0, -x1 - x0, -y1 - y0), state, p, fades[at])])
            derived["claims"] = ([p], [entities[s]], [node], [scissor])
            derived["one"] = (p, s)
            at += 1
            continue
        views, nodes, claims = [], [], ([], [], [], [])
        for i in range(at, at + len(candidates)):
            x0, y0, x1, y1, mirrored, node = columns[i]  # x1, y1: negated (LEVEL_ROW)
            p, s, *scissor = numbers[i]
            state = states[s]
            views.append(PlannedView(blocks[i * step:(i + 1) * step], size, state.kind, state.entity,
                                     state.exit_plane, mirrored == 1, tuple(scissor), node, state.exit_entity,
                                     hide))
            nodes.append((node, (x0, y0, -x1 - x0, -y1 - y0), state, p, fades[i]))
            for column, value in zip(claims, (p, entities[s], node, scissor), strict=True):
                column.append(value)
        derived[("nodes", hide)] = (views, nodes)
        derived["claims"] = claims
        at += len(candidates)
    ones = [candidates.derived[("nodes", hide)][0][0] for candidates in levels if len(candidates) == 1]
    if len(ones) > 1:  # the Camera blocks of the levels of one view, in one upload (ViewTree._draw_level)
        for candidates in levels:
            if len(candidates) == 1:
                candidates.derived["view_run"] = ones
    if len(levels) > 2:  # the claims below the first level, in one run (MirrorPasses.prepare_level)
        ids, rects, starts = [], [], []
        above = 0  # the first row of the level above, in ``columns``
        for upper, candidates in zip(levels[:-1], levels[1:], strict=True):
            starts.append(len(ids))
            at = above + len(upper)
            for i in range(at, at + len(candidates)):
                p, s, *scissor = numbers[i]  # (a parent's node: its row's, one level up)
                ids.append((columns[above + p][5], entities[s], columns[i][5]))
                rects.append(scissor)
            above = at
        run = Claims(ids, rects)
        for candidates, start in zip(levels[1:], starts, strict=True):
            candidates.derived["claim_run"] = (run, start)
