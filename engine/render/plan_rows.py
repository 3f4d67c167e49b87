"""The planner's rows: how a level's views, its candidates and each mirror's or portal's part
of them lie in float64 arrays, and the columns every reader of those rows uses.

``LEVEL_ROW`` is one view of a level (its matrices ``x``, rectangle, packed Camera block and
ids side by side), read by field name through ``ROW``; ``LevelRows`` holds a level's rows (the
root's made from its ``View``), ``Candidates`` a planned level's before its claims choose.
``SURFACE_ROW`` is a surface's part (``SurfaceTable.float_rows``, what multiplies a parent's
``x``), and the cull's rows (``_cull_rows``) are the part of a view's ``x`` that the cull
multiplies the corners by.  The underscored columns are the planner's own
(``engine/render/view_plan.py``, ``engine/render/plan_scratch.py``); other modules read the
rows through ``ROW`` and these classes.

Conventions: matrices here are numpy (..., 4, 4) arrays in the usual row-major math
layout (``M @ x``); glm's and GL's are column-major, so they are transposed at the edges.
"""
from __future__ import annotations

import numpy as np
from pyglm import glm

from engine.render.views import CAMERA_BLOCK_BYTES, CAMERA_DTYPE, CAMERA_FLOATS, CAMERA_IDS, View, field_columns

# One row of ``LevelRows``: a view of a level, everything the planner and the view tree read of
# it side by side in one float64 row (ints and the float32 Camera block seen through views of
# it), so that a level's rows are gathered, and its candidates chosen, with one ``take``.
#
# ``x`` holds the view's matrices as a 22 x 4 and an 8 x 5 block, so that two products a level
# carry all of them through the surfaces (``SurfaceTable._plan``): with V the view matrix, IV its
# inverse, P0 the root's projection and C the cull's rows (``_cull_rows``),
#   x[0] = [V; P0 V; C P0 V; -clip plane; eye; 0]     (multiplied on the right by inv(carry))
#   x[1] = [(IV inv(P0))^T | t; IV^T | p]            (multiplied on the right by [carry^T | carry^T e])
# where e is the plane the view looks out of (world), p = e IV that plane in view space (the
# oblique near plane's) and t = e IV inv(P0) (its Sherman-Morrison update).  The cull's 14
# rows (C P0 V, minus the clip plane, the eye, one of scratch) are what it multiplies the
# corners (and the planes) by; IV^T's last row is the eye, copied into x[0] after the
# products (a point is not carried as the rows of x[0] are: it is written, not multiplied).
X_ROWS = 22   # x[0]'s; x[1] has 8
X0 = X_ROWS * 4
_V, _P0V, CULL, _NEG_CLIP = slice(0, 4), slice(4, 8), slice(8, 22), 19
EYE_ROW = 20  # x[0]'s copy of the eye (the cull's facing values: its row times the planes)
LEVEL_ROW = np.dtype([
    ("rect", "<f8", (4,)),         # x0, y0, -x1, -y1 where it shows, screen pixels (the cull's signs)
    ("x", "<f8", (X0 + 8 * 5,)),
    ("node", "<f8"),               # its index in the tree
    ("scissor", "<i8", (4,)),      # x, y, w, h in the level's pixels
    ("block", "<f4", (CAMERA_FLOATS["skip"].stop,)),  # the packed Camera block (CAMERA_DTYPE)
    ("exit_row", "<f8"),           # the SurfaceTable row of the surface it looks out of (-1: none)
    ("view_mask", "<f8"),          # its kinds and the layers it shows (View.view_mask)
    ("mirrored", "<f8"),           # 1.0 where front faces wind clockwise
    ("parent", "<i8"),             # a candidate's row of its parent in the level above
    ("surface", "<i8"),            # and of its surface in the SurfaceTable
    ("fade", "<f8"),               # the reflection's weight (Mirror fades; 1: none)
    ("ids", "<i8"),                # the number of its exit row, view mask and winding (ids_number)
])
ROW = field_columns(LEVEL_ROW, 8)  # each field's columns
X_COLUMNS, RECT, BLOCK = (ROW[name] for name in ("x", "rect", "block"))
_EXIT_ROW, _MASK, _MIRRORED, NODE, FADE, _PARENT, _SURFACE, IDS = (ROW[name].start for name in (
    "exit_row", "view_mask", "mirrored", "node", "fade", "parent", "surface", "ids"))
SCISSOR = ROW["scissor"]
IDS_PART = slice(_EXIT_ROW, _MIRRORED + 1)    # exit row, view mask, mirrored: what decides which surfaces
# it may see and what its children's are
GRID_PART = slice(BLOCK.start, IDS + 1)    # what _child_ids holds for a level's rows: the block, then
# the exit row, view mask, mirrored, parent, surface, fade, ids number
_EYE = slice(X_COLUMNS.start + X0 + 7 * 5, X_COLUMNS.start + X0 + 7 * 5 + 4)  # IV^T's last row: the eye
CLIP = slice(X_COLUMNS.start + _NEG_CLIP * 4, X_COLUMNS.start + _NEG_CLIP * 4 + 4)       # minus the clip plane
assert CAMERA_BLOCK_BYTES == 8 * (BLOCK.stop - BLOCK.start)
assert _EXIT_ROW == BLOCK.stop and FADE == _EXIT_ROW + 5 and IDS == FADE + 1
GRID_WIDTH = GRID_PART.stop - GRID_PART.start
GRID_PARENT = _PARENT - GRID_PART.start  # the parent's column in it

# Every distinct (exit row, view mask, winding) a row has held, numbered in the order first
# seen: a row's ``ids`` column, so that what the planner keeps of a parent by its ids (its
# children's camera-free rows, its cull bias: ``SurfaceTable._child_ids``, ``_pair_bias``)
# is gathered for a level's parents in one ``take`` by their numbers, with no look-up a
# parent.  One numbering for every table (rows keep their numbers from table to table):
# what a number means never changes.  It grows with the distinct ids rows are made with (a
# root's; a surface's views' from their parents': exit rows times the kinds and layers a
# chain can show, times two windings), a few dozen for the 16-mirror ring.
IDS_NUMBERS: dict[tuple[float, float, float], int] = {}
IDS_OF: list[tuple[float, float, float]] = []  # IDS_NUMBERS' keys by number
# What a view's children's camera-free rows depend on is its view mask and winding alone, not
# the surface it looks out of (``SurfaceTable._child_ids``), so those rows are kept by the
# number of that pair, its ids number's class: a few dozen classes however many surfaces
# there are.  (Kept by ids number, a table of S rows a number grows with the exit rows,
# S x S x 376 bytes: 24 GiB for 600 surfaces.)
IDS_CLASS: list[int] = []  # each ids number's class
CLASS_OF: list[tuple[float, float]] = []  # each class's (view mask, winding)
_CLASS_NUMBERS: dict[tuple[float, float], int] = {}
_CLASSES = np.zeros(0, np.int64)  # IDS_CLASS as an array (ids_classes)


def ids_number(exit_row: float, mask: float, mirrored: float) -> int:
    """The number of a row's ids (``IDS_NUMBERS``), given one (and its class) when first seen."""
    key = (float(exit_row), float(mask), float(mirrored))
    found = IDS_NUMBERS.get(key)
    if found is None:
        found = IDS_NUMBERS[key] = len(IDS_OF)
        IDS_OF.append(key)
        pair = key[1:]
        kind = _CLASS_NUMBERS.get(pair)
        if kind is None:
            kind = _CLASS_NUMBERS[pair] = len(CLASS_OF)
            CLASS_OF.append(pair)
        IDS_CLASS.append(kind)
    return found


def ids_classes() -> np.ndarray:
    """Each ids number's class (``IDS_CLASS``) as an int64 array, remade when numbers came."""
    global _CLASSES
    if len(_CLASSES) != len(IDS_CLASS):
        _CLASSES = np.array(IDS_CLASS, np.int64)
        _CLASSES.flags.writeable = False
    return _CLASSES


def x0_rows(data: np.ndarray) -> np.ndarray:
    """``x[0]`` of rows ``data``: (n, X_ROWS, 4)."""
    return data[:, X_COLUMNS.start:X_COLUMNS.start + X0].reshape(-1, X_ROWS, 4)


# x[0]'s cull rows (C P0 V, minus the clip plane, the eye, scratch) as columns of a row: contiguous.
CULL_COLUMNS = slice(X_COLUMNS.start + CULL.start * 4, X_COLUMNS.start + CULL.stop * 4)


def cull_rows(data: np.ndarray) -> np.ndarray:
    """The cull's rows of rows ``data``, row by row, as one (14 P, 4) operand: row r of
    parent i at r P + i (a view for one parent; else a copy)."""
    if len(data) == 1:
        return data[0, CULL_COLUMNS].reshape(14, 4)
    return data[:, CULL_COLUMNS].reshape(-1, 14, 4).transpose(1, 0, 2).reshape(-1, 4)


def x1_rows(data: np.ndarray) -> np.ndarray:
    """``x[1]`` of rows ``data``: (n, 8, 5)."""
    return data[:, X_COLUMNS.start + X0:X_COLUMNS.stop].reshape(-1, 8, 5)


# SurfaceTable.float_rows: what multiplies a parent's ``x`` (LEVEL_ROW) from the right: inv(carry)
# (x[0]'s), then carry^T and carry^T e (x[1]'s, 4 x 5; e the plane its views look out of); that
# plane and its negative; its resolution scale.
SURFACE_ROW = np.dtype([("inv_carry", "<f8", (4, 4)), ("ops", "<f8", (4, 5)), ("exit_plane", "<f8", (4,)),
                        ("neg_exit_plane", "<f8", (4,)), ("resolution_scale", "<f8")])
_SURFACE_COLUMNS = field_columns(SURFACE_ROW, 8)
SURFACE_WIDTH = SURFACE_ROW.itemsize // 8
_OPS, EXIT_PLANE, NEG_EXIT_PLANE = (_SURFACE_COLUMNS[name] for name in ("ops", "exit_plane", "neg_exit_plane"))
OPS0, OPS1 = _SURFACE_COLUMNS["inv_carry"], _OPS
SCALE = _SURFACE_COLUMNS["resolution_scale"].start
# The Camera block's float32 columns (CAMERA_DTYPE) the planner writes.
MATRICES = slice(CAMERA_FLOATS["view"].start, CAMERA_FLOATS["inv_view_proj"].stop)
CAMERA_EYE, CAMERA_VIEWPORT, CAMERA_CLIP = (CAMERA_FLOATS[name] for name in ("eye", "viewport", "clip_plane"))
ID_SKIP, ID_HIDE, ID_MASK, _ID_NODE = (CAMERA_IDS.index(name) for name in ("skip", "hide", "view_mask", "node"))
ID_NODE_COLUMN = CAMERA_FLOATS["skip"].start + _ID_NODE  # the node's uint32 column in a block
assert CAMERA_DTYPE.names[:4] == ("view", "proj", "view_proj", "inv_view_proj")  # the matrices, in order
assert CAMERA_FLOATS["skip"].stop == CAMERA_BLOCK_BYTES // 4 and CAMERA_FLOATS["skip"].start % 2 == 0
assert _ID_NODE == 3  # the last: the ids but the node are the first three of the last two float64s

# A rectangle as the cull keeps it, x0, y0, -x1, -y1: its signs.
SIGNS = np.array([1.0, 1.0, -1.0, -1.0])

# The rows SurfaceTable.cull applies to a view's clip space (x, y, z, w, the rows of P0 V) to
# get, over each corner: x0, y0, -x1, -y1 in pixels times w (half the root's width or height
# times x + w, y + w, -x - w, -y - w, less w: a pixel outwards), w, then x - w, y - w, z - w, -x - w, -y - w, -z - w
# (each > 0 outside one side of the frustum).
_CULL_ROWS = np.array([
    [1, 0, 0, 1], [0, 1, 0, 1], [-1, 0, 0, -1], [0, -1, 0, -1], [0, 0, 0, 1],
    [1, 0, 0, -1], [0, 1, 0, -1], [0, 0, 1, -1], [-1, 0, 0, -1], [0, -1, 0, -1], [0, 0, -1, -1]], np.float64)
_CULLS: dict[tuple[int, int], np.ndarray] = {}


def _cull_rows(size: tuple[int, int]) -> np.ndarray:
    """``_CULL_ROWS`` for a root of ``size`` pixels: its first four scaled by half of it,
    less w (a pixel outwards once divided by w)."""
    found = _CULLS.get(size)
    if found is None:
        if len(_CULLS) > 32:
            _CULLS.clear()
        found = _CULL_ROWS * np.array([0.5 * size[0], 0.5 * size[1]] * 2 + [1.0] * 7)[:, None]
        found[0:4, 3] -= 1.0
        _CULLS[size] = found
    return found


_CULL_BLOCKS: dict[tuple[int, int], list[glm.dmat4]] = {}


def _cull_blocks(size: tuple[int, int]) -> list[glm.dmat4]:
    """``_cull_rows(size)`` and a row of zeros as three glm matrices, each the transpose R^T
    of four of those rows R (their row-major bytes read column-major): a root's
    ``(P0 V)^T * R^T`` is (R P0 V)^T, whose column-major bytes are R P0 V's rows."""
    found = _CULL_BLOCKS.get(size)
    if found is None:
        if len(_CULL_BLOCKS) > 32:
            _CULL_BLOCKS.clear()
        rows = np.zeros((12, 4))
        rows[0:11] = _cull_rows(size)
        found = _CULL_BLOCKS[size] = [glm.dmat4.from_bytes(rows[i:i + 4].tobytes()) for i in (0, 4, 8)]
    return found


class LevelRows:
    """The views of one level of a tree as arrays, a row each (the root: one row), packed
    in one float64 array (``LEVEL_ROW``'s fields, read by name through ``ROW``) so that a
    level's rows are gathered in one operation."""

    WIDTH = LEVEL_ROW.itemsize // 8
    # A lazy plan's rows (``SurfaceTable.plan(lazy=True)``) whose cameras are still to be
    # worked out: what ``finish`` works them out from (the table, its parents' rows, the root
    # projection); None: worked out.  Their ``x`` and their Camera blocks are not the views'
    # until then; every other column is.
    pending: tuple | None = None

    def __init__(self, data: np.ndarray) -> None:
        self.data = data

    def finish(self) -> None:
        """Work out the rows' cameras if they are pending (``SurfaceTable.finish_rows``, in
        place: views of the rows made before stay theirs).  A lazy plan's candidates are
        mostly claims that turn out empty, so the view tree finishes only those it chooses
        (``level_nodes.level_nodes``), and the planner those that become parents."""
        pending = self.pending
        if pending is not None:
            self.pending = None
            pending[0].finish_rows(self.data, pending[1], pending[2])

    @property
    def view(self) -> np.ndarray:
        """(n, 4, 4) world -> eye."""
        self.finish()
        return x0_rows(self.data)[:, _V, 0:4]

    @property
    def inv_view(self) -> np.ndarray:
        """(n, 4, 4) eye -> world."""
        self.finish()
        return x1_rows(self.data)[:, 4:8, 0:4].transpose(0, 2, 1)

    @property
    def eye(self) -> np.ndarray:
        """(n, 4) homogeneous world position."""
        self.finish()
        return self.data[:, _EYE]

    @property
    def clip(self) -> np.ndarray:
        """(n, 4) world clip plane (what the view keeps)."""
        self.finish()
        return -self.data[:, CLIP]

    @property
    def rect(self) -> np.ndarray:
        """(n, 4) x0, y0, x1, y1 where it shows, screen pixels."""
        return self.data[:, RECT] * SIGNS

    @property
    def exit_row(self) -> np.ndarray:
        """(n,) the SurfaceTable row of the surface the view looks out of (-1: none)."""
        return self.data[:, _EXIT_ROW]

    @property
    def mask(self) -> np.ndarray:
        """(n,) int64: the view's kinds and the layers it shows (``View.view_mask``)."""
        return self.data[:, _MASK].astype(np.int64)

    @property
    def mirrored(self) -> np.ndarray:
        """(n,) 1.0 where front faces wind clockwise."""
        return self.data[:, _MIRRORED]

    @property
    def node(self) -> np.ndarray:
        """(n,) the view's index in the tree."""
        return self.data[:, NODE]

    @staticmethod
    def root(view: View) -> LevelRows:
        """A root view's row (its projection is the tree's root projection), its matrices
        made in glm doubles of the float32 glm holds (the inverse view: glm's float32
        inverse, its eye too, as the planner always took it; the cull's rows as three 4 x 4
        products, ``_cull_blocks``), their bytes joined and written in
        one copy over a copy of a row kept per size, clip plane, mask and winding (the
        rectangle, minus the clip plane, the ids): glm's bytes are column-major, so a
        matrix's are its transpose's rows."""
        v, proj = glm.dmat4(view.view), glm.dmat4(view.proj)
        inv_v = glm.dmat4(glm.inverse(view.view))
        clip_space = glm.transpose(proj * v)  # (P0 V)^T
        cull = _cull_blocks(view.size)
        row = _root_template(view.size, view.clip_plane, view.view_mask, view.mirrored).copy()
        row.reshape(-1)[_ROOT_COLUMNS] = np.frombuffer(b"".join((
            glm.transpose(v).to_bytes(), clip_space.to_bytes(), (clip_space * cull[0]).to_bytes(),
            (clip_space * cull[1]).to_bytes(), (clip_space * cull[2]).to_bytes()[:96], inv_v[3].to_bytes(),
            (inv_v * glm.dmat4(glm.inverse(view.proj))).to_bytes(), inv_v.to_bytes())), np.float64)
        return LevelRows(row)


_ROOT_TEMPLATES: dict[tuple, np.ndarray] = {}


def _root_template(size: tuple[int, int], clip_plane: glm.vec4, view_mask: int, mirrored: bool) -> np.ndarray:
    """A root row but its matrices: the rectangle (x0, y0, -x1, -y1), minus the clip plane,
    the ids (no exit row, its mask and winding, node 0, a fade of 1, their number)."""
    key = (size, tuple(clip_plane), view_mask, mirrored)
    found = _ROOT_TEMPLATES.get(key)
    if found is None:
        if len(_ROOT_TEMPLATES) > 64:
            _ROOT_TEMPLATES.clear()
        found = _ROOT_TEMPLATES[key] = np.zeros((1, LevelRows.WIDTH))
        found[0, RECT] = (0.0, 0.0, -size[0], -size[1])
        found[0, CLIP] = tuple(-clip_plane)
        found[0, [_EXIT_ROW, _MASK, _MIRRORED, NODE, FADE]] = (-1.0, float(view_mask), float(mirrored), 0.0, 1.0)
        found.view(np.int64)[0, IDS] = ids_number(-1.0, view_mask, mirrored)
    return found


# The columns of a root row LevelRows.root writes in one copy: x[0]'s first 19 rows (V, P0 V and the
# cull's rows, not minus the clip plane) and its eye row, then x[1]'s first four columns.
_ROOT_COLUMNS = np.concatenate([np.arange(X_COLUMNS.start, X_COLUMNS.start + 19 * 4),
                                np.arange(X_COLUMNS.start + EYE_ROW * 4, X_COLUMNS.start + EYE_ROW * 4 + 4),
                                (X_COLUMNS.start + X0 + np.arange(8)[:, None] * 5 + np.arange(4)[None, :]).reshape(-1)])


class _kept:  # noqa: N801 (a decorator, named as functools.cached_property is)
    """``functools.cached_property`` without its lock: Python 3.11's takes a lock at every
    first read, and a level's candidates are read for a few arrays each (about 30 first
    reads a frame at portal depth 8).  The value goes into the instance's ``__dict__``, which
    later reads find first (a descriptor without ``__set__``)."""

    def __init__(self, function) -> None:
        self.function = function
        self.name = function.__name__
        self.__doc__ = function.__doc__

    def __get__(self, instance, owner=None):
        if instance is None:
            return self
        value = instance.__dict__[self.name] = self.function(instance)
        return value


class Candidates:
    """A level's candidate views, before its claims say which have pixels: one row each of
    ``LevelRows`` (claim order), read through views of it made when first asked for (a
    level's candidates, those it chooses and those that grow are each read for a few)."""

    def __init__(self, rows: LevelRows, size: tuple[int, int], end: np.ndarray | None = None) -> None:
        self.rows = rows          # their cameras, rectangles, blocks (node: claim order from first_index)
        self.size = size          # the level's pixels
        self.end = end            # (k,) bool: an end view, cut by the depth limits (None: none asked for)
        self._chosen: dict[bytes, Candidates] = {}  # select's, once read-only
        # What the view tree makes of a kept plan's (read-only) candidates that is a function
        # of their rows alone, kept with them while they are (``level_nodes.level_nodes``).
        self.derived: dict[tuple, object] = {}

    def __len__(self) -> int:
        return len(self.rows.data)

    @_kept
    def parent(self) -> np.ndarray:
        """(k,) row of the parent in the level above."""
        return self.rows.data.view(np.int64)[:, _PARENT]

    @_kept
    def surface(self) -> np.ndarray:
        """(k,) row in the SurfaceTable."""
        return self.rows.data.view(np.int64)[:, _SURFACE]

    @_kept
    def scissor(self) -> np.ndarray:
        """(k, 4) int x, y, w, h in the level's pixels."""
        return self.rows.data.view(np.int64)[:, SCISSOR]

    @_kept
    def blocks(self) -> np.ndarray:
        """(k, CAMERA_BLOCK_BYTES / 4) float32: the packed Camera blocks (a lazy plan's
        worked out first: ``LevelRows.finish``)."""
        self.rows.finish()
        return self.rows.data[:, BLOCK].view(np.float32)

    @_kept
    def fade(self) -> np.ndarray:
        """(k,) the reflection's weight (Mirror fades; 1: none)."""
        return self.rows.data[:, FADE]

    def freeze(self) -> None:
        """Make every array read-only (a kept plan is shared by the frames that read it; a
        view made after this is read-only with its base); a lazy plan's rows are finished first."""
        self.rows.finish()
        self.rows.data.flags.writeable = False
        for name in ("parent", "surface", "scissor", "blocks", "fade", "end"):
            array_ = self.__dict__.get(name)
            if array_ is not None:
                array_.flags.writeable = False

    def select(self, keep: np.ndarray) -> Candidates:
        """The candidates at ``keep`` (int64 indices), in their order (``take``: several
        times cheaper than fancy indexing for these small gathers).  A kept plan's
        (read-only) keeps its choices, read-only too: the frames that choose the same find
        the same rows again, and so the plans kept for them (``SurfaceTable.plan``)."""
        data = self.rows.data
        if data.flags.writeable:  # (a lazy plan's choice is lazy too: its rows are finished when read)
            found = Candidates(LevelRows(data.take(keep, axis=0)), self.size,
                               None if self.end is None else self.end.take(keep))
            found.rows.pending = self.rows.pending
            return found
        key = keep.tobytes()
        found = self._chosen.get(key)
        if found is None:
            if len(self._chosen) > 16:
                self._chosen.clear()
            found = self._chosen[key] = Candidates(LevelRows(data.take(keep, axis=0)), self.size,
                                                   None if self.end is None else self.end.take(keep))
            found.freeze()
        return found
