"""The scene programs: the builds of ``scene.vert``/``scene.frag`` (and
``scene_batched.geom``) a scene pass draws with, and the per-draw uniforms each one keeps.

Programs are specialised: a batch whose instances all use the same material variants is
drawn with a build of ``scene.frag`` whose slots are those variants as constants (the
other cases of each slot's switch compile away; llvmpipe would otherwise run every case
of every slot for every pixel), built once and cached; a batch of mixed variants uses the
build that switches per instance.  A level's batches get every build a view may need
(``prepare``: root and per-mirror views, each batched invocation count) after its first
frame, so a mirror first coming into view compiles nothing.

Apart from the pass (``engine/render/scene_pass.py``, which draws with them) because
choosing, building and wiring a build (defines, units, blocks, a hot reload's rebuild) is
one job, done once a build, and drawing the views is another, done every frame: the pass
asks for a batch's draw record (``ScenePrograms.record``) once and then only draws."""
from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING

import moderngl

from components.rendering import ALBEDO_UV_BIT
from engine.core.material_slots import SLOTS, ReflectVariant
from engine.render.batched_mirrors import MAX_BATCHED_VIEWS
from engine.render.bindings import (
    ALBEDO_UNIT,
    CAMERA_BINDING,
    CAUSTIC_UNIT,
    CAUSTICS_BINDING,
    CLOUDS_BINDING,
    COOKIE_UNIT,
    EMISSIVE_MAP_UNIT,
    FOAM_BINDING,
    FOG_BINDING,
    IRRADIANCE_BINDING,
    IRRADIANCE_UNIT,
    LAMP_SEE_THROUGH_UNIT,
    LIGHTMAP_UNIT,
    LIGHTS_BINDING,
    METALLIC_ROUGHNESS_UNIT,
    MORPH_UNIT,
    NODE_UNIT,
    NORMAL_UNIT,
    OBJECT_MOTION_UNIT,
    OCCLUSION_UNIT,
    POINT_SHADOW_UNITS,
    POSE_BEFORE_UNIT,
    POSE_ROWS_UNIT,
    PROBE2_UNIT,
    PROBE_REST_UNIT,
    PROBE_UNIT,
    REFRACTION_COPY_UNIT,
    RIPPLE_UNIT,
    RIPPLES_BINDING,
    SCREEN_CONTACT_UNIT,
    SCREEN_OCCLUSION_UNIT,
    SEE_THROUGH_UNIT,
    SHADOW_ATLAS_UNIT,
    SHADOWS_BINDING,
    SKY_UNIT,
    SPOT_SHADOW_UNIT,
    SUN_DEPTH_UNIT,
    VIEWS_BINDING,
    VIRTUAL_LIGHTS_BINDING,
    VIRTUAL_SEE_THROUGH_UNIT,
    VIRTUAL_SHADOW_UNIT,
    assign_slots,
)
from engine.render.caustics import NO_CAUSTIC_WATERS
from engine.render.foam import MAX_FOAM_WATERS
from engine.render.gpu import Gpu
from engine.render.instances import blend_code, forget_reads
from engine.render.pose_rows import skinning_defines
from engine.render.screen_refraction import refuse_screen_refraction, sampler_count
from engine.render.shadows import ShadowMaps
from engine.render.unlit_mirrors import may_be_unlit

if TYPE_CHECKING:
    from engine.render.instances import InstanceBatch

# The uniforms a draw may write, in the order a draw record keeps them.
PER_DRAW_UNIFORMS = ("sky_face_size", "drawn_instances", "caustic_waters", "has_albedo_map", "transparent",
                     "probe_face_size", "probe_position", "probe_box_min", "probe_box_max",
                     "probe2_face_size", "probe2_position", "probe2_box_min", "probe2_box_max",
                     "probe_rest_face_size", "probe_rest_position", "probe_rest_box_min", "probe_rest_box_max",
                     "checker_cells", "checker_even", "checker_odd", "alpha_cutoff",
                     "occlusion_strength", "clearcoat", "dielectric_f0", "sheen", "dispersion",
                     "anisotropy", "iridescence", "pose_row", "morph_targets", "diffuse_transmission",
                     "parallax_depth", "lightmap_intensity", "subsurface")
PER_PASS_UNIFORMS = 3  # the first three change with the pass (or the caustic waters a batch is under); the rest
# with the batch (a view's node index is its Camera block's: nothing is written per view)
NO_PROBE_LOOKUP = ((0.0, 0.0, 0.0, 0.0),) * 3  # a probe's lookup uniforms where the sky stands in for it
NO_CHECKER = (0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
NO_CLEARCOAT = (0.0, 0.0)  # the coat uniform of a batch without one (its builds do not read it)
NO_SHEEN = (0.0, 0.0, 0.0, 0.0)  # the sheen uniform of a batch without one (likewise)
NO_DIFFUSE_TRANSMISSION = (0.0, 0.0, 0.0, 0.0)  # the diffuse transmission's of a batch without one (likewise)
NO_SUBSURFACE = (0.0, 0.0, 0.0, 0.0)  # the subsurface scattering's of a batch without one (likewise)
NO_ANISOTROPY = (0.0, 0.0)  # the anisotropy uniform of a batch without one (likewise)
NO_IRIDESCENCE = (0.0, 1.0, 0.0)  # the thin film's uniform of a batch without one (likewise)
# a batch's build with none of _material_build's
NO_MATERIAL_MAPS = (False, False, False, "", False, False, False, False, False, False, False, False, False, False, 0,
                    False, False, False, False)



# The scene builds' texture units by sampler and uniform blocks by binding (a build reads some).
_SCENE_UNITS = {"albedo_map": ALBEDO_UNIT, "sky_map": SKY_UNIT, "node_map": NODE_UNIT,
                "probe_map": PROBE_UNIT, "probe2_map": PROBE2_UNIT, "probe_rest_map": PROBE_REST_UNIT,
                "normal_map": NORMAL_UNIT, "emissive_map": EMISSIVE_MAP_UNIT,
                "metallic_roughness_map": METALLIC_ROUGHNESS_UNIT, "shadow_atlas": SHADOW_ATLAS_UNIT,
                "point_shadow0": POINT_SHADOW_UNITS[0],
                "point_shadow1": POINT_SHADOW_UNITS[1], "irradiance_table": IRRADIANCE_UNIT,
                "virtual_atlas": VIRTUAL_SHADOW_UNIT, "spot_atlas": SPOT_SHADOW_UNIT, "occlusion_map": OCCLUSION_UNIT,
                "lightmap": LIGHTMAP_UNIT, "screen_occlusion": SCREEN_OCCLUSION_UNIT,
                "screen_contact_lamps": SCREEN_CONTACT_UNIT, "spot_cookies": COOKIE_UNIT,
                "shadow_depths": SUN_DEPTH_UNIT, "pose_rows": POSE_ROWS_UNIT, "morph_offsets": MORPH_UNIT,
                "object_motion": OBJECT_MOTION_UNIT, "pose_before": POSE_BEFORE_UNIT,
                "refraction_copy": REFRACTION_COPY_UNIT, "caustic_maps": CAUSTIC_UNIT, "ripple_atlas": RIPPLE_UNIT,
                "see_through_atlas": SEE_THROUGH_UNIT, "lamp_see_through_atlas": LAMP_SEE_THROUGH_UNIT,
                "virtual_see_through_atlas": VIRTUAL_SEE_THROUGH_UNIT}
_SCENE_BLOCKS = {"Camera": CAMERA_BINDING, "Views": VIEWS_BINDING, "Lights": LIGHTS_BINDING,
                 "Shadows": SHADOWS_BINDING, "Fog": FOG_BINDING, "VirtualLights": VIRTUAL_LIGHTS_BINDING,
                 "Irradiance": IRRADIANCE_BINDING, "Clouds": CLOUDS_BINDING,
                 "Caustics": CAUSTICS_BINDING, "Foam": FOAM_BINDING, "Ripples": RIPPLES_BINDING}

# The reflect slots whose reflection is the sky's or a probe's, which screen reflections
# replace: none (the material's environment reflection, scene.frag environment_specular) and a
# Reflective's "skybox" and "cube"; not a mirror's or a portal's (their views are exact).
_REFLECTING = (int(ReflectVariant.NONE), int(ReflectVariant.SKYBOX), int(ReflectVariant.CUBE))


def reflects_environment(batch: InstanceBatch) -> bool:
    """Whether ``batch`` may reflect the sky or a probe (its instances' reflect slot, or
    variants that differ between them): what screen reflections put the screen's in place of,
    the batches the main view draws with their ``reflected`` builds."""
    variants = batch.variants
    return variants is None or variants[2] in _REFLECTING

class ScenePrograms:
    """The scene programs by what picks a build, each one's per-draw uniforms (``uniforms``)
    and the values last written to them (``written``, ``last_own``), made again after a
    shader hot reload (``forget``).  The shadows stage says which shadow lookups and how
    many virtual lights a build compiles (``shadows``)."""

    def __init__(self, renderer: Gpu, shadows: ShadowMaps) -> None:
        self.renderer = renderer
        self.shadows = shadows
        # Scene programs by (1 for every view of a level in one draw, the geometry shader's
        # invocations for a layered capture, else 0; "" / "culled" / "naive" for a layered
        # capture, the batch's variants or None, whether it reads a normal map, draws
        # the analytic checker, reads an emissive map, a metallic-roughness map, ...: ``program``).
        self.built: dict[tuple, moderngl.Program] = {}
        self.uniforms: dict[int, tuple] = {}  # program -> its PER_DRAW_UNIFORMS (None where dropped)
        self.reloads_seen = 0  # ShaderLibrary.reloads when the caches here were made
        # program -> the values last written to its per-draw uniforms: a program keeps its
        # uniforms' values between passes and frames (GL program state), and only
        # ScenePass._draw_batches writes these, so a value is written only when it changes.
        self.written: dict[int, list] = {}
        self.last_own: dict[int, tuple] = {}  # program -> the batch values it last drew with
        # The ``screen`` builds drawn so far, each with whether masked ("" and, once a camera
        # has ambient occlusion, "occluded" and "depth_normals", masked too where reflection
        # levels are occluded, or screen reflections, "reflected"): ``prepare`` builds a
        # batch's in each of them.
        self.screens: set[tuple[str, bool]] = {("", False)}

    def program(self, variants: tuple[int, int, int] | None = None, views: int = 0,
                layered: str = "", normal_mapped: bool = False, checker: bool = False,
                material: tuple = NO_MATERIAL_MAPS,
                probe_blend: bool = False,
                ambient_probes: bool = False, probe_rest: bool = False, unlit: bool = False,
                masked: bool = False, screen: str = "", caustic: bool = False) -> moderngl.Program:
        """The scene program for a batch of ``variants`` (None: mixed, switched per
        instance): plain (``views`` 0: the one view of the Camera block), a reflection
        level's views in one draw (``views`` > 0: ``INSTANCED_VIEWS``, each instance drawn
        once a view, any count of views) or a one-pass cube-map capture (``layered``
        "culled" or "naive": ``views`` faces, the geometry shader's invocations), with or without a normal map
        (a build of its own: llvmpipe would run the map's derivatives and fetch for every
        pixel behind a uniform branch), and with or without the analytic checker (``CHECKER``:
        a generated checker texture drawn from its cells, filtered by the pixel's footprint,
        instead of sampled), and with or without each of the material maps ``material``
        names (emissive, metallic-roughness, occlusion: ``EMISSIVE_MAP``,
        ``METALLIC_ROUGHNESS_MAP`` and ``OCCLUSION_MAP`` builds, or ``OCCLUSION_PACKED``: the
        occlusion in the metallic-roughness map's red, glTF's packed ORM image,
        shaders/include/material_maps.glsl; a batch without them samples nothing for them)
        and whether it is a cutout (``ALPHA_CUTOFF``: it discards where its alpha falls
        below its ``alpha_cutoff`` uniform; only its builds may discard, so every other keeps
        its early depth test on llvmpipe) and its mesh has vertex colours (``VERTEX_COLOR``),
        blending probes (``probe_blend``: ``PROBE_BLEND``) with a probe instead of the sky
        taking the rest (``probe_rest``: ``PROBE_REST``, a curved object's own), or unlit
        (``unlit``: ``UNLIT_SURFACE``, a mirror batch ``shading_replaced`` names), and
        masked or not (``masked``: ``MASKED``, a reflection level's: only the pixels its node
        image gives the view; a root view's build has no node-image fetch and no discard, so
        llvmpipe neither runs the fetch for every pixel nor defers the depth write past the
        shader, as a discarding program makes it), built once.  After a shader hot
        reload the set-up is done again and the batches' vertex arrays are made again (the
        relinked program may read uniforms, samplers and vertex inputs the first build
        dropped).

        ``caustic``: with the frame's ``CAUSTICS`` (a batch reaching into the body of the water
        that gathers the sun: ``engine/render/caustics.py``; the others are built without, as
        llvmpipe runs a build's caustics on every pixel).

        ``screen``: "" the plain builds; "occluded" (a root view with ambient occlusion)
        ``SCREEN_OCCLUSION``: it multiplies the screen's occlusion image
        (``Gpu.screen_occlusion``) into its light from all round (an unlit mirror, which
        shades nothing, keeps its plain build); "reflected" (a root view with screen
        reflections) ``SCREEN_REFLECTION``: it writes the reflection's weight, what the sky
        or probe added and the normal for the composite (``ScreenReflectionPass``), and
        "occluded reflected" both; "refracted" (a view tree's view, after its copy)
        ``SCREEN_REFRACTION``: its refraction reads what the view drew behind it
        (``engine/render/screen_refraction.py``); "depth_normals" ``DEPTH_NORMALS``: depth and
        the surface's normal only (occlusion's first pass), one build a cutout or not, whatever
        else the batch has ("depth_normals half": a reflection level's at half its size, masked
        by every second pixel of its node image, ``NODE_STEP``)."""
        if self.renderer.shaders.reloads != self.reloads_seen:
            self.forget()
        virtual = self.shadows.virtual_shining  # the shadows stage set how many shine
        shadowing = self.shadows.program_defines  # the lookups a program compiles (ShadowMaps.upload's)
        fogging = self.renderer.fog.defines       # FOG while the active camera's fog has a density
        cookies = self.renderer.spot_cookies.defines  # SPOT_COOKIES while a kept spot light has a cookie
        if self.renderer.sphere_lights:  # SPHERE_LIGHTS while a kept point light has a radius
            cookies = (*cookies, ("SPHERE_LIGHTS", "1"))
        if self.renderer.rect_lights:  # RECT_LIGHTS while a kept point light (or its image) is a rectangle
            cookies = (*cookies, ("RECT_LIGHTS", "1"))
        cookies = (*cookies, *self.renderer.clouds.shadow_defines)  # CLOUD_SHADOWS while a CloudLayer shades
        if caustic:  # CAUSTICS for a batch reaching into the body of a water that gathers the sun
            # (and RIPPLES while a water's rings are alive: they gather the light too)
            cookies = (*cookies, *self.renderer.caustics.defines, *self.renderer.ripples.caustic_defines)
        if not layered:  # OBJECT_MOTION while the camera's motion blur streaks moving things (not in probes)
            cookies = (*cookies, *self.renderer.object_motion.defines)
        if "occluded" in screen.split():  # CONTACT_LAMPS while a lamp has contact shadows (its image read)
            cookies = (*cookies, *self.renderer.contact_lamp_defines)
        if screen.startswith("depth_normals"):  # nothing shaded: only a cutout's discard picks the build
            variants, normal_mapped, checker, probe_blend, ambient_probes, probe_rest = None, False, False, False, \
                False, False
            material = (False, False, material[2], "", False, False, False, False, False, False, False, False,
                        material[12], material[13],  # (a posed mesh's depth is where its pose puts it)
                        material[14] & ALBEDO_UV_BIT if material[2] else 0,  # (a cutout's holes)
                        False, False, False, False)
            virtual, unlit, shadowing, fogging, cookies = False, False, (), (), ()  # (masked: a level's)
        elif unlit:  # shades nothing: no occlusion read (it still writes "nothing reflected")
            screen = "reflected" if "reflected" in screen else ""
        self.screens.add((screen, masked))
        # The light from all round the table gives (Gpu.ambient_defines: boxes, a volume), in a
        # pass that draws with it (IrradianceTable.bind; never a capture's).
        ambient = self.renderer.ambient_defines if ambient_probes else ()
        last = self.renderer.discards_last  # DISCARDS_LAST: a decal's clear part dropped after the derivatives
        key = (views if layered else min(views, 1), layered, variants, normal_mapped, checker, material, probe_blend,
               virtual, ambient, probe_rest, unlit, masked, screen, last, shadowing, fogging, cookies)
        program = self.built.get(key)
        if program is None and "refracted" in screen.split():
            # The march reads the copy (and, unmasked, the node image): one or two samplers
            # more than the build without.  Where that passes the fragment stage's units (a
            # 16-unit driver's fullest builds), the build without serves, and a warning says so.
            plain = self.program(variants, views, layered, normal_mapped, checker, material, probe_blend,
                                 ambient_probes, probe_rest, unlit, masked,
                                 " ".join(word for word in screen.split() if word != "refracted"), caustic)
            needed = sampler_count(plain) + (1 if masked else 2)
            if needed > self.renderer.caps.max_texture_image_units:
                refuse_screen_refraction(needed, self.renderer.caps.max_texture_image_units)
                program = self.built[key] = plain
        if program is None:
            defines = {}
            if variants is not None:
                defines = {f"FIXED_{slot}": f"{value}u" for slot, value in zip(SLOTS, variants, strict=True)}
            if normal_mapped:
                defines["NORMAL_MAP"] = "1"
            if checker:
                defines["CHECKER"] = "1"
            if material[0]:
                defines["EMISSIVE_MAP"] = "1"
            if material[1]:
                defines["METALLIC_ROUGHNESS_MAP"] = "1"
            if material[2]:
                defines["ALPHA_CUTOFF"] = "1"
            if material[3]:  # its own occlusion map, or (packed) the metallic-roughness map's red
                defines["OCCLUSION_PACKED" if material[3] == "packed" else "OCCLUSION_MAP"] = "1"
            if material[5]:  # its environment reflection reads the probes it samples (scene.frag)
                defines["ENVIRONMENT_PROBE"] = "1"
            if material[4]:  # its mesh's colour a vertex (Mesh.colors)
                defines["VERTEX_COLOR"] = "1"
            if material[6]:  # a clear coat over it (Material.clearcoat: scene.frag's coat layer)
                defines["CLEARCOAT"] = "1"
            if material[7]:  # its colour as it is, lit by nothing (Material.unlit)
                defines["UNLIT_MATERIAL"] = "1"
            if material[8]:  # a sheen over it (Material.sheen_color: scene.frag's sheen layer)
                defines["SHEEN"] = "1"
            if material[9]:  # each colour refracted by its own index (Refractive.dispersion)
                defines["DISPERSION"] = "1"
            if material[10]:  # highlights stretched along a direction (Material.anisotropy)
                defines["ANISOTROPY"] = "1"
            if material[11]:  # a thin film's colours over it (Material.iridescence)
                defines["IRIDESCENCE"] = "1"
            # its mesh bent by its joints (a Skin: shaders/include/pose.glsl), blended as its skinning says
            defines.update(skinning_defines(material[12]))
            if material[13]:  # its mesh's morph targets weighed in (a Morph: shaders/include/pose.glsl)
                defines["MORPHED"] = "1"
            if material[14]:  # maps that read the mesh's second UV set (shaders/include/uv_sets.glsl)
                defines["SECOND_UV_MAPS"] = str(material[14])
            if material[15]:  # light from behind let through (Material.diffuse_transmission: scene.frag)
                defines["DIFFUSE_TRANSMISSION"] = "1"
            if material[16]:  # the normal map's heights marched (Material.parallax_depth: parallax.glsl)
                defines["PARALLAX"] = "1"
            if material[17]:  # its light from all round baked (Material.lightmap: material_maps.glsl)
                defines["LIGHTMAP"] = "1"
            if material[18]:  # light scattered under its surface (Material.subsurface: subsurface.glsl)
                defines["SUBSURFACE"] = "1"
            if last:
                defines["DISCARDS_LAST"] = "1"
            if probe_blend:  # two probes and the sky by the instances' weights (shaders/include/probe.glsl)
                defines["PROBE_BLEND"] = "1"
                if probe_rest:  # a probe, not the sky, takes what the weights leave
                    defines["PROBE_REST"] = "1"
            if virtual:  # light through mirrors and portals (shaders/include/virtual_lights.glsl)
                defines["VIRTUAL_LIGHTS"] = "1"
            # Diffuse light from the probes' boxes (AMBIENT_PROBES) and an irradiance volume
            # (IRRADIANCE_VOLUME) too (shaders/include/ambient.glsl).
            defines.update(ambient)
            if unlit:  # depth and ids only: the composites paint every pixel over (shading_replaced)
                defines["UNLIT_SURFACE"] = "1"
            if masked:  # the claimed pixels only (a reflection level's views)
                defines["MASKED"] = "1"
            if screen.startswith("depth_normals"):
                defines["DEPTH_NORMALS"] = "1"
                if screen == "depth_normals half":  # a level's at half its size: its node image's every 2nd pixel
                    defines["NODE_STEP"] = "2"
            else:
                words = screen.split()
                if "occluded" in words:  # the screen's ambient occlusion (a root view's)
                    defines["SCREEN_OCCLUSION"] = "1"
                if "reflected" in words:  # what the screen reflections' composite reads (a root view's)
                    defines["SCREEN_REFLECTION"] = "1"
                if "refracted" in words:  # what the view drew behind, marched (engine/render/screen_refraction.py)
                    defines["SCREEN_REFRACTION"] = "1"
                if "foam" in words:  # a water's shore foam over its level (engine/render/foam.py)
                    defines["FOAM"] = "1"
                    defines["MAX_FOAM_WATERS"] = str(MAX_FOAM_WATERS)
            defines.update(shadowing)
            defines.update(fogging)
            defines.update(cookies)
            geometry = None
            if views:  # scene.frag reads the view's node and eye from the stage before
                defines.update({"BATCHED_VIEWS": "1", "MAX_LEVEL_VIEWS": str(MAX_BATCHED_VIEWS)})
            if views and not layered:  # the vertex stage takes its view from the instance (scene.vert)
                defines["INSTANCED_VIEWS"] = "1"
            elif layered:  # a face an invocation of the geometry shader, which culls by face
                geometry = "scene_layered.geom"
                defines["GS_INVOCATIONS"] = str(views)
                if layered == "naive":
                    defines["NO_FACE_CULLING"] = "1"
            program = self.renderer.shaders.program("scene.vert", "scene.frag", geometry, defines=defines)
            assign_slots(program, _SCENE_UNITS, _SCENE_BLOCKS)   # (a batched build reads Views, not Camera)
            self.built[key] = program
            self.uniforms[program.glo] = tuple(program.get(name, None) for name in PER_DRAW_UNIFORMS)
        return program

    def forget(self) -> None:
        """After a shader hot reload: every program set-up, written value, batch vertex array
        and draw record is made again (a relinked program may read uniforms, samplers and
        vertex inputs the first build dropped)."""
        self.built.clear()
        self.uniforms.clear()
        self.written.clear()  # a relinked program's uniforms start again from the defaults
        self.last_own.clear()
        for batch in self.renderer.batches.values():
            batch.drop_vertex_arrays()  # made again for the relinked programs' inputs
        forget_reads()  # (what each program reads: a relinked one may read more)
        self.reloads_seen = self.renderer.shaders.reloads

    def prepare(self, batches: Iterable[InstanceBatch], reflections: bool, ambient_boxes: bool,
                levels: bool = False) -> int:
        """Build the programs and vertex arrays ``batches`` will be drawn with: one view a draw
        (root and per-mirror views) and, with ``reflections``, the batched path's
        (``INSTANCED_VIEWS``; its vertex arrays by view count are made as levels ask); each without the
        ``AMBIENT_PROBES`` lookups and, given ``ambient_boxes`` (``IrradianceTable.has_boxes``),
        with them.
        A batch of mirrors gets its ``UNLIT_SURFACE`` builds too, and with ``levels`` (the
        world has reflection levels) the ``MASKED`` builds (a level whose claims overlap, or
        any drawn by predicted visibility, draws masked; one whose claims lie apart, exactly
        known, unmasked: ``view_tree._APART``).  Returns how many programs
        were built (0 when all were there)."""
        before = len(self.built)
        counts = (0, 1) if reflections else (0,)
        ambient = (False, True) if ambient_boxes else (False,)  # captures: False
        caustics = self.renderer.caustics
        for batch in batches:
            unlit = (False, True) if may_be_unlit(batch) else (False,)
            caustic = bool(caustics.waters) and caustics.slots_of(
                batch.box, batch.caustic_waters, batch.skinned or batch.morphed) is not NO_CAUSTIC_WATERS
            for views in counts:
                for masked in (False, True) if levels or reflections else (False,):
                    for probes in ambient:
                        for dark in unlit:
                            batch.vao(self.program(batch.variants, views, "", batch.normal_map is not None,
                                                   batch.checker is not None, _material_build(batch),
                                                   batch.probe_blend, probes, bool(batch.rest_probe), dark, masked,
                                                   caustic=caustic))
            for screen, masked in self.screens - {("", False), ("", True)}:  # one view a draw
                if "reflected" in screen.split() and not reflects_environment(batch):
                    continue  # (drawn with the builds without: ScenePass._draw_reflecting)
                if "refracted" in screen.split() and not batch.refracts_screen:
                    continue  # (only a refracting batch is drawn after the copy: ScenePass.refract)
                foam = self.renderer.foam.entities
                if "foam" in screen.split() and not any(entity in batch.row_of for entity in foam):
                    continue  # (only a foamy water's batch is drawn with it: ScenePass.draw_foam)
                for probes in ambient:
                    for dark in unlit if "reflected" in screen.split() else (False,):  # (unlit: its own build)
                        batch.vao(self.program(batch.variants, 0, "", batch.normal_map is not None,
                                               batch.checker is not None, _material_build(batch), batch.probe_blend,
                                               probes, bool(batch.rest_probe), dark, masked, screen, caustic))
        return len(self.built) - before

    def record(self, batch: InstanceBatch, kind: tuple[int, str, bool, bool, bool, str], stamp: tuple,
               variants: tuple[int, int, int] | None, caustic: bool = False) -> tuple:
        """What ``batch`` draws with in passes of ``kind`` (views, layered, ambient
        probes, unlit, masked, screen), with ``caustic`` (the batch reaches into the caustic water's
        body: its CAUSTICS build): (stamp, (variants, caustic), program name, vertex array, per-draw uniforms, the
        program's written values, the (unit, texture) pairs to bind, its own uniform values
        or None where probes give them per draw, its mesh's vertex count, the program (an
        instanced-views draw asks the batch for its array by view count, ``InstanceBatch.vao``),
        whether the sky is bound at the probe's unit for it)."""
        views, layered, ambient, unlit, masked, screen = kind
        program = self.program(variants, views, layered, batch.normal_map is not None,
                               batch.checker is not None, _material_build(batch), batch.probe_blend,
                               ambient, bool(batch.rest_probe), unlit, masked, screen, caustic)
        glo = program.glo
        values = self.written.get(glo)
        if values is None:
            values = self.written[glo] = [None] * len(PER_DRAW_UNIFORMS)
        # A batch with no albedo map binds the blank one: the program's sampler is there all
        # the same (``Gpu.blank_color``).
        albedo = batch.texture if batch.texture is not None else self.renderer.blank_color
        textures = tuple((unit, texture) for unit, texture in (
            (ALBEDO_UNIT, albedo), (NORMAL_UNIT, batch.normal_map), (EMISSIVE_MAP_UNIT, batch.emissive_map),
            (METALLIC_ROUGHNESS_UNIT, batch.metallic_roughness_map), (OCCLUSION_UNIT, batch.occlusion_map),
            (LIGHTMAP_UNIT, batch.lightmap),
            (POSE_ROWS_UNIT, self.renderer.pose_rows.texture if batch.skinned or batch.morphed else None),
            (MORPH_UNIT, batch.mesh.morphs if batch.morphed else None),
            (OBJECT_MOTION_UNIT, self.renderer.object_motion.texture if not layered else None),
            (POSE_BEFORE_UNIT, self.renderer.pose_rows.before if (batch.skinned or batch.morphed) and not layered
             else None))
            if texture is not None)
        own = None
        if not batch.probe and not batch.probe_blend and not batch.rest_probe:
            own = (batch.texture is not None, blend_code(batch), 0, *NO_PROBE_LOOKUP, 0, *NO_PROBE_LOOKUP,
                   0, *NO_PROBE_LOOKUP, *(batch.checker or NO_CHECKER), batch.alpha_cutoff or 0.0,
                   batch.occlusion_strength, batch.clearcoat or NO_CLEARCOAT, batch.dielectric_f0,
                   batch.sheen or NO_SHEEN, batch.dispersion, batch.anisotropy or NO_ANISOTROPY,
                   batch.iridescence or NO_IRIDESCENCE, batch.pose_row, batch.mesh.morph_count if batch.morphed else 0,
                   batch.diffuse_transmission or NO_DIFFUSE_TRANSMISSION, batch.parallax_depth,
                   batch.lightmap_intensity, batch.subsurface or NO_SUBSURFACE)
        # A build that declares the probe's sampler, drawing a batch with no probe: the sky
        # there (GL reads an active sampler's unit whether or not a branch samples it).
        sky_at_probe = own is not None and "probe_map" in program
        return (stamp, (variants, caustic), glo, batch.vao(program), self.uniforms[glo], values, textures, own,
                batch.mesh.index_count, program, sky_at_probe)

    def release(self) -> None:
        """Forget the programs (the shader library owns and releases them)."""
        self.built.clear()


def _material_build(batch: InstanceBatch) -> tuple:
    """What of a batch's material picks its build: whether it samples an emissive and a
    metallic-roughness map, whether it is a cutout, where its occlusion is read ("map": a
    map of its own, "packed": the metallic-roughness map's red, "": none), whether its
    mesh has a colour a vertex, whether it samples a probe (its environment reflection
    reads the probe, ``ENVIRONMENT_PROBE``: only such batches pay for the lookup), and
    whether it is clear-coated (``CLEARCOAT``), whether it is unlit (``UNLIT_MATERIAL``) and
    whether it has a sheen (``SHEEN``) and whether its refraction splits the colours
    (``DISPERSION``), whether its highlights are anisotropic (``ANISOTROPY``), whether a
    thin film colours its reflections (``IRIDESCENCE``), how a Skin bends its mesh (its
    skinning: ``SKINNED``, ``DUAL_QUATERNION_SKINNING``; "": none), whether it wears a Morph
    (``MORPHED``), which of its maps read the mesh's second UV set (``SECOND_UV_MAPS``, their
    bits; 0: none) and whether it lets light through from behind (``DIFFUSE_TRANSMISSION``),
    whether its normal map's heights are marched (``PARALLAX``), whether a lightmap gives its
    light from all round (``LIGHTMAP``) and whether light scatters under its surface
    (``SUBSURFACE``)."""
    occlusion = "packed" if batch.occlusion_packed else "map" if batch.occlusion_map is not None else ""
    return (batch.emissive_map is not None, batch.metallic_roughness_map is not None, batch.alpha_cutoff is not None,
            occlusion, batch.mesh.colors is not None, batch.probe != 0, batch.clearcoat is not None, batch.unlit,
            batch.sheen is not None, batch.dispersion > 0.0, batch.anisotropy is not None,
            batch.iridescence is not None, batch.skinned, batch.morphed, batch.second_uv_maps,
            batch.diffuse_transmission is not None, batch.parallax_depth > 0.0, batch.lightmap is not None,
            batch.subsurface is not None)

