"""The camera's lens for depth of field (``components/post.py`` ``DepthOfField``), defined once
for the depth-of-field pass (``shaders/dof_prepare.frag`` evaluates the same thin lens per
pixel: ``glsl_defines``) and the tests that check its pixels.

**Thin lens.** A lens of focal length f at f-number N focused at distance s images a point at
distance d as a disc on the sensor (the circle of confusion) of diameter

    c = f^2 |d - s| / (N d (s - f))

(the aperture's diameter f / N, scaled by how far the point's image lies from the sensor).
Over the sensor's height it is a share of the picture's height; in pixels, half of that
share x the picture's height is the disc's radius, signed here (negative nearer than the
focus, positive beyond), since ``(d - s) / d = 1 - s / d`` grows with d: ordering by it orders by
distance, as the gather's test of what lies in front needs.  Beyond everything (d -> inf, the
sky) the disc tends to f^2 / (N (s - f)).

**The distance** is the length of the light's way from the eye to what the pixel shows
(``shaders/include/way.glsl``): through a mirror or portal, the image's distance (eye to the
glass plus the glass to the thing), as a real camera focuses on a reflection; the sky's
way is ``SKY_WAY``.

**The focal length** is the lens's (``DepthOfField.focal_length``, millimetres) or, by
default, the one whose field of view on a full-frame sensor (``SENSOR_HEIGHT``, 24 mm) is
the camera's vertical field of view: a wide camera has a short lens and a deep focus, as
real ones do.  An orthographic camera, which has no field of view, takes ``ORTHOGRAPHIC_FOCAL_LENGTH``.
"""
from __future__ import annotations

import math

import numpy as np

from components.post import MAX_FOCUS_DISTANCE, MIN_FOCUS_DISTANCE

SENSOR_HEIGHT = 0.024            # metres: a full-frame (35 mm) sensor's height
ORTHOGRAPHIC_FOCAL_LENGTH = 0.05  # metres: an orthographic camera's lens, unless given
SKY_WAY = 1.0e30                 # the way's length where the sky shows (beyond everything)
NEAREST_FOCUS = 1.001            # the focus is kept beyond this many focal lengths (s > f)


def focal_length(fov_y_degrees: float | None, given_mm: float | None = None) -> float:
    """The lens's focal length in metres: ``given_mm`` (millimetres), or the one whose
    vertical field of view on the sensor is ``fov_y_degrees`` (None: an orthographic
    camera's, ``ORTHOGRAPHIC_FOCAL_LENGTH``)."""
    if given_mm is not None:
        return given_mm * 1e-3
    if fov_y_degrees is None:
        return ORTHOGRAPHIC_FOCAL_LENGTH
    return 0.5 * SENSOR_HEIGHT / math.tan(math.radians(fov_y_degrees) * 0.5)


def lens_scale(f: float, f_stop: float, height_px: float) -> float:
    """f^2 / (N x the sensor's height) x half the picture's height in pixels: with the focus
    s and the distance d, the disc's radius in pixels is this x (d - s) / (d (s - f))."""
    return f * f / (f_stop * SENSOR_HEIGHT) * 0.5 * height_px


def blur_radius(distance: float | np.ndarray, focus: float, f: float, f_stop: float, height_px: float,
                max_radius: float) -> np.ndarray:
    """The signed radius in pixels of the disc a point at ``distance`` (metres along the
    light's way; a number or an array) is blurred into, by a lens of focal length ``f``
    (metres) at ``f_stop`` focused at ``focus`` metres, on a picture ``height_px`` pixels high:
    negative nearer than the focus, positive beyond, its size at most ``max_radius``."""
    s = max(focus, f * NEAREST_FOCUS)
    d = np.maximum(np.asarray(distance, np.float64), 1e-6)
    radius = lens_scale(f, f_stop, height_px) * (1.0 - s / d) / (s - f)
    return np.clip(radius, -max_radius, max_radius)


def focus_step(previous: float, target: float, blend: float) -> float:
    """Autofocus's move in a frame: the share ``blend`` of the way from ``previous`` to
    ``target`` (metres), in dioptres (1 / distance), as a lens's focus ring turns; ``blend``
    >= 1 is the target itself.  Both are first kept within the focus distances a
    ``DepthOfField`` takes."""
    target = min(max(target, MIN_FOCUS_DISTANCE), MAX_FOCUS_DISTANCE)
    if blend >= 1.0:
        return target
    return 1.0 / ((1.0 - blend) / previous + blend / target)


def max_blur_radius(max_blur: float, height_px: float) -> float:
    """The largest disc's radius in pixels: half of ``DepthOfField.max_blur`` (a diameter, as
    a share of the picture's height) x the height."""
    return 0.5 * max_blur * height_px


def glsl_defines() -> dict[str, str]:
    """The numbers the depth-of-field shaders share with this module."""
    return {"SKY_WAY": f"{SKY_WAY:.1e}", "NEAREST_FOCUS": repr(NEAREST_FOCUS),
            "MIN_FOCUS": repr(MIN_FOCUS_DISTANCE), "MAX_FOCUS": f"{MAX_FOCUS_DISTANCE:.1e}"}
