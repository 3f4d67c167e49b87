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


# Rec. 709 luminance of linear RGB: how bright a colour x intensity looks.
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
# Chromaticities (CIE 1931 xy) of red, green, blue and white: Rec. 709 / sRGB's, the primaries
# the engine's linear colours are in, with the D65 white point.
REC709_CHROMATICITIES = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)
# Bradford's cone response matrix (Lam 1985), the chromatic adaptation ICC profiles and
# OpenColorIO use to carry one white point's colours to another's.
_BRADFORD = np.array([[0.8951, 0.2664, -0.1614],
                      [-0.7502, 1.7135, 0.0367],
                      [0.0389, -0.0685, 1.0296]])


def rgb_to_xyz_matrix(chromaticities: tuple[float, ...]) -> np.ndarray:
    """The 3 x 3 matrix taking linear RGB in the primaries ``chromaticities`` (red x, y, green
    x, y, blue x, y, white x, y) to CIE XYZ, white (1, 1, 1) going to the white point at Y = 1
    (SMPTE RP 177's derivation)."""
    rx, ry, gx, gy, bx, by, wx, wy = (float(c) for c in chromaticities)
    primaries = np.array([[x / y, 1.0, (1.0 - x - y) / y] for x, y in ((rx, ry), (gx, gy), (bx, by))]).T
    white = np.array([wx / wy, 1.0, (1.0 - wx - wy) / wy])
    return primaries * np.linalg.solve(primaries, white)


def xyz_to_rec709_matrix() -> np.ndarray:
    """CIE XYZ (D65) to linear Rec. 709 RGB: the inverse of ``rgb_to_xyz_matrix`` of Rec. 709."""
    return np.linalg.inv(rgb_to_xyz_matrix(REC709_CHROMATICITIES))


def to_rec709_matrix(chromaticities: tuple[float, ...]) -> np.ndarray:
    """The 3 x 3 matrix taking linear RGB in the primaries ``chromaticities`` to linear Rec. 709
    RGB: to XYZ, the white point carried to D65 by Bradford's adaptation (so the file's white
    stays white), then to Rec. 709.  ACES2065-1's (AP0, white near D60) gives the matrix
    OpenColorIO's ACES config uses for its linear sRGB output."""
    source = rgb_to_xyz_matrix(chromaticities)
    cones = _BRADFORD @ np.stack([source @ np.ones(3), rgb_to_xyz_matrix(REC709_CHROMATICITIES) @ np.ones(3)], axis=1)
    adapt = np.linalg.inv(_BRADFORD) @ np.diag(cones[:, 1] / cones[:, 0]) @ _BRADFORD
    return xyz_to_rec709_matrix() @ adapt @ source
