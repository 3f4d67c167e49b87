"""Planar reflections: the ReflectionSystem schedules one view per visible (mirror, path).

Per frame, after the main view is drawn into level 0:
  1. cull   - for every view of level L and every mirror or portal at once (SurfaceTable):
              skip it if disabled, too deep, facing away, behind the view's own mirror,
              outside the frustum or off the view's rectangle;
  2. claim  - each candidate takes, in level L+1's node image and depth mask, the pixels
              where level L shows it; a samples query counts them, and a candidate with
              none gets no view (MirrorPasses.prepare_level);
  3. render - each view: mirrored camera, oblique near plane (or clip distance close up),
              scissored to the mirror's rectangle, front faces clockwise; one draw per
              mesh per view (Renderer.render_reflection_views), or the whole level in one
              draw per mesh (the batched path);
  4. repeat for mirrors seen in those reflections, up to the depth limits;
  5. composite, deepest level first: blend each level's views into their mirrors' pixels
              one level up (one instanced draw per level).
Levels are screen-sized (times the largest resolution_scale of their mirrors), so memory
is bounded by (levels x one screen), however many mirrors.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import esper
import numpy as np
from pyglm import glm

from components import MeshRef, Mirror, Portal, Transform
from engine.errors import SpeculumError
from engine.mesh import flat_plane
from engine.portal_math import pair_transform, portal_plane
from engine.reflection_math import (
    oblique_is_safe,
    oblique_projection,
    plane_from_point_normal,
    reflection_matrix,
    transform_plane,
)
from engine.render.batched_mirrors import BatchedMirrors, choose_path, submitted_triangles
from engine.render.mirror_passes import (
    MAX_LEVEL_VIEWS,
    Claim,
    Composite,
    CompositeSurface,
    MirrorPasses,
    PreparedComposites,
    composite_surface,
)
from engine.render.renderer import Renderer
from engine.render.views import View
from engine.world import World
from systems.render_system import RenderSystem

# Mirrors clip a hair in front of their plane, so their own surface never shows in them.
CLIP_OFFSET = 1e-3
# A mirror mesh thinner than this fraction of its size composites over its outline quad;
# anything thicker (a mirror plane given explicitly on a solid mesh) over its rectangle.
FLAT_OUTLINE_TOLERANCE = 1e-3


class MirrorError(SpeculumError, ValueError):
    """A Mirror component on something that cannot be a mirror."""


@dataclass
class SurfaceState:
    """A mirror or a portal as the passes see it: where it is and where its view goes."""

    entity: int
    kind: str                    # "mirror" or "portal"
    plane: glm.vec4              # world; its normal points to the side it is seen from
    corners: np.ndarray          # world corners, homogeneous rows
    outline: np.ndarray | None   # for a flat surface: its 4 world corners as a 2 x 2 grid (a quad), else None
    carry: glm.mat4              # takes the parent camera to this surface's view (a reflection, or the pair)
    exit_plane: glm.vec4         # what the view keeps: the mirror's front, or the look-out portal's front
    exit_entity: int             # the surface the view looks out of: the mirror itself, or the partner
    max_depth: int
    enabled: bool = True
    tint: glm.vec4 = field(default_factory=lambda: glm.vec4(1.0))
    reflect_rate: float = 1.0
    roughness: float = 0.0
    resolution_scale: float = 1.0
    look: CompositeSurface = field(init=False, repr=False)  # what its composite reads, packed once

    def __post_init__(self) -> None:
        self.look = composite_surface(self.tint, self.reflect_rate, self.roughness, glm.vec3(self.plane),
                                      self.outline, portal=self.kind == "portal", carry=glm.mat3(self.carry))


@dataclass
class ReflectionView:
    """One node of the view tree: a view at some level, looking into one mirror or portal."""

    index: int
    level: int
    view: View
    rect: tuple[int, int, int, int]   # where it shows, in screen (level 0) pixels
    surface: SurfaceState | None = None
    parent: ReflectionView | None = None


@dataclass
class LevelCandidates:
    """The views a reflection level may have, before its claims say which have pixels."""

    found: list[tuple[ReflectionView, SurfaceState, tuple[int, int, int, int]]]  # (parent, surface, screen rect)
    size: tuple[int, int]          # the level's pixels
    claims: list[Claim]
    views: list[View]              # each candidate's camera, in claim order
    next_index: int                # the first view index the level after may use


class ReflectionSystem(esper.Processor):
    """Renders and composites mirror reflections after the main view, before present."""

    def __init__(self, world: World, render_system: RenderSystem, renderer: Renderer,
                 max_depth_cap: int = 8) -> None:
        self.world = world
        self.render_system = render_system
        self.renderer = renderer
        self.passes = MirrorPasses(renderer)
        self.max_depth_cap = max_depth_cap
        self.mirrors: dict[int, SurfaceState] = {}
        self.portals: dict[int, SurfaceState] = {}
        self.views: list[ReflectionView] = []   # last frame's view tree, level order
        # How a level's views are drawn: "per_mirror" (each view its own draws), "batched" (one
        # draw per mesh for the whole level, engine/render/batched_mirrors.py) or "auto"
        # (chosen per level by view and triangle count; the rule and its numbers: choose_path).
        self.path = "auto"
        self.batched = BatchedMirrors(renderer)

    # --- extract ---------------------------------------------------------------------------
    def _refresh_mirrors(self) -> None:
        world = self.world
        touched = world.changed(Mirror) | world.changed(MeshRef)
        touched |= {e for e in world.frame.moved | world.frame.added if e in self.mirrors or e in touched}
        for entity in touched:
            mirror = world.try_get(entity, Mirror) if world.exists(entity) else None
            if mirror is None:
                self.mirrors.pop(entity, None)
                continue
            mesh_ref = world.try_get(entity, MeshRef)
            transform = world.try_get(entity, Transform)
            if mesh_ref is None or transform is None:
                raise MirrorError(f"entity {entity}: a Mirror needs a MeshRef and a Transform")
            self.mirrors[entity] = self._mirror_state(entity, mirror, mesh_ref, transform)

    def _refresh_portals(self) -> None:
        """Portals depend on their partner's pose too; there are few, so all are redone."""
        world = self.world
        self.portals = {}
        for entity, (portal, transform) in world.query(Portal, Transform):
            partner = portal.partner
            out = world.try_get(partner, Transform) if partner is not None and world.exists(partner) else None
            if out is None or not world.has(partner, Portal):
                continue  # closed: the scene shader shows its closed colour
            w, h = portal.size
            corners = np.array([(x, y, 0.0, 1.0) for x in (-w / 2, w / 2) for y in (-h / 2, h / 2)])
            corners = corners @ np.array(transform.world.to_list(), np.float64)
            self.portals[entity] = SurfaceState(
                entity, "portal", portal_plane(transform.world), corners, corners,
                pair_transform(transform.world, out.world), portal_plane(out.world), partner,
                portal.max_depth, portal.enabled)

    @staticmethod
    def _mirror_state(entity: int, mirror: Mirror, mesh_ref: MeshRef, transform: Transform) -> SurfaceState:
        mesh = mesh_ref.mesh
        if mirror.plane_normal is not None:
            point = np.array(mirror.plane_point if mirror.plane_point is not None else (0.0, 0.0, 0.0))
            normal = np.array(mirror.plane_normal)
        else:
            found = flat_plane(mesh)
            if found is None:
                lo, hi = mesh.bounds
                raise MirrorError(
                    f"entity {entity}: Mirror on mesh {mesh.name!r} which is not flat (model-space "
                    f"extents {np.round(hi - lo, 4).tolist()}); give the mirror a flat mesh or plane_normal")
            point, normal = found
        model = transform.world
        local_plane = plane_from_point_normal(tuple(float(v) for v in point), tuple(float(v) for v in normal))
        plane = transform_plane(model, local_plane)
        lo, hi = mesh.bounds
        corners = np.array([(x, y, z, 1.0) for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        corners = corners @ np.array(model.to_list(), np.float64)
        # A flat mesh's box has its corners in pairs across the flat axis: one of each pair is
        # the mesh's outline on its plane (what the composite covers instead of the rectangle).
        extents = hi - lo
        flat_axis = int(np.argmin(extents))
        outline = None
        if extents[flat_axis] <= FLAT_OUTLINE_TOLERANCE * max(float(extents.max()), 1e-9):
            outline = corners[[i for i in range(8) if not (i >> (2 - flat_axis)) & 1]]
        return SurfaceState(entity, "mirror", plane, corners, outline,
                            reflection_matrix(plane), plane, entity, mirror.max_depth, mirror.enabled,
                            mirror.color, mirror.reflect_rate, mirror.roughness, mirror.resolution_scale)

    # --- schedule and render -----------------------------------------------------------------
    def process(self, dt: float) -> None:
        self._refresh_mirrors()
        self._refresh_portals()
        self.views = []
        main = self.render_system.main_view
        if main is None:
            return
        renderer = self.renderer
        if self.mirrors or self.portals:
            # The main view rasterises while the CPU culls and works out the first level's
            # cameras; the same after each level's views (engine/raw_gl.py says why).
            renderer.flush()
        root = ReflectionView(0, 0, main, (0, 0, *main.size))
        levels = [[root]]
        self.views = [root]
        paths = set()
        composites: list[PreparedComposites] = []
        surfaces = SurfaceTable([*self.mirrors.values(), *self.portals.values()])
        candidates = self._candidates(surfaces, [root], main, 1)
        for level in range(self.max_depth_cap):
            if candidates is None:
                break
            targets = renderer.level_targets(level + 1, candidates.size)
            pixels = self.passes.prepare_level(targets, renderer.levels[level], candidates.claims)
            children = []
            for (parent, state, rect), view, count in zip(candidates.found, candidates.views, pixels, strict=True):
                if count and len(children) < MAX_LEVEL_VIEWS:
                    children.append(ReflectionView(view.node, level + 1, view, rect, state, parent))
            if not children:
                break
            path = choose_path(self.path, len(children), submitted_triangles(renderer))
            paths.add(path)
            if path == "batched":
                self.batched.render_level([c.view for c in children], targets)
            else:
                renderer.render_reflection_views([c.view for c in children], targets)
            renderer.flush()
            levels.append(children)
            self.views.extend(children)
            # While the GPU draws the views: the next level's cull and cameras (measured: on
            # the critical path when done after the views finish), then their composite rows.
            candidates = self._candidates(surfaces, children, main, candidates.next_index)
            composites.append(self._prepare_composite(children, main, renderer.levels[level].size))
        for level in range(len(levels) - 1, 0, -1):
            self.passes.composite_level(renderer.levels[level - 1], renderer.levels[level], composites[level - 1])
        renderer.stats.reflection_views = len(self.views) - 1
        renderer.stats.reflection_path = paths.pop() if len(paths) == 1 else ("mixed" if paths else "")

    def _candidates(self, surfaces: SurfaceTable, parents: list[ReflectionView], main: View,
                    first_index: int) -> LevelCandidates | None:
        """The next level's candidate views: every (parent, surface) the cull keeps, its claim
        (view indices from ``first_index``) and its camera, packed; None when there are none.
        Needs no pixels, so it is done while the GPU draws the parents."""
        found = surfaces.cull(parents, main, self.max_depth_cap)
        if not found:
            return None
        scale = max(state.resolution_scale for _, state, _ in found)
        size = (max(1, round(main.size[0] * scale)), max(1, round(main.size[1] * scale)))
        claims = [Claim(parent.index, state.entity, first_index + k, _to_level(rect, main.size, size))
                  for k, (parent, state, rect) in enumerate(found)]
        views = [self._surface_view(parent, state, main, claim.index, size, claim.rect)
                 for (parent, state, _), claim in zip(found, claims, strict=True)]
        for view in views:
            view.camera_block()  # packed now, not on the critical path of the views' draws
        return LevelCandidates(found, size, claims, views, first_index + len(claims))

    def _prepare_composite(self, children: list[ReflectionView], main: View,
                           parent_size: tuple[int, int]) -> PreparedComposites:
        """The composite of a level's views into the level above (``parent_size`` pixels)."""
        return self.passes.prepare_composites([Composite(
            child.index, _to_level(child.rect, main.size, parent_size), child.view.scissor, child.parent.view,
            child.surface.look) for child in children], parent_size)

    @staticmethod
    def _surface_view(parent: ReflectionView, state: SurfaceState, main: View, index: int,
                      size: tuple[int, int], scissor: tuple[int, int, int, int]) -> View:
        """The parent's camera carried through the surface (for a mirror: ``mirrored_view``;
        for a portal: seed 001's look-out x half turn x inverse(look-in)), clipped at the
        plane it looks out of, with an oblique near plane there unless the eye is too close."""
        eye = glm.vec3(state.carry * glm.vec4(parent.view.eye, 1.0))
        view = parent.view.view * glm.inverse(state.carry)
        exit_plane = state.exit_plane
        clip_plane = glm.vec4(glm.vec3(exit_plane), exit_plane.w - CLIP_OFFSET)
        proj = main.proj
        if oblique_is_safe(eye, exit_plane, _near_distance(main.proj)):
            proj = oblique_projection(main.proj, transform_plane(view, clip_plane))
        mirrored = parent.view.mirrored != (state.kind == "mirror")
        return View(view=view, proj=proj, eye=eye, size=size, name=f"{state.kind} {state.entity}",
                    clip_plane=clip_plane, mirrored=mirrored, scissor=scissor, node=index)

    def mirror_planes(self) -> dict[int, tuple[list[float], list[float]]]:
        """Each mirror's world plane as (point on it, unit normal towards its front)."""
        planes = {}
        for entity, state in self.mirrors.items():
            n = glm.vec3(state.plane)
            planes[entity] = (list(-state.plane.w * n), list(n))
        return planes

    def close(self) -> None:
        self.passes.release()
        self.batched.release()


class SurfaceTable:
    """Every mirror and portal as arrays, so one view culls them all with a few numpy
    operations (the per-surface Python loop was most of the reflection system's CPU time)."""

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
        self.deepest = int(self.max_depth[self.enabled].max()) if self.enabled.any() else 0

    def cull(self, parents: list[ReflectionView], main: View,
             depth_cap: int) -> list[tuple[ReflectionView, SurfaceState, tuple[int, int, int, int]]]:
        """Each (parent, surface) where the parent view can see the surface, with the screen
        rectangle where it can show: enabled and within its depth, not the surface the view
        looks out of, facing the view's eye (seed 000's tip), not wholly behind the view's
        clip plane, inside the frustum and overlapping the parent's rectangle.  All parents
        are one level deep.  Every (parent, surface) pair goes through the same few array
        operations: in a frame, after the rasteriser has run, each numpy call costs about
        twice what it does in a warm loop (measured), so their number is what counts here."""
        depth = parents[0].level + 1 if parents else 0
        if not parents or depth > min(self.deepest, depth_cap):
            return []  # nothing enabled may be seen this deep (also: no surfaces at all)
        # Per parent: eye (homogeneous, 4), rectangle corners (x0, y0, x1, y1) and exit entity.
        rows = np.array([(*p.view.eye, 1.0, p.rect[0], p.rect[1], p.rect[0] + p.rect[2], p.rect[1] + p.rect[3],
                          p.surface.exit_entity if p.surface else -1) for p in parents], np.float64)
        eyes, rects, exits = rows[:, 0:4], rows[:, 4:8], rows[:, 8]
        # Per parent, one 4 x 11 matrix: corner rows @ it give the corners in clip space (the
        # view-projection with the main projection, as the rectangle is in screen pixels),
        # then six values that are > 0 outside each side of the frustum (x > w, x < -w, ...)
        # and the corner's side of the parent's clip plane.
        rows_in = np.frombuffer(b"".join(glm.transpose(main.proj * p.view.view).to_bytes()
                                         + p.view.clip_plane.to_bytes() for p in parents),
                                np.float32).reshape(len(parents), 5, 4)
        to_clip = _CULL_ROWS @ rows_in
        clip = (self.corners.reshape(1, -1, 4) @ to_clip.transpose(0, 2, 1)).reshape(len(parents), -1, 8, 11)
        keep = self.enabled & (depth <= np.minimum(self.max_depth, depth_cap))
        keep = keep & (exits[:, None] != self.entities) & (eyes @ self.planes.T > 0.0)
        # Culled: every corner outside one side of the frustum, or every corner behind the clip plane.
        outside = np.concatenate([clip[..., 4:10] > 0.0, clip[..., 10:11] <= 0.0], axis=3)
        keep &= ~outside.all(axis=2).any(axis=2)
        w = clip[..., 3]
        behind = w <= 1e-6
        straddles = behind.any(axis=2)  # corners behind the eye: be conservative
        ndc = clip[..., :2] / np.where(behind, 1.0, w)[..., None]
        half = 0.5 * np.array(main.size)
        lo = np.where(straddles[..., None], -np.inf, np.floor((ndc.min(axis=2) + 1.0) * half) - 1.0)  # P x S x 2
        hi = np.where(straddles[..., None], np.inf, np.ceil((ndc.max(axis=2) + 1.0) * half) + 1.0)
        x0y0 = np.maximum(lo, rects[:, None, 0:2])
        x1y1 = np.minimum(hi, rects[:, None, 2:4])
        keep &= (x1y1 > x0y0).all(axis=2)
        found = []
        for p, i in np.argwhere(keep).tolist():
            x0, y0 = int(x0y0[p, i, 0]), int(x0y0[p, i, 1])
            found.append((parents[p], self.states[i], (x0, y0, int(x1y1[p, i, 0]) - x0, int(x1y1[p, i, 1]) - y0)))
        return found


# From the rows of a view-projection (x, y, z, w) and a clip plane, the rows SurfaceTable.cull
# applies to every corner: x, y, z, w, then x - w, y - w, z - w, -x - w, -y - w, -z - w (each
# > 0 outside one side of the frustum), then the clip plane.
_CULL_ROWS = np.array([
    [1, 0, 0, 0, 0], [0, 1, 0, 0, 0], [0, 0, 1, 0, 0], [0, 0, 0, 1, 0],
    [1, 0, 0, -1, 0], [0, 1, 0, -1, 0], [0, 0, 1, -1, 0],
    [-1, 0, 0, -1, 0], [0, -1, 0, -1, 0], [0, 0, -1, -1, 0],
    [0, 0, 0, 0, 1]], np.float32)


def _near_distance(proj: glm.mat4) -> float:
    """The near-plane distance of a standard GL perspective matrix."""
    a, b = proj[2][2], proj[3][2]
    return b / (a - 1.0)


def _to_level(rect: tuple[int, int, int, int], screen: tuple[int, int],
              level: tuple[int, int]) -> tuple[int, int, int, int]:
    """A screen-pixel rectangle in the pixels of a level of another size (rounded outwards)."""
    if level == screen:
        return rect
    sx, sy = level[0] / screen[0], level[1] / screen[1]
    x0, y0 = int(rect[0] * sx), int(rect[1] * sy)
    x1 = min(level[0], int(np.ceil((rect[0] + rect[2]) * sx)))
    y1 = min(level[1], int(np.ceil((rect[1] + rect[3]) * sy)))
    return x0, y0, max(1, x1 - x0), max(1, y1 - y0)

