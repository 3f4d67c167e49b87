"""Screen-space ambient occlusion of the active camera's view (``AmbientOcclusion`` on the
camera): the share of the light from all round that reaches each pixel's surface, which
the main view's scene pass multiplies into its ambient light and its sky and probe
reflections.

Three passes before the main view is drawn, at half the view's size in each direction (a
quarter of its pixels; ``half_resolution``) or at its size:

1. **Depth and normals**: the scene pass draws the view's opaque batches, and a guard band
   a tenth of the image wide about them, with the
   ``DEPTH_NORMALS`` build of the scene shader (``ScenePass.draw_depth_normals``: the
   same draws, visibility and cutouts as the view, shading nothing), writing the depth and
   each surface's own normal, as Unity's depth-normals prepass and Godot's depth prepass do.
   The main view cannot give them: it needs the occlusion while it shades.
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
the occlusion).

Only the root view is occluded; mirror, portal and probe views and the transparent slot are
drawn without it.  The targets are made at the first occluded frame of a size and released
when no camera asks for occlusion (``release_targets``)."""
from __future__ import annotations

from dataclasses import dataclass

import moderngl
from pyglm import glm

from components.ambient import OCCLUSION_QUALITIES, AmbientOcclusion, ContactShadows
from engine.render.bindings import (
    OCCLUSION_DEPTH_UNIT,
    OCCLUSION_IMAGE_UNIT,
    OCCLUSION_NORMAL_UNIT,
    PassState,
    apply_pass_state,
    assign_slots,
    bind_texture,
)
from engine.render.gpu import Gpu
from engine.render.scene_pass import ScenePass
from engine.render.targets import check_target_size, release_framebuffer
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
_PASS = PassState()


@dataclass
class _Targets:
    """One size's images (half the view's, or all of it): the depth and normals pass's, the
    occlusion found and the shares the scene pass reads."""

    size: tuple[int, int]          # the found and shares images' (half the view's, or the view's)
    view_size: tuple[int, int]
    margin: tuple[int, int]        # the guard band, each side: the depth and normals are size + 2 margin
    depth: moderngl.Texture
    normals: moderngl.Texture
    prepass: moderngl.Framebuffer
    found: moderngl.Texture
    found_framebuffer: moderngl.Framebuffer
    shares: moderngl.Texture
    shares_framebuffer: moderngl.Framebuffer

    def release(self) -> None:
        for framebuffer in (self.prepass, self.found_framebuffer, self.shares_framebuffer):
            release_framebuffer(framebuffer)
        for texture in (self.depth, self.normals, self.found, self.shares):
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
        self._finds: dict[tuple[str | None, int], moderngl.VertexArray] = {}  # by quality and contact samples
        self._filter: moderngl.VertexArray | None = None
        self._programs_of = -1  # the shader library's reloads when they were made
        # What the shares image was last found from (``_still_key``): equal, the passes are
        # not run again and the image stands.
        self._found_from: tuple | None = None
        self.keep_still = True  # False: found every frame (what the still fuzz compares with)

    def _programs(self, quality: str | None, samples: int) -> tuple[moderngl.VertexArray, moderngl.VertexArray]:
        """The find pass's build for ``quality`` (None: no occlusion) and ``samples`` contact
        samples (0: no contact shadows), and the filter's."""
        shaders = self.gpu.shaders
        if self._programs_of != shaders.reloads:
            self._release_programs()
            self._programs_of = shaders.reloads
        find = self._finds.get((quality, samples))
        if find is None:
            defines = {}
            if quality is not None:
                slices, steps = QUALITY_SAMPLES[quality]
                defines.update(AMBIENT_OCCLUSION="1", SLICES=str(slices), STEPS=str(steps))
            if samples:
                defines.update(CONTACT_SHADOWS="1", CONTACT_SAMPLES=str(samples))
            program = assign_slots(shaders.program("fullscreen.vert", "screen_occlusion.frag", defines=defines),
                                   {"depth_map": OCCLUSION_DEPTH_UNIT, "normal_map": OCCLUSION_NORMAL_UNIT})
            find = self._finds[(quality, samples)] = self.ctx.vertex_array(program, [])
        if self._filter is None:
            smooth = shaders.program("fullscreen.vert", "screen_occlusion_filter.frag")
            smooth["depth_map"].value = OCCLUSION_DEPTH_UNIT
            smooth["normal_map"].value = OCCLUSION_NORMAL_UNIT
            smooth["occlusion_map"].value = OCCLUSION_IMAGE_UNIT
            self._filter = self.ctx.vertex_array(smooth, [])
        return find, self._filter

    def _targets_for(self, view_size: tuple[int, int], half: bool) -> _Targets:
        size = (max(1, view_size[0] // 2), max(1, view_size[1] // 2)) if half else view_size
        kept = self._targets
        if kept is not None and kept.size == size and kept.view_size == view_size:
            return kept
        self.release_targets()
        ctx = self.ctx
        margin = (round(GUARD_SHARE * size[0]), round(GUARD_SHARE * size[1]))
        guarded = (size[0] + 2 * margin[0], size[1] + 2 * margin[1])
        check_target_size(ctx, guarded, "ambient occlusion's images")
        depth = ctx.depth_texture(guarded)
        depth.compare_func = ""  # read as distances, not compared
        normals = ctx.texture(guarded, 4)
        found = ctx.texture(size, 4, dtype="f2")
        shares = ctx.texture(size, 4, dtype="f2")
        for texture in (depth, normals, found, shares):
            texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
            texture.repeat_x = texture.repeat_y = False
        depth.filter = (moderngl.LINEAR, moderngl.LINEAR)  # the find reads it between texels (texelFetch elsewhere)
        self._targets = _Targets(size, view_size, margin, depth, normals, ctx.framebuffer([normals], depth), found,
                                 ctx.framebuffer([found]), shares, ctx.framebuffer([shares]))
        return self._targets

    def draw(self, view: View, settings: AmbientOcclusion | None, contact: ContactShadows | None = None,
             sun: glm.vec3 | None = None) -> moderngl.Texture:
        """Find ``view``'s occlusion as ``settings`` say (None: none) and its contact shadows
        as ``contact`` says, towards ``sun`` (world, the way to the sun; None: no sun, so no
        contact shadow); returns the shares image (half the view's size, or all of it), bound
        for the main view's draw."""
        gpu, ctx = self.gpu, self.ctx
        if sun is None:
            contact = None
        if settings is None and contact is None:
            raise ValueError("ScreenOcclusion.draw: nothing to find (no AmbientOcclusion, and no ContactShadows "
                             "with a sun)")
        half = settings.half_resolution if settings is not None else contact.half_resolution
        targets = self._targets_for(view.size, half)
        key = self._still_key(view, settings, contact, sun)
        if self.keep_still and key == self._found_from:  # nothing it is found from changed: the image stands
            gpu.screen_occlusion = targets.shares
            return targets.shares
        self._found_from = key
        find, smooth = self._programs(settings.quality if settings is not None else None,
                                      contact.samples if contact is not None else 0)
        width, height = targets.size
        # 1. Depth and normals, at the images' size, with the guard band about them.
        guard = _guarded(view, targets.size, targets.margin)
        self.scene_pass.draw_depth_normals(guard, targets.prepass, guard.size)
        proj = guard.proj
        # What both passes read to put a depth texel back in the view's space (view_depth.glsl),
        # and where the view's pixels start in the guarded images.
        unproject = {"unproject": (float(proj[0][0]), float(proj[1][1]), float(proj[2][0]), float(proj[2][1])),
                     "unproject_z": (float(proj[2][2]), float(proj[3][2])),
                     "depth_size": (float(guard.size[0]), float(guard.size[1])), "margin": targets.margin}
        rotation = glm.mat3(view.view).to_bytes()
        # 2. The occlusion found.
        targets.found_framebuffer.use()
        apply_pass_state(ctx, _PASS, (0, 0, width, height))
        bind_texture(ctx, targets.depth, OCCLUSION_DEPTH_UNIT)
        bind_texture(ctx, targets.normals, OCCLUSION_NORMAL_UNIT)
        program = find.program
        for name, value in unproject.items():
            if name in program:
                program[name].value = value
        program["view_rotation"].write(rotation)
        if settings is not None:
            program["radius"].value = settings.radius
            program["pixels_per_metre"].value = float(proj[1][1]) * 0.5 * guard.size[1]
            program["max_radius_pixels"].value = max(MAX_REACH_SHARE * height,
                                                     float(QUALITY_SAMPLES[settings.quality][1]))
        if contact is not None:
            program["sun_view"].value = tuple(glm.normalize(glm.mat3(view.view) * glm.vec3(sun)))
            program["contact"].value = (contact.length, contact.thickness, contact.opacity, contact.distance)
        find.render(moderngl.TRIANGLES, vertices=3)
        # 3. Filtered into the shares.
        targets.shares_framebuffer.use()
        apply_pass_state(ctx, _PASS, (0, 0, width, height))
        bind_texture(ctx, targets.found, OCCLUSION_IMAGE_UNIT)
        program = smooth.program
        for name, value in unproject.items():
            program[name].value = value
        program["view_rotation"].write(rotation)
        program["intensity"].value = settings.intensity if settings is not None else 1.0
        program["direct_light"].value = settings.direct_light if settings is not None else 0.0
        smooth.render(moderngl.TRIANGLES, vertices=3)
        stats = gpu.stats
        stats.passes += 2
        stats.draw_calls += 2
        gpu.screen_occlusion = targets.shares
        if gpu.debug:
            gpu.checkpoint("ambient occlusion")
        return targets.shares

    def target_count(self) -> int:
        """Images held now (4 while a camera asks for occlusion, else 0)."""
        return 0 if self._targets is None else 4

    def _still_key(self, view: View, settings: AmbientOcclusion | None, contact: ContactShadows | None,
                   sun: glm.vec3 | None) -> tuple:
        """What the occlusion is found from: every instance row, batch and texture the depth
        pass draws (``Gpu.scene_version``, moved on by each upload of them), the shaders, the
        view's Camera block (pose, projection, layers, the entities it leaves out) and size,
        the settings and the sun.  A still scene (the camera and what it sees not moving)
        finds it once."""
        occlusion = None if settings is None else (settings.radius, settings.intensity, settings.direct_light,
                                                   settings.half_resolution, settings.quality)
        shadows = None if contact is None else (contact.length, contact.thickness, contact.opacity,
                                                contact.distance, contact.samples, contact.half_resolution, tuple(sun))
        return (self.gpu.scene_version, self.gpu.shaders.reloads, view.camera_block(), view.size, occlusion, shadows)

    def release_targets(self) -> None:
        """Let the images go (no camera asks for occlusion, or another size)."""
        if self._targets is not None:
            self._targets.release()
            self._targets = None
        self._found_from = None
        self.gpu.screen_occlusion = None

    def _release_programs(self) -> None:
        for vao in (*self._finds.values(), self._filter):
            if vao is not None:
                vao.release()
        self._finds.clear()
        self._filter = None

    def release(self) -> None:
        self.release_targets()
        self._release_programs()
