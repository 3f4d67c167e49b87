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

from components.tracking import TrackedComponent, color, finite

# The thickest fog: 1000 per metre is a millimetre's visibility, past which nothing is seen.
MAX_FOG_DENSITY = 1000.0
# The sharpest falloff: a thousandth of a metre's scale height.
MAX_FOG_FALLOFF = 1000.0
# Fog's base height within this of the origin (metres), as a camera's far plane is bounded.
MAX_FOG_HEIGHT = 1.0e6
# The strongest sun scatter: the glow towards the sun this many times the sun's light.
MAX_FOG_SUN_SCATTER = 100.0


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

