"""Views as data: what a pass renders from (the main camera now; mirror, portal and cube-face
views later), and the std140 packing of the Camera and Lights uniform blocks."""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
from pyglm import glm

from components.limits import ALL_LAYERS, VIEW_DIRECT, VIEW_KINDS
from engine.rules.visibility_rules import KIND_MASK, visibility_code

CAMERA_BLOCK_BYTES = 4 * 64 + 4 * 16
# Float columns of a packed Camera block (View.camera_block; camera.glsl): view 0-15,
# proj 16-31, then these, then viewport and clip plane.
CAMERA_BLOCK_VIEW_PROJ = slice(32, 48)
CAMERA_BLOCK_INVERSE = slice(48, 64)
CAMERA_BLOCK_EYE = slice(64, 67)
CAMERA_BLOCK_CLIP = slice(72, 76)
CAMERA_BLOCK_IDS = slice(76, 80)   # uint32 skip, hide, view mask, node
NO_CLIP = glm.vec4(0.0, 0.0, 0.0, 1.0)
MAX_DIRECTIONAL_LIGHTS = 4
MAX_POINT_LIGHTS = 16
SKY_SH_COEFFICIENTS = 9  # the sky's irradiance coefficients (engine/render/irradiance.py)
LIGHTS_BLOCK_BYTES = 16 * SKY_SH_COEFFICIENTS + 16 + 2 * 16 * MAX_DIRECTIONAL_LIGHTS + 2 * 16 * MAX_POINT_LIGHTS


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
    _block: bytes | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def view_proj(self) -> glm.mat4:
        return self.proj * self.view

    @property
    def view_mask(self) -> int:
        """Its kinds and the layers it shows, packed as the shaders read them
        (``engine.rules.visibility_rules.visibility_code``)."""
        return visibility_code(self.kinds, self.layers)

    def camera_block(self) -> bytes:
        """The Camera uniform block of this view, packed once: a View is made for one pass
        and not changed after (the ReflectionSystem packs its views while the GPU is busy)."""
        if self._block is None:
            vp = self.view_proj
            w, h = self.size
            self._block = b"".join([
                self.view.to_bytes(), self.proj.to_bytes(), vp.to_bytes(), glm.inverse(vp).to_bytes(),
                glm.vec4(self.eye, 1.0).to_bytes(), glm.vec4(0.0, 0.0, w, h).to_bytes(), self.clip_plane.to_bytes(),
                glm.uvec4(self.skip, self.hide, self.view_mask, self.node).to_bytes(),
            ])
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
        return glm.mat4.from_bytes(self._block[0:64])

    @property
    def proj(self) -> glm.mat4:
        return glm.mat4.from_bytes(self._block[64:128])

    @property
    def view_proj(self) -> glm.mat4:
        return glm.mat4.from_bytes(self._block[128:192])

    @property
    def eye(self) -> glm.vec3:
        return glm.vec3.from_bytes(self._block[256:268])

    @property
    def kinds(self) -> int:
        return self.view_mask & KIND_MASK

    @property
    def layers(self) -> int:
        return self.view_mask >> VIEW_KINDS

    @property
    def view_mask(self) -> int:
        return int.from_bytes(self._block[312:316], "little")


def camera_view(world_matrix: glm.mat4, fov_y_deg: float, near: float, far: float,
                size: tuple[int, int], name: str = "main") -> View:
    """The view of a camera whose model-to-world matrix is ``world_matrix`` (looks down -Z).
    A matrix that mirrors (a camera under a parent with a negative scale: a negative
    determinant) has its X axis turned back first, as game engines' cameras ignore a
    mirroring in their transform: the camera looks the same way with the same up, its
    image is not mirrored and its front faces wind as any view's (else every face would be
    culled as a back face: no floor, no mirror)."""
    w, h = size
    proj = glm.perspective(glm.radians(fov_y_deg), w / max(h, 1), near, far)
    if glm.determinant(glm.mat3(world_matrix)) < 0.0:
        world_matrix = world_matrix * glm.scale(glm.vec3(-1.0, 1.0, 1.0))
    return View(view=glm.inverse(world_matrix), proj=proj, eye=glm.vec3(world_matrix[3]), size=size, name=name)


def lights_block(sky_sh: Sequence[Sequence[float]] | np.ndarray, directional: list[tuple],
                 point: list[tuple]) -> bytes:
    """Pack the Lights block (shaders/include/lights.glsl, std140): ``sky_sh`` the sky's nine
    irradiance coefficients (9, 3) (``engine.render.irradiance``), directional =
    [(direction, rgb)], point = [(position, range, rgb)]."""
    data = np.zeros(LIGHTS_BLOCK_BYTES // 4, np.float32)
    sh = np.asarray(sky_sh, np.float64)
    if sh.shape != (SKY_SH_COEFFICIENTS, 3):
        raise ValueError(f"lights_block: sky_sh must be {SKY_SH_COEFFICIENTS} RGB coefficients, got shape {sh.shape}")
    data[0:4 * SKY_SH_COEFFICIENTS].reshape(SKY_SH_COEFFICIENTS, 4)[:, :3] = sh
    base = 4 * SKY_SH_COEFFICIENTS
    counts = np.array([min(len(directional), MAX_DIRECTIONAL_LIGHTS), min(len(point), MAX_POINT_LIGHTS), 0, 0],
                      np.int32)
    data[base:base + 4] = counts.view(np.float32)
    base += 4
    for i, (direction, rgb) in enumerate(directional[:MAX_DIRECTIONAL_LIGHTS]):
        data[base + 4 * i: base + 4 * i + 3] = direction
        data[base + 4 * (MAX_DIRECTIONAL_LIGHTS + i): base + 4 * (MAX_DIRECTIONAL_LIGHTS + i) + 3] = rgb
    base += 8 * MAX_DIRECTIONAL_LIGHTS
    for i, (position, light_range, rgb) in enumerate(point[:MAX_POINT_LIGHTS]):
        data[base + 4 * i: base + 4 * i + 4] = (*position, light_range)
        data[base + 4 * (MAX_POINT_LIGHTS + i): base + 4 * (MAX_POINT_LIGHTS + i) + 3] = rgb
    return data.tobytes()


def union_rect(rects: Iterable[tuple[int, int, int, int]]) -> tuple[int, int, int, int]:
    """The smallest (x, y, width, height) rectangle holding all of ``rects``."""
    rects = list(rects)
    x0 = min(r[0] for r in rects)
    y0 = min(r[1] for r in rects)
    x1 = max(r[0] + r[2] for r in rects)
    y1 = max(r[1] + r[3] for r in rects)
    return x0, y0, x1 - x0, y1 - y0
