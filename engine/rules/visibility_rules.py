"""The visibility rule (``components/visibility.py``, which also packs its code): whether a
view draws an entity, defined once.  Every place that decides it calls this module: the scene
shaders (per instance, through ``shaders/include/visibility.glsl``, whose ``VIEW_KIND_BITS``
is ``glsl_defines`` here), the view planner (which mirrors and portals a parent view draws:
``SurfaceTable.drawn_in``) and the probes' scheduler (which moves a probe can see: ``ChangedBoxes.seen_by``).

One packing serves both sides, an integer of ``VIEW_KINDS`` bits of kinds of view and
``REFLECTION_LAYERS`` bits of layers above them (``visibility_code``):

- an entity's code: the kinds of view it is hidden in and the layers it belongs to
  (``entity_code``; it rides in an instance row's float ``tint.w``, exact below 2^24);
- a view's mask: the kinds of view it is (accumulated along its chain of surfaces) and the
  layers it shows (``View.view_mask``, the Camera block's ``skip.z``).

A view draws an entity when it is of no kind the entity is hidden in and they share a layer
(``drawn_in``); an entity hidden in every kind of view is drawn nowhere and casts no shadow
(``hidden_everywhere``), and one whose ``MeshRef.casts_shadows`` is off is drawn but casts
none (``NO_SHADOW_BIT`` in its code, above the layers, which no view's mask has: ``casts_shadow``)."""
from __future__ import annotations

from typing import TypeVar

import numpy as np

from components import MeshRef, Visibility
from components.limits import NO_SHADOW_BIT, VIEW_KINDS
from components.visibility import DRAWN_EVERYWHERE, KIND_MASK, visibility_code
from engine.core.world import World

Code = TypeVar("Code", int, np.ndarray)


def entity_code(visibility: Visibility | None, drawn: bool = True, casts_shadows: bool = True) -> int:
    """Where an entity is drawn: its ``Visibility``'s hidden kinds and layers
    (``DRAWN_EVERYWHERE`` without one), with ``NO_SHADOW_BIT`` when it casts no shadow
    (``casts_shadows`` False: its ``MeshRef.casts_shadows``); 0, on no layer, when it is not
    drawn at all (``drawn`` False: an invisible mesh)."""
    if not drawn:
        return 0
    code = DRAWN_EVERYWHERE if visibility is None else visibility_code(visibility.hidden_kinds, visibility.layer_mask)
    return code if casts_shadows else code | NO_SHADOW_BIT


def drawn_code(world: World, entity: int) -> int:
    """Where ``entity`` is drawn, read from the world: ``entity_code`` of its Visibility, and
    no layer at all with an invisible mesh (a mirror's or portal's own, for the planner)."""
    mesh_ref = world.try_get(entity, MeshRef)
    return entity_code(world.try_get(entity, Visibility), drawn=mesh_ref is None or mesh_ref.visible)


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


def glsl_defines() -> dict[str, str]:
    """``VIEW_KIND_BITS``: the kinds' bit count, and ``NO_SHADOW_BIT``, for
    ``shaders/include/visibility.glsl``."""
    return {"VIEW_KIND_BITS": f"{VIEW_KINDS}u", "NO_SHADOW_BIT": f"{NO_SHADOW_BIT}u"}
