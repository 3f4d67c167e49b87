"""The scene pass: the one function that draws the world for a set of views into a target.

Every view goes through it: the main camera, each mirror and portal view of a reflection
level, and each face of a cube-map probe (``draw_layered``: all six in one pass, colour
only, so such a face roots no view tree); shadow maps are depth views drawn by a pass of
their own (``engine/render/shadows.py``).  For each view it draws

  1. the opaque batches, one instanced draw per (mesh, texture), smallest first, so big
     surfaces behind small things fail the depth test before they are shaded;
  2. the sky behind them (a full-screen triangle at the far plane, depth test <=:
     ``engine/render/sky_draw.py``), into the same framebuffer: it writes id 0 where it
     shows, the value the clear left there;
  3. the transparent slot: batches marked transparent (a material's alpha below 1),
     farthest first (by centre, and around a see-through mirror or portal by its plane:
     ``slot_order.back_to_front``), blended over what is there, testing depth but not writing it.  A
     view a view tree roots or draws (``SceneOptions.transparent`` False) draws here only
     its see-through mirrors and portals (water: the tree's claims must find their pixels,
     and their composites go over them) and what must blend before one of them
     (``split_slot``), and leaves the rest (glass) to the tree, which draws it with
     ``draw_transparent`` once the levels below are composited into the view's pixels:
     glass in front of a mirror blends over its reflection, at every level, as in an engine
     that draws its planar reflections before the view that shows them (drawn before the
     composite, glass held the mirror's own colour, and its ids, which the claims read, kept
     the mirror's reflection out).

Each batch draws with a build of ``scene.frag`` specialised to its material variants and
maps (``engine/render/scene_programs.py``: the builds, their per-draw uniforms, the draw
records the pass keeps on each batch), all built by ``prepare`` before a view needs them.

``SceneOptions`` says how: clear the target first (a root view) or keep the depth mask a
reflection level's claims wrote; draw only the pixels the target's node image gives each
view (the claimed-pixels mask); draw the sky or leave it to the composite; and whether a
level's views are drawn each with their own draws or all at once (``batched``: each
instance drawn once a view, as single-pass instanced stereo draws two eyes; views of one
winding and at most ``MAX_BATCHED_VIEWS`` a draw, more in groups:
``engine/render/batched_mirrors.py``).

Mirrors whose reflection paints over every pixel of them draw unlit (``SceneOptions.unlit``;
``engine/render/unlit_mirrors.py`` says which, view by view).
"""
from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import nullcontext
from typing import TYPE_CHECKING

import moderngl
import numpy as np
from pyglm import glm

from engine.core.errors import GLPassError, RefractionLimitWarning
from engine.render import bindings
from engine.render.batch_cull import CULL_MIN_BATCHES, CULL_MIN_DRAWS, batch_reach
from engine.render.batched_mirrors import VIEWS_BLOCK_BYTES, instanced_groups, views_block
from engine.render.bindings import (
    ALBEDO_UNIT,
    BATCHED_SCENE_CLIPS,
    BLEND_PREMULTIPLIED,
    LIGHTS_BINDING,
    NODE_UNIT,
    PROBE2_UNIT,
    PROBE_REST_UNIT,
    PROBE_UNIT,
    SCENE_CLIPS,
    SCREEN_CONTACT_UNIT,
    SCREEN_OCCLUSION_UNIT,
    SKY_UNIT,
    VIEWS_BINDING,
    PassState,
    apply_pass_state,
    bind_sampler,
    bind_texture,
    bind_uniform_block,
    bindings_epoch,
    flip_front_face,
    forget_sampler,
    set_face_culling,
    set_front_face,
    set_scissor,
    texture_record,
    watching,
)
from engine.render.caustics import NO_CAUSTIC_WATERS
from engine.render.gpu import Gpu
from engine.render.instances import blend_code
from engine.render.irradiance import IrradianceTable
from engine.render.particle_draw import ParticleDraw
from engine.render.raw_gl import LayeredArrayTarget, LayeredCubeTarget, inspect_bound_target
from engine.render.scene_options import ROOT_VIEW, SceneOptions
from engine.render.scene_programs import (
    NO_ANISOTROPY,
    NO_CHECKER,
    NO_CLEARCOAT,
    NO_DIFFUSE_TRANSMISSION,
    NO_IRIDESCENCE,
    NO_PROBE_LOOKUP,
    NO_SHEEN,
    NO_SUBSURFACE,
    PER_PASS_UNIFORMS,
    ScenePrograms,
    reflects_environment,
)
from engine.render.screen_refraction import (
    ALL_INSTANCES,
    MAX_REFRACTION_LAYERS,
    RefractionCopy,
    behind_the_glass,
    box_rects,
    meets,
    refraction_layers,
)
from engine.render.shadows import ShadowMaps
from engine.render.sky_draw import SkyDraw
from engine.render.slot_order import (
    SlotGeometry,
    back_to_front,
    see_through_surface,
    slot_groups,
    split_slot,
)
from engine.render.targets import RenderTargets
from engine.render.unlit_mirrors import UnlitBoxes, unlit_batches
from engine.render.views import View, union_rect

if TYPE_CHECKING:
    from engine.render.instances import InstanceBatch
    from engine.render.screen_reflections import ScreenReflectionPass
    from engine.render.volumetric_fog import VolumetricFogPass

_ALWAYS = nullcontext()  # a view drawn whatever its claim counted
_SLOT_SPLITS_KEPT = 64  # slot splits kept from a before draw to its after at most (a frame's levels)
_SCENE = PassState(depth_func="<", cull=True, clips=SCENE_CLIPS)
_BATCHED_SCENE = PassState(depth_func="<", cull=True, clips=BATCHED_SCENE_CLIPS)
# The sky's shaders write no gl_ClipDistance: a clip distance left on with no value written
# is undefined (llvmpipe reads 0 and keeps the pixel; a GPU may clip the sky away), so its
# pass turns none on.  It needs none: the sky lies on the far plane, behind any view's plane.
_SKY = PassState(depth_func="<=")
# A decal's cut mesh lies on the surface it was cut from, computed through another matrix:
# glPolygonOffset's (slope factor, units of depth resolution) pulls it towards the eye so the
# depth test ("<") keeps it over that surface at any angle and distance, and nothing else.
DECAL_DEPTH_OFFSET = (-1.0, -4.0)
_ALBEDO_KEY = (ALBEDO_UNIT, moderngl.Texture)  # the albedo unit's 2D binding in the texture record
_LAYERED_SCENE = PassState(depth_func="<", cull=True, clips=BATCHED_SCENE_CLIPS)
_LAYERED_SKY = PassState(depth_func="<=")
_BATCHED_TRANSPARENT = PassState(depth_func="<", cull=True, clips=BATCHED_SCENE_CLIPS, blend=BLEND_PREMULTIPLIED)
_LAYERED_TRANSPARENT = _BATCHED_TRANSPARENT
_TRANSPARENT = PassState(depth_func="<", cull=True, clips=SCENE_CLIPS, blend=BLEND_PREMULTIPLIED)


class ScenePass:
    """The one ``draw`` every view goes through (``draw_layered`` is the same scene for the
    six faces of a cube map at once), drawn with the scene programs (``programs``) and the
    sky's (``sky_draw``).  Every pass binds the shadow maps (``shadows``) and the probes'
    irradiance (``irradiance``) it shades with."""

    def __init__(self, renderer: Gpu, shadows: ShadowMaps, irradiance: IrradianceTable,
                 screen_reflections: ScreenReflectionPass | None = None,
                 volumetric_fog: VolumetricFogPass | None = None) -> None:
        self.renderer = renderer
        self.shadows = shadows
        self.irradiance = irradiance
        # The active camera's screen-space reflections: the main view draws into its
        # framebuffer (SceneOptions.reflections), its composite runs in finish_root.
        self.screen_reflections = screen_reflections
        # The active camera's light shafts: added in finish_root, after the reflections.
        self.volumetric_fog = volumetric_fog
        self.ctx = renderer.ctx
        self.sky_draw = SkyDraw(renderer)  # the sky's triangle behind every view
        self.particle_draw = ParticleDraw(renderer, shadows)  # every emitter's particles, in among a view's glass
        self.programs = ScenePrograms(renderer, shadows)  # the builds and their per-draw uniforms
        self.refraction_copy = RefractionCopy(renderer)  # what refracting surfaces march (refract)
        self._said_layers_cut = False  # (RefractionLimitWarning, said once)
        # A slot's split about the glass, from its "before" draw to its "after" (_part): by its
        # views' ids, the items' ids and which go first.
        self._slot_splits: dict[tuple[int, ...], tuple[tuple, list[bool]]] = {}
        self._layouts: dict = {}  # refraction_layers' answers, by view, glass and boxes
        # (invocations, layered, ambient probes, masked) -> a batch's draw-record keys (lit, unlit)
        self._kinds: dict[tuple, tuple[tuple, tuple]] = {}
        self._sky_size = 0
        self._views_ubo: moderngl.Buffer | None = None
        self._views_written: bytes | None = None  # what _views_table last wrote into it
        self._ambient_probes = False  # this pass draws the AMBIENT_PROBES builds (IrradianceTable.bind)
        self._reflection_sampler: moderngl.Sampler | None = None
        # Per-view passes leave out the draws a batch's boxes cannot reach (batch_cull), where
        # they have this many batches and views x batches; cull_batches False draws every batch
        # in every view (what the tests compare the frames with).
        self.cull_batches = True
        self.cull_min_batches = CULL_MIN_BATCHES
        self.cull_min_draws = CULL_MIN_DRAWS
        # The transparent slot's SlotGeometry (_slot_geometry).
        self._slot_kept: SlotGeometry | None = None
        self.unlit_boxes = UnlitBoxes()  # what each view keeps unlit of a pass's unlit mirrors
        # A run's pass-wide bindings (draw's run): (run, (capturing, reflection filter), bindings_epoch
        # after them), or None.
        self._pass_wide: tuple | None = None

    def prepare(self, batches: Iterable[InstanceBatch], reflections: bool, levels: bool = False) -> int:
        """Build the programs and vertex arrays ``batches`` will be drawn with
        (``ScenePrograms.prepare``; ``levels``: their masked builds too) and, with
        ``reflections``, the batched path's view table and the reflection sampler.  Returns
        how many programs were built (0 when all were there)."""
        built = self.programs.prepare(batches, reflections, self.irradiance.has_boxes(), levels or reflections)
        if reflections:
            self._views_buffer()
            self._reflection_filter()
        return built

    def _draw_batches(self, batches, views: int, masked: bool, layered: str = "",
                      skip: int = 0, before_draw: Callable[[], None] | None = None, hide: int = 0,
                      unlit: frozenset | set = frozenset(), screen: str = "",
                      rows: tuple[int, int] = ALL_INSTANCES) -> None:
        """One instanced draw per batch, each with the program of its variants: for one view
        (``views`` 0: the Camera block's), for ``views`` views of a level at once (their Views
        block: each instance drawn once a view, ``InstanceBatch.vao``) or, with ``layered``, for
        the ``views`` faces of a one-pass capture (the geometry shader's).  A program's
        uniforms are written only when their value changes (``ScenePrograms.written``, kept for the
        program's life): each write is a moderngl call of a few microseconds on a view's
        critical path (about 490 a frame at 16 mirrors when they were written again every pass).
        What a batch draws with in passes of one kind (its program, vertex array, uniforms,
        textures, and its uniform values where no probe's lookup can change them) is looked up
        once and kept on the batch (``InstanceBatch.draw_records``, ``ScenePrograms.record``) until a shader
        reload, a virtual light starting or ending, a kind of light starting or ending to cast
        (``ShadowMaps.program_defines``), fog coming or going (``FogBlock.defines``), or its
        variants change: a view's draws then
        cost a dictionary look-up and a comparison a batch, not a program key built and found.
        A batch whose one instance is the view's ``skip`` or ``hide`` entity (a mirror's own
        quad, a probe's own sphere) is not drawn at all: its vertices would all be clipped
        away (0: none; entities start at 1).  A batch in ``unlit`` (``unlit_batches``: its
        mirrors all ``shading_replaced``) draws with its ``UNLIT_SURFACE`` build.  ``screen``
        "occluded" draws the builds that read the screen's ambient occlusion, "depth_normals"
        the build that writes only depth and normals (``ScenePrograms.program``), "refracted"
        the screen-space refraction's, which draw the batches' ``rows`` (first, past)
        alone (a layer's run: ``screen_refraction.refraction_layers``)."""
        ctx = self.ctx
        renderer = self.renderer
        programs = self.programs
        seen = programs.reloads_seen
        if renderer.shaders.reloads != seen:
            programs.forget()
            seen = programs.reloads_seen
        # What else picks a batch's program: a virtual light shining, the shadow lookups compiled,
        # the fog, the kept lights' kinds (spheres, rectangles, cookies), what the light from
        # all round reads, the clouds' shadows, the caustics and the motion blur's own motion
        # (ScenePrograms.program).
        shadows = self.shadows
        # (And the pose and motion textures: a record binds them, made again as they grow.)
        stamp = (seen, shadows.virtual_shining, shadows.program_defines, renderer.fog.defines,
                 renderer.pose_rows.version, renderer.object_motion.version, renderer.contact_lamp_defines,
                 renderer.sphere_lights, renderer.rect_lights, renderer.spot_cookies.defines, renderer.ambient_defines,
                 renderer.clouds.shadow_defines, renderer.caustics.defines, renderer.ripples.caustic_defines,
                 renderer.object_motion.defines)
        build = views if layered else min(views, 1)  # (one instanced-views build serves any view count)
        per_view = views if views > 1 and not layered else 0
        kinds = self._kinds.get((build, layered, self._ambient_probes, masked, screen))
        if kinds is None:
            kinds = self._kinds[build, layered, self._ambient_probes, masked, screen] = (
                (build, layered, self._ambient_probes, False, masked, screen),
                (build, layered, self._ambient_probes, True, masked, screen))
        kind, unlit_kind = kinds
        sky_size = self._sky_size
        last_own = programs.last_own
        blank, colour_maps, recorded = renderer.blank_color, renderer.colour_maps, texture_record(ctx)
        draws = instances = 0
        skipped = (skip, hide)
        offset = False  # the decals' depth offset on (their cuts come in one run: set once for it)
        caustics = renderer.caustics   # (the batches reaching into its waters' bodies draw with caustics)
        caustic_waters = caustics.waters
        for batch in batches:
            count = batch.count
            if not count or (count == 1 and batch.entity_at[0] in skipped):
                continue
            variants = batch.variants
            drawn_as = unlit_kind if unlit and batch in unlit else kind  # a batch the composites paint over
            record = batch.draw_records.get(drawn_as)
            # (a batch's rows reach into a caustic water's body: extract keys them apart, by their
            # meshes' rest boxes; a posed batch, its own, by the box its pose holds)
            under = NO_CAUSTIC_WATERS
            if caustic_waters and (batch.caustic_waters or batch.skinned or batch.morphed):
                under = caustics.slots_of(batch.box, batch.caustic_waters, batch.skinned or batch.morphed)
            built = (variants, under is not NO_CAUSTIC_WATERS)
            if record is None or record[0] != stamp or record[1] != built:
                record = batch.draw_records[drawn_as] = programs.record(batch, drawn_as, stamp, *built)
            _, _, glo, vao, uniforms, values, textures, own, vertices, program, sky_at_probe = record
            if per_view:  # (its rows advancing every per_view instances)
                vao = batch.vao(program, per_view)
                count *= per_view
            for unit, texture in textures:
                if texture is blank and recorded.get(_ALBEDO_KEY) in colour_maps:
                    continue  # (no map: any colour map there serves, unread)
                bind_texture(ctx, texture, unit, True)  # the pass's albedo sampler stays (bind_sampler)
            if own is None:  # probes bound now: their lookups are read each draw
                own = self._probe_values(batch)
            elif variants is None or sky_at_probe:  # no probe, but the build declares its sampler: the sky there
                bind_texture(ctx, renderer.sky, PROBE_UNIT)
            if values[0] != sky_size and uniforms[0] is not None:
                uniforms[0].value = values[0] = sky_size
            if values[1] != rows and uniforms[1] is not None:  # (SCREEN_REFRACTION builds')
                uniforms[1].value = values[1] = rows
            if values[2] != under and uniforms[2] is not None:  # (CAUSTICS builds': the waters it is under)
                uniforms[2].value = values[2] = under
            # The batch's own values: one tuple compared (by identity first), and a uniform at
            # a time only where it differs from what this program last drew with.
            last = last_own.get(glo)
            if last is not own and last != own:
                for i, value in enumerate(own, PER_PASS_UNIFORMS):
                    if values[i] != value and uniforms[i] is not None:
                        uniforms[i].value = values[i] = value
                last_own[glo] = own
            if before_draw is not None:
                before_draw()
            if batch.decal != offset:  # a decal's cut mesh, on the surface it was cut from: its depth offset
                ctx.polygon_offset = DECAL_DEPTH_OFFSET if batch.decal else (0.0, 0.0)  # (set once for a run)
                offset = batch.decal
            if batch.double_sided:  # both faces (Material.double_sided): culling off for its draw
                culled = set_face_culling(ctx, False)
                vao.render(moderngl.TRIANGLES, vertices=vertices, instances=count)
                set_face_culling(ctx, culled)
            elif batch.mirrored:
                # A negative determinant (a negative Transform.scale, or a mirrored parent):
                # its front faces wind the other way on screen, so the view's winding is
                # turned for its draw (its own batch: extract keys batches by it).
                restore = flip_front_face(ctx)
                vao.render(moderngl.TRIANGLES, vertices=vertices, instances=count)
                set_front_face(ctx, restore)
            else:
                vao.render(moderngl.TRIANGLES, vertices=vertices, instances=count)
            draws += 1
            instances += count
        if offset:
            ctx.polygon_offset = (0.0, 0.0)
        if draws:
            stats = renderer.stats
            stats.draw_calls += draws
            stats.instances += instances

    def _probe_values(self, batch: InstanceBatch) -> tuple:
        """Bind the probes ``batch`` samples; its own uniform values with their lookups."""
        cubes = self.renderer.probe_cubes
        probe_size, lookup = self._bind_probe(batch.probe, PROBE_UNIT, cubes) if batch.probe else (0, NO_PROBE_LOOKUP)
        probe2_size, lookup2 = 0, NO_PROBE_LOOKUP
        if batch.probe_blend:  # the second probe's unit (the sky where the blend is a probe and the sky)
            probe2_size, lookup2 = self._bind_probe(batch.second_probe, PROBE2_UNIT, cubes)
        rest_size, lookup_rest = 0, NO_PROBE_LOOKUP
        if batch.rest_probe:  # the probe taking what the weights leave (a curved object's own)
            rest_size, lookup_rest = self._bind_probe(batch.rest_probe, PROBE_REST_UNIT, cubes)
        return (batch.texture is not None, blend_code(batch), probe_size, *lookup, probe2_size, *lookup2, rest_size,
                *lookup_rest, *(batch.checker or NO_CHECKER), batch.alpha_cutoff or 0.0, batch.occlusion_strength,
                batch.clearcoat or NO_CLEARCOAT, batch.dielectric_f0, batch.sheen or NO_SHEEN, batch.dispersion,
                batch.anisotropy or NO_ANISOTROPY, batch.iridescence or NO_IRIDESCENCE, batch.pose_row,
                batch.mesh.morph_count if batch.morphed else 0, batch.diffuse_transmission or NO_DIFFUSE_TRANSMISSION,
                batch.parallax_depth, batch.lightmap_intensity, batch.subsurface or NO_SUBSURFACE)

    def _bind_probe(self, probe: int, unit: int, cubes) -> tuple[int, tuple]:
        """Bind the cube map of ``probe`` to ``unit``: its face size and lookup uniforms.  The
        probe being captured is drawn into, so it cannot be sampled (a rendering feedback
        loop: undefined on a GPU); what samples it shows the sky in its capture.  A probe with
        no capture yet (one whose first capture comes later in this stage), that one, and no
        probe (0) bind the sky, as an object with no probe reflects, rather than whatever cube
        another pass left on the unit."""
        # Gpu.capturing: the probe whose cube map is being drawn into (ProbeCaptures sets it):
        # batches sampling it read the sky instead (no rendering feedback loop).
        cube = cubes.get(probe) if probe and probe != self.renderer.capturing else None
        if cube is not None:
            bind_texture(self.ctx, cube.texture, unit)
            return cube.face_size, cube.lookup()
        bind_texture(self.ctx, self.renderer.sky, unit)
        return self._sky_size, NO_PROBE_LOOKUP

    # --- the pass ------------------------------------------------------------------------------
    def draw(self, views: Sequence[View], targets: RenderTargets, options: SceneOptions = ROOT_VIEW,
             conditions: Sequence[moderngl.Query] | None = None, run: object | None = None) -> None:
        """Draw the scene for each of ``views`` into ``targets`` (all of one size).  With
        ``conditions`` (a samples query per view: its claim), view by view each view's draws
        are conditional on its query having counted pixels (GL conditional rendering: the
        GPU skips a view hidden this frame without the CPU reading the count); the batched
        path draws them all (the node image masks a hidden view's pixels anyway).

        ``run``: passes given the same object (a view tree's levels in one render: nothing
        the pass-wide bindings read changes between them) bind the lights, shadow maps,
        irradiance, sky and sampler once; a later one of them binds again only if one of
        those bindings changed since (``bindings.bindings_epoch``: the claims between two
        levels bind other units).  At portal depth 8 those checks, every one a binding
        already in place, cost about 3.5 us a level in a frame (measured, 32x18,
        LP_NUM_THREADS=0)."""
        if not views:
            return
        renderer = self.renderer
        self._sky_size = renderer.sky.size[0]
        viewport = (0, 0, *targets.size)
        if options.clear:
            # Every image: colour and alpha 0, ids 0, the node image 0 (a root is view 0 of
            # its tree), depth far.  The views then write colour and ids, never the node image.
            # Each image with the clear of its kind: glClear leaves integer images undefined.
            # (The main view drawn for screen reflections: its framebuffer, their images too.)
            framebuffer = self._reflecting_framebuffer(options) or targets.framebuffer
            framebuffer.use()
            apply_pass_state(self.ctx, _SCENE, viewport)
            renderer.raw_gl.clear_level(framebuffer)
            self.refraction_copy.drawn_over(targets)   # (a copy of them is of what the clear wiped)
        # Per-view draws start with the first view's scissor (set once, not reset then set).
        self._begin(views, targets, options, _BATCHED_SCENE if options.batched else _SCENE, run)
        if options.batched:
            for group in instanced_groups(views):
                self._draw_batched([views[i] for i in group], targets, options)
        else:
            self._draw_each(views, targets, viewport, options, conditions)
        if renderer.debug:  # the name is made only where it is checked
            renderer.checkpoint(f"scene ({views[0].name}{' and others' if len(views) > 1 else ''})")

    def draw_depth_normals(self, views: Sequence[View], framebuffer: moderngl.Framebuffer, size: tuple[int, int],
                           nodes: moderngl.Texture | None = None, step: int = 1) -> None:
        """The depth and geometric normals of ``views``' opaque batches into ``framebuffer``
        (an image of ``size`` for the normals and the distance, and a depth image), cleared
        first: the first pass of screen-space ambient occlusion
        (``engine/render/screen_occlusion.py``).  The same draws as each view's (its
        visibility, layers and skipped entities, a cutout's holes) with the ``DEPTH_NORMALS``
        build, which shades nothing; no sky, no transparent slot.  A reflection level's views
        (``nodes``: its node image) draw only their own pixels, masked by that image's every
        ``step``-th pixel (2: the images are half the level's size, and so are the views'
        scissors)."""
        ctx, renderer = self.ctx, self.renderer
        framebuffer.use()
        apply_pass_state(ctx, _SCENE, (0, 0, *size))
        renderer.raw_gl.clear_level(framebuffer)
        # What every scene build may declare (a driver may keep a block the build's early
        # return leaves unread), and the albedo's plain filter: a cutout's alpha as the view reads it.
        self._bind_pass_wide(ROOT_VIEW, None)
        masked = nodes is not None
        if masked:
            bind_texture(ctx, nodes, NODE_UNIT)
        screen = "depth_normals half" if step == 2 else "depth_normals"
        renderer.upload_views(views)
        opaque = renderer.tree_opaque_batches()  # (a refracting surface's pixels: what it shows, behind it)
        reach = None   # a level's: which batch can draw a sample in which view (as its draw culls them)
        if (masked and self.cull_batches and opaque and len(opaque) >= self.cull_min_batches
                and len(views) * len(opaque) >= self.cull_min_draws):
            reach = batch_reach(views, nodes.size, opaque)
        for index, view in enumerate(views):
            set_scissor(ctx, stepped_scissor(view.scissor, step, size))
            set_front_face(ctx, "cw" if view.mirrored else "ccw")
            renderer.bind_view_at(index)
            self._draw_batches(opaque if reach is None else self._reaching(opaque, reach[index], view), 0, masked,
                               skip=view.skip, hide=view.hide, screen=screen)
        renderer.stats.passes += 1
        if renderer.debug:
            renderer.checkpoint(f"depth and normals ({views[0].name}{' and others' if len(views) > 1 else ''})")

    def finish_root(self, root: View, targets: RenderTargets, options: SceneOptions) -> None:
        """What a view tree does last in its root ``root`` (drawn into ``targets`` with
        ``options``), once the levels below are composited into it: the screen-space
        reflections, where the main view was drawn for them (``ScreenReflectionPass``), the
        light shafts, where its camera has them (``VolumetricFogPass``), the refracting
        surfaces (``refract``) and the transparent slot (``draw_transparent``) about them
        (``_slot_and_glass``), so glass goes over all."""
        if self.screen_reflections is not None:
            self.screen_reflections.composite(targets)
        if self.volumetric_fog is not None:
            self.volumetric_fog.composite(targets)
        self._slot_and_glass([root], targets, options, None, True)

    def _slot_and_glass(self, views: Sequence[View], targets: RenderTargets, options: SceneOptions,
                        conditions: Sequence[moderngl.Query] | None, slot: bool) -> None:
        """``views``' waters' shore foam (``draw_foam``), their refracting surfaces
        (``refract``) and, with ``slot``, their transparent slot (``draw_transparent``):
        where some refract and some of the slot is there, the
        slot in two parts about them, each in its back-to-front order: first, into the copy
        the glass marches, so the glass shows them, its things that lie behind every
        refracting surface they meet on screen and meet none drawn after (HDRP's "before
        refraction" pass, chosen here by where things are); then, over the glass, the rest
        (what of it lies behind glass is unseen through it; counted in
        ``RenderStats.slot_after_glass``)."""
        self.draw_foam(views, targets, options, conditions)
        refracting = self.renderer.refracting_batches()
        # (which refracting batch can reach which view: for the glass and the slot's split alike)
        drawn = refracting and views and not options.transparent
        reach = batch_reach(views, targets.size, refracting) if drawn else None
        glass = self._glass_boxes(views, reach) if slot and reach is not None and self.slot_drawn() else None
        if glass is None:
            self.refract(views, targets, options, conditions, reach)
            if slot:
                self.draw_transparent(views, targets, options, conditions)
            return
        self.draw_transparent(views, targets, options, conditions, glass=glass, part="before")
        self.refract(views, targets, options, conditions, reach)
        self.draw_transparent(views, targets, options, conditions, glass=glass, part="after")

    def _glass_boxes(self, views: Sequence[View], reach: list[list[bool]]) -> list[np.ndarray | None] | None:
        """For each of ``views``, the world boxes ([n, lo/hi, xyz]) of the refracting
        instances that can reach it (``reach``: ``batch_reach`` of the refracting batches;
        None: none), or None for all where none reaches them."""
        refracting = self.renderer.refracting_batches()
        boxes = [np.concatenate([batch.row_boxes for batch, reaches in zip(refracting, rows, strict=True) if reaches])
                 if any(rows) else None for rows in reach]
        return boxes if any(box is not None for box in boxes) else None

    def _slot_before(self, views: Sequence[View], size: tuple[int, int], glass: Sequence[np.ndarray | None],
                     items: list) -> list[bool]:
        """Which of ``items`` (``_slot_items``: batches and, as lists a view, particle emitters,
        in blending order; drawn for ``views``, ``glass`` the refracting boxes that reach each)
        are drawn before the refracting surfaces: in order, each that in every view lies
        wholly behind the glass it meets on screen (``screen_refraction.behind_the_glass``;
        a decal lies on an opaque surface: before glass, it is hidden where the glass is
        nearer, as it should be) and meets on screen none of the things before it that are
        drawn after (so drawing it first changes no blend: things apart on screen blend in
        either order).  The rest are drawn after, in their order."""
        rects, fine = [], []  # a view each: each item's rows' rectangles, and whether it may go first
        for index, view in enumerate(views):
            rows, owner = [], []
            for at, item in enumerate(items):
                boxes = [record.row_boxes for record in item[index]] if isinstance(item, list) else [item.row_boxes]
                for box in boxes:
                    rows.append(box)
                    owner.append(np.full(len(box), at))
            owner = np.concatenate(owner) if owner else np.zeros(0, np.int64)
            boxes = np.concatenate(rows) if rows else np.zeros((0, 2, 3))
            drawn = box_rects(view, size, boxes)
            rects.append([drawn[owner == at] for at in range(len(items))])
            behind = (np.ones(len(boxes), bool) if glass[index] is None
                      else behind_the_glass(view, size, glass[index], boxes, drawn))
            fine.append([bool(behind[owner == at].all()) or (not isinstance(item, list) and item.decal)
                         for at, item in enumerate(items)])
        before, after = [], [[] for _ in views]
        for at in range(len(items)):
            first = all(fine[v][at] for v in range(len(views))) and not any(
                len(after[v]) and meets(rects[v][at], np.concatenate(after[v])).any() for v in range(len(views)))
            before.append(first)
            if not first:
                for v in range(len(views)):
                    after[v].append(rects[v][at])
        return before

    def draw_foam(self, views: Sequence[View], targets: RenderTargets, options: SceneOptions,
                  conditions: Sequence[moderngl.Query] | None = None) -> None:
        """The shore foam of the waters that have it (``Water.foam``: ``engine/render/foam.py``)
        in a view tree's ``views`` (drawn into ``targets`` with ``options``), once the level
        below is composited into them, before their glass: the level's depth from the copy
        its water's composite took (``RefractionCopy.holds_depth_of``; else copied now: the
        water wrote no depth, so the copy holds what lies under it), then each view's foamy
        waters drawn again with their ``FOAM`` builds,
        blended over the water's reflection as glass is (``shaders/include/foam.glsl``).
        Nothing where no water has foam or none reaches the views, nor for a view drawn whole
        (a probe face's: it has no copy)."""
        renderer = self.renderer
        entities = renderer.foam.entities
        if not entities or not views or options.transparent:
            return
        foamy = [batch for batch in renderer.batches.values()
                 if batch.count and any(entity in batch.row_of for entity in entities)]
        if not foamy:
            return
        reach = batch_reach(views, targets.size, foamy)
        # (a water's own reflection or refraction view, which looks out of it, shows no foam of its own)
        shown = [any(rows) and bool(entities - {view.skip}) for rows, view in zip(reach, views, strict=True)]
        if not any(shown):
            return
        if not self.refraction_copy.holds_depth_of(targets):   # (the water's composite took it: its depth is as it is)
            self.refraction_copy.take(targets, False)
        targets.begin_glass()
        self._begin(views, targets, options, _TRANSPARENT)
        renderer.foam.bind()
        renderer.upload_views(views)
        self._sky_size = renderer.sky.size[0]
        for index, view in self._each_view(views, conditions, shown):
            self._draw_batches(self._reaching(foamy, reach[index], view), 0, options.masked, skip=view.skip,
                               hide=view.hide, screen="foam")
        targets.end_glass()
        renderer.stats.passes += 1

    def _each_view(self, views: Sequence[View], conditions: Sequence[moderngl.Query] | None,
                   chosen: Sequence[object]) -> Iterator[tuple[int, View]]:
        """Each of ``views`` whose ``chosen`` entry is true, with its index: inside its
        conditional render (``conditions``, where given), its scissor, winding and Camera
        block set for the draws the caller makes."""
        ctx, renderer = self.ctx, self.renderer
        for index, view in enumerate(views):
            if not chosen[index]:
                continue
            with _ALWAYS if conditions is None else conditions[index].crender:
                set_scissor(ctx, view.scissor)
                set_front_face(ctx, "cw" if view.mirrored else "ccw")
                renderer.bind_view_at(index)
                yield index, view

    def refract(self, views: Sequence[View], targets: RenderTargets, options: SceneOptions,
                conditions: Sequence[moderngl.Query] | None = None, reach: list[list[bool]] | None = None) -> None:
        """The refracting batches (``Gpu.refracting_batches``: ``Refractive.screen``) of a view
        tree's ``views`` (drawn into ``targets`` with ``options``, whose opaque draws left them
        out), once everything but the glass is in their pixels: the level's colour and depth
        copied (``RefractionCopy.take``), then each view's draws with the ``SCREEN_REFRACTION``
        builds, which march their refracted rays across the copy, depth tested and written as
        opaque draws are (``engine/render/screen_refraction.py``).  ``conditions`` as for
        ``draw``; ``reach``: the refracting batches' ``batch_reach`` of ``views``, where the
        caller has it.  Nothing where none refracts or none reaches the views, or
        for a view drawn whole (its ``options.transparent``, which drew them with its opaque
        batches: a paths' self-check's face; a probe's faces finish as a root where glass
        refracts, ``ProbeCaptures._finished``); where none refracts, the copies are let go once a whole
        frame has taken none (water takes them too)."""
        renderer, ctx = self.renderer, self.ctx
        refracting = renderer.refracting_batches()
        if not refracting:  # (the last refracting surface went: its copies with it, water's kept)
            self.refraction_copy.let_go_unused()
            return
        if not views or options.transparent:
            return
        # Which batch can draw a sample in which view (its boxes against the view's volume):
        # a level none reaches copies nothing.
        if reach is None:
            reach = batch_reach(views, targets.size, refracting)
        if not any(any(rows) for rows in reach):
            return
        # Glass behind glass: each view's refracting instances in layers, farthest first, each
        # layer drawn over a copy that holds the layers before it (refraction_layers).
        layers = [refraction_layers(view, targets.size, self._reaching(refracting, reach[index], view), self._layouts)
                  if any(reach[index]) else None for index, view in enumerate(views)]
        stats = renderer.stats
        count = max(len(plan.runs) for plan in layers if plan is not None)
        cut = sum(plan.cut for plan in layers if plan is not None)
        if cut:
            stats.refraction_layers_cut += cut
            if not self._said_layers_cut:
                self._said_layers_cut = True
                warnings.warn(RefractionLimitWarning(
                    f"Refractive.screen: {cut} refracting surfaces lie behind {MAX_REFRACTION_LAYERS} others on "
                    f"screen (MAX_REFRACTION_LAYERS): drawn in the last layer, they do not show the glass of that "
                    "layer behind them (RenderStats.refraction_layers_cut)"), stacklevel=2)
        stats.refraction_layers = max(stats.refraction_layers, count)
        self._sky_size = renderer.sky.size[0]
        for layer in range(count):
            runs = [plan.runs[layer] if plan is not None and layer < len(plan.runs) else [] for plan in layers]
            # After the first, a layer's copy takes again only what the layer before drew.
            region = None
            if layer:
                drawn = [plan.drawn[layer - 1] for plan in layers if plan is not None and layer - 1 < len(plan.drawn)]
                x0, y0 = min(r[0] for r in drawn), min(r[1] for r in drawn)
                region = (x0, y0, max(r[2] for r in drawn) - x0, max(r[3] for r in drawn) - y0)
            # (a rough one's march reads the copy's mips: made only then)
            self.refraction_copy.take(targets, any(batch.rows["surface"][first:past, 1].max() > 0.0
                                                   for view_runs in runs for batch, first, past in view_runs), region)
            self._begin(views, targets, options, _SCENE)
            bind_texture(ctx, targets.node, NODE_UNIT)  # (the march keeps to its view's pixels, masked or not)
            if not layer:  # (the views' Camera blocks stay uploaded for the layers after)
                renderer.upload_views(views)
            for index, view in self._each_view(views, conditions, runs):
                whole = [batch for batch, first, past in runs[index] if first == 0 and past == batch.count]
                self._draw_batches(whole, 0, options.masked, skip=view.skip, hide=view.hide, screen="refracted")
                for batch, first, past in runs[index]:
                    if first != 0 or past != batch.count:
                        self._draw_batches([batch], 0, options.masked, skip=view.skip, hide=view.hide,
                                           screen="refracted", rows=(first, past))
            stats.passes += 1
        if renderer.debug:
            renderer.checkpoint(f"refraction ({views[0].name}{' and others' if len(views) > 1 else ''})")

    def finish_level(self, depth: int, views: Sequence[View], targets: RenderTargets, options: SceneOptions,
                     conditions: Sequence[moderngl.Query] | None, glass: bool) -> None:
        """What a view tree does last in its reflection level ``depth`` (``views`` drawn into
        ``targets`` with ``options``), once the level below is composited into it: the
        screen-space reflections, where the level was drawn for them
        (``ScreenReflectionPass.composite_level``), the light shafts where the camera's reach
        it (``VolumetricFogPass.composite_level``), the refracting surfaces (``refract``)
        and, with ``glass`` (something see-through is drawn), the transparent slot about
        them (``_slot_and_glass``)."""
        if self.screen_reflections is not None:
            self.screen_reflections.composite_level(depth, views, targets)
        if self.volumetric_fog is not None:
            self.volumetric_fog.composite_level(depth, views, targets)
        self._slot_and_glass(views, targets, options, conditions, glass)

    def draw_transparent(self, views: Sequence[View], targets: RenderTargets, options: SceneOptions,
                         conditions: Sequence[moderngl.Query] | None = None,
                         glass: Sequence[np.ndarray | None] | None = None, part: str | None = None) -> None:
        """The rest of the transparent slot of ``views``, drawn by ``draw`` with ``options``
        (its ``transparent`` False) into ``targets``: each view's transparent batches nearer
        than its see-through mirrors and portals (all of them where there are none: glass),
        farthest first, its particle emitters in among them, blended over what its pixels
        hold now, testing the depth its opaque draws left but not writing it.  A view tree
        calls it for a level's views (its root's too) after the levels below are composited
        into them, so glass blends over the reflections behind it.  ``conditions`` as for
        ``draw``.  ``part`` "before" or "after", with ``glass`` (each view's refracting boxes:
        ``_glass_boxes``): only the slot's things that lie behind the glass they meet and need
        not blend after the rest (``_slot_before``), drawn before the refracting surfaces, or
        only the rest, after them.  Nothing at all where no batch is transparent and no
        particle lives."""
        transparent = self.renderer.transparent_batches()
        particles = self._particles_now()
        if not views or not (transparent or particles):
            return
        renderer, size = self.renderer, targets.size
        self._sky_size = renderer.sky.size[0]
        state = _BATCHED_TRANSPARENT if options.batched else _TRANSPARENT
        targets.begin_glass()
        self._begin(views, targets, options, state)
        try:
            if not transparent and part is None:  # the particles alone (engine/render/particle_draw.py)
                renderer.upload_views(views)
                self.particle_draw.draw(views, targets, options.masked, self._ambient_probes, conditions=conditions)
            elif not transparent:  # each view's particles before or after the glass
                renderer.upload_views(views)
                emitters = self.particle_draw.visible(views, size)
                chosen = []
                for index, view in enumerate(views):
                    items = self._part(_slot_items([], [emitters[index]], view.sorting_eye), [view],
                                       [glass[index]], part, size)
                    chosen.append([record for item in items for record in item[0]])
                if any(chosen):
                    self.particle_draw.draw(views, targets, options.masked, self._ambient_probes,
                                            conditions=conditions, chosen=chosen)
            elif options.batched:
                geometry = self._slot_geometry(transparent)
                for indices in instanced_groups(views):
                    chunk = [views[i] for i in indices]
                    emitters = self.particle_draw.visible(chunk, size) if particles else None
                    for group, _, rest, _ in slot_groups(transparent, chunk, geometry):
                        at = [chunk.index(view) for view in group]
                        drawn = [emitters[i] for i in at] if emitters is not None else [[] for _ in group]
                        items = self._part(_slot_items(rest, drawn, group[0].sorting_eye), group,
                                           None if glass is None else [glass[indices[i]] for i in at], part, size)
                        if items:
                            self._batched_slot(group, [indices[i] for i in at], items, targets, options, state,
                                               conditions)
            else:
                geometry = self._slot_geometry(transparent)
                renderer.upload_views(views)
                emitters = self.particle_draw.visible(views, size) if particles else None
                for index, view in enumerate(views):
                    batches = split_slot(transparent, view, geometry)[1]
                    items = self._part(_slot_items(batches, [emitters[index] if emitters else []], view.sorting_eye),
                                       [view], None if glass is None else [glass[index]], part, size)
                    if items:  # (else all behind its see-through surfaces: drawn with them)
                        with _ALWAYS if conditions is None else conditions[index].crender:
                            self._slot_view(view, index, items, options.masked, targets, _TRANSPARENT)
        finally:
            targets.end_glass()
        if renderer.debug:
            renderer.checkpoint(f"transparent ({views[0].name}{' and others' if len(views) > 1 else ''})")

    def _part(self, items: list, views: Sequence[View], glass: Sequence[np.ndarray | None] | None, part: str | None,
              size: tuple[int, int]) -> list:
        """``items`` (``_slot_items``, drawn for ``views``) as ``draw_transparent``'s ``part``
        has them: all (None), those drawn before the refracting surfaces ("before":
        ``_slot_before``) or the rest, after them ("after"; some there counts in
        ``RenderStats.slot_after_glass``).  The "before" draw's answer serves the "after"
        draw of the same views and items (worked out once)."""
        if part is None or glass is None or not items:
            return items
        key = tuple(map(id, views))
        signature = tuple(tuple(id(record) for drawn in item for record in drawn) if isinstance(item, list)
                          else id(item) for item in items)
        kept = self._slot_splits.pop(key, None)
        if part == "after" and kept is not None and kept[0] == signature:
            before = kept[1]
        else:
            before = self._slot_before(views, size, glass, items)
        if part == "before":
            if len(self._slot_splits) >= _SLOT_SPLITS_KEPT:
                self._slot_splits.clear()
            self._slot_splits[key] = (signature, before)
            return [item for item, first in zip(items, before, strict=True) if first]
        if not all(before):
            self.renderer.stats.slot_after_glass += 1
        return [item for item, first in zip(items, before, strict=True) if not first]

    def _begin(self, views: Sequence[View], targets: RenderTargets, options: SceneOptions, state: PassState,
               run: object | None = None) -> None:
        """What every pass of ``draw`` and ``draw_transparent`` starts with: ``targets``'
        colour, surface and seen ids and depth bound with ``state`` (per-view passes at the
        first view's scissor), the node image where masked, the lights, shadows, irradiance,
        sky and the albedo's sampler (once a ``run``: ``_bind_pass_wide``)."""
        targets.view_framebuffer.use()  # colour, surface and seen ids, depth
        apply_pass_state(self.ctx, state, (0, 0, *targets.size), None if options.batched else views[0].scissor)
        if options.masked:
            bind_texture(self.ctx, targets.node, NODE_UNIT)
        self._bind_pass_wide(options, run)

    def _reflecting_framebuffer(self, options: SceneOptions) -> moderngl.Framebuffer | None:
        """For the main view (or a reflection level) drawn for screen reflections, the
        framebuffer of the level's images and theirs (``ScreenReflectionPass.framebuffer``: a
        root's node image too, which it writes 0 to, as its clear did; a level's a stand-in for
        it, as its masked draws read its own); None otherwise."""
        if options.reflections and self.screen_reflections is not None:
            return self.screen_reflections.framebuffer
        return None

    def _bind_pass_wide(self, options: SceneOptions, run: object | None) -> None:
        """The bindings every scene pass draws with: the Lights block, the shadow maps and
        their blocks, the irradiance table and boxes, the sky, the albedo sampler; left as
        they are in a pass of the same ``run`` (``draw``) as the last that bound them, with
        the same capture state and sampler, while none of them changed
        (``bindings_epoch``)."""
        ctx, renderer = self.ctx, self.renderer
        kept, state = self._pass_wide, (renderer.capturing, options.reflection_filter, self.irradiance.bounce_lit)
        if run is not None and kept is not None and kept[0] is run and kept[1] == state \
                and kept[2] == bindings_epoch(ctx) and bindings.CACHE_STATE:
            return
        if run is None:
            self._pass_wide = None
            self._bind_pass_wide_now(options)
            return
        with watching(ctx):  # what these bind is watched: binding any of them otherwise moves the epoch on
            self._bind_pass_wide_now(options)
        self._pass_wide = (run, state, bindings_epoch(ctx))

    def _bind_pass_wide_now(self, options: SceneOptions) -> None:
        ctx, renderer = self.ctx, self.renderer
        bind_uniform_block(ctx, renderer.lights_ubo, LIGHTS_BINDING)
        renderer.fog.bind()
        self.shadows.bind()
        renderer.spot_cookies.bind()
        renderer.caustics.bind()
        renderer.ripples.bind()
        renderer.clouds.bind()
        # The irradiance table (unit 5 serves other passes between) and the boxes; a probe's
        # capture, and a world without boxes, draw the build without them (sky only).
        self._ambient_probes = self.irradiance.bind(capturing=renderer.capturing != 0)
        bind_texture(ctx, renderer.sky, SKY_UNIT)
        # A bound sampler object overrides the textures' own filter; it stays bound from one
        # reflection level to the next (bind_texture takes it off for any other pass).
        bind_sampler(ctx, self._reflection_filter() if options.reflection_filter else None, ALBEDO_UNIT)

    def slot_drawn(self) -> bool:
        """Whether a view's transparent slot (``draw_transparent``) draws anything now: some
        batch is transparent, or particles live."""
        return bool(self.renderer.transparent_batches()) or self._particles_now()

    def _particles_now(self) -> bool:
        """Whether a view drawn now draws particles: some live, and no probe is captured (a
        capture leaves them out: ``ParticleEmitter``)."""
        return self.renderer.capturing == 0 and any(record.particles for record in self.particle_draw.emitters.values())

    def _slot_geometry(self, transparent: list[InstanceBatch]) -> SlotGeometry:
        """``transparent``'s ``SlotGeometry``, worked out again only when the batches, their
        planes, instances or variants are others (``SlotGeometry.matches``; a frame's views,
        levels and probe faces share it, and so do frames while the glass stands, whatever
        else moves: at 51 batches it costs about 0.4 ms)."""
        kept = self._slot_kept
        if kept is not None and kept.matches(transparent):
            return kept
        geometry = self._slot_kept = SlotGeometry(transparent)
        return geometry

    def _transparent_view(self, view: View, index: int, batches: list[InstanceBatch], masked: bool) -> None:
        """One view's transparent ``batches``, in their order (the pass state is _TRANSPARENT,
        the depth mask off): its scissor, winding and Camera block (``index`` of the last
        ``upload_views``)."""
        set_scissor(self.ctx, view.scissor)
        set_front_face(self.ctx, "cw" if view.mirrored else "ccw")
        self.renderer.bind_view_at(index)
        self._draw_batches(batches, 0, masked, skip=view.skip, hide=view.hide)

    def _slot_view(self, view: View, index: int, items: list, masked: bool, targets: RenderTargets,
                   state: PassState) -> None:
        """One view's slot ``items`` (``_slot_items``: its glass batches, in their order, and
        its particle emitters among them; the pass state is ``state``): the batches of a run
        in one go, each run of emitters drawn where it stands, so a cloud behind a window is
        tinted by it and one in front of it covers it."""
        ctx, run, copied = self.ctx, [], False
        for at, item in enumerate(items):
            if not isinstance(item, list):
                run.append(item)
                continue
            if run:
                self._transparent_view(view, index, run, masked)
                run = []
            if at and isinstance(items[at - 1], list):
                continue  # (drawn with the run of emitters it belongs to)
            records = [record for chosen in _emitter_run(items, at) for record in chosen[0]]
            self.particle_draw.draw([view], targets, masked, self._ambient_probes, first_index=index,
                                    chosen=[records], copy_depth=not copied)
            copied = True
            apply_pass_state(ctx, state, (0, 0, *targets.size), view.scissor)
        if run:
            self._transparent_view(view, index, run, masked)

    def _batched_slot(self, group: Sequence[View], indices: list[int], items: list, targets: RenderTargets,
                      options: SceneOptions, state: PassState, conditions: Sequence[moderngl.Query] | None) -> None:
        """A batched group's slot ``items`` (``_slot_items``: its glass batches, one draw a
        batch for all of ``group``, its views at ``indices`` of the pass, and each view's
        particle emitters in among them)."""
        renderer, ctx = self.renderer, self.ctx
        copied, scissor, glass_run = False, None, []

        def flush_glass() -> None:
            nonlocal scissor
            if not glass_run:
                return
            if scissor is None:  # (the group's view table, written once)
                scissor = self._views_table(group)
            apply_pass_state(ctx, state, (0, 0, *targets.size), scissor)
            set_front_face(ctx, "cw" if group[0].mirrored else "ccw")  # (a group has one winding: instanced_groups)
            self._draw_batches(glass_run, len(group), options.masked)
            glass_run.clear()

        for at, item in enumerate(items):
            if not isinstance(item, list):
                glass_run.append(item)
                continue
            if at and isinstance(items[at - 1], list):
                continue  # (drawn with the run of emitters it belongs to)
            flush_glass()
            run = _emitter_run(items, at)
            chosen = [[record for ready in run for record in ready[view]] for view in range(len(group))]
            renderer.upload_views(group)
            self.particle_draw.draw(group, targets, options.masked, self._ambient_probes, chosen=chosen,
                                    copy_depth=not copied,
                                    conditions=None if conditions is None else [conditions[i] for i in indices])
            copied = True
        flush_glass()

    def _draw_each(self, views: Sequence[View], targets: RenderTargets, viewport: tuple[int, int, int, int],
                   options: SceneOptions, conditions: Sequence[moderngl.Query] | None = None) -> None:
        """Each view its own draws: state shared by the views is set once; per view there is
        a scissor, a winding, a camera and the draws (on llvmpipe the Python and driver cost
        per view is on the frame's critical path)."""
        ctx = self.ctx
        renderer = self.renderer
        transparent = renderer.transparent_batches()
        now = _drawn_now(transparent, options)
        geometry = self._slot_geometry(transparent) if now else None
        particles = options.transparent and self._particles_now()  # (a tree's views: draw_transparent's)
        # (a tree's views draw their refracting batches after their copy: refract)
        opaque = renderer.opaque_batches() if options.transparent else renderer.tree_opaque_batches()
        unlit = unlit_batches(opaque, options.unlit)
        # What each view keeps of them.
        check = self.unlit_boxes.views(unlit, renderer.scene_version) if now and unlit else None
        renderer.upload_views(views)  # every view's Camera block in one write; each binds its range
        reach = None
        if (self.cull_batches and opaque and len(opaque) >= self.cull_min_batches
                and len(views) * len(opaque) >= self.cull_min_draws):
            reach = batch_reach(views, targets.size, opaque)  # which batch can draw a sample in which view
        masked = options.masked
        screen = ""
        if options.occlusion and renderer.screen_occlusion is not None:
            screen = "occluded"  # (the root's, or an occluded level's: the image is its pixels')
            bind_texture(ctx, renderer.screen_occlusion, SCREEN_OCCLUSION_UNIT)
            if renderer.screen_contact_lamps is not None:
                bind_texture(ctx, renderer.screen_contact_lamps, SCREEN_CONTACT_UNIT)
        reflecting = self._reflecting_framebuffer(options)
        if conditions is None and not options.sky and not now and not particles and reflecting is None:
            # A reflection level's views (exact visibility), drawn whatever their claims
            # count: per view its scissor, winding, camera and draws, nothing else.
            draw, bind_view_at = self._draw_batches, renderer.bind_view_at
            for index, view in enumerate(views):
                set_scissor(ctx, view.scissor)
                set_front_face(ctx, "cw" if view.mirrored else "ccw")
                bind_view_at(index)
                draw(opaque if reach is None else self._reaching(opaque, reach[index], view),
                     0, masked, skip=view.skip, hide=view.hide, unlit=unlit, screen=screen)
            renderer.stats.passes += len(views)
            return
        sky_draw = self.sky_draw
        for index, view in enumerate(views):
            if now:  # the slot, or (a tree's view) its part up to its see-through surfaces
                if options.transparent:
                    batches = back_to_front(transparent, view.sorting_eye, view, geometry)
                else:
                    batches, _, torn = split_slot(transparent, view, geometry)
                    renderer.stats.glass_between_surfaces += torn
            view_unlit = unlit if check is None else check.keep(view, batches)
            with _ALWAYS if conditions is None else conditions[index].crender:
                set_scissor(ctx, view.scissor)  # unless in place (moderngl's own record: the cache reads it)
                set_front_face(ctx, "cw" if view.mirrored else "ccw")
                renderer.bind_view_at(index)
                drawn = opaque if reach is None else self._reaching(opaque, reach[index], view)
                if reflecting is None:
                    self._draw_batches(drawn, 0, masked, skip=view.skip, hide=view.hide, unlit=view_unlit,
                                       screen=screen)
                else:
                    self._draw_reflecting(drawn, view, targets, reflecting, viewport, view_unlit, screen, masked)
                if options.sky:
                    # Into the view's own framebuffer: the sky writes id 0 (nothing) to the
                    # surface and seen images, the very values the clear put where no surface
                    # drew (it draws only where depth is still the cleared far plane).  One
                    # framebuffer for the draws and the sky: two binds fewer a view.  (The flush
                    # llvmpipe did at the switch was its rasterising of the queued draws, which
                    # the next flush now does: measured, no faster a frame; issue 40.)
                    apply_pass_state(ctx, _SKY, viewport, view.scissor)
                    sky_draw.vertex_array(layered=False).render(moderngl.TRIANGLES, vertices=3)
                    renderer.stats.draw_calls += 1
                if now or particles:  # the slot, the particles in among it (engine/render/particle_draw.py)
                    targets.begin_glass()
                    apply_pass_state(ctx, _TRANSPARENT, viewport, view.scissor)
                    emitters = self.particle_draw.visible([view], targets.size)[0] if particles else ()
                    items = _slot_items(batches if now else [], [emitters], view.sorting_eye)
                    self._slot_view(view, index, items, options.masked, targets, _TRANSPARENT)
                    targets.end_glass()
                if (options.sky or now or particles) and index + 1 < len(views):
                    # The next view's state (the pass after the last applies its own).
                    apply_pass_state(ctx, _SCENE, viewport, views[index + 1].scissor)
                renderer.stats.passes += 1

    def _draw_reflecting(self, batches: list[InstanceBatch], view: View, targets: RenderTargets,
                         reflecting: moderngl.Framebuffer, viewport: tuple[int, int, int, int], unlit: frozenset | set,
                         screen: str, masked: bool = False) -> None:
        """A view's opaque ``batches`` drawn for screen reflections (the main view's, or a
        reflection level's view's, ``masked``): those that reflect
        no sky or probe first, as ever (their pixels keep the cleared "nothing reflected"),
        then those that may (``reflects_environment``) into ``reflecting``, the framebuffer
        with the reflections' images, with the builds that write them: only the surfaces
        that reflect pay for the three images' writes.  The view's own framebuffer is bound
        again after."""
        ctx = self.ctx
        others = [batch for batch in batches if not reflects_environment(batch)]
        mirrored = [batch for batch in batches if reflects_environment(batch)]
        self._draw_batches(others, 0, masked, skip=view.skip, hide=view.hide, unlit=unlit, screen=screen)
        if mirrored:
            winding = "cw" if view.mirrored else "ccw"  # (the pass state's is counter-clockwise: a mirror's view's not)
            reflecting.use()
            apply_pass_state(ctx, _SCENE, viewport, view.scissor)
            set_front_face(ctx, winding)
            self._draw_batches(mirrored, 0, masked, skip=view.skip, hide=view.hide, unlit=unlit,
                               screen=f"{screen} reflected".lstrip())
            targets.view_framebuffer.use()
            apply_pass_state(ctx, _SCENE, viewport, view.scissor)
            set_front_face(ctx, winding)

    def _reaching(self, batches: list[InstanceBatch], reach: list[bool], view: View) -> list[InstanceBatch]:
        """The batches whose ``reach`` (batch_cull.batch_reach) in ``view`` is True; those
        left out that ``_draw_batches`` would have drawn (not the view's own skipped one)
        count in ``RenderStats.draws_culled``."""
        kept = [batch for batch, reaches in zip(batches, reach, strict=True) if reaches]
        if len(kept) < len(batches):
            skipped = (view.skip, view.hide)
            self.renderer.stats.draws_culled += sum(
                1 for batch, reaches in zip(batches, reach, strict=True)
                if not reaches and not (batch.count == 1 and batch.entity_at[0] in skipped))
        return kept

    def _reaching_any(self, batches: list[InstanceBatch], reach: list[list[bool]]) -> list[InstanceBatch]:
        """The batches that ``reach`` (``batch_reach`` of a batched draw's views) says reach
        some view; those left out count in ``RenderStats.draws_culled``, a draw each."""
        kept = [batch for batch, reaches in zip(batches, zip(*reach, strict=True), strict=True) if any(reaches)]
        self.renderer.stats.draws_culled += len(batches) - len(kept)
        return kept

    def _draw_batched(self, views: Sequence[View], targets: RenderTargets, options: SceneOptions) -> None:
        """Every batch once for all ``views`` (a group of ``instanced_groups``: at most
        MAX_BATCHED_VIEWS, one winding): each instance drawn once a view, its view's camera
        from the Views block, clipped to the view's rectangle by clip distances 1-4 (the
        per-view scissor of ``_draw_each``).  A batch whose boxes reach none of the views is
        left out (``batch_reach``, at the per-view pass's thresholds).  The slot's part drawn
        with them (see-through mirrors, water) tests depth but writes none (``begin_glass``), as
        ``_draw_each``'s: a water's foam is drawn over it later, and its copy holds what lies below."""
        renderer = self.renderer
        ctx = self.ctx
        scissor = self._views_table(views)
        ctx.scissor = scissor
        winding = "cw" if views[0].mirrored else "ccw"
        set_front_face(ctx, winding)
        count = len(views)
        transparent = renderer.transparent_batches()
        now = _drawn_now(transparent, options)
        opaque = renderer.opaque_batches() if options.transparent else renderer.tree_opaque_batches()
        if (self.cull_batches and opaque and len(opaque) >= self.cull_min_batches
                and count * len(opaque) >= self.cull_min_draws):
            opaque = self._reaching_any(opaque, batch_reach(views, views[0].size, opaque))
        unlit = unlit_batches(opaque, options.unlit)
        groups = None
        if now and not options.transparent:  # each group of views with the same part of the slot before the claims
            groups = slot_groups(transparent, views, self._slot_geometry(transparent))
        if now and unlit:  # one draw for every view: unlit where no view's slot can blend over it
            check = self.unlit_boxes.views(unlit, renderer.scene_version)
            for group, first in ([(views, transparent)] if groups is None else [group[:2] for group in groups]):
                for view in group:
                    check.unlit = check.keep(view, first)
            unlit = check.unlit
        self._draw_batches(opaque, count, options.masked, unlit=unlit)
        if now:
            targets.begin_glass()
            viewport = (0, 0, *views[0].size)
            if groups is None:  # farthest from the first view's eye first (the views of a level are close)
                apply_pass_state(ctx, _BATCHED_TRANSPARENT, viewport, scissor)
                set_front_face(ctx, winding)
                ordered = back_to_front(transparent, views[0].sorting_eye, None, self._slot_geometry(transparent))
                self._draw_batches(ordered, count, options.masked)
            else:  # in one draw a batch a group
                for group, first, _, torn in groups:
                    renderer.stats.glass_between_surfaces += torn
                    if not first:
                        continue
                    if len(groups) > 1:
                        scissor = self._views_table(group)
                    apply_pass_state(ctx, _BATCHED_TRANSPARENT, viewport, scissor)
                    set_front_face(ctx, winding)
                    self._draw_batches(first, len(group), options.masked)
            targets.end_glass()
            apply_pass_state(ctx, _BATCHED_SCENE, viewport)
        renderer.stats.passes += 1

    def _views_table(self, views: Sequence[View]) -> tuple[int, int, int, int]:
        """The Views block of ``views`` (at most MAX_BATCHED_VIEWS) written and bound; the
        union of their rectangles (the pass's scissor).  A block the buffer holds already
        (a level's glass drawn for the group its opaque draws were) is not written again."""
        buffer, block = self._views_buffer(), views_block(views)
        if block != self._views_written:
            buffer.write(block)
            self._views_written = block
        bind_uniform_block(self.ctx, buffer, VIEWS_BINDING)
        return union_rect([v.scissor or (0, 0, *v.size) for v in views])

    def _views_buffer(self) -> moderngl.Buffer:
        """The Views block's buffer, made the first time it is asked for (holding nothing yet)."""
        if self._views_ubo is None:
            self._views_ubo = self.ctx.buffer(reserve=VIEWS_BLOCK_BYTES)
            self._views_written = None
        return self._views_ubo

    def draw_layered(self, views: Sequence[View], target: LayeredCubeTarget | LayeredArrayTarget,
                     culled: bool = True) -> None:
        """The six faces of a cube map in one pass (``views[i]`` is face i, its layer): every
        batch drawn once through the geometry shader with six invocations, each triangle
        emitted to the faces whose frustum it touches (``culled``) or to all six, then the
        sky behind, per face.  Colour only: a layered face has no ids, so it cannot root a
        view tree (faces that must see mirrors and portals take the six-pass path).  The
        target is the cube map itself or a six-layer 2D array (layer i face i) that the
        caller copies into the cube afterwards (``raw_gl.LayeredArrayTarget``)."""
        renderer = self.renderer
        ctx = self.ctx
        self._sky_size = renderer.sky.size[0]
        self._views_table(views)
        bind_uniform_block(self.ctx, renderer.lights_ubo, LIGHTS_BINDING)
        renderer.fog.bind()
        self.shadows.bind()
        renderer.spot_cookies.bind()
        renderer.caustics.bind()
        renderer.ripples.bind()
        renderer.clouds.bind()
        self._ambient_probes = self.irradiance.bind(capturing=True)  # a capture: the sky's light (a bounce: the grid's)
        bind_texture(self.ctx, renderer.sky, SKY_UNIT)
        renderer.bind_view(views[0])  # the shared eye, for what reads the Camera block
        size = (0, 0, target.size, target.size)
        # moderngl's state setters first (they write to the framebuffer moderngl thinks is
        # bound), then the raw bind, which sets this target's viewport, scissor and masks.
        apply_pass_state(ctx, _LAYERED_SCENE, size)
        target.bind()
        check = self._layered_target_check(target) if renderer.debug else None
        if check is not None:
            check("clear")
        target.clear()
        bind_sampler(ctx, self._reflection_filter(), ALBEDO_UNIT)
        skip = views[0].skip  # the probe's own object: in none of its faces (not drawn at all)
        draw_check = (lambda: check("draw")) if check is not None else None
        try:
            layered = "culled" if culled else "naive"
            self._draw_batches(renderer.opaque_batches(), len(views), False, layered, skip=skip,
                               before_draw=draw_check)
            transparent = renderer.transparent_batches()
            if transparent:
                apply_pass_state(ctx, _LAYERED_TRANSPARENT, size)
                ordered = back_to_front(transparent, views[0].sorting_eye, None, self._slot_geometry(transparent))
                self._draw_batches(ordered, len(views), False, layered, skip=skip,
                                   before_draw=draw_check)
            apply_pass_state(ctx, _LAYERED_SKY, size)
            if check is not None:
                check("sky")
            self.sky_draw.vertex_array(layered=True).render(moderngl.TRIANGLES, vertices=3)
        finally:
            target.unbind()
        renderer.stats.passes += 1
        renderer.checkpoint("layered cube-map capture")

    def _layered_target_check(self, target: LayeredCubeTarget | LayeredArrayTarget) -> Callable[[str], None]:
        """Debug mode: a check that the driver has the layered target bound and attached as
        a layered draw needs (``raw_gl.inspect_bound_target``), raising ``GLPassError`` with
        what differs.  Run before the clear and before each draw of the capture.  What is
        checked is the texture the draw writes (``target.texture``: the cube map, or the
        2D array later copied into it) and where that texture is bound for sampling."""

        what = "layered cube-map capture" if isinstance(target, LayeredCubeTarget) else "layered 2D-array capture"

        def check(moment: str) -> None:
            state = inspect_bound_target(self.ctx, target.texture, depth=True, binding=target.texture_binding)
            problems = state.problems(target.framebuffer, target.texture, 0, target.size, depth=True)
            if problems:
                raise GLPassError(f"{what}, at the {moment}: " + "; ".join(problems))

        return check

    def _reflection_filter(self) -> moderngl.Sampler | None:
        """The albedo sampler of reflection views, or None when they filter like the main view."""
        renderer = self.renderer
        if renderer.reflection_anisotropy == renderer.texture_anisotropy:
            return None
        sampler = self._reflection_sampler
        if sampler is None or sampler.anisotropy != renderer.reflection_anisotropy:
            if sampler is not None:
                forget_sampler(self.ctx, sampler)
                sampler.release()
            sampler = self._reflection_sampler = self.ctx.sampler(
                filter=(moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR), anisotropy=renderer.reflection_anisotropy)
        return sampler

    def release(self) -> None:
        if self._reflection_sampler is not None:
            forget_sampler(self.ctx, self._reflection_sampler)
        self.sky_draw.release()
        self.particle_draw.release()
        for obj in (self._views_ubo, self._reflection_sampler):
            if obj is not None:
                obj.release()
        self._views_ubo = self._reflection_sampler = self._views_written = None
        self.programs.release()
        self.refraction_copy.release()


def _drawn_now(transparent: list, options: SceneOptions) -> list:
    """What of the transparent slot ``draw`` may draw with the opaque batches: all of it,
    or, for a tree's view (``options.transparent`` False), its see-through surfaces (and,
    view by view, what must blend before one of them: ``split_slot``)."""
    if options.transparent or not transparent:
        return transparent
    return [batch for batch in transparent if see_through_surface(batch)]


def stepped_scissor(scissor: tuple[int, int, int, int] | None, step: int,
             size: tuple[int, int]) -> tuple[int, int, int, int] | None:
    """A level's scissor (its pixels) in an image ``step`` times smaller each way (of
    ``size``): every texel any of its pixels fall in."""
    if scissor is None or step == 1:
        return scissor
    x, y, width, height = scissor
    x0, y0 = x // step, y // step
    x1, y1 = min(-(-(x + width) // step), size[0]), min(-(-(y + height) // step), size[1])
    return x0, y0, max(x1 - x0, 0), max(y1 - y0, 0)


def _slot_items(batches: Sequence[InstanceBatch], emitters: Sequence[Sequence[tuple[float, object]]],
                eye: glm.vec3) -> list:
    """A slot's things in blending order: its glass ``batches`` (in their order) and, as
    lists of one list a view, the particle emitters of each view (``emitters``: its
    (squared distance, record) pairs, ``ParticleDraw.visible``) each put before the first batch
    whose middle is nearer ``eye`` than its own (a decal's: never; it lies on a surface),
    the rest after the last.  A single view's emitters are an item each (the slot may be
    cut between them: ``ScenePass._slot_before``)."""
    if not any(emitters):
        return list(batches)
    distance = {id(record): glm.length2(glm.vec3(*record.row_boxes[0].mean(axis=0)) - eye)
                for drawn in emitters for _, record in drawn}
    items: list = []
    placed: set[int] = set()
    for batch in [*batches, None]:
        near = -1.0 if batch is None else math.inf if batch.decal else glm.length2(batch.centre() - eye)
        ready = [[record for _, record in drawn if id(record) not in placed and distance[id(record)] > near]
                 for drawn in emitters]
        if any(ready):
            placed.update(id(record) for drawn in ready for record in drawn)
            if len(ready) == 1:
                items.extend([[record]] for record in ready[0])
            else:
                items.append(ready)
        if batch is not None:
            items.append(batch)
    return items


def _emitter_run(items: list, at: int) -> list:
    """The run of emitter items (lists) of ``items`` that starts at ``at``."""
    end = at
    while end < len(items) and isinstance(items[end], list):
        end += 1
    return items[at:end]
