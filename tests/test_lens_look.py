"""A lens's colour fringes and film's grain (``components/post.py`` ChromaticAberration and
FilmGrain, drawn in the present pass): the red and blue images scaled about the middle by what
the intensity says (each channel's centroid of a thin bright line against the scaling worked
out by hand), and grain of the stated spread, zero mean, its response, its size, new each
frame and the same in a screenshot of the frame."""
from __future__ import annotations

import numpy as np
import pytest

from components import (
    ChromaticAberration,
    ComponentValueError,
    ComponentWarning,
    Emissive,
    FilmGrain,
    Material,
    MeshRef,
    Transform,
)
from components.post import MAX_ABERRATION
from engine.assets.mesh import quad
from engine.render.present import GRAIN_SPREAD
from tests.support import camera_level_round_trip, look_from

SIZE = (320, 180)
LINES = (-1.4, 0.0, 1.1)   # x of thin bright lines 3 m before the camera


def lines(world, **components):
    camera = look_from(world, (0, 1.5, 3), (0, 1.5, 0))
    for component in components.values():
        world.add_component(camera, component)
    for x in LINES:
        world.spawn(Transform(position=(x, 1.5, 0)), MeshRef(quad(0.02, 2.0)), Material(color=(1.0, 1.0, 1.0)),
                    Emissive(1.0))
    return camera


def centroids(rgb: np.ndarray, row: int, around: float, reach: int = 14) -> np.ndarray:
    """Each channel's brightness-weighted mean column in ``reach`` columns about ``around``."""
    low, high = int(around) - reach, int(around) + reach + 1
    band = rgb[row, low:high].astype(float)
    band -= band.min(axis=0)   # (the sky behind the line)
    columns = np.arange(low, high) + 0.5
    return (band * columns[:, None]).sum(axis=0) / band.sum(axis=0)


@pytest.mark.parametrize("intensity", [1.0, 0.5])
def test_the_red_image_is_larger_and_the_blue_smaller_about_the_middle(scene, intensity):
    camera = {}

    def build(world):
        camera["entity"] = lines(world, aberration=ChromaticAberration(intensity=intensity))

    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.engine.stages["present"].grade = False   # (the look switch: no fringes)
    plain = runner.frame()
    runner.engine.stages["present"].grade = True
    fringed = runner.frame()
    k = intensity * MAX_ABERRATION
    middle = SIZE[0] / 2.0
    row = SIZE[1] // 2
    for x in LINES:
        column, _ = runner.project((x, 1.5, 0.0))
        at = centroids(plain, row, column)[1]               # the line's own centre (green, unfringed)
        r, g, b = centroids(fringed, row, at)
        assert g == pytest.approx(at, abs=0.05)
        assert r == pytest.approx(middle + (at - middle) * (1 + k), abs=0.3)
        assert b == pytest.approx(middle + (at - middle) * (1 - k), abs=0.3)
    assert abs(centroids(fringed, row, runner.project((1.1, 1.5, 0))[0])[0] - middle) > 10   # (a line off the middle)


def grey_wall(world, **components):
    camera = look_from(world, (0, 1.5, 3), (0, 1.5, 0))
    for component in components.values():
        world.add_component(camera, component)
    world.spawn(Transform(position=(0, 1.5, 0)), MeshRef(quad(40, 40)), Material(color=(0.2, 0.2, 0.2)), Emissive(1.0))
    return camera


def test_grain_has_its_spread_zero_mean_and_changes_each_frame_not_in_a_screenshot(scene):
    """On a flat grey wall (response 0): the grain's spread is intensity x 0.1 of white either
    way (uniform: a standard deviation of that over the square root of 3), its mean nil; the next
    frame's differs; a screenshot of a frame (presented again, dt 0) has the frame's grain."""
    runner = scene(lambda world: grey_wall(world, grain=FilmGrain(intensity=0.5, response=0.0)), SIZE)
    runner.engine.renderer.antialias = "off"
    present = runner.engine.stages["present"]
    present.grade = False
    plain = runner.frame().astype(float)
    present.grade = True
    first = runner.frame().astype(float)
    noise = (first - plain)[..., 1]
    spread = 0.5 * GRAIN_SPREAD * 255.0
    assert abs(noise.mean()) < 0.05 * spread
    assert noise.std() == pytest.approx(spread / np.sqrt(3.0), rel=0.08)
    again = runner.engine.renderer.present_pass.grain_seed
    present.present_into(runner.capture.framebuffer, SIZE, dt=0.0)   # a screenshot of the same frame
    np.testing.assert_array_equal(runner.capture.read_rgb().astype(float), first)
    assert runner.engine.renderer.present_pass.grain_seed == again
    second = runner.frame().astype(float)
    assert np.abs(second - first).mean() > 0.3 * spread


def test_grain_takes_its_size_and_spares_white_by_its_response(scene):
    runner = scene(lambda world: grey_wall(world, grain=FilmGrain(intensity=0.5, response=0.0, size=2.0)), SIZE)
    runner.engine.renderer.antialias = "off"
    present = runner.engine.stages["present"]
    present.grade = False
    plain = runner.frame().astype(int)
    present.grade = True
    noise = runner.frame().astype(int)[..., 1] - plain[..., 1]
    # The same grain over each 2x2 block of pixels (GL's rows, from the bottom: even rows pair up).
    # (Each pixel's own rounding aside: within a block at most one level apart, blocks apart far more.)
    from_bottom = noise[::-1].astype(float)
    within = np.abs(from_bottom[0::2, 0::2] - from_bottom[1::2, 1::2])
    across = np.abs(from_bottom[0::2, 0:-2:2] - from_bottom[0::2, 2::2])
    assert within.max() <= 1.0 and across.mean() > 5.0 * max(within.mean(), 0.2)
    # On white with response 1: none.
    white = scene(lambda world: _white_wall(world), SIZE)
    white.engine.renderer.antialias = "off"
    rgb = white.frame()
    assert (rgb == 255).all()


def _white_wall(world):
    camera = look_from(world, (0, 1.5, 3), (0, 1.5, 0))
    world.add_component(camera, FilmGrain(intensity=1.0, response=1.0))
    world.spawn(Transform(position=(0, 1.5, 0)), MeshRef(quad(40, 40)), Material(color=(1.0, 1.0, 1.0)), Emissive(4.0))


@pytest.mark.parametrize(("cls", "field", "value"), [
    (ChromaticAberration, "intensity", -0.1), (ChromaticAberration, "intensity", 1.5),
    (FilmGrain, "intensity", 2.0), (FilmGrain, "response", -1.0), (FilmGrain, "size", 0.5), (FilmGrain, "size", 9.0),
    (FilmGrain, "intensity", "strong"),
])
def test_lens_look_values_are_checked(cls, field, value):
    with pytest.raises(ComponentValueError, match=f"{cls.__name__}.{field}"):
        cls(**{field: value})


def test_a_level_file_keeps_the_fringes_and_the_grain(tmp_path):
    again, eye = camera_level_round_trip(
        tmp_path, "ChromaticAberration = { intensity = 0.4 }\nFilmGrain = { intensity = 0.2, response = 0.5, "
                  "size = 2.0 }", ("size = 2.0", "size = 20.0"), "size")
    assert again.get(eye, ChromaticAberration).intensity == pytest.approx(0.4)
    grain = again.get(eye, FilmGrain)
    assert (grain.intensity, grain.response, grain.size) == pytest.approx((0.2, 0.5, 2.0))


def test_output_is_unchanged_by_a_zero_intensity(scene):
    """An intensity of 0 draws the plain picture (no build with the effect)."""
    runner = scene(lambda world: lines(world, aberration=ChromaticAberration(intensity=0.0),
                                       grain=FilmGrain(intensity=0.0)), SIZE)
    runner.engine.renderer.antialias = "off"
    shown = runner.frame()
    present = runner.engine.stages["present"]
    present.grade = False
    np.testing.assert_array_equal(runner.frame(), shown)


LENS_FOG, FRAME_FOG = (0.1, 0.2, 0.6), (0.6, 0.2, 0.1)   # the lens's own fog's colour, the active camera's


def _nearest_box(origin: np.ndarray, direction: np.ndarray, centre: np.ndarray, half: np.ndarray) -> np.ndarray:
    """How far each ray (rows, unit ``direction``) goes to the axis-aligned box (inf: it misses)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (centre - half - origin) / direction
        t2 = (centre + half - origin) / direction
    near = np.nanmax(np.minimum(t1, t2), axis=1)
    far = np.nanmin(np.maximum(t1, t2), axis=1)
    return np.where((near <= far) & (near > 0.0), near, np.inf)


@pytest.mark.parametrize("frame_fog", [False, True], ids=["frame_without", "frame_with_another"])
def test_a_lenss_own_fog_fogs_its_pictures_mirror_along_the_lights_whole_way(scene, frame_fog):
    """A monitor's camera with a ``Fog`` of its own (density 0.25, one colour) looks at a mirror
    3 m off; the unlit red box stands behind it, seen only in the mirror, in a black world
    (``tests/test_monitors.py``'s studio).  Each picture pixel whose ray, reflected off the
    mirror, meets the box shows red x T + the fog's colour x (1 - T), T = exp(-0.25 L) over
    the whole way L from the lens to the mirror and on to the box (cast here in float64), as
    the camera's own mirror level is fogged; the mirror's sky, all the fog's colour; whether
    the active camera has no fog or another (``frame_with_another``: its colour nowhere in
    the picture).  The active camera posed as the lens with that fog draws its mirror the same
    (its level 0, linear, against the picture)."""
    from components import Camera, Fog, Monitor
    from tests.test_monitors import PICTURE, RED, active_camera, lens_rays, run, studio

    behind, half = np.array([0.5, 1.2, 1.5]), np.array([0.8, 0.6, 0.3])   # (behind the lens, out of its sight)
    density = 0.25

    def build_with(fogged_lens: bool):
        build, held = studio(Monitor(size=PICTURE, depth=1), mirror=True, box_at=behind, box_half=half)

        def fogged(world):
            build(world)
            eye = active_camera(world)
            if fogged_lens:
                world.add_component(held["lens"], Fog(color=LENS_FOG, density=density))
                if frame_fog:
                    world.add_component(eye, Fog(color=FRAME_FOG, density=0.1))
            else:   # the active camera where the lens stands, with its fog, at the picture's size
                lens = world.get(held["lens"], Transform)
                world.get(eye, Transform).position, world.get(eye, Transform).rotation = lens.position, lens.rotation
                world.get(eye, Camera).fov_y = world.get(held["lens"], Camera).fov_y
                world.add_component(eye, Fog(color=LENS_FOG, density=density))
        return fogged, held

    build, held = build_with(True)
    runner, _ = run(scene, build, 2, size=(160, 120))
    shown = runner.engine.renderer.monitors.read(held["screen"])[..., :3].astype(np.float64)
    eye, rays = lens_rays()
    rays = rays.reshape(-1, 3)
    t_mirror = (-3.0 - eye[2]) / rays[:, 2]
    glass = eye + rays * t_mirror[:, None]
    on_mirror = (t_mirror > 0) & (np.abs(glass[:, 0]) < 1.45) & (np.abs(glass[:, 1] - 1.0) < 0.95)
    t_box = _nearest_box(glass, rays * np.array([1.0, 1.0, -1.0]), behind, half)
    whole = (t_mirror + t_box).reshape(PICTURE[1], PICTURE[0])
    box = on_mirror.reshape(PICTURE[1], PICTURE[0]) & np.isfinite(whole)
    padded = np.pad(box, 1)
    box &= padded[:-2, 1:-1] & padded[2:, 1:-1] & padded[1:-1, :-2] & padded[1:-1, 2:]   # (a pixel from its edge)
    sky = on_mirror.reshape(PICTURE[1], PICTURE[0]) & ~np.isfinite(whole)
    assert box.sum() > 40 and sky.sum() > 500, (box.sum(), sky.sum())
    kept = np.exp(-density * whole[box])[:, None]
    expected = np.array(RED) * kept + np.array(LENS_FOG) * (1.0 - kept)
    np.testing.assert_allclose(shown[box], expected, atol=4e-3)
    beyond = np.exp(-density * t_box.reshape(PICTURE[1], PICTURE[0])[box])[:, None]   # (the mirror's stretch alone)
    assert np.abs(np.array(RED) * beyond + np.array(LENS_FOG) * (1.0 - beyond) - expected).min() > 0.02
    np.testing.assert_allclose(shown[sky], np.broadcast_to(LENS_FOG, shown[sky].shape), atol=4e-3)
    # The camera's own mirror level, the same fog on the active camera posed as the lens.
    direct_build, _ = build_with(False)
    direct, _ = run(scene, direct_build, 2, size=PICTURE)
    targets = direct.engine.renderer.targets
    level = np.frombuffer(targets.color.read(), np.float16).reshape(targets.size[1], targets.size[0], 4)[::-1, :, :3]
    mirror = on_mirror.reshape(PICTURE[1], PICTURE[0])
    np.testing.assert_allclose(shown[mirror], level[mirror].astype(np.float64), atol=3e-3)


def test_a_monitors_cameras_fringes_and_grain_leave_its_picture_as_it_is(scene):
    """A picture has no post-processing of its own (README, "Monitors"): a monitor's camera
    with ``ChromaticAberration`` and ``FilmGrain`` at full strength draws its picture, the
    mirror it shows too, texel for texel as without them, and a warning says so; the same
    components on the active camera do change its frame (so they are drawn where a camera presents)."""
    from components import Monitor
    from tests.test_monitors import PICTURE, active_camera, run, studio

    def drawn(on_lens: bool, on_eye: bool):
        build, held = studio(Monitor(size=PICTURE, depth=1), mirror=True, box_at=np.array([0.5, 1.2, 1.5]),
                             box_half=np.array([0.8, 0.6, 0.3]))

        def look(world):
            build(world)
            for entity, on in ((held["lens"], on_lens), (active_camera(world), on_eye)):
                if on:
                    world.add_component(entity, ChromaticAberration(intensity=1.0))
                    world.add_component(entity, FilmGrain(intensity=1.0, response=0.0))
        runner, rgb = run(scene, look, 2)
        return runner.engine.renderer.monitors.read(held["screen"]), rgb

    plain, plain_frame = drawn(False, False)
    with pytest.warns(ComponentWarning, match="ChromaticAberration, FilmGrain on entity .* do nothing there"):
        lens, _ = drawn(True, False)   # (and said so)
    _, eye_frame = drawn(False, True)
    assert (plain[..., 0] > 0.1).sum() > 60   # (the box, in the mirror)
    np.testing.assert_array_equal(lens, plain)
    assert np.abs(eye_frame.astype(int) - plain_frame.astype(int)).max() > 20
