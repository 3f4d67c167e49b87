"""Change tracking shared by every component.

Systems must not scan 10,000 entities a frame to find the few that changed, so each
component reports its own field writes to the world that owns it.  A component is still
plain data: a dataclass whose ``__setattr__`` validates the value and, once the component
belongs to a world, adds its entity to that world's change set for its type.

**In-place edits.**  A glm vector or quaternion held in a field can be edited in place
(``t.position.y += 1``, ``material.color.a = 0.5``): no field write happens, so the
component cannot report it when it happens.  It is seen one stage later instead: reading
such a field from a component in a world records the value and a copy of it (``World``'s
in-place watch); at the start of the transform stage (``World.settle_in_place_edits``) each
value read since is compared with its copy, and one that changed is checked as a write
would be and reported as one (the stages from the transform stage on see it in this frame's
change sets; an edit made after the extract stage is drawn from the next frame).  A value
still held elsewhere (``p = t.position`` kept by a game) stays watched; the others are
dropped after the check, so a world pays only for what was read.  Assigning the field
(``t.position = ...``, ``t.position += ...``) is reported at once and costs nothing extra.
``touch`` reports a change the component cannot see at all (a numpy array edited in place).

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
from numbers import Integral, Real
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


# glm types a field may hold that can be edited in place (the in-place watch follows them).
IN_PLACE_TYPES = frozenset({glm.vec2, glm.vec3, glm.vec4, glm.quat, glm.dvec3, glm.dquat})


class TrackedComponent:
    """Base of all components: validates fields and reports writes to its world."""

    # Set by engine.core.world.World when the component is attached; never by users.
    _sink: set[int] | None = None
    _entity: int = 0                      # the entity it last joined
    _entities: frozenset[int] = frozenset()  # every entity holding it (one unless shared)
    _written: dict[int, Any] | None = None    # the world's hot-path writes of its kind (World.written)
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
        self.__dict__[name] = value  # past the fields' watch properties (``_watched_field``)
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
    """The dataclass fields of a component class (None for a non-dataclass subclass); the
    first call for a class also puts the in-place watch on its fields (``_watched_field``)."""
    try:
        return _FIELDS[cls]
    except KeyError:
        names = frozenset(f.name for f in dataclasses.fields(cls)) if dataclasses.is_dataclass(cls) else None
        _FIELDS[cls] = names
        for f in dataclasses.fields(cls) if names is not None else ():
            # Public fields set by __init__ (a private or init=False field keeps its class
            # default) that may hold a glm vector: only they pay for the watch's property.
            if f.init and not f.name.startswith("_") and _may_hold_glm(f) and not any(
                    isinstance(vars(base).get(f.name), property) for base in cls.__mro__):
                setattr(cls, f.name, _watched_field(f.name))
        return names


def _may_hold_glm(f: dataclasses.Field) -> bool:
    """Whether a field may hold a glm vector or quaternion: its default is one, or it is an
    ``Any`` field whose default is None (``Mirror.plane_normal``, ``ReflectionProbe.influence``)."""
    if f.default_factory is not dataclasses.MISSING:
        default = f.default_factory()
    else:
        default = f.default
    if type(default) in IN_PLACE_TYPES:
        return True
    annotation = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
    return default is None and annotation in ("Any", "typing.Any")


def _watched_field(name: str) -> property:
    """A field as a property over the instance's ``__dict__``: reading a glm vector or
    quaternion from a component in a world puts it in the world's in-place watch (the
    module docstring), once per value until the watch is settled."""

    def read(self: TrackedComponent) -> Any:
        state = self.__dict__
        try:
            value = state[name]
        except KeyError:
            raise AttributeError(f"{type(self).__name__} has no value for {name!r} yet") from None
        if type(value) in IN_PLACE_TYPES:
            handed = state.get("_handed")
            if handed is not None:
                key = (id(self), name)
                if key not in handed:
                    handed[key] = (self, name, value, type(value)(value))
        return value

    def write(self: TrackedComponent, value: Any) -> None:  # object.__setattr__ and dataclasses come here
        self.__dict__[name] = value

    return property(read, write, doc=f"The {name!r} field (edits in place are seen: module docstring).")


def raw_field(component: TrackedComponent, name: str) -> Any:
    """A field's value without entering the in-place watch (the engine's own hot reads)."""
    return component.__dict__[name]


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


def vec3(owner: object, name: str, value: Any, *, low: float | None = None, high: float | None = None,
         why: str = "", nonzero: bool = False, one_number: bool = True) -> glm.vec3:
    """A glm.vec3 of finite components (each >= low and <= high when given; ``why``: what the
    bounds are, said after them when one is crossed).  Three numbers, or (``one_number``) one
    number standing for all three (a uniform scale, no gravity); never two or four (glm took
    four, a glm.vec4 among them, and dropped the last silently)."""
    if type(value) is glm.vec3 and low is None and high is None and not nonzero:
        # The per-frame case (``t.position += step``): a glm vector needs only the finite test.
        x, y, z = value
        if math.isfinite(x) and math.isfinite(y) and math.isfinite(z):
            return glm.vec3(value)
        raise _fail(owner, name, value, "must be finite")
    if _not_a_number(value) or isinstance(value, dict) or any(_not_a_number(c) for c in _items(value)):
        raise _fail(owner, name, value, "must be three numbers")
    parts = _items(value)
    if parts and len(parts) != 3:
        raise _fail(owner, name, value, f"must be three numbers, not {len(parts)}")
    if not parts and not one_number:
        one = isinstance(value, (Real, np.number)) or (isinstance(value, np.ndarray) and value.ndim == 0)
        raise _fail(owner, name, value, "must be three numbers" + (" (a direction, not one number)" if one else ""))
    try:
        if parts:
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
        if high is not None and c > high:
            raise _fail(owner, name, value, f"must have every component in [{'-inf' if low is None else f'{low:g}'}, "
                                            f"{high:g}]{why}")
    if nonzero and glm.length(v) == 0.0:
        raise _fail(owner, name, value, "must not be the zero vector")
    return v


def direction(owner: object, name: str, value: Any) -> glm.vec3:
    """A unit glm.vec3 along three finite numbers, not all zero.  ``glm.normalize`` squares
    in float32, where a length past about 1.8e19 is infinite (the vector came out zero) and
    one below about 1e-19 loses its digits (it came out longer or shorter than 1): such a
    vector is normalised in double precision instead (any other keeps glm's result, bit for bit)."""
    v = vec3(owner, name, value, one_number=False)
    unit = glm.normalize(v)
    if abs(glm.length(unit) - 1.0) <= 1e-5:  # (a NaN fails it too)
        return unit
    x, y, z = float(v.x), float(v.y), float(v.z)
    length = math.sqrt(x * x + y * y + z * z)
    if length == 0.0:
        raise _fail(owner, name, value, "must not be the zero vector")
    return glm.vec3(x / length, y / length, z / length)


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
    if value is True or value is False or (isinstance(value, str) and value == "auto"):  # (an array: no ==)
        return value
    raise _fail(owner, name, value, 'must be True, False or "auto"')


def choice(owner: object, name: str, value: Any, options: tuple[str, ...]) -> str:
    if not isinstance(value, str) or value not in options:
        raise _fail(owner, name, value, f"must be one of {options}")
    return value
