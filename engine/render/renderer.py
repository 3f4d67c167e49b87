"""GL resources of one world's rendering.

The systems decide what is drawn; the renderer owns what it is drawn with: the ``Gpu``
every pass draws with (``engine/render/gpu.py``: uniform blocks, the sky cube map, the
instance batches and their draw order), the shared meshes and textures (reference counted,
released when the last user goes), the main view tree's render targets, and the passes:
the scene pass (``engine/render/scene_pass.py``, through which every view is drawn),
shadows, irradiance, probes, the path self-check, present and screen text.  It stands
above every pass: a pass is given the ``Gpu`` and the passes it draws through, never the
renderer.
"""
from __future__ import annotations

import math
from collections.abc import Iterable

import moderngl
import numpy as np

from components.post import MAX_EXPOSURE_EV
from engine.assets.mesh import Mesh
from engine.assets.texture_data import TextureData
from engine.core.budget import ViewBudget
from engine.core.color import srgb_to_linear
from engine.core.errors import GLLimitError
from engine.render.bindings import LIGHTMAP_OCCLUSION_SAMPLERS
from engine.render.cutout_mips import FILTERED_TEXELS, alpha_share, keep_alpha_share
from engine.render.dynamic_resolution import GpuFrameTimer, ResolutionController
from engine.render.gl_context import GLCapabilities
from engine.render.gpu import BACKGROUND, Gpu, Shared
from engine.render.instances import MAX_CHANGED_PARTS, MORPH_TEXTURE_WIDTH, BatchKey, GpuMesh, InstanceBatch
from engine.render.irradiance import IrradianceTable
from engine.render.level_copies import LevelCopies
from engine.render.monitors import MonitorPictures
from engine.render.path_checks import PathChecks
from engine.render.present import ANTIALIAS_MODES, CameraPost, PresentPass
from engine.render.probes import ProbeCaptures
from engine.render.resample import check_render_scale, check_sharpness
from engine.render.scene_pass import ScenePass
from engine.render.screen_occlusion import ScreenOcclusion
from engine.render.screen_reflections import ScreenReflectionPass
from engine.render.shadows import ShadowMaps
from engine.render.sky import SkyModel, flat_cube, upload_cube
from engine.render.sky_bake import SkyBake
from engine.render.sky_view import SkyView
from engine.render.targets import SEEN_CHANNELS, SEEN_MOVING_CHANNELS, LevelStack, RenderTargets
from engine.render.text import TextPass
from engine.render.volumetric_fog import VolumetricFogPass
from engine.resources import PortalCrossing

_MAX_EXPOSURE = 2.0 ** MAX_EXPOSURE_EV


def checker_look(texture: TextureData | None) -> tuple[float, tuple, tuple] | None:
    """How the scene pass draws a generated checker (``checker_texture``) analytically: its
    cells across the UV square and the linear colours of the cells whose integer coordinates
    sum even and odd (the image's top-left cell, colour ``a``, is cell (0, squares - 1) in
    GL's bottom-up UVs).  Drawn from its cells, filtered by each pixel's footprint, a checker
    floor is crisp near the camera and grey far off, where a magnified texture of 16 texels
    a cell was blurred with beaded edges.  None for any other texture, and for a checker
    whose size is not a whole number of cells (its last cells are narrower: sampled)."""
    source = getattr(texture, "source", None)
    if not isinstance(source, dict) or "checker" not in source:
        return None
    size, squares = source["checker"]
    if size % squares:
        return None
    a = _srgb_bytes_to_linear(source.get("a", (230, 230, 230)))
    b = _srgb_bytes_to_linear(source.get("b", (40, 40, 48)))
    even, odd = (b, a) if squares % 2 == 0 else (a, b)
    return float(squares), even, odd


def _srgb_bytes_to_linear(rgb) -> tuple[float, ...]:
    """Bytes of an sRGB colour as the GL's sRGB texture decode gives them."""
    return tuple(float(c) for c in srgb_to_linear(np.asarray(rgb, np.float64) / 255.0))


class Renderer(Gpu):
    """A world's rendering: the ``Gpu`` every pass draws with; the passes, each made after
    those it draws through and given them (irradiance and shadows, then the scene pass,
    the probe captures, the path self-check); the main view tree's targets, present and
    screen text; and the shared meshes, textures and batches, made and released by
    reference count."""

    def __init__(self, ctx: moderngl.Context, caps: GLCapabilities) -> None:
        super().__init__(ctx, caps)
        self._meshes: dict[int, Shared] = {}  # GpuMesh by Mesh.id, shared by reference count
        # Counts uploads that wrote instance rows, and batches made or dropped: the shadows
        # stage draws a map again when it moves on (a caster moved, came, went or changed).
        self.casters_version = 0
        self._dropped_changes: tuple[np.ndarray, np.ndarray] | None = None  # boxes of batches dropped
        self._level_union: tuple[list, tuple[np.ndarray, np.ndarray] | None] | None = None  # level_bounds' last
        self.present_pass = PresentPass(ctx, self.shaders, caps.software, self.object_motion)
        self.text_pass: TextPass | None = None  # made when text is first drawn (its atlas costs a few ms)
        self.screen_quads = np.zeros((0, 12), np.float32)  # the last frame's screen text (a screenshot draws it again)
        self.screen_pictures: tuple[moderngl.Texture, ...] = ()   # ... and the pictures its panels show
        self.levels = LevelStack(ctx)   # the main view tree's: [0] the main view, then its reflection levels
        # Copies of the main view tree's levels while a still tree's end images settle (the
        # reflect stage's tree makes and lets go of them: StillTree.keep, level_copies.py).
        self.level_copies = LevelCopies(ctx)
        self._exposure = 1.0
        self._antialias = "fxaa"
        self._render_scale = 1.0
        self._sharpness = 0.0
        self.frame_timer = GpuFrameTimer(ctx)     # the GPU's time a frame (dynamic resolution)
        self.resolution = ResolutionController()  # the scale it chooses under a ViewBudget's frame_ms
        self._timed_readings = 0                  # the timer's readings the controller has seen
        self.irradiance = IrradianceTable(self)  # the probes' diffuse light (engine/render/irradiance.py)
        self.shadows = ShadowMaps(self)
        self.screen_reflections = ScreenReflectionPass(self)  # the camera's ScreenReflections
        self.volumetric_fog = VolumetricFogPass(self, self.shadows)  # the camera's VolumetricFog
        self.scene_pass = ScenePass(self, self.shadows, self.irradiance, self.screen_reflections,
                                    self.volumetric_fog)
        self.monitors = MonitorPictures(self, self.scene_pass)  # each Monitor's picture (engine/render/monitors.py)
        self.probes = ProbeCaptures(self, self.scene_pass, self.irradiance, self.monitors)
        self.occlusion = ScreenOcclusion(self, self.scene_pass)  # the camera's AmbientOcclusion
        self.sky_bake = SkyBake(self)  # a generated sky's cube map, drawn (engine/render/sky_bake.py)
        self.sky_view_pass = SkyView(self)   # an atmosphere's sky-view table (engine/render/sky_view.py)
        self.moon_view_pass = SkyView(self, tables_from=self.sky_view_pass)   # ... at its moon's elevation
        self.path_checks: PathChecks = PathChecks(self, self.probes)

    @property
    def exposure(self) -> float:
        """The linear scale of the image of a camera without a ``Tonemap`` (1: as drawn), in
        [0, 2**MAX_EXPOSURE_EV] (a Tonemap's +-24 EV reach), checked when set: a NaN or
        infinite one presented a black or white frame with no word."""
        return self._exposure

    @exposure.setter
    def exposure(self, value: float) -> None:
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)) \
                or not math.isfinite(value) or not 0.0 <= value <= _MAX_EXPOSURE:
            raise ValueError(f"Renderer.exposure must be a finite number in [0, 2**{MAX_EXPOSURE_EV:g}] (a linear "
                             f"scale: 1 shows the image as drawn), got {value!r}")
        self._exposure = float(value)

    @property
    def antialias(self) -> str:
        """Anti-aliasing of the presented frame: "fxaa" (the default: a filter on the final
        colour; ids, mirrors and portals untouched; ``engine/render/present.py``), "taa" (each
        frame drawn from a sub-pixel offset and blended into the frames before, reprojected:
        ``engine/render/temporal_aa.py``) or "off"."""
        return self._antialias

    @antialias.setter
    def antialias(self, mode: str) -> None:
        if mode not in ANTIALIAS_MODES:
            raise ValueError(f"antialias must be one of {', '.join(map(repr, ANTIALIAS_MODES))}, got {mode!r}")
        self._antialias = mode

    @property
    def render_scale(self) -> float:
        """The share of the output's width and height the main view (and every reflection
        level and post-processing image sized from it) is drawn at, in
        ``RENDER_SCALE_RANGE`` (default 1): the picture is brought up to the output's size
        by temporal AA's resolve, or else by a Catmull-Rom upscale after FXAA; above 1
        (supersampling) brought down by an area box filter in linear light
        (``engine/render/resample.py``)."""
        return self._render_scale

    @render_scale.setter
    def render_scale(self, value: float) -> None:
        self._render_scale = check_render_scale(value)

    def main_scale(self, budget: ViewBudget | None) -> float:
        """The render scale this frame's main view is drawn at: ``render_scale``, or under a
        budget's ``frame_ms`` the dynamic one between its ``min_render_scale`` and
        ``render_scale`` (``engine/render/dynamic_resolution.py``)."""
        if budget is None or budget.frame_ms is None:
            self.resolution.scale = self._render_scale
            return self._render_scale
        self.frame_timer.require()
        timer = self.frame_timer
        reading = timer.latest_ms if timer.readings != self._timed_readings else None
        self._timed_readings = timer.readings
        return self.resolution.update(reading, budget.frame_ms, min(budget.min_render_scale, self._render_scale),
                                      self._render_scale)

    @property
    def sharpness(self) -> float:
        """Contrast-adaptive sharpening of the presented picture, in [0, 1] (default 0: none;
        ``shaders/resample.frag``): gives back what an upscale or temporal AA softens."""
        return self._sharpness

    @sharpness.setter
    def sharpness(self, value: float) -> None:
        self._sharpness = check_sharpness(value)

    # --- shared resources ------------------------------------------------------------------
    def batch_for(self, mesh: Mesh, texture: TextureData | None, probe: int = 0,
                  transparent_entity: int = 0, normal_map: TextureData | None = None,
                  emissive_map: TextureData | None = None,
                  metallic_roughness_map: TextureData | None = None, second_probe: int = 0,
                  probe_blend: bool = False, rest_probe: int = 0,
                  mirrored: bool = False, alpha_cutoff: float | None = None,
                  occlusion_map: TextureData | None = None, occlusion_strength: float = 1.0,
                  lightmap: TextureData | None = None, lightmap_intensity: float = 1.0,
                  double_sided: bool = False, keeps_specular: bool = False,
                  clearcoat: tuple[float, float] | None = None, unlit: bool = False,
                  dielectric_f0: tuple[float, float, float] = (0.04, 0.04, 0.04),
                  sheen: tuple[float, float, float, float] | None = None,
                  dispersion: float = 0.0, anisotropy: tuple[float, float] | None = None,
                  iridescence: tuple[float, float, float] | None = None,
                  posed: tuple[int, str, bool] = (0, "", False), second_uv_maps: int = 0,
                  diffuse_transmission: tuple[float, float, float, float] | None = None,
                  decal: bool = False, decal_order: int = 0, parallax_depth: float = 0.0,
                  subsurface: tuple[float, float, float, float] | None = None,
                  refracts_screen: bool = False, caustic_waters: tuple[int, ...] = ()) -> InstanceBatch:
        """The batch of (mesh, albedo texture, normal map, emissive map, metallic-roughness
        map, the probe its instances sample (0: none), a cutout's cutoff, an occlusion map and
        its strength, double-sidedness).  A transparent entity gets a batch of its own
        (``transparent_entity``): transparent things are drawn one by one, farthest first.
        Textures are shared by every batch that uses them; a normal, metallic-roughness or
        occlusion map is uploaded linear (their texels are vectors and factors,
        not colours), so one image used both ways is two GPU textures."""
        # ``second_probe`` and ``probe_blend``: the instances blend two probes, or a probe and
        # the sky, by per-instance weights (probe_rules.probe_blend; the PROBE_BLEND build);
        # ``rest_probe``: a probe, not the sky, takes what the weights leave (PROBE_REST).
        # ``mirrored``: instances whose model matrix has a negative determinant, drawn with the
        # other winding (ScenePass), so they get batches of their own.  ``alpha_cutoff``: a
        # cutout's threshold (Material.alpha_cutoff): a batch of its own, its builds' uniform;
        # so is an occlusion map's strength.  ``double_sided``: drawn with face culling off.
        # ``keeps_specular``: a transparent entity's Material.blend "transparent".
        # ``clearcoat``: a clear-coated material's (clearcoat, clearcoat_roughness), its
        # CLEARCOAT build's uniform (None: none).  ``unlit``: Material.unlit (UNLIT_MATERIAL).
        # ``dielectric_f0``: 0.16 x Material.reflectance^2 x its specular_color, its draws' uniform.  ``sheen``: a
        # sheen's (red, green, blue, roughness), its SHEEN build's uniform (None: none).
        # ``dispersion``: a refraction's Refractive.dispersion, its DISPERSION build's (0: none).
        # ``anisotropy``: (Material.anisotropy, its direction in radians), ANISOTROPY's (None: none).
        # ``iridescence``: (Material.iridescence, the film's index, its nm), IRIDESCENCE's (None: none).
        # ``posed``: (entity, its Skin.skinning or "", morphed): a posed entity (a Skin bends its mesh, or it
        # wears a Morph) gets a batch of its own, drawn with the SKINNED and MORPHED builds, its
        # row of the pose texture their uniform (set by extract).  ``second_uv_maps``: the maps
        # that read the mesh's second UV set, as bits (components.rendering.second_uv_mask): its
        # SECOND_UV_MAPS builds.  ``diffuse_transmission``: (red, green, blue, share) of what a
        # thin surface lets through from behind, its DIFFUSE_TRANSMISSION build's uniform (None: none).
        # ``decal``: a decal's cut mesh (systems/decal_system.py), lying on the surfaces it was
        # cut from: its draws' depth is offset towards the eye (ScenePass), so it wins their tie;
        # ``decal_order``: its Decal.order (the transparent slot blends higher orders later).
        # ``parallax_depth``: Material.parallax_depth with a normal map, its PARALLAX build's (0: none).
        # ``lightmap``: Material.lightmap (sRGB, its LIGHTMAP build's) and ``lightmap_intensity`` its uniform.
        # ``subsurface``: (red, green, blue: each channel's profile distance in metres, share) of
        # the light scattered under its surface, its SUBSURFACE build's uniform (None: none).
        # ``refracts_screen``: a Refractive's ``screen``: a view tree's views draw it after their
        # copy of colour and depth (engine/render/screen_refraction.py), a batch of its own.
        # ``caustic_waters``: the waters that gather the sun whose bodies its rows reach into
        # (caustics.caustic_waters_of), a batch of its own: only its rows pay for the CAUSTICS builds.
        if second_uv_maps and mesh.second_uvs is None:
            raise GLLimitError(f"mesh {mesh.name!r}: Material.second_uv_maps reads a second UV set the mesh does "
                               "not have (Mesh.second_uvs)")
        key = BatchKey(mesh.id, id(texture) if texture is not None else 0,
                       (probe, second_probe, probe_blend, rest_probe), transparent_entity,
                       id(normal_map) if normal_map is not None else 0,
                       id(emissive_map) if emissive_map is not None else 0,
                       id(metallic_roughness_map) if metallic_roughness_map is not None else 0, mirrored,
                       alpha_cutoff, id(occlusion_map) if occlusion_map is not None else 0,
                       occlusion_strength if occlusion_map is not None else 1.0, double_sided,
                       bool(keeps_specular and transparent_entity), clearcoat, unlit, dielectric_f0, sheen,
                       dispersion, anisotropy, iridescence, posed, second_uv_maps, diffuse_transmission, decal,
                       decal_order, parallax_depth if normal_map is not None else 0.0,
                       id(lightmap) if lightmap is not None else 0,
                       lightmap_intensity if lightmap is not None else 1.0, subsurface, refracts_screen,
                       caustic_waters)
        batch = self.batches.get(key)
        if batch is None:
            for name, image in (("Material.texture", texture), ("Material.normal_map", normal_map),
                                ("Material.emissive_map", emissive_map),
                                ("Material.metallic_roughness_map", metallic_roughness_map),
                                ("Material.occlusion_map", occlusion_map), ("Material.lightmap", lightmap)):
                if image is not None:
                    self.check_texture(image, name)  # before anything is made: nothing half-built
            if lightmap is not None and occlusion_map is not None and occlusion_map is not metallic_roughness_map \
                    and self.caps.max_texture_image_units < LIGHTMAP_OCCLUSION_SAMPLERS:
                raise GLLimitError(f"mesh {mesh.name!r}: a Material with both a lightmap and an occlusion map needs "
                                   f"{LIGHTMAP_OCCLUSION_SAMPLERS} texture units in the fragment stage; this OpenGL "
                                   f"({self.caps.renderer}) has {self.caps.max_texture_image_units} "
                                   "(GL_MAX_TEXTURE_IMAGE_UNITS): bake the occlusion into the lightmap, or pack it "
                                   "in the metallic-roughness map's red (the same image for both)")
            rows = -(-len(mesh.positions) * mesh.morph_count * 2 // MORPH_TEXTURE_WIDTH)
            if rows > self.caps.max_texture_size:  # (its offsets' texture: GpuMesh.morphs)
                raise GLLimitError(f"mesh {mesh.name!r}: {len(mesh.positions)} vertices x {mesh.morph_count} morph "
                                   f"targets need a {MORPH_TEXTURE_WIDTH}x{rows} texture of offsets; this OpenGL "
                                   f"({self.caps.renderer}) takes {self.caps.max_texture_size} rows at most "
                                   "(GL_MAX_TEXTURE_SIZE): fewer targets or a lighter mesh")
            gpu_mesh = self._acquire(self._meshes, mesh.id, lambda: GpuMesh(self.ctx, mesh))
            gpu_texture = gpu_normal_map = None
            if texture is not None and alpha_cutoff is not None:  # its mips keep its coverage at the cutoff
                gpu_texture = self._acquire(self._textures, ("cutout", id(texture), alpha_cutoff),
                                            lambda: self._upload_cutout_texture(texture, alpha_cutoff))
            elif texture is not None:
                gpu_texture = self._acquire(self._textures, id(texture), lambda: self._upload_texture(texture))
            if normal_map is not None:
                gpu_normal_map = self._acquire(self._textures, ("normal", id(normal_map)),
                                               lambda: self._upload_texture(normal_map, linear=True))
            batch = self.batches[key] = InstanceBatch(self.ctx, gpu_mesh, gpu_texture, gpu_normal_map)
            if emissive_map is not None:  # sRGB, shared with the same image used as an albedo texture
                batch.emissive_map = self._acquire(self._textures, id(emissive_map),
                                                   lambda: self._upload_texture(emissive_map))
            if metallic_roughness_map is not None:  # linear, shared with the same image as a normal map
                batch.metallic_roughness_map = self._acquire(
                    self._textures, ("normal", id(metallic_roughness_map)),
                    lambda: self._upload_texture(metallic_roughness_map, linear=True))
            if occlusion_map is not None and occlusion_map is metallic_roughness_map:
                batch.occlusion_packed = True  # glTF's ORM: read from the metallic-roughness map's red
            elif occlusion_map is not None:  # linear, shared with the same image as a normal map
                batch.occlusion_map = self._acquire(self._textures, ("normal", id(occlusion_map)),
                                                    lambda: self._upload_texture(occlusion_map, linear=True))
            batch.occlusion_strength = key.occlusion_strength
            if lightmap is not None:  # sRGB, shared with the same image used as an albedo texture
                batch.lightmap = self._acquire(self._textures, id(lightmap), lambda: self._upload_texture(lightmap))
            batch.lightmap_intensity = key.lightmap_intensity
            batch.key = key
            batch.mirrored = mirrored
            batch.caustic_waters = caustic_waters
            batch.alpha_cutoff = alpha_cutoff
            batch.double_sided = double_sided
            batch.decal, batch.decal_order = decal, decal_order
            batch.probe = probe
            batch.second_probe, batch.probe_blend, batch.rest_probe = second_probe, probe_blend, rest_probe
            batch.checker = checker_look(texture)
            batch.transparent = bool(transparent_entity)
            batch.keeps_specular = key.keeps_specular
            batch.clearcoat = clearcoat
            batch.unlit = unlit
            batch.dielectric_f0 = dielectric_f0
            batch.sheen = sheen
            batch.dispersion = dispersion
            batch.refracts_screen = refracts_screen
            batch.anisotropy = anisotropy
            batch.iridescence = iridescence
            batch.skinned, batch.morphed = posed[1], posed[2]
            batch.second_uv_maps = second_uv_maps
            batch.diffuse_transmission = diffuse_transmission
            batch.parallax_depth = key.parallax_depth
            batch.subsurface = subsurface
            if sheen is not None:  # the sheen's albedo table, made once a sheen is drawn
                self.irradiance.write_sheen_albedo()
            if subsurface is not None:  # the scattered light's table, made once it is drawn
                self.irradiance.write_subsurface()
            self._order_stale = True
            self.needs_preparing = True
            self.note_scene_change()
        return batch

    def prepare_programs(self, reflections: bool, level_scale: float | None = None, levels: bool = False) -> int:
        """Build now what drawing the current batches will need, rather than when it is first
        drawn: each batch's scene program (and vertex array) for root and per-mirror views,
        with ``levels`` (the world has mirrors or portals) its builds for a reflection level
        drawn masked too (claims that overlap, or predicted visibility: a GPU's default), and,
        with ``reflections`` (the batched path may be taken too), its instanced-views builds
        (their vertex arrays, one a view count, made as levels ask), the level's view
        table and the reflection sampler.  With
        ``level_scale`` (the largest ``resolution_scale`` of the world's surfaces), the first
        reflection level's targets too, at the root's size times it (the size the view tree
        gives a level when that surface is in it).  A mirror coming into view for the first
        time then compiles and allocates nothing (three.js users see a hitch there,
        mrdoob/three.js#30568).  The composite, claim and reset programs are built when the
        view tree is made.  Returns the number of programs built."""
        self.needs_preparing = False
        # Every batch when what the builds depend on across batches changed (the batched
        # path's coming or going, the ambient probes' boxes), else only those not prepared as
        # they are now (made since, or drawn with other variants): a frame that makes one new
        # batch (a decal cut again, a level of detail switched) does not walk every other.
        everything = (reflections, levels, self.irradiance.has_boxes())
        whole = everything != self._prepared_for
        self._prepared_for = everything
        batches = [b for b in self.batches.values() if b.count and (whole or b.prepared_variants != b.variants)]
        built = self.scene_pass.prepare(batches, reflections, levels or reflections)
        if self.ripples.waters and self.caustics.waters and self.ripples.in_caustics:
            # The builds a rippling water's first drop would make: its caustics' with RIPPLES.
            with self.ripples.as_rippling():
                built += self.scene_pass.prepare([batch for batch in batches if batch.caustic_waters], reflections,
                                                 levels or reflections)
        for batch in batches:
            batch.prepared_variants = batch.variants
        if level_scale is not None and len(self.levels) and self.targets is not None:
            width, height = self.targets.size
            self.levels.get(1, (max(1, round(width * level_scale)), max(1, round(height * level_scale))))
        return built

    def drop_batch_if_empty(self, batch: InstanceBatch) -> None:
        if batch.count:
            return
        del self.batches[batch.key]
        self._order_stale = True
        self.note_scene_change()
        self._note_dropped(batch.take_changed_box())
        batch.release()
        key = batch.key
        self._release(self._meshes, key.mesh)
        if key.texture:
            self._release(self._textures, key.texture if key.alpha_cutoff is None
                          else ("cutout", key.texture, key.alpha_cutoff))
        if key.normal_map:
            self._release(self._textures, ("normal", key.normal_map))
        if key.emissive_map:
            self._release(self._textures, key.emissive_map)
        if key.metallic_roughness_map:
            self._release(self._textures, ("normal", key.metallic_roughness_map))
        if key.occlusion_map and key.occlusion_map != key.metallic_roughness_map:  # (packed: nothing of its own)
            self._release(self._textures, ("normal", key.occlusion_map))
        if key.lightmap:
            self._release(self._textures, key.lightmap)

    def _upload_cutout_texture(self, texture: TextureData, cutoff: float) -> moderngl.Texture:
        """A cutout's albedo texture whose mip levels keep level 0's coverage at ``cutoff``
        (``engine/render/cutout_mips.py``): the driver's mip chain, each level's alpha rescaled."""
        gl_texture = self._upload_texture(texture)
        alpha = texture.as_8_bits()[..., 3]
        target = alpha_share(alpha, cutoff, filtered=alpha.size <= FILTERED_TEXELS)
        width, height = gl_texture.size
        level = 1
        while max(width, height) > 1:
            width, height = max(1, width // 2), max(1, height // 2)
            texels = np.frombuffer(gl_texture.read(level=level), np.uint8).reshape(height, width, 4).copy()
            texels[..., 3] = keep_alpha_share(texels[..., 3], cutoff, target)
            gl_texture.write(texels.tobytes(), level=level)
            level += 1
        return gl_texture

    def set_sky_faces(self, faces: np.ndarray | None) -> None:
        """The world's sky: a Skybox's given ``faces`` (None: the flat background), sampled
        from the cube map by the sky pass too."""
        if faces is not None:
            self._check_sky_size("Skybox.faces", faces.shape[1])
        self._replace_sky(upload_cube(self.ctx, faces) if faces is not None else flat_cube(self.ctx, BACKGROUND),
                          None)

    def set_generated_sky(self, model: SkyModel, size: int) -> None:
        """The world's sky: a generated Skybox, drawn per pixel from ``model`` by the sky pass
        and into a cube map of ``size`` texels a face for what samples it (``SkyBake``)."""
        self._check_sky_size("Skybox.face_size", size)
        self._set_sky_view(model)   # (the bake reads an atmosphere's table and space)
        self._replace_sky(self.sky_bake.bake(model, size), model)

    def _check_sky_size(self, what: str, size: int) -> None:
        """A GLLimitError naming ``what`` where a sky cube map of ``size`` texels a face is past
        this context's cube-map limit (the start-up check asks 512 of it; a Skybox takes 2048)."""
        limit = self.caps.max_cube_map_size
        if size > limit:
            raise GLLimitError(f"{what}: a sky cube map of {size}x{size} texels a face is over this OpenGL's "
                               f"({self.caps.renderer}) {limit} (GL_MAX_CUBE_MAP_TEXTURE_SIZE); make the faces "
                               "smaller")

    def _replace_sky(self, cube: moderngl.TextureCube, model: SkyModel | None) -> None:
        old = self.sky
        self.sky = cube
        old.release()
        self.set_sky_model(model)

    def set_sky_model(self, model: SkyModel | None) -> None:
        """The ``model`` the sky pass draws a generated Skybox from, the cube map kept (its
        sun turning: the prepare stage makes the cube again a moment later)."""
        self._set_sky_view(model)
        self.sky_model = model
        self.sky_version += 1
        self.note_scene_change()

    def _set_sky_view(self, model: SkyModel | None) -> None:
        """An atmosphere's sky-view table, drawn on the GPU for its air and the sun's
        elevation (``SkyView``: again only when either changed), and the cube map of its
        space (its Skybox's given faces: uploaded when they are others); released with the
        last atmosphere; and the clouds' block (``CloudBlock``: the bake and the scene's
        cloud shadows read it)."""
        self.clouds.set(None if model is None else model.clouds)
        space = None if model is None else model.space
        if space is None or (self.sky_space is not None and self._space_key != model.space_key):
            if self.sky_space is not None:
                self.sky_space.release()
            self.sky_space, self._space_key = None, 0
        if space is not None and self.sky_space is None:   # its space: uploaded once, kept while it stays
            self.sky_space, self._space_key = upload_cube(self.ctx, space), model.space_key
        if model is None or not model.moon_lights_air:
            self.moon_view_pass.release()
            self.moon_view = None
        if model is None or not model.atmosphere:
            self.sky_view_pass.release()
            self.sky_view = None
            return
        self.sky_view = self.sky_view_pass.draw(model.air, model.air_elevation)
        if model.moon_lights_air:
            self.moon_view = self.moon_view_pass.draw(model.air, model.moon_elevation)

    def resource_counts(self) -> dict[str, int]:
        """Live GL resources this renderer owns, by kind (soak and churn runs check that they
        come back to their baseline; tests that they go back to zero)."""
        return {"meshes": len(self._meshes), "textures": len(self._textures), "batches": len(self.batches),
                "probe_cubes": len(self.probes.cubes),
                "sky_view": int(self.sky_view is not None), "moon_view": int(self.moon_view is not None),
                "sky_space": int(self.sky_space is not None),
                "shadow_cubes": len(self.shadows.cubes),
                "spot_atlases": int(self.shadows.spot_atlas is not None),
                "spot_cookies": self.spot_cookies.count(),
                "layered_targets": len(self.probes._layered),
                "face_targets": len(self.probes._faces),
                "levels": len(self.levels), "level_copies": len(self.level_copies),
                "probe_levels": sum(len(s) for s in self.probes._stacks.values()),
                "pose_rows": int(self.pose_rows.texture is not None) + int(self.pose_rows.before is not None),
                "object_motion": int(self.object_motion.texture is not None),
                "programs": len(self.shaders._programs), "post_targets": self.present_pass.post_target_count(),
                "irradiance_rows": len(self.irradiance.rows), "bounce_copies": self.irradiance.bounce_copies,
                "occlusion_targets": self.occlusion.target_count(),
                "reflection_targets": self.screen_reflections.target_count(),
                "volumetric_targets": self.volumetric_fog.target_count(),
                "particle_buffers": len(self.scene_pass.particle_draw.emitters)}

    # --- frame -----------------------------------------------------------------------------
    @property
    def targets(self) -> RenderTargets | None:
        """The main view's targets (level 0 of the main view tree)."""
        return self.levels[0] if len(self.levels) else None

    def upload_instances(self) -> int:
        """Upload changed instance rows; re-sort the draw order when sizes may have changed.

        Batches draw smallest first: big surfaces (ground, walls) mostly lie behind small
        things, so drawn last their hidden pixels fail the depth test before shading
        (measured on llvmpipe: the benchmark's main view 25 -> 21 ms against mesh order)."""
        sent = 0
        for batch in self.batches.values():
            written = batch.upload()
            sent += written
            self._order_stale |= written > 0
        self.stats.uploaded_bytes += sent
        if self._order_stale:
            self.casters_version += 1
        if sent or self._order_stale:
            self.note_scene_change()
        return sent

    def begin_object_motion(self, on: bool, dt: float, crossings: Iterable[PortalCrossing] = ()) -> None:
        """Start the frame's per-object motion (``ObjectMotion.begin``: ``on`` while the active
        camera's motion blur streaks moving things); when it turns on or off the main tree's
        levels are made again with or without the seen images' motion channels, and nothing
        drawn before is kept."""
        if self.object_motion.begin(on, dt, crossings):
            self.levels.set_seen_channels(SEEN_MOVING_CHANNELS if on else SEEN_CHANNELS)
            self.level_copies.release()
            self.note_scene_change()
        if self.pose_rows.track(on, dt):   # (last frame's poses: a posed mesh's own motion)
            self.note_scene_change()

    def _note_dropped(self, box: tuple[np.ndarray, np.ndarray] | None) -> None:
        if box is not None:
            old = self._dropped_changes
            self._dropped_changes = box if old is None else (np.minimum(old[0], box[0]), np.maximum(old[1], box[1]))

    def take_changed_box(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The box holding where casting instances (``shadow_casting_batches``) were and are
        whose rows changed since the last call (moved, came, went, changed their look),
        forgotten; None: none.  What a shadow map redraws (engine/render/shadows.py)."""
        return self.take_changes()[0]

    def take_changes(self) -> tuple[tuple[np.ndarray, np.ndarray] | None, list | None]:
        """``take_changed_box``'s box and the boxes it holds (each batch's few changed rows'
        own, [lo, hi] lists of floats; None: past ``MAX_CHANGED_PARTS`` in all, the box alone), forgotten: a
        shadow map redraws only the texels under those in it, not all under a box spanning
        the level."""
        boxes, parts = [], []
        for batch in self.batches.values():
            box, batch_parts = batch.take_changes()
            if box is None or (batch.transparent and not batch.see_through_paint):   # (casts nothing)
                continue
            boxes.append(box)
            parts = None if parts is None or batch_parts is None else parts + batch_parts
            if parts is not None and len(parts) > MAX_CHANGED_PARTS:
                parts = None   # many movers: a map's region from the box alone (a few calls, not one a part)
        if self._dropped_changes is not None:
            boxes.append(self._dropped_changes)
            if parts is not None:
                parts.append((self._dropped_changes[0].tolist(), self._dropped_changes[1].tolist()))
            self._dropped_changes = None
        return _union(boxes), parts

    def level_bounds(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The world box holding every instance of the batches that cast (the opaque ones,
        an instance that casts no shadow among them, and the see-through ones:
        ``shadow_casting_batches``; not the particles) as of the last upload (None: none): what a directional
        light's shadow map is fitted to."""
        batches = self.shadow_casting_batches()
        kept = self._level_union
        if kept is not None and len(kept[0]) == len(batches):
            for batch, box in zip(batches, kept[0], strict=True):
                if batch.box is not box:
                    break
            else:  # the same batches' boxes as last time (a batch keeps its box object while it holds)
                return kept[1]
        boxes = [batch.box for batch in batches]
        union = _union([box for box in boxes if box is not None])
        self._level_union = (boxes, union)
        return union

    def drawing_settings(self) -> tuple:
        """Besides ``scene_version``, what every view's drawing depends on, as values: shader
        reloads, the texture filters, the batch cull, the screen passes' reflection-level
        keys, the water rings.  Part of each still key (the main tree's, a monitor's
        picture's): equal to the last, nothing of these changed."""
        return (self.shaders.reloads, self.texture_anisotropy, self.reflection_anisotropy, self.normal_map_anisotropy,
                self.scene_pass.cull_batches, self.occlusion.level_key(), self.screen_reflections.level_key(),
                self.volumetric_fog.level_key(), self.ripples.version)

    def set_lights(self, block: bytes) -> None:
        self.lights_ubo.write(block)
        self.note_scene_change()

    def present(self, output: moderngl.Framebuffer, size: tuple[int, int], post: CameraPost | None = None,
                curve: str | None = None, camera: int | None = None, dt: float = 0.0,
                image: RenderTargets | None = None) -> None:
        """Encode the HDR ``image`` (the present stage's: the main view's, ``FrameViews.image``;
        None: level 0 of the main view tree) to sRGB into ``output`` (a window's or a capture
        target), anti-aliased unless ``antialias`` is "off"; with the active camera's ``post``
        components (``components/post.py``: ``PresentPass.draw``; ``exposure`` is used only
        without a Tonemap), its lens and motion blur reading the ways in ``image``'s seen image."""
        image = image if image is not None else self.targets
        assert image is not None
        self.present_pass.draw(image.color, self.exposure, self._antialias, output, size, post, curve, camera, dt,
                               image.seen, self._sharpness)
        self.checkpoint("present")

    def text(self) -> TextPass:
        """The screen text pass (``engine/render/text.py``), made on first use."""
        if self.text_pass is None:
            self.text_pass = TextPass(self.ctx, self.shaders)
        return self.text_pass

    def draw_screen_text(self, quads: np.ndarray, output: moderngl.Framebuffer, size: tuple[int, int],
                         pictures: tuple[moderngl.Texture, ...] = ()) -> None:
        """Blend the screen text's ``quads`` (``engine.render.text.layout``) over ``output``,
        after present (a picture panel's from ``pictures``, exposed and tone-mapped as the
        present did the frame: ``PresentPass.look``); kept in ``screen_quads`` and
        ``screen_pictures`` so a screenshot shows them too."""
        self.screen_quads, self.screen_pictures = quads, pictures
        if len(quads):
            self.text().draw(quads, output, size, pictures, self.present_pass.look)
            self.checkpoint("screen text")

    def release(self) -> None:
        self.monitors.release()   # (its holds of the pictures first: the table below releases what batches hold)
        for batch in list(self.batches.values()):
            batch.release()
        self.batches.clear()
        for table in (self._meshes, self._textures):
            for shared in table.values():
                shared.obj.release()
            table.clear()
        self.levels.release()
        self.level_copies.release()
        self._draw_order.clear()
        self.probes.release()
        self.shadows.release()
        self.irradiance.release()
        self.sky_bake.release()
        self.occlusion.release()
        self.screen_reflections.release()
        self.volumetric_fog.release()
        self.release_depth_values()
        self.scene_pass.release()
        self.present_pass.release()
        self.frame_timer.release()
        if self.text_pass is not None:
            self.text_pass.release()
            self.text_pass = None
        self._set_sky_view(None)
        for obj in (self.sky, self.blank_color, self.blank_ids, self.cameras_ubo, self.lights_ubo, self.fog,
                    self.clouds, self.caustics, self.foam, self.ripples, self.spot_cookies, self.pose_rows,
                    self.object_motion):
            obj.release()
        self.shaders.release()


def _union(boxes: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray] | None:
    """The box holding ``boxes`` ([lo, hi] each; None: none), read-only like them: a box
    alone is itself, more are folded pairwise (a frame has a few batches: a pairwise
    minimum is one small numpy call where stacking a list first makes an array)."""
    if not boxes:
        return None
    lo, hi = boxes[0]
    for other_lo, other_hi in boxes[1:]:
        lo, hi = np.minimum(lo, other_lo), np.maximum(hi, other_hi)
    return lo, hi
