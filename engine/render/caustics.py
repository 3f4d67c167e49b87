"""Caustics under waters (``components.Water.caustics``): the uniform block and the normal
maps' array the scene's ``CAUSTICS`` builds read (``shaders/include/caustics.glsl``, which
says how the light is gathered), and the rules of what they hold.

The lamps' light is gathered too: the prepare stage names the kept lamps that stand over a
held water within their range (``lamps_over``, at most ``MAX_CAUSTIC_LAMPS``, those whose light
at the water is brightest; the block's ``caustic_lamps``, the ``CAUSTIC_LAMPS`` builds while
any), and scene.frag's lamps take ``caustic_lamp_light`` under the waters a draw names.

A water that also reflects light (``Mirror.reflects_light``) throws what its waves gather of
the sun's light back up: the scene's virtual light for the sun's image in it names its slot
(``shadow_rules.reflected_caustic_water``, ``Shadows.set_virtual_caustic``) and the points it
lights over the water take ``caustic_reflected_light``.

Only the batches whose world boxes reach into a held water's reach (``reach_box``: its body,
and the air over one that reflects light; ``reaches``, ``CausticBlock.slots_of``) are drawn
with the CAUSTICS builds: on llvmpipe every pixel of a build runs its caustics, on the water
or off it, behind a branch or not (measured: a build whose caustics return at once
cost as much as one that works them out), so a level with a pond pays only where the pond is.
A batch's box is the union of its rows', and one mesh's rows across a level (a hall's boxes)
span any pond in it; so the extract stage puts the rows that reach into the body of a
water that gathers the sun in batches of their own, keyed by the waters they reach
(``caustic_waters_of``, ``BatchKey.caustic_waters``), and only those are drawn with the
builds (measured on the sample level with caustics on its pond, 640x360 on llvmpipe: +24% a
frame before, about +9% after).

Up to ``MAX_CAUSTIC_WATERS`` waters gather the sun at once: the prepare stage gives the block
the nearest the active camera of the waters that have caustics and waves (a normal map), in
the order of their entities (a camera walking between two ponds does not reorder the block
and remake the maps' array), and says when others are left out.  Each draw names the held waters its batch
reaches into (scene.frag's ``caustic_waters``, at most four: an ivec4), and each of its
points takes the light of every one of them (one off its outline or below its body gives 1),
so one floor under two ponds is lit through each.  The waters' normal maps are the layers of
one array texture (``CausticMaps``: one sampler, the 19th of the fullest scene build, for
every water).  The light shafts march every held water.  A still water (no normal map)
bends no light: it has none.
A context with fewer than ``CAUSTIC_SAMPLERS`` texture units in the fragment stage draws
none, said once (``GLLimitWarning``).

The waves move every frame, so while a water gathers the sun its block is written every
frame, and the views that show what is under it are drawn again (``Gpu.note_scene_change``);
a probe shows them as they were when it captured its faces.
"""
from __future__ import annotations

import math
import warnings
import weakref
from collections.abc import Sequence
from dataclasses import dataclass

import moderngl
import numpy as np
from pyglm import glm

from engine.assets.texture_data import TextureData
from engine.core.errors import GLLimitWarning
from engine.render.bindings import CAUSTIC_UNIT, CAUSTICS_BINDING, bind_texture, bind_uniform_block
from engine.render.spot_cookies import SCENE_SAMPLERS
from engine.resources import MirrorBumps, SurfaceState

MAX_CAUSTIC_WATERS = 4      # waters whose caustics are drawn at once (the nearest the active camera; at most 4:
#                             a draw names its waters in an ivec4, scene.frag's caustic_waters)
CAUSTIC_SAMPLERS = SCENE_SAMPLERS + 3   # the fullest build with cookies, soft suns' depths and caustics
CAUSTIC_SUN_SPREAD = 0.0093  # radians: the sun's disc (0.53 degrees), how a caustic blurs with depth
CAUSTIC_MAP_MAX_SIDE = 2048  # the most texels along a side of the waters' normal maps' array (CausticMaps)
MAX_CAUSTIC_LAMPS = 4       # lamps over a held water whose light is gathered too (the block's caustic_lamps, an ivec4)
_ROWS = 7                   # a water's vec4s in the block (caustics.glsl's Caustics block: one array each)
# the arrays, then the ivec4 of how many are held, then the lamps' slots
_BLOCK_FLOATS = 4 * _ROWS * MAX_CAUSTIC_WATERS + 4 + 4
CAUSTICS_BLOCK_BYTES = 4 * _BLOCK_FLOATS
NO_CAUSTIC_WATERS = (-1, -1, -1, -1)   # scene.frag's caustic_waters for a batch under none


@dataclass(frozen=True, eq=False)
class CausticWater:
    """A water whose caustics the block holds: its entity, its normal map and the block's
    rows (``caustic_rows``)."""

    entity: int
    normal_map: TextureData
    rows: tuple[float, ...]
    box: tuple[tuple[float, float, float], tuple[float, float, float]]   # what it can light (reach_box)


def body_box(corners: np.ndarray, down: tuple[float, float, float],
             depth: float) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """The world box [lo, hi] of what a water can light: its surface's ``corners``
    (homogeneous rows) and the same ``depth`` metres along the unit ``down``."""
    top = np.asarray(corners, np.float64)[:, :3]
    ends = np.concatenate([top, top + np.asarray(down, np.float64) * depth])
    return tuple(ends.min(axis=0).tolist()), tuple(ends.max(axis=0).tolist())


Box = tuple[tuple[float, float, float], tuple[float, float, float]]   # a world box (lo, hi)


MAX_REACH_LEAN = 8.0   # a low sun's light thrown back up reaches at most this many depths out along the plane
LEAN_STEP = 0.25       # the lean's depths rounded up to these (a sun moving over a day keys rows again rarely)
HEADINGS = 64          # ... and its way along the plane to one of these
REACH_GRID = 0.25      # metres: a reach box's edges lie on this grid (out), so small moves keep it


def reach_box(corners: np.ndarray, up: tuple[float, float, float], depth: float, reflects: bool,
              suns: tuple[tuple[float, float, float], ...] = (),
              lamps: tuple[tuple[float, float, float], ...] = ()) -> Box:
    """The world box [lo, hi] of what a water's caustics can light: its body (``body_box``:
    down to ``depth`` under its surface ``corners``) and, for a water that reflects light
    (``Mirror.reflects_light``: its waves gather the sun's light they throw back up), the air
    up to ``depth`` over it too: where each of ``suns`` (the ways their light travels) is
    reflected, rising ``depth`` as it leans out along the plane (``depth`` / tan of the sun's
    height over the plane, rounded up to ``LEAN_STEP`` depths: 1 at 45 degrees, 2.75 at 20;
    at most ``MAX_REACH_LEAN``, a sun under 7 degrees), the whole widened by ``depth`` every
    way along its plane (the waves turn the light aside; a sun 45 degrees or more over the
    surface leans no farther), and where each of ``lamps`` (positions) over the water throws
    its light as it rises ``depth`` (out from the lamp's foot, as far again times ``depth``
    over the lamp's height, at most ``MAX_REACH_LEAN`` depths past the surface's edge).  What
    lies in it is drawn with the caustics (``reaches``):
    ``shaders/include/caustics.glsl`` gathers the net at any point up to ``depth`` over the
    water whose flat reflected ray meets it."""
    up_vector = np.asarray(up, np.float64)
    lo, hi = body_box(corners, tuple(-up_vector), depth)
    if not reflects:
        return lo, hi
    top = np.asarray(corners, np.float64)[:, :3]
    risen = top + up_vector * depth
    ends = [top, risen]
    for sun in suns:
        travel = np.asarray(sun, np.float64)
        rise = -float(travel @ up_vector)   # the reflected ray's rise a unit of its length
        if rise <= 1e-6:
            continue   # (a sun under the plane: no light off it)
        along = travel + rise * up_vector   # the reflected ray's way along the plane
        length = float(np.linalg.norm(along))
        if length <= rise:
            continue   # (45 degrees or higher: within the widening below)
        lean = min(MAX_REACH_LEAN, math.ceil(length / rise / LEAN_STEP - 1e-9) * LEAN_STEP)
        ends.append(risen + _snapped_way(along / length, up_vector) * (lean * depth))
    for lamp in lamps:
        position = np.asarray(lamp, np.float64)
        height = float((position - top[0]) @ up_vector)   # (over the plane)
        if height <= 1e-4:
            continue   # (a lamp under the plane throws nothing up)
        foot = position - height * up_vector
        out = (top - foot) * (depth / height)   # each corner's light, risen depth, leaned out from the foot
        length = np.linalg.norm(out, axis=1, keepdims=True)
        ends.append(risen + out * np.minimum(1.0, MAX_REACH_LEAN * depth / np.maximum(length, 1e-9)))
    ends = np.concatenate(ends)
    widen = depth * np.sqrt(np.clip(1.0 - up_vector * up_vector, 0.0, 1.0))   # along the plane, per axis
    # (out to a grid of REACH_GRID metres: a lamp moving a little moves no edge; an edge a
    # rounding error past a line of the grid stays on it)
    low = np.minimum(lo, ends.min(axis=0) - widen) / REACH_GRID
    high = np.maximum(hi, ends.max(axis=0) + widen) / REACH_GRID
    return (tuple((np.floor(low + 1e-6) * REACH_GRID).tolist()), tuple((np.ceil(high - 1e-6) * REACH_GRID).tolist()))


class ReachBoxes:
    """Each water's ``reach_box``, made again only when what it is made from changed (its
    surface's state, by identity, its depth, whether it reflects light, the suns' ways and the
    lamps' places): the extract and prepare stages ask every frame (one keeper for both:
    ``CausticBlock.reach``), and a box with suns and lamps is about 80 us of numpy."""

    def __init__(self) -> None:
        self._boxes: dict[int, tuple[tuple, Box]] = {}   # entity -> ((a weak ref to its state, key), box)

    def box(self, entity: int, state: SurfaceState, depth: float, reflects: bool, suns: tuple = (),
            lamps: tuple = ()) -> Box:
        """``reach_box`` of ``state`` (a ``SurfaceState``: its corners and plane) for ``entity``."""
        key = (depth, reflects, suns if reflects else (), lamps if reflects else ())
        kept = self._boxes.get(entity)
        if kept is not None and kept[0][0]() is state and kept[0][1] == key:
            return kept[1]
        found = reach_box(state.corners, tuple(glm.vec3(state.plane)), depth, reflects, key[2], key[3])
        if len(self._boxes) > 64:
            self._boxes.clear()
        self._boxes[entity] = ((weakref.ref(state), key), found)   # (a gone water's state, its normal map, let go)
        return found


def _snapped_way(along: np.ndarray, up: np.ndarray) -> np.ndarray:
    """The unit way ``along`` (in the plane square to ``up``) turned to the nearest of
    ``HEADINGS`` ways round: so a sun moving over a day moves a reach box in steps (at
    ``MAX_REACH_LEAN`` the step's half turns the lean's end by 0.4 depth, inside the box's
    widening by one)."""
    first = np.cross(up, (1.0, 0.0, 0.0) if abs(up[0]) < 0.9 else (0.0, 0.0, 1.0))
    first /= np.linalg.norm(first)
    second = np.cross(up, first)
    step = 2.0 * math.pi / HEADINGS
    angle = round(math.atan2(float(along @ second), float(along @ first)) / step) * step
    return first * math.cos(angle) + second * math.sin(angle)


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


def lamps_over(waters: Sequence[CausticWater], lamps: Sequence[tuple[int, np.ndarray, float, float]]) -> list[int]:
    """The Lights block slots of ``lamps`` ((slot, world position, range, power: intensity x
    its colour's brightest channel) each) that stand over one of ``waters`` (in front of its
    plane) and reach its box (``CausticWater.box``) within their range: the lamps whose light
    the waves gather, the one whose light at the nearest of those boxes is brightest (power
    over the engine's distance falloff, d^2 + 1) first, a tie by slot."""
    found = []
    for slot, position, reach, power in lamps:
        p = np.asarray(position, np.float64)
        brightest = -1.0
        for water in waters:
            plane = np.asarray(water.rows[:4], np.float64)
            lo, hi = np.asarray(water.box[0]), np.asarray(water.box[1])
            distance = float(np.linalg.norm(p - np.clip(p, lo, hi)))
            if plane[:3] @ p + plane[3] > 0.0 and distance < reach:
                brightest = max(brightest, power / (distance * distance + 1.0))
        if brightest >= 0.0:
            found.append((-brightest, slot))
    return [slot for _, slot in sorted(found)]


def caustic_waters_of(box: Box, bodies: tuple[tuple[int, Box], ...]) -> tuple[int, ...]:
    """The entities of the waters among ``bodies`` ((entity, body box) each: ``body_box``) whose
    body the world ``box`` reaches into: a row drawn with the CAUSTICS builds under them (in a
    batch of its own, ``BatchKey.caustic_waters``), so that a mesh's other rows across a level
    do not pay for them."""
    return tuple(entity for entity, body in bodies if reaches(box, body))


def uv_axes(normal: np.ndarray, uv_rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float] | None:
    """A surface's UVs laid on its plane (unit ``normal``): the unit directions of +U and +V
    along it (each UV row's gradient with its part along the normal taken out) and the
    gradients' lengths there (UV units a metre); None where a row runs square to the
    surface (no frame to lay anything on it by)."""
    flats = [np.asarray(row, np.float64)[:3] for row in uv_rows]
    flats = [row - np.dot(row, normal) * normal for row in flats]
    lengths = [float(np.linalg.norm(flat)) for flat in flats]
    if min(lengths) < 1e-9:
        return None
    return flats[0] / lengths[0], flats[1] / lengths[1], lengths[0], lengths[1]


def caustic_rows(plane: tuple[float, float, float, float], bumps: MirrorBumps, *, tiling: float, cross: float,
                 offset: tuple[float, float], ior: float, strength: float, depth: float,
                 map_width: int) -> tuple[float, ...] | None:
    """A water's rows of the ``Caustics`` block (caustics.glsl): its top ``plane`` (normal up,
    out of the water), its mirror's UV rows, the surface's unit directions of +U and +V (each UV
    row's direction laid on the plane, as the composite's frame), the waves' layers
    (``tiling``, ``cross``, ``offset``, ``bumps.scale``), 1 / ``ior``, the ``strength``
    (``Water.caustics``), a map texel's size in metres along U (the texels of its layer in
    ``CausticMaps``: ``map_width`` across), the body's ``depth`` and the sun's spread.  None
    where the UVs do not run along the surface (a row square to it: no frame to read the
    waves in)."""
    normal = np.array(plane[:3], np.float64)
    u_row, v_row = (np.asarray(row, np.float64) for row in bumps.uv_rows)
    axes = uv_axes(normal, bumps.uv_rows)
    if axes is None:
        return None
    texel = 1.0 / (map_width * tiling * float(np.linalg.norm(u_row[:3])))
    return tuple(float(v) for v in (*normal, plane[3], *u_row, *v_row, *axes[0], cross, *axes[1],
                                    bumps.scale, *offset, 1.0 / ior, strength, tiling, texel, depth,
                                    CAUSTIC_SUN_SPREAD))


def caustic_map_size(maps: Sequence[TextureData]) -> tuple[int, int]:
    """The size of the layers of the waters' normal maps' array (``CausticMaps``): the widest
    and the tallest of ``maps``, at most ``CAUSTIC_MAP_MAX_SIDE`` a side (maps of one size, the
    usual case, are copied texel for texel)."""
    return (min(max(m.size[0] for m in maps), CAUSTIC_MAP_MAX_SIDE),
            min(max(m.size[1] for m in maps), CAUSTIC_MAP_MAX_SIDE))


def wrapped_resample(pixels: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``pixels`` (rows, columns, channels) resampled bilinearly to ``size`` (width, height),
    wrapping at the edges as a repeating normal map does (the same array where the size is
    its own)."""
    h, w = pixels.shape[:2]
    if (w, h) == tuple(size):
        return pixels

    def axis(n: int, count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        x = (np.arange(count) + 0.5) * n / count - 0.5   # each new texel's centre in the old texels
        low = np.floor(x).astype(np.int64)
        return low % n, (low + 1) % n, x - low

    y0, y1, ty = axis(h, size[1])
    x0, x1, tx = axis(w, size[0])
    p = pixels.astype(np.float64)
    rows = p[y0] * (1.0 - ty)[:, None, None] + p[y1] * ty[:, None, None]
    out = rows[:, x0] * (1.0 - tx)[None, :, None] + rows[:, x1] * tx[None, :, None]
    return np.rint(out).astype(pixels.dtype)


class CausticMaps:
    """The held waters' normal maps as the layers of one array texture (``caustics.glsl``'s
    ``caustic_maps``): one sampler for every water, whatever their number (the fullest scene
    build already takes the 19th unit for it).  Layers are of one size (``caustic_map_size``);
    a map of another size is resampled to it, wrapping.  16 bits a channel where any map has
    them (an 8-bit map's values scaled to them), else 8.  Made again when the held maps change."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.array: moderngl.TextureArray | None = None
        self._held: tuple[TextureData, ...] = ()

    def hold(self, maps: Sequence[TextureData]) -> bool:
        """Hold ``maps``, a layer each in their order; True when the array was made again."""
        if len(maps) == len(self._held) and all(a is b for a, b in zip(maps, self._held, strict=True)):
            return False
        self.release()
        if not maps:
            return True
        size = caustic_map_size(maps)
        sixteen = any(m.pixels.dtype == np.uint16 for m in maps)
        layers = []
        for m in maps:
            pixels = m.pixels.astype(np.uint16) * 257 if sixteen and m.pixels.dtype == np.uint8 else m.pixels
            layers.append(wrapped_resample(pixels, size)[::-1])   # (rows top-first; GL's bottom-first)
        self.array = self.ctx.texture_array((*size, len(maps)), 4, np.ascontiguousarray(np.stack(layers)).tobytes(),
                                            dtype="nu2" if sixteen else "f1")
        self.array.build_mipmaps()
        self.array.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        self._held = tuple(maps)
        return True

    def release(self) -> None:
        if self.array is not None:
            self.array.release()
        self.array, self._held = None, ()


class CausticBlock:
    """The ``Caustics`` uniform block on the GPU (bound at ``CAUSTICS_BINDING``: up to
    ``MAX_CAUSTIC_WATERS`` waters' rows, by entity), written when a held
    water's rows change; the ``CAUSTICS`` defines while it holds any; their normal maps'
    array (``CausticMaps``) bound for each scene pass (``bind``); and which waters a batch's
    draw reads (``slots_of``)."""

    def __init__(self, ctx: moderngl.Context, texture_units: int) -> None:
        self.ctx = ctx
        self.ubo = ctx.buffer(reserve=CAUSTICS_BLOCK_BYTES)
        self.supported = texture_units >= CAUSTIC_SAMPLERS
        self.texture_units = texture_units
        self.waters: tuple[CausticWater, ...] = ()
        self.lamps: tuple[int, ...] = ()   # the Lights block slots of the lamps whose light is gathered
        self.maps = CausticMaps(ctx)
        self.reach = ReachBoxes()   # the waters' reach boxes, which the extract and prepare stages both ask
        self.defines: tuple[tuple[str, str], ...] = ()
        self._warned = False
        # slots_of's answers while the held waters' entities and bodies stay: id(box) -> (box, keyed, posed, slots)
        self._slots: dict[int, tuple] = {}
        self._layout: tuple = ()

    def set(self, waters: Sequence[CausticWater], lamps: Sequence[int] = ()) -> bool:
        """Hold ``waters`` (at most ``MAX_CAUSTIC_WATERS``, a slot each in their order; none:
        none) and the Lights block slots of the ``lamps`` over them whose light they gather
        (at most ``MAX_CAUSTIC_LAMPS``: ``lamps_over``; the CAUSTIC_LAMPS builds while any);
        True when what the scene shows changed."""
        if len(lamps) > MAX_CAUSTIC_LAMPS:
            raise ValueError(f"{len(lamps)} caustic lamps given; the block holds {MAX_CAUSTIC_LAMPS}")
        if len(waters) > MAX_CAUSTIC_WATERS:
            raise ValueError(f"{len(waters)} caustic waters given; the block holds {MAX_CAUSTIC_WATERS}")
        if waters and not self.supported:
            if not self._warned:
                self._warned = True
                warnings.warn(GLLimitWarning(
                    f"Water on entity {waters[0].entity}: caustics need {CAUSTIC_SAMPLERS} texture units in the "
                    f"fragment stage and this OpenGL has {self.texture_units} (GL_MAX_TEXTURE_IMAGE_UNITS): the "
                    "water gathers no light"), stacklevel=3)
            waters = ()
        old, waters = self.waters, tuple(waters)
        layout = tuple((water.entity, water.box) for water in waters)
        if layout != self._layout:
            self._layout = layout
            self._slots.clear()
        if not waters:
            self.waters, self.defines, self.lamps = (), (), ()
            self.maps.release()
            return bool(old)
        remade = self.maps.hold([water.normal_map for water in waters])
        old_lamps, self.lamps = self.lamps, tuple(lamps)
        self.waters = waters
        self.defines = (("CAUSTICS", "1"), ("MAX_CAUSTIC_WATERS", str(MAX_CAUSTIC_WATERS)),
                        *((("CAUSTIC_LAMPS", "1"),) if lamps else ()))
        if not remade and old_lamps == self.lamps and len(old) == len(waters) and all(
                a.entity == b.entity and a.rows == b.rows and a.box == b.box for a, b in zip(old, waters, strict=True)):
            return False
        block = np.zeros((_ROWS, MAX_CAUSTIC_WATERS, 4), np.float32)
        for slot, water in enumerate(waters):
            block[:, slot] = np.asarray(water.rows, np.float32).reshape(_ROWS, 4)
        slots = [*self.lamps, *[-1] * (MAX_CAUSTIC_LAMPS - len(self.lamps))]
        self.ubo.write(block.tobytes() + np.array([len(waters), 0, 0, 0, *slots], np.int32).tobytes())
        return True

    def slots_of(self, box: tuple[np.ndarray, np.ndarray] | None, keyed: tuple[int, ...],
                 posed: bool = False) -> tuple[int, int, int, int]:
        """scene.frag's ``caustic_waters`` for a batch of world ``box`` keyed under the waters
        ``keyed`` (``BatchKey.caustic_waters``; a ``posed`` batch, its own, under any whose
        body its pose's box reaches): the slots of the held waters among them whose bodies
        the box reaches, -1 after the last (``NO_CAUSTIC_WATERS``: none, drawn without the
        CAUSTICS build)."""
        known = self._slots.get(id(box))
        if known is not None and known[0] is box and known[1] == keyed and known[2] == posed:
            return known[3]   # (a batch's box is made anew when its rows move)
        found = [slot for slot, water in enumerate(self.waters)
                 if (posed or water.entity in keyed) and reaches(box, water.box)]
        slots = (*found, *NO_CAUSTIC_WATERS[len(found):]) if found else NO_CAUSTIC_WATERS
        if box is not None:
            if len(self._slots) >= 256:   # (the boxes of batches whose rows moved: gone)
                self._slots.clear()
            self._slots[id(box)] = (box, keyed, posed, slots)
        return slots

    def bind(self) -> None:
        """Bind the block and the waters' maps for a scene pass (while it holds any): each
        pass, as another engine on the context binds its own block at the same point."""
        if self.waters:
            bind_uniform_block(self.ctx, self.ubo, CAUSTICS_BINDING)
            bind_texture(self.ctx, self.maps.array, CAUSTIC_UNIT)

    def release(self) -> None:
        self.ubo.release()
        self.maps.release()
        self.waters, self.defines, self.lamps = (), (), ()


def reaches(batch_box: tuple[np.ndarray, np.ndarray] | None,
            box: tuple[tuple[float, float, float], tuple[float, float, float]]) -> bool:
    """Whether a batch's world box (``InstanceBatch.box``; None: empty) overlaps ``box`` (a
    box not measured yet, NaN, counts as reaching it)."""
    if batch_box is None:
        return False
    (lx, ly, lz), (hx, hy, hz) = box
    lo, hi = batch_box
    return not (hi[0] < lx or hi[1] < ly or hi[2] < lz or lo[0] > hx or lo[1] > hy or lo[2] > hz)


def nearest_first(candidates: list[tuple[int, np.ndarray]], eye: np.ndarray) -> list[int]:
    """The entities of ``candidates`` ((entity, outline corners) each), the one whose outline's
    centre is nearest ``eye`` first (ties: the lower entity)."""
    return [c[0] for c in sorted(candidates, key=lambda c: (float(np.linalg.norm(
        np.asarray(c[1], np.float64)[:, :3].mean(axis=0) - eye)), c[0]))]
