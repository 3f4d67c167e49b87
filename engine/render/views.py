"""Views as data: what a pass renders from (the main camera, each mirror and portal view of a
view tree, each face of a probe, a light's shadow camera), and the std140 packing of the
Camera and Lights uniform blocks.

A ``View`` is view and projection, eye, size, clip plane, scissor, its node in its tree, the
entity it never draws (``skip``: the surface it looks out of) and the one no view of its
tree draws (``hide``: a probe's own object, inherited down the tree), and its kinds and
layers: direct, mirror, portal or probe, and the reflection layers every surface of its
chain shows (``view_mask``)."""
from __future__ import annotations

import math
import struct
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
from pyglm import glm

from components.limits import (
    ALL_LAYERS,
    MAX_IRRADIANCE_VOLUMES,
    MAX_RECT_LIGHTS,
    MAX_SHADOW_CASCADES,
    MAX_VOLUME_AXIS_POINTS,
    VIEW_DIRECT,
    VIEW_KINDS,
)
from components.visibility import KIND_MASK, visibility_code
from engine.render.environment_brdf import ENVIRONMENT_BRDF_SIZE
from engine.render.ltc_fit import LTC_SIZE
from engine.rules.light_rules import NO_COOKIE

# The Camera uniform block (shaders/include/camera.glsl, std140), the one schema of every
# writer (View.camera_block, the planner's packed blocks) and reader (PlannedView, the
# composite rows, the batched Views block); tests/test_rendering.py checks the GLSL block
# against it (names, order, std140 offsets).  Matrices are column-major, as GL reads them.
CAMERA_DTYPE = np.dtype([
    ("view", "<f4", (16,)),
    ("proj", "<f4", (16,)),
    ("view_proj", "<f4", (16,)),
    ("inv_view_proj", "<f4", (16,)),
    ("eye", "<f4", (4,)),          # xyz: the eye, w: 1
    ("viewport", "<f4", (4,)),     # 0, 0, width, height
    ("clip_plane", "<f4", (4,)),   # world space
    ("skip", "<u4", (4,)),         # CAMERA_IDS
])
CAMERA_BLOCK_BYTES = CAMERA_DTYPE.itemsize
# What each component of the block's uvec4 ``skip`` holds, in order: the entity the view never
# draws (the surface it looks out of), one no view of its tree draws (a probe's own object),
# the view's mask (View.view_mask) and its index in its tree (View.node).
CAMERA_IDS = ("skip", "hide", "view_mask", "node")


def field_columns(dtype: np.dtype, unit: int) -> dict[str, slice]:
    """Each field of a packed record ``dtype`` as the slice of its columns in an array of
    ``unit``-byte scalars (4: a float32 view of a Camera block; 8: LevelRows' float64s)."""
    return {name: slice(dtype.fields[name][1] // unit, (dtype.fields[name][1] + dtype.fields[name][0].itemsize) // unit)
            for name in dtype.names}


CAMERA_FLOATS = field_columns(CAMERA_DTYPE, 4)  # each field's float32 columns
CAMERA_BYTES = field_columns(CAMERA_DTYPE, 1)   # each field's bytes
CAMERA_BLOCK_VIEW_PROJ = CAMERA_FLOATS["view_proj"]
CAMERA_BLOCK_INVERSE = CAMERA_FLOATS["inv_view_proj"]
CAMERA_BLOCK_EYE = slice(CAMERA_FLOATS["eye"].start, CAMERA_FLOATS["eye"].start + 3)  # xyz
CAMERA_BLOCK_CLIP = CAMERA_FLOATS["clip_plane"]
_VIEW_MASK_BYTES = slice(CAMERA_BYTES["skip"].start + 4 * CAMERA_IDS.index("view_mask"),
                         CAMERA_BYTES["skip"].start + 4 * CAMERA_IDS.index("view_mask") + 4)
CAMERA_EYE_BYTES = slice(CAMERA_BYTES["eye"].start, CAMERA_BYTES["eye"].start + 12)  # xyz
NO_CLIP = glm.vec4(0.0, 0.0, 0.0, 1.0)
# The shaders' array sizes (the shader library makes them defines): lights, point lights that
# cast shadows (engine/render/shadows.py), probes whose irradiance the scene blends
# (engine/render/irradiance.py).
MAX_DIRECTIONAL_LIGHTS = 4
MAX_POINT_LIGHTS = 16
MAX_POINT_SHADOWS = 2  # cube samplers in shaders/include/shadows.glsl
MAX_SHADOW_RINGS = MAX_SHADOW_CASCADES - 1  # a sun's cascades about the camera besides its level map
MAX_IRRADIANCE_PROBES = 32   # influence boxes the shader blends from (more: the first captured hold rows, a warning)
# The irradiance table's rows (engine/render/irradiance.py): the probes', the environment
# BRDF's, then from here the LTC table's of rectangle lights (shaders/include/rect_lights.glsl),
# then the irradiance volumes' tiles (VOLUME_ROW, a slot of VOLUME_SLOT_ROWS a volume: tile
# (c, y) holds coefficient c of the grid's layer y, x across and z down, at columns c x
# points-along-x, rows y x points-along-z of its slot; so its texels are read by bilinear
# filtering across x and z, shaders/include/ambient.glsl).
LTC_ROW = MAX_IRRADIANCE_PROBES + ENVIRONMENT_BRDF_SIZE
VOLUME_ROW = LTC_ROW + 2 * LTC_SIZE
VOLUME_SLOT_ROWS = MAX_VOLUME_AXIS_POINTS * MAX_VOLUME_AXIS_POINTS
VOLUME_ROWS = MAX_IRRADIANCE_VOLUMES * VOLUME_SLOT_ROWS
SKY_SH_COEFFICIENTS = 9  # the sky's irradiance coefficients (engine/render/irradiance.py)
LIGHTS_BLOCK_BYTES = 16 * SKY_SH_COEFFICIENTS + 16 + 2 * 16 * MAX_DIRECTIONAL_LIGHTS + 7 * 16 * MAX_POINT_LIGHTS \
    + 4 * MAX_RECT_LIGHTS


@dataclass
class View:
    """A camera pose and projection for one pass.

    ``clip_plane`` (world space) discards what lies behind it through gl_ClipDistance;
    ``mirrored`` views wind front faces clockwise; ``scissor`` limits the pass to the
    pixels that can show it; ``node`` is the index written to the level's node image.
    """

    view: glm.mat4
    proj: glm.mat4
    eye: glm.vec3
    size: tuple[int, int]
    name: str = "main"
    clip_plane: glm.vec4 = field(default_factory=lambda: glm.vec4(NO_CLIP))
    mirrored: bool = False
    scissor: tuple[int, int, int, int] | None = None
    node: int = 0
    skip: int = 0
    hide: int = 0  # an entity no view of the tree draws (a probe's own object), whatever surface it looks out of
    kinds: int = VIEW_DIRECT     # the kinds of view it is (components/limits.py): an entity hidden in one is not drawn
    layers: int = ALL_LAYERS     # the reflection layers it shows
    jitter: tuple[float, float] = (0.0, 0.0)  # its projection's sub-pixel offset (temporal AA: temporal_aa.jittered)
    _block: bytes | None = field(default=None, init=False, repr=False, compare=False)
    _views_row: bytes | None = field(default=None, init=False, repr=False, compare=False)  # (batched_mirrors.views_row)

    @property
    def view_proj(self) -> glm.mat4:
        return self.proj * self.view

    @property
    def steady_view_proj(self) -> glm.mat4:
        """Its view-projection without its sub-pixel offset (``jitter``): what motion from frame to
        frame is measured by (temporal AA, motion blur), the offsets' own steps left out."""
        if self.jitter == (0.0, 0.0):
            return self.view_proj
        return glm.translate(glm.vec3(-self.jitter[0], -self.jitter[1], 0.0)) * self.view_proj

    @property
    def parallel(self) -> bool:
        """Whether it is orthographic (its rays parallel: Camera.projection "orthographic", and
        its mirror and portal views): its projection's fourth row is 0, 0, 0, 1."""
        proj = self.proj
        return proj[0][3] == 0.0 and proj[1][3] == 0.0 and proj[2][3] == 0.0

    @property
    def axis(self) -> glm.vec3:
        """An orthographic view's axis (unit, its camera's +Z: the way behind it), along which
        its parallel rays run; zero for a perspective view (``shaders/include/view_axis.glsl``'s
        ``view_axis``, whose sign the rays' starts do not depend on)."""
        if not self.parallel:
            return glm.vec3(0.0)
        return glm.normalize(glm.vec3(self.view[0][2], self.view[1][2], self.view[2][2]))

    @property
    def sorting_eye(self) -> glm.vec3:
        """Where the transparent slot's order (and the unlit mirrors' cover) is measured from:
        its eye, or, for an orthographic view, a point ``PARALLEL_SORT_DISTANCE`` back along its
        axis (its rays are parallel: what lies farther along the axis is behind, whatever its
        offset across it, as from a far eye)."""
        if not self.parallel:
            return self.eye
        return self.eye + self.axis * PARALLEL_SORT_DISTANCE

    @property
    def view_mask(self) -> int:
        """Its kinds and the layers it shows, packed as the shaders read them
        (``engine.rules.visibility_rules.visibility_code``)."""
        return visibility_code(self.kinds, self.layers)

    def camera_block(self) -> bytes:
        """The Camera uniform block of this view (``CAMERA_DTYPE``), packed once: a View is
        made for one pass and not changed after (the ReflectionSystem packs its views while
        the GPU is busy).  Joined bytes, in the dtype's order: cheaper than a record's fields."""
        if self._block is None:
            vp = self.view_proj
            w, h = self.size
            parts = {"view": self.view.to_bytes(), "proj": self.proj.to_bytes(), "view_proj": vp.to_bytes(),
                     "inv_view_proj": glm.inverse(vp).to_bytes(), "eye": glm.vec4(self.eye, 1.0).to_bytes(),
                     "viewport": glm.vec4(0.0, 0.0, w, h).to_bytes(), "clip_plane": self.clip_plane.to_bytes(),
                     "skip": glm.uvec4(self.skip, self.hide, self.view_mask, self.node).to_bytes()}  # CAMERA_IDS
            self._block = b"".join([parts[name] for name in CAMERA_DTYPE.names])
        return self._block


class PlannedView(View):
    """A mirror or portal view planned in arrays (``engine.render.view_plan``): its Camera
    block comes packed, and its matrices and eye are read back from the block only when
    something asks (the per-view passes read the block; the batched path packs its row).
    Made for one pass, like every View, and not changed after."""

    def __init__(self, block: bytes, size: tuple[int, int], kind: str, entity: int,
                 clip_plane: glm.vec4, mirrored: bool, scissor: tuple[int, int, int, int], node: int,
                 skip: int, hide: int) -> None:
        self._block = block
        self.size = size
        self._kind, self._entity = kind, entity
        self.clip_plane = clip_plane
        self.mirrored = mirrored
        self.scissor = scissor
        self.node = node
        self.skip = skip
        self.hide = hide

    @property
    def name(self) -> str:
        return f"{self._kind} {self._entity}"

    @property
    def view(self) -> glm.mat4:
        return glm.mat4.from_bytes(self._block[CAMERA_BYTES["view"]])

    @property
    def proj(self) -> glm.mat4:
        return glm.mat4.from_bytes(self._block[CAMERA_BYTES["proj"]])

    @property
    def view_proj(self) -> glm.mat4:
        return glm.mat4.from_bytes(self._block[CAMERA_BYTES["view_proj"]])

    @property
    def eye(self) -> glm.vec3:
        return glm.vec3.from_bytes(self._block[CAMERA_EYE_BYTES])

    @property
    def kinds(self) -> int:
        return self.view_mask & KIND_MASK

    @property
    def layers(self) -> int:
        return self.view_mask >> VIEW_KINDS

    @property
    def view_mask(self) -> int:
        return int.from_bytes(self._block[_VIEW_MASK_BYTES], "little")


_VIEW_COLUMN = struct.Struct("<3f")   # the view matrix's first column's xyz, at the block's start
_FLOAT = struct.Struct("<f")
_UINT = struct.Struct("<I")


def way_scale(view: View) -> float:
    """How long a metre of ``view``'s world is in its tree root's (the light's way, depth of
    field's distance: shaders/include/view_axis.glsl way_scale, the same rule): its view
    matrix's first column's length, read from its Camera block: 1 / k beyond a pair of
    portals k times as large on the way out, 1 through mirrors."""
    x, y, z = _VIEW_COLUMN.unpack_from(view.camera_block(), CAMERA_BYTES["view"].start)
    return math.sqrt(x * x + y * y + z * z)


def way_scale_bits(view: View) -> int:
    """``way_scale`` as a float32's bits, 0 where it is 1 within a float32's step (a row that
    holds 0 takes a metre a metre: mirror_composite.vert's fallbacks)."""
    scale = way_scale(view)
    return 0 if abs(scale - 1.0) < 1e-6 else _UINT.unpack(_FLOAT.pack(scale))[0]


# How far back along an orthographic view's axis its transparent things are ordered from
# (View.sorting_eye): objects a metre apart in depth order right up to about 200 m across it.
PARALLEL_SORT_DISTANCE = 1.0e4


def camera_view(world_matrix: glm.mat4, fov_y_deg: float, near: float, far: float,
                size: tuple[int, int], name: str = "main", ortho_height: float | None = None,
                aspect: float | None = None) -> View:
    """The view of a camera whose model-to-world matrix is ``world_matrix`` (looks down -Z).
    A matrix that mirrors (a camera under a parent with a negative scale: a negative
    determinant) has its X axis turned back first, as game engines' cameras ignore a
    mirroring in their transform: the camera looks the same way with the same up, its
    image is not mirrored and its front faces wind as any view's (else every face would be
    culled as a back face: no floor, no mirror).  ``aspect``: the width over the height the
    picture is shown at, where it is not ``size``'s (drawn at a render scale, rounded)."""
    w, h = size
    aspect = aspect if aspect is not None else w / max(h, 1)
    if ortho_height is None:
        proj = glm.perspective(glm.radians(fov_y_deg), aspect, near, far)
    else:  # an orthographic camera: ortho_height world units top to bottom, parallel rays
        half_h = ortho_height / 2.0
        half_w = half_h * aspect
        proj = glm.ortho(-half_w, half_w, -half_h, half_h, near, far)
    if glm.determinant(glm.mat3(world_matrix)) < 0.0:
        world_matrix = world_matrix * glm.scale(glm.vec3(-1.0, 1.0, 1.0))
    return View(view=glm.inverse(world_matrix), proj=proj, eye=glm.vec3(world_matrix[3]), size=size, name=name)


def lights_block(sky_sh: Sequence[Sequence[float]] | np.ndarray, directional: list[tuple],
                 point: list[tuple], flat_sky: bool = False, environment: bool = True,
                 rect_slots: Sequence[int] = ()) -> bytes:
    """Pack the Lights block (shaders/include/lights.glsl, std140): ``sky_sh`` the sky's nine
    irradiance coefficients (9, 3) (``engine.render.irradiance``), directional =
    [(direction, rgb[, sun])] (``sun``: 1 for the brightest, whose light contact shadows dim,
    -1 for a moon, 0 for a fill light and when left out; a CloudLayer shades the first two),
    point = [(position, range, rgb, cone[, cookie[, radius[, contact[, rectangle]]]])]
    (``cone``: the spot cone, ``light_rules.spot_cone``; ``ALL_ROUND`` for a point light;
    ``cookie``: its two cookie rows, ``light_rules.lamp_cookie``, ``NO_COOKIE`` when left out;
    ``radius``: its sphere's, ``PointLight.radius``, 0 when left out; ``contact``: its contact
    shadows' channel + 1, ``ContactLamps``, 0 (none) when left out; ``rectangle``: its two
    rectangle rows, ``light_rules.lamp_rectangle``, ``NO_RECTANGLE`` when left out).  ``flat_sky``: the sky cube
    is the flat background of a world with no Skybox, not the light ``sky_sh`` holds (the
    environment's reflection then reads the harmonics: scene.frag environment_radiance).
    ``environment`` False: no surface reflects the light from all round by its material (the
    debug overlay's switch).  ``rect_slots``: the slots of the point lights lit as rectangles
    (at most ``MAX_RECT_LIGHTS``; the scene shader loops over them apart)."""
    data = np.zeros(LIGHTS_BLOCK_BYTES // 4, np.float32)
    sh = np.asarray(sky_sh, np.float64)
    if sh.shape != (SKY_SH_COEFFICIENTS, 3):
        raise ValueError(f"lights_block: sky_sh must be {SKY_SH_COEFFICIENTS} RGB coefficients, got shape {sh.shape}")
    data[0:4 * SKY_SH_COEFFICIENTS].reshape(SKY_SH_COEFFICIENTS, 4)[:, :3] = sh
    base = 4 * SKY_SH_COEFFICIENTS
    counts = np.array([min(len(directional), MAX_DIRECTIONAL_LIGHTS), min(len(point), MAX_POINT_LIGHTS),
                       int(flat_sky), int(environment)], np.int32)
    data[base:base + 4] = counts.view(np.float32)
    base += 4
    for i, (direction, rgb, *sun) in enumerate(directional[:MAX_DIRECTIONAL_LIGHTS]):
        data[base + 4 * i: base + 4 * i + 4] = (*direction, sun[0] if sun else 0.0)
        data[base + 4 * (MAX_DIRECTIONAL_LIGHTS + i): base + 4 * (MAX_DIRECTIONAL_LIGHTS + i) + 3] = rgb
    base += 8 * MAX_DIRECTIONAL_LIGHTS
    for i, (position, light_range, rgb, cone, *more) in enumerate(point[:MAX_POINT_LIGHTS]):
        cookie = more[:1]
        data[base + 4 * i: base + 4 * i + 4] = (*position, light_range)
        data[base + 4 * (MAX_POINT_LIGHTS + i): base + 4 * (MAX_POINT_LIGHTS + i) + 4] = \
            (*rgb, more[1] if len(more) > 1 else 0.0)
        data[base + 4 * (2 * MAX_POINT_LIGHTS + i): base + 4 * (2 * MAX_POINT_LIGHTS + i) + 4] = cone
        right, up = cookie[0] if cookie else NO_COOKIE
        data[base + 4 * (3 * MAX_POINT_LIGHTS + i): base + 4 * (3 * MAX_POINT_LIGHTS + i) + 4] = right
        data[base + 4 * (4 * MAX_POINT_LIGHTS + i): base + 4 * (4 * MAX_POINT_LIGHTS + i) + 3] = up[:3]
        data[base + 4 * (4 * MAX_POINT_LIGHTS + i) + 3] = more[2] if len(more) > 2 else 0.0
        if len(more) > 3:
            u, v = more[3]
            data[base + 4 * (5 * MAX_POINT_LIGHTS + i): base + 4 * (5 * MAX_POINT_LIGHTS + i) + 4] = u
            data[base + 4 * (6 * MAX_POINT_LIGHTS + i): base + 4 * (6 * MAX_POINT_LIGHTS + i) + 4] = v
    base += 4 * 7 * MAX_POINT_LIGHTS
    if len(rect_slots) > MAX_RECT_LIGHTS:
        raise ValueError(f"lights_block: at most {MAX_RECT_LIGHTS} rectangle slots, got {len(rect_slots)}")
    slots = np.full(MAX_RECT_LIGHTS, -1, np.int32)
    slots[:len(rect_slots)] = rect_slots
    data[base:base + MAX_RECT_LIGHTS] = slots.view(np.float32)
    return data.tobytes()


def union_rect(rects: Iterable[tuple[int, int, int, int]]) -> tuple[int, int, int, int]:
    """The smallest (x, y, width, height) rectangle holding all of ``rects``."""
    rects = list(rects)
    x0 = min(r[0] for r in rects)
    y0 = min(r[1] for r in rects)
    x1 = max(r[0] + r[2] for r in rects)
    y1 = max(r[1] + r[3] for r in rects)
    return x0, y0, x1 - x0, y1 - y0
