"""The beam's path: a ray that bounces off mirrors and stops at the first solid it meets.

Bounces use the renderer's own description of each mirror, the ``SurfaceState`` rows of the
``Surfaces`` resource (``systems/surface_system.py``): the world plane, the outline the
composite covers, and ``carry``, the reflection matrix (``engine.core.reflection_math``) that
builds the mirror's virtual camera.  A ray hits a mirror where it crosses that plane inside
the outline, coming from the front (the side the plane's normal points to); the bounce is
the incoming ray carried by the same matrix, so the beam turns exactly as the picture in
the mirror does.  A ray that reaches a mirror's back is stopped there, like any solid.

Solids (walls, the target, mirror frames) are found by a callable, in the game the engine's
ray cast against world triangles (``engine.rules.raycast``, Möller–Trumbore), so the beam stops
where the visible geometry is.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from pyglm import glm

from engine.resources import SurfaceState

# How far a beam that meets nothing is drawn, and the smallest ray parameter that counts as
# a hit (so a ray leaving a mirror does not hit that mirror again at its own start).
OPEN_LENGTH = 40.0
EPSILON = 1e-5
# |cos| between the beam and a mirror's normal below which the beam runs along the mirror
# (edge-on, in float32 rounding) and passes it.
GRAZING = 1e-5


@dataclass(frozen=True)
class Bounce:
    """One reflection: where, off which mirror, the ray's direction before and after."""

    mirror: int
    point: glm.vec3
    incoming: glm.vec3
    outgoing: glm.vec3


@dataclass
class BeamPath:
    """The traced beam: its corner points (start, each bounce, end), its bounces and how it
    ended: 'target' (reached the target), 'solid' (stopped by ``stopped_by``), 'back' (met a
    mirror's back), 'open' (left the level), 'limit' (a mirror past the bounce limit)."""

    points: list[glm.vec3] = field(default_factory=list)
    bounces: list[Bounce] = field(default_factory=list)
    end: str = "open"
    stopped_by: int | None = None

    def same_as(self, other: BeamPath | None, tolerance: float = 1e-6) -> bool:
        """Whether two paths draw the same (used to re-pose the beam only when it changed)."""
        if other is None or len(other.points) != len(self.points):
            return False
        return all(glm.distance(a, b) <= tolerance for a, b in zip(self.points, other.points, strict=True))


def hit_mirror(state: SurfaceState, origin: glm.vec3, direction: glm.vec3) -> tuple[float, bool] | None:
    """(ray parameter, from the front) where the ray crosses the mirror inside its outline,
    or None.  The outline is the mirror's 4 world corners as a 2 x 2 grid (a parallelogram)."""
    if state.outline is None:
        return None
    normal = glm.vec3(state.plane)
    denom = glm.dot(normal, direction)
    if abs(denom) < GRAZING:
        return None  # edge-on: the beam slides past
    t = -(glm.dot(normal, origin) + state.plane.w) / denom
    if t <= EPSILON:
        return None
    point = origin + t * direction
    c = state.outline
    c0 = glm.vec3(*c[0][:3])
    for other in (c[1], c[2]):
        edge = glm.vec3(*other[:3]) - c0
        s = glm.dot(point - c0, edge) / glm.dot(edge, edge)
        if s < -1e-6 or s > 1.0 + 1e-6:
            return None
    return t, denom < 0.0


def reflect_ray(state: SurfaceState, point: glm.vec3, direction: glm.vec3) -> glm.vec3:
    """The bounce direction: the incoming direction carried by the mirror's reflection matrix
    (the matrix the renderer reflects its camera with; directions are w = 0)."""
    return glm.normalize(glm.vec3(state.carry * glm.vec4(direction, 0.0)))


# (origin, unit direction, entity to leave out) -> (distance, entity) of the first solid, or None
FirstSolid = Callable[[glm.vec3, glm.vec3, "int | None"], "tuple[float, int] | None"]


def trace_beam(origin, direction, mirrors: Iterable[SurfaceState], first_solid: FirstSolid, target: int,
               max_bounces: int, skip: int | None = None) -> BeamPath:
    """Follow the beam from ``origin`` along ``direction``: at each step the nearest enabled
    mirror (front: bounce; back: stop) or solid (the target: win; else stop); after
    ``max_bounces`` bounces the next mirror stops it.  ``skip`` is an entity the first
    segment starts inside (the source)."""
    o = glm.vec3(origin)
    d = glm.normalize(glm.vec3(direction))
    live = [s for s in mirrors if s.enabled and s.kind == "mirror"]
    path = BeamPath(points=[glm.vec3(o)])
    last = skip
    while True:
        best_t, best_mirror, best_front, best_solid = float("inf"), None, False, None
        for state in live:
            if state.entity == last:
                continue
            found = hit_mirror(state, o, d)
            if found is not None and found[0] < best_t:
                best_t, best_mirror, best_front, best_solid = found[0], state, found[1], None
        solid = first_solid(o, d, last)
        if solid is not None and solid[0] < best_t:
            best_t, best_mirror, best_solid = solid[0], None, solid[1]
        if best_mirror is None and best_solid is None:
            path.points.append(o + OPEN_LENGTH * d)
            path.end = "open"
            return path
        point = o + best_t * d
        path.points.append(point)
        if best_solid is not None:
            path.end = "target" if best_solid == target else "solid"
            path.stopped_by = best_solid
            return path
        if not best_front or len(path.bounces) >= max_bounces:
            path.end = "back" if not best_front else "limit"
            path.stopped_by = best_mirror.entity
            return path
        outgoing = reflect_ray(best_mirror, point, d)
        path.bounces.append(Bounce(best_mirror.entity, point, d, outgoing))
        o, d, last = point, outgoing, best_mirror.entity
