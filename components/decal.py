"""Decals: an image projected onto the surfaces inside a box (a poster, a stain, a scorch
mark, footprints, a painted line), as Godot's Decal, Unity's Decal Projector and Bevy's
decals place them.

The decal is plain data here.  The decals stage (``systems/decal_system.py``) cuts the
surfaces in its box into a mesh of their own (``engine/core/decal_clip.py``), drawn over
them as any see-through surface is, so every view (the camera's, each mirror's, portal's
and probe face's) shows it, lit as the surface under it is."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pyglm import glm

from components.tracking import HALF_MAX, ComponentValueError, TrackedComponent, color, finite, integer
from components.visibility import layer_list

# Assets are the engine's types (engine.assets.texture_data.TextureData); components import none
# of it: the field is checked by the class's ASSET_KIND.
TextureData = Any

MAX_DECAL_NORMAL_SCALE = 10.0  # Decal.normal_scale: as Material.normal_scale's bound
MAX_DECAL_ORDER = 1 << 20      # Decal.order either side of 0: far more layers of decals than a wall holds


@dataclass(eq=False)
class Decal(TrackedComponent):
    """Projects ``texture`` (None: a plain rectangle of ``color``) onto every surface inside
    the entity's box: the unit cube of its Transform, so the Transform's scale is the decal's
    width (x), height (y) and depth (z).  The image lies on the box's x-y face, right along
    +x and up along +y, and is thrown along -z (the box's local forward, as a camera looks):
    stand the entity in front of a wall facing it, or above a floor looking down.

    - ``color`` tints the image (linear RGB); its alpha is the decal's opacity.  The image's
      own alpha cuts its shape.
    - ``normal_map`` (tangent space, as a Material's) bends the light on it: a crack, a
      bullet hole's rim; ``normal_scale`` scales its bumps.
    - ``roughness`` and ``metallic``: what the decal's surface is (paint, wet mud, a metal
      plate); ``emissive``: light of its own, its colour times this power (a glowing sign).
    - ``alpha_cutoff``: a hard-edged decal, drawn solid where the image's alpha is at least
      this and not at all below (None: its edges blend).
    - ``region`` (u0, v0, u1, v1): the part of the image to throw, for decals packed in one
      image (an atlas of footprints).
    - ``angle_fade`` (start, end), degrees: a surface turned from facing the decal by more
      than ``start`` fades, and by ``end`` has none of it (a wall's side does not get a
      floor decal's smear).
    - ``depth_fade``: the share of the box's depth at each end over which it fades in (0:
      a hard cut where a surface leaves the box).
    - ``layers``: only surfaces on one of these reflection layers take it (their
      ``Visibility.layers``; None: every surface), so a character walking through a floor's
      decal is not painted.
    - ``order``: where decals overlap, one of a higher order is blended over one of a lower
      (a bullet hole over a poster: Unity's draw order, Godot's sorting offset); of the same
      order, the one whose box's middle is farther from the eye first.

    Mirrors and portals take no decal (their picture is the view beyond them), nor water,
    see-through surfaces (a Material faded by its alpha: glass is blended after every decal),
    skinned or morphed meshes (the GPU poses them), nor particles (a decal that meets a mirror
    or portal and no surface that takes it, a sticker put on a mirror, is said once in a
    ComponentWarning: it shows nowhere).  A surface that moves
    through the box, or changes its mesh, is cut again the frame it does; one parented with
    the decal under the same mover is not (nothing moved between them)."""

    texture: TextureData | None = None
    color: Any = field(default_factory=lambda: glm.vec4(1.0))
    normal_map: TextureData | None = None
    normal_scale: float = 1.0
    roughness: float = 0.5
    metallic: float = 0.0
    emissive: float = 0.0
    alpha_cutoff: float | None = None
    region: Any = (0.0, 0.0, 1.0, 1.0)
    angle_fade: Any = (60.0, 80.0)
    depth_fade: float = 0.1
    layers: Any = None
    order: int = 0

    def _validate(self, name: str, value: Any) -> Any:
        if name == "color":
            return color(self, name, value)
        if name in ("texture", "normal_map"):
            if value is not None and getattr(type(value), "ASSET_KIND", None) != "texture":
                raise ComponentValueError(f"Decal.{name} must be an engine.assets.texture_data.TextureData, "
                                          f"got {type(value).__name__}")
            return value
        if name == "normal_scale":
            return finite(self, name, value, low=0.0, high=MAX_DECAL_NORMAL_SCALE)
        if name in ("roughness", "metallic"):
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "emissive":
            return finite(self, name, value, low=0.0, high=HALF_MAX)  # (half floats, as Emissive.power)
        if name == "alpha_cutoff":
            return None if value is None else finite(self, name, value, low=0.0, high=1.0)
        if name == "region":
            return self._region(value)
        if name == "angle_fade":
            return self._angle_fade(value)
        if name == "depth_fade":
            return finite(self, name, value, low=0.0, high=0.5)
        if name == "order":
            return integer(self, name, value, low=-MAX_DECAL_ORDER, high=MAX_DECAL_ORDER)
        if name == "layers":
            if value is None:
                return None
            if isinstance(value, (list, tuple)) and not value:
                raise ComponentValueError("Decal.layers must name at least one layer (None: every surface takes it), "
                                          f"got {value!r}")
            return layer_list(self, name, value)
        return value

    def _region(self, value: Any) -> tuple[float, float, float, float]:
        try:
            u0, v0, u1, v1 = value
        except (TypeError, ValueError):
            raise ComponentValueError(f"Decal.region must be four numbers (u0, v0, u1, v1), got {value!r}") from None
        u0, v0, u1, v1 = (finite(self, "region", v, low=0.0, high=1.0) for v in (u0, v0, u1, v1))
        if u1 <= u0 or v1 <= v0:
            raise ComponentValueError(f"Decal.region must have u1 > u0 and v1 > v0 (a part of the image with "
                                      f"area), got {value!r}")
        return u0, v0, u1, v1

    def _angle_fade(self, value: Any) -> tuple[float, float]:
        try:
            start, end = value
        except (TypeError, ValueError):
            raise ComponentValueError(f"Decal.angle_fade must be two angles in degrees (start, end), "
                                      f"got {value!r}") from None
        start = finite(self, "angle_fade", start, low=0.0, high=90.0)
        end = finite(self, "angle_fade", end, low=0.0, high=90.0)
        if end < start:
            raise ComponentValueError(f"Decal.angle_fade must have end >= start (degrees from facing the decal), "
                                      f"got {value!r}")
        return start, end


@dataclass(eq=False)
class FromDecal(TrackedComponent):
    """On the entity the decals stage makes for a decal (a child of the decal's entity): the
    surfaces in its box, cut, with the decal's look.  Derived state, made again from the
    ``Decal`` whenever it or what is under it changes: a level file holds the decal alone,
    and the editor selects the decal when its mesh is clicked."""

    SHAREABLE = False
    decal: int = 0
    order: int = 0  # the decal's Decal.order: blended over the cuts of lower orders

    def _validate(self, name: str, value: Any) -> Any:
        if name == "decal" and (isinstance(value, bool) or not isinstance(value, int) or value <= 0):
            raise ComponentValueError(f"FromDecal.decal must be an entity id, got {value!r}")
        if name == "order":
            return integer(self, name, value, low=-MAX_DECAL_ORDER, high=MAX_DECAL_ORDER)
        return value
