"""Targets benchmark: the engine's speed targets, each measured on its own and set against its
limit, so one command (and one ``gpu-report`` section) says which are met on this machine.

Each target runs only the engines it compares, their frames interleaved (one machine's
drift lands on both sides of a ratio or a difference alike), at the size the target names,
whatever ``--size`` the other suites take:

==========================  ==========================================  =======  =============
target                      measured                                     limit    set for
==========================  ==========================================  =======  =============
``frame_0_mirrors``         the mirrors ring with no mirror, 640x360,    0.85 ms  a GPU
                            frame median (Panda3D 1.10: 0.84 on an H200)
``frame_16_mirrors_1080p``  16 mirrors at 1920x1080, frame median        3 ms     a GPU
``portal_depth_8_ratio``    the facing portals at depth 8 over depth 0,  2.5 x    a GPU
                            640x360 (two engines, frames interleaved)
``dynamic_probe_ms``        a probe recaptured every frame less none,    0.3 ms   a GPU
                            640x360 (the probes suite's four engines)
``plan_us_per_view``        16 mirrors, 640x360: the view trees'         10 us    this machine
                            planning time a reflection view
``ecs_cpu_ms``              100,000 entities, 1% moving: the ECS         10 ms    this machine
                            frame's CPU (the ecs suite's ``cpu_ms``)
==========================  ==========================================  =======  =============

Frame times are wall clock around ``Engine.frame`` and ``ctx.finish()`` with each scene's
default settings (``auto`` path and visibility: exact on a software rasteriser, predicted
on a GPU).  "Set for": the machine the limit is set for; ``applies`` says whether
this is one (a GPU target on a software rasteriser is reported, not judged: llvmpipe's
frame is its rasteriser's).  One JSON object a target with ``--json``::

    python -m benchmarks targets                 # table
    python -m benchmarks targets --json --frames 30
"""
from __future__ import annotations

import argparse
import json
import statistics
import time

from benchmarks import non_negative_int, positive_int
from benchmarks.ecs import run_scene as run_ecs
from benchmarks.mirrors import run_scenes
from benchmarks.portals import FacingPortals, set_depth
from benchmarks.probes import frame_rows as probe_frame_rows
from engine.core.frame_io import Output
from engine.render.gl_context import GLCapabilities, create_headless_context
from engine.render.targets import CaptureTarget
from shell.app import Engine

SMALL = (640, 360)
LARGE = (1920, 1080)
ECS_ENTITIES = 100_000
# name -> (limit, unit, the machine the limit is set for)
LIMITS: dict[str, tuple[float, str, str]] = {
    "frame_0_mirrors": (0.85, "ms", "gpu"),
    "frame_16_mirrors_1080p": (3.0, "ms", "gpu"),
    "portal_depth_8_ratio": (2.5, "x", "gpu"),
    "dynamic_probe_ms": (0.3, "ms", "gpu"),
    "plan_us_per_view": (10.0, "us", "this machine"),
    "ecs_cpu_ms": (10.0, "ms", "this machine"),
}


def portal_depths(ctx, depths: tuple[int, ...], frames: int, warmup: int) -> list[float]:
    """Median frame ms of the facing portals at each of ``depths``, an engine each, frames
    interleaved."""
    engines = [Engine(FacingPortals(), ctx) for _ in depths]
    captures = [CaptureTarget(ctx, SMALL) for _ in depths]
    try:
        for engine, depth in zip(engines, depths, strict=True):
            set_depth(engine, depth)
        outputs = [Output(capture.framebuffer, SMALL) for capture in captures]
        times: list[list[float]] = [[] for _ in depths]
        for frame in range(warmup + frames):
            for at, (engine, output) in enumerate(zip(engines, outputs, strict=True)):
                start = time.perf_counter()
                engine.frame(1 / 60, output)
                ctx.finish()
                if frame >= warmup:
                    times[at].append((time.perf_counter() - start) * 1e3)
        return [statistics.median(t) for t in times]
    finally:
        for capture in captures:
            capture.release()
        for engine in engines:
            engine.close()


def measure(ctx, frames: int, warmup: int) -> dict[str, tuple[float, str]]:
    """Each target's value and how it was measured."""
    found: dict[str, tuple[float, str]] = {}
    none, sixteen = run_scenes(ctx, (0, 16), ("auto",), frames, warmup, size=SMALL)
    found["frame_0_mirrors"] = (none.frame_ms_median, "0 mirrors, 640x360, frame ms median")
    found["plan_us_per_view"] = (sixteen.plan_us_per_view, f"16 mirrors, 640x360, {sixteen.visibility} visibility "
                                 f"({sixteen.used}), {sixteen.reflection_views} views")
    (large,) = run_scenes(ctx, (16,), ("auto",), frames, warmup, size=LARGE)
    found["frame_16_mirrors_1080p"] = (large.frame_ms_median, f"16 mirrors, 1920x1080, frame ms median "
                                       f"({large.used} visibility)")
    shallow, deep = portal_depths(ctx, (0, 8), frames, warmup)
    found["portal_depth_8_ratio"] = (round(deep / shallow, 2), f"facing portals, 640x360: depth 8 {deep:.2f} ms over "
                                     f"depth 0 {shallow:.2f} ms")
    probes = {row["probe"]: row["frame_ms_median"] for row in probe_frame_rows(ctx, frames, warmup, SMALL)}
    found["dynamic_probe_ms"] = (round(probes["dynamic"] - probes["none"], 2), f"640x360: every frame "
                                 f"{probes['dynamic']} ms less none {probes['none']} ms")
    ecs = run_ecs(ctx, ECS_ENTITIES, frames, warmup)
    found["ecs_cpu_ms"] = (ecs.cpu_ms_median, f"{ecs.entities} entities, {ecs.moving} moving, CPU ms median")
    return found


def rows(found: dict[str, tuple[float, str]], software: bool) -> list[dict]:
    """The report's rows: each target with its limit and whether it is met (and judged here)."""
    out = []
    for name, (limit, unit, machine) in LIMITS.items():
        value, how = found[name]
        out.append({"target": name, "value": value, "limit": limit, "unit": unit,
                    "met": value is not None and value <= limit, "set_for": machine,
                    "applies": (machine == "this machine") == software, "measured": how})
    return out


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--frames", type=positive_int, default=30, help="timed frames per engine (default 30)")
    parser.add_argument("--warmup", type=non_negative_int, default=5, help="untimed frames first (default 5)")


def main(args: argparse.Namespace) -> int:
    ctx = create_headless_context()
    try:
        software = GLCapabilities.read(ctx).software
        found = rows(measure(ctx, args.frames, args.warmup), software)
        if ctx.error != "GL_NO_ERROR":
            raise RuntimeError(f"OpenGL error: {ctx.error}")
        renderer = ctx.info.get("GL_RENDERER", "?")
    finally:
        ctx.release()
    if args.json:
        for row in found:
            print(json.dumps(row))
        return 0
    print(f"Speed targets on {renderer} ({args.frames} frames after {args.warmup} warm-up)")
    print(f"{'target':<24} {'value':>8} {'limit':>9} {'met':>6} {'set for':>13}  measured")
    for row in found:
        met = ("yes" if row["met"] else "no") if row["applies"] else "(n/a)"
        limit = f"{row['limit']} {row['unit']}"
        print(f"{row['target']:<24} {row['value']!s:>8} {limit:>9} {met:>6} {row['set_for']:>13}  {row['measured']}")
    return 0
