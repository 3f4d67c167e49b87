"""A generated sky's cube map drawn on the GPU from its function (``shaders/sky_cube.frag``,
the sky pass's ``include/sky_model.glsl``), a face at a time into a 2D target copied into
the face (``RawGL.copy_to_cube_face``: the plain way every driver draws right; a face
attached straight to a framebuffer is a path the self-check must trust first), then its
mips.

Why on the GPU.  Made with numpy (``engine.render.sky.build_faces``, still the reference the
tests hold it to) a 128-texel sky took about 7 ms of the 2-core machine's CPU to evaluate,
project and upload: a hitch each time a turning sun moved a degree.  Here it is six
full-screen triangles and a mip build, a fraction of a millisecond of CPU, and its light
comes in closed form (``engine.render.irradiance.generated_sky_sh``) instead of from its texels.
"""
from __future__ import annotations

import moderngl

from engine.render.bindings import (
    SCRATCH_UNIT,
    PassState,
    apply_pass_state,
)
from engine.render.gpu import Gpu
from engine.render.sky import SEAMLESS_CUBE_MAP, SkyModel
from engine.render.sky_draw import bind_sky, sky_build, wire_sky, write_sky
from engine.render.targets import release_target


class SkyBake:
    """Draws generated skies' cube maps; keeps the face target (one size at a time)."""

    STATE = PassState()  # no depth test, no blending, no clip distances

    def __init__(self, renderer: Gpu) -> None:
        self.renderer = renderer
        self.ctx = renderer.ctx
        self._target: moderngl.Framebuffer | None = None
        self._vao: moderngl.VertexArray | None = None

    def bake(self, model: SkyModel, size: int) -> moderngl.TextureCube:
        """A new mipmapped RGBA16F cube map of ``size`` texels a face holding ``model``'s sky,
        filtered as ``engine.render.sky.upload_cube``'s (seamless, trilinear).  RGBA, as the
        probes' cubes: the copy's source and destination the same colour-renderable format
        (GL 4.1 does not require RGB16F to be one)."""
        ctx = self.ctx
        cube = ctx.texture_cube((size, size), 4, dtype="f2")
        try:
            target = self._face_target(size)
            vao = self._vertex_array(sky_build(model))
            program = vao.program
            wire_sky(program)   # (the clouds' block: Renderer._set_sky_view wrote it)
            bind_sky(self.renderer)
            write_sky(program, model)
            program["face_size"].value = float(size)
            for face in range(6):
                target.use()
                apply_pass_state(ctx, self.STATE, (0, 0, size, size))
                program["face"].value = face
                vao.render(moderngl.TRIANGLES, vertices=3)
                self.renderer.raw_gl.copy_to_cube_face(target, cube, face, SCRATCH_UNIT)
            cube.build_mipmaps()
            cube.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
            ctx.enable_direct(SEAMLESS_CUBE_MAP)
        except BaseException:
            cube.release()
            raise
        return cube

    def _face_target(self, size: int) -> moderngl.Framebuffer:
        target = self._target
        if target is None or target.size != (size, size):
            self._release_target()
            target = self._target = self.ctx.framebuffer([self.ctx.texture((size, size), 4, dtype="f2")])
        return target

    def _vertex_array(self, build: tuple[tuple[str, str], ...]) -> moderngl.VertexArray:
        program = self.renderer.shaders.program("fullscreen.vert", "sky_cube.frag", defines=dict(build))
        if self._vao is None or self._vao.program is not program:
            if self._vao is not None:
                self._vao.release()
            self._vao = self.ctx.vertex_array(program, [])
        return self._vao

    def _release_target(self) -> None:
        if self._target is not None:
            release_target(self._target)
            self._target = None

    def release(self) -> None:
        self._release_target()
        if self._vao is not None:
            self._vao.release()
            self._vao = None
