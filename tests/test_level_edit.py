"""Editing a loaded level: saving with ``keep`` writes back only what changed (the diff is
the edit, names, order and comments kept), and the saved file loads to the edited world."""
from __future__ import annotations

import difflib
import shutil
from pathlib import Path

from components import Material, Mirror, Visibility
from engine.assets.level_file import load_level, same_floats, save_level
from engine.core.world import World
from games.hall_of_mirrors.level import Spin
from tests.test_level_files import fields_by_name

ROOT = Path(__file__).resolve().parents[1]
HALL = ROOT / "games/hall_of_mirrors/hall.toml"
EXTRA = {"Spin": Spin}


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
    world.delete_entity(names.pop("ghost"))
    extra = world.spawn(Material(roughness=0.25))
    names["new_one"] = extra
    save_level(world, path, names, extra_components=EXTRA, keep=path)
    text = path.read_text()
    removed = [line for line in diff(original, text) if line.startswith("-")]
    added = [line for line in diff(original, text) if line.startswith("+")]
    ghost = original[original.index('name = "ghost"'):].splitlines()
    assert removed == ["-[entity.Spin]", "-speed = 35.0"] + [f"-{line}" for line in ghost]
    assert added == ["+[entity.Visibility]", "+in_mirrors = false",
                     '+name = "new_one"', "+[entity.Material]", "+roughness = 0.25"]
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
