"""sRGB's transfer functions (IEC 61966-2-1), the one Python copy: texture colours, vertex
colours and checker colours are decoded to linear light here exactly as the GL's sRGB texture
decode does it, and linear colours the output holds are encoded here as
``shaders/include/color.glsl`` does it (``tests/test_one_owner.py`` holds them equal)."""
from __future__ import annotations

import numpy as np


def srgb_to_linear(encoded: np.ndarray | float) -> np.ndarray:
    """sRGB-encoded values in [0, 1] to linear light (float64, the shape given)."""
    c = np.asarray(encoded, np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(linear: np.ndarray | float) -> np.ndarray:
    """Linear values to sRGB-encoded ones in [0, 1] (clamped first; float64, the shape given)."""
    c = np.clip(np.asarray(linear, np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, c * 12.92, 1.055 * c ** (1.0 / 2.4) - 0.055)
