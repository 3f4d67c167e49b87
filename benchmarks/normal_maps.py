"""Normal-maps benchmark: what a normal map costs a whole frame.

The scene is ``benchmarks.mirrors.MirrorRing`` with no mirrors (a 40 x 40 textured ground
that covers about half of the 640 x 360 frame (``--size``), 20 boxes, two lights); the ``mapped`` engine
gives the ground a ripple normal map (``engine.assets.texture_data.ripple_normal_map``).  Rows
(``ground``, ``anisotropy``, ``frame_ms_median``, ``ratio_to_plain``): whole frames
(``Engine.frame`` + ``finish``), the engines interleaved frame by frame: ``plain``, then
``mapped`` with the renderer's normal-map anisotropy (``Renderer.normal_map_anisotropy``:
1 on a software rasteriser) and with the colour textures' (8x), which is what made llvmpipe
filter normal maps trilinearly; ``parallax``: the map with heights in its alpha (rings) and
``Material.parallax_depth`` 5 cm (its PARALLAX build: the view ray marched in 6 to 16 steps).

    python -m benchmarks normal_maps            # table
    python -m benchmarks normal_maps --json     # one JSON object per line
    python -m benchmarks normal_maps --size 1920x1080
"""
from __future__ import annotations

import argparse
import json
import statistics
import time

import moderngl
import numpy as np

from benchmarks import add_size_argument
from benchmarks.mirrors import DT, OUTPUT_SIZE, MirrorRing
from components import Material
from engine.assets.texture_data import TextureData, ripple_normal_map
from engine.core.frame_io import Output
from engine.render.gl_context import create_headless_context
from engine.render.targets import CaptureTarget
from shell.app import Engine


class MappedGround(MirrorRing):
    """The mirror benchmark's scene without mirrors, its ground normal-mapped."""

    title = "benchmark: normal maps"

    def __init__(self, normal_map, parallax_depth: float = 0.0) -> None:
        super().__init__(0)
        self.normal_map = normal_map
        self.parallax_depth = parallax_depth

    def build(self, world) -> None:
        super().build(world)
        for _, (material,) in world.query(Material):
            if material.texture is not None:  # the ground, the scene's one textured thing
                material.normal_map = self.normal_map
                material.parallax_depth = self.parallax_depth


def with_heights(normal_map: TextureData) -> TextureData:
    """``normal_map`` with heights in its alpha: rings, 0 to 1 (its ``parallax`` row's)."""
    pixels = normal_map.pixels.copy()
    h, w = pixels.shape[:2]
    y, x = np.mgrid[0:h, 0:w] / np.array([h, w])[:, None, None]
    pixels[..., 3] = (127.5 + 127.5 * np.sin(np.hypot(x - 0.5, y - 0.5) * 60.0)).astype(np.uint8)
    return TextureData(pixels, name=f"{normal_map.name} with heights")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--frames", type=int, default=40, help="timed frames (default 40)")
    parser.add_argument("--warmup", type=int, default=3)
    add_size_argument(parser, OUTPUT_SIZE)


def main(args: argparse.Namespace) -> int:
    ctx: moderngl.Context = create_headless_context()
    engines, captures = [], []
    try:
        ripples = ripple_normal_map(256, 10, 0.5)
        plain = Engine(MirrorRing(0), ctx)
        default = Engine(MappedGround(ripples), ctx)
        anisotropic = Engine(MappedGround(ripple_normal_map(256, 10, 0.5, name="ripples 8x")), ctx)
        anisotropic.renderer.normal_map_anisotropy = anisotropic.renderer.texture_anisotropy
        parallax = Engine(MappedGround(with_heights(ripples), parallax_depth=0.05), ctx)
        engines = [plain, default, anisotropic, parallax]
        rows = [("plain", None), ("mapped", default.renderer.normal_map_anisotropy),
                ("mapped", anisotropic.renderer.texture_anisotropy),
                ("parallax", parallax.renderer.normal_map_anisotropy)]
        captures = [CaptureTarget(ctx, args.size) for _ in engines]
        times: list[list[float]] = [[] for _ in engines]
        for frame in range(args.warmup + args.frames):
            for i, (engine, capture) in enumerate(zip(engines, captures, strict=True)):
                start = time.perf_counter()
                engine.frame(DT, Output(capture.framebuffer, args.size))
                ctx.finish()
                if frame >= args.warmup:
                    times[i].append((time.perf_counter() - start) * 1e3)
        base = statistics.median(times[0])
        for (ground, anisotropy), samples in zip(rows, times, strict=True):
            row = {"ground": ground, "anisotropy": anisotropy, "frame_ms_median": round(statistics.median(samples), 2),
                   "ratio_to_plain": round(statistics.median(samples) / base, 3)}
            print(json.dumps(row) if args.json else "  ".join(f"{k}={v}" for k, v in row.items()), flush=True)
    finally:
        for capture in captures:
            capture.release()
        for engine in engines:
            engine.close()
        ctx.release()
    return 0
