"""A water's body (Water.fog_density, fog_color, depth, absorption): the light's way through
the water below the surface, down to ``depth`` under its outline, fogged at one density.
Measured in rendered frames against the same frame without it: what is seen keeps, in each
channel, exp(-density x the channel's absorption x the length of its way in the box) of its
light, the rest becomes the fog's colour; each test is run with grey water (absorption 1 in
every channel) and with water that takes red fastest and blue slowest (``TINTED``)."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from pyglm import glm

from components import (
    ComponentValueError,
    ComponentWarning,
    DirectionalLight,
    Emissive,
    FogVolume,
    Material,
    MeshRef,
    Mirror,
    PointLight,
    Portal,
    Skybox,
    Transform,
    Water,
    look_rotation,
)
from engine.assets.mesh import box, plane, quad
from engine.core.errors import FogLimitWarning
from tests.support import srgb_to_linear
from tests.test_water import FLAT, SKY, pool, render

FOG = (0.1, 0.3, 0.35)
DENSITY = 0.4
GREY, TINTED = (1.0, 1.0, 1.0), (2.5, 1.0, 0.3)
ABSORPTIONS = pytest.mark.parametrize("absorption", [GREY, TINTED], ids=["grey", "tinted"])


def murky(world, eye, target, density: float, *, depth: float = 10.0, reflect_rate: float = 1.0,
          absorption: tuple[float, float, float] = GREY) -> int:
    """``pool``'s pond (its floor a metre down), its water fogged by ``density`` (each channel
    by its share, ``absorption``), with a white wall standing in the water four metres off
    along -Z and a red block on the bank beside the pond; the water's entity."""
    pool(world, True, eye, target, reflect_rate=reflect_rate)
    world.spawn(Transform(position=(0.0, -0.5, -4.0)), MeshRef(box((6.0, 0.98, 0.2))),
                Material(color=(0.25, 0.25, 0.25, 1.0), roughness=1.0), Emissive(1.0))
    water = max(entity for entity, _ in world.query_one(Water))
    world.get(water, Water).fog_density = density
    world.get(water, Water).fog_color = FOG
    world.get(water, Water).depth = depth
    world.get(water, Water).absorption = absorption
    return water


def unlit_murky(world, eye, target, density: float, absorption: tuple[float, float, float],
                dark_sky: bool = True) -> None:
    """``murky``'s pond reflecting nothing, its floor and wall a grey 0.6 that emits nothing
    (lit only by the lights a test adds), and with ``dark_sky`` a black sky (no light from
    all round)."""
    murky(world, eye, target, density, reflect_rate=0.0, absorption=absorption)
    for entity, _ in world.query_one(Emissive):
        world.remove_component(entity, Emissive)
        world.get(entity, Material).color = (0.6, 0.6, 0.6, 1.0)
    if dark_sky:
        for entity, _ in world.query_one(Skybox):
            world.delete_entity(entity)
        world.spawn(Skybox(faces=[np.zeros((8, 8, 3), np.float32) for _ in range(6)]))


def kept_through(metres: float, absorption: tuple[float, float, float]) -> np.ndarray:
    """What of each channel's light ``metres`` of the water keep (Beer-Lambert, channel by channel)."""
    return np.exp(-DENSITY * np.array(absorption) * metres)


@ABSORPTIONS
def test_under_the_water_a_thing_fades_into_the_fog_colour_with_its_distance_through_the_water(scene, absorption):
    """Under the surface looking along it at a wall four metres off in the water: each pixel
    of the wall is what it gives off, plus the sky's light on it dimmed by the water over it
    (exp(-density x its depth)), all times exp(-density x d), plus the fog's colour x (1 -
    that), d the length of the pixel's ray from the eye to the wall.  (The clear frame's wall
    is its emission and the uniform sky's light on it, E x (1 + SKY).)"""
    eye, target = (0.0, -0.5, 0.0), (0.0, -0.5, -4.0)
    runner, fogged = render(scene, lambda w: murky(w, eye, target, DENSITY, absorption=absorption), size=(64, 48))
    _, clear = render(scene, lambda w: murky(w, eye, target, 0.0), size=(64, 48))
    assert runner.engine.renderer.fog.volume_count == 1
    checked = 0
    for column in range(0, 64, 7):
        for row in range(0, 48, 5):
            view = runner.engine.main_view
            ndc = glm.vec4((column + 0.5) / 64 * 2.0 - 1.0, 1.0 - (row + 0.5) / 48 * 2.0, -1.0, 1.0)
            near = glm.inverse(view.view_proj) * ndc
            direction = glm.normalize(glm.vec3(near) / near.w - view.eye)
            t = (-3.9 - view.eye.z) / direction.z  # the wall's near face
            hit = view.eye + direction * t
            if not (-0.95 < hit.y < -0.05 and abs(hit.x) < 2.5):
                continue  # off the wall, or too near its edges
            kept = kept_through(t, absorption)
            lit = clear[row, column] / (1.0 + SKY) * (1.0 + SKY * kept_through(-hit.y, absorption))  # -hit.y: its depth
            expected = lit * kept + np.array(FOG) * (1.0 - kept)
            np.testing.assert_allclose(fogged[row, column], expected, atol=0.012, err_msg=f"{row}, {column}")
            assert np.abs(fogged[row, column] - clear[row, column]).max() > 0.1  # the fog is seen
            checked += 1
    assert checked > 15


@ABSORPTIONS
def test_from_above_the_water_column_fogs_what_is_below_and_the_bank_is_clear(scene, absorption):
    """Looking straight down through a pond that reflects nothing (reflect_rate 0): the floor
    a metre down keeps exp(-density) of its light on the way up to the eye, and the sky's
    light on it came down through the same metre; with the body only half a metre deep
    (``depth``), half a metre each way; a red block on the bank, out of the box, is the clear
    frame's, pixel for pixel."""
    eye, target = (0.0, 3.0, 0.0), (0.0, 0.0, -0.01)

    def build(density: float, depth: float = 10.0):
        def b(world):
            murky(world, eye, target, density, depth=depth, reflect_rate=0.0, absorption=absorption)
            world.spawn(Transform(position=(0.0, 0.25, -0.6), rotation=FLAT), MeshRef(quad(0.4, 0.4)),
                        Material(color=(0.7, 0.05, 0.05, 1.0), roughness=1.0), Emissive(1.0))
        return b

    runner, fogged = render(scene, build(DENSITY))
    _, shallow = render(scene, build(DENSITY, depth=0.5))
    _, clear = render(scene, build(0.0))
    col, row = runner.project((0.0, -1.0, 0.0))
    for image, through in ((fogged, 1.0), (shallow, 0.5)):
        kept = kept_through(through, absorption)
        lit = clear[row, col] / (1.0 + SKY) * (1.0 + SKY * kept)  # its emission, and the sky's light through the water
        np.testing.assert_allclose(image[row, col], lit * kept + np.array(FOG) * (1.0 - kept), atol=0.01)
    col, row = runner.project((0.0, 0.25, -0.6))
    assert clear[row, col][0] > 0.5
    np.testing.assert_array_equal(fogged[row, col], clear[row, col])


@ABSORPTIONS
@pytest.mark.parametrize("light", ["sun", "slanted_sun", "lamp", "panel", "sky"])
def test_the_light_comes_down_through_the_water_to_what_is_under_it(scene, light, absorption):
    """A grey floor a metre under a murky pond, lit by one light: a sun straight down, a sun
    53.1 degrees off straight down (its way through the metre of water 1 / cos = 5/3 m long),
    a lamp a metre over the pond, a small panel there facing down (a rectangle light's own
    falloff: its light through the water lost once), or the uniform sky alone.  Its light
    came down through the water along its own way (exp(-density x length)), and keeps
    exp(-density) on the way up to the eye looking straight down (the pond reflecting
    nothing)."""
    eye, target = (0.0, 3.0, 0.0), (0.0, 0.0, -0.01)

    def build(density: float):
        def b(world):
            unlit_murky(world, eye, target, density, absorption, dark_sky=light != "sky")
            if light == "lamp":
                world.spawn(Transform(position=(0.0, 1.0, 0.0)), PointLight(intensity=5.0, range=20.0))
            elif light == "panel":  # (its front, -Z, turned down)
                down = glm.angleAxis(-math.pi / 2, glm.vec3(1, 0, 0))
                world.spawn(Transform(position=(0.0, 1.0, 0.0), rotation=down),
                            PointLight(intensity=5.0, range=20.0, rectangle=(0.2, 0.2)))
            elif light == "sun":
                world.spawn(DirectionalLight(direction=(0.0, -1.0, 0.0), intensity=1.0))
            elif light == "slanted_sun":
                world.spawn(DirectionalLight(direction=(0.8, -0.6, 0.0), intensity=4.0))
        return b

    runner, fogged = render(scene, build(DENSITY))
    _, clear = render(scene, build(0.0))
    col, row = runner.project((0.0, -1.0, 0.0))
    assert 0.1 < clear[row, col].max() < 0.9, clear[row, col]  # lit, not clipped
    kept = kept_through(1.0, absorption)
    came = kept_through(1.0 / 0.6 if light == "slanted_sun" else 1.0, absorption)   # (the light's way down)
    np.testing.assert_allclose(fogged[row, col], clear[row, col] * came * kept + np.array(FOG) * (1.0 - kept),
                               atol=0.01)


@ABSORPTIONS
@pytest.mark.parametrize("way", ["down_from_a_mirror", "up_from_a_mirror_under_it"])
def test_light_through_a_mirror_is_dimmed_by_the_water_on_every_stretch_of_its_way(scene, way, absorption):
    """A sun's light turned by a mirror (a virtual light) through a murky pond, against the
    same frame with clear water, no light from the sky.  ``down_from_a_mirror``: the sun level
    with the pond (it lights nothing under it itself), turned down at 45 degrees by a mirror
    over the bank onto the floor a metre under the water: sqrt(2) metres of water after the
    mirror, and the metre up to the eye looking straight down.  ``up_from_a_mirror_under_it``:
    the sun at 45 degrees down into the pond onto a mirror lying on its floor, turned up onto
    the underside of a board over the water, seen through the air: sqrt(2) x 0.99 metres of
    water before the mirror and as much after it (the stretch before is the line to the
    image taken back through the mirror)."""
    if way == "down_from_a_mirror":
        eye, target, seen = (0.0, 3.0, 0.0), (0.0, 0.0, -0.01), (0.0, -1.0, 0.0)
        light_way, view_way = math.sqrt(2.0), 1.0
    else:
        eye, target, seen = (3.0, 0.6, 4.0), (3.0, 2.0, 0.0), (3.0, 2.0, 0.0)
        light_way, view_way = 2.0 * 0.99 * math.sqrt(2.0), 0.0

    def build(density: float):
        def b(world):
            unlit_murky(world, eye, target, density, absorption)
            if way == "down_from_a_mirror":
                sun = glm.vec3(1.0, 0.0, 0.0)
                turned = glm.normalize(glm.vec3(1.0, -1.0, 0.0))
                at = glm.vec3(-3.0, 2.0, 0.0)            # on the line up from the floor's (0, -1, 0)
            else:
                sun = glm.normalize(glm.vec3(1.0, -1.0, 0.0))
                turned = glm.normalize(glm.vec3(1.0, 1.0, 0.0))
                at = glm.vec3(0.0, -0.99, 0.0)           # on the pond's floor
                world.spawn(Transform(position=(3.0, 2.1, 0.0)), MeshRef(box((2.0, 0.2, 2.0))),
                            Material(color=(0.6, 0.6, 0.6, 1.0), roughness=1.0))
            facing = glm.normalize(turned - sun)       # the mirror's front: against the sun, towards where it turns it
            world.spawn(Transform(position=at, rotation=look_rotation(-facing)), MeshRef(quad(1.5, 1.5)),
                        Material(), Mirror(reflects_light=True))
            world.spawn(DirectionalLight(direction=tuple(sun), intensity=1.0))
        return b

    runner, fogged = render(scene, build(DENSITY))
    _, clear = render(scene, build(0.0))
    col, row = runner.project(seen)
    assert 0.05 < clear[row, col].max() < 0.9, clear[row, col]  # lit by the mirror, not clipped
    lit = kept_through(light_way, absorption)
    seen_through = kept_through(view_way, absorption)
    np.testing.assert_allclose(fogged[row, col], clear[row, col] * lit * seen_through
                               + np.array(FOG) * (1.0 - seen_through), atol=0.01)


def test_a_lamp_through_a_portal_pair_of_two_scales_is_dimmed_by_the_water_before_it(scene):
    """test_virtual_lights' lamp in front of portal A, shining out of B (B scaled 2: its image
    is the lamp twice as large, 2 m behind B), the lamp and A's opening in a tinted water's
    body.  On the floor beyond B, out of the water, what the lamp's image adds (the frame less
    the one with A carrying no light) is, channel by channel, the clear water's times
    exp(-density x share x the real length of the way from the lamp to where the line to the
    image crosses A, carried back through the pair): a line twice as long on B's side is the
    same water on A's."""
    from engine.assets.portals import spawn_portal_pair
    from engine.core.portal_math import pair_transform
    from tests.support import look_from, pixel_rays

    lamp = np.array([0.0, 1.5, 5.0])

    def build(density: float):
        def make(world):
            look_from(world, (-1.0, 7.0, 6.0), (-3.0, 0.0, 0.0))
            world.spawn(Transform(), MeshRef(plane(24, 24)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
            world.spawn(Transform(position=lamp.tolist()), PointLight(intensity=20.0, range=8.0))
            ids = world.resources["ids"] = dict(zip("ab", spawn_portal_pair(
                world, (0.0, 1.5, 4.0), None, (-6.0, 1.5, 0.0), look_rotation(glm.vec3(-1, 0, 0))), strict=True))
            world.get(ids["b"], Transform).scale = glm.vec3(2.0)
            world.get(ids["a"], Portal).carries_light = True
            # A pond over the lamp: its body a box 4 m deep, x in [-1, 1], z in [3, 6], y in [-1, 3].
            world.spawn(Transform(position=(0.0, 3.0, 4.5), rotation=FLAT), MeshRef(quad(2.0, 3.0)),
                        Material(color=(1.0, 1.0, 1.0, 0.0)), Mirror(reflect_rate=0.0),
                        Water(fog_density=density, fog_color=FOG, depth=4.0, absorption=TINTED))
        return make

    def light(density: float):
        runner = scene(build(density), (160, 120))
        runner.engine.renderer.antialias = "off"
        on = srgb_to_linear(runner.frame())
        runner.world.get(runner.world.resources["ids"]["a"], Portal).carries_light = False
        return runner, on - srgb_to_linear(runner.frame())

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (a still water: no waves, said)
        runner, murky = light(DENSITY)
        _, clear = light(0.0)
    assert runner.stats.virtual_lights == 0  # (carries no light in the last frame)
    ids = runner.world.resources["ids"]
    carry = glm.dmat4(pair_transform(runner.world.get(ids["a"], Transform).world,
                                     runner.world.get(ids["b"], Transform).world))
    image = np.array(glm.dvec3(carry * glm.dvec4(*lamp, 1.0)))
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    points = (eye + rays * (-eye[1] / rays[..., 1])[..., None]).reshape(-1, 3)   # on the floor, y = 0
    back = np.linalg.inv(np.array(carry.to_list(), np.float64).T)   # B's side -> A's side
    t = (-6.0 - points[:, 0]) / (image - points)[:, 0]
    crossing = points + (image - points) * t[:, None]   # on B's 4 x 6 m opening, well inside
    at_a = crossing @ back[:3, :3].T + back[:3, 3]
    way = np.linalg.norm(lamp - at_a, axis=1)   # the lamp to A, all of it in the water
    lit = clear.reshape(-1, 3)
    sure = (points[:, 0] > -5.8) & (points[:, 0] < -1.5) & (np.abs(crossing[:, 1] - 1.5) < 2.7) \
        & (np.abs(crossing[:, 2]) < 1.7) & (lit.min(axis=1) > 0.05) & (lit.max(axis=1) < 0.8)
    assert sure.sum() > 200, int(sure.sum())
    want = lit[sure] * np.exp(-DENSITY * np.array(TINTED) * way[sure, None])
    np.testing.assert_allclose(murky.reshape(-1, 3)[sure], want, atol=0.012)


def test_absorption_given_and_taken_while_running_shows_from_the_next_frame(scene):
    """Grey water draws with one optical depth for every channel (no FOG_TINTED build: a vec3's
    exponentials cost llvmpipe three times one's); absorption given to it while running tints
    the next frame, as an engine built with it draws it, and taken back, the grey frame again."""
    eye, target = (0.0, 3.0, 0.0), (0.0, 0.0, -0.01)

    def build(absorption):
        return lambda world: murky(world, eye, target, DENSITY, reflect_rate=0.0, absorption=absorption)

    runner, grey = render(scene, build(GREY))
    assert "FOG_WATER" in dict(runner.engine.renderer.fog.defines)
    assert "FOG_TINTED" not in dict(runner.engine.renderer.fog.defines)
    _, tinted = render(scene, build(TINTED))
    assert np.abs(tinted - grey).max() > 0.05
    water = max(entity for entity, _ in runner.world.query_one(Water))
    runner.world.get(water, Water).absorption = TINTED
    np.testing.assert_array_equal(srgb_to_linear(runner.frame()), tinted)
    assert "FOG_TINTED" in dict(runner.engine.renderer.fog.defines)
    runner.world.get(water, Water).absorption = GREY
    np.testing.assert_array_equal(srgb_to_linear(runner.frame()), grey)
    assert "FOG_TINTED" not in dict(runner.engine.renderer.fog.defines)


def test_water_body_values_are_checked_when_given():
    for field, value in (("fog_density", -0.1), ("fog_density", math.nan), ("depth", 0.0), ("depth", 1e9),
                         ("fog_color", (1.0, 2.0)), ("absorption", (1.0, -0.5, 1.0)), ("absorption", (100.0, 1.0, 1.0)),
                         ("absorption", (1.0, 1.0)), ("absorption", (math.inf, 1.0, 1.0))):
        with pytest.raises(ComponentValueError, match=f"Water.{field}"):
            Water(**{field: value})
        water = Water()
        with pytest.raises(ComponentValueError, match=f"Water.{field}"):
            setattr(water, field, value)


def test_a_water_body_counts_among_the_fog_volumes_and_past_them_the_farthest_is_left_out(scene):
    """Eight FogVolumes far off and a murky pond under the camera: nine fogs, one left out (a
    volume, the farthest), said in a FogLimitWarning and counted in the stats."""
    def build(world):
        murky(world, (0.0, -0.5, 0.0), (0.0, -0.5, -4.0), DENSITY)
        for k in range(8):
            world.spawn(Transform(position=(30.0 + 5.0 * k, 1.0, 0.0)), FogVolume())

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        runner, _ = render(scene, build, size=(32, 24))
    assert [w for w in caught if issubclass(w.category, FogLimitWarning)]
    assert runner.stats.fog_volumes_cut == 1
    assert runner.engine.renderer.fog.volume_count == 8
    block = runner.engine.renderer.fog.block  # 16 floats, then 20 a fog: its density last (a body's negated)
    assert [block[16 + 20 * k + 19] < 0.0 for k in range(8)].count(True) == 1  # the body, nearest, is kept


def test_a_water_body_on_a_mesh_with_no_flat_outline_is_said(scene):
    def build(world):
        murky(world, (0.0, 2.0, 3.0), (0.0, 0.0, 0.0), 0.0)
        world.spawn(Transform(position=(5.0, 0.0, 0.0)), MeshRef(box((2.0, 0.2, 2.0))),
                    Material(color=(1.0, 1.0, 1.0, 0.5)),
                    Mirror(plane_point=(0.0, 0.1, 0.0), plane_normal=(0.0, 1.0, 0.0)), Water(fog_density=0.5))

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        runner, _ = render(scene, build, size=(32, 24))
    said = [str(w.message) for w in caught if issubclass(w.category, ComponentWarning) and "fog_density" in str(
        w.message)]
    assert len(said) == 1 and "not flat" in said[0]
