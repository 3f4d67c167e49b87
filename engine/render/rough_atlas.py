"""Per-view blur sources for rough mirrors: each rough view of a level gets its own tile.

A rough mirror samples its reflection with a roughness mip bias (``lod += 2/(1-m)^2 - 1``,
see ``roughness_lod_bias`` in shaders/include/ggx.glsl).  If each mirror rendered into its
own texture, the coarse mips would average that mirror's reflection only.  Here the views
of a level share one screen-sized image, whose coarse mips would average every mirror's
reflection (and pixels no view owns): a rough mirror next to another would show its
neighbour's colours.  So before a level is composited, each of its
rough views is copied into its own T x T tile of an atlas - its own pixels only, everything
else empty - and the atlas is mipmapped.  Tiles sit on a power-of-two grid, so up to mip
log2(T) no texel straddles two tiles; the composite keeps its samples half a texel inside.
A rectangle larger than T is scaled down into its tile (a rough mirror is blurred anyway).
The atlas is as wide as the level's rough views need (1, 2, 4 or 8 tiles, ``atlas_grid``),
one image kept for each size a tree uses: ``glGenerateMipmap`` filters the whole image, and
an atlas of eight columns for one rough view mipmapped seven empty tiles (the sample level,
640x360 on llvmpipe: four atlases a frame of 2048x256 texels, 9.5 ms of its frame).
"""
from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from engine.render.bindings import LEVEL_UNITS, PassState, apply_pass_state, bind_texture
from engine.render.gpu import Gpu
from engine.render.targets import RenderTargets, release_framebuffer

TILE = 256
COLUMNS = 8
KEPT_SIZES = 4  # atlas sizes a tree keeps (RoughAtlas._use_size): 1, 2, 4 and 8 columns of one row

_ROW_DTYPE = np.dtype([("tile", "<f4", (4,)), ("source", "<f4", (4,)), ("place", "<f4", (2,)),
                       ("scale", "<f4"), ("view", "<f4")])
_FORMAT = "4f 4f 2f 1f 1f/i"
_COPY = PassState()  # no depth, cull, blend or clip distances
_ATTRIBUTES = ("in_tile", "in_source", "in_place", "in_scale", "in_view")


@dataclass(frozen=True)
class Tile:
    """Where a rough view's blur source is: its first texel in the atlas and the scale from
    its level's pixels to tile texels (<= 1)."""

    x: int
    y: int
    scale: float


def atlas_grid(count: int) -> tuple[int, int]:
    """The atlas's columns and rows of tiles for ``count`` rough views: as many columns as the
    views need up to ``COLUMNS``, a power of two (few sizes, each kept), then rows."""
    columns = min(COLUMNS, 1 << max(0, count - 1).bit_length())
    return columns, -(-count // columns)


def place_tiles(views: list[tuple[int, tuple[int, int, int, int]]]) -> dict[int, Tile]:
    """Each (view index, rectangle) its tile, in list order on the atlas grid (no GL: the
    composite's rows are built from this before the level's pixels are ready)."""
    columns = atlas_grid(len(views))[0]
    return {view: Tile((i % columns) * TILE, (i // columns) * TILE, min(1.0, TILE / max(w, h)))
            for i, (view, (_, _, w, h)) in enumerate(views)}


class RoughAtlas:
    def __init__(self, renderer: Gpu) -> None:
        self.renderer = renderer
        self.ctx = renderer.ctx
        self.program = renderer.shaders.program("rough_isolate.vert", "rough_isolate.frag")
        self.program["level_color"].value, self.program["level_nodes"].value = LEVEL_UNITS
        self.texture: moderngl.Texture | None = None  # the atlas the last isolate drew (its size: atlas_grid)
        self._framebuffer: moderngl.Framebuffer | None = None
        self._atlases: dict[tuple[int, int], tuple[moderngl.Texture, moderngl.Framebuffer]] = {}  # by size
        self._rows: moderngl.Buffer | None = None
        self._vao: moderngl.VertexArray | None = None

    def isolate(self, level: RenderTargets, views: list[tuple[int, tuple[int, int, int, int]]]) -> dict[int, Tile]:
        """Copy each (view index, rectangle in ``level``'s pixels) into its own tile and
        build the atlas mips; returns each view's tile.  One instanced draw."""
        if not views:
            return {}
        ctx = self.ctx
        columns, rows_needed = atlas_grid(len(views))
        self._use_size(columns * TILE, rows_needed * TILE)
        width, height = self.texture.size
        rows = np.zeros(len(views), _ROW_DTYPE)
        tiles = place_tiles(views)
        for row, (view, rect) in zip(rows, views, strict=True):
            tile = tiles[view]
            row["tile"] = (2.0 * tile.x / width - 1.0, 2.0 * tile.y / height - 1.0,
                           2.0 * (tile.x + TILE) / width - 1.0, 2.0 * (tile.y + TILE) / height - 1.0)
            row["source"] = rect
            row["place"] = (tile.x, tile.y)
            row["scale"] = tile.scale
            row["view"] = float(view)
        if self._rows is None or self._rows.size < rows.nbytes:
            if self._vao is not None:
                self._vao.release()
                self._rows.release()
            self._rows = ctx.buffer(reserve=max(rows.nbytes, 32 * _ROW_DTYPE.itemsize))
            self._vao = ctx.vertex_array(self.program, [(self._rows, _FORMAT, *_ATTRIBUTES)])
        self._rows.write(rows.tobytes())
        self._framebuffer.use()
        apply_pass_state(ctx, _COPY, (0, 0, width, height))
        bind_texture(self.ctx, level.color, LEVEL_UNITS[0])
        bind_texture(self.ctx, level.node, LEVEL_UNITS[1])
        self._vao.render(moderngl.TRIANGLE_STRIP, vertices=4, instances=len(views))
        self.texture.build_mipmaps(0, int(np.log2(TILE)))
        self.renderer.checkpoint("rough atlas")
        return tiles

    def _use_size(self, width: int, height: int) -> None:
        """The atlas of exactly this size, made the first time (at most ``KEPT_SIZES`` kept:
        the one used longest ago goes)."""
        size = (width, height)
        found = self._atlases.pop(size, None)
        if found is None:
            while len(self._atlases) >= KEPT_SIZES:
                self._release(self._atlases.pop(next(iter(self._atlases))))
            texture = self.ctx.texture(size, 4, dtype="f2")
            texture.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
            texture.repeat_x = texture.repeat_y = False
            found = (texture, self.ctx.framebuffer([texture]))
        self._atlases[size] = found  # (the most recently used last)
        self.texture, self._framebuffer = found

    @staticmethod
    def _release(atlas: tuple[moderngl.Texture, moderngl.Framebuffer]) -> None:
        texture, framebuffer = atlas
        release_framebuffer(framebuffer)
        texture.release()

    def held(self) -> int:
        """Atlas images held now."""
        return len(self._atlases)

    def release(self) -> None:
        for atlas in self._atlases.values():
            self._release(atlas)
        self._atlases.clear()
        self.texture = self._framebuffer = None
        for obj in (self._vao, self._rows):
            if obj is not None:
                obj.release()
        self._vao = self._rows = None
