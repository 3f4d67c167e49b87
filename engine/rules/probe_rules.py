"""The probe rules: which reflection probe an object samples, what changes a look, what a
probe face sees and what relights a probe.  Worked out from components alone (no GL), so
the extract stage (which builds instance rows), the probes scheduler (which picks the faces
to capture) and the captures agree.

Sampling.  An object samples a probe when it is ``Reflective("cube")`` or ``Refractive``
(glass refracts what the probe saw behind it), or when it is a plain lit mesh (no
``Reflective``, ``Mirror`` or ``Portal``: its material's environment reflection reads the
probes whose boxes hold it, as Unity's and HDRP's probes serve every renderer in their
volumes): ``samples_a_probe``, the one definition (``probe_samplers`` finds them all).  It
samples:
  - its own probe, when it has a ``ReflectionProbe`` component;
  - else the probes whose influence boxes hold its position, blended by weight
    (``probe_blend``: each box's weight falls off to 0 over its ``blend_distance`` inside its
    walls; the MAX_BLENDED_PROBES strongest are sampled, their weights normalised only when
    they add up to more than 1, and what is left of 1 is the sky's); when its mesh is not
    flat, what is left is its own probe's instead (below);
  - else, when its mesh is not flat and it is cube-reflective or refractive (not a plain
    mesh: ``has_own_probe``), a probe of its own at its bounding box's centre (made
    by the probes stage; the chrome-sphere case: material detection as in the OpenGL 4
    course chapter "Texture Effects": a flat reflective mesh is a planar mirror, any other
    a cube map);
  - else nothing: it reflects the sky.
A mirror or portal seen with no view of its own shows the boxes' blend at its centre, the sky
taking the rest (``surface_blend``, the reflection fallback).
A probe is known by the entity that owns it (the ReflectionProbe's, or the object's own).
``probe_for`` is the strongest of them: the one an object is said to sample.

Looks.  ``LOOK_KINDS`` (with why each kind is there) and ``LookChanges`` (those, plus the
objects whose sampled probe changed) say whose look changed this frame: the extract stage
rewrites their rows, the probes scheduler recaptures the faces that see them.

Faces.  A face sees what is in its frustum (``faces_touched``) and what its mirror and portal
views show (``images_through_surfaces``), never the probe's own object.  A point light
relights what is in its range (``lights_reaching``); ``LIGHTING_KINDS`` relight everything.
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from pyglm import glm

from components import (
    DirectionalLight,
    Emissive,
    FromDecal,
    HemisphereLight,
    Material,
    MeshRef,
    Mirror,
    Monitor,
    Morph,
    Portal,
    PortalClone,
    ReflectionProbe,
    Reflective,
    Refractive,
    Skin,
    Skybox,
    Slice,
    Transform,
    Visibility,
    Water,
)
from engine.assets.mesh import Mesh, flat_plane
from engine.core.cube_faces import CUBE_FACES
from engine.core.skinning import posed_bounds
from engine.core.world import World
from engine.resources import SurfaceState
from engine.rules.frame_rules import world_corners

_FLAT: dict[int, bool] = {}  # mesh id -> flat (meshes do not change once made)


def is_flat(mesh: Mesh) -> bool:
    flat = _FLAT.get(mesh.id)
    if flat is None:
        flat = _FLAT[mesh.id] = flat_plane(mesh) is not None
    return flat


SAMPLER_KINDS = (Reflective, Refractive)  # an entity that samples a probe has one of these


def _samples(reflective: Reflective | None, refractive: bool) -> bool:
    """The rule: cube-reflective, or refractive (glass refracts what its probe saw)."""
    return (reflective is not None and reflective.mode == "cube") or refractive


def _plain(world: World, entity: int) -> bool:
    """A plain lit mesh: no Reflective, Mirror or Portal decides what it reflects."""
    return (world.has(entity, MeshRef) and not world.has(entity, Reflective) and not world.has(entity, Mirror)
            and not world.has(entity, Portal))


def plain_meshes(world: World) -> set[int]:
    """Every plain lit mesh (``_plain``), by sets of the components' holders: one pass over
    each kind, not a look at each mesh's components."""
    meshes = {entity for entity, _ in world.query_one(MeshRef)}
    for kind in (Reflective, Mirror, Portal):
        meshes.difference_update(entity for entity, _ in world.query_one(kind))
    return meshes


def samples_a_probe(world: World, entity: int) -> bool:
    """Cube-reflective, refractive or a plain lit mesh: what looks up a probe when one serves it."""
    return _samples(world.try_get(entity, Reflective), world.has(entity, Refractive)) or _plain(world, entity)


def has_boxes(world: World) -> bool:
    """Whether any ReflectionProbe has an influence box (plain meshes sample only those)."""
    return any(probe.influence is not None for _, probe in world.query_one(ReflectionProbe))


def probe_samplers(world: World, plain: bool = True) -> set[int]:
    """Every entity that samples a probe (the rule of ``samples_a_probe``): the few with a
    component of ``SAMPLER_KINDS``, and with ``plain`` the plain meshes, only where an
    influence box could hold them (a 10,000-entity world with no box does not pay for a look
    at each; the automatic probes' owners are among the few: ``plain`` False)."""
    found: dict[int, list] = {entity: [reflective, False] for entity, reflective in world.query_one(Reflective)}
    for entity, _ in world.query_one(Refractive):
        found.setdefault(entity, [None, False])[1] = True
    samplers = {entity for entity, (reflective, refractive) in found.items() if _samples(reflective, refractive)}
    if plain and has_boxes(world):
        samplers |= plain_meshes(world)
    return samplers


def has_own_probe(world: World, entity: int) -> bool:
    """An automatic probe: a non-flat cube-reflective or refractive mesh with no ReflectionProbe
    (a plain mesh samples the boxes' probes only)."""
    mesh_ref = world.try_get(entity, MeshRef)
    return (mesh_ref is not None and _samples(world.try_get(entity, Reflective), world.has(entity, Refractive))
            and not world.has(entity, ReflectionProbe) and not is_flat(mesh_ref.mesh))


def world_bounds(mesh: Mesh, model: glm.mat4, bounds: tuple[np.ndarray, np.ndarray] | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The world AABB of ``mesh`` (or of ``bounds``, its pose's box: ``pose_bounds``) placed by
    ``model`` (from ``frame_rules.world_corners``)."""
    world = world_corners(mesh, model, bounds)
    return world[:, :3].min(axis=0), world[:, :3].max(axis=0)


def pose_bounds(world: World, entity: int, mesh: Mesh) -> tuple[np.ndarray, np.ndarray] | None:
    """The box of ``mesh`` as ``entity``'s Skin and Morph pose it (``skinning.posed_bounds``),
    or None where it has neither (the mesh's own box holds it)."""
    skin = world.try_get(entity, Skin) if mesh.skinned else None
    morph = world.try_get(entity, Morph) if mesh.morph_count else None
    if skin is None and morph is None:
        return None
    return posed_bounds(mesh, skin.joint_matrices if skin is not None else None,
                        morph.weights if morph is not None else None,
                        skin is not None and skin.skinning == "dual_quaternion")


MAX_BLENDED_PROBES = 2  # probes an object blends at most (two cube samplers: GL 4.1 has no cube-map arrays)


@dataclass(frozen=True)
class ProbeBlend:
    """What an object's cube-map lookups read: ``probes`` (owners, the strongest first, at
    most MAX_BLENDED_PROBES) with their ``weights`` (the same order; their sum is at most 1).
    What they leave of 1 (``left``) is the sky's, or, with ``rest``, that probe's: a curved
    object's own automatic probe where influence boxes hold it only in part.  ``NO_PROBE``:
    the sky alone."""

    probes: tuple[int, ...] = ()
    weights: tuple[float, ...] = ()
    rest: int = 0  # who takes what the weights leave: 0 the sky, else the owner of a probe

    @property
    def left(self) -> float:
        """What the weights leave of 1 (the sky's, or ``rest``'s)."""
        return max(0.0, 1.0 - sum(self.weights))

    @property
    def sky(self) -> float:
        """The sky's weight."""
        return self.left if not self.rest else 0.0

    @property
    def blended(self) -> bool:
        """More than one source: two probes, or a probe and the sky (the scene shader's
        PROBE_BLEND build); a lone probe at full weight is sampled as it always was."""
        return len(self.probes) > 1 or (len(self.probes) == 1 and self.weights[0] < 1.0)


NO_PROBE = ProbeBlend()


def probe_weight(position: glm.vec3 | Sequence[float] | np.ndarray, centre: glm.vec3 | Sequence[float] | np.ndarray,
                 influence: glm.vec3 | Sequence[float] | np.ndarray, blend_distance: float) -> float:
    """A probe's weight at ``position``: 0 outside its influence box (``influence`` wide
    about ``centre``), rising linearly from the box's nearest wall to 1 at ``blend_distance``
    inside it (1 everywhere inside with no blend distance; a wall counts as inside then).
    The linear falloff of Unity HDRP's influence volumes."""
    inside = float(np.min(np.asarray(influence, np.float64) / 2.0
                          - np.abs(np.asarray(position, np.float64) - np.asarray(centre, np.float64))))
    if inside < 0.0:
        return 0.0
    if blend_distance <= 0.0:
        return 1.0
    return min(1.0, inside / blend_distance)


def probe_blend(world: World, entity: int) -> ProbeBlend:
    """The probes ``entity`` samples and their weights (the module docstring's rule): a
    ReflectionProbe of its own alone, or the MAX_BLENDED_PROBES influence boxes that weigh
    most at its position (ties: the nearest centre first), weights w_i normalised as
    w_i / max(1, sum w) (Bevy's and HDRP's normalisation: only where the boxes' weights add
    up to more than 1 do they share 1 between them; where they fall short, as in a lone
    box's falloff, the rest is the sky's), or ``NO_PROBE``.  A curved object with an
    automatic probe blends the boxes that hold it the same way, its own probe taking the
    rest in place of the sky (its own probe alone outside every box): so it crosses a box's
    wall without a pop.  Continuous in the position while at most MAX_BLENDED_PROBES boxes
    weigh more than 0 there."""
    if not samples_a_probe(world, entity):
        return NO_PROBE
    if world.has(entity, ReflectionProbe):
        return ProbeBlend((entity,), (1.0,))
    transform = world.try_get(entity, Transform)
    own = has_own_probe(world, entity)
    if transform is None:
        return ProbeBlend((entity,), (1.0,)) if own else NO_PROBE
    boxes = box_blend(world, transform.world[3].xyz)
    if not own:
        return boxes
    if not boxes.probes:
        return ProbeBlend((entity,), (1.0,))
    return boxes if boxes.left <= 0.0 else ProbeBlend(boxes.probes, boxes.weights, entity)


def box_blend(world: World, position: glm.vec3 | Sequence[float] | np.ndarray) -> ProbeBlend:
    """The influence boxes' blend at ``position`` (``probe_blend``'s rule for an object with
    no probe of its own): the MAX_BLENDED_PROBES boxes that weigh most there (ties: the
    nearest centre first), normalised only when their weights add up to more than 1, the
    sky taking the rest; ``NO_PROBE`` where no box holds it."""
    position = np.array(tuple(position), np.float64)
    found = []
    for owner, (probe, probe_t) in world.query(ReflectionProbe, Transform):
        if probe.influence is None:
            continue
        centre = np.array(probe_t.world[3].xyz)
        weight = probe_weight(position, centre, probe.influence, probe.blend_distance)
        if weight > 0.0:
            found.append((-weight, float(np.linalg.norm(position - centre)), owner, weight))
    if not found:
        return NO_PROBE
    found.sort()
    kept = found[:MAX_BLENDED_PROBES]
    scale = 1.0 / max(1.0, sum(weight for *_, weight in kept))
    return ProbeBlend(tuple(owner for _, _, owner, _ in kept), tuple(weight * scale for *_, weight in kept))


def box_blends(world: World, entities: Iterable[int]) -> dict[int, ProbeBlend]:
    """``box_blend`` at each of ``entities``' positions (those with a Transform), worked out
    for all of them at once in numpy: the same rule, so a probe box that moves, which asks
    again of every plain mesh it could hold, costs a few array operations, not a Python
    loop over the probes for each mesh."""
    boxes = [(owner, np.array(probe_t.world[3].xyz), np.asarray(probe.influence, np.float64) / 2.0,
              probe.blend_distance) for owner, (probe, probe_t) in world.query(ReflectionProbe, Transform)
             if probe.influence is not None]
    placed = [(entity, world.try_get(entity, Transform)) for entity in entities]
    placed = [(entity, transform) for entity, transform in placed if transform is not None]
    if not boxes or not placed:
        return {entity: NO_PROBE for entity, _ in placed}
    positions = np.array([tuple(transform.world[3].xyz) for _, transform in placed], np.float64)  # (N, 3)
    centres = np.stack([centre for _, centre, _, _ in boxes])                                      # (P, 3)
    halves = np.stack([half for _, _, half, _ in boxes])
    blends = np.array([blend for *_, blend in boxes], np.float64)
    owners = np.array([owner for owner, *_ in boxes])
    offsets = positions[:, None, :] - centres[None, :, :]                                          # (N, P, 3)
    inside = np.min(halves[None, :, :] - np.abs(offsets), axis=2)                                  # (N, P)
    with np.errstate(divide="ignore", invalid="ignore"):
        weights = np.where(inside < 0.0, 0.0,
                           np.where(blends[None, :] <= 0.0, 1.0, np.minimum(1.0, inside / blends[None, :])))
    distances = np.linalg.norm(offsets, axis=2)
    # Strongest first; ties: the nearest centre, then the lower owner (box_blend's sort): stable
    # sorts by each key in turn, the last the first key.
    order = np.argsort(np.broadcast_to(owners, weights.shape), axis=1, kind="stable")
    for key in (distances, -weights):
        order = np.take_along_axis(order, np.argsort(np.take_along_axis(key, order, axis=1), axis=1, kind="stable"),
                                   axis=1)
    order = order[:, :MAX_BLENDED_PROBES]
    strongest = np.take_along_axis(weights, order, axis=1)
    held = strongest > 0.0
    scale = 1.0 / np.maximum(1.0, np.where(held, strongest, 0.0).sum(axis=1, keepdims=True))
    # The blends as plain lists, each distinct one made once (a box's whole room shares one).
    made: dict[tuple, ProbeBlend] = {}
    result: dict[int, ProbeBlend] = {}
    for (entity, _), row_owners, row_weights, row_held in zip(
            placed, owners[order].tolist(), (strongest * scale).tolist(), held.tolist(), strict=True):
        key = tuple((owner, weight) for owner, weight, kept in zip(row_owners, row_weights, row_held, strict=True)
                    if kept)
        blend = made.get(key)
        if blend is None:
            blend = made[key] = ProbeBlend(tuple(owner for owner, _ in key), tuple(weight for _, weight in key)) \
                if key else NO_PROBE
        result[entity] = blend
    return result


def surface_point(state: SurfaceState) -> np.ndarray:
    """Where a mirror's or portal's fallback reflection is looked up from (its probes'
    weights, ``surface_blend``): a mirror's centre; for a portal, its centre carried through
    the pair, beside the partner, where the view it stands for would look out."""
    centre = np.append(np.asarray(state.corners, np.float64)[:, :3].mean(axis=0), 1.0)
    if state.kind == "portal":
        centre = np.array(state.carry.to_list(), np.float64).T @ centre
    return centre[:3]


def surface_blend(world: World, state: SurfaceState) -> ProbeBlend:
    """The probes (and weights) of a mirror's or portal's fallback: what its surface shows
    where it has no view of its own (cut by the view budget, faded out, past the depth limit,
    a mirror switched off): the influence boxes' blend at ``surface_point`` (``box_blend``),
    else the sky."""
    return box_blend(world, surface_point(state))


class SurfaceProbes:
    """Every mirror's and portal's ``surface_blend``, by entity, worked out again only for
    surfaces that changed (a new ``SurfaceState``) or when a probe with an influence box came,
    went, moved or changed: a still frame compares a few tuples."""

    def __init__(self) -> None:
        self._probes: tuple = ()
        self._states: dict[int, SurfaceState] = {}
        self.blends: dict[int, ProbeBlend] = {}

    def update(self, world: World, states: Iterable[SurfaceState]) -> dict[int, ProbeBlend]:
        """The blends of ``states`` (this frame's surfaces); the same dict while nothing changed."""
        probes = tuple((owner, tuple(probe.influence), probe.blend_distance, tuple(probe_t.world[3].xyz))
                       for owner, (probe, probe_t) in world.query(ReflectionProbe, Transform)
                       if probe.influence is not None)
        states = {state.entity: state for state in states}
        if probes == self._probes and states.keys() == self._states.keys() and all(
                state is self._states[entity] for entity, state in states.items()):
            return self.blends
        again = probes != self._probes
        self.blends = {entity: self.blends[entity] if not again and self._states.get(entity) is state
                       and entity in self.blends else surface_blend(world, state)
                       for entity, state in states.items()}
        self._probes, self._states = probes, states
        return self.blends


def probe_for(world: World, entity: int) -> int:
    """The entity owning the probe ``entity`` samples (the strongest of ``probe_blend``), or 0
    (the sky)."""
    probes = probe_blend(world, entity).probes
    return probes[0] if probes else 0


# What changes a look: an entity one of these components was added to, removed from or
# written on is drawn differently (why, per kind).  The extract stage rewrites its instance
# row; the probes scheduler recaptures the probe faces that see it.  Not here: Transform
# (where a thing is, not how it looks: the transform stage's moved set says that) and
# ReflectionProbe (what it changes in a look is which probe an object samples, which
# ``LookChanges`` follows object by object, and the cube's picture, which is not followed
# into the probes that see the object: two probes that see each other's objects would
# recapture each other every frame).
LOOK_KINDS: dict[type, str] = {
    MeshRef: "the mesh drawn, and whether it is drawn at all (visible)",
    Material: "colour, alpha (the transparent slot), texture, normal map, metallic and roughness",
    Emissive: "the light it gives off",
    Reflective: "what it reflects (sky, planar mirror, probe or portal), and whether it samples a probe",
    Refractive: "glass: it refracts what its probe saw behind it (and samples a probe)",
    Mirror: "a mirror's surface: its tint, reflectance, roughness and view resolution, or switched off",
    Portal: "a portal's surface: its partner's view, or closed",
    Slice: "the clip plane that cuts a thing part-way through a portal (the PortalSliceSystem writes and "
           "drops it on travellers that need not move: a pair opening or closing around one)",
    PortalClone: "the entity it is drawn as: the id image, and the views that hide it (a probe face hides "
                 "its own object's clones too)",
    Visibility: "which kinds of view draw it (direct, mirrors, portals, probe captures) and its reflection layers",
    FromDecal: "a decal's cut: blended in the transparent slot whatever its alpha, its depth offset",
    Skin: "where its joints bend its mesh (a new pose, a Skin come or gone: its own batch or a shared one)",
    Morph: "how much of each morph target it wears",
    Monitor: "a screen's picture: its size (a picture of its own) and brightness (the light it gives off)",
}
# The look kinds that pose a mesh: a new pose alone is written to the pose texture, not the
# instance's whole row (the extract stage's ``_pose``).
POSE_KINDS = (Skin, Morph)
# What changes a look by coming or going only, not by its writes (why, per kind): its
# coming or going is followed as a LOOK_KINDS change is, its writes are not.
PRESENCE_KINDS: dict[type, str] = {
    Water: "a mirror's surface drawn with both faces (water is seen from below too); its offset, written every "
           "frame as the waves move, changes only its composite, not its instance",
}
APPEARANCE_KINDS = tuple(kind for kind in LOOK_KINDS if kind not in POSE_KINDS)


class LookChanges:
    """The entities whose look may have changed this frame, for one reader (the extract stage
    and the probes scheduler keep one each): a component of ``LOOK_KINDS`` added, removed or
    written, or the probes the entity samples or their weights (``probe_blend``) changed: it
    moved into, out of or within the falloff of a probe's influence box, a probe came, went,
    moved or changed, or its own components changed.  It remembers what each object sampled
    when last asked."""

    def __init__(self) -> None:
        # The entities the last ``entities`` call found whose sampled probes changed.
        self.last_resampled: set[int] = set()
        self._sampled: dict[int, ProbeBlend] = {}  # entity -> what it sampled (not NO_PROBE), when last asked
        self._influences: dict[int, tuple | None] = {}  # probe owner -> its influence box and falloff, when last asked
        self._present: dict[type, set[int]] = {kind: set() for kind in PRESENCE_KINDS}  # who held each, when last asked

    def entities(self, world: World) -> set[int]:
        """This frame's entities whose look may have changed (each call follows on from the
        last: ask once a frame)."""
        looks = world.changed_any(LOOK_KINDS)
        for kind, holders in self._present.items():
            for entity in world.changed(kind):
                if (world.exists(entity) and world.has(entity, kind)) != (entity in holders):
                    holders.symmetric_difference_update((entity,))
                    looks.add(entity)
        self.last_resampled = self.resampled(world, looks)
        return looks | self.last_resampled

    def resampled(self, world: World, looks: set[int]) -> set[int]:
        """The entities whose sampled probes or their weights changed since the last call
        (``looks``: this frame's LOOK_KINDS changes)."""
        frame = world.frame
        for entity in world.deleted() & self._sampled.keys():
            del self._sampled[entity]
        # Which probes an object samples depends on its components, its position and the probes:
        # which entities own one, where the influence boxes are and how they fall off.
        influences = {entity: None if probe.influence is None else (*probe.influence, probe.blend_distance)
                      for entity, probe in world.query_one(ReflectionProbe)}
        probes_changed = influences != self._influences or any(
            influences[entity] is not None for entity in frame.moved & influences.keys())
        self._influences = influences
        boxes = any(influence is not None for influence in influences.values())
        changed = looks | frame.moved | frame.added
        if not probes_changed and not changed:
            return set()  # a still frame costs a look at each probe
        # Plain meshes sample only boxes' probes: with none, none of them is asked.
        if probes_changed:  # every sampler asked again
            plain = plain_meshes(world) if boxes else set()
            candidates = probe_samplers(world, plain=False) | plain | self._sampled.keys()
        else:  # only what changed (a look, a move, a new entity)
            plain = {entity for entity in changed if world.exists(entity) and _plain(world, entity)} if boxes else set()
            kinds: set[int] = set(self._sampled)
            for kind in SAMPLER_KINDS:
                kinds.update(entity for entity, _ in world.query_one(kind))
            candidates = (changed & kinds) | plain
        resampled = set()
        # Plain meshes hold no probe of their own (but one owning a ReflectionProbe): their
        # blends are the boxes', all at once.
        blends = box_blends(world, (candidates & plain) - influences.keys()) if plain else {}
        for entity in candidates:
            probe = blends[entity] if entity in blends else probe_blend(world, entity) if world.exists(entity) \
                else NO_PROBE
            if probe != self._sampled.get(entity, NO_PROBE):
                resampled.add(entity)
            if probe.probes:
                self._sampled[entity] = probe
            else:
                self._sampled.pop(entity, None)
        return resampled


# --- what a probe face sees -------------------------------------------------------------------
ALL_FACES = frozenset(range(6))


def _side_normals(face: int) -> np.ndarray:
    """The inward normals of a face's four side planes (through the probe's centre)."""
    forward = CUBE_FACES[face].forward
    axis = int(np.argmax(np.abs(forward)))
    sign = forward[axis]
    rows = []
    for other in range(3):
        if other == axis:
            continue
        for side in (1.0, -1.0):
            n = np.zeros(3)
            n[axis] = sign
            n[other] = -side  # sign * d[axis] - side * d[other] >= 0
            rows.append(n)
    return np.array(rows)


_SIDE_NORMALS = np.stack([_side_normals(face) for face in range(6)])  # (face, plane, xyz)
_CORNER_PICK = np.array([(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=bool)  # (8, 3)


def face_planes(position: glm.vec3, face: int) -> np.ndarray:
    """The four side planes of a face's frustum as rows (a, b, c, d): a point p is inside
    the face's pyramid when every row . (p, 1) >= 0."""
    normals = _SIDE_NORMALS[face]
    return np.concatenate([normals, -(normals @ np.array(position))[:, None]], axis=1)


def face_hits(position: glm.vec3, far: float, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(box, face) booleans: which faces' frustums (from ``position`` out to ``far``) each
    world box [lo, hi] (rows, or one box's corners) may touch.  Conservative: a box is left
    out of a face only when all its corners are outside one of the face's planes.  All
    boxes and faces in a few array operations: a probe may see many movers a frame."""
    centre = np.array(position, dtype=np.float64)
    lo = np.atleast_2d(np.asarray(lo, dtype=np.float64))
    hi = np.atleast_2d(np.asarray(hi, dtype=np.float64))
    hits = np.zeros((len(lo), 6), dtype=bool)
    in_range = np.linalg.norm(np.clip(centre, lo, hi) - centre, axis=1) <= far
    if not in_range.any():
        return hits
    near_lo, near_hi = lo[in_range] - centre, hi[in_range] - centre  # planes through the centre: d = 0
    corners = np.where(_CORNER_PICK[None], near_hi[:, None, :], near_lo[:, None, :])  # (box, corner, xyz)
    inside = np.einsum("bck,fpk->bcfp", corners, _SIDE_NORMALS) >= 0.0  # (box, corner, face, plane)
    hits[in_range] = ~(~inside).all(axis=1).any(axis=2)  # not wholly outside one plane: (box, face)
    return hits


def box_corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(box, 8, xyz): the corners of each box [lo, hi] (rows)."""
    return np.where(_CORNER_PICK[None], np.asarray(hi)[:, None, :], np.asarray(lo)[:, None, :])


_SIDE_NORMALS_BY_COLUMN = _SIDE_NORMALS.reshape(-1, 3).T.copy()  # (xyz, face * plane): one matrix product


def hull_face_hits(position: glm.vec3 | Sequence[float], far: float, points: np.ndarray, lo: np.ndarray,
                   hi: np.ndarray) -> np.ndarray:
    """(hull, face) booleans: which faces' frustums (from ``position`` out to ``far``) may
    touch the convex hull of each row of ``points`` (hull, point, xyz), whose bounding box
    is [lo, hi] (rows).  Conservative as ``face_hits``: a hull is left out of a face only
    when all its points are outside one of the face's planes (a plane through the apex: a
    convex hull is outside it when its points are), or when its box is beyond ``far``.
    ``face_hits_swept`` is one such hull: a box swept along a light, tighter than the box
    bounding the sweep (a long diagonal sweep makes that as wide as the level)."""
    centre = np.asarray(tuple(position), np.float64)
    hits = np.zeros((len(points), 6), dtype=bool)
    if not len(points):
        return hits
    reach = np.clip(centre, lo, hi) - centre
    in_range = np.sqrt((reach * reach).sum(axis=1)) <= far
    if not in_range.any():
        return hits
    near = points[in_range] - centre
    # A hull is outside a plane when its farthest point along the plane's normal is: (hull,
    # face * plane) of those farthest reaches, and a face is hit when no plane of it has all
    # the hull outside.
    reach_along = (near @ _SIDE_NORMALS_BY_COLUMN).max(axis=1)
    hits[in_range] = (reach_along >= 0.0).reshape(len(near), 6, -1).all(axis=2)
    return hits


# The side planes' normals split by sign, stacked: every entry is 0 or +-1, so a box's
# farthest reach along a plane (the largest of its corners' dot products) is ``(hi - c, lo -
# c) @ _PLANES_SPLIT``: two exact terms and one rounding, the farthest corner's own sum bit
# for bit.
_PLANES_SPLIT = np.concatenate([np.maximum(_SIDE_NORMALS_BY_COLUMN, 0.0), np.minimum(_SIDE_NORMALS_BY_COLUMN, 0.0)])
_TWICE = np.array([0, 1, 2, 0, 1, 2])  # a point's xyz, twice (hi's and lo's)


def box_pair_face_hits(position: glm.vec3 | Sequence[float], far: float, lo: np.ndarray, hi: np.ndarray,
                       far_lo: np.ndarray, far_hi: np.ndarray) -> np.ndarray:
    """(row, face) booleans: ``hull_face_hits`` of the convex hull of each row's two world
    boxes, [lo, hi] and [far_lo, far_hi] (a box swept along a light: the box and the box
    moved; the same box twice: the box alone), the same booleans bit for bit, without the
    sixteen corners: the hull's farthest point along a plane is one box's farthest corner,
    and a box's farthest corner takes, axis by axis, ``hi`` where the normal is positive and
    ``lo`` where it is negative (``_PLANES_SPLIT``; rounding is monotonic, so the corner that
    wins is the same).  One small matrix product for any number of rows: the probes
    scheduler tests every changed box and its shadows' hulls a frame
    (``ProbeScheduler._mark_changes``)."""
    centre = np.array(tuple(position), np.float64)
    count = len(lo)
    if not count:
        return np.zeros((0, 6), dtype=bool)
    # np.clip's bounds, without its dispatch: the nearest point of the hull's box.
    reach = np.minimum(np.maximum(centre, np.minimum(lo, far_lo)), np.maximum(hi, far_hi)) - centre
    in_range = np.sqrt((reach * reach).sum(axis=1)) <= far
    # (row, one box and the other, hi and lo less the centre) through the planes.
    ends = np.concatenate([hi, lo, far_hi, far_lo], axis=1).reshape(count * 2, 6) - centre[_TWICE]
    along = (ends @ _PLANES_SPLIT).reshape(count, 2, 24)
    out = (np.maximum(along[:, 0], along[:, 1]) >= 0.0).reshape(count, 6, 4)
    return out[..., 0] & out[..., 1] & out[..., 2] & out[..., 3] & in_range[:, None]


def swept_box_face_hits(position: glm.vec3 | Sequence[float], far: float, lo: np.ndarray, hi: np.ndarray,
                        sweep: np.ndarray) -> np.ndarray:
    """(box, face) booleans: ``hull_face_hits`` of each world box [lo, hi] (rows) and the same
    box moved by its row of ``sweep`` (a zero row: the box alone), bit for bit
    (``box_pair_face_hits``)."""
    return box_pair_face_hits(position, far, lo, hi, lo + sweep, hi + sweep)


def face_hits_swept(position: glm.vec3, far: float, lo: np.ndarray, hi: np.ndarray,
                    sweep: np.ndarray) -> np.ndarray:
    """(box, face) booleans: which faces' frustums may touch the convex hull of each world
    box [lo, hi] (rows) and the same box moved by its row of ``sweep`` (a box swept along a
    light: where its shadow may fall, ``shadow_rules.directional_shadow_sweep``): its
    sixteen corners through ``hull_face_hits``."""
    lo = np.atleast_2d(np.asarray(lo, dtype=np.float64))
    hi = np.atleast_2d(np.asarray(hi, dtype=np.float64))
    sweep = np.atleast_2d(np.asarray(sweep, dtype=np.float64))
    corners = box_corners(lo, hi)
    points = np.concatenate([corners, corners + sweep[:, None, :]], axis=1)
    return hull_face_hits(position, far, points, np.minimum(lo, lo + sweep), np.maximum(hi, hi + sweep))


def faces_touched(position: glm.vec3, far: float, lo: np.ndarray, hi: np.ndarray) -> set[int]:
    """The faces any of the boxes [lo, hi] may touch (``face_hits``, all boxes together)."""
    return {int(face) for face in np.flatnonzero(face_hits(position, far, lo, hi).any(axis=0))}


# Each face's forward, s and t axes (``CUBE_FACES``: each is a world axis, signed): the axis
# index and sign of each, (face, forward/s/t).
_FACE_AXES = np.array([[int(np.flatnonzero(axis)[0]) for axis in face] for face in CUBE_FACES])
_FACE_POSITIVE = np.array([[axis[int(np.flatnonzero(axis)[0])] > 0.0 for axis in face] for face in CUBE_FACES])
NO_RECT = (np.inf, np.inf, -np.inf, -np.inf)  # the empty rectangle: any union with it is the other


# Rectangles are worked out as (s0, t0, -s1, -t1) ("low form"): a union is then the least of
# each number, a common part the greatest, and the face's own [-1, 1] a floor of -1 on all four.
_LOW_EMPTY = np.inf  # an empty rectangle in low form: all four infinite
_NORMAL = np.array([1.0, 1.0, -1.0, -1.0])
# Gathers from a box's [lo, hi, -lo, -hi] (less the probe's centre: 12 numbers) of each
# face's depth range (start, end) and its s and t ranges in low form (s0, t0, -s1, -t1):
# along a positive axis the range is [lo, hi], along a negative one [-hi, -lo].
_START = np.where(_FACE_POSITIVE, _FACE_AXES, 9 + _FACE_AXES)  # (face, forward/s/t): where the range starts
_END = np.where(_FACE_POSITIVE, 3 + _FACE_AXES, 6 + _FACE_AXES)
_MINUS_END = np.where(_FACE_POSITIVE, 9 + _FACE_AXES, _FACE_AXES)  # its end, negated
_GATHER = np.concatenate([_START[:, :1], _END[:, :1], _START[:, 1:], _MINUS_END[:, 1:]], axis=1)  # (face, 6)


def _face_ranges(position: glm.vec3 | Sequence[float], lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(box, face, 6): each box's depth range along each face's axis (start, end) and its s
    and t ranges in low form."""
    ends = np.concatenate([lo, hi], axis=1) - np.asarray(tuple(position), np.float64)[_TWICE]
    return np.concatenate([ends, -ends], axis=1)[:, _GATHER]


def _low_rects(ranges: np.ndarray, near: float) -> np.ndarray:
    """(box, face, 4): ``face_rects`` in low form, of boxes given by their ranges
    (``_face_ranges``); ``_LOW_EMPTY`` where a box shows nothing of a face."""
    depth_lo = np.maximum(ranges[..., 0:1], near)  # >= near > 0: no division by zero
    depth_hi = np.maximum(ranges[..., 1:2], depth_lo)
    # s / depth grows with s (depth > 0): least at the start of s's range, at one end of
    # depth's; -s1 likewise.
    sides = ranges[..., 2:]
    rects = np.maximum(np.minimum(sides / depth_lo, sides / depth_hi), -1.0)
    rects[ranges[..., 1] < depth_lo[..., 0]] = _LOW_EMPTY  # nothing in front of the near plane
    return rects


def _outside_emptied(rects: np.ndarray) -> np.ndarray:
    """Low-form rectangles, those wholly outside their face (a range ending before the
    face's other edge) made empty.  Only for a whole row's: the corners of a hull may all
    lie outside a face that the hull crosses."""
    rects[(rects[..., 0] + rects[..., 2] > 0.0) | (rects[..., 1] + rects[..., 3] > 0.0)] = _LOW_EMPTY
    return rects


def _normal_form(low: np.ndarray) -> np.ndarray:
    """Rectangles in low form as (s0, t0, s1, t1), ``NO_RECT`` where empty."""
    return low * _NORMAL  # (an empty one, all four infinite, is NO_RECT)


def face_rects(position: glm.vec3 | Sequence[float], near: float, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(box, face, 4): where in each cube face from ``position`` each world box [lo, hi]
    (rows, lo <= hi) may draw, as the face's rectangle (s0, t0, s1, t1) in its normalised
    coordinates (-1..1 along ``CUBE_FACES``' s and t axes: a face view's NDC x and y), within
    [-1, 1]; ``NO_RECT`` where the box has no point at ``near`` or more along the face's
    axis (no fragment in front of the near plane) or none within the face.  Conservative: a
    face's axes are world axes, so the box's part in front of the near plane is a box, and
    s / depth over it is extreme at its corners (s and depth ranges' ends).  The far plane
    is not used (it only leaves more in)."""
    lo = np.atleast_2d(np.asarray(lo, np.float64))
    hi = np.atleast_2d(np.asarray(hi, np.float64))
    return _normal_form(_outside_emptied(_low_rects(_face_ranges(position, lo, hi), near)))


def _hull_low_rects(position: glm.vec3 | Sequence[float], near: float, lo: np.ndarray, hi: np.ndarray,
                    far_lo: np.ndarray, far_hi: np.ndarray, box_lo: np.ndarray | None = None,
                    box_hi: np.ndarray | None = None) -> np.ndarray:
    """``hull_rects`` in low form."""
    boxes = 0 if box_lo is None else len(box_lo)
    count = len(lo)
    ranges = _face_ranges(position, np.concatenate([*([box_lo] if boxes else []), lo, far_lo]),
                          np.concatenate([*([box_hi] if boxes else []), hi, far_hi]))
    rects = _low_rects(ranges, near)
    hull = np.minimum(rects[boxes:boxes + count], rects[boxes + count:])
    box = ranges[boxes:boxes + count]
    step = ranges[boxes + count:] - box  # v along each face's axis (twice), its s and t in low form
    w = step[..., 0]
    moving = w != 0.0
    safe = np.where(moving, w, 1.0)
    # The l where the swept box spans depth ``near``: start + l w <= near <= end + l w.
    a, b = (near - box[..., 1]) / safe, (near - box[..., 0]) / safe
    low, high = np.maximum(np.minimum(a, b), 0.0), np.minimum(np.maximum(a, b), 1.0)
    cut = moving & (low <= high)
    if cut.any():
        sides = step[..., 2:]
        section = np.maximum((box[..., 2:] + np.minimum(low[..., None] * sides, high[..., None] * sides)) / near,
                             -1.0)
        hull = np.minimum(hull, np.where(cut[..., None], section, _LOW_EMPTY))
    return np.concatenate([rects[:boxes], hull]) if boxes else hull


def hull_rects(position: glm.vec3 | Sequence[float], near: float, lo: np.ndarray, hi: np.ndarray,
               far_lo: np.ndarray, far_hi: np.ndarray, box_lo: np.ndarray | None = None,
               box_hi: np.ndarray | None = None) -> np.ndarray:
    """(row, face, 4): ``face_rects`` of the convex hull of each row's two world boxes [lo,
    hi] and [far_lo, far_hi] = [lo, hi] moved by one vector v (a box swept along a light:
    where its shadow may fall), tighter than the rectangle of the box bounding both (a long
    diagonal sweep's box may hold the probe, and fill every face); first, where given, the
    ``face_rects`` of the boxes [box_lo, box_hi] (one pass for both kinds of row).  The hull
    is the box swept, {b + l v: b in the box, 0 <= l <= 1}; its part in front of the near
    plane is the convex hull of its corners in front (the two boxes' corners: ``face_rects``
    of each) and of its section by the plane, whose s and t ranges are linear in l over the
    l that reach the plane, so taken at that range's ends (with v along the plane, the
    section is the box's own, in its rectangle already)."""
    lo = np.atleast_2d(np.asarray(lo, np.float64))
    return _normal_form(_outside_emptied(_hull_low_rects(position, near, lo, np.atleast_2d(hi), np.atleast_2d(far_lo),
                                                         np.atleast_2d(far_hi), box_lo, box_hi)))


def change_rects(position: glm.vec3 | Sequence[float], near: float, lo: np.ndarray, hi: np.ndarray,
                 hits: np.ndarray, swept: tuple[np.ndarray, ...] | None = None) -> np.ndarray:
    """(face, 4): where in each face a probe's changes may draw, as (s0, t0, s1, t1)
    (``NO_RECT`` for none): the union, over the rows ``hits`` (row, face) says reach a face,
    of the boxes [lo, hi]'s rectangles then, with ``swept`` = (lo, hi, far_lo, far_hi,
    bound_lo, bound_hi), each sun's hull's (``hull_rects``) within its clipped box's (both
    hold every point it shades): the probes scheduler's rows in one pass."""
    if swept is None:
        rects = _low_rects(_face_ranges(position, lo, hi), near)
    else:
        swept_lo, swept_hi, far_lo, far_hi, bound_lo, bound_hi = swept
        plain = len(lo)
        rects = _hull_low_rects(position, near, swept_lo, swept_hi, far_lo, far_hi, np.concatenate([lo, bound_lo]),
                                np.concatenate([hi, bound_hi]))
        rects = np.concatenate([rects[:plain], np.maximum(rects[plain:plain + len(bound_lo)],
                                                          rects[plain + len(bound_lo):])])
    if not len(rects):
        return _normal_form(np.full((6, 4), _LOW_EMPTY))
    return _normal_form(np.where(hits[..., None], _outside_emptied(rects), _LOW_EMPTY).min(axis=0))


MAX_SURFACE_IMAGES = 4096  # boxes seen through mirrors and portals a probe's schedule follows a frame


def images_through_surfaces(eye: glm.vec3 | Sequence[float], lo: np.ndarray, hi: np.ndarray,
                            surfaces: Iterable[SurfaceState], depth: int,
                            far: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """Where the world boxes [lo, hi] (rows) appear to a probe at ``eye`` through the mirrors
    and portals ``surfaces`` (each with ``plane``, ``exit_plane``, ``carry`` and ``entity``,
    as ``engine.resources.SurfaceState``), up to ``depth`` surfaces deep: a box that can be
    seen through a surface (a corner in front of the plane the surface's view looks out of)
    is seen where the inverse of the surface's ``carry`` puts it (its mirror image; through a
    portal, carried back to this side).  The images' boxes, within ``far`` of the eye, as
    rows (lo, hi, the row of [lo, hi] each is an image of, the surface seen last: the one the
    probe looks into); conservative (a box is only left out when it cannot be seen).  None
    when there would be more than MAX_SURFACE_IMAGES: the caller then takes every face that
    sees a surface."""
    eye = np.asarray(eye, np.float64)
    carried = []
    for surface in surfaces:
        plane = np.asarray(surface.plane, np.float64)
        exit_plane = np.asarray(surface.exit_plane, np.float64)
        back = np.linalg.inv(np.array(surface.carry.to_list(), np.float64).T)
        carried.append((plane, exit_plane, back, surface.entity))
    images_lo, images_hi, images_of, images_via = [], [], [], []
    level_lo, level_hi = np.atleast_2d(lo).astype(np.float64), np.atleast_2d(hi).astype(np.float64)
    level_of = np.arange(len(level_lo))
    for level in range(depth):
        next_lo, next_hi, next_of, next_via = [], [], [], []
        for plane, exit_plane, back, entity in carried:
            if level == 0 and plane[:3] @ eye + plane[3] <= 0.0:
                continue  # the probe is behind it: it sees the surface's back
            corners = np.where(_CORNER_PICK[None], level_hi[:, None, :], level_lo[:, None, :])  # (box, corner, xyz)
            homogeneous = np.concatenate([corners, np.ones(corners.shape[:2] + (1,))], axis=2)
            seen = (homogeneous @ exit_plane >= 0.0).any(axis=1)
            if not seen.any():
                continue
            moved = homogeneous[seen] @ back.T
            moved = moved[..., :3] / moved[..., 3:4]
            next_lo.append(moved.min(axis=1))
            next_hi.append(moved.max(axis=1))
            next_of.append(level_of[seen])
            next_via.append(np.full(int(seen.sum()), entity, np.int64))
        if not next_lo:
            break
        level_lo, level_hi = np.concatenate(next_lo), np.concatenate(next_hi)
        level_of, level_via = np.concatenate(next_of), np.concatenate(next_via)
        near = np.linalg.norm(np.clip(eye, level_lo, level_hi) - eye, axis=1) <= far
        level_lo, level_hi, level_of, level_via = level_lo[near], level_hi[near], level_of[near], level_via[near]
        images_lo.append(level_lo)
        images_hi.append(level_hi)
        images_of.append(level_of)
        images_via.append(level_via)
        if sum(len(b) for b in images_lo) > MAX_SURFACE_IMAGES:
            return None
        if not len(level_lo):
            break
    if not images_lo:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0, np.int64)
    return (np.concatenate(images_lo), np.concatenate(images_hi), np.concatenate(images_of),
            np.concatenate(images_via))


# --- what relights a probe ----------------------------------------------------------------
# A change to one of these relights every face of every probe.  A PointLight relights only the
# probes within its reach (``lights_reaching``) when it changes, comes, goes or moves (its own
# Transform or a parent's: the transform stage's moved set holds descendants).
LIGHTING_KINDS = (DirectionalLight, Skybox, HemisphereLight)  # the sun, and the sky's light and ambient


def lights_reaching(eye: glm.vec3 | Sequence[float], far: float, lights: list[tuple[np.ndarray, float]]) -> list[int]:
    """Which point lights of ``lights`` ((position, range) rows, where a light was or is)
    light something a probe at ``eye`` sees out to ``far``: their sphere of range meets the
    probe's sphere of sight (their rows' indices)."""
    eye = np.asarray(eye, np.float64)
    return [index for index, (position, reach) in enumerate(lights)
            if float(np.linalg.norm(np.asarray(position, np.float64) - eye)) <= reach + far]


def projection_box(position: glm.vec3, probe: ReflectionProbe) -> tuple[tuple, tuple] | None:
    """The box a probe's lookups are parallax-corrected against (world min, max corners):
    its influence box about where it was captured, with ``box_projection``; else None."""
    if not probe.box_projection or probe.influence is None:
        return None
    half = glm.vec3(probe.influence) / 2.0
    return tuple(position - half), tuple(position + half)
