"""The game's own code (its ``update``, its systems) failing: headless, the error ends the
frame as ever; in the window shell (``GameGuard.contain``), it stops the game instead of the
program, the engine's stages draw the world on, the overlay and the console say where, the
level's edits can still be saved, and F5 resumes the game.  Then the sample level's own game
code and controls, as README's "Game: hall of mirrors" and "Controls (windowed)" state them:
the headless tour, the spinning crates, what the level holds, and the fly camera's keys."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import DirectionalLight, Material, MeshRef, Skybox, Transform
from engine.assets.mesh import box, plane
from engine.core.frame_io import Output
from engine.core.game import Game, GameSystem
from engine.render.targets import CaptureTarget
from shell.app import Engine
from shell.overlay_text import overlay_lines
from tests.support import SceneRunner, look_from


def _room(world) -> None:
    look_from(world, (0.0, 2.0, 5.0), (0.0, 0.5, 0.0))
    world.spawn(Skybox())
    world.spawn(DirectionalLight(direction=(-0.4, -1.0, -0.3)))
    world.spawn(Transform(), MeshRef(plane(10, 10)), Material(color=(0.7, 0.7, 0.7)))


def _failing_update(calls: list[int], on: int):
    def update(world, dt):
        calls.append(len(calls) + 1)
        if len(calls) == on:
            raise RuntimeError("boom")
    return update


def test_headless_the_games_error_ends_the_frame(ctx):
    calls: list[int] = []
    runner = SceneRunner(ctx, _room, (32, 24), update=_failing_update(calls, 2))
    try:
        assert runner.engine.game_guard.contain is False
        runner.frame()
        with pytest.raises(RuntimeError, match="boom"):
            runner.frame()
    finally:
        runner.close()


def test_a_contained_error_stops_the_games_code_and_the_world_is_drawn_on(ctx, capsys):
    calls: list[int] = []
    runner = SceneRunner(ctx, _room, (48, 32), update=_failing_update(calls, 2))
    try:
        guard = runner.engine.game_guard
        guard.contain = True
        first = runner.frame()
        stopped = runner.frame()  # the update raises in this frame: the frame is drawn all the same
        assert guard.stopped == "game: RuntimeError: boom"
        assert "the game stopped in game (F5 resumes it)" in capsys.readouterr().err
        later = runner.frame()
        assert calls == [1, 2]  # left out of the frames while stopped
        np.testing.assert_array_equal(stopped, first)  # the engine's stages drew the same world
        np.testing.assert_array_equal(later, first)
        assert first.max() > 0
        assert overlay_lines(runner.engine, [0.02])[0] == \
            "game stopped in game: RuntimeError: boom (F5 resumes; the traceback is on the console)"
        guard.resume()
        runner.frame()
        assert calls == [1, 2, 3] and guard.stopped is None
        assert not overlay_lines(runner.engine, [0.02])[0].startswith("game stopped")
    finally:
        runner.close()


class _Holder(Game):
    """A game whose system holds the lamp entity from its build (as a laser holds its source)."""

    title = "holder"

    def __init__(self, as_processor: bool) -> None:
        self.as_processor = as_processor
        self.lamp = 0
        self.seen = 0

    def build(self, world) -> None:
        _room(world)
        self.lamp = world.spawn(Transform(position=(1.0, 0.5, 0.0)), MeshRef(box()), Material(color=(0.9, 0.8, 0.2)))
        self.crate = world.spawn(Transform(position=(-1.0, 0.5, 0.0)), MeshRef(box()), Material())

    def follow(self, world, dt) -> None:
        world.get(self.lamp, Transform)  # a KeyError once the lamp is gone
        self.seen += 1

    def systems(self) -> list[GameSystem]:
        if self.as_processor:
            game = self

            class Follow:
                def process(self, dt: float) -> None:
                    game.follow(game.world, dt)

            return [GameSystem(Follow(), before="extract", name="follow")]
        return [GameSystem(self.follow, before="extract", name="follow")]


@pytest.mark.parametrize("as_processor", [False, True], ids=["function", "processor"])
def test_a_game_system_holding_a_deleted_entity_stops_and_the_edits_are_saved(ctx, tmp_path, as_processor):
    """The editor deletes the entity the game's system holds: the next frame stops the game
    (named by the system), the world is drawn on without it, and the level, with an edit made
    before, saves and loads back."""
    from engine.assets.level_file import load_level
    from engine.core.world import World
    from shell.editor import Editor

    game = _Holder(as_processor)
    engine = Engine(game, ctx)
    game.world = engine.world
    capture = CaptureTarget(ctx, (48, 32))
    output = Output(capture.framebuffer, (48, 32))
    try:
        engine.game_guard.contain = True
        engine.frame(1 / 60, output)
        editor = Editor(engine.world, names={"lamp": game.lamp, "crate": game.crate})
        editor.set_field(game.crate, "Transform", "position", glm.vec3(-1.5, 0.5, 0.5))
        editor.delete(game.lamp)
        engine.frame(1 / 60, output)
        assert engine.game_guard.stopped is not None and engine.game_guard.stopped.startswith("follow: KeyError")
        seen = game.seen
        engine.frame(1 / 60, output)
        assert game.seen == seen and capture.read_rgb().max() > 0
        saved = editor.save(tmp_path / "holder.toml")
        again = World("again")
        names = load_level(saved).spawn(again)
        assert set(names) >= {"crate"} and "lamp" not in names
        assert tuple(again.get(names["crate"], Transform).position) == (-1.5, 0.5, 0.5)
    finally:
        capture.release()
        engine.close()


def test_the_window_shell_contains_the_games_error_and_f5_resumes_it(capsys):
    """moderngl-window's headless window: the shell sets ``contain``; after the game's error
    the title says so, F5 (a key no game gets while the game is stopped) resumes it."""
    import moderngl_window as mglw

    from shell.window import make_window_config
    from tests.support import FunctionGame

    calls: list[int] = []
    config = mglw.create_window_config_instance(
        make_window_config(FunctionGame(_room, _failing_update(calls, 2))),
        args=["--window", "headless", "--backend", "egl", "--size", "32x24"])
    try:
        assert config.engine.game_guard.contain is True
        keys = config.wnd.keys

        class Mods:
            shift = False
            ctrl = False

        for _ in range(3):
            config.on_render(0.0, 1 / 60)
        assert calls == [1, 2] and config.engine.game_guard.stopped == "game: RuntimeError: boom"
        assert config.shown_title.endswith("(game stopped: F5 resumes)")
        f5 = keys.F5
        config.on_key_event(f5 if isinstance(f5, int) else "F5", keys.ACTION_PRESS, Mods())
        config.on_render(0.0, 1 / 60)
        assert calls == [1, 2, 3] and config.engine.game_guard.stopped is None
        assert not config.shown_title.endswith("(game stopped: F5 resumes)")
    finally:
        config.on_close()


FAILING_GAME = r'''
import sys
from components import Skybox
from engine import Game, spawn_camera
from shell import run


class Failing(Game):
    title = "failing"

    def build(self, world):
        spawn_camera(world, position=(0.0, 1.0, 4.0))
        world.spawn(Skybox())
        self.frames = 0

    def update(self, world, dt):
        self.frames += 1
        if self.frames == 3:
            raise RuntimeError("boom")


run(Failing(), sys.argv[1:])
'''


def test_a_real_windows_run_whose_game_stopped_ends_with_an_error(x_display, tmp_path):
    """``--frames`` in a real window (Xvfb): the game's error stops the game, the window runs
    its frames to the end, and the run ends with exit status 2 and one line saying where the
    game stopped, after its traceback (a scripted windowed run does not pass as a clean one)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "DISPLAY": x_display, "PYTHONPATH": str(root)}
    result = subprocess.run([sys.executable, "-c", FAILING_GAME, "--frames", "8", "--size", "64x48"],
                            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 2, (result.returncode, result.stderr[-3000:])
    assert "the game stopped in game (F5 resumes it):" in result.stderr
    assert "RuntimeError: boom" in result.stderr
    assert result.stderr.strip().splitlines()[-1] == ("speculum: error: the game stopped in game: RuntimeError: "
                                                       "boom, and was not resumed before the window closed (its "
                                                       "traceback is above)")


def test_a_level_saved_while_the_game_is_stopped_is_built_afresh_and_the_game_runs_again(ctx, tmp_path):
    """The game stopped at an error; its level file saved (an edit that gives it what it
    needed) reloads (``Engine.watch_level``): the world is built afresh from the file and the
    game's code runs again from the next frame, without F5."""
    from engine.assets.level_file import LevelGame
    from tests.test_level_reload import level_text, save

    class NeedsTheBox(LevelGame):
        """Fails while the level has no entity named "box"."""

        def update(self, world, dt) -> None:
            world.get(self.names["box"], Transform)  # a KeyError without one
            self.updates = getattr(self, "updates", 0) + 1

    path = tmp_path / "level.toml"
    save(path, level_text().replace('name = "box"', 'name = "crate"'))
    game = NeedsTheBox(path)
    engine = Engine(game, ctx)
    capture = CaptureTarget(ctx, (48, 32))
    output = Output(capture.framebuffer, (48, 32))
    try:
        engine.game_guard.contain = True
        reload = engine.watch_level(interval=0.0)
        engine.frame(1 / 60, output)
        assert engine.game_guard.stopped == "game: KeyError: 'box'"
        save(path, level_text())
        assert reload.poll() == [] and reload.poll() == [f"level reloaded: {path}"]  # (its stat settled)
        assert engine.game_guard.stopped is None
        engine.frame(1 / 60, output)
        assert game.updates == 1 and engine.game_guard.stopped is None
    finally:
        capture.release()
        engine.close()


def test_a_processor_reused_by_a_second_engine_is_guarded_by_that_engine_alone(ctx):
    """A game handing the same processor to two engines in turn: the second engine's guard
    runs it, not the first's (stopped there, it would be left out for good)."""

    class Counting:
        def __init__(self) -> None:
            self.runs = 0
            self.fail = True

        def process(self, dt: float) -> None:
            self.runs += 1
            if self.fail:
                raise RuntimeError("first engine")

    counting = Counting()

    class Reusing(Game):
        title = "reusing"

        def build(self, world) -> None:
            _room(world)

        def systems(self) -> list[GameSystem]:
            return [GameSystem(counting, name="counting")]

    capture = CaptureTarget(ctx, (32, 24))
    output = Output(capture.framebuffer, (32, 24))
    try:
        first = Engine(Reusing(), ctx)
        first.game_guard.contain = True
        first.frame(1 / 60, output)
        assert first.game_guard.stopped == "counting: RuntimeError: first engine"
        first.close()
        counting.fail = False
        second = Engine(Reusing(), ctx)
        for _ in range(2):
            second.frame(1 / 60, output)
        second.close()
        assert counting.runs == 3 and second.game_guard.stopped is None
    finally:
        capture.release()


# --- the sample level's game code and the windowed controls ------------------------------------

def _hall():
    from engine.core.world import World
    from games.hall_of_mirrors.level import HallOfMirrors

    game = HallOfMirrors(tour=True)
    world = World("hall")
    game.build(world)
    return game, world


def _looks(rotation) -> glm.vec3:
    return glm.normalize(rotation * glm.vec3(0.0, 0.0, -1.0))


def test_the_sample_levels_tour_holds_each_pose_while_it_pans_and_its_crates_spin_at_their_speed():
    """The hall's script (``HallOfMirrors.update``, no frames drawn) at 0.25 s a frame over two
    rounds of the tour: in each pose's two seconds (the file's ``tour_seconds``) the camera
    stands at that pose, its yaw starting half of ``tour_pan`` (20 degrees) left of the
    pose's and panning right, never back, with the pose's pitch; it looks where that yaw and
    pitch say (yaw 0 looks down -Z, 90 down -X: -sin yaw cos pitch, sin pitch, -cos yaw cos
    pitch); after the last pose the first comes again.  Each Spin crate has turned about +Y
    by its speed times the time (its +X axis's heading, worked out from its rotation)."""
    import math

    from components import FlyController
    from games.hall_of_mirrors.level import Spin

    try:
        import tomllib
    except ImportError:  # Python 3.10
        import tomli as tomllib
    from games.hall_of_mirrors.level import LEVEL

    rules = tomllib.loads(LEVEL.read_text())["rules"]
    poses, seconds, pan = rules["tour"], rules["tour_seconds"], rules["tour_pan"]
    assert (len(poses), seconds, pan) == (6, 2.0, 20.0)
    game, world = _hall()
    camera = game.names["camera"]
    spins = {e: (spin.speed, glm.quat(world.get(e, Transform).rotation)) for e, spin in world.query_one(Spin)}
    assert len(spins) >= 3
    dt = 0.25
    per_pose = int(seconds / dt)
    yaws: dict[int, list[float]] = {}
    for frame in range(2 * len(poses) * per_pose):
        game.update(world, dt)
        index = frame // per_pose % len(poses)
        x, y, z, yaw, pitch = poses[index]
        transform = world.get(camera, Transform)
        assert glm.distance(transform.position, glm.vec3(x, y, z)) < 1e-6, frame
        fly = world.get(camera, FlyController)
        assert fly.pitch == pytest.approx(pitch)
        a, b = math.radians(fly.yaw), math.radians(pitch)
        expected = glm.vec3(-math.sin(a) * math.cos(b), math.sin(b), -math.cos(a) * math.cos(b))
        assert glm.distance(_looks(transform.rotation), expected) < 1e-5, frame
        yaws.setdefault(frame // per_pose, []).append((fly.yaw - yaw + 180.0) % 360.0 - 180.0)
    for window, turned in yaws.items():
        assert turned[0] == pytest.approx(-pan / 2), window
        assert all(b > a for a, b in zip(turned, turned[1:], strict=False)) and turned[-1] < pan / 2
    elapsed = 2 * len(poses) * per_pose * dt
    for entity, (speed, start) in spins.items():
        side = world.get(entity, Transform).rotation * glm.inverse(start) * glm.vec3(1.0, 0.0, 0.0)
        heading = math.degrees(math.atan2(-side.z, side.x))  # counter-clockwise seen from above
        assert abs(side.y) < 1e-5
        assert (heading - speed * elapsed + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=1e-2), entity


def test_the_sample_level_holds_the_pairs_its_section_lists():
    """What "Game: hall of mirrors" says the level holds, from its file (geometry worked out
    from each surface's position and +Z normal): mirrors tinted and rough, a facing pair of
    mirrors (normals opposite, each in front of the other), two portal pairs, one of them
    facing each other (the tunnel), the other's far door beyond the hall's mirror wall span
    (more than 10 m off); the chrome ball's probe redrawn every frame a face a frame; a
    normal-mapped brass statue; a glass ball; an emissive lamp with a point light; motes;
    the pond's water and ripples, its koi breathing every 2.5 s; a monitor showing the
    security camera; one mirror of the wall throwing the sun's light back."""
    from components import (
        Camera,
        DirectionalLight,
        Emissive,
        Material,
        Mirror,
        Monitor,
        ParticleEmitter,
        PointLight,
        Portal,
        ReflectionProbe,
        Refractive,
        Ripples,
        Water,
    )
    from games.hall_of_mirrors.level import Rise

    game, world = _hall()
    names = game.names

    def placed(entity):
        transform = world.get(entity, Transform)
        return glm.vec3(transform.position), glm.normalize(transform.rotation * glm.vec3(0.0, 0.0, 1.0))

    def facing(a, b) -> bool:
        (pa, na), (pb, nb) = placed(a), placed(b)
        return glm.dot(na, nb) < -0.99 and glm.dot(pb - pa, na) > 0.5 and glm.dot(pa - pb, nb) > 0.5

    mirrors = [e for e, m in world.query_one(Mirror) if not world.has(e, Water)]
    assert any(tuple(world.get(e, Mirror).color)[:3] != (1.0, 1.0, 1.0) for e in mirrors)
    assert any(world.get(e, Mirror).roughness > 0.0 for e in mirrors)
    assert any(facing(a, b) for a in mirrors for b in mirrors if a < b), "a facing pair of mirrors"
    pairs = {frozenset((e, p.partner)) for e, p in world.query_one(Portal)}
    assert len(pairs) == 2
    facing_pairs = [pair for pair in pairs if facing(*pair)]
    assert [set(pair) for pair in facing_pairs] == [{names["tunnel"], names["tunnel_far"]}]
    door = next(iter(pairs - set(facing_pairs)))
    assert glm.distance(*(placed(e)[0] for e in door)) > 10.0, "a doorway that opens far across the hall"
    probe = world.get(names["probe_ball"], ReflectionProbe)
    assert (probe.refresh, probe.time_slicing) == ("every_frame", "one_face_per_frame")
    assert world.get(names["brass_statue"], Material).normal_map is not None
    assert world.has(names["glass_ball"], Refractive)
    assert world.has(names["lamp"], Emissive) and world.has(names["lamp"], PointLight)
    assert world.query_one(ParticleEmitter) and world.query_one(DirectionalLight)
    assert world.has(names["pond"], Water) and world.has(names["pond"], Ripples)
    assert [rise.every for _, rise in world.query_one(Rise)] == [2.5]
    monitors = [m for _, m in world.query_one(Monitor)]
    assert len(monitors) == 1 and monitors[0].camera == names["security_camera"]
    assert world.has(names["security_camera"], Camera)
    throwing = [e for e in mirrors if world.get(e, Mirror).reflects_light]
    assert len(throwing) == 1 and placed(throwing[0])[0].z == pytest.approx(-6.0), "one mirror of the wall"


@pytest.mark.parametrize("shift", [False, True])
def test_the_fly_keys_move_the_camera_along_its_own_view_axes_and_shift_flies_three_times_as_far(ctx, shift):
    """A fly camera looking down at a room (pitched, turned): W, S, A, D, Q, E held for one
    0.1 s frame each move its eye by the controller's speed x 0.1 s (x 3 with Shift) along the
    view's own forward, back, left, right, down and up: the columns of the inverse of the view
    matrix the renderer drew the frame before with."""
    from components import Camera, FlyController, look_rotation
    from engine.core.frame_io import Input

    def build(world) -> None:
        _room(world)  # its camera, turned aside and given the controller
        camera, _ = next(iter(world.query_one(Camera)))
        eye = glm.vec3(1.0, 2.0, 5.0)
        world.get(camera, Transform).position = eye
        world.get(camera, Transform).rotation = look_rotation(glm.vec3(-0.5, 0.5, 0.0) - eye)
        world.add_component(camera, FlyController(speed=4.0))

    runner = SceneRunner(ctx, build, (32, 24))
    try:
        runner.frame(0.1)
        keys = runner.world.resources[Input]
        speed = 4.0 * (3.0 if shift else 1.0)
        for key, column, sign in (("w", 2, -1.0), ("s", 2, 1.0), ("a", 0, -1.0), ("d", 0, 1.0),
                                  ("q", 1, -1.0), ("e", 1, 1.0)):
            view = glm.inverse(runner.engine.main_view.view)
            axis = glm.normalize(glm.vec3(view[column])) * sign
            eye = glm.vec3(view[3])
            keys.held |= {key} | ({"shift"} if shift else set())
            runner.frame(0.1)
            keys.held.clear()
            moved = glm.vec3(glm.inverse(runner.engine.main_view.view)[3]) - eye
            assert glm.distance(moved, axis * (speed * 0.1)) < 1e-4, (key, moved, axis)
    finally:
        runner.close()
