"""Level files reload on save (shell/level_reload.py): a run with reload on rebuilds its world
from the saved file, keeping the camera; a broken save keeps the old world and reports its
error once (file and line); a fixed save loads again.  Real frames, compared with a second
path: the saved file rendered by an engine of its own, from the same camera pose."""
from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np
import pytest

from components import Transform
from engine.assets.level_file import LevelGame
from engine.core.frame_io import Output
from engine.render.targets import CaptureTarget
from shell.app import Engine
from shell.runner import HEADLESS_DT, run_headless

SIZE = (96, 72)
POSE = (0.4, 1.2, 4.5, 4.0, -6.0)  # x, y, z, yaw, pitch: not the file's camera

LEVEL = """[level]
name = "reload test"

[[entity]]
name = "camera"
[entity.Transform]
position = [0.0, 1.0, 5.0]
[entity.Camera]

[[entity]]
name = "sun"
[entity.DirectionalLight]
direction = [-0.3, -1.0, -0.5]
intensity = 2.0

[[entity]]
name = "floor"
[entity.Transform]
[entity.MeshRef]
mesh = { plane = [10.0, 10.0] }
[entity.Material]
color = [0.5, 0.5, 0.5, 1.0]

[[entity]]
name = "box"
[entity.Transform]
position = [BOX_X, 1.0, 0.0]
[entity.MeshRef]
mesh = { box = [1.0, 1.0, 1.0] }
[entity.Material]
color = BOX_COLOR
roughness = ROUGHNESS
"""
RED, BLUE = "[0.9, 0.1, 0.1, 1.0]", "[0.1, 0.2, 0.9, 1.0]"
ROUGHNESS_LINE = LEVEL.split("\n").index("roughness = ROUGHNESS") + 1


def level_text(box_x: float = 0.0, color: str = RED, roughness: str = "0.5") -> str:
    return LEVEL.replace("BOX_X", str(box_x)).replace("BOX_COLOR", color).replace("ROUGHNESS", roughness)


_clock = [1_700_000_000 * 10**9]
# A model placed by the level: crate.glb beside it.
CRATE = ('\n[[entity]]\nname = "crate"\n[entity.Transform]\nposition = [1.5, 0.5, 0.0]\n'
         '[entity.Model]\nfile = "crate.glb"\n')


def save(path: Path, text: str) -> None:
    """Write ``text`` as an editor saves, with a modification time later than any before
    (a file system's clock may be coarser than two writes in a test)."""
    path.write_text(text)
    _clock[0] += 10**9
    os.utime(path, ns=(_clock[0], _clock[0]))


class Run:
    """An Engine on a level file rendering into a capture target."""

    def __init__(self, ctx, path: Path) -> None:
        self.engine = Engine(LevelGame(path), ctx)
        self.capture = CaptureTarget(ctx, SIZE)

    def frame(self) -> np.ndarray:
        self.engine.frame(HEADLESS_DT, Output(self.capture.framebuffer, SIZE))
        return self.capture.read_rgb()

    def close(self) -> None:
        self.capture.release()
        self.engine.close()


def reference(ctx, tmp_path: Path, text: str, frames: int = 3) -> np.ndarray:
    """The second path: ``text`` as a level of its own, from ``POSE``."""
    path = tmp_path / "reference.toml"
    path.write_text(text)
    run = Run(ctx, path)
    try:
        run.engine.place_camera(*POSE)
        for _ in range(frames - 1):
            run.frame()
        return run.frame()
    finally:
        run.close()


def box_entity(engine: Engine) -> int:
    return engine.game.names["box"]


def test_saved_level_reloads_broken_keeps_old_fixed_reloads(ctx, tmp_path):
    path = tmp_path / "level.toml"
    save(path, level_text())
    run = Run(ctx, path)
    try:
        reload = run.engine.watch_level(interval=0.0)
        run.engine.place_camera(*POSE)
        for _ in range(2):
            run.frame()
        before = run.frame()
        assert reload.poll() == []  # nothing saved: nothing happens
        old_box = box_entity(run.engine)

        # A save: the box moves and turns blue.  The first poll sees the stat change and
        # waits (the save may be mid-write); the next, with the stat stable, reloads.
        changed = level_text(box_x=-0.8, color=BLUE)
        save(path, changed)
        assert reload.poll() == []
        assert run.engine.world.exists(old_box)
        messages = reload.poll()
        assert messages == [f"level reloaded: {path}"] and reload.reloads == 1 and reload.error is None
        new_box = box_entity(run.engine)
        assert new_box != old_box and not run.engine.world.exists(old_box)
        assert tuple(run.engine.world.get(new_box, Transform).position) == pytest.approx((-0.8, 1.0, 0.0))
        # The camera stayed where it was placed, not where the file puts it.
        _, _, camera = run.engine.active_camera()
        assert tuple(camera.position) == pytest.approx(POSE[:3])
        for _ in range(2):
            run.frame()
        after = run.frame()
        expected = reference(ctx, tmp_path, changed)
        assert np.abs(after.astype(int) - expected.astype(int)).max() <= 1
        assert np.abs(after.astype(int) - before.astype(int)).max() > 60  # a change one can see
        blue = (after[..., 2].astype(int) - after[..., 0]) > 60
        assert blue.sum() > 50, "the blue box is in the frame"

        # A broken save: the old (blue) world keeps running, the error is said once and
        # names the file and the line.
        save(path, level_text(box_x=0.8, color=RED, roughness="7.0"))
        assert reload.poll() == []
        messages = reload.poll()
        assert len(messages) == 1
        assert f"{path}:{ROUGHNESS_LINE}" in messages[0] and "'box'" in messages[0] and "roughness" in messages[0]
        assert reload.error == messages[0]
        for _ in range(3):
            assert reload.poll() == []  # once
            frame = run.frame()
        assert np.abs(frame.astype(int) - after.astype(int)).max() <= 1
        assert run.engine.world.exists(new_box) and reload.reloads == 1
        # The overlay shows it at the top of its error area, as it shows shader errors.
        overlay_module = pytest.importorskip("shell.overlay")
        overlay = overlay_module.DebugOverlay(ctx)
        try:
            overlay.draw(run.engine, run.capture.framebuffer, SIZE)
            assert overlay.shown_errors[:1] == [reload.error]
        finally:
            overlay.release()

        # A TOML syntax error: the same.
        save(path, changed.replace("[[entity]]\nname = \"box\"", "[[entity]\nname = \"box\""))
        reload.poll()
        (message,) = reload.poll()
        assert f"{path}:" in message and run.engine.world.exists(new_box)

        # Fixed: it reloads.
        fixed = level_text(box_x=0.8, color=RED)
        save(path, fixed)
        reload.poll()
        assert reload.poll() == [f"level reloaded: {path}"] and reload.error is None and reload.reloads == 2
        for _ in range(2):
            run.frame()
        final = run.frame()
        assert np.abs(final.astype(int) - reference(ctx, tmp_path, fixed).astype(int)).max() <= 1
    finally:
        run.close()


def test_mid_write_and_unchanged_saves_do_not_reload(ctx, tmp_path):
    path = tmp_path / "level.toml"
    save(path, level_text())
    run = Run(ctx, path)
    try:
        reload = run.engine.watch_level(interval=0.0)
        run.frame()
        # Half a file (an editor writing in chunks), seen by one poll; then the rest.
        full = level_text(box_x=-0.8, color=BLUE)
        save(path, full[: len(full) // 2])
        assert reload.poll() == []
        save(path, full)
        assert reload.poll() == []  # changed again since the last look: still waiting
        assert reload.poll() == [f"level reloaded: {path}"]
        assert reload.error is None
        # Saved again without an edit: no rebuild.
        entity = box_entity(run.engine)
        save(path, full)
        reload.poll()
        assert reload.poll() == [] and box_entity(run.engine) == entity and reload.reloads == 1
        run.frame()
    finally:
        run.close()


class SavingLevel(LevelGame):
    """A level game that, as an editor would, saves its own file at frame ``at``."""

    def __init__(self, path: Path, text: str, at: int) -> None:
        super().__init__(path)
        self.text, self.at, self.frame = text, at, 0

    def update(self, world, dt) -> None:
        self.frame += 1
        if self.frame == self.at:
            save(self.level_path, self.text)


def test_runner_reload_flag(ctx, tmp_path, capsys):
    """``--reload`` in a headless run: frames after a save show the saved level."""
    path = tmp_path / "level.toml"
    save(path, level_text())
    changed = level_text(box_x=-0.8, color=BLUE)
    out = tmp_path / "out"
    out.mkdir()
    args = argparse.Namespace(frames=6, out=out, size=SIZE, aa="fxaa", camera=POSE, overlay=False, gif=None,
                              ids=False, export_scene=None, dt=HEADLESS_DT, reload=True)
    written = run_headless(SavingLevel(path, changed, at=1), args)
    assert "level reloaded" in capsys.readouterr().err
    import imageio.v3 as iio

    last = iio.imread(written[-1])[..., :3]
    first = iio.imread(written[0])[..., :3]
    # Saved in frame 1's update, stable by the poll before frame 3: frames from there on are
    # the new level's (the reference runs as many frames after its build).
    expected = reference(ctx, tmp_path, changed, frames=4)
    assert np.abs(last.astype(int) - expected.astype(int)).max() <= 1
    assert np.abs(first.astype(int) - expected.astype(int)).max() > 60


def test_window_reloads_a_saved_level_and_prints_a_broken_one_once(ctx, tmp_path, capsys):
    """The windowed shell (moderngl-window's headless window) watches a level game's file
    by itself: a save rebuilds the world; a broken one is printed once and the old kept."""
    import moderngl_window as mglw

    from shell.window import make_window_config

    path = tmp_path / "level.toml"
    save(path, level_text())
    config = mglw.create_window_config_instance(
        make_window_config(LevelGame(path)), args=["--window", "headless", "--backend", "egl", "--size", "96x72"])
    try:
        reload = config.engine.level_reload
        assert reload is not None
        config.on_render(0.0, 1 / 60)
        old_box = box_entity(config.engine)
        save(path, level_text(box_x=-0.8, color=BLUE))
        for _ in range(3):
            reload._next_poll = 0.0  # as if a quarter second had passed each frame
            config.on_render(0.0, 1 / 60)
        assert reload.reloads == 1 and not config.engine.world.exists(old_box)
        save(path, level_text(roughness="7.0"))
        for _ in range(4):
            reload._next_poll = 0.0
            config.on_render(0.0, 1 / 60)
        printed = [line for line in capsys.readouterr().err.splitlines() if "level reload" in line]
        assert printed == [f"speculum: level reloaded: {path}", f"speculum: {reload.error}"], printed
        assert f"{path}:{ROUGHNESS_LINE}" in reload.error
        assert config.engine.world.exists(box_entity(config.engine)) and reload.reloads == 1
    finally:
        config.on_close()
        config.wnd.destroy()


def test_a_game_that_changes_level_is_followed(ctx, tmp_path):
    """A game that plays another level (mirror beam's 'n') is watched on its new file: the
    old file's saves reload nothing, the new one's do."""
    first, second = tmp_path / "first.toml", tmp_path / "second.toml"
    save(first, level_text())
    save(second, level_text(box_x=0.5))
    run = Run(ctx, first)
    try:
        reload = run.engine.watch_level(interval=0.0)
        run.frame()
        run.engine.game.level_path = second  # as a game's next level does (it builds it itself)
        assert reload.poll() == [] and reload.path == second
        save(first, level_text(color=BLUE))
        reload.poll()
        assert reload.poll() == [] and reload.reloads == 0
        save(second, level_text(box_x=0.5, color=BLUE))
        reload.poll()
        assert reload.poll() == [f"level reloaded: {second}"]
        run.frame()
    finally:
        run.close()


def test_a_save_made_by_the_run_itself_is_not_reloaded_after_follow(ctx, tmp_path):
    """The run's own save (an in-window editor writing the world back) calls ``follow``: the
    file as written counts as loaded, and the world the editor holds is not rebuilt."""
    path = tmp_path / "level.toml"
    save(path, level_text())
    run = Run(ctx, path)
    try:
        reload = run.engine.watch_level(interval=0.0)
        run.frame()
        entity = box_entity(run.engine)
        save(path, level_text(roughness="0.25"))  # as save_level would write the edited world
        reload.follow(path)
        for _ in range(3):
            assert reload.poll() == []
        assert box_entity(run.engine) == entity and run.engine.world.exists(entity) and reload.reloads == 0
    finally:
        run.close()


def test_a_model_file_the_level_places_reloads_the_level_when_saved(ctx, tmp_path):
    """A level placing a model (``Model``) reloads when the model file is exported again:
    its new colour shows; a broken export keeps the old world and says so once."""
    from components import FromModel, Material
    from engine.assets.mesh import box
    from tests.test_materials_from_files import write_glb

    def export(color: list[float]) -> None:
        write_glb(tmp_path / "crate.glb", box((1.0, 1.0, 1.0)),
                  {"name": "paint", "pbrMetallicRoughness": {"baseColorFactor": color, "metallicFactor": 0.0}}, [])
        _clock[0] += 10**9
        os.utime(tmp_path / "crate.glb", ns=(_clock[0], _clock[0]))

    def part_color(engine: Engine) -> list[float]:
        (entity,) = [e for e, _ in engine.world.query_one(FromModel)]
        return list(engine.world.get(entity, Material).color)

    export([0.9, 0.1, 0.1, 1.0])
    path = tmp_path / "level.toml"
    save(path, level_text() + CRATE)
    run = Run(ctx, path)
    try:
        reload = run.engine.watch_level(interval=0.0)
        red = run.frame()
        assert part_color(run.engine) == pytest.approx([0.9, 0.1, 0.1, 1.0], abs=0.01)
        export([0.1, 0.2, 0.9, 1.0])
        assert reload.poll() == []                               # changed since the last look: wait
        assert reload.poll() == [f"level reloaded: {path}"]
        assert part_color(run.engine) == pytest.approx([0.1, 0.2, 0.9, 1.0], abs=0.01)
        assert not np.array_equal(run.frame(), red)
        (tmp_path / "crate.glb").write_bytes(b"glTF broken")
        _clock[0] += 10**9
        os.utime(tmp_path / "crate.glb", ns=(_clock[0], _clock[0]))
        reload.poll()
        said = reload.poll()
        assert len(said) == 1 and "level reload failed, previous level kept" in said[0] and "crate.glb" in said[0]
        assert reload.poll() == [] and part_color(run.engine) == pytest.approx([0.1, 0.2, 0.9, 1.0], abs=0.01)
    finally:
        run.close()


def test_an_image_a_model_names_beside_it_reloads_the_level_when_painted_again(ctx, tmp_path):
    """A GLB whose colour map is a PNG beside it: painting the PNG again (the model file
    untouched) reloads the level, and the part wears the new image."""
    from components import FromModel, Material
    from engine.assets.mesh import box
    from tests.test_materials_from_files import write_glb
    from tests.test_model_variants import edit_glb

    def paint(rgb: tuple[int, int, int]) -> None:
        from PIL import Image

        Image.fromarray(np.full((4, 4, 3), rgb, np.uint8)).save(tmp_path / "paint.png")
        _clock[0] += 10**9
        os.utime(tmp_path / "paint.png", ns=(_clock[0], _clock[0]))

    def texel(engine: Engine) -> list[int]:
        (entity,) = [e for e, _ in engine.world.query_one(FromModel)]
        return engine.world.get(entity, Material).texture.pixels[0, 0, :3].tolist()

    paint((200, 30, 30))
    write_glb(tmp_path / "crate.glb", box((1.0, 1.0, 1.0)),
              {"name": "paint", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0.0}}, [])
    edit_glb(tmp_path / "crate.glb", lambda doc: doc.update(images=[{"uri": "paint.png"}], textures=[{"source": 0}]))
    path = tmp_path / "level.toml"
    save(path, level_text() + CRATE)
    run = Run(ctx, path)
    try:
        reload = run.engine.watch_level(interval=0.0)
        run.frame()
        assert texel(run.engine) == [200, 30, 30]
        paint((30, 60, 220))
        assert reload.poll() == []                               # changed since the last look: wait
        assert reload.poll() == [f"level reloaded: {path}"]
        assert texel(run.engine) == [30, 60, 220]
    finally:
        run.close()


def test_reload_on_the_command_line_reloads_and_without_it_a_save_is_not(ctx, tmp_path, capsys):
    """``main`` with ``--reload`` parsed from the command line (not a Namespace made here): a
    level that saves its own file at frame 1 is drawn as saved from frame 3 on, the same
    pixels as the saved file played from the start; without ``--reload`` every frame is the
    old level's."""
    from shell.runner import main

    changed = level_text(box_x=-0.8, color=BLUE)
    camera = ",".join(str(v) for v in POSE)
    last = {}
    for name, flags in (("reload", ["--reload"]), ("plain", [])):
        path = tmp_path / f"{name}.toml"
        save(path, level_text())
        out = tmp_path / name
        argv = ["--headless", "--frames", "4", "--size", f"{SIZE[0]}x{SIZE[1]}", "--camera", camera,
                "--out", str(out), *flags]
        assert main(SavingLevel(path, changed, at=1), argv) == 0
        said = [line for line in capsys.readouterr().err.splitlines() if "level reload" in line]
        assert said == ([f"speculum: level reloaded: {path}"] if flags else []), said
        import imageio.v3 as iio

        last[name] = iio.imread(out / "frame_0003.png")[..., :3].astype(int)
    saved = reference(ctx, tmp_path, changed, frames=2).astype(int)
    old = reference(ctx, tmp_path, level_text(), frames=4).astype(int)
    assert np.abs(last["reload"] - saved).max() <= 1
    assert np.abs(last["plain"] - old).max() <= 1
    assert np.abs(saved - old).max() > 60  # (the save is a change one can see)


FLY = '\n[entity.FlyController]\nyaw = 0.0\npitch = 0.0\n'


def test_a_reload_keeps_the_fly_cameras_heading_so_the_next_mouse_move_turns_from_it(ctx, tmp_path):
    """The camera kept across a reload is its FlyController's yaw and pitch too: a mouse move
    after the reload turns from the kept heading (POSE's yaw less dx times the sensitivity),
    not from the file's 0, 0 (which would swing the view back first)."""
    from components import FlyController, yaw_pitch_rotation
    from engine.core.frame_io import Input

    text = level_text().replace("[entity.Camera]\n", "[entity.Camera]" + FLY, 1)
    path = tmp_path / "level.toml"
    save(path, text)
    run = Run(ctx, path)
    try:
        reload = run.engine.watch_level(interval=0.0)
        run.engine.place_camera(*POSE)
        run.frame()
        save(path, text.replace("roughness = 0.5", "roughness = 0.3"))
        reload.poll()
        assert reload.poll() == [f"level reloaded: {path}"]
        entity, _, transform = run.engine.active_camera()
        fly = run.engine.world.get(entity, FlyController)
        assert (fly.yaw, fly.pitch) == pytest.approx(POSE[3:])
        run.engine.world.resources[Input].mouse_dx = 20.0
        run.frame()
        yaw = POSE[3] - 20.0 * fly.mouse_sensitivity
        expected = yaw_pitch_rotation(yaw, POSE[4])
        turned = transform.rotation * glm_forward()
        wanted = expected * glm_forward()
        assert np.allclose(tuple(turned), tuple(wanted), atol=1e-5), (tuple(turned), tuple(wanted))
        assert tuple(transform.position) == pytest.approx(POSE[:3])
    finally:
        run.close()


def glm_forward():
    from pyglm import glm

    return glm.vec3(0.0, 0.0, -1.0)
