"""GPU report: what this machine's OpenGL is, what the engine verified on it, whether the
tests pass on it, what the mirrors, portals, probes and stages benchmarks measure on it, where
its frames' CPU time goes (the profile and cpu suites) and whether the speed targets are met
(the cpu suite), written as ``DIR/report.md`` (to read) and ``DIR/report.json`` (to compare).

Sections, in the order they run (both files are rewritten after each, so a driver crash part
way leaves what came before, with ``"complete": false``):

* ``gl``: ``GL_RENDERER``, ``GL_VENDOR``, ``GL_VERSION`` (``ctx.info``), whether it is a
  software rasteriser, the engine's capability check (``engine.render.gl_context.prepare_context``)
  with each requirement's value next to its minimum, and every ``GL_MAX_*`` limit.
* ``paths``: the rendering paths the engine's self-check verified or refused on this
  context (``Renderer.path_checks.run_all()``: ``layered_capture``, ``layered_mips``,
  ``direct_faces`` and any other path ``engine.render.path_checks.PATH_NAMES`` lists; each
  ``verified``, ``refused``, ``unavailable`` or ``unchecked``, with its detail).  A checkout
  without the self-check reports each path ``unchecked``.
* ``agreement``: frames two paths must draw alike, drawn now (``agreement_section``): the
  ring of mirrors with exact and with predicted visibility, and per mirror and batched; the
  pixels of the third frame that differ by more than 1, and by how much at most.  Where a
  GPU parts them (derivatives, rounding, a read of what no pass wrote) it shows here first,
  without the test suite.
* ``benchmarks``: ``mirrors``, ``portals``, ``probes``, ``stages``, ``profile`` and ``lighting``
  (shadows and post-processing on and off, and its LP_NUM_THREADS=0 stand-in of a GPU's
  640x360 frame, the same at every size: made at the first size only; its targets are
  ``target`` rows, judged here: it runs with ``--report-only``) (``--benchmarks``) at each
  ``--size`` (default 640x360 and 1920x1080), and ``cpu`` once at the sizes it names (its
  targets tabled first, as "Targets", then its scenes' frames and GL calls), each run as
  ``python -m benchmarks <suite> --json --size WxH --frames N --warmup M`` would run it
  (``cpu`` without ``--size`` and with ``--report-only``: this report judges its targets;
  ``--cpu-parts`` its ``--parts``, all by default; in this process, or one subprocess each
  with ``--isolate``); the rows are the suite's own
  JSON lines, kept as they are, and the report's median tables are read from them.
  ``--frames`` (default 10) is per suite and size; the suites' own defaults are 30-60.
  ``profile``'s and ``cpu``'s cProfile rows (the functions a frame's CPU time goes to, per
  scene) get a table each, its first ``PROFILE_ROWS`` functions.
* ``tests``: ``python -m pytest -q`` (plus ``--tests-args``) in a subprocess from the
  repository root, when its ``tests/`` folder is there: passed / failed / errors / skipped
  counts, the failing tests' ids and why tests were skipped; each failing test's arrays
  and frames go to ``DIR/failures/<test>.npz``.  ``--no-tests`` leaves it out.

Exit status 0 when every section ran clean, 1 when a benchmark failed, a test failed, two
second paths parted (``agreement``) or a
speed target that applies to this kind of machine is not met (``--report-only``: targets
are reported only; the report is written either way), 2 for a bad command line.  The test
suite is the longest section (about 5 minutes on a GPU machine's CPU, longer on a slow one;
``--no-tests`` leaves it out), and the report says before it starts.  Nothing here imports the debug
overlay, so the report runs where imgui-bundle is not installed.

On a GPU machine (from the repository root, ``pip install -e ".[dev]"`` done)::

    python -m benchmarks gpu-report --out gpu-report                 # everything, ~minutes
    python -m benchmarks gpu-report --out gpu-report --no-tests      # benchmarks only
    python -m benchmarks gpu-report --out gpu-report --size 2560x1440 --frames 30
    python -m benchmarks gpu-report --out gpu-report --tests-args="-x -k probes"

On a headless Linux GPU box the context is made through EGL: check that ``GL_RENDERER`` in
the report names the GPU, not llvmpipe (with NVIDIA, ``__EGL_VENDOR_LIBRARY_FILENAMES=
/usr/share/glvnd/egl_vendor.d/10_nvidia.json`` picks its EGL when Mesa's is found first).
``SPECULUM_DEBUG=1`` (the test suite's setting) checks for a GL error after every pass;
the report records it, and timings should be taken without it.  CI on llvmpipe runs it at a
tiny size::

    python -m benchmarks gpu-report --out report --size 160x90 --frames 2 --no-tests --report-only
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import platform
import re
import shlex
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path

from benchmarks import format_size, names_from, non_negative_int, parse_sizes, positive_int
from benchmarks.cpu import PARTS as CPU_PARTS
from benchmarks.cpu import RUN_FRAMES

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_SIZES = ((640, 360), (1920, 1080))
BENCHMARKS = ("mirrors", "portals", "probes", "stages", "profile", "lighting", "cpu")
FIXED_SIZE = ("cpu",)  # suites that run at the sizes they name: once, not at each --size
JUDGED = ("cpu", "lighting")  # suites with target rows, run with --report-only: the report judges them
FIXED = "own sizes"  # their runs' key where the others' is a size
PROFILE_ROWS = 15  # functions per scene and size in report.md (report.json keeps every row)
PATHS = ("layered_capture", "layered_mips", "direct_faces")
STATUSES = ("verified", "refused", "unavailable", "unchecked")
SCHEMA = 1

# Per suite, the tables of medians the report lays side by side across sizes: the rows that
# have every key field and the value field, keyed by those fields.
# A frame's CPU cost (``cpu_ms_median``: until Engine.frame returns) and the view trees'
# planning time per reflection view (``plan_us_per_view``) follow each frame table.
MEDIANS: dict[str, tuple[tuple[tuple[str, ...], str], ...]] = {
    "mirrors": ((("n_mirrors", "path", "aa"), "frame_ms_median"), (("n_mirrors", "path", "aa"), "cpu_ms_median"),
                (("n_mirrors", "path", "aa"), "plan_us_per_view")),
    "portals": ((("depth",), "frame_ms_median"), (("depth",), "cpu_ms_median"), (("depth",), "plan_us_per_view")),
    "probes": ((("probe",), "frame_ms_median"), (("probe",), "cpu_ms_median"), (("probe",), "plan_us_per_view"),
               (("path", "culled", "size"), "capture_ms_median"), (("prefilter", "size"), "prefilter_ms_median")),
    "stages": ((("scene", "stage"), "gpu_ms_median"), (("scene", "stage"), "cpu_ms_median"),
               (("scene", "stage"), "frame_ms_median")),
    "lighting": ((("part", "n_mirrors", "variant"), "frame_ms_median"),
                 (("part", "n_mirrors", "variant"), "ratio_to_off"),
                 (("part", "n_mirrors", "variant"), "cpu_ms_median"), (("target",), "value")),
}


def _suites(text: str) -> tuple[str, ...]:
    return names_from(text, BENCHMARKS, "suites")


def _cpu_parts(text: str) -> tuple[str, ...]:
    return names_from(text, CPU_PARTS, "cpu parts")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", type=Path, required=True, metavar="DIR",
                        help="folder for report.md and report.json (made if missing)")
    parser.add_argument("--size", type=parse_sizes, default=DEFAULT_SIZES, metavar="WxH[,WxH...]",
                        help="output sizes the benchmarks run at (default 640x360,1920x1080)")
    parser.add_argument("--frames", type=positive_int, default=10,
                        help="timed frames per suite and size (default 10)")
    parser.add_argument("--warmup", type=non_negative_int, default=2, help="untimed frames first (default 2)")
    parser.add_argument("--benchmarks", type=_suites, default=BENCHMARKS, metavar="NAME[,NAME...]",
                        help=f"which suites (default {','.join(BENCHMARKS)})")
    parser.add_argument("--cpu-parts", type=_cpu_parts, default=CPU_PARTS, metavar="NAME[,NAME...]",
                        help=f"which parts of the cpu suite (default {','.join(CPU_PARTS)}; its --parts: a target "
                             "of a part not run is reported as not judged)")
    parser.add_argument("--isolate", action="store_true",
                        help="run each suite in a subprocess (a driver crash costs that suite, not the report)")
    parser.add_argument("--no-tests", action="store_true",
                        help="do not run the test suite (python -m pytest: about 9.5 minutes on 2 llvmpipe "
                             "cores, 4-5 on a 16-core GPU machine's 14 workers)")
    parser.add_argument("--report-only", action="store_true",
                        help="report the speed targets, met or not, without failing the exit status on them")
    parser.add_argument("--tests-args", type=shlex.split, default=[], metavar="ARGS",
                        help='more pytest arguments, one string: --tests-args="-x -k probes"')
    parser.add_argument("--tests-timeout", type=float, default=3600.0, help="seconds (default 3600)")
    parser.add_argument("--tests-workers", type=non_negative_int, default=None, metavar="N",
                        help="pytest-xdist workers for the test suite (default: the machine's cores less two, "
                             "at most 14, where pytest-xdist is installed and there are 4 cores or more; "
                             "0: one process)")


# -- sections ---------------------------------------------------------------------------------

def _jsonable(value):
    if isinstance(value, (bool, int, float, str)) or value is None:
        return value
    if isinstance(value, (tuple, list)):
        return [_jsonable(v) for v in value]
    return str(value)


def gl_section(ctx) -> dict:
    """Renderer, vendor, version, the capability check and the limits of ``ctx``."""
    from engine.core.errors import GLCapabilityError
    from engine.render.gl_context import REQUIREMENTS, GLCapabilities, prepare_context

    info = ctx.info
    try:
        caps = prepare_context(ctx)
        check = "passed"
    except GLCapabilityError as exc:
        caps = GLCapabilities.read(ctx)
        check = str(exc)
    return {
        "renderer": str(info.get("GL_RENDERER", "?")),
        "vendor": str(info.get("GL_VENDOR", "?")),
        "version": str(info.get("GL_VERSION", "?")),
        "version_code": ctx.version_code,
        "software": caps.software,
        "capability_check": check,
        "requirements": [{"name": name, "have": getattr(caps, name), "minimum": minimum, "for": why}
                         for name, minimum, why in REQUIREMENTS],
        "limits": {key: _jsonable(value) for key, value in sorted(info.items()) if key.startswith("GL_MAX_")},
        "extensions": len(caps.extensions),
    }


def path_section(ctx) -> dict:
    """Each rendering path's verdict from the engine's self-check, run now on ``ctx``."""
    from engine.core.game import Game
    from shell.app import Engine

    class Empty(Game):
        title = "gpu report: path checks"

        def build(self, world) -> None:
            pass

    try:
        from engine.render.path_checks import PATH_NAMES as expected
    except ImportError:
        expected = PATHS
    engine = Engine(Empty(), ctx)
    try:
        return verdicts_of(getattr(engine.renderer, "path_checks", None), (*PATHS, *expected))
    finally:
        engine.close()


def layered_target_section(ctx) -> dict:
    """What the driver reports with a layered cube-map target bound as a capture binds it
    (bound framebuffer, layered attachments, scissor, viewport, texture units the cube is
    on, the loader's ``glFramebufferTexture``): the first thing to read where the layered
    capture is refused."""
    from engine.core.game import Game
    from shell.app import Engine

    class Empty(Game):
        title = "gpu report: layered target"

        def build(self, world) -> None:
            pass

    engine = Engine(Empty(), ctx)
    try:
        return engine.renderer.path_checks.layered_target_state()
    except Exception as exc:  # the report goes on
        return {"error": f"{type(exc).__name__}: {exc}"}
    finally:
        engine.close()


AGREEMENT_SIZE = (192, 108)
AGREEMENT_FRAMES = 3
# (scene, first settings, second settings): ReflectionSystem attributes of two engines that
# must draw the same frame.  A predicted level keeps the node-image test where an exact one
# whose claims lie apart draws without it (view_tree._APART), so the first pair also holds
# the masked build against the unmasked one: on an H200 they parted at 269 pixels by up
# to 54 until a masked level's discard moved last (scene.frag), 2026-12-04.
AGREEMENT_PAIRS = (
    ("mirrors_8", {"visibility": "exact"}, {"visibility": "predicted"}),
    ("mirrors_16", {"visibility": "exact"}, {"visibility": "predicted"}),
    ("mirrors_8", {"path": "per_mirror"}, {"path": "batched"}),
)


def agreement_rows(ctx, pairs=AGREEMENT_PAIRS, size: tuple[int, int] = AGREEMENT_SIZE,
                   frames: int = AGREEMENT_FRAMES) -> list[dict]:
    """For each (scene, settings, settings) of ``pairs`` (``benchmarks.cpu.make_scene``'s
    scenes; ReflectionSystem attributes, or a function of the engine): both engines'
    ``frames``-th frame at ``size``, the pixels whose colour differs by more than 1 (of
    255) and the largest difference."""
    import numpy as np

    from benchmarks.cpu import make_scene
    from engine.core.frame_io import Output
    from engine.render.targets import CaptureTarget

    rows = []
    for scene, first, second in pairs:
        frames_of = []
        for settings in (first, second):
            engine = make_scene(scene, ctx)
            capture = CaptureTarget(ctx, size)
            try:
                if callable(settings):
                    settings(engine)
                else:
                    for name, value in settings.items():
                        setattr(engine.reflection_system, name, value)
                for _ in range(frames):
                    engine.frame(1.0 / 60.0, Output(capture.framebuffer, size))
                frames_of.append(capture.read_rgb().astype(np.int16))
            finally:
                capture.release()
                engine.close()
        delta = np.abs(frames_of[0] - frames_of[1]).max(axis=-1)
        rows.append({"scene": scene, "first": _settings_text(first), "second": _settings_text(second),
                     "pixels": int((delta > 1).sum()), "max": int(delta.max())})
    return rows


def _settings_text(settings) -> str:
    if callable(settings):
        return getattr(settings, "__name__", "a function")
    return ", ".join(f"{name} {value}" for name, value in settings.items()) or "as made"


def agreement_section(ctx) -> dict:
    """``agreement_rows`` on ``ctx``, or why they could not be drawn."""
    try:
        return {"size": format_size(AGREEMENT_SIZE), "frames": AGREEMENT_FRAMES, "rows": agreement_rows(ctx)}
    except Exception as exc:  # the report goes on
        return {"error": f"{type(exc).__name__}: {exc}", "rows": []}


def verdicts_of(checks, expected: tuple[str, ...] = PATHS) -> dict:
    """``checks.run_all()``, then {path: {"status", "detail"}} for every path ``expected`` (and
    any other the self-check names); ``unchecked`` where there is no self-check, it raised, or
    it has no verdict for a path."""
    expected = tuple(dict.fromkeys(expected))

    def every(detail: str) -> dict:
        return {name: {"status": "unchecked", "detail": detail} for name in expected}

    if checks is None:
        return every("this checkout has no rendering-path self-check (Renderer.path_checks)")
    try:
        checks.run_all()
        verdicts = dict(checks.verdicts)
    except Exception as exc:  # the report goes on: this is what it says about the paths
        return every(f"the self-check raised {type(exc).__name__}: {exc}")
    found = {str(name): {"status": str(getattr(v, "status", "unchecked")), "detail": str(getattr(v, "detail", ""))}
             for name, v in verdicts.items()}
    for name in expected:
        found.setdefault(name, {"status": "unchecked", "detail": "the self-check gave no verdict on it"})
    return {name: found[name] for name in (*expected, *sorted(set(found) - set(expected)))}


def sized_runs(suites: tuple[str, ...], sizes: list[tuple[int, int]]) -> list[tuple[str, tuple[int, int], tuple]]:
    """The suites run at each size, size by size: (suite, size, its own options).  The
    lighting suite's LP_NUM_THREADS=0 stand-in (its ``cpu`` part, a 4x2 frame) is the same
    whatever the size, so it is made with the first size only (6 s each time on llvmpipe);
    the later sizes run its ``frames`` part."""
    return [(suite, size, ("--parts", "frames") if suite == "lighting" and index else ())
            for index, size in enumerate(sizes) for suite in suites if suite not in FIXED_SIZE]


def run_suite(name: str, size: tuple[int, int] | None, frames: int, warmup: int, isolate: bool,
              extra: tuple[str, ...] = ()) -> dict:
    """One suite at one size (None: at its own, ``FIXED_SIZE``), as ``python -m benchmarks
    <name> --json ...`` (``extra``: the suite's own options): its JSON rows."""
    argv = [name, "--json", *(("--size", format_size(size)) if size is not None else ()), "--frames", str(frames),
            "--warmup", str(warmup), *(("--report-only",) if name in JUDGED else ()), *extra]
    out, err = io.StringIO(), io.StringIO()
    start = time.perf_counter()
    status: int | str
    if isolate:
        try:
            done = subprocess.run([sys.executable, "-m", "benchmarks", *argv], cwd=ROOT, capture_output=True,
                                  text=True, timeout=3600)
            out.write(done.stdout)
            err.write(done.stderr)
            status = done.returncode
        except subprocess.TimeoutExpired as exc:
            status = f"timed out after {exc.timeout:.0f} s"
    else:
        from benchmarks.__main__ import build_parser

        parser, modules = build_parser()
        args = parser.parse_args(argv)
        try:
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                status = modules[name].main(args)
        except SystemExit as exc:
            status = exc.code if isinstance(exc.code, int) else str(exc.code)
        except Exception:
            status = "raised"
            err.write(traceback.format_exc())
    rows, stray = [], []
    for line in out.getvalue().splitlines():
        try:
            rows.append(json.loads(line))
        except ValueError:
            if line.strip():
                stray.append(line)
    result = {"command": "python -m benchmarks " + " ".join(argv), "status": "ok" if status in (0, None) else "failed",
              "exit": status, "seconds": round(time.perf_counter() - start, 2), "rows": rows}
    problems = "\n".join(stray + err.getvalue().splitlines())
    if problems.strip():
        result["stderr_tail"] = problems[-4000:]
    return result


SUMMARY_WORDS = ("passed", "failed", "error", "errors", "skipped", "xfailed", "xpassed", "deselected", "warning",
                 "warnings")


def parse_pytest(output: str) -> dict:
    """Counts, failing test ids and skip reasons from ``pytest -q -ra`` output."""
    counts = {"passed": 0, "failed": 0, "errors": 0, "skipped": 0, "xfailed": 0, "xpassed": 0, "deselected": 0}
    summary = ""
    lines = output.splitlines()
    for line in reversed(lines):
        found = re.findall(r"(\d+) (" + "|".join(SUMMARY_WORDS) + r")\b", line)
        if found and re.search(r"\bin [\d.]+s\b", line):
            summary = line.strip("= ").strip()
            for number, word in found:
                word = {"error": "errors", "warning": "warnings"}.get(word, word)
                if word in counts:
                    counts[word] = int(number)
            break
    failures, skips = [], []
    for line in lines:
        match = re.match(r"^(FAILED|ERROR) (\S+)(?: - (.*))?$", line)
        if match:
            failures.append({"test": match[2], "outcome": match[1].lower(), "message": (match[3] or "")[:300]})
        elif line.startswith("SKIPPED "):
            skips.append(line[len("SKIPPED "):][:300])
    return {**counts, "summary": summary, "failures": failures, "skips": skips}


def junit_messages(path: Path) -> dict[str, str]:
    """{test id: first line of its failure or error message} from a pytest JUnit XML file."""
    import xml.etree.ElementTree as ElementTree

    try:
        tree = ElementTree.parse(path)
    except (OSError, ElementTree.ParseError):
        return {}
    found = {}
    for case in tree.iter("testcase"):
        for problem in (*case.findall("failure"), *case.findall("error")):
            found[f"{case.get('classname', '')}::{case.get('name', '')}"] = (problem.get("message") or "")[:500]
    return found


def _junit_id(nodeid: str) -> str:
    """``tests/test_x.py::Class::test[p]`` -> ``tests.test_x.Class::test[p]`` (JUnit's classname::name)."""
    parts = nodeid.split("::")
    module = parts[0].removesuffix(".py").replace("/", ".")
    return ".".join([module, *parts[1:-1]]) + "::" + parts[-1]


def suite_workers(asked: int | None, cores: int | None = None, xdist: bool | None = None) -> int:
    """How many pytest-xdist workers run the suite: ``asked``, or by default the machine's
    ``cores`` less two, at most 14, where pytest-xdist is installed and there are 4 cores or
    more (a lent GPU machine's 16 cores: the suite in about 265 s rather than 9.5 minutes);
    0 runs it in one process."""
    if asked is not None:
        return asked
    cores = (os.cpu_count() or 1) if cores is None else cores
    if xdist is None:
        import importlib.util
        xdist = importlib.util.find_spec("xdist") is not None
    return min(cores - 2, 14) if xdist and cores >= 4 else 0


def tests_section(extra: list[str], timeout: float, failures: Path | None = None, workers: int = 0) -> dict:
    """``python -m pytest -q -ra`` from the repository root, in a subprocess (on ``workers``
    pytest-xdist workers: ``suite_workers``); with ``failures``, each failing test's arrays
    and frames are saved there as ``.npz`` and its traceback as ``.txt`` when it fails
    (``SPECULUM_FAIL_OUT``, tests/conftest.py), to look at after the machine is gone."""
    if not (ROOT / "tests").is_dir():
        return {"ran": False, "reason": f"no tests/ folder in {ROOT} (an installed copy of the benchmarks)"}
    with tempfile.TemporaryDirectory(prefix="speculum-gpu-report-") as scratch:
        junit = Path(scratch) / "junit.xml"
        command = [sys.executable, "-m", "pytest", "-q", "-ra", "-p", "no:cacheprovider",
                   *(("-n", str(workers)) if workers else ()), *extra]
        shown = shlex.join(["python", *command[1:]])
        start = time.perf_counter()
        try:
            env = dict(os.environ) if failures is None else {**os.environ, "SPECULUM_FAIL_OUT": str(failures)}
            done = subprocess.run([*command, f"--junitxml={junit}"], cwd=ROOT, capture_output=True, text=True,
                                  timeout=timeout, env=env)
        except subprocess.TimeoutExpired as exc:
            output = exc.stdout.decode(errors="replace") if isinstance(exc.stdout, bytes) else (exc.stdout or "")
            return {"ran": True, "command": shown, "exit": f"timed out after {timeout:.0f} s",
                    "seconds": round(time.perf_counter() - start, 1), **parse_pytest(output),
                    "output_tail": output[-4000:]}
        messages = junit_messages(junit)
    result = {"ran": True, "command": shown, "exit": done.returncode,
              "seconds": round(time.perf_counter() - start, 1), **parse_pytest(done.stdout)}
    for failure in result["failures"]:
        failure["message"] = messages.get(_junit_id(failure["test"])) or failure["message"]
    if done.returncode not in (0, 1) or not result["summary"]:  # crashed, interrupted, usage error
        result["output_tail"] = (done.stdout + done.stderr)[-4000:]
    return result


def host_section() -> dict:
    import moderngl

    def git(*args: str) -> str | None:
        try:
            done = subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, timeout=30)
        except (OSError, subprocess.TimeoutExpired):
            return None
        return done.stdout.strip() if done.returncode == 0 else None

    status = git("status", "--porcelain", "--untracked-files=no")
    return {"python": platform.python_version(), "platform": platform.platform(), "machine": platform.machine(),
            "cpus": os.cpu_count(), "moderngl": moderngl.__version__, "git_commit": git("rev-parse", "HEAD"),
            "git_dirty": None if status is None else bool(status),
            "speculum_debug": os.environ.get("SPECULUM_DEBUG", "") not in ("", "0")}


# -- the report ------------------------------------------------------------------------------

def medians(report: dict) -> dict[str, list[dict]]:
    """Per suite, one table per ``MEDIANS`` entry: {"keys", "value", "rows": [{key..., size: ms}]}."""
    tables: dict[str, list[dict]] = {}
    for suite, runs in report.get("benchmarks", {}).items():
        for keys, value in MEDIANS.get(suite, ()):
            table: dict[tuple, dict] = {}
            for size, run in runs.items():
                for row in run.get("rows", ()):
                    if value in row and all(key in row for key in keys):
                        key = tuple(_jsonable(row[k]) for k in keys)
                        table.setdefault(key, dict(zip(keys, key, strict=True)))[size] = row[value]
            if table:
                tables.setdefault(suite, []).append({"keys": list(keys), "value": value, "rows": list(table.values())})
    return tables


def _one_line(text: str, limit: int = 300) -> str:
    text = " / ".join(line.strip() for line in text.splitlines() if line.strip())
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _cell(value) -> str:
    if isinstance(value, dict):
        value = ", ".join(f"{k}: {v}" for k, v in value.items())
    return str(value).replace("|", "\\|").replace("\n", " ")


def _table(columns: list[str], rows: list[dict]) -> list[str]:
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(_cell(row.get(c, "")) for c in columns) + " |" for row in rows]
    return lines + [""]


def markdown(report: dict) -> str:
    host, gl = report["host"], report.get("gl", {})
    out = ["# Speculum GPU report", ""]
    if not report.get("complete"):
        out += ["**Incomplete**: the run stopped before every section was done.", ""]
    out += [f"- created: {report['created']}", f"- command: `{report['command']}`",
            f"- commit: {host['git_commit'] or '?'}{' (with local changes)' if host['git_dirty'] else ''}",
            f"- python {host['python']}, moderngl {host['moderngl']}, {host['platform']}, {host['cpus']} CPUs"]
    if host["speculum_debug"]:
        out.append("- **SPECULUM_DEBUG is set**: a GL error check after every pass; timings are not representative")
    out.append("")
    if gl:
        out += ["## OpenGL", ""]
        out += _table(["field", "value"], [
            {"field": "GL_RENDERER", "value": gl["renderer"]}, {"field": "GL_VENDOR", "value": gl["vendor"]},
            {"field": "GL_VERSION", "value": gl["version"]},
            {"field": "software rasteriser", "value": "yes" if gl["software"] else "no"},
            {"field": "engine capability check", "value": gl["capability_check"]},
            {"field": "extensions", "value": gl["extensions"]}])
        out += ["Engine requirements:", ""]
        out += _table(["name", "have", "minimum", "for"], gl["requirements"])
        out += ["<details><summary>GL_MAX_* limits</summary>", ""]
        out += _table(["limit", "value"], [{"limit": k, "value": v} for k, v in gl["limits"].items()])
        out += ["</details>", ""]
    if "paths" in report:
        out += ["## Rendering paths (engine self-check)", ""]
        out += _table(["path", "status", "detail"],
                      [{"path": name, **verdict} for name, verdict in report["paths"].items()])
    if "layered_target" in report:
        out += ["## A layered cube-map target as the driver reports it", ""]
        out += _table(["field", "value"], [{"field": k, "value": v} for k, v in report["layered_target"].items()])
    if "agreement" in report:
        agreement = report["agreement"]
        out += ["## Second paths (frames that must agree)", "",
                f"Each pair of engines' frame {agreement.get('frames')} at {agreement.get('size')}: the pixels "
                "whose colour differs by more than 1 of 255 (`pixels`, 0 where they agree) and the largest "
                "difference (`max`).", ""]
        if "error" in agreement:
            out += [f"Not drawn: {agreement['error']}", ""]
        out += _table(["scene", "first", "second", "pixels", "max"], agreement["rows"])
    cpu = report.get("benchmarks", {}).get("cpu", {}).get(FIXED)
    if cpu is not None:
        out += ["## Targets", "",
                "Each measured on the cpu suite's engines at the size it names (`python -m benchmarks cpu`); "
                "`applies`: whether its limit is set for this kind of machine (`set_for`: a software rasteriser "
                "or a GPU; the others are reported, not judged); `met` is empty where its part did not run.", ""]
        out += _table(["target", "value", "limit", "unit", "met", "set_for", "applies", "measured"],
                      [row for row in cpu["rows"] if "target" in row])
        scenes = [row for row in cpu["rows"] if "gl_calls" in row]
        if scenes:
            out += ["## CPU frames", "",
                    "The 32x18 scenes run in a process with `LP_NUM_THREADS=0` (`lp_num_threads`): on llvmpipe "
                    "their frame is the engine's CPU.  Medians, ms, of frames that follow their own engine's "
                    f"(`cold_frame_ms_median`: the first of each run of {RUN_FRAMES}, after the other engines' runs); "
                    "`gl_calls`: "
                    "calls into moderngl and raw GL calls a frame (`python -m benchmarks cpu --help` says what "
                    "counts); `gl_share`: the share of the frame's CPU spent inside them (`gl_ms_top`: in which), "
                    "`engine_ms`: the rest (Python and numpy).", ""]
            out += _table(["scene", "size", "lp_num_threads", "frame_ms_median", "cold_frame_ms_median",
                           "cpu_ms_median", "thread_ms_median", "views", "passes", "draw_calls", "gl_calls",
                           "gl_share", "engine_ms", "gl_calls_top",
                           "gl_ms_top"], scenes)
        ecs = [row for row in cpu["rows"] if row.get("scene") == "ecs"]
        if ecs:
            out += _table(["scene", "entities", "moving", "cpu_ms_median", "frame_ms_median", "draw_calls"], ecs)
    lighting = [{"size": size, **row} for size, run in report.get("benchmarks", {}).get("lighting", {}).items()
                for row in run.get("rows", ()) if "target" in row]
    if lighting:
        out += ["## Lighting targets", "",
                "`python -m benchmarks lighting` at each size: the ratios set for a GPU at 640x360 (`frames`) and "
                "their LP_NUM_THREADS=0 stand-in on a software rasteriser (`cpu`: a 4x2 frame issuing a GPU's "
                "640x360 passes; the same at every size, so made with the first size only), and the shadow maps "
                "a frame draws.", ""]
        out += _table(["size", "target", "value", "limit", "unit", "met", "set_for", "part", "applies", "measured"],
                      lighting)
    if "benchmarks" in report:
        sizes = report["sizes"]
        out += ["## Benchmarks", "",
                f"{report['frames']} timed frames after {report['warmup']} warm-up per suite and size; "
                "times in ms (wall clock around each frame and `ctx.finish()`); `cpu_ms_median` is until "
                "`Engine.frame` returns, without the `ctx.finish()` (on a GPU, the frame's CPU cost); "
                "`plan_us_per_view` is the view trees' planning time per reflection view in microseconds "
                "(None where a frame has no reflection views).", ""]
        for suite, tables in medians(report).items():
            for table in tables:
                out += [f"### {suite}: {table['value']} by size", ""]
                out += _table(table["keys"] + [s for s in sizes if any(s in r for r in table["rows"])], table["rows"])
        out += profile_tables(report)
        if "probes" in report["benchmarks"]:
            out += ["(The probes' capture and prefilter rows draw cube faces of 128 and 512 texels: they do not "
                    "depend on the output size.)", ""]
        out += ["### Every row", "", "Each suite's JSON lines as it printed them, by suite and size.", ""]
        for suite, runs in report["benchmarks"].items():
            for size, run in runs.items():
                out += [f"<details><summary>{suite} at {size}: {run['status']}, {len(run['rows'])} rows, "
                        f"{run['seconds']} s</summary>", "", f"`{run['command']}`", ""]
                groups: dict[tuple, list[dict]] = {}
                for row in run["rows"]:
                    groups.setdefault(tuple(row), []).append(row)
                for columns, rows in groups.items():
                    out += _table(list(columns), rows)
                out += ["</details>", ""]
                if "stderr_tail" in run:
                    out += [f"{suite} at {size} said:", "", "```", run["stderr_tail"][-1500:], "```", ""]
    tests = report.get("tests")
    if tests is not None:
        out += ["## Test suite", ""]
        if not tests["ran"]:
            out += [f"Not run: {tests['reason']}.", ""]
        else:
            out += [f"`{tests['command']}`: exit {tests['exit']}, {tests['seconds']} s", "",
                    f"**{tests['passed']} passed, {tests['failed']} failed, {tests['errors']} errors, "
                    f"{tests['skipped']} skipped** ({tests['summary'] or 'no summary line'})", ""]
            if tests["failures"]:
                out += ["Failures:", ""] + [f"- `{f['test']}` ({f['outcome']}): {_one_line(f['message'])}"
                                           for f in tests["failures"]] + [""]
            if tests["skips"]:
                out += ["Skipped:", ""] + [f"- {s}" for s in tests["skips"]] + [""]
            if "output_tail" in tests:
                out += ["```", tests["output_tail"][-2000:], "```", ""]
    return "\n".join(out)


def profile_tables(report: dict) -> list[str]:
    """The ``profile`` suite's rows as report.md lines: per size and scene, the first
    ``PROFILE_ROWS`` functions by their own time."""
    out = []
    runs = [("profile", size, run) for size, run in report.get("benchmarks", {}).get("profile", {}).items()]
    runs += [("cpu", "32x18", run) for run in report.get("benchmarks", {}).get("cpu", {}).values()]
    for suite, size, run in runs:
        for head in (row for row in run.get("rows", ()) if "frame_ms_profiled" in row):
            out += [f"### {suite}: {head['scene']} at {size} (cProfile, ms a frame; {head['frames']} frames, "
                    f"median {head['frame_ms_profiled']} ms profiled)", ""]
            out += _table(["rank", "own_ms_per_frame", "total_ms_per_frame", "calls_per_frame", "function"],
                          [row for row in run["rows"] if row.get("scene") == head["scene"] and "rank" in row
                           and row["rank"] <= PROFILE_ROWS])
    return out


def write(report: dict, out: Path) -> None:
    report["medians"] = medians(report)
    (out / "report.json").write_text(json.dumps(report, indent=1) + "\n")
    (out / "report.md").write_text(markdown(report))


def failed(report: dict, targets: bool = True) -> list[str]:
    """What went wrong: failed suites, failed or unfinished tests and (``targets``) the speed
    targets that apply here and are not met."""
    found = [f"{suite} at {size}: {run['exit']}" for suite, runs in report.get("benchmarks", {}).items()
             for size, run in runs.items() if run["status"] != "ok"]
    if targets:
        found += [f"target {row['target']} not met: {row['value']} {row['unit']} over {row['limit']}"
                  for runs in report.get("benchmarks", {}).values() for run in runs.values()
                  for row in run.get("rows", ()) if "target" in row and row.get("applies") and not row.get("met")]
    agreement = report.get("agreement") or {}
    if "error" in agreement:
        found.append(f"second paths: {agreement['error']}")
    found += [f"second paths disagree: {row['scene']} {row['first']} / {row['second']}: {row['pixels']} pixels, "
              f"by up to {row['max']}" for row in agreement.get("rows", ()) if row["pixels"]]
    tests = report.get("tests") or {}
    if tests.get("ran") and (tests["exit"] != 0 or tests["failed"] or tests["errors"]):
        found.append(f"tests: {tests['summary'] or 'exit ' + str(tests['exit'])}")
    return found


def command_line(args: argparse.Namespace) -> str:
    """The command that makes this report again."""
    words = ["python", "-m", "benchmarks", "gpu-report", "--out", str(args.out),
             "--size", ",".join(format_size(size) for size in args.size), "--frames", str(args.frames),
             "--warmup", str(args.warmup), "--benchmarks", ",".join(args.benchmarks)]
    if args.cpu_parts != CPU_PARTS:
        words += ["--cpu-parts", ",".join(args.cpu_parts)]
    if args.isolate:
        words.append("--isolate")
    if args.report_only:
        words.append("--report-only")
    if args.no_tests:
        words.append("--no-tests")
    elif args.tests_args:
        words.append("--tests-args=" + shlex.join(args.tests_args))
    return shlex.join(words)


def main(args: argparse.Namespace) -> int:
    from engine.render.gl_context import create_headless_context

    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    sizes = [format_size(size) for size in args.size]
    report: dict = {"schema": SCHEMA, "complete": False, "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                    "command": command_line(args), "host": host_section(), "sizes": sizes, "frames": args.frames,
                    "warmup": args.warmup}

    def progress(text: str) -> None:
        if not args.json:
            print(text, flush=True)

    ctx = create_headless_context()
    try:
        report["gl"] = gl_section(ctx)
        progress(f"{report['gl']['renderer']} | {report['gl']['vendor']} | {report['gl']['version']}")
        write(report, out)
        try:
            report["paths"] = path_section(ctx)
        except Exception as exc:  # no engine on this context (the capability check says why)
            report["paths"] = verdicts_of(None) | {
                name: {"status": "unchecked", "detail": f"no engine to check with: {type(exc).__name__}: {exc}"}
                for name in PATHS}
        progress("paths: " + ", ".join(f"{name} {v['status']}" for name, v in report["paths"].items()))
        report["layered_target"] = layered_target_section(ctx)
        write(report, out)
        report["agreement"] = agreement_section(ctx)
        progress("agreement: " + ("; ".join(f"{row['scene']} {row['first']} / {row['second']}: {row['pixels']} px"
                                            for row in report["agreement"]["rows"])
                                  or report["agreement"].get("error", "")))
        write(report, out)
    finally:
        ctx.release()
    report["benchmarks"] = {suite: {} for suite in args.benchmarks}
    for suite, size, extra in sized_runs(args.benchmarks, args.size):
        text = format_size(size)
        run = report["benchmarks"][suite][text] = run_suite(suite, size, args.frames, args.warmup, args.isolate, extra)
        progress(f"{suite} at {text}: {run['status']}, {len(run['rows'])} rows, {run['seconds']} s")
        write(report, out)
    for suite in (s for s in args.benchmarks if s in FIXED_SIZE):
        extra = ("--parts", ",".join(args.cpu_parts)) if suite == "cpu" and args.cpu_parts != CPU_PARTS else ()
        run = report["benchmarks"][suite][FIXED] = run_suite(suite, None, args.frames, args.warmup, args.isolate,
                                                             extra)
        progress(f"{suite}: {run['status']}, {len(run['rows'])} rows, {run['seconds']} s")
        write(report, out)
    if args.no_tests:
        report["tests"] = {"ran": False, "reason": "--no-tests"}
    else:
        progress("tests: python -m pytest -q ... (the whole test suite: minutes)")
        report["tests"] = tests_section(args.tests_args, args.tests_timeout, args.out / "failures",
                                        suite_workers(args.tests_workers))
        if report["tests"]["ran"]:
            progress(f"tests: {report['tests']['summary'] or 'exit ' + str(report['tests']['exit'])}")
    report["complete"] = True
    write(report, out)
    problems = failed(report, targets=not args.report_only)
    if args.json:
        print(json.dumps(report))
    else:
        print(f"wrote {out / 'report.md'} and {out / 'report.json'}")
        for problem in problems:
            print(f"failed: {problem}", file=sys.stderr)
    return 1 if problems else 0
