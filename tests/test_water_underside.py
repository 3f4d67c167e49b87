"""Water seen from below (the camera under the surface): the underside reflects everything
past the critical angle (total internal reflection) and shows the air above through Snell's
window, bent away from the normal.  Each is measured in rendered frames against the optics
worked out here, ray by ray."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    Emissive,
    Material,
    MeshRef,
    Mirror,
    ReflectionProbe,
    Skybox,
    Transform,
    Water,
    look_rotation,
)
from engine.assets.mesh import quad, sphere
from engine.resources import Surfaces
from tests.support import kept_frames_equal_drawn, srgb_to_linear
from tests.test_water import FLAT, FLOOR_SEEN, SKY, pool, render, schlick, uniform_sky

INDEX = 1.333
F0 = ((INDEX - 1.0) / (INDEX + 1.0)) ** 2
CRITICAL = math.asin(1.0 / INDEX)  # from the normal, in the water
# A quad faces +Z; turned this way it lies flat, facing down.
FACING_DOWN = glm.angleAxis(math.pi / 2, glm.vec3(1, 0, 0))


def under(eye, target):
    """``pool``'s clear pond with the camera at ``eye`` (under the surface) looking at ``target``."""
    return lambda world: pool(world, True, eye, target)


def pixel_ray(runner, column: int, row: int) -> tuple[glm.vec3, glm.vec3]:
    """The eye and unit direction of a pixel centre's ray in the main view."""
    view = runner.engine.main_view
    w, h = runner.size
    ndc = glm.vec4((column + 0.5) / w * 2.0 - 1.0, 1.0 - (row + 0.5) / h * 2.0, -1.0, 1.0)
    near = glm.inverse(view.view_proj) * ndc
    return view.eye, glm.normalize(glm.vec3(near) / near.w - view.eye)


def underside_weight(cos_water: float) -> float:
    """The underside's reflectance for a ray meeting it at ``cos_water`` (to the normal, in
    the water): 1 past the critical angle, else Schlick's at the angle in the air."""
    sin_air = INDEX * math.sqrt(max(0.0, 1.0 - cos_water * cos_water))
    if sin_air >= 1.0:
        return 1.0
    return schlick(F0, math.sqrt(1.0 - sin_air * sin_air))


def test_from_below_all_is_reflected_past_the_critical_angle_and_the_sky_shows_inside_snells_window(scene):
    """Half a metre under a clear pond over a floor a metre down, looking up at a slant: a
    pixel whose ray meets the surface past the critical angle (48.6 degrees for 1.333) shows
    the floor's mirror image, all of it; one inside Snell's window shows the uniform sky
    through the surface, F x floor + (1 - F) x sky by Schlick's formula at the angle in the
    air."""
    runner, seen = render(scene, under((0.0, -0.5, 0.0), (0.0, 1.5, -2.0)), size=(64, 96))
    assert runner.stats.views_spent == 1  # its reflection, seen from below (its mesh drawn with both faces)
    column = runner.size[0] // 2
    inside = outside = 0
    for row in range(runner.size[1]):
        _, direction = pixel_ray(runner, column, row)
        if direction.y < 0.02:
            continue  # on the floor, or along the surface
        angle = math.acos(direction.y)
        if abs(angle - CRITICAL) < math.radians(2.5):
            continue  # the rim: the weight leaps there, within a pixel
        weight = underside_weight(direction.y)
        expected = weight * FLOOR_SEEN + (1.0 - weight) * SKY
        assert abs(seen[row, column, 0] - expected) < 0.015, (row, math.degrees(angle), seen[row, column, 0], expected)
        if angle > CRITICAL:
            outside += 1
        else:
            inside += 1
    assert inside > 10 and outside > 10, (inside, outside)


def refracted_hit(eye: glm.vec3, direction: glm.vec3, height: float) -> glm.vec3 | None:
    """Where a ray from ``eye`` under the water (y < 0) along ``direction`` meets the plane y
    = ``height`` above it, bent at y = 0 by Snell's law (None: reflected whole)."""
    at = eye + direction * (-eye.y / direction.y)
    sin_water = math.sqrt(max(0.0, 1.0 - direction.y * direction.y))
    sin_air = INDEX * sin_water
    if sin_air >= 1.0:
        return None
    level = glm.normalize(glm.vec3(direction.x, 0.0, direction.z)) if sin_water > 1e-9 else glm.vec3(0.0)
    bent = level * sin_air + glm.vec3(0.0, math.sqrt(1.0 - sin_air * sin_air), 0.0)
    return at + bent * (height / bent.y)


def test_a_panel_above_the_water_is_seen_through_snells_window_where_refraction_puts_it(scene):
    """A red panel two metres above the pond, facing down: from under the water it is seen
    where the pixels' rays, bent at the surface, meet it (nearer the middle of the window
    than the straight line to it), and the straight line to it lies past the critical
    angle, where the surface shows the floor's reflection, not the panel."""
    eye = glm.vec3(0.0, -0.5, 0.0)
    centre = glm.vec3(0.0, 2.0, -4.0)
    red = np.array([0.9, 0.05, 0.05])

    def build(world):
        pool(world, True, eye, (0.0, 1.5, -1.5))
        world.spawn(Transform(position=centre, rotation=FACING_DOWN), MeshRef(quad(2.0, 2.0)),
                    Material(color=(*red, 1.0), roughness=1.0), Emissive(1.0))

    runner, seen = render(scene, build, size=(64, 96))
    column = runner.size[0] // 2
    traced = []
    for row in range(runner.size[1]):
        origin, direction = pixel_ray(runner, column, row)
        if direction.y <= 0.02:
            continue
        hit = refracted_hit(origin, direction, centre.y)
        if hit is not None and abs(hit.x - centre.x) < 1.0 and abs(hit.z - centre.z) < 1.0:
            traced.append(row)
    assert len(traced) >= 6, traced
    red_rows = [row for row in range(runner.size[1]) if seen[row, column, 0] > 0.5 and seen[row, column, 1] < 0.2]
    # Every row the bent rays say shows the panel does (a row at each end may be split).
    assert set(traced[1:-1]) <= set(red_rows), (traced, red_rows)
    assert len(red_rows) <= len(traced) + 2, (traced, red_rows)
    # The straight line to the panel's middle: past the critical angle, the floor's reflection.
    straight = glm.normalize(centre - eye)
    assert math.acos(straight.y) > CRITICAL + math.radians(3.0)
    col, row = runner.project(centre)
    assert 0 <= row < runner.size[1] and row not in red_rows
    assert abs(seen[row, col, 0] - FLOOR_SEEN) < 0.015, seen[row, col]


def test_the_main_tree_sees_a_water_by_the_side_its_camera_is_on_and_the_frame_above_is_unchanged(scene):
    """The published state of a water is its top whatever the camera does; the planner's table
    holds its top and its underside (plane facing down, the underside's look), and the main
    view under the water gets the underside's view alone.  Come up again, the frame is the
    frame of an engine that never went under, bit for bit."""
    from engine.render.surface_table import PlannerSurfaces

    above_eye, above_target = (0.0, 0.4, 0.0), (0.0, 0.05, -10.0)
    runner, _ = render(scene, under((0.0, -0.5, 0.0), (0.0, 1.5, -2.0)))
    surfaces = runner.world.resources[Surfaces]
    (entity,) = surfaces.undersides
    assert not surfaces.mirrors[entity].water.underside and surfaces.mirrors[entity].plane.y > 0.0
    table = runner.world.resources[PlannerSurfaces].table
    assert table.states == [surfaces.mirrors[entity], surfaces.undersides[entity]]
    assert list(table.exit_rows) == [0, 1]   # (each side's views look out of that side)
    (view,) = runner.engine.reflection_system.views[1:]
    assert view.surface.water.underside and view.surface.plane.y < 0.0
    ((_, transform),) = [(e, runner.world.get(e, Transform)) for e, _ in runner.world.query_one(Camera)]
    eye = glm.vec3(above_eye)
    transform.position = eye
    transform.rotation = look_rotation(glm.vec3(above_target) - eye)
    for _ in range(2):
        dived = runner.frame()
    never = scene(under(above_eye, above_target), runner.size)
    for _ in range(4):
        fresh = never.frame()
    assert np.array_equal(dived, fresh)


def test_a_probe_sees_the_water_by_the_side_it_is_on_wherever_the_camera_is(scene):
    """A probe over the pond captures the same faces with the camera above the water as under
    it (the probe's tree sees the water's top, not the side the camera is on), and a probe
    under the water captures its underside: its upward face shows Snell's window (the sky
    straight up), its sideways faces the floor's mirror image past the critical angle."""
    def build(camera_y: float, probe_y: float):
        def b(world):
            pool(world, True, (0.0, camera_y, 3.0), (0.0, camera_y, 0.0))
            world.spawn(Transform(position=(0.0, probe_y, 0.0)),
                        ReflectionProbe(resolution=16, refresh="on_change", depth=1))
        return b

    def faces(runner) -> list[np.ndarray]:
        (probe,) = [e for e, _ in runner.world.query_one(ReflectionProbe)]
        return [runner.engine.renderer.probes.read_face(probe, face) for face in range(6)]

    above, _ = render(scene, build(1.0, 1.5), frames=3)
    below, _ = render(scene, build(-0.5, 1.5), frames=3)
    for face_above, face_below in zip(faces(above), faces(below), strict=True):
        np.testing.assert_array_equal(face_above, face_below)
    under_probe, _ = render(scene, build(1.0, -0.5), frames=3)
    up, side = faces(under_probe)[2], faces(under_probe)[0]  # +Y, +X
    assert abs(float(up[8, 8, 0]) - SKY) < 0.05, up[8, 8]           # straight up: the sky through the window
    assert abs(float(side[2, 8, 0]) - FLOOR_SEEN) < 0.03, side[2, 8]  # up and sideways: the floor, mirrored whole


def test_a_water_given_to_a_mirror_later_is_seen_from_below_and_taken_off_is_not(scene):
    """A plain mirror has no back: from under it, no view.  Given a Water it is drawn with
    both faces and its underside's view is made; with the Water taken off, none again."""
    def build(world):
        pool(world, True, (0.0, -0.5, 0.0), (0.0, 1.5, -2.0))
        (entity,) = [e for e, _ in world.query_one(Water)]
        world.remove_component(entity, Water)

    runner, _ = render(scene, build)
    assert runner.stats.views_spent == 0
    (entity,) = [e for e, _ in runner.world.query_one(Mirror)]
    runner.world.add_component(entity, Water())
    runner.frame()
    assert runner.stats.views_spent == 1
    runner.world.remove_component(entity, Water)
    runner.frame()
    assert runner.stats.views_spent == 0


def test_a_ball_over_the_pond_is_seen_once_through_the_window_inside_where_the_bent_rays_meet_it(scene):
    """A red ball two metres over the pond, seen from a metre under it: its pixels lie where
    the pixels' rays, bent at the surface, meet it (the ray-traced image, a pixel's slack at
    its edge), and cover most of that; none lies where the straight line meets it only (its
    unbent image, lower in the picture: a ghost there would be red outside the traced image).
    Where the pixel itself shows the sky, the ball is found by marching out along the bent ray
    (water_march in mirror_composite.frag)."""
    centre, radius = np.array([0.8, 2.0, 0.5]), 0.5

    def build(world):
        pool(world, True, (0.0, -1.0, 3.0), (0.0, 1.5, -0.7))
        world.spawn(Transform(position=tuple(centre)), MeshRef(sphere(radius)),
                    Material(color=(0.9, 0.05, 0.05, 1.0), roughness=1.0), Emissive(1.0))

    runner, seen = render(scene, build, size=(96, 64))
    w, h = runner.size
    traced = np.zeros((h, w), bool)
    straight = np.zeros((h, w), bool)
    for row in range(h):
        for column in range(w):
            eye, direction = pixel_ray(runner, column, row)
            if direction.y <= 0.0:
                continue
            o, d = np.array(eye), np.array(direction)
            straight[row, column] = sphere_hit(o, d, centre, radius)
            at = o + d * (-o[1] / d[1])
            sin_air = INDEX * math.sqrt(max(0.0, 1.0 - d[1] * d[1]))
            if sin_air >= 1.0:
                continue
            level = np.array([d[0], 0.0, d[2]]) / math.hypot(d[0], d[2])
            traced[row, column] = sphere_hit(at, level * sin_air + np.array([0.0, math.sqrt(1.0 - sin_air ** 2), 0.0]),
                                             centre, radius)
    red = (seen[..., 0] > 0.4) & (seen[..., 1] < 0.2)
    slack = traced.copy()
    for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        slack |= np.roll(traced, (dy, dx), axis=(0, 1))
    assert traced.sum() > 20 and (straight & ~slack).sum() > 20  # the two images lie apart
    assert not (red & ~slack).any(), np.argwhere(red & ~slack)[:5]
    # (the march out along the bent ray: 114 of 124 here; starting from the direction's far point
    # alone, 88)
    assert red.sum() > 0.85 * traced.sum(), (red.sum(), traced.sum())


def sphere_hit(origin: np.ndarray, direction: np.ndarray, centre: np.ndarray, radius: float) -> bool:
    """Whether the ray from ``origin`` along the unit ``direction`` meets the sphere."""
    to_origin = origin - centre
    b = to_origin @ direction
    disc = b * b - (to_origin @ to_origin - radius * radius)
    return disc > 0.0 and -b + math.sqrt(disc) > 0.0


def test_a_still_camera_under_the_water_keeps_its_views_and_they_are_the_drawn_ones(scene):
    """A still camera under a still pond (no waves, nothing moving): the reflect stage keeps
    the underside's view once it settles, and every frame, kept or drawn, is bit for bit an
    engine's that draws its whole tree each frame; the frames after the camera comes up too."""
    def build(world):
        pool(world, True, (0.0, -0.5, 0.0), (0.0, 1.5, -2.0))
        for _, water in world.query_one(Water):
            water.speed = 0.0
        world.spawn(Transform(position=(0.8, 1.5, -1.5)), MeshRef(sphere(0.4)),
                    Material(color=(0.9, 0.05, 0.05, 1.0), roughness=1.0), Emissive(1.0))

    keeping, drawing = scene(build, (64, 48)), scene(build, (64, 48))
    assert kept_frames_equal_drawn(keeping, drawing, frames=6) > 0
    for runner in (keeping, drawing):
        ((_, transform),) = [(e, runner.world.get(e, Transform)) for e, _ in runner.world.query_one(Camera)]
        transform.position = glm.vec3(0.0, 0.5, 0.0)
    kept_frames_equal_drawn(keeping, drawing, frames=4)


def test_a_view_through_a_portal_into_the_water_sees_its_underside_as_a_camera_there_does(scene):
    """A portal in the air whose partner stands under the pond, turned to look up at the
    surface at a slant: the view through it (a level of a tree whose root is above the water)
    sees the water by the side its own eye is on, its underside: the floor's mirror image past
    the critical angle, the sky through Snell's window.  Its picture is the picture of a camera
    standing where the portal carries the eye, under the water, to within a few 8-bit steps
    (the portal's view is a level deeper, and drawn through its clip plane)."""
    from engine.assets.portals import spawn_portal_pair

    up_slant = glm.angleAxis(-math.radians(50.0), glm.vec3(1.0, 0.0, 0.0))   # +Z tipped up 50 degrees
    entrance, exit_at = glm.vec3(30.0, 1.5, 0.0), glm.vec3(0.0, -0.55, 0.0)
    eye = entrance + glm.vec3(0.0, 0.0, 0.6)

    def through(world):
        pool(world, True, eye, entrance)
        spawn_portal_pair(world, entrance, None, exit_at, up_slant, size=(1.6, 1.6))

    runner, seen = render(scene, through, size=(48, 48), frames=3)
    surfaces = runner.world.resources[Surfaces]
    (a,) = [e for e, state in surfaces.portals.items() if glm.length(glm.vec3(state.corners[:, :3].mean(axis=0))
                                                                     - entrance) < 1e-3]
    carried = surfaces.portals[a].carry * runner.world.get(
        next(e for e, _ in runner.world.query_one(Camera)), Transform).world
    there, turned = glm.vec3(carried[3]), glm.quat_cast(glm.mat3(carried))
    assert there.y < -0.6   # (the eye carried under the water, below the portal)

    def direct(world):
        pool(world, True, (0.0, 0.0, 0.0), (0.0, 0.0, -1.0))
        camera = next(e for e, _ in world.query_one(Camera))
        world.get(camera, Transform).position = there
        world.get(camera, Transform).rotation = turned

    _, expected = render(scene, direct, size=(48, 48), frames=3)
    tir = np.abs(expected[..., 0] - FLOOR_SEEN) < 0.02    # the floor's mirror image, all of it (past the critical)
    window = np.abs(expected[..., 0] - SKY) < 0.1         # the sky through Snell's window
    assert tir.sum() > 100 and window.sum() > 50, (tir.sum(), window.sum())
    assert np.median(np.abs(seen - expected)) < 0.01
    assert np.abs(seen[tir] - expected[tir]).max() < 0.03


@pytest.mark.parametrize("side", ["underside", "top"])
def test_a_lamp_is_reflected_by_the_waters_side_it_shines_on_by_fresnels_weight(scene, side):
    """A lamp 0.3 m from a pond that reflects light (``Mirror.reflects_light``), on one side
    of it, the camera on that side: what the water's image of the lamp adds to the plane it
    lights (a floor 1 m under the pond, or a ceiling 1 m over it; the frame less the one whose
    water reflects no light) is, pixel by pixel, the light of the same lamp standing at the
    image times the water's reflect rate times Fresnel's reflectance where the line from the
    pixel's point to the image crosses the surface: Schlick's at that angle from above; from
    below, all of it past the critical angle (a bright ring round a dim disc under the lamp,
    Snell's window for its light) and Schlick's at the angle in the air inside it.  The sky
    is black, the plane lit by the lamps alone."""
    from components import PointLight
    from tests.support import pixel_rays

    rate = 0.6
    up = 1.0 if side == "top" else -1.0      # the side the lamp, the camera and the lit plane are on
    lamp_at, image_at = (0.0, 0.3 * up, 0.0), (0.0, -0.3 * up, 0.0)
    plane_y = 1.0 * up
    power = 10.0 if side == "top" else 4.0   # (from above, the water reflects a few percent but at grazing)
    # Spots aimed at the water, so the plane behind the lamp gets only its image's light (no
    # clipped pixels); the image's cone is the lamp's mirrored, aimed back at the plane.
    towards_water, towards_plane = (FLAT, FACING_DOWN) if side == "top" else (FACING_DOWN, FLAT)

    def build(reflects: bool, image_lamp: bool):
        def b(world):
            eye = glm.vec3(0.0, 0.15 * up, 2.5)
            world.spawn(Transform(position=eye, rotation=look_rotation(glm.vec3(0.0, plane_y, 0.0) - eye)),
                        Camera(fov_y=70.0))
            world.spawn(uniform_sky(0.0))
            world.spawn(Transform(position=(0.0, plane_y, 0.0), rotation=FLAT if side == "underside" else FACING_DOWN),
                        MeshRef(quad(40.0, 40.0)),
                        Material(color=(0.7, 0.7, 0.7, 1.0), roughness=1.0, environment_reflection=0.0))
            world.spawn(Transform(rotation=FLAT), MeshRef(quad(40.0, 40.0)), Material(color=(1.0, 1.0, 1.0, 0.0)),
                        Mirror(reflect_rate=rate, reflects_light=reflects), Water(ior=INDEX))
            world.spawn(Transform(position=lamp_at, rotation=towards_water),
                        PointLight(intensity=power, range=6.0, spot_angle=88.0, spot_blend=0.0))
            if image_lamp:
                world.spawn(Transform(position=image_at, rotation=towards_plane),
                            PointLight(intensity=power * rate, range=6.0, spot_angle=88.0, spot_blend=0.0))
        return b

    runner, reflected = render(scene, build(True, False), size=(64, 48), frames=3)
    _, alone = render(scene, build(False, False), size=(64, 48), frames=3)
    _, beside = render(scene, build(False, True), size=(64, 48), frames=3)
    assert runner.stats.virtual_lights == 1
    eye, directions = pixel_rays(runner.engine.main_view, runner.size)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (plane_y - eye[1]) / directions[..., 1]
    points = eye + directions * t[..., None]
    # The plane, within 4 m of the lamp's axis.  (The image's shadow camera is opened to its
    # widest here, 0.3 m from a 40 m pond; with its normal offset sized by the whole pond, as
    # it was, a line of shadow crossed the plane 3.3 m out: shadow_rules.virtual_shadow_camera.)
    lit = (t > 0.0) & (np.hypot(points[..., 0], points[..., 2]) < 4.0)
    to_image = np.asarray(image_at) - points
    cosine = np.abs(to_image[..., 1]) / np.linalg.norm(to_image, axis=-1)   # the line's angle at the surface
    if side == "top":
        weight = schlick(F0, cosine)
    else:
        weight = np.vectorize(underside_weight)(cosine)
    rim = np.abs(np.arccos(np.clip(cosine, 0.0, 1.0)) - CRITICAL) < math.radians(2.0)  # the weight leaps there
    added = (reflected - alone)[lit & ~rim]
    expected = (beside - alone)[lit & ~rim] * weight[lit & ~rim][:, None]
    assert lit.sum() > 500 and expected.max() > 0.008, (lit.sum(), expected.max())
    if side == "underside":
        assert (weight[lit] == 1.0).sum() > 200 and (weight[lit] < 0.2).sum() > 100   # both the ring and the disc
    # (0.0005 at most on llvmpipe; Fresnel's F0 everywhere instead is 0.003 off from above)
    assert np.abs(added - expected).max() < 0.0015, np.abs(added - expected).max()


def test_a_water_earlier_on_a_lamps_way_weighs_its_light_by_the_angle_the_light_met_it(scene):
    """A lamp's light off a pond and then a mirror wall (``PointLight.bounces`` 2), onto a wall
    across the room: what the second bounce adds to that wall (the frame with two bounces less
    the frame with one) is the light of the same lamp standing at the image of the image
    times Fresnel's reflectance at the angle the line from the wall's point to that image
    crosses the pond's plane as the mirror carries it: the water's weight is taken at the
    surface it is, not only at the last one."""
    from components import PointLight
    from tests.support import pixel_rays

    power, rate = 150.0, 0.8
    lamp_at, image_at = (0.0, 0.3, 0.0), np.array([6.0, -0.3, 0.0])   # reflected in y = 0, then in x = 3
    east, west = glm.angleAxis(math.pi / 2, glm.vec3(0, 1, 0)), glm.angleAxis(-math.pi / 2, glm.vec3(0, 1, 0))

    def build(bounces: int, image_lamp: bool):
        def b(world):
            eye = glm.vec3(0.5, 2.0, 0.0)
            world.spawn(Transform(position=eye, rotation=look_rotation(glm.vec3(-3.0, 2.0, 0.0) - eye)),
                        Camera(fov_y=70.0))
            world.spawn(uniform_sky(0.0))
            world.spawn(Transform(position=(-3.0, 2.0, 0.0), rotation=east), MeshRef(quad(8.0, 4.0)),
                        Material(color=(0.7, 0.7, 0.7, 1.0), roughness=1.0, environment_reflection=0.0))
            world.spawn(Transform(position=(3.0, 2.0, 0.0), rotation=west), MeshRef(quad(8.0, 4.0)), Material(),
                        Mirror(reflect_rate=rate, reflects_light=True))
            world.spawn(Transform(rotation=FLAT), MeshRef(quad(4.0, 4.0)), Material(color=(1.0, 1.0, 1.0, 0.0)),
                        Mirror(reflects_light=True), Water(ior=INDEX))
            world.spawn(Transform(position=lamp_at, rotation=FLAT),
                        PointLight(intensity=power, range=16.0, spot_angle=88.0, spot_blend=0.0, bounces=bounces))
            if image_lamp:
                world.spawn(Transform(position=tuple(image_at), rotation=FACING_DOWN),
                            PointLight(intensity=power * rate, range=16.0, spot_angle=88.0, spot_blend=0.0))
        return b

    runner, two = render(scene, build(2, False), size=(64, 48), frames=3)
    _, one = render(scene, build(1, False), size=(64, 48), frames=3)
    _, beside = render(scene, build(1, True), size=(64, 48), frames=3)
    assert runner.stats.virtual_lights > 2
    eye, directions = pixel_rays(runner.engine.main_view, runner.size)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (-3.0 - eye[0]) / directions[..., 0]
    points = eye + directions * t[..., None]
    line = image_at - points
    # Where the line to the image crosses the mirror (x = 3) and the pond's plane as the mirror
    # carries it (y = 0, x in [4, 8], z in [-2, 2]), in that order.
    s_mirror = (3.0 - points[..., 0]) / line[..., 0]
    s_pond = -points[..., 1] / line[..., 1]
    at_mirror, at_pond = points + line * s_mirror[..., None], points + line * s_pond[..., None]
    through = ((t > 0) & (np.abs(points[..., 2]) < 3.5) & (points[..., 1] > 0.5) & (points[..., 1] < 3.9)
               & (s_mirror < s_pond) & (np.abs(at_mirror[..., 2]) < 4.0) & (at_mirror[..., 1] > 0.0)
               & (at_pond[..., 0] > 4.0) & (at_pond[..., 0] < 8.0) & (np.abs(at_pond[..., 2]) < 2.0))
    edge = (np.abs(at_pond[..., 0] - 4.0) < 0.15) | (np.abs(np.abs(at_pond[..., 2]) - 2.0) < 0.15)
    kept = through & ~edge
    cosine = np.abs(line[..., 1]) / np.linalg.norm(line, axis=-1)
    weight = schlick(F0, cosine)
    added = (two - one)[kept]
    expected = (beside - one)[kept] * weight[kept][:, None]
    assert kept.sum() > 200 and expected.max() > 0.01, (kept.sum(), expected.max())
    # (0.0036 at most on llvmpipe, an 8-bit step at 0.1; with no weight there, 0.18)
    assert np.abs(added - expected).max() < 0.006, np.abs(added - expected).max()


@pytest.mark.parametrize("visibility", ["exact", "predicted"])
@pytest.mark.parametrize("side", ["above", "below"])
def test_a_waters_view_plans_no_view_of_its_other_side(scene, visibility, side):
    """A view looking out of one side of a water cannot see the other: it lies on the view's
    clip plane, where the water is not drawn.  So a lone pond's tree is one view a frame, by
    either side and either visibility (predicted visibility once drew a second, of the other
    side, every frame: empty, its whole scene pass and its fallback's refraction copy paid
    for nothing), and no candidate below it is claimed.  The frame is the same either way."""
    eye, target = ((0.0, 0.6, 0.0), (0.0, -0.3, -3.0)) if side == "above" else ((0.0, -0.5, 0.0), (0.0, 1.5, -2.0))
    frames = []
    for mode in ("exact", visibility):
        runner = scene(under(eye, target), (48, 36))
        system = runner.engine.reflection_system
        system.visibility = mode
        levels: list[int] = []
        system.tree._choose = _counting(system.tree._choose, levels)
        for _ in range(4):
            levels.clear()
            rgb = runner.frame()
            stats = runner.engine.renderer.stats
            assert stats.reflection_views == 1 and stats.reflection_views_unseen == 0, (mode, stats)
            (view,) = system.views[1:]
            assert view.surface.water.underside == (side == "below")
            assert levels == [1], (mode, levels)   # no level below the water's view
        frames.append(rgb)
    np.testing.assert_array_equal(frames[0], frames[1])


def _counting(choose, levels: list[int]):
    """A spy on ``ViewTree._choose``: each level the tree chooses views from, by its candidates."""
    def counted(walk, stack, candidates):
        levels.append(len(candidates))
        return choose(walk, stack, candidates)
    return counted


# A sky each part of which says where it was read: straight up, straight down, and the sides'
# upper and lower halves (rows 0-3 of a side face look above the horizon: cube_faces.py).
_SKY_UP, _SKY_DOWN = (0.9, 0.8, 0.2), (0.05, 0.4, 0.05)
_SKY_SIDE_UPPER, _SKY_SIDE_LOWER = (0.1, 0.1, 0.6), (0.6, 0.2, 0.05)


def _told_sky():
    from components import Skybox

    side = np.empty((8, 8, 3), np.float32)
    side[:4], side[4:] = _SKY_SIDE_UPPER, _SKY_SIDE_LOWER
    up, down = np.full((8, 8, 3), _SKY_UP, np.float32), np.full((8, 8, 3), _SKY_DOWN, np.float32)
    return Skybox(faces=[side, side.copy(), up, down, side.copy(), side.copy()])


def _told_sky_along(directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``_told_sky``'s radiance along unit ``directions`` (..., 3), and whether each is clear of
    a face's edge and the sides' horizon (where the cube's filter blends two colours)."""
    a = np.abs(directions)
    major = a.max(axis=-1)
    second = np.sort(a, axis=-1)[..., 1]
    y = directions[..., 1]
    up_or_down = a[..., 1] >= major
    colour = np.where((y > 0.0)[..., None], _SKY_SIDE_UPPER, _SKY_SIDE_LOWER)
    colour = np.where((up_or_down & (y > 0.0))[..., None], _SKY_UP, colour)
    colour = np.where((up_or_down & (y < 0.0))[..., None], _SKY_DOWN, colour)
    clear = (second < 0.72 * major) & (up_or_down | (np.abs(y) > 0.28 * major))  # (8 texels a side, filtered)
    return colour, clear


_NO_VIEW = {"switched off": "enabled", "past the view budget": "views", "under min_pixels": "min_pixels"}


@pytest.mark.parametrize("shown_by", _NO_VIEW)
def test_a_water_seen_from_below_with_no_view_shows_the_undersides_fallback(scene, shown_by):
    """Half a metre under a clear pond whose underside gets no view (its mirror switched off,
    the view budget spent, or its view under ``min_pixels``): its fallback is the underside's,
    not the top's.  Under a sky whose up, down and the sides' upper and lower halves differ,
    each pixel is, by the optics worked out here in numpy, w x the sky along the ray reflected
    down off the surface + (1 - w) x the sky along the ray bent up through Snell's window, w
    the underside's reflectance: 1 past the critical angle (so there the sides' lower half,
    below the horizon, shows), Schlick's at the angle in the air inside it.  The top's
    fallback (Fresnel from above, nothing bent from below) shows the sky above there."""
    from engine.resources import ViewBudget
    from tests.support import pixel_rays

    def build(world):
        pool(world, True, (0.0, -0.5, 0.0), (0.0, 1.5, -2.0))
        for entity, _ in list(world.query_one(Skybox)):
            world.remove_component(entity, Skybox)
            world.add_component(entity, _told_sky())
        if shown_by == "switched off":
            for _, mirror in world.query_one(Mirror):
                mirror.enabled = False
        else:
            world.resources[ViewBudget] = ViewBudget(views=0) if shown_by == "past the view budget" else \
                ViewBudget(min_pixels=10 ** 6)

    runner, seen = render(scene, build, size=(48, 72))
    stats = runner.stats
    assert (stats.reflection_fallbacks, stats.reflection_views) == (1, 0), stats
    assert runner.engine.reflection_system.views[1:] == []
    view = runner.engine.main_view
    _, d = pixel_rays(view, runner.size)
    up = d[..., 1]
    cos_air_2 = 1.0 - INDEX * INDEX * (1.0 - up * up)
    inside = cos_air_2 > 0.0
    cos_air = np.sqrt(np.clip(cos_air_2, 0.0, 1.0))
    weight = np.where(inside, F0 + (1.0 - F0) * (1.0 - cos_air) ** 5, 1.0)
    reflected = d * np.array([1.0, -1.0, 1.0])
    level = d * np.array([1.0, 0.0, 1.0])
    level /= np.maximum(np.linalg.norm(level, axis=-1, keepdims=True), 1e-9)
    bent = level * np.sqrt(np.clip(1.0 - cos_air_2, 0.0, 1.0))[..., None] + np.array([0.0, 1.0, 0.0]) * \
        cos_air[..., None]
    sky_reflected, clear_reflected = _told_sky_along(reflected)
    sky_bent, clear_bent = _told_sky_along(bent)
    expected = weight[..., None] * sky_reflected + (1.0 - weight[..., None]) * sky_bent
    # Where the bent ray's sky lies in the picture (the fallback reads it there), clear of the
    # band along the edges over which it fades to the unbent pixel (water_edge_share).
    far = np.concatenate([bent * 1e4 + np.array(view.eye), np.ones(bent.shape[:-1] + (1,))], axis=-1)
    clip = far @ np.array(view.view_proj.to_list(), np.float64)
    ndc = clip[..., :2] / clip[..., 3:]
    landed = (clip[..., 3] > 0.0) & (np.abs(ndc) < 0.8).all(axis=-1)
    rim = np.abs(np.arccos(np.clip(up, -1.0, 1.0)) - CRITICAL) < math.radians(2.5)
    measured = (up > 0.05) & ~rim & clear_reflected & (~inside | (clear_bent & landed))
    tir = measured & ~inside
    window = measured & inside
    assert tir.sum() > 300 and window.sum() > 100, (tir.sum(), window.sum())
    # Past the critical angle: the sky below the horizon (what the top's fallback never shows).
    assert np.abs(seen[tir] - _SKY_SIDE_LOWER).max() < 0.01
    error = np.abs(seen - expected).max(axis=-1)
    # (0.003 at most on llvmpipe)
    assert error[measured].max() < 0.01, (np.argwhere(measured & (error >= 0.01))[:5], error[measured].max())


def _diving(world):
    """``pool`` seen from 0.3 m over it, looking ahead, with a mirror standing under the water
    3 m off facing the camera (no end image: a frame that differs would echo on in it) and a
    red ball under the water between them, which the mirror shows."""
    pool(world, True, (0.0, 0.3, 2.0), (0.0, 0.1, -3.0))
    world.spawn(Transform(position=(0.0, -0.55, -3.0)), MeshRef(quad(3.0, 0.8)), Material(color=(0.1, 0.1, 0.1)),
                Mirror(end_image=False))
    world.spawn(Transform(position=(1.2, -0.5, -1.5)), MeshRef(sphere(0.15)),
                Material(color=(0.9, 0.05, 0.05, 1.0), roughness=1.0), Emissive(1.0))


@pytest.mark.parametrize("visibility", ["exact", "predicted"])
def test_the_frame_the_eye_goes_under_the_water_draws_its_underside_and_the_mirror_under_it(scene, visibility):
    """The camera dives through the pond (0.3 m over it for three frames, then 0.3 m under it,
    then up again): on the very frame its eye crosses the plane, the water's view is its
    underside's (going up, its top's), the mirror under the water, hidden from above behind
    the surface, has a view of its own that shows the red ball where the mirror's plane
    reflects it (worked out here), and the frame is the exact visibility's frame but for the
    mirror's own pixels (predicted visibility: the mirrors inside an uncovered one come a
    frame later, README).  A frame later they agree everywhere, and on the frame going up."""
    from engine.core.reflection_math import plane_from_point_normal, reflection_matrix

    runners = []
    for mode in ("exact", visibility):
        runner = scene(_diving, (96, 72))
        runner.engine.renderer.antialias = "off"
        runner.engine.reflection_system.visibility = mode
        runners.append(runner)
    camera = next(e for e, _ in runners[0].world.query_one(Camera))
    mirror = next(e for e, m in runners[0].world.query_one(Mirror) if runners[0].world.try_get(e, Water) is None)
    heights = (0.3, 0.3, 0.3, -0.3, -0.3, 0.3, 0.3)
    for n, height in enumerate(heights):
        frames, sides = [], []
        for runner in runners:
            runner.world.get(camera, Transform).position = glm.vec3(0.0, height, 2.0)
            frames.append(srgb_to_linear(runner.frame()))
            sides.append([view.surface.water.underside for view in runner.engine.reflection_system.views[1:]
                          if view.level == 1 and view.surface.water is not None])
        exact, seen = frames
        assert sides[0] == sides[1] == [height < 0.0], (n, sides)
        runner = runners[1]
        differs = np.abs(exact - seen).max(axis=-1) > 0.01
        if n == 3:  # the dive's frame
            near = np.zeros(runner.size[::-1], bool)
            in_mirror = runner.engine.renderer.targets.read_surface_ids() == mirror
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    near |= np.roll(in_mirror, (dy, dx), axis=(0, 1))
            assert in_mirror.sum() > 100 and not (differs & ~near).any(), np.argwhere(differs & ~near)[:5]
            assert any(view.surface.entity == mirror and view.level == 1
                       for view in runner.engine.reflection_system.views[1:])
            image = reflection_matrix(plane_from_point_normal((0.0, -0.55, -3.0), (0.0, 0.0, 1.0))) * \
                glm.vec4(1.2, -0.5, -1.5, 1.0)
            column, row = runner.project(glm.vec3(image))
            red, green = seen[row, column, 0], seen[row, column, 1]
            assert in_mirror[row, column] and red > 0.5 and red > 4.0 * green, seen[row, column]
        else:
            assert not differs.any(), (n, np.argwhere(differs)[:5])
