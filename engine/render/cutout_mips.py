"""Mip levels of a cutout's texture that keep its coverage (Castaño, "Computing Alpha Mipmaps",
2010; Unity's "Mip Maps Preserve Coverage").

A cutout (``Material.alpha_cutoff``) draws where its alpha reaches the cutoff.  Averaged
down the mip chain, thin parts (a branch, a leaf, a fence wire) fall under it: at a distance
a tree loses its leaves and a fence its wires.  Each level's alpha is scaled so that the
share of it at or over the cutoff is level 0's, found by bisection on the scale.  The share
is measured as the sampler sees the level: 4 x 4 points a texel, each the bilinear blend of
its neighbours (an isolated texel just over the cutoff covers only its middle once
filtered).  Colour is the driver's own mip chain (``build_mipmaps``, sRGB-correct); only
alpha is rescaled."""
from __future__ import annotations

import numpy as np

SCALE_STEPS = 14        # bisection steps on the scale
MAX_ALPHA_SCALE = 64.0  # a level's alpha is multiplied by at most this
FILTERED_TEXELS = 256 * 256  # larger levels are measured texel by texel (near the camera they are
                             # read as they are; the filtered measure costs 16 arrays a step)
_OFFSETS = (-0.375, -0.125, 0.125, 0.375)  # the 4 x 4 points' offsets from a texel's middle


def filtered_samples(alpha: np.ndarray) -> np.ndarray:
    """``alpha`` (float, one level, repeating) at 4 x 4 points a texel, bilinearly blended
    with its neighbours as the sampler does: an array of 16 levels."""
    points = []
    for dx in _OFFSETS:
        across = (1.0 - abs(dx)) * alpha + abs(dx) * np.roll(alpha, -1 if dx > 0 else 1, axis=1)
        for dy in _OFFSETS:
            points.append((1.0 - abs(dy)) * across + abs(dy) * np.roll(across, -1 if dy > 0 else 1, axis=0))
    return np.stack(points)


def alpha_share(alpha: np.ndarray, cutoff: float, filtered: bool = False) -> float:
    """The share of ``alpha`` (uint8) at or over ``cutoff`` (the shader discards below it):
    texel by texel, or (``filtered``) as the sampler blends it."""
    values = alpha.astype(np.float32) / 255.0
    if filtered:
        values = filtered_samples(values)
    return float((values >= cutoff).mean())


def keep_alpha_share(alpha: np.ndarray, cutoff: float, target: float) -> np.ndarray:
    """``alpha`` (uint8, one mip level) scaled so its coverage at ``cutoff`` is as near
    ``target`` as a scale can make it (uint8 again); left as it is where it is near already."""
    values = alpha.astype(np.float32) / 255.0
    if cutoff <= 0.0 or values.size == 0:
        return alpha
    samples = filtered_samples(values) if values.size <= FILTERED_TEXELS else values[None]

    def covered(scale: float) -> float:
        return float((samples * scale >= cutoff).mean())

    if abs(covered(1.0) - target) <= 0.5 / values.size + 0.01:
        return alpha  # already about right: left as the driver made it
    low, high = 0.0, MAX_ALPHA_SCALE
    for _ in range(SCALE_STEPS):  # coverage grows with the scale
        middle = 0.5 * (low + high)
        if covered(middle) < target:
            low = middle
        else:
            high = middle
    best = min((low, high), key=lambda s: abs(covered(s) - target))
    return np.clip(np.rint(values * best * 255.0), 0, 255).astype(np.uint8)
