"""A reflection level whose claim rectangles overlap none of the others' draws its views with
the scene program built without the node-image test (``view_tree._APART``: depth alone is the
claim test there), and the frame is the one the masked build draws.

The facts: ``_claims_apart`` says what a numpy pixel count of the rectangles says (the second
path); on the ring of mirrors at least one level is drawn unmasked, and every frame matches,
byte for byte, the frame of the same engine made to draw every level masked."""
from __future__ import annotations

import numpy as np
import pytest

import engine.render.view_tree as view_tree
from benchmarks.mirrors import DT, MirrorRing
from engine.core.frame_io import Output
from engine.render.scene_pass import ScenePass
from engine.render.targets import CaptureTarget
from shell.app import Engine


def _overlap_by_pixels(rects: list[tuple[int, int, int, int]]) -> bool:
    """Whether two rectangles cover one pixel: each painted into a count image."""
    counts = np.zeros((64, 64), np.int32)
    for x, y, w, h in rects:
        counts[y:y + h, x:x + w] += 1
    return bool((counts > 1).any())


def test_claims_apart_matches_a_pixel_count():
    rng = np.random.default_rng(7)
    seen = {True: 0, False: 0}
    for _ in range(400):
        n = int(rng.integers(1, 7))
        rects = [tuple(int(v) for v in (*rng.integers(0, 48, 2), *rng.integers(0, 16, 2))) for _ in range(n)]
        apart = view_tree._claims_apart(rects)
        assert apart == (not _overlap_by_pixels(rects)), rects
        seen[apart] += 1
    assert seen[True] > 20 and seen[False] > 20  # both answers were checked
    # Rectangles that share an edge share no pixel.
    assert view_tree._claims_apart([(0, 0, 4, 4), (4, 0, 4, 4), (0, 4, 4, 4)])
    assert not view_tree._claims_apart([(0, 0, 4, 4), (3, 3, 4, 4)])


def _frames(ctx, mirrors: int, size: tuple[int, int], masked_always: bool, monkeypatch) -> tuple[list, list]:
    """Three frames of the ring, and the ``masked`` of every reflection level's scene draw."""
    drawn = []
    draw = ScenePass.draw

    def recording(self, views, targets, options, *args, **kwargs):
        if not options.clear:  # a reflection level (a root clears)
            drawn.append(options.masked)
        return draw(self, views, targets, options, *args, **kwargs)

    with monkeypatch.context() as patch:
        patch.setattr(ScenePass, "draw", recording)
        if masked_always:
            patch.setattr(view_tree, "_claims_apart", lambda rects: False)
        engine = Engine(MirrorRing(mirrors), ctx)
        # (exact visibility, a GPU's "auto" predicting: a level drawn on its claims' conditions
        # keeps the node test, view_tree._APART)
        engine.reflection_system.visibility = "exact"
        capture = CaptureTarget(ctx, size)
        frames = []
        try:
            for _ in range(3):
                engine.frame(DT, Output(capture.framebuffer, size))
                frames.append(capture.read_rgb().copy())
        finally:
            capture.release()
            engine.close()
    return frames, drawn


# 8 mirrors: levels whose claims lie apart; 16: levels whose claims overlap (drawn masked).
@pytest.mark.parametrize("mirrors, apart", [(8, True), (16, False)])
def test_unmasked_levels_draw_the_masked_frame(ctx, monkeypatch, mirrors, apart):
    size = (192, 108)
    frames, drawn = _frames(ctx, mirrors, size, False, monkeypatch)
    reference, reference_drawn = _frames(ctx, mirrors, size, True, monkeypatch)
    assert (drawn.count(False) >= 1) == apart  # drawn without the node test where the claims lie apart
    assert drawn.count(True) >= (0 if apart else 1)
    assert reference_drawn and all(reference_drawn)
    for frame, expected in zip(frames, reference, strict=True):
        assert expected.std() > 5.0  # a real frame, not a blank one
        np.testing.assert_array_equal(frame, expected)
