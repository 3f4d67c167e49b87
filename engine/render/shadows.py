"""Shadow maps: drawn once a frame at most, by the shadows stage, and read by every view.

A directional light's map is one tile of a depth atlas (a tile a light, up to
``MAX_DIRECTIONAL_LIGHTS``), drawn from an orthographic camera fitted to the whole level
(``engine/rules/shadow_rules.py``), so the main camera, each mirror and portal view and each
probe face find their shadows in the same map, and the same shadow shows directly, in a
mirror and through a portal.  A sun with cascades (``DirectionalLight.shadow_cascades``) has
rings about the camera besides, each a map in a tile no level map takes (``draw_ring``); the
lookup reads the smallest ring holding the point, whatever the view.  A monitor's picture has
rings about its own camera, at half the tile's side in the quarters of the tiles left free
(``draw_picture_ring``), read in place of the camera's while it is drawn (``swap_ring_rows``).
A point light's map
is a cube of distances (distance / range in a 32-bit float channel), drawn in one layered
pass where the path self-check trusts the layered cube capture
(``engine/render/path_checks.py``, the probes' check), else as six views (a spot's: only the
faces its cone meets); a spot no wider than ``light_rules.SPOT_MAP_MAX_ANGLE`` has instead one
perspective depth map fitted to its cone, a tile of the spot atlas (``draw_spot``), several
times sharper for a narrow cone at the same resolution.  At most ``MAX_POINT_SHADOWS`` point
lights cast shadows (two slots, each a cube sampler or a spot tile), the rest light without
and are counted in ``RenderStats.shadows_cut``.

See-through things (the transparent slot's batches, and glass among the opaque ones) are
not in the depth maps: a sun's level map has a see-through map beside it
(``see_through_atlas``, ``fit_see_through``), half its texels a side, holding the share of the
light they let through (1 - alpha each, multiplied) and the nearest one's depth, drawn with
the level map (``_draw_see_through``) and read by the scene pass's SEE_THROUGH_SHADOWS builds
(``shaders/include/shadows.glsl`` see_through_shadows).  A casting point or spot light has the
same beside its cube or spot map (``lamp_see_through_atlas``, ``fit_lamp_see_through``): six
face tiles (a spot: one), half the map's texels a side, the nearest one's distance over the
range in place of a depth, drawn with the map (``_draw_lamp_see_through``) and read by the
LAMP_SEE_THROUGH_SHADOWS builds (lamp_see_through_cube; a spot's in spot_map_light_shadow).
A light through mirrors and portals (a virtual light) has one beside its tile of the virtual
atlas (``virtual_see_through_atlas``, ``fit_virtual_see_through``), laid out as that atlas at
half its texels, its casters drawn stretch by stretch as the depth map's
(``_draw_virtual_see_through``), read by the VIRTUAL_SEE_THROUGH_SHADOWS builds in
``virtual_shadow`` (``shaders/include/virtual_light_ways.glsl``).

Nothing here decides when a map is drawn again: the shadows stage does
(``systems/shadow_system.py``, from the frame's change sets).  The Shadows uniform block
(``shaders/include/shadows.glsl``) holds each light's atlas matrix and filter, written when
a map is drawn or a light's shadows are turned off.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import replace

import moderngl
import numpy as np
from pyglm import glm

from components.limits import ALL_LAYERS
from components.rendering import ALBEDO_UV_BIT
from engine.core.cube_faces import CUBE_FACES
from engine.core.errors import GLLimitError, GLLimitWarning
from engine.render.bindings import (
    ALBEDO_UNIT,
    CAMERA_BINDING,
    CLIP_LEG_PLANE,
    LAMP_SEE_THROUGH_SAMPLERS,
    LAMP_SEE_THROUGH_UNIT,
    MORPH_UNIT,
    POINT_SHADOW_UNITS,
    POSE_ROWS_UNIT,
    SCENE_CLIPS,
    SCRATCH_UNIT,
    SEE_THROUGH_SAMPLERS,
    SEE_THROUGH_UNIT,
    SHADOW_ATLAS_UNIT,
    SHADOWS_BINDING,
    SPOT_SHADOW_UNIT,
    SUN_DEPTH_UNIT,
    VIRTUAL_LIGHTS_BINDING,
    VIRTUAL_SEE_THROUGH_SAMPLERS,
    VIRTUAL_SEE_THROUGH_UNIT,
    VIRTUAL_SHADOW_UNIT,
    PassState,
    apply_pass_state,
    bind_sampler,
    bind_texture,
    bind_uniform_block,
)
from engine.render.free_depth_images import give_depth_image, take_depth_image
from engine.render.gpu import Gpu
from engine.render.instances import InstanceBatch
from engine.render.pose_rows import skinning_defines
from engine.render.raw_gl import ARRAY_R32F, LayeredArrayTarget, LayeredCubeTarget
from engine.render.targets import release_framebuffer
from engine.render.views import (
    CAMERA_BLOCK_BYTES,
    MAX_DIRECTIONAL_LIGHTS,
    MAX_POINT_LIGHTS,
    MAX_POINT_SHADOWS,
    MAX_SHADOW_RINGS,
    View,
)
from engine.rules.light_rules import LightLimits
from engine.rules.shadow_rules import (
    MAX_APERTURES,
    MAX_VIRTUAL_LIGHTS,
    DirectionalFit,
    Leg,
    VirtualLight,
    boxes_in_reach,
)

SHADOW_FILTERS = ("grid", "single")
# The slots the light rule (engine/rules/light_rules.py) fills: the Lights block's and the cubes.
LIGHT_LIMITS = LightLimits(MAX_DIRECTIONAL_LIGHTS, MAX_POINT_LIGHTS, MAX_POINT_SHADOWS)
VIRTUAL_RESOLUTION = 1024   # texels a side of a virtual light's map (a tile of the virtual atlas)
# Texels of far depth round each virtual light's map in its atlas tile: the filter's taps from a
# point just inside the map (softness / 2 + 1 texels out: 5 at MAX_SHADOW_SOFTNESS 8) read its
# own tile's far depth, not the next light's map or texels no draw wrote.  A multiple of
# SEE_THROUGH_SCALE: the see-through tile keeps a whole gutter of its own.
VIRTUAL_GUTTER = 8
VIRTUAL_TILE = VIRTUAL_RESOLUTION + 2 * VIRTUAL_GUTTER   # texels a side of a virtual light's tile
# The VirtualLights block (shaders/include/virtual_light_ways.glsl): a count, then per light a
# matrix and thirteen vectors.
VIRTUAL_FIELDS = ("position", "color", "exit", "origin", "u", "v", "params", "spot", "cookie_u", "cookie_v",
                  "rect_u", "rect_v", "tile")
# ... then, for light reflected more than once, each light's further outlines (the earlier
# surfaces as the later ones carry them): a plane, a corner and two edges each.
VIRTUAL_MORE = MAX_APERTURES - 1
# ... then, per light and outline, the matrix that takes the line from a lit point to the image,
# past that outline, back to where that stretch of the light's way runs (the inverse of its
# leg's carry; virtual_water: a water's body on the way).
VIRTUAL_UNFOLD_AT = 16 + 64 * MAX_VIRTUAL_LIGHTS + 16 * MAX_VIRTUAL_LIGHTS * len(VIRTUAL_FIELDS) \
    + 16 * 4 * MAX_VIRTUAL_LIGHTS * VIRTUAL_MORE
VIRTUAL_BLOCK_BYTES = VIRTUAL_UNFOLD_AT + 64 * MAX_VIRTUAL_LIGHTS * MAX_APERTURES
# Then the shadow cascades (DirectionalLight.shadow_cascades): rings about the camera, each in
# an atlas tile no light's level map takes; per ring its map from the level's uv, its texel, its
# tile, its light's slot.
_POINTS_END = 64 * MAX_DIRECTIONAL_LIGHTS + 16 * MAX_DIRECTIONAL_LIGHTS + 4 * MAX_POINT_LIGHTS \
    + 16 * MAX_POINT_SHADOWS + 16
_RINGS_END = _POINTS_END + (16 + 16 + 16) * MAX_SHADOW_RINGS + 16
# Then the spot maps (a spot within light_rules.SPOT_MAP_MAX_ANGLE): per point-shadow slot a
# matrix (world -> the spot atlas's uv and depth) and its tile's uv corners.
# Then each cube's light's size (soft shadows: shadows.glsl soft_cube_shadow).
_SPOTS_END = _RINGS_END + (64 + 16) * MAX_POINT_SHADOWS
# Then each directional light's size (soft shadows: shadows.glsl soft_sun_shadow): its map's
# depth range in metres and 2 tan(half its angular diameter), 0 for a hard edge; then its level
# map's tile in the atlas (corner u, v and side), where the soft shadows' taps are kept.
_SIZES_END = _SPOTS_END + 16 * MAX_POINT_SHADOWS
_TILES_START = _SIZES_END + 16 * MAX_DIRECTIONAL_LIGHTS
# Then each point-shadow slot's see-through tiles in the lamps' see-through atlas (a row a
# slot, a tile a face): 1 / the atlas's size, a face's side (texels; 0: none), the gutter.
_LAMP_THROUGH_START = _TILES_START + 16 * MAX_DIRECTIONAL_LIGHTS
SHADOWS_BLOCK_BYTES = _LAMP_THROUGH_START + 16 * MAX_POINT_SHADOWS
# The scene programs' fullest build reads 16 samplers, 17 with the cookies: a soft sun's map
# read as it is takes one more (SUN_DEPTH_UNIT).
SOFT_SUN_SAMPLERS = 18
# The casters' slope-scaled depth offset (glPolygonOffset factor, units): with the normal
# offset in the lookup, no acne on the sample level's slanted and curved surfaces.
SLOPE_BIAS = (1.5, 2.0)
POINT_NEAR = 0.02   # metres: a point light's cube sees casters from here out
# Texels of far depth round each spot map in its atlas tile: the lookup's normal offset (at
# most 1.5 texels) and the filter's spread (softness / 2 + 1) from a point just inside the
# cone stay in its own tile (MAX_SHADOW_SOFTNESS 8: 1.5 + 5; the push was (1 + softness) x
# 1.5 texels before the taps followed the receiver's plane).
SPOT_GUTTER = 20
# The caster builds (shadow.vert/frag's defines): a depth map's; a point light's cube face
# (distance over range); its six faces in one layered pass; a middle stretch of a virtual
# light's way (a second clip plane).  Each has a cutout build too (ALPHA_CUTOFF).
_DEPTH: tuple[tuple[str, str], ...] = ()
_DISTANCE = (("DISTANCE", "1"),)
_LAYERED = (("DISTANCE", "1"), ("LAYERED", "1"))
_LEG = (("LEG", "1"),)
# A see-through caster into a sun's see-through map (drawn with the cutout build: its alpha);
# into a lamp's, its distance over the range in place of the depth.
_SEE_THROUGH = (("SEE_THROUGH", "1"),)
_LAMP_SEE_THROUGH = (("SEE_THROUGH", "1"), ("DISTANCE", "1"))
_LEG_SEE_THROUGH = (("SEE_THROUGH", "1"), ("LEG", "1"))   # ... a virtual light's middle stretch
# Depth only, both faces: a quad (a mirror, a wall of one face) casts whichever side the
# light reaches; the normal offset keeps a closed mesh's lit side off its own back.
_CASTERS = PassState(depth_func="<", cull=False, clips=SCENE_CLIPS)
# A virtual light's stretch between two surfaces: kept between both planes.
_LEG_CASTERS = PassState(depth_func="<", cull=False, clips=SCENE_CLIPS | frozenset((CLIP_LEG_PLANE,)))
# The see-through casters into a sun's see-through map: no depth test, both faces, the share
# let through multiplied into the texel's (its alpha, the depth, by MIN: _draw_see_through).
_SEE_THROUGH_CASTERS = PassState(cull=False, blend=(moderngl.DST_COLOR, moderngl.ZERO, moderngl.ONE, moderngl.ONE),
                                 clips=SCENE_CLIPS)
# A virtual light's see-through tile: the last stretch's share into green, its depth into
# alpha; the stretches before it into red (``_draw_virtual_see_through``).
_LAST_STRETCH_WRITES, _EARLIER_STRETCH_WRITES = (False, True, False, True), (True, False, False, False)
_LEG_SEE_THROUGH_CASTERS = replace(_SEE_THROUGH_CASTERS, clips=SCENE_CLIPS | frozenset((CLIP_LEG_PLANE,)))
# The see-through map's texels against the depth map's, a side (a soft dimming needs fewer).
SEE_THROUGH_SCALE = 2
# Texels round each lamp see-through tile, drawn by a face view widened to cover them: the
# bilinear lookup at a face's edge reads texels of its own face's view.
LAMP_SEE_THROUGH_GUTTER = 2


def _set_uniform(program: moderngl.Program, name: str, value: object) -> None:
    """A caster program's uniform: bytes are an array, written whole."""
    if isinstance(value, bytes):
        program[name].write(value)
    else:
        program[name].value = value


def _axes(matrix: glm.mat4) -> tuple[float, float, float, float]:
    """An axis-aligned affine map's x scale, x offset, y scale and y offset (an orthographic
    projection and the moves and scales after it)."""
    return float(matrix[0][0]), float(matrix[3][0]), float(matrix[1][1]), float(matrix[3][1])


def _over_length(edge) -> tuple[float, float, float]:
    """An outline's edge over its length squared (the shader's dot gives 0 to 1 across it)."""
    edge = np.asarray(edge, np.float64)
    return tuple(float(v) for v in edge / max(float(edge @ edge), 1e-12))


class ShadowMaps:
    """The shadow maps' GL objects: the directional atlas, the point lights' cubes, the
    Shadows block, and the caster programs."""

    def __init__(self, renderer: Gpu) -> None:
        self.renderer = renderer
        ctx = self.ctx = renderer.ctx
        self.block = np.zeros(SHADOWS_BLOCK_BYTES // 4, np.float32)
        self._slots = self.block[(64 + 16) * MAX_DIRECTIONAL_LIGHTS // 4:][:MAX_POINT_LIGHTS].view(np.int32)
        self._slots[:] = -1
        # Per cube: the point light it holds, or -1 (the block's point_light; the lookups are
        # made a cube at a time, before the lights' loop).
        self._cube_lights = self.block[_POINTS_END // 4 - 4:_POINTS_END // 4].view(np.int32)
        self._cube_lights[:] = -1
        # Per ring: the directional slot whose ring it is, or -1 (the block's ring_slot).
        self._ring_slots = self.block[_RINGS_END // 4 - 4:][:MAX_SHADOW_RINGS].view(np.int32)
        self._ring_slots[:] = -1
        # Per directional slot: its level map's uv from light space (_axes), what its rings map from.
        self._level_uv: dict[int, tuple[float, float, float, float]] = {}
        # Per directional slot that casts: its level map's square in the atlas (corner u, v and
        # side, in uv).  A point whose lookup falls outside it is outside the map's fit, where
        # no caster stands between it and the light: read by the light shafts' march, whose
        # points lie anywhere in the air (the scene pass's surfaces are all inside the fit).
        self.directional_tiles: dict[int, tuple[float, float, float]] = {}
        self.ubo = ctx.buffer(self.block.tobytes())
        # The caster programs by (build: _DEPTH, _DISTANCE, _LAYERED or _LEG; whether for
        # cutouts): _caster_program.
        self._casters: dict[tuple[tuple[tuple[str, str], ...], bool | str, bool, bool], moderngl.Program] = {}
        for build in (_DEPTH, _DISTANCE):
            self._caster_program(build, False)
        # Until a light casts: a 1x1 atlas at the far depth and 1x1 cubes at the range's end
        # (every lookup lit), so the scene programs always have something defined to read.
        self.atlas = self._make_atlas((1, 1))
        self.tile = 0
        self.atlases_made = 0   # (fit_atlas: a new atlas holds none of the old one's maps)
        # slot -> (the fit, resolution, the buffer holding its Camera block) (_bind_fit)
        # (a picture's ring's: under ("picture", ring): draw_picture_ring)
        self._fit_blocks: dict[object, tuple[DirectionalFit, int, moderngl.Buffer]] = {}
        self._block_rows: dict[int, tuple] = {}  # slot -> what its Shadows block rows were written from
        self._atlas_framebuffer = ctx.framebuffer(depth_attachment=self.atlas)
        self._atlas_framebuffer.clear(depth=1.0)
        self._empty_cube = ctx.texture_cube((1, 1), 1, np.ones(6, np.float32).tobytes(), dtype="f4")
        self.cubes: dict[int, moderngl.TextureCube] = {}        # slot -> the light's distance cube
        self._face_framebuffers: dict[int, list[moderngl.Framebuffer]] = {}
        self._face_depth: dict[int, moderngl.Texture] = {}
        self._layered: dict[int, LayeredCubeTarget | LayeredArrayTarget] = {}
        # Spot maps: slot -> whether it holds a spot's perspective map (draw_spot) rather than a
        # cube; the atlas holds a tile a slot, side by side, ``spot_tile`` texels a side (0: none).
        self._spot_maps = np.zeros(MAX_POINT_SHADOWS, bool)
        self._spot_rows = self.block[_RINGS_END // 4:].reshape(-1)
        self.spot_atlas: moderngl.Texture | None = None
        self._spot_framebuffer: moderngl.Framebuffer | None = None
        self.spot_tile = 0
        # How edges are filtered: "grid" (2 x 2 taps, 3 x 3 past a softness of 1, a lamp's
        # cube's too), each a bilinear percentage-closer comparison (a cube's gathered and
        # weighed by hand: shadows.glsl cube_bilinear_lit); "single" (one such tap: a
        # one-texel edge).  On a software rasteriser every tap is CPU time for every pixel a
        # light reaches (the benchmark scene at 640x360 on llvmpipe, the sun's map 2048 a side:
        # a still frame 1.43x the frame without shadows with the grid, 1.24x with one tap
        # (1.16-1.18x since the lookups are made before the lights' loops), the frame without
        # building no lookup at all; benchmarks/lighting.py), so there the default is
        # "single"; set "grid" for equal quality (maps are drawn again).
        #
        # What upload found: (the directional slots read, the last casting one's index + 1;
        # the point slots read, the last used one's index + 1; the rings read; the point
        # slots that hold a spot's map; whether a ring in use has a blend band).
        self._casting: tuple[int, int, int, tuple[int, ...], bool, bool, bool] = (0, 0, 0, (), False, False, False)
        # A sun with a size (DirectionalLight.angular_diameter) reads its map's depths through a
        # sampler of its own: only where the fragment stage has the units for it.
        self.soft_sun_supported = renderer.caps.max_texture_image_units >= SOFT_SUN_SAMPLERS
        self._soft_sun_warned = False
        self._depth_ranges = np.zeros(MAX_DIRECTIONAL_LIGHTS, np.float32)   # each slot's map's, metres
        self.program_defines: tuple[tuple[str, str], ...] = ()
        # The suns' see-through maps (``fit_see_through``): the light the see-through things let
        # through, a tile for each level map's, where the context has a unit for it.
        self.see_through_supported = renderer.caps.max_texture_image_units >= SEE_THROUGH_SAMPLERS
        self._no_units_said: set[str] = set()   # the lights whose see-through maps had no unit, said
        self.see_through_atlas: moderngl.Texture | None = None
        self._see_through_framebuffer: moderngl.Framebuffer | None = None
        # The lamps' (``fit_lamp_see_through``): a row of six face tiles a point-shadow slot.
        self.lamp_see_through_supported = renderer.caps.max_texture_image_units >= LAMP_SEE_THROUGH_SAMPLERS
        self.lamp_see_through_atlas: moderngl.Texture | None = None
        self._lamp_see_through_framebuffer: moderngl.Framebuffer | None = None
        self.lamp_see_through_face = 0   # a face tile's texels a side, gutter left out (0: no atlas)
        self._lamp_through = self.block[_LAMP_THROUGH_START // 4:][:4 * MAX_POINT_SHADOWS].reshape(-1, 4)
        # The lights' through mirrors and portals (``fit_virtual_see_through``): the virtual atlas's
        # layout at half its texels.
        self.virtual_see_through_supported = \
            renderer.caps.max_texture_image_units >= VIRTUAL_SEE_THROUGH_SAMPLERS
        self.virtual_see_through_atlas: moderngl.Texture | None = None
        self._virtual_see_through_framebuffer: moderngl.Framebuffer | None = None
        self.filter = "single" if renderer.caps.software else "grid"
        # Lights through mirrors and portals: a depth atlas of 2 x 2 tiles and their block.
        self.virtual_block = np.zeros(VIRTUAL_BLOCK_BYTES // 4, np.float32)
        self.virtual_shining = False  # set_virtual_count's: the scene pass reads it each program look-up
        self._virtual_count = 0       # the count in the block (set_virtual_count)
        self.virtual_ubo = ctx.buffer(self.virtual_block.tobytes())
        self.virtual_atlas: moderngl.Texture | None = None
        self._virtual_framebuffer: moderngl.Framebuffer | None = None
        self._virtual_empty = self._make_atlas((1, 1))
        empty = ctx.framebuffer(depth_attachment=self._virtual_empty)
        empty.clear(depth=1.0)
        release_framebuffer(empty)

    # --- the atlas --------------------------------------------------------------------------
    def _make_atlas(self, size: tuple[int, int]) -> moderngl.Texture:
        """A depth atlas of ``size`` read as ``sampler2DShadow``: a released engine's
        (``free_depth_images``) or a new one, its texels undefined until drawn."""
        atlas = take_depth_image(self.ctx, size)
        atlas.compare_func = "<="   # sampler2DShadow: each tap a bilinear percentage-closer lookup
        atlas.filter = (moderngl.LINEAR, moderngl.LINEAR)
        atlas.repeat_x = atlas.repeat_y = False
        return atlas

    def fit_atlas(self, tile: int) -> None:
        """Make the atlas hold ``MAX_DIRECTIONAL_LIGHTS`` tiles of ``tile`` texels (2 x 2),
        keeping it when it does; a new atlas leaves every map to be drawn again."""
        if tile == self.tile:
            return
        self._check_size(f"DirectionalLight.shadow_resolution {tile}: the suns' shadow atlas (2 x 2 of its maps)",
                         (2 * tile, 2 * tile))
        release_framebuffer(self._atlas_framebuffer)
        give_depth_image(self.ctx, self.atlas)
        self.renderer.note_scene_change()
        self.atlas = self._make_atlas((2 * tile, 2 * tile))
        self._atlas_framebuffer = self.ctx.framebuffer(depth_attachment=self.atlas)
        self.tile = tile
        self.atlases_made += 1

    def fit_see_through(self, casting: bool) -> bool:
        """Make the see-through atlas (``see_through_atlas``) while see-through things cast
        (``casting``: ``Gpu.see_through_casters``), the depth atlas's layout at
        1 / SEE_THROUGH_SCALE its texels a side, RGBA half floats: for each casting sun's level
        map, the share of its light the see-through things over a texel let through (red) and
        the nearest one's depth (alpha); drop it when none does.  True when it was made,
        remade or dropped (every sun's map is to be drawn again with it).  Where the context
        has no unit for it, see-through things cast nothing, said once in a GLLimitWarning."""
        if casting and not self.see_through_supported:
            self._say_no_units("the suns'", SEE_THROUGH_SAMPLERS)
            casting = False
        size = (max(self.atlas.size[0] // SEE_THROUGH_SCALE, 1), max(self.atlas.size[1] // SEE_THROUGH_SCALE, 1))
        atlas = self.see_through_atlas
        if casting and atlas is not None and atlas.size == size or not casting and atlas is None:
            return False
        self._drop_see_through()
        if casting:
            self.see_through_atlas, self._see_through_framebuffer = self._see_through_target(size)
        self._set_program_defines()
        return True

    def _say_no_units(self, lights: str, needed: int) -> None:
        """Say once for ``lights`` that see-through things dim none of their light: their
        see-through maps need ``needed`` fragment texture units and the context has fewer."""
        if lights in self._no_units_said:
            return
        self._no_units_said.add(lights)
        warnings.warn(GLLimitWarning(
            f"see-through things dim {lights} light through maps of their own that need {needed} texture units "
            f"in the fragment stage, and this OpenGL has {self.renderer.caps.max_texture_image_units} "
            "(GL_MAX_TEXTURE_IMAGE_UNITS): they cast no shadow in those lights"), stacklevel=4)

    def _release_target(self, atlas: moderngl.Texture | None, framebuffer: moderngl.Framebuffer | None) -> None:
        """Let a see-through atlas and its framebuffer go (either may be None)."""
        if framebuffer is not None:
            release_framebuffer(framebuffer)
        if atlas is not None:
            atlas.release()
            self.renderer.note_scene_change()

    def _check_size(self, what: str, size: tuple[int, int], cube: bool = False) -> None:
        """A GLLimitError naming ``what`` where a texture (``cube``: a cube map's face) of
        ``size`` texels is past this context's limit, before anything is made or let go."""
        caps = self.renderer.caps
        limit, name = (caps.max_cube_map_size, "GL_MAX_CUBE_MAP_TEXTURE_SIZE") if cube else \
            (caps.max_texture_size, "GL_MAX_TEXTURE_SIZE")
        if max(size) > limit:
            raise GLLimitError(f"{what} is {size[0]}x{size[1]} texels{' a face' if cube else ''}: this OpenGL "
                               f"({caps.renderer}) takes at most {limit} ({name}); make shadow_resolution smaller")

    def _see_through_target(self, size: tuple[int, int]) -> tuple[moderngl.Texture, moderngl.Framebuffer]:
        """A see-through atlas of ``size`` (RGBA half floats, filtered linearly, clamped) and
        its framebuffer, cleared to nothing in the way (a new texture's texels are undefined
        until written)."""
        atlas = self.ctx.texture(size, 4, dtype="f2")
        atlas.filter = (moderngl.LINEAR, moderngl.LINEAR)
        atlas.repeat_x = atlas.repeat_y = False
        framebuffer = self.ctx.framebuffer(color_attachments=[atlas])
        framebuffer.clear(1.0, 1.0, 1.0, 1.0)
        return atlas, framebuffer

    def fit_lamp_see_through(self, casting: bool, resolution: int) -> bool:
        """Make the lamps' see-through atlas (``lamp_see_through_atlas``) while see-through
        things cast and a point or spot light casts (``casting``), for maps of up to
        ``resolution`` texels a side: a row for each point-shadow slot of six face tiles (a
        spot uses the first), each ``resolution`` / SEE_THROUGH_SCALE texels a side and a
        gutter of LAMP_SEE_THROUGH_GUTTER round it, RGBA half floats (the share let through
        in red, the nearest one's distance over the range in alpha); drop it when none casts.
        True when it was made, remade or dropped (every lamp's map is to be drawn again with
        it).  Where the context has no unit for it, see-through things dim no lamp, said once
        in a GLLimitWarning."""
        if casting and not self.lamp_see_through_supported:
            self._say_no_units("the point and spot lights'", LAMP_SEE_THROUGH_SAMPLERS)
            casting = False
        face = max(resolution // SEE_THROUGH_SCALE, 1) if casting else 0
        if face == self.lamp_see_through_face:
            return False
        tile = face + 2 * LAMP_SEE_THROUGH_GUTTER
        if face:
            self._check_size(f"PointLight.shadow_resolution {resolution}: the lamps' see-through atlas",
                             (6 * tile, MAX_POINT_SHADOWS * tile))
        self._drop_lamp_see_through()
        if face:
            self.lamp_see_through_atlas, self._lamp_see_through_framebuffer = \
                self._see_through_target((6 * tile, MAX_POINT_SHADOWS * tile))
        self.lamp_see_through_face = face
        self._set_program_defines()
        return True

    def _drop_lamp_see_through(self) -> None:
        self._release_target(self.lamp_see_through_atlas, self._lamp_see_through_framebuffer)
        self.lamp_see_through_atlas = self._lamp_see_through_framebuffer = None
        self.lamp_see_through_face = 0
        self._lamp_through[:] = 0.0

    def _draw_lamp_see_through(self, slot: int, views: list[View], lit: tuple[bool, ...], half_tan: float,
                               light_range: float, body: int) -> None:
        """Point-shadow slot ``slot``'s see-through tiles: for each of ``views`` (a cube's six
        faces, or a spot's one; ``half_tan``: the tangent of its half-angle), a tile cleared
        to all the light let through, then, where ``lit``, each see-through caster multiplies
        in its share and keeps the nearest distance over ``light_range`` (MIN, as the suns'),
        drawn from the view widened over the tile's gutter.  ``body``: the light's own entity
        (its mesh dims none of its light).  Only the see-through batches whose boxes reach into
        the light's range are drawn; with none, or without an atlas, the slot reads none (its
        lookup returns before the texture)."""
        face = self.lamp_see_through_face
        position = np.array(tuple(views[0].eye), np.float64)
        reaching = [batch for batch in self.renderer.see_through_casters()
                    if batch.count and boxes_in_reach(*batch.box, position, light_range)[0]] if face else []
        if not reaching:
            self._lamp_through[slot] = 0.0
            return
        ctx = self.ctx
        gutter = LAMP_SEE_THROUGH_GUTTER
        tile = face + 2 * gutter
        widened = 2.0 * math.atan(half_tan * tile / face)
        framebuffer = self._lamp_see_through_framebuffer
        framebuffer.use()
        ctx.blend_equation = moderngl.FUNC_ADD, moderngl.MIN
        try:
            for k, view in enumerate(views):
                rect = (k * tile, slot * tile, tile, tile)
                apply_pass_state(ctx, _SEE_THROUGH_CASTERS, rect, rect)
                framebuffer.clear(1.0, 1.0, 1.0, 1.0, viewport=rect)
                if not lit[k]:
                    continue
                self.renderer.bind_view(View(
                    view=view.view, proj=glm.perspective(widened, 1.0, POINT_NEAR, max(light_range, POINT_NEAR * 2)),
                    eye=view.eye, size=(tile, tile), name=f"{view.name} see-through", kinds=0, layers=ALL_LAYERS))
                self._draw_see_through_casters(_LAMP_SEE_THROUGH, {"light_range": light_range}, body, reaching)
        finally:
            ctx.blend_equation = moderngl.FUNC_ADD
        width, height = self.lamp_see_through_atlas.size
        self._lamp_through[slot] = (1.0 / width, 1.0 / height, face, gutter)

    def _drop_see_through(self) -> None:
        self._release_target(self.see_through_atlas, self._see_through_framebuffer)
        self.see_through_atlas = self._see_through_framebuffer = None

    def fit_virtual_see_through(self, casting: bool) -> bool:
        """Make the virtual lights' see-through atlas (``virtual_see_through_atlas``) while
        see-through things and a virtual light's map exist (``casting``), the virtual atlas's
        2 x 2 tiles at 1 / SEE_THROUGH_SCALE its texels a side (the same uv), RGBA half floats as
        the suns'; drop it when not.  True when it was made or dropped (every virtual light's
        map is to be drawn again with it).  Where the context has no unit for it, see-through
        things dim no virtual light, said once in a GLLimitWarning."""
        if casting and not self.virtual_see_through_supported:
            self._say_no_units("the lights through mirrors and portals'", VIRTUAL_SEE_THROUGH_SAMPLERS)
            casting = False
        if casting == (self.virtual_see_through_atlas is not None):
            return False
        self._release_target(self.virtual_see_through_atlas, self._virtual_see_through_framebuffer)
        self.virtual_see_through_atlas = self._virtual_see_through_framebuffer = None
        if casting:
            side = 2 * VIRTUAL_TILE // SEE_THROUGH_SCALE
            self.virtual_see_through_atlas, self._virtual_see_through_framebuffer = \
                self._see_through_target((side, side))
        self._set_program_defines()
        return True

    def tile_origin(self, slot: int) -> tuple[int, int]:
        return (slot % 2) * self.tile, (slot // 2) * self.tile

    def draw_directional(self, slot: int, fit: DirectionalFit, resolution: int, softness: float,
                         region: tuple[int, int, int, int] | None = None) -> int:
        """Draw directional light ``slot``'s map (its tile of the atlas, ``resolution`` texels
        a side) from ``fit``, and write its row of the Shadows block.  With ``region`` (x, y,
        width, height in the tile's texels) only those texels are cleared and drawn again (the
        casters' draws scissored to them: the same depths a whole redraw writes there).
        Returns the texels drawn.  With a see-through atlas its tile is drawn too, over the
        same texels (``_draw_see_through``)."""
        texels = self._draw_square(self.tile_origin(slot), slot, fit, resolution, region)
        if self.see_through_atlas is not None:
            self._draw_see_through(slot, resolution, region)
        # World -> the tile's uv and depth in [0, 1]; the block's rows written again only when
        # what they are made of changed (a frame redrawing a region under moved casters keeps them).
        width = self.atlas.size[0]
        written = (fit, resolution, softness, width, self._filter)
        if self._block_rows.get(slot) != written:
            x, y = self.tile_origin(slot)
            scale = resolution / width
            to_tile = glm.translate(glm.vec3(x / width + 0.5 * scale, y / width + 0.5 * scale, 0.5)) \
                * glm.scale(glm.vec3(0.5 * scale, 0.5 * scale, 0.5))
            self.block[16 * slot:16 * slot + 16] = np.array((to_tile * fit.view_proj).to_list(), np.float32).ravel()
            self._level_uv[slot] = _axes(to_tile * fit.proj)
            self.directional_tiles[slot] = (x / width, y / width, scale)
            base = 16 * MAX_DIRECTIONAL_LIGHTS + 4 * slot
            self.block[base:base + 4] = (fit.texel, softness, 1.0 / width, self._taps(softness))
            self._depth_ranges[slot] = fit.depth[1] - fit.depth[0]
            self.block[_SIZES_END // 4 + 4 * slot] = self._depth_ranges[slot]
            self.block[_TILES_START // 4 + 4 * slot:_TILES_START // 4 + 4 * slot + 3] = self.directional_tiles[slot]
            self._block_rows[slot] = written
        if self.renderer.debug:
            self.renderer.checkpoint(f"shadow map of directional light {slot}")
        return texels

    def draw_ring(self, ring: int, tile: int, slot: int, fit: DirectionalFit, resolution: int, softness: float,
                  region: tuple[int, int, int, int] | None = None) -> int:
        """Draw ring ``ring`` (a cascade about the camera, ``DirectionalLight.shadow_cascades``)
        of directional light ``slot`` into atlas tile ``tile`` from ``fit``, as
        ``draw_directional`` draws a level map (the light's own, drawn first), and write its
        rows of the Shadows block (``ring_rows``)."""
        origin = self.tile_origin(tile)
        texels = self._draw_square(origin, MAX_DIRECTIONAL_LIGHTS + ring, fit, resolution, region)
        key = MAX_DIRECTIONAL_LIGHTS + ring
        written = (fit, resolution, softness, self.atlas.size[0], tile, slot, self._level_uv[slot])
        if self._block_rows.get(key) != written:
            self._write_ring_rows(ring, self.ring_rows(origin, slot, fit, resolution, softness))
            self._ring_slots[ring] = slot
            self._block_rows[key] = written
        if self.renderer.debug:
            self.renderer.checkpoint(f"shadow ring {ring} of directional light {slot}")
        return texels

    def ring_rows(self, origin: tuple[int, int], slot: int, fit: DirectionalFit, resolution: int,
                  softness: float) -> np.ndarray:
        """A ring's rows of the Shadows block, for its map drawn from ``fit`` at ``origin``
        (texels) in the atlas, ``resolution`` texels a side, of directional light ``slot``
        (its level map drawn): the map from the level map's uv to the ring's own [0, 1]
        square (the lookup tests a point is inside it before it reads the atlas), its texel
        and softness, where its square lies in the atlas and the filter's margin; ten floats."""
        width = self.atlas.size[0]
        level = self._level_uv[slot]
        # Both maps are the same light space through an orthographic projection (scale and
        # offset a light-space axis): the ring's square from the level map's uv, axis by axis.
        square = _axes(glm.translate(glm.vec3(0.5)) * glm.scale(glm.vec3(0.5)) * fit.proj)
        sx, sy = square[0] / level[0], square[2] / level[2]
        # A point nearer the square's edge than the filter reaches is left to a larger map.
        margin = (softness + 2.0) / resolution
        return np.array((sx, sy, square[1] - sx * level[1], square[3] - sy * level[3], fit.texel, softness,
                         origin[0] / width, origin[1] / width, resolution / width, margin), np.float32)

    def _ring_row_spans(self, ring: int) -> tuple[slice, slice, slice]:
        """Where ring ``ring``'s rows lie in the block: its map, its texel and softness (the
        blend band after them is ``set_ring_blend``'s), its square in the atlas."""
        base = _POINTS_END // 4 + 4 * ring
        return (slice(base, base + 4), slice(base + 4 * MAX_SHADOW_RINGS, base + 4 * MAX_SHADOW_RINGS + 2),
                slice(base + 8 * MAX_SHADOW_RINGS, base + 8 * MAX_SHADOW_RINGS + 4))

    def _write_ring_rows(self, ring: int, rows: np.ndarray) -> None:
        spans = self._ring_row_spans(ring)
        self.block[spans[0]], self.block[spans[1]], self.block[spans[2]] = rows[:4], rows[4:6], rows[6:]

    def draw_picture_ring(self, ring: int, origin: tuple[int, int], fit: DirectionalFit, resolution: int,
                          region: tuple[int, int, int, int] | None = None) -> int:
        """Draw a monitor's picture's ring ``ring`` (its camera's cascade, in place of the active
        camera's while the picture is drawn: ``swap_ring_rows``) at ``origin`` (texels: a square
        no level map or the active camera's rings take) from ``fit``; the texels drawn."""
        texels = self._draw_square(origin, ("picture", ring), fit, resolution, region)
        if self.renderer.debug:
            self.renderer.checkpoint(f"a picture's shadow ring {ring}")
        return texels

    def swap_ring_rows(self, rows: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
        """Put ``rows`` (ring -> ``ring_rows``) in the Shadows block in place of those rings'
        own and send it: what the scene programs read while a monitor's picture is drawn
        (its camera's rings, the same lights' and ring counts: the programs' builds stay).
        Returns the rows put aside, to be swapped back after the picture: the block then is
        what it was, so no scene change is noted."""
        aside = {}
        for ring, values in rows.items():
            spans = self._ring_row_spans(ring)
            aside[ring] = np.concatenate([self.block[span] for span in spans])
            self._write_ring_rows(ring, values)
        # (the rings' rows alone: from the first ring's map to the ring slots' row)
        self.ubo.write(self.block[_POINTS_END // 4:_RINGS_END // 4].tobytes(), offset=_POINTS_END)
        return aside

    def set_ring_blend(self, ring: int, blend: float) -> None:
        """Ring ``ring`` fades into the next larger map over the outer ``blend`` share of its
        square's half side (``DirectionalLight.shadow_cascade_blend``; 0: a hard switch)."""
        at = _POINTS_END // 4 + 4 * MAX_SHADOW_RINGS + 4 * ring + 2
        self.block[at] = 0.5 * blend   # the square spans 0 to 1: its half side is 0.5

    def clear_rings(self, used: int) -> None:
        """Rings ``used`` and up hold no map (their light has fewer, or none)."""
        for ring in range(used, MAX_SHADOW_RINGS):
            if self._ring_slots[ring] >= 0:
                self._ring_slots[ring] = -1
                self._block_rows.pop(MAX_DIRECTIONAL_LIGHTS + ring, None)
                kept = self._fit_blocks.pop(MAX_DIRECTIONAL_LIGHTS + ring, None)
                if kept is not None:
                    kept[2].release()

    def _draw_square(self, origin: tuple[int, int], camera: object, fit: DirectionalFit, resolution: int,
                     region: tuple[int, int, int, int] | None) -> int:
        """The casters' depths into the atlas's square at ``origin`` (texels), ``resolution``
        texels a side, from ``fit`` (its Camera block kept under ``camera``), all of it or only
        ``region``; the texels drawn (a sun has no body: ``_draw_casters``)."""
        x, y = origin
        square = (x, y, resolution, resolution)
        rect = square if region is None else (x + region[0], y + region[1], region[2], region[3])
        framebuffer = self._atlas_framebuffer
        framebuffer.use()
        apply_pass_state(self.ctx, _CASTERS, square, rect)
        framebuffer.clear(depth=1.0, viewport=rect)
        self._bind_fit(camera, fit, resolution)
        self._draw_casters(None, _DEPTH)
        return rect[2] * rect[3]

    def _draw_see_through(self, slot: int, resolution: int, region: tuple[int, int, int, int] | None) -> None:
        """Directional light ``slot``'s see-through tile (its level map's, ``resolution`` /
        SEE_THROUGH_SCALE texels a side; ``region``: only the texels under the depth map's
        region, grown to whole see-through texels) from the Camera block ``_draw_square`` bound:
        cleared to all the light let through, then each see-through caster multiplies in its
        share and keeps the nearest depth (the alpha channel blends by MIN: the blend equation
        is set for this pass and given back)."""
        ctx = self.ctx
        x, y = self.tile_origin(slot)
        scale = SEE_THROUGH_SCALE
        side = max(resolution // scale, 1)
        square = (x // scale, y // scale, side, side)
        if region is None:
            rect = square
        else:
            x0, y0 = region[0] // scale, region[1] // scale
            x1, y1 = -(-(region[0] + region[2]) // scale), -(-(region[1] + region[3]) // scale)
            rect = (square[0] + x0, square[1] + y0, min(x1, side) - x0, min(y1, side) - y0)
        framebuffer = self._see_through_framebuffer
        framebuffer.use()
        apply_pass_state(ctx, _SEE_THROUGH_CASTERS, square, rect)
        framebuffer.clear(1.0, 1.0, 1.0, 1.0, viewport=rect)
        ctx.blend_equation = moderngl.FUNC_ADD, moderngl.MIN
        try:
            self._draw_see_through_casters(_SEE_THROUGH, {}, 0, self.renderer.see_through_casters())
        finally:
            ctx.blend_equation = moderngl.FUNC_ADD

    def _draw_see_through_casters(self, build: tuple[tuple[str, str], ...], uniforms: dict[str, object],
                                  body: int, batches: list[InstanceBatch]) -> None:
        """See-through casters (``batches``, of ``Gpu.see_through_casters``) into the bound
        see-through map, from the Camera block bound, with the caster programs of ``build``
        given ``uniforms`` (the blend set by the caller); ``body``: the light's entity, whose
        mesh dims none of its light (as ``_draw_casters``)."""
        ctx = self.ctx
        renderer = self.renderer
        for batch in batches:
            if not batch.count:
                continue
            kind = "vertex alpha" if batch.mesh.has_alpha else True
            second_uv = bool(batch.second_uv_maps & ALBEDO_UV_BIT)
            program = self._caster_program(build, kind, batch.skinned, batch.morphed, second_uv)
            for name, value in {**uniforms, "light_body": body, "glass_only": not batch.transparent}.items():
                _set_uniform(program, name, value)
            bind_texture(ctx, batch.texture if batch.texture is not None else renderer.blank_color, ALBEDO_UNIT)
            if batch.skinned or batch.morphed:
                bind_texture(ctx, renderer.pose_rows.texture, POSE_ROWS_UNIT)
                program["pose_row"].value = batch.pose_row
            if batch.morphed:
                bind_texture(ctx, batch.mesh.morphs, MORPH_UNIT)
                program["morph_targets"].value = batch.mesh.morph_count
            batch.draw(program)
            renderer.stats.shadow_draw_calls += 1

    def _bind_fit(self, slot: object, fit: DirectionalFit, resolution: int) -> None:
        """Bind the Camera block of directional light ``slot``'s map (a ring's: past the
        lights' slots), drawn from ``fit``: a buffer of the slot's own, packed and written
        when the light's map is fitted again (a new ``fit``), so a frame that redraws only
        the texels under moved casters packs and uploads no camera."""
        kept = self._fit_blocks.get(slot)
        if kept is None or kept[0] is not fit or kept[1] != resolution:
            view = View(view=fit.view, proj=fit.proj, eye=glm.vec3(0.0), size=(resolution, resolution),
                        name=f"shadow {slot}", kinds=0, layers=ALL_LAYERS)
            buffer = kept[2] if kept is not None else self.ctx.buffer(reserve=CAMERA_BLOCK_BYTES)
            buffer.write(view.camera_block())
            kept = self._fit_blocks[slot] = (fit, resolution, buffer)
        bind_uniform_block(self.ctx, kept[2], CAMERA_BINDING)

    @property
    def filter(self) -> str:
        return self._filter

    @filter.setter
    def filter(self, value: str) -> None:
        if value not in SHADOW_FILTERS:
            raise ValueError(f"shadow filter must be one of {', '.join(map(repr, SHADOW_FILTERS))}, got {value!r}")
        self._filter = value
        self._set_program_defines()

    def _set_program_defines(self) -> None:
        """``program_defines``: the shadow lookups the scene programs compile
        (``shaders/include/shadows.glsl``): ``DIRECTIONAL_SHADOWS`` while a directional light
        casts (its value the directional slots looked up: the last casting one's index + 1,
        each slot's lookup made outside the lights' loop), ``POINT_SHADOWS`` while a point
        light does (its value the cubes looked up, likewise), ``SHADOW_RINGS`` while a sun has
        cascades (the ring entries read), ``SHADOW_RING_BLEND`` while a ring in use has a blend
        band (a second lookup in it), ``SPOT_MAP<slot>`` where a point slot holds a spot's
        map (its lookup instead of the cube's), ``SOFT_POINT_SHADOWS`` while a cube's light has a
        size (a sphere or a rectangle: percentage-closer soft shadows, not with the "single"
        filter), ``SEE_THROUGH_SHADOWS`` while see-through things cast (``fit_see_through``),
        ``LAMP_SEE_THROUGH_SHADOWS`` while they do in a point or spot light's (``fit_lamp_see_through``),
        ``VIRTUAL_SEE_THROUGH_SHADOWS`` while they do in a virtual light's (``fit_virtual_see_through``),
        ``SOFT_SUN_SHADOWS`` while a casting directional light has a size (its map read
        as it is too: ``soft_sun_shadow``, not with the "single" filter), ``SHADOW_SINGLE_TAP``
        with the "single" filter.
        The scene pass builds
        (and caches) a program per combination; a frame where nothing casts runs no lookup
        (llvmpipe runs every branch's code: a third of such a frame at 640x360 went to
        lookups that returned 1)."""
        directional, point, rings, spots, blend, soft, soft_sun = self._casting
        self.renderer.note_scene_change()
        self.program_defines = tuple((name, value) for name, value, on in (
            ("DIRECTIONAL_SHADOWS", str(directional), directional > 0), ("POINT_SHADOWS", str(point), point > 0),
            ("SHADOW_RINGS", str(rings), rings > 0 and directional > 0),
            ("SHADOW_RING_BLEND", "1", blend and rings > 0 and directional > 0),
            *((f"SPOT_MAP{slot}", "1", True) for slot in spots),
            ("SOFT_POINT_SHADOWS", "1", soft and point > 0),
            ("SOFT_SUN_SHADOWS", "1", soft_sun and directional > 0),
            ("SEE_THROUGH_SHADOWS", "1", self.see_through_atlas is not None and directional > 0),
            ("LAMP_SEE_THROUGH_SHADOWS", "1", self.lamp_see_through_atlas is not None and point > 0),
            ("VIRTUAL_SEE_THROUGH_SHADOWS", "1", self.virtual_see_through_atlas is not None),
            ("SHADOW_SINGLE_TAP", "1", self._filter == "single")) if on)

    def _taps(self, softness: float) -> float:
        """Taps a side of a light's grid (a sun's, a spot's map's, a lamp's cube's)."""
        if self._filter == "single":
            return 1.0
        return 3.0 if softness > 1.0 else 2.0

    def set_sun_size(self, slot: int, angular_diameter: float, name: str) -> None:
        """Directional light ``slot``'s size (``DirectionalLight.angular_diameter``, degrees;
        ``name``: the light, for the warning): the penumbra its shadows widen by, 2 tan(half
        of it) metres a metre from the caster (``soft_sun_shadow``).  Where the context has
        no unit for the map read as it is, the edge stays hard and a GLLimitWarning says so
        once."""
        if angular_diameter > 0.0 and not self.soft_sun_supported:
            if not self._soft_sun_warned:
                self._soft_sun_warned = True
                warnings.warn(GLLimitWarning(
                    f"{name}: a sun's soft shadows (angular_diameter) need {SOFT_SUN_SAMPLERS} texture units in the "
                    f"fragment stage and this OpenGL has {self.renderer.caps.max_texture_image_units} "
                    "(GL_MAX_TEXTURE_IMAGE_UNITS): its shadows keep a hard edge"), stacklevel=3)
            angular_diameter = 0.0
        at = _SIZES_END // 4 + 4 * slot
        self.block[at:at + 2] = (self._depth_ranges[slot], 2.0 * math.tan(math.radians(angular_diameter) / 2.0))

    def clear_directional(self, slot: int) -> None:
        """Directional light ``slot`` casts no shadow (off, or no light there)."""
        self.block[16 * MAX_DIRECTIONAL_LIGHTS + 4 * slot + 3] = 0.0
        self.block[_SIZES_END // 4 + 4 * slot + 1] = 0.0
        self._block_rows.pop(slot, None)
        self._level_uv.pop(slot, None)
        self.directional_tiles.pop(slot, None)
        kept = self._fit_blocks.pop(slot, None)
        if kept is not None:
            kept[2].release()

    # --- virtual lights (through mirrors and portals) -------------------------------------
    def draw_virtual(self, slot: int, light: VirtualLight, fit: DirectionalFit, softness: float = 1.0) -> None:
        """Draw virtual light ``slot``'s map (a tile of the virtual atlas) and write its row of
        the VirtualLights block, its edges filtered ``softness`` of the map's texels wide (its
        light's ``shadow_softness``).  The casters are drawn once for each stretch of the light's
        way (``VirtualLight.legs``) into the one map: as they are, in front of the last
        surface (the way out to what it lights), and, for each stretch before it, carried to
        where the image sees it and kept between the surfaces it runs between (the way in
        from the light: in front of the first surface; a stretch from one mirror to the next:
        in front of both, the second plane a clip distance of its own); the surfaces on the
        way are left out.  The tile is cleared to far depth whole, its gutter
        (``VIRTUAL_GUTTER``) round the map included; the lookup takes a point outside the
        tile as unshadowed (``virtual_shadow``), as a sun's outside its map."""
        if self.virtual_atlas is None:
            self.virtual_atlas = self._make_atlas((2 * VIRTUAL_TILE, 2 * VIRTUAL_TILE))
            self._virtual_framebuffer = self.ctx.framebuffer(depth_attachment=self.virtual_atlas)
        tile_x, tile_y = (slot % 2) * VIRTUAL_TILE, (slot // 2) * VIRTUAL_TILE
        x, y = tile_x + VIRTUAL_GUTTER, tile_y + VIRTUAL_GUTTER   # the map's corner
        rect = (x, y, VIRTUAL_RESOLUTION, VIRTUAL_RESOLUTION)
        framebuffer = self._virtual_framebuffer
        framebuffer.use()
        whole = (tile_x, tile_y, VIRTUAL_TILE, VIRTUAL_TILE)
        apply_pass_state(self.ctx, _CASTERS, whole, whole)
        framebuffer.clear(depth=1.0, viewport=whole)
        apply_pass_state(self.ctx, _CASTERS, rect, rect)
        size = (VIRTUAL_RESOLUTION, VIRTUAL_RESOLUTION)
        body = light.light if light.kind == "point" else 0   # a lamp's image leaves its bulb's image out too
        legs = light.legs or (Leg(glm.mat4(1.0), (glm.vec4(*light.exit_plane),), (light.exit_entity, light.surface)),
                              Leg(light.carry, (glm.vec4(light.entry_plane),), (light.surface, light.exit_entity)))
        views = [View(view=fit.view * leg.carry, proj=fit.proj, eye=glm.vec3(light.position), size=size,
                      name=f"virtual light {slot} (stretch {index})", clip_plane=glm.vec4(leg.planes[0]),
                      skip=leg.skip[0], hide=leg.skip[1], kinds=0, layers=ALL_LAYERS)
                 for index, leg in enumerate(legs)]
        for view, leg in zip(views, legs, strict=True):
            if len(leg.planes) == 1:
                self._draw_casters(view, _DEPTH, body=body)
                continue
            apply_pass_state(self.ctx, _LEG_CASTERS, rect, rect)
            self._draw_casters(view, _LEG, {"leg_plane": tuple(glm.vec4(leg.planes[1]))}, body)
            apply_pass_state(self.ctx, _CASTERS, rect, rect)
        if self.virtual_see_through_atlas is not None:
            self._draw_virtual_see_through(slot, views, legs, body)
        width = 2 * VIRTUAL_TILE
        scale = VIRTUAL_RESOLUTION / width
        to_tile = glm.translate(glm.vec3(x / width + 0.5 * scale, y / width + 0.5 * scale, 0.5)) \
            * glm.scale(glm.vec3(0.5 * scale, 0.5 * scale, 0.5))
        block = self.virtual_block
        base = 4 + 16 * slot
        block[base:base + 16] = np.array((to_tile * fit.view_proj).to_list(), np.float32).ravel()
        point = light.kind == "point"
        more = light.apertures[1:]
        rows = {
            "position": (*light.position, 1.0 if point else 0.0),
            "color": (*light.color, light.light_range),
            "exit": light.exit_plane,
            "origin": (*light.aperture[0], fit.texel),
            "u": (*_over_length(light.aperture[1]), light.apertures[0].water if light.apertures else 0.0),
            "v": (*_over_length(light.aperture[2]), 0.0),
            "params": (1.0 / width, softness, self._taps(softness), float(len(more))),
            "spot": light.cone,
            "cookie_u": light.cookie[0],
            "cookie_v": (*light.cookie[1][:3], light.radius),
            "rect_u": light.rectangle[0],
            "rect_v": light.rectangle[1],
            "tile": (tile_x / width, tile_y / width, VIRTUAL_TILE / width, 0.0),
        }
        for index, name in enumerate(VIRTUAL_FIELDS):
            at = 4 + 16 * MAX_VIRTUAL_LIGHTS + 4 * (index * MAX_VIRTUAL_LIGHTS + slot)
            block[at:at + 4] = rows[name]
        start = 4 + 16 * MAX_VIRTUAL_LIGHTS + 4 * MAX_VIRTUAL_LIGHTS * len(VIRTUAL_FIELDS)
        for index, aperture in enumerate(more):
            at = start + 16 * (slot * VIRTUAL_MORE + index)
            block[at:at + 16] = (*aperture.plane, *aperture.origin, 0.0, *_over_length(aperture.u), aperture.water,
                                 *_over_length(aperture.v), 0.0)
        for index, leg in enumerate(legs[1:]):
            at = VIRTUAL_UNFOLD_AT // 4 + 16 * (slot * MAX_APERTURES + index)
            block[at:at + 16] = np.array(glm.inverse(leg.carry).to_list(), np.float32).ravel()
        self.renderer.checkpoint(f"shadow map of virtual light {slot}")

    def _draw_virtual_see_through(self, slot: int, views: list[View], legs: list[Leg], body: int) -> None:
        """Virtual light ``slot``'s see-through tile (its depth tile's, at 1 / SEE_THROUGH_SCALE
        the texels): cleared to all the light let through, then the see-through casters drawn
        from each stretch's view of ``views`` as the depth map's casters were (the same clip
        planes: in front of a stretch's surfaces, carried to where the image sees them), each
        multiplying in its share: the stretches before the last surface into red alone (every
        point the light reaches lies past them), the last stretch's into green, keeping its
        nearest depth in alpha (MIN, as the suns'), so a pane the line meets on the way in and
        again past a lit point (a pane over a floor mirror) dims that point once
        (shadows.glsl virtual_see_through_at)."""
        ctx = self.ctx
        tile, gutter, side = (n // SEE_THROUGH_SCALE for n in (VIRTUAL_TILE, VIRTUAL_GUTTER, VIRTUAL_RESOLUTION))
        tile_x, tile_y = (slot % 2) * tile, (slot // 2) * tile
        rect = (tile_x + gutter, tile_y + gutter, side, side)
        framebuffer = self._virtual_see_through_framebuffer
        framebuffer.use()
        whole = (tile_x, tile_y, tile, tile)
        apply_pass_state(ctx, _SEE_THROUGH_CASTERS, whole, whole)
        framebuffer.clear(1.0, 1.0, 1.0, 1.0, viewport=whole)
        apply_pass_state(ctx, _SEE_THROUGH_CASTERS, rect, rect)
        batches = self.renderer.see_through_casters()
        ctx.blend_equation = moderngl.FUNC_ADD, moderngl.MIN
        try:
            for index, (view, leg) in enumerate(zip(views, legs, strict=True)):
                framebuffer.color_mask = _LAST_STRETCH_WRITES if index == 0 else _EARLIER_STRETCH_WRITES
                framebuffer.use()   # (moderngl applies a framebuffer's colour mask as it binds it)
                self.renderer.bind_view(replace(view, size=(side, side)))
                if len(leg.planes) == 1:
                    apply_pass_state(ctx, _SEE_THROUGH_CASTERS, rect, rect)
                    self._draw_see_through_casters(_SEE_THROUGH, {}, body, batches)
                else:
                    apply_pass_state(ctx, _LEG_SEE_THROUGH_CASTERS, rect, rect)
                    self._draw_see_through_casters(_LEG_SEE_THROUGH, {"leg_plane": tuple(glm.vec4(leg.planes[1]))},
                                                   body, batches)
        finally:
            framebuffer.color_mask = (True, True, True, True)
            framebuffer.use()
            ctx.blend_equation = moderngl.FUNC_ADD

    def set_virtual_color(self, slot: int, color: tuple[float, float, float], light_range: float) -> None:
        """Virtual light ``slot``'s colour row (what reaches its first surface changed, its map
        not: a CloudLayer's shadow drifting over a mirror the sun lights)."""
        at = 4 + 16 * MAX_VIRTUAL_LIGHTS + 4 * (VIRTUAL_FIELDS.index("color") * MAX_VIRTUAL_LIGHTS + slot)
        self.virtual_block[at:at + 4] = (*color, light_range)

    def set_virtual_caustic(self, slot: int, water_slot: int) -> None:
        """Virtual light ``slot``'s caustic water: the slot in the caustics' block of the
        water it is the sun's image in, whose waves gather what it reflects (-1: none; the v
        row's w holds it plus 1: virtual_lights.glsl)."""
        at = 4 + 16 * MAX_VIRTUAL_LIGHTS + 4 * (VIRTUAL_FIELDS.index("v") * MAX_VIRTUAL_LIGHTS + slot)
        self.virtual_block[at + 3] = water_slot + 1

    def set_virtual_count(self, count: int) -> None:
        """How many virtual lights shine (slots 0 to count - 1).  ``virtual_shining`` follows
        it: the scene pass builds its programs with the virtual lights' loop only while one
        shines (llvmpipe runs a loop's body for every pixel even when it has nothing to do)."""
        if self._virtual_count != count:
            self.renderer.note_scene_change()
            self.virtual_block[:4].view(np.int32)[0] = self._virtual_count = count
        self.virtual_shining = count > 0

    # --- point lights ---------------------------------------------------------------------
    def draw_point(self, slot: int, light_index: int, position: glm.vec3, light_range: float, resolution: int,
                   softness: float, layered: str | None, faces: tuple[bool, ...] = (True,) * 6,
                   size: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0), body: int = 0) -> str:
        """Draw point light ``light_index``'s distance cube into cube ``slot``: one layered
        pass (every face lit; ``layered``: into the cube, "cube", or into a 2D array copied
        into it, "array": ``gpu.layered_target``; None: never) or a view a face, the faces a spot's cone does not
        light (``faces`` False: ``light_rules.cube_faces_lit``) cleared to "nothing nearer
        than the range" and not drawn; ``size``: the light's and a rectangle's front
        (``light_rules.light_size``; above 0 its lookups are soft shadows:
        ``SOFT_POINT_SHADOWS``); ``body``: the light's entity (``_draw_casters``).  Returns
        the path taken."""
        cube = self._cube(slot, resolution)
        views = [View(view=glm.lookAt(position, position + glm.vec3(forward), glm.vec3(up)),
                      proj=glm.perspective(glm.radians(90.0), 1.0, POINT_NEAR, max(light_range, POINT_NEAR * 2)),
                      eye=glm.vec3(position), size=(resolution, resolution), name=f"point shadow {slot} face {face}",
                      kinds=0, layers=ALL_LAYERS)
                 for face, (forward, _, up) in enumerate(CUBE_FACES)]
        every = all(faces)
        path = "layered" if every and layered and self._draw_layered(slot, cube, views, light_range, layered, body) \
            else "six_pass"
        stats = self.renderer.stats
        if path == "six_pass":
            for face, view in enumerate(views):
                framebuffer = self._face_framebuffers[slot][face]
                framebuffer.use()
                rect = (0, 0, resolution, resolution)
                apply_pass_state(self.ctx, _CASTERS, rect)
                framebuffer.clear(1.0, 1.0, 1.0, 1.0, depth=1.0)
                if faces[face]:
                    self._draw_casters(view, _DISTANCE, {"light_range": light_range}, body)
                    stats.shadow_faces_drawn += 1
        else:
            stats.shadow_faces_drawn += 6
        self._draw_lamp_see_through(slot, views, faces, 1.0, light_range, body)
        self._slots[light_index] = slot
        self._cube_lights[slot] = light_index
        self._spot_maps[slot] = False
        base = (64 + 16) * MAX_DIRECTIONAL_LIGHTS // 4 + MAX_POINT_LIGHTS + 4 * slot
        # A texel's angle: 90 degrees over the face's texels; the grid's taps a side, as a
        # sun's (shadows.glsl point_cube_shadow).
        self.block[base:base + 4] = (np.pi / 2.0 / resolution, softness, light_range, self._taps(softness))
        self.block[_SPOTS_END // 4 + 4 * slot:_SPOTS_END // 4 + 4 * slot + 4] = size
        self.renderer.checkpoint(f"shadow cube of point light {light_index}")
        return path

    def fit_spot_atlas(self, tile: int) -> None:
        """Make the spot atlas hold ``MAX_POINT_SHADOWS`` maps of up to ``tile`` texels a side,
        side by side, each in a tile with a border of ``SPOT_GUTTER`` texels; keep it when it
        does; 0: no spot casts from a map (the atlas released).  A new atlas leaves every spot
        map to be drawn again."""
        if tile == self.spot_tile:
            return
        if tile:
            self._check_size(f"PointLight.shadow_resolution {tile}: the spot lights' shadow atlas",
                             (MAX_POINT_SHADOWS * (tile + 2 * SPOT_GUTTER), tile + 2 * SPOT_GUTTER))
        self.renderer.note_scene_change()
        if self._spot_framebuffer is not None:
            release_framebuffer(self._spot_framebuffer)
            give_depth_image(self.ctx, self.spot_atlas)
            self._spot_framebuffer = self.spot_atlas = None
        self.spot_tile = tile
        if tile:
            side = tile + 2 * SPOT_GUTTER
            self.spot_atlas = self._make_atlas((MAX_POINT_SHADOWS * side, side))
            self._spot_framebuffer = self.ctx.framebuffer(depth_attachment=self.spot_atlas)

    def draw_spot(self, slot: int, light_index: int, position: glm.vec3, axis: glm.vec3, half_width: float,
                  light_range: float, resolution: int, softness: float, body: int = 0) -> str:
        """Draw spot light ``light_index``'s shadow into tile ``slot`` of the spot atlas (made
        by ``fit_spot_atlas``, at least ``resolution`` a side): one perspective depth map from
        the light along ``axis``, ``half_width`` (the tangent of its half-angle:
        ``light_rules.spot_map_half_width``) each side, out to the range, read by the lookup
        in place of cube ``slot``.  The whole tile is cleared to the far depth first: a lookup
        near the map's edge, moved off the surface and spread by the filter, reads its border
        (lit), never texels no pass wrote or the other slot's map.  ``body``: the light's
        entity (``_draw_casters``).  Returns the path taken ("spot_map")."""
        side = self.spot_tile + 2 * SPOT_GUTTER
        tile = (slot * side, 0, side, side)
        x, y = slot * side + SPOT_GUTTER, SPOT_GUTTER
        rect = (x, y, resolution, resolution)
        framebuffer = self._spot_framebuffer
        framebuffer.use()
        apply_pass_state(self.ctx, _CASTERS, tile, tile)
        framebuffer.clear(depth=1.0, viewport=tile)
        apply_pass_state(self.ctx, _CASTERS, rect, rect)
        up = glm.vec3(0.0, 1.0, 0.0) if abs(axis.y) < 0.9 else glm.vec3(1.0, 0.0, 0.0)
        fov = 2.0 * float(np.arctan(half_width))
        view = View(view=glm.lookAt(position, position + axis, up),
                    proj=glm.perspective(fov, 1.0, POINT_NEAR, max(light_range, POINT_NEAR * 2)),
                    eye=glm.vec3(position), size=(resolution, resolution), name=f"spot shadow {slot}",
                    kinds=0, layers=ALL_LAYERS)
        self._draw_casters(view, _DEPTH, body=body)
        self._draw_lamp_see_through(slot, [view], (True,), half_width, light_range, body)
        width, height = self.spot_atlas.size
        sx, sy = resolution / width, resolution / height
        to_tile = glm.translate(glm.vec3(x / width + 0.5 * sx, y / height + 0.5 * sy, 0.5)) \
            * glm.scale(glm.vec3(0.5 * sx, 0.5 * sy, 0.5))
        rows = self._spot_rows
        rows[16 * slot:16 * slot + 16] = np.array((to_tile * view.view_proj).to_list(), np.float32).ravel()
        box = 16 * MAX_POINT_SHADOWS + 4 * slot
        rows[box:box + 4] = (x / width, y / height, x / width + sx, y / height + sy)
        self._slots[light_index] = slot
        self._cube_lights[slot] = light_index
        self._spot_maps[slot] = True
        base = (64 + 16) * MAX_DIRECTIONAL_LIGHTS // 4 + MAX_POINT_LIGHTS + 4 * slot
        # A texel's width over its distance on the map's axis, the filter's taps a side.
        self.block[base:base + 4] = (2.0 * half_width / resolution, softness, light_range, self._taps(softness))
        self.block[_SPOTS_END // 4 + 4 * slot] = 0.0   # (a spot's map filters as a directional one's)
        self.renderer.checkpoint(f"spot shadow map of point light {light_index}")
        return "spot_map"

    def keep_point(self, slot: int, light_index: int) -> None:
        """Point light ``light_index`` reads cube ``slot`` as drawn before."""
        if self._slots[light_index] != slot or self._cube_lights[slot] != light_index:
            self.renderer.note_scene_change()
        self._slots[light_index] = slot
        self._cube_lights[slot] = light_index

    def clear_points(self) -> None:
        """No point light casts (each drawn again sets its own slot)."""
        if (self._slots >= 0).any() or (self._cube_lights >= 0).any():
            self.renderer.note_scene_change()
        self._slots[:] = -1
        self._cube_lights[:] = -1

    def forget_point(self, light_index: int) -> None:
        self.renderer.note_scene_change()
        slot = self._slots[light_index]
        if slot >= 0 and self._cube_lights[slot] == light_index:
            self._cube_lights[slot] = -1
        self._slots[light_index] = -1

    def _cube(self, slot: int, resolution: int) -> moderngl.TextureCube:
        cube = self.cubes.get(slot)
        if cube is not None and cube.size[0] == resolution:
            return cube
        self._check_size(f"PointLight.shadow_resolution {resolution}: a point light's shadow cube map",
                         (resolution, resolution), cube=True)
        self._drop_cube(slot)
        ctx = self.ctx
        cube = self.cubes[slot] = ctx.texture_cube((resolution, resolution), 1, dtype="f4")
        cube.filter = (moderngl.NEAREST, moderngl.NEAREST)
        depth = self._face_depth[slot] = ctx.depth_texture((resolution, resolution))
        placeholder = ctx.texture((resolution, resolution), 1, dtype="f4")
        try:
            framebuffers = self._face_framebuffers[slot] = []
            for face in range(6):
                framebuffer = ctx.framebuffer([placeholder], depth)
                framebuffers.append(framebuffer)
                self.renderer.raw_gl.attach_cube_face(framebuffer, cube, face)
        finally:
            placeholder.release()
        return cube

    def _draw_layered(self, slot: int, cube: moderngl.TextureCube, views: list[View], light_range: float,
                      into: str, body: int) -> bool:
        """The six faces in one pass through ``shadow_layered.geom``, into the cube ("cube")
        or into a six-layer array whose layers are then copied into its faces ("array");
        False where the layered target cannot be made (the caller draws six views)."""
        target = self._layered.get(slot)
        array = into == "array"
        if target is None or target.cube is not cube or isinstance(target, LayeredArrayTarget) != array:
            if target is not None:
                target.release()
                del self._layered[slot]
            try:
                target = LayeredArrayTarget(self.ctx, cube, ARRAY_R32F) if array else LayeredCubeTarget(self.ctx, cube)
            except RuntimeError:
                return False
            self._layered[slot] = target
        faces = b"".join(v.view_proj.to_bytes() for v in views)
        size = (0, 0, target.size, target.size)
        apply_pass_state(self.ctx, _CASTERS, size)
        target.bind()
        try:
            target.clear((1.0, 1.0, 1.0, 1.0))  # distance / range: nothing nearer than the range
            self._draw_casters(views[0], _LAYERED, {"light_range": light_range, "face_view_proj": faces}, body)
        finally:
            target.unbind()
        if array:
            target.copy_to_cube(SCRATCH_UNIT)  # (a unit no pass reads: the sky goes back there)
            bind_texture(self.ctx, self.renderer.sky, SCRATCH_UNIT)
            self.renderer.checkpoint("point shadow's copy into its cube")
        return True

    # --- drawing --------------------------------------------------------------------------
    def _caster_program(self, build: tuple[tuple[str, str], ...], cutout: bool | str,
                        skinned: str = "", morphed: bool = False, second_uv: bool = False) -> moderngl.Program:
        """The caster program of ``build`` (its defines), for cutouts (``cutout``: the
        ``ALPHA_CUTOFF`` build, its albedo map read for its holes; "vertex alpha": and its
        mesh's alpha a vertex, ``VERTEX_ALPHA``; ``second_uv``: the map read at the mesh's
        second UV set, ``Material.second_uv_maps``) or whole casters, bent by a Skin or not
        (``skinned``: its Skin.skinning, the ``SKINNED`` build, its joints read from the pose texture) or wearing a
        Morph or not (``morphed``: the ``MORPHED`` build, its offsets read from its mesh's)."""
        program = self._casters.get((build, cutout, skinned, morphed, second_uv))
        if program is None:
            defines = dict(build)
            if cutout:
                defines["ALPHA_CUTOFF"] = "1"
            if cutout and second_uv:
                defines["SECOND_UV_MAPS"] = str(ALBEDO_UV_BIT)
            if cutout == "vertex alpha":
                defines["VERTEX_ALPHA"] = "1"
            defines.update(skinning_defines(skinned))
            if morphed:
                defines["MORPHED"] = "1"
            geometry = "shadow_layered.geom" if "LAYERED" in defines else None
            program = self._casters[(build, cutout, skinned, morphed, second_uv)] = self.renderer.shaders.program(
                "shadow.vert", "shadow.frag", geometry, defines=defines)
            program["Camera"].binding = CAMERA_BINDING
            if "albedo_map" in program:
                program["albedo_map"].value = ALBEDO_UNIT
            if "pose_rows" in program:
                program["pose_rows"].value = POSE_ROWS_UNIT
            if "morph_offsets" in program:
                program["morph_offsets"].value = MORPH_UNIT
        return program

    def _draw_casters(self, view: View | None, build: tuple[tuple[str, str], ...],
                      uniforms: dict[str, object] | None = None, body: int = 0) -> None:
        """Every opaque batch into the bound map, from ``view`` (None: the Camera block bound
        already), with the caster programs of ``build`` given ``uniforms`` (bytes: an array,
        written whole); a cutout with the cutout build, its albedo map bound and its cutoff set.

        ``body`` is the light's own entity (0: none), whose mesh casts none of this light's
        shadow (shadow.vert's ``light_body``): a light on the entity of the mesh that shows it
        (a lamp's glowing bulb, a panel's box) sits inside that mesh, and a closed caster round
        a light would leave everything outside it dark.  Other lights' maps keep it."""
        renderer = self.renderer
        ctx = self.ctx
        renderer.note_scene_change()  # a map drawn again: what the views' shadows read
        if view is not None:
            renderer.bind_view(view)
        ctx.polygon_offset = SLOPE_BIAS
        whole = self._caster_program(build, False)
        # The other builds (a cutout's, a posed mesh's), made and given ``uniforms`` at their first batch.
        others: dict[tuple[bool | str, bool, bool, bool], moderngl.Program] = {}
        uniforms = {**(uniforms or {}), "light_body": body}
        for name, value in uniforms.items():
            _set_uniform(whole, name, value)
        stats = renderer.stats
        try:
            for batch in renderer.opaque_batches():
                if not batch.count:
                    continue
                cutoff = batch.alpha_cutoff
                if cutoff is None and not batch.skinned and not batch.morphed:
                    batch.draw(whole)
                else:
                    kind = False if cutoff is None else "vertex alpha" if batch.mesh.has_alpha else True
                    second_uv = bool(cutoff is not None and batch.second_uv_maps & ALBEDO_UV_BIT)
                    posed = (batch.skinned, batch.morphed, second_uv)
                    program = others.get((kind, *posed))
                    if program is None:
                        program = others[(kind, *posed)] = self._caster_program(build, kind, *posed)
                        for name, value in uniforms.items():
                            _set_uniform(program, name, value)
                    if cutoff is not None:
                        bind_texture(ctx, batch.texture if batch.texture is not None else renderer.blank_color,
                                     ALBEDO_UNIT)
                        program["alpha_cutoff"].value = cutoff
                    if batch.skinned or batch.morphed:  # its joints and weights: its row of the pose texture
                        bind_texture(ctx, renderer.pose_rows.texture, POSE_ROWS_UNIT)
                        program["pose_row"].value = batch.pose_row
                    if batch.morphed:  # its mesh's offsets
                        bind_texture(ctx, batch.mesh.morphs, MORPH_UNIT)
                        program["morph_targets"].value = batch.mesh.morph_count
                    batch.draw(program)
                stats.shadow_draw_calls += 1
        finally:
            ctx.polygon_offset = (0.0, 0.0)

    def upload(self) -> None:
        self.renderer.note_scene_change()
        self.ubo.write(self.block.tobytes())
        base = 16 * MAX_DIRECTIONAL_LIGHTS
        taps = np.flatnonzero(self.block[base + 3:base + 4 * MAX_DIRECTIONAL_LIGHTS:4])  # the casting slots
        cubes = np.flatnonzero(self._cube_lights >= 0)
        rings = np.flatnonzero(self._ring_slots >= 0)
        bands = self.block[_POINTS_END // 4 + 4 * MAX_SHADOW_RINGS + 2::4][:MAX_SHADOW_RINGS]
        sizes = self.block[_SPOTS_END // 4::4][:MAX_POINT_SHADOWS]
        suns = self.block[_SIZES_END // 4 + 1::4][:MAX_DIRECTIONAL_LIGHTS]
        casting = (int(taps[-1]) + 1 if taps.size else 0, int(cubes[-1]) + 1 if cubes.size else 0,
                   int(rings[-1]) + 1 if rings.size else 0, tuple(int(c) for c in cubes if self._spot_maps[c]),
                   bool((bands[rings] > 0.0).any()),
                   bool(any(sizes[c] > 0.0 and not self._spot_maps[c] for c in cubes)) and self._filter != "single",
                   bool((suns[taps] > 0.0).any()) and self._filter != "single")
        if casting != self._casting:
            self._casting = casting
            self._set_program_defines()
        self.virtual_ubo.write(self.virtual_block.tobytes())

    def bind(self) -> None:
        """Bind the maps and the Shadows block for a scene pass (every pass: the units are
        shared with passes that are not scene passes)."""
        bind_texture(self.ctx, self.atlas, SHADOW_ATLAS_UNIT)
        if self.see_through_atlas is not None:   # (the SEE_THROUGH_SHADOWS builds)
            bind_texture(self.ctx, self.see_through_atlas, SEE_THROUGH_UNIT)
        if self.lamp_see_through_atlas is not None:   # (the LAMP_SEE_THROUGH_SHADOWS builds)
            bind_texture(self.ctx, self.lamp_see_through_atlas, LAMP_SEE_THROUGH_UNIT)
        if self.virtual_see_through_atlas is not None:   # (the VIRTUAL_SEE_THROUGH_SHADOWS builds)
            bind_texture(self.ctx, self.virtual_see_through_atlas, VIRTUAL_SEE_THROUGH_UNIT)
        if self._casting[6]:   # (the soft suns' builds: the atlas again, its depths as values)
            bind_texture(self.ctx, self.atlas, SUN_DEPTH_UNIT)
            bind_sampler(self.ctx, self.renderer.depth_values(), SUN_DEPTH_UNIT)
        for slot, unit in enumerate(POINT_SHADOW_UNITS):
            bind_texture(self.ctx, self.cubes.get(slot, self._empty_cube), unit)
        bind_uniform_block(self.ctx, self.ubo, SHADOWS_BINDING)
        bind_texture(self.ctx, self.virtual_atlas or self._virtual_empty, VIRTUAL_SHADOW_UNIT)
        bind_texture(self.ctx, self.spot_atlas or self._virtual_empty, SPOT_SHADOW_UNIT)
        bind_uniform_block(self.ctx, self.virtual_ubo, VIRTUAL_LIGHTS_BINDING)

    def _drop_cube(self, slot: int) -> None:
        self.renderer.note_scene_change()
        for framebuffer in self._face_framebuffers.pop(slot, []):
            release_framebuffer(framebuffer)
        for table in (self.cubes, self._face_depth):
            obj = table.pop(slot, None)
            if obj is not None:
                obj.release()
        target = self._layered.pop(slot, None)
        if target is not None:
            target.release()

    def drop_unused_cubes(self, used: set[int]) -> None:
        for slot in [s for s in self.cubes if s not in used]:
            self._drop_cube(slot)

    def release(self) -> None:
        for slot in list(self.cubes):
            self._drop_cube(slot)
        self.fit_spot_atlas(0)
        release_framebuffer(self._atlas_framebuffer)
        if self._virtual_framebuffer is not None:
            release_framebuffer(self._virtual_framebuffer)
        self._drop_see_through()
        self._drop_lamp_see_through()
        self.fit_virtual_see_through(False)
        for _, _, buffer in self._fit_blocks.values():
            buffer.release()
        self._fit_blocks.clear()
        for atlas in (self.atlas, self.virtual_atlas, self._virtual_empty):   # (to the next engine on the context)
            if atlas is not None:
                give_depth_image(self.ctx, atlas)
        for obj in (self._empty_cube, self.ubo, self.virtual_ubo):
            obj.release()
