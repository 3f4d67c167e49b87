"""Property-based: any value in any component field is refused naming ``Class.field`` or
renders a frame with no NaN in the HDR target and ``ctx.error`` clean.

hypothesis draws the component class, one to three of its fields and their values from the
same adversarial pool as ``python -m benchmarks fuzz`` (NaN, infinities, numbers past float32
and float16, ints past 2**63, wrong kinds, zero vectors, Euler-looking tuples); it shrinks a
failure to its smallest case.  The CI profile keeps it to about 200 cases in total (one
engine is reused, a case costs a 48 x 32 frame).
"""
from __future__ import annotations

import dataclasses
import random

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from benchmarks.fuzz import CLASSES, Case, Fuzzer, random_value
from components import Mirror, Transform

CI = settings(max_examples=200, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


@st.composite
def cases(draw) -> Case:
    cls = draw(st.sampled_from(CLASSES))
    names = [f.name for f in dataclasses.fields(cls) if f.init and not f.name.startswith("_")]
    chosen = draw(st.lists(st.sampled_from(names), min_size=1, max_size=3, unique=True))
    # Values from the shared pool, picked by a hypothesis-drawn seed so shrinking still works.
    rng = random.Random(draw(st.integers(0, 2 ** 32 - 1)))
    values = {name: random_value(rng) for name in chosen}
    if cls.__name__ == "MeshRef" and "mesh" not in values:
        from engine.assets.mesh import box

        values["mesh"] = box()
    return Case(cls, values)


@pytest.fixture(scope="module")
def fuzzer(ctx):
    f = Fuzzer(ctx)
    yield f
    f.close()


@CI
@given(case=cases())
def test_every_component_value_is_refused_by_name_or_renders_clean(fuzzer, case):
    why = fuzzer.run(case)
    assert why is None, f"{case.describe()}: {why}"


def test_the_fuzzer_catches_a_value_that_breaks_a_frame(fuzzer):
    """The check itself can fail: an unnamed refusal and a wrong field are reported."""
    assert fuzzer.run(Case(Transform, {"position": (float("nan"), 0, 0)})) is None
    assert fuzzer.run(Case(Mirror, {"roughness": 0.3})) is None
    why = Fuzzer._named(Case(Mirror, {"color": 5}), __import__("components").ComponentValueError("boom"))
    assert why is not None and "without naming Mirror" in why


def test_water_and_visibility_are_fuzzed_and_a_case_runs_several_frames(fuzzer, monkeypatch):
    """Issue 41 item 9: Water (on a mirror quad with waves) and Visibility are among the
    classes; a case renders FRAMES_PER_CASE frames, so a problem that shows only after the
    first frame (waves moved on, a fade or a schedule settled) fails the case."""
    from benchmarks.fuzz_cases import FRAMES as FRAMES_PER_CASE
    from components import Visibility, Water
    from systems.surface_system import SurfaceSystem

    assert Water in CLASSES and Visibility in CLASSES and FRAMES_PER_CASE >= 2
    rendered = fuzzer.rendered
    assert fuzzer.run(Case(Water, {"speed": 2.0, "tiling": 3.0})) is None
    assert fuzzer.run(Case(Visibility, {"in_mirrors": False})) is None
    assert fuzzer.rendered == rendered + 2
    assert fuzzer.run(Case(Water, {"ior": float("nan")})) is None  # refused naming Water.ior

    calls = []
    original = SurfaceSystem.process

    def breaks_on_the_second_frame(self, dt):
        calls.append(dt)
        if len(calls) == 2:
            raise RuntimeError("a surface that breaks a frame after the first")
        original(self, dt)

    monkeypatch.setattr(SurfaceSystem, "process", breaks_on_the_second_frame)
    why = fuzzer.run(Case(Water, {"speed": 1.0}))
    assert why is not None and "a surface that breaks a frame after the first" in why


def test_budget_cases_are_refused_by_name_or_render_clean(ctx):
    """ViewBudget values with the surfaces that spend them (facing mirrors, an every-frame
    probe, a pond with fades, Water and Visibility drawn too), several frames a case."""
    from benchmarks.fuzz import fuzz_budgets

    ran, failures, passes = fuzz_budgets(ctx, 40, seed=5)
    assert ran == 40 and failures == [], failures[:3]
    assert passes["refused"] > 0 and passes["rendered"] > 0, passes


def test_the_budget_fuzzer_catches_a_refusal_that_names_no_field(ctx, monkeypatch):
    from benchmarks.fuzz import BudgetCase, BudgetFuzzer
    from engine.core import budget

    fuzzer = BudgetFuzzer(ctx)
    try:
        assert fuzzer.run(BudgetCase({"views": 3}, {}, {}, {})) is None  # under a cube: still renders
        assert fuzzer.run(BudgetCase({"views": -3}, {}, {}, {})) is None  # refused naming ViewBudget.views

        def unnamed(self):
            raise budget.ViewBudgetError("no")

        monkeypatch.setattr(budget.ViewBudget, "check", unnamed)
        why = fuzzer.run(BudgetCase({"views": 3}, {}, {}, {}))
        assert why is not None and "without naming ViewBudget" in why
    finally:
        fuzzer.close()


# --- level files ---------------------------------------------------------------------------------

LEVEL_CI = settings(max_examples=120, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


@pytest.fixture(scope="module")
def level_fuzzer(ctx, tmp_path_factory):
    from benchmarks.level_fuzz import LevelFuzzer

    f = LevelFuzzer(ctx, tmp_path_factory.mktemp("level_fuzz"))
    yield f
    f.close()


@LEVEL_CI
@given(seed=st.integers(0, 2 ** 32 - 1))
def test_every_mutated_level_file_is_refused_naming_the_file_or_renders_clean(level_fuzzer, seed):
    """A small level's text with one to three random mutations (awkward values, unknown
    components and fields, broken lines, bad references, bad mesh and texture specs)."""
    from benchmarks.level_fuzz import random_level_case

    case = random_level_case(random.Random(seed))
    why = level_fuzzer.run(case)
    assert why is None, f"{case.describe()}: {why}\n{case.text}"


def test_the_level_fuzzer_renders_the_base_level_and_catches_a_silent_failure(level_fuzzer):
    """The unmutated level renders (so mutations are measured against a working level), and
    a refusal that leaves entities behind is reported."""
    from benchmarks.level_fuzz import BASE, LevelCase

    before = level_fuzzer.rendered
    assert level_fuzzer.run(LevelCase(BASE, [])) is None and level_fuzzer.rendered == before + 1
    keep = level_fuzzer.world.spawn(Transform())
    try:
        why = level_fuzzer.run(LevelCase(BASE.replace('name = "fuzz"', 'title = "fuzz"'), ["no name"]))
        assert why is not None and "left entities" in why
    finally:
        level_fuzzer.world.delete_entity(keep)


# --- still frames: kept and refilled view trees (benchmarks/still_fuzz.py) -----------------------

def test_still_cases_refill_and_draw_what_a_whole_drawn_engine_draws(ctx):
    """A few seeded still-frame cases: a facing pair with end images kept and refilled by a
    still camera, glass between see-through surfaces, glass behind glass drawn in layers, the
    see-through things cut about the glass, one random change mid-refill; every frame bit for
    bit the frame of an engine drawing its whole tree, resources back after each case (the big
    runs are ``python -m benchmarks fuzz --still-cases N``)."""
    from benchmarks.still_fuzz import fuzz_still

    ran, failures, passes = fuzz_still(ctx, 8, seed=5)
    assert ran == 8 and failures == [], failures
    assert passes["rendered"] > 0 and passes["refill_frames"] >= 8 and passes["glass_between_frames"] > 0, passes
    assert passes["glass_layered_frames"] > 0, passes  # (glass behind glass, its layers refilled too)
    assert passes["slot_cut_frames"] > 0, passes  # (see-through things on both sides of the glass)


def test_the_still_fuzz_makes_its_engines_afresh_past_its_programs_bound(monkeypatch):
    """Each still case's scene-wide features (shadow rings, kinds of lamp, fog, the screen
    effects) make builds of their own, kept by each engine: past ``PROGRAMS_BEFORE_RESTART``
    the fuzzer makes both engines afresh and the context's free list lets go of all but its
    ``keep``, so a long run's programs (llvmpipe's memory for them: 3-7 MB each) stay
    bounded.  A context of its own (the suite's keeps 512 free programs for its engines)."""
    import benchmarks.still_fuzz as still_fuzz
    from benchmarks.fuzz_cases import run_cases
    from engine.render.gl_context import create_headless_context
    from engine.render.shader_library import FreePrograms

    ctx = create_headless_context()
    try:
        fuzzer = still_fuzz.StillFuzzer(ctx)
        base = fuzzer.keeping.engine.renderer.resource_counts()["programs"]
        free = FreePrograms.of(ctx)
        at_start = []   # (the keeping engine's programs, the free list's) as each case spawns its level
        real_spawn = still_fuzz._spawn

        def spawn(world, case):
            if world is fuzzer.keeping.world:
                at_start.append((fuzzer.keeping.engine.renderer.resource_counts()["programs"], free.count))
            return real_spawn(world, case)

        monkeypatch.setattr(still_fuzz, "_spawn", spawn)
        monkeypatch.setattr(still_fuzz, "PROGRAMS_BEFORE_RESTART", base + 5)
        ran, failures, passes = run_cases(fuzzer, still_fuzz.random_still_case, 4, 322)
        assert ran == 4 and failures == [], failures
        assert passes["refused"] + passes["rendered"] == 4 and fuzzer.restarts == 3, (fuzzer.restarts, at_start)
        # Every case after the first starts on fresh engines, nothing left on the free list.
        assert at_start[0] == (base, 0) and all(start == (base, 0) for start in at_start[1:]), (base, at_start)
    finally:
        FreePrograms.of(ctx).release()
        ctx.release()


def _glass_pair_case(change: str, detail: dict):
    from benchmarks.still_fuzz import StillCase

    return StillCase(pair="mirrors", depth=3, panes=[((-0.6, 1.0, -1.0), 1.4, (0.9, 0.2, 0.1, 0.5))], water=False,
                     see_through_mirror=False, sandwich=None, still=5, change=change, detail=detail, after=3,
                     rate=0.8)


def test_the_still_fuzz_catches_a_refill_that_does_not_put_a_level_back(ctx, monkeypatch):
    """The checks can fail: a refill that skips putting its levels back (their old composites
    left in) differs from the whole-drawn frame, a level copy kept after the pair went is
    reported as resources that did not come back, and a shadow map kept after its light
    turned differs from the other engine's, drawn whole every frame."""
    from benchmarks.still_fuzz import StillFuzzer
    from engine.render.level_copies import LevelCopies

    fuzzer = StillFuzzer(ctx)
    try:
        case = _glass_pair_case("depth_cap", {"cap": 8})
        assert fuzzer.run(case) is None and fuzzer.refills >= 3
        with monkeypatch.context() as patch:
            patch.setattr(LevelCopies, "restore", lambda self, level, targets, rect: None)
            why = fuzzer.run(case)
        assert why is not None and "differs from the frame drawn whole" in why, why
        with monkeypatch.context() as patch:
            patch.setattr(LevelCopies, "release", lambda self: None)
            why = fuzzer.run(_glass_pair_case("remove", {"target": "box"}))
        assert why is not None and "level_copies" in why, why
        # A shadow stage that keeps its maps though the light turned (edited in place):
        # the other engine draws every map whole, so the stale shadows show.
        monkeypatch.setattr(fuzzer.keeping.engine.stages["shadows"], "_directional_maps", lambda *args: None)
        why = fuzzer.run(_glass_pair_case("component", {"target": "light_in_place", "field": "direction",
                                                        "value": 0.9}))
        assert why is not None and "differs from the frame drawn whole" in why, why
    finally:
        fuzzer.close()


@pytest.mark.parametrize("how", ["quarter", "half", "flip"])
def test_the_box_turned_inside_its_own_box_draws_what_a_whole_drawn_engine_draws(ctx, how):
    """The still fuzz's ``turn``: the L turned by an exact quarter or half turn, or flipped by
    scale, mid-refill; a half turn and the flip leave its world box the same to the bit (the
    keeping engine's sun map kept its old shadow there before ``InstanceBatch._row_models``)."""
    from benchmarks.still_fuzz import StillFuzzer

    fuzzer = StillFuzzer(ctx)
    try:
        assert fuzzer.run(_glass_pair_case("turn", {"how": how})) is None
    finally:
        fuzzer.close()


def test_in_float32_images_the_check_finds_values_past_a_half_float(ctx, monkeypatch):
    """``--hdr32``: the colour images float32, the frame check (``fuzz_cases.hdr_problem``) also
    finds a value past 65504 (which llvmpipe saturates and a correctly rounding GPU stores as
    +inf); a white-hot material lit by the fuzz scene's light renders clean, its pixels kept
    within a half float by the shaders (broken on purpose, hdr_store returning its input, this
    case reports "6 values past 65504", up to 84952)."""
    import numpy as np

    import engine.render.targets as targets
    from benchmarks.fuzz_cases import hdr_problem
    from components import Material

    assert hdr_problem(np.array([0.0, 65504.0], np.float32)) is None
    assert "past 65504" in hdr_problem(np.array([1.0, 65504.5], np.float32))
    assert "non-finite" in hdr_problem(np.array([1.0, np.inf], np.float16))
    assert "non-finite" in hdr_problem(np.array([np.nan, 1.0], np.float32))
    monkeypatch.setattr(targets, "HDR_FORMAT", "f4")
    wide = Fuzzer(ctx)
    try:
        assert wide.run(Case(Material, {"color": (65504.0, 65504.0, 65504.0)})) is None
        assert wide.engine.renderer.targets.color.dtype == "f4" and wide.rendered == 1
    finally:
        wide.close()
