"""The OpenGL calls moderngl 5.13 does not make, in one place.

``make_current``: moderngl has no call that just makes a context current.  Its context's
``__enter__`` does (and remembers the previous context for ``__exit__``, which restores
it); the engine enters and never exits, so its context stays current after a frame, as a
program expects of its own renderer, whatever other context (a window, a tool's) was
made current in between.

``glCopyTexSubImage2D`` into a cube-map face: moderngl cannot attach a cube-map face to a
framebuffer, so a probe face is drawn into an ordinary 2D target and copied into its face
(``copy_to_cube_face``).  The copy reads the bound framebuffer and writes the cube bound
on the active texture unit; both are bound through moderngl first (``Framebuffer.use``,
``TextureCube.use`` on a unit no program reads), so moderngl's idea of the state stays
true.  Where the loader is not reachable the copy goes through client memory instead.

A layered cube-map target (``LayeredCubeTarget``): moderngl cannot attach a whole cube map
either, so the one-pass probe capture (a geometry shader choosing each triangle's face with
``gl_Layer``) draws into a framebuffer made here: the probe's cube map (moderngl's) as its
colour attachment and a depth cube map of its own.  It is bound with raw calls for the
pass; the next moderngl ``Framebuffer.use`` binds moderngl's again (it always binds), and
the calls are checked with ``glGetError`` so a failure is named where it happens; an error
already pending before them (left by earlier moderngl or engine work) is raised as such
(``start_clean``), never taken for theirs nor dropped.

A layered 2D-array target copied into the cube (``LayeredArrayTarget``): on an NVIDIA H200
(driver 580.159.04, OpenGL 4.1 core through EGL, 2026-11-26) a cube map attached with
``glFramebufferTexture`` makes a complete framebuffer that reports itself layered, yet a
layered clear and draw reach face 0 only, for a moderngl cube, a raw ``glTexImage2D`` cube
and ``LayeredCubeTarget`` alike; a 2D array texture of six layers attached the same way
takes all six.  So the same one-pass draw (``gl_Layer`` = face) goes into an RGBA16F array
and a depth array of six layers, and each layer is then copied into its cube face: GL 4.1
has no ``glCopyImageSubData``, so a read framebuffer per layer (``glFramebufferTextureLayer``)
and ``glCopyTexSubImage2D`` into the face, with the cube bound through moderngl as
``copy_to_cube_face`` binds it.  Six copies of a face each cost a little GPU bandwidth; the
five scene passes the six-pass path would draw instead cost far more CPU.

A cube map's mip levels drawn by the engine (``CubeMipTarget``): ``glGenerateMipmap`` on a
cube map is six blits a level, each with a draw's fixed cost, which on llvmpipe is most of
a small probe's capture; a layered target on one mip level takes a level's six faces in
one draw.  Meanwhile the cube's base and max level are limited to the level above (raw
``glTexParameteri``; moderngl keeps no copy of them, and ``build_mipmaps`` sets them
itself), so the level written is never one the draw reads.

A cube-map face as a colour attachment (``RawGL.attach_cube_face``): a probe face that
roots no view tree is drawn straight into its face instead of into a 2D target and copied.
The framebuffer is made by moderngl (a placeholder colour texture and a depth texture);
its colour attachment 0 is then re-pointed at the face with ``glFramebufferTexture2D``.
moderngl still binds, clears and sets the viewport of it as its own; the copy's wait for
each face's rasterisation (llvmpipe) is gone with the copy.

Clearing integer colour attachments (``RawGL.clear_level``): moderngl's ``Framebuffer.clear``
is one ``glClear`` with a float clear colour, and GL 4.1 (4.2.3) leaves what ``glClear`` writes
into an integer colour buffer undefined (llvmpipe writes the bits of 0.0, a GPU driver need
not): a level's id and node images are cleared with ``glClearBufferuiv``, its colour and
depth with ``glClearBufferfv``, after moderngl bound the framebuffer (its draw buffers,
colour and depth masks and scissor, all of which the clear obeys; it changes no state).

``glFlush``.  moderngl has ``finish`` (wait for everything) but no flush (start
the GPU on what is queued, without waiting).  On llvmpipe that difference is frame time:
draws are binned on the calling thread and rasterised only at a flush, a framebuffer
switch or a wait, so CPU-only work after a pass (culling the next level) leaves the
rasteriser threads idle unless the pass is flushed first.  A flush changes no GL state,
so there is nothing of moderngl's to re-sync afterwards.

The function comes from the loader moderngl's own context uses (glcontext); where that is
not reachable (another moderngl build), ``flush`` does nothing: it is never needed for a
correct image, only for overlap.

GPU timestamps (``TimestampQueries``): moderngl's queries are time-elapsed ones, which
cannot nest (the probes' path timing runs one inside a frame), so the frame's own GPU time
(dynamic resolution, ``engine/render/dynamic_resolution.py``) is two ``glQueryCounter``
timestamps (GL 3.3 core), read without waiting once ``GL_QUERY_RESULT_AVAILABLE`` says so.
They bind nothing and change no state.
"""
from __future__ import annotations

import ctypes
from collections.abc import Callable
from dataclasses import dataclass

import moderngl
import numpy as np

from engine.core.errors import GLPassError
from engine.render.bindings import bind_texture_now, invalidate

_VOID_CALL = ctypes.CFUNCTYPE(None)
_CLEAR_BUFFER = ctypes.CFUNCTYPE(None, ctypes.c_uint, ctypes.c_int, ctypes.c_void_p)  # glClearBuffer{f,ui}v
_COPY_TEX_SUB_IMAGE_2D = ctypes.CFUNCTYPE(None, ctypes.c_uint, ctypes.c_int, ctypes.c_int, ctypes.c_int,
                                          ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_int)
GL_TEXTURE_CUBE_MAP_POSITIVE_X = 0x8515
GL_TEXTURE_CUBE_MAP = 0x8513
GL_TEXTURE_2D = 0x0DE1
GL_FRAMEBUFFER = 0x8D40
GL_COLOR_ATTACHMENT0 = 0x8CE0
GL_DEPTH_ATTACHMENT = 0x8D00
GL_FRAMEBUFFER_COMPLETE = 0x8CD5
GL_DEPTH_COMPONENT = 0x1902
GL_DEPTH_COMPONENT24 = 0x81A6
GL_UNSIGNED_INT = 0x1405
GL_FLOAT = 0x1406
GL_RGBA = 0x1908
GL_TEXTURE_MIN_FILTER = 0x2801
GL_TEXTURE_MAG_FILTER = 0x2800
GL_NEAREST = 0x2600
GL_TEXTURE_BASE_LEVEL = 0x813C
GL_TEXTURE_MAX_LEVEL = 0x813D
GL_MAX_LEVEL_DEFAULT = 1000
GL_COLOR = 0x1800
GL_DEPTH = 0x1801
GL_DRAW_FRAMEBUFFER = 0x8CA9
GL_DRAW_FRAMEBUFFER_BINDING = 0x8CA6
GL_FRAMEBUFFER_ATTACHMENT_LAYERED = 0x8DA7
GL_FRAMEBUFFER_ATTACHMENT_OBJECT_NAME = 0x8CD1
GL_FRAMEBUFFER_ATTACHMENT_TEXTURE_LEVEL = 0x8CD2
GL_SCISSOR_TEST = 0x0C11
GL_SCISSOR_BOX = 0x0C10
GL_VIEWPORT = 0x0BA2
GL_ACTIVE_TEXTURE = 0x84E0
GL_TEXTURE0 = 0x84C0
GL_TEXTURE_BINDING_CUBE_MAP = 0x8514
GL_MAX_COMBINED_TEXTURE_IMAGE_UNITS = 0x8B4D
GL_TEXTURE_2D_ARRAY = 0x8C1A
GL_TEXTURE_BINDING_2D_ARRAY = 0x8C1D
GL_READ_FRAMEBUFFER = 0x8CA8
GL_RGBA16F = 0x881A
GL_HALF_FLOAT = 0x140B
GL_R32F = 0x822E
GL_RED = 0x1903
_u = ctypes.c_uint
_i = ctypes.c_int
_SIGNATURES = {
    "glGenTextures": (None, _i, ctypes.POINTER(_u)),
    "glDeleteTextures": (None, _i, ctypes.POINTER(_u)),
    "glBindTexture": (None, _u, _u),
    "glTexImage2D": (None, _u, _i, _i, _i, _i, _i, _u, _u, ctypes.c_void_p),
    "glTexParameteri": (None, _u, _u, _i),
    "glGenFramebuffers": (None, _i, ctypes.POINTER(_u)),
    "glDeleteFramebuffers": (None, _i, ctypes.POINTER(_u)),
    "glBindFramebuffer": (None, _u, _u),
    "glFramebufferTexture": (None, _u, _u, _u, _i),
    "glFramebufferTexture2D": (None, _u, _u, _u, _u, _i),
    "glCheckFramebufferStatus": (_u, _u),
    "glDrawBuffers": (None, _i, ctypes.POINTER(_u)),
    "glClearBufferfv": (None, _u, _i, ctypes.POINTER(ctypes.c_float)),
    "glClearBufferuiv": (None, _u, _i, ctypes.POINTER(_u)),
    "glViewport": (None, _i, _i, _i, _i),
    "glGetError": (_u,),
    "glDisable": (None, _u),
    "glEnable": (None, _u),
    "glScissor": (None, _i, _i, _i, _i),
    "glColorMask": (None, ctypes.c_ubyte, ctypes.c_ubyte, ctypes.c_ubyte, ctypes.c_ubyte),
    "glDepthMask": (None, ctypes.c_ubyte),
}
# What the 2D-array target needs besides (``LayeredArrayTarget``).
_ARRAY_SIGNATURES = {
    "glTexImage3D": (None, _u, _i, _i, _i, _i, _i, _i, _u, _u, ctypes.c_void_p),
    "glFramebufferTextureLayer": (None, _u, _u, _u, _i, _i),
    "glReadBuffer": (None, _u),
    "glCopyTexSubImage2D": (None, _u, _i, _i, _i, _i, _i, _i, _i),
}
# Read-backs for debug mode (``inspect_bound_target``): what the driver says is bound and attached.
_QUERY_SIGNATURES = {
    "glGetIntegerv": (None, _u, ctypes.POINTER(_i)),
    "glGetFramebufferAttachmentParameteriv": (None, _u, _u, _u, ctypes.POINTER(_i)),
    "glIsEnabled": (ctypes.c_ubyte, _u),
    "glActiveTexture": (None, _u),
}


# GPU timestamps (``TimestampQueries``).
_TIMER_SIGNATURES = {
    "glGenQueries": (None, _i, ctypes.POINTER(_u)),
    "glDeleteQueries": (None, _i, ctypes.POINTER(_u)),
    "glQueryCounter": (None, _u, _u),
    "glGetQueryObjectiv": (None, _u, _u, ctypes.POINTER(_i)),
    "glGetQueryObjectui64v": (None, _u, _u, ctypes.POINTER(ctypes.c_uint64)),
}
GL_TIMESTAMP = 0x8E28
GL_QUERY_RESULT = 0x8866
GL_QUERY_RESULT_AVAILABLE = 0x8867


class MissingEntryPoints(RuntimeError):
    """The loader does not give a GL function a raw path needs (the path is unavailable,
    not broken)."""


GL_ERROR_NAMES = {0x0500: "GL_INVALID_ENUM", 0x0501: "GL_INVALID_VALUE", 0x0502: "GL_INVALID_OPERATION",
                  0x0503: "GL_STACK_OVERFLOW", 0x0504: "GL_STACK_UNDERFLOW", 0x0505: "GL_OUT_OF_MEMORY",
                  0x0506: "GL_INVALID_FRAMEBUFFER_OPERATION"}
_MAX_ERROR_FLAGS = 8  # glGetError calls that empty every flag a driver keeps (one an error kind, at most)


def gl_error_name(code: int) -> str:
    """``code`` (a ``glGetError`` answer) as its number and name, as in 0x500 (GL_INVALID_ENUM)."""
    return f"0x{code:x} ({GL_ERROR_NAMES.get(code, 'GL_NO_ERROR' if not code else 'an unknown GL error')})"


def start_clean(get_error: Callable[[], int], before: str) -> None:
    """Before raw calls whose errors are checked (``glGetError`` after them): raise
    ``GLPassError`` naming each error already pending, left by earlier moderngl or engine
    work, so it is neither taken for the raw calls' own nor dropped unsaid; the flags are
    read, so the context is clean after either way.  ``before``: what the calls do."""
    pending = []
    for _ in range(_MAX_ERROR_FLAGS):
        code = get_error()
        if not code:
            break
        pending.append(code)
    if pending:
        raise GLPassError(f"OpenGL error {', '.join(map(gl_error_name, pending))} was pending before {before} "
                          "(left by earlier moderngl or engine work on this context, not by these raw GL calls)")


def clear_images(ctx: moderngl.Context, framebuffer: moderngl.Framebuffer) -> None:
    """Clear the bound ``framebuffer`` to colour 0, integer ids 0 and depth far, each
    attachment with the clear call of its kind (glClearBufferfv for float colour and depth,
    glClearBufferuiv for unsigned-integer images: the module's docstring).  The framebuffer
    must be bound (``use``): the clear obeys its draw buffers, masks and scissor, and changes
    no state.  The calls are worked out once a framebuffer (its attachments never change).
    Raises ``MissingEntryPoints`` where the loader does not give glClearBuffer* (core since
    GL 3.0: a broken loader; moderngl's glClear instead would leave the integer id images
    undefined, so nothing falls back silently)."""
    try:
        calls = framebuffer._speculum_clears
    except AttributeError:
        calls = framebuffer._speculum_clears = _clear_calls(ctx, framebuffer)
    for call, buffer, index, values in calls:
        call(buffer, index, values)


def _clear_calls(ctx: moderngl.Context, framebuffer: moderngl.Framebuffer) -> tuple:
    """(function, buffer, draw buffer, values) for each clear ``clear_images`` makes of
    ``framebuffer``."""
    # The values by address (a plain int crosses into C faster than an array does); the
    # arrays live on the context, as long as the calls.
    clear = _required(ctx, "glClearBufferfv", _CLEAR_BUFFER)
    clear_uint = _required(ctx, "glClearBufferuiv", _CLEAR_BUFFER)
    values = getattr(ctx, "_speculum_clear_values", None)
    if values is None:
        values = ctx._speculum_clear_values = ((ctypes.c_float * 4)(), (_u * 4)(), (ctypes.c_float * 1)(1.0))
    zero_floats, zero_uints, far = (ctypes.addressof(v) for v in values)
    calls = [(clear_uint, GL_COLOR, index, zero_uints) if texture.dtype[0] == "u" else
             (clear, GL_COLOR, index, zero_floats)
             for index, texture in enumerate(framebuffer.color_attachments)]
    if framebuffer.depth_attachment is not None:
        calls.append((clear, GL_DEPTH, 0, far))
    return tuple(calls)


def make_current(ctx: moderngl.Context) -> None:
    """Make ``ctx`` the calling thread's current context."""
    ctx.__enter__()


class RawGL:
    """Raw GL entry points of one context, loaded once."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        # What every frame calls is checked now, at start-up, not when a level first clears.
        self._flush = _required(ctx, "glFlush", _VOID_CALL)
        for name in ("glClearBufferfv", "glClearBufferuiv"):
            _required(ctx, name, _CLEAR_BUFFER)
        self._copy_tex_sub_image = _load(ctx, "glCopyTexSubImage2D", _COPY_TEX_SUB_IMAGE_2D)
        self._attach = {name: _load(ctx, name, ctypes.CFUNCTYPE(*_SIGNATURES[name]))
                        for name in ("glBindFramebuffer", "glFramebufferTexture2D", "glCheckFramebufferStatus",
                                     "glGetError")}

    def clear_level(self, framebuffer: moderngl.Framebuffer) -> None:
        """``clear_images`` on this context (the scene pass's clear of a level)."""
        clear_images(self.ctx, framebuffer)

    @property
    def can_attach_cube_faces(self) -> bool:
        return all(fn is not None for fn in self._attach.values())

    def attach_cube_face(self, framebuffer: moderngl.Framebuffer, cube: moderngl.TextureCube, face: int,
                         level: int = 0) -> None:
        """Make ``face`` (0-5: +X, -X, +Y, -Y, +Z, -Z) of ``cube``'s mip ``level`` the colour
        attachment 0 of ``framebuffer`` (made by moderngl with a colour texture of the
        face's size at that level, which it replaces).  Raises RuntimeError where the calls are not
        reachable or the framebuffer is not complete; moderngl's bound framebuffer is bound
        again either way."""
        if not self.can_attach_cube_faces:
            raise RuntimeError("attaching a cube-map face needs GL entry points the loader lacks")
        gl = self._attach
        start_clean(gl["glGetError"], f"attaching face {face} level {level} of a cube map to a framebuffer")
        gl["glBindFramebuffer"](GL_FRAMEBUFFER, framebuffer.glo)
        gl["glFramebufferTexture2D"](GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_CUBE_MAP_POSITIVE_X + face,
                                     cube.glo, level)
        status = gl["glCheckFramebufferStatus"](GL_FRAMEBUFFER)
        error = gl["glGetError"]()
        gl["glBindFramebuffer"](GL_FRAMEBUFFER, 0)
        if self.ctx.fbo is not None:
            self.ctx.fbo.use()
        if status != GL_FRAMEBUFFER_COMPLETE or error:
            raise RuntimeError(f"cube-map face {face} level {level} of {cube.size[0]} as a colour attachment: "
                               f"framebuffer status 0x{status:x}, GL error {gl_error_name(error)}")

    def flush(self) -> None:
        """Start the GPU (or llvmpipe's rasteriser threads) on every queued command."""
        self._flush()


    def copy_to_cube_face(self, source: moderngl.Framebuffer, cube: moderngl.TextureCube, face: int,
                          unit: int) -> None:
        """Copy ``source``'s first colour attachment (the cube's face size) into ``face``
        (0-5: +X, -X, +Y, -Y, +Z, -Z) of ``cube``'s base level, binding ``cube`` on ``unit``."""
        size = cube.size
        source.use()
        if self._copy_tex_sub_image is None:
            pixels = source.read(components=cube.components, dtype=cube.dtype)
            cube.write(face, pixels)
            return
        bind_texture_now(self.ctx, cube, unit)  # the copy writes the active unit's cube
        self._copy_tex_sub_image(GL_TEXTURE_CUBE_MAP_POSITIVE_X + face, 0, 0, 0, 0, 0, size[0], size[1])

    def copy_depth(self, source: moderngl.Framebuffer, target: moderngl.Texture, unit: int) -> None:
        """Copy ``source``'s depth image into ``target`` (a depth texture of its size), binding
        ``target`` on ``unit``: ``glCopyTexSubImage2D`` into a depth texture reads the read
        framebuffer's depth (soft particles read the copy: the view's own depth stays attached,
        and sampling an attached image is a feedback loop).  Through client memory where the
        loader is not reachable."""
        source.use()
        if self._copy_tex_sub_image is None:
            target.write(source.read(attachment=-1, dtype="f4"))
            return
        bind_texture_now(self.ctx, target, unit)  # the copy writes the active unit's texture
        width, height = target.size
        self._copy_tex_sub_image(GL_TEXTURE_2D, 0, 0, 0, 0, 0, width, height)


class LayeredCubeTarget:
    """A framebuffer drawing into every face of ``cube`` at once (``gl_Layer`` = face), with a
    depth cube map of its own (raw GL; see the module's docstring)."""

    def __init__(self, ctx: moderngl.Context, cube: moderngl.TextureCube) -> None:
        self.ctx = ctx
        self.cube = cube
        self.size = cube.size[0]
        self.texture = cube.glo  # what the layered draw writes (the debug check's)
        self.texture_binding = GL_TEXTURE_BINDING_CUBE_MAP
        self.gl = {name: _load(ctx, name, ctypes.CFUNCTYPE(*sig)) for name, sig in _SIGNATURES.items()}
        missing = [name for name, fn in self.gl.items() if fn is None]
        if missing:
            raise RuntimeError(f"layered cube-map capture needs GL entry points the loader lacks: {missing}")
        gl = self.gl
        start_clean(gl["glGetError"], f"making a layered cube-map target of {self.size}")
        name = _u(0)
        gl["glGenTextures"](1, ctypes.byref(name))
        self.depth = name.value
        gl["glBindTexture"](GL_TEXTURE_CUBE_MAP, self.depth)
        for face in range(6):
            gl["glTexImage2D"](GL_TEXTURE_CUBE_MAP_POSITIVE_X + face, 0, GL_DEPTH_COMPONENT24, self.size, self.size,
                               0, GL_DEPTH_COMPONENT, GL_UNSIGNED_INT, None)
        gl["glTexParameteri"](GL_TEXTURE_CUBE_MAP, GL_TEXTURE_MIN_FILTER, GL_NEAREST)
        gl["glTexParameteri"](GL_TEXTURE_CUBE_MAP, GL_TEXTURE_MAG_FILTER, GL_NEAREST)
        gl["glBindTexture"](GL_TEXTURE_CUBE_MAP, 0)
        invalidate(ctx)  # the active unit's cube-map binding changed behind moderngl's back
        gl["glGenFramebuffers"](1, ctypes.byref(name))
        self.framebuffer = name.value
        gl["glBindFramebuffer"](GL_FRAMEBUFFER, self.framebuffer)
        gl["glFramebufferTexture"](GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, cube.glo, 0)
        gl["glFramebufferTexture"](GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, self.depth, 0)
        buffers = (_u * 1)(GL_COLOR_ATTACHMENT0)
        gl["glDrawBuffers"](1, buffers)
        status = gl["glCheckFramebufferStatus"](GL_FRAMEBUFFER)
        error = gl["glGetError"]()
        self.unbind()
        if status != GL_FRAMEBUFFER_COMPLETE or error:
            self.release()
            raise RuntimeError(f"layered cube-map target of {self.size}: framebuffer status 0x{status:x}, "
                               f"GL error {gl_error_name(error)}")

    def bind(self) -> None:
        """Draw into all six faces from now on (until a moderngl framebuffer is used).  The
        state a moderngl ``Framebuffer.use`` sets for its own framebuffer (viewport, scissor,
        colour and depth write masks) is set here for this one, so nothing the framebuffer
        used before left behind (a scissor box, a depth mask off) reaches the clear or the
        draws; the next moderngl ``use`` sets it all again for its own."""
        gl = self.gl
        invalidate(self.ctx)  # the viewport and scissor below are set behind moderngl's back
        gl["glBindFramebuffer"](GL_FRAMEBUFFER, self.framebuffer)
        gl["glViewport"](0, 0, self.size, self.size)
        gl["glDisable"](GL_SCISSOR_TEST)
        gl["glColorMask"](1, 1, 1, 1)
        gl["glDepthMask"](1)

    def unbind(self) -> None:
        """Back to the framebuffer moderngl thinks is bound."""
        self.gl["glBindFramebuffer"](GL_FRAMEBUFFER, 0)
        if self.ctx.fbo is not None:
            self.ctx.fbo.use()

    def clear(self, color: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)) -> None:
        """``color`` (0 by default) and depth far on every face (the target must be bound)."""
        self.gl["glClearBufferfv"](GL_COLOR, 0, (ctypes.c_float * 4)(*color))
        self.gl["glClearBufferfv"](GL_DEPTH, 0, (ctypes.c_float * 1)(1.0))

    def release(self) -> None:
        if self.framebuffer:
            self.gl["glDeleteFramebuffers"](1, ctypes.byref(_u(self.framebuffer)))
            self.framebuffer = 0
        if self.depth:
            self.gl["glDeleteTextures"](1, ctypes.byref(_u(self.depth)))
            self.depth = 0


# A layered array's colour formats (internal format, format, type): a probe's cube, a point
# light's distance cube.
ARRAY_RGBA16F = (GL_RGBA16F, GL_RGBA, GL_HALF_FLOAT)
ARRAY_R32F = (GL_R32F, GL_RED, GL_FLOAT)


class LayeredArrayTarget:
    """A framebuffer drawing into the six layers of a 2D array texture at once (``gl_Layer`` =
    face), with a depth array of its own, whose layers ``copy_to_cube`` then copies into the
    faces of ``cube``'s level 0: ``LayeredCubeTarget``'s draw for a driver that takes a
    layered array attachment but not a layered cube map (the module's docstring).  The same
    ``bind``, ``clear`` and ``unbind`` as ``LayeredCubeTarget``; the copy follows the draw.
    ``colour``: the array's (internal format, format, type), the cube's own (a probe's
    ``ARRAY_RGBA16F``, a point light's distance cube ``ARRAY_R32F``)."""

    def __init__(self, ctx: moderngl.Context, cube: moderngl.TextureCube,
                 colour: tuple[int, int, int] | None = None) -> None:
        self.ctx = ctx
        self.cube = cube
        self.size = cube.size[0]
        wanted = {**_SIGNATURES, **_ARRAY_SIGNATURES}
        self.gl = {name: _load(ctx, name, ctypes.CFUNCTYPE(*sig)) for name, sig in wanted.items()}
        missing = [name for name, fn in self.gl.items() if fn is None]
        if missing:
            raise MissingEntryPoints(f"layered array capture needs GL entry points the loader lacks: {missing}")
        self.texture = self.depth = self.framebuffer = 0
        self.read_framebuffers: list[int] = []
        self.texture_binding = GL_TEXTURE_BINDING_2D_ARRAY
        gl = self.gl
        start_clean(gl["glGetError"], f"making a layered array target of {self.size}")
        problems = []
        try:
            self.texture = self._array(*(colour or ARRAY_RGBA16F))
            self.depth = self._array(GL_DEPTH_COMPONENT24, GL_DEPTH_COMPONENT, GL_UNSIGNED_INT)
            self.framebuffer = self._framebuffer()
            gl["glBindFramebuffer"](GL_FRAMEBUFFER, self.framebuffer)
            gl["glFramebufferTexture"](GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, self.texture, 0)
            gl["glFramebufferTexture"](GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, self.depth, 0)
            gl["glDrawBuffers"](1, (_u * 1)(GL_COLOR_ATTACHMENT0))
            status = gl["glCheckFramebufferStatus"](GL_FRAMEBUFFER)
            if status != GL_FRAMEBUFFER_COMPLETE:
                problems.append(f"layered framebuffer status 0x{status:x}")
            # One read framebuffer a layer, so a copy is a bind and glCopyTexSubImage2D.
            for layer in range(6):
                read = self._framebuffer()
                self.read_framebuffers.append(read)
                gl["glBindFramebuffer"](GL_READ_FRAMEBUFFER, read)
                gl["glFramebufferTextureLayer"](GL_READ_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, self.texture, 0, layer)
                gl["glReadBuffer"](GL_COLOR_ATTACHMENT0)
                status = gl["glCheckFramebufferStatus"](GL_READ_FRAMEBUFFER)
                if status != GL_FRAMEBUFFER_COMPLETE:
                    problems.append(f"layer {layer}'s read framebuffer status 0x{status:x}")
            error = gl["glGetError"]()
            if error:
                problems.append(f"GL error {gl_error_name(error)}")
        finally:
            self.unbind()
        if problems:
            self.release()
            raise RuntimeError(f"layered array target of {self.size}: " + ", ".join(problems))

    def _array(self, internal: int, format: int, kind: int) -> int:
        gl = self.gl
        name = _u(0)
        gl["glGenTextures"](1, ctypes.byref(name))
        gl["glBindTexture"](GL_TEXTURE_2D_ARRAY, name.value)
        gl["glTexImage3D"](GL_TEXTURE_2D_ARRAY, 0, internal, self.size, self.size, 6, 0, format, kind, None)
        gl["glTexParameteri"](GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, GL_NEAREST)  # one level: complete
        gl["glTexParameteri"](GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_NEAREST)
        gl["glBindTexture"](GL_TEXTURE_2D_ARRAY, 0)
        invalidate(self.ctx)  # the active unit's array binding changed behind moderngl's back
        return name.value

    def _framebuffer(self) -> int:
        name = _u(0)
        self.gl["glGenFramebuffers"](1, ctypes.byref(name))
        return name.value

    # The layered cube target's own (the same raw state for the draw); the functions, not
    # a subclass, so a stand-in patched onto LayeredCubeTarget in a test stays its own.
    bind = LayeredCubeTarget.bind
    unbind = LayeredCubeTarget.unbind
    clear = LayeredCubeTarget.clear

    def copy_to_cube(self, unit: int) -> None:
        """Each layer into its face of the cube's level 0 (``glCopyTexSubImage2D`` from layer
        i's read framebuffer into face i), binding the cube on ``unit`` (one no pass reads
        while the cube is drawn into); then moderngl's framebuffer is bound again.  Raises
        RuntimeError naming the GL error a copy left."""
        gl = self.gl
        start_clean(gl["glGetError"], f"copying a layered array into the faces of a {self.size} cube")
        bind_texture_now(self.ctx, self.cube, unit)
        for face, read in enumerate(self.read_framebuffers):
            gl["glBindFramebuffer"](GL_READ_FRAMEBUFFER, read)
            gl["glCopyTexSubImage2D"](GL_TEXTURE_CUBE_MAP_POSITIVE_X + face, 0, 0, 0, 0, 0, self.size, self.size)
        error = gl["glGetError"]()
        self.unbind()
        if error:
            raise RuntimeError(f"copying the layered array into the faces of a {self.size} cube: "
                               f"GL error {gl_error_name(error)}")

    def release(self) -> None:
        framebuffers = [fb for fb in (self.framebuffer, *self.read_framebuffers) if fb]
        if framebuffers:
            self.gl["glDeleteFramebuffers"](len(framebuffers), (_u * len(framebuffers))(*framebuffers))
        self.framebuffer, self.read_framebuffers = 0, []
        textures = [t for t in (self.texture, self.depth) if t]
        if textures:
            self.gl["glDeleteTextures"](len(textures), (_u * len(textures))(*textures))
        self.texture = self.depth = 0


class CubeMipTarget:
    """A framebuffer drawing into every face of one mip level of ``cube`` at a time, for the
    probe's mip pass (see the module's docstring)."""

    def __init__(self, ctx: moderngl.Context, cube: moderngl.TextureCube) -> None:
        self.ctx = ctx
        self.cube = cube
        self.gl = {name: _load(ctx, name, ctypes.CFUNCTYPE(*sig)) for name, sig in _SIGNATURES.items()}
        missing = [name for name, fn in self.gl.items() if fn is None]
        if missing:
            raise RuntimeError(f"cube-map mip pass needs GL entry points the loader lacks: {missing}")
        name = _u(0)
        self.gl["glGenFramebuffers"](1, ctypes.byref(name))
        self.framebuffer = name.value
        self._level: int | None = None  # the level whose state is set (None: none, after done)
        self._scissored = False  # the scissor test on (a level drawn in part)
        self._complete: set[tuple[int, int | None]] = set()  # (level, face) attachments checked complete

    def bind_level(self, level: int, unit: int, face: int | None = None,
                   scissor: tuple[int, int, int, int] | None = None) -> int:
        """Draw into mip ``level`` (>= 1) of every face (layered: ``glFramebufferTexture``),
        or of ``face`` alone (``glFramebufferTexture2D``: the per-face pass, for a driver
        whose layered draw was refused), reading only level ``level - 1`` through ``unit``;
        returns the level's face size.  The framebuffer, its draw buffer, scissor and colour
        mask are set at a build's first level (nothing between the levels' draws changes
        them: a uniform and a draw); a level's source levels and viewport at its first face;
        the next faces of the same level only re-point the attachment.  ``scissor`` (x, y,
        width, height in the level's texels): the level is drawn there alone (None: all of
        it).  Each attachment's
        completeness and GL errors are checked
        the first time it is bound (it cannot change while the cube's storage stands): on a
        GPU driver each raw call is a ctypes call of several microseconds, and the per-face
        pass binds 42 attachments for a 128 cube."""
        gl = self.gl
        size = max(1, self.cube.size[0] >> level)
        first = (level, face) not in self._complete
        if first:
            start_clean(gl["glGetError"], f"drawing into cube-map mip level {level} of {self.cube.size[0]}")
        if self._level is None:  # a build's first level
            invalidate(self.ctx)  # the viewport and scissor below are set behind moderngl's back
            gl["glBindFramebuffer"](GL_FRAMEBUFFER, self.framebuffer)
            gl["glDrawBuffers"](1, (_u * 1)(GL_COLOR_ATTACHMENT0))
            gl["glDisable"](GL_SCISSOR_TEST)
            gl["glColorMask"](1, 1, 1, 1)
            self._scissored = False
        if self._level != level:
            if scissor is not None:
                gl["glEnable"](GL_SCISSOR_TEST)
                gl["glScissor"](*scissor)
                self._scissored = True
            elif self._scissored:
                gl["glDisable"](GL_SCISSOR_TEST)
                self._scissored = False
            bind_texture_now(self.ctx, self.cube, unit)  # (the active unit: the parameters below are its texture's)
            gl["glTexParameteri"](GL_TEXTURE_CUBE_MAP, GL_TEXTURE_BASE_LEVEL, level - 1)
            gl["glTexParameteri"](GL_TEXTURE_CUBE_MAP, GL_TEXTURE_MAX_LEVEL, level - 1)
            gl["glViewport"](0, 0, size, size)
            self._level = level
        if face is None:
            gl["glFramebufferTexture"](GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, self.cube.glo, level)
        else:
            gl["glFramebufferTexture2D"](GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_CUBE_MAP_POSITIVE_X + face,
                                         self.cube.glo, level)
        if first:
            status = gl["glCheckFramebufferStatus"](GL_FRAMEBUFFER)
            error = gl["glGetError"]()
            if status != GL_FRAMEBUFFER_COMPLETE or error:
                self.done(unit)
                where = "every face" if face is None else f"face {face}"
                raise RuntimeError(f"cube-map mip level {level} ({where}) of {self.cube.size[0]}: framebuffer "
                                   f"status 0x{status:x}, GL error {gl_error_name(error)}")
            self._complete.add((level, face))
        return size

    def done(self, unit: int) -> None:
        """Every level readable again; back to the framebuffer moderngl thinks is bound."""
        self._level = None
        if self._scissored:
            self.gl["glDisable"](GL_SCISSOR_TEST)
            self._scissored = False
        bind_texture_now(self.ctx, self.cube, unit)
        self.gl["glTexParameteri"](GL_TEXTURE_CUBE_MAP, GL_TEXTURE_BASE_LEVEL, 0)
        self.gl["glTexParameteri"](GL_TEXTURE_CUBE_MAP, GL_TEXTURE_MAX_LEVEL, GL_MAX_LEVEL_DEFAULT)
        self.gl["glBindFramebuffer"](GL_FRAMEBUFFER, 0)
        if self.ctx.fbo is not None:
            self.ctx.fbo.use()

    def release(self) -> None:
        if self.framebuffer:
            self.gl["glDeleteFramebuffers"](1, ctypes.byref(_u(self.framebuffer)))
            self.framebuffer = 0


def read_cube_level(ctx: moderngl.Context, cube: moderngl.TextureCube, face: int, level: int,
                    unit: int) -> np.ndarray:
    """Face ``face`` of mip ``level`` of ``cube`` as RGBA float32, rows in texture order
    (``glGetTexImage``: moderngl reads level 0 only); binds ``cube`` on ``unit``."""
    get = _load(ctx, "glGetTexImage", ctypes.CFUNCTYPE(None, _u, _i, _u, _u, ctypes.c_void_p))
    if get is None:
        raise RuntimeError("reading a cube-map mip level needs glGetTexImage, which the loader lacks")
    n = max(1, cube.size[0] >> level)
    out = np.zeros((n, n, 4), np.float32)
    bind_texture_now(ctx, cube, unit)
    get(GL_TEXTURE_CUBE_MAP_POSITIVE_X + face, level, GL_RGBA, GL_FLOAT, out.ctypes.data)
    return out


def write_cube_level(ctx: moderngl.Context, cube: moderngl.TextureCube, face: int, level: int,
                     rgba: np.ndarray, unit: int) -> None:
    """Write ``rgba`` (n x n x 4 float32) into face ``face`` of mip ``level`` of ``cube``
    (``glTexSubImage2D``; moderngl writes level 0 only); binds ``cube`` on ``unit``."""
    put = _load(ctx, "glTexSubImage2D", ctypes.CFUNCTYPE(None, _u, _i, _i, _i, _i, _i, _u, _u, ctypes.c_void_p))
    if put is None:
        raise RuntimeError("writing a cube-map mip level needs glTexSubImage2D, which the loader lacks")
    data = np.ascontiguousarray(rgba, np.float32)
    bind_texture_now(ctx, cube, unit)
    put(GL_TEXTURE_CUBE_MAP_POSITIVE_X + face, level, 0, 0, data.shape[1], data.shape[0], GL_RGBA, GL_FLOAT,
        data.ctypes.data)


@dataclass(frozen=True)
class BoundTargetState:
    """What the driver reports while a layered target is bound (``inspect_bound_target``):
    the draw framebuffer, whether each attachment is layered (``GL_FRAMEBUFFER_ATTACHMENT_LAYERED``)
    and what it names, the scissor and viewport, the texture units the target's cube is
    bound on, and the address the loader gave for ``glFramebufferTexture``."""

    draw_framebuffer: int
    colour_layered: bool
    depth_layered: bool | None  # None: no depth attachment
    colour_texture: int
    colour_level: int
    scissor_test: bool
    scissor_box: tuple[int, int, int, int]
    viewport: tuple[int, int, int, int]
    cube_bound_on_units: tuple[int, ...]
    framebuffer_texture_entry: int

    def problems(self, framebuffer: int, cube: int, level: int, size: int, depth: bool,
                 source_units: tuple[int, ...] = (), scissor: tuple[int, int, int, int] | None = None) -> list[str]:
        """Each way this state differs from what a layered draw into every face of ``cube``'s
        mip ``level`` (``size`` texels) through ``framebuffer`` needs, in words
        (``source_units``: where the cube may be bound, limited to other levels: the mip
        pass's source; ``scissor``: the part of the faces drawn, None: all of them)."""
        found = []
        if self.draw_framebuffer != framebuffer:
            found.append(f"draw framebuffer {self.draw_framebuffer} is bound, not the layered target {framebuffer}")
        if not self.colour_layered:
            found.append("the colour attachment is not layered")
        if depth and not self.depth_layered:
            found.append("the depth attachment is not layered")
        if (self.colour_texture, self.colour_level) != (cube, level):
            found.append(f"the colour attachment is texture {self.colour_texture} level {self.colour_level}, "
                         f"not the texture drawn into ({cube}) level {level}")
        if scissor is not None:
            if not self.scissor_test or tuple(self.scissor_box) != tuple(scissor):
                found.append(f"the scissor box is {self.scissor_box if self.scissor_test else 'off'}, not the part "
                             f"{scissor} drawn")
        elif self.scissor_test and not (self.scissor_box[:2] <= (0, 0) and self.scissor_box[2] >= size
                                        and self.scissor_box[3] >= size):
            found.append(f"the scissor box {self.scissor_box} cuts the {size}-texel faces")
        if self.viewport != (0, 0, size, size):
            found.append(f"the viewport is {self.viewport}, not the {size}-texel face")
        stray = tuple(unit for unit in self.cube_bound_on_units if unit not in source_units)
        if stray:
            found.append(f"the texture drawn into is bound for sampling on texture units {stray} "
                         "(a rendering feedback loop: undefined results)")
        return found


def inspect_bound_target(ctx: moderngl.Context, cube: moderngl.TextureCube | int, depth: bool,
                         binding: int = GL_TEXTURE_BINDING_CUBE_MAP) -> BoundTargetState:
    """Read back the state a layered draw depends on, with the framebuffer bound (debug mode:
    glGet calls wait for the driver).  ``cube`` is the texture drawn into (a moderngl cube
    map, or a GL texture name: ``LayeredArrayTarget``'s array, with ``binding``
    ``GL_TEXTURE_BINDING_2D_ARRAY``, the query that finds it bound for sampling).  The
    active texture unit is restored afterwards; nothing else is changed."""
    glo = cube if isinstance(cube, int) else cube.glo
    gl = {name: _load(ctx, name, ctypes.CFUNCTYPE(*sig)) for name, sig in _QUERY_SIGNATURES.items()}
    missing = [name for name, fn in gl.items() if fn is None]
    if missing:
        raise RuntimeError(f"inspecting a layered target needs GL entry points the loader lacks: {missing}")

    def integers(pname: int, count: int = 1) -> tuple[int, ...]:
        values = (_i * max(count, 4))()
        gl["glGetIntegerv"](pname, values)
        return tuple(values[:count])

    def attachment(point: int, pname: int) -> int:
        value = _i(0)
        gl["glGetFramebufferAttachmentParameteriv"](GL_DRAW_FRAMEBUFFER, point, pname, ctypes.byref(value))
        return value.value

    active = integers(GL_ACTIVE_TEXTURE)[0]
    bound_on = []
    for unit in range(integers(GL_MAX_COMBINED_TEXTURE_IMAGE_UNITS)[0]):
        gl["glActiveTexture"](GL_TEXTURE0 + unit)
        if integers(binding)[0] == glo:
            bound_on.append(unit)
    gl["glActiveTexture"](active)
    entry = _address(ctx, "glFramebufferTexture")
    return BoundTargetState(
        draw_framebuffer=integers(GL_DRAW_FRAMEBUFFER_BINDING)[0],
        colour_layered=bool(attachment(GL_COLOR_ATTACHMENT0, GL_FRAMEBUFFER_ATTACHMENT_LAYERED)),
        depth_layered=bool(attachment(GL_DEPTH_ATTACHMENT, GL_FRAMEBUFFER_ATTACHMENT_LAYERED)) if depth else None,
        colour_texture=attachment(GL_COLOR_ATTACHMENT0, GL_FRAMEBUFFER_ATTACHMENT_OBJECT_NAME),
        colour_level=attachment(GL_COLOR_ATTACHMENT0, GL_FRAMEBUFFER_ATTACHMENT_TEXTURE_LEVEL),
        scissor_test=bool(gl["glIsEnabled"](GL_SCISSOR_TEST)),
        scissor_box=integers(GL_SCISSOR_BOX, 4),
        viewport=integers(GL_VIEWPORT, 4),
        cube_bound_on_units=tuple(bound_on),
        framebuffer_texture_entry=entry or 0,
    )


def _address(ctx: moderngl.Context, name: str) -> int | None:
    loader = getattr(getattr(ctx.mglo, "_context", None), "load_opengl_function", None)
    return loader(name) if loader is not None else None


def _required(ctx: moderngl.Context, name: str, prototype):
    """GL function ``name``, which every frame needs (core in GL 4.1): ``MissingEntryPoints``
    naming it where the context's loader does not give it."""
    function = _load(ctx, name, prototype)
    if function is None:
        raise MissingEntryPoints(f"{name} is not given by this context's GL loader; Speculum needs it every "
                                 f"frame (core since OpenGL 3.0, and the engine needs OpenGL 4.1 core)")
    return function


def _load(ctx: moderngl.Context, name: str, prototype):
    loader = getattr(getattr(ctx.mglo, "_context", None), "load_opengl_function", None)
    if loader is None:
        return None
    address = loader(name)
    return prototype(address) if address else None


class TimestampQueries:
    """``glQueryCounter(GL_TIMESTAMP)`` queries of one context: ``make`` names, ``mark`` one
    with the time the GPU reaches it, ``nanoseconds`` its time once available (None before:
    never waits).  ``missing`` names the entry points the loader lacks (empty: usable)."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self._gl = {name: _load(ctx, name, ctypes.CFUNCTYPE(*signature))
                    for name, signature in _TIMER_SIGNATURES.items()}
        self.missing = tuple(name for name, function in self._gl.items() if function is None)

    def make(self, count: int) -> list[int]:
        names = (_u * count)()
        self._gl["glGenQueries"](count, names)
        return list(names)

    def mark(self, query: int) -> None:
        self._gl["glQueryCounter"](query, GL_TIMESTAMP)

    def nanoseconds(self, query: int) -> int | None:
        ready = _i(0)
        self._gl["glGetQueryObjectiv"](query, GL_QUERY_RESULT_AVAILABLE, ctypes.byref(ready))
        if not ready.value:
            return None
        value = ctypes.c_uint64(0)
        self._gl["glGetQueryObjectui64v"](query, GL_QUERY_RESULT, ctypes.byref(value))
        return int(value.value)

    def release(self, queries: list[int]) -> None:
        if queries:
            self._gl["glDeleteQueries"](len(queries), (_u * len(queries))(*queries))
