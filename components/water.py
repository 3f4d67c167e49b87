"""Water: a still or moving pond on a Mirror entity."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from pyglm import glm

from components.fog import MAX_FOG_DENSITY, MAX_FOG_VOLUME_SIDE, MIN_FOG_VOLUME_SIDE
from components.tracking import ComponentValueError, TrackedComponent, color, finite, vec3

MAX_WATER_SPEED = 100.0    # normal-map tiles a second; faster is a strobe, not a wave
MAX_WATER_TILING = 1000.0  # repeats of the map across the mirror's UV square
MAX_WATER_ABSORPTION = 64.0  # a channel's share of fog_density: past it the channel is gone within millimetres
MIN_FOAM_SIZE = 0.001        # metres: the least foam_depth and foam_scale
MAX_FOAM_SCALE = 100.0       # metres across a foam cell


@dataclass(eq=False)
class Water(TrackedComponent):
    """Makes the entity's Mirror a water surface, as game engines draw ponds and pools: the
    planar reflection weighted by Fresnel, the surface rippled by a moving normal map, and
    what lies below seen through it.

    Needs a ``Mirror`` on the same entity (the view tree plans its reflection as any
    mirror's) with ``roughness`` 0: the waves, not a blur, break up the image.  The look:

    - **Fresnel.**  The reflection's weight is Schlick's approximation for a dielectric of
      index ``ior`` (F0 = ((ior - 1) / (ior + 1))^2, 0.02 for water's 1.333) at the angle
      between the eye ray and the (rippled) surface normal: a few percent looking straight
      down, everything at grazing angles.  It replaces the Mirror's fixed mix:
      ``Mirror.reflect_rate`` scales it (1, the default, is the physical weight) and
      ``Mirror.color`` tints what is reflected.  The light a water reflects
      (``Mirror.reflects_light``) is weighed the same way, at the angle each lit point's
      light met the (flat) surface.
    - **What is below.**  The water quad's own shading is what the weight leaves: its
      ``Material`` with an alpha below 1 is drawn see-through (the scene pass's blended
      slot), so the pond's floor and anything under the surface show through, tinted by
      the material's colour in proportion to its alpha (the water's murk: 0 is clear).
      What is below is seen bent by the surface (Snell's law for ``ior`` at the rippled
      normal): the view's composite reads a copy of the level it goes into where each pixel's
      refracted ray meets a floor as deep as the one drawn below it (refined over three
      turns), so a still pool looks shallower than it is and a rippled one wavers
      (``shaders/mirror_composite.frag`` ``water_below``); what is below a pixel whose bent
      ray meets it off the picture is seen unbent (the copy holds nothing there), and the
      two blend over a band along the edge, so a deep pool seen steeply shows no seam; a surface shown by its fallback
      (no view of its own: cut by the view budget, switched off, faded) bends it the same
      way, and a partly faded one's view blends over its fallback's bent pixels.
    - **Waves.**  ``Material.normal_map`` (``normal_scale`` its strength) is read twice in
      the reflection's composite and the two heightfields summed (their slopes averaged,
      ``cross`` the second's share): once ``tiling`` times across the mirror's UVs,
      scrolling along ``direction`` (in UV space) at ``speed`` tiles a second, and once
      turned a quarter turn at 1.7 times that tiling, its waves crossing the first's and
      scrolling across them (along ``direction`` turned a quarter turn, at ``speed`` of its
      own smaller tiles a second), so the pattern never slides by as one piece (the
      two-layer scrolling normal maps of Valve's and Unity's water).  ``offset`` is where
      the waves are (the first layer's shift in map tiles, u and v, each kept in [0, 1):
      the map repeats): the surfaces stage moves it on by speed x dt along the direction
      every frame, so a change of speed or direction carries on from where the waves are,
      and a saved level or an exported scene draws them where they were (a game may set
      it too).  The waves bend the reflection (the
      bumpy-mirror lookup) and the Fresnel angle.  Without a normal map the water is
      still: a Fresnel-weighted mirror.
    - **From below.**  With the camera under the surface (behind its plane) the surface is
      seen from the water: past the critical angle (48.6 degrees from straight up for 1.333)
      it reflects all of what is under it (total internal reflection), and inside that cone,
      Snell's window, it shows the air above, bent away from the normal (the whole sky and
      what stands over the pond squeezed into the cone, brightest and most bent at its rim),
      under the reflection by Fresnel's weight from the water's side.  The surfaces stage
      makes each water's state for both sides; the view trees' planner holds both, and each
      view, at any level (a portal's view out under the pond, a mirror's under it), sees the
      side facing its eye; the planner, claims and composites then take it as any mirror.
    - **The water's body** (``fog_density`` per metre, 0 by default: clear; ``fog_color``
      linear; ``depth`` metres): the light's way through the water below the surface, down
      to ``depth`` under its outline, is fogged as a FogVolume's is, at the same density
      everywhere in that box: a thing under a murky pond fades into ``fog_color`` with its
      distance through the water, from above as from below (a camera under the surface sees
      the pond's far side lost in it), and the light reaching what is under the surface
      comes through it too (the sun's and the lamps' along their way, the sky's down through
      the water over the point).  It fogs every view, as a ``FogVolume`` does, and
      counts among their ``MAX_FOG_VOLUMES`` (a flat water mesh only: its outline is the box's top).
      ``absorption`` (linear RGB, each channel 0 to ``MAX_WATER_ABSORPTION``; (1, 1, 1) by
      default: every colour alike) is each channel's share of that density: real water takes
      red within a few metres, green slower and blue slowest (Pope and Fry's pure water:
      about 0.35, 0.06 and 0.01 per metre at 650, 550 and 450 nm), so with ``absorption=(3,
      1, 0.5)`` a white stone 2 m down looks blue-green and the light reaching it comes down
      tinted so.  A channel's light through d metres keeps exp(-fog_density x its share x
      d), on the view's way (what is seen becomes ``fog_color`` as its light goes) and on
      the light's (the suns', the lamps', the sky's, and the light shafts'), as HDRP's water
      takes its absorption and Crest its colour with depth.
    - **Shore foam** (``foam``, 0 by default: none; 1: all of it): white water where the
      water is shallow: where what the view sees under a point of the surface is less than
      ``foam_depth`` metres below it (along the shore, and beside what stands in the water on
      the sides the view sees under the surface), a pattern of cells ``foam_scale`` metres
      across (carried with the waves' ``offset``; a still water's stays) covers the
      surface, all of it at the water's edge and less of it deeper, in ``foam_color`` (a
      linear albedo), lit as any surface is (the suns and their shadows, the lamps, the light
      from all round), over the water's reflection and what is seen through it
      (``shaders/include/foam.glsl``).  Drawn in every view the view trees draw, a probe's
      faces at any ``depth`` too.
    - **Ripples**: a ``Ripples`` component beside it makes it ripple (rings from drops, rain,
      and what wades through it with a ``Wake``: ``components/ripples.py``), their slopes
      bending the reflection and what is seen through the surface as the waves do.
    - **Caustics** (``caustics``, 0 by default: none; 1: all of them): the suns' light (and
      the lamps' over the water: up to four) through the waves is bent by each one and
      gathers where the bent rays converge, so what lies
      under the water, inside its outline and down to ``depth``, is lit in the bright
      moving net of a sunny pool: each point's sunlight times the ratio of the surface's
      area its light came through to the area it spreads over (``shaders/include/caustics.glsl``),
      blurred with depth by the sun's disc.  A water that also reflects light
      (``Mirror.reflects_light``) throws what its waves gather of the sun's light back up, onto
      what lies up to ``depth`` over it (the net of light on the walls over a sunlit pool).
      Needs waves (``Material.normal_map``); up to
      four waters gather the sun at once, the nearest the active camera
      (``engine/render/caustics.py``).
    """

    ior: float = 1.333
    speed: float = 0.05
    direction: Any = (1.0, 0.0)
    tiling: float = 1.0
    cross: float = 0.5
    offset: Any = (0.0, 0.0)
    fog_density: float = 0.0
    fog_color: Any = field(default_factory=lambda: glm.vec4(0.02, 0.12, 0.14, 1.0))
    depth: float = 10.0
    absorption: Any = (1.0, 1.0, 1.0)
    caustics: float = 0.0
    foam: float = 0.0
    foam_depth: float = 0.3
    foam_scale: float = 0.2
    foam_color: Any = field(default_factory=lambda: glm.vec4(0.85, 0.88, 0.9, 1.0))

    def _validate(self, name: str, value: Any) -> Any:
        if name == "fog_density":
            return finite(self, name, value, low=0.0, high=MAX_FOG_DENSITY)
        if name == "fog_color":
            return color(self, name, value)
        if name == "depth":
            return finite(self, name, value, low=MIN_FOG_VOLUME_SIDE, high=MAX_FOG_VOLUME_SIDE)
        if name in ("caustics", "foam"):
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "foam_depth":
            return finite(self, name, value, low=MIN_FOAM_SIZE, high=MAX_FOG_VOLUME_SIDE)
        if name == "foam_scale":
            return finite(self, name, value, low=MIN_FOAM_SIZE, high=MAX_FOAM_SCALE)
        if name == "foam_color":
            return color(self, name, value)
        if name == "absorption":
            return vec3(self, name, value, low=0.0, high=MAX_WATER_ABSORPTION, why=" (its share of fog_density)")
        if name == "ior":
            return finite(self, name, value, low=1.0, high=4.0)
        if name == "speed":
            return finite(self, name, value, low=0.0, high=MAX_WATER_SPEED)
        if name == "tiling":
            return finite(self, name, value, positive=True, high=MAX_WATER_TILING)
        if name == "cross":
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "offset":
            u, v = self._pair(name, value)
            return (u % 1.0, v % 1.0)
        if name == "direction":
            u, v = self._pair(name, value)
            length = math.hypot(u, v)
            if not length > 0.0 or not math.isfinite(length):
                raise ComponentValueError(f"Water.direction must not be the zero vector, got {value!r}")
            return (u / length, v / length)
        return value

    def _pair(self, name: str, value: Any) -> tuple[float, float]:
        try:
            u, v = (finite(self, name, c) for c in value)
        except (TypeError, ValueError) as exc:
            if isinstance(exc, ComponentValueError):
                raise
            raise ComponentValueError(f"Water.{name} must be two numbers (u, v), got {value!r}") from None
        return u, v

    @property
    def f0(self) -> float:
        """Reflectance looking straight down (Schlick's F0 for this index against air)."""
        return f0_from_ior(self.ior)


def f0_from_ior(ior: float) -> float:
    """Schlick's F0, the reflectance at normal incidence of a dielectric of index ``ior``
    against air: ((ior - 1) / (ior + 1))^2.  The one Python copy; the shaders' is
    ``f0_from_ior`` in ``shaders/include/ggx.glsl`` (refraction)."""
    return ((ior - 1.0) / (ior + 1.0)) ** 2
