"""The per-pixel passes of planar reflections: preparing a level (reset, then claims with
their visibility queries), the composite, and the fallback of surfaces with no view.

The fallback (issue 36's reflection fallback chain, as Unity and Godot drop a cut planar
reflection to the nearest probe or the sky): a mirror or portal a view sees but that gets no
view of its own shows what the composite would show with an empty reflection, its
environment (``COMPOSITE_FALLBACK`` builds of the same shader, one code path).  It is drawn
over the parent view's own pixels of the surface, found by the parent level's node and
surface images, so it needs no claim; the probes are uniforms of a draw and each row's
weights and ids ride in a uniform block (FallbackRows: the composite's row fills a vertex
shader's 16 attribute slots).  A row is a (parent view, surface) pair's, not a surface's
for every parent of a level: its pixels' rays start from the parent's camera (the row's
inverse view-projection and eye) and its quad is the surface's outline in the parent's clip
space, so one row for several parents would need each pixel's camera found by its node and a
quad over every parent's outline: more pixels shaded, and the edge pixels that one parent's
outline leaves out now (no margin: ``conservative_corner``) could get it.
Why there and not in the scene pass: the scene pass cannot know which
mirrors will get views (the budgets choose after it has drawn them), so writing the fallback
there would cost every mirror pixel its probe lookups and need the composite to take it out
again where a view is drawn, changing drawn mirrors' pixels; here a drawn view's pixels are
never touched, and only the pixels that show a fallback pay for it.

A view whose mirror or portal moved since the last frame (``surface_motion``) is composited
by a draw of its own with the ``SURFACE_MOTION`` build, which adds to the seen image's own
motion where last frame's surface showed each point (temporal AA's history and motion blur's
streaks follow a turning mirror's reflection); a level's views of still surfaces stay one
draw a build.

The claims' rectangles are one buffer a level (two triangles each, every vertex with its
claim's ids: claim.vert): the reset is one draw over all of them (rects.vert), each claim
a draw of its own six vertices (three GL calls a claim: its query's begin and end and the
draw; no scissor, no uniform); the composite is one instanced draw per level, a quad per
view over its surface.  They read the uint images
of a level (which view drew a pixel, which entity's surface is there).  The claim does the
work of a visibility query and a mask at once: its samples-passed count is the number of
pixels a candidate view owns.  (A mask pass that found each pixel's owner by looping over
a table of the level's views cost ~100 ns a pixel on llvmpipe, the loop's uniform-array
reads; a claim per view costs a few ns a pixel.)
"""
from __future__ import annotations

import struct
import weakref
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Protocol

import moderngl
import numpy as np
from pyglm import glm

from engine.assets.texture_data import TextureData
from engine.render.bindings import (
    ATLAS_UNIT,
    BLEND_OVER,
    FALLBACK_BINDING,
    FALLBACK_PARENT_UNITS,
    FOG_BINDING,
    NORMAL_UNIT,
    PARENT_NODE_UNIT,
    PARENT_SURFACE_UNIT,
    PROBE2_UNIT,
    PROBE_UNIT,
    RECT_CLIPS,
    REFLECTION_UNITS,
    REFRACTION_COPY_UNIT,
    RIPPLE_UNIT,
    RIPPLES_BINDING,
    SCENE_CLIPS,
    SKY_UNIT,
    PassState,
    apply_pass_state,
    assign_slots,
    bind_texture,
    bind_textures,
    bind_uniform_block,
)
from engine.render.context_kept import kept_on
from engine.render.gpu import Gpu
from engine.render.ripples import RIPPLE_DEFINES
from engine.render.rough_atlas import TILE, RoughAtlas, Tile, place_tiles
from engine.render.screen_refraction import RefractionCopy
from engine.render.sky_draw import bind_sky, sky_build, wire_sky, write_sky
from engine.render.targets import RenderTargets
from engine.render.views import (
    CAMERA_BLOCK_EYE,
    CAMERA_BLOCK_INVERSE,
    CAMERA_BLOCK_VIEW_PROJ,
    View,
    way_scale_bits,
)
from engine.resources import MirrorBumps, SurfaceState, WaterLook
from engine.rules.probe_rules import ProbeBlend

# The claims and the reset write every depth they touch (depth test "always"); the
# composite blends quads trimmed to their rectangles by clip distances 1-4.  The claims keep
# the scene pass's culling and clip distances (their rectangles face the front, their
# vertices keep every clip distance: claim.vert, rects.vert), so between a level's claims and
# its views only the depth function changes: 2 GL calls a level, not 8.
# Added to a water's F0 in its composite row where the camera is below it (water_row_f0;
# the composite's WATER_UNDERSIDE define).
WATER_UNDERSIDE = 2.0
_CLAIM = PassState(depth_func="1", cull=True, clips=SCENE_CLIPS)
_COMPOSITE = PassState(blend=BLEND_OVER, clips=RECT_CLIPS)


@dataclass(frozen=True)
class CompositeSurface:
    """What a surface's composite reads that stays put while the surface does, packed once
    (``composite_surface``) so a level's rows are joins of bytes, not numpy work."""

    variant: str                 # the build of mirror_composite.frag (COMPOSITE_VARIANTS)
    roughness: float
    reflect_rate: float
    params_z: float              # the surface plane's w (with ``normal``: where a pixel's ray meets it)
    outline: glm.mat4 | None     # its 4 world corners as columns (a 2 x 2 grid), or None: the rect
    tint: bytes                  # 3 floats
    normal: bytes                # 3 floats: world, facing the side it is seen from
    carry: bytes                 # a column-major mat3: a portal's directions here -> the view's
                                 # world; a bumpy mirror's UV map (u's gradient, v's, (u0, v0, scale))
    normal_map: TextureData | None = None  # a bumpy mirror's (its rows are drawn per map)
    water: object | None = None            # a water mirror's WaterLook (engine.resources): its row carries
                                           # F0, the waves' offset and the second layer's share
    entity: int = 0                        # the surface's (its fallback finds its pixels by it)
    plane_w: float = 0.0                   # its plane's w (the normal's is ``normal``)
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)  # a portal's carry's translation (its fallback)
    # What its row's tile slots (x, scale, y) hold where no rough tile is placed: 0, but a
    # portal's its offset (the sky beyond the partner is fogged from there, mirror_composite.frag).
    tile_slots: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def fallback_variant(self) -> str:
        """The build of mirror_composite.frag that draws this surface's fallback
        (FALLBACK_VARIANTS): a rough mirror's roughness is a mip bias there, as in the sharp one."""
        kind = self.variant.split("_")[0]
        base = {"portal": "fallback_portal", "water": "fallback_water"}.get(kind, "fallback")
        return base + ("_bumpy" if self.variant.endswith("_bumpy") else "")


def composite_surface(tint: glm.vec4, reflect_rate: float, roughness: float, normal: glm.vec3,
                      outline: np.ndarray | None = None, portal: bool = False,
                      carry: glm.mat3 | None = None, bumps: MirrorBumps | None = None,
                      water: WaterLook | None = None, entity: int = 0, plane_w: float = 0.0,
                      offset: glm.vec3 | None = None) -> CompositeSurface:
    """A surface's composite parameters; ``outline`` is its 4 world corners as homogeneous
    rows in 2 x 2 grid order (None: composite over its screen rectangle).  A mirror with
    ``bumps`` reads its normal map in the composite (a ``_bumpy`` variant).  A mirror with
    ``water`` (``engine.resources.WaterLook``) is a "water" variant (always sharp: its
    row's tile components carry the waves instead), its UV map scaled by the water's tiling.
    ``entity``, ``plane_w`` (the plane's w, with ``normal`` its xyz) and a portal's
    ``offset`` (its carry's translation) are what its fallback reads besides."""
    variant = "portal" if portal else ("rough" if roughness > 0.0 else "sharp")
    if water is not None and not portal:
        variant = "water"
    else:
        water = None
    columns = None if outline is None else glm.mat4(*(glm.vec4(*map(float, row)) for row in outline))
    params_z = float(plane_w)   # where the parent's ray meets the surface (the fog's, a bumpy mirror's)
    if bumps is not None and not portal:
        variant += "_bumpy"
        u, v = (glm.vec4(*map(float, row)) for row in bumps.uv_rows)
        if water is not None:
            u, v = u * water.tiling, v * water.tiling
        carry = glm.mat3(glm.vec3(u), glm.vec3(v), glm.vec3(u.w, v.w, bumps.scale))
        params_z = float(bumps.plane_offset)
    placed = tuple(map(float, offset)) if offset is not None else (0.0, 0.0, 0.0)
    return CompositeSurface(variant, float(roughness), float(reflect_rate), params_z, columns,
                            glm.vec3(tint).to_bytes(), glm.vec3(normal).to_bytes(),
                            (carry if carry is not None else glm.mat3(1.0)).to_bytes(),
                            bumps.normal_map if bumps is not None and not portal else None, water,
                            int(entity), float(plane_w), placed, placed if portal else (0.0, 0.0, 0.0))


_LOOKS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def surface_look(state: SurfaceState) -> CompositeSurface:
    """What the composite reads of a surface (``engine.resources.SurfaceState``), packed once
    per state object: the packing is the renderer's, so the public state stays plain data."""
    look = _LOOKS.get(state)
    if look is None:
        look = _LOOKS[state] = composite_surface(state.tint, state.reflect_rate, state.roughness,
                                                 glm.vec3(state.plane), state.outline, portal=state.kind == "portal",
                                                 carry=glm.mat3(state.carry), bumps=state.bumps,
                                                 water=getattr(state, "water", None), entity=state.entity,
                                                 plane_w=state.plane.w, offset=glm.vec3(state.carry[3]))
    return look


@dataclass(slots=True)
class Composite:
    """One view of a reflection level as its composite sees it."""

    view_index: int
    rect: tuple[int, int, int, int]                            # in the parent level's pixels
    level_rect: tuple[int, int, int, int]                      # the same, in the view's level (its claim)
    parent_view: View                                          # the view that sees the surface
    surface: CompositeSurface
    tile: Tile | None = None                                   # a rough view's blur source (RoughAtlas)
    fade: float = 1.0                                          # the reflection's weight (a mirror's fades)


class CompositeView(Protocol):
    """A view a level's composite draws (``ViewTree``'s ``ReflectionView``)."""

    index: int               # its node: its pixels in its level's node image
    view: View               # its scissor: its rectangle in its level
    surface: SurfaceState    # the surface it is seen in
    parent: FallbackParent   # the view that sees the surface
    fade: float              # its reflection's weight


class FallbackParent(Protocol):
    """A view whose pixels show fallbacks (``ViewTree``'s ``ReflectionView``)."""

    index: int   # its node: its pixels in its level's node image
    level: int   # 0: a root, whose rectangle is its whole target
    view: View


class Fallbacks:
    """A level's fallbacks, as columns: each a surface seen by a view with no view of its own
    (or a partly faded one, or an end view's holes), its parent the view that sees it.  The
    view tree adds them in blocks as it finds them (the planner's (parent, surface) pairs, a
    level's cut or faded candidates, its end views), each block as columns, never an object
    a fallback; ``MirrorPasses.prepare_fallbacks`` packs them (the 16-mirror ring has 130-230
    of them a frame at 320 x 180: an object and a Composite a fallback cost ~3 us each)."""

    __slots__ = ("states", "parents", "at", "surface", "share", "end", "_from", "_offset")

    def __init__(self, states: Sequence[SurfaceState]) -> None:
        self.states = states                     # the frame's surfaces (``surface`` are rows of them)
        self.parents: list[FallbackParent] = []  # the blocks' parents, a list after another
        self.at: list[int] = []                  # each fallback's parent: an index of ``parents``
        self.surface: list[int] = []             # each one's surface row
        self.share: list[float] | None = None    # each one's share of the reflection (None: all 1)
        self.end: list[int] | None = None        # each one's end view, whose holes it fills (None: all -1)
        self._from: Sequence[FallbackParent] | None = None  # the last block's parents (added once)
        self._offset = 0

    def __len__(self) -> int:
        return len(self.at)

    def add(self, parents: Sequence[FallbackParent], at: np.ndarray | Sequence[int],
            surface: np.ndarray | Sequence[int], share: np.ndarray | float = 1.0,
            end: np.ndarray | Sequence[int] | int = -1) -> None:
        """Fallbacks of surfaces ``surface`` (rows of ``states``) seen by ``parents[at]``, with
        the fallback's ``share`` of the reflection (1 - the view's fade; 1: no view) and the
        end view whose holes it fills (its node; -1: none), each one value or one a
        fallback.  Consecutive blocks of the same ``parents`` (the same list, not changed
        since) share them."""
        count = len(at)
        if not count:
            return
        if parents is not self._from:
            self._from, self._offset = parents, len(self.parents)
            self.parents.extend(parents)
        before = len(self.at)
        at = at.tolist() if isinstance(at, np.ndarray) else list(at)
        self.at += [a + self._offset for a in at] if self._offset else at
        self.surface += surface.tolist() if isinstance(surface, np.ndarray) else surface
        if not isinstance(share, float) or share != 1.0:
            if self.share is None:
                self.share = [1.0] * before
            self.share += [share] * count if isinstance(share, float) else np.asarray(share, np.float64).tolist()
        elif self.share is not None:
            self.share += [1.0] * count
        if not isinstance(end, int) or end != -1:
            if self.end is None:
                self.end = [-1] * before
            self.end += [end] * count if isinstance(end, int) else np.asarray(end, np.int64).tolist()
        elif self.end is not None:
            self.end += [-1] * count


@dataclass
class PreparedFallbacks:
    """A level's fallbacks, ready to draw: per (variant, normal map, first probe, second
    probe), chunks of ``MirrorPasses.fallback_chunk`` rows (a draw each), each (composite
    rows, ids, weights: the FallbackRows block's arrays)."""

    groups: dict[tuple[str, TextureData | None, int, int], list[tuple[bytes, bytes, bytes]]]
    count: int = 0


@dataclass
class PreparedComposites:
    """A level's composite, ready to draw (``MirrorPasses.prepare_composites``)."""

    rough: list[tuple[int, tuple[int, int, int, int]]]   # rough views to copy into the atlas
    rows: dict[tuple[str, TextureData | None], bytes]    # packed instance rows per (variant, normal map)
    # Views whose surface moved since the last frame (MirrorPasses.surface_motion), a draw each
    # of the SURFACE_MOTION build: ((variant, normal map), its row, the parent's view-projection
    # and that times the surface's motion, column-major bytes: the build's two uniforms).
    moving: list[tuple[tuple[str, TextureData | None], bytes, bytes, bytes]] = field(default_factory=list)


# One row per composite instance: mirror_composite.vert's attributes, in order, each one or
# more of these fields.  A vertex shader has 16 attribute slots and the rest of the row fills
# them, so the tile and the view's index ride in spare components; a water row (never rough,
# so it has no tile) carries the waves' offset u and v where the tile's x and y go, the second
# layer's share where its scale goes, and F0 where the roughness goes (composite_rows).
COMPOSITE_DTYPE = np.dtype([
    ("corners", "<f4", (16,)),        # the 4 clip-space corners of its quad
    ("rect", "<f4", (4,)),            # the view's rectangle in its level
    ("inv_view_proj", "<f4", (16,)),  # the parent view's
    ("eye", "<f4", (3,)),             # the parent view's
    ("tile_x", "<f4"),                # the rough atlas tile's x; water: the waves' offset u
    ("tint", "<f4", (3,)),
    ("tile_scale", "<f4"),            # the tile's scale; water: the second layer's share
    ("reflect_rate", "<f4"),          # times the view's fade
    ("roughness", "<f4"),             # water: F0 (negative: a partly faded view, over its fallback)
    ("params_z", "<f4"),              # CompositeSurface.params_z: the surface plane's w
    ("view_index", "<f4"),            # the view's node index
    ("normal", "<f4", (3,)),
    ("tile_y", "<f4"),                # the tile's y; water: the waves' offset v
    ("carry", "<f4", (9,)),           # a portal's carry (a mirror: identity)
])
_COMPOSITE_ATTRIBUTES = (("in_corners", ("corners",)), ("in_rect", ("rect",)), ("in_inv_view_proj", ("inv_view_proj",)),
                         ("in_eye", ("eye", "tile_x")), ("in_tint", ("tint", "tile_scale")),
                         ("in_params", ("reflect_rate", "roughness", "params_z", "view_index")),
                         ("in_normal", ("normal", "tile_y")), ("in_carry", ("carry",)))
_COMPOSITE_COLUMNS = tuple((name, sum(COMPOSITE_DTYPE.fields[f][0].itemsize // 4 for f in fields))
                           for name, fields in _COMPOSITE_ATTRIBUTES)
assert [f for _, fields in _COMPOSITE_ATTRIBUTES for f in fields] == list(COMPOSITE_DTYPE.names)
# Packed with struct, field by field in that order (composite_rows: cheaper than a record's fields).
_COMPOSITE_ROW = struct.Struct("<64s4f64s12sf12sf4f12sf36s")
assert _COMPOSITE_ROW.size == COMPOSITE_DTYPE.itemsize
# The parts of a packed Camera block (views.py) a composite row copies, in bytes.
_BLOCK_VIEW_PROJ = slice(4 * CAMERA_BLOCK_VIEW_PROJ.start, 4 * CAMERA_BLOCK_VIEW_PROJ.stop)
_BLOCK_INVERSE = slice(4 * CAMERA_BLOCK_INVERSE.start, 4 * CAMERA_BLOCK_INVERSE.stop)
_BLOCK_EYE = slice(4 * CAMERA_BLOCK_EYE.start, 4 * CAMERA_BLOCK_EYE.stop)
# Flattens clip-space corners onto z = 0: every depth is kept (an oblique near plane would
# cut the quad) while clipping still drops w <= 0.
_FLATTEN_Z = glm.mat4(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
_COLOR_UNIT, _SEEN_UNIT, _NODE_UNIT = REFLECTION_UNITS  # the composite's units for a level's images
_NO_PROBE = ((0.0, 0.0, 0.0, 0.0),) * 3  # a probe's lookup uniforms where the sky stands in for it
# A claim as two clip-space triangles, each vertex its position and the claim's ids (claim.vert).
_CLAIM_VERTICES = struct.Struct("<" + "2f3I" * 6)
# The composite and fallback builds' texture units, by sampler (a build samples some of them).
_COMPOSITE_UNITS = {**dict(zip(("reflection", "reflection_seen", "reflection_nodes"), REFLECTION_UNITS, strict=True)),
                    "sky_map": SKY_UNIT, "rough_atlas": ATLAS_UNIT, "normal_map": NORMAL_UNIT,
                    "probe_map": PROBE_UNIT, "probe2_map": PROBE2_UNIT,
                    **dict(zip(("parent_nodes", "parent_surfaces"), FALLBACK_PARENT_UNITS, strict=True)),
                    "refraction_copy": REFRACTION_COPY_UNIT, "ripple_atlas": RIPPLE_UNIT}
# The composite's variants (mirror_composite.frag); a level's views are drawn grouped by them.
# A "_bumpy" build reads the mirror's normal map (MirrorBumps); its views are drawn per map.
COMPOSITE_VARIANTS = {"sharp": {}, "rough": {"COMPOSITE_ROUGH": "1"}, "portal": {"COMPOSITE_PORTAL": "1"},
                      "sharp_bumpy": {"COMPOSITE_BUMPY": "1"},
                      "rough_bumpy": {"COMPOSITE_ROUGH": "1", "COMPOSITE_BUMPY": "1"},
                      "water": {"COMPOSITE_WATER": "1", "WATER_REFRACTION": "1"},
                      "water_bumpy": {"COMPOSITE_WATER": "1", "COMPOSITE_BUMPY": "1", "WATER_REFRACTION": "1"}}
# (a water view's composite bends what lies below the surface: the level copied first, composite_level)
WATER_VARIANTS = frozenset(("water", "water_bumpy"))
# The variants that read the sky along one reflected ray (no blur): under a generated sky they
# evaluate it per pixel (MirrorPasses._composite_for).
SKY_VARIANTS = frozenset(("sharp", "sharp_bumpy", "water", "water_bumpy"))


# The fallback's builds (COMPOSITE_FALLBACK, mirror_composite.frag): one for sharp and rough
# mirrors (roughness is a mip bias of the environment), a portal's, water's, and the bumpy ones;
# each with the probes ("fallback_probes...": FALLBACK_PROBES) or the sky alone (no influence
# box holds the draw's surfaces: on llvmpipe, the 8-mirror ring faded out at 640x360, its six
# fallbacks took 0.8 ms a frame without the probes' lookups at weight 0, 0.9-1.2 with them).
_FALLBACK_BUILDS = (("", {}), ("_portal", {"COMPOSITE_PORTAL": "1"}), ("_bumpy", {"COMPOSITE_BUMPY": "1"}),
                    ("_water", {"COMPOSITE_WATER": "1", "WATER_REFRACTION": "1"}),
                    ("_water_bumpy", {"COMPOSITE_WATER": "1", "COMPOSITE_BUMPY": "1", "WATER_REFRACTION": "1"}))
FALLBACK_VARIANTS = {f"fallback{probes}{name}": {"COMPOSITE_FALLBACK": "1", **extra, **defines}
                     for probes, extra in (("", {}), ("_probes", {"FALLBACK_PROBES": "1"}))
                     for name, defines in _FALLBACK_BUILDS}
FALLBACK_ROWS = 256  # rows a fallback draw takes (its uniform block's arrays); more are drawn in chunks
_FALLBACK_IDS_BYTES = 16 * FALLBACK_ROWS  # the block's ids array (std140: a uvec4 a row), then its weights
_FALLBACK_IDS = struct.Struct("<4I")
_FALLBACK_WEIGHTS = struct.Struct("<8f")
# A composite row (_COMPOSITE_ROW) as a fallback's is joined: its corners, the parent's head
# (rectangle, inverse, eye), the surface's head, the parent's node, the surface's tail.
_PIECE_PARENT = struct.Struct("<4f64s12s")
_PIECE_HEAD = struct.Struct("<f12s4f")
_PIECE_NODE = struct.Struct("<f")
_PIECE_TAIL = struct.Struct("<12sf36s")
assert 64 + _PIECE_PARENT.size + _PIECE_HEAD.size + _PIECE_NODE.size + _PIECE_TAIL.size == _COMPOSITE_ROW.size


def _instance_format(program: moderngl.Program) -> tuple[str, list[str]]:
    """The composite rows' vertex format for ``program``: a variant's shader may not read
    every column, and the linker drops those attributes, so they are skipped as padding."""
    parts, names = [], []
    for name, count in _COMPOSITE_COLUMNS:
        if name in program:
            parts.append(f"{count}f")
            names.append(name)
        else:
            parts.append(f"{4 * count}x")
    return " ".join(parts) + "/i", names


class _CompositeDraw:
    """One variant of the composite: its program and its instance rows."""

    def __init__(self, ctx: moderngl.Context, program: moderngl.Program) -> None:
        self.ctx = ctx
        self.program = program
        self.format, self.attributes = _instance_format(program)
        self.rows: moderngl.Buffer | None = None     # grown as needed
        self.vao: moderngl.VertexArray | None = None
        self.reloads = 0  # ShaderLibrary.reloads when the format and vertex array were made
        self.sky_version = -1  # a GENERATED_SKY build's: the Gpu.sky_version its sky uniforms are of

    def draw(self, rows: bytes, reloads: int = 0) -> None:
        """Draw ``rows``; ``reloads`` is the shader library's count of rebuilds: after a hot
        reload the program may read columns its first build dropped, so the format and the
        vertex array are made again."""
        if reloads != self.reloads:
            self.reloads = reloads
            self.format, self.attributes = _instance_format(self.program)
            self.release()
        if self.rows is None or self.rows.size < len(rows):
            self.prepare(len(rows))
        self.rows.write(rows)
        self.vao.render(moderngl.TRIANGLE_STRIP, vertices=4, instances=len(rows) // _COMPOSITE_ROW.size)

    def prepare(self, size: int = 0) -> None:
        """A rows buffer of at least ``size`` bytes (16 rows at least) and its vertex array."""
        self.release()
        self.rows = self.ctx.buffer(reserve=max(size, 16 * _COMPOSITE_ROW.size))
        self.vao = self.ctx.vertex_array(self.program, [(self.rows, self.format, *self.attributes)])

    def release(self) -> None:
        for obj in (self.vao, self.rows):
            if obj is not None:
                obj.release()
        self.vao = self.rows = None


def composite_rows(composites: list[Composite], size: tuple[int, int]) -> bytes:
    """The packed instance rows of ``composites`` drawn into a level of ``size`` pixels.

    A row is one struct pack of pieces packed earlier (the surface's, the parent view's
    camera block) and one matrix product for an outlined surface: in a frame, after the
    rasteriser has run, the numpy version of this cost ~0.27 ms a level (measured on
    llvmpipe), several times its warm cost, for a handful of rows."""
    flattened: dict[bytes, glm.mat4] = {}  # per parent view (a parent has a view into each surface it sees)
    return b"".join([_composite_row(c.surface, c.parent_view.camera_block(), c.rect, c.level_rect, c.tile, c.fade,
                                    c.view_index, size, flattened) for c in composites])


def _composite_row(surface: CompositeSurface, block: bytes, rect: tuple[int, int, int, int],
                   level_rect: tuple[int, int, int, int], tile: Tile | None, fade: float, view_index: int,
                   size: tuple[int, int], flattened: dict[bytes, glm.mat4]) -> bytes:
    """One row of ``composite_rows`` (a view of ``surface`` seen from the parent view whose
    Camera block is ``block``; ``flattened``: the parents' flattened view-projections so far)."""
    if surface.outline is not None:
        # The surface's own quad in the parent's clip space, flattened onto z = 0.
        to_clip = flattened.get(block)
        if to_clip is None:
            to_clip = flattened[block] = _FLATTEN_Z * glm.mat4.from_bytes(block[_BLOCK_VIEW_PROJ])
        corners = (to_clip * surface.outline).to_bytes()
    else:
        x0, y0, x1, y1 = _ndc_rect(rect, size)
        corners = struct.pack("<16f", x0, y0, 0.0, 1.0, x0, y1, 0.0, 1.0, x1, y0, 0.0, 1.0, x1, y1, 0.0, 1.0)
    lx, ly, lw, lh = level_rect
    water = surface.water
    if water is None:
        x, scale, y = (tile.x, tile.scale, tile.y) if tile is not None else surface.tile_slots
        rough = surface.roughness
    else:  # this frame's offset of the waves (the surfaces stage moves it in place)
        (x, y), scale, rough = water.flow.offset, water.cross, water_row_f0(water)
        if fade < 1.0:  # (partly faded: its fallback under it bends what is below, mirror_composite.frag)
            rough = -rough
    return _COMPOSITE_ROW.pack(
        corners, lx, ly, lx + lw, ly + lh, block[_BLOCK_INVERSE], block[_BLOCK_EYE], x,
        surface.tint, scale, surface.reflect_rate * fade, rough, surface.params_z, float(view_index),
        surface.normal, y, surface.carry)


@dataclass
class _FallbackSurface:
    """What a fallback's row reads of one surface (``fallback_surfaces``), packed once: the
    composite row's pieces around the parent's (``composite_rows``'s fields, with no tile
    and no fade) and its extras with no end view, a share of 1 and no probes."""

    head: bytes                   # tile x, tint, tile scale, reflect rate, roughness, params z
    tail: bytes                   # normal, tile y, carry
    outline: glm.mat4 | None
    ids: bytes                    # _FALLBACK_IDS: entity, 0, 0, 0
    weights: bytes                # _FALLBACK_WEIGHTS: 0, 0, 1, 0, the plane's w, the offset
    key: tuple[str, TextureData | None, int, int]  # its draw's (build, normal map), without probes
    look: CompositeSurface


def fallback_surfaces(states: Sequence[SurfaceState]) -> list[_FallbackSurface]:
    """Each surface's fallback pieces (``_FallbackSurface``); a water surface's head and tail
    are packed again each frame (its waves move: ``_water_pieces``)."""
    found = []
    for state in states:
        look = surface_look(state)
        x, scale, y = look.tile_slots   # (no tile: as _composite_row's)
        head, tail = _water_pieces(look) if look.water is not None else (
            _PIECE_HEAD.pack(x, look.tint, scale, look.reflect_rate, look.roughness, look.params_z),
            _PIECE_TAIL.pack(look.normal, y, look.carry))
        found.append(_FallbackSurface(head, tail, look.outline, _FALLBACK_IDS.pack(look.entity & 0xFFFFFFFF, 0, 0, 0),
                                      _FALLBACK_WEIGHTS.pack(0.0, 0.0, 1.0, 0.0, look.plane_w, *look.offset),
                                      (look.fallback_variant, look.normal_map, 0, 0), look))
    return found


def water_row_f0(water: WaterLook) -> float:
    """A water's F0 as its composite row carries it (in the roughness's place): F0, plus
    WATER_UNDERSIDE where it is seen from below (mirror_composite.frag tells the two apart;
    F0 is at most 0.36, an index of 4)."""
    return water.f0 + WATER_UNDERSIDE if water.underside else water.f0


def _water_pieces(look: CompositeSurface) -> tuple[bytes, bytes]:
    """A water surface's head and tail: this frame's waves where the tile goes and F0 where
    the roughness goes (as ``composite_rows`` packs them)."""
    water = look.water
    (x, y), scale, rough = water.flow.offset, water.cross, water_row_f0(water)
    return (_PIECE_HEAD.pack(x, look.tint, scale, look.reflect_rate, rough, look.params_z),
            _PIECE_TAIL.pack(look.normal, y, look.carry))


def _ndc_rect(rect: tuple[int, int, int, int], size: tuple[int, int]) -> tuple[float, float, float, float]:
    """A pixel rectangle (x, y, width, height) of a ``size`` target as NDC x0, y0, x1, y1."""
    x, y, w, h = rect
    sx, sy = 2.0 / size[0], 2.0 / size[1]
    return x * sx - 1.0, y * sy - 1.0, (x + w) * sx - 1.0, (y + h) * sy - 1.0


def take_samples_queries(ctx: moderngl.Context, count: int) -> list[moderngl.Query]:
    """``count`` samples-passed queries from the context's free pool (made where it has too
    few): moderngl 5.13 cannot release a Query, so trees and engines made and closed on one
    context (probes, tests, editors) hand theirs back (``give_samples_queries``) instead of
    leaking them; the pool grows to the most any tree held at once."""
    pool = kept_on(ctx, "speculum.samples_queries", list)
    taken = pool[len(pool) - min(count, len(pool)):]
    del pool[len(pool) - len(taken):]
    return taken + [ctx.query(samples=True) for _ in range(count - len(taken))]


def give_samples_queries(ctx: moderngl.Context, queries: list[moderngl.Query]) -> None:
    """Hand queries back to the context's free pool (``take_samples_queries``)."""
    kept_on(ctx, "speculum.samples_queries", list).extend(queries)


@dataclass
class Claims:
    """A reflection level's candidate views: candidate i is drawn over ``rects[i]`` (x, y,
    width, height in this level's pixels) with the claim shader's ``ids[i]``: (parent view,
    surface entity, view index)."""

    ids: list[tuple[int, int, int]]
    rects: list[tuple[int, int, int, int]] | list[list[int]]

    def __len__(self) -> int:
        return len(self.rects)


class MirrorPasses:
    def __init__(self, renderer: Gpu, refraction_copy: RefractionCopy | None = None) -> None:
        self.renderer = renderer
        # Water's view composites read the level they go into, copied before them (its colour
        # and depth: mirror_composite.frag's WATER_REFRACTION); the scene pass's copies serve.
        self.refraction_copy = refraction_copy or RefractionCopy(renderer)
        ctx = renderer.ctx
        self.ctx = ctx
        shaders = renderer.shaders
        self.reset = shaders.program("rects.vert", "mirror_reset.frag")
        self.claim = shaders.program("claim.vert", "mirror_claim.frag")
        self.claim["parent_node_map"].value = PARENT_NODE_UNIT
        self.claim["parent_surface_map"].value = PARENT_SURFACE_UNIT
        self.uniforms = renderer.shaders.uniforms  # what the claim, composite and fallback programs hold
        # Each composite and fallback variant's draw, by the fog's defines (FogBlock.defines),
        # made the first time they are needed: when a level with mirrors or portals loads
        # (``prepare``: the main tree's) or a tree first composites (a probe's, the monitors'),
        # not with every engine (three trees of 18 draws each were a quarter of an engine's
        # making: 16 ms on llvmpipe, with the programs already linked).
        self._draws: dict[tuple, tuple[dict[str, _CompositeDraw], dict[str, _CompositeDraw]]] = {}
        # The SURFACE_MOTION builds, by the fog's defines and variant, made the first time a
        # moved surface's view is composited.
        self._moving_draws: dict[tuple[tuple, str], _CompositeDraw] = {}
        # The sharp and water variants' builds that draw a generated sky per pixel (SKY_VARIANTS),
        # by the fog's defines, the sky's build (sky_draw.sky_build), variant and motion.
        self._sky_draws: dict[tuple, _CompositeDraw] = {}
        # Each surface that moved since the last frame, by entity: the matrix taking a point
        # where its view shows it now (in the world of the view that sees the surface) to where
        # the surface showed it last frame (last frame's carry^-1 x this one's).  Set a frame
        # by the main tree's owner (the reflect stage) while TAA or motion blur follows motion;
        # empty: no view's composite adds any.
        self.surface_motion: dict[int, glm.mat4] = {}
        # The fallback draws' ids and weights (FallbackRows: a chunk's, written before its draw).
        self._fallback_block = ctx.buffer(reserve=_FALLBACK_IDS_BYTES + 32 * FALLBACK_ROWS)
        self.fallback_chunk = FALLBACK_ROWS  # rows a fallback draw takes, at most FALLBACK_ROWS (fewer: more draws)
        self.rough_atlas = RoughAtlas(renderer)
        # (weak references to the states, their probes' blends, their pieces, water rows:
        # _fallback_surfaces), let go when a state it was packed from goes (_keep_fallbacks)
        self._fallback_table: tuple | None = None
        self._claim_buffer: moderngl.Buffer | None = None  # the claims' triangles (claim.vert), grown as needed
        self._reset_vao: moderngl.VertexArray | None = None
        self._claim_vao: moderngl.VertexArray | None = None
        self._claims_written: tuple[Claims, tuple[int, int]] | None = None  # the run the buffer holds (prepare_level)
        # The query of every claim known to be empty before it is drawn (engine/render/claim_cull.py):
        # begun and ended once around nothing, so it counts 0 samples, and a view drawn on its
        # condition (predicted visibility) is skipped as that claim's would have skipped it.
        self.no_pixels = take_samples_queries(ctx, 1)[0]
        with self.no_pixels:
            pass

    def prepare_level(self, level: RenderTargets, parent: RenderTargets, claims: Claims,
                      queries: list[moderngl.Query], run: tuple[Claims, int] | None = None) -> None:
        """Write ``level``'s node image and depth mask for the candidate views ``claims``,
        counting each one's pixels in ``queries[i]`` (0: the surface is hidden there, or off
        the pixels its parent view drew).  A claim whose query is ``no_pixels`` is known to
        be empty (``engine/render/claim_cull.py``) and is not drawn, but its rectangle is
        reset, as a view drawn on that query's condition would need (its composite, its
        views' claims and its fallbacks read its node ids in its rectangle).  (``ViewTree``
        leaves such claims out, in either visibility: no view, and nothing reads a
        rectangle that is no view's.)  Outside the claims' rectangles nothing is written or
        read this frame.  Nothing waits here: the
        counts are read by ``claimed_pixels``, now (the CPU waits for the GPU) or a frame
        later (``ViewTree``'s visibility).

        ``run``: (the claims of several levels drawn one after another, where ``claims``
        start among them): their triangles are written once, by the first of those levels
        (of this size) that draws, and the others draw theirs from where they lie, so a level
        writes nothing (a chain of levels planned ahead: ``plan_ahead.ahead_columns``)."""
        if not claims:
            return
        ctx = self.ctx
        level.framebuffer.use()
        apply_pass_state(ctx, _CLAIM, (0, 0, *level.size))
        # Every claim's rectangle as two triangles, its ids on each vertex: one write.  The
        # reset draws them all at once (a rectangle reset twice is reset the same), then
        # each claim draws its own six vertices inside its query.
        count, first = len(claims), 0
        if run is None:
            self._write_claims(claims, level.size, None)
        else:
            written, first = self._claims_written, run[1]
            if written is None or written[0] is not run[0] or written[1] != level.size:
                self._write_claims(run[0], level.size, run[0])
        self._reset_vao.render(moderngl.TRIANGLES, vertices=6 * count, first=6 * first)
        bind_textures(ctx, ((parent.node, PARENT_NODE_UNIT), (parent.surface, PARENT_SURFACE_UNIT)))
        self.uniforms.set(self.claim, "to_parent", (parent.size[0] / level.size[0], parent.size[1] / level.size[1]))
        # A claim's cost on llvmpipe is linear in the claims, no cliff at some count: each
        # query's begin and end re-validate the fragment state (a new ~20 KB rasteriser state
        # in the scene per claim, as any state change between draws does).  The cliff a small
        # standalone script shows past ~12-16 of them is glibc handing that scene memory back
        # and faulting it in again each scene (~170 page faults at 32 claims); the engine's
        # frames take ~0-4 faults, so splitting a level's claims into chunks gains nothing.
        # (Calling the objects' ``mglo`` methods instead of the wrappers saved ~1% at 16
        # mirrors, within the noise, and hid the calls from benchmarks' GLCallCounter.)
        # A query's begin and end are most of a claim's GL cost on llvmpipe: a standalone
        # loop of 6-vertex draws took 2.3 us a draw with a query around each, 0.4 without.
        # Keeping an any-samples query active around them all does not help: the GL allows
        # one occlusion query at a time (the samples query's begin is INVALID_OPERATION).
        # On llvmpipe (Mesa 22.3) the first claim of a level waits on the CPU until the parent
        # level is rasterised: a draw that samples a texture a queued scene renders into
        # blocks the calling thread (a 640x360 target: 54 ms for that draw call against
        # 0.04 ms sampling another texture).  So on a software rasteriser a frame's levels
        # run their CPU work and their rasterising one after the other, in either visibility
        # (8 mirrors at 640x360: ~5.4 ms of a 13.7 ms frame waits in these draws, predicted
        # or exact); a GPU orders the read after the write without the CPU.  Taking the wait
        # away (claims reading last frame's images, an experiment) left the frame as it was:
        # the wait moves to the first composite, and the frame is bound by its work
        # (benchmarks/README.md, "Where an 8-mirror frame's time goes").

        render, empty = self._claim_vao.render, self.no_pixels
        for at, query in enumerate(queries[:count]):
            if query is not empty:
                with query:
                    render(moderngl.TRIANGLES, vertices=6, first=6 * (first + at))
        self.renderer.checkpoint("claims")

    def _write_claims(self, claims: Claims, size: tuple[int, int], run: Claims | None) -> None:
        """``claims``' triangles into the claims buffer, from its start; ``run``: the run they
        are (``prepare_level``), None: one level's."""
        vertices = self._claim_vertices(claims, size)
        if self._claim_buffer is None or self._claim_buffer.size < len(vertices):
            self._reserve_claims(len(vertices))
        self._claim_buffer.write(vertices)
        self._claims_written = None if run is None else (run, size)

    @staticmethod
    def _claim_vertices(claims: Claims, size: tuple[int, int]) -> bytes:
        """Each claim's rectangle as two clip-space triangles, each vertex with the claim's
        three ids (claim.vert's attributes)."""
        pack = _CLAIM_VERTICES.pack
        sx, sy = 2.0 / size[0], 2.0 / size[1]  # _ndc_rect's, inline: a level's claims in one loop
        out = []
        for (a, b, c), (x, y, w, h) in zip(claims.ids, claims.rects, strict=True):
            x0, y0, x1, y1 = x * sx - 1.0, y * sy - 1.0, (x + w) * sx - 1.0, (y + h) * sy - 1.0
            out.append(pack(x0, y0, a, b, c, x1, y0, a, b, c, x1, y1, a, b, c,
                            x0, y0, a, b, c, x1, y1, a, b, c, x0, y1, a, b, c))
        return b"".join(out)

    def claimed_pixels(self, queries: list[moderngl.Query]) -> list[int]:
        """The pixels each claim of ``queries`` got: the CPU waits until the GPU has drawn
        them (all issued before the first is read, so it waits once); ``no_pixels``, read
        without asking the GL, counted 0."""
        empty = self.no_pixels
        return [0 if query is empty else query.samples for query in queries]

    def _reserve_claims(self, size: int) -> None:
        """A claims buffer of at least ``size`` bytes (64 claims at least), with the reset's
        and the claims' vertex arrays over it."""
        for old in (self._reset_vao, self._claim_vao, self._claim_buffer):
            if old is not None:
                old.release()
        self._claim_buffer = self.ctx.buffer(reserve=max(size, 64 * _CLAIM_VERTICES.size))
        self._reset_vao = self.ctx.vertex_array(self.reset, [(self._claim_buffer, "2f 12x", "in_position")])
        self._claim_vao = self.ctx.vertex_array(self.claim, [(self._claim_buffer, "2f 3u", "in_position",
                                                              "in_claim")])

    def _builds(self) -> tuple[tuple[str, str], ...]:
        """The defines every composite and fallback build takes this frame: the fog's
        (``FogBlock.defines``) and the ripples' (``RippleAtlas.defines``: while a water's rings
        are alive, its block and heights bound for them)."""
        ripples = self.renderer.ripples
        if ripples.defines:
            ripples.bind()
            return self.renderer.fog.defines + ripples.defines
        return self.renderer.fog.defines

    def _variant_draws(self, fogging: tuple) -> tuple[dict[str, _CompositeDraw], dict[str, _CompositeDraw]]:
        """The composite and fallback variants' draws built with ``fogging`` (the fog's
        defines: ``FOG`` while the active camera's fog has a density), made the first time."""
        made = self._draws.get(fogging)
        if made is not None:
            return made
        composites = {variant: self._composite_draw(defines, fogging)
                      for variant, defines in COMPOSITE_VARIANTS.items()}
        fallbacks = {variant: self._composite_draw({"FALLBACK_ROWS": str(FALLBACK_ROWS), **defines}, fogging)
                     for variant, defines in FALLBACK_VARIANTS.items()}
        made = self._draws[fogging] = (composites, fallbacks)
        return made

    def _composite_draw(self, defines: Mapping[str, str], fogging: tuple) -> _CompositeDraw:
        """A composite build (``defines``, with ``fogging``'s) and its draw."""
        program = self.renderer.shaders.program("mirror_composite.vert", "mirror_composite.frag",
                                                defines={"ROUGH_TILE": f"{TILE}.0",
                                                         "WATER_UNDERSIDE": str(WATER_UNDERSIDE),
                                                         **defines, **dict(fogging)})
        assign_slots(program, _COMPOSITE_UNITS, {"FallbackRows": FALLBACK_BINDING, "Fog": FOG_BINDING,
                                                        "Ripples": RIPPLES_BINDING})
        return _CompositeDraw(self.ctx, program)

    def _composite_for(self, fogging: tuple, variant: str, moving: bool) -> _CompositeDraw:
        """The composite build of ``variant`` (``moving``: its SURFACE_MOTION build): a sharp
        or water mirror's under a generated sky draws the sky per pixel along the reflected
        ray (its ``sky_build``, the sky pass's function: as sharp as the sky behind the
        mirror, where the cube map's texels showed a sun or a cloud's edge in blocks), its
        uniforms written when the sky changed; the others sample the cube map."""
        sky = sky_build(self.renderer.sky_model) if variant in SKY_VARIANTS else ()
        if not sky:
            return self._moving_draw(fogging, variant) if moving else self._variant_draws(fogging)[0][variant]
        key = (fogging, sky, variant, moving)
        draw = self._sky_draws.get(key)
        if draw is None:
            defines = {**COMPOSITE_VARIANTS[variant], **dict(sky), **({"SURFACE_MOTION": "1"} if moving else {})}
            draw = self._sky_draws[key] = self._composite_draw(defines, fogging)
            wire_sky(draw.program)
        if draw.sky_version != self.renderer.sky_version:
            write_sky(draw.program, self.renderer.sky_model)
            draw.sky_version = self.renderer.sky_version
        return draw

    def _moving_draw(self, fogging: tuple, variant: str) -> _CompositeDraw:
        """The ``SURFACE_MOTION`` build of a composite variant, made the first time."""
        draw = self._moving_draws.get((fogging, variant))
        if draw is None:
            draw = self._moving_draws[(fogging, variant)] = self._composite_draw(
                {**COMPOSITE_VARIANTS[variant], "SURFACE_MOTION": "1"}, fogging)
        return draw

    def prepare(self) -> None:
        """The reset's and every composite variant's buffers and vertex arrays, made now
        (when a level loads: ``Renderer.prepare_programs``'s caller) rather than when the
        first mirror comes into view; under a generated sky, the sharp and water variants'
        builds that draw it per pixel too (``_composite_for``; with the fog's defines as they are
        now); with a rippling water, the ``RIPPLES`` builds of them all (its first drop would
        otherwise build them: ~90 ms on llvmpipe)."""
        if self._claim_buffer is None:
            self._reserve_claims(0)
        # A rippling water's builds too: made with the level, not at its first drop.
        fog = self.renderer.fog.defines
        rippling = self._variant_draws(fog + RIPPLE_DEFINES) if self.renderer.ripples.waters else ({}, {})
        builds = (fog, fog + RIPPLE_DEFINES) if self.renderer.ripples.waters else (fog,)
        sky_draws = [self._composite_for(fogging, variant, False)
                     for fogging in builds for variant in sorted(SKY_VARIANTS)]
        composites, fallbacks = self._variant_draws(())
        for draw in (*composites.values(), *fallbacks.values(), *sky_draws, *rippling[0].values(),
                     *rippling[1].values()):
            if draw.vao is None:
                draw.prepare()

    def prepare_composites(self, composites: list[Composite], parent_size: tuple[int, int]) -> PreparedComposites:
        """The CPU half of compositing a level into a parent of ``parent_size`` pixels: rough
        views' atlas tiles and each variant's instance rows.  Needs no pixels, so the
        ReflectionSystem does it while the GPU still draws the level."""
        rough = [(c.view_index, c.level_rect) for c in composites if c.surface.variant.startswith("rough")]
        tiles = place_tiles(rough)
        groups: dict[tuple[str, TextureData | None], list[Composite]] = {}
        moving = []
        for c in composites:
            c.tile = tiles.get(c.view_index)
            key = (c.surface.variant, c.surface.normal_map)
            motion = self.surface_motion.get(c.surface.entity) if self.surface_motion else None
            if motion is None:
                groups.setdefault(key, []).append(c)
            else:
                view_proj = glm.mat4.from_bytes(c.parent_view.camera_block()[_BLOCK_VIEW_PROJ])
                moving.append((key, composite_rows([c], parent_size), view_proj.to_bytes(),
                               (view_proj * motion).to_bytes()))
        rows = {key: composite_rows(group, parent_size) for key, group in groups.items()}
        return PreparedComposites(rough, rows, moving)

    def prepare_views(self, views: Sequence[CompositeView], rects: Sequence[tuple[int, int, int, int]],
                      parent_size: tuple[int, int]) -> PreparedComposites:
        """``prepare_composites`` for a level's views as the view tree holds them (``rects``:
        each one's rectangle in the parent level's pixels), their rows packed straight from
        them, grouped by build and normal map: no ``Composite`` a view (a level with a rough
        view, whose tile is placed first, goes through them)."""
        if len(views) == 1:  # (a chain's level: one row, no grouping)
            view, look = views[0], surface_look(views[0].surface)
            if not look.variant.startswith("rough") and view.surface.entity not in self.surface_motion:
                return PreparedComposites([], {(look.variant, look.normal_map): _composite_row(
                    look, view.parent.view.camera_block(), rects[0], view.view.scissor, None, view.fade, view.index,
                    parent_size, {})})
        looks = [surface_look(view.surface) for view in views]
        moved = self.surface_motion
        if any(look.variant.startswith("rough") for look in looks) or (
                moved and any(view.surface.entity in moved for view in views)):
            return self.prepare_composites([Composite(view.index, rect, view.view.scissor, view.parent.view, look,
                                                      fade=view.fade)
                                            for view, rect, look in zip(views, rects, looks, strict=True)],
                                           parent_size)
        groups: dict[tuple[str, TextureData | None], list[bytes]] = {}
        flattened: dict[bytes, glm.mat4] = {}
        last_key, rows = None, []
        for view, rect, look in zip(views, rects, looks, strict=True):
            key = (look.variant, look.normal_map)
            if key != last_key:
                last_key, rows = key, groups.setdefault(key, [])
            rows.append(_composite_row(look, view.parent.view.camera_block(), rect, view.view.scissor, None,
                                       view.fade, view.index, parent_size, flattened))
        return PreparedComposites([], {key: b"".join(rows) for key, rows in groups.items()})

    def composite_level(self, parent: RenderTargets, level: RenderTargets, prepared: PreparedComposites,
                        parent_is_root: bool = False) -> None:
        """Blend every view of ``level`` into its surface's pixels of ``parent`` (``parent_is_root``:
        a root view's level, whose rays start at its eye, for the fog): one instanced
        draw per composite variant present, a quad per view over its surface (each pixel
        belongs to one view, so the quads never blend over each other's pixels).  Rough
        views first get their own blur source (``RoughAtlas``).  Not flushed: a tree's
        composites go to the GPU together (``ViewTree``'s step 5 flushes once after the
        last; each composite reads what the one before wrote, so a flush between them gained
        the GPU nothing and cost a GL call a level)."""
        if not prepared.rows and not prepared.moving:
            return
        ctx = self.ctx
        fogging = self._builds()
        if prepared.rough:
            self.rough_atlas.isolate(level, prepared.rough)
        # Water bends what lies below it: the level as it stands (its colour and depth) copied
        # first, read where the refracted rays meet the floor (mirror_composite.frag water_below).
        water = any(key[0] in WATER_VARIANTS for key in prepared.rows) or any(
            key[0] in WATER_VARIANTS for key, *_ in prepared.moving)
        if water:
            self.refraction_copy.take(parent, False)
            bind_texture(ctx, parent.node, PARENT_NODE_UNIT)  # (the parent view's own pixels only)
        parent.composite_framebuffer.use()
        # Colour: reflection x rate + own x (1 - rate); alpha (coverage) is kept.
        apply_pass_state(ctx, _COMPOSITE, (0, 0, *parent.size))
        bind_textures(ctx, ((level.color, _COLOR_UNIT), (level.seen, _SEEN_UNIT), (level.node, _NODE_UNIT),
                            (self.renderer.sky, SKY_UNIT)))
        bind_sky(self.renderer)   # (a generated sky's table and space, for the SKY_VARIANTS builds)
        if prepared.rough:
            bind_texture(self.ctx, self.rough_atlas.texture, ATLAS_UNIT)
        draws = [(key, rows, None) for key, rows in prepared.rows.items()]
        draws += [(key, row, (view_proj, moved)) for key, row, view_proj, moved in prepared.moving]
        for (variant, normal_map), variant_rows, motion in draws:
            if normal_map is not None:
                texture = self.renderer.normal_map_texture(normal_map)
                if texture is None:  # the mirror's own batch holds it; none drawn: the flat build
                    variant = variant.removesuffix("_bumpy")
                else:
                    bind_texture(self.ctx, texture, NORMAL_UNIT)
            draw = self._composite_for(fogging, variant, motion is not None)
            program = draw.program
            uniforms = self.uniforms
            if variant.startswith("rough"):
                uniforms.set(program, "atlas_size", self.rough_atlas.texture.size)
            uniforms.set(program, "parent_size", parent.size)
            uniforms.set(program, "to_reflection", (level.size[0] / parent.size[0], level.size[1] / parent.size[1]))
            if self.renderer.fog.defines:   # (FOG builds: the ripples' defines ride in ``fogging`` too)
                uniforms.set(program, "fog_from_eye", parent_is_root)
            if motion is not None:
                uniforms.write(program, "parent_view_proj", motion[0])
                uniforms.write(program, "moved_view_proj", motion[1])
            draw.draw(variant_rows, self.renderer.shaders.reloads)
        self.renderer.checkpoint("composite")

    def prepare_fallbacks(self, fallbacks: Fallbacks, size: tuple[int, int],
                          probes: Mapping[int, ProbeBlend]) -> PreparedFallbacks:
        """The CPU half of a level's fallbacks (drawn into a level of ``size`` pixels): their
        rows, grouped by build, normal map and the probes of their surfaces (``probes``, by
        surface entity: the extract stage's ``SurfaceBlends``; the probes are uniforms of a
        draw, their weights ride in the row's extras), in the order they were added.

        A row is a composite's (``composite_rows``, with the parent's rectangle as the view's
        and no fade or tile) and its extras (mirror_composite.vert's FallbackRows), joined
        from pieces packed once: each parent's (its rectangle, camera and node, once a
        level) and each surface's (``_FallbackSurface``, kept while the states are); a row
        packs only its corners (the outline in the parent's clip space: one glm product,
        ~0.07 us; numpy's for 40 rows at once, rounded as glm's, cost 3 times as much, and a
        level's rows a column at a time cost ~25 us whatever their count).  The 16-mirror
        ring's 36 rows a level at 32 x 18 took 62 us packed through a Composite each, 22 us so."""
        count = len(fallbacks)
        if not count:
            return PreparedFallbacks({}, 0)
        surfaces, water = self._fallback_surfaces(fallbacks.states, probes)
        parents = fallbacks.parents
        pieces: list[tuple | None] = [None] * len(parents)  # each parent's, packed when first read
        if water:  # this frame's waves
            surfaces = list(surfaces)
            for row in water:
                head, tail = _water_pieces(surfaces[row].look)
                surfaces[row] = replace(surfaces[row], head=head, tail=tail)
        groups: dict[tuple, tuple[list[bytes], list[bytes], list[bytes]]] = {}
        last_key, last = None, None
        shares, ends = fallbacks.share, fallbacks.end
        for i, (p, s) in enumerate(zip(fallbacks.at, fallbacks.surface, strict=True)):
            surface = surfaces[s]
            parent = pieces[p]
            if parent is None:
                parent = pieces[p] = self._fallback_parent(parents[p], size)
            if surface.key is not last_key:
                last_key = surface.key
                last = groups.get(last_key)
                if last is None:
                    last = groups[last_key] = ([], [], [])
            rows, ids, weights = last
            outline = surface.outline
            rows += ((parent[0] * outline).to_bytes() if outline is not None else parent[1], parent[2],
                     surface.head, parent[3], surface.tail)
            if (ends is None or ends[i] < 0) and not parent[4]:
                ids.append(surface.ids)
            else:
                ids.append(_FALLBACK_IDS.pack(surface.look.entity & 0xFFFFFFFF,
                                              0 if ends is None or ends[i] < 0 else ends[i] + 1, parent[4], 0))
            if shares is None or shares[i] == 1.0:
                weights.append(surface.weights)
            else:
                w1, w2, _, _, plane_w, *offset = _FALLBACK_WEIGHTS.unpack(surface.weights)
                weights.append(_FALLBACK_WEIGHTS.pack(w1, w2, shares[i], 0.0, plane_w, *offset))
        chunk = self.fallback_chunk
        return PreparedFallbacks({key: [(b"".join(rows[5 * at:5 * (at + chunk)]), b"".join(ids[at:at + chunk]),
                                         b"".join(weights[at:at + chunk])) for at in range(0, len(ids), chunk)]
                                  for key, (rows, ids, weights) in groups.items()}, count)

    @staticmethod
    def _fallback_parent(parent: FallbackParent,
                         size: tuple[int, int]) -> tuple[glm.mat4, bytes, bytes, bytes, int]:
        """A parent view's pieces of its fallbacks' rows: its view-projection flattened onto
        z = 0 (times an outline: the corners), the corners of its rectangle (a surface with
        no outline), its head and its node (``_PIECE_PARENT``, ``_PIECE_NODE``), and its way
        scale's bits for the rows' ids (``way_scale_bits``: 0 for a metre a metre)."""
        view = parent.view
        block = view.camera_block()
        x, y, w, h = rect = view.scissor if parent.level and view.scissor is not None else (0, 0, *view.size)
        x0, y0, x1, y1 = _ndc_rect(rect, size)
        return (_FLATTEN_Z * glm.mat4.from_bytes(block[_BLOCK_VIEW_PROJ]),
                struct.pack("<16f", x0, y0, 0.0, 1.0, x0, y1, 0.0, 1.0, x1, y0, 0.0, 1.0, x1, y1, 0.0, 1.0),
                _PIECE_PARENT.pack(x, y, x + w, y + h, block[_BLOCK_INVERSE], block[_BLOCK_EYE]),
                _PIECE_NODE.pack(float(parent.index)), way_scale_bits(view))

    def _fallback_surfaces(self, states: Sequence[SurfaceState], probes: Mapping[int, ProbeBlend]
                           ) -> tuple[list[_FallbackSurface], list[int]]:
        """``fallback_surfaces(states)`` with each surface's probes of ``probes`` in its key
        and weights, and the rows of water surfaces (whose pieces the caller packs again),
        kept while the states are the same objects (the same every frame while no surface
        changes: ``surface_look`` keeps a state's look as long) and their probes' blends the
        same (while no probe or surface moves)."""
        kept = self._fallback_table
        blends = [probes.get(state.entity) for state in states]
        if kept is not None and kept[1] == blends and [ref() for ref in kept[0]] == states:  # (a state: by identity)
            return kept[2], kept[3]
        found = fallback_surfaces(states)
        for row, piece in enumerate(found):
            blend = probes.get(piece.look.entity)
            if blend is None or not (blend.probes or blend.weights):
                continue  # the sky alone: as no blend
            owners = (*blend.probes, 0, 0)[:2]
            variant, normal_map, _, _ = piece.key
            if owners != (0, 0):
                variant = variant.replace("fallback", "fallback_probes", 1)
            w1, w2 = (*blend.weights, 0.0, 0.0)[:2]
            look = piece.look
            found[row] = replace(piece, key=(variant, normal_map, *owners),
                                 weights=_FALLBACK_WEIGHTS.pack(w1, w2, 1.0, 0.0, look.plane_w, *look.offset))
        water = [row for row, piece in enumerate(found) if piece.look.water is not None]
        self._keep_fallbacks(states, blends, found, water)
        return found, water

    def _keep_fallbacks(self, states: Sequence[SurfaceState], blends: list[ProbeBlend | None],
                        found: list[_FallbackSurface], water: list[int]) -> None:
        """Keep ``_fallback_surfaces``'s table, holding its states weakly: when one of them
        goes (its surface changed or was deleted) the table is let go, so the pieces (their
        normal maps, their waters' looks) do not outlive the surfaces when no fallback is
        drawn again to replace them (a level left with no surface)."""
        passes = weakref.ref(self)

        def forget(gone: weakref.ref) -> None:
            held = passes()
            table = held._fallback_table if held is not None else None
            if table is not None and any(ref is gone for ref in table[0]):
                held._fallback_table = None

        self._fallback_table = (tuple(weakref.ref(state, forget) for state in states), blends, found, water)

    def draw_fallbacks(self, parent: RenderTargets, level: RenderTargets | None, prepared: PreparedFallbacks,
                       parent_is_root: bool = False) -> None:
        """Blend each fallback of ``prepared`` over its surface's pixels in ``parent`` (before
        the views of ``level``, the one below, are composited there: a partly faded view's
        composite goes over its fallback).  ``level`` is read for end views' holes."""
        if not prepared.groups:
            return
        ctx = self.ctx
        fogging = self._builds()
        renderer = self.renderer
        if any("_water" in key[0] for key in prepared.groups):
            # Water with no view over it bends what lies below it as a view's composite does
            # (composite_level): the parent as it stands, copied first.
            self.refraction_copy.take(parent, False)
        parent.composite_framebuffer.use()
        apply_pass_state(ctx, _COMPOSITE, (0, 0, *parent.size))
        # With no level below, the level's images are blank (``Gpu.blank_ids``): the program
        # reads them only for end views, but its samplers must not find what is left on their
        # units (the parent's own seen image, attached here: a rendering feedback loop).
        bind_textures(ctx, ((parent.node, FALLBACK_PARENT_UNITS[0]), (parent.surface, FALLBACK_PARENT_UNITS[1]),
                            (renderer.blank_ids, _SEEN_UNIT), (renderer.blank_ids, _NODE_UNIT),
                            (renderer.sky, SKY_UNIT)) if level is None else
                      ((parent.node, FALLBACK_PARENT_UNITS[0]), (parent.surface, FALLBACK_PARENT_UNITS[1]),
                       (level.seen, _SEEN_UNIT), (level.node, _NODE_UNIT), (renderer.sky, SKY_UNIT)))
        block = self._fallback_block
        bind_uniform_block(ctx, block, FALLBACK_BINDING)
        uniforms = self.uniforms
        to_child = (1.0, 1.0) if level is None else (level.size[0] / parent.size[0], level.size[1] / parent.size[1])
        for (variant, normal_map, first, second), chunks in prepared.groups.items():
            if normal_map is not None:
                texture = renderer.normal_map_texture(normal_map)
                if texture is None:  # the mirror's own batch holds it; none drawn: the flat build
                    variant = variant.removesuffix("_bumpy")
                else:
                    bind_texture(self.ctx, texture, NORMAL_UNIT)
            draw = self._variant_draws(fogging)[1][variant]
            program = draw.program
            for prefix, probe, unit in (("probe", first, PROBE_UNIT), ("probe2", second, PROBE2_UNIT)):
                if not first:
                    break  # a draw with no probes is a build without them
                for name, value in zip(("position", "box_min", "box_max"), self._bind_probe(probe, unit),
                                       strict=True):
                    if f"{prefix}_{name}" in program:
                        uniforms.set(program, f"{prefix}_{name}", value)
            uniforms.set(program, "parent_size", parent.size)
            uniforms.set(program, "to_reflection", (1.0, 1.0))
            if self.renderer.fog.defines:   # (FOG builds: the ripples' defines ride in ``fogging`` too)
                uniforms.set(program, "fog_from_eye", parent_is_root)
            if "to_child" in program:
                uniforms.set(program, "to_child", to_child)
            for rows, ids, weights in chunks:
                block.write(ids.ljust(_FALLBACK_IDS_BYTES, b"\0") + weights)  # (a draw reads its instances' only)
                draw.draw(rows, renderer.shaders.reloads)
        renderer.stats.reflection_fallbacks += prepared.count
        renderer.checkpoint("fallback")

    def _bind_probe(self, probe: int, unit: int) -> tuple[tuple[float, ...], ...]:
        """Bind ``probe``'s cube map to ``unit`` and give its lookup uniforms; the sky where
        there is none (0), it has no capture yet, or it is the probe being captured (nothing
        samples a cube while it is drawn into: what would read it reads the sky, as in the
        scene pass)."""
        renderer = self.renderer
        cube = renderer.probe_cubes.get(probe) if probe and probe != renderer.capturing else None
        if cube is not None:
            bind_texture(self.ctx, cube.texture, unit)
            return cube.lookup()
        bind_texture(self.ctx, renderer.sky, unit)
        return _NO_PROBE

    def release(self) -> None:
        for obj in (self._reset_vao, self._claim_vao, self._claim_buffer):
            if obj is not None:
                obj.release()
        give_samples_queries(self.ctx, [self.no_pixels])
        self._fallback_block.release()
        for composites, fallbacks in self._draws.values():
            for draw in (*composites.values(), *fallbacks.values()):
                draw.release()
        for draw in (*self._moving_draws.values(), *self._sky_draws.values()):
            draw.release()
        self.rough_atlas.release()
