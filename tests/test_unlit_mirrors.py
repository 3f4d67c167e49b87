"""Mirrors the view tree paints over entirely are drawn unlit, in the main view and in the
tree's levels (issue 40: less pixel work in the 8-mirror frame).  Checked by a second path:
the same scene from an engine that shades every mirror (``MainViewSystem.depth_cap`` None,
``ViewTree.unlit`` False) must give the very same frame, pixel for pixel and id for id, in
the cases the rule takes (reflect rate 1, no fade) and in those it must leave alone (a lower
reflect rate, a fade, a smaller level, a pixel budget, glass in front of a mirror), with
mirrors at and past the depth limits too (their end views and fallbacks paint over them);
and by what the main view itself wrote under the mirrors before the composites: black
where the rule took them, lit where not."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from benchmarks.glass import GlassHouse
from benchmarks.mirrors import START_ANGLE, MirrorRing
from components import Material, MeshRef, Mirror, Transform, look_rotation
from engine.assets.mesh import quad
from engine.core.frame_io import Output
from engine.core.game import Game
from engine.render import unlit_mirrors
from engine.render.frame_views import FrameViews
from engine.render.targets import CaptureTarget
from engine.render.unlit_mirrors import shading_replaced
from engine.resources import Surfaces, ViewBudget
from shell.app import Engine

SIZE = (160, 90)
FRAMES = 3


def _engine(ctx, setup=None, shaded: bool = False, game: Game | None = None) -> Engine:
    engine = Engine(game or MirrorRing(8), ctx)
    if shaded:  # the second path: every mirror lit, in the main view and in the tree's levels
        engine.stages["main"].depth_cap = None
        engine.reflection_system.tree.unlit = False
    if setup is not None:
        setup(engine)
    return engine


def _mirrors(**fields):
    def setup(engine: Engine) -> None:
        for _, mirror in engine.world.query_one(Mirror):
            for name, value in fields.items():
                setattr(mirror, name, value)
    return setup


def _budget(**fields):
    def setup(engine: Engine) -> None:
        engine.world.resources[ViewBudget] = ViewBudget(**fields)
    return setup


def _cap(depth: int):
    def setup(engine: Engine) -> None:
        engine.reflection_system.max_depth_cap = depth
    return setup


def _frames(ctx, engine: Engine, frames: int = FRAMES, size=SIZE) -> list[tuple[np.ndarray, np.ndarray]]:
    capture = CaptureTarget(ctx, size)
    try:
        out = []
        for _ in range(frames):
            engine.frame(1.0 / 60.0, Output(capture.framebuffer, size))
            out.append((capture.read_rgb(), engine.renderer.targets.read_ids()))
        return out
    finally:
        capture.release()


CASES = {
    "plain": (None, 8),                                     # rate 1, no fade: all eight unlit
    "rough": (_mirrors(roughness=0.3), 8),                  # the rough composite weighs by the rate too
    "half_rate": (_mirrors(reflect_rate=0.5), 0),           # own shading is half the pixel
    "faded": (_mirrors(fade_distance=(5.0, 40.0)), 0),      # partly faded: weights are a quotient
    "small_level": (_mirrors(resolution_scale=0.5), 0),     # a smaller level misses edge pixels
    "no_depth": (_mirrors(max_depth=0), 8),                 # no view: end view or fallback, at weight 1
    "cap_0": (_cap(0), 8),
    "view_budget": (_budget(views=3), 8),                   # cut views show the fallback at weight 1
    "pixel_budget": (_budget(pixels=2000), 0),              # levels drawn smaller, decided later
    "min_pixels": (_budget(min_pixels=100), 8),             # small views show the fallback at weight 1
}


@pytest.mark.parametrize("case", list(CASES))
def test_the_frame_is_the_same_as_with_every_mirror_shaded(ctx, case):
    setup, expected_unlit = CASES[case]
    fast, shaded = _engine(ctx, setup), _engine(ctx, setup, shaded=True)
    try:
        got, want = _frames(ctx, fast), _frames(ctx, shaded)
        _same_frames(got, want)
        assert len(fast.stages["main"]._root_options().unlit) == expected_unlit
        assert shaded.stages["main"]._root_options().unlit == frozenset()
    finally:
        fast.close()
        shaded.close()


def _same_frames(got, want) -> None:
    for (image, ids), (image_ref, ids_ref) in zip(got, want, strict=True):
        assert image.max() > 40  # a picture, not a black frame
        assert np.array_equal(ids, ids_ref)
        assert np.array_equal(image, image_ref), f"{int(np.any(image != image_ref, axis=2).sum())} pixels differ"


def _unlit_draws(engine: Engine) -> int:
    """The batches with a draw record of the unlit build (ScenePass._draw_batches' kinds)."""
    return sum(any(kind[3] for kind in batch.draw_records) for batch in engine.renderer.batches.values())


def test_the_levels_draw_their_mirrors_unlit_and_every_claimed_pixel_is_composited(ctx):
    """16 mirrors, frames 0-11 at 320x180: in frame 11 a level-1 pixel of a mirror seen in a
    mirror was one the composite's quad (the outline through the parent's camera, rounded
    apart from the mesh's own triangles) left out, so its own shading showed; the composite's
    quad is now a pixel larger all round (mirror_composite.vert) and that pixel shows the
    reflection, in both paths.  Only the levels draw unlit here (the main view shades)."""
    def levels_only(engine: Engine) -> None:
        engine.stages["main"].depth_cap = None

    fast = _engine(ctx, levels_only, game=MirrorRing(16))
    shaded = _engine(ctx, shaded=True, game=MirrorRing(16))
    try:
        got, want = _frames(ctx, fast, 12, (320, 180)), _frames(ctx, shaded, 12, (320, 180))
        assert _unlit_draws(fast) == 1 and _unlit_draws(shaded) == 0
        assert max(view.level for view in fast.reflection_system.views) >= 3
        _same_frames(got, want)
    finally:
        fast.close()
        shaded.close()


@pytest.mark.parametrize("pose", ["start", "mirror_wall", "doorway", "back_mirror"])
def test_the_sample_level_with_its_ghost_and_pond_is_the_all_lit_frame(ctx, monkeypatch, pose):
    """The sample level's ghost (alpha 0.7, seen only in mirrors) stands before the mirror
    wall, and its pond is a see-through mirror.  The ghost is glass: a tree draws it after
    the composites, over the reflections.  The pond is drawn with the opaque batches (the
    claims find its pixels; ScenePass._drawn_now), so a view keeps lit the mirrors it can
    blend over and draws the others unlit (unlit_mirrors._UnlitViews); the frame is the
    all-lit path's.  (Glass alone keeps them unlit: tests/test_glass_over_reflection.py.)"""
    from tests.golden_scenes import HALL_POSES, _hall

    def place(engine: Engine) -> None:
        if HALL_POSES[pose] is not None:
            engine.place_camera(*HALL_POSES[pose])

    seen = _count_kept(monkeypatch)
    fast, shaded = _engine(ctx, place, game=_hall()), _engine(ctx, place, shaded=True, game=_hall())
    try:
        got, want = _frames(ctx, fast, 2, (320, 180)), _frames(ctx, shaded, 2, (320, 180))
        assert fast.renderer.transparent_batches()
        kept, lost = seen[fast.renderer.scene_pass.unlit_boxes]
        assert kept > 10, (kept, lost)  # views with the pond drawn before their claims drew mirrors unlit
        _same_frames(got, want)
    finally:
        fast.close()
        shaded.close()


def test_the_main_view_writes_no_light_under_the_mirrors_it_draws_unlit(ctx):
    """What the main view drew under each mirror, read before the reflect stage paints over
    it: the unlit build's black, and the mirror's lit shading from the engine that shades it."""
    def main_view_colour(engine: Engine) -> tuple[np.ndarray, np.ndarray, set[int]]:
        _frames(ctx, engine, 2)
        mirrors = set(engine.world.resources[Surfaces].mirrors)
        engine.stages["main"].process(1.0 / 60.0)  # the main view alone, into level 0
        targets = engine.world.resources[FrameViews].levels[0]
        w, h = targets.size
        colour = np.frombuffer(targets.color.read(), np.float16).reshape(h, w, 4).astype(np.float32)
        surface = np.frombuffer(targets.surface.read(), np.uint32).reshape(h, w)
        return colour, surface, mirrors

    fast, shaded = _engine(ctx), _engine(ctx, shaded=True)
    try:
        colour, surface, mirrors = main_view_colour(fast)
        colour_ref, surface_ref, _ = main_view_colour(shaded)
    finally:
        fast.close()
        shaded.close()
    under = np.isin(surface, list(mirrors))
    assert under.sum() > 200  # the mirrors cover pixels of the main view
    assert np.array_equal(surface, surface_ref)  # the same ids and depth test outcome
    assert np.all(colour[under] == (0.0, 0.0, 0.0, 1.0))
    assert colour_ref[under][:, :3].max() > 0.01  # lit where the mirrors are shaded
    assert np.array_equal(colour[~under], colour_ref[~under])  # everything else as it was


def test_a_mirror_changed_at_run_time_is_shaded_again(ctx):
    """The main view's set follows the surfaces: a reflect rate lowered after some frames
    takes that mirror's batch back to the lit build, and the frame stays the second path's."""
    fast, shaded = _engine(ctx), _engine(ctx, shaded=True)
    try:
        _frames(ctx, fast, 2)
        _frames(ctx, shaded, 2)
        assert len(fast.stages["main"]._root_options().unlit) == 8
        for engine in (fast, shaded):
            entity, mirror = next(iter(engine.world.query_one(Mirror)))
            mirror.reflect_rate = 0.6
        got, want = _frames(ctx, fast, 2), _frames(ctx, shaded, 2)
        assert entity not in fast.stages["main"]._root_options().unlit
        assert len(fast.stages["main"]._root_options().unlit) == 7
        _same_frames(got, want)
    finally:
        fast.close()
        shaded.close()


def test_shading_replaced_takes_only_what_the_composites_paint_over_at_weight_one(ctx):
    engine = _engine(ctx)
    try:
        _frames(ctx, engine, 1)
        states = list(engine.world.resources[Surfaces].mirrors.values())
    finally:
        engine.close()
    everyone = {state.entity for state in states}
    assert shading_replaced(states) == everyone
    assert shading_replaced(states, pixel_budget=True) == frozenset()
    from dataclasses import replace
    first = states[0]
    for change in ({"reflect_rate": 0.99}, {"enabled": False}, {"fade": (1.0, 2.0, 1e30, 2e30)},
                   {"resolution_scale": 0.5}, {"water": object()}, {"kind": "portal"}):
        changed = [replace(first, **change), *states[1:]]
        assert shading_replaced(changed) == everyone - {first.entity}, change


def _ring_setup(max_depth: int, end_image: bool, visibility: str):
    def setup(engine: Engine) -> None:
        _mirrors(max_depth=max_depth, end_image=end_image)(engine)
        engine.reflection_system.visibility = visibility
    return setup


RING_CASES = [(count, depth, end, vis) for count in (8, 16) for depth in (1, 2, 3)
              for end in (True, False) for vis in ("exact", "predicted")]


@pytest.mark.parametrize("count,depth,end,vis", RING_CASES)
def test_mirrors_at_the_depth_limit_are_unlit_and_the_frame_is_the_same(ctx, count, depth, end, vis):
    """Rings of 8 and 16 mirrors at max_depth 1-3, end images on and off, exact and
    predicted visibility, four frames: every mirror unlit at every level, its views at the
    limit shown by end views and fallbacks, the frames the all-lit path's bit for bit (they
    differed before the end candidates with nothing to repeat got the fallback, b8de431)."""
    setup = _ring_setup(depth, end, vis)
    fast = _engine(ctx, setup, game=MirrorRing(count))
    shaded = _engine(ctx, setup, shaded=True, game=MirrorRing(count))
    try:
        got, want = _frames(ctx, fast, 4, (320, 180)), _frames(ctx, shaded, 4, (320, 180))
        assert len(fast.stages["main"]._root_options().unlit) == count
        assert max(view.level for view in fast.reflection_system.views) == depth  # views reach the limit
        assert fast.renderer.stats.reflection_fallbacks > 0
        if end and depth == 3:  # the ring's end views (none at depths 1-2: nothing up their chains to repeat)
            assert fast.renderer.stats.reflection_end_views > 0
        _same_frames(got, want)
    finally:
        fast.close()
        shaded.close()


def _count_kept(monkeypatch) -> dict:
    """Per scene pass (its ``unlit_boxes``), [candidates kept unlit, made lit] over the views that drew transparent
    batches before their composites (``unlit_mirrors._UnlitViews.keep``), counted as frames run."""
    counts: dict = {}
    narrowed = unlit_mirrors._UnlitViews.keep

    def counting(check, view, drawn):
        kept = narrowed(check, view, drawn)
        if check.unlit and drawn:
            count = counts.setdefault(check.boxes, [0, 0])
            count[0] += len(kept)
            count[1] += len(check.unlit) - len(kept)
        return kept

    monkeypatch.setattr(unlit_mirrors._UnlitViews, "keep", counting)
    return counts


class _RingWithSeeThrough(GlassHouse):
    """The glass benchmark's ring of 8 (``benchmarks.glass``: a see-through pond at the
    centre, ``panes`` glass panes round it) and a see-through mirror standing at the centre
    facing the camera's start, in front of the far side of the ring: a tree draws it before
    its claims, so where it covers a mirror it blends over that mirror's own colour."""

    def build(self, world) -> None:
        super().build(world)
        towards = glm.normalize(glm.vec3(math.cos(START_ANGLE), 0.0, math.sin(START_ANGLE)))
        world.spawn(Transform(position=(0.0, 1.6, 0.0), rotation=look_rotation(-towards)), MeshRef(quad(3.0, 2.0)),
                    Material(color=(0.3, 0.35, 0.4, 0.5)), Mirror(reflect_rate=0.7))


@pytest.mark.parametrize("panes,path", [(0, "per_mirror"), (6, "per_mirror"), (6, "batched")])
def test_see_through_surfaces_keep_lit_only_the_mirrors_they_can_blend_over(ctx, monkeypatch, panes, path):
    """A see-through surface is drawn before the claims (its pixels are claimed), so a mirror
    it blends over must be shaded in that view; every other view draws the ring's mirrors
    unlit (``unlit_mirrors._UnlitViews``: screen rectangles and depth), and the frames are
    the all-lit path's, pixel for pixel and id for id.  (A batched level draws its views
    at once: unlit only where no view's surfaces can blend over them, here seldom.)"""
    counts = _count_kept(monkeypatch)

    def setup(engine: Engine) -> None:
        engine.reflection_system.path = path

    fast = _engine(ctx, setup, game=_RingWithSeeThrough(panes))
    shaded = _engine(ctx, setup, shaded=True, game=_RingWithSeeThrough(panes))
    try:
        got, want = _frames(ctx, fast, 4, (320, 180)), _frames(ctx, shaded, 4, (320, 180))
        _same_frames(got, want)
        kept, lost = counts[fast.renderer.scene_pass.unlit_boxes]
        seen = {"kept": kept, "lost": lost}
        assert len(fast.stages["main"]._root_options().unlit) == 8
        if path == "per_mirror":
            assert seen["kept"] > 10 and seen["lost"] > 2, seen  # unlit in most views, lit where covered
        else:
            assert seen["kept"] + seen["lost"] > 2, seen
    finally:
        fast.close()
        shaded.close()


class _RandomGlassAndMirrors(Game):
    """``tests.test_slot_order``'s random panes, ponds and see-through mirrors, with six
    opaque mirrors (reflect rate 1: drawn unlit where nothing blends over them) among them,
    a light, a floor and the camera at a random place looking in."""

    def __init__(self, seed: int) -> None:
        self.seed = seed

    def build(self, world) -> None:
        import random

        from components import Camera, DirectionalLight
        from tests.test_slot_order import _random_level
        rng = random.Random(self.seed)
        _random_level(self.seed, 10, 2, 1, {})(world)   # (its sky too)
        world.spawn(DirectionalLight(direction=(-0.4, -1.0, -0.3), intensity=1.5))
        for _ in range(6):
            yaw = glm.angleAxis(rng.uniform(0, 2 * math.pi), glm.vec3(0, 1, 0))
            world.spawn(Transform(position=(rng.uniform(-4, 4), rng.uniform(-1, 2), rng.uniform(-5, 3)), rotation=yaw),
                        MeshRef(quad(rng.uniform(2, 4), rng.uniform(2, 3))), Material(color=(0.1, 0.1, 0.1)), Mirror())
        eye = glm.vec3(rng.uniform(-4, 4), rng.uniform(0, 3), rng.uniform(5, 8))
        world.spawn(Transform(position=eye, rotation=look_rotation(glm.vec3(0, 0, 0) - eye)), Camera(fov_y=70.0))


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_random_glass_among_mirrors_is_the_all_lit_frame(ctx, monkeypatch, seed):
    """Random see-through surfaces and panes among opaque mirrors, from a random place: the
    mirrors each view keeps unlit (``unlit_mirrors._UnlitViews``) leave the frames the all-lit
    path's, pixel for pixel and id for id."""
    counts = _count_kept(monkeypatch)
    fast = _engine(ctx, game=_RandomGlassAndMirrors(seed))
    shaded = _engine(ctx, shaded=True, game=_RandomGlassAndMirrors(seed))
    try:
        got, want = _frames(ctx, fast, 2, (192, 108)), _frames(ctx, shaded, 2, (192, 108))
        _same_frames(got, want)
        assert sum(counts.get(fast.renderer.scene_pass.unlit_boxes, [0, 0])) > 0  # views chose
    finally:
        fast.close()
        shaded.close()
