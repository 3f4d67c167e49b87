"""Decals: each ``Decal``'s box cut out of the surfaces in it, as a mesh of its own drawn over
them (``engine/core/decal_clip.py`` says how a cut is made).

A decal's mesh lives on an entity this stage makes for it: a child of the decal's entity
(so it moves with the decal) carrying a ``FromDecal``, a MeshRef of the cut triangles in the
decal's box space (casting no shadow) and a Material with the decal's look; the extract
stage puts it in the transparent slot with a depth offset (``Renderer.batch_for``'s
``decal``), so every view draws it after the surface it lies on and before any glass.

Work is done only when something changed: a decal is cut again when its ``Decal``, its
``Visibility`` or its place changes, or when a surface that took it (or now reaches into its
box) moves, changes its mesh, material or layers, or goes; each surface's piece is cut on its
own and kept while its pose relative to the decal stays the same (a crate turning under a
floor's stain cuts the crate's piece alone; a decal parented with its wall under a moving
platform is not cut again).  To find the surfaces a box reaches without a look at every
entity, the stage keeps every candidate surface's world box in arrays (``ReceiverBoxes``),
made when the first decal comes, brought up to date with the frame's movers, and dropped
when the last decal goes; the entities holding a Decal are kept from the change sets, so a
level without decals asks the world nothing.

It runs after the transform stage (it reads world matrices and the frame's movers) and
before extract; a new part's Transform is worked out by the transform stage's system again
at once (``settle``), so the part is drawn this frame."""
from __future__ import annotations

import weakref
from collections.abc import Callable
from dataclasses import dataclass, field

import esper
import numpy as np
from pyglm import glm

from components import Emissive, Material, MeshRef, Mirror, Portal, PortalClone, Refractive, Transform, Visibility
from components.decal import Decal, FromDecal
from components.tracking import warn_component
from components.visibility import DEFAULT_LAYERS
from engine.assets.mesh import Mesh
from engine.core.decal_clip import DecalGeometry, decal_geometry, join_geometry, soup
from engine.core.world import World
from engine.rules.probe_rules import world_bounds

# How far a surface's pose relative to its decal may drift (box-space units, matrix entries)
# before its cut is made again: float32 world matrices of two entities moved together agree
# to about 1e-7 relative.
_SAME_POSE = 1e-5
_LOW_BITS, _HIGH_BITS = np.array([1, 2, 4], np.uint8), np.array([8, 16, 32], np.uint8)  # a vertex beyond a side
_HALF_CUBE = np.array([[-0.5, -0.5, -0.5], [0.5, 0.5, 0.5]])  # a decal's box, in its own space
_CORNERS = np.array([[x, y, z, 1.0] for x in (0, 1) for y in (0, 1) for z in (0, 1)])


def _matrix(m: glm.mat4) -> np.ndarray:
    """A glm matrix as numpy's (4, 4), rows as in the maths (numpy's copy of a glm matrix is
    row by row, though glm indexes it by columns)."""
    return np.array(m, np.float64)


def _placed_boxes(lows: np.ndarray, highs: np.ndarray, worlds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World bounds of boxes [lows, highs] (N, 3) placed by ``worlds`` (N, 4, 4): their
    corners', min and max, for all N at once."""
    corners = np.where(_CORNERS[None, :, :3] > 0, highs[:, None, :], lows[:, None, :])  # (N, 8, 3)
    placed = np.einsum("nij,nkj->nki", worlds[:, :3, :3], corners) + worlds[:, None, :3, 3]
    return placed.min(axis=1), placed.max(axis=1)


class ReceiverBoxes:
    """Every surface that could take a decal, with its world box, in arrays: entity -> row."""

    def __init__(self) -> None:
        self.row: dict[int, int] = {}
        self.entities: list[int] = []
        self.low = np.zeros((0, 3))
        self.high = np.zeros((0, 3))

    def put(self, entity: int, low: np.ndarray, high: np.ndarray) -> None:
        row = self.row.get(entity)
        if row is None:
            row = self.row[entity] = len(self.entities)
            self.entities.append(entity)
            if row >= len(self.low):
                grown = max(16, 2 * len(self.low))
                self.low = np.resize(self.low, (grown, 3))
                self.high = np.resize(self.high, (grown, 3))
        self.low[row], self.high[row] = low, high

    def drop(self, entity: int) -> None:
        row = self.row.pop(entity, None)
        if row is None:
            return
        last = len(self.entities) - 1
        moved = self.entities.pop()
        if row != last:  # the last row fills the hole
            self.entities[row] = moved
            self.row[moved] = row
            self.low[row], self.high[row] = self.low[last], self.high[last]

    def reaching(self, low: np.ndarray, high: np.ndarray) -> list[int]:
        """The entities whose boxes meet the box [low, high]."""
        n = len(self.entities)
        meets = (self.low[:n] <= high).all(axis=1) & (self.high[:n] >= low).all(axis=1)
        return [self.entities[i] for i in np.flatnonzero(meets)]


@dataclass
class _Piece:
    """The decal on one surface, and what it was cut from."""

    mesh_id: int                        # the surface's Mesh.id
    pose: np.ndarray                    # its matrix into the decal's box space
    geometry: DecalGeometry | None      # None: nothing of it takes the decal (turned away, faded out)


@dataclass
class _DecalState:
    """What a decal's cut was made from, to tell whether it must be made again."""

    low: np.ndarray                    # the decal's box, world bounds
    high: np.ndarray
    pieces: dict[int, _Piece] = field(default_factory=dict)  # by the surface it lies on
    part: int | None = None            # the entity holding its mesh (None: nothing in its box takes it)


class DecalSystem(esper.Processor):
    """Cuts each decal's surfaces into its part's mesh, again when they or it change."""

    def __init__(self, world: World, settle: Callable[[float], None]) -> None:
        super().__init__()
        self.world = world
        self.settle = settle  # the transform stage's work again (a part made after it ran)
        self.states: dict[int, _DecalState] = {}
        self.holders: set[int] = set()  # the entities with a Decal
        self.boxes: ReceiverBoxes | None = None
        self._mesh_bounds: weakref.WeakKeyDictionary[Mesh, np.ndarray] = weakref.WeakKeyDictionary()
        self.cuts = 0  # decals' meshes made (or made again) since the start: what tests count
        self.pieces_cut = 0  # surfaces' pieces cut since the start
        self._said_alone: set[int] = set()  # decals said to show nowhere (_say_on_views_alone)

    def process(self, dt: float) -> None:
        world = self.world
        # The entities holding a Decal, kept from the change sets (a frame without decals asks
        # the world nothing: a look at two sets).
        written = world.changed(Decal)  # (added, removed or written)
        deleted = world.deleted()
        if written or (deleted and self.holders):
            self.holders = {e for e in self.holders | written if e not in deleted and world.has(e, Decal)}
        if not self.holders and not self.states:
            self.boxes = None
            return
        frame = world.frame
        gone = deleted | frame.removed
        if gone or written:
            for entity in [e for e in self.states if e in gone or not world.has(e, Decal)
                           or not world.has(e, Transform)]:
                self._drop(entity)
        # The surfaces that changed this frame (moved, came, went, a new mesh, material or
        # layers): their boxes brought up to date, and the decals they reach, before or now, cut
        # again.  A still frame stops here.
        looks = world.changed_any((MeshRef, Visibility, Mirror, Portal, Material, Refractive))
        touched = frame.moved | frame.added | gone | looks
        changed_decals = written | (world.changed(Visibility) & self.holders)
        if self.boxes is not None and not touched and not changed_decals:
            return
        reached: set[int] = set()
        if self.boxes is None:
            self.boxes = ReceiverBoxes()
            self._put_boxes([e for e, _ in world.query(MeshRef, Transform) if self._receives(e)])
        elif touched:
            boxes = self.boxes
            rows = [boxes.row[e] for e in touched if e in boxes.row]  # where they were
            reached |= self._decals_meeting(boxes.low[rows], boxes.high[rows])
            # Whether each can take a decal is asked again only where its components changed
            # (a mover that only moved keeps its answer).
            again = frame.added | gone | looks | written
            receiving = [e for e in touched if (self._receives(e) if e in again else e in boxes.row)]
            for entity in touched:
                if entity in boxes.row:
                    boxes.drop(entity)
            reached |= self._decals_meeting(*self._put_boxes(receiving))  # where they are
        decals = [(e, (world.get(e, Decal), transform)) for e in sorted(self.holders)
                  if (transform := world.try_get(e, Transform)) is not None]
        spawned = False
        for entity, (decal, transform) in decals:
            state = self.states.get(entity)
            if state is None or entity in changed_decals or entity in touched or entity in reached \
                    or not touched.isdisjoint(state.pieces):
                spawned |= self._refresh(entity, decal, transform, state, entity in changed_decals or state is None)
        if spawned:
            self.settle(dt)

    # --- the surfaces -------------------------------------------------------------------------
    def _receives(self, entity: int) -> bool:
        """Whether ``entity`` is a surface a decal may be thrown on."""
        world = self.world
        if not world.exists(entity):
            return False
        mesh_ref = world.try_get(entity, MeshRef)
        if mesh_ref is None or not mesh_ref.visible or not world.has(entity, Transform):
            return False
        mesh = mesh_ref.mesh
        if mesh.skinned or mesh.morph_count or world.has(entity, FromDecal) or world.has(entity, Mirror) \
                or world.has(entity, Portal) or world.has(entity, PortalClone) or world.has(entity, Decal):
            return False
        # A see-through surface (faded by its alpha) is glass in the transparent slot, which
        # the decals' cut meshes precede: a decal there would be blended under it.
        material = world.try_get(entity, Material)
        return material is None or material.color.w >= 1.0 or material.alpha_cutoff is not None \
            or world.has(entity, Refractive)

    def _put_boxes(self, entities: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """Put ``entities``' world boxes in the table (all at once); the boxes."""
        if not entities:
            return np.zeros((0, 3)), np.zeros((0, 3))
        world = self.world
        meshes = [world.get(e, MeshRef).mesh for e in entities]
        bounds = np.array([self._bounds(mesh) for mesh in meshes])  # (N, 2, 3)
        worlds = np.array([world.get(e, Transform).world for e in entities], np.float64)  # rows as in the maths
        lows, highs = _placed_boxes(bounds[:, 0], bounds[:, 1], worlds)
        for entity, low, high in zip(entities, lows, highs, strict=True):
            self.boxes.put(entity, low, high)
        return lows, highs

    def _bounds(self, mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
        """A mesh's own bounds, kept while it lives (``Mesh.bounds`` reads every vertex)."""
        found = self._mesh_bounds.get(mesh)
        if found is None:
            found = self._mesh_bounds[mesh] = np.array(mesh.bounds)
        return found

    def _decals_meeting(self, lows: np.ndarray, highs: np.ndarray) -> set[int]:
        """The decals whose boxes meet any of the boxes [lows, highs]."""
        if not len(lows) or not self.states:
            return set()
        entities = list(self.states)
        d_low = np.array([self.states[e].low for e in entities])
        d_high = np.array([self.states[e].high for e in entities])
        meets = ((lows[:, None] <= d_high[None]).all(axis=2) & (highs[:, None] >= d_low[None]).all(axis=2)).any(axis=0)
        return {entities[i] for i in np.flatnonzero(meets)}

    # --- a decal's cut --------------------------------------------------------------------------
    def _refresh(self, entity: int, decal: Decal, transform: Transform, state: _DecalState | None,
                 look_changed: bool) -> bool:
        """Cut ``entity``'s decal again where its surfaces or their poses changed (each
        surface's piece on its own: a crate turning under a floor's stain cuts the crate's
        piece alone); its part's look where its Decal or Visibility did.  Whether a part was made."""
        world = self.world
        box_world = _matrix(transform.world)
        lows, highs = _placed_boxes(_HALF_CUBE[None, 0], _HALF_CUBE[None, 1], box_world[None])
        low, high = lows[0], highs[0]
        to_box = np.linalg.inv(box_world)
        if state is None:
            state = self.states[entity] = _DecalState(low, high)
        state.low, state.high = low, high
        layers = decal.layers
        pieces: dict[int, _Piece] = {}
        changed = look_changed or (state.part is not None and not world.exists(state.part))  # (deleted by hand)
        for surface in self.boxes.reaching(low, high):
            if layers is not None:
                shown = world.try_get(surface, Visibility)
                if not set(shown.layers if shown is not None else DEFAULT_LAYERS) & set(layers):
                    continue
            mesh = world.get(surface, MeshRef).mesh
            pose = to_box @ _matrix(world.get(surface, Transform).world)
            kept = state.pieces.get(surface)
            if not look_changed and kept is not None and kept.mesh_id == mesh.id \
                    and np.allclose(pose, kept.pose, rtol=0.0, atol=_SAME_POSE):
                pieces[surface] = kept
                continue
            pieces[surface] = _Piece(mesh.id, pose, self._cut(decal, box_world, surface, mesh, pose))
            self.pieces_cut += 1
            changed = True
        changed |= pieces.keys() != state.pieces.keys()
        state.pieces = pieces
        if not pieces and look_changed:
            self._say_on_views_alone(entity, low, high)
        if not changed:
            return False
        self.cuts += 1
        geometry = join_geometry([p.geometry for p in pieces.values() if p.geometry is not None])
        if geometry is None:
            if state.part is not None:
                self._delete_part(state)
            return False
        mesh = Mesh(geometry.positions, geometry.normals, geometry.uvs,
                    np.arange(len(geometry.positions), dtype=np.int32).reshape(-1, 3),
                    name=f"decal {entity}", colors=np.concatenate(
                        [np.ones((len(geometry.alphas), 3), np.float32), geometry.alphas[:, None]], axis=1))
        if state.part is not None and world.exists(state.part):
            part = state.part
            world.get(part, MeshRef).mesh = mesh
            if look_changed:
                self._dress(part, entity, decal)
            return False
        state.part = world.spawn(Transform(parent=entity), MeshRef(mesh, casts_shadows=False),
                                 FromDecal(decal=entity, order=decal.order))
        self._dress(state.part, entity, decal)
        return True

    def _say_on_views_alone(self, entity: int, low: np.ndarray, high: np.ndarray) -> None:
        """Where a decal, made or changed, reaches no surface that takes one but meets a
        mirror or portal (a sticker put on a mirror), say once that it shows nowhere: such a
        surface's picture is the view beyond it (the Decal's docstring)."""
        if entity in self._said_alone:
            return
        world = self.world
        for kind in (Mirror, Portal):
            for surface, _ in world.query_one(kind):
                mesh_ref, transform = world.try_get(surface, MeshRef), world.try_get(surface, Transform)
                if mesh_ref is None or transform is None:
                    continue
                lo, hi = world_bounds(mesh_ref.mesh, transform.world)
                if np.all(lo <= high) and np.all(hi >= low):
                    self._said_alone.add(entity)
                    warn_component(f"Decal on entity {entity}: its box meets the {kind.__name__} of entity {surface} "
                                   f"and no surface that takes a decal: mirrors and portals take none (their picture "
                                   f"is the view beyond them), nor water, see-through or posed surfaces, so it "
                                   f"shows nowhere")
                    return

    def _cut(self, decal: Decal, box_world: np.ndarray, surface: int, mesh: Mesh,
             pose: np.ndarray) -> DecalGeometry | None:
        """The piece of the decal on one surface (``pose``: its matrix into box space)."""
        axis = box_world[:3, 2] / max(np.linalg.norm(box_world[:3, 2]), 1e-30)  # whence it comes, in the world
        surface_world = _matrix(self.world.get(surface, Transform).world)
        positions = mesh.positions @ pose[:3, :3].T + pose[:3, 3]
        # Only the triangles whose bounds meet the box go on (a small decal on a big mesh:
        # the soup and its normals are made for a few of its triangles, not all): a bit a
        # vertex for each of the box's six sides it lies beyond, and a triangle whose three
        # vertices share one lies wholly beyond that side.
        beyond = (positions < -0.5) @ _LOW_BITS | (positions > 0.5) @ _HIGH_BITS
        triangle_beyond = beyond[mesh.indices[:, 0]] & beyond[mesh.indices[:, 1]] & beyond[mesh.indices[:, 2]]
        indices = mesh.indices[triangle_beyond == 0]
        if not len(indices):
            return None
        used = np.unique(indices)
        to_surface = np.linalg.inv(surface_world[:3, :3])
        normals = mesh.normals[used]
        world_normals = normals @ to_surface          # inverse transpose, rows
        world_normals /= np.maximum(np.linalg.norm(world_normals, axis=1, keepdims=True), 1e-30)
        box_normals = normals @ to_surface @ box_world[:3, :3]
        triangles = soup(positions[used], box_normals, world_normals @ axis, np.searchsorted(used, indices))
        return decal_geometry(triangles, decal.angle_fade, decal.depth_fade, decal.region)

    def _dress(self, part: int, entity: int, decal: Decal) -> None:
        """The part's look: a Material (and Emissive, Visibility, its order) from the decal's."""
        world = self.world
        cut = world.get(part, FromDecal)
        if cut.order != decal.order:
            cut.order = decal.order
        world.add_component(part, Material(color=glm.vec4(decal.color), texture=decal.texture,
                                           normal_map=decal.normal_map, normal_scale=decal.normal_scale,
                                           roughness=decal.roughness, metallic=decal.metallic,
                                           alpha_cutoff=decal.alpha_cutoff))
        self._match(part, Emissive, Emissive(decal.emissive) if decal.emissive > 0.0 else None)
        shown = world.try_get(entity, Visibility)
        self._match(part, Visibility, None if shown is None else Visibility(
            direct=shown.direct, in_mirrors=shown.in_mirrors, in_portals=shown.in_portals,
            in_probes=shown.in_probes, layers=shown.layers))

    def _match(self, part: int, kind: type, component) -> None:
        world = self.world
        if component is not None:
            world.add_component(part, component)
        elif world.has(part, kind):
            world.remove_component(part, kind)

    def _delete_part(self, state: _DecalState) -> None:
        if state.part is not None and self.world.exists(state.part):
            self.world.delete_entity(state.part)
        state.part = None

    def _drop(self, entity: int) -> None:
        self._delete_part(self.states.pop(entity))
        self._said_alone.discard(entity)

    def close(self) -> None:
        self.states.clear()
        self.holders.clear()
        self.boxes = None
        self._mesh_bounds.clear()
