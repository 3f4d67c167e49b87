"""Monitors (``Monitor``): a screen showing what a camera sees, drawn by the scene pass into a
picture its screen gives off (``engine/render/monitors.py``, ``systems/monitor_system.py``).

The pictures are read back and checked against rays cast from the monitor's camera (which
pixels meet the box, or its image in a mirror), and the frame's screen against the picture
read back, sampled where each pixel's ray meets the screen."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    ComponentValueError,
    ComponentWarning,
    Material,
    MeshRef,
    Mirror,
    Monitor,
    Skybox,
    Transform,
    look_rotation,
)
from engine.assets.level_file import LevelError, load_level, save_level
from engine.assets.mesh import box, quad
from engine.core.errors import MonitorLimitWarning
from engine.core.world import World
from engine.render.monitors import MAX_MONITORS
from engine.render.views import camera_view
from tests.support import box_hits, pixel_rays, srgb_to_linear

DT = 1.0 / 60.0
RED = (0.3, 0.05, 0.05)           # the box's light (unlit: its colour as it is), linear
BOX_AT, BOX_HALF = np.array([0.7, 1.5, -4.0]), np.array([0.6, 0.45, 0.4])   # off the picture's middle: up and right
LENS_AT, LENS_FOV = (0.0, 1.0, 0.0), 60.0   # the monitor's camera, looking down -z
SCREEN_AT, SCREEN_SIZE = (0.0, 1.0, 6.0), (1.6, 0.9)   # facing +z, behind the lens
PICTURE = (96, 54)


def black_sky():
    return Skybox(faces=[np.zeros((8, 8, 3), np.float32) for _ in range(6)])


def studio(monitor: Monitor | None = None, eye=(0.0, 1.0, 7.5), mirror: bool = False, box_at=BOX_AT,
           box_half=BOX_HALF, bare_screen: bool = False):
    """A black world (no light: what shows is the unlit box's colour and the screen's light):
    a red unlit box, a camera (not active) at LENS_AT looking down -z, a screen quad facing +z
    behind it with ``monitor`` (its camera set to the lens), and the active camera at ``eye``
    looking at the screen; ``mirror``: a mirror 3 m in front of the lens, facing it;
    ``bare_screen``: the screen without a monitor.  Returns the build and a dict it fills
    (lens, screen, box)."""
    held = {}

    def build(world):
        world.spawn(Transform(position=eye, rotation=look_rotation(glm.vec3(SCREEN_AT) - glm.vec3(eye))),
                    Camera(fov_y=40.0))
        world.spawn(black_sky())
        held["box"] = world.spawn(Transform(position=tuple(box_at)), MeshRef(box(tuple(2 * np.asarray(box_half)))),
                                  Material(color=(*RED, 1.0), unlit=True))
        held["lens"] = world.spawn(Transform(position=LENS_AT), Camera(fov_y=LENS_FOV, active=False))
        if mirror:
            held["mirror"] = world.spawn(Transform(position=(0.0, 1.0, -3.0)), MeshRef(quad(3.0, 2.0)),
                                         Material(color=(1.0, 1.0, 1.0, 1.0)), Mirror())
        if monitor is not None or bare_screen:
            if monitor is not None and monitor.camera is None:
                monitor.camera = held["lens"]
            held["screen"] = world.spawn(Transform(position=SCREEN_AT), MeshRef(quad(*SCREEN_SIZE)),
                                         Material(color=(0.0, 0.0, 0.0, 1.0), roughness=1.0,
                                                  environment_reflection=0.0), *([monitor] if monitor else []))
    return build, held


def run(scene, build, frames: int, size=(160, 120)):
    runner = scene(build, size)
    runner.engine.renderer.antialias = "off"
    rgb = None
    for _ in range(frames):
        rgb = runner.frame(DT)
    return runner, rgb


def picture(runner, held) -> np.ndarray:
    return runner.engine.renderer.monitors.read(held["screen"])


def lens_rays(size=PICTURE):
    """The monitor camera's primary rays through each picture pixel (rows from the top)."""
    view = camera_view(glm.translate(glm.vec3(LENS_AT)), LENS_FOV, 0.1, 100.0, size)
    return pixel_rays(view, size)


def active_camera(world) -> int:
    """The world's active camera entity."""
    (camera, _), = [(e, c) for e, c in world.query_one(Camera) if c.active]
    return camera


def spawn_watcher(world, held) -> None:
    """Monitor A (``held["watcher"]``): a screen at x = 4 fed by a lens behind the studio's
    screen (B's), looking at it and, past it, the box."""
    lens = world.spawn(Transform(position=(0.0, 1.0, 8.5), rotation=look_rotation(glm.vec3(0.0, 0.0, -1.0))),
                       Camera(fov_y=LENS_FOV, active=False))
    held["watcher"] = world.spawn(Transform(position=(4.0, 1.0, 6.0)), MeshRef(quad(*SCREEN_SIZE)),
                                  Material(color=(0.0, 0.0, 0.0, 1.0), roughness=1.0, environment_reflection=0.0),
                                  Monitor(camera=lens, size=PICTURE))


def facing_own_screen(world, held, in_front: bool = True) -> None:
    """The box moved beside the screen and the lens turned to the screen, from in front of
    it (+z, its face) or from behind."""
    world.get(held["box"], Transform).position = (-1.7, 1.0, 6.0)
    lens = world.get(held["lens"], Transform)
    lens.position = (0.3, 1.0, 9.0) if in_front else (0.3, 1.0, 3.0)
    lens.rotation = look_rotation(glm.vec3(-0.25, 0.0, -1.0) if in_front else glm.vec3(-0.1, 0.0, 1.0))


def seen_in_a_mirror(world) -> None:
    """A mirror behind the screen facing it, and the active camera (a new one) looking into
    the mirror, still: it sees the screen there."""
    from tests.support import look_from

    world.spawn(Transform(position=(0.0, 1.0, 9.5), rotation=look_rotation(glm.vec3(0.0, 0.0, 1.0))),
                MeshRef(quad(3.0, 2.0)), Material(color=(1.0, 1.0, 1.0, 1.0)), Mirror())
    world.delete_entity(active_camera(world))
    look_from(world, (0.4, 1.0, 7.0), target=(0.0, 1.0, 9.5), fov=50.0)


def test_a_monitor_shows_what_its_camera_sees_on_its_screen(scene):
    """The picture is red exactly where the monitor camera's rays meet the box (the box up and
    to the right of the picture's middle: the picture is the right way up and round); on the
    frame, each pixel whose ray meets the screen gives off brightness x the picture there
    (its texel at the screen point's UV, filtered), against the frame drawn with the
    picture's brightness doubled: twice the light."""
    frames = {}
    for brightness in (1.0, 2.0):
        build, held = studio(Monitor(size=PICTURE, brightness=brightness))
        runner, rgb = run(scene, build, 2)
        frames[brightness] = srgb_to_linear(rgb)
        assert runner.stats.monitor_views == 0 and runner.stats.monitors_kept == 1   # (the first frame's, kept)
    shown = picture(runner, held)
    eye, rays = lens_rays()
    hits = box_hits(eye, rays.reshape(-1, 3), BOX_AT, BOX_HALF).reshape(PICTURE[1], PICTURE[0])
    red = shown[..., 0] > RED[0] / 2
    assert hits.sum() > 150 and (~hits).sum() > 150
    assert np.mean(red != hits) < 0.005, np.mean(red != hits)
    assert np.allclose(shown[hits][:, :3], RED, atol=0.01) and np.abs(shown[~hits][:, :3]).max() < 0.01
    # The box stands up and right of the lens's axis: its pixels are in the picture's top right.
    rows, columns = np.nonzero(hits)
    assert rows.mean() < PICTURE[1] / 2 and columns.mean() > PICTURE[0] / 2
    # Where each frame pixel's ray meets the screen (facing +z at SCREEN_AT), its UV, the
    # picture sampled there bilinearly (texel centres at (i + 0.5) / size).
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    t = (SCREEN_AT[2] - eye[2]) / rays[..., 2]
    point = eye + rays * t[..., None]
    u = (point[..., 0] - SCREEN_AT[0]) / SCREEN_SIZE[0] + 0.5
    v = (point[..., 1] - SCREEN_AT[1]) / SCREEN_SIZE[1] + 0.5
    inside = (u > 0.02) & (u < 0.98) & (v > 0.02) & (v < 0.98)
    assert inside.sum() > 2000
    x = np.clip(u[inside] * PICTURE[0] - 0.5, 0, PICTURE[0] - 1.001)
    y = np.clip((1.0 - v[inside]) * PICTURE[1] - 0.5, 0, PICTURE[1] - 1.001)
    x0, y0 = x.astype(int), y.astype(int)
    fx, fy = x - x0, y - y0
    texels = shown[..., 0]
    sampled = (texels[y0, x0] * (1 - fx) * (1 - fy) + texels[y0, x0 + 1] * fx * (1 - fy)
               + texels[y0 + 1, x0] * (1 - fx) * fy + texels[y0 + 1, x0 + 1] * fx * fy)
    for brightness, linear in frames.items():
        seen = linear[..., 0][inside]
        assert np.corrcoef(seen, sampled)[0, 1] > 0.97, (brightness, np.corrcoef(seen, sampled)[0, 1])
        assert np.median(np.abs(seen - brightness * sampled)) < 0.01, brightness
        assert abs(seen.mean() - brightness * sampled.mean()) < 0.02 * brightness, brightness
    # Off the screen the frame is black (nothing else gives light but the box, not in view).
    assert frames[1.0][~((u > -0.05) & (u < 1.05) & (v > -0.05) & (v < 1.05))].max() < 0.02


def test_a_pictures_light_is_kept_whole_past_one_and_between_eight_bit_steps(scene):
    """The picture holds the light its camera sees as the frame's own levels do (half floats):
    a box of linear colour (3, 0.3039, 0.05) reads back so where the lens's rays meet it, its
    red past 1 and its green halfway between two 8-bit steps (an 8-bit copy reads 1 and
    0.302 or 0.306); and the frame's screen, at a brightness of 0.25, gives off 0.25 x 3 in
    red where the picture's box fills it (0.25 from a picture cut at 1)."""
    bright = (3.0, 0.3039, 0.05)
    build, held = studio(Monitor(size=PICTURE, brightness=0.25))

    def brighter(world):
        build(world)
        world.get(held["box"], Material).color = (*bright, 1.0)

    runner, rgb = run(scene, brighter, 2)
    shown = picture(runner, held)
    eye, rays = lens_rays()
    hits = box_hits(eye, rays.reshape(-1, 3), BOX_AT, BOX_HALF).reshape(PICTURE[1], PICTURE[0])
    assert hits.sum() > 150
    # (inside the box's image, a texel from its edge: bilinear mips leave the texels as drawn)
    inner = hits & np.roll(hits, 1, 0) & np.roll(hits, -1, 0) & np.roll(hits, 1, 1) & np.roll(hits, -1, 1)
    assert inner.sum() > 100
    np.testing.assert_allclose(shown[inner][:, :3], np.broadcast_to(bright, (inner.sum(), 3)), rtol=2e-3, atol=3e-4)
    # On the frame: the screen's brightest pixels are the box's image, 0.75 in red (under 1:
    # the frame's 8-bit output holds it), and its green at 0.25 x 0.3039.
    linear = srgb_to_linear(rgb)
    red = linear[..., 0]
    top = red > 0.5
    assert top.sum() > 40, top.sum()
    assert np.median(red[top]) == pytest.approx(0.25 * bright[0], abs=0.02)
    assert np.median(linear[..., 1][top]) == pytest.approx(0.25 * bright[1], abs=0.01)


@pytest.mark.parametrize("depth", [0, 1])
def test_a_monitors_picture_shows_the_mirrors_its_camera_sees_to_its_depth(scene, depth):
    """The lens looks at a mirror; the box stands behind the lens, out of its sight.  With
    ``depth`` 1 the picture is red where the lens's rays, reflected off the mirror, meet the
    box; with 0 the mirror shows its fallback (the black sky): no red at all."""
    behind, half = np.array([0.5, 1.2, 1.5]), np.array([0.8, 0.6, 0.3])
    build, held = studio(Monitor(size=PICTURE, depth=depth), mirror=True, box_at=behind, box_half=half)
    runner, _ = run(scene, build, 2)
    shown = picture(runner, held)
    red = shown[..., 0] > RED[0] / 2
    eye, rays = lens_rays()
    rays = rays.reshape(-1, 3)
    t = (-3.0 - eye[2]) / rays[:, 2]
    point = eye + rays * t[:, None]
    on_mirror = (t > 0) & (np.abs(point[:, 0]) < 1.5) & (np.abs(point[:, 1] - 1.0) < 1.0)
    reflected = rays * np.array([1.0, 1.0, -1.0])
    hits = np.zeros(len(rays), bool)
    hits[on_mirror] = box_hits(point[on_mirror], reflected[on_mirror], behind, half)
    hits = hits.reshape(PICTURE[1], PICTURE[0])
    # (the first frame's picture, kept: the mirror's view sees the one-sided screen from behind;
    # on a GPU a tree drawn on predicted counts is drawn once more with exact ones first)
    predicted = depth > 0 and not runner.engine.renderer.caps.software
    assert (runner.stats.monitor_views, runner.stats.monitors_kept) == ((2, 0) if predicted else (0, 1))
    if depth == 0:
        assert not red.any()
    else:
        assert hits.sum() > 60, hits.sum()
        assert np.sum(red != hits) < 0.05 * hits.sum(), (np.sum(red != hits), hits.sum())


def test_a_slow_monitor_is_drawn_every_few_frames_and_keeps_its_picture_between(scene):
    """``every`` 3: drawn on its first frame and every third after; the box moving every frame,
    the picture changes on those frames alone."""
    build, held = studio(Monitor(size=PICTURE, every=3))
    runner = scene(build, (64, 48))
    drawn, pictures = [], []
    for _ in range(7):
        transform = runner.world.get(held["box"], Transform)
        transform.position = transform.position + glm.vec3(0.05, 0.0, 0.0)
        runner.frame(DT)
        drawn.append(runner.stats.monitor_views)
        pictures.append(picture(runner, held))
    assert drawn == [1, 0, 0, 1, 0, 0, 1]
    changed = [not np.array_equal(a, b) for a, b in zip(pictures, pictures[1:], strict=False)]
    assert changed == [False, False, True, False, False, True]


def test_a_monitor_its_own_camera_sees_shows_its_picture_of_the_draw_before(scene):
    """The lens turned to look at its own screen's face (the box beside it, in sight): the first
    picture shows the screen black (nothing drawn on it yet); the second shows the first
    picture on it: the box's red inside the screen's rectangle."""
    build, held = studio(Monitor(size=PICTURE))

    def turned(world):
        build(world)
        facing_own_screen(world, held)

    runner = scene(turned, (64, 48))
    runner.frame(DT)
    first = picture(runner, held)
    runner.frame(DT)
    second = picture(runner, held)
    assert runner.engine.ctx.error == "GL_NO_ERROR"
    eye, rays = pixel_rays(camera_view(runner.world.get(held["lens"], Transform).world, LENS_FOV, 0.1, 100.0,
                                       PICTURE), PICTURE)
    t = (SCREEN_AT[2] - eye[2]) / rays[..., 2]
    point = eye + rays * t[..., None]
    screen = (t > 0) & (np.abs(point[..., 0] - SCREEN_AT[0]) < 0.75) & (np.abs(point[..., 1] - SCREEN_AT[1]) < 0.4)
    assert screen.sum() > 100
    box_red = (first[..., 0] > RED[0] / 2) & ~screen
    assert box_red.sum() > 20   # the box beside the screen, in both
    assert first[screen][:, :3].max() < 0.01            # the screen black in the first picture
    assert (second[screen][:, 0] > RED[0] / 4).sum() > 5   # the first picture's box on it in the second


def test_monitors_past_the_limit_wait_a_frame_and_are_drawn_first_the_next(scene):
    """MAX_MONITORS + 2 monitors, all due every frame and the box they watch moving: each
    frame draws MAX_MONITORS, the two left over are said once and counted, and are the first
    drawn the next frame; after two frames every picture has been drawn.  With nothing moving
    the third frame keeps every picture, and cuts none."""
    count = MAX_MONITORS + 2
    build, held = studio(None)

    def many(world):
        build(world)
        held["screens"] = [world.spawn(Transform(position=(i * 0.3, 0.5, 6.0)), MeshRef(quad(0.2, 0.2)),
                                       Material(color=(0, 0, 0, 1)), Monitor(camera=held["lens"], size=(16, 16)))
                           for i in range(count)]

    runner = scene(many, (64, 48))
    box = runner.world.get(held["box"], Transform)
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        runner.frame(DT)
        first = dict(runner.engine.stages["monitors"].drawn)
        assert runner.stats.monitor_views == MAX_MONITORS and runner.stats.monitors_cut == 2
        box.position = box.position + glm.vec3(0.05, 0.0, 0.0)
        runner.frame(DT)
        second = dict(runner.engine.stages["monitors"].drawn)
    assert sum(issubclass(w.category, MonitorLimitWarning) for w in said) == 1
    assert sorted(first) == held["screens"][:MAX_MONITORS]   # the first by entity
    waited = held["screens"][MAX_MONITORS:]
    assert all(second[entity] == second[waited[0]] for entity in waited) and set(second) == set(held["screens"])
    assert runner.stats.monitors_cut == 2 and runner.stats.monitor_views == MAX_MONITORS
    runner.frame(DT)
    assert runner.stats.monitors_cut == 0 and runner.stats.monitor_views == 2   # (the two that waited)
    runner.frame(DT)
    assert (runner.stats.monitors_cut, runner.stats.monitor_views, runner.stats.monitors_kept) == (0, 0, count)


def test_a_monitor_with_no_camera_is_said_once_and_its_picture_goes_with_it(scene):
    """A Monitor naming no camera, or an entity that is not one, is said once (its picture
    black, not drawn); named again it is drawn.  Taken off, its picture is let go (with its
    screen's batch, the texture); put back, it has a new one; given a new size, a new one of
    that size (the old let go); its entity deleted, let go."""
    build, held = studio(Monitor(size=PICTURE, camera=None))

    def nameless(world):
        build(world)
        world.get(held["screen"], Monitor).camera = None

    runner = scene(nameless, (64, 48))
    monitors = runner.engine.renderer.monitors
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        for _ in range(2):
            runner.frame(DT)
        runner.world.get(held["screen"], Monitor).camera = held["box"]
        for _ in range(2):
            runner.frame(DT)
    messages = [str(w.message) for w in said if issubclass(w.category, ComponentWarning)]
    assert sum("names no camera" in m for m in messages) == 1
    assert sum(f"names entity {held['box']}, which has no Camera" in m for m in messages) == 1
    assert runner.stats.monitor_views == 0 and np.abs(picture(runner, held)).max() == 0.0
    runner.world.get(held["screen"], Monitor).camera = held["lens"]
    runner.frame(DT)
    assert runner.stats.monitor_views == 1 and picture(runner, held)[..., 0].max() > RED[0] / 2
    texture = monitors.texture(held["screen"])
    runner.world.remove_component(held["screen"], Monitor)
    runner.frame(DT)
    assert monitors.entities == set()
    assert not _alive(texture)
    runner.world.add_component(held["screen"], Monitor(camera=held["lens"], size=PICTURE))
    runner.frame(DT)
    again = monitors.texture(held["screen"])
    assert again is not texture and _alive(again)
    # A new size: a new picture of it, drawn; the old one let go.
    runner.world.get(held["screen"], Monitor).size = (48, 27)
    runner.frame(DT)
    resized = monitors.texture(held["screen"])
    assert resized.size == (48, 27) and not _alive(again) and picture(runner, held)[..., 0].max() > RED[0] / 2
    again = resized
    runner.world.delete_entity(held["screen"])
    runner.frame(DT)
    assert monitors.entities == set() and not _alive(again)


def _alive(texture) -> bool:
    """Whether a moderngl texture is still a GL object (its release leaves an invalid object)."""
    return type(texture.mglo).__name__ != "InvalidObject"


def test_bad_monitor_values_are_refused_naming_the_field():
    with pytest.raises(ComponentValueError, match="Monitor.size"):
        Monitor(size=(4, 100))
    with pytest.raises(ComponentValueError, match="Monitor.size"):
        Monitor(size=100)
    with pytest.raises(ComponentValueError, match="Monitor.brightness"):
        Monitor(brightness=math.nan)
    with pytest.raises(ComponentValueError, match="Monitor.every"):
        Monitor(every=0)
    with pytest.raises(ComponentValueError, match="Monitor.depth"):
        Monitor(depth=-1)
    with pytest.raises(ComponentValueError, match="Monitor.camera"):
        Monitor(camera=True)
    with pytest.raises(ComponentValueError, match="Monitor.update"):
        Monitor(update="sometimes")


def test_a_level_file_names_a_monitors_camera_by_its_entity(tmp_path):
    """``camera = "lobby"`` in a level file is that entity's id in the world, saved as its name
    again; a name no entity has is refused naming Monitor.camera."""
    text = ('[level]\nname = "cctv"\n\n[[entity]]\nname = "lobby"\n[entity.Transform]\nposition = [0.0, 2.0, 0.0]\n'
            '[entity.Camera]\nactive = false\n\n[[entity]]\nname = "screen"\n[entity.MeshRef]\n'
            'mesh = { quad = [1.6, 0.9] }\n[entity.Monitor]\ncamera = "lobby"\nsize = [320, 180]\nevery = 2\n')
    path = tmp_path / "cctv.toml"
    path.write_text(text)
    world = World("cctv")
    names = load_level(path).spawn(world)
    monitor = world.get(names["screen"], Monitor)
    assert (monitor.camera, monitor.size, monitor.every) == (names["lobby"], (320, 180), 2)
    saved = save_level(world, tmp_path / "again.toml", names, name="cctv")
    assert 'camera = "lobby"' in saved.read_text()
    again = World("cctv again")
    names_again = load_level(saved).spawn(again)
    assert again.get(names_again["screen"], Monitor).camera == names_again["lobby"]
    (tmp_path / "bad.toml").write_text(text.replace('camera = "lobby"', 'camera = "hall"'))
    with pytest.raises(LevelError, match="Monitor.camera"):
        load_level(tmp_path / "bad.toml")
    for w in (world, again):
        w.close()


def test_a_screen_panel_with_a_monitor_shows_its_picture_over_the_frame(scene):
    """A ``ScreenPanel`` with a ``Monitor`` on its entity (a rear-view mirror on the screen) is
    filled with the monitor's picture: where the panel lies each output pixel is the picture's
    texel there (the panel as large as the picture: texel for pixel) times the panel's
    colour, sRGB-encoded; text of a higher order is drawn over it, and with no camera the
    panel keeps its plain colour."""
    from components import ScreenPanel, ScreenText
    from tests.support import linear_to_srgb8

    held = {}
    build, parts = studio(None, eye=(0.0, 1.0, 30.0))   # (the main camera sees black: the box is far off)

    def hud(world):
        build(world)
        held["panel"] = world.spawn(ScreenPanel(size=PICTURE, position=(10, 6), color=(1.0, 0.5, 1.0, 1.0)),
                                    Monitor(camera=parts["lens"], size=PICTURE))
        world.spawn(ScreenText("REAR", position=(14, 8), color=(0.0, 1.0, 0.0, 1.0), order=1))

    runner, rgb = run(scene, hud, 2, size=(160, 120))
    shown = runner.engine.renderer.monitors.read(held["panel"])
    assert shown[..., 0].max() > RED[0] / 2   # the box is in the picture
    expected = linear_to_srgb8(np.clip(shown[..., :3] * np.array([1.0, 0.5, 1.0]), 0.0, 1.0))
    drawn = rgb[6:6 + PICTURE[1], 10:10 + PICTURE[0]].astype(int)
    text = (drawn[..., 1] > 200) & (drawn[..., 0] < 50)
    assert 20 < text.sum() < 400   # the text over it
    ys, xs = np.nonzero(text)
    clear = np.ones(text.shape, bool)
    clear[ys.min() - 2:ys.max() + 3, xs.min() - 2:xs.max() + 3] = False   # (the text's box: its edges blend)
    assert np.abs(drawn[clear] - expected[clear]).max() <= 1
    assert rgb[:6].max() == 0 and rgb[6 + PICTURE[1]:].max() == 0   # the frame about it black
    # With no camera the panel is its colour alone.
    runner.world.get(held["panel"], Monitor).camera = None
    runner.engine.renderer.monitors.drop(held["panel"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plain = runner.frame(DT)
    assert np.abs(plain[40, 60].astype(int) - linear_to_srgb8(np.array([1.0, 0.5, 1.0]))).max() <= 1


@pytest.mark.parametrize("curve, auto", [("aces", False), ("agx", True)])
def test_a_picture_panel_is_exposed_and_tone_mapped_as_the_frame_under_it(scene, curve, auto):
    """With a ``Tonemap`` on the active camera (its curve, a stop up, and in the second case
    automatic exposure), a picture panel's pixels are that curve of picture x colour x the
    frame's exposure (2^1, times 2^EV of the adapted exposure read back, at most 0.5 here),
    sRGB-encoded, within one 8-bit step: the rear view looks as the view does, not as the
    plain clamp would."""
    from components import ScreenPanel
    from components.post import Tonemap
    from tests.support import linear_to_srgb8
    from tests.test_post_processing import CURVES, expected_srgb8

    held = {}
    build, parts = studio(None, eye=(0.0, 1.0, 30.0))
    tint = np.array([1.0, 0.5, 1.0])

    def hud(world):
        build(world)
        world.add_component(active_camera(world),
                            Tonemap(curve=curve, exposure=1.0, auto_exposure=auto, min_ev=-2.0, max_ev=0.5))
        held["panel"] = world.spawn(ScreenPanel(size=PICTURE, position=(10, 6), color=(*tint, 1.0)),
                                    Monitor(camera=parts["lens"], size=PICTURE))

    runner, rgb = run(scene, hud, 3)
    shown = runner.engine.renderer.monitors.read(held["panel"])[..., :3] * tint
    look = runner.engine.renderer.present_pass.look
    scale = 2.0
    if auto:
        ev = float(np.frombuffer(look.exposure_state.read(), np.float32)[0])
        assert 0.05 < ev <= 0.5 + 1e-6   # (a dark frame: the adapted exposure brightens it, up to max_ev)
        scale *= 2.0 ** ev
    else:
        assert look.exposure_state is None
    drawn = rgb[6:6 + PICTURE[1], 10:10 + PICTURE[0]].astype(np.int16)
    expected = expected_srgb8(CURVES[curve](shown * scale))
    assert np.abs(drawn - expected).max() <= 1
    # (and the curve and the exposure each show: without either the pixels are not these)
    assert np.abs(expected - linear_to_srgb8(np.clip(shown * scale, 0.0, 1.0))).max() > 8
    assert np.abs(expected - expected_srgb8(CURVES[curve](shown * scale / (2.0 ** ev if auto else 2.0)))).max() > 5


@pytest.mark.parametrize("table", [False, True], ids=["grade", "grade_and_table"])
def test_a_picture_panel_is_graded_as_the_frame_under_it(scene, table):
    """With a ``ColorGrading`` on the active camera (contrast, slope, saturation; in the second
    case a colour table at half strength too), a picture panel's pixels are the grade of
    picture x colour x exposure (the numpy formula of tests/test_color_grading.py), through
    the curve, encoded, then the table's own CPU lookup mixed in: within one 8-bit step.  The
    panel without the grade is far from that: the rear view is graded as the view is."""
    from components import ColorGrading, ScreenPanel
    from components.post import Tonemap
    from tests.support import linear_to_srgb8
    from tests.test_color_grading import _function_lut, grade
    from tests.test_post_processing import CURVES

    held = {}
    build, parts = studio(None, eye=(0.0, 1.0, 30.0))
    tint = np.array([1.0, 0.5, 1.0])
    controls = dict(contrast=1.3, slope=(1.2, 1.0, 0.8), saturation=0.6)
    lut = _function_lut(9) if table else None

    def hud(world):
        build(world)
        camera = active_camera(world)
        world.add_component(camera, Tonemap(curve="agx", exposure=1.0))
        world.add_component(camera, ColorGrading(**controls, lut=lut, lut_strength=0.5))
        held["panel"] = world.spawn(ScreenPanel(size=PICTURE, position=(10, 6), color=(*tint, 1.0)),
                                    Monitor(camera=parts["lens"], size=PICTURE))

    runner, rgb = run(scene, hud, 3)
    shown = runner.engine.renderer.monitors.read(held["panel"])[..., :3] * tint * 2.0

    def expected_panel() -> np.ndarray:
        encoded = linear_to_srgb8(CURVES["agx"](grade(shown, **controls))) / 255.0
        if table:
            encoded = 0.5 * encoded + 0.5 * np.clip(lut.apply(encoded), 0.0, 1.0)
        return np.rint(np.clip(encoded, 0.0, 1.0) * 255.0)

    drawn = rgb[6:6 + PICTURE[1], 10:10 + PICTURE[0]].astype(np.int16)
    expected = expected_panel()
    assert np.abs(drawn - expected).max() <= 1
    ungraded = np.rint(linear_to_srgb8(CURVES["agx"](shown)))
    assert np.abs(expected - ungraded).max() > 20
    # The grade changed: the panel follows the next frame (its uniforms written again).
    controls["contrast"] = 0.8
    runner.world.get(active_camera(runner.world), ColorGrading).contrast = 0.8
    rgb = runner.frame(DT)
    drawn = rgb[6:6 + PICTURE[1], 10:10 + PICTURE[0]].astype(np.int16)
    assert np.abs(drawn - expected_panel()).max() <= 1 and np.abs(expected_panel() - expected).max() > 5


def test_a_monitor_spends_none_of_the_frames_view_budget(scene):
    """Under a ViewBudget that allows one view, one pixel and no view under a million pixels,
    the monitor's mirror still gets its view (its picture red where the box's image is) and
    the frame's ledger is what it is with no monitor at all: the monitors draw outside it."""
    from dataclasses import asdict

    from engine.frame_stats import BudgetLedger
    from engine.resources import ViewBudget

    ledgers = {}
    for monitored in (True, False):
        build, held = studio(Monitor(size=PICTURE, depth=1) if monitored else None, mirror=True,
                             box_at=np.array([0.5, 1.2, 1.5]), box_half=np.array([0.8, 0.6, 0.3]), bare_screen=True)

        def tight(world, build=build):
            build(world)
            world.resources[ViewBudget] = ViewBudget(views=1, pixels=1, min_pixels=10**6)

        runner, _ = run(scene, tight, 1)
        ledger = asdict(runner.stats)
        ledgers[monitored] = {name: ledger[name] for name in BudgetLedger.__dataclass_fields__}
        if monitored:
            assert runner.stats.monitor_views == 2 and (picture(runner, held)[..., 0] > RED[0] / 2).sum() > 60
    assert ledgers[True] == ledgers[False]


def test_an_exported_scene_holds_a_screens_picture_as_its_emissive_map(scene, tmp_path):
    """``--export-scene`` (``write_scene``) writes a monitor's screen with its picture as it
    stands as its emissive map (sRGB, clamped at white) at its brightness: loaded back with
    the engine's glTF loader, the screen's part emits that image, texel for texel."""
    from engine.assets.mesh import load_model
    from shell.capture import write_scene
    from tests.support import linear_to_srgb8

    build, held = studio(Monitor(size=PICTURE, brightness=1.5))
    runner, _ = run(scene, build, 2)
    shown = picture(runner, held)
    write_scene(runner.engine, tmp_path / "scene.glb", runner.size)
    parts = load_model(tmp_path / "scene.glb")
    emitting = [part for part in parts if part.emissive_map is not None]
    assert len(emitting) == 1
    written = emitting[0].emissive_map.as_8_bits()[..., :3].astype(int)
    assert written.shape == (PICTURE[1], PICTURE[0], 3)
    assert np.abs(written - np.round(linear_to_srgb8(shown[..., :3]))).max() <= 1
    assert (written[..., 0] > 100).sum() > 100   # the box's red in it
    assert emitting[0].emissive_factor == pytest.approx(1.5)


def test_a_mirror_showing_a_screen_keeps_no_stale_picture_while_the_camera_stands_still(scene):
    """A still camera looking into a mirror that shows the screen (its tree kept while nothing
    changes: ``keep_still_views``); the box the monitor watches moves once, and the monitor,
    drawn every second frame, shows it a frame later: every frame equals an engine that draws
    its whole tree (a picture drawn moves the scene on, as any texture written does)."""
    def build_with_mirror(world):
        build(world)
        seen_in_a_mirror(world)

    runners = []
    for _ in range(2):
        build, held = studio(Monitor(size=PICTURE, every=2))
        runners.append((scene(build_with_mirror, (96, 72)), held))
    (keeping, held_k), (drawing, held_d) = runners
    drawing.engine.reflection_system.keep_still_views = False
    for runner, _ in runners:
        exact_visibility(runner)
    kept = 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for frame in range(9):
            if frame == 5:   # (the monitor is drawn on even frames: its picture shows it on the next)
                for runner, held in runners:
                    transform = runner.world.get(held["box"], Transform)
                    transform.position = transform.position + glm.vec3(-1.2, 0.0, 0.0)
            frames = [runner.frame(DT) for runner, _ in runners]
            assert np.array_equal(frames[0], frames[1]), frame
            kept += keeping.stats.reflection_views_kept > 0
    assert drawing.stats.reflection_views_kept == 0
    assert kept >= 3   # (the frames the monitor is not drawn on keep the tree)
    assert (frames[0][..., 0] > 60).sum() > 5   # the box, on the screen, in the mirror


def _monitor_system(runner):
    from systems.monitor_system import MonitorSystem
    return runner.world.get_system(MonitorSystem)


def _keeping_and_drawing(scene, make_build, size=(96, 72)):
    """Two engines of one scene: the first keeps still pictures and views (as a game does), the
    second draws every due picture and its whole tree each frame."""
    runners = []
    for _ in range(2):
        build, held = make_build()
        runners.append((scene(build, size), held))
    drawing = runners[1][0]
    drawing.engine.reflection_system.keep_still_views = False
    _monitor_system(drawing).keep_still_pictures = False
    for runner, _ in runners:   # (exact, so the frames to the first keep are a GPU's too: its "auto" predicts)
        exact_visibility(runner)
    return runners


def exact_visibility(runner) -> None:
    """The main tree's and the monitors' trees' visibility exact."""
    runner.engine.reflection_system.visibility = "exact"
    runner.engine.renderer.monitors.visibility = "exact"


def test_a_still_monitor_keeps_its_picture_and_the_mirror_showing_it_keeps_its_view(scene):
    """A still camera looking into a mirror that shows the screen; the lens still, the box it
    watches moved on one frame and the lens turned on another.  The picture is drawn on the
    first frame and on those two alone (kept, ``monitors_kept``, on the others), and the
    mirror's view is kept on the frames after; every frame and picture equals an engine that
    draws every picture and its whole tree each frame."""
    def make_build():
        build, held = studio(Monitor(size=PICTURE))

        def with_mirror(world):
            build(world)
            seen_in_a_mirror(world)
        return with_mirror, held

    runners = _keeping_and_drawing(scene, make_build)
    keeping = runners[0][0]
    drawn, kept, views_kept = [], [], []
    for frame in range(12):
        for runner, held in runners:
            if frame == 5:
                transform = runner.world.get(held["box"], Transform)
                transform.position = transform.position + glm.vec3(-1.2, 0.0, 0.0)
            if frame == 9:
                transform = runner.world.get(held["lens"], Transform)
                transform.rotation = look_rotation(glm.vec3(0.1, 0.0, -1.0))
        frames = [runner.frame(DT) for runner, _ in runners]
        assert np.array_equal(frames[0], frames[1]), frame
        assert np.array_equal(picture(*runners[0]), picture(*runners[1])), frame
        drawn.append(keeping.stats.monitor_views)
        kept.append(keeping.stats.monitors_kept)
        views_kept.append(keeping.stats.reflection_views_kept)
    assert drawn == [1, 0, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0]
    assert kept == [1 - count for count in drawn]
    from shell.overlay_text import overlay_lines
    assert "monitors: views 0, pictures kept 1, unseen 0" in overlay_lines(keeping.engine, [0.016])
    assert all(views_kept[frame] > 0 for frame in (1, 2, 3, 4, 6, 7, 8, 10, 11))
    assert not any(views_kept[frame] for frame in (0, 5, 9))
    assert runners[1][0].stats.monitors_kept == 0 and runners[1][0].stats.monitor_views == 1
    assert (frames[0][..., 0] > 60).sum() > 5   # the box, on the screen, in the mirror


def test_a_monitor_watching_another_draws_again_once_the_other_changed(scene):
    """Monitor A's camera sees monitor B's screen (and the box), B's sees the box; A is drawn
    before B.  The first frame draws A (B's screen black) then B; the second draws A again
    (B's picture changed after A drew it) and keeps B; the next keep both, until the box
    moves: both draw, and A again the frame after.  Every frame and picture equals an engine
    that draws every one."""
    def make_build():
        build, held = studio(Monitor(size=PICTURE))

        def two(world):
            spawn_watcher(world, held)
            build(world)
        return two, held

    runners = _keeping_and_drawing(scene, make_build, (64, 48))
    (keeping, held), (drawing, held_d) = runners
    assert held["watcher"] < held["screen"]   # (drawn first: the lower entity, when both wait as long)
    drawn, kept = [], []
    for frame in range(7):
        if frame == 4:
            for runner, each in runners:
                transform = runner.world.get(each["box"], Transform)
                transform.position = transform.position + glm.vec3(-0.6, 0.0, 0.0)
        frames = [runner.frame(DT) for runner, _ in runners]
        assert np.array_equal(frames[0], frames[1]), frame
        for name in ("screen", "watcher"):
            assert np.array_equal(keeping.engine.renderer.monitors.read(held[name]),
                                  drawing.engine.renderer.monitors.read(held_d[name])), (frame, name)
        drawn.append(keeping.stats.monitor_views)
        kept.append(keeping.stats.monitors_kept)
    assert drawn == [2, 1, 0, 0, 2, 1, 0]
    assert kept == [0, 1, 2, 2, 0, 1, 2]
    watched = keeping.engine.renderer.monitors.read(held["watcher"])
    assert (watched[..., 0] > RED[0] / 4).sum() > 10   # B's picture of the box, on B's screen (hiding the box)


def test_a_still_picture_drawn_on_predicted_counts_is_drawn_once_more_exactly_then_kept(scene):
    """Predicted visibility (a GPU's "auto"): a still picture whose tree was drawn on its last
    drawing's counts is not kept (the counts may not be its own) but drawn once more with exact
    counts, and kept from then on; at depth 0 (no tree) it is kept at once.  Every frame
    equals an engine that draws every picture on predicted counts."""
    def make_build(depth):
        def make():
            build, held = studio(Monitor(size=PICTURE, depth=depth), mirror=True,
                                 box_at=np.array([0.5, 1.2, 1.5]), box_half=np.array([0.8, 0.6, 0.3]))

            def aside(world):   # (the screen far to the side: out of the mirror's view, so not its own input)
                build(world)
                world.get(held["screen"], Transform).position = (30.0, 1.0, 6.0)
            return aside, held
        return make

    for depth, kept in ((1, [0, 0, 1, 1]), (0, [0, 1, 1, 1])):
        runners = _keeping_and_drawing(scene, make_build(depth), (64, 48))
        for runner, _ in runners:
            runner.engine.renderer.monitors.visibility = "predicted"
        seen = []
        for frame in range(4):
            frames = [runner.frame(DT) for runner, _ in runners]
            assert np.array_equal(frames[0], frames[1]), (depth, frame)
            assert np.array_equal(picture(*runners[0]), picture(*runners[1])), (depth, frame)
            seen.append(runners[0][0].stats.monitors_kept)
        assert seen == kept, depth


@pytest.mark.parametrize("double_sided, scale, in_front, kept", [
    (False, (1, 1, 1), True, False), (False, (1, 1, 1), False, True), (True, (1, 1, 1), False, False),
    (False, (-1, 1, 1), True, False), (False, (-1, 1, 1), False, True),
    (False, (1, 1, -1), True, True), (False, (1, 1, -1), False, False)])
def test_a_camera_behind_its_own_one_sided_screen_keeps_its_picture(scene, double_sided, scale, in_front, kept):
    """The lens looking at its own screen (facing +z), from in front (+z) or from behind: from
    behind a one-sided screen shows it nothing of the picture (its faces culled), so the
    picture is not its own input and is kept after the first frame; in front, or behind a
    double-sided one, it is drawn every frame.  Mirrored by a scale of -1 on x it faces the
    same way; by -1 on z (its corners where they were, its winding turned) it faces -z.
    Every frame and picture equals an engine that draws every picture."""
    def make_build():
        build, held = studio(Monitor(size=PICTURE))

        def placed(world):
            build(world)
            facing_own_screen(world, held, in_front)
            if double_sided:
                world.get(held["screen"], Material).double_sided = True
            world.get(held["screen"], Transform).scale = tuple(map(float, scale))
        return placed, held

    runners = _keeping_and_drawing(scene, make_build, (64, 48))
    keeping, held = runners[0]
    seen, pictures = [], []
    for frame in range(4):
        frames = [runner.frame(DT) for runner, _ in runners]
        assert np.array_equal(frames[0], frames[1]), frame
        pictures.append(picture(*runners[0]))
        assert np.array_equal(pictures[-1], picture(*runners[1])), frame
        seen.append(keeping.stats.monitors_kept)
    assert seen == ([0, 1, 1, 1] if kept else [0, 0, 0, 0])
    assert (pictures[-1][..., 0] > RED[0] / 2).sum() > 20   # (the box in sight)
    # (drawn every frame, its screen in its picture: a picture in a picture, a level deeper each time)
    assert kept or not np.array_equal(pictures[1], pictures[2])


def test_only_a_flat_mesh_wound_one_way_has_one_face():
    """``flat_face``: a quad faces +z (its winding's way); a box, a quad bent out of its plane
    and a quad with one triangle turned over have no one face."""
    from systems.monitor_system import flat_face

    square = quad(1.0, 1.0)
    point, normal = flat_face(square.positions, square.indices)
    assert np.allclose(normal, (0.0, 0.0, 1.0)) and abs(point[2]) < 1e-9
    cube = box((1.0, 1.0, 1.0))
    assert flat_face(cube.positions, cube.indices) is False
    bent = square.positions.copy()
    bent[2, 2] = 0.1
    assert flat_face(bent, square.indices) is False
    turned = square.indices.copy()
    turned[1] = turned[1][::-1]
    assert flat_face(square.positions, turned) is False



def _moving_box(runners) -> None:
    """The box each monitor watches moved a little (so a picture drawn differs from the last)."""
    for runner, held in runners:
        transform = runner.world.get(held["box"], Transform)
        transform.position = transform.position + glm.vec3(0.03, 0.0, 0.0)


def test_a_monitor_drawn_when_seen_is_drawn_from_the_frame_the_camera_turns_to_it(scene):
    """``update="when_seen"``: while the camera looks away from the screen the picture is not
    drawn (``monitors_unseen``), though the box it watches moves; on the frame the camera turns
    to it, it is drawn (this frame's main view sees it), and every frame equals an engine whose
    monitor is drawn always."""
    def make_build(update):
        def make():
            build, held = studio(Monitor(size=PICTURE, update=update))

            def away(world):
                build(world)
                held["camera"] = camera = active_camera(world)
                world.get(camera, Transform).rotation = look_rotation(glm.vec3(1.0, 0.0, 0.0))
            return away, held
        return make

    runners = []
    for update in ("when_seen", "always"):
        build, held = make_build(update)()
        runners.append((scene(build, (64, 48)), held))
    seeing, always = runners[0][0], runners[1][0]
    drawn, unseen = [], []
    for frame in range(6):
        _moving_box(runners)
        if frame == 3:
            for runner, held in runners:
                runner.world.get(held["camera"], Transform).rotation = \
                    look_rotation(glm.vec3(SCREEN_AT) - glm.vec3(0.0, 1.0, 7.5))
        frames = [runner.frame(DT) for runner, _ in runners]
        assert np.array_equal(frames[0], frames[1]), frame
        drawn.append(seeing.stats.monitor_views)
        unseen.append(seeing.stats.monitors_unseen)
        assert always.stats.monitor_views == 1
    assert drawn == [0, 0, 0, 1, 1, 1] and unseen == [1, 1, 1, 0, 0, 0]
    assert (frames[0][..., 0] > 60).sum() > 5   # the box, on the screen
    from shell.overlay_text import overlay_lines
    runners[0][0].world.get(runners[0][1]["camera"], Transform).rotation = look_rotation(glm.vec3(1.0, 0.0, 0.0))
    seeing.frame(DT)
    assert "monitors: views 0, pictures kept 0, unseen 1" in overlay_lines(seeing.engine, [0.016])


def test_a_monitor_drawn_when_seen_through_a_mirror_is_drawn_from_the_first_frame(scene):
    """The screen seen only in a mirror behind it: from the first frame the camera carried
    through the mirror (this frame's first level, worked out before the reflect stage plans
    it: ``MonitorSystem._first_level``) sees it, so it is drawn each frame, every frame equal
    to an engine whose monitor is drawn always.  The mirror turned away, so that its view
    shows no screen, it is not drawn.  On a screen panel it is always seen."""
    def make_build(update):
        def make():
            build, held = studio(Monitor(size=PICTURE, update=update))

            def mirrored(world):
                build(world)
                seen_in_a_mirror(world)
            return mirrored, held
        return make

    runners = []
    for update in ("when_seen", "always"):
        build, held = make_build(update)()
        runners.append((scene(build, (96, 72)), held))
    seeing = runners[0][0]
    drawn, same = [], []
    for _ in range(4):
        _moving_box(runners)
        frames = [runner.frame(DT) for runner, _ in runners]
        same.append(np.array_equal(frames[0], frames[1]))
        drawn.append(seeing.stats.monitor_views)
    assert drawn == [1, 1, 1, 1] and same == [True, True, True, True]
    assert (frames[0][..., 0] > 60).sum() > 5   # the box, on the screen, in the mirror
    build, held = make_build("when_seen")()

    def turned(world):
        build(world)
        mirror = next(entity for entity, _ in world.query_one(Mirror))
        world.get(mirror, Transform).rotation = look_rotation(glm.vec3(np.sin(1.3), 0.0, np.cos(1.3)))

    away = scene(turned, (96, 72))
    for _ in range(2):
        away.frame(DT)
        assert away.stats.monitor_views == 0 and away.stats.monitors_unseen == 1
    from components import ScreenPanel

    held = {}
    build, parts = studio(None, eye=(0.0, 1.0, 30.0))

    def hud(world):
        build(world)
        held["panel"] = world.spawn(ScreenPanel(size=PICTURE, position=(10, 6)),
                                    Monitor(camera=parts["lens"], size=PICTURE, update="when_seen"))

    runner, _ = run(scene, hud, 1)
    assert runner.stats.monitor_views == 1 and runner.stats.monitors_unseen == 0


def test_a_monitor_drawn_when_seen_through_a_portal_is_drawn_from_the_first_frame(scene):
    """The screen seen only through a portal: the active camera, far off, looks into portal
    A, whose partner B stands behind the screen facing it.  From the first frame (no view of
    the frame before to see it by) the camera carried through the pair
    (``MonitorSystem._first_level``) sees the screen, so it is drawn every frame, each frame
    equal to an engine whose monitor is drawn always, the box on the screen through the
    portal; with B turned away from the screen it is not drawn."""
    from engine.assets.portals import spawn_portal_pair
    from tests.support import look_from

    def make_build(update, b_turn=np.pi):
        build, held = studio(Monitor(size=PICTURE, update=update))

        def through(world):
            build(world)
            world.delete_entity(active_camera(world))
            look_from(world, (20.0, 1.0, 2.0), target=(20.0, 1.0, 0.0), fov=50.0)
            held["a"], held["b"] = spawn_portal_pair(world, (20.0, 1.0, 0.0), None, (0.0, 1.0, 8.5),
                                                     glm.angleAxis(float(b_turn), glm.vec3(0, 1, 0)), size=(2.0, 1.5))
        return through, held

    runners = []
    for update in ("when_seen", "always"):
        build, held = make_build(update)
        runners.append((scene(build, (96, 72)), held))
    seeing = runners[0][0]
    drawn, same = [], []
    for _ in range(4):
        _moving_box(runners)
        frames = [runner.frame(DT) for runner, _ in runners]
        same.append(np.array_equal(frames[0], frames[1]))
        drawn.append(seeing.stats.monitor_views)
    assert seeing.stats.reflection_views >= 1
    assert drawn == [1, 1, 1, 1] and same == [True, True, True, True], (drawn, same)
    assert (frames[0][..., 0] > 60).sum() > 5   # the box, on the screen, through the portal
    build, _ = make_build("when_seen", b_turn=np.pi / 2)   # (B looks along +x: no screen there)
    away = scene(build, (96, 72))
    for _ in range(2):
        away.frame(DT)
        assert away.stats.monitor_views == 0 and away.stats.monitors_unseen == 1


def test_a_monitor_drawn_when_seen_by_another_monitor_is_drawn(scene):
    """Monitor B (``when_seen``) is seen by monitor A's camera alone (the active camera looks
    away): A, the lower entity, is drawn first each frame, and its view (its last drawing's)
    sees B's screen, so B is drawn each frame too; and with B's picture in A's."""
    build, held = studio(Monitor(size=PICTURE, update="when_seen"))

    def watched(world):
        spawn_watcher(world, held)
        build(world)
        world.get(active_camera(world), Transform).rotation = look_rotation(glm.vec3(1.0, 0.0, -0.2))

    runner = scene(watched, (64, 48))
    drawn, unseen = [], []
    for _ in range(3):
        _moving_box([(runner, held)])
        runner.frame(DT)
        drawn.append(runner.stats.monitor_views)
        unseen.append(runner.stats.monitors_unseen)
    assert drawn == [2, 2, 2] and unseen == [0, 0, 0]
    watched_picture = runner.engine.renderer.monitors.read(held["watcher"])
    assert (watched_picture[..., 0] > RED[0] / 4).sum() > 10   # B's picture of the box, on B's screen


def test_a_monitor_drawn_when_seen_that_only_its_own_camera_sees_is_not_drawn(scene):
    """The lens looks at its own screen (``when_seen``): drawn while the active camera sees
    the screen too; once the camera turns away, only the picture's own view sees it, which
    counts for nothing (nobody sees that picture), so it is not drawn."""
    build, held = studio(Monitor(size=PICTURE, update="when_seen"))

    def own(world):
        build(world)
        facing_own_screen(world, held)
        held["camera"] = active_camera(world)

    runner = scene(own, (64, 48))
    drawn, unseen = [], []
    for frame in range(4):
        if frame == 2:
            runner.world.get(held["camera"], Transform).rotation = look_rotation(glm.vec3(1.0, 0.0, 0.0))
        runner.frame(DT)
        drawn.append(runner.stats.monitor_views)
        unseen.append(runner.stats.monitors_unseen)
    assert drawn == [1, 1, 0, 0] and unseen == [0, 0, 1, 1]


def _towards_screen() -> int:
    """The cube face of a probe before the screen that looks at it (-z)."""
    from engine.core.cube_faces import CUBE_FACES

    return next(face for face, (forward, _, _) in enumerate(CUBE_FACES) if tuple(forward) == (0, 0, -1))


def _probe_before_an_unseen_screen(scene, refresh: str) -> list[tuple]:
    """Two engines, (runner, held) each, the screen's monitor "when_seen" in the first and
    "always" in the second: the active camera turned away from the screen, and a probe
    (``refresh``, 32 texels) 1 m before it (``held["probe"]``)."""
    from components import ReflectionProbe

    runners = []
    for update in ("when_seen", "always"):
        build, held = studio(Monitor(size=PICTURE, update=update))

        def probed(world, build=build, held=held):
            build(world)
            world.get(active_camera(world), Transform).rotation = look_rotation(glm.vec3(1.0, 0.0, 0.0))
            held["probe"] = world.spawn(Transform(position=(0.0, 1.0, 7.0)),
                                        ReflectionProbe(resolution=32, refresh=refresh))
        runners.append((scene(probed, (64, 48)), held))
    return runners


@pytest.mark.parametrize("gpu_ms", [(5.0, 0.1), (0.1, 5.0)], ids=["parts_when_seen", "parts_always"])
def test_a_monitor_drawn_when_seen_by_a_probes_recapture_is_drawn_for_it(scene, gpu_ms):
    """The active camera looks away from the screen, but a probe recaptured every frame stands
    before it (what a chrome ball by the screen reflects): its faces recaptured after the
    frame's present (``ProbeSchedule``'s undrawn faces) see the screen, so a ``when_seen``
    picture is drawn for them, and the probe's face towards the screen equals that of an
    engine whose monitor is drawn always, frame by frame, as the box it watches moves.  (On
    the first frame the probe's first capture, drawn before the monitors, shows it black in
    both, but sees it: the picture is drawn for it too.)  One engine's host draws faces in
    part (its GPU took longer over the timed captures than issuing them:
    ``ProbePaths.fill_bound``), the other's does not, as two runs' timings may say: the faces
    are the same (a face showing a picture drawn since is drawn whole)."""
    from tests.test_probe_keeping import _probe_stage

    towards_screen = _towards_screen()
    runners = _probe_before_an_unseen_screen(scene, "every_frame")
    for (runner, _), gpu in zip(runners, gpu_ms, strict=True):
        _probe_stage(runner).path = "six_pass"   # (nothing timed: the timings below stand)
        paths = runner.engine.renderer.probes.paths
        paths.samples, paths.thread_ms = {"six_pass": [(gpu, 6.0)] * 3}, {"six_pass": [1.0] * 3}
    assert [runner.engine.renderer.probes.paths.fill_bound for runner, _ in runners] == [gpu > 1.0 for gpu in gpu_ms]
    seeing = runners[0][0]
    drawn, unseen = [], []
    for frame in range(5):
        _moving_box(runners)
        for runner, _ in runners:
            runner.frame(DT)
        faces = [runner.engine.renderer.probes.read_face(held["probe"], towards_screen) for runner, held in runners]
        np.testing.assert_array_equal(faces[0], faces[1], err_msg=f"frame {frame}")
        drawn.append(seeing.stats.monitor_views)
        unseen.append(seeing.stats.monitors_unseen)
    assert drawn == [1, 1, 1, 1, 1] and unseen == [0, 0, 0, 0, 0]
    assert (faces[1][..., 0] > 0.1).sum() > 5   # the red box, on the screen, in the probe's face


@pytest.mark.parametrize("refresh", ["every_frame", "on_change"])
@pytest.mark.parametrize("box_in_probes", [True, False], ids=["box_seen", "box_hidden_from_probes"])
def test_a_probe_face_showing_a_screen_shows_the_picture_drawn_since(scene, refresh, box_in_probes):
    """A probe before the screen, on a host that draws faces in part (the six-pass path,
    nothing timed): the box the monitor watches moves, so the picture is drawn again every
    other frame (``every=2``), and a face showing the screen is then no longer what it was
    drawn with, though the scheduler, which runs before the monitors, knows only of the
    drawing a frame before.  No change the
    probe's scheduler follows need reach the screen's part of the face (the box may move
    elsewhere in it, or be hidden from probes): the face is neither kept nor drawn in part
    where the picture it shows was drawn since (``ProbeCaptures._keep_plan``), so an
    ``every_frame`` probe's cube is, bit for bit, a capture of all six drawn whole, every
    frame.  An ``on_change`` probe recaptures the faces that see a screen whose picture was
    drawn (``PicturesDrawn``, the scheduler's next update): once the box stands still, its
    cube is too, and then it draws nothing."""
    from components import ReflectionProbe, Visibility
    from tests.test_probe_keeping import _Cube, _probe_stage

    towards_screen = _towards_screen()
    build, held = studio(Monitor(size=PICTURE, every=2))

    def probed(world):
        build(world)
        if not box_in_probes:
            world.add_component(held["box"], Visibility(in_probes=False))
        world.resources["probe"] = held["probe"] = world.spawn(
            Transform(position=(0.0, 1.0, 7.0)), ReflectionProbe(resolution=32, refresh=refresh))

    runner = scene(probed, (64, 48))
    _probe_stage(runner).path = "six_pass"
    cube = _Cube(runner)
    runner.frame(DT)
    first = cube.probes.read_face(held["probe"], towards_screen).copy()
    for _ in range(4):
        _moving_box([(runner, held)])
        runner.frame(DT)
        if refresh == "every_frame":
            assert cube.as_if_drawn_whole()
    for _ in range(4):   # the box stands still (the last frame one the monitor is due on)
        runner.frame(DT)
    if refresh == "on_change":
        # Still: the picture is kept and the probe draws nothing (the screen recaptured once
        # after its last drawing, and the picture drawn again for that capture alone is no
        # new look of the screen's: no loop).
        assert runner.stats.monitors_kept == 1 and runner.stats.probe_faces == 0
    assert not np.array_equal(cube.probes.read_face(held["probe"], towards_screen), first)
    assert cube.as_if_drawn_whole()


def test_a_monitors_camera_draws_its_picture_through_its_own_fog(scene):
    """A monitor whose camera has a ``Fog`` of its own draws its picture through that fog, not
    the active camera's (none, or another); a camera without one takes the active camera's
    (the frame's).  The picture equals the one drawn where the active camera has that fog and
    the lens none, differs from the one drawn with no fog anywhere, and the frame's own fog
    is given back after it (the Fog block holds the active camera's).  With the frame's fog
    turned off (the overlay's toggle), no picture has any."""
    from components import Fog

    def thick():
        return Fog(color=(0.1, 0.2, 0.6), density=0.25)

    def thin():
        return Fog(color=(0.6, 0.2, 0.1), density=0.1)

    def picture(lens_fog, eye_fog, shown=True):
        build, held = studio(Monitor(size=PICTURE))

        def fogged(world):
            build(world)
            if lens_fog is not None:
                world.add_component(held["lens"], lens_fog())
            if eye_fog is not None:
                world.add_component(active_camera(world), eye_fog())

        runner = scene(fogged, (64, 48))
        runner.engine.stages["prepare"].fog = shown
        runner.frame(DT)
        return runner, runner.engine.renderer.monitors.read(held["screen"])

    own_runner, own = picture(thick, None)
    _, inherited = picture(None, thick)
    over_runner, over = picture(thick, thin)
    _, bare = picture(None, None)
    np.testing.assert_array_equal(own, inherited)
    np.testing.assert_array_equal(over, inherited)
    assert np.abs(own - bare).max() > 0.05
    assert own_runner.engine.renderer.fog.block[4] == 0.0            # the active camera has none
    assert over_runner.engine.renderer.fog.block[4] == np.float32(0.1)   # ... and here the thin one
    _, hidden = picture(thick, thin, shown=False)
    np.testing.assert_array_equal(hidden, bare)


def test_an_unseen_monitor_seen_by_a_probes_first_capture_is_drawn_and_the_probe_shows_it(scene):
    """The active camera looks away from a ``when_seen`` screen; an ``on_change`` probe stands
    before it.  Its first capture (drawn before the monitors: the screen still black) sees the
    screen, so the picture is drawn that frame, and the faces that show the screen are asked
    for again the next (``PicturesDrawn``): from then on the probe's face towards the screen
    equals that of an engine whose monitor is drawn always, and shows the red box."""
    towards_screen = _towards_screen()
    runners = _probe_before_an_unseen_screen(scene, "on_change")
    drawn = []
    for frame in range(3):
        for runner, _ in runners:
            runner.frame(DT)
        drawn.append(runners[0][0].stats.monitor_views)
        faces = [runner.engine.renderer.probes.read_face(held["probe"], towards_screen) for runner, held in runners]
        if frame:
            np.testing.assert_array_equal(faces[0], faces[1], err_msg=f"frame {frame}")
    assert drawn[0] == 1 and drawn[2] == 0   # drawn for the first capture; not once nothing sees it
    assert (faces[0][..., 0] > 0.1).sum() > 5   # the red box, on the screen, in the probe's face


@pytest.mark.parametrize("refresh", ["once", "scripted"])
@pytest.mark.parametrize("update", ["when_seen", "always"])
def test_a_probe_captured_before_a_screens_first_picture_is_drawn_again_for_it(scene, refresh, update):
    """A ``once`` (or ``scripted``) probe stands before a screen the active camera does not see.
    Its first capture, on the first frame, is drawn before the monitors: the screen black in
    it (a ``when_seen`` picture is drawn then because the capture sees it).  The next frame the
    faces that may see the screen are drawn again ("first picture: entity N",
    ``PicturesDrawn.first``): the face towards the screen equals the first capture of a probe
    made only after the picture was drawn (in an engine whose monitor is drawn always), and
    shows the red box; after that the probe draws nothing more, as its mode says."""
    from components import ReflectionProbe
    from engine.rules.probe_schedule import ProbeSchedule

    towards_screen = _towards_screen()
    runs = []
    for late in (False, True):
        build, held = studio(Monitor(size=PICTURE, update="always" if late else update))

        def probed(world, build=build, held=held, late=late):
            build(world)
            world.get(active_camera(world), Transform).rotation = look_rotation(glm.vec3(1.0, 0.0, 0.0))
            if not late:
                held["probe"] = world.spawn(Transform(position=(0.0, 1.0, 7.0)),
                                            ReflectionProbe(resolution=32, refresh=refresh))
        runs.append((scene(probed, (64, 48)), held))
    (runner, held), (late_runner, late_held) = runs
    for run, _ in runs:
        run.frame(DT)
    early = runner.engine.renderer.probes.read_face(held["probe"], towards_screen)
    assert (early[..., 0] > 0.1).sum() == 0   # the screen black: its picture came after the capture
    late_held["probe"] = late_runner.world.spawn(Transform(position=(0.0, 1.0, 7.0)),
                                                 ReflectionProbe(resolution=32, refresh=refresh))
    for run, _ in runs:
        run.frame(DT)
    due = runner.world.resources[ProbeSchedule].due[held["probe"]]
    assert towards_screen in due.reasons[f"first picture: entity {held['screen']}"]
    assert not due.first and due.faces != frozenset(range(6))   # (only the faces that may see the screen)
    face = runner.engine.renderer.probes.read_face(held["probe"], towards_screen)
    np.testing.assert_array_equal(face, late_runner.engine.renderer.probes.read_face(late_held["probe"],
                                                                                     towards_screen))
    assert (face[..., 0] > 0.1).sum() > 5   # the red box, on the screen, in the probe's face
    for _ in range(2):
        runner.frame(DT)
        assert runner.stats.probe_faces == 0


def test_a_kept_picture_is_drawn_again_when_its_cameras_own_fog_changes(scene):
    """A still picture is kept frame after frame; its camera's own ``Fog`` thickened (a write
    no upload follows: only the key's count of the world's changes sees it) draws it again,
    equal to a fresh engine's picture through the thicker fog, and it is kept again after."""
    from components import Fog

    def build_with(density):
        build, held = studio(Monitor(size=PICTURE))

        def fogged(world):
            build(world)
            world.add_component(held["lens"], Fog(color=(0.1, 0.2, 0.6), density=density))
        return fogged, held

    build, held = build_with(0.05)
    runner = scene(build, (64, 48))
    for _ in range(3):
        runner.frame(DT)
    assert runner.stats.monitors_kept == 1
    runner.world.get(held["lens"], Fog).density = 0.3
    runner.frame(DT)
    assert runner.stats.monitors_kept == 0 and runner.stats.monitor_views == 1
    fresh_build, fresh_held = build_with(0.3)
    fresh = scene(fresh_build, (64, 48))
    fresh.frame(DT)
    np.testing.assert_array_equal(runner.engine.renderer.monitors.read(held["screen"]),
                                  fresh.engine.renderer.monitors.read(fresh_held["screen"]))
    runner.frame(DT)
    assert runner.stats.monitors_kept == 1


def test_two_monitors_cameras_far_apart_each_read_the_sharp_shadow_of_their_own_rings(scene):
    """Two monitors' cameras, each 39 m from the active camera and 78 m from the other, each
    looking at a box's shadow as the camera looks at its own: each picture's shadow agrees
    with float64 shadow rays cast from its own floor points (a few millimetres from the
    box's outline: only a ring about that camera resolves it; the level's map and the other
    camera's rings cannot), and so does the frame: the rings read while each picture is
    drawn are its own camera's (``ShadowMaps.swap_ring_rows``), put back for the next."""
    from components import DirectionalLight
    from tests.test_shadow_cascades import BOX_CENTRE, BOX_HALF, EYE, TARGET, _agreement, _build

    offsets = [np.array([30.0, 0.0, 25.0]), np.array([-30.0, 0.0, -25.0])]
    size = (320, 216)

    def build(world):
        _build(3)(world)
        ids = world.resources["ids"]
        ids["lenses"], ids["screens"] = [], []
        for k, off in enumerate(offsets):
            eye, target = glm.vec3(*(np.array(EYE) + off)), glm.vec3(*(np.array(TARGET) + off))
            lens = world.spawn(Transform(position=eye, rotation=look_rotation(target - eye)),
                               Camera(fov_y=60.0, active=False))
            world.spawn(Transform(position=list(BOX_CENTRE + off)), MeshRef(box()), Material(color=(0.8, 0.3, 0.2)))
            ids["screens"].append(world.spawn(Transform(position=(2.0 * k, 1.6, 6.0)), MeshRef(quad(1.6, 1.0)),
                                              Material(), Monitor(camera=lens, size=size)))
            ids["lenses"].append(lens)

    runner = scene(build, (96, 64))
    runner.engine.renderer.antialias = "off"
    ids = runner.world.resources["ids"]
    sun = runner.world.get(ids["sun"], DirectionalLight)
    sun.shadows = False
    frame_without = runner.frame()
    without = [picture(runner, {"screen": screen}).copy() for screen in ids["screens"]]
    sun.shadows = True
    frame_with = runner.frame()
    assert runner.stats.monitor_views == 2 and runner.stats.picture_cascades_cut == 0
    for k, (lens, screen) in enumerate(zip(ids["lenses"], ids["screens"], strict=True)):
        # The floor point each picture pixel shows, where its ray meets the floor before the box.
        eye, rays = pixel_rays(camera_view(runner.world.get(lens, Transform).world, 60.0, 0.1, 100.0, size), size)
        rays = rays.reshape(-1, 3)
        boxed = box_hits(np.tile(eye, (len(rays), 1)), rays, BOX_CENTRE + offsets[k], BOX_HALF + 0.02)
        points = eye + rays * (-eye[1] / rays[:, 1])[:, None]
        floor = ((rays[:, 1] < 0.0) & ~boxed).reshape(size[1], size[0])
        shown = picture(runner, {"screen": screen})
        share, counted, in_shadow = _agreement(runner, shown, without[k], points, floor, BOX_CENTRE + offsets[k],
                                               linear=True)
        assert counted > 400 and in_shadow > 150, (k, counted, in_shadow)   # a real floor, a real shadow
        assert share >= 0.99, (k, share)
    assert _agreement(runner, frame_with, frame_without)[0] >= 0.99


def test_a_monitor_cameras_tone_curve_and_lens_effects_are_said_once_to_do_nothing_in_its_picture(scene):
    """A Bloom and a Vignette on the camera a monitor shows (not the active one) do nothing in
    its picture (it has no post-processing of its own: the frame's apply to it as to any
    light): said once, naming both, the camera and the monitor, over frames; the picture is
    texel for texel the one drawn without them.  Made the active camera, it is not said again
    (they work there); a monitor camera with none is not said."""
    from components import Bloom, Vignette

    def with_lens_effects(effects):
        build, held = studio(Monitor(size=PICTURE))

        def make(world):
            build(world)
            for effect in effects:
                world.add_component(held["lens"], effect)
        return make, held

    plain_build, plain_held = with_lens_effects(())
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        plain, _ = run(scene, plain_build, 2)
    assert not [w for w in said if "camera of the Monitor" in str(w.message)]
    build, held = with_lens_effects((Bloom(), Vignette()))
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        runner, _ = run(scene, build, 3)
    messages = [str(w.message) for w in said if issubclass(w.category, ComponentWarning)
                and "camera of the Monitor" in str(w.message)]
    assert messages == [f"Bloom, Vignette on entity {held['lens']}, the camera of the Monitor on entity "
                        f"{held['screen']}: a monitor's picture has no tone curve, grade or lens effects of its own "
                        "(the frame's apply to it as to any light), so they do nothing there (it works while that "
                        "camera is the active one)"], messages
    drawn = picture(runner, held)
    assert drawn[..., 0].max() > RED[0] / 2   # (the box is in it)
    np.testing.assert_array_equal(drawn, picture(plain, plain_held))
    world = runner.world
    world.get(active_camera(world), Camera).active = False
    world.get(held["lens"], Camera).active = True
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        runner.frame(DT)
        world.remove_component(held["lens"], Vignette)
        runner.frame(DT)
    assert active_camera(world) == held["lens"]
    assert not [w for w in said if "camera of the Monitor" in str(w.message)]


STRETCH = (0.8, 0.0, 0.2)   # where a skinned screen's joint carries its right edge (right, and towards +z)


def _skinned_screen(world, held, by_hand: bool = False) -> None:
    """The studio's screen re-meshed as a quad whose right edge's two corners ride a second
    joint that carries them by ``STRETCH`` (``Skin``: the screen half as wide again and bent,
    its two triangles no longer in one plane); ``by_hand``: the same shape modelled so, the
    corners moved in the mesh itself, with no skin."""
    from components import Skin
    from engine.assets.mesh import Mesh

    flat = quad(*SCREEN_SIZE)
    positions = np.asarray(flat.positions, np.float32)
    right = (positions[:, 0] > 0).astype(np.uint16)   # (corners 1 and 2)
    triangles = np.asarray(flat.indices).reshape(-1, 3)
    if by_hand:
        moved = positions + right[:, None] * np.asarray(STRETCH, np.float32)
        world.get(held["screen"], MeshRef).mesh = Mesh(moved, flat.normals, flat.uvs, triangles, name="bent screen")
        return
    joints = np.stack([np.eye(4), np.eye(4)])
    joints[1, :3, 3] = STRETCH   # (points as columns: M @ (x, y, z, 1))
    world.get(held["screen"], MeshRef).mesh = Mesh(positions, flat.normals, flat.uvs, triangles, name="skinned screen",
                                                    joints=np.stack([right, 0 * right], axis=1),
                                                    weights=np.tile([1.0, 0.0], (len(right), 1)))
    world.add_component(held["screen"], Skin(joints))


def _posed_screen_uvs(eye: np.ndarray, rays: np.ndarray, at=SCREEN_AT) -> tuple[np.ndarray, np.ndarray]:
    """Where each ray (..., 3) from ``eye`` (one, or one a ray) first meets ``_skinned_screen``'s two triangles as
    posed (worked out here: the quad's corners, the right two moved by STRETCH, placed at
    ``at``): whether it meets one, and the texture coordinates there (the triangle's
    barycentric weights of the corners' UVs), float64."""
    flat = quad(*SCREEN_SIZE)
    corners = np.asarray(flat.positions, np.float64) + np.asarray(at, np.float64)
    corners[corners[:, 0] > at[0]] += STRETCH
    uvs = np.asarray(flat.uvs, np.float64)
    shape = rays.shape[:-1]
    rays = rays.reshape(-1, 3)
    eye = np.broadcast_to(eye, (*shape, 3)).reshape(-1, 3)
    best = np.full(len(rays), np.inf)
    found = np.zeros((len(rays), 2))
    for i, j, k in np.asarray(flat.indices).reshape(-1, 3):   # (Moeller-Trumbore)
        e1, e2 = corners[j] - corners[i], corners[k] - corners[i]
        p = np.cross(rays, e2)
        det = p @ e1
        with np.errstate(divide="ignore", invalid="ignore"):
            s = eye - corners[i]
            b1 = (p * s).sum(-1) / det
            q = np.cross(s, e1)
            b2 = (rays * q).sum(-1) / det
            t = (q @ e2) / det
        hit = (np.abs(det) > 1e-12) & (b1 >= 0) & (b2 >= 0) & (b1 + b2 <= 1) & (t > 0) & (t < best)
        best[hit] = t[hit]
        found[hit] = ((1 - b1 - b2)[:, None] * uvs[i] + b1[:, None] * uvs[j] + b2[:, None] * uvs[k])[hit]
    return np.isfinite(best).reshape(shape), found.reshape(*shape, 2)


def _sampled(shown: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """The picture's red (rows from the top) sampled bilinearly at texture coordinates ``uv``
    (rows from the bottom, texel centres at (i + 0.5) / size), as the screen's batch samples it."""
    height, width = shown.shape[:2]
    x = np.clip(uv[:, 0] * width - 0.5, 0, width - 1.001)
    y = np.clip((1.0 - uv[:, 1]) * height - 0.5, 0, height - 1.001)
    x0, y0 = x.astype(int), y.astype(int)
    fx, fy = x - x0, y - y0
    texels = shown[..., 0]
    return (texels[y0, x0] * (1 - fx) * (1 - fy) + texels[y0, x0 + 1] * fx * (1 - fy)
            + texels[y0 + 1, x0] * (1 - fx) * fy + texels[y0 + 1, x0 + 1] * fx * fy)


def test_a_skinned_screen_shows_its_picture_by_its_texture_coordinates_as_posed(scene):
    """The studio's screen bent by a ``Skin`` (its right edge's corners carried 0.8 m right and
    0.2 m towards the eye): each frame pixel whose ray meets the screen as posed (its two
    triangles, cast here in float64) gives off the picture sampled at the texture coordinates
    of the posed triangle there, not at the flat quad's; and the frame is the frame of the
    same shape modelled with no skin (a second path), the box on it."""
    frames = {}
    for by_hand in (False, True):
        build, held = studio(Monitor(size=PICTURE))

        def bent(world, build=build, held=held, by_hand=by_hand):
            build(world)
            _skinned_screen(world, held, by_hand)
            eye = world.get(active_camera(world), Transform)   # (the whole bent screen in view)
            eye.position = glm.vec3(0.4, 1.0, 9.5)
            eye.rotation = look_rotation(glm.vec3(0.0, 0.0, -1.0))

        runner, rgb = run(scene, bent, 2)
        frames[by_hand] = (runner, rgb, held)
    runner, rgb, held = frames[False]
    linear = srgb_to_linear(rgb)[..., 0]
    shown = picture(runner, held)
    assert (shown[..., 0] > RED[0] / 2).sum() > 150   # (the box, in the picture)
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    met, uv = _posed_screen_uvs(eye, rays)
    inside = met & (uv[..., 0] > 0.02) & (uv[..., 0] < 0.98) & (uv[..., 1] > 0.02) & (uv[..., 1] < 0.98)
    assert inside.sum() > 3000, inside.sum()
    sampled = _sampled(shown, uv[inside])
    seen = linear[inside]
    assert (sampled > RED[0] / 2).sum() > 100 and (seen > RED[0] / 2).sum() > 100   # (the box, on the screen)
    assert np.corrcoef(seen, sampled)[0, 1] > 0.97, np.corrcoef(seen, sampled)[0, 1]
    assert np.median(np.abs(seen - sampled)) < 0.01 and abs(seen.mean() - sampled.mean()) < 0.01
    # The flat quad's coordinates (the mesh as modelled, where the ray meets its plane) would
    # put the box elsewhere: the skin moved what the picture lands on.
    t = (SCREEN_AT[2] - eye[2]) / rays[..., 2]
    point = eye + rays * t[..., None]
    flat_uv = np.stack([(point[..., 0] - SCREEN_AT[0]) / SCREEN_SIZE[0] + 0.5,
                        (point[..., 1] - SCREEN_AT[1]) / SCREEN_SIZE[1] + 0.5], axis=-1)
    assert np.corrcoef(seen, _sampled(shown, flat_uv[inside]))[0, 1] < 0.8
    # Off the bent screen the frame is black; the screen modelled bent draws the same frame.
    grown = met.copy()
    for _ in range(2):   # (two pixels past its outline)
        padded = np.pad(grown, 1)
        grown = grown | padded[:-2, 1:-1] | padded[2:, 1:-1] | padded[1:-1, :-2] | padded[1:-1, 2:]
    assert linear[~grown].max() < 0.02
    by_hand = frames[True][1].astype(np.int32)
    assert np.abs(rgb.astype(np.int32) - by_hand).max() <= 2


@pytest.mark.parametrize("bent", [False, True], ids=["flat", "skinned"])
def test_a_click_through_a_portal_on_a_screen_picks_what_its_picture_shows_there(scene, bent):
    """The screen seen only through a portal (the active camera, 1 m before portal A, sees
    nothing but A; its partner B stands 2.5 m before the screen, facing it), as the pick path
    says (``shell/picture_pick.py``: the main view's ray is cast on through mirrors and
    portals to the screen): every pixel where the frame shows the box on the screen (red: the
    GPU's picture) picks the box, every pixel of the screen showing the black sky picks
    nothing; the surface image holds A there, the id image the screen.  ``skinned``: the
    screen bent by a ``Skin`` (``_skinned_screen``), its texture coordinates the posed
    triangle's; the red pixels are where the rays carried through the pair by hand (A's
    point moved by B - A: B is A half turned, facing it) meet the posed screen where the
    picture is red."""
    from engine.assets.portals import spawn_portal_pair
    from shell.editor import Editor
    from shell.handles import view_ray
    from shell.picture_pick import into_pictures
    from tests.support import look_from

    made, held = studio(Monitor(size=PICTURE))
    a_at, b_at = np.array([20.0, 1.0, 0.0]), np.array([0.0, 1.0, 8.5])

    def build(world):
        made(world)
        if bent:
            _skinned_screen(world, held)
        world.delete_entity(active_camera(world))
        look_from(world, tuple(a_at + (0.3, 0.0, 1.0)), target=tuple(a_at + (0.3, 0.0, 0.0)), fov=50.0)
        held["a"], held["b"] = spawn_portal_pair(world, tuple(a_at), None, tuple(b_at),
                                                 glm.angleAxis(glm.radians(180.0), glm.vec3(0, 1, 0)), size=(2.0, 1.5))

    runner, rgb = run(scene, build, 2)
    rgb = rgb.astype(np.int32)
    ids, surfaces = runner.ids(), runner.engine.renderer.targets.read_surface_ids()
    assert (surfaces == held["a"]).all() and runner.stats.reflection_views == 1   # (nothing but A in view)
    screen = ids == held["screen"]
    red = screen & (rgb[..., 0] - rgb[..., 1] > 50)
    # Each pixel's ray carried through the pair by hand: A's local point (x, y, z) leaves B at
    # B's local (-x, y, -z), B half turned about y: the world's (x, y, z) from B, its way the same.
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    start, way = b_at + eye + rays * ((a_at[2] - eye[2]) / rays[..., 2])[..., None] - a_at, rays
    if bent:
        met, uv = _posed_screen_uvs(start, way)
    else:
        t = (SCREEN_AT[2] - start[..., 2]) / way[..., 2]
        point = start + way * t[..., None]
        uv = np.stack([(point[..., 0] - SCREEN_AT[0]) / SCREEN_SIZE[0] + 0.5,
                       (point[..., 1] - SCREEN_AT[1]) / SCREEN_SIZE[1] + 0.5], axis=-1)
        met = (t > 0) & (uv >= 0).all(-1) & (uv <= 1).all(-1)
    met, uv = met.reshape(screen.shape), uv.reshape(*screen.shape, 2)
    assert np.mean(met != screen) < 0.01, np.mean(met != screen)
    expected = np.zeros(screen.shape)
    expected[met] = _sampled(picture(runner, held), uv[met])
    assert np.mean((expected > RED[0] / 2) != red) < 0.005, np.mean((expected > RED[0] / 2) != red)
    inner = red.copy()   # (away from the box's edges, where a pixel's ray and the picture's texels part)
    for _ in range(2 if bent else 1):
        inner = inner & np.roll(inner, 1, 0) & np.roll(inner, -1, 0) & np.roll(inner, 1, 1) & np.roll(inner, -1, 1)
    within = screen & np.roll(screen, 1, 0) & np.roll(screen, -1, 0) & np.roll(screen, 1, 1) & np.roll(screen, -1, 1)
    dark = within & (rgb.max(axis=-1) < 10)   # (a pixel from the screen's outline, where the casts may part)
    assert inner.sum() > 20 and dark.sum() > 200, (inner.sum(), dark.sum())
    editor = Editor(runner.world)
    view = runner.engine.main_view

    def click(x, y, surface=False):
        follow = into_pictures(runner.world, runner.engine.renderer.monitors.entities,
                               *view_ray(view.view_proj, runner.size, (x + 0.5, y + 0.5)), view.view_mask)
        return editor.pick(ids, surfaces, x, y, surface, follow)

    for row, column in zip(*np.nonzero(inner), strict=True):
        assert click(column, row) == held["box"], (column, row)
    rows, columns = np.nonzero(dark)
    for row, column in list(zip(rows, columns, strict=True))[::10]:
        assert click(column, row) is None, (column, row)
    row, column = np.argwhere(inner)[0]
    assert click(column, row, surface=True) == held["a"]


@pytest.mark.parametrize("posed_by", ["skin", "morph"])
def test_a_posed_screens_picture_eye_is_weighed_by_its_share_as_posed(scene, posed_by):
    """A screen modelled 10 m behind the active camera and carried 10 m forward into its view
    by a ``Skin``'s joint (or a ``Morph``'s target): its picture's camera is weighed by the
    share of the frame the screen covers as posed (``PictureEyes``: its rectangle's area over
    the frame's), the share of the same screen placed there with no pose (a second path), and
    the share worked out here from its four corners projected by glm (whole pixels, within
    a row and a column); the screen is drawn there (its id's pixels)."""
    from components import Morph, Skin
    from engine.assets.mesh import Mesh
    from engine.rules.light_rules import PictureEyes
    from tests.support import look_from

    size, shown_at, forward = (64, 48), np.array([0.7, 1.4, 0.0]), np.array([0.0, 0.0, -10.0])

    def build_for(posed: bool):
        def build(world):
            look_from(world, (0.0, 1.6, 5.0), (0.0, 1.6, 0.0))
            lens = world.spawn(Transform(position=(20.0, 1.0, 0.0)), Camera(active=False))
            flat = quad(*SCREEN_SIZE)
            positions, triangles = np.asarray(flat.positions, np.float32), np.asarray(flat.indices).reshape(-1, 3)
            parts = [Material(), Monitor(camera=lens, size=(8, 8))]
            if not posed:
                world.spawn(Transform(position=tuple(shown_at)), MeshRef(flat), *parts)
                return
            n = len(positions)
            if posed_by == "skin":
                mesh = Mesh(positions, flat.normals, flat.uvs, triangles, name="carried screen",
                            joints=np.zeros((n, 2), np.uint16), weights=np.tile([1.0, 0.0], (n, 1)))
                joint = np.eye(4)[None].copy()
                joint[0, :3, 3] = forward
                parts.append(Skin(joint))
            else:
                offsets = np.tile(forward, (n, 1))[None].astype(np.float32)
                mesh = Mesh(positions, flat.normals, flat.uvs, triangles, name="carried screen",
                            morph_positions=offsets, morph_normals=np.zeros_like(offsets))
                parts.append(Morph((1.0,)))
            world.spawn(Transform(position=tuple(shown_at - forward)), MeshRef(mesh), *parts)
        return build

    shares = {}
    for posed in (True, False):
        runner = scene(build_for(posed), size)
        for _ in range(3):
            runner.frame(DT)
        (screen, _), = runner.world.query_one(Monitor)
        assert (runner.ids() == screen).sum() > 60   # (drawn where it was carried to)
        points = runner.world.resources[PictureEyes].points
        assert len(points) == 1 and np.allclose(points[0][:3], (20.0, 1.0, 0.0)), points
        shares[posed] = points[0][3]
    # The four corners projected: the whole pixels they span.
    view_proj = np.array(runner.engine.main_view.view_proj.to_list(), np.float64).T
    corners = np.array([(x, y, 0.0, 1.0) for x in (-0.8, 0.8) for y in (-0.45, 0.45)]) + (*shown_at, 0.0)
    clip = corners @ view_proj.T
    ndc = clip[:, :2] / clip[:, 3:]
    pixels = (ndc * 0.5 + 0.5) * size
    width, height = np.ceil(pixels.max(axis=0)) - np.floor(pixels.min(axis=0))
    expected = width * height / (size[0] * size[1])
    assert shares[True] == pytest.approx(shares[False], abs=1e-9)
    assert shares[True] == pytest.approx(expected, abs=(width + height + 1) / (size[0] * size[1])), \
        (shares[True], expected)
