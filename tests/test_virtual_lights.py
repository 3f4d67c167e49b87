"""Light through mirrors and portals: the frame against a float64 ray computation in numpy
(a point of the floor is lit by the mirror's image of the sun when the line to the image
crosses the mirror's outline and neither leg, floor to mirror nor mirror to sun, meets an
occluder), the patch's brightness against the direct light's times the mirror's rate and
tint, a light that cannot reach the mirror changing nothing, a lamp through a portal pair,
and the budget."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    DirectionalLight,
    Material,
    MeshRef,
    Mirror,
    PointLight,
    Portal,
    Skybox,
    Transform,
    look_rotation,
)
from engine.assets.mesh import box, plane, quad
from engine.assets.portals import spawn_portal_pair
from engine.core.portal_math import pair_transform
from engine.resources import ViewBudget
from tests.support import box_hits, drawn_over_near_depth, look_from, pcf_edge_profile, pixel_rays, srgb_to_linear

SUN = np.array([1.0, -1.0, 0.0]) / np.sqrt(2.0)
# Boxes as (centre, half sizes): a wall shading part of the floor from the sun, a small box.
WALL = (np.array([-1.1, 1.25, 0.0]), np.array([0.1, 1.25, 3.0]))
CUBE = (np.array([0.8, 0.3, 0.6]), np.array([0.3, 0.3, 0.3]))
# The mirror: at x = 3 facing -x, 3 m wide (z) and 2.5 m tall (y), centred at y = 2.25.
MIRROR_X, MIRROR_Y, MIRROR_HALF = 3.0, 2.25, np.array([1.25, 1.5])   # half height, half width
EDGE = 0.06   # metres either side of an outline left out (the maps' texels and the filter)


def _scene(world, mirror_color=(1.0, 1.0, 1.0), rate=1.0, sun=SUN, reflects=True):
    ids = {}
    look_from(world, (0.5, 6.0, 8.0), (0.5, 0.0, 0.0))
    ids["sun"] = world.spawn(DirectionalLight(direction=tuple(sun), intensity=2.0))
    ids["floor"] = world.spawn(Transform(), MeshRef(plane(14, 14)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
    for name, (centre, half) in (("wall", WALL), ("cube", CUBE)):
        ids[name] = world.spawn(Transform(position=centre.tolist()), MeshRef(box(tuple(2 * half))),
                                Material(color=(0.6, 0.5, 0.4)))
    facing_minus_x = look_rotation(glm.vec3(1, 0, 0))   # a quad's front is its +Z: turned to face -x
    ids["mirror"] = world.spawn(Transform(position=(MIRROR_X, MIRROR_Y, 0.0), rotation=facing_minus_x),
                                MeshRef(quad(2 * MIRROR_HALF[1], 2 * MIRROR_HALF[0])), Material(),
                                Mirror(color=mirror_color, reflect_rate=rate, reflects_light=reflects))
    return ids


def _box_hit(origin, direction, box, grow, limit=None):
    centre, half = box
    return box_hits(origin, direction, centre, half + grow, limit)


def _mirror_lit(points: np.ndarray, grow: float) -> np.ndarray:
    """Whether the mirror throws the sun on ``points`` (rows), occluders grown by ``grow``
    and the mirror's outline shrunk by it: the line towards the sun's image crosses the
    outline from its front, and both legs are clear."""
    image = SUN * np.array([-1.0, 1.0, 1.0])       # the mirror plane x = 3 flips x
    to_image = -image
    t = (MIRROR_X - points[:, 0]) / to_image[0]     # where the line meets the mirror's plane
    crossing = points + to_image * t[:, None]
    inside = (np.abs(crossing[:, 1] - MIRROR_Y) < MIRROR_HALF[0] - grow) & \
             (np.abs(crossing[:, 2]) < MIRROR_HALF[1] - grow) & (t > 0) & (points[:, 0] < MIRROR_X)
    direction = np.tile(to_image, (len(points), 1))
    blocked_out = _box_hit(points, direction, WALL, grow, t) | _box_hit(points, direction, CUBE, grow, t)
    to_sun = np.tile(-SUN, (len(points), 1))
    blocked_in = _box_hit(crossing, to_sun, WALL, grow) | _box_hit(crossing, to_sun, CUBE, grow)
    return inside & ~blocked_out & ~blocked_in


def _floor_points(runner):
    """Where each pixel's primary ray meets the floor (y = 0), rows of the flattened image."""
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    t = -eye[1] / rays[..., 1]
    return (eye + rays * t[..., None]).reshape(-1, 3)


def _rays_agree(before, after, pixels, lit_grown, lit_shrunk):
    """What the frame says against what the rays say: of ``pixels`` where the rays agree with
    the outlines grown and shrunk by a pixel's margin (``sure``), the share whose change from
    ``before`` to ``after`` (brighter by 10%: lit; within 2%: not) is the rays' word.  Returns
    the share, ``sure`` and the rays' word there (1: lit)."""
    ratio = srgb_to_linear(after).mean(-1) / np.maximum(srgb_to_linear(before).mean(-1), 1e-6)
    says = np.where(ratio > 1.1, 1, np.where(ratio < 1.02, 0, -1))
    sure = pixels & (lit_grown == lit_shrunk)
    rays = lit_grown[sure].astype(int)
    return float((says[sure] == rays).mean()), sure, rays


def _frames(scene, build, size=(320, 240), shadow_filter="single"):
    """The frame with the mirror's light off, then on."""
    runner = scene(build, size)
    runner.engine.renderer.antialias = "off"
    runner.engine.renderer.shadows.filter = shadow_filter
    mirror = runner.world.get(runner.world.resources["ids"]["mirror"], Mirror)
    mirror.reflects_light = False
    off = runner.frame()
    mirror.reflects_light = True
    on = runner.frame()
    return runner, off, on


@pytest.mark.parametrize("shadow_filter", ["single", "grid"])
def test_a_mirror_throws_the_sun_where_the_rays_say(scene, shadow_filter):
    def build(world):
        world.resources["ids"] = _scene(world)

    runner, off, on = _frames(scene, build, shadow_filter=shadow_filter)
    assert runner.stats.virtual_lights == 1
    ids = runner.world.resources["ids"]
    floor = runner.ids() == ids["floor"]
    points = _floor_points(runner)
    lit_out = _mirror_lit(points, -EDGE).reshape(floor.shape)
    share, sure, rays_say = _rays_agree(off, on, floor, _mirror_lit(points, EDGE).reshape(floor.shape), lit_out)
    assert sure.sum() > 40000 and rays_say.sum() > 1000, (int(sure.sum()), int(rays_say.sum()))
    # The cube's shadow inside the patch: lit by the sun's image except where the cube stands in the way.
    assert (floor & lit_out & ~_mirror_lit(points, 0.0).reshape(floor.shape)).any()
    assert share >= 0.99, f"{share:.4f} of {int(sure.sum())} floor pixels agree with the rays"


def test_the_patch_is_the_direct_light_times_the_mirrors_rate_and_colour(scene):
    """On the Lambertian floor, where only the mirror's light lands (in the wall's shadow) its
    share of the radiance over the direct sun's share on open floor is the mirror's reflect
    rate times its colour: the reflected direction makes the same angle with the floor."""
    tint, rate = (0.9, 0.75, 0.6), 0.8

    def build(world):
        world.resources["ids"] = _scene(world, mirror_color=tint, rate=rate)

    runner, off, on = _frames(scene, build, size=(320, 240))
    points = _floor_points(runner)
    seen = runner.ids() == runner.world.resources["ids"]["floor"]
    patch = _mirror_lit(points, 0.25).reshape(seen.shape) & seen
    # The wall's shadow: points whose line to the sun meets the wall (grown: none near its edge).
    to_sun = np.tile(-SUN, (len(points), 1))
    shaded = _box_hit(points, to_sun, WALL, 0.25).reshape(seen.shape)
    open_floor = ~_box_hit(points, to_sun, WALL, -0.25).reshape(seen.shape) & \
        ~_box_hit(points, to_sun, CUBE, -0.25).reshape(seen.shape) & ~_mirror_lit(points, -0.25).reshape(seen.shape)
    near = np.abs(points[:, 2]).reshape(seen.shape) < 1.0   # the same stretch of floor (the view angle is alike)
    only_mirror = patch & shaded & near
    direct = open_floor & ~shaded & near & seen & (points[:, 0] > -4.0).reshape(seen.shape) & \
        (points[:, 0] < 1.0).reshape(seen.shape)
    shadowed = seen & shaded & near & ~_mirror_lit(points, -0.25).reshape(seen.shape)
    counts = (int(only_mirror.sum()), int(direct.sum()), int(shadowed.sum()))
    assert counts[0] > 300 and counts[1] > 300 and counts[2] > 100, counts
    lin_on, lin_off = srgb_to_linear(on), srgb_to_linear(off)
    mirror_share = np.median(lin_on[only_mirror] - lin_off[only_mirror], axis=0)
    sun_share = np.median(lin_off[direct], axis=0) - np.median(lin_off[shadowed], axis=0)
    expected = rate * np.array(tint)
    np.testing.assert_allclose(mirror_share / sun_share, expected, rtol=0.06)


def test_a_light_that_cannot_reach_the_mirror_changes_no_pixel(scene):
    """The sun behind the mirror (travelling the way the mirror faces) makes no image: the
    frame with reflects_light on is the frame with it off, and no virtual light is drawn."""
    behind = np.array([-1.0, -1.0, 0.0]) / np.sqrt(2.0)

    def build(world):
        world.resources["ids"] = _scene(world, sun=behind)

    runner, off, on = _frames(scene, build)
    assert runner.stats.virtual_lights == 0
    assert np.array_equal(off, on)


def test_the_budget_cuts_a_virtual_light_and_says_so(scene):
    def build(world):
        world.resources["ids"] = _scene(world)
        world.resources[ViewBudget] = ViewBudget(views=0)

    runner, off, on = _frames(scene, build)
    assert (runner.stats.virtual_lights, runner.stats.virtual_lights_cut) == (0, 1)
    assert np.array_equal(off, on)


def test_a_still_scene_keeps_the_virtual_lights_map(scene):
    def build(world):
        world.resources["ids"] = _scene(world)

    runner = scene(build)
    runner.frame()
    drawn_first = runner.stats.shadow_maps_drawn
    runner.frame()
    assert drawn_first == 2 and runner.stats.shadow_maps_drawn == 0 and runner.stats.virtual_lights == 1
    runner.world.get(runner.world.resources["ids"]["mirror"], Mirror).reflect_rate = 0.5
    runner.frame()
    assert runner.stats.shadow_maps_drawn == 1   # the image's colour changed: its map and block again


def test_a_lamp_lights_the_floor_beyond_a_portal(scene):
    """A lamp in front of portal A (at z = 4, facing +z) shines out of portal B (at x = -6,
    facing +x) onto the floor beyond B: a floor point is lit by the lamp's image when it is in
    front of B, within range, its line to the image crosses B's opening, and neither leg meets
    a box: one stands beyond B, one between the lamp and A (its shadow comes out of B)."""
    lamp = np.array([0.0, 1.5, 5.5])
    beyond = (np.array([-3.5, 0.4, 0.6]), np.array([0.4, 0.4, 0.4]))
    before = (np.array([0.45, 1.2, 4.7]), np.array([0.15, 0.15, 0.15]))

    def build(world):
        look_from(world, (-3.0, 7.0, 6.0), (-3.5, 0.0, 0.0))
        ids = world.resources["ids"] = {}
        ids["floor"] = world.spawn(Transform(), MeshRef(plane(20, 20)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
        ids["lamp"] = world.spawn(Transform(position=lamp.tolist()), PointLight(intensity=20.0, range=14.0))
        ids["a"], ids["b"] = spawn_portal_pair(world, (0.0, 1.5, 4.0), None, (-6.0, 1.5, 0.0),
                                               look_rotation(glm.vec3(-1, 0, 0)))
        world.get(ids["a"], Portal).carries_light = True
        for centre, half in (beyond, before):
            world.spawn(Transform(position=centre.tolist()), MeshRef(box(tuple(2 * half))), Material())

    runner = scene(build, (320, 240))
    runner.engine.renderer.antialias = "off"
    ids = runner.world.resources["ids"]
    portal = runner.world.get(ids["a"], Portal)
    portal.carries_light = False
    off = runner.frame()
    portal.carries_light = True
    on = runner.frame()
    assert runner.stats.virtual_lights == 1
    carry = glm.dmat4(pair_transform(runner.world.get(ids["a"], Transform).world,
                                     runner.world.get(ids["b"], Transform).world))
    image = np.array(glm.dvec3(carry * glm.dvec4(*lamp, 1.0)))
    points = _floor_points(runner)
    seen = (runner.ids() == ids["floor"]).reshape(-1)
    to_image = image - points
    distance = np.linalg.norm(to_image, axis=1)
    # B faces +x at x = -6: a point in front has x > -6; the line meets x = -6 at t.
    t = (-6.0 - points[:, 0]) / to_image[:, 0]
    crossing = points + to_image * t[:, None]

    back = np.linalg.inv(np.array(carry.to_list(), np.float64).T)   # B's side -> A's side
    at_a = crossing @ back[:3, :3].T + back[:3, 3]

    def lit(margin):
        through = (points[:, 0] > -6.0) & (t > 0) & (t < 1) & (np.abs(crossing[:, 1] - 1.5) < 1.5 - margin) & \
            (np.abs(crossing[:, 2]) < 1.0 - margin)
        out_leg = _box_hit(points, to_image, beyond, margin, t)
        in_leg = _box_hit(at_a, lamp - at_a, before, margin, np.ones(len(points)))
        shadows.append((int((seen & through & out_leg).sum()), int((seen & through & in_leg).sum())))
        return through & ~out_leg & ~in_leg

    shadows: list[tuple[int, int]] = []

    # Where the image's light would be bright enough to see in 8 bits: the engine's falloff
    # (lights.glsl) along the whole path, times the cosine at the floor, over a Lambertian 0.8.
    fade = np.clip(1.0 - (distance / 14.0) ** 4, 0.0, 1.0)
    expected = 20.0 * fade * fade / (distance ** 2 + 1.0) * np.clip(to_image[:, 1] / distance, 0.0, 1.0) * 0.8 / np.pi
    near = expected > 0.03
    ratio = (srgb_to_linear(on).mean(-1) / np.maximum(srgb_to_linear(off).mean(-1), 1e-6)).reshape(-1)
    sure = seen & near & (lit(EDGE) == lit(-EDGE))
    says = np.where(ratio > 1.05, 1, np.where(ratio < 1.02, 0, -1))[sure]
    rays = lit(EDGE)[sure].astype(int)
    assert sure.sum() > 5000 and rays.sum() > 1500, (int(sure.sum()), int(rays.sum()))
    assert float((says == rays).mean()) >= 0.99, float((says == rays).mean())
    assert min(shadows[0]) > 100, shadows   # both boxes' shadows fall in the light out of B


def test_a_lamp_out_of_a_portal_scaled_2_lights_as_the_lamp_twice_its_size_there(scene):
    """B scaled 2 by its Transform: the view through A shows B's side at half size, so the
    lamp's image out of B is the lamp twice as large: 2 m behind B where the lamp is 1 m before
    A, twice its range and (its radiance kept, from four times the area) four times its
    intensity.  The floor beyond B, through B's opening, is lit as a real lamp made so lights
    it (the same frame there, within 8 bits), and not as the lamp itself would."""
    lamp = np.array([0.0, 1.5, 5.0])
    image = np.array([-8.0, 1.5, 0.0])   # by hand: A-local (0, 0, 1) -> B-local (0, 0, -1) x 2

    def build(lit):
        def make(world):
            look_from(world, (-1.0, 7.0, 6.0), (-3.0, 0.0, 0.0))
            ids = world.resources["ids"] = {}
            ids["floor"] = world.spawn(Transform(), MeshRef(plane(24, 24)),
                                       Material(color=(0.8, 0.8, 0.8), roughness=1.0))
            ids["lamp"] = world.spawn(Transform(position=lamp.tolist()), PointLight(intensity=20.0, range=6.0))
            ids["a"], ids["b"] = spawn_portal_pair(world, (0.0, 1.5, 4.0), None, (-6.0, 1.5, 0.0),
                                                   look_rotation(glm.vec3(-1, 0, 0)))
            world.get(ids["b"], Transform).scale = glm.vec3(2.0)
            world.get(ids["a"], Portal).carries_light = lit == "through"
            if lit in ("twice", "same"):  # a real lamp at the image: made twice the size, or as it is
                k = 2.0 if lit == "twice" else 1.0
                world.spawn(Transform(position=image.tolist()), PointLight(intensity=20.0 * k * k, range=6.0 * k))
        return make

    frames = {}
    for lit in ("through", "twice", "same"):
        runner = scene(build(lit), (240, 180))
        runner.engine.renderer.antialias = "off"
        frames[lit] = runner.frame().astype(int)
        if lit == "through":
            assert runner.stats.virtual_lights == 1
            ids = runner.world.resources["ids"]
            points = _floor_points(runner)
            seen = (runner.ids() == ids["floor"]).reshape(-1)
    # Floor points beyond B (x > -6) whose line to the image crosses B's 4 x 6 m opening well inside.
    to_image = image - points
    t = (-6.0 - points[:, 0]) / to_image[:, 0]
    crossing = points + to_image * t[:, None]
    through = seen & (points[:, 0] > -6.0) & (t > 0) & (t < 1) & (np.abs(crossing[:, 1] - 1.5) < 2.7) & \
        (np.abs(crossing[:, 2]) < 1.7)
    assert through.sum() > 2000, int(through.sum())
    flat = {name: frame.reshape(-1, 3)[through] for name, frame in frames.items()}
    assert np.abs(flat["through"] - flat["twice"]).mean() < 1.0, np.abs(flat["through"] - flat["twice"]).mean()
    assert np.abs(flat["through"] - flat["same"]).mean() > 10.0   # the check tells the two apart


def test_level_files_carry_the_light_fields(tmp_path):
    from engine.assets.level_file import LevelError, load_level, save_level
    from engine.core.world import World

    text = """
[level]
name = "light through"

[[entity]]
name = "mirror"
[entity.Transform]
position = [0.0, 1.0, -3.0]
[entity.MeshRef]
mesh = { quad = [2.0, 2.0] }
[entity.Mirror]
reflects_light = true

[[entity]]
name = "a"
[entity.Transform]
position = [-5.0, 0.0, 0.0]
[entity.Portal]
partner = "b"
carries_light = true

[[entity]]
name = "b"
[entity.Transform]
position = [5.0, 0.0, 0.0]
[entity.Portal]
partner = "a"
"""
    path = tmp_path / "through.toml"
    path.write_text(text)
    world = World("through")
    names = load_level(path).spawn(world)
    assert world.get(names["mirror"], Mirror).reflects_light and world.get(names["a"], Portal).carries_light
    again = World("again")
    names_again = load_level(save_level(world, tmp_path / "again.toml", names)).spawn(again)
    assert again.get(names_again["mirror"], Mirror).reflects_light
    assert again.get(names_again["a"], Portal).carries_light and not again.get(names_again["b"], Portal).carries_light
    path.write_text(text.replace("reflects_light = true", 'reflects_light = "yes"'))
    with pytest.raises(LevelError, match="reflects_light"):
        load_level(path)


@pytest.mark.parametrize("glass", [False, True], ids=["box", "glass_sun_casting_none"])
def test_a_probe_face_recaptures_when_a_shadow_in_the_mirrors_light_moves(scene, glass):
    """The probe's -Y face sees the floor where the mirror throws the sun; a box on the
    light's way in (between the sun and the mirror, out of the probe's reach and out of that
    face even as the sun's own shadow) moves: its shadow in the thrown light moves in that
    face, which is captured again, for that reason.  So does a glass box's (the share it
    lets through), where the sun itself casts no shadow: the mirror's light alone has a map."""
    from components import ReflectionProbe, Refractive
    from engine.rules.probe_schedule import ProbeSchedule

    def build(world):
        ids = world.resources["ids"] = _scene(world)
        if glass:
            world.get(ids["sun"], DirectionalLight).shadows = False
        ids["probe"] = world.spawn(Transform(position=(0.7, 0.6, 0.0)), ReflectionProbe(resolution=16, far=1.5))
        ids["way_in"] = world.spawn(Transform(position=(2.0, 3.25, 0.0)), MeshRef(box((0.3, 0.3, 0.3))),
                                    Material(color=(1.0, 1.0, 1.0, 0.2) if glass else (1.0, 1.0, 1.0, 1.0)),
                                    *([Refractive(screen=False)] if glass else []))

    runner = scene(build)
    runner.frame()
    runner.frame()
    ids = runner.world.resources["ids"]
    assert ids["probe"] not in runner.world.resources[ProbeSchedule].due
    runner.world.get(ids["way_in"], Transform).position += glm.vec3(0.0, 0.0, 0.1)
    runner.frame()
    due = runner.world.resources[ProbeSchedule].due
    assert ids["probe"] in due and 3 in due[ids["probe"]].faces, due
    reasons = due[ids["probe"]].reasons
    assert any(reason.startswith("shadow of entity") and 3 in faces for reason, faces in reasons.items()), reasons


# --- light reflected twice: the sun -> mirror A -> mirror B -> the floor ----------------------
# A high on the right (x = 3, facing -x) throws the sun down-left onto B, low on the left
# (x = -2, facing +x), which throws it down-right onto the floor beside it, the way the sun
# itself travels (two parallel mirrors: the light leaves B parallel to the sun).  A cube
# stands in the patch, a small box on the way from A to B.
A_X, A_Y, A_HALF = 3.0, 5.5, np.array([1.0, 1.5])     # half height (y), half width (z)
B_X, B_Y, B_HALF = -2.0, 1.5, np.array([1.25, 1.5])
TWICE_CUBE = (np.array([-1.1, 0.3, 0.6]), np.array([0.3, 0.3, 0.3]))
ON_THE_WAY = (np.array([0.0, 3.2, -0.6]), np.array([0.25, 0.25, 0.25]))
THIN = 0.002   # a mirror quad as an occluder: a box this thin


def _two_mirror_scene(world, tint_a=(1.0, 1.0, 1.0), rate_a=1.0, tint_b=(1.0, 1.0, 1.0), rate_b=1.0, bounces=2):
    ids = {}
    look_from(world, (2.0, 4.0, 4.5), (-1.0, 0.3, 0.0))
    ids["sun"] = world.spawn(DirectionalLight(direction=tuple(SUN), intensity=2.0, bounces=bounces))
    ids["floor"] = world.spawn(Transform(), MeshRef(plane(14, 14)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
    for name, (centre, half) in (("cube", TWICE_CUBE), ("way", ON_THE_WAY)):
        ids[name] = world.spawn(Transform(position=centre.tolist()), MeshRef(box(tuple(2 * half))),
                                Material(color=(0.6, 0.5, 0.4)))
    for name, x, y, half, face, tint, rate in (("a", A_X, A_Y, A_HALF, (1, 0, 0), tint_a, rate_a),
                                               ("b", B_X, B_Y, B_HALF, (-1, 0, 0), tint_b, rate_b)):
        ids[name] = world.spawn(Transform(position=(x, y, 0.0), rotation=look_rotation(glm.vec3(*face))),
                                MeshRef(quad(2 * half[1], 2 * half[0])), Material(),
                                Mirror(color=tint, reflect_rate=rate, reflects_light=True))
    return ids


def _mirror_box(x, y, half):
    return np.array([x, y, 0.0]), np.array([THIN, half[0], half[1]])


def _twice_way(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The way back from ``points`` (rows) towards the doubly reflected sun: the direction
    (-SUN), how far to B's plane, where it meets it and where the way from there meets A's."""
    back = np.tile(-SUN, (len(points), 1))
    t_b = (B_X - points[:, 0]) / back[:, 0]
    at_b = points + back * t_b[:, None]
    a_image_x = 2 * B_X - A_X
    t_a = (a_image_x - points[:, 0]) / back[:, 0]
    at_a_image = points + back * t_a[:, None]
    at_a = at_a_image * np.array([-1.0, 1.0, 1.0]) + np.array([2 * B_X, 0.0, 0.0])   # reflected back in B
    return back, t_b, at_b, at_a


def _twice_lit(points: np.ndarray, grow: float, boxes=(TWICE_CUBE, ON_THE_WAY)) -> np.ndarray:
    """Whether the sun reaches ``points`` (rows) by A then B (float64 rays, occluders grown by
    ``grow``, outlines shrunk by it): the line from the point towards the doubly reflected
    sun (it travels as the sun: the line runs along -SUN) crosses B's plane inside B from its
    front, then A's image in B's plane (x = 2 B_X - A_X) inside A's outline; each real leg,
    point to B, B to A, A to the sun, meets no box and no other mirror."""
    back, t_b, at_b, at_a = _twice_way(points)
    inside = (points[:, 0] > B_X) & (t_b > 0) & \
        (np.abs(at_b[:, 1] - B_Y) < B_HALF[0] - grow) & (np.abs(at_b[:, 2]) < B_HALF[1] - grow) & \
        (np.abs(at_a[:, 1] - A_Y) < A_HALF[0] - grow) & (np.abs(at_a[:, 2]) < A_HALF[1] - grow)
    a_box, b_box = _mirror_box(A_X, A_Y, A_HALF), _mirror_box(B_X, B_Y, B_HALF)
    ones = np.ones(len(points))
    blocked = np.zeros(len(points), bool)
    for box_ in (*boxes, a_box):             # the point to B
        blocked |= _box_hit(points, at_b - points, box_, grow, ones)
    for box_ in boxes:                       # B to A (the mirrors are its ends)
        blocked |= _box_hit(at_b, at_a - at_b, box_, grow, ones)
    for box_ in (*boxes, b_box):             # A to the sun
        blocked |= _box_hit(at_a, back, box_, grow)
    return inside & ~blocked


def _seen_in_a_mirror(runner) -> np.ndarray:
    """Pixels whose primary ray meets a mirror (grown a little) before the floor: the id image
    shows what the mirror shows there, the floor too, but not the floor the ray meets."""
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    rays = rays.reshape(-1, 3)
    origin = np.tile(eye, (len(rays), 1))
    hit = np.zeros(len(rays), bool)
    for x, y, half in ((A_X, A_Y, A_HALF), (B_X, B_Y, B_HALF)):
        hit |= _box_hit(origin, rays, _mirror_box(x, y, half), 0.05)
    w, h = runner.size
    return hit.reshape(h, w)


def _bounce_frames(scene, build, size=(320, 240)):
    """The frame with the sun reflected once, then twice."""
    runner = scene(build, size)
    runner.engine.renderer.antialias = "off"
    runner.engine.renderer.shadows.filter = "single"
    sun = runner.world.get(runner.world.resources["ids"]["sun"], DirectionalLight)
    sun.bounces = 1
    once = runner.frame()
    once_lights = runner.stats.virtual_lights
    sun.bounces = 2
    twice = runner.frame()
    return runner, once, twice, once_lights


def test_the_sun_reflected_by_two_mirrors_lands_where_the_rays_say(scene):
    def build(world):
        world.resources["ids"] = _two_mirror_scene(world)

    runner, once, twice, once_lights = _bounce_frames(scene, build)
    assert (once_lights, runner.stats.virtual_lights) == (1, 2)   # A's light, then also A's through B
    ids = runner.world.resources["ids"]
    floor = (runner.ids() == ids["floor"]) & ~_seen_in_a_mirror(runner)
    points = _floor_points(runner)
    lit_out = _twice_lit(points, -EDGE).reshape(floor.shape)
    share, sure, rays_say = _rays_agree(once, twice, floor, _twice_lit(points, EDGE).reshape(floor.shape), lit_out)
    assert sure.sum() > 40000 and rays_say.sum() > 600, (int(sure.sum()), int(rays_say.sum()))
    exact = _twice_lit(points, 0.0).reshape(floor.shape)
    # Both boxes shadow the patch: the cube on the last leg, the small box on the way from A to B.
    for box_ in (TWICE_CUBE, ON_THE_WAY):
        alone = _twice_lit(points, 0.0, (box_,)).reshape(floor.shape)
        assert (floor & ~alone & _twice_lit(points, 0.0, ()).reshape(floor.shape)).sum() > 100, box_
    assert (floor & lit_out & ~exact).sum() > 200
    assert share >= 0.99, f"{share:.4f} of {int(sure.sum())} floor pixels agree with the rays"


def test_light_reflected_twice_is_the_direct_light_times_both_mirrors(scene):
    """On the Lambertian floor in B's own shadow (the sun is cut off there, A's light once
    reflected lands farther left), the light that came by A and B, over the direct sun's share
    on open floor, is A's rate x tint times B's: two parallel mirrors send it on parallel to
    the sun, so it meets the floor at the sun's angle.  Tolerance 6%, as for one mirror (8-bit
    frames, the sRGB curve, the floor's small GGX highlight)."""
    tint_a, rate_a, tint_b, rate_b = (0.9, 0.8, 0.7), 0.9, (1.0, 0.7, 0.5), 0.8

    def build(world):
        world.resources["ids"] = _two_mirror_scene(world, tint_a, rate_a, tint_b, rate_b)

    runner, once, twice, _ = _bounce_frames(scene, build)
    shape = (runner.size[1], runner.size[0])
    seen = (runner.ids() == runner.world.resources["ids"]["floor"]) & ~_seen_in_a_mirror(runner)
    points = _floor_points(runner)
    to_sun = np.tile(-SUN, (len(points), 1))

    def sun_blocked(grow):
        hit = np.zeros(len(points), bool)
        for box_ in (TWICE_CUBE, ON_THE_WAY, _mirror_box(A_X, A_Y, A_HALF), _mirror_box(B_X, B_Y, B_HALF)):
            hit |= _box_hit(points, to_sun, box_, grow)
        return hit.reshape(shape)

    x = points[:, 0].reshape(shape)
    once_from_a = x < -1.4          # where A's light reflected once can land (A's image line through A)
    patch = _twice_lit(points, 0.2).reshape(shape) & seen & sun_blocked(-0.2) & ~once_from_a
    shaded = seen & sun_blocked(-0.2) & ~_twice_lit(points, -0.2).reshape(shape) & ~once_from_a
    direct = seen & ~sun_blocked(0.2) & ~once_from_a & (x < 2.0) & \
        (np.abs(points[:, 2]).reshape(shape) < 1.5)
    counts = (int(patch.sum()), int(shaded.sum()), int(direct.sum()))
    assert counts[0] > 200 and counts[1] > 100 and counts[2] > 300, counts
    lin_once, lin_twice = srgb_to_linear(once), srgb_to_linear(twice)
    twice_share = np.median(lin_twice[patch] - lin_once[patch], axis=0)
    sun_share = np.median(lin_once[direct], axis=0) - np.median(lin_once[shaded], axis=0)
    expected = rate_a * rate_b * np.array(tint_a) * np.array(tint_b)
    np.testing.assert_allclose(twice_share / sun_share, expected, rtol=0.06)


def test_each_bounce_is_spent_under_the_budget_and_stops_at_the_depth_limits(scene):
    """The second bounce is a virtual light of its own: a budget of one view draws A's light
    and cuts A-through-B, and says so; B's max_depth of 1 (it shows no mirror in a mirror)
    and the view tree's depth cap of 1 stop it as they stop views; a sun with bounces = 0 is
    reflected by no mirror."""
    def build(world):
        world.resources["ids"] = _two_mirror_scene(world)
        world.resources[ViewBudget] = ViewBudget(views=1)

    runner = scene(build)
    ids = runner.world.resources["ids"]
    runner.frame()
    assert (runner.stats.virtual_lights, runner.stats.virtual_lights_cut) == (1, 1)
    runner.world.resources[ViewBudget] = ViewBudget(views=None)
    runner.frame()
    assert (runner.stats.virtual_lights, runner.stats.virtual_lights_cut) == (2, 0)
    runner.world.get(ids["b"], Mirror).max_depth = 1
    runner.frame()
    assert (runner.stats.virtual_lights, runner.stats.virtual_lights_cut) == (1, 0)
    runner.world.get(ids["b"], Mirror).max_depth = 3
    runner.engine.stages["reflect"].max_depth_cap = 1
    runner.frame()
    assert runner.stats.virtual_lights == 1
    runner.engine.stages["reflect"].max_depth_cap = 8
    runner.world.get(ids["sun"], DirectionalLight).bounces = 0
    runner.frame()
    assert runner.stats.virtual_lights == 0


def test_light_bounces_is_checked_and_carried_by_level_files(tmp_path):
    from components.tracking import ComponentValueError
    from engine.assets.level_file import load_level, save_level
    from engine.core.world import World

    with pytest.raises(ComponentValueError, match="bounces"):
        DirectionalLight(bounces=5)
    with pytest.raises(ComponentValueError, match="bounces"):
        PointLight(bounces=-1)
    path = tmp_path / "bounces.toml"
    path.write_text('[level]\nname = "b"\n\n[[entity]]\nname = "sun"\n[entity.DirectionalLight]\nbounces = 3\n\n'
                    '[[entity]]\nname = "lamp"\n[entity.Transform]\n[entity.PointLight]\nbounces = 2\n')
    world = World("bounces")
    names = load_level(path).spawn(world)
    assert world.get(names["sun"], DirectionalLight).bounces == 3
    again = World("again")
    names_again = load_level(save_level(world, tmp_path / "again.toml", names)).spawn(again)
    assert again.get(names_again["sun"], DirectionalLight).bounces == 3
    assert again.get(names_again["lamp"], PointLight).bounces == 2


def test_light_path_is_the_shaders_aperture_test_on_the_cpu(scene):
    """``shadow_rules.light_path`` (what a game asks, e.g. mirror beam's target) says the
    doubly reflected sun reaches exactly the floor points the float64 rays say it reaches
    through both outlines (no occluders: it tests no shadows), and its corners are where
    those rays cross B and A."""
    from engine.rules.shadow_rules import ShadowCasters, light_path

    def build(world):
        world.resources["ids"] = _two_mirror_scene(world)

    runner = scene(build)
    runner.frame()
    twice = [v for v in runner.world.resources[ShadowCasters].virtual if v.bounces == 2]
    assert len(twice) == 1
    ids = runner.world.resources["ids"]
    assert twice[0].path == (ids["a"], ids["b"])
    rng = np.random.default_rng(7)
    points = np.column_stack([rng.uniform(-3.0, 2.0, 4000), np.zeros(4000), rng.uniform(-2.5, 2.5, 4000)])
    rays = _twice_lit(points, 0.0, ())
    ways = [light_path(twice[0], p) for p in points]
    says = np.array([w is not None for w in ways])
    near_edge = _twice_lit(points, 0.01, ()) != _twice_lit(points, -0.01, ())
    assert rays.sum() > 500 and np.array_equal(says[~near_edge], rays[~near_edge])
    lit = int(np.flatnonzero(rays & ~near_edge)[0])
    back = -SUN
    at_b = points[lit] + back * (B_X - points[lit][0]) / back[0]
    at_a_image = points[lit] + back * (2 * B_X - A_X - points[lit][0]) / back[0]
    at_a = at_a_image * np.array([-1.0, 1.0, 1.0]) + np.array([2 * B_X, 0.0, 0.0])
    np.testing.assert_allclose(ways[lit][1], at_b, atol=1e-4)
    np.testing.assert_allclose(ways[lit][2], at_a, atol=1e-4)
    np.testing.assert_allclose((ways[lit][3] - at_a) / np.linalg.norm(ways[lit][3] - at_a), back, atol=1e-4)


def test_a_lamp_carried_by_a_portal_then_reflected_by_a_mirror_lands_where_the_rays_say(scene):
    """A chain of two kinds: a lamp in front of portal A (z = 4, facing +z) shines out of
    portal B (x = -6, facing +x) onto mirror M (x = -3.5, facing -x), which throws it back on
    the floor between them.  With ``bounces = 2`` the frame gains exactly the floor points
    the float64 rays give: the line from the point to the lamp's image through the pair and
    then M crosses M's outline from its front, and from there the line to the pair's image
    crosses B's opening from its front (nothing else stands in the way)."""
    lamp = np.array([0.0, 1.5, 8.0])             # far from A: B's opening, not only M's, bounds the patch
    m_x, m_half = -3.5, np.array([1.5, 2.5])        # M: half height (y, centred at 1.5), half width (z)
    b_half = np.array([1.5, 1.0])                   # the pair's opening: 2 m wide, 3 m tall

    def build(world):
        look_from(world, (-4.75, 6.0, 4.0), (-4.75, 0.0, 0.0))
        ids = world.resources["ids"] = {}
        ids["floor"] = world.spawn(Transform(), MeshRef(plane(20, 20)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
        ids["lamp"] = world.spawn(Transform(position=lamp.tolist()), PointLight(intensity=80.0, range=14.0, bounces=2))
        ids["a"], ids["b"] = spawn_portal_pair(world, (0.0, 1.5, 4.0), None, (-6.0, 1.5, 0.0),
                                               look_rotation(glm.vec3(-1, 0, 0)))   # B's front: +x
        world.get(ids["a"], Portal).carries_light = True
        # (look_rotation points a surface's back along the direction: M's front is -x)
        ids["m"] = world.spawn(Transform(position=(m_x, 1.5, 0.0), rotation=look_rotation(glm.vec3(1, 0, 0))),
                               MeshRef(quad(2 * m_half[1], 2 * m_half[0])), Material(),
                               Mirror(reflects_light=True))

    runner = scene(build, (320, 240))
    runner.engine.renderer.antialias = "off"
    runner.engine.renderer.shadows.filter = "single"
    ids = runner.world.resources["ids"]
    light = runner.world.get(ids["lamp"], PointLight)
    light.bounces = 1
    once = runner.frame()
    once_lights = runner.stats.virtual_lights
    light.bounces = 2
    twice = runner.frame()
    assert (once_lights, runner.stats.virtual_lights) == (1, 2)   # the pair's light, then also M's of it
    carry = glm.dmat4(pair_transform(runner.world.get(ids["a"], Transform).world,
                                     runner.world.get(ids["b"], Transform).world))
    image1 = np.array(glm.dvec3(carry * glm.dvec4(*lamp, 1.0)))   # the lamp seen through the pair
    image2 = image1 * np.array([-1.0, 1.0, 1.0]) + np.array([2 * m_x, 0.0, 0.0])   # and then in M
    points = _floor_points(runner)
    to_image = image2 - points
    distance = np.linalg.norm(to_image, axis=1)

    def lit(margin, through_b=True):
        t_m = (m_x - points[:, 0]) / to_image[:, 0]
        at_m = points + to_image * t_m[:, None]
        to_first = image1 - at_m
        t_b = (-6.0 - at_m[:, 0]) / to_first[:, 0]
        at_b = at_m + to_first * t_b[:, None]
        by_m = (points[:, 0] < m_x) & (t_m > 0) & (t_m < 1) & (distance < 14.0) & \
            (np.abs(at_m[:, 1] - 1.5) < m_half[0] - margin) & (np.abs(at_m[:, 2]) < m_half[1] - margin)
        return by_m & (t_b > 0) & (t_b < 1) & (np.abs(at_b[:, 1] - 1.5) < b_half[0] - margin) & \
            (np.abs(at_b[:, 2]) < b_half[1] - margin) if through_b else by_m

    # Pixels whose primary ray meets M or B first show what those show, not this floor point.
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    rays = rays.reshape(-1, 3)
    origin = np.tile(eye, (len(rays), 1))
    through = _box_hit(origin, rays, (np.array([m_x, 1.5, 0.0]), np.array([THIN, *m_half])), 0.05) | \
        _box_hit(origin, rays, (np.array([-6.0, 1.5, 0.0]), np.array([THIN, *b_half])), 0.05)
    seen = (runner.ids() == ids["floor"]).reshape(-1) & ~through
    fade = np.clip(1.0 - (distance / 14.0) ** 4, 0.0, 1.0)
    expected = 80.0 * fade * fade / (distance ** 2 + 1.0) * np.clip(to_image[:, 1] / distance, 0.0, 1.0) * 0.8 / np.pi
    before = srgb_to_linear(once).mean(-1).reshape(-1)
    ratio = srgb_to_linear(twice).mean(-1).reshape(-1) / np.maximum(before, 1e-6)
    # Where the second bounce would add a visible share: the pair's own light out of B already
    # lights this floor, brightest near B, where a few per cent more is within 8 bits' steps.
    strong = (expected > 0.03) & (expected > 0.15 * before)
    sure = seen & strong & (lit(EDGE) == lit(-EDGE))
    says = np.where(ratio > 1.05, 1, np.where(ratio < 1.02, 0, -1))[sure]
    rays_say = lit(EDGE)[sure].astype(int)
    assert sure.sum() > 3000 and rays_say.sum() > 500, (int(sure.sum()), int(rays_say.sum()))
    # B's opening, not M's outline alone, bounds the patch: a shader that tested only the last
    # surface it crossed would light these too.
    assert (sure & lit(-EDGE, through_b=False) & ~lit(-EDGE)).sum() > 1000
    assert float((says == rays_say).mean()) >= 0.99, float((says == rays_say).mean())


def test_a_portal_that_carries_light_shades_what_lies_behind_its_opening(scene):
    """A lamp casting shadows in front of portal A (at z = 0, facing +z, 2 m wide and 3 m
    tall), its partner B far off facing away: with A carrying light, the floor behind A whose
    line to the lamp passes through A's opening gets none of the lamp's light (it went in and
    out of B) and is the frame without the lamp there; with A carrying none, the light goes
    on through the opening as before and lights it.  Floor behind A whose line misses the
    opening is lit either way."""
    lamp = np.array([0.0, 1.5, 2.5])

    def build(world, with_lamp=True):
        look_from(world, (0.0, 7.0, -7.0), (0.0, 0.0, -2.5))
        ids = world.resources["ids"] = {}
        ids["floor"] = world.spawn(Transform(), MeshRef(plane(20, 20)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
        if with_lamp:
            world.spawn(Transform(position=lamp.tolist()), PointLight(intensity=20.0, range=12.0, shadows=True))
        ids["a"], ids["b"] = spawn_portal_pair(world, (0.0, 1.5, 0.0), None, (9.0, 1.5, 8.0),
                                               look_rotation(glm.vec3(1, 0, 0)))
        world.get(ids["a"], Portal).carries_light = True

    runner = scene(build, (240, 180))
    dark = scene(lambda world: build(world, with_lamp=False), (240, 180)).frame()
    carried = runner.frame()
    ids = runner.world.resources["ids"]
    runner.world.get(ids["a"], Portal).carries_light = False
    through = runner.frame()
    points = _floor_points(runner)
    seen = (runner.ids() == ids["floor"]).reshape(-1)
    to_lamp = lamp - points
    t = -points[:, 2] / to_lamp[:, 2]          # where the line to the lamp meets A's plane, z = 0
    crossing = points + to_lamp * t[:, None]
    behind = seen & (points[:, 2] < -0.3) & (np.linalg.norm(to_lamp, axis=1) < 6.0)   # where the lamp is bright
    inside = behind & (np.abs(crossing[:, 0]) < 1.0 - EDGE) & (crossing[:, 1] > EDGE) & (crossing[:, 1] < 3.0 - EDGE)
    outside = behind & ((np.abs(crossing[:, 0]) > 1.0 + EDGE) | (crossing[:, 1] > 3.0 + EDGE))
    assert inside.sum() > 500 and outside.sum() > 500, (int(inside.sum()), int(outside.sum()))
    flat = [frame.reshape(-1, 3).astype(int) for frame in (carried, through, dark)]
    carried, through, dark = flat
    assert np.abs(carried[inside] - dark[inside]).max() <= 1        # the opening's shadow: no lamp light
    lit = srgb_to_linear(through[inside]).mean(-1) > srgb_to_linear(dark[inside]).mean(-1) + 0.02
    assert lit.all(), lit.mean()                                     # carrying none, the light goes through
    lit_beside = srgb_to_linear(carried[outside]).mean(-1) > srgb_to_linear(dark[outside]).mean(-1) + 0.005
    assert lit_beside.mean() > 0.97, lit_beside.mean()
    assert np.array_equal(carried[outside], through[outside])        # beside the opening: the same either way


# See-through panes (plane meshes, facing up) in the mirror's light: one on its way out (between
# the mirror and the floor it lights) and one on its way in (between the sun and the mirror).
PANE_ALPHA, PANE_HALF = 0.6, np.array([0.5, 0.6])   # half sizes along x and z
PANES = {"way_out": np.array([1.5, 1.0, 0.0]), "way_in": np.array([2.0, 3.5, 0.0])}


def _pane_crossed(origin: np.ndarray, direction: np.ndarray, centre: np.ndarray, grow: float,
                  limit: np.ndarray | None = None) -> np.ndarray:
    """Whether each ray (rows) meets the pane at ``centre`` (a level rectangle) grown by ``grow``,
    ahead of it and short of ``limit``."""
    t = (centre[1] - origin[:, 1]) / direction[:, 1]
    at = origin + direction * t[:, None]
    inside = (np.abs(at[:, 0] - centre[0]) < PANE_HALF[0] + grow) & (np.abs(at[:, 2] - centre[2]) < PANE_HALF[1] + grow)
    return inside & (t > 0) & (t < (np.inf if limit is None else limit))


def _one_mirror_with_pane(centre: np.ndarray, alpha: float = PANE_ALPHA):
    def build(world):
        ids = _scene(world)
        ids["pane"] = world.spawn(Transform(position=centre.tolist()), MeshRef(plane(*(2 * PANE_HALF))),
                                  Material(color=(0.7, 0.8, 0.9, alpha)))
        world.resources["ids"] = ids
    return build


def _share_behind_the_pane(runner, off, on, centre: np.ndarray) -> np.ndarray:
    """The mirror's light on the floor where the rays from it towards the sun's image cross
    the pane at ``centre`` (on either stretch of the way), over where they do not: the
    medians of the frames' difference (the mirror's light on, less off), per channel; floor
    seen through the pane left out."""
    ids = runner.world.resources["ids"]
    floor = (runner.ids() == ids["floor"]).ravel()
    points = _floor_points(runner)
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    rays = rays.reshape(-1, 3)
    seen_through_pane = _pane_crossed(np.tile(eye, (len(points), 1)), rays, centre, 0.1,
                                      np.linalg.norm(points - eye, axis=1) / np.linalg.norm(rays, axis=1))
    image = SUN * np.array([-1.0, 1.0, 1.0])
    to_image = np.tile(-image, (len(points), 1))
    t = (MIRROR_X - points[:, 0]) / to_image[:, 0]
    crossing = points + to_image * t[:, None]
    to_sun = np.tile(-SUN, (len(points), 1))

    def crossed(grow):
        return _pane_crossed(points, to_image, centre, grow, t) | _pane_crossed(crossing, to_sun, centre, grow)

    lit = _mirror_lit(points, 0.1) & floor & ~seen_through_pane
    behind, beside = lit & crossed(-0.1), lit & ~crossed(0.1)
    assert behind.sum() > 100 and beside.sum() > 1000, (int(behind.sum()), int(beside.sum()))
    share = (srgb_to_linear(on) - srgb_to_linear(off)).reshape(-1, 3)
    return np.median(share[behind], axis=0) / np.median(share[beside], axis=0)


@pytest.mark.parametrize("where", list(PANES))
def test_a_see_through_pane_on_the_mirrors_way_lets_through_its_share(scene, where):
    """A see-through pane (alpha 0.6) in the mirror's light, on its way from the mirror to the
    floor, or from the sun to the mirror (the stretch the virtual light's map draws carried to
    where the sun's image sees it): where the rays from the floor towards the sun's image
    cross it, the mirror's light on the Lambertian floor is 1 - alpha of what it is beside
    (``VIRTUAL_SEE_THROUGH_SHADOWS``)."""
    runner, off, on = _frames(scene, _one_mirror_with_pane(PANES[where]), size=(480, 360))
    assert runner.engine.renderer.shadows.virtual_see_through_atlas is not None
    np.testing.assert_allclose(_share_behind_the_pane(runner, off, on, PANES[where]), 1.0 - PANE_ALPHA, rtol=0.06)


@pytest.mark.parametrize("decoys", [1, 2, 3])
def test_a_virtual_light_in_a_later_slot_reads_its_own_see_through_tile(scene, decoys):
    """Small mirrors of a higher ``priority`` beside the hall (along z, far from the floor the
    mirror lights), each throwing the sun away from it, take the first virtual-light slots,
    so the mirror's light is drawn in slot ``decoys`` (the 2 x 2 tiles' second column, and
    in its second row: slots 2 and 3): the pane on its way out lets through 1 - alpha, as in
    slot 0."""
    def build(world):
        _one_mirror_with_pane(PANES["way_out"])(world)
        facing_minus_x = look_rotation(glm.vec3(1, 0, 0))
        for z in (-5.0, 5.0, 9.0)[:decoys]:
            world.spawn(Transform(position=(MIRROR_X, MIRROR_Y, z), rotation=facing_minus_x),
                        MeshRef(quad(1.0, 1.0)), Material(), Mirror(reflects_light=True, priority=1))

    runner, off, on = _frames(scene, build, size=(480, 360))
    mirror = runner.world.resources["ids"]["mirror"]
    slots = {slot: key[1] for slot, key in runner.engine.stages["shadows"]._virtual.items()}
    assert len(slots) == decoys + 1 and slots[decoys] == (mirror,), slots
    np.testing.assert_allclose(_share_behind_the_pane(runner, off, on, PANES["way_out"]), 1.0 - PANE_ALPHA, rtol=0.06)


def test_without_a_unit_for_the_virtual_see_through_map_the_pane_dims_no_mirror_light_and_says_so(scene):
    """A context whose fragment stage has too few texture units for the virtual lights'
    see-through map (one more than the lamps'): a GLLimitWarning names the count, once, no
    atlas is made, and the mirror's light behind the pane is as beside it."""
    import warnings

    from engine.core.errors import GLLimitWarning
    from engine.render.bindings import VIRTUAL_SEE_THROUGH_SAMPLERS

    runner = scene(_one_mirror_with_pane(PANES["way_out"]), (480, 360))
    runner.engine.renderer.antialias = "off"
    runner.engine.renderer.shadows.filter = "single"
    shadows = runner.engine.renderer.shadows
    shadows.virtual_see_through_supported = False
    mirror = runner.world.get(runner.world.resources["ids"]["mirror"], Mirror)
    mirror.reflects_light = False
    off = runner.frame()
    mirror.reflects_light = True
    with pytest.warns(GLLimitWarning, match=f"need {VIRTUAL_SEE_THROUGH_SAMPLERS} texture units"):
        on = runner.frame()
    with warnings.catch_warnings():
        warnings.simplefilter("error", GLLimitWarning)
        runner.frame()
    assert shadows.virtual_see_through_atlas is None
    assert not any(name == "VIRTUAL_SEE_THROUGH_SHADOWS" for name, _ in shadows.program_defines)
    np.testing.assert_allclose(_share_behind_the_pane(runner, off, on, PANES["way_out"]), 1.0, rtol=0.06)


def test_a_pane_in_the_mirrors_light_moved_faded_or_removed_draws_what_a_fresh_engine_draws(scene):
    """The pane on the mirror's way out slides 0.6 m: the virtual light's map is drawn again, and
    the frame is the one an engine built with the pane there draws; its alpha goes from 0.6
    to 0.3, the same; then it is removed: the frame is one with no pane at all, and the
    virtual lights' see-through atlas is let go."""
    size = (240, 180)

    def engine(build):
        runner = scene(build, size)
        runner.engine.renderer.antialias = "off"
        runner.engine.renderer.shadows.filter = "single"
        return runner

    runner = engine(_one_mirror_with_pane(PANES["way_out"]))
    runner.frame()
    runner.frame()
    pane = runner.world.resources["ids"]["pane"]
    moved_to = PANES["way_out"] + np.array([-0.6, 0.0, 0.3])
    runner.world.get(pane, Transform).position = moved_to.tolist()
    moved = runner.frame()
    assert runner.stats.shadow_maps_drawn >= 1
    assert np.array_equal(moved, engine(_one_mirror_with_pane(moved_to)).frame())
    runner.world.get(pane, Material).color = (0.7, 0.8, 0.9, 0.3)
    faded = runner.frame()
    assert np.array_equal(faded, engine(_one_mirror_with_pane(moved_to, 0.3)).frame())
    runner.world.delete_entity(pane)
    gone = runner.frame()

    def bare(world):
        world.resources["ids"] = _scene(world)

    assert np.array_equal(gone, engine(bare).frame())
    assert runner.engine.renderer.shadows.virtual_see_through_atlas is None


def _twice_share_behind_a_pane(scene, centre: np.ndarray, where: str) -> np.ndarray:
    """The two-mirror scene with a see-through pane (alpha 0.6) at ``centre``: the
    twice-reflected light (the frame with two bounces less the one with one) on the floor
    where the way back from it crosses the pane, over where it does not, per channel (the
    medians); the way between the mirrors (``where`` "between"), or its line on past B
    ("beyond_b": behind B)."""
    def build(world):
        ids = _two_mirror_scene(world)
        ids["pane"] = world.spawn(Transform(position=centre.tolist()), MeshRef(plane(*(2 * PANE_HALF))),
                                  Material(color=(0.7, 0.8, 0.9, PANE_ALPHA)))
        world.resources["ids"] = ids

    runner, once, twice, _ = _bounce_frames(scene, build, size=(480, 360))
    ids = runner.world.resources["ids"]
    points = _floor_points(runner)
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    rays = rays.reshape(-1, 3)
    seen_through_pane = _pane_crossed(np.tile(eye, (len(points), 1)), rays, centre, 0.1,
                                      np.linalg.norm(points - eye, axis=1) / np.linalg.norm(rays, axis=1))
    floor = (runner.ids() == ids["floor"]).ravel() & ~_seen_in_a_mirror(runner).ravel() & ~seen_through_pane
    _, _, at_b, at_a = _twice_way(points)
    ones = np.ones(len(points))

    def crossed(grow):
        if where == "beyond_b":
            return _pane_crossed(at_b, at_b - at_a, centre, grow)
        return _pane_crossed(at_b, at_a - at_b, centre, grow, ones)

    lit = _twice_lit(points, 0.1) & floor
    behind, beside = lit & crossed(-0.1), lit & ~crossed(0.1)
    assert behind.sum() > 100 and beside.sum() > 500, (int(behind.sum()), int(beside.sum()))
    share = (srgb_to_linear(twice) - srgb_to_linear(once)).reshape(-1, 3)
    return np.median(share[behind], axis=0) / np.median(share[beside], axis=0)


def test_a_see_through_pane_between_two_mirrors_lets_through_its_share(scene):
    """A see-through pane (alpha 0.6) on the way from A to B (the middle stretch of A-through-B's
    way, drawn between both mirrors' planes: ``_LEG_SEE_THROUGH``): where the way back from the
    floor crosses it between the mirrors, the twice-reflected light is 1 - alpha of what it is
    beside."""
    ratio = _twice_share_behind_a_pane(scene, np.array([0.3, 3.2, 0.6]), "between")
    np.testing.assert_allclose(ratio, 1.0 - PANE_ALPHA, rtol=0.06)


def test_a_see_through_pane_behind_the_second_mirror_dims_no_light_off_both(scene):
    """The same pane behind B, low over the floor, on the line of the way from A to B carried
    on past B: the middle stretch's view of the sun's image looks through it towards the
    floor's image, and only B's plane (the stretch's second clip plane, ``leg_plane``) leaves
    it out; the light leaves B from its front, so the twice-reflected light where that line
    crosses the pane is what it is beside (with the plane left out: 1 - alpha)."""
    ratio = _twice_share_behind_a_pane(scene, np.array([-2.7, 0.2, 0.0]), "beyond_b")
    np.testing.assert_allclose(ratio, 1.0, rtol=0.06)


def test_a_pane_past_what_the_mirror_lights_dims_none_of_its_light_where_one_on_the_way_in_does(scene):
    """A lower sun (its way (1, -1/2, 0)) thrown by the mirror onto the wall's face, through a
    level pane (alpha 0.6) high over the hall on its way in, and a standing pane behind the
    wall (on the way out, past the face along the line): on the face the mirror's light is
    0.4 of what it is with the high pane casting nothing, and the pane behind the wall takes
    none of it, though the map's line through a point of the face meets both, the way-in
    pane nearer than the point (its stretches before the glass are kept apart from the last
    one's: shadows.glsl virtual_see_through_at)."""
    sun = np.array([1.0, -0.5, 0.0]) / np.sqrt(1.25)

    def build(reflects: bool, high_casts: bool, behind_casts: bool):
        def make(world):
            ids = _scene(world, sun=sun, reflects=reflects)
            for entity, _ in world.query_one(Camera):
                world.delete_entity(entity)
            look_from(world, (2.0, 1.5, 4.0), (-1.0, 0.8, 0.0))
            ids["high"] = world.spawn(Transform(position=(-1.5, 4.5, 0.0)), MeshRef(plane(7.0, 5.0),
                                      casts_shadows=high_casts), Material(color=(0.7, 0.8, 0.9, PANE_ALPHA)))
            facing_x = look_rotation(glm.vec3(-1, 0, 0))
            ids["behind"] = world.spawn(Transform(position=(-1.6, 1.25, 0.0), rotation=facing_x),
                                        MeshRef(quad(6.0, 2.5), casts_shadows=behind_casts),
                                        Material(color=(0.7, 0.8, 0.9, PANE_ALPHA), double_sided=True))
            world.resources["ids"] = ids
        return make

    frames = {}
    for name, how in (("off", (False, True, True)), ("both", (True, True, True)), ("high", (True, True, False)),
                      ("neither", (True, False, False))):
        runner = scene(build(*how), (320, 240))
        runner.engine.renderer.antialias = "off"
        runner.frame()
        frames[name] = srgb_to_linear(runner.frame()).mean(axis=-1)
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    t = (-1.0 - eye[0]) / rays[..., 0]
    at = eye + rays * t[..., None]   # where each ray meets the face's plane (x = -1)
    face = (runner.ids() == runner.world.resources["ids"]["wall"]) & (t > 0) & (at[..., 1] > 0.2) & \
        (at[..., 1] < 1.5) & (np.abs(at[..., 2] + 0.55) < 0.65)   # (short of the cube's shadow at z 0.3-0.9)
    assert face.sum() > 500, face.sum()
    light = {name: frames[name][face] - frames["off"][face] for name in ("both", "high", "neither")}
    assert np.median(light["neither"]) > 0.05, np.median(light["neither"])
    np.testing.assert_allclose(np.median(light["high"] / light["neither"]), 1.0 - PANE_ALPHA, rtol=0.06)
    np.testing.assert_allclose(np.median(light["both"] / light["high"]), 1.0, atol=0.02)
    assert np.abs(light["both"] - light["high"]).max() < 0.02


def test_a_see_through_pane_in_a_lamps_light_out_of_a_portal_lets_through_its_share(scene):
    """A lamp shines out of portal B (its image's map a perspective one, depths not linear in
    distance); a see-through pane (alpha 0.6) lies level beyond B, 0.5 m over the floor: where
    the line from the floor to the lamp's image crosses it, the image's light on the floor
    is 1 - alpha of what an engine whose pane casts nothing gives, pixel by pixel, and where
    it does not, the same."""
    lamp = np.array([0.0, 1.5, 5.5])
    centre = np.array([-3.8, 0.5, 0.2])

    def build(casts):
        def make(world):
            look_from(world, (-3.0, 7.0, 6.0), (-3.5, 0.0, 0.0))
            ids = world.resources["ids"] = {}
            ids["floor"] = world.spawn(Transform(), MeshRef(plane(20, 20)),
                                       Material(color=(0.8, 0.8, 0.8), roughness=1.0))
            world.spawn(Transform(position=lamp.tolist()), PointLight(intensity=20.0, range=14.0))
            ids["a"], ids["b"] = spawn_portal_pair(world, (0.0, 1.5, 4.0), None, (-6.0, 1.5, 0.0),
                                                   look_rotation(glm.vec3(-1, 0, 0)))
            world.get(ids["a"], Portal).carries_light = True
            world.spawn(Transform(position=centre.tolist()), MeshRef(plane(*(2 * PANE_HALF)), casts_shadows=casts),
                        Material(color=(0.7, 0.8, 0.9, PANE_ALPHA)))
        return make

    shares = []
    for casts in (True, False):
        runner = scene(build(casts), (320, 240))
        runner.engine.renderer.antialias = "off"
        portal = runner.world.get(runner.world.resources["ids"]["a"], Portal)
        portal.carries_light = False
        off = runner.frame()
        portal.carries_light = True
        on = runner.frame()
        assert runner.stats.virtual_lights == 1
        shares.append((srgb_to_linear(on) - srgb_to_linear(off)).mean(-1).reshape(-1))
    ids = runner.world.resources["ids"]
    carry = glm.dmat4(pair_transform(runner.world.get(ids["a"], Transform).world,
                                     runner.world.get(ids["b"], Transform).world))
    image = np.array(glm.dvec3(carry * glm.dvec4(*lamp, 1.0)))
    points = _floor_points(runner)
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    rays = rays.reshape(-1, 3)
    seen_through_pane = _pane_crossed(np.tile(eye, (len(points), 1)), rays, centre, 0.1,
                                      np.linalg.norm(points - eye, axis=1) / np.linalg.norm(rays, axis=1))
    lit = (runner.ids() == ids["floor"]).reshape(-1) & ~seen_through_pane & (shares[1] > 0.02)
    to_image = image - points

    def crossed(grow):
        return _pane_crossed(points, to_image, centre, grow, np.ones(len(points)))

    behind, beside = lit & crossed(-0.1), lit & ~crossed(0.1)
    assert behind.sum() > 300 and beside.sum() > 1000, (int(behind.sum()), int(beside.sum()))
    ratio = shares[0] / np.maximum(shares[1], 1e-6)
    assert abs(float(np.median(ratio[behind])) - (1.0 - PANE_ALPHA)) < 0.03, float(np.median(ratio[behind]))
    assert abs(float(np.median(ratio[beside])) - 1.0) < 0.01, float(np.median(ratio[beside]))


# --- a grazing sun through the mirror: its shadow edge stays put -------------------------------
# A sun 25 degrees up travelling +x meets a mirror at x = 2.2 (facing -x), which throws it back
# down towards -x onto a white floor under a black sky; a tall black wall at x = -3.6 keeps the
# sun itself off the floor from it to x = 1.5, so there only the mirror's light lands; a thin
# black slab 0.5 m up over 0 < x < 1.8 casts that light's shadow, a straight edge along z.
GRAZING_UP = np.radians(25.0)
GRAZING_SUN = np.array([np.cos(GRAZING_UP), -np.sin(GRAZING_UP), 0.0])
GRAZING_SLAB, GRAZING_SLAB_HALF = np.array([0.9, 0.5, 0.0]), np.array([0.9, 0.01, 2.0])
SUN_WALL, SUN_WALL_HALF = np.array([-3.6, 1.2, 0.0]), np.array([0.05, 1.2, 4.0])
GRAZING_MIRROR_X, GRAZING_MIRROR_Y, GRAZING_MIRROR_HALF = 2.2, 1.625, np.array([1.075, 2.0])   # half y, half z


def _grazing_mirror_frames(scene) -> dict:
    """The floor's light (linear green) with the mirror's light off, then on under the "grid"
    filter at the sun's softness 0, 1, 4 and 8 and under "single" (keys "off", 0.0, 1.0, 4.0,
    8.0, "single"), and on with the slab casting nothing ("open"); the floor's points and pixels;
    the ray-cast edge (float64 rays from the floor along the reflected light, back towards the
    mirror, against the slab); the virtual map's texel on the floor along x there (metres,
    from its matrix in the VirtualLights block) and where the map's texel lattice puts that
    edge, in those texels from it (a bilinear comparison's step lies on the texel boundary
    nearest the caster's silhouette: the midpoint of the texel centres astride it)."""
    back = -GRAZING_SUN * np.array([-1.0, 1.0, 1.0])   # from the floor towards the mirror
    xs = np.linspace(-3.0, 0.0, 30001)
    line = np.stack([xs, np.zeros_like(xs), np.zeros_like(xs)], axis=1)
    edge = float(xs[np.argmax(box_hits(line, np.tile(back, (len(xs), 1)), GRAZING_SLAB, GRAZING_SLAB_HALF))])

    def build(world):
        look_from(world, (edge - 1.5, 2.0, 2.0), (edge, 0.0, 0.0), fov=55.0)
        world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
        ids = world.resources["ids"] = {}
        ids["floor"] = world.spawn(Transform(), MeshRef(plane(12.0, 12.0)), Material(
            color=(1.0, 1.0, 1.0), roughness=1.0, environment_reflection=0.0))
        ids["slab"] = world.spawn(Transform(position=tuple(GRAZING_SLAB)), MeshRef(box(tuple(2.0 * GRAZING_SLAB_HALF))),
                                  Material(color=(0.0, 0.0, 0.0)))
        world.spawn(Transform(position=tuple(SUN_WALL)), MeshRef(box(tuple(2.0 * SUN_WALL_HALF))),
                    Material(color=(0.0, 0.0, 0.0)))
        ids["mirror"] = world.spawn(
            Transform(position=(GRAZING_MIRROR_X, GRAZING_MIRROR_Y, 0.0), rotation=look_rotation(glm.vec3(1, 0, 0))),
            MeshRef(quad(2 * GRAZING_MIRROR_HALF[1], 2 * GRAZING_MIRROR_HALF[0])), Material(),
            Mirror(reflects_light=True))
        ids["sun"] = world.spawn(DirectionalLight(direction=tuple(GRAZING_SUN), intensity=2.0))

    runner = scene(build, (128, 96))
    runner.engine.renderer.antialias = "off"
    ids = runner.world.resources["ids"]
    mirror, sun = runner.world.get(ids["mirror"], Mirror), runner.world.get(ids["sun"], DirectionalLight)
    slab = runner.world.get(ids["slab"], MeshRef)
    frames = {}
    for key in ("off", 0.0, 1.0, 4.0, 8.0, "single", "open"):
        mirror.reflects_light = key != "off"
        slab.casts_shadows = key != "open"
        sun.shadow_softness = 1.0 if isinstance(key, str) else key
        runner.engine.renderer.shadows.filter = "single" if key == "single" else "grid"
        runner.frame()
        frames[key] = srgb_to_linear(runner.frame())[..., 1]
        assert runner.stats.virtual_lights == (key != "off"), key
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    points = eye + rays * (-eye[1] / rays[..., 1])[..., None]
    shadows = runner.engine.renderer.shadows
    to_map = shadows.virtual_block[4:20].astype(np.float64).reshape(4, 4).T   # slot 0: world -> atlas uv

    def map_texels(point) -> np.ndarray:
        return (to_map @ np.array([*point, 1.0]))[:2] * shadows.virtual_atlas.size[0]

    way = (map_texels((edge + 1e-4, 0.0, 0.0)) - map_texels((edge, 0.0, 0.0))) / 1e-4   # texels per metre along x
    across = int(np.argmax(np.abs(way)))   # the map's axis the edge crosses (it runs along the other)
    silhouette = map_texels(GRAZING_SLAB + GRAZING_SLAB_HALF * np.array([-1.0, 1.0, 0.0]))[across]   # its top corner
    lattice = (np.floor(silhouette + 0.5) - map_texels((edge, 0.0, 0.0))[across]) / way[across]
    texel = 1.0 / float(np.linalg.norm(way))
    return {"frames": frames, "points": points, "floor": runner.ids() == ids["floor"],
            "edge": edge, "texel": texel, "lattice": float(lattice) / texel}


def test_a_grazing_sun_through_a_mirror_keeps_its_shadow_edge_whatever_the_softness(scene):
    """The mirror's image of a sun 25 degrees up casts the slab's shadow on the floor (the
    virtual map's texels 2.4 cm there), its edge filtered as the sun's shadow_softness says
    (``ShadowMaps.draw_virtual``'s row: it was 1 whatever the sun's): across the edge the
    image's light is the grid's profile at that softness (pcf_edge_profile: a mean miss of
    at most 0.0004 against 0.003 or more for any other of 0, 1, 4, 8).  The edge's place
    (where a step holding the same light would stand; the image's light alone, on less off,
    over the same with the slab casting nothing) is the same at softness 0, 1, 4 and 8
    (within 0.3 texel), within 2 texels of the float64 ray-cast edge and within 1.5 of where
    the map's texel lattice puts it (0.47 texel on), and the floor under the slab is dark:
    the lookup is pushed off the floor by (1.5 - n.l) texels, which moves the edge (1.5 -
    n.l) cos 25 = 0.98 texel into the shadow, and the taps follow the receiver's plane
    carried into the map, not a push as wide as the filter (measured 1.65 texels from the
    ray-cast edge at each softness and under "single"; the push (1 + softness)(1.5 - n.l)
    made them 1.65, 2.84, 6.45 and 11.3).  And no acne: the lit floor past the edge keeps
    0.97 of the image's light at each softness and under "single" (measured: all; the taps
    compared with a flat plane left 0.66 at softness 8)."""
    shot = _grazing_mirror_frames(scene)
    frames, points, floor, edge, texel = shot["frames"], shot["points"], shot["floor"], shot["edge"], shot["texel"]
    x, z = points[..., 0], points[..., 2]
    image_light = frames["open"] - frames["off"]
    assert 0.015 < texel < 0.04, texel
    near = floor & (np.abs(z) < 0.6) & (np.abs(x - edge) < 0.8)
    past = floor & (np.abs(z) < 0.5) & (x < edge - 0.6) & (x > edge - 2.0)
    assert near.sum() > 800 and past.sum() > 800, (near.sum(), past.sum())
    # Only the image lights the floor there (the wall keeps the sun off), and it lights it.
    assert frames["off"][near | past].max() < 0.005 and image_light[near | past].min() > 0.15
    for key in (0.0, 1.0, 4.0, 8.0, "single"):
        share = (frames[key][past] - frames["off"][past]) / image_light[past]
        assert share.min() > 0.97, (key, share.min())
    places = {}
    bins = np.arange(edge - 0.75, edge + 0.75 - 1e-9, 0.02)
    for key in (0.0, 1.0, 4.0, 8.0, "single"):
        share, xs = (frames[key][near] - frames["off"][near]) / image_light[near], x[near]
        means = np.array([share[(xs >= b) & (xs < b + 0.02)].mean() for b in bins])
        under = means[bins > edge + 0.5]   # 0.5 m on, well under the slab
        assert under.max() < 0.02, (key, under.max())
        # Where a step holding the same light would stand, into the shadow (+x) positive.
        places[key] = (bins[0] + 0.02 * float(np.sum(means)) - edge) / texel
    grid = [places[s] for s in (0.0, 1.0, 4.0, 8.0)]
    # The image's edges are as soft as the sun's softness says: the profile across the edge is
    # the grid's (pcf_edge_profile) at that softness, not another's.
    for softness in (0.0, 1.0, 4.0, 8.0):
        share, xs = (frames[softness][near] - frames["off"][near]) / image_light[near], x[near]
        t = places[softness] - (xs - edge) / texel   # map texels from the edge's middle, towards the light
        misses = {other: float(np.abs(share - pcf_edge_profile(t, other)).mean()) for other in (0.0, 1.0, 4.0, 8.0)}
        assert misses[softness] < 0.002 and min(v for k, v in misses.items() if k != softness) > 0.002, \
            (softness, misses)
    assert max(grid) - min(grid) < 0.3, places
    assert max(abs(p) for p in places.values()) < 2.0, places
    assert max(abs(p - shot["lattice"]) for p in places.values()) < 1.5, (places, shot["lattice"])


# A lamp 5 cm in front of a wide, low wall mirror (at x = 0, facing +x, 8 m along z, 1 m tall,
# centred 0.5 m up): its image's map opens no wider than VIRTUAL_MAX_FOV, so the floor along
# the wall, where the image's light comes in more than 85 degrees off the map's axis, lies
# past the map on both sides.
WIDE_LAMP = np.array([0.05, 0.5, 0.0])
WIDE_HALF = np.array([0.5, 4.0])   # the mirror's half height and half width


def _past_the_widest_angle(points: np.ndarray) -> np.ndarray:
    """Floor points whose line to the lamp's image comes in past VIRTUAL_MAX_FOV / 2 sideways."""
    from engine.rules.shadow_rules import VIRTUAL_MAX_FOV
    image = WIDE_LAMP * np.array([-1.0, 1.0, 1.0])
    d = points - image
    return np.abs(d[:, 2]) > np.tan(np.radians(VIRTUAL_MAX_FOV / 2.0)) * d[:, 0]


def test_a_lamp_by_a_wide_mirror_lights_the_floor_past_its_maps_widest_angle_on_both_sides(scene):
    """Past the map's widest angle nothing of the image's is shadowed (``virtual_shadow``
    takes a point outside the light's tile as unshadowed), whichever side: a lookup there
    read the next tile's texels on one side (another light's map, or texels no draw wrote:
    the test clears the whole atlas to the near depth first, as such texels may hold).  By
    the rays, with nothing in the way, every floor point in front of the mirror whose line to
    the image crosses its outline is lit by it."""
    def build(world):
        look_from(world, (1.0, 1.0, 0.0), (0.1, 0.0, 0.0), fov=110.0)
        ids = world.resources["ids"] = {}
        ids["floor"] = world.spawn(Transform(), MeshRef(plane(14, 14)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
        world.spawn(Transform(position=WIDE_LAMP.tolist()), PointLight(intensity=8.0, range=12.0))
        facing_plus_x = look_rotation(glm.vec3(-1, 0, 0))
        ids["mirror"] = world.spawn(Transform(position=(0.0, WIDE_HALF[0], 0.0), rotation=facing_plus_x),
                                    MeshRef(quad(2 * WIDE_HALF[1], 2 * WIDE_HALF[0])), Material(), Mirror())

    runner = scene(build, (320, 240))
    runner.engine.renderer.antialias = "off"
    mirror = runner.world.get(runner.world.resources["ids"]["mirror"], Mirror)
    mirror.reflects_light = False
    off = runner.frame()
    mirror.reflects_light = True
    runner.frame()   # (the virtual atlas made)
    maps = runner.engine.renderer.shadows
    on = drawn_over_near_depth(runner, maps.virtual_atlas, lambda shines: setattr(mirror, "reflects_light", shines))
    assert runner.stats.virtual_lights == 1
    points = _floor_points(runner)
    floor = (runner.ids() == runner.world.resources["ids"]["floor"]).reshape(-1)
    past = floor & _past_the_widest_angle(points) & (points[:, 0] > 0.02)
    ratio = (srgb_to_linear(on).mean(-1) / np.maximum(srgb_to_linear(off).mean(-1), 1e-6)).reshape(-1)
    # Where the image's light is bright enough to see in 8 bits (lights.glsl's falloff, the
    # cosine at the floor, a Lambertian 0.8): there it lights the floor by the rays.
    to_image = WIDE_LAMP * np.array([-1.0, 1.0, 1.0]) - points
    distance = np.linalg.norm(to_image, axis=1)
    fade = np.clip(1.0 - (distance / 12.0) ** 4, 0.0, 1.0)
    expected = 8.0 * fade * fade / (distance ** 2 + 1.0) * np.clip(to_image[:, 1] / distance, 0.0, 1.0) * 0.8 / np.pi
    lit = ratio > 1.05
    left, right = (past & (expected > 0.02) & side for side in (points[:, 2] < 0.0, points[:, 2] > 0.0))
    assert left.sum() > 300 and right.sum() > 300, (int(left.sum()), int(right.sum()))
    assert lit[left].mean() > 0.99 and lit[right].mean() > 0.99, (float(lit[left].mean()), float(lit[right].mean()))
    # The tile drawn again holds the far depth in its gutter round the map, the floor in the
    # map, and left the rest of the atlas as it was.
    from engine.render.shadows import VIRTUAL_GUTTER, VIRTUAL_RESOLUTION, VIRTUAL_TILE
    side = maps.virtual_atlas.size[0]
    assert side == 2 * VIRTUAL_TILE
    depth = np.frombuffer(maps.virtual_atlas.read(), np.float32).reshape(side, side)
    tile = depth[:VIRTUAL_TILE, :VIRTUAL_TILE]
    inner = slice(VIRTUAL_GUTTER, VIRTUAL_GUTTER + VIRTUAL_RESOLUTION)
    ring = np.ones(tile.shape, bool)
    ring[inner, inner] = False
    assert (tile[ring] == 1.0).all()
    assert (tile[inner, inner] < 1.0).mean() > 0.3   # the floor (half the map looks down at it)
    assert (depth[VIRTUAL_TILE:, :] == 0.0).all() and (depth[:, VIRTUAL_TILE:] == 0.0).all()
    # The filter's widest reach from a point just inside the map stays in the gutter.
    from components.camera import MAX_SHADOW_SOFTNESS
    assert MAX_SHADOW_SOFTNESS / 2.0 + 1.0 <= VIRTUAL_GUTTER
