"""Planning a reflection level in arrays: which (parent view x surface) pairs get a view,
where on screen, and each view's camera, for all pairs of a level at once.

A view tree level is planned in a fixed number of numpy operations whatever its number of
views: the parents of a level are rows of arrays (``LevelRows``; the rows' layouts are in
``engine/render/plan_rows.py``), every mirror and portal is a row of ``SurfaceTable``, and
``SurfaceTable.cull`` and ``SurfaceTable.plan`` work on (parents x surfaces) blocks.  Per
view, only what the draws need is made in Python (a ``View`` holding its packed camera
block).  This is the one planner, for levels of every size (``tests/test_view_plan.py`` holds
its cameras to glm's, worked out one view at a time).  What it costs at a level of one
or two views is its numpy calls (in a frame each costs 1-3 us, a call of a kind not made for
a while the most) and the views of arrays they read and write (a view costs about what a
small call does), so the work is laid out to need few of both: each view's row holds every
matrix its children and the cull read (``x``: carried through a surface by two products, the
oblique near plane a scalar from them), what does not depend on the camera (the Camera
block's projection, viewport, clip plane and ids; the exit row, mask, winding) is gathered
per (parent, surface) in one ``take`` from rows kept by the number of the parents' ids (a
column of every row, ``plan_rows.IDS``: no look-up a parent), a candidate is one row, and the
cull's and the plan's arrays and views are made once per count of parents or views
(``CullWork``, ``PlanWork``, kept with the other scratch in
``engine/render/plan_scratch.py``) and written with ``out=``: about 44 calls a level (13 of
them the cull's), 4 of them products, where the first array planner took about 72 and made a
view or a new array for most (measured warm, a level of one view: about 31 us, against 53
for that planner and 20 for the glm one it replaced; of three or four views: 38 against 62
and 46-74).  A call costs least on operands of one shape and dtype: a broadcast operand, a
scalar one, a strided or converting output or ``take(out=)`` each cost about as much again
(measured), so twos and epsilons are arrays and gathers are ``take`` then a copy.  Below
the first level, most candidates are claims that turn out empty (16 mirrors: 60 and 87
candidates for 16 and 9 views), so the view tree plans those levels lazily
(``SurfaceTable.plan(lazy=True)``): their cameras, about 25 calls, are worked out for the
views chosen (``LevelRows.finish``), and not at all for a level where none is.

Conventions: matrices here are numpy (..., 4, 4) arrays in the usual row-major math
layout (``M @ x``); glm's and GL's are column-major, so they are transposed at the edges.
"""
from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import numpy as np
from pyglm import glm

from components.limits import VIEW_MIRROR, VIEW_PORTAL
from components.visibility import visibility_code
from engine.render.plan_rows import (
    _PARENT,
    _SURFACE,
    BLOCK,
    CAMERA_CLIP,
    CAMERA_VIEWPORT,
    CLASS_OF,
    CLIP,
    EXIT_PLANE,
    EYE_ROW,
    GRID_PARENT,
    GRID_PART,
    GRID_WIDTH,
    ID_HIDE,
    ID_MASK,
    ID_SKIP,
    IDS,
    IDS_OF,
    IDS_PART,
    MATRICES,
    NEG_EXIT_PLANE,
    NODE,
    OPS0,
    OPS1,
    RECT,
    SCALE,
    SCISSOR,
    SIGNS,
    SURFACE_WIDTH,
    X_COLUMNS,
    Candidates,
    LevelRows,
    cull_rows,
    ids_classes,
    ids_number,
    x0_rows,
    x1_rows,
)
from engine.render.plan_scratch import (
    PLAN_WORK_KEPT,
    ChildTable,
    CullWork,
    PlanBuffers,
    PlanWork,
    RootRows,
    kept_root_rows,
    kept_work,
    node_numbers,
)
from engine.render.views import CAMERA_FLOATS, View
from engine.rules.visibility_rules import KINDS_BUT_DIRECT, drawn_in

if TYPE_CHECKING:  # the surfaces stage's records (engine/resources.py): read here by their fields
    from engine.resources import SurfaceState


def _mat(matrix: glm.mat4) -> np.ndarray:
    """A glm matrix as a row-major numpy one."""
    return np.frombuffer(matrix.to_bytes(), np.float32).reshape(4, 4).T.astype(np.float64)


_NONE = np.zeros(0, np.int64)
_NO_RECTS = np.zeros((0, 4))
_NEVER = (1e30, 2e30, 1e30, 2e30)  # fade starts no distance or angle reaches
# The hidden entity's uint32 in a row of ``SurfaceTable._child_ids`` (its Camera block's ids)
_HIDE_WORD = CAMERA_FLOATS["skip"].start + ID_HIDE
# A rectangle as the cull keeps it (x0, y0, -x1, -y1, ``SIGNS``): what makes it x, y, w, h.
_TO_SCISSOR = np.array([[1, 0, -1, 0], [0, 1, 0, -1], [0, 0, -1, 0], [0, 0, 0, -1]], np.float64)
_MIN, _MAX = np.minimum.reduce, np.maximum.reduce

# How many level plans a SurfaceTable keeps (SurfaceTable.plan): a frame's main tree and a
# probe's six faces, a few levels each, with room for a second probe.
PLANS_KEPT = 96


class SurfaceTable:
    """Every mirror and portal as arrays, so one level of views culls them all, and plans
    the views it keeps, with a few numpy operations."""

    def __init__(self, states: list[SurfaceState]) -> None:
        self.states = states
        count = len(states)
        self.planes = np.array([tuple(s.plane) for s in states], np.float64).reshape(count, 4)
        # Corner rows padded to 8 per surface (a portal has 4) by repeating its first corner.
        self.corners = np.zeros((count, 8, 4))
        for i, state in enumerate(states):
            rows = state.corners
            self.corners[i] = np.concatenate([rows, np.repeat(rows[:1], 8 - len(rows), axis=0)])
        self.enabled = np.array([s.enabled for s in states], bool)
        self.max_depth = np.array([s.max_depth for s in states], np.int64)
        self.entities = np.array([s.entity for s in states], np.int64)
        self.entity_list = self.entities.tolist()
        self.deepest = int(self.max_depth[self.enabled].max()) if self.enabled.any() else 0
        # What carries a parent's camera through each surface (a reflection, or the portal pair).
        self.carry = np.array([_mat(s.carry) for s in states]).reshape(count, 4, 4)
        self.inv_carry = np.linalg.inv(self.carry) if count else self.carry
        self.exit_planes = np.array([tuple(s.exit_plane) for s in states], np.float64).reshape(count, 4)
        self.exit_entities = np.array([s.exit_entity for s in states], np.int64)
        row_of: dict[int, int] = {}
        for i, entity in enumerate(self.entity_list):
            row_of.setdefault(entity, i)
        # The row of the surface each view through a surface looks out of (a mirror: itself, a
        # water's side its own row; a portal: its partner; -1: not in the table), which that
        # view cannot see.  (The other side of a water it looks out of lies on its clip plane
        # and is not drawn in it: ``ID_SKIP`` is the entity.)
        self.exit_rows = np.array([i if e == entity else row_of.get(e, -1) for i, (e, entity) in enumerate(
            zip(self.exit_entities.tolist(), self.entity_list, strict=True))], np.int64)
        # Each row's other side (a water's underside for its top and the top for its underside,
        # -1: none): a view that looks out of one side of a water cannot see the other either,
        # which lies on its clip plane (without it each water's reflection planned a view of
        # its own underside, empty, every frame: with predicted visibility drawn whole).
        rows_of: dict[int, list[int]] = {}
        for i, entity in enumerate(self.entity_list):
            rows_of.setdefault(entity, []).append(i)
        self.other_side = np.array([next((j for j in rows_of[entity] if j != i), -1)
                                    for i, entity in enumerate(self.entity_list)], np.int64)
        self.is_mirror = np.array([s.kind == "mirror" for s in states], bool)
        # The surfaces that show a fallback (the probe's or the sky's reflection, drawn by the
        # composite) where they are seen without a view of their own: every mirror, switched
        # off or not, and every enabled portal (a closed one keeps its closed look).
        self.falls_back = self.is_mirror | self.enabled
        # The kind a view through each surface gains, and the layers each shows (a view shows
        # the layers every surface of its chain shows).
        self.kind_bit = np.where(self.is_mirror, VIEW_MIRROR, VIEW_PORTAL).astype(np.int64)
        self.layers = np.array([s.layers for s in states], np.int64)
        # Where each surface itself is drawn (its entity's Visibility, as the scene shaders
        # read it): a view that does not draw it gives it no pixels, so no candidate.
        self.drawn = np.array([s.drawn for s in states], np.int64)
        self._drawn_in: dict[int, np.ndarray | None] = {}
        self.scale = np.array([s.resolution_scale for s in states], np.float64)
        self.priority = np.array([s.priority for s in states], np.int64)
        self.end_image = self._end_images(states)
        self.has_end_images = bool(self.end_image.any())
        # Fades (Mirror.fade_distance, fade_angle): start and end of each, and each surface's
        # bounding sphere; a surface without fades never fades.
        self.fades = [s.fade for s in states]
        self.fading = any(f is not None for f in self.fades)
        if self.fading:
            self.fade = np.array([f if f is not None else _NEVER for f in self.fades], np.float64)
            self.centres = self.corners[:, :, :3].mean(axis=1)
            self.radii = np.linalg.norm(self.corners[:, :, :3] - self.centres[:, None, :], axis=2).max(axis=1)
        # What the planner reads per level, packed once while the surfaces stand still (the
        # table is made again when one changes), so a level gathers each surface's part in
        # one operation: the distinct corners as the columns of one product per corner
        # (a flat mirror's 8 box corners are 4 twice over: the extremes of a set do not
        # change when its repeats go), ...
        distinct = [np.unique(c, axis=0) for c in self.corners]
        self.corner_count = max((len(c) for c in distinct), default=1)
        # corner c of every surface: a 4 x S block; then the planes (the facing values' columns)
        self.corner_columns = np.zeros((self.corner_count + 1, 4, count))
        for i, c in enumerate(distinct):
            self.corner_columns[:-1, :, i] = np.concatenate([c, np.repeat(c[:1], self.corner_count - len(c), axis=0)])
        self.corner_columns[-1] = self.planes.T
        self.planes_t = np.ascontiguousarray(self.planes.T)
        # ... and each surface's part of its views' rows (``SURFACE_ROW``): the blocks two
        # products multiply a parent's ``x`` by (``LEVEL_ROW``), the plane its views look out
        # of, its resolution scale.
        self.float_rows = np.zeros((count, SURFACE_WIDTH))
        self.float_rows[:, OPS0] = self.inv_carry.reshape(count, 16)
        ops = self.float_rows[:, OPS1].reshape(count, 4, 5)
        ops[:, :, 0:4] = self.carry.transpose(0, 2, 1)
        ops[:, :, 4] = np.einsum("sji,sj->si", self.carry, self.exit_planes)  # carry^T e
        self.float_rows[:, EXIT_PLANE] = self.exit_planes
        self.float_rows[:, NEG_EXIT_PLANE] = -self.exit_planes
        self.float_rows[:, SCALE] = self.scale
        self.keep = visibility_code(KINDS_BUT_DIRECT, self.layers)  # the mask bits a view through it keeps
        self._depths: dict[tuple[int, int], tuple[np.ndarray, np.ndarray, list[bool], bool]] = {}
        self._biases: dict[tuple, tuple[np.ndarray | None, list]] = {}  # _bias_rows' tables, by depth, cap, ends
        self._bias_tables: dict[bytes, list] = {}  # [allowed, class rows]: _bias_rows', by the surfaces allowed
        self._exit_columns = np.zeros((0, 2), np.int64)  # _bias_rows' knock-out columns, by ids number
        self._row_starts: dict[tuple[int, int], np.ndarray] = {}  # _bias_rows' flat row starts, by (rows, width)
        # What plan_chain reads of each surface row as Python numbers: its views' exit row, the
        # mask bits they keep, the kind bit they gain, whether it is a mirror.
        self._chain_lists = (self.exit_rows.tolist(), self.keep.tolist(), self.kind_bit.tolist(),
                             self.is_mirror.tolist())
        self._chains: dict[tuple, tuple] = {}  # _chain_ids', by the chain and what else it reads
        self._plans: dict[tuple, tuple[np.ndarray | None, tuple[Candidates | None, int]]] = {}  # plan's, least
        # recently used first
        self._ends: dict[tuple[int, int], tuple[np.ndarray, np.ndarray, list[bool]]] = {}
        self._unviewed: dict[tuple, tuple[np.ndarray | None, tuple[np.ndarray, np.ndarray]]] = {}  # unviewed's
        self._faded: tuple | None = None  # the last cull's pairs faded out, and for what (cull)
        self._boxes: np.ndarray | None = None  # the last cull's rectangles before rounding (4 x P x S)
        self.bounds_claims = bool(self.is_mirror.any())  # boxes are kept for claim_cull (a mirror's bound its claims)
        self._last_numbers: tuple | None = None  # the last parents' rows _pair_bias read, and their ids numbers
        self._child_rows: dict[tuple, np.ndarray] = {}  # _child_row's
        self._cuts: dict[tuple, tuple[np.ndarray | None, np.ndarray, bool]] = {}  # _cut's
        self._cull_work: dict[int, CullWork] = {}  # the cull's scratch, by its count of parents
        # The last cull's parents and its work, while no cull came after it (cull: a fallback cull takes it)
        self._cull_geometry: tuple[np.ndarray, CullWork] | None = None
        self._plan_work: dict[int, PlanWork] = {}  # _plan's, by its count of views
        self._plan_buffers: dict[int, PlanBuffers] = {}  # their arrays, by capacity
        self._child_tables: dict[tuple, ChildTable] = {}  # _child_ids', by root projection and size
        # The resolution scale every surface shares (None: they differ; a level takes its largest).
        self.one_scale = float(self.scale[0]) if count and (self.scale == self.scale[0]).all() else None

    @functools.cached_property
    def inv_carry_glm(self) -> list[glm.mat4]:
        """``inv_carry``'s matrices as glm ones (an end view's matrix to its ancestor's eye
        space), made the first time a frame has end views and kept with the table."""
        return [glm.inverse(state.carry) for state in self.states]

    def _end_images(self, states: list[SurfaceState]) -> np.ndarray:
        """Which surfaces end their recursion in an image: ``end_image`` True, or "auto" for
        one of a facing pair (each in front of the other: mirrors facing each other, or a
        portal and its partner facing each other, whose views see themselves again)."""
        wanted = np.array([s.end_image is True for s in states], bool)
        auto = np.array([s.end_image == "auto" for s in states], bool)
        if not auto.any():
            return wanted
        centres = np.concatenate([self.corners[:, :, :3].mean(axis=1), np.ones((len(states), 1))], axis=1)
        in_front = centres @ self.planes.T > 1e-6           # [i, j]: i's centre in front of j's plane
        mirrors = self.is_mirror
        facing_mirrors = (in_front & in_front.T & (self.planes[:, :3] @ self.planes[:, :3].T < -0.5)
                          & mirrors[:, None] & mirrors[None, :]).any(axis=1)
        # A portal's view looks out of its partner: it sees itself when it stands in front of
        # the partner's plane and the partner in front of its own.
        partner_front = np.einsum("si,si->s", centres, self.exit_planes) > 1e-6
        index = {entity: i for i, entity in enumerate(self.entities.tolist())}
        partner_sees = np.array([self.exit_entities[i] in index and bool(in_front[index[self.exit_entities[i]], i])
                                 for i in range(len(states))], bool)
        facing_portals = ~mirrors & partner_front & partner_sees
        return wanted | (auto & (facing_mirrors | facing_portals))

    def drawn_in(self, view_mask: int) -> np.ndarray | None:
        """(S,) bool: the surfaces a view of ``view_mask`` (``View.view_mask``) draws, by the
        visibility rule (``engine.rules.visibility_rules.drawn_in``; None: all of them)."""
        found = self._drawn_in.get(view_mask, False)
        if found is False:
            found = drawn_in(self.drawn, view_mask)
            found = self._drawn_in[view_mask] = None if found.all() else found
        return found

    def _within(self, depth: int, depth_cap: int) -> tuple[np.ndarray, np.ndarray, list[bool], bool]:
        """Per surface: enabled and allowed at ``depth`` by its own limit and the cap, and
        cut there by them, the first as a list, and whether any is allowed (the same for
        every level of that depth: kept)."""
        key = (depth, depth_cap)
        found = self._depths.get(key)
        if found is None:
            cut = depth > np.minimum(self.max_depth, depth_cap)
            allowed = self.enabled & ~cut
            found = self._depths[key] = (allowed, cut, allowed.tolist(), bool(allowed.any()))
        return found

    def _with_ends(self, depth: int, depth_cap: int, ends: np.ndarray) -> tuple[np.ndarray, list[bool]]:
        """``_within``'s surfaces and those of ``ends`` (enabled), as an array and a list, kept
        while ``ends`` is the same array (the view tree keeps it while nothing changes)."""
        key = (depth, depth_cap)
        found = self._ends.get(key)
        if found is None or found[0] is not ends:
            allowed = self._within(depth, depth_cap)[0] | (self.enabled & ends)
            found = self._ends[key] = (ends, allowed, allowed.tolist())
        return found[1], found[2]

    def _cut(self, depth: int, depth_cap: int, ends: np.ndarray | None) -> tuple[np.ndarray, bool]:
        """(S,) the surfaces that ``falls_back`` but get no view at ``depth`` (cut by their
        limits or the cap, not one of ``ends``; switched off), and whether there is one: kept
        per depth, cap and ``ends`` (the same array while nothing changes)."""
        key = (depth, depth_cap, id(ends))
        found = self._cuts.get(key)
        if found is None or found[0] is not ends:
            viewable = self._within(depth, depth_cap)[0] if ends is None else \
                self._with_ends(depth, depth_cap, ends)[0]
            cut = self.falls_back & ~viewable
            if len(self._cuts) > 64:
                self._cuts.clear()
            found = self._cuts[key] = (ends, cut, bool(cut.any()))
        return found[1], found[2]

    def _new_plan_work(self, k: int) -> PlanWork:
        """A plan's scratch for ``k`` views, kept (views of the buffers of its capacity: the
        least power of two not below ``k``, at least 16, kept too)."""
        capacity = max(16, 1 << (k - 1).bit_length())
        buffers = self._plan_buffers.get(capacity)
        if buffers is None:
            buffers = self._plan_buffers[capacity] = PlanBuffers(capacity)
        work = PlanWork(k, buffers)
        if len(self._plan_work) >= PLAN_WORK_KEPT:
            del self._plan_work[next(iter(self._plan_work))]
        self._plan_work[k] = work
        return work

    def _new_cull_work(self, count: int) -> CullWork:
        """A cull's scratch for ``count`` parents of this table."""
        return CullWork(count, self.corner_count, len(self.states))

    def _pair_bias(self, data: np.ndarray, depth: int, depth_cap: int, ends: np.ndarray | None,
                   fallback: bool) -> np.ndarray:
        """(P, S): what the cull takes each (parent, surface) facing value from (its bias,
        negated: the cull keeps minus the facing value, each > 0 out): 0 where the parent
        view may see the surface at ``depth`` (enabled, within its limits or one of
        ``ends``; with ``fallback``, any surface that ``falls_back``, whatever its limits;
        and drawn by the view: the visibility rule, ``drawn_in``, a row a parent), +inf where
        not, and on the surface the view looks out of.  A function of each parent's exit row
        and mask alone, so gathered by the parents' ids numbers (``plan_rows.IDS``) from a
        table of a row per class of number, the exit row knocked out (``_bias_rows``); the
        numbers are kept for ``_child_ids``."""
        numbers = data.view(np.int64)[:, IDS]
        self._last_numbers = (data, numbers)
        return self._bias_rows(numbers, depth, depth_cap, ends, fallback)

    def _bias_rows(self, numbers: np.ndarray, depth: int, depth_cap: int, ends: np.ndarray | None,
                   fallback: bool) -> np.ndarray:
        """``_pair_bias``' rows of the ids ``numbers``: their classes' rows (``plan_rows.
        IDS_CLASS``: view mask and winding) gathered from the table of the surfaces allowed
        (the depth's, with the end images' or not, or those that fall back), then each
        parent's exit row knocked out (the surface its view looks out of, ``_exit_columns``).
        A table holds a row a class, not a number: a few rows, not as many as the surfaces
        (S rows of S were 128 MB a table at 2000 surfaces, each grown by a copy)."""
        key = (depth, depth_cap, id(ends), fallback)
        found = self._biases.get(key)
        if found is None or found[0] is not ends:
            if fallback:
                allowed = self.falls_back
            else:
                allowed = self._within(depth, depth_cap)[0] if ends is None else \
                    self._with_ends(depth, depth_cap, ends)[0]
            # Kept by the surfaces allowed, whatever array says so: the end images' mask is
            # made anew whenever the surfaces they show change.
            table = self._bias_tables.get(allowed.tobytes())
            if table is None:
                if len(self._bias_tables) > 64:
                    self._bias_tables.clear()
                table = self._bias_tables[allowed.tobytes()] = [allowed, np.zeros((0, len(self.states) + 1))]
            if len(self._biases) > 256:
                self._biases.clear()
            found = self._biases[key] = (ends, table)
        table = found[1]
        try:
            rows = table[1].take(ids_classes().take(numbers), axis=0)
            columns = self._exit_columns.take(numbers, axis=0)
        except IndexError:  # numbers or classes first seen since: their rows and columns join
            table[1] = self._more_bias(table[0], table[1])
            if len(self._exit_columns) < len(IDS_OF):
                self._exit_columns = self._more_exit_columns()
            rows = table[1].take(ids_classes().take(numbers), axis=0)
            columns = self._exit_columns.take(numbers, axis=0)
        width = rows.shape[1]
        starts = self._row_starts.get((len(numbers), width))
        if starts is None:
            if len(self._row_starts) > 256:
                self._row_starts.clear()
            starts = self._row_starts[(len(numbers), width)] = np.arange(0, len(numbers) * width, width).reshape(-1, 1)
        rows.put(starts + columns, np.inf)
        return rows[:, :-1]

    def _more_bias(self, allowed: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """``rows`` (``_bias_rows``' table of the surfaces ``allowed``: a row an ids class, the
        last column a spare the knock-out of a parent with no exit row writes) with the rows
        of every class given since, read-only."""
        masks = np.array([mask for mask, _ in CLASS_OF[len(rows):]], np.int64).reshape(-1, 1)
        seen = allowed & drawn_in(self.drawn, masks)  # the rule, a row a class
        more = np.zeros((len(masks), len(self.states) + 1))
        more[:, :-1] = np.where(seen, 0.0, np.inf)
        found = np.concatenate([rows, more])
        found.flags.writeable = False
        return found

    def _more_exit_columns(self) -> np.ndarray:
        """(N, 2): each ids number's exit row and that row's other side (``other_side``) as
        columns of ``_bias_rows``' tables: the surfaces its views look out of, S (the spare
        column) where none of this table's."""
        exit_rows = np.array([exit_row for exit_row, _, _ in IDS_OF], np.float64).astype(np.int64)
        surfaces = len(self.states)
        found = np.full((len(exit_rows), 2), surfaces, np.int64)
        valid = (exit_rows >= 0) & (exit_rows < surfaces)
        found[valid, 0] = exit_rows[valid]
        other = self.other_side.take(exit_rows[valid])
        found[valid, 1] = np.where(other >= 0, other, surfaces)
        found.flags.writeable = False
        return found

    def _child_ids(self, data: np.ndarray, hide: int, root_rows: RootRows, size: tuple[int, int],
                   p: np.ndarray, s: np.ndarray) -> np.ndarray:
        """(k, GRID_WIDTH) 8-byte words (int64): for each pair (p, s), what a view through
        surface s from parent row p of ``data`` holds that is not a matter of the camera,
        laid out as ``LEVEL_ROW`` from its Camera block on: the block with its projection
        (the root's, ``root_rows``: its third row is the view's own, written over), viewport
        (``size``), clip plane and ids but the node (uint32 skip, hide, view mask); then its
        exit row, view mask, winding, p, s (int64s), a fade of 1.0 and its ids number.

        Gathered in one ``take`` from a table of every ids class's rows (``_child_row``,
        S a class, in the order of the classes: ``plan_rows.IDS_CLASS``) seen with this
        projection and size (``ChildTable``), by the classes of the parents' numbers (those
        the cull's ``_pair_bias`` read): no look-up a parent; then ``hide`` written in (a
        probe's face trees each hide their own object: kept by it, the tables were as many
        as the probes)."""
        surfaces = len(self.states)
        last = self._last_numbers
        numbers = last[1] if last is not None and last[0] is data else data.view(np.int64)[:, IDS]
        table = self._child_tables.get((root_rows.key, size))
        if table is None:
            if len(self._child_tables) > 16:
                self._child_tables.clear()
            table = self._child_tables[(root_rows.key, size)] = ChildTable()
        try:
            found = table.stacked.take(self._child_at(table.offsets, numbers, p, s), axis=0)
        except IndexError:  # numbers or classes first seen since the table was made: they join it
            for kind in range(len(table.rows), len(CLASS_OF)):
                table.rows.append(self._child_row(*CLASS_OF[kind], root_rows, size))
            table.stacked = np.concatenate(table.rows)
            table.offsets = ids_classes() * surfaces
            found = table.stacked.take(self._child_at(table.offsets, numbers, p, s), axis=0)
        if len(data) > 1:
            found[:, GRID_PARENT] = p
        if hide:
            found.view(np.uint32)[:, _HIDE_WORD] = hide & 0xFFFFFFFF
        return found

    @staticmethod
    def _child_at(offsets: np.ndarray, numbers: np.ndarray, p: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Each pair's row in a ``ChildTable``: its parent's class's first row (``offsets``, by
        ids number) plus its surface (IndexError: a number the table does not know yet)."""
        if len(numbers) == 1:
            return s + int(offsets[numbers[0]])
        at = offsets.take(numbers.take(p))
        at += s
        return at

    def _child_row(self, mask: float, mirrored: float, root_rows: RootRows, size: tuple[int, int]) -> np.ndarray:
        """(S, GRID_WIDTH) int64: ``_child_ids``' rows of a parent with this view mask and
        winding (its row number 0), whatever surface it looks out of, hiding nothing (the
        caller writes its ``hide`` in).  A view's mask: the kinds of its chain, the layers
        every surface of its chain shows."""
        key = (mask, mirrored, root_rows.key, size)
        found = self._child_rows.get(key)
        if found is None:
            rows = np.zeros((len(self.states), GRID_WIDTH))
            block = rows[:, 0:BLOCK.stop - BLOCK.start].view(np.float32)
            block[:, MATRICES.start + 16:MATRICES.start + 32] = root_rows.proj_t.reshape(16)
            block[:, CAMERA_VIEWPORT] = (0.0, 0.0, *size)
            block[:, CAMERA_CLIP] = self.exit_planes
            child_mask = (int(mask) & self.keep) | self.kind_bit
            ids = block[:, CAMERA_FLOATS["skip"]].view(np.uint32)
            ids[:, ID_SKIP] = self.exit_entities & 0xFFFFFFFF
            ids[:, ID_MASK] = child_mask & 0xFFFFFFFF
            rest = rows[:, BLOCK.stop - BLOCK.start:]
            rest[:, 0] = self.exit_rows
            rest[:, 1] = child_mask
            rest[:, 2] = mirrored != self.is_mirror
            rest.view(np.int64)[:, 4] = np.arange(len(self.states))
            rest[:, 5] = 1.0
            rest.view(np.int64)[:, 6] = [ids_number(*row) for row in rest[:, 0:3].tolist()]
            if len(self._child_rows) > 1024:
                self._child_rows.clear()
            found = self._child_rows[key] = rows.view(np.int64)  # copied as integers: bit for bit
        return found

    def cull(self, parents: LevelRows, depth: int, root_proj: np.ndarray, root_size: tuple[int, int],
             depth_cap: int, ends: np.ndarray | None = None,
             fallback: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """Each (parent, surface) where the parent view can see the surface, with the screen
        rectangle where it can show: enabled and within its depth, not the surface the view
        looks out of, facing the view's eye (a mirror facing away shows nothing, as the
        "Multiple Mirrors" project notes), not wholly behind the view's clip plane, inside
        the frustum and overlapping the parent's rectangle.  ``depth`` is the level the
        views would be on.  Returns (parent rows, surface rows, rects x0 y0 -x1 -y1 (the
        signs ``LEVEL_ROW`` keeps them with)), parent major, and the fade weights of the
        pairs seen before the fades (None: no surface fades; a pair faded out, weight 0, is
        not returned).  With ``ends`` (a mask of surfaces), the pairs of those surfaces the
        depth limits cut are kept too: the end views (``engine/render/end_images.py``).
        With ``fallback`` (``unviewed``), every surface that ``falls_back`` is tested
        whatever its limits, and the pairs faded out are returned too (their weight 0).
        ``root_proj`` is the one the parents' rows were made with (their clip space).

        Every (parent x surface) pair goes through the same few array operations, the
        whole grid at once: in a frame, after the rasteriser has run, each numpy call costs
        about twice what it does in a warm loop (measured), so their number, not the pairs
        they hold, is what a level costs at these sizes.  One product takes every distinct
        corner of every surface through 14 rows per parent, kept in its ``x`` (``C P0 V``
        from its clip space): the rectangle's sides x0, y0, -x1, -y1 in pixels, a pixel
        outwards, times w, then w, six values > 0 outside each side of the frustum, minus
        the side of the parent's clip plane, the eye and a row of scratch; the surfaces'
        planes are one more "corner", so the eye's row times them gives the facing values
        in the same product.  Then one minimum over the corners gives each pair's frustum
        and clip-plane tests, and, with the sides divided by w first, its rectangle's four
        sides as minima (the same rounding rule, one pixel out then floor, for each side)."""
        parents.finish()  # (a lazy plan's rows: their cameras first)
        count, surfaces = len(parents.data), len(self.states)
        if not count or not surfaces:
            return _NONE, _NONE, _NO_RECTS, None
        if ends is None and not fallback and not self._within(depth, depth_cap)[3]:
            return _NONE, _NONE, _NO_RECTS, None  # nothing enabled may be seen this deep
        data = parents.data
        # First what needs no corners: allowed (enabled, within its depth, drawn by the view,
        # not the surface the view looks out of): a bias per pair, +inf where a surface is
        # not allowed (_pair_bias; a level where none is finds no pair, as the tests below
        # find none: no early way out, which would cost a look at every parent).
        neg_bias = self._pair_bias(data, depth, depth_cap, ends, fallback)
        # Each parent's 14 rows (kept in its ``x``), row by row (the 14 P rows row major: a
        # row's values of every parent and surface are one contiguous block below), times
        # each corner's (4, S) gives (corners, 14, P, S), so the sides are divided by w, and
        # the minima over the corners; the planes as one more corner give the facing values
        # (the eye's row times them).  None of it reads the depth or which surfaces are
        # allowed: a fallback cull (``unviewed``) of the parents the last cull tested, with
        # no cull between (the level at the depth limits: its plan's cull, then its
        # fallbacks'), takes the work it left, written over by nothing since, and only
        # tests its own bias.
        cull_work = self._cull_geometry
        self._cull_geometry = None
        if fallback and cull_work is not None and cull_work[0] is data:
            work = cull_work[1]
        else:
            work = self._cull_work.get(count) or kept_work(self._cull_work, count, self._new_cull_work)
            np.matmul(cull_rows(data), self.corner_columns, out=work.product)
            np.maximum(work.w, work.epsilon, out=work.w_safe)  # w <= 0: see straddles
            np.divide(work.sides, work.w_safe, out=work.sides)
            least = _MIN(work.corners, axis=0, out=work.least)                                  # 14 x P x S
            # x0, y0, -x1, -y1 in pixels, rounded outwards with a pixel's margin; a pair with a
            # corner behind the eye is conservative (the parent's whole rectangle).
            rects = work.rects
            if work.least_w.min() <= 1e-6:
                np.copyto(rects, -np.inf, where=least[4] <= 1e-6)
            if self.bounds_claims and not fallback:  # (for the plan's candidates)
                self._boxes = rects.copy()  # unrounded: what claim_cull bounds a claim's pixel centres by
            np.floor(rects, out=rects)  # (the pixel's margin is in the rows: each side less w)
            np.maximum(rects, data.T[RECT, :, None], out=rects)  # inside the parent's
            np.add(work.x0y0, work.x1y1, out=work.sizes)
            if not fallback:
                self._cull_geometry = (data, work)
        rects = work.rects
        # Seen: facing and allowed, not culled (every corner outside one side of the frustum,
        # or behind the clip plane; on a side counts as outside) and a rectangle with pixels
        # (x1 > x0 and y1 > y0): one maximum over the rows 4-13, written over, each < 0 to keep.
        np.subtract(neg_bias, work.facing, out=work.least_w)
        np.less(_MAX(work.tests, axis=0, out=work.worst), 0.0, out=work.seen)
        if count == 1:  # (a take costs a third of a fancy index's two arrays)
            s = work.seen[0].nonzero()[0]
            p = np.zeros(len(s), np.int64)
            rects = rects[:, 0].take(s, axis=1).T
        else:
            p, s = np.nonzero(work.seen)
            rects = rects[:, p, s].T
        if not self.fading:
            return p, s, rects, None
        fade = self.fade_weights(parents.eye[p], s)
        if fallback:
            return p, s, rects, fade
        kept = fade > 0.0  # faded out: no view at all (the weights of the pairs kept say how many went)
        # The pairs faded out, for ``unviewed`` next (their fallbacks: no second cull for them).
        self._faded = (parents.data, depth, depth_cap, ends, p[~kept], s[~kept])
        return p[kept], s[kept], rects[kept], np.where(kept, fade, 0.0)

    def unviewed(self, parents: LevelRows, depth: int, root_proj: np.ndarray, root_size: tuple[int, int],
                 depth_cap: int, ends: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The (parent, surface) pairs a level shows without a view of their own, as parent
        rows and surface rows: surfaces that ``falls_back`` seen by the parents (the cull's
        tests) but cut at ``depth`` by their limits or the cap (not an end view of ``ends``),
        switched off (a mirror), or faded out (weight 0).  Their pixels get the fallback
        (``engine/render/mirror_passes.py``).  No array work when nothing can be cut here
        and nothing fades (a level with every surface it sees within its limits)."""
        cut, cuts_any = self._cut(depth, depth_cap, ends)
        if not len(parents.data) or (not cuts_any and not self.fading):
            return _NONE, _NONE
        # Kept like the plans (``plan``): the same read-only parent rows (a still camera, a
        # probe face), known by identity, give the same pairs.
        data = parents.data
        key = None if data.flags.writeable or root_proj.flags.writeable else (
            id(data), id(root_proj), depth, depth_cap, root_size, id(ends))
        if key is not None:
            found = self._unviewed.pop(key, None)
            if found is not None and found[0][0] is data and found[0][1] is root_proj and found[0][2] is ends:
                self._unviewed[key] = found
                return found[1]
        faded = self._faded
        if not cuts_any and faded is not None and faded[0] is parents.data and faded[1:3] == (depth, depth_cap) \
                and faded[3] is ends:
            # Nothing cut here: the pairs without a view are those the plan's cull just faded out.
            pairs = (faded[4], faded[5])
        else:
            p, s, _, fade = self.cull(parents, depth, root_proj, root_size, depth_cap, ends, fallback=True)
            unviewed = cut[s] if fade is None else cut[s] | (fade <= 0.0)
            pairs = (p[unviewed], s[unviewed])
        for array_ in pairs:
            array_.flags.writeable = False  # shared by the frames that find them again
        if key is not None:
            if len(self._unviewed) >= PLANS_KEPT:
                del self._unviewed[next(iter(self._unviewed))]
            self._unviewed[key] = ((data, root_proj, ends), pairs)
        return pairs

    def fade_weights(self, eyes: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Each surface ``s`` seen from ``eyes``: the product of its distance fade (by the
        distance to its bounding sphere) and its angle fade (by the angle between its normal
        and the direction to the eye), each falling linearly from 1 at start to 0 at end."""
        to_eye = eyes[:, :3] - self.centres[s]
        distance = np.sqrt((to_eye * to_eye).sum(axis=1))
        fade = self.fade[s]
        by_distance = (fade[:, 1] - np.maximum(distance - self.radii[s], 0.0)) / (fade[:, 1] - fade[:, 0])
        cosine = (to_eye * self.planes[s, :3]).sum(axis=1) / np.maximum(distance, 1e-9)
        angle = np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))
        by_angle = (fade[:, 3] - angle) / (fade[:, 3] - fade[:, 2])
        return np.clip(by_distance, 0.0, 1.0) * np.clip(by_angle, 0.0, 1.0)

    def plan(self, parents: LevelRows, depth: int, root: View, root_proj: np.ndarray, inv_root_proj: np.ndarray,
             first_index: int, depth_cap: int, hide: int, ends: np.ndarray | None = None,
             size: tuple[int, int] | None = None, scale: float = 1.0,
             defer: bool = False, lazy: bool = False) -> tuple[Candidates | None, int]:
        """``_plan``, kept: a level's plan is a function of the table (made again when a
        surface changes) and these arguments alone, so a level planned before from the same
        parent rows (a probe face's tree, whose camera stands still; a still main camera)
        is that plan again, read-only.  The rows are known by identity, for the price of a
        dictionary look-up (a moving camera's are new every frame: bytes compared would be
        paid for nothing): read-only rows the view tree keeps while its root's camera stands
        still (``ViewTree._root_rows``), and a kept plan's candidates, read-only with the
        choices made from them (``Candidates.select``); rows that can still change are
        planned afresh.  The ``PLANS_KEPT`` plans used last are kept, each holding the
        arrays it is known by.

        ``lazy``: the candidates' cameras (their ``x`` and Camera blocks, about 25 numpy
        calls) are left to their rows' ``LevelRows.finish``, for those chosen (the view tree
        finishes the views it makes; a plan or cull from the rows finishes them first).  A
        level below the first is mostly claims that turn out empty (16 mirrors: 60 and 87
        candidates for 16 and 9 views, the deepest level's 35 for none), and a level with no
        view then costs no camera at all; the first level (one parent) is planned whole, its
        candidates mostly all views.  Not for a kept plan (its rows are read-only) nor with
        ``defer``."""
        data = parents.data
        key = None if data.flags.writeable or root_proj.flags.writeable else (
            id(data), id(root_proj), depth, first_index, depth_cap, hide, size, scale, root.size, id(ends))
        if key is not None:
            found = self._plans.pop(key, None)
            if found is not None and found[0][0] is data and found[0][1] is root_proj and found[0][2] is ends:
                self._plans[key] = found  # the most recently used last
                return found[1]
        planned = self._plan(parents, depth, root, root_proj, inv_root_proj, first_index, depth_cap, hide, ends,
                             size, scale, defer and key is None,
                             lazy and key is None and not defer and len(data) > 1)
        if key is not None:
            if planned[0] is not None:
                planned[0].freeze()
            if len(self._plans) >= PLANS_KEPT:
                del self._plans[next(iter(self._plans))]  # the least recently used
            self._plans[key] = ((data, root_proj, ends), planned)
        return planned

    def _plan(self, parents: LevelRows, depth: int, root: View, root_proj: np.ndarray, inv_root_proj: np.ndarray,
              first_index: int, depth_cap: int, hide: int, ends: np.ndarray | None = None,
              size: tuple[int, int] | None = None, scale: float = 1.0,
              defer: bool = False, lazy: bool = False) -> tuple[Candidates | None, int]:
        """The next level's candidate views from ``parents`` (level ``depth - 1``): the
        cull's pairs, each with its camera (the parent's carried through the surface: for a
        mirror its reflection, for a portal look-out x half turn x inverse(look-in), as in
        the DirectX "magic mirrors" write-up), clipped at the plane it looks out of, with
        Lengyel's oblique near plane there unless the eye is too close (then the clip
        distance alone), its claim rectangle in the level's pixels, and its packed Camera
        block (None when nothing can be seen), and how many pairs the
        fades took out.  ``ends``: those surfaces' end views too (``cull``; marked in
        ``Candidates.end``); ``size``: the level's pixels, when given; ``scale``: a factor on
        the level's resolution (the frame's pixel budget, ``ViewTree``); ``defer``: the
        Camera blocks' camera parts are left to ``finish_blocks`` (no later level's plan
        reads them).

        Like the cull, a fixed number of array operations whatever the number of views
        (about 27 after the cull's, four of them products): each candidate's parent row and
        surface row are gathered once (``take``); two products carry all of the parent's
        matrices (``x``) through the surface, and give the plane it looks out of in view
        space (p) and that plane through the inverse root projection (t), from which Lengyel's near plane is a
        scalar a view: with P0 the root projection, s = (sign p.x, sign p.y, 1, 1) and
        f = 2 / (t . s), the projection's third row is f p - P0[3], the view-projection's is
        f e - (P0 V)[3] (p V = e, the world plane), and its inverse is Sherman-Morrison's
        rank-one update of IV inv(P0), kept in ``x``.  What is not a matter of the camera
        (the block's projection, viewport, clip plane and ids; the exit row, view mask,
        winding) is gathered from ``_child_ids``.
        Everything is written where it is read next: each candidate's ``LevelRows`` row,
        its Camera block inside it."""
        p, s, rects, weights = self.cull(parents, depth, root_proj, root.size, depth_cap, ends)
        if weights is None:
            faded = 0
        else:
            faded = int((weights == 0.0).sum())
        k = len(p)
        if not k:
            return None, faded
        w = self._plan_work.get(k) or self._new_plan_work(k)
        if size is None:
            scale *= self.one_scale if self.one_scale is not None else float(self.scale.take(s).max())
            size = _level_size(root.size, scale)
        if not lazy:
            self._carry(w, parents.data, p, s)
        np.copyto(w.rect, rects)
        root_rows = kept_root_rows(root_proj)
        w.grid[...] = self._child_ids(parents.data, hide, root_rows, size, p, s)
        if weights is not None:
            w.fade[...] = weights[weights > 0.0]
        node = node_numbers(first_index, k)
        np.copyto(w.node, node)
        if size == root.size:  # whole pixels already: x, y, -(x1 + x0)... as x, y, w, h
            np.matmul(rects, _TO_SCISSOR, out=w.scissor, casting="unsafe")
        else:
            w.scissor[...] = level_rects(rects * SIGNS, root.size, size)
        if not defer and not lazy:
            self._camera_blocks(w, root_proj, root_rows.safe_distance)
        data = w.data.copy()
        end = None if ends is None else self._within(depth, depth_cap)[1].take(s)
        candidates = Candidates(LevelRows(data), size, end)
        if lazy:
            candidates.rows.pending = (self, parents.data, root_proj)
        candidates.__dict__.update(parent=p, surface=s)  # the cull's arrays: no views to make when read
        if self.bounds_claims:
            boxes = self._boxes  # (claim_cull)
            candidates.box = (boxes[:, 0].take(s, axis=1) if len(parents.data) == 1 else boxes[:, p, s]).T
        return candidates, faded

    def _carry(self, w: PlanWork, parents: np.ndarray, p: np.ndarray, s: np.ndarray) -> None:
        """The views' ``x`` in ``w`` (their rows but ``x`` and the Camera blocks' camera parts
        may be there already): each pair's parent row (of ``parents``) and surface row
        gathered, then carried through the surface by the two products, and the cull's copies
        of the eye and the clip plane."""
        w.surface[...] = self.float_rows.take(s, axis=0)  # (take with out= costs more than take and a copy)
        if len(parents) == 1:  # one parent: its row for every view (a broadcast copy, no gather)
            w.parent[...] = parents[:, X_COLUMNS]
        else:
            w.parent[...] = parents[:, X_COLUMNS].take(p, axis=0)  # the parents' matrices (no more of their rows)
        np.matmul(w.parent_x0, w.ops0, out=w.x0)
        np.matmul(w.parent_x1, w.ops1, out=w.x1)
        np.copyto(w.eye_row, w.eye)  # the cull's copy of the eye
        np.copyto(w.clip, w.neg_exit)

    def finish_rows(self, data: np.ndarray, parents: np.ndarray, root_proj: np.ndarray) -> None:
        """The cameras of a lazy plan's rows ``data`` (``plan(lazy=True)``; all its rows, or
        those a choice took), worked out in place from their parents' rows ``parents`` (the
        level above's, standing as they were) and surfaces, with the operations ``_plan``
        works out every candidate's with (row by row or elementwise: the same numbers), in
        the plan scratch of their count."""
        k = len(data)
        if not k:
            return
        w = self._plan_work.get(k) or self._new_plan_work(k)
        np.copyto(w.data, data)
        ints = data.view(np.int64)
        self._carry(w, parents, ints[:, _PARENT], ints[:, _SURFACE])
        self._camera_blocks(w, root_proj, kept_root_rows(root_proj).safe_distance)
        np.copyto(data, w.data)

    def _camera_blocks(self, w: PlanWork, root_proj: np.ndarray, safe: float) -> None:
        """The camera parts of the Camera blocks (CAMERA_DTYPE) of the views in ``w`` (their
        rows' ``x`` and nodes, their surfaces' rows), as float32 columns: each matrix
        column-major (its transpose, row by row); ``safe``: the distance from its plane
        within which a view keeps the root projection (``RootRows.safe_distance``)."""
        np.copyto(w.block_node, w.node, casting="unsafe")  # the node image's value for its pixels
        np.copyto(w.v_p0v_block, w.v_p0v, casting="same_kind")  # V, P0 V
        np.sign(w.plane_xy, out=w.signs_xy)
        f = np.vecdot(w.through, w.signs, out=w.f)
        np.divide(w.two, f, out=f)  # (an array of twos: a scalar operand costs more)
        np.multiply(w.col4, w.f_col, out=w.scaled)  # f t, f p
        if w.buffers.fourth_of is not root_proj or root_proj.flags.writeable:
            np.copyto(w.buffers.fourth, root_proj[3])  # P0[3] a row a view (a broadcast operand costs more)
            w.buffers.fourth_of = root_proj
        np.subtract(w.fp, w.fourth, out=w.proj_row, casting="same_kind")  # the third row: f p - P0[3]
        np.multiply(w.exit, w.f_col, out=w.fe)
        np.subtract(w.fe, w.p0v_row3, out=w.vp_row, casting="same_kind")  # f e - (P0 V)[3]
        # (IV P^-1)^T = (IV inv(P0))^T - b a^T, with a = IV inv(P0) e2 (the third row of the
        # kept transpose) and b = u / (1 + u . e2), u = (f p - P0[2] - P0[3]) inv(P0) = f t - e2 - e3
        # (so 1 + u . e2 = f t . e2).
        np.subtract(w.ft, w.e23, out=w.b)
        np.divide(w.b, w.ft2, out=w.b)
        np.multiply(w.b_col, w.a_row, out=w.outer)
        np.subtract(w.inv_source, w.outer, out=w.inv, casting="same_kind")
        # Too close to its plane, a view keeps the root projection (the clip distance alone).
        if min(map(abs, w.plane_w.tolist())) <= safe:
            close = np.abs(w.plane_w) <= safe
            np.copyto(w.proj_row, root_proj[2], where=close[:, None], casting="same_kind")
            np.copyto(w.vp_row, w.p0v_row2, where=close[:, None], casting="same_kind")
            np.copyto(w.inv, w.inv_source, where=close[:, None, None], casting="same_kind")
        np.copyto(w.block_eye, w.eye, casting="same_kind")

    def finish_blocks(self, levels: list[Candidates], root_proj: np.ndarray) -> None:
        """The Camera blocks of levels planned with ``defer`` (``plan``), all at once: their
        rows gathered in one plan scratch, the blocks' camera parts worked out there by one
        run of ``_camera_blocks``' operations (about 16) for all of them, not one a level,
        and copied back into each level's rows (elementwise: the same values as a level's
        own run)."""
        for candidates in levels:
            candidates.rows.finish()
        count = sum(len(candidates) for candidates in levels)
        w = self._plan_work.get(count) or self._new_plan_work(count)
        np.concatenate([candidates.rows.data for candidates in levels], out=w.data)
        w.surface[...] = self.float_rows.take(np.concatenate([candidates.surface for candidates in levels]), axis=0)
        self._camera_blocks(w, root_proj, kept_root_rows(root_proj).safe_distance)
        at = 0
        for candidates in levels:
            k = len(candidates)
            candidates.rows.data[:, BLOCK] = w.data[at:at + k, BLOCK]
            at += k

    def _chain_ids(self, ids: tuple[float, float, float], depth: int, through: tuple[int, ...], depth_cap: int,
                   ends: list[np.ndarray | None], hide: int, root_rows: RootRows,
                   size: tuple[int, int]) -> tuple[int, np.ndarray, np.ndarray]:
        """What ``plan_chain`` reads of a chain that is not a matter of the camera: how many of
        its levels may see anything (the cull's early outs), their parents' bias rows
        (``_pair_bias``'s) and their rows' camera-free part (``_child_ids``'), from the first
        parent's ``ids`` (exit row, view mask, winding) down through the surfaces ``through``.
        Kept by all of that (``ends`` by identity): a chain goes through the same surfaces
        frame after frame."""
        key = (ids, depth, through, depth_cap, tuple(map(id, ends)), hide, root_rows.key, size)
        found = self._chains.get(key)
        if found is not None and all(a is b for a, b in zip(found[0], ends, strict=True)):
            return found[1]
        exit_row, mask, mirrored = ids
        exit_rows, keep, kind_bit, is_mirror = self._chain_lists
        grids, biases = [], []
        for i, s in enumerate(through):
            level = depth + 1 + i
            if ends[i] is None and not self._within(level, depth_cap)[3]:
                break  # nothing may be seen this deep
            bias = self._bias_rows(np.array([ids_number(exit_row, mask, mirrored)]), level, depth_cap, ends[i], False)
            if not np.isfinite(bias).any():
                break  # the cull sees nothing here
            biases.append(bias[0])
            grids.append(self._child_row(mask, mirrored, root_rows, size)[s])
            exit_row, mask, mirrored = (float(exit_rows[s]), float((int(mask) & keep[s]) | kind_bit[s]),
                                        float(mirrored != is_mirror[s]))
        result = (len(biases), np.array(biases), np.array(grids))
        if hide and grids:
            result[2].view(np.uint32)[:, _HIDE_WORD] = hide & 0xFFFFFFFF
        for array_ in result[1:]:
            array_.flags.writeable = False
        if len(self._chains) > 64:
            self._chains.clear()
        self._chains[key] = (tuple(ends), result)
        return result

    @functools.cached_property
    def _chain_ops(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Each surface row's two product operands as ``_plan``'s scratch of one view holds
        them (views of its ``float_rows`` row: inv(carry), then carry^T | carry^T e)."""
        return [(self.float_rows[s:s + 1, OPS0].reshape(1, 4, 4), self.float_rows[s:s + 1, OPS1].reshape(1, 4, 5))
                for s in range(len(self.states))]

    def plan_chain(self, parents: LevelRows, depth: int, through: list[int], root: View, root_proj: np.ndarray,
                   depth_cap: int, hide: int, ends: list[np.ndarray | None], first_index: int) -> list[Candidates]:
        """The levels below ``parents`` (one view of level ``depth``: a root, or a level's one
        candidate) planned as a chain of one view a level, each through the surface
        ``through`` names (row i: level ``depth + 1 + i``'s, what the root's last render's
        levels had), numbered from ``first_index``, with ``ends`` each level's end images
        (``plan``'s): the plans ``plan`` makes one level after another (their Camera blocks
        left to ``finish_blocks``), for as many levels as each cull finds exactly the
        surface named (none where the first does not), and the last where its one
        candidate is an end view.

        A level of one view from one parent costs its ~30 numpy calls, whatever it holds (a
        portal pair at depth 8: seven levels planned ahead a frame).  Here only what one
        level's products need of the one above is done level by level: the two products
        carrying the parent's ``x`` through the surface (``_plan``'s, in its scratch of one
        view: the same operands, the same numbers), the ids its children's rows and bias
        are kept by (Python, from the kept rows), then every level's cull in one run over
        the chain's parents, as a level of that many parents (each parent row's values are
        its own: the products are row by row, the rest elementwise), its parents'
        rectangles, which each level's cull clips by and which come out of the cull above,
        being the running maximum down the chain of the rectangles it finds, and the rows'
        rectangles, scissors and nodes at once.  Needs every surface at the resolution
        scale 1 (the level is the root's size), no fades and writeable rows."""
        parents.finish()
        count = len(through)
        if count < 2 or len(parents.data) != 1 or self.fading or self.one_scale != 1.0 or \
                not parents.data.flags.writeable:
            return []
        size = root.size
        root_rows = kept_root_rows(root_proj)
        data = np.empty((count + 1, LevelRows.WIDTH))  # the parent, then a row a level
        data[0] = parents.data[0]
        ints = data.view(np.int64)
        count, biases, grids = self._chain_ids(tuple(data[0, IDS_PART].tolist()), depth, tuple(through), depth_cap,
                                               ends, hide, root_rows, size)
        if count < 2:
            return []
        # Each level's x from its parent's: _plan's two products, operands laid out as its
        # scratch of one view lays them (a row's x, a surface's row), from row to row.
        x0, x1 = x0_rows(data), x1_rows(data)
        x1_in = x1[:, :, 0:4]
        ops = self._chain_ops
        for i, s in enumerate(through[:count]):
            ops0, ops1 = ops[s]
            np.matmul(x0[i:i + 1], ops0, out=x0[i + 1:i + 2])
            np.matmul(x1_in[i:i + 1], ops1, out=x1[i + 1:i + 2])
        rows_s = np.array(through[:count], np.int64)
        below = data[1:count + 1]
        np.copyto(x0[1:count + 1, EYE_ROW], x1[1:count + 1, 7, 0:4])  # (the products do not read them)
        below[:, CLIP] = self.float_rows[rows_s][:, NEG_EXIT_PLANE]
        ints[1:count + 1, GRID_PART] = grids
        # Every level's cull at once (``cull``'s operations over the chain's parents).
        parents = data[:count]
        self._cull_geometry = None
        work = self._cull_work.get(count) or kept_work(self._cull_work, count, self._new_cull_work)
        np.matmul(cull_rows(parents), self.corner_columns, out=work.product)
        np.maximum(work.w, work.epsilon, out=work.w_safe)
        np.divide(work.sides, work.w_safe, out=work.sides)
        least = _MIN(work.corners, axis=0, out=work.least)
        rects = work.rects
        if work.least_w.min() <= 1e-6:
            np.copyto(rects, -np.inf, where=least[4] <= 1e-6)
        boxes = rects.copy() if self.bounds_claims else None
        np.floor(rects, out=rects)
        steps = np.arange(count)
        # Each parent's rectangle: the first's, then the running maximum of the rectangles the
        # levels above found for the surfaces named (each level's is its own, clipped by its parent's).
        clipped = np.concatenate([parents[0:1, RECT].T, rects[:, steps[:-1], rows_s[:-1]]], axis=1)
        np.maximum.accumulate(clipped, axis=1, out=clipped)
        np.maximum(rects, clipped[:, :, None], out=rects)
        np.subtract(biases, work.facing, out=work.least_w)
        np.add(work.x0y0, work.x1y1, out=work.sizes)
        seen = np.less(_MAX(work.tests, axis=0, out=work.worst), 0.0, out=work.seen)
        planned = 0
        for hit, many in zip(seen[steps, rows_s].tolist(), seen.sum(axis=1).tolist(), strict=True):
            if not hit or many != 1:
                break
            planned += 1
        if not planned:
            return []
        rows_s, steps = rows_s[:planned], steps[:planned]
        chosen = rects[:, steps, rows_s].T
        below = data[1:planned + 1]
        below[:, RECT] = chosen
        np.matmul(chosen, _TO_SCISSOR, out=ints[1:planned + 1, SCISSOR], casting="unsafe")
        below[:, NODE] = node_numbers(first_index, planned)
        levels = []
        zeros = np.zeros(planned, np.int64)
        for i in range(planned):
            end = None if ends[i] is None else self._within(depth + 1 + i, depth_cap)[1].take(rows_s[i:i + 1])
            candidates = Candidates(LevelRows(data[i + 1:i + 2]), size, end)
            candidates.__dict__.update(parent=zeros[i:i + 1], surface=rows_s[i:i + 1])
            if boxes is not None:
                candidates.box = boxes[:, i, rows_s[i]][None, :]
            levels.append(candidates)
            if end is not None and end.any():
                break  # (the levels below an end view are not planned ahead)
        return levels


def level_rects(rects: np.ndarray, screen: tuple[int, int], level: tuple[int, int]) -> np.ndarray:
    """Screen-pixel rectangles (x0, y0, x1, y1) as (x, y, width, height) in the pixels of a
    level of another size (rounded outwards, at least one pixel)."""
    if level == screen:
        rects = rects.astype(np.int64)  # whole pixels already
        rects[:, 2:4] -= rects[:, 0:2]
        return rects
    s = np.array(level, np.float64) / np.array(screen, np.float64)
    x0y0 = np.floor(rects[:, 0:2] * s)
    x1y1 = np.minimum(np.array(level, np.float64), np.ceil(rects[:, 2:4] * s))
    return np.concatenate([x0y0, np.maximum(1.0, x1y1 - x0y0)], axis=1).astype(np.int64)


@functools.lru_cache(maxsize=64)
def _level_size(screen: tuple[int, int], scale: float) -> tuple[int, int]:
    """A level's pixels: the root's scaled, at least one each way."""
    return max(1, round(screen[0] * scale)), max(1, round(screen[1] * scale))
