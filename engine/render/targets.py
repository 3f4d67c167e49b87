"""Render targets: one screen-sized set per reflection level, and the capture target.

Level 0 is the main view; level L+1 holds what mirrors seen at level L reflect.  Every
level has the same size as the screen, so a pixel at any level lines up with the screen
pixel it will be composited into, and the regions of different mirrors never overlap.
"""
from __future__ import annotations

import moderngl
import numpy as np

from engine.core.errors import GLLimitError
from engine.render.raw_gl import clear_images

# The HDR colour images' texel format: half floats, whose largest finite value is 65504.  What
# the shaders write there is kept within it at the source (shaders/include/hdr.glsl), never left
# to the conversion, which the GL spec leaves to the implementation: llvmpipe saturates to 65504,
# a correctly rounded conversion (Vulkan's rule) makes +inf from 65520 up, and an inf pixel
# breaks every blend over it (inf x 0 is NaN), exposure and bloom.  tests/test_hdr_range.py
# widens it to float32 to see what the shaders write before a half float would round it.
HDR_FORMAT = "f2"


def check_target_size(ctx: moderngl.Context, size: tuple[int, int], what: str) -> None:
    """Refuse a render target this context cannot make (before any GL object is made, so no
    error is left pending): both sides within GL_MAX_TEXTURE_SIZE and the viewport limits."""
    info = ctx.info
    limit = min(int(info.get("GL_MAX_TEXTURE_SIZE", 0) or 1 << 30),
                *(int(v) for v in (info.get("GL_MAX_VIEWPORT_DIMS") or (1 << 30, 1 << 30))))
    w, h = size
    if not (1 <= w <= limit and 1 <= h <= limit):
        raise GLLimitError(f"{what} of {w}x{h} pixels: this OpenGL ({info.get('GL_RENDERER', '?')}) makes "
                           f"targets of at most {limit}x{limit} (GL_MAX_TEXTURE_SIZE / GL_MAX_VIEWPORT_DIMS)")


def release_framebuffer(framebuffer: moderngl.Framebuffer) -> None:
    """Release a framebuffer, first binding framebuffer 0 if it is the bound one: moderngl
    re-binds its remembered framebuffer after creating another, and binding a deleted
    name is GL_INVALID_OPERATION."""
    ctx = framebuffer.ctx
    if ctx.fbo is framebuffer:
        ctx.detect_framebuffer(0).use()
    framebuffer.release()


def release_target(framebuffer: moderngl.Framebuffer) -> None:
    """Release a framebuffer made for one pass's own textures, and its colour attachments."""
    textures = list(framebuffer.color_attachments)
    release_framebuffer(framebuffer)
    for texture in textures:
        texture.release()


# Per attachment of a level's view framebuffer (colour, surface ids, the seen pair), what a
# draw writes: everything, or (the glass slot) all but the seen pair's way.
_WRITE_ALL = ((True, True, True, True),) * 3
_GLASS_WRITES = ((True, True, True, True), (True, True, True, True), (True, False, False, False))
# The seen image's channels: the entity and the way; with each pixel's own motion on the
# picture besides, while the camera's motion blur streaks moving things (object_motion.py).
SEEN_CHANNELS = 2
SEEN_MOVING_CHANNELS = 4


class RenderTargets:
    """One level: HDR colour (alpha = something was drawn), and three uint images:
    ``surface`` - the entity whose surface is at the pixel (masks of the next level),
    ``seen``    - what is finally seen there, following reflections: r the entity (the --ids
                  image), g the length of the light's way from the eye to it as float bits
                  (``shaders/include/way.glsl``: through mirrors and portals, the image's
                  distance; what depth of field focuses by), and with ``seen_channels`` 4
                  b and a: what shows there moved on the picture since the last frame by its
                  own motion (float bits; ``engine/render/object_motion.py``),
    ``node``    - which view of this level drew the pixel."""

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int], seen_channels: int = SEEN_CHANNELS) -> None:
        check_target_size(ctx, size, "a render target")
        self.ctx = ctx
        self.size = size
        self._depth_copy: moderngl.Texture | None = None  # (depth_copy: made when soft particles draw)
        self.color = ctx.texture(size, 4, dtype=HDR_FORMAT)
        self.color.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.surface = ctx.texture(size, 1, dtype="u4")
        self.seen = ctx.texture(size, seen_channels, dtype="u4")
        self.node = ctx.texture(size, 1, dtype="u4")
        for texture in (self.surface, self.seen, self.node):
            texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.depth = ctx.depth_texture(size)
        self.framebuffer = ctx.framebuffer([self.color, self.surface, self.seen, self.node], self.depth)
        # Views write colour and ids but never the node image (the claims write it; a root's
        # is cleared to 0), which masked views read; the sky is drawn into it too, writing
        # id 0 (nothing) where it shows, as the clear did (one framebuffer for a view's pass).
        self.view_framebuffer = ctx.framebuffer([self.color, self.surface, self.seen], self.depth)
        # Colour alone (with depth): what copies the colour only read from (end_images' history).
        self.color_framebuffer = ctx.framebuffer([self.color], self.depth)
        # Composites write the reflection's colour and seen-id only (they read surface and node).
        self.composite_framebuffer = ctx.framebuffer([self.color, self.seen])
        # Every image cleared once when made (colour 0, ids 0, depth far): a GPU hands back new
        # textures holding whatever its memory held (llvmpipe zero-fills them), and a
        # reflection's bilinear lookups (a water surface's bent rays, a scaled level) take
        # texels beside the claimed pixels, which no pass of the first frame writes.
        bound = ctx.fbo
        self.framebuffer.use()
        clear_images(ctx, self.framebuffer)
        if bound is not None:
            bound.use()

    def begin_glass(self) -> None:
        """Bind the view framebuffer for a glass slot: depth tested but not written, and the
        seen pair's way kept (glass writes its entity, but what shows through it keeps its own
        way: depth of field focuses by it, as a depth buffer the glass does not write)."""
        framebuffer = self.view_framebuffer
        framebuffer.depth_mask = False
        framebuffer.color_mask = _GLASS_WRITES
        framebuffer.use()

    def end_glass(self) -> None:
        """Bind the view framebuffer writing everything again (after ``begin_glass``)."""
        framebuffer = self.view_framebuffer
        framebuffer.depth_mask = True
        framebuffer.color_mask = _WRITE_ALL
        framebuffer.use()

    def read_ids(self) -> np.ndarray:
        """Entity finally seen at each pixel, uint32 (height, width), row 0 at the top."""
        return self._read(self.seen)[..., 0].copy()

    def read_ways(self) -> np.ndarray:
        """The length of the light's way from the eye to what each pixel finally shows, in
        metres, float32 (height, width), row 0 at the top (``SKY_WAY`` where the sky shows; 0
        where nothing was drawn); waits for the GPU: tests and tools only."""
        return self._read(self.seen)[..., 1].copy().view(np.float32)

    def read_motion(self) -> np.ndarray | None:
        """What each pixel shows moved on the picture since the last frame by its own motion,
        in the picture's widths and heights, float32 (height, width, 2: x right, y up), row 0 at
        the top; None where the seen image has no motion channels (per-object motion blur off);
        waits for the GPU: tests and tools only."""
        if self.seen.components != SEEN_MOVING_CHANNELS:
            return None
        return self._read(self.seen)[..., 2:4].copy().view(np.float32)

    def read_surface_ids(self) -> np.ndarray:
        return self._read(self.surface)

    def _read(self, texture: moderngl.Texture) -> np.ndarray:
        w, h = self.size
        data = np.frombuffer(texture.read(), np.uint32).reshape(h, w, texture.components)
        return np.flipud(data if texture.components > 1 else data[..., 0]).copy()

    def depth_copy(self) -> moderngl.Texture:
        """A depth texture of this size for a copy of ``depth`` (soft particles read it while
        ``depth`` stays attached), made the first time it is asked for; read as numbers (no
        comparison)."""
        if self._depth_copy is None:
            self._depth_copy = self.ctx.depth_texture(self.size)
            self._depth_copy.compare_func = ""
            self._depth_copy.filter = (moderngl.NEAREST, moderngl.NEAREST)
        return self._depth_copy

    def release(self) -> None:
        release_framebuffer(self.composite_framebuffer)
        release_framebuffer(self.color_framebuffer)
        release_framebuffer(self.view_framebuffer)
        release_framebuffer(self.framebuffer)
        for texture in (self.color, self.surface, self.seen, self.node, self.depth):
            texture.release()
        if self._depth_copy is not None:
            self._depth_copy.release()
            self._depth_copy = None


class LevelStack:
    """The render targets of one view tree: ``[0]`` is its root view's, ``[L]`` reflection
    level L's.  Each is made on first use and remade when its size changes (a resize, or
    another resolution scale); they are kept between frames, and a level keeps the set of
    the size it had before too, so a level the pixel budget draws at two sizes in turn
    (``ViewTree``) does not make and release GPU targets every frame.  A set kept so is
    one made for the root's present size: when the root's size changes (a window resized)
    the sets kept for the old one are released, and a level's set of the old root size is
    released, not kept, when the level is remade (at 1920x1080 a level's set is about
    50 MB of GPU memory)."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self._levels: list[RenderTargets | None] = []
        self._before: dict[int, RenderTargets] = {}  # level -> its targets of the size before
        self._made_for: dict[int, tuple[int, int]] = {}  # level -> the root's size when its set was made
        self.made = 0  # target sets made so far (tests watch it)
        self.seen_channels = SEEN_CHANNELS  # what a set made now has (set_seen_channels: the others released)

    def get(self, level: int, size: tuple[int, int]) -> RenderTargets:
        while len(self._levels) <= level:
            self._levels.append(None)
        targets = self._levels[level]
        if targets is None or targets.size != size:
            if level == 0 and targets is not None:  # the root resized: what was kept is the old size's
                for kept in self._before.values():
                    kept.release()
                self._before.clear()
            root = size if level == 0 else (self._levels[0].size if self._levels[0] is not None else None)
            spare = self._before.pop(level, None)
            if targets is not None:
                if level > 0 and self._made_for.get(level) == root:
                    self._before[level] = targets
                else:
                    targets.release()
            if spare is not None and spare.size == size:
                targets = spare
            else:
                if spare is not None:
                    spare.release()
                targets = RenderTargets(self.ctx, size, self.seen_channels)
                self.made += 1
            self._levels[level] = targets
            self._made_for[level] = root
        return targets

    def set_seen_channels(self, channels: int) -> None:
        """Make every set from now on with ``channels`` seen channels (``SEEN_CHANNELS`` or
        ``SEEN_MOVING_CHANNELS``); the sets held of the other kind are released."""
        if channels != self.seen_channels:
            self.release()
            self.seen_channels = channels

    def kept(self) -> int:
        """Target sets held besides the levels' own (the pixel budget's previous sizes)."""
        return len(self._before)

    def holds(self, targets: RenderTargets) -> bool:
        """Whether ``targets`` is one of its levels' sets."""
        return any(level is targets for level in self._levels)

    def __getitem__(self, level: int) -> RenderTargets:
        targets = self._levels[level]
        if targets is None:
            raise IndexError(f"level {level} has no targets yet")
        return targets

    def __len__(self) -> int:
        return len(self._levels)

    def release(self) -> None:
        for targets in (*self._levels, *self._before.values()):
            if targets is not None:
                targets.release()
        self._levels.clear()
        self._before.clear()
        self._made_for.clear()


class CaptureTarget:
    """An RGBA8 target the present pass writes to: the output when there is no window
    (headless runs), and the encoded frame the FXAA pass reads (clamped to the edge)."""

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int]) -> None:
        check_target_size(ctx, size, "an output (capture target)")
        self.size = size
        self.texture = ctx.texture(size, 4)
        self.texture.repeat_x = self.texture.repeat_y = False
        self.framebuffer = ctx.framebuffer([self.texture])

    def read_rgb(self) -> np.ndarray:
        """sRGB uint8 (height, width, 3), row 0 at the top."""
        w, h = self.size
        data = np.frombuffer(self.framebuffer.read(components=3), np.uint8).reshape(h, w, 3)
        return np.flipud(data).copy()

    def release(self) -> None:
        release_framebuffer(self.framebuffer)
        self.texture.release()
