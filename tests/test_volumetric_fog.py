"""Light shafts (``VolumetricFog``): the sun's single scattering by the camera's fog, in its
shadow map's light, summed along each pixel's ray.

The ground truth is its own: each march texel's ray (from the near plane through its pixel's
centre) is cut where it meets the floor, the wall or a roof slab (slab tests in float64),
and the integral of density x transmittance x visibility along it is summed at 1,000 points,
each point's visibility found by casting its ray towards the sun against the slabs.  The
pass's image is compared with that in bands away from the shadows' and the objects' edges."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from pyglm import glm

from components import (
    CloudLayer,
    ComponentValueError,
    ComponentWarning,
    DirectionalLight,
    Fog,
    Material,
    MeshRef,
    Mirror,
    PointLight,
    Skybox,
    Tonemap,
    Transform,
    VolumetricFog,
    look_rotation,
)
from components.limits import MAX_VOLUMETRIC_LAMPS
from engine.assets.level_file import LevelError, load_level, save_level
from engine.assets.mesh import box, plane, quad
from engine.assets.texture_data import TextureData
from engine.core.errors import LightLimitWarning, NoCameraWarning
from engine.core.world import World
from engine.render.clouds import cloud_shadow, cloud_shape
from engine.render.sky import sunlight_tint
from engine.resources import VolumetricLamps
from engine.rules.light_rules import ALL_ROUND, spot_cone, spot_factor
from shell.overlay_text import post_lines
from tests.support import look_from, srgb_to_linear

SIZE = (160, 96)
EYE = (0.0, 1.6, 9.0)
TARGET = (0.0, 2.4, 0.0)
SUN = glm.normalize(glm.vec3(0.35, -1.0, -0.25))   # the way the sun's light travels
SUN_LIGHT = 3.0
DENSITY = 0.08
# Axis-aligned boxes (centre, size) that stand in the fog: two roof slabs with a gap between
# them, a back wall; the floor is the plane y = 0.
ROOF = [((-3.5, 5.0, 0.0), (5.0, 0.3, 14.0)), ((3.5, 5.0, 0.0), (5.0, 0.3, 14.0))]
WALL = ((0.0, 3.0, -7.0), (14.0, 6.0, 0.3))
FLOOR = 40.0   # the floor's side (metres), about the origin
MIRROR = ((0.5, 2.2, -6.8), (9.0, 4.0, 1e-4))   # a mirror on the wall (its quad, as a thin box)


GAP = ((0.0, 5.0, 0.0), (2.0, 14.0))   # the roof's gap (its middle, its size in x and z): ``_hall``'s ``pane``


def _hall(world, shafts: VolumetricFog | None = None, fog: Fog | None = None, sun: bool = True,
          shadows: bool = True, cascades: int = 1, mirror: bool = False, clouds: CloudLayer | None = None,
          skybox: Skybox | None = None, pane: float | None = None) -> int:
    camera = look_from(world, EYE, TARGET, fov=70.0)
    if pane is not None:   # a see-through pane over the gap, its alpha
        world.spawn(Transform(position=GAP[0], rotation=glm.angleAxis(-np.pi / 2, glm.vec3(1, 0, 0))),
                    MeshRef(quad(*GAP[1])), Material(color=(0.3, 0.4, 0.9, pane), double_sided=True))
    world.spawn(skybox if skybox is not None else Skybox(), *([clouds] if clouds is not None else []))
    if sun:
        world.spawn(DirectionalLight(direction=tuple(SUN), intensity=SUN_LIGHT, shadows=shadows,
                                     shadow_cascades=cascades))
    world.spawn(Transform(), MeshRef(plane(FLOOR, FLOOR)), Material(color=(0.5, 0.5, 0.5)))
    for centre, size in [*ROOF, WALL]:
        world.spawn(Transform(position=centre), MeshRef(box(size)), Material(color=(0.6, 0.5, 0.4)))
    if mirror:  # on the wall, facing the camera
        world.spawn(Transform(position=MIRROR[0]), MeshRef(quad(*MIRROR[1][:2])), Material(), Mirror())
    world.add_component(camera, fog if fog is not None else Fog(density=DENSITY, color=(0.02, 0.02, 0.02)))
    world.add_component(camera, Tonemap(curve="none"))
    if shafts is not None:
        world.add_component(camera, shafts)
    return camera


def _hits(origin: np.ndarray, way: np.ndarray, boxes) -> np.ndarray:
    """The nearest distance along each ray (``origin`` + t ``way``, unit ``way``) at which it
    enters one of ``boxes`` (inf: none), slab tests."""
    nearest = np.full(len(origin), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for centre, size in boxes:
            lo = np.array(centre) - 0.5 * np.array(size)
            hi = np.array(centre) + 0.5 * np.array(size)
            t1, t2 = (lo - origin) / way, (hi - origin) / way
            near, far = np.minimum(t1, t2), np.maximum(t1, t2)
            # (fmax and fmin pass over a NaN, a ray in a slab's face, as nanmax and nanmin do;
            # column by column: a reduce along rows of three took half this file's time)
            t_in = np.fmax(np.fmax(near[:, 0], near[:, 1]), near[:, 2])
            t_out = np.fmin(np.fmin(far[:, 0], far[:, 1]), far[:, 2])
            hit = (t_out >= np.maximum(t_in, 0.0))
            nearest = np.where(hit, np.minimum(nearest, np.maximum(t_in, 0.0)), nearest)
    return nearest


def march_rays(runner, size: tuple[int, int], ratio: int,
               every: int = 1) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
    """Each march texel's ray (``ratio``: the view's pixels a texel each way, of a ``size``
    view; its first pixel's centre): where it starts (the near plane) and its unit direction,
    rows of (of every ``every``-th row and column of) texels, and the grid's shape."""
    view = runner.engine.main_view
    inverse = np.array(glm.inverse(view.view_proj).to_list(), np.float64).T  # (numpy rows)
    width, height = size
    rows, columns = -(-height // ratio), -(-width // ratio)
    ys, xs = np.mgrid[0:rows:every, 0:columns:every]
    px = np.minimum(xs * ratio, width - 1) + 0.5
    py = np.minimum(ys * ratio, height - 1) + 0.5
    ndc = np.stack([px / width * 2 - 1, py / height * 2 - 1], -1).reshape(-1, 2)

    def unproject(z):
        points = np.concatenate([ndc, np.full((len(ndc), 1), z), np.ones((len(ndc), 1))], 1) @ inverse.T
        return points[:, :3] / points[:, 3:]

    origin = unproject(-1.0)
    way = unproject(1.0) - origin
    way /= np.linalg.norm(way, axis=1, keepdims=True)
    return origin, way, xs.shape


def _rays(runner, ratio: int, distance: float, every: int = 1,
          mirror: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``march_rays`` of the hall, and how far each goes (to the floor, the wall or a slab, at
    most ``distance``), by rows of texels."""
    origin, way, shape = march_rays(runner, SIZE, ratio, every)
    with np.errstate(divide="ignore", invalid="ignore"):
        floor = np.where(way[:, 1] < 0, -origin[:, 1] / way[:, 1], np.inf)
    reach = np.minimum(np.minimum(floor, _hits(origin, way, [*ROOF, WALL, *([MIRROR] if mirror else [])])), distance)
    return origin, way, reach.reshape(shape)


def _ground_truth(runner, settings: VolumetricFog, ratio: int, shade: bool = True, every: int = 1,
                  mirror: bool = False, clouds: CloudLayer | None = None,
                  pane: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Each march texel's light (the sun's colour is white: one channel) and its ray's
    length, as the module's docstring says (``shade`` False: no point is in shadow; ``every``
    as ``_rays``; ``clouds``: each point's light through them, their twin's; ``pane``: the
    gap's pane's alpha)."""
    origin, way, reach_grid = _rays(runner, ratio, settings.distance, every, mirror)
    light = _light(origin, way, reach_grid.reshape(-1), settings, shade, clouds, pane)
    return light.reshape(reach_grid.shape), reach_grid


def _light(origin: np.ndarray, way: np.ndarray, reach: np.ndarray, settings: VolumetricFog,
           shade: bool = True, clouds: CloudLayer | None = None, pane: float | None = None) -> np.ndarray:
    """The sun's light the air sends back along each ray (``origin`` + t ``way``, t up to
    ``reach``), summed at 1,000 points (``shade`` False: no point in shadow; ``clouds``: each
    point's share of the sun through them, ``engine/render/clouds.py``'s ``cloud_shadow``;
    ``pane``: 1 - that alpha where the way to the sun crosses the gap's pane)."""
    points = 1000
    t = (np.arange(points) + 0.5) / points
    light_way = -np.array(tuple(SUN))
    total = np.zeros(len(origin))
    for first in range(0, len(origin), 512):
        part = slice(first, first + 512)
        along = reach[part, None] * t[None, :]                       # (rays, points)
        at = origin[part, None, :] + way[part, None, :] * along[..., None]
        flat = at.reshape(-1, 3)
        blocked = np.isfinite(_hits(flat, np.broadcast_to(light_way, flat.shape), ROOF)).reshape(along.shape)
        blocked &= shade
        seen = np.exp(-DENSITY * along)
        through = 1.0 if clouds is None else cloud_shadow(cloud_shape(clouds), at, light_way)
        if pane is not None:   # below the gap's plane, the way to the sun through the pane
            t_pane = (GAP[0][1] - flat[:, 1]) / light_way[1]
            cross = flat + light_way * t_pane[:, None]
            under = (t_pane > 0) & (np.abs(cross[:, 0] - GAP[0][0]) < GAP[1][0] / 2) \
                & (np.abs(cross[:, 2] - GAP[0][2]) < GAP[1][1] / 2)
            through = through * np.where(under, 1.0 - pane, 1.0).reshape(along.shape)
        total[part] = (DENSITY * seen * ~blocked * through).sum(1) * reach[part] / points
    g = settings.anisotropy
    c = way @ light_way
    phase = (1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * c) ** 1.5)
    return SUN_LIGHT * settings.intensity * phase * total


def marched_light(runner) -> np.ndarray:
    images = runner.engine.renderer.volumetric_fog._images
    data = np.frombuffer(images.light.read(), np.float32).reshape(images.light.size[1], images.light.size[0], 4)
    return data


@pytest.mark.parametrize(("half", "cascades", "shadows", "mirror"), [
    (True, 1, True, False), (False, 1, True, False), (True, 3, True, False), (True, 1, False, False),
    (True, 1, True, True)])
def test_each_rays_light_is_the_ground_truths(scene, half, cascades, shadows, mirror):
    """At half and full size; with the sun's cascades (rings about the camera read where
    they hold a point); with a sun that casts no shadow (every point lit); with a mirror on
    the wall (its pixels' rays end on the glass: the air in front of it, not its image's)."""
    settings = VolumetricFog(steps=64, half_resolution=half)
    runner = scene(lambda world: _hall(world, settings, shadows=shadows, cascades=cascades, mirror=mirror), SIZE)
    runner.frame()
    if mirror:
        assert runner.stats.reflection_views == 1
    every = 1 if half else 2  # (at full size every other row and column: the same rays, a quarter of the time)
    marched = marched_light(runner)[::every, ::every]
    truth, reach = _ground_truth(runner, settings, 2 if half else 1, shade=shadows, every=every, mirror=mirror)
    assert marched.shape[:2] == truth.shape
    assert np.allclose(marched[..., 0], marched[..., 2], rtol=1e-4, atol=1e-6)  # a white sun
    # The rays' lengths where they end on a surface or at the distance, away from the edges
    # the depth image's pixels straddle.
    steady = np.abs(reach - np.roll(reach, 1, 0)) + np.abs(reach - np.roll(reach, 1, 1)) < 0.05 * reach
    assert np.median(np.abs(marched[..., 3] - reach)[steady] / reach[steady]) < 0.002
    # The light, where the truth has some, within 7% at 90% of the texels and 2.5% in the
    # median (the march's 64 steps against 1,000 points, the shadow map's texels at the
    # slabs' edges).
    lit = steady & (truth > 0.02 * truth.max())
    error = np.abs(marched[..., 0] - truth)[lit] / truth[lit]
    assert lit.sum() > 0.3 * truth.size
    assert np.median(error) < 0.025
    assert np.quantile(error, 0.9) < 0.07
    if shadows:  # the shaft is there: the rays through the gap's light far above the rest
        assert truth.max() > 3 * np.median(truth[lit])


def test_a_see_through_pane_over_the_gap_lets_its_share_of_the_sun_into_the_shaft(scene):
    """A see-through pane (alpha 0.6) across the roof's gap: the shaft below it takes 0.4 of
    the sun (the sun's see-through map, read by the march at each step), against the ground
    truth with the pane's share taken where the way to the sun crosses it."""
    settings = VolumetricFog(steps=64)
    runner = scene(lambda world: _hall(world, settings, pane=0.6), SIZE)
    runner.frame()
    assert runner.engine.renderer.shadows.see_through_atlas is not None
    marched = marched_light(runner)
    truth, reach = _ground_truth(runner, settings, 2, pane=0.6)
    steady = np.abs(reach - np.roll(reach, 1, 0)) + np.abs(reach - np.roll(reach, 1, 1)) < 0.05 * reach
    lit = steady & (truth > 0.02 * truth.max())
    error = np.abs(marched[..., 0] - truth)[lit] / truth[lit]
    assert lit.sum() > 0.3 * truth.size
    assert np.median(error) < 0.025, np.median(error)
    assert np.quantile(error, 0.9) < 0.07, np.quantile(error, 0.9)


ELSEWHERE = tuple(glm.normalize(glm.vec3(-0.6, -0.5, 0.6)))   # another body's way, far from SUN's


@pytest.mark.parametrize("night", ["moon_outshines_the_sun", "sun_outshines_the_moon", "sun_set_under_air"])
def test_the_sun_or_by_night_the_moon_lights_the_air(scene, night):
    """The shafts and the fog's glow are the light of whichever of the sun and the moon is
    the brighter once an atmosphere has dimmed each (``sky.air_light``): here the body along
    ``SUN``, casting the slabs' shadows, at ``SUN_LIGHT``; the other, along ``ELSEWHERE``,
    lights the scene but not the air.  ``sun_set_under_air``: an atmosphere, the sun (the
    brighter light) below the horizon, where the air lets none of it through."""
    settings = VolumetricFog(steps=64)
    air = night == "sun_set_under_air"
    lit_body = "sun" if night == "sun_outshines_the_moon" else "moon"
    other = "moon" if lit_body == "sun" else "sun"

    def build(world):
        _hall(world, settings, fog=Fog(density=DENSITY, color=(0.02, 0.02, 0.02), sun_scatter=0.5), sun=False,
              skybox=Skybox(model="atmosphere") if air else None)
        world.spawn(DirectionalLight(direction=tuple(SUN), intensity=SUN_LIGHT, body=lit_body))
        set_way = (0.3, 0.2, -0.93) if air else ELSEWHERE   # (below the horizon: travelling up)
        world.spawn(DirectionalLight(direction=set_way, intensity=10.0 if air else 0.2, body=other, shadows=False))
    runner = scene(build, SIZE)
    runner.frame()
    tint = sunlight_tint(Skybox(model="atmosphere"), tuple(SUN)) if air else (1.0, 1.0, 1.0)
    marched = marched_light(runner)
    truth, reach = _ground_truth(runner, settings, 2)
    steady = np.abs(reach - np.roll(reach, 1, 0)) + np.abs(reach - np.roll(reach, 1, 1)) < 0.05 * reach
    lit = steady & (truth > 0.02 * truth.max())
    assert lit.sum() > 0.3 * truth.size and truth.max() > 3 * np.median(truth[lit])   # (the shafts)
    for channel in range(3):
        error = np.abs(marched[..., channel] - truth * tint[channel])[lit] / (truth[lit] * tint[channel])
        assert np.median(error) < 0.025 and np.quantile(error, 0.9) < 0.07, (channel, np.median(error))
    # The fog's glow towards the same body, its light x sun_scatter (x the air's tint).
    block = runner.engine.renderer.fog.block
    assert np.allclose(block[8:11], -np.array(tuple(SUN)), atol=1e-6)
    assert np.allclose(block[12:15], SUN_LIGHT * 0.5 * np.array(tint), rtol=1e-5)


@pytest.mark.parametrize("scale, height, drift, stride", [(20.0, 20.0, (0.0, 0.0), 1),
                                                        (600.0, 200.0, (3427.0, 0.0), 5)])
def test_a_cloud_layers_shadows_dim_the_shafts_as_their_twin_says(scene, scale, height, drift, stride):
    """Clouds 20 m across 20 m over the hall, and 600 m across 200 m up: each point of a ray
    gets the sun's light the cloud on its way lets through (the twin's exp(-depth)) as well as
    the roof's shadow; the march agrees with the truth so summed at every point (as the test
    above), reading the clouds at every step for the small ones and every fifth for the large
    (``clouds.cloud_stride``: linear between), and the clouds take a good share of the light
    away where they stand (the shafts are not the clear sky's)."""
    settings = VolumetricFog(steps=64)
    clouds = CloudLayer(coverage=0.5, scale=scale, height=height, wind=(0.0, 0.0), drift=drift)
    runner = scene(lambda world: _hall(world, settings, clouds=clouds), SIZE)
    runner.frame()
    assert runner.engine.renderer.volumetric_fog.cloud_stride == stride
    marched = marched_light(runner)
    truth, reach = _ground_truth(runner, settings, 2, clouds=clouds)
    clear, _ = _ground_truth(runner, settings, 2)
    steady = np.abs(reach - np.roll(reach, 1, 0)) + np.abs(reach - np.roll(reach, 1, 1)) < 0.05 * reach
    lit = steady & (truth > 0.02 * truth.max())
    error = np.abs(marched[..., 0] - truth)[lit] / truth[lit]
    assert lit.sum() > 0.3 * truth.size
    assert np.median(error) < 0.025
    assert np.quantile(error, 0.9) < 0.07
    share = truth[lit] / clear[lit]
    assert share.min() < 0.3 and share.max() > 0.6   # rays under the clouds' shadows and through their gaps


def _linear(runner) -> np.ndarray:
    """The main view's HDR colour (level 0), linear (rows from the bottom)."""
    targets = runner.engine.renderer.targets
    return np.frombuffer(targets.color.read(), np.float16).reshape(targets.size[1], targets.size[0], 4)[..., :3]


def _filtered(marched: np.ndarray, reach: np.ndarray, ratio: int, counts: np.ndarray | None = None) -> np.ndarray:
    """The filter's sum written again in numpy: each pixel's 3 x 3 texels about it, by a
    Gaussian of the distance in texels times 2^-(length gap / (5% of its length + 5 cm))
    (``counts``: the texels that may be taken, the others weigh 0)."""
    rows, columns = reach.shape
    ys, xs = np.mgrid[0:rows, 0:columns]
    at_x, at_y = xs / ratio, ys / ratio
    base_x, base_y = np.floor(at_x + 0.5).astype(int) - 1, np.floor(at_y + 0.5).astype(int) - 1
    tolerance = 0.05 * reach + 0.05
    total = np.zeros((rows, columns))
    weights = np.zeros((rows, columns))
    for dy in range(3):
        for dx in range(3):
            qx = np.clip(base_x + dx, 0, marched.shape[1] - 1)
            qy = np.clip(base_y + dy, 0, marched.shape[0] - 1)
            found = marched[qy, qx]
            d2 = (base_x + dx - at_x) ** 2 + (base_y + dy - at_y) ** 2
            w = np.exp(-0.5 * d2) * np.exp2(-np.abs(found[..., 3] - reach) / tolerance)
            if counts is not None:
                w = np.where(counts[qy, qx], w, 0.0)
            total += found[..., 0] * w
            weights += w
    with np.errstate(invalid="ignore"):
        return total / weights   # (NaN where no texel may be taken)


def _added(scene, settings: VolumetricFog, mirror: bool = False) -> tuple[np.ndarray, object]:
    """What ``settings``' shafts add to the hall's HDR colour (linear, rows from the bottom),
    and the runner drawn with them (``mirror``: the hall's mirror on its wall)."""
    with_shafts = scene(lambda world: _hall(world, settings, mirror=mirror), SIZE)
    with_shafts.frame()
    plain = scene(lambda world: _hall(world, mirror=mirror), SIZE)
    plain.frame()
    return _linear(with_shafts).astype(np.float64) - _linear(plain).astype(np.float64), with_shafts


def test_the_filter_adds_the_light_to_every_pixel(scene):
    """The view's colour with shafts less the same view's without is the march's light
    filtered up to each pixel: by the texels about it, weighed by their distance and their
    rays' lengths against the pixel's own (its ray's length found by the slab tests)."""
    settings = VolumetricFog(steps=64)
    added, with_shafts = _added(scene, settings)
    _, _, reach = _rays(with_shafts, 1, settings.distance)
    expected = _filtered(marched_light(with_shafts).astype(np.float64), reach, 2)
    assert np.allclose(added[..., 0], added[..., 2], atol=2e-3)
    assert added.min() > -2e-3  # light only added
    close = np.abs(added[..., 0] - expected) < 2e-3 + 0.02 * expected
    assert close.mean() > 0.97   # (the rest: pixels on an edge the depth image's pixel straddles)
    assert expected.max() > 0.1


def test_passes_images_and_their_release(scene):
    runner = scene(lambda world: _hall(world, VolumetricFog()), SIZE)
    runner.frame()
    stats_on = runner.stats.passes
    counts = runner.engine.renderer.resource_counts()
    assert counts["volumetric_targets"] == 1
    assert runner.engine.renderer.volumetric_fog.composites == 1
    assert "; shafts 32 steps half" in post_lines(runner.engine)[1]   # the overlay's screen line
    camera = runner.engine.active_camera()[0]
    runner.world.remove_component(camera, VolumetricFog)
    runner.frame()
    assert runner.stats.passes == stats_on - 2
    assert runner.engine.renderer.resource_counts()["volumetric_targets"] == 0
    runner.world.add_component(camera, VolumetricFog())
    runner.frame()
    assert runner.engine.renderer.resource_counts()["volumetric_targets"] == 1
    with pytest.warns(NoCameraWarning):
        runner.world.delete_entity(camera)   # the camera goes: its images with it
        runner.frame()
    assert runner.engine.renderer.resource_counts()["volumetric_targets"] == 0


@pytest.mark.parametrize(("field", "value"), [("intensity", -1.0), ("intensity", float("nan")),
                                              ("anisotropy", 0.99), ("distance", 0.0), ("steps", 2),
                                              ("steps", 3.5), ("half_resolution", 1), ("albedo", (1.0, 1.2, 0.5)),
                                              ("albedo", (1.0, -0.1, 0.5)), ("albedo", (1.0, 0.5)),
                                              ("albedo", (float("nan"), 0.5, 0.5))])
def test_bad_values_are_refused_naming_the_field(field, value):
    with pytest.raises(ComponentValueError, match=field):
        VolumetricFog(**{field: value})


def test_the_albedo_and_intensity_scatter_each_colour_by_their_share(scene):
    """``VolumetricFog.albedo``: each channel of the march is the white air's times its share
    (the same steps at the same points: to float rounding), the sun's shafts and the
    lamps' alike, and times ``intensity`` (2.5 here: the air's scattering boosted); given
    while running (a still camera, its march kept) it is marched again the next frame."""
    white = scene(lambda world: _hall(world, VolumetricFog(steps=32)), SIZE)
    white.frame()
    plain = marched_light(white)[..., :3].astype(np.float64)
    share = np.array([1.0, 0.5, 0.25])
    tinted = scene(lambda world: _hall(world, VolumetricFog(steps=32, albedo=tuple(share), intensity=2.5)), SIZE)
    tinted.frame()
    np.testing.assert_allclose(marched_light(tinted)[..., :3], plain * share * 2.5, rtol=1e-5, atol=1e-8)
    assert plain.max() > 0.05
    white.frame()   # (still: the march kept)
    marches = white.engine.renderer.volumetric_fog.marches
    camera = next(entity for entity, _ in white.world.query_one(VolumetricFog))
    white.world.get(camera, VolumetricFog).albedo = (0.25, 0.5, 1.0)
    white.frame()
    assert white.engine.renderer.volumetric_fog.marches == marches + 1
    np.testing.assert_allclose(marched_light(white)[..., :3], plain * share[::-1], rtol=1e-5, atol=1e-8)


@pytest.mark.parametrize("what", ["no fog", "no density", "no sun"])
def test_without_air_or_sun_it_says_so_once_and_adds_nothing(scene, what):
    fog = Fog(density=0.0) if what == "no density" else None

    def build(world):
        camera = _hall(world, VolumetricFog(), fog=fog, sun=what != "no sun")
        if what == "no fog":
            world.remove_component(camera, Fog)
    runner = scene(build, SIZE)
    with pytest.warns(ComponentWarning, match="VolumetricFog on entity .* adds nothing"):
        runner.frame()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        runner.frame()
    assert runner.engine.renderer.volumetric_fog.composites == 0
    assert runner.engine.renderer.resource_counts()["volumetric_targets"] == 0


def test_a_level_file_keeps_it(tmp_path):
    (tmp_path / "hall.toml").write_text("""[level]
name = "hall"

[[entity]]
name = "camera"
Transform = { position = [0.0, 1.0, 3.0] }
Camera = {}
Fog = { density = 0.1 }

[entity.VolumetricFog]
intensity = 2.0
anisotropy = 0.3
distance = 25.0
steps = 16
half_resolution = false
albedo = [1.0, 0.8, 0.5]
""")
    world = World()
    names = load_level(tmp_path / "hall.toml").spawn(world)
    shafts = world.get(names["camera"], VolumetricFog)
    assert (shafts.intensity, shafts.anisotropy, shafts.distance, shafts.steps, shafts.half_resolution) == (
        pytest.approx(2.0), pytest.approx(0.3), pytest.approx(25.0), 16, False)
    saved = save_level(world, tmp_path / "again.toml", names, name="hall")
    again = World()
    names = load_level(saved).spawn(again)
    assert again.get(names["camera"], VolumetricFog).steps == 16
    assert tuple(again.get(names["camera"], VolumetricFog).albedo) == pytest.approx((1.0, 0.8, 0.5))
    (tmp_path / "bad.toml").write_text(
        '[level]\nname = "bad"\n\n[[entity]]\nname = "camera"\nCamera = {}\nVolumetricFog = { steps = 1 }\n')
    with pytest.raises(LevelError, match="steps"):
        load_level(tmp_path / "bad.toml")


def test_under_temporal_aa_each_frame_starts_the_points_elsewhere(scene):
    """A still view marches the same points every frame with FXAA, and other points each
    frame under temporal AA (whose history averages them), the light about the same."""
    images = {}
    for antialias in ("fxaa", "taa"):
        runner = scene(lambda world: _hall(world, VolumetricFog(steps=16)), SIZE)
        runner.engine.renderer.antialias = antialias
        runner.frame()
        first = marched_light(runner).copy()
        runner.frame()
        images[antialias] = (first, marched_light(runner).copy())
    assert np.array_equal(*images["fxaa"])
    first, second = images["taa"]
    assert not np.array_equal(first[..., 0], second[..., 0])
    assert abs(first[..., 0].mean() / second[..., 0].mean() - 1.0) < 0.03


def _level_marched(runner, depth: int) -> np.ndarray:
    images = runner.engine.renderer.volumetric_fog._levels[depth]
    return np.frombuffer(images.light.read(), np.float32).reshape(images.light.size[1], images.light.size[0], 4)


def _level_colour(runner, depth: int = 1) -> np.ndarray:
    targets = runner.engine.renderer.levels[depth]
    return np.frombuffer(targets.color.read(), np.float16).reshape(targets.size[1], targets.size[0], 4)[..., :3]


def _mirror_rays(runner) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each pixel's camera ray reflected in the mirror on the wall (the plane z = MIRROR's,
    facing +z): where it meets the glass, its reflected direction, how far it goes on (to
    the floor or a slab, at most the shafts' distance), and whether it meets the glass well
    inside its outline (3 pixels' worth of margin), by rows of pixels."""
    view = runner.engine.main_view
    inverse = np.array(glm.inverse(view.view_proj).to_list(), np.float64).T
    width, height = SIZE
    ys, xs = np.mgrid[0:height, 0:width]
    ndc = np.stack([(xs + 0.5) / width * 2 - 1, (ys + 0.5) / height * 2 - 1], -1).reshape(-1, 2)

    def unproject(z):
        points = np.concatenate([ndc, np.full((len(ndc), 1), z), np.ones((len(ndc), 1))], 1) @ inverse.T
        return points[:, :3] / points[:, 3:]

    near = unproject(-1.0)
    way = unproject(1.0) - near
    way /= np.linalg.norm(way, axis=1, keepdims=True)
    (cx, cy, cz), (w, h, _) = MIRROR
    t = (cz - near[:, 2]) / way[:, 2]
    glass = near + way * t[:, None]
    margin = 3 * 2 * np.tan(np.radians(35.0)) * t / height   # 3 pixels at the glass's distance
    inside = (np.abs(glass[:, 0] - cx) < 0.5 * w - margin) & (np.abs(glass[:, 1] - cy) < 0.5 * h - margin)
    bounced = way * np.array([1.0, 1.0, -1.0])
    with np.errstate(divide="ignore", invalid="ignore"):
        floor = np.where(bounced[:, 1] < 0, -glass[:, 1] / bounced[:, 1], np.inf)
    landing = glass + bounced * np.where(np.isfinite(floor), floor, 0.0)[:, None]
    floor = np.where(np.abs(landing[:, [0, 2]]).max(1) <= 0.5 * FLOOR, floor, np.inf)   # (the floor's edge)
    reach = np.clip(np.minimum(floor, _hits(glass, bounced, ROOF)), 0.0, 40.0)   # (0: a ray that misses the glass)
    return glass, bounced, reach, inside.reshape(height, width)


def test_a_mirrors_view_marches_the_air_it_shows_from_the_glass(scene):
    """The mirror's level: each of its pixels' ray starts on the glass and goes on as the
    camera's ray reflected; its light is the ground truth's for that ray (the composite then
    dims it with the rest of the reflection by the air in front of the glass)."""
    settings = VolumetricFog(steps=64)
    runner = scene(lambda world: _hall(world, settings, mirror=True), SIZE)
    runner.frame()
    assert runner.stats.reflection_views == 1
    level = runner.engine.renderer.levels[1]
    assert level.size == SIZE
    marched = _level_marched(runner, 1)
    nodes = np.frombuffer(level.node.read(), np.uint32).reshape(SIZE[1], SIZE[0])
    origin, way, reach, inside = _mirror_rays(runner)
    mirror_node = np.bincount(nodes[inside]).argmax()
    ours = inside & (nodes == mirror_node)
    assert ours.sum() > 300
    truth = _light(origin, way, reach, settings).reshape(SIZE[1], SIZE[0])
    reach = reach.reshape(SIZE[1], SIZE[0])
    steady = np.abs(reach - np.roll(reach, 1, 0)) + np.abs(reach - np.roll(reach, 1, 1)) < 0.05 * reach
    check = ours & steady
    assert np.median(np.abs(marched[..., 3] - reach)[check] / reach[check]) < 0.002
    error = np.abs(marched[..., 0] - truth)[check] / truth[check]
    assert np.median(error) < 0.025
    assert np.quantile(error, 0.9) < 0.07
    assert truth[check].max() > 2 * np.median(truth[check])   # the reflected rays cross the shaft too
    # Added to the level's colour by the filter, within the mirror's own pixels (against the
    # same level at depth 0, with nothing added): its numpy twin, the texels of its own view.
    unlit = scene(lambda world: _hall(world, VolumetricFog(steps=64, reflection_depth=0), mirror=True), SIZE)
    unlit.frame()
    added = _level_colour(runner).astype(np.float64) - _level_colour(unlit).astype(np.float64)
    expected = _filtered(marched.astype(np.float64), reach, 1, counts=nodes == mirror_node)
    close = np.abs(added[..., 0] - expected) < 2e-3 + 0.02 * expected
    assert close[check].mean() > 0.97
    assert np.abs(added[nodes != mirror_node]).max() < 2e-3   # nothing added to the room's pixels


def test_reflection_depth_zero_keeps_the_shafts_to_the_camera_and_the_levels_images_go(scene):
    runner = scene(lambda world: _hall(world, VolumetricFog(), mirror=True), SIZE)
    runner.frame()
    fog = runner.engine.renderer.volumetric_fog
    assert fog.composites == 2 and runner.engine.renderer.resource_counts()["volumetric_targets"] == 2
    passes = runner.stats.passes
    camera = runner.engine.active_camera()[0]
    runner.world.get(camera, VolumetricFog).reflection_depth = 0
    runner.frame()   # (the root's march stands: nothing it reads moved; its filter draws again)
    assert fog.composites == 3 and fog.marches == 2 and runner.stats.passes == passes - 3
    assert runner.engine.renderer.resource_counts()["volumetric_targets"] == 1
    runner.world.get(camera, VolumetricFog).reflection_depth = 1
    runner.frame()
    assert fog.composites == 5
    for entity, _ in list(runner.world.query_one(Mirror)):
        runner.world.delete_entity(entity)
    runner.frame()
    assert runner.engine.renderer.resource_counts()["volumetric_targets"] == 1


@pytest.mark.parametrize("pair", ["mirrors", "portals"])
def test_a_still_tree_with_shafts_in_its_levels_refills_as_it_draws_whole(ctx, pair):
    """A facing pair with end images, kept and refilled by a still camera: its levels get
    shafts (added over what their pixels hold), so a refill must put each level back before
    adding them again.  Against an engine drawing every frame whole (the still fuzz's
    check); with the refill's copy of such a level left out, the frames differ (both pairs)."""
    from benchmarks.still_fuzz import StillCase, StillFuzzer

    case = StillCase(pair=pair, depth=3, panes=[], water=False, see_through_mirror=False, sandwich=None, still=5,
                     change="depth_cap", detail={"cap": 8}, after=3, rate=1.0, fog=True, shafts=True)
    fuzzer = StillFuzzer(ctx)
    try:
        assert fuzzer.run(case) is None
        assert fuzzer.refills >= 3
    finally:
        fuzzer.close()


# --- lamps (PointLight.volumetric) ----------------------------------------------------------
LAMP = (0.0, 4.0, 0.0)            # a spot shining straight down, a box in its cone
LAMP_LIGHT = 20.0
LAMP_RANGE = 12.0
LAMP_ANGLE, LAMP_BLEND = 35.0, 0.2
CAGE = ((0.7, 2.5, 0.0), (0.5, 0.5, 0.5))


# A see-through pane level in the beam over the box (``_lamp_hall``'s ``pane``): its centre, its side.
PANE = ((0.0, 3.2, 0.0), 1.2)


def _lamp_hall(world, shafts: VolumetricFog | None, lamps: int = 1, volumetric: float = 1.0,
               cookie: TextureData | None = None, panel: bool = False, tube: bool = False,
               pane: float | None = None) -> int:
    camera = look_from(world, (0.0, 2.0, 7.0), (0.0, 2.0, 0.0), fov=60.0)
    if pane is not None:   # its alpha: it lets 1 - alpha of the lamp's light through
        world.spawn(Transform(position=PANE[0], rotation=glm.angleAxis(-np.pi / 2, glm.vec3(1, 0, 0))),
                    MeshRef(quad(PANE[1], PANE[1])), Material(color=(0.3, 0.4, 0.9, pane), double_sided=True))
    world.spawn(Skybox())
    world.spawn(Transform(), MeshRef(plane(FLOOR, FLOOR)), Material(color=(0.5, 0.5, 0.5)))
    world.spawn(Transform(position=CAGE[0]), MeshRef(box(CAGE[1])), Material(color=(0.6, 0.5, 0.4)))
    for k in range(lamps):
        at = glm.vec3(LAMP) + glm.vec3(0.0, 0.0, -3.0 * k)
        world.spawn(Transform(position=at, rotation=look_rotation(glm.vec3(0.0, -1.0, 0.0))),
                    PointLight(intensity=LAMP_LIGHT, range=LAMP_RANGE,
                               spot_angle=180.0 if panel or tube else LAMP_ANGLE, spot_blend=LAMP_BLEND,
                               shadows=k == 0, volumetric=volumetric, cookie=cookie,
                               rectangle=(0.6, 0.6) if panel else (0.0, 0.0), length=TUBE if tube else 0.0))
    world.add_component(camera, Fog(density=DENSITY, color=(0.02, 0.02, 0.02)))
    world.add_component(camera, Tonemap(curve="none"))
    if shafts is not None:
        world.add_component(camera, shafts)
    return camera


# A tube lamp's length (its axis the lamp entity's X: level, as it looks down).
TUBE = 1.2


def _lamp_light(origin: np.ndarray, way: np.ndarray, reach: np.ndarray, settings: VolumetricFog,
                panel: bool = False, tube: bool = False, pane: float | None = None) -> np.ndarray:
    """The lamp's light the air sends back along each ray, at 1,000 points: its falloff (the
    inverse square faded to 0 at its range), its cone (``light_rules.spot_factor``), the
    phase function, the box's shadow (the point's segment to the lamp cast against it);
    ``panel``: all round, a rectangle facing down (Lambert's cosine of its face, 0 above it);
    ``tube``: all round, a tube along the lamp's X (the sine of the way's angle from its axis:
    its outline's width); ``pane``: the see-through pane's alpha, its share of the light taken
    where the segment to the lamp crosses it."""
    cone = ALL_ROUND if panel or tube else spot_cone((0.0, -1.0, 0.0), LAMP_ANGLE, LAMP_BLEND)
    axis = np.array(glm.mat3_cast(look_rotation(glm.vec3(0.0, -1.0, 0.0)))[0], np.float64)
    points = 1000
    t = (np.arange(points) + 0.5) / points
    lamp = np.array(LAMP)
    total = np.zeros(len(origin))
    g = settings.anisotropy
    for first in range(0, len(origin), 256):
        part = slice(first, first + 256)
        along = reach[part, None] * t[None, :]
        at = (origin[part, None, :] + way[part, None, :] * along[..., None]).reshape(-1, 3)
        to_lamp = lamp - at
        dist = np.linalg.norm(to_lamp, axis=1)
        l = to_lamp / dist[:, None]
        fade = np.clip(1.0 - (dist / LAMP_RANGE) ** 4, 0.0, 1.0)
        falloff = fade * fade / (dist * dist + 1.0) * spot_factor(cone, l)
        if panel:
            falloff *= np.maximum(l[:, 1], 0.0)   # (-l the way from the lamp; its face looks down)
        if tube:
            falloff *= np.linalg.norm(np.cross(l, axis), axis=1)
        blocked = _hits(at, l, [CAGE]) < dist
        if pane is not None:   # where the segment to the lamp crosses the pane's plane
            with np.errstate(divide="ignore", invalid="ignore"):
                t_pane = (PANE[0][1] - at[:, 1]) / l[:, 1]
            cross = at + l * t_pane[:, None]
            through = (t_pane > 0) & (t_pane < dist) & (np.abs(cross[:, 0] - PANE[0][0]) < PANE[1] / 2) \
                & (np.abs(cross[:, 2] - PANE[0][2]) < PANE[1] / 2)
            falloff = falloff * np.where(through, 1.0 - pane, 1.0)
        c = np.einsum("ij,ij->i", np.repeat(way[part], points, 0), l)
        phase = (1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * c) ** 1.5)
        light = (falloff * phase * ~blocked).reshape(along.shape)
        total[part] = (DENSITY * np.exp(-DENSITY * along) * light).sum(1) * reach[part] / points
    return LAMP_LIGHT * settings.intensity * total


def test_a_spot_lights_beam_in_the_air_is_the_ground_truths(scene):
    """No sun: a spot light's cone lit in the fog, the box in it casting its shadow down the
    beam (the spot's shadow map), against the ground truth along each march texel's ray (128
    steps: the beam is a metre or two across, its light peaked, and the steps' offsets
    scatter the sum by a tenth at 64, in both directions)."""
    settings = VolumetricFog(steps=128)
    runner = scene(lambda world: _lamp_hall(world, settings), SIZE)
    runner.frame()
    marched, truth, reach, lit, steady = _lamp_march_and_truth(runner, settings)
    assert lit.sum() > 200
    error = np.abs(marched[..., 0] - truth)[lit] / truth[lit]
    assert np.median(error) < 0.02
    assert np.quantile(error, 0.9) < 0.06
    assert np.abs(marched[..., 0] - truth)[steady & (truth < 0.05 * truth.max())].max() < 0.06 * truth.max()


def test_a_see_through_pane_in_a_spots_beam_lets_its_share_through_the_air_below(scene):
    """A see-through pane (alpha 0.6) across the beam over the box: the air below it takes
    0.4 of the lamp's light (the lamps' see-through map, read by the march as by the scene
    pass), against the same ground truth with the pane's share taken where the way to the
    lamp crosses it."""
    settings = VolumetricFog(steps=128)
    runner = scene(lambda world: _lamp_hall(world, settings, pane=0.6), SIZE)
    runner.frame()
    assert runner.engine.renderer.shadows.lamp_see_through_atlas is not None
    marched, truth, reach, lit, steady = _lamp_march_and_truth(runner, settings, pane=0.6)
    assert lit.sum() > 100
    error = np.abs(marched[..., 0] - truth)[lit] / truth[lit]
    assert np.median(error) < 0.03, np.median(error)
    assert np.quantile(error, 0.9) < 0.08, np.quantile(error, 0.9)


@pytest.mark.parametrize("shape", ["panel", "tube"])
def test_a_lamp_with_a_shape_lights_the_air_by_its_outline(scene, shape):
    """No sun: the lamp a 0.6 m panel facing down (``PointLight.rectangle``: the air below it
    lit by Lambert's cosine of its face, the air above its plane not at all, as a point light
    all round would light it) or a 1.2 m level tube (``PointLight.length``: by the sine of each
    way's angle from its axis, its outline's width; end on, nothing), against the same ground
    truth with that cosine or sine."""
    settings = VolumetricFog(steps=128)
    runner = scene(lambda world: _lamp_hall(world, settings, **{shape: True}), SIZE)
    runner.frame()
    marched, truth, reach, lit, steady = _lamp_march_and_truth(runner, settings, **{shape: True})
    assert lit.sum() > 200
    error = np.abs(marched[..., 0] - truth)[lit] / truth[lit]
    assert np.median(error) < 0.03, np.median(error)
    assert np.quantile(error, 0.9) < 0.08, np.quantile(error, 0.9)


def _lamp_march_and_truth(runner, settings: VolumetricFog, panel: bool = False, tube: bool = False,
                          pane: float | None = None):
    """The march's texels and the lamp's ground truth along each texel's ray, its length, the
    texels compared (lit, steady, not within a metre of the lamp) and the steady ones."""
    marched = marched_light(runner)
    view = runner.engine.main_view
    inverse = np.array(glm.inverse(view.view_proj).to_list(), np.float64).T
    width, height = SIZE
    ys, xs = np.mgrid[0:height // 2, 0:width // 2]
    ndc = np.stack([(xs * 2 + 0.5) / width * 2 - 1, (ys * 2 + 0.5) / height * 2 - 1], -1).reshape(-1, 2)
    ends = [np.concatenate([ndc, np.full((len(ndc), 1), z), np.ones((len(ndc), 1))], 1) @ inverse.T for z in (-1, 1)]
    origin = ends[0][:, :3] / ends[0][:, 3:]
    way = ends[1][:, :3] / ends[1][:, 3:] - origin
    way /= np.linalg.norm(way, axis=1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        floor = np.where(way[:, 1] < 0, -origin[:, 1] / way[:, 1], np.inf)
    reach = np.minimum(np.minimum(floor, _hits(origin, way, [CAGE])), settings.distance)
    truth = _lamp_light(origin, way, reach, settings, panel, tube, pane).reshape(xs.shape)
    reach = reach.reshape(xs.shape)
    steady = np.abs(reach - np.roll(reach, 1, 0)) + np.abs(reach - np.roll(reach, 1, 1)) < 0.1 * reach
    # (Not the rays that pass within a metre of the lamp: there the light peaks sharper than
    # the march's steps, 8 cm apart, can follow.)
    passing = np.linalg.norm(np.cross(np.array(LAMP) - origin, way), axis=1).reshape(xs.shape)
    lit = steady & (truth > 0.05 * truth.max()) & (passing > 1.0)
    return marched, truth, reach, lit, steady


def test_lamps_past_the_limit_are_cut_and_said_and_a_lamp_at_zero_lights_no_air(scene):
    runner = scene(lambda world: _lamp_hall(world, VolumetricFog(steps=8), lamps=MAX_VOLUMETRIC_LAMPS + 1), SIZE)
    with pytest.warns(LightLimitWarning, match="volumetric_lamps_cut"):
        runner.frame()
    assert runner.stats.volumetric_lamps_cut == 1
    assert len(runner.world.resources[VolumetricLamps].slots) == MAX_VOLUMETRIC_LAMPS
    dark = scene(lambda world: _lamp_hall(world, VolumetricFog(steps=8), volumetric=0.0), SIZE)
    with pytest.warns(ComponentWarning, match="no such PointLight"):
        dark.frame()
    assert dark.engine.renderer.volumetric_fog.composites == 0


def test_the_shafts_flag_gives_the_camera_shafts_and_thin_air_where_it_has_none(scene):
    """``--shafts`` (``Engine.start(shafts=True)``): a ``VolumetricFog()``, and a
    ``Fog(density=SHAFTS_FOG_DENSITY)`` on a camera with no Fog; a camera's own Fog is kept."""
    from shell.app import SHAFTS_FOG_DENSITY

    def sunlit(world) -> None:   # (a camera and a sun, no fog)
        look_from(world, EYE, TARGET)
        world.spawn(DirectionalLight(direction=tuple(SUN)))

    bare = scene(sunlit, SIZE)
    bare.engine.start(shafts=True)
    camera = bare.engine.active_camera()[0]
    assert bare.world.get(camera, Fog).density == pytest.approx(SHAFTS_FOG_DENSITY)
    assert bare.world.has(camera, VolumetricFog)
    bare.frame()
    assert bare.engine.renderer.volumetric_fog.composites == 1
    own = scene(lambda world: _hall(world), SIZE)
    own.engine.start(shafts=True)
    camera = own.engine.active_camera()[0]
    assert own.world.get(camera, Fog).density == pytest.approx(DENSITY)
    assert own.world.has(camera, VolumetricFog)


def test_a_lamps_cookie_colours_its_light_in_the_air(scene):
    """A spot with an amber cookie (one colour all over, so whatever its frame): the light its
    beam puts in the air is the plain beam's times the cookie's linear colour, channel by
    channel."""
    amber = (255, 96, 16)
    pixels = np.zeros((8, 8, 4), np.uint8)
    pixels[...] = (*amber, 255)
    plain = scene(lambda world: _lamp_hall(world, VolumetricFog(steps=32)), SIZE)
    plain.frame()
    tinted = scene(lambda world: _lamp_hall(world, VolumetricFog(steps=32),
                                           cookie=TextureData(pixels, name="amber")), SIZE)
    tinted.frame()
    white, coloured = marched_light(plain)[..., :3], marched_light(tinted)[..., :3]
    lit = white[..., 0] > 0.1 * white[..., 0].max()
    assert lit.sum() > 100
    expected = srgb_to_linear(np.array(amber, np.float64))
    ratio = np.median(coloured[lit] / white[lit], axis=0)
    assert np.allclose(ratio, expected, rtol=0.03, atol=0.003), (ratio, expected)


def test_a_panels_image_colours_its_light_in_the_air_by_its_mean(scene):
    """A panel lamp showing an image on its face (``PointLight.cookie`` on a rectangle), red on
    its left half and blue on its right: the air takes the image's mean colour (half red,
    half blue), channel by channel, of the plain panel's light."""
    pixels = np.zeros((16, 16, 4), np.uint8)
    pixels[..., 3] = 255
    pixels[:, :8, 0] = 255
    pixels[:, 8:, 2] = 255
    plain = scene(lambda world: _lamp_hall(world, VolumetricFog(steps=32), panel=True), SIZE)
    plain.frame()
    imaged = scene(lambda world: _lamp_hall(world, VolumetricFog(steps=32), panel=True,
                                            cookie=TextureData(pixels, name="red and blue")), SIZE)
    imaged.frame()
    white, coloured = marched_light(plain)[..., :3], marched_light(imaged)[..., :3]
    lit = white[..., 0] > 0.1 * white[..., 0].max()
    assert lit.sum() > 100
    ratio = np.median(coloured[lit] / white[lit], axis=0)
    assert np.allclose(ratio, (0.5, 0.0, 0.5), rtol=0.03, atol=0.005), ratio


def test_a_pane_keeps_of_the_shafts_what_it_keeps_of_all_behind_it(scene):
    """Glass is drawn after the shafts and blended over them: along a pane of alpha 0.5 half
    the shafts' light stays, the air's in front of the pane too (the documented limit)."""
    def build(shafts: bool, pane: bool):
        def run(world) -> None:
            _hall(world, VolumetricFog(steps=32) if shafts else None)
            if pane:
                world.spawn(Transform(position=(-1.5, 2.2, 5.0)), MeshRef(quad(2.0, 2.0)),
                            Material(color=(0.5, 0.5, 0.5, 0.5), roughness=1.0))
        return run

    frames = {}
    for shafts in (False, True):
        for pane in (False, True):
            runner = scene(build(shafts, pane), SIZE)
            runner.frame()
            frames[shafts, pane] = _linear(runner).astype(np.float64)[..., 0]
    covered = np.abs(frames[False, True] - frames[False, False]) > 1e-3
    assert covered.sum() > 500
    behind = frames[True, True] - frames[False, True]
    open_air = frames[True, False] - frames[False, False]
    assert np.median(behind[covered] / np.maximum(open_air[covered], 1e-4)) == pytest.approx(0.5, abs=0.02)


def test_a_still_view_marches_once_and_draws_what_marching_every_frame_draws(scene):
    """The root's march is kept while nothing it reads moves (the scene's rows, the shadow
    maps and blocks: ``Gpu.scene_version``; the camera; the settings; the lamps): later frames
    draw the filter alone, the same bytes as an engine that marches every frame; a moved box
    or a turned camera marches again, temporal AA's moving offsets every frame."""
    keeping = scene(lambda world: _hall(world, VolumetricFog(steps=16)), SIZE)
    marching = scene(lambda world: _hall(world, VolumetricFog(steps=16)), SIZE)
    marching.engine.renderer.volumetric_fog.keep_still = False
    for _ in range(3):
        assert np.array_equal(keeping.frame(), marching.frame())
    fog = keeping.engine.renderer.volumetric_fog
    assert (fog.marches, fog.composites) == (1, 3)
    assert (marching.engine.renderer.volumetric_fog.marches, keeping.stats.passes) == (3, marching.stats.passes - 1)
    for runner in (keeping, marching):   # a slab moves: its shadow in the air with it
        slab = next(e for e, (t, _) in runner.world.query(Transform, MeshRef) if t.position.y == 5.0)
        runner.world.get(slab, Transform).position = glm.vec3(-3.3, 5.0, 0.0)
    assert np.array_equal(keeping.frame(), marching.frame())
    assert fog.marches == 2
    keeping.engine.place_camera(0.2, 1.6, 9.0, 5.0, 0.0)
    keeping.frame()
    assert fog.marches == 3
    keeping.engine.renderer.antialias = "taa"
    keeping.frame()
    keeping.frame()
    assert fog.marches == 5


WATER_DENSITY = 0.3   # a murky pond's body (Water.fog_density), its surface at y = 0, 6 m deep
AIR_DENSITY = 0.002   # the camera's own thin air


# (Tinted: no channel denser than the grey water's: the march's error in a texel grows with the
# density times its step, as the light it loses within a step.)
@pytest.mark.parametrize("absorption", [(1.0, 1.0, 1.0), (1.0, 0.5, 0.2)], ids=["grey", "tinted"])
def test_under_a_waters_body_the_shafts_light_comes_down_through_the_water(scene, absorption):
    """A camera under a murky pond (a water's body, as a volume of the fog) with light shafts
    and a sun straight down: each march texel's light is the ground truth's sum along its ray
    of density x transmittance x the sun's light at the point, which came down through the
    water over it (exp(-density x its depth)), not the sun's whole light; channel by channel,
    each with the water's density times its share (``Water.absorption``)."""
    from components import Camera, Water

    settings = VolumetricFog(steps=64, half_resolution=True)
    eye = glm.vec3(0.0, -1.0, 0.0)

    def build(world):
        world.spawn(Transform(position=eye, rotation=look_rotation(glm.vec3(0.0, -0.3, -1.0))),
                    Camera(fov_y=60.0, far=60.0), Fog(density=AIR_DENSITY, color=(0.0, 0.0, 0.0)), settings,
                    Tonemap(curve="none"))
        world.spawn(Skybox(faces=[np.zeros((8, 8, 3), np.float32) for _ in range(6)]))
        world.spawn(DirectionalLight(direction=(0.0, -1.0, 0.0), intensity=SUN_LIGHT, shadows=False))
        world.spawn(Transform(position=(0.0, -6.0, 0.0)), MeshRef(plane(FLOOR, FLOOR)), Material(color=(0.5,) * 3))
        world.spawn(Transform(rotation=glm.angleAxis(-np.pi / 2, glm.vec3(1, 0, 0))), MeshRef(quad(FLOOR, FLOOR)),
                    Material(color=(1.0, 1.0, 1.0, 0.0)), Mirror(),
                    Water(fog_density=WATER_DENSITY, fog_color=(0.0, 0.0, 0.0), depth=6.0, absorption=absorption))

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # (a still water: no waves, said)
        runner = scene(build, SIZE)
        runner.frame()
    marched = marched_light(runner)
    origin, way, (rows, columns) = march_rays(runner, SIZE, 2)
    with np.errstate(divide="ignore", invalid="ignore"):   # to the floor (y = -6), the surface or the distance
        floor = np.where(way[:, 1] < 0, (-6.0 - origin[:, 1]) / way[:, 1], np.inf)
        surface = np.where(way[:, 1] > 0, -origin[:, 1] / way[:, 1], np.inf)
    reach = np.minimum(np.minimum(floor, surface), settings.distance)
    points = 1000
    t = (np.arange(points) + 0.5) / points
    along = reach[:, None] * t[None, :]
    height = origin[:, 1:2] + way[:, 1:2] * along     # every point is in the body (under the surface, over the floor)
    g = settings.anisotropy
    c = way @ np.array([0.0, 1.0, 0.0])
    phase = (1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * c) ** 1.5)
    truths = []
    for channel, share in enumerate(absorption):
        water = WATER_DENSITY * share
        density = AIR_DENSITY + water
        seen = np.exp(-density * along)
        light = SUN_LIGHT * settings.intensity * phase * (density * seen * np.exp(-water * -height)).sum(1) \
            * reach / points
        truth = light.reshape(rows, columns)
        undimmed = (SUN_LIGHT * settings.intensity * phase * (density * seen).sum(1) * reach / points).reshape(
            truth.shape)
        lit = truth > 0.02 * truth.max()
        assert lit.mean() > 0.5
        error = np.abs(marched[..., channel] - truth)[lit] / truth[lit]
        assert np.median(error) < 0.03, (channel, np.median(error))
        if share == 1.0:   # (what the sun's whole light would give: far more)
            assert np.median(undimmed[lit] / truth[lit]) > 1.5
        truths.append(truth)
    if absorption[0] != absorption[2]:   # the channels apart (each held to its own truth above)
        assert np.median(np.abs(truths[2][lit] / truths[0][lit] - 1.0)) > 0.1


def _added_by_images(scene, build_for) -> tuple:
    """The runner of the world ``build_for(True)`` builds (a surface that carries light), its
    march, and what that adds over the march of ``build_for(False)`` (the same world whose
    surface carries none: the same steps at the same points), and each march texel's ray
    (``march_rays``: origins, ways, the grid's shape) with its distance to the floor y = 0."""
    marches = []
    for carries in (True, False):
        runner = scene(build_for(carries), SIZE)
        runner.frame()
        assert runner.stats.virtual_lights == int(carries)
        marches.append((runner, marched_light(runner)))
    (runner, marched), (_, without) = marches
    origin, way, shape = march_rays(runner, SIZE, 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        floor = np.where(way[:, 1] < 0, -origin[:, 1] / way[:, 1], np.inf)
    return runner, marched, marched[..., 0].astype(np.float64) - without[..., 0], origin, way, shape, floor


FLOOR_MIRROR = ((1.75, 0.01, -1.25), (2.6, 6.0))   # a floor mirror across the shaft's patch (centre, x and z sides)


def _level_pane_crossed(start: np.ndarray, way: np.ndarray, length: np.ndarray | float, pane) -> np.ndarray:
    """Whether each line (rows: ``start`` + s ``way``, 0 < s < ``length``) crosses ``pane`` (a
    level rectangle: its centre, its x and z sides)."""
    (px, py, pz), (sx, sz) = pane
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (py - start[:, 1]) / way[:, 1]
    at = start + way * s[:, None]
    return (s > 0) & (s < length) & (np.abs(at[:, 0] - px) < sx / 2) & (np.abs(at[:, 2] - pz) < sz / 2)


def _image_light(origin: np.ndarray, way: np.ndarray, reach: np.ndarray, settings: VolumetricFog,
                 points: int = 1000, pane=None, alpha: float = 0.0) -> np.ndarray:
    """The sun's light the floor mirror reflects (a sun at its image, travelling ``R``, the
    sun's way turned up), scattered back along each ray: at each of ``points`` points, lit where
    the line back along R meets the mirror's rectangle, nothing stands between, and the sun
    reaches that point of the glass through the roof's gap (``pane``: a level see-through
    pane, ``_level_pane_crossed``'s, of ``alpha``: 1 - alpha of the light for each stretch of
    its way, sun to glass and glass to the point, that crosses it)."""
    (cx, cy, cz), (width, depth) = FLOOR_MIRROR
    sun = np.array(tuple(SUN))
    up = sun * np.array([1.0, -1.0, 1.0])   # R: the reflected light's way
    t = (np.arange(points) + 0.5) / points
    total = np.zeros(len(origin))
    for first in range(0, len(origin), 512):
        part = slice(first, first + 512)
        along = reach[part, None] * t[None, :]
        at = (origin[part, None, :] + way[part, None, :] * along[..., None]).reshape(-1, 3)
        s = (at[:, 1] - cy) / up[1]                     # back along R to the glass's plane
        glass = at - up * s[:, None]
        inside = (s > 0) & (np.abs(glass[:, 0] - cx) <= width / 2) & (np.abs(glass[:, 2] - cz) <= depth / 2)
        between = _hits(at, np.broadcast_to(-up, at.shape), [*ROOF, WALL]) < s
        sunlit = ~np.isfinite(_hits(glass, np.broadcast_to(-sun, glass.shape), ROOF))
        lit = (inside & ~between & sunlit).astype(np.float64)
        if pane is not None:
            lit *= np.where(_level_pane_crossed(at, np.broadcast_to(-up, at.shape), s, pane), 1.0 - alpha, 1.0)
            lit *= np.where(_level_pane_crossed(glass, np.broadcast_to(-sun, glass.shape), np.inf, pane),
                            1.0 - alpha, 1.0)
        lit = lit.reshape(along.shape)
        total[part] = (DENSITY * np.exp(-DENSITY * along) * lit).sum(1) * reach[part] / points
    g = settings.anisotropy
    c = way @ -up
    phase = (1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * c) ** 1.5)
    return SUN_LIGHT * settings.intensity * phase * total


def test_the_suns_light_off_a_mirror_lights_the_air_as_the_sun_at_its_image(scene):
    """A mirror on the floor across the shaft's patch (its sides in the roof's shadow),
    reflecting light (``Mirror.reflects_light``):
    the sun's image through it (a VirtualLight) scatters in the air as the sun does, a
    column from the glass up to the roof, where it comes out of the glass and its shadow
    map lets it.  Each ray's light is the sun's ground truth plus the image's
    (``_image_light``); the image's alone is what the march adds over the same hall whose
    mirror reflects no light (the same steps at the same points: the sun's part is the same
    to the bit).  Scattered alike every way (anisotropy 0): the camera looks up the column."""
    settings = VolumetricFog(steps=64, anisotropy=0.0)

    def hall(reflects: bool):
        def build(world):
            _hall(world, settings)
            centre, sides = FLOOR_MIRROR   # (the quad's +y turned to -z)
            world.spawn(Transform(position=centre, rotation=glm.angleAxis(-np.pi / 2, glm.vec3(1, 0, 0))),
                        MeshRef(quad(*sides)), Material(), Mirror(reflects_light=reflects))
        return build

    runner, marched, added, origin, way, shape, floor = _added_by_images(scene, hall)
    centre, (width, depth) = FLOOR_MIRROR
    ends = np.minimum(floor, _hits(origin, way, [*ROOF, WALL, (centre, (width, 2e-4, depth))]))   # (the glass too)
    reach = np.minimum(ends, settings.distance)
    image = _image_light(origin, way, reach, settings)
    truth, image, reach = (a.reshape(shape) for a in (_light(origin, way, reach, settings) + image, image, reach))
    steady = np.abs(reach - np.roll(reach, 1, 0)) + np.abs(reach - np.roll(reach, 1, 1)) < 0.05 * reach
    lit = steady & (truth > 0.02 * truth.max())
    error = np.abs(marched[..., 0] - truth)[lit] / truth[lit]
    assert np.median(error) < 0.025, np.median(error)
    assert np.quantile(error, 0.9) < 0.08, np.quantile(error, 0.9)
    # The image's own light: the column, within 5% in the median and 15% at 90% of its texels
    # (its edges in the image's shadow map's texels), and nothing elsewhere.
    column = steady & (image > 0.05 * image.max())
    assert column.sum() > 60, column.sum()
    column_error = np.abs(added - image)[column] / image[column]
    assert np.median(column_error) < 0.05, np.median(column_error)
    assert np.quantile(column_error, 0.9) < 0.15, np.quantile(column_error, 0.9)
    assert np.abs(added[steady & (image == 0.0)]).max() < 0.01 * image.max()


# Level panes over the floor mirror (centre, x and z sides): the narrow one narrower along x
# than the way R and the sun's way part in its height (no line of the image's map crosses it
# twice); the wide one met by many lines twice, on the way in and again past the points under it.
MIRROR_PANES = {"narrow": ((1.8, 2.5, 0.5), (1.6, 3.0)), "wide": ((1.8, 2.5, 0.5), (3.2, 3.0))}


@pytest.mark.parametrize("pane", list(MIRROR_PANES))
def test_a_see_through_pane_in_the_light_off_a_mirror_lets_its_share_of_the_image_into_the_air(scene, pane):
    """The floor mirror's column of the sun's reflected light, with a level see-through pane
    (alpha 0.6) 2.5 m over the glass across part of it: the image's light in the air (what the
    march adds over the same hall whose mirror reflects no light) is ``_image_light``'s with
    0.4 of it for each stretch of the way, sun to glass or glass to the point, that crosses
    the pane (the virtual light's see-through map, read by the march at each step: at points
    over the pane on the way out, under it where the sun came through it on the way in), not
    the bare image's.  Rays that meet the pane on their way from the camera are left out.
    Under the wide pane the line through a point meets the pane again past it, on the way
    out: that point takes the pane's share once (the map keeps the stretches before the
    glass apart from the last one's)."""
    MIRROR_PANE = MIRROR_PANES[pane]  # noqa: N806
    settings = VolumetricFog(steps=64, anisotropy=0.0)
    alpha = 0.6

    def hall(reflects: bool):
        def build(world):
            _hall(world, settings)
            centre, sides = FLOOR_MIRROR   # (the quad's +y turned to -z)
            world.spawn(Transform(position=centre, rotation=glm.angleAxis(-np.pi / 2, glm.vec3(1, 0, 0))),
                        MeshRef(quad(*sides)), Material(), Mirror(reflects_light=reflects))
            pane_centre, (sx, sz) = MIRROR_PANE   # (likewise: a level pane)
            world.spawn(Transform(position=pane_centre, rotation=glm.angleAxis(-np.pi / 2, glm.vec3(1, 0, 0))),
                        MeshRef(quad(sx, sz)), Material(color=(0.7, 0.8, 0.9, alpha), double_sided=True))
        return build

    runner, _, added, origin, way, shape, floor = _added_by_images(scene, hall)
    assert runner.engine.renderer.shadows.virtual_see_through_atlas is not None
    centre, (width, depth) = FLOOR_MIRROR
    ends = np.minimum(floor, _hits(origin, way, [*ROOF, WALL, (centre, (width, 2e-4, depth))]))
    reach = np.minimum(ends, settings.distance)
    # The image's light at 400 points a ray, on the rays a 40 points' sum finds in its column
    # (and their neighbours): elsewhere none.
    near = (_image_light(origin, way, reach, settings, 40) > 0.0).reshape(shape)
    near = (near | np.roll(near, 1, 0) | np.roll(near, -1, 0) | np.roll(near, 1, 1) | np.roll(near, -1, 1)).ravel()
    image, bare = np.zeros(len(origin)), np.zeros(len(origin))
    image[near] = _image_light(origin[near], way[near], reach[near], settings, 400, MIRROR_PANE, alpha)
    bare[near] = _image_light(origin[near], way[near], reach[near], settings, 400)
    seen_through = _level_pane_crossed(origin, way, reach, MIRROR_PANE).reshape(shape)
    image, bare, reach = image.reshape(shape), bare.reshape(shape), reach.reshape(shape)
    steady = np.abs(reach - np.roll(reach, 1, 0)) + np.abs(reach - np.roll(reach, 1, 1)) < 0.05 * reach
    column = steady & ~seen_through & (image > 0.05 * image.max())
    dimmed = column & (image < 0.8 * bare)   # (rays whose light the pane takes a fifth of or more)
    assert column.sum() > 60 and dimmed.sum() > 30, (column.sum(), dimmed.sum())
    assert bare[dimmed].sum() > 1.4 * image[dimmed].sum()
    # Where the pane dims the light, the march's sum is the pane's truth's (the bare image's is
    # half again as much), and texel by texel it keeps to it as it does beside the pane.
    np.testing.assert_allclose(added[dimmed].sum() / image[dimmed].sum(), 1.0, atol=0.06)
    error = np.abs(added - image)[column] / image[column]
    assert np.median(error) < 0.07, np.median(error)
    assert np.quantile(error, 0.9) < 0.2, np.quantile(error, 0.9)


WALL_MIRROR = ((-3.0, 2.0, -1.0), (6.0, 4.0))   # a standing mirror facing +x (centre, z and y sides)
IMAGED_LAMP, IMAGED_RANGE, IMAGED_LIGHT = (-1.2, 2.6, -0.5), 12.0, 4.0


def _lamp_image_light(origin: np.ndarray, way: np.ndarray, reach: np.ndarray, settings: VolumetricFog,
                      image: np.ndarray, exit_x: float, centre_yz: tuple[float, float], sides_yz: tuple[float, float],
                      light_range: float, light: float) -> np.ndarray:
    """A lamp's image (at ``image``, of ``light_range`` and ``light``) seen through an opening
    on the plane x = ``exit_x`` facing +x (centred on ``centre_yz``, ``sides_yz`` across),
    scattered back along each ray at 1,000 points: lit where the point is in front of the
    opening and the line from it to the image crosses the opening, by the falloff over the
    whole way (the distance to the image: lights.glsl's) and the phase function."""
    points = 1000
    t = (np.arange(points) + 0.5) / points
    g = settings.anisotropy
    total = np.zeros(len(origin))
    for first in range(0, len(origin), 256):
        part = slice(first, first + 256)
        along = reach[part, None] * t[None, :]
        at = (origin[part, None, :] + way[part, None, :] * along[..., None]).reshape(-1, 3)
        to_image = image - at
        dist = np.linalg.norm(to_image, axis=1)
        l = to_image / dist[:, None]
        cross = at + l * ((exit_x - at[:, 0]) / l[:, 0])[:, None]   # where the line meets the opening's plane
        through = (at[:, 0] > exit_x) & (np.abs(cross[:, 1] - centre_yz[0]) <= sides_yz[0] / 2) \
            & (np.abs(cross[:, 2] - centre_yz[1]) <= sides_yz[1] / 2)
        fade = np.clip(1.0 - (dist / light_range) ** 4, 0.0, 1.0)
        c = np.einsum("ij,ij->i", np.repeat(way[part], points, 0), l)
        phase = (1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * c) ** 1.5)
        lit = (fade * fade / (dist * dist + 1.0) * phase * through).reshape(along.shape)
        total[part] = (DENSITY * np.exp(-DENSITY * along) * lit).sum(1) * reach[part] / points
    return light * settings.intensity * total


@pytest.mark.parametrize("volumetric", [0.7, 0.0])
def test_a_volumetric_lamps_image_in_a_mirror_lights_the_air_by_its_share(scene, volumetric):
    """A lamp before a standing mirror that reflects light: its image scatters in the air as
    the lamp would from the image's place, through the glass's outline, times the lamp's
    ``PointLight.volumetric`` (0: the lamp lights no air, nor does its image).  What the
    march adds over the same room whose mirror reflects no light, against
    ``_lamp_image_light`` of the lamp reflected in the glass's plane.  A sun lights the air
    too (its light meets the glass's back: no image of it), so the shafts stand at 0."""
    settings = VolumetricFog(steps=128, anisotropy=0.0)

    def room(reflects: bool):
        def build(world):
            camera = look_from(world, (0.0, 2.0, 7.0), (-0.5, 2.0, 0.0), fov=60.0)
            world.spawn(Skybox())
            world.spawn(DirectionalLight(direction=(1.0, -1.0, 0.0), intensity=0.5, shadows=False))
            world.spawn(Transform(), MeshRef(plane(FLOOR, FLOOR)), Material(color=(0.5, 0.5, 0.5)))
            centre, sides = WALL_MIRROR   # (the quad's +z turned to +x)
            world.spawn(Transform(position=centre, rotation=glm.angleAxis(np.pi / 2, glm.vec3(0, 1, 0))),
                        MeshRef(quad(*sides)), Material(), Mirror(reflects_light=reflects))
            world.spawn(Transform(position=IMAGED_LAMP),
                        PointLight(intensity=IMAGED_LIGHT, range=IMAGED_RANGE, volumetric=volumetric, shadows=False))
            world.add_component(camera, Fog(density=DENSITY, color=(0.02, 0.02, 0.02)))
            world.add_component(camera, Tonemap(curve="none"))
            world.add_component(camera, settings)
        return build

    _, _, added, origin, way, shape, floor = _added_by_images(scene, room)
    centre, (depth, height) = WALL_MIRROR
    reach = np.minimum(np.minimum(floor, _hits(origin, way, [(centre, (2e-4, height, depth))])), settings.distance)
    (mx, my, mz), _ = WALL_MIRROR   # the lamp reflected in the glass's plane, seen through it
    image_at = np.array(IMAGED_LAMP) * np.array([-1.0, 1.0, 1.0]) + np.array([2.0 * mx, 0.0, 0.0])
    image = _lamp_image_light(origin, way, reach, settings, image_at, mx, (my, mz), (height, depth), IMAGED_RANGE,
                              IMAGED_LIGHT * 0.7).reshape(shape)
    reach = reach.reshape(shape)
    steady = np.abs(reach - np.roll(reach, 1, 0)) + np.abs(reach - np.roll(reach, 1, 1)) < 0.05 * reach
    if volumetric == 0.0:
        assert np.abs(added).max() == 0.0   # (no image is marched: the same build and sum as without)
        return
    lit = steady & (image > 0.05 * image.max())
    assert lit.sum() > 300, lit.sum()
    error = np.abs(added - image)[lit] / image[lit]
    assert np.median(error) < 0.03, np.median(error)
    assert np.quantile(error, 0.9) < 0.1, np.quantile(error, 0.9)
    assert np.abs(added[steady & (image == 0.0)]).max() < 0.02 * image.max()


def test_a_lamps_image_through_a_portal_pair_of_two_scales_lights_the_air_beyond_it(scene):
    """A volumetric lamp before portal A, which carries light (``Portal.carries_light``), out
    of B scaled 2: the lamp's image (carried through the pair: 2 m behind B, its range and
    size twice the lamp's, its light four times) scatters in the air in front of B where the
    line to it crosses B's opening.  What the march adds over the frame whose A carries no
    light, against the ground truth of a lamp of that range and light at the image."""
    from components import Portal
    from engine.assets.portals import spawn_portal_pair
    from engine.core.portal_math import pair_transform

    lamp, lamp_range, lamp_light, k = np.array([0.0, 1.5, 5.0]), 6.0, 3.0, 2.0
    exit_at, opening = np.array([-6.0, 1.5, 0.0]), (2.0 * k, 3.0 * k)   # B's centre and (z, y) sides
    settings = VolumetricFog(steps=128, anisotropy=0.0)
    ids = {}

    def build(world):
        camera = look_from(world, (2.0, 2.5, 7.0), (-3.5, 1.5, 0.0), fov=60.0)
        world.spawn(Skybox())
        world.spawn(Transform(), MeshRef(plane(FLOOR, FLOOR)), Material(color=(0.5, 0.5, 0.5)))
        world.spawn(Transform(position=tuple(lamp)), PointLight(intensity=lamp_light, range=lamp_range, shadows=False))
        ids.update(zip("ab", spawn_portal_pair(world, (0.0, 1.5, 4.0), None, tuple(exit_at),
                                               look_rotation(glm.vec3(-1, 0, 0))), strict=True))
        world.get(ids["b"], Transform).scale = glm.vec3(k)
        world.get(ids["a"], Portal).carries_light = True
        world.add_component(camera, Fog(density=DENSITY, color=(0.02, 0.02, 0.02)))
        world.add_component(camera, Tonemap(curve="none"))
        world.add_component(camera, settings)

    runner = scene(build, SIZE)
    runner.frame()
    assert runner.stats.virtual_lights == 1
    carried = marched_light(runner)[..., 0].astype(np.float64)
    runner.world.get(ids["a"], Portal).carries_light = False
    runner.frame()
    assert runner.stats.virtual_lights == 0
    added = carried - marched_light(runner)[..., 0]
    carry = glm.dmat4(pair_transform(runner.world.get(ids["a"], Transform).world,
                                     runner.world.get(ids["b"], Transform).world))
    image = np.array(glm.dvec3(carry * glm.dvec4(*lamp, 1.0)))
    assert np.allclose(image, exit_at + np.array([-k, 0.0, 0.0]), atol=1e-5)   # 2 m behind B
    origin, way, shape = march_rays(runner, SIZE, 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        floor = np.where(way[:, 1] < 0, -origin[:, 1] / way[:, 1], np.inf)
    portals = [(tuple(exit_at), (2e-4, opening[1], opening[0])), ((0.0, 1.5, 4.0), (2.0, 3.0, 2e-4))]
    reach = np.minimum(np.minimum(floor, _hits(origin, way, portals)), settings.distance)
    truth = _lamp_image_light(origin, way, reach, settings, image, exit_at[0], (exit_at[1], exit_at[2]),
                              (opening[1], opening[0]), lamp_range * k, lamp_light * k * k).reshape(shape)
    reach = reach.reshape(shape)
    steady = np.abs(reach - np.roll(reach, 1, 0)) + np.abs(reach - np.roll(reach, 1, 1)) < 0.05 * reach
    lit = steady & (truth > 0.05 * truth.max())
    assert lit.sum() > 300, lit.sum()
    error = np.abs(added - truth)[lit] / truth[lit]
    assert np.median(error) < 0.03, np.median(error)
    assert np.quantile(error, 0.9) < 0.1, np.quantile(error, 0.9)


def _watched_hall(world, shafts: VolumetricFog | None, lens_fog: bool = True, mirror: bool = False) -> dict:
    """``_hall`` with no shafts on the active camera, and a monitor whose camera (not active)
    stands where it does with ``shafts`` (and the hall's fog of its own, ``lens_fog``, else it
    takes the active camera's), its picture the frame's size, the screen out of both cameras'
    sight (``mirror``: the hall's mirror on its wall, the picture's view tree one level deep)."""
    from components import Camera, Monitor

    camera = _hall(world, mirror=mirror)
    lens = look_from(world, EYE, TARGET, fov=70.0)
    world.get(lens, Camera).active = False
    if lens_fog:
        world.add_component(lens, Fog(density=DENSITY, color=(0.02, 0.02, 0.02)))
    if shafts is not None:
        world.add_component(lens, shafts)
    screen = world.spawn(Transform(position=(0.0, 1.0, 14.0)), MeshRef(quad(1.6, 0.9)),
                         Material(color=(0.0, 0.0, 0.0), roughness=1.0, environment_reflection=0.0),
                         Monitor(camera=lens, size=SIZE))
    return {"camera": camera, "lens": lens, "screen": screen}


@pytest.mark.parametrize("lens_fog", [True, False], ids=["own_fog", "the_frames_fog"])
def test_a_monitors_camera_has_its_shafts_in_its_picture(scene, lens_fog):
    """A monitor's camera with a ``VolumetricFog`` (the active camera, at the same place, none):
    what the shafts add to its picture is what they add to the camera's own view where the
    active camera has them (a second path, checked against the ground truth above), whether
    its air is its own ``Fog`` or the frame's; its image is the picture's own, let go with
    the component and with the monitor."""
    from components import Monitor

    expected, _ = _added(scene, VolumetricFog(steps=64))
    assert expected.max() > 0.1

    def picture(shafts):
        names: dict = {}
        runner = scene(lambda world: names.update(_watched_hall(world, shafts, lens_fog)), SIZE)
        runner.frame()
        # (rows from the bottom, as _linear's)
        return runner.engine.renderer.monitors.read(names["screen"])[::-1, :, :3].astype(np.float64), runner, names

    lit, runner, names = picture(VolumetricFog(steps=64))
    bare, _, _ = picture(None)
    added = lit - bare
    # (the two paths' pictures without shafts differ by up to 2e-3 already: half floats, a
    # texture's copy and a framebuffer's)
    assert (expected.max(axis=-1) > 0.02).mean() > 0.5   # the shafts cover most of the view
    close = np.abs(added - expected).max(axis=-1) < 5e-3 + 0.03 * np.abs(expected).max(axis=-1)
    assert close.mean() > 0.99, close.mean()
    counts = runner.engine.renderer.resource_counts
    assert counts()["volumetric_targets"] == 1   # the picture's alone
    runner.world.remove_component(names["lens"], VolumetricFog)
    runner.frame()
    assert counts()["volumetric_targets"] == 0
    runner.world.add_component(names["lens"], VolumetricFog())
    runner.frame()
    assert counts()["volumetric_targets"] == 1
    runner.world.remove_component(names["screen"], Monitor)
    runner.frame()
    assert counts()["volumetric_targets"] == 0


def test_a_monitors_camera_has_its_shafts_in_the_mirror_its_picture_shows(scene):
    """The hall's mirror on its wall, seen by the monitor's camera (a view tree one level
    deep; its ``VolumetricFog`` reaching one level): what the shafts add to its picture,
    the mirror's view too, is what they add to the camera's own view where the active camera
    has them; its images are the picture's own, its root's and its level's (2)."""
    expected, direct = _added(scene, VolumetricFog(steps=64), mirror=True)
    assert direct.engine.renderer.resource_counts()["volumetric_targets"] == 2   # (the camera's root and level)

    def picture(shafts):
        names: dict = {}
        runner = scene(lambda world: names.update(_watched_hall(world, shafts, mirror=True)), SIZE)
        runner.frame()
        return runner.engine.renderer.monitors.read(names["screen"])[::-1, :, :3].astype(np.float64), runner, names

    lit, runner, names = picture(VolumetricFog(steps=64))
    bare, _, _ = picture(None)
    shallow, _, _ = picture(VolumetricFog(steps=64, reflection_depth=0))
    added = lit - bare
    close = np.abs(added - expected).max(axis=-1) < 5e-3 + 0.03 * np.abs(expected).max(axis=-1)
    assert close.mean() > 0.99, close.mean()
    # The mirror's pixels (its level's): the level's own shafts, over the root's, are what
    # they are in the camera's own view (its frame at reflection_depth 1 less at 0).
    (mirror,) = [entity for entity, _ in direct.world.query_one(Mirror)]
    nodes = direct.engine.renderer.targets.read_surface_ids()[::-1] == mirror
    expected_level = expected - _added(scene, VolumetricFog(steps=64, reflection_depth=0), mirror=True)[0]
    level = lit - shallow
    assert nodes.sum() > 500 and expected_level.max() > 0.03, (nodes.sum(), expected_level.max())
    close = np.abs(level - expected_level).max(axis=-1) < 5e-3 + 0.03 * np.abs(expected_level).max(axis=-1)
    assert close[nodes].mean() > 0.99, close[nodes].mean()
    assert np.abs(level[~nodes]).max() < 5e-3
    assert runner.engine.renderer.resource_counts()["volumetric_targets"] == 2


def test_a_monitors_camera_with_shafts_and_no_air_says_so_once(scene):
    """No fog on the monitor's camera nor on the active one: its shafts add nothing, said once."""
    from components import Monitor

    names: dict = {}

    def build(world):
        names.update(_watched_hall(world, VolumetricFog(), lens_fog=False))
        world.remove_component(names["camera"], Fog)

    runner = scene(build, SIZE)
    with pytest.warns(ComponentWarning, match=r"the camera of monitor \d+, has no Fog .*adds nothing to its picture"):
        runner.frame()
    runner.world.get(names["screen"], Monitor).size = (80, 48)   # (drawn again: nothing more said)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        runner.frame()
    assert runner.engine.renderer.resource_counts()["volumetric_targets"] == 0


# --- deeper levels: a portal on the wall, a mirror facing the wall's (the camera's and a picture's) ---
CARRY = np.array([0.0, 0.0, 18.8])   # A on the wall (MIRROR's place), B this far behind it turned half round
DEEP_EYE, DEEP_TARGET = (0.5, 2.2, -0.5), (0.5, 2.4, -6.8)   # the cameras 6.3 m from the wall, facing it


def _deep_hall(world, shafts: VolumetricFog | None, through: str, watched: bool = False) -> dict:
    """``_hall`` (``watched``: ``_watched_hall``, the monitor's picture two levels deep), its
    cameras at DEEP_EYE facing the wall, with ``through`` "portals": portal A on the wall where
    the mirror hangs and B at A + CARRY behind the camera, turned half round (facing -z:
    looking into A is looking out of B, a shift by CARRY), so A's view shows the hall again and
    A in it (level 2, a portal through a portal); or "mirrors": the wall's mirror and one at
    the same place + CARRY facing it (level 2, a mirror in a mirror).  B and the back mirror
    cast no shadow (the ground truth's sun is shaded by the roof alone)."""
    from components import Monitor
    from engine.assets.portals import spawn_portal_pair

    mirrors = through == "mirrors"
    if watched:
        names = _watched_hall(world, shafts, mirror=mirrors)
        world.get(names["screen"], Monitor).depth = 2
    else:
        names = {"camera": _hall(world, shafts, mirror=mirrors)}
    for camera in (names["camera"], names.get("lens")):   # (both posed 6.3 m from the wall)
        if camera is not None:
            pose = world.get(camera, Transform)
            pose.position = glm.vec3(DEEP_EYE)
            pose.rotation = look_rotation(glm.vec3(DEEP_TARGET) - glm.vec3(DEEP_EYE))
    if mirrors:
        (names["mirror"],) = [entity for entity, _ in world.query_one(Mirror)]
    half_round = glm.angleAxis(glm.radians(180.0), glm.vec3(0, 1, 0))
    if mirrors:
        names["back"] = world.spawn(Transform(position=tuple(np.add(MIRROR[0], CARRY)), rotation=half_round),
                                    MeshRef(quad(*MIRROR[1][:2]), casts_shadows=False), Material(), Mirror())
    else:
        names["a"], names["b"] = spawn_portal_pair(world, MIRROR[0], None, tuple(np.add(MIRROR[0], CARRY)),
                                                   half_round, size=MIRROR[1][:2])
        for portal in (names["a"], names["b"]):
            world.get(portal, MeshRef).casts_shadows = False
    return names


BACK = ((MIRROR[0][0], MIRROR[0][1], MIRROR[0][2] + CARRY[2]), MIRROR[1])   # B, or the back mirror, as a thin box


def _deep_rays(runner, depth: int, through: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each pixel's camera ray ``depth`` levels down ``_deep_hall``'s ``through``: "portals",
    each time it meets A's plane it goes on from that point + CARRY, its way the same;
    "mirrors", reflected in the wall's mirror, then in the back one (a z = const plane each):
    where it leaves the last surface, its way, how far it goes on (to the floor, a slab, the
    wall, A or a mirror, at most 40 m), and whether it met each surface well inside its
    outline (3 pixels' worth at the length of the way so far), by rows of pixels (from the
    bottom)."""
    view = runner.engine.main_view
    inverse = np.array(glm.inverse(view.view_proj).to_list(), np.float64).T
    width, height = SIZE
    ys, xs = np.mgrid[0:height, 0:width]
    ndc = np.stack([(xs + 0.5) / width * 2 - 1, (ys + 0.5) / height * 2 - 1], -1).reshape(-1, 2)

    def unproject(z):
        points = np.concatenate([ndc, np.full((len(ndc), 1), z), np.ones((len(ndc), 1))], 1) @ inverse.T
        return points[:, :3] / points[:, 3:]

    start = unproject(-1.0)
    way = unproject(1.0) - start
    way /= np.linalg.norm(way, axis=1, keepdims=True)
    inside = np.ones(len(start), bool)
    travelled = np.zeros(len(start))
    for level in range(depth):
        (cx, cy, cz), (w, h, _) = BACK if through == "mirrors" and level % 2 else MIRROR
        t = (cz - start[:, 2]) / way[:, 2]
        glass = start + way * t[:, None]
        travelled += t
        margin = 3 * 2 * np.tan(np.radians(35.0)) * travelled / height
        inside &= (t > 0) & (np.abs(glass[:, 0] - cx) < 0.5 * w - margin) \
            & (np.abs(glass[:, 1] - cy) < 0.5 * h - margin)
        if through == "mirrors":
            start, way = glass, way * np.array([1.0, 1.0, -1.0])
        else:
            start = glass + CARRY
    with np.errstate(divide="ignore", invalid="ignore"):
        floor = np.where(way[:, 1] < 0, -start[:, 1] / way[:, 1], np.inf)
    landing = start + way * np.where(np.isfinite(floor), floor, 0.0)[:, None]
    floor = np.where(np.abs(landing[:, [0, 2]]).max(1) <= 0.5 * FLOOR, floor, np.inf)   # (the floor's edge)
    ahead = [MIRROR] if through == "portals" or depth % 2 == 0 else [BACK]   # (the surface it may end on)
    reach = np.clip(np.minimum(floor, _hits(start, way, [*ROOF, WALL, *ahead])), 0.0, 40.0)
    return start, way, reach, inside.reshape(height, width)


def _marched(images) -> np.ndarray:
    """A march image's texels (rows from the bottom): the light, and the ray's length in alpha."""
    return np.frombuffer(images.light.read(), np.float32).reshape(images.light.size[1], images.light.size[0], 4)


@pytest.mark.parametrize("watched", [False, True], ids=["camera", "picture"])
@pytest.mark.parametrize("through", ["portals", "mirrors"])
def test_each_level_two_deep_marches_the_air_it_shows_from_its_surface(scene, through, watched):
    """Portal A on the hall's wall and B behind the camera (a shift by CARRY), or the wall's
    mirror and one facing it there: each pixel of level 1 (A's view, the mirror's) and of
    level 2 (A seen through A, the back mirror in the wall's) marches its ray carried or
    reflected that far (``_deep_rays``) on to the floor, a slab, the wall or the surface ahead,
    and its light is the ground truth's for that ray.  ``watched``: the march images of a
    monitor's picture whose camera, posed as the active one (which has none), has the shafts
    reaching two levels, the picture two levels deep: its portal level and its level 2 are
    marched as the rays say."""
    settings = VolumetricFog(steps=64, reflection_depth=2)
    names: dict = {}
    runner = scene(lambda world: names.update(_deep_hall(world, settings, through, watched)), SIZE)
    runner.frame()
    fog = runner.engine.renderer.volumetric_fog
    levels = fog._picture_levels[names["screen"]] if watched else fog._levels
    assert sorted(levels) == [1, 2]
    for depth, least in ((1, 1000), (2, 60)):
        marched = _marched(levels[depth]).reshape(-1, 4)
        assert levels[depth].light.size == SIZE
        origin, way, reach, inside = _deep_rays(runner, depth, through)
        grid = reach.reshape(SIZE[1], SIZE[0])
        steady = np.abs(grid - np.roll(grid, 1, 0)) + np.abs(grid - np.roll(grid, 1, 1)) < 0.05 * grid
        check = inside & steady
        assert check.sum() > least, (depth, check.sum())
        rows = np.flatnonzero(check)[::max(1, check.sum() // 1200)]   # (about 1,200 of them)
        assert np.median(np.abs(marched[rows, 3] - reach[rows]) / reach[rows]) < 0.002, depth
        truth = _light(origin[rows], way[rows], reach[rows], settings)
        error = np.abs(marched[rows, 0] - truth) / truth
        assert np.median(error) < 0.025 and np.quantile(error, 0.9) < 0.07, (depth, np.median(error),
                                                                             np.quantile(error, 0.9))
        assert truth.max() > 1.5 * np.median(truth), depth   # (the rays cross the shaft too)


@pytest.mark.parametrize("through", ["portals", "mirrors"])
def test_a_monitors_camera_has_its_shafts_two_levels_deep_in_its_picture(scene, through):
    """A monitor's camera (the active camera, at the same place, none) whose ``VolumetricFog``
    reaches two levels, its picture two levels deep, facing a portal on the wall (level 2: A
    through A) or the wall's mirror facing another (level 2: a mirror in a mirror): what each
    level's shafts add to its picture (the picture at reflection_depth d less at d - 1) is
    what they add to the camera's own view where the active camera has them (its frame
    likewise), within the wall's surface and nothing outside it; level 2's (0.008 at most,
    near the half floats' step) on the whole; its images are the picture's own (3)."""
    def drawn(depth: int, watched: bool) -> tuple[np.ndarray, object, dict]:
        names: dict = {}
        runner = scene(lambda world: names.update(
            _deep_hall(world, VolumetricFog(steps=64, reflection_depth=depth), through, watched)), SIZE)
        runner.frame()
        if watched:
            return runner.engine.renderer.monitors.read(names["screen"])[::-1, :, :3].astype(np.float64), runner, names
        return _linear(runner).astype(np.float64), runner, names

    camera = {depth: drawn(depth, False)[0] for depth in (0, 1, 2)}
    picture = {}
    for depth in (0, 1, 2):
        picture[depth], runner, names = drawn(depth, True)
    assert runner.engine.renderer.resource_counts()["volumetric_targets"] == 3
    surface = runner.engine.renderer.targets.read_surface_ids()[::-1]   # (the active camera's: the lens's pose)
    seen = surface == names["mirror" if through == "mirrors" else "a"]
    for depth in (1, 2):
        expected = camera[depth] - camera[depth - 1]
        got = picture[depth] - picture[depth - 1]
        strong = expected.max(axis=-1) > 0.3 * expected.max()
        assert strong.sum() > (1000 if depth == 1 else 150) and not (strong & ~seen).any(), (depth, strong.sum())
        assert np.abs(got[~seen]).max() < 2e-3, depth
        if depth == 1:
            close = np.abs(got - expected).max(axis=-1) < 5e-3 + 0.03 * np.abs(expected).max(axis=-1)
            assert close.mean() > 0.99, close.mean()
        else:
            assert got[strong].mean() == pytest.approx(expected[strong].mean(), rel=0.05)
