"""Clouds: a layer of them over a generated sky (``CloudLayer``), drifting on the wind."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from pyglm import glm

from components.limits import MAX_CLOUD_DENSITY, MAX_CLOUD_WIND
from components.tracking import ComponentValueError, TrackedComponent, boolean, color, finite, integer

MAX_CLOUD_SEED = 65535   # CloudLayer.seed: which pattern (the GPU takes it as a float, exact below 2^24)


@dataclass(eq=False)
class CloudLayer(TrackedComponent):
    """A layer of clouds over the world's generated ``Skybox`` (its gradient or atmosphere
    sky; a photographed sky has its own), as HDRP's Cloud Layer and the cloud planes of
    Godot's and three.js's skies: drawn by the sky pass per pixel, in the sky's cube map (so
    mirrors, water and chrome reflect them and the sky's light is whiter under them), hiding
    the sun's and the moon's discs where they pass, and casting their shadows on the world
    (the sun's light dimmed where a cloud stands between a point and the sun).

    The clouds are a sheet ``height`` metres above the world's y = 0 on a sphere the Earth's
    size (so they crowd towards the horizon and fade into its haze) whose thickness at each
    place is fractal noise (value noise, ``scale`` metres the largest clouds, three more
    octaves at half the size each: ``engine/render/clouds.py``): ``coverage`` is the share of
    the sheet under cloud (0 clear, 1 overcast), ``density`` the optical depth straight up
    through a cloud's thickest part (4: 2% of the sun through it; seen slanting, more), and
    ``thickness`` metres the sheet's depth, over which sunlight slanting in is shadowed by the
    cloud beside it (a cloud's sunny side bright, its far side grey).  Lit by the sky's sun
    (the disc's colour: an atmosphere's reddened at dusk) with a silver lining towards it, and
    by the clear sky overhead; ``color`` is their albedo.  ``wind`` (metres a second along x
    and z) moves ``drift``, the metres the pattern has moved, each frame (the clouds stage);
    a game or a level may set ``drift`` to put them somewhere.  ``shadows`` False: they shade
    nothing.  ``seed`` picks another pattern.

    One a world (the lowest entity's; more are said once and left out).  The sky is at
    infinity: the clouds stand over the eye wherever it goes, their shadows over the world's
    origin (a point's shadow is the cloud the way to the sun from it, 1500 m up)."""

    SHAREABLE = False   # its drift is its own
    coverage: float = 0.5
    density: float = 4.0
    height: float = 1500.0
    scale: float = 2000.0
    thickness: float = 400.0
    color: Any = field(default_factory=lambda: glm.vec4(1.0, 1.0, 1.0, 1.0))
    wind: Any = (10.0, 0.0)
    drift: Any = (0.0, 0.0)
    shadows: bool = True
    seed: int = 0

    def _validate(self, name: str, value: Any) -> Any:
        if name == "coverage":
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "density":
            return finite(self, name, value, low=0.0, high=MAX_CLOUD_DENSITY)
        if name == "height":
            return finite(self, name, value, low=10.0, high=20000.0)
        if name == "scale":
            return finite(self, name, value, low=10.0, high=100000.0)
        if name == "thickness":
            return finite(self, name, value, low=0.0, high=10000.0)
        if name == "color":
            return color(self, name, value)
        if name in ("wind", "drift"):
            x, z = self._pair(name, value)
            if name == "wind" and math.hypot(x, z) > MAX_CLOUD_WIND:
                raise ComponentValueError(
                    f"CloudLayer.wind must be at most {MAX_CLOUD_WIND:g} m/s, got {value!r}")
            return (x, z)
        if name == "shadows":
            return boolean(self, name, value)
        if name == "seed":
            return integer(self, name, value, low=0, high=MAX_CLOUD_SEED)
        return value

    def _pair(self, name: str, value: Any) -> tuple[float, float]:
        try:
            x, z = (finite(self, name, c) for c in value)
        except (TypeError, ValueError) as exc:
            if isinstance(exc, ComponentValueError):
                raise
            raise ComponentValueError(f"CloudLayer.{name} must be two numbers (x, z), got {value!r}") from None
        return x, z
