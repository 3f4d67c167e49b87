"""CPU benchmark: the frame a GPU host pays for, measured with the rasteriser taken out, and
the speed targets judged against their limits.

On a GPU the rasteriser is nearly free and a frame costs what the CPU spends (Python, numpy,
the driver calls).  That is measured here by rendering at 32x18 in a process started with
``LP_NUM_THREADS=0`` (llvmpipe reads it when it starts: no rasteriser threads, and at 32x18
almost nothing to rasterise), so the frame is the engine's CPU.  Parts (``--parts``):

* ``cpu``: the mirrors ring (``benchmarks.mirrors``) with 0, 8 and 16 mirrors and the
  facing portal pair (``benchmarks.portals``) at depth 0 and 8, still and with a camera
  that sways a little every frame (``_sway``), 32x18, in a subprocess with
  ``LP_NUM_THREADS=0``; then a cProfile table of each scene's top functions (``--top``).
  The still pair keeps its reflection views once its end images settle (about frame 52 at
  32x18: ``ReflectionSystem.keep_still_views``), so its depth-8 frames are drawn whole
  before that and cost about depth 0's after; the swaying pair plans and draws every level
  every frame, what a moving camera pays a level, over one whole sway in the default 60
  frames (``benchmarks.portals.SWAY_PERIOD``).
* ``frames``: 640x360 with the rasteriser in (this process's environment): the mirrors
  ring with 0 and 8 mirrors, the probes suite's sphere with no probe and with a probe
  recaptured every frame, the portal pair at depth 0 and 8.
* ``hd``: 16 mirrors at 1920x1080.
* ``views``: 16 mirrors at 128x72 in a subprocess with ``LP_NUM_THREADS=0``, as ``cpu``:
  about the views a GPU's 1920x1080 frame has (a view needs a claimed pixel: 34 at 32x18,
  about 90 here, 92-112 at 1920x1080), with llvmpipe's rasterising still small, so its
  ``engine_ms`` is the engine's Python and numpy at a GPU frame's view count; no target
  (``benchmarks/README.md``, "What the 32x18 frame leaves out").
* ``ecs``: the ECS suite's grid of 100,000 entities, 1% moving: the ECS frame's CPU.
* ``sample``: the sample level (``hall``: ``games.hall_of_mirrors`` from its start pose,
  crates spinning, three probes recaptured as they see them move, each face a view tree of
  the mirrors and portals it sees) at 640x360, and on a GPU at 1920x1080 too: what a user's
  first run costs; no target.  On llvmpipe it is the slowest scene by far (about 170 ms a
  frame at 640x360 on 2 cores); on a GPU host its frame is the engine's CPU.

Each part's engines run their frames interleaved in runs (``RUN_FRAMES``): every engine,
in a shuffled order, draws a run of frames back to back, then the next, so a shared
machine's drift falls on every scene alike and the ratios hold when absolute times drift.
A run's first frame follows the other engines' runs on the same context and finds the CPU's
caches full of their code and data, and its GL state displaced: it is the ``cold`` frame
(``cold_frame_ms_median``), reported and not judged; the others follow their own engine's
frame, as a game's frames follow each other, and are the frames the targets read (at 0
mirrors on 32x18 a cold frame is about 1.5x a following one: 2026-12-04, 0.99 against 0.64
ms, 50 GL calls against 37).  Scene rows: ``frame_ms_median`` (wall clock
around ``Engine.frame`` and ``ctx.finish()``), ``cpu_ms_median`` (until ``Engine.frame``
returns), ``thread_ms_median`` (the CPU time this thread spent in the frame, finish
included: with ``LP_NUM_THREADS=0`` llvmpipe rasterises on it, so at 32x18 it is the whole
frame's CPU, and on a loaded machine it does not count the time other processes took; with
rasteriser threads it leaves theirs out), ``views`` (reflection views), ``passes``, ``draw_calls`` (medians of
``RenderStats``) and ``gl_calls``: the calls a frame makes into the GL, counted over
``COUNTED_FRAMES`` more frames with ``GLCallCounter`` on (so the counting costs no timed
frame).  What that counts: every call into moderngl's GL objects (a method, a property
written, a query's result or ``ctx.error`` read; the outermost only where one calls
another), each of which reaches the driver, plus every raw GL call
(``engine/render/raw_gl.py``'s ctypes functions); ``gl_calls_top`` names the most made.
One moderngl call may issue a few GL functions (a draw binds its program and vertex array
first), so it is the count of the engine's requests to the driver, not of GL entry points.
The counter also times each call it counts: ``gl_share`` is the median share of a counted
frame's CPU (until ``Engine.frame`` returns) spent inside them, ``gl_ms_top`` where (ms a
frame, by label), and ``engine_ms`` the ``cpu_ms_median`` less that share: the engine's own
Python and numpy.  On llvmpipe the time in GL is not what a GPU's driver takes: even with
``LP_NUM_THREADS=0`` each draw shades its vertices on the calling thread (at 16 mirrors
about half the frame is inside ``VertexArray.render``, a box batch's draw in a view ~30 us
against a claim's ~4), and a flush or a query's read rasterises what is queued.  On a GPU
host the same columns give the driver's own cost a call.

Targets, each against its limit (``met``) on the kind of machine it is set for
(``applies``; the others are reported, not judged):

==============================  ============================================  ========  ========
target                          measured                                      limit     set for
==============================  ============================================  ========  ========
``cpu_frame_0_mirrors``         0 mirrors, 32x18, LP_NUM_THREADS=0: frame     0.6 ms    software
``cpu_frame_8_mirrors``         8 mirrors, the same                           2.0 ms    software
``cpu_frame_16_mirrors``        16 mirrors, the same                          3.5 ms    software
``cpu_portal_depth_8_ratio``    portals at depth 8 over depth 0, the same     2.5 x     software
``cpu_portal_moving_ratio``     the same with the swaying camera              2.5 x     software
``ratio_8_to_0_mirrors``        640x360: 8 mirrors' frame over 0 mirrors'     1.4 x     software
``dynamic_probe_share``         640x360: what a probe recaptured every frame  0.3 x     software
                                adds, over the frame without it
``ecs_cpu_ms``                  100,000 entities, 1% moving: the ECS          8 ms      software
                                frame's CPU (the ecs suite's ``cpu_ms``)
``gpu_frame_0_mirrors``         0 mirrors, 640x360: frame                     0.85 ms   gpu
``gpu_frame_16_mirrors_1080p``  16 mirrors, 1920x1080: frame                  3 ms      gpu
``gpu_portal_depth_8_ratio``    portals, 640x360: depth 8 over depth 0        2.5 x     gpu
``gpu_dynamic_probe_ms``        640x360: a probe every frame less none        0.3 ms    gpu
==============================  ============================================  ========  ========

"software": the limit is set for a software rasteriser (llvmpipe on the 2-core machine the
project is built on), "gpu": for a GPU.  Exit status 1 when a target that applies is not met
(``--report-only``: 0 whatever the values); a target whose part did not run is ``null``,
not judged.

The default run takes about two minutes on 2 llvmpipe cores (the 1920x1080 frames, the
100,000 entities and the sample level most of it).

    python -m benchmarks cpu                      # every part, tables, targets
    python -m benchmarks cpu --parts cpu --top 25 # the CPU frames and their profile only
    python -m benchmarks cpu --json --report-only
"""
from __future__ import annotations

import argparse
import inspect
import json
import os
import random
import statistics
import sys
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from time import perf_counter

from benchmarks import format_size, names_from, non_negative_int, positive_int, rows_without_rasteriser

ROOT = Path(__file__).resolve().parents[1]
CPU_SIZE = (32, 18)
SMALL = (640, 360)
LARGE = (1920, 1080)
ECS_ENTITIES = 100_000
DT = 1.0 / 60.0
COUNTED_FRAMES = 10  # frames per scene with the GL call counter on, after the timed ones
RUN_FRAMES = 10  # an engine's frames back to back in a round: one cold frame, then nine timed
VIEWS_SIZE = (128, 72)  # the views part: about as many views as a GPU's 1920x1080 frame
PARTS = ("cpu", "frames", "hd", "views", "ecs", "sample")
CPU_SCENES = ("mirrors_0", "mirrors_8", "mirrors_16", "portals_d0", "portals_d8", "portals_d0_sway",
              "portals_d8_sway")
FRAME_SCENES = ("mirrors_0", "mirrors_8", "probe_none", "probe_dynamic", "portals_d0", "portals_d8")
HD_SCENES = ("mirrors_16",)
VIEWS_SCENES = ("mirrors_16",)
SAMPLE_SCENES = ("hall",)


@dataclass(frozen=True)
class Target:
    limit: float
    unit: str
    set_for: str  # "software" (a software rasteriser: llvmpipe, this machine) or "gpu"
    part: str     # the part (--parts) that measures it
    what: str


TARGETS: dict[str, Target] = {
    "cpu_frame_0_mirrors": Target(0.6, "ms", "software", "cpu", "0 mirrors, 32x18, LP_NUM_THREADS=0: frame median"),
    "cpu_frame_8_mirrors": Target(2.0, "ms", "software", "cpu", "8 mirrors, 32x18, LP_NUM_THREADS=0: frame median"),
    "cpu_frame_16_mirrors": Target(3.5, "ms", "software", "cpu",
                                   "16 mirrors, 32x18, LP_NUM_THREADS=0: frame median"),
    "cpu_portal_depth_8_ratio": Target(2.5, "x", "software", "cpu",
                                       "portals, 32x18, LP_NUM_THREADS=0: depth 8 over depth 0"),
    "cpu_portal_moving_ratio": Target(2.5, "x", "software", "cpu",
                                      "portals, camera swaying, 32x18, LP_NUM_THREADS=0: depth 8 over depth 0"),
    "ratio_8_to_0_mirrors": Target(1.4, "x", "software", "frames", "640x360: 8 mirrors over 0 mirrors"),
    "dynamic_probe_share": Target(0.3, "x", "software", "frames",
                                  "640x360: a probe recaptured every frame, what it adds over the frame without"),
    "ecs_cpu_ms": Target(8.0, "ms", "software", "ecs", "100,000 entities, 1% moving: the ECS frame's CPU median"),
    "gpu_frame_0_mirrors": Target(0.85, "ms", "gpu", "frames", "0 mirrors, 640x360: frame median"),
    "gpu_frame_16_mirrors_1080p": Target(3.0, "ms", "gpu", "hd", "16 mirrors, 1920x1080: frame median"),
    "gpu_portal_depth_8_ratio": Target(2.5, "x", "gpu", "frames", "portals, 640x360: depth 8 over depth 0"),
    "gpu_dynamic_probe_ms": Target(0.3, "ms", "gpu", "frames", "640x360: a probe recaptured every frame less none"),
}


# -- scenes -----------------------------------------------------------------------------------

def make_scene(name: str, ctx):
    """The engine of scene ``name`` (``mirrors_<n>``, ``portals_d<depth>``, ``portals_d<depth>_sway``
    with a swaying camera, ``probe_none``, ``probe_dynamic``, ``glass_<panes>``: the 8-mirror ring
    with a see-through pond and that many panes, ``benchmarks.glass``; ``posed_<mirrors>_<n>``:
    the ring with n animated skinned and morphed meshes, ``benchmarks.posed`` (``_dq`` after:
    blended as dual quaternions);
    ``sparks_<mirrors>_<n>``: the ring with n living particles, ``benchmarks.sparks``;
    ``decals_<mirrors>_<n>``: the ring with n stains on its floor, ``benchmarks.decals``;
    any of them with ``_predicted`` after: its reflections with predicted visibility (a
    GPU's "auto": last frame's claim counts, no wait a level; ``ReflectionSystem.visibility``);
    ``focus_<mirrors>``: the ring seen through a lens with autofocus (its camera's
    ``DepthOfField``: 85 mm at f/1.4, the widest disc 0.05 of the height);
    ``monitor_<mirrors>``: the ring with a box of 256x144 monitor screens (depth 1) over its
    middle, fed by a camera over the ring (``components.Monitor``);
    ``streaks_<mirrors>``: the ring with motion blur on its orbiting camera, its spinning boxes
    streaking by their own motion (``MotionBlur()``; ``streaks_<mirrors>_camera``: by the
    camera's alone, ``objects=False``); ``hall``:
    the sample level), each with its suite's default settings."""
    from shell.app import Engine

    if name.endswith("_predicted"):  # (any scene, as a GPU's default draws its reflections)
        engine = make_scene(name.removesuffix("_predicted"), ctx)
        engine.reflection_system.visibility = "predicted"
        return engine
    if name == "hall":
        from games.hall_of_mirrors.level import HallOfMirrors

        return Engine(HallOfMirrors(), ctx)
    kind, _, arg = name.partition("_")
    if kind == "mirrors":
        from benchmarks.mirrors import MirrorRing

        return Engine(MirrorRing(int(arg)), ctx)
    if kind == "portals":  # portals_d<depth>, or portals_d<depth>_sway: the camera sways (FacingPortals)
        from benchmarks.portals import FacingPortals, set_depth

        depth, _, sway = arg.partition("_")
        if sway not in ("", "sway"):
            raise ValueError(f"no scene {name!r}")
        engine = Engine(FacingPortals(sway=sway == "sway"), ctx)
        set_depth(engine, int(depth.removeprefix("d")))
        return engine
    if kind == "glass":
        from benchmarks.glass import GlassHouse

        return Engine(GlassHouse(int(arg)), ctx)
    if kind == "sparks":  # sparks_<mirrors>_<particles>: the ring with sparks and smoke (benchmarks.sparks)
        from benchmarks.sparks import SparkRing

        mirrors, _, particles = arg.partition("_")
        return Engine(SparkRing(int(mirrors), int(particles or 0)), ctx)
    if kind == "decals":  # decals_<mirrors>_<decals>: the ring with stains on its floor and boxes (benchmarks.decals)
        from benchmarks.decals import DecalRing

        mirrors, _, decals = arg.partition("_")
        return Engine(DecalRing(int(mirrors), int(decals or 0)), ctx)
    if kind == "focus":  # focus_<mirrors>: the ring, its camera's lens focusing by itself (depth of field)
        from benchmarks.mirrors import MirrorRing
        from components import Camera, DepthOfField

        engine = Engine(MirrorRing(int(arg)), ctx)
        (camera, _), = engine.world.query_one(Camera)
        engine.world.add_component(camera, DepthOfField(f_stop=1.4, focal_length=85.0, max_blur=0.05,
                                                        autofocus=True))
        return engine
    if kind == "streaks":  # streaks_<mirrors>[_camera]: the ring with motion blur (per-object unless _camera)
        from benchmarks.mirrors import MirrorRing
        from components import Camera, MotionBlur

        mirrors, _, only = arg.partition("_")
        if only not in ("", "camera"):
            raise ValueError(f"no scene {name!r}")
        engine = Engine(MirrorRing(int(mirrors)), ctx)
        (camera, _), = engine.world.query_one(Camera)
        engine.world.add_component(camera, MotionBlur(objects=not only))
        return engine
    if kind == "monitor":  # monitor_<mirrors>: the ring with a monitor over its middle (components.Monitor)
        from pyglm import glm

        from benchmarks.mirrors import MirrorRing
        from components import Camera, Material, MeshRef, Monitor, Transform, look_rotation
        from engine.assets.mesh import box

        engine = Engine(MirrorRing(int(arg)), ctx)
        eye = glm.vec3(9.0, 6.0, 9.0)   # a feed over the ring, looking at its middle, its mirrors in sight
        feed = engine.world.spawn(Transform(position=eye, rotation=look_rotation(glm.vec3(0.0, 1.0, 0.0) - eye)),
                                  Camera(fov_y=60.0, active=False))
        # A box of screens over the middle (each side shows the picture): the orbiting camera
        # sees one or two of them all the way round.
        engine.world.spawn(Transform(position=(0.0, 4.5, 0.0)), MeshRef(box((1.6, 0.9, 1.6))),
                           Material(color=(0.01, 0.01, 0.01)), Monitor(camera=feed, size=(256, 144)))
        return engine
    if kind == "posed":  # posed_<mirrors>_<tentacles>[_dq]: the ring with animated skinned and morphed meshes
        from benchmarks.posed import PosedRing

        mirrors, _, posed = arg.partition("_")
        posed, _, blend = posed.partition("_")
        return Engine(PosedRing(int(mirrors), int(posed or 0), "dual_quaternion" if blend == "dq" else "linear"), ctx)
    if kind == "probe":
        from benchmarks.probes import MODES, ProbeRing

        return Engine(ProbeRing(MODES[arg]), ctx)
    raise ValueError(f"no scene {name!r}")


def scale_shadows_down(engine) -> None:
    """Shadow maps as small as the frame: at 32x18 llvmpipe should rasterise almost nothing,
    so the frame is the engine's CPU, but a sun's map is 2048 texels a side whatever the
    output, and a spinning box redraws part of it every frame.  The casters' draws (the CPU
    a GPU host pays for) are the same at any resolution."""
    from components import DirectionalLight, PointLight
    from components.camera import MIN_SHADOW_RESOLUTION

    for kind in (DirectionalLight, PointLight):
        for _, light in engine.world.query_one(kind):
            light.shadow_resolution = MIN_SHADOW_RESOLUTION


# -- counting GL calls ------------------------------------------------------------------------

class GLCallCounter:
    """Counts the calls the engine makes into the GL while open (``with GLCallCounter() as
    counter``): every call into moderngl's GL objects (their methods, the properties written,
    ``ctx.error`` and a query's results read) and, with ``count_raw`` set, every raw GL call
    (``engine/render/raw_gl.py``'s ctypes functions).

    moderngl's methods are wrapped on their classes only while open (nothing of it in a timed
    frame); where one wrapped call makes another, only the outermost counts (the engine asked
    once).  The raw functions are loaded when the objects that call them are made, so
    ``raw_gl_loading()`` (open around the process's engines) hands out counting wrappers: a
    flag test and an add a call, on a few calls a frame.  ``calls`` maps ``Class.name`` to its
    count; ``reset()`` before a frame, ``total`` after it.
    """

    READS = {"Context": ("error",), "Query": ("samples", "primitives", "elapsed"), "Uniform": ("value",)}
    NOT_GL = {"Program": ("get",), "Context": ("core_profile_check",)}  # pure Python lookups

    def __init__(self) -> None:
        self.calls: Counter[str] = Counter()
        # Seconds spent inside the calls counted (the outermost, wall clock), by label as
        # ``calls``: what a frame spends in the driver (on llvmpipe with LP_NUM_THREADS=0 that
        # includes the vertex work each draw does on the calling thread and the rasterising a
        # flush or a query's read waits for; on a GPU, the driver's CPU and its waits).
        self.seconds: Counter[str] = Counter()
        self.count_raw = False
        self._depth = 0
        self._saved: list[tuple[type, str, object]] = []

    @staticmethod
    def classes() -> list[type]:
        import _moderngl
        import moderngl

        return [moderngl.Context, moderngl.Buffer, moderngl.Texture, moderngl.TextureArray, moderngl.Texture3D,
                moderngl.TextureCube, moderngl.Framebuffer, moderngl.Renderbuffer, moderngl.VertexArray,
                moderngl.Program, moderngl.Query, moderngl.ConditionalRender, moderngl.Sampler, moderngl.Scope,
                _moderngl.Uniform, _moderngl.UniformBlock]

    @property
    def total(self) -> int:
        return sum(self.calls.values())

    @property
    def total_seconds(self) -> float:
        return sum(self.seconds.values())

    def reset(self) -> None:
        self.calls.clear()
        self.seconds.clear()

    def open(self) -> GLCallCounter:
        if self._saved:
            return self
        self.count_raw = True
        for owner in self.classes():
            skip = self.NOT_GL.get(owner.__name__, ())
            reads = self.READS.get(owner.__name__, ())
            for name, attr in list(vars(owner).items()):
                if name in skip or (name.startswith("_") and name not in ("__enter__", "__exit__")):
                    continue
                label = f"{owner.__name__}.{name}"
                if isinstance(attr, property):
                    if attr.fset is None and name not in reads:
                        continue
                    wrapped = property(self._counted(attr.fget, label) if name in reads else attr.fget,
                                       None if attr.fset is None else self._counted(attr.fset, label), attr.fdel,
                                       attr.__doc__)
                elif inspect.isfunction(attr):
                    wrapped = self._counted(attr, label)
                else:
                    continue
                self._saved.append((owner, name, attr))
                setattr(owner, name, wrapped)
        return self

    def close(self) -> None:
        self.count_raw = False
        for owner, name, original in reversed(self._saved):
            setattr(owner, name, original)
        self._saved.clear()

    def __enter__(self) -> GLCallCounter:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _counted(self, function, label: str):
        counter = self

        def counted(*args, **kwargs):
            if counter._depth:
                return function(*args, **kwargs)
            counter.calls[label] += 1
            counter._depth += 1
            start = perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                counter.seconds[label] += perf_counter() - start
                counter._depth -= 1
        return counted

    def raw_gl_loading(self):
        """A context manager: raw GL functions loaded inside it count their calls while this
        counter is open (``engine.render.raw_gl._load`` hands out counting wrappers)."""
        import contextlib

        from engine.render import raw_gl

        counter = self

        @contextlib.contextmanager
        def loading():
            real = raw_gl._load

            def load(ctx, name, prototype):
                function = real(ctx, name, prototype)
                if function is None:
                    return None
                label = f"raw {name}"

                def raw(*args):
                    if counter.count_raw and not counter._depth:
                        counter.calls[label] += 1
                        start = perf_counter()
                        try:
                            return function(*args)
                        finally:
                            counter.seconds[label] += perf_counter() - start
                    return function(*args)
                raw.__code__ = raw.__code__.replace(co_name=name)  # a profile names the GL function
                return raw

            raw_gl._load = load
            try:
                yield counter
            finally:
                raw_gl._load = real
        return loading()


# -- running scenes ---------------------------------------------------------------------------

def _percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, max(0, int(q * len(ordered) + 0.999999) - 1))]


def run_scenes(ctx, names: tuple[str, ...], size: tuple[int, int], frames: int, warmup: int,
               profile_top: int = 0, profile_frames: int = 0, seed: int = 0) -> list[dict]:
    """Every scene of ``names`` an engine, drawn at ``size``: ``warmup`` frames each, then
    rounds of runs (``RUN_FRAMES``: a cold frame, timed apart, then up to ``RUN_FRAMES - 1``
    timed ones) in a shuffled order each round until each has ``frames`` timed frames, then
    a cold frame and ``COUNTED_FRAMES`` frames each with the GL call counter on, then
    (``profile_top``) ``profile_frames`` frames each under cProfile.  A row a scene, then
    each profiled scene's ``profile_top`` functions by their own time."""
    from engine.core.frame_io import Output
    from engine.render.targets import CaptureTarget

    counter = GLCallCounter()
    engines, captures = [], []
    try:
        with counter.raw_gl_loading():
            for name in names:
                engines.append(make_scene(name, ctx))
                if size == CPU_SIZE:
                    scale_shadows_down(engines[-1])
                captures.append(CaptureTarget(ctx, size))
        outputs = [Output(capture.framebuffer, size) for capture in captures]
        times: list[list[float]] = [[] for _ in names]
        cold: list[list[float]] = [[] for _ in names]  # each run's first frame, after the others' runs
        cpu: list[list[float]] = [[] for _ in names]
        thread: list[list[float]] = [[] for _ in names]
        stats: list[list] = [[] for _ in names]
        order = list(range(len(names)))
        rng = random.Random(seed)
        for i in order:
            for _ in range(warmup):
                engines[i].frame(DT, outputs[i])
                ctx.finish()
        timed_per_run = RUN_FRAMES - 1
        for first in range(0, frames, timed_per_run):
            rng.shuffle(order)  # each engine's run follows every other's alike
            for i in order:
                for run_frame in range(min(timed_per_run, frames - first) + 1):
                    start, own = time.perf_counter(), time.thread_time()
                    engines[i].frame(DT, outputs[i])
                    returned = time.perf_counter()
                    ctx.finish()
                    if not run_frame:
                        cold[i].append((time.perf_counter() - start) * 1e3)
                        continue
                    times[i].append((time.perf_counter() - start) * 1e3)
                    cpu[i].append((returned - start) * 1e3)
                    thread[i].append((time.thread_time() - own) * 1e3)
                    stats[i].append(engines[i].renderer.stats)
        counted: list[list[int]] = [[] for _ in names]
        kinds: list[Counter] = [Counter() for _ in names]
        in_gl: list[list[float]] = [[] for _ in names]  # each counted frame's share of its CPU in GL calls
        gl_ms: list[list[float]] = [[] for _ in names]
        spent: list[Counter] = [Counter() for _ in names]
        with counter:
            for i in range(len(names)):  # a cold frame, then COUNTED_FRAMES following ones
                engines[i].frame(DT, outputs[i])
                ctx.finish()
                for _ in range(COUNTED_FRAMES):
                    counter.reset()
                    start = perf_counter()
                    engines[i].frame(DT, outputs[i])
                    took = perf_counter() - start
                    counted[i].append(counter.total)
                    kinds[i].update(counter.calls)
                    spent[i].update(counter.seconds)
                    gl_ms[i].append(counter.total_seconds * 1e3)
                    in_gl[i].append(counter.total_seconds / took)
                    ctx.finish()
        if ctx.error != "GL_NO_ERROR":
            raise RuntimeError(f"OpenGL error: {ctx.error}")
        lp = os.environ.get("LP_NUM_THREADS")
        rows = [{"scene": name, "size": format_size(size), "frames": frames,
                 "frame_ms_median": round(statistics.median(times[i]), 3),
                 "frame_ms_p95": round(_percentile(times[i], 0.95), 3),
                 "cold_frame_ms_median": round(statistics.median(cold[i]), 3),
                 "cpu_ms_median": round(statistics.median(cpu[i]), 3),
                 "thread_ms_median": round(statistics.median(thread[i]), 3),
                 "views": round(statistics.median(s.reflection_views for s in stats[i])),
                 "passes": round(statistics.median(s.passes for s in stats[i])),
                 "draw_calls": round(statistics.median(s.draw_calls for s in stats[i])),
                 "gl_calls": round(statistics.median(counted[i])),
                 "gl_calls_top": {label: round(n / COUNTED_FRAMES, 1) for label, n in kinds[i].most_common(8)},
                 "gl_ms_median": round(statistics.median(gl_ms[i]), 3),
                 "gl_share": round(statistics.median(in_gl[i]), 3),
                 "engine_ms": round(statistics.median(cpu[i]) * (1.0 - statistics.median(in_gl[i])), 3),
                 "gl_ms_top": {label: round(t * 1e3 / COUNTED_FRAMES, 3) for label, t in spent[i].most_common(8)},
                 "lp_num_threads": lp}
                for i, name in enumerate(names)]
        if profile_top:
            for name, engine, output in zip(names, engines, outputs, strict=True):
                rows += profile_rows(ctx, name, engine, output, profile_frames, profile_top)
        return rows
    finally:
        for capture in captures:
            capture.release()
        for engine in engines:
            engine.close()


def profile_rows(ctx, name: str, engine, output, frames: int, top: int) -> list[dict]:
    """``frames`` frames of ``engine`` under cProfile (around ``Engine.frame`` only): a head row
    and its ``top`` functions by own time, as the profile suite's rows."""
    from benchmarks.cpu_profile import function_rows, profile_frames

    times, ranked = profile_frames(ctx, engine, output, frames, top)
    rows = [{"scene": name, "frames": frames, "frame_ms_profiled": round(statistics.median(times), 3)}]
    return rows + function_rows(name, ranked, frames)


def run_ecs(ctx, frames: int, warmup: int) -> list[dict]:
    from benchmarks.ecs import run_scene

    result = run_scene(ctx, ECS_ENTITIES, frames, warmup)
    return [{"scene": "ecs", "entities": result.entities, "moving": result.moving, "frames": frames,
             "cpu_ms_median": result.cpu_ms_median, "frame_ms_median": result.frame_ms_median,
             "draw_calls": result.draw_calls}]


def cpu_part(frames: int, warmup: int, top: int, part: str = "cpu") -> list[dict]:
    """The ``cpu`` (or ``views``) part's rows, from a subprocess started with ``LP_NUM_THREADS=0``."""
    return rows_without_rasteriser(["cpu", "--json", "--child", "--parts", part, "--frames", str(frames),
                                    "--warmup", str(warmup), "--top", str(top)])


# -- targets ----------------------------------------------------------------------------------

def values(rows: list[dict]) -> dict[str, float | None]:
    """Each target's value from the scene rows (None where its scenes did not run)."""
    frame: dict[tuple[str, str], float] = {(r["scene"], r["size"]): r["frame_ms_median"]
                                           for r in rows if "size" in r and "rank" not in r}
    ecs = next((r["cpu_ms_median"] for r in rows if r.get("scene") == "ecs"), None)
    cpu, small, large = format_size(CPU_SIZE), format_size(SMALL), format_size(LARGE)

    def ratio(a: str, b: str, size: str, less: float = 0.0) -> float | None:
        if (a, size) not in frame or (b, size) not in frame:
            return None
        return round(frame[a, size] / frame[b, size] - less, 3)

    def diff(a: str, b: str, size: str) -> float | None:
        if (a, size) not in frame or (b, size) not in frame:
            return None
        return round(frame[a, size] - frame[b, size], 3)

    return {
        "cpu_frame_0_mirrors": frame.get(("mirrors_0", cpu)),
        "cpu_frame_8_mirrors": frame.get(("mirrors_8", cpu)),
        "cpu_frame_16_mirrors": frame.get(("mirrors_16", cpu)),
        "cpu_portal_depth_8_ratio": ratio("portals_d8", "portals_d0", cpu),
        "cpu_portal_moving_ratio": ratio("portals_d8_sway", "portals_d0_sway", cpu),
        "ratio_8_to_0_mirrors": ratio("mirrors_8", "mirrors_0", small),
        "dynamic_probe_share": ratio("probe_dynamic", "probe_none", small, less=1.0),
        "ecs_cpu_ms": ecs,
        "gpu_frame_0_mirrors": frame.get(("mirrors_0", small)),
        "gpu_frame_16_mirrors_1080p": frame.get(("mirrors_16", large)),
        "gpu_portal_depth_8_ratio": ratio("portals_d8", "portals_d0", small),
        "gpu_dynamic_probe_ms": diff("probe_dynamic", "probe_none", small),
    }


def judge(found: dict[str, float | None], software: bool) -> list[dict]:
    """A row a target: its value, limit, whether it is met (None: not measured) and whether
    it is judged here (``applies``: measured, on the kind of machine its limit is set for)."""
    out = []
    for name, target in TARGETS.items():
        value = found.get(name)
        out.append({"target": name, "value": value, "limit": target.limit, "unit": target.unit,
                    "met": None if value is None else value <= target.limit, "set_for": target.set_for,
                    "applies": value is not None and (target.set_for == "software") == software,
                    "measured": target.what})
    return out


def unmet(targets: list[dict]) -> list[dict]:
    """The targets that apply here and are not met."""
    return [row for row in targets if row["applies"] and not row["met"]]


# -- command line -----------------------------------------------------------------------------

def _parts(text: str) -> tuple[str, ...]:
    return names_from(text, PARTS, "parts")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--frames", type=positive_int, default=60, help="timed frames per scene (default 60)")
    parser.add_argument("--warmup", type=non_negative_int, default=10, help="untimed frames first (default 10)")
    parser.add_argument("--top", type=non_negative_int, default=15,
                        help="functions per 32x18 scene in the cProfile table (default 15; 0: no profile)")
    parser.add_argument("--parts", type=_parts, default=PARTS, metavar="NAME[,NAME...]",
                        help=f"which parts (default {','.join(PARTS)}); a target of a part not run is not judged")
    parser.add_argument("--report-only", action="store_true",
                        help="exit 0 whatever the targets (they are still printed, met or not)")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)  # the LP_NUM_THREADS=0 process


def measure(args: argparse.Namespace) -> tuple[list[dict], bool, str]:
    """(scene and profile rows of the parts asked, software rasteriser or not, GL_RENDERER)."""
    from engine.render.gl_context import GLCapabilities, create_headless_context

    rows: list[dict] = []
    if "cpu" in args.parts:
        rows += cpu_part(args.frames, args.warmup, args.top)
    if "views" in args.parts:
        rows += cpu_part(args.frames, args.warmup, 0, "views")
    ctx = create_headless_context()
    try:
        software = GLCapabilities.read(ctx).software
        renderer = str(ctx.info.get("GL_RENDERER", "?"))
        if "frames" in args.parts:
            rows += run_scenes(ctx, FRAME_SCENES, SMALL, args.frames, args.warmup)
        if "hd" in args.parts:
            rows += run_scenes(ctx, HD_SCENES, LARGE, args.frames, args.warmup)
        if "ecs" in args.parts:
            rows += run_ecs(ctx, args.frames, args.warmup)
        if "sample" in args.parts:
            for size in (SMALL,) if software else (SMALL, LARGE):
                rows += run_scenes(ctx, SAMPLE_SCENES, size, args.frames, args.warmup)
        if ctx.error != "GL_NO_ERROR":
            raise RuntimeError(f"OpenGL error: {ctx.error}")
    finally:
        ctx.release()
    return rows, software, renderer


def _share(value: float | None) -> str:
    return "-" if value is None else f"{value:.0%}"


def print_tables(rows: list[dict], targets: list[dict], renderer: str, frames: int, warmup: int,
                 out: Callable[[str], None] = print) -> None:
    out(f"CPU frames and targets on {renderer} ({frames} frames after {warmup} warm-up, interleaved in runs of "
        f"{RUN_FRAMES}; cold: a run's first frame, after the other engines' runs)")
    out(f"{'scene':<15} {'size':>9} {'LP':>3} {'frame ms':>9} {'cold ms':>8} {'cpu ms':>8} {'thread ms':>9} "
        f"{'views':>5} {'passes':>6} {'draws':>5} {'GL calls':>8} {'in GL':>6} {'engine ms':>9}")
    scenes = [row for row in rows if not ("rank" in row or "frames" not in row or row.get("scene") == "ecs"
                                          or "frame_ms_profiled" in row)]
    for row in scenes:
        out(f"{row['scene']:<15} {row['size']:>9} {row['lp_num_threads'] or '-':>3} {row['frame_ms_median']:>9} "
            f"{row.get('cold_frame_ms_median', '-')!s:>8} {row['cpu_ms_median']:>8} {row['thread_ms_median']:>9} "
            f"{row['views']:>5} {row['passes']:>6} "
            f"{row['draw_calls']:>5} {row['gl_calls']:>8} {_share(row.get('gl_share')):>6} "
            f"{row.get('engine_ms', '-')!s:>9}")
    if any("gl_ms_top" in row for row in scenes):
        out("in GL: the share of a frame's CPU (until Engine.frame returns) spent inside GL calls, over "
            f"{COUNTED_FRAMES} counted frames; engine ms: cpu ms less that share (Python and numpy).  Where the GL "
            "time goes, ms a frame:")
        for row in scenes:
            out(f"  {row['scene']:<15} " + ", ".join(f"{label} {ms}" for label, ms in row.get("gl_ms_top", {}).items()))
    for row in rows:
        if row.get("scene") == "ecs":
            out(f"ecs: {row['entities']} entities, {row['moving']} moving: CPU {row['cpu_ms_median']} ms, "
                f"frame {row['frame_ms_median']} ms, {row['draw_calls']} draws")
    for head in (r for r in rows if "frame_ms_profiled" in r):
        out(f"\n{head['scene']} at 32x18 under cProfile: {head['frames']} frames, median "
            f"{head['frame_ms_profiled']} ms profiled")
        out(f"{'own ms':>9} {'total ms':>9} {'calls':>8}  function")
        for row in rows:
            if row.get("scene") == head["scene"] and "rank" in row:
                out(f"{row['own_ms_per_frame']:9.3f} {row['total_ms_per_frame']:9.3f} {row['calls_per_frame']:8.1f}  "
                    f"{row['function']}")
    out("")
    out(f"{'target':<28} {'value':>8} {'limit':>9} {'met':>6} {'set for':>9}  measured")
    for row in targets:
        met = "-" if row["met"] is None else ("yes" if row["met"] else "no")
        if row["met"] is not None and not row["applies"]:
            met = f"({met})"
        limit = f"{row['limit']} {row['unit']}"
        out(f"{row['target']:<28} {row['value']!s:>8} {limit:>9} {met:>6} {row['set_for']:>9}  {row['measured']}")


def main(args: argparse.Namespace) -> int:
    if args.child:  # the LP_NUM_THREADS=0 process: the 32x18 scenes' rows (the views part's: 128x72)
        from engine.render.gl_context import create_headless_context

        ctx = create_headless_context()
        try:
            if args.parts == ("views",):
                rows = run_scenes(ctx, VIEWS_SCENES, VIEWS_SIZE, args.frames, args.warmup)
            else:
                rows = run_scenes(ctx, CPU_SCENES, CPU_SIZE, args.frames, args.warmup, args.top,
                                  args.frames if args.top else 0)
        finally:
            ctx.release()
        for row in rows:
            print(json.dumps(row), flush=True)
        return 0
    rows, software, renderer = measure(args)
    targets = judge(values(rows), software)
    if args.json:
        for row in rows + targets:
            print(json.dumps(row), flush=True)
    else:
        print_tables(rows, targets, renderer, args.frames, args.warmup)
        sys.stdout.flush()
    missed = unmet(targets)
    if missed and not args.json:
        print(f"not met: {', '.join(row['target'] for row in missed)}", file=sys.stderr)
    return 1 if missed and not args.report_only else 0
