"""Per-view batch culling (engine/render/batch_cull.py): a per-view pass leaves out a batch
whose instances' boxes cannot reach a view (its frustum within its scissor rectangle, in front
of its clip plane), a batched level's draw one that reaches none of its views.  Checked
against what it must not change and against the GL itself:

* the frames, colours and entity ids, are the same bytes with the cull on (on every pass:
  its thresholds set to 1) and off, frame by frame over the benchmark's mirror ring (8 and
  16 mirrors, the camera orbiting, boxes spinning; at 8 with ambient occlusion in the
  mirrors' level too, whose depth and normals pass culls as its draw does), the same ring with every box its own
  mesh (its own batch: left at the scene pass's own thresholds; with auto and predicted
  visibility, the latter drawing each view conditionally on its claim) and the facing
  portal pair (exact and predicted visibility), and that ring of boxes with 4 mirrors drawn
  batched, where a level's views leave some boxes out;
* every draw it leaves out is one the unculled frame made (draw calls on + culled == draw
  calls off), and on the ring with a batch a box it leaves out draws
  (``RenderStats.draws_culled``);
* the oracle: each batch it leaves out of a view, drawn anyway into that view with the depth
  test passing everything and writes off, inside a samples query, counts no sample.
"""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks.mirrors import MirrorRing
from benchmarks.portals import FacingPortals, set_depth
from components import AmbientOcclusion, Camera, MeshRef
from engine.assets.mesh import box
from engine.core.frame_io import Output
from engine.render.scene_pass import ScenePass
from engine.render.targets import CaptureTarget
from shell.app import Engine
from tests.support import own_mesh

SIZE = (96, 54)
FRAMES = 14


class BoxPerBatch(MirrorRing):
    """The benchmark ring with each box its own mesh, so its own batch (a level of many
    meshes, where a mirror's view reaches only some)."""

    def build(self, world) -> None:
        super().build(world)
        for entity, (ref,) in world.query(MeshRef):
            if ref.mesh.name == "bench box":
                world.add_component(entity, MeshRef(own_mesh(box(name=f"box {entity}"))))


def _engine(ctx, case: str, cull: bool):
    kind, arg, *visibility = case.split("_")
    if kind in ("ring", "boxes", "occluded", "batched"):
        engine = Engine((BoxPerBatch if kind in ("boxes", "batched") else MirrorRing)(int(arg)), ctx)
        engine.reflection_system.path = "batched" if kind == "batched" else "per_mirror"
        if kind == "occluded":  # the mirrors' level found too: its depth and normals pass culls alike
            for camera, _ in engine.world.query_one(Camera):
                engine.world.add_component(camera, AmbientOcclusion(radius=0.8))
        if visibility:  # the views' draws conditional on their claims (predicted: last frame's)
            engine.reflection_system.visibility = visibility[0]
    else:
        engine = Engine(FacingPortals(), ctx)
        set_depth(engine, 8)
        engine.reflection_system.visibility = arg
    scene_pass = engine.renderer.scene_pass
    scene_pass.cull_batches = cull
    if kind != "boxes":  # every pass tests (the scene pass's own thresholds leave these out)
        scene_pass.cull_min_batches = scene_pass.cull_min_draws = 1
    return engine


CASES = ("ring_8", "ring_16", "boxes_16", "boxes_16_predicted", "batched_4", "portals_exact", "portals_predicted",
         "occluded_8")


@pytest.mark.parametrize("case", CASES)
def test_frames_are_the_same_with_the_cull_on_and_off(ctx, case):
    engines = [_engine(ctx, case, cull) for cull in (True, False)]
    captures = [CaptureTarget(ctx, SIZE) for _ in engines]
    culled = 0
    try:
        for frame in range(FRAMES):
            images = []
            for engine, capture in zip(engines, captures, strict=True):
                engine.frame(1.0 / 60.0, Output(capture.framebuffer, SIZE))
                images.append((capture.read_rgb(), engine.renderer.targets.read_ids(),
                               engine.renderer.targets.read_surface_ids()))
            on, off = (engine.renderer.stats for engine in engines)
            for a, b in zip(*images, strict=True):
                assert np.array_equal(a, b), (case, frame)
            assert off.draws_culled == 0
            assert on.draw_calls + on.draws_culled == off.draw_calls, (case, frame)
            assert on.reflection_views == off.reflection_views > 0
            if len(case.split("_")) == 3:
                assert on.reflection_visibility == case.split("_")[2]
            culled += on.draws_culled
        rgb, ids, _ = images[0]
        assert rgb.std() > 10 and len(np.unique(ids)) > 5  # a real frame, not a blank one
    finally:
        for capture in captures:
            capture.release()
        for engine in engines:
            engine.close()
    if case.startswith("boxes"):
        assert culled > FRAMES * 16, culled  # a mirror's view reaches only some of the boxes
    if case.startswith("batched"):
        assert culled > 0  # a box that none of a level's views reaches


@pytest.mark.parametrize("case", ("ring_16", "boxes_16"))
def test_a_culled_batch_draws_no_sample(ctx, case, monkeypatch):
    """Each batch left out of a view is drawn anyway, counted by a samples query with the
    depth test passing every fragment and nothing written: it must count 0.  (The view's
    clip plane, scissor and claimed-pixels mask still apply: they are what the cull reads
    or what can only take samples away.)"""
    original_draw, original_reaching = ScenePass._draw_batches, ScenePass._reaching
    counted: list[tuple[int, int, int]] = []
    left_out: list = []  # what the view about to draw left out (ScenePass._reaching, then its draws)

    def reaching(self, batches, reach, view):
        kept = original_reaching(self, batches, reach, view)
        left_out[:] = [batch for batch in batches if batch not in kept]
        return kept

    def draw_batches(self, batches, invocations, masked, layered="", skip=0, before_draw=None, hide=0,
                     unlit=frozenset(), screen=""):
        original_draw(self, batches, invocations, masked, layered, skip, before_draw, hide, unlit, screen)
        left, left_out[:] = list(left_out), []
        if not left:
            return
        ctx = self.ctx
        fbo = ctx.fbo
        colour, depth = fbo.color_mask, fbo.depth_mask
        off = (False,) * 4
        fbo.color_mask = tuple(off for _ in colour) if isinstance(colour[0], tuple) else off
        fbo.depth_mask = False
        ctx.depth_func = "1"
        try:
            query = ctx.query(samples=True)
            for batch in left:
                with query:
                    original_draw(self, [batch], invocations, masked, layered, skip, before_draw, hide, unlit)
                counted.append((batch.entity_at[0], batch.count, query.samples))
        finally:
            fbo.color_mask, fbo.depth_mask = colour, depth
            ctx.depth_func = "<"  # the per-view scene pass's (scene_pass._SCENE; moderngl cannot read it)

    monkeypatch.setattr(ScenePass, "_reaching", reaching)
    monkeypatch.setattr(ScenePass, "_draw_batches", draw_batches)
    engine = _engine(ctx, case, True)
    capture = CaptureTarget(ctx, SIZE)
    try:
        for _ in range(6):
            engine.frame(1.0 / 60.0, Output(capture.framebuffer, SIZE))
    finally:
        capture.release()
        engine.close()
    assert counted, case  # some batches were culled and checked
    assert [c for c in counted if c[2]] == [], case
