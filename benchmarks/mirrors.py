"""Mirrors benchmark: whole-frame cost of planar reflections, per-mirror vs batched path.

The scene: a 40 x 40 ground with a checker texture, 20 boxes of size 1-2 scattered within
radius 8 (fixed seed; one shared box mesh, so one batch), 5 of them spinning, a directional
and a point light, and N mirrors of 4 x 3 on a ring of radius 9 facing the centre.  The
camera orbits at radius 14, height 3, looking at the centre (0.5 degrees a frame, the
same angles for every path), starting across the ring from the first mirror.  Output
640 x 360 (``--size``) into a capture target.  For each N in 0, 1, 2, 4, 8, 16 there is one engine per
``ReflectionSystem.path`` (per_mirror, batched, auto); they run ``--warmup`` frames, then
``--frames`` timed frames; every (N, path) engine runs interleaved frame by frame with all
the others, so other load on the machine falls on every one alike and the ratios between
them hold even when absolute times drift.  The default run takes about 30 seconds on 2
llvmpipe cores.

Frame time is wall clock around ``Engine.frame`` plus ``ctx.finish()`` (every system, every
draw, present), so it includes the GPU work; on llvmpipe (a software rasteriser) GPU timer
queries do not measure anything useful.  ``passes``, ``draw_calls`` and
``reflection_views`` are medians of ``engine.renderer.stats`` over the timed frames;
``chosen`` counts the frames by ``stats.reflection_path`` (what auto picked).  The last
line is the ratio of the auto path's 8-mirror median frame to its 0-mirror median frame.
``cpu_ms_median`` is the wall clock until ``Engine.frame`` returns, without the
``ctx.finish()`` after it (on a GPU, the frame's CPU cost; on llvmpipe it includes the
rasterising the engine waits for, so it is reported, not targeted).  ``plan_us_per_view``
is the time the view trees spent planning the frame's reflection views (``PlanClock``:
candidate search and culling, claims, each view's camera and view block, ordering, the
level budget), over the views they made, median over the frames that had views (None
when no frame had one).
``--spheres N`` puts N spheres of 4096 triangles each in every ring (five of them: the
20754-triangle scene the batched path's GPU limit was measured on); each row gives the
``triangles`` a view's pass submits.  ``--aa fxaa,off`` runs every case once per
anti-aliasing mode (``Renderer.antialias``), interleaved like the rest, and ends with each
case's ratio of the two medians: the cost of the FXAA pass.

    python -m benchmarks mirrors               # table
    python -m benchmarks mirrors --json        # one JSON object per line
    python -m benchmarks mirrors --frames 20 --mirrors 0,8
    python -m benchmarks mirrors --mirrors 0,8 --paths auto --aa fxaa,off --frames 200
    python -m benchmarks mirrors --size 1920x1080
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from collections import Counter
from dataclasses import asdict, dataclass, field

import numpy as np
from pyglm import glm

from benchmarks import add_size_argument, format_size
from components import (
    Camera,
    DirectionalLight,
    Material,
    MeshRef,
    Mirror,
    PointLight,
    Skybox,
    Transform,
    look_rotation,
)
from engine.assets.mesh import box, plane, quad, sphere
from engine.assets.texture_data import checker_texture
from engine.core.frame_io import Output
from engine.core.game import Game
from engine.core.world import World
from engine.render.batched_mirrors import submitted_triangles
from engine.render.end_images import EndImages
from engine.render.gl_context import create_headless_context
from engine.render.gpu import Gpu
from engine.render.mirror_passes import MirrorPasses
from engine.render.present import ANTIALIAS_MODES
from engine.render.scene_pass import ScenePass
from engine.render.targets import CaptureTarget
from engine.render.tree_visibility import VISIBILITY_MODES
from engine.render.view_tree import ViewTree
from shell.app import Engine

MIRROR_COUNTS = (0, 1, 2, 4, 8, 16)
PATHS = ("per_mirror", "batched", "auto")
OUTPUT_SIZE = (640, 360)
DT = 1.0 / 60.0
SEED = 7
BOXES = 20
SPINNING = 5
ORBIT_RADIUS = 14.0
ORBIT_HEIGHT = 3.0
ORBIT_STEP = math.radians(0.5)   # per frame
START_ANGLE = math.radians(170.0)  # across the ring from the first mirror, which faces the camera
RING_RADIUS = 9.0
# ``--spheres``: each a 64 x 32 sphere, 4096 triangles (five of them and the ring: the scene
# the batched path's GPU limit was measured on, engine/render/batched_mirrors.py).
SPHERE_DETAIL = (64, 32)
CENTRE = glm.vec3(0.0, 1.0, 0.0)


class MirrorRing(Game):
    """The benchmark scene with ``mirrors`` mirrors on the ring."""

    title = "benchmark: mirrors"

    def __init__(self, mirrors: int, faded: bool = False, spheres: int = 0) -> None:
        self.mirrors = mirrors
        self.faded = faded  # every mirror past its distance fade: it should cost no view
        self.spheres = spheres  # heavy spheres (SPHERE_DETAIL) about the centre: ``--spheres``
        self.camera: Transform | None = None
        self.spinning: list[tuple[Transform, float]] = []
        self.angle = START_ANGLE
        self.time = 0.0

    def build(self, world: World) -> None:
        rng = np.random.default_rng(SEED)
        world.spawn(DirectionalLight(direction=(-0.4, -1.0, -0.3), intensity=1.5))
        world.spawn(Transform(position=(0.0, 4.0, 0.0)), PointLight(color=(1.0, 0.85, 0.6), intensity=6.0,
                                                                     range=16.0))
        world.spawn(Skybox())
        world.spawn(Transform(), MeshRef(plane(40, 40, uv_repeat=10)), Material(texture=checker_texture(256, 8)))
        cube = box(name="bench box")
        for i in range(BOXES):
            radius = 8.0 * math.sqrt(rng.uniform(0.0, 1.0))
            theta = rng.uniform(0.0, 2.0 * math.pi)
            size = glm.vec3(*rng.uniform(1.0, 2.0, 3))
            transform = Transform(position=(radius * math.cos(theta), size.y / 2, radius * math.sin(theta)),
                                  rotation=glm.angleAxis(float(rng.uniform(0, math.pi)), glm.vec3(0, 1, 0)),
                                  scale=size)
            world.spawn(transform, MeshRef(cube), Material(color=tuple(rng.uniform(0.2, 0.9, 3)),
                                                           roughness=float(rng.uniform(0.2, 0.8))))
            if i < SPINNING:
                self.spinning.append((transform, float(rng.uniform(0.5, 1.5))))
        ball = sphere(0.8, *SPHERE_DETAIL, name="bench sphere")
        for i in range(self.spheres):
            a = 2.0 * math.pi * (i + 0.5) / self.spheres
            world.spawn(Transform(position=(4.0 * math.cos(a), 1.2, 4.0 * math.sin(a))), MeshRef(ball),
                        Material(color=(0.8, 0.8, 0.85), roughness=0.3))
        glass = quad(4, 3, name="mirror")
        for i in range(self.mirrors):
            a = 2.0 * math.pi * i / self.mirrors
            outward = glm.vec3(math.cos(a), 0.0, math.sin(a))
            world.spawn(Transform(position=RING_RADIUS * outward + glm.vec3(0.0, 1.5, 0.0),
                                  rotation=look_rotation(outward)),  # +Z (the glass's front) to the centre
                        MeshRef(glass), Material(color=(0.1, 0.1, 0.1)),
                        Mirror(color=(0.95, 0.97, 1.0), fade_distance=(0.0, 0.5) if self.faded else None))
        self.camera = Transform()
        world.spawn(self.camera, Camera(fov_y=60.0, near=0.1, far=100.0))
        self._place_camera()

    def _place_camera(self) -> None:
        eye = glm.vec3(ORBIT_RADIUS * math.cos(self.angle), ORBIT_HEIGHT, ORBIT_RADIUS * math.sin(self.angle))
        self.camera.position = eye
        self.camera.rotation = look_rotation(CENTRE - eye)

    def update(self, world: World, dt: float) -> None:
        self.time += dt
        self.angle += ORBIT_STEP
        self._place_camera()
        for transform, speed in self.spinning:
            transform.rotation = glm.angleAxis(self.time * speed, glm.vec3(0, 1, 0))


class PlanClock:
    """How long the view trees spend planning reflection views, and how many views they make.

    While open (``with PlanClock() as clock``) it wraps, on their classes, ``ViewTree.render``
    and the calls it makes that are not planning: a level's GL work
    (``MirrorPasses.prepare_level``: the claims; ``claimed_pixels``: waiting for their counts;
    ``ScenePass.draw``: the views;
    ``Gpu.flush``; ``MirrorPasses.composite_level``; ``EndImages.draw`` and ``keep``:
    the end images' pass and blit) and the composite's CPU half
    (``ViewTree._prepare_composite``, where there is one).  Planning is the time inside
    ``render`` less the time in those: the candidate search and cull (``SurfaceTable.cull``),
    the claims' rectangles, each view's camera and view block, ordering and the level budget.
    Every tree of every engine counts (the main view's and each probe face's); ``views`` is
    the reflection views their results hold (``len(TreeResult.views) - 1`` each).
    ``reset()`` before a frame, read ``plan_s`` and ``views`` after it.  Nothing in
    ``engine`` changes: the wrappers go when the block ends (or at ``close``).
    """

    NOT_PLANNING = ((MirrorPasses, "prepare_level"), (MirrorPasses, "claimed_pixels"), (ScenePass, "draw"),
                    (Gpu, "flush"), (MirrorPasses, "composite_level"), (ViewTree, "_prepare_composite"),
                    (EndImages, "draw"), (EndImages, "keep"))
    OPTIONAL = ((ViewTree, "_prepare_composite"),)  # the others must be there: a renamed GL call
    # would otherwise count as planning without a word

    def __init__(self) -> None:
        self.plan_s = 0.0
        self.views = 0
        self._trees = 0       # ViewTree.render calls under way
        self._aside = 0       # not-planning calls under way inside one (the outermost is timed)
        self._aside_s = 0.0   # their time, since the clock was made
        self._saved: list[tuple[type, str, object]] = []

    def reset(self) -> None:
        self.plan_s, self.views = 0.0, 0

    def us_per_view(self) -> float | None:
        """This frame's planning time per reflection view, in microseconds (None: no views)."""
        return self.plan_s * 1e6 / self.views if self.views else None

    def open(self) -> PlanClock:
        """Put the wrappers on (``close`` takes them off; ``with`` does both)."""
        if not self._saved:
            self._wrap(ViewTree, "render", self._tree)
            for owner, name in self.NOT_PLANNING:
                if name in vars(owner) or (owner, name) not in self.OPTIONAL:
                    self._wrap(owner, name, self._aside_call)
        return self

    def close(self) -> None:
        for owner, name, original in reversed(self._saved):
            setattr(owner, name, original)
        self._saved.clear()

    def __enter__(self) -> PlanClock:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _wrap(self, owner: type, name: str, make) -> None:
        if name not in vars(owner):
            self.close()
            raise AttributeError(f"PlanClock times {owner.__name__}.{name}, which is not there any more: "
                                 "say in PlanClock what the view tree calls now")
        original = vars(owner)[name]
        self._saved.append((owner, name, original))
        setattr(owner, name, make(original))

    def _tree(self, render):
        clock = self

        def timed_render(*args, **kwargs):
            aside = clock._aside_s
            clock._trees += 1
            start = time.perf_counter()
            try:
                result = render(*args, **kwargs)
            finally:
                clock._trees -= 1
            clock.plan_s += time.perf_counter() - start - (clock._aside_s - aside)
            clock.views += len(result.views) - 1
            return result
        return timed_render

    def _aside_call(self, method):
        clock = self

        def timed(*args, **kwargs):
            if not clock._trees or clock._aside:
                return method(*args, **kwargs)
            clock._aside += 1
            start = time.perf_counter()
            try:
                return method(*args, **kwargs)
            finally:
                clock._aside_s += time.perf_counter() - start
                clock._aside -= 1
        return timed


def plan_median(samples: list[float | None]) -> float | None:
    """The median of the frames' ``PlanClock.us_per_view`` over the frames with views."""
    values = [v for v in samples if v is not None]
    return round(statistics.median(values), 2) if values else None


@dataclass
class Result:
    n_mirrors: int
    path: str
    frame_ms_median: float
    frame_ms_p95: float
    passes: int
    draw_calls: int
    reflection_views: int
    frames: int
    aa: str = "fxaa"
    chosen: dict[str, int] = field(default_factory=dict)
    cpu_ms_median: float = 0.0
    plan_us_per_view: float | None = None
    faded: bool = False   # every mirror faded out (``--faded``)
    visibility: str = "auto"  # ReflectionSystem.visibility (``--visibility``); what the frames used: ``used``
    used: str = ""
    unseen: int = 0           # views drawn on last frame's word with no pixels then (median)
    spheres: int = 0          # heavy spheres in the ring (``--spheres``)
    triangles: int = 0        # what a view's pass submits (batched_mirrors.submitted_triangles)


def _percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, max(0, math.ceil(q * len(ordered)) - 1))]


def run_scenes(ctx, mirror_counts: tuple[int, ...], paths: tuple[str, ...], frames: int,
               warmup: int, aa_modes: tuple[str, ...] = ("fxaa",),
               size: tuple[int, int] = OUTPUT_SIZE, faded: bool = False,
               visibilities: tuple[str, ...] = ("auto",), spheres: int = 0) -> list[Result]:
    """One engine per (mirror count, path, anti-aliasing mode) on the same scene, their
    frames interleaved (frame i of every engine, then frame i + 1), so load from outside the
    benchmark, and the drift of a shared machine, land on every engine alike and the ratios
    between them hold.  ``size`` is the output's (width, height); ``faded`` adds, for each
    mirror count, the same ring with every mirror faded out (``Mirror.fade_distance``);
    ``visibilities``: the ``ReflectionSystem.visibility`` modes, an engine each; ``spheres``
    heavy spheres in every ring (``MirrorRing``)."""
    cases = [(mirrors, path, aa, fade, visibility) for mirrors in mirror_counts for path in paths
             for aa in aa_modes for fade in ((False, True) if faded and mirrors else (False,))
             for visibility in visibilities]
    engines, captures = [], []
    clock = PlanClock()
    try:
        clock.open()
        for mirrors, path, aa, fade, visibility in cases:
            engine = Engine(MirrorRing(mirrors, fade, spheres), ctx)
            engine.reflection_system.path = path
            engine.reflection_system.visibility = visibility
            engine.renderer.antialias = aa
            engines.append(engine)
            captures.append(CaptureTarget(ctx, size))
        outputs = [Output(capture.framebuffer, size) for capture in captures]
        times: list[list[float]] = [[] for _ in cases]
        cpu: list[list[float]] = [[] for _ in cases]
        plan: list[list[float | None]] = [[] for _ in cases]
        stats: list[list] = [[] for _ in cases]
        for frame in range(warmup + frames):
            for i, (engine, output) in enumerate(zip(engines, outputs, strict=True)):
                clock.reset()
                start = time.perf_counter()
                engine.frame(DT, output)
                returned = time.perf_counter()
                ctx.finish()
                if frame >= warmup:
                    times[i].append((time.perf_counter() - start) * 1e3)
                    cpu[i].append((returned - start) * 1e3)
                    plan[i].append(clock.us_per_view())
                    stats[i].append(engine.renderer.stats)
        if ctx.error != "GL_NO_ERROR":
            raise RuntimeError(f"OpenGL error: {ctx.error}")
        return [Result(
            n_mirrors=mirrors,
            path=path,
            frame_ms_median=round(statistics.median(times[i]), 2),
            frame_ms_p95=round(_percentile(times[i], 0.95), 2),
            passes=round(statistics.median(s.passes for s in stats[i])),
            draw_calls=round(statistics.median(s.draw_calls for s in stats[i])),
            reflection_views=round(statistics.median(s.reflection_views for s in stats[i])),
            frames=frames,
            aa=aa,
            chosen=dict(Counter(s.reflection_path or "none" for s in stats[i])),
            cpu_ms_median=round(statistics.median(cpu[i]), 2),
            plan_us_per_view=plan_median(plan[i]),
            faded=fade,
            visibility=visibility,
            used=",".join(sorted({s.reflection_visibility for s in stats[i]} - {""})),
            unseen=round(statistics.median(s.reflection_views_unseen for s in stats[i])),
            spheres=spheres,
            triangles=submitted_triangles(engines[i].renderer),
        ) for i, (mirrors, path, aa, fade, visibility) in enumerate(cases)]
    finally:
        clock.close()
        for capture in captures:
            capture.release()
        for engine in engines:
            engine.close()


def _ints(text: str) -> tuple[int, ...]:
    return tuple(int(v) for v in text.split(","))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--mirrors", type=_ints, default=MIRROR_COUNTS,
                        help="comma-separated mirror counts (default 0,1,2,4,8,16)")
    parser.add_argument("--paths", type=lambda text: tuple(text.split(",")), default=PATHS,
                        help="comma-separated paths (default per_mirror,batched,auto)")
    parser.add_argument("--frames", type=int, default=40, help="timed frames per path and mirror count (default 40)")
    parser.add_argument("--warmup", type=int, default=3, help="untimed frames first (default 3)")
    parser.add_argument("--aa", type=lambda text: tuple(text.split(",")), default=("fxaa",),
                        help="comma-separated anti-aliasing modes (default fxaa; fxaa,off measures its cost)")
    parser.add_argument("--faded", action="store_true",
                        help="also run each mirror count with every mirror faded out (it should cost no view)")
    parser.add_argument("--visibility", type=lambda text: tuple(text.split(",")), default=("auto",),
                        help="comma-separated ReflectionSystem.visibility modes (default auto; "
                             "exact,predicted compares them)")
    parser.add_argument("--spheres", type=int, default=0,
                        help="heavy spheres (4096 triangles each) in every ring: a scene past the auto rule's "
                             "triangle limits (default 0)")
    add_size_argument(parser, OUTPUT_SIZE)


COLUMNS = (("n_mirrors", "mirrors", 8), ("path", "path", 11), ("aa", "aa", 5), ("frame_ms_median", "ms med", 8),
           ("frame_ms_p95", "ms p95", 8), ("cpu_ms_median", "cpu ms", 8), ("plan_us_per_view", "plan us/v", 10),
           ("passes", "passes", 7), ("draw_calls", "draws", 6), ("reflection_views", "views", 6),
           ("faded", "faded", 6), ("used", "visibility", 10), ("unseen", "unseen", 6), ("triangles", "tris", 6))


def main(args: argparse.Namespace) -> int:
    if args.frames < 1 or args.warmup < 0 or args.spheres < 0 or any(n < 0 for n in args.mirrors):
        raise SystemExit("--frames must be >= 1, --warmup, --spheres and --mirrors >= 0")
    unknown = set(args.paths) - set(PATHS)
    if unknown:
        raise SystemExit(f"unknown paths {sorted(unknown)}; choose from {PATHS}")
    unknown = set(args.visibility) - set(VISIBILITY_MODES)
    if unknown:
        raise SystemExit(f"unknown --visibility modes {sorted(unknown)}; choose from {VISIBILITY_MODES}")
    unknown = set(args.aa) - set(ANTIALIAS_MODES)
    if unknown:
        raise SystemExit(f"unknown --aa modes {sorted(unknown)}; choose from {ANTIALIAS_MODES}")
    ctx = create_headless_context()
    results: list[Result] = []
    try:
        if not args.json:
            print(f"Mirrors: whole frame incl. ctx.finish() at {format_size(args.size)} "
                  f"({ctx.info.get('GL_RENDERER', '?')}, {args.frames} frames after {args.warmup} warm-up)")
            print(" ".join(f"{title:>{width}}" for _, title, width in COLUMNS) + "  chosen")
        for result in run_scenes(ctx, args.mirrors, args.paths, args.frames, args.warmup, args.aa, args.size,
                                 args.faded, args.visibility, args.spheres):
            results.append(result)
            if args.json:
                print(json.dumps(asdict(result)), flush=True)
            else:
                row = asdict(result)
                print(" ".join(f"{row[key]!s:>{width}}" for key, _, width in COLUMNS)
                      + f"  {result.chosen}", flush=True)
    finally:
        ctx.release()
    if "fxaa" in args.aa and "off" in args.aa:
        off = {(r.n_mirrors, r.path): r.frame_ms_median for r in results if r.aa == "off"}
        for r in results:
            if r.aa == "fxaa":
                ratio = round(r.frame_ms_median / off[r.n_mirrors, r.path], 3)
                if args.json:
                    print(json.dumps({"n_mirrors": r.n_mirrors, "path": r.path, "ratio_fxaa_to_off": ratio}))
                else:
                    print(f"fxaa / off, {r.n_mirrors} mirrors, {r.path}: {ratio}x "
                          f"({r.frame_ms_median - off[r.n_mirrors, r.path]:+.2f} ms)")
    auto = {r.n_mirrors: r for r in results if r.path == "auto" and r.aa == args.aa[0]}
    if 0 in auto and 8 in auto:
        ratio = round(auto[8].frame_ms_median / auto[0].frame_ms_median, 2)
        chosen = max(auto[8].chosen, key=auto[8].chosen.get)
        if args.json:
            print(json.dumps({"ratio_auto_8_to_0": ratio, "auto_8_chosen": auto[8].chosen}), flush=True)
        else:
            print(f"auto path ({chosen}) with 8 mirrors / no mirror: {ratio}x")
    elif "auto" in args.paths:
        print("(the 8-to-0 ratio needs --mirrors with 0 and 8)", file=sys.stderr)
    return 0
