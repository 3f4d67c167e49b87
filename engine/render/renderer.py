"""GL resources of one world's rendering and the passes that draw them.

The RenderSystem decides what is drawn; this class owns how: programs, uniform blocks,
shared meshes and textures (reference counted, released when the last user goes), the
instance batches, the sky cube map and the render targets.
"""
from __future__ import annotations

from dataclasses import dataclass

import moderngl

from engine.gl_context import GLCapabilities
from engine.mesh import Mesh
from engine.raw_gl import RawGL
from engine.render.instances import GpuMesh, InstanceBatch
from engine.render.sky import flat_cube, upload_cube
from engine.render.targets import RenderTargets
from engine.render.views import CAMERA_BLOCK_BYTES, LIGHTS_BLOCK_BYTES, View
from engine.shader_library import ShaderLibrary
from engine.texture_data import TextureData

CAMERA_BINDING = 0
LIGHTS_BINDING = 1
ALBEDO_UNIT = 0
SKY_UNIT = 1
NODE_UNIT = 2
GL_SRGB8_ALPHA8 = 0x8C43
TEXTURE_ANISOTROPY = 8.0
GL_CLIP_DISTANCE0 = 0x3000  # the view's clip plane (mirror and portal views)
GL_CLIP_DISTANCE_SLICE = 0x3005  # the instance's slice plane (SLICE_CLIP in scene.vert)
# Clip distances 1-4: a rectangle, for passes that draw many views or quads in one draw
# (the batched mirror path, the composite); enabled only around those draws.
RECT_CLIP_DISTANCES = range(GL_CLIP_DISTANCE0 + 1, GL_CLIP_DISTANCE0 + 5)
BACKGROUND = (0.05, 0.05, 0.06)


@dataclass
class RenderStats:
    """What the last frame cost: read by tests and benchmarks."""

    passes: int = 0
    draw_calls: int = 0
    uploaded_bytes: int = 0
    instances: int = 0
    reflection_views: int = 0
    # How reflection levels were drawn: "per_mirror", "batched", "mixed" (auto chose both in
    # one frame), or "" when no reflection view was drawn (ReflectionSystem.path).
    reflection_path: str = ""


class _Shared:
    """A GL object shared by reference count."""

    __slots__ = ("obj", "users")

    def __init__(self, obj) -> None:
        self.obj = obj
        self.users = 0


class Renderer:
    def __init__(self, ctx: moderngl.Context, caps: GLCapabilities) -> None:
        self.ctx = ctx
        self.caps = caps
        self.raw_gl = RawGL(ctx)
        self.shaders = ShaderLibrary(ctx)
        self.scene_program = self.shaders.program("scene.vert", "scene.frag")
        self.sky_program = self.shaders.program("sky.vert", "sky.frag")
        self.present_program = self.shaders.program("present.vert", "present.frag")
        for program in (self.scene_program, self.sky_program):
            program["Camera"].binding = CAMERA_BINDING
        self.scene_program["Lights"].binding = LIGHTS_BINDING
        self.scene_program["albedo_map"].value = ALBEDO_UNIT
        self.scene_program["sky_map"].value = SKY_UNIT
        self.scene_program["node_map"].value = NODE_UNIT
        self.sky_program["sky_map"].value = SKY_UNIT
        self.present_program["hdr_image"].value = 0
        self.camera_ubo = ctx.buffer(reserve=CAMERA_BLOCK_BYTES)
        self.lights_ubo = ctx.buffer(reserve=LIGHTS_BLOCK_BYTES)
        self.fullscreen_sky = ctx.vertex_array(self.sky_program, [])
        self.fullscreen_present = ctx.vertex_array(self.present_program, [])
        self._meshes: dict[int, _Shared] = {}
        self._textures: dict[int, _Shared] = {}
        self.batches: dict[tuple[int, int], InstanceBatch] = {}
        self._draw_order: list[InstanceBatch] = []   # non-empty batches, smallest extent first
        self._order_stale = True
        self.sky = flat_cube(ctx, BACKGROUND)
        self.levels: list[RenderTargets] = []   # [0] is the main view; more for reflections
        self.stats = RenderStats()
        self.exposure = 1.0
        self.texture_anisotropy = min(TEXTURE_ANISOTROPY, ctx.max_anisotropy)
        # Texture filtering inside mirror and portal views.  A software rasteriser spends
        # about 60% of a reflection view's time in the anisotropic filter (measured on
        # llvmpipe, benchmarks/mirrors.py), so there reflections filter trilinearly; a GPU
        # filters them like the main view.  Set it to texture_anisotropy for equal quality.
        self.reflection_anisotropy = 1.0 if caps.software else self.texture_anisotropy
        self._reflection_sampler: moderngl.Sampler | None = None
        ctx.enable_direct(GL_CLIP_DISTANCE0)
        ctx.enable_direct(GL_CLIP_DISTANCE_SLICE)

    # --- shared resources ------------------------------------------------------------------
    def batch_for(self, mesh: Mesh, texture: TextureData | None) -> InstanceBatch:
        key = (mesh.id, id(texture) if texture is not None else 0)
        batch = self.batches.get(key)
        if batch is None:
            gpu_mesh = self._acquire(self._meshes, mesh.id, lambda: GpuMesh(self.ctx, mesh))
            gpu_texture = None
            if texture is not None:
                gpu_texture = self._acquire(self._textures, id(texture), lambda: self._upload_texture(texture))
            batch = self.batches[key] = InstanceBatch(self.ctx, gpu_mesh, gpu_texture)
            batch.key = key
            self._order_stale = True
        return batch

    def drop_batch_if_empty(self, batch: InstanceBatch) -> None:
        if batch.count:
            return
        del self.batches[batch.key]
        self._order_stale = True
        batch.release()
        mesh_id, texture_id = batch.key
        self._release(self._meshes, mesh_id)
        if texture_id:
            self._release(self._textures, texture_id)

    @staticmethod
    def _acquire(table: dict[int, _Shared], key: int, make):
        shared = table.get(key)
        if shared is None:
            shared = table[key] = _Shared(make())
        shared.users += 1
        return shared.obj

    @staticmethod
    def _release(table: dict[int, _Shared], key: int) -> None:
        shared = table[key]
        shared.users -= 1
        if shared.users == 0:
            shared.obj.release()
            del table[key]

    def _upload_texture(self, texture: TextureData) -> moderngl.Texture:
        w, h = texture.size
        # Image rows are top-first, GL's are bottom-first: flip so v=0 is the bottom.
        gl_texture = self.ctx.texture((w, h), 4, texture.pixels[::-1].tobytes(), internal_format=GL_SRGB8_ALPHA8)
        gl_texture.build_mipmaps()
        gl_texture.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        gl_texture.anisotropy = self.texture_anisotropy
        return gl_texture

    def set_sky_faces(self, faces) -> None:
        old = self.sky
        self.sky = upload_cube(self.ctx, faces) if faces is not None else flat_cube(self.ctx, BACKGROUND)
        old.release()

    def resource_counts(self) -> dict[str, int]:
        """Live GL objects this renderer owns (tests check that they go back to zero)."""
        return {"meshes": len(self._meshes), "textures": len(self._textures), "batches": len(self.batches)}

    # --- frame -----------------------------------------------------------------------------
    @property
    def targets(self) -> RenderTargets | None:
        """The main view's targets (level 0)."""
        return self.levels[0] if self.levels else None

    def level_targets(self, level: int, size: tuple[int, int]) -> RenderTargets:
        """The targets of a reflection level (0 = main view), made on first use and remade
        when the level's size changes (a resize, or another resolution scale)."""
        while len(self.levels) <= level:
            self.levels.append(None)
        targets = self.levels[level]
        if targets is None or targets.size != size:
            if targets is not None:
                targets.release()
            targets = self.levels[level] = RenderTargets(self.ctx, size)
        return targets

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
        return sent

    def set_lights(self, block: bytes) -> None:
        self.lights_ubo.write(block)

    def bind_view(self, view: View) -> None:
        """Make ``view`` the Camera block every program reads."""
        self.camera_ubo.write(view.camera_block())
        self.camera_ubo.bind_to_uniform_block(CAMERA_BINDING)

    def render_view(self, view: View, targets: RenderTargets) -> None:
        """Draw the main view into ``targets``: clear, every batch, then the sky behind them."""
        ctx = self.ctx
        targets.framebuffer.use()
        ctx.viewport = (0, 0, *view.size)
        ctx.scissor = view.scissor
        ctx.enable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        ctx.front_face = "cw" if view.mirrored else "ccw"
        ctx.depth_func = "<"
        targets.framebuffer.clear(depth=1.0)
        program = self.scene_program
        program["masked"].value = False
        program["node_index"].value = view.node
        self.bind_view(view)
        self.bind_scene_inputs(program)
        self.draw_batches(program)
        ctx.depth_func = "<="
        ctx.disable(moderngl.CULL_FACE)
        self.fullscreen_sky.render(moderngl.TRIANGLES, vertices=3)
        self.stats.draw_calls += 1
        ctx.front_face = "ccw"
        ctx.scissor = None
        self.stats.passes += 1

    def render_reflection_views(self, views: list[View], level: RenderTargets) -> None:
        """Draw every batch from each of ``views`` into reflection ``level``: each only where
        the level's node image names it (over the depth mask ``MirrorPasses.prepare_level``
        wrote), scissored to its rectangle.  The sky is left to the composite.  State shared
        by the views is set once: per view there is a scissor, a winding, a camera and the
        draws (on llvmpipe the Python and driver cost per view is on the frame's critical path)."""
        if not views:
            return
        ctx = self.ctx
        level.view_framebuffer.use()  # reads the node image, so must not also write it
        ctx.viewport = (0, 0, *level.size)
        ctx.enable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        ctx.depth_func = "<"
        level.node.use(NODE_UNIT)
        program = self.scene_program
        program["masked"].value = True
        node_index = program["node_index"]
        sampler = self.bind_scene_inputs(program, reflection=True)
        for view in views:
            ctx.scissor = view.scissor
            ctx.front_face = "cw" if view.mirrored else "ccw"
            node_index.value = view.node
            self.bind_view(view)
            self.draw_batches(program)
            self.stats.passes += 1
        if sampler is not None:
            sampler.clear(ALBEDO_UNIT)
        ctx.front_face = "ccw"
        ctx.scissor = None

    def bind_scene_inputs(self, program: moderngl.Program, reflection: bool = False) -> moderngl.Sampler | None:
        """Bind what every scene draw reads besides the camera: lights, sky, and for a
        reflection view the albedo sampler of ``reflection_anisotropy`` (returned, to be
        cleared after the draws; None when reflections filter like the main view)."""
        self.lights_ubo.bind_to_uniform_block(LIGHTS_BINDING)
        self.sky.use(SKY_UNIT)
        program["sky_face_size"].value = self.sky.size[0]
        sampler = self._sampler_for_reflections() if reflection else None
        if sampler is not None:
            sampler.use(ALBEDO_UNIT)  # a bound sampler object overrides the texture's own filter
        return sampler

    def draw_batches(self, program: moderngl.Program) -> None:
        """One instanced draw per non-empty batch, smallest first, with a scene-shading
        ``program`` (albedo maps bound here; camera, lights, sky and targets are the caller's,
        see ``bind_scene_inputs``)."""
        has_map = program["has_albedo_map"]
        if self._order_stale:
            self._draw_order = sorted((b for b in self.batches.values() if b.count), key=lambda b: b.extent)
            self._order_stale = False
        textured = None  # the flag is written only when it changes: one call fewer per draw in a view loop
        for batch in self._draw_order:
            if not batch.count:
                continue
            if batch.texture is not None:
                batch.texture.use(ALBEDO_UNIT)
            if textured != (batch.texture is not None):
                textured = batch.texture is not None
                has_map.value = textured
            batch.draw(program)
            self.stats.draw_calls += 1
            self.stats.instances += batch.count

    def _sampler_for_reflections(self) -> moderngl.Sampler | None:
        """The albedo sampler of reflection views, or None when they filter like the main view."""
        if self.reflection_anisotropy == self.texture_anisotropy:
            return None
        sampler = self._reflection_sampler
        if sampler is None or sampler.anisotropy != self.reflection_anisotropy:
            if sampler is not None:
                sampler.release()
            sampler = self._reflection_sampler = self.ctx.sampler(
                filter=(moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR), anisotropy=self.reflection_anisotropy)
        return sampler

    def flush(self) -> None:
        """Start the GPU on the passes queued so far, before CPU-only work (``RawGL.flush``)."""
        self.raw_gl.flush()

    def present(self, output: moderngl.Framebuffer, size: tuple[int, int]) -> None:
        """Encode the HDR image to sRGB into ``output`` (a window's or a capture target)."""
        assert self.targets is not None
        output.use()
        self.ctx.scissor = None
        self.ctx.viewport = (0, 0, *size)
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        self.targets.color.use(0)
        self.present_program["exposure"].value = self.exposure
        self.fullscreen_present.render(moderngl.TRIANGLES, vertices=3)

    def release(self) -> None:
        for batch in list(self.batches.values()):
            batch.release()
        self.batches.clear()
        for table in (self._meshes, self._textures):
            for shared in table.values():
                shared.obj.release()
            table.clear()
        for targets in self.levels:
            if targets is not None:
                targets.release()
        self.levels.clear()
        self._draw_order.clear()
        if self._reflection_sampler is not None:
            self._reflection_sampler.release()
            self._reflection_sampler = None
        for obj in (self.sky, self.camera_ubo, self.lights_ubo, self.fullscreen_sky, self.fullscreen_present):
            obj.release()
        self.shaders.release()
