"""The sun in an HDR panorama taken out as a ``DirectionalLight`` (sun extraction, as Filament's
``cmgen --extract`` and Blender's sun-position add-on's "sync to HDRI" find it), so a photographed
sky's sun casts the engine's shadows: a panorama's light from all round is spherical harmonics,
which spread a small, bright sun into a soft lobe that shadows nothing.

What counts as the sun: the pixels within ``MAX_SUN_ANGULAR_DIAMETER`` / 2 of the brightest
one whose luminance is at least ``SUN_CONTRAST`` times the panorama's median (an unclipped
sun is 10^4 to 10^5 times its sky; a disc's edge pixels, partly covered, pass too).  None
when the brightest pixel is under that (an overcast sky).  Its light is what those pixels hold
above the sky round them (the mean of a ring just outside), all but ``SUN_KEPT`` of it: the
irradiance ``color`` x ``intensity`` = 0.99 x the sum over them of (L - sky) x the pixel's
solid angle, the engine's
``DirectionalLight`` units (a surface facing it is lit ``albedo / pi`` times that).  Its
direction is that light's mean direction, its ``angular_diameter`` the circle of the disc's
solid angle (each pixel counted by its share of the peak: at least a pixel across).  The
panorama handed back holds the ring's sky in the sun's place plus the 1% left, so the sky
and the light together give the panorama's light once, not twice, and the sun's disc still
shows in the sky and sharp reflections (1% of a real sun is still far past white on screen;
1% of its light counted twice).

A sun clipped in the file (an 8-bit panorama, an HDRI saved with its sun cut at some value)
gives too little light: the file holds no more.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from components.limits import MAX_SUN_ANGULAR_DIAMETER
from engine.core.color import LUMINANCE

SUN_CONTRAST = 100.0          # the sun's pixels against the panorama's median luminance
SUN_KEPT = 0.01               # the share of the sun's light left in the sky: its disc still drawn there


@dataclass(frozen=True)
class PanoramaSun:
    """A panorama's sun as a ``DirectionalLight``'s fields: ``direction`` the way its light
    travels (world space, the panorama turned by its ``yaw``), ``color`` its light's colour
    (the brightest channel 1), ``intensity`` its irradiance at normal incidence (``color`` x
    ``intensity``), ``angular_diameter`` degrees."""

    direction: tuple[float, float, float]
    color: tuple[float, float, float]
    intensity: float
    angular_diameter: float

    def light_fields(self) -> dict[str, object]:
        """The fields to give a ``DirectionalLight`` (``DirectionalLight(**sun.light_fields())``,
        or set on one a level already has)."""
        return {"direction": self.direction, "color": self.color, "intensity": self.intensity,
                "angular_diameter": self.angular_diameter}


def pixel_directions(height: int, width: int, yaw: float = 0.0) -> np.ndarray:
    """(height, width, 3) unit world directions of an equirectangular panorama's pixel centres
    as ``engine.assets.panorama.panorama_faces`` maps them: the middle column ahead (-Z), a
    quarter right +X, the top row up; the image turned ``yaw`` degrees about +Y."""
    lat = (0.5 - (np.arange(height) + 0.5) / height)[:, None] * math.pi
    lon = ((np.arange(width) + 0.5) / width - 0.5)[None, :] * 2.0 * math.pi
    x, y, z = np.cos(lat) * np.sin(lon), np.sin(lat) + 0.0 * lon, -np.cos(lat) * np.cos(lon)
    turn = math.radians(yaw)   # panorama_faces reads world (x, z) at image (x cos - z sin, x sin + z cos)
    return np.stack([x * math.cos(turn) + z * math.sin(turn), y, -x * math.sin(turn) + z * math.cos(turn)], -1)


def find_sun(panorama: np.ndarray, yaw: float = 0.0) -> tuple[PanoramaSun | None, np.ndarray]:
    """(the panorama's sun or None, the panorama without it) for an (height, width, 3) linear
    panorama turned ``yaw`` degrees as its faces are; see the module's docstring."""
    image = np.asarray(panorama, np.float64)
    if image.ndim != 3 or image.shape[2] != 3 or min(image.shape[:2]) < 2:
        raise ValueError(f"a panorama is an (height, width, 3) image at least 2 x 2, got shape {image.shape}")
    if not np.isfinite(image).all() or image.min() < 0.0:
        raise ValueError("a panorama holds finite, non-negative linear colours")
    if not math.isfinite(yaw):
        raise ValueError(f"yaw must be a finite number of degrees, got {yaw!r}")
    height, width = image.shape[:2]
    luminance = image @ LUMINANCE
    peak = np.unravel_index(int(np.argmax(luminance)), luminance.shape)
    floor = float(np.median(luminance))
    if luminance[peak] <= SUN_CONTRAST * max(floor, 1e-30):
        return None, np.ascontiguousarray(image, np.float32)
    ways = pixel_directions(height, width, yaw)
    angle = np.degrees(np.arccos(np.clip(ways @ ways[peak], -1.0, 1.0)))
    cap = MAX_SUN_ANGULAR_DIAMETER / 2.0
    sun = (angle <= cap) & (luminance >= SUN_CONTRAST * floor)
    pixel_angle = 180.0 / height   # a pixel's height in degrees (its width at the equator)
    reach = float(angle[sun].max()) + pixel_angle
    ring = (angle > reach) & (angle <= reach + max(2.0 * pixel_angle, 0.5 * reach)) & ~sun
    sky = image[ring].mean(axis=0) if ring.any() else np.zeros(3)
    solid = (2.0 * math.pi / width) * (math.pi / height) * np.cos(
        (0.5 - (np.arange(height) + 0.5) / height) * math.pi)[:, None] * np.ones((1, width))
    excess = np.maximum(image[sun] - sky, 0.0)
    above = excess * (1.0 - SUN_KEPT) * solid[sun][:, None]
    irradiance = above.sum(axis=0)
    weight = above @ LUMINANCE
    towards = (ways[sun] * weight[:, None]).sum(axis=0)
    towards /= np.linalg.norm(towards)
    share = np.clip((luminance[sun] - sky @ LUMINANCE) / max(luminance[peak] - sky @ LUMINANCE, 1e-30), 0.0, 1.0)
    disc = max(float((share * solid[sun]).sum()), float(solid[peak]))
    diameter = min(2.0 * math.degrees(math.acos(max(-1.0, 1.0 - disc / (2.0 * math.pi)))), MAX_SUN_ANGULAR_DIAMETER)
    brightest = float(irradiance.max())
    without = image.copy()
    without[sun] = sky + SUN_KEPT * excess
    found = PanoramaSun(direction=tuple(float(v) for v in -towards),
                        color=tuple(float(v) for v in irradiance / brightest), intensity=brightest,
                        angular_diameter=diameter)
    return found, without.astype(np.float32)

