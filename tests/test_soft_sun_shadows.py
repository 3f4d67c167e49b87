"""A sun with a size (``DirectionalLight.angular_diameter``): its shadows by percentage-closer
soft shadows (``shaders/include/shadows.glsl`` ``soft_sun_shadow``), with the "grid" filter
(the default on a GPU; a software rasteriser's "single" keeps one tap).  The reference: a
thin slab with a straight edge along z at x = 0 (the slab over x < 0) ``h`` metres over a
floor, the sun a disc of angular radius a in the sky, a little off straight down; seen from
a floor point, the slab's edge cuts the sun's disc along a line, and the share of the disc
left is the segment's area, in float64 (a small disc: the edge's angle across it is taken
as a straight cut)."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from components import ComponentValueError, DirectionalLight, Material, MeshRef, Skybox, Transform
from engine.assets.mesh import box, plane
from engine.core.errors import GLLimitWarning
from tests.support import look_from, srgb_to_linear
from tests.test_soft_shadows import grid_floor, penumbra_width

SIZE = (128, 96)
SUN = np.array([0.12, -1.0, 0.05]) / np.linalg.norm([0.12, -1.0, 0.05])   # the way its light travels


def floor_light(scene, slab_height: float | None, angular_diameter: float, cascades: int = 1,
                defines: list | None = None):
    """The floor's light (linear green, the "grid" filter) under the sun, the slab at
    ``slab_height`` (None: none), each floor pixel's point and whether it is the floor's."""
    def build(world):
        look_from(world, (2.2, 0.4, 2.6), (-0.2, 0.0, 0.0), fov=55.0)
        world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
        world.spawn(Transform(), MeshRef(plane(12.0, 12.0)),
                    Material(color=(1.0, 1.0, 1.0), roughness=1.0, environment_reflection=0.0))
        if slab_height is not None:
            world.spawn(Transform(position=(-2.0, slab_height, 0.0)), MeshRef(box((4.0, 0.02, 8.0))),
                        Material(color=(0.0, 0.0, 0.0)))
        world.spawn(DirectionalLight(direction=tuple(float(v) for v in SUN), intensity=2.0, shadow_resolution=2048,
                                     angular_diameter=angular_diameter, shadow_cascades=cascades,
                                     shadow_distance=8.0))
    return grid_floor(scene(build, SIZE), defines)


def disc_left(x: np.ndarray, slab_height: float, angular_diameter: float) -> np.ndarray:
    """The share of the sun's disc a floor point at ``x`` sees past the slab's edge: in the
    plane across the edge, the way to the edge leans atan(-x / h) from straight up, the sun's
    centre atan2(-SUN.x, -SUN.y); the disc's part leaning further towards +x than the edge is
    seen (it passes the slab's plane at x > 0)."""
    radius = math.radians(angular_diameter) / 2.0
    edge = np.arctan2(-x, slab_height)
    centre = math.atan2(-SUN[0], -SUN[1])
    u = np.clip((centre - edge) / radius, -1.0, 1.0)
    return 1.0 - (np.arccos(u) - u * np.sqrt(1.0 - u * u)) / math.pi


def shadow_share(scene, slab_height, angular_diameter, **kw):
    lit, points, floor = floor_light(scene, slab_height, angular_diameter, **kw)
    open_, _, _ = floor_light(scene, None, angular_diameter, **kw)
    keep = floor & (open_ > 0.05) & (np.abs(points[:, 2]) < 2.5) & (points[:, 0] > -2.5)
    return lit[keep] / open_[keep], points[keep]


@pytest.mark.parametrize(("slab_height", "cascades"), [(1.2, 1), (0.6, 1), (1.2, 3)])
def test_the_suns_shadow_follows_its_disc_across_the_penumbra(scene, slab_height, cascades):
    """A sun 6 degrees across over a slab 1.2 m and 0.6 m up (penumbras 2 tan 3 x h: 12.6 and
    6.3 cm), from the level's map alone and from the innermost of three cascades: each floor
    pixel's light about the shadow's edge within 0.08 of the disc's share left at the 90th
    percentile (measured 0.034, 0.019 and 0.036), 0.05 in the median; the 20-80% stretch
    within 30% of the disc's (measured 6%, 0% and 2% narrower)."""
    share, points = shadow_share(scene, slab_height, 6.0, cascades=cascades)
    expected = disc_left(points[:, 0], slab_height, 6.0)
    band = np.abs(points[:, 0] + slab_height * SUN[0] / SUN[1]) < 0.25   # about the shadow's edge
    assert band.sum() > 150
    assert expected[band].min() < 0.05 and expected[band].max() > 0.95
    error = np.abs(share - expected)
    assert np.percentile(error[band], 90) < 0.08, np.percentile(error[band], 90)
    assert np.median(error) < 0.05, np.median(error)
    measured, reference = penumbra_width(share, points[:, 0]), penumbra_width(expected, points[:, 0])
    assert abs(measured / reference - 1.0) < 0.3, (measured, reference)


def test_the_penumbra_hardens_where_the_caster_nears_the_floor_and_a_point_sun_is_hard(scene):
    """The same sun over the slab 1.2 m up and 0.3 m up: a quarter of the penumbra (contact
    hardening); a sun of no size draws its map's edge, and its build reads no depths."""
    high, high_points = shadow_share(scene, 1.2, 6.0)
    low, low_points = shadow_share(scene, 0.3, 6.0)
    defines: list = []
    floor_light(scene, 1.2, 0.0, defines=defines)
    hard, hard_points = shadow_share(scene, 1.2, 0.0)
    wide, narrow = penumbra_width(high, high_points[:, 0]), penumbra_width(low, low_points[:, 0])
    sharp = penumbra_width(hard, hard_points[:, 0])
    assert narrow < wide / 2.5, (narrow, wide)
    assert sharp < wide / 4.0, (sharp, wide)
    assert "SOFT_SUN_SHADOWS" not in dict(defines)
    soft: list = []
    floor_light(scene, 1.2, 6.0, defines=soft)
    assert "SOFT_SUN_SHADOWS" in dict(soft)


def test_a_context_without_the_units_keeps_the_edge_hard_and_says_so(scene):
    """Where the fragment stage has fewer than 18 units, a sun with a size casts hard shadows
    and a GLLimitWarning says so once."""
    def build(world):
        look_from(world, (2.2, 0.4, 2.6), (-0.2, 0.0, 0.0))
        world.spawn(Transform(), MeshRef(plane(12.0, 12.0)), Material())
        world.spawn(Transform(position=(-2.0, 1.0, 0.0)), MeshRef(box((4.0, 0.02, 8.0))), Material())
        world.spawn(DirectionalLight(direction=tuple(float(v) for v in SUN), angular_diameter=2.0))
    runner = scene(build, SIZE)
    runner.engine.renderer.shadows.filter = "grid"
    runner.engine.renderer.shadows.soft_sun_supported = False
    with pytest.warns(GLLimitWarning, match="angular_diameter"):
        runner.frame()
    assert "SOFT_SUN_SHADOWS" not in dict(runner.engine.renderer.shadows.program_defines)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        runner.frame()


def test_angular_diameter_is_checked():
    assert DirectionalLight(angular_diameter=0.53).angular_diameter == pytest.approx(0.53)
    for bad in (-0.1, 20.5, float("nan"), "1"):
        with pytest.raises(ComponentValueError, match="DirectionalLight.angular_diameter"):
            DirectionalLight(angular_diameter=bad)


def test_a_slope_in_a_wide_suns_light_does_not_shadow_itself(scene):
    """A floor tilted 60 degrees from the sun (the light grazing it at 30) under a sun 10
    degrees across, nothing else in the scene: every pixel as lit as under a sun of no size,
    within 3%: the slope does not shadow itself across the wide taps (each compared with the
    receiver's own plane there, the point moved off the surface and the casters' slope-scaled
    depth offset; measured 1.000 from the 1st to the 99th percentile, at 10 and 15 degrees
    of grazing under a sun 20 degrees across too)."""
    from components import look_rotation

    def slope(angular_diameter):
        def build(world):
            look_from(world, (0.0, 3.0, 5.0), (0.0, 0.0, 0.0), fov=50.0)
            world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
            tilt = look_rotation((0.0, -0.5, -0.866), (0.0, 1.0, 0.0))
            world.spawn(Transform(rotation=tilt), MeshRef(box((6.0, 6.0, 0.05))),
                        Material(color=(1.0, 1.0, 1.0), roughness=1.0, environment_reflection=0.0))
            world.spawn(DirectionalLight(direction=(0.05, -1.0, 0.02), intensity=2.0,
                                         angular_diameter=angular_diameter))
        runner = scene(build, SIZE)
        runner.engine.renderer.antialias = "off"
        runner.engine.renderer.shadows.filter = "grid"
        runner.frame()
        return srgb_to_linear(runner.frame())[..., 1]

    soft, hard = slope(10.0), slope(0.0)
    lit = hard > 0.02
    assert lit.sum() > 2000
    ratio = soft[lit] / hard[lit]
    assert np.percentile(ratio, 1) > 0.97 and np.percentile(ratio, 99) < 1.03, np.percentile(ratio, [1, 99])


@pytest.mark.parametrize(("how", "cascades"), [("mirror", 1), ("mirror", 3), ("portal", 1)])
def test_a_wide_suns_shadow_in_a_mirror_or_through_a_portal_is_its_discs_share_where_the_ray_lands(
        scene, how, cascades):
    """A sun 10 degrees across over the slab 1.5 m up (a penumbra 2 tan 5 x 1.5 = 26 cm), seen
    only in a mirror or through a portal (``test_soft_shadows.seen_floor_light``), from the
    level's map and from the rings about the camera: each pixel's floor point found in float64
    (the ray reflected in the mirror's plane, or carried by the pair's transform), its light
    (against the same view without the slab) within 0.08 of the share of the sun's disc left
    there at the 90th percentile (measured 0.04), the 20-80% stretch within 20% of the disc's
    (measured 2-6% narrower; a hard edge is a tenth of it)."""
    from tests.test_soft_shadows import binned_width, seen_floor_light

    def sun(world):
        world.spawn(DirectionalLight(direction=tuple(float(v) for v in SUN), intensity=2.0, shadow_resolution=2048,
                                     angular_diameter=10.0, shadow_cascades=cascades, shadow_distance=8.0))
    lit, points, seen = seen_floor_light(scene, 1.5, how, light=sun)
    open_, _, _ = seen_floor_light(scene, None, how, light=sun)
    keep = seen & (open_ > 0.05) & (points[:, 2] > -2.0) & (points[:, 2] < 0.5) & (np.abs(points[:, 0]) < 1.5)
    share, x = lit[keep] / open_[keep], points[keep, 0]
    expected = disc_left(x, 1.5, 10.0)
    band = np.abs(x + 1.5 * SUN[0] / SUN[1]) < 0.3   # about the shadow's edge
    assert band.sum() > 100 and expected[band].min() < 0.05 and expected[band].max() > 0.95, band.sum()
    error = np.abs(share - expected)
    assert np.percentile(error[band], 90) < 0.08, np.percentile(error[band], 90)
    measured, reference = binned_width(share, x, 0.02), binned_width(expected, x, 0.02)
    assert abs(measured / reference - 1.0) < 0.2, (measured, reference)
