"""Tube lights (``PointLight.length``): a fluorescent tube, a neon bar.  The reference is the
tube's light integrated along it in float64, here and apart from the engine: each floor
pixel found by casting its ray, the tube cut into 2000 elements, each a thin Lambertian
cylinder's slice whose intensity towards the pixel's point is the light's intensity over the
length, times the slice's length and the sine of the way's angle from the axis (its outline's
width seen from there), over the distance squared, times the floor's BRDF towards the eye
(Lambert's and GGX with the shader's distribution, Smith visibility and Schlick's Fresnel).
The engine lights a tube as the rectangle through its axis turned to face the point
(``shaders/include/rect_lights.glsl``): its diffuse light exact, its highlight linearly
transformed cosines."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, Material, MeshRef, Mirror, PointLight, Skybox, Transform
from engine.assets.mesh import plane, quad
from engine.rules.light_rules import lamp_rectangle, light_size, sphere_radius
from tests.support import green_and_rays, look_from, split_sum
from tests.test_rect_lights import floor_ggx

SIZE = (96, 72)
RANGE = 40.0
ELEMENTS = 2000


def tube_frame(yaw: float, pitch: float = 0.0) -> tuple[glm.quat, np.ndarray]:
    """A tube's rotation turned ``yaw`` degrees about +y and ``pitch`` about its turned z, and
    its unit axis (the entity's +X), float64."""
    rotation = glm.angleAxis(glm.radians(yaw), glm.vec3(0.0, 1.0, 0.0)) * \
        glm.angleAxis(glm.radians(pitch), glm.vec3(0.0, 0.0, 1.0))
    return rotation, np.array(glm.mat3_cast(rotation)[0], np.float64)


def tube_light(points, view, centre, axis, length, roughness, f0, diffuse, slices=ELEMENTS) -> np.ndarray:
    """The light a unit-intensity tube (``centre``, unit ``axis``, ``length``) sends towards
    ``view`` from a floor (normal +y) at ``points``, cut into ``slices``."""
    centre = np.asarray(centre, np.float64)
    s = (np.arange(slices) + 0.5) / slices - 0.5
    elements = centre + s[:, None] * length * axis
    step = length / slices
    out = np.zeros(len(points))
    for start in range(0, len(points), 64):
        p, eye = points[start:start + 64], view[start:start + 64]
        d = elements[None] - p[:, None]
        dist = np.linalg.norm(d, axis=-1)
        l = d / dist[..., None]
        sine = np.linalg.norm(np.cross(l, axis), axis=-1)     # the slice's outline's width towards p
        nl = np.maximum(l[..., 1], 0.0)
        reach = sine * step / length / dist ** 2                # intensity over length x slice, inverse square
        specular = floor_ggx(l, eye, roughness, f0)
        out[start:start + 64] = ((diffuse / math.pi + specular) * nl * reach).sum(axis=1)
    fade = np.clip(1.0 - (np.linalg.norm(centre - points, axis=1) / RANGE) ** 4, 0.0, 1.0) ** 2
    return out * fade


def floor_frame(scene, roughness, metallic, centre, rotation, length, radius, intensity, eye=(0.0, 1.0, 3.0)):
    def build(world):
        look_from(world, eye, (0.0, 0.0, -1.0), fov=50.0)
        world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
        world.spawn(Transform(), MeshRef(plane(30.0, 30.0)),
                    Material(color=(1.0, 1.0, 1.0, 1.0), metallic=metallic, roughness=roughness,
                             environment_reflection=0.0))
        world.spawn(Transform(position=tuple(centre), rotation=rotation),
                    PointLight(intensity=intensity, range=RANGE, length=length, radius=radius))
    shown, eye, rays = green_and_rays(scene, build, SIZE)
    t = -eye[1] / rays[:, 1]
    on_floor = (t > 0) & (t < 12.0)
    return shown[on_floor], (eye + rays * t[:, None])[on_floor], -rays[on_floor]


# A tube across the view 1 m up, one along it 0.4 m up (seen end on from the camera's side:
# much of the floor sees it at a slant), and one leaning 45 degrees with its lower end 0.25 m
# off the floor.
TUBES = {"across": ((0.0, 1.0, -1.0), 0.0, 0.0, 1.6), "along": ((0.3, 0.4, -1.5), 90.0, 0.0, 1.2),
         "leaning": ((0.0, 0.8, -1.5), 20.0, 45.0, 1.5)}


@pytest.mark.parametrize("name", sorted(TUBES))
def test_a_tube_lights_a_rough_floor_as_its_slices_add_up(scene, name):
    """A rough dielectric floor (roughness 0.6) under a thin tube (1 cm across): each lit
    pixel against the tube's slices added in float64, within 2% in the median and 6% at the
    90th percentile (measured 1.0-1.5% and 2.3-5.1%: the diffuse light exact, within 1.6% at
    the 90th percentile on a floor of roughness 1; the highlight the LTC's, which along a thin
    line is 0.8-1.1 x the slices' in the median and up to 1.7 x at the 90th percentile at
    grazing views, where it is a tenth of the light)."""
    centre, yaw, pitch, length = TUBES[name]
    rotation, axis = tube_frame(yaw, pitch)
    shown, points, view = floor_frame(scene, 0.6, 0.0, centre, rotation, length, 0.005, 2.0)
    expected = 2.0 * tube_light(points, view, centre, axis, length, 0.6, 0.04, 1.0)
    lit = (expected > 0.02) & (expected < 0.9)
    assert lit.sum() > 1000
    error = np.abs(shown[lit] - expected[lit]) / expected[lit]
    assert np.median(error) < 0.02 and np.percentile(error, 90) < 0.06, \
        (np.median(error), np.percentile(error, 90))


@pytest.mark.parametrize("roughness", [0.2, 0.45])
def test_a_metal_floors_streak_is_the_tubes_light_its_lobe_gathers(scene, roughness):
    """A white metal floor's highlight of a tube across the view (the streak a glossy floor
    shows of a fluorescent tube): its sum within 8% and its median within 10% of the slices'
    (measured: 1.2% and 5.3% low, 7.3% and 4.5%; the engine's energy compensation taken out,
    as the rectangle lights' test does)."""
    centre, yaw, pitch, length = TUBES["across"]
    rotation, axis = tube_frame(yaw, pitch)
    shown, points, view = floor_frame(scene, roughness, 1.0, centre, rotation, length, 0.005, 1.0)
    expected = tube_light(points, view, centre, axis, length, roughness, 1.0, 0.0)
    expected /= split_sum(roughness, view[:, 1]).sum(axis=-1)
    lit = (expected > 0.02) & (expected < 0.95) & (shown < 0.99)
    assert lit.sum() > 200
    total = shown[lit].sum() / expected[lit].sum()
    error = np.abs(shown[lit] - expected[lit]) / expected[lit]
    assert abs(total - 1.0) < 0.08 and np.median(error) < 0.10, (total, np.median(error))


def test_a_tubes_image_in_a_mirror_lights_as_the_tube_there_would(scene):
    """A tube before a mirror that reflects light: the floor in front of the mirror is lit by
    the tube and its image as the tube alone and a real tube at the image's place light it
    (two more scenes, added), where the line to the image's centre passes through the glass;
    the VirtualLights block carries the tube's axis reflected and its radius."""
    from tests.test_rect_lights import through_the_mirror, virtual_rect_rows

    centre, mirror_z, length = (0.0, 1.2, 0.5), -2.0, 1.0
    rotation, axis = tube_frame(35.0, 20.0)
    image_centre = (centre[0], centre[1], 2 * mirror_z - centre[2])
    image_rotation, image_axis = tube_frame(-35.0, 20.0)
    assert np.allclose(image_axis * [1.0, 1.0, -1.0], axis) or np.allclose(-image_axis * [1.0, 1.0, -1.0], axis)

    def look(world):
        look_from(world, (0.0, 1.0, 3.0), (0.0, 0.0, -1.0), fov=50.0)
        world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
        world.spawn(Transform(), MeshRef(plane(30.0, 30.0)),
                    Material(color=(1.0, 1.0, 1.0, 1.0), roughness=0.6, environment_reflection=0.0))

    def tube(at, turned):
        return lambda world: world.spawn(Transform(position=at, rotation=turned),
                                         PointLight(intensity=3.0, range=RANGE, length=length, radius=0.01))

    def with_mirror(world):
        look(world)
        world.spawn(Transform(position=(0.0, 1.5, mirror_z)), MeshRef(quad(4.0, 3.0)), Material(),
                    Mirror(reflects_light=True))
        tube(centre, rotation)(world)

    def scene_of(*parts):
        def build(world):
            look(world)
            for part in parts:
                part(world)
        return build

    runner = scene(with_mirror, SIZE)
    rows = virtual_rect_rows(runner)
    np.testing.assert_allclose(rows[0][:3], axis * [1.0, 1.0, -1.0] * length / 2.0, atol=1e-5)
    assert rows[0][3] == pytest.approx(1.0 / (length * 0.02), rel=1e-5) and rows[1][3] == pytest.approx(0.01)
    shown, other = through_the_mirror(scene, runner, (scene_of(tube(image_centre, image_rotation)),
                                                      scene_of(tube(centre, rotation))), image_centre, mirror_z)
    np.testing.assert_allclose(shown, other, rtol=0.03, atol=2e-3)


def test_a_tubes_rows_size_and_builds(scene):
    """The rows a tube packs (its half length along the entity's X, one over its outline's
    area, its radius: at least half a millimetre), its soft shadows' size (a disc of its
    outline's area, no front: it shines all round) and six cube faces, the RECT_LIGHTS builds
    on and the sphere's off (a capsule's radius is the tube's)."""
    rotation, axis = tube_frame(30.0)
    world_matrix = glm.translate(glm.mat4(1.0), glm.vec3(1.0, 2.0, 3.0)) * glm.mat4_cast(rotation)
    u, v = lamp_rectangle(PointLight(length=1.5, radius=0.05), world_matrix)
    np.testing.assert_allclose(u[:3], axis * 0.75, atol=1e-6)
    assert u[3] == pytest.approx(1.0 / (1.5 * 0.1)) and v == (0.0, 0.0, 0.0, pytest.approx(0.05))
    assert lamp_rectangle(PointLight(length=1.0), world_matrix)[1][3] == pytest.approx(0.0005)
    assert light_size(PointLight(length=1.5, radius=0.05), world_matrix) == \
        (pytest.approx(math.sqrt(1.5 * 0.1 / math.pi)), 0.0, 0.0, 0.0)
    assert sphere_radius(PointLight(length=1.5, radius=0.05)) == 0.0 and sphere_radius(PointLight(radius=0.2)) == 0.2

    def build(world):
        look_from(world, (0.0, 1.0, 3.0), (0.0, 0.0, -1.0))
        world.spawn(Transform(), MeshRef(plane(10.0, 10.0)), Material())
        world.spawn(Transform(position=(0.0, 2.0, 0.0)),
                    PointLight(intensity=3.0, length=1.0, radius=0.05, shadows=True))
    runner = scene(build, (48, 36))
    runner.engine.renderer.shadows.filter = "grid"
    runner.frame()
    renderer = runner.engine.renderer
    assert renderer.rect_lights and not renderer.sphere_lights
    assert runner.stats.shadow_faces_drawn == 6


def test_length_is_checked():
    assert PointLight(length=1.2, radius=0.02).length == 1.2
    for bad in (0.0005, 51.0, -1.0, float("nan"), "1", None):
        with pytest.raises(ComponentValueError, match="PointLight.length"):
            PointLight(length=bad)
    with pytest.raises(ComponentValueError, match="a sphere, a tube or a rectangle"):
        PointLight(length=1.0, rectangle=(1.0, 1.0))
    light = PointLight(rectangle=(1.0, 1.0))
    with pytest.raises(ComponentValueError, match="a sphere, a tube or a rectangle"):
        light.length = 1.0
    assert light.length == 0.0
    tube = PointLight(length=1.0)
    with pytest.raises(ComponentValueError, match="this light is a tube"):
        tube.rectangle = (1.0, 1.0)


def test_a_level_file_keeps_a_tube(tmp_path):
    from tests.support import entity_level_round_trip

    again, neon = entity_level_round_trip(
        tmp_path, "[entity.Transform]\nposition = [0.0, 2.5, 0.0]\n[entity.PointLight]\nintensity = 8.0\n"
        "length = 1.2\nradius = 0.02\n", ("length = 1.2", "length = -1.2"), "length")
    light = again.get(neon, PointLight)
    assert (light.length, light.radius) == (1.2, 0.02)


def test_a_tubes_image_through_a_portal_lights_as_the_tube_there_would(scene):
    """A tube before portal A, which carries light: the floor before B, where the lines to both
    of the image's ends pass through B's opening, is lit by the tube's image (the tube carried
    by the pair's transform, its axis turned with it) as the tube cut into slices in float64
    at the image's place, plus the tube's own light from 9 m off: within 3% in the median, 8%
    at the 90th percentile (measured 0.9% and 1.7%)."""
    from tests.test_rect_lights import portal_image_frame, through_b

    centre, length, intensity = np.array([8.7, 1.6, 0.0]), 1.2, 2.0
    rotation, axis = tube_frame(60.0, 15.0)

    def lamp(world):
        world.spawn(Transform(position=tuple(centre), rotation=rotation),
                    PointLight(intensity=intensity, range=RANGE, length=length, radius=0.01))
    shown, points, view, carry = portal_image_frame(scene, lamp)
    turn = carry[:3, :3]
    image_centre, image_axis = turn @ centre + carry[:3, 3], turn @ axis
    np.testing.assert_allclose(image_centre, (0.0, 1.6, -1.3), atol=1e-5)   # (behind B)
    ends = image_centre + np.outer([-0.5, 0.5], image_axis * length)
    through = through_b(points, ends)
    points, view = points[through], view[through]
    reference = intensity * (tube_light(points, view, image_centre, image_axis, length, 0.8, 0.04, 1.0)
                             + tube_light(points, view, centre, axis, length, 0.8, 0.04, 1.0, 60))
    lit = (reference > 0.02) & (reference < 0.95)
    assert lit.sum() > 800, lit.sum()
    error = np.abs(shown[through][lit] / reference[lit] - 1.0)
    assert np.median(error) < 0.03 and np.percentile(error, 90) < 0.08, (np.median(error), np.percentile(error, 90))


@pytest.mark.parametrize("pitch", [0.0, 90.0, 50.0])
def test_seen_from_far_off_a_tube_lights_as_a_point_light_broadside_and_not_at_all_end_on(scene, pitch):
    """A tube 1 m long 8 m over the floor, level (every floor point sees it broadside, or
    nearly), upright (the floor under it sees it end on) or leaning 50 degrees: each floor
    pixel is the same lamp as a point's light times the sine of the way's angle from the
    tube's axis (its outline's width from there; the point's inverse square kept finite at
    the light, 1 / (d^2 + 1), the tube's the true one), within 2% in the median and 4% at the
    90th percentile; within 15 cm of the foot of the upright tube's axis (the sine under
    0.019), under 3% of the point's light, where the point's is brightest."""
    from tests.test_rect_lights import far_floor

    point, points = far_floor(scene, {})
    rotation, axis = tube_frame(20.0, pitch)
    tube, _ = far_floor(scene, {"length": 1.0, "radius": 0.01}, rotation)
    to_floor = points - np.array([0.0, 8.0, 0.0])
    d2 = (to_floor ** 2).sum(axis=1)
    sine = np.linalg.norm(np.cross(to_floor / np.sqrt(d2)[:, None], axis), axis=1)
    expected = point * sine * (d2 + 1.0) / d2
    lit = expected > 0.03
    assert lit.sum() > 500
    error = np.abs(tube[lit] / expected[lit] - 1.0)
    assert np.median(error) < 0.02 and np.percentile(error, 90) < 0.04, (np.median(error), np.percentile(error, 90))
    if pitch == 90.0:
        under = np.linalg.norm(points[:, [0, 2]], axis=1) < 0.15
        assert under.sum() > 3 and tube[under].max() < 0.03 * point[under].min(), (tube[under], point[under])
