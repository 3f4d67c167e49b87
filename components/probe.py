"""Cube-map reflection probes (what a curved shiny object, or glass, sees around it) and
irradiance volumes (a grid of captures that light whatever stands among them)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pyglm import glm

from components.limits import MAX_VIEW_DEPTH, MAX_VOLUME_AXIS_POINTS, MAX_VOLUME_BOUNCES, check_near_far
from components.tracking import ComponentValueError, boolean, choice, finite, integer, vec3
from components.visibility import LAYER_FIELDS, ShownLayers

REFRESH_MODES = ("once", "on_change", "every_frame", "every_n", "scripted")
TIME_SLICING = ("all_faces", "one_face_per_frame")
PREFILTERS = ("mips", "ggx")
MIN_PROBE_RESOLUTION = 8
MAX_PROBE_RESOLUTION = 2048  # also checked against the context's cube-map limit when the probe is made
_DEFAULT_FAR = 100.0


@dataclass(eq=False)
class Captured(ShownLayers):
    """What probes and irradiance volumes share: the reflection layers their captures show
    (``ShownLayers``), a count of requests for captures again, and the checks of their
    resolution and of a blend distance inside their box."""

    _requests: int = field(default=0, init=False, repr=False, compare=False)

    def request(self) -> None:
        """Ask for everything captured again: a probe's every face next frame (a ``scripted``
        one's only way), a volume's whole grid (its light kept until the new bake is done)."""
        self._requests += 1
        self.touch()

    @property
    def requests(self) -> int:
        """How many times ``request()`` was called.  A reader (the probes scheduler, the volume
        stage) compares it with the count it saw last: reading a request clears nothing."""
        return self._requests

    def _resolution(self, name: str, value: Any, low: int, high: int) -> int:
        """A power of two in [low, high] (a cube face's texels across)."""
        value = integer(self, name, value, low=low, high=high)
        if value & (value - 1):
            raise ComponentValueError(f"{type(self).__name__}.{name} must be a power of two, got {value!r}")
        return value

    def _check_blend(self, blend: float | None, box: Any, name: str) -> None:
        """A falloff wider than half the box's smallest side would never reach full weight,
        even at the centre: refused, naming the field just written."""
        if blend is None or box is None:
            return
        half = min(float(box[0]), float(box[1]), float(box[2])) / 2.0
        if blend > half:
            raise ComponentValueError(
                f"{type(self).__name__}.{name}: blend_distance ({blend}) must be at most half the "
                f"{'influence box' if isinstance(self, ReflectionProbe) else 'box'}'s smallest side ({half})")


@dataclass(eq=False)
class ReflectionProbe(Captured):
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

    def _validate(self, name: str, value: Any) -> Any:
        if name in LAYER_FIELDS:
            return super()._validate(name, value)  # ShownLayers' check
        if name == "priority":
            return integer(self, name, value, low=-1000, high=1000)
        if name == "resolution":
            return self._resolution(name, value, MIN_PROBE_RESOLUTION, MAX_PROBE_RESOLUTION)
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


VOLUME_REFRESH = ("once", "continuous", "scripted")
MIN_VOLUME_RESOLUTION = 16   # a capture's face: the projection reads a 16-texel level
MAX_VOLUME_RESOLUTION = 128
MAX_NORMAL_BIAS = 10.0


@dataclass(eq=False)
class IrradianceVolume(Captured):
    """A grid of light probes over a box: the light arriving at each point of the grid from
    all round, captured as a cube map and kept as nine spherical-harmonic coefficients
    (irradiance volumes: Greger, Shirley, Hubbard and Greenberg 1998; Unity's light probes
    and adaptive probe volumes, Godot's LightmapGI probes, Unreal's volumetric lightmap).
    Whatever stands inside the box takes its light from all round from the grid, blended
    between the eight points about it (trilinear), instead of from the sky or the reflection
    probes' boxes: a ball rolling from a sunlit courtyard under an arch darkens, a white wall
    beside a red one turns pink. Its captures see the lights, shadows and sky (not the
    probes' diffuse light), so light bounced off walls and floors reaches what they face;
    with ``bounces`` above 1 they see the grid too, so that light bounces again.

    - ``size``: the box (metres, world axes), centred on the entity's position; the grid's
      corner points lie on its corners.
    - ``points``: how many points along x, y and z (each 2 to ``MAX_VOLUME_AXIS_POINTS``, 16).
    - ``resolution``: texels across each capture's face (a power of two, 16 to 128).
    - ``near`` / ``far``: each capture's depth range.
    - ``blend_distance``: how far inside the box's walls the grid's weight falls to nothing
      (the sky's or the probes' light taking the rest); 0 (the default): a hard edge.
    - ``normal_bias``: metres each shaded point is moved along its surface's normal before
      the grid is read (Unity's normal bias): a floor reads the points above it rather than
      the layer under it, less light leaks through thin walls.
    - ``refresh``: ``once`` (the default: captured when it is made, and again whole when any
      field here changes or its entity moves), ``continuous`` (round and round the grid,
      ``points_per_frame`` a frame: light that moves, a sun that sets) or ``scripted``
      (only after ``request()``, its first bake too).  ``request()`` bakes any of them again,
      the grid lighting the scene meanwhile.
    - ``points_per_frame``: captures a frame (each six faces of the frame's view budget).
    - ``bounces`` (1 to ``MAX_VOLUME_BOUNCES``, 8; default 1): how many times the light the
      grid holds has bounced.  A bake is that many rounds of the whole grid, each one's
      captures lit by the grid as the round before left it (the first by the lights and the
      sky alone), as Unity's and Godot's bakers add bounces: a room lit through one window
      is lit in its far corners too.  The grid lights the scene from the first round on,
      brighter each round.  Raised after a bake, the rounds it lacks are added; lowered, it
      is baked again.  A ``continuous`` volume with ``bounces`` above 1 keeps lighting
      each round by the last, so its light settles to every bounce (as DDGI's does).

    The grid lights the scene once every point has been captured; until then the sky and
    the probes do. At most ``MAX_IRRADIANCE_VOLUMES`` (4) a world (a room each: a point takes
    the one weighing most there; the lowest entities', more said once and ignored).
    It dims the sky's reflection where it is darker than the sky (a room's floor does not
    mirror the daylight), as it does the probes' boxes.
    """

    size: Any = field(default_factory=lambda: glm.vec3(4.0, 3.0, 4.0))
    points: tuple[int, int, int] = (4, 3, 4)
    resolution: int = 32
    near: float = 0.05
    far: float = _DEFAULT_FAR
    blend_distance: float = 0.0
    normal_bias: float = 0.1
    refresh: str = "once"
    points_per_frame: int = 4
    bounces: int = 1

    @property
    def point_count(self) -> int:
        """Points in the grid."""
        x, y, z = self.points
        return x * y * z

    def _validate(self, name: str, value: Any) -> Any:
        if name in LAYER_FIELDS:
            return super()._validate(name, value)
        if name == "size":
            value = vec3(self, name, value, low=0.0)
            if min(value) <= 0.0 or max(value) > 1e5:
                raise ComponentValueError(f"IrradianceVolume.size must have every side in (0, 1e5] metres, "
                                          f"got {tuple(value)!r}")
            self._check_blend(self.__dict__.get("blend_distance"), value, name)
            return value
        if name == "points":
            parts = list(value) if isinstance(value, (list, tuple)) else []
            if len(parts) != 3:
                raise ComponentValueError(f"IrradianceVolume.points must be three ints (along x, y and z), "
                                          f"got {value!r}")
            return tuple(integer(self, name, v, low=2, high=MAX_VOLUME_AXIS_POINTS) for v in parts)
        if name == "resolution":
            return self._resolution(name, value, MIN_VOLUME_RESOLUTION, MAX_VOLUME_RESOLUTION)
        if name in ("near", "far"):
            return check_near_far(self, name, value, _DEFAULT_FAR)
        if name == "blend_distance":
            value = finite(self, name, value, low=0.0, high=1e5)
            self._check_blend(value, self.__dict__.get("size"), name)
            return value
        if name == "normal_bias":
            return finite(self, name, value, low=0.0, high=MAX_NORMAL_BIAS)
        if name == "refresh":
            return choice(self, name, value, VOLUME_REFRESH)
        if name == "points_per_frame":
            return integer(self, name, value, low=1, high=MAX_VOLUME_AXIS_POINTS ** 3)
        if name == "bounces":
            return integer(self, name, value, low=1, high=MAX_VOLUME_BOUNCES)
        return value
