"""Command line of every game: windowed through moderngl-window, or headless on EGL.

  python -m games.<name> [--headless] [--frames N] [--size WxH] [--out DIR] [--level FILE.toml] ...

``python -m games.<name> --help`` lists every option (``build_parser``): what to write (PNGs,
ids, a GIF, the scene as glTF), the camera and time step, the effects to turn on (ambient
occlusion, contact shadows, light shafts, screen-space reflections, depth of field, motion
blur), the sky (model, altitude, panorama, time of day, moon, clouds), anti-aliasing and
resolution scaling, asset folders, the overlay and live reload of the level file.

With no display the runner goes headless by itself and says so.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from components import ComponentValueError
from components.limits import MAX_ALTITUDE
from components.rendering import SKY_MODELS
from components.time_of_day import SYNODIC_MONTH
from engine.core.budget import ViewBudget, ViewBudgetError
from engine.core.errors import SpeculumError
from engine.core.frame_io import Output
from engine.core.game import Game
from engine.render.gl_context import create_headless_context, have_display
from engine.render.present import ANTIALIAS_MODES
from engine.render.resample import RENDER_SCALE_RANGE, check_render_scale, check_sharpness
from engine.render.targets import CaptureTarget
from shell.app import Engine
from shell.capture import SCENE_FORMATS, OutputPathError, prepare_out, save_ids, save_png, write_scene

HEADLESS_DT = 1.0 / 60.0


def build_parser(game: Game | type[Game]) -> argparse.ArgumentParser:
    """Every game's options, titled by the game (an instance or its class).  A game with
    options of its own adds them to this parser (an argument group) and passes it to
    ``main``, so ``--help`` is one title, one usage and every option."""
    module = (game if isinstance(game, type) else type(game)).__module__
    title = game.title if "speculum" in game.title.lower() else f"{game.title} (Speculum)"
    parser = argparse.ArgumentParser(prog=f"python -m games.{module.split('.')[1]}"
                                     if module.startswith("games.") else None, description=title)
    parser.add_argument("--headless", action="store_true", help="render offscreen through EGL and write PNGs")
    parser.add_argument("--frames", type=int, default=None, metavar="N",
                        help="frames to run (headless default 4; windowed: the window closes after N)")
    parser.add_argument("--size", type=_size, default=game.size, metavar="WxH", help="WxH, e.g. 1280x720")
    parser.add_argument("--out", type=Path, default=None, metavar="DIR",
                        help="folder for frame_NNNN.png (headless) or F12 screenshots (windowed)")
    parser.add_argument("--level", type=Path, default=None, metavar="FILE",
                        help="play this level file (.toml, docs/level_files.md) instead of the game's own")
    parser.add_argument("--ids", action="store_true",
                        help="headless: also write ids_NNNN.npy per frame (the drawn picture's size: "
                             "--render-scale times the output's)")
    parser.add_argument("--export-scene", type=_scene_path, default=None, metavar="FILE",
                        help="write FILE.glb or FILE.gltf (world geometry) and FILE.json (camera, components) "
                             "at the end (windowed: as the window closes)")
    parser.add_argument("--camera", type=_pose, default=None, metavar="X,Y,Z,YAW,PITCH",
                        help="start pose (metres, degrees)")
    parser.add_argument("--dt", type=_seconds, default=HEADLESS_DT, metavar="SECONDS",
                        help=f"seconds of game time per headless frame (default {HEADLESS_DT:.4f}: 60 a second)")
    parser.add_argument("--gif", type=_gif_path, default=None, metavar="FILE",
                        help="headless: also write the frames as an animated GIF (one frame per --dt)")
    parser.add_argument("--ao", action="store_true",
                        help="ambient occlusion on the active camera (an AmbientOcclusion(), if it has none)")
    parser.add_argument("--contact-shadows", action="store_true",
                        help="contact shadows on the active camera (a ContactShadows(), if it has none)")
    parser.add_argument("--shafts", action="store_true",
                        help="light shafts on the active camera (a VolumetricFog(), and a thin Fog where it has none)")
    parser.add_argument("--ssr", action="store_true",
                        help="screen-space reflections on the active camera (a ScreenReflections(), if it has none)")
    parser.add_argument("--dof", action="store_true",
                        help="depth of field on the active camera (an 85 mm lens at f/1.4 with autofocus, if it has "
                             "no DepthOfField)")
    parser.add_argument("--motion-blur", action="store_true",
                        help="camera motion blur on the active camera (a MotionBlur(), if it has none)")
    parser.add_argument("--sky", choices=SKY_MODELS, default=None,
                        help="the level's Skybox (made if it has none) drawn as this model: 'atmosphere' a "
                             "physically based sky, with a night's stars beyond its air")
    parser.add_argument("--altitude", type=_altitude, default=None, metavar="METRES",
                        help="with an atmosphere sky (--sky atmosphere, or the level's): the level stands this "
                             f"high above sea level, 0 to {MAX_ALTITUDE:g} (default the level's, 200)")
    parser.add_argument("--panorama", default=None, metavar="FILE",
                        help="the level's sky (its Skybox, made if it has none) an equirectangular panorama: a "
                             "Radiance .hdr or OpenEXR .exr HDRI, or a PNG or JPEG taken as sRGB (512 texels a face)")
    parser.add_argument("--panorama-yaw", type=_yaw, default=0.0, metavar="DEGREES",
                        help="with --panorama: turn it this many degrees about up (default 0)")
    parser.add_argument("--panorama-sun", action="store_true",
                        help="with --panorama: take its sun out of the sky and give its light, direction and size "
                             "to the level's brightest DirectionalLight (made if there is none), so it casts shadows")
    parser.add_argument("--time", type=_hour, default=None, metavar="HOUR",
                        help="the sun (the brightest DirectionalLight, made if there is none) where it stands at "
                             "this hour of a summer's day at 45 degrees north (a TimeOfDay on it)")
    parser.add_argument("--moon", type=_moon_age, default=None, metavar="DAYS",
                        help="with --time: a moon this many days past new (14.77: full) on the same clock")
    parser.add_argument("--clouds", type=_cloud_share, default=None, metavar="SHARE",
                        help="clouds over the level's generated sky (a CloudLayer on its Skybox, made if it has "
                             "none): this share of the sky under cloud, 0 to 1, drifting on the wind")
    parser.add_argument("--day-minutes", type=_day_minutes, default=None, metavar="MINUTES",
                        help="with --time: a whole day passes in this many minutes of game time")
    parser.add_argument("--aa", choices=ANTIALIAS_MODES, default="fxaa",
                        help="anti-aliasing of the final image (default fxaa; ids are never affected)")
    parser.add_argument("--render-scale", type=_render_scale, default=1.0, metavar="SHARE",
                        help=f"draw the world at this share of the output's width and height, in "
                             f"[{RENDER_SCALE_RANGE[0]:g}, {RENDER_SCALE_RANGE[1]:g}] (default 1), brought up to the "
                             "output's size by temporal AA (--aa taa) or a Catmull-Rom upscale; above 1 "
                             "supersampled, brought down by a box filter in linear light")
    parser.add_argument("--sharpen", type=_sharpness, default=0.0, metavar="AMOUNT",
                        help="contrast-adaptive sharpening of the final image, in [0, 1] (default 0: none)")
    parser.add_argument("--frame-ms", type=_frame_ms, default=None, metavar="MS",
                        help="dynamic resolution: the GPU's milliseconds a frame may take (ViewBudget.frame_ms); "
                             "the render scale goes down to the budget's min_render_scale (0.5) while frames run over")
    parser.add_argument("--asset-root", type=_folder, action="append", default=[], metavar="DIR",
                        help="a folder a level file's meshes and textures may come from besides the level's own "
                             "(repeatable; a level's assets stay in its folder otherwise)")
    parser.add_argument("--overlay", action="store_true",
                        help="draw the debug overlay (frame rate, passes, draw calls, views, probe captures, "
                             "paths) into the frames; windowed: shown from the start (F1 toggles it)")
    parser.add_argument("--reload", action="store_true",
                        help="headless: reload the level file when it is saved, keeping the camera (windowed runs "
                             "always do); a file that fails to load keeps the old level and prints its error")
    return parser


def parse_args(game: Game, argv: Sequence[str] | None,
               parser: argparse.ArgumentParser | None = None) -> argparse.Namespace:
    """``argv`` by ``parser`` (``build_parser(game)`` when None), checked."""
    if parser is None:
        parser = build_parser(game)
    args = parser.parse_args(_negative_values_joined(sys.argv[1:] if argv is None else argv))
    if args.frames is not None and args.frames < 1:
        parser.error("--frames must be >= 1")
    if args.day_minutes is not None and args.time is None:
        parser.error("--day-minutes needs --time (the hour the day starts at)")
    if args.moon is not None and args.time is None:
        parser.error("--moon needs --time (the clock it follows)")
    if args.clouds is not None and args.panorama is not None and args.sky != "atmosphere":
        parser.error("--clouds needs a generated sky: a --panorama is a photographed sky with its own clouds "
                     "(with --sky atmosphere it is the space beyond the air, and clouds are drawn)")
    if args.panorama_yaw != 0.0 and args.panorama is None:
        parser.error("--panorama-yaw needs --panorama (the panorama it turns)")
    if args.panorama_sun and args.panorama is None:
        parser.error("--panorama-sun needs --panorama (the panorama whose sun it takes)")
    if args.panorama_sun and args.time is not None:
        parser.error("--panorama-sun and --time both place the sun: the panorama's stands where it was photographed")
    return args


# Options whose value may start with a minus sign (argparse takes "-4.5,1.6,3,90,0" for an
# option of its own, as it is not one negative number).
NEGATIVE_VALUE_OPTIONS = ("--camera", "--panorama-yaw")


def _negative_values_joined(argv: Sequence[str]) -> list[str]:
    """``--camera -4.5,1.6,3,90,0`` as ``--camera=-4.5,1.6,3,90,0``, so it works without the ``=``."""
    joined: list[str] = []
    items = list(argv)
    index = 0
    while index < len(items):
        item = items[index]
        following = items[index + 1] if index + 1 < len(items) else None
        if item in NEGATIVE_VALUE_OPTIONS and following is not None and following.startswith("-") \
                and len(following) > 1 and (following[1].isdigit() or following[1] == "."):
            joined.append(f"{item}={following}")
            index += 2
            continue
        joined.append(item)
        index += 1
    return joined


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--size must look like 640x360, got {text!r}") from None
    if not (1 <= w <= 8192 and 1 <= h <= 8192):
        raise argparse.ArgumentTypeError(f"--size must be between 1x1 and 8192x8192, got {text!r}")
    return w, h


def _scene_path(text: str) -> Path:
    path = Path(text)
    if path.suffix.lower() not in SCENE_FORMATS:
        raise argparse.ArgumentTypeError(
            f"--export-scene must end in {' or '.join(SCENE_FORMATS)} (the format written), got {text!r}")
    return path


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0.0 < value <= 1.0:
        raise argparse.ArgumentTypeError(f"--dt must be seconds in (0, 1], got {text!r}")
    return value


def _render_scale(text: str) -> float:
    try:
        return check_render_scale(float(text))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"--render-scale {text!r}: {exc}") from None


def _sharpness(text: str) -> float:
    try:
        return check_sharpness(float(text))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"--sharpen {text!r}: {exc}") from None


def _frame_ms(text: str) -> float:
    try:
        return ViewBudget(frame_ms=float(text)).frame_ms
    except (ValueError, ViewBudgetError) as exc:
        raise argparse.ArgumentTypeError(f"--frame-ms {text!r}: {exc}") from None


def _number(flag: str, what: str, accepts: Callable[[float], bool]) -> Callable[[str], float]:
    """An option's parser: a float that ``accepts`` takes, else one error line saying what
    ``flag`` must be (``what``)."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and accepts(value)):
            raise argparse.ArgumentTypeError(f"{flag} must be {what}, got {text!r}")
        return value
    return parse


_yaw = _number("--panorama-yaw", "a finite number of degrees", lambda v: True)
_moon_age = _number("--moon", f"the moon's age in days, 0 to {SYNODIC_MONTH:.2f}", lambda v: 0.0 <= v <= SYNODIC_MONTH)
_cloud_share = _number("--clouds", "a share of the sky from 0 to 1", lambda v: 0.0 <= v <= 1.0)
_altitude = _number("--altitude", f"metres from 0 to {MAX_ALTITUDE:g}", lambda v: 0.0 <= v <= MAX_ALTITUDE)
_hour = _number("--time", "an hour from 0 to 24", lambda v: 0.0 <= v <= 24.0)
_day_minutes = _number("--day-minutes", "a number of minutes > 0", lambda v: v > 0.0)


def _gif_path(text: str) -> Path:
    path = Path(text)
    if path.suffix.lower() != ".gif":
        raise argparse.ArgumentTypeError(f"--gif must name a .gif file, got {text!r}")
    return path


def _folder(text: str) -> Path:
    path = Path(text)
    if not path.is_dir():
        raise argparse.ArgumentTypeError(f"--asset-root must name an existing folder, got {text!r}: not a folder")
    return path


MAX_POSE = 1e6  # --camera's largest coordinate or angle: well inside a Transform's and a rotation's range


def _pose(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 5:
        raise argparse.ArgumentTypeError(f"--camera must be x,y,z,yaw,pitch, got {text!r}")
    if not all(math.isfinite(v) for v in values) or any(abs(v) > MAX_POSE for v in values):
        raise argparse.ArgumentTypeError(f"--camera must be five finite numbers (metres, degrees; at most "
                                         f"{MAX_POSE:g} either way), got {text!r}")
    if abs(values[4]) > 90.0:  # (past it the view is upside down, and a FlyController refuses it)
        raise argparse.ArgumentTypeError(f"--camera's pitch must be degrees from -90 (straight down) to 90 "
                                         f"(straight up), got {text!r}")
    return values


def main(game: Game, argv: Sequence[str] | None = None, parser: argparse.ArgumentParser | None = None) -> int:
    """Run ``game`` as ``argv`` says; the exit status (0, or 2 after one error line).
    ``parser``: ``build_parser``'s with the game's own options added."""
    from engine.assets.level_assets import set_asset_roots, user_asset_roots

    args = parse_args(game, argv, parser)
    before = user_asset_roots()
    set_asset_roots(args.asset_root)  # for every level loaded in this run, the game's own loads too
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _one_line_warning
            return _main(game, args)
    finally:
        set_asset_roots(before)


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Warnings (no camera, a drawable without a Transform, a missing material library) as
    one line, like errors: what is wrong, not where in the engine it was noticed."""
    print(f"speculum: warning: {message}", file=sys.stderr if file is None else file)


def _main(game: Game, args: argparse.Namespace) -> int:
    try:
        use_level(game, args.level)
        if getattr(args, "reload", False):
            check_reload(game)
        if not args.headless and not have_display():
            print("speculum: no display found (DISPLAY/WAYLAND_DISPLAY unset); running headless", file=sys.stderr)
            args.headless = True
        if args.headless:
            if args.out is None:
                args.out = Path("out") / type(game).__name__.lower()
            prepare_out(args.out)
            if args.export_scene is not None:
                prepare_out(args.export_scene.parent, "--export-scene folder")
            if args.gif is not None:
                prepare_out(args.gif.parent, "--gif folder")
            written = run_headless(game, args)
            frames = sum(1 for path in written if path.name.startswith("frame_"))
            print(f"speculum: wrote {frames} frame(s): {describe_written(written)}")
        else:
            from shell.window import run_windowed

            if args.out is not None:
                prepare_out(args.out)
            run_windowed(game, args)
    except (SpeculumError, ComponentValueError) as exc:
        # Bad input (a level's mesh file, component value, mirror, missing GL feature, an
        # output folder that cannot be written): one line naming the thing and the reason.
        print(f"speculum: error: {exc}", file=sys.stderr)
        return 2
    return 0


def use_level(game: Game, level: Path | None) -> None:
    """``--level FILE``: a game built from a level file (``LevelGame``) plays ``FILE``
    instead; any other game refuses it.  A level game's file is checked here, before a
    context or window is made, so a mistake in it is one error line and nothing drawn."""
    from engine.assets.level_file import LevelGame

    if not isinstance(game, LevelGame):
        if level is not None:
            raise SpeculumError(f"--level {str(level)!r}: {game.title!r} builds its own world in Python, not from "
                                "a level file, so it cannot play one")
        return
    if level is not None:
        game.level_path = level
    game.load()  # load_level and the game's own checks (a level for another game, no camera)


def check_reload(game: Game) -> None:
    """``--reload`` needs a level file to watch: a game built in Python is refused, as
    ``--level`` is, before a context or an output folder is made."""
    from engine.assets.level_file import LevelGame

    if not isinstance(game, LevelGame):
        raise SpeculumError(f"--reload: {game.title!r} builds its own world in Python, not from a level file, so "
                            "there is no file to reload")


def describe_written(written: Sequence[Path]) -> str:
    """Every file written, by name; a run of numbered files (frame_0000.png ...) longer than
    three as its first and last name and a count."""
    runs: dict[tuple, list[Path]] = {}
    for path in written:
        prefix, _, number = path.stem.rpartition("_")
        key = (path.parent, prefix, path.suffix) if prefix and number.isdigit() else (path,)
        runs.setdefault(key, []).append(path)
    parts = []
    for paths in runs.values():
        if len(paths) <= 3:
            parts.extend(str(p) for p in paths)
        else:
            parts.append(f"{paths[0]} .. {paths[-1].name} ({len(paths)} files)")
    return ", ".join(parts)


def run_headless(game: Game, args: argparse.Namespace) -> list[Path]:
    """Render ``args.frames`` frames offscreen and write them (and ids, and the scene) to
    ``args.out``; returns every file written, in order."""
    frames = args.frames or 4
    written: list[Path] = []
    ctx = create_headless_context()
    engine = None
    capture = None
    overlay = None
    try:
        engine = Engine(game, ctx)
        engine.start_from(args)
        capture = CaptureTarget(ctx, args.size)
        output = Output(capture.framebuffer, args.size)
        if args.overlay:
            from shell.overlay import DebugOverlay

            overlay = DebugOverlay(ctx)
        reload = engine.watch_level(interval=0.0) if getattr(args, "reload", False) else None
        gif_frames: list[np.ndarray] = []
        for index in range(frames):
            if reload is not None:  # a stat a frame: a save is loaded once it is stable for one frame
                for message in reload.poll():
                    print(f"speculum: {message}", file=sys.stderr, flush=True)
            start = time.perf_counter()
            engine.frame(args.dt, output)
            if overlay is not None:  # over the presented frame, numbers of this frame
                overlay.record(time.perf_counter() - start)
                overlay.draw(engine, capture.framebuffer, args.size)
            rgb = capture.read_rgb()
            written.append(_write(save_png, rgb, args.out / f"frame_{index:04d}.png"))
            if args.gif is not None:
                gif_frames.append(rgb)
            if args.ids:
                written.append(_write(save_ids, engine.renderer.targets.read_ids(), args.out / f"ids_{index:04d}.npy"))
        if args.gif is not None:
            written.append(_write(lambda data, path: save_gif(data, path, args.dt), gif_frames, args.gif))
        if args.export_scene:
            written += write_scene(engine, args.export_scene, args.size)
    finally:
        if overlay is not None:
            overlay.release()
        if capture is not None:
            capture.release()
        if engine is not None:
            engine.close()
        ctx.release()
    return written


def save_gif(frames: Sequence[np.ndarray], path: Path, seconds_per_frame: float) -> None:
    """The frames as a looping animated GIF (imageio; 256 colours a frame)."""
    import imageio.v3 as iio

    iio.imwrite(path, np.stack(frames), extension=".gif", duration=max(20, round(seconds_per_frame * 1000)), loop=0)


def _write(save: Callable[[np.ndarray, Path], None], data: np.ndarray, path: Path) -> Path:
    """``save(data, path)``, a disk error (full, removed folder) as one line naming the file."""
    try:
        save(data, path)
    except OSError as exc:
        raise OutputPathError(f"cannot write {str(path)!r}: {exc.strerror or exc}") from None
    return path
