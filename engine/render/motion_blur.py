"""Camera motion blur for a camera's ``MotionBlur`` (``components/post.py``): one full-screen
draw after depth of field and before bloom (``shaders/motion_blur.frag``), each pixel smeared
along its point's motion on screen since the last frame.

The point is where the light's way puts it (the main view's seen image holds the way's length:
``shaders/include/way.glsl``): the eye plus the pixel's ray times the way.  Through a mirror
that is the reflection's image behind the glass, which stands still in the world while the
camera moves, so reprojecting it with last frame's view-projection gives the reflection's own
motion on screen (a depth buffer would give the glass's: a far thing in a mirror would streak
as if it were on the mirror).

Last frame's view-projection is kept here.  A camera carried through a portal this frame
(``PortalCrossings``) has it carried too (times the inverse of each crossing's carry: the
points beyond are where the old camera saw them before the portal), so crossing a portal
does not smear the picture from one world to the other; a camera cut (another active camera,
the first frame, a new size) starts with none.  A frame of dt 0 (a second presentation: a
screenshot) reads the kept one and keeps it.
"""
from __future__ import annotations

import moderngl
import numpy as np
from pyglm import glm

from components.post import MotionBlur
from engine.render.bindings import DOF_SEEN_UNIT, PRESENT_UNIT, PassState, apply_pass_state, bind_texture
from engine.render.shader_library import ShaderLibrary
from engine.render.targets import release_framebuffer
from engine.render.views import View

_PASS = PassState()


class MotionBlurPass:
    """The active camera's motion blur: ``draw`` returns the smeared HDR image."""

    def __init__(self, ctx: moderngl.Context, shaders: ShaderLibrary) -> None:
        self.ctx = ctx
        program = shaders.program("fullscreen.vert", "motion_blur.frag")
        program["hdr_image"].value = PRESENT_UNIT
        program["seen_image"].value = DOF_SEEN_UNIT
        self._blur = ctx.vertex_array(program, [])
        self._image: tuple[moderngl.Texture, moderngl.Texture, moderngl.Framebuffer] | None = None
        self.previous: glm.mat4 | None = None   # last frame's view-projection (None: none yet)
        self.camera: int | None = None
        self._size: tuple[int, int] | None = None

    def _make(self, size: tuple[int, int]) -> None:
        if self._image is not None and self._image[0].size == size:
            return
        self.release_targets(keep_view=True)
        result = self.ctx.texture(size, 4, dtype="f2")
        result.filter = (moderngl.LINEAR, moderngl.LINEAR)   # (bloom reads it bilinear)
        streaks = self.ctx.texture(size, 2, dtype="f2")
        streaks.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._image = (result, streaks, self.ctx.framebuffer([result, streaks]))

    def carry(self, through: glm.mat4) -> None:
        """The camera was carried by ``through`` (a portal pair's transform) since last frame:
        last frame's view goes with it."""
        if self.previous is not None:
            self.previous = self.previous * glm.inverse(through)

    def draw(self, hdr: moderngl.Texture, seen: moderngl.Texture, settings: MotionBlur, view: View,
             camera: int | None, dt: float) -> moderngl.Texture:
        """Smear ``hdr`` (``seen``: the same level's seen pair) by the camera's motion from last
        frame's view to ``view`` (this frame's main view), ``camera`` whose it is; ``dt`` 0
        keeps last frame's view for the next.  Returns the smeared image (kept until the next
        draw), or ``hdr`` itself where the view is last frame's (a still camera: no pass)."""
        size = hdr.size
        now = glm.mat4(view.view_proj)
        if camera != self.camera or size != self._size or self.previous is None:
            self.previous = now   # (a cut: nothing moved)
        self.camera, self._size = camera, size
        if self.previous == now:
            return hdr
        self._make(size)
        result, _, framebuffer = self._image
        framebuffer.use()
        apply_pass_state(self.ctx, _PASS, (0, 0, *size))
        bind_texture(self.ctx, hdr, PRESENT_UNIT)
        bind_texture(self.ctx, seen, DOF_SEEN_UNIT)
        program = self._blur.program
        program["inv_view_proj"].write(glm.inverse(now))
        program["previous_view_proj"].write(self.previous)
        program["eye"].value = tuple(view.eye)
        program["axis"].value = tuple(view.axis)
        program["blur"].value = (settings.shutter, settings.max_blur * size[1])
        self._blur.render(moderngl.TRIANGLES, vertices=3)
        if dt > 0.0:
            self.previous = now
        return result

    def streaks(self) -> np.ndarray | None:
        """Each pixel's streak in pixels from the last pass drawn, float32 (height, width, 2:
        x right, y up), row 0 at the top (read back: tests only); None before the first."""
        if self._image is None:
            return None
        texture = self._image[1]
        w, h = texture.size
        return np.flipud(np.frombuffer(texture.read(), np.float16).reshape(h, w, 2)).astype(np.float32)

    def release_targets(self, keep_view: bool = False) -> None:
        if self._image is not None:
            release_framebuffer(self._image[2])
            self._image[0].release()
            self._image[1].release()
            self._image = None
        if not keep_view:
            self.previous, self.camera, self._size = None, None, None

    def target_count(self) -> int:
        return 0 if self._image is None else 2

    def release(self) -> None:
        self.release_targets()
        self._blur.release()
