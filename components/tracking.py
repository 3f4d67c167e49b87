"""Change tracking shared by every component.

Systems must not scan 10,000 entities a frame to find the few that changed, so each
component reports its own field writes to the world that owns it.  A component is still
plain data: a dataclass whose ``__setattr__`` validates the value and, once the component
belongs to a world, adds its entity to that world's change set for its type.

In-place edits of a mutable field (``t.position.x = 1``) cannot be seen; assign the
field (``t.position = ...``, ``t.position += ...``) or call :meth:`touch`.

**Sharing one component object between entities.**  Components that are plain data about
how something looks (Material, MeshRef, Mirror, Emissive, Reflective, Refractive, lights,
probes, Skybox) may be given to several entities on purpose: the component keeps the set of
entities holding it, and a field write marks every one of them changed (three boxes sharing
a Material all turn green; deleting one leaves the others updating).  Components that
describe one entity's own state (``SHAREABLE = False``: Transform with its parent and the
travel writes, Camera, FlyController, Portal with its partner, Traveller, Slice, PortalClone)
are refused on a second entity with an error naming the class and both entities: give each
entity its own object (``dataclasses.replace(c)`` copies one).  A component belongs to one
world at a time.
"""
from __future__ import annotations

import dataclasses
import math
from numbers import Integral
from typing import Any, ClassVar

import numpy as np
from pyglm import glm


class ComponentValueError(ValueError):
    """A component field was given a value it cannot hold (NaN, negative, wrong kind)."""


class ComponentWarning(UserWarning):
    """A component value the engine can hold but that is almost certainly not what was meant
    (a colour written 0-255, an entity hidden in every kind of view, a view that shows no
    layer): said when it is given, as one line (``speculum: warning:`` from the command line)."""


def warn_component(message: str) -> None:
    """A ``ComponentWarning`` pointing past the component code, at the caller's line."""
    import sys
    import warnings

    level, frame = 2, sys._getframe(1)
    while frame is not None and frame.f_globals.get("__name__", "").startswith(("components.", "engine.core.world",
                                                                                 "engine.rules.", "dataclasses")):
        frame, level = frame.f_back, level + 1
    warnings.warn(message, ComponentWarning, stacklevel=level)


class TrackedComponent:
    """Base of all components: validates fields and reports writes to its world."""

    # Set by engine.core.world.World when the component is attached; never by users.
    _sink: set[int] | None = None
    _entity: int = 0                      # the entity it last joined
    _entities: frozenset[int] = frozenset()  # every entity holding it (one unless shared)
    # False for components that are one entity's own state (see the module docstring).
    SHAREABLE: ClassVar[bool] = True

    def __setattr__(self, name: str, value: Any) -> None:
        if not name.startswith("_"):
            fields = _field_names(type(self))
            if fields is not None and name not in fields:
                # A typo (``light.intesity = 5``) would otherwise be silently ignored.
                raise AttributeError(f"{type(self).__name__} has no field {name!r} "
                                     f"(fields: {', '.join(sorted(fields))})")
            value = self._validate(name, value)
        object.__setattr__(self, name, value)
        sink = self._sink
        if sink is not None and not name.startswith("_"):
            sink.update(self._entities)

    def touch(self) -> None:
        """Report an in-place edit the component could not see by itself."""
        if self._sink is not None:
            self._sink.update(self._entities)

    def _validate(self, name: str, value: Any) -> Any:  # overridden per component
        return value


_FIELDS: dict[type, frozenset[str] | None] = {}


def _field_names(cls: type) -> frozenset[str] | None:
    """The dataclass fields of a component class (None for a non-dataclass subclass)."""
    try:
        return _FIELDS[cls]
    except KeyError:
        names = frozenset(f.name for f in dataclasses.fields(cls)) if dataclasses.is_dataclass(cls) else None
        _FIELDS[cls] = names
        return names


# --- validators used by the component classes -------------------------------------------

def _not_a_number(value: Any) -> bool:
    """Kinds ``float()`` would accept but a numeric field must not: text and booleans."""
    return isinstance(value, (str, bytes, bool, np.bool_))


def _fail(owner: object, name: str, value: Any, why: str) -> ComponentValueError:
    return ComponentValueError(f"{type(owner).__name__}.{name} {why}, got {value!r}")


# What the GPU formats hold: float32 for positions, sizes and parameters; float16 (largest
# finite 65504) for anything that lands in the HDR colour targets (colours, intensities).
FLOAT32_MAX = 3.4028234663852886e38
HALF_MAX = 65504.0


def finite(owner: object, name: str, value: Any, *, low: float | None = None,
           high: float | None = None, positive: bool = False) -> float:
    """A finite float inside [low, high] (and > 0 when ``positive``)."""
    if _not_a_number(value):
        raise _fail(owner, name, value, "must be a number")
    try:
        number = float(value)
    except OverflowError:
        raise _fail(owner, name, value, "must be finite (too large for a float)") from None
    except (TypeError, ValueError):
        raise _fail(owner, name, value, "must be a number") from None
    if not math.isfinite(number):
        raise _fail(owner, name, value, "must be finite")
    if abs(number) > FLOAT32_MAX:
        raise _fail(owner, name, value, "must fit in a 32-bit float (|x| <= 3.4e38)")
    if positive and number <= 0.0:
        raise _fail(owner, name, value, "must be > 0")
    if low is not None and number < low:
        raise _fail(owner, name, value, f"must be >= {low}")
    if high is not None and number > high:
        raise _fail(owner, name, value, f"must be <= {high}")
    return number


def vec3(owner: object, name: str, value: Any, *, low: float | None = None,
         nonzero: bool = False) -> glm.vec3:
    """A glm.vec3 of finite components (each >= low when given)."""
    if type(value) is glm.vec3 and low is None and not nonzero:
        # The per-frame case (``t.position += step``): a glm vector needs only the finite test.
        x, y, z = value
        if math.isfinite(x) and math.isfinite(y) and math.isfinite(z):
            return glm.vec3(value)
        raise _fail(owner, name, value, "must be finite")
    if _not_a_number(value) or isinstance(value, dict) or any(_not_a_number(c) for c in _items(value)):
        raise _fail(owner, name, value, "must be three numbers")
    try:
        parts = _items(value)
        if len(parts) == 3:
            # Through float() first: glm wraps ints >= 2**63 silently ((2**64 + 5, 0, 0) -> 5).
            v = glm.vec3(*(float(c) for c in parts))
        else:
            v = glm.vec3(value) if not isinstance(value, (int, float)) else glm.vec3(float(value))
    except OverflowError:
        raise _fail(owner, name, value, "must be finite (too large for a float)") from None
    except (TypeError, ValueError):
        raise _fail(owner, name, value, "must be three numbers") from None
    for c in v:
        if not math.isfinite(c):
            raise _fail(owner, name, value, "must be finite")
        if low is not None and c < low:
            raise _fail(owner, name, value, f"must have every component >= {low}")
    if nonzero and glm.length(v) == 0.0:
        raise _fail(owner, name, value, "must not be the zero vector")
    return v


def color(owner: object, name: str, value: Any) -> glm.vec4:
    """A linear RGBA colour; RGB given alone gets alpha 1. Components in [0, inf), alpha <= 1."""
    parts = [] if _not_a_number(value) or isinstance(value, dict) else _items(value)
    if not parts or any(_not_a_number(c) for c in parts):
        raise _fail(owner, name, value, "must be 3 or 4 numbers")
    try:
        items = [float(c) for c in parts]
    except OverflowError:
        raise _fail(owner, name, value, "must have finite components (too large for a float)") from None
    except (TypeError, ValueError):
        raise _fail(owner, name, value, "must be 3 or 4 numbers") from None
    if len(items) == 3:
        items.append(1.0)
    if len(items) != 4:
        raise _fail(owner, name, value, "must be 3 or 4 numbers")
    if not all(math.isfinite(c) and c >= 0.0 for c in items):
        raise _fail(owner, name, value, "must have finite components >= 0")
    if items[3] > 1.0:
        raise _fail(owner, name, value, "must have alpha <= 1")
    if max(items) > HALF_MAX:
        raise _fail(owner, name, value, "must have components <= 65504 (the half-float colour targets' limit)")
    rgb = parts[:3]
    if all(isinstance(c, (Integral, np.integer)) and not isinstance(c, (bool, np.bool_)) for c in rgb) \
            and 1 < max(items[:3]) <= 255:
        scaled = ", ".join(f"{float(c) / 255.0:.3g}" for c in rgb)
        warn_component(f"{type(owner).__name__}.{name} = {value!r} looks like 0-255 colour values; colours are "
                       f"linear 0-1 (that is ({scaled}) in 0-1; write floats, e.g. 3.0, for a colour brighter than 1)")
    return glm.vec4(*items)


def boolean(owner: object, name: str, value: Any) -> bool:
    """True or False (not 1, "yes" or None)."""
    if not isinstance(value, (bool, np.bool_)):
        raise _fail(owner, name, value, "must be True or False")
    return bool(value)


def integer(owner: object, name: str, value: Any, *, low: int, high: int) -> int:
    """An int (Python or numpy, not bool) inside [low, high]."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, Integral) or not low <= value <= high:
        raise _fail(owner, name, value, f"must be an int in [{low}, {high}]")
    return int(value)


def _items(value: Any) -> list[Any]:
    try:
        return list(value)
    except TypeError:
        return []


def end_image_choice(owner: object, name: str, value: Any) -> bool | str:
    """True, False or "auto" (a surface's ``end_image``)."""
    if value is True or value is False or value == "auto":
        return value
    raise _fail(owner, name, value, 'must be True, False or "auto"')


def choice(owner: object, name: str, value: Any, options: tuple[str, ...]) -> str:
    if not isinstance(value, str) or value not in options:
        raise _fail(owner, name, value, f"must be one of {options}")
    return value
