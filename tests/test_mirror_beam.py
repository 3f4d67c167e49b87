"""games/mirror_beam: every shipped level solved from scripted key presses (the win event),
the beam's path against plain vector math and the renderer's reflection matrix, the beam on
screen and inside a mirror (pixels and entity ids), restart, click picking, walls and the
bounce limit, and bad rules as clear errors.  Frames are real llvmpipe renders."""
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

from components import Emissive, MeshRef, Mirror, Transform
from engine.core.frame_io import Input, Output
from engine.core.reflection_math import plane_from_point_normal, reflection_matrix
from engine.render.targets import CaptureTarget
from engine.resources import Surfaces
from games.mirror_beam import BeamState, LevelRulesError, MirrorBeam, levels
from games.mirror_beam.beam import trace_beam
from games.mirror_beam.game import BARREL_LENGTH, BeamSegment, MirrorFrame, laser_front
from shell.app import Engine
from shell.capture import save_png

try:
    import tomllib
except ImportError:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
LEVELS = levels()
BOUNCES = {"01_one_bounce": 1, "02_two_bounces": 2, "03_sixty_degrees": 2, "04_around_the_wall": 3,
           "05_four_bounces": 4}
FRAMES_DIR = Path(os.environ.get("MIRROR_BEAM_FRAMES", "")) if os.environ.get("MIRROR_BEAM_FRAMES") else None


class BeamRun:
    """A MirrorBeam level on the test context: press keys, render a frame, read it back."""

    def __init__(self, ctx, level: Path, size=(96, 54)) -> None:
        self.game = MirrorBeam(level)
        self.engine = Engine(self.game, ctx)
        self.world = self.engine.world
        self.size = size
        self.capture = CaptureTarget(ctx, size)

    @property
    def state(self) -> BeamState:
        return self.world.resources[BeamState]

    def frame(self, *keys: str, clicks=(), mouse=None) -> np.ndarray:
        inp = self.world.resources[Input]
        inp.press(*keys)
        inp.clicks.update(clicks)
        if mouse is not None:
            inp.mouse = mouse
        self.engine.frame(1 / 60, Output(self.capture.framebuffer, self.size))
        inp.release(*keys)
        return self.capture.read_rgb()

    def project(self, point) -> tuple[float, float]:
        clip = self.engine.main_view.view_proj * glm.vec4(glm.vec3(point), 1.0)
        ndc = glm.vec3(clip) / clip.w
        w, h = self.size
        return (ndc.x * 0.5 + 0.5) * w, (1.0 - (ndc.y * 0.5 + 0.5)) * h

    def close(self) -> None:
        self.capture.release()
        self.engine.close()


@pytest.fixture
def run(ctx):
    runs: list[BeamRun] = []

    def make(level: Path, size=(96, 54)) -> BeamRun:
        runs.append(BeamRun(ctx, level, size))
        return runs[-1]

    yield make
    for r in runs:
        r.close()


def level_file(stem: str) -> Path:
    return next(p for p in LEVELS if p.stem == stem)


def solution_keys(path: Path) -> list[str]:
    """The level's solution as key presses, read from the file (mirror's number, then turns)."""
    rules = tomllib.loads(path.read_text())["rules"]
    keys = []
    for name, steps in rules["solution"].items():
        keys.append(str(rules["rotatable"].index(name) + 1))
        keys += ["left" if steps > 0 else "right"] * abs(steps)
    return keys


def mirror_pose(path: Path, name: str) -> tuple[glm.vec3, float]:
    """(position, yaw degrees after the solution) of a mirror, from the level file alone."""
    data = tomllib.loads(path.read_text())
    table = next(e for e in data["entity"] if e["name"] == name)
    steps = data["rules"].get("solution", {}).get(name, 0)
    yaw = table["Transform"]["rotation"]["yaw"] + steps * data["rules"]["step"]
    return glm.vec3(table["Transform"]["position"]), yaw


def test_five_levels_ship_and_rise_in_bounces():
    assert [p.stem for p in LEVELS] == list(BOUNCES)


@pytest.mark.parametrize("stem", list(BOUNCES))
def test_each_level_is_won_by_its_scripted_key_presses(run, stem, tmp_path):
    path = level_file(stem)
    r = run(path)
    r.frame()
    r.frame()
    assert r.state.path is not None and r.state.path.end != "target", "the level starts unsolved"
    keys = solution_keys(path)
    for key in keys[:-1]:
        r.frame(key)
        assert not r.state.wins(), f"won before the last key of {keys}"
    first = r.frame(keys[-1])  # the beam drawn with a frame's mirrors: the last turn wins in its own frame
    assert len(r.state.wins()) == 1 and r.state.wins()[0].frame == r.state.frame - 1
    last = r.frame()
    wins = r.state.wins()
    assert len(wins) == 1 and wins[0].detail["level"].startswith("Mirror beam")
    assert r.state.path.end == "target" and len(r.state.path.bounces) == BOUNCES[stem]
    assert r.world.get(r.state.rules.target, Emissive).power > 1.0, "the target glows"
    # A won level keeps still: further arrows do nothing, the win is recorded once.
    r.frame("left")
    r.frame()
    assert len(r.state.wins()) == 1 and r.state.path.end == "target"
    for name, image in (("won_a", first), ("won_b", last)):
        save_png(image, (FRAMES_DIR or tmp_path) / f"{stem}_{name}.png")


def test_beam_bounces_as_plain_vector_math_and_the_renderers_reflection_matrix(run):
    """Level 4 solved: each bounce point is the line-plane intersection with the mirror as
    the file places it, each outgoing direction is d - 2(d.n)n, and the renderer's reflection
    matrix of that plane takes the previous corner of the path onto the outgoing ray's
    backward extension (the mirror image the renderer draws lies on the reflected beam)."""
    path = level_file("04_around_the_wall")
    r = run(path)
    for key in [None, *solution_keys(path), None, None]:
        r.frame(*([key] if key else []))
    beam = r.state.path
    assert beam.end == "target"
    names = {entity: name for name, entity in r.game.names.items()}
    o = glm.vec3(-4.0, 1.0, 2.0)  # the laser's position in the file
    d = glm.vec3(1.0, 0.0, 0.0)   # it looks along +X
    for bounce in beam.bounces:
        p, yaw = mirror_pose(path, names[bounce.mirror])
        n = glm.vec3(math.sin(math.radians(yaw)), 0.0, math.cos(math.radians(yaw)))
        t = glm.dot(p - o, n) / glm.dot(d, n)
        hit = o + t * d
        assert glm.distance(hit, bounce.point) < 1e-4
        out = d - 2.0 * glm.dot(d, n) * n
        assert glm.distance(out, bounce.outgoing) < 1e-5
        m = reflection_matrix(plane_from_point_normal(p, n))
        drawn = r.world.resources[Surfaces].mirrors[bounce.mirror].carry  # what the renderer reflects with
        assert max(abs(drawn[c][k] - m[c][k]) for c in range(4) for k in range(4)) < 1e-5
        image = glm.vec3(m * glm.vec4(o, 1.0))
        assert glm.distance(glm.normalize(hit - image), out) < 1e-4
        assert glm.distance(glm.vec3(m * glm.vec4(hit, 1.0)), hit) < 1e-4
        o, d = hit, out
    # Three bounces, then straight onto the target's box (0.6 wide at (3.5, 1, 2)): its near face.
    assert [names[b.mirror] for b in beam.bounces] == ["m1", "m2", "m3"]
    assert glm.distance(beam.points[-1], glm.vec3(3.5, 1.0, 2.0 - 0.3)) < 1e-4


def test_a_wall_stops_the_beam_and_the_bounce_limit_is_kept(run, tmp_path):
    r = run(level_file("04_around_the_wall"))
    for key in [None, "left", "left", "left", "left", "left", "left", None, None]:
        r.frame(*([key] if key else []))  # m1 from -90 to 0 degrees: edge-on, the beam passes it
    beam = r.state.path
    assert beam.end == "solid" and beam.stopped_by == r.game.names["wall"]
    assert not beam.bounces
    assert abs(beam.points[-1].x - 0.8) < 1e-4  # the wall's face: x = 1.0 - 0.4 / 2

    for key in ["left"] * 6 + [None, None]:
        r.frame(*([key] if key else []))  # m1 at 90 degrees: its back to the laser
    m1 = r.game.names["m1"]
    beam = r.state.path
    assert beam.end == "solid" and not beam.bounces and beam.stopped_by != m1  # the frame behind m1
    assert r.world.get(beam.stopped_by, MirrorFrame).mirror == m1
    bare = trace_beam(glm.vec3(-4.0, 1.0, 2.0), glm.vec3(1.0, 0.0, 0.0), r.world.resources[Surfaces].mirrors.values(),
                      lambda origin, direction, leave_out: None, r.state.rules.target, 8)
    assert bare.end == "back" and bare.stopped_by == m1 and abs(bare.points[-1].x + 2.0) < 1e-4

    text = level_file("02_two_bounces").read_text().replace("max_bounces = 8", "max_bounces = 1")
    limited = tmp_path / "limited.toml"
    limited.write_text(text)
    r = run(limited)
    for key in [None, *solution_keys(limited), None, None]:
        r.frame(*([key] if key else []))
    assert r.state.path.end == "limit" and len(r.state.path.bounces) == 1 and not r.state.wins()
    assert r.state.path.stopped_by == r.game.names["m2"]


def red(pixel) -> bool:
    r, g, b = (int(c) for c in pixel)
    return r > 150 and r - g > 70 and r - b > 70


def test_the_beam_is_drawn_emissive_and_seen_inside_a_mirror(run):
    """Level 1 solved, 320x180: where each beam segment projects the frame is the beam's red
    and the id image names a beam segment; and inside m1 (its outline, seen from the front)
    the reflection of the incoming segment is red too, with m1 as the surface id and a beam
    segment as the entity seen: the beam is in the mirror's picture, not only in the room."""
    path = level_file("01_one_bounce")
    r = run(path, size=(320, 180))
    for key in [None, *solution_keys(path), None]:
        image = r.frame(*([key] if key else []))
    ids, surfaces = r.engine.renderer.targets.read_ids(), r.engine.renderer.targets.read_surface_ids()
    segments = {e for e, _ in r.world.query_one(BeamSegment)}
    beam = r.state.path
    # The laser's barrel (around the beam's first stretch, games/mirror_beam/game.py) hides it there.
    barrel_end = laser_front(r.world, r.state.rules) + BARREL_LENGTH + 0.05
    direct = skipped = 0
    for a, b in zip(beam.points[:-1], beam.points[1:], strict=True):
        for f in np.linspace(0.2, 0.8, 7):
            if glm.distance(a + float(f) * (b - a), beam.points[0]) < barrel_end:
                skipped += 1
                continue
            x, y = r.project(a + float(f) * (b - a))
            near = [(int(y) + dy, int(x) + dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
            assert any(red(image[p]) for p in near), f"no beam colour near {x:.0f},{y:.0f}"
            assert any(ids[p] in segments for p in near)
            direct += 1
    assert direct + skipped == 14 and direct >= 12
    # The incoming segment's mirror image through m1's plane, sampled where it shows inside m1.
    m1 = r.game.names["m1"]
    p, yaw = mirror_pose(path, "m1")
    n = glm.vec3(math.sin(math.radians(yaw)), 0.0, math.cos(math.radians(yaw)))
    eye = r.engine.main_view.eye
    assert glm.dot(eye - p, n) > 0, "the camera sees m1's front"
    m = reflection_matrix(plane_from_point_normal(p, n))
    seen = 0
    for f in np.linspace(0.5, 0.97, 24):
        point = beam.points[0] + float(f) * (beam.points[1] - beam.points[0])
        image_point = glm.vec3(m * glm.vec4(point, 1.0))
        crossing = eye + (image_point - eye) * (glm.dot(p - eye, n) / glm.dot(image_point - eye, n))
        local = crossing - p
        if abs(local.y) > 0.45 or glm.length(local - glm.vec3(0, local.y, 0)) > 0.55:
            continue  # outside the mirror's 1.2 x 1.0 outline (with a margin)
        x, y = r.project(image_point)
        near = [(int(y) + dy, int(x) + dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
        if all(surfaces[q] != m1 for q in near):
            continue
        assert any(red(image[q]) and surfaces[q] == m1 and ids[q] in segments for q in near), \
            f"the beam's reflection is not at {x:.0f},{y:.0f} inside m1"
        seen += 1
    assert seen >= 3, "too few samples of the beam's reflection land inside m1"


def test_frame_0_shows_the_beam(run):
    """The beam is a game system after the surfaces stage and before extract
    (``MirrorBeam.systems``), so the very first frame draws it: its segments are posed with
    their world matrices worked out again before extract ("transform_late"), each visible
    segment's entity id is in frame 0's id image where the segment projects, its pixels are
    the beam's red, and frame 0 is the same picture as frame 1."""
    path = level_file("01_one_bounce")
    r = run(path, size=(320, 180))
    names = [name for name, _ in r.engine.schedule]
    assert names[names.index("surfaces"):names.index("extract") + 1] == ["surfaces", "beam", "transform_late",
                                                                         "detail", "decals", "extract"]
    first = r.frame()
    assert r.world.frame_index == 1 and r.state.frame == 1
    beam = r.state.path
    assert beam is not None and len(beam.points) >= 3, "traced in frame 0 (one bounce off m1 at least)"
    ids = r.engine.renderer.targets.read_ids()
    shown = set(np.unique(ids).tolist())
    segments = {entity for entity, _ in r.world.query(BeamSegment)}
    for entity, (segment, transform) in r.world.query(BeamSegment, Transform):
        drawn = segment.index < len(beam.points) - 1
        assert r.world.get(entity, MeshRef).visible == drawn
        if not drawn:
            assert entity not in shown
            continue
        a, b = beam.points[segment.index], beam.points[segment.index + 1]
        assert glm.distance(glm.vec3(transform.world[3]), (a + b) * 0.5) < 1e-5, "this frame's world matrix"
        if segment.index > 1:
            continue  # the open end leaves the view; the first two segments are in it
        assert entity in shown
        for f in (0.3, 0.5, 0.7):
            x, y = r.project(a + f * (b - a))
            near = [(int(y) + dy, int(x) + dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
            # A beam segment there: this one, or the other where the bounce runs back over it
            # on screen (which of two overlapping thin boxes wins the depth test is the
            # rasteriser's: llvmpipe shows the second, an H200 the first).
            assert any(ids[p] in segments for p in near), f"segment {segment.index} not at {x:.0f},{y:.0f}"
            assert any(red(first[p]) for p in near)
    second = r.frame()
    assert np.abs(second.astype(int) - first.astype(int)).max() <= 2, "frame 0 is the picture frame 1 is"


def test_restart_puts_the_level_back_as_it_started(run):
    path = level_file("02_two_bounces")
    r = run(path)
    r.frame()
    start = r.frame()
    rotations = {e: glm.quat(r.world.get(e, Transform).rotation) for e in r.state.rules.rotatable}
    glow = r.world.get(r.state.rules.target, Emissive).power
    start_path = [glm.vec3(v) for v in r.state.path.points]
    for key in solution_keys(path) + [None]:
        r.frame(*([key] if key else []))
    assert r.state.won and r.state.selected == 1
    won = r.frame()
    r.frame("r")
    r.frame()
    after = r.frame()
    assert not r.state.won and r.state.selected == 0
    assert [e.kind for e in r.state.events].count("restart") == 1
    for e, q in rotations.items():
        assert abs(glm.dot(r.world.get(e, Transform).rotation, q)) > 1 - 1e-6
    assert r.world.get(r.state.rules.target, Emissive).power == glow
    assert all(glm.distance(a, b) < 1e-5 for a, b in zip(r.state.path.points, start_path, strict=True))
    assert np.abs(after.astype(int) - start.astype(int)).max() <= 2, "the frame after restart is the first one"
    assert np.abs(won.astype(int) - start.astype(int)).max() > 50
    # And the level can be won again after a restart.
    for key in solution_keys(path) + [None]:
        r.frame(*([key] if key else []))
    assert len(r.state.wins()) == 2


def test_a_click_on_a_mirror_selects_and_turns_it(run):
    path = level_file("02_two_bounces")
    r = run(path, size=(192, 108))
    r.frame()
    r.frame()
    m2 = r.game.names["m2"]
    before = glm.quat(r.world.get(m2, Transform).rotation)
    x, y = r.project(glm.vec3(-1.0, 1.0, 1.5))
    r.frame(clicks={"left"}, mouse=(x, y))
    assert r.state.rules.rotatable[r.state.selected] == m2
    turned = r.world.get(m2, Transform).rotation
    assert abs(glm.dot(turned, glm.angleAxis(glm.radians(15.0), glm.vec3(0, 1, 0)) * before)) > 1 - 1e-6
    r.frame(clicks={"right"}, mouse=(x, y))
    assert abs(glm.dot(r.world.get(m2, Transform).rotation, before)) > 1 - 1e-6
    r.frame(clicks={"left"}, mouse=(2.0, 2.0))  # the sky: nothing picked, nothing turns
    assert abs(glm.dot(r.world.get(m2, Transform).rotation, before)) > 1 - 1e-6


def bad_level(tmp_path: Path, old: str, new: str) -> Path:
    text = level_file("02_two_bounces").read_text()
    assert old in text
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(old, new))
    return path


@pytest.mark.parametrize(("old", "new", "words"), [
    ('target = "target"', 'target = "nowhere"', ["rules.target", "'nowhere'", "no entity"]),
    ('rotatable = ["m1", "m2"]', 'rotatable = ["m1", "floor"]', ["rules.rotatable", "'floor'", "not a mirror"]),
    ("step = 15", "step = 0", ["rules.step", "(0, 180]"]),
    ("max_bounces = 8", "max_bounces = 99", ["rules.max_bounces", "99"]),
    ("solution = { m1 = 3", "solution = { sun = 3", ["rules.solution", "'sun'", "not in rules.rotatable"]),
    ('source = "laser"', 'source = "laser"\ncolour = 3', ["rules.colour", "not a mirror_beam rule"]),
])
def test_bad_rules_are_errors_naming_the_file_and_the_rule(ctx, tmp_path, old, new, words):
    path = bad_level(tmp_path, old, new)
    with pytest.raises(LevelRulesError) as error:
        Engine(MirrorBeam(path), ctx)
    message = str(error.value)
    assert str(path) in message
    for word in words:
        assert word in message
    assert ctx.error == "GL_NO_ERROR"


@pytest.mark.parametrize("how", ["--headless", "no display"])
def test_command_line_autopilot_writes_frames_of_the_level_solved(tmp_path, how):
    """The headless command plays the solution: the last frame shows the target lit, and the
    win is said in one line.  So does a run with no display, which goes headless (it drew the
    unsolved level before); a bad --level is one 'speculum: error:' line and exit 2."""
    out = tmp_path / "frames"
    flags, env = (["--headless"], os.environ) if how == "--headless" else \
        ([], {**os.environ, "DISPLAY": "", "WAYLAND_DISPLAY": ""})
    done = subprocess.run([sys.executable, "-m", "games.mirror_beam", *flags, "--frames", "7",
                           "--size", "192x108", "--out", str(out), "--level", str(level_file("01_one_bounce")),
                           "--aa", "off"],  # the colours of a 40-pixel target, not its blended rim
                          # (192x108: at 96x54 the level's caption, 16-pixel text, covered the target)
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    solved = [line for line in done.stdout.splitlines() if line.startswith("mirror_beam: solved:")]
    assert solved == ["mirror_beam: solved: Mirror beam 1: one bounce with 1 bounce (frame 4; press n for the next "
                      "level, r to restart)"], done.stdout
    frames = sorted(out.glob("frame_*.png"))
    assert len(frames) == 7
    from PIL import Image

    first, last = (np.asarray(Image.open(f).convert("RGB")).astype(int) for f in (frames[1], frames[-1]))
    target = (first[..., 1] > first[..., 0] + 60)  # the green target's pixels, before the win
    assert target.sum() >= 10
    assert first[target][:, 1].mean() < 230 and last[target][:, 1].mean() > 250, \
        "the target lights up once the autopilot has solved the level"

    bad = bad_level(tmp_path, 'target = "target"', 'target = "nowhere"')
    done = subprocess.run([sys.executable, "-m", "games.mirror_beam", "--headless", "--frames", "1",
                           "--out", str(tmp_path / "bad"), "--level", str(bad)],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines()[-1].startswith("speculum: error:")
    assert "rules.target" in done.stderr and "Traceback" not in done.stderr


def test_n_after_a_win_plays_the_next_level_in_the_same_world(run):
    """Level 1 won, 'n': every entity of level 1 goes, level 2 is built in the same world and
    engine (its mirrors are the renderer's surfaces, the frame shows none of level 1's ids) and
    is won by its own keys (its beam is traced in the frame it is built); 'n' before a win does nothing;
    after the last level comes the first."""
    r = run(level_file("01_one_bounce"))
    r.frame("n")
    assert r.game.level_path == level_file("01_one_bounce")
    for key in [None, *solution_keys(level_file("01_one_bounce")), None]:
        r.frame(*([key] if key else []))
    assert r.state.won
    old = set(r.world.entities())
    r.frame("n")
    assert r.state.path is not None and r.state.path.bounces, "level 2's beam, traced in the frame it is built"
    assert {b.mirror for b in r.state.path.bounces} <= {r.game.names["m1"], r.game.names["m2"]}
    r.frame()
    r.frame()
    assert r.game.level_path == level_file("02_two_bounces") and r.state.level_name == "Mirror beam 2: two bounces"
    assert not r.state.won and not r.state.wins()
    assert not old & set(r.world.entities())
    mirrors = set(r.world.resources[Surfaces].mirrors)
    assert mirrors == {r.game.names["m1"], r.game.names["m2"]}
    seen = set(np.unique(r.engine.renderer.targets.read_ids()).tolist())
    assert not seen & old and seen & set(r.game.names.values())
    for key in [*solution_keys(level_file("02_two_bounces")), None]:
        r.frame(*([key] if key else []))
    assert len(r.state.wins()) == 1

    r.game.level_path = level_file("05_four_bounces")
    assert r.game.next_level() == level_file("01_one_bounce").resolve()


WINDOW_SCRIPT = r'''
import json, sys

import moderngl_window as mglw
import pyglet
from pyglet.window import key, mouse
from pyglm import glm

from components import Transform
from shell.window import make_window_config
from games.mirror_beam import BeamState, MirrorBeam

config = mglw.create_window_config_instance(make_window_config(MirrorBeam(sys.argv[1])),
                                            args=["--window", "pyglet", "--size", "192x108"])
window = config.wnd._window
world = config.engine.world
errors = []

def frame():
    config.on_render(0.0, 1 / 60)
    config.wnd.swap_buffers()
    errors.append(config.ctx.error)

def tap(symbol):
    # As the X server delivers a key: through pyglet's queue to the shell's on_key_event.
    window.dispatch_event("on_key_press", symbol, 0)
    window.dispatch_event("on_key_release", symbol, 0)
    window.dispatch_events()
    frame()

frame()
frame()
state = world.resources[BeamState]
m2 = state.rules.rotatable[1]
before = glm.quat(world.get(m2, Transform).rotation)
clip = config.engine.main_view.view_proj * glm.vec4(world.get(m2, Transform).position, 1.0)
w, h = config.wnd.size
x, y = (clip.x / clip.w * 0.5 + 0.5) * w, (clip.y / clip.w * 0.5 + 0.5) * h  # pyglet: y up
window.dispatch_event("on_mouse_press", int(x), int(y), mouse.LEFT, 0)
window.dispatch_event("on_mouse_release", int(x), int(y), mouse.LEFT, 0)
window.dispatch_events()
frame()
clicked = {"selected": state.selected, "turned_deg": glm.degrees(glm.angle(world.get(m2, Transform).rotation
                                                                            * glm.inverse(before))),
           "captured": config.mouse_captured}
for symbol in [key._1, key.LEFT, key.LEFT, key.LEFT, key._2] + [key.RIGHT] * 4 + [None, None]:
    if symbol is None:
        frame()
    else:
        tap(symbol)
print(json.dumps({"errors": errors, "clicked": clicked, "wins": len(state.wins()), "end": state.path.end}))
config.on_close()
config.wnd.destroy()
'''


def test_played_in_a_real_window_with_keys_and_a_click(x_display, tmp_path):
    """Level 2 in an X window (Xvfb, pyglet): a click on m2 selects and turns it one step and
    leaves the pointer free (no fly camera here); then the number and arrow keys, delivered
    through pyglet's event queue, solve it; no GL error in any frame.  Skipped, saying why,
    without Xvfb or pyglet."""
    env = {**os.environ, "DISPLAY": x_display, "PYTHONPATH": str(ROOT), "SPECULUM_DEBUG": "1"}
    result = subprocess.run([sys.executable, "-c", WINDOW_SCRIPT, str(level_file("02_two_bounces"))], cwd=tmp_path,
                            env=env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads(result.stdout.strip().splitlines()[-1])
    assert set(report["errors"]) == {"GL_NO_ERROR"}
    assert report["clicked"]["selected"] == 1 and abs(report["clicked"]["turned_deg"] - 15.0) < 1e-3
    assert report["clicked"]["captured"] is False
    assert report["wins"] == 1 and report["end"] == "target"


@pytest.mark.parametrize("short", [0, 1])
def test_the_target_lights_up_because_the_lasers_reflected_light_reaches_it(run, short):
    """Level 2 solved (both mirrors turned), then with the second mirror one step short: the
    game's light test (the lamp's virtual lights through the mirrors, the shader's aperture
    test on the CPU, the legs ray cast) says lit, by both mirrors in order, and the level is
    won; one step short, not lit and not won.  The frame agrees (a second path): with the
    target's own glow and the beam hidden, turning the mirrors' light off darkens target
    pixels when lit and changes none when not."""
    path = level_file("02_two_bounces")
    r = run(path, (240, 135))
    keys = solution_keys(path)
    for key in keys[:len(keys) - short]:
        r.frame(key)
    r.frame()
    state = r.state
    rules = state.rules
    assert state.lit == (short == 0) and len(state.wins()) == (short == 0)
    if not short:
        assert list(state.lit_by) == [r.game.names["m1"], r.game.names["m2"]]
    r.world.get(rules.target, Emissive).power = 0.0
    for _, (_, mesh_ref) in r.world.query(BeamSegment, MeshRef):
        mesh_ref.visible = False
    on = r.frame()
    assert r.engine.renderer.stats.virtual_lights >= 2 and r.engine.renderer.stats.virtual_lights_cut == 0
    target = r.engine.renderer.targets.read_ids() == rules.target
    for _, mirror in r.world.query_one(Mirror):
        mirror.reflects_light = False
    off = r.frame()
    brighter = (on.astype(int).sum(-1) - off.astype(int).sum(-1) > 6) & target
    assert target.sum() > 100
    if short:
        assert not brighter.any()
    else:
        assert brighter.sum() > 20, int(brighter.sum())


def test_a_beam_sent_straight_back_stops_on_the_lasers_front_face(run):
    """Level 1 as it starts: m1 at (0, 1, -2) faces -X (yaw -90), square to the laser's beam
    (from (-4, 1, -2) along +X), so d - 2(d.n)n sends it straight back along -X; the laser is
    solid to its own beam once it has left it, so the beam stops on the housing's front face,
    x = -4 + 0.7 / 2 (its box is 0.7 long along the way it looks)."""
    r = run(level_file("01_one_bounce"))
    r.frame()
    beam = r.state.path
    m1 = r.game.names["m1"]
    d, n = glm.vec3(1.0, 0.0, 0.0), glm.vec3(-1.0, 0.0, 0.0)
    back = d - 2.0 * glm.dot(d, n) * n
    assert [b.mirror for b in beam.bounces] == [m1]
    assert glm.distance(beam.bounces[0].outgoing, back) < 1e-5
    assert beam.end == "solid" and beam.stopped_by == r.state.rules.source
    expected = [glm.vec3(-4.0, 1.0, -2.0), glm.vec3(0.0, 1.0, -2.0), glm.vec3(-4.0 + 0.35, 1.0, -2.0)]
    assert len(beam.points) == 3 and all(glm.distance(a, b) < 1e-4 for a, b in zip(beam.points, expected, strict=True))
    assert not r.state.lit and not r.state.wins()


def test_a_beam_passing_beside_a_mirrors_outline_goes_on_past_it(run):
    """Level 1 with m1 (1.2 x 1.0) raised: the beam (y = 1) crosses m1's plane x = 0 at
    (0, 1, -2); raised 0.45 m that point is inside the outline (0.45 < 0.5 below its centre)
    and the beam bounces; raised 1.2 m it is outside, and the beam goes on along +X past the
    mirror and its frame (nothing else stands there: it leaves the level), and the frame
    shows a beam segment beyond the mirror."""
    r = run(level_file("01_one_bounce"), size=(192, 108))
    m1 = r.game.names["m1"]
    segments = {e for e, _ in r.world.query_one(BeamSegment)}
    for raised, bounces in ((0.45, 1), (1.2, 0)):
        r.world.get(m1, Transform).position = (0.0, 1.0 + raised, -2.0)
        r.frame()
        image = r.frame()
        beam = r.state.path
        local = glm.vec3(0.0, 1.0, -2.0) - glm.vec3(0.0, 1.0 + raised, -2.0)  # the crossing, from m1's centre
        assert (abs(local.y) <= 0.5) == bool(bounces)
        assert len(beam.bounces) == bounces, raised
        if bounces:
            assert beam.bounces[0].mirror == m1 and glm.distance(beam.points[1], glm.vec3(0.0, 1.0, -2.0)) < 1e-4
            continue
        assert beam.end == "open" and len(beam.points) == 2
        assert beam.points[1].x > 30.0 and abs(beam.points[1].y - 1.0) < 1e-5 and abs(beam.points[1].z + 2.0) < 1e-5
        ids = r.engine.renderer.targets.read_ids()
        x, y = r.project(glm.vec3(2.0, 1.0, -2.0))  # past the mirror
        near = [(int(y) + dy, int(x) + dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
        # (a thin beam at this size: a pixel wide, its red blended with the floor by FXAA)
        assert any(ids[p] in segments for p in near) and any(int(image[p][0]) - int(image[p][1]) > 20 for p in near)


def _blocked_level_2(r, blocker_at):
    """Level 2 with a tall slab (0.2 x 2.2 x 1.6) standing across the beam's last leg, which
    runs from m2 at (-1, 1, 1.5) along +X to the target's face at x = 3.2, once solved."""
    from components import Material
    from engine.assets.mesh import box

    return r.world.spawn(Transform(position=blocker_at), MeshRef(box((0.2, 2.2, 1.6), name="slab")), Material())


def test_a_solid_on_the_lights_way_keeps_the_target_unlit_until_it_is_moved_away(run, monkeypatch):
    """Level 2 solved with a slab across the last leg: the beam stops on the slab's face
    (x = 1.5 - 0.1) and the laser's light is not said to reach the target (no win).  The slab
    moved off the way (no mirror turned): the next frame's beam reaches the target, the light
    is said to reach it and the level is won; the frame agrees (a second path: with the
    target's glow and the beam hidden, the mirrors' light brightens target pixels).  (The
    light's test was kept from the mirrors' last turn, so a moved solid was not seen: the beam
    drawn onto a lit target, and no win.)"""
    path = level_file("02_two_bounces")
    r = run(path, (192, 108))
    slab = _blocked_level_2(r, (1.5, 1.0, 1.5))
    for key in [None, *solution_keys(path), None]:
        r.frame(*([key] if key else []))
    state = r.state
    assert state.path.end == "solid" and state.path.stopped_by == slab
    assert glm.distance(state.path.points[-1], glm.vec3(1.4, 1.0, 1.5)) < 1e-4
    assert not state.lit and not state.wins()
    # Standing still, the light is not worked out again (the world's change sets are empty).
    import games.mirror_beam.game as beam_game
    worked = []
    light = beam_game.reflected_light
    monkeypatch.setattr(beam_game, "reflected_light", lambda *args: worked.append(1) or light(*args))
    r.frame()   # (last frame's turn is in the transform stage's moved set: at most once more)
    settled = len(worked)
    r.frame()
    r.frame()
    assert settled <= 1 and len(worked) == settled, worked
    r.world.get(slab, Transform).position = (1.5, 1.0, -1.0)  # off the way
    r.frame()
    assert state.path.end == "target"
    assert state.lit and len(state.wins()) == 1, "the light on the target once nothing stands in its way"
    r.world.get(state.rules.target, Emissive).power = 0.0
    for _, (_, mesh_ref) in r.world.query(BeamSegment, MeshRef):
        mesh_ref.visible = False
    on = r.frame()
    target = r.engine.renderer.targets.read_ids() == state.rules.target
    for _, mirror in r.world.query_one(Mirror):
        mirror.reflects_light = False
    off = r.frame()
    brighter = (on.astype(int).sum(-1) - off.astype(int).sum(-1) > 6) & target
    assert target.sum() > 50 and brighter.sum() > 10, (int(target.sum()), int(brighter.sum()))


def _normal_on_screen(r, mirror) -> float:
    """The screen angle (degrees, counter-clockwise positive, y up) of a mirror's normal as
    the level's camera sees it on the floor plane: its centre and a point a metre along its
    normal, both projected."""
    t = r.world.get(mirror, Transform)
    centre = glm.vec3(t.position)
    tip = centre + t.rotation * glm.vec3(0.0, 0.0, 1.0)
    (x0, y0), (x1, y1) = r.project(centre), r.project(tip)
    return math.degrees(math.atan2(-(y1 - y0), x1 - x0))


def test_tab_and_number_keys_select_a_mirror_the_marker_shows_it_and_left_turns_it_counter_clockwise(run):
    """Level 3 (three mirrors): Tab steps the selection 1, 2, 3 and round to 1, a number key
    picks its mirror; the yellow marker stands 0.2 m over the selected mirror's top (its
    position from the file, half its 1 m height up) and is where its id is drawn; Left turns
    the selected mirror's normal counter-clockwise as the camera above shows it (its angle on
    the screen grows by about the level's 15 degrees), Right back; once solved the marker is
    gone from the frame."""
    from games.mirror_beam.game import SelectionMarker

    path = level_file("03_sixty_degrees")
    r = run(path, size=(192, 108))
    r.frame()
    marker = next(e for e, _ in r.world.query_one(SelectionMarker))
    names = ["m1", "m2", "m3"]
    for keys, index in ((None, 0), ("tab", 1), ("tab", 2), ("tab", 0), ("3", 2), ("2", 1), ("1", 0)):
        r.frame(*([keys] if keys else []))
        r.frame()
        assert r.state.selected == index
        position, _ = mirror_pose(path, names[index])
        over = position + glm.vec3(0.0, 0.5 + 0.2, 0.0)
        assert glm.distance(glm.vec3(r.world.get(marker, Transform).position), over) < 1e-5
        x, y = r.project(over)
        ids = r.engine.renderer.targets.read_ids()
        assert any(ids[int(y) + dy, int(x) + dx] == marker for dy in (-1, 0, 1) for dx in (-1, 0, 1)), keys
    m3 = r.game.names["m3"]
    r.frame("3")
    before = _normal_on_screen(r, m3)
    r.frame("left")
    turned = (_normal_on_screen(r, m3) - before + 180.0) % 360.0 - 180.0
    assert 8.0 < turned < 25.0, turned  # counter-clockwise (the camera's tilt stretches the 15 degrees)
    r.frame("right")
    assert abs((_normal_on_screen(r, m3) - before + 180.0) % 360.0 - 180.0) < 1e-3
    for key in [*solution_keys(path), None]:
        r.frame(*([key] if key else []))
    assert r.state.won
    assert marker not in set(np.unique(r.engine.renderer.targets.read_ids()).tolist())


def test_the_caption_says_solved_and_the_autopilot_presses_a_key_every_interval_frames(ctx):
    """Level 1 played by the autopilot with ``interval=3``: its four keys (the file's
    solution: m1's number, then three turns left) come three frames apart after three empty
    frames, so the last turn, which wins in its own frame, is pressed in frame 3 x 4 = 12;
    the caption is the level's name until then and says "solved!" with the keys from that
    frame, and the caption's pixels (top left, past the name) change with it; 'r' puts the name back."""
    from components import ScreenText
    from games.mirror_beam.game import Caption

    path = level_file("01_one_bounce")
    keys = solution_keys(path)
    game = MirrorBeam(path, autopilot=True, interval=3, verbose=False)
    engine = Engine(game, ctx)
    size = (512, 72)  # wide enough for the caption's whole line (16-pixel text)
    capture = CaptureTarget(ctx, size)
    try:
        caption = next(t for _, (t, _) in engine.world.query(ScreenText, Caption))
        frames = []
        while not game.state.won and len(frames) < 30:
            engine.frame(1 / 60, Output(capture.framebuffer, size))
            frames.append(capture.read_rgb())
            if not game.state.won:
                assert caption.text == "Mirror beam 1: one bounce"
        assert game.state.wins()[0].frame == 3 * len(keys) == len(frames) - 1
        assert caption.text == "Mirror beam 1: one bounce: solved! (n: next, r: restart)"
        engine.frame(1 / 60, Output(capture.framebuffer, size))
        solved = capture.read_rgb()
        said = (slice(10, 36), slice(230, 470))  # right of the level's name: the words "solved! (...)"
        assert np.abs(solved[said].astype(int) - frames[-3][said].astype(int)).max() > 100, "the caption's text"
        engine.world.resources[Input].press("r")
        engine.frame(1 / 60, Output(capture.framebuffer, size))
        assert caption.text == "Mirror beam 1: one bounce" and not game.state.won
    finally:
        capture.release()
        engine.close()
