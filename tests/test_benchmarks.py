"""The benchmark command line: every suite that renders takes ``--size WxH`` (its default
unchanged, a bad value an argparse error, the size reaching the render target), and
``python -m benchmarks gpu-report`` writes report.md and report.json naming this context's
renderer, the sizes asked and each benchmark's rows, with imgui-bundle out of reach."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from benchmarks import RENDERING_SUITES, SUITES, parse_size
from benchmarks.__main__ import build_parser
from engine.render.gl_context import GLCapabilities
from engine.render.raw_gl import make_current

ROOT = Path(__file__).resolve().parents[1]

# What each rendering suite drew at before --size existed: the default must not move.
DEFAULT_SIZES = {"ecs": (64, 36), "portals": (640, 360), "mirrors": (640, 360), "soak": (320, 180),
                 "churn": (320, 180), "probes": (640, 360), "normal_maps": (640, 360), "stages": (640, 360),
                 "profile": (640, 360)}


@pytest.fixture
def own_contexts(ctx):
    """For tests whose suites make (and release) contexts of their own: the session's is made
    current again afterwards, for the tests that follow."""
    yield
    make_current(ctx)


def test_every_rendering_suite_takes_size_with_its_old_default():
    parser, _ = build_parser()
    assert set(RENDERING_SUITES) == set(DEFAULT_SIZES) and set(RENDERING_SUITES) <= set(SUITES)
    for name in RENDERING_SUITES:
        assert parser.parse_args([name]).size == DEFAULT_SIZES[name], name
        assert parser.parse_args([name, "--size", "1920x1080"]).size == (1920, 1080), name
        assert parser.parse_args([name, "--size", "32X18"]).size == (32, 18), name


@pytest.mark.parametrize("bad", ["640", "640x", "x360", "0x360", "640x0", "axb", "640x360x2", "6.5x3", "99999x10"])
def test_a_bad_size_is_an_argparse_error_that_says_what_was_expected(bad, capsys):
    parser, _ = build_parser()
    for name in (*RENDERING_SUITES, "gpu-report"):
        argv = [name, "--size", bad] + (["--out", "unused"] if name == "gpu-report" else [])
        with pytest.raises(SystemExit) as exit_:
            parser.parse_args(argv)
        assert exit_.value.code == 2
        error = capsys.readouterr().err
        assert "argument --size:" in error and repr(bad) in error, error
        assert "WIDTHxHEIGHT" in error or "1 to 16384" in error, error
    with pytest.raises(SystemExit):
        parser.parse_args(["gpu-report", "--out", "unused", "--size", "64x36,64x36"])
    assert "names a size twice" in capsys.readouterr().err
    assert parse_size(" 64x36 ") == (64, 36)


def test_every_suite_has_a_clean_help(capsys):
    parser, _ = build_parser()
    for name in SUITES:
        with pytest.raises(SystemExit) as exit_:
            parser.parse_args([name, "--help"])
        assert exit_.value.code == 0
        text = capsys.readouterr().out
        assert text.startswith(f"usage: python -m benchmarks {name}"), text[:200]
        if name in RENDERING_SUITES or name == "gpu-report":
            assert "--size" in text, name


def _spy_on_capture_targets(monkeypatch, module) -> list[tuple[int, int]]:
    made = []
    real = module.CaptureTarget

    def capture_target(ctx, size, *args, **kwargs):
        made.append(tuple(size))
        return real(ctx, size, *args, **kwargs)

    monkeypatch.setattr(module, "CaptureTarget", capture_target)
    return made


@pytest.mark.parametrize("argv", [
    ["portals", "--frames", "1", "--warmup", "0"],
    ["mirrors", "--mirrors", "0,1", "--paths", "auto", "--frames", "1", "--warmup", "0"],
    ["normal_maps", "--frames", "1", "--warmup", "0"],
    ["ecs", "--sizes", "100", "--frames", "1", "--warmup", "1"],
    ["churn", "--entities", "5", "--waves", "1", "--frames", "1"],
    ["profile", "--scenes", "portals_d8", "--frames", "1", "--warmup", "0"],
], ids=lambda argv: argv[0])
def test_the_size_reaches_the_render_target(argv, monkeypatch, capsys, own_contexts):
    parser, modules = build_parser()
    args = parser.parse_args([*argv, "--json", "--size", "48x27"])
    made = _spy_on_capture_targets(monkeypatch, modules[argv[0]])
    assert modules[argv[0]].main(args) == 0
    assert made and set(made) == {(48, 27)}, made
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert rows


@pytest.mark.parametrize("argv", [
    ["portals", "--frames", "2", "--warmup", "1"],
    ["mirrors", "--mirrors", "8", "--paths", "auto", "--frames", "2", "--warmup", "1"],
], ids=lambda argv: argv[0])
def test_visibility_modes_run_side_by_side(argv, capsys, own_contexts):
    """``--visibility exact,predicted``: a row per mode (per depth, or mirror count and path),
    each saying the mode its frames used; the modes draw the same views or more when
    predicting (views drawn unseen on last frame's word)."""
    parser, modules = build_parser()
    args = parser.parse_args([*argv, "--json", "--size", "96x54", "--visibility", "exact,predicted"])
    assert modules[argv[0]].main(args) == 0
    rows = [row for row in map(json.loads, capsys.readouterr().out.splitlines()) if "reflection_views" in row]
    by_mode = {}
    for row in rows:
        by_mode.setdefault(row["visibility"], []).append(row)
        assert row["used"] in ("", row["visibility"])
    assert set(by_mode) == {"exact", "predicted"} and len(by_mode["exact"]) == len(by_mode["predicted"])
    assert any(row["used"] == "predicted" for row in by_mode["predicted"])
    for exact, predicted in zip(by_mode["exact"], by_mode["predicted"], strict=True):
        assert predicted["reflection_views"] >= exact["reflection_views"]
    with pytest.raises(SystemExit, match="visibility"):
        modules[argv[0]].main(parser.parse_args([*argv, "--visibility", "sometimes"]))


def test_the_probe_suite_draws_every_part_at_the_size(monkeypatch, capsys, own_contexts):
    """Captures and prefilters run at 128 and 512 texels a face whatever the size (seconds on
    llvmpipe): each part is stood in for by a recorder here; the whole frames run for real."""
    from benchmarks import probes

    asked = []
    monkeypatch.setattr(probes, "capture_rows", lambda ctx, frames, size: asked.append(("capture", size)) or [])
    monkeypatch.setattr(probes, "prefilter_rows", lambda ctx, frames, size: asked.append(("prefilter", size)) or [])
    made = _spy_on_capture_targets(monkeypatch, probes)
    parser, _ = build_parser()
    assert probes.main(parser.parse_args(["probes", "--json", "--size", "48x27", "--frames", "1",
                                          "--warmup", "0"])) == 0
    assert asked == [("capture", (48, 27)), ("prefilter", (48, 27))]
    assert set(made) == {(48, 27)} and len(made) == 4
    assert [json.loads(line)["probe"] for line in capsys.readouterr().out.splitlines()] == \
        ["none", "static", "on_change", "dynamic"]


# Blocks imgui-bundle (an import of it raises ImportError), runs the report, and says whether
# the debug overlay was imported.
WITHOUT_IMGUI = """
import sys
sys.modules["imgui_bundle"] = None
from benchmarks.__main__ import main
status = main(sys.argv[1:])
print("overlay imported:", "shell.overlay" in sys.modules)
sys.exit(status)
"""


def test_gpu_report_writes_markdown_and_json_without_imgui(ctx, tmp_path):
    out = tmp_path / "report"
    done = subprocess.run(
        [sys.executable, "-c", WITHOUT_IMGUI, "gpu-report", "--out", str(out), "--size", "160x90", "--no-tests",
         "--frames", "2"],
        cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True, timeout=120)
    assert "overlay imported: False" in done.stdout
    report = json.loads((out / "report.json").read_text())
    # Exit 1 exactly when a target that applies to this machine is not met (whether it is
    # depends on the machine and its load), each named on stderr; 0 otherwise.
    unmet = [row["target"] for row in report["benchmarks"]["targets"]["own sizes"]["rows"]
             if row["applies"] and not row["met"]]
    assert done.returncode == (1 if unmet else 0), done.stdout[-2000:] + done.stderr[-3000:]
    assert all(f"failed: target {name} not met" in done.stderr for name in unmet), done.stderr
    markdown = (out / "report.md").read_text()

    assert report["complete"] and report["sizes"] == ["160x90"] and report["frames"] == 2
    assert report["gl"]["renderer"] == ctx.info["GL_RENDERER"]
    assert report["gl"]["vendor"] == ctx.info["GL_VENDOR"] and report["gl"]["version"] == ctx.info["GL_VERSION"]
    assert report["gl"]["capability_check"] == "passed"
    assert report["gl"]["software"] == GLCapabilities.read(ctx).software  # True on llvmpipe
    assert report["gl"]["limits"]["GL_MAX_TEXTURE_SIZE"] == ctx.info["GL_MAX_TEXTURE_SIZE"]
    assert set(report["paths"]) >= {"layered_capture", "layered_mips", "direct_faces"}
    for path, verdict in report["paths"].items():
        assert verdict["status"] in ("verified", "refused", "unavailable", "unchecked"), (path, verdict)
        assert verdict["status"] == "verified" or verdict["detail"], (path, verdict)  # a refusal says why
    try:
        from engine.render.path_checks import PATH_NAMES
    except ImportError:  # a checkout without the self-check: every path unchecked
        assert {v["status"] for v in report["paths"].values()} == {"unchecked"}
    else:  # run_all checked every path on the report's context
        assert set(report["paths"]) == {"layered_capture", "layered_mips", "direct_faces", *PATH_NAMES}
        assert "unchecked" not in {v["status"] for v in report["paths"].values()}, report["paths"]
    assert report["tests"] == {"ran": False, "reason": "--no-tests"}

    runs = report["benchmarks"]
    assert set(runs) == {"mirrors", "portals", "probes", "stages", "profile", "targets"}
    targets = runs.pop("targets")  # at the sizes it names, once
    assert set(targets) == {"own sizes"} and targets["own sizes"]["status"] == "ok", targets
    assert "--size" not in targets["own sizes"]["command"] and "--frames 2" in targets["own sizes"]["command"]
    from benchmarks.targets import LIMITS
    assert [row["target"] for row in targets["own sizes"]["rows"]] == list(LIMITS)
    for row in targets["own sizes"]["rows"]:
        assert row["value"] > 0 and row["met"] == (row["value"] <= row["limit"]), row
        assert row["applies"] == (row["set_for"] == "this machine"), row  # llvmpipe: this machine's kind
    assert "## Targets" in markdown and not re.search(r"issue \d", markdown.lower())
    assert "portal_depth_8_ratio" in markdown
    for suite, by_size in runs.items():
        assert set(by_size) == {"160x90"}, suite
        assert by_size["160x90"]["status"] == "ok", by_size["160x90"]
        assert "--size 160x90" in by_size["160x90"]["command"] and "--frames 2" in by_size["160x90"]["command"]
    mirrors = [r for r in runs["mirrors"]["160x90"]["rows"] if "n_mirrors" in r and "path" in r]
    assert {(r["n_mirrors"], r["path"]) for r in mirrors} == \
        {(n, p) for n in (0, 1, 2, 4, 8, 16) for p in ("per_mirror", "batched", "auto")}
    assert all(r["frames"] == 2 and r["frame_ms_median"] > 0 for r in mirrors)
    # Each frame row carries its CPU time and, where the frames had reflection views, the
    # planning time per view (none without mirrors).
    assert all(0 < r["cpu_ms_median"] <= r["frame_ms_median"] for r in mirrors)
    assert all((r["plan_us_per_view"] is None) == (r["reflection_views"] == 0) for r in mirrors)
    assert all(r["plan_us_per_view"] > 0 for r in mirrors if r["n_mirrors"] == 16)
    portal_rows = runs["portals"]["160x90"]["rows"]
    assert all(r["cpu_ms_median"] > 0 and (r["plan_us_per_view"] is None) == (r["depth"] == 0) for r in portal_rows)
    assert [r["depth"] for r in runs["portals"]["160x90"]["rows"]] == list(range(9))
    probe_rows = runs["probes"]["160x90"]["rows"]
    assert [r["probe"] for r in probe_rows if "probe" in r] == ["none", "static", "on_change", "dynamic"]
    assert all(r["cpu_ms_median"] > 0 and "plan_us_per_view" in r for r in probe_rows if "probe" in r)
    assert {(r["path"], r["size"]) for r in probe_rows if "capture_ms_median" in r} == \
        {(p, s) for p in ("six_pass", "layered") for s in (128, 512)}

    # The medians, side by side by size, are read from those rows.
    portals = report["medians"]["portals"][0]
    assert portals["value"] == "frame_ms_median" and [r["160x90"] for r in portals["rows"]] == \
        [r["frame_ms_median"] for r in runs["portals"]["160x90"]["rows"]]
    assert ctx.info["GL_RENDERER"] in markdown
    assert {t["value"] for t in report["medians"]["mirrors"]} == {"frame_ms_median", "cpu_ms_median",
                                                                  "plan_us_per_view"}
    stage_rows = runs["stages"]["160x90"]["rows"]
    assert {r["scene"] for r in stage_rows} == {"mirrors_0", "mirrors_8", "mirrors_16", "probe_dynamic"}
    profiled = runs["profile"]["160x90"]["rows"]
    assert {r["scene"] for r in profiled if "rank" not in r} == {"mirrors_16", "portals_d8", "probe_dynamic"}
    for heading in ("## OpenGL", "## Rendering paths", "## Benchmarks", "### mirrors: frame_ms_median by size",
                    "### profile: mirrors_16 at 160x90", "### profile: probe_dynamic at 160x90",
                    "### stages: gpu_ms_median by size",
                    "### mirrors: plan_us_per_view by size", "### portals: cpu_ms_median by size", "## Test suite"):
        assert heading in markdown, heading


def test_pytest_output_is_read_into_counts_failures_and_skips(tmp_path):
    from benchmarks.gpu_report import _junit_id, junit_messages, parse_pytest

    output = "\n".join([
        "....F.s",
        "=========================== short test summary info ============================",
        "SKIPPED [1] tests/test_window.py:59: Xvfb is not installed",
        "FAILED tests/test_probes.py::test_layered[512] - AssertionError: assert 1 == 2",
        "ERROR tests/test_x.py::Case::test_y",
        "1 failed, 4 passed, 1 skipped, 3 deselected, 1 error in 12.34s",
    ])
    parsed = parse_pytest(output)
    assert (parsed["passed"], parsed["failed"], parsed["skipped"], parsed["errors"], parsed["deselected"]) == \
        (4, 1, 1, 1, 3)
    assert parsed["summary"] == "1 failed, 4 passed, 1 skipped, 3 deselected, 1 error in 12.34s"
    assert parsed["failures"] == [
        {"test": "tests/test_probes.py::test_layered[512]", "outcome": "failed",
         "message": "AssertionError: assert 1 == 2"},
        {"test": "tests/test_x.py::Case::test_y", "outcome": "error", "message": ""}]
    assert parsed["skips"] == ["[1] tests/test_window.py:59: Xvfb is not installed"]

    junit = tmp_path / "junit.xml"
    junit.write_text('<testsuites><testsuite><testcase classname="tests.test_x.Case" name="test_y">'
                     '<error message="RuntimeError: boom"/></testcase></testsuite></testsuites>')
    assert junit_messages(junit) == {"tests.test_x.Case::test_y": "RuntimeError: boom"}
    assert _junit_id("tests/test_x.py::Case::test_y") == "tests.test_x.Case::test_y"


def test_path_verdicts_are_read_from_the_self_check_or_unchecked():
    from benchmarks.gpu_report import PATHS, verdicts_of

    class Verdict:
        def __init__(self, status, detail):
            self.status, self.detail = status, detail

    class Checks:
        ran = 0

        def run_all(self):
            self.ran += 1
            self.verdicts = {"layered_capture": Verdict("verified", "matches six_pass"),
                             "direct_faces": Verdict("refused", "face 3 differs")}

    checks = Checks()
    found = verdicts_of(checks)
    assert checks.ran == 1 and list(found) == list(PATHS)
    assert found["layered_capture"] == {"status": "verified", "detail": "matches six_pass"}
    assert found["direct_faces"] == {"status": "refused", "detail": "face 3 differs"}
    assert found["layered_mips"]["status"] == "unchecked"
    assert all(v["status"] == "unchecked" for v in verdicts_of(None).values())

    class Broken:
        def run_all(self):
            raise RuntimeError("no geometry shaders")

    assert all("RuntimeError: no geometry shaders" in v["detail"] for v in verdicts_of(Broken()).values())


def test_the_profile_finds_the_view_tree_once_a_frame_and_a_plan_a_level(capsys, own_contexts):
    """The portal pair at depth 8 draws one view a level: a frame renders one tree, plans
    each of its 8 levels and the one below them that finds nothing, and no function's own
    time exceeds the frame's."""
    parser, modules = build_parser()
    args = parser.parse_args(["profile", "--scenes", "portals_d8", "--frames", "3", "--warmup", "1", "--top", "400",
                              "--json", "--size", "64x36"])
    assert modules["profile"].main(args) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    head, functions = rows[0], rows[1:]
    assert head["scene"] == "portals_d8" and head["frames"] == 3 and head["reflection_views"] == 8
    assert [r["rank"] for r in functions] == list(range(1, len(functions) + 1))
    def one(path: str, name: str) -> dict:
        found = [r for r in functions if r["function"].startswith(path + ":") and r["function"].endswith(f"({name})")]
        assert len(found) == 1, (path, name, found)
        return found[0]

    tree = one("engine/render/view_tree.py", "render")
    assert tree["calls_per_frame"] == 1.0
    assert one("engine/render/view_plan.py", "plan")["calls_per_frame"] == head["reflection_views"] + 1
    own = [r["own_ms_per_frame"] for r in functions]
    assert own == sorted(own, reverse=True) and 0 < sum(own) <= head["frame_ms_profiled_mean"] * 1.02
    assert tree["total_ms_per_frame"] <= head["frame_ms_profiled_mean"]


def test_the_plan_clock_counts_the_view_trees_planning_and_leaves_the_engine_as_it_was(ctx):
    """``PlanClock`` wraps ViewTree.render and the level's GL calls on their classes while
    open: a frame of 8 mirrors counts the views the frame's stats count, a planning time
    below the tree's whole time, and closing puts every method back."""
    from benchmarks.mirrors import DT, MirrorRing, PlanClock
    from engine.core.frame_io import Output
    from engine.render.mirror_passes import MirrorPasses
    from engine.render.scene_pass import ScenePass
    from engine.render.targets import CaptureTarget
    from engine.render.view_tree import ViewTree
    from shell.app import Engine

    originals = {(owner, name): vars(owner)[name] for owner, name in (*PlanClock.NOT_PLANNING, (ViewTree, "render"))
                 if name in vars(owner)}
    engine = Engine(MirrorRing(8), ctx)
    capture = CaptureTarget(ctx, (160, 90))
    whole = []
    try:
        with PlanClock() as clock:
            assert vars(ViewTree)["render"] is not originals[ViewTree, "render"]
            render = vars(ViewTree)["render"]

            def timed(*args, **kwargs):  # the tree's whole time, around the clock's own wrapper
                import time
                start = time.perf_counter()
                try:
                    return render(*args, **kwargs)
                finally:
                    whole.append(time.perf_counter() - start)
            ViewTree.render = timed
            try:
                engine.frame(DT, Output(capture.framebuffer, (160, 90)))
                clock.reset()
                whole.clear()
                engine.frame(DT, Output(capture.framebuffer, (160, 90)))
            finally:
                ViewTree.render = render
            views = engine.renderer.stats.reflection_views
            assert views > 0 and clock.views == views
            assert 0 < clock.plan_s < sum(whole)
            assert clock.us_per_view() == clock.plan_s * 1e6 / views
            clock.reset()
            assert clock.us_per_view() is None
    finally:
        capture.release()
        engine.close()
    assert all(vars(owner)[name] is method for (owner, name), method in originals.items())
    assert MirrorPasses.prepare_level is originals[MirrorPasses, "prepare_level"]
    assert ScenePass.draw is originals[ScenePass, "draw"]


def test_many_movers_rows_are_gathered_and_the_buffer_holds_every_rows_matrices(ctx):
    """The ECS benchmark's scene with 6,400 entities, 64 moving (16 per batch): after the
    frame that gathers the movers' rows at the front of their batches, a moving frame uploads
    exactly the movers' rows in one span per batch, and every row, in the batch and in its GPU
    buffer, holds its own entity's world matrix."""
    import numpy as np

    from benchmarks.ecs import DT, OUTPUT_SIZE, GridScene
    from components import Transform
    from engine.core.frame_io import Output
    from engine.render.instances import INSTANCE_DTYPE
    from engine.render.targets import CaptureTarget
    from shell.app import Engine

    engine = Engine(GridScene(6400), ctx)
    capture = CaptureTarget(ctx, OUTPUT_SIZE)
    output = Output(capture.framebuffer, OUTPUT_SIZE)
    try:
        for _ in range(3):
            engine.frame(DT, output)
        batches = [b for b in engine.renderer.batches.values() if b.count]
        assert len(batches) == 4
        writes = []
        for batch in batches:
            buffer_write = batch._buffer.write
            batch._buffer.write = lambda data, offset=0, write=buffer_write: writes.append(len(data)) or \
                write(data, offset=offset)
        engine.frame(DT, output)
        movers = len(engine.game.movers)
        assert movers == 64
        assert engine.renderer.stats.uploaded_bytes == movers * INSTANCE_DTYPE.itemsize
        assert len(writes) == len(batches)
        ctx.finish()
        for batch in batches:
            gpu = np.frombuffer(batch._buffer.read(batch.count * INSTANCE_DTYPE.itemsize), INSTANCE_DTYPE)
            assert gpu.tobytes() == batch.rows[: batch.count].tobytes()
            for row, entity in enumerate(batch.entity_at[: batch.count]):
                assert batch.row_of[entity] == row and batch.rows["slots"][row, 3] == entity
                model = engine.world.get(entity, Transform).world
                assert batch.rows["model"][row].tobytes() == model.to_bytes()
    finally:
        capture.release()
        engine.close()


# Blocks imgui-bundle and collects the whole suite: the report runs these tests on GPU
# machines where imgui-bundle is not installed, and there the overlay's tests must skip,
# not stop the collection (a module importing shell.overlay at its top once did).
COLLECT_WITHOUT_IMGUI = """
import sys
sys.modules["imgui_bundle"] = None
import numpy as np
import pytest
sys.exit(pytest.main(["--collect-only", "-q", "-p", "no:cacheprovider", "tests"]))
"""


def test_the_suite_collects_without_imgui():
    done = subprocess.run([sys.executable, "-c", COLLECT_WITHOUT_IMGUI], cwd=ROOT,
                          env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
    assert " error" not in done.stdout.splitlines()[-1], done.stdout[-3000:]
    assert "tests/test_view_budget.py::" in done.stdout


def test_stages_time_every_stage_inside_its_frame(ctx):
    """Every stage of every scene has a row, and the stages' CPU times are parts of the
    frame's: their medians add up to no more than Engine.frame's (plus a little: medians of
    parts need not add up exactly), and the view stages are where the mirrors' time goes.
    The CPU columns are timed here by this thread's CPU time (``time.thread_time``, injected):
    another process's load does not stretch one stage of one frame and not the next."""
    import time

    from benchmarks import stages
    from engine.render.gl_context import prepare_context
    from shell.app import FRAME_STAGES

    rows = stages.run(ctx, (0, 16), frames=3, warmup=1, size=(64, 36), clock=time.thread_time)
    scenes = {r["scene"] for r in rows}
    assert scenes == {"mirrors_0", "mirrors_16", "probe_dynamic"}
    for scene in scenes:
        by_stage = {r["stage"]: r for r in rows if r["scene"] == scene}
        assert set(by_stage) == {*(name for name, _ in FRAME_STAGES), "frame"}, scene
        frame = by_stage.pop("frame")
        assert 0 < frame["cpu_ms_median"] <= frame["frame_ms_median"]
        assert sum(r["cpu_ms_median"] for r in by_stage.values()) <= 1.2 * frame["cpu_ms_median"] + 0.05, scene
        software = prepare_context(ctx).software
        assert all(r["gpu_ms_median"] >= 0 and r["software"] == software for r in by_stage.values())
    reflect = {r["scene"]: r["cpu_ms_median"] for r in rows if r["stage"] == "reflect"}
    assert reflect["mirrors_16"] > 5 * reflect["mirrors_0"]
    probes = {r["scene"]: r["cpu_ms_median"] for r in rows if r["stage"] == "probes"}
    assert probes["probe_dynamic"] > probes["mirrors_0"]


FAILING_TEST = """
import numpy as np

def test_a_frame_that_is_wrong():
    frame = np.full((4, 6, 3), 7, np.uint8)
    frames = [np.zeros((2, 2)), np.ones((2, 2))]
    assert frame.mean() == 0

def test_a_frame_that_is_right():
    frame = np.zeros((4, 6, 3), np.uint8)
    assert frame.mean() == 0
"""


def test_a_failing_tests_frames_are_kept_where_speculum_fail_out_says(tmp_path):
    """What a GPU session cannot look at while the machine is lent: with SPECULUM_FAIL_OUT
    set (gpu-report sets it), each failing test's numpy arrays are saved there as .npz, the
    passing tests' are not."""
    folder = tmp_path / "tests"
    folder.mkdir()
    (folder / "conftest.py").write_text((ROOT / "tests" / "conftest.py").read_text())
    (folder / "test_frames.py").write_text(FAILING_TEST)
    out = tmp_path / "failures"
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(folder)],
                          cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(ROOT), "SPECULUM_FAIL_OUT": str(out)},
                          capture_output=True, text=True, timeout=300)
    assert "1 failed, 1 passed" in done.stdout, done.stdout[-2000:] + done.stderr[-2000:]
    saved = sorted(out.iterdir())
    assert len(saved) == 1 and "test_a_frame_that_is_wrong" in saved[0].name
    with np.load(saved[0]) as arrays:
        frame = next(arrays[key] for key in arrays.files if key.endswith("_frame"))
        assert frame.shape == (4, 6, 3) and (frame == 7).all()
        assert sum(key.endswith(("_frames_0", "_frames_1")) for key in arrays.files) == 2


def test_targets_rows_judge_each_value_against_its_limit_on_the_machine_it_is_set_for():
    from benchmarks.targets import LIMITS, rows
    found = {name: (limit * 0.5, "below") for name, (limit, _, _) in LIMITS.items()}
    found["portal_depth_8_ratio"] = (LIMITS["portal_depth_8_ratio"][0] + 0.01, "just over")
    found["plan_us_per_view"] = (None, "no view")  # no frame had a reflection view: nothing to judge as met
    for software in (True, False):
        table = {row["target"]: row for row in rows(found, software)}
        assert list(table) == list(LIMITS)
        assert not table["portal_depth_8_ratio"]["met"] and not table["plan_us_per_view"]["met"]
        assert table["frame_0_mirrors"]["met"] and table["ecs_cpu_ms"]["met"]
        assert table["frame_16_mirrors_1080p"]["applies"] == (not software)
        assert table["ecs_cpu_ms"]["applies"] == software
