"""Views and lights: a camera looks down its Transform's -Z; lights light the scene."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pyglm import glm

from components.tracking import ComponentValueError, TrackedComponent, boolean, color, finite, vec3


@dataclass(eq=False)
class Camera(TrackedComponent):
    """A perspective camera. The active camera with the lowest entity id renders."""

    fov_y: float = 60.0
    near: float = 0.05
    far: float = 200.0
    active: bool = True

    def _validate(self, name: str, value: Any) -> Any:
        if name == "fov_y":
            return finite(self, name, value, low=1.0, high=179.0)
        if name in ("near", "far"):
            value = finite(self, name, value, positive=True)
            # Checked on every write, not only at construction (the other plane is in
            # __dict__ once set; during __init__ ``near`` comes first).
            near = value if name == "near" else self.__dict__.get("near")
            far = value if name == "far" else self.__dict__.get("far")
            if near is not None and far is not None and far <= near:
                raise ComponentValueError(f"Camera.{name} must keep far > near, got near={near} far={far}")
            return value
        if name == "active":
            return boolean(self, name, value)
        return value


@dataclass(eq=False)
class FlyController(TrackedComponent):
    """WASD + mouse fly controls for the entity's Transform (used by windowed runs)."""

    speed: float = 4.0
    mouse_sensitivity: float = 0.15
    yaw: float = 0.0
    pitch: float = 0.0

    def _validate(self, name: str, value: Any) -> Any:
        if name in ("speed", "mouse_sensitivity"):
            return finite(self, name, value, low=0.0)
        if name in ("yaw", "pitch"):
            return finite(self, name, value)
        return value


@dataclass(eq=False)
class DirectionalLight(TrackedComponent):
    """Light from infinitely far along ``direction`` (the way the light travels)."""

    direction: Any = field(default_factory=lambda: glm.vec3(-0.3, -1.0, -0.4))
    color: Any = field(default_factory=lambda: glm.vec4(1.0))
    intensity: float = 1.0

    def _validate(self, name: str, value: Any) -> Any:
        if name == "direction":
            return glm.normalize(vec3(self, name, value, nonzero=True))
        if name == "color":
            return color(self, name, value)
        if name == "intensity":
            return finite(self, name, value, low=0.0)
        return value


@dataclass(eq=False)
class PointLight(TrackedComponent):
    """Light from the entity's position, falling off smoothly to zero at ``range``."""

    color: Any = field(default_factory=lambda: glm.vec4(1.0))
    intensity: float = 1.0
    range: float = 10.0

    def _validate(self, name: str, value: Any) -> Any:
        if name == "color":
            return color(self, name, value)
        if name == "intensity":
            return finite(self, name, value, low=0.0)
        if name == "range":
            return finite(self, name, value, positive=True)
        return value
