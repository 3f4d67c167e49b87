"""glTF animations (``Animation`` on a model's root): a clip moves the model's parts as
its channels say.  A door on a hinge node (rotation, linear), a knob on it (translation,
cubic spline) and a lamp shade (scale, step): each part's place at a time against the
matrices glm multiplies out from the clip's keys (slerp, Hermite, step), and the frame of
the posed model against the same box placed by hand there (a second path); playing, speed,
looping and holding at the end; a clip the file lacks, and malformed channels, refused."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from pyglm import glm

from components import Animation, ComponentValueError, DirectionalLight, Material, MeshRef, Model, Transform
from engine.assets.mesh import box, load_model_file
from engine.assets.models import SpawnedModels, spawn_model
from engine.core.errors import AssetError
from engine.core.world import World
from tests.support import look_from
from tests.test_materials_from_files import write_glb
from tests.test_model_variants import add_accessors, edit_glb

QUARTER = glm.angleAxis(math.pi / 2, glm.vec3(0.0, 1.0, 0.0))


def door(path: Path, channels: list[dict] | None = None) -> Path:
    """Nodes: 0 the hinge at (1, 0, 0) (no mesh), 1 the door box under it at (0.5, 0, 0);
    clip "Open" turns the hinge a quarter about +Y over 2 s; clip "Slide" moves the door along
    a cubic spline; clip "Blink" steps its scale."""
    write_glb(path, box((1.0, 1.0, 0.1)), {"name": "wood", "pbrMetallicRoughness": {"baseColorFactor":
                                                                                   [0.7, 0.4, 0.2, 1.0]}}, [])
    q = [QUARTER.x, QUARTER.y, QUARTER.z, QUARTER.w]
    arrays = [np.array([0.0, 2.0], np.float32), np.array([[0, 0, 0, 1], q], np.float32),
              np.array([0.0, 1.0], np.float32),
              # cubic: (in-tangent, value, out-tangent) a key
              np.array([[0, 0, 0], [0.5, 0, 0], [1, 0, 0], [1, 0, 0], [0.5, 1, 0], [0, 0, 0]], np.float32),
              np.array([0.0, 1.0, 2.0], np.float32), np.array([[1, 1, 1], [2, 2, 2], [1, 1, 1]], np.float32)]

    def change(doc: dict) -> None:
        first = add_accessors(doc, arrays)
        doc["nodes"] = [{"name": "hinge", "translation": [1.0, 0.0, 0.0], "children": [1]},
                        {"name": "door", "mesh": 0, "translation": [0.5, 0.0, 0.0]}]
        doc["scenes"] = [{"nodes": [0]}]
        a = first
        doc["animations"] = [
            {"name": "Open", "samplers": [{"input": a, "output": a + 1}],
             "channels": channels or [{"sampler": 0, "target": {"node": 0, "path": "rotation"}}]},
            {"name": "Slide", "samplers": [{"input": a + 2, "output": a + 3, "interpolation": "CUBICSPLINE"}],
             "channels": [{"sampler": 0, "target": {"node": 1, "path": "translation"}}]},
            {"name": "Blink", "samplers": [{"input": a + 4, "output": a + 5, "interpolation": "STEP"}],
             "channels": [{"sampler": 0, "target": {"node": 1, "path": "scale"}}]}]
    return edit_glb(path, change)


def door_matrix(world: World) -> glm.mat4:
    (record,) = world.resources[SpawnedModels].values()
    entity = record.parts[[part.node for part in record.loaded.parts].index(1)]   # the door's node
    t = world.get(entity, Transform)
    return glm.translate(t.position) * glm.mat4_cast(t.rotation) * glm.scale(t.scale)


def played(path: Path, clip: str, seconds: list[float], **fields) -> tuple[World, list[glm.mat4]]:
    """The model under a root at the origin with an Animation, stepped by ``seconds``."""
    from systems.model_system import ModelSystem

    world = World(f"playing {clip}")
    root = spawn_model(world, path)
    world.add_component(root, Animation(clip=clip, **fields))
    stage = ModelSystem(world)
    placed = []
    for dt in seconds:
        stage.process(dt)
        placed.append(door_matrix(world))
    return world, placed


def close(a: glm.mat4, b: glm.mat4) -> bool:
    return all(abs(a[c][r] - b[c][r]) < 1e-4 for c in range(4) for r in range(4))


def test_a_clips_channels_place_the_parts_at_each_time(tmp_path):
    path = door(tmp_path / "door.glb")
    loaded = load_model_file(path)
    assert [(c.name, c.duration) for c in loaded.animations] == [("Open", 2.0), ("Slide", 1.0), ("Blink", 2.0)]
    hinge, offset = glm.translate(glm.vec3(1, 0, 0)), glm.translate(glm.vec3(0.5, 0, 0))
    _, open_ = played(path, "Open", [0.0, 0.5, 0.5, 0.9, 1.0])
    for placed, t in zip(open_, (0.0, 0.5, 1.0, 1.9, 0.9), strict=True):   # looped: 2.9 s is 0.9 s in
        turn = glm.slerp(glm.quat(), QUARTER, t / 2.0)
        assert close(placed, hinge * glm.mat4_cast(turn) * offset), t
    _, slide = played(path, "Slide", [0.5])
    s = 0.5   # Hermite between (0.5, 0, 0) with out-tangent (1, 0, 0) and (0.5, 1, 0) with in-tangent (1, 0, 0)
    p = (2 * s ** 3 - 3 * s ** 2 + 1) * glm.vec3(0.5, 0, 0) + (s ** 3 - 2 * s ** 2 + s) * glm.vec3(1, 0, 0) \
        + (-2 * s ** 3 + 3 * s ** 2) * glm.vec3(0.5, 1, 0) + (s ** 3 - s ** 2) * glm.vec3(1, 0, 0)
    assert close(slide[0], hinge * glm.translate(p))
    _, blink = played(path, "Blink", [0.5, 0.6, 1.0], loop=False)   # steps: 1 until 1 s, 2 until 2 s, held
    assert [round(m[0][0], 4) for m in blink] == [1.0, 2.0, 1.0]


def test_paused_reversed_and_held_at_the_end(tmp_path):
    path = door(tmp_path / "door.glb")
    world, paused = played(path, "Open", [0.5, 0.5], playing=False, time=1.0)
    half = glm.translate(glm.vec3(1, 0, 0)) * glm.mat4_cast(glm.slerp(glm.quat(), QUARTER, 0.5)) \
        * glm.translate(glm.vec3(0.5, 0, 0))
    assert close(paused[0], half) and close(paused[1], half)
    _, held = played(path, "Open", [5.0], loop=False)
    hinge, offset = glm.translate(glm.vec3(1, 0, 0)), glm.translate(glm.vec3(0.5, 0, 0))
    assert close(held[0], hinge * glm.mat4_cast(QUARTER) * offset)
    world, back = played(path, "Open", [0.5], speed=-1.0, time=1.0, loop=False)
    assert close(back[0], hinge * glm.mat4_cast(glm.slerp(glm.quat(), QUARTER, 0.25)) * offset)
    ((_, animation),) = list(world.query_one(Animation))
    assert animation.time == pytest.approx(0.5)


def test_a_posed_model_draws_as_the_box_placed_there_by_hand(scene, tmp_path):
    path = door(tmp_path / "door.glb")

    def lit(build):
        def made(world):
            look_from(world, (0.5, 2.5, 4.0), (1.0, 0.0, 0.0), fov=50.0)
            world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.5), intensity=2.0))
            build(world)
        return made

    def animated(world):
        root = world.spawn(Transform(), Model(file=str(path)))
        world.add_component(root, Animation(clip="Open", time=1.0, playing=False))

    def by_hand(world):
        turn = glm.slerp(glm.quat(), QUARTER, 0.5)
        world.spawn(Transform(position=glm.vec3(1, 0, 0) + turn * glm.vec3(0.5, 0, 0), rotation=turn),
                    MeshRef(load_model_file(path).parts[0].mesh), Material(color=(0.7, 0.4, 0.2, 1.0)))

    frames = []
    for build in (animated, by_hand):
        runner = scene(lit(build), (96, 72))
        runner.frame()
        frames.append(runner.frame().astype(int))
    assert np.abs(frames[0] - frames[1]).max() <= 2
    assert (np.abs(frames[0] - frames[0][0, 0]).sum(-1) > 30).sum() > 80   # the door is there


def test_a_missing_clip_and_malformed_channels_are_refused(tmp_path):
    path = door(tmp_path / "door.glb")
    with pytest.raises(AssetError, match=r"its model has no clip 'Close' \(its clips: 'Open', 'Slide', 'Blink'\)"):
        played(path, "Close", [0.1])
    bad = door(tmp_path / "bad.glb", [{"sampler": 0, "target": {"node": 7, "path": "rotation"}}])
    with pytest.raises(AssetError, match=r"bad\.glb': animation 0 \('Open'\): channel 0: target.node names node 7"):
        load_model_file(bad)
    odd = door(tmp_path / "odd.glb", [{"sampler": 0, "target": {"node": 0, "path": "skew"}}])
    with pytest.raises(AssetError, match=r"target.path must be one of"):
        load_model_file(odd)
    wide = door(tmp_path / "wide.glb", [{"sampler": 0, "target": {"node": 0, "path": "translation"}}])
    with pytest.raises(AssetError, match=r"its output must be 2 finite translation values of 3"):
        load_model_file(wide)
    def spoil(change):
        return edit_glb(door(tmp_path / "spoilt.glb"), change)
    with pytest.raises(AssetError, match=r"animation 0 \('Open'\): channels must be a list, got 5"):
        load_model_file(spoil(lambda doc: doc["animations"][0].update(channels=5)))
    def bad_matrix(doc: dict) -> None:   # on the door, animated now only by "Open" on its hinge
        doc["nodes"][1]["matrix"] = [1, 2, 3]
        del doc["animations"][1:]
    with pytest.raises(AssetError, match=r"node 1: matrix must be 16 finite numbers"):
        load_model_file(spoil(bad_matrix))
    for field, value in (("clip", 3), ("time", -1.0), ("speed", float("nan")), ("loop", 1)):
        with pytest.raises(ComponentValueError, match=f"Animation.{field}"):
            Animation(**{field: value})


OFFSET_POINTER = "/materials/0/pbrMetallicRoughness/baseColorTexture/extensions/KHR_texture_transform/offset"


def test_animation_pointer_channels_play_a_nodes_transform_and_leave_the_rest_out_saying_so(tmp_path):
    """KHR_animation_pointer: a channel aimed at ``/nodes/0/rotation`` turns the hinge exactly
    as the same channel by ``path``; one aimed at a property the engine does not play (a
    texture transform's offset) is left out with a warning naming its pointer (the clip plays
    the rest, no refusal of the file); a pointer target without its pointer string is refused."""
    plain = door(tmp_path / "plain.glb")
    pointed = door(tmp_path / "pointed.glb", [
        {"sampler": 0, "target": {"path": "pointer", "extensions": {"KHR_animation_pointer": {
            "pointer": "/nodes/0/rotation"}}}},
        {"sampler": 0, "target": {"path": "pointer", "extensions": {"KHR_animation_pointer": {
            "pointer": OFFSET_POINTER}}}}])
    with pytest.warns(UserWarning, match=r"animation 0 \('Open'\): channel 1: KHR_animation_pointer "
                                         rf"'{OFFSET_POINTER}' left out"):
        loaded = load_model_file(pointed)
    assert [(channel.node, channel.path) for channel in loaded.animations[0].channels] == [(0, "rotation")]
    times = [0.0, 0.5, 1.0, 0.5]
    with pytest.warns(UserWarning):
        _, turned = played(pointed, "Open", times)
    _, expected = played(plain, "Open", times)
    assert all(close(a, b) for a, b in zip(turned, expected, strict=True))
    assert not close(turned[1], turned[0])
    bare = door(tmp_path / "bare.glb", [{"sampler": 0, "target": {"path": "pointer"}}])
    with pytest.raises(AssetError, match=r"channel 0: target.path 'pointer' needs extensions.KHR_animation_pointer"):
        load_model_file(bare)
    far = door(tmp_path / "far.glb", [{"sampler": 0, "target": {"path": "pointer", "extensions": {
        "KHR_animation_pointer": {"pointer": "/nodes/9/rotation"}}}}])
    with pytest.raises(AssetError, match=r"channel 0: target.node names node 9"):
        load_model_file(far)


def glowing(path: Path, metallic: tuple[float, float] = (0.0, 1.0), camera: int = 0) -> Path:
    """The door with a spot light and a camera under the hinge, and a clip "Glow" of
    KHR_animation_pointer channels over 2 s: material 0's baseColorFactor (linear) and
    metallicFactor (step, ``metallic``), light 0's intensity 5 -> 15 (linear) and camera
    ``camera``'s yfov 0.8 -> 0.4 (linear)."""
    def change(doc: dict) -> None:
        doc["extensionsUsed"] = ["KHR_lights_punctual", "KHR_animation_pointer"]
        doc["extensions"] = {"KHR_lights_punctual": {"lights": [
            {"type": "spot", "intensity": 5.0, "spot": {"outerConeAngle": 0.6}}]}}
        doc["cameras"] = [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}}]
        doc["nodes"][0]["children"] += [2, 3]
        doc["nodes"] += [{"name": "lamp", "translation": [0.5, 1.0, 0.0],
                          "extensions": {"KHR_lights_punctual": {"light": 0}}},
                         {"name": "eye", "camera": 0, "translation": [0.0, 0.5, 2.0]}]
        first = add_accessors(doc, [np.array([0.0, 2.0], np.float32),
                                    np.array([[0.7, 0.4, 0.2, 1.0], [0.1, 0.9, 0.3, 0.5]], np.float32),
                                    np.array([[metallic[0]], [metallic[1]]], np.float32),
                                    np.array([[5.0], [15.0]], np.float32), np.array([[0.8], [0.4]], np.float32)])

        def aimed(sampler: int, pointer: str) -> dict:
            return {"sampler": sampler, "target": {"path": "pointer",
                                                   "extensions": {"KHR_animation_pointer": {"pointer": pointer}}}}
        doc["animations"].append({"name": "Glow", "samplers": [
            {"input": first, "output": first + 1}, {"input": first, "output": first + 2, "interpolation": "STEP"},
            {"input": first, "output": first + 3}, {"input": first, "output": first + 4}], "channels": [
            aimed(0, "/materials/0/pbrMetallicRoughness/baseColorFactor"),
            aimed(1, "/materials/0/pbrMetallicRoughness/metallicFactor"),
            aimed(2, "/extensions/KHR_lights_punctual/lights/0/intensity"),
            aimed(3, f"/cameras/{camera}/perspective/yfov")]})
    return edit_glb(door(path), change)


def playing_lamp(path: Path, clip: str, **spawned) -> tuple:
    """The door model of ``path`` spawned playing ``clip`` once: (world, its models stage, the
    door's part, the lamp's entity, the camera's entity)."""
    from components import Camera, PointLight
    from systems.model_system import ModelSystem

    world = World(clip)
    root = spawn_model(world, path, **spawned)
    world.add_component(root, Animation(clip=clip, loop=False))
    record = world.resources[SpawnedModels][root]
    (lamp, _), = world.query_one(PointLight)
    (eye, _), = world.query_one(Camera)
    return world, ModelSystem(world), record.parts[record.nodes.index(1)], lamp, eye


def test_animation_pointers_play_a_materials_colour_a_lights_intensity_and_a_cameras_lens(tmp_path):
    """A clip of KHR_animation_pointer channels at a material's baseColorFactor (linear) and
    metallicFactor (step), a spot light's intensity (linear; the engine's is the file's times
    the light scale) and a camera's yfov: at each time the components made from them hold the
    keys' values mixed as glTF says (worked out here); keys outside a property's range, or a
    pointer at a camera the file lacks, are refused naming the channel."""
    from components import Camera, PointLight

    world, stage, door_part, lamp, eye = playing_lamp(glowing(tmp_path / "door.glb"), "Glow", light_scale=2.0)
    for dt, t in ((0.5, 0.5), (1.0, 1.5)):
        stage.process(dt)
        s = t / 2.0
        material = world.get(door_part, Material)
        expected = np.array([0.7, 0.4, 0.2, 1.0]) * (1 - s) + np.array([0.1, 0.9, 0.3, 0.5]) * s
        np.testing.assert_allclose(list(material.color), expected, atol=1e-6)
        assert material.metallic == 0.0                                     # (stepped: the first key's)
        assert world.get(lamp, PointLight).intensity == pytest.approx((5.0 * (1 - s) + 15.0 * s) * 2.0)
        assert world.get(eye, Camera).fov_y == pytest.approx(math.degrees(0.8 * (1 - s) + 0.4 * s))
    stage.process(1.0)   # (held at the end: the last keys)
    assert world.get(door_part, Material).metallic == 1.0
    assert world.get(lamp, PointLight).intensity == pytest.approx(30.0)
    world.step(0.0)      # (forgets the frame's changes)
    stage.process(0.5)   # held: the same values, not written again (no rows uploaded again)
    assert door_part not in world.changed(Material) and lamp not in world.changed(PointLight)
    with pytest.raises(AssetError, match=r"'Glow'\): channel 1: .*materials.metallicFactor keys must lie in \[0, 1\]"):
        load_model_file(glowing(tmp_path / "bad.glb", metallic=(0.0, 2.0)))
    with pytest.raises(AssetError, match=r"channel 3: KHR_animation_pointer '/cameras/7/perspective/yfov' names "
                                         r"camera 7, which the file does not have"):
        load_model_file(glowing(tmp_path / "far.glb", camera=7))


def pulsing(path: Path, inner: float = 0.5) -> Path:
    """The door with a spot light (cones 0.2 and 0.6 rad, range 8 m) and an orthographic
    camera (ymag 2) under the hinge, and a clip "Pulse" over 2 s (all linear): material 0's
    emissiveFactor (0, 0, 0) -> (0.35, 0.2, 0.1) and emissive strength 1 -> 3, its normal
    texture's scale 1 -> 0.5 and occlusion texture's strength 1 -> 0, the light's range 8 -> 4
    and cones 0.2 -> ``inner``, 0.6 -> 0.7, the camera's ymag 2 -> 1."""
    def change(doc: dict) -> None:
        doc["extensionsUsed"] = ["KHR_lights_punctual", "KHR_animation_pointer", "KHR_materials_emissive_strength"]
        doc["materials"][0]["extensions"] = {"KHR_materials_emissive_strength": {"emissiveStrength": 1.0}}
        doc["extensions"] = {"KHR_lights_punctual": {"lights": [
            {"type": "spot", "intensity": 5.0, "range": 8.0, "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.6}}]}}
        doc["cameras"] = [{"type": "orthographic", "orthographic": {"xmag": 2.0, "ymag": 2.0, "znear": 0.1,
                                                                     "zfar": 50.0}}]
        doc["nodes"][0]["children"] += [2, 3]
        doc["nodes"] += [{"name": "lamp", "translation": [0.5, 1.0, 0.0],
                          "extensions": {"KHR_lights_punctual": {"light": 0}}},
                         {"name": "eye", "camera": 0, "translation": [0.0, 0.5, 2.0]}]
        pairs = [([0.0, 0.0, 0.0], [0.35, 0.2, 0.1]), ([1.0], [3.0]), ([1.0], [0.5]), ([1.0], [0.0]),
                 ([8.0], [4.0]), ([0.2], [inner]), ([0.6], [0.7]), ([2.0], [1.0])]
        first = add_accessors(doc, [np.array([0.0, 2.0], np.float32),
                                    *(np.array([a, b], np.float32) for a, b in pairs)])
        pointers = ["/materials/0/emissiveFactor",
                    "/materials/0/extensions/KHR_materials_emissive_strength/emissiveStrength",
                    "/materials/0/normalTexture/scale", "/materials/0/occlusionTexture/strength",
                    "/extensions/KHR_lights_punctual/lights/0/range",
                    "/extensions/KHR_lights_punctual/lights/0/spot/innerConeAngle",
                    "/extensions/KHR_lights_punctual/lights/0/spot/outerConeAngle", "/cameras/0/orthographic/ymag"]
        doc["animations"].append({"name": "Pulse", "samplers": [
            {"input": first, "output": first + 1 + i} for i in range(len(pointers))], "channels": [
            {"sampler": i, "target": {"path": "pointer", "extensions": {"KHR_animation_pointer": {"pointer": p}}}}
            for i, p in enumerate(pointers)]})
    return edit_glb(door(path), change)


def test_animation_pointers_play_emission_map_strengths_a_spots_cones_and_range_and_an_orthographic_height(
        tmp_path):
    """A clip of KHR_animation_pointer channels at a material's emissiveFactor and emissive
    strength (the part had no Emissive: one is given, its power the factor over the diffuse
    colour on its strongest channel times the strength, as the loader works it out), its
    normal scale and occlusion strength, a spot light's range and cone angles (spot_angle the
    outer in degrees, spot_blend the share between the cones) and an orthographic camera's
    ymag (half its height): at each time the components hold the keys' mix; a cone past 90
    degrees is refused naming the channel."""
    from components import Camera, Emissive, PointLight

    world, stage, door_part, lamp, eye = playing_lamp(pulsing(tmp_path / "door.glb"), "Pulse")
    assert world.try_get(door_part, Emissive) is None   # (black at rest)
    red = world.get(door_part, Material).color[0]       # its diffuse's strongest channel (0.7, as the file keeps it)
    for dt, t in ((0.5, 0.5), (1.0, 1.5)):
        stage.process(dt)
        s = t / 2.0
        assert world.get(door_part, Emissive).power == pytest.approx(0.35 * s * (1 + 2 * s) / red, rel=1e-5)
        material = world.get(door_part, Material)
        assert (material.normal_scale, material.occlusion_strength) == pytest.approx((1 - 0.5 * s, 1 - s))
        light = world.get(lamp, PointLight)
        inner, outer = 0.2 + 0.3 * s, 0.6 + 0.1 * s
        assert light.range == pytest.approx(8 - 4 * s)
        assert light.spot_angle == pytest.approx(math.degrees(outer), rel=1e-5)
        assert light.spot_blend == pytest.approx((outer - inner) / outer, rel=1e-5)
        camera = world.get(eye, Camera)
        assert camera.projection == "orthographic" and camera.ortho_height == pytest.approx(2 * (2 - s))
    with pytest.raises(AssetError, match=r"'Pulse'\): channel 5: .*lights.innerConeAngle keys must lie in "
                                         r"\[0, 1.5708\]"):
        load_model_file(pulsing(tmp_path / "bad.glb", inner=2.0))


def test_a_crossfade_mixes_the_properties_both_clips_animate(tmp_path):
    """"Glow" fading into "Blue" (the material's colour held blue) over a second: half way the
    colour is the two clips' colours mixed half and half, as the nodes' poses are; the lamp's
    intensity, which "Blue" leaves alone, follows "Glow" until the fade ends and then holds."""
    from components import PointLight
    from engine.assets.models import crossfade

    def blue(doc: dict) -> None:
        first = add_accessors(doc, [np.array([0.0, 2.0], np.float32),
                                    np.array([[0.0, 0.0, 1.0, 1.0], [0.0, 0.0, 1.0, 1.0]], np.float32)])
        doc["animations"].append({"name": "Blue", "samplers": [{"input": first, "output": first + 1}], "channels": [
            {"sampler": 0, "target": {"path": "pointer", "extensions": {"KHR_animation_pointer": {
                "pointer": "/materials/0/pbrMetallicRoughness/baseColorFactor"}}}}]})

    world, stage, door_part, lamp, _ = playing_lamp(edit_glb(glowing(tmp_path / "door.glb"), blue), "Glow")
    stage.process(0.5)                                   # Glow at 0.5 s
    animation = next(a for _, a in world.query_one(Animation))
    crossfade(animation, "Blue", 1.0)
    stage.process(0.5)                                   # half way: Glow at 1.0 s, Blue at 0.5 s
    glow = np.array([0.7, 0.4, 0.2, 1.0]) * 0.5 + np.array([0.1, 0.9, 0.3, 0.5]) * 0.5
    np.testing.assert_allclose(list(world.get(door_part, Material).color), glow * 0.5 + np.array([0, 0, 1, 1]) * 0.5,
                               atol=1e-5)
    assert world.get(lamp, PointLight).intensity == pytest.approx(10.0)   # (Glow's at 1.0 s: 5 -> 15 over 2 s)
    stage.process(0.75)                                  # the fade done: Blue alone, the intensity held
    np.testing.assert_allclose(list(world.get(door_part, Material).color), [0.0, 0.0, 1.0, 1.0], atol=1e-6)
    held = world.get(lamp, PointLight).intensity
    stage.process(0.5)
    assert world.get(lamp, PointLight).intensity == held


def test_a_level_plays_a_clip_and_a_missing_one_is_refused_by_its_line(tmp_path):
    from engine.assets.level_file import LevelError, load_level

    door(tmp_path / "door.glb")
    text = ('[level]\nname = "hall"\n\n[[entity]]\nname = "door"\n[entity.Transform]\n[entity.Model]\n'
            'file = "door.glb"\n[entity.Animation]\nclip = "CLIP"\ntime = 1.0\nplaying = false\n')
    (tmp_path / "hall.toml").write_text(text.replace("CLIP", "Open"))
    world = World("hall")
    load_level(tmp_path / "hall.toml").spawn(world)
    from systems.model_system import ModelSystem
    ModelSystem(world).process(1 / 60)
    half = glm.translate(glm.vec3(1, 0, 0)) * glm.mat4_cast(glm.slerp(glm.quat(), QUARTER, 0.5)) \
        * glm.translate(glm.vec3(0.5, 0, 0))
    assert close(door_matrix(world), half)
    (tmp_path / "hall.toml").write_text(text.replace("CLIP", "Close"))
    with pytest.raises(LevelError, match=r"no animation clip 'Close' \(its clips: 'Open', 'Slide', 'Blink'") as caught:
        load_level(tmp_path / "hall.toml")
    assert (caught.value.entity, caught.value.field, caught.value.line) == ("door", "Animation.clip", 10)


def test_a_playing_clip_leaves_the_parts_it_does_not_move_unwritten(tmp_path):
    """A frame beside the door (a node of its own, not under the hinge): once the clip plays
    on, only the door's Transform is written each frame (the frame's rows are not uploaded
    again, nor its shadow drawn again); switching clips writes every part once."""
    from engine.assets.models import SpawnedModels
    from systems.model_system import ModelSystem

    def frame(doc: dict) -> None:
        doc["nodes"].append({"name": "frame", "mesh": 0, "translation": [-1.0, 0.0, 0.0]})
        doc["scenes"][0]["nodes"].append(2)
    path = edit_glb(door(tmp_path / "door.glb"), frame)
    world = World("beside")
    root = spawn_model(world, path)
    world.add_component(root, Animation(clip="Open"))
    stage = ModelSystem(world)
    record = world.resources[SpawnedModels][root]
    door_part, frame_part = (record.parts[record.nodes.index(n)] for n in (1, 2))
    stage.process(0.1)
    world.step(0.0)                      # (the step forgets this frame's changes)
    stage.process(0.1)
    assert door_part in world.changed(Transform) and frame_part not in world.changed(Transform)
    world.step(0.0)
    world.get(root, Animation).clip = "Slide"
    stage.process(0.1)
    assert {door_part, frame_part} <= world.changed(Transform)
    assert list(world.get(frame_part, Transform).position) == pytest.approx([-1.0, 0.0, 0.0])


def test_a_clip_moves_the_lights_and_cameras_on_the_nodes_it_turns(tmp_path):
    """A spot light, a sun and a camera on nodes under the hinge: half way through "Open" each
    stands (and the sun shines) where the hinge's turn puts its node, the camera unscaled."""
    from components import Camera, PointLight

    path = door(tmp_path / "door.glb")

    def change(doc: dict) -> None:
        doc["extensionsUsed"] = ["KHR_lights_punctual"]
        doc["extensions"] = {"KHR_lights_punctual": {"lights": [
            {"type": "spot", "intensity": 5.0, "spot": {"outerConeAngle": 0.6}}, {"type": "directional"}]}}
        doc["cameras"] = [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}}]
        doc["nodes"][0]["children"] += [2, 3, 4]
        doc["nodes"] += [{"name": "lamp", "translation": [0.5, 1.0, 0.0],
                          "extensions": {"KHR_lights_punctual": {"light": 0}}},
                         {"name": "sun", "extensions": {"KHR_lights_punctual": {"light": 1}}},
                         {"name": "eye", "camera": 0, "translation": [0.0, 0.5, 2.0], "scale": [2.0, 2.0, 2.0]}]

    edit_glb(path, change)
    world, _ = played(path, "Open", [1.0], playing=True)
    hinge = glm.translate(glm.vec3(1, 0, 0)) * glm.mat4_cast(glm.slerp(glm.quat(), QUARTER, 0.5))

    def placed(kind) -> Transform:
        ((entity, _),) = list(world.query_one(kind))
        return world.get(entity, Transform)

    lamp, eye = placed(PointLight), placed(Camera)
    assert glm.distance(lamp.position, glm.vec3(hinge * glm.vec4(0.5, 1.0, 0.0, 1.0))) < 1e-5
    assert abs(abs(glm.dot(lamp.rotation, glm.quat_cast(glm.mat3(hinge)))) - 1.0) < 1e-6   # turned with it
    assert glm.distance(eye.position, glm.vec3(hinge * glm.vec4(0.0, 0.5, 2.0, 1.0))) < 1e-5
    assert glm.distance(eye.scale, glm.vec3(1.0)) < 1e-6
    ((_, sun),) = list(world.query_one(DirectionalLight))
    expected = glm.normalize(glm.vec3(hinge * glm.vec4(0.0, 0.0, -1.0, 0.0)))
    assert glm.distance(glm.normalize(sun.direction), expected) < 1e-5
    # The model's root turned a quarter about +y (the clip paused): its sun turns with it.
    from systems.model_system import ModelSystem
    ((root, animation),) = list(world.query_one(Animation))
    animation.playing = False
    stage = ModelSystem(world)
    stage.process(0.0)   # (posed once, paused: the next frame poses nothing)
    world.step(0.0)      # (a frame's end: its change sets cleared)
    world.get(root, Transform).rotation = QUARTER
    stage.process(0.0)
    turned = glm.normalize(glm.vec3(glm.mat4_cast(QUARTER) * hinge * glm.vec4(0.0, 0.0, -1.0, 0.0)))
    assert glm.distance(glm.normalize(sun.direction), turned) < 1e-5


def test_every_nodes_pose_is_its_own_transform_times_its_parents_on_a_branching_tree():
    """``pose_all`` (every node at once, a depth at a time) against each node's matrix worked
    out by hand with glm, its parent's times its own: a tree branching at its root, a chain
    under one branch, a node given a matrix, channels of each interpolation (two groups of
    rotations with different key times), at rest, between keys and past the end."""
    from engine.assets.gltf_animations import Channel, Clip, NodeTree, pose_all

    rng = np.random.default_rng(5)
    parents = [None, 0, 0, 2, 3, 4, None]
    rest = [(rng.uniform(-1, 1, 3), (lambda q: q / np.linalg.norm(q))(rng.normal(size=4)), rng.uniform(0.5, 2, 3))
            for _ in parents]
    given = glm.translate(glm.vec3(0.3, 0.2, 0.1)) * glm.mat4_cast(glm.angleAxis(0.4, glm.vec3(0, 0, 1)))
    tree = NodeTree(parents=parents, rest=rest, matrices={1: np.array(given, np.float64)})

    def unit_rows(n):
        q = rng.normal(size=(n, 4))
        return q / np.linalg.norm(q, axis=1, keepdims=True)

    times = np.array([0.0, 0.5, 1.2])
    channels = [Channel(3, "rotation", times, unit_rows(3), "LINEAR"),
                Channel(5, "rotation", times, unit_rows(3), "LINEAR"),
                Channel(4, "rotation", np.array([0.0, 2.0]), unit_rows(2), "LINEAR"),
                Channel(2, "translation", times, rng.uniform(-1, 1, (3, 3)), "STEP"),
                Channel(0, "scale", times, rng.uniform(0.5, 1.5, (3, 3, 3)), "CUBICSPLINE")]
    clip = Clip("mixed", channels, 2.0)

    def by_hand(node: int, t: float) -> glm.mat4:
        if node in tree.matrices:
            local = glm.mat4(*np.asarray(tree.matrices[node], np.float32).T.ravel())
        else:
            translation, rotation, scale = (glm.vec3(*rest[node][0]), glm.quat(rest[node][1][3], *rest[node][1][:3]),
                                            glm.vec3(*rest[node][2]))
            for channel in channels:
                if channel.node != node:
                    continue
                k = min(max(int(np.searchsorted(channel.times, t, side="right")) - 1, 0), len(channel.times) - 1)
                s = 0.0 if k == len(channel.times) - 1 else \
                    min(max((t - channel.times[k]) / (channel.times[k + 1] - channel.times[k]), 0.0), 1.0)
                if channel.path == "rotation":
                    a, b = (glm.quat(v[3], *v[:3]) for v in channel.values[k:k + 2]) if s else \
                        (glm.quat(channel.values[k][3], *channel.values[k][:3]),) * 2
                    rotation = glm.slerp(a, b, s)
                elif channel.interpolation == "STEP":
                    translation = glm.vec3(*channel.values[k])
                else:  # the cubic spline's Hermite terms
                    v = channel.values
                    if s == 0.0:
                        scale = glm.vec3(*v[k, 1])
                    else:
                        span = channel.times[k + 1] - channel.times[k]
                        s2, s3 = s * s, s ** 3
                        scale = glm.vec3(*((2 * s3 - 3 * s2 + 1) * v[k, 1] + (s3 - 2 * s2 + s) * span * v[k, 2]
                                           + (-2 * s3 + 3 * s2) * v[k + 1, 1] + (s3 - s2) * span * v[k + 1, 0]))
            local = glm.translate(translation) * glm.mat4_cast(rotation) * glm.scale(scale)
        parent = parents[node]
        return local if parent is None else by_hand(parent, t) * local

    for t in (0.0, 0.3, 0.5, 0.9, 1.7, 3.0):
        placed = pose_all(tree, clip, t)
        for node in range(len(parents)):
            expected = np.array(by_hand(node, t), np.float64)
            np.testing.assert_allclose(placed[node], expected, atol=2e-4, err_msg=f"node {node} at {t}")


def test_a_node_a_clip_shrinks_to_nothing_or_grows_from_nothing_is_hidden_then_drawn(scene, tmp_path):
    """Clip "Vanish" steps the door's scale to 0 at 1 s: hidden there, drawn before (no error
    for the flat transform); a second box, its node at scale 0 at rest, is kept (hidden) because
    clip "Appear" grows it, drawn at its grown size as a box placed there by hand; a node at
    scale 0 that no clip grows is left out, as before."""
    from components import DirectionalLight
    from systems.model_system import ModelSystem

    path = door(tmp_path / "door.glb")
    keys = [np.array([0.0, 1.0], np.float32), np.array([[1, 1, 1], [0, 0, 0]], np.float32),
            np.array([[0, 0, 0], [1, 1, 1]], np.float32)]

    def change(doc: dict) -> None:
        first = add_accessors(doc, keys)
        doc["nodes"] += [{"name": "lid", "mesh": 0, "translation": [-1.5, 0.5, 0.0], "scale": [0.0, 0.0, 0.0]},
                         {"name": "ghost", "mesh": 0, "translation": [0.0, 2.0, 0.0], "scale": [0.0, 1.0, 1.0]}]
        doc["scenes"][0]["nodes"] += [2, 3]
        doc["animations"] += [
            {"name": "Vanish", "samplers": [{"input": first, "output": first + 1, "interpolation": "STEP"}],
             "channels": [{"sampler": 0, "target": {"node": 1, "path": "scale"}}]},
            {"name": "Appear", "samplers": [{"input": first, "output": first + 2}],
             "channels": [{"sampler": 0, "target": {"node": 2, "path": "scale"}}]}]

    edit_glb(path, change)
    loaded = load_model_file(path)
    assert sorted((p.node, p.hidden) for p in loaded.parts) == [(1, False), (2, True)]   # the ghost left out
    world, _ = played(path, "Vanish", [0.5])
    record = world.resources[SpawnedModels][next(iter(world.resources[SpawnedModels]))]
    door_part, lid = (record.parts[[p.node for p in record.loaded.parts].index(node)] for node in (1, 2))
    assert world.get(door_part, MeshRef).visible and not world.get(lid, MeshRef).visible
    ((root, animation),) = list(world.query_one(Animation))
    animation.time = 1.5
    stage = ModelSystem(world)
    stage.process(0.0)
    assert not world.get(door_part, MeshRef).visible
    animation.time = 0.25
    stage.process(0.0)
    assert world.get(door_part, MeshRef).visible

    def lit(build):
        def made(world):
            look_from(world, (-0.5, 2.0, 4.0), (-1.0, 0.5, 0.0), fov=50.0)
            world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.5), intensity=2.0))
            build(world)
        return made

    def appearing(world):
        world.add_component(world.spawn(Transform(), Model(file=str(path))),
                            Animation(clip="Appear", time=0.6, playing=False))

    def by_hand(world):
        world.spawn(Transform(position=(1.5, 0.0, 0.0)), MeshRef(load_model_file(path).parts[0].mesh),
                    Material(color=(0.7, 0.4, 0.2, 1.0)))  # the door at rest (the hinge turns it nowhere)
        world.spawn(Transform(position=(-1.5, 0.5, 0.0), scale=(0.6, 0.6, 0.6)),
                    MeshRef(load_model_file(path).parts[0].mesh), Material(color=(0.7, 0.4, 0.2, 1.0)))

    frames = []
    for build in (appearing, by_hand):
        runner = scene(lit(build), (96, 72))
        runner.frame()
        frames.append(runner.frame().astype(int))
    assert np.abs(frames[0] - frames[1]).max() <= 2


def test_a_crossfade_mixes_the_two_clips_poses_and_ends_in_the_new_one(tmp_path):
    """``crossfade`` from "Open" (at 1 s: the hinge a quarter's half) into "Slide" over 1 s:
    half way, each node's own transform is the two clips' mixed half and half (the hinge's
    turn half of its, along the arc; the door's place half way between its rest and the
    slide's cubic spline at 0.5 s), multiplied down as any pose; once the fade has lasted
    its second, the pose is the slide's alone and the fade is over."""
    from engine.assets.models import crossfade
    from systems.model_system import ModelSystem

    path = door(tmp_path / "door.glb")
    world = World("fading")
    root = spawn_model(world, path)
    animation = Animation(clip="Open", time=1.0, playing=False, loop=False)   # (held at their ends)
    world.add_component(root, animation)
    stage = ModelSystem(world)
    stage.process(0.0)
    animation.playing = True
    crossfade(animation, "Slide", 1.0)
    assert (animation.fade_from, animation.fade_from_time) == ("Open", 1.0)
    assert (animation.clip, animation.time) == ("Slide", 0.0)
    stage.process(0.5)
    s = 0.5   # the slide at 0.5 s (its Hermite spline, as test_a_clips_channels_place_the_parts_at_each_time)
    slid = (2 * s ** 3 - 3 * s ** 2 + 1) * glm.vec3(0.5, 0, 0) + (s ** 3 - 2 * s ** 2 + s) * glm.vec3(1, 0, 0) \
        + (-2 * s ** 3 + 3 * s ** 2) * glm.vec3(0.5, 1, 0) + (s ** 3 - s ** 2) * glm.vec3(1, 0, 0)
    open_turn = glm.slerp(glm.quat(), QUARTER, (1.0 + 0.5) / 2.0)   # "Open" moved on to 1.5 s
    hinge = glm.translate(glm.vec3(1, 0, 0)) * glm.mat4_cast(glm.slerp(open_turn, glm.quat(), 0.5))
    mixed = hinge * glm.translate(glm.mix(glm.vec3(0.5, 0, 0), slid, 0.5))
    assert close(door_matrix(world), mixed)
    stage.process(0.5)   # the fade's second is up: the slide alone (at 1 s: its end, (0.5, 1, 0))
    assert animation.fade_from == ""
    assert close(door_matrix(world), glm.translate(glm.vec3(1, 0, 0)) * glm.translate(glm.vec3(0.5, 1, 0)))


def spun(path: Path, clips: dict[str, tuple[str, list[float], np.ndarray]]) -> Path:
    """The door with more clips turning its hinge: name -> (interpolation, key times, the
    rotation keys (x, y, z, w) a key, or (in-tangent, value, out-tangent) a key for a cubic
    spline)."""
    door(path)

    def change(doc: dict) -> None:
        for name, (interpolation, times, values) in clips.items():
            first = add_accessors(doc, [np.array(times, np.float32), np.asarray(values, np.float32).reshape(-1, 4)])
            doc["animations"].append({"name": name, "samplers": [
                {"input": first, "output": first + 1, "interpolation": interpolation}],
                "channels": [{"sampler": 0, "target": {"node": 0, "path": "rotation"}}]})
    return edit_glb(path, change)


def hinged(rotation) -> glm.mat4:
    """The door's matrix with its hinge turned by ``rotation`` (x, y, z, w; any length)."""
    x, y, z, w = np.asarray(rotation, np.float64) / np.linalg.norm(rotation)
    return glm.translate(glm.vec3(1, 0, 0)) * glm.mat4_cast(glm.quat(w, x, y, z)) * glm.translate(glm.vec3(0.5, 0, 0))


def test_rotation_keys_turn_along_the_shorter_arc_step_and_follow_a_normalised_cubic_spline(tmp_path):
    """Rotations as glTF says, worked out here with numpy: linear keys whose quaternions point
    apart (the second a quarter turn written as its negative, dot < 0) turn the short way (half
    way: an eighth turn, not three eighths the other way round); step keys hold each key to the
    next; cubic-spline keys over spans of 0.5 and 1.5 s are the Hermite sum with the tangents
    scaled by the span, normalised."""
    rng = np.random.default_rng(3)
    negated = -np.array([QUARTER.x, QUARTER.y, QUARTER.z, QUARTER.w])
    steps = np.array([[0, 0, 0, 1], [QUARTER.x, QUARTER.y, QUARTER.z, QUARTER.w], [0, 0, 0.6, 0.8]])
    values = rng.normal(size=(3, 3, 4)) * 0.3
    values[:, 1] = [[0, 0, 0, 1], [0.3, 0.2, 0.1, 0.9], [-0.5, 0.4, 0.2, 0.7]]   # the keys' values
    values[:, 1] /= np.linalg.norm(values[:, 1], axis=1, keepdims=True)
    path = spun(tmp_path / "spun.glb", {"Short": ("LINEAR", [0.0, 2.0], np.array([[0, 0, 0, 1], negated])),
                                         "Steps": ("STEP", [0.0, 1.0, 2.0], steps),
                                         "Spline": ("CUBICSPLINE", [0.0, 0.5, 2.0], values)})
    _, (half,) = played(path, "Short", [1.0], playing=False, time=1.0)
    eighth = glm.angleAxis(math.pi / 4, glm.vec3(0, 1, 0))
    assert close(half, hinged([eighth.x, eighth.y, eighth.z, eighth.w]))
    for t, key in ((0.0, 0), (0.99, 0), (1.0, 1), (1.7, 1), (2.0, 2)):
        _, (m,) = played(path, "Steps", [0.0], playing=False, time=t, loop=False)
        assert close(m, hinged(steps[key])), t
    times = [0.0, 0.5, 2.0]
    for t in (0.2, 0.5, 0.9, 1.6):
        k = 0 if t < 0.5 else 1
        span = times[k + 1] - times[k]
        s = (t - times[k]) / span
        q = (2 * s ** 3 - 3 * s ** 2 + 1) * values[k, 1] + (s ** 3 - 2 * s ** 2 + s) * span * values[k, 2] \
            + (-2 * s ** 3 + 3 * s ** 2) * values[k + 1, 1] + (s ** 3 - s ** 2) * span * values[k + 1, 0]
        _, (m,) = played(path, "Spline", [0.0], playing=False, time=t)
        assert close(m, hinged(q)), t


def test_speed_scales_the_clips_time_and_a_looping_clip_played_backwards_wraps_to_its_end(tmp_path):
    """``speed`` 2: a frame of 0.25 s moves "Open" on 0.5 s; 0.5: 0.125 s; -1 on a looping
    clip from 0.25 s by 0.5 s: 1.75 s (wrapped from below its start to the end of its 2 s),
    posed there (the hinge's turn slerped by hand)."""
    path = door(tmp_path / "door.glb")
    hinge, offset = glm.translate(glm.vec3(1, 0, 0)), glm.translate(glm.vec3(0.5, 0, 0))
    for speed, start, expected in ((2.0, 0.0, 0.5), (0.5, 0.0, 0.125), (-1.0, 0.5, 1.75)):
        steps = [0.25] if speed > 0 else [0.25, 0.5]
        world, placed = played(path, "Open", steps, speed=speed, time=start)
        ((_, animation),) = list(world.query_one(Animation))
        assert animation.time == pytest.approx(expected), speed
        assert close(placed[-1], hinge * glm.mat4_cast(glm.slerp(glm.quat(), QUARTER, expected / 2.0)) * offset)


@pytest.mark.parametrize("where", ["per_mirror", "batched", "direct"])
def test_a_playing_clips_skinned_pose_is_drawn_in_a_mirror_as_it_is_that_frame(scene, tmp_path, where):
    """The skinned arm of tests/test_skinning.py playing "Bend" (its elbow turned a quarter over
    1 s) at 0.25 s a frame, behind the camera and seen only in a mirror ahead (either
    reflection path; or in front of it, seen directly): the third frame (0.75 s in) shows the
    arm as the bar bent by hand at that frame's angle, 3/4 of a quarter, and not at the frame
    before's (1/2 of it): the mirror's view is not a frame behind the pose."""
    from components import Mirror
    from engine.assets.mesh import quad
    from tests.test_skinning import RED, arm_glb, bent_by_hand, same_picture

    path = arm_glb(tmp_path / "arm.glb")
    behind = glm.vec3(0.0, 0.0, 2.5) if where != "direct" else glm.vec3(-0.3, 0.0, -2.5)
    turned = glm.angleAxis(math.pi, glm.vec3(0.0, 1.0, 0.0)) if where != "direct" else glm.quat()

    def drawn(place) -> np.ndarray:
        def build(world):
            look_from(world, (0.0, 1.2, 1.5), (0.0, 1.2, 0.0), fov=35.0)
            world.spawn(DirectionalLight(direction=(0.3, -0.6, 1.0 if where != "direct" else -1.0), intensity=2.0))
            if where != "direct":
                world.spawn(Transform(position=(0.0, 1.2, -0.5)), MeshRef(quad(5.0, 3.0)), Mirror())
            place(world)
        runner = scene(build, (96, 72))
        if where != "direct":
            runner.engine.reflection_system.path = where
        for _ in range(2):
            runner.frame(0.25)
        return runner.frame(0.25).astype(int)

    def playing(world):
        root = spawn_model(world, path, position=behind, rotation=turned)
        world.add_component(root, Animation(clip="Bend"))

    def by_hand(share):
        return lambda world: world.spawn(Transform(position=behind, rotation=turned),
                                         MeshRef(bent_by_hand(share * math.pi / 2)), Material(color=RED))

    posed, now, before = drawn(playing), drawn(by_hand(0.75)), drawn(by_hand(0.5))
    assert same_picture(posed, now)
    assert not same_picture(posed, before)
    assert (posed[..., 0] > posed[..., 2] + 40).sum() > 60   # (the arm is there to see: red)
