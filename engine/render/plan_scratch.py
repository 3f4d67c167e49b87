"""What the planner keeps so that a level makes few arrays and views of them: the cull's and
the plan's scratch per count of parents or views (``CullWork``; ``PlanWork``, views of
``PlanBuffers``; kept by ``kept_work``), the camera-free rows of the parents' ids numbers
(``ChildTable``), each root projection's oblique near plane constants (``RootRows``) and
read-only node numbers.

A view of an array costs about what a small numpy call does (1-3 us in a frame), so each one
a level reads or writes is made once here, with its arrays, and used again by every level of
that count (``SurfaceTable.cull`` and ``SurfaceTable.plan``, ``engine/render/view_plan.py``);
the rows they are views of are laid out in ``engine/render/plan_rows.py``.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from engine.core.reflection_math import OBLIQUE_SAFE_NEARS
from engine.render.plan_rows import (
    BLOCK,
    CAMERA_EYE,
    CLIP,
    CULL,
    EXIT_PLANE,
    EYE_ROW,
    FADE,
    GRID_PART,
    GRID_WIDTH,
    ID_NODE_COLUMN,
    MATRICES,
    NEG_EXIT_PLANE,
    NODE,
    OPS0,
    OPS1,
    RECT,
    SCALE,
    SCISSOR,
    SURFACE_WIDTH,
    X0,
    X_COLUMNS,
    X_ROWS,
    LevelRows,
    x0_rows,
    x1_rows,
)

_Work = TypeVar("_Work")  # a kind of scratch (kept_work)
_E23 = np.array([0.0, 0.0, 1.0, 1.0])  # e2 + e3, a row a view (PlanBuffers.e23)


class CullWork:
    """``SurfaceTable.cull``'s scratch for a count of parents: its arrays and every view of
    them it reads, made once (a view costs about what a small numpy call does), so a cull
    makes none and allocates only its results."""

    def __init__(self, count: int, corners: int, surfaces: int) -> None:
        clip = np.empty((corners + 1, 14, count, surfaces))
        self.product = clip.reshape(corners + 1, 14 * count, surfaces)  # the corner product's
        self.corners = clip[:corners]
        self.sides, self.w = clip[:corners, 0:4], clip[:corners, 4:5]
        self.w_safe = np.empty((corners, 1, count, surfaces))
        self.epsilon = np.full((corners, 1, count, surfaces), 1e-6)  # (a scalar operand costs more)
        self.facing = clip[corners, EYE_ROW - CULL.start]  # the eye's row times the planes
        self.least = np.empty((14, count, surfaces))
        self.rects = self.least[0:4]
        self.x0y0, self.x1y1 = self.rects[0:2], self.rects[2:4]
        self.least_w = self.least[4]
        self.sizes = self.least[12:14]
        self.tests = self.least[4:14]
        self.worst = np.empty((count, surfaces))
        self.seen = np.empty((count, surfaces), bool)


class ChildTable:
    """The camera-free rows (``SurfaceTable._child_row``) of every ids class
    (``plan_rows.IDS_CLASS``: a view mask and winding) seen with one root projection and
    size, stacked in the order of the classes (S rows each): a level gathers its candidates'
    rows from it in one ``take`` by their parents' numbers' offsets."""

    def __init__(self) -> None:
        self.rows: list[np.ndarray] = []
        self.stacked = np.zeros((0, GRID_WIDTH), np.int64)
        self.offsets = np.zeros(0, np.int64)  # by ids number: its class's first row in ``stacked``


class PlanBuffers:
    """The arrays of ``PlanWork`` for up to ``capacity`` views (a power of two, at least
    16): one set per capacity, so the scratches of every count are views of a few arrays
    (not a set of arrays each: that memory, kept, evicted the frame's own from the caches;
    made afresh, it cost its first writes)."""

    def __init__(self, capacity: int) -> None:
        self.parent = np.empty((capacity, X_COLUMNS.stop - X_COLUMNS.start))
        self.surface = np.empty((capacity, SURFACE_WIDTH))
        self.data = np.empty((capacity, LevelRows.WIDTH))
        self.signs = np.ones((capacity, 4))  # (sign p.x, sign p.y, 1, 1)
        self.f = np.empty(capacity)
        self.two = np.full(capacity, 2.0)
        self.e23 = np.tile(_E23, (capacity, 1))
        self.fourth = np.empty((capacity, 4))  # the root projection's fourth row, a row a view
        self.fourth_of: np.ndarray | None = None  # the root projection it is of
        self.scaled = np.empty((capacity, 8))
        self.fe = np.empty((capacity, 4))
        self.b = np.empty((capacity, 4))
        self.outer = np.empty((capacity, 4, 4))


class PlanWork:
    """``SurfaceTable._plan``'s scratch for a count of views: the gathered parent and surface
    rows, the level's rows (copied out at the end) and every view of them it writes or
    reads, made once (views of the first ``k`` rows of ``buffers``)."""

    def __init__(self, k: int, buffers: PlanBuffers) -> None:
        self.buffers = buffers
        self.parent, self.surface = buffers.parent[:k], buffers.surface[:k]
        self.parent_x0 = self.parent[:, 0:X0].reshape(k, X_ROWS, 4)
        self.parent_x1 = self.parent[:, X0:].reshape(k, 8, 5)[..., 0:4]
        self.ops0 = self.surface[:, OPS0].reshape(k, 4, 4)
        self.ops1 = self.surface[:, OPS1].reshape(k, 4, 5)
        self.exit, self.neg_exit = self.surface[:, EXIT_PLANE], self.surface[:, NEG_EXIT_PLANE]
        self.scale = self.surface[:, SCALE]
        self.data = data = buffers.data[:k]
        ints = data.view(np.int64)
        self.x0, self.x1 = x0, x1 = x0_rows(data), x1_rows(data)
        self.eye_row, self.eye = x0[:, EYE_ROW], x1[:, 7, 0:4]
        self.clip, self.rect = data[:, CLIP], data[:, RECT]
        self.grid, self.scissor = ints[:, GRID_PART], ints[:, SCISSOR]
        self.fade, self.node = data[:, FADE], data[:, NODE]
        block = data[:, BLOCK].view(np.float32)
        self.block_node = block.view(np.uint32)[:, ID_NODE_COLUMN]
        self.block_eye = block[:, CAMERA_EYE]
        matrices = block[:, MATRICES].reshape(k, 4, 4, 4)
        self.v_p0v_block = matrices[:, 0:3:2]
        self.v_p0v = x0[:, 0:8, 0:4].reshape(k, 2, 4, 4).transpose(0, 1, 3, 2)
        self.proj_row, self.vp_row, self.inv = matrices[:, 1, :, 2], matrices[:, 2, :, 2], matrices[:, 3]
        self.plane_xy, self.plane_w = x1[:, 4:6, 4], x1[:, 7, 4]  # p.x, p.y; p.w
        self.through, self.col4 = x1[:, 0:4, 4], x1[:, 0:8, 4]  # t; t, p
        self.signs = buffers.signs[:k]
        self.signs_xy = self.signs[:, 0:2]
        self.f, self.two, self.e23, self.fourth = buffers.f[:k], buffers.two[:k], buffers.e23[:k], buffers.fourth[:k]
        self.f_col = self.f[:, None]
        self.scaled = buffers.scaled[:k]
        self.ft, self.fp, self.ft2 = self.scaled[:, 0:4], self.scaled[:, 4:8], self.scaled[:, 2:3]
        self.fe, self.b, self.outer = buffers.fe[:k], buffers.b[:k], buffers.outer[:k]
        self.p0v_row2, self.p0v_row3 = x0[:, 6, 0:4], x0[:, 7, 0:4]
        self.b_col = self.b[:, :, None]
        self.a_row = x1[:, None, 2, 0:4]
        self.inv_source = x1[:, 0:4, 0:4]


# How many scratches a table keeps of each kind (CullWork, PlanWork), the first kept dropped
# first, and for counts up to what: a
# scratch made afresh costs as much as the views it saves, which is what a level of a few
# views costs; a large level's work is in its arrays, and keeping its scratches (half a
# megabyte each for a hundred views) measured slower, the memory they hold evicting the
# frame's own from the caches (16 mirrors: 1.048 -> 1.019 of the plan before them).
WORK_KEPT = 48
WORK_KEPT_COUNT = 16
# How many PlanWorks a table keeps, of any count: views of the PlanBuffers of their capacity,
# no memory of their own to speak of, so the counts of a frame's large levels, which change
# by a few from frame to frame, are kept too (with 48, a 16-mirror frame made a new one
# most frames, about fifty views each).
PLAN_WORK_KEPT = 256


def kept_work(kept: dict, count: int, make: Callable[[int], _Work]) -> _Work:
    """A new scratch for ``count``, kept in ``kept`` (the first kept dropped when full) for a
    count up to ``WORK_KEPT_COUNT``."""
    found = make(count)
    if count <= WORK_KEPT_COUNT:
        if len(kept) >= WORK_KEPT:
            del kept[next(iter(kept))]
        kept[count] = found
    return found


@dataclass
class RootRows:
    """What the oblique near planes read of a root projection, worked out once per projection."""

    safe_distance: float     # closer to its plane, a view keeps the clip distance alone
    key: bytes               # the projection's bytes
    proj_t: np.ndarray       # the projection, transposed (its Camera block columns)
    of: np.ndarray           # the projection


_ROOTS: dict[bytes, RootRows] = {}
_LAST_ROOT: list[RootRows | None] = [None]


def kept_root_rows(root_proj: np.ndarray) -> RootRows:
    """The oblique near planes' constants of ``root_proj``: the last one's again for the same
    read-only array (the view tree's, kept while its root's projection stays), else found by
    its bytes."""
    last = _LAST_ROOT[0]
    if last is not None and last.of is root_proj and not root_proj.flags.writeable:
        return last
    key = root_proj.tobytes()
    found = _ROOTS.get(key)
    if found is None:
        if len(_ROOTS) > 32:
            _ROOTS.clear()
        near = root_proj[2, 3] / (root_proj[2, 2] - 1.0)
        found = _ROOTS[key] = RootRows(OBLIQUE_SAFE_NEARS * near, key, root_proj.T.copy(), root_proj)
    _LAST_ROOT[0] = found
    return found



_NODES = np.arange(1024, dtype=np.float64)


def node_numbers(first: int, k: int) -> np.ndarray:
    """first, first + 1, ... k of them (read only, float64)."""
    global _NODES
    if len(_NODES) < first + k:
        _NODES = np.arange(2 * (first + k), dtype=np.float64)
        _NODES.flags.writeable = False
    return _NODES[first:first + k]


_NODES.flags.writeable = False
