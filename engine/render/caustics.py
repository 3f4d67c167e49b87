"""Caustics under a water (``components.Water.caustics``): the uniform block and the normal
map the scene's ``CAUSTICS`` builds read (``shaders/include/caustics.glsl``, which says how
the light is gathered), and the rules of what they hold.

Only the batches whose world boxes reach into the water's body box (``reaches``, ``box``)
are drawn with the CAUSTICS builds: on llvmpipe every pixel of a build runs its caustics, on
the water or off it, behind a branch or not (measured: a build whose caustics return at once
cost as much as one that works them out), so a level with a pond pays only where the pond is.
A batch's box is the union of its rows', and one mesh's rows across a level (a hall's boxes)
span any pond in it; so the extract stage puts the rows that reach into the body of any
water that gathers the sun in batches of their own (``under_caustics``,
``BatchKey.under_caustics``), and only those are drawn with the builds (measured on the
sample level with caustics on its pond, 640x360 on llvmpipe: +24% a frame before, about +9% after).

One water at a time gathers the sun (``MAX_CAUSTIC_WATERS``: its normal map takes a sampler
of its own, the 19th of the fullest scene build): the prepare stage gives the block the
nearest the active camera of the waters that have caustics and waves (a normal map), and
says when others are left out.  A still water (no normal map) bends no light: it has none.
A context with fewer than ``CAUSTIC_SAMPLERS`` texture units in the fragment stage draws
none, said once (``GLLimitWarning``).

The waves move every frame, so while a water gathers the sun its block is written every
frame, and the views that show what is under it are drawn again (``Gpu.note_scene_change``);
a probe shows them as they were when it captured its faces.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import moderngl
import numpy as np
from pyglm import glm

from engine.assets.texture_data import TextureData
from engine.core.errors import GLLimitWarning
from engine.render.bindings import CAUSTIC_UNIT, CAUSTICS_BINDING, bind_texture, bind_uniform_block
from engine.render.spot_cookies import SCENE_SAMPLERS
from engine.resources import MirrorBumps

MAX_CAUSTIC_WATERS = 1      # waters whose caustics are drawn at once (the nearest the active camera)
CAUSTIC_SAMPLERS = SCENE_SAMPLERS + 3   # the fullest build with cookies, soft suns' depths and caustics
CAUSTIC_SUN_SPREAD = 0.0093  # radians: the sun's disc (0.53 degrees), how a caustic blurs with depth
_BLOCK_FLOATS = 28          # seven vec4s (caustics.glsl's Caustics block)
CAUSTICS_BLOCK_BYTES = 4 * _BLOCK_FLOATS


@dataclass(frozen=True, eq=False)
class CausticWater:
    """The water whose caustics the block holds: its entity, its normal map and the block's
    rows (``caustic_rows``)."""

    entity: int
    normal_map: TextureData
    rows: tuple[float, ...]
    box: tuple[tuple[float, float, float], tuple[float, float, float]]   # the body's world box (body_box)


def body_box(corners: np.ndarray, down: tuple[float, float, float],
             depth: float) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """The world box [lo, hi] of what a water can light: its surface's ``corners``
    (homogeneous rows) and the same ``depth`` metres along the unit ``down``."""
    top = np.asarray(corners, np.float64)[:, :3]
    ends = np.concatenate([top, top + np.asarray(down, np.float64) * depth])
    return tuple(ends.min(axis=0).tolist()), tuple(ends.max(axis=0).tolist())


Box = tuple[tuple[float, float, float], tuple[float, float, float]]   # a world box (lo, hi)


def placed_box(matrix: glm.mat4, lo: tuple[float, float, float], hi: tuple[float, float, float]) -> Box:
    """The world box of the model box [``lo``, ``hi``] placed by ``matrix`` (a glm mat4):
    along each world axis the translation plus, for each model axis, the lower (higher) of
    its two ends' terms (as ``InstanceBatch`` measures its rows)."""
    low, high = [], []
    for r in range(3):
        a = b = float(matrix[3][r])
        for c in range(3):
            m = float(matrix[c][r])
            p, q = m * lo[c], m * hi[c]
            a += p if p < q else q
            b += q if p < q else p
        low.append(a)
        high.append(b)
    return (low[0], low[1], low[2]), (high[0], high[1], high[2])


def under_caustics(box: Box, bodies: tuple[Box, ...]) -> bool:
    """Whether the world ``box`` reaches into any of ``bodies`` (the boxes of the waters that
    gather the sun: ``body_box``): a row drawn with the CAUSTICS builds (in a batch of its own,
    ``BatchKey.under_caustics``), so that a mesh's other rows across a level do not pay for them."""
    return any(reaches(box, body) for body in bodies)


def caustic_rows(plane: tuple[float, float, float, float], bumps: MirrorBumps, *, tiling: float, cross: float,
                 offset: tuple[float, float], ior: float, strength: float, depth: float) -> tuple[float, ...] | None:
    """The ``Caustics`` block (caustics.glsl) of a water: its top ``plane`` (normal up, out of
    the water), its mirror's UV rows, the surface's unit directions of +U and +V (each UV
    row's direction laid on the plane, as the composite's frame), the waves' layers
    (``tiling``, ``cross``, ``offset``, ``bumps.scale``), 1 / ``ior``, the ``strength``
    (``Water.caustics``), a map texel's size in metres along U, the body's ``depth`` and the
    sun's spread.  None where the UVs do not run along the surface (a row square to it: no
    frame to read the waves in)."""
    normal = np.array(plane[:3], np.float64)
    u_row, v_row = (np.asarray(row, np.float64) for row in bumps.uv_rows)
    flats = [row[:3] - np.dot(row[:3], normal) * normal for row in (u_row, v_row)]
    if min(float(np.linalg.norm(flat)) for flat in flats) < 1e-9:
        return None

    def along(row: np.ndarray) -> np.ndarray:
        flat = row[:3] - np.dot(row[:3], normal) * normal
        return flat / np.linalg.norm(flat)

    width = bumps.normal_map.size[0]
    texel = 1.0 / (width * tiling * float(np.linalg.norm(u_row[:3])))
    return tuple(float(v) for v in (*normal, plane[3], *u_row, *v_row, *along(u_row), cross, *along(v_row),
                                    bumps.scale, *offset, 1.0 / ior, strength, tiling, texel, depth,
                                    CAUSTIC_SUN_SPREAD))


class CausticBlock:
    """The ``Caustics`` uniform block on the GPU (bound once at ``CAUSTICS_BINDING``), written
    when its water's rows change, the ``CAUSTICS`` define while it holds one, and its normal
    map bound for each scene pass (``bind``)."""

    def __init__(self, ctx: moderngl.Context, texture_units: int) -> None:
        self.ctx = ctx
        self.ubo = ctx.buffer(reserve=CAUSTICS_BLOCK_BYTES)
        self.supported = texture_units >= CAUSTIC_SAMPLERS
        self.texture_units = texture_units
        self.water: CausticWater | None = None
        self._texture: moderngl.Texture | None = None
        self.defines: tuple[tuple[str, str], ...] = ()
        self._warned = False

    def set(self, water: CausticWater | None, texture: moderngl.Texture | None = None) -> bool:
        """Hold ``water`` (None: none) with ``texture``, its normal map on the GPU (None: not
        uploaded, so none drawn); True when what the scene shows changed."""
        if water is not None and not self.supported:
            if not self._warned:
                self._warned = True
                warnings.warn(GLLimitWarning(
                    f"Water on entity {water.entity}: caustics need {CAUSTIC_SAMPLERS} texture units in the fragment "
                    f"stage and this OpenGL has {self.texture_units} (GL_MAX_TEXTURE_IMAGE_UNITS): the water gathers "
                    "no light"), stacklevel=3)
            water = None
        if water is not None and texture is None:
            water = None
        self._texture = texture if water is not None else None
        old = self.water
        if water is None:
            self.water, self.defines = None, ()
            return old is not None
        self.water, self.defines = water, (("CAUSTICS", "1"),)
        if old is not None and old.rows == water.rows:
            return False
        self.ubo.write(np.array(water.rows, np.float32).tobytes())
        return True

    @property
    def box(self) -> tuple[tuple[float, float, float], tuple[float, float, float]] | None:
        """The world box of what the held water lights (None: none held): the batches that
        reach into it are drawn with the CAUSTICS builds (``reaches``), the rest without (on
        llvmpipe every pixel of a build pays for its caustics, on or off the water)."""
        return None if self.water is None else self.water.box

    def bind(self) -> None:
        """Bind the block and the water's normal map for a scene pass (while there is one):
        each pass, as another engine on the context binds its own block at the same point."""
        if self.water is not None:
            bind_uniform_block(self.ctx, self.ubo, CAUSTICS_BINDING)
            bind_texture(self.ctx, self._texture, CAUSTIC_UNIT)

    def release(self) -> None:
        self.ubo.release()
        self.water, self.defines, self._texture = None, (), None


def reaches(batch_box: tuple[np.ndarray, np.ndarray] | None,
            box: tuple[tuple[float, float, float], tuple[float, float, float]]) -> bool:
    """Whether a batch's world box (``InstanceBatch.box``; None: empty) overlaps ``box`` (a
    box not measured yet, NaN, counts as reaching it)."""
    if batch_box is None:
        return False
    (lx, ly, lz), (hx, hy, hz) = box
    lo, hi = batch_box
    return not (hi[0] < lx or hi[1] < ly or hi[2] < lz or lo[0] > hx or lo[1] > hy or lo[2] > hz)


def nearest(candidates: list[tuple[int, np.ndarray]], eye: np.ndarray) -> int:
    """The entity of ``candidates`` ((entity, outline corners) each) whose outline's centre is
    nearest ``eye``."""
    return min(candidates, key=lambda c: (float(np.linalg.norm(np.asarray(c[1], np.float64)[:, :3].mean(axis=0)
                                                               - eye)), c[0]))[0]

