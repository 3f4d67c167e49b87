"""Shadow atlases outlive the engine that made them, on its context (as its programs do:
``shader_library.FreePrograms``).

A sun's shadow atlas is one depth image of 2 x 2 tiles of its ``shadow_resolution``: 4096 x
4096 texels (64 MiB) at the default 2048.  Making one is a new store for the driver to find
and, on llvmpipe, to fill: 44 ms on the 2-core machine, half of what a small level's engine
costs to open and draw its first frames.  An engine closed and another opened on the same
context (a level reloaded, an editor's preview, the test suite's thousands of engines) takes
the closed one's atlases instead of making them again.

A depth image taken from the list holds what its last owner drew.  That is no new danger: GL
leaves a new image's texels undefined as well, so every user writes a texel before it reads
it (a shadow map clears its tile before its casters are drawn; tests/test_gl_strict.py makes
every new image full of noise, and hands out none from this list while it does).

The list keeps the images the last engine gave back, at most ``KEEP`` (its sun's, spots' and
mirror-thrown lights' atlases), the longest unused going first; it goes with its context
(kept in ``ctx.extra``).
"""
from __future__ import annotations

import moderngl

from engine.render.context_kept import kept_on

KEEP = 3  # depth images held: one engine's shadow atlases (the sun's, the spots', the virtual lights')


class FreeDepthImages:
    """Depth images given back by released engines on one context, waiting for one that needs
    the same size."""

    EXTRA_KEY = "speculum.free_depth_images"

    def __init__(self) -> None:
        self._free: list[moderngl.Texture] = []   # the longest unused first
        self.keep = KEEP
        self.taken = 0          # images handed out instead of made (for tests and benchmarks)
        self.released = False   # after ``release``: nothing is handed out, an image given is released

    @classmethod
    def of(cls, ctx: moderngl.Context) -> FreeDepthImages:
        """The list of ``ctx`` (made on first use)."""
        return kept_on(ctx, cls.EXTRA_KEY, cls)

    def take(self, size: tuple[int, int]) -> moderngl.Texture | None:
        """A free depth image of ``size`` (off the list), or None (always, once released)."""
        if self.released:
            return None
        for index, image in enumerate(self._free):
            if image.size == tuple(size):
                del self._free[index]
                self.taken += 1
                return image
        return None

    def give(self, image: moderngl.Texture) -> None:
        """Put ``image`` on the list (released at once after ``release``, or when it is a
        1 x 1 stand-in: nothing to save), releasing the longest unused past ``keep``."""
        if self.released or image.size == (1, 1):
            image.release()
            return
        self._free.append(image)
        while len(self._free) > self.keep:
            self._free.pop(0).release()

    @property
    def count(self) -> int:
        """Images held."""
        return len(self._free)

    def release(self) -> None:
        """Release every image held (the context stays) and every one given from now on."""
        self.released = True
        for image in self._free:
            image.release()
        self._free.clear()


def take_depth_image(ctx: moderngl.Context, size: tuple[int, int]) -> moderngl.Texture:
    """A depth image of ``size`` on ``ctx``: a released engine's (``FreeDepthImages``) or a
    new one; its texels undefined either way (written before they are read)."""
    image = FreeDepthImages.of(ctx).take(size)
    return image if image is not None else ctx.depth_texture(size)


def give_depth_image(ctx: moderngl.Context, image: moderngl.Texture) -> None:
    """Hand ``image`` (made by ``take_depth_image``) back for the next engine on ``ctx``."""
    FreeDepthImages.of(ctx).give(image)
