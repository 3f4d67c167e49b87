"""Material variants (glTF's ``KHR_materials_variants``): one model in several looks.  A
model placed in a variant wears that variant's materials (its parts' colours are the
variant's, and its frame is the frame of a file whose default material is that variant's:
a second path); a Model's variant changed at run time makes its parts again; a level file
places a variant; a variant the file does not have is refused listing those it has."""
from __future__ import annotations

import base64
import json
import struct
from pathlib import Path

import numpy as np
import pytest

from components import DirectionalLight, FromModel, Material, Model, Transform
from engine.assets.level_file import LevelError, load_level
from engine.assets.mesh import box, load_model_file
from engine.assets.models import spawn_model
from engine.core.errors import AssetError
from engine.core.world import World
from tests.support import look_from
from tests.test_materials_from_files import write_glb

RED, BLUE, GREEN = [0.8, 0.1, 0.1, 1.0], [0.1, 0.2, 0.8, 1.0], [0.1, 0.7, 0.2, 1.0]


def paint(color: list[float], name: str) -> dict:
    return {"name": name, "pbrMetallicRoughness": {"baseColorFactor": color, "metallicFactor": 0.0}}


def edit_glb(path: Path, change) -> Path:
    """Rewrite a GLB's JSON chunk with ``change(doc)`` (its binary chunk kept)."""
    data = path.read_bytes()
    length = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + length])
    change(doc)
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    rest = data[20 + length:]
    path.write_bytes(b"glTF" + struct.pack("<II", 2, 12 + 8 + len(text) + len(rest)) + struct.pack("<I", len(text))
                     + b"JSON" + text + rest)
    return path


# componentType and type of the arrays add_accessors stores
_COMPONENTS = {np.dtype(np.uint8): 5121, np.dtype(np.uint16): 5123, np.dtype(np.float32): 5126}
_TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}


def add_accessors(doc: dict, arrays: list[np.ndarray], normalized: frozenset[int] = frozenset()) -> int:
    """Append ``arrays`` to a glTF document (as ``edit_glb`` hands it): one base64 buffer, a
    view and an accessor each (componentType from the dtype, type from the width; a
    one-dimensional array gets its min and max, as an animation's input must); those whose
    index is in ``normalized`` marked normalised.  Returns the first new accessor's index."""
    blob = bytearray()
    doc["buffers"].append({})
    first = len(doc["accessors"])
    for index, array in enumerate(arrays):
        while len(blob) % 4:
            blob.append(0)
        doc["bufferViews"].append({"buffer": len(doc["buffers"]) - 1, "byteOffset": len(blob),
                                   "byteLength": array.nbytes})
        blob.extend(array.tobytes())
        doc["accessors"].append({"bufferView": len(doc["bufferViews"]) - 1, "componentType": _COMPONENTS[array.dtype],
                                 "count": len(array), "type": _TYPES[1 if array.ndim == 1 else array.shape[1]],
                                 **({"normalized": True} if index in normalized else {}),
                                 **({"min": [float(array.min())], "max": [float(array.max())]}
                                    if array.ndim == 1 else {})})
    doc["buffers"][-1] = {"byteLength": len(blob), "uri": "data:application/octet-stream;base64,"
                          + base64.b64encode(bytes(blob)).decode()}
    return first


def shoe(path: Path, default: list[float] = RED, mappings: list[dict] | None = None) -> Path:
    """A box whose default material is ``default``, with variants "midnight" (blue) and
    "forest" (green)."""
    write_glb(path, box((1.0, 1.0, 1.0)), paint(default, "canvas"), [])

    def change(doc: dict) -> None:
        doc["materials"] += [paint(BLUE, "navy"), paint(GREEN, "moss")]
        doc["extensions"] = {"KHR_materials_variants": {"variants": [{"name": "midnight"}, {"name": "forest"}]}}
        doc["extensionsUsed"] = ["KHR_materials_variants"]
        doc["meshes"][0]["primitives"][0]["extensions"] = {"KHR_materials_variants": {"mappings": mappings or [
            {"material": 1, "variants": [0]}, {"material": 2, "variants": [1]}]}}
    return edit_glb(path, change)


def frame(scene, build) -> np.ndarray:
    def lit(world):
        look_from(world, (1.5, 1.5, 3.0), (0.0, 0.0, 0.0), fov=45.0)
        world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.5), intensity=2.0))
        build(world)
    runner = scene(lit, (64, 48))
    runner.frame()
    return runner.frame().astype(int)


def test_a_model_placed_in_a_variant_wears_its_materials(scene, tmp_path):
    path = shoe(tmp_path / "shoe.glb")
    assert load_model_file(path).variants == ["midnight", "forest"]
    for variant, color in (("", RED), ("midnight", BLUE), ("forest", GREEN)):
        world = World(variant or "default")
        spawn_model(world, path, variant=variant)
        ((_, material),) = list(world.query_one(Material))
        assert list(material.color) == pytest.approx(color, abs=0.01)
    # The second path: a file whose default is blue draws what the midnight variant draws.
    plain_blue = write_glb(tmp_path / "blue.glb", box((1.0, 1.0, 1.0)), paint(BLUE, "navy"), [])
    midnight = frame(scene, lambda w: spawn_model(w, path, variant="midnight"))
    assert np.array_equal(midnight, frame(scene, lambda w: spawn_model(w, plain_blue)))
    assert not np.array_equal(midnight, frame(scene, lambda w: spawn_model(w, path)))


def test_changing_a_models_variant_makes_its_parts_again(scene, tmp_path):
    path = shoe(tmp_path / "shoe.glb")
    made = {}

    def build(world):
        look_from(world, (1.5, 1.5, 3.0), (0.0, 0.0, 0.0))
        made["root"] = world.spawn(Transform(), Model(file=str(path), variant="forest"))
    runner = scene(build, (64, 48))
    runner.frame()
    world = runner.world

    def colour():
        ((entity, _),) = list(world.query_one(FromModel))
        return list(world.get(entity, Material).color)
    assert colour() == pytest.approx(GREEN, abs=0.01)
    world.get(made["root"], Model).variant = "midnight"
    runner.frame()
    assert colour() == pytest.approx(BLUE, abs=0.01)
    world.get(made["root"], Model).variant = "sunset"
    with pytest.raises(AssetError, match=r"has no material variant 'sunset' \(its variants: 'midnight', 'forest'"):
        runner.frame()


def test_a_level_places_a_variant_and_a_missing_one_is_refused_by_its_line(tmp_path):
    shoe(tmp_path / "shoe.glb")
    level = """[level]\nname = "shop"\n\n[[entity]]\nname = "shoe"\n[entity.Transform]\n[entity.Model]
file = "shoe.glb"\nvariant = "VARIANT"\n"""
    (tmp_path / "shop.toml").write_text(level.replace("VARIANT", "forest"))
    world = World("shop")
    load_level(tmp_path / "shop.toml").spawn(world)
    ((_, material),) = list(world.query_one(Material))
    assert list(material.color) == pytest.approx(GREEN, abs=0.01)
    (tmp_path / "shop.toml").write_text(level.replace("VARIANT", "sunset"))
    with pytest.raises(LevelError, match=r"has no material variant 'sunset'") as caught:
        load_level(tmp_path / "shop.toml")
    assert (caught.value.entity, caught.value.field, caught.value.line) == ("shoe", "Model.variant", 9)


def test_the_editor_refuses_a_variant_the_file_does_not_have(scene, tmp_path):
    from shell.editor import EditError, Editor

    path = shoe(tmp_path / "shoe.glb")
    world = World("editing")
    root = spawn_model(world, path)
    editor = Editor(world)
    with pytest.raises(EditError, match=r"Model.variant: .*has no material variant 'sunset'"):
        editor.set_field(root, "Model", "variant", "sunset")
    editor.set_field(root, "Model", "variant", "midnight")
    assert world.get(root, Model).variant == "midnight"


@pytest.mark.parametrize("mappings, message", [
    ([{"material": 9, "variants": [0]}], r"names material 9, which the file does not have"),
    ([{"material": 1, "variants": [5]}], r"variants must be indices of the file's 2 variants"),
])
def test_a_malformed_mapping_is_refused(tmp_path, mappings, message):
    path = shoe(tmp_path / "bad.glb", mappings=mappings)
    with pytest.raises(AssetError, match=rf"bad\.glb.*{message}"):
        load_model_file(path, variant="midnight")
