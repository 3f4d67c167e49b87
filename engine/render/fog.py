"""The Fog uniform block (``shaders/include/fog.glsl``): the active camera's ``Fog``
(``components/fog.py``; a monitor's camera's own while its picture is drawn: ``camera_fog``)
and the local ``FogVolume``s, written when they change, bound for every pass that fogs
(scene passes, the sky, the composites, particles, the light shafts).

The scene, sky and composite programs fog only in their ``FOG`` builds (``defines``: while
the fog has a density or a volume stands; ``FOG_FALLOFF`` and ``FOG_GLOW`` add the height
falloff's and the sun glow's terms where it has them, ``FOG_VOLUMES`` the volumes' integrals,
its value how many, ``FOG_WATER`` a water's body among them: the light to each point dimmed
through it too, ``FOG_TINTED`` a water whose ``absorption`` takes its channels apart: each
optical depth a colour), so a frame without fog runs none of it: llvmpipe runs the fog's
exponentials for every pixel a program draws (read on every sky pixel, they made the
640x360 mirror ring's frame 1.03x dearer with no fog at all).

A volume is an ellipsoid: the block holds the matrix that takes a world point into its unit
ball (``volume_to_unit``) and its colour and density at the centre; the shader integrates its
density, falling as 1 - r^2, along each stretch in closed form.  A water's body
(``Water.fog_density``) is a box of one density in a volume's row, its density negated
(``water_body_row``): the length of each stretch inside it, times its density.  Each row
carries its channels' shares of its density too (``volume_absorption``: a water's
``Water.absorption``, a volume's 1 in each), so a stretch's optical depth is a colour: what
is seen through water keeps more blue than red, and so does the light coming down through it.
"""
from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager

import moderngl
import numpy as np
from pyglm import glm

from components import DirectionalLight
from components.fog import Fog, FogVolume
from components.limits import MAX_FOG_VOLUMES
from components.tracking import raw_field
from engine.render.bindings import FOG_BINDING, bind_uniform_block

# Four vec4s (colour and sky share; density, falloff, base height; the sun's direction (towards
# it); its light x the sun scatter), then per volume its matrix, its colour and density, and
# its channels' shares of that density (each an array of its own in the block).
FOG_BLOCK_BYTES = 64 + (64 + 16 + 16) * MAX_FOG_VOLUMES
ROW_FLOATS = 24  # a volume's row: its matrix (16), colour and density (4), channels' shares (4)
_EVERY_CHANNEL = (1.0, 1.0, 1.0, 0.0)  # a FogVolume's shares: its density in every channel alike
_NO_FOG = (0.0,) * 16


def volume_to_unit(volume: FogVolume, world: glm.mat4) -> np.ndarray:
    """The matrix (4 x 4 float32, GL's column order flattened) that takes a world point into
    ``volume``'s unit ball: its entity's rotation and position (``world``: its world matrix,
    whose scale is left out), its ``size`` the ball's diameters."""
    m = np.array(world.to_list(), np.float64).T   # rows: glm's lists are its columns
    axes = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0)
    half = np.array(volume.size, np.float64) / 2.0
    to_unit = np.eye(4)
    to_unit[:3, :3] = (axes / half).T            # row k: axis k over its half side
    to_unit[:3, 3] = -to_unit[:3, :3] @ m[:3, 3]
    return to_unit.T.astype(np.float32).ravel()   # (GL's columns)


def volume_rows(volumes: Sequence[tuple[FogVolume, glm.mat4]]) -> tuple[float, ...]:
    """The block's rows of ``volumes`` (each with its entity's world matrix; those with no
    density left out): per volume its ``volume_to_unit`` matrix, then its colour and density,
    then its channels' shares (1 each: mist takes every colour alike), ``ROW_FLOATS`` floats."""
    return tuple(float(v) for volume, world in volumes if volume.density > 0.0 for v in (
        *volume_to_unit(volume, world), volume.color.x, volume.color.y, volume.color.z, volume.density,
        *_EVERY_CHANNEL))


def box_to_unit(top: np.ndarray, down: glm.vec3, depth: float) -> np.ndarray:
    """The matrix (as ``volume_to_unit``'s) that takes a world point into the cube [-1, 1]^3
    of a water's body (``components.Water``): the box under its outline ``top`` (4 world
    corners, homogeneous rows in 2 x 2 grid order), ``depth`` metres along the unit ``down``."""
    corners = np.asarray(top, np.float64)[:, :3]
    half_u = (corners[2] - corners[0]) / 2.0
    half_v = (corners[1] - corners[0]) / 2.0
    half_w = np.array(tuple(down), np.float64) * depth / 2.0
    centre = corners.mean(axis=0) + half_w
    to_unit = np.eye(4)
    to_unit[:3, :3] = np.linalg.inv(np.column_stack((half_u, half_v, half_w)))
    to_unit[:3, 3] = -to_unit[:3, :3] @ centre
    return to_unit.T.astype(np.float32).ravel()   # (GL's columns)


def water_body_row(top: np.ndarray, down: glm.vec3, depth: float, color: glm.vec4, density: float,
                   absorption: tuple[float, float, float] = (1.0, 1.0, 1.0)) -> tuple[float, ...]:
    """A water body's row of the block, ``ROW_FLOATS`` floats as a volume's: its
    ``box_to_unit`` matrix, its colour and its density negated (fog.glsl: a box of that
    density throughout, not a ball falling off), and each channel's share of the density
    (``Water.absorption``)."""
    return (*(float(v) for v in box_to_unit(top, down, depth)), float(color.x), float(color.y), float(color.z),
            -float(density), *(float(share) for share in absorption), 0.0)


def _fog_values(fog: Fog | None, sun: DirectionalLight | None, tint: tuple[float, float, float]) -> tuple[float, ...]:
    """The block's first rows for a camera's ``fog`` (``FogBlock.set``): its colour, density,
    falloff and the sun glow's direction and light."""
    if fog is None or fog.density <= 0.0:
        return _NO_FOG
    glow = (0.0,) * 8
    if sun is not None and fog.sun_scatter > 0.0:
        color = raw_field(sun, "color")
        k = sun.intensity * fog.sun_scatter
        glow = (-sun.direction.x, -sun.direction.y, -sun.direction.z, 0.0,
                color.x * k * tint[0], color.y * k * tint[1], color.z * k * tint[2], 0.0)
    return (fog.color.x, fog.color.y, fog.color.z, fog.sky_affect, fog.density, fog.height_falloff,
            fog.height, fog.aerial_perspective, *glow)


class FogBlock:
    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self._values = _NO_FOG
        self._volumes: tuple[float, ...] = ()
        self.ubo = ctx.buffer(np.zeros(FOG_BLOCK_BYTES // 4, np.float32).tobytes())
        bind_uniform_block(ctx, self.ubo, FOG_BINDING)   # (through the record: each pass binds it again, bind)
        self.defines: tuple[tuple[str, str], ...] = ()
        self.shown = True   # the frame draws a camera's Fog (the overlay's toggle: the prepare stage's)

    def set(self, fog: Fog | None, sun: DirectionalLight | None = None, rows: tuple[float, ...] = (),
            tint: tuple[float, float, float] = (1.0, 1.0, 1.0)) -> bool:
        """Write ``fog`` (None: no fog), glowing towards ``sun`` (the sun or the moon, whichever
        lights the air: ``sky.air_light``; its colour times ``tint``, an atmosphere's share of
        it) by its ``sun_scatter``, and the fog
        volumes' ``rows`` (``volume_rows``; at most ``MAX_FOG_VOLUMES``: the caller chose them)
        into the block where it differs from what it holds; True when it did (every view's
        fogged pixels change).  Compared as plain floats: the prepare stage asks every frame."""
        if len(rows) > ROW_FLOATS * MAX_FOG_VOLUMES:
            raise ValueError(f"{len(rows) // ROW_FLOATS} fog volumes: the block holds {MAX_FOG_VOLUMES}")
        return self._write(_fog_values(fog, sun, tint), rows)

    @contextmanager
    def camera_fog(self, fog: Fog | None, sun: DirectionalLight | None = None,
                   tint: tuple[float, float, float] = (1.0, 1.0, 1.0)) -> Iterator[None]:
        """Within the block, ``fog`` (another camera's own: a monitor's) in place of the frame's,
        glowing towards ``sun`` as ``set`` says, the fog volumes as they are; the frame's given
        back after (the block written twice where they differ, not at all where not)."""
        values, volumes = self._values, self._volumes
        self._write(_fog_values(fog, sun, tint), volumes)
        try:
            yield
        finally:
            self._write(values, volumes)

    def _write(self, values: tuple[float, ...], rows: tuple[float, ...]) -> bool:
        """Write the camera's ``values`` and the volumes' ``rows`` where they differ from what the
        block holds, and the builds they need (``defines``); True when it did."""
        count = len(rows) // ROW_FLOATS
        if values == self._values and rows == self._volumes:
            return False
        self._values, self._volumes = values, rows
        block = np.zeros(FOG_BLOCK_BYTES // 4, np.float32)
        block[:16] = values
        matrices = np.array(rows, np.float32).reshape(-1, ROW_FLOATS)
        block[16:16 + 16 * count] = matrices[:, :16].ravel()
        at = 16 + 16 * MAX_FOG_VOLUMES
        block[at:at + 4 * count] = matrices[:, 16:20].ravel()
        at += 4 * MAX_FOG_VOLUMES
        block[at:at + 4 * count] = matrices[:, 20:24].ravel()
        self.ubo.write(block.tobytes())
        starts = range(0, len(rows), ROW_FLOATS)
        self.defines = () if values[4] <= 0.0 and not count else tuple((name, value) for name, value, on in (
            ("FOG", "1", True), ("FOG_FALLOFF", "1", values[5] > 0.0), ("FOG_GLOW", "1", any(values[12:15])),
            ("FOG_AERIAL", "1", values[4] > 0.0 and values[7] > 0.0),
            ("FOG_VOLUMES", str(count), bool(count)),
            ("FOG_WATER", "1", any(rows[at + 19] < 0.0 for at in starts)),
            ("FOG_TINTED", "1", any(rows[at + 20:at + 23] != _EVERY_CHANNEL[:3] for at in starts))) if on)
        return True

    @property
    def volume_count(self) -> int:
        """The FogVolumes the block holds (with a density)."""
        return len(self._volumes) // ROW_FLOATS

    @property
    def block(self) -> tuple[float, ...]:
        """What the block holds (what a probe face drawn through it is kept for)."""
        return self._values + self._volumes

    def bind(self) -> None:
        bind_uniform_block(self.ctx, self.ubo, FOG_BINDING)

    def release(self) -> None:
        self.ubo.release()
