"""Predicted visibility leaves out the candidates the claim cull knows empty
(``engine/render/claim_cull.py``, ``tree_visibility.chosen_by_prediction``): no view, no claim or
reset, no draws, no views below, as exact visibility treats them; their claims count 0 for
the next frame.

The facts, on the ring of 8 and 16 mirrors and the portal pair, 40 frames each, against the
same engine with the cull off (every candidate a view, drawn on its claim's condition: the
predicted frames before the skip): the same colours and ids every frame; the views are a
subset of those without the skip, and every view left out counted 0 pixels there (the GPU's
own count, read a frame later: a second path); on the rings fewer views, draws, passes and
claims.  Each candidate left out is counted 0 for the next frame, so it is predicted hidden
there.  With end images (the default) a frame can differ from the one without the skip only
after a frame whose end-image "seen" surfaces differed, and then only by surfaces that no
view with pixels saw (``EndImages.keep``: a surface seen only by views that count nothing is
no longer "seen", as in exact visibility)."""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks.cpu import make_scene
from benchmarks.mirrors import DT
from components import Mirror, Portal
from engine.core.frame_io import Output
from engine.render import view_tree
from engine.render.end_images import EndImages
from engine.render.mirror_passes import MirrorPasses
from engine.render.targets import CaptureTarget
from engine.render.tree_visibility import TreeVisibility

FRAMES = 40
SCENES = [("mirrors_8", (32, 18)), ("mirrors_16", (32, 18)), ("mirrors_16", (64, 36)), ("portals_d8", (32, 18))]


def _key(node) -> tuple[int, ...]:
    """A view's chain of surface entities from the root (``RootVisibility``'s keys)."""
    chain = []
    while node.parent is not None:
        chain.append(node.surface.entity)
        node = node.parent
    return tuple(reversed(chain))


def _run(ctx, monkeypatch, scene: str, size: tuple[int, int], cull: bool, end_images: bool,
         path: str = "per_mirror") -> list[dict]:
    """Each frame of ``scene`` in predicted visibility, its levels drawn by ``path``: colours,
    ids, stats, the claims drawn, the tree's views (as keys), last frame's counts read this
    frame, the candidates left out as known empty, and the surfaces kept as seen for the end
    images.  (The path is set, not "auto": auto batches a level of three views or more, and
    its rule differs on a GPU, so a level the skip leaves fewer views could draw one draw a
    view where the other run draws one for the level.)"""
    frames: list[dict] = []
    current: dict = {}
    with monkeypatch.context() as patch:
        if not cull:
            patch.setattr(view_tree, "empty_claims", lambda *args: (None, None))
        prepare, render = MirrorPasses.prepare_level, view_tree.ViewTree.render
        visibility_of, predicted = TreeVisibility.of, view_tree.chosen_by_prediction
        keep = EndImages.keep

        def prepare_level(self, level, parent, claims, queries, *run):
            current["claims"] += sum(1 for query in queries[:len(claims)] if query is not self.no_pixels)
            return prepare(self, level, parent, claims, queries, *run)

        def rendered(self, *args, **kwargs):
            result = render(self, *args, **kwargs)
            nodes = (*result.views[1:], *result.end_views)
            current["views"] |= {_key(node) for node in nodes}
            current["shown"] |= {_key(node) for node in nodes if not node.unseen}
            return result

        def visibility(self, root):
            record = visibility_of(self, root)
            current["counts"].update(record.seen)
            return record

        def chosen(candidates, queries, none, *args):
            found = predicted(candidates, queries, none, *args)
            current["skipped"] |= {key for key, query in zip(found[3], queries, strict=True) if query is none}
            return found

        def kept(self, targets, root, seen, compare=False):
            current["seen"] = seen
            return keep(self, targets, root, seen, compare)

        patch.setattr(MirrorPasses, "prepare_level", prepare_level)
        patch.setattr(view_tree.ViewTree, "render", rendered)
        patch.setattr(TreeVisibility, "of", visibility)
        patch.setattr(view_tree, "chosen_by_prediction", chosen)
        patch.setattr(EndImages, "keep", kept)
        engine = make_scene(scene, ctx)
        engine.reflection_system.visibility = "predicted"
        engine.reflection_system.path = path
        if not end_images:
            for kind in (Mirror, Portal):
                for _, surface in engine.world.query_one(kind):
                    surface.end_image = False
        capture = CaptureTarget(ctx, size)
        try:
            for _ in range(FRAMES):
                current.clear()
                current.update(claims=0, views=set(), shown=set(), counts={}, skipped=set(), seen=frozenset())
                engine.frame(DT, Output(capture.framebuffer, size))
                stats = engine.renderer.stats
                frames.append({**current, "rgb": capture.read_rgb(), "ids": engine.renderer.targets.read_ids(),
                               "stats": (stats.reflection_views, stats.reflection_views_unseen, stats.draw_calls,
                                         stats.passes)})
        finally:
            capture.release()
            engine.close()
    return frames


@pytest.mark.parametrize("path", ("per_mirror", "batched"))
@pytest.mark.parametrize("end_images", (False, True))
@pytest.mark.parametrize("scene, size", SCENES)
def test_predicted_frames_without_known_empty_views_equal_frames_with_them(ctx, monkeypatch, scene, size,
                                                                           end_images, path):
    """The same colours and ids every frame (with end images: but after a frame whose seen
    surfaces lost one that only views counting nothing saw, or whose image differed so), the
    views a subset of the frames' without the skip, those left out counting 0 there, and on
    the rings fewer views, claims, and (drawn per mirror: a draw and a pass a view) draws
    and passes; batched, a level's views share their draws and pass."""
    skip = _run(ctx, monkeypatch, scene, size, cull=True, end_images=end_images, path=path)
    every = _run(ctx, monkeypatch, scene, size, cull=False, end_images=end_images, path=path)
    assert every[-1]["stats"][0] > 0 and every[-1]["rgb"].std() > 10, "no reflection views, or a flat frame"
    differ_after = set()
    for n, (a, b) in enumerate(zip(skip, every, strict=True)):
        where = f"{scene} {size} frame {n}"
        if n not in differ_after:  # (else it may differ: the end images' input did)
            assert np.array_equal(a["rgb"], b["rgb"]), f"{where}: colours differ"
            assert np.array_equal(a["ids"], b["ids"]), f"{where}: ids differ"
        elif not np.array_equal(a["rgb"], b["rgb"]):
            differ_after.add(n + 1)  # the next frame's end views read this frame's image
        assert a["views"] <= b["views"], f"{where}: views the tree without the skip does not have"
        if n + 1 < FRAMES:  # the views left out counted nothing (read the next frame)
            left_out = b["views"] - a["views"]
            counted = {key: every[n + 1]["counts"].get(key) for key in left_out}
            assert all(count == 0 for count in counted.values()), \
                f"{where}: views left out had pixels: {[k for k, c in counted.items() if c]}"
        if a["seen"] != b["seen"] and n + 1 < FRAMES:  # (the last frame's is read by no frame)
            assert end_images, f"{where}: end-image surfaces kept without end images"
            assert a["seen"] < b["seen"], f"{where}: the skip added seen surfaces {a['seen'] - b['seen']}"
            # Each surface only the tree without the skip keeps: every view that kept it (drawn
            # on last frame's word that it had pixels) counted 0.
            lost = b["seen"] - a["seen"]
            views = [key for key in b["shown"] if key[-1] in lost]
            assert views and all(every[n + 1]["counts"].get(key) == 0 for key in views), \
                f"{where}: a surface lost from the end images' seen set had pixels"
            differ_after.add(n + 1)
    counted = range(4) if path == "per_mirror" else (0, 1)  # (views, unseen, draws, passes)
    totals = [[sum(frame["stats"][i] for frame in run) for i in counted] + [sum(frame["claims"] for frame in run)]
              for run in (skip, every)]
    names = "views, unseen, draws, passes, claims" if path == "per_mirror" else "views, unseen, claims"
    assert all(a <= b for a, b in zip(*totals, strict=True)), f"{names} {totals}"
    if scene.startswith("mirrors"):
        assert sum(len(frame["skipped"]) for frame in skip) > 0, "the cull knew no claim empty"
        assert all(a < b for a, b in zip(*totals, strict=True)), f"{names} {totals}"


@pytest.mark.parametrize("mirrors", ("mirrors_8", "mirrors_16"))
def test_known_empty_candidates_are_counted_zero_for_the_next_frame(ctx, monkeypatch, mirrors):
    """Every candidate left out as known empty is no view, and next frame's counts hold it
    as 0 (so it is predicted hidden there: drawn unseen, with no views below, should it
    show), as the GPU would have counted its claim."""
    skip = _run(ctx, monkeypatch, mirrors, (32, 18), cull=True, end_images=True)
    assert sum(len(frame["skipped"]) for frame in skip) > 0, "the cull knew no claim empty"
    for n in range(FRAMES - 1):
        skipped, counts = skip[n]["skipped"], skip[n + 1]["counts"]
        assert not skipped & skip[n]["views"], f"frame {n}: a candidate known empty became a view"
        wrong = {key: counts.get(key) for key in skipped if counts.get(key) != 0}
        assert not wrong, f"frame {n}: known-empty candidates not counted 0 for the next frame: {wrong}"
