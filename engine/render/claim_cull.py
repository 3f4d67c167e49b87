"""Claims that cannot take a pixel, found on the CPU before any is drawn.

A candidate view's claim (``MirrorPasses.prepare_level``, shaders/mirror_claim.frag) takes
the pixels of its level where the level above shows its parent view and, in it, its
surface.  A pixel is rasterised where its centre lies inside a triangle, so a pixel of the
claim has its centre inside the surface's mesh as the parent view projects it, and (the
parent owns the pixel only where its own claim took it) inside the parent's surface's mesh
as the grandparent projects it, and so on up to the root.  So the claim's pixels have their
centres inside the intersection of those projections' bounding boxes, the chain's box:
where no pixel centre is inside it, the claim is empty, and its draw and its query are
skipped (``empty_claims``; its count is 0, as the GPU would have counted: which views a
level draws is what it was).  In either visibility such a candidate is no view
(``ViewTree``): exact visibility would find it without pixels, and predicted visibility,
which draws a view on its claim's condition, skips its claim's reset, its draws, its views
below and its composite, and counts it 0 for the next frame (predicted hidden there).  On
the 16-mirror ring at 32x18 that is ~90 of a frame's ~160 claims (~123 of them empty).

Each candidate's own box is the cull's rectangle before it is rounded outwards
(``SurfaceTable.cull``, kept as ``Candidates.box`` by the plan): the bounding box of its
surface's box corners through its parent's projection (x and y in pixels, less one: x0 - 1,
y0 - 1, -x1 - 1, -y1 - 1, so intersecting is a maximum), -inf where a corner is at or behind
the eye plane (bounds nothing).  A mirror's mesh lies inside its box; a portal's mesh may be
any shape (its corners are its ``Portal.size``), so a portal's own box bounds nothing.  A
centre within ``MARGIN`` pixels of a box counts as inside (float32 on the GPU, float64 here;
the rasteriser's sub-pixel snapping).  The levels are single-sampled: a pixel is covered at
its centre (multisampled levels would need the sample positions).  A level at another
resolution than the root's, or below one, breaks the chain (``ViewTree``): its pixels, or its
parent's, are not the root's.  Nothing here waits for the GPU or reads its images: the test
is the planner's arrays, a handful of numpy calls a level.

One case differs from drawing every claim: a mirror that travels through a portal has a
``PortalClone`` drawn as the mirror (its id in the surface image) where its box does not
reach; a claim only ever covers its rectangle, the box rounded out by a pixel or two, so
what the cull drops there is a clone's pixels in that border of a mirror that covers no pixel
centre itself (before, they showed a view of the mirror's plane; now the clone's own look).

Why the claims left are empty, measured (exact visibility, 60 frames after 20, each empty
drawn claim's parent images read back and its surface's quad projected through its parent):
on the 16-mirror ring at 32x18, 32.9 drawn claims a frame of 69 count 0.  18.5 of them are
depth occlusion in the parent view (its quad covers pixel centres the parent owns, and a box
or the ground, 16.6, another mirror, 1.3, or both, 0.6, is nearer there) and 5.6 more lost
their parent's pixels to occlusion higher up: not knowable without drawing.  8.6 hold no pixel
centre in the chain of their surfaces' quads (a polygon test up the chain would find them),
6.6 of those none in their own quad within the chain box; 0.1 are clipped by the parent's
plane.  So a test of the quads can find at most ~26% of them (~8.6 x 4-5 us a claim), and a
level of separating-axis tests (the quad's edges against the chain box) costs ~15-40 us in a
warm loop, about twice that in a frame, on each of the two or three tested levels: more than
it saves, so the boxes are where this cull stops.  (At 64x36: 30.8 of 99 empty, 15.6
occluded in the parent view, 7.9 without a centre in the chain of quads.)  Counted again
later (100 frames after 20, 16 mirrors at 32x18), level by level: candidates, culled here,
drawn and empty, views: level 1 11.5, 0, 0.2, 11.3; level 2 59.6, 31.2, 12.3, 16.1; level 3
87.2, 57.9, 19.4, 9.9 (the deepest with views: each is drawn and composited); level 4 1.3,
1.1, 0.2, 0.  A surface facing away from its parent view is no candidate (the planner's
cull).  Reading a level's counts costs the wait for its first one (~30-45 us: llvmpipe
rasterising the reset and the claims); the other reads ~0.14 us each.
"""
from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from engine.render.plan_rows import ROW

if TYPE_CHECKING:
    from engine.render.view_plan import SurfaceTable

MARGIN = 1.0 / 16.0   # pixels: a centre this near a box counts as inside
_NODE = ROW["node"].start
# Added to a box before its ceiling: a box [b0, b1, b2, b3] = [x0 - 1, y0 - 1, -x1 - 1, -y1 - 1]
# holds a pixel centre i + 0.5 in x where ceil(x0 - 0.5 - MARGIN) <= floor(x1 - 0.5 + MARGIN),
# that is ceil(b0 + 0.5 - MARGIN) + ceil(b2 + 1.5 - MARGIN) <= 0 (and the same in y).
_TO_FIRST_LAST = np.array([0.5 - MARGIN, 0.5 - MARGIN, 1.5 - MARGIN, 1.5 - MARGIN])
_TABLES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


@dataclass
class ChainBoxes:
    """A level's candidates' chain boxes (``empty_claims``', for the next level): row i of
    ``boxes`` is candidate i's [x0 - 1, y0 - 1, -x1 - 1, -y1 - 1] in its level's pixels
    (-inf: unbounded), and ``nodes`` their node indices (rising: a level's nodes are
    numbered in candidate order)."""

    boxes: np.ndarray
    nodes: np.ndarray


def _own_bounds(table: SurfaceTable) -> np.ndarray | None:
    """What is added to each SurfaceTable row's box: 0 for a mirror, -inf for a portal (its
    box bounds nothing), as (S, 4) rows; None where every surface is a mirror (nothing to
    add).  Kept while the table lives."""
    found = _TABLES.get(table, False)
    if found is False:
        found = _TABLES[table] = None if table.is_mirror.all() else \
            np.where(table.is_mirror, 0.0, -np.inf)[:, None].repeat(4, axis=1)
    return found


def empty_claims(table: SurfaceTable, box: np.ndarray, surface_rows: np.ndarray, parents: np.ndarray,
                 parent_rows: np.ndarray, above: ChainBoxes | None,
                 nodes: np.ndarray) -> tuple[list[bool] | None, ChainBoxes]:
    """Which of a level's candidates cannot claim a pixel (None: none is known empty), and
    the chain boxes its children are tested against.  ``box``: the candidates' own boxes
    (``Candidates.box``, from a table with a mirror), ``surface_rows`` their SurfaceTable
    rows; ``parents``: the parent views' ``LevelRows`` data, ``parent_rows`` each
    candidate's; ``above``: the level above's boxes (None at the first level, or where the
    chain broke); ``nodes``: the candidates' node indices (every level of the chain at the
    root's size).  The first level is not tested: its boxes are the root's own views of the
    surfaces, whose rectangles the cull already keeps only where they have pixels (on the
    mirror ring at 32x18 no first-level claim was ever found empty this way), so only its
    boxes are kept for the levels below."""
    bounds = _own_bounds(table)
    boxes = box if bounds is None else box + bounds.take(surface_rows, axis=0)
    if above is None:
        return None, ChainBoxes(boxes, nodes)
    rows = np.searchsorted(above.nodes, parents[:, _NODE]).take(parent_rows)
    boxes = np.maximum(boxes, above.boxes.take(rows, axis=0))
    first_last = np.ceil(boxes + _TO_FIRST_LAST)
    sums = first_last[:, 0:2] + first_last[:, 2:4]  # first less last centre, in x and in y
    empty = (np.maximum(sums[:, 0], sums[:, 1]) > 0.0).tolist()
    return (empty if True in empty else None), ChainBoxes(boxes, nodes)
