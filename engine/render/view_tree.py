"""The view tree: mirrors and portals seen from a root view, level by level.

A root is any view with its own targets: the main camera (``ReflectionSystem``), and next a
cube-map probe's faces.  From it, ``ViewTree.render`` runs the loop of planar reflections
and portals:

  1. cull   - for every view of level L and every mirror or portal at once (SurfaceTable):
              skip it if disabled, too deep, facing away, behind the view's own mirror,
              outside the frustum or off the view's rectangle;
  2. claim  - each candidate takes, in level L+1's node image and depth mask, the pixels
              where level L shows it; a samples query counts them, and a candidate with
              none gets no view (MirrorPasses.prepare_level);
  3. render - the level's views through the scene pass (``ScenePass.draw``): the parent's
              camera carried through the surface, oblique near plane (or clip distance
              close up), only its claimed pixels; view by view, or all in one draw per
              mesh through the geometry shader (the batched path);
  4. repeat for surfaces seen in those views, up to the depth limits;
  5. composite, deepest level first: blend each level's views into their surfaces' pixels
              one level up (one instanced draw per level and composite variant).

Levels are the size of the root's targets (times the largest resolution_scale of their
surfaces), so memory is bounded by (levels x one root image), however many surfaces.
Limits, each a setting and each reported in ``RenderStats`` when reached: the depth cap
(``TreeSettings.depth_cap``, at most ``MAX_TREE_DEPTH``) and an optional view budget per
level (``TreeSettings.level_budget``: the views with the most claimed pixels are kept).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from pyglm import glm

from components.limits import MAX_VIEW_DEPTH
from engine.core.reflection_math import oblique_is_safe, oblique_projection, transform_plane
from engine.render.batched_mirrors import PATHS, choose_path, submitted_triangles
from engine.render.mirror_passes import (
    Claim,
    Composite,
    MirrorPasses,
    PreparedComposites,
    surface_look,
)
from engine.render.scene_pass import REFLECTION_LEVEL, SceneOptions
from engine.render.targets import LevelStack
from engine.render.views import View

# The deepest a tree may go (each level is one more set of root-sized targets); the depth
# limits of Mirror and Portal components take values up to this.
MAX_TREE_DEPTH = MAX_VIEW_DEPTH  # the depth cap's limit: the components' own
_BATCHED = SceneOptions(clear=False, masked=True, sky=False, batched=True, reflection_filter=True)

# The mirror and portal records the surfaces stage publishes (``engine.resources.SurfaceState``,
# plain data above this floor): read here by their fields.
SurfaceState = Any


@dataclass(frozen=True)
class TreeSettings:
    """The limits and the drawing path of one view tree."""

    depth_cap: int = 8                 # levels below the root, whatever the surfaces' own limits
    level_budget: int | None = None    # most views a level draws (None: every view with pixels)
    path: str = "auto"                 # "per_mirror", "batched" or "auto" (batched_mirrors.choose_path)

    def __post_init__(self) -> None:
        if not isinstance(self.depth_cap, int) or isinstance(self.depth_cap, bool) \
                or not 0 <= self.depth_cap <= MAX_TREE_DEPTH:
            raise ValueError(f"view tree depth_cap must be an int in [0, {MAX_TREE_DEPTH}], got {self.depth_cap!r}")
        if self.level_budget is not None and (not isinstance(self.level_budget, int) or self.level_budget < 1):
            raise ValueError(f"view tree level_budget must be None or an int >= 1, got {self.level_budget!r}")
        if self.path not in PATHS:
            raise ValueError(f"view tree path must be one of {PATHS}, got {self.path!r}")


@dataclass
class TreeResult:
    """What one render of a tree drew, and what its limits cut."""

    views: list[ReflectionView]   # the root first, then level by level
    paths: set[str]               # how the levels were drawn
    dropped: int = 0              # views with pixels left out by the level budget
    capped: int = 0               # views the surfaces' own limits allowed below the depth cap


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


class ViewTree:
    """Renders the reflection levels below a root view into a ``LevelStack`` and composites
    them back into the root's targets."""

    def __init__(self, renderer) -> None:
        self.renderer = renderer
        self.passes = MirrorPasses(renderer)

    def render(self, root: View, levels: LevelStack, surfaces: SurfaceTable,
               settings: TreeSettings = TreeSettings()) -> TreeResult:
        """Draw every level below ``root`` (already drawn into ``levels[0]``) and composite them."""
        renderer = self.renderer
        root_node = ReflectionView(0, 0, root, (0, 0, *root.size))
        result = TreeResult([root_node], set())
        composites: list[PreparedComposites] = []
        candidates = self._candidates(surfaces, [root_node], root, 1, settings.depth_cap)
        level = 0
        children: list[ReflectionView] = []
        while candidates is not None and level < settings.depth_cap:
            targets = levels.get(level + 1, candidates.size)
            pixels = self.passes.prepare_level(targets, levels[level], candidates.claims)
            children = [ReflectionView(view.node, level + 1, view, rect, state, parent)
                        for (parent, state, rect), view, count in zip(candidates.found, candidates.views, pixels,
                                                                      strict=True) if count]
            if settings.level_budget is not None and len(children) > settings.level_budget:
                by_pixels = dict(zip((v.node for v in candidates.views), pixels, strict=True))
                kept = sorted(children, key=lambda c: -by_pixels[c.index])[: settings.level_budget]
                result.dropped += len(children) - len(kept)
                children = sorted(kept, key=lambda c: c.index)
            if not children:
                break
            path = choose_path(settings.path, len(children), submitted_triangles(renderer))
            result.paths.add(path)
            renderer.scene_pass.draw([c.view for c in children], targets,
                                     _BATCHED if path == "batched" else REFLECTION_LEVEL)
            renderer.flush()
            result.views.extend(children)
            level += 1
            # While the GPU draws the views: the next level's cull and cameras (measured: on
            # the critical path when done after the views finish), then their composite rows.
            candidates = self._candidates(surfaces, children, root, candidates.next_index, settings.depth_cap)
            composites.append(self._prepare_composite(children, root, levels[level - 1].size))
        if children and level == settings.depth_cap:
            # Reaching the cap is reported: how many views the surfaces' own limits still allowed.
            result.capped = len(surfaces.cull(children, root, MAX_TREE_DEPTH))
        for depth in range(level, 0, -1):
            self.passes.composite_level(levels[depth - 1], levels[depth], composites[depth - 1])
        return result

    def _candidates(self, surfaces: SurfaceTable, parents: list[ReflectionView], root: View,
                    first_index: int, depth_cap: int) -> LevelCandidates | None:
        """The next level's candidate views: every (parent, surface) the cull keeps, its claim
        (view indices from ``first_index``) and its camera, packed; None when there are none.
        Needs no pixels, so it is done while the GPU draws the parents."""
        found = surfaces.cull(parents, root, depth_cap)
        if not found:
            return None
        scale = max(state.resolution_scale for _, state, _ in found)
        size = (max(1, round(root.size[0] * scale)), max(1, round(root.size[1] * scale)))
        claims = [Claim(parent.index, state.entity, first_index + k, _to_level(rect, root.size, size))
                  for k, (parent, state, rect) in enumerate(found)]
        views = [self._surface_view(parent, state, root, claim.index, size, claim.rect)
                 for (parent, state, _), claim in zip(found, claims, strict=True)]
        for view in views:
            view.camera_block()  # packed now, not on the critical path of the views' draws
        return LevelCandidates(found, size, claims, views, first_index + len(claims))

    def _prepare_composite(self, children: list[ReflectionView], root: View,
                           parent_size: tuple[int, int]) -> PreparedComposites:
        """The composite of a level's views into the level above (``parent_size`` pixels)."""
        return self.passes.prepare_composites([Composite(
            child.index, _to_level(child.rect, root.size, parent_size), child.view.scissor, child.parent.view,
            surface_look(child.surface)) for child in children], parent_size)

    @staticmethod
    def _surface_view(parent: ReflectionView, state: SurfaceState, root: View, index: int,
                      size: tuple[int, int], scissor: tuple[int, int, int, int]) -> View:
        """The parent's camera carried through the surface (for a mirror: its reflection; for
        a portal: look-out x half turn x inverse(look-in), as in the DirectX "magic mirrors"
        write-up), clipped at the plane it looks out of, with an oblique near plane there
        unless the eye is too close.  The projection is the root's: levels map onto it
        pixel for pixel."""
        eye = glm.vec3(state.carry * glm.vec4(parent.view.eye, 1.0))
        view = parent.view.view * glm.inverse(state.carry)
        # Clipped exactly at the plane it looks out of (what touches a mirror meets its
        # reflection without a crack); the surface on that plane is left out by entity.
        clip_plane = state.exit_plane
        proj = root.proj
        if oblique_is_safe(eye, clip_plane, _near_distance(root.proj)):
            proj = oblique_projection(root.proj, transform_plane(view, clip_plane))
        mirrored = parent.view.mirrored != (state.kind == "mirror")
        return View(view=view, proj=proj, eye=eye, size=size, name=f"{state.kind} {state.entity}",
                    clip_plane=clip_plane, mirrored=mirrored, scissor=scissor, node=index,
                    skip=state.exit_entity, hide=parent.view.hide)

    def release(self) -> None:
        self.passes.release()


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

    def cull(self, parents: list[ReflectionView], root: View,
             depth_cap: int) -> list[tuple[ReflectionView, SurfaceState, tuple[int, int, int, int]]]:
        """Each (parent, surface) where the parent view can see the surface, with the screen
        rectangle where it can show: enabled and within its depth, not the surface the view
        looks out of, facing the view's eye (a mirror facing away shows nothing, as the "Multiple
        Mirrors" project notes), not wholly behind the view's
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
        # view-projection with the root projection, as the rectangle is in root pixels),
        # then six values that are > 0 outside each side of the frustum (x > w, x < -w, ...)
        # and the corner's side of the parent's clip plane.
        rows_in = np.frombuffer(b"".join(glm.transpose(root.proj * p.view.view).to_bytes()
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
        half = 0.5 * np.array(root.size)
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

