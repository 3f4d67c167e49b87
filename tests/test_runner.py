"""The command line and the windowed shell, run as a user runs them."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from PIL import Image

from tests.support import run_level, run_level_process

ROOT = Path(__file__).resolve().parents[1]


def test_sample_level_headless_writes_frames_ids_and_scene(tmp_path):
    out = tmp_path / "frames"
    scene_file = tmp_path / "scene.glb"
    result = run_level_process("--headless", "--frames", "2", "--size", "160x90", "--out", str(out), "--ids",
                               "--export-scene", str(scene_file), "--camera", "0,1.7,6.5,0,-8")
    assert result.returncode == 0, result.stderr
    frames = sorted(out.glob("frame_*.png"))
    assert [f.name for f in frames] == ["frame_0000.png", "frame_0001.png"]
    image = np.asarray(Image.open(frames[-1]))
    assert image.shape == (90, 160, 3)
    assert image.std() > 20  # a real picture, not a flat or black frame
    ids = np.load(out / "ids_0001.npy")
    assert ids.shape == (90, 160) and ids.dtype == np.uint32
    assert (ids[0] == 0).all()  # top row is sky

    info = json.loads(scene_file.with_suffix(".json").read_text())
    cam = info["camera"]
    assert cam["image_size"] == [160, 90] and abs(cam["aspect"] - 160 / 90) < 1e-6
    np.testing.assert_allclose(cam["position"], [0, 1.7, 6.5], atol=1e-5)
    assert cam["forward"][2] < -0.9 and cam["forward"][1] < 0  # looking down -Z, a little down
    renderable = {e for e, kinds in info["entities"].items() if "MeshRef" in kinds}
    seen = {str(v) for v in np.unique(ids) if v}
    assert seen and seen <= renderable  # the id image names renderable entities only

    import trimesh

    loaded = trimesh.load(str(scene_file), force="scene")
    assert set(loaded.graph.nodes_geometry) == renderable  # one node per renderable entity
    floor = loaded.geometry[min(renderable, key=int)]
    assert np.ptp(floor.vertices[:, 0]) > 39  # world-space: the 40 m floor is 40 m wide


def test_no_display_goes_headless_and_says_so(tmp_path):
    env = {"DISPLAY": "", "WAYLAND_DISPLAY": ""}
    result = run_level("--frames", "1", "--size", "64x36", "--out", str(tmp_path), env_extra=env)
    assert result.returncode == 0, result.stderr
    assert "running headless" in result.stderr
    assert (tmp_path / "frame_0000.png").is_file()


def test_bad_arguments_give_clear_errors(tmp_path):
    result = run_level("--headless", "--size", "big", "--out", str(tmp_path))
    assert result.returncode != 0 and "--size must look like 640x360" in result.stderr
    result = run_level("--headless", "--camera", "1,2", "--out", str(tmp_path))
    assert result.returncode != 0 and "--camera must be x,y,z,yaw,pitch" in result.stderr
    for pose in ("0,1,5,nan,0", "0,1,5,0,1e300"):  # refused as an argument, not later inside a rotation
        result = run_level("--headless", "--camera", pose, "--out", str(tmp_path))
        assert result.returncode == 2 and "argument --camera: --camera must be five finite numbers" in result.stderr


def test_window_shell_runs_under_moderngl_window_headless(tmp_path):
    """The WindowConfig used for windowed runs, driven by moderngl-window's EGL headless window."""
    import moderngl_window as mglw

    from games.hall_of_mirrors import HallOfMirrors
    from shell.window import make_window_config

    config_cls = make_window_config(HallOfMirrors())
    config = mglw.create_window_config_instance(
        config_cls, args=["--window", "headless", "--backend", "egl", "--size", "96x54"])
    try:
        keys = config.wnd.keys
        config.screenshots = tmp_path
        config.on_render(0.0, 1 / 60)
        cam = config.engine.active_camera()[2]
        start = cam.position.z

        class Mods:
            shift = False

        w_key = keys.W if isinstance(keys.W, int) else "W"  # the headless backend has no key codes
        config.on_key_event(w_key, keys.ACTION_PRESS, Mods())
        for _ in range(10):
            config.on_render(0.0, 1 / 30)
        config.on_key_event(w_key, keys.ACTION_RELEASE, Mods())
        assert cam.position.z < start - 0.5  # W flew the camera forward (-Z)
        config.on_mouse_drag_event(0, 0, 40, 0)
        config.on_render(0.0, 1 / 60)
        shot = config.screenshot()
        assert np.asarray(Image.open(shot)).std() > 10
        config.on_resize(0, 0)
    finally:
        config.on_close()
        config.wnd.destroy()


def test_a_bad_level_stops_cleanly_with_one_line(tmp_path):
    """A level whose mirror sits on a box: the runner names it and exits 2, no traceback."""
    level = tmp_path / "bad_level.py"
    level.write_text(
        "from components import Material, MeshRef, Mirror, Transform\n"
        "from engine import Game, spawn_camera\nfrom shell import run\n"
        "from engine.assets.mesh import box\n"
        "class Bad(Game):\n"
        "    def build(self, world):\n"
        "        spawn_camera(world)\n"
        "        world.spawn(Transform(), MeshRef(box(name='crate')), Material(), Mirror())\n"
        "run(Bad())\n")
    result = subprocess.run([sys.executable, str(level), "--headless", "--frames", "1", "--size", "32x32",
                             "--out", str(tmp_path)], cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)},
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    assert "speculum: error: Mirror on entity" in result.stderr and "'crate' is not flat" in result.stderr
    assert "Traceback" not in result.stderr


def one_error_line(result: subprocess.CompletedProcess) -> str:
    """The run failed as bad input does: exit 2 and a single ``speculum: error:`` line."""
    assert result.returncode == 2, (result.returncode, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("speculum: error: "), result.stderr
    return lines[0]


def test_an_out_that_is_a_file_or_cannot_be_made_is_one_error_line(tmp_path):
    a_file = tmp_path / "taken"
    a_file.write_text("not a folder")
    line = one_error_line(run_level("--headless", "--frames", "1", "--size", "32x32", "--out", str(a_file)))
    assert repr(str(a_file)) in line and "existing file" in line
    line = one_error_line(run_level("--headless", "--frames", "1", "--size", "32x32", "--out", str(a_file / "sub")))
    assert repr(str(a_file / "sub")) in line and "cannot be made" in line
    assert a_file.read_text() == "not a folder"
    if os.geteuid() != 0:  # root writes anywhere, so a read-only folder is tested only as a user
        locked = tmp_path / "locked"
        locked.mkdir(mode=0o500)
        line = one_error_line(run_level("--headless", "--frames", "1", "--size", "32x32", "--out", str(locked)))
        assert "not writable" in line


def test_export_scene_writes_the_format_its_extension_says_and_the_closing_line_names_every_file(tmp_path):
    out = tmp_path / "frames"
    result = run_level("--headless", "--frames", "5", "--size", "64x36", "--ids", "--out", str(out),
                       "--export-scene", str(tmp_path / "scene.obj"))
    assert result.returncode == 2 and ".glb or .gltf" in result.stderr and "'" in result.stderr
    assert not out.exists() and not list(tmp_path.iterdir())  # refused before anything was written

    result = run_level("--headless", "--frames", "5", "--size", "64x36", "--ids", "--out", str(out),
                       "--export-scene", str(tmp_path / "scene.gltf"))
    assert result.returncode == 0, result.stderr
    gltf = json.loads((tmp_path / "scene.gltf").read_text())  # JSON glTF, buffer embedded
    assert gltf["asset"]["version"] == "2.0" and gltf["buffers"][0]["uri"].startswith("data:")
    import trimesh

    loaded = trimesh.load(str(tmp_path / "scene.gltf"), force="scene")
    info = json.loads((tmp_path / "scene.json").read_text())
    assert set(loaded.graph.nodes_geometry) == {e for e, kinds in info["entities"].items() if "MeshRef" in kinds}

    written = sorted(p for p in tmp_path.rglob("*") if p.is_file())
    assert len(written) == 5 + 5 + 2
    closing = result.stdout.strip().splitlines()[-1]
    assert closing == (f"speculum: wrote 5 frame(s): {out / 'frame_0000.png'} .. frame_0004.png (5 files), "
                       f"{out / 'ids_0000.npy'} .. ids_0004.npy (5 files), "
                       f"{tmp_path / 'scene.gltf'}, {tmp_path / 'scene.json'}")


def _no_camera_level(folder: Path) -> Path:
    """A game script whose world has a box and no camera."""
    level = folder / "no_camera.py"
    level.write_text(
        "from components import Material, MeshRef, Transform\n"
        "from engine import Game\nfrom shell import run\n"
        "from engine.assets.mesh import box\n"
        "class NoCamera(Game):\n"
        "    def build(self, world):\n"
        "        world.spawn(Transform(), MeshRef(box()), Material())\n"
        "run(NoCamera())\n")
    return level


def test_export_scene_without_a_camera_is_an_error_not_silence(tmp_path):
    level = _no_camera_level(tmp_path)
    scene_file = tmp_path / "scene.glb"
    result = subprocess.run([sys.executable, str(level), "--headless", "--frames", "1", "--size", "32x32",
                             "--out", str(tmp_path / "frames"), "--export-scene", str(scene_file)],
                            cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)},
                            capture_output=True, text=True, timeout=120)
    # The frame drawn first says there is no camera (a warning line); the export then fails.
    warned = [line for line in result.stderr.splitlines() if line.startswith("speculum: warning: ")]
    assert len(warned) == 1 and "no active camera" in warned[0]
    line = one_error_line(subprocess.CompletedProcess(result.args, result.returncode, result.stdout,
                                                      result.stderr.replace(warned[0] + "\n", "")))
    assert "camera" in line
    assert not scene_file.exists() and not scene_file.with_suffix(".json").exists()


def test_no_camera_is_said_once_and_again_when_it_goes_away(ctx):
    """Frames without an active camera are black: the main stage says so (NoCameraWarning)
    on the first such frame, not on every one, and again after a camera came and went."""
    import warnings

    from components import Camera, Skybox
    from engine.core.errors import NoCameraWarning
    from tests.support import SceneRunner, look_from

    scene = SceneRunner(ctx, lambda world: world.spawn(Skybox()), size=(16, 12))
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            scene.frame()
            scene.frame()
            said = [w for w in caught if issubclass(w.category, NoCameraWarning)]
            assert len(said) == 1 and "frame 1: the world has no active camera" in str(said[0].message)
            camera = look_from(scene.world, (0, 1, 4))
            rgb = scene.frame()
            assert rgb.std() > 0 or rgb.mean() > 0  # the sky shows once there is a camera
            scene.world.get(camera, Camera).active = False
            rgb = scene.frame()
            said = [w for w in caught if issubclass(w.category, NoCameraWarning)]
            assert len(said) == 2 and "frame 4:" in str(said[1].message)
            # Black: not the last frame with a camera left in the output (nor a window's old
            # back buffer); screen text is still drawn over it.
            assert rgb.max() == 0
            from components import ScreenText
            scene.world.spawn(ScreenText("x", position=(1.0, 1.0)))
            rgb = scene.frame()
            assert rgb.max() > 200 and (rgb == 0).all(axis=2).any()
    finally:
        scene.close()


def test_the_runner_says_no_camera_in_one_line(tmp_path):
    level = tmp_path / "no_camera.py"
    level.write_text("from components import Skybox\nfrom engine import Game\nfrom shell import run\n"
                     "class Empty(Game):\n    def build(self, world):\n        world.spawn(Skybox())\nrun(Empty())\n")
    result = subprocess.run([sys.executable, str(level), "--headless", "--frames", "2", "--size", "16x12",
                             "--out", str(tmp_path / "out")], cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)},
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stderr.strip().splitlines() == [
        "speculum: warning: frame 1: the world has no active camera (a Camera with a Transform and active=True; "
        "engine.spawn_camera makes one): frames show nothing until there is one"]


def _sample_with_flags(tmp_path, size: str, flags: tuple[str, ...]) -> tuple[dict, dict]:
    """The sample level's second headless frame at ``size`` without and with ``flags``
    ("plain", "with"), and the kinds of its camera's components as the scene export lists them."""
    frames, cameras = {}, {}
    for name, given in (("plain", ()), ("with", flags)):
        out = tmp_path / name
        result = run_level("--headless", "--frames", "2", "--size", size, "--aa", "off", "--out", str(out),
                           "--export-scene", str(tmp_path / f"{name}.gltf"), *given)
        assert result.returncode == 0, result.stderr
        frames[name] = np.asarray(Image.open(out / "frame_0001.png")).astype(int)
        info = json.loads((tmp_path / f"{name}.json").read_text())
        cameras[name] = next(kinds for kinds in info["entities"].values() if "Camera" in kinds)
    return frames, cameras


def test_dof_and_motion_blur_flags_put_the_lens_and_the_shutter_on_the_active_camera(tmp_path):
    """``--dof`` and ``--motion-blur`` give the sample level's camera its lens (autofocus) and
    a MotionBlur: the scene export lists them on the camera and the frame is blurred (the
    checker floor's edges soften: fewer steps between neighbouring pixels)."""
    frames, cameras = _sample_with_flags(tmp_path, "320x180", ("--dof", "--motion-blur"))
    assert "DepthOfField" in cameras["with"] and "MotionBlur" in cameras["with"], sorted(cameras["with"])
    assert not {"DepthOfField", "MotionBlur"} & set(cameras["plain"])
    steps = {name: np.abs(np.diff(frame.mean(axis=-1), axis=1)).mean() for name, frame in frames.items()}
    assert steps["with"] < 0.9 * steps["plain"], steps


def test_ao_and_ssr_flags_put_the_screen_effects_on_the_active_camera(tmp_path, capsys):
    """``--ao`` and ``--ssr`` give the sample level's camera an AmbientOcclusion() and a
    ScreenReflections() (its chrome ball and crates reflect the room where their rays find
    it; corners darken): the frame changes, the scene export lists them on the camera, and a
    game without a camera is told why the flag cannot be kept."""
    frames, cameras = _sample_with_flags(tmp_path, "160x90", ("--ao", "--ssr"))
    assert "AmbientOcclusion" in cameras["with"] and "ScreenReflections" in cameras["with"], sorted(cameras["with"])
    assert not {"AmbientOcclusion", "ScreenReflections"} & set(cameras["plain"])
    changed = np.abs(frames["with"] - frames["plain"]).max(axis=-1) > 8
    assert 0.01 < changed.mean() < 0.9  # (the picture, not a different one)

    # (In this process: shell.runner.main as the script's run() calls it.)
    from components import Material, MeshRef, Transform
    from engine import Game
    from engine.assets.mesh import box
    from shell.runner import main

    class NoCamera(Game):
        def build(self, world):
            world.spawn(Transform(), MeshRef(box()), Material())

    for flag in (["--ssr"], ["--ao"], ["--dof"], ["--motion-blur"], ["--contact-shadows"], ["--shafts"],
                 ["--camera", "0,1,2,0,0"]):  # (--camera: one line too, no traceback)
        status = main(NoCamera(), ["--headless", "--frames", "1", "--size", "32x32", "--out",
                                   str(tmp_path / "none"), *flag])
        lines = capsys.readouterr().err.strip().splitlines()
        assert status == 2 and len(lines) == 1 and lines[0].startswith("speculum: error: "), lines
        assert f"{flag[0]} given but the level has no active Camera" in lines[0]


def test_sky_and_time_flags_make_the_sample_levels_sky_an_evening(tmp_path, ctx):
    """``--sky atmosphere --time 19 --day-minutes 10`` on a game: its Skybox is the atmosphere
    with stars, its sun a TimeOfDay at 19:00 moving a day in ten minutes (the light's direction
    where the clock puts it after the frames), and the frame is darker and redder than the plain
    one; ``--day-minutes`` without ``--time`` and a bad hour are one error line each."""
    from components import DirectionalLight, Skybox, TimeOfDay
    from components.time_of_day import sun_towards
    from engine import Game, spawn_camera
    from shell.app import Engine

    class Open(Game):
        def build(self, world):
            spawn_camera(world, position=(0.0, 1.6, 4.0), pitch=5)
            world.spawn(DirectionalLight(intensity=3.0))

    engine = Engine(Open(), ctx)
    try:
        engine.start_sky("atmosphere", 19.0, 10.0)
        world = engine.world
        sky = world.query_one(Skybox)[0][1]
        assert sky.model == "atmosphere" and sky.faces is not None   # (made: the game had none)
        ((entity, clock),) = world.query_one(TimeOfDay)
        assert clock.hour == 19.0 and abs(clock.hours_per_second - 24.0 / 600.0) < 1e-12
        engine.frame(1.0, None)
        assert abs(clock.hour - (19.0 + 24.0 / 600.0)) < 1e-9
        light = world.get(entity, DirectionalLight)
        np.testing.assert_allclose(tuple(light.direction), tuple(-sun_towards(clock)), atol=1e-6)
    finally:
        engine.close()
    frames = {}
    for name, given in (("plain", ()), ("evening", ("--sky", "atmosphere", "--time", "19.5"))):
        result = run_level("--headless", "--frames", "2", "--size", "96x54", "--aa", "off",
                           "--out", str(tmp_path / name), *given)
        assert result.returncode == 0, result.stderr
        frames[name] = np.asarray(Image.open(tmp_path / name / "frame_0001.png")).astype(float)
    assert frames["evening"].mean() < 0.8 * frames["plain"].mean()
    red, blue = (frames["evening"][..., c].mean() / frames["plain"][..., c].mean() for c in (0, 2))
    assert red > 1.1 * blue
    for bad, words in ((("--day-minutes", "5"), "--day-minutes needs --time"), (("--time", "25"), "--time must be")):
        result = run_level("--headless", "--frames", "1", "--size", "16x12", "--out", str(tmp_path / "bad"), *bad)
        assert result.returncode != 0 and words in result.stderr, result.stderr
