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

from engine.render.atmosphere import SPACE_DARK
from engine.render.batched_mirrors import MAX_BATCHED_VIEWS
from engine.render.bindings import (
    CAMERA_BINDING,
    CLOUDS_BINDING,
    FOG_BINDING,
    MOON_VIEW_UNIT,
    SKY_UNIT,
    SKY_VIEW_UNIT,
    SPACE_UNIT,
    VIEWS_BINDING,
    bind_texture,
)
from engine.render.gpu import Gpu
from engine.render.sky import SkyModel


def sky_build(model: SkyModel | None) -> tuple[tuple[str, str], ...]:
    """The defines of a build that draws ``model`` per pixel (``shaders/include/sky_model.glsl``):
    ``GENERATED_SKY``, and ``ATMOSPHERE``, ``SPACE`` (with ``SPACE_DARK``, ``atmosphere.space_shown``'s),
    ``MOON``, ``MOON_AIR``, ``CLOUDS`` where it has them;
    none for no generated sky (the build samples the cube map).  The sky pass, the sky's cube
    map and a sharp mirror's composite build so."""
    if model is None:
        return ()
    space = model.atmosphere and model.space is not None
    return tuple((name, "1") for name, on in (
        ("GENERATED_SKY", True), ("ATMOSPHERE", model.atmosphere),
        ("SPACE", space), ("MOON", model.moon),
        ("MOON_AIR", model.moon_lights_air), ("CLOUDS", model.clouds is not None)) if on) + \
        ((("SPACE_DARK", f"{SPACE_DARK:.6e}"),) if space else ())


def wire_sky(program: moderngl.Program) -> None:
    """A ``sky_build`` program's samplers and the clouds' block on their units and binding."""
    if "sky_view" in program:
        program["sky_view"].value = SKY_VIEW_UNIT
    if "sky_space" in program:
        program["sky_space"].value = SPACE_UNIT
    if "moon_view" in program:
        program["moon_view"].value = MOON_VIEW_UNIT
    if "Clouds" in program:
        program["Clouds"].binding = CLOUDS_BINDING


def write_sky(program: moderngl.Program, model: SkyModel) -> None:
    """``model``'s colours and ways into a ``sky_build`` program."""
    for name, value in model.uniforms().items():
        program[name].value = value


def bind_sky(renderer: Gpu) -> None:
    """The textures a ``sky_build`` program of the renderer's sky reads: an atmosphere's
    sky-view tables (the sun's, the moon's) and its space; and its clouds' block (another
    engine on the context binds its own at the same point)."""
    renderer.clouds.bind()
    if renderer.sky_view is not None:
        bind_texture(renderer.ctx, renderer.sky_view, SKY_VIEW_UNIT)
    if renderer.sky_space is not None:
        bind_texture(renderer.ctx, renderer.sky_space, SPACE_UNIT)
    if renderer.moon_view is not None:
        bind_texture(renderer.ctx, renderer.moon_view, MOON_VIEW_UNIT)


class SkyDraw:
    """The sky's vertex arrays by (layered, generated, atmosphere), and the sky version each one's
    program was last given (``Gpu.sky_version``)."""

    def __init__(self, renderer: Gpu) -> None:
        self.renderer = renderer
        self.ctx = renderer.ctx
        self._skies: dict[tuple, moderngl.VertexArray] = {}   # by (layered, sky_build, fog)
        self._sky_written: dict[tuple, int] = {}

    def vertex_array(self, layered: bool) -> moderngl.VertexArray:
        """The sky's full-screen triangle for the renderer's sky now (generated or the cube
        map); ``layered``: the six-face build of a one-pass cube-map capture.  Built the first
        time it is asked for (a layered capture's even where that path is refused: its
        programs are reported with the others)."""
        renderer = self.renderer
        model = renderer.sky_model
        fogging = renderer.fog.defines
        key = (layered, sky_build(model), fogging)
        vao = self._skies.get(key)
        if vao is None:
            defines = {"LAYERED": "1", "MAX_LEVEL_VIEWS": str(MAX_BATCHED_VIEWS)} if layered else {}
            defines.update(sky_build(model))
            defines.update(fogging)
            program = renderer.shaders.program("sky.vert", "sky.frag", "sky_layered.geom" if layered else None,
                                               defines=defines)
            if layered:
                program["Views"].binding = VIEWS_BINDING
            else:
                program["Camera"].binding = CAMERA_BINDING
            if "Fog" in program:
                program["Fog"].binding = FOG_BINDING
            if "fog_sky_map" in program:   # (Fog.aerial_perspective: the scene pass binds the sky there)
                program["fog_sky_map"].value = SKY_UNIT
            if model is None:
                program["sky_map"].value = SKY_UNIT
            wire_sky(program)
            vao = self._skies[key] = self.ctx.vertex_array(program, [])
        if model is not None and self._sky_written.get(key) != renderer.sky_version:
            write_sky(vao.program, model)   # (a shader reload writes them back: ShaderLibrary)
            self._sky_written[key] = renderer.sky_version
        bind_sky(renderer)
        return vao

    def release(self) -> None:
        for vao in self._skies.values():
            vao.release()
        self._skies.clear()
        self._sky_written.clear()
