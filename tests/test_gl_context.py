"""The start-up capability check: names what a context lacks, passes the real one."""
from __future__ import annotations

import dataclasses

import pytest

from engine.core.errors import GLCapabilityError
from engine.render.gl_context import REQUIREMENTS, GLCapabilities, check_capabilities, prepare_context

GOOD = GLCapabilities(
    version_code=410,
    renderer="Simulated GPU",
    max_texture_size=4096,
    max_cube_map_size=1024,
    max_color_attachments=4,
    max_draw_buffers=4,
    max_uniform_block_size=16384,
    max_vertex_attribs=16,
    max_geometry_output_vertices=256,
    max_clip_distances=8,
    extensions=frozenset(),
)


def test_exactly_the_minimums_pass():
    minimal = dataclasses.replace(GOOD, **{name: minimum for name, minimum, _ in REQUIREMENTS})
    assert check_capabilities(minimal) is minimal
    assert check_capabilities(GOOD) is GOOD


@pytest.mark.parametrize("version_code, shown", [(330, "3.3"), (400, "4.0"), (210, "2.1")])
def test_old_opengl_version_is_named(version_code, shown):
    caps = dataclasses.replace(GOOD, version_code=version_code)
    with pytest.raises(GLCapabilityError) as info:
        check_capabilities(caps)
    message = str(info.value)
    assert f"OpenGL {shown} < 4.1" in message
    assert "Simulated GPU" in message       # which context
    assert "max_" not in message            # only what is missing


@pytest.mark.parametrize("name, minimum, why", REQUIREMENTS[1:], ids=[r[0] for r in REQUIREMENTS[1:]])
def test_each_limit_below_its_minimum_is_named(name, minimum, why):
    caps = dataclasses.replace(GOOD, **{name: minimum - 1})
    with pytest.raises(GLCapabilityError) as info:
        check_capabilities(caps)
    message = str(info.value)
    assert f"{name} = {minimum - 1} < {minimum}" in message
    assert why in message
    assert "OpenGL 4.1 core:" not in message   # the version was fine


def test_everything_missing_is_named_at_once():
    caps = dataclasses.replace(GOOD, version_code=330, max_texture_size=1024, max_clip_distances=0)
    with pytest.raises(GLCapabilityError) as info:
        check_capabilities(caps)
    message = str(info.value)
    for part in ("OpenGL 3.3 < 4.1", "max_texture_size = 1024 < 2048", "max_clip_distances = 0 < 6"):
        assert part in message
    assert message.count(" < ") == 3


def test_capabilities_are_read_from_the_real_context(ctx):
    caps = GLCapabilities.read(ctx)
    assert caps.version_code == ctx.version_code >= 410
    assert caps.renderer and caps.renderer != "?"
    assert caps.max_texture_size == ctx.info["GL_MAX_TEXTURE_SIZE"]
    assert caps.max_cube_map_size == ctx.info["GL_MAX_CUBE_MAP_TEXTURE_SIZE"]
    assert caps.max_clip_distances == ctx.info["GL_MAX_CLIP_DISTANCES"]
    assert all(getattr(caps, name) > 0 for name, _, _ in REQUIREMENTS)   # nothing read as "absent"
    assert caps.extensions == frozenset(ctx.extensions) and caps.extensions
    assert check_capabilities(caps) is caps


def test_prepare_context_checks_and_returns_capabilities(ctx):
    caps = prepare_context(ctx)
    assert isinstance(caps, GLCapabilities)
    assert caps.version_code == ctx.version_code
    assert ctx.gc_mode is None


def test_capabilities_are_what_the_context_reports(ctx):
    """Each limit is read from its own GL query (a swapped or misspelt name would read 0 or
    another limit's value, and the start-up check would then judge the wrong number)."""
    caps = GLCapabilities.read(ctx)
    info = ctx.info
    assert caps.version_code == ctx.version_code
    assert caps.renderer == info["GL_RENDERER"]
    for name in ("max_texture_size", "max_cube_map_size", "max_color_attachments", "max_draw_buffers",
                 "max_uniform_block_size", "max_vertex_attribs", "max_geometry_output_vertices",
                 "max_clip_distances"):
        gl_name = "GL_MAX_CUBE_MAP_TEXTURE_SIZE" if name == "max_cube_map_size" else f"GL_{name.upper()}"
        assert getattr(caps, name) == info[gl_name] > 0, name
    assert caps.extensions == frozenset(ctx.extensions)
