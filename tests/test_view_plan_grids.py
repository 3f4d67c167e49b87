"""The planner's camera-free grids (``SurfaceTable._child_ids`` and ``_pair_bias``, gathered
by the parents' ids numbers from rows kept per number): a level planned by a table that has
planned other levels before (its grids and rows found again, in another order) is bit for
bit the level a fresh table plans from the same parent rows, and a level's parents taken in
another order give the same views, each with its own parent's number."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

import engine.render.plan_rows as plan_rows
import engine.render.view_plan as view_plan
from components.limits import VIEW_MIRROR
from components.visibility import DRAWN_EVERYWHERE, visibility_code
from engine.core.reflection_math import reflection_matrix
from engine.render.views import CAMERA_FLOATS, CAMERA_IDS, View
from engine.resources import SurfaceState
from engine.rules.visibility_rules import drawn_in

# A level row's hidden entity as a uint32: its Camera block's place in the row, then the
# block's ids (View.camera_block's layout: skip, hide, view mask, node).
_HIDE_AT = plan_rows.LEVEL_ROW.fields["block"][1] // 4 + CAMERA_FLOATS["skip"].start + CAMERA_IDS.index("hide")


def _mirror(entity: int, z: float, facing: float, x: float = 0.0, layers: int = 0xFFFF,
            drawn: int = DRAWN_EVERYWHERE) -> SurfaceState:
    plane = glm.vec4(0.0, 0.0, facing, -facing * z)
    corners = np.array([(x + dx, y, z, 1.0) for dx in (-1.0, 1.0) for y in (0.0, 2.0)])
    return SurfaceState(entity, "mirror", plane, corners, None, reflection_matrix(plane), plane, entity, 4,
                        layers=layers, drawn=drawn)


def _table() -> view_plan.SurfaceTable:
    # Two facing pairs side by side (one of them shows other layers each): views through one see the other.
    return view_plan.SurfaceTable([_mirror(3, 0.0, 1.0), _mirror(4, 6.0, -1.0), _mirror(5, 0.0, 1.0, x=2.1, layers=3),
                                   _mirror(6, 6.0, -1.0, x=2.1, layers=5)])


def _levels(table: view_plan.SurfaceTable, eye: tuple[float, float, float], depth: int = 3, kept: bool = False):
    """``depth`` levels from a camera at ``eye`` looking between the pairs: each level's
    candidates (all of them grow).  ``kept``: the root's row and projection read-only, as
    the view tree keeps them for a camera that stands still (its plans are kept)."""
    proj = glm.perspective(glm.radians(70.0), 16 / 9, 0.1, 60.0)
    view = View(glm.lookAt(glm.vec3(eye), glm.vec3(1.5, 1.0, 0.0), glm.vec3(0, 1, 0)), proj, glm.vec3(eye), (320, 180))
    root_proj, inv_root_proj = view_plan._mat(proj), view_plan._mat(glm.inverse(proj))
    rows, first, levels = plan_rows.LevelRows.root(view), 1, []
    if kept:
        rows.data.flags.writeable = root_proj.flags.writeable = False
    for level in range(1, depth + 1):
        candidates, _ = table.plan(rows, level, view, root_proj, inv_root_proj, first, 8, 0)
        if candidates is None:
            break
        levels.append((rows, candidates))
        rows, first = candidates.rows, first + len(candidates)
    return view, root_proj, inv_root_proj, levels


def _parent_ids(levels) -> set[tuple[float, float]]:
    """Each level's parents' (exit row, view mask)."""
    return {tuple(row) for parents, _ in levels for row in parents.data[:, [plan_rows.ROW[name].start for name in (
        "exit_row", "view_mask")]].tolist()}


def test_a_level_from_kept_grids_is_the_level_a_fresh_table_plans():
    warm = _table()
    *_, before = _levels(warm, (1.6, 1.0, 2.5), depth=6)  # another camera first: its grids and rows are kept
    view, root_proj, inv_root_proj, levels = _levels(warm, (0.8, 1.0, 3.5), depth=6)
    assert len(levels) >= 4, [len(c) for _, c in levels]
    # Parents looking out of the same surface with other masks (through the pair that shows
    # fewer layers first, or not), one camera's and the other's: one's rows must not be
    # taken for the other's.
    seen = _parent_ids(before) | _parent_ids(levels)
    assert len({exit_row for exit_row, _ in seen}) < len(seen), seen
    fresh = _table()
    for level, (parents, candidates) in enumerate(levels, start=1):
        first = int(candidates.rows.node[0])
        again, _ = fresh._plan(parents, level, view, root_proj, inv_root_proj, first, 8, 0)
        assert np.array_equal(again.rows.data.view(np.int64), candidates.rows.data.view(np.int64)), level


def test_parents_in_another_order_give_the_same_views_with_their_own_parents():
    table = _table()
    view, root_proj, inv_root_proj, levels = _levels(table, (2.0, 0.8, 4.0))
    parents, candidates = next((p, c) for p, c in levels if len(p.data) >= 2)
    level = next(i for i, (p, _) in enumerate(levels, start=1) if p is parents)
    order = np.arange(len(parents.data))[::-1].copy()
    swapped = plan_rows.LevelRows(parents.data.take(order, axis=0))
    again, _ = table._plan(swapped, level, view, root_proj, inv_root_proj, 1, 8, 0)
    assert len(again) == len(candidates)
    # The same (parent, surface) pairs, parents numbered in the new order; the same cameras.
    want = {(int(order.tolist().index(p)), s): i for i, (p, s) in
            enumerate(zip(candidates.parent.tolist(), candidates.surface.tolist(), strict=True))}
    got = list(zip(again.parent.tolist(), again.surface.tolist(), strict=True))
    assert set(got) == set(want)
    for i, pair in enumerate(got):
        j = want[pair]
        assert np.array_equal(again.blocks[i, :76], candidates.blocks[j, :76]), pair  # all but the ids
        assert again.rows.data[i, plan_rows.ROW["view_mask"].start] == candidates.rows.data[j, plan_rows.ROW[
            "view_mask"].start]


def test_every_rows_ids_number_names_its_own_exit_row_mask_and_winding():
    """What the planner keeps of a parent by its ids (its children's camera-free rows, its
    cull bias) is gathered by the number in its row (``plan_rows.IDS``): every row's, the
    root's and each planned level's, is the number of its own exit row, view mask and
    winding (``plan_rows.IDS_OF``), and the rows planned by a table that has planned other
    levels before (its tables made for fewer numbers, then grown) are bit for bit a fresh
    table's."""
    warm = _table()
    _levels(warm, (1.6, 1.0, 2.5), depth=6)
    view, root_proj, inv_root_proj, levels = _levels(warm, (0.8, 1.0, 3.5), depth=6)
    assert len(levels) >= 4 and any(len(parents.data) >= 2 for parents, _ in levels)
    columns = [plan_rows.ROW[name].start for name in ("exit_row", "view_mask", "mirrored")]
    rows = [parents.data for parents, _ in levels] + [levels[-1][1].rows.data]
    for data in rows:
        numbers = data.view(np.int64)[:, plan_rows.IDS].tolist()
        assert [plan_rows.IDS_OF[n] for n in numbers] == [tuple(row) for row in data[:, columns].tolist()]
    assert len({n for data in rows for n in data.view(np.int64)[:, plan_rows.IDS].tolist()}) >= 3
    fresh = _table()
    for level, (parents, candidates) in enumerate(levels, start=1):
        again, _ = fresh._plan(parents, level, view, root_proj, inv_root_proj, int(candidates.rows.node[0]), 8, 0)
        assert np.array_equal(again.rows.data.view(np.int64), candidates.rows.data.view(np.int64)), level


def test_a_kept_plans_choice_is_found_again_and_so_is_its_plan():
    """A kept plan's candidates are read-only, and the choice made from them is the same
    read-only rows when made again (``Candidates.select``): the plan kept for them is found
    again by their identity (a still camera's deeper levels), and is the plan they give."""
    table = _table()
    view, root_proj, inv_root_proj, levels = _levels(table, (0.8, 1.0, 3.5), depth=2, kept=True)
    _, first = levels[0]
    assert len(first) >= 2 and not first.rows.data.flags.writeable
    keep = np.array([len(first) - 1, 0], np.int64)
    chosen = first.select(keep)
    assert chosen is first.select(keep.copy()) and not chosen.rows.data.flags.writeable
    assert np.array_equal(chosen.rows.data, first.rows.data[keep])
    planned, _ = table.plan(chosen.rows, 2, view, root_proj, inv_root_proj, 10, 8, 0)
    again, _ = table.plan(first.select(keep).rows, 2, view, root_proj, inv_root_proj, 10, 8, 0)
    assert again is planned
    fresh, _ = _table()._plan(chosen.rows, 2, view, root_proj, inv_root_proj, 10, 8, 0)
    assert np.array_equal(fresh.rows.data.view(np.int64), planned.rows.data.view(np.int64))


def test_parents_through_one_surface_with_other_masks_each_get_their_own_bias():
    """The cull's bias (``SurfaceTable._pair_bias``: which surfaces each parent may see) is
    kept a parent at a time, by the number of its ids (``_bias_rows``): parents looking
    out of the same mirror, one showing the layer a surface is drawn on and one not, each get
    their own row, whichever was seen first, alone or with the other, in either order, as
    the visibility rule says surface by surface (worked out here pair by pair in Python)."""
    on_layer_2 = _mirror(5, 0.0, 1.0, x=2.1, drawn=visibility_code(0, 1 << 2))
    states = [_mirror(3, 0.0, 1.0), _mirror(4, 6.0, -1.0), on_layer_2, _mirror(6, 6.0, -1.0, x=2.1)]
    masks = {"shows_layer_2": visibility_code(VIEW_MIRROR, 1 | 1 << 2), "not": visibility_code(VIEW_MIRROR, 1)}
    exit_row = 1  # both look out of mirror 4

    def parents(*names: str) -> np.ndarray:
        data = np.zeros((len(names), plan_rows.LevelRows.WIDTH))
        data[:, plan_rows.ROW["exit_row"].start] = exit_row
        data[:, plan_rows.ROW["view_mask"].start] = [masks[name] for name in names]
        data.view(np.int64)[:, plan_rows.IDS] = [plan_rows.ids_number(exit_row, masks[name], 0.0) for name in names]
        return data

    def wanted(names: tuple[str, ...], fallback: bool) -> np.ndarray:
        return np.array([[0.0 if (fallback or state.max_depth >= 1) and drawn_in(state.drawn, masks[name])
                          and row != exit_row else np.inf for row, state in enumerate(states)] for name in names])

    table = view_plan.SurfaceTable(states)
    assert not np.array_equal(wanted(("shows_layer_2",), False), wanted(("not",), False))  # the rows differ
    for names in (("shows_layer_2",), ("not", "shows_layer_2"), ("shows_layer_2", "not"), ("not",),
                  ("not", "not", "shows_layer_2")):
        for fallback in (False, True):
            bias = table._pair_bias(parents(*names), 1, 8, None, fallback)
            assert np.array_equal(bias, wanted(names, fallback)), (names, fallback)


@pytest.mark.parametrize("hide", [0, 4242])
def test_a_chain_is_planned_in_one_run_as_far_as_each_level_finds_the_surface_named(hide):
    """``SurfaceTable.plan_chain``: the levels below one view, each of one view through the
    surface named, planned in one run, are bit for bit the levels ``plan`` makes one after
    another (from a root's row too) (their Camera blocks finished by ``finish_blocks`` either way), with each
    level's pairs, claim boxes and nodes; the run stops at the first level whose cull does
    not find exactly the surface named (another surface, or nothing), and plans nothing
    where the first does not.  Both write the entity the tree hides (a probe's own object:
    4242) into every view's Camera block, though the rows they gather it into are kept
    whatever it is."""
    table = _table()
    view, root_proj, inv_root_proj, levels = _levels(table, (0.8, 1.0, 3.5), depth=1)
    first = levels[0][1].select(np.array([1], np.int64))  # through the second pair's near mirror
    one_at_a_time, parent = [], first
    for depth in range(2, 6):
        planned, _ = table.plan(parent.rows, depth, view, root_proj, inv_root_proj, int(parent.rows.node[-1]) + 1,
                                8, hide, defer=True)
        if planned is None:
            break
        assert len(planned) == 1
        one_at_a_time.append(planned)
        parent = planned
    through = [int(candidates.surface[0]) for candidates in one_at_a_time]
    assert len(through) == 3 and through[0] != through[1], through  # back and forth, then out of sight
    table.finish_blocks(one_at_a_time, root_proj)
    for asked, wanted in ((through, 3), (through + [through[1]], 3), (through[:2] + [through[1]], 2),
                          ([through[1]] + through[1:], 0)):
        fresh = _table()
        chain = fresh.plan_chain(first.rows, 1, asked, view, root_proj, 8, hide, [None] * len(asked),
                                 int(first.rows.node[-1]) + 1)
        assert len(chain) == wanted, (asked, len(chain))
        if chain:
            fresh.finish_blocks(chain, root_proj)
        for got, want in zip(chain, one_at_a_time, strict=False):
            assert np.array_equal(got.rows.data.view(np.int64), want.rows.data.view(np.int64))
            assert got.rows.data.view(np.uint32)[:, _HIDE_AT].tolist() == [hide] * len(got.rows.data)
            assert got.parent.tolist() == want.parent.tolist() and got.surface.tolist() == want.surface.tolist()
            assert np.array_equal(got.box, want.box) and got.size == want.size and got.end is want.end is None
    # Through the first pair's near mirror the next level sees both far mirrors: the surface
    # named is one of them, but a level of two views is no chain.
    other = levels[0][1].select(np.array([0], np.int64))
    seen, _ = table.plan(other.rows, 2, view, root_proj, inv_root_proj, 10, 8, 0)
    assert len(seen) == 2, seen.surface
    for named in seen.surface.tolist():
        assert _table().plan_chain(other.rows, 1, [named, through[0]], view, root_proj, 8, 0, [None, None], 10) == []


def test_a_lazy_plans_cameras_worked_out_when_read_are_the_eager_plans():
    """``plan(lazy=True)`` leaves its candidates' cameras (their ``x`` and their Camera
    blocks) to ``LevelRows.finish`` (the view tree finishes the views it
    chooses): the rest of each row is there at once, and a choice finished alone, the whole
    level finished, and the level planned below from the lazy rows (finished first) are bit
    for bit what the eager plan gives.  A kept plan (read-only rows) and a level of one
    parent are never lazy."""
    def table() -> view_plan.SurfaceTable:  # the pairs at other depths: each surface its own camera
        return view_plan.SurfaceTable([_mirror(3, 0.0, 1.0), _mirror(4, 6.0, -1.0), _mirror(5, 0.5, 1.0, x=2.1),
                                       _mirror(6, 6.5, -1.0, x=2.1)])

    view, root_proj, inv_root_proj, levels = _levels(table(), (0.8, 1.0, 3.5), depth=3)
    assert any(len(candidates) >= 3 and len(parents.data) >= 2 for parents, candidates in levels)
    assert any(len(set(map(tuple, parents.view.reshape(-1, 16).tolist()))) >= 2 for parents, _ in levels)
    camera = np.zeros(plan_rows.LevelRows.WIDTH, bool)
    camera[plan_rows.X_COLUMNS] = True
    camera[plan_rows.BLOCK] = True
    lazy_table = table()
    for level, (parents, eager) in enumerate(levels, start=1):
        lazy, _ = lazy_table.plan(parents, level, view, root_proj, inv_root_proj, int(eager.rows.node[0]), 8, 0,
                                  lazy=True)
        if len(parents.data) == 1:  # the first level (one parent) is planned whole
            assert lazy.rows.pending is None and np.array_equal(lazy.rows.data, eager.rows.data)
            continue
        assert lazy.rows.pending is not None
        want = eager.rows.data.view(np.int64)
        assert np.array_equal(lazy.rows.data.view(np.int64)[:, ~camera], want[:, ~camera]), level
        keep = np.arange(len(lazy))[::-2].copy()
        chosen = lazy.select(keep)
        assert chosen.rows.pending is not None
        assert np.array_equal(chosen.blocks.view(np.int32), eager.blocks[keep].view(np.int32)), level  # finished
        assert chosen.rows.pending is None and np.array_equal(chosen.rows.data.view(np.int64), want[keep])
        assert lazy.rows.pending is not None  # the choice's rows alone
        below, _ = lazy_table.plan(lazy.rows, level + 1, view, root_proj, inv_root_proj, 100, 8, 0)
        assert lazy.rows.pending is None and np.array_equal(lazy.rows.data.view(np.int64), want), level
        again, _ = table().plan(eager.rows, level + 1, view, root_proj, inv_root_proj, 100, 8, 0)
        assert (below is None) == (again is None)
        if below is not None:
            assert np.array_equal(below.rows.data.view(np.int64), again.rows.data.view(np.int64)), level
    view, root_proj, inv_root_proj, kept_levels = _levels(lazy_table, (0.8, 1.0, 3.5), depth=1, kept=True)
    parents, _ = kept_levels[0]
    kept, _ = lazy_table.plan(parents, 1, view, root_proj, inv_root_proj, 1, 8, 0, lazy=True)
    assert kept.rows.pending is None and not kept.rows.data.flags.writeable
