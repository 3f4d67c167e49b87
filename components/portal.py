"""Paired portals (each a window onto its partner: the view is carried by
the pair's relative transform) and the things that travel through them."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pyglm import glm

from components.limits import MAX_VIEW_DEPTH
from components.tracking import (
    ComponentValueError,
    TrackedComponent,
    _items,
    color,
    end_image_choice,
    finite,
    integer,
    vec3,
)
from components.visibility import LAYER_FIELDS, ShownLayers


class PortalPartnerWarning(UserWarning):
    """A Portal's ``partner`` names no entity of its world, so the portal stays closed."""


@dataclass(eq=False)
class Portal(ShownLayers):
    """A rectangular window onto the partner portal (not on an entity with a Mirror: refused,
    ``mirror_rules.check_one_surface``; nor with a Reflective, Refractive or Emissive:
    ``mirror_rules.check_surface_looks``).

    The rectangle is ``size`` (width, height) in the entity's local XY plane, facing local
    +Z; looking into its front shows what lies in front of the partner, on the pixels of the
    entity's mesh: a quad of ``size`` (one with depth along local Z, a box, is said in a
    ComponentWarning: its sides would show the view too; so is a flat mesh whose outline is
    not ``size``'s rectangle: the view would show where nothing goes through, or the other
    way round: ``mirror_rules.warn_portal_not_flat``).  ``closed_color``
    is what it shows when it has no working partner (deleted, disabled); cut by the view
    budget or past the recursion limit, it shows what lies beyond the partner as the probes
    there (or the sky) saw it, its fallback.  A ``partner`` that names an entity never made in its world is a
    ``PortalPartnerWarning`` from the frame's rules stage (once a portal and partner id:
    such a portal stays closed); a partner spawned after the portal (a pair spawned one
    after the other) is no mistake, and a partner deleted later closes it without a word
    (deleting one of a pair is how a pair is closed).
    ``shows_layers`` (None: all) and ``hides_layers`` are the reflection layers its view
    shows (``components.visibility``): ``hides_layers=[3]`` shows all but layer 3.
    ``priority`` and ``end_image``: as on ``Mirror`` (the view budget's order; past the
    depth limit, last frame's image instead of the fallback, "auto" for a facing pair).
    ``carries_light`` (off by default): lights in front of it shine out of its partner's
    opening (their images carried by the pair's transform), with shadows on both sides, and
    its opening casts a shadow in their own maps: the light it takes in leaves by the
    partner instead of going on behind it (off, the opening casts none: light passes).
    """

    SHAREABLE = False  # one entity's own state: see components.tracking
    partner: int | None = None
    size: Any = (2.0, 3.0)
    max_depth: int = 4
    enabled: bool = True
    priority: int = 0
    end_image: Any = "auto"
    closed_color: Any = field(default_factory=lambda: glm.vec4(0.02, 0.02, 0.03, 1.0))
    carries_light: bool = False

    def check_attach(self, entity: int) -> None:
        """Called by the world before the component joins ``entity`` (the world's entities are
        esper's current ones then)."""
        if self.partner == entity:
            raise ComponentValueError(f"Portal on entity {entity} is paired with itself")

    def _validate(self, name: str, value: Any) -> Any:
        if name == "partner" and value is not None:
            if not isinstance(value, int) or isinstance(value, bool) or value <= 0:
                raise ComponentValueError(f"Portal.partner must be an entity id, got {value!r}")
        if name == "partner" and value is not None and value == self._entity and self._sink is not None:
            raise ComponentValueError(f"Portal on entity {value} is paired with itself")
        if name == "size":
            try:
                w, h = (finite(self, name, v, positive=True) for v in value)
            except (TypeError, ValueError) as exc:
                if isinstance(exc, ComponentValueError):
                    raise
                raise ComponentValueError(f"Portal.size must be (width, height) > 0, got {value!r}") from None
            world = getattr(self, "_world_ref", None)
            if world is not None:
                for entity in self._entities:  # a size that is not its mesh's outline is said at the write
                    world.check_invariants(entity, Portal, size=(w, h))
            return (w, h)
        if name == "max_depth":
            if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= MAX_VIEW_DEPTH:
                raise ComponentValueError(f"Portal.max_depth must be an int in [0, {MAX_VIEW_DEPTH}], got {value!r}")
        if name == "priority":
            return integer(self, name, value, low=-1000, high=1000)
        if name == "end_image":
            return end_image_choice(self, name, value)
        if name in ("enabled", "carries_light") and not isinstance(value, bool):
            raise ComponentValueError(f"Portal.{name} must be True or False, got {value!r}")
        if name == "closed_color":
            return color(self, name, value)
        if name in LAYER_FIELDS:
            return super()._validate(name, value)  # ShownLayers' check
        return value


MAX_SPEED = 1e6  # m/s; a Traveller faster than this leaves float32 range within a game's lifetime


@dataclass(eq=False)
class Traveller(TrackedComponent):
    """An entity that goes through portals, with everything below it (a model's root: its
    parts go with it, sliced at the portal while they straddle it); ``velocity`` (world,
    m/s) moves it each frame and is turned with it when it travels."""

    SHAREABLE = False  # one entity's own state: see components.tracking
    velocity: Any = field(default_factory=glm.vec3)

    def _validate(self, name: str, value: Any) -> Any:
        if name == "velocity":
            v = vec3(self, name, value)
            if glm.length(v) > MAX_SPEED:
                # 3e38 m/s would overflow the position float32 frames later, far from the cause.
                raise ComponentValueError(f"Traveller.velocity must be at most {MAX_SPEED:.0e} m/s long, got {value!r}")
            return v
        return value


@dataclass(eq=False)
class Slice(TrackedComponent):
    """Draw only the part of the entity in front of ``plane`` (world n.x + d >= 0).

    Written by the PortalSliceSystem on things that straddle a portal (so the part
    already through does not show at the entry side); the render system turns it into a per-instance clip plane.
    """

    SHAREABLE = False  # one entity's own state: see components.tracking
    plane: Any = field(default_factory=lambda: glm.vec4(0.0, 0.0, 0.0, 1.0))

    def _validate(self, name: str, value: Any) -> Any:
        if name == "plane":
            # Each part through float() (glm.vec4 wraps an int past 2**63, 2**64 to 0, reads
            # bytes as their codes and one number as four), not text or a bool.
            parts = _items(value) if not isinstance(value, (str, bytes, dict)) else []
            if len(parts) != 4 or any(isinstance(c, (bool, np.bool_)) for c in parts):
                raise ComponentValueError(f"Slice.plane must be 4 numbers (nx, ny, nz, d), got {value!r}")
            return glm.vec4(*(finite(self, name, c) for c in parts))
        return value


@dataclass(eq=False)
class PortalClone(TrackedComponent):
    """Marks the stand-in drawn at the partner portal for the part of ``source`` that went
    through ``portal``; the id image reports it as ``source``."""

    SHAREABLE = False  # one entity's own state: see components.tracking
    source: int = 0
    portal: int = 0

    def _validate(self, name: str, value: Any) -> Any:
        if name in ("source", "portal"):
            return integer(self, name, value, low=0, high=2**31 - 1)  # an entity id (it goes into the id image)
        return value
