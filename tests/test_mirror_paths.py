"""The two ways of drawing a reflection level give the same frame: each view its own draws
("per_mirror") and one draw per mesh for all views ("batched": each instance drawn once a
view, scene.vert's INSTANCED_VIEWS build)."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    DirectionalLight,
    Emissive,
    Material,
    MeshRef,
    Mirror,
    PointLight,
    Skybox,
    Transform,
    look_rotation,
)
from engine.assets.mesh import box, plane, quad, sphere
from engine.assets.portals import spawn_portal_pair
from engine.assets.texture_data import checker_texture
from engine.render.batched_mirrors import (
    AUTO_GPU_MAX_TRIANGLES,
    AUTO_MAX_TRIANGLES,
    AUTO_MIN_VIEWS,
    MAX_BATCHED_VIEWS,
    choose_path,
    instanced_groups,
    submitted_triangles,
)
from engine.render.views import View

SIZE = (200, 150)


def yaw(degrees: float) -> glm.quat:
    return glm.angleAxis(glm.radians(degrees), glm.vec3(0, 1, 0))


def hall(ents, eye=(-1.2, 1.7, 2.5), target=(0.3, 1.3, -4.0), sphere_detail=(16, 8)):
    """Three mirror panels on the back wall, a wide mirror facing them behind the camera,
    two side mirrors, and a box, a sphere and a lit post in front on a checker floor:
    levels of 5, 5 and 9 views, mirrored (levels 1, 3) and not (level 2).  Without the
    sphere (``sphere_detail=None``) the scene is 38 triangles."""

    def build(world):
        world.spawn(DirectionalLight(direction=(0.3, -1.0, -0.4), intensity=2.0))
        world.spawn(Transform(position=(0, 3, 0)), PointLight(intensity=4.0, range=12))
        world.spawn(Skybox())
        look = glm.vec3(target) - glm.vec3(eye)
        world.spawn(Transform(position=eye, rotation=look_rotation(look)), Camera(fov_y=75.0))
        world.spawn(Transform(), MeshRef(plane(20, 20, uv_repeat=8)), Material(texture=checker_texture(64, 8)))
        panel = quad(1.8, 2.6)
        ents["mirrors"] = [
            world.spawn(Transform(position=(x, 1.4, -4), rotation=yaw(12 * (1 - i))), MeshRef(panel),
                        Material(color=(0.1, 0.1, 0.1)), Mirror(color=(1.0, 0.95 - 0.05 * i, 0.9 + 0.05 * i)))
            for i, x in enumerate((-2.0, 0.0, 2.0))]
        ents["mirrors"].append(world.spawn(Transform(position=(0, 1.5, 4.5), rotation=yaw(180)), MeshRef(quad(6, 3)),
                                           Material(color=(0.1, 0.1, 0.1)), Mirror(color=(0.9, 0.95, 0.9))))
        small = quad(2, 2)
        for x, turn, tint in ((4, -70, (1.0, 0.8, 0.8)), (-4, 70, (0.8, 0.8, 1.0))):
            ents["mirrors"].append(world.spawn(Transform(position=(x, 1.2, -1), rotation=yaw(turn)), MeshRef(small),
                                               Material(), Mirror(color=tint)))
        ents["box"] = world.spawn(
            Transform(position=(1.0, 1.3, 0.5), rotation=glm.angleAxis(0.5, glm.normalize(glm.vec3(1, 1, 0))),
                      scale=(0.6, 0.6, 0.6)), MeshRef(box()), Material(color=(0.9, 0.1, 0.1)))
        if sphere_detail is not None:
            ents["ball"] = world.spawn(Transform(position=(-0.8, 0.8, -0.5)), MeshRef(sphere(0.5, *sphere_detail)),
                                       Material(color=(0.1, 0.8, 0.2), roughness=0.3))
        ents["post"] = world.spawn(Transform(position=(0.5, 0.5, -2.0), scale=(0.5, 1, 0.5)), MeshRef(box()),
                                   Material(color=(0.9, 0.8, 0.1)), Emissive(0.5))

    return build


def render(scene, build, path, size=SIZE):
    runner = scene(build, size)
    runner.engine.reflection_system.path = path
    # The level counts below are the exact tree's (on a GPU "auto" would predict, and a first
    # frame predicts nothing hidden: tests/test_predicted_visibility.py).
    runner.engine.reflection_system.visibility = "exact"
    rgb = runner.frame()
    views = runner.engine.reflection_system.views
    return {
        "rgb": rgb,
        "ids": runner.ids(),
        "surface": runner.engine.renderer.targets.read_surface_ids(),
        "stats": runner.stats,
        "levels": [sum(v.level == level for v in views) for level in range(1, 1 + max(v.level for v in views))],
        "views": [(v.level, v.rect, v.view.node, v.view.mirrored) for v in views],
        "skips": [v.view.skip for v in views],
        "runner": runner,
    }


def assert_same_frame(a, b):
    diff = np.abs(a["rgb"].astype(int) - b["rgb"].astype(int))
    assert diff.mean() < 0.5 and np.percentile(diff, 99) <= 2, (diff.mean(), np.percentile(diff, 99))
    assert (a["ids"] == b["ids"]).mean() >= 0.99
    assert a["stats"].reflection_views == b["stats"].reflection_views
    assert a["views"] == b["views"]  # same view tree: levels, rectangles, node indices, handedness


def test_batched_draws_the_per_mirror_frame_in_fewer_passes(scene):
    ents = {}
    build = hall(ents)
    per_mirror = render(scene, build, "per_mirror")
    batched = render(scene, build, "batched")
    # The frame is not empty: a lit floor, and reflections of the objects inside the mirrors.
    rgb = batched["rgb"].astype(int)
    assert rgb.mean() > 60 and rgb.std() > 25
    in_mirrors = np.isin(batched["surface"], ents["mirrors"])
    assert in_mirrors.mean() > 0.1
    reflected = batched["ids"][in_mirrors]
    for name in ("box", "ball", "post"):
        assert (reflected == ents[name]).sum() > 20, name
    assert batched["levels"] == [5, 5, 9]  # mirrored, not, mirrored: one winding a level
    assert {m for _, _, _, m in batched["views"][1:]} == {True, False}

    assert_same_frame(per_mirror, batched)
    views = batched["stats"].reflection_views
    assert views == 19
    assert per_mirror["stats"].passes == 1 + views  # one pass per view
    assert batched["stats"].passes == 1 + 3         # one pass per level
    batches = len(batched["runner"].engine.renderer.batches)
    assert batched["stats"].draw_calls == (batches + 1) + 3 * batches  # main view (+ sky), then one per batch
    # A view leaves out the batch of its own mirror when that mirror is the batch's one instance.
    alone = {b.entity_at[0] for b in per_mirror["runner"].engine.renderer.batches.values() if b.count == 1}
    skipped = sum(skip in alone for skip in per_mirror["skips"])
    assert skipped > 0  # the back mirror is the one instance of its mesh
    # ... and a batch whose boxes cannot reach a view (engine/render/batch_cull.py).
    culled = per_mirror["stats"].draws_culled
    assert per_mirror["stats"].draw_calls == (batches + 1) + views * batches - skipped - culled
    assert per_mirror["stats"].reflection_path == "per_mirror"
    assert batched["stats"].reflection_path == "batched"


def test_paths_agree_with_the_camera_close_to_a_mirror(scene):
    """Within 4 x near of the glass the views use a clip distance instead of an oblique near plane."""
    ents = {}
    build = hall(ents, eye=(0.0, 1.4, -3.9), target=(0.2, 1.3, -5.0))
    per_mirror = render(scene, build, "per_mirror")
    batched = render(scene, build, "batched")
    main_proj = per_mirror["runner"].engine.main_view.proj
    first = per_mirror["runner"].engine.reflection_system.views[1]
    assert first.view.proj == main_proj  # the clip-distance case
    assert np.isin(batched["surface"], ents["mirrors"]).mean() > 0.8
    assert batched["rgb"].astype(int).std() > 15
    assert_same_frame(per_mirror, batched)


def test_auto_rule_boundaries():
    assert choose_path("per_mirror", 32, 10) == "per_mirror"
    assert choose_path("batched", 1, 10**6) == "batched"
    assert choose_path("auto", AUTO_MIN_VIEWS - 1, 10) == "per_mirror"
    assert choose_path("auto", AUTO_MIN_VIEWS, AUTO_MAX_TRIANGLES) == "batched"
    assert choose_path("auto", 32, AUTO_MAX_TRIANGLES) == "batched"
    assert choose_path("auto", 32, AUTO_MAX_TRIANGLES + 1) == "per_mirror"
    # On a GPU a view's draws cost more than its vertex stage up to a larger scene.
    assert choose_path("auto", AUTO_MIN_VIEWS, AUTO_GPU_MAX_TRIANGLES, software=False) == "batched"
    assert choose_path("auto", AUTO_MIN_VIEWS - 1, 10, software=False) == "per_mirror"
    assert choose_path("auto", 32, AUTO_GPU_MAX_TRIANGLES + 1, software=False) == "per_mirror"
    assert AUTO_GPU_MAX_TRIANGLES > AUTO_MAX_TRIANGLES
    # Given as a function, the scene's triangles are counted only where the views could batch.
    counted = []

    def count() -> int:
        counted.append(1)
        return AUTO_MAX_TRIANGLES + 1
    assert choose_path("auto", AUTO_MIN_VIEWS - 1, count) == "per_mirror" and not counted
    assert choose_path("per_mirror", 32, count) == "per_mirror" and not counted
    assert choose_path("auto", AUTO_MIN_VIEWS, count) == "per_mirror" and counted == [1]
    assert choose_path("auto", AUTO_MIN_VIEWS, lambda: AUTO_MAX_TRIANGLES) == "batched"
    with pytest.raises(ValueError, match="ReflectionSystem.path must be one of"):
        choose_path("fast", 3, 10)


def test_auto_follows_the_rule_each_level_and_reports_it(scene):
    light = render(scene, hall({}, sphere_detail=None), "auto")
    assert submitted_triangles(light["runner"].engine.renderer) <= AUTO_MAX_TRIANGLES
    assert light["levels"] == [5, 5, 9]
    assert light["stats"].reflection_path == "batched" and light["stats"].passes == 1 + 3

    # The sphere: 224 more triangles, over llvmpipe's limit; 960 on a GPU, over its own.
    software = light["runner"].engine.renderer.caps.software
    heavier = render(scene, hall({}, sphere_detail=(16, 8) if software else (32, 16)), "auto")
    assert submitted_triangles(heavier["runner"].engine.renderer) > \
        (AUTO_MAX_TRIANGLES if software else AUTO_GPU_MAX_TRIANGLES)
    assert heavier["stats"].reflection_path == "per_mirror" and heavier["stats"].passes == 1 + 19

    # Close to the middle panel: levels of 1, 2 and 6 views, the first two under AUTO_MIN_VIEWS.
    build = hall({}, eye=(0.0, 1.4, -3.9), target=(0.2, 1.3, -5.0), sphere_detail=None)
    mixed = render(scene, build, "auto")
    assert mixed["levels"] == [1, 2, 6]
    assert mixed["stats"].reflection_path == "mixed" and mixed["stats"].passes == 1 + 1 + 2 + 1
    assert_same_frame(render(scene, build, "per_mirror"), mixed)


def test_no_reflection_view_reports_no_path(scene):
    def build(world):
        world.spawn(DirectionalLight())
        world.spawn(Transform(position=(0, 1.5, 5)), Camera())
        world.spawn(Transform(position=(0, 1.5, -2), rotation=yaw(180)), MeshRef(quad(2, 2)), Material(), Mirror())

    runner = scene(build, (64, 48))
    runner.engine.reflection_system.path = "batched"
    runner.frame()
    assert runner.stats.reflection_views == 0 and runner.stats.reflection_path == ""


def test_an_unknown_path_is_a_clear_error(scene):
    """Refused when it is set (not frames later inside the system), keeping the old path."""
    runner = scene(hall({}), (64, 48))
    with pytest.raises(ValueError, match="path must be one of"):
        runner.engine.reflection_system.path = "fastest"
    assert runner.engine.reflection_system.path == "auto"
    runner.frame()
    assert runner.stats.reflection_views > 0


def mirror_and_portal(ents):
    """A mirror on the left and a portal on the right, both in front of the camera: level 1
    holds a mirrored view (the mirror's: its front faces clockwise) and one that is not (the
    portal's), each showing the box and the post."""

    def build(world):
        world.spawn(DirectionalLight(direction=(0.3, -1.0, -0.4), intensity=2.0))
        world.spawn(Skybox())
        world.spawn(Transform(position=(0, 1.6, 4), rotation=look_rotation(glm.vec3(0, -0.15, -1))),
                    Camera(fov_y=75.0))
        world.spawn(Transform(), MeshRef(plane(30, 30, uv_repeat=10)), Material(texture=checker_texture(64, 8)))
        ents["mirror"] = world.spawn(Transform(position=(-1.6, 1.4, -1), rotation=yaw(25)), MeshRef(quad(2.2, 2.6)),
                                     Material(), Mirror(color=(0.95, 0.95, 1.0)))
        ents["portals"] = spawn_portal_pair(world, (1.6, 1.4, -1), yaw(-25), (8, 1.4, 2), yaw(-90), size=(2.2, 2.6))
        ents["box"] = world.spawn(Transform(position=(0.0, 0.6, 2.0), rotation=yaw(30), scale=(0.8, 1.2, 0.8)),
                                  MeshRef(box()), Material(color=(0.9, 0.1, 0.1)))
        ents["post"] = world.spawn(Transform(position=(5.0, 0.8, 2.0), scale=(0.6, 1.6, 0.6)), MeshRef(box()),
                                   Material(color=(0.1, 0.3, 0.9)))

    return build


def test_a_level_of_mirrored_and_unmirrored_views_batches_once_per_winding(scene):
    """One draw culls by one winding, so the batched path draws a level whose views are
    mirrored and not (a mirror's and a portal's) once for each (``instanced_groups``), and
    its frame is the per-mirror path's."""
    ents = {}
    build = mirror_and_portal(ents)
    per_mirror = render(scene, build, "per_mirror")
    batched = render(scene, build, "batched")
    first = [mirrored for level, _, _, mirrored in batched["views"] if level == 1]
    assert sorted(first) == [False, True]
    assert_same_frame(per_mirror, batched)
    surface, ids = batched["surface"], batched["ids"]
    for entity in (ents["mirror"], ents["portals"][0]):  # each view shows the box or the post
        shown = ids[surface == entity]
        assert shown.size > 200 and np.isin(shown, (ents["box"], ents["post"])).sum() > 30, entity
    levels = batched["levels"]
    assert batched["stats"].passes == 1 + 2 + sum(
        len({m for lvl, _, _, m in batched["views"] if lvl == level}) for level in range(2, len(levels) + 1))


def test_instanced_groups_hold_each_view_once_one_winding_and_at_most_the_limit():
    """A level's views in the groups one batched draw each takes: every view once, each group
    of one winding and at most MAX_BATCHED_VIEWS views (a level of 70: 46 mirrored and 24 not)."""
    views = [View(glm.mat4(1.0), glm.mat4(1.0), glm.vec3(0.0), (64, 48), mirrored=i % 3 != 0) for i in range(70)]
    groups = instanced_groups(views)
    assert sorted(i for group in groups for i in group) == list(range(70))
    assert all(0 < len(group) <= MAX_BATCHED_VIEWS for group in groups)
    assert all(len({views[i].mirrored for i in group}) == 1 for group in groups)
    assert [len(group) for group in groups] == [24, 32, 14]  # not mirrored first, then mirrored in two
    assert instanced_groups([]) == []


def mirror_wall(ents, columns=9, rows=5):
    """``columns`` x ``rows`` small mirrors on a wall facing the camera, each seeing its own
    part of a large glowing checker panel behind the camera (none sees another mirror):
    one level of columns x rows views, all mirrored."""
    def build(world):
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))
        world.spawn(Transform(position=(0.0, 1.5, 4.0), rotation=look_rotation(glm.vec3(0.0, 0.0, -1.0))),
                    Camera(fov_y=70.0))
        ents["mirrors"] = [
            world.spawn(Transform(position=(-3.2 + 0.8 * c, 0.3 + 0.55 * r, -2.0)), MeshRef(quad(0.5, 0.42)),
                        Material(color=(0.1, 0.1, 0.1)), Mirror())
            for c in range(columns) for r in range(rows)]
        ents["panel"] = world.spawn(Transform(position=(0.0, 1.5, 9.0), scale=(40.0, 20.0, 0.1)), MeshRef(box()),
                                    Material(texture=checker_texture(64, 16)), Emissive(1.0))
    return build


def test_a_level_of_more_views_than_one_batched_draw_takes_draws_every_group_as_the_per_mirror_path(scene):
    """A level of 45 mirrored views is more than MAX_BATCHED_VIEWS of one winding: the batched
    path draws it in two groups (``instanced_groups``), each with its own Views table.  Every
    mirror shows its part of the panel, pixel for pixel as the per-mirror path draws it,
    those of the second group as well as the first (a mirror is under 0.3% of the frame, so
    the whole-frame check alone would let a group go)."""
    ents = {}
    build = mirror_wall(ents)
    size = (240, 150)
    per_mirror = render(scene, build, "per_mirror", size)
    batched = render(scene, build, "batched", size)
    views = batched["runner"].engine.reflection_system.views[1:]
    level = [node.view for node in views if node.level == 1]
    assert len(level) == len(ents["mirrors"]) > MAX_BATCHED_VIEWS and all(view.mirrored for view in level)
    groups = instanced_groups(level)
    assert len(groups) == 2 and len(groups[1]) == len(level) - MAX_BATCHED_VIEWS
    assert_same_frame(per_mirror, batched)
    surface = batched["surface"]
    assert np.array_equal(surface, per_mirror["surface"])
    second = {views[i].surface.entity for i in groups[1]}
    for mirror in ents["mirrors"]:
        on_it = surface == mirror
        assert on_it.sum() >= 40, mirror
        assert (batched["ids"][on_it] == ents["panel"]).mean() > 0.9, (mirror, mirror in second)
        diff = np.abs(batched["rgb"][on_it].astype(int) - per_mirror["rgb"][on_it].astype(int))
        assert diff.max() <= 2, (mirror, mirror in second, int(diff.max()))
    shown = per_mirror["rgb"][np.isin(surface, ents["mirrors"])].astype(int)
    assert shown.std() > 20  # the checker's squares, not one colour
    assert batched["stats"].reflection_path == "batched" and batched["stats"].passes == 1 + len(groups)
