"""Copies of reflection levels as they were before their composites, for a still tree whose
end images have not settled yet (``StillTree.keep``'s refill).

A still view tree with end views changes a little every frame until its image settles
(``engine/render/end_images.py``): each frame's end views repeat the last frame's image, one
period of the recursion deeper, while every view's scene pass draws exactly what it drew the
frame before.  So such a frame needs again only what depends on the end images: the end
views filled from the new image, and from the deepest level with end views up, each level's
fallbacks, the composite of the level below and its transparent slot, each over the level's
own pixels as its views drew them.  Those pixels are copied here once, on the frame that
draws the still tree (never on a frame whose camera or scene moved), and each refill puts
them back before the level's composites are done again: a blit of the colour, surface-id,
seen-id and depth images (what the end views, fallbacks, composites, refracting surfaces and
transparent slot write: the refracting surfaces' depth, drawn after their copy,
``engine/render/screen_refraction.py``, must not be in the next copy; the node image they
only read), within the rectangle of the level's views (where those passes write), which
glBlitFramebuffer keeps to by the scissor test.  A level whose
composites and fallbacks paint every pixel they write whole (portals, mirrors of reflect
rate 1 unfaded: ``kept_tree.painted_whole``) and that has no transparent slot needs no copy:
what they write does not depend on what the pixel held.
"""
from __future__ import annotations

from collections.abc import Container
from dataclasses import dataclass

import moderngl

from engine.render.bindings import PassState, apply_pass_state
from engine.render.targets import RenderTargets, release_framebuffer

_COPY = PassState()  # a blit tests nothing but the scissor


@dataclass
class _Copy:
    """One level's copy: the level's targets it copies, a framebuffer over their colour,
    surface and seen images, and the copy's own images and framebuffer."""

    targets: RenderTargets
    level: moderngl.Framebuffer
    textures: tuple[moderngl.Texture, ...]
    framebuffer: moderngl.Framebuffer

    def release(self) -> None:
        release_framebuffer(self.framebuffer)
        release_framebuffer(self.level)
        for texture in self.textures:
            texture.release()


class LevelCopies:
    """Each level's colour, surface, seen and depth images as a tree's views drew them, by level
    (made when first saved, remade when the level's targets are other ones)."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self._copies: dict[int, _Copy] = {}

    def __len__(self) -> int:
        return len(self._copies)

    def save(self, level: int, targets: RenderTargets, rect: tuple[int, int, int, int]) -> None:
        """Copy ``targets``' (level ``level``'s) colour, ids and depth within ``rect`` (x, y, w, h)."""
        copy = self._copies.get(level)
        if copy is None or copy.targets is not targets:
            if copy is not None:
                copy.release()
            copy = self._copies[level] = self._make(targets)
        self._blit(copy.framebuffer, copy.level, targets.size, rect)

    def restore(self, level: int, targets: RenderTargets, rect: tuple[int, int, int, int]) -> None:
        """Put back what ``save`` copied of level ``level`` (``targets``, the same) within ``rect``."""
        copy = self._copies[level]
        if copy.targets is not targets:
            raise ValueError(f"level {level}'s copy is of other targets than those restored")
        self._blit(copy.level, copy.framebuffer, targets.size, rect)

    def keep_only(self, levels: Container[int]) -> None:
        """Let go the copies of the levels not in ``levels``."""
        for level in [level for level in self._copies if level not in levels]:
            self._copies.pop(level).release()

    def _make(self, targets: RenderTargets) -> _Copy:
        ctx = self.ctx
        textures = (ctx.texture(targets.size, 4, dtype=targets.color.dtype), ctx.texture(targets.size, 1, dtype="u4"),
                    ctx.texture(targets.size, targets.seen.components, dtype="u4"))
        for texture in textures:
            texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        depth = ctx.depth_texture(targets.size)  # (a blit between the framebuffers copies depth too)
        return _Copy(targets, ctx.framebuffer([targets.color, targets.surface, targets.seen], targets.depth),
                     (*textures, depth), ctx.framebuffer(list(textures), depth))

    def _blit(self, destination: moderngl.Framebuffer, source: moderngl.Framebuffer, size: tuple[int, int],
              rect: tuple[int, int, int, int]) -> None:
        """Every colour attachment of ``source`` into ``destination``'s, and its depth, within
        ``rect``: the scissor test bounds a blit (GL 4.1 core, 4.3.2)."""
        destination.use()
        apply_pass_state(self.ctx, _COPY, (0, 0, *size), rect)
        self.ctx.copy_framebuffer(destination, source)

    def release(self) -> None:
        for copy in self._copies.values():
            copy.release()
        self._copies.clear()
