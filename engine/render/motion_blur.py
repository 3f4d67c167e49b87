"""Motion blur for a camera's ``MotionBlur`` (``components/post.py``): four full-screen
draws after depth of field and before bloom, each pixel smeared along the motion on screen
of what it shows and of what moves past it.

1. ``motion_streaks.frag``: each pixel's streak.  The camera's part: the point is where the
   light's way puts it (the main view's seen image holds the way's length:
   ``shaders/include/way.glsl``), the eye plus the pixel's ray times the way.  Through a
   mirror that is the reflection's image behind the glass, which stands still in the world
   while the camera moves, so reprojecting it with last frame's view-projection gives the
   reflection's own motion on screen (a depth buffer would give the glass's: a far thing in a
   mirror would streak as if it were on the mirror).  With ``MotionBlur.objects`` the thing's
   own motion is added: the scene pass writes it into the seen image beside the way, as the
   view that drew it projects the instance's last place (``engine/render/object_motion.py``),
   and the composites carry it up as they carry the way.
2. ``motion_tiles.frag``, 3. ``motion_neighbours.frag``: each tile's longest streak, then the
   longest of the tiles a streak can reach it from.
4. ``motion_blur.frag``: McGuire et al.'s reconstruction filter (2012) along that longest
   streak: a moving thing smears out over the still background round it, and what lies in
   front stays in front (the ways compared).

Last frame's view-projection is kept here.  A camera carried through a portal this frame
(``PortalCrossings``) has it carried too (times the inverse of each crossing's carry: the
points beyond are where the old camera saw them before the portal), so crossing a portal
does not smear the picture from one world to the other; a camera cut (another active camera,
the first frame, a new size) starts with none.  A frame of dt 0 (a second presentation: a
screenshot) reads the kept one and keeps it.  While the view is last frame's and nothing
moved, no pass is drawn.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import moderngl
import numpy as np
from pyglm import glm

from components.post import MotionBlur
from engine.render.bindings import (
    DOF_SEEN_UNIT,
    MOTION_NEIGHBOURS_UNIT,
    MOTION_STREAKS_UNIT,
    MOTION_TILES_UNIT,
    PRESENT_UNIT,
    PassState,
    apply_pass_state,
    bind_texture,
)
from engine.render.object_motion import ObjectMotion
from engine.render.shader_library import ShaderLibrary
from engine.render.targets import SEEN_MOVING_CHANNELS, release_framebuffer
from engine.render.views import View

_PASS = PassState()
TILE = 16   # pixels a side of the longest-streak tiles


@dataclass
class _Images:
    """One size's images: the result, each pixel's streak, the tiles' longest and their
    neighbours' longest (each with its framebuffer)."""

    result: moderngl.Texture
    streaks: moderngl.Texture
    tiles: moderngl.Texture
    neighbours: moderngl.Texture
    framebuffers: tuple[moderngl.Framebuffer, ...]

    def release(self) -> None:
        for framebuffer in self.framebuffers:
            release_framebuffer(framebuffer)
        for texture in (self.result, self.streaks, self.tiles, self.neighbours):
            texture.release()


class MotionBlurPass:
    """The active camera's motion blur: ``draw`` returns the smeared HDR image."""

    def __init__(self, ctx: moderngl.Context, shaders: ShaderLibrary, moving: ObjectMotion) -> None:
        self.ctx = ctx
        self.moving = moving   # the frame's movers (their own motion)
        self._streaks = shaders.fullscreen("motion_streaks.frag", seen_image=DOF_SEEN_UNIT)
        self._tiles = shaders.fullscreen("motion_tiles.frag", streaks=MOTION_STREAKS_UNIT)
        self._neighbours = shaders.fullscreen("motion_neighbours.frag", tiles=MOTION_TILES_UNIT)
        self._blur = shaders.fullscreen("motion_blur.frag", hdr_image=PRESENT_UNIT, streaks=MOTION_STREAKS_UNIT,
                                        neighbours=MOTION_NEIGHBOURS_UNIT)
        for vao in (self._tiles, self._blur):
            vao.program["tile"].value = TILE   # (once: the tiles' side never changes)
        self._images: _Images | None = None
        self.previous: glm.mat4 | None = None   # last frame's view-projection (None: none yet)
        self.camera: int | None = None
        self._size: tuple[int, int] | None = None
        self.objects = False   # the last draw's MotionBlur streaks moving things (the extract stage reads it)
        self.passes = 0        # draws the last ``draw`` made

    def _make(self, size: tuple[int, int]) -> _Images:
        if self._images is not None and self._images.result.size == size:
            return self._images
        self.release_targets(keep_view=True)
        ctx = self.ctx
        result = ctx.texture(size, 4, dtype="f2")
        result.filter = (moderngl.LINEAR, moderngl.LINEAR)   # (bloom reads it bilinear)
        tiled = (-(-size[0] // TILE), -(-size[1] // TILE))
        streaks = ctx.texture(size, 4, dtype="f2")   # (xy the streak, z the way)
        tiles, neighbours = (ctx.texture(tiled, 2, dtype="f2") for _ in range(2))
        for texture in (streaks, tiles, neighbours):
            texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._images = _Images(result, streaks, tiles, neighbours,
                               tuple(ctx.framebuffer([texture]) for texture in (result, streaks, tiles, neighbours)))
        return self._images

    def carry(self, through: glm.mat4) -> None:
        """The camera was carried by ``through`` (a portal pair's transform) since last frame:
        last frame's view goes with it."""
        if self.previous is not None:
            self.previous = self.previous * glm.inverse(through)

    def draw(self, hdr: moderngl.Texture, seen: moderngl.Texture, settings: MotionBlur, view: View,
             camera: int | None, dt: float) -> moderngl.Texture:
        """Smear ``hdr`` (``seen``: the same level's seen image) by the motion from last frame's
        view to ``view`` (this frame's main view), ``camera`` whose it is, and, with
        ``settings.objects`` and ``seen`` holding it, each thing's own; ``dt`` 0 keeps last
        frame's view for the next.  Returns the smeared image (kept until the next draw), or
        ``hdr`` itself where the view is last frame's and nothing moved (no pass)."""
        size = hdr.size
        now = glm.mat4(view.steady_view_proj)   # (temporal AA's sub-pixel offsets are no motion)
        self.objects = settings.objects
        self.passes = 0
        if camera != self.camera or size != self._size or self.previous is None:
            self.previous = now   # (a cut: nothing moved)
        self.camera, self._size = camera, size
        objects = settings.objects and seen.components == SEEN_MOVING_CHANNELS
        if self.previous == now and not (objects and self.moving.moving):
            return hdr
        images = self._make(size)
        ctx = self.ctx
        bind_texture(ctx, hdr, PRESENT_UNIT)
        bind_texture(ctx, seen, DOF_SEEN_UNIT)
        longest = settings.max_blur * size[1]
        program = self._streaks.program
        program["inv_view_proj"].write(glm.inverse(now))
        program["previous_view_proj"].write(self.previous)
        program["eye"].value = tuple(view.eye)
        program["axis"].value = tuple(view.axis)
        program["blur"].value = (settings.shutter, longest)
        program["image_size"].value = (float(size[0]), float(size[1]))
        program["objects"].value = objects
        self._run(self._streaks, images.framebuffers[1], size)
        bind_texture(ctx, images.streaks, MOTION_STREAKS_UNIT)
        self._run(self._tiles, images.framebuffers[2], images.tiles.size)
        bind_texture(ctx, images.tiles, MOTION_TILES_UNIT)
        self._neighbours.program["reach"].value = math.ceil(0.5 * longest / TILE)
        self._run(self._neighbours, images.framebuffers[3], images.tiles.size)
        bind_texture(ctx, images.neighbours, MOTION_NEIGHBOURS_UNIT)
        self._run(self._blur, images.framebuffers[0], size)
        if dt > 0.0:
            self.previous = now
        return images.result

    def _run(self, vao: moderngl.VertexArray, framebuffer: moderngl.Framebuffer, size: tuple[int, int]) -> None:
        framebuffer.use()
        apply_pass_state(self.ctx, _PASS, (0, 0, *size))
        vao.render(moderngl.TRIANGLES, vertices=3)
        self.passes += 1

    def streaks(self) -> np.ndarray | None:
        """Each pixel's streak in pixels from the last pass drawn, float32 (height, width, 2:
        x right, y up), row 0 at the top (read back: tests only); None before the first."""
        if self._images is None:
            return None
        texture = self._images.streaks
        w, h = texture.size
        return np.flipud(np.frombuffer(texture.read(), np.float16).reshape(h, w, 4)[..., :2]).astype(np.float32)

    def release_targets(self, keep_view: bool = False) -> None:
        if self._images is not None:
            self._images.release()
            self._images = None
        if not keep_view:
            self.previous, self.camera, self._size = None, None, None
            self.objects = False

    def target_count(self) -> int:
        return 0 if self._images is None else 4

    def release(self) -> None:
        self.release_targets()
        for vao in (self._streaks, self._tiles, self._neighbours, self._blur):
            vao.release()
