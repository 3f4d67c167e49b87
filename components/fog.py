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
from components.tracking import ComponentValueError, TrackedComponent, boolean, color, finite, integer, vec3

# The thickest fog: 1000 per metre is a millimetre's visibility, past which nothing is seen.
MAX_FOG_DENSITY = 1000.0
# The sharpest falloff: a thousandth of a metre's scale height.
MAX_FOG_FALLOFF = 1000.0
# Fog's base height within this of the origin (metres), as a camera's far plane is bounded.
MAX_FOG_HEIGHT = 1.0e6
# The strongest sun scatter: the glow towards the sun this many times the sun's light.
MAX_FOG_SUN_SCATTER = 100.0
# A FogVolume's sides: a centimetre to ten kilometres (metres).
MIN_FOG_VOLUME_SIDE, MAX_FOG_VOLUME_SIDE = 0.01, 1.0e4
# VolumetricFog: the strongest scattering, the longest march (metres) and its most steps.
MAX_VOLUMETRIC_INTENSITY = 100.0
MAX_VOLUMETRIC_DISTANCE = 10_000.0
MIN_VOLUMETRIC_STEPS, MAX_VOLUMETRIC_STEPS = 4, 128


@dataclass(eq=False)
class Fog(TrackedComponent):
    """Fog seen by the camera whose entity holds it: the active camera's fogs the frame (without
    one, no fog), and a monitor's camera's its picture (without one, the active camera's does).

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
      ``DirectionalLight``; by night the moon, where it outshines the sun once an
      atmosphere has dimmed each: ``engine.render.sky.air_light``): looking along a
      direction at angle a from it, the fog's colour gains the sun's light (colour x
      intensity) x ``sun_scatter`` x max(cos a, 0)^8, as Godot's fog sun scatter and
      Unreal's directional inscattering do.  In a mirror each stretch of the way glows by
      its own direction.
    - ``aerial_perspective`` (0 to 1, default 0): how much of the fog's colour is the sky's
      along each ray instead (the sky's cube map blurred to its 8-texel level), as Godot's
      fog aerial perspective: far things dissolve into the sky behind them, blue under a blue
      sky, orange towards a sunset, a horizon with no seam between fog and sky (1: all the
      sky's; the sun glow above is added on top).
    """

    color: Any = field(default_factory=lambda: glm.vec4(0.6, 0.65, 0.72, 1.0))
    density: float = 0.02
    height: float = 0.0
    height_falloff: float = 0.0
    sky_affect: float = 1.0
    sun_scatter: float = 0.0
    aerial_perspective: float = 0.0

    def _validate(self, name: str, value: Any) -> Any:
        if name == "aerial_perspective":
            return finite(self, name, value, low=0.0, high=1.0)
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
    shadow of a pillar across the haze.  The active camera's, and a ``Monitor`` camera's for
    its picture (through its own ``Fog``, else the active camera's).

    Along each pixel's ray from the camera to what it shows (the sky: ``distance`` on), the
    air's single scattering of the sun (the brightest ``DirectionalLight``; by night the
    moon, whichever is the brighter once an atmosphere has dimmed each) is summed in
    ``steps`` steps (``engine/render/volumetric_fog.py``): at each, the air's density (the
    Fog's, with its height falloff), what of it reaches the eye (the Fog's transmittance
    from the camera), whether the sun reaches it (the sun's shadow map, its cascades
    included) and the Henyey-Greenstein phase function of the angle between the sun's light
    and the ray.  A step starts at a different offset each pixel (and each frame under
    temporal AA), and a depth-aware filter brings the sum to every pixel and hides the
    steps' banding.  It is added to what the Fog's colour and sun glow already give (set the
    Fog's ``sun_scatter`` to 0 where the shafts should be the sun's only glow).  The lamps
    with ``PointLight.volumetric`` scatter likewise, and so does the light of the sun (or
    moon) and of those lamps through mirrors and portals that carry light
    (``Mirror.reflects_light``, ``Portal.carries_light``): a beam off a mirror, by its own
    shadow map, from where it leaves the glass or the opening.

    - ``intensity``: the share of the light the air takes away that it scatters (its
      albedo; 1 by default: none absorbed), times any artistic boost (at most 100).
    - ``albedo`` (linear RGB, each channel 0 to 1; white by default): that share colour by
      colour, as Unreal's and Godot's volumetric fog albedo: (1, 0.85, 0.6) a dusty, amber
      haze whose shafts are warmer than the light that makes them; times ``intensity``.
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
    opacity, the air's in front of it too.  Probe views have none.  The air is the Fog's and
    every ``FogVolume``'s: shafts through a bank of mist.  Without a Fog with a density or a
    FogVolume, or without a sun or such a lamp, it adds nothing and says so once (a
    ``ComponentWarning`` from the main stage); a light that casts no shadow lights the air
    everywhere it reaches.
    """

    intensity: float = 1.0
    albedo: Any = field(default_factory=lambda: glm.vec3(1.0))
    anisotropy: float = 0.6
    distance: float = 40.0
    steps: int = 32
    half_resolution: bool = True
    reflection_depth: int = 1

    def _validate(self, name: str, value: Any) -> Any:
        if name == "intensity":
            return finite(self, name, value, low=0.0, high=MAX_VOLUMETRIC_INTENSITY)
        if name == "albedo":
            return vec3(self, name, value, low=0.0, high=1.0, why=" (the share of each colour it scatters)")
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


@dataclass(eq=False)
class FogVolume(TrackedComponent):
    """A local fog volume: a bank of mist where its entity stands, a pit of smoke, a glowing
    haze in a cave (Unreal's local fog volume, Godot's FogVolume, HDRP's local volumetric
    fog), seen by every camera, in every view, with or without the camera's ``Fog``.

    - ``size`` (metres, each 0.01 to 10,000; default (4, 2, 4)): an ellipsoid this wide along
      the entity's X, Y and Z (its rotation turns it; its scale is left out), centred on its
      position.
    - ``density`` (per metre, 0 to 1000; default 0.5): the air's at its centre, falling
      smoothly to 0 at its surface (as 1 - r^2, r the distance from the centre over the
      ellipsoid's radius that way), so it has no edge: a metre through the middle of the
      default volume at 0.5 takes about two fifths of the light away (optical depth 0.49).
    - ``color`` (linear RGB; default a pale grey): what the light it takes away becomes.

    Along each stretch of a light's way (the eye to a surface, a mirror's view from its glass
    on, the sky seen past the volume) its optical depth is the integral of that density along
    the line, in closed form; the camera's ``Fog`` and every volume add theirs, and what they
    take becomes their colours weighed by their shares (``shaders/include/fog.glsl``
    ``fog_way``).  A camera's ``VolumetricFog`` scatters the sun's and the lamps' light in
    its air too: shafts through a bank of mist.  At most ``MAX_FOG_VOLUMES`` (8) at once, the
    nearest the active camera; the rest are counted in ``RenderStats.fog_volumes_cut`` and
    a ``FogLimitWarning`` says so.
    """

    size: Any = field(default_factory=lambda: glm.vec3(4.0, 2.0, 4.0))
    density: float = 0.5
    color: Any = field(default_factory=lambda: glm.vec4(0.7, 0.72, 0.75, 1.0))

    def _validate(self, name: str, value: Any) -> Any:
        if name == "size":
            value = vec3(self, name, value)
            if not all(MIN_FOG_VOLUME_SIDE <= c <= MAX_FOG_VOLUME_SIDE for c in value):
                raise ComponentValueError(
                    f"FogVolume.size must have every side in [{MIN_FOG_VOLUME_SIDE:g}, {MAX_FOG_VOLUME_SIDE:g}] "
                    f"metres, got {tuple(value)!r}")
            return value
        if name == "density":
            return finite(self, name, value, low=0.0, high=MAX_FOG_DENSITY)
        if name == "color":
            return color(self, name, value)
        return value

