"""The OpenGL calls moderngl 5.13 does not make, in one place.

``make_current``: moderngl has no call that just makes a context current.  Its context's
``__enter__`` does (and remembers the previous context for ``__exit__``, which restores
it); the engine enters and never exits, so its context stays current after a frame, as a
program expects of its own renderer, whatever other context (a window, a tool's) was
made current in between.

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


def make_current(ctx: moderngl.Context) -> None:
    """Make ``ctx`` the calling thread's current context."""
    ctx.__enter__()


class RawGL:
    """Raw GL entry points of one context, loaded once."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self._flush = _load(ctx, "glFlush", _VOID_CALL)

    @property
    def can_flush(self) -> bool:
        return self._flush is not None

    def flush(self) -> None:
        """Start the GPU (or llvmpipe's rasteriser threads) on every queued command."""
        if self._flush is not None:
            self._flush()


def _load(ctx: moderngl.Context, name: str, prototype):
    loader = getattr(getattr(ctx.mglo, "_context", None), "load_opengl_function", None)
    if loader is None:
        return None
    address = loader(name)
    return prototype(address) if address else None
