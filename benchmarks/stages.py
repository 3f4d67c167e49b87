"""Stages benchmark: where a frame's time goes, stage by stage, on the CPU and on the GPU.

Each stage of ``Engine.stages`` (``FRAME_STAGES``: game, rules, ..., main, reflect, present)
is timed twice a frame: the wall clock of its ``process`` call (the CPU's share, including
any wait for the GPU inside it) and the GPU time of the commands it issued (a GL timer
query, ``GL_TIME_ELAPSED``, around the call, read after the frame's ``ctx.finish()``).  On
a GPU that says which stage a frame waits for and whether it is the CPU or the GPU: the
frame-time tables of the other suites cannot.  On llvmpipe (a software rasteriser that
draws on the calling thread at flushes) the GPU column is not a GPU's and is reported with
``software: true``.

Scenes, each its own engine, their frames interleaved (frame i of every engine, then i + 1):
the mirrors benchmark's ring (``benchmarks.mirrors.MirrorRing``) with 0, 8 and 16 mirrors
(``--mirrors``), the ring of 8 with sparks and lit soft smoke keeping ``SPARKS`` particles
alive (``benchmarks.sparks.SparkRing``: the particles stage's CPU and the views' draws of them),
and the probes benchmark's dynamic probe (``ProbeRing``, six faces due a
frame, those no change reached kept; its capture path is fixed to ``six_pass``, since ``auto`` times its candidates with
timer queries of its own, which cannot nest in these).  The engine has no timing code: the
stages' ``process`` methods are wrapped on the instances for the run.

On llvmpipe the rasteriser is threads of this process, so each stage also gets what they
and the engine's thread spent while it ran: ``raster_ms`` (the CPU time of llvmpipe's
threads, read from their per-thread CPU clocks: Linux, the threads named ``llvmpipe-N``;
None elsewhere) and ``thread_ms`` (this thread's CPU time).  With the wall clock they say
how much of a stage the two overlap: on n cores a stage's wall time is at least
(thread + raster) / n, and a stage whose wall time is its thread's CPU time with no
rasteriser time beside it left the rasteriser idle (issue 40's timeline: at 640x360 the
8-mirror frame's reflection levels alternate the two, each waiting for the other).

One JSON row per scene and stage: ``scene``, ``stage``, ``cpu_ms_median``,
``gpu_ms_median``, ``thread_ms_median``, ``raster_ms_median``; and one per scene with
``stage`` "frame": the whole ``Engine.frame`` (``cpu_ms_median``), the frame with its
``ctx.finish()`` (``frame_ms_median``) and the thread's and the rasteriser's CPU time over
that (``thread_ms_median``, ``raster_ms_median``).

    python -m benchmarks stages                 # table
    python -m benchmarks stages --json --size 1920x1080
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from collections.abc import Callable

from benchmarks import add_size_argument, format_size
from benchmarks.mirrors import DT, MirrorRing
from benchmarks.probes import ProbeRing
from benchmarks.sparks import SparkRing
from engine.core.frame_io import Output
from engine.core.game import Game
from engine.render.gl_context import create_headless_context, prepare_context
from engine.render.targets import CaptureTarget
from shell.app import Engine

SIZE = (640, 360)
SPARKS = 2000  # living particles in the sparks scene


def scenes(mirror_counts: tuple[int, ...]) -> list[tuple[str, Callable[[], Game]]]:
    """(name, game factory) of every scene the suite times."""
    found = [(f"mirrors_{n}", lambda n=n: MirrorRing(n)) for n in mirror_counts]
    return [*found, ("probe_dynamic", lambda: ProbeRing("every_frame")),
            (f"sparks_8_{SPARKS}", lambda: SparkRing(8, SPARKS))]


def rasteriser_clocks(prefix: str = "llvmpipe-") -> list[int]:
    """The CPU clocks of this process's software-rasteriser threads (llvmpipe's, named
    ``llvmpipe-N``), for ``time.clock_gettime``: each thread's clock id as glibc's
    ``pthread_getcpuclockid`` makes it from the thread id, ``(~tid << 3) | 6`` (Linux's
    per-thread scheduler clock).  Empty where there is no ``/proc/self/task`` (not Linux) or
    no such thread (a GPU driver; llvmpipe with ``LP_NUM_THREADS=0``, which rasterises on
    the calling thread)."""
    clocks = []
    try:
        tasks = os.listdir("/proc/self/task")
    except OSError:
        return clocks
    for tid in tasks:
        try:
            with open(f"/proc/self/task/{tid}/comm") as comm:
                name = comm.read().strip()
        except OSError:
            continue  # a thread that ended
        if name.startswith(prefix):
            clocks.append(((~int(tid)) << 3) | 6)
    return clocks


class RasterClock:
    """The rasteriser threads' CPU time (``rasteriser_clocks``), in seconds: ``None`` where
    there are none."""

    def __init__(self, clocks: list[int] | None = None) -> None:
        self.clocks = rasteriser_clocks() if clocks is None else clocks

    def __call__(self) -> float | None:
        if not self.clocks:
            return None
        return sum(time.clock_gettime(clock) for clock in self.clocks)


def _ms(start: float | None, end: float | None) -> float | None:
    return None if start is None or end is None else (end - start) * 1e3


class StageClock:
    """Times each stage of one engine: wraps its stages' ``process`` (on the instances) with
    a wall clock, a GL timer query, this thread's CPU clock and the rasteriser threads'
    (``raster``); ``read()`` after the frame's finish gives that frame's {stage: (cpu ms,
    gpu ms, thread ms, raster ms or None)}."""

    def __init__(self, engine: Engine, clock: Callable[[], float] = time.perf_counter,
                 raster: Callable[[], float | None] | None = None) -> None:
        self.ctx = engine.ctx
        self.clock = clock
        self.raster = raster or RasterClock()
        self.cpu: dict[str, tuple[float, float, float | None]] = {}
        self.queries: dict[str, object] = {}
        for name, system in engine.stages.items():
            system.process = self._timed(name, system.process)

    def _timed(self, name: str, process: Callable) -> Callable:
        def timed(*args, **kwargs):
            query = self.queries.get(name)
            if query is None:
                query = self.queries[name] = self.ctx.query(time=True)
            start, own, raster = self.clock(), time.thread_time(), self.raster()
            with query:
                result = process(*args, **kwargs)
            self.cpu[name] = ((self.clock() - start) * 1e3, (time.thread_time() - own) * 1e3,
                              _ms(raster, self.raster()))
            return result
        return timed

    def read(self) -> dict[str, tuple[float, float, float, float | None]]:
        """This frame's times (call after ``ctx.finish()``), then forget them."""
        times = {name: (ms, self.queries[name].elapsed / 1e6, own, raster)
                 for name, (ms, own, raster) in self.cpu.items()}
        self.cpu = {}
        return times


def run(ctx, mirror_counts: tuple[int, ...], frames: int, warmup: int, size: tuple[int, int],
        clock: Callable[[], float] = time.perf_counter) -> list[dict]:
    """Every scene's rows (module docstring), its frames interleaved with the others'.
    ``clock`` (seconds) times the CPU columns: the wall clock by default; a test passes
    ``time.thread_time`` (this thread's CPU time, which another process's load does not
    stretch) so that what it asserts about the stages' shares holds on a loaded machine."""
    software = prepare_context(ctx).software
    raster = RasterClock()  # the rasteriser's threads are the context's: made with it
    built, captures = [], []
    try:
        for name, game in scenes(mirror_counts):
            engine = Engine(game(), ctx)
            if name.startswith("probe"):
                engine.stages["probes"].path = "six_pass"
            capture = CaptureTarget(ctx, size)
            captures.append(capture)
            built.append((name, engine, Output(capture.framebuffer, size), StageClock(engine, clock, raster)))
        samples: dict[str, dict[str, list[tuple]]] = {name: {} for name, *_ in built}
        for frame in range(warmup + frames):
            for name, engine, output, stage_clock in built:
                start, own, rastered = clock(), time.thread_time(), raster()
                engine.frame(DT, output)
                returned = clock()
                ctx.finish()
                finished = clock()
                times = stage_clock.read()
                if frame >= warmup:
                    for stage, sample in times.items():
                        samples[name].setdefault(stage, []).append(sample)
                    samples[name].setdefault("frame", []).append(((returned - start) * 1e3,
                                                                  (finished - start) * 1e3,
                                                                  (time.thread_time() - own) * 1e3,
                                                                  _ms(rastered, raster())))
        if ctx.error != "GL_NO_ERROR":
            raise RuntimeError(f"OpenGL error: {ctx.error}")
        rows = []
        for name, *_ in built:
            for stage, pairs in samples[name].items():
                cpu, other, own = (round(statistics.median(p[i] for p in pairs), 3) for i in range(3))
                rastered = None if pairs[0][3] is None else round(statistics.median(p[3] for p in pairs), 3)
                row = {"scene": name, "stage": stage, "cpu_ms_median": cpu, "software": software,
                       "frames": frames}
                row["frame_ms_median" if stage == "frame" else "gpu_ms_median"] = other
                row["thread_ms_median"], row["raster_ms_median"] = own, rastered
                rows.append(row)
        return rows
    finally:
        for capture in captures:
            capture.release()
        for _, engine, _, _ in built:
            engine.close()


def _ints(text: str) -> tuple[int, ...]:
    return tuple(int(part) for part in text.split(",") if part.strip())


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--mirrors", type=_ints, default=(0, 8, 16), help="mirror counts (default 0,8,16)")
    parser.add_argument("--frames", type=int, default=30, help="timed frames per scene (default 30)")
    parser.add_argument("--warmup", type=int, default=5, help="untimed frames first (default 5)")
    add_size_argument(parser, SIZE)


def main(args: argparse.Namespace) -> int:
    if args.frames < 1 or args.warmup < 0 or any(n < 0 for n in args.mirrors):
        raise SystemExit("--frames must be >= 1, --warmup and --mirrors >= 0")
    ctx = create_headless_context()
    try:
        rows = run(ctx, args.mirrors, args.frames, args.warmup, args.size)
        if args.json:
            for row in rows:
                print(json.dumps(row), flush=True)
            return 0
        print(f"Stages at {format_size(args.size)} ({ctx.info.get('GL_RENDERER', '?')}, medians of {args.frames} "
              f"frames; GPU column by timer query{', not a GPU: software rasteriser' if rows[0]['software'] else ''})")
        def raster(row: dict) -> str:
            value = row["raster_ms_median"]
            return "" if value is None else f"   thread {row['thread_ms_median']:8.3f} ms   raster {value:8.3f} ms"

        for scene in dict.fromkeys(row["scene"] for row in rows):
            frame = next(row for row in rows if row["scene"] == scene and row["stage"] == "frame")
            print(f"{scene}: frame {frame['frame_ms_median']} ms, Engine.frame {frame['cpu_ms_median']} ms"
                  f"{raster(frame)}")
            for row in rows:
                if row["scene"] == scene and row is not frame and (row["cpu_ms_median"] >= 0.005
                                                                   or row["gpu_ms_median"] >= 0.005):
                    print(f"    {row['stage']:14s} cpu {row['cpu_ms_median']:8.3f} ms   "
                          f"gpu {row['gpu_ms_median']:8.3f} ms{raster(row)}")
        return 0
    finally:
        ctx.release()
