"""The benchmark command line: every suite that renders takes ``--size WxH`` (its default
unchanged, a bad value an argparse error, the size reaching the render target), and
``python -m benchmarks gpu-report`` writes report.md and report.json naming this context's
renderer, the sizes asked and each benchmark's rows, with imgui-bundle out of reach."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from benchmarks import RENDERING_SUITES, SUITES, format_size, parse_size
from benchmarks.__main__ import build_parser
from engine.render.gl_context import GLCapabilities, software_renderer
from engine.render.raw_gl import make_current

ROOT = Path(__file__).resolve().parents[1]

# What each rendering suite drew at before --size existed: the default must not move.
DEFAULT_SIZES = {"ecs": (64, 36), "portals": (640, 360), "mirrors": (640, 360), "soak": (320, 180),
                 "churn": (320, 180), "probes": (640, 360), "normal_maps": (640, 360), "stages": (640, 360),
                 "profile": (640, 360), "lighting": (640, 360)}


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
    # (three of its variants: each engine's target is made by the one function the spy watches)
    ["lighting", "--frames", "1", "--warmup", "0", "--parts", "frames", "--report-only", "--variants",
     "off,shadows,glass"],
], ids=lambda argv: argv[0])
def test_the_size_reaches_the_render_target(argv, monkeypatch, capsys, own_contexts):
    parser, modules = build_parser()
    args = parser.parse_args([*argv, "--json", "--size", "48x27"])
    made = _spy_on_capture_targets(monkeypatch, modules[argv[0]])
    assert modules[argv[0]].main(args) == 0
    assert made and set(made) == {(48, 27)}, made
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert rows


def test_the_lighting_stand_in_issues_a_gpus_640x360_passes_at_4x2(ctx, capsys, own_contexts):
    """The lighting suite's cpu part: a process of its own with LP_NUM_THREADS=0, its frames
    at 4x2 with the passes, draws and GL calls of a GPU's 640x360 frame (the bloom chain of
    640x360 from a half start: six levels, eleven draws; the process checks them against a
    640x360 frame it draws itself and fails where they differ), and its two targets judged on
    a software rasteriser.  What the values are is timing: not asserted."""
    from benchmarks.lighting import STAND_IN_VARIANTS, TARGETS

    parser, modules = build_parser()
    args = parser.parse_args(["lighting", "--json", "--parts", "cpu", "--cpu-frames", "3", "--warmup", "1",
                              "--report-only"])
    assert modules["lighting"].main(args) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    frames = {row["variant"]: row for row in rows if "variant" in row}
    assert list(frames) == list(STAND_IN_VARIANTS)
    for row in frames.values():
        assert (row["part"], row["size"], row["stands_in_for"], row["lp_num_threads"]) == ("cpu", "4x2", "640x360", "0")
        assert row["frames"] == 3 and row["frame_ms_median"] > 0 and row["gl_calls"] > 0
    # The post variant's frame: the scene pass, then 11 bloom draws (the present and FXAA draws
    # are not counted as passes); the others only the scene pass.
    assert frames["post"]["passes"] == frames["off"]["passes"] + 11 == frames["shadows"]["passes"] + 11
    assert frames["shadows"]["gl_calls"] == frames["off"]["gl_calls"] < frames["post"]["gl_calls"]
    targets = {row["target"]: row for row in rows if "target" in row}
    software = GLCapabilities.read(ctx).software
    for name in ("cpu_post_0_mirrors", "cpu_shadows_still"):
        target, spec = targets[name], TARGETS[name]
        assert target["limit"] == spec.limit and target["set_for"] == "software" and target["part"] == "cpu"
        assert target["applies"] == software and target["at_its_size"]
        assert target["met"] == (target["value"] <= target["limit"])
        assert target["value"] == round(frames[spec.variant]["frame_ms_median"]
                                        / frames[spec.over]["frame_ms_median"], 3)
    assert "post_0_mirrors" not in targets   # the frames part did not run
    # The bare passes' floor under the post target: (off + 11 bare passes) / off, above 1.
    assert targets["cpu_post_0_mirrors"]["least_possible"] > 1.0
    assert "11 bare passes" in targets["cpu_post_0_mirrors"]["measured"]


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


def test_the_mirror_suite_puts_heavy_spheres_in_the_ring(capsys, own_contexts):
    """``--spheres N``: every ring holds N more spheres of 64 x 32 segments (two triangles a
    quad, 4096 each), and each row says how many triangles a view's pass submits: the
    plain ring's, counted from its meshes here, and the spheres'."""
    from benchmarks.mirrors import BOXES

    parser, modules = build_parser()
    args = parser.parse_args(["mirrors", "--json", "--size", "48x27", "--mirrors", "2", "--paths", "auto",
                              "--frames", "1", "--warmup", "0", "--spheres", "2"])
    assert modules["mirrors"].main(args) == 0
    row, = [row for row in map(json.loads, capsys.readouterr().out.splitlines()) if "triangles" in row]
    ring = 2 + BOXES * 12 + 2 * 2  # the ground's two, a box's twelve, each mirror's two
    assert (row["spheres"], row["triangles"]) == (2, ring + 2 * 64 * 32 * 2)
    with pytest.raises(SystemExit, match="spheres"):
        modules["mirrors"].main(parser.parse_args(["mirrors", "--spheres", "-1"]))


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


def test_gpu_report_makes_the_lighting_stand_in_once_whatever_the_sizes():
    """The report runs every sized suite at each ``--size``, size by size, the lighting suite
    at the later sizes with its ``frames`` part only: its LP_NUM_THREADS=0 stand-in is a 4x2
    frame, the same whatever the size (its rows at the first size)."""
    from benchmarks.gpu_report import FIXED_SIZE, sized_runs

    suites = ("mirrors", "lighting", "cpu")
    runs = sized_runs(suites, [(640, 360), (1920, 1080), (160, 90)])
    assert [(suite, size) for suite, size, _ in runs] == [
        (suite, size) for size in ((640, 360), (1920, 1080), (160, 90)) for suite in suites if suite not in FIXED_SIZE]
    assert [extra for suite, _, extra in runs if suite == "lighting"] == [(), ("--parts", "frames"),
                                                                           ("--parts", "frames")]
    assert all(extra == () for suite, _, extra in runs if suite != "lighting")
    parser, _ = build_parser()
    assert parser.parse_args(["lighting", "--parts", "frames"]).parts == ("frames",)


def test_gpu_report_writes_markdown_and_json_without_imgui(ctx, tmp_path):
    out = tmp_path / "report"
    done = subprocess.run(
        [sys.executable, "-c", WITHOUT_IMGUI, "gpu-report", "--out", str(out), "--size", "160x90", "--no-tests",
         "--frames", "1", "--warmup", "0", "--report-only", "--cpu-parts", "cpu"],
        cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True, timeout=120)
    assert "overlay imported: False" in done.stdout
    report = json.loads((out / "report.json").read_text())
    # --report-only: the targets are judged in the report, not in the exit status (whether
    # they are met depends on the machine and its load).
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
    markdown = (out / "report.md").read_text()

    assert report["complete"] and report["sizes"] == ["160x90"] and report["frames"] == 1
    assert report["gl"]["renderer"] == ctx.info["GL_RENDERER"]
    assert report["gl"]["vendor"] == ctx.info["GL_VENDOR"] and report["gl"]["version"] == ctx.info["GL_VERSION"]
    assert report["gl"]["capability_check"] == "passed"
    # True on llvmpipe: the report's own process reads it from the renderer's name (this one's
    # answer is False under SPECULUM_AS_GPU)
    assert report["gl"]["software"] == software_renderer(ctx.info["GL_RENDERER"])
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
    # The second paths agree (an exit status of 0 says so too: a disagreement fails the report).
    from benchmarks.gpu_report import AGREEMENT_PAIRS
    assert [(row["scene"], row["pixels"]) for row in report["agreement"]["rows"]] == \
        [(scene, 0) for scene, _, _ in AGREEMENT_PAIRS]
    assert "## Second paths (frames that must agree)" in markdown

    runs = report["benchmarks"]
    assert set(runs) == {"mirrors", "portals", "probes", "stages", "profile", "lighting", "cpu"}
    cpu = runs.pop("cpu")  # at the sizes it names, once
    assert set(cpu) == {"own sizes"} and cpu["own sizes"]["status"] == "ok", cpu
    command = cpu["own sizes"]["command"]
    assert "--size" not in command and "--frames 1" in command and "--report-only" in command
    # (The cpu suite's other parts are left out: each is tested here on its own, the ECS part's
    # 100,000 entities alone took most of the report's time; a target of a part not run is
    # reported as not judged.)
    assert "--parts cpu " in command + " " and "--cpu-parts cpu" in report["command"]
    from benchmarks.cpu import TARGETS
    targets = [row for row in cpu["own sizes"]["rows"] if "target" in row]
    assert [row["target"] for row in targets] == list(TARGETS)
    for row in targets:  # the part run: its targets have their values (what they are is timing: not asserted)
        if TARGETS[row["target"]].part != "cpu":
            assert row["value"] is None and row["met"] is None and not row["applies"], row
            continue
        assert row["value"] is not None and row["met"] == (row["value"] <= row["limit"]), row
        # (set for the machine's kind: llvmpipe a software rasteriser, a lent GPU host not)
        assert row["applies"] == ((row["set_for"] == "software") == report["gl"]["software"]), row
    scenes = {(row["scene"], row["size"]): row for row in cpu["own sizes"]["rows"] if "gl_calls" in row}
    assert {scene for scene, size in scenes if size == "32x18"} == \
        {"mirrors_0", "mirrors_8", "mirrors_16", "portals_d0", "portals_d8", "portals_d0_sway", "portals_d8_sway"}
    assert all(row["lp_num_threads"] == "0" for (_, size), row in scenes.items() if size == "32x18")
    assert {size for _, size in scenes} == {"32x18"}   # (the frames, hd and sample parts not run)
    assert "## Targets" in markdown and "cpu_portal_depth_8_ratio" in markdown and "## CPU frames" in markdown
    assert "issue 25" not in markdown
    for suite, by_size in runs.items():
        assert set(by_size) == {"160x90"}, suite
        assert by_size["160x90"]["status"] == "ok", by_size["160x90"]
        assert "--size 160x90" in by_size["160x90"]["command"] and "--frames 1" in by_size["160x90"]["command"]
    mirrors = [r for r in runs["mirrors"]["160x90"]["rows"] if "n_mirrors" in r and "path" in r]
    assert {(r["n_mirrors"], r["path"]) for r in mirrors} == \
        {(n, p) for n in (0, 1, 2, 4, 8, 16) for p in ("per_mirror", "batched", "auto")}
    assert all(r["frames"] == 1 and r["frame_ms_median"] > 0 for r in mirrors)
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
    assert {r["scene"] for r in stage_rows} == {"mirrors_0", "mirrors_8", "mirrors_16", "probe_dynamic",
                                                 "sparks_8_2000"}
    lighting = runs["lighting"]["160x90"]["rows"]
    from benchmarks.lighting import STAND_IN_VARIANTS, VARIANTS
    frame_rows = [r for r in lighting if "variant" in r]
    assert [r["variant"] for r in frame_rows if r["part"] == "frames"] == [v.name for v in VARIANTS]
    assert [r["variant"] for r in frame_rows if r["part"] == "cpu"] == list(STAND_IN_VARIANTS)
    targets = {r["target"]: r for r in lighting if "target" in r}
    assert not targets["post_0_mirrors"]["applies"]  # set for 640x360 on a GPU
    # Its LP_NUM_THREADS=0 stand-in of a GPU's 640x360 frame, judged on a software rasteriser.
    for name in ("cpu_post_0_mirrors", "cpu_shadows_still"):
        assert targets[name]["applies"] == report["gl"]["software"] and targets[name]["part"] == "cpu"
    assert "## Lighting targets" in markdown and "cpu_shadows_still" in markdown
    assert "### lighting: ratio_to_off by size" in markdown
    profiled = runs["profile"]["160x90"]["rows"]
    assert {r["scene"] for r in profiled if "rank" not in r} == {"mirrors_16", "portals_d8", "probe_dynamic"}
    for heading in ("## OpenGL", "## Rendering paths", "## Benchmarks", "### mirrors: frame_ms_median by size",
                    "### profile: mirrors_16 at 160x90", "### profile: probe_dynamic at 160x90",
                    "### cpu: mirrors_16 at 32x18",
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
    buffer, holds its own entity's world matrix (times its size: the cube and the post are
    the unit box's batch, each axis of the matrix scaled by the box's side)."""
    import numpy as np

    from benchmarks.ecs import DT, OUTPUT_SIZE, GridScene
    from components import MeshRef, Transform
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
        assert len(batches) == 3  # the unit box (cubes and posts), the ball, the pebble
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
                model = np.frombuffer(engine.world.get(entity, Transform).world.to_bytes(), np.float32)
                size = engine.world.get(entity, MeshRef).mesh.unit_scale
                columns = model.reshape(4, 4).copy()
                columns[:3] *= np.array(size, np.float32)[:, None]
                assert batch.rows["model"][row].tobytes() == columns.tobytes()
    finally:
        capture.release()
        engine.close()


# Blocks imgui-bundle and collects the whole suite: the report runs these tests on GPU
# machines where imgui-bundle is not installed, and there the overlay's tests must skip,
# not stop the collection (a module importing shell.overlay at its top once did).
COLLECT_WITHOUT_IMGUI = """
import importlib
import sys
from pathlib import Path

sys.modules["imgui_bundle"] = None
from _pytest.outcomes import Skipped

importlib.import_module("tests.conftest")
for path in sorted(Path("tests").glob("test_*.py")):
    try:
        importlib.import_module("tests." + path.stem)
    except Skipped as skipped:
        print("skipped:", path.name, skipped.msg)
    else:
        print("imported:", path.name)
"""


def test_the_suite_collects_without_imgui():
    """A GPU host the suite is carried to has no imgui-bundle (too big to carry): every test
    module imports there, and those of the overlay skip as a whole, saying why.  What pytest's
    collection would fail on is a module's import (its parametrize lists are made there too):
    importing each, without pytest's collection, is that check in a quarter of its time."""
    done = subprocess.run([sys.executable, "-c", COLLECT_WITHOUT_IMGUI], cwd=ROOT,
                          env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
    said = [line.split(" ", 2) for line in done.stdout.splitlines()]   # (kind, file, why a skip)
    assert sorted(words[1] for words in said) == sorted(path.name for path in (ROOT / "tests").glob("test_*.py"))
    skipped = {words[1]: words[2] for words in said if words[0] == "skipped:"}
    assert set(skipped) == {"test_overlay.py", "test_inspector.py"}, skipped
    assert all("imgui-bundle" in why for why in skipped.values()), skipped


NO_RASTERISER_THREADS = 77  # the exit status of a check below that needs them where a process has none


def _in_a_process_of_its_own(check: str) -> None:
    """Run ``check``, a function of this module, in a fresh interpreter: llvmpipe's
    rasteriser threads are what it looks at, and the suite's workers may draw without them
    (``pytest_sessionstart`` in tests/conftest.py); a fresh process has the threads its
    environment gives it.  Skips where ``check`` says it found none it needs."""
    done = subprocess.run([sys.executable, "-c", f"import tests.test_benchmarks as module; module.{check}()"],
                          cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True,
                          timeout=300)
    if done.returncode == NO_RASTERISER_THREADS:
        pytest.skip(done.stdout.strip())
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]


def test_stages_time_every_stage_inside_its_frame():
    """Every stage of every scene has a row, and the stages' CPU times are parts of the
    frame's: their medians add up to no more than Engine.frame's (plus a little: medians of
    parts need not add up exactly), and the view stages are where the mirrors' time goes.
    The CPU columns are timed here by this thread's CPU time (``time.thread_time``, injected):
    another process's load does not stretch one stage of one frame and not the next.  In a
    process of its own, with the rasteriser threads llvmpipe starts there (none on a GPU)."""
    _in_a_process_of_its_own("_stages_check")


def _stages_check() -> None:
    import time

    from benchmarks import stages
    from engine.render.gl_context import create_headless_context, prepare_context
    from shell.app import FRAME_STAGES

    ctx = create_headless_context()
    rows = stages.run(ctx, (0, 16), frames=3, warmup=1, size=(64, 36), clock=time.thread_time)
    scenes = {r["scene"] for r in rows}
    assert scenes == {"mirrors_0", "mirrors_16", "probe_dynamic", f"sparks_8_{stages.SPARKS}"}
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
    particles = {r["scene"]: r["cpu_ms_median"] for r in rows if r["stage"] == "particles"}
    assert particles[f"sparks_8_{stages.SPARKS}"] > particles["mirrors_0"]
    # The rasteriser's CPU time: llvmpipe's threads, where it has any (None elsewhere); the
    # stages' shares are parts of the frame's, which has some (its shadow maps, its views).
    if stages.rasteriser_clocks():
        for scene in scenes:
            by_stage = {r["stage"]: r for r in rows if r["scene"] == scene}
            frame = by_stage.pop("frame")
            assert frame["raster_ms_median"] > 0, scene
            assert sum(r["raster_ms_median"] for r in by_stage.values()) <= 1.2 * frame["raster_ms_median"] + 0.05
            assert all(r["raster_ms_median"] >= 0 for r in by_stage.values())
    else:
        assert all(r["raster_ms_median"] is None for r in rows)


def test_the_rasteriser_clock_counts_llvmpipes_threads_not_this_one():
    """A draw that llvmpipe's threads shade for milliseconds shows in ``RasterClock`` and
    hardly in this thread's CPU time (which issued it and waited).  In a process of its own,
    whose llvmpipe has its threads (skipped where it has none)."""
    _in_a_process_of_its_own("_rasteriser_clock_check")


def _rasteriser_clock_check() -> None:
    import time

    import moderngl

    from benchmarks.stages import RasterClock
    from engine.render.gl_context import create_headless_context

    ctx = create_headless_context()
    clock = RasterClock()
    if not clock.clocks:
        print("no llvmpipe rasteriser threads in a process of its own (a GPU, LP_NUM_THREADS=0, or not Linux)")
        sys.exit(NO_RASTERISER_THREADS)
    target = ctx.texture((320, 180), 4)
    framebuffer = ctx.framebuffer([target])
    program = ctx.program(vertex_shader="#version 410 core\nvoid main() { vec2 p = vec2(gl_VertexID & 1, "
                                        "gl_VertexID >> 1) * 4.0 - 1.0; gl_Position = vec4(p, 0.0, 1.0); }",
                          fragment_shader="#version 410 core\nout vec4 colour; void main() { float s = 0.0; "
                                          "for (int i = 0; i < 400; i++) s += sin(gl_FragCoord.x * 0.01 * float(i)); "
                                          "colour = vec4(s); }")
    vao = ctx.vertex_array(program, [])
    try:
        framebuffer.use()
        vao.render(moderngl.TRIANGLES, vertices=3)  # the shader's compile (this thread's) out of the way
        ctx.finish()
        raster, own = clock(), time.thread_time()
        vao.render(moderngl.TRIANGLES, vertices=3)
        ctx.finish()
        raster, own = clock() - raster, time.thread_time() - own
        assert raster > 0.002 and raster > 5 * own, (raster, own)
    finally:
        ctx.release()


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
    set (gpu-report sets it), each failing test's numpy arrays are saved there as .npz and
    its traceback as .txt (written when it fails: a run stopped before its summary keeps
    them), the passing tests' are not."""
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
    assert [path.suffix for path in saved] == [".npz", ".txt"]
    assert all("test_a_frame_that_is_wrong" in path.name for path in saved)
    assert "assert frame.mean() == 0" in saved[1].read_text()  # (the failing line, in its traceback)
    with np.load(saved[0]) as arrays:
        frame = next(arrays[key] for key in arrays.files if key.endswith("_frame"))
        assert frame.shape == (4, 6, 3) and (frame == 7).all()
        assert sum(key.endswith(("_frames_0", "_frames_1")) for key in arrays.files) == 2


def _scene_row(scene: str, size: str, frame_ms: float) -> dict:
    return {"scene": scene, "size": size, "frames": 1, "frame_ms_median": frame_ms, "cpu_ms_median": frame_ms,
            "thread_ms_median": frame_ms, "views": 0, "passes": 1, "draw_calls": 3, "gl_calls": 40,
            "gl_calls_top": {}, "lp_num_threads": None}


def test_the_cpu_targets_are_read_from_the_scene_rows_and_judged_against_their_limits():
    """Each target's value from the rows of the scenes it compares, met when at or under its
    limit, judged only on the kind of machine its limit is set for and only where measured."""
    from benchmarks.cpu import TARGETS, judge, unmet, values

    rows = [_scene_row("mirrors_0", "32x18", 0.6), _scene_row("mirrors_8", "32x18", 2.5),
            _scene_row("portals_d0", "32x18", 0.5), _scene_row("portals_d8", "32x18", 1.25),
            _scene_row("portals_d0_sway", "32x18", 0.5), _scene_row("portals_d8_sway", "32x18", 1.5),
            _scene_row("mirrors_0", "640x360", 10.0), _scene_row("mirrors_8", "640x360", 14.0),
            _scene_row("probe_none", "640x360", 10.0), _scene_row("probe_dynamic", "640x360", 13.5),
            {"scene": "ecs", "entities": 100_000, "moving": 1000, "frames": 1, "cpu_ms_median": 7.5,
             "frame_ms_median": 50.0, "draw_calls": 5},
            {"scene": "mirrors_0", "rank": 1, "function": "f", "calls_per_frame": 1.0, "own_ms_per_frame": 9.0,
             "total_ms_per_frame": 9.0}]
    found = values(rows)
    assert set(found) == set(TARGETS)
    assert found["cpu_frame_0_mirrors"] == 0.6 and found["cpu_frame_8_mirrors"] == 2.5
    assert found["cpu_frame_16_mirrors"] is None  # its scene did not run
    assert found["cpu_portal_depth_8_ratio"] == 2.5 and found["ratio_8_to_0_mirrors"] == 1.4
    assert found["cpu_portal_moving_ratio"] == 3.0  # the swaying pair's rows, not the still pair's
    assert found["dynamic_probe_share"] == 0.35 and found["gpu_dynamic_probe_ms"] == 3.5
    assert found["ecs_cpu_ms"] == 7.5 and found["gpu_frame_0_mirrors"] == 10.0
    assert found["gpu_portal_depth_8_ratio"] is None and found["gpu_frame_16_mirrors_1080p"] is None
    for software in (True, False):
        table = {row["target"]: row for row in judge(found, software)}
        assert list(table) == list(TARGETS)
        assert table["cpu_frame_0_mirrors"]["met"] and table["cpu_portal_depth_8_ratio"]["met"]  # at the limit
        assert table["ratio_8_to_0_mirrors"]["met"] and table["ecs_cpu_ms"]["met"]
        assert table["cpu_frame_8_mirrors"]["met"] is False and table["dynamic_probe_share"]["met"] is False
        assert table["cpu_portal_moving_ratio"]["met"] is False
        assert table["cpu_frame_16_mirrors"]["met"] is None and not table["cpu_frame_16_mirrors"]["applies"]
        assert table["cpu_frame_8_mirrors"]["applies"] == software
        assert table["gpu_frame_0_mirrors"]["applies"] == (not software)
        assert table["gpu_frame_0_mirrors"]["met"] is False and table["gpu_dynamic_probe_ms"]["met"] is False
        missed = [row["target"] for row in unmet(list(table.values()))]
        assert missed == (["cpu_frame_8_mirrors", "cpu_portal_moving_ratio", "dynamic_probe_share"] if software else
                          ["gpu_frame_0_mirrors", "gpu_dynamic_probe_ms"])


def test_the_cpu_suite_prints_each_target_and_fails_its_exit_status_on_one_not_met(monkeypatch, capsys):
    """The table names every target with its value, limit and verdict; the exit status is 1
    while a target that applies is not met, 0 with --report-only or when all are met."""
    from benchmarks import cpu

    rows = [_scene_row("mirrors_0", "32x18", 0.5), _scene_row("mirrors_8", "32x18", 2.5)]
    monkeypatch.setattr(cpu, "measure", lambda args: (list(rows), True, "a test renderer"))
    parser, _ = build_parser()
    assert cpu.main(parser.parse_args(["cpu"])) == 1
    out, err = capsys.readouterr()
    assert "a test renderer" in out and "not met: cpu_frame_8_mirrors" in err
    lines = {line.split()[0]: line.split() for line in out.splitlines() if line.split() and
             line.split()[0] in cpu.TARGETS}
    assert list(lines) == list(cpu.TARGETS)
    assert lines["cpu_frame_0_mirrors"][1:5] == ["0.5", "0.6", "ms", "yes"]
    assert lines["cpu_frame_8_mirrors"][1:5] == ["2.5", "2.0", "ms", "no"]
    assert lines["cpu_frame_16_mirrors"][1:5] == ["None", "3.5", "ms", "-"]
    assert "issue" not in out.lower()
    assert cpu.main(parser.parse_args(["cpu", "--report-only"])) == 0
    capsys.readouterr()
    assert cpu.main(parser.parse_args(["cpu", "--json"])) == 1
    printed = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert printed[:2] == rows and [row["target"] for row in printed[2:]] == list(cpu.TARGETS)
    rows[1]["frame_ms_median"] = 1.5
    assert cpu.main(parser.parse_args(["cpu"])) == 0


def test_gpu_report_fails_on_a_target_not_met_where_it_applies_unless_told_to_report_only():
    from benchmarks.gpu_report import failed

    target = {"target": "cpu_frame_8_mirrors", "value": 2.5, "limit": 2.0, "unit": "ms", "met": False,
              "applies": True}
    report = {"benchmarks": {"cpu": {"own sizes": {"status": "ok", "exit": 0, "rows": [
        target, {**target, "target": "gpu_frame_0_mirrors", "applies": False},
        {**target, "target": "cpu_frame_0_mirrors", "value": 0.5, "met": True},
        {**target, "target": "ecs_cpu_ms", "value": None, "met": None, "applies": False}]}}}}
    assert failed(report) == ["target cpu_frame_8_mirrors not met: 2.5 ms over 2.0"]
    assert failed(report, targets=False) == []


def test_the_gl_call_counter_counts_each_call_the_engine_makes_once_and_puts_moderngl_back(ctx):
    """Known calls give known counts (a uniform written counts once, though its setter calls
    its write); a raw GL function loaded while counting is allowed counts its calls; with the
    counter closed nothing counts and every moderngl method is the one it was."""
    import _moderngl
    import moderngl

    from benchmarks.cpu import GLCallCounter
    from engine.render import raw_gl
    from engine.render.bindings import invalidate
    from engine.render.targets import release_framebuffer

    program = ctx.program(vertex_shader="#version 410 core\nuniform float scale;\nin vec2 p;\n"
                                        "void main() { gl_Position = vec4(p * scale, 0.0, 1.0); }",
                          fragment_shader="#version 410 core\nout vec4 c;\nvoid main() { c = vec4(1.0); }")
    buffer = ctx.buffer(np.zeros(6, "f4").tobytes())
    vao = ctx.vertex_array(program, [(buffer, "2f", "p")])
    target = ctx.simple_framebuffer((8, 8))
    ctx.enable_only(moderngl.NOTHING)
    ctx.scissor = None
    originals = {(owner, name): attr for owner in GLCallCounter.classes() for name, attr in vars(owner).items()}
    counter = GLCallCounter()
    try:
        with counter.raw_gl_loading():
            flush = raw_gl._load(ctx, "glFlush", raw_gl._VOID_CALL)
        with counter:
            target.use()
            buffer.write(np.array([-1, -1, 3, -1, -1, 3], "f4").tobytes())  # a triangle over the target
            program["scale"].value = 1.0
            vao.render(moderngl.TRIANGLES)
            vao.render(moderngl.TRIANGLES)
            flush()
            assert ctx.error == "GL_NO_ERROR"
            assert counter.calls == {"Framebuffer.use": 1, "Buffer.write": 1, "Uniform.value": 1,
                                     "VertexArray.render": 2, "raw glFlush": 1, "Context.error": 1}
            assert counter.total == 7
            # Each counted call's time, under its label; the outermost only, as the counts.
            assert set(counter.seconds) == set(counter.calls) and min(counter.seconds.values()) > 0
            assert counter.total_seconds == pytest.approx(sum(counter.seconds.values()))
            counter.reset()
            assert counter.total == 0 and counter.total_seconds == 0
        vao.render(moderngl.TRIANGLES)
        flush()
        assert counter.total == 0
        assert ctx.fbo is target and (np.frombuffer(target.read(), np.uint8) == 255).all()  # the draws drew
    finally:
        release_framebuffer(target)  # the bound one: moderngl would bind its deleted name again
        for thing in (vao, buffer, program):
            thing.release()
        invalidate(ctx)  # the engines' state cache: this test set state behind it
    now = {(owner, name): attr for owner in GLCallCounter.classes() for name, attr in vars(owner).items()}
    assert now == originals and vars(_moderngl.Uniform)["value"] is originals[_moderngl.Uniform, "value"]


def test_cpu_scenes_run_their_frames_back_to_back_and_time_the_cold_one_apart(ctx, monkeypatch):
    """The cpu suite's engines take turns in runs (``RUN_FRAMES``): each run's first frame
    follows the other engines' runs and is the cold one, timed apart; the rest follow their own
    engine's frame and are the timed frames, ``frames`` of them a scene.  The GL calls are
    counted on frames that follow their own too."""
    from benchmarks import cpu
    from shell.app import Engine

    order: list[int] = []
    frame = Engine.frame

    def recorded(self, dt, output):
        order.append(id(self))
        return frame(self, dt, output)

    monkeypatch.setattr(Engine, "frame", recorded)
    frames, warmup = 12, 2
    rows = cpu.run_scenes(ctx, ("mirrors_0", "portals_d0"), cpu.CPU_SIZE, frames, warmup)
    runs: list[tuple[int, int]] = []  # (engine, frames back to back)
    for engine in order:
        if runs and runs[-1][0] == engine:
            runs[-1] = (engine, runs[-1][1] + 1)
        else:
            runs.append((engine, 1))
    timed = cpu.RUN_FRAMES - 1
    # Warm-up, then the timed rounds (a cold frame and up to nine timed: 9 + 3), then the
    # counted frames (a cold one and COUNTED_FRAMES).  (The default seed's shuffles never
    # put an engine's run next to its own, where two runs would read as one.)
    expected = [warmup, warmup, timed + 1, timed + 1, frames - timed + 1, frames - timed + 1,
                cpu.COUNTED_FRAMES + 1, cpu.COUNTED_FRAMES + 1]
    assert [length for _, length in runs] == expected and len({engine for engine, _ in runs}) == 2
    for row in rows:
        assert row["frames"] == frames and row["cold_frame_ms_median"] > 0 and row["frame_ms_median"] > 0


def test_the_cpu_part_runs_in_its_own_process_with_no_rasteriser_threads(capsys, own_contexts):
    """``--parts cpu`` on tiny frame counts: each 32x18 scene's row comes from the
    LP_NUM_THREADS=0 process with its views (none without mirrors, a view a portal level),
    its draw calls among its counted GL calls, and a profile of its top functions; only the
    targets of that part have values."""
    from benchmarks import cpu

    parser, _ = build_parser()
    assert cpu.main(parser.parse_args(["cpu", "--parts", "cpu", "--frames", "1", "--warmup", "0", "--top", "3",
                                       "--json", "--report-only"])) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    scenes = {row["scene"]: row for row in rows if "gl_calls" in row}
    assert list(scenes) == list(cpu.CPU_SCENES)
    for row in scenes.values():
        assert row["size"] == "32x18" and row["lp_num_threads"] == "0" and row["frames"] == 1
        # (the draws counted over later frames than the one timed: a first frame draws more)
        assert row["gl_calls"] >= row["gl_calls_top"]["VertexArray.render"] > 0 and row["draw_calls"] > 0, row
        assert 0 < row["cpu_ms_median"] <= row["frame_ms_median"] and row["thread_ms_median"] > 0
        # Time in GL calls is measured inside the frame's: a share of it, the engine's the rest.
        assert 0 < row["gl_share"] < 1 and 0 < row["engine_ms"] < row["cpu_ms_median"], row
        assert "VertexArray.render" in row["gl_ms_top"], row
        assert sum(row["gl_ms_top"].values()) <= row["gl_ms_median"] * cpu.COUNTED_FRAMES + 1e-3, row
    assert scenes["mirrors_0"]["views"] == scenes["portals_d0"]["views"] == 0
    assert scenes["portals_d8"]["views"] == 8 and 0 < scenes["mirrors_8"]["views"] < scenes["mirrors_16"]["views"]
    profiled = [row for row in rows if "rank" in row]
    assert [(row["scene"], row["rank"]) for row in profiled] == [(s, r) for s in cpu.CPU_SCENES for r in (1, 2, 3)]
    targets = {row["target"]: row for row in rows if "target" in row}
    assert list(targets) == list(cpu.TARGETS)
    assert {name for name, row in targets.items() if row["value"] is not None} == \
        {name for name, target in cpu.TARGETS.items() if target.part == "cpu"}


def test_the_views_part_draws_the_16_mirror_ring_with_a_gpu_frames_views_in_a_process_of_its_own(
        ctx, capsys, own_contexts):
    """``--parts views``: the 16-mirror ring at 128x72 from the LP_NUM_THREADS=0 process, one
    row with its engine's share and no target.  A view needs a claimed pixel, so the ring drawn
    here at 32x18 (the cpu part's size, the same camera and frame) has fewer views than that
    row: the part stands for a larger frame's view count."""
    from benchmarks import cpu
    from engine.core.frame_io import Output
    from engine.render.targets import CaptureTarget

    parser, _ = build_parser()
    assert cpu.main(parser.parse_args(["cpu", "--parts", "views", "--frames", "2", "--warmup", "0", "--top", "0",
                                       "--json", "--report-only"])) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    scenes = [row for row in rows if "gl_calls" in row]
    size = format_size(cpu.VIEWS_SIZE)
    assert [(row["scene"], row["size"], row["lp_num_threads"]) for row in scenes] == [("mirrors_16", size, "0")]
    row = scenes[0]
    assert 0 < row["engine_ms"] < row["cpu_ms_median"] <= row["frame_ms_median"] and row["draw_calls"] > 0, row
    make_current(ctx)
    small = cpu.make_scene("mirrors_16", ctx)
    cpu.scale_shadows_down(small)
    # (this frame's counts on any machine: a GPU's predicted visibility draws every candidate on
    # its first frame, where the row's views are those of frames that follow a counted one)
    small.reflection_system.visibility = "exact"
    capture = CaptureTarget(ctx, cpu.CPU_SIZE)
    try:
        for _ in range(2):
            small.frame(cpu.DT, Output(capture.framebuffer, cpu.CPU_SIZE))
        assert 0 < small.renderer.stats.reflection_views < row["views"], (small.renderer.stats.reflection_views, row)
    finally:
        capture.release()
        small.close()
    assert all(target["value"] is None for target in rows if "target" in target)  # (it feeds none)


def test_second_paths_that_part_are_counted_and_fail_the_report(ctx):
    """``agreement_rows`` counts the pixels two engines draw otherwise: a ring whose second
    engine's mirrors reflect half (``Mirror.reflect_rate``) parts at every mirror pixel,
    and the report names the pair among what failed; the same settings twice agree."""
    from benchmarks.gpu_report import agreement_rows, failed
    from components import Mirror

    def half_mirrors(engine) -> None:
        for _, mirror in engine.world.query_one(Mirror):
            mirror.reflect_rate = 0.5

    rows = agreement_rows(ctx, (("mirrors_8", {}, half_mirrors), ("mirrors_8", {}, {})), size=(96, 54), frames=2)
    parted, same = rows
    assert parted["second"] == "half_mirrors" and parted["pixels"] > 200 and parted["max"] > 5, parted
    assert same["pixels"] == 0 and same["max"] == 0, same
    assert failed({"agreement": {"rows": rows}}) == [
        f"second paths disagree: mirrors_8 as made / half_mirrors: {parted['pixels']} pixels, by up to {parted['max']}"]


def test_the_sample_part_draws_the_sample_level_with_its_probes_and_views(capsys, ctx, own_contexts):
    """``--parts sample``: one row, the sample level at 640x360 on llvmpipe (a GPU adds
    1920x1080), a frame with reflection views, probe captures among its passes, and no target
    of its own (every target unmeasured)."""
    from benchmarks import cpu

    parser, _ = build_parser()
    assert cpu.main(parser.parse_args(["cpu", "--parts", "sample", "--frames", "1", "--warmup", "1", "--json",
                                       "--report-only"])) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    scenes = [row for row in rows if "gl_calls" in row]
    software = GLCapabilities.read(ctx).software
    assert [(row["scene"], row["size"]) for row in scenes] == [("hall", "640x360")] + \
        ([] if software else [("hall", "1920x1080")])
    hall = scenes[0]
    assert hall["views"] > 0 and hall["passes"] > hall["views"] + 1 and hall["draw_calls"] > 0, hall
    assert all(row["value"] is None for row in rows if "target" in row)


def test_ab_runs_both_trees_in_alternating_processes_and_prints_their_ratio(capsys, tmp_path):
    """``python -m benchmarks ab``: a tree against itself (A/A) gives one row a scene, each
    side's median from its own processes (old, new, then new, old for the second pair) and
    their ratio; a folder that is no checkout is refused by name before anything starts."""
    from benchmarks import ab

    parser, _ = build_parser()
    assert ab.main(parser.parse_args(["ab", str(ROOT), str(ROOT), "--scenes", "mirrors_1,portals_d0", "--rounds", "2",
                                      "--frames", "1", "--procs", "2", "--warmup", "0", "--json"])) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [row["scene"] for row in rows] == ["mirrors_1", "portals_d0"]
    for row in rows:
        assert [side for side, _ in row["per_process"]] == ["old", "new", "new", "old"]
        assert row["old_ms"] > 0 and row["new_ms"] > 0
        assert row["ratio"] == pytest.approx(row["new_ms"] / row["old_ms"], abs=1e-3)
    with pytest.raises(SystemExit, match="is not a Speculum checkout"):
        ab.main(parser.parse_args(["ab", str(tmp_path), str(ROOT)]))


def test_ab_at_another_size_times_frames_with_the_rasteriser_in_and_gives_the_8_to_0_ratio(capsys):
    """``--size`` other than 32x18: the scenes at that size with the rasteriser in, each row
    with the wall-clock medians (and their ratio), each side's thread and rasteriser CPU, and a
    last row with each side's 8-mirror over 0-mirror wall ratio, read from the rows above."""
    from benchmarks import ab

    parser, _ = build_parser()
    assert ab.main(parser.parse_args(["ab", str(ROOT), str(ROOT), "--scenes", "mirrors_0,mirrors_8", "--size",
                                      "64x36", "--rounds", "2", "--frames", "1", "--procs", "1", "--warmup", "1",
                                      "--json"])) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    rows, summary = lines[:-1], lines[-1]
    assert [row["scene"] for row in rows] == ["mirrors_0", "mirrors_8"]
    for row in rows:
        assert [side for side, _ in row["per_process"]] == ["old", "new"]
        assert row["old_ms"] > 0 and row["new_ms"] > 0
        assert row["ratio"] == pytest.approx(row["new_ms"] / row["old_ms"], abs=1e-3)
        for side in ("old", "new"):
            # one process a side: its median is the side's; the thread's CPU is part of the wall time
            assert dict(row["per_process"])[side] == row[f"{side}_ms"]
            assert 0 < row[f"{side}_thread_ms"] <= row[f"{side}_ms"] + 0.5
            assert row[f"{side}_raster_ms"] >= 0
    by_scene = {row["scene"]: row for row in rows}
    assert summary["size"] == "64x36"
    for side in ("old", "new"):
        assert summary["ratio_8_to_0_mirrors"][side] == pytest.approx(
            by_scene["mirrors_8"][f"{side}_ms"] / by_scene["mirrors_0"][f"{side}_ms"], abs=1e-3)


def test_the_posed_scene_poses_its_meshes_every_frame_and_draws_them(ctx):
    """``posed_<mirrors>_<n>``: n tentacles, each a Skin and a Morph written by the game each
    frame, drawn bent (pixels of their colour) with a row each in the pose texture."""
    from benchmarks.cpu import make_scene
    from components import Morph, Skin
    from engine.core.frame_io import Output
    from engine.render.targets import CaptureTarget

    engine = make_scene("posed_0_3", ctx)
    capture = CaptureTarget(ctx, (96, 54))
    try:
        poses = []
        for _ in range(2):
            engine.frame(1.0 / 60.0, Output(capture.framebuffer, (96, 54)))
            poses.append([skin.joint_matrices for _, skin in engine.world.query_one(Skin)])
        rgb = capture.read_rgb().astype(int)
        assert len(poses[1]) == 3 and len(list(engine.world.query_one(Morph))) == 3
        assert all(not np.array_equal(a, b) for a, b in zip(poses[0], poses[1], strict=True))
        assert len(engine.renderer.pose_rows) == 3
        assert ((rgb[..., 0] > rgb[..., 1] + 40) & (rgb[..., 2] > rgb[..., 1] + 40)).sum() > 10   # purple
    finally:
        capture.release()
        engine.close()


def _scenes_after(ctx, names: tuple[str, ...], size: tuple[int, int], frames: int, dt: float, look) -> dict:
    """Each of the cpu suite's scenes ``names`` (``benchmarks.cpu.make_scene``) drawn ``frames``
    frames of ``dt`` into one capture target of ``size``, one engine after another: what
    ``look(engine, capture)`` finds in each then, by name."""
    from benchmarks.cpu import make_scene
    from engine.core.frame_io import Output
    from engine.render.targets import CaptureTarget

    capture = CaptureTarget(ctx, size)
    found = {}
    try:
        for name in names:
            engine = make_scene(name, ctx)
            try:
                for _ in range(frames):
                    engine.frame(dt, Output(capture.framebuffer, size))
                found[name] = look(engine, capture)
            finally:
                engine.close()
    finally:
        capture.release()
    return found


def test_the_sparks_scene_keeps_about_its_particles_alive_and_draws_them(ctx):
    """``sparks_<mirrors>_<n>``: two emitters at the ring's centre, about n living after a
    lifetime (their rates n / 2 / LIFETIME each), drawn: the frame differs from the same ring's
    without them, frame for frame (the camera's orbit the same)."""
    from benchmarks.sparks import LIFETIME

    frames = _scenes_after(ctx, ("sparks_2_400", "sparks_2_0"), (96, 54), int(LIFETIME * 30) + 5, 1.0 / 30.0,
                           lambda engine, capture: (capture.read_rgb().astype(int), engine.renderer.stats.particles,
                                                    engine.renderer.stats.reflection_views))
    assert 360 <= frames["sparks_2_400"][1] <= 400 and frames["sparks_2_0"][1] == 0
    assert frames["sparks_2_400"][2] > 0
    assert (np.abs(frames["sparks_2_400"][0] - frames["sparks_2_0"][0]).max(axis=2) > 8).sum() >= 5


def test_the_decals_scene_throws_its_stains_and_draws_them(ctx):
    """``decals_<mirrors>_<n>``: n decals on the ring's floor, each cut into a part of its own
    (the floor under every one, some boxes too), drawn: the frame differs from the same ring's
    without them, frame for frame."""
    from components.decal import FromDecal

    frames = _scenes_after(ctx, ("decals_2_12", "decals_2_0"), (96, 54), 3, 1.0 / 30.0,
                           lambda engine, capture: (capture.read_rgb().astype(int),
                                                    len(engine.world.query_one(FromDecal)),
                                                    sum(len(state.pieces)
                                                        for state in engine.stages["decals"].states.values())))
    assert frames["decals_2_12"][1] == 12 and frames["decals_2_0"][1] == 0
    assert frames["decals_2_12"][2] > 12  # each on the floor, and some on boxes
    assert (np.abs(frames["decals_2_12"][0] - frames["decals_2_0"][0]).max(axis=2) > 8).sum() >= 20


def test_the_streaks_scenes_blur_the_ring_by_the_camera_and_the_spinning_boxes(ctx):
    """``streaks_<mirrors>``: the orbiting camera's MotionBlur streaks the spinning boxes by their
    own motion too (movers in the motion table, four passes); ``_camera``: by the camera's alone."""
    from benchmarks.cpu import make_scene

    seen = _scenes_after(ctx, ("streaks_2", "streaks_2_camera"), (192, 108), 3, 1.0 / 30.0,
                         lambda engine, capture: (engine.renderer.object_motion.count,
                                                  engine.renderer.present_pass.motion_blur.passes))
    assert seen["streaks_2"][0] > 0 and seen["streaks_2"][1] == 4
    assert seen["streaks_2_camera"] == (0, 4)
    with pytest.raises(ValueError, match="streaks_2_other"):
        make_scene("streaks_2_other", ctx)


def test_a_scene_named_predicted_draws_its_reflections_with_last_frames_counts(ctx):
    """``<scene>_predicted``: the scene with predicted visibility (a GPU's default); its tree
    says so, the plain scene's is exact on llvmpipe (auto; predicted on a GPU), and with the camera still their
    third frames are equal (last frame's counts are this frame's)."""
    found = _scenes_after(ctx, ("portals_d4", "portals_d4_predicted"), (96, 54), 3, 1.0 / 60.0,
                          lambda engine, capture: (engine.reflection_system.visibility,
                                                   engine.renderer.stats.reflection_visibility, capture.read_rgb()))
    assert found["portals_d4_predicted"][:2] == ("predicted", "predicted")
    assert found["portals_d4"][:2] == ("auto", "exact" if GLCapabilities.read(ctx).software else "predicted")
    assert np.array_equal(found["portals_d4"][2], found["portals_d4_predicted"][2])


def test_the_focus_scene_blurs_the_ring_through_its_lens(ctx):
    """``focus_<mirrors>``: the ring's camera has a DepthOfField with autofocus; its four
    passes run and the frame differs from the plain ring's."""
    frames = _scenes_after(ctx, ("focus_2", "mirrors_2"), (192, 108), 3, 1.0 / 30.0,
                           lambda engine, capture: (capture.read_rgb().astype(int),
                                                    engine.renderer.present_pass.post_passes))
    assert frames["focus_2"][1] >= frames["mirrors_2"][1] + 4
    assert (np.abs(frames["focus_2"][0] - frames["mirrors_2"][0]).max(axis=2) > 8).sum() >= 20


def test_the_gpu_reports_suite_runs_on_the_machines_cores_less_two_where_xdist_is_there(tmp_path):
    """A lent GPU machine's minutes are few: the report's test section runs the suite on
    pytest-xdist workers, the cores less two (at most 14), one process on a small machine
    or without xdist, or what ``--tests-workers`` says; the failures' files are kept."""
    from benchmarks.gpu_report import suite_workers, tests_section

    assert suite_workers(None, cores=16, xdist=True) == 14
    assert suite_workers(None, cores=64, xdist=True) == 14
    assert suite_workers(None, cores=6, xdist=True) == 4
    assert suite_workers(None, cores=2, xdist=True) == 0 and suite_workers(None, cores=16, xdist=False) == 0
    assert suite_workers(3, cores=2, xdist=False) == 3
    result = tests_section(["tests/test_claims_apart.py::test_claims_apart_matches_a_pixel_count"], 300,
                           tmp_path / "failures", workers=2)
    assert " -n 2 " in result["command"] and result["exit"] == 0, result
    assert result["summary"].startswith("1 passed"), result["summary"]
