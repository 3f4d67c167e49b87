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


def test_fly_keys_move_the_camera_along_its_own_axes_and_the_mouse_turns_it_the_way_it_moves(ctx):
    """README's controls: W A S D fly forward / left / back / right, Q E down / up, Shift
    faster, the mouse looks.  A fly camera turned 90 degrees to the left (looking down -X,
    its right -Z, worked out here from the turn) is given each key for one 0.5 s frame: it
    moves speed x 0.5 along that axis of its own; with Shift further the same way; a mouse
    move to the right turns its view towards its right, one down turns it down."""
    import math

    from pyglm import glm

    from components import FlyController, Transform, yaw_pitch_rotation
    from engine import spawn_camera

    speed, dt = 2.0, 0.5
    forward, right, up = glm.vec3(-1, 0, 0), glm.vec3(0, 0, -1), glm.vec3(0, 1, 0)
    expected = {"w": forward, "s": -forward, "a": -right, "d": right, "e": up, "q": -up}
    holder = {}

    def build(world):
        holder["camera"] = spawn_camera(world, position=(0.0, 1.0, 0.0), yaw=90.0)
        world.get(holder["camera"], FlyController).speed = speed
        world.spawn(Skybox())

    scene = SceneRunner(ctx, build, size=(16, 12))
    try:
        state = scene.world.resources[Input]
        transform = scene.world.get(holder["camera"], Transform)
        fly = scene.world.get(holder["camera"], FlyController)

        def step(*keys):
            start = glm.vec3(transform.position)
            state.press(*keys)
            scene.frame(dt)
            state.release(*keys)
            return transform.position - start

        for key, axis in expected.items():
            moved = step(key)
            assert glm.length(moved - axis * (speed * dt)) < 1e-5, (key, tuple(moved))
        plain, fast = step("d"), step("d", "shift")
        assert glm.dot(glm.normalize(fast), glm.normalize(plain)) > 0.9999
        assert glm.length(fast) > 1.5 * glm.length(plain)

        state.mouse_dx = 30.0  # to the right
        scene.frame(dt)
        looking = transform.rotation * glm.vec3(0, 0, -1)
        assert glm.dot(looking, right) > 0.05 and abs(looking.y) < 1e-6
        assert math.isclose(glm.dot(looking, forward), math.cos(math.radians(90.0 - fly.yaw)), abs_tol=1e-5)
        state.mouse_dy = 30.0  # down (window rows grow downwards)
        scene.frame(dt)
        assert (transform.rotation * glm.vec3(0, 0, -1)).y < -0.05
        assert transform.rotation == yaw_pitch_rotation(fly.yaw, fly.pitch)
    finally:
        scene.close()
