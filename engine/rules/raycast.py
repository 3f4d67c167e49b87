"""Ray casts against the world's geometry: the nearest triangle of any entity with a MeshRef
and a Transform that a ray hits (for picking, aiming, placing things on walls).

The test is Möller–Trumbore ray/triangle intersection, vectorised with numpy over every
triangle of every candidate entity at once (one pass of array arithmetic per ray, no Python
loop over triangles).  Triangles are kept in world space in a per-entity cache; an entry is
rebuilt only when its entity's world matrix, mesh or pose (its ``Skin`` and ``Morph``: its
triangles where its joints and morph targets put them, as drawn) changed:

* the TransformSystem writes a new ``Transform.world`` matrix object whenever it recomputes a
  pose (its ``world.frame.moved`` set), so an entry keyed on that object's identity goes
  stale exactly when the entity (or an ancestor) moved, even if the caster was not asked
  anything for several frames and missed those frames' moved sets;
* a Transform written this frame before the transform stage (in a game's update, or a
  newly spawned entity) is in ``world.changed(Transform)``: its pose is taken from the
  components as they are now (the parent chain's local matrices), so a ray cast in the game stage sees
  a wall moved a moment ago where it now is.

A cutout's holes (``Material.alpha_cutoff``) are hit like the rest of its triangles, as a
physics collider is in Unity or Godot: the cast is of geometry, not of what its texture shows
(make the gaps geometry, or leave the cutout out with ``where``, to shoot through them).

``raycast(world, origin, direction)`` uses one ``RayCaster`` kept in
``world.resources[RayCaster]``; make your own ``RayCaster(world)`` to hold a separate cache.

``raycast_seen`` follows a ray as the picture shows it: on through each mirror it meets from
the front (reflected by the mirror's own carry, the matrix its view is drawn with) and each
open portal (carried to beyond the partner), so a click on a floor seen in a mirror finds the
real floor where the image shows it (the editor places things so), with the length of the
light's way the seen image holds there.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass

import numpy as np
from pyglm import glm

from components import MeshRef, Morph, Skin, Transform
from engine.core.errors import SpeculumError
from engine.core.skinning import posed_positions
from engine.core.transforms import MAX_PARENT_HOPS, current_world_matrix
from engine.core.world import World
from engine.resources import Surfaces
from engine.rules.visibility_rules import drawn_code, drawn_in, mask_through

EPSILON = 1e-9  # |determinant| below this: the ray runs along the triangle's plane (no hit)
MAX_SEEN_SURFACES = 16  # raycast_seen follows at most this many mirrors and portals (facing pairs)


class RayCastError(SpeculumError, ValueError):
    """A ray that cannot be cast (zero or non-finite direction, non-finite origin)."""


@dataclass(frozen=True)
class RayHit:
    """Where a ray first met the world.

    ``normal`` is the hit triangle's unit geometric normal in world space, turned to face the
    ray's origin (``dot(normal, direction) < 0``); ``front`` says whether that is the side the
    triangle's winding faces (counter-clockwise seen from the front), i.e. the ray hit the
    outside of a closed mesh.  ``triangle`` indexes the mesh's ``indices`` rows."""

    entity: int
    point: glm.vec3
    normal: glm.vec3
    distance: float
    triangle: int
    front: bool


@dataclass
class _Entry:
    """One entity's world-space triangles and what they were computed from."""

    mesh_id: int
    world_key: object  # the Transform.world object they were built from, or a tuple of the matrix
    v0: np.ndarray  # (n, 3) float64
    e1: np.ndarray
    e2: np.ndarray
    normal: np.ndarray  # (n, 3) unit geometric normals (zero for degenerate triangles)
    # What posed them: (its Skin.joint_matrices, its Morph.weights, each None where it has none; dual quaternions)
    pose: tuple = (None, None, False)


class RayCaster:
    """Nearest-hit ray casts over a world's meshes, with a cache of world-space triangles."""

    def __init__(self, world: World) -> None:
        self.world = world
        self._entries: dict[int, _Entry] = {}
        self._order: list[int] = []  # entity of each block in the stacked arrays
        self._stacked: tuple[np.ndarray, ...] | None = None
        self._owner: np.ndarray = np.zeros(0, np.int64)  # block index of each stacked triangle
        self._first: np.ndarray = np.zeros(0, np.int64)  # first stacked row of each block
        self.rebuilds = 0  # entities whose triangles were (re)computed, for tests and profiling

    # --- public --------------------------------------------------------------------------
    def cast(self, origin: glm.vec3 | Sequence[float], direction: glm.vec3 | Sequence[float],
             max_distance: float = math.inf,
             where: Callable[[int], bool] | None = None, ignore: Collection[int] = (),
             two_sided: bool = True) -> RayHit | None:
        """The nearest hit along ``origin + t * direction`` for 0 <= t <= ``max_distance``
        (``distance`` is in units of a unit direction: ``direction`` is normalised first).

        ``where(entity)`` keeps only entities it returns True for (asked once per entity per
        cast), ``ignore`` leaves entities out; ``two_sided=False`` skips triangles seen from
        behind (back-face culling).  Returns None when nothing is hit."""
        o = _vector("origin", origin)
        d = _vector("direction", direction)
        length = float(np.linalg.norm(d))
        if not length > 0.0:
            raise RayCastError(f"ray direction must not be zero, got {tuple(d)}")
        d = d / length
        if not (max_distance >= 0.0):
            raise RayCastError(f"ray max_distance must be >= 0, got {max_distance!r}")
        self._refresh()
        if self._stacked is None or not self._order:
            return None
        v0, e1, e2, normals = self._stacked
        keep_block = np.array([(e not in ignore) and (where is None or bool(where(e))) for e in self._order], bool)
        if not keep_block.any():
            return None
        rows = keep_block[self._owner]
        # Möller–Trumbore: solve origin + t d = v0 + u e1 + v e2 by Cramer's rule, per triangle.
        p = np.cross(d, e2)  # (n, 3)
        det = np.einsum("ij,ij->i", e1, p)
        rows &= np.abs(det) > EPSILON
        if not two_sided:
            rows &= det > 0.0  # the ray sees the counter-clockwise (front) side
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.where(rows, 1.0 / np.where(rows, det, 1.0), 0.0)
            s = o - v0
            u = np.einsum("ij,ij->i", s, p) * inv
            q = np.cross(s, e1)
            v = (q @ d) * inv
            t = np.einsum("ij,ij->i", e2, q) * inv
        rows &= (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (t >= 0.0) & (t <= max_distance)
        if not rows.any():
            return None
        candidates = np.flatnonzero(rows)
        best = int(candidates[np.argmin(t[candidates])])
        block = int(self._owner[best])
        entity = self._order[block]
        distance = float(t[best])
        n = normals[best]
        front = bool(det[best] > 0.0)
        facing = n if float(n @ d) < 0.0 else -n
        point = o + d * distance
        return RayHit(entity, glm.vec3(*point), glm.vec3(*facing), distance, best - int(self._first[block]), front)

    def triangles(self, entity: int) -> np.ndarray:
        """The entity's world-space triangles as an (n, 3, 3) float64 array (corners in
        winding order), from the cache; for a game that needs a face's extent."""
        self._refresh()
        entry = self._entries.get(entity)
        if entry is None:
            raise RayCastError(f"entity {entity} has no MeshRef and Transform, so no triangles to cast against")
        return np.stack([entry.v0, entry.v0 + entry.e1, entry.v0 + entry.e2], axis=1)

    def forget(self) -> None:
        """Drop the whole cache (the next cast rebuilds every entity)."""
        self._entries.clear()
        self._stacked = None
        self._order = []

    # --- cache ---------------------------------------------------------------------------
    def _refresh(self) -> None:
        """Bring the cache up to the world as it is now; restack only when something changed."""
        world = self.world
        written = world.changed(Transform)
        present: set[int] = set()
        dirty = False
        for entity, (mesh_ref, transform) in world.query(MeshRef, Transform):
            present.add(entity)
            entry = self._entries.get(entity)
            key = self._world_key(entity, transform, written)
            mesh = mesh_ref.mesh
            skin = world.try_get(entity, Skin) if mesh.skinned else None
            morph = world.try_get(entity, Morph) if mesh.morph_count else None
            # (a new array or tuple each pose: Skin and Morph copy what they are given)
            pose = (skin.joint_matrices if skin is not None else None, morph.weights if morph is not None else None,
                    skin is not None and skin.skinning == "dual_quaternion")
            if entry is not None and entry.mesh_id == mesh.id and _same_key(entry.world_key, key) \
                    and entry.pose[0] is pose[0] and entry.pose[1] is pose[1] and entry.pose[2] == pose[2]:
                continue
            matrix = _matrix_of(key)
            self._entries[entity] = _build(mesh, matrix, mesh.id, key, pose)
            self.rebuilds += 1
            dirty = True
        gone = [entity for entity in self._entries if entity not in present]
        for entity in gone:
            del self._entries[entity]
        if dirty or gone or self._stacked is None:
            self._restack()

    def _world_key(self, entity: int, transform: Transform, written: set[int]) -> object:
        """What the entity's world matrix is: the TransformSystem's matrix object when nothing
        in its chain was written since, else the matrix worked out from the components now."""
        chain_written = entity in written
        parent = transform.parent
        hops = 0
        while not chain_written and parent is not None and hops < MAX_PARENT_HOPS:
            chain_written = parent in written
            above = self.world.try_get(parent, Transform) if self.world.exists(parent) else None
            parent = above.parent if above is not None else None
            hops += 1
        if chain_written:
            return tuple(current_world_matrix(self.world, transform).to_list())
        return transform.world

    def _restack(self) -> None:
        self._order = list(self._entries)
        if not self._order:
            self._stacked = None
            self._owner = np.zeros(0, np.int64)
            self._first = np.zeros(0, np.int64)
            return
        entries = [self._entries[e] for e in self._order]
        counts = np.array([len(entry.v0) for entry in entries], np.int64)
        self._owner = np.repeat(np.arange(len(entries)), counts)
        self._first = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
        self._stacked = tuple(np.concatenate([getattr(entry, name) for entry in entries])
                              for name in ("v0", "e1", "e2", "normal"))


def raycast(world: World, origin: glm.vec3 | Sequence[float], direction: glm.vec3 | Sequence[float],
            max_distance: float = math.inf,
            where: Callable[[int], bool] | None = None, ignore: Collection[int] = (),
            two_sided: bool = True) -> RayHit | None:
    """``RayCaster.cast`` on the world's shared caster (``shared_caster``)."""
    return shared_caster(world).cast(origin, direction, max_distance, where, ignore, two_sided)


def shared_caster(world: World) -> RayCaster:
    """The world's shared caster (``world.resources[RayCaster]``, made on first use): its
    cache of posed world triangles, which ``raycast`` and ``raycast_seen`` cast against."""
    caster = world.resources.get(RayCaster)
    if caster is None or caster.world is not world:
        caster = world.resources[RayCaster] = RayCaster(world)
    return caster


@dataclass(frozen=True)
class SeenHit:
    """What a ray from an eye meets as the picture shows it (``raycast_seen``): ``hit`` where
    the thing really is (world space; its ``distance`` the last stretch's), ``through`` the
    mirrors and portals the ray went on through, in order, and ``way`` the length of the whole
    way (the seen image's, ``shaders/include/way.glsl``)."""

    hit: RayHit
    through: tuple[int, ...]
    way: float


def raycast_seen(world: World, origin: glm.vec3 | Sequence[float], direction: glm.vec3 | Sequence[float],
                 where: Callable[[int], bool] | None = None, ignore: Collection[int] = (),
                 max_surfaces: int = MAX_SEEN_SURFACES, view_mask: int | None = None) -> SeenHit | None:
    """``raycast``, followed on through each enabled mirror met from its front (the ray
    reflected by the mirror's ``carry``) and each open portal met from its front (the point and
    the ray carried by the pair to beyond the partner, which the next stretch leaves out), as
    the surfaces stage left them (``Surfaces``; none there: a plain cast).  A surface met
    from behind, switched off, or past ``max_surfaces`` is the hit itself.  ``where`` and
    ``ignore`` as for ``raycast``, on every stretch.  With ``view_mask`` (the mask of the view
    the ray leaves: ``View.view_mask``) each stretch meets only what its view draws (the
    visibility rule: ``drawn_in``), the view through each surface passed being
    ``mask_through`` it, as the planner makes it: a thing hidden in mirror views is met in
    the direct view and passed through in a mirror.  None when a stretch meets nothing."""
    surfaces = world.resources.get(Surfaces)
    o = glm.vec3(*_vector("origin", origin))
    d = _vector("direction", direction)
    length = float(np.linalg.norm(d))
    if not length > 0.0:
        raise RayCastError(f"ray direction must not be zero, got {tuple(d)}")
    d = glm.vec3(*(d / length))
    through: list[int] = []
    way = 0.0
    left_out = set(ignore)
    mask = view_mask
    while True:
        hit = raycast(world, o, d, where=where if mask is None else _drawn_and(world, where, mask), ignore=left_out)
        if hit is None:
            return None
        way += hit.distance
        state = None if surfaces is None else surfaces.mirrors.get(hit.entity) or surfaces.portals.get(hit.entity)
        if state is None or not state.enabled or glm.dot(glm.vec3(state.plane), d) >= 0.0 \
                or len(through) >= max_surfaces:
            return SeenHit(hit, tuple(through), way)
        through.append(hit.entity)
        if mask is not None:
            mask = mask_through(mask, state.kind == "mirror", state.layers)
        o = glm.vec3(state.carry * glm.vec4(hit.point, 1.0))
        d = glm.normalize(glm.vec3(state.carry * glm.vec4(d, 0.0)))
        left_out = set(ignore) | {state.exit_entity}


# --- helpers ---------------------------------------------------------------------------------

def _drawn_and(world: World, where: Callable[[int], bool] | None, mask: int) -> Callable[[int], bool]:
    """``where`` (None: anything) and drawn by a view of ``mask`` (``drawn_in``)."""
    return lambda entity: (where is None or bool(where(entity))) and bool(drawn_in(drawn_code(world, entity), mask))


def _vector(name: str, value) -> np.ndarray:
    try:
        v = np.array([float(c) for c in value], np.float64)
    except (TypeError, ValueError):
        raise RayCastError(f"ray {name} must be 3 numbers, got {value!r}") from None
    if v.shape != (3,) or not np.isfinite(v).all():
        raise RayCastError(f"ray {name} must be 3 finite numbers, got {value!r}")
    return v


def _same_key(a: object, b: object) -> bool:
    if isinstance(a, tuple) or isinstance(b, tuple):
        return isinstance(a, tuple) and isinstance(b, tuple) and a == b
    return a is b


def _matrix_of(key: object) -> np.ndarray:
    """A 4x4 float64 row-major model matrix from a world key (glm.mat4 or its column tuple)."""
    columns = key if isinstance(key, tuple) else key.to_list()
    return np.array(columns, np.float64).T


def _build(mesh, matrix: np.ndarray, mesh_id: int, key: object, pose: tuple = (None, None, False)) -> _Entry:
    positions = posed_positions(mesh, *pose)  # where its Morph and Skin put them, as drawn
    world = positions @ matrix[:3, :3].T + matrix[:3, 3]
    tri = world[np.asarray(mesh.indices)]
    v0 = np.ascontiguousarray(tri[:, 0])
    e1 = np.ascontiguousarray(tri[:, 1] - tri[:, 0])
    e2 = np.ascontiguousarray(tri[:, 2] - tri[:, 0])
    cross = np.cross(e1, e2)
    length = np.linalg.norm(cross, axis=1)
    normal = np.divide(cross, length[:, None], out=np.zeros_like(cross), where=length[:, None] > 0.0)
    return _Entry(mesh_id, key, v0, e1, e2, normal, pose)
