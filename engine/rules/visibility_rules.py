"""The visibility rule (``components/visibility.py``, which also packs its code): whether a
view draws an entity, defined once.  Every place that decides it calls this module: the scene
shaders (per instance, through ``shaders/include/visibility.glsl``, whose ``VIEW_KIND_BITS``
is ``glsl_defines`` here), the view planner (which mirrors and portals a parent view draws:
``SurfaceTable.drawn_in``; the view through one: ``mask_through``), the probes' scheduler (which
moves a probe can see: ``ChangedBoxes.seen_by``) and a cast as a view sees it
(``raycast.raycast_seen``'s ``view_mask``: the editor's clicks).

One packing serves both sides, an integer of ``VIEW_KINDS`` bits of kinds of view and
``REFLECTION_LAYERS`` bits of layers above them (``visibility_code``):

- an entity's code: the kinds of view it is hidden in and the layers it belongs to
  (``entity_code``; it rides in an instance row's float ``tint.w``, exact below 2^24);
- a view's mask: the kinds of view it is (accumulated along its chain of surfaces) and the
  layers it shows (``View.view_mask``, the Camera block's ``skip.z``).

A view draws an entity when it is of no kind the entity is hidden in and they share a layer
(``drawn_in``); an entity hidden in every kind of view is drawn nowhere and casts no shadow
(``hidden_everywhere``), and one whose ``MeshRef.casts_shadows`` is off is drawn but casts
none (``NO_SHADOW_BIT`` in its code, above the layers, which no view's mask has: ``casts_shadow``);
one whose ``MeshRef.receives_shadows`` is off has ``NO_RECEIVE_BIT`` (``receives_shadow``):
the scene shader looks up no map for it.
Glass casts into no depth map, whatever its code (it lets its share of a light through: the
light's see-through map holds it), and a portal's surface is an opening that casts none
unless it carries light (``Portal.carries_light``: ``OPENING_CASTS_BIT`` in its code,
``opening_casts``), when the light it takes in leaves by its partner, not on behind it
(``row_casts_shadow`` on instance rows, ``ShadowCasting`` from the world): the shadow pass's
whole test, ``shaders/shadow.vert``'s ``casts``."""
from __future__ import annotations

from typing import TypeVar

import numpy as np

from components import MeshRef, Portal, PortalClone, Refractive, Visibility
from components.limits import (
    NO_RECEIVE_BIT,
    NO_SHADOW_BIT,
    OPENING_CASTS_BIT,
    VIEW_DIRECT,
    VIEW_KINDS,
    VIEW_MIRROR,
    VIEW_PORTAL,
)
from components.visibility import DRAWN_EVERYWHERE, KIND_MASK, visibility_code
from engine.core.material_slots import ReflectVariant
from engine.core.world import World

Code = TypeVar("Code", int, np.ndarray)


def entity_code(visibility: Visibility | None, drawn: bool = True, casts_shadows: bool = True,
                receives_shadows: bool = True, opening_carries: bool = False) -> int:
    """Where an entity is drawn: its ``Visibility``'s hidden kinds and layers
    (``DRAWN_EVERYWHERE`` without one), with ``NO_SHADOW_BIT`` when it casts no shadow
    (``casts_shadows`` False: its ``MeshRef.casts_shadows``), ``NO_RECEIVE_BIT`` when it
    receives none (its ``MeshRef.receives_shadows``) and ``OPENING_CASTS_BIT`` when it is a
    portal's opening that carries light (``opening_carries``: its ``Portal.carries_light``);
    0, on no layer, when it is not drawn at all (``drawn`` False: an invisible mesh)."""
    if not drawn:
        return 0
    code = DRAWN_EVERYWHERE if visibility is None else visibility_code(visibility.hidden_kinds, visibility.layer_mask)
    return code | (0 if casts_shadows else NO_SHADOW_BIT) | (0 if receives_shadows else NO_RECEIVE_BIT) \
        | (OPENING_CASTS_BIT if opening_carries else 0)


def drawn_code(world: World, entity: int) -> int:
    """Where ``entity`` is drawn, read from the world: ``entity_code`` of its Visibility, and
    no layer at all with an invisible mesh (a mirror's or portal's own, for the planner)."""
    mesh_ref = world.try_get(entity, MeshRef)
    return entity_code(world.try_get(entity, Visibility), drawn=mesh_ref is None or mesh_ref.visible)


KINDS_BUT_DIRECT = KIND_MASK & ~VIEW_DIRECT  # a view through a surface is no longer direct


def mask_through(view_mask: int, mirror: bool, layers: int) -> int:
    """The mask of the view through a mirror (``mirror``) or a portal whose view shows
    ``layers`` (its ``SurfaceState.layers``), seen in a view of ``view_mask``: no longer
    direct, a mirror or a portal view besides the kinds it was, showing the layers both show
    (the planner's ``SurfaceTable.keep`` and ``kind_bit``, every surface at once)."""
    return (view_mask & visibility_code(KINDS_BUT_DIRECT, layers)) | (VIEW_MIRROR if mirror else VIEW_PORTAL)


def drawn_in(codes: Code, view_mask: Code) -> bool | np.ndarray:
    """Whether a view of ``view_mask`` draws what has ``codes``: it is of no kind they are
    hidden in, and they share a layer.  Python ints or numpy integer arrays (broadcast).
    ``hidden_in_view`` in ``shaders/include/visibility.glsl`` is its negation."""
    return ((codes & view_mask & KIND_MASK) == 0) & (((codes >> VIEW_KINDS) & (view_mask >> VIEW_KINDS)) != 0)


def hidden_everywhere(codes: Code) -> bool | np.ndarray:
    """Whether what has ``codes`` is hidden in every kind of view (drawn nowhere, so it casts
    no shadow: ``shaders/shadow.vert``)."""
    return (codes & KIND_MASK) == KIND_MASK


def casts_shadow(codes: Code) -> bool | np.ndarray:
    """Whether what has ``codes`` is in the lights' shadow maps: drawn somewhere
    (``hidden_everywhere``) and not marked ``NO_SHADOW_BIT``.  ``casts_no_shadow`` in
    ``shaders/include/visibility.glsl`` is its negation."""
    return ~hidden_everywhere(codes) & ((codes & NO_SHADOW_BIT) == 0) if isinstance(codes, np.ndarray) \
        else not hidden_everywhere(codes) and not codes & NO_SHADOW_BIT


def receives_shadow(codes: Code) -> bool | np.ndarray:
    """Whether what has ``codes`` is darkened by the lights' shadow maps (not marked
    ``NO_RECEIVE_BIT``).  ``receives_no_shadow`` in ``shaders/include/visibility.glsl`` is
    its negation."""
    return (codes & NO_RECEIVE_BIT) == 0


def opening_casts(codes: Code) -> bool | np.ndarray:
    """Whether what has ``codes`` is a portal's opening that carries light
    (``OPENING_CASTS_BIT``), so casts a shadow: ``opening_casts`` in
    ``shaders/include/visibility.glsl``."""
    return (codes & OPENING_CASTS_BIT) != 0


def row_casts_shadow(reflect: np.ndarray, codes: np.ndarray) -> np.ndarray:
    """Whether each instance row (its reflect variant and its code) is drawn into the lights'
    shadow maps: ``casts`` in ``shaders/shadow.vert``, on arrays; glass, which lets its share
    of the light through, is drawn into the lights' see-through maps (its SEE_THROUGH build:
    ``engine/render/shadows.py``).  A portal's surface is an opening that casts only when it
    carries light (``opening_casts``: the light goes in there and out of its partner)."""
    return ((reflect != ReflectVariant.PORTAL) | opening_casts(codes)) & casts_shadow(codes)


class ShadowCasting:
    """Whether entities, read from the world, are drawn into the lights' shadow maps (the rule
    ``row_casts_shadow`` applies to their instance rows): a visible mesh, not a portal that
    carries no light, drawn somewhere and not ``casts_shadows = False``; a portal's clone of an entity
    by its source's Visibility and ``casts_shadows``, as the extract stage writes its row.
    Glass is in the lights' see-through maps, not their depth maps: ``glass_casts`` says
    whether it counts (True where its share of a light's light is asked about too: the
    probes' scheduler, the lamps' maps while they have see-through maps).
    Made once for a frame's many movers: the glass, the portals and the clones are looked up
    once, then each mover by the MeshRef and Visibility its caller holds already."""

    def __init__(self, world: World, glass_casts: bool = False) -> None:
        self.world = world
        self._see_through = {entity for entity, portal in world.query_one(Portal) if not portal.carries_light}
        if not glass_casts:
            self._see_through |= {entity for entity, _ in world.query_one(Refractive)}
        self._clones = {entity: clone.source for entity, clone in world.query_one(PortalClone)}

    def casts(self, entity: int, mesh_ref: MeshRef, visibility: Visibility | None) -> bool:
        if not mesh_ref.visible or entity in self._see_through:
            return False
        source = self._clones.get(entity)
        if source is not None and self.world.exists(source):
            mesh_ref = self.world.try_get(source, MeshRef) or mesh_ref
            visibility = self.world.try_get(source, Visibility)
        return mesh_ref.casts_shadows and (visibility is None or visibility.hidden_kinds != KIND_MASK)


def glsl_defines() -> dict[str, str]:
    """``VIEW_KIND_BITS``: the kinds' bit count, ``NO_SHADOW_BIT``, ``NO_RECEIVE_BIT`` and
    ``OPENING_CASTS_BIT``, for ``shaders/include/visibility.glsl``."""
    return {"VIEW_KIND_BITS": f"{VIEW_KINDS}u", "NO_SHADOW_BIT": f"{NO_SHADOW_BIT}u",
            "NO_RECEIVE_BIT": f"{NO_RECEIVE_BIT}u", "OPENING_CASTS_BIT": f"{OPENING_CASTS_BIT}u"}
