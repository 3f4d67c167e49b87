"""The player's body: an axis-aligned box (AABB) that falls and collides with the level's
solids, themselves taken as their world-space AABBs.

Motion is the swept-AABB method resolved one axis at a time (vertical first, so standing on
a floor never snags on its edge when walking), in sub-steps no longer than ``MAX_STEP`` so
a fast body cannot tunnel through a wall thinner than its step.  A body that starts a frame
inside a solid (just carried out of a portal into a wall's thickness) is pushed out along
the axis of least penetration first.  ``passable(entity, lo, hi)`` lets the game open a hole
in a solid (the wall a portal sits on, while the body is in front of the portal's opening).

A limit: a solid turned off the world axes collides as its world-axis box, which is larger
than it; the game reports such solids once a build (``CoarseCollisionWarning``).
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

MAX_STEP = 0.1  # m: longest move along an axis before collisions are resolved
SKIN = 1e-4  # m: gap left between a body and what stopped it, so resting contact is no overlap
STEP_UP = 0.35  # m: an overlap this shallow from above is resolved upwards (feet in a floor)


@dataclass(frozen=True)
class Solid:
    """A solid thing's world-space AABB."""

    entity: int
    lo: np.ndarray
    hi: np.ndarray


@dataclass(frozen=True)
class BodyShape:
    """The body relative to its reference point (the eye): ``lo`` and ``hi`` offsets."""

    lo: np.ndarray
    hi: np.ndarray

    @classmethod
    def standing(cls, half_width: float, height: float, eye_height: float) -> BodyShape:
        return cls(np.array([-half_width, -eye_height, -half_width]),
                   np.array([half_width, height - eye_height, half_width]))


@dataclass
class Moved:
    """The result of one move: where the eye ended, the velocity left after contacts, and
    which ways the body was stopped."""

    position: np.ndarray
    velocity: np.ndarray
    on_ground: bool
    blocked: set[int]  # entities that stopped the body this move


def _overlap(lo: np.ndarray, hi: np.ndarray, solid: Solid) -> bool:
    return bool(np.all(lo < solid.hi) and np.all(hi > solid.lo))


def move_body(position: Sequence[float], velocity: Sequence[float], dt: float, shape: BodyShape,
              solids: Sequence[Solid], passable: Callable[[int, np.ndarray, np.ndarray], bool] | None = None
              ) -> Moved:
    """Move a body by ``velocity * dt`` through ``solids``; see the module docstring."""
    pos = np.array(position, np.float64)
    vel = np.array(velocity, np.float64)
    blocked: set[int] = set()
    on_ground = False

    def solid_at(lo: np.ndarray, hi: np.ndarray, solid: Solid) -> bool:
        return _overlap(lo, hi, solid) and not (passable is not None and passable(solid.entity, lo, hi))

    # Push out of anything the body starts inside.
    for _ in range(4):
        lo, hi = pos + shape.lo, pos + shape.hi
        inside = [s for s in solids if solid_at(lo, hi, s)]
        if not inside:
            break
        s = inside[0]
        up = s.hi[1] - lo[1]
        if up <= STEP_UP:
            pos[1] += up + SKIN
            on_ground = True
            vel[1] = max(vel[1], 0.0)
            continue
        pushes = [(s.hi[a] - lo[a] + SKIN, a, 1.0) for a in range(3)] + [(hi[a] - s.lo[a] + SKIN, a, -1.0)
                                                                          for a in range(3)]
        amount, axis, sign = min(pushes)
        pos[axis] += sign * amount
        blocked.add(s.entity)

    delta = vel * dt
    steps = max(1, math.ceil(float(np.max(np.abs(delta))) / MAX_STEP))
    step = delta / steps
    for _ in range(steps):
        for axis in (1, 0, 2):
            d = step[axis]
            if d == 0.0:
                continue
            before_lo, before_hi = pos + shape.lo, pos + shape.hi
            pos[axis] += d
            lo, hi = pos + shape.lo, pos + shape.hi
            for s in solids:
                if not solid_at(lo, hi, s):
                    continue
                if _overlap(before_lo, before_hi, s):
                    # Already inside its box (through a portal's opening) and now not let through:
                    # the step ran into the opening's edge, so it is taken back.
                    pos[axis] -= d
                    d = 0.0
                elif d > 0.0:
                    pos[axis] = s.lo[axis] - shape.hi[axis] - SKIN
                else:
                    pos[axis] = s.hi[axis] - shape.lo[axis] + SKIN
                    if axis == 1:
                        on_ground = True
                vel[axis] = 0.0
                step[axis] = 0.0
                blocked.add(s.entity)
                lo, hi = pos + shape.lo, pos + shape.hi
    return Moved(pos, vel, on_ground, blocked)
