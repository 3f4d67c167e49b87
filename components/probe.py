"""Cube-map reflection probes: what a curved shiny object (or glass) sees around it."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from components.limits import MAX_VIEW_DEPTH, check_near_far
from components.tracking import ComponentValueError, boolean, choice, finite, integer, vec3
from components.visibility import LAYER_FIELDS, ShownLayers

REFRESH_MODES = ("once", "on_change", "every_frame", "every_n", "scripted")
TIME_SLICING = ("all_faces", "one_face_per_frame")
PREFILTERS = ("mips", "ggx")
MIN_PROBE_RESOLUTION = 8
MAX_PROBE_RESOLUTION = 2048  # also checked against the context's cube-map limit when the probe is made
_DEFAULT_FAR = 100.0


@dataclass(eq=False)
class ReflectionProbe(ShownLayers):
    """A cube map captured at the entity's position (its Transform), of the scene around it.

    ``resolution`` texels across a face (a power of two), ``near`` / ``far`` the capture
    range (held to a camera's depth limits: ``components.limits.check_near_far``).
    ``refresh``: ``once`` (captured the first frame only), ``on_change`` (the
    default: captured the first frame, then only the faces whose view holds something that
    was added, removed, moved or changed its material), ``every_frame``, ``every_n``
    (every ``every_n`` frames) or ``scripted`` (only after ``request()``).  A due face that
    shows the sky alone, as it did when last drawn from the same place under the same sky,
    is kept rather than drawn again: it is the picture a capture would draw.
    ``time_slicing`` spreads a capture over six frames (one face each) instead of one.
    ``influence`` is the size of a box around the probe: objects inside it that reflect a
    cube map, refract, or reflect the light from all round by their material (every plain
    mesh: ``Material.environment_reflection``) sample this probe (None: the probe serves
    only its own entity).
    ``blend_distance`` is how far inside the box's walls its weight falls off to nothing
    (Unity HDRP's blend distance): an object blends the probes whose boxes hold it by their
    weights (normalised only where they add up to more than 1; the sky, or a curved object's
    own probe, takes what they leave), so it moves from one probe's room to the next without
    a pop (``engine.rules.probe_rules.probe_blend``; 0, the default: full weight up to the walls,
    the box's edge is hard).  At most half the box's smallest side.
    ``box_projection`` corrects lookups for the box's walls (parallax-corrected, as Unity's
    and Godot's probes do).  ``depth`` is how many levels of mirrors and portals a face
    sees (0: none, and no view tree: mirrors show their own surface in its captures).
    ``prefilter``: how rough materials blur what the probe saw: ``mips`` (the default: a
    box-filtered mip chain, sampled with a roughness bias) or ``ggx`` (each level convolved
    with a GGX lobe of its own roughness, as three.js's PMREM and Unity's probe convolution
    do: closer to the light's true spread, and dearer to capture).
    ``priority`` (an int, higher first; default 0) orders its captures under the frame's
    budgets (``engine.resources.ViewBudget``), after first captures and before distance.
    ``shows_layers`` (None: all) and ``hides_layers`` are the reflection layers its captures
    show (``components.visibility``), in the faces and the mirrors and portals they see.
    """

    resolution: int = 128
    near: float = 0.05
    far: float = _DEFAULT_FAR
    refresh: str = "on_change"
    every_n: int = 1
    time_slicing: str = "all_faces"
    influence: Any = None
    blend_distance: float = 0.0
    box_projection: bool = False
    depth: int = 1
    prefilter: str = "mips"
    priority: int = 0
    _requests: int = field(default=0, init=False, repr=False, compare=False)

    def request(self) -> None:
        """Ask a ``scripted`` probe (or any other) for a capture of every face next frame."""
        self._requests += 1
        self.touch()

    @property
    def requests(self) -> int:
        """How many times ``request()`` was called.  A reader (the probes scheduler) compares
        it with the count it saw last: reading a request clears nothing."""
        return self._requests

    def _validate(self, name: str, value: Any) -> Any:
        if name in LAYER_FIELDS:
            return super()._validate(name, value)  # ShownLayers' check
        if name == "priority":
            return integer(self, name, value, low=-1000, high=1000)
        if name == "resolution":
            value = integer(self, name, value, low=MIN_PROBE_RESOLUTION, high=MAX_PROBE_RESOLUTION)
            if value & (value - 1):
                raise ComponentValueError(f"ReflectionProbe.resolution must be a power of two, got {value!r}")
            return value
        if name in ("near", "far"):
            return check_near_far(self, name, value, _DEFAULT_FAR)
        if name == "refresh":
            return choice(self, name, value, REFRESH_MODES)
        if name == "every_n":
            return integer(self, name, value, low=1, high=1_000_000)
        if name == "time_slicing":
            return choice(self, name, value, TIME_SLICING)
        if name == "prefilter":
            return choice(self, name, value, PREFILTERS)
        if name == "influence" and value is not None:
            value = vec3(self, name, value, low=0.0, nonzero=True)
            self._check_blend(self.__dict__.get("blend_distance"), value, name)
            return value
        if name == "blend_distance":
            value = finite(self, name, value, low=0.0, high=1e6)
            self._check_blend(value, self.__dict__.get("influence"), name)
            return value
        if name == "box_projection":
            return boolean(self, name, value)
        if name == "depth":
            return integer(self, name, value, low=0, high=MAX_VIEW_DEPTH)
        return value

    @staticmethod
    def _check_blend(blend: float | None, influence: Any, name: str) -> None:
        """A falloff wider than half the box's smallest side would never reach full weight,
        even at the centre: refused, naming the field just written."""
        if blend is None or influence is None:
            return
        half = min(float(influence[0]), float(influence[1]), float(influence[2])) / 2.0
        if blend > half:
            raise ComponentValueError(
                f"ReflectionProbe.{name}: blend_distance ({blend}) must be at most half the influence box's "
                f"smallest side ({half})")
