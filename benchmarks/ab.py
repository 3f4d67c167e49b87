"""A/B: the ``cpu`` suite's scenes from two code trees, interleaved, as ratios.

How a speed change is judged on a shared, noisy machine (``../shared/measurements``): the
same scenes (``benchmarks.cpu.make_scene``: 32x18, ``LP_NUM_THREADS=0``, the lights' maps
scaled down, so a frame is the engine's CPU) built from the code at OLD and at NEW (two
checkouts, e.g. ``git worktree add /tmp/old HEAD~1``), ``--procs`` processes a side, all
alive at once; rounds of ``--frames`` frames are taken from each process in turn, the order
reversed every other round, so the machine's drift and each process's own bias (a few per
cent between two processes of the same code) fall on both sides alike.  Each frame is timed
by the thread's CPU clock around ``Engine.frame`` and ``ctx.finish()``.  Printed: each
scene's median over all frames of a side, new/old, and each process's median (their spread
is the noise to read a ratio against; an A/A run, the same tree twice, shows it).

With ``--size`` other than 32x18 the scenes are drawn at that size with the rasteriser in, as
the ``cpu`` suite's ``frames`` part draws them (this process's environment, so llvmpipe's
rasteriser threads on; the lights' maps at their own sizes): what the 640x360 targets
measure.  Each frame is then timed three ways: the wall clock around ``Engine.frame`` and
``ctx.finish()`` (the ``ms`` columns and the ratio: what the targets read), this thread's CPU
time (``thread``) and the rasteriser threads' CPU time (``raster``, ``stages.RasterClock``:
0 where there are none).  The two CPU times move much less with other load on the machine
than the wall clock does: on n free cores a frame's wall time is about thread + raster / n
where the two alternate (issue 40), so they say which side of a change moved.  Where the
scenes hold ``mirrors_0`` and ``mirrors_8`` a last line gives each side's 8/0 wall ratio
(the ``ratio_8_to_0_mirrors`` target's).

    python -m benchmarks ab /tmp/old . --scenes mirrors_1,mirrors_2,portals_d8
    python -m benchmarks ab /tmp/old . --scenes mirrors_0,mirrors_8 --size 640x360 --procs 1
    python -m benchmarks ab /tmp/old . --scenes glass_0,glass_20,glass_50   # many see-through batches
    python -m benchmarks ab /tmp/old . --scenes portals_d8_sway_predicted,mirrors_16_predicted  # a GPU's visibility
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

from benchmarks import add_size_argument, format_size

DEFAULT_SCENES = "mirrors_0,mirrors_8,mirrors_16,portals_d0,portals_d8"

CPU_SIZE = (32, 18)  # benchmarks.cpu.CPU_SIZE (not imported: this module reads no engine code)

# Each side's process: imports the benchmark scenes from its own tree (argv[1]), builds every
# scene at argv[3] (WxH), says "ready", then answers each line "N" with N frames of every
# scene (shuffled order each frame) as JSON lists of milliseconds: at the cpu suite's size,
# thread CPU; at any other, [wall, thread CPU, rasteriser CPU] a frame.
_CHILD = """
import json, os, random, sys, time
root, scenes = sys.argv[1], sys.argv[2].split(",")
size = tuple(int(side) for side in sys.argv[3].split("x"))
os.chdir(root)
sys.path.insert(0, root)
from benchmarks.cpu import CPU_SIZE, DT, make_scene, scale_shadows_down
from engine.core.frame_io import Output
from engine.render.gl_context import create_headless_context
from engine.render.targets import CaptureTarget
ctx = create_headless_context()
cpu = size == CPU_SIZE
raster = lambda: 0.0
if not cpu:
    try:
        from benchmarks.stages import RasterClock
        clock = RasterClock()
        raster = lambda: clock() or 0.0
    except ImportError:  # a tree from before the rasteriser's clocks
        pass
engines, outputs = [], []
for name in scenes:
    engine = make_scene(name, ctx)
    if cpu:
        scale_shadows_down(engine)
    engines.append(engine)
    outputs.append(Output(CaptureTarget(ctx, size).framebuffer, size))
order, shuffle = list(range(len(scenes))), random.Random(0).shuffle
print("ready", flush=True)
for line in sys.stdin:
    times = [[] for _ in scenes]
    for _ in range(int(line)):
        shuffle(order)
        for i in order:
            start, wall, rastered = time.thread_time(), time.perf_counter(), raster()
            engines[i].frame(DT, outputs[i])
            ctx.finish()
            own = (time.thread_time() - start) * 1e3
            times[i].append(own if cpu else [(time.perf_counter() - wall) * 1e3, own, (raster() - rastered) * 1e3])
    print(json.dumps(times), flush=True)
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("old", type=Path, help="the tree measured first (the commit before)")
    parser.add_argument("new", type=Path, help="the tree with the change")
    parser.add_argument("--scenes", default=DEFAULT_SCENES,
                        help=f"cpu suite scenes, comma-separated (default {DEFAULT_SCENES}; mirrors_N for any N; "
                             "glass_N: the 8-mirror ring, a see-through pond and N glass panes)")
    parser.add_argument("--rounds", type=int, default=10, help="rounds, each side's processes in turn (default 10)")
    parser.add_argument("--frames", type=int, default=10, help="frames of every scene a process a round (default 10)")
    parser.add_argument("--procs", type=int, default=2, help="processes a side (default 2)")
    parser.add_argument("--warmup", type=int, default=15, help="untimed frames a process first (default 15)")
    add_size_argument(parser, CPU_SIZE, "frame (32x18: the cpu suite's frames, LP_NUM_THREADS=0; any other: "
                                        "with the rasteriser in, timed by wall clock, thread and rasteriser CPU)")


def main(args: argparse.Namespace) -> int:
    for tree in (args.old, args.new):
        if not (tree / "benchmarks" / "cpu.py").is_file():
            raise SystemExit(f"benchmarks ab: {tree} is not a Speculum checkout (no benchmarks/cpu.py)")
    if min(args.rounds, args.frames, args.procs) < 1 or args.warmup < 0:
        raise SystemExit("benchmarks ab: --rounds, --frames and --procs must be >= 1, --warmup >= 0")
    scenes = [s for s in args.scenes.split(",") if s]
    cpu = tuple(args.size) == CPU_SIZE
    env = {**os.environ, "LP_NUM_THREADS": "0"} if cpu else dict(os.environ)
    procs: list[tuple[str, subprocess.Popen]] = []
    for i in range(args.procs):
        for side in (("old", "new") if i % 2 == 0 else ("new", "old")):
            tree = (args.old if side == "old" else args.new).resolve()
            procs.append((side, subprocess.Popen([sys.executable, "-c", _CHILD, str(tree), ",".join(scenes),
                                                  format_size(args.size)],
                                                 stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)))
    try:
        for side, proc in procs:
            if proc.stdout.readline().strip() != "ready":
                raise SystemExit(f"benchmarks ab: the {side} tree's process did not start (its error is above)")

        def run(proc: subprocess.Popen, frames: int) -> list[list[float]]:
            proc.stdin.write(f"{frames}\n")
            proc.stdin.flush()
            return json.loads(proc.stdout.readline())

        if args.warmup:
            for _, proc in procs:
                run(proc, args.warmup)
        per_proc = [[[] for _ in scenes] for _ in procs]
        for r in range(args.rounds):
            for j in (range(len(procs)) if r % 2 == 0 else reversed(range(len(procs)))):
                for i, times in enumerate(run(procs[j][1], args.frames)):
                    per_proc[j][i] += times
    finally:
        for _, proc in procs:
            proc.stdin.close()
            proc.wait()
    rows = []
    for i, scene in enumerate(scenes):
        frames = {s: [t for j, (k, _) in enumerate(procs) if k == s for t in per_proc[j][i]] for s in ("old", "new")}
        wall = {s: times if cpu else [t[0] for t in times] for s, times in frames.items()}
        old, new = statistics.median(wall["old"]), statistics.median(wall["new"])
        each = [(k, round(statistics.median(per_proc[j][i] if cpu else [t[0] for t in per_proc[j][i]]), 3))
                for j, (k, _) in enumerate(procs)]
        row = {"scene": scene, "old_ms": round(old, 3), "new_ms": round(new, 3), "ratio": round(new / old, 3)}
        if not cpu:  # the frame's CPU on this thread and on the rasteriser's
            for s, times in frames.items():
                row[f"{s}_thread_ms"] = round(statistics.median(t[1] for t in times), 3)
                row[f"{s}_raster_ms"] = round(statistics.median(t[2] for t in times), 3)
        row["per_process"] = each
        rows.append(row)
    by_scene = {row["scene"]: row for row in rows}
    eight_to_none = None
    if "mirrors_0" in by_scene and "mirrors_8" in by_scene:  # the ratio_8_to_0_mirrors target's, each side
        eight_to_none = {s: round(by_scene["mirrors_8"][f"{s}_ms"] / by_scene["mirrors_0"][f"{s}_ms"], 3)
                         for s in ("old", "new")}
    if args.json:
        for row in rows:
            print(json.dumps(row))
        if eight_to_none is not None:
            print(json.dumps({"ratio_8_to_0_mirrors": eight_to_none, "size": format_size(args.size)}))
    else:
        cpu_columns = "" if cpu else f" {'thread old/new':>15} {'raster old/new':>17}"
        print(f"{'scene':<12} {'old ms':>8} {'new ms':>8} {'new/old':>8}{cpu_columns}   each process's median (ms)")
        for row in rows:
            each = " ".join(f"{k}:{v:.3f}" for k, v in row["per_process"])
            columns = "" if cpu else (f" {row['old_thread_ms']:7.3f}/{row['new_thread_ms']:<7.3f}"
                                      f" {row['old_raster_ms']:8.3f}/{row['new_raster_ms']:<8.3f}")
            print(f"{row['scene']:<12} {row['old_ms']:8.3f} {row['new_ms']:8.3f} {row['ratio']:8.3f}{columns}   {each}")
        if eight_to_none is not None:
            print(f"8 mirrors over 0 at {format_size(args.size)}: old {eight_to_none['old']:.3f}, "
                  f"new {eight_to_none['new']:.3f}")
    return 0
