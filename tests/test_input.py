"""The Input resource a game reads: held keys, one-frame presses and clicks, through real frames
and through the window shell's key handler (moderngl-window's headless window)."""
from __future__ import annotations

from components import Skybox
from engine.core.frame_io import Input
from tests.support import SceneRunner, look_from


def test_a_press_lasts_one_frame_and_a_held_key_stays(ctx):
    seen: list[tuple[set, set, set]] = []

    def build(world):
        look_from(world, (0, 1, 4))
        world.spawn(Skybox())

    def update(world, dt):
        state = world.resources[Input]
        seen.append((set(state.held), set(state.pressed), set(state.clicks)))

    scene = SceneRunner(ctx, build, size=(32, 24), update=update)
    try:
        state = scene.world.resources[Input]
        state.press("space", "r")
        state.clicks.add("left")
        scene.frame()
        scene.frame()
        state.release("r")
        scene.frame()
    finally:
        scene.close()
    assert seen[0] == ({"space", "r"}, {"space", "r"}, {"left"})
    assert seen[1] == ({"space", "r"}, set(), set())  # still held, no new press, no click
    assert seen[2] == ({"space"}, set(), set())


def test_window_shell_names_keys_and_clicks(tmp_path):
    import moderngl_window as mglw

    from shell.window import make_window_config
    from tests.support import FunctionGame

    seen: list[tuple[set, set]] = []

    def build(world):
        look_from(world, (0, 1, 4))
        world.spawn(Skybox())

    def update(world, dt):
        state = world.resources[Input]
        seen.append((set(state.pressed), set(state.clicks)))

    config = mglw.create_window_config_instance(
        make_window_config(FunctionGame(build, update)),
        args=["--window", "headless", "--backend", "egl", "--size", "32x24"])
    try:
        keys = config.wnd.keys

        class Mods:
            shift = False
            ctrl = False

        for name in ("SPACE", "R", "LEFT", "NUMBER_3"):
            code = getattr(keys, name)
            config.on_key_event(code if isinstance(code, int) else name, keys.ACTION_PRESS, Mods())
        config.on_mouse_press_event(10, 5, 1)
        config.on_render(0.0, 1 / 60)
        config.on_render(0.0, 1 / 60)
        assert config.input.mouse == (10.0, 5.0)
    finally:
        config.on_close()
    assert seen[0] == ({"space", "r", "left", "3"}, {"left"})
    assert seen[1] == (set(), set())
