"""Ripples on waters (``components.Ripples``): each rippling water's height field, simulated
on the GPU, and the uniform block the composites read its slopes through.

**The simulation.**  A water's surface height is the damped wave equation
h_tt + 2 damping h_t = speed^2 (h_xx + h_yy), stepped on a grid of texels about ``cell``
metres apart over the water's outline with the explicit leapfrog scheme (the height field of
interactive water in games since Tessendorf's "Interactive Water Surfaces"):
h' = h + (h - h_before) x keep + the sum over the outline's two edges of courant^2 x (the two
neighbours along it - 2h), where courant = speed x step / the texels' spacing along that
edge and keep = exp(-2 damping step); stable while the two courants' squares sum to at most
1, so a frame is taken in as many steps as keep each at most ``MAX_COURANT``.  At the
outline's edges the height beyond is the edge's own (the walls reflect the rings).
A drop pushes the height down by its depth over a disc (a raised cosine), in the frame's
first step.

**Where it lives.**  The waters' fields are tiles of one atlas of ``RIPPLE_TILE`` texels a
side each, two of them (the step reads one and writes the other), RG32F: the height now
and a step ago, in metres.  A step draws each awake tile's rectangle with
``shaders/ripple_step.frag``; a tile whose rings have died away (the ripple stage's account:
``systems/ripple_system.py``) is cleared in both and not drawn again until a drop wakes it.

**How it is seen.**  ``shaders/include/ripples.glsl``: the composites of water (a view's and
a fallback's, in ``RIPPLES`` builds while any tile is awake) find the water a point lies on
by its plane and outline in the ``Ripples`` block, read the height's slope there (central
differences of the filtered field) and tilt the water's normal by it (``defines``); the
scene's CAUSTICS builds, and the light shafts' march, tilt the normal their light crosses
the surface by the same way (``caustic_defines``: where the context has
``RIPPLE_CAUSTIC_SAMPLERS`` units)."""
from __future__ import annotations

import math
import struct
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass

import moderngl
import numpy as np

from engine.render.bindings import (
    RIPPLE_STEP_UNIT,
    RIPPLE_UNIT,
    RIPPLES_BINDING,
    PassState,
    apply_pass_state,
    bind_texture,
    bind_uniform_block,
)
from engine.render.foam import FOAM_SAMPLERS
from engine.render.shader_library import ShaderLibrary

RIPPLE_TILE = 256          # a water's field: at most this many texels a side (MAX_RIPPLE_TEXELS)
MAX_RIPPLE_TEXELS = RIPPLE_TILE
MAX_RIPPLE_WATERS = 4      # waters rippling at once: the atlas's 2 x 2 tiles
MAX_RIPPLE_DROPS = 32      # drops a water takes a frame (the step's uniform array); more are counted
MAX_COURANT = 0.5          # speed x step / cell at most (stable below 1 / sqrt(2))
MAX_RIPPLE_STEPS = 16      # steps a frame at most: past it the rings spread slower (said by the stage)
_ATLAS = 2 * RIPPLE_TILE
_ORIGINS = ((0, 0), (RIPPLE_TILE, 0), (0, RIPPLE_TILE), (RIPPLE_TILE, RIPPLE_TILE))
_ROWS = 5                  # a water's vec4s in the block (ripples.glsl's arrays)
RIPPLES_BLOCK_BYTES = 4 * (4 * _ROWS * MAX_RIPPLE_WATERS + 4)   # the arrays, then the count
_STEP = PassState()        # no depth test, no blending, no clip distances
# The composites' defines while a water's rings are alive (RippleAtlas.defines).
RIPPLE_DEFINES = (("RIPPLES", "1"), ("MAX_RIPPLE_WATERS", str(MAX_RIPPLE_WATERS)))
# The caustics gather the rings' light too where the fullest scene build (a water's caustics,
# its foam's copy) has one more texture unit for the heights (RippleAtlas.caustic_defines).
RIPPLE_CAUSTIC_SAMPLERS = FOAM_SAMPLERS + 1


@dataclass(frozen=True)
class RippleWater:
    """A rippling water as the atlas holds it: its entity, its plane (its top's normal and
    w), its outline's first corner and two edges (world), and its field's texels along each
    edge; ``strength`` scales the slopes the composite reads."""

    entity: int
    plane: tuple[float, float, float, float]
    origin: tuple[float, float, float]
    edge_u: tuple[float, float, float]
    edge_v: tuple[float, float, float]
    texels: tuple[int, int]
    strength: float = 1.0

    def texel_rows(self, tile: int) -> tuple[np.ndarray, np.ndarray]:
        """The two rows (x, y, z, w) taking a world point (x, y, z, 1) to its texel
        coordinates in the atlas, for the water in ``tile`` (texel i's centre at i + 0.5):
        along each edge, the share of the edge times its texels, from the tile's origin."""
        origin = np.asarray(self.origin, np.float64)
        rows = []
        for edge, count, start in zip((self.edge_u, self.edge_v), self.texels, _ORIGINS[tile], strict=True):
            edge = np.asarray(edge, np.float64)
            axis = edge * (count / float(edge @ edge))
            rows.append(np.array([*axis, start - axis @ origin]))
        return rows[0], rows[1]


def outline_edges(outline: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An outline's (``SurfaceState.outline``: 4 homogeneous world corners in 2 x 2 grid
    order) first corner and its two edges from it."""
    corners = np.asarray(outline, np.float64)[:, :3] / np.asarray(outline, np.float64)[:, 3:4]
    return corners[0], corners[1] - corners[0], corners[2] - corners[0]


def field_texels(edge_u: np.ndarray, edge_v: np.ndarray, cell: float) -> tuple[tuple[int, int], bool]:
    """The texels along each edge for points ``cell`` metres apart (at least 4), and whether
    a side had to be coarser than that (over ``MAX_RIPPLE_TEXELS``)."""
    wanted = [max(4, math.ceil(float(np.linalg.norm(edge)) / cell)) for edge in (edge_u, edge_v)]
    return (min(wanted[0], MAX_RIPPLE_TEXELS), min(wanted[1], MAX_RIPPLE_TEXELS)), max(wanted) > MAX_RIPPLE_TEXELS


class RippleAtlas:
    """The rippling waters' height fields (two RG32F atlases, made with the first water and
    released with the last), the step program, and the ``Ripples`` block (bound at
    ``RIPPLES_BINDING``).  ``defines``: the composite's ``RIPPLES`` builds while any tile is
    awake; ``version`` counts the frames stepped (what a still frame compares)."""

    def __init__(self, ctx: moderngl.Context, texture_units: int = RIPPLE_CAUSTIC_SAMPLERS) -> None:
        self.ctx = ctx
        # Whether the scene's caustics builds can read the heights too (RIPPLE_CAUSTIC_SAMPLERS).
        self.in_caustics = texture_units >= RIPPLE_CAUSTIC_SAMPLERS
        self.texture_units = texture_units
        self.caustic_defines: tuple[tuple[str, str], ...] = ()   # the CAUSTICS builds' (defines, when they can)
        self.waters: dict[int, tuple[int, RippleWater]] = {}   # entity -> (tile, water)
        self.awake: set[int] = set()                            # entities whose tiles are stepped
        self.defines: tuple[tuple[str, str], ...] = ()
        self.version = 0
        self.steps = 0          # steps drawn, over the atlas's life (tests count them)
        self._images: list[moderngl.Texture] = []
        self._targets: list[moderngl.Framebuffer] = []
        self._current = 0       # the image holding the latest heights
        self._ubo: moderngl.Buffer | None = None
        self._vao: moderngl.VertexArray | None = None
        self._program: moderngl.Program | None = None
        self._shaders: ShaderLibrary | None = None

    # -- the waters ------------------------------------------------------------------------

    def set(self, waters: Sequence[RippleWater], shaders: ShaderLibrary) -> None:
        """Hold ``waters`` (at most ``MAX_RIPPLE_WATERS``): one that stays with the same texels
        keeps its tile and its rings (a water that moves carries them along: the field lies in
        its outline's frame); one new, or whose texels changed, gets a cleared tile, asleep."""
        if len(waters) > MAX_RIPPLE_WATERS:
            raise ValueError(f"RippleAtlas.set: at most {MAX_RIPPLE_WATERS} waters, got {len(waters)}")
        self._shaders = shaders
        if not waters:
            self.release()
            return
        self._make()
        self._step_program()   # (built with the first water, not at its first drop)
        kept = {w.entity: self.waters[w.entity] for w in waters if w.entity in self.waters
                and self.waters[w.entity][1].texels == w.texels}
        free = [tile for tile in range(MAX_RIPPLE_WATERS) if tile not in {t for t, _ in kept.values()}]
        held: dict[int, tuple[int, RippleWater]] = {}
        for water in waters:
            if water.entity in kept:
                held[water.entity] = (kept[water.entity][0], water)
            else:
                tile = free.pop(0)
                held[water.entity] = (tile, water)
                self._clear(tile)
                self.awake.discard(water.entity)
        self.awake &= set(held)
        changed = held != self.waters
        self.waters = held
        if changed:
            self._write_block()
        self._say_awake()

    def tile_of(self, entity: int) -> int | None:
        held = self.waters.get(entity)
        return None if held is None else held[0]

    def to_texels(self, entity: int, points: np.ndarray) -> np.ndarray:
        """World points (n, 3) on ``entity``'s water as texel coordinates in its tile (0 at
        the tile's corner; texel i's centre at i + 0.5)."""
        tile, water = self.waters[entity]
        u, v = water.texel_rows(tile)
        points = np.atleast_2d(np.asarray(points, np.float64))
        ones = np.ones((len(points), 1))
        homogeneous = np.hstack([points, ones])
        return np.stack([homogeneous @ u - _ORIGINS[tile][0], homogeneous @ v - _ORIGINS[tile][1]], axis=1)

    def sleep(self, entity: int) -> None:
        """The water's rings have died away: its tile cleared and no longer stepped."""
        if entity in self.awake:
            self.awake.discard(entity)
            self._clear(self.waters[entity][0])
            self._say_awake()

    def wake(self, entity: int) -> None:
        if entity in self.waters and entity not in self.awake:
            self.awake.add(entity)
            self._say_awake()

    # -- a frame's steps ---------------------------------------------------------------------

    def step(self, rates: Mapping[int, tuple[float, float, float]],
             drops: Mapping[int, Sequence[tuple[float, ...]]], steps: int) -> None:
        """Move every awake water on by ``steps`` steps: ``rates`` gives each one's courant^2
        along each edge and keep (per step), ``drops`` its drops this frame (texel x, y in its tile, radius in
        texels, depth in metres: at most ``MAX_RIPPLE_DROPS``), pushed in at the first step."""
        if not self.awake or steps <= 0:
            return
        ctx = self.ctx
        program = self._step_program()
        for at in range(steps):
            source, target = self._images[self._current], self._targets[1 - self._current]
            target.use()
            bind_texture(ctx, source, RIPPLE_STEP_UNIT)
            for entity in sorted(self.awake):
                tile, water = self.waters[entity]
                nu, nv = water.texels
                x0, y0 = _ORIGINS[tile]
                program["tile"].value = (float(x0), float(y0), float(x0 + nu), float(y0 + nv))
                program["rates"].value = rates[entity]
                these = list(drops.get(entity, ()))[:MAX_RIPPLE_DROPS] if at == 0 else []
                program["drop_count"].value = len(these)
                if these:
                    rows = [(x + x0, y + y0, radius, depth) for x, y, radius, depth in these]
                    rows += [(0.0, 0.0, 0.0, 0.0)] * (MAX_RIPPLE_DROPS - len(rows))
                    program["drops"].write(struct.pack(f"<{4 * MAX_RIPPLE_DROPS}f", *(v for row in rows for v in row)))
                apply_pass_state(ctx, _STEP, (x0, y0, nu, nv))
                self._vao.render(moderngl.TRIANGLES, vertices=3)
            self._current = 1 - self._current
            self.steps += 1
        self.version += 1

    def bind(self) -> None:
        """The latest heights on ``RIPPLE_UNIT`` and the block on ``RIPPLES_BINDING`` (the
        composites' ``RIPPLES`` builds read them)."""
        if self._images:
            bind_texture(self.ctx, self._images[self._current], RIPPLE_UNIT)
            bind_uniform_block(self.ctx, self._ubo, RIPPLES_BINDING)

    def heights(self, entity: int) -> np.ndarray:
        """``entity``'s field as it stands, metres, rows along its outline's second edge
        (read back from the GPU: for tests and tools, not a frame's work)."""
        tile, water = self.waters[entity]
        nu, nv = water.texels
        x0, y0 = _ORIGINS[tile]
        data = self._images[self._current].read()
        field = np.frombuffer(data, np.float32).reshape(_ATLAS, _ATLAS, 2)
        return field[y0:y0 + nv, x0:x0 + nu, 0].copy()

    # -- GL objects ---------------------------------------------------------------------------

    def _make(self) -> None:
        if self._images:
            return
        ctx = self.ctx
        for _ in range(2):
            image = ctx.texture((_ATLAS, _ATLAS), 2, dtype="f4")
            image.filter = (moderngl.LINEAR, moderngl.LINEAR)
            image.repeat_x = image.repeat_y = False
            self._images.append(image)
            target = ctx.framebuffer([image])
            target.clear(0.0, 0.0, 0.0, 0.0)   # (a new texture's texels are undefined)
            self._targets.append(target)
        self._ubo = ctx.buffer(reserve=RIPPLES_BLOCK_BYTES)
        self._current = 0

    def _clear(self, tile: int) -> None:
        x0, y0 = _ORIGINS[tile]
        for target in self._targets:
            target.clear(0.0, 0.0, 0.0, 0.0, viewport=(x0, y0, RIPPLE_TILE, RIPPLE_TILE))

    def _step_program(self) -> moderngl.Program:
        program = self._shaders.program("fullscreen.vert", "ripple_step.frag",
                                        defines={"MAX_RIPPLE_DROPS": str(MAX_RIPPLE_DROPS)})
        if self._vao is None or self._program is not program:
            if self._vao is not None:
                self._vao.release()
            self._vao = self.ctx.vertex_array(program, [])
            self._program = program
            program["heights"].value = RIPPLE_STEP_UNIT
        return program

    def _write_block(self) -> None:
        rows = np.zeros((_ROWS, MAX_RIPPLE_WATERS, 4), np.float32)
        for slot, (tile, water) in enumerate(sorted(self.waters.values(), key=lambda held: held[0])):
            u, v = water.texel_rows(tile)
            x0, y0 = _ORIGINS[tile]
            nu, nv = water.texels
            rows[0, slot], rows[1, slot], rows[2, slot] = u, v, water.plane
            rows[3, slot] = (x0, y0, x0 + nu, y0 + nv)
            rows[4, slot] = (water.strength, 0.0, 0.0, 0.0)
        self._ubo.write(rows.tobytes() + struct.pack("<4i", len(self.waters), 0, 0, 0))

    def _say_awake(self) -> None:
        self.defines = RIPPLE_DEFINES if self.awake else ()
        self.caustic_defines = self.defines if self.in_caustics else ()

    @contextmanager
    def as_rippling(self) -> Iterator[None]:
        """Within the block, ``defines`` and ``caustic_defines`` are those of a ring alive: what a
        level's programs are built with ahead (``Renderer.prepare_programs``), so that the first
        drop builds none (the scene's CAUSTICS builds with RIPPLES: several of them, each a
        shader compile of a few tens of ms on llvmpipe, in the frame the drop lands)."""
        kept = self.defines, self.caustic_defines
        self.defines = RIPPLE_DEFINES
        self.caustic_defines = RIPPLE_DEFINES if self.in_caustics else ()
        try:
            yield
        finally:
            self.defines, self.caustic_defines = kept

    def release(self) -> None:
        """Every GL object it holds (the last rippling water gone, or closing)."""
        for obj in (*self._targets, *self._images, self._ubo, self._vao):
            if obj is not None:
                obj.release()
        self._targets, self._images, self._ubo, self._vao, self._program = [], [], None, None, None
        self.waters, self.awake = {}, set()
        self._say_awake()

