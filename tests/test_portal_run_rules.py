"""games.portal_run's rules as the README states them, played in-process without pictures where
the rule is the body's (the physics, the caption's words), each against numbers worked out
from the level file alone: a lone portal keeps its wall solid, a pair opens it only in front
of the opening, WASD walks along the camera's own axes, Space jumps about a metre
(v^2 / 2g), ``not_solid`` lets the body through, and the caption's time stops at the win.
(The slow window and whole-level tests are in tests/test_portal_run.py.)"""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import ScreenText
from games.portal_run import levels
from games.portal_run.autopilot import Autopilot
from games.portal_run.game import EYE_HEIGHT, GRAVITY, HALF_WIDTH, JUMP_SPEED, WALK_SPEED
from tests.test_portal_run import DT, SMALL_LEVEL, Play

FIRST = levels()[0]  # facing walls: the front wall's face is z = 8, the ledge's x = -6 .. 6
FRONT_FACE = 8.2 - 0.4 / 2  # front_wall: box 0.4 thick at z = 8.2
ARRIVED_X = 0.35  # walk_to stops within 0.3 m of its point


@pytest.fixture
def play(ctx):
    made: list[Play] = []

    def make(level, script=None) -> Play:
        made.append(Play(ctx, level, script))
        return made[-1]

    yield make
    for p in made:
        p.close()


def _walk(p: Play, frames: int) -> list[float]:
    """Frames without pictures; the eye's z after each."""
    zs = []
    for _ in range(frames):
        p.frame(render=False)
        zs.append(float(p.eye.z))
    return zs


def test_a_lone_portal_keeps_its_wall_solid(play):
    """Level 1, portal A alone on the front wall straight behind the start (centred at x = 0,
    the player's x): walking into it for 2.5 s (5 m to go at 4.5 m/s) the body stops at the
    wall's face, z = 8 - its half width, and never passes it, and nothing travels."""
    p = play(FIRST, ["aim 0 1 8", "click left", "look 180 0", "hold w 150"])
    zs = _walk(p, 154)
    assert [e.detail for e in p.game.events] == ["portal A on front_wall"]
    assert p.game.placed[1] is None
    assert max(zs) + HALF_WIDTH <= FRONT_FACE + 1e-6
    assert zs[-1] + HALF_WIDTH == pytest.approx(FRONT_FACE, abs=1e-3)
    assert "travelled" not in p.game.event_kinds()


def test_a_pair_opens_the_wall_only_in_front_of_the_opening(play):
    """Level 1 with both portals placed, A centred at x = 1.5 on the front wall (1.2 m wide:
    x = 0.9 .. 2.1): walking at the wall at x = -1.5 (the body's 0.6 m from -1.8 to -1.2,
    clear of the opening) stops at its face with no travel; walking in at x = 1.5 goes
    through the opening and out of B (a travel through A)."""
    p = play(FIRST, ["aim 0 3.8 -8", "click right", "aim 1.5 1 8", "click left", "walk_to -1.5 5",
                     "look 180 0", "hold w 100"])
    zs = []
    while not p.pilot.done:
        p.frame(render=False)
        zs.append(float(p.eye.z))
    a = next(e for e in p.game.events if e.kind == "placed" and e.portal == 0)
    assert a.point[0] == pytest.approx(1.5, abs=0.05) and a.point[2] == pytest.approx(FRONT_FACE, abs=1e-4)
    assert abs(float(p.eye.x) + 1.5) < ARRIVED_X
    assert abs(float(p.eye.x) - a.point[0]) - HALF_WIDTH > 1.2 / 2  # the body is beside the opening
    assert max(zs) + HALF_WIDTH <= FRONT_FACE + 1e-6
    assert zs[-1] + HALF_WIDTH == pytest.approx(FRONT_FACE, abs=1e-3)
    assert "travelled" not in p.game.event_kinds()
    p.pilot = Autopilot(["walk_to 1.5 5", "walk_to 1.5 9"])
    p.run_script(render=False)
    travels = [e for e in p.game.events if e.kind == "travelled"]
    assert [e.detail for e in travels] == ["through portal A"]



def test_wasd_walks_along_the_cameras_own_axes_and_space_jumps_about_a_metre(play):
    """Level 1, turned 30 degrees: each of W, A, S, D held half a second moves the eye
    WALK_SPEED x 0.5 s along the view's own forward, left, back and right, read from the
    renderer's view matrix (its inverse's columns); then a jump from the floor peaks at
    v^2 / 2g = 5.5^2 / 30, about a metre, and lands back on the floor."""
    p = play(FIRST, ["look 30 0", "wait 2"])
    p.run_script()
    world_from_view = glm.inverse(p.engine.main_view.view)
    right = glm.vec3(world_from_view[0])
    forward = -glm.vec3(world_from_view[2])
    assert abs(right.y) < 1e-6 and abs(forward.y) < 1e-6
    for key, way in (("w", forward), ("a", -right), ("s", -forward), ("d", right)):
        start = glm.vec3(p.eye)
        p.pilot = Autopilot([f"hold {key} 30", "wait 2"])
        p.run_script(render=False)
        moved = p.eye - start
        assert glm.distance(moved, way * (WALK_SPEED * 0.5)) < 0.02, (key, moved)
    floor = float(p.eye.y) - EYE_HEIGHT
    assert floor == pytest.approx(0.0, abs=1e-3)
    p.pilot = Autopilot(["press space", "wait 70"])
    heights = []
    while not p.pilot.done:
        p.frame(render=False)
        heights.append(float(p.eye.y) - EYE_HEIGHT)
    assert max(heights) == pytest.approx(JUMP_SPEED ** 2 / (2 * GRAVITY), abs=0.03)
    assert 0.9 < max(heights) < 1.1 and heights[-1] == pytest.approx(0.0, abs=1e-3) and p.body.on_ground


def test_a_not_solid_entity_lets_the_body_through(play, tmp_path):
    """A room with a 1 m crate (z = -6 .. -5) before a wall whose face is z = -6: walking at
    them from z = 0 for 1.5 s stops at the crate's face (eye z = -5 + 0.3); with the crate
    named in ``not_solid`` the body walks through it to the wall's face (eye z = -6 + 0.3)."""
    stops = {}
    for name, text in (("solid", SMALL_LEVEL), ("not_solid", SMALL_LEVEL.replace('portal_walls = ["wall"]',
                                                                                'portal_walls = ["wall"]\n'
                                                                                'not_solid = ["crate"]'))):
        level = tmp_path / f"{name}.toml"
        level.write_text(text)
        p = play(level, ["hold w 90"])
        _walk(p, 92)
        stops[name] = float(p.eye.z)
    assert stops["solid"] == pytest.approx(-5.0 + HALF_WIDTH, abs=1e-3)
    assert stops["not_solid"] == pytest.approx(-6.0 + HALF_WIDTH, abs=1e-3)


def test_the_caption_shows_the_levels_name_and_time_and_the_time_stops_at_the_win(ctx):
    """Level 1 played by its solution: the caption is the level's name and the game time so
    far (frames x 1/60 s, to one decimal) until the win, then "complete in" the time at the win's
    frame, which stays so while the frames go on."""
    from games.portal_run import PortalRun
    from shell.app import Engine

    game = PortalRun(FIRST, autopilot=True, verbose=False)
    engine = Engine(game, ctx)
    try:
        caption = engine.world.get(game.caption, ScreenText)
        frames = 0
        while not game.won and frames < 400:
            engine.frame(DT, None)
            frames += 1
            if not game.won:
                name, _, seconds = caption.text.rpartition("   ")
                assert name == "Portal run 1: first jump" and seconds.endswith(" s") and len(seconds) == len("0.0 s")
                assert abs(float(seconds[:-2]) - frames * DT) <= 0.05 + 1e-6, (frames, caption.text)  # one decimal
        assert game.won
        won_at = next(e.frame for e in game.events if e.kind == "win")
        assert won_at == frames
        for _ in range(30):
            engine.frame(DT, None)
        name, _, seconds = caption.text.rpartition(": complete in ")
        assert name == "Portal run 1: first jump" and seconds.endswith(" s")
        assert abs(float(seconds[:-2]) - won_at * DT) <= 0.05 + 1e-6, caption.text
        assert np.isclose(game.elapsed, won_at * DT)
    finally:
        engine.close()
