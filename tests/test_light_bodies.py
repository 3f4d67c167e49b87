"""A light's own mesh is its body: it casts none of that light's shadow.

A lamp is built the obvious way as one entity, a glowing bulb with a ``PointLight`` on it
(the sample level's lamp is). The light then sits inside its bulb, and a closed caster round a
light leaves everything outside it in shadow. With ``shadows=True`` such a lamp lit nothing at
all: its frame was the frame with the lamp off, bit for bit. Every map a light draws (its
cube, a spot's map, its image through a mirror) now leaves out its own entity's mesh
(``shadow.vert``'s ``light_body``, set by ``Shadows._draw_casters``). Other lights' maps keep it.

The second path: the same level with the bulb made a non-caster (``MeshRef.casts_shadows``
False, the way around it before) must be the same frame, bit for bit. The lamp must light the
floor under it, and the block beside it must still cast the lamp's shadow where the line from
the lamp over the block's top meets the floor. Broken on purpose: with ``light_body`` left at 0
(no body passed to the caster programs), the bulb's frames are the frames with the lamp off and
every test of it fails.

A bulb made as an entity of its own round a lamp that casts is a mistake the engine cannot
undo (it may be a shade meant to block), so the shadows stage names it in a ComponentWarning
(``ShadowSystem._say_enclosed``): a closed caster round the light (``shadow_rules.holds_point``,
held to the distance from a sphere's centre below), small beside its range, asked when the light
starts to cast and when a mesh comes. Broken on purpose: without the size test a closed room
round its lamp is named; with any odd ray taken for "held", an open lampshade is; with the
meshes that came not asked, a bulb made after its lamp is not named; with a light that starts
to cast not asked, a bulb made before it is not.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from pyglm import glm

from components import (
    ComponentWarning,
    DirectionalLight,
    Emissive,
    Material,
    MeshRef,
    Mirror,
    PointLight,
    Portal,
    Refractive,
    Transform,
    look_rotation,
)
from engine.assets.mesh import Mesh, box, plane, quad, sphere
from engine.rules.shadow_rules import holds_point
from tests.support import look_from, pixel_rays, six_pass_only

SIZE = (320, 240)
LAMP = glm.vec3(0.0, 2.0, 0.0)
BULB = 0.15                      # the bulb's radius: the light at its centre
BLOCK = glm.vec3(1.2, 0.4, 0.3)  # a 0.8 m block beside the lamp, on the floor
SUN = glm.vec3(-0.5, -1.0, -0.3)
# The spot aims down and a little out; 40 degrees: at most SPOT_MAP_MAX_ANGLE, one map of its own.
# "point_six_pass": the point light's cube drawn a face a pass where the context draws it layered.
KINDS = {"point": {}, "point_six_pass": {}, "spot": {"spot_angle": 40.0, "spot_blend": 0.1}}
PATHS = {"point": ("layered", "six_pass"), "point_six_pass": ("six_pass",), "spot": ("spot_map",)}


def _level(kind: str, bulb_casts: bool = True, lamp: float = 12.0, shadows: bool = True, sun: bool = False,
           mirror: bool = False, carries: bool = True):
    def build(world):
        look_from(world, (0.0, 4.5, 6.5), (0.0, 0.0, 0.0))
        world.spawn(Transform(), MeshRef(plane(14, 14)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
        world.spawn(Transform(position=BLOCK), MeshRef(box((0.8, 0.8, 0.8))), Material(color=(0.3, 0.5, 0.8)))
        world.spawn(Transform(position=LAMP, rotation=look_rotation(glm.vec3(0.15, -1.0, 0.1))),
                    MeshRef(sphere(BULB), casts_shadows=bulb_casts), Material(color=(1.0, 0.9, 0.7)), Emissive(2.0),
                    PointLight(intensity=lamp, range=9.0, shadows=shadows, **KINDS[kind]))
        if sun:
            world.spawn(DirectionalLight(direction=tuple(SUN), intensity=2.0))
        if mirror:  # its back to -x, facing the lamp: the lamp's image lights the floor before it
            world.spawn(Transform(position=(-3.0, 1.5, 0.0), rotation=look_rotation(glm.vec3(-1.0, 0.0, 0.0))),
                        MeshRef(quad(3.0, 2.5)), Material(), Mirror(reflects_light=carries))
    return build


def _frame(scene, build) -> tuple[np.ndarray, object, tuple[int, str]]:
    """The second frame of ``build`` (the first draws the maps: their count and the path of
    the last, with it), its runner."""
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    first = (runner.stats.shadow_maps_drawn, runner.stats.shadow_path)
    return runner.frame().astype(np.int32), runner, first


def _on_floor(origin: glm.vec3, through: glm.vec3) -> glm.vec3:
    """Where the line from ``origin`` through ``through`` meets the floor (y = 0)."""
    way = through - origin
    return origin + way * (-origin.y / way.y)


@pytest.mark.parametrize("kind", list(KINDS))
def test_a_lamp_on_its_glowing_bulb_lights_as_if_the_bulb_cast_nothing(scene, kind, monkeypatch):
    if kind == "point_six_pass":
        six_pass_only(monkeypatch)
    own, runner, (drawn, path) = _frame(scene, _level(kind))
    assert drawn == 1 and path in PATHS[kind], (drawn, path)
    no_caster, _, _ = _frame(scene, _level(kind, bulb_casts=False))
    np.testing.assert_array_equal(own, no_caster)

    # The lamp lights the floor under it (against the lamp off)...
    off, _, _ = _frame(scene, _level(kind, lamp=0.0))
    x, y = runner.project(glm.vec3(LAMP.x, 0.0, LAMP.z) + glm.vec3(0.3, 0.0, 0.3))
    assert own[y, x].sum() > off[y, x].sum() + 60, (own[y, x], off[y, x])
    # ...and the block still casts its shadow, beyond the block from the lamp (against the
    # lamp casting no shadows).
    unshadowed, _, _ = _frame(scene, _level(kind, shadows=False))
    x, y = runner.project(_on_floor(LAMP, BLOCK + glm.vec3(0.0, 0.3, 0.0)))
    assert own[y, x].sum() + 30 < unshadowed[y, x].sum(), (own[y, x], unshadowed[y, x])


def test_the_suns_map_keeps_the_bulbs_shadow(scene):
    """The sun casts the bulb's shadow on the floor: the frame differs from the one with the
    bulb a non-caster only there, darker."""
    own, runner, _ = _frame(scene, _level("point", sun=True))
    no_caster, _, _ = _frame(scene, _level("point", bulb_casts=False, sun=True))
    x, y = runner.project(_on_floor(LAMP, LAMP + SUN))
    differ = np.argwhere(np.abs(own - no_caster).sum(axis=2) > 0)
    assert len(differ) > 0
    assert np.abs(differ - (y, x)).max() <= 8, (differ.min(axis=0), differ.max(axis=0), (y, x))
    assert own[y, x].sum() + 30 < no_caster[y, x].sum(), (own[y, x], no_caster[y, x])


def test_a_lamps_image_in_a_mirror_leaves_its_bulbs_image_out(scene):
    """The lamp's image through a mirror that carries light has a map of its own, drawn with
    the scene carried through the mirror, where the bulb's image surrounds the lamp's image as
    the bulb surrounds the lamp: left out too, the image lights the floor before the mirror."""
    own, runner, (drawn, _) = _frame(scene, _level("point", mirror=True))
    assert runner.stats.virtual_lights == 1 and drawn == 2, (runner.stats.virtual_lights, drawn)
    no_caster, _, _ = _frame(scene, _level("point", bulb_casts=False, mirror=True))
    np.testing.assert_array_equal(own, no_caster)
    # A floor point whose line to the lamp's image (-6, 2, 0) passes through the mirror's
    # outline: brighter than with the mirror carrying no light.
    dark, _, _ = _frame(scene, _level("point", mirror=True, carries=False))
    x, y = runner.project(glm.vec3(-2.0, 0.0, -0.5))
    assert own[y, x].sum() > dark[y, x].sum() + 30, (own[y, x], dark[y, x])



PORTAL_SIZE = (160, 120)
PORTAL_LAMP = np.array([11.5, 1.8, 0.3])   # 1.5 m in front of B (at x = 10, facing +X)
PORTAL_BULB = 0.3                          # (a wide globe: many pixels through the portal)


def _portal_level(bulb_casts: bool = True, carries: bool = True, lamp: float = 12.0):
    """A portal pair, A at (0, 1.5, -3) facing +Z (the camera before it), B at (10, 1.5, 0)
    facing +X (``carries``: its lights shine out of A), and the lamp on its glowing bulb in
    front of B, casting; a floor under both."""
    def build(world):
        from engine.assets.portals import spawn_portal_pair

        look_from(world, (0.3, 1.6, 2.0), (0.0, 1.5, -3.0))
        world.spawn(Transform(), MeshRef(plane(40, 40)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
        world.resources["a"], world.resources["b"] = spawn_portal_pair(
            world, (0.0, 1.5, -3.0), None, (10.0, 1.5, 0.0), glm.angleAxis(glm.pi() / 2, glm.vec3(0, 1, 0)))
        world.get(world.resources["b"], Portal).carries_light = carries
        world.resources["bulb"] = world.spawn(
            Transform(position=tuple(PORTAL_LAMP)), MeshRef(sphere(PORTAL_BULB), casts_shadows=bulb_casts),
            Material(color=(1.0, 0.9, 0.7)), Emissive(2.0), PointLight(intensity=lamp, range=9.0, shadows=True))
    return build


def _portal_frame(scene, build):
    runner = scene(build, PORTAL_SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return runner.frame().astype(np.int32), runner


def test_a_lamps_glowing_bulb_is_seen_through_a_portal_where_its_carry_puts_it(scene):
    """Each pixel of A's picture, its ray carried by the pair's transform (float64, from the
    Transforms), is the bulb where the carried ray meets the bulb's sphere (a margin in), and
    not where it misses it (a margin out); there the glow's colour (warm, bright), and its
    image is behind A, where carry^-1 puts the lamp (not the lamp's own place)."""
    own, runner = _portal_frame(scene, _portal_level())
    world = runner.world
    on_a = runner.engine.renderer.targets.read_surface_ids() == world.resources["a"]
    assert on_a.sum() > 2000 and runner.stats.reflection_views >= 1
    a_world, b_world = (np.array(glm.dmat4(world.get(world.resources[e], Transform).world).to_list()).T for e in "ab")
    turn = np.array(glm.dmat4(glm.rotate(glm.pi(), glm.vec3(0, 1, 0))).to_list()).T
    carry = b_world @ turn @ np.linalg.inv(a_world)
    eye, rays = pixel_rays(runner.engine.main_view, PORTAL_SIZE)
    origin = carry[:3, :3] @ eye + carry[:3, 3]
    ways = rays[on_a] @ carry[:3, :3].T
    along = (PORTAL_LAMP - origin) @ ways.T
    miss = np.linalg.norm(origin + along[:, None] * ways - PORTAL_LAMP, axis=1)   # the ray's distance from the centre
    shown = runner.ids()[on_a] == world.resources["bulb"]
    inside, outside = miss < PORTAL_BULB - 0.02, miss > PORTAL_BULB + 0.02
    assert inside.sum() > 20
    assert shown[inside].all(), int((~shown[inside]).sum())
    assert not shown[outside].any(), int(shown[outside].sum())
    glow = own[on_a][inside]
    assert (glow[:, 0] > 200).all() and (glow[:, 0] >= glow[:, 2]).all(), glow.min(axis=0)
    behind = np.linalg.inv(carry) @ np.append(PORTAL_LAMP, 1.0)
    assert behind[2] < -3.0   # (behind A's opening)
    col, row = runner.project(glm.vec3(*behind[:3]))
    assert runner.ids()[row, col] == world.resources["bulb"]
    col, row = runner.project(glm.vec3(*PORTAL_LAMP))
    assert not (0 <= col < PORTAL_SIZE[0] and 0 <= row < PORTAL_SIZE[1]) \
        or runner.ids()[row, col] != world.resources["bulb"]


def test_a_lamps_light_carried_out_of_a_portal_leaves_its_bulb_out(scene):
    """The lamp's light through B shines out of A (``Portal.carries_light``): its image's map,
    drawn with the scene carried through the pair, leaves the bulb out as the lamp's own map
    does (the frame is the one with the bulb a non-caster, bit for bit), and the floor before
    A, where the lamp's image reaches through A's opening, is brighter than with B carrying no
    light."""
    own, runner = _portal_frame(scene, _portal_level())
    assert runner.stats.virtual_lights == 1, runner.stats.virtual_lights
    no_caster, _ = _portal_frame(scene, _portal_level(bulb_casts=False))
    np.testing.assert_array_equal(own, no_caster)
    dark, _ = _portal_frame(scene, _portal_level(carries=False))
    x, y = runner.project(glm.vec3(0.0, 0.0, -1.2))   # under the line from A's centre to the lamp's image
    assert own[y, x].sum() > dark[y, x].sum() + 30, (own[y, x], dark[y, x])

def _bulb_apart(how: str):
    """A lamp that casts shadows, with a mesh round it made as an entity of its own: ``how``
    "bulb" a closed glowing sphere (the mistake to say), "no_caster" the same casting none,
    "shade" a box open at the bottom (light leaves by it), "room" a closed box far larger
    than a bulb beside the range (its inside is the lit room), "beside" the sphere next to
    the light, not round it, "see_through" the sphere see-through (alpha 0.5: it lets half the
    light through, in the lamp's see-through map) and "glass" the sphere glass."""
    def build(world):
        look_from(world, (0.0, 4.5, 6.5), (0.0, 0.0, 0.0))
        world.spawn(Transform(), MeshRef(plane(14, 14)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
        world.resources["lamp"] = world.spawn(Transform(position=LAMP), PointLight(intensity=12.0, range=9.0,
                                                                                   shadows=True))
        if how == "shade":
            cube = box((0.6, 0.6, 0.6))
            low = cube.positions[cube.indices][:, :, 1].max(axis=1) < -0.29   # the bottom face's two triangles
            mesh = Mesh(cube.positions, cube.normals, cube.uvs, cube.indices[~low], name="shade")
            world.resources["mesh"] = world.spawn(Transform(position=LAMP), MeshRef(mesh), Material())
        elif how == "room":
            world.resources["mesh"] = world.spawn(Transform(position=LAMP), MeshRef(box((8.0, 5.0, 8.0))), Material())
        else:
            at = LAMP + glm.vec3(0.5, 0.0, 0.0) if how == "beside" else LAMP
            world.resources["mesh"] = world.spawn(Transform(position=at),
                                                  MeshRef(sphere(BULB), casts_shadows=how != "no_caster"),
                                                  Material(color=(1.0, 0.9, 0.7, 0.5 if how == "see_through" else 1.0)),
                                                  Emissive(2.0), *([Refractive()] if how == "glass" else []))
    return build


def test_a_closed_caster_round_a_lamp_made_apart_from_it_is_said_once(scene):
    """The glowing bulb made apart from its lamp and casting: the lamp lights nothing outside
    it, and a ComponentWarning names both entities and the two ways out, once (not again
    when the lamp and its bulb move and the map is drawn again)."""
    runner = scene(_bulb_apart("bulb"), SIZE)
    lamp, bulb = runner.world.resources["lamp"], runner.world.resources["mesh"]
    with pytest.warns(ComponentWarning, match=f"PointLight on entity {lamp} casts shadows from inside the mesh of "
                                              f"entity {bulb} .* put the PointLight on entity {bulb} .* "
                                              r"MeshRef\(casts_shadows=False\)"):
        runner.frame()
    for entity in (lamp, bulb):
        runner.world.get(entity, Transform).position += glm.vec3(0.1, 0.0, 0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ComponentWarning)
        runner.frame()
    assert runner.stats.shadow_maps_drawn == 1


def test_a_bulb_that_comes_round_a_casting_lamp_later_is_said_the_frame_it_comes(scene):
    """The lamp casts alone for a frame; the closed bulb made round it after is said then
    (the meshes that came are asked about every casting light)."""
    def build(world):
        look_from(world, (0.0, 4.5, 6.5), (0.0, 0.0, 0.0))
        world.spawn(Transform(), MeshRef(plane(14, 14)), Material())
        world.resources["lamp"] = world.spawn(Transform(position=LAMP), PointLight(range=9.0, shadows=True))

    runner = scene(build, SIZE)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ComponentWarning)
        runner.frame()
    bulb = runner.world.spawn(Transform(position=LAMP), MeshRef(sphere(BULB)), Material(), Emissive(2.0))
    with pytest.warns(ComponentWarning, match=f"PointLight on entity {runner.world.resources['lamp']} casts "
                                              f"shadows from inside the mesh of entity {bulb} "):
        runner.frame()


def test_a_lamp_that_starts_to_cast_inside_a_bulb_made_before_is_said(scene):
    """The bulb and its lamp stand a frame with the lamp's shadows off; turned on, the lamp
    is asked about every mesh (none came this frame) and the bulb is said."""
    runner = scene(_bulb_apart("bulb"), SIZE)
    lamp, bulb = runner.world.resources["lamp"], runner.world.resources["mesh"]
    runner.world.get(lamp, PointLight).shadows = False
    with warnings.catch_warnings():
        warnings.simplefilter("error", ComponentWarning)
        runner.frame()
        runner.frame()
    runner.world.get(lamp, PointLight).shadows = True
    with pytest.warns(ComponentWarning, match=f"entity {lamp} casts shadows from inside the mesh of entity {bulb} "):
        runner.frame()


@pytest.mark.parametrize("how", ["no_caster", "shade", "room", "beside", "see_through", "glass"])
def test_no_word_where_the_mesh_casts_nothing_is_open_is_a_room_or_stands_beside(scene, how):
    runner = scene(_bulb_apart(how), SIZE)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ComponentWarning)
        runner.frame()
    assert runner.stats.shadow_maps_drawn == 1


def test_holds_point_agrees_with_the_distance_from_a_spheres_centre():
    """The even-odd test against a second computation: points well inside a tessellated
    sphere (nearer its centre than its flat faces come) are held, points beyond its radius
    are not; a shell between is left out (the faces cut the sphere there)."""
    radius = 0.5
    mesh = sphere(radius, 24, 12)
    rng = np.random.default_rng(7)
    points = rng.uniform(-0.7, 0.7, (400, 3))
    distance = np.linalg.norm(points, axis=1)
    inner = radius * np.cos(np.pi / 12) ** 2   # below the faces everywhere (two angles' chord sag)
    chosen = (distance < inner) | (distance > radius)
    held = [holds_point(mesh.positions, mesh.indices, point) for point in points[chosen]]
    np.testing.assert_array_equal(held, distance[chosen] < inner)
    assert 30 < int(np.sum(distance[chosen] < inner)) < len(held) - 30
