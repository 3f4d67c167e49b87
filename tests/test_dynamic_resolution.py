"""Dynamic resolution (``ViewBudget.frame_ms``; ``engine/render/dynamic_resolution.py``): the
controller against a simulated GPU whose frame time goes with the pixels drawn (readings a
few frames late), settling inside the budget's band without oscillating, following a
lighter load back up a step at a time; the engine drawing at the floor under an impossible
budget and at the render scale under an ample one, the GPU's frame timed (never waited on),
temporal AA's history kept across a change; the budget's fields checked when given."""
from __future__ import annotations

import math

import pytest

from engine.core.budget import ViewBudgetError
from engine.render.dynamic_resolution import COOLDOWN, MAX_RAISE, RAISE_BELOW, TIMER_FRAMES, ResolutionController
from engine.render.resample import render_size
from engine.resources import ViewBudget
from tests.test_temporal_aa import edge_scene

SIZE = (160, 120)
LAG = 3   # frames between a frame and its reading


def simulate(controller: ResolutionController, full_ms, frames: int, budget: float = 10.0, low: float = 0.25,
             high: float = 1.0) -> list[float]:
    """The scales of ``frames`` frames, each frame's GPU time ``full_ms(frame)`` x its scale
    squared (its pixels), give or take 25% from frame to frame, read ``LAG`` frames later."""
    scales: list[float] = []
    for frame in range(frames):
        jitter = 1.0 + 0.25 * math.sin(frame * 2.3)
        reading = full_ms(frame - LAG) * scales[frame - LAG] ** 2 * jitter if frame >= LAG else None
        scales.append(controller.update(reading, budget, low, high))
    return scales


def test_the_scale_settles_inside_the_budget_and_follows_the_load_back_up():
    """A GPU taking 25 ms at full size against a 10 ms budget: the scale comes down and
    settles where the frame takes between RAISE_BELOW of the budget and the budget, then holds
    (no oscillation); changes come at least COOLDOWN frames apart, in steps of 1/32.  The
    load falling to 5 ms: the scale climbs back, at most MAX_RAISE a step, to the render scale
    (1) and holds.  A load past reach holds at the floor."""
    controller = ResolutionController()
    scales = simulate(controller, lambda frame: 25.0 if frame < 200 else 5.0, 500)
    settled = scales[100:200]
    assert len(set(settled)) == 1
    assert RAISE_BELOW * 10.0 < 25.0 * settled[0] ** 2 <= 10.0, settled[0]
    changes = [frame for frame in range(1, len(scales)) if scales[frame] != scales[frame - 1]]
    assert changes and all(b - a >= COOLDOWN for a, b in zip(changes, changes[1:], strict=False))
    assert all(abs(s * 32 - round(s * 32)) < 1e-9 for s in scales)
    climb = [scales[f] / scales[f - 1] for f in changes if f > 200]
    assert climb and all(1.0 < ratio <= MAX_RAISE + 1e-9 for ratio in climb)
    assert scales[-1] == 1.0 and len(set(scales[-100:])) == 1
    floor = simulate(ResolutionController(), lambda frame: 1000.0, 100, low=0.4)
    assert floor[-1] == 0.4 and min(floor) == 0.4


def test_no_reading_changes_nothing_and_the_bounds_hold():
    """Without a reading the scale stays; bounds moved below or above it take it at once."""
    controller = ResolutionController(scale=0.75)
    assert all(controller.update(None, 10.0, 0.25, 1.0) == 0.75 for _ in range(40))
    assert controller.update(None, 10.0, 0.25, 0.5) == 0.5
    assert controller.update(None, 10.0, 0.6, 1.0) == 0.6
    assert math.isclose(controller.update(2.0, 10.0, 0.6, 1.0), 0.6)   # (cooldown: a change was just made)


@pytest.mark.parametrize("bad, words", [
    ({"frame_ms": 0.0}, "ViewBudget.frame_ms must be None or a finite number > 0"),
    ({"frame_ms": float("nan")}, "ViewBudget.frame_ms must be None or a finite number > 0"),
    ({"frame_ms": True}, "ViewBudget.frame_ms must be None or a finite number > 0"),
    ({"min_render_scale": 0.1}, "ViewBudget.min_render_scale must be a number in [0.25, 1]"),
    ({"min_render_scale": "0.5"}, "ViewBudget.min_render_scale must be a number in [0.25, 1]"),
])
def test_the_budgets_fields_are_checked_when_given(bad, words):
    with pytest.raises(ViewBudgetError, match=words.replace("[", r"\[").replace("]", r"\]")):
        ViewBudget(**bad)


def test_the_engine_draws_at_the_floor_over_budget_and_at_the_render_scale_under_it(scene):
    """An impossible budget (a microsecond): within the timer's lag and a cooldown the main view
    is drawn at the budget's floor, and stays there; the GPU's frame is read back (positive
    times); temporal AA's history (the output's size) goes on across the change, not cut.  An
    ample budget keeps the render scale (0.75 here: the most dynamic resolution draws at); a
    floor above the render scale is the render scale.  No budget: nothing timed."""
    tight = scene(edge_scene, SIZE)
    tight.engine.renderer.antialias = "taa"
    tight.world.resources[ViewBudget] = ViewBudget(frame_ms=0.001, min_render_scale=0.5)
    scales = []
    for _ in range(COOLDOWN + TIMER_FRAMES + 4):
        tight.frame()
        scales.append(tight.engine.renderer.stats.render_scale)
    renderer = tight.engine.renderer
    assert scales[0] == 1.0 and scales[-1] == 0.5 and renderer.targets.size == render_size(SIZE, 0.5)
    assert renderer.frame_timer.readings > 0 and renderer.stats.gpu_frame_ms > 0.0
    assert renderer.present_pass.temporal.resolved == len(scales)   # (never cut)
    assert tight.frame().shape[:2] == (SIZE[1], SIZE[0])

    ample = scene(edge_scene, SIZE)
    ample.engine.renderer.render_scale = 0.75
    ample.world.resources[ViewBudget] = ViewBudget(frame_ms=1e6, min_render_scale=0.5)
    for _ in range(COOLDOWN + TIMER_FRAMES + 4):
        ample.frame()
    assert ample.engine.renderer.stats.render_scale == 0.75
    assert ample.engine.renderer.targets.size == render_size(SIZE, 0.75)
    ample.engine.renderer.render_scale = 0.4   # (below the floor: the render scale wins)
    ample.frame()
    assert ample.engine.renderer.targets.size == render_size(SIZE, 0.4)

    untimed = scene(edge_scene, SIZE)
    for _ in range(TIMER_FRAMES + 2):
        untimed.frame()
    assert untimed.engine.renderer.frame_timer.readings == 0 and untimed.engine.renderer.stats.gpu_frame_ms is None
