"""Probes benchmark: the cost of cube-map reflection probes on the mirror benchmark's scene.

The scene is ``benchmarks.mirrors.MirrorRing`` with no mirrors (a textured ground, 20
boxes of which 5 spin, two lights, the orbiting camera) plus a chrome sphere (radius 1) at
the ring's centre, 640 x 360 (``--size``: the output, not the probe's faces).

Capture rows (``path``, ``culled``, ``size``, ``capture_ms_median``, ``primitives``): all six
faces of the sphere's probe captured ``--frames`` times at 128 and 512 texels a face, each
timed with ``ctx.finish()`` around it (wall clock: llvmpipe's GPU timers are not usable),
with a primitives-generated query around the capture (less the mip pass's six triangles a
level).  ``face_primitives`` is the same
query around the main view's scene pass (one view of the scene), the yardstick for how much
geometry six faces push.  Paths: ``six_pass`` (each face a view through the scene pass;
the primitives count includes the probe's own sphere, which each face view clips),
``layered`` with ``culled`` true (one pass, each triangle sent to the faces it touches) and
false (to all six faces).  An ``auto_chose`` row per size names the path ``ProbeSystem.path
= "auto"`` settled on at the engine's first capture and ``chosen_over_faster``, its median
here over the faster path's (1.0 when it chose right; the target is at most 1.10);
``auto_timed`` is false where it timed nothing because the path self-check
(``Renderer.path_checks``) had not verified the layered capture on this context, so auto
used ``six_pass``.  The capture rows time the layered paths whatever the self-check said.

Prefilter rows (``prefilter``, ``size``, ``prefilter_ms_median``): the mip chain of a
captured cube rebuilt, box-filtered (``mips``, the default) or GGX-convolved level by
level (``ggx``, ``ReflectionProbe.prefilter``), and ``build_mipmaps`` (glGenerateMipmap)
for comparison; interleaved.

Frame rows (``probe``, ``frame_ms_median``): whole frames (``Engine.frame`` + ``finish``)
of four engines, interleaved frame by frame in a shuffled order each round (an engine's
frame pays for the caches the frame before it left cold): ``none`` (the sphere reflects
the sky), ``static`` (a probe of static surroundings: captured on the first frame, never
again; an ``on_change`` probe in a still scene does the same work, tests/test_probes.py
counts one capture in 100 frames), ``on_change`` (the default refresh in this scene, where
5 boxes spin: the faces that see one are recaptured, 3 a frame), ``dynamic``
(``every_frame`` at 128: all six due a frame; those no change
reached since drawn are kept, ``ProbeDue.unchanged``: 3 drawn a frame here, each within the
part of it the spinning boxes and their shadows reach, ``ProbeDue.regions``: about a quarter
of its texels).  Ratios are to
``none``.  Recaptures are drawn
after present (``ProbeSystem.recapture_after_present``).  ``cpu_ms_median``: until
``Engine.frame`` returns, without the ``ctx.finish()``; ``plan_us_per_view``: the view
trees' planning time per reflection view (``benchmarks.mirrors.PlanClock``, the main view's
tree and each probe face's; None here, where no mirror or portal makes a view).

    python -m benchmarks probes            # table
    python -m benchmarks probes --json     # one JSON object per line
    python -m benchmarks probes --size 1920x1080
"""
from __future__ import annotations

import argparse
import json
import random
import statistics
import time
from functools import partial

import moderngl

from benchmarks import add_size_argument
from benchmarks.mirrors import DT, OUTPUT_SIZE, MirrorRing, PlanClock, plan_median
from components import Material, MeshRef, ReflectionProbe, Reflective, Transform
from engine.assets.mesh import sphere
from engine.core.frame_io import Output
from engine.render.gl_context import create_headless_context
from engine.render.probes import face_view
from engine.render.targets import CaptureTarget
from shell.app import Engine

MODES = {"none": None, "static": "once", "on_change": "on_change", "dynamic": "every_frame"}


class ProbeRing(MirrorRing):
    """The mirror benchmark's scene without mirrors, with a chrome sphere at the centre."""

    title = "benchmark: probes"

    def __init__(self, refresh: str | None, resolution: int = 128) -> None:
        super().__init__(0)
        self.refresh = refresh
        self.resolution = resolution

    def build(self, world) -> None:
        super().build(world)
        components = [Transform(position=(0.0, 1.0, 0.0)), MeshRef(sphere(1.0)),
                      Material(color=(0.95, 0.95, 0.95), metallic=1.0, roughness=0.05)]
        if self.refresh is None:
            components.append(Reflective("skybox"))
        else:
            components += [Reflective("cube"), ReflectionProbe(resolution=self.resolution, refresh=self.refresh)]
        self.sphere = world.spawn(*components)


def captured_ring(ctx, size: int, output_size: tuple[int, int] = OUTPUT_SIZE) -> tuple[Engine, CaptureTarget]:
    """A scripted-probe ring of ``size``-texel faces after its first frame (probe captured)."""
    engine = Engine(ProbeRing("scripted", size), ctx)
    capture = CaptureTarget(ctx, output_size)
    engine.frame(DT, Output(capture.framebuffer, output_size))
    return engine, capture


def capture_rows(ctx, frames: int, output_size: tuple[int, int] = OUTPUT_SIZE) -> list[dict]:
    rows = []
    for size in (128, 512):
        engine, capture = captured_ring(ctx, size, output_size)
        try:
            stage = engine.stages["probes"]
            # "auto" timed both on the first capture, where the path self-check trusted the
            # layered one; where it did not, auto used six_pass without timing anything.
            timed, chosen = stage.chosen_path is not None, stage.chosen_path or stage.path_used
            query = ctx.query(primitives=True)
            with query:
                engine.renderer.scene_pass.draw([engine.main_view], engine.renderer.targets)
            face_primitives = query.primitives
            engine.stages["probes"].path = "six_pass"
            owner = engine.stages["probes"].probes[engine.game.sphere].owner
            position = engine.stages["probes"].probes[owner].position
            views = {face: face_view(face, position, 0.05, 100.0, size, skip=owner) for face in range(6)}
            probes = engine.renderer.probes
            captures = {
                ("six_pass", False): partial(probes.capture, owner, views, None, 0),
                ("layered", True): partial(probes.capture_layered, owner, views, culled=True),
                ("layered", False): partial(probes.capture_layered, owner, views, culled=False),
            }
            times = {key: [] for key in captures}
            primitives = {}
            for _ in range(frames):
                for key, run in captures.items():  # interleaved, so drift falls on every path alike
                    ctx.finish()
                    start = time.perf_counter()
                    with query:
                        run()
                    ctx.finish()
                    times[key].append((time.perf_counter() - start) * 1e3)
                    primitives[key] = query.primitives - probes.mips.primitives(size)
            for (path, culled), samples in times.items():
                rows.append({"path": path, "culled": culled, "size": size,
                             "capture_ms_median": round(statistics.median(samples), 2),
                             "primitives": primitives[(path, culled)], "face_primitives": face_primitives})
            medians = {path: statistics.median(times[(path, path == "layered")]) for path in ("six_pass", "layered")}
            rows.append({"auto_chose": chosen, "size": size, "auto_timed": timed,
                         "chosen_over_faster": round(medians[chosen] / min(medians.values()), 3)
                         if chosen in medians else None})
        finally:
            capture.release()
            engine.close()
    return rows


def prefilter_rows(ctx, frames: int, output_size: tuple[int, int] = OUTPUT_SIZE) -> list[dict]:
    rows = []
    for size in (128, 512):
        engine, capture = captured_ring(ctx, size, output_size)
        try:
            owner = engine.stages["probes"].probes[engine.game.sphere].owner
            probes = engine.renderer.probes
            cube = probes.cubes[owner].texture
            runs = {"mips": partial(probes.mips.build, owner, cube, "mips"),
                    "ggx": partial(probes.mips.build, owner, cube, "ggx"),
                    "build_mipmaps": cube.build_mipmaps}
            times = {name: [] for name in runs}
            for _ in range(frames):
                for name, run in runs.items():
                    ctx.finish()
                    start = time.perf_counter()
                    run()
                    ctx.finish()
                    times[name].append((time.perf_counter() - start) * 1e3)
            rows += [{"prefilter": name, "size": size, "prefilter_ms_median": round(statistics.median(samples), 2)}
                     for name, samples in times.items()]
        finally:
            capture.release()
            engine.close()
    return rows


def frame_rows(ctx, frames: int, warmup: int, output_size: tuple[int, int] = OUTPUT_SIZE) -> list[dict]:
    engines, captures = [], []
    clock = PlanClock()
    try:
        clock.open()
        for refresh in MODES.values():
            engines.append(Engine(ProbeRing(refresh), ctx))
            captures.append(CaptureTarget(ctx, output_size))
        outputs = [Output(c.framebuffer, output_size) for c in captures]
        times: list[list[float]] = [[] for _ in engines]
        cpu: list[list[float]] = [[] for _ in engines]
        plan: list[list[float | None]] = [[] for _ in engines]
        faces: list[int] = [0 for _ in engines]
        rng = random.Random(0)
        for frame in range(warmup + frames):
            # A shuffled order each round: an engine's frame pays for the caches the frame
            # before it left cold (a capture's most), so each follows every other alike.
            order = list(range(len(engines)))
            rng.shuffle(order)
            for i in order:
                engine, output = engines[i], outputs[i]
                clock.reset()
                start = time.perf_counter()
                engine.frame(DT, output)
                returned = time.perf_counter()
                ctx.finish()
                if frame >= warmup:
                    times[i].append((time.perf_counter() - start) * 1e3)
                    cpu[i].append((returned - start) * 1e3)
                    plan[i].append(clock.us_per_view())
                    faces[i] += engine.renderer.stats.probe_faces
        base = statistics.median(times[0])
        return [{"probe": name, "frame_ms_median": round(statistics.median(times[i]), 2),
                 "ratio_to_none": round(statistics.median(times[i]) / base, 3),
                 "faces_per_frame": round(faces[i] / frames, 2),
                 "cpu_ms_median": round(statistics.median(cpu[i]), 2), "plan_us_per_view": plan_median(plan[i])}
                for i, name in enumerate(MODES)]
    finally:
        clock.close()
        for capture in captures:
            capture.release()
        for engine in engines:
            engine.close()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--frames", type=int, default=30, help="timed frames (default 30)")
    parser.add_argument("--warmup", type=int, default=3)
    add_size_argument(parser, OUTPUT_SIZE)


def main(args: argparse.Namespace) -> int:
    ctx: moderngl.Context = create_headless_context()
    try:
        rows = capture_rows(ctx, args.frames, args.size) + prefilter_rows(ctx, min(args.frames, 10), args.size) + \
            frame_rows(ctx, args.frames, args.warmup, args.size)
    finally:
        ctx.release()
    for row in rows:
        print(json.dumps(row) if args.json else "  ".join(f"{k}={v}" for k, v in row.items()), flush=True)
    return 0
