"""Animation events (``AnimationEvents``, fired into ``FiredEvents`` by the models stage):
which a playback passes, checked against the unwrapped time line worked out here by hand
(forwards, backwards, a loop's wraps, several wraps in one long frame, a held end, a paused
clip, a layer's clip); a bad event refused by the models stage and by a level file's line."""
from __future__ import annotations

import textwrap

import pytest

from components import Animation, AnimationEvents, AnimationLayer, ComponentValueError
from engine.core.clip_events import MAX_EVENTS_A_FRAME, passed_events
from engine.core.errors import AssetError
from engine.core.world import World
from engine.resources import FiredEvents
from systems.model_system import ModelSystem
from tests.support import look_from
from tests.test_root_motion import walker

STEPS = (("Walk", 0.0, "left"), ("Walk", 1.0, "right"), ("Walk", 2.0, "end"))


def playing(tmp_path, steps, events=STEPS, layer=None, **fields):
    """The walker (clip "Walk", 2 s) with ``events``; each step's fired events as (name, time)."""
    from engine.assets.models import spawn_model

    world = World("events")
    root = spawn_model(world, walker(tmp_path / "walker.glb"))
    world.add_component(root, Animation("Walk", **fields))
    world.add_component(root, AnimationEvents(events=events))
    if layer is not None:
        world.add_component(root, layer)
    stage = ModelSystem(world)
    seen = []
    for dt in steps:
        stage.process(dt)
        fired = world.resources[FiredEvents]
        assert all(event.entity == root and event.clip == "Walk" for event in fired)
        seen.append([(event.name, event.time, event.layer) for event in fired])
    return seen


def test_forwards_events_fire_once_as_the_time_passes_them(tmp_path):
    seen = playing(tmp_path, [0.5, 0.4, 0.2, 0.5, 0.5, 0.5])  # times 0.5, 0.9, 1.1, 1.6, 2.1 -> 0.1, 0.6
    assert seen == [[("left", 0.0, False)], [], [("right", 1.0, False)], [],
                    [("end", 2.0, False), ("left", 0.0, False)], []]


def test_backwards_through_the_start_and_a_long_frame_of_wraps(tmp_path):
    # From 1.2 s back 0.5 s a step: 0.7, then 0.2, then -0.3 (wrapped to 1.7): "left" at 0 once
    # (the end at 2 is the start at 0 of the loop before, so "end" is met too, as the time
    # comes down through 2).
    seen = playing(tmp_path, [0.5, 0.5, 0.5], time=1.2, speed=-1.0)
    assert seen == [[("right", 1.0, False)], [], [("left", 0.0, False), ("end", 2.0, False)]]
    # 5.1 s forwards from 0.5 in one frame: places 1, 2, 2|0, 3, 4, 4|0, 5 (unwrapped) passed.
    (events,) = playing(tmp_path, [5.1], time=0.5)
    assert [name for name, _, _ in events] == ["right", "end", "left", "right", "end", "left", "right"]


def test_a_clip_that_does_not_loop_fires_its_end_once_and_a_paused_one_nothing(tmp_path):
    seen = playing(tmp_path, [1.5, 1.0, 1.0], time=0.2, loop=False)
    assert seen == [[("right", 1.0, False)], [("end", 2.0, False)], []]
    assert playing(tmp_path, [0.5, 0.5], playing=False) == [[], []]


def test_a_layers_clip_fires_its_events_as_the_layers(tmp_path):
    seen = playing(tmp_path, [0.6], layer=AnimationLayer("Walk", time=0.5, speed=1.0), speed=0.5)
    assert seen == [[("left", 0.0, False), ("right", 1.0, True)]]


def test_passed_events_counts_what_a_frame_leaves_out():
    events = [(0.0, "tick")]
    fired, dropped = passed_events(events, 0.0, 10.0, 1 / 128, True)  # 1280 passes of a 7.8 ms clip
    assert len(fired) == MAX_EVENTS_A_FRAME and len(fired) + dropped == 1280
    fired, dropped = passed_events(events, 10.0, -10.0, 1 / 128, True)   # (1 / 128: 10 s is 1280 of it exactly)
    assert len(fired) == MAX_EVENTS_A_FRAME and len(fired) + dropped == 1280


def test_bad_events_are_refused(tmp_path):
    with pytest.raises(ComponentValueError, match="AnimationEvents.events"):
        AnimationEvents(events=[("Walk", -1.0, "x")])
    with pytest.raises(ComponentValueError, match="triples"):
        AnimationEvents(events=[("Walk", 1.0)])
    with pytest.raises(ComponentValueError, match="non-empty strs"):
        AnimationEvents(events=[("Walk", 1.0, "")])
    with pytest.raises(AssetError, match=r"event 'x' is on clip 'Run', which the model has not \(its clips: 'Walk'\)"):
        playing(tmp_path, [0.1], events=[("Run", 0.5, "x")])
    with pytest.raises(AssetError, match=r"event 'late' at 2.5 s is past the end of clip 'Walk' \(2 s long\)"):
        playing(tmp_path, [0.1], events=[("Walk", 2.5, "late")])


def test_a_level_file_gives_events_and_names_a_bad_ones_line(tmp_path):
    from engine.assets.level_file import LevelError, load_level, save_level

    walker(tmp_path / "walker.glb")
    text = textwrap.dedent("""
        [level]
        name = "steps"

        [[entity]]
        name = "walker"
        [entity.Transform]
        [entity.Model]
        file = "walker.glb"
        [entity.Animation]
        clip = "Walk"
        [entity.AnimationEvents]
        events = [["Walk", 0.0, "left"], ["Walk", 1.0, "right"]]
        """)
    path = tmp_path / "steps.toml"
    path.write_text(text)
    world = World("steps")
    names = load_level(path).spawn(world)
    assert world.get(names["walker"], AnimationEvents).events == (("Walk", 0.0, "left"), ("Walk", 1.0, "right"))
    saved = save_level(world, tmp_path / "saved.toml", names, name="steps")
    again = World("again")
    names_again = load_level(saved).spawn(again)
    first = world.get(names["walker"], AnimationEvents).events
    assert again.get(names_again["walker"], AnimationEvents).events == first
    path.write_text(text.replace('["Walk", 1.0, "right"]', '["Run", 1.0, "right"]'))
    with pytest.raises(LevelError, match=r"steps\.toml:13: entity 'walker': AnimationEvents\.events: event 'right' "
                                         r"is on clip 'Run'"):
        load_level(path)


def test_an_emitter_under_a_model_bursts_on_its_event(scene, tmp_path):
    """A dust emitter hung under the walker bursts 10 each time "step" fires (at 0.5 and 1.5 s
    of the 2 s Walk), and not as it starts; one hung elsewhere does not."""
    from pyglm import glm

    from components import ParticleEmitter, Transform
    from engine.assets.models import spawn_model

    path = walker(tmp_path / "walker.glb")

    def build(world):
        look_from(world, (0.0, 1.0, 6.0), (0.0, 1.0, 0.0))
        world.root = spawn_model(world, path)
        world.add_component(world.root, Animation("Walk"))
        world.add_component(world.root, AnimationEvents(events=[("Walk", 0.5, "step"), ("Walk", 1.5, "step")]))
        dust = dict(rate=0.0, burst=10, lifetime=100.0, speed=0.0, burst_on="step")
        world.dust = world.spawn(Transform(parent=world.root), ParticleEmitter(**dust))
        world.other = world.spawn(Transform(position=glm.vec3(5.0, 0.0, 0.0)), ParticleEmitter(**dust))
    runner = scene(build, (32, 18))
    clouds = runner.engine.stages["particles"].clouds
    counts = []
    for _ in range(8):  # 0.25 s a frame: steps at 0.5 (frame 2) and 1.5 (frame 6)
        runner.frame(0.25)
        counts.append((clouds[runner.world.dust][0].count, clouds[runner.world.other][0].count))
    assert counts == [(0, 0), (0, 0), (10, 0), (10, 0), (10, 0), (10, 0), (20, 0), (20, 0)]


PASSES = (("Walk", 0.0, "left"), ("Walk", 0.1, "tick"), ("Walk", 1.0, "right"), ("Walk", 2.0, "end"))


@pytest.mark.parametrize(("start", "dt", "frames", "speed"), [
    ("0.5", "0.25", 17, 1.0),    # frames landing right on the wrap (2.0, 4.0): "end" and "left" there
    ("1.6", "0.5", 8, 1.0),      # frames landing on "tick"'s place past the wrap (2.1 = 0.1 + 2)
    ("1.5", "0.25", 15, -1.0),   # backwards, landing right on the start (0.0) and a loop before it
    ("0.3", "0.1", 5, -1.0),     # backwards, landing a hair below 0 (0.3 - 3 x 0.1), which wraps to 2.0 itself
    ("0.3", "0.35", 6, 2.0),     # twice as fast (0.7 s of clip a frame)
    ("0.05", "1.3", 4, 1.0),     # frames longer than half the clip
])
def test_each_event_fires_once_for_each_of_its_places_however_the_frames_land(tmp_path, start, dt, frames, speed):
    """The 2 s Walk played on from ``start`` by ``frames`` frames of ``dt`` x ``speed``: each
    event fires, over the run, once for each of its places t + 2k on the unwrapped time line
    between where the run starts and ends (counted here in exact fractions of the decimal
    times; neither end is any event's place), whether or not a frame lands right on a wrap
    or on an event's place after one."""
    from fractions import Fraction

    seen = playing(tmp_path, [float(dt)] * frames, events=PASSES, time=float(start), speed=speed)
    low = Fraction(start)
    high = low + frames * Fraction(dt) * Fraction(speed)
    low, high = min(low, high), max(low, high)
    for _, t, name in PASSES:
        at = Fraction(str(t))
        expected = sum(1 for k in range(-10, 10) if low < at + 2 * k < high)
        got = sum(1 for frame in seen for fired, _, _ in frame if fired == name)
        assert got == expected, (name, got, expected, seen)


def test_a_games_update_reads_the_last_frames_events_and_a_long_frame_counts_what_it_left_out(ctx, tmp_path):
    """Rendered frames of 0.6 s (Walk's "left" at 0, "right" at 1, "end" at 2): the game's
    update sees each frame the events the frame before fired (none, left, right, none), and
    after the fourth frame ``FiredEvents`` holds its own (end, left); one 601 s frame passes
    301 + 300 + 300 places, fires the first 256 and counts the 645 others as dropped."""
    from engine.assets.models import spawn_model
    from tests.support import SceneRunner

    path = walker(tmp_path / "walker.glb")
    heard = []

    def build(world):
        look_from(world, (0.0, 1.0, 6.0), (0.0, 1.0, 0.0))
        root = spawn_model(world, path)
        world.add_component(root, Animation("Walk"))
        world.add_component(root, AnimationEvents(events=STEPS))

    def update(world, dt):
        heard.append([event.name for event in world.resources.get(FiredEvents, [])])

    runner = SceneRunner(ctx, build, (16, 16), update)
    try:
        for _ in range(4):
            runner.frame(0.6)
        assert heard == [[], ["left"], ["right"], []]
        assert [event.name for event in runner.world.resources[FiredEvents]] == ["end", "left"]
    finally:
        runner.close()
    world = World("long")
    root = spawn_model(world, path)
    world.add_component(root, Animation("Walk"))
    world.add_component(root, AnimationEvents(events=STEPS))
    ModelSystem(world).process(601.0)
    fired = world.resources[FiredEvents]
    assert len(fired) == MAX_EVENTS_A_FRAME and fired.dropped == 301 + 300 + 300 - MAX_EVENTS_A_FRAME
    assert [event.name for event in fired[:6]] == ["left", "right", "end", "left", "right", "end"]
