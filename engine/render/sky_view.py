"""An atmosphere's sky-view table drawn on the GPU (``shaders/sky_view.frag``): the radiance
per unit of sunlight along each of the table's ways, which the sky pass and the sky's cube
map read (``shaders/include/sky_model.glsl``'s ATMOSPHERE build).

Why on the GPU.  The table depends on the sun's elevation, so a sun that rises or sets needs
a new one; made with numpy (``engine.render.atmosphere.sky_view_table``, still the reference
the tests hold this one to) it took about 30 ms of the 2-core machine's CPU, a hitch each
time the sun had moved a quarter degree.  Here it is one full-screen triangle over 48 x 96
texels (about 3 ms of llvmpipe's; not measured on a GPU), drawn again whenever the elevation
moves by ``atmosphere.TABLE_STEP_DEGREES`` (0.02), as Hillaire's is each frame.
Its two inputs, the transmittance and multiple-scattering tables, depend on the air alone:
made with numpy once an air and uploaded.  A moon's table (the air's moonlight, the same
scattering for a light at the moon's elevation) is a second ``SkyView`` that borrows the
sun's air tables (``tables_from``).
"""
from __future__ import annotations

import moderngl
import numpy as np

from engine.render.atmosphere import VIEW_SIZE, Air, glsl_defines, multiple_scattering_table, transmittance_table
from engine.render.bindings import (
    AIR_SCATTERING_UNIT,
    AIR_TRANSMITTANCE_UNIT,
    PassState,
    apply_pass_state,
    bind_texture,
)
from engine.render.gpu import Gpu
from engine.render.targets import release_target


def _table_texture(ctx: moderngl.Context, table: np.ndarray) -> moderngl.Texture:
    """An RGBA16F texture of a (rows, columns, 3) table, filtered linearly, clamped."""
    rows, columns = table.shape[:2]
    texels = np.concatenate([table, np.ones((rows, columns, 1))], -1).astype(np.float16)
    texture = ctx.texture((columns, rows), 4, texels.tobytes(), dtype="f2")
    texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
    texture.repeat_x = texture.repeat_y = False
    return texture


class SkyView:
    """Draws the sky-view table of an air and a sun's elevation; keeps the air's two tables
    and the target (its colour texture is the table: ``texture``) until ``release``."""

    STATE = PassState()  # no depth test, no blending, no clip distances

    def __init__(self, renderer: Gpu, tables_from: SkyView | None = None) -> None:
        self.renderer = renderer
        self.ctx = renderer.ctx
        self._lender = tables_from   # another table's SkyView whose air tables this one reads
        self._air: Air | None = None
        self._tables: tuple[moderngl.Texture, moderngl.Texture] | None = None
        self._target: moderngl.Framebuffer | None = None
        self._vao: moderngl.VertexArray | None = None
        self.key: tuple = ()   # (air, elevation) the target holds
        self.draws = 0         # tables drawn (tests count them)

    @property
    def texture(self) -> moderngl.Texture | None:
        return None if self._target is None else self._target.color_attachments[0]

    def draw(self, air: Air, elevation_degrees: float) -> moderngl.Texture:
        """The table for ``air`` with the sun ``elevation_degrees`` up (drawn unless the target
        holds it already)."""
        key = (air, float(elevation_degrees))
        if key == self.key and self._target is not None:
            return self.texture
        ctx = self.ctx
        tables = self._air_tables(air)
        if self._target is None:
            rows, columns = VIEW_SIZE
            self._target = ctx.framebuffer([ctx.texture((columns, rows), 4, dtype="f2")])
            self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
            self.texture.repeat_x = self.texture.repeat_y = False
        vao = self._vertex_array()
        program = vao.program
        elevation = np.radians(elevation_degrees)
        program["sun"].value = (float(np.cos(elevation)), float(np.sin(elevation)), 0.0)
        program["rayleigh_scale"].value = air.rayleigh
        program["haze_scale"].value = air.haze
        program["multiple"].value = 1.0 if air.multiple else 0.0
        program["eye_km"].value = air.eye_km
        program["transmittance_table"].value = AIR_TRANSMITTANCE_UNIT
        program["scattering_table"].value = AIR_SCATTERING_UNIT
        self._target.use()
        apply_pass_state(ctx, self.STATE, (0, 0, *self._target.size))
        bind_texture(ctx, tables[0], AIR_TRANSMITTANCE_UNIT)
        bind_texture(ctx, tables[1], AIR_SCATTERING_UNIT)
        vao.render(moderngl.TRIANGLES, vertices=3)
        self.key = key
        self.draws += 1
        return self.texture

    def _air_tables(self, air: Air) -> tuple[moderngl.Texture, moderngl.Texture]:
        """The transmittance and multiple-scattering tables of ``air`` (the lender's, if any),
        made and uploaded when the air is another."""
        if self._lender is not None:
            return self._lender._air_tables(air)
        if air.column != self._air or self._tables is None:   # (the same for every altitude)
            self._release_tables()
            self._tables = (_table_texture(self.ctx, transmittance_table(air)),
                            _table_texture(self.ctx, multiple_scattering_table(air)))
            self._air = air.column
        return self._tables

    def _vertex_array(self) -> moderngl.VertexArray:
        program = self.renderer.shaders.program("fullscreen.vert", "sky_view.frag", defines=glsl_defines())
        if self._vao is None or self._vao.program is not program:
            if self._vao is not None:
                self._vao.release()
            self._vao = self.ctx.vertex_array(program, [])
        return self._vao

    def _release_tables(self) -> None:
        if self._tables is not None:
            for texture in self._tables:
                texture.release()
        self._tables, self._air = None, None

    def release(self) -> None:
        """Everything it holds (the renderer's sky no longer an atmosphere, or closing)."""
        self._release_tables()
        if self._target is not None:
            release_target(self._target)
            self._target = None
        if self._vao is not None:
            self._vao.release()
            self._vao = None
        self.key = ()
