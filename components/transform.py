"""Where an entity is: local pose relative to an optional parent entity."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from numbers import Integral
from typing import Any

from pyglm import glm

from components.tracking import ComponentValueError, TrackedComponent, vec3


@dataclass(eq=False)
class Transform(TrackedComponent):
    """Local translation, rotation and scale; ``parent`` is another entity id or None.

    ``world`` is derived state written by the TransformSystem (not tracked): the
    model-to-world matrix as of the last frame.
    """

    position: Any = field(default_factory=glm.vec3)
    rotation: Any = field(default_factory=glm.quat)
    scale: Any = field(default_factory=lambda: glm.vec3(1.0))
    parent: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "_world", glm.mat4(1.0))

    @property
    def world(self) -> glm.mat4:
        return self._world

    def local_matrix(self) -> glm.mat4:
        return glm.translate(self.position) * glm.mat4_cast(self.rotation) * glm.scale(self.scale)

    def _validate(self, name: str, value: Any) -> Any:
        if name == "position":
            return vec3(self, name, value)
        if name == "scale":
            v = vec3(self, name, value)
            if min(abs(v.x), abs(v.y), abs(v.z)) == 0.0:
                raise ComponentValueError(f"Transform.scale must have no zero component, got {value!r}")
            return v
        if name == "rotation":
            try:
                q = glm.quat(value)
            except TypeError:
                raise ComponentValueError(f"Transform.rotation must be a glm.quat, got {value!r}") from None
            if not (math.isfinite(q.w) and math.isfinite(q.x) and math.isfinite(q.y) and math.isfinite(q.z)):
                raise ComponentValueError(f"Transform.rotation must be finite, got {value!r}")
            if glm.length(q) == 0.0:
                raise ComponentValueError("Transform.rotation must not be the zero quaternion")
            return glm.normalize(q)
        if name == "parent" and value is not None:
            if isinstance(value, bool) or not isinstance(value, Integral) or value <= 0:
                raise ComponentValueError(f"Transform.parent must be an entity id or None, got {value!r}")
            return int(value)
        return value


def look_rotation(forward: Any, up: Any = (0.0, 1.0, 0.0)) -> glm.quat:
    """The rotation whose -Z axis points along ``forward`` (GL's camera convention)."""
    f = glm.normalize(glm.vec3(forward))
    u = glm.vec3(up)
    if abs(glm.dot(f, glm.normalize(u))) > 0.999:
        u = glm.vec3(0.0, 0.0, 1.0) if abs(f.z) < 0.9 else glm.vec3(1.0, 0.0, 0.0)
    return glm.quat_cast(glm.inverse(glm.lookAt(glm.vec3(0.0), f, u)))


def yaw_pitch_rotation(yaw_deg: float, pitch_deg: float) -> glm.quat:
    """Yaw about +Y then pitch about the local +X, in degrees (yaw 0 looks down -Z)."""
    return glm.angleAxis(glm.radians(yaw_deg), glm.vec3(0, 1, 0)) * glm.angleAxis(
        glm.radians(pitch_deg), glm.vec3(1, 0, 0))
