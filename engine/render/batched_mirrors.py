"""The batched mirror path's rule and data: which path draws a reflection level, and the
table of views the geometry shader reads.

The per-mirror path draws a level with ``ScenePass.draw`` view by view: every batch once
per view, each with its own camera block and scissor.  The batched path (the same pass with
``SceneOptions.batched``) draws each batch once per level: ``shaders/scene_batched.geom``
emits every triangle once for each view of the level that can see it, reading the views
from the ``Views`` uniform block (std140, up to MAX_BATCHED_VIEWS), and ``scene.frag``
(built with BATCHED_VIEWS) takes the view's node index and eye from the geometry shader.
The pixels drawn and their values are those of the per-mirror path: the same view_proj,
clip plane, eye, node mask and faces (tests/test_mirror_paths.py).  The geometry shader
culls, per view, triangles behind the mirror or outside the view's frustum or screen
rectangle, and clips the rest to that rectangle with clip distances (the per-mirror
path's scissor).  This is the one-draw technique of the "Multiple Mirrors" OpenGL project.

Which path a level takes is ``choose_path`` (``ReflectionSystem.path``).  On llvmpipe the
batched path is rarely faster (see the measurements above AUTO_MIN_VIEWS), so "auto" takes
it only for the lightest scenes there.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from engine.render.gpu import Gpu
from engine.render.views import CAMERA_BLOCK_CLIP, CAMERA_BLOCK_EYE, CAMERA_BLOCK_IDS, CAMERA_BLOCK_VIEW_PROJ, View

PATHS = ("auto", "per_mirror", "batched")
# Views one batched draw takes (a level with more is drawn in groups of this many).  The
# Views block is 16 + 128 bytes a view, well under GL 4.1's 16 KiB minimum block size.
MAX_BATCHED_VIEWS = 32
# Views per geometry-shader invocation.  One view is 3 vertices of 41 output components (48
# where whole vec4 slots count; 49 and 56 in the OBJECT_MOTION builds, two clip positions
# more); 4 keeps 12 vertices under GL 4.1's 1024 total output components, and 8 invocations
# x 4 views cover MAX_BATCHED_VIEWS (32 invocations guaranteed).
VIEWS_PER_INVOCATION = 4
# std140 layout of the Views block: ivec4 count, then per view (128 bytes)
# mat4 view_proj, vec4 clip_plane, vec4 eye (w: mirrored), vec4 rect (NDC), uvec4 node (node,
# skip, hide, view mask: View.view_mask).
_VIEW_DTYPE = np.dtype([
    ("view_proj", "<f4", (16,)),
    ("clip_plane", "<f4", (4,)),
    ("eye", "<f4", (4,)),
    ("rect", "<f4", (4,)),
    ("node", "<u4", (4,)),
])
VIEWS_BLOCK_BYTES = 16 + MAX_BATCHED_VIEWS * _VIEW_DTYPE.itemsize
_VIEW_FLOATS = _VIEW_DTYPE.itemsize // 4

# The "auto" rule: batched when a level has at least AUTO_MIN_VIEWS views and the scene
# submits at most AUTO_MAX_TRIANGLES triangles (each batch's mesh triangles x instances,
# what both paths push through geometry once per view); per_mirror otherwise.
#
# Measured on llvmpipe (Mesa 22.3, LLVM 15, 2 cores, 640x360; the machine was shared, so
# the paths ran interleaved frame by frame).  Whole frames of ``python -m benchmarks
# mirrors`` (incl. ctx.finish(), median ms, per_mirror / batched):
#
#   scene (triangles)                   4 mirrors      8 mirrors      16 mirrors
#   benchmark, 20 boxes (~260)          57.0 / 57.6    70.3 / 73.1    120.7 / 126.4
#   boxes as 20 meshes (22 batches)     35.6 / 38.3    49.0 / 51.4     99.2 / 111.4
#   no boxes (18-34)                         -         47.2 / 44.8    106.5 / 107.7
#
# Per level, the app-thread time of the level's draws (where the paths differ: both
# rasterise the same pixels), mean ms per_mirror / batched:
#
#   triangles     1 view       2 views      3-8 views    11-12 views   28-32 views
#     <= 34       0.32 / 0.37  0.83 / 0.89  2.43 / 2.29  3.75 / 3.75   3.71 / 3.40
#     60-95       0.39 / 0.51  0.72 / 0.70  2.12 / 2.25  3.74 / 3.83   3.69 / 4.63
#     120-155     0.40 / 0.51  0.78 / 0.94  2.41 / 2.56  4.54 / 4.96   4.91 / 5.87
#     250-274          -       0.73 / 0.91  2.06 / 2.59  5.78 / 7.14   6.29 / 9.29
#     ~1300            -       1.17 / 2.03  3.17 / 3.64  5.15 / 12.95  5.93 / 21.28
#
# A per-mirror view costs ~0.1 ms of its own (state, camera block, ~7 us a draw).  The
# batched draw's geometry shader runs on llvmpipe's app thread: with the lightest geometry
# a 28-32 view level still costs ~1 ms a draw (8 invocations), and each triangle adds
# ~0.4 us per view against ~0.06 us in the per-mirror vertex stage.  So batching pays only
# for the lightest geometry with several views, and there by ~5-8% of the level's draw
# time, a few percent of a frame.  On a GPU, where geometry amplification is cheap and a
# pass's CPU overhead is the bottleneck, the balance is likely the other way: re-measure.
AUTO_MIN_VIEWS = 3
AUTO_MAX_TRIANGLES = 40
#
# On a GPU (NVIDIA H200, 2026-11-26, .whl/vis_exp.py in one process, engines interleaved,
# predicted visibility; whole frames, median ms, per_mirror / batched):
#
#   scene (triangles a view)        4 mirrors     8 mirrors     16 mirrors
#   benchmark ring (274), 640x360       -         5.37 / 5.19   10.89 / 8.98
#   benchmark ring (274), 1080p         -         5.99 / 5.81   10.86 / 9.24
#   ring + five 64x32 spheres (20754)   3.17 / 3.81      -       9.63 / 70.67
#
# The batched draw saves ~16 us of CPU a view; its geometry shader costs ~30 ns a triangle a
# view against ~4 ns through the per-mirror vertex stage, so it pays below ~600 triangles.
AUTO_GPU_MAX_TRIANGLES = 512


def choose_path(setting: str, view_count: int, triangles: int | Callable[[], int], software: bool = True) -> str:
    """The path that draws a level of ``view_count`` views of a scene submitting
    ``triangles`` triangles a view (or a function that counts them, called only where the
    view count could batch): ``setting`` unless it is "auto" (the rules above: on a
    ``software`` rasteriser, or on a GPU)."""
    if setting not in PATHS:
        raise ValueError(f"ReflectionSystem.path must be one of {PATHS}, got {setting!r}")
    if setting != "auto":
        return setting
    if view_count < AUTO_MIN_VIEWS:
        return "per_mirror"
    limit = AUTO_MAX_TRIANGLES if software else AUTO_GPU_MAX_TRIANGLES
    if (triangles() if callable(triangles) else triangles) <= limit:
        return "batched"
    return "per_mirror"


def submitted_triangles(renderer: Gpu) -> int:
    """Triangles one scene pass submits: each batch's mesh triangles x its instances."""
    return sum(batch.mesh.index_count // 3 * batch.count for batch in renderer.batches.values())


def views_block(views: Sequence[View]) -> bytes:
    """The Views uniform block for ``views`` (at most MAX_BATCHED_VIEWS), read from their
    packed Camera blocks in a few array operations (a level's views come with their blocks
    packed by the planner: one numpy row a view cost ~10 us a view)."""
    count = len(views)
    if count > MAX_BATCHED_VIEWS:
        raise ValueError(f"{count} mirror views in one level; at most {MAX_BATCHED_VIEWS}")
    rows = np.zeros((MAX_BATCHED_VIEWS, _VIEW_FLOATS), np.float32)
    if count:
        blocks = np.frombuffer(b"".join(view.camera_block() for view in views), np.float32).reshape(count, -1)
        rows[:count, 0:16] = blocks[:, CAMERA_BLOCK_VIEW_PROJ]
        rows[:count, 16:20] = blocks[:, CAMERA_BLOCK_CLIP]
        rows[:count, 20:23] = blocks[:, CAMERA_BLOCK_EYE]
        rows[:count, 23] = [1.0 if view.mirrored else 0.0 for view in views]
        # The screen rectangle in NDC: the scissor, or the whole target.
        rects = np.array([view.scissor if view.scissor is not None else (0, 0, *view.size) for view in views],
                         np.float64)
        sizes = np.array([(*view.size, *view.size) for view in views], np.float64)
        rects[:, 2:4] += rects[:, 0:2]  # x0, y0, x1, y1
        rows[:count, 24:28] = 2.0 * rects / sizes - 1.0
        # (skip, hide, view mask, node) in the block; (node, skip, hide, view mask) in the row.
        rows[:count, 28:32].view(np.uint32)[:] = blocks[:, CAMERA_BLOCK_IDS].view(np.uint32)[:, (3, 0, 1, 2)]
    return np.array([count, 0, 0, 0], np.int32).tobytes() + rows.tobytes()
