"""Soak: the sample level on a camera tour for many frames; the engine's GL resources and
the process's memory, printed as it goes, must stay flat.

The camera circles the hall (radius 4.5 m about (0, 1.6, -1), once every 600 frames, a
slow bob up and down) at 320 x 180 (``--size``), so views of mirrors, portals and probes come and go.
Printed at the start, every ``--every`` frames and at the end (one JSON object a line with
``--json``): the frame, the renderer's live GL resources by kind (``resource_counts``), the
resident memory (MiB) and the median frame time since the last line.  The exit status is 1
when a resource count or the memory grew between the first report after warm-up and the
last (memory by more than ``--rss-slack`` MiB).

    python -m benchmarks soak --frames 10000

``--lens`` puts depth of field and motion blur on the camera; ``--dynamic`` temporal AA and
dynamic resolution driven down and back up over and over (every level's targets remade at
each step); ``--day`` makes the hall's sky an atmosphere with stars and a moon and turns its sun round
the sky once every ``DAY_FRAMES`` frames (the sky-view table drawn again every frame, the
CPU's table, the cube map and the sky's light every degree, day and night).
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import time

from benchmarks import add_size_argument
from components import ReflectionProbe, Transform, yaw_pitch_rotation
from engine.core.frame_io import Output
from engine.render.gl_context import create_headless_context
from engine.render.targets import CaptureTarget
from engine.resources import ViewBudget
from games.hall_of_mirrors.level import HallOfMirrors
from shell.app import Engine

SIZE = (320, 180)
DT = 1.0 / 60.0


def resident_mib() -> float:
    """Resident set size of this process (Linux /proc; 0 elsewhere)."""
    try:
        with open("/proc/self/statm") as statm:
            pages = int(statm.read().split()[1])
    except OSError:
        return 0.0
    import resource

    return pages * resource.getpagesize() / 2**20


def tour(engine: Engine, frame: int) -> None:
    """Place the camera on the tour for ``frame``."""
    angle = 2.0 * math.pi * frame / 600.0
    camera = engine.active_camera()
    if camera is None:
        return
    transform: Transform = camera[2]
    transform.position = (4.5 * math.sin(angle), 1.6 + 0.3 * math.sin(3 * angle), -1.0 + 4.5 * math.cos(angle))
    transform.rotation = yaw_pitch_rotation(math.degrees(angle), -5.0)


# --dynamic: the frame's ViewBudget.frame_ms turns between a budget nothing meets and one
# everything does every this many frames, so dynamic resolution takes the main view down to
# its floor and back up step by step, remaking every level's targets at each step.
DYNAMIC_TURN = 40


def dynamic_budget(frame: int) -> ViewBudget:
    """The ``--dynamic`` tour's budget at ``frame``."""
    return ViewBudget(frame_ms=1e-3 if (frame // DYNAMIC_TURN) % 2 == 0 else 1e6, min_render_scale=0.5)


DAY_FRAMES = 240  # --day: frames the sun takes round the sky (1.5 degrees a frame)


def start_day(engine: Engine) -> None:
    """``--day``: the hall's Skybox an atmosphere with a night's stars, and a moon."""
    from components import DirectionalLight, Skybox
    from engine.assets.star_field import star_faces

    for _, sky in engine.world.query_one(Skybox):
        sky.faces = star_faces(size=64, stars=800)
        sky.model = "atmosphere"
    engine.world.spawn(DirectionalLight(intensity=0.1, shadows=False, body="moon"))


def turn_sun(engine: Engine, frame: int) -> None:
    """``--day``: the sun at ``frame`` of its day, round a tilted circle (noon 55 degrees up),
    the moon a little behind its opposite (a gibbous moon up at night)."""
    from components import DirectionalLight

    angle = 2.0 * math.pi * frame / DAY_FRAMES
    towards = (math.cos(angle) * 0.6, math.sin(angle) * 0.82, math.sin(angle) * 0.3 + 0.2)
    moon = (-math.cos(angle + 0.5) * 0.6, -math.sin(angle + 0.5) * 0.82, 0.3 - math.sin(angle + 0.5) * 0.3)
    for _, light in engine.world.query_one(DirectionalLight):
        light.direction = tuple(-c for c in (moon if light.body == "moon" else towards))


def run(frames: int, every: int, warmup: int = 60, size: tuple[int, int] = SIZE, lens: bool = False,
        dynamic: bool = False, day: bool = False, probe_resolution: int | None = None) -> list[dict]:
    """``lens``: the camera has depth of field with autofocus and motion blur (its spinning
    crates streaking by their own motion) as ``--dof --motion-blur`` give it.  ``dynamic``:
    temporal AA, and dynamic resolution driven down and up (``dynamic_budget``).  ``day``: an
    atmosphere with stars, its sun going round (``start_day``, ``turn_sun``).
    ``probe_resolution``: the level's reflection probes' faces that many texels a side (the
    tests' short tours: at 128 the sample tour takes a third longer on llvmpipe)."""
    ctx = create_headless_context()
    engine = Engine(HallOfMirrors(), ctx)
    if probe_resolution is not None:
        for _, probe in engine.world.query_one(ReflectionProbe):
            probe.resolution = probe_resolution
    if day:
        start_day(engine)
    if dynamic:
        engine.renderer.antialias = "taa"
    if lens:
        from components import MotionBlur
        from shell.app import start_lens

        camera = engine.active_camera()[0]
        engine.world.add_component(camera, start_lens())
        engine.world.add_component(camera, MotionBlur())
    capture = CaptureTarget(ctx, size)
    output = Output(capture.framebuffer, size)
    rows, times = [], []
    try:
        for frame in range(frames + 1):
            if frame % every == 0 or frame == frames or frame == warmup:
                rows.append({"frame": frame, "gl_resources": engine.renderer.resource_counts(),
                             "rss_mib": round(resident_mib(), 1),
                             "frame_ms_median": round(statistics.median(times), 2) if times else None})
                times = []
            if frame == frames:
                break
            tour(engine, frame)
            if day:
                turn_sun(engine, frame)
            if dynamic:
                engine.world.resources[ViewBudget] = dynamic_budget(frame)
            start = time.perf_counter()
            engine.frame(DT, output)
            ctx.finish()
            times.append((time.perf_counter() - start) * 1e3)
    finally:
        capture.release()
        engine.close()
        ctx.release()
    return rows


def grew(rows: list[dict], warmup: int, rss_slack: float) -> list[str]:
    """What grew between the report at the end of warm-up and the last one."""
    base = next(row for row in rows if row["frame"] >= warmup)
    last = rows[-1]
    found = [f"{kind} {base['gl_resources'][kind]} -> {count}" for kind, count in last["gl_resources"].items()
             if count > base["gl_resources"][kind]]
    if last["rss_mib"] - base["rss_mib"] > rss_slack:
        found.append(f"resident memory {base['rss_mib']} -> {last['rss_mib']} MiB")
    return found


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--frames", type=int, default=10_000)
    parser.add_argument("--every", type=int, default=1000, help="frames between reports")
    parser.add_argument("--rss-slack", type=float, default=20.0, help="MiB of growth tolerated (allocator noise)")
    parser.add_argument("--lens", action="store_true",
                        help="depth of field and motion blur on the camera (as --dof --motion-blur)")
    parser.add_argument("--dynamic", action="store_true",
                        help=f"temporal AA, and dynamic resolution driven to its floor and back every "
                             f"{DYNAMIC_TURN} frames (ViewBudget.frame_ms)")
    parser.add_argument("--day", action="store_true",
                        help=f"an atmosphere sky with stars, its sun round the sky every {DAY_FRAMES} frames")
    add_size_argument(parser, SIZE)


def main(args: argparse.Namespace) -> int:
    warmup = min(60, args.frames)
    rows = run(args.frames, args.every, warmup, args.size, args.lens, args.dynamic, args.day)
    for row in rows:
        print(json.dumps(row) if args.json else
              f"frame {row['frame']:>6}  rss {row['rss_mib']:>7} MiB  ms {row['frame_ms_median']}  "
              f"{row['gl_resources']}", flush=True)
    problems = grew(rows, warmup, args.rss_slack)
    print(json.dumps({"grew": problems}) if args.json else ("grew: " + "; ".join(problems) if problems
                                                              else "nothing grew"))
    return 1 if problems else 0
