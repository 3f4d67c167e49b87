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

``glFlush``.  moderngl has ``finish`` (wait for everything) but no flush (start
the GPU on what is queued, without waiting).  On llvmpipe that difference is frame time:
draws are binned on the calling thread and rasterised only at a flush, a framebuffer
switch or a wait, so CPU-only work after a pass (culling the next level) leaves the
rasteriser threads idle unless the pass is flushed first.  A flush changes no GL state,
so there is nothing of moderngl's to re-sync afterwards.

The function comes from the loader moderngl's own context uses (glcontext); where that is
not reachable (another moderngl build), ``flush`` does nothing: it is never needed for a
correct image, only for overlap.
"""
from __future__ import annotations

import ctypes

import moderngl

_VOID_CALL = ctypes.CFUNCTYPE(None)
_COPY_TEX_SUB_IMAGE_2D = ctypes.CFUNCTYPE(None, ctypes.c_uint, ctypes.c_int, ctypes.c_int, ctypes.c_int,
                                          ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_int)
GL_TEXTURE_CUBE_MAP_POSITIVE_X = 0x8515


def make_current(ctx: moderngl.Context) -> None:
    """Make ``ctx`` the calling thread's current context."""
    ctx.__enter__()


class RawGL:
    """Raw GL entry points of one context, loaded once."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self._flush = _load(ctx, "glFlush", _VOID_CALL)
        self._copy_tex_sub_image = _load(ctx, "glCopyTexSubImage2D", _COPY_TEX_SUB_IMAGE_2D)

    @property
    def can_flush(self) -> bool:
        return self._flush is not None

    def flush(self) -> None:
        """Start the GPU (or llvmpipe's rasteriser threads) on every queued command."""
        if self._flush is not None:
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
        cube.use(unit)
        self._copy_tex_sub_image(GL_TEXTURE_CUBE_MAP_POSITIVE_X + face, 0, 0, 0, 0, 0, size[0], size[1])


def _load(ctx: moderngl.Context, name: str, prototype):
    loader = getattr(getattr(ctx.mglo, "_context", None), "load_opengl_function", None)
    if loader is None:
        return None
    address = loader(name)
    return prototype(address) if address else None
