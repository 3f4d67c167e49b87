"""Clouds (``CloudLayer``): the sky pass draws them as the CPU's twin does
(engine/render/clouds.py owns the rules), their coverage is the share of the sheet under
cloud, they hide the sun's disc, the cube map and the sky's light take them, they shade the
sun's light on the world as the twin says point by point, and the wind moves them (the sky
pass every frame, the cube map once they have drifted two of its texels)."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    CloudLayer,
    ComponentValueError,
    ComponentWarning,
    DirectionalLight,
    Material,
    MeshRef,
    ReflectionProbe,
    Skybox,
    Transform,
    look_rotation,
)
from engine.assets.mesh import plane
from engine.render.clouds import (
    EARTH_RADIUS,
    NOISE_PERIOD,
    cloud_cover,
    cloud_noise,
    cloud_shadow,
    cloud_shape,
    cloud_thickness,
    layer_cells,
    layer_distance,
)
from engine.render.irradiance import generated_sky_sh, project_faces
from engine.render.sky import build_faces, cloud_hidden, model_sky, sky_model, sky_radiance
from tests.test_generated_sky import SIZE, SKY, SUN, _cube_faces, _read

UP_AHEAD = glm.normalize(glm.vec3(0.2, 0.8, -0.5))


def _cloud_frame(scene, skybox: Skybox, layer: CloudLayer | None, look: glm.vec3, fov: float = 60.0,
                 build_more=None):
    """A frame of ``skybox`` under ``layer`` through a camera of ``fov`` along ``look``: level
    0's linear colour and rays, and the runner."""

    def build(world):
        world.spawn(Transform(rotation=look_rotation(look)), Camera(fov_y=fov, near=0.1, far=100.0))
        world.spawn(skybox, *(() if layer is None else (layer,)))
        if build_more is not None:
            build_more(world)

    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return (*_read(runner), runner)


def _still(**values) -> CloudLayer:
    """A CloudLayer with no wind (a test's frames leave it where it is)."""
    return CloudLayer(**{"wind": (0.0, 0.0), **values})


# -- the rules ----------------------------------------------------------------------------------

def _bisected_distance(point: np.ndarray, way: np.ndarray, height: float) -> float:
    """Where the ray meets the sphere of radius R + height about (0, -R, 0), by bisection on
    the distance from the centre (exact arithmetic's answer, float64's rounding)."""
    centre = np.array([0.0, -EARTH_RADIUS, 0.0])
    radius = EARTH_RADIUS + height
    low, high = 0.0, 4.0e6
    for _ in range(200):
        middle = (low + high) / 2.0
        if np.linalg.norm(point + middle * way - centre) < radius:
            low = middle
        else:
            high = middle
    return (low + high) / 2.0


@pytest.mark.parametrize("point", [(0.0, 0.0, 0.0), (300.0, 40.0, -120.0)])
@pytest.mark.parametrize("elevation", [90.0, 30.0, 3.0, 0.0, -2.0])
def test_a_way_meets_the_sheet_where_the_sphere_says(point, elevation):
    """The sheet on the Earth's curve: met at the distance bisection finds (1e-7 of it), the
    horizon's at sqrt(2 R h) about (finite: the clouds crowd there), straight up at h."""
    way = np.array([math.cos(math.radians(elevation)) * 0.6, math.sin(math.radians(elevation)),
                    -math.cos(math.radians(elevation)) * 0.8])
    way /= np.linalg.norm(way)
    p = np.array(point)
    t, crossing = layer_distance(p, way, 1500.0)
    want = _bisected_distance(p, way, 1500.0)
    assert abs(t - want) <= 1e-7 * want + 1e-6
    normal = (p + t * way - np.array([0.0, -EARTH_RADIUS, 0.0])) / (EARTH_RADIUS + 1500.0)
    assert abs(crossing - way @ normal) < 1e-9
    if elevation == 90.0 and point[1] == 0.0:
        assert abs(t - 1500.0) < 1e-6
    if elevation == 0.0 and point[1] == 0.0:
        assert abs(t / math.sqrt(2.0 * EARTH_RADIUS * 1500.0) - 1.0) < 1e-3


@pytest.mark.parametrize("coverage", [0.15, 0.5, 0.85])
def test_coverage_is_the_share_of_the_sheet_under_cloud(coverage):
    """Over places of the whole pattern (two seeds), the share thicker than half and the mean
    thickness are the coverage (0.03); 1 is overcast (every place whole), 0 no cloud at all."""
    rng = np.random.default_rng(7)
    places = rng.random((100_000, 2)) * NOISE_PERIOD
    for seed in (3, 4000):
        shape = cloud_shape(_still(coverage=coverage, seed=seed))
        thick = cloud_thickness(shape, cloud_noise(places, seed))
        assert abs((thick > 0.5).mean() - coverage) < 0.03
        assert abs(thick.mean() - coverage) < 0.03
    overcast = cloud_shape(_still(coverage=1.0))
    assert cloud_thickness(overcast, cloud_noise(places, 0)).min() > 0.999
    assert cloud_shape(_still(coverage=0.0)) is None and cloud_shape(_still(density=0.0)) is None


def test_the_pattern_wraps_with_its_period_and_moves_with_the_drift():
    """The noise repeats every NOISE_PERIOD cells (so the drift wraps), another seed is another
    pattern, and a drift of d metres moves the clouds by d."""
    rng = np.random.default_rng(3)
    places = rng.random((2000, 2)) * NOISE_PERIOD
    np.testing.assert_allclose(cloud_noise(places + NOISE_PERIOD * np.array([1.0, -2.0]), 5),
                               cloud_noise(places, 5), atol=1e-9)
    assert np.abs(cloud_noise(places, 5) - cloud_noise(places, 6)).mean() > 0.05
    still, moved = cloud_shape(_still()), cloud_shape(_still(drift=(700.0, -300.0)))
    xz = rng.random((2000, 2)) * 5000.0
    np.testing.assert_allclose(cloud_noise(layer_cells(moved, xz + np.array([700.0, -300.0])), 0),
                               cloud_noise(layer_cells(still, xz), 0), atol=1e-9)


# -- the sky ------------------------------------------------------------------------------------

@pytest.mark.parametrize("model", ["gradient", "atmosphere"])
def test_the_sky_pass_draws_the_clouds_as_the_twin(scene, model):
    """A 60-degree lens up into a half-cloudy sky: every pixel is the CPU's sky along its ray
    (clouds, their light and what they leave of the sky), clouds and clear sky both in view."""
    skybox = Skybox(**SKY, model=model)
    layer = _still(coverage=0.5, drift=(400.0, 900.0))
    colour, rays, _ = _cloud_frame(scene, skybox, layer, UP_AHEAD)
    shape = cloud_shape(layer)
    want = sky_radiance(skybox, rays, None, shape)
    np.testing.assert_allclose(colour, want, rtol=6e-3, atol=6e-3)
    hidden = cloud_hidden(sky_model(skybox, None, shape), rays)[0]
    assert (hidden > 0.9).mean() > 0.15 and (hidden < 0.05).mean() > 0.15
    clear = sky_radiance(skybox, rays)
    assert np.abs(colour - clear).max(axis=-1)[hidden > 0.9].min() > 0.02   # (the clouds show)


def test_a_moon_lights_the_clouds_at_night_as_the_twin_says(scene):
    """A night under an atmosphere, a full moon 35 degrees up and clouds about it: every pixel
    of a lens on the moon is the CPU's sky (the clouds lit by the moon as by the sun: its
    disc's colour times its phase's share, through the cloud beside it, a silver lining round
    it); the moonlit clouds are brighter than the same clouds with the moon's light on them
    taken out, most of all near the moon."""
    from engine.rules.light_rules import SkySun

    night_sun = glm.normalize(glm.vec3(0.6, -0.3, 0.75))
    moon = glm.normalize(glm.vec3(-0.5, 0.7, -0.75))
    skybox = Skybox(model="atmosphere", sun_direction=tuple(night_sun), moon_color=(2.0, 2.0, 2.1))
    layer = _still(coverage=0.5, drift=(400.0, 900.0))

    def moon_light(world):
        world.spawn(DirectionalLight(direction=tuple(-moon), intensity=0.3, body="moon", shadows=False))
    colour, rays, runner = _cloud_frame(scene, skybox, layer, moon, build_more=moon_light)
    shape = cloud_shape(layer)
    sun = SkySun(tuple(night_sun), moon=tuple(moon))
    want = sky_radiance(skybox, rays, sun, shape)
    np.testing.assert_allclose(colour, want, rtol=6e-3, atol=1e-3)
    model = sky_model(skybox, sun, shape)
    assert any(model.moon_light)
    hidden, light = cloud_hidden(model, rays)
    from engine.render.sky import clear_radiance
    unlit = cloud_cover(shape, rays, np.array(model.sun_direction), np.array(model.sun_color),
                        clear_radiance(model, np.array([0.0, 1.0, 0.0])))[1]
    cloudy = hidden > 0.9
    assert cloudy.mean() > 0.1
    gain = (light - unlit)[..., 1]
    assert gain[cloudy].min() >= 0.0 and np.median(gain[cloudy] / unlit[..., 1][cloudy]) > 0.5
    near = cloudy & (rays @ np.array(moon) > 0.97)
    assert gain[near].mean() > gain[cloudy & (rays @ np.array(moon) < 0.9)].mean()


def _drift_over(point: np.ndarray, thick: bool, layer_values: dict) -> tuple[float, float]:
    """A drift that puts a cloud's thickest part (``thick``) or clear sky over the sheet's
    place seen along unit ``point`` (found on a grid of drifts)."""
    t, _ = layer_distance(np.zeros(3), point, layer_values.get("height", 1500.0))
    xz = point[[0, 2]] * t
    for x in np.arange(0.0, 20000.0, 97.0):
        for z in (0.0, 1300.0, 2900.0):
            shape = cloud_shape(_still(**layer_values, drift=(x, z)))
            value = float(cloud_thickness(shape, cloud_noise(layer_cells(shape, xz), shape.seed)))
            if (value > 0.999) if thick else (value < 1e-3):
                return (x, z)
    raise AssertionError("no drift found")


def test_a_cloud_hides_the_suns_disc(scene):
    """A 10-degree lens on the sun: under clear sky the disc is whole; with a cloud's thick part
    over it the disc's pixels are gone (its light times exp(-depth), as the twin says)."""
    sun = np.array(SUN, np.float64)
    for thick in (False, True):
        drift = _drift_over(sun, thick, {"coverage": 0.5})
        layer = _still(coverage=0.5, drift=drift)
        colour, rays, _ = _cloud_frame(scene, Skybox(**SKY), layer, SUN, fov=10.0)
        np.testing.assert_allclose(colour, sky_radiance(Skybox(**SKY), rays, None, cloud_shape(layer)),
                                   rtol=6e-3, atol=6e-3)
        discless = model_sky(sky_model(Skybox(**SKY), None, cloud_shape(layer)), rays, disc=False)
        disc = int(((colour - discless)[..., 0] > 1.0).sum())   # (the clouds round it shine brightly)
        assert (disc == 0) if thick else (disc > 2000), disc


def test_the_cube_map_and_the_skys_light_take_the_clouds(scene):
    """The cube map reflections and probes read is the twin's faces with the clouds; the sky's
    light (clear sky's closed form plus the clouds' change, projected coarsely) agrees with
    the projection of the twin's 128-texel faces (2% of the largest coefficient), and white
    clouds over a blue sky make it whiter."""
    skybox = Skybox(**SKY, face_size=64)
    layer = _still(coverage=0.6, drift=(1200.0, 300.0))
    _, _, runner = _cloud_frame(scene, skybox, layer, UP_AHEAD)
    shape = cloud_shape(layer)
    faces = _cube_faces(runner)
    want = build_faces(skybox, None, shape)
    np.testing.assert_allclose(faces, want.astype(np.float16), rtol=5e-3, atol=5e-3)
    assert np.abs(want - build_faces(skybox)).max() > 0.5   # (the clouds are in it)
    light = generated_sky_sh(sky_model(skybox, None, shape))
    fine = project_faces(build_faces(Skybox(**SKY, face_size=128), None, shape))
    assert np.abs(light - fine).max() < 0.02 * np.abs(fine).max()
    clear = generated_sky_sh(sky_model(skybox))
    assert light[0, 2] / light[0, 0] < 0.9 * clear[0, 2] / clear[0, 0]


@pytest.mark.parametrize("night", [False, True], ids=["gradient_by_day", "atmosphere_moonlit"])
def test_a_sharp_mirror_shows_the_clouds_and_the_moon_as_the_twin_along_its_reflected_rays(scene, night):
    """A mirror across the view, facing the camera: each of its pixels is the CPU's sky along
    the pixel's ray reflected in it (the composite's per-pixel sky: the clouds' edges, and by
    night an atmosphere's moonlit air, the moon's disc and the clouds it lights, as the sky
    pass draws them; not the cube map's blocks), clouds and clear sky both in it, and not the
    sky straight ahead (the mirror is there)."""
    from components import Mirror
    from engine.assets.mesh import quad
    from engine.rules.light_rules import SkySun

    if night:
        night_sun = glm.normalize(glm.vec3(0.6, -0.3, 0.75))
        target = glm.normalize(glm.vec3(-0.5, 0.7, -0.75))   # the moon
        skybox = Skybox(model="atmosphere", sun_direction=tuple(night_sun), moon_color=(2.0, 2.0, 2.1))
        sun = SkySun(tuple(night_sun), moon=tuple(target))
    else:
        target, skybox, sun = UP_AHEAD, Skybox(**SKY), None
    look = glm.normalize(glm.vec3(target.x, target.y, -target.z))   # what a plane z = 2 reflects to target
    layer = _still(coverage=0.5, drift=(400.0, 900.0))

    def build_more(world):
        if night:
            world.spawn(DirectionalLight(direction=tuple(-target), intensity=0.3, body="moon", shadows=False))
        world.spawn(Transform(position=(0.0, 0.0, 2.0), rotation=glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))),
                    MeshRef(quad(40.0, 40.0)), Material(), Mirror())
    colour, rays, _ = _cloud_frame(scene, skybox, layer, look, fov=40.0, build_more=build_more)
    on_mirror = rays[..., 2] > 0.05
    hit = rays * (2.0 / np.where(on_mirror, rays[..., 2], 1.0))[..., None]
    on_mirror &= (np.abs(hit[..., 0]) < 19.0) & (np.abs(hit[..., 1]) < 19.0)
    assert on_mirror.mean() > 0.95
    reflected = rays * np.array([1.0, 1.0, -1.0])
    shape = cloud_shape(layer)
    want = sky_radiance(skybox, reflected, sun, shape)
    np.testing.assert_allclose(colour[on_mirror], want[on_mirror], rtol=6e-3, atol=1e-3 if night else 6e-3)
    hidden = cloud_hidden(sky_model(skybox, sun, shape), reflected)[0][on_mirror]
    assert (hidden > 0.9).mean() > 0.05 and (hidden < 0.05).mean() > 0.05         # (clouds and clear sky)
    clear = sky_radiance(skybox, reflected, sun)[on_mirror]
    assert np.abs(colour[on_mirror] - clear).max(axis=-1)[hidden > 0.9].min() > (0.002 if night else 0.02)
    ahead = sky_radiance(skybox, rays, sun, shape)[on_mirror]
    assert np.abs(colour[on_mirror] - ahead).max() > 0.05                          # (the mirror is drawn)
    if night:
        discless = model_sky(sky_model(skybox, sun, shape), reflected, disc=False)
        assert ((colour - discless)[..., 2][on_mirror] > 0.05).sum() > 20          # (the moon's disc)


# -- shadows ------------------------------------------------------------------------------------

SHADOW_SUN = glm.normalize(glm.vec3(-0.3, -0.85, 0.2))   # the way the light travels
FILL = glm.normalize(glm.vec3(0.5, -0.7, -0.3))


def _floor_frame(scene, layer: CloudLayer, intensity: float = 3.0, body: str = "sun", fill: float = 0.0):
    """A 70-degree lens straight down on a grey floor from 30 m, lit by a sun (or a moon:
    ``body``) along ``SHADOW_SUN`` (the sky's sun pinned elsewhere: its light and sky stay
    the same); ``fill``: a dimmer light of the sun's body along ``FILL`` too (a fill light)."""

    def build(world):
        world.spawn(Transform(position=(5.0, 30.0, -3.0), rotation=look_rotation(glm.vec3(0.0, -1.0, 0.0),
                                                                                   glm.vec3(0.0, 0.0, -1.0))),
                    Camera(fov_y=70.0, near=0.5, far=200.0))
        world.spawn(Skybox(**SKY), layer)
        world.spawn(DirectionalLight(direction=tuple(SHADOW_SUN), intensity=intensity, shadows=False, body=body))
        if fill:
            world.spawn(DirectionalLight(direction=tuple(FILL), intensity=fill, shadows=False))
        world.spawn(Transform(), MeshRef(plane(400.0, 400.0)), Material(color=(0.5, 0.5, 0.5), roughness=0.9))

    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    colour, rays = _read(runner)
    eye = np.array(runner.engine.main_view.eye, np.float64)
    return colour, eye + rays * (-eye[1] / rays[..., 1:2])   # each pixel's floor point


def test_clouds_shade_the_suns_light_as_the_twin_says(scene):
    """Clouds 40 m across 80 m up over a floor seen from 30 m: the sun's share of each pixel's
    light (the frame less the sunless frame, over the same without cloud shadows) is the
    twin's exp(-depth) of the cloud on the way from the pixel's floor point to the sun
    (0.02), and both deep shadow and full sun are on the floor."""
    values = dict(coverage=0.5, scale=40.0, height=80.0, drift=(13.0, 7.0))
    shaded, points = _floor_frame(scene, _still(**values))
    lit, _ = _floor_frame(scene, _still(**values, shadows=False))
    dark, _ = _floor_frame(scene, _still(**values), intensity=0.0)
    share = (shaded - dark)[..., 1] / (lit - dark)[..., 1]
    want = cloud_shadow(cloud_shape(_still(**values)), points, -np.array(SHADOW_SUN, np.float64))
    assert np.abs(share - want).max() < 0.02
    assert (want < 0.05).mean() > 0.1 and (want > 0.95).mean() > 0.1


def test_clouds_shade_a_moons_light_and_leave_a_fill_lights(scene):
    """A moon (``DirectionalLight.body`` "moon") alone: its share of each floor pixel's light is
    the twin's along its way, as the sun's is.  A fill light (a second, dimmer light of the
    sun's body: not the sky's sun, not reddened by the air either) is not under the clouds:
    its light (the frame with it less the frame without) is the same with and without the
    clouds' shadows."""
    values = dict(coverage=0.5, scale=40.0, height=80.0, drift=(13.0, 7.0))
    shaded, points = _floor_frame(scene, _still(**values), body="moon")
    lit, _ = _floor_frame(scene, _still(**values, shadows=False), body="moon")
    dark, _ = _floor_frame(scene, _still(**values), intensity=0.0, body="moon")
    share = (shaded - dark)[..., 1] / (lit - dark)[..., 1]
    want = cloud_shadow(cloud_shape(_still(**values)), points, -np.array(SHADOW_SUN, np.float64))
    assert np.abs(share - want).max() < 0.02
    assert (want < 0.05).mean() > 0.1
    fill = {}
    for shadows in (True, False):
        with_fill, _ = _floor_frame(scene, _still(**values, shadows=shadows), fill=1.0)
        without, _ = _floor_frame(scene, _still(**values, shadows=shadows))
        fill[shadows] = (with_fill - without)[..., 1]
    assert fill[False].min() > 0.02
    assert np.abs(fill[True] / fill[False] - 1.0).max() < 0.02


SKY_BODY_SUN = glm.normalize(glm.vec3(0.0, -0.35, -1.0))   # low, from +Z, towards the mirror at -Z
MIRROR_MIDDLE = (0.0, 1.5, -1.0)


def test_the_light_a_mirror_throws_is_shaded_by_the_cloud_over_the_mirror(scene):
    """A mirror throwing a low sun back onto the floor under clouds 5 km across: the thrown
    light (the floor with the mirror throwing less without) with the clouds' shadows over
    the same without is the twin's share at the mirror's middle towards the sun (the light
    reaches the floor by way of the mirror: the cloud between the mirror and the sun shades
    it, not the one over the floor)."""
    from components import Mirror
    from engine.assets.mesh import quad

    values = dict(coverage=0.6, scale=5000.0, height=1500.0, drift=(7844.0, 0.0))
    thrown = {}
    for shadows in (True, False):
        frames = []
        for throws in (True, False):
            def build(world, shadows=shadows, throws=throws):
                world.spawn(Transform(position=(0.0, 7.0, 2.0), rotation=look_rotation(glm.vec3(0.0, -1.0, -0.001))),
                            Camera(fov_y=60.0, near=0.1, far=100.0))
                world.spawn(Skybox(**SKY), _still(**values, shadows=shadows))
                world.spawn(DirectionalLight(direction=tuple(SKY_BODY_SUN), intensity=3.0, shadows=True))
                world.spawn(Transform(), MeshRef(plane(40, 40)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
                world.spawn(Transform(position=MIRROR_MIDDLE), MeshRef(quad(6.0, 3.0)), Material(),
                            Mirror(reflects_light=throws))

            runner = scene(build, SIZE)
            runner.engine.renderer.antialias = "off"
            runner.frame()
            frames.append(_read(runner)[0])
        thrown[shadows] = frames[0] - frames[1]
    patch = thrown[False].sum(axis=-1) > 0.1
    assert patch.sum() > 200
    want = float(cloud_shadow(cloud_shape(_still(**values)), np.array(MIRROR_MIDDLE, np.float64),
                              -np.array(SKY_BODY_SUN, np.float64)))
    assert 0.15 < want < 0.7
    np.testing.assert_allclose(thrown[True][patch].mean(axis=0) / thrown[False][patch].mean(axis=0), want, rtol=0.02)


# -- the wind -----------------------------------------------------------------------------------

def test_the_wind_moves_the_clouds_the_sky_pass_each_frame_the_cube_every_two_texels(scene):
    """Wind 60 m/s at 1/60 s a frame: the drift moves a metre a frame (wrapped to the
    pattern's period); the sky pass draws the clouds where the drift is each frame; the cube
    map (32 texels a face, 1500 m up: two texels straight up are 147 m) is made again only
    when they have drifted past that."""
    skybox = Skybox(**SKY, face_size=32)
    layer = CloudLayer(coverage=0.5, wind=(60.0, 0.0), drift=(NOISE_PERIOD * 2000.0 - 0.5, 0.0))
    _, _, runner = _cloud_frame(scene, skybox, layer, UP_AHEAD)
    assert layer.drift[0] == pytest.approx(0.5, abs=1e-6)   # (wrapped)
    renderer = runner.engine.renderer
    cubes = [renderer.sky]
    served = 2.0 * (math.pi / 2.0) / 32 * 1500.0
    for frame in range(1, 181):
        runner.frame()
        if renderer.sky is not cubes[-1]:
            cubes.append(renderer.sky)
        if frame % 60 == 0:
            colour, rays = _read(runner)
            np.testing.assert_allclose(colour, sky_radiance(skybox, rays, None, cloud_shape(layer)),
                                       rtol=6e-3, atol=6e-3)
    assert layer.drift[0] == pytest.approx(0.5 + 180.0, abs=1e-6)
    assert len(cubes) == 1 + int(180.0 // served)


def test_a_reflection_probe_is_relit_once_the_clouds_drift_past_what_its_capture_serves(scene):
    """An on_change probe over a floor under clouds 40 m across (their finest octave 2.5 m: a
    capture serves an eighth of it, 0.3125 m of drift) blown at 6 m/s, 0.1 m a frame: its
    faces are captured again each time the drift passes that (every fourth frame), and not
    between; the capture after shows the shadows moved.  (A face that shows the sky alone is
    drawn again as the sky's cube map is, ``test_the_wind_moves_the_clouds...``.)"""
    layer = CloudLayer(coverage=0.5, scale=40.0, height=60.0, wind=(6.0, 0.0))

    def build(world):
        world.spawn(Transform(position=(0.0, 30.0, 0.0)), Camera(fov_y=60.0, near=0.5, far=200.0))
        world.spawn(Skybox(**SKY), layer)
        world.spawn(DirectionalLight(direction=tuple(SHADOW_SUN), intensity=3.0, shadows=False))
        world.spawn(Transform(), MeshRef(plane(400.0, 400.0)), Material(color=(0.5, 0.5, 0.5), roughness=0.9))
        world.spawn(Transform(position=(0.0, 2.0, 0.0)), ReflectionProbe(resolution=16))
    runner = scene(build, (32, 24))
    runner.frame()
    assert runner.stats.probe_faces >= 6   # (its first capture)
    probe = next(e for e, _ in runner.world.query_one(ReflectionProbe))
    cube = runner.engine.renderer.probes.cubes[probe].texture
    before = np.frombuffer(cube.read(face=3), np.float16 if cube.dtype == "f2" else np.float32).copy()
    faces = []
    for _ in range(12):
        runner.frame()
        faces.append(runner.stats.probe_faces)
    assert [count > 0 for count in faces] == [False, False, False, True] * 3, faces
    assert all(count >= 5 for count in faces if count), faces   # (the face up, sky alone, as the sky's cube: below)
    after = np.frombuffer(cube.read(face=3), np.float16 if cube.dtype == "f2" else np.float32)
    assert not np.array_equal(before, after)   # (the floor below it: the shadows moved)
    # Still clouds relight nothing.
    layer.wind = (0.0, 0.0)
    runner.frame()
    still = []
    for _ in range(6):
        runner.frame()
        still.append(runner.stats.probe_faces)
    assert still == [0] * 6, still


# -- the world's layer --------------------------------------------------------------------------

def test_a_layer_taken_away_leaves_the_clear_sky_and_misplaced_layers_are_said(scene):
    """Deleting the CloudLayer draws the clear sky again (pixel for pixel) and the scene's
    builds lose their cloud shadows; a second layer, a given-faces sky and no sky are each
    said once."""
    skybox = Skybox(**SKY)
    colour, rays, runner = _cloud_frame(scene, skybox, _still(), UP_AHEAD)
    renderer = runner.engine.renderer
    assert renderer.clouds.shadow_defines
    entity = next(e for e, _ in runner.world.query_one(CloudLayer))
    runner.world.remove_component(entity, CloudLayer)
    runner.frame()
    colour, rays = _read(runner)
    np.testing.assert_allclose(colour, sky_radiance(skybox, rays), rtol=4e-3, atol=4e-3)
    assert renderer.clouds.shape is None and not renderer.clouds.shadow_defines
    with pytest.warns(ComponentWarning, match="one sheet of clouds"):
        runner.world.spawn(_still())
        runner.world.spawn(_still(coverage=0.9))
        runner.frame()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        runner.frame()   # (said once)
    with pytest.warns(ComponentWarning, match="given faces"):
        _cloud_frame(scene, Skybox(faces=np.ones((6, 4, 4, 3), np.float32)), _still(), UP_AHEAD)
    with pytest.warns(ComponentWarning, match="no Skybox"):
        runner = scene(lambda world: (world.spawn(_still()), world.spawn(Transform(), Camera())), SIZE)
        runner.frame()


@pytest.mark.parametrize("field, value", [
    ("coverage", 1.5), ("coverage", -0.1), ("density", 65.0), ("height", 5.0), ("scale", 0.0),
    ("thickness", -1.0), ("wind", (300.0, 0.0)), ("wind", "east"), ("wind", (1.0, 2.0, 3.0)),
    ("drift", (math.nan, 0.0)), ("seed", -1), ("seed", 70000), ("color", (-1.0, 0.0, 0.0)), ("shadows", "yes")])
def test_bad_values_are_refused_when_given(field, value):
    with pytest.raises(ComponentValueError, match=field):
        CloudLayer(**{field: value})


def test_a_level_file_gives_clouds_and_saves_them_back(tmp_path):
    from engine.assets.level_read import load_level
    from engine.assets.level_save import save_level
    from engine.core.world import World

    level = tmp_path / "cloudy.toml"
    level.write_text('[level]\nname = "cloudy"\n[[entity]]\nname = "sky"\nSkybox = { model = "atmosphere" }\n'
                     'CloudLayer = { coverage = 0.4, wind = [6.0, 2.0], drift = [120.0, -40.0], seed = 9 }\n')
    world = World()
    load_level(level).spawn(world)
    ((_, layer),) = world.query_one(CloudLayer)
    assert (layer.coverage, layer.wind, layer.drift, layer.seed) == (0.4, (6.0, 2.0), (120.0, -40.0), 9)
    again = World()
    load_level(save_level(world, tmp_path / "again.toml")).spawn(again)
    ((_, copy),) = again.query_one(CloudLayer)
    assert (copy.coverage, copy.wind, copy.drift, copy.seed) == (0.4, (6.0, 2.0), (120.0, -40.0), 9)
    bad = tmp_path / "bad.toml"
    bad.write_text('[level]\nname = "bad"\n[[entity]]\nname = "sky"\nCloudLayer = { coverage = 2.0 }\n')
    from engine.assets.level_read import LevelError

    with pytest.raises(LevelError, match="coverage"):
        load_level(bad)


def test_the_runners_clouds_cover_the_levels_sky(ctx, tmp_path):
    """``--clouds 0.4`` on a game: a CloudLayer of that coverage on its Skybox (one made if it
    has none); a bad share, and clouds over a photographed sky, are one error line each."""
    from engine import Game, spawn_camera
    from shell.app import Engine
    from tests.support import run_level

    class Open(Game):
        def build(self, world):
            spawn_camera(world, position=(0.0, 1.6, 4.0), pitch=5)
            world.spawn(DirectionalLight(intensity=3.0))

    engine = Engine(Open(), ctx)
    try:
        engine.start_sky(None, clouds=0.4)
        engine.frame(1.0, None)
        ((entity, layer),) = engine.world.query_one(CloudLayer)
        assert layer.coverage == 0.4 and engine.world.try_get(entity, Skybox) is not None
        assert layer.drift == pytest.approx((10.0, 0.0))   # (a second of a 10 m/s wind)
        assert engine.renderer.clouds.shape is not None
    finally:
        engine.close()
    panorama = tmp_path / "sky.png"
    from PIL import Image

    Image.new("RGB", (8, 4), (90, 120, 200)).save(panorama)
    for bad, words in ((("--clouds", "1.5"), "--clouds must be"),
                       (("--clouds", "0.5", "--panorama", str(panorama)), "--clouds needs a generated sky")):
        result = run_level("--headless", "--frames", "1", "--size", "16x12", "--out", str(tmp_path / "bad"), *bad)
        assert result.returncode != 0 and words in result.stderr.splitlines()[-1], result.stderr


SHADING = dict(coverage=0.5, scale=40.0, height=80.0, drift=(13.0, 7.0))   # the two tests below


def _sunlit_floor(layer: CloudLayer | None, look=(0.0, -1.0, 0.0)):
    """A grey floor under the sun along ``SHADOW_SUN``, seen from 30 m along ``look``, its sky
    with ``layer`` (None: none)."""
    def build(world):
        world.spawn(Transform(position=(5.0, 30.0, -3.0), rotation=look_rotation(glm.vec3(*look),
                                                                                   glm.vec3(0.0, 0.0, -1.0))),
                    Camera(fov_y=70.0, near=0.5, far=200.0))
        world.spawn(Skybox(**SKY), *([layer] if layer is not None else []))
        world.spawn(DirectionalLight(direction=tuple(SHADOW_SUN), intensity=3.0, shadows=False))
        world.spawn(Transform(), MeshRef(plane(400.0, 400.0)), Material(color=(0.5, 0.5, 0.5), roughness=0.9))
    return build


def test_clouds_given_while_running_shade_the_floor_from_that_frame(scene):
    """A CloudLayer put on the sky after some frames shades the floor from the next frame as a
    world that had it from the start does (each batch's build takes its cloud shadows)."""
    late = scene(_sunlit_floor(None), SIZE)
    late.frame()
    late.frame()
    sky = next(e for e, _ in late.world.query_one(Skybox))
    late.world.add_component(sky, _still(**SHADING))
    shaded = late.frame()
    early = scene(_sunlit_floor(_still(**SHADING)), SIZE)
    early.frame()
    np.testing.assert_array_equal(shaded, early.frame())


def test_an_engine_keeps_its_clouds_beside_another_engine_on_the_context(scene):
    """Two engines on one GL context (an editor's level and its preview, a test's scenes):
    one with clouds draws its sky and their shadows from its own block whatever the other
    has, frame for frame as it drew alone."""
    look = (0.3, -1.0, 0.0)   # (some sky in the picture)
    clouded = scene(_sunlit_floor(_still(**SHADING), look), SIZE)
    alone = [clouded.frame() for _ in range(2)][-1]
    other = scene(_sunlit_floor(_still(**{**SHADING, "coverage": 0.9, "seed": 5}), look), SIZE)
    np.testing.assert_array_equal(clouded.frame(), alone)   # the other made, not drawn yet
    other.frame()
    np.testing.assert_array_equal(clouded.frame(), alone)   # ... and drawn


def test_the_clouds_shadows_move_over_the_floor_with_the_wind_at_its_speed(scene):
    """A wind of (6, -4) m/s for 1.5 s (three half-second frames) moves the clouds' shadows
    (6 m across their finest detail) by (9, -6) m over the floor: the floor seen from over a
    point moved that far shows, pixel for pixel, what the still layer's floor showed from over
    the first point; from over the first point it shows something else."""
    wind, seconds = np.array([6.0, -4.0]), 1.5
    values = dict(coverage=0.5, scale=40.0, height=80.0, drift=(13.0, 7.0))

    def frame(layer, at, frames, dt=0.5):
        def build(world):
            world.spawn(Transform(position=(at[0], 30.0, at[1]), rotation=look_rotation(glm.vec3(0.0, -1.0, 0.0),
                                                                                        glm.vec3(0.0, 0.0, -1.0))),
                        Camera(fov_y=60.0, near=0.5, far=200.0))
            world.spawn(Skybox(**SKY), layer)
            world.spawn(DirectionalLight(direction=tuple(SHADOW_SUN), intensity=3.0, shadows=False))
            world.spawn(Transform(), MeshRef(plane(400.0, 400.0)), Material(color=(0.5, 0.5, 0.5), roughness=0.9))

        runner = scene(build, (64, 48))
        runner.engine.renderer.antialias = "off"
        for _ in range(frames):
            picture = runner.frame(dt=dt).astype(np.float64)
        return picture

    start = np.array([5.0, -3.0])
    still = frame(_still(**values), start, 1)
    blown = CloudLayer(**values, wind=tuple(wind))
    followed = frame(blown, start + wind * seconds, 3)
    np.testing.assert_allclose(blown.drift, np.array(values["drift"]) + wind * seconds, atol=1e-6)
    assert still.std() > 20.0   # (shadows and sunlight both on the floor)
    assert np.abs(followed - still).max() <= 2.0   # (the sRGB rounding; measured 1)
    left = frame(CloudLayer(**values, wind=tuple(wind)), start, 3)
    assert np.abs(left - still).mean() > 10.0
