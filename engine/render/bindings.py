"""Every number two pieces of GL code must agree on, in one table, and the state each pass
sets at its start.

Texture units, uniform-block binding points and clip-distance indices are fixed for the
whole engine (OpenGL 4.1 has no ``layout(binding=)``, so programs are told their units
from here when they are built; the clip-distance indices reach the GLSL as ``#define``s,
``clip_glsl_defines``, that the shader library gives every program).  A unit may serve
different samplers in different passes (a claim's parent images, a composite's reflection
images) as long as no pass binds two of them to it.

``PassState`` is everything a pass's draws depend on besides its program and inputs:
depth test and function, face culling and winding, blending, which clip distances are on,
the scissor and the viewport.  Each pass applies its whole state when it starts
(``apply_pass_state``), so no pass relies on what the one before left behind and passes
can run in any order (tests/test_pass_state.py renders them shuffled).

Only what changed is set: ``apply_pass_state`` remembers, per context, the fixed-function
state it last set (flags, depth and blend functions, winding, clip distances) and skips a
moderngl setter whose value is already in place (on a GPU driver each setter is a call of
several microseconds, ``depth_func`` about 15).  The viewport and scissor are compared with
moderngl's own record for the bound framebuffer (``ctx.viewport``, ``ctx.scissor``: moderngl
keeps them per framebuffer and ``Framebuffer.use`` sets them again), so switching
framebuffers, or anyone setting them with moderngl's ``ctx.viewport``/``ctx.scissor``
(as passes do per view or claim), needs nothing more.  Within a pass, a winding changed per
view goes through ``set_front_face`` so the record stays true.  Uniform buffers are bound
to their binding points likewise once (``bind_uniform_block``: once a frame for the camera
and lights blocks, not once a view or pass), and textures to their units (``bind_texture``:
a unit keeps what it holds until a pass wants another texture there, so a frame's second
and later scene passes bind no shadow map, irradiance table or sky already in place).  The
record holds the texture object itself, per unit and kind (a unit has a 2D binding and a
cube-map binding of its own), so a released texture whose GL name is reused by a new one
is bound again (deleting a texture resets the units that held it to 0).  moderngl's own
texture work (making, writing, filtering, reading) binds on its default unit (the last of
the context's), which no pass uses.  A uniform-block range (``bind_uniform_range``: a view's
Camera block) is bound only where another is bound, so a level of one view binds none.  A
sampler object (``bind_sampler``: the reflection levels' albedo filter) stays on its unit
from one pass to the next until a pass binds otherwise with ``bind_sampler``, or binds a
texture on that unit through ``bind_texture`` (which takes it off first, so no other pass
is filtered by it); only ``bind_sampler`` binds sampler objects, so its record survives
``invalidate``.

**``invalidate(ctx)``** must be called after any other GL state is set other than through
these functions: moderngl's ``enable_only``/``enable``/``depth_func``/``blend_func``/
``front_face``/``enable_direct`` setters, or raw GL (``glViewport``, ``glDisable(GL_SCISSOR_TEST)``...).
The next ``apply_pass_state`` then sets everything, and every texture is bound again.
Where it is called: raw GL targets (engine/render/raw_gl.py) on binding and where they bind
textures themselves, an ``Engine`` when it is made (whatever used the context before it),
and the debug overlay after it draws (shell/overlay.py, moderngl setters of its own, after
a frame).  The record is kept from one frame to the next (``Engine.frame`` does not forget
it: a frame binds only what another pass displaced, not every texture and block again), so
any other code that sets state on the context, between frames or in the middle of one (a
pass of a game's own), calls it itself.
"""
from __future__ import annotations

import contextlib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from types import MappingProxyType

import moderngl

# --- texture units -----------------------------------------------------------------------
# What binds to a texture unit (``use(location)``; bind_texture).
Bindable = moderngl.Texture | moderngl.TextureCube | moderngl.TextureArray | moderngl.Texture3D
ALBEDO_UNIT = 0          # scene: the batch's albedo map
SKY_UNIT = 1             # scene, sky, composite: the sky cube map
NODE_UNIT = 2            # scene (masked views): the level's node image
# The claims read the parent level's node image where a masked scene pass of that level left
# it (NODE_UNIT: the next level's claims follow it, so it is bound already), and its surface
# image on a unit no scene pass samples: the claims between two levels' scene passes then
# displace none of the pass-wide bindings (point shadows on 3 and 4, irradiance on 5), which
# the next level's pass would bind again.
PARENT_NODE_UNIT = NODE_UNIT  # claim: the parent level's node image
PARENT_SURFACE_UNIT = 6  # claim: the parent level's surface image (the composite's ATLAS_UNIT)
REFLECTION_UNITS = (3, 4, 5)  # composite: the level's colour, seen-id and node images
ATLAS_UNIT = 6           # composite (rough variant): the rough-reflection atlas
# composite (fallback variants): the parent level's node and surface images, on the claims'
# units for them (the level's claims bound them there already), and never on the scene's
# albedo unit: a scene pass after a fallback would otherwise find an id image under its
# float albedo sampler (a batch with no map binds the blank one, Gpu.blank_color, again).
FALLBACK_PARENT_UNITS = (PARENT_NODE_UNIT, PARENT_SURFACE_UNIT)
LEVEL_UNITS = (3, 5)     # rough-atlas copy: a level's colour and node images (the composite's units for them)
OUTLINE_UNIT = 0         # selection outline (the editor): the main view's seen-id image (engine/render/outline.py)
PROBE_UNIT = 7           # scene: the cube map of the batch's reflection probe; composite (fallback): its draw's first
PROBE2_UNIT = 9          # scene: the cube map of the batch's second probe (probe blending); composite (fallback): the
                         # draw's second
HISTORY_UNIT = 10        # end images: the previous frame's main image (engine/render/end_images.py)
SETTLE_IMAGE_UNIT = 2    # end images' settle check: this frame's finished main image (history at HISTORY_UNIT)
PROBE_REST_UNIT = 10     # scene (PROBE_REST builds): the probe taking what the blend's weights leave (a curved
                         # object's own, probe_rules.probe_blend)
NORMAL_UNIT = 8          # scene: the batch's normal map; composite (bumpy mirrors): the mirror's
EMISSIVE_MAP_UNIT = 12   # scene: the batch's emissive map (Material.emissive_map)
METALLIC_ROUGHNESS_UNIT = 13  # scene: the batch's metallic-roughness map (Material.metallic_roughness_map)
CUBE_MIP_UNIT = 14       # cube-map mip pass: the cube whose next level it draws
SCRATCH_UNIT = 15        # raw-GL copies bind their target here; no program reads it
# Lighting (the scene pass binds these at its start: the passes that use 3, 4 and 5 for
# other images are not scene passes).
SHADOW_ATLAS_UNIT = 11   # scene: the directional lights' shadow maps, one depth atlas (sampler2DShadow)
POINT_SHADOW_UNITS = (3, 4)  # scene: the shadowed point lights' distance cube maps, one a light
IRRADIANCE_UNIT = 5      # scene: the irradiance table (sky and probes' spherical harmonics)
VIRTUAL_SHADOW_UNIT = 14  # scene: the virtual lights' shadow maps, one depth atlas (the mip pass's unit)
# Post-processing (the present stage).  The bloom levels and the HDR image are read on units
# of their own, past the 16 the scene's samplers use (a sampler may name any unit below
# GL_MAX_COMBINED_TEXTURE_IMAGE_UNITS, at least 80 in OpenGL 4.1): the chain's binds displace
# no other pass's texture (the sky on 1, bound again by the next frame's scene pass), and the
# HDR image stays bound from frame to frame.  FXAA and exposure keep units the scene uses:
# FXAA's input on a unit of its own as well (a still frame then binds no texture at all)
# cost llvmpipe 15% more CPU a 640x360 frame (interleaved A/B, 15.5 -> 17.9 ms; FXAA on 15
# the same; the cause, inside llvmpipe, not found), and its bind is one call a frame.
BLOOM_UNIT = 16          # bloom steps after the first, present: a level of the chain (engine/render/bloom.py)
PRESENT_UNIT = 17        # present, bloom's first step, exposure's luminance step: the HDR image
LUT_UNIT = 24            # present (LUT builds): the grade's colour table, a 3D texture (ColorGrading.lut)
# The spots' shadow maps (a depth atlas, sampler2DShadow) on a unit past 16 too: the scene's
# fragment stage reads at most 16 samplers (GL 4.1's least GL_MAX_TEXTURE_IMAGE_UNITS), and
# with it a build holds 15, but 0-15 are each some pass's.
SPOT_SHADOW_UNIT = 18    # scene (SPOT_MAP builds): the spot lights' perspective shadow maps
# A batch's occlusion map past 16 as well: with it the fullest build reads 16 samplers.
OCCLUSION_UNIT = 19      # scene (OCCLUSION_MAP builds): the batch's occlusion map (Material.occlusion_map)
# The spot lights' cookies (engine/render/spot_cookies.py), a texture array: the 17th sampler of
# the fullest build, only where the context has one (SpotCookies.supported).
COOKIE_UNIT = 25         # scene (SPOT_COOKIES builds): the kept spot lights' cookie images
# The posed entities' joint matrices and morph weights (engine/render/pose_rows.py) and a
# morphed mesh's offsets: read by the vertex stage of the SKINNED and MORPHED scene and caster
# builds, so no fragment stage's 16 samplers count them.
POSE_ROWS_UNIT = 26  # scene, casters (SKINNED, MORPHED builds): the pose texture
MORPH_UNIT = 27      # scene, casters (MORPHED builds): the batch's mesh's morph offsets (GpuMesh.morphs)
# Each mover's own motion (engine/render/object_motion.py), read by the scene builds' vertex
# stage while the camera's motion blur streaks moving things.
OBJECT_MOTION_UNIT = 30  # scene (OBJECT_MOTION builds): the frame's movers' records
POSE_BEFORE_UNIT = 48    # scene (OBJECT_MOTION posed builds): last frame's pose texture (PoseRows.before)
# Particles (engine/render/particle_draw.py): an emitter's sprite, on a unit no scene build reads.
PARTICLE_UNIT = 28   # particles (SPRITE builds): the emitter's texture (ParticleEmitter.texture)
PARTICLE_DEPTH_UNIT = 29  # particles (SOFT builds): a copy of the view's depth (RenderTargets.depth_copy)
# Screen-space ambient occlusion (engine/render/screen_occlusion.py): the root view's builds
# that read it are not MASKED, so its sampler takes the node image's place in the count; an
# occluded reflection level's are (one more: ScreenOcclusion.levels_supported).
SCREEN_OCCLUSION_UNIT = 20  # scene (SCREEN_OCCLUSION builds): the camera's occlusion image, a texel a pixel
OCCLUSION_NODE_UNIT = 21   # occlusion passes of a reflection level: the level's node image
OCCLUSION_NORMAL_UNIT = 22  # occlusion passes: the depth and normals pass's normals and distances
OCCLUSION_IMAGE_UNIT = 23   # occlusion filter: the occlusion found (and each texel's distance)
# Screen-space reflections' composite (engine/render/screen_reflections.py): units no other pass
# reads, past 31: moderngl binds a texture it makes or builds mips of on its
# ``default_texture_unit`` (GL_MAX_TEXTURE_IMAGE_UNITS - 1: 31 on llvmpipe and NVIDIA, 15 on a
# 16-unit driver), behind the record's back, so no pass keeps a texture on 15 or 31 (the
# half-size rays on 31 read the colour copy whose mips were just built there).
REFLECTION_COLOR_UNIT = 32    # the main view's colour, copied, with its mip chain
REFLECTION_DEPTH_UNIT = 33    # the main view's depth (read through a sampler that compares nothing)
REFLECTION_WEIGHT_UNIT = 34   # the scene pass's reflection weights and roughness
REFLECTION_ADDED_UNIT = 35    # the sky's or probe's reflection the scene pass added
REFLECTION_NORMAL_UNIT = 36   # the shading normals
REFLECTION_SURFACE_UNIT = 37  # the main view's surface ids
REFLECTION_HITS_UNIT = 38     # the rays marched at half size (ScreenReflections.half_resolution)
REFLECTION_NODE_UNIT = 51     # a reflection level's composite: the level's node image
# Contact shadows of point lights (PointLight.contact_shadows; engine/render/screen_occlusion.py).
SCREEN_CONTACT_UNIT = 52      # scene (SCREEN_OCCLUSION builds with CONTACT_LAMPS): the lamps' shares
OCCLUSION_LAMPS_UNIT = 53     # occlusion filter: the lamps' shares found
# Light shafts (VolumetricFog; engine/render/volumetric_fog.py), past 31 as the reflections'.
VOLUMETRIC_DEPTH_UNIT = 54    # the march and its filter: the main view's depth (compared with nothing)
VOLUMETRIC_LIGHT_UNIT = 55    # the filter: the light the march found
VOLUMETRIC_NODE_UNIT = 56     # a reflection level's march and filter: the level's node image
# The directional shadow atlas again, read as it is (no comparison: the blockers' depths) by
# the soft suns' builds (DirectionalLight.angular_diameter): the 18th sampler of the fullest
# build, only where the context has one (ShadowMaps.soft_sun_supported); past 31 (moderngl's).
SUN_DEPTH_UNIT = 57           # scene (SOFT_SUN_SHADOWS builds): the shadow atlas, its depths as values
FLARE_UNIT = 58               # present (LENS_FLARE builds): the lens flare's ghosts (engine/render/lens_flare.py)
DIRT_UNIT = 59                # present (LENS_DIRT builds): the bloom's lens dirt (Bloom.dirt)
# A batch's lightmap: with an occlusion map of its own, the 17th sampler of the fullest build
# (Renderer.batch_for refuses the pair on a 16-unit context: macOS's).
LIGHTMAP_UNIT = 61            # scene (LIGHTMAP builds): the batch's lightmap (Material.lightmap)
LIGHTMAP_OCCLUSION_SAMPLERS = 17
SKY_VIEW_UNIT = 60            # sky, sky cube (ATMOSPHERE builds): the air's sky-view table (render/atmosphere.py)
SPACE_UNIT = 62               # sky, sky cube (SPACE builds): an atmosphere's space, a cube map (its given faces)
MOON_VIEW_UNIT = 63           # sky, sky cube (MOON_AIR builds): the sky-view table at the moon's elevation
# Screen-space refraction (engine/render/screen_refraction.py): the copy the SCREEN_REFRACTION
# scene builds march (colour and window depth, with mips), and the copy pass's two reads.
REFRACTION_COPY_UNIT = 64
REFRACTION_SOURCE_UNITS = (65, 66)  # the copy pass: the view's colour and depth images
# Caustics under waters (engine/render/caustics.py): their normal maps' array, the 19th sampler
# of the fullest build, only where the context has one (CausticBlock.supported).
CAUSTIC_UNIT = 67             # scene (CAUSTICS builds): the caustic waters' normal maps (CausticMaps)
# Ripples on waters (engine/render/ripples.py): their height fields' atlas.
RIPPLE_UNIT = 68              # composite (RIPPLES builds): the latest heights
RIPPLE_STEP_UNIT = 69         # the ripples' step: the heights it moves on
# The suns' see-through maps (engine/render/shadows.py: the light see-through things let
# through): the 20th sampler of the fullest build, only where the context has one
# (ShadowMaps.see_through_supported).
SEE_THROUGH_UNIT = 70         # scene (SEE_THROUGH_SHADOWS builds): ShadowMaps.see_through_atlas
SEE_THROUGH_SAMPLERS = 20
# The lamps' see-through maps (the same, for the point and spot lights' maps): the 21st.
LAMP_SEE_THROUGH_UNIT = 71    # scene (LAMP_SEE_THROUGH_SHADOWS builds): ShadowMaps.lamp_see_through_atlas
LAMP_SEE_THROUGH_SAMPLERS = 21
# The virtual lights' see-through maps (lights through mirrors and portals): the 22nd.
VIRTUAL_SEE_THROUGH_UNIT = 72   # scene (VIRTUAL_SEE_THROUGH_SHADOWS builds): ShadowMaps.virtual_see_through_atlas
VIRTUAL_SEE_THROUGH_SAMPLERS = 22
# Depth of field (engine/render/depth_of_field.py, before bloom): units past the reflections'.
DOF_SEEN_UNIT = 39       # the main view's seen pair (the way's length: shaders/include/way.glsl)
DOF_FOCUS_UNIT = 40      # the 1x1 focus distance
DOF_PREPARED_UNIT = 41   # each pixel's colour and signed blur radius
DOF_TILES_UNIT = 42      # each tile's largest blur radius of what lies nearer than the focus
DOF_BACK_UNIT = 43       # at half size: the gather's layer behind
DOF_FRONT_UNIT = 44      # at half size: the gather's layer in front
# Motion blur (engine/render/motion_blur.py, after depth of field): the main view's seen image
# on DOF_SEEN_UNIT, the picture on PRESENT_UNIT, and these.
MOTION_STREAKS_UNIT = 45     # each pixel's streak
MOTION_TILES_UNIT = 46       # each tile's longest streak
MOTION_NEIGHBOURS_UNIT = 47  # each tile's longest streak near it
# Temporal anti-aliasing (engine/render/temporal_aa.py, before depth of field): the frame on
# PRESENT_UNIT, the seen image on DOF_SEEN_UNIT, and the history.
TEMPORAL_HISTORY_UNIT = 49
TEMPORAL_REACTIVE_UNIT = 50   # temporal AA: the main view's particles' reactive mask
FXAA_UNIT = 0            # FXAA: the encoded frame (engine/render/present.py)
EXPOSURE_UNIT = 2        # present, exposure adaptation: the 1x1 adapted exposure (engine/render/post.py)
EXPOSURE_MEAN_UNIT = 0   # exposure adaptation: the 64x64 log-luminance image it averages
TEXT_UNIT = 0            # screen text (after present): the font atlas (engine/render/text.py)
PICTURE_UNIT = 1         # screen text: a picture panel's monitor picture (engine/render/text.py)
AIR_TRANSMITTANCE_UNIT = 0   # sky view (engine/render/sky_view.py): the air's transmittance table
AIR_SCATTERING_UNIT = 1      # ... and its multiple-scattering table

# --- uniform-block binding points ----------------------------------------------------------
CAMERA_BINDING = 0
LIGHTS_BINDING = 1
VIEWS_BINDING = 2        # the batched scene program's table of a level's views
SHADOWS_BINDING = 3      # scene: the lights' shadow matrices and atlas rectangles
IRRADIANCE_BINDING = 4   # scene: the probes' influence boxes for diffuse image lighting
VIRTUAL_LIGHTS_BINDING = 5  # scene: lights seen through mirrors and portals (shadow_rules.VirtualLight)
FALLBACK_BINDING = 6     # composite (fallback): each row's ids and weights (mirror_composite.vert's FallbackRows)
FOG_BINDING = 7          # scene (FOG builds), sky, composites: the active camera's fog (engine/render/fog.py)
CLOUDS_BINDING = 8       # sky (CLOUDS builds), scene (CLOUD_SHADOWS): the CloudLayer (engine/render/clouds.py)
CAUSTICS_BINDING = 9     # scene (CAUSTICS builds): the waters whose waves gather the sun (engine/render/caustics.py)
FOAM_BINDING = 10        # scene (FOAM builds): the waters with shore foam (engine/render/foam.py)
RIPPLES_BINDING = 11     # composite (RIPPLES builds): the rippling waters' tiles (engine/render/ripples.py)

# --- clip distances ------------------------------------------------------------------------
# The GLSL writes gl_ClipDistance[CLIP_VIEW_PLANE] and so on: the names below, defined for
# every program (``clip_glsl_defines``), never a number.
CLIP_VIEW_PLANE = 0      # a mirror or portal view's plane (camera.clip_plane)
CLIP_RECT = (1, 2, 3, 4)  # a rectangle: views drawn in one batched draw, composite quads
CLIP_RECT_SIDES = ("LEFT", "RIGHT", "BOTTOM", "TOP")  # CLIP_RECT's order: x >= x0, x <= x1, y >= y0, y <= y1
CLIP_SLICE = 5           # an instance's slice plane (things partly through a portal)
# A virtual light's shadow map draws the stretch of its way between two surfaces (light
# reflected more than once): the second surface's plane.  Shadow casters only, which never
# clip to a rectangle, so it shares the rectangle's first slot.
CLIP_LEG_PLANE = CLIP_RECT[0]
CLIP_DISTANCE_COUNT = 6
_GL_CLIP_DISTANCE0 = 0x3000

SCENE_CLIPS = frozenset((CLIP_VIEW_PLANE, CLIP_SLICE))
BATCHED_SCENE_CLIPS = SCENE_CLIPS | frozenset(CLIP_RECT)
RECT_CLIPS = frozenset(CLIP_RECT)
NO_CLIPS: frozenset[int] = frozenset()



_NONE: Mapping[str, int] = MappingProxyType({})


def clip_glsl_defines() -> dict[str, str]:
    """``CLIP_VIEW_PLANE``, ``CLIP_RECT_LEFT`` .. ``CLIP_RECT_TOP``, ``CLIP_SLICE``, ``CLIP_LEG_PLANE`` and
    ``CLIP_DISTANCE_COUNT`` for the GLSL, from the indices above."""
    rect = {f"CLIP_RECT_{side}": str(index) for side, index in zip(CLIP_RECT_SIDES, CLIP_RECT, strict=True)}
    return {"CLIP_VIEW_PLANE": str(CLIP_VIEW_PLANE), **rect, "CLIP_SLICE": str(CLIP_SLICE),
            "CLIP_LEG_PLANE": str(CLIP_LEG_PLANE),
            "CLIP_DISTANCE_COUNT": str(CLIP_DISTANCE_COUNT)}


# Blending "over": the composite's (reflection x rate + own x (1 - rate)) and the transparent
# slot's.  Alpha is a level's coverage (premultiplied: 0 where nothing is drawn, which the
# composite above fills with the sky), and over it too: a + dst x (1 - a), so the sky shows
# behind something see-through in a reflection by 1 - a, not in full.
BLEND_OVER = (moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA, moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)
# "Over" for a colour the shader already multiplied by its alpha (the scene's transparent slot:
# Material.blend "transparent" keeps part of it whole, which SRC_ALPHA would fade).
BLEND_PREMULTIPLIED = (moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA, moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)
# Adding light to what a level holds, its alpha (coverage) kept: the light shafts'.
BLEND_ADD = (moderngl.ONE, moderngl.ONE, moderngl.ZERO, moderngl.ONE)


@dataclass(frozen=True)
class PassState:
    """The fixed-function state of a pass (the scissor and viewport are given per apply)."""

    depth_func: str | None = None        # None: no depth test
    cull: bool = False
    front_face: str = "ccw"
    blend: tuple[int, ...] | None = None
    clips: frozenset[int] = NO_CLIPS

    def __post_init__(self) -> None:
        # The state as the cache compares it, less the winding (set per view within a pass):
        # one small number for each distinct (flags, depth function, blend, clips).
        flags = moderngl.NOTHING
        if self.depth_func is not None:
            flags |= moderngl.DEPTH_TEST
        if self.cull:
            flags |= moderngl.CULL_FACE
        if self.blend is not None:
            flags |= moderngl.BLEND
        key = (flags, self.depth_func, self.blend, self.clips)
        object.__setattr__(self, "_fixed", _FIXED_IDS.setdefault(key, len(_FIXED_IDS)))
        if len(_FIXED_STATES) < len(_FIXED_IDS):
            _FIXED_STATES.append(key)


_FIXED_IDS: dict[tuple, int] = {}   # (flags, depth_func, blend, clips) -> its number
_FIXED_STATES: list[tuple] = []     # by number
_UNKNOWN = -1
# (number known to be set or _UNKNOWN, number wanted) -> the setter calls between them:
# (Context attribute, value, whether it is a method to call rather than a property to set).
_TRANSITIONS: dict[tuple[int, int], tuple[tuple[str, object, bool], ...]] = {}


def _transition(known: int, wanted: int) -> tuple[tuple[str, object, bool], ...]:
    flags, depth_func, blend, clips = _FIXED_STATES[wanted]
    if known == _UNKNOWN:
        old_flags, old_depth, old_blend, old_clips = None, None, None, None
    else:
        old_flags, old_depth, old_blend, old_clips = _FIXED_STATES[known]
    actions: list[tuple[str, object, bool]] = []
    # A depth or blend function left from before is kept while its test is off (set again
    # only when a state that tests depth or blends wants another).
    if depth_func is not None and depth_func != old_depth:
        actions.append(("depth_func", depth_func, False))
    elif depth_func is None and old_depth is not None:
        depth_func = old_depth
    if blend is not None and blend != old_blend:
        actions.append(("blend_func", blend, False))
    elif blend is None and old_blend is not None:
        blend = old_blend
    if flags != old_flags:
        actions.append(("enable_only", flags, True))
    for index in range(CLIP_DISTANCE_COUNT):
        on = index in clips
        if old_clips is None or on != (index in old_clips):
            actions.append(("enable_direct" if on else "disable_direct", _GL_CLIP_DISTANCE0 + index, True))
    # What is then known to be set: the state, with the functions kept from before.
    after = (flags, depth_func, blend, clips)
    if after != _FIXED_STATES[wanted]:
        _FIXED_IDS.setdefault(after, len(_FIXED_IDS))
        if len(_FIXED_STATES) < len(_FIXED_IDS):
            _FIXED_STATES.append(after)
    return tuple(actions), _FIXED_IDS[after]


class _StateCache:
    """What ``apply_pass_state`` last set on one context."""

    __slots__ = ("fixed", "front_face", "rects_known", "blocks", "textures", "samplers", "epoch", "watched",
                 "recording")

    def __init__(self) -> None:
        self.fixed = _UNKNOWN        # the number of the (flags, functions, clips) set
        self.front_face: str | None = None
        self.rects_known = False     # False: set the viewport and scissor whatever moderngl says
        # uniform-block binding point -> the buffer bound, or (buffer, offset, size) for a range
        self.blocks: dict[int, moderngl.Buffer | tuple[moderngl.Buffer, int, int]] = {}
        self.textures: dict[tuple[int, type], Bindable] = {}  # (unit, texture class) -> the texture bound
        self.samplers: dict[int, moderngl.Sampler] = {}  # unit -> the sampler object bound there (bind_sampler)
        # ``watching``: the keys (a texture's (unit, class), a block's binding, a sampler's ("sampler",
        # unit)) whose binding changing moves ``epoch`` on (as ``invalidate`` does), and those being
        # recorded now (None: none)
        self.epoch = 0
        self.watched: set = set()
        self.recording: set | None = None


# False: every apply sets every piece of state, as before the cache (kept for the
# before/after measurement and as a fallback: ``bindings.CACHE_STATE = False``).
CACHE_STATE = True


def _cache(ctx: moderngl.Context) -> _StateCache:
    try:
        return ctx._speculum_pass_state
    except AttributeError:
        cache = ctx._speculum_pass_state = _StateCache()
        return cache


def invalidate(ctx: moderngl.Context) -> None:
    """Forget what the cache knows of ``ctx``'s state: the next ``apply_pass_state`` sets
    everything.  Call after GL state was set outside these functions (raw GL, the debug
    overlay, a test scrambling state)."""
    cache = getattr(ctx, "_speculum_pass_state", None)
    if cache is not None:
        cache.epoch += 1
        cache.fixed = _UNKNOWN
        cache.front_face = None
        cache.rects_known = False
        cache.blocks.clear()
        cache.textures.clear()


def assign_slots(program: moderngl.Program, units: Mapping[str, int] = _NONE,
                 blocks: Mapping[str, int] = _NONE) -> moderngl.Program:
    """Each sampler of ``units`` on its texture unit and each uniform block of ``blocks`` on
    its binding, of those ``program`` has (a build may not read every one: the linker drops
    what a variant never uses); returns the program."""
    for name, unit in units.items():
        if name in program:
            program[name].value = unit
    for name, binding in blocks.items():
        if name in program:
            program[name].binding = binding
    return program


def bind_texture(ctx: moderngl.Context, texture: Bindable, unit: int, keep_sampler: bool = False) -> None:
    """Bind ``texture`` (a moderngl Texture, TextureCube, TextureArray or Texture3D) on
    ``unit`` unless it is what that unit holds already (the object itself is remembered, as
    ``bind_uniform_block`` does for buffers).  A sampler object left on ``unit`` by
    ``bind_sampler`` is taken off first (the texture is then filtered by its own
    parameters), unless ``keep_sampler`` (the pass that bound it, binding the textures it
    filters).  Which unit is active afterwards is not defined: code that then acts on the
    active unit (raw GL) uses ``bind_texture_now``.  With ``CACHE_STATE`` off it binds every
    time."""
    try:
        cache = ctx._speculum_pass_state
    except AttributeError:
        cache = _cache(ctx)
    if cache.samplers and not keep_sampler and unit in cache.samplers:
        cache.samplers.pop(unit).clear(unit)  # the texture's own filter again
        _changed(cache, ("sampler", unit))
    textures = cache.textures
    key = (unit, texture.__class__)
    if cache.recording is not None:
        cache.recording.add(key)
    if textures.get(key) is not texture or not CACHE_STATE:
        texture.use(unit)
        textures[key] = texture
        if key in cache.watched:
            cache.epoch += 1


def texture_record(ctx: moderngl.Context) -> dict[tuple[int, type], Bindable]:
    """The record of what each unit holds, (unit, texture class) -> texture, as kept by
    ``bind_texture`` (read only; the same dict for the context's life, emptied by
    ``invalidate``): a pass that may leave a unit as it is when it holds a suitable texture
    looks there once rather than calling per draw."""
    return _cache(ctx).textures


def bind_textures(ctx: moderngl.Context, textures: tuple[tuple[Bindable, int], ...]) -> None:
    """``bind_texture`` for each (texture, unit) pair of ``textures`` (a pass's images: one
    look-up of the record for all of them)."""
    try:
        cache = ctx._speculum_pass_state
    except AttributeError:
        cache = _cache(ctx)
    bound, samplers, recording = cache.textures, cache.samplers, cache.recording
    for texture, unit in textures:
        if samplers and unit in samplers:
            samplers.pop(unit).clear(unit)  # the texture's own filter again
            _changed(cache, ("sampler", unit))
        key = (unit, texture.__class__)
        if recording is not None:
            recording.add(key)
        if bound.get(key) is not texture or not CACHE_STATE:
            texture.use(unit)
            bound[key] = texture
            if key in cache.watched:
                cache.epoch += 1


def bind_texture_now(ctx: moderngl.Context, texture: Bindable, unit: int) -> None:
    """Bind ``texture`` on ``unit`` and make ``unit`` the active one, whatever the record says
    (for raw GL that then sets parameters of, or copies into, the active unit's texture);
    the record is kept true."""
    cache = _cache(ctx)
    if unit in cache.samplers:
        cache.samplers.pop(unit).clear(unit)
        _changed(cache, ("sampler", unit))
    texture.use(unit)
    cache.textures[unit, texture.__class__] = texture
    _changed(cache, (unit, texture.__class__))


def bind_sampler(ctx: moderngl.Context, sampler: moderngl.Sampler | None, unit: int) -> None:
    """Bind the sampler object ``sampler`` on ``unit`` (None: none, the textures' own
    filtering) unless it is what is there.  It stays bound after the pass (the reflection
    levels' scene passes of a frame bind it once, not once and off again a level) until a
    pass binds with ``bind_sampler`` otherwise, or binds a texture on ``unit`` through
    ``bind_texture`` (which takes it off first, so no other pass is filtered by it).  Only
    this function binds sampler objects; ``forget_sampler`` before one is released."""
    cache = _cache(ctx)
    samplers = cache.samplers
    if cache.recording is not None:
        cache.recording.add(("sampler", unit))
    bound = samplers.get(unit)
    if bound is sampler and CACHE_STATE:
        return
    _changed(cache, ("sampler", unit))
    if sampler is None:
        if bound is not None:
            bound.clear(unit)
        samplers.pop(unit, None)
    else:
        sampler.use(unit)
        samplers[unit] = sampler


def forget_sampler(ctx: moderngl.Context, sampler: moderngl.Sampler) -> None:
    """``sampler`` is about to be released: deleting a sampler object unbinds it from every
    unit it is bound to (glDeleteSamplers), so the record of it goes without a GL call."""
    cache = _cache(ctx)
    samplers = cache.samplers
    for unit in [unit for unit, bound in samplers.items() if bound is sampler]:
        del samplers[unit]
        _changed(cache, ("sampler", unit))


def bind_uniform_block(ctx: moderngl.Context, buffer: moderngl.Buffer, binding: int) -> None:
    """Bind ``buffer`` to uniform-block ``binding`` unless it is the buffer bound there
    (binding points are the context's, shared by every program; the buffer object itself
    is remembered, so a released buffer whose GL name is reused is bound again).  With
    ``CACHE_STATE`` off it binds every time."""
    try:
        cache = ctx._speculum_pass_state
    except AttributeError:
        cache = _cache(ctx)
    blocks = cache.blocks
    if cache.recording is not None:
        cache.recording.add(binding)
    if blocks.get(binding) is not buffer or not CACHE_STATE:
        buffer.bind_to_uniform_block(binding)
        blocks[binding] = buffer
        if binding in cache.watched:
            cache.epoch += 1


def bind_uniform_range(ctx: moderngl.Context, buffer: moderngl.Buffer, binding: int, offset: int,
                       size: int) -> None:
    """Bind ``size`` bytes of ``buffer`` from ``offset`` to uniform-block ``binding`` unless that
    very range is bound there (a pass of one view binds the first view's range of the
    camera buffer, as the pass before it did: a binding names the buffer object, so it holds
    when the buffer's storage is orphaned and written again; a buffer made anew is another
    object and is bound).  The record then holds (buffer, offset, size), never the buffer
    alone, so ``bind_uniform_block`` binds its whole buffer again.  With ``CACHE_STATE`` off
    it binds every time."""
    cache = _cache(ctx)
    blocks = cache.blocks
    if cache.recording is not None:
        cache.recording.add(binding)
    bound = blocks.get(binding)
    if bound.__class__ is not tuple or bound[0] is not buffer or bound[1] != offset or bound[2] != size \
            or not CACHE_STATE:
        buffer.bind_to_uniform_block(binding, offset=offset, size=size)
        blocks[binding] = (buffer, offset, size)
        if binding in cache.watched:
            cache.epoch += 1


def _changed(cache: _StateCache, key: object) -> None:
    """A binding of ``key`` changed: ``epoch`` moves on if it is watched."""
    if key in cache.watched:
        cache.epoch += 1


def bindings_epoch(ctx: moderngl.Context) -> int:
    """A number that stays the same while no binding ``watching`` recorded changes (texture,
    uniform block or sampler object; ``invalidate`` moves it on too): a pass that bound a
    set of things, and finds the same number at its next run (with the same things to
    bind), can leave them as they are (``ScenePass``'s pass-wide bindings, a reflection
    level after another: the claims between bind other units)."""
    return _cache(ctx).epoch


@contextlib.contextmanager
def watching(ctx: moderngl.Context) -> Iterator[None]:
    """Inside: every binding asked for (``bind_texture``, ``bind_uniform_block``,
    ``bind_uniform_range``, ``bind_sampler``), bound now or already in place, is watched from
    then on (``bindings_epoch``)."""
    cache = _cache(ctx)
    cache.recording = recorded = set()
    try:
        yield
    finally:
        cache.recording = None
        cache.watched |= recorded


def set_front_face(ctx: moderngl.Context, front_face: str) -> None:
    """The winding, within a pass (a view's), set only if it differs."""
    cache = _cache(ctx)
    if cache.front_face != front_face or not CACHE_STATE:
        ctx.front_face = cache.front_face = front_face


def set_face_culling(ctx: moderngl.Context, on: bool) -> bool:
    """Face culling on or off within a pass (a double-sided material's draw turns it off
    and back), keeping the record ``apply_pass_state`` compares against; returns whether it
    was on."""
    cache = _cache(ctx)
    known = cache.fixed
    if known == _UNKNOWN or not CACHE_STATE:  # nothing known: set, and keep knowing nothing
        if on:
            ctx.enable(moderngl.CULL_FACE)
        else:
            ctx.disable(moderngl.CULL_FACE)
        cache.fixed = _UNKNOWN
        return not on
    flags, depth_func, blend, clips = _FIXED_STATES[known]
    was = bool(flags & moderngl.CULL_FACE)
    if was != on:
        key = (flags | moderngl.CULL_FACE if on else flags & ~moderngl.CULL_FACE, depth_func, blend, clips)
        cache.fixed = _FIXED_IDS.setdefault(key, len(_FIXED_IDS))
        if len(_FIXED_STATES) < len(_FIXED_IDS):
            _FIXED_STATES.append(key)
        if on:
            ctx.enable(moderngl.CULL_FACE)
        else:
            ctx.disable(moderngl.CULL_FACE)
    return was


def flip_front_face(ctx: moderngl.Context) -> str:
    """Turn the winding to the other one (for instances whose model matrix mirrors them:
    their front faces wind the other way on screen); returns the one to put back."""
    current = _cache(ctx).front_face or ctx.front_face
    set_front_face(ctx, "cw" if current == "ccw" else "ccw")
    return current


def set_scissor(ctx: moderngl.Context, scissor: tuple[int, int, int, int] | None) -> None:
    """The scissor, within a pass (a view's), set only if moderngl's record for the bound
    framebuffer does not already clip as ``scissor`` does (None: nothing): a pass that
    applied its state with its first view's scissor sets nothing for that view."""
    try:
        known = ctx._speculum_pass_state.rects_known
    except AttributeError:
        known = False
    if not known or not CACHE_STATE or not _scissor_is(ctx, ctx.mglo.fbo, scissor):
        ctx.scissor = scissor


def _scissor_is(ctx: moderngl.Context, bound, scissor: tuple[int, int, int, int] | None) -> bool:
    """Whether moderngl's scissor of the ``bound`` framebuffer already clips as ``scissor``
    does (None: nothing; a rectangle covering the whole framebuffer clips nothing either)."""
    if scissor is not None:
        return bound.scissor == scissor
    fbo = ctx.fbo
    return fbo is not None and fbo.mglo is bound and bound.scissor == (0, 0, *fbo.size)


def apply_pass_state(ctx: moderngl.Context, state: PassState, viewport: tuple[int, int, int, int],
                     scissor: tuple[int, int, int, int] | None = None) -> None:
    """Make ``state`` (and the viewport and scissor) the context's, setting only what differs
    from what is known to be set (everything after ``invalidate``)."""
    if not CACHE_STATE:
        _apply_all(ctx, state, viewport, scissor)
        return
    try:
        cache = ctx._speculum_pass_state
    except AttributeError:
        cache = _cache(ctx)
    known = cache.fixed
    if known != state._fixed:
        step = _TRANSITIONS.get((known, state._fixed))
        if step is None:
            step = _TRANSITIONS[known, state._fixed] = _transition(known, state._fixed)
        actions, cache.fixed = step
        for name, value, call in actions:
            if call:
                getattr(ctx, name)(value)
            else:
                setattr(ctx, name, value)
    if cache.front_face != state.front_face:
        ctx.front_face = cache.front_face = state.front_face
    if cache.rects_known:
        bound = ctx.mglo.fbo
        if bound.viewport != viewport:
            ctx.viewport = viewport
        if not _scissor_is(ctx, bound, scissor):
            ctx.scissor = scissor
    else:
        ctx.viewport = viewport
        ctx.scissor = scissor
        cache.rects_known = True


def _apply_all(ctx: moderngl.Context, state: PassState, viewport: tuple[int, int, int, int],
               scissor: tuple[int, int, int, int] | None = None) -> None:
    """Set every piece of ``state`` (and the viewport and scissor), whatever was set before."""
    flags = moderngl.NOTHING
    if state.depth_func is not None:
        flags |= moderngl.DEPTH_TEST
        ctx.depth_func = state.depth_func
    if state.cull:
        flags |= moderngl.CULL_FACE
    if state.blend is not None:
        flags |= moderngl.BLEND
        ctx.blend_func = state.blend
    ctx.enable_only(flags)
    ctx.front_face = state.front_face
    for index in range(CLIP_DISTANCE_COUNT):
        if index in state.clips:
            ctx.enable_direct(_GL_CLIP_DISTANCE0 + index)
        else:
            ctx.disable_direct(_GL_CLIP_DISTANCE0 + index)
    ctx.viewport = viewport
    ctx.scissor = scissor
