"""The present pass: the main view's finished HDR image (reflections composited in), times
exposure, encoded to sRGB into the output; with anti-aliasing on, encoded into an RGBA8
image (luma in alpha) that an FXAA pass (``shaders/fxaa.frag``) filters into the output.

With the active camera's ``Tonemap`` or ``Bloom`` (``components/post.py``) the order is:
bloom on the HDR image (``engine/render/bloom.py``; the image is only read), automatic
exposure measured from it (``engine/render/post.py``; on the GPU, nothing read back), then
one full-screen draw that mixes the bloom in, exposes (``2 ** Tonemap.exposure``, times the
adapted value), applies the tone curve (``shaders/include/tonemap.glsl``) and encodes to
sRGB, then FXAA.  Each combination (curve, bloom, automatic exposure) is a build of
``present.frag`` of its own.  Without either component the plain build draws, as before
(curve none, ``Renderer.exposure``), and the bloom and exposure textures are released.

FXAA runs once on the final colour: ids are never touched, and mirror and portal images,
already composited, get no seam at their edges.  Its walk along an edge (long nearly level
edges become ramps) is ``search_steps`` long: 8 on a GPU; 0 on a software rasteriser,
where each step costs ~4% of a mirrorless frame (every fetch is CPU time there), so it
blends only the pixels that stand out at an edge (the stair steps).

What post-processing adds to a frame, and where (640x360, no mirror, llvmpipe, process CPU
time, variants interleaved; ``python -m benchmarks lighting``): against a camera without
the components, which draws the same two full-screen passes (present and FXAA, the same
half-float image read and the same RGBA8 targets written), ``Tonemap(curve="agx")`` alone
adds about 10% (its curve: three log2 and three pow a pixel, ACES and PBR Neutral about a
quarter of that), ``Bloom()`` alone about 10% (the chain's nine draws, the first reading the
whole image, about 1.4 ms of CPU, and the present draw's one bilinear tap of the chain), so
``post`` is about 1.2x.  No pass runs at full resolution that the plain frame lacks; the
POST build fetches the image's texel where the plain one filters it.
"""
from __future__ import annotations

from dataclasses import dataclass

import moderngl

from components.post import (
    MAX_ABERRATION,
    TONEMAP_CURVES,
    Bloom,
    ChromaticAberration,
    ColorGrading,
    DepthOfField,
    FilmGrain,
    LensFlare,
    MotionBlur,
    Tonemap,
    Vignette,
)
from engine.assets.color_lut import ColorLut
from engine.assets.texture_data import TextureData
from engine.render.bindings import (
    BLOOM_UNIT,
    DIRT_UNIT,
    EXPOSURE_UNIT,
    FLARE_UNIT,
    FXAA_UNIT,
    LUT_UNIT,
    OCCLUSION_IMAGE_UNIT,
    PRESENT_UNIT,
    PassState,
    apply_pass_state,
    bind_texture,
)
from engine.render.bloom import BloomPass
from engine.render.depth_of_field import DepthOfFieldPass
from engine.render.gpu import GL_SRGB8_ALPHA8
from engine.render.grading import grade_uniforms, grades, lut_lookup, upload_lut
from engine.render.lens_flare import LensFlarePass
from engine.render.motion_blur import MotionBlurPass
from engine.render.object_motion import ObjectMotion
from engine.render.post import AutoExposure
from engine.render.resample import ResamplePass
from engine.render.shader_library import ShaderLibrary
from engine.render.targets import CaptureTarget
from engine.render.temporal_aa import TemporalPass
from engine.render.views import View

ANTIALIAS_MODES = ("fxaa", "taa", "off")
MAX_SEARCH_STEPS = 8   # the length of fxaa.frag's SEARCH table
GPU_SEARCH_STEPS = 8
_PRESENT = PassState()


def _vignette_ray(projection) -> tuple[float, float, float, float]:
    """The VIGNETTE build's ``vignette_ray``: normalised device x, y -> the tangents of the
    pixel's ray from the view axis (x / -z, y / -z in view space), for a perspective
    ``projection`` P: (ndc + (P[2][0], P[2][1])) / (P[0][0], P[1][1])."""
    p = projection
    return (1.0 / float(p[0][0]), 1.0 / float(p[1][1]), float(p[2][0]) / float(p[0][0]),
            float(p[2][1]) / float(p[1][1]))


GRAIN_SPREAD = 0.1     # FilmGrain.intensity 1: the grain moves the encoded picture up to 0.1 either way
GRAIN_SEEDS = 1 << 20  # film grain's frames go round after this many


@dataclass(frozen=True)
class CameraPost:
    """The active camera's post-processing components (None: it has none) and what they read
    of it: what the present stage hands ``PresentPass.draw`` each frame."""

    tonemap: Tonemap | None = None
    bloom: Bloom | None = None
    grading: ColorGrading | None = None
    vignette: Vignette | None = None
    focus: DepthOfField | None = None     # depth of field
    motion: MotionBlur | None = None      # motion blur
    aberration: ChromaticAberration | None = None
    grain: FilmGrain | None = None
    flare: LensFlare | None = None        # lens flare (drawn from the bloom's image: with a Bloom only)
    view: View | None = None              # this frame's main view (the vignette's rays, motion blur)
    fov_y: float | None = None            # the camera's field of view (the lens's; None: orthographic)


@dataclass(frozen=True)
class PictureLook:
    """How the last present exposed, graded and tone-mapped the frame: what a picture panel
    over it (``engine/render/text.py``: a monitor's picture on the HUD) goes through too, so it
    looks as the view does.  ``scale``: the linear exposure (the Tonemap's ``2^exposure``, else
    the renderer's); ``curve``: the tone curve ("none" clamps); ``exposure_state``: the adapted
    automatic exposure's 1x1 texture (its EV multiplies the scale), or None; ``grading``: the
    camera's ColorGrading where it changes a colour (its controls or its table), else None;
    ``lut``: its table's texture where it has one.  The lens's effects over the frame (bloom,
    flare, vignette, aberration, grain) are not the panel's: it lies over the lens's image, as
    a HUD does."""

    scale: float = 1.0
    curve: str = "none"
    exposure_state: moderngl.Texture | None = None
    grading: ColorGrading | None = None
    lut: moderngl.Texture3D | None = None


class PresentPass:
    def __init__(self, ctx: moderngl.Context, shaders: ShaderLibrary, software: bool, moving: ObjectMotion) -> None:
        self.ctx = ctx
        self.shaders = shaders
        self.moving = moving   # the frame's movers, whose own motion the motion blur streaks
        self._encode = self._fullscreen("present.frag")
        self._encode_luma = self._fullscreen("present.frag", LUMA_IN_ALPHA="1")
        for encode in (self._encode, self._encode_luma):
            encode.program["hdr_image"].value = PRESENT_UNIT
        self._fxaa: moderngl.VertexArray | None = None
        self._encoded: CaptureTarget | None = None    # what FXAA or the resample reads, at the drawn size
        self._filtered: CaptureTarget | None = None   # FXAA's picture when the resample reads it
        self.resample = ResamplePass(ctx, shaders)     # the last pass at a render scale or sharpening
        self.search_steps = 0 if software else GPU_SEARCH_STEPS
        self._post: dict[tuple, moderngl.VertexArray] = {}   # present.frag's POST builds, by their defines
        self._written: dict[tuple[int, str], object] = {}    # (vao id, uniform) -> the value last written
        self.bloom = BloomPass(ctx, shaders, software)
        self.lens_flare = LensFlarePass(ctx, shaders)
        self._dirt: tuple[TextureData, moderngl.Texture] | None = None   # the bloom's lens dirt, uploaded
        self.auto_exposure = AutoExposure(ctx, shaders)
        self.post_passes = 0   # passes past present and FXAA last frame (TAA, lens, blur, bloom, exposure, resample)
        self.look = PictureLook()   # the last frame's exposure and tone curve (a picture panel's)
        self._lut: tuple[ColorLut, moderngl.Texture3D] | None = None  # the grade's table, uploaded
        self._occlusion_view: moderngl.VertexArray | None = None  # the overlay's "AO only" view, made on first use
        self._depth_of_field: DepthOfFieldPass | None = None  # made when a camera first has a DepthOfField
        self._motion_blur: MotionBlurPass | None = None       # made when a camera first has a MotionBlur
        self._temporal: TemporalPass | None = None             # made when temporal AA is first on
        self.grain_seed = 0   # film grain's frame: a new one each frame with time in it

    @property
    def motion_blur(self) -> MotionBlurPass:
        """The motion blur pass (``engine/render/motion_blur.py``), made on first use."""
        if self._motion_blur is None:
            self._motion_blur = MotionBlurPass(self.ctx, self.shaders, self.moving)
        return self._motion_blur

    @property
    def temporal(self) -> TemporalPass:
        """The temporal anti-aliasing pass (``engine/render/temporal_aa.py``), made on first use."""
        if self._temporal is None:
            self._temporal = TemporalPass(self.ctx, self.shaders)
        return self._temporal

    @property
    def streaks_objects(self) -> bool:
        """Whether the last frame's motion blur streaked moving things by their own motion
        (``MotionBlur.objects``): the next frame's scene pass writes it (``ObjectMotion``)."""
        return self._motion_blur is not None and self._motion_blur.objects

    @property
    def depth_of_field(self) -> DepthOfFieldPass:
        """The depth-of-field pass (``engine/render/depth_of_field.py``), made on first use."""
        if self._depth_of_field is None:
            self._depth_of_field = DepthOfFieldPass(self.ctx, self.shaders)
        return self._depth_of_field

    @property
    def search_steps(self) -> int:
        """How far FXAA walks along an edge (0: no walk, only the small-feature blend)."""
        return self._search_steps

    @search_steps.setter
    def search_steps(self, steps: int) -> None:
        if not isinstance(steps, int) or not 0 <= steps <= MAX_SEARCH_STEPS:
            raise ValueError(f"FXAA search_steps must be an int from 0 to {MAX_SEARCH_STEPS}, got {steps!r}")
        if self._fxaa is not None:
            self._fxaa.release()
        self._fxaa = self._fullscreen("fxaa.frag", SEARCH_STEPS=str(steps))
        self._fxaa.program["frame"].value = FXAA_UNIT
        self._search_steps = steps

    def _fullscreen(self, fragment: str, **defines: str) -> moderngl.VertexArray:
        program = self.shaders.program("present.vert", fragment, defines=defines or None)
        return self.ctx.vertex_array(program, [])

    def _post_build(self, curve: str, bloom: bool, auto: bool, luma: bool, grade: bool = False,
                    lut: bool = False, vignette: bool = False, aberration: bool = False,
                    grain: bool = False, flare: bool = False, dirt: bool = False) -> moderngl.VertexArray:
        """The present build for these (``flare``: a lens flare's ghosts added; ``dirt``: the
        bloom's lens dirt)."""
        key = (curve, bloom, auto, luma, grade, lut, vignette, aberration, grain, flare, dirt)
        vao = self._post.get(key)
        if vao is None:
            defines = {"POST": "1", "TONEMAP_CURVE": str(TONEMAP_CURVES.index(curve))}
            if flare:
                defines["LENS_FLARE"] = "1"
            if dirt:
                defines["LENS_DIRT"] = "1"
            defines.update((name, "1") for name, on in (("BLOOM", bloom), ("AUTO_EXPOSURE", auto),
                                                        ("LUMA_IN_ALPHA", luma), ("GRADE", grade), ("LUT", lut),
                                                        ("VIGNETTE", vignette), ("ABERRATION", aberration),
                                                        ("GRAIN", grain)) if on)
            vao = self._post[key] = self._fullscreen("present.frag", **defines)
            vao.program["hdr_image"].value = PRESENT_UNIT
            if bloom:
                vao.program["bloom_image"].value = BLOOM_UNIT
            if flare:
                vao.program["flare_image"].value = FLARE_UNIT
            if dirt:
                vao.program["dirt_map"].value = DIRT_UNIT
            if auto:
                vao.program["exposure_state"].value = EXPOSURE_UNIT
            if lut:
                vao.program["lut_map"].value = LUT_UNIT
        return vao

    def draw(self, hdr: moderngl.Texture, exposure: float, antialias: str, output: moderngl.Framebuffer,
             size: tuple[int, int], post: CameraPost | None = None, curve: str | None = None,
             camera: int | None = None, dt: float = 0.0, seen: moderngl.Texture | None = None,
             sharpness: float = 0.0) -> None:
        """Present ``hdr`` into ``output`` (``size``; ``hdr`` may be smaller: drawn at a render
        scale below 1) as the active camera's ``post`` says (its components; None: none): first
        blurred by its lens (``focus``: ``seen`` is the same level's seen pair, its ways), then
        smeared by its motion (``motion``), then bloomed, exposed, vignetted, graded and tone
        mapped, then anti-aliased, brought up to ``size`` and sharpened by ``sharpness``
        (``engine/render/resample.py``).  ``curve`` overrides the tone curve (the
        debug overlay's choice; None: the Tonemap's, or "none"); ``camera`` is whose image it
        is (automatic exposure, autofocus and motion blur start over when it changes) and
        ``dt`` the frame's time step (adaptation)."""
        post = post if post is not None else CameraPost()
        tonemap, bloom, grading, vignette = post.tonemap, post.bloom, post.grading, post.vignette
        focus, motion, view = post.focus, post.motion, post.view
        projection = view.proj if view is not None else None
        fxaa = antialias == "fxaa"
        self.post_passes = 0
        if antialias == "taa" and seen is not None and view is not None:   # (first: the lens blurs a steady picture)
            # (brought up to size on the way; a supersampled picture is resolved at its own size
            # and brought down by the last pass)
            supersampled = hdr.size[0] > size[0] or hdr.size[1] > size[1]
            hdr = self.temporal.draw(hdr, seen, view, camera, dt, None if supersampled else size)
            self.post_passes += 1
        elif self._temporal is not None:
            self._temporal.release_targets()
        if focus is not None and seen is not None:
            hdr = self.depth_of_field.draw(hdr, seen, focus, post.fov_y, camera, dt)
            self.post_passes += self.depth_of_field.passes
        elif self._depth_of_field is not None:
            self._depth_of_field.release_targets()
        if motion is not None and seen is not None and view is not None and motion.shutter > 0.0:
            hdr = self.motion_blur.draw(hdr, seen, motion, view, camera, dt)
            self.post_passes += self.motion_blur.passes
        elif self._motion_blur is not None:
            self._motion_blur.release_targets()
        if grading is not None and not grades(grading) and (grading.lut is None or grading.lut_strength == 0.0):
            grading = None  # (nothing to grade: the same picture without it)
        if vignette is not None and (vignette.intensity == 0.0 or projection is None):
            vignette = None  # (no darkening: the same picture without it)
        aberration = post.aberration if post.aberration is not None and post.aberration.intensity > 0.0 else None
        grain = post.grain if post.grain is not None and post.grain.intensity > 0.0 else None
        if dt > 0.0:
            self.grain_seed = (self.grain_seed + 1) % GRAIN_SEEDS   # (a screenshot's grain is its frame's)
        drawn = hdr.size   # (the output's size, or smaller: a render scale below 1 without temporal AA)
        resample = drawn != size or sharpness > 0.0
        # Where the encoding goes: the output, or a picture FXAA or the resample reads.
        encoded = self._capture("_encoded", drawn if fxaa or resample else None)
        if tonemap is None and bloom is None and curve is None and grading is None and vignette is None \
                and aberration is None and grain is None:
            self._release_post_targets()
            encode = self._encode_luma if fxaa else self._encode
            bind_texture(self.ctx, hdr, PRESENT_UNIT)
            encode.program["exposure"].value = exposure
            self.look = PictureLook(exposure)
        else:
            encode = self._post_encode(hdr, exposure, tonemap, bloom, curve, camera, dt, fxaa, grading,
                                       vignette is not None, aberration is not None, grain is not None, post.flare)
            if aberration is not None:
                self._set(encode, "aberration", aberration.intensity * MAX_ABERRATION)
            if grain is not None:
                self._set(encode, "grain", (grain.intensity * GRAIN_SPREAD, grain.response, grain.size,
                                            float(self.grain_seed)))
            if vignette is not None:
                self._set(encode, "vignette_ray", _vignette_ray(projection))
                self._set(encode, "vignette", (vignette.intensity, vignette.falloff))
        (encoded.framebuffer if encoded is not None else output).use()
        apply_pass_state(self.ctx, _PRESENT, (0, 0, *drawn))
        encode.render(moderngl.TRIANGLES, vertices=3)
        picture = encoded
        if fxaa:
            filtered = self._capture("_filtered", drawn) if resample else None
            (filtered.framebuffer if filtered is not None else output).use()
            # Its own pass: a framebuffer's use() brings back the viewport last set while
            # moderngl took it for bound, which raw-GL passes may have left at any size.
            apply_pass_state(self.ctx, _PRESENT, (0, 0, *drawn))
            bind_texture(self.ctx, encoded.texture, FXAA_UNIT)
            self._fxaa.render(moderngl.TRIANGLES, vertices=3)
            picture = filtered
        if not resample:
            self._capture("_filtered", None)
        else:
            self.resample.draw(picture.texture, output, size, sharpness)
            self.post_passes += 1

    def _capture(self, name: str, size: tuple[int, int] | None) -> CaptureTarget | None:
        """The RGBA8 picture ``name`` ("_encoded": what FXAA or the resample reads; "_filtered":
        FXAA's, when the resample reads it) at ``size``, made again when the size changed;
        None: released."""
        kept = getattr(self, name)
        if kept is not None and (size is None or kept.size != size):
            kept.release()
            kept = None
        if kept is None and size is not None:
            kept = CaptureTarget(self.ctx, size)
        setattr(self, name, kept)
        return kept

    def _post_encode(self, hdr: moderngl.Texture, exposure: float, tonemap: Tonemap | None, bloom: Bloom | None,
                     curve: str | None, camera: int | None, dt: float, luma: bool,
                     grading: ColorGrading | None = None, vignette: bool = False, aberration: bool = False,
                     grain: bool = False, flare: LensFlare | None = None) -> moderngl.VertexArray:
        """Run bloom and automatic exposure; the present build to draw, its inputs bound (a lens
        ``flare`` drawn from the bloom's image: none without one)."""
        bloomed = None
        if bloom is not None and bloom.intensity > 0.0:
            bloomed = self.bloom.draw(hdr, bloom)
            self.post_passes += self.bloom.passes()
        if bloomed is None:
            self.bloom.release_targets()
        auto = tonemap is not None and tonemap.auto_exposure
        state = None
        if auto:
            state = self.auto_exposure.draw(hdr, tonemap, camera, dt)
            self.post_passes += self.auto_exposure.passes()
        else:
            self.auto_exposure.release_targets()
        curve = curve if curve is not None else (tonemap.curve if tonemap is not None else "none")
        lut = self._lut_texture(grading.lut if grading is not None and grading.lut_strength > 0.0 else None)
        graded = grades(grading)
        flared = None
        if flare is not None and bloomed is not None:
            flared = self.lens_flare.draw(bloomed, flare)
            self.post_passes += 1
        else:
            self.lens_flare.release_targets()
        dirt = self._dirt_texture(bloom.dirt if bloomed is not None and bloom.dirt_intensity > 0.0 else None)
        encode = self._post_build(curve, bloomed is not None, auto, luma, graded, lut is not None, vignette,
                                  aberration, grain, flared is not None, dirt is not None)
        if flared is not None:
            bind_texture(self.ctx, flared, FLARE_UNIT)
        if dirt is not None:
            bind_texture(self.ctx, dirt, DIRT_UNIT)
            self._set(encode, "dirt_intensity", bloom.dirt_intensity)
        scale = 2.0 ** tonemap.exposure if tonemap is not None else exposure
        self._set(encode, "exposure", scale)
        self.look = PictureLook(scale, curve, state, grading if graded or lut is not None else None, lut)
        if graded:
            self._set_grade(encode, grading)
        if lut is not None:
            bind_texture(self.ctx, lut, LUT_UNIT)
            scale, bias = lut_lookup(grading.lut)
            self._set(encode, "lut_scale", scale)
            self._set(encode, "lut_bias", bias)
            self._set(encode, "lut_strength", grading.lut_strength)
        bind_texture(self.ctx, hdr, PRESENT_UNIT)
        if bloomed is not None:
            bind_texture(self.ctx, bloomed, BLOOM_UNIT)
            share = bloom.intensity / self.bloom.levels
            self._set(encode, "bloom_mix", ((1.0 - bloom.intensity) if bloom.composite == "energy_conserving"
                                            else 1.0, share))
        if state is not None:
            bind_texture(self.ctx, state, EXPOSURE_UNIT)
        return encode

    def show_nothing(self, output: moderngl.Framebuffer, size: tuple[int, int]) -> None:
        """``output`` cleared to black: the frame of a world with no active camera, which
        otherwise kept the last frame drawn into it (a window's back buffer: whatever it held)."""
        output.use()
        whole = (0, 0, *size)
        apply_pass_state(self.ctx, _PRESENT, whole, whole)
        output.clear(0.0, 0.0, 0.0, 1.0, viewport=whole)

    def draw_occlusion(self, shares: moderngl.Texture, output: moderngl.Framebuffer, size: tuple[int, int]) -> None:
        """The debug view of ambient occlusion: ``shares`` (the camera's occlusion image,
        ``Gpu.screen_occlusion``) as grey into ``output``, in place of the picture."""
        if self._occlusion_view is None:
            self._occlusion_view = self._fullscreen("occlusion_view.frag")
            self._occlusion_view.program["occlusion_image"].value = OCCLUSION_IMAGE_UNIT
        output.use()
        apply_pass_state(self.ctx, _PRESENT, (0, 0, *size))
        filtered = shares.filter
        shares.filter = (moderngl.LINEAR, moderngl.LINEAR)
        bind_texture(self.ctx, shares, OCCLUSION_IMAGE_UNIT)
        self._occlusion_view.render(moderngl.TRIANGLES, vertices=3)
        shares.filter = filtered

    def _set_grade(self, encode: moderngl.VertexArray, grading: ColorGrading) -> None:
        """The GRADE build's uniforms from ``grading`` (``grade_uniforms``)."""
        for name, value in grade_uniforms(grading).items():
            self._set(encode, name, value)

    def _lut_texture(self, lut: ColorLut | None) -> moderngl.Texture3D | None:
        """``lut`` uploaded (once while it is the camera's), or None; a table no camera uses
        now is let go."""
        if self._lut is not None and self._lut[0] is not lut:
            self._lut[1].release()
            self._lut = None
        if lut is None:
            return None
        if self._lut is None:
            self._lut = (lut, upload_lut(self.ctx, lut))
        return self._lut[1]

    def _dirt_texture(self, dirt: TextureData | None) -> moderngl.Texture | None:
        """The bloom's lens ``dirt`` uploaded (sRGB, with mipmaps: once while it is the
        camera's), or None; an image no camera uses now is let go."""
        if self._dirt is not None and self._dirt[0] is not dirt:
            self._dirt[1].release()
            self._dirt = None
        if dirt is None:
            return None
        if self._dirt is None:
            h, w = dirt.pixels.shape[:2]
            texture = self.ctx.texture((w, h), 4, dirt.as_8_bits()[::-1].tobytes(), internal_format=GL_SRGB8_ALPHA8)
            texture.build_mipmaps()
            texture.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
            texture.repeat_x = texture.repeat_y = False
            self._dirt = (dirt, texture)
        return self._dirt[1]

    def _set(self, vao: moderngl.VertexArray, name: str, value) -> None:
        """Write a uniform of a POST build only when its value changes (each write is a GL call)."""
        key = (id(vao), name)
        if self._written.get(key) != value:
            if isinstance(value, bytes):
                vao.program[name].write(value)
            else:
                vao.program[name].value = value
            self._written[key] = value

    def release_post_targets(self) -> None:
        """Let the bloom chain, the automatic exposure, the grade's table and the depth of
        field's images go (no camera asks for them now)."""
        self._release_post_targets()
        if self._depth_of_field is not None:
            self._depth_of_field.release_targets()
        if self._motion_blur is not None:
            self._motion_blur.release_targets()

    def _release_post_targets(self) -> None:
        self._lut_texture(None)
        self._dirt_texture(None)
        if self.bloom.textures:
            self.bloom.release_targets()
        self.lens_flare.release_targets()
        if self.auto_exposure.current is not None:
            self.auto_exposure.release_targets()

    def post_target_count(self) -> int:
        """Textures the bloom chain, automatic exposure, the grade and depth of field hold now
        (0 without a camera that asks for them)."""
        return (self.bloom.target_count() + self.lens_flare.target_count() + len(self.auto_exposure._targets)
                + len(self.auto_exposure._state)
                + (self._lut is not None) + (self._dirt is not None)
                + (self._depth_of_field.target_count() if self._depth_of_field is not None else 0)
                + (self._motion_blur.target_count() if self._motion_blur is not None else 0)
                + (self._temporal.target_count() if self._temporal is not None else 0))

    def release(self) -> None:
        self._lut_texture(None)
        self._dirt_texture(None)
        self._capture("_encoded", None)
        self._capture("_filtered", None)
        self.resample.release()
        for vao in (self._encode, self._encode_luma, self._fxaa, *self._post.values()):
            vao.release()
        if self._occlusion_view is not None:
            self._occlusion_view.release()
            self._occlusion_view = None
        if self._depth_of_field is not None:
            self._depth_of_field.release()
            self._depth_of_field = None
        if self._motion_blur is not None:
            self._motion_blur.release()
            self._motion_blur = None
        if self._temporal is not None:
            self._temporal.release()
            self._temporal = None
        self._post.clear()
        self.bloom.release()
        self.lens_flare.release()
        self.auto_exposure.release()
