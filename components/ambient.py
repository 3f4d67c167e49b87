"""Ambient light where there is no sky: a sky/ground hemisphere."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pyglm import glm

from components.tracking import HALF_MAX, TrackedComponent, color, finite

# The hemisphere a world with neither a Skybox nor a HemisphereLight is lit by: dim, a
# little bluer above than below (a wall facing sideways gets their mean, 0.03 0.03 0.035).
DEFAULT_SKY = (0.04, 0.04, 0.045)
DEFAULT_GROUND = (0.02, 0.02, 0.025)


@dataclass(eq=False)
class HemisphereLight(TrackedComponent):
    """Ambient light from a sky above and a ground below, for a world without a ``Skybox``
    (with one, the sky's own irradiance lights the world, and this is not used).

    ``sky`` is the linear radiance arriving from every direction above the horizon,
    ``ground`` from every direction below, both times ``intensity``: an upward-facing white
    surface shows ``sky``, a downward-facing one ``ground``, one facing sideways their mean
    (three.js's HemisphereLight; the engine represents it as the sky's spherical harmonics,
    ``engine/render/irradiance.py``).  Inside a reflection probe's influence box the probe's
    capture lights things instead.  One a world (the lowest entity's, if several).
    """

    sky: Any = field(default_factory=lambda: glm.vec4(*DEFAULT_SKY, 1.0))
    ground: Any = field(default_factory=lambda: glm.vec4(*DEFAULT_GROUND, 1.0))
    intensity: float = 1.0

    def _validate(self, name: str, value: Any) -> Any:
        if name in ("sky", "ground"):
            return color(self, name, value)
        if name == "intensity":
            return finite(self, name, value, low=0.0, high=HALF_MAX)
        return value
