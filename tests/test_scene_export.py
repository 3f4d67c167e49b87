"""scene.json says what things are: each entity's components with their field values, in
plain JSON with the encoding written into the file, enough to rebuild the scene."""
from __future__ import annotations

import importlib
import json

import numpy as np
from pyglm import glm

from components import FromDecal, ParticleEmitter, PortalClone, Slice, Transform
from engine.assets.values import json_value
from engine.resources import ViewBudget
from games.hall_of_mirrors import HallOfMirrors
from shell.capture import export_scene

SIZE = (160, 90)
SYSTEM_MADE = {"PortalClone", "Slice"}  # the slice system makes these each frame; not level data
_GLM = {"vec2": glm.vec2, "vec3": glm.vec3, "vec4": glm.vec4}


def decode(value, kind: str, meshes: dict, textures: dict):
    """A field value back from scene.json, by the kind ``component_types`` gives its field and
    the rules in ``value_kinds`` (a quaternion is [w, x, y, z])."""
    if value is None:
        return None
    if kind in _GLM:
        return _GLM[kind](*value)
    if kind == "quat":
        return glm.quat(*value)  # glm.quat(w, x, y, z)
    if kind == "mat4":
        return glm.mat4(*value)
    if kind == "mesh":
        return meshes[value["id"]]
    if kind == "texture":
        return textures[(value["name"], *value["size"])]
    if kind == "float" and isinstance(value, str):
        return float(value)
    if kind == "list":
        return tuple(value)
    assert kind in ("bool", "int", "float", "str"), f"no decoder for {kind}"
    return value


def same(a, b) -> bool:
    """Equal JSON values, numbers to 1e-6 (a component may renormalise what it is given)."""
    if isinstance(a, float | int) and isinstance(b, float | int) and not isinstance(a, bool):
        return abs(a - b) <= 1e-6
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    return a == b


def rebuild(info: dict, meshes: dict, textures: dict) -> dict[int, list]:
    """Every entity's components, made again from scene.json alone (classes by their path)."""
    rebuilt = {}
    for entity, components in info["components"].items():
        rebuilt[int(entity)] = []
        for type_name, fields in components.items():
            described = info["component_types"][type_name]
            module, _, qualname = described["class"].rpartition(".")
            cls = getattr(importlib.import_module(module), qualname)
            kwargs = {name: decode(v, described["fields"][name], meshes, textures) for name, v in fields.items()}
            rebuilt[int(entity)].append(cls(**kwargs))
    return rebuilt


def live_assets(world):
    from components import Material, MeshRef

    meshes = {m.mesh.id: m.mesh for _, (m,) in world.query(MeshRef)}
    textures = {}
    for _, (material,) in world.query(Material):
        for image in (material.texture, material.normal_map):
            if image is not None:
                height, width = image.pixels.shape[:2]
                textures[(image.name, width, height)] = image
    return meshes, textures


def test_scene_json_round_trips_every_component_value_of_the_sample_level(scene, tmp_path):
    game = HallOfMirrors()
    runner = scene(lambda world: game.build(world), SIZE)
    runner.frame()
    world = runner.world
    camera = runner.engine.active_camera()[0]
    export_scene(world, tmp_path / "scene.glb", camera, SIZE)
    text = (tmp_path / "scene.json").read_text()
    info = json.loads(text)  # plain JSON: no NaN/Infinity tokens, no repr strings
    assert "NaN" not in text and "Infinity" not in text

    assert set(info["components"]) == {str(e) for e in world.entities()}
    assert info["component_types"]["Transform"]["fields"]["rotation"] == "quat"
    assert "w first" in info["value_kinds"]["quat"]

    rebuilt = rebuild(info, *live_assets(world))
    checked = 0
    for entity in world.entities():
        originals = sorted(world.components_of(entity), key=lambda c: type(c).__name__)
        again = sorted(rebuilt[entity], key=lambda c: type(c).__name__)
        assert [type(c) for c in again] == [type(c) for c in originals]
        for original, copy in zip(originals, again, strict=True):
            for name, value in vars(original).items():
                if name.startswith("_"):
                    continue
                (stored, kind), (again_value, again_kind) = json_value(value), json_value(getattr(copy, name))
                assert kind == again_kind and same(again_value, stored), (entity, type(original).__name__, name)
                assert same(info["components"][str(entity)][type(original).__name__][name], stored)
                checked += 1
    assert checked > 300

    # The conventions hold against the live values, not only against themselves: a turned
    # portal's rotation read as w, x, y, z is its quaternion; a mirror's tint is its colour.
    turned = [e for e, (t,) in world.query(Transform) if abs(t.rotation.w) < 0.999]
    assert turned
    for entity in turned:
        stored = info["components"][str(entity)]["Transform"]["rotation"]
        assert glm.quat(*stored) == world.get(entity, Transform).rotation


def test_a_scene_rebuilt_from_scene_json_renders_the_same_frame(scene, tmp_path):
    game = HallOfMirrors()
    original = scene(lambda world: game.build(world), SIZE)
    original.frame()
    export_scene(original.world, tmp_path / "scene.glb", original.engine.active_camera()[0], SIZE)
    info = json.loads((tmp_path / "scene.json").read_text())
    rebuilt = rebuild(info, *live_assets(original.world))
    # A particle cloud is simulation state the file does not hold (each copy grows its own
    # from the emitter): the emitters are left out of both pictures compared.
    for entity, _ in original.world.query_one(ParticleEmitter):
        original.world.remove_component(entity, ParticleEmitter)
    expected = original.frame(0.0)  # the exported state, drawn again (no time passes)
    expected_ids = original.ids()

    assert info["view_budget"] == {"views": None, "probe_ms": None, "pixels": None, "min_pixels": 64,  # the level's
                                   "frame_ms": None, "min_render_scale": 0.5}

    def build(world):
        world.resources[ViewBudget] = ViewBudget(**info["view_budget"])
        for entity in range(1, max(rebuilt) + 1):  # same ids, so parents and partners still point right
            kept = [c for c in rebuilt.get(entity, []) if type(c).__name__ not in SYSTEM_MADE
                    and not isinstance(c, ParticleEmitter)]
            if any(type(c).__name__ == "FromDecal" for c in kept):  # a decal's cut: the copy's decals stage
                kept = []                                             # makes its own (an empty entity keeps the ids)
            assert world.spawn(*kept) == entity

    copy = scene(build, SIZE)
    copy.frame(0.0)
    frame = copy.frame(0.0)
    ids = copy.ids()
    clones = {e for e, _ in original.world.query(PortalClone)} | {e for e, _ in copy.world.query(PortalClone)}
    assert original.world.query(Slice) and clones  # the level has a thing part-way through a portal
    cuts = {e for e, _ in original.world.query(FromDecal)} | {e for e, _ in copy.world.query(FromDecal)}
    assert len(cuts) == 2  # the oil stain's, in each (under another id in the copy)
    clones |= cuts
    same = ~np.isin(expected_ids, list(clones)) & ~np.isin(ids, list(clones))
    assert same.mean() > 0.95
    np.testing.assert_array_equal(ids[same], expected_ids[same])
    difference = np.abs(frame.astype(int) - expected.astype(int))
    assert (difference > 2).mean() < 0.002, ((difference > 2).mean(), difference.max())


def test_an_export_path_that_cannot_be_written_is_one_clear_error_naming_it(scene, tmp_path):
    """``write_scene`` (``--export-scene``): a path under a file, a path that is a folder and an
    extension that is not glTF's are each one error naming the path and why (OutputPathError,
    a SpeculumError the runner prints as one line; ValueError for the extension), nothing
    half-written beside them; a good path writes both files."""
    import pytest

    from components import Material, MeshRef
    from engine.assets.mesh import box
    from engine.core.errors import SpeculumError
    from shell.capture import OutputPathError, write_scene
    from tests.support import look_from

    def stage(world):
        look_from(world, (0.0, 1.0, 4.0), (0.0, 0.0, 0.0))
        world.spawn(Transform(), MeshRef(box((1.0, 1.0, 1.0))), Material())

    runner = scene(stage, (32, 32))
    runner.frame()
    a_file = tmp_path / "taken"
    a_file.write_text("not a folder")
    a_folder = tmp_path / "folder.glb"
    a_folder.mkdir()
    for path, why in ((a_file / "scene.glb", "cannot be written"), (a_folder, "cannot be written")):
        with pytest.raises(OutputPathError) as error:
            write_scene(runner.engine, path, (32, 32))
        assert isinstance(error.value, SpeculumError) and "\n" not in str(error.value)
        assert repr(str(path)) in str(error.value) and why in str(error.value), str(error.value)
    with pytest.raises(ValueError, match=r"'.*scene\.obj' must end in \.glb or \.gltf"):
        write_scene(runner.engine, tmp_path / "scene.obj", (32, 32))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder.glb", "taken"]
    assert a_file.read_text() == "not a folder" and not list(a_folder.iterdir())
    written = write_scene(runner.engine, tmp_path / "good" / "scene.gltf", (32, 32))
    assert [p.name for p in written] == ["scene.gltf", "scene.json"] and all(p.stat().st_size for p in written)


def test_an_export_scene_folder_that_is_a_file_stops_the_runner_before_it_draws_with_one_line(tmp_path):
    """``--export-scene taken/scene.glb`` where ``taken`` is a file: the runner checks the folder
    up front (``prepare_out``) and stops with exit 2 and one ``speculum: error:`` line naming
    it, no traceback, no frame drawn."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    a_file = tmp_path / "taken"
    a_file.write_text("not a folder")
    root = Path(__file__).resolve().parent.parent
    result = subprocess.run([sys.executable, "-m", "games.hall_of_mirrors", "--headless", "--frames", "1", "--size",
                             "32x32", "--out", str(tmp_path / "frames"), "--export-scene", str(a_file / "scene.glb")],
                            cwd=root, env={**os.environ}, capture_output=True, text=True, timeout=300)
    assert result.returncode == 2, result.stderr
    (line,) = result.stderr.strip().splitlines()
    assert line.startswith("speculum: error: --export-scene folder") and repr(str(a_file)) in line, line
    assert "existing file" in line and not list((tmp_path / "frames").glob("frame_*"))
