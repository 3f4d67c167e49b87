"""One EGL context for the whole test session (as moderngl's own tests do); every test gets
its own world and must leave the context without a GL error."""
from __future__ import annotations

import contextlib
import os
import re
import shutil
import subprocess

import numpy as np
import pytest

# Debug mode in every engine the tests make (and in their subprocesses): each pass checks
# for a GL error when it ends and names itself (engine.render.renderer.Renderer.checkpoint).
os.environ.setdefault("SPECULUM_DEBUG", "1")

from engine.render.gl_context import GLCapabilities, create_headless_context
from engine.render.raw_gl import make_current
from engine.render.shader_library import FreePrograms
from tests.support import SceneRunner

FREE_PROGRAMS_KEPT = 512

# With SPECULUM_AS_GPU=1, every engine the tests make takes a GPU's branches on llvmpipe
# (``GLCapabilities.software`` False: predicted visibility, the GPU's auto-path thresholds,
# FXAA's edge search, bloom's half-size start, the grid shadow filter), so a machine without
# a GPU runs the code paths only a GPU user's engine takes; all but the anisotropic filter of
# reflections, normal maps and the lights' images, which llvmpipe does not do as the GL says
# (``GLCapabilities.filters_anisotropically``).
# (The tests' own renderer checks read it too: a golden frame is judged by the hardware rule.)
if os.environ.get("SPECULUM_AS_GPU", "") not in ("", "0"):
    GLCapabilities.software = property(lambda self: False)


def workers_fill_the_cores() -> bool:
    """Whether this is one of pytest-xdist's workers and there are no fewer of them than
    cores (CI's two on two): each already has a core, so llvmpipe's rasteriser threads
    only hand each draw to another thread and back."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "0") or 0)
    return workers >= (os.cpu_count() or 1)


def pytest_sessionstart(session):
    """Where the workers fill the cores (``workers_fill_the_cores``) and nobody set
    ``LP_NUM_THREADS``: llvmpipe without rasteriser threads in this worker, drawing on the
    calling thread (7 render-heavy test files took 87-93 s so, 90-99 s with the threads,
    2026-12-07).  llvmpipe reads the variable once a process, when its first context is
    made (every later one shares that screen, released or not), so one is made and released
    here, before any test makes its own; the variable is then put back, so the subprocesses
    the tests start get the environment they were given."""
    if "LP_NUM_THREADS" in os.environ or not workers_fill_the_cores():
        return
    os.environ["LP_NUM_THREADS"] = "0"
    try:
        create_headless_context().release()
    finally:
        del os.environ["LP_NUM_THREADS"]


@pytest.fixture(scope="session")
def ctx():
    context = create_headless_context()
    # The suite's thousands of engines take turns on this context with different programs:
    # the free list keeps more of them than an engine holds (engine/render/shader_library.py).
    FreePrograms.of(context).keep = FREE_PROGRAMS_KEPT
    yield context
    context.release()


@pytest.fixture(autouse=True)
def _no_gl_error(request):
    if "ctx" not in request.fixturenames:
        yield
        return
    context = request.getfixturevalue("ctx")
    # Current first: a test before this one (or this one) may have run a program in this
    # process that made and released a context of its own (tests/support.py's run_level).
    make_current(context)
    assert context.error == "GL_NO_ERROR"
    yield
    make_current(context)
    assert context.error == "GL_NO_ERROR"


@pytest.fixture(autouse=True)
def _strict_gl(request):
    """With SPECULUM_STRICT_GL=1, every test that draws on the shared context runs under the
    GL 4.1 draw check (tests/gl_strict.py) and fails naming what a GPU driver may not
    forgive: a sweep of every feature the suite draws, too slow to be on by default.
    With SPECULUM_NOISY_GL=1, every texture made without data is made full of NaN (float
    images) or noise, every buffer made with room only full of random bytes, as a GPU may
    hand them back (tests/gl_strict.py noisy_textures): a test whose pixels then differ
    reads what no pass wrote (or makes such a texture itself)."""
    strict_on = os.environ.get("SPECULUM_STRICT_GL", "") not in ("", "0")
    if request.node.get_closest_marker("draws_illegal"):  # the checker's own test: its illegal draws
        strict_on = False                                  # are the ones it must name, not failures
    noisy_on = os.environ.get("SPECULUM_NOISY_GL", "") not in ("", "0")
    if not (strict_on or noisy_on) or "ctx" not in request.fixturenames:
        yield
        return
    from tests.gl_strict import noisy_textures, strict_draws

    with contextlib.ExitStack() as stack:
        if noisy_on:
            stack.enter_context(noisy_textures(nan=True))
        strict = stack.enter_context(strict_draws(request.getfixturevalue("ctx"))) if strict_on else None
        yield
    if strict is not None and strict.problems:
        pytest.fail("GL 4.1 draw check:\n" + "\n".join(f"{where}: {problem}"
                                                      for problem, where in strict.problems.items()))


@pytest.fixture
def scene(ctx):
    """``scene(build, size=(w, h))`` -> a SceneRunner; closed (world and GL objects) after the test."""
    runners: list[SceneRunner] = []

    def make(build, size=(160, 120)) -> SceneRunner:
        runner = SceneRunner(ctx, build, size)
        runners.append(runner)
        return runner

    yield make
    for runner in runners:
        runner.close()


def pytest_addoption(parser):
    parser.addoption("--update-golden", action="store_true",
                     help="rewrite tests/golden/ from the frames rendered now (say why in the commit)")


@pytest.fixture(scope="session")
def x_display():
    """A private Xvfb display for the windowed tests (any DISPLAY the machine has is left alone);
    skipped, saying why, without Xvfb or pyglet."""
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        pytest.skip("Xvfb is not installed (apt-get install xvfb): no X server to open a real window on")
    try:
        import pyglet  # noqa: F401
    except ImportError:
        pytest.skip("pyglet is not installed: moderngl-window has no windowed backend")
    read_fd, write_fd = os.pipe()
    server = subprocess.Popen([xvfb, "-displayfd", str(write_fd), "-screen", "0", "640x480x24", "-nolisten", "tcp"],
                              pass_fds=(write_fd,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(write_fd)
    with os.fdopen(read_fd) as pipe:
        number = pipe.readline().strip()  # Xvfb writes its display number once it is ready
    if not number:
        server.kill()
        pytest.skip("Xvfb did not start")
    yield f":{number}"
    server.terminate()
    server.wait(timeout=10)


# A failing test's pictures, kept for a machine one cannot look at while it runs (a GPU host
# lent for minutes): with SPECULUM_FAIL_OUT set, the numpy arrays and frames (``.rgb`` /
# ``.ids``) a failing test held in its own frames are saved to <that folder>/<test id>.npz,
# and its traceback to <test id>.txt.
# ``python -m benchmarks gpu-report`` sets it to <report>/failures.
@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    folder = os.environ.get("SPECULUM_FAIL_OUT")
    if not folder or not report.failed or call.excinfo is None:
        return
    stem = os.path.join(folder, re.sub(r"[^A-Za-z0-9_.-]", "_", item.nodeid)[-150:])
    # Its traceback as pytest reports it, at once: a run stopped before its summary (a lent
    # machine's time running out) still says why each test failed.
    os.makedirs(folder, exist_ok=True)
    with open(stem + ".txt", "w") as text:
        text.write(f"{item.nodeid}\n{report.longreprtext}\n")
    arrays: dict[str, np.ndarray] = {}
    for entry in call.excinfo.traceback:
        if "tests" not in str(entry.path):
            continue
        for name, value in entry.frame.f_locals.items():
            values = value if isinstance(value, (list, tuple)) else (value,)
            for i, one in enumerate(values):
                parts = (("", one), ("_rgb", getattr(one, "rgb", None)), ("_ids", getattr(one, "ids", None)))
                for part, array in parts:
                    if isinstance(array, np.ndarray) and array.nbytes < 4_000_000:
                        suffix = f"_{i}" if len(values) > 1 else ""
                        arrays[f"line{entry.lineno + 1}_{name}{suffix}{part}"] = array
    if arrays:
        np.savez_compressed(stem + ".npz", **arrays)
