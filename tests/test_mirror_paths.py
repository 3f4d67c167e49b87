"""The two ways of drawing a reflection level give the same frame: each view its own draws
("per_mirror") and one draw per mesh for all views ("batched": each instance drawn once a
view, scene.vert's INSTANCED_VIEWS build)."""
from __future__ import annotations

import warnings

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
    Refractive,
    Skybox,
    Transform,
    Water,
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
from tests.support import box_hits, look_from, pixel_rays

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


# ---- The transparent slot and glass in a batched level, against the per-mirror level and the
# ---- eye a portal carries (the same world drawn without portals from there).

FLAT = glm.angleAxis(-np.pi / 2, glm.vec3(1, 0, 0))   # a quad turned to lie flat, facing up
SLOT_SIZE = (96, 72)


def placed(carry, position, rotation=None) -> Transform:
    """A transform at ``position`` (turned by ``rotation``) as seen through portal A, placed
    beyond portal B by the pair's ``carry``."""
    turn = glm.quat_cast(carry)
    return Transform(position=glm.vec3(carry * glm.vec4(glm.vec3(position), 1.0)),
                     rotation=turn if rotation is None else turn * rotation)


def three_ways(scene, content, *, eye=(0.0, 0.6, 0.0), target=(0.0, -0.6, -5.0), fov=55.0, size=SLOT_SIZE,
               frames=2, margin=2):
    """What ``content(world, carry, ents)`` spawns beyond portal B (``tests/test_particles``'s
    pair: ``carry`` A's side to B's; ``ents`` a dict it names entities in) drawn three ways:
    through portal A from ``eye`` with each reflection path ("per_mirror", "batched": every
    level of the portal's tree so), and ("direct") from the eye the pair carries the
    camera's to, in the same world without portals.  For each: level 0's linear colour
    (HDR, before present), its seen ids mapped to ``ents``' names ("": none of them), its
    ways, the runner; and the pixels at
    least ``margin`` in from the edges of A's opening (the main view's rays), where all
    three must agree."""
    from tests.test_particles import PORTAL_A, PORTAL_B, PORTAL_SIZE, PORTAL_TURN, pair_carry

    carry = pair_carry()
    out = {}
    for way in ("per_mirror", "batched", "direct"):
        ents: dict = {}

        def build(world, through=way != "direct", ents=ents):
            if through:
                look_from(world, eye, target, fov=fov)
                spawn_portal_pair(world, PORTAL_A, None, PORTAL_B, PORTAL_TURN, size=PORTAL_SIZE)
            else:
                look_from(world, glm.vec3(carry * glm.vec4(glm.vec3(eye), 1.0)),
                          glm.vec3(carry * glm.vec4(glm.vec3(target), 1.0)), fov=fov)
            content(world, carry, ents)
        runner = scene(build, size)
        runner.engine.renderer.antialias = "off"
        runner.engine.reflection_system.visibility = "exact"
        if way != "direct":
            runner.engine.reflection_system.path = way
        for k in range(frames):
            runner.frame(1.0 / 60.0 if k < frames - 1 else 0.0)
        level = runner.engine.renderer.levels[0]
        w, h = size
        colour = np.frombuffer(level.color.read(), np.float16).reshape(h, w, 4)[::-1, :, :3].astype(np.float64)
        seen = level.read_ids()
        names = np.zeros(seen.shape, object)
        names[:] = ""
        for name, entity in ents.items():
            names[seen == entity] = name
        out[way] = {"colour": colour, "names": names, "ways": level.read_ways(), "runner": runner, "ents": ents}
    for way in ("per_mirror", "batched"):
        stats = out[way]["runner"].stats
        assert stats.reflection_views >= 1 and stats.reflection_path == way, (way, stats.reflection_path)
    origin, rays = pixel_rays(out["batched"]["runner"].engine.main_view, size)
    hit = origin + rays * ((PORTAL_A.z - origin[2]) / rays[..., 2])[..., None]
    pixel = 2.0 * np.tan(np.radians(fov / 2.0)) * abs(PORTAL_A.z - origin[2]) / size[1]
    out["opening"] = (np.abs(hit[..., 0] - PORTAL_A.x) < PORTAL_SIZE[0] / 2 - margin * pixel) \
        & (np.abs(hit[..., 1] - PORTAL_A.y) < PORTAL_SIZE[1] / 2 - margin * pixel)
    return out


def assert_three_agree(out, truth_q95=0.02, truth_names=0.98):
    """Inside A's opening: the batched level's colour is the per-mirror level's within a few
    levels of a float16 image, its seen ids the same entities pixel for pixel and its ways
    (the lengths of the light's way, what depth of field and motion read) the same; and each
    path's is the direct frame's (where the portal's level is its own view: all but a few
    pixels at the opening's rim, where a refracting march reads beyond its view)."""
    opening = out["opening"]
    parity = np.abs(out["batched"]["colour"] - out["per_mirror"]["colour"]).max(axis=-1)[opening]
    assert np.quantile(parity, 0.99) <= 0.004 and parity.max() <= 0.03, (np.quantile(parity, 0.99), parity.max())
    assert (out["batched"]["names"][opening] == out["per_mirror"]["names"][opening]).all()
    ways = [out[way]["ways"][opening] for way in ("batched", "per_mirror", "direct")]
    assert (ways[0] > 0).all() and np.abs(ways[0] - ways[1]).max() <= 1e-4 * ways[1].max(), \
        np.abs(ways[0] - ways[1]).max()
    for way in ("batched", "per_mirror"):
        apart = np.abs(out[way]["colour"] - out["direct"]["colour"]).max(axis=-1)[opening]
        assert np.quantile(apart, 0.95) <= truth_q95, (way, np.quantile(apart, [0.5, 0.8, 0.9, 0.95, 0.99]))
        assert (out[way]["names"][opening] == out["direct"]["names"][opening]).mean() >= truth_names, way
        near = np.abs(out[way]["ways"] - out["direct"]["ways"])[opening] <= 0.01 * out["direct"]["ways"][opening]
        assert near.mean() >= truth_names, (way, near.mean())


FOG_GREEN = (0.05, 0.6, 0.1)
FLOOR_RED = (0.9, 0.15, 0.1, 1.0)


def pond_beyond(*, density=0.0, alpha=0.0, water=True, depth=3.0):
    """Beyond the portal, 5 m off and 1.3 m down: a still pond 5 m square over a red glowing
    floor a metre below it, a white block standing in the water, a blue-grey wall behind
    (no sky shows through the portal), a grey sky.  ``water``: a water whose body is fogged
    to FOG_GREEN at ``density`` down to ``depth``; else a see-through mirror tinted gold.  Its
    material at ``alpha``."""
    def content(world, carry, ents):
        world.spawn(Skybox(faces=[np.full((8, 8, 3), 0.25, np.float32) for _ in range(6)]))
        ents["floor"] = world.spawn(placed(carry, (0.0, -2.3, -5.0), FLAT), MeshRef(quad(12.0, 12.0)),
                                    Material(color=FLOOR_RED, roughness=1.0), Emissive(1.0))
        ents["block"] = world.spawn(placed(carry, (0.6, -1.6, -5.5)), MeshRef(box((0.8, 1.0, 0.8))),
                                    Material(color=(0.9, 0.9, 0.9, 1.0), roughness=1.0), Emissive(1.0))
        ents["wall"] = world.spawn(placed(carry, (0.0, 0.0, -9.0)), MeshRef(quad(30.0, 20.0)),
                                   Material(color=(0.3, 0.3, 0.5, 1.0), roughness=1.0), Emissive(1.0))
        kind = [Water(speed=0.0, fog_density=density, fog_color=FOG_GREEN, depth=depth)] if water else []
        ents["pond"] = world.spawn(placed(carry, (0.0, -1.3, -5.0), FLAT), MeshRef(quad(5.0, 5.0)),
                                   Material(color=(0.1, 0.2, 0.3, alpha), roughness=0.1),
                                   Mirror(reflect_rate=1.0 if water else 0.6,
                                          color=(1.0, 1.0, 1.0) if water else (1.0, 0.8, 0.3)), *kind)
    return content


def glass_beyond():
    """``pond_beyond``'s pond as a see-through mirror (tinted gold, at alpha 0.5), a pink pane
    of glass at alpha 0.5 standing on its far side, and a refracting pane (index 1.3, screen
    refraction) standing in it in front of the block."""
    pond = pond_beyond(water=False, alpha=0.5)

    def content(world, carry, ents):
        pond(world, carry, ents)
        ents["pane"] = world.spawn(placed(carry, (-1.0, -0.8, -6.5)), MeshRef(quad(1.4, 1.0)),
                                   Material(color=(0.9, 0.15, 0.5, 0.5)), Emissive(0.6))
        ents["glass"] = world.spawn(placed(carry, (0.7, -0.7, -4.3)), MeshRef(quad(1.2, 1.4)),
                                    Material(color=(1.0, 1.0, 1.0, 0.0), double_sided=True, roughness=0.0,
                                             reflectance=0.0, environment_reflection=0.0), Refractive(ior=1.3))
    return content


def under_the_pond(world, carry, ents):
    """Beyond the portal, the whole opening under water: a still pond 20 m square 1.5 m up
    (over the carried eye), its floor 3 m down, a yellow glowing panel 2.5 m over the water
    (seen through Snell's window) and a grey sky."""
    world.spawn(Skybox(faces=[np.full((8, 8, 3), 0.25, np.float32) for _ in range(6)]))
    ents["floor"] = world.spawn(placed(carry, (0.0, -4.0, -5.0), FLAT), MeshRef(quad(60.0, 60.0)),
                                Material(color=FLOOR_RED, roughness=1.0), Emissive(1.0))
    ents["panel"] = world.spawn(placed(carry, (0.0, 4.0, -6.0), glm.angleAxis(np.pi / 2, glm.vec3(1, 0, 0))),
                                MeshRef(quad(3.0, 3.0)), Material(color=(0.9, 0.8, 0.1, 1.0), double_sided=True),
                                Emissive(2.0))
    ents["pond"] = world.spawn(placed(carry, (0.0, 1.5, -5.0), FLAT), MeshRef(quad(20.0, 20.0)),
                               Material(color=(1.0, 1.0, 1.0, 0.0)), Mirror(), Water(speed=0.0))


def pond_pixels(out) -> np.ndarray:
    """The opening's pixels whose rays (straight through the portal: it carries them) meet
    ``pond_beyond``'s pond inside its outline, at least 0.2 m in, and pass the block."""
    eye, rays = pixel_rays(out["batched"]["runner"].engine.main_view, SLOT_SIZE)
    t = (-1.3 - eye[1]) / rays[..., 1]
    hit = eye + t[..., None] * rays
    inside = (t > 0) & (np.abs(hit[..., 0]) < 2.3) & (hit[..., 2] > -7.3) & (hit[..., 2] < -2.7)
    block = np.abs(hit[..., 0] - 0.6) < 0.6   # (the block and its shadowed strip, to be sure)
    return out["opening"] & inside & ~block


def test_a_batched_levels_water_shows_its_fogged_body_below_as_the_per_mirror_level_and_a_camera_there(scene):
    """A pond whose body fogs green (its reflection a level below) seen through a portal, the
    portal's tree drawn batched (checked reported), per mirror, and directly from the eye the
    portal carries: the same pixels, ids and ways (``assert_three_agree``).  The water's
    composite reads the level's depth under it from the copy it takes: the batched level drew
    the water writing its depth, so the copy held the surface itself, no way through the
    water and no fog (2d32e5f1).  The fog is there: the pond's pixels are green over a red
    floor."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # (a still water: no waves, said)
        out = three_ways(scene, pond_beyond(density=1.2), margin=6)
    assert_three_agree(out)
    pond = pond_pixels(out)
    assert pond.sum() > 400, pond.sum()
    colour = out["batched"]["colour"][pond]
    assert (colour[:, 1] > 1.5 * colour[:, 0]).mean() > 0.95


def test_see_through_mirror_glass_on_it_and_refracting_glass_in_a_batched_level(scene):
    """A see-through mirror (tinted, at alpha 0.5: drawn with the level's opaque batches, its
    reflection a level below), a pane of glass standing on it and a refracting pane in front
    of it, seen through a portal: batched (checked reported), per mirror and directly from
    the eye the portal carries, the same pixels, ids and ways; both panes seen."""
    out = three_ways(scene, glass_beyond(), margin=4)
    assert_three_agree(out)
    names = out["batched"]["names"][out["opening"]]
    assert (names == "pane").sum() > 150 and (names == "glass").sum() > 300
    assert out["batched"]["runner"].engine.renderer.refracting_batches()


def test_a_batched_level_under_the_water_sees_its_underside_as_the_per_mirror_level_and_a_camera_there(scene):
    """A portal whose view lies under a pond (its eye carried under the water, looking up at a
    slant): the water's underside, the floor mirrored past the critical angle and the yellow
    panel in Snell's window, drawn batched (checked reported), per mirror and directly from
    the eye the portal carries: the same pixels, ids and ways; the window and the floor's
    mirror image both in the opening."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = three_ways(scene, under_the_pond, eye=(0.0, -0.9, -1.0), target=(0.0, 0.4, -3.5), margin=3)
    assert_three_agree(out)
    colour = out["batched"]["colour"][out["opening"]]
    panel = (colour[:, 0] > 0.6) & (colour[:, 1] > 0.6) & (colour[:, 2] < 0.3)
    floor = out["batched"]["names"][out["opening"]] == "floor"
    assert panel.sum() > 20 and floor.sum() > 1000, (panel.sum(), floor.sum())


def test_a_level_the_screen_effects_reach_is_drawn_view_by_view_and_says_so(scene):
    """Ambient occlusion reaching the reflection levels (``AmbientOcclusion.reflection_depth``)
    reads and writes images of each view, which the batched builds do not: asked for
    "batched", those levels are drawn view by view, as many passes as the per-mirror path's,
    and the stats say "per_mirror", as drawn; the levels past its reach batch again ("mixed":
    the third level's nine views one pass, eight fewer)."""
    from components import AmbientOcclusion

    def occluded(reach):
        def build(world):
            hall({}, sphere_detail=None)(world)
            for entity, _ in world.query_one(Camera):
                world.add_component(entity, AmbientOcclusion(reflection_depth=reach))
        return build

    every = render(scene, occluded(3), "batched")
    assert every["levels"] == [5, 5, 9]
    assert every["stats"].reflection_path == "per_mirror"
    assert every["stats"].passes == render(scene, occluded(3), "per_mirror")["stats"].passes
    two = render(scene, occluded(2), "batched")
    assert two["stats"].reflection_path == "mixed"
    assert two["stats"].passes == render(scene, occluded(2), "per_mirror")["stats"].passes - 8
    plain = render(scene, hall({}, sphere_detail=None), "batched")
    assert plain["stats"].reflection_path == "batched" and plain["stats"].passes == 1 + 3


# ---- Portals seen in mirrors: a level of portal views drawn in one batched draw.

TWIN_SIZE = (128, 96)
TWIN_BOX = (np.array([20.0, 1.3, 2.0]), np.full(3, 0.5))   # before B: centre, half sizes
TWIN_GAP = 0.05                                             # half the gap between the two mirrors


def twin_mirrors_and_a_portal(ents):
    """Two mirrors side by side in the plane z = -1.5 (2 m wide each, a 0.1 m gap between)
    facing the camera (z = 1) and, behind the camera, portal A facing them: each mirror sees
    A, so level 2 is two portal views seen in mirrors (mirrored, one batched draw).  A red
    box 2 m before partner B (at (20, 1.5, 0)), a blue backdrop behind it: the box's image
    straddles the gap, so each view shows part of it."""
    def build(world):
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))
        world.spawn(Skybox())
        world.spawn(Transform(position=(0.0, 1.5, 1.0), rotation=look_rotation(glm.vec3(0.0, 0.0, -1.0))),
                    Camera(fov_y=60.0))
        ents["mirrors"] = [world.spawn(Transform(position=(x, 1.5, -1.5)), MeshRef(quad(2.0, 3.0)),
                                       Material(color=(0.1, 0.1, 0.1)), Mirror())
                           for x in (-1.0 - TWIN_GAP, 1.0 + TWIN_GAP)]
        ents["a"], ents["b"] = spawn_portal_pair(world, (0, 1.5, 2.5), yaw(180), (20, 1.5, 0), None, size=(3.0, 2.4))
        ents["backdrop"] = world.spawn(Transform(position=(20, 2, 10)), MeshRef(box((16, 8, 0.2))),
                                       Material(color=(0.05, 0.05, 0.9)), Emissive(1.0))
        ents["box"] = world.spawn(Transform(position=tuple(TWIN_BOX[0]), scale=tuple(2.0 * TWIN_BOX[1])),
                                  MeshRef(box()), Material(color=(0.9, 0.05, 0.05)), Emissive(0.8))
    return build


def twin_rays(runner, grow):
    """Which pixels see the box, in float64 (no renderer), and on which side of the gap: each
    pixel's ray met on a mirror's rectangle (z = -1.5), reflected, through A's rectangle
    (z = 2.5, 3 x 2.4 m), carried to B's side by the pair's transform (B x a half turn x
    A^-1, A itself turned a half turn and B not: a move by B - A) and cast at the box grown
    by ``grow``.  Returns (box pixels, mirror x < 0 there)."""
    eye, rays = pixel_rays(runner.engine.main_view, TWIN_SIZE)
    rays = rays.reshape(-1, 3)
    t = (-1.5 - eye[2]) / rays[:, 2]
    at_mirror = eye + t[:, None] * rays
    x = at_mirror[:, 0]
    on_mirror = (t > 0) & (np.abs(x) > TWIN_GAP) & (np.abs(x) < 2.0 + TWIN_GAP) & (np.abs(at_mirror[:, 1] - 1.5) < 1.5)
    directions = rays * (1.0, 1.0, -1.0)
    t = (2.5 - at_mirror[:, 2]) / directions[:, 2]
    at_a = at_mirror + t[:, None] * directions
    through = on_mirror & (t > 0) & (np.abs(at_a[:, 0]) < 1.5) & (np.abs(at_a[:, 1] - 1.5) < 1.2)
    hits = box_hits(at_a + (20.0, 0.0, -2.5), directions, TWIN_BOX[0], TWIN_BOX[1] + grow)
    shape = (TWIN_SIZE[1], TWIN_SIZE[0])
    return (through & hits).reshape(shape), (x < 0).reshape(shape)


def test_portal_views_seen_in_two_mirrors_draw_in_one_batched_draw_as_the_per_mirror_path(scene):
    """Two mirrors each see portal A behind the camera: level 1 is two mirror views, level 2
    two portal views seen in them (mirrored, so one winding: the batched path draws each
    level in one pass, the per-mirror path in one pass a view).  The box beyond B lands where
    the rays, reflected and carried through the pair in float64, meet it (a margin in: the
    box; a margin out: never), in both level-2 views (its pixels on both sides of the gap),
    red there; the two paths draw the same views, the same ids and colours within 2."""
    results = {}
    for path in ("per_mirror", "batched"):
        ents = {}
        runner = scene(twin_mirrors_and_a_portal(ents), TWIN_SIZE)
        runner.engine.reflection_system.path = path
        runner.engine.reflection_system.visibility = "exact"
        rgb = runner.frame()
        stats = runner.stats
        assert stats.reflection_path == path
        views = runner.engine.reflection_system.views[1:]
        assert sorted((v.level, v.surface.entity, v.view.mirrored) for v in views) == sorted(
            [(1, m, True) for m in ents["mirrors"]] + [(2, ents["a"], True)] * 2)
        assert stats.passes == 1 + (4 if path == "per_mirror" else 2)
        ids = runner.ids()
        inside, left = twin_rays(runner, -0.05)
        outside = ~twin_rays(runner, 0.05)[0]
        assert (inside & left).sum() > 20 and (inside & ~left).sum() > 20  # in both portal views
        assert (ids[inside] == ents["box"]).all(), (path, np.unique(ids[inside]))
        red = rgb[inside].astype(int)
        assert (red[:, 0] > red[:, 2] + 60).all(), path
        assert not (ids[outside] == ents["box"]).any(), path
        surface = runner.engine.renderer.targets.read_surface_ids()
        assert (ids[np.isin(surface, ents["mirrors"]) & outside] == ents["backdrop"]).sum() > 100
        results[path] = ids, rgb.astype(int)
    (ids, rgb), (batched_ids, batched_rgb) = results["per_mirror"], results["batched"]
    np.testing.assert_array_equal(batched_ids, ids)
    assert np.abs(batched_rgb - rgb).max() <= 2
