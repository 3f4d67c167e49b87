"""Shore foam on waters (``components.Water.foam``): the uniform block the scene's ``FOAM``
builds read (``shaders/include/foam.glsl``, which says how the foam is laid), and the rules
of what it holds.

Foam lies on the surface, over the water's reflection and what is seen through it, so it is
drawn after them: once a view tree has composited a level's views into it, the scene pass
draws each foamy water's batch once more (``ScenePass.draw_foam``), with its ``FOAM``
build, blended over the level as glass is, lit as any surface is.  Where the foam lies needs
the depth of what is under each pixel of the surface: the level's window depth, copied first
(``RefractionCopy``: the water itself writes no depth, so the copy holds what lies below it).
A probe's faces are finished as a root is, with no view tree at ``depth`` 0
(``ProbeCaptures._finished``): they show the foam too.

Up to ``MAX_FOAM_WATERS`` waters have foam at once (the first by entity; the rest counted in
``RenderStats.foam_waters_cut`` and said once).  A draw's instances find their water by
entity (``foam_entities``), so waters of one mesh and material, one batch, each keep their
own foam."""
from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import moderngl
import numpy as np

from engine.core.errors import GLLimitWarning
from engine.render.bindings import FOAM_BINDING, bind_uniform_block
from engine.render.caustics import CAUSTIC_SAMPLERS, uv_axes
from engine.resources import MirrorBumps

MAX_FOAM_WATERS = 4   # waters whose foam is drawn at once (the block's arrays; foam_entities an uvec4)
FOAM_SAMPLERS = CAUSTIC_SAMPLERS + 1   # a water's fullest build (caustics under it too) and the level's copy
_ROWS = 5             # a water's vec4s in the block (foam.glsl's Foam block: one array each)
FOAM_BLOCK_BYTES = 4 * (4 * _ROWS * MAX_FOAM_WATERS + 4 + 4)   # the arrays, the entities, how many


@dataclass(frozen=True)
class FoamWater:
    """A water whose foam the block holds: its entity and its rows (``foam_rows``)."""

    entity: int
    rows: tuple[float, ...]


def foam_frame(plane: Sequence[float], bumps: MirrorBumps | None, offset: tuple[float, float],
               tiling: float) -> tuple[np.ndarray, np.ndarray, tuple[float, float]]:
    """Where a water's foam pattern lies on its ``plane``: two unit directions along the
    surface (its UVs' U and V laid on the plane, where it has a normal map: ``bumps``; else
    any two square to each other) and how far the pattern has drifted along them (the waves'
    ``offset`` in map tiles times a tile's metres along each: the pattern moves with the
    waves)."""
    normal = np.asarray(plane[:3], np.float64)
    axes = uv_axes(normal, bumps.uv_rows) if bumps is not None else None
    if axes is not None:   # (UVs running along the surface: their tiles have a size there)
        unit_u, unit_v, per_metre_u, per_metre_v = axes
        return unit_u, unit_v, (offset[0] / (tiling * per_metre_u), offset[1] / (tiling * per_metre_v))
    side = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    unit_u = np.cross(normal, side)
    unit_u /= np.linalg.norm(unit_u)
    return unit_u, np.cross(normal, unit_u), (0.0, 0.0)


def foam_rows(plane: Sequence[float], frame: tuple[np.ndarray, np.ndarray, tuple[float, float]],
              strength: float, depth: float, scale: float, colour: Sequence[float]) -> tuple[float, ...]:
    """A water's rows in the Foam block: its ``plane`` (its up normal and d), its pattern's
    ``frame`` (``foam_frame``: each direction with the drift along it), then ``strength``,
    1 / ``depth``, 1 / ``scale`` and the foam's ``colour``."""
    unit_u, unit_v, (drift_u, drift_v) = frame
    return (*(float(v) for v in plane), *(float(v) for v in unit_u), float(drift_u),
            *(float(v) for v in unit_v), float(drift_v),
            float(strength), 1.0 / depth, 1.0 / scale, 0.0, *(float(c) for c in tuple(colour)[:3]), 0.0)


class FoamBlock:
    """The ``Foam`` uniform block on the GPU (bound at ``FOAM_BINDING``: up to
    ``MAX_FOAM_WATERS`` waters' rows), written when a held water's rows change; the
    entities it holds (``entities``: which batches the foam pass draws)."""

    def __init__(self, ctx: moderngl.Context, texture_units: int) -> None:
        self.ctx = ctx
        self.ubo = ctx.buffer(reserve=FOAM_BLOCK_BYTES)
        self.waters: tuple[FoamWater, ...] = ()
        self.entities: frozenset[int] = frozenset()
        self.supported = texture_units >= FOAM_SAMPLERS
        self.texture_units = texture_units
        self._warned = False

    def set(self, waters: Sequence[FoamWater]) -> bool:
        """Hold ``waters`` (at most ``MAX_FOAM_WATERS``, a slot each in their order); True
        when what the scene shows changed.  A context with fewer than ``FOAM_SAMPLERS``
        fragment texture units holds none, said once."""
        if len(waters) > MAX_FOAM_WATERS:
            raise ValueError(f"{len(waters)} foamy waters given; the block holds {MAX_FOAM_WATERS}")
        if waters and not self.supported:
            if not self._warned:
                self._warned = True
                warnings.warn(GLLimitWarning(
                    f"Water on entity {waters[0].entity}: foam needs {FOAM_SAMPLERS} texture units in the fragment "
                    f"stage and this OpenGL has {self.texture_units} (GL_MAX_TEXTURE_IMAGE_UNITS): the water has "
                    "no foam"), stacklevel=3)
            waters = ()
        waters = tuple(waters)
        if waters == self.waters:
            return False
        self.waters = waters
        self.entities = frozenset(water.entity for water in waters)
        block = np.zeros((_ROWS, MAX_FOAM_WATERS, 4), np.float32)
        for slot, water in enumerate(waters):
            block[:, slot] = np.asarray(water.rows, np.float32).reshape(_ROWS, 4)
        entities = [water.entity for water in waters] + [0] * (MAX_FOAM_WATERS - len(waters))
        self.ubo.write(block.tobytes() + np.array(entities, np.uint32).tobytes()
                       + np.array([len(waters), 0, 0, 0], np.int32).tobytes())
        return True

    def bind(self) -> None:
        """Bind the block for the foam pass."""
        bind_uniform_block(self.ctx, self.ubo, FOAM_BINDING)

    def release(self) -> None:
        self.ubo.release()
        self.waters, self.entities = (), frozenset()
