"""What every pass draws with: the GL context and its capabilities, the shader library, the
Camera and Lights blocks, the sky, the instance batches in their draw order, the probes'
cube maps, the path self-check's verdicts, and the frame's ``RenderStats`` while a frame
runs.

The passes (the scene pass, shadows, irradiance, probes, the view tree's passes, the path
self-check) are given this and the passes they draw through, never the whole renderer:
``Renderer`` (``engine/render/renderer.py``) is a ``Gpu`` that also makes the passes and
makes and releases the shared meshes, textures and batches (by reference count), so it
stands above every pass and no pass imports it.
"""
from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import moderngl
import numpy as np

from engine.assets.texture_data import TextureData
from engine.core.errors import GLLimitError, GLPassError
from engine.frame_stats import RenderStats
from engine.render.bindings import CAMERA_BINDING, bind_uniform_range, forget_sampler
from engine.render.caustics import CausticBlock
from engine.render.clouds import CloudBlock
from engine.render.foam import FoamBlock
from engine.render.fog import FogBlock
from engine.render.gl_context import GLCapabilities
from engine.render.instances import GpuMesh, InstanceBatch
from engine.render.object_motion import ObjectMotion
from engine.render.pose_rows import PoseRows
from engine.render.raw_gl import RawGL
from engine.render.ripples import RippleAtlas
from engine.render.shader_library import ShaderLibrary
from engine.render.sky import SkyModel, flat_cube
from engine.render.spot_cookies import SpotCookies
from engine.render.views import CAMERA_BLOCK_BYTES, LIGHTS_BLOCK_BYTES, View

__all__ = ["BACKGROUND", "Gpu", "PathTrust", "ProbeCube", "Shared"]

TEXTURE_ANISOTROPY = 8.0
BACKGROUND = (0.05, 0.05, 0.06)
GL_SRGB8_ALPHA8 = 0x8C43  # an sRGB colour texture (moderngl names no such format)


@dataclass
class ProbeCube:
    """One probe's cube map (RGBA16F, mipmapped, seamless) and where it was captured from.

    ``box`` (world min, max corners), when set, makes lookups parallax-corrected: the
    reflected ray is followed from the shaded point to the box's wall and the cube is
    sampled towards that point from ``position`` (box projection)."""

    texture: moderngl.TextureCube
    resolution: int
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    box: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    prefilter: str = "mips"

    @property
    def roughness_levels(self) -> float:
        """For a GGX-prefiltered chain, its top level (level L holds roughness L / this);
        0 for box mips (sampled with a roughness bias instead)."""
        return float(self.resolution.bit_length() - 1) if self.prefilter == "ggx" else 0.0

    def lookup(self) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]:
        """The scene shader's probe_position (w: ``roughness_levels``), probe_box_min (w: 1 =
        box projection on) and probe_box_max uniforms."""
        position = (*self.position, self.roughness_levels)
        if self.box is None:
            return position, (0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0)
        return position, (*self.box[0], 1.0), (*self.box[1], 0.0)

    @property
    def face_size(self) -> int:
        return self.resolution


class PathTrust(Protocol):
    """Whether an alternative GL path (a name of ``path_checks.PATH_NAMES``) may be used on
    this context: the path self-check answers, checking it at its first use."""

    def trusted(self, path: str) -> bool: ...


class _TrustNone:
    """The verdicts before the self-check is made: no alternative path is trusted."""

    def trusted(self, path: str) -> bool:
        return False


_TRUST_NONE = _TrustNone()


def layered_target(trust: PathTrust) -> str | None:
    """Where a layered pass over a cube map's six faces draws on this context: "cube" (into
    the cube map, ``layered_capture`` verified), "array" (a six-layer 2D array copied into its
    faces, ``layered_array_capture`` verified where the other was refused: the NVIDIA H200's
    driver draws a layered cube-map attachment's face 0 alone), or None (neither: a pass a
    face).  Each check runs at its first need, the array's only where the cube's was refused."""
    if trust.trusted("layered_capture"):
        return "cube"
    if trust.trusted("layered_array_capture"):
        return "array"
    return None


class Shared:
    """A GL object shared by reference count."""

    __slots__ = ("obj", "users")

    def __init__(self, obj: moderngl.Texture | GpuMesh) -> None:
        self.obj = obj
        self.users = 0


def _anisotropy(name: str, about: str) -> property:
    """A texture-filtering setting of the ``Gpu``, checked when set: a number from 1 (no
    anisotropic filtering) to the context's ``max_anisotropy`` (a NaN, a string or a value
    the driver cannot filter with was clamped in silence, or failed inside a scene pass)."""
    key = "_" + name

    def get(gpu: Gpu) -> float:
        return getattr(gpu, key)

    def set_(gpu: Gpu, value: float) -> None:
        most = max(float(gpu.ctx.max_anisotropy), 1.0)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                or not 1.0 <= value <= most:
            raise ValueError(f"{name} must be a number from 1 (off) to {most:g} (this context's max_anisotropy), "
                             f"got {value!r}")
        setattr(gpu, key, float(value))

    return property(get, set_, doc=about)


class Gpu:
    """The GL objects every pass draws with, and the frame's counters (module docstring)."""

    texture_anisotropy = _anisotropy("texture_anisotropy", "Anisotropic filtering of textures in the main view.")
    reflection_anisotropy = _anisotropy("reflection_anisotropy",
                                        "Anisotropic filtering of albedo inside mirror and portal views.")
    normal_map_anisotropy = _anisotropy("normal_map_anisotropy",
                                        "Anisotropic filtering of normal maps (set before the first is uploaded).")

    def __init__(self, ctx: moderngl.Context, caps: GLCapabilities) -> None:
        self.ctx = ctx
        self.caps = caps
        self.raw_gl = RawGL(ctx)
        # A software rasteriser's anisotropic filter has no bound on its taps: its builds hold
        # each map read's footprint to one texture a pixel (shaders/include/footprint.glsl).
        self.shaders = ShaderLibrary(ctx, driver_defines={} if caps.filters_anisotropically
                                     else {"BOUNDED_FOOTPRINT": "1"})
        # A pass's Camera blocks, one after another at the alignment a uniform range needs.
        align = max(1, int(ctx.info.get("GL_UNIFORM_BUFFER_OFFSET_ALIGNMENT", 256)))
        self.camera_stride = -(-CAMERA_BLOCK_BYTES // align) * align
        self._camera_padding = bytes(self.camera_stride - CAMERA_BLOCK_BYTES)
        self.cameras_ubo = ctx.buffer(reserve=self.camera_stride * 16)
        # The views of the last ``upload_run`` (their blocks in ``cameras_ubo`` now) by id, and
        # where the views of the pass drawing now start in it (``upload_views``, ``bind_view_at``).
        self._view_run: tuple[Sequence[View], dict[int, int]] | None = None
        self._view_base = 0
        self.lights_ubo = ctx.buffer(reserve=LIGHTS_BLOCK_BYTES)
        self.fog = FogBlock(ctx)   # the active camera's Fog (the prepare stage sets it)
        self.clouds = CloudBlock(ctx)   # the sky's CloudLayer (set with the sky: Renderer.set_sky_model)
        # The active camera's ambient occlusion this frame, a texel a pixel of the main view
        # (engine/render/screen_occlusion.py; None: none): its SCREEN_OCCLUSION builds read it.
        self.screen_occlusion: moderngl.Texture | None = None
        # Beside it, the shares of the lamps with contact shadows (None: no lamp has them), and
        # the define of the builds that read it (ScreenOcclusion sets both).
        self.screen_contact_lamps: moderngl.Texture | None = None
        self.contact_lamp_defines: tuple[tuple[str, str], ...] = ()
        # Textures shared by reference count (the Renderer makes and releases them), by
        # id(TextureData); ("normal", id): uploaded linear (normal and metallic-roughness maps)
        self._textures: dict[object, Shared] = {}
        # BatchKey (mesh, texture, probes, transparent entity, the material's maps, ...) -> batch
        self.batches: dict[tuple[int, int, int, int, int, int, int], InstanceBatch] = {}
        self._draw_order: list[InstanceBatch] = []   # non-empty batches, smallest extent first
        self._transparent: list[InstanceBatch] = []  # the non-empty transparent ones (found with it)
        # The draw order without the batches that refract the screen, and those (found with it).
        self._before_copy: list[InstanceBatch] = []
        self._refracting: list[InstanceBatch] = []
        self._order_stale = True
        self.sky = flat_cube(ctx, BACKGROUND)
        # The generated sky the sky pass evaluates per pixel (None: it samples ``sky``), and a
        # count of the skies set, so a pass writes a sky's colours into its programs once.
        self.sky_model: SkyModel | None = None
        self.sky_version = 0
        # An atmosphere's sky-view table (drawn by the renderer's SkyView; None: no atmosphere).
        self.sky_view: moderngl.Texture | None = None
        self.moon_view: moderngl.Texture | None = None   # ... an atmosphere's moonlit air's (SkyModel.moon_air)
        # ... and its space (the Skybox's given faces, a cube map; None: none), by the faces' id.
        self.sky_space: moderngl.TextureCube | None = None
        self._space_key = 0
        # Stand-ins for an image a program samples in a branch its draw does not take (a batch
        # with no albedo map; a fallback with no reflection level below it).  A sampler the
        # program uses statically must still find a complete texture of its own type on its
        # unit: otherwise it reads whatever another pass left there (an integer id image under
        # a float sampler, a texture attached to the framebuffer drawn into: a rendering
        # feedback loop), which GL 4.1 leaves undefined even unread, and which GL drivers
        # layered on other APIs (Apple's 4.1 over Metal) reject.  1x1, so complete whatever the
        # filter (the reflections' mipmapped albedo sampler included).
        # A batch with no albedo map needs none bound where its unit holds any colour map
        # already (``colour_maps``: the material maps uploaded, mipmapped, and the blank one):
        # the blank is bound only over something else, so batches with and without maps in
        # turn do not bind it and their maps again at every switch.
        self.blank_color = ctx.texture((1, 1), 4, b"\xff\xff\xff\xff")
        self.blank_ids = ctx.texture((1, 1), 1, bytes(4), dtype="u4")
        self.blank_ids.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.colour_maps: set[moderngl.Texture] = {self.blank_color}  # (a texture leaves it when released)
        self.stats = RenderStats()  # the frame's, while a frame runs (Engine.frame gives it)
        self._depth_values: moderngl.Sampler | None = None  # depth_values()
        # Every probe's cube map by probe key: made and released by the probe captures
        # (engine/render/probes.py), sampled by the scene pass and the composites.
        self.probe_cubes: dict[int, ProbeCube] = {}
        self.capturing = 0  # the probe whose cube is being drawn into (0: none): no pass samples it
        # The path self-check (engine/render/path_checks.py, made by the Renderer above every
        # pass): which alternative GL paths this context draws right.  Until it is made, none.
        self.path_checks: PathTrust = _TRUST_NONE
        self.texture_anisotropy = max(min(TEXTURE_ANISOTROPY, ctx.max_anisotropy), 1.0)
        # Texture filtering inside mirror and portal views.  A software rasteriser spends
        # about 60% of a reflection view's time in the anisotropic filter (measured on
        # llvmpipe, benchmarks/mirrors.py), so there reflections filter trilinearly; a GPU
        # filters them like the main view.  Set it to texture_anisotropy for equal quality.
        self.reflection_anisotropy = self.texture_anisotropy if caps.filters_anisotropically else 1.0
        # Normal maps likewise: on llvmpipe an 8x anisotropic normal map on the benchmark
        # ground cost +36-41% of the frame, trilinear +4-5% (benchmarks/normal_maps.py).  Set
        # before the first normal map is uploaded.
        self.normal_map_anisotropy = self.texture_anisotropy if caps.filters_anisotropically else 1.0
        # Where the scene programs discard a decal's clear part (scene.frag's DISCARDS_LAST): on
        # a GPU after every derivative its quad's other pixels take (GLSL leaves them undefined
        # after a discard); on a software rasteriser first, unshaded (llvmpipe keeps a quad's
        # pixels running, and drew every frame 5% slower with it last).  Set before the first frame.
        self.discards_last = not caps.software
        # The kept spot lights' cookies (PointLight.cookie; the prepare stage sets them), filtered
        # as normal maps are (anisotropy on a GPU).
        # Whether a kept point light is a sphere (PointLight.radius; the prepare stage sets it):
        # the scene programs' SPHERE_LIGHTS builds.  Whether one is a rectangle
        # (PointLight.rectangle): the RECT_LIGHTS builds, which read the LTC table's rows of
        # the irradiance table (IrradianceTable.write_ltc, when the first is kept).
        self.sphere_lights = False
        self.rect_lights = False
        # What the scene's light from all round reads besides the sky in a pass that draws
        # with the irradiance table (IrradianceTable.bind): AMBIENT_PROBES while a probe's box
        # has a capture, IRRADIANCE_VOLUME while an irradiance volume is baked (the table sets it).
        self.ambient_defines: tuple[tuple[str, str], ...] = ()
        self.spot_cookies = SpotCookies(ctx, caps.max_texture_image_units, self.normal_map_anisotropy, caps.software)
        # The water whose waves gather the sun under it (the prepare stage sets it): CAUSTICS builds.
        self.caustics = CausticBlock(ctx, caps.max_texture_image_units)
        self.foam = FoamBlock(ctx, caps.max_texture_image_units)   # the waters with shore foam (engine/render/foam.py)
        self.ripples = RippleAtlas(ctx, caps.max_texture_image_units)   # rippling waters' heights (render/ripples.py)
        # Every posed entity's joint matrices and morph weights (engine/render/pose_rows.py;
        # the extract stage writes them): the SKINNED and MORPHED builds read them.
        self.pose_rows = PoseRows(ctx, caps.max_texture_size)
        # Each mover's own motion since the last frame while the camera's motion blur streaks
        # moving things (engine/render/object_motion.py; extract notes, prepare sends).
        self.object_motion = ObjectMotion(ctx, caps.max_texture_size, self.pose_rows)
        # Debug mode: every pass checks for an OpenGL error when it ends and names itself
        # (checkpoint); glGetError is cheap on the CPU but makes no sense to pay in a game.
        self.debug = os.environ.get("SPECULUM_DEBUG", "") not in ("", "0")
        # When set, the only batches scene passes draw (the path self-check's own scene).
        self.scene_only: list[InstanceBatch] | None = None
        # A batch was made since prepare_programs last ran (Engine.frame calls it then).
        self.needs_preparing = False
        self._prepared_for: tuple | None = None  # (reflections, ambient boxes) the last preparing was for
        # What the views show, as a version (``note_scene_change``): moved on by every
        # upload or redraw that changes what a scene pass, a fallback or a composite draws.
        self.scene_version = 0

    def note_scene_change(self) -> None:
        """Something a view shows changed on the GPU (instance rows, a batch made or dropped,
        the Lights block, the sky, the irradiance table, a shadow map or its block, a probe's
        cube): ``scene_version`` moves on, so the main view tree keeps no level drawn before
        (``ReflectionSystem.keep_still_views``).  Every place that writes such data calls
        it; one missed is a stale reflection, so a doubtful write calls it too."""
        self.scene_version += 1

    @staticmethod
    def _acquire(table: dict[int, Shared], key: int, make):
        shared = table.get(key)
        if shared is None:
            shared = table[key] = Shared(make())
        shared.users += 1
        return shared.obj

    def _release(self, table: dict[int, Shared], key: int) -> None:
        shared = table[key]
        shared.users -= 1
        if shared.users == 0:
            self.colour_maps.discard(shared.obj)  # (a texture: no longer one to leave bound)
            shared.obj.release()
            del table[key]

    def check_texture(self, texture: TextureData, field: str = "texture") -> None:
        """Refuse a texture this context cannot hold, naming it, the field it fills and the limit."""
        w, h = texture.size
        limit = self.caps.max_texture_size
        if w > limit or h > limit:
            raise GLLimitError(f"{field}: texture {texture.name!r} is {w}x{h}: this OpenGL ({self.caps.renderer}) "
                               f"takes textures of at most {limit}x{limit} (GL_MAX_TEXTURE_SIZE); scale the image down")

    def _upload_texture(self, texture: TextureData, linear: bool = False) -> moderngl.Texture:
        w, h = texture.size
        # Image rows are top-first, GL's are bottom-first: flip so v=0 is the bottom.  A 16-bit
        # normal map stays 16 bits (normalised RGBA16: its slopes without 8-bit terraces); a
        # colour is 8 bits (sRGB decoding has no 16-bit format).
        if linear and texture.pixels.dtype == np.uint16:
            gl_texture = self.ctx.texture((w, h), 4, texture.pixels[::-1].tobytes(), dtype="nu2")
        else:
            gl_texture = self.ctx.texture((w, h), 4, texture.as_8_bits()[::-1].tobytes(),
                                          internal_format=None if linear else GL_SRGB8_ALPHA8)
        gl_texture.build_mipmaps()
        gl_texture.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        gl_texture.anisotropy = self.normal_map_anisotropy if linear else self.texture_anisotropy
        self.colour_maps.add(gl_texture)  # complete (mipmapped), a float format: a stand-in albedo map too
        return gl_texture

    def shared_texture(self, texture: TextureData, field: str) -> moderngl.Texture:
        """``texture`` on the GPU (colour: sRGB, mipmapped), shared with every batch and emitter
        that uses it; each call is one more user, let go by ``let_go_texture``.  Checked
        against the context's size limit first (``field`` names it in the error)."""
        if id(texture) not in self._textures:
            self.check_texture(texture, field)
        return self._acquire(self._textures, id(texture), lambda: self._upload_texture(texture))

    def hold_texture(self, stand_in: TextureData, texture: moderngl.Texture) -> None:
        """Make ``texture``, drawn on the GPU (a monitor's picture: ``engine/render/monitors.py``),
        what ``stand_in`` is there: a batch whose map is ``stand_in`` samples it, shared and
        counted as an uploaded texture is.  The caller holds it once, let go by
        ``let_go_texture``; it is released with its last user."""
        if id(stand_in) in self._textures:
            raise ValueError(f"texture {stand_in.name!r} is on the GPU already: a stand-in is held once, when made")
        self._acquire(self._textures, id(stand_in), lambda: texture)

    def let_go_texture(self, texture: TextureData) -> None:
        """One user fewer of ``shared_texture(texture)``: released with its last."""
        self._release(self._textures, id(texture))

    def normal_map_texture(self, normal_map: TextureData) -> moderngl.Texture | None:
        """The uploaded normal map of ``normal_map`` while a batch draws with it (a mirror's
        composite reads the one its scene-pass batch holds), else None."""
        shared = self._textures.get(("normal", id(normal_map)))
        return shared.obj if shared is not None else None

    def bind_view(self, view: View) -> None:
        """Make ``view`` the Camera block every program reads (a pass of one view)."""
        self.upload_views((view,))
        self.bind_view_at(0)

    def upload_views(self, views: Sequence[View]) -> None:
        """The Camera blocks of a pass's views in one buffer, in one upload (``bind_view_at``
        then binds view i's range): one write a pass, not one a view, and into fresh storage
        (orphaned), so a GPU driver never waits for, or copies, a block the pass before
        still reads."""
        run = self._view_run
        if run is not None and len(views) == 1:
            at = run[1].get(id(views[0]))
            if at is not None:  # (uploaded with its run: upload_run)
                self._view_base = at
                return
        self._write_views(views)
        self._view_run, self._view_base = None, 0

    def upload_run(self, views: Sequence[View]) -> None:
        """The Camera blocks of the views of several passes of one view each, drawn one after
        another with no other pass uploading views between (a chain of reflection levels
        planned ahead: the claims between them upload none), in one upload: ``upload_views``
        of one of them then writes nothing, and its pass binds its block where the run put
        it.  Kept until another pass uploads views."""
        if self._view_run is not None and self._view_run[0] is views:
            return
        self._write_views(views)
        self._view_run, self._view_base = (views, {id(view): at for at, view in enumerate(views)}), 0

    def _write_views(self, views: Sequence[View]) -> None:
        padding = self._camera_padding
        data = b"".join(view.camera_block() + padding for view in views)
        if len(data) > self.cameras_ubo.size:
            reserve = max(len(data), 2 * self.cameras_ubo.size)
            self.cameras_ubo.release()
            self.cameras_ubo = self.ctx.buffer(reserve=reserve)
        else:
            self.cameras_ubo.orphan()
        self.cameras_ubo.write(data)

    def bind_view_at(self, index: int) -> None:
        """Make the ``index``-th view of the last ``upload_views`` the Camera block."""
        bind_uniform_range(self.ctx, self.cameras_ubo, CAMERA_BINDING, (self._view_base + index) * self.camera_stride,
                           CAMERA_BLOCK_BYTES)

    def opaque_batches(self) -> list[InstanceBatch]:
        """Non-empty opaque batches, smallest extent first (re-sorted after uploads)."""
        if self.scene_only is not None:
            return self.scene_only
        if self._order_stale:
            self._sort_batches()
        return self._draw_order

    def transparent_batches(self) -> list[InstanceBatch]:
        """Non-empty batches drawn in the scene pass's transparent slot (a material's alpha
        below 1), found with the opaque ones' order (asked by each view tree's levels, so
        kept, not looked for every time)."""
        if self.scene_only is not None:
            return []
        if self._order_stale:
            self._sort_batches()
        return self._transparent

    def shadow_casting_batches(self) -> list[InstanceBatch]:
        """What the shadow maps hold: the opaque batches (the depth maps; glass among them
        in a sun's see-through map), then the transparent slot's see-through ones (its
        see-through map: ``see_through_casters``)."""
        see_through = [batch for batch in self.transparent_batches() if batch.see_through_paint]
        return self.opaque_batches() + see_through if see_through else self.opaque_batches()

    def see_through_casters(self) -> list[InstanceBatch]:
        """The batches that dim a sun's light by their alpha (its see-through map:
        ``ShadowMaps.see_through_atlas``): the transparent slot's see-through paint
        (``InstanceBatch.see_through_paint``), then the opaque batches with glass in them
        (``InstanceBatch.refracts``: their refracting instances alone are drawn there)."""
        return [batch for batch in self.transparent_batches() if batch.see_through_paint] + \
            [batch for batch in self.opaque_batches() if batch.refracts]

    def tree_opaque_batches(self) -> list[InstanceBatch]:
        """What a view tree's views (root and levels) draw as opaque: ``opaque_batches``
        without those that refract the screen (``refracting_batches``), which they draw after
        their copy of colour and depth (``ScenePass.refract``).  The same list where none do."""
        if self.scene_only is not None:
            return self.scene_only
        if self._order_stale:
            self._sort_batches()
        return self._before_copy

    def refracting_batches(self) -> list[InstanceBatch]:
        """The non-empty opaque batches that refract what their view drew behind them
        (``Refractive.screen``), in the draw order."""
        if self.scene_only is not None:
            return []
        if self._order_stale:
            self._sort_batches()
        return self._refracting

    def _sort_batches(self) -> None:
        drawn = [b for b in self.batches.values() if b.count]
        self._draw_order = sorted((b for b in drawn if not b.transparent), key=lambda b: b.extent)
        self._transparent = [b for b in drawn if b.transparent]
        self._refracting = [b for b in self._draw_order if b.refracts_screen]
        self._before_copy = [b for b in self._draw_order if not b.refracts_screen] if self._refracting \
            else self._draw_order
        self._order_stale = False

    def depth_values(self) -> moderngl.Sampler:
        """The sampler a screen pass reads a view's depth image through as values (nearest,
        comparing nothing: a depth texture's own state may be set for shadow comparisons):
        screen reflections' march and the light shafts'.  One for the context, made on first
        use, released with the Gpu (``release_depth_values``)."""
        if self._depth_values is None:
            self._depth_values = self.ctx.sampler(filter=(moderngl.NEAREST, moderngl.NEAREST), compare_func="")
        return self._depth_values

    def release_depth_values(self) -> None:
        if self._depth_values is not None:
            forget_sampler(self.ctx, self._depth_values)
            self._depth_values.release()
            self._depth_values = None

    def checkpoint(self, name: str) -> None:
        """In debug mode, raise ``GLPassError`` naming pass ``name`` if it left a GL error."""
        if self.debug:
            error = self.ctx.error
            if error != "GL_NO_ERROR":
                raise GLPassError(f"OpenGL error {error} in the {name} pass")

    def flush(self) -> None:
        """Start the GPU on the passes queued so far, before CPU-only work (``RawGL.flush``)."""
        self.raw_gl.flush()
