"""The batched mirror path (seed 000): one draw per mesh for every view of a reflection level.

The per-mirror path draws a level with one ``Renderer.render_view`` per view: every batch
once per view, each with its own camera block and scissor.  The batched path draws each
batch once per level: ``shaders/scene_batched.geom`` emits every triangle once for each
view of the level that can see it, reading the views from the ``Views`` uniform block
(std140, up to MAX_LEVEL_VIEWS), and ``scene.frag`` (built with BATCHED_VIEWS) takes the
view's node index and eye from the geometry shader.  The pixels drawn and their values are
those of the per-mirror path: the same view_proj, clip plane, eye, node mask and faces.

Which path a level takes is ``choose_path`` (``ReflectionSystem.path``).
"""
from __future__ import annotations

from collections.abc import Sequence

import moderngl
import numpy as np

from engine.render.mirror_passes import MAX_LEVEL_VIEWS
from engine.render.renderer import (
    ALBEDO_UNIT,
    CAMERA_BINDING,
    GL_CLIP_DISTANCE0,
    LIGHTS_BINDING,
    NODE_UNIT,
    SKY_UNIT,
    Renderer,
)
from engine.render.targets import RenderTargets
from engine.render.views import View

PATHS = ("auto", "per_mirror", "batched")
VIEWS_BINDING = 2
# Views per geometry-shader invocation.  One view is 3 vertices of 41 output components (48
# where whole vec4 slots count); 4 keeps 12 vertices under GL 4.1's 1024 total output
# components, and 8 invocations x 4 views cover MAX_LEVEL_VIEWS (32 invocations guaranteed).
VIEWS_PER_INVOCATION = 4
# The rectangle's four sides are clip distances 1-4 (0 is the mirror plane).
RECT_CLIP_DISTANCES = range(GL_CLIP_DISTANCE0 + 1, GL_CLIP_DISTANCE0 + 5)

# std140 layout of the Views block: ivec4 count, then per view (128 bytes)
# mat4 view_proj, vec4 clip_plane, vec4 eye (w: mirrored), vec4 rect (NDC), uvec4 node.
_VIEW_DTYPE = np.dtype([
    ("view_proj", "<f4", (16,)),
    ("clip_plane", "<f4", (4,)),
    ("eye", "<f4", (4,)),
    ("rect", "<f4", (4,)),
    ("node", "<u4", (4,)),
])
VIEWS_BLOCK_BYTES = 16 + MAX_LEVEL_VIEWS * _VIEW_DTYPE.itemsize

# The "auto" rule: batched when a level has at least AUTO_MIN_VIEWS views and the scene
# submits at most AUTO_TRIANGLES_BASE + AUTO_TRIANGLES_X_VIEWS / views triangles (every
# batch's mesh triangles x instances: what each path pushes through geometry per view).
#
# Measured on llvmpipe (Mesa 23, LLVM 15, 2 cores) in the benchmarks/mirrors.py scene at
# 640x360, with the boxes swapped for coarser and finer meshes; ctx.finish() around each
# level's draws, median ms of one level's geometry pass, per_mirror -> batched:
#
#   triangles   1 view       3 views      5-8 views     11-12 views    28-32 views
#     ~260      0.35 -> 0.65  2.4 -> 2.2   4.3 -> 3.8    16.0 -> 13.1   14.5 -> 11.1
#     ~500      0.38 -> 0.64  2.6 -> 2.2   5.0 -> 3.8    16.0 -> 16.9   12.5 -> 16.8
#     ~740      0.58 -> 0.99  3.4 -> 2.7   4.3 -> 4.2    13.7 -> 14.7   11.8 -> 16.1
#    ~1300      0.57 -> 1.13  3.0 -> 2.9   4.3 -> 8.9    20.0 -> 23.5   17.5 -> 28.0
#   ~20500      2.27 -> 7.33  7.7 -> 14.7  15.7 -> 68.1  34.3 -> 111.7  48.5 -> 270.3
#
# Batching saves the per-view fixed cost of a pass (~0.3-0.5 ms here: state, camera block,
# one draw per batch), but on llvmpipe a geometry shader costs ~0.2 us per input triangle
# per invocation before it does anything, and ~0.35 us per triangle and view in all, against
# ~0.06 us per triangle and view in the per-mirror path's vertex stage.  So batched wins
# only for light geometry, by less as views (and invocations) grow; at 2 views the two are
# within noise (0.79-1.20), at 1 view batched always loses.  A least-squares fit of the
# difference over 672 levels gives batched - per_mirror ~ -0.62 - 0.071 V + 0.35e-3 T V ms,
# zero at T ~ 200 + 1800 / V; the constants below are that line rounded up a little (their
# summed cost over the sweep is within 0.1% of the best rule of this form, 1.6% above
# choosing each level's faster path after the fact, 2.2% below always per_mirror).
# A GPU with fast geometry shaders would move the line; re-measure before trusting it there.
AUTO_MIN_VIEWS = 3
AUTO_TRIANGLES_BASE = 300
AUTO_TRIANGLES_X_VIEWS = 2000


def choose_path(setting: str, view_count: int, triangles: int) -> str:
    """The path that draws a level of ``view_count`` views of a scene submitting
    ``triangles`` triangles a view: ``setting`` unless it is "auto" (the rule above)."""
    if setting not in PATHS:
        raise ValueError(f"ReflectionSystem.path must be one of {PATHS}, got {setting!r}")
    if setting != "auto":
        return setting
    if view_count >= AUTO_MIN_VIEWS and triangles <= AUTO_TRIANGLES_BASE + AUTO_TRIANGLES_X_VIEWS / view_count:
        return "batched"
    return "per_mirror"


def submitted_triangles(renderer: Renderer) -> int:
    """Triangles one scene pass submits: each batch's mesh triangles x its instances."""
    return sum(batch.mesh.index_count // 3 * batch.count for batch in renderer.batches.values())


def views_block(views: Sequence[View]) -> bytes:
    """The Views uniform block for ``views`` (at most MAX_LEVEL_VIEWS)."""
    if len(views) > MAX_LEVEL_VIEWS:
        raise ValueError(f"{len(views)} mirror views in one level; at most {MAX_LEVEL_VIEWS}")
    table = np.zeros(MAX_LEVEL_VIEWS, _VIEW_DTYPE)
    for row, view in zip(table, views, strict=False):
        width, height = view.size
        x, y, w, h = view.scissor if view.scissor is not None else (0, 0, width, height)
        row["view_proj"] = np.frombuffer(view.view_proj.to_bytes(), np.float32)
        row["clip_plane"] = tuple(view.clip_plane)
        row["eye"] = (*view.eye, 1.0 if view.mirrored else 0.0)
        row["rect"] = (2.0 * x / width - 1.0, 2.0 * y / height - 1.0,
                       2.0 * (x + w) / width - 1.0, 2.0 * (y + h) / height - 1.0)
        row["node"] = (view.node, 0, 0, 0)
    count = np.array([len(views), 0, 0, 0], np.int32)
    return count.tobytes() + table.tobytes()


class BatchedMirrors:
    """Draws all views of a reflection level with one draw per instance batch."""

    def __init__(self, renderer: Renderer) -> None:
        self.renderer = renderer
        self.ctx = renderer.ctx
        self._programs: dict[int, moderngl.Program] = {}  # by geometry-shader invocations
        self._ubo: moderngl.Buffer | None = None

    def program(self, view_count: int) -> moderngl.Program:
        """The batched scene program for a level of ``view_count`` views, built on first use.

        Its geometry shader runs ceil(view_count / VIEWS_PER_INVOCATION) invocations rounded
        up to a power of two: invocations with no view still cost a pass over the triangles.
        """
        needed = -(-view_count // VIEWS_PER_INVOCATION)
        invocations = min(1 << max(0, needed - 1).bit_length(), -(-MAX_LEVEL_VIEWS // VIEWS_PER_INVOCATION))
        program = self._programs.get(invocations)
        if program is None:
            program = self.renderer.shaders.program("scene.vert", "scene.frag", "scene_batched.geom", defines={
                "BATCHED_VIEWS": "1",
                "MAX_LEVEL_VIEWS": str(MAX_LEVEL_VIEWS),
                "VIEWS_PER_INVOCATION": str(VIEWS_PER_INVOCATION),
                "GS_INVOCATIONS": str(invocations),
                "GS_MAX_VERTICES": str(3 * VIEWS_PER_INVOCATION),
            })
            program["Views"].binding = VIEWS_BINDING
            program["Lights"].binding = LIGHTS_BINDING
            if "Camera" in program:  # the batched stages read their cameras from Views
                program["Camera"].binding = CAMERA_BINDING
            program["albedo_map"].value = ALBEDO_UNIT
            program["sky_map"].value = SKY_UNIT
            program["node_map"].value = NODE_UNIT
            program["masked"].value = True
            self._programs[invocations] = program
        if self._ubo is None:
            self._ubo = self.ctx.buffer(reserve=VIEWS_BLOCK_BYTES)
        return program

    def render_level(self, views: Sequence[View], targets: RenderTargets) -> None:
        """Draw every batch once for all ``views`` into ``targets``, a reflection level whose
        node image and depth mask ``MirrorPasses.prepare_level`` wrote.

        Counts one pass, and one draw call per batch, in the renderer's stats.
        """
        if not views:
            return
        renderer = self.renderer
        ctx = self.ctx
        program = self.program(len(views))
        self._ubo.write(views_block(views))
        self._ubo.bind_to_uniform_block(VIEWS_BINDING)
        targets.framebuffer.use()
        ctx.viewport = (0, 0, *views[0].size)
        ctx.scissor = _union([v.scissor or (0, 0, *v.size) for v in views])
        ctx.enable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        ctx.front_face = "ccw"  # mirrored views reverse their vertices in the geometry shader
        ctx.depth_func = "<"
        for cap in RECT_CLIP_DISTANCES:
            ctx.enable_direct(cap)
        targets.node.use(NODE_UNIT)
        renderer.lights_ubo.bind_to_uniform_block(LIGHTS_BINDING)
        renderer.sky.use(SKY_UNIT)
        sky_size = program.get("sky_face_size", None)
        if sky_size is not None:
            sky_size.value = renderer.sky.size[0]
        has_map = program["has_albedo_map"]
        stats = renderer.stats
        for batch in renderer.batches.values():
            if not batch.count:
                continue
            if batch.texture is not None:
                batch.texture.use(ALBEDO_UNIT)
            has_map.value = batch.texture is not None
            batch.draw(program)
            stats.draw_calls += 1
            stats.instances += batch.count
        for cap in RECT_CLIP_DISTANCES:
            ctx.disable_direct(cap)
        ctx.scissor = None
        stats.passes += 1

    def release(self) -> None:
        if self._ubo is not None:
            self._ubo.release()
            self._ubo = None
        self._programs.clear()  # the renderer's shader library owns and releases them


def _union(rects) -> tuple[int, int, int, int]:
    rects = list(rects)
    x0 = min(r[0] for r in rects)
    y0 = min(r[1] for r in rects)
    x1 = max(r[0] + r[2] for r in rects)
    y1 = max(r[1] + r[3] for r in rects)
    return x0, y0, x1 - x0, y1 - y0
