"""A GL error left pending by earlier work is named, never dropped, by the raw GL calls that
check their own errors (engine/render/raw_gl.py ``start_clean``): each of them raises
``GLPassError`` naming the pending error's code and name and saying it was there before
the raw calls, and leaves the context clean, so the same call then succeeds.

The pending error is made here through the same loader the engine's raw calls use:
``glEnable`` of an enum no GL has (GL_INVALID_ENUM, 0x500, by the GL spec)."""
from __future__ import annotations

import ctypes

import pytest

from engine.core.errors import GLPassError
from engine.render.raw_gl import (
    CubeMipTarget,
    LayeredArrayTarget,
    LayeredCubeTarget,
    RawGL,
    _load,
)
from engine.render.targets import release_framebuffer

NO_SUCH_CAPABILITY = 0xFFFF  # glEnable of it: GL_INVALID_ENUM


def leave_invalid_enum(ctx) -> None:
    """Leave GL_INVALID_ENUM pending on ``ctx``, as a broken call of other code would."""
    enable = _load(ctx, "glEnable", ctypes.CFUNCTYPE(None, ctypes.c_uint))
    assert enable is not None
    enable(NO_SUCH_CAPABILITY)


def _attach(ctx, cube, undo):
    colour = ctx.texture((16, 16), 4, dtype="f2")
    target = ctx.framebuffer([colour])
    undo += [lambda: release_framebuffer(target), colour.release]
    raw = RawGL(ctx)
    return lambda: raw.attach_cube_face(target, cube, 1)


def _layered_cube(ctx, cube, undo):
    def make() -> None:
        undo.append(LayeredCubeTarget(ctx, cube).release)
    return make


def _layered_array(ctx, cube, undo):
    def make() -> None:
        undo.append(LayeredArrayTarget(ctx, cube).release)
    return make


def _array_copy(ctx, cube, undo):
    target = LayeredArrayTarget(ctx, cube)
    undo.append(target.release)
    return lambda: target.copy_to_cube(7)


def _mip_level(ctx, cube, undo):
    target = CubeMipTarget(ctx, cube)
    undo.append(target.release)

    def bind() -> None:
        target.bind_level(1, 7)
        target.done(7)
    return bind


CALLS = {"RawGL.attach_cube_face": _attach, "LayeredCubeTarget()": _layered_cube,
         "LayeredArrayTarget()": _layered_array, "LayeredArrayTarget.copy_to_cube": _array_copy,
         "CubeMipTarget.bind_level": _mip_level}


@pytest.mark.parametrize("call", list(CALLS))
def test_a_gl_error_pending_before_a_checked_raw_call_is_named_and_the_context_left_clean(ctx, call):
    """With GL_INVALID_ENUM pending, the call raises GLPassError naming 0x500 and
    GL_INVALID_ENUM as pending before it; the context's error is then GL_NO_ERROR, and the
    same call made again succeeds (the pending error was not the call's own)."""
    cube = ctx.texture_cube((16, 16), 4, dtype="f2")
    cube.build_mipmaps()
    undo = []
    run = CALLS[call](ctx, cube, undo)
    try:
        assert ctx.error == "GL_NO_ERROR"
        leave_invalid_enum(ctx)
        with pytest.raises(GLPassError, match=r"OpenGL error 0x500 \(GL_INVALID_ENUM\) was pending before "):
            run()
        assert ctx.error == "GL_NO_ERROR"
        run()
        assert ctx.error == "GL_NO_ERROR"
    finally:
        for release in undo:
            release()
        cube.release()
