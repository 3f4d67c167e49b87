"""games.portal_run played on real frames (llvmpipe, 96x54): each level from a scripted input
sequence to its win event, walls that stop the body, portals refused with a visible cue,
the turned velocity out of a portal at right angles, restart, the rules' errors and the
command line.  Some frames are written to out/portal_run/ to look at."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pyglm import glm

from components import Emissive, Material, MeshRef, Portal, Transform
from engine.assets.level_file import LevelError
from engine.core.frame_io import Input, Output
from engine.render.targets import CaptureTarget
from engine.rules.frame_rules import FrameRules
from games.portal_run import LevelRulesError, PortalRun, levels
from games.portal_run.autopilot import Autopilot, ScriptError
from games.portal_run.game import EYE_HEIGHT, GRAVITY, HALF_WIDTH, JUMP_SPEED, WALK_SPEED, PlayerBody, load_rules
from shell.app import Engine
from shell.capture import save_png

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "out" / "portal_run"
SIZE = (96, 54)
DT = 1.0 / 60.0
LEVELS = levels()


class Play:
    """A PortalRun on the test context; ``frame()`` fills the Input from a script first, as a
    person's keys and mouse would, then renders a frame."""

    def __init__(self, ctx, level: Path, script=None) -> None:
        # No caption: at 96x54 its 16-pixel text would cover the cues these frames look at
        # (the caption itself: tests/test_text.py).
        self.game = PortalRun(level, verbose=False, show_caption=False)
        self.engine = Engine(self.game, ctx)
        self.world = self.engine.world
        self.capture = CaptureTarget(ctx, SIZE)
        self.input: Input = self.world.resources[Input]
        self.pilot = Autopilot(self.game.rules.solution if script is None else script)

    def frame(self, render: bool = True) -> np.ndarray | None:
        if not self.pilot.done:
            self.pilot.fill(self.input, self.game)
        output = Output(self.capture.framebuffer, SIZE) if render else None
        self.engine.frame(DT, output)
        return self.capture.read_rgb() if render else None

    def run_script(self, render: bool = True, limit: int = 900) -> list[np.ndarray]:
        frames = []
        while not self.pilot.done and limit > 0:
            frames.append(self.frame(render))
            limit -= 1
        return frames

    @property
    def eye(self) -> glm.vec3:
        return glm.vec3(self.world.get(self.game.player, Transform).position)

    @property
    def body(self) -> PlayerBody:
        return self.world.get(self.game.player, PlayerBody)

    def pixel(self, point) -> tuple[int, int]:
        view = self.engine.main_view
        clip = view.view_proj * glm.vec4(glm.vec3(point), 1.0)
        ndc = glm.vec3(clip) / clip.w
        return int((ndc.x * 0.5 + 0.5) * SIZE[0]), int((1.0 - (ndc.y * 0.5 + 0.5)) * SIZE[1])

    def entity_box(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """An entity's world box from its Transform and mesh bounds (a box or quad, unrotated)."""
        entity = self.game.names[name]
        t = self.world.get(entity, Transform)
        lo, hi = self.world.get(entity, MeshRef).mesh.bounds
        p, s = np.array(t.position), np.array(t.scale)
        return p + lo * s, p + hi * s

    def close(self) -> None:
        self.capture.release()
        self.engine.close()


@pytest.fixture
def play(ctx):
    made: list[Play] = []

    def make(level: Path, script=None) -> Play:
        made.append(Play(ctx, level, script))
        return made[-1]

    yield make
    for p in made:
        p.close()


def _save(frame: np.ndarray, name: str) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    save_png(frame, OUT / name)


@pytest.mark.parametrize("level", LEVELS, ids=[p.stem for p in LEVELS])
def test_each_level_is_won_from_its_scripted_input(play, level):
    p = play(level)
    pad_lo, pad_hi = p.entity_box(p.game.rules.exit)
    start_feet = p.game.rules.start[1]
    if "fling" not in level.stem:
        # Out of reach on foot: the pad is higher than a jump (v^2 / 2g) above the start.
        assert pad_hi[1] - start_feet > JUMP_SPEED ** 2 / (2 * GRAVITY) + 1.0
    else:
        # Out of reach on foot: from the deck's edge a running jump falls to the ledge's height
        # (8 + 5.5 t - 7.5 t^2 = 3) before it covers the gap to the ledge's near edge.
        deck_lo, _ = p.entity_box("deck")
        _, ledge_hi = p.entity_box("ledge")
        drop = start_feet - ledge_hi[1]
        airtime = (JUMP_SPEED + math.sqrt(JUMP_SPEED ** 2 + 2 * GRAVITY * drop)) / GRAVITY
        assert deck_lo[2] - ledge_hi[2] > WALK_SPEED * airtime + 2 * HALF_WIDTH
    speeds = []  # the body's velocity after each frame
    frames = []
    while not p.pilot.done:
        frames.append(p.frame())
        speeds.append(np.array(p.body.velocity))
    kinds = p.game.event_kinds()
    assert kinds.count("win") == 1, p.game.events
    assert kinds.count("travelled") >= (2 if "two_hops" in level.stem else 1)
    assert "restart" not in kinds and "fell" not in kinds
    # Standing on the pad (a flat marker the feet stand in, on the ledge): the body over it.
    eye = p.eye
    assert pad_lo[1] - 0.01 <= eye.y - EYE_HEIGHT <= pad_hi[1]
    assert pad_lo[0] - HALF_WIDTH <= eye.x <= pad_hi[0] + HALF_WIDTH
    assert pad_lo[2] - HALF_WIDTH <= eye.z <= pad_hi[2] + HALF_WIDTH
    win = next(e for e in p.game.events if e.kind == "win")
    travel = next(e for e in p.game.events if e.kind == "travelled")
    if "fling" in level.stem:
        # The fall's speed comes out of B turned along its normal (+X): at least sqrt(2 g h) for
        # the eight metres from the deck to the pit floor, far more than walking.
        fall = start_feet - p.entity_box("pit_floor")[1][1]
        before, after = speeds[travel.frame - 2], speeds[travel.frame - 1]
        assert before[1] < -math.sqrt(2 * GRAVITY * fall) and abs(before[0]) < 1e-6
        assert after[0] == pytest.approx(-before[1], rel=0.02) and after[0] > 3 * WALK_SPEED
    for old in OUT.glob(f"{level.stem}_*.png"):  # the last run's frames (their numbers may differ)
        old.unlink()
    for index in (0, travel.frame - 3, travel.frame, win.frame, len(frames) - 1):
        _save(frames[index], f"{level.stem}_{index:04d}.png")
    # The win cue: the pad glows. The script ends looking down at it; the same frame with the
    # pad's glow put back to the level's own is darker there.
    column, row = p.pixel((pad_lo + pad_hi) / 2)
    assert 0 <= column < SIZE[0] and 0 <= row < SIZE[1]
    lit = frames[-1][row, column].astype(int)
    glow = p.world.get(p.game.names[p.game.rules.exit], Emissive)
    glow.power = 0.3
    p.input.mouse_dx = p.input.mouse_dy = 0.0
    dim = p.frame()[row, column].astype(int)
    # (100 levels: the sky's ambient light lights the dimmed pad too, and the glowing one
    # is clipped at 255 in green and blue.)
    assert lit[1] >= 200 and lit.sum() > dim.sum() + 100, (lit, dim)


def test_walking_at_a_wall_stops_at_its_face_and_a_ledge_cannot_be_climbed(play):
    level = LEVELS[0]
    # Face the left wall (its face is the plane x = -6) and walk at it for longer than it takes.
    p = play(level, ["look 90 0", "hold w 100"])
    face = p.entity_box("left_wall")[1][0]
    xs = []
    for _ in range(101):
        p.frame(render=False)
        xs.append(p.eye.x)
        assert p.eye.x - HALF_WIDTH >= face - 1e-6  # the body never passes the wall's plane
    assert xs[-1] - HALF_WIDTH == pytest.approx(face, abs=1e-3)  # it got there and stopped
    assert xs[40] < xs[10] - 2.0  # and it did walk
    # At the ledge (3 m high): walking and jumping at it never gets the feet onto it.
    p2 = play(level, ["look 0 0"] + ["hold w 20", "press space", "hold w 30"] * 3)
    ledge_lo, ledge_hi = p2.entity_box("ledge")
    highest = 0.0
    while not p2.pilot.done:
        p2.frame(render=False)
        highest = max(highest, p2.eye.y - EYE_HEIGHT)
        assert p2.eye.z - HALF_WIDTH >= ledge_hi[2] - 1e-6
    assert 0.8 < highest < ledge_hi[1]  # it jumped, and not high enough
    assert p2.eye.z - HALF_WIDTH == pytest.approx(ledge_hi[2], abs=1e-3)


def test_a_portal_on_a_too_narrow_wall_is_refused_with_a_red_marker(play):
    level = LEVELS[1]  # the pillar (0.8 m wide) takes portals but is narrower than one (1.2 m)
    p = play(level, ["aim -1 1.5 1.6", "click left"])
    portal = p.game.portals[0]
    before = glm.vec3(p.world.get(portal, Transform).position)
    frames = p.run_script()
    refused = [e for e in p.game.events if e.kind == "refused"]
    assert len(refused) == 1 and "pillar" in refused[0].detail and "wide" in refused[0].detail
    assert p.world.get(portal, Transform).position == before  # the portal did not move
    assert not p.world.get(portal, Portal).enabled and not p.world.get(portal, MeshRef).visible
    # The cue: the marker stands off the pillar's face where the shot hit, and shows red there.
    hit = np.array(refused[0].point)
    assert hit[2] == pytest.approx(1.6, abs=1e-4) and -1.4 <= hit[0] <= -0.6
    marker = glm.vec3(p.world.get(p.game.marker, Transform).position)
    column, row = p.pixel(marker + glm.vec3(0.12, -0.12, 0.0))  # in the 0.5 m marker, off the crosshair
    r, g, b = frames[-1][row, column].astype(int)
    _save(frames[-1], "refused_pillar.png")
    assert r > 150 and g < 90 and b < 90, (r, g, b)
    # It goes after a while, and the pixel shows the pillar again.
    for _ in range(45):
        frame = p.frame()
    assert not p.world.get(p.game.marker, MeshRef).visible
    r, g, b = frame[row, column].astype(int)
    assert not (r > 150 and g < 90 and b < 90)


def test_other_refusals_and_the_fit_sliding_onto_the_face(play):
    level = LEVELS[1]
    p = play(level, ["aim -3 1 -8", "click left",  # the metal back wall takes no portals
                     "aim -3 0.2 8", "click right"])  # low on the front wall: slides up onto the face
    p.run_script(render=False)
    details = [e.detail for e in p.game.events if e.kind == "refused"]
    assert len(details) == 1 and "back_wall does not take portals" in details[0]
    placed = [e for e in p.game.events if e.kind == "placed"]
    assert len(placed) == 1
    # A 2 m portal on a face from y = 0 up: its centre at y = 1, x where the shot hit, on z = 8.
    center = placed[0].point
    assert center[1] == pytest.approx(1.0, abs=1e-6) and center[2] == pytest.approx(8.0, abs=1e-4)
    assert center[0] == pytest.approx(-3.0, abs=0.05)
    portal_t = p.world.get(p.game.portals[1], Transform)
    normal = portal_t.rotation * glm.vec3(0, 0, 1)  # a portal faces its local +Z: out of the wall
    assert glm.length(normal - glm.vec3(0, 0, -1)) < 1e-5
    assert portal_t.position.z == pytest.approx(8.0 - 0.01, abs=1e-5)
    # Level 1 takes portals on every wall, but the floor is no wall.
    p1 = play(LEVELS[0], ["look 0 -80", "click left"])
    p1.run_script(render=False)
    assert [e.detail for e in p1.game.events] == ["portal A: floor is not a wall there (portals go on upright faces)"]


def test_a_lone_portal_is_closed_and_a_pair_shows_the_other_side(play):
    level = LEVELS[0]
    p = play(level, ["aim 0 1 8", "click left", "wait 1"])
    p.run_script()
    a, b = p.game.portals
    below = glm.vec3(0.0, -0.4, 0.0)  # a point on A below its centre, where the crosshair is not
    column, row = p.pixel(p.world.get(a, Transform).position + below)
    assert p.engine.renderer.targets.read_ids()[row, column] == a  # closed: the portal itself
    p.pilot = Autopilot(["aim 0 3.8 -8", "click right", "aim 0 1 8", "wait 1"])
    p.run_script()
    ids = p.engine.renderer.targets.read_ids()
    column, row = p.pixel(p.world.get(a, Transform).position + below)
    seen = int(ids[row, column])
    beyond = {p.game.names[n] for n in ("ledge", "floor", "exit_pad", "front_wall", "left_wall", "right_wall")}
    assert seen in beyond, seen  # through A: what stands in front of B


def test_velocity_turns_with_the_player_through_portals_at_right_angles(play):
    level = LEVELS[1]
    # B high on the wall above the ledge (it slides to the top: centre 6 m), A on the front wall;
    # walking +Z into A leaves B (facing -X) two metres above the ledge, falling.
    p = play(level, ["aim 6 6.5 0", "click right", "aim -3 1 8", "click left", "walk_to -3 9", "wait 40"])
    positions, travelled_at = [], None
    while not p.pilot.done:
        p.frame(render=False)
        positions.append(np.array(p.eye))
        if travelled_at is None and "travelled" in p.game.event_kinds():
            travelled_at = len(positions) - 1
    b_center = next(e.point for e in p.game.events if e.kind == "placed" and e.portal == 1)
    assert b_center[1] == pytest.approx(6.0, abs=1e-6)
    path = np.array(positions[travelled_at:travelled_at + 12])
    step = np.diff(path, axis=0) / DT
    # In the air: moving -X at walking speed (it went in moving +Z), no Z, falling faster each frame.
    assert np.allclose(step[1:8, 0], -WALK_SPEED, atol=0.05), step[:8]
    assert np.allclose(step[1:8, 2], 0.0, atol=0.05)
    assert np.allclose(np.diff(step[1:8, 1]), -GRAVITY * DT, atol=1e-3)
    # It lands on the ledge (feet at 3 m), the far side of the room from where it went in.
    assert p.eye.y - EYE_HEIGHT == pytest.approx(3.0, abs=0.01)
    assert 3.0 < p.eye.x < 6.0 and p.body.on_ground


def test_restart_puts_everything_back(play):
    level = LEVELS[0]
    fresh = play(level, ["wait 1"])
    first = fresh.frame()
    p = play(level)
    for _ in range(80):  # portals placed, through them, onto the ledge
        p.frame(render=False)
    assert "travelled" in p.game.event_kinds()
    p.pilot = Autopilot(["press r"])
    frame = p.frame()
    assert p.game.event_kinds()[-1] == "restart"
    start = p.game.rules.start
    assert glm.length(p.eye - glm.vec3(start[0], start[1] + EYE_HEIGHT, start[2])) < 1e-3  # standing at the start
    assert not p.game.won and p.game.placed == [None, None]
    for portal in p.game.portals:
        assert not p.world.get(portal, Portal).enabled and not p.world.get(portal, MeshRef).visible
    assert len(p.world.entities()) == len(fresh.world.entities())
    # The frame after the restart is the first frame of a fresh game.
    diff = np.abs(frame.astype(int) - first.astype(int))
    _save(np.concatenate([first, frame, (diff * 40).clip(0, 255).astype(np.uint8)], axis=1), "restart_diff.png")
    assert diff.max() <= 2, diff.max()
    # And the level plays again from there.
    p.pilot = Autopilot(p.game.rules.solution)
    p.run_script(render=False)
    assert p.game.event_kinds().count("win") == 1


@pytest.mark.parametrize("rules, words", [
    ({"start": [0, 0, 0]}, "'exit' is missing"),
    ({"exit": "nowhere", "start": [0, 0, 0]}, "'exit' must name an entity"),
    ({"exit": "pad"}, "'start' is missing"),
    ({"exit": "pad", "start": [0, 0]}, "'start' must be a list of 3 numbers"),
    ({"exit": "pad", "start": [0, 0, 0], "portal_walls": ["wall", "ghost"]}, "'ghost', which is no entity"),
    ({"exit": "pad", "start": [0, 0, 0], "kill_y": 5}, "'kill_y' must be below the start"),
    ({"exit": "pad", "start": [0, 0, 0], "portal_size": [0.4, 2.0]}, "'portal_size' must"),
    ({"exit": "pad", "start": [0, 0, 0], "pitch": 95}, "'pitch' must be a number in [-89, 89]"),
    ({"exit": "pad", "start": [0, 0, 0], "speed": 3}, "'speed' is not a portal_run rule"),
    ({"exit": "pad", "start": [0, 0, 0], "solution": ["fly 1 2"]}, "unknown command 'fly'"),
    ({"exit": "pad", "start": [0, 0, 0], "solution": ["aim 1 2"]}, "aim takes 3 argument(s), got 2"),
])
def test_bad_rules_are_named(rules, words):
    with pytest.raises(LevelRulesError) as info:
        load_rules(rules, {"pad": 1, "wall": 2}, "level file 'x.toml'")
    assert words in str(info.value) and "x.toml" in str(info.value)


@pytest.mark.parametrize("change, words", [
    (('exit = "pad"', 'exit = "sun"'), "rule 'exit' names 'sun', which has no MeshRef"),
    (('portal_walls = ["wall"]', 'portal_walls = ["wall", "pad"]\nnot_solid = ["pad"]'),
     "rule 'portal_walls' names 'pad', which is not solid"),
])
def test_rules_that_need_the_spawned_level_are_named(ctx, tmp_path, change, words):
    level = tmp_path / "bad.toml"
    level.write_text(SMALL_LEVEL.replace(*change))
    with pytest.raises(LevelRulesError) as info:
        Engine(PortalRun(level, verbose=False), ctx)
    assert words in str(info.value) and "bad.toml" in str(info.value)


def test_a_broken_level_file_is_the_loaders_error_naming_file_and_line(tmp_path):
    level = tmp_path / "broken.toml"
    level.write_text(SMALL_LEVEL.replace("[entity.Material]\ncolor = [0.6, 0.4, 0.2, 1.0]",
                                         "[entity.Material]\ncolour = [0.6, 0.4, 0.2, 1.0]"))
    with pytest.raises(LevelError) as info:
        PortalRun(level, verbose=False)
    text = str(info.value)
    assert "broken.toml" in text and "'crate'" in text and "colour" in text
    line = int(text.split("broken.toml:")[1].split(":")[0])
    assert level.read_text().splitlines()[line - 1].startswith("colour")


def test_bad_script_steps_are_named():
    with pytest.raises(ScriptError, match="step 2 'hold w 0'"):
        Autopilot(["wait 1", "hold w 0"])
    with pytest.raises(ScriptError, match="click takes left or right"):
        Autopilot(["click middle"])


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "games.portal_run", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)


def test_command_line_runs_a_level_file_headless_and_names_a_bad_one(tmp_path):
    out = tmp_path / "frames"
    result = _cli("--headless", "--frames", "3", "--size", "96x54", "--out", str(out), "--level", str(LEVELS[2]))
    assert result.returncode == 0, result.stderr
    assert sorted(f.name for f in out.iterdir()) == ["frame_0000.png", "frame_0001.png", "frame_0002.png"]
    bad = tmp_path / "bad.toml"
    bad.write_text(LEVELS[0].read_text().replace('exit = "exit_pad"', 'exit = "exit_door"'))
    result = _cli("--headless", "--frames", "1", "--out", str(out), "--level", str(bad))
    assert result.returncode == 2
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("speculum: error:"), result.stderr
    assert "bad.toml" in lines[0] and "'exit'" in lines[0] and "exit_door" in lines[0]


def test_level_files_are_in_rising_order_and_ship_a_solution():
    assert [p.name for p in LEVELS] == ["01_first_jump.toml", "02_round_the_corner.toml", "03_two_hops.toml",
                                        "04_the_fling.toml", "05_lamp_through_a_portal.toml"]
    for path in LEVELS:
        assert PortalRun(path, verbose=False).level.rules.get("solution"), path


WINDOW_SCRIPT = r'''
import json, sys

import moderngl_window as mglw
from pyglet.window import key, mouse

from components import Transform
from shell.window import make_window_config
from games.portal_run import PortalRun

game = PortalRun(sys.argv[1], verbose=False)
config = mglw.create_window_config_instance(make_window_config(game), args=["--window", "pyglet", "--size", "192x108"])
window = config.wnd._window
world = config.engine.world
errors = []

def frame():
    config.on_render(0.0, 1 / 60)
    config.wnd.swap_buffers()
    errors.append(config.ctx.error)

def click(button):
    # As the X server delivers it: through pyglet's queue to the shell.
    window.dispatch_event("on_mouse_press", 96, 54, button, 0)
    window.dispatch_event("on_mouse_release", 96, 54, button, 0)
    window.dispatch_events()
    frame()

frame()
frame()
click(mouse.LEFT)  # takes the pointer for mouse look; fires nothing
first = {"captured": config.mouse_captured, "events": len(game.events)}
window.dispatch_event("on_mouse_motion", 96, 54, 1200, 0)  # 1200 px at 0.15 degrees a pixel: half a turn
window.dispatch_events()
frame()
yaw = game.player_view()[1]
click(mouse.LEFT)  # portal A where the player looks: the front wall behind the start
placed = [e.detail for e in game.events if e.kind == "placed"]
z0 = world.get(game.player, Transform).position.z
window.dispatch_event("on_key_press", key.W, 0)
window.dispatch_events()
for _ in range(30):
    frame()
window.dispatch_event("on_key_release", key.W, 0)
window.dispatch_events()
frame()
z1 = world.get(game.player, Transform).position.z
print(json.dumps({"errors": errors, "first": first, "yaw": yaw, "placed": placed, "walked": z1 - z0}))
config.on_close()
config.wnd.destroy()
'''


def test_played_in_a_real_window_with_mouse_look_clicks_and_keys(x_display, tmp_path):
    """Level 1 in an X window (Xvfb, pyglet): the first click only takes the pointer, mouse
    motion turns the player half round, the next click puts portal A on the wall it looks
    at, W walks; no GL error in any frame.  Skipped, saying why, without Xvfb or pyglet."""
    env = {**os.environ, "DISPLAY": x_display, "PYTHONPATH": str(ROOT), "SPECULUM_DEBUG": "1"}
    result = subprocess.run([sys.executable, "-c", WINDOW_SCRIPT, str(LEVELS[0])], cwd=tmp_path, env=env,
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads(result.stdout.strip().splitlines()[-1])
    assert set(report["errors"]) == {"GL_NO_ERROR"}
    assert report["first"] == {"captured": True, "events": 0}
    assert abs(abs(report["yaw"]) - 180.0) < 1e-3
    assert report["placed"] == ["portal A on front_wall"]
    assert report["walked"] == pytest.approx(WALK_SPEED * 30 / 60, abs=0.1)


SMALL_LEVEL = """
[level]
name = "test: a wall, a crate, a pit"
game = "portal_run"
[rules]
exit = "pad"
start = [0, 0, 0]
portal_walls = ["wall"]
kill_y = -5
[[entity]]
name = "sun"
[entity.DirectionalLight]
direction = [-0.4, -1.0, -0.3]
intensity = 2.5
[[entity]]
name = "floor"
[entity.Transform]
position = [0, -0.1, -2]
[entity.MeshRef]
mesh = { box = [8, 0.2, 8] }
[entity.Material]
color = [0.7, 0.7, 0.7, 1.0]
[[entity]]
name = "wall"
[entity.Transform]
position = [0, 2, -6.2]
[entity.MeshRef]
mesh = { box = [8, 4, 0.4] }
[entity.Material]
color = [0.8, 0.8, 0.8, 1.0]
[[entity]]
name = "crate"
[entity.Transform]
position = [0, 0.5, -5.5]
[entity.MeshRef]
mesh = { box = [1, 1, 1] }
[entity.Material]
color = [0.6, 0.4, 0.2, 1.0]
[[entity]]
name = "pad"
[entity.Transform]
position = [0, 3.05, -20]
[entity.MeshRef]
mesh = { box = [1, 0.1, 1] }
[entity.Material]
color = [0.1, 0.9, 0.3, 1.0]
"""


def test_a_portal_over_a_crate_is_refused_and_falling_off_the_level_restarts(play, tmp_path):
    level = tmp_path / "small.toml"
    level.write_text(SMALL_LEVEL)
    # Aimed at the wall just above the crate: the portal (2 m high, slid onto the face from
    # y = 0) would have its lower corners behind the crate, whose front is 0.5 m off the wall.
    p = play(level, ["aim 0 1.4 -6", "click left", "aim 3 1.4 -6", "click left"])
    p.run_script(render=False)
    kinds = [(e.kind, e.detail) for e in p.game.events]
    assert kinds[0] == ("refused", "portal A: crate is in front of wall there"), kinds
    assert kinds[1] == ("placed", "portal A on wall")  # clear of the crate, it fits
    # Walk off the floor's edge (z = 2): below kill_y the level restarts, the player at the start.
    p.pilot = Autopilot(["look 180 0", "hold w 300"])
    for _ in range(300):
        p.frame(render=False)
        if p.game.events[-1].kind == "fell":
            break
    assert p.game.events[-1].kind == "fell"
    assert p.game.placed == [None, None]
    assert glm.length(p.eye - glm.vec3(0, EYE_HEIGHT, 0)) < 0.5


def test_a_solid_turned_off_the_world_axes_is_reported_once_a_build(play, tmp_path):
    """The body's physics is axis-aligned, so a crate turned 30 degrees collides as its
    world-axis box: the game says so, naming the crate, when it first moves the body (and
    again after a restart rebuilds the level), and says nothing of quarter turns."""
    import warnings as warnings_module

    from games.portal_run.game import CoarseCollisionWarning

    crate = "position = [0, 0.5, -5.5]"
    turned = tmp_path / "turned.toml"
    turned.write_text(SMALL_LEVEL.replace(crate, crate + "\nrotation = { yaw = 30 }"))
    quarter = tmp_path / "quarter.toml"
    quarter.write_text(SMALL_LEVEL.replace(crate, crate + "\nrotation = { yaw = 90 }"))
    for level, expected in ((turned, ["'crate'"]), (quarter, [])):
        p = play(level, ["hold w 3"])
        with warnings_module.catch_warnings(record=True) as caught:
            warnings_module.simplefilter("always")
            p.run_script(render=False)
            p.game.restart(p.engine.world)
            p.frame(render=False)
        found = [str(w.message) for w in caught if issubclass(w.category, CoarseCollisionWarning)]
        assert len(found) == (2 if expected else 0), found
        for text in found:
            assert all(name in text for name in expected) and "'wall'" not in text and level.name in text


def test_a_fast_body_does_not_tunnel_through_a_thin_wall_and_rests_on_a_floor():
    from games.portal_run.physics import BodyShape, Solid, move_body

    shape = BodyShape.standing(HALF_WIDTH, 1.8, EYE_HEIGHT)
    wall = Solid(1, np.array([2.0, -5.0, -5.0]), np.array([2.05, 5.0, 5.0]))  # 5 cm thick, face at x = 2
    floor = Solid(2, np.array([-50.0, -1.0, -50.0]), np.array([50.0, 0.0, 50.0]))
    # 150 m/s for one frame is 2.5 m: past the wall in one step without sub-steps.
    moved = move_body((0.0, EYE_HEIGHT + 0.5, 0.0), (150.0, 0.0, 0.0), 1 / 60, shape, [wall, floor])
    assert moved.position[0] + HALF_WIDTH == pytest.approx(2.0, abs=1e-3) and moved.velocity[0] == 0.0
    assert moved.blocked == {1} and not moved.on_ground
    # Falling onto the floor: the feet stop at its top, the fall's speed is gone, on the ground.
    moved = move_body((0.0, EYE_HEIGHT + 0.05, 0.0), (0.0, -20.0, 0.0), 1 / 60, shape, [wall, floor])
    assert moved.position[1] - EYE_HEIGHT == pytest.approx(0.0, abs=1e-3)
    assert moved.velocity[1] == 0.0 and moved.on_ground
    # A wall that is passable (a portal's opening) lets it through.
    moved = move_body((0.0, EYE_HEIGHT + 0.5, 0.0), (150.0, 0.0, 0.0), 1 / 60, shape, [wall, floor],
                      passable=lambda entity, lo, hi: entity == 1)
    assert moved.position[0] == pytest.approx(2.5, abs=1e-6)


def _autoplay(ctx, level: Path, dt: float, seconds: float = 20.0, script=None) -> tuple[PortalRun, Engine, int]:
    """The game's own autopilot plays ``level`` at ``dt`` a frame (no frames drawn) until it
    wins or ``seconds`` of game time pass; returns the game, its engine and the frames run."""
    game = PortalRun(level, autopilot=True, script=script, verbose=False)
    engine = Engine(game, ctx)
    frames = 0
    while "win" not in game.event_kinds() and frames * dt < seconds and not (script and game.pilot.done):
        engine.frame(dt, None)
        frames += 1
    return game, engine, frames


def test_the_body_physics_is_a_system_before_the_rules_and_travel(play):
    """``PortalRun.systems()``: "physics" runs right after the game stage and before the rules
    stage (so before travel), so a step that completes the pair opens it in the same frame's
    rules (travel, views and slicing act on it at once)."""
    p = play(LEVELS[0])
    names = [name for name, _ in p.engine.schedule]
    assert names[:5] == ["game", "physics", "models", "rules", "input"]
    assert names.index("physics") < names.index("travel")
    placed = 0
    while placed < 2:
        assert not p.pilot.done, "the solution places both portals"
        p.frame(render=False)
        placed = p.game.event_kinds().count("placed")
    assert set(p.world.resources[FrameRules].open_portals) == set(p.game.portals), "open in the frame it was placed"


@pytest.mark.parametrize("level", LEVELS, ids=[p.stem for p in LEVELS])
def test_every_level_is_won_at_a_slow_frame_rate_as_at_60(ctx, level):
    """The body moves in fixed physics steps and the autopilot gives input every 1/60 s of game
    time, so a level plays the same at --dt 0.1 as at 1/60 (the fling was never completed at
    0.1: one gravity step a frame fell short of the ledge, and 'hold w 20' was two seconds)."""
    won_at = {}
    for dt in (1.0 / 60.0, 0.1):
        game, engine, frames = _autoplay(ctx, level, dt)
        try:
            kinds = game.event_kinds()
            assert kinds.count("win") == 1 and "fell" not in kinds and "restart" not in kinds, (dt, game.events)
            won_at[dt] = frames * dt
        finally:
            engine.close()
    assert won_at[0.1] == pytest.approx(won_at[1.0 / 60.0], abs=0.15), won_at


def test_the_body_moves_the_same_whatever_the_frame_time(ctx):
    """A run and a jump played at 1/60, 0.1 and 0.05 s a frame: after the same game time the
    eye is in the same place (the same fixed steps ran)."""
    script = ["look 90 0", "press space", "hold w+a 59"]  # 1 s of game time from the press on
    eyes = {}
    for dt in (1.0 / 60.0, 0.1, 0.05):
        game, engine, frames = _autoplay(ctx, LEVELS[0], dt, seconds=1.02, script=script)
        try:
            eyes[dt] = np.array(engine.world.get(game.player, Transform).position)
        finally:
            engine.close()
    start = np.array([0.0, EYE_HEIGHT, 3.0])
    assert np.linalg.norm(eyes[1.0 / 60.0] - start) > 3.0  # it did move
    for dt in (0.1, 0.05):
        np.testing.assert_allclose(eyes[dt], eyes[1.0 / 60.0], atol=1e-9)


def test_n_after_a_win_plays_the_next_level_in_the_same_world(play, capsys):
    p = play(LEVELS[0])
    p.game.verbose = True
    p.run_script(render=False)
    assert p.game.won
    said = capsys.readouterr().out
    assert "level complete: Portal run 1: first jump" in said and "press n for the next level" in said
    p.pilot = Autopilot(["press n", "wait 2"])
    p.run_script(render=False)
    assert p.game.level_path == LEVELS[1] and p.game.level.name == "Portal run 2: round the corner"
    assert p.game.event_kinds()[-1] == "next" and not p.game.won and p.game.placed == [None, None]
    start = p.game.rules.start
    assert glm.length(p.eye - glm.vec3(start[0], start[1] + EYE_HEIGHT, start[2])) < 1e-2
    assert "next level: Portal run 2" in capsys.readouterr().out
    # And the next level plays from there to its own win.
    p.pilot = Autopilot(p.game.rules.solution)
    p.run_script(render=False)
    assert p.game.won


def _floor_hits(view, size) -> np.ndarray:
    """Where each pixel's primary ray meets the plane y = 0 (rows of the flattened image)."""
    from tests.support import pixel_rays

    eye, rays = pixel_rays(view, size)
    t = -eye[1] / rays[..., 1]
    return (eye + rays * t[..., None]).reshape(-1, 3)


def test_a_lamp_lights_the_dark_room_through_a_portal_pair(ctx):
    """Level 5 at night: the lamp is in a closet behind the left wall (it casts shadows: the
    wall keeps its own light out);
    the closet's portal carries its light out of the skylight high on the left wall.  Looking
    at the floor below it, float64 rays predict which floor pixels the lamp's image lights
    (the line from the point to the lamp carried by the pair crosses the skylight's opening,
    within range) and the frame agrees on 98% of the floor outside a band at the edge; with
    the closet portal's carries_light off no floor pixel is brighter than the night's."""
    from components import Portal as PortalComponent
    from engine.core.portal_math import pair_transform
    from tests.support import srgb_to_linear

    size = (240, 135)
    level = next(p for p in LEVELS if p.stem == "05_lamp_through_a_portal")
    game = PortalRun(level, verbose=False, show_caption=False)
    engine = Engine(game, ctx)
    capture = CaptureTarget(ctx, size)
    # The floor's reflection of the night sky adds the same to both frames and blurs their
    # ratio where the lamp's light is weak: the floor reflects none here.
    engine.world.get(game.names["floor"], Material).environment_reflection = 0.0
    try:
        pilot = Autopilot(["look 60 -20", "wait 3"])
        while not pilot.done:
            pilot.fill(engine.world.resources[Input], game)
            engine.frame(DT, Output(capture.framebuffer, size))
        on = capture.read_rgb()
        assert engine.renderer.stats.virtual_lights == 1 and engine.renderer.stats.virtual_lights_cut == 0
        floor = (engine.renderer.targets.read_ids() == game.names["floor"]).reshape(-1)
        closet = engine.world.get(game.names["closet_portal"], PortalComponent)
        closet.carries_light = False
        engine.frame(DT, Output(capture.framebuffer, size))
        off = capture.read_rgb()
        assert engine.renderer.stats.virtual_lights == 0
        points = _floor_hits(engine.main_view, size)
        world = engine.world
        carry = glm.dmat4(pair_transform(world.get(game.names["closet_portal"], Transform).world,
                                         world.get(game.names["skylight"], Transform).world))
        lamp = np.array(world.get(game.names["lamp"], Transform).position, np.float64)
        image = np.array(glm.dvec3(carry * glm.dvec4(*lamp, 1.0)))
    finally:
        capture.release()
        engine.close()
    # The skylight: facing +x at x = -5.99, 1.6 m wide (z) and 2 m tall (y), centred at y = 5, z = 0.
    to_image = image - points
    t = (-5.99 - points[:, 0]) / to_image[:, 0]
    crossing = points + to_image * t[:, None]
    distance = np.linalg.norm(to_image, axis=1)

    def lit(margin):
        return (points[:, 0] > -5.99) & (t > 0) & (t < 1) & (np.abs(crossing[:, 1] - 5.0) < 1.0 - margin) & \
            (np.abs(crossing[:, 2]) < 0.8 - margin) & (distance < 16.0)

    ratio = (srgb_to_linear(on).mean(-1) / np.maximum(srgb_to_linear(off).mean(-1), 1e-6)).reshape(-1)
    sure = floor & (lit(0.05) == lit(-0.05))
    says = np.where(ratio > 1.2, 1, np.where(ratio < 1.02, 0, -1))[sure]
    rays = lit(0.05)[sure].astype(int)
    assert sure.sum() > 10000 and rays.sum() > 3000, (int(sure.sum()), int(rays.sum()))
    assert float((says == rays).mean()) >= 0.98, float((says == rays).mean())
    assert srgb_to_linear(off).reshape(-1, 3)[floor].mean() < 0.05, "the room is dark without the portal's light"


def test_placed_portals_carry_light_unless_the_rules_say_not(ctx, tmp_path):
    """Level 1's sun goes into portal B (on the back wall, which the sun falls on) and out of
    portal A, and its fill light into A and out of B: with both placed, a virtual light for
    each light travelling towards a placed portal's front (counted here from the placed
    portals' normals); with ``portal_light = false`` in the rules the placed portals carry none."""
    from components import DirectionalLight

    for light, text in ((True, LEVELS[0].read_text()),
                        (False, LEVELS[0].read_text().replace("kill_y = -10", "kill_y = -10\nportal_light = false"))):
        level = tmp_path / f"light_{light}.toml"
        level.write_text(text)
        game = PortalRun(level, verbose=False, show_caption=False)
        engine = Engine(game, ctx)
        try:
            pilot = Autopilot(list(game.rules.solution[:4]) + ["wait 2"])
            while not pilot.done:
                pilot.fill(engine.world.resources[Input], game)
                engine.frame(DT, None)
            assert all(p is not None for p in game.placed)
            assert [engine.world.get(p, Portal).carries_light for p in game.portals] == [light, light]
            towards = sum(float(np.dot(placed.normal, np.array(sun.direction))) < 0.0
                          for placed in game.placed for _, sun in engine.world.query_one(DirectionalLight))
            assert towards == 2
            assert engine.renderer.stats.virtual_lights == (towards if light else 0)
        finally:
            engine.close()
