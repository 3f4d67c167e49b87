"""ECS benchmark: the per-frame CPU cost of the systems and the instance upload.

Scenes of 100, 1,000 and 10,000 renderable entities (Transform + MeshRef + Material) on a
grid, spread over four shared meshes, so a frame is 4 instanced draws plus the sky
(``draw_calls`` = 5 whatever the entity count).  1% of the entities move: the game's
``update`` assigns their ``Transform.rotation`` and ``Transform.position`` every frame
(those 2 validated writes a mover are part of ``cpu_ms``: about half of it at 100,000).
The movers are scattered over every batch; from their first moving frame their rows lie
together at the front of each batch (``InstanceBatch.write_transforms``), so a moving
frame uploads one span a batch.

What is timed (``cpu_ms``): one ``Engine.frame(dt, output)`` call, i.e. ``World.step`` -
game update, fly camera, TransformSystem, RenderSystem extract + prepare (instance upload,
lights) - *minus* the time spent inside ``ScenePass.draw`` and ``Renderer.present``
(the draw submission, which on a software rasteriser is GPU work done on the CPU).
``ctx.finish()`` runs after every frame, outside the timed span, so one frame's drawing
never stalls the next frame's upload.  The output is a 64x36 capture target, as in the
tests (``--size``; ``--sizes`` is the entity counts).  ``frame_ms_median`` is the whole
``Engine.frame`` call for reference.  On a software rasteriser (llvmpipe) the draw of the
previous frame leaves the CPU caches cold, which adds ~0.2 ms to ``cpu_ms`` at 10,000
entities compared with running the systems back to back without drawing; that cost is
real for a frame and is left in.

Each size runs ``--warmup`` frames (the first uploads every instance), then ``--frames``
timed frames with the movers moving, then ``--frames`` frames where nothing is assigned:
``static_uploaded_bytes`` is the most any of those uploaded and must be 0 (the exit status
is 1 otherwise) and ``static_cpu_ms_median`` is their cost.  ``draw_calls``,
``uploaded_bytes`` and ``instances`` are medians of ``engine.renderer.stats`` over the
timed moving frames.

    python -m benchmarks ecs            # table
    python -m benchmarks ecs --json     # one JSON object per scene size
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from dataclasses import asdict, dataclass

from pyglm import glm

from benchmarks import add_size_argument
from components import DirectionalLight, Material, MeshRef, Transform
from engine.assets.mesh import box, sphere
from engine.core.frame_io import Output
from engine.core.game import Game, spawn_camera
from engine.core.world import World
from engine.render.gl_context import create_headless_context
from engine.render.targets import CaptureTarget
from shell.app import Engine

SIZES = (100, 1_000, 10_000)
MOVING_FRACTION = 0.01
OUTPUT_SIZE = (64, 36)
DT = 1.0 / 60.0
# Low-poly meshes keep the (untimed) software-rasterised draws short.
MESHES = (
    lambda: box((0.8, 0.8, 0.8), name="cube"),
    lambda: box((0.4, 1.2, 0.4), name="post"),
    lambda: sphere(0.45, segments=12, rings=6, name="ball"),
    lambda: sphere(0.3, segments=8, rings=4, name="pebble"),
)


class GridScene(Game):
    """``count`` renderable entities on a square grid, one in ``1 / MOVING_FRACTION`` moving.

    Entity ``i`` draws mesh ``i % 4``; the movers are spread over every mesh (and so every
    batch) and over the whole grid: one per block of 100, at offset ``block % 4``.
    """

    title = "benchmark: ecs"

    def __init__(self, count: int) -> None:
        self.count = count
        self.moving = True
        self.movers: list[tuple[Transform, glm.vec3]] = []
        self._time = 0.0

    def build(self, world: World) -> None:
        side = math.ceil(math.sqrt(self.count))
        spawn_camera(world, position=(0.0, side * 0.6, side * 1.2), pitch=-30.0, fly=False)
        # Its sun casts no shadow: this suite times the ECS stages, and a thousand movers
        # scattered over the grid redraw the whole shadow map every frame, 100,000 instances
        # of vertex work that llvmpipe does on the frame's own thread (about a second a frame
        # here).  What shadows cost is the lighting suite's (benchmarks/lighting.py).
        world.spawn(DirectionalLight(direction=(-0.4, -1.0, -0.5), shadows=False))
        meshes = [make() for make in MESHES]
        every = max(1, round(1.0 / MOVING_FRACTION))
        for i in range(self.count):
            position = glm.vec3(i % side - side / 2, 0.0, i // side - side / 2)
            transform = Transform(position=position)
            world.spawn(transform, MeshRef(meshes[i % len(meshes)]),
                        Material(color=(0.2 + 0.6 * (i % 7) / 6, 0.5, 0.8 - 0.6 * (i % 5) / 4)))
            if i % every == (i // every) % len(meshes):
                self.movers.append((transform, position))

    def update(self, world: World, dt: float) -> None:
        if not self.moving:
            return
        self._time += dt
        spin = glm.angleAxis(self._time, glm.vec3(0.0, 1.0, 0.0))
        lift = glm.vec3(0.0, 0.25 * math.sin(self._time * 3.0), 0.0)
        for transform, home in self.movers:
            transform.rotation = spin
            transform.position = home + lift


@dataclass
class Result:
    entities: int
    moving: int
    cpu_ms_median: float
    cpu_ms_p95: float
    draw_calls: int
    uploaded_bytes: int
    static_uploaded_bytes: int
    static_cpu_ms_median: float
    frame_ms_median: float
    instances: int
    frames: int


class _DrawClock:
    """Accumulates the wall time spent in the renderer's draw calls (the scene pass, present)."""

    def __init__(self, renderer) -> None:
        self.seconds = 0.0
        for owner, name in ((renderer.scene_pass, "draw"), (renderer, "present")):
            setattr(owner, name, self._timed(getattr(owner, name)))

    def _timed(self, method):
        def timed(*args, **kwargs):
            start = time.perf_counter()
            try:
                return method(*args, **kwargs)
            finally:
                self.seconds += time.perf_counter() - start
        return timed


def _percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, max(0, math.ceil(q * len(ordered)) - 1))]


def run_scene(ctx, count: int, frames: int, warmup: int, size: tuple[int, int] = OUTPUT_SIZE) -> Result:
    game = GridScene(count)
    engine = Engine(game, ctx)
    capture = CaptureTarget(ctx, size)
    output = Output(capture.framebuffer, size)
    clock = _DrawClock(engine.renderer)
    try:
        def frame() -> tuple[float, float]:
            clock.seconds = 0.0
            start = time.perf_counter()
            engine.frame(DT, output)
            total = time.perf_counter() - start
            ctx.finish()
            return (total - clock.seconds) * 1e3, total * 1e3

        for _ in range(warmup):
            frame()
        cpu, whole, stats = [], [], []
        for _ in range(frames):
            c, w = frame()
            cpu.append(c)
            whole.append(w)
            stats.append(engine.renderer.stats)
        game.moving = False
        static_cpu, static_bytes = [], 0
        for _ in range(frames):
            static_cpu.append(frame()[0])
            static_bytes = max(static_bytes, engine.renderer.stats.uploaded_bytes)
        if ctx.error != "GL_NO_ERROR":
            raise RuntimeError(f"OpenGL error in the {count}-entity scene: {ctx.error}")
        return Result(
            entities=count,
            moving=len(game.movers),
            cpu_ms_median=round(statistics.median(cpu), 3),
            cpu_ms_p95=round(_percentile(cpu, 0.95), 3),
            draw_calls=round(statistics.median(s.draw_calls for s in stats)),
            uploaded_bytes=round(statistics.median(s.uploaded_bytes for s in stats)),
            static_uploaded_bytes=static_bytes,
            static_cpu_ms_median=round(statistics.median(static_cpu), 3),
            frame_ms_median=round(statistics.median(whole), 3),
            instances=round(statistics.median(s.instances for s in stats)),
            frames=frames,
        )
    finally:
        capture.release()
        engine.close()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--sizes", type=lambda text: tuple(int(v) for v in text.split(",")), default=SIZES,
                        help="comma-separated entity counts (default 100,1000,10000)")
    parser.add_argument("--frames", type=int, default=60, help="timed frames per size (default 60)")
    parser.add_argument("--warmup", type=int, default=10, help="untimed frames first (default 10)")
    add_size_argument(parser, OUTPUT_SIZE, "output (not the entity counts: --sizes)")


COLUMNS = (("entities", "entities", 9), ("moving", "moving", 7), ("cpu_ms_median", "cpu ms med", 11),
           ("cpu_ms_p95", "cpu ms p95", 11), ("draw_calls", "draws", 6), ("uploaded_bytes", "uploaded B", 11),
           ("static_uploaded_bytes", "static B", 9), ("static_cpu_ms_median", "static ms", 10),
           ("frame_ms_median", "frame ms", 9))


def main(args: argparse.Namespace) -> int:
    if args.frames < 1 or args.warmup < 1 or any(size < 1 for size in args.sizes):
        raise SystemExit("--frames, --warmup and --sizes must be >= 1")
    ctx = create_headless_context()
    failed = []
    try:
        if not args.json:
            print(f"ECS systems + instance upload per frame ({ctx.info.get('GL_RENDERER', '?')}, "
                  f"{args.frames} frames after {args.warmup} warm-up)")
            print(" ".join(f"{title:>{width}}" for _, title, width in COLUMNS))
        for size in args.sizes:
            result = run_scene(ctx, size, args.frames, args.warmup, args.size)
            if result.static_uploaded_bytes:
                failed.append(size)
            if args.json:
                print(json.dumps(asdict(result)), flush=True)
            else:
                row = asdict(result)
                print(" ".join(f"{row[key]:>{width}}" for key, _, width in COLUMNS), flush=True)
    finally:
        ctx.release()
    if failed:
        print(f"benchmarks ecs: frames where nothing moved still uploaded instance data at sizes {failed}",
              file=sys.stderr)
        return 1
    return 0
