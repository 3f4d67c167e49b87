"""Cameras from glTF files: ``spawn_model`` makes a file's perspective cameras into Camera
entities under the model, placed by their nodes and not active; made active, one shows the
frame a camera placed by hand at the node's place in the world shows (a second path); bad
cameras are refused naming them; orthographic ones become orthographic Cameras."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import Camera, DirectionalLight, FromModel, Transform
from engine.assets.mesh import box, load_model_file
from engine.assets.models import spawn_model
from engine.core.errors import AssetError
from engine.core.world import World
from tests.support import look_from
from tests.test_materials_from_files import write_glb

PAINT = {"name": "paint", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.3, 0.1, 1.0], "metallicFactor": 0.0}}
TILT = glm.angleAxis(math.radians(-20.0), glm.vec3(1.0, 0.0, 0.0))       # looking a little down
SHOT = {"type": "perspective", "name": "shot", "perspective": {"yfov": math.radians(40.0), "znear": 0.1, "zfar": 50.0}}


def filmed_box(path, cameras: list[dict], camera_nodes: list[dict] | None = None):
    """A 1 m box at the model's origin and, under a node 2 m up, a node 4 m back on +Z
    tilted 20 degrees down (scaled by 3, which a camera leaves out) naming camera 0."""
    nodes = [{"mesh": 0}, {"translation": [0.0, 2.0, 0.0], "children": [2]},
             {"translation": [0.0, 0.0, 4.0], "rotation": [TILT.x, TILT.y, TILT.z, TILT.w], "scale": [3.0, 3.0, 3.0],
              "camera": 0}]
    if camera_nodes is not None:
        nodes = [{"mesh": 0}, *camera_nodes]
    return write_glb(path, box((1.0, 1.0, 1.0)), PAINT, [],
                     {"scenes": [{"nodes": [0, 1] if camera_nodes is None else list(range(len(nodes)))}],
                      "nodes": nodes, "cameras": cameras})


def test_a_files_camera_made_active_shows_what_a_camera_placed_by_hand_there_shows(scene, tmp_path):
    path = filmed_box(tmp_path / "filmed.glb", [SHOT])
    place, turn = glm.vec3(3.0, 0.0, -1.0), glm.angleAxis(math.radians(50.0), glm.vec3(0.0, 1.0, 0.0))

    def from_file(world):
        look_from(world, (0.0, 10.0, 10.0), (0.0, 0.0, 0.0))          # the level's camera, active
        world.spawn(DirectionalLight(direction=(-0.4, -1.0, -0.3), intensity=2.0))
        spawn_model(world, path, position=place, rotation=turn)
        for _, camera in world.query_one(Camera):
            camera.active = not camera.active                        # the model's shot shown instead

    def by_hand(world):
        world.spawn(DirectionalLight(direction=(-0.4, -1.0, -0.3), intensity=2.0))
        spawn_model(world, path, position=place, rotation=turn)
        for entity, _ in list(world.query_one(Camera)):
            world.delete_entity(entity)
        world.spawn(Transform(position=place + turn * glm.vec3(0.0, 2.0, 4.0), rotation=turn * TILT),
                    Camera(fov_y=40.0, near=0.1, far=50.0))

    shown = []
    for build in (from_file, by_hand):
        runner = scene(build, (96, 72))
        runner.frame()
        shown.append(runner.frame().astype(int))
    assert np.array_equal(shown[0], shown[1])
    box_pixels = (shown[0][..., 0] > shown[0][..., 2] + 40).sum()
    assert 200 < box_pixels < 96 * 72 / 2                             # the box, in the middle of the shot
    world = World("scaled node")
    spawn_model(world, path)
    ((entity, _),) = list(world.query_one(Camera))
    assert list(world.get(entity, Transform).scale) == [1.0, 1.0, 1.0]   # the node's scale of 3 left out


def test_a_files_cameras_are_entities_under_the_model_not_active(tmp_path):
    nodes = [{"camera": 0}, {"translation": [1.0, 0.0, 0.0], "camera": 0},
             {"camera": 1}, {"camera": 2}]
    cameras = [SHOT, {"type": "perspective", "perspective": {"yfov": 1.0, "znear": 0.5}},
               {"type": "orthographic", "name": "plan", "orthographic": {"xmag": 1, "ymag": 1, "znear": 0, "zfar": 9}}]
    path = filmed_box(tmp_path / "three.glb", cameras, nodes)
    loaded = load_model_file(path)
    assert [c.name for c in loaded.cameras] == ["shot", "shot", "camera 1", "plan"]
    world = World("cameras")
    root = spawn_model(world, path)
    found = sorted(((world.get(e, Transform).position.x, c.projection == "orthographic", c)
                    for e, c in world.query_one(Camera)), key=lambda i: i[:2])
    assert len(found) == 4 and not any(c.active for _, _, c in found)
    assert [(round(c.fov_y, 4), c.near, c.far, c.projection) for _, _, c in found if c.projection == "perspective"] == [
        (40.0, 0.1, 50.0, "perspective"), (round(math.degrees(1.0), 4), 0.5, Camera().far, "perspective"),
        (40.0, 0.1, 50.0, "perspective")]
    ((_, _, plan),) = [f for f in found if f[1]]   # (glTF's ymag is half the height; its znear 0 held just above)
    assert (plan.ortho_height, plan.near, plan.far) == (2.0, pytest.approx(1e-3), 9.0)
    assert all(world.get(e, FromModel).model == root for e, _ in world.query_one(Camera))


@pytest.mark.parametrize("camera, message", [
    ({"type": "perspective", "perspective": {"yfov": 3.2, "znear": 0.1}}, r"yfov must be an angle .* got 3\.2"),
    ({"type": "perspective", "perspective": {"yfov": 1.0, "znear": 0}}, r"znear must be a number > 0, got 0"),
    ({"type": "perspective", "perspective": {"yfov": 1.0, "znear": 1.0, "zfar": 0.5}}, r"zfar must be a number beyond"),
    ({"type": "fisheye"}, r"type must be 'perspective'"),
    ({"type": "orthographic", "orthographic": {"xmag": 1, "ymag": 0, "znear": 0, "zfar": 9}},
     r"ymag must be a number > 0"),
    ({"type": "orthographic", "orthographic": {"xmag": 1, "ymag": 1, "znear": 2, "zfar": 1}},
     r"zfar must be a number beyond znear"),
])
def test_a_bad_camera_is_refused_naming_it(tmp_path, camera, message):
    path = filmed_box(tmp_path / "bad.glb", [camera])
    with pytest.raises(AssetError, match=rf"bad\.glb': camera 0: {message}"):
        load_model_file(path)
    missing = filmed_box(tmp_path / "missing.glb", [SHOT], [{"camera": 4}])
    with pytest.raises(AssetError, match=r"node 1 names camera 4, which the file does not have \(1 defined\)"):
        load_model_file(missing)
