"""Fog: light scattered and absorbed by the air between the eye and what it sees, a
component on the camera entity (as three.js puts ``Fog`` on its scene and Godot on its
Environment).

Exponential height fog (Unreal's ExponentialHeightFog, Godot's height fog): the air's
density is ``density`` per metre at ``height`` and falls by e every ``1 / height_falloff``
metres above it (0: the same everywhere).  A surface at the end of a stretch of air whose
optical depth is tau keeps ``exp(-tau)`` of its light, the rest becomes ``color``.  Along a
reflection the stretch is the light's real way, in pieces: each view fogs the stretch from
the surface it looks out of to what it shows, and each composite the stretch from its
parent's start to the surface, so a mirror shows a thing as fogged as the whole way from the
eye to the mirror and on to the thing (``shaders/include/fog.glsl``).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pyglm import glm

from components.limits import MAX_VIEW_DEPTH
from components.tracking import TrackedComponent, boolean, color, finite, integer

# The thickest fog: 1000 per metre is a millimetre's visibility, past which nothing is seen.
MAX_FOG_DENSITY = 1000.0
# The sharpest falloff: a thousandth of a metre's scale height.
MAX_FOG_FALLOFF = 1000.0
# Fog's base height within this of the origin (metres), as a camera's far plane is bounded.
MAX_FOG_HEIGHT = 1.0e6
# The strongest sun scatter: the glow towards the sun this many times the sun's light.
MAX_FOG_SUN_SCATTER = 100.0
# VolumetricFog: the strongest scattering, the longest march (metres) and its most steps.
MAX_VOLUMETRIC_INTENSITY = 100.0
MAX_VOLUMETRIC_DISTANCE = 10_000.0
MIN_VOLUMETRIC_STEPS, MAX_VOLUMETRIC_STEPS = 4, 128


@dataclass(eq=False)
class Fog(TrackedComponent):
    """Fog seen by the camera whose entity holds it (the active camera's is used; without
    one, no fog).

    - ``color``: the linear colour the air's light tends to (its alpha is not used).
    - ``density``: how much of the light a metre of air at ``height`` takes away (per metre:
      0.02 leaves ``exp(-0.02 x 100)``, 14%, of a thing 100 m off); 0 is no fog.
    - ``height`` (metres) and ``height_falloff`` (per metre, 0: the same density everywhere):
      above ``height`` the density falls by e every ``1 / height_falloff`` metres, below it
      it grows the same way, so the fog lies in the valleys.
    - ``sky_affect`` (0 to 1, default 1): how much of its fog the sky takes.  The sky lies
      infinitely far off: with the same density everywhere it is all fog colour at 1; with
      a falloff, only as much fog as the air along its direction holds.
    - ``sun_scatter`` (default 0): the air glows towards the sun (the brightest
      ``DirectionalLight``): looking along a direction at angle a from it, the fog's colour
      gains the sun's light (colour x intensity) x ``sun_scatter`` x max(cos a, 0)^8, as
      Godot's fog sun scatter and Unreal's directional inscattering do.  In a mirror each
      stretch of the way glows by its own direction.
    """

    color: Any = field(default_factory=lambda: glm.vec4(0.6, 0.65, 0.72, 1.0))
    density: float = 0.02
    height: float = 0.0
    height_falloff: float = 0.0
    sky_affect: float = 1.0
    sun_scatter: float = 0.0

    def _validate(self, name: str, value: Any) -> Any:
        if name == "color":
            return color(self, name, value)
        if name == "density":
            return finite(self, name, value, low=0.0, high=MAX_FOG_DENSITY)
        if name == "height":
            return finite(self, name, value, low=-MAX_FOG_HEIGHT, high=MAX_FOG_HEIGHT)
        if name == "height_falloff":
            return finite(self, name, value, low=0.0, high=MAX_FOG_FALLOFF)
        if name == "sky_affect":
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "sun_scatter":
            return finite(self, name, value, low=0.0, high=MAX_FOG_SUN_SCATTER)
        return value



@dataclass(eq=False)
class VolumetricFog(TrackedComponent):
    """Light shafts: the sun's light scattered towards the eye by the air of the camera's
    ``Fog``, shadowed by what stands between the air and the sun, for the camera whose
    entity holds it beside its ``Fog`` (as Unreal's volumetric fog, Godot's and HDRP's do
    for their height fog).  Sunbeams through a window, a doorway or a portal's frame, the
    shadow of a pillar across the haze.

    Along each pixel's ray from the camera to what it shows (the sky: ``distance`` on), the
    air's single scattering of the sun (the brightest ``DirectionalLight``) is summed in
    ``steps`` steps (``engine/render/volumetric_fog.py``): at each, the air's density (the
    Fog's, with its height falloff), what of it reaches the eye (the Fog's transmittance
    from the camera), whether the sun reaches it (the sun's shadow map, its cascades
    included) and the Henyey-Greenstein phase function of the angle between the sun's light
    and the ray.  A step starts at a different offset each pixel (and each frame under
    temporal AA), and a depth-aware filter brings the sum to every pixel and hides the
    steps' banding.  It is added to what the Fog's colour and sun glow already give (set the
    Fog's ``sun_scatter`` to 0 where the shafts should be the sun's only glow).

    - ``intensity``: the share of the light the air takes away that it scatters (its
      albedo; 1 by default: none absorbed), times any artistic boost (at most 100).
    - ``anisotropy``: the phase function's g, from -0.95 (light scattered back towards the
      sun) through 0 (the same every way) to 0.95 (forwards: bright shafts looking towards
      the sun); 0.6 by default, haze.
    - ``distance``: metres along each ray the air is summed (past that, or past what the
      pixel shows, nothing more is added); 40 by default.
    - ``steps``: samples along each ray (4 to 128; 32 by default): fewer are faster, more
      resolve thinner shadows.
    - ``half_resolution``: the rays marched at half the screen's size in each direction (a
      ray a 2 x 2 block) and filtered up to every pixel (True, the default); False: a ray a
      pixel.
    - ``reflection_depth``: the levels of mirror and portal views below the camera's whose
      air has its shafts too (0 to 16; 1 by default: the views of the mirrors and portals the
      camera sees, so a mirror shows the beams in the room behind the camera, and a portal
      the beams of the hall beyond; 0: the camera's view alone, a mirror showing the fog's
      colour and glow).  A view's rays start on the surface it looks out of; the air between
      the eye and the surface is its parent's.  A level's rays are marched a pixel each (its
      ``half_resolution`` is the camera's view's alone) and filtered within their own view.

    Point and spot lights light the air too, each by its ``PointLight.volumetric`` (1 by
    default), at most ``MAX_VOLUMETRIC_LAMPS`` (4) of them: its falloff, cone, cookie and
    shadow at each step, by the same phase function.

    Glass is blended over the shafts as over everything behind it: a pane dims them by its
    opacity, the air's in front of it too.  Probe views have none.  Without a Fog
    with a density, or without a sun or such a lamp, it adds nothing and says so once (a
    ``ComponentWarning`` from the main stage); a light that casts no shadow lights the air
    everywhere it reaches.
    """

    intensity: float = 1.0
    anisotropy: float = 0.6
    distance: float = 40.0
    steps: int = 32
    half_resolution: bool = True
    reflection_depth: int = 1

    def _validate(self, name: str, value: Any) -> Any:
        if name == "intensity":
            return finite(self, name, value, low=0.0, high=MAX_VOLUMETRIC_INTENSITY)
        if name == "anisotropy":
            return finite(self, name, value, low=-0.95, high=0.95)
        if name == "distance":
            return finite(self, name, value, positive=True, high=MAX_VOLUMETRIC_DISTANCE)
        if name == "steps":
            return integer(self, name, value, low=MIN_VOLUMETRIC_STEPS, high=MAX_VOLUMETRIC_STEPS)
        if name == "half_resolution":
            return boolean(self, name, value)
        if name == "reflection_depth":
            return integer(self, name, value, low=0, high=MAX_VIEW_DEPTH)
        return value
