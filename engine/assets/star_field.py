"""A night sky's stars as six cube-map faces: the space an atmosphere Skybox shows beyond its
air (``Skybox(model="atmosphere", faces=star_faces())``), where the air lets it through and is
itself dark, so the stars come out as the sun sets, fade towards the horizon and are lost in
the day's sky.

Stars fall evenly over the sphere; their brightness follows a power law (many faint, a few
bright, as a sky's stars by magnitude), their colours run from orange to blue-white (a star's
temperature, 3000 to 12000 K, as an RGB ramp).  Each lights one texel, so a star is as wide
as a texel of the faces (``size`` 512: about 0.18 degrees).
"""
from __future__ import annotations

import math

import numpy as np

from engine.core.cube_faces import face_texels
from engine.core.errors import AssetError

MAX_STARS = 1_000_000
COOL = np.array([1.0, 0.62, 0.35])    # a 3000 K star's colour, roughly
HOT = np.array([0.72, 0.82, 1.0])     # a 12000 K star's


def star_faces(size: int = 512, stars: int = 6000, brightness: float = 1.0, seed: int = 0) -> np.ndarray:
    """(6, size, size, 3) float32 faces of ``stars`` stars (GL's face order, linear colour),
    the faintest ``brightness`` x 0.05 and the brightest at most 40 times that; ``seed`` picks
    the sky.  ``size`` 16 to 2048, ``stars`` 0 to ``MAX_STARS``, ``brightness`` finite and >= 0."""
    if isinstance(size, bool) or not isinstance(size, int) or not 16 <= size <= 2048:
        raise AssetError(f"star_faces: size must be a whole number of texels from 16 to 2048, got {size!r}")
    if isinstance(stars, bool) or not isinstance(stars, int) or not 0 <= stars <= MAX_STARS:
        raise AssetError(f"star_faces: stars must be a whole number from 0 to {MAX_STARS}, got {stars!r}")
    if isinstance(brightness, bool) or not isinstance(brightness, (int, float)) or not math.isfinite(brightness) \
            or brightness < 0.0:
        raise AssetError(f"star_faces: brightness must be a finite number >= 0, got {brightness!r}")
    rng = np.random.default_rng(seed)
    ways = rng.normal(size=(stars, 3))
    ways /= np.maximum(np.linalg.norm(ways, axis=1, keepdims=True), 1e-12)
    light = brightness * 0.05 * np.minimum(rng.pareto(1.5, stars) + 1.0, 40.0)
    warmth = rng.random(stars)[:, None]
    colour = (COOL * warmth + HOT * (1.0 - warmth)) * light[:, None]
    faces = np.zeros((6, size, size, 3), np.float32)
    face, row, column = face_texels(ways, size)
    np.add.at(faces, (face, row, column), colour.astype(np.float32))
    return faces
