"""Profile benchmark: where a frame's CPU time goes, function by function (cProfile).

Scenes, each its own engine, profiled one after the other: the mirrors benchmark's ring with
16 mirrors (``mirrors_16``, the auto path and visibility), the portal pair at recursion depth
8 (``portals_d8``) and the probes benchmark's dynamic probe (``probe_dynamic``, every face
due a frame, those no change reached kept).  Each runs ``--warmup`` frames, then ``--frames``
frames with the profiler on around
``Engine.frame`` only (the ``ctx.finish()`` after each frame is outside it, so on a GPU a
function's time is the CPU's, waits for the GPU inside the frame included).  Rows: per
scene, the ``--top`` functions by their own time (``own_ms_per_frame``: in the function
itself; ``total_ms_per_frame``: with what it calls; ``calls_per_frame``; each the mean over
the frames), and a row with the frames' median and mean wall clock under the profiler.

What it is for: a GPU frame's CPU cost (the ``cpu_ms_median`` of the other suites) in one
call of ``gpu-report``, so a lent GPU machine says which functions to work on.  The
profiler adds about a microsecond to every Python call: compare functions within a run, and
take frame times from the other suites.

    python -m benchmarks profile                    # table
    python -m benchmarks profile --json --top 40
    python -m benchmarks profile --scenes portals_d8 --frames 60
"""
from __future__ import annotations

import argparse
import cProfile
import json
import pstats
import statistics
import time
from pathlib import Path

from benchmarks import add_size_argument, names_from, non_negative_int, positive_int
from engine.core.frame_io import Output
from engine.render.gl_context import create_headless_context
from engine.render.targets import CaptureTarget
from shell.app import Engine

SIZE = (640, 360)
DT = 1.0 / 60.0
ROOT = Path(__file__).resolve().parents[1]


def _mirrors_16(ctx) -> Engine:
    from benchmarks.mirrors import MirrorRing

    return Engine(MirrorRing(16), ctx)


def _portals_d8(ctx) -> Engine:
    from benchmarks.portals import FacingPortals, set_depth

    engine = Engine(FacingPortals(), ctx)
    set_depth(engine, 8)
    # Drawn whole every frame: a still camera's tree is otherwise kept, or only its end images
    # refilled until they settle (the cpu suite's portals_d8 times those frames).
    engine.reflection_system.keep_still_views = False
    return engine


def _probe_dynamic(ctx) -> Engine:
    from benchmarks.probes import ProbeRing

    return Engine(ProbeRing("every_frame"), ctx)


SCENES = {"mirrors_16": _mirrors_16, "portals_d8": _portals_d8, "probe_dynamic": _probe_dynamic}


def _scenes(text: str) -> tuple[str, ...]:
    return names_from(text, tuple(SCENES), "scenes")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--frames", type=positive_int, default=30, help="profiled frames per scene (default 30)")
    parser.add_argument("--warmup", type=non_negative_int, default=5,
                        help="frames before the profiler starts (default 5)")
    parser.add_argument("--top", type=positive_int, default=25, help="functions per scene, by own time (default 25)")
    parser.add_argument("--scenes", type=_scenes, default=tuple(SCENES), metavar="NAME[,NAME...]",
                        help=f"which scenes (default {','.join(SCENES)})")
    add_size_argument(parser, SIZE)


def function_name(key: tuple[str, int, str]) -> str:
    """A pstats key as ``path:line(name)``, the path relative to the repository where it is
    in it, else its package folder and file (``moderngl/__init__.py``); C functions by name."""
    path, line, name = key
    if path == "~":
        return name
    try:
        path = str(Path(path).resolve().relative_to(ROOT))
    except ValueError:
        path = "/".join(Path(path).parts[-2:])
    return f"{path}:{line}({name})"


def profile_frames(ctx, engine, output, frames: int, top: int) -> tuple[list[float], list]:
    """``frames`` frames of ``engine`` under cProfile (around ``Engine.frame`` only, each
    finished before the next): their wall-clock ms and the ``top`` functions by own time, as
    (key, (primitive calls, calls, own s, total s, callers)) pairs."""
    profiler = cProfile.Profile()
    times = []
    for _ in range(frames):
        start = time.perf_counter()
        profiler.enable()
        engine.frame(DT, output)
        profiler.disable()
        times.append((time.perf_counter() - start) * 1e3)
        ctx.finish()
    return times, sorted(pstats.Stats(profiler).stats.items(), key=lambda item: -item[1][2])[:top]


def function_rows(scene: str, ranked: list, frames: int) -> list[dict]:
    """A row a profiled function: its calls and its own and total ms, a frame."""
    return [{"scene": scene, "rank": rank, "function": function_name(key), "calls_per_frame": round(calls / frames, 1),
             "own_ms_per_frame": round(own * 1e3 / frames, 4), "total_ms_per_frame": round(total * 1e3 / frames, 4)}
            for rank, (key, (_, calls, own, total, _)) in enumerate(ranked, 1)]


def profile_scene(ctx, name: str, size: tuple[int, int], frames: int, warmup: int, top: int) -> list[dict]:
    """``top`` functions of ``frames`` profiled frames of scene ``name``, by own time, and the
    frames' median wall clock under the profiler."""
    engine = SCENES[name](ctx)
    capture = CaptureTarget(ctx, size)
    try:
        output = Output(capture.framebuffer, size)
        for _ in range(warmup):
            engine.frame(DT, output)
            ctx.finish()
        times, ranked = profile_frames(ctx, engine, output, frames, top)
        rows = [{"scene": name, "frames": frames, "frame_ms_profiled": round(statistics.median(times), 3),
                 "frame_ms_profiled_mean": round(statistics.fmean(times), 3),
                 "reflection_views": engine.renderer.stats.reflection_views}]
        return rows + function_rows(name, ranked, frames)
    finally:
        capture.release()
        engine.close()


def main(args: argparse.Namespace) -> int:
    ctx = create_headless_context()
    renderer = ctx.info["GL_RENDERER"]
    try:
        rows = [row for name in args.scenes
                for row in profile_scene(ctx, name, args.size, args.frames, args.warmup, args.top)]
        if ctx.error != "GL_NO_ERROR":
            raise RuntimeError(f"OpenGL error: {ctx.error}")
    finally:
        ctx.release()
    if args.json:
        for row in rows:
            print(json.dumps(row))
        return 0
    print(f"CPU profile at {args.size[0]}x{args.size[1]} ({renderer}), ms a frame under cProfile")
    for row in rows:
        if "rank" not in row:
            print(f"\n{row['scene']}: {row['frames']} frames, median {row['frame_ms_profiled']} ms profiled, "
                  f"{row['reflection_views']} reflection views")
            print(f"{'own ms':>9} {'total ms':>9} {'calls':>8}  function")
        else:
            print(f"{row['own_ms_per_frame']:9.3f} {row['total_ms_per_frame']:9.3f} {row['calls_per_frame']:8.1f}  "
                  f"{row['function']}")
    return 0
