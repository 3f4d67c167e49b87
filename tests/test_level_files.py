"""Level files: every shipped level survives load -> save -> load unchanged, a mistake is
refused naming the file, line, entity and field with nothing made, and one asset file is
one GPU resource."""
from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest

from components import Camera, MeshRef, Mirror, Portal, Transform, look_rotation
from engine.assets.level_file import LevelError, load_level, save_level
from engine.assets.level_save import _encode_component, same_floats
from engine.assets.mesh import load_model
from engine.assets.texture_data import ripple_normal_map
from engine.core.world import World
from games.hall_of_mirrors.level import LEVEL as HALL
from games.hall_of_mirrors.level import HallOfMirrors, Rise, Spin
from tests.support import SceneRunner

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = sorted(ROOT.glob("games/**/*.toml"))
EXTRA = {"Spin": Spin, "Rise": Rise}  # the hall's own component; the games' levels use engine components only


def fields_by_name(world: World, names: dict[str, int]) -> dict[str, dict]:
    """Every entity's components as a level file writes them, by entity name."""
    by_id = {entity: name for name, entity in names.items()}
    return {name: {type(c).__name__: _encode_component(Path("x.toml"), c, by_id, name)
                   for c in world.components_of(entity)} for name, entity in names.items()}


def test_the_shipped_levels_are_found():
    names = {p.relative_to(ROOT).as_posix() for p in SHIPPED}
    assert "games/hall_of_mirrors/hall.toml" in names
    assert sum(n.startswith("games/mirror_beam/levels/") for n in names) >= 5
    assert sum(n.startswith("games/portal_run/levels/") for n in names) >= 3


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_a_shipped_level_loads_saves_and_loads_to_the_same_world(path, tmp_path):
    level = load_level(path, EXTRA)
    first = World("first")
    names = level.spawn(first)
    saved = save_level(first, tmp_path / "again.toml", names, name=level.name, game=level.game, rules=level.rules,
                       extra_components=EXTRA)
    again = load_level(saved, EXTRA)
    second = World("second")
    names_again = again.spawn(second)
    assert (again.name, again.game, again.rules) == (level.name, level.game, level.rules)
    assert list(names_again) == list(names)
    # Equal up to float32 rounding (a direction is normalised again when it is read back).
    assert same_floats(fields_by_name(second, names_again), fields_by_name(first, names), 1e-6)
    # References are names in the file and ids in the world: the same named pairs either way.
    assert references(second, names_again) == references(first, names)


def references(world: World, names: dict[str, int]) -> set[tuple[str, str, str]]:
    by_id = {entity: name for name, entity in names.items()}
    found = {("partner", by_id[e], by_id[p.partner]) for e, p in world.query_one(Portal) if p.partner}
    return found | {("parent", by_id[e], by_id[t.parent]) for e, t in world.query_one(Transform) if t.parent}


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_a_shipped_level_saved_and_loaded_renders_the_same_frame(ctx, tmp_path, path):
    """The round trip is checked on pixels too: each shipped level and its saved copy, seen
    by the level's own camera, or (the games' levels, whose game adds the camera) from
    above and behind the middle of what it holds."""
    copy = tmp_path / "copy.toml"
    level = load_level(path, EXTRA)
    world = World("copy")
    save_level(world, copy, level.spawn(world), name=level.name, game=level.game, rules=level.rules,
               extra_components=EXTRA)

    def build(file: Path, world: World) -> None:
        load_level(file, EXTRA).spawn(world)
        if not world.query_one(Camera):
            points = np.array([list(t.position) for _, (t, _m) in world.query(Transform, MeshRef)])
            low, high = points.min(axis=0), points.max(axis=0)
            middle, reach = (low + high) / 2, max(float(np.linalg.norm(high - low)), 4.0)
            eye = middle + np.array([0.0, 0.6, 0.8]) * reach
            world.spawn(Transform(position=tuple(eye), rotation=look_rotation(tuple(middle - eye))), Camera())

    frames = []
    for file in (path, copy):
        scene = SceneRunner(ctx, lambda world, file=file: build(file, world), size=(96, 54))
        try:
            frames.append(scene.frame())
        finally:
            scene.close()
    assert frames[0].std() > 10  # a picture, not a flat frame
    np.testing.assert_array_equal(frames[0], frames[1])


BASE = """\
[level]
name = "test"

[[entity]]
name = "floor"
[entity.Transform]
position = [0.0, 0.0, 0.0]
[entity.MeshRef]
mesh = { plane = [4.0, 4.0] }
[entity.Material]
color = [0.5, 0.5, 0.5, 1.0]

[[entity]]
name = "door_a"
[entity.Transform]
position = [0.0, 1.0, 0.0]
[entity.MeshRef]
mesh = { quad = [1.0, 2.0] }
[entity.Material]
[entity.Portal]
partner = "door_b"
size = [1.0, 2.0]

[[entity]]
name = "door_b"
[entity.Transform]
position = [3.0, 1.0, 0.0]
rotation = { yaw = 90, pitch = 0 }
[entity.MeshRef]
mesh = { quad = [1.0, 2.0] }
[entity.Material]
[entity.Portal]
partner = "door_a"
size = [1.0, 2.0]
"""


def write(tmp_path: Path, text: str, name: str = "level.toml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def line_of(path: Path, needle: str, after: str | None = None) -> int:
    lines = path.read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if after in line) if after else 0
    return next(i for i, line in enumerate(lines) if i >= start and needle in line) + 1


def test_the_base_level_loads_and_spawns(tmp_path):
    world = World("base")
    names = load_level(write(tmp_path, BASE)).spawn(world)
    assert world.get(names["door_a"], Portal).partner == names["door_b"]
    assert world.get(names["door_b"], Portal).partner == names["door_a"]


@pytest.mark.parametrize("case", [
    "unknown_component", "unknown_field", "wrong_type", "bad_value", "missing_mesh", "missing_texture",
    "partner_names_nothing", "parent_names_nothing", "duplicate_name", "bad_rotation", "parent_cycle",
    "yaw_as_text", "look_nowhere", "pitch_past_float", "partner_no_portal", "monitor_camera_no_camera",
    "on_death_no_emitter",
])
def test_a_mistake_names_file_line_entity_and_field_and_makes_nothing(tmp_path, case):
    edits = {
        # case: (old text, new text, entity, field or None, the line's text, reason pattern)
        "unknown_component": ("[entity.Portal]\npartner = \"door_b\"", "[entity.Portl]\npartner = \"door_b\"",
                              "door_a", None, "[entity.Portl]", r"no component 'Portl'"),
        "unknown_field": ("color = [0.5, 0.5, 0.5, 1.0]", "colour = [0.5, 0.5, 0.5, 1.0]",
                          "floor", "Material.colour", "colour =", r"Material has no field 'colour'"),
        "wrong_type": ("size = [1.0, 2.0]\n\n[[entity]]", "size = \"big\"\n\n[[entity]]",
                       "door_a", "Portal.size", "size = \"big\"", r"Portal\.size"),
        "bad_value": ("color = [0.5, 0.5, 0.5, 1.0]", "color = [0.5, -2.0, 0.5, 1.0]",
                      "floor", "Material.color", "color = [0.5, -2.0", r"Material\.color"),
        "missing_mesh": ("mesh = { plane = [4.0, 4.0] }", "mesh = { file = \"meshes/gone.obj\" }",
                         "floor", "MeshRef.mesh", "gone.obj", r"mesh file .*gone\.obj.*: no such file"),
        "missing_texture": ("color = [0.5, 0.5, 0.5, 1.0]",
                            "color = [0.5, 0.5, 0.5, 1.0]\ntexture = { file = \"tex/gone.png\" }",
                            "floor", "Material.texture", "gone.png", r"texture file .*gone\.png.*: no such file"),
        "partner_names_nothing": ("partner = \"door_a\"", "partner = \"door_c\"", "door_b", "Portal.partner",
                                  "partner = \"door_c\"", r"names no entity in this file, got 'door_c'"),
        "parent_names_nothing": ("position = [3.0, 1.0, 0.0]", "position = [3.0, 1.0, 0.0]\nparent = \"table\"",
                                 "door_b", "Transform.parent", "parent = \"table\"",
                                 r"names no entity in this file, got 'table'"),
        # (each names an entity of the file that is not of the kind the field wants)
        "partner_no_portal": ("partner = \"door_a\"", "partner = \"floor\"", "door_b", "Portal.partner",
                              "partner = \"floor\"", r"names 'floor', which has no Portal"),
        "monitor_camera_no_camera": ("[entity.Material]\n[entity.Portal]\npartner = \"door_a\"",
                                     "[entity.Material]\n[entity.Monitor]\ncamera = \"floor\"\n"
                                     "[entity.Portal]\npartner = \"door_a\"", "door_b", "Monitor.camera",
                                     "camera = \"floor\"", r"names 'floor', which has no Camera"),
        "on_death_no_emitter": ("partner = \"door_a\"\nsize = [1.0, 2.0]\n",
                                "partner = \"door_a\"\nsize = [1.0, 2.0]\n[entity.ParticleEmitter]\n"
                                "on_death = \"floor\"\n",
                                "door_b", "ParticleEmitter.on_death", "on_death = \"floor\"",
                                r"names 'floor', which has no ParticleEmitter"),
        "duplicate_name": ("name = \"door_b\"", "name = \"door_a\"", "door_a", None, None,
                           r"the name is used twice"),
        "bad_rotation": ("rotation = { yaw = 90, pitch = 0 }", "rotation = { yaw = 90, roll = 3 }", "door_b",
                         "Transform.rotation", "roll = 3", r"a rotation table is"),
        "parent_cycle": ("position = [3.0, 1.0, 0.0]", "position = [3.0, 1.0, 0.0]\nparent = \"door_a\"",
                         "door_a", "Transform.parent", None, r"parents make a cycle"),
        # (a string was read as its number, and a zero direction or a huge angle made NaNs)
        "yaw_as_text": ("rotation = { yaw = 90, pitch = 0 }", "rotation = { yaw = \"90\", pitch = 0 }", "door_b",
                        "Transform.rotation", "yaw = \"90\"", r"a rotation's yaw is a number of degrees, got '90'"),
        "look_nowhere": ("rotation = { yaw = 90, pitch = 0 }", "rotation = { look = [0, 0, 0] }", "door_b",
                         "Transform.rotation", "look = [0, 0, 0]", r"look_rotation forward must be a finite direction"),
        "pitch_past_float": ("rotation = { yaw = 90, pitch = 0 }", "rotation = { yaw = 90, pitch = 1e300 }",
                             "door_b", "Transform.rotation", "pitch = 1e300", r"pitch_deg must be a finite number"),
    }
    old, new, entity, field, line_text, reason = edits[case]
    text = BASE
    if case == "parent_cycle":  # door_b's parent is door_a and door_a's is door_b
        text = text.replace("position = [0.0, 1.0, 0.0]", "position = [0.0, 1.0, 0.0]\nparent = \"door_b\"")
    assert old in text
    path = write(tmp_path, text.replace(old, new, 1))
    world = World("untouched")
    keep = world.spawn(Transform(position=(1.0, 2.0, 3.0)))
    with pytest.raises(LevelError, match=reason) as caught:
        load_level(path).spawn(world)
    error = caught.value
    assert error.file == str(path) and str(path) in str(error)
    assert error.entity == entity and f"entity {entity!r}" in str(error)
    if field is not None:
        assert error.field == field and field in str(error)
    if line_text is not None:
        assert error.line == line_of(path, line_text) and f"{path}:{error.line}:" in str(error)
    else:
        assert error.line is not None and f"{path}:{error.line}:" in str(error)
    assert world.entities() == [keep]  # checked before anything was made; what was there stays
    assert len(world.components_of(keep)) == 1 and list(world.get(keep, Transform).position) == [1.0, 2.0, 3.0]


def test_a_toml_syntax_error_names_its_line(tmp_path):
    path = write(tmp_path, BASE.replace("position = [3.0, 1.0, 0.0]", "position = [3.0, 1.0, 0.0"))
    with pytest.raises(LevelError, match=r"not valid TOML") as caught:
        load_level(path)
    assert caught.value.line == line_of(path, "position = [3.0, 1.0, 0.0") + 1 or \
        caught.value.line == line_of(path, "position = [3.0, 1.0, 0.0")
    assert f"{path}:{caught.value.line}:" in str(caught.value)


def test_a_failure_at_spawn_takes_back_what_it_made(tmp_path):
    """A mirror on a mesh without area is a whole-entity mistake the world refuses at spawn:
    the level's earlier entities are deleted again, and the error names the file and the entity."""
    path = write(tmp_path, BASE + textwrap.dedent("""
        [[entity]]
        name = "crate_mirror"
        [entity.Transform]
        [entity.MeshRef]
        mesh = { quad = [0.0, 1.0] }
        [entity.Material]
        [entity.Mirror]
        """))
    world = World("spawn")
    keep = world.spawn(Transform())
    with pytest.raises(LevelError, match=r"entity 'crate_mirror'.*Mirror") as caught:
        load_level(path).spawn(world)
    assert str(path) in str(caught.value)
    assert world.entities() == [keep]
    assert not world.query_one(Mirror)


# An entity's components that each pass their own checks but break a rule the world holds them
# to together (engine/rules): (its tables, the table or field named, its line's text, reason).
WHOLE_ENTITY_MISTAKES = {
    "mirrored_portal": ("[entity.Transform]\nscale = [-1.0, 1.0, 1.0]\n[entity.MeshRef]\nmesh = { quad = [1.0, 1.0] }\n"
                        "[entity.Material]\n[entity.Portal]\n", "Portal", "[entity.Portal]", r"mirrors it"),
    "detail_without_mesh": ("[entity.Transform]\n[entity.LevelOfDetail]\nmeshes = [{ box = [1.0, 1.0, 1.0] }]\n",
                            "LevelOfDetail", "[entity.LevelOfDetail]", r"give the entity a MeshRef too"),
    "mesh_emitter_without_mesh": ("[entity.Transform]\n[entity.ParticleEmitter]\nshape = \"mesh\"\n",
                                  "ParticleEmitter", "[entity.ParticleEmitter]", r"give the entity a MeshRef too"),
    "second_uvs_the_mesh_lacks": ("[entity.Transform]\n[entity.MeshRef]\nmesh = { box = [1.0, 1.0, 1.0] }\n"
                                  "[entity.Material]\nlightmap = { checker = [8, 2] }\n"
                                  "second_uv_maps = [\"lightmap\"]\n", "Material.second_uv_maps",
                                  "second_uv_maps =", r"has no second UV set"),
    "cutout_portal": ("[entity.Transform]\n[entity.MeshRef]\nmesh = { quad = [1.0, 1.0] }\n[entity.Material]\n"
                      "alpha_cutoff = 0.5\n[entity.Portal]\n", "Material.alpha_cutoff", "alpha_cutoff =",
                      r"a mirror or portal is drawn whole"),
    "occlusion_on_orthographic_camera": ("[entity.Transform]\n[entity.Camera]\nprojection = \"orthographic\"\n"
                                         "[entity.AmbientOcclusion]\n", None, None,
                                         r"AmbientOcclusion on an orthographic Camera"),
    "mirror_and_portal": ("[entity.Transform]\n[entity.MeshRef]\nmesh = { quad = [1.0, 1.0] }\n[entity.Material]\n"
                          "[entity.Mirror]\n[entity.Portal]\n", None, None, r"on an entity with a (Mirror|Portal)"),
    "mirror_with_reflective": ("[entity.Transform]\n[entity.MeshRef]\nmesh = { quad = [1.0, 1.0] }\n"
                               "[entity.Material]\n[entity.Mirror]\n[entity.Reflective]\n", None, None,
                               r"a Reflective on a Mirror changes nothing"),
    "second_sky": ("[entity.Skybox]\n\n[[entity]]\nname = \"extra_sky\"\n[entity.Skybox]\n", "Skybox",
                   "[entity.Skybox]", r"entity 'extra' holds the level's Skybox already, and a world has one sky"),
}


@pytest.mark.parametrize("case", sorted(WHOLE_ENTITY_MISTAKES))
def test_a_whole_entity_mistake_is_refused_when_the_level_loads(tmp_path, case):
    """The world's rules over an entity's components together are run when the file loads:
    the LevelError names the file, the line and the entity of the file (not a world's
    "entity 4" at spawn, after the level was taken as checked), and the component or field."""
    tables, field, line_text, reason = WHOLE_ENTITY_MISTAKES[case]
    path = write(tmp_path, BASE + "\n[[entity]]\nname = \"extra\"\n" + tables)
    with pytest.raises(LevelError, match=reason) as caught:
        load_level(path)
    error = caught.value
    entity = "extra_sky" if case == "second_sky" else "extra"
    assert error.entity == entity and error.field == field and "entity 0" not in str(error)
    after = f"name = \"{entity}\""  # (no table named: the entity's own [[entity]] line, just above)
    line = line_of(path, line_text, after=after) if line_text else line_of(path, after) - 1
    assert error.line == line and f"{path}:{error.line}:" in str(error)

def test_bad_paths_and_headers_are_named(tmp_path):
    with pytest.raises(LevelError, match=r"no such file"):
        load_level(tmp_path / "nothing.toml")
    with pytest.raises(LevelError, match=r"a level file path is a str or pathlib\.Path, got int"):
        load_level(5)
    with pytest.raises(LevelError, match=r"\[level\] needs name"):
        load_level(write(tmp_path, BASE.replace('name = "test"', 'title = "test"')))
    with pytest.raises(LevelError, match=r"PortalClone is made by the engine"):
        load_level(write(tmp_path, BASE + '\n[[entity]]\nname = "x"\n[entity.PortalClone]\nsource = 2\n'))


def test_one_asset_file_is_one_gpu_resource(ctx, tmp_path):
    """Two entities naming one OBJ (and two naming one PNG, two one generated box) share one
    Mesh / TextureData and so one GPU mesh and texture; saved, the level names the files
    relative to itself."""
    from PIL import Image

    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    Image.fromarray(np.full((8, 8, 3), 200, np.uint8)).save(tmp_path / "wood.png")
    extra = "".join(f"""
[[entity]]
name = "thing_{i}"
[entity.Transform]
position = [{i}.0, 0.5, -1.0]
[entity.MeshRef]
mesh = {{ file = "meshes/tri.obj" }}
[entity.Material]
texture = {{ file = "wood.png" }}
""" for i in range(2))
    path = write(tmp_path, BASE + extra + '\n[[entity]]\nname = "cam"\n[entity.Transform]\nposition = [0.0, 1.0, 4.0]'
                                          '\n[entity.Camera]\n')
    level = load_level(path)
    names: dict[str, int] = {}
    scene = SceneRunner(ctx, lambda world: names.update(level.spawn(world)), size=(32, 24))
    try:
        scene.frame()
        world = scene.world
        from components import Material, MeshRef
        meshes = {id(world.get(names[f"thing_{i}"], MeshRef).mesh) for i in range(2)}
        textures = {id(world.get(names[f"thing_{i}"], Material).texture) for i in range(2)}
        assert len(meshes) == 1 and len(textures) == 1
        counts = scene.engine.renderer.resource_counts()
        assert counts["meshes"] == 3  # plane, quad (both doors), triangle
        assert counts["textures"] == 1
        (tmp_path / "out").mkdir()
        text = save_level(world, tmp_path / "out" / "saved.toml", names, name="t").read_text()
        assert 'mesh = { file = "../meshes/tri.obj" }' in text and 'texture = { file = "../wood.png" }' in text
    finally:
        scene.close()


def test_the_hall_takes_another_level_file(ctx, tmp_path):
    """HallOfMirrors(level_path) builds any level file (as --level does): an edited copy of
    the hall with its floor removed has one entity fewer and no floor."""
    text = HALL.read_text()
    start = text.index('[[entity]]\nname = "floor"')
    end = text.index("[[entity]]", start + 10)
    edited = write(tmp_path, text[:start] + text[end:], "no_floor.toml")
    game = HallOfMirrors(edited)
    world = World("edited")
    game.build(world)
    assert "floor" not in game.names and len(game.names) == len(load_level(HALL, EXTRA).entity_names) - 1


def test_every_toml_example_in_the_docs_loads_and_spawns(tmp_path):
    """The README's and docs/level_files.md's level examples are levels that load."""
    import re

    blocks = [block for doc in ("README.md", "docs/level_files.md")
              for block in re.findall(r"^```toml\n(.*?)^```", (ROOT / doc).read_text(), flags=re.S | re.M)]
    assert len(blocks) >= 2
    for index, block in enumerate(blocks):
        world = World(f"example {index}")
        names = load_level(write(tmp_path, block, f"example_{index}.toml"), EXTRA).spawn(world)
        assert names and world.entities()


def test_a_bad_level_through_the_runner_is_one_error_line(tmp_path):
    """--level with a mistake: exit 2 and one 'speculum: error:' line naming file, line,
    entity and field; no frame written."""
    import os
    import subprocess
    import sys

    path = write(tmp_path, BASE.replace("color = [0.5, 0.5, 0.5, 1.0]", "colour = [0.5, 0.5, 0.5, 1.0]"))
    result = subprocess.run([sys.executable, "-m", "games.hall_of_mirrors", "--level", str(path), "--headless",
                             "--frames", "1", "--size", "32x18", "--out", str(tmp_path / "out")],
                            cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    import dataclasses

    from components import Material

    # (The fields a level file may set: the dataclass's own, those a constructor takes, sorted.)
    fields = ", ".join(sorted(f.name for f in dataclasses.fields(Material) if f.init and not f.name.startswith("_")))
    assert "color, diffuse_transmission" in fields and "unlit" in fields
    assert lines == [f"speculum: error: {path}:{line_of(path, 'colour =')}: entity 'floor': Material.colour: "
                     f"Material has no field 'colour' (fields: {fields})"], lines
    assert not list((tmp_path / "out").glob("frame_*.png"))


RED_WALL = """\
[level]
name = "A red wall"

[[entity]]
name = "camera"
[entity.Transform]
position = [0.0, 0.0, 2.0]
[entity.Camera]

[[entity]]
name = "wall"
[entity.Transform]
[entity.MeshRef]
mesh = { quad = [6.0, 6.0] }
[entity.Material]
color = [1.0, 0.0, 0.0, 1.0]
[entity.Emissive]
power = 1.0
"""


def test_level_through_the_runner_plays_that_file(tmp_path):
    """--level is the runner's: the hall's script plays any level file (here a red wall
    filling the view, with no tour in its rules)."""
    import os
    import subprocess
    import sys

    from PIL import Image

    path = write(tmp_path, RED_WALL)
    out = tmp_path / "out"
    result = subprocess.run([sys.executable, "-m", "games.hall_of_mirrors", "--level", str(path), "--headless",
                             "--frames", "1", "--size", "32x18", "--out", str(out)],
                            cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    frame = np.asarray(Image.open(out / "frame_0000.png")).astype(int)
    assert (frame[..., 0] > 200).all() and (frame[..., 1:] < 40).all()  # the wall, not the hall


def test_level_replaces_a_level_games_file_and_is_refused_by_any_other_game(tmp_path, capsys):
    """runner.use_level: a LevelGame's file is replaced (and checked before anything is
    made); a game that builds in Python refuses --level with one error line, exit 2."""
    from shell.runner import main, use_level
    from tests.support import FunctionGame

    game = HallOfMirrors()
    path = write(tmp_path, RED_WALL)
    use_level(game, path)
    assert game.level_path == path
    world = World("red")
    game.build(world)
    assert set(game.names) == {"camera", "wall"}

    out = tmp_path / "out"
    assert main(FunctionGame(lambda world: None), ["--level", str(path), "--headless", "--out", str(out)]) == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and error[0].startswith("speculum: error: --level ") and str(path) in error[0] \
        and "not from a level file" in error[0], error
    assert not out.exists() or not list(out.iterdir())


def test_a_file_with_several_meshes_needs_a_part(tmp_path):
    """An OBJ with two materials is two meshes: naming the file alone is an error listing
    them; part = "name" (as in the file, or file:name) picks one, and saving keeps it."""
    (tmp_path / "two.obj").write_text("o left\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl m1\nf 1 2 3\n"
                                      "o right\nv 2 0 0\nv 3 0 0\nv 2 1 0\nusemtl m2\nf 4 5 6\n")
    whole = '[level]\nname = "parts"\n\n[[entity]]\nname = "thing"\n[entity.Transform]\n[entity.MeshRef]\n' \
            'mesh = { file = "two.obj" }\n'
    path = write(tmp_path, whole)
    with pytest.raises(LevelError, match=r"has 2 parts \['two\.obj:left', 'two\.obj:left_1'\]: say which") as caught:
        load_level(path)
    assert (caught.value.entity, caught.value.field, caught.value.line) == ("thing", "MeshRef.mesh", 8)

    other = whole.split("\n\n", 1)[1].replace('"thing"', '"other"')
    parts = whole.replace('"two.obj" }', '"two.obj", part = "left_1" }') + \
        other.replace('"two.obj" }', '"two.obj", part = "two.obj:left" }')
    world = World("parts")
    names = load_level(write(tmp_path, parts)).spawn(world)
    first, second = (world.get(names[n], MeshRef).mesh for n in ("thing", "other"))
    by_name = {part.mesh.name: part.mesh.positions for part in load_model(tmp_path / "two.obj")}
    assert (first.name, second.name) == ("two.obj:left_1", "two.obj:left")
    np.testing.assert_array_equal(first.positions, by_name["two.obj:left_1"])
    np.testing.assert_array_equal(second.positions, by_name["two.obj:left"])
    assert not np.array_equal(first.positions, second.positions)
    text = save_level(world, tmp_path / "saved.toml", names, name="parts").read_text()
    assert 'mesh = { file = "two.obj", part = "left_1" }' in text
    again = World("again")
    names_again = load_level(tmp_path / "saved.toml").spawn(again)
    assert again.get(names_again["thing"], MeshRef).mesh is first  # one file, one mesh per part

    with pytest.raises(LevelError, match=r"has no part 'middle' \(parts: "):
        load_level(write(tmp_path, whole.replace('"two.obj" }', '"two.obj", part = "middle" }'), "bad.toml"))


POND = BASE + """
[[entity]]
name = "pond"
[entity.Transform]
position = [0.0, 0.01, 2.0]
[entity.MeshRef]
mesh = { quad = [1.0, 1.0] }
[entity.Material]
normal_map = { ripples = [64, 4] }
normal_scale = 0.5

[[entity]]
name = "puddle"
[entity.Transform]
position = [1.0, 0.01, 2.0]
[entity.MeshRef]
mesh = { quad = [0.5, 0.5] }
[entity.Material]
texture = { checker = [16, 2] }
normal_map = { ripples = [64, 4], slope = 0.5 }

[[entity]]
name = "tiles"
[entity.Transform]
position = [2.0, 0.01, 2.0]
[entity.MeshRef]
mesh = { quad = [0.5, 0.5] }
[entity.Material]
normal_map = { ripples = [32, 2], slope = 0.25, name = "wide" }
normal_scale = 2.0
"""


def test_a_wave_normal_map_loads_and_saves_as_it_was_made(tmp_path):
    """Material.normal_map = { waves = [size, trains] } (optional slope, seed, name) is
    ``wave_normal_map``'s map, saved back as it was asked for; a wrong kind is refused."""
    from components import Material
    from engine.assets.texture_data import wave_normal_map

    text = BASE + textwrap.dedent("""
        [[entity]]
        name = "sea"
        [entity.Transform]
        [entity.MeshRef]
        mesh = { quad = [1.0, 1.0] }
        [entity.Material]
        normal_map = { waves = [64, 8], seed = 3, slope = 0.25 }
        """)
    world = World("sea")
    names = load_level(write(tmp_path, text)).spawn(world)
    material = world.get(names["sea"], Material)
    np.testing.assert_array_equal(material.normal_map.pixels, wave_normal_map(64, 8, 0.25, seed=3).pixels)
    (tmp_path / "out").mkdir()
    written = save_level(world, tmp_path / "out" / "saved.toml", names, name="sea").read_text()
    assert "normal_map = { waves = [64, 8], slope = 0.25, seed = 3 }" in written
    with pytest.raises(LevelError, match=r"seed must be an integer"):
        load_level(write(tmp_path, text.replace("seed = 3", "seed = 'x'")))


def test_a_normal_map_loads_saves_and_loads_again(tmp_path):
    """Material.normal_map = { ripples = [size, rings] } (optional slope, name) is the
    generator's map, one object for one call (the default slope written or not), and
    normal_scale a plain number; a normal map file is named like a texture file. Saved, the
    level writes each map by how it was made, and loads again to the same pixels and scales."""
    from PIL import Image

    from components import Material

    (tmp_path / "maps").mkdir()
    Image.fromarray(ripple_normal_map(8, 1).pixels[..., :3]).save(tmp_path / "maps" / "bumps.png")
    text = POND + textwrap.dedent("""
        [[entity]]
        name = "filed"
        [entity.Transform]
        [entity.MeshRef]
        mesh = { quad = [1.0, 1.0] }
        [entity.Material]
        normal_map = { file = "maps/bumps.png" }
        """)
    world = World("pond")
    names = load_level(write(tmp_path, text)).spawn(world)
    pond, puddle, tiles, filed = (world.get(names[n], Material) for n in ("pond", "puddle", "tiles", "filed"))
    np.testing.assert_array_equal(pond.normal_map.pixels, ripple_normal_map(64, 4).pixels)
    assert pond.normal_map.source == {"ripples": [64, 4]} and pond.normal_scale == 0.5
    assert puddle.normal_map is pond.normal_map and puddle.normal_scale == 1.0 and puddle.texture is not None
    np.testing.assert_array_equal(tiles.normal_map.pixels, ripple_normal_map(32, 2, 0.25).pixels)
    assert tiles.normal_map.name == "wide" and tiles.normal_scale == 2.0
    np.testing.assert_array_equal(filed.normal_map.pixels, ripple_normal_map(8, 1).pixels)

    (tmp_path / "out").mkdir()
    saved = save_level(world, tmp_path / "out" / "saved.toml", names, name="pond")
    written = saved.read_text()
    assert "normal_map = { ripples = [64, 4] }\nnormal_scale = 0.5\n" in written
    assert 'normal_map = { ripples = [32, 2], slope = 0.25, name = "wide" }\nnormal_scale = 2.0\n' in written
    assert 'normal_map = { file = "../maps/bumps.png" }' in written
    with pytest.raises(LevelError, match=r"'\.\./maps/bumps\.png' is outside the level's folder"):
        load_level(saved)  # written relative, but outside the saved file's folder: a root is needed
    again = World("again")
    names_again = load_level(saved, asset_roots=[tmp_path]).spawn(again)
    for name in ("pond", "puddle", "tiles", "filed"):
        first, second = world.get(names[name], Material), again.get(names_again[name], Material)
        np.testing.assert_array_equal(second.normal_map.pixels, first.normal_map.pixels)
        assert second.normal_scale == first.normal_scale and second.normal_map.name == first.normal_map.name
    assert same_floats(fields_by_name(again, names_again), fields_by_name(world, names))


@pytest.mark.parametrize("old, new, field, reason", [
    ("{ ripples = [64, 4] }", "{ ripples = [64, 0] }", "Material.normal_map",
     r"rings must be an int in \[1, size=64\]"),
    ("{ ripples = [64, 4] }", "{ ripples = [0, 4] }", "Material.normal_map", r"size must be an int in \[1, "),
    ("{ ripples = [64, 4] }", "{ ripples = [64] }", "Material.normal_map", r"ripples = \[size, rings\] \(two integ"),
    ("{ ripples = [64, 4] }", "{ ripples = [64, 4.5] }", "Material.normal_map", r"ripples = \[size, rings\]"),
    ("{ ripples = [64, 4] }", "{ ripples = [64, 4], slope = -1.0 }", "Material.normal_map",
     r"slope must be a number in \[0, 100\], got -1\.0"),
    ("{ ripples = [64, 4] }", "{ ripples = [64, 4], slope = \"steep\" }", "Material.normal_map",
     r"slope must be a number, got 'steep'"),
    ("{ ripples = [64, 4] }", "{ ripples = [64, 4], slop = 1.0 }", "Material.normal_map",
     r"ripples normal map: unknown keys \['slop'\]"),
    ("{ ripples = [64, 4] }", "{ swells = 3 }", "Material.normal_map",
     r"names one of checker, ripples, waves, puff, file or ies"),
    ("{ ripples = [64, 4] }", "{ waves = 3 }", "Material.normal_map", r"waves = \[size, trains\] \(two integers\)"),
    ("{ ripples = [64, 4] }", "{ waves = [64, 0] }", "Material.normal_map", r"waves must be an int in \[1, 64\]"),
    ("{ ripples = [64, 4] }", "{ ies = \"lamp.ies\" }", "Material.normal_map", r"not a normal map"),
    ("{ ripples = [64, 4] }", "\"ripples.png\"", "Material.normal_map", r"a texture is a table"),
    ("{ ripples = [64, 4] }", "{ file = \"maps/gone.png\" }", "Material.normal_map",
     r"texture file .*gone\.png.*: no such file"),
    ("normal_scale = 0.5", "normal_scale = 20.0", "Material.normal_scale", r"normal_scale"),
    ("normal_scale = 0.5", "normal_scale = -0.5", "Material.normal_scale", r"normal_scale"),
], ids=["rings", "size", "one_number", "float_rings", "negative_slope", "string_slope", "unknown_key",
        "no_generator", "waves_one_number", "waves_none", "ies", "not_a_table", "missing_file", "scale_too_big",
        "scale_negative"])
def test_a_bad_normal_map_names_the_entity_and_field(tmp_path, old, new, field, reason):
    text = POND.replace(old, new, 1)
    assert text != POND
    path = write(tmp_path, text)
    with pytest.raises(LevelError, match=reason) as caught:
        load_level(path)
    error = caught.value
    assert (error.entity, error.field) == ("pond", field)
    assert error.line == line_of(path, new.split(" = ")[0] if new.startswith("normal_scale") else "normal_map =",
                                 after='name = "pond"')
    assert f"{path}:{error.line}: entity 'pond': {field}: " in str(error)
