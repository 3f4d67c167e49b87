"""Planning a reflection level in arrays: which (parent view x surface) pairs get a view,
where on screen, and each view's camera, for all pairs of a level at once.

A view tree level is planned in a fixed number of numpy operations whatever its number of
views: the parents of a level are rows of arrays (``LevelRows``), every mirror and portal
is a row of ``SurfaceTable``, and ``SurfaceTable.cull`` and ``SurfaceTable.plan`` work on
(parents x surfaces) blocks.  Per view, only what the draws need is made in Python (a
``View`` holding its packed camera block).  This is the one planner, for levels of every
size: a level costs some 70 numpy calls whatever its views (about 50 us on llvmpipe's
machine for a level of one view, measured warm; planning pair by pair in glm cost some
15 us a view, so a level of one or two views was cheaper that way, and dearer from about
six: the second planner that did so is gone, for one set of rules).

Conventions: matrices here are numpy (..., 4, 4) arrays in the usual row-major math
layout (``M @ x``); glm's and GL's are column-major, so they are transposed at the edges.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from pyglm import glm

from components.limits import VIEW_DIRECT, VIEW_MIRROR, VIEW_PORTAL
from components.visibility import KIND_MASK, visibility_code
from engine.core.reflection_math import OBLIQUE_SAFE_NEARS
from engine.render.views import CAMERA_BLOCK_BYTES, CAMERA_DTYPE, CAMERA_FLOATS, CAMERA_IDS, View, field_columns
from engine.rules.visibility_rules import drawn_in

if TYPE_CHECKING:  # the surfaces stage's records (engine/resources.py): read here by their fields
    from engine.resources import SurfaceState

_CAMERA_FLOATS = CAMERA_BLOCK_BYTES // 4
_KINDS_BUT_DIRECT = KIND_MASK & ~VIEW_DIRECT  # a view through a surface is no longer direct


def _mat(matrix: glm.mat4) -> np.ndarray:
    """A glm matrix as a row-major numpy one."""
    return np.frombuffer(matrix.to_bytes(), np.float32).reshape(4, 4).T.astype(np.float64)


# One row of ``LevelRows``: a view of a level, in float64.  Eye, viewport and clip plane side
# by side are the Camera block's (one copy, ``CAMERA_DTYPE``), and the clip plane above the
# view matrix makes the 5 x 4 block ``SurfaceTable.cull`` multiplies once a level.
LEVEL_ROW = np.dtype([
    ("eye", "<f8", (4,)),          # homogeneous world position
    ("viewport", "<f8", (4,)),     # 0, 0, the level's width and height
    ("clip_plane", "<f8", (4,)),   # world clip plane (what the view keeps)
    ("view", "<f8", (16,)),        # world -> eye, row by row
    ("inv_view", "<f8", (16,)),    # eye -> world, row by row
    ("rect", "<f8", (4,)),         # x0, y0, x1, y1 where it shows, screen pixels
    ("exit_row", "<f8"),           # the SurfaceTable row of the surface it looks out of (-1: none)
    ("view_mask", "<f8"),          # its kinds and the layers it shows (View.view_mask)
    ("mirrored", "<f8"),           # 1.0 where front faces wind clockwise
    ("node", "<f8"),               # its index in the tree
])
ROW = field_columns(LEVEL_ROW, 8)  # each field's columns
_EYE, _VIEWPORT, _CLIP, _VIEW, _INV_VIEW, _RECT = (ROW[name] for name in (
    "eye", "viewport", "clip_plane", "view", "inv_view", "rect"))
_EXIT_ROW, _MASK, _MIRRORED, _NODE = (ROW[name].start for name in ("exit_row", "view_mask", "mirrored", "node"))
_CAMERA_PART = slice(_EYE.start, _CLIP.stop)   # eye, viewport, clip plane: the Camera block's, in its order
_CLIP_VIEW = slice(_CLIP.start, _VIEW.stop)    # the cull's 5 x 4 block
_IDS_PART = slice(_EXIT_ROW, _MASK + 1)        # exit row and view mask: what decides which surfaces it may see


class LevelRows:
    """The views of one level of a tree as arrays, a row each (the root: one row), packed
    in one float64 array (``LEVEL_ROW``'s fields, read by name through ``ROW``) so that a
    level's rows are gathered in one operation."""

    WIDTH = LEVEL_ROW.itemsize // 8

    def __init__(self, data: np.ndarray) -> None:
        self.data = data

    @property
    def view(self) -> np.ndarray:
        """(n, 4, 4) world -> eye."""
        return self.data[:, _VIEW].reshape(-1, 4, 4)

    @property
    def inv_view(self) -> np.ndarray:
        """(n, 4, 4) eye -> world."""
        return self.data[:, _INV_VIEW].reshape(-1, 4, 4)

    @property
    def eye(self) -> np.ndarray:
        """(n, 4) homogeneous world position."""
        return self.data[:, _EYE]

    @property
    def clip(self) -> np.ndarray:
        """(n, 4) world clip plane (what the view keeps)."""
        return self.data[:, _CLIP]

    @property
    def rect(self) -> np.ndarray:
        """(n, 4) x0, y0, x1, y1 where it shows, screen pixels."""
        return self.data[:, _RECT]

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
        return self.data[:, _NODE]

    @staticmethod
    def root(view: View) -> LevelRows:
        """A root view's row, made from its glm values in one array (each a float64 of the
        float32 glm holds)."""
        row = np.zeros((1, LevelRows.WIDTH))
        row[0, _EYE] = (*view.eye, 1.0)
        row[0, _VIEWPORT] = (0.0, 0.0, *view.size)
        row[0, _CLIP] = tuple(view.clip_plane)
        row[0, _VIEW] = _rows(view.view)
        row[0, _INV_VIEW] = _rows(glm.inverse(view.view))
        row[0, _RECT] = (0.0, 0.0, *view.size)
        row[0, [_EXIT_ROW, _MASK, _MIRRORED, _NODE]] = (-1.0, float(view.view_mask), float(view.mirrored), 0.0)
        return LevelRows(row)


@dataclass
class Candidates:
    """A level's candidate views, before its claims say which have pixels: one row each,
    in claim order (``parent`` rows of the level above, ``surface`` rows of the table)."""

    parent: np.ndarray       # (k,) row of the parent in the level above
    surface: np.ndarray      # (k,) row in the SurfaceTable
    rows: LevelRows          # their cameras and screen rectangles (node: claim order from first_index)
    scissor: np.ndarray      # (k, 4) int x, y, w, h in the level's pixels
    blocks: np.ndarray       # (k, CAMERA_BLOCK_BYTES / 4) float32: packed Camera blocks
    size: tuple[int, int]    # the level's pixels
    fade: np.ndarray         # (k,) the reflection's weight (Mirror fades; 1: none)
    end: np.ndarray | None = None  # (k,) bool: an end view, cut by the depth limits (None: none asked for)

    def __len__(self) -> int:
        return len(self.parent)

    def freeze(self) -> None:
        """Make every array read-only (a kept plan is shared by the frames that read it)."""
        for array_ in (self.parent, self.surface, self.rows.data, self.scissor, self.blocks, self.fade, self.end):
            if array_ is not None:
                array_.flags.writeable = False

    def select(self, keep: np.ndarray) -> Candidates:
        """The candidates at ``keep`` (int64 indices), in their order (``take``: several
        times cheaper than fancy indexing for these small gathers)."""
        return Candidates(self.parent.take(keep), self.surface.take(keep), LevelRows(self.rows.data.take(keep, axis=0)),
                          self.scissor.take(keep, axis=0), self.blocks.take(keep, axis=0), self.size,
                          self.fade.take(keep), None if self.end is None else self.end.take(keep))


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
        row_of = {entity: i for i, entity in enumerate(self.entity_list)}
        # The row of the surface each view through a surface looks out of (a mirror: itself; a
        # portal: its partner; -1: not in the table), which that view cannot see.
        self.exit_rows = np.array([row_of.get(e, -1) for e in self.exit_entities.tolist()], np.int64)
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
        self.corner_columns = np.zeros((self.corner_count, 4, count))  # corner c of every surface: a 4 x S block
        for i, c in enumerate(distinct):
            self.corner_columns[:, :, i] = np.concatenate([c, np.repeat(c[:1], self.corner_count - len(c), axis=0)])
        self.planes_t = np.ascontiguousarray(self.planes.T)
        # ... the floats of each surface's views (``SURFACE_ROW``) and their integers
        # (``_SURFACE_INTS``), in the order the view's rows and Camera block take them.
        self.float_rows = np.concatenate([self.carry.reshape(count, 16), self.inv_carry.reshape(count, 16),
                                          self.exit_planes, self.is_mirror[:, None], self.scale[:, None]], axis=1)
        self.int_rows = np.stack([self.exit_rows, visibility_code(_KINDS_BUT_DIRECT, self.layers),
                                  self.exit_entities, self.kind_bit], axis=1).reshape(count, len(_SURFACE_INTS))
        self._depths: dict[tuple[int, int], tuple[np.ndarray, np.ndarray, list[bool], bool]] = {}
        self._biases: dict[tuple, tuple[np.ndarray | None, np.ndarray]] = {}  # _pair_bias's
        self._plans: dict[tuple, tuple[np.ndarray | None, tuple[Candidates | None, int]]] = {}  # plan's, least
        # recently used first
        self._ends: dict[tuple[int, int], tuple[np.ndarray, np.ndarray, list[bool]]] = {}
        self._unviewed: dict[tuple, tuple[np.ndarray | None, tuple[np.ndarray, np.ndarray]]] = {}  # unviewed's
        self._faded: tuple | None = None  # the last cull's pairs faded out, and for what (cull)
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

    def _pair_bias(self, data: np.ndarray, depth: int, depth_cap: int, ends: np.ndarray | None,
                   fallback: bool) -> np.ndarray:
        """(P, S): what the cull adds to each (parent, surface) facing value: 0 where the
        parent view may see the surface at ``depth`` (enabled, within its limits or one of
        ``ends``; with ``fallback``, any surface that ``falls_back``, whatever its limits;
        and drawn by the view: ``drawn_in`` its mask), -inf where not, and on the surface the
        view looks out of.  A function of each parent's exit row and mask alone, so kept by
        their bytes (a level's parents see through the same surfaces frame after frame) with
        the depth, cap and ``ends`` (an array the view tree keeps while nothing changes)."""
        ids = data[:, _IDS_PART]
        key = (ids.tobytes(), depth, depth_cap, id(ends), fallback)
        found = self._biases.get(key)
        if found is None or found[0] is not ends:
            if fallback:
                allowed = self.falls_back
            else:
                allowed = self._within(depth, depth_cap)[0] if ends is None else self._with_ends(depth, depth_cap,
                                                                                                  ends)[0]
            bias = np.empty((len(data), len(self.states)))
            for row, (exit_row, mask) in zip(bias, ids.astype(np.int64).tolist(), strict=True):
                drawn = self.drawn_in(mask)
                row[:] = np.where(allowed if drawn is None else allowed & drawn, 0.0, -np.inf)
                if exit_row >= 0:
                    row[exit_row] = -np.inf
            bias.flags.writeable = False
            if len(self._biases) > 256:
                self._biases.clear()
            found = self._biases[key] = (ends, bias)
        return found[1]

    def cull(self, parents: LevelRows, depth: int, root_proj: np.ndarray, root_size: tuple[int, int],
             depth_cap: int, ends: np.ndarray | None = None,
             fallback: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """Each (parent, surface) where the parent view can see the surface, with the screen
        rectangle where it can show: enabled and within its depth, not the surface the view
        looks out of, facing the view's eye (a mirror facing away shows nothing, as the
        "Multiple Mirrors" project notes), not wholly behind the view's clip plane, inside
        the frustum and overlapping the parent's rectangle.  ``depth`` is the level the
        views would be on.  Returns (parent rows, surface rows, rects x0 y0 x1 y1), parent
        major, and the fade weights of the pairs seen before the fades (None: no surface
        fades; a pair faded out, weight 0, is not returned).  With ``ends`` (a mask of
        surfaces), the pairs of those surfaces the depth limits cut are kept too: the end
        views (``engine/render/end_images.py``).  With ``fallback`` (``unviewed``), every
        surface that ``falls_back`` is tested whatever its limits, and the pairs faded out
        are returned too (their weight 0).

        Every (parent x surface) pair goes through the same few array operations, the
        whole grid at once: in a frame, after the rasteriser has run, each numpy call costs
        about twice what it does in a warm loop (measured), so their number, not the pairs
        they hold, is what a level costs at these sizes.  One product takes every distinct
        corner of every surface through 12 rows per parent (``_cull_rows``): x, y, -x, -y
        and w in clip space, six values > 0 outside each side of the frustum, and minus the
        side of the parent's clip plane.  Then one minimum over the corners gives each
        pair's frustum and clip-plane tests, and, with x and y divided by w first, its
        rectangle's four sides as minima (x0, y0, -x1, -y1: the same rounding rule, floor
        then one pixel out, for each side)."""
        count, surfaces = len(parents.data), len(self.states)
        if not count or not surfaces:
            return _NONE, _NONE, _NO_RECTS, None
        if ends is None and not fallback and not self._within(depth, depth_cap)[3]:
            return _NONE, _NONE, _NO_RECTS, None  # nothing enabled may be seen this deep
        data = parents.data
        # First what needs no corners: facing the view's eye, and allowed (enabled, within
        # its depth, drawn by the view, not the surface the view looks out of): one product
        # and a bias per pair, -inf where a surface is not allowed (_pair_bias).
        facing = data[:, _EYE] @ self.planes_t                                       # P x S
        facing += self._pair_bias(data, depth, depth_cap, ends, fallback)
        if not facing.max() > 0.0:
            return _NONE, _NONE, _NO_RECTS, None
        # Rows first: (12, 5) times every parent's (5, 4) block side by side, then (12 P, 4)
        # times each corner's (4, S) gives (corners, 12, P, S), so x and y are divided by w,
        # and the minima over the corners and over the rows taken, along the first axis
        # (numpy's fast one for small arrays), in whole blocks.
        block = data[:, _CLIP_VIEW].reshape(count, 5, 4).transpose(1, 0, 2).reshape(5, 4 * count)
        clip = (_cull_rows(root_proj) @ block).reshape(12 * count, 4) @ self.corner_columns
        clip = clip.reshape(self.corner_count, 12, count, surfaces)
        np.divide(clip[:, 0:4], np.maximum(clip[:, 4:5], 1e-6), out=clip[:, 0:4])  # a w <= 0: see straddles
        least = _MIN(clip, axis=0)                                                       # 12 x P x S
        # x0, y0, -x1, -y1 in pixels, rounded outwards with a pixel's margin; a pair with a
        # corner behind the eye is conservative (the parent's whole rectangle).
        rects = least[0:4] + _OUTWARDS
        rects *= _half_sizes(root_size)
        np.floor(rects, out=rects)
        rects -= 1.0
        np.copyto(rects, -np.inf, where=least[4] <= 1e-6)
        np.maximum(rects, (data[:, _RECT] * _SIGNS).T[:, :, None], out=rects)  # inside the parent's
        # Seen: facing and allowed, not culled (every corner outside one side of the frustum,
        # or behind the clip plane; on a side counts as outside) and a rectangle with pixels
        # (x1 > x0 and y1 > y0): one maximum over the rows 2-11, written over, each < 0 to keep.
        np.negative(facing, out=least[2])
        np.add(rects[0:2], rects[2:4], out=least[3:5])
        p, s = np.nonzero(_MAX(least[2:12], axis=0) < 0.0)
        rects = rects[:, p, s].T
        rects *= _SIGNS
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
        viewable = self._within(depth, depth_cap)[0] if ends is None else self._with_ends(depth, depth_cap, ends)[0]
        cut = self.falls_back & ~viewable
        if not len(parents.data) or (not cut.any() and not self.fading):
            return _NONE, _NONE
        # Kept like the plans (``plan``): the same parent rows (a still camera, a probe face)
        # give the same pairs, for the price of comparing bytes.
        key = (parents.data.tobytes(), root_proj.tobytes(), depth, depth_cap, root_size, id(ends))
        found = self._unviewed.pop(key, None)
        if found is not None and found[0] is ends:
            self._unviewed[key] = found
            return found[1]
        faded = self._faded
        if not cut.any() and faded is not None and faded[0] is parents.data and faded[1:3] == (depth, depth_cap) \
                and faded[3] is ends:
            # Nothing cut here: the pairs without a view are those the plan's cull just faded out.
            pairs = (faded[4], faded[5])
        else:
            p, s, _, fade = self.cull(parents, depth, root_proj, root_size, depth_cap, ends, fallback=True)
            unviewed = cut[s] if fade is None else cut[s] | (fade <= 0.0)
            pairs = (p[unviewed], s[unviewed])
        for array_ in pairs:
            array_.flags.writeable = False  # shared by the frames that find them again
        if len(self._unviewed) >= PLANS_KEPT:
            del self._unviewed[next(iter(self._unviewed))]
        self._unviewed[key] = (ends, pairs)
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
             size: tuple[int, int] | None = None, scale: float = 1.0) -> tuple[Candidates | None, int]:
        """``_plan``, kept: a level's plan is a function of the table (made again when a
        surface changes) and these arguments alone, so a level planned before from the same
        parent rows (a probe face's tree, whose camera stands still; a still main camera)
        is that plan again, read-only, for the price of comparing its inputs' bytes.  The
        ``PLANS_KEPT`` plans used last are kept."""
        key = (parents.data.tobytes(), root_proj.tobytes(), depth, first_index, depth_cap, hide, size, scale,
               root.size, id(ends))
        found = self._plans.pop(key, None)
        if found is not None and found[0] is ends:
            self._plans[key] = found  # the most recently used last
            return found[1]
        planned = self._plan(parents, depth, root, root_proj, inv_root_proj, first_index, depth_cap, hide, ends,
                             size, scale)
        if planned[0] is not None:
            planned[0].freeze()
        if len(self._plans) >= PLANS_KEPT:
            del self._plans[next(iter(self._plans))]  # the least recently used
        self._plans[key] = (ends, planned)
        return planned

    def _plan(self, parents: LevelRows, depth: int, root: View, root_proj: np.ndarray, inv_root_proj: np.ndarray,
              first_index: int, depth_cap: int, hide: int, ends: np.ndarray | None = None,
              size: tuple[int, int] | None = None, scale: float = 1.0) -> tuple[Candidates | None, int]:
        """The next level's candidate views from ``parents`` (level ``depth - 1``): the
        cull's pairs, each with its camera (the parent's carried through the surface: for a
        mirror its reflection, for a portal look-out x half turn x inverse(look-in), as in
        the DirectX "magic mirrors" write-up), clipped at the plane it looks out of, with
        Lengyel's oblique near plane there unless the eye is too close (then the clip
        distance alone), its claim rectangle in the level's pixels, and its packed Camera
        block (None when nothing can be seen), and how many pairs the
        fades took out.  ``ends``: those surfaces' end views too (``cull``; marked in
        ``Candidates.end``); ``size``: the level's pixels, when given; ``scale``: a factor on
        the level's resolution (the frame's pixel budget, ``ViewTree``).

        Like the cull, a fixed number of array operations whatever the number of views:
        each candidate's parent row and surface rows are gathered once (``take``), and the
        results are written where they are read next (the level's rows, the Camera blocks)."""
        p, s, rects, weights = self.cull(parents, depth, root_proj, root.size, depth_cap, ends)
        if weights is None:
            faded, fade = 0, None
        else:
            faded = int((weights == 0.0).sum())
            fade = weights[weights > 0.0]
        k = len(p)
        if not k:
            return None, faded
        surface = self.float_rows.take(s, axis=0)
        ints = self.int_rows.take(s, axis=0)
        parent = parents.data.take(p, axis=0)
        if size is None:
            scale *= self.one_scale if self.one_scale is not None else float(surface[:, _SCALE].max())
            size = (max(1, round(root.size[0] * scale)), max(1, round(root.size[1] * scale)))
        data = np.empty((k, LevelRows.WIDTH))
        view = data[:, _VIEW].reshape(k, 4, 4)
        inv_view = data[:, _INV_VIEW].reshape(k, 4, 4)
        np.matmul(parent[:, _VIEW].reshape(k, 4, 4), surface[:, _INV_CARRY].reshape(k, 4, 4), out=view)
        np.matmul(surface[:, _CARRY].reshape(k, 4, 4), parent[:, _INV_VIEW].reshape(k, 4, 4), out=inv_view)
        data[:, _EYE] = inv_view[:, :, 3]  # where the carried camera is: its eye-to-world translation
        data[:, _VIEWPORT] = (0.0, 0.0, *size)
        data[:, _CLIP] = clip = surface[:, _EXIT_PLANE]
        data[:, _RECT] = rects
        mask = ints[:, _KEEP]  # a view shows the layers every surface of its chain shows
        np.bitwise_and(parent[:, _MASK].astype(np.int64), mask, out=mask)
        mask |= ints[:, _KIND_BIT]
        data[:, _IDS_PART] = ints[:, _EXIT_ROW_AND_KEEP]  # the exit's row, the mask
        np.not_equal(parent[:, _MIRRORED], surface[:, _IS_MIRROR], out=data[:, _MIRRORED])
        data[:, _NODE] = np.arange(first_index, first_index + k)
        proj, inv_proj = _oblique_projections(root_proj, inv_root_proj, inv_view, clip)
        # The Camera blocks (CAMERA_DTYPE) as float32 columns: the four matrices written
        # straight into their columns (column-major: each seen transposed), then the eye,
        # viewport and clip plane in one copy, then the ids.
        blocks = np.empty((k, _CAMERA_WIDTH), np.float32)
        matrices = blocks[:, _MATRICES].reshape(k, 4, 4, 4).transpose(0, 1, 3, 2)
        matrices[:, 0] = view
        matrices[:, 1] = proj
        np.matmul(proj, view, out=matrices[:, 2])
        np.matmul(inv_view, inv_proj, out=matrices[:, 3])
        blocks[:, _CAMERA_ROWS] = data[:, _CAMERA_PART]
        ids = blocks[:, _CAMERA_ID_COLUMNS].view(np.uint32)
        ids[:, _ID_SKIP_AND_MASK] = ints[:, _EXIT_ENTITY_AND_KEEP]  # skip (the exit entity), mask
        ids[:, _ID_HIDE] = hide
        ids[:, _ID_NODE] = data[:, _NODE]  # the view's node (the node image's value for its pixels)
        end = None if ends is None else self._within(depth, depth_cap)[1].take(s)
        return Candidates(p, s, LevelRows(data), level_rects(rects, root.size, size), blocks, size,
                          fade if fade is not None else _ones(k), end), faded


def _oblique_projections(root_proj: np.ndarray, inv_root_proj: np.ndarray, inv_view: np.ndarray,
                         clip: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lengyel's oblique near plane for each view (``reflection_math.oblique_projection``, in
    arrays), and the projections' inverses: the root projection's third row replaced so that
    the clip plane, in view space, is the near plane; the root projection where the eye is
    too close to the plane.  One row changes, so each inverse is a rank-one update of the
    root's (Sherman-Morrison), not a 4 x 4 inversion."""
    plane = np.matmul(clip[:, None, :], inv_view)[:, 0]  # planes transform by the inverse transpose; the
    # construction below is unchanged by the plane's (positive) scale, so it is not normalised
    root = _projection(root_proj, inv_root_proj)
    safe = np.abs(plane[:, 3]) > root.safe_distance  # the eye's distance to the plane: clip . eye
    q = np.sign(plane[:, :2]) @ root.inv_xy_t
    q += root.inv_zw
    c = plane * (2.0 / np.vecdot(plane, q))[:, None]
    c -= root.rows_2_3
    change = np.where(safe[:, None], c, 0.0)  # the third row's change
    proj = root_proj[None].repeat(len(plane), 0)
    proj[:, 2] += change
    # The inverse: P = P0 + e2 change^T, so P^-1 = P0^-1 - (P0^-1 e2)(change^T P0^-1) / (1 + change^T P0^-1 e2),
    # both products of the change in one (root.inv_and_column: P0^-1 with its third column after it).
    row = change @ root.inv_and_column
    row[:, 0:4] /= 1.0 + row[:, 4:5]
    inv_proj = inv_root_proj - root.column[None, :, None] * row[:, None, 0:4]
    return proj, inv_proj


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


# SurfaceTable.float_rows: each surface's carry and its inverse (row by row), the plane its
# views look out of, 1.0 for a mirror, its resolution scale.
SURFACE_ROW = np.dtype([("carry", "<f8", (16,)), ("inv_carry", "<f8", (16,)), ("exit_plane", "<f8", (4,)),
                        ("is_mirror", "<f8"), ("resolution_scale", "<f8")])
_SURFACE = field_columns(SURFACE_ROW, 8)
_CARRY, _INV_CARRY, _EXIT_PLANE = _SURFACE["carry"], _SURFACE["inv_carry"], _SURFACE["exit_plane"]
_IS_MIRROR, _SCALE = _SURFACE["is_mirror"].start, _SURFACE["resolution_scale"].start
# SurfaceTable.int_rows: the row of the surface its views look out of, the view mask bits a view
# through it keeps (its layers and every kind but direct), the entity they look out of, the
# kind bit it adds.  Laid out so that the pairs the rows and blocks take together are slices.
_SURFACE_INTS = ("exit_row", "keep", "exit_entity", "kind_bit")
_KEEP, _KIND_BIT = _SURFACE_INTS.index("keep"), _SURFACE_INTS.index("kind_bit")
_EXIT_ROW_AND_KEEP = slice(_SURFACE_INTS.index("exit_row"), _KEEP + 1)  # LevelRows' exit_row, view_mask
_EXIT_ENTITY_AND_KEEP = slice(_SURFACE_INTS.index("exit_entity"), _KEEP - 1, -1)  # the Camera ids' skip, mask
assert _MASK == _EXIT_ROW + 1 and _KEEP == 1 and _SURFACE_INTS.index("exit_entity") == 2
# The Camera block's float32 columns (CAMERA_DTYPE) the planner writes.
_CAMERA_WIDTH = CAMERA_BLOCK_BYTES // 4
_MATRICES = slice(CAMERA_FLOATS["view"].start, CAMERA_FLOATS["inv_view_proj"].stop)
_CAMERA_ROWS = slice(CAMERA_FLOATS["eye"].start, CAMERA_FLOATS["clip_plane"].stop)
_CAMERA_ID_COLUMNS = CAMERA_FLOATS["skip"]
_ID_SKIP_AND_MASK = slice(CAMERA_IDS.index("skip"), None, CAMERA_IDS.index("view_mask") - CAMERA_IDS.index("skip"))
_ID_HIDE, _ID_NODE = CAMERA_IDS.index("hide"), CAMERA_IDS.index("node")
assert CAMERA_DTYPE.names[:4] == ("view", "proj", "view_proj", "inv_view_proj")  # the matrices, in order
assert _CAMERA_ROWS.stop - _CAMERA_ROWS.start == _CAMERA_PART.stop - _CAMERA_PART.start  # eye, viewport, clip

_NONE = np.zeros(0, np.int64)
_NO_RECTS = np.zeros((0, 4))
_NEVER = (1e30, 2e30, 1e30, 2e30)  # fade starts no distance or angle reaches
# A rectangle as the cull keeps it, x0, y0, -x1, -y1: its signs, the pixel axis of each
# side, and what each side's NDC value gets before it is scaled to pixels and floored.
_SIGNS = np.array([1.0, 1.0, -1.0, -1.0])
_XYXY = np.array([0, 1, 0, 1])
_OUTWARDS = np.array([1.0, 1.0, -1.0, -1.0])[:, None, None]
_MIN, _MAX = np.minimum.reduce, np.maximum.reduce

# From the rows of a projection (x, y, z, w) and a view's clip plane, the rows
# SurfaceTable.cull applies to the block (clip plane; view matrix) of a view (LevelRows'
# clip_plane and view) and then to every corner: x, y, -x, -y, w, then x - w, y - w, z - w, -x - w,
# -y - w, -z - w (each > 0 outside one side of the frustum), then minus the clip plane.
_CULL_ROWS = np.array([
    [1, 0, 0, 0], [0, 1, 0, 0], [-1, 0, 0, 0], [0, -1, 0, 0], [0, 0, 0, 1],
    [1, 0, 0, -1], [0, 1, 0, -1], [0, 0, 1, -1], [-1, 0, 0, -1], [0, -1, 0, -1], [0, 0, -1, -1]], np.float64)


@dataclass
class _Projection:
    """What the oblique near planes read of a root projection, worked out once per projection."""

    safe_distance: float     # closer to its plane, a view keeps the clip distance alone
    inv_xy_t: np.ndarray     # the inverse's first two columns, transposed
    inv_zw: np.ndarray       # the inverse's last two columns, summed
    column: np.ndarray       # the inverse's third column
    inv_and_column: np.ndarray  # 4 x 5: the inverse, then its third column
    rows_2_3: np.ndarray     # the projection's third and fourth rows, summed
    of: tuple[np.ndarray, np.ndarray]  # the projection and its inverse it was made from


# Kept per root projection (the main camera's, a probe face's: a few a frame).
_PROJECTIONS: dict[bytes, _Projection] = {}
_CULLS: dict[bytes, np.ndarray] = {}
_LAST_PROJECTION: list[_Projection | None] = [None]
_LAST_CULL: list = [None, None]  # the last root projection asked for and its rows


def _projection(root_proj: np.ndarray, inv_root_proj: np.ndarray) -> _Projection:
    """The oblique near planes' constants of ``root_proj`` (with its inverse): the last one's
    again for the same read-only arrays (the view tree's, kept while its root's projection
    stays), else found by their bytes."""
    last = _LAST_PROJECTION[0]
    if last is not None and last.of[0] is root_proj and last.of[1] is inv_root_proj \
            and not root_proj.flags.writeable and not inv_root_proj.flags.writeable:
        return last
    key = root_proj.tobytes() + inv_root_proj.tobytes()
    found = _PROJECTIONS.get(key)
    if found is None:
        if len(_PROJECTIONS) > 32:
            _PROJECTIONS.clear()
        near = root_proj[2, 3] / (root_proj[2, 2] - 1.0)
        found = _PROJECTIONS[key] = _Projection(OBLIQUE_SAFE_NEARS * near, inv_root_proj[:, :2].T.copy(),
                                                inv_root_proj[:, 2] + inv_root_proj[:, 3],
                                                inv_root_proj[:, 2].copy(),
                                                np.concatenate([inv_root_proj, inv_root_proj[:, 2:3]], axis=1),
                                                root_proj[2] + root_proj[3], (root_proj, inv_root_proj))
    _LAST_PROJECTION[0] = found
    return found


def _cull_rows(root_proj: np.ndarray) -> np.ndarray:
    """``SurfaceTable.cull``'s 12 x 5 rows for ``root_proj``: ``_CULL_ROWS`` through it, and
    minus the clip plane (column 0: the clip plane comes first in a view's block); the last
    one's again for the same read-only array."""
    last = _LAST_CULL
    if last[0] is root_proj and not root_proj.flags.writeable:
        return last[1]
    key = root_proj.tobytes()
    rows = _CULLS.get(key)
    if rows is None:
        if len(_CULLS) > 32:
            _CULLS.clear()
        rows = _CULLS[key] = np.zeros((12, 5))
        rows[:11, 1:] = _CULL_ROWS @ root_proj
        rows[11, 0] = -1.0
    last[:] = root_proj, rows
    return rows


_HALVES: dict[tuple[int, int], np.ndarray] = {}


def _half_sizes(size: tuple[int, int]) -> np.ndarray:
    """Half a root's width and height, as the cull's 4 x 1 x 1 factor of x0, y0, -x1, -y1."""
    found = _HALVES.get(size)
    if found is None:
        if len(_HALVES) > 32:
            _HALVES.clear()
        found = _HALVES[size] = (0.5 * np.array(size, np.float64))[_XYXY, None, None]
    return found


_ONES = np.ones(256)


def _ones(k: int) -> np.ndarray:
    """k ones (read only: a level's fades where no surface fades)."""
    global _ONES
    if len(_ONES) < k:
        _ONES = np.ones(2 * k)
    return _ONES[:k]


# How many level plans a SurfaceTable keeps (SurfaceTable.plan): a frame's main tree and a
# probe's six faces, a few levels each, with room for a second probe.
PLANS_KEPT = 96


def _rows(matrix: glm.dmat4 | glm.mat4) -> list[float]:
    """A glm matrix's 16 values row by row (LevelRows' layout)."""
    return [value for row in glm.transpose(matrix).to_list() for value in row]

