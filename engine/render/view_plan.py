"""Planning a reflection level in arrays: which (parent view x surface) pairs get a view,
where on screen, and each view's camera, for all pairs of a level at once.

A view tree level is planned in a fixed number of numpy operations whatever its number of
views: the parents of a level are rows of arrays (``LevelRows``), every mirror and portal
is a row of ``SurfaceTable``, and ``SurfaceTable.cull`` and ``plan_candidates`` work on
(parents x surfaces) blocks.  Per view, only what the draws need is made in Python (a
``View`` holding its packed camera block).  Planning a view one at a
time with glm cost ~30 us a view on llvmpipe's machine (one glm call is ~0.3 us, and a
view took about a hundred); a level in arrays costs a few us a view.

Conventions: matrices here are numpy (..., 4, 4) arrays in the usual row-major math
layout (``M @ x``); glm's and GL's are column-major, so they are transposed at the edges.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from pyglm import glm

from components.limits import VIEW_DIRECT, VIEW_KINDS, VIEW_MIRROR, VIEW_PORTAL
from engine.core.reflection_math import OBLIQUE_SAFE_NEARS
from engine.render.views import CAMERA_BLOCK_BYTES, PlannedView, View

# The mirror and portal records the surfaces stage publishes (``engine.resources.SurfaceState``,
# plain data above this floor): read here by their fields.
SurfaceState = Any

_CAMERA_FLOATS = CAMERA_BLOCK_BYTES // 4
_KINDS_BUT_DIRECT = ((1 << VIEW_KINDS) - 1) & ~VIEW_DIRECT  # a view through a surface is no longer direct


def _mat(matrix: glm.mat4) -> np.ndarray:
    """A glm matrix as a row-major numpy one."""
    return np.frombuffer(matrix.to_bytes(), np.float32).reshape(4, 4).T.astype(np.float64)


class LevelRows:
    """The views of one level of a tree as arrays, a row each (the root: one row), packed
    in one float64 array so that a level's rows are gathered in one operation."""

    WIDTH = 48  # view 0-15, inv_view 16-31, eye 32-35, clip 36-39, rect 40-43, exit 44, mirrored 45, node 46,
    # view mask 47 (its kinds and layers: View.view_mask)

    def __init__(self, data: np.ndarray) -> None:
        self.data = data

    @property
    def view(self) -> np.ndarray:
        """(n, 4, 4) world -> eye."""
        return self.data[:, 0:16].reshape(-1, 4, 4)

    @property
    def inv_view(self) -> np.ndarray:
        """(n, 4, 4) eye -> world."""
        return self.data[:, 16:32].reshape(-1, 4, 4)

    @property
    def eye(self) -> np.ndarray:
        """(n, 4) homogeneous world position."""
        return self.data[:, 32:36]

    @property
    def clip(self) -> np.ndarray:
        """(n, 4) world clip plane (what the view keeps)."""
        return self.data[:, 36:40]

    @property
    def rect(self) -> np.ndarray:
        """(n, 4) x0, y0, x1, y1 where it shows, screen pixels."""
        return self.data[:, 40:44]

    @property
    def exit(self) -> np.ndarray:
        """(n,) the entity the view looks out of (-1: none)."""
        return self.data[:, 44]

    @property
    def mirrored(self) -> np.ndarray:
        """(n,) 1.0 where front faces wind clockwise."""
        return self.data[:, 45]

    @property
    def node(self) -> np.ndarray:
        """(n,) the view's index in the tree."""
        return self.data[:, 46]

    @property
    def mask(self) -> np.ndarray:
        """(n,) int64: the view's kinds and the layers it shows (``View.view_mask``)."""
        return self.data[:, 47].astype(np.int64)

    @staticmethod
    def root(view: View) -> LevelRows:
        data = np.empty((1, LevelRows.WIDTH))
        data[0, 0:16] = _mat(view.view).reshape(16)
        data[0, 16:32] = _mat(glm.inverse(view.view)).reshape(16)
        data[0, 32:48] = (*view.eye, 1.0, *view.clip_plane, 0.0, 0.0, *view.size, -1.0, float(view.mirrored), 0.0,
                          float(view.view_mask))
        return LevelRows(data)


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

    def select(self, keep: np.ndarray) -> Candidates:
        """The candidates at ``keep`` (indices or a mask), in their order."""
        return Candidates(self.parent[keep], self.surface[keep], LevelRows(self.rows.data[keep]), self.scissor[keep],
                          self.blocks[keep], self.size, self.fade[keep],
                          None if self.end is None else self.end[keep])


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
        self.corner_columns = self.corners.transpose(0, 2, 1).copy()  # S x 4 x 8: the corners as columns
        self.enabled = np.array([s.enabled for s in states], bool)
        self.max_depth = np.array([s.max_depth for s in states], np.int64)
        self.entities = np.array([s.entity for s in states], np.int64)
        self.deepest = int(self.max_depth[self.enabled].max()) if self.enabled.any() else 0
        # What carries a parent's camera through each surface (a reflection, or the portal pair).
        self.carry = np.array([_mat(s.carry) for s in states]).reshape(count, 4, 4)
        self.inv_carry = np.linalg.inv(self.carry) if count else self.carry
        self.exit_planes = np.array([tuple(s.exit_plane) for s in states], np.float64).reshape(count, 4)
        self.exit_entities = np.array([s.exit_entity for s in states], np.int64)
        self.is_mirror = np.array([s.kind == "mirror" for s in states], bool)
        # The kind a view through each surface gains, and the layers each shows (a view shows
        # the layers every surface of its chain shows).
        self.kind_bit = np.where(self.is_mirror, VIEW_MIRROR, VIEW_PORTAL).astype(np.int64)
        self.layers = np.array([s.layers for s in states], np.int64)
        self.scale = np.array([s.resolution_scale for s in states], np.float64)
        self.priority = np.array([s.priority for s in states], np.int64)
        self.end_image = self._end_images(states)
        # Fades (Mirror.fade_distance, fade_angle): start and end of each, and each surface's
        # bounding sphere; a surface without fades never fades.
        self.fades = [s.fade for s in states]
        self.fading = any(f is not None for f in self.fades)
        if self.fading:
            self.fade = np.array([f if f is not None else _NEVER for f in self.fades], np.float64)
            self.centres = self.corners[:, :, :3].mean(axis=1)
            self.radii = np.linalg.norm(self.corners[:, :, :3] - self.centres[:, None, :], axis=2).max(axis=1)

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

    def cull(self, parents: LevelRows, depth: int, root_proj: np.ndarray, root_size: tuple[int, int],
             depth_cap: int, ends: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                                     np.ndarray | None]:
        """Each (parent, surface) where the parent view can see the surface, with the screen
        rectangle where it can show: enabled and within its depth, not the surface the view
        looks out of, facing the view's eye (a mirror facing away shows nothing, as the
        "Multiple Mirrors" project notes), not wholly behind the view's clip plane, inside
        the frustum and overlapping the parent's rectangle.  ``depth`` is the level the
        views would be on.  Returns (parent rows, surface rows, rects x0 y0 x1 y1), parent
        major, and the fade weights of the pairs seen before the fades (None: no surface
        fades; a pair faded out, weight 0, is not returned).  Every pair goes through the
        same few array operations: in a frame, after the rasteriser has run, each numpy call
        costs about twice what it does in a warm loop (measured), so their number is what
        counts here.  With ``ends`` (a mask of surfaces), the pairs of those surfaces the depth
        limits cut are kept too: the end views (``engine/render/end_images.py``)."""
        if not len(parents.node):
            return _NONE, _NONE, _NO_RECTS, None
        within = depth <= np.minimum(self.max_depth, depth_cap)
        if ends is not None:
            keep = self.enabled & (within | ends)
        elif depth > min(self.deepest, depth_cap):
            return _NONE, _NONE, _NO_RECTS, None  # nothing enabled may be seen this deep
        else:
            keep = self.enabled & within
        # First what needs no corners, for every pair: enabled and within its depth, not the
        # surface the view looks out of, and facing the view's eye.
        keep = keep & (parents.exit[:, None] != self.entities) & (parents.eye @ self.planes.T > 0.0)
        p, s = np.nonzero(keep)
        if not len(p):
            return _NONE, _NONE, _NO_RECTS, None
        # Per parent, one 11 x 4 matrix: times a corner, the corner in clip space (the
        # view-projection with the root projection, as the rectangle is in root pixels), then
        # six values that are > 0 outside each side of the frustum (x > w, x < -w, ...) and
        # the corner's side of the parent's clip plane.  Per pair: 11 values x 8 corners.
        rows_in = np.concatenate([root_proj @ parents.view, parents.clip[:, None, :]], axis=1)  # P x 5 x 4
        clip = (_CULL_ROWS @ rows_in)[p] @ self.corner_columns[s]                          # K x 11 x 8
        # Corners first: numpy reduces over a leading axis ~15x faster than over a short last one.
        clip = np.ascontiguousarray(clip.transpose(2, 0, 1))                                # 8 x K x 11
        least, most = clip.min(axis=0), clip.max(axis=0)                                    # K x 11
        # Culled: every corner outside one side of the frustum, or every corner behind the clip plane.
        seen = ~(least[:, 4:10] > 0.0).any(axis=1) & (most[:, 10] > 0.0)
        w = clip[:, :, 3]
        ndc = clip[:, :, 0:2] / np.where(w <= 1e-6, 1.0, w)[:, :, None]                   # 8 x K x 2
        half = 0.5 * np.array(root_size, np.float64)
        lo = np.floor((ndc.min(axis=0) + 1.0) * half) - 1.0                                 # K x 2
        hi = np.ceil((ndc.max(axis=0) + 1.0) * half) + 1.0
        straddles = least[:, 3] <= 1e-6  # a corner behind the eye: be conservative
        lo[straddles], hi[straddles] = -np.inf, np.inf
        rect = parents.rect[p]
        x0y0 = np.maximum(lo, rect[:, 0:2])
        x1y1 = np.minimum(hi, rect[:, 2:4])
        seen &= (x1y1 > x0y0).all(axis=1)
        p, s, rects = p[seen], s[seen], np.concatenate([x0y0[seen], x1y1[seen]], axis=1)
        if not self.fading:
            return p, s, rects, None
        fade = self.fade_weights(parents.eye[p], s)
        kept = fade > 0.0  # faded out: no view at all (the weights of the pairs kept say how many went)
        return p[kept], s[kept], rects[kept], np.where(kept, fade, 0.0)

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
        """The next level's candidate views from ``parents`` (level ``depth - 1``): the
        cull's pairs, each with its camera (the parent's carried through the surface: for a
        mirror its reflection, for a portal look-out x half turn x inverse(look-in), as in
        the DirectX "magic mirrors" write-up), clipped at the plane it looks out of, with
        Lengyel's oblique near plane there unless the eye is too close (then the clip
        distance alone), its claim rectangle in the level's pixels, and its packed Camera
        block (None when nothing can be seen), and how many pairs the
        fades took out.  ``ends``: those surfaces' end views too (``cull``; marked in
        ``Candidates.end``); ``size``: the level's pixels, when given; ``scale``: a factor on
        the level's resolution (the frame's pixel budget, ``ViewTree``)."""
        p, s, rects, weights = self.cull(parents, depth, root_proj, root.size, depth_cap, ends)
        faded = 0 if weights is None else int((weights == 0.0).sum())
        fade = None if weights is None else weights[weights > 0.0]
        k = len(p)
        if not k:
            return None, faded
        if size is None:
            scale *= float(self.scale[s].max())
            size = (max(1, round(root.size[0] * scale)), max(1, round(root.size[1] * scale)))
        parent = LevelRows(parents.data[p])
        data = np.empty((k, LevelRows.WIDTH))
        rows = LevelRows(data)
        view, inv_view = rows.view, rows.inv_view
        np.matmul(parent.view, self.inv_carry[s], out=view)
        np.matmul(self.carry[s], parent.inv_view, out=inv_view)
        eye = inv_view[:, :, 3]  # where the carried camera is: its eye-to-world translation
        data[:, 32:36] = eye
        data[:, 36:40] = clip = self.exit_planes[s]
        data[:, 40:44] = rects
        data[:, 44] = skip = self.exit_entities[s]
        data[:, 45] = parent.mirrored != self.is_mirror[s]
        data[:, 46] = np.arange(first_index, first_index + k)
        mask = parent.mask
        mask = (mask & _KINDS_BUT_DIRECT) | self.kind_bit[s] | (mask & (self.layers[s] << VIEW_KINDS))
        data[:, 47] = mask
        proj, inv_proj = _oblique_projections(root_proj, inv_root_proj, inv_view, eye, clip)
        scissor = level_rects(rects, root.size, size)
        # The Camera blocks (camera.glsl): four column-major matrices, then eye, viewport,
        # clip plane and ids; the matrices are written straight into their columns.
        blocks = np.empty((k, _CAMERA_FLOATS), np.float32)
        matrices = blocks[:, 0:64].reshape(k, 4, 4, 4).transpose(0, 1, 3, 2)
        matrices[:, 0] = view
        matrices[:, 1] = proj
        np.matmul(proj, view, out=matrices[:, 2])
        np.matmul(inv_view, inv_proj, out=matrices[:, 3])
        blocks[:, 64:68] = eye
        blocks[:, 68:72] = (0.0, 0.0, *size)
        blocks[:, 72:76] = clip
        ids = blocks[:, 76:80].view(np.uint32)
        ids[:, 0], ids[:, 1], ids[:, 2], ids[:, 3] = skip, hide, mask, 0
        end = None if ends is None else depth > np.minimum(self.max_depth[s], depth_cap)
        return Candidates(p, s, rows, scissor, blocks, size, fade if fade is not None else np.ones(k),
                          end), faded


def planned_views(table: SurfaceTable, candidates: Candidates, hide: int) -> list[PlannedView]:
    """A ``PlannedView`` for each candidate (what the scene pass and the composite read): its
    Camera block already packed; its matrices are read from the block
    only if something asks for them."""
    states = table.states
    size = candidates.size
    blocks = candidates.blocks.tobytes()
    step = CAMERA_BLOCK_BYTES
    views = []
    for i, (s, mirrored, node, scissor) in enumerate(zip(
            candidates.surface.tolist(), (candidates.rows.mirrored > 0.0).tolist(),
            candidates.rows.node.astype(np.int64).tolist(),
            candidates.scissor.tolist(), strict=True)):
        state = states[s]
        views.append(PlannedView(blocks[i * step:(i + 1) * step], size,
                                 state.kind, state.entity, state.exit_plane, mirrored, tuple(scissor), node,
                                 state.exit_entity, hide))
    return views


def _oblique_projections(root_proj: np.ndarray, inv_root_proj: np.ndarray, inv_view: np.ndarray, eye: np.ndarray,
                         clip: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lengyel's oblique near plane for each view (``reflection_math.oblique_projection``, in
    arrays), and the projections' inverses: the root projection's third row replaced so that
    the clip plane, in view space, is the near plane; the root projection where the eye is
    too close to the plane.  One row changes, so each inverse is a rank-one update of the
    root's (Sherman-Morrison), not a 4 x 4 inversion."""
    plane = np.matmul(clip[:, None, :], inv_view)[:, 0]  # planes transform by the inverse transpose; the
    # construction below is unchanged by the plane's (positive) scale, so it is not normalised
    near = root_proj[2, 3] / (root_proj[2, 2] - 1.0)
    safe = np.abs((clip * eye).sum(axis=1)) > OBLIQUE_SAFE_NEARS * near
    q = np.sign(plane[:, :2]) @ inv_root_proj[:, :2].T + (inv_root_proj[:, 2] + inv_root_proj[:, 3])
    c = plane * (2.0 / (plane * q).sum(axis=1))[:, None]
    change = np.where(safe[:, None], c - root_proj[3] - root_proj[2], 0.0)  # the third row's change
    proj = np.repeat(root_proj[None], len(plane), axis=0)
    proj[:, 2] += change
    # The inverse: P = P0 + e2 change^T, so P^-1 = P0^-1 - (P0^-1 e2)(change^T P0^-1) / (1 + change^T P0^-1 e2).
    column = inv_root_proj[:, 2]
    row = (change @ inv_root_proj) / (1.0 + change @ column)[:, None]
    inv_proj = inv_root_proj - column[None, :, None] * row[:, None, :]
    return proj, inv_proj


def level_rects(rects: np.ndarray, screen: tuple[int, int], level: tuple[int, int]) -> np.ndarray:
    """Screen-pixel rectangles (x0, y0, x1, y1) as (x, y, width, height) in the pixels of a
    level of another size (rounded outwards, at least one pixel)."""
    if level == screen:
        xy = rects[:, 0:2]
        return np.concatenate([xy, rects[:, 2:4] - xy], axis=1).astype(np.int64)
    s = np.array(level, np.float64) / np.array(screen, np.float64)
    x0y0 = np.floor(rects[:, 0:2] * s)
    x1y1 = np.minimum(np.array(level, np.float64), np.ceil(rects[:, 2:4] * s))
    return np.concatenate([x0y0, np.maximum(1.0, x1y1 - x0y0)], axis=1).astype(np.int64)


_NONE = np.zeros(0, np.int64)
_NO_RECTS = np.zeros((0, 4))
_NEVER = (1e30, 2e30, 1e30, 2e30)  # fade starts no distance or angle reaches

# From the rows of a view-projection (x, y, z, w) and a clip plane, the rows SurfaceTable.cull
# applies to every corner: x, y, z, w, then x - w, y - w, z - w, -x - w, -y - w, -z - w (each
# > 0 outside one side of the frustum), then the clip plane.
_CULL_ROWS = np.array([
    [1, 0, 0, 0, 0], [0, 1, 0, 0, 0], [0, 0, 1, 0, 0], [0, 0, 0, 1, 0],
    [1, 0, 0, -1, 0], [0, 1, 0, -1, 0], [0, 0, 1, -1, 0],
    [-1, 0, 0, -1, 0], [0, -1, 0, -1, 0], [0, 0, -1, -1, 0],
    [0, 0, 0, 0, 1]], np.float64)
