"""What the shadow stage and the probes' scheduler must agree on about shadows, defined once:
the box a directional light's shadow map covers and its light-space camera, a point light's
reach, and where the shadow of a box can fall (a probe face that shows that place must be
captured again when the box moves, even when the box itself is outside the face).  Light
through mirrors and portals is defined here too: each light reaching the front of a mirror
with ``reflects_light`` or a portal with ``carries_light`` becomes a ``VirtualLight`` (its
image by the surface's carry, and the image of an image for ``bounces`` > 1), ranked for the
budget by ``rank_virtual_lights``; ``light_path`` makes the shader's aperture test on the CPU
(mirror beam decides its target with it).

GL-free: numpy and glm only.  The render side (``engine/render/shadows.py``) draws what
these give; the shader side (``shaders/include/shadows.glsl``) reads them from the Shadows
block.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from pyglm import glm

from components.limits import MAX_LIGHT_BOUNCES
from engine.core.budget import spending_order
from engine.core.portal_math import carries_scale
from engine.resources import Surfaces, SurfaceState
from engine.rules.light_rules import (
    ALL_ROUND,
    NO_COOKIE,
    NO_RECTANGLE,
    SPOT_MAP_MAX_ANGLE,
    carried_cone,
    carried_cookie,
    carried_rectangle,
    cone_half_width,
    cone_reaches,
    opened_cone,
    spot_factor,
)

# A directional light's map covers the level's box grown by this share of its diagonal (and
# at least SHADOW_MARGIN metres), so a caster resting on the box's edge still has texels
# around it for the filter.
SHADOW_MARGIN = 0.25
SHADOW_MARGIN_SHARE = 0.02


@dataclass(frozen=True)
class DirectionalFit:
    """A directional light's shadow camera: ``view`` (world to light space, looking along the
    light), ``proj`` (orthographic over the level's box), and ``texel`` (the world size of
    one texel of its map, what the shader's normal offset scales with)."""

    view: glm.mat4
    proj: glm.mat4
    texel: float
    depth: tuple[float, float] = (0.0, 1.0)  # the projection's near and far (light space, metres)

    @property
    def view_proj(self) -> glm.mat4:
        return self.proj * self.view


LEVEL_GRID = 2.0 ** -10   # metres: the level's box is fitted outward to this grid (level_on_grid)


def level_on_grid(level: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The level's box grown outward to the next multiple of ``LEVEL_GRID`` (about a
    millimetre) on each side: what a sun's level map is fitted to.  A thing moving at the
    level's edge (a screen held before the camera, a bird at a fixed height) changes the box
    by float noise every frame (2e-7 m measured), which fitted the map anew and drew all of
    it again; on the grid the box changes only when the edge crosses a millimetre line.  A
    box already on the grid (a floor from -20 to 20) is itself."""
    lo, hi = level
    return np.floor(lo / LEVEL_GRID) * LEVEL_GRID, np.ceil(hi / LEVEL_GRID) * LEVEL_GRID


# How a sun's level map follows a level that grows or shrinks (``level_fit_box``): a side the
# level outgrew is given this share of the level's diagonal beyond it, and a fitted box whose
# diagonal is more than FIT_LOOSE times the level's is fitted tight again.
FIT_SLACK = 0.25
FIT_LOOSE = 2.0


def _diagonal(box: tuple[np.ndarray, np.ndarray]) -> float:
    return math.dist(box[0].tolist(), box[1].tolist())


def level_fit_box(fitted: tuple[np.ndarray, np.ndarray] | None,
                  level: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The box a sun's level map is fitted to, given the one it was fitted to (``fitted``,
    None: none yet) and the level's box now (``level_on_grid``'s): a fit with slack, as a
    cascade's texel snapping keeps a map still under a moving camera.

    Fitted to the level's box itself, a thing moving out past the level's edge (a ball
    thrown, a bird climbing, a screen that casts nothing carried off) fits the map anew every
    frame: the whole map is drawn again each frame, and every shadow in the level swims as
    its texels slide.  So the fit is kept while the level's box stays inside it and it is
    not more than FIT_LOOSE times the level's size; a side the level outgrew is moved
    FIT_SLACK of the level's diagonal past the new edge (the others stay), so a thing
    flying off refits the map a few times (the box grows by a quarter or more each time),
    not every frame.  The first fit, and a level that never grows, is the level's box:
    a still level's map is what it was.  The cost is resolution: at most about a quarter
    coarser until the level shrinks back (a box twice the level's is fitted tight again)."""
    if fitted is None:
        return level
    lo, hi = level
    fitted_lo, fitted_hi = fitted
    reach = max(_diagonal(level), LEVEL_GRID)
    if all(a >= b for a, b in zip(lo.tolist(), fitted_lo.tolist(), strict=True)) and \
            all(a <= b for a, b in zip(hi.tolist(), fitted_hi.tolist(), strict=True)):
        # (the frame's usual case, a few microseconds in floats: inside the fit)
        return fitted if _diagonal(fitted) <= FIT_LOOSE * reach else level
    grew_lo, grew_hi = lo < fitted_lo, hi > fitted_hi
    slack = FIT_SLACK * reach
    grown = level_on_grid((np.where(grew_lo, lo - slack, fitted_lo), np.where(grew_hi, hi + slack, fitted_hi)))
    if _diagonal(grown) <= FIT_LOOSE * reach:
        return grown
    # It grew on one side and shrank far on another: the level's box, with slack where it grew.
    return level_on_grid((np.where(grew_lo, lo - slack, lo), np.where(grew_hi, hi + slack, hi)))


def directional_fit(direction: glm.vec3, lo: np.ndarray, hi: np.ndarray, resolution: int) -> DirectionalFit:
    """The orthographic shadow camera of a light travelling along ``direction`` that holds the
    whole world box [lo, hi] (grown by the margin), for a map of ``resolution`` texels a side.

    Fitting the level rather than the main camera's frustum (cascades) means every view of the
    frame (a mirror's looks behind the camera, a probe face anywhere) finds its shadows in the
    one map, and the map does not change when only the camera moves: it is drawn again only
    when a caster or the light changes.  The cost is resolution: a level tens of metres across
    gets centimetre texels from a 2048 map, a kilometre-wide one would not; a sun's cascades
    (``ring_fit``: rings about the camera, in this map's light space) give the camera's
    surroundings finer ones."""
    lo = np.asarray(lo, np.float64)
    hi = np.asarray(hi, np.float64)
    margin = max(SHADOW_MARGIN, SHADOW_MARGIN_SHARE * float(np.linalg.norm(hi - lo)))
    lo, hi = lo - margin, hi + margin
    d = glm.normalize(glm.dvec3(*direction))
    centre = glm.dvec3(*((lo + hi) / 2.0))
    radius = float(np.linalg.norm(hi - lo)) / 2.0
    up = glm.dvec3(0.0, 1.0, 0.0) if abs(d.y) < 0.99 else glm.dvec3(1.0, 0.0, 0.0)
    view = glm.lookAt(centre - d * radius, centre, up)
    corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    light = corners @ np.array(view.to_list(), np.float64)  # row vectors: glm's columns are rows here
    x0, y0, z0 = light[:, :3].min(axis=0)
    x1, y1, z1 = light[:, :3].max(axis=0)
    # Light space looks down -z: the nearest corner has the largest z.
    proj = glm.ortho(x0, x1, y0, y1, -z1, -z0)
    texel = max(x1 - x0, y1 - y0) / resolution
    return DirectionalFit(glm.mat4(view), glm.mat4(proj), float(texel), (float(-z1), float(-z0)))


# A ring's (a shadow cascade's) square about the camera: its centre snaps to a grid of about
# this share of its radius in light space, so the map is drawn again only when the camera has
# moved about that far.
RING_STEP_SHARE = 0.25
# Each ring inside the next is this much smaller (DirectionalLight.shadow_distance is the largest).
RING_SHRINK = 4.0


def ring_radii(distance: float, rings: int) -> tuple[float, ...]:
    """The radii of a sun's ``rings`` cascades about the camera, outermost (``distance``) first."""
    return tuple(distance / RING_SHRINK ** k for k in range(rings))


def _ring_square(radius: float, resolution: int) -> tuple[float, float, float]:
    """A ring's (half side, grid step, texel) in metres: the square holds the ring from any
    eye up to a step off its centre on each axis (``ring_cell`` keeps a cell that long), and
    the step is a whole number of texels, so a map drawn for another cell lies on the same
    texel lattice (a shadow's edge does not crawl as the camera moves)."""
    half = radius * (1.0 + RING_STEP_SHARE)
    texel = 2.0 * half / resolution
    step = max(1, round(RING_STEP_SHARE * radius / texel)) * texel
    return half, step, texel


def ring_cell(level: DirectionalFit, eye: tuple[float, float, float], radius: float, resolution: int,
              kept: tuple[int, int] | None = None) -> tuple[int, int]:
    """The grid cell (light space) of the ring of ``radius`` about ``eye``, for the light
    whose level map is fitted by ``level`` and a map of ``resolution`` texels a side:
    ``kept`` (the ring's cell now) while the eye is within a step of its centre on each axis,
    else the nearest one.  The half step of slack on each side is hysteresis: a camera
    swaying across the line between two cells does not draw the ring again every frame."""
    view = level.view
    x, y, z = eye
    step = _ring_square(radius, resolution)[1]
    lx = (view[0][0] * x + view[1][0] * y + view[2][0] * z + view[3][0]) / step
    ly = (view[0][1] * x + view[1][1] * y + view[2][1] * z + view[3][1]) / step
    if kept is not None and abs(lx - kept[0]) <= 1.0 and abs(ly - kept[1]) <= 1.0:
        return kept
    return round(lx), round(ly)


def ring_fit(level: DirectionalFit, cell: tuple[int, int], radius: float, resolution: int) -> DirectionalFit:
    """The orthographic camera of a ring (a shadow cascade) of ``radius`` centred on ``cell``
    (``ring_cell``): the level map's view and depth range (every caster along the light
    still casts into it), a square holding every point within ``radius`` of any eye in the
    cell's keeping (``ring_cell``: a step either way, to a texel), for a map of
    ``resolution`` texels a side."""
    half, step, texel = _ring_square(radius, resolution)
    cx, cy = cell[0] * step, cell[1] * step
    near, far = level.depth
    proj = glm.ortho(cx - half, cx + half, cy - half, cy + half, near, far)
    return DirectionalFit(level.view, glm.mat4(proj), texel, level.depth)


# Texels around a changed caster's footprint redrawn with it: the rasteriser's rounding at
# the footprint's edge (the filter reads the map, it does not write it).
REGION_PAD = 2
# Past this share of a map's texels a region is drawn whole (one clear and draw of the tile).
REGION_WHOLE_SHARE = 0.5


# The last fit map_region was given and the two rows of its view-projection it reads (x and
# y in clip space), as plain floats: a light's fit lasts until its map is fitted again.
_REGION_ROWS: list = [None, None]


def _region_rows(fit: DirectionalFit) -> tuple:
    """The two rows of ``fit``'s view-projection ``map_region`` reads (x and y in clip space)
    as plain floats, kept for the last fit given (a light's fit lasts until it is fitted again)."""
    if _REGION_ROWS[0] is not fit:
        vp = fit.view_proj
        _REGION_ROWS[:] = fit, tuple(tuple(float(vp[column][row]) for column in range(4)) for row in (0, 1))
    return _REGION_ROWS[1]


def _floats(v: np.ndarray | list[float]) -> list[float]:
    """A box corner as Python floats (a numpy array's, or the floats themselves)."""
    return v.tolist() if isinstance(v, np.ndarray) else v


def _footprint(rows: tuple, lo: list[float], hi: list[float], resolution: int) -> tuple[int, int, int, int]:
    """The padded texel rectangle (x0, y0, x1, y1), clamped to the map, that the world box
    [lo, hi] (Python floats) covers under the view-projection ``rows`` (``_region_rows``):
    empty (x1 <= x0 or y1 <= y0) where it misses the map.

    The projection is orthographic (affine), so along each map axis the box's lowest corner
    takes, axis by axis, the lower of ``m * lo`` and ``m * hi``, and the highest the higher:
    the same bounds as the eight corners' (to rounding, which the padding covers), in a
    dozen float operations rather than an array product a frame."""
    lo_x, lo_y, lo_z = lo
    hi_x, hi_y, hi_z = hi
    ends = []
    for m0, m1, m2, m3 in rows:
        a, b = m0 * lo_x, m0 * hi_x
        c, d = m1 * lo_y, m1 * hi_y
        e, f = m2 * lo_z, m2 * hi_z
        low = (a if a < b else b) + (c if c < d else d) + (e if e < f else f) + m3
        high = (b if a < b else a) + (d if c < d else c) + (f if e < f else e) + m3
        ends.append(((low * 0.5 + 0.5) * resolution, (high * 0.5 + 0.5) * resolution))
    (low_x, high_x), (low_y, high_y) = ends
    return (max(math.floor(low_x) - REGION_PAD, 0), max(math.floor(low_y) - REGION_PAD, 0),
            min(math.ceil(high_x) + REGION_PAD, resolution), min(math.ceil(high_y) + REGION_PAD, resolution))


def _as_region(x0: int, y0: int, x1: int, y1: int, resolution: int) -> tuple[int, int, int, int] | None:
    """(x, y, width, height) of the texels [x0, x1) x [y0, y1): (0, 0, 0, 0) when empty, None
    past ``REGION_WHOLE_SHARE`` of the map (draw it whole)."""
    if x1 <= x0 or y1 <= y0:
        return (0, 0, 0, 0)
    if (x1 - x0) * (y1 - y0) > REGION_WHOLE_SHARE * resolution * resolution:
        return None
    return x0, y0, x1 - x0, y1 - y0


def map_region(fit: DirectionalFit, lo: np.ndarray | list[float], hi: np.ndarray | list[float],
               resolution: int) -> tuple[int, int, int, int] | None:
    """The texels (x, y, width, height) of a directional light's map that the world box
    [lo, hi] (arrays or floats) covers, seen along the light, padded; None when they are
    most of the map (draw it whole).  A caster's shadow is in the map only where its
    footprint is: moving it from one box to another changes only the texels under both."""
    return _as_region(*_footprint(_region_rows(fit), _floats(lo), _floats(hi), resolution), resolution)


def changed_region(fit: DirectionalFit, box: tuple | None, parts: list | None,
                   resolution: int) -> tuple[int, int, int, int] | None:
    """``map_region`` of what changed: the rectangle holding the footprints of each of
    ``parts`` (the changed boxes, [lo, hi] lists of floats) that fall in the map, or of
    their union ``box`` where they are not known (``parts`` None); (0, 0, 0, 0) for nothing
    (``box`` None, or every part outside the map); None: most of the map (draw it whole).
    Three crates spinning metres apart change a small region each, not the map under the
    box holding all three."""
    if box is None:
        return (0, 0, 0, 0)
    if parts is None:
        return map_region(fit, box[0], box[1], resolution)
    rows = _region_rows(fit)
    x0 = y0 = resolution
    x1 = y1 = 0
    for lo, hi in parts:
        a0, b0, a1, b1 = _footprint(rows, lo, hi, resolution)
        if a1 > a0 and b1 > b0:
            x0, y0, x1, y1 = min(x0, a0), min(y0, b0), max(x1, a1), max(y1, b1)
    return _as_region(x0, y0, x1, y1, resolution)


def point_reach(position: np.ndarray, light_range: float) -> tuple[np.ndarray, np.ndarray]:
    """The world box a point light's shadows can change: its range's sphere."""
    position = np.asarray(position, np.float64)
    return position - light_range, position + light_range


def boxes_in_reach(lo: np.ndarray, hi: np.ndarray, position: np.ndarray, light_range: float) -> np.ndarray:
    """Which world boxes [lo, hi] (rows) reach into a point light's range (sphere test)."""
    position = np.asarray(position, np.float64)
    nearest = np.clip(position, np.atleast_2d(lo), np.atleast_2d(hi))
    return np.linalg.norm(nearest - position, axis=1) <= light_range


# The rays ``holds_point`` casts: fourteen spread round the sphere (the six towards a cube's
# faces and the eight towards its corners, each turned a little off the axes and diagonals, so
# a ray along a box's face or through a sphere's pole, an edge or vertex crossed twice or not at
# all, is the rare case), so an opening of any size (a lampshade's open bottom) lets one out.
_PARITY_RAYS = np.array([[1.0, 0.1163, 0.0731], [-1.0, 0.0917, -0.1289], [0.1307, 1.0, 0.0617],
                         [-0.0853, -1.0, 0.1171], [0.0691, -0.1237, 1.0], [0.1033, 0.0779, -1.0],
                         [1.0, 1.09, 0.93], [1.07, 0.95, -1.0], [1.0, -0.92, 1.06], [0.94, -1.0, -1.08],
                         [-1.0, 1.05, 0.97], [-0.96, 1.0, -1.07], [-1.04, -0.97, 1.0], [-1.0, -1.06, -0.95]])
_PARITY_RAYS /= np.linalg.norm(_PARITY_RAYS, axis=1, keepdims=True)


# A mesh round a casting point light, at most this share of the light's range across, is
# taken for a bulb made apart from its light (the shadows stage says so): a room round its
# lamp is far larger.
ENCLOSING_SHARE = 0.25


def holds_point(positions: np.ndarray, triangles: np.ndarray, point: Sequence[float] | np.ndarray) -> bool:
    """Whether the surface of ``triangles`` (rows of indices into ``positions``) closes round
    ``point`` (the same space): each of fourteen rays from the point crosses it an odd number
    of times (the even-odd rule; Moller and Trumbore's ray-triangle test, in float64).  An
    open surface (a lampshade, a bowl) lets some ray out with an even count: not held."""
    corners = np.asarray(positions, np.float64)[np.asarray(triangles, np.int64)]   # (T, 3 corners, xyz)
    if not len(corners):
        return False
    origin = np.asarray(point, np.float64)
    a = corners[:, 0]
    e1, e2 = corners[:, 1] - a, corners[:, 2] - a
    s = origin - a
    q = np.cross(s, e1)
    for way in _PARITY_RAYS:
        p = np.cross(way, e2)
        det = np.einsum("ij,ij->i", e1, p)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            u = np.einsum("ij,ij->i", s, p) * inv
            v = (q @ way) * inv
            t = np.einsum("ij,ij->i", e2, q) * inv
            crossed = (np.abs(det) > 1e-14) & (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (t > 0.0)
        if int(np.count_nonzero(crossed)) % 2 == 0:
            return False
    return True


def directional_shadow_bounds(lo: np.ndarray, hi: np.ndarray, direction: glm.vec3 | np.ndarray,
                              level_lo: np.ndarray, level_hi: np.ndarray,
                              sweep: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """World boxes (rows) holding where the shadows of the boxes [lo, hi] fall under a light
    travelling along ``direction``: each box swept along the light until its last corner
    leaves the level's box (nothing beyond it receives a shadow).  Conservative.  ``sweep``:
    ``directional_shadow_sweep``'s rows, where worked out already."""
    lo = np.atleast_2d(np.asarray(lo, np.float64))
    hi = np.atleast_2d(np.asarray(hi, np.float64))
    level_lo = np.asarray(level_lo, np.float64)
    level_hi = np.asarray(level_hi, np.float64)
    if sweep is None:
        sweep = directional_shadow_sweep(lo, hi, direction, level_lo, level_hi)
    far_lo, far_hi = lo + sweep, hi + sweep
    out_lo = np.maximum(np.minimum(lo, far_lo), np.minimum(level_lo, lo))
    out_hi = np.minimum(np.maximum(hi, far_hi), np.maximum(level_hi, hi))
    return out_lo, out_hi


def directional_shadow_sweep(lo: np.ndarray, hi: np.ndarray, direction: glm.vec3 | np.ndarray,
                             level_lo: np.ndarray, level_hi: np.ndarray) -> np.ndarray:
    """(box, xyz): how far each box [lo, hi] (rows) is swept along a light travelling along
    ``direction`` until its last corner leaves the level's box: where its shadow may fall is
    within the convex hull of the box and the box moved by that much (what
    ``directional_shadow_bounds`` bounds with a box; ``probe_rules.face_hits_swept`` tests
    the hull itself).  What depends on the light and the level alone (``_sweep_constants``)
    is kept until either changes: the probes scheduler sweeps every changed box a frame."""
    lo = np.atleast_2d(np.asarray(lo, np.float64))
    hi = np.atleast_2d(np.asarray(hi, np.float64))
    d, moving, wall, step, diagonal = _sweep_constants(direction, level_lo, level_hi)
    # How far each box's corners travel before leaving the level's box: per axis the distance
    # to the wall the light runs towards, the nearest of those; the farthest corner's.
    from_lo = (wall - lo) / step
    from_hi = (wall - hi) / step
    if moving is not None:  # an axis the light runs along is never reached
        from_lo = np.where(moving, from_lo, np.inf)
        from_hi = np.where(moving, from_hi, np.inf)
    travel = np.maximum(np.maximum(from_lo, from_hi).min(axis=1), 0.0)   # the corner farthest from the walls
    travel = np.minimum(travel, diagonal)
    return d * travel[:, None]


def directional_shadow_hull(lo: np.ndarray, hi: np.ndarray, direction: glm.vec3 | np.ndarray,
                            level_lo: np.ndarray, level_hi: np.ndarray) -> tuple[np.ndarray, ...]:
    """(far_lo, far_hi, bound_lo, bound_hi): each box [lo, hi] (rows, float64) moved by its
    ``directional_shadow_sweep`` (the hull of the box and the moved box holds where its
    shadow may fall) and ``directional_shadow_bounds``' boxes, the same values, made
    together: the probes scheduler asks for both every frame for every changed box."""
    sweep = directional_shadow_sweep(lo, hi, direction, level_lo, level_hi)
    far_lo, far_hi = lo + sweep, hi + sweep
    level_lo, level_hi = np.asarray(level_lo, np.float64), np.asarray(level_hi, np.float64)
    return (far_lo, far_hi, np.maximum(np.minimum(lo, far_lo), np.minimum(level_lo, lo)),
            np.minimum(np.maximum(hi, far_hi), np.maximum(level_hi, hi)))


_SWEEP_KEPT: dict[tuple, tuple] = {}  # (direction, level box) -> _sweep_constants'


def _sweep_constants(direction: glm.vec3 | np.ndarray, level_lo: np.ndarray,
                     level_hi: np.ndarray) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray, float]:
    """A sweep's parts that depend on the light's direction and the level's box alone, kept
    by their values (a turned sun or a new level box is a new key): the unit direction, the
    axes it moves along (None: all three), the walls it runs towards, the divisor a wall's
    distance is taken with (1 on an axis it does not move along: no division by zero) and
    the level's diagonal (the longest sweep)."""
    level_lo = np.asarray(level_lo, np.float64)
    level_hi = np.asarray(level_hi, np.float64)
    key = (tuple(direction), level_lo.tobytes(), level_hi.tobytes())
    kept = _SWEEP_KEPT.get(key)
    if kept is None:
        d = np.asarray(direction, np.float64)
        d = d / np.linalg.norm(d)
        moving = np.abs(d) > 1e-9
        wall = np.where(d > 0.0, level_hi, level_lo)
        step = np.where(moving, d, 1.0)
        if len(_SWEEP_KEPT) > 64:
            _SWEEP_KEPT.clear()
        kept = _SWEEP_KEPT[key] = (d, None if moving.all() else moving, wall, step,
                                   float(np.linalg.norm(level_hi - level_lo)))
    return kept


_CORNER_PICK = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], bool)  # (8, 3): hi where set


def point_shadow_bounds(lo: np.ndarray, hi: np.ndarray, position: np.ndarray,
                        light_range: float) -> tuple[np.ndarray, np.ndarray]:
    """World boxes (rows) holding where the shadows of the boxes [lo, hi] fall under a point
    light at ``position``: each box's corners and their projections away from the light to
    its range, grown by a tenth of the range (the sphere's cap between the projected
    corners).  A box holding the light shadows its whole range.  Conservative."""
    lo = np.atleast_2d(np.asarray(lo, np.float64))
    hi = np.atleast_2d(np.asarray(hi, np.float64))
    p = np.asarray(position, np.float64)
    corners = np.where(_CORNER_PICK[None], hi[:, None, :], lo[:, None, :])  # (box, 8, 3)
    away = corners - p
    # np.linalg.norm's own sum (its 2-norm along an axis), without its checks and dispatch.
    distance = np.maximum(np.sqrt(np.add.reduce(away * away, axis=2, keepdims=True)), 1e-9)
    projected = p + away / distance * light_range
    points = np.concatenate([corners, projected], axis=1)
    pad = 0.1 * light_range
    out_lo, out_hi = points.min(axis=1) - pad, points.max(axis=1) + pad
    holds = np.all((lo <= p) & (p <= hi), axis=1)
    out_lo[holds], out_hi[holds] = p - light_range, p + light_range
    return out_lo, out_hi


@dataclass(frozen=True)
class CascadeRing:
    """One of the active camera's rings this frame (``ShadowCasters.cascades``): its index
    in the Shadows block, its light's slot, radius, map side and softness."""

    ring: int
    slot: int
    radius: float
    resolution: int
    softness: float


@dataclass(frozen=True)
class Cascades:
    """What a monitor's picture needs to draw the suns' cascades about its own camera (the
    monitors stage: ``systems/shadow_rings.py``), published by the shadows stage: the active
    camera's rings (a picture's are the same rings about another eye, so the scene programs'
    builds stay), each casting light's level map's fit and what that map was drawn from, by
    slot, the atlas squares no level map or ring of the camera's takes (texel corners,
    ``side`` texels a side: the free tiles' quarters), and whether casters changed this
    frame (and the renderer's changed box and parts: ``changed_region``'s), with ``stamp``
    the count of frames they changed in (a picture not drawn every frame redraws its rings
    whole when it missed one)."""

    rings: tuple[CascadeRing, ...]
    levels: dict[int, DirectionalFit]
    keys: dict[int, tuple]
    places: tuple[tuple[int, int], ...]
    side: int
    atlas: int = 0   # which atlas (ShadowMaps.atlases_made): a new one holds no picture's rings
    casters_changed: bool = False
    changes: tuple = (None, None)
    stamp: int = 0


@dataclass
class ShadowCasters:
    """The lights casting shadows this frame (published by the shadows stage,
    ``systems/shadow_system.py``): the level's box the directional maps cover, each
    directional light's direction and each shadowed point light's (position, range)."""

    level: tuple[np.ndarray, np.ndarray] | None = None
    directional: list[tuple[float, float, float]] = field(default_factory=list)
    points: list[tuple[tuple[float, float, float], float]] = field(default_factory=list)
    # Lights through mirrors and portals: each image's light shadows what lies beyond the
    # surface, and what stands on the way in shadows there as its carried image.
    virtual: list[VirtualLight] = field(default_factory=list)
    # The suns' cascades, for the monitors' pictures to draw their own (None: no sun has rings).
    cascades: Cascades | None = None

    def shadow_bounds(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World boxes (rows) holding where the shadows of the boxes [lo, hi] may fall under
        these lights, and for each the row of [lo, hi] it is the shadow of (none: no light
        casts, or no box reaches a light)."""
        out_lo, out_hi, out_of = [np.zeros((0, 3))], [np.zeros((0, 3))], [np.zeros(0, np.int64)]
        lo = np.atleast_2d(np.asarray(lo, np.float64))
        hi = np.atleast_2d(np.asarray(hi, np.float64))
        rows = np.arange(len(lo))
        if len(lo) and self.level is not None:
            for direction in self.directional:
                a, b = directional_shadow_bounds(lo, hi, direction, *self.level)
                out_lo.append(a)
                out_hi.append(b)
                out_of.append(rows)
        for position, light_range in self.points:
            reach = boxes_in_reach(lo, hi, np.array(position), light_range) if len(lo) else np.zeros(0, bool)
            if reach.any():
                a, b = point_shadow_bounds(lo[reach], hi[reach], np.array(position), light_range)
                out_lo.append(a)
                out_hi.append(b)
                out_of.append(rows[reach])
        for light in self.virtual:
            if not len(lo) or self.level is None:
                break
            legs = light.legs or (Leg(glm.mat4(1.0), (), (0, 0)), Leg(light.carry, (), (0, 0)))
            carried = [_carried_boxes(lo, hi, leg.carry) for leg in legs[1:]]
            for box_lo, box_hi in ((lo, hi), *carried):
                if light.kind == "directional":
                    level_lo = np.minimum.reduce([self.level[0], *(c[0].min(axis=0) for c in carried)])
                    level_hi = np.maximum.reduce([self.level[1], *(c[1].max(axis=0) for c in carried)])
                    a, b = directional_shadow_bounds(box_lo, box_hi, light.position, level_lo, level_hi)
                    keep = rows
                else:
                    keep = rows[boxes_in_reach(box_lo, box_hi, np.array(light.position), light.light_range)]
                    if not len(keep):
                        continue
                    a, b = point_shadow_bounds(box_lo[keep], box_hi[keep], np.array(light.position),
                                               light.light_range)
                out_lo.append(a)
                out_hi.append(b)
                out_of.append(keep)
        return np.concatenate(out_lo), np.concatenate(out_hi), np.concatenate(out_of)


def _carried_boxes(lo: np.ndarray, hi: np.ndarray, carry: glm.mat4) -> tuple[np.ndarray, np.ndarray]:
    """The world boxes holding the boxes [lo, hi] (rows) carried by ``carry``."""
    pick = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], bool)
    corners = np.where(pick[None], hi[:, None, :], lo[:, None, :])
    m = np.array(carry.to_list(), np.float64)   # glm's columns as rows: row vectors times it
    moved = corners @ m[:3, :3] + m[3, :3]
    return moved.min(axis=1), moved.max(axis=1)


# --- light through mirrors and portals -------------------------------------------------------
MAX_VIRTUAL_LIGHTS = 4   # virtual lights a frame (shaders/include/virtual_lights.glsl)
VIRTUAL_NEAR = 0.05      # metres: a virtual point light's shadow camera sees casters from here on
VIRTUAL_MAX_FOV = 170.0  # degrees: the widest a virtual point light's shadow camera opens
MAX_APERTURES = MAX_LIGHT_BOUNCES   # outlines a virtual light's line must cross (one a bounce)


@dataclass(frozen=True)
class Aperture:
    """One outline a virtual light's line passes through, in the image's space (where the
    line from a lit point to the image is straight): ``plane`` (its front positive: the line
    enters it from the front), ``origin`` (a corner) and its edges ``u``, ``v``; ``to_image``
    takes the real outline (world) to where it is here, so a crossing found here is
    ``inverse(to_image)`` of the real one.  ``water`` is the surface's water as the light's
    weight reads it (``water_code``): a water reflects the share of the light Fresnel's
    equations give at the angle the line meets it, a mirror or a portal all of it."""

    plane: tuple[float, float, float, float]
    origin: tuple[float, float, float]
    u: tuple[float, float, float]
    v: tuple[float, float, float]
    to_image: glm.mat4
    water: float = 0.0


def water_code(surface: SurfaceState) -> float:
    """A surface's water as a virtual light's outline carries it to the shaders
    (``shaders/include/virtual_light_ways.glsl`` virtual_fresnel): 0 for a mirror that is no
    water and for a portal; 1 + F0 for a water's top; -(1 + F0) for its underside, whose
    light meets it from the water (total internal reflection past the critical angle)."""
    water = surface.water if surface.kind == "mirror" else None
    if water is None:
        return 0.0
    return -(1.0 + water.f0) if water.underside else 1.0 + water.f0


@dataclass(frozen=True)
class Leg:
    """One straight stretch of a virtual light's way (the light to the first surface, one
    surface to the next, the last surface to what it lights), as its shadow map draws it:
    the casters of that stretch, where they are (world), carried by ``carry`` to where the
    image sees them, kept only in front of every plane of ``planes`` (world; one or two:
    the surfaces it runs between) and without ``skip`` (the surfaces themselves)."""

    carry: glm.mat4
    planes: tuple[glm.vec4, ...]
    skip: tuple[int, int]


@dataclass(frozen=True)
class VirtualLight:
    """A light's image through one or more mirrors or portals in a row
    (``Mirror.reflects_light``, ``Portal.carries_light``; ``bounces`` of them, at most the
    light's own ``bounces``): the light as the room beyond the last surface receives it.

    For a mirror the image is the light reflected in the mirror's plane; for a portal, carried
    by the pair's transform (the light in front of the portal goes in and comes out of its
    partner); for several, the image of the image.  It lights a point only when the straight
    line from the point to the image passes through every surface's outline on the way, in
    order, each entered from its front (``apertures``: the last surface's outline first, as
    it is, then each earlier one as the later surfaces carry it); its colour is the light's
    times each surface's tint and reflect rate.  Out of a portal pair of two scales (k times
    the size on the way out) a lamp's image is the lamp k times as large, as the view through
    shows it: its range and radius times k and, a point or sphere, its colour times k squared
    (a rectangle's carried rows keep its radiance over k squared the area).  ``legs`` are the stretches of its way its
    shadow map holds: the last (way out) as the scene is, each earlier carried to where the
    image sees it.  ``exit_plane``, ``aperture``, ``carry`` and ``entry_plane`` are the last
    surface's: the one-bounce light's whole description."""

    light: int                       # the light's entity
    surface: int                     # the last mirror or entry portal on the way
    kind: str                        # "directional" or "point"
    position: tuple[float, float, float]   # the image's position (point), or the direction it travels
    color: tuple[float, float, float]
    light_range: float               # a point light's range (the whole path, times a scaled pair's k); 0: directional
    exit_plane: tuple[float, float, float, float]   # lit points lie in front of it
    aperture: tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]  # origin, u, v of the exit outline
    carry: glm.mat4                  # the last surface's carry (the real scene before it -> as the image sees it)
    entry_plane: glm.vec4
    exit_entity: int
    priority: int                    # the surfaces' priorities on the way, summed
    bounces: int = 1
    path: tuple[int, ...] = ()       # the surfaces (mirrors, entry portals) in the order the light meets them
    apertures: tuple[Aperture, ...] = ()
    legs: tuple[Leg, ...] = ()
    cone: tuple[float, float, float, float] = ALL_ROUND   # a point image's spot cone, carried (light_rules.spot_cone)
    cookie: tuple[tuple[float, ...], ...] = NO_COOKIE   # its cookie rows, carried (light_rules.lamp_cookie)
    radius: float = 0.0              # a point light's sphere (PointLight.radius), scaled as the carry scales
    rectangle: tuple[tuple[float, ...], ...] = NO_RECTANGLE   # its rectangle rows, carried (lamp_rectangle)


def _outline(surface) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """A flat surface's outline as an origin corner and its two edges (a parallelogram)."""
    if surface.outline is None:
        return None
    c = np.asarray(surface.outline, np.float64)[:, :3]
    return c[0], c[2] - c[0], c[1] - c[0]


def _carry_scale(carry: glm.mat4) -> float:
    """How much ``carry`` scales lengths (a mirror 1; a portal pair of unequal sizes the
    cube root of its linear part's determinant)."""
    return abs(float(glm.determinant(glm.mat3(carry)))) ** (1.0 / 3.0)


def _carry_plane(plane: glm.vec4, carry: glm.mat4) -> glm.vec4:
    """A plane (its front positive) where ``carry`` takes it."""
    return glm.transpose(glm.inverse(glm.dmat4(carry))) * glm.dvec4(plane)


def _carry_aperture(aperture: Aperture, carry: glm.mat4) -> Aperture:
    m = glm.dmat4(carry)
    origin = m * glm.dvec4(*aperture.origin, 1.0)
    u, v = m * glm.dvec4(*aperture.u, 0.0), m * glm.dvec4(*aperture.v, 0.0)
    plane = glm.dvec4(_carry_plane(glm.dvec4(*aperture.plane), carry))
    plane /= glm.length(glm.dvec3(plane))
    return Aperture(tuple(float(x) for x in plane), tuple(float(x) for x in origin.xyz),
                    tuple(float(x) for x in u.xyz), tuple(float(x) for x in v.xyz),
                    glm.mat4(m * glm.dmat4(aperture.to_image)), aperture.water)


def _reaches_through(image: glm.vec3, kind: str, aperture: Aperture, corners: np.ndarray) -> bool:
    """Whether light from ``image`` (a point, or a direction travelled) through the
    parallelogram ``aperture`` (world) can meet any of ``corners`` (a flat outline, rows): a
    corner in front of the aperture's plane and not every corner outside one side of the
    pyramid (a prism for a direction) the aperture cuts.  Conservative: it only rules out."""
    plane = np.asarray(aperture.plane, np.float64)
    if not (corners @ plane[:3] + plane[3] > 1e-6).any():
        return False
    o, u, v = (np.asarray(x, np.float64) for x in (aperture.origin, aperture.u, aperture.v))
    ring = [o, o + u, o + u + v, o + v]
    inside = o + 0.5 * (u + v)
    p = np.asarray(image, np.float64)
    for a, b in zip(ring, ring[1:] + ring[:1], strict=True):
        along = p if kind == "directional" else p - a
        normal = np.cross(b - a, along)
        if np.linalg.norm(normal) < 1e-12:
            continue
        side = np.sign(np.dot(inside - a, normal))
        if np.all((corners - a) @ normal * side < -1e-6):
            return False
    return True


def _reach(point: np.ndarray, corners: np.ndarray) -> float:
    """The distance from ``point`` to the nearest point of a parallelogram (corners o, o + u,
    o + u + v, o + v as rows)."""
    o, u, v = corners[0], corners[1] - corners[0], corners[3] - corners[0]
    a = float(np.clip((point - o) @ u / max(float(u @ u), 1e-12), 0.0, 1.0))
    b = float(np.clip((point - o) @ v / max(float(v @ v), 1e-12), 0.0, 1.0))
    return float(np.linalg.norm(o + a * u + b * v - point))


def virtual_lights(directional: list[tuple[int, glm.vec3, glm.vec3]],
                   points: list[tuple[int, glm.vec3, float, glm.vec3, tuple]],
                   surfaces: Surfaces | None, bounces: dict[int, int] | None = None,
                   depth_cap: int = MAX_LIGHT_BOUNCES) -> list[VirtualLight]:
    """The virtual lights of this frame's lights through the surfaces that carry light:
    ``directional`` as (entity, direction travelled, colour x intensity), ``points`` as
    (entity, position, range, colour x intensity, spot cone: ``light_rules.spot_cone``, or
    ``ALL_ROUND``[, cookie rows: ``light_rules.lamp_cookie``[, sphere radius[, rectangle rows:
    ``light_rules.lamp_rectangle``]]]), ``surfaces`` the
    ``Surfaces`` resource,
    ``bounces`` each light's limit (its ``bounces`` field; 1 when not given), ``depth_cap``
    the view tree's.

    A light makes an image through a surface when it reaches the surface's front (a point
    light in front of it, within range and, a spot, its cone reaching the surface's outline:
    ``light_rules.cone_reaches``; a directional one travelling towards it); an image
    makes an image of its own through a further surface (light reflected more than once,
    mirror to mirror) while the chain is within the light's ``bounces``, the surface's
    ``max_depth`` (its n-th bounce is at depth n, as its n-th view in the view tree) and
    ``depth_cap``, the image reaches that surface's front, and the last surface's outline,
    seen from the image, can reach it.  Every image on the way is a virtual light of its own
    (it lights what its last surface faces)."""
    found: list[VirtualLight] = []
    if surfaces is None:
        return found
    bounces = bounces or {}
    # (a water's underside beside its top: a lamp under the water is reflected down by it)
    shown = [s for s in (*surfaces.mirrors.values(), *surfaces.undersides.values(), *surfaces.portals.values())
             if s.carries_light and s.enabled]
    steps = []   # (surface, its exit outline as an aperture, corners of its entry outline, tint)
    for surface in shown:
        exit_surface = surface if surface.kind == "mirror" else surfaces.portals.get(surface.exit_entity)
        if exit_surface is None:
            continue
        outline = _outline(exit_surface)
        entry = _outline(surface)
        if outline is None or entry is None:
            continue
        exit_plane = glm.dvec4(surface.exit_plane)
        exit_plane /= glm.length(glm.dvec3(exit_plane))
        aperture = Aperture(tuple(float(v) for v in exit_plane), *(tuple(float(v) for v in part) for part in outline),
                            glm.mat4(1.0), water_code(surface))
        o, u, v = entry
        corners = np.array([o, o + u, o + u + v, o + v])
        tint = glm.vec3(surface.tint) * surface.reflect_rate if surface.kind == "mirror" else glm.vec3(1.0)
        centre = corners.mean(axis=0)
        ball = (centre, float(np.linalg.norm(corners - centre, axis=1).max()))   # what a spot's cone must reach
        steps.append((surface, exit_surface, aperture, corners, tint, ball))

    def extend(light: VirtualLight | None, entity: int, kind: str, image: glm.vec3, light_range: float,
               rgb: glm.vec3, limit: int, cone: tuple = ALL_ROUND, cookie: tuple = NO_COOKIE,
               radius: float = 0.0, rectangle: tuple = NO_RECTANGLE) -> None:
        depth = 1 if light is None else light.bounces + 1
        if depth > limit:
            return
        for surface, exit_surface, aperture, corners, tint, ball in steps:
            if depth > min(surface.max_depth, depth_cap):
                continue
            if light is not None and not _reaches_through(image, kind, light.apertures[0], corners):
                continue
            entry = glm.vec4(surface.plane)
            carry = glm.mat4(surface.carry)
            if kind == "directional":
                d = glm.normalize(glm.vec3(image))
                if glm.dot(glm.vec3(entry), d) >= 0.0:
                    continue  # travelling away from its front: it never lights the surface
                new_image = glm.normalize(glm.mat3(carry) * d)
            else:
                height = (glm.dot(glm.vec3(entry), glm.vec3(image)) + entry.w) / glm.length(glm.vec3(entry))
                if height <= 0.0 or _reach(np.asarray(glm.vec3(image), np.float64), corners) >= light_range:
                    continue  # behind the surface, or its range ends before its outline
                if not cone_reaches(cone, glm.vec3(image), *ball):
                    continue  # a spot aimed away from the surface
                new_image = glm.vec3(carry * glm.vec4(glm.vec3(image), 1.0))
            color = glm.vec3(rgb) * tint
            image_range = light_range
            if kind != "directional" and carries_scale(carry):
                # Out of a pair of two scales the image is the lamp that much larger: its reach
                # scaled, and (as its rectangle keeps its radiance) a point's or a sphere's power
                # by the area, so what it lights beyond looks as lit as the view shows it.
                grow = _carry_scale(carry)
                image_range = light_range * grow
                if rectangle[0][3] == 0.0:
                    color = color * (grow * grow)
            way_out = Leg(glm.mat4(1.0), (glm.vec4(surface.exit_plane),), (exit_surface.entity, surface.entity))
            if light is None:
                legs = (way_out, Leg(carry, (entry,), (surface.entity, exit_surface.entity)))
                apertures = (aperture,)
                path = (surface.entity,)
            else:
                # The earlier way out runs from the last exit to this entry: carried, between both.
                last = light.legs[0]
                middle = Leg(carry, (*last.planes, entry), (last.skip[0], surface.entity))
                legs = (way_out, middle, *(Leg(carry * leg.carry, leg.planes, leg.skip) for leg in light.legs[1:]))
                apertures = (aperture, *(_carry_aperture(a, carry) for a in light.apertures))
                path = (*light.path, surface.entity)
            made = VirtualLight(entity, surface.entity, kind, tuple(float(v) for v in new_image),
                                tuple(float(v) for v in color), float(image_range),
                                aperture.plane, (aperture.origin, aperture.u, aperture.v), carry, entry,
                                exit_surface.entity, surface.priority + (0 if light is None else light.priority),
                                depth, path, apertures, legs,
                                ALL_ROUND if kind == "directional" else carried_cone(cone, carry),
                                NO_COOKIE if kind == "directional" else carried_cookie(cookie, carry),
                                0.0 if kind == "directional" else radius * _carry_scale(carry),
                                NO_RECTANGLE if kind == "directional" else carried_rectangle(rectangle, carry))
            found.append(made)
            extend(made, entity, kind, new_image, image_range, color, limit, made.cone, made.cookie, made.radius,
                   made.rectangle)

    for entity, direction, rgb in directional:
        extend(None, entity, "directional", glm.normalize(glm.vec3(direction)), 0.0, glm.vec3(rgb),
               bounces.get(entity, 1))
    for entity, position, light_range, rgb, cone, *more in points:
        extend(None, entity, "point", glm.vec3(position), float(light_range), glm.vec3(rgb), bounces.get(entity, 1),
               cone, more[0] if more else NO_COOKIE, float(more[1]) if len(more) > 1 else 0.0,
               more[2] if len(more) > 2 else NO_RECTANGLE)
    return found


def reflected_caustic_water(light: VirtualLight) -> int | None:
    """The water whose waves gather what ``light`` reflects (``shaders/include/caustics.glsl``
    caustic_reflected_light, caustic_reflected_lamp_light): the sun's or a lamp's image (a
    point, a sphere, a rectangle or a tube: its net blurred as far as its shape spreads its
    light, ``caustic_lamp_radius``) in one water's top, its entity; None for any other (light
    off two surfaces, a water's underside, a mirror)."""
    if len(light.apertures) != 1 or light.apertures[0].water <= 0.0:
        return None
    return light.surface


def light_path(light: VirtualLight, point: np.ndarray) -> list[np.ndarray] | None:
    """The way the light of ``light`` takes to ``point`` (world), as the shader's aperture
    test decides it (``shaders/include/virtual_lights.glsl``; no shadows): None when it does
    not light the point, else the real corners from the point back towards the light: the
    point, where the way crosses each surface (last first: for a portal, where it comes out,
    then where it went in), and the light (a point light's position; for a directional one,
    a point a kilometre back along it).  Float64: a game's or a test's second opinion."""
    x = np.asarray(point, np.float64)
    p = np.asarray(light.position, np.float64)
    if light.kind == "point":
        to = p - x
        dist = float(np.linalg.norm(to))
        if dist <= 1e-9 or dist >= light.light_range:
            return None
        l = to / dist
        if spot_factor(light.cone, l) <= 0.0:
            return None   # outside the spot's cone, as the image sees it
    else:
        l = -p / np.linalg.norm(p)
        dist = np.inf
    corners = [x]
    t_last = 0.0
    for aperture in light.apertures:
        plane = np.asarray(aperture.plane, np.float64)
        towards = float(plane[:3] @ l)
        height = float(plane[:3] @ x + plane[3])
        if towards >= 0.0 or height <= 0.0:
            return None
        t = height / -towards
        if t <= t_last or t > dist:
            return None
        crossing = x + l * t
        offset = crossing - np.asarray(aperture.origin)
        u, v = np.asarray(aperture.u), np.asarray(aperture.v)
        a, b = offset @ u / (u @ u), offset @ v / (v @ v)
        if not (0.0 <= a <= 1.0 and 0.0 <= b <= 1.0):
            return None
        t_last = t
        back = np.linalg.inv(np.array(aperture.to_image.to_list(), np.float64).T)
        corners.append(back[:3, :3] @ crossing + back[:3, 3])
    # Each surface's far side: a mirror's light leaves where it arrived; a portal's entry is
    # the exit's crossing carried back by its pair.
    out = [corners[0]]
    for index, crossing in enumerate(corners[1:]):
        out.append(crossing)
        # The leg before this surface is carried by legs[index + 1], the one after by legs[index].
        before = np.array(light.legs[index + 1].carry.to_list(), np.float64).T
        after = np.array(light.legs[index].carry.to_list(), np.float64).T
        there = np.linalg.inv(before) @ after
        entered = there[:3, :3] @ crossing + there[:3, 3]
        if np.linalg.norm(entered - crossing) > 1e-6:
            out.append(entered)
    if light.kind == "point":
        out.append(np.asarray(light_origin(light), np.float64))
    else:
        first = out[-1]
        direction = np.asarray(light.legs[-1].carry.to_list(), np.float64).T
        travel = np.linalg.inv(direction)[:3, :3] @ (np.asarray(light.position) / np.linalg.norm(light.position))
        out.append(first - 1000.0 * travel / np.linalg.norm(travel))
    return out


def light_origin(light: VirtualLight) -> tuple[float, float, float]:
    """A virtual point light's real light: its image carried back along every leg."""
    back = np.linalg.inv(np.array(light.legs[-1].carry.to_list(), np.float64).T)
    return tuple(float(v) for v in back[:3, :3] @ np.asarray(light.position) + back[:3, 3])


def rank_virtual_lights(lights: list[VirtualLight]) -> list[VirtualLight]:
    """The order the budget spends on them (``spending_order``): the priority of the
    surfaces on the way (their ``priority`` summed: a way through two preferred mirrors before
    a way through one), then the brightest (an image of an image is never brighter than the
    image: tints and rates are at most 1), then fewer bounces, then by surface and light."""
    order = spending_order([v.priority for v in lights], [max(v.color) for v in lights],
                           [v.bounces for v in lights], [v.surface for v in lights], [v.light for v in lights])
    return [lights[i] for i in order.tolist()]


def virtual_shadow_camera(light: VirtualLight, level_lo: np.ndarray, level_hi: np.ndarray,
                          resolution: int) -> DirectionalFit:
    """The shadow camera of a virtual light: for a directional image, the level's box seen
    along it (as a real sun's); for a point image, a perspective camera at the image looking
    at the exit outline's centre, wide enough for the whole outline (the light reaches
    nothing else), or, for a spot's image whose carried cone is narrower than that, along
    the cone's axis fitted to the cone (as the spot's own map: ``light_rules.cone_half_width``),
    so a narrow flashlight on a wide mirror keeps its texels where its light goes."""
    if light.kind == "directional":
        return directional_fit(glm.vec3(light.position), level_lo, level_hi, resolution)
    eye = glm.dvec3(*light.position)
    origin, u, v = (np.asarray(part, np.float64) for part in light.aperture)
    corners = [origin, origin + u, origin + v, origin + u + v]
    centre = glm.dvec3(*(origin + 0.5 * (u + v)))
    forward = glm.normalize(centre - eye)
    up = glm.dvec3(0.0, 1.0, 0.0) if abs(forward.y) < 0.99 else glm.dvec3(1.0, 0.0, 0.0)
    view = glm.lookAt(eye, centre, up)
    # The widest angle from the axis to a corner, each way, and a texel's margin.
    half = 0.0
    for corner in corners:
        local = view * glm.dvec4(*corner, 1.0)
        depth = max(-local.z, 1e-6)
        half = max(half, abs(local.x) / depth, abs(local.y) / depth)
    fov = 2.0 * np.degrees(np.arctan(half * (1.0 + 4.0 / resolution))) + 0.5
    opened = opened_cone(light.cone)
    if opened is not None and opened[1] <= SPOT_MAP_MAX_ANGLE:
        narrow = cone_half_width(opened[1], resolution)
        if 2.0 * np.degrees(np.arctan(narrow)) < fov:
            axis = glm.dvec3(*opened[0])
            up = glm.dvec3(0.0, 1.0, 0.0) if abs(axis.y) < 0.99 else glm.dvec3(1.0, 0.0, 0.0)
            view = glm.lookAt(eye, eye + axis, up)
            half = narrow
            fov = 2.0 * np.degrees(np.arctan(narrow))
    if fov > VIRTUAL_MAX_FOV:
        # A lamp near a wide outline: the map stops short of the outline's edge (what lies
        # past it is unshadowed), and a texel is the clamped map's, not the outline's
        # (the normal offset scales with it: sized by the outline, it was metres wide).
        fov = VIRTUAL_MAX_FOV
        half = math.tan(math.radians(fov) / 2.0)
    fov = float(fov)
    proj = glm.perspective(glm.radians(fov), 1.0, VIRTUAL_NEAR, max(light.light_range * 1.5, VIRTUAL_NEAR * 4))
    texel = 2.0 * half / resolution   # a texel's angle (radians, small): the lookup scales it by distance
    return DirectionalFit(glm.mat4(view), glm.mat4(proj), float(texel))
