"""The schedule games extend: ``Game.systems()`` returns ``GameSystem``s that run after and
before named stages (``shell.app.FRAME_STAGES``) or each other; the Engine orders them in
among the stages when it is made (``Engine.schedule``), runs them in that order, and refuses
an unknown name, constraints the stage table contradicts and a cycle between game systems
with a ``ScheduleError`` naming the system and the reason, before it makes anything.  A
game system after the transform stage that moves something has it drawn where it moved, in
the same frame ("transform_late")."""
from __future__ import annotations

import esper
import numpy as np
import pytest

from components import DirectionalLight, Material, MeshRef, Transform
from engine.assets.mesh import box
from engine.core.frame_io import Output
from engine.core.game import Game, GameSystem, ScheduleError, schedule_order
from engine.render.targets import CaptureTarget
from shell.app import FRAME_STAGES, Engine
from tests.support import look_from

STAGES = [name for name, _ in FRAME_STAGES]


class Recorder(esper.Processor):
    """A game system given as a processor: records its name when it runs."""

    def __init__(self, calls: list[str]) -> None:
        self.calls = calls

    def process(self, dt: float) -> None:
        self.calls.append("recorder")


class ScheduledGame(Game):
    """An empty level whose systems are ``make(game)``; every system records its name."""

    title = "schedule"

    def __init__(self, make) -> None:
        self.calls: list[str] = []
        self.make = make
        self.built = False

    def record(self, name: str):
        def system(world, dt: float) -> None:
            self.calls.append(name)
        system.__name__ = name
        return system

    def systems(self):
        return self.make(self)

    def build(self, world) -> None:
        self.built = True
        look_from(world, (0.0, 1.0, 4.0), (0.0, 0.5, 0.0))

    def update(self, world, dt: float) -> None:
        self.calls.append("update")


def test_a_game_without_systems_runs_the_stage_table_as_it_is(ctx):
    engine = Engine(ScheduledGame(lambda game: ()), ctx)
    try:
        assert [name for name, _ in engine.schedule] == STAGES
        assert all(system is engine.stages[name] for name, system in engine.schedule)
    finally:
        engine.close()


def test_game_systems_are_ordered_in_among_the_stages_and_run_in_that_order(ctx):
    def systems(game):
        return [
            GameSystem(game.record("trace"), after="surfaces", before="extract"),
            GameSystem(game.record("physics"), before="rules"),  # after the game stage by default
            GameSystem(game.record("follow"), after="trace"),
            GameSystem(game.record("late"), after=("present", "follow")),
            GameSystem(game.record("first"), after=()),  # nothing to wait for: first in the frame
            GameSystem(Recorder(game.calls), after="travel", before="transform", name="recorder"),
        ]

    game = ScheduledGame(systems)
    engine = Engine(game, ctx)
    try:
        names = [name for name, _ in engine.schedule]
        assert names == ["first", "game", "physics", "models", "rules", "input", "sun", "clouds", "travel", "recorder",
                         "slice", "transform", "surfaces", "trace", "follow", "transform_late", "detail", "decals",
                         "extract", "particles",
                         "prepare", "ripples", "shadows", "probes", "volume", "monitors", "main", "reflect", "present",
                         "late", "text", "probes_after"]
        assert dict(engine.schedule)["recorder"].calls is game.calls  # a processor is scheduled as it is
        assert game.built
        capture = CaptureTarget(ctx, (32, 18))
        try:
            for _ in range(2):
                engine.frame(1 / 60, Output(capture.framebuffer, (32, 18)))
        finally:
            capture.release()
        ours = ["first", "update", "physics", "recorder", "trace", "follow", "late"]
        assert game.calls == ours * 2
    finally:
        engine.close()


def test_the_order_is_the_same_every_time_and_follows_the_listing_where_free():
    def f(world, dt):
        pass

    def g(world, dt):
        pass

    both = [GameSystem(f, after="surfaces"), GameSystem(g, after="surfaces")]
    order = [item if isinstance(item, str) else item.name for item in schedule_order(STAGES, both)]
    assert order[order.index("surfaces"):order.index("detail")] == ["surfaces", "f", "g"]
    order = [item if isinstance(item, str) else item.name for item in schedule_order(STAGES, both[::-1])]
    assert order[order.index("surfaces"):order.index("detail")] == ["surfaces", "g", "f"]
    for _ in range(3):
        again = [item if isinstance(item, str) else item.name for item in schedule_order(STAGES, both[::-1])]
        assert again == order


def _system(name: str):
    def system(world, dt: float) -> None:
        pass
    system.__name__ = name
    return system


@pytest.mark.parametrize(("systems", "words"), [
    pytest.param([GameSystem(_system("beam"), after="surfacse")],
                 ["ScheduledGame.systems()", "game system 'beam'", "runs after 'surfacse'",
                  "no stage or game system", "did you mean 'surfaces'?", "stages: game, models, rules"],
                 id="unknown stage"),
    pytest.param([GameSystem(_system("beam"), before="nowhere")],
                 ["game system 'beam'", "runs before 'nowhere'", "no stage or game system"], id="unknown name"),
    pytest.param([GameSystem(_system("beam"), after="extract", before="surfaces")],
                 ["game system 'beam'", "runs after 'extract' and before 'surfaces'",
                  "the stages run 'surfaces' before 'extract' (FRAME_STAGES)"], id="contradicts the table"),
    pytest.param([GameSystem(_system("beam"), after="extract", before="extract")],
                 ["game system 'beam'", "runs both after and before 'extract'"], id="after and before one stage"),
    pytest.param([GameSystem(_system("a"), after="extract"), GameSystem(_system("b"), after="a", before="surfaces")],
                 ["game systems 'a', 'b'", "contradict the stage order (FRAME_STAGES)", "'b' runs after 'a'",
                  "'b' runs before 'surfaces'", "the stages run 'surfaces' before 'extract'",
                  "'a' runs after 'extract'"], id="contradicts the table through another system"),
    pytest.param([GameSystem(_system("a"), after="c"), GameSystem(_system("b"), after="a"),
                  GameSystem(_system("c"), after="b")],
                 ["game systems 'a', 'b', 'c'", "form a cycle between game systems", "'c' runs after 'b'",
                  "'b' runs after 'a'", "'a' runs after 'c'", "'a' would run before itself"], id="cycle"),
    pytest.param([GameSystem(_system("a"), after="a")], ["game system 'a'", "runs after itself"], id="self"),
    pytest.param([GameSystem(_system("extract"))], ["game system 'extract'", "has the name of an engine stage"],
                 id="a stage's name"),
    pytest.param([GameSystem(_system("transform_late"))],
                 ["game system 'transform_late'", "the engine's schedule uses"], id="the engine's own entry"),
    pytest.param([GameSystem(_system("a")), GameSystem(_system("a"))], ["game system 'a'", "listed twice"],
                 id="twice"),
    pytest.param([GameSystem(42, name="answer")], ["game system 'answer'", "neither a function(world, dt)"],
                 id="not a system"),
    pytest.param([_system("bare")], ["returned", "which is not a GameSystem"], id="not a GameSystem"),
])
def test_schedules_that_cannot_run_are_refused_by_name_before_anything_is_made(ctx, systems, words):
    game = ScheduledGame(lambda game: systems)
    with pytest.raises(ScheduleError) as error:
        Engine(game, ctx)
    message = str(error.value)
    for word in words:
        assert word in message, message
    assert not game.built, "refused before the level is built"
    assert ctx.error == "GL_NO_ERROR"


def test_what_a_game_system_moves_after_the_transform_stage_is_drawn_there_in_the_same_frame(ctx):
    """A box moved by a game system between surfaces and extract: its world matrix is this
    frame's, ``world.frame`` says it moved, and the frame's id image has it at the new place
    (the schedule's "transform_late" entry works the matrices out again before extract)."""
    size = (64, 48)
    moves = [(-1.0, 0.5, 0.0), (1.0, 0.5, 0.0)]

    class Mover(ScheduledGame):
        def build(self, world) -> None:
            super().build(world)
            world.spawn(DirectionalLight())
            self.box = world.spawn(Transform(position=(0.0, 0.5, 0.0)), MeshRef(box((0.6, 0.6, 0.6))),
                                   Material(color=(0.8, 0.2, 0.1)))

        def move(self, world, dt: float) -> None:
            world.get(self.box, Transform).position = moves[world.frame_index % 2]

    game = Mover(lambda game: [GameSystem(game.move, after="surfaces", before="extract")])
    engine = Engine(game, ctx)
    capture = CaptureTarget(ctx, size)
    try:
        for index in range(3):
            engine.frame(1 / 60, Output(capture.framebuffer, size))
            where = moves[index % 2]
            transform = engine.world.get(game.box, Transform)
            assert tuple(transform.world[3])[:3] == pytest.approx(where)
            assert game.box in engine.world.frame.moved | engine.world.frame.added
            ids = engine.renderer.targets.read_ids()
            columns = np.nonzero((ids == game.box).any(axis=0))[0]
            assert len(columns), f"frame {index}: the box is not drawn"
            centre = columns.mean() / size[0]
            assert (centre < 0.5) == (where[0] < 0), f"frame {index}: the box is drawn where it was, not at {where}"
    finally:
        capture.release()
        engine.close()
