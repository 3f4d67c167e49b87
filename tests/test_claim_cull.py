"""Claims known empty before they are drawn (``engine/render/claim_cull.py``): a candidate
whose chain of bounding boxes holds no pixel centre is not claimed, and counts 0.

The facts, on the ring of mirrors at sizes where many claims are empty: every claim the
cull calls empty counts 0 pixels when it is drawn anyway (the GPU's own count, a second
path), and the cull calls a good share of the empty ones empty; a frame drawn with the
cull equals the frame drawn without it (colours, ids; views and pixels spent too in exact
visibility, where predicted visibility draws no more), in exact and predicted visibility,
with fewer claims drawn."""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks.mirrors import DT, MirrorRing
from components import Mirror
from engine.core.frame_io import Output
from engine.render import view_tree
from engine.render.mirror_passes import MirrorPasses
from engine.render.targets import CaptureTarget
from shell.app import Engine


def _frames(ctx, mirrors: int, size: tuple[int, int], frames: int, visibility: str = "exact",
            scale: float = 1.0):
    """Each frame of the ring: (colours, ids, views, unseen views, pixels spent); ``scale``:
    every mirror's resolution_scale."""
    engine = Engine(MirrorRing(mirrors), ctx)
    engine.reflection_system.visibility = visibility
    for _, mirror in engine.world.query_one(Mirror):
        mirror.resolution_scale = scale
    capture = CaptureTarget(ctx, size)
    try:
        out = []
        for _ in range(frames):
            engine.frame(DT, Output(capture.framebuffer, size))
            stats = engine.renderer.stats
            out.append((capture.read_rgb(), engine.renderer.targets.read_ids(), stats.reflection_views,
                        stats.reflection_views_unseen, stats.pixels_spent))
        return out
    finally:
        capture.release()
        engine.close()


@pytest.mark.parametrize("mirrors, size", [(16, (32, 18)), (8, (32, 18)), (16, (64, 36))])
def test_claims_called_empty_count_no_pixels(ctx, monkeypatch, mirrors, size):
    """With every claim drawn (the cull's verdicts recorded, not used), no claim the cull
    calls empty counts a pixel, and it calls at least a third of the empty ones empty."""
    verdicts: list[list[bool] | None] = []
    cull = view_tree.empty_claims

    def recorded(*args):
        empty, chain = cull(*args)
        verdicts.append(empty)
        return None, chain

    monkeypatch.setattr(view_tree, "empty_claims", recorded)
    chosen = view_tree.ViewTree._chosen_by_counts
    pairs: list[tuple[bool, int]] = []

    def counted(self, surfaces, step, *args):
        verdict = verdicts.pop() if verdicts else None
        result = chosen(self, surfaces, step, *args)
        pairs.extend(zip(verdict or [False] * len(step.pixels), step.pixels, strict=True))
        return result

    monkeypatch.setattr(view_tree.ViewTree, "_chosen_by_counts", counted)
    _frames(ctx, mirrors, size, 24)
    called = [pixels for empty, pixels in pairs if empty]
    empty = sum(1 for _, pixels in pairs if pixels == 0)
    assert called, "the cull called no claim empty"
    assert max(called) == 0, f"{sum(1 for p in called if p)} claims called empty took pixels"
    assert len(called) >= empty / 3, f"{len(called)} of {empty} empty claims found"


@pytest.mark.parametrize("visibility, scale", [("exact", 1.0), ("predicted", 1.0), ("exact", 0.5)])
def test_frames_with_the_cull_equal_frames_without(ctx, monkeypatch, visibility, scale):
    """The ring of 16 mirrors at 32x18 and 64x36, 12 frames each: the same colours, ids,
    views and pixels with the cull and without it (predicted: no more views, unseen views or
    pixels spent), with fewer claims drawn.  At half
    resolution (every level's pixels are not the root's), nothing is culled, and nothing
    changes."""
    drawn = {"n": 0}
    prepare = MirrorPasses.prepare_level

    def counting(self, level, parent, claims, queries, *run):
        drawn["n"] += sum(1 for query in queries if query is not self.no_pixels)
        return prepare(self, level, parent, claims, queries, *run)

    monkeypatch.setattr(MirrorPasses, "prepare_level", counting)
    for size in ((32, 18), (64, 36)):
        drawn["n"] = 0
        with_cull = _frames(ctx, 16, size, 12, visibility, scale)
        claims_with = drawn["n"]
        with monkeypatch.context() as patch:
            patch.setattr(view_tree, "empty_claims", lambda *args: (None, None))
            drawn["n"] = 0
            without = _frames(ctx, 16, size, 12, visibility, scale)
        for frame, (a, b) in enumerate(zip(with_cull, without, strict=True)):
            assert np.array_equal(a[0], b[0]), f"{size} frame {frame}: colours differ"
            assert np.array_equal(a[1], b[1]), f"{size} frame {frame}: ids differ"
            if visibility == "exact":
                assert a[2:] == b[2:], f"{size} frame {frame}: views, unseen views, pixels spent {a[2:]} != {b[2:]}"
            else:  # predicted: a claim known empty is no view (tests/test_predicted_claim_skip.py)
                assert all(x <= y for x, y in zip(a[2:], b[2:], strict=True)), \
                    f"{size} frame {frame}: views, unseen views, pixels spent {a[2:]} > {b[2:]}"
        assert with_cull[-1][2] > 0
        if scale == 1.0:
            assert claims_with < drawn["n"], f"{size}: {claims_with} claims drawn with the cull, {drawn['n']} without"
