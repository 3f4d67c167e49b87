"""What preparing a reflection level leaves in its images (``MirrorPasses.prepare_level``: the
reset over every claim's rectangle, then each claim into the node image and depth alone).

The facts, read back right after each level is prepared on the ring of mirrors and checked
against the same claims computed with numpy from the parent level's node and surface images
(the second path): in every claim's rectangle the node image holds the claim's view where
the parent pixel shows its parent view and its surface and no view elsewhere, depth is the
far plane where claimed and the near plane elsewhere, and the colour and both id images are
zero (what a reflection view's pixel holds where it draws nothing); each claim's query
counts its pixels."""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks.mirrors import DT, MirrorRing
from components import Mirror
from engine.core.frame_io import Output
from engine.render.mirror_passes import MirrorPasses
from engine.render.targets import CaptureTarget
from shell.app import Engine

NO_NODE = 0xFFFFFFFF


def _image(texture, dtype) -> np.ndarray:
    """A texture's first component as (height, width), row 0 at the bottom (GL's)."""
    w, h = texture.size
    data = np.frombuffer(texture.read(), dtype)
    return data.reshape(h, w, -1)[..., 0] if data.size != w * h else data.reshape(h, w)


def _expected_nodes(parent_node, parent_surface, level_size, claims) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """The node image in the claims' rectangles (NO_NODE where none claims), the mask of
    the rectangles' pixels, and each claim's pixel count, from the parent's images: a
    level pixel's parent pixel is floor((p + 0.5) x parent / level), as claim.frag reads it."""
    w, h = level_size
    ph, pw = parent_node.shape
    to_x, to_y = np.float32(pw / w), np.float32(ph / h)
    px = np.floor((np.arange(w, dtype=np.float32) + np.float32(0.5)) * to_x).astype(int)
    py = np.floor((np.arange(h, dtype=np.float32) + np.float32(0.5)) * to_y).astype(int)
    nodes_seen = parent_node[np.ix_(py, px)]
    surfaces_seen = parent_surface[np.ix_(py, px)]
    expected = np.full((h, w), NO_NODE, np.uint32)
    in_rects = np.zeros((h, w), bool)
    counts = []
    for _, (x, y, rw, rh) in zip(claims.ids, claims.rects, strict=True):
        in_rects[y:y + rh, x:x + rw] = True
    for (parent_view, surface, view), (x, y, rw, rh) in zip(claims.ids, claims.rects, strict=True):
        mine = np.zeros((h, w), bool)
        mine[y:y + rh, x:x + rw] = True
        mine &= (nodes_seen == parent_view) & (surfaces_seen == surface)
        assert not (expected[mine] != NO_NODE).any(), "two claims took one pixel"
        expected[mine] = view
        counts.append(int(mine.sum()))
    return expected, in_rects, counts


@pytest.mark.parametrize("mirrors, size, scale", [(8, (160, 90), 1.0), (8, (160, 90), 0.5), (16, (128, 72), 1.0)])
def test_prepared_level_images(ctx, monkeypatch, mirrors, size, scale):
    checked = []
    prepare = MirrorPasses.prepare_level

    def checking(self, level, parent, claims, queries, *run):
        prepare(self, level, parent, claims, queries, *run)
        if not claims:
            return
        ctx.finish()
        expected, in_rects, counts = _expected_nodes(_image(parent.node, np.uint32), _image(parent.surface, np.uint32),
                                                     level.size, claims)
        node = _image(level.node, np.uint32)
        np.testing.assert_array_equal(node[in_rects], expected[in_rects])
        depth = _image(level.depth, np.float32)
        claimed = in_rects & (expected != NO_NODE)
        assert (depth[claimed] == 1.0).all() and (depth[in_rects & ~claimed] == 0.0).all()
        for texture in (level.surface, level.seen):
            assert not _image(texture, np.uint32)[in_rects].any()
        color = np.frombuffer(level.color.read(), np.float16).reshape(level.size[1], level.size[0], 4)
        assert not color[in_rects].any()
        drawn = [query for query in queries[:len(claims)] if query is not self.no_pixels]
        got = self.claimed_pixels(queries[:len(claims)])
        assert got == [n if q is not self.no_pixels else 0 for n, q in zip(counts, queries[:len(claims)], strict=True)]
        checked.append((len(claims), len(drawn), int(claimed.sum()), int(in_rects.sum())))

    monkeypatch.setattr(MirrorPasses, "prepare_level", checking)
    engine = Engine(MirrorRing(mirrors), ctx)
    for _, mirror in engine.world.query_one(Mirror):
        mirror.resolution_scale = scale
    capture = CaptureTarget(ctx, size)
    try:
        for _ in range(3):
            engine.frame(DT, Output(capture.framebuffer, size))
            rgb = capture.read_rgb()
    finally:
        capture.release()
        engine.close()
    assert rgb.std() > 5.0  # a real frame, not a blank one
    # Levels were prepared, claims drawn, and pixels both claimed and left to the reset.
    assert len(checked) >= 3
    assert sum(c[2] for c in checked) > 0 and sum(c[3] - c[2] for c in checked) > 0
