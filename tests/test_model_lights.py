"""Lights from glTF files (``KHR_lights_punctual``): ``spawn_model`` makes a file's point,
spot and directional lights into the engine's, placed by their nodes.  The floor a file's
spot light lights is checked pixel by pixel against the light's own numbers (candela over
distance squared, Lambert's albedo / pi, its cone) by casting each pixel's ray at the floor,
and against the same light built by hand; bad lights are refused naming the light."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from pyglm import glm

from components import DirectionalLight, Material, MeshRef, PointLight, Transform
from engine.assets.mesh import load_model_file, plane
from engine.assets.model_lights import RANGE_CUTOFF_LUX
from engine.assets.models import spawn_model
from engine.core.errors import AssetError
from engine.core.world import World
from tests.support import green_and_rays, look_from
from tests.test_materials_from_files import write_glb

WHITE_FLOOR = {"name": "floor", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0],
                                                           "metallicFactor": 0.0, "roughnessFactor": 1.0}}
DOWN = [-math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)]   # a quarter turn about x: the node's -Z points down
SPOT = {"type": "spot", "name": "lamp", "color": [1.0, 0.8, 0.6], "intensity": 5.0, "range": 10.0,
        "spot": {"innerConeAngle": 0.25, "outerConeAngle": 0.4}}
HEIGHT, FOOT = 2.0, np.array([1.0, 0.0, 0.0])


def lit_file(path: Path, lights: list[dict], light_nodes: list[dict] | None = None, required: bool = False) -> Path:
    """A white floor (8 x 8 m at y = 0) and, under a node moved 1 m along x, a node 2 m up
    turned to face down carrying light 0 (or ``light_nodes`` of one's own)."""
    nodes = [{"mesh": 0}, {"translation": [1.0, 0.0, 0.0], "children": [2]},
             {"translation": [0.0, HEIGHT, 0.0], "rotation": DOWN, "extensions": {"KHR_lights_punctual": {"light": 0}}}]
    if light_nodes is not None:
        nodes = [{"mesh": 0}, *light_nodes]
    extra = {"scenes": [{"nodes": [0, 1] if light_nodes is None else list(range(len(nodes)))}], "nodes": nodes,
             "extensions": {"KHR_lights_punctual": {"lights": lights}},
             "extensionsUsed": ["KHR_lights_punctual"]}
    if required:
        extra["extensionsRequired"] = ["KHR_lights_punctual"]
    return write_glb(path, plane(8.0, 8.0), WHITE_FLOOR, [], extra)


def floor_scene(spawn):
    def build(world):
        look_from(world, (1.0, 5.0, 3.0), (1.0, 0.0, 0.0), fov=50.0)
        spawn(world)
    return build


def test_a_files_spot_light_lights_the_floor_as_its_candela_colour_and_cone_say(scene, tmp_path):
    """The floor's green, less the frame with the light at intensity 0 (what the ambient light
    and the sky give), is the spot's light: albedo / pi x green 0.8 x 5 cd x fade^2 / (d^2 + 1)
    x cos(incidence) (the engine's falloff, ``PointLight``) inside the inner cone, nothing
    outside the outer one (the floor's highlight at roughness 1: under 3%).  The same light
    built by hand gives the same frame."""
    path = lit_file(tmp_path / "spot.glb", [SPOT], required=True)
    size = (96, 72)
    lit, eye, rays = green_and_rays(scene, floor_scene(lambda w: spawn_model(w, path)), size)
    dark, _, _ = green_and_rays(scene, floor_scene(lambda w: spawn_model(w, path, light_scale=0.0)), size)
    light = lit - dark

    t = -eye[1] / rays[:, 1]                      # each pixel's ray at the floor, y = 0
    floor = eye + t[:, None] * rays
    across = np.linalg.norm((floor - FOOT)[:, [0, 2]], axis=1)
    d = np.sqrt(across ** 2 + HEIGHT ** 2)
    fade = np.clip(1.0 - (d / 10.0) ** 4, 0.0, 1.0) ** 2
    expected = (1.0 / math.pi) * 0.8 * 5.0 * fade / (d * d + 1.0) * (HEIGHT / d)
    inner = across < 0.85 * HEIGHT * math.tan(0.25)
    outer = across > 1.15 * HEIGHT * math.tan(0.4)
    assert inner.sum() > 40 and outer.sum() > 1000
    np.testing.assert_allclose(light[inner], expected[inner], rtol=0.05)
    assert np.abs(light[outer]).max() < 0.004

    def by_hand(world):
        spawn_model(world, path, light_scale=0.0)
        down = glm.angleAxis(-math.pi / 2, glm.vec3(1.0, 0.0, 0.0))
        world.spawn(Transform(position=(1.0, HEIGHT, 0.0), rotation=down),
                    PointLight(color=(1.0, 0.8, 0.6), intensity=5.0, range=10.0, spot_angle=math.degrees(0.4),
                               spot_blend=(0.4 - 0.25) / 0.4))
    hand, _, _ = green_and_rays(scene, floor_scene(by_hand), size)
    np.testing.assert_allclose(lit, hand, atol=0.004)


def test_a_files_lights_become_entities_placed_by_their_nodes(tmp_path):
    """A sun turned by its node and by the model's rotation shines along -Z of both; a point
    light without a range reaches where its light falls to RANGE_CUTOFF_LUX; two nodes
    naming one light are two lights; light_scale multiplies every intensity."""
    sun_turn = glm.angleAxis(math.radians(30.0), glm.vec3(1.0, 0.0, 0.0))
    nodes = [{"rotation": [sun_turn.x, sun_turn.y, sun_turn.z, sun_turn.w],
              "extensions": {"KHR_lights_punctual": {"light": 0}}},
             {"translation": [0.0, 3.0, 0.0], "extensions": {"KHR_lights_punctual": {"light": 1}}},
             {"translation": [2.0, 3.0, 0.0], "extensions": {"KHR_lights_punctual": {"light": 1}}}]
    path = lit_file(tmp_path / "lights.glb", [{"type": "directional", "intensity": 3.0, "color": [1.0, 0.9, 0.8]},
                                              {"type": "point", "intensity": 4.0}], nodes)
    assert [light.kind for light in load_model_file(path).lights] == ["directional", "point", "point"]
    world = World("lights")
    model_turn = glm.angleAxis(math.radians(90.0), glm.vec3(0.0, 1.0, 0.0))
    root = spawn_model(world, path, position=(5.0, 0.0, 0.0), rotation=model_turn, light_scale=0.5)
    (sun_entity, sun), = list(world.query_one(DirectionalLight))
    np.testing.assert_allclose(list(sun.direction), list(model_turn * sun_turn * glm.vec3(0.0, 0.0, -1.0)), atol=1e-6)
    assert sun.intensity == pytest.approx(1.5) and list(sun.color) == pytest.approx([1.0, 0.9, 0.8, 1.0])
    assert world.get(sun_entity, Transform).parent == root
    lamps = sorted(world.query_one(PointLight), key=lambda item: world.get(item[0], Transform).position.x)
    assert len(lamps) == 2
    for (entity, lamp), x in zip(lamps, (0.0, 2.0), strict=True):
        assert lamp.intensity == pytest.approx(2.0) and lamp.spot_angle == 180.0
        assert lamp.range == pytest.approx(math.sqrt(2.0 / RANGE_CUTOFF_LUX))   # its light there: 1/256 lux
        assert world.get(entity, Transform).parent == root
        assert list(world.get(entity, Transform).position) == pytest.approx([x, 3.0, 0.0])
    assert len(list(world.query_one(MeshRef))) == 1 and len(list(world.query_one(Material))) == 1


@pytest.mark.parametrize("light, message", [
    ({"type": "area"}, r"light 0: type must be one of \('directional', 'point', 'spot'\), got 'area'"),
    ({"type": "point", "color": [2.0, 1.0, 1.0]}, r"color must be three numbers in \[0, 1\]"),
    ({"type": "point", "intensity": -1}, r"intensity must be a number >= 0, got -1"),
    ({"type": "point", "range": 0}, r"range must be a number > 0, got 0"),
    ({"type": "spot", "name": "cone", "spot": {"innerConeAngle": 0.5, "outerConeAngle": 0.3}},
     r"light 0 \('cone'\): its cone angles must satisfy 0 <= innerConeAngle < outerConeAngle <= pi/2"),
    ({"type": "spot"}, r"a spot light needs its spot object"),
    ({"type": "point", "extras": {"speculum": {"radius": "big"}}},
     r"extras\.speculum\.radius must be a number \(PointLight\.radius\), got 'big'"),
    ({"type": "point", "extras": {"speculum": {"rectangle": [1.0]}}},
     r"extras\.speculum\.rectangle must be two numbers"),
    ({"type": "point", "extras": {"speculum": {"width": 1.0}}},
     r"extras\.speculum must be an object of PointLight's fields \('radius', 'rectangle', 'length', 'shadows'"),
    ({"type": "directional", "extras": {"speculum": {"radius": 1.0}}},
     r"extras\.speculum must be an object of DirectionalLight's fields \('shadows'"),
    ({"type": "spot", "spot": {}, "extras": {"speculum": {"shadows": 1}}},
     r"extras\.speculum\.shadows must be true or false \(PointLight\.shadows\), got 1"),
    ({"type": "point", "extras": {"speculum": {"shadow_resolution": 512.5}}},
     r"extras\.speculum\.shadow_resolution must be a whole number \(PointLight\.shadow_resolution\), got 512\.5"),
    ({"type": "directional", "extras": {"speculum": {"body": 3}}},
     r"extras\.speculum\.body must be a string \(DirectionalLight\.body\), got 3"),
])
def test_a_bad_light_is_refused_naming_it(tmp_path, light, message):
    path = lit_file(tmp_path / "bad.glb", [light])
    with pytest.raises(AssetError, match=rf"bad\.glb.*{message}"):
        load_model_file(path)


def test_a_lamps_shape_the_engine_refuses_is_refused_at_spawn_naming_the_light(tmp_path):
    """A shape whose types are right and whose values PointLight refuses (a radius with a
    rectangle, a negative length) is an error naming the file, its light and the field,
    nothing spawned."""
    for shape, field in (({"radius": 0.2, "rectangle": [1.0, 1.0]}, "radius"), ({"length": -1.0}, "length")):
        world = World("shaped")
        path = lit_file(tmp_path / "shaped.glb", [{"type": "point", "name": "bulb", "extras": {"speculum": shape}}])
        with pytest.raises(AssetError, match=rf"shaped\.glb.*light 'bulb'.*{field}"):
            spawn_model(world, path)
        assert not list(world.query_one(Transform))


def test_a_missing_light_or_one_past_half_floats_is_refused(tmp_path):
    path = lit_file(tmp_path / "none.glb", [{"type": "point"}],
                    [{"extensions": {"KHR_lights_punctual": {"light": 3}}}])
    with pytest.raises(AssetError, match=r"node 1 names KHR_lights_punctual light 3, which the file does not have"):
        load_model_file(path)
    world = World("sunny")
    path = lit_file(tmp_path / "sunny.glb", [{"type": "directional", "name": "noon", "intensity": 100000.0}],
                    [{"extensions": {"KHR_lights_punctual": {"light": 0}}}])
    with pytest.raises(AssetError, match=r"sunny\.glb.*'noon': intensity 100000 lux .* give spawn_model a light_scale "
                                         r"of at most 0\.655"):
        spawn_model(world, path)
    assert not list(world.query_one(Transform))   # nothing half-spawned
    spawn_model(world, path, light_scale=0.5)
    ((_, sun),) = list(world.query_one(DirectionalLight))
    assert sun.intensity == pytest.approx(50000.0)


def test_a_models_sun_turns_with_an_entity_it_hangs_under(tmp_path):
    """A model placed under a turntable entity: turning the turntable (the model's root
    untouched) turns the file's sun with it, as turning the root does."""
    from systems.model_system import ModelSystem

    nodes = [{"extensions": {"KHR_lights_punctual": {"light": 0}}}]
    path = lit_file(tmp_path / "sun.glb", [{"type": "directional", "intensity": 3.0}], nodes)
    world = World("turntable")
    table = world.spawn(Transform())
    root = spawn_model(world, path)
    world.get(root, Transform).parent = table
    stage = ModelSystem(world)
    stage.process(0.0)
    ((_, sun),) = list(world.query_one(DirectionalLight))
    np.testing.assert_allclose(list(sun.direction), [0.0, 0.0, -1.0], atol=1e-6)
    world.step(0.0)   # (the frame over: its changes forgotten)
    turn = glm.angleAxis(math.radians(90.0), glm.vec3(0.0, 1.0, 0.0))
    world.get(table, Transform).rotation = turn
    stage.process(0.0)
    np.testing.assert_allclose(list(sun.direction), list(turn * glm.vec3(0.0, 0.0, -1.0)), atol=1e-6)


def test_a_suns_field_the_engine_refuses_is_refused_at_spawn_naming_the_light(tmp_path):
    """A sun's extras whose types are right and whose value DirectionalLight refuses (nine
    cascades) is an error naming the file, its light and the field, nothing spawned."""
    world = World("sunny")
    path = lit_file(tmp_path / "cascades.glb", [{"type": "directional", "name": "noon",
                                                 "extras": {"speculum": {"shadow_cascades": 9}}}],
                    [{"extensions": {"KHR_lights_punctual": {"light": 0}}}])
    with pytest.raises(AssetError, match=r"cascades\.glb.*light 'noon'.*shadow_cascades"):
        spawn_model(world, path)
    assert not list(world.query_one(Transform))
