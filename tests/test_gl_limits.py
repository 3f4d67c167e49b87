"""Limits of the GL context are checked before anything is made, and named; debug mode
names the pass that raised a GL error; an error left by other code is not the engine's."""
from __future__ import annotations

import numpy as np
import pytest

from components import Camera, Material, MeshRef, Transform
from engine.assets.mesh import box
from engine.assets.texture_data import TextureData
from engine.core.errors import GLLimitError, GLPassError
from engine.core.frame_io import Output
from engine.render.gl_context import GLCapabilities
from engine.render.targets import CaptureTarget, RenderTargets


def test_a_texture_wider_than_the_gl_limit_is_named_with_its_entity(scene, ctx):
    limit = GLCapabilities.read(ctx).max_texture_size
    wide = TextureData(np.zeros((1, limit + 1, 4), np.uint8), name="too wide.png")
    ents = {}

    def build(world):
        world.spawn(Transform(position=(0, 0, 3)), Camera())
        world.spawn(Transform(), MeshRef(box()), Material())
        ents["crate"] = world.spawn(Transform(), MeshRef(box()), Material(texture=wide))

    runner = scene(build, (32, 32))
    before = runner.engine.renderer.resource_counts()
    with pytest.raises(GLLimitError, match=rf"entity {ents['crate']}: Material.texture: texture 'too wide.png' "
                                           rf"is {limit + 1}x1.*at most {limit}x{limit}"):
        runner.frame()
    assert ctx.error == "GL_NO_ERROR"  # refused before any GL call
    counts = runner.engine.renderer.resource_counts()
    assert counts["textures"] == 0 and counts["meshes"] <= before["meshes"] + 1  # nothing half-made for it


@pytest.mark.parametrize("make", [CaptureTarget, RenderTargets])
def test_a_target_over_the_gl_limit_is_refused_before_it_is_made(ctx, make):
    limit = GLCapabilities.read(ctx).max_texture_size
    with pytest.raises(GLLimitError, match=rf"{limit + 1}x1 pixels.*at most"):
        make(ctx, (limit + 1, 1))
    assert ctx.error == "GL_NO_ERROR"


def test_an_output_over_the_limit_fails_the_frame_cleanly_and_the_next_frame_works(scene, ctx):
    runner = scene(lambda world: world.spawn(Transform(position=(0, 0, 3)), Camera()), (16, 16))
    limit = GLCapabilities.read(ctx).max_texture_size
    with pytest.raises(GLLimitError):
        runner.engine.frame(1 / 60, Output(runner.capture.framebuffer, (limit + 1, 1)))
    assert ctx.error == "GL_NO_ERROR"
    runner.frame()  # the right size again: no error pending from the refused one


def test_debug_mode_names_the_pass_that_left_a_gl_error(scene, ctx):
    runner = scene(lambda world: world.spawn(Transform(position=(0, 0, 3)), Camera()), (16, 16))
    renderer = runner.engine.renderer
    assert renderer.debug  # the tests run in debug mode (tests/conftest.py)
    ctx.enable_direct(0xFFFF)  # not a capability: GL_INVALID_ENUM
    with pytest.raises(GLPassError, match="GL_INVALID_ENUM in the composite pass"):
        renderer.checkpoint("composite")
    assert ctx.error == "GL_NO_ERROR"  # reading it cleared it


def test_an_error_left_by_other_code_is_reported_as_not_the_engines(scene, ctx):
    runner = scene(lambda world: world.spawn(Transform(position=(0, 0, 3)), Camera()), (16, 16))
    runner.frame()
    ctx.enable_direct(0xFFFF)
    with pytest.raises(GLPassError, match="pending before frame 2 .*not by the engine"):
        runner.frame()
    runner.frame()  # the report cleared it; the engine goes on


@pytest.mark.parametrize("name", ["texture_anisotropy", "reflection_anisotropy", "normal_map_anisotropy"])
@pytest.mark.parametrize("bad", [float("nan"), float("inf"), 0.5, 0, "8", None, True, "past"])
def test_a_filtering_setting_refuses_what_the_driver_cannot_filter_with(scene, ctx, name, bad):
    """The renderer's anisotropy settings are checked when set, naming the setting and the
    context's reach: a NaN or a value past max_anisotropy was clamped in silence, and a
    string failed inside a scene pass.  A refused value leaves the one before, and the next
    frame draws as the one before it."""
    most = max(float(ctx.max_anisotropy), 1.0)
    if bad == "past":
        bad = most + 1.0

    def build(world):
        world.spawn(Transform(position=(0, 0, 3)), Camera())
        world.spawn(Transform(), MeshRef(box()), Material(color=(0.8, 0.4, 0.2)))

    runner = scene(build, (32, 32))
    renderer = runner.engine.renderer
    before = runner.frame()
    kept = getattr(renderer, name)
    with pytest.raises(ValueError, match=rf"{name} must be a number from 1 \(off\) to {most:g}"):
        setattr(renderer, name, bad)
    assert getattr(renderer, name) == kept
    assert np.array_equal(runner.frame(), before)
    setattr(renderer, name, most)   # the context's own reach is taken
    assert getattr(renderer, name) == most
