"""The runner's command-line options in this process (``shell.runner.main`` as a game's
``run()`` calls it, and its parser): what README says each does, checked against numbers
worked out here (PNG counts and sizes, the game time a frame is given, where a moving box
must land on the picture), and a bad value of each refused in one error line naming it.
(The slower runs of the sample level as a user runs it: tests/test_runner.py.)"""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from components import DirectionalLight, Fog, Material, MeshRef, Skybox, Transform, VolumetricFog
from engine import Game, spawn_camera
from engine.assets.mesh import box
from games.hall_of_mirrors.level import HallOfMirrors
from shell.runner import HEADLESS_DT, build_parser, main

ROOT = Path(__file__).resolve().parents[1]
RED = (0.9, 0.05, 0.05)
EYE_Z, FOV = 4.0, 60.0
SPEED = 1.0  # metres a second the box moves along +X


class Sliding(Game):
    """An unlit red box 0.6 m wide sliding along +X at ``SPEED`` m/s in front of a camera at
    (0, 1, ``EYE_Z``) looking down -Z; each update's ``dt`` is kept in ``seen``."""

    def __init__(self) -> None:
        self.seen: list[float] = []
        self.box = None

    def build(self, world) -> None:
        spawn_camera(world, position=(0.0, 1.0, EYE_Z), fov_y=FOV)
        world.spawn(Skybox())
        self.box = world.spawn(Transform(position=(0.0, 1.0, 0.0), scale=(0.6, 0.6, 0.6)), MeshRef(box()),
                               Material(color=(*RED, 1.0), unlit=True))

    def update(self, world, dt) -> None:
        self.seen.append(dt)
        transform = world.get(self.box, Transform)
        x, y, z = transform.position
        transform.position = (x + SPEED * dt, y, z)


def red_mask(image: np.ndarray) -> np.ndarray:
    rgb = image[..., :3].astype(int)
    return (rgb[..., 0] > 150) & (rgb[..., 1] < 110) & (rgb[..., 2] < 110)


def box_column(x: float, size: tuple[int, int]) -> float:
    """The column of the box's centre at ``x`` (m), by the pinhole camera: the front face sits
    0.3 m nearer than the centre, but its middle projects as the centre does on the axis row."""
    w, h = size
    half_width = (EYE_Z - 0.3) * math.tan(math.radians(FOV / 2)) * w / h  # metres across half the picture
    return (0.5 + 0.5 * x / half_width) * w


# --- README <-> --help ---------------------------------------------------------------------

def _runner_options() -> set[str]:
    return {option for action in build_parser(HallOfMirrors)._actions for option in action.option_strings
            if option.startswith("--") and option != "--help"}


def test_every_runner_option_is_in_the_readme_and_every_run_option_it_names_exists():
    """README's running-games paragraphs (from "Without `--headless`" to the controls) name
    every option the runner's parser has, and every option they name is the parser's or a
    game's own (``add_argument`` in ``games/*/__main__.py``, each named somewhere in README)."""
    readme = (ROOT / "README.md").read_text()
    section = readme[readme.index("Without `--headless`"):readme.index("## Controls (windowed)")]
    named = set(re.findall(r"`(--[a-z][a-z-]*)", section)) | {"--headless"}
    runner = _runner_options()
    assert runner - named == set(), f"in --help, not in README's run options: {sorted(runner - named)}"
    assert named - runner == set(), f"in README's run options, not in --help: {sorted(named - runner)}"
    games = {}
    for script in sorted((ROOT / "games").glob("*/__main__.py")):
        for option in re.findall(r"add_argument\(\s*\"(--[a-z][a-z-]*)\"", script.read_text()):
            games[option] = script.parent.name
    assert games, "the games add options of their own (mirror beam's --interval, portal run's --autopilot)"
    missing = {option: game for option, game in games.items() if f"`{option}" not in readme}
    assert not missing, f"a game's own option README never names: {missing}"


# --- bad values: one line naming the option ------------------------------------------------

BAD_VALUES = [
    ("--frames", ["--frames", "0"]), ("--frames", ["--frames", "two"]),
    ("--size", ["--size", "big"]), ("--size", ["--size", "0x10"]), ("--size", ["--size", "9000x10"]),
    ("--export-scene", ["--export-scene", "scene.obj"]),
    ("--camera", ["--camera", "1,2"]), ("--camera", ["--camera", "0,1,2,0,95"]),
    ("--dt", ["--dt", "0"]), ("--dt", ["--dt", "2"]), ("--dt", ["--dt", "nan"]),
    ("--gif", ["--gif", "frames.png"]), ("--sky", ["--sky", "cloudy"]),
    ("--altitude", ["--altitude", "-1"]), ("--panorama-yaw", ["--panorama-yaw", "inf"]),
    ("--time", ["--time", "25"]), ("--moon", ["--time", "20", "--moon", "40"]),
    ("--clouds", ["--clouds", "1.5"]), ("--day-minutes", ["--time", "6", "--day-minutes", "0"]),
    ("--aa", ["--aa", "msaa"]), ("--render-scale", ["--render-scale", "9"]), ("--sharpen", ["--sharpen", "2"]),
    ("--frame-ms", ["--frame-ms", "0"]), ("--asset-root", ["--asset-root", "/no/such/folder"]),
    # options that need another
    ("--day-minutes", ["--day-minutes", "5"]), ("--moon", ["--moon", "14.77"]),
    ("--panorama-yaw", ["--panorama-yaw", "30"]), ("--panorama-sun", ["--panorama-sun"]),
]


@pytest.mark.parametrize("option,argv", BAD_VALUES, ids=[" ".join(argv) for _, argv in BAD_VALUES])
def test_a_bad_value_of_each_option_is_one_error_line_naming_it(option, argv, tmp_path, capsys):
    """Refused by the parser before anything is made: exit status 2, the usage, and one
    ``error:`` line that names the option (no traceback, no output folder)."""
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as info:
        main(Sliding(), ["--headless", "--out", str(out), *argv])
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if "error:" in line]
    assert info.value.code == 2 and len(errors) == 1, err
    assert option in errors[0] and "Traceback" not in err, errors
    assert not out.exists()
    assert option in _runner_options()


def test_options_refused_once_the_game_is_built_are_one_error_line_naming_the_option(tmp_path, capsys):
    """What only the game can say (its sky is no atmosphere, it has no level file to play or
    to reload) is a ``speculum: error:`` line naming the option, exit 2."""
    cases = [(["--altitude", "300"], "--altitude 300"), (["--level", str(tmp_path / "x.toml")], "--level"),
             (["--reload"], "--reload")]
    for argv, named in cases:
        status = main(Sliding(), ["--headless", "--frames", "1", "--size", "8x8", "--out", str(tmp_path / "o"),
                                  *argv])
        lines = capsys.readouterr().err.strip().splitlines()
        assert status == 2 and len(lines) == 1 and lines[0].startswith("speculum: error: "), (argv, lines)
        assert named in lines[0], (argv, lines)
    # A camera straight up or down is a pose, not a mistake.
    assert main(Sliding(), ["--headless", "--frames", "1", "--size", "8x8", "--out", str(tmp_path / "o"),
                            "--camera", "0,1,2,0,-90"]) == 0


# --- --frames, --size, --out, --dt, --gif --------------------------------------------------

def test_frames_size_and_out_write_exactly_those_frames_at_that_size(tmp_path, capsys, monkeypatch):
    """``--frames 3 --size 40x24 --out DIR``: frame_0000..0002.png in DIR, each 40x24 with the
    red box where the pinhole camera puts it and sky at the corners; the closing line names
    them.  Without ``--frames`` and ``--out``: four frames in ``out/<game>`` of the working folder."""
    out = tmp_path / "frames"
    assert main(Sliding(), ["--headless", "--frames", "3", "--size", "40x24", "--aa", "off", "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == [f"frame_{i:04d}.png" for i in range(3)]
    for index in range(3):
        image = np.asarray(Image.open(out / f"frame_{index:04d}.png"))
        assert image.shape == (24, 40, 3), image.shape
        red = red_mask(image)
        columns = np.nonzero(red.any(axis=0))[0]
        x = SPEED * HEADLESS_DT * (index + 1)  # moved by each update before the frame is drawn
        assert abs(columns.mean() + 0.5 - box_column(x, (40, 24))) <= 1.0, (index, columns)
        assert not red[[0, 0, -1, -1], [0, -1, 0, -1]].any()
    names = ", ".join(str(out / f"frame_{i:04d}.png") for i in range(3))
    assert capsys.readouterr().out.strip() == f"speculum: wrote 3 frame(s): {names}"

    monkeypatch.chdir(tmp_path)
    assert main(Sliding(), ["--headless", "--size", "8x6"]) == 0
    written = sorted((tmp_path / "out" / "sliding").iterdir())
    assert [p.name for p in written] == [f"frame_{i:04d}.png" for i in range(4)]
    assert all(Image.open(p).size == (8, 6) for p in written)


def test_dt_is_the_game_time_each_headless_frame_steps(tmp_path):
    """``--dt 0.5``: every update is given 0.5 s (by default 1/60), so the box at 1 m/s is
    1.5 m along after three frames: its column on the last frame is the pinhole camera's for
    x = 1.5, far from the 0.05 m a default run reaches."""
    game = Sliding()
    size = (96, 48)
    assert main(game, ["--headless", "--frames", "3", "--size", "96x48", "--aa", "off", "--dt", "0.5",
                       "--out", str(tmp_path / "slow")]) == 0
    assert game.seen == [0.5, 0.5, 0.5]
    image = np.asarray(Image.open(tmp_path / "slow" / "frame_0002.png"))
    columns = np.nonzero(red_mask(image).any(axis=0))[0]
    assert abs(columns.mean() + 0.5 - box_column(1.5, size)) <= 1.0, columns
    assert abs(box_column(1.5, size) - box_column(0.05, size)) > 10  # a step one can see

    default = Sliding()
    assert main(default, ["--headless", "--frames", "2", "--size", "8x8", "--out", str(tmp_path / "default")]) == 0
    assert default.seen == [HEADLESS_DT, HEADLESS_DT] and HEADLESS_DT == pytest.approx(1 / 60)


def test_gif_holds_every_frame_in_order_each_shown_for_dt(tmp_path):
    """``--gif FILE.gif --dt 0.1 --frames 3``: a looping GIF of three frames at the run's size,
    each 100 ms, the i-th closest to frame_000i.png of all three (256 colours: near, not equal)."""
    gif = tmp_path / "anim" / "run.gif"
    out = tmp_path / "frames"
    assert main(Sliding(), ["--headless", "--frames", "3", "--size", "64x32", "--aa", "off", "--dt", "0.1",
                            "--out", str(out), "--gif", str(gif)]) == 0
    pngs = [np.asarray(Image.open(out / f"frame_{i:04d}.png")).astype(int) for i in range(3)]
    with Image.open(gif) as animation:
        assert animation.n_frames == 3 and animation.size == (64, 32)
        assert animation.info.get("loop") == 0
        frames, durations = [], []
        for index in range(3):
            animation.seek(index)
            durations.append(animation.info["duration"])
            frames.append(np.asarray(animation.convert("RGB")).astype(int))
    assert durations == [100, 100, 100]
    for index, frame in enumerate(frames):
        distances = [np.abs(frame - png).mean() for png in pngs]
        assert int(np.argmin(distances)) == index and distances[index] < 4, (index, distances)
        assert red_mask(frame).sum() > 10  # the box is in it


# --- --shafts ------------------------------------------------------------------------------

def test_shafts_give_the_camera_volumetric_fog_and_a_thin_fog_only_where_it_has_none(ctx):
    """``--shafts``: a ``VolumetricFog()`` and ``Fog(density=SHAFTS_FOG_DENSITY)`` on the active
    camera; a camera's own Fog is kept as it is; the frame changes (the air now scatters)."""
    from shell.app import SHAFTS_FOG_DENSITY
    from tests.support import SceneRunner

    def build(world, own_fog=None):
        camera = spawn_camera(world, position=(0.0, 1.0, EYE_Z))
        if own_fog is not None:
            world.add_component(camera, own_fog)
        world.spawn(Skybox())
        world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.5), intensity=3.0))
        world.spawn(Transform(position=(0.0, 1.0, 0.0)), MeshRef(box()), Material(color=(0.8, 0.8, 0.8, 1.0)))

    pictures = {}
    for name, shafts in (("plain", False), ("shafts", True)):
        scene = SceneRunner(ctx, build, size=(32, 24))
        try:
            scene.engine.start(shafts=shafts)
            entity = scene.engine.active_camera()[0]
            fog = scene.world.try_get(entity, Fog)
            volume = scene.world.try_get(entity, VolumetricFog)
            if shafts:
                assert volume is not None and fog is not None and fog.density == SHAFTS_FOG_DENSITY
            else:
                assert volume is None and fog is None
            scene.frame()
            pictures[name] = scene.frame().astype(int)
        finally:
            scene.close()
    assert np.abs(pictures["shafts"] - pictures["plain"]).max() > 8

    own = Fog(density=0.2)
    scene = SceneRunner(ctx, lambda world: build(world, own), size=(16, 12))
    try:
        scene.engine.start(shafts=True)
        entity = scene.engine.active_camera()[0]
        assert scene.world.get(entity, Fog) is own and own.density == 0.2
        assert scene.world.try_get(entity, VolumetricFog) is not None
    finally:
        scene.close()


# --- --out in a window ---------------------------------------------------------------------

def test_a_windows_screenshots_go_to_out_and_show_the_frame_a_headless_run_draws(tmp_path, monkeypatch):
    """README's F12 row: a screenshot goes to ``screenshots/``, or to ``--out`` when given.
    The window (moderngl-window's headless EGL window) is made from the parsed command line;
    its screenshot after one 1/60 s frame is the headless run's frame_0000.png at that size."""
    import moderngl_window as mglw

    from shell.runner import parse_args
    from shell.window import make_window_config

    monkeypatch.chdir(tmp_path)
    assert main(Sliding(), ["--headless", "--frames", "1", "--size", "48x32", "--aa", "off",
                            "--out", "headless"]) == 0
    headless = np.asarray(Image.open(tmp_path / "headless" / "frame_0000.png")).astype(int)
    for given, folder in ((["--out", "shots"], tmp_path / "shots"), ([], tmp_path / "screenshots")):
        game = Sliding()
        args = parse_args(game, ["--size", "48x32", "--aa", "off", *given])
        config = mglw.create_window_config_instance(
            make_window_config(game, args), args=["--window", "headless", "--backend", "egl", "--size", "48x32"])
        try:
            config.on_render(0.0, 1 / 60)
            shot = config.screenshot()
        finally:
            config.on_close()
            config.wnd.destroy()
        assert shot.resolve().parent == folder and [p.name for p in folder.iterdir()] == [shot.name]
        picture = np.asarray(Image.open(shot))[..., :3].astype(int)
        assert picture.shape == headless.shape and np.abs(picture - headless).max() <= 1
        assert red_mask(picture).sum() > 10
