"""The sky a scene pass draws behind every view: one full-screen triangle at the far plane,
its programs built once for each of (layered, generated, atmosphere, fogged).

A generated Skybox is evaluated per pixel (the ``GENERATED_SKY`` build of ``sky.frag``, its
colours written to the program only when the sky changed: ``Gpu.sky_model``,
``Gpu.sky_version``; an atmosphere's ``ATMOSPHERE`` build reads its sky-view table,
``Gpu.sky_view``), else the cube map is sampled; ``layered``: the six-face build of a
one-pass cube-map capture (``sky_layered.geom``).  Apart from the pass
(``engine/render/scene_pass.py``, which sets the sky's pass state and draws the triangle)
because which build to draw and when to write its colours is the sky's business, not the
views'."""
from __future__ import annotations

import moderngl

from engine.render.batched_mirrors import MAX_BATCHED_VIEWS
from engine.render.bindings import (
    CAMERA_BINDING,
    CLOUDS_BINDING,
    FOG_BINDING,
    SKY_UNIT,
    SKY_VIEW_UNIT,
    SPACE_UNIT,
    VIEWS_BINDING,
    bind_texture,
)
from engine.render.gpu import Gpu


class SkyDraw:
    """The sky's vertex arrays by (layered, generated, atmosphere), and the sky version each one's
    program was last given (``Gpu.sky_version``)."""

    def __init__(self, renderer: Gpu) -> None:
        self.renderer = renderer
        self.ctx = renderer.ctx
        self._skies: dict[tuple, moderngl.VertexArray] = {}   # by (layered, generated, air, space, moon, clouds, fog)
        self._sky_written: dict[tuple, int] = {}

    def vertex_array(self, layered: bool) -> moderngl.VertexArray:
        """The sky's full-screen triangle for the renderer's sky now (generated or the cube
        map); ``layered``: the six-face build of a one-pass cube-map capture.  Built the first
        time it is asked for (a layered capture's even where that path is refused: its
        programs are reported with the others)."""
        renderer = self.renderer
        model = renderer.sky_model
        fogging = renderer.fog.defines
        air = model is not None and model.atmosphere
        space = air and model.space is not None
        moon = model is not None and model.moon
        clouds = model is not None and model.clouds is not None
        key = (layered, model is not None, air, space, moon, clouds, fogging)
        vao = self._skies.get(key)
        if vao is None:
            defines = {"LAYERED": "1", "MAX_LEVEL_VIEWS": str(MAX_BATCHED_VIEWS)} if layered else {}
            if model is not None:
                defines["GENERATED_SKY"] = "1"
            if air:
                defines["ATMOSPHERE"] = "1"
            if space:
                defines["SPACE"] = "1"
            if moon:
                defines["MOON"] = "1"
            if clouds:
                defines["CLOUDS"] = "1"
            defines.update(fogging)
            program = renderer.shaders.program("sky.vert", "sky.frag", "sky_layered.geom" if layered else None,
                                               defines=defines)
            if layered:
                program["Views"].binding = VIEWS_BINDING
            else:
                program["Camera"].binding = CAMERA_BINDING
            if "Fog" in program:
                program["Fog"].binding = FOG_BINDING
            if clouds:
                program["Clouds"].binding = CLOUDS_BINDING
            if "fog_sky_map" in program:   # (Fog.aerial_perspective: the scene pass binds the sky there)
                program["fog_sky_map"].value = SKY_UNIT
            if model is None:
                program["sky_map"].value = SKY_UNIT
            if air:
                program["sky_view"].value = SKY_VIEW_UNIT
            if space:
                program["sky_space"].value = SPACE_UNIT
            vao = self._skies[key] = self.ctx.vertex_array(program, [])
        if model is not None and self._sky_written.get(key) != renderer.sky_version:
            for name, value in model.uniforms().items():
                vao.program[name].value = value  # (a shader reload writes them back: ShaderLibrary)
            self._sky_written[key] = renderer.sky_version
        if air:
            bind_texture(self.ctx, renderer.sky_view, SKY_VIEW_UNIT)
        if space:
            bind_texture(self.ctx, renderer.sky_space, SPACE_UNIT)
        return vao

    def release(self) -> None:
        for vao in self._skies.values():
            vao.release()
        self._skies.clear()
        self._sky_written.clear()
