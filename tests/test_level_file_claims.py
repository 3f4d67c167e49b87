"""What docs/level_files.md and the README's "Edit a level" promise a level file's user, checked
where no other test holds it: every field edited in the editor is saved as its own line and
taken back exactly by undo; a rotation turns the way the doc says; a generator's options, the
view budget, the game and the rules are written back as they were given; and a level file or
mesh file past its documented size is refused by its size.  The expectations are worked out
here (rotation matrices in numpy, the saved text parsed with tomllib), not read off the code
under test.  No GL context: nothing here draws."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import tomllib

from components import Material, MeshRef, Transform
from engine.assets.level_file import LevelError, load_level, save_level
from engine.assets.level_save import same_floats
from engine.core.budget import ViewBudget
from engine.core.world import World
from tests.test_level_files import every_kind_level, fields_by_name, vary_fields, write


def as_toml(value: object) -> object:
    """A plain field value as a level file holds it: vectors and tuples as lists, a quaternion
    ``[w, x, y, z]``."""
    from pyglm import glm

    if isinstance(value, glm.quat):
        return [float(value.w), float(value.x), float(value.y), float(value.z)]
    if isinstance(value, (glm.vec2, glm.vec3, glm.vec4)):
        return [float(v) for v in value]
    if isinstance(value, (tuple, list)):
        return [as_toml(v) for v in value]
    return value


def entities_in(text: str) -> dict[str, dict]:
    """A level file's ``[[entity]]`` tables by name, as tomllib reads the text."""
    return {table["name"]: table for table in tomllib.loads(text)["entity"]}


# --- the editor: every field, saved, undone and redone ----------------------------------------------------------

def test_every_field_edited_in_the_editor_is_its_line_in_the_save_and_undo_gives_back_the_file(tmp_path):
    """README "Edit a level": an edit goes through the component's checks, a save writes the
    edited components into the file's own text, undo and redo take an edit back and make it
    again.  For one entity of every component kind a level file holds, every field is set to
    a value unlike its default through ``Editor.set_field`` (the inspector's path): the saved
    text, read with tomllib, has each edited field with its value, and loads to the edited
    world; every edit undone gives the loaded world back field for field, and a save then
    writes the file's text unchanged; redone, the world is the edited one again (a direction
    normalised a second time may move in float32's last place)."""
    from shell.editor import Editor

    path = write(tmp_path, every_kind_level(tmp_path), "every_kind.toml")
    original_text = path.read_text()
    level = load_level(path)
    varied = vary_fields(level)
    world = World("every field edited")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (a Tonemap on no camera, ...: each kind is alone on its entity)
        names = level.spawn(world)
        original = fields_by_name(world, names)
        editor = Editor(world, None, names, path)
        edits = 0
        for kind, fields in varied.items():
            for field, value in fields.items():
                refused = editor.try_set_field(names[kind], kind, field, value)
                assert refused is None, (kind, field, refused)
                edits += 1
        assert edits > 250  # (every field of every kind, less the given ones)
        edited = fields_by_name(world, names)
        editor.save()
        saved = entities_in(path.read_text())
        for kind, fields in varied.items():
            for field, value in fields.items():
                assert field in saved[kind][kind], f"{kind}.{field} edited but not in the saved file"
                assert same_floats(saved[kind][kind][field], as_toml(value), 1e-6), (kind, field, value)
        again = World("every field loaded")
        back = fields_by_name(again, load_level(path).spawn(again))
        assert same_floats(back, edited, 1e-6)

        while editor.undo():
            pass
        assert fields_by_name(world, names) == original
        editor.save()
        assert path.read_text() == original_text
        while editor.redo():
            pass
        assert same_floats(fields_by_name(world, names), edited, 1e-6)
    world.close()
    again.close()


# --- which way a rotation turns -------------------------------------------------------------------------------

def turned(rotation, vector) -> np.ndarray:
    """``vector`` turned by a unit quaternion (w, x, y, z): v + 2w (q x v) + 2 q x (q x v)."""
    w, q = float(rotation.w), np.array([rotation.x, rotation.y, rotation.z], np.float64)
    v = np.array(vector, np.float64)
    t = 2.0 * np.cross(q, v)
    return v + w * t + np.cross(q, t)


def about(axis: str, degrees: float) -> np.ndarray:
    """The right-handed rotation matrix about the x or y axis."""
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]]) if axis == "x" else np.array([[c, 0, s], [0, 1, 0],
                                                                                      [-s, 0, c]])


VIEW, FACE = (0.0, 0.0, -1.0), (0.0, 0.0, 1.0)  # a camera with no rotation looks down -Z; a quad faces +Z
# (rotation as the file writes it, where the doc says the camera's view goes, where a quad's face goes)
DOCUMENTED_TURNS = [
    ("{ yaw = 90, pitch = 0 }", (-1.0, 0.0, 0.0), (1.0, 0.0, 0.0)),
    ("{ yaw = -90, pitch = 0 }", (1.0, 0.0, 0.0), (-1.0, 0.0, 0.0)),
    ("{ yaw = 180, pitch = 0 }", (0.0, 0.0, 1.0), (0.0, 0.0, -1.0)),
    ("{ yaw = 0, pitch = -90 }", (0.0, -1.0, 0.0), (0.0, 1.0, 0.0)),
    ("{ pitch = -10 }", (0.0, -math.sin(math.radians(10)), -math.cos(math.radians(10))), None),
    ("{ look = [3.0, 0.0, -4.0] }", (0.6, 0.0, -0.8), None),
]


def test_a_rotation_turns_the_way_the_doc_says_and_is_saved_w_first(tmp_path):
    """docs/level_files.md, ``Transform.rotation``: with no rotation a camera looks down -Z and a
    quad faces +Z; ``yaw = 90`` turns the view to -X and the face to +X, ``yaw = -90`` the view
    to +X and the face to -X, ``yaw = 180`` the face to -Z; ``pitch = -90`` turns the face up,
    ``pitch = -10`` the view a little down; ``look`` is the view's direction.  And a yaw and
    pitch together is the yaw about +Y after the pitch about the turned +X (R_y R_x, worked
    out here as matrices).  Saved, a rotation is ``[w, x, y, z]``, w first: read back by
    tomllib, the list is the quaternion of half the yaw's angle about +Y."""
    text = '[level]\nname = "turns"\n'
    cases = [*DOCUMENTED_TURNS, ("{ yaw = 30, pitch = 20 }", tuple(about("y", 30) @ about("x", 20) @ VIEW),
                                 tuple(about("y", 30) @ about("x", 20) @ FACE))]
    for index, (rotation, _, _) in enumerate(cases):
        text += f'\n[[entity]]\nname = "t{index}"\n[entity.Transform]\nrotation = {rotation}\n'
    path = write(tmp_path, text)
    world = World("turns")
    names = load_level(path).spawn(world)
    for index, (rotation, view, face) in enumerate(cases):
        quat = world.get(names[f"t{index}"], Transform).rotation
        assert np.allclose(turned(quat, VIEW), view, atol=1e-6), (rotation, turned(quat, VIEW), view)
        if face is not None:
            assert np.allclose(turned(quat, FACE), face, atol=1e-6), (rotation, turned(quat, FACE), face)
    saved = entities_in(save_level(world, tmp_path / "saved.toml", names).read_text())
    half = math.radians(90) / 2
    assert np.allclose(saved["t0"]["Transform"]["rotation"], [math.cos(half), 0.0, math.sin(half), 0.0], atol=1e-6)
    world.close()


# --- what a save writes back as it was given -------------------------------------------------------------------

GIVEN_LEVEL = """\
[level]
name = "written back"
game = "hall_of_mirrors"
view_budget = { views = 7, pixels = 12345, probe_ms = 1.5, min_pixels = 9, frame_ms = 20.0, min_render_scale = 0.3 }

[rules]
exit = "ball"
speeds = [1, 2.5]
doors = { north = "ball", keys = [1, 2] }

[[entity]]
name = "ball"
[entity.Transform]
[entity.MeshRef]
mesh = { sphere = 0.5, segments = 8, rings = 5 }
[entity.Material]
texture = { checker = [16, 4], a = [10, 20, 30], b = [200, 100, 50] }
normal_map = { ripples = [32, 3], slope = 0.3, name = "rings" }
emissive_map = { waves = [32, 4], slope = 0.2, seed = 7, name = "swell" }
occlusion_map = { file = "maps/ao.png" }

[[entity]]
name = "ground"
[entity.Transform]
[entity.MeshRef]
mesh = { plane = [3.0, 2.0], uv_repeat = 4.0 }
[entity.Skybox]
faces = { panorama = "sky.png", face_size = 8, yaw = 40.0, intensity = 2.0 }

[[entity]]
name = "smoke"
[entity.Transform]
[entity.ParticleEmitter]
texture = { puff = [16, 5], name = "smoke" }
"""


def test_generator_options_the_view_budget_the_game_and_the_rules_are_saved_as_given(tmp_path):
    """docs/level_files.md: ``save_level`` writes meshes and textures "by how they were made (a
    generator call or a file, relative to the new file)", the ``[level]`` header's ``game``
    and every ``view_budget`` key, and the ``[rules]`` table.  A level giving every generator
    option the doc names (a sphere's ``segments`` and ``rings``, a plane's ``uv_repeat``, a
    checker's colours ``a`` and ``b``, ripples' and waves' ``slope``, ``seed`` and ``name``, a
    puff's name, a panorama's ``face_size``, ``yaw`` and ``intensity``) is saved into another
    folder: read with tomllib, each table is the one given (a file's path from the new folder),
    and the header and rules are the given ones.  The options are applied, not only carried:
    the sphere has (8 + 1) x (5 + 1) vertices, not the default's."""
    from PIL import Image

    (tmp_path / "maps").mkdir()
    Image.fromarray(np.full((8, 8, 3), 100, np.uint8)).save(tmp_path / "maps" / "ao.png")
    Image.fromarray(np.full((8, 16, 3), 100, np.uint8)).save(tmp_path / "sky.png")
    path = write(tmp_path, GIVEN_LEVEL)
    given = tomllib.loads(GIVEN_LEVEL)
    level = load_level(path)
    world = World("written back")
    names = level.spawn(world)
    assert len(world.get(names["ball"], MeshRef).mesh.positions) == 9 * 6
    (tmp_path / "saved").mkdir()
    saved_path = save_level(world, tmp_path / "saved" / "level.toml", names, name=level.name, game=level.game,
                            rules=level.rules)
    saved = tomllib.loads(saved_path.read_text())
    assert saved["level"] == given["level"]
    assert saved["rules"] == given["rules"]
    expected = {table["name"]: table for table in given["entity"]}
    expected["ball"]["Material"]["occlusion_map"] = {"file": "../maps/ao.png"}
    expected["ground"]["Skybox"]["faces"]["panorama"] = "../sky.png"
    got = {table["name"]: table for table in saved["entity"]}
    for name, table in expected.items():
        for kind, fields in table.items():
            if kind != "name" and fields:
                assert got[name][kind] == fields, (name, kind, got[name][kind], fields)
    again = load_level(saved_path, asset_roots=[tmp_path])
    assert again.view_budget == level.view_budget == ViewBudget(views=7, pixels=12345, probe_ms=1.5, min_pixels=9,
                                                                frame_ms=20.0, min_render_scale=0.3)
    assert (again.game, again.rules) == (level.game, level.rules)
    second = World("written back again")
    names_again = again.spawn(second)
    assert world.get(names["ball"], Material).texture.pixels.tobytes() == \
        second.get(names_again["ball"], Material).texture.pixels.tobytes()
    world.close()
    second.close()


@pytest.mark.parametrize("table, saved", [
    ('{ panorama = "sky.png" }', {"panorama": "../sky.png"}),
    ('{ panorama = "sky.png", face_size = 8, yaw = 0.0 }', {"panorama": "../sky.png", "face_size": 8}),
    ('{ panorama = "sky.png", face_size = 256, yaw = -30.0 }', {"panorama": "../sky.png", "yaw": -30.0}),
])
def test_a_panoramas_table_is_saved_with_what_was_given_past_its_defaults(tmp_path, table, saved):
    """A sky panorama's table (docs/level_files.md: ``face_size`` 256 and ``yaw`` 0 unless
    given) is written back with its file and what differs from those defaults, as every
    component field is (a default is not written): a table naming only its file comes back
    naming only its file (a save used to add ``face_size = 256`` and ``yaw = 0.0`` to it).
    The saved level loads again into the same faces."""
    from PIL import Image

    from components import Skybox

    Image.fromarray(np.full((8, 16, 3), 100, np.uint8)).save(tmp_path / "sky.png")
    path = write(tmp_path, f'[level]\nname = "sky"\n[[entity]]\nname = "ground"\n[entity.Skybox]\nfaces = {table}\n')
    level = load_level(path)
    world = World("sky")
    names = level.spawn(world)
    (tmp_path / "saved").mkdir()
    saved_path = save_level(world, tmp_path / "saved" / "level.toml", names, name=level.name)
    got = tomllib.loads(saved_path.read_text())["entity"][0]["Skybox"]["faces"]
    assert got == saved, got
    second = World("sky again")
    again = load_level(saved_path, asset_roots=[tmp_path]).spawn(second)
    assert np.array_equal(second.get(again["ground"], Skybox).faces, world.get(names["ground"], Skybox).faces)
    world.close()
    second.close()


# --- files past their documented sizes -------------------------------------------------------------------------

def test_a_level_file_over_4_mib_and_a_mesh_file_over_256_mib_are_refused_by_their_size(tmp_path):
    """docs/level_files.md, "Files a level names": the level file itself "is at most 4 MiB", and
    "a mesh file at most 256 MiB".  A level of exactly 4 MiB loads; one byte more is refused
    naming the file and its size.  A mesh file (sparse: nothing is written) one byte over 256
    MiB, named by a MeshRef or a Model, is refused naming the file, line, entity and field,
    before any of it is read."""
    head = '[level]\nname = "big"\n'
    path = tmp_path / "big.toml"
    path.write_text(head + "#" * ((4 << 20) - len(head)))
    assert path.stat().st_size == 4 << 20 and load_level(path).name == "big"
    with path.open("a") as file:
        file.write("#")
    with pytest.raises(LevelError, match=f"is {(4 << 20) + 1} bytes, more than") as caught:
        load_level(path)
    assert str(caught.value).startswith(f"{path}: ")
    with (tmp_path / "huge.obj").open("wb") as file:
        file.truncate((256 << 20) + 1)
    for kind, table in (("MeshRef", 'mesh = { file = "huge.obj" }'), ("Model", 'file = "huge.obj"')):
        level = write(tmp_path, f'[level]\nname = "m"\n[[entity]]\nname = "statue"\n[entity.Transform]\n'
                                f'[entity.{kind}]\n{table}\n', f"{kind}.toml")
        with pytest.raises(LevelError, match=f"huge.obj'?: is {(256 << 20) + 1} bytes, more than") as caught:
            load_level(level)
        field = "mesh" if kind == "MeshRef" else "file"
        assert str(caught.value).startswith(f"{level}:7: entity 'statue': {kind}.{field}: "), str(caught.value)



# --- every field naming a file stays in the level's folder -----------------------------------------------------

# (tables an entity needs, the field that names a file, the value with {target} for the path)
FILE_NAMING = {
    "mesh": ("[entity.Transform]\n[entity.MeshRef]\n", "MeshRef.mesh", 'mesh = {{ file = "{target}.glb" }}'),
    "model": ("[entity.Transform]\n[entity.Model]\n", "Model.file", 'file = "{target}.glb"'),
    "detail": ("[entity.Transform]\n[entity.MeshRef]\nmesh = { box = [1.0, 1.0, 1.0] }\n[entity.LevelOfDetail]\n"
               "distances = [3.0]\n", "LevelOfDetail.meshes",
               'meshes = [{{ box = [1.0, 1.0, 1.0] }}, {{ file = "{target}.glb" }}]'),
    "normal_map": ("[entity.Transform]\n[entity.Material]\n", "Material.normal_map",
                   'normal_map = {{ file = "{target}.png" }}'),
    "lightmap": ("[entity.Transform]\n[entity.Material]\n", "Material.lightmap",
                 'lightmap = {{ file = "{target}.png" }}'),
    "lut": ("[entity.Transform]\n[entity.Camera]\n[entity.ColorGrading]\n", "ColorGrading.lut",
            'lut = {{ file = "{target}.cube" }}'),
    "dirt": ("[entity.Transform]\n[entity.Camera]\n[entity.Bloom]\n", "Bloom.dirt",
             'dirt = {{ file = "{target}.png" }}'),
    "panorama": ("[entity.Skybox]\n", "Skybox.faces", 'faces = {{ panorama = "{target}.png" }}'),
    "cookie": ("[entity.Transform]\n[entity.PointLight]\n", "PointLight.cookie",
               'cookie = {{ file = "{target}.png" }}'),
    "ies": ("[entity.Transform]\n[entity.PointLight]\n", "PointLight.cookie", 'cookie = {{ ies = "{target}.ies" }}'),
    "decal": ("[entity.Transform]\n[entity.Decal]\n", "Decal.texture", 'texture = {{ file = "{target}.png" }}'),
    "particles": ("[entity.Transform]\n[entity.ParticleEmitter]\n", "ParticleEmitter.texture",
                  'texture = {{ file = "{target}.png" }}'),
}


@pytest.mark.parametrize("case", sorted(FILE_NAMING))
def test_every_field_that_names_a_file_refuses_one_outside_the_levels_folder(tmp_path, case):
    """docs/level_files.md, "Files a level names": "`file = \\"...\\"` is relative to the level file
    and must stay in its folder: `../../x.png`, an absolute path, or a link that leads out is
    refused", whichever field names it (a mesh, a model, a detail level, a map, a colour table,
    lens dirt, a panorama, a cookie or IES profile, a decal's or particles' image).  Each way
    out is refused naming the file, line, entity and field, and says the file is outside the
    level's folder; the same file inside the folder passes that check (it may fail as the
    junk it is, but not for where it is)."""
    tables, field, value = FILE_NAMING[case]
    level_folder = tmp_path / "level"
    level_folder.mkdir()
    for ext in ("glb", "png", "cube", "ies"):
        (tmp_path / f"secret.{ext}").write_bytes(b"not what it says")
        (level_folder / f"inside.{ext}").write_bytes(b"not what it says")
        (level_folder / f"link.{ext}").symlink_to(tmp_path / f"secret.{ext}")
    for target in ("../secret", str(tmp_path / "secret"), "link", "sub/../../secret", "inside"):
        path = write(level_folder, f'[level]\nname = "out"\n\n[[entity]]\nname = "thing"\n{tables}'
                                   f'{value.format(target=target)}\n')
        try:
            load_level(path)
            reason = ""
        except LevelError as exc:
            reason = str(exc)
            assert reason.startswith(f"{path}:{len(tables.splitlines()) + 6}: entity 'thing': {field}: "), reason
        assert ("outside the level's folder" in reason) == (target != "inside"), (target, reason)
