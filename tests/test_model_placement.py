"""A model file placed whole (``Model``): in a level file, by the editor or by code.

A level file's ``[entity.Model]`` draws the same frame as ``spawn_model`` placing the file
there (its materials, images and lights included: a second path); a saved level holds the
root's Model alone (the parts are made again as it loads) and loads back to the same frame;
the models stage makes the parts of a Model added by code, makes them again when the Model
changes and deletes them (and their GPU resources) with the root; mistakes are refused
naming the file, line, entity and field."""
from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, DirectionalLight, FromModel, Material, MeshRef, Model, PointLight, Transform
from engine.assets.level_file import LevelError, load_level, save_level
from engine.assets.mesh import box
from engine.assets.models import SpawnedModels, spawn_model
from engine.core.errors import AssetError
from engine.core.world import World
from tests.support import look_from
from tests.test_materials_from_files import write_glb
from tests.test_model_lights import SPOT, lit_file

SIZE = (96, 72)
TURN = glm.angleAxis(math.radians(30.0), glm.vec3(0.0, 1.0, 0.0))


def textured_box(path: Path) -> Path:
    """A 1 m box whose colour is an image of four quarters (red, green, blue, yellow) held
    inside the GLB (no file of its own)."""
    quarters = np.array([[[255, 20, 20, 255], [20, 255, 20, 255]], [[20, 20, 255, 255], [255, 255, 20, 255]]], np.uint8)
    image = np.repeat(np.repeat(quarters, 8, axis=0), 8, axis=1)
    material = {"name": "paint", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0.0,
                                                          "roughnessFactor": 0.8}}
    return write_glb(path, box((1.0, 1.0, 1.0)), material, [image])


def level_text(models: list[tuple[str, str, str]]) -> str:
    """A level with a camera looking at the origin from above and the given (name, file,
    more Model fields) models, the first at x = 1 turned 30 degrees."""
    text = textwrap.dedent("""\
        [level]
        name = "placed"

        [[entity]]
        name = "eye"
        [entity.Transform]
        position = [1.0, 5.0, 3.0]
        rotation = { look = [0.0, -5.0, -3.0] }
        [entity.Camera]
        fov_y = 50.0

        [[entity]]
        name = "sun"
        [entity.DirectionalLight]
        direction = [-0.3, -1.0, -0.5]
        intensity = 0.4
        """)
    for index, (name, file, more) in enumerate(models):
        position = "[1.0, 0.0, 0.0]" if index == 0 else f"[{-0.8 * index}, 0.5, 0.6]"
        rotation = "\nrotation = { yaw = 30, pitch = 0 }" if index == 0 else ""
        text += (f'\n[[entity]]\nname = "{name}"\n[entity.Transform]\nposition = {position}{rotation}\n'
                 f'[entity.Model]\nfile = "{file}"\n{more}')
    return text


def write(folder: Path, text: str, name: str = "level.toml") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(text, encoding="utf-8")
    return path


def frame_of(scene, build) -> np.ndarray:
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return runner.frame().astype(int)


def models_folder(tmp_path: Path) -> Path:
    folder = tmp_path / "level" / "models"
    folder.mkdir(parents=True)
    lit_file(folder / "lamp.glb", [SPOT])
    textured_box(folder / "crate.glb")
    return folder


def test_a_level_files_model_draws_as_spawn_model_places_it(scene, tmp_path):
    """The floor lit by the file's spot and the box in its own image's colours: the level's
    frame equals the one spawn_model's placing draws, and the spot's light is in it (the
    frame with the light scaled to nothing is darker under the spot)."""
    folder = models_folder(tmp_path)
    level = load_level(write(folder.parent, level_text([("lamp", "models/lamp.glb", ""),
                                                        ("crate", "models/crate.glb", "")])))

    def by_code(light_scale: float):
        def build(world):
            look_from(world, (1.0, 5.0, 3.0), (1.0, 0.0, 0.0), fov=50.0)
            spawn_model(world, folder / "lamp.glb", position=(1.0, 0.0, 0.0), rotation=TURN, light_scale=light_scale)
            spawn_model(world, folder / "crate.glb", position=(-0.8, 0.5, 0.6))
            world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.5), intensity=0.4))
        return build

    names: dict[str, int] = {}
    from_level = frame_of(scene, lambda world: names.update(level.spawn(world)))
    from_code = frame_of(scene, by_code(1.0))
    dark = frame_of(scene, by_code(0.0))
    assert np.abs(from_level - from_code).max() <= 1
    lit = (from_code - dark)[..., 1]
    assert lit.max() > 60 and (lit > 10).sum() > 100          # the spot's pool of light on the floor
    r, g, b = from_code[..., 0], from_code[..., 1], from_code[..., 2]
    red, green = (r > g + 40) & (r > b + 40), (g > r + 40) & (g > b + 40)
    assert red.sum() > 10 and green.sum() > 10                # the crate's image: its red and green quarters


def test_a_levels_model_makes_its_parts_under_its_root(tmp_path):
    folder = models_folder(tmp_path)
    level = load_level(write(folder.parent, level_text([("lamp", "models/lamp.glb", "light_scale = 0.5\n")])))
    world = World("parts")
    names = level.spawn(world)
    root = names["lamp"]
    parts = [entity for entity, part in world.query_one(FromModel) if part.model == root]
    assert len(parts) == 2 and all(world.get(entity, Transform).parent == root for entity in parts)
    ((_, lamp),) = list(world.query_one(PointLight))
    assert lamp.intensity == pytest.approx(0.5 * SPOT["intensity"])
    assert world.get(root, Model).file == str((folder / "lamp.glb").resolve())
    assert set(world.resources[SpawnedModels][root].parts) == set(parts)
    assert list(names) == ["eye", "sun", "lamp"]                     # the file's entities, not the parts


def test_a_saved_level_holds_the_model_not_its_parts_and_loads_to_the_same_frame(scene, tmp_path):
    """Saved into another folder, the Model's file is written relative to it; the parts (an
    image held inside the GLB among them, which a level file could not name) are not
    written; loading the saved file draws the same frame."""
    folder = models_folder(tmp_path)
    level = load_level(write(folder.parent, level_text([("lamp", "models/lamp.glb", "max_probes = 2\n"),
                                                        ("crate", "models/crate.glb", "")])))
    world = World("saving")
    names = level.spawn(world)
    saved = save_level(world, tmp_path / "elsewhere" / "saved.toml", names, name="placed") \
        if (tmp_path / "elsewhere").mkdir() is None else None
    text = saved.read_text(encoding="utf-8")
    assert text.count("[[entity]]") == 4 and text.count("[entity.Model]") == 2
    assert 'file = "../level/models/lamp.glb"' in text and "max_probes = 2" in text
    assert "MeshRef" not in text and "PointLight" not in text
    again = load_level(saved, asset_roots=[folder.parent])
    first = frame_of(scene, level.spawn)
    second = frame_of(scene, again.spawn)
    assert np.array_equal(first, second)
    # Kept text: an edit of the model's place is its line; the parts stay out.
    world.get(names["crate"], Transform).position = glm.vec3(-3.0, 0.0, -1.0)
    kept = save_level(world, folder.parent / "level.toml", names, keep=folder.parent / "level.toml")
    kept_text = kept.read_text(encoding="utf-8")
    assert "position = [-3.0, 0.0, -1.0]" in kept_text and kept_text.count("[[entity]]") == 4


def test_spawn_models_root_saves_as_its_model(tmp_path):
    """A model spawned by code saves as one entity with its Model (before, its parts were
    written, and an image inside the GLB was refused)."""
    folder = models_folder(tmp_path)
    world = World("by code")
    root = spawn_model(world, folder / "crate.glb", position=(0.0, 1.0, 0.0))
    assert world.get(root, Model).file == str(folder / "crate.glb")
    saved = save_level(world, folder.parent / "code.toml", {"crate": root})
    text = saved.read_text(encoding="utf-8")
    assert text.count("[[entity]]") == 1 and 'file = "models/crate.glb"' in text
    again = World("again")
    names = load_level(saved).spawn(again)
    assert len(list(again.query_one(FromModel))) == 1
    assert list(again.get(names["crate"], Transform).position) == [0.0, 1.0, 0.0]


def test_the_models_stage_makes_remakes_and_deletes_a_models_parts(scene, tmp_path):
    """A Model added by code gets its parts in the same frame; a changed light_scale or file
    makes them again; the root deleted takes them and their GPU resources with it."""
    folder = models_folder(tmp_path)
    made: dict[str, int] = {}

    def build(world):
        look_from(world, (1.0, 5.0, 3.0), (1.0, 0.0, 0.0), fov=50.0)
        made["root"] = world.spawn(Transform(position=(1.0, 0.0, 0.0)), Model(file=str(folder / "lamp.glb")))

    runner = scene(build, SIZE)
    empty = runner.frame().astype(int)
    world, renderer = runner.world, runner.engine.renderer
    root = made["root"]

    def parts():
        return sorted(entity for entity, part in world.query_one(FromModel) if part.model == root)

    first = parts()
    assert len(first) == 2 and len(list(world.query_one(PointLight))) == 1
    assert empty[..., 1].max() > 60                             # drawn in the frame the Model came: the lit floor
    world.get(root, Model).light_scale = 0.25
    runner.frame()
    second = parts()
    assert len(second) == 2 and not set(second) & set(first)   # made again
    assert [lamp.intensity for _, lamp in world.query_one(PointLight)] == [pytest.approx(0.25 * SPOT["intensity"])]
    world.get(root, Model).file = str(folder / "crate.glb")
    runner.frame()
    third = parts()
    assert len(third) == 1 and not list(world.query_one(PointLight))
    (mesh_ref,) = [world.get(e, MeshRef) for e in third]
    assert mesh_ref.mesh.indices.size == 36
    world.delete_entity(root)
    runner.frame()
    assert not list(world.query_one(FromModel)) and not list(world.query_one(Material))
    counts = renderer.resource_counts()
    assert counts["meshes"] == 0 and counts["textures"] == 0 and counts["batches"] == 0


def test_a_model_whose_file_is_cleared_has_no_parts_and_a_bad_one_is_named(scene, tmp_path):
    folder = models_folder(tmp_path)
    made: dict[str, int] = {}

    def build(world):
        look_from(world, (1.0, 5.0, 3.0), (1.0, 0.0, 0.0))
        made["root"] = world.spawn(Transform(), Model(file=str(folder / "crate.glb")))

    runner = scene(build, SIZE)
    runner.frame()
    world = runner.world
    assert len(list(world.query_one(FromModel))) == 1
    world.get(made["root"], Model).file = ""
    runner.frame()
    assert not list(world.query_one(FromModel))
    world.get(made["root"], Model).file = str(folder / "missing.glb")
    with pytest.raises(AssetError, match=rf"entity {made['root']}'s Model: .*missing\.glb"):
        runner.frame()


@pytest.mark.parametrize("model, message, field", [
    ('file = "models/none.glb"\n', r"none\.glb", "Model.file"),
    ('file = "../../outside.glb"\n', r"outside the level's folder", "Model.file"),
    ('file = "models/lamp.glb"\nlight_scale = -1.0\n', r"light_scale .*must be >= 0", "Model.light_scale"),
    ('file = "models/lamp.glb"\nmax_probes = 100\n', r"max_probes .*must be an int in \[0, 64\]", "Model.max_probes"),
    ('file = "models/lamp.glb"\ncolour = 1\n', r"Model has no field 'colour'", "Model.colour"),
    ('file = ""\nlight_scale = "2"\n', r"light_scale must be a number", "Model.light_scale"),
])
def test_a_bad_model_in_a_level_is_refused_naming_its_line_and_field(tmp_path, model, message, field):
    folder = models_folder(tmp_path)
    text = level_text([]) + f'\n[[entity]]\nname = "thing"\n[entity.Transform]\n[entity.Model]\n{model}'
    with pytest.raises(LevelError, match=message) as caught:
        load_level(write(folder.parent, text))
    assert (caught.value.entity, caught.value.field) == ("thing", field) and caught.value.line is not None


def test_a_model_without_a_transform_or_a_bad_value_is_refused_when_given(tmp_path):
    folder = models_folder(tmp_path)
    with pytest.raises(LevelError, match="a Model needs a Transform"):
        load_level(write(folder.parent, level_text([]) + '\n[[entity]]\nname = "x"\n[entity.Model]\n'
                                                         'file = "models/lamp.glb"\n'))
    for field, value in (("file", 3), ("light_scale", float("nan")), ("max_probes", True), ("file", "a\0b")):
        with pytest.raises(ComponentValueError, match=f"Model.{field}"):
            Model(**{field: value})
    with pytest.raises(ComponentValueError, match="FromModel.model"):
        FromModel(model=0)
    with pytest.raises(LevelError, match="FromModel is made by the engine"):
        load_level(write(folder.parent, level_text([]) + '\n[[entity]]\nname = "x"\n[entity.FromModel]\nmodel = 1\n'))


def test_a_level_cannot_name_a_models_part(tmp_path):
    """An entity parented to a model's part is refused when saved, naming the part's model:
    the part is not in the file to be named."""
    folder = models_folder(tmp_path)
    world = World("named part")
    root = spawn_model(world, folder / "crate.glb")
    ((part, _),) = list(world.query_one(FromModel))
    child = world.spawn(Transform(parent=part))
    with pytest.raises(LevelError, match=r"a part of the model on 'crate'.*name the model's entity instead") as caught:
        save_level(world, tmp_path / "x.toml", {"crate": root, "child": child})
    assert (caught.value.entity, caught.value.field) == ("child", "Transform.parent")


def test_the_editor_picks_a_model_places_it_and_refuses_edits_of_its_parts(scene, tmp_path):
    """A click on a model's part selects the model (its root); an edit of a part is refused
    saying why; the editor places a model file (loaded and checked as the field is given), a
    save writes its entity alone, deleting the model takes its parts, and undo brings it back."""
    from shell.editor import EditError, Editor

    folder = models_folder(tmp_path)
    path = write(folder.parent, level_text([("crate", "models/crate.glb", "")]))
    level = load_level(path)
    names: dict[str, int] = {}
    runner = scene(lambda world: names.update(level.spawn(world)), SIZE)
    runner.frame()
    world = runner.world
    editor = Editor(world, names=names, level_path=path)
    root = names["crate"]
    ((part, _),) = list(world.query_one(FromModel))
    ids = runner.ids()
    rows, columns = np.nonzero(ids == part)
    assert len(rows) > 20
    assert editor.pick(ids, None, int(columns[0]), int(rows[0])) == root == editor.selected
    with pytest.raises(EditError, match=r"is a part of the model crate, made from its file each time the level loads"):
        editor.set_field(part, "Material", "color", (0.0, 1.0, 0.0, 1.0))
    for refused in (lambda: editor.delete(part), lambda: editor.duplicate(part),
                    lambda: editor.remove_component(part, "Material"), lambda: editor.add_component(part, "Emissive")):
        with pytest.raises(EditError, match="is a part of the model crate"):
            refused()

    lamp = editor.create(Transform(position=(1.0, 0.0, 0.0)), Model(), name="lamp")
    with pytest.raises(EditError, match=r"Model.file: .*nothing\.glb"):
        editor.set_model_file(lamp, "models/nothing.glb")
    editor.set_model_file(lamp, "models/lamp.glb")
    assert editor.model_file_text(lamp) == "models/lamp.glb"
    runner.frame()
    assert len(list(world.query_one(PointLight))) == 1
    saved = editor.save().read_text(encoding="utf-8")
    assert saved.count("[[entity]]") == 4 and 'file = "models/lamp.glb"' in saved and "PointLight" not in saved

    editor.delete(root)                                    # its part is no child that blocks it
    runner.frame()
    assert not world.exists(part) and len(list(world.query_one(FromModel))) == 2   # the lamp's two
    assert editor.undo()                                   # the crate again, under a new id
    runner.frame()
    assert len(list(world.query_one(FromModel))) == 3
