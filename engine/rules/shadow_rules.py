"""What the shadow stage and the probes' scheduler must agree on about shadows, defined once:
the box a directional light's shadow map covers and its light-space camera, a point light's
reach, and where the shadow of a box can fall (a probe face that shows that place must be
captured again when the box moves, even when the box itself is outside the face).

GL-free: numpy and glm only.  The render side (``engine/render/shadows.py``) draws what
these give; the shader side (``shaders/include/shadows.glsl``) reads them from the Shadows
block.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pyglm import glm

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

    @property
    def view_proj(self) -> glm.mat4:
        return self.proj * self.view


def directional_fit(direction: glm.vec3, lo: np.ndarray, hi: np.ndarray, resolution: int) -> DirectionalFit:
    """The orthographic shadow camera of a light travelling along ``direction`` that holds the
    whole world box [lo, hi] (grown by the margin), for a map of ``resolution`` texels a side.

    Fitting the level rather than the main camera's frustum (cascades) means every view of the
    frame (a mirror's looks behind the camera, a probe face anywhere) finds its shadows in the
    one map, and the map does not change when only the camera moves: it is drawn again only
    when a caster or the light changes.  The cost is resolution: a level tens of metres across
    gets centimetre texels from a 2048 map, a kilometre-wide one would not (the README's limits)."""
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
    return DirectionalFit(glm.mat4(view), glm.mat4(proj), float(texel))


def point_reach(position: np.ndarray, light_range: float) -> tuple[np.ndarray, np.ndarray]:
    """The world box a point light's shadows can change: its range's sphere."""
    position = np.asarray(position, np.float64)
    return position - light_range, position + light_range


def boxes_in_reach(lo: np.ndarray, hi: np.ndarray, position: np.ndarray, light_range: float) -> np.ndarray:
    """Which world boxes [lo, hi] (rows) reach into a point light's range (sphere test)."""
    position = np.asarray(position, np.float64)
    nearest = np.clip(position, np.atleast_2d(lo), np.atleast_2d(hi))
    return np.linalg.norm(nearest - position, axis=1) <= light_range


def directional_shadow_bounds(lo: np.ndarray, hi: np.ndarray, direction: glm.vec3 | np.ndarray,
                              level_lo: np.ndarray, level_hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World boxes (rows) holding where the shadows of the boxes [lo, hi] fall under a light
    travelling along ``direction``: each box swept along the light until its last corner
    leaves the level's box (nothing beyond it receives a shadow).  Conservative."""
    lo = np.atleast_2d(np.asarray(lo, np.float64))
    hi = np.atleast_2d(np.asarray(hi, np.float64))
    level_lo = np.asarray(level_lo, np.float64)
    level_hi = np.asarray(level_hi, np.float64)
    d = np.asarray(direction, np.float64)
    d = d / np.linalg.norm(d)
    # How far each box's corners travel before leaving the level's box: per axis the distance
    # to the wall the light runs towards, the nearest of those; the farthest corner's.
    moving = np.abs(d) > 1e-9
    wall = np.where(d > 0.0, level_hi, level_lo)
    with np.errstate(divide="ignore", invalid="ignore"):
        from_lo = np.where(moving, (wall - lo) / np.where(moving, d, 1.0), np.inf)
        from_hi = np.where(moving, (wall - hi) / np.where(moving, d, 1.0), np.inf)
    travel = np.maximum(np.maximum(from_lo, from_hi).min(axis=1), 0.0)   # the corner farthest from the walls
    travel = np.minimum(travel, float(np.linalg.norm(level_hi - level_lo)))
    far_lo, far_hi = lo + d * travel[:, None], hi + d * travel[:, None]
    out_lo = np.maximum(np.minimum(lo, far_lo), np.minimum(level_lo, lo))
    out_hi = np.minimum(np.maximum(hi, far_hi), np.maximum(level_hi, hi))
    return out_lo, out_hi


def point_shadow_bounds(lo: np.ndarray, hi: np.ndarray, position: np.ndarray,
                        light_range: float) -> tuple[np.ndarray, np.ndarray]:
    """World boxes (rows) holding where the shadows of the boxes [lo, hi] fall under a point
    light at ``position``: each box's corners and their projections away from the light to
    its range, grown by a tenth of the range (the sphere's cap between the projected
    corners).  A box holding the light shadows its whole range.  Conservative."""
    lo = np.atleast_2d(np.asarray(lo, np.float64))
    hi = np.atleast_2d(np.asarray(hi, np.float64))
    p = np.asarray(position, np.float64)
    pick = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], bool)
    corners = np.where(pick[None], hi[:, None, :], lo[:, None, :])  # (box, 8, 3)
    away = corners - p
    distance = np.maximum(np.linalg.norm(away, axis=2, keepdims=True), 1e-9)
    projected = p + away / distance * light_range
    points = np.concatenate([corners, projected], axis=1)
    pad = 0.1 * light_range
    out_lo, out_hi = points.min(axis=1) - pad, points.max(axis=1) + pad
    holds = np.all((lo <= p) & (p <= hi), axis=1)
    out_lo[holds], out_hi[holds] = p - light_range, p + light_range
    return out_lo, out_hi


@dataclass
class ShadowCasters:
    """The lights casting shadows this frame (published by the shadows stage,
    ``systems/shadow_system.py``): the level's box the directional maps cover, each
    directional light's direction and each shadowed point light's (position, range)."""

    level: tuple[np.ndarray, np.ndarray] | None = None
    directional: list[tuple[float, float, float]] = field(default_factory=list)
    points: list[tuple[tuple[float, float, float], float]] = field(default_factory=list)

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
        return np.concatenate(out_lo), np.concatenate(out_hi), np.concatenate(out_of)
