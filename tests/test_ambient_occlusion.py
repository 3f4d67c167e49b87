"""Screen-space ambient occlusion (``AmbientOcclusion`` on the camera): the light from all
round is scaled by the share of the cosine-weighted hemisphere over each point that no
geometry within the radius hides; the lights' direct light is not (unless ``direct_light``).

The scene is a floor and a tall, long wall, lit only by a hemisphere light of one radiance
above and below, so every surface's unoccluded colour is the same and a pixel's colour with
occlusion over its colour without it (in linear light) is the share the engine applied.
That share is compared with the ground truth, computed here apart from the engine: for a
point on the floor at distance d from the wall (or on the wall at height d over the floor),
the wall (the floor) within the radius R hides the directions whose component towards it
is over d / R, and the share kept is the cosine-weighted measure of the others, found by
quadrature over the hemisphere.  Each pixel's point is found by casting its ray in float64
and its surface from the id image."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import (
    AmbientOcclusion,
    ComponentValueError,
    ComponentWarning,
    DirectionalLight,
    HemisphereLight,
    Material,
    MeshRef,
    Transform,
    Visibility,
)
from engine.assets.level_file import LevelError, load_level, save_level
from engine.assets.mesh import box
from engine.assets.texture_data import TextureData
from engine.core.world import World
from tests.support import look_from, pixel_rays, srgb_to_linear

SIZE = (200, 150)
WALL_FACE = 0.25   # the wall's face is the plane x = 0.25, facing -x; the floor is y = 0
RADIUS = 1.0
GREY = (0.8, 0.8, 0.8)


def open_share(t: np.ndarray) -> np.ndarray:
    """The cosine-weighted share of the hemisphere over a plane whose directions' component
    along one tangent is at most ``t`` (0: half of it; 1 and more: all of it): what a point
    at distance t x R from an endless perpendicular wall keeps of the light from all round,
    with occluders counted within R.  Midpoint quadrature in (polar angle, azimuth)."""
    n = 240
    theta = (np.arange(n) + 0.5) / n * (np.pi / 2)
    phi = (np.arange(2 * n) + 0.5) / (2 * n) * (2 * np.pi)
    theta, phi = np.meshgrid(theta, phi, indexing="ij")
    weight = np.cos(theta) * np.sin(theta) * (np.pi / 2 / n) * (np.pi / n) / np.pi  # sums to 1
    along = (np.sin(theta) * np.cos(phi)).ravel()
    order = np.argsort(along)
    cumulative = np.concatenate([[0.0], np.cumsum(weight.ravel()[order])])
    # share of directions with along <= t
    return cumulative[np.searchsorted(along[order], np.asarray(t, np.float64), side="right")]


def _room(world, occlusion: AmbientOcclusion | None, ambient: float = 1.0, sun: float = 0.0,
          wall: bool = True, wall_parts: tuple = ()) -> dict:
    camera = look_from(world, (-2.5, 2.5, -1.5), (0.0, 0.3, -0.5))
    if occlusion is not None:
        world.add_component(camera, occlusion)
    world.spawn(HemisphereLight(sky=(0.6, 0.6, 0.6), ground=(0.6, 0.6, 0.6), intensity=ambient))
    if sun:
        world.spawn(DirectionalLight(direction=glm.vec3(0.6, -1.0, 0.3), intensity=sun))
    names = {"camera": camera}
    names["floor"] = world.spawn(Transform(position=(0.0, -0.05, 0.0)), MeshRef(box((12.0, 0.1, 12.0))),
                                 Material(color=GREY, roughness=1.0))
    if wall:
        names["wall"] = world.spawn(Transform(position=(WALL_FACE + 0.25, 1.5, 0.0)), MeshRef(box((0.5, 3.0, 8.0))),
                                    Material(color=GREY, roughness=1.0), *wall_parts)
    return names


def _frame(scene, build) -> tuple[np.ndarray, object, dict]:
    """A frame of ``build`` (which returns its entities' names) in linear light, its runner
    and the names."""
    names: dict = {}
    runner = scene(lambda world: names.update(build(world)), SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return srgb_to_linear(runner.frame()), runner, names


def _shares(scene, occlusion: AmbientOcclusion, **room) -> tuple[np.ndarray, object, dict]:
    """The share of its colour each pixel kept with ``occlusion`` (linear, per pixel: the
    mean of the three channels' ratios), the runner with it and the room's names."""
    lit, runner, names = _frame(scene, lambda world: _room(world, occlusion, **room))
    plain, _, _ = _frame(scene, lambda world: _room(world, None, **room))
    return (lit / np.maximum(plain, 1e-6)).mean(axis=-1), runner, names


def _surfaces(runner, names) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per pixel: floor mask, its distance from the wall's face; wall-face mask, its height.
    Every pixel, the screen's sides' too: the guard band (screen_occlusion.GUARD_SHARE) sees
    what occludes them a little way off the screen."""
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    ids = runner.ids()
    t_floor = -eye[1] / rays[..., 1]
    floor_points = eye + rays * t_floor[..., None]
    floor = (ids == names["floor"]) & (floor_points[..., 0] < WALL_FACE)
    t_wall = (WALL_FACE - eye[0]) / rays[..., 0]
    wall_points = eye + rays * t_wall[..., None]
    wall = (ids == names.get("wall", -1)) & (t_wall > 0) & (t_wall < t_floor)
    return floor, WALL_FACE - floor_points[..., 0], wall, wall_points[..., 1]


@pytest.mark.parametrize("half, quality", [(True, "medium"), (False, "medium"), (True, "low"), (True, "high")],
                         ids=["half", "full", "low", "high"])
def test_the_floor_and_wall_keep_the_ground_truth_share(scene, half, quality):
    shares, runner, names = _shares(scene, AmbientOcclusion(radius=RADIUS, half_resolution=half, quality=quality))
    floor, distance, wall, height = _surfaces(runner, names)
    for low, high in ((0.0, 0.1), (0.1, 0.25), (0.25, 0.45), (0.45, 0.65), (0.65, 0.85)):
        band = floor & (distance > low) & (distance <= high)
        assert band.sum() > 30, (low, high)
        expected = open_share(distance[band] / RADIUS).mean()
        assert shares[band].mean() == pytest.approx(expected, abs=0.03), f"floor {low}-{high} m from the wall"
    for low, high in ((0.05, 0.3), (0.3, 0.6)):
        band = wall & (height > low) & (height <= high)
        assert band.sum() > 30, (low, high)
        expected = open_share(height[band] / RADIUS).mean()
        assert shares[band].mean() == pytest.approx(expected, abs=0.03), f"wall {low}-{high} m over the floor"
    # Pixel by pixel, the screen's sides too (where the wall runs off it: without the guard
    # band the crease there was 0.25 too light).
    near = floor & (distance < 0.85)
    assert np.abs(shares[near] - open_share(distance[near] / RADIUS)).max() < 0.1
    # Past the radius nothing occludes, and a flat floor does not occlude itself.
    far = floor & (distance > 1.3 * RADIUS)
    assert far.sum() > 500
    assert shares[far].mean() > 0.985 and shares[far].min() > 0.95
    # The crease is near half: the wall hides half the hemisphere at its foot.
    foot = floor & (distance < 0.05)
    assert shares[foot].mean() == pytest.approx(0.5, abs=0.05)


def test_without_the_wall_nothing_is_occluded(scene):
    shares, runner, names = _shares(scene, AmbientOcclusion(radius=RADIUS), wall=False)
    ids = runner.ids()
    floor = ids == names["floor"]
    assert floor.sum() > 10000
    assert shares[floor].mean() > 0.985 and shares[floor].min() > 0.95


def test_the_radius_bounds_the_occlusion(scene):
    small, runner, names = _shares(scene, AmbientOcclusion(radius=0.3))
    floor, distance, _, _ = _surfaces(runner, names)
    band = floor & (distance > 0.1) & (distance < 0.2)
    assert shares_near(small, band) == pytest.approx(open_share(distance[band] / 0.3).mean(), abs=0.05)
    beyond = floor & (distance > 0.45) & (distance < 1.0)   # occluded with radius 1, not 0.3
    assert small[beyond].mean() > 0.985


def shares_near(shares: np.ndarray, band: np.ndarray) -> float:
    assert band.sum() > 30
    return float(shares[band].mean())


def test_intensity_is_an_exponent(scene):
    one, runner, names = _shares(scene, AmbientOcclusion(radius=RADIUS, intensity=1.0))
    two, _, _ = _shares(scene, AmbientOcclusion(radius=RADIUS, intensity=2.0))
    zero, _, _ = _shares(scene, AmbientOcclusion(radius=RADIUS, intensity=0.0))
    floor, distance, _, _ = _surfaces(runner, names)
    near = floor & (distance < 0.6)
    np.testing.assert_allclose(two[near], one[near] ** 2, atol=0.025)
    np.testing.assert_allclose(zero[floor], 1.0, atol=0.01)


def test_the_lights_direct_light_is_not_occluded_unless_asked(scene):
    # No light from all round: a sun alone lights the room; occlusion changes nothing.
    lit, runner, names = _frame(scene, lambda world: _room(world, AmbientOcclusion(radius=RADIUS), ambient=0.0,
                                                            sun=2.0))
    plain, _, _ = _frame(scene, lambda world: _room(world, None, ambient=0.0, sun=2.0))
    assert plain.max() > 0.2  # the sun lights the floor
    np.testing.assert_allclose(lit, plain, atol=2e-3)
    # direct_light=1: the sun's light takes the same share as the light from all round did.
    direct, _, _ = _frame(scene, lambda world: _room(world, AmbientOcclusion(radius=RADIUS, direct_light=1.0),
                                                    ambient=0.0, sun=2.0))
    ambient_shares, _, _ = _shares(scene, AmbientOcclusion(radius=RADIUS))
    floor, distance, _, _ = _surfaces(runner, names)
    sunlit = floor & (distance < 0.8) & (plain.mean(axis=-1) > 0.05)
    assert sunlit.sum() > 100
    direct_shares = (direct / np.maximum(plain, 1e-6)).mean(axis=-1)
    np.testing.assert_allclose(direct_shares[sunlit], ambient_shares[sunlit], atol=0.03)
    half, _, _ = _frame(scene, lambda world: _room(world, AmbientOcclusion(radius=RADIUS, direct_light=0.5),
                                                  ambient=0.0, sun=2.0))
    half_shares = (half / np.maximum(plain, 1e-6)).mean(axis=-1)
    np.testing.assert_allclose(half_shares[sunlit], 0.5 + 0.5 * ambient_shares[sunlit], atol=0.03)


def test_a_foreground_edge_keeps_its_own_light(scene):
    """A box floating in the open, in front of the dark crease: its pixels, its silhouette's
    too, keep their light (the filter does not carry the crease's occlusion across the edge)."""
    floating = {}

    def build(world, occlusion):
        names = _room(world, occlusion)
        floating["box"] = world.spawn(Transform(position=(-0.85, 1.0, -0.9)), MeshRef(box((0.3, 0.3, 0.3))),
                                      Material(color=GREY, roughness=1.0))
        return names

    lit, runner, names = _frame(scene, lambda world: build(world, AmbientOcclusion(radius=0.6)))
    plain, _, _ = _frame(scene, lambda world: build(world, None))
    shares = (lit / np.maximum(plain, 1e-6)).mean(axis=-1)
    ids = runner.ids()
    own = ids == floating["box"]
    assert own.sum() > 100
    # Its pixels beside a pixel of something else: the silhouette.
    edge = own & ~(np.roll(own, 1, 0) & np.roll(own, -1, 0) & np.roll(own, 1, 1) & np.roll(own, -1, 1))
    behind = (~own) & (np.roll(own, 2, 0) | np.roll(own, -2, 0) | np.roll(own, 2, 1) | np.roll(own, -2, 1))
    assert shares[behind].min() < 0.75   # what lies about the edge, the crease, is occluded
    assert shares[edge].min() > 0.95
    assert shares[own].mean() > 0.985


def test_what_the_camera_does_not_draw_does_not_occlude(scene):
    """A wall hidden from the camera's own view (Visibility(direct=False)) and a wall that is
    all holes (a cutout whose texture is clear) hide nothing; the same wall solid does."""
    solid, runner, names = _shares(scene, AmbientOcclusion(radius=RADIUS))
    floor = runner.ids() == names["floor"]
    assert solid[floor].min() < 0.7
    hidden, runner, names = _shares(scene, AmbientOcclusion(radius=RADIUS), wall_parts=(Visibility(direct=False),))
    floor = runner.ids() == names["floor"]
    assert floor.sum() > 10000
    assert hidden[floor].min() > 0.95
    clear = TextureData(np.zeros((4, 4, 4), np.uint8), name="clear")
    cut = Material(color=GREY, roughness=1.0, texture=clear, alpha_cutoff=0.5)

    def build(world, occlusion):
        names = _room(world, occlusion)
        world.add_component(names["wall"], cut)
        return names

    lit, runner, names = _frame(scene, lambda world: build(world, AmbientOcclusion(radius=RADIUS)))
    plain, _, _ = _frame(scene, lambda world: build(world, None))
    shares = (lit / np.maximum(plain, 1e-6)).mean(axis=-1)
    floor = runner.ids() == names["floor"]
    assert floor.sum() > 10000
    assert shares[floor].min() > 0.95


def test_the_passes_and_their_images(scene):
    """Three passes a frame (depth and normals, find, filter), images of half the view's size
    (or all of it with ``half_resolution`` False), let go when the camera loses the component."""
    occlusion = AmbientOcclusion(radius=RADIUS)
    names = {}
    runner = scene(lambda world: names.update(_room(world, occlusion)), SIZE)
    runner.frame()
    renderer = runner.engine.renderer
    with_it = runner.stats.passes
    half = (SIZE[0] // 2, SIZE[1] // 2)
    assert renderer.screen_occlusion is not None and renderer.screen_occlusion.size == half
    assert renderer.resource_counts()["occlusion_targets"] == 4
    margin = renderer.occlusion._targets.margin   # the depth and normals: a guard band about the view
    assert margin == (round(0.1 * half[0]), round(0.1 * half[1]))
    assert renderer.occlusion._targets.depth.size == (half[0] + 2 * margin[0], half[1] + 2 * margin[1])
    occlusion.half_resolution = False
    runner.frame()
    assert renderer.screen_occlusion.size == SIZE
    # Each quality its own build of the find pass (2, 3 or 4 directions): other images.
    shares = {}
    for quality in ("low", "high"):
        occlusion.quality = quality
        runner.frame()
        shares[quality] = np.frombuffer(renderer.screen_occlusion.read(), np.float16)
    assert not np.array_equal(shares["low"], shares["high"])
    runner.world.remove_component(names["camera"], AmbientOcclusion)
    runner.frame()
    assert renderer.screen_occlusion is None and renderer.resource_counts()["occlusion_targets"] == 0
    assert runner.stats.passes == with_it - 3


@pytest.mark.parametrize("field, value", [
    ("radius", 0.0), ("radius", -1.0), ("radius", float("nan")), ("radius", 1000.0),
    ("intensity", -0.1), ("intensity", 9.0), ("direct_light", 1.5), ("direct_light", -0.5),
    ("half_resolution", "yes"), ("quality", "ultra"), ("quality", 3),
])
def test_bad_values_are_refused_naming_the_field(field, value):
    with pytest.raises(ComponentValueError, match=f"AmbientOcclusion.{field}"):
        AmbientOcclusion(**{field: value})
    occlusion = AmbientOcclusion()
    with pytest.raises(ComponentValueError, match=f"AmbientOcclusion.{field}"):
        setattr(occlusion, field, value)


def test_a_level_file_keeps_it(tmp_path):
    (tmp_path / "room.toml").write_text("""[level]
name = "room"

[[entity]]
name = "camera"
Transform = { position = [0.0, 1.0, 3.0] }
Camera = {}
AmbientOcclusion = { radius = 0.8, intensity = 1.5, direct_light = 0.25, half_resolution = false, quality = "high" }
""")
    world = World()
    names = load_level(tmp_path / "room.toml").spawn(world)
    occlusion = world.get(names["camera"], AmbientOcclusion)
    assert (occlusion.radius, occlusion.intensity, occlusion.direct_light, occlusion.half_resolution,
            occlusion.quality) == (pytest.approx(0.8), pytest.approx(1.5), pytest.approx(0.25), False, "high")
    saved = save_level(world, tmp_path / "again.toml", names, name="room")
    again = World()
    names = load_level(saved).spawn(again)
    assert again.get(names["camera"], AmbientOcclusion).radius == pytest.approx(0.8)
    (tmp_path / "bad.toml").write_text(
        '[level]\nname = "bad"\n\n[[entity]]\nname = "camera"\nCamera = {}\nAmbientOcclusion = { radius = -2.0 }\n')
    with pytest.raises(LevelError, match="radius"):
        load_level(tmp_path / "bad.toml")


def test_the_images_go_with_the_camera(scene):
    """Deleting the camera entity lets its occlusion images, and its grade's colour table, go."""
    from components import ColorGrading
    from engine.assets.color_lut import identity_lut

    names = {}
    runner = scene(lambda world: names.update(_room(world, AmbientOcclusion())), SIZE)
    runner.world.add_component(names["camera"], ColorGrading(lut=identity_lut(5)))
    runner.frame()
    counts = runner.engine.renderer.resource_counts()
    assert counts["occlusion_targets"] == 4 and counts["post_targets"] == 1
    runner.world.delete_entity(names["camera"])
    with pytest.warns(UserWarning, match="no active camera"):
        runner.frame()
    counts = runner.engine.renderer.resource_counts()
    assert counts["occlusion_targets"] == 0 and counts["post_targets"] == 0


def test_the_debug_view_shows_the_occlusion_alone(scene):
    """``PresentSystem.show_occlusion`` (the overlay's "AO only") presents the share each
    pixel keeps as grey, 255 for all of it: the occlusion image's own values."""
    names = {}
    runner = scene(lambda world: names.update(_room(world, AmbientOcclusion(half_resolution=False))), SIZE)
    runner.engine.renderer.antialias = "off"
    picture = runner.frame()
    runner.engine.stages["present"].show_occlusion = True
    shown = runner.frame().astype(np.int16)
    shares = np.frombuffer(runner.engine.renderer.screen_occlusion.read(), np.float16).reshape(SIZE[1], SIZE[0], 4)
    want = np.rint(np.flipud(shares[..., 0]).astype(np.float64) * 255.0)
    assert np.abs(shown - want[..., None]).max() <= 1
    assert shown.min() < 150 and shown.max() == 255   # the crease, and the open floor and sky
    assert not np.array_equal(shown, picture)


def test_a_still_scene_finds_its_occlusion_once(scene):
    """While neither the camera nor what it sees moves, the three passes are not run again
    (the image stands); a box moved, the occlusion follows it: the frame is a fresh engine's
    of the box where it now is."""
    names = {}

    def build(world, at):
        names.update(_room(world, AmbientOcclusion()))
        names["box"] = world.spawn(Transform(position=at), MeshRef(box((0.4, 0.4, 0.4))),
                                   Material(color=GREY, roughness=1.0))

    runner = scene(lambda world: build(world, (-0.4, 0.2, -0.5)), SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    first = runner.stats.passes
    still = runner.frame()
    assert runner.stats.passes == first - 3   # depth and normals, find, filter: not drawn again
    runner.world.get(names["box"], Transform).position = glm.vec3(-1.2, 0.2, -0.5)
    moved = runner.frame()
    assert runner.stats.passes == first
    fresh = scene(lambda world: build(world, (-1.2, 0.2, -0.5)), SIZE)
    fresh.engine.renderer.antialias = "off"
    fresh.frame()
    assert np.abs(moved.astype(np.int16) - fresh.frame().astype(np.int16)).max() <= 1
    assert np.abs(moved.astype(np.int16) - still.astype(np.int16)).max() > 10


def _watched_room(world, occlusion: AmbientOcclusion | None) -> dict:
    """``_room`` without occlusion on the active camera, and a monitor whose camera (not active)
    stands where the active one does with ``occlusion``, its picture the frame's size; the
    screen behind both cameras, out of their sight."""
    from components import Camera, Monitor
    from engine.assets.mesh import quad

    names = _room(world, None)
    active = world.get(names["camera"], Transform)
    camera = world.get(names["camera"], Camera)
    names["lens"] = world.spawn(Transform(position=active.position, rotation=active.rotation),
                                Camera(fov_y=camera.fov_y, near=camera.near, far=camera.far, active=False),
                                *([occlusion] if occlusion is not None else []))
    names["screen"] = world.spawn(Transform(position=(-6.0, 1.0, -3.0)), MeshRef(quad(1.6, 0.9)),
                                  Material(color=(0.0, 0.0, 0.0), roughness=1.0),
                                  Monitor(camera=names["lens"], size=SIZE))
    return names


def test_a_monitors_camera_finds_its_pictures_occlusion(scene):
    """A monitor whose camera has an ``AmbientOcclusion`` (the active camera none) has its
    picture's found as the active camera's view's is: the picture with it over the picture
    without keeps the ground truth's share on the floor by the wall (``open_share``), and
    nothing far from it; its images are the picture's own (4), let go when its camera's
    component goes, and with the monitor.  The overlay's toggle off leaves the picture bare."""
    from components import Monitor

    def picture(occlusion):
        names: dict = {}
        runner = scene(lambda world: names.update(_watched_room(world, occlusion)), SIZE)
        runner.engine.renderer.antialias = "off"
        runner.frame()
        return runner.engine.renderer.monitors.read(names["screen"])[..., :3], runner, names

    lit, runner, names = picture(AmbientOcclusion(radius=RADIUS))
    plain, _, _ = picture(None)
    shares = (lit / np.maximum(plain, 1e-6)).mean(axis=-1)
    floor, distance, _, _ = _surfaces(runner, names)   # (the main view's rays and ids: the lens's pose and size)
    for low, high in ((0.0, 0.1), (0.1, 0.25), (0.25, 0.45), (0.45, 0.65)):
        band = floor & (distance > low) & (distance <= high)
        assert band.sum() > 30, (low, high)
        assert shares[band].mean() == pytest.approx(open_share(distance[band] / RADIUS).mean(), abs=0.03), \
            f"floor {low}-{high} m from the wall"
    far = floor & (distance > 1.3 * RADIUS)
    assert far.sum() > 500 and shares[far].mean() > 0.985
    occlusion = runner.engine.renderer.occlusion
    assert occlusion.target_count() == 4   # the picture's alone: the active camera has none
    runner.engine.stages["main"].occlusion = False   # (the overlay's toggle: the picture drawn again, bare)
    runner.frame()
    np.testing.assert_allclose(runner.engine.renderer.monitors.read(names["screen"])[..., :3], plain, atol=1e-3)
    assert occlusion.target_count() == 0
    runner.engine.stages["main"].occlusion = True
    runner.frame()
    assert occlusion.target_count() == 4
    runner.world.remove_component(names["lens"], AmbientOcclusion)
    runner.frame()
    assert occlusion.target_count() == 0
    np.testing.assert_allclose(runner.engine.renderer.monitors.read(names["screen"])[..., :3], plain, atol=1e-3)
    runner.world.add_component(names["lens"], AmbientOcclusion(radius=RADIUS))
    runner.frame()
    assert occlusion.target_count() == 4
    runner.world.remove_component(names["screen"], Monitor)   # (the monitor goes: its images too)
    runner.frame()
    assert occlusion.target_count() == 0
    runner.world.add_component(names["screen"], Monitor(camera=names["lens"], size=SIZE))
    runner.frame()
    assert occlusion.target_count() == 4
    runner.world.delete_entity(names["lens"])   # (the picture kept as it is, said once; the images go)
    with pytest.warns(ComponentWarning, match="names entity"):
        runner.frame()
    assert occlusion.target_count() == 0
