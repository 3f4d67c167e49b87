"""Command line of every game: windowed through moderngl-window, or headless on EGL.

  python -m games.<name> [--headless] [--frames N] [--size WxH] [--out DIR]
                         [--ids] [--export-scene FILE.glb] [--camera x,y,z,yaw,pitch]

With no display the runner goes headless by itself and says so.
"""
from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from components import ComponentValueError
from engine.app import Engine, Game
from engine.capture import export_scene, save_ids, save_png
from engine.errors import SpeculumError
from engine.frame_io import Output
from engine.gl_context import create_headless_context, have_display
from engine.render.targets import CaptureTarget

HEADLESS_DT = 1.0 / 60.0


def parse_args(game: Game, argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog=f"python -m games.{type(game).__module__.split('.')[1]}"
                                     if type(game).__module__.startswith("games.") else None,
                                     description=f"{game.title} (Speculum)")
    parser.add_argument("--headless", action="store_true", help="render offscreen through EGL and write PNGs")
    parser.add_argument("--frames", type=int, default=None,
                        help="frames to run (headless default 4; windowed: until closed)")
    parser.add_argument("--size", type=_size, default=game.size, help="WxH, e.g. 1280x720")
    parser.add_argument("--out", type=Path, default=None, help="folder for frame_NNNN.png (headless)")
    parser.add_argument("--ids", action="store_true", help="also write ids_NNNN.npy per frame")
    parser.add_argument("--export-scene", type=Path, default=None,
                        help="write FILE.glb (world geometry) and FILE.json (camera, components) at the end")
    parser.add_argument("--camera", type=_pose, default=None, help="start pose x,y,z,yaw,pitch (degrees)")
    args = parser.parse_args(argv)
    if args.frames is not None and args.frames < 1:
        parser.error("--frames must be >= 1")
    return args


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--size must look like 640x360, got {text!r}") from None
    if not (1 <= w <= 8192 and 1 <= h <= 8192):
        raise argparse.ArgumentTypeError(f"--size must be between 1x1 and 8192x8192, got {text!r}")
    return w, h


def _pose(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 5:
        raise argparse.ArgumentTypeError(f"--camera must be x,y,z,yaw,pitch, got {text!r}")
    return values


def main(game: Game, argv: Sequence[str] | None = None) -> int:
    args = parse_args(game, argv)
    try:
        if not args.headless and not have_display():
            print("speculum: no display found (DISPLAY/WAYLAND_DISPLAY unset); running headless", file=sys.stderr)
            args.headless = True
        if args.headless:
            written = run_headless(game, args)
            print(f"speculum: wrote {written} frame(s) to {args.out}")
        else:
            from engine.window import run_windowed

            run_windowed(game, args)
    except (SpeculumError, ComponentValueError) as exc:
        # Bad input (a level's mesh file, component value, mirror, missing GL feature):
        # one line naming the thing and the reason, and a clean exit.
        print(f"speculum: error: {exc}", file=sys.stderr)
        return 2
    return 0


def run_headless(game: Game, args: argparse.Namespace) -> int:
    """Render ``args.frames`` frames offscreen and write them (and ids) to ``args.out``."""
    frames = args.frames or 4
    if args.out is None:
        args.out = Path("out") / type(game).__name__.lower()
    args.out.mkdir(parents=True, exist_ok=True)
    ctx = create_headless_context()
    engine = None
    capture = None
    try:
        engine = Engine(game, ctx)
        if args.camera:
            engine.place_camera(*args.camera)
        capture = CaptureTarget(ctx, args.size)
        output = Output(capture.framebuffer, args.size)
        for index in range(frames):
            engine.frame(HEADLESS_DT, output)
            save_png(capture.read_rgb(), args.out / f"frame_{index:04d}.png")
            if args.ids:
                save_ids(engine.renderer.targets.read_ids(), args.out / f"ids_{index:04d}.npy")
        if args.export_scene:
            camera = engine.active_camera()
            if camera is not None:
                export_scene(engine.world, args.export_scene, camera[0], args.size,
                             engine.reflection_system.mirror_planes())
    finally:
        if capture is not None:
            capture.release()
        if engine is not None:
            engine.close()
        ctx.release()
    return frames
