"""What a player hits (issue 26 items 8 and 9): each game's --help is one title, one usage and
every option; a level file with no camera, or made for another game, is one error line
naming the file (and both games) instead of black frames or the wrong game's rules; a
portal paired with an entity that does not exist says so once.  (Esc, --frames and the
refused outputs in a window: tests/test_window.py; portal run at any --dt:
tests/test_portal_run.py; mirror beam with no display: tests/test_mirror_beam.py.)"""
from __future__ import annotations

import os
import re
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from components import Portal, Transform
from components.portal import PortalPartnerWarning
from engine.assets.level_file import LevelError
from engine.core.world import World
from games.hall_of_mirrors.level import HallOfMirrors
from games.mirror_beam import MirrorBeam
from games.mirror_beam import levels as beam_levels
from games.portal_run import PortalRun
from games.portal_run import levels as run_levels
from shell.runner import build_parser, main

ROOT = Path(__file__).resolve().parents[1]
GAME_OPTIONS = {"hall_of_mirrors": [], "mirror_beam": ["--interval"], "portal_run": ["--autopilot", "--no-autopilot"]}
HEADLESS = ["--headless", "--frames", "1", "--size", "8x8"]


@pytest.fixture
def world():
    made = World("player facing")
    try:
        yield made
    finally:
        made.close()


def _cli(module: str, *args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", module, *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=120, env={**os.environ, "PYTHONPATH": str(ROOT), **(env or {})})


@pytest.mark.parametrize("name", sorted(GAME_OPTIONS))
def test_help_is_one_title_one_usage_and_every_option(name):
    """portal_run printed its own usage, then 'runner options:' and the runner's; mirror_beam
    a line of its options before the runner's usage, which did not list them; the hall's
    title said Speculum twice."""
    result = _cli(f"games.{name}", "--help")
    assert result.returncode == 0 and not result.stderr, result.stderr
    text = result.stdout
    assert text.count("usage:") == 1 and text.startswith(f"usage: python -m games.{name} "), text
    runner_options = [option for action in build_parser(HallOfMirrors)._actions
                      for option in action.option_strings if option.startswith("--") and option != "--help"]
    usage, title = text.split("\n\n")[:2]
    for option in runner_options + GAME_OPTIONS[name]:
        assert f"[{option}" in usage, (option, usage)  # in the one usage block
        assert re.search(rf"^  {re.escape(option)}\b", text, re.M), (option, text)  # and described
    assert title.count("Speculum") == 1 and name.replace("_", " ") in title, title
    assert text.count("Speculum") == 1, text  # one title


def _level(tmp_path: Path, text: str, name: str = "level.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


NO_CAMERA = """\
[level]
name = "a wall and no camera"

[[entity]]
name = "wall"
[entity.Transform]
[entity.MeshRef]
mesh = { quad = [2.0, 2.0] }
[entity.Material]
"""
CAMERA = """
[[entity]]
name = "camera"
[entity.Transform]
position = [0.0, 0.0, 3.0]
[entity.Camera]
"""


def test_a_level_file_with_no_camera_is_an_error_naming_the_file(tmp_path, capsys):
    """It rendered black frames and exited 0 (a Python game with no camera still warns:
    tests/test_runner.py)."""
    path = _level(tmp_path, NO_CAMERA)
    with pytest.raises(LevelError) as info:
        HallOfMirrors(path).build(World("no camera"))
    assert str(path) in str(info.value) and "Camera" in str(info.value)
    out = tmp_path / "out"
    assert main(HallOfMirrors(), ["--level", str(path), "--out", str(out), *HEADLESS]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"speculum: error: {path}: no entity has a Camera"), lines
    assert not out.exists() or not list(out.iterdir())
    # A camera turned off is no camera; one that is on (or a game that makes its own) plays.
    off = _level(tmp_path, NO_CAMERA + CAMERA + "active = false\n", "off.toml")
    with pytest.raises(LevelError, match="no entity has a Camera"):
        HallOfMirrors(off).load()
    HallOfMirrors(_level(tmp_path, NO_CAMERA + CAMERA, "camera.toml")).load()
    assert MirrorBeam.makes_camera and PortalRun.makes_camera


def test_a_level_made_for_another_game_is_refused_naming_both(tmp_path, capsys):
    """A mirror_beam level given to portal_run (or the hall) was played by it without a word."""
    beam, run = beam_levels()[0], run_levels()[0]
    for game, level, own, other in ((HallOfMirrors(), run, "hall_of_mirrors", "portal_run"),
                                    (MirrorBeam(), run, "mirror_beam", "portal_run"),
                                    (HallOfMirrors(), beam, "hall_of_mirrors", "mirror_beam")):
        assert main(game, ["--level", str(level), "--out", str(tmp_path / "out"), *HEADLESS]) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"speculum: error: {level}:"), lines
        assert f"[level] game = '{other}'" in lines[0] and f"not for {own}" in lines[0], lines
    with pytest.raises(LevelError, match="the level is for mirror_beam, not for portal_run"):
        PortalRun(beam)
    result = _cli("games.portal_run", "--level", str(beam), *HEADLESS, "--out", str(tmp_path / "out"))
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and "mirror_beam" in lines[0] and "portal_run" in lines[0]
    # A level naming no game plays in any; one naming the game itself plays.
    text = NO_CAMERA + CAMERA
    HallOfMirrors(_level(tmp_path, text, "any.toml")).load()
    HallOfMirrors(_level(tmp_path, text.replace("[level]\n", '[level]\ngame = "hall_of_mirrors"\n'), "own.toml")).load()


def test_a_portal_paired_with_no_entity_says_so_once(world):
    """Portal(partner=999) left a closed portal without a word: the rules stage says so,
    once a portal and id; a partner spawned after its portal, or deleted later, is no
    mistake and says nothing."""
    from engine.assets.portals import spawn_portal_pair
    from engine.rules.frame_rules import open_portal_pairs
    from systems.frame_rules_system import FrameRulesSystem

    world.add_system(FrameRulesSystem(world), priority=0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        a = world.spawn(Transform(), Portal(partner=999))
        world.step(0.0)
        world.get(a, Portal).partner = 999  # the same again: said already
        world.step(0.0)
        said = [str(w.message) for w in caught if issubclass(w.category, PortalPartnerWarning)]
        assert said == [f"Portal on entity {a}: partner 999 names no entity in this world, so the portal stays "
                        "closed (it shows closed_color) until partner names a portal"], said
        assert open_portal_pairs(world) == {}
        world.get(a, Portal).partner = 998  # another id that is no entity: said
        world.step(0.0)
        pair = spawn_portal_pair(world, (0, 0, 0), None, (3, 0, 0), None)  # partners that exist: nothing
        late = world.spawn(Transform(position=(9, 0, 0)), Portal(partner=world.spawn() + 2))  # its partner comes next
        world.spawn(Transform(position=(12, 0, 0)), Portal(partner=late))
        b = world.spawn(Transform(position=(6, 0, 0)), Portal(partner=a))
        world.get(a, Portal).partner = b
        world.step(0.0)
        assert open_portal_pairs(world)[a] == b and open_portal_pairs(world)[pair[0]] == pair[1]
        world.delete_entity(b)  # a partner deleted later closes the portal without a word
        world.step(0.0)
        said = [str(w.message) for w in caught if issubclass(w.category, PortalPartnerWarning)]
    assert len(said) == 2 and "partner 998" in said[1], said


NO_PARTNER_GAME = """
from components import Portal, Transform
from engine import Game, spawn_camera
from shell import run

class Lone(Game):
    def build(self, world):
        spawn_camera(world)
        world.spawn(Transform(), Portal(partner=999))

run(Lone())
"""


def test_the_runner_says_a_missing_partner_in_one_line(tmp_path):
    game = tmp_path / "lone.py"
    game.write_text(NO_PARTNER_GAME)
    result = subprocess.run([sys.executable, str(game), *HEADLESS, "--out", str(tmp_path / "out")], cwd=ROOT,
                            capture_output=True, text=True, timeout=120, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert result.returncode == 0, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("speculum: warning: Portal on entity ") \
        and "partner 999 names no entity" in lines[0], lines
