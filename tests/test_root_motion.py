"""Root motion (``Animation.root_motion``): a walker whose clip carries its hips across the
ground walks on the spot while its root's Transform moves by the clip's travel, frame by
frame, as worked out here from the clip's keys: through a loop's wrap (forwards and back),
held at a clip's end, turned and scaled with the root; its height kept in the pose; a node
the file lacks refused, by the models stage and by a level file's line."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from pyglm import glm

from components import Animation, ComponentValueError, FromModel, Transform
from engine.assets.mesh import box
from engine.assets.models import spawn_model
from engine.core.errors import AssetError
from engine.core.world import World
from systems.model_system import ModelSystem
from tests.test_materials_from_files import write_glb
from tests.test_model_variants import add_accessors, edit_glb


def walker(path: Path) -> Path:
    """Nodes: 0 "armature" (scale 0.5) over 1 "hips" (a box); clip "Walk" moves the hips
    linearly through (0, 2, 0), (4, 2.4, 0), (8, 2, 0) at 0, 1 and 2 s: in the model's
    space (halved) 2 m a second along x, bobbing from height 1 to 1.2 and back."""
    write_glb(path, box((0.4, 0.8, 0.3)), {"name": "cloth", "pbrMetallicRoughness": {"baseColorFactor":
                                                                                    [0.2, 0.4, 0.8, 1.0]}}, [])
    arrays = [np.array([0.0, 1.0, 2.0], np.float32), np.array([[0, 2, 0], [4, 2.4, 0], [8, 2, 0]], np.float32)]

    def change(doc: dict) -> None:
        first = add_accessors(doc, arrays)
        doc["nodes"] = [{"name": "armature", "scale": [0.5, 0.5, 0.5], "children": [1]},
                        {"name": "hips", "mesh": 0, "translation": [0.0, 2.0, 0.0]}]
        doc["scenes"] = [{"nodes": [0]}]
        doc["animations"] = [{"name": "Walk", "samplers": [{"input": first, "output": first + 1}],
                              "channels": [{"sampler": 0, "target": {"node": 1, "path": "translation"}}]}]
    return edit_glb(path, change)


def height(t: float) -> float:
    """The hips' height (model space) at ``t`` s into Walk."""
    t = t % 2.0
    return 1.0 + 0.2 * (t if t <= 1.0 else 2.0 - t)


def near(a, b) -> bool:
    return bool(np.allclose(list(a), list(b), atol=1e-5))


def walking(tmp_path, steps, root_transform=None, **fields):
    world = World("walk")
    root = spawn_model(world, walker(tmp_path / "walker.glb"))
    if root_transform is not None:
        t = world.get(root, Transform)
        t.rotation, t.scale = root_transform
    world.add_component(root, Animation("Walk", **{"root_motion": "hips", **fields}))
    stage = ModelSystem(world)
    ((hips, _),) = list(world.query_one(FromModel))
    seen = []
    for dt in steps:
        stage.process(dt)
        seen.append((glm.vec3(world.get(root, Transform).position), glm.vec3(world.get(hips, Transform).position)))
    return world, seen


def test_the_root_walks_by_the_clips_travel_and_the_hips_stay_over_it(tmp_path):
    _, seen = walking(tmp_path, [0.0, 0.5, 0.5, 0.25])
    for (root, hips), t in zip(seen, (0.0, 0.5, 1.0, 1.25), strict=True):
        assert near(root, (2.0 * t, 0.0, 0.0)), (t, root)
        assert near(hips, (0.0, height(t), 0.0)), (t, hips)   # on the spot, bobbing


def test_a_loops_wrap_carries_on_forwards_and_back_and_a_held_end_stops(tmp_path):
    """From 1.5 s a second on (the loop wraps at 2 s): 2 m on, not back to the start; backwards
    from 0.5 s a second (wrapping below 0): 2 m back; not looping from 1.5 s, held at 2 s: 1 m."""
    _, seen = walking(tmp_path, [1.0], time=1.5)
    assert near(seen[0][0], (2.0, 0.0, 0.0)), seen
    _, seen = walking(tmp_path, [1.0], time=0.5, speed=-1.0)
    assert near(seen[0][0], (-2.0, 0.0, 0.0)), seen
    _, seen = walking(tmp_path, [1.0, 1.0], time=1.5, loop=False)
    assert near(seen[0][0], (1.0, 0.0, 0.0)) and near(seen[1][0], (1.0, 0.0, 0.0)), seen
    _, seen = walking(tmp_path, [3.0], time=0.0)   # a wrap and a half in one step
    assert near(seen[0][0], (6.0, 0.0, 0.0)), seen


def test_the_travel_is_turned_and_scaled_as_the_root_is(tmp_path):
    """The root turned a quarter about y and scaled 2: half a second's 1 m along the model's x
    is 2 m along the world's -z."""
    turn = glm.angleAxis(math.pi / 2, glm.vec3(0.0, 1.0, 0.0))
    _, seen = walking(tmp_path, [0.5], (turn, glm.vec3(2.0)))
    assert near(seen[0][0], turn * glm.vec3(2.0, 0.0, 0.0)), seen


def test_a_node_the_model_lacks_is_refused(tmp_path):
    with pytest.raises(AssetError, match=r"Animation.root_motion: its model has no node 'pelvis' \(its nodes: "
                                         r"'armature', 'hips'\)"):
        walking(tmp_path, [0.1], root_motion="pelvis")
    with pytest.raises(ComponentValueError, match="Animation.root_motion must be a node's name"):
        Animation("Walk", root_motion=1)


def test_a_level_file_walks_its_model_and_refuses_a_missing_node_by_line(tmp_path):
    from engine.assets.level_file import LevelError, load_level

    walker(tmp_path / "walker.glb")
    text = ('[level]\nname = "walk"\n\n[[entity]]\nname = "walker"\n[entity.Transform]\n[entity.Model]\n'
            'file = "walker.glb"\n[entity.Animation]\nclip = "Walk"\nroot_motion = "NODE"\n')
    (tmp_path / "walk.toml").write_text(text.replace("NODE", "hips"))
    world = World("walk")
    names = load_level(tmp_path / "walk.toml").spawn(world)
    ModelSystem(world).process(0.5)
    assert near(world.get(names["walker"], Transform).position, (1.0, 0.0, 0.0))
    (tmp_path / "walk.toml").write_text(text.replace("NODE", "pelvis"))
    with pytest.raises(LevelError, match=r"no node 'pelvis' \(its nodes: 'armature', 'hips'\)") as caught:
        load_level(tmp_path / "walk.toml")
    assert (caught.value.field, caught.value.line) == ("Animation.root_motion", 11)


def turner(path: Path, aside: float = 0.0) -> Path:
    """Nodes: 0 "armature" (scale 0.5) over 1 "hips" (a box); clip "Turn" (1 s) walks the hips a
    quarter round a circle of radius 4 about (0, 2, -4) (keys every 0.125 s) while turning
    them a quarter about +y (keys likewise, slerped): a walk round a corner, facing its way;
    ``aside``: the whole walk that far along x (it starts off the model's middle)."""
    write_glb(path, box((0.4, 0.8, 0.3)), {"name": "cloth", "pbrMetallicRoughness": {"baseColorFactor":
                                                                                    [0.2, 0.4, 0.8, 1.0]}}, [])
    times = np.linspace(0.0, 1.0, 9)
    angles = 0.5 * math.pi * times
    # Facing -z at the start, it walks forwards (-z) and curves left, towards -x.
    places = np.stack([4.0 * (np.cos(angles) - 1.0) + aside, np.full_like(times, 2.0), -4.0 * np.sin(angles)], axis=1)
    turns = np.stack([np.zeros_like(angles), np.sin(angles / 2), np.zeros_like(angles), np.cos(angles / 2)], axis=1)
    arrays = [times.astype(np.float32), places.astype(np.float32), turns.astype(np.float32)]

    def change(doc: dict) -> None:
        first = add_accessors(doc, arrays)
        doc["nodes"] = [{"name": "armature", "scale": [0.5, 0.5, 0.5], "children": [1]},
                        {"name": "hips", "mesh": 0, "translation": [0.0, 2.0, 0.0]}]
        doc["scenes"] = [{"nodes": [0]}]
        doc["animations"] = [{"name": "Turn", "samplers": [{"input": first, "output": first + 1},
                                                           {"input": first, "output": first + 2}],
                              "channels": [{"sampler": 0, "target": {"node": 1, "path": "translation"}},
                                           {"sampler": 1, "target": {"node": 1, "path": "rotation"}}]}]
    return edit_glb(path, change)


def placed_hips(world: World, root: int, hips: int) -> glm.mat4:
    """The hips' matrix in the world: the root's Transform times the part's (model space)."""
    def matrix(t: Transform) -> glm.mat4:
        return glm.translate(t.position) * glm.mat4_cast(t.rotation) * glm.scale(t.scale)
    return matrix(world.get(root, Transform)) * matrix(world.get(hips, Transform))


@pytest.mark.parametrize(("steps", "aside"), [([0.1] * 10, 0.0), ([0.35, 0.35, 0.3], 0.0), ([0.1] * 10, 3.0)])
def test_a_turn_comes_out_of_the_pose_and_turns_the_root(tmp_path, steps, aside):
    """``root_turn``: the hips stay on the spot facing as they started while the root walks
    and turns a quarter; at every frame the hips stand in the world where the clip alone (no
    root motion) puts them, whatever the frames' lengths; a level file keeps the field."""
    path = turner(tmp_path / "turner.glb", aside)
    worlds = {}
    for name, fields in (("walked", {"root_motion": "hips", "root_turn": True}), ("posed", {})):
        world = World(name)
        root = spawn_model(world, path, position=(1.0, 0.0, 2.0))
        world.add_component(root, Animation("Turn", loop=False, **fields))
        ((hips, _),) = list(world.query_one(FromModel))
        worlds[name] = (world, root, hips, ModelSystem(world))
    for dt in steps:
        for *_, stage in worlds.values():
            stage.process(dt)
        walked, posed = (placed_hips(w, r, h) for w, r, h, _ in worlds.values())
        for column in range(4):
            np.testing.assert_allclose(list(walked[column]), list(posed[column]), atol=2e-3)
    world, root, hips, _ = worlds["walked"]
    assert abs(glm.angle(world.get(hips, Transform).rotation)) < 1e-4            # facing as it started
    assert near(world.get(hips, Transform).position, (0.5 * aside, 1.0, 0.0))  # on the spot
    quarter = glm.angleAxis(math.pi / 2, glm.vec3(0.0, 1.0, 0.0))
    assert abs(glm.dot(world.get(root, Transform).rotation, quarter)) == pytest.approx(1.0, abs=1e-6)
    if not aside:
        assert near(world.get(root, Transform).position, (1.0 - 2.0, 0.0, 2.0 - 2.0))   # (the arc's end, halved)
    with pytest.raises(ComponentValueError, match="Animation.root_turn"):
        Animation("Turn", root_turn="yes")


@pytest.mark.parametrize("steps", [[1.0, 1.0], [0.25] * 8, [2.0]])
def test_a_looping_turn_carries_on_round_through_each_wrap(tmp_path, steps):
    """The walk round a corner looped for 2 s: the root turns a half and walks the two arcs
    one after the other (the second turned a quarter by the first), however the frames fall."""
    world = World("loop")
    root = spawn_model(world, turner(tmp_path / "turner.glb"), position=(1.0, 0.0, 2.0))
    world.add_component(root, Animation("Turn", root_motion="hips", root_turn=True))
    stage = ModelSystem(world)
    for dt in steps:
        stage.process(dt)
    arc = glm.vec3(-2.0, 0.0, -2.0)   # (one arc, halved)
    quarter = glm.angleAxis(math.pi / 2, glm.vec3(0.0, 1.0, 0.0))
    assert near(world.get(root, Transform).position, glm.vec3(1.0, 0.0, 2.0) + arc + quarter * arc)
    assert abs(glm.dot(world.get(root, Transform).rotation, quarter * quarter)) == pytest.approx(1.0, abs=1e-6)


def test_the_root_moves_by_the_clips_time_times_its_speed_and_not_by_a_layers(tmp_path):
    """Speed 2: two frames of 0.25 s are 1 s of Walk, 2 m (the clip's 4 m halved); backwards
    not looping from 1.5 s by 1 s frames: 2 m back to 0.5 s, then 1 m more, held at the start;
    a layer playing Walk three times as fast over it leaves the root moving by the Animation's
    clip alone (its travel is the Animation's)."""
    from components import AnimationLayer

    _, seen = walking(tmp_path, [0.25, 0.25], speed=2.0)
    assert near(seen[0][0], (1.0, 0.0, 0.0)) and near(seen[1][0], (2.0, 0.0, 0.0)), seen
    assert near(seen[1][1], (0.0, height(1.0), 0.0)), seen   # (on the spot, at the top of its bob)
    _, seen = walking(tmp_path, [1.0, 1.0, 1.0], time=1.5, speed=-1.0, loop=False)
    assert [round(root.x, 5) for root, _ in seen] == [-2.0, -3.0, -3.0], seen
    _, seen = walking(tmp_path, [0.1] * 5, time=0.3, speed=-1.0)   # (0.3 - 3 x 0.1 lands a hair below 0)
    assert [round(root.x, 5) for root, _ in seen] == [-0.2, -0.4, -0.6, -0.8, -1.0], seen
    world = World("layered walk")
    root = spawn_model(world, walker(tmp_path / "walker.glb"))
    world.add_component(root, Animation("Walk", root_motion="hips"))
    world.add_component(root, AnimationLayer("Walk", speed=3.0, weight=0.5))
    stage = ModelSystem(world)
    for _ in range(3):
        stage.process(0.25)
    assert near(world.get(root, Transform).position, (1.5, 0.0, 0.0))
