"""System tests of portal views: what a portal shows, recursion, fill, composition with mirrors."""
from __future__ import annotations

import numpy as np
from pyglm import glm

from components import (
    DirectionalLight,
    Emissive,
    Material,
    MeshRef,
    Mirror,
    Portal,
    Skybox,
    Transform,
)
from engine.assets.mesh import box, plane, quad
from engine.assets.portals import spawn_portal_pair
from engine.assets.texture_data import checker_texture
from engine.render.sky import sky_radiance
from engine.rules.light_rules import SkySun
from tests.support import box_hits, look_from, pixel_rays, srgb_to_linear

SIZE = (200, 150)
TURN_Y_90 = glm.angleAxis(glm.radians(90), glm.vec3(0, 1, 0))
HALF_TURN = glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))


SUN_LIGHT = (0.3, -1.0, -0.4)  # the way the sun's light travels: the sky's sun stands against it
SKY_SUN = SkySun(tuple(-glm.normalize(glm.vec3(SUN_LIGHT))))


def lit(world):
    world.spawn(Skybox())
    world.spawn(DirectionalLight(direction=SUN_LIGHT, intensity=2.0))


def glowing_box(world, position, color, size=0.6):
    return world.spawn(Transform(position=position, scale=(size, size, size)), MeshRef(box()), Material(color=color),
                       Emissive(1.0))


def test_box_beyond_the_look_out_portal_shows_where_the_math_says(scene):
    ents = {}

    def build(world):
        lit(world)
        look_from(world, (0.5, 1.6, 6.0), (0, 1.5, 0))
        # A at the origin facing +Z; B at x = 10 facing +X (turned 90 degrees about Y).
        ents["a"], ents["b"] = spawn_portal_pair(world, (0, 1.5, 0), None, (10, 1.5, 0), TURN_Y_90)
        ents["green"] = glowing_box(world, (13.0, 1.2, 0.4), (0.1, 0.9, 0.1))      # in front of B
        ents["magenta"] = glowing_box(world, (8.5, 1.5, 0.0), (0.9, 0.1, 0.9))     # between B and the virtual eye

    runner = scene(build, SIZE)
    rgb = runner.frame()
    # By hand: B's front is +X; a point d in front of B and s to B's right maps to d in
    # front of A... A's front is +Z, seen through from its front, so green at B + (3, -0.3, 0.4)
    # appears as if at A + (0.4 * -1 ..): carry^-1 of (13, 1.2, 0.4) = (0.4, 1.2, -3.0).
    col, row = runner.project((0.4, 1.2, -3.0))
    assert runner.ids()[row, col] == ents["green"]
    r, g, b = rgb[row, col].astype(int)
    assert g > 120 and g > r + 60 and g > b + 60
    assert ents["magenta"] not in runner.ids()  # behind the look-out plane: never through the portal
    view = runner.engine.reflection_system.views[1]
    assert view.surface.kind == "portal" and not view.view.mirrored


def test_a_portal_scaled_2_shows_its_side_at_half_size_where_the_math_says(scene):
    """B scaled 2 by its Transform (4 x 6 m): through A, B's side is carried back by the
    pair's inverse, so a box 1.2 m across 3 m in front of B shows as one 0.6 m across 1.5 m
    behind A, where carry^-1 puts it: its centre is the box, a point 0.45 m off it is not
    (it would be, at the box's own size)."""
    ents = {}

    def build(world):
        lit(world)
        look_from(world, (0.5, 1.6, 6.0), (0, 1.5, 0))
        ents["a"], ents["b"] = spawn_portal_pair(world, (0, 1.5, 0), None, (10, 1.5, 0), TURN_Y_90)
        world.get(ents["b"], Transform).scale = glm.vec3(2.0)
        ents["green"] = glowing_box(world, (13.0, 1.5, 0.4), (0.1, 0.9, 0.1), size=1.2)

    runner = scene(build, SIZE)
    runner.frame()
    ids = runner.ids()
    # By hand: B-local (x right, z out of B's front +X) of (13, 1.5, 0.4) is (-0.2, 0, 1.5) at
    # scale 2; out of A's front side that is A-local (0.2, 0, -1.5): behind A, half as far.
    centre = glm.vec3(0.2, 1.5, -1.5)
    a_world, b_world = (glm.dmat4(runner.world.get(ents[e], Transform).world) for e in "ab")
    carry = b_world * glm.dmat4(glm.rotate(glm.pi(), glm.vec3(0, 1, 0))) * glm.inverse(a_world)
    np.testing.assert_allclose(glm.dvec3(carry * glm.dvec4(glm.dvec3(centre), 1.0)), (13.0, 1.5, 0.4), atol=1e-5)
    col, row = runner.project(centre)
    assert ids[row, col] == ents["green"]
    for offset in ((0.2, 0.0, 0.0), (0.0, 0.2, 0.0)):   # within the half-size box's 0.3 half side
        col, row = runner.project(centre + glm.vec3(offset))
        assert ids[row, col] == ents["green"], offset
    for offset in ((0.45, 0.0, 0.0), (0.0, 0.45, 0.0), (0.0, -0.45, 0.0)):   # past it, within the box's own 0.6
        col, row = runner.project(centre + glm.vec3(offset))
        assert ids[row, col] != ents["green"], offset


def test_facing_portals_recurse_to_max_depth_then_fill(scene):
    def build(world):
        lit(world)
        look_from(world, (0.0, 1.5, 2.5), (0, 1.5, 0))
        spawn_portal_pair(world, (0, 1.5, 0), None, (0, 1.5, 5), HALF_TURN, size=(2.0, 2.0), max_depth=4)
        for x in (-1.5, 1.5):  # posts beside A, so each nested image has something in it
            glowing_box(world, (x, 1.5, 0.0), (0.9, 0.6, 0.1), size=0.5)

    runner = scene(build, SIZE)
    rgb = runner.frame()
    views = runner.engine.reflection_system.views[1:]
    assert len(views) == 4 and [v.level for v in views] == [1, 2, 3, 4]
    areas = [w * h for _, _, w, h in (v.rect for v in views)]
    assert all(a > b for a, b in zip(areas, areas[1:], strict=False))
    # Past the limit, on the first frame (no image of the pair from before), the innermost
    # portal shows its fallback: the sky along the carried ray (issue 36; the pair's carry
    # turns no direction, so the centre's ray, straight down -Z), not its closed colour;
    # later frames end in last frame's image (tests/test_end_images.py).
    cx, cy = SIZE[0] // 2, SIZE[1] // 2
    inverse = glm.inverse(runner.engine.main_view.view_proj)
    ndc = glm.vec4((cx + 0.5) / SIZE[0] * 2 - 1, 1 - (cy + 0.5) / SIZE[1] * 2, 1.0, 1.0)
    far = inverse * ndc
    ray = np.array(glm.vec3(far) / far.w - glm.vec3(0.0, 1.5, 2.5))  # (the sky is steep about the horizon)
    sky = sky_radiance(Skybox(), ray, sun=SKY_SUN)
    # (Within the sky cube's texels against the formula, where it changes fastest: at the horizon.)
    np.testing.assert_allclose(srgb_to_linear(rgb[cy, cx]), sky, atol=0.025)
    assert np.abs(sky - np.array(Portal().closed_color)[:3]).max() > 0.2
    # Eight levels work too.
    for _, portal in runner.world.query_one(Portal):
        portal.max_depth = 8
    runner.engine.reflection_system.max_depth_cap = 8
    runner.frame()
    assert runner.stats.reflection_views == 8 and runner.stats.reflection_end_views >= 1
    assert len(runner.engine.renderer.levels) == 10  # the root's, eight levels', the end image's


def test_deleting_one_portal_closes_the_other_and_keeps_running(scene):
    ents = {}

    def build(world):
        lit(world)
        look_from(world, (0.0, 1.5, 5.0), (0, 1.5, 0))
        ents["a"], ents["b"] = spawn_portal_pair(world, (0, 1.5, 0), None, (10, 1.5, 0), TURN_Y_90)

    runner = scene(build, SIZE)
    runner.frame()
    assert runner.stats.reflection_views == 1
    runner.world.delete_entity(ents["b"])
    rgb = runner.frame()
    assert runner.stats.reflection_views == 0
    col, row = runner.project((0.2, 1.5, 0.0))
    assert runner.ids()[row, col] == ents["a"]
    np.testing.assert_allclose(srgb_to_linear(rgb[row, col]), np.array(Portal().closed_color)[:3], atol=0.01)
    runner.frame()


def test_a_mirror_seen_through_a_portal_and_a_portal_seen_in_a_mirror(scene):
    ents = {}

    def build(world):
        lit(world)
        look_from(world, (0.0, 1.5, 6.0), (0, 1.5, 0))
        ents["a"], ents["b"] = spawn_portal_pair(world, (0, 1.5, 0), None, (20, 1.5, 0), None)
        # Beyond B (in front of it, +Z): a mirror facing back at B, and a red box beside B that
        # only the mirror shows from where the portal's view stands.
        ents["mirror"] = world.spawn(Transform(position=(20, 1.5, 6), rotation=HALF_TURN), MeshRef(quad(6, 4)),
                                     Material(color=(0.1, 0.1, 0.1)), Mirror())
        ents["red"] = glowing_box(world, (21.5, 1.5, 1.0), (0.9, 0.1, 0.1))

    runner = scene(build, SIZE)
    runner.frame()
    kinds = [(v.level, v.surface.kind) for v in runner.engine.reflection_system.views[1:]]
    assert (1, "portal") in kinds and (2, "mirror") in kinds
    assert ents["red"] in runner.ids()  # the red box, seen in the mirror, seen through the portal
    # By hand: the box's mirror image is at (21.5, 1.5, 11); back through the pair (minus B,
    # half turn about Y, plus A) that is (-1.5, 1.5, -11) as seen through A.
    col, row = runner.project((-1.5, 1.5, -11.0))
    assert runner.ids()[row, col] == ents["red"]


def test_a_portal_seen_in_a_mirror(scene):
    ents = {}

    def build(world):
        lit(world)
        look_from(world, (0.3, 1.5, 4.0), (0, 1.5, 0))
        world.spawn(Transform(position=(0, 1.5, 0)), MeshRef(quad(6, 4)), Material(color=(0.1, 0.1, 0.1)), Mirror())
        # A behind the camera, facing the mirror; B far away; a green box in front of B.
        ents["a"], ents["b"] = spawn_portal_pair(world, (0, 1.5, 8), HALF_TURN, (20, 1.5, 0), None, size=(3, 3))
        ents["green"] = glowing_box(world, (20.3, 1.5, 3.0), (0.1, 0.9, 0.1))

    runner = scene(build, SIZE)
    runner.frame()
    kinds = [(v.level, v.surface.kind) for v in runner.engine.reflection_system.views[1:]]
    assert kinds[:2] == [(1, "mirror"), (2, "portal")]
    # By hand: green is B + (0.3, 0, 3); back through the pair (minus B, half turn, then A's
    # own half turn, plus A) that is A + (0.3, 0, 3) = (0.3, 1.5, 11), behind A as seen from
    # its front; the mirror at z = 0 shows that at (0.3, 1.5, -11).
    col, row = runner.project((0.3, 1.5, -11.0))
    assert runner.ids()[row, col] == ents["green"]


def test_sharp_rough_and_portal_views_in_one_level_composite_as_they_do_alone(scene):
    """One level holding all three composite variants (mirror_composite.frag: sharp mirror,
    rough mirror, portal), drawn as separate groups: each surface's pixels must be what they
    are when it is the only surface in the level."""
    def build(world):
        lit(world)
        look_from(world, (0.0, 2.2, 5.0), (0.0, 1.2, -2.0))
        world.spawn(Transform(), MeshRef(plane(80, 20, uv_repeat=20)), Material(texture=checker_texture(64, 8)))
        world.spawn(Transform(position=(-2.2, 1.5, -2.0)), MeshRef(quad(1.8, 2.0)), Material(color=(0.1, 0.1, 0.1)),
                    Mirror())
        world.spawn(Transform(position=(0.0, 1.5, -2.0)), MeshRef(quad(1.8, 2.0)), Material(color=(0.1, 0.1, 0.1)),
                    Mirror(roughness=0.4))
        spawn_portal_pair(world, (2.2, 1.5, -2.0), None, (30.0, 1.5, 0.0), HALF_TURN, size=(1.8, 2.0))
        for x, color in ((-2.2, (0.9, 0.1, 0.1)), (0.0, (0.1, 0.2, 0.9))):
            glowing_box(world, (x, 0.5, -0.8), color)
        glowing_box(world, (30.0, 1.5, -3.0), (0.1, 0.9, 0.2))  # beyond the look-out portal

    def surfaces(runner):
        world = runner.world
        mirrors = sorted(e for e, _ in world.query_one(Mirror))
        portals = sorted(e for e, _ in world.query_one(Portal))
        return {"sharp": [mirrors[0]], "rough": [mirrors[1]], "portal": portals}

    runner = scene(build, SIZE)
    mixed = runner.frame().astype(int)
    owner = runner.engine.renderer.targets.read_surface_ids()
    groups = surfaces(runner)
    level_one = {view.surface.entity for view in runner.engine.reflection_system.views if view.level == 1}
    assert {groups["sharp"][0], groups["rough"][0], groups["portal"][0]} <= level_one
    for kind, keep in groups.items():
        alone = scene(build, SIZE)
        for other, entities in groups.items():
            if other != kind:
                for entity in entities:
                    alone.world.delete_entity(entity)
        single = alone.frame().astype(int)
        assert {v.surface.entity for v in alone.engine.reflection_system.views if v.level == 1} == {keep[0]}
        pixels = owner == keep[0]
        assert pixels.sum() > 500, kind
        assert np.abs(mixed[pixels] - single[pixels]).max() <= 2, kind
        assert mixed[pixels].std() > 5, kind  # a reflection or a view, not a flat fill


def test_looking_into_the_portal_scaled_2_shows_the_other_side_at_twice_its_size_where_rays_say(scene):
    """B scaled 2 by its Transform, seen from in front of B: through it, A's side is carried
    out by the pair's carry, so it shows at twice its size.  Each pixel of B's picture is
    checked against its ray carried back to A's side (carry^-1, float64) and cast at a green
    box in front of A: the box where the ray meets it (a margin in), not where it misses (a
    margin out).  At A's own scale (the carry without B's scale) the rays would find it in
    under half of those pixels, mostly elsewhere."""
    ents = {}
    size = (160, 120)

    def build(world):
        lit(world)
        look_from(world, (15.0, 1.7, 0.8), (10.0, 1.5, 0.0))
        ents["a"], ents["b"] = spawn_portal_pair(world, (0, 1.5, 0), None, (10, 1.5, 0), TURN_Y_90)
        world.get(ents["b"], Transform).scale = glm.vec3(2.0)
        ents["green"] = glowing_box(world, (0.8, 1.5, 1.5), (0.1, 0.9, 0.1), size=0.8)

    runner = scene(build, size)
    runner.frame()
    ids = runner.ids()
    on_b = runner.engine.renderer.targets.read_surface_ids() == ents["b"]
    assert on_b.sum() > 3000 and runner.stats.reflection_views >= 1
    a_world, b_world = (np.array(glm.dmat4(runner.world.get(ents[e], Transform).world).to_list()).T for e in "ab")
    turn = np.array(glm.dmat4(glm.rotate(glm.pi(), glm.vec3(0, 1, 0))).to_list()).T
    eye, rays = pixel_rays(runner.engine.main_view, size)
    centre, half = np.array([0.8, 1.5, 1.5]), np.full(3, 0.4)

    def hits(carry, grow):
        back = np.linalg.inv(carry)
        origin = back[:3, :3] @ eye + back[:3, 3]
        directions = rays[on_b] @ back[:3, :3].T
        return box_hits(origin, directions, centre, half + grow)

    carry = b_world @ turn @ np.linalg.inv(a_world)
    inside, outside = hits(carry, -0.03), ~hits(carry, 0.03)
    shown = ids[on_b] == ents["green"]
    assert inside.sum() > 300
    assert shown[inside].all(), int((~shown[inside]).sum())
    assert not shown[outside].any(), int(shown[outside].sum())
    unscaled = b_world @ np.diag([0.5, 0.5, 0.5, 1.0]) @ turn @ np.linalg.inv(a_world)
    at_own_scale = hits(unscaled, 0.0)  # (llvmpipe: 196 pixels, 98 of them green, against 574 green)
    assert at_own_scale.sum() < 0.5 * inside.sum() and (at_own_scale & shown).sum() < 0.5 * shown.sum()
