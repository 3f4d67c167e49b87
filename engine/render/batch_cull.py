"""Per-view batch culling: which of a pass's batches can draw a sample in which of its views,
worked out for all the views of a pass at once in a fixed handful of numpy calls.

A reflection level draws every batch in every view, and many of those draws reach no pixel:
a mirror's view sees a narrow wedge of the world through its scissor rectangle, on the far
side of its clip plane.  A draw costs several microseconds of CPU whatever it covers (the
uniforms, the driver's draw), so a batch none of whose instances' world boxes
(``InstanceBatch.row_boxes``) can reach a view is left out of that view.

The test is conservative: what it leaves out cannot draw a sample.  A view's volume is the
intersection of half-spaces in world space: its ``view_proj`` rows by Gribb and Hartmann
("Fast extraction of viewing frustum planes from the world-view-projection matrix", 2001)
with the side planes moved in to the view's scissor rectangle in NDC (``x >= l w`` ...;
a fragment's centre lies inside the rectangle, so nothing outside its edges is drawn), the
near plane, and the view's clip plane (``gl_ClipDistance``: ``dot(world, plane) >= 0`` is
kept).  The far plane is left out: its world normal is about ``2 near / far`` long, so
float32 rounding of clip coordinates moves it by far more than the margin below, and little
lies beyond it.  Every point the GL draws satisfies all six; a box whose eight corners all fail
one of them cannot hold a drawn point (the half-space's complement is convex).  A box's
largest value of a plane ``(n, d)`` is ``min(n, 0) . lo + max(n, 0) . hi + d``: one matrix
product for every (plane, box) pair.  The boxes are grown first by ``BOX_MARGIN`` of the
level's largest coordinate (the GPU places vertices in float32), so a box that touches a
plane within rounding is drawn.  A box not measured yet (NaN) compares false: drawn.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from engine.render.views import CAMERA_BLOCK_CLIP, CAMERA_BLOCK_VIEW_PROJ

if TYPE_CHECKING:
    from engine.render.instances import InstanceBatch
    from engine.render.views import View

__all__ = ["BOX_MARGIN", "CULL_MIN_BATCHES", "CULL_MIN_DRAWS", "PLANES", "batch_reach"]

# A per-view scene pass (ScenePass._draw_each) tests its opaque batches' boxes against each
# view (batch_reach) and draws a batch only where it can reach, when it has at least
# CULL_MIN_BATCHES batches and views x batches is at least CULL_MIN_DRAWS.  Measured on the
# benchmark ring at 32x18, LP_NUM_THREADS=0, cull forced on against off, interleaved: the test
# and the kept lists cost a fixed share a pass, a draw left out saves a few microseconds, and
# the share of draws left out grows with the batches (the ring's boxes in 3, 5, 10, 20 meshes
# by angle: 16%, 27%, 40%, 50% of the draws); 16 mirrors: 5 batches +6.8% a frame, 7 batches
# +2.3%, 12 -3.4%.  At these thresholds: 12 batches -5.9%, 22 -11.8%, and the benchmark scenes
# (3 batches, each reaching every view: its rows spread round the ring) never test.
CULL_MIN_BATCHES = 10
CULL_MIN_DRAWS = 64

# The planes of a view, in order: left, right, bottom, top (at its scissor rectangle), near,
# clip plane.
PLANES = 6
# How much the boxes grow, as a share of the largest coordinate of the level's boxes (at
# least of 1 world unit): float32 vertex placement is good to about 1e-7 of it.
BOX_MARGIN = 1e-4
# Scissor rectangle (x, y, width, height, 1) in pixels to the side planes' (-l, r, -b, t) in
# NDC, at a viewport of (width, height) (``_edges``): l = 2 x / W - 1, r = 2 (x + w) / W - 1.
_EDGES = np.array([[-2.0, 2.0, 0.0, 0.0],
                   [0.0, 0.0, -2.0, 2.0],
                   [0.0, 2.0, 0.0, 0.0],
                   [0.0, 0.0, 0.0, 2.0],
                   [1.0, -1.0, 1.0, -1.0]])
# Each plane as a combination of the clip-space rows (x, y, z, w); the scissor's edges fill
# the w column of the first four: x - l w >= 0, r w - x >= 0, y - b w >= 0, t w - y >= 0,
# z + w >= 0.
_COMBINATIONS = np.array([[1.0, 0.0, 0.0, 0.0],
                          [-1.0, 0.0, 0.0, 0.0],
                          [0.0, 1.0, 0.0, 0.0],
                          [0.0, -1.0, 0.0, 0.0],
                          [0.0, 0.0, 1.0, 1.0]])
# Kept between passes (a numpy call costs several microseconds on a frame's cold caches, so
# the fixed part is made once): the edge matrix of each viewport size, and by view count the
# planes' combinations (their w column written each pass), the planes, and their rows.
_edges: dict[tuple[int, int], np.ndarray] = {}
_work: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}


def batch_reach(views: Sequence[View], size: tuple[int, int],
                batches: Sequence[InstanceBatch]) -> list[list[bool]]:
    """For each of ``views`` (drawn into a viewport of ``size`` pixels), for each of
    ``batches`` (non-empty), whether any of its instances' world boxes reaches the view's
    volume (its frustum within its scissor rectangle, in front of its clip plane): False
    only where the batch cannot draw a sample in that view."""
    n = len(views)
    width, height = size
    edges = _edges.get(size)
    if edges is None:
        edges = _edges[size] = _EDGES * [[1.0 / width], [1.0 / height], [1.0 / width], [1.0 / height], [1.0]]
    work = _work.get(n)
    if work is None:
        combos = np.empty((n, PLANES - 1, 4))
        combos[:] = _COMBINATIONS
        work = _work[n] = (combos, np.empty((n, PLANES, 4)), np.empty((n * PLANES, 7)))
    combos, planes, rows = work
    blocks = np.frombuffer(b"".join([view.camera_block() for view in views]), np.float32).reshape(n, -1)
    full = (0, 0, width, height)
    rects = np.array([(*(view.scissor or full), 1.0) for view in views], np.float64)
    np.matmul(rects, edges, out=combos[:, :4, 3])
    # view_proj is column-major ([column, row]): its rows are the transpose's.
    np.matmul(combos, blocks[:, CAMERA_BLOCK_VIEW_PROJ].reshape(n, 4, 4).transpose(0, 2, 1),
              out=planes[:, :PLANES - 1])
    planes[:, PLANES - 1] = blocks[:, CAMERA_BLOCK_CLIP]
    flat = planes.reshape(n * PLANES, 4)
    # Each plane as a row against a box's (lo, hi, 1): its highest value over the box.
    np.minimum(flat[:, :3], 0.0, out=rows[:, :3])
    np.maximum(flat[:, :3], 0.0, out=rows[:, 3:6])
    rows[:, 6] = flat[:, 3]
    boxes = np.concatenate([batch.row_boxes for batch in batches])  # [box, lo/hi, xyz]
    margin = BOX_MARGIN * max(float(boxes.max()), -float(boxes.min()), 1.0)
    ends = np.empty((len(boxes), 7))
    ends[:, 6] = 1.0
    np.add(boxes.reshape(-1, 6), [-margin] * 3 + [margin] * 3, out=ends[:, :6])
    # A box is out of a view where some plane's highest value over it is below 0 (its least
    # over the planes is); a batch, where all its boxes are.  NaN (a box not measured)
    # carries through min and max and compares false: reached.
    least = (rows @ ends.T).reshape(n, PLANES, -1).min(axis=1)  # [view, box]
    starts = [0]
    for batch in batches[:-1]:
        starts.append(starts[-1] + batch.count)
    out = np.less(np.maximum.reduceat(least, starts, axis=1), 0.0)
    return np.logical_not(out, out=out).tolist()
