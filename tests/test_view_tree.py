"""The view tree's limits: every view with pixels is drawn, a budget keeps the biggest and
says what it dropped, and the depth cap is a setting that agrees with the components'."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, DirectionalLight, Emissive, Material, MeshRef, Mirror, Portal, Transform
from engine.assets.mesh import box, quad, sphere
from engine.render.mirror_passes import MirrorPasses
from engine.render.tree_walk import MAX_TREE_DEPTH
from tests.support import look_from

FACING_BACK = glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))


def mirror_grid(ents, columns=10, rows=6):
    """``columns`` x ``rows`` small mirrors on a wall facing the camera (sizes vary by
    column), and a large emissive red panel behind the camera that each of them reflects."""
    def build(world):
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))
        look_from(world, (0.0, 1.5, 4.0), target=(0.0, 1.5, -2.0), fov=70.0)
        ents["mirrors"] = []
        for c in range(columns):
            for r in range(rows):
                size = 0.25 + 0.03 * c + 0.01 * r
                ents["mirrors"].append(world.spawn(
                    Transform(position=(-3.6 + 0.8 * c, 0.2 + 0.55 * r, -2.0)), MeshRef(quad(size, size * 0.8)),
                    Material(color=(0.1, 0.1, 0.1)), Mirror()))
        ents["panel"] = world.spawn(Transform(position=(0, 1.5, 9.0), scale=(40, 20, 0.1)), MeshRef(box()),
                                    Material(color=(0.9, 0.1, 0.1)), Emissive(1.0))
    return build


def test_sixty_mirrors_each_get_their_view(scene):
    """More views than a level used to hold (32): every mirror with pixels shows its
    reflection (the red panel), none shows its own surface."""
    ents = {}
    runner = scene(mirror_grid(ents), (320, 200))
    runner.frame()
    surface = runner.engine.renderer.targets.read_surface_ids()
    seen = runner.ids()
    visible = [m for m in ents["mirrors"] if (surface == m).any()]
    assert len(visible) == 60
    assert runner.stats.reflection_views == 60 and runner.stats.reflection_views_dropped == 0
    for mirror in visible:
        on_it = surface == mirror
        assert (seen[on_it] == ents["panel"]).mean() > 0.9, f"mirror {mirror} does not show the panel"


def test_a_level_budget_keeps_the_views_with_the_most_pixels_and_reports_the_rest(scene):
    ents = {}
    runner = scene(mirror_grid(ents), (320, 200))
    runner.engine.reflection_system.level_budget = 10
    runner.frame()
    surface = runner.engine.renderer.targets.read_surface_ids()
    seen = runner.ids()
    pixels = {m: int((surface == m).sum()) for m in ents["mirrors"]}
    tenth = sorted(pixels.values(), reverse=True)[9]
    assert runner.stats.reflection_views == 10 and runner.stats.reflection_views_dropped == 50
    shows_panel = {m for m in ents["mirrors"] if (seen[surface == m] == ents["panel"]).mean() > 0.9}
    assert len(shows_panel) == 10
    assert {m for m in pixels if pixels[m] > tenth} <= shows_panel  # every bigger one is kept
    assert all(pixels[m] >= tenth for m in shows_panel)  # and none smaller (ties at the tenth may go either way)


def facing_pair(ents, depth):
    def build(world):
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))
        look_from(world, (0.3, 1.5, 2.0), target=(0.0, 1.5, -4.0), fov=50.0)
        for z, turn in ((-4.0, None), (4.0, FACING_BACK)):
            ents.setdefault("mirrors", []).append(world.spawn(
                Transform(position=(0, 1.5, z), rotation=turn or glm.quat()), MeshRef(quad(4, 3)),
                Material(color=(0.1, 0.1, 0.1)), Mirror(max_depth=depth)))
        ents["ball"] = world.spawn(Transform(position=(0.8, 1.2, 0.0)), MeshRef(sphere(0.3)),
                                   Material(color=(0.1, 0.8, 0.2)), Emissive(0.5))
    return build


def test_a_depth_12_facing_pair_with_the_cap_at_12_shows_12_nested_images(scene):
    ents = {}
    runner = scene(facing_pair(ents, 12), (320, 240))
    runner.engine.reflection_system.max_depth_cap = 12
    runner.frame()
    views = runner.engine.reflection_system.views[1:]
    assert [v.level for v in views] == list(range(1, 13))
    assert runner.stats.reflection_views == 12 and runner.stats.reflection_depth_capped == 0
    for outer, inner in zip(views, views[1:], strict=False):  # each image inside the one before
        ox, oy, ow, oh = outer.rect
        ix, iy, iw, ih = inner.rect
        assert ox <= ix and oy <= iy and ix + iw <= ox + ow and iy + ih <= oy + oh and iw * ih < ow * oh
    # The innermost image shows the ball's copy: reflections go all the way down.
    x, y, w, h = views[-1].rect
    seen = runner.ids()
    rows = slice(seen.shape[0] - (y + h), seen.shape[0] - y)  # rects count rows from the bottom
    assert (seen[rows, x:x + w] == ents["ball"]).any()


def test_reaching_the_cap_is_reported(scene):
    ents = {}
    runner = scene(facing_pair(ents, 12), (160, 120))
    runner.engine.reflection_system.max_depth_cap = 5
    runner.frame()
    assert runner.stats.reflection_views == 5
    assert runner.stats.reflection_depth_capped == 1  # the mirrors' own limit allowed a sixth


def test_the_cap_and_the_components_depth_limits_agree():
    Mirror(max_depth=MAX_TREE_DEPTH)
    Portal(max_depth=MAX_TREE_DEPTH)
    with pytest.raises(ComponentValueError, match="Mirror.max_depth"):
        Mirror(max_depth=MAX_TREE_DEPTH + 1)
    with pytest.raises(ComponentValueError, match="Portal.max_depth"):
        Portal(max_depth=MAX_TREE_DEPTH + 1)


def test_a_cap_beyond_the_limit_is_refused_when_set(scene):
    runner = scene(lambda world: look_from(world, (0, 1.5, 3)), (32, 32))
    system = runner.engine.reflection_system
    system.max_depth_cap = MAX_TREE_DEPTH
    with pytest.raises(ValueError, match=r"depth_cap must be an int in \[0, 16\]"):
        system.max_depth_cap = MAX_TREE_DEPTH + 1
    with pytest.raises(ValueError, match="level_budget"):
        system.level_budget = 0
    assert system.max_depth_cap == MAX_TREE_DEPTH and system.level_budget is None
    assert np.asarray(runner.frame()).shape == (32, 32, 3)


def test_a_world_without_mirrors_or_portals_plans_nothing(scene, monkeypatch):
    """No mirror or portal: the tree is its root alone, and no level is planned (the planner's
    fixed cost is not paid by a frame that has nothing to reflect); a mirror added later is
    planned and drawn."""
    from engine.render.view_plan import SurfaceTable

    planned = []
    original = SurfaceTable.plan
    monkeypatch.setattr(SurfaceTable, "plan", lambda self, *a, **k: planned.append(1) or original(self, *a, **k))

    def build(world):
        look_from(world, (0, 1.5, 5), (0, 1.5, 0))
        world.spawn(DirectionalLight())
        world.spawn(Transform(position=(0, 1, 0)), MeshRef(box()), Material(color=(0.8, 0.2, 0.2)))

    runner = scene(build, (64, 48))
    runner.frame()
    assert planned == [] and len(runner.engine.reflection_system.views) == 1
    assert runner.stats.reflection_views == 0
    runner.world.spawn(Transform(position=(0, 1.5, -2)), MeshRef(quad(3, 3)), Material(), Mirror())
    runner.frame()
    assert planned and runner.stats.reflection_views == 1


def _pair_and_side_mirror(ents, end_image="auto", depth=6):
    """``facing_pair``'s mirrors (``depth``, with ``end_image``) and a third on the left wall,
    seen at level 1 beside the pair's first, and an occluder kept far below until a test
    moves it."""
    def build(world):
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))
        ents["camera"] = look_from(world, (0.3, 1.5, 2.0), target=(0.0, 1.5, -4.0), fov=50.0)
        for z, turn in ((-4.0, None), (4.0, FACING_BACK)):
            ents.setdefault("pair", []).append(world.spawn(
                Transform(position=(0, 1.5, z), rotation=turn or glm.quat()), MeshRef(quad(4, 3)),
                Material(color=(0.1, 0.1, 0.1)), Mirror(max_depth=depth, end_image=end_image)))
        ents["side"] = world.spawn(Transform(position=(-2.5, 1.5, -1.5),
                                             rotation=glm.angleAxis(glm.pi() / 2, glm.vec3(0, 1, 0))),
                                   MeshRef(quad(1.5, 1.5)), Material(color=(0.1, 0.1, 0.1)), Mirror(max_depth=6))
        ents["ball"] = world.spawn(Transform(position=(0.8, 1.2, 0.0)), MeshRef(sphere(0.3)),
                                   Material(color=(0.1, 0.8, 0.2)), Emissive(0.5))
        ents["occluder"] = world.spawn(Transform(position=(0.0, -50.0, 0.0)), MeshRef(box((1.2, 2.0, 1.2))),
                                       Material(color=(0.8, 0.2, 0.2)))
    return build


def _planned_tree(runner) -> list[tuple]:
    """What a render planned, view by view: its place in the tree, surface, rectangles,
    node, fade and camera (from its packed block)."""
    return [(node.index, node.level, node.parent.index, node.surface.entity, node.rect, node.fade, node.view.scissor,
             node.view.node, node.view.view.to_bytes(), node.view.proj.to_bytes(), node.view.view_proj.to_bytes(),
             node.view.eye.to_bytes()) for node in runner.engine.reflection_system.views[1:]]


def _facing_pair(ents, kind, end_image):
    """A facing pair of mirrors, or of portals each other's exit, and a ball between."""
    def build(world):
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))
        ents["camera"] = look_from(world, (0.3, 1.5, 2.0), target=(0.0, 1.5, -4.0), fov=50.0)
        for z, turn in ((-4.0, None), (4.0, FACING_BACK)):
            surface = Mirror(max_depth=6, end_image=end_image) if kind == "mirror" else \
                Portal(size=(4.0, 3.0), max_depth=6, end_image=end_image)
            ents.setdefault("pair", []).append(world.spawn(
                Transform(position=(0, 1.5, z), rotation=turn or glm.quat()), MeshRef(quad(4, 3)),
                Material(color=(0.1, 0.1, 0.1)), surface))
        if kind == "portal":
            front, back = ents["pair"]
            world.get(front, Portal).partner = back
            world.get(back, Portal).partner = front
        world.spawn(Transform(position=(0.8, 1.2, 0.0)), MeshRef(sphere(0.3)), Material(color=(0.1, 0.8, 0.2)),
                    Emissive(0.5))
    return build


@pytest.mark.parametrize(("kind", "end_image"), (("mirror", False), ("mirror", "auto"), ("portal", False)))
def test_a_chain_planned_in_one_run_draws_the_tree_planned_level_by_level(scene, monkeypatch, kind, end_image):
    """A facing pair (mirrors: claim boxes kept; portals: none) seen head on is a chain of
    one view a level, which the levels planned ahead plan in one run from the surfaces of
    the root's last render's levels (``SurfaceTable.plan_chain``).  While the camera moves,
    the trees and the frames equal, frame by frame, those of a tree planning each level
    after its parent's claims (``plan_ahead`` False), with the pair's end images or without
    them (past its depth limit it shows its fallback)."""
    from engine.render.view_plan import SurfaceTable

    chained: list[int] = []  # levels planned a run
    original = SurfaceTable.plan_chain
    monkeypatch.setattr(SurfaceTable, "plan_chain", lambda *a, **k: chained.append(len(planned := original(
        *a, **k))) or planned)
    ents = {True: {}, False: {}}
    runners = {chains: scene(_facing_pair(ents[chains], kind, end_image), (160, 120)) for chains in (True, False)}
    for chains, runner in runners.items():
        runner.engine.reflection_system.tree.plan_ahead = chains
        runner.engine.reflection_system.visibility = "exact"  # (a GPU's auto predicts: no counts to plan from)
    runs = []
    for frame in range(4):
        trees, images = {}, {}
        for chains, runner in runners.items():
            transform = runner.world.get(ents[chains]["camera"], Transform)
            transform.position = glm.vec3(0.3 + 0.02 * frame, 1.5, 2.0)  # a moving camera: nothing kept
            chained.clear()
            images[chains] = runner.frame()
            if chains:
                runs.append(list(chained))
            trees[chains] = _planned_tree(runner)
        assert len(trees[True]) >= 4, (frame, len(trees[True]))
        assert trees[True] == trees[False], f"frame {frame}: the trees differ"
        assert images[True].std() > 5.0 and np.array_equal(images[True], images[False]), f"frame {frame}"
    assert runs[0] == [] and all(run and min(run) >= 2 for run in runs[1:]), runs  # (a first render: nothing before)


@pytest.mark.parametrize(("end_image", "depth"), (("auto", 6), (False, 3)))
def test_levels_planned_ahead_are_the_levels_planned_one_at_a_time(scene, monkeypatch, end_image, depth):
    """Exact visibility plans each level from its parent level's claim counts; where the
    root's last render made every candidate of a level a view that grew, the levels below
    it are planned ahead, back to back, before its claims (``plan_ahead.plan_ahead``), and
    used only where the counts make every candidate a view again.  The trees equal, frame
    by frame, those of a tree that plans each level after its parent's claims (``plan_ahead``
    False) while the camera moves, and when an occluder hides the side mirror seen at
    level 1 (its plans made ahead are made again, from the pair's view alone), and so do
    the frames: with the pair's end images (planning ahead stops at a level with end
    views) and without (the pair past its depth limit, 3, shows its fallback there, whose
    pairs are found ahead too)."""
    from engine.render.view_plan import SurfaceTable

    events: list[str] = []
    for owner, name, label in ((SurfaceTable, "plan", "plan"), (MirrorPasses, "prepare_level", "claim")):
        original = getattr(owner, name)
        monkeypatch.setattr(owner, name, lambda *a, _original=original, _label=label, **k:
                            events.append(_label) or _original(*a, **k))
    ents = {True: {}, False: {}}
    runners = {ahead: scene(_pair_and_side_mirror(ents[ahead], end_image, depth), (160, 120))
               for ahead in (True, False)}
    for ahead, runner in runners.items():
        runner.engine.reflection_system.tree.plan_ahead = ahead
        runner.engine.reflection_system.visibility = "exact"  # (a GPU's auto predicts: no counts to plan from)
    orders: dict[bool, list[list[str]]] = {True: [], False: []}
    for frame in range(4):
        trees, images = {}, {}
        for ahead, runner in runners.items():
            transform = runner.world.get(ents[ahead]["camera"], Transform)
            transform.position = glm.vec3(0.3 + 0.02 * frame, 1.5, 2.0)  # a moving camera: nothing kept
            if frame == 2:  # in front of the side mirror
                runner.world.get(ents[ahead]["occluder"], Transform).position = glm.vec3(-1.3, 1.5, 0.2)
            events.clear()
            images[ahead] = runner.frame()
            orders[ahead].append(list(events))
            trees[ahead] = _planned_tree(runner)
            level_1 = {node.surface.entity for node in runner.engine.reflection_system.views if node.level == 1}
            first, side = ents[ahead]["pair"][0], ents[ahead]["side"]
            assert level_1 == ({first} if frame >= 2 else {first, side})  # the occluder hides the side mirror
            assert max(node.level for node in runner.engine.reflection_system.views) >= min(depth, 4)
        assert trees[True] == trees[False], f"frame {frame}: the trees differ"
        # and so the frames, fallbacks past the pair's depth limit and all
        assert images[True].std() > 5.0 and np.array_equal(images[True], images[False]), f"frame {frame}"
    for frame, order in enumerate(orders[False]):  # one level at a time: one plan before the first claims
        assert order.index("claim") == 1, (frame, order)
    ahead_orders = orders[True]
    assert ahead_orders[0].index("claim") == 1  # a first render knows nothing of its levels
    assert ahead_orders[1].index("claim") >= 3, ahead_orders[1]  # levels 2 and below planned before level 1's claims
    # The occluder takes a candidate from level 1: the levels planned ahead are planned again.
    assert ahead_orders[2].index("claim") >= 2 and "plan" in ahead_orders[2][ahead_orders[2].index("claim"):]
    assert sum(label == "plan" for label in ahead_orders[3]) <= sum(label == "plan" for label in orders[False][3])



@pytest.mark.parametrize(("pair", "visibility"), (("portals", "exact"), ("mirrors", "exact"),
                                                  ("portals_closed", "exact"), ("portals", "predicted"),
                                                  ("mirrors", "predicted")))
def test_levels_of_one_view_on_the_lean_path_draw_what_the_general_path_draws(scene, monkeypatch, pair,
                                                                              visibility):
    """A facing pair seen head on is a chain of one view a level, which the view tree
    chooses, descends from and plans on a lean path (``ViewTree._choose_one``: none of the
    lists a level of many views is chosen through), packing each level's composite row
    with the others' in step 5.  While the camera sways and then stands still (the tree
    kept, its end images refilled until they settle), the trees, the frames' counts and the
    frames equal, frame by frame, those of a tree that chooses every level through the
    general path (``lean_levels`` False): the benchmark's portal pair at depth 8 (its floor
    and crates in every level), as mirrors, and with its end images off (the fallback past
    the depth limit); in exact visibility (this frame's counts) and predicted (last
    frame's: the levels' claims then drawn after the whole chain is planned)."""
    import dataclasses

    from benchmarks.portals import FacingPortals
    from engine.render.gpu import Gpu
    from engine.render.view_tree import ViewTree

    # What each frame took of the lean path: levels chosen on it, claims drawn from a run,
    # and the uploads of Camera blocks (a run's once).
    lean: list[str] = []
    for owner, name, label in ((ViewTree, "_choose_one", "level"), (Gpu, "_write_views", "views")):
        original = getattr(owner, name)
        monkeypatch.setattr(owner, name, lambda self, *a, _original=original, _label=label:
                            lean.append(_label) or _original(self, *a))
    prepare = MirrorPasses.prepare_level
    monkeypatch.setattr(MirrorPasses, "prepare_level", lambda self, *a: lean.append(
        "claims" if len(a) > 4 else "claim") or prepare(self, *a))
    # How each level's views are drawn (not the root's): on their claims' conditions
    # (predicted) or not, masked or not.
    from engine.render.scene_pass import ScenePass
    draw = ScenePass.draw
    monkeypatch.setattr(ScenePass, "draw", lambda self, views, targets, options, conditions=None, **k: (
        options.reflection_filter and lean.append(
            ("draw", len(views), None if conditions is None else len(conditions), options.masked))) or
        draw(self, views, targets, options, conditions, **k))

    def build(game):
        def level(world):
            game.build(world)
            for entity, portal in list(world.query_one(Portal)):
                if pair == "mirrors":  # the same quads, each a mirror
                    world.remove_component(entity, Portal)
                    world.add_component(entity, Mirror(max_depth=8))
                elif pair == "portals_closed":
                    portal.end_image = False
        return level

    games = {lean_levels: FacingPortals(sway=True) for lean_levels in (True, False)}
    runners = {lean_levels: scene(build(game), (160, 120)) for lean_levels, game in games.items()}
    for lean_levels, runner in runners.items():
        runner.engine.reflection_system.tree.lean_levels = lean_levels
        runner.engine.reflection_system.visibility = visibility
    kept = 0
    for frame in range(11):
        trees, images, stats, uploads, draws = {}, {}, {}, {}, {}
        for lean_levels, runner in runners.items():
            if frame < 5:  # the camera sways, then stands still (the tree kept, its end images refilled)
                games[lean_levels].update(runner.world, 1.0 / 60.0)
            lean.clear()
            images[lean_levels] = runner.frame()
            stats[lean_levels] = dataclasses.asdict(runner.stats)
            trees[lean_levels] = _planned_tree(runner)
            uploads[lean_levels] = lean.count("views")
            draws[lean_levels] = [event for event in lean if isinstance(event, tuple)]
            if not lean_levels:
                assert {event for event in lean if isinstance(event, str)} <= {"claim", "views"}, lean
            elif not (runner.stats.reflection_views_kept or runner.stats.reflection_end_refills):  # drawn
                if 0 < frame < 5:  # moving (a first render plans nothing ahead; a still camera's plans are kept)
                    assert lean.count("claims") >= 4, (frame, lean)
                assert lean.count("level") >= 6, (frame, lean)
        if 0 < frame < 5:  # (a level of one view's Camera block: uploaded with its run's)
            assert uploads[True] <= uploads[False] - 4, (frame, uploads)
        kept += bool(stats[True]["reflection_views_kept"] or stats[True]["reflection_end_refills"])
        assert len(trees[True]) >= 6, (frame, len(trees[True]))
        assert trees[True] == trees[False], f"frame {frame}: the trees differ"
        assert stats[True] == stats[False], f"frame {frame}: the counts differ"
        assert draws[True] == draws[False], f"frame {frame}: the levels drawn differ"
        assert all((conditions is None) == (visibility == "exact") for *_, conditions, _ in draws[True]), draws
        assert images[True].std() > 5.0 and np.array_equal(images[True], images[False]), f"frame {frame}"
    assert kept >= 3, kept
