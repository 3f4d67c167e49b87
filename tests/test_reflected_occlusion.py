"""Ambient occlusion and contact shadows in mirror and portal views
(``AmbientOcclusion.reflection_depth``, ``ContactShadows.reflection_depth``;
``ScreenOcclusion.draw_level``): a reflection level is found from its own views' depth and
normals, so the world in a mirror or through a portal is occluded as it is seen directly.

Each check casts the pixels' rays in float64 apart from the engine: to the mirror's plane and
on, reflected, or into a portal and out of its partner (carried by the pair's rule, "looking
into either shows the other's front side"), then to the room's floor and wall or towards
the sun past the box, and compares the share the engine kept with the ground truth there, as
``tests/test_ambient_occlusion.py`` and ``tests/test_contact_shadows.py`` do for the camera's
own view.  A mirror's view is found from what it shows alone (its outline, and the screen's
edge, end what it can find), so the pixels judged are those well inside it."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from pyglm import glm

from components import (
    AmbientOcclusion,
    ComponentValueError,
    ContactShadows,
    Material,
    MeshRef,
    Mirror,
    Monitor,
    Transform,
    look_rotation,
)
from engine.assets.mesh import quad
from engine.assets.portals import spawn_portal_pair
from engine.core.errors import GLLimitWarning
from tests.support import box_hits, pixel_rays, srgb_to_linear
from tests.test_ambient_occlusion import GREY, RADIUS, WALL_FACE, _room, open_share
from tests.test_contact_shadows import BOX, SUN
from tests.test_contact_shadows import SIZE as CONTACT_SIZE
from tests.test_contact_shadows import _scene as contact_scene

SIZE = (200, 150)
MIRROR_X = -1.5          # the upright mirror's plane (facing +x, the wall's way)
INSIDE = 20              # pixels from a view's outline or the screen's edge: judged past it
BANDS = ((0.0, 0.1), (0.1, 0.25), (0.25, 0.45), (0.45, 0.65), (0.65, 0.85))
PORTAL_A = np.array([10.0, 1.3, 10.0])  # facing +z, away from everything
PORTAL_B = np.array([-1.5, 1.3, -0.5])  # facing +x, the wall's way


def _aim(runner, camera: int, eye, target) -> None:
    transform = runner.world.get(camera, Transform)
    transform.position = glm.vec3(eye)
    transform.rotation = look_rotation(glm.vec3(target) - glm.vec3(eye))


def _mirror_room(world, occlusion: AmbientOcclusion | None) -> dict:
    """The floor and wall of ``tests/test_ambient_occlusion.py`` and a large mirror facing the
    wall 1.75 m from it; the camera (aimed by ``_frame``) looks into the mirror, which shows
    the wall's foot."""
    names = _room(world, occlusion)
    names["mirror"] = world.spawn(
        Transform(position=(MIRROR_X, 1.3, -0.5), rotation=glm.angleAxis(glm.radians(90.0), glm.vec3(0, 1, 0))),
        MeshRef(quad(4.0, 2.4)), Mirror(), Material(color=GREY))
    return names


def _portal_room(world, occlusion: AmbientOcclusion | None) -> dict:
    """The same room seen through a portal: A stands alone far off, B in the room facing
    the wall where the mirror stood."""
    names = _room(world, occlusion)
    names["a"], names["b"] = spawn_portal_pair(
        world, tuple(PORTAL_A), None, tuple(PORTAL_B), glm.angleAxis(glm.radians(90.0), glm.vec3(0, 1, 0)),
        size=(3.0, 3.0))
    return names


MIRROR_EYE = ((-0.7, 1.5, -0.6), (-1.5, 0.95, -0.3))
PORTAL_EYE = ((10.0, 1.5, 10.8), (10.0, 1.04, 10.0))


def _frame(scene, build, occlusion, aim) -> tuple[np.ndarray, object, dict]:
    names: dict = {}
    runner = scene(lambda world: names.update(build(world, occlusion)), SIZE)
    _aim(runner, names["camera"], *aim)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return srgb_to_linear(runner.frame()), runner, names


def _shares(scene, build, occlusion, aim) -> tuple[np.ndarray, object, dict]:
    """Each pixel's share of its colour kept with ``occlusion`` (as test_ambient_occlusion's)."""
    lit, runner, names = _frame(scene, build, occlusion, aim)
    plain, _, _ = _frame(scene, build, None, aim)
    return (lit / np.maximum(plain, 1e-6)).mean(axis=-1), runner, names


def _inside(mask: np.ndarray, pixels: int) -> np.ndarray:
    """The pixels of ``mask`` at least ``pixels`` from its edge and the screen's."""
    inner = mask.copy()
    for _ in range(pixels):
        padded = np.pad(inner, 1, constant_values=False)
        inner &= padded[:-2, 1:-1] & padded[2:, 1:-1] & padded[1:-1, :-2] & padded[1:-1, 2:]
    return inner


def _reflected_rays(runner) -> tuple[np.ndarray, np.ndarray]:
    """Each pixel's ray after the mirror (x = MIRROR_X): where it meets the plane, and its way on."""
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    starts = eye + rays * ((MIRROR_X - eye[0]) / rays[..., 0])[..., None]
    ways = rays * np.array([-1.0, 1.0, 1.0])
    return starts, ways


def _carried_rays(runner) -> tuple[np.ndarray, np.ndarray]:
    """Each pixel's ray through portal A (the plane z = A's) and out of B: A's local point
    (x, y, z) leaves B at B's local (-x, y, -z), its way likewise, in B's frame (a quarter
    turn about y: B's local +z is the world's +x, its +x the world's -z)."""
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    at = eye + rays * ((PORTAL_A[2] - eye[2]) / rays[..., 2])[..., None] - PORTAL_A

    def out_of_b(local: np.ndarray) -> np.ndarray:
        x, y, z = -local[..., 0], local[..., 1], -local[..., 2]
        return np.stack([z, y, -x], axis=-1)   # B's rotation: (x, y, z) -> (z, y, -x)

    return out_of_b(at) + PORTAL_B, out_of_b(rays)


def _room_hits(starts: np.ndarray, ways: np.ndarray, shown: np.ndarray):
    """Where rays from ``starts`` along ``ways`` meet the floor (y = 0) or the wall's face,
    for the pixels ``shown``: (floor mask, its distance from the wall, wall mask, its height)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t_floor = -starts[..., 1] / ways[..., 1]
        t_wall = (WALL_FACE - starts[..., 0]) / ways[..., 0]
    floor = shown & (t_floor > 0) & ((t_floor < t_wall) | (t_wall <= 0))
    wall = shown & (t_wall > 0) & (t_wall < t_floor)
    floor_points = starts + ways * t_floor[..., None]
    wall_points = starts + ways * t_wall[..., None]
    return floor, WALL_FACE - floor_points[..., 0], wall, wall_points[..., 1]


def _assert_ground_truth(shares, floor, distance, wall, height, tolerance=0.03) -> None:
    for low, high in BANDS:
        band = floor & (distance > low) & (distance <= high)
        assert band.sum() > 100, (low, high, band.sum())
        expected = open_share(distance[band] / RADIUS).mean()
        assert shares[band].mean() == pytest.approx(expected, abs=tolerance), f"floor {low}-{high} m from the wall"
    for low, high in ((0.05, 0.3), (0.3, 0.6)):
        band = wall & (height > low) & (height <= high)
        assert band.sum() > 100, (low, high, band.sum())
        expected = open_share(height[band] / RADIUS).mean()
        assert shares[band].mean() == pytest.approx(expected, abs=tolerance), f"wall {low}-{high} m over the floor"
    far = floor & (distance > 1.3 * RADIUS)
    if far.sum() > 100:
        assert shares[far].mean() > 0.97


@pytest.mark.parametrize("half", [True, False], ids=["half", "full"])
def test_a_mirror_shows_the_room_occluded_as_the_ground_truth(scene, half):
    shares, runner, names = _shares(scene, _mirror_room, AmbientOcclusion(radius=RADIUS, half_resolution=half),
                                    MIRROR_EYE)
    assert runner.stats.reflection_views == 1
    surface = runner.engine.renderer.targets.read_surface_ids()
    shown = _inside(surface == names["mirror"], INSIDE)
    assert shown.sum() > 10000
    _assert_ground_truth(shares, *_room_hits(*_reflected_rays(runner), shown))


def test_through_a_portal_the_room_is_occluded_as_the_ground_truth(scene):
    shares, runner, names = _shares(scene, _portal_room, AmbientOcclusion(radius=RADIUS), PORTAL_EYE)
    assert runner.stats.reflection_views >= 1
    surface = runner.engine.renderer.targets.read_surface_ids()
    shown = _inside(surface == names["a"], INSIDE)
    assert shown.sum() > 10000
    _assert_ground_truth(shares, *_room_hits(*_carried_rays(runner), shown))


def test_at_reflection_depth_0_the_mirror_shows_the_room_unoccluded(scene):
    """The camera's own view alone: the mirror's pixels are those of a frame without
    occlusion, while the floor seen directly by the mirror's foot is darkened."""
    occlusion = AmbientOcclusion(radius=RADIUS, reflection_depth=0)
    lit, runner, names = _frame(scene, _mirror_room, occlusion, MIRROR_EYE)
    plain, _, _ = _frame(scene, _mirror_room, None, MIRROR_EYE)
    mirror = runner.engine.renderer.targets.read_surface_ids() == names["mirror"]
    assert mirror.sum() > 10000 and runner.stats.reflection_views == 1
    np.testing.assert_allclose(lit[mirror], plain[mirror], atol=2e-3)
    assert np.abs(lit - plain)[~mirror].max() > 0.05
    assert runner.engine.renderer.occlusion.target_count() == 4   # the camera's view's images alone


def test_each_level_reached_is_found_and_its_images_go_with_it(scene):
    """A mirror facing another: level 1 and level 2 are found where the depth reaches them,
    three passes and four images each, and let go when it no longer does."""
    occlusion = AmbientOcclusion(radius=RADIUS, reflection_depth=2)

    def build(world, occlusion):
        names = _mirror_room(world, occlusion)
        # A second mirror behind the camera, facing the first: level 2 sees the first again.
        names["back"] = world.spawn(
            Transform(position=(0.0, 1.3, -0.5), rotation=glm.angleAxis(glm.radians(-90.0), glm.vec3(0, 1, 0))),
            MeshRef(quad(1.0, 1.0)), Mirror(), Material(color=GREY))
        return names

    _, runner, names = _frame(scene, build, occlusion, MIRROR_EYE)
    found = runner.engine.renderer.occlusion
    assert runner.stats.reflection_views >= 2
    assert found.target_count() == 12 and sorted(found._levels) == [1, 2]
    passes = runner.stats.passes
    occlusion.reflection_depth = 1
    runner.frame()
    assert found.target_count() == 8 and sorted(found._levels) == [1]
    assert runner.stats.passes == passes - 3
    occlusion.reflection_depth = 0
    runner.frame()
    assert found.target_count() == 4 and runner.stats.passes == passes - 6
    occlusion.reflection_depth = 2
    runner.frame()
    assert found.target_count() == 12
    for mirror in (names["mirror"], names["back"]):   # the mirrors go: their levels' images with them
        runner.world.delete_entity(mirror)
    runner.frame()
    assert found.target_count() == 4
    runner.world.remove_component(names["camera"], AmbientOcclusion)
    runner.frame()
    assert found.target_count() == 0 and runner.engine.renderer.resource_counts()["occlusion_targets"] == 0


def _two_mirrors(right_reflects: bool):
    """Two mirrors side by side, turned apart (80 and 100 degrees about the vertical), the
    right one a mirror or a plain quad of the same shape."""
    def build(world, occlusion):
        names = _room(world, occlusion)
        for name, z, turn in (("left", -1.5, 80.0), ("right", 0.5, 100.0)):
            parts = (Mirror(),) if name == "left" or right_reflects else ()
            names[name] = world.spawn(
                Transform(position=(MIRROR_X, 1.3, z), rotation=glm.angleAxis(glm.radians(turn), glm.vec3(0, 1, 0))),
                MeshRef(quad(2.0, 2.4)), Material(color=GREY), *parts)
        return names
    return build


def test_two_mirrors_side_by_side_each_find_their_own_world(scene):
    """Two views of one level, edge to edge on the screen, each showing another world: the
    left mirror's pixels are the same whether the right one's view shares its level (a
    mirror) or not (a plain quad: the left's view alone in the level), so a view's samples
    stop at the other's pixels; and the right one's floor is occluded as its reflection's
    ground truth says.  (With the find and filter taking the other view's texels the left
    mirror's pixels by the shared edge changed by up to 0.16.)"""
    occlusion = AmbientOcclusion(radius=RADIUS)
    both, runner, names = _frame(scene, _two_mirrors(True), occlusion, MIRROR_EYE)
    alone, runner_alone, _ = _frame(scene, _two_mirrors(False), AmbientOcclusion(radius=RADIUS), MIRROR_EYE)
    assert runner.stats.reflection_views == 2 and runner_alone.stats.reflection_views == 1
    surface = runner.engine.renderer.targets.read_surface_ids()
    left = surface == names["left"]
    assert left.sum() > 5000
    np.testing.assert_allclose(both[left], alone[left], atol=2e-3)
    plain, _, _ = _frame(scene, _two_mirrors(True), None, MIRROR_EYE)
    shares = (both / np.maximum(plain, 1e-6)).mean(axis=-1)
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    normal = np.array(glm.angleAxis(glm.radians(100.0), glm.vec3(0, 1, 0)) * glm.vec3(0, 0, 1), np.float64)
    centre = np.array(runner.world.get(names["right"], Transform).position, np.float64)
    starts = eye + rays * (((centre - eye) @ normal) / (rays @ normal))[..., None]
    ways = rays - 2.0 * (rays @ normal)[..., None] * normal
    floor, distance, _, _ = _room_hits(starts, ways, _inside(surface == names["right"], 8))
    for low, high in ((0.0, 0.15), (0.15, 0.45), (0.45, 0.85)):
        band = floor & (distance > low) & (distance <= high)
        assert band.sum() > 100, (low, high, band.sum())
        expected = open_share(distance[band] / RADIUS).mean()
        assert shares[band].mean() == pytest.approx(expected, abs=0.04), (low, high)


CEILING = 1.5   # the mirror overhead, facing down
MARGIN = 0.03   # metres either side of the box's foot left out
REACH_MARGIN = 0.05   # and of the ray's reach: 3 pixels of the floor there (the find's steps, a texel)


def _overhead(names: dict, world) -> dict:
    """A scene of ``tests/test_contact_shadows.py`` (its ``names``) seen in a mirror overhead by
    a camera looking up at it: the mirror's view looks down on the box from where that test's
    camera stood."""
    transform = world.get(names["camera"], Transform)
    transform.position = glm.vec3(0.3, 1.0, 0.05)
    transform.rotation = look_rotation(glm.vec3(0.0, 0.5, -0.05))
    names["mirror"] = world.spawn(
        Transform(position=(0.3, CEILING, 0.0), rotation=glm.angleAxis(glm.radians(90.0), glm.vec3(1, 0, 0))),
        MeshRef(quad(4.0, 4.0)), Mirror(), Material(color=(0.5, 0.5, 0.5)))
    return names


OVERHEAD_A = np.array([10.0, 1.3, 10.0])   # portal A, facing +z, away from everything
OVERHEAD_B = np.array([0.3, CEILING, 0.0])   # portal B over the box, facing down (the overhead mirror's place)


def _overhead_portal(names: dict, world) -> dict:
    """A scene of ``tests/test_contact_shadows.py`` (its ``names``) seen through a portal pair:
    the camera 0.5 m before A looking into it, B overhead facing down where ``_overhead``'s
    mirror hangs, so the portal's view looks down on the box from 0.5 m over B."""
    transform = world.get(names["camera"], Transform)
    transform.position = glm.vec3(*(OVERHEAD_A + (0.0, 0.0, 0.5)))
    transform.rotation = look_rotation(glm.vec3(0.0, 0.0, -1.0))
    names["mirror"], names["b"] = spawn_portal_pair(
        world, tuple(OVERHEAD_A), None, tuple(OVERHEAD_B), glm.angleAxis(glm.radians(90.0), glm.vec3(1, 0, 0)),
        size=(3.0, 3.0))
    return names


def _carried_down(eye: np.ndarray, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each pixel's ray through A (the plane z = A's) and out of B: A's local (x, y, z) leaves B
    at B's local (-x, y, -z), and B's quarter turn about x takes local (x, y, z) to the world's
    (x, -z, y): so the world's (-x, z, y) about B, its way likewise."""
    at = eye + rays * ((OVERHEAD_A[2] - eye[2]) / rays[..., 2])[..., None] - OVERHEAD_A

    def out_of_b(local: np.ndarray) -> np.ndarray:
        return np.stack([-local[..., 0], local[..., 2], local[..., 1]], axis=-1)

    return out_of_b(at) + OVERHEAD_B, out_of_b(rays)


def _kept_in_mirror(scene, build, contact: ContactShadows, dark: dict, watched: bool = False,
                    portal: bool = False) -> tuple:
    """The overhead mirror over ``build``'s scene (``build(world, contact, **options)``): each
    pixel's share of the light ``dark`` turns off kept under ``contact`` (linear, as
    ``tests/test_contact_shadows.py`` finds it), each pixel's floor point (its ray reflected
    off the ceiling to the floor, float64), the mirror's floor pixels to judge (lit, clear of
    the box's footprint) and the runner drawn with ``contact``.  ``watched``: ``contact`` on a
    monitor's camera posed as the active one (which has none), the picture's pixels judged
    (the frame and the picture ``tests/test_contact_shadows.py``'s size).  ``portal``: the
    scene seen through a portal pair in place of the mirror (``_overhead_portal``: each pixel's
    ray carried out of B), its A the surface judged (``names["mirror"]``)."""
    def posed(names: dict, world) -> dict:
        (_overhead_portal if portal else _overhead)(names, world)
        if watched:   # (the lens where the active camera now stands)
            lens = world.get(world.get(names["screen"], Monitor).camera, Transform)
            active = world.get(names["camera"], Transform)
            lens.position, lens.rotation = active.position, active.rotation
        return names

    frames = []
    for light_off, shadows in (({}, contact), ({}, None), (dark, None)):
        names: dict = {}
        extra = {"watched": True} if watched else {}
        runner = scene(lambda world, names=names, shadows=shadows, light_off=light_off, extra=extra: names.update(
            posed(build(world, shadows, **light_off, **extra), world)), CONTACT_SIZE if watched else SIZE)
        runner.engine.renderer.antialias = "off"
        runner.frame()
        frame = srgb_to_linear(runner.frame())
        if watched:
            frame = runner.engine.renderer.monitors.read(names["screen"])[..., :3].astype(np.float64)
        frames.append((frame, runner, names))
    (shadowed, runner, names), (lit, _, _), (off, _, _) = frames
    light = (lit - off).mean(axis=-1)
    kept = (shadowed - off).mean(axis=-1) / np.maximum(light, 1e-6)
    assert runner.stats.reflection_views == 1
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    if portal:
        starts, ways = _carried_down(eye, rays)
    else:
        starts = eye + rays * ((CEILING - eye[1]) / rays[..., 1])[..., None]
        ways = rays * np.array([1.0, -1.0, 1.0])
    points = starts + ways * (-starts[..., 1] / ways[..., 1])[..., None]
    floor = (runner.engine.renderer.targets.read_surface_ids() == names["mirror"]) & (light > 0.02)
    floor &= ~((np.abs(points[..., 0] - BOX[0][0]) < BOX[1][0] + MARGIN)
               & (np.abs(points[..., 2] - BOX[0][2]) < BOX[1][2] + MARGIN))
    return kept, points, floor


def _judged(points: np.ndarray, floor: np.ndarray, towards: np.ndarray, reach, grow: float) -> tuple:
    """The floor pixels whose ray ``towards`` the light (unit, a row a floor pixel) meets the
    box shrunk by ``grow`` within ``reach`` less REACH_MARGIN (surely shadowed), and those that
    miss it grown by ``grow`` within ``reach`` plus it (surely lit)."""
    inside = np.zeros(floor.shape, bool)
    outside = np.zeros(floor.shape, bool)
    rows = points[floor]
    inside[floor] = box_hits(rows, towards, BOX[0], BOX[1] - grow, limit=reach - REACH_MARGIN)
    outside[floor] = ~box_hits(rows, towards, BOX[0], BOX[1] + grow, limit=reach + REACH_MARGIN)
    return inside, outside


@pytest.mark.parametrize("watched", [False, True], ids=["camera", "picture"])
@pytest.mark.parametrize("depth", [1, 0])
def test_a_mirror_shows_the_contact_shadow_where_the_sun_ray_meets_the_box(scene, depth, watched):
    """Each floor point the mirror shows (its pixel's ray reflected off the ceiling): within
    the ray's reach of the box towards the sun its sun is gone, outside it kept; at
    reflection_depth 0 it is kept everywhere (the camera's own view sees only the mirror).
    ``watched``: the same in the mirror level of a monitor's picture whose camera, posed as
    the active one (which has none) at the frame's size, has the ``ContactShadows`` (the
    picture's levels occluded as its camera's component reaches: ``ScreenOcclusion.draw_picture``),
    judged by the rays cast from the active camera's view."""
    contact = ContactShadows(length=0.3, thickness=0.5, reflection_depth=depth)
    kept, points, floor = _kept_in_mirror(scene, contact_scene, contact, {"sun": 0.0}, watched=watched)
    towards = np.broadcast_to(-np.array(SUN, np.float64), points[floor].shape)
    inside, outside = _judged(points, floor, towards, contact.length, 0.0)
    assert inside.sum() > 120 and outside.sum() > 5000, (inside.sum(), outside.sum())
    if depth:
        assert np.median(kept[inside]) < 0.05 and np.percentile(kept[inside], 90) < 0.25, kept[inside]
    else:
        assert np.percentile(kept[inside], 5) > 0.97
    assert np.percentile(kept[outside], 0.5) > 0.9, np.percentile(kept[outside], 0.5)


@pytest.mark.parametrize("watched", [False, True], ids=["camera", "picture"])
@pytest.mark.parametrize("depth", [1, 0])
def test_through_a_portal_the_contact_shadow_lies_where_the_sun_ray_meets_the_box(scene, depth, watched):
    """The box under the sun seen through a portal pair, B overhead facing down (the view
    looks down on the box from 0.5 m over B): each floor point the portal shows (its pixel's
    ray carried out of B to the floor), within the ray's reach of the box towards the sun, has
    lost its sun, outside it kept; at reflection_depth 0 kept everywhere.  ``watched``: the
    same in the portal level of a monitor's picture whose camera, posed as the active one (which
    has none) at the frame's size, has the ``ContactShadows``, judged by the rays carried from
    the active camera's view."""
    contact = ContactShadows(length=0.3, thickness=0.5, reflection_depth=depth)
    kept, points, floor = _kept_in_mirror(scene, contact_scene, contact, {"sun": 0.0}, watched=watched, portal=True)
    towards = np.broadcast_to(-np.array(SUN, np.float64), points[floor].shape)
    inside, outside = _judged(points, floor, towards, contact.length, 0.0)
    assert inside.sum() > 120 and outside.sum() > 5000, (inside.sum(), outside.sum())
    if depth:
        assert np.median(kept[inside]) < 0.05 and np.percentile(kept[inside], 90) < 0.25, kept[inside]
    else:
        assert np.percentile(kept[inside], 5) > 0.97
    assert np.percentile(kept[outside], 0.5) > 0.9, np.percentile(kept[outside], 0.5)


def test_a_context_without_the_texture_units_finds_the_camera_view_alone(scene):
    """Where the fragment stage has fewer texture units than an occluded level's builds read
    (ScreenOcclusion.levels_supported False: 16, GL 4.1's least), the mirror shows the room
    unoccluded and a GLLimitWarning says so, once."""
    frames = {}
    for name, depth in (("short", 1), ("none", 0)):
        names: dict = {}
        occlusion = AmbientOcclusion(radius=RADIUS, reflection_depth=depth)
        runner = scene(lambda world, names=names, occlusion=occlusion: names.update(_mirror_room(world, occlusion)),
                       SIZE)
        _aim(runner, names["camera"], *MIRROR_EYE)
        runner.engine.renderer.antialias = "off"
        runner.engine.renderer.occlusion.levels_supported = False
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            runner.frame()
            frames[name] = runner.frame()
        said = [w for w in caught if issubclass(w.category, GLLimitWarning)]
        assert len(said) == (1 if depth else 0)
        if said:
            assert "reflection_depth 1" in str(said[0].message) and "GL_MAX_TEXTURE_IMAGE_UNITS" in str(said[0].message)
    np.testing.assert_array_equal(frames["short"], frames["none"])


@pytest.mark.parametrize("kind", [AmbientOcclusion, ContactShadows])
@pytest.mark.parametrize("value", [-1, 17, 1.5, True, "1"])
def test_bad_depths_are_refused_naming_the_field(kind, value):
    with pytest.raises(ComponentValueError, match="reflection_depth"):
        kind(reflection_depth=value)


def test_a_mirror_shows_a_lamps_contact_shadow_where_its_ray_meets_the_box(scene):
    """The lamp of ``tests/test_contact_shadows.py``'s lamp scene (``PointLight.contact_shadows``)
    seen in the overhead mirror: each floor point the mirror shows, its ray towards the lamp
    cast against the box (shrunk and grown by the margin): within the reach the lamp's light
    is gone, outside it kept (the lamp carried into the mirror's view's space)."""
    from tests.test_contact_shadows import LAMP, _lamp_scene

    contact = ContactShadows(length=0.3, thickness=0.5)
    kept, points, floor = _kept_in_mirror(scene, _lamp_scene, contact, {"intensity": 0.0})
    towards = LAMP - points[floor]
    reach = np.linalg.norm(towards, axis=-1)
    inside, outside = _judged(points, floor, towards / reach[:, None], np.minimum(contact.length, reach), MARGIN)
    assert inside.sum() > 80 and outside.sum() > 5000, (inside.sum(), outside.sum())
    assert np.median(kept[inside]) < 0.05 and np.percentile(kept[inside], 90) < 0.3, kept[inside]
    assert np.percentile(kept[outside], 0.5) > 0.9, np.percentile(kept[outside], 0.5)


def _watched_room(scene, build, aim, occlusion, active: bool) -> tuple[np.ndarray, object, dict]:
    """``build``'s room with a monitor whose camera (not active, posed at ``aim`` as the active
    one, at the picture's size, ``depth`` 1) has ``occlusion`` (None: nothing), the active
    camera the same component of its own where ``active``: the picture (linear), the runner
    and the names (the active camera's frame, linear, as ``frame``)."""
    from components import Camera, Monitor

    names: dict = {}

    def room(world):
        own = AmbientOcclusion(radius=RADIUS, reflection_depth=occlusion.reflection_depth) \
            if active and occlusion is not None else None   # (the active camera's: a component of its own)
        names.update(build(world, own))
        eye, target = (glm.vec3(point) for point in aim)
        pose = dict(position=eye, rotation=look_rotation(target - eye))
        camera = world.get(names["camera"], Camera)
        names["lens"] = world.spawn(Transform(**pose), Camera(fov_y=camera.fov_y, near=camera.near, far=camera.far,
                                                              active=False), *([occlusion] if occlusion else []))
        names["screen"] = world.spawn(Transform(position=(-6.0, 1.0, 3.0)), MeshRef(quad(1.6, 0.9)),
                                      Material(color=(0.0, 0.0, 0.0), roughness=1.0),
                                      Monitor(camera=names["lens"], size=SIZE, depth=1))

    runner = scene(room, SIZE)
    _aim(runner, names["camera"], *aim)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    names["frame"] = srgb_to_linear(runner.frame())
    return runner.engine.renderer.monitors.read(names["screen"])[..., :3].astype(np.float64), runner, names


@pytest.mark.parametrize("active", [False, True], ids=["lens_alone", "both"])
def test_a_monitors_camera_finds_the_occlusion_in_the_mirror_its_picture_shows(scene, active):
    """A monitor whose camera (not active, posed as the mirror test's camera, at the
    picture's size) has ``AmbientOcclusion(reflection_depth=1)``: its picture shows the room in
    the mirror occluded as the ground truth (the active camera, posed the same, gives the rays
    and the mirror's pixels); its levels' images are the picture's own (4 for its root, 4 for
    its mirror level), let go with the camera's component.  At ``reflection_depth`` 0 the
    mirror in the picture is bare.  ``both``: the active camera has the same component, and
    its own frame's mirror is occluded as the ground truth too (the picture's images put
    aside for it and back)."""
    def picture(occlusion):
        return _watched_room(scene, _mirror_room, MIRROR_EYE, occlusion, active)

    lit, runner, names = picture(AmbientOcclusion(radius=RADIUS, reflection_depth=1))
    plain, _, plain_names = picture(None)
    bare, _, _ = picture(AmbientOcclusion(radius=RADIUS, reflection_depth=0))
    shares = (lit / np.maximum(plain, 1e-6)).mean(axis=-1)
    surface = runner.engine.renderer.targets.read_surface_ids()   # (the active camera's: the lens's pose and size)
    shown = _inside(surface == names["mirror"], INSIDE)
    hits = _room_hits(*_reflected_rays(runner), shown)
    _assert_ground_truth(shares, *hits)
    assert runner.engine.renderer.occlusion.target_count() == (16 if active else 8)
    if active:
        _assert_ground_truth((names["frame"] / np.maximum(plain_names["frame"], 1e-6)).mean(axis=-1), *hits)
    bare_shares = (bare / np.maximum(plain, 1e-6)).mean(axis=-1)
    assert bare_shares[shown].min() > 0.98   # (the mirror bare; the room seen directly is found as before)
    runner.world.remove_component(names["lens"], AmbientOcclusion)
    runner.frame()
    assert runner.engine.renderer.occlusion.target_count() == (8 if active else 0)


@pytest.mark.parametrize("active", [False, True], ids=["lens_alone", "both"])
def test_a_monitors_camera_finds_the_occlusion_in_the_portal_its_picture_shows(scene, active):
    """The portal room seen by a monitor's camera (not active, posed as the portal test's
    camera, at the picture's size) with ``AmbientOcclusion(reflection_depth=1)``: the room
    beyond portal A, in the picture's portal level, is occluded as the ground truth along the
    rays carried out of B (cast from the active camera's view, posed the same, which gives
    portal A's pixels too); 4 images for the picture's root and 4 for its level.  At
    ``reflection_depth`` 0 the room through the portal is bare in the picture.  ``both``: the
    active camera has the same component and its frame's portal is occluded as the truth too."""
    def picture(occlusion):
        return _watched_room(scene, _portal_room, PORTAL_EYE, occlusion, active)

    lit, runner, names = picture(AmbientOcclusion(radius=RADIUS, reflection_depth=1))
    plain, _, plain_names = picture(None)
    bare, _, _ = picture(AmbientOcclusion(radius=RADIUS, reflection_depth=0))
    surface = runner.engine.renderer.targets.read_surface_ids()
    shown = _inside(surface == names["a"], INSIDE)
    assert shown.sum() > 10000
    hits = _room_hits(*_carried_rays(runner), shown)
    _assert_ground_truth((lit / np.maximum(plain, 1e-6)).mean(axis=-1), *hits)
    assert runner.engine.renderer.occlusion.target_count() == (16 if active else 8)
    if active:
        _assert_ground_truth((names["frame"] / np.maximum(plain_names["frame"], 1e-6)).mean(axis=-1), *hits)
    bare_shares = (bare / np.maximum(plain, 1e-6)).mean(axis=-1)
    assert bare_shares[shown].min() > 0.98


def test_a_pictures_draw_that_raises_leaves_the_active_cameras_effects_as_they_were(scene, monkeypatch):
    """The mirror room with the active camera and a monitor's camera (posed alike) both with
    occlusion, screen reflections and light shafts reaching one level: a picture's tree that
    raises mid-draw (the error comes out of the frame) leaves the passes' state the active
    camera's (``end_picture`` whatever happened): with the monitor gone after (no later
    picture to put it back), the frames are the frames of an engine whose picture never
    failed."""
    from components import Camera, DirectionalLight, Fog, Monitor, ScreenReflections, VolumetricFog
    from engine.render import view_tree

    def build(names):
        def b(world):
            names.update(_mirror_room(world, AmbientOcclusion(radius=RADIUS)))
            world.spawn(DirectionalLight(direction=(0.6, -1.0, 0.3), intensity=2.0))   # (the shafts' light)
            eye, target = (glm.vec3(point) for point in MIRROR_EYE)
            for entity in (names["camera"],):
                world.add_component(entity, ScreenReflections())
                world.add_component(entity, VolumetricFog(steps=16))
                world.add_component(entity, Fog(density=0.05))
            names["lens"] = world.spawn(Transform(position=eye, rotation=look_rotation(target - eye)),
                                        Camera(active=False), AmbientOcclusion(radius=RADIUS), ScreenReflections(),
                                        VolumetricFog(steps=16), Fog(density=0.05))
            names["screen"] = world.spawn(Transform(position=(-6.0, 1.0, 3.0)), MeshRef(quad(1.6, 0.9)),
                                          Material(color=(0.0, 0.0, 0.0), roughness=1.0),
                                          Monitor(camera=names["lens"], size=(64, 48), depth=1))
        return b

    def engine():
        names: dict = {}
        runner = scene(build(names), SIZE)
        _aim(runner, names["camera"], *MIRROR_EYE)
        runner.engine.renderer.antialias = "off"
        return runner

    failing, sound = engine(), engine()
    render = view_tree.ViewTree.render
    calls = {"n": 0}

    def raising(self, *args, **kwargs):
        if self is failing.engine.renderer.monitors.tree and calls["n"] == 0:
            calls["n"] += 1
            raise RuntimeError("a picture's tree failed")
        return render(self, *args, **kwargs)

    sound.frame()
    with monkeypatch.context() as patch:
        patch.setattr(view_tree.ViewTree, "render", raising)
        with pytest.raises(RuntimeError, match="a picture's tree failed"):
            failing.frame()
        assert calls["n"] == 1
        for runner in (failing, sound):   # (no picture after: nothing puts the camera's state back but end_picture)
            screen = next(entity for entity, _ in runner.world.query_one(Monitor))
            runner.world.remove_component(screen, Monitor)
        for _ in range(2):
            assert np.array_equal(failing.frame(), sound.frame())
