"""The batched mirror path's rule and data: which path draws a reflection level, and the
table of views its draws read.

The per-mirror path draws a level with ``ScenePass.draw`` view by view: every batch once
per view, each with its own camera block and scissor.  The batched path (the same pass with
``SceneOptions.batched``) draws each batch once for a group of the level's views
(``instanced_groups``: one winding, at most MAX_BATCHED_VIEWS): instanced views, the
technique of single-pass instanced stereo.  The draw has count x n instances, and the
batch's vertex array advances its instance rows every n instances (``InstanceBatch.vao``),
so instance i is row i / n drawn by view i % n; ``scene.vert`` (its ``INSTANCED_VIEWS``
build) reads that view from the ``Views`` uniform block (std140, ``views_block``), clips
to its mirror plane and to its screen rectangle with clip distances (the per-mirror path's
scissor), and hands ``scene.frag`` (built with BATCHED_VIEWS) the view's node index and
eye.  The pixels drawn and their values are those of the per-mirror path: the same
view_proj, clip plane, eye, node mask and faces (tests/test_mirror_paths.py).  Each
triangle costs what it costs there, a pass through the vertex stage a view; what the path
saves is a view's draws, state and camera block.

(It replaced a geometry shader that emitted each triangle once per view, the one-draw
technique of the "Multiple Mirrors" OpenGL project: on an H200 that shader cost ~30 ns a
triangle a view against the vertex stage's ~4, and on llvmpipe it ran on the app thread; a
one-pass cube-map capture still takes its faces that way, ``shaders/scene_layered.geom``.)

Which path a level takes is ``choose_path`` (``ReflectionSystem.path``; the measurements
are above AUTO_MIN_VIEWS).
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
# what both paths push through the vertex stage once per view); per_mirror otherwise.
#
# Measured on llvmpipe (Mesa 22.3, LLVM 15, 2 cores, shared; every case's engines in one
# process, interleaved 4 frames at a time, exact visibility, nothing kept; 2026-12-04),
# whole frames incl. ctx.finish(), median ms, per_mirror / batched:
#
#   scene (triangles, views)              32x18, LP_NUM_THREADS=0    640x360
#   hall of tests/test_mirror_paths (38)  2.23 / 2.13 (15 views)    21.0 / 21.0 (19)
#   the same with its sphere (262)        2.52 / 2.45               22.0 / 21.2
#   benchmark ring, 8 mirrors (258)       3.11 / 3.17 (14)          21.4 / 22.1 (19)
#   benchmark ring, 16 mirrors (274)      5.72 / 5.45 (40)          37.0 / 36.0 (98)
#   ring of 8 and 4 glass panes (268)     5.16 / 5.96 (14)          29.0 / 29.6 (23)
#
# At 16 mirrors and 32x18 the batched path makes 13 draws where the per-mirror one makes
# 112, but its draws' time falls only from 1.67 to 1.46 ms: on llvmpipe a view's vertex
# stage (~7.5 us a batch here), which both paths run, outweighs its draw's state (~6.5 us).
# So the paths are within the machine's noise of each other except where the glass slot
# is drawn in groups (15% dearer), and "auto" keeps llvmpipe's old rule: the lightest
# scenes only, with several views.
AUTO_MIN_VIEWS = 3
AUTO_MAX_TRIANGLES = 40
#
# On a GPU (NVIDIA H200, 2026-11-26, .whl/vis_exp.py in one process, engines interleaved,
# predicted visibility; whole frames, median ms, per_mirror / batched, the batched path
# then a geometry shader's):
#
#   scene (triangles a view)        4 mirrors     8 mirrors     16 mirrors
#   benchmark ring (274), 640x360       -         5.37 / 5.19   10.89 / 8.98
#   benchmark ring (274), 1080p         -         5.99 / 5.81   10.86 / 9.24
#   ring + five 64x32 spheres (20754)   3.17 / 3.81      -       9.63 / 70.67
#
# The batched draw saved ~16 us of CPU a view; that geometry shader cost ~30 ns a triangle a
# view against ~4 ns through the per-mirror vertex stage, so it paid below ~600 triangles.
# The instanced draw runs the vertex stage as the per-mirror path does, so its limit lies
# higher (where the batches the per-mirror path culls view by view, ``batch_cull``, cost
# more than the draws it saves): measure it on the next GPU lent, until then the old one.
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


def instanced_groups(views: Sequence[View]) -> list[list[int]]:
    """The positions in ``views`` of each group one batched draw takes: views of one winding
    (a mirrored view's front faces are clockwise, and a draw culls by one winding) and at
    most MAX_BATCHED_VIEWS of them; those not mirrored first."""
    groups = []
    for mirrored in (False, True):
        same = [at for at, view in enumerate(views) if view.mirrored == mirrored]
        groups += [same[first:first + MAX_BATCHED_VIEWS] for first in range(0, len(same), MAX_BATCHED_VIEWS)]
    return groups


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
