"""Portal benchmark: a facing pair of portals, recursion depth 0 to 8.

Two 2 x 2.5 m portals face each other 6 m apart over a checkered floor with a few boxes
between them; the camera stands between them looking into one, so every level of
recursion shows the other one again, smaller.  For each depth limit the whole frame is
timed (``Engine.frame`` then ``ctx.finish()``, wall clock: llvmpipe's GPU timers are not
usable), 640x360 (``--size``).  ``passes`` counts scene renders (1 main + 1 per portal view).
``cpu_ms_median``: until ``Engine.frame`` returns, without the ``ctx.finish()``;
``plan_us_per_view``: the view tree's planning time per reflection view
(``benchmarks.mirrors.PlanClock``; None at depth 0, which has no views).  The tree is drawn
whole every frame (``ReflectionSystem.keep_still_views = False``): a still camera's frames
would otherwise keep it, or refill only its end images until they settle, and time that
instead (the ``cpu`` suite's ``portals_d8`` does: ``benchmarks/cpu.py``).  ``--visibility
exact,predicted`` runs one engine per ``ReflectionSystem.visibility`` mode, frames interleaved.

    python -m benchmarks portals            # table
    python -m benchmarks portals --json     # one JSON object per depth
    python -m benchmarks portals --size 1920x1080
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import time

from pyglm import glm

from benchmarks import add_size_argument
from benchmarks.mirrors import PlanClock, plan_median
from components import DirectionalLight, Material, MeshRef, Portal, Skybox, Transform
from components.transform import yaw_pitch_rotation
from engine.assets.mesh import box, plane
from engine.assets.portals import spawn_portal_pair
from engine.assets.texture_data import checker_texture
from engine.core.frame_io import Output
from engine.core.game import Game
from engine.core.world import World
from engine.render.gl_context import create_headless_context
from engine.render.targets import CaptureTarget
from engine.render.tree_visibility import VISIBILITY_MODES
from shell.app import Engine

SIZE = (640, 360)
DEPTHS = range(0, 9)
SWAY_CENTRE = glm.vec3(0.3, 1.5, 3.0)  # the camera's place (FacingPortals), the centre of its sway
# Seconds a sway takes: 60 frames at the suites' 1/60 s, the cpu suite's default window, so
# its median is over one whole sway.  At 32x18 the deepest levels lose their last pixels for
# part of each sway (5 to 8 views a frame), so a window over part of one reads the part: at
# 2 s the default window held the first half, whose median frame had 6 views against 8.
SWAY_PERIOD = 1.0


class FacingPortals(Game):
    """The portal pair; with ``sway`` the camera turns and drifts a little every frame (a
    game's usual camera, which finds no plan or view of the frame before to keep)."""

    title = "portal benchmark"

    def __init__(self, sway: bool = False) -> None:
        self.sway = sway
        self.camera: Transform | None = None
        self.time = 0.0

    def build(self, world: World) -> None:
        from engine.core.game import spawn_camera

        camera = spawn_camera(world, position=SWAY_CENTRE, yaw=3.0, pitch=-2.0, fly=False)
        self.camera = world.get(camera, Transform)
        world.spawn(Skybox())
        world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.4), intensity=2.5))
        world.spawn(Transform(), MeshRef(plane(40, 40, uv_repeat=10)), Material(texture=checker_texture(128, 8)))
        back = glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))
        spawn_portal_pair(world, (0, 1.25, 0), None, (0, 1.25, 6), back, size=(2.0, 2.5), max_depth=8)
        crate = box((0.5, 0.5, 0.5))
        for i, (x, z) in enumerate(((-0.6, 1.0), (0.7, 2.0), (-0.3, 4.5), (0.5, 5.2))):
            world.spawn(Transform(position=(x, 0.25, z)), MeshRef(crate),
                        Material(color=(0.2 + 0.2 * i, 0.5, 0.9 - 0.2 * i)))

    def update(self, world: World, dt: float) -> None:
        if not self.sway:
            return
        # A slow sway of a degree or two and a few centimetres: the levels see the other
        # portal as the still camera's do (at 32x18 the deepest ones lose their last pixels
        # for part of it), but no frame's cameras repeat.
        self.time += dt
        phase = 2.0 * math.pi * self.time / SWAY_PERIOD
        self.camera.position = SWAY_CENTRE + glm.vec3(0.05 * math.sin(phase), 0.02 * math.cos(2.0 * phase), 0.0)
        self.camera.rotation = yaw_pitch_rotation(3.0 + 1.5 * math.sin(phase), -2.0 + 0.5 * math.cos(phase))


def set_depth(engine: Engine, depth: int) -> None:
    """Both portals' recursion depth ``depth`` (the tree's cap with them, at least 1)."""
    for _, portal in engine.world.query_one(Portal):
        portal.max_depth = depth
    engine.reflection_system.max_depth_cap = max(depth, 1)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--frames", type=int, default=30, help="timed frames per depth")
    parser.add_argument("--warmup", type=int, default=3)
    parser.add_argument("--visibility", type=lambda text: tuple(text.split(",")), default=("auto",),
                        help="comma-separated ReflectionSystem.visibility modes, each its own engine, their "
                             "frames interleaved (default auto; exact,predicted compares them)")
    add_size_argument(parser, SIZE)


def main(args: argparse.Namespace) -> int:
    unknown = set(args.visibility) - set(VISIBILITY_MODES)
    if unknown:
        raise SystemExit(f"unknown --visibility modes {sorted(unknown)}; choose from {VISIBILITY_MODES}")
    ctx = create_headless_context()
    engines, captures = [], []
    rows = []
    clock = PlanClock()
    try:
        for visibility in args.visibility:
            engine = Engine(FacingPortals(), ctx)
            engine.reflection_system.visibility = visibility
            engine.reflection_system.keep_still_views = False  # the recursion drawn (module docstring)
            engines.append(engine)
            captures.append(CaptureTarget(ctx, args.size))
        outputs = [Output(capture.framebuffer, args.size) for capture in captures]
        clock.open()
        for depth in DEPTHS:
            for engine in engines:
                set_depth(engine, depth)
            times, cpu, plan = ([[] for _ in engines] for _ in range(3))
            for i in range(args.warmup + args.frames):
                for at, (engine, output) in enumerate(zip(engines, outputs, strict=True)):
                    clock.reset()
                    start = time.perf_counter()
                    engine.frame(1 / 60, output)
                    returned = time.perf_counter()
                    ctx.finish()
                    if i >= args.warmup:
                        times[at].append((time.perf_counter() - start) * 1000.0)
                        cpu[at].append((returned - start) * 1000.0)
                        plan[at].append(clock.us_per_view())
            for at, (engine, visibility) in enumerate(zip(engines, args.visibility, strict=True)):
                frame_times = sorted(times[at])
                stats = engine.renderer.stats
                rows.append({"depth": depth, "frame_ms_median": round(statistics.median(frame_times), 2),
                             "frame_ms_p95": round(frame_times[min(len(frame_times) - 1,
                                                                   int(0.95 * len(frame_times)))], 2),
                             "passes": stats.passes, "reflection_views": stats.reflection_views,
                             "cpu_ms_median": round(statistics.median(cpu[at]), 2),
                             "plan_us_per_view": plan_median(plan[at]), "visibility": visibility,
                             "used": stats.reflection_visibility})
    finally:
        clock.close()
        for capture in captures:
            capture.release()
        for engine in engines:
            engine.close()
        ctx.release()
    base = {row["visibility"]: row["frame_ms_median"] for row in rows if row["depth"] == 0}
    for row in rows:
        row["ratio_to_depth_0"] = round(row["frame_ms_median"] / base[row["visibility"]], 2)
        if args.json:
            print(json.dumps(row))
    if not args.json:
        print(f"{'depth':>5} {'median ms':>10} {'p95 ms':>8} {'passes':>6} {'x depth 0':>9} {'cpu ms':>8} "
              f"{'plan us/v':>10} {'visibility':>10}")
        for row in rows:
            print(f"{row['depth']:>5} {row['frame_ms_median']:>10} {row['frame_ms_p95']:>8} {row['passes']:>6} "
                  f"{row['ratio_to_depth_0']:>9} {row['cpu_ms_median']:>8} {row['plan_us_per_view']!s:>10} "
                  f"{row['used'] or row['visibility']:>10}")
    return 0
