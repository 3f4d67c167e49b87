"""Texture units remember what they hold (``bindings.bind_texture``): a pass binds only what
another pass displaced, so a frame's second and later scene passes bind no shadow map,
irradiance table or sky already in place; and the record never takes a texture for another:
a released texture whose GL name a new texture reuses is bound again, and after
``invalidate`` (raw GL, state set outside the engine) everything is bound again.

GL calls are counted with the cpu benchmark's ``GLCallCounter`` (every call into moderngl's
GL objects); which texture went to which unit is recorded by a spy that passes every call
on to moderngl (the frames are real).  Checked by breaking the record: keyed by the GL name
(``texture.glo``) instead of the object, the reused-name test draws black; with
``invalidate`` not clearing it, the raw-GL test draws the other texture; binding every time
(``CACHE_STATE = False``) fails the counts.
"""
from __future__ import annotations

import contextlib
import os
import subprocess
import sys
from pathlib import Path

import moderngl
import numpy as np
import pytest

from benchmarks.cpu import GLCallCounter
from benchmarks.mirrors import DT, MirrorRing
from components import DirectionalLight
from engine.core.frame_io import Output
from engine.render import bindings, scene_pass
from engine.render.bindings import SHADOW_ATLAS_UNIT, bind_texture, invalidate
from engine.render.targets import CaptureTarget
from shell.app import Engine

SIZE = (96, 54)
REPO = Path(__file__).resolve().parent.parent
UNIT = 6

_VERTEX = """#version 410 core
void main() { gl_Position = vec4(vec2(gl_VertexID & 1, gl_VertexID >> 1) * 4.0 - 1.0, 0.0, 1.0); }
"""
_FRAGMENT = """#version 410 core
uniform sampler2D image;
out vec4 colour;
void main() { colour = texelFetch(image, ivec2(0), 0); }
"""


def _texture(ctx: moderngl.Context, rgba: tuple[int, int, int, int]) -> moderngl.Texture:
    return ctx.texture((1, 1), 4, bytes(rgba))


def _draw(ctx: moderngl.Context, vao: moderngl.VertexArray, target: CaptureTarget,
          forget: bool = True) -> tuple[int, ...]:
    """One full-screen draw sampling ``UNIT``; the centre pixel.  The fixed-function state is
    set here outside ``apply_pass_state``; ``forget``: then ``invalidate`` (which forgets the
    textures too)."""
    target.framebuffer.use()
    ctx.viewport = (0, 0, *target.size)
    ctx.disable(moderngl.BLEND | moderngl.DEPTH_TEST | moderngl.CULL_FACE)
    if forget:
        invalidate(ctx)
    vao.render(moderngl.TRIANGLES, vertices=3)
    return tuple(int(v) for v in target.read_rgb()[2, 2])


@pytest.fixture
def sampling(ctx):
    program = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
    program["image"].value = UNIT
    vao = ctx.vertex_array(program, [])
    target = CaptureTarget(ctx, (4, 4))
    yield vao, target
    target.release()
    vao.release()
    program.release()


def reused_name_case() -> str:
    """In a context whose driver reuses released names: bind red, release it, make green
    (it gets red's GL name), bind green; the pixel drawn, and whether the name was reused."""
    from engine.render.gl_context import create_headless_context

    ctx = create_headless_context()
    program = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
    program["image"].value = UNIT
    vao = ctx.vertex_array(program, [])
    target = CaptureTarget(ctx, (4, 4))
    red = _texture(ctx, (255, 0, 0, 255))
    bind_texture(ctx, red, UNIT)
    first = _draw(ctx, vao, target, forget=False)
    name = red.glo
    red.release()   # the unit now holds texture 0
    green = _texture(ctx, (0, 255, 0, 255))
    bind_texture(ctx, green, UNIT)
    second = _draw(ctx, vao, target, forget=False)
    return f"{green.glo == name} {first} {second}".replace(", ", ",")


def test_a_released_texture_whose_name_a_new_one_reuses_is_bound_again():
    """Mesa reuses released texture names when asked (driconf ``force_gl_names_reuse``, read
    when the process makes its first context), as GPU drivers do: so in a process of its own."""
    code = "from tests.test_texture_bindings import reused_name_case; print(reused_name_case())"
    env = {**os.environ, "force_gl_names_reuse": "true"}
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    reused, first, second = done.stdout.strip().splitlines()[-1].split(" ", 2)
    assert reused == "True", "the driver did not reuse the released name: the case is not set up"
    assert first == "(255,0,0)"
    assert second == "(0,255,0)", second   # a record keyed by the GL name skips the bind: black


def test_after_invalidate_every_texture_is_bound_again(ctx, sampling):
    vao, target = sampling
    red, blue = _texture(ctx, (255, 0, 0, 255)), _texture(ctx, (0, 0, 255, 255))
    try:
        invalidate(ctx)
        bind_texture(ctx, red, UNIT)
        assert _draw(ctx, vao, target) == (255, 0, 0)
        bind_texture(ctx, red, UNIT)
        blue.use(UNIT)  # GL outside the record (raw GL, a game's own pass)...
        invalidate(ctx)  # ...followed by invalidate, as bindings' contract asks
        bind_texture(ctx, red, UNIT)
        assert _draw(ctx, vao, target) == (255, 0, 0)
    finally:
        red.release()
        blue.release()


def _ring(ctx, mirrors: int) -> Engine:
    """The ring of ``mirrors``, its sun casting, nothing spinning, drawn as llvmpipe's auto
    draws it on every machine (per mirror, exactly known; reflections filtered trilinearly):
    a pass a view, each binding what it reads."""
    engine = Engine(MirrorRing(mirrors), ctx)
    for _, light in engine.world.query_one(DirectionalLight):
        light.shadows = True
    engine.game.spinning.clear()
    engine.reflection_system.path = "per_mirror"
    engine.reflection_system.visibility = "exact"
    engine.renderer.reflection_anisotropy = 1.0
    return engine


class _BindSpy:
    """Which texture each ``use`` call bound on which unit (every call passed on)."""

    def __init__(self, monkeypatch) -> None:
        self.binds: list[tuple[object, int]] = []
        for cls in (moderngl.Texture, moderngl.TextureCube):
            original = cls.use

            def use(texture, location=0, _original=original):
                self.binds.append((texture, location))
                return _original(texture, location)
            monkeypatch.setattr(cls, "use", use)


def test_a_second_identical_scene_pass_binds_nothing(ctx):
    engine = _ring(ctx, 0)
    capture = CaptureTarget(ctx, SIZE)
    try:
        output = Output(capture.framebuffer, SIZE)
        engine.frame(DT, output)
        renderer = engine.renderer
        first = np.frombuffer(renderer.targets.color.read(), np.float16).copy()
        assert renderer.shadows.atlas is not None and np.isfinite(first).all() and first.max() > 0.05
        counter = GLCallCounter()
        with counter:
            renderer.scene_pass.draw([engine.main_view], renderer.targets)
            bound_first = counter.calls["Texture.use"] + counter.calls["TextureCube.use"]
            counter.reset()
            renderer.scene_pass.draw([engine.main_view], renderer.targets)
            bound_again = counter.calls["Texture.use"] + counter.calls["TextureCube.use"]
        assert bound_first > 0   # a batch's albedo map again: FXAA took its unit (0) since
        assert bound_again == 0, dict(counter.calls)
        again = np.frombuffer(renderer.targets.color.read(), np.float16)
        np.testing.assert_array_equal(again, first)
    finally:
        capture.release()
        engine.close()


def test_a_mirror_frame_binds_the_shadow_atlas_once(ctx, monkeypatch):
    """Eight mirrors: the main pass and the reflection passes each read the shadow atlas; it
    is bound at the frame's first pass only, and the frame equals that of a twin engine
    whose passes bind every texture every time (``CACHE_STATE`` off), frame by frame."""
    engines = [_ring(ctx, 8), _ring(ctx, 8)]
    captures = [CaptureTarget(ctx, SIZE), CaptureTarget(ctx, SIZE)]
    try:
        outputs = [Output(capture.framebuffer, SIZE) for capture in captures]
        spy = _BindSpy(monkeypatch)
        for _ in range(3):
            frames, atlas_binds = [], []
            for engine, output, capture, cache in zip(engines, outputs, captures, (True, False), strict=True):
                monkeypatch.setattr(bindings, "CACHE_STATE", cache)
                spy.binds.clear()
                engine.frame(DT, output)
                atlas = engine.renderer.shadows.atlas
                atlas_binds.append([unit for texture, unit in spy.binds if texture is atlas])
                frames.append(capture.read_rgb().copy())
            assert engines[0].renderer.stats.passes > 4, "the frame has reflection passes"
            assert atlas_binds[0] == [SHADOW_ATLAS_UNIT]
            assert len(atlas_binds[1]) > 1   # binding every time: once a scene pass
            assert frames[0].mean() > 10
            np.testing.assert_array_equal(frames[0], frames[1])
    finally:
        for capture in captures:
            capture.release()
        for engine in engines:
            engine.close()


_FILTERED = """#version 410 core
uniform sampler2D image;
out vec4 colour;
void main() { colour = texture(image, vec2(0.375, 0.5)); }
"""


def test_a_sampler_stays_bound_until_another_pass_binds_its_unit(ctx):
    """``bind_sampler``: a sampler object bound again is not bound twice; a texture bound on
    its unit with ``keep_sampler`` is filtered by it, and one bound by any other pass
    (``bind_texture``, even a texture the record says is there) is filtered by its own
    parameters again.  A 2x1 texture, black then white, NEAREST, sampled a quarter texel
    right of the first texel's centre: NEAREST reads 0, the LINEAR sampler a quarter white."""
    program = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FILTERED)
    program["image"].value = UNIT
    vao = ctx.vertex_array(program, [])
    target = CaptureTarget(ctx, (4, 4))
    texture = ctx.texture((2, 1), 4, bytes((0, 0, 0, 255, 255, 255, 255, 255)))
    texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
    sampler = ctx.sampler(filter=(moderngl.LINEAR, moderngl.LINEAR))
    counter = GLCallCounter()
    try:
        invalidate(ctx)
        bind_texture(ctx, texture, UNIT)
        assert _draw(ctx, vao, target, forget=False)[0] == 0
        with counter:
            for _ in range(3):
                bindings.bind_sampler(ctx, sampler, UNIT)
                bind_texture(ctx, texture, UNIT, keep_sampler=True)
        assert counter.calls["Sampler.use"] == 1 and counter.total == 1, dict(counter.calls)
        assert abs(_draw(ctx, vao, target, forget=False)[0] - 64) <= 2
        bind_texture(ctx, texture, UNIT)  # another pass: already bound, but the sampler comes off
        assert _draw(ctx, vao, target, forget=False)[0] == 0
        bindings.bind_sampler(ctx, sampler, UNIT)
        assert abs(_draw(ctx, vao, target, forget=False)[0] - 64) <= 2
        bindings.bind_sampler(ctx, None, UNIT)
        assert _draw(ctx, vao, target, forget=False)[0] == 0
        with counter:
            counter.reset()
            bindings.bind_sampler(ctx, None, UNIT)
        assert counter.total == 0
    finally:
        bindings.forget_sampler(ctx, sampler)
        for obj in (sampler, texture, vao, program):
            obj.release()
        target.release()


def test_a_frame_of_reflection_levels_binds_their_sampler_once(ctx, monkeypatch):
    """Sixteen mirrors (reflection levels 1, 2 and 3, each a scene pass with the reflection
    albedo sampler): a still frame binds the sampler once (the first level) and takes it off
    once (the next frame's main view), not once and off again a level; and the frame equals
    that of a twin engine
    binding everything every time (``CACHE_STATE`` off)."""
    engines = [_ring(ctx, 16), _ring(ctx, 16)]
    captures = [CaptureTarget(ctx, SIZE), CaptureTarget(ctx, SIZE)]
    try:
        outputs = [Output(capture.framebuffer, SIZE) for capture in captures]
        assert engines[0].renderer.reflection_anisotropy != engines[0].renderer.texture_anisotropy
        levels = []  # the scene passes that asked for the reflection sampler
        real = scene_pass.bind_sampler

        def bind_sampler(ctx, sampler, unit):
            if sampler is not None:
                levels.append(unit)
            real(ctx, sampler, unit)
        monkeypatch.setattr(scene_pass, "bind_sampler", bind_sampler)
        counter = GLCallCounter()
        for frame in range(3):
            pictures = []
            for engine, output, capture, cache in zip(engines, outputs, captures, (True, False), strict=True):
                monkeypatch.setattr(bindings, "CACHE_STATE", cache)
                if cache:
                    levels.clear()
                    counter.reset()
                    with counter if frame else contextlib.nullcontext():
                        engine.frame(DT, output)
                    calls = dict(counter.calls)
                else:
                    engine.frame(DT, output)
                pictures.append(capture.read_rgb().copy())
            if frame:  # the first frame draws no reflections (visibility is read a frame late)
                assert len(levels) >= 2, levels  # two or more scene passes with the sampler this frame
                assert calls.get("Sampler.use") == 1 and calls.get("Sampler.clear") == 1, calls
            assert pictures[0].mean() > 10
            np.testing.assert_array_equal(pictures[0], pictures[1])
    finally:
        for capture in captures:
            capture.release()
        for engine in engines:
            engine.close()


def test_a_run_binds_its_pass_wide_state_once_and_again_after_another_pass_rebinds_it(ctx, monkeypatch):
    """``ScenePass.draw`` with a ``run`` (a view tree's levels in one render): the second pass
    of the run leaves the pass-wide bindings (lights, shadow maps, irradiance, sky, sampler)
    as they are, without asking for them (``ShadowMaps.bind`` is not called); after another
    pass binds something else on one of their units (here the shadow atlas's), the next pass
    of the run binds it again, and draws what the first drew.  A pass of another run binds
    its own again.  Checked by breaking it: a run that ignores ``bindings_epoch`` draws the
    other texture's shadows here (the pixels differ) and binds no atlas."""
    engine = _ring(ctx, 0)
    capture = CaptureTarget(ctx, SIZE)
    other = ctx.depth_texture((4, 4), data=np.zeros(16, np.float32).tobytes())
    try:
        output = Output(capture.framebuffer, SIZE)
        engine.frame(DT, output)
        renderer = engine.renderer
        atlas = renderer.shadows.atlas
        asked = []
        real_bind = type(renderer.shadows).bind

        def shadows_bind(shadows):
            asked.append(1)
            real_bind(shadows)
        monkeypatch.setattr(type(renderer.shadows), "bind", shadows_bind)
        spy = _BindSpy(monkeypatch)
        run = object()
        renderer.scene_pass.draw([engine.main_view], renderer.targets, run=run)
        first = np.frombuffer(renderer.targets.color.read(), np.float16).copy()
        assert np.isfinite(first).all() and first.max() > 0.05
        assert len(asked) == 1
        renderer.scene_pass.draw([engine.main_view], renderer.targets, run=run)
        assert len(asked) == 1, "the run's second pass asked for its pass-wide bindings again"
        np.testing.assert_array_equal(np.frombuffer(renderer.targets.color.read(), np.float16), first)
        bind_texture(ctx, other, SHADOW_ATLAS_UNIT)  # another pass, between two levels
        spy.binds.clear()
        renderer.scene_pass.draw([engine.main_view], renderer.targets, run=run)
        np.testing.assert_array_equal(np.frombuffer(renderer.targets.color.read(), np.float16), first)
        assert len(asked) == 2
        assert (atlas, SHADOW_ATLAS_UNIT) in spy.binds
        renderer.scene_pass.draw([engine.main_view], renderer.targets, run=object())
        assert len(asked) == 3  # another run: its own bindings
    finally:
        other.release()
        capture.release()
        engine.close()


def test_no_pass_keeps_a_texture_on_modernGLs_own_unit(ctx):
    """moderngl binds a texture it makes, or builds the mips of, on its ``default_texture_unit``
    (GL_MAX_TEXTURE_IMAGE_UNITS - 1) without telling the record: a texture a pass kept there
    would be displaced behind its back (the screen reflections' half-size rays on 31 read the
    colour copy whose mips were built there, and nothing was reflected).  Only the raw-GL copies'
    scratch unit, which no program reads, may be it (on a 16-unit driver)."""
    units = {name: value for name, value in vars(bindings).items() if name.endswith("_UNIT") and isinstance(value, int)}
    for name, value in vars(bindings).items():
        if name.endswith("_UNITS") and isinstance(value, tuple):
            units.update({f"{name}[{index}]": unit for index, unit in enumerate(value)})
    assert len(units) > 30
    for default in {ctx.default_texture_unit, 15, 31}:  # (this driver's, a 16-unit driver's, a 32-unit one's)
        clashing = sorted(name for name, unit in units.items() if unit == default and name != "SCRATCH_UNIT")
        assert not clashing, f"units on moderngl's own unit {default}: {clashing}"
