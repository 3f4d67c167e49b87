"""Soft shadows of lights with a size (a sphere's ``PointLight.radius``, a rectangle's
``PointLight.rectangle``) from their distance cubes, by percentage-closer soft shadows
(``shaders/include/shadows.glsl`` ``soft_cube_shadow``), with the "grid" filter (the default
on a GPU; a software rasteriser's "single" keeps one tap).  The reference: a sphere light of
radius R, R = 0.3 m, 3 m above a floor, a thin slab with a straight edge between them; seen
from a floor point the light is a disc, the slab's edge cuts it along a line, and the share
of the disc left is the segment's area, in float64 (the light's disc taken level: below it,
off by at most a few per cent)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import Material, MeshRef, Mirror, PointLight, Skybox, Transform, look_rotation
from engine.assets.mesh import box, plane, quad
from engine.assets.portals import spawn_portal_pair
from engine.core.portal_math import pair_transform
from tests.support import look_from, pixel_rays, srgb_to_linear

SIZE = (128, 96)
LIGHT_HEIGHT = 3.0
RADIUS = 0.3


def floor_light(scene, slab_height: float | None, radius: float = RADIUS, rectangle=(0.0, 0.0),
                ceiling: bool = False, spot_angle: float = 180.0, defines: list | None = None, length: float = 0.0):
    """The floor's light (linear green, the "grid" filter) under the light, the slab's edge
    along z at x = 0 (the slab over x < 0) at ``slab_height`` (None: no slab), a ceiling 3 cm
    over the light where asked (``spot_angle``: its cone about straight down), and each floor
    pixel's point and whether it is the floor's; ``defines`` gets the shadow lookups' builds."""
    def build(world):
        look_from(world, (2.2, 1.0, 2.6), (-0.2, 0.0, 0.0), fov=55.0)
        world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
        world.spawn(Transform(), MeshRef(plane(20.0, 20.0)),
                    Material(color=(1.0, 1.0, 1.0), roughness=1.0, environment_reflection=0.0))
        if slab_height is not None:
            world.spawn(Transform(position=(-2.0, slab_height, 0.0)), MeshRef(box((4.0, 0.02, 8.0))),
                        Material(color=(0.0, 0.0, 0.0)))
        if ceiling:
            world.spawn(Transform(position=(0.0, LIGHT_HEIGHT + 0.04, 0.0)), MeshRef(box((20.0, 0.02, 20.0))),
                        Material(color=(0.0, 0.0, 0.0)))
        down = look_rotation((0.0, -1.0, 0.0), (0.0, 0.0, -1.0))
        world.spawn(Transform(position=(0.0, LIGHT_HEIGHT, 0.0), rotation=down),
                    PointLight(intensity=8.0, range=20.0, shadows=True, shadow_resolution=1024, radius=radius,
                               rectangle=rectangle, spot_angle=spot_angle, spot_blend=0.05, length=length))
    return grid_floor(scene(build, SIZE), defines)


def grid_floor(runner, defines: list | None = None):
    """``runner``'s second frame with the "grid" shadow filter (FXAA off) as linear green, each
    pixel's point on the floor (y = 0) and whether its ray meets it; ``defines`` gets the
    shadow lookups' builds."""
    from tests.support import pixel_rays, srgb_to_linear

    runner.engine.renderer.antialias = "off"
    runner.engine.renderer.shadows.filter = "grid"
    runner.frame()
    shown = srgb_to_linear(runner.frame())[..., 1].reshape(-1)
    if defines is not None:
        defines.extend(runner.engine.renderer.shadows.program_defines)
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    rays = rays.reshape(-1, 3)
    t = -eye[1] / rays[:, 1]
    return shown, eye + rays * np.where(t > 0, t, 0.0)[:, None], t > 0


def disc_left(x: np.ndarray, slab_height: float, radius: float) -> np.ndarray:
    """The share of a level disc of ``radius`` at the light's height that a floor point at
    ``x`` sees past the slab's edge: the edge, seen from the point, meets the light's height at
    x_L = -x (h - s) / s... (h the light's height, s the slab's): the light left of it is hidden."""
    edge = -x * (LIGHT_HEIGHT - slab_height) / slab_height   # where the edge's line meets the light's height
    u = np.clip(edge / radius, -1.0, 1.0)
    hidden = (math.pi - np.arccos(u) + u * np.sqrt(1.0 - u * u)) / math.pi   # the disc's part left of x = u R
    return 1.0 - hidden


def shadow_share(scene, slab_height, **light):
    lit, points, floor = floor_light(scene, slab_height, **light)
    open_, _, _ = floor_light(scene, None, **light)
    keep = floor & (open_ > 0.05) & (np.abs(points[:, 2]) < 2.5) & (points[:, 0] > -3.0)
    return lit[keep] / open_[keep], points[keep]


def penumbra_width(share: np.ndarray, x: np.ndarray) -> float:
    """The floor's stretch where the light left goes from 20% to 80%."""
    order = np.argsort(x)
    x, share = x[order], share[order]
    return float(x[np.argmax(share > 0.8)] - x[np.argmax(share > 0.2)])


def test_a_sphere_lights_shadow_follows_its_disc_across_the_penumbra(scene):
    """Slab 1.5 m up: the penumbra 2 R (3 - 1.5) / 1.5 = 0.6 m wide, each floor pixel's light
    within 0.15 of the disc's share left; the 20-80% stretch within 30% of the disc's."""
    share, points = shadow_share(scene, 1.5)
    expected = disc_left(points[:, 0], 1.5, RADIUS)
    band = np.abs(points[:, 0]) < 0.6
    assert band.sum() > 200
    error = np.abs(share - expected)
    assert np.percentile(error[band], 90) < 0.15, np.percentile(error[band], 90)
    assert np.median(error) < 0.05
    measured, reference = penumbra_width(share, points[:, 0]), penumbra_width(expected, points[:, 0])
    assert abs(measured / reference - 1.0) < 0.3, (measured, reference)


def test_the_penumbra_hardens_where_the_caster_nears_the_floor(scene):
    """The same slab 0.5 m up: its penumbra 2 R (3 - 0.5) / 0.5 = 0.12 m, a fifth of the one
    at 1.5 m (contact hardening); a point light (radius 0) draws the hard edge of its map."""
    high, high_points = shadow_share(scene, 1.5)
    low, low_points = shadow_share(scene, 0.5)
    hard, hard_points = shadow_share(scene, 1.5, radius=0.0)
    wide, narrow = penumbra_width(high, high_points[:, 0]), penumbra_width(low, low_points[:, 0])
    sharp = penumbra_width(hard, hard_points[:, 0])
    assert narrow < wide / 3.0, (narrow, wide)
    assert sharp < wide / 6.0, (sharp, wide)


def test_a_rectangle_softens_its_shadow_as_its_disc_would(scene):
    """A 1 x 0.3 m panel facing down: a penumbra as wide as its disc of the same area gives
    (within 35%)."""
    share, points = shadow_share(scene, 1.5, radius=0.0, rectangle=(1.0, 0.3))
    size = math.sqrt(0.3 / math.pi)
    measured = penumbra_width(share, points[:, 0])
    reference = penumbra_width(disc_left(points[:, 0], 1.5, size), points[:, 0])
    assert abs(measured / reference - 1.0) < 0.35, (measured, reference)


def test_a_tube_softens_its_shadow_as_the_disc_of_its_outlines_area(scene):
    """A tube 1 m long, 5 cm round, across the slab's edge: a penumbra as wide as the disc of
    its outline's area (1 x 0.1 m: R = 0.18 m) gives, the 20-80% stretch of the binned share
    within 20% (measured 7% narrower; the disc of half that area's 30% narrower)."""
    share, points = shadow_share(scene, 1.5, radius=0.05, length=1.0)
    measured = binned_width(share, points[:, 0])
    reference = binned_width(disc_left(points[:, 0], 1.5, math.sqrt(0.1 / math.pi)), points[:, 0])
    assert abs(measured / reference - 1.0) < 0.2, (measured, reference)


def test_the_wall_a_panel_hangs_on_blocks_none_of_its_light(scene):
    """A softbox 2 cm before a side wall, facing into a room with a floor and a back wall: the
    back wall and the floor take the same light with the side wall as without it (within 2%).
    The blocker search about a direction near the panel's plane reaches the wall behind it;
    were that counted, the penumbra it gives would spread the filter's taps over the floor
    and the walls (with the rectangle's front left out of the search: up to 15 levels in 255
    on 569 pixels)."""
    from components import yaw_pitch_rotation
    from tests.support import srgb_to_linear

    def room(side_wall: bool):
        def build(world):
            look_from(world, (0.0, 1.5, 3.0), (-1.0, 1.5, -3.0), fov=60.0)
            world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
            white = Material(color=(1.0, 1.0, 1.0), roughness=1.0, environment_reflection=0.0)
            world.spawn(Transform(position=(0.0, 1.5, -3.0)), MeshRef(box((8.0, 3.0, 0.1))), white)
            world.spawn(Transform(position=(0.0, -0.05, 0.0)), MeshRef(box((8.0, 0.1, 10.0))), white)
            if side_wall:
                world.spawn(Transform(position=(-3.0, 1.5, 0.0)), MeshRef(box((0.1, 3.0, 10.0))),
                            Material(color=(0.0, 0.0, 0.0)))
            world.spawn(Transform(position=(-2.93, 1.4, -1.2), rotation=yaw_pitch_rotation(-90, 0)),
                        PointLight(intensity=6.0, range=12.0, shadows=True, rectangle=(0.8, 1.4)))
        runner = scene(build, SIZE)
        runner.engine.renderer.antialias = "off"
        runner.engine.renderer.shadows.filter = "grid"
        runner.frame()
        return srgb_to_linear(runner.frame())[..., 1].reshape(-1), runner.ids().reshape(-1)
    open_, ids = room(False)
    walled, walled_ids = room(True)
    same = (ids == walled_ids) & (open_ > 0.02)   # the back wall's and the floor's pixels, lit
    assert same.sum() > 4000
    np.testing.assert_allclose(walled[same], open_[same], rtol=0.02, atol=2e-3)


def test_a_rectangle_draws_no_cube_face_behind_it(scene):
    """A panel facing straight down sheds no light above its plane: its cube's upward face is
    neither drawn nor read (five faces drawn, a sphere light's six), and the floor's light is
    the same as with all six (a caster above the panel changes nothing)."""
    from tests.support import srgb_to_linear

    def frame(radius, rectangle, caster_above):
        def build(world):
            look_from(world, (2.2, 1.0, 2.6), (-0.2, 0.0, 0.0), fov=55.0)
            world.spawn(Transform(), MeshRef(plane(20.0, 20.0)), Material(color=(1.0, 1.0, 1.0), roughness=1.0))
            world.spawn(Transform(position=(-1.0, 0.5, 0.0)), MeshRef(box((0.5, 1.0, 0.5))), Material())
            if caster_above:
                world.spawn(Transform(position=(0.0, LIGHT_HEIGHT + 0.5, 0.0)), MeshRef(box((1.0, 0.1, 1.0))),
                            Material())
            down = look_rotation((0.0, -1.0, 0.0), (0.0, 0.0, -1.0))
            world.spawn(Transform(position=(0.0, LIGHT_HEIGHT, 0.0), rotation=down),
                        PointLight(intensity=8.0, range=20.0, shadows=True, shadow_resolution=256, radius=radius,
                                   rectangle=rectangle))
        runner = scene(build, SIZE)
        runner.engine.renderer.shadows.filter = "grid"
        runner.frame()
        faces = runner.engine.renderer.stats.shadow_faces_drawn
        return faces, srgb_to_linear(runner.frame())
    panel_faces, panel = frame(0.0, (1.0, 0.3), False)
    sphere_faces, _ = frame(0.3, (0.0, 0.0), False)
    assert (panel_faces, sphere_faces) == (5, 6)
    _, covered = frame(0.0, (1.0, 0.3), True)
    np.testing.assert_array_equal(covered, panel)


def test_a_narrow_spot_with_a_size_casts_soft_from_its_cube(scene):
    """A 30-degree spot casts from a perspective map fitted to its cone; with a radius its
    shadow is soft, so it casts from its cube (the faces its cone lights), as wide a penumbra
    as the all-round sphere's (within 15%)."""
    def share(spot_angle: float, radius: float):
        defines: list = []
        lit, points, floor = floor_light(scene, 1.5, radius=radius, spot_angle=spot_angle, defines=defines)
        open_, _, _ = floor_light(scene, None, radius=radius, spot_angle=spot_angle)
        keep = floor & (open_ > 0.05) & (np.abs(points[:, 2]) < 0.8) & (np.abs(points[:, 0]) < 1.2)
        return penumbra_width(lit[keep] / open_[keep], points[keep, 0]), defines
    soft, defines = share(30.0, RADIUS)
    assert ("SOFT_POINT_SHADOWS", "1") in defines and ("SPOT_MAP0", "1") not in defines   # its cube
    hard, hard_defines = share(30.0, 0.0)
    assert ("SPOT_MAP0", "1") in hard_defines   # the perspective map fitted to its cone
    round_, _ = share(180.0, RADIUS)
    assert soft > 4.0 * hard and abs(soft / round_ - 1.0) < 0.15, (soft, hard, round_)


# --- the same soft shadow seen in a mirror and through a portal -----------------------------------------
SEEN_SIZE = (160, 120)
# A mirror 4 x 2.5 m hung high behind the scene, tilted to show the eye the floor about the slab's edge.
SEEN_EYE, MIRROR_AT = np.array([1.5, 1.0, 2.0]), np.array([0.0, 2.5, -4.0])
_halfway = [(end - MIRROR_AT) / np.linalg.norm(end - MIRROR_AT) for end in (SEEN_EYE, np.array([0.0, 0.0, -0.75]))]
MIRROR_NORMAL = (_halfway[0] + _halfway[1]) / np.linalg.norm(_halfway[0] + _halfway[1])


def seen_floor_light(scene, slab_height: float | None, how: str, radius: float = RADIUS, rectangle=(0.0, 0.0),
                     light=None):
    """The floor's light (linear green, the "grid" filter) as a mirror ("mirror") or a portal
    ("portal": A before the eye, B 3.5 m behind the light facing it) shows it, under the light
    of ``floor_light`` (or the one ``light(world)`` spawns) and the slab (3.5 m long here,
    ending before the eye and B): each pixel's floor point, found by reflecting its ray in the
    mirror's plane or carrying it by the pair's transform, and whether the pixel shows the
    floor in the mirror or the portal."""
    ids = {}

    def build(world):
        world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
        ids["floor"] = world.spawn(Transform(), MeshRef(plane(20.0, 20.0)),
                                   Material(color=(1.0, 1.0, 1.0), roughness=1.0, environment_reflection=0.0))
        if slab_height is not None:
            world.spawn(Transform(position=(-2.0, slab_height, -0.75)), MeshRef(box((4.0, 0.02, 3.5))),
                        Material(color=(0.0, 0.0, 0.0)))
        if light is not None:
            light(world)
        else:
            down = look_rotation((0.0, -1.0, 0.0), (0.0, 0.0, -1.0))
            world.spawn(Transform(position=(0.0, LIGHT_HEIGHT, 0.0), rotation=down),
                        PointLight(intensity=8.0, range=20.0, shadows=True, shadow_resolution=1024, radius=radius,
                                   rectangle=rectangle))
        if how == "mirror":
            look_from(world, tuple(SEEN_EYE), tuple(MIRROR_AT), fov=40.0)
            ids["surface"] = world.spawn(Transform(position=tuple(MIRROR_AT), rotation=look_rotation(-MIRROR_NORMAL)),
                                         MeshRef(quad(4.0, 2.5)), Material(), Mirror())
        else:
            look_from(world, (0.8, 1.0, 8.5), (0.0, 0.3, 6.0), fov=55.0)
            ids["surface"], ids["b"] = spawn_portal_pair(world, (0.0, 1.5, 6.0), None, (0.0, 1.5, -3.5), None,
                                                         size=(5.0, 3.0))
    runner = scene(build, SEEN_SIZE)
    runner.engine.renderer.antialias = "off"
    runner.engine.renderer.shadows.filter = "grid"
    runner.frame()
    shown = srgb_to_linear(runner.frame())[..., 1].reshape(-1)
    eye, rays = pixel_rays(runner.engine.main_view, SEEN_SIZE)
    if how == "mirror":
        t = ((MIRROR_AT - eye) @ MIRROR_NORMAL) / (rays @ MIRROR_NORMAL)
        at = eye + rays * t[..., None]
        turned = rays - 2.0 * (rays @ MIRROR_NORMAL)[..., None] * MIRROR_NORMAL
    else:
        world = runner.world
        carry = np.array(glm.dmat4(pair_transform(world.get(ids["surface"], Transform).world,
                                                  world.get(ids["b"], Transform).world)).to_list(), np.float64).T
        t = (6.0 - eye[2]) / rays[..., 2]
        at = (eye + rays * t[..., None]) @ carry[:3, :3].T + carry[:3, 3]
        turned = rays @ carry[:3, :3].T
    s = -at[..., 1] / turned[..., 1]
    points = (at + turned * s[..., None]).reshape(-1, 3)
    seen = (runner.engine.renderer.targets.read_surface_ids() == ids["surface"]) & (runner.ids() == ids["floor"])
    return shown, points, seen.reshape(-1) & (s.reshape(-1) > 0)


def binned_width(share: np.ndarray, x: np.ndarray, step: float = 0.04) -> float:
    """``penumbra_width`` for the few pixels a mirror or portal shows: the share's median over
    bins of x ``step`` wide (kept rising), its 20% and 80% crossings interpolated."""
    centres, medians = [], []
    for low in np.arange(-0.8, 0.8, step):
        inside = (x >= low) & (x < low + step)
        if inside.sum() >= 3:
            centres.append(low + step / 2.0)
            medians.append(np.median(share[inside]))
    rising = np.maximum.accumulate(np.array(medians))
    return float(np.interp(0.8, rising, centres) - np.interp(0.2, rising, centres))


@pytest.mark.parametrize(("how", "light"), [("mirror", "sphere"), ("portal", "sphere"), ("mirror", "rectangle")])
def test_a_soft_shadow_in_a_mirror_or_through_a_portal_is_the_discs_share_where_the_ray_lands(scene, how, light):
    """The slab 1.5 m up under a sphere light (R = 0.3 m) or a 1 x 0.3 m panel, seen only in a
    mirror or through a portal: each pixel's floor point found in float64 (the ray reflected
    in the mirror's plane, or carried by the pair's transform), its light (against the same
    view without the slab) within 0.15 of the share of the light's disc left at the 90th
    percentile there (measured 0.05), the penumbra's 20-80% stretch within 25% of the disc's
    (measured 6-11% narrower; a hard edge is a sixth of it)."""
    size = {"sphere": dict(radius=RADIUS), "rectangle": dict(radius=0.0, rectangle=(1.0, 0.3))}[light]
    lit, points, seen = seen_floor_light(scene, 1.5, how, **size)
    open_, _, _ = seen_floor_light(scene, None, how, **size)
    keep = seen & (open_ > 0.05) & (points[:, 2] > -2.0) & (points[:, 2] < 0.5) & (np.abs(points[:, 0]) < 1.5)
    share, x = lit[keep] / open_[keep], points[keep, 0]
    expected = disc_left(x, 1.5, RADIUS if light == "sphere" else math.sqrt(0.3 / math.pi))
    band = np.abs(x) < 0.6
    assert band.sum() > 200 and expected[band].min() < 0.05 and expected[band].max() > 0.95, band.sum()
    error = np.abs(share - expected)
    assert np.percentile(error[band], 90) < 0.15, np.percentile(error[band], 90)
    measured, reference = binned_width(share, x), binned_width(expected, x)
    assert abs(measured / reference - 1.0) < 0.25, (measured, reference)
