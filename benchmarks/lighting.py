"""Lighting benchmark: what the light a game ships with costs, on the mirrors
benchmark's scene (``benchmarks/mirrors.py``: the ring of mirrors, boxes, a sun and a lamp,
the orbiting camera).

Each **variant** is a function that configures a freshly made engine of that scene (the
camera's components, lights' settings, a moving object...); every (mirror count, variant)
engine runs its frames interleaved with all the others in one process (frame i of each,
then frame i + 1), so the drift of a shared machine lands on every variant alike and the
ratios hold.  Frame time is wall clock around ``Engine.frame`` plus ``ctx.finish()``.
Each row gives the median and its ratio to the ``off`` variant of the same mirror count;
``process_ms_median`` and ``process_ratio_to_off`` are the same for the process's CPU time
over the frame (every thread's: on llvmpipe its rasteriser's too, so the frame's whole
work), which other processes on a shared machine do not lengthen: the steadier ratio there.

Variants now (``VARIANTS``; add a row by appending a ``Variant``):

* ``off``: the scene lit as before shadows and post-processing (the sun's shadows off, no
  Tonemap, no Bloom); in every variant the scene's spinning boxes stand still (only the
  camera moves), so what a variant moves is all that moves;
* ``shadows``: the sun casts shadows; nothing but the camera moves, so its map is drawn
  once and kept (the still scene);
* ``shadows_moving``: the same with a box sliding to and fro under the sun every frame
  (its map drawn again each frame);
* ``mirror_light``: shadows, and the mirror of the ring the sun reaches most throws its
  light (``Mirror.reflects_light``: one virtual light with its own shadow map); still;
* ``mirror_light_moving``: the same with the sliding box (at most two maps a frame: the
  sun's and the virtual light's);
* ``post``: no shadows, the camera gets ``Tonemap(curve="agx")`` and ``Bloom()`` (six levels on a
  GPU; a software rasteriser's quarter-size start makes five, ending at the same smallest level:
  ``engine/render/bloom.py``);
* ``post_auto``: the same with ``Tonemap(auto_exposure=True)``.

**Targets** (``TARGETS``), each a ratio of two variants' medians at a mirror count against
its limit, printed as value, limit, met:

* ``post_0_mirrors``: ``post`` / ``off`` with no mirror at 640x360 (bloom and tone mapping
  together add at most 10%), set for a GPU: on a software rasteriser (llvmpipe) every post
  pass is pixel work on the CPU, so it is reported there, not judged;
* ``shadows_still``: ``shadows`` / ``off`` (a still scene with shadows costs at most 1.05x:
  its maps are kept), set for a GPU likewise (the shadow lookups are per-pixel work);
* ``shadow_maps_moving`` (a count, judged everywhere): the shadow maps a frame of
  ``shadows_moving`` draws, at most 1 whatever the number of mirrors; ``shadows`` draws 0;
  ``mirror_light`` 0 and ``mirror_light_moving`` at most 2 (one more for the virtual light).

::

    python -m benchmarks lighting                     # table, 0 mirrors, 640x360
    python -m benchmarks lighting --mirrors 0,8 --frames 60
    python -m benchmarks lighting --json
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

from pyglm import glm

from benchmarks import add_size_argument, format_size, non_negative_int, positive_int
from benchmarks.mirrors import DT, OUTPUT_SIZE, MirrorRing
from components import Bloom, Camera, DirectionalLight, Material, MeshRef, Mirror, Tonemap, Transform
from engine.assets.mesh import box
from engine.core.frame_io import Output
from engine.render.gl_context import GLCapabilities, create_headless_context
from engine.render.targets import CaptureTarget
from shell.app import Engine


@dataclass(frozen=True)
class Variant:
    """A named way to set up the scene: ``configure(engine)`` runs once, after the engine is
    made and before its first frame."""

    name: str
    configure: Callable[[Engine], None]
    about: str = ""
    step: Callable[[Engine, int], None] | None = None   # before each frame i (a moving caster)


def camera_entity(engine: Engine) -> int:
    (entity, _), = engine.world.query_one(Camera)
    return entity


def _sun_shadows(engine: Engine, on: bool) -> None:
    """The sun's shadows on or off, and the scene's spinning boxes stopped: every variant is a
    still scene but for what it moves itself."""
    for _, light in engine.world.query_one(DirectionalLight):
        light.shadows = on
    engine.game.spinning.clear()


def _plain(engine: Engine) -> None:
    _sun_shadows(engine, False)


def _shadows(engine: Engine) -> None:
    _sun_shadows(engine, True)


def _moving_caster(engine: Engine) -> None:
    _sun_shadows(engine, True)
    engine.world.resources["lighting caster"] = engine.world.spawn(
        Transform(position=(0.0, 0.6, 2.0)), MeshRef(box((0.8, 0.8, 0.8))), Material(color=(0.7, 0.7, 0.7)))


def _slide_caster(engine: Engine, frame: int) -> None:
    transform = engine.world.get(engine.world.resources["lighting caster"], Transform)
    transform.position = glm.vec3(math.sin(frame * 0.1) * 1.5, 0.6, 2.0)


def _mirror_light(engine: Engine) -> None:
    """The sun's shadows on, and the ring's mirror the sun reaches most throws its light."""
    _sun_shadows(engine, True)
    (_, sun), = engine.world.query_one(DirectionalLight)
    facing = [(glm.dot(-sun.direction, glm.vec3(glm.mat3(engine.world.get(entity, Transform).world)
                                                  * glm.vec3(0.0, 0.0, 1.0))), entity)
              for entity, _ in engine.world.query_one(Mirror)]
    if facing:
        engine.world.get(max(facing)[1], Mirror).reflects_light = True


def _mirror_light_moving(engine: Engine) -> None:
    _mirror_light(engine)
    _moving_caster(engine)


def _post(engine: Engine) -> None:
    _sun_shadows(engine, False)
    engine.world.add_component(camera_entity(engine), Tonemap(curve="agx"))
    engine.world.add_component(camera_entity(engine), Bloom())


def _post_auto(engine: Engine) -> None:
    _sun_shadows(engine, False)
    engine.world.add_component(camera_entity(engine), Tonemap(curve="agx", auto_exposure=True))
    engine.world.add_component(camera_entity(engine), Bloom())


VARIANTS: list[Variant] = [
    Variant("off", _plain, "no shadows, no Tonemap, no Bloom (the plain look)"),
    Variant("shadows", _shadows, "the sun casts shadows; a still scene (its map kept)"),
    Variant("shadows_moving", _moving_caster, "the sun casts shadows; a box slides under it every frame",
            _slide_caster),
    Variant("mirror_light", _mirror_light, "shadows, and one mirror throws the sun (a virtual light); still"),
    Variant("mirror_light_moving", _mirror_light_moving, "the same with a box sliding under the sun",
            _slide_caster),
    Variant("post", _post, "Tonemap(curve='agx') and Bloom() on the camera"),
    Variant("post_auto", _post_auto, "Tonemap(curve='agx', auto_exposure=True) and Bloom()"),
]
BASELINE = "off"
# name -> (variant, over variant, mirror count, size, limit, the machine it is set
# for): a ratio of two medians.  "gpu": on a software rasteriser the ratio is reported, not
# judged (every post pass is pixel work its CPU does, where a GPU's frame at 0 mirrors is the
# CPU issuing draws), as benchmarks/cpu.py does.
TARGETS: dict[str, tuple[str, str, int, tuple[int, int], float, str]] = {
    "post_0_mirrors": ("post", "off", 0, (640, 360), 1.10, "gpu"),
    "shadows_still": ("shadows", "off", 0, (640, 360), 1.05, "gpu"),
}
# name -> (variant, limit): the most shadow maps a frame of it may draw, at every mirror count.
COUNT_TARGETS: dict[str, tuple[str, int]] = {"shadow_maps_moving": ("shadows_moving", 1),
                                             "shadow_maps_still": ("shadows", 0),
                                             "shadow_maps_mirror_light_still": ("mirror_light", 0),
                                             "shadow_maps_mirror_light_moving": ("mirror_light_moving", 2)}


@dataclass
class Row:
    n_mirrors: int
    variant: str
    frame_ms_median: float
    cpu_ms_median: float
    ratio_to_off: float
    process_ms_median: float
    process_ratio_to_off: float
    passes: int
    shadow_maps: int   # drawn a frame (median)
    frames: int
    size: str


def run_variants(ctx, variants: list[Variant], mirror_counts: tuple[int, ...], frames: int, warmup: int,
                 size: tuple[int, int] = OUTPUT_SIZE) -> list[Row]:
    """One engine per (mirror count, variant), frames interleaved; a row each."""
    cases = [(mirrors, variant) for mirrors in mirror_counts for variant in variants]
    engines, captures = [], []
    try:
        for mirrors, variant in cases:
            engine = Engine(MirrorRing(mirrors), ctx)
            variant.configure(engine)
            engines.append(engine)
            captures.append(CaptureTarget(ctx, size))
        outputs = [Output(capture.framebuffer, size) for capture in captures]
        times: list[list[float]] = [[] for _ in cases]
        cpu: list[list[float]] = [[] for _ in cases]
        work: list[list[float]] = [[] for _ in cases]
        passes: list[list[int]] = [[] for _ in cases]
        shadow_maps: list[list[int]] = [[] for _ in cases]
        for frame in range(warmup + frames):
            for i, (engine, output) in enumerate(zip(engines, outputs, strict=True)):
                step = cases[i][1].step
                if step is not None:
                    step(engine, frame)
                ctx.finish()
                start, start_work = time.perf_counter(), time.process_time()
                engine.frame(DT, output)
                returned = time.perf_counter()
                ctx.finish()
                if frame >= warmup:
                    times[i].append((time.perf_counter() - start) * 1e3)
                    work[i].append((time.process_time() - start_work) * 1e3)
                    cpu[i].append((returned - start) * 1e3)
                    passes[i].append(engine.renderer.stats.passes + engine.renderer.present_pass.post_passes)
                    shadow_maps[i].append(engine.renderer.stats.shadow_maps_drawn)
        if ctx.error != "GL_NO_ERROR":
            raise RuntimeError(f"OpenGL error: {ctx.error}")
    finally:
        for capture in captures:
            capture.release()
        for engine in engines:
            engine.close()
    medians = {(m, v.name): statistics.median(times[i]) for i, (m, v) in enumerate(cases)}
    work_medians = {(m, v.name): statistics.median(work[i]) for i, (m, v) in enumerate(cases)}
    rows = []
    for i, (mirrors, variant) in enumerate(cases):
        base = medians.get((mirrors, BASELINE))
        work_base = work_medians.get((mirrors, BASELINE))
        median = medians[mirrors, variant.name]
        work_median = work_medians[mirrors, variant.name]
        rows.append(Row(n_mirrors=mirrors, variant=variant.name, frame_ms_median=round(median, 3),
                        cpu_ms_median=round(statistics.median(cpu[i]), 3),
                        ratio_to_off=round(median / base, 3) if base else float("nan"),
                        process_ms_median=round(work_median, 3),
                        process_ratio_to_off=round(work_median / work_base, 3) if work_base else float("nan"),
                        passes=round(statistics.median(passes[i])),
                        shadow_maps=round(statistics.median(shadow_maps[i])), frames=frames, size=format_size(size)))
    return rows


def target_rows(rows: list[Row], size: tuple[int, int], software: bool) -> list[dict]:
    """Each target measured in ``rows`` (at its size and mirror count): value, limit, met,
    and whether it applies here (its size, and a GPU target on a GPU)."""
    by = {(r.n_mirrors, r.variant): r for r in rows}
    found = []
    for name, (variant, over, mirrors, wanted, limit, machine) in TARGETS.items():
        if (mirrors, variant) not in by or (mirrors, over) not in by:
            continue
        value = round(by[mirrors, variant].frame_ms_median / by[mirrors, over].frame_ms_median, 3)
        found.append({"target": name, "value": value, "limit": limit, "met": value <= limit,
                      "at_its_size": tuple(size) == wanted, "set_for": machine,
                      "applies": tuple(size) == wanted and (machine == "gpu") != software,
                      "measured": f"{variant} {by[mirrors, variant].frame_ms_median} ms / {over} "
                                  f"{by[mirrors, over].frame_ms_median} ms, {mirrors} mirrors, {format_size(size)}"})
    for name, (variant, limit) in COUNT_TARGETS.items():
        measured = [r for r in rows if r.variant == variant]
        if not measured:
            continue
        value = max(r.shadow_maps for r in measured)
        found.append({"target": name, "value": value, "limit": limit, "met": value <= limit, "at_its_size": True,
                      "set_for": "any", "applies": True,
                      "measured": f"{variant}: shadow maps a frame at "
                                  + ", ".join(f"{r.n_mirrors} mirrors {r.shadow_maps}" for r in measured)})
    return found


def _ints(text: str) -> tuple[int, ...]:
    return tuple(int(v) for v in text.split(","))


def _variants(text: str) -> tuple[str, ...]:
    names = tuple(v.strip() for v in text.split(",") if v.strip())
    known = [v.name for v in VARIANTS]
    unknown = sorted(set(names) - set(known))
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"unknown variants {unknown}; choose from {','.join(known)}")
    return names


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--mirrors", type=_ints, default=(0,), help="comma-separated mirror counts (default 0)")
    parser.add_argument("--variants", type=_variants, default=tuple(v.name for v in VARIANTS),
                        help=f"comma-separated variants (default all: {','.join(v.name for v in VARIANTS)})")
    parser.add_argument("--frames", type=positive_int, default=60, help="timed frames per engine (default 60)")
    parser.add_argument("--warmup", type=non_negative_int, default=5, help="untimed frames first (default 5)")
    add_size_argument(parser, OUTPUT_SIZE)


COLUMNS = (("n_mirrors", "mirrors", 8), ("variant", "variant", 10), ("frame_ms_median", "ms med", 9),
           ("cpu_ms_median", "cpu ms", 9), ("ratio_to_off", "/ off", 7), ("process_ms_median", "proc ms", 9),
           ("process_ratio_to_off", "p / off", 8), ("passes", "passes", 7),
           ("shadow_maps", "shadows", 8))


def main(args: argparse.Namespace) -> int:
    if any(n < 0 for n in args.mirrors):
        raise SystemExit("--mirrors must be >= 0")
    chosen = [v for v in VARIANTS if v.name in args.variants]
    if BASELINE not in args.variants:
        chosen.insert(0, next(v for v in VARIANTS if v.name == BASELINE))  # every ratio is to it
    ctx = create_headless_context()
    try:
        renderer = ctx.info.get("GL_RENDERER", "?")
        software = GLCapabilities.read(ctx).software
        rows = run_variants(ctx, chosen, args.mirrors, args.frames, args.warmup, args.size)
    finally:
        ctx.release()
    targets = target_rows(rows, args.size, software)
    if args.json:
        for row in rows:
            print(json.dumps(asdict(row)), flush=True)
        for target in targets:
            print(json.dumps(target), flush=True)
        return 0
    print(f"Lighting: whole frame incl. ctx.finish() at {format_size(args.size)} ({renderer}, {args.frames} frames "
          f"after {args.warmup} warm-up, variants interleaved)")
    print(" ".join(f"{title:>{width}}" for _, title, width in COLUMNS))
    for row in rows:
        values = asdict(row)
        print(" ".join(f"{values[key]!s:>{width}}" for key, _, width in COLUMNS))
    for target in targets:
        met = "yes" if target["met"] else "no"
        if not target["at_its_size"]:
            met += " (not at the target's size)"
        elif not target["applies"]:
            met += f" (set for a {target['set_for']}: reported, not judged here)"
        print(f"target {target['target']}: {target['value']}x, limit {target['limit']}x, met: {met}  "
              f"({target['measured']})")
    return 0
