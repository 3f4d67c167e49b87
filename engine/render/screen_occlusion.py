"""Screen-space ambient occlusion of the active camera's view (``AmbientOcclusion`` on the
camera): the share of the light from all round that reaches each pixel's surface, which
the main view's scene pass multiplies into its ambient light and its sky and probe
reflections.

Three passes before the main view is drawn, at half the view's size in each direction (a
quarter of its pixels; ``half_resolution``) or at its size:

1. **Depth and normals**: the scene pass draws the view's opaque batches, and a guard band
   a tenth of the image wide about them, with the
   ``DEPTH_NORMALS`` build of the scene shader (``ScenePass.draw_depth_normals``: the
   same draws, visibility and cutouts as the view, shading nothing), writing each surface's
   own normal in the view's space and one over its distance along the view's axis
   (``shaders/include/occlusion_geometry.glsl``: a float image, read bilinearly where the
   passes look between texels), as Unity's depth-normals prepass and Godot's depth prepass
   do.  The main view cannot give them: it needs the occlusion while it shades.
2. **Find** (``shaders/screen_occlusion.frag``): ground-truth ambient occlusion (Jimenez
   et al. 2016, as Unreal's GTAO and Intel's XeGTAO): ``SLICES`` planes through the view
   direction a pixel, each searched ``STEPS`` depth samples each way for its horizons
   (``QUALITY_SAMPLES``: 3 and 8 at the default "medium")
   within the radius, the visible arc integrated against the cosine to the normal in closed
   form.  A 4 x 4 tile of pixels takes 16 rotations of the slices, so the tile samples
   ``16 x SLICES`` directions.
   Where a slice's samples cross the radius, the point at the radius on the surface between
   the two counts too: the last sample inside falls short of the radius by up to a step,
   which left a crease's occlusion lighter than the ground truth by about 0.04 (and would
   jump as a sample crossed the radius).  Measured against the ground truth in
   ``tests/test_ambient_occlusion.py``: within 0.02 on a floor beside a wall and on the wall
   (band means), and within 0.07 at every pixel, the screen's sides too: the depth and
   normals pass draws a guard band (``GUARD_SHARE``) about the view, so what occludes a
   pixel near the edge a little way off the screen is found (without it the crease at the
   screen's edge was 0.25 too light).
3. **Filter** (``shaders/screen_occlusion_filter.frag``): each texel takes the mean of the
   4 x 4 found texels about it (one tile: every rotation once), each weighed by how near it
   lies to the plane of the texel's surface, so a foreground edge keeps its own occlusion.
   It writes the two shares the scene pass multiplies (``SCREEN_OCCLUSION`` builds):
   ``visibility ** intensity`` for the light from all round, and that mixed by
   ``direct_light`` for the lights' direct light, with each texel's distance.

The scene pass brings the shares to its pixels (``scene.frag``'s
``screen_occlusion_shares``): the four texels about a pixel by their bilinear weights, each
also by how near its distance lies to the pixel's own (a joint bilateral upsample), so a
half-size image leaves no halo along silhouettes.  An earlier form filtered to every pixel
in a full-size pass and found the occlusion from full-size depth; at 640x360 on llvmpipe
(``python -m benchmarks lighting --variants off,occlusion``, interleaved) the occlusion then
cost 1.9x the rest of a plain frame (the filter's 16 taps at every pixel nearly half of
it), now 1.4x.

**Contact shadows** (``ContactShadows`` on the camera, with or without the occlusion): the find
pass's ``CONTACT_SHADOWS`` build also marches each texel's ray towards the sun through the
same depth (``contact_shadow``: a sample behind the surface the image shows, by less than the
thickness, hides the sun), the filter smooths the sun's share with the same weights and
writes it beside the occlusion's shares, and the scene pass multiplies it into the sun's
light (the brightest directional light, marked in the Lights block).  Without an
``AmbientOcclusion`` the images are the view's size (or half of it: the contact shadows'
``half_resolution``) and the find pass is the march alone (``AMBIENT_OCCLUSION`` builds find
the occlusion).  The lamps that ask (``PointLight.contact_shadows``, at most
``MAX_CONTACT_LAMPS``: ``ContactLamps``, the prepare stage's, by channel) are marched
towards too (``CONTACT_LAMPS``: each texel's ray to each lamp, no longer than the way to it)
into a second image, a channel a lamp, which the filter smooths alike and the scene's
``CONTACT_LAMPS`` builds read beside the shares (a sampler more: ``lamps_supported``).

**Reflection levels** (``AmbientOcclusion.reflection_depth``, ``ContactShadows.reflection_depth``:
the levels of mirror and portal views below the camera's that are found too, 1 by default):
the main view tree hands each such level to ``draw_level`` between its claims and its draw,
so a mirror or a portal shows its world occluded as the camera's view shows the world.  The
same three passes over the level's images (no guard band: a view ends at its surface's
outline, which is that view's screen edge): the depth and normals of every view of the
level, each on its own claimed pixels (masked by the level's node image); the find drawn
once a view over its rectangle (``LEVEL_VIEWS`` builds: its own pixels only, the sun turned
into its space, a sample on another view's pixels ending the search as the image's edge
does); the filter, which weighs only the texels of the view that drew each texel.  The
level's views are then drawn one by one (not the batched path) with the ``SCREEN_OCCLUSION``
builds, masked.  Those read one sampler more than the fullest masked build (17; 18 with
spot cookies): a context with fewer fragment-stage texture units than that finds the
camera's view alone and says so once (a ``GLLimitWarning``).

**Monitors' pictures** (``draw_picture``): a monitor's camera with an ``AmbientOcclusion`` or
``ContactShadows`` of its own has its picture's found as the active camera's view's is (the
same three passes, the guard band, images of the picture's size kept by monitor), before
the picture's root view is drawn; its mirror and portal levels as far as its camera's
components reach (``draw_level``, images of the picture's own; the active camera's put aside
until ``end_picture``).

Probe views and the transparent slot are drawn without it.  The targets are made at the
first occluded frame of a size (a level's at the first frame that finds it) and released
when no camera asks for occlusion (``release_targets``), a level's when the camera's depth
no longer reaches it."""
from __future__ import annotations

import struct
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import moderngl
from pyglm import glm

from components.ambient import OCCLUSION_QUALITIES, AmbientOcclusion, ContactShadows
from components.limits import MAX_CONTACT_LAMPS
from engine.core.errors import GLLimitWarning
from engine.render.bindings import (
    OCCLUSION_IMAGE_UNIT,
    OCCLUSION_LAMPS_UNIT,
    OCCLUSION_NODE_UNIT,
    OCCLUSION_NORMAL_UNIT,
    PassState,
    apply_pass_state,
    assign_slots,
    bind_texture,
    set_scissor,
)
from engine.render.gpu import Gpu
from engine.render.picture_images import PictureImages
from engine.render.scene_pass import ScenePass, stepped_scissor
from engine.render.spot_cookies import SCENE_SAMPLERS
from engine.render.targets import RenderTargets, check_target_size, release_framebuffer
from engine.render.views import View

# AmbientOcclusion.quality -> (slice planes a pixel, depth samples each way along a slice):
# shaders/screen_occlusion.frag's SLICES and STEPS.  Against the ground truth of
# tests/test_ambient_occlusion.py's floor and wall (band means, 200 x 150, half size) each is
# within 0.02 (the 4 x 4 tile's rotations make 16 x SLICES directions); more samples make a
# smoother image where small things occlude.  "low" is half the find pass's samples.
QUALITY_SAMPLES = dict(zip(OCCLUSION_QUALITIES, ((2, 6), (3, 8), (4, 12)), strict=True))
# The reach on screen, at most this share of the view's height: a radius that spans more
# (the camera up against a wall) samples as far as this, so what occludes is looked for
# nearer than ``radius`` there.  (A quarter cut the horizons short at a 1 m radius 3.5 m
# off, 150 pixels high: 0.01 lighter creases.)
MAX_REACH_SHARE = 0.5
# The guard band: the depth and normals pass draws this share of the images' size beyond each
# side of the view (the same pixels' size, a wider frustum), so what occludes a pixel near
# the edge of the screen is there to be found.  Only that pass is wider (its pixels cost
# least); the find and filter passes run over the view's own pixels.
GUARD_SHARE = 0.1
# The fragment-stage texture units an occluded reflection level's fullest build reads: the
# fullest masked build's, the occlusion image, and spot cookies' array.
LEVEL_SAMPLERS = SCENE_SAMPLERS + 2
_PASS = PassState()
# Each texel the find leaves (another view's, or none of the level's): "nothing found there".
_NOTHING_FOUND = (1.0, -1.0, 1.0, 1.0)
# The scene builds' define where the contact lamps' image is read (Gpu.contact_lamp_defines).
_LAMP_DEFINES = (("CONTACT_LAMPS", "1"),)


@dataclass
class _Targets:
    """One size's images (half the view's, or all of it): the depth and normals pass's (the
    normals and distances, and the depth its draws test), the occlusion found and the shares
    the scene pass reads."""

    size: tuple[int, int]          # the found and shares images' (half the view's, or the view's)
    view_size: tuple[int, int]
    margin: tuple[int, int]        # the guard band, each side: the depth and normals are size + 2 margin
    depth: moderngl.Texture
    normals: moderngl.Texture      # occlusion_geometry.glsl's: the view-space normal, 1 / distance
    prepass: moderngl.Framebuffer
    found: moderngl.Texture
    found_lamps: moderngl.Texture  # the contact lamps' shares found (a channel each; 1 without)
    found_framebuffer: moderngl.Framebuffer
    shares: moderngl.Texture
    shares_lamps: moderngl.Texture  # ... filtered: what the scene builds read beside the shares
    shares_framebuffer: moderngl.Framebuffer

    def release(self) -> None:
        for framebuffer in (self.prepass, self.found_framebuffer, self.shares_framebuffer):
            release_framebuffer(framebuffer)
        for texture in (self.depth, self.normals, self.found, self.found_lamps, self.shares, self.shares_lamps):
            texture.release()


def _guarded(view: View, size: tuple[int, int], margin: tuple[int, int]) -> View:
    """``view`` widened by ``margin`` pixels of an image of ``size`` on each side: the same
    eye and pixel size, the frustum scaled out (x and y of the projection's clip space by
    size / (size + 2 margin), an off-centre shift with them)."""
    wide = (size[0] + 2 * margin[0], size[1] + 2 * margin[1])
    sx, sy = size[0] / wide[0], size[1] / wide[1]
    proj = glm.mat4(view.proj)
    proj[0, 0], proj[2, 0] = proj[0, 0] * sx, proj[2, 0] * sx
    proj[1, 1], proj[2, 1] = proj[1, 1] * sy, proj[2, 1] * sy
    return View(view=view.view, proj=proj, eye=view.eye, size=wide, name=f"{view.name} (occlusion)",
                clip_plane=view.clip_plane, mirrored=view.mirrored, skip=view.skip, hide=view.hide,
                kinds=view.kinds, layers=view.layers)


class ScreenOcclusion:
    """The active camera's ambient occlusion and contact shadows: ``draw`` a view's, which
    returns the image the main view's ``SCREEN_OCCLUSION`` builds read (and leaves it as
    ``Gpu.screen_occlusion``)."""

    def __init__(self, gpu: Gpu, scene_pass: ScenePass) -> None:
        self.gpu = gpu
        self.ctx = gpu.ctx
        self.scene_pass = scene_pass
        self._targets: _Targets | None = None
        self._levels: dict[int, _Targets] = {}  # a reflection level's images, by its depth
        # The find's builds by quality, contact samples, node step (0: the root's; 1 or 2: a
        # level's, LEVEL_VIEWS with that NODE_STEP), sun and lamps; the filter's by node step.
        self._finds: dict[tuple[str | None, int, int, bool, bool], moderngl.VertexArray] = {}
        self._filters: dict[int, moderngl.VertexArray] = {}
        # What the camera's view was found with this frame (draw), which its reflection levels
        # are found with where its components' reflection_depth reaches them (draw_level):
        # (AmbientOcclusion or None, ContactShadows or None, the way to the sun or None, the
        # contact lamps' world positions by channel).
        self.frame: tuple[AmbientOcclusion | None, ContactShadows | None, glm.vec3 | None, tuple] | None = None
        # Whether the context has the texture units an occluded level's builds read
        # (LEVEL_SAMPLERS), and one more for the contact lamps' image.
        self.levels_supported = gpu.caps.max_texture_image_units >= LEVEL_SAMPLERS
        self.lamps_supported = gpu.caps.max_texture_image_units >= LEVEL_SAMPLERS + 1
        self._said_no_units = False
        self._said_no_lamp_units = False
        self._programs_of = -1  # the shader library's reloads when they were made
        # What the shares image was last found from (``_still_key``): equal, the passes are
        # not run again and the image stands.
        self._found_from: tuple | None = None
        self.keep_still = True  # False: found every frame (what the still fuzz compares with)
        self._pictures: PictureImages[_Targets] = PictureImages()  # monitors' pictures' (draw_picture)
        # Their reflection levels' images, by monitor, then depth; and, while a picture is
        # drawn, the active camera's frame, levels and images put aside (``end_picture``).
        self._picture_levels: dict[int, dict[int, _Targets]] = {}
        self._aside: tuple | None = None
        # The debug overlay's toggle (``MainViewSystem.occlusion``): off, no camera's occlusion
        # or contact shadows are found, the active camera's or a monitor's.
        self.shown = True

    def _programs(self, quality: str | None, samples: int, step: int = 0, sun: bool = True,
                  lamps: bool = False) -> tuple[moderngl.VertexArray, moderngl.VertexArray]:
        """The find pass's build for ``quality`` (None: no occlusion) and ``samples`` contact
        samples (0: no contact shadows) towards the ``sun`` and the ``lamps``, and the
        filter's; ``step`` 0 the root's, else a reflection level's whose images are ``step``
        of its pixels a texel each way."""
        shaders = self.gpu.shaders
        if self._programs_of != shaders.reloads:
            self._release_programs()
            self._programs_of = shaders.reloads
        level = {"LEVEL_VIEWS": "1", "NODE_STEP": str(step)} if step else {}
        units = {"geometry_map": OCCLUSION_NORMAL_UNIT, "node_map": OCCLUSION_NODE_UNIT,
                 "occlusion_map": OCCLUSION_IMAGE_UNIT, "lamps_map": OCCLUSION_LAMPS_UNIT}
        key = (quality, samples, step, sun, lamps)
        find = self._finds.get(key)
        if find is None:
            defines = dict(level)
            if quality is not None:
                slices, steps = QUALITY_SAMPLES[quality]
                defines.update(AMBIENT_OCCLUSION="1", SLICES=str(slices), STEPS=str(steps))
            if samples:
                defines["CONTACT_SAMPLES"] = str(samples)
                if sun:
                    defines["CONTACT_SHADOWS"] = "1"
                if lamps:
                    defines["CONTACT_LAMPS"] = "1"
            program = assign_slots(shaders.program("fullscreen.vert", "screen_occlusion.frag", defines=defines), units)
            find = self._finds[key] = self.ctx.vertex_array(program, [])
        smooth = self._filters.get(step)
        if smooth is None:
            program = assign_slots(shaders.program("fullscreen.vert", "screen_occlusion_filter.frag", defines=level),
                                   units)
            smooth = self._filters[step] = self.ctx.vertex_array(program, [])
        return find, smooth

    def _make_targets(self, view_size: tuple[int, int], half: bool, guard: bool) -> _Targets:
        """The images for a view (or level) of ``view_size``: half its size each way with
        ``half``, and with ``guard`` a guard band about the depth and normals."""
        ctx = self.ctx
        size = (max(1, view_size[0] // 2), max(1, view_size[1] // 2)) if half else view_size
        margin = (round(GUARD_SHARE * size[0]), round(GUARD_SHARE * size[1])) if guard else (0, 0)
        guarded = (size[0] + 2 * margin[0], size[1] + 2 * margin[1])
        check_target_size(ctx, guarded, "ambient occlusion's images")
        depth = ctx.depth_texture(guarded)
        normals = ctx.texture(guarded, 4, dtype="f4")
        found = ctx.texture(size, 4, dtype="f2")
        shares = ctx.texture(size, 4, dtype="f2")
        found_lamps, shares_lamps = ctx.texture(size, 4), ctx.texture(size, 4)   # (shares 0 to 1: eight bits)
        for texture in (depth, normals, found, shares, found_lamps, shares_lamps):
            texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
            texture.repeat_x = texture.repeat_y = False
        normals.filter = (moderngl.LINEAR, moderngl.LINEAR)  # the find reads it between texels (texelFetch elsewhere)
        return _Targets(size, view_size, margin, depth, normals, ctx.framebuffer([normals], depth), found, found_lamps,
                        ctx.framebuffer([found, found_lamps]), shares, shares_lamps,
                        ctx.framebuffer([shares, shares_lamps]))

    def _targets_for(self, view_size: tuple[int, int], half: bool) -> _Targets:
        kept = self._targets
        want = (max(1, view_size[0] // 2), max(1, view_size[1] // 2)) if half else view_size
        if kept is not None and kept.size == want and kept.view_size == view_size:
            return kept
        self._release_root()
        self._targets = self._make_targets(view_size, half, guard=True)
        return self._targets

    def draw(self, view: View, settings: AmbientOcclusion | None, contact: ContactShadows | None = None,
             sun: glm.vec3 | None = None, lamps: Sequence[tuple[float, float, float]] = ()) -> moderngl.Texture:
        """Find ``view``'s occlusion as ``settings`` say (None: none) and its contact shadows
        as ``contact`` says, towards ``sun`` (world, the way to the sun; None: no sun) and the
        ``lamps`` (world positions, a channel each: ``ContactLamps``); returns the shares image
        (half the view's size, or all of it), bound for the main view's draw."""
        lamps = self.usable_lamps(lamps)
        if sun is None and not lamps:
            contact = None
        if settings is None and contact is None:
            raise ValueError("ScreenOcclusion.draw: nothing to find (no AmbientOcclusion, and no ContactShadows "
                             "with a sun or a lamp that has them)")
        if contact is None:
            lamps = ()
        self._set_frame(settings, contact, sun, lamps)
        half = settings.half_resolution if settings is not None else contact.half_resolution
        targets = self._targets_for(view.size, half)
        key = self._still_key(view, settings, contact, sun, lamps)
        if self.keep_still and key == self._found_from:  # nothing it is found from changed: the image stands
            self.restore_root()
            return targets.shares
        self._found_from = key
        # 1. Depth and normals, at the images' size, with the guard band about them.
        guard = _guarded(view, targets.size, targets.margin)
        self.scene_pass.draw_depth_normals([guard], targets.prepass, guard.size)
        # 2. and 3. The occlusion found, and filtered into the shares.
        self._find(targets, [view], guard.proj, settings, contact, sun, lamps, 0)
        self.restore_root()
        return targets.shares

    def draw_picture(self, monitor: int, view: View, settings: AmbientOcclusion | None,
                     contact: ContactShadows | None = None, sun: glm.vec3 | None = None,
                     lamps: Sequence[tuple[float, float, float]] = ()) -> bool:
        """Find the occlusion and contact shadows of monitor ``monitor``'s picture, whose camera's
        ``view`` is about to be drawn (``settings``, ``contact``, ``sun`` and ``lamps`` as for
        ``draw``: its camera's components), into images of the picture's own, with the guard
        band, and leave them as ``Gpu.screen_occlusion`` for its draw (``restore_root`` puts
        the active camera's back after).  Returns whether there was anything to find (with
        nothing, the picture's images are let go).  Found every time: a picture nothing it
        shows changed is kept whole by the monitor stage, so a drawing is a change."""
        lamps = self.usable_lamps(lamps)
        if sun is None and not lamps:
            contact = None
        if settings is None and contact is None:
            self.drop_picture(monitor)
            return False
        if contact is None:
            lamps = ()
        half = (settings or contact).half_resolution
        want = (max(1, view.size[0] // 2), max(1, view.size[1] // 2)) if half else view.size
        images = self._pictures.kept(monitor, lambda kept: kept.size == want and kept.view_size == view.size,
                                     lambda: self._make_targets(view.size, half, guard=True))
        guard = _guarded(view, images.size, images.margin)
        self.scene_pass.draw_depth_normals([guard], images.prepass, guard.size)
        self._find(images, [view], guard.proj, settings, contact, sun, lamps, 0)
        # Until ``end_picture``: the picture's frame, levels and images are the pass's (its
        # tree's levels are found as its camera's components reach, ``draw_level``, and
        # ``restore_root`` puts the picture's root back after each).
        if self._aside is None:
            self._aside = (self.frame, self._levels, self._targets)
        self._levels = self._picture_levels.setdefault(monitor, {})
        self._targets = images
        self._set_frame(settings, contact, sun, lamps)
        self._bind_shares(images, bool(lamps))
        return True

    def end_picture(self) -> None:
        """After a picture ``draw_picture`` found: the active camera's frame, levels and
        images back, its shares bound again (``restore_root``)."""
        if self._aside is not None:
            self.frame, self._levels, self._targets = self._aside
            self._aside = None
        self.restore_root()

    def drop_picture(self, monitor: int) -> None:
        """Let go of monitor ``monitor``'s picture's images (it went, or its camera finds none),
        its levels' too."""
        self._pictures.drop(monitor)
        for images in self._picture_levels.pop(monitor, {}).values():
            images.release()

    def usable_lamps(self, lamps: Sequence[tuple[float, float, float]]) -> tuple:
        """``lamps`` (the contact lamps' positions), or none where the context lacks the texture
        unit their image takes in the scene builds (said once: a ``GLLimitWarning``)."""
        if lamps and not self.lamps_supported:
            if not self._said_no_lamp_units:
                self._said_no_lamp_units = True
                warnings.warn(GLLimitWarning(
                    f"contact shadows of point lights need {LEVEL_SAMPLERS + 1} texture units in the fragment stage "
                    f"and this OpenGL has {self.gpu.caps.max_texture_image_units} (GL_MAX_TEXTURE_IMAGE_UNITS): the "
                    "lights with contact_shadows shine without them"), stacklevel=4)
            return ()
        return tuple(lamps)

    def draw_level(self, depth: int, views: Sequence[View], targets: RenderTargets) -> moderngl.Texture | None:
        """Find the occlusion and contact shadows of reflection level ``depth`` (1: the views of
        mirrors and portals the camera sees), whose ``views`` are about to be drawn into
        ``targets`` (its claims made: its node image says which view has which pixel), where the
        camera's components reach that deep (``frame``); returns its shares image, left as
        ``Gpu.screen_occlusion`` for the level's draw (``restore_root`` puts the camera's back),
        or None: the level is drawn without."""
        if self.frame is None or not views or not self.levels_supported:
            return None
        settings, contact, sun, lamps = self.frame
        if settings is not None and depth > settings.reflection_depth:
            settings = None
        if contact is not None and depth > contact.reflection_depth:
            contact = None
        if settings is None and contact is None:
            return None
        half = (settings or contact).half_resolution
        images = self._levels.get(depth)
        want = (max(1, targets.size[0] // 2), max(1, targets.size[1] // 2)) if half else targets.size
        if images is None or images.size != want or images.view_size != targets.size:
            if images is not None:
                images.release()
            images = self._levels[depth] = self._make_targets(targets.size, half, guard=False)
        step = 2 if half else 1
        self.scene_pass.draw_depth_normals(views, images.prepass, images.size, targets.node, step)
        if contact is None:
            lamps = ()
        self._find(images, views, views[0].proj, settings, contact, sun, lamps, step, targets.node)
        self._bind_shares(images, bool(lamps))
        return images.shares

    def restore_root(self) -> None:
        """Put the camera's own view's shares back as ``Gpu.screen_occlusion`` (after a level's
        draw), and its contact lamps' image as ``Gpu.screen_contact_lamps``."""
        lamps = self.frame is not None and bool(self.frame[3])
        self._bind_shares(self._targets, lamps)

    def _bind_shares(self, targets: _Targets | None, lamps: bool) -> None:
        """``targets``' shares what the scene builds read (``Gpu.screen_occlusion``), with its
        contact lamps' image and their builds (``Gpu.contact_lamp_defines``) where ``lamps``."""
        gpu = self.gpu
        gpu.screen_occlusion = None if targets is None else targets.shares
        gpu.screen_contact_lamps = targets.shares_lamps if targets is not None and lamps else None
        gpu.contact_lamp_defines = _LAMP_DEFINES if gpu.screen_contact_lamps is not None else ()

    def _find(self, targets: _Targets, views: Sequence[View], proj: glm.mat4, settings: AmbientOcclusion | None,
              contact: ContactShadows | None, sun: glm.vec3 | None, lamps: tuple, step: int,
              nodes: moderngl.Texture | None = None) -> None:
        """Passes 2 and 3 over ``targets``' depth and normals: the find (once a view of a
        level, ``step`` > 0, over its rectangle; the root's one view over all of it) and the
        filter.  ``proj``: the projection the depth and normals were drawn with (its x and y
        rows, a level's views' alike, put a texel back in its view's space)."""
        gpu, ctx = self.gpu, self.ctx
        find, smooth = self._programs(settings.quality if settings is not None else None,
                                      contact.samples if contact is not None else 0, step, sun is not None,
                                      bool(lamps))
        width, height = targets.size
        depth_size = (float(targets.size[0] + 2 * targets.margin[0]), float(targets.size[1] + 2 * targets.margin[1]))
        # What both passes read to put a texel back in its view's space (view_depth.glsl), and
        # where the view's pixels start in the guarded images.
        unproject = {"unproject": (float(proj[0][0]), float(proj[1][1]), float(proj[2][0]), float(proj[2][1])),
                     "depth_size": depth_size, "margin": targets.margin}
        targets.found_framebuffer.use()
        apply_pass_state(ctx, _PASS, (0, 0, width, height))
        if step:  # (each view's draw finds its own pixels: the rest say "nothing found")
            targets.found_framebuffer.clear(*_NOTHING_FOUND)
            bind_texture(ctx, nodes, OCCLUSION_NODE_UNIT)
        bind_texture(ctx, targets.normals, OCCLUSION_NORMAL_UNIT)
        program = find.program
        for name, value in unproject.items():
            if name in program:
                program[name].value = value
        if settings is not None:
            program["radius"].value = settings.radius
            program["pixels_per_metre"].value = float(proj[1][1]) * 0.5 * depth_size[1]
            program["max_radius_pixels"].value = max(MAX_REACH_SHARE * height,
                                                     float(QUALITY_SAMPLES[settings.quality][1]))
        if contact is not None:
            program["contact"].value = (contact.length, contact.thickness, contact.opacity, contact.distance)
        for view in views:
            if step:
                set_scissor(ctx, stepped_scissor(view.scissor, step, targets.size))
                program["node"].value = view.node
            if contact is not None and sun is not None:
                program["sun_view"].value = tuple(glm.normalize(glm.mat3(view.view) * glm.vec3(sun)))
            if lamps:
                program["lamp_view"].write(_lamp_rows(view, lamps))
            find.render(moderngl.TRIANGLES, vertices=3)
        # 3. Filtered into the shares.
        targets.shares_framebuffer.use()
        apply_pass_state(ctx, _PASS, (0, 0, width, height))
        bind_texture(ctx, targets.found, OCCLUSION_IMAGE_UNIT)
        bind_texture(ctx, targets.found_lamps, OCCLUSION_LAMPS_UNIT)
        program = smooth.program
        for name, value in unproject.items():
            if name in program:
                program[name].value = value
        program["intensity"].value = settings.intensity if settings is not None else 1.0
        program["direct_light"].value = settings.direct_light if settings is not None else 0.0
        smooth.render(moderngl.TRIANGLES, vertices=3)
        stats = gpu.stats
        stats.passes += 2
        stats.draw_calls += len(views) + 1
        if gpu.debug:
            gpu.checkpoint("ambient occlusion" if not step else f"ambient occlusion ({views[0].name} and its level)")

    def _set_frame(self, settings: AmbientOcclusion | None, contact: ContactShadows | None,
                   sun: glm.vec3 | None, lamps: tuple) -> None:
        """What this frame's reflection levels are found with; a level the components no longer
        reach lets its images go, and a context without the units they need says so once."""
        self.frame = (settings, contact, sun, lamps)
        reach = max(settings.reflection_depth if settings is not None else 0,
                    contact.reflection_depth if contact is not None else 0)
        for depth in [depth for depth in self._levels if depth > reach]:
            self._levels.pop(depth).release()
        if reach and not self.levels_supported and not self._said_no_units:
            self._said_no_units = True
            warnings.warn(GLLimitWarning(
                f"ambient occlusion and contact shadows in mirror and portal views (reflection_depth {reach}) need "
                f"{LEVEL_SAMPLERS} texture units in the fragment stage and this OpenGL has "
                f"{self.gpu.caps.max_texture_image_units} (GL_MAX_TEXTURE_IMAGE_UNITS): only the camera's own view "
                "has them"), stacklevel=3)

    def level_key(self) -> tuple | None:
        """What this frame's reflection levels are found with, as values (the reflect stage's
        still key: a change draws its levels again)."""
        if self.frame is None or not self.levels_supported:
            return None
        settings, contact, sun, lamps = self.frame
        return (_occlusion_values(settings), None if settings is None else settings.reflection_depth,
                _contact_values(contact, sun, lamps), None if contact is None else contact.reflection_depth)

    def target_count(self) -> int:
        """Images held now (4 while a camera asks for occlusion, and 4 for each reflection
        level found, each monitor's picture found and each of its levels, else 0)."""
        aside = self._aside if self._aside is not None else (None, self._levels, self._targets)
        levels = sum(len(kept) for kept in self._picture_levels.values())
        return 4 * ((aside[2] is not None) + len(aside[1]) + len(self._pictures) + levels)

    def _still_key(self, view: View, settings: AmbientOcclusion | None, contact: ContactShadows | None,
                   sun: glm.vec3 | None, lamps: tuple) -> tuple:
        """What the occlusion is found from: every instance row, batch and texture the depth
        pass draws (``Gpu.scene_version``, moved on by each upload of them), the shaders, the
        view's Camera block (pose, projection, layers, the entities it leaves out) and size,
        the settings, the sun and the lamps.  A still scene (the camera and what it sees not moving)
        finds it once."""
        return (self.gpu.scene_version, self.gpu.shaders.reloads, view.camera_block(), view.size,
                _occlusion_values(settings), _contact_values(contact, sun, lamps))

    def release_levels(self) -> None:
        """Let the reflection levels' images go (the world has no mirror or portal now)."""
        for images in self._levels.values():
            images.release()
        self._levels.clear()

    def _release_root(self) -> None:
        if self._targets is not None:
            self._targets.release()
            self._targets = None
        self._found_from = None

    def release_targets(self) -> None:
        """Let the images go (no camera asks for occlusion), the levels' too."""
        self._release_root()
        self.release_levels()
        self.frame = None
        self._bind_shares(None, False)

    def _release_programs(self) -> None:
        for vao in (*self._finds.values(), *self._filters.values()):
            vao.release()
        self._finds.clear()
        self._filters.clear()

    def release(self) -> None:
        self.release_targets()
        for monitor in list(self._picture_levels):
            self.drop_picture(monitor)
        self._pictures.release()
        self._release_programs()


def _occlusion_values(settings: AmbientOcclusion | None) -> tuple | None:
    """What of ``settings`` the images are found from."""
    if settings is None:
        return None
    return settings.radius, settings.intensity, settings.direct_light, settings.half_resolution, settings.quality


def _contact_values(contact: ContactShadows | None, sun: glm.vec3 | None, lamps: tuple) -> tuple | None:
    """What of ``contact`` (towards ``sun`` and the ``lamps``) the images are found from."""
    if contact is None:
        return None
    return (contact.length, contact.thickness, contact.opacity, contact.distance, contact.samples,
            contact.half_resolution, None if sun is None else tuple(sun), lamps)


def _lamp_rows(view: View, lamps: tuple) -> bytes:
    """The find's ``lamp_view``: each contact lamp's place in ``view``'s space, w 1, by channel
    (a channel with no lamp all 0)."""
    rows = [(*(view.view * glm.vec4(*lamp, 1.0)).xyz, 1.0) for lamp in lamps]
    rows += [(0.0, 0.0, 0.0, 0.0)] * (MAX_CONTACT_LAMPS - len(rows))
    return struct.pack(f"{4 * MAX_CONTACT_LAMPS}f", *(value for row in rows for value in row))
