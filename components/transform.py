"""Where an entity is: local pose relative to an optional parent entity."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from numbers import Integral, Real
from typing import Any

from pyglm import glm

from components.tracking import ComponentValueError, TrackedComponent, vec3

# Bounds a pose must keep for its matrices to stay meaningful in float32: past a billion
# metres a float32 position steps by 64 m, and a scale far from 1 drives the normal matrix
# (the inverse transpose) towards 0 or infinity, where normalising gives NaN.
POSITION_MAX = 1e9
SCALE_RANGE = (1e-6, 1e6)
_MIRRORING = [False]  # whether any Transform was given a negative scale component (in this process)


def mirroring_seen() -> bool:
    """Whether any Transform has been given a negative scale component: until one has, no
    world matrix can mirror, and the extract stage skips looking for instances that do."""
    return _MIRRORING[0]


@dataclass(eq=False)
class Transform(TrackedComponent):
    """Local translation, rotation and scale; ``parent`` is another entity id or None.

    ``world`` is derived state written by the TransformSystem (not tracked): the
    model-to-world matrix as of the last frame.
    """

    SHAREABLE = False  # one entity's own state: see components.tracking
    position: Any = field(default_factory=glm.vec3)
    rotation: Any = field(default_factory=glm.quat)
    scale: Any = field(default_factory=lambda: glm.vec3(1.0))
    parent: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "_world", glm.mat4(1.0))

    @property
    def world(self) -> glm.mat4:
        return self._world

    def __setattr__(self, name: str, value: Any) -> None:
        # The hot writes, a game's every frame (``t.position = p``, ``t.rotation = q`` with
        # glm values), checked inline: the same checks ``_validate`` makes, without its calls
        # (a thousand movers write twice each a frame).  A value that fails them, or any other
        # write, takes the general path (TrackedComponent.__setattr__), which says why.
        kind = type(value)
        if kind is glm.vec3 and name == "position":
            x, y, z = value
            limit = POSITION_MAX  # a NaN fails every comparison, an infinity the bound
            if -limit <= x <= limit and -limit <= y <= limit and -limit <= z <= limit:
                self.__dict__["position"] = glm.vec3(value)
                sink = self._sink
                if sink is not None:  # held by one entity (not SHAREABLE): _entities is {_entity}
                    entity = self._entity
                    sink.add(entity)
                    self._written[entity] = self  # World.written: found without a look-up
                return
        elif kind is glm.quat and name == "rotation":
            w, x, y, z = value  # a glm.quat unpacks as (w, x, y, z)
            norm = math.sqrt(w * w + x * x + y * y + z * z)  # as rotation() does, in double
            if norm != 0.0 and math.isfinite(norm):
                self.__dict__["rotation"] = glm.quat(w / norm, x / norm, y / norm, z / norm)
                sink = self._sink
                if sink is not None:
                    entity = self._entity
                    sink.add(entity)
                    self._written[entity] = self
                return
        TrackedComponent.__setattr__(self, name, value)

    def local_matrix(self) -> glm.mat4:
        # The fields read past the in-place watch (components.tracking): this is the engine's
        # own read, every changed transform every frame, and never edits them.
        state = self.__dict__
        return glm.translate(state["position"]) * glm.mat4_cast(state["rotation"]) * glm.scale(state["scale"])

    def _validate(self, name: str, value: Any) -> Any:
        if name == "position":
            v = vec3(self, name, value)
            if max(abs(v.x), abs(v.y), abs(v.z)) > POSITION_MAX:
                raise ComponentValueError(f"Transform.position must be within {POSITION_MAX:g} m of the origin on "
                                          f"each axis (float32 precision), got {value!r}")
            return v
        if name == "scale":
            v = vec3(self, name, value)
            if min(abs(v.x), abs(v.y), abs(v.z)) == 0.0:
                raise ComponentValueError(f"Transform.scale must have no zero component, got {value!r}")
            low, high = SCALE_RANGE
            if v.x < 0.0 or v.y < 0.0 or v.z < 0.0:
                _MIRRORING[0] = True
                world = getattr(self, "_world_ref", None)
                if world is not None:  # (a scale with a negative part: the rules about mirroring, a portal's)
                    for entity in self._entities:
                        world.check_invariants(entity, Transform, scale=v)
            if not all(low <= abs(c) <= high for c in v):
                raise ComponentValueError(f"Transform.scale components must be {low:g} to {high:g} in size "
                                          f"(the normal matrix is their inverse), got {value!r}")
            return v
        if name == "rotation":
            return rotation(value)
        if name == "parent" and value is not None:
            if isinstance(value, bool) or not isinstance(value, Integral) or value <= 0:
                raise ComponentValueError(f"Transform.parent must be an entity id or None, got {value!r}")
            if self._sink is not None and value in self._entities:
                raise ComponentValueError(f"Transform.parent of entity {value} is the entity itself, got {value!r}")
            if self._sink is not None and self._parent_cycle(int(value)):
                raise ComponentValueError(f"Transform.parent {value!r} would make a cycle (that entity descends "
                                          f"from entity {self._entity})")
            return int(value)
        return value

    def _parent_cycle(self, parent: int) -> bool:
        """Whether ``parent`` is this entity or one of its descendants (walks up from parent)."""
        world = getattr(self, "_world_ref", None)
        if world is None:
            return False
        seen: set[int] = set()
        entity: int | None = parent
        while entity is not None and entity not in seen:
            if entity in self._entities:
                return True
            seen.add(entity)
            other = world.try_get(entity, Transform) if world.exists(entity) else None
            entity = other.parent if other is not None else None
        return False


def rotation(value: Any) -> glm.quat:
    """A unit quaternion from a glm.quat or (w, x, y, z); normalised in double precision.

    A 3-tuple is refused: glm reads it as Euler angles in radians, which is rarely what a
    caller meant; :func:`euler_rotation` takes degrees by name.
    """
    if type(value) is glm.quat:  # the common case, a game's every rotation write: the same
        w, x, y, z = value.w, value.x, value.y, value.z  # arithmetic as below, without the checks
        norm = math.sqrt(w * w + x * x + y * y + z * z)  # a finite non-zero norm needs
        if norm != 0.0 and math.isfinite(norm):  # finite parts; anything else is refused below
            return glm.quat(w / norm, x / norm, y / norm, z / norm)
    if isinstance(value, (glm.vec3, glm.dvec3)) or (not isinstance(value, (glm.quat, glm.dquat))
                                                    and len(_parts(value)) == 3):
        raise ComponentValueError(
            f"Transform.rotation must be a quaternion (glm.quat or (w, x, y, z)); for angles use "
            f"euler_rotation(pitch_deg, yaw_deg, roll_deg), yaw_pitch_rotation or look_rotation, got {value!r}")
    if isinstance(value, (glm.quat, glm.dquat)):
        parts = [value.w, value.x, value.y, value.z]
    else:
        parts = _parts(value)
    if len(parts) != 4 or any(isinstance(c, (str, bytes, bool)) for c in parts):
        raise ComponentValueError(f"Transform.rotation must be a glm.quat or (w, x, y, z), got {value!r}")
    try:
        w, x, y, z = (float(c) for c in parts)
    except (TypeError, ValueError, OverflowError):
        raise ComponentValueError(f"Transform.rotation must be four finite numbers, got {value!r}") from None
    if not all(math.isfinite(c) for c in (w, x, y, z)):
        raise ComponentValueError(f"Transform.rotation must be finite, got {value!r}")
    norm = math.sqrt(w * w + x * x + y * y + z * z)  # in double: quat(1e20, ...) keeps its direction
    if norm == 0.0 or not math.isfinite(norm):
        raise ComponentValueError(f"Transform.rotation must not be the zero quaternion, got {value!r}")
    return glm.quat(w / norm, x / norm, y / norm, z / norm)


def _parts(value: Any) -> list[Any]:
    try:
        return list(value)
    except TypeError:
        return []


def euler_rotation(pitch_deg: float, yaw_deg: float, roll_deg: float = 0.0) -> glm.quat:
    """The rotation of Euler angles in **degrees**: roll about Z, then pitch about X, then yaw about Y.

    Named so that angles are never mistaken for a quaternion or for radians.
    """
    _check_degrees("euler_rotation", pitch_deg=pitch_deg, yaw_deg=yaw_deg, roll_deg=roll_deg)
    return (glm.angleAxis(glm.radians(float(yaw_deg)), glm.vec3(0, 1, 0))
            * glm.angleAxis(glm.radians(float(pitch_deg)), glm.vec3(1, 0, 0))
            * glm.angleAxis(glm.radians(float(roll_deg)), glm.vec3(0, 0, 1)))


# The largest angle a rotation is made from, in degrees: glm turns it in float32, where a
# larger one loses every digit of its turn (1e300 is infinite there, and the quaternion NaN).
MAX_DEGREES = 1e7


def _check_degrees(function: str, **angles: Any) -> None:
    """Each of ``angles`` a number of degrees within MAX_DEGREES, or an error naming
    ``function`` and it."""
    for name, v in angles.items():
        if isinstance(v, bool) or not isinstance(v, Real) or not abs(float(v)) <= MAX_DEGREES:
            raise ComponentValueError(f"{function} {name} must be a finite number of degrees "
                                      f"(at most {MAX_DEGREES:.0e} either way), got {v!r}")


def _direction(function: str, name: str, value: Any) -> glm.vec3:
    """``value`` as a direction: three finite numbers, not all zero (a zero or infinite one
    has no way to point, and would turn a rotation made from it into NaNs)."""
    parts = _parts(value)
    if len(parts) != 3 or any(isinstance(c, (str, bytes, bool)) for c in parts):
        raise ComponentValueError(f"{function} {name} must be a direction of three numbers, got {value!r}")
    try:
        x, y, z = (float(c) for c in parts)
    except (TypeError, ValueError, OverflowError):
        raise ComponentValueError(f"{function} {name} must be a direction of three numbers, got {value!r}") from None
    length = math.sqrt(x * x + y * y + z * z)
    if not math.isfinite(length) or length == 0.0:
        raise ComponentValueError(f"{function} {name} must be a finite direction, not zero, got {value!r}")
    return glm.vec3(x / length, y / length, z / length)


def look_rotation(forward: Any, up: Any = (0.0, 1.0, 0.0)) -> glm.quat:
    """The rotation whose -Z axis points along ``forward`` (GL's camera convention); ``up``
    (any length but zero) says which way the turn keeps its +Y, as near as it can (along
    ``forward``, another axis stands in)."""
    f = _direction("look_rotation", "forward", forward)
    u = _direction("look_rotation", "up", up)
    if abs(glm.dot(f, glm.normalize(u))) > 0.999:
        u = glm.vec3(0.0, 0.0, 1.0) if abs(f.z) < 0.9 else glm.vec3(1.0, 0.0, 0.0)
    return glm.quat_cast(glm.inverse(glm.lookAt(glm.vec3(0.0), f, u)))


def yaw_pitch_rotation(yaw_deg: float, pitch_deg: float) -> glm.quat:
    """Yaw about +Y then pitch about the local +X, in degrees (yaw 0 looks down -Z)."""
    if type(yaw_deg) is not float or type(pitch_deg) is not float or not (
            abs(yaw_deg) <= MAX_DEGREES and abs(pitch_deg) <= MAX_DEGREES):  # (the fly camera's floats: one test)
        _check_degrees("yaw_pitch_rotation", yaw_deg=yaw_deg, pitch_deg=pitch_deg)
    return glm.angleAxis(glm.radians(yaw_deg), glm.vec3(0, 1, 0)) * glm.angleAxis(
        glm.radians(pitch_deg), glm.vec3(1, 0, 0))


def yaw_pitch_of(direction: Any) -> tuple[float, float]:
    """The (yaw, pitch) in degrees that ``yaw_pitch_rotation`` turns -Z to, for ``direction``
    (any length but zero; three numbers or a glm vector): the one inverse of it, for a
    camera's heading, a look at a point, a pose carried through a portal.  Yaw in
    [-180, 180], pitch in [-90, 90]; straight up or down the yaw is 0 or 180 (no heading)."""
    x, y, z = (float(c) for c in direction)
    return math.degrees(math.atan2(-x, -z)), math.degrees(math.atan2(y, math.hypot(x, z)))


def heading(rotation: glm.quat) -> tuple[float, float]:
    """``yaw_pitch_of`` the direction an orientation looks (its -Z); its roll is dropped."""
    return yaw_pitch_of(rotation * glm.vec3(0.0, 0.0, -1.0))
