"""Where boxes fall on screens, in pixels: the monitors stage's tests of which mirrors and
screens a view may see (``systems/monitor_system.py``), a picture's share of the frame
(``light_rules.PictureEyes``) and the glass's layers (``screen_refraction.box_rects``).
GL-free: numpy only."""
from __future__ import annotations

from typing import Any

import numpy as np


def ndc_extents(corners: np.ndarray,
                view_proj: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The rectangles in normalized device coordinates holding boxes on screens: ``corners``
    (n, 8, 4) world rows through ``view_proj`` ((4, 4) or (n, 4, 4), as ``view_matrix`` gives
    it); (low and high corners, (n, 2); whether a corner lies at or behind the eye, where
    it is not divided by its w and the box's rectangle means nothing; whether every corner
    does).  The one projection under ``projected_rects`` (whole pixels, for the monitors'
    tests) and ``screen_refraction.box_rects`` (subpixel, for the glass's layers)."""
    clip = corners @ view_proj   # every corner of every box at once
    w = clip[:, :, 3]
    ndc = clip[:, :, :2] / np.where(w[:, :, None] > 1e-6, w[:, :, None], 1.0)
    return ndc.min(axis=1), ndc.max(axis=1), (w <= 1e-6).any(axis=1), (w <= 1e-6).all(axis=1)


def projected_rects(corners: np.ndarray, view_proj: np.ndarray,
                    size: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The pixel rectangles of boxes on screens: ``corners`` (n, 8, 4) world rows, each box
    through ``view_proj`` (4, 4: a view's matrix as ``view_matrix`` gives it; or (n, 4, 4),
    a view each) onto a screen of ``size`` pixels ((2,) or (n, 2)); (low and high corners,
    (n, 2) whole pixels clipped to the screen; whether a corner lies behind the eye; whether
    the box is off the screen: beside it, or wholly behind the eye)."""
    low_ndc, high_ndc, behind, wholly_behind = ndc_extents(corners, view_proj)
    low = np.floor((np.clip(low_ndc, -1.0, 1.0) * 0.5 + 0.5) * size)
    high = np.ceil((np.clip(high_ndc, -1.0, 1.0) * 0.5 + 0.5) * size)
    off = (high <= low).any(axis=1) | (high_ndc < -1.0).any(axis=1) | (low_ndc > 1.0).any(axis=1) | wholly_behind
    return low, high, behind, off


def view_matrix(view: Any) -> np.ndarray:
    """A view's (anything with a glm ``view_proj``: ``engine.render.views.View``) view-projection
    as a (4, 4) float64 array a row of world points is multiplied by (glm's buffer is the
    matrix's rows; a row vector takes its columns)."""
    return np.array(view.view_proj.to_list(), np.float64)


def largest_share(corners: np.ndarray, matrices: np.ndarray, rects: np.ndarray, sizes: np.ndarray,
                  screen: tuple[int, int]) -> float:
    """The largest share of a ``screen`` (width, height pixels) a box (``corners``: (8, 4)
    world rows) covers in any of some views (``matrices`` (n, 4, 4), each drawn at ``sizes``
    (n, 2) pixels and shown over ``rects`` (n, 4): x, y, width, height in the screen's
    pixels): its rectangle in each, within the view's rectangle (a box across a view's eye
    plane takes all of it, one behind it none)."""
    if not len(matrices):
        return 0.0
    low, high, behind, off = projected_rects(corners[None], matrices, sizes)
    to_screen = np.asarray(screen, np.float64) / np.maximum(sizes, 1.0)   # (a level drawn smaller)
    corner, far = rects[:, :2], rects[:, :2] + rects[:, 2:]
    across = (behind & ~off)[:, None]
    low = np.where(across, corner, low * to_screen)
    high = np.where(across, far, high * to_screen)
    extent = np.maximum(np.minimum(high, far) - np.maximum(low, corner), 0.0)
    areas = np.where(off, 0.0, extent[:, 0] * extent[:, 1])
    return float(areas.max()) / float(screen[0] * screen[1])
