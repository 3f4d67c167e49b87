"""The colour grade's numbers the present shader reads (``ColorGrading``,
``shaders/include/grade.glsl``, in the present's GRADE and LUT builds and a picture panel's
over the frame): the white balance as one 3 x 3 matrix on linear sRGB, and the colour table's
texture coordinates.  No GL here but the table's upload (``upload_lut``).

**White balance** is a von Kries adaptation in CAT02's cone space (CIECAM02): linear sRGB ->
CIE XYZ -> cone responses, each scaled by the target white's response over the source
white's, and back.  The target white is the CIE daylight locus at 6504 K (D65, sRGB's own
white); the source white is the locus at ``6504 K x 2 ** temperature`` (the CIE 15 daylight
formula for x, kept below 4000 K down to the 3252 K that temperature -1 gives), with y moved
by ``0.05 x tint``.  So temperature 0 and tint 0 are the identity, and a light of the
source's colour comes out neutral.
"""
from __future__ import annotations

import functools

import moderngl
import numpy as np

from components.post import ColorGrading
from engine.assets.color_lut import ColorLut

NEUTRAL_KELVIN = 6504.0   # D65 on the daylight locus
TINT_SHIFT = 0.05          # y moved by this at tint 1
# Linear sRGB (D65) -> CIE XYZ (IEC 61966-2-1), and XYZ -> CAT02 cone responses (CIECAM02).
SRGB_TO_XYZ = np.array([[0.4124564, 0.3575761, 0.1804375],
                        [0.2126729, 0.7151522, 0.0721750],
                        [0.0193339, 0.1191920, 0.9503041]])
XYZ_TO_CAT02 = np.array([[0.7328, 0.4296, -0.1624],
                         [-0.7036, 1.6975, 0.0061],
                         [0.0030, 0.0136, 0.9834]])


def grades(grading: ColorGrading | None) -> bool:
    """Whether ``grading``'s controls before the tone curve change any colour (a neutral one
    draws the build without them: the same picture, to the bit)."""
    return grading is not None and (
        grading.temperature != 0.0 or grading.tint != 0.0 or grading.contrast != 1.0
        or tuple(grading.slope) != (1.0, 1.0, 1.0) or tuple(grading.offset) != (0.0, 0.0, 0.0)
        or tuple(grading.power) != (1.0, 1.0, 1.0) or grading.saturation != 1.0)


def daylight_xy(kelvin: float) -> tuple[float, float]:
    """The chromaticity of CIE daylight of correlated colour temperature ``kelvin`` (CIE 15:
    x a cubic in 1 / T, two ranges split at 7000 K; y = -3 x^2 + 2.87 x - 0.275)."""
    t = float(kelvin)
    if t <= 7000.0:
        x = -4.6070e9 / t ** 3 + 2.9678e6 / t ** 2 + 0.09911e3 / t + 0.244063
    else:
        x = -2.0064e9 / t ** 3 + 1.9018e6 / t ** 2 + 0.24748e3 / t + 0.237040
    return x, -3.0 * x * x + 2.87 * x - 0.275


def _cone_white(x: float, y: float) -> np.ndarray:
    return XYZ_TO_CAT02 @ np.array([x / y, 1.0, (1.0 - x - y) / y])


def grade_uniforms(grading: ColorGrading) -> dict[str, bytes | float | tuple[float, float, float]]:
    """The GRADE build's uniforms by name: ``white_balance`` as the bytes of GLSL's
    column-major mat3 (worked out once for each temperature and tint), the rest as values."""
    return {"white_balance": _white_balance_bytes(grading.temperature, grading.tint),
            "contrast": grading.contrast, "slope": tuple(grading.slope), "offset": tuple(grading.offset),
            "power": tuple(grading.power), "saturation": grading.saturation}


@functools.lru_cache(maxsize=16)
def _white_balance_bytes(temperature: float, tint: float) -> bytes:
    # Row-major numpy to GLSL's column-major mat3: the transpose's bytes.
    return white_balance(temperature, tint).T.astype("f4").tobytes()


def white_balance(temperature: float, tint: float) -> np.ndarray:
    """The 3 x 3 matrix (row-major, float64) on linear sRGB for ``ColorGrading``'s
    ``temperature`` and ``tint`` (the identity for 0 and 0)."""
    if temperature == 0.0 and tint == 0.0:
        return np.eye(3)
    x, y = daylight_xy(NEUTRAL_KELVIN * 2.0 ** temperature)
    source = _cone_white(x, y + TINT_SHIFT * tint)
    target = _cone_white(*daylight_xy(NEUTRAL_KELVIN))
    adapt = np.linalg.inv(XYZ_TO_CAT02) @ np.diag(target / source) @ XYZ_TO_CAT02
    return np.linalg.inv(SRGB_TO_XYZ) @ adapt @ SRGB_TO_XYZ


def lut_lookup(lut: ColorLut) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """(scale, bias) taking a colour to the table texture's coordinates: the domain onto the
    first to the last point's texel centre (so trilinear filtering interpolates between
    points, and the texture's edge clamp clamps inputs outside the domain)."""
    n = lut.size
    lo, hi = np.array(lut.domain_min), np.array(lut.domain_max)
    scale = (n - 1) / (n * (hi - lo))
    bias = 0.5 / n - lo * scale
    return tuple(float(v) for v in scale), tuple(float(v) for v in bias)


def upload_lut(ctx: moderngl.Context, lut: ColorLut) -> moderngl.Texture3D:
    """The table as an RGBA half-float 3D texture, filtered trilinearly, clamped at its edges."""
    n = lut.size
    data = np.concatenate([lut.table, np.ones((n, n, n, 1), np.float32)], axis=-1)
    texture = ctx.texture3d((n, n, n), 4, data.astype(np.float16).tobytes(), dtype="f2")
    texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
    texture.repeat_x = texture.repeat_y = texture.repeat_z = False
    return texture
