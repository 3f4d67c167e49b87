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


# --- every component kind and field a level file holds, read and written back ------------------------------------

# The tables an entity needs beside the component under test (a mirror's mesh, a water's mirror, ...).
QUAD = "[entity.MeshRef]\nmesh = { quad = [1.0, 1.0] }\n[entity.Material]\n"
PLACED_QUAD = "[entity.Transform]\n" + QUAD
HOSTS = {
    "Mirror": QUAD, "Portal": QUAD, "Monitor": QUAD, "Water": QUAD + "[entity.Mirror]\n",
    "Ripples": QUAD + "[entity.Mirror]\n[entity.Water]\n",
    "LevelOfDetail": "[entity.MeshRef]\nmesh = { box = [1.0, 1.0, 1.0] }\n",
    "Animation": "[entity.Model]\nfile = \"door.glb\"\n",
    "AnimationLayer": "[entity.Model]\nfile = \"door.glb\"\n[entity.Animation]\nclip = \"Open\"\n",
    "AnimationEvents": "[entity.Model]\nfile = \"door.glb\"\n[entity.Animation]\nclip = \"Open\"\n",
}
# Values a variation of the default cannot find (assets, names, None defaults), as the file writes them.
GIVEN = {
    "Material": {"texture": "{ checker = [8, 2] }", "normal_map": "{ ripples = [16, 2] }",
                 "emissive_map": "{ checker = [8, 4] }", "metallic_roughness_map": "{ checker = [4, 2] }",
                 "occlusion_map": "{ checker = [16, 4] }", "lightmap": "{ checker = [16, 2] }", "alpha_cutoff": "0.5"},
    "MeshRef": {"mesh": "{ box = [1.0, 2.0, 3.0] }"},
    "LevelOfDetail": {"meshes": "[{ box = [1.0, 1.0, 1.0] }, { sphere = 0.5 }]", "distances": "[12.0]"},
    "Mirror": {"shows_layers": "[0, 1]", "hides_layers": "[2]", "end_image": "true", "plane_point": "[0.0, 0.0, 0.0]",
               "plane_normal": "[0.0, 0.0, 1.0]", "fade_distance": "[8.0, 14.0]", "fade_angle": "[60.0, 85.0]"},
    "Portal": {"partner": "\"Portal_partner\"", "shows_layers": "[0, 1]", "hides_layers": "[2]", "end_image": "true"},
    "Camera": {"shows_layers": "[0, 1]", "hides_layers": "[2]"},
    "ReflectionProbe": {"shows_layers": "[0, 1]", "hides_layers": "[2]", "influence": "[4.0, 3.0, 4.0]"},
    "IrradianceVolume": {"shows_layers": "[0, 1]", "hides_layers": "[2]"},
    "Model": {"file": "\"door.glb\""},
    "Animation": {"clip": "\"Open\"", "fade_from": "\"Slide\"", "root_motion": "\"door\""},
    "AnimationLayer": {"clip": "\"Slide\"", "root": "\"door\""},
    "AnimationEvents": {"events": "[[\"Open\", 0.5, \"creak\"]]"},
    "Bloom": {"dirt": "{ checker = [8, 2] }"},
    "ColorGrading": {"lut": "{ file = \"grade.cube\" }"},
    "DepthOfField": {"focal_length": "85.0"},
    "Decal": {"texture": "{ puff = [16, 3] }", "normal_map": "{ ripples = [16, 2] }", "alpha_cutoff": "0.5",
              "layers": "[1]"},
    "ParticleEmitter": {"end_color": "[1.0, 0.0, 0.0, 0.0]", "texture": "{ puff = [16, 2] }", "ground": "-1.0",
                        "burst_on": "\"step\"", "color_keys": "[[0.0, 1.0, 0.9, 0.2, 1.0], [1.0, 0.3, 0.3, 0.3, 0.0]]",
                        "size_keys": "[[0.0, 0.5], [1.0, 0.25]]", "on_death": "\"ParticleEmitter_partner\""},
    "PointLight": {"cookie": "{ checker = [8, 2] }"},
    "Reflective": {"mix": "0.5"},
    "ScreenText": {"text": "\"Level 1\"", "background": "[0.0, 0.0, 0.0, 0.5]"},
    "Skybox": {"sun_direction": "[0.0, 1.0, 0.0]", "faces": "{ panorama = \"sky.png\", face_size = 8 }"},
    "Transform": {"parent": "\"Transform_partner\""},
    "Monitor": {"camera": "\"Monitor_partner\""},
}
# Fields that exclude others set above (a rectangle light has no radius, ...): on a second entity, "<kind>_alt".
ALTERNATES = {"PointLight": {"rectangle": "[1.0, 0.5]"}, "ParticleEmitter": {"space": "\"local\""},
              "LevelOfDetail": {"meshes": "[{ box = [1.0, 1.0, 1.0] }, { sphere = 0.5 }]", "screen_heights": "[0.3]"}}
# The entities those names name.
PARTNERS = {"Portal": QUAD + "[entity.Portal]\npartner = \"Portal\"\n", "ParticleEmitter": "[entity.ParticleEmitter]\n",
            "Transform": "", "Monitor": "[entity.Camera]\n"}
# Fields no level here sets, and why (each is read and saved in the test named).
NOT_VARIED = {
    ("Material", "second_uv_maps"): "needs a mesh file with a second UV set (tests/test_second_uvs.py)",
    ("Model", "variant"): "needs a file with material variants (tests/test_model_variants.py)",
}


def every_kind_level(folder: Path, varied: dict[str, dict[str, object]] | None = None) -> str:
    """A level with an entity named after each engine component kind holding it (its
    ``HOSTS`` tables beside it), its ``GIVEN`` fields and ``varied`` ones; the assets it names
    are written into ``folder``."""
    from PIL import Image

    from engine.assets.level_read import ENGINE_COMPONENTS
    from engine.assets.level_save import _literal, _plain
    from tests.test_color_grading import _cube
    from tests.test_model_animation import door

    if not (folder / "door.glb").exists():
        door(folder / "door.glb")
        _cube(folder / "grade.cube", 2)
        Image.fromarray(np.linspace(0, 255, 16 * 8 * 3).astype(np.uint8).reshape(8, 16, 3)).save(folder / "sky.png")
    text = '[level]\nname = "every kind"\n'
    for kind in sorted(ENGINE_COMPONENTS):
        fields = dict(GIVEN.get(kind, {}))
        for field, value in (varied or {}).get(kind, {}).items():
            fields[field] = _literal(_plain(value, folder, kind, field))
        host = "" if kind == "Transform" else "[entity.Transform]\n"
        text += f'\n[[entity]]\nname = "{kind}"\n{host}{HOSTS.get(kind, "")}[entity.{kind}]\n'
        text += "".join(f"{field} = {value}\n" for field, value in fields.items())
        if kind in ALTERNATES:
            text += f'\n[[entity]]\nname = "{kind}_alt"\n{host}{HOSTS.get(kind, "")}[entity.{kind}]\n'
            text += "".join(f"{field} = {value}\n" for field, value in ALTERNATES[kind].items())
        if kind in PARTNERS:
            text += f'\n[[entity]]\nname = "{kind}_partner"\n[entity.Transform]\n{PARTNERS[kind]}'
    return text


def vary_fields(level) -> dict[str, dict[str, object]]:
    """For each kind's entity of ``level`` (loaded from ``every_kind_level``): each field not
    given set to a value unlike its default that the component, and the entity's rules with
    its other components, accept: a boolean flipped, a number or vector moved, a string the
    first other choice its refusal names."""
    import dataclasses
    import re
    import warnings

    from pyglm import glm

    from components import ComponentValueError
    from engine.core.world import check_components

    def numbers(value, integer):
        if integer:
            return [value + 1, value - 1, 2, 1, 0, 3, 4, 8, 16, value * 2, value // 2]
        return [value * 0.5 if value else 0.25, value + 0.25, value * 2, 0.75, 0.5, 0.125, value - 0.25, 1.0, 2.0]

    def choices(cls, given, default, field):
        if isinstance(default, bool):
            return [not default]
        if isinstance(default, int):
            return numbers(default, True)
        if isinstance(default, float):
            return numbers(default, False)
        if isinstance(default, (glm.vec2, glm.vec3, glm.vec4)):
            return [type(default)(*(numbers(v, False)[k] for v in default)) for k in range(3)] + \
                [type(default)(*(min(v, 0.875) * 0.5 + 0.0625 for v in default))]
        if isinstance(default, glm.quat):
            return [glm.angleAxis(0.5, glm.normalize(glm.vec3(1.0, 2.0, 3.0)))]
        if isinstance(default, (tuple, list)) and default and all(
                isinstance(v, (int, float)) and not isinstance(v, bool) for v in default):
            integer = all(isinstance(v, int) for v in default)
            return [type(default)(numbers(v, integer)[k] for v in default) for k in range(4)] + \
                [type(default)(sorted(numbers(v, integer)[0] for v in default))]
        if isinstance(default, str):
            try:
                cls(**{**given, field: "not_one_of_them"})
            except (ComponentValueError, ValueError) as exc:
                return [s for s in re.findall(r"['\"](\w+)['\"]", str(exc)) if s not in (default, "not_one_of_them")]
        return []

    varied: dict[str, dict[str, object]] = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for spec in level._entities:
            kind = spec.name
            parts = {cls.__name__: (cls, fields) for cls, fields in spec.components}
            if kind not in parts:
                continue  # a partner
            cls, given = parts[kind]
            host = [c(**f) for name, (c, f) in parts.items() if name != kind]
            defaults = cls(**given)
            chosen: dict[str, object] = {}
            for f in dataclasses.fields(cls):
                if not f.init or f.name.startswith("_") or f.name in GIVEN.get(kind, {}):
                    continue
                default = getattr(defaults, f.name)
                for value in choices(cls, given, default, f.name):
                    try:
                        made = cls(**{**given, **chosen, f.name: value})
                        check_components([*host, made])
                    except Exception:
                        continue
                    if getattr(made, f.name) != default:  # (a direction is normalised: a longer one is the same)
                        chosen[f.name] = getattr(made, f.name)
                        break
            varied[kind] = chosen
    return varied


def test_every_component_kind_and_field_is_read_as_written_and_saved_back_to_the_same_world(tmp_path):
    """One entity for every component a level file may hold (``ENGINE_COMPONENTS``), each of
    its fields set to a value unlike its default (found by varying the default until the
    component takes it, or given: assets, names, fields whose default is None): loaded, each
    field is the value written, not its default; saved and loaded again, the world is the
    same, references included. A component or field added later that no level here can set
    fails until it is given a value (or a reason in ``NOT_VARIED``)."""
    import dataclasses

    from engine.assets.level_read import ENGINE_COMPONENTS, REFERENCE_FIELDS
    from engine.assets.level_save import _plain

    plain = write(tmp_path, every_kind_level(tmp_path), "given.toml")
    varied = vary_fields(load_level(plain))
    path = write(tmp_path, every_kind_level(tmp_path, varied), "every_kind.toml")
    level = load_level(path)
    first = World("first")
    names = level.spawn(first)
    written = fields_by_name(first, names)
    unset = []
    for kind, cls in sorted(ENGINE_COMPONENTS.items()):
        fields = {f.name for f in dataclasses.fields(cls) if f.init and not f.name.startswith("_")}
        # Read as written: each varied value is the loaded component's (to float32), and every
        # field the file sets differs from its default (the save writes only those).
        loaded = first.get(names[kind], cls)
        for field, value in varied[kind].items():
            assert same_floats(_plain(getattr(loaded, field), path, kind, field), _plain(value, path, kind, field),
                               1e-6), (kind, field, getattr(loaded, field), value)
        set_here = set(written[kind][kind]) | {f for c, f in REFERENCE_FIELDS if c == kind}
        assert set(varied[kind]) | set(GIVEN.get(kind, {})) <= set_here, (kind, set(varied[kind]) - set_here)
        if kind in ALTERNATES:
            assert set(ALTERNATES[kind]) <= set(written[f"{kind}_alt"][kind]), kind
            set_here |= set(ALTERNATES[kind])
        unset += [(kind, f) for f in sorted(fields - set_here) if (kind, f) not in NOT_VARIED]
    assert not unset, f"fields no level here sets (give them in GIVEN, or a reason in NOT_VARIED): {unset}"

    saved = save_level(first, tmp_path / "saved" / "every_kind.toml", names, name=level.name) \
        if (tmp_path / "saved").mkdir() is None else None
    again = load_level(saved, asset_roots=[tmp_path])
    second = World("second")
    names_again = again.spawn(second)
    assert list(names_again) == list(names)
    assert same_floats(fields_by_name(second, names_again), written, 1e-6)
    by_id = {entity: name for name, entity in names.items()}
    by_id_again = {entity: name for name, entity in names_again.items()}
    for kind, field in sorted(REFERENCE_FIELDS):
        assert by_id[getattr(first.get(names[kind], ENGINE_COMPONENTS[kind]), field)] == f"{kind}_partner"
        assert by_id_again[getattr(second.get(names_again[kind], ENGINE_COMPONENTS[kind]), field)] == \
            f"{kind}_partner"


# --- docs/level_files.md against the reader ----------------------------------------------------------------------

DOC = ROOT / "docs" / "level_files.md"


def level_fields(cls) -> set[str]:
    import dataclasses

    return {f.name for f in dataclasses.fields(cls) if f.init and not f.name.startswith("_")}


def doc_items(text: str) -> list[str]:
    """The doc's list items and paragraphs (a fenced example stays with the item before it)."""
    import re

    items, current, fenced = [], [], False
    for line in text.splitlines():
        if not fenced and current and (line.startswith(("- ", "#")) or not line.strip()):
            items.append("\n".join(current))
            current = []
        fenced ^= line.strip().startswith("```")
        current.append(line)
    return [re.sub(r"[ \t]*\n[ \t]*", "\n", item) for item in [*items, "\n".join(current)]]


def named_in(kind: str, field: str, text: str) -> bool:
    """Whether ``text`` names ``kind``'s ``field``: as `Kind.field`, or in an item about the kind
    as `field` or as a key a TOML example sets (`field = ...`)."""
    import re

    if f"{kind}.{field}" in text:
        return True
    return any(re.search(rf"\b{kind}\b", item) and re.search(rf"`{field}`|(^|[\s{{,`\]#]){field} =", item, re.M)
               for item in doc_items(text))


def test_the_docs_component_list_is_every_component_a_level_file_holds():
    """The doc's list of component tables (``Components and values``) is the reader's
    ``ENGINE_COMPONENTS``, and every `Kind.field` the doc names is a field the reader takes."""
    import re

    from engine.assets.level_read import ENGINE_COMPONENTS

    text = DOC.read_text()
    listed = re.search(r"A component table is named by its class \(`\[entity\.Material\]`\): (.*?)\. A game", text,
                       re.S).group(1)
    assert sorted(w.strip() for w in listed.split(",")) == sorted(ENGINE_COMPONENTS)
    named = set(re.findall(r"`(\w+)\.(\w+)", text))
    for kind, field in named:
        if kind in ENGINE_COMPONENTS:
            assert field in level_fields(ENGINE_COMPONENTS[kind]), f"the doc names {kind}.{field}, not a field"
    assert len([n for n in named if n[0] in ENGINE_COMPONENTS]) > 50


def test_every_field_a_level_file_takes_is_named_in_the_docs():
    """Each field of each component a level file may hold is named where that component is
    spoken of, in docs/level_files.md or the README: a field added without a word fails."""
    from engine.assets.level_read import ENGINE_COMPONENTS

    doc, readme = DOC.read_text(), (ROOT / "README.md").read_text()
    unnamed = [(kind, field) for kind, cls in sorted(ENGINE_COMPONENTS.items()) for field in sorted(level_fields(cls))
               if not named_in(kind, field, doc) and not named_in(kind, field, readme)]
    assert not unnamed, f"fields no doc names: {unnamed}"


def doc_defaults(text: str) -> list[tuple[str, str, str]]:
    """(component, field, the default as TOML) for each "`field` (..., default X)" of the doc,
    the field's component the nearest one its item names that has such a field; "`a` and `b`
    (..., default X and Y)" gives each its own, and a default after another field named in the
    parentheses' last clause, which it starts (`padding` pixels..., default 6), is that field's."""
    import re

    from engine.assets.level_read import ENGINE_COMPONENTS
    from engine.core.budget import ViewBudget

    owners = {**ENGINE_COMPONENTS, "ViewBudget": ViewBudget}
    kinds = "|".join(sorted(owners, key=len, reverse=True))
    value = r"(`[^`]*`|-?[\d.]+\b|true|false)"
    found = []
    for item in doc_items(text):
        flat = re.sub(r"\s+", " ", item)
        marks = [(m.start(), m.group(1)) for m in re.finditer(rf"\b({kinds})\b", flat)]
        for m in re.finditer(rf"(?:`(\w+)` and )?`(?:(\w+)\.)?(\w+)` \(((?:[^()]|\([^()]*\))*?)\bdefault {value}"
                             rf"(?: and {value})?", flat):
            first, named, field, inner, default, second = m.groups()
            clause = re.split(r"[,;:] ", inner.rstrip(" ,;"))[-1]
            pairs = [(first, default), (field, second)] if first and second else [(field, default)]
            if clause.startswith("`") and re.match(r"`(\w+)`", clause) and not first:
                pairs = [(re.match(r"`(\w+)`", clause).group(1), default)]
            for name, text_value in pairs:
                nearest = [k for p, k in reversed(marks) if p < m.end(3)] + [k for p, k in marks if p >= m.end(3)]
                owner = named if named in owners else next((k for k in nearest if name in level_fields(owners[k])),
                                                           None)
                if owner is not None and name in level_fields(owners[owner]):
                    found.append((owner, name, text_value.strip("`")))
    return found


def test_the_defaults_the_doc_gives_are_the_components_defaults():
    """Every "(..., default X)" docs/level_files.md gives a field is that component's default
    as a level file leaves the field out (a colour given as [r, g, b] has alpha 1)."""
    import math

    import tomllib

    from engine.assets.level_read import ENGINE_COMPONENTS
    from engine.core.budget import ViewBudget

    owners = {**ENGINE_COMPONENTS, "ViewBudget": ViewBudget}
    found = doc_defaults(DOC.read_text())
    assert len(found) > 100
    wrong = []
    for kind, field, text in found:
        doc = tomllib.loads(f"v = {text}")["v"]
        actual = getattr(owners[kind](), field)
        if not isinstance(actual, (bool, int, float, str)) and actual is not None:
            actual = [float(v) for v in actual]
            if isinstance(doc, list) and len(doc) == 3 and len(actual) == 4 and actual[3] == 1.0:
                actual = actual[:3]
        if isinstance(doc, list) != isinstance(actual, list):
            same = False
        elif isinstance(doc, list):
            same = len(doc) == len(actual) and all(math.isclose(a, b, rel_tol=1e-6)
                                                   for a, b in zip(doc, actual, strict=True))
        elif isinstance(doc, bool) or isinstance(actual, bool) or not isinstance(actual, (int, float)):
            same = doc == actual
        else:
            same = math.isclose(doc, actual, rel_tol=1e-6, abs_tol=1e-12)
        if not same:
            wrong.append((kind, field, text, actual))
    assert not wrong, f"the doc's defaults that are not the code's: {wrong}"


# --- the refusals docs/level_files.md promises, each by its line, entity and field ---------------------------------

# case: (the entity "extra"'s tables, the field or table named, the refused line's text, reason pattern)
PROMISED_REFUSALS = {
    "water_without_mirror": (PLACED_QUAD + "[entity.Water]\n", "Water", "[entity.Water]", r"a Water needs a Mirror"),
    "water_on_a_rough_mirror": (PLACED_QUAD + "[entity.Mirror]\nroughness = 0.2\n[entity.Water]\n", "Mirror.roughness",
                                "roughness = 0.2", r"a water surface is sharp: its Mirror\.roughness must be 0"),
    "ripples_without_water": (PLACED_QUAD + "[entity.Mirror]\n[entity.Ripples]\n", "Ripples", "[entity.Ripples]",
                              r"Ripples need a Water"),
    "model_without_transform": ("[entity.Model]\nfile = \"door.glb\"\n", "Model", "[entity.Model]",
                                r"a Model needs a Transform"),
    "model_file_not_a_model": ("[entity.Transform]\n[entity.Model]\nfile = \"junk.glb\"\n", "Model.file",
                               "file = \"junk.glb\"", r"junk\.glb"),
    "clip_the_model_lacks": ("[entity.Transform]\n[entity.Model]\nfile = \"door.glb\"\n[entity.Animation]\n"
                             "clip = \"Dance\"\n", "Animation.clip", "clip = \"Dance\"",
                             r"no animation clip 'Dance' \(its clips: 'Open', 'Slide', 'Blink'\)"),
    "event_past_its_clip": ("[entity.Transform]\n[entity.Model]\nfile = \"door.glb\"\n[entity.AnimationEvents]\n"
                            "events = [[\"Open\", 9.0, \"late\"]]\n", "AnimationEvents.events", "events =", r"9"),
    "partner_names_itself": ("[entity.Transform]\n" + QUAD + "[entity.Portal]\npartner = \"extra\"\n",
                             "Portal.partner", "partner = \"extra\"", r"names the entity itself"),
    "reference_not_a_name": ("[entity.Transform]\n" + QUAD + "[entity.Portal]\npartner = 3\n", "Portal.partner",
                             "partner = 3", r"must be an entity's name, got 3"),
    "component_not_a_table": ("Material = 5\n", None, "Material = 5", r"\[entity\.Material\] must be a table"),
    "a_games_field_of_the_wrong_type": ("[entity.Transform]\n[entity.Spin]\nspeed = \"fast\"\n", "Spin.speed",
                                        "speed = \"fast\"", r"must be a number \(the annotation of Spin\.speed\)"),
    "curve_not_one_of_them": ("[entity.Transform]\n[entity.Camera]\n[entity.Tonemap]\ncurve = \"filmic\"\n",
                              "Tonemap.curve", "curve = \"filmic\"", r"Tonemap\.curve"),
    "exposure_out_of_range": ("[entity.Transform]\n[entity.Camera]\n[entity.Tonemap]\nexposure = 30.0\n",
                              "Tonemap.exposure", "exposure = 30.0", r"Tonemap\.exposure"),
    "min_ev_above_max_ev": ("[entity.Transform]\n[entity.Camera]\n[entity.Tonemap]\nmin_ev = 4.0\nmax_ev = 2.0\n",
                            "Tonemap.max_ev", "max_ev = 2.0", r"min_ev"),
    "bloom_levels_not_an_integer": ("[entity.Transform]\n[entity.Camera]\n[entity.Bloom]\nlevels = 2.5\n",
                                    "Bloom.levels", "levels = 2.5", r"Bloom\.levels"),
    "grading_out_of_range": ("[entity.Transform]\n[entity.Camera]\n[entity.ColorGrading]\ncontrast = 5.0\n",
                             "ColorGrading.contrast", "contrast = 5.0", r"ColorGrading\.contrast"),
    "lut_not_a_cube_file": ("[entity.Transform]\n[entity.Camera]\n[entity.ColorGrading]\n"
                            "lut = { file = \"junk.cube\" }\n", "ColorGrading.lut", "lut = ", r"junk\.cube"),
    "fade_start_past_its_end": ("[entity.Transform]\n" + QUAD + "[entity.Mirror]\nfade_distance = [14.0, 8.0]\n",
                                "Mirror.fade_distance", "fade_distance =", r"Mirror\.fade_distance"),
    "fade_angle_over_90": ("[entity.Transform]\n" + QUAD + "[entity.Mirror]\nfade_angle = [60.0, 95.0]\n",
                           "Mirror.fade_angle", "fade_angle =", r"Mirror\.fade_angle"),
    "priority_not_an_integer": ("[entity.Transform]\n" + QUAD + "[entity.Mirror]\npriority = 1.5\n",
                                "Mirror.priority", "priority = 1.5", r"Mirror\.priority"),
    "another_end_image": ("[entity.Transform]\n" + QUAD + "[entity.Mirror]\nend_image = \"sometimes\"\n",
                          "Mirror.end_image", "end_image =", r"Mirror\.end_image"),
    "bad_anchor": ("[entity.ScreenText]\ntext = \"hi\"\nanchor = \"middle\"\n", "ScreenText.anchor",
                   "anchor = \"middle\"", r"ScreenText\.anchor"),
    "bad_text_scale": ("[entity.ScreenText]\ntext = \"hi\"\nscale = 0\n", "ScreenText.scale", "scale = 0",
                       r"ScreenText\.scale"),
    "bad_panel_size": ("[entity.ScreenPanel]\nsize = [-4.0, 8.0]\n", "ScreenPanel.size", "size = [-4.0",
                       r"ScreenPanel\.size"),
    "a_bare_layer_number": ("[entity.Transform]\n[entity.Visibility]\nlayers = 3\n", "Visibility.layers",
                            "layers = 3", r"Visibility\.layers"),
    "mesh_emitter_without_a_mesh": ("[entity.Transform]\n[entity.ParticleEmitter]\nshape = \"mesh\"\n",
                                    "ParticleEmitter", "[entity.ParticleEmitter]", r"MeshRef"),
    "a_derived_component": ("[entity.Transform]\n[entity.Slice]\n", None, "[entity.Slice]",
                            r"Slice is made by the engine each frame, not written in a level"),
}


@pytest.mark.parametrize("case", sorted(PROMISED_REFUSALS))
def test_a_refusal_the_doc_promises_names_the_file_line_entity_and_field(tmp_path, case):
    """docs/level_files.md's refusals (``Mistakes`` and each component's "is refused naming the
    field"): each fails the load with a LevelError whose text names the file and the line
    the mistake is on, the entity and the field (or the table), found by the line's text here."""
    from tests.test_model_animation import door

    door(tmp_path / "door.glb")
    (tmp_path / "junk.glb").write_bytes(b"glTF\x02\x00\x00\x00junk")
    (tmp_path / "junk.cube").write_text("LUT_3D_SIZE 2\n0 0 0\n")
    tables, field, line_text, reason = PROMISED_REFUSALS[case]
    path = write(tmp_path, BASE + "\n[[entity]]\nname = \"extra\"\n" + tables)
    with pytest.raises(LevelError, match=reason) as caught:
        load_level(path, EXTRA)
    error = caught.value
    assert (error.entity, error.field) == ("extra", field), (error.entity, error.field, str(error))
    assert error.line == line_of(path, line_text, after='name = "extra"'), (error.line, str(error))
    assert str(error).startswith(f"{path}:{error.line}: entity 'extra': " + (f"{field}: " if field else ""))
