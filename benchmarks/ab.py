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

    python -m benchmarks ab /tmp/old . --scenes mirrors_1,mirrors_2,portals_d8
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

DEFAULT_SCENES = "mirrors_0,mirrors_8,mirrors_16,portals_d0,portals_d8"

# Each side's process: imports the benchmark scenes from its own tree (argv[1]), builds every
# scene, says "ready", then answers each line "N" with N frames of every scene (shuffled
# order each frame) as JSON lists of thread-CPU milliseconds.
_CHILD = """
import json, os, random, sys, time
root, scenes = sys.argv[1], sys.argv[2].split(",")
os.chdir(root)
sys.path.insert(0, root)
from benchmarks.cpu import CPU_SIZE, DT, make_scene, scale_shadows_down
from engine.core.frame_io import Output
from engine.render.gl_context import create_headless_context
from engine.render.targets import CaptureTarget
ctx = create_headless_context()
engines, outputs = [], []
for name in scenes:
    engine = make_scene(name, ctx)
    scale_shadows_down(engine)
    engines.append(engine)
    outputs.append(Output(CaptureTarget(ctx, CPU_SIZE).framebuffer, CPU_SIZE))
order, shuffle = list(range(len(scenes))), random.Random(0).shuffle
print("ready", flush=True)
for line in sys.stdin:
    times = [[] for _ in scenes]
    for _ in range(int(line)):
        shuffle(order)
        for i in order:
            start = time.thread_time()
            engines[i].frame(DT, outputs[i])
            ctx.finish()
            times[i].append((time.thread_time() - start) * 1e3)
    print(json.dumps(times), flush=True)
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("old", type=Path, help="the tree measured first (the commit before)")
    parser.add_argument("new", type=Path, help="the tree with the change")
    parser.add_argument("--scenes", default=DEFAULT_SCENES,
                        help=f"cpu suite scenes, comma-separated (default {DEFAULT_SCENES}; mirrors_N for any N)")
    parser.add_argument("--rounds", type=int, default=10, help="rounds, each side's processes in turn (default 10)")
    parser.add_argument("--frames", type=int, default=10, help="frames of every scene a process a round (default 10)")
    parser.add_argument("--procs", type=int, default=2, help="processes a side (default 2)")
    parser.add_argument("--warmup", type=int, default=15, help="untimed frames a process first (default 15)")


def main(args: argparse.Namespace) -> int:
    for tree in (args.old, args.new):
        if not (tree / "benchmarks" / "cpu.py").is_file():
            raise SystemExit(f"benchmarks ab: {tree} is not a Speculum checkout (no benchmarks/cpu.py)")
    if min(args.rounds, args.frames, args.procs) < 1 or args.warmup < 0:
        raise SystemExit("benchmarks ab: --rounds, --frames and --procs must be >= 1, --warmup >= 0")
    scenes = [s for s in args.scenes.split(",") if s]
    env = {**os.environ, "LP_NUM_THREADS": "0"}
    procs: list[tuple[str, subprocess.Popen]] = []
    for i in range(args.procs):
        for side in (("old", "new") if i % 2 == 0 else ("new", "old")):
            tree = (args.old if side == "old" else args.new).resolve()
            procs.append((side, subprocess.Popen([sys.executable, "-c", _CHILD, str(tree), ",".join(scenes)],
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
        side = {s: [t for j, (k, _) in enumerate(procs) if k == s for t in per_proc[j][i]] for s in ("old", "new")}
        old, new = statistics.median(side["old"]), statistics.median(side["new"])
        each = [(k, round(statistics.median(per_proc[j][i]), 3)) for j, (k, _) in enumerate(procs)]
        rows.append({"scene": scene, "old_ms": round(old, 3), "new_ms": round(new, 3), "ratio": round(new / old, 3),
                     "per_process": each})
    if args.json:
        for row in rows:
            print(json.dumps(row))
    else:
        print(f"{'scene':<12} {'old ms':>8} {'new ms':>8} {'new/old':>8}   each process's median (ms)")
        for row in rows:
            each = " ".join(f"{k}:{v:.3f}" for k, v in row["per_process"])
            print(f"{row['scene']:<12} {row['old_ms']:8.3f} {row['new_ms']:8.3f} {row['ratio']:8.3f}   {each}")
    return 0
