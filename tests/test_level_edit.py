"""Editing a loaded level: saving with ``keep`` writes back only what changed (the diff is
the edit, names, order and comments kept), and the saved file loads to the edited world."""
from __future__ import annotations

import difflib
import os
import shutil
import textwrap
from pathlib import Path

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, Material, MeshRef, Mirror, Transform, Visibility
from engine.assets.level_file import load_level, save_level
from engine.assets.level_save import same_floats
from engine.assets.mesh import box
from engine.core.world import World
from games.hall_of_mirrors.level import Rise, Spin
from tests.support import small_probes
from tests.test_level_files import fields_by_name

ROOT = Path(__file__).resolve().parents[1]
HALL = ROOT / "games/hall_of_mirrors/hall.toml"
EXTRA = {"Spin": Spin, "Rise": Rise}


def loaded(path: Path, name: str) -> tuple[World, dict[str, int], object]:
    level = load_level(path, EXTRA)
    world = World(name)
    return world, level.spawn(world), level


def diff(a: str, b: str) -> list[str]:
    return [line for line in difflib.unified_diff(a.splitlines(), b.splitlines(), lineterm="", n=0)
            if not line.startswith(("---", "+++", "@@"))]


def test_one_edited_field_is_one_changed_line_and_loads_as_edited(tmp_path):
    path = tmp_path / "hall.toml"
    shutil.copy(HALL, path)
    original = path.read_text()
    world, names, level = loaded(path, "edit_one")
    world.get(names["red_crate"], Material).roughness = 0.35
    save_level(world, path, names, rules=level.rules, extra_components=EXTRA, keep=path)
    changed = diff(original, path.read_text())
    # Independently: the one line under red_crate's [entity.Material] that says roughness.
    lines = original.splitlines()
    crate = lines.index('name = "red_crate"')
    line = next(i for i in range(crate, len(lines)) if lines[i].startswith("roughness ="))
    assert changed == [f"-{lines[line]}", "+roughness = 0.35"]
    again, names_again, _ = loaded(path, "edit_one_again")
    assert list(names_again) == list(names)
    assert same_floats(fields_by_name(again, names_again), fields_by_name(world, names), 1e-6)
    assert again.get(names_again["red_crate"], Material).roughness == 0.35
    world.close()
    again.close()


def test_a_field_with_a_comment_keeps_its_comment(tmp_path):
    path = tmp_path / "hall.toml"
    shutil.copy(HALL, path)
    original = path.read_text()
    world, names, level = loaded(path, "edit_comment")
    world.get(names["mirror_3"], Mirror).reflects_light = False  # the default: the line goes
    world.get(names["mirror_2"], Mirror).roughness = 0.3
    save_level(world, path, names, extra_components=EXTRA, keep=path)
    changed = diff(original, path.read_text())
    assert changed == ["-roughness = 0.25", "+roughness = 0.3",
                       "-reflects_light = true   # throws the sun back onto the floor in front of the wall"]
    world.close()


def test_added_and_removed_components_and_entities_are_their_tables_only(tmp_path):
    path = tmp_path / "hall.toml"
    shutil.copy(HALL, path)
    original = path.read_text()
    world, names, level = loaded(path, "edit_tables")
    world.remove_component(names["koi"], Spin)  # the last table of its entity
    world.add_component(names["lamp_post"], Visibility(in_mirrors=False))
    world.delete_entity(names.pop("oil_stain"))  # (the file's last entity but the koi's mouth)
    extra = world.spawn(Material(roughness=0.25))
    names["new_one"] = extra
    save_level(world, path, names, extra_components=EXTRA, keep=path)
    text = path.read_text()
    removed = [line for line in diff(original, text) if line.startswith("-")]
    added = [line for line in diff(original, text) if line.startswith("+")]
    start = original.index('name = "oil_stain"')
    last = original[start:original.index("\n\n", start)].splitlines()   # (its table, to the blank line)
    assert removed == ["-[entity.Spin]", "-speed = 35.0", "-[[entity]]"] + [f"-{line}" for line in last] + ["-"]
    assert added == ["+[entity.Visibility]", "+in_mirrors = false",   # (difflib pairs the [[entity]] lines anew)
                     "+", "+[[entity]]", '+name = "new_one"', "+[entity.Material]", "+roughness = 0.25"]
    # Every comment of the original is still there, and blank lines still part the entities.
    comments = [line for line in original.splitlines() if line.lstrip().startswith("#")]
    assert all(c in text.splitlines() for c in comments)
    assert "\n\n[[entity]]\nname = \"blue_crate\"" in text
    again, names_again, _ = loaded(path, "edit_tables_again")
    assert list(names_again) == list(names)
    assert same_floats(fields_by_name(again, names_again), fields_by_name(world, names), 1e-6)
    world.close()
    again.close()


def test_an_unedited_save_is_the_same_text(tmp_path):
    path = tmp_path / "hall.toml"
    shutil.copy(HALL, path)
    world, names, level = loaded(path, "edit_none")
    out = save_level(world, tmp_path / "copy.toml", names, name=level.name, game=level.game, rules=level.rules,
                     extra_components=EXTRA, keep=path)
    assert out.read_text() == HALL.read_text()
    world.close()


# --- edits through the editor: the same frames as the same edit in code -----------------------

def edit_scene(world, ents):
    from tests.support import look_from
    from tests.test_mirrors import base_scene, mirror_wall

    base_scene(world)
    look_from(world, (1.5, 1.8, 5.0))
    ents["mirror"] = mirror_wall(world)
    ents["box"] = world.spawn(Transform(position=(-1.0, 1.2, 0.0), scale=(0.6, 0.6, 0.6)), MeshRef(box()),
                              Material(color=(0.9, 0.05, 0.05), roughness=0.4))


def test_an_edit_through_the_editor_renders_as_the_same_edit_in_code(scene):
    from shell.editor import Editor

    by_editor, by_code = {}, {}
    edited = scene(lambda world: edit_scene(world, by_editor), (160, 120))
    coded = scene(lambda world: edit_scene(world, by_code), (160, 120))
    editor = Editor(edited.world)
    first = edited.frame()
    assert np.array_equal(first, coded.frame()) and first.std() > 10  # a picture, the same in both

    box_e, box_c = by_editor["box"], by_code["box"]
    editor.set_field(box_e, "Material", "color", (0.1, 0.8, 0.1, 1.0))
    coded.world.get(box_c, Material).color = (0.1, 0.8, 0.1, 1.0)
    editor.set_field(by_editor["mirror"], Mirror, "color", [0.6, 0.6, 1.0, 1.0])
    coded.world.get(by_code["mirror"], Mirror).color = [0.6, 0.6, 1.0, 1.0]
    green = edited.frame()
    assert np.array_equal(green, coded.frame())
    assert not np.array_equal(green, first)
    # The box seen directly and in the mirror both turned from red to green.
    ids = edited.ids()
    for pixels in (green[ids == box_e],):
        assert (pixels[:, 1].astype(int) > pixels[:, 0]).mean() > 0.9
    assert (first[ids == box_e][:, 0].astype(int) > first[ids == box_e][:, 1]).mean() > 0.9

    # A bad value: the component's own message, and nothing changes (nor the undo list).
    try:
        Material(roughness=-1.0)
    except ComponentValueError as exc:
        expected = str(exc)
    assert editor.try_set_field(box_e, "Material", "roughness", -1.0) == expected == editor.message
    with pytest.raises(ComponentValueError):
        editor.set_field(box_e, "Material", "roughness", float("nan"))
    assert edited.world.get(box_e, Material).roughness == 0.4
    assert np.array_equal(edited.frame(), coded.frame())

    # Undo twice is the first frame again (the code side sets the old values back); redo both.
    assert editor.undo() and editor.undo() and not editor.undo()
    coded.world.get(box_c, Material).color = (0.9, 0.05, 0.05, 1.0)
    coded.world.get(by_code["mirror"], Mirror).color = (1.0, 1.0, 1.0, 1.0)
    undone = edited.frame()
    assert np.array_equal(undone, coded.frame())
    assert np.array_equal(undone, first)
    assert editor.redo() and editor.redo() and not editor.redo()
    assert np.array_equal(edited.frame(), green)


def test_a_drag_is_one_undo_and_components_come_and_go_with_undo(tmp_path):
    from shell.editor import EditError, Editor

    world, names, level = loaded(_copy_hall(tmp_path), "edit_drag")
    editor = Editor(world, EXTRA, names, tmp_path / "hall.toml")
    crate = names["red_crate"]
    for value in (0.5, 0.4, 0.3, 0.2):
        editor.set_field(crate, "Material", "roughness", value, merge=True)
    editor.end_drag()
    editor.set_field(crate, "Material", "metallic", 0.5)
    assert editor.undo() and world.get(crate, Material).metallic == 0.0
    assert editor.undo() and world.get(crate, Material).roughness == 0.6  # the whole drag
    assert not editor.can_undo
    assert "Visibility" in editor.addable(crate) and "Spin" not in editor.addable(crate)
    added = editor.add_component(crate, "Visibility")
    removed = editor.remove_component(crate, "Spin")
    assert world.get(crate, Visibility) is added and not world.has(crate, Spin)
    assert editor.undo() and world.get(crate, Spin) is removed
    assert editor.undo() and not world.has(crate, Visibility)
    assert editor.redo() and world.get(crate, Visibility) is added
    with pytest.raises(EditError, match="no component 'Nonsense'"):
        editor.add_component(crate, "Nonsense")
    with pytest.raises(EditError, match="already has a Material"):
        editor.add_component(crate, "Material")
    with pytest.raises(EditError, match="Material has no field 'shine'"):
        editor.set_field(crate, "Material", "shine", 1.0)
    # A Mirror on an entity without a mesh is refused by the world's own rule, nothing added.
    with pytest.raises(EditError, match="Mirror"):
        editor.add_component(names["sun"], "Mirror")
    assert not world.has(names["sun"], Mirror)
    # A Mirror on the crate's box is refused by the mirror rule, naming the crate (not entity 0).
    with pytest.raises(EditError, match=rf"Mirror on entity {crate}: its MeshRef.mesh .* is not flat"):
        editor.add_component(crate, "Mirror")
    assert not world.has(crate, Mirror)
    # Saved: the file's diff is the edits left (Visibility added; roughness back as it was).
    editor.set_field(crate, "Material", "roughness", 0.3)
    # Play is not an edit: the camera flown and the crate spun are not saved.
    world.get(names["camera"], Transform).position = (1.0, 2.0, 3.0)
    world.get(crate, Transform).rotation = glm.angleAxis(0.5, glm.vec3(0, 1, 0))
    original = (tmp_path / "hall.toml").read_text()
    editor.save()
    changed = diff(original, (tmp_path / "hall.toml").read_text())
    assert changed == ["-roughness = 0.6", "+roughness = 0.3", "+[entity.Visibility]"]
    world.close()


@pytest.mark.parametrize("gone", ["first", "middle", "last"])
def test_a_deleted_entity_takes_the_comment_above_it_and_leaves_its_neighbours(tmp_path, gone):
    """The comments above an entity's header are its own (tomlkit keeps them at the end of the
    table before): saved after a deletion, the file is the original less the deleted entity's
    table and the comment above it, every other comment where it was (one commented-out field
    at the end of a table, before a blank line, stays that table's)."""
    parts = {
        "first": '# The first, a red one.\n[[entity]]\nname = "first"\n[entity.Material]\nroughness = 0.5\n'
                 '# metallic = 1.0\n\n',
        "middle": '# The middle one: rough.\n# (two lines of it)\n[[entity]]\nname = "middle"\n'
                  '[entity.Material]\nroughness = 0.9\n\n',
        "last": '# The last.\n[[entity]]\nname = "last"\n[entity.Material]\nroughness = 0.1\n',
    }
    head = '[level]\nname = "comments"\n\n'
    path = tmp_path / "level.toml"
    path.write_text(head + "".join(parts.values()))
    world, names, _ = loaded(path, f"comments_{gone}")
    world.delete_entity(names.pop(gone))
    save_level(world, path, names, extra_components=EXTRA, keep=path)
    saved = path.read_text()
    expected = head + "".join(text for name, text in parts.items() if name != gone)
    assert saved.rstrip("\n") == expected.rstrip("\n")
    again, names_again, _ = loaded(path, f"comments_{gone}_again")
    assert set(names_again) == set(names)
    world.close()
    again.close()


def _copy_hall(tmp_path: Path) -> Path:
    path = tmp_path / "hall.toml"
    shutil.copy(HALL, path)
    return path


def test_rotation_angles_go_on_past_ninety_degrees_and_follow_turns_without_a_jump():
    """A rotation shows as Euler angles (degrees) that make it.  glm's own decomposition
    keeps yaw within 90 degrees, so a yaw set past 90 came back as the other triple (x + 180,
    180 - y, z + 180) and a drag turned back there; the editor shows the angles last set,
    and after a turn from elsewhere (a handle, an undo) the triple nearest the last shown."""
    from shell.editor import Editor, euler_degrees

    world = World()
    box_entity = world.spawn(Transform(), MeshRef(box()))
    editor = Editor(world)

    def rotation():
        return glm.quat(world.get(box_entity, Transform).rotation)

    def makes(angles, turn):  # the angles give the rotation (q and -q are one rotation)
        return abs(abs(glm.dot(glm.quat(glm.radians(glm.vec3(angles))), turn)) - 1.0) < 1e-6

    for yaw in range(0, 200, 10):  # a drag of yaw: each step set, then shown as set
        assert editor.set_angles(box_entity, "Transform", "rotation", (10.0, yaw, 20.0), merge=True) is None
        assert tuple(editor.angles(box_entity, Transform, "rotation")) == (10.0, yaw, 20.0)
        assert makes((10.0, yaw, 20.0), rotation())
    editor.end_drag()
    # glm alone shows 190 as -170, 10, -160: the same rotation by other numbers.
    plain = glm.degrees(glm.eulerAngles(rotation()))
    assert abs(plain.y - 170.0) > 100.0 and makes(plain, rotation())

    # Turns from elsewhere (a turn handle about world y, from no rotation): the yaw shown goes
    # on by each turn to 240, pitch and roll stay 0, and the angles always make the rotation.
    editor.set_angles(box_entity, Transform, "rotation", (0.0, 0.0, 0.0))
    for step in range(1, 17):
        editor.turn(box_entity, rotation(), glm.vec3(0, 1, 0), glm.radians(15.0))
        now = editor.angles(box_entity, Transform, "rotation")
        assert makes(now, rotation()), (now, rotation())
        # (within a float rotation's rounding: at yaw 90, 0.03 degrees)
        assert tuple(now) == pytest.approx((0.0, 15.0 * step, 0.0), abs=0.05), (step, now)
    editor.end_drag()
    assert editor.undo() and makes(editor.angles(box_entity, Transform, "rotation"), rotation())
    # The nearest triple by whole turns: 370 degrees of yaw shows as 370 next to 360.
    assert euler_degrees(glm.angleAxis(glm.radians(10.0), glm.vec3(0, 1, 0)), glm.vec3(0, 360, 0)).y \
        == pytest.approx(370.0, abs=1e-3)


def test_an_edit_the_frame_would_refuse_is_refused_and_changes_nothing(tmp_path):
    from shell.editor import EditError, Editor

    world, names, level = loaded(_copy_hall(tmp_path), "edit_refused")
    editor = Editor(world, EXTRA, names)
    with pytest.raises(EditError, match="a Mirror needs a MeshRef and a Transform"):
        editor.remove_component(names["mirror_1"], "MeshRef")
    assert world.has(names["mirror_1"], MeshRef)
    with pytest.raises(EditError, match="Water"):
        editor.remove_component(names["pond"], "Mirror")
    assert world.has(names["pond"], Mirror) and not editor.can_undo
    world.close()


@pytest.mark.parametrize("path", sorted(ROOT.glob("games/**/*.toml")), ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_shipped_level_saved_unedited_is_its_own_text(path, tmp_path):
    world, names, level = loaded(path, "edit_shipped")
    out = save_level(world, tmp_path / path.name, names, extra_components=EXTRA, keep=path)
    assert out.read_text() == path.read_text()
    world.close()


def test_inline_component_tables_and_a_rotation_written_as_yaw_keep_their_form(tmp_path):
    path = tmp_path / "inline.toml"
    path.write_text(textwrap.dedent("""\
        [level]
        name = "inline"

        [[entity]]
        name = "lamp"   # the only light
        PointLight = { intensity = 2.0 }
        Transform = { position = [0.0, 2.0, 0.0], rotation = { yaw = 90, pitch = 0 } }
        """))
    original = path.read_text()
    world, names, level = loaded(path, "edit_inline")
    from components import PointLight

    world.get(names["lamp"], PointLight).intensity = 3.0
    world.get(names["lamp"], PointLight).range = 5.0
    world.get(names["lamp"], Transform).position = (1.0, 2.0, 0.0)
    save_level(world, path, names, keep=path)
    assert diff(original, path.read_text()) == [
        "-PointLight = { intensity = 2.0 }",
        "-Transform = { position = [0.0, 2.0, 0.0], rotation = { yaw = 90, pitch = 0 } }",
        "+PointLight = { intensity = 3.0, range = 5.0 }",
        "+Transform = { position = [1.0, 2.0, 0.0], rotation = { yaw = 90, pitch = 0 } }"]
    again, names_again, _ = loaded(path, "edit_inline_again")
    assert again.get(names_again["lamp"], PointLight).range == 5.0
    world.close()
    again.close()


def test_saved_into_another_folder_every_file_it_names_is_found_from_there(tmp_path):
    """Only the edited component is written, but a file the rest names is named again from
    the new folder (else the copy would name files that are not there)."""
    from shell.editor import Editor

    (tmp_path / "a").mkdir()
    (tmp_path / "b" / "deeper").mkdir(parents=True)
    from engine.assets.texture_data import TextureData
    from shell.capture import save_png

    save_png(np.full((4, 4, 3), 200, np.uint8), tmp_path / "a" / "wood.png")
    path = tmp_path / "a" / "level.toml"
    path.write_text(textwrap.dedent("""\
        [level]
        name = "files"

        [[entity]]
        name = "box"
        [entity.Transform]
        [entity.MeshRef]
        mesh = { box = [1.0, 1.0, 1.0] }
        [entity.Material]
        texture = { file = "wood.png" }
        roughness = 0.7
        """))
    world, names, _ = loaded(path, "edit_moved")
    assert isinstance(world.get(names["box"], Material).texture, TextureData)
    editor = Editor(world, names=names, level_path=path)
    editor.set_field(names["box"], "Transform", "position", (0.0, 1.0, 0.0))
    copy = editor.save(tmp_path / "b" / "deeper" / "level.toml")
    text = copy.read_text()
    assert 'texture = { file = "../../a/wood.png" }' in text and "position = [0.0, 1.0, 0.0]" in text
    again = World("edit_moved_again")  # the file is outside the copy's folder: an asset root allows it
    names_again = load_level(copy, asset_roots=[tmp_path / "a"]).spawn(again)
    assert again.get(names_again["box"], Material).roughness == 0.7
    assert again.get(names_again["box"], Material).texture is world.get(names["box"], Material).texture
    world.close()
    again.close()


def test_undo_of_an_edit_to_an_entity_gone_since_says_so(tmp_path):
    from shell.editor import EditError, Editor

    world, names, _ = loaded(_copy_hall(tmp_path), "edit_gone")
    editor = Editor(world, EXTRA, names)
    editor.set_field(names["koi"], "Material", "roughness", 0.1)
    world.delete_entity(names["koi"])
    with pytest.raises(EditError, match=f"entity {names['koi']} .* no longer exists"):
        editor.undo()
    world.close()


def test_entities_made_copied_and_deleted_in_the_editor_are_their_tables_in_the_save(tmp_path):
    """A new entity (a Transform 3 m before the camera, given a PointLight), a copy of a
    crate and the deletion of the pond's back kerb are, saved, exactly those tables; undo and redo make a
    deleted entity again (a new id) with the very same components, and the edits made to it
    before follow it there; a portal's partner comes back with it."""
    from components import PointLight, Portal
    from shell.editor import EditError, Editor

    path = _copy_hall(tmp_path)
    original = path.read_text()
    world, names, _ = loaded(path, "edit_whole")
    editor = Editor(world, EXTRA, dict(names), path)
    camera = world.get(names["camera"], Transform)
    assert editor.create(name="lamp") and editor.name_of(editor.selected) == "lamp_2"  # the hall has a lamp
    assert editor.undo() and not world.exists(editor.selected or -1)
    lamp = editor.create(name="torch")
    assert editor.selected == lamp and editor.name_of(lamp) == "torch"
    expected = camera.position + camera.rotation * glm.vec3(0.0, 0.0, -3.0)
    assert glm.length(world.get(lamp, Transform).position - expected) < 1e-5
    editor.add_component(lamp, "PointLight")
    editor.set_field(lamp, "PointLight", "intensity", 3.0)
    crate = names["red_crate"]
    copy = editor.duplicate(crate)
    assert editor.name_of(copy) == "red_crate_copy" and editor.selected == copy
    assert world.get(copy, Material) is not world.get(crate, Material)
    assert world.get(copy, Transform).position == world.get(crate, Transform).position
    assert world.get(copy, Transform).position is not world.get(crate, Transform).position  # its own vectors
    editor.set_field(copy, "Transform", "position", (0.0, 0.6, 2.5))
    assert world.get(crate, Transform).position != glm.vec3(0.0, 0.6, 2.5)
    kerb = names["pond_kerb_back"]
    editor.set_field(kerb, "Material", "roughness", 0.1)
    kerb_material = world.get(kerb, Material)
    editor.delete(kerb)
    assert not world.exists(kerb) and "pond_kerb_back" not in editor.names
    assert editor.undo()
    back = editor.names["pond_kerb_back"]
    assert back != kerb and world.get(back, Material) is kerb_material and kerb_material.roughness == 0.1
    assert editor.redo() and not world.exists(back)

    editor.save()
    changed = diff(original, path.read_text())
    again = load_level(path, EXTRA)
    spawned = World("edit_whole_again")
    ids = again.spawn(spawned)
    assert "pond_kerb_back" not in ids and {"torch", "red_crate_copy"} <= set(ids) and "lamp_2" not in ids
    assert spawned.get(ids["torch"], PointLight).intensity == 3.0
    assert glm.length(spawned.get(ids["torch"], Transform).position - expected) < 1e-5
    assert spawned.get(ids["red_crate_copy"], Transform).position == glm.vec3(0.0, 0.6, 2.5)
    start = original.index('[[entity]]\nname = "pond_kerb_back"')
    without_kerb = original[:start] + original[original.index("[[entity]]", start + 1):]
    saved = path.read_text()
    assert saved.startswith(without_kerb.rstrip("\n") + "\n")  # the kerb's table out, the rest as it was
    added = saved[len(without_kerb.rstrip("\n")) + 1:]
    assert added.count("[[entity]]") == 2 and 'name = "torch"' in added and 'name = "red_crate_copy"' in added
    assert changed and all(line[1:] in original for line in changed if line.startswith("-"))
    # A portal's partner: deleting one portal leaves the other closed; undo pairs them again.
    door, far = names["door"], names["door_far"]
    with pytest.raises(EditError, match="door is the parent of door_post_left"):
        editor.delete(door)
    editor.delete(far)
    assert world.get(door, Portal).partner is None
    assert editor.undo() and world.get(door, Portal).partner == editor.names["door_far"]
    assert editor.redo() and world.get(door, Portal).partner is None
    editor.save()  # the door's partner goes with door_far: the file loads, the door closed
    door_table = path.read_text().split('name = "door"\n')[1].split("[[entity]]")[0]
    assert "partner" not in door_table and "[entity.Portal]" in door_table
    third = World("edit_whole_third")
    assert "door_far" not in load_level(path, EXTRA).spawn(third)
    third.close()
    with pytest.raises(EditError, match="only active camera"):
        editor.delete(names["camera"])
    world.close()
    spawned.close()


def test_deleting_the_camera_a_monitor_shows_clears_its_camera_and_the_save_loads(tmp_path):
    """The hall's security camera, which its monitor shows, deleted in the editor: the
    monitor's ``camera`` is cleared (as a portal's partner is), undo gives it back the camera
    made again, redo clears it again, and the save writes the monitor without one and loads.
    The inspector offers cameras alone for ``Monitor.camera``.  A save of a world whose field
    names an entity gone, or one without what the field wants, is refused, saying so; the
    editor refuses to set such a field, or to take away the component one names."""
    from components import Camera, Monitor
    from engine.assets.level_read import LevelError
    from shell.editor import EditError, Editor

    path = _copy_hall(tmp_path)
    world, names, _ = loaded(path, "edit_monitor")
    editor = Editor(world, EXTRA, dict(names), path)
    screen = next(entity for entity, _ in world.query_one(Monitor))
    feed = names["security_camera"]
    assert world.get(screen, Monitor).camera == feed
    choices, _ = editor.reference_choices(screen, "Monitor", "camera")
    assert {c for c, _ in choices} - {None} == {e for e, _ in world.query_one(Camera)} - {screen}
    editor.delete(feed)
    assert world.get(screen, Monitor).camera is None
    assert editor.undo() and world.get(screen, Monitor).camera == editor.names["security_camera"]
    assert editor.redo() and world.get(screen, Monitor).camera is None
    editor.save()
    again = World("edit_monitor_again")
    ids = load_level(path, EXTRA).spawn(again)
    assert "security_camera" not in ids and again.get(ids[editor.name_of(screen)], Monitor).camera is None
    again.close()
    # The editor refuses to make such a field (a crate is no camera), or to take away what one names.
    with pytest.raises(EditError, match=r"Monitor\.camera: red_crate has no Camera"):
        editor.set_field(screen, "Monitor", "camera", names["red_crate"])
    editor.undo()   # (the camera back)
    with pytest.raises(EditError, match=r"security_camera's Camera is what .* Monitor\.camera names"):
        editor.remove_component(editor.names["security_camera"], "Camera")
    world.get(screen, Monitor).camera = names["red_crate"]   # (set in code: not a camera)
    with pytest.raises(LevelError, match=r"Monitor\.camera: names entity \d+, which has no Camera"):
        save_level(world, tmp_path / "wrong.toml", editor.names, extra_components=EXTRA)
    world.get(screen, Monitor).camera = 10_000
    with pytest.raises(LevelError, match=r"names entity 10000, which no longer exists"):
        save_level(world, tmp_path / "gone.toml", editor.names, extra_components=EXTRA)
    assert not (tmp_path / "wrong.toml").exists() and not (tmp_path / "gone.toml").exists()
    world.close()


EDIT_OPERATIONS = ("create", "duplicate", "delete", "delete", "move", "rough", "add", "remove", "undo", "undo", "redo")


def random_edit(editor, rng, op: str, entity: int) -> None:
    """One editor operation of the random edit tests on ``entity`` (a refusal raises the
    editor's or the component's error; an operation that does not apply does nothing)."""
    world = editor.world
    if op == "create":
        editor.create(Transform(position=(rng.uniform(-5, 5), rng.uniform(0, 3), rng.uniform(-5, 5))))
    elif op == "duplicate":
        editor.duplicate(entity)
    elif op == "delete":
        editor.delete(entity)
    elif op == "move" and world.has(entity, Transform):
        editor.set_field(entity, "Transform", "position", (rng.uniform(-5, 5), 1.0, rng.uniform(-5, 5)))
    elif op == "rough" and world.has(entity, Material):
        editor.set_field(entity, "Material", "roughness", round(rng.random(), 3))
    elif op == "add" and editor.addable(entity):
        editor.add_component(entity, rng.choice(editor.addable(entity)))
    elif op == "remove" and editor.components_of(entity):
        editor.remove_component(entity, rng.choice(editor.components_of(entity))[0])
    elif op == "undo":
        editor.undo()
    elif op == "redo":
        editor.redo()


@pytest.mark.filterwarnings("ignore:.*no Transform")  # a Transform taken away on purpose
@pytest.mark.parametrize("seed", [int(s) for s in os.environ.get("EDIT_FUZZ_SEEDS", "7,20261129").split(",")])
@pytest.mark.parametrize("level", [HALL] if "EDIT_FUZZ_LEVELS" not in os.environ
                         else sorted(ROOT.glob("games/**/*.toml")), ids=lambda p: p.stem)
def test_random_edits_with_undo_and_redo_save_and_load_back_as_the_world(tmp_path, seed, level):
    """Hardening: 160 random editor operations on a copy of the sample level (every shipped
    level with ``EDIT_FUZZ_LEVELS`` set) (make,
    duplicate, delete, move, set a roughness, add and remove components, undo, redo; the
    refused ones refused with an EditError or a ComponentValueError and nothing changed),
    then a save over the file: the file loads to the world the editor holds, entity by
    entity and field by field (the level file's own encoding of both, floats to float32)."""
    import random

    from engine.assets.level_save import _world_tables
    from shell.editor import EditError, Editor

    rng = random.Random(seed)
    path = tmp_path / level.name
    shutil.copy(level, path)
    world, names, _ = loaded(path, f"edit_fuzz_{seed}")
    editor = Editor(world, EXTRA, dict(names), path)
    counts: dict[str, int] = {}

    def alive() -> list[int]:
        return sorted(editor.names[n] for n in editor.names if world.exists(editor.names[n]))

    for _ in range(int(os.environ.get("EDIT_FUZZ_OPS", "160"))):
        op, entities = rng.choice(EDIT_OPERATIONS), alive()
        if not entities:  # every entity deleted (a level whose game makes its camera allows it)
            op = rng.choice(["create", "undo"])
        entity = rng.choice(entities) if entities else 0
        try:
            random_edit(editor, rng, op, entity)
            counts[op] = counts.get(op, 0) + 1
        except (EditError, ComponentValueError):
            counts["refused"] = counts.get("refused", 0) + 1
    assert counts.get("refused", 0) < 80 and all(counts.get(op, 0) > 3 for op in ("create", "delete", "undo")), counts
    try:
        editor.save()
    except Exception as exc:  # a value no level file can hold is refused by name; then there is nothing to load
        pytest.fail(f"the save was refused: {exc} ({counts})")
    again = World(f"edit_fuzz_{seed}_again")
    spawned = load_level(path, EXTRA).spawn(again)
    by_id_now = {e: n for n, e in editor.names.items() if world.exists(e)}
    _, tables_now = _world_tables(world, path, {n: e for e, n in by_id_now.items()}, EXTRA)
    _, tables_back = _world_tables(again, path, spawned, EXTRA)
    now = {t["name"]: t for t in tables_now.values()}
    back = {t["name"]: t for t in tables_back.values()}
    assert sorted(now) == sorted(back), (sorted(set(now) ^ set(back)), counts)
    different = [name for name in now if not same_floats(now[name], back[name], 1e-5)]
    assert not different, [(name, now[name], back[name]) for name in different[:3]]
    world.close()
    again.close()


@pytest.mark.filterwarnings("ignore:.*no Transform")
def test_random_edits_while_the_sample_level_runs_draw_without_a_gl_error(ctx):
    """Hardening: 90 random editor operations (as above) on the running sample level, a
    frame after every third: every frame draws without a GL error, and after the level's
    own frames go on the renderer holds no batch of an entity gone (its GPU resources came
    back)."""
    import random

    from engine.core.frame_io import Output
    from engine.render.targets import CaptureTarget
    from games.hall_of_mirrors.level import HallOfMirrors
    from shell.app import Engine
    from shell.editor import EditError, Editor

    rng = random.Random(20261129)
    game = HallOfMirrors()
    engine = Engine(game, ctx)
    size = (96, 54)
    capture = CaptureTarget(ctx, size)
    world = engine.world
    editor = Editor(world, game.components, dict(game.names))
    small_probes(world)   # (at 128 the captures edits set off took half the time)
    try:
        def frame() -> None:
            engine.frame(1 / 60, Output(capture.framebuffer, size))
            assert ctx.error == "GL_NO_ERROR"

        frame()
        start = engine.renderer.resource_counts()
        for step in range(90):
            op = rng.choice(EDIT_OPERATIONS)
            entity = rng.choice(sorted(e for e in editor.names.values() if world.exists(e)))
            try:
                random_edit(editor, rng, op, entity)
            except (EditError, ComponentValueError):
                pass
            if step % 3 == 0:
                frame()
        while editor.undo():  # every edit taken back: the level as it was
            pass
        for _ in range(3):
            frame()
        assert engine.renderer.resource_counts()["batches"] <= start["batches"] + 2
        assert sorted(game.names) == sorted(n for n, e in editor.names.items() if world.exists(e))
    finally:
        capture.release()
        engine.close()


def test_a_file_whose_every_entity_is_deleted_saves_its_new_ones_as_valid_toml(tmp_path):
    """Every entity of a level deleted and a new one made (a mirror-beam level: its game makes
    the camera, so nothing refuses): the save loads, holding the new entity alone.  tomlkit
    left an empty ``entity = []`` that the new ``[[entity]]`` tables clashed with (the random
    edit test found it on this level)."""
    from shell.editor import Editor

    source = ROOT / "games/mirror_beam/levels/01_one_bounce.toml"
    for only in (True, False):
        path = tmp_path / f"{only}_{source.name}"
        shutil.copy(source, path)
        world, names, _ = loaded(path, f"edit_emptied_{only}")
        editor = Editor(world, EXTRA, dict(names), path)
        for entity in list(names.values()):
            editor.delete(entity)
        editor.create(Transform(position=(1.0, 2.0, 3.0)), name="only_one")
        if only:
            editor.save()
        else:
            save_level(world, path, editor.names, extra_components=EXTRA, keep=path)
        level = load_level(path, EXTRA)
        again = World(f"edit_emptied_{only}_again")
        assert list(level.spawn(again)) == ["only_one"]
        assert path.read_text().startswith("# One mirror turns the beam")  # the file's own text kept
        again.close()
        world.close()


@pytest.mark.filterwarnings("ignore:.*no Transform")
@pytest.mark.parametrize("game_name", ["mirror_beam", "portal_run"])
def test_the_editor_refuses_what_a_game_cannot_do_without_and_random_edits_keep_it_running(ctx, game_name):
    """A game's own entities (mirror beam's source, target and turning mirrors; portal run's
    solids and exit pad) cannot be deleted, nor their meshes removed, in the editor: the
    game's systems hold them from the build and would fail the next frame.  The refusal is in
    the game's words.  Then 60 random editor operations with a frame after every second run
    without an error (before the game said what it needs, deleting the target or a ledge
    raised inside the next frame)."""
    import random

    from engine.core.frame_io import Output
    from engine.render.targets import CaptureTarget
    from shell.app import Engine
    from shell.editor import EditError, Editor

    if game_name == "mirror_beam":
        from games.mirror_beam.game import MirrorBeam as GameClass
        needed = "target"
    else:
        from games.portal_run.game import PortalRun as GameClass
        needed = "floor"
    game = GameClass()
    engine = Engine(game, ctx)
    size = (96, 54)
    capture = CaptureTarget(ctx, size)
    world = engine.world
    editor = Editor(world, game.components, dict(game.names), needs=game.needs)
    try:
        engine.frame(1 / 60, Output(capture.framebuffer, size))
        with pytest.raises(EditError, match=f"{needed}: {game_name.replace('_', ' ')} cannot do without it"):
            editor.delete(game.names[needed])
        with pytest.raises(EditError, match="cannot do without its MeshRef"):
            editor.remove_component(game.names[needed], "MeshRef")
        assert world.exists(game.names[needed]) and not editor.can_undo
        rng = random.Random(3)
        for step in range(60):
            alive = sorted(e for e in editor.names.values() if world.exists(e))
            try:
                random_edit(editor, rng, rng.choice(EDIT_OPERATIONS), rng.choice(alive))
            except (EditError, ComponentValueError):
                pass
            if step % 2 == 0:
                engine.frame(1 / 60, Output(capture.framebuffer, size))
                assert ctx.error == "GL_NO_ERROR"
    finally:
        capture.release()
        engine.close()


def test_a_level_game_keeps_what_its_rules_name(tmp_path):
    """``LevelGame.needs``' default: an entity the level's [rules] name (a value, or in a
    list or table, nested) cannot be deleted in the editor, in words naming the rule; an
    entity no rule names can, and so can a named entity's components (the game guards those
    itself, as mirror beam and portal run do)."""
    from engine.assets.level_file import LevelGame
    from shell.editor import EditError, Editor

    path = tmp_path / "rules.toml"
    path.write_text(textwrap.dedent("""\
        [level]
        name = "rules"

        [rules]
        exit = "door"
        checkpoints = [["flag_a"], { second = "flag_b" }]
        speed = 3.0

        [[entity]]
        name = "camera"
        [entity.Transform]
        [entity.Camera]

        [[entity]]
        name = "door"
        [entity.Transform]
        [entity.MeshRef]
        mesh = { box = [1.0, 2.0, 0.1] }

        [[entity]]
        name = "flag_a"
        [entity.Transform]

        [[entity]]
        name = "flag_b"
        [entity.Transform]

        [[entity]]
        name = "crate"
        [entity.Transform]
        """))

    class Course(LevelGame):
        game = "course"

    game = Course(path)
    world = World("course")
    try:
        game.build(world)
        editor = Editor(world, game.components, dict(game.names), needs=game.needs)
        with pytest.raises(EditError, match=r"door: course cannot do without it: the level's rules name it "
                                            r"\(exit = 'door'\)"):
            editor.delete(game.names["door"])
        for flag in ("flag_a", "flag_b"):
            with pytest.raises(EditError, match=f"rules name it \\(checkpoints = '{flag}'\\)"):
                editor.delete(game.names[flag])
        assert all(world.exists(game.names[n]) for n in ("door", "flag_a", "flag_b")) and not editor.can_undo
        editor.remove_component(game.names["door"], "MeshRef")   # its components are the game's to guard
        editor.delete(game.names["crate"])                        # no rule names it
        assert not world.exists(game.names["crate"])
    finally:
        world.close()


def test_a_portal_added_in_the_editor_takes_its_quads_outline_as_its_size(tmp_path):
    """The editor's way to a doorway: an entity, a MeshRef made a quad, a Portal. The Portal
    takes the quad's width and height as its size, so things go through the rectangle the
    view shows on (a Portal of the default (2, 3) on the 1 x 1 quad was said by the rule);
    on a box it keeps its default, and the rule says the box is not flat: in the editor's
    message (the overlay's line), as a refusal is, and to the console."""
    import warnings

    from components import ComponentWarning, MeshRef, Portal
    from engine.assets.mesh import quad
    from shell.editor import Editor

    world, names, _ = loaded(_copy_hall(tmp_path), "edit_portal")
    editor = Editor(world, EXTRA, dict(names), tmp_path / "hall.toml")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        door = editor.create(name="door")
        editor.add_component(door, "MeshRef")
        editor.add_component(door, "Material")
        editor.set_mesh_shape(door, "quad")
        editor.add_component(door, "Portal")
        assert world.get(door, Portal).size == (1.0, 1.0)
        wide = editor.create(name="wide")
        editor.add_component(wide, "MeshRef", mesh=quad(1.6, 2.5))
        editor.add_component(wide, "Portal")
        assert world.get(wide, Portal).size == (1.6, 2.5)
        assert not [w for w in caught if issubclass(w.category, ComponentWarning)]
        crate = editor.create(name="crate")
        editor.add_component(crate, "MeshRef")  # the editor's first mesh: a box
        editor.add_component(crate, "Portal")
        assert world.get(crate, Portal).size == (2.0, 3.0)
        said = [str(w.message) for w in caught if issubclass(w.category, ComponentWarning)]
        assert len(said) == 1 and "is not flat" in said[0], said
        assert editor.message == said[0]   # the overlay shows it, as it shows a refusal
        editor.set_field(door, "Portal", "size", (2.0, 1.0))   # a size the quad is not: said at the write
        said = [str(w.message) for w in caught if issubclass(w.category, ComponentWarning)]
        assert len(said) == 2 and editor.message == said[1] and "spans x -0.5 to 0.5" in said[1]
        editor.set_field(door, "Portal", "size", (1.0, 1.0))   # put right: the message goes
        assert editor.message is None and len([w for w in caught if issubclass(w.category, ComponentWarning)]) == 2
    assert world.get(door, MeshRef).mesh.name == "quad"
    world.close()


def test_a_deleted_entity_made_again_by_undo_takes_its_earlier_edits_with_it(scene):
    """The box recoloured, then deleted; undo makes it again under a new id, green, and the
    undo after that takes back the recolouring of the new box (the edit follows it there):
    each frame, pixel for pixel, the frame the scene showed at that step before (the first
    frame, the green one); redo twice is the green box and then none again."""
    from shell.editor import Editor

    ents = {}
    runner = scene(lambda world: edit_scene(world, ents), (96, 72))
    world, box = runner.world, ents["box"]
    editor = Editor(world)
    first = runner.frame()
    assert (runner.ids() == box).sum() > 30
    editor.set_field(box, "Material", "color", (0.1, 0.8, 0.1, 1.0))
    green = runner.frame()
    editor.delete(box)
    gone = runner.frame()
    assert not world.exists(box) and not np.array_equal(gone, green) and not np.array_equal(green, first)
    assert editor.undo()
    back = editor.names[f"entity {box}"]
    assert back != box and world.exists(back) and editor.selected != box
    assert np.array_equal(runner.frame(), green) and (runner.ids() == back).sum() > 30
    assert editor.undo() and world.get(back, Material).color == glm.vec4(0.9, 0.05, 0.05, 1.0)
    assert np.array_equal(runner.frame(), first) and not editor.can_undo
    assert editor.redo() and world.get(back, Material).color == glm.vec4(0.1, 0.8, 0.1, 1.0)
    assert np.array_equal(runner.frame(), green)
    assert editor.redo() and not world.exists(back) and not editor.can_redo
    assert np.array_equal(runner.frame(), gone)


def test_a_handle_is_the_same_size_on_screen_near_or_far_and_through_an_orthographic_lens(scene):
    """``transform_handles``: the x handle of a box straight ahead (its axis across the view)
    is, on a 96x72 output, GIZMO_SHARE x 72 / (2 tan 30 degrees) pixels long from the box's
    projected origin, whether the 60-degree camera stands 3 m or 12 m away, and as long again
    through an orthographic lens 10 m or 40 m tall (the frame's own view-projection each time)."""
    from components import Camera
    from shell.handles import GIZMO_SHARE, transform_handles
    from tests.support import look_from

    size, ents = (96, 72), {}

    def build(world):
        ents["camera"] = look_from(world, (0.0, 1.5, 3.0), (0.0, 1.5, 0.0))
        ents["box"] = world.spawn(Transform(position=(0.0, 1.5, 0.0)), MeshRef(box()), Material())

    runner = scene(build, size)
    world = runner.world
    want = GIZMO_SHARE * size[1] / (2.0 * np.tan(np.radians(30.0)))
    for distance, projection, height in ((3.0, "perspective", None), (12.0, "perspective", None),
                                         (6.0, "orthographic", 10.0), (6.0, "orthographic", 40.0)):
        world.get(ents["camera"], Transform).position = (0.0, 1.5, distance)
        lens = world.get(ents["camera"], Camera)
        lens.projection = projection
        if height is not None:
            lens.ortho_height = height
        runner.frame()
        view = runner.engine.main_view
        handles = transform_handles(world, ents["box"], view.view_proj, view.eye, size, "move")
        (x0, y0), (x1, y1) = handles.lines[0]
        assert abs(x0 - size[0] / 2) < 1e-3 and abs(y0 - size[1] / 2) < 1e-3, (projection, x0, y0)
        assert abs(y1 - y0) < 1e-3 and x1 - x0 == pytest.approx(want, rel=1e-4), (projection, height, x1 - x0, want)
