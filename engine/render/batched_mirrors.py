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

import struct
from collections.abc import Callable, Sequence

import numpy as np

from engine.render.gpu import Gpu
from engine.render.views import CAMERA_BYTES, CAMERA_EYE_BYTES, View, way_scale

PATHS = ("auto", "per_mirror", "batched")
# Views one batched draw takes (a level with more is drawn in groups of this many).  The
# Views block is 16 + 128 bytes a view, well under GL 4.1's 16 KiB minimum block size.
MAX_BATCHED_VIEWS = 32
# std140 layout of the Views block: ivec4 count, then per view (128 bytes)
# mat4 view_proj, vec4 clip_plane, vec4 eye (w: its way scale, negative: mirrored), vec4 rect (NDC), uvec4 node (node,
# skip, hide, view mask: View.view_mask).
_VIEW_DTYPE = np.dtype([
    ("view_proj", "<f4", (16,)),
    ("clip_plane", "<f4", (4,)),
    ("eye", "<f4", (4,)),
    ("rect", "<f4", (4,)),
    ("node", "<u4", (4,)),
])
VIEWS_BLOCK_BYTES = 16 + MAX_BATCHED_VIEWS * _VIEW_DTYPE.itemsize
_ROW_BYTES = _VIEW_DTYPE.itemsize
_NO_ROWS = bytes(MAX_BATCHED_VIEWS * _ROW_BYTES)
_COUNT, _RECT = struct.Struct("<4i"), struct.Struct("<4f")
_EYE_W = struct.Struct("<f")   # the eye's w: the view's way scale, negative where it is mirrored
_VIEW_PROJ, _CLIP, _IDS = CAMERA_BYTES["view_proj"], CAMERA_BYTES["clip_plane"], CAMERA_BYTES["skip"]

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
# The glass slot, drawn in groups of views, wrote a Views table a group (26 a frame for the
# panes, ~29 us each): with each view's row packed once (``views_row``) and a table the
# buffer holds not written again, the same run at 32x18 gave 0.88 (hall), 0.90 (with its
# sphere), 0.99 (the panes) and 0.95 (16 mirrors), batched over per mirror; at 640x360 the
# paths stay within 5% either way, 13% at 16 mirrors in one run and 3% the other way in
# another.  So "auto" keeps llvmpipe's rule: the lightest scenes only, with several views.
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
# more than the draws it saves): measure it on the next GPU lent (``python -m benchmarks
# mirrors --spheres 5``), until then the old one.  On llvmpipe that scene (2026-12-04,
# 640x360, 10 frames) drew 35.8 / 37.6 ms at 4 mirrors and 130 / 147 at 16, per mirror /
# batched: the views' vertex stage left out by the per-view cull.
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
    """The Views uniform block for ``views`` (at most MAX_BATCHED_VIEWS): the count, each
    view's row (``views_row``), then zeros."""
    count = len(views)
    if count > MAX_BATCHED_VIEWS:
        raise ValueError(f"{count} mirror views in one level; at most {MAX_BATCHED_VIEWS}")
    rest = _NO_ROWS[:(MAX_BATCHED_VIEWS - count) * _ROW_BYTES]
    return b"".join((_COUNT.pack(count, 0, 0, 0), *map(views_row, views), rest))


def views_row(view: View) -> bytes:
    """``view``'s row of the Views block, packed once a view (a View is made for one pass and
    not changed after) from its Camera block's bytes: a level drawn in groups (the glass
    slot's) writes a table a group, and numpy rows cost ~25 us a table (issue 40)."""
    row = view._views_row
    if row is None:
        block = view.camera_block()
        width, height = view.size
        x, y, w, h = view.scissor if view.scissor is not None else (0, 0, width, height)
        ids = block[_IDS]  # (skip, hide, view mask, node) in the block; (node, skip, hide, view mask) in the row
        row = view._views_row = b"".join((
            block[_VIEW_PROJ], block[_CLIP], block[CAMERA_EYE_BYTES],
            _EYE_W.pack(-way_scale(view) if view.mirrored else way_scale(view)),
            _RECT.pack(2.0 * x / width - 1.0, 2.0 * y / height - 1.0, 2.0 * (x + w) / width - 1.0,
                       2.0 * (y + h) / height - 1.0),  # the screen rectangle in NDC: the scissor, or the whole target
            ids[12:16], ids[0:12]))
    return row
