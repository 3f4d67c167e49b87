"""The rules every system shares (engine/rules/frame_rules.py): which portal pairs are open, the
active camera, a mesh's world corners.

Scene tests render real frames: portal A at (-3, 1.5, 0) and B at (3, 1.5, 0), both facing
+Z, so by hand the pair carries A + (x, y, z) to B + (-x, y, -z) (a half turn about up).
The camera looks straight into A from 6 m in front; a green box at B + (0, 0, 3) is seen
through A at A + (0, 0, -3), the middle of the picture, and nowhere else.  A walker (a
Traveller with no mesh) steps through A in one frame; a bar (a Traveller with a mesh)
stands half through A's lower left.  Each way of closing the pair must close it for the
picture, travel and slicing alike, and the open pair must do all three.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    DirectionalLight,
    Emissive,
    Material,
    MeshRef,
    Portal,
    PortalClone,
    Skybox,
    Slice,
    Transform,
    Traveller,
)
from engine.assets.mesh import box
from engine.assets.portals import spawn_portal_pair
from engine.core.world import World
from engine.resources import PortalCrossings
from engine.rules.frame_rules import FrameRules, active_camera, frame_rules, open_portal_pairs, world_corners
from shell.capture import export_scene
from tests.support import look_from, srgb_to_linear

SIZE = (160, 120)
A_POS, B_POS = (-3.0, 1.5, 0.0), (3.0, 1.5, 0.0)
GREEN_AT = (3.0, 1.5, 3.0)          # B + (0, 0, 3)
GREEN_SEEN_AT = (-3.0, 1.5, -3.0)   # A + (0, 0, -3): where it shows through A
CLOSED = (0.5, 0.2, 0.05, 1.0)      # A's closed colour: nothing else in the scene is this orange
WALKER_FROM = (-2.4, 2.5, 0.05)     # A + (0.6, 1.0, 0.05): 5 cm in front of A, inside its rectangle
WALKER_SPEED = 6.0                  # m/s towards -Z: 10 cm a frame at 60 fps, through A in one frame


def carry(point) -> glm.vec3:
    """A + (x, y, z) -> B + (-x, y, -z), worked out by hand (not with portal_math)."""
    x, y, z = (point[i] - A_POS[i] for i in range(3))
    return glm.vec3(B_POS[0] - x, B_POS[1] + y, B_POS[2] - z)


def build(world: World, ents: dict) -> None:
    world.spawn(Skybox())
    world.spawn(DirectionalLight(direction=(0.3, -1.0, -0.4), intensity=2.0))
    ents["camera"] = look_from(world, (-3.0, 1.5, 6.0), (-3.0, 1.5, 0.0))
    ents["a"], ents["b"] = spawn_portal_pair(world, A_POS, None, B_POS, None)
    world.get(ents["a"], Portal).closed_color = CLOSED
    ents["green"] = world.spawn(Transform(position=GREEN_AT, scale=(0.6, 0.6, 0.6)), MeshRef(box()),
                                Material(color=(0.1, 0.9, 0.1)), Emissive(1.0))
    # x -3.8..-3.4, y 0.3..0.7, z -1..1: through A's plane inside its rectangle (x -4..-2, y 0..3).
    ents["bar"] = world.spawn(Transform(position=(-3.6, 0.5, 0.0)), MeshRef(box((0.4, 0.4, 2.0))),
                              Material(color=(0.9, 0.5, 0.1)), Emissive(1.0), Traveller())


def new_walker(runner, ents: dict) -> None:
    """A fresh walker 5 cm in front of A (a fresh entity: travel judges a step from where the
    entity was at the end of the last frame, so moving an old one back would be a long step)."""
    if "walker" in ents:
        runner.world.delete_entity(ents["walker"])
    ents["walker"] = runner.world.spawn(Transform(position=WALKER_FROM), Traveller(velocity=(0, 0, -WALKER_SPEED)))


def frame_with_walker(runner, ents: dict) -> np.ndarray:
    new_walker(runner, ents)
    return runner.frame(1.0 / 60.0)


def assert_open(runner, ents: dict, rgb: np.ndarray) -> None:
    world = runner.world
    col, row = runner.project(GREEN_SEEN_AT)
    assert runner.ids()[row, col] == ents["green"]                     # the view through A
    r, g, b = rgb[row, col].astype(int)
    assert g > 120 and g > r + 60 and g > b + 60
    crossings = list(world.resources[PortalCrossings])                  # travel
    assert [(c.entity, c.from_portal, c.to_portal) for c in crossings] == [(ents["walker"], ents["a"], ents["b"])]
    walker_at = world.get(ents["walker"], Transform).position
    expected = carry((WALKER_FROM[0], WALKER_FROM[1], WALKER_FROM[2] - WALKER_SPEED / 60.0))
    assert glm.length(walker_at - expected) < 1e-4
    assert world.get(ents["bar"], Slice).plane == glm.vec4(0, 0, 1, 0)  # slice: A's front kept
    (clone, found), = world.query_one(PortalClone)
    assert found.source == ents["bar"] and found.portal == ents["a"]
    # The clone stands where the bar is, carried by hand: bar centre A + (-0.6, -1, 0).
    assert glm.length(world.get(clone, Transform).position - carry((-3.6, 0.5, 0.0))) < 1e-4


def assert_closed(runner, ents: dict, rgb: np.ndarray) -> None:
    world = runner.world
    col, row = runner.project(GREEN_SEEN_AT)
    assert runner.ids()[row, col] == ents["a"]                          # A's own flat quad
    np.testing.assert_allclose(srgb_to_linear(rgb[row, col]), CLOSED[:3], atol=0.01)
    assert ents["green"] not in runner.ids()
    assert list(world.resources[PortalCrossings]) == []                  # no travel
    walker_at = world.get(ents["walker"], Transform).position            # just walked on, behind A
    assert glm.length(walker_at - glm.vec3(WALKER_FROM[0], WALKER_FROM[1], WALKER_FROM[2] - WALKER_SPEED / 60)) < 1e-5
    assert not world.has(ents["bar"], Slice)                             # no slice
    assert world.query_one(PortalClone) == []


def close_partner_disabled(world, ents):
    world.get(ents["b"], Portal).enabled = False


def reopen_partner_disabled(world, ents):
    world.get(ents["b"], Portal).enabled = True


def close_partner_transform_removed(world, ents):
    world.remove_component(ents["b"], Transform)


def reopen_partner_transform_removed(world, ents):
    world.add_component(ents["b"], Transform(position=B_POS))


def close_partner_deleted(world, ents):
    world.delete_entity(ents["b"])


def close_portal_disabled(world, ents):
    world.get(ents["a"], Portal).enabled = False


def reopen_portal_disabled(world, ents):
    world.get(ents["a"], Portal).enabled = True


def close_partner_mirrored_by_its_parent(world, ents):
    """B put below a parent whose scale mirrors x, at the same place (the parent's -x of B's x):
    a pair cannot carry a mirror image, so the rules close it (``mirrored_by_parents``)."""
    ents["mirroring"] = world.spawn(Transform(scale=(-1.0, 1.0, 1.0)))
    b = world.get(ents["b"], Transform)
    b.parent, b.position = ents["mirroring"], (-B_POS[0], B_POS[1], B_POS[2])


def reopen_partner_mirrored_by_its_parent(world, ents):
    world.get(ents["mirroring"], Transform).scale = (1.0, 1.0, 1.0)  # the parent turned back: B at -3 now
    world.get(ents["b"], Transform).position = B_POS


CASES = {
    "partner disabled": (close_partner_disabled, reopen_partner_disabled),
    "partner mirrored by its parent": (close_partner_mirrored_by_its_parent, reopen_partner_mirrored_by_its_parent),
    "partner without Transform": (close_partner_transform_removed, reopen_partner_transform_removed),
    "partner deleted": (close_partner_deleted, None),
    "portal itself disabled": (close_portal_disabled, reopen_portal_disabled),
}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.filterwarnings("ignore:Portal on entity .* its parents' Transform.scale mirror it")  # (said: its own test)
def test_a_closed_pair_is_closed_in_every_system_and_reopens_the_next_frame(scene, case):
    close, reopen = CASES[case]
    ents: dict = {}
    runner = scene(lambda world: build(world, ents), SIZE)
    assert_open(runner, ents, frame_with_walker(runner, ents))   # the scene does show all three open

    close(runner.world, ents)
    assert_closed(runner, ents, frame_with_walker(runner, ents))
    assert_closed(runner, ents, frame_with_walker(runner, ents))  # and stays so, frame after frame

    # The picture is that of the same scene whose portal never had a partner.
    never: dict = {}

    def no_partner(world):
        build(world, never)
        world.get(never["a"], Portal).partner = None

    reference = scene(no_partner, SIZE)
    reference.frame()
    new_walker(reference, never)
    expected = reference.frame()
    rgb = runner.frame()
    assert ents["a"] == never["a"] and ents["green"] == never["green"]
    np.testing.assert_array_equal(runner.ids(), reference.ids())
    assert np.abs(rgb.astype(int) - expected.astype(int)).max() <= 2

    if reopen is not None:
        reopen(runner.world, ents)
        assert_open(runner, ents, frame_with_walker(runner, ents))


def test_export_names_a_partner_only_for_an_open_pair(scene, tmp_path):
    ents: dict = {}
    runner = scene(lambda world: build(world, ents), SIZE)
    runner.frame()

    def exported() -> dict:
        path = export_scene(runner.world, tmp_path / "scene.glb", ents["camera"], SIZE)
        return json.loads(path.with_suffix(".json").read_text())["portals"]

    assert exported()[str(ents["a"])]["partner"] == ents["b"]
    runner.world.get(ents["b"], Portal).enabled = False  # between frames: export sees it at once
    portals = exported()
    assert portals[str(ents["a"])] == {"partner": None, "to_partner": None}
    assert portals[str(ents["b"])] == {"partner": None, "to_partner": None}


def test_the_rules_stage_publishes_this_frames_answers(scene):
    ents: dict = {}
    runner = scene(lambda world: build(world, ents), SIZE)
    runner.frame()
    published = runner.world.resources[FrameRules]
    assert dict(published.open_portals) == {ents["a"]: ents["b"], ents["b"]: ents["a"]}
    assert published.active_camera == ents["camera"]
    # Read in a later frame (here: between frames, after a change) they are worked out again.
    runner.world.get(ents["b"], Portal).enabled = False
    assert dict(frame_rules(runner.world).open_portals) == {}
    assert dict(runner.world.resources[FrameRules].open_portals) != {}  # the old frame's, not used


# --- the rules by hand, on a bare world -----------------------------------------------------------
@pytest.fixture
def world():
    w = World("rules-test")
    yield w
    w.close()


def portal_entity(world: World, partner=None, transform=True, enabled=True) -> int:
    components = [Portal(partner=partner, enabled=enabled)]
    if transform:
        components.append(Transform())
    return world.spawn(*components)


def pair_up(world: World, **b_options) -> tuple[int, int]:
    a = portal_entity(world)
    b = portal_entity(world, partner=a, **b_options)
    world.get(a, Portal).partner = b
    return a, b


def test_open_portal_pairs_by_hand(world):
    a, b = pair_up(world)
    assert open_portal_pairs(world) == {a: b, b: a}

    # One-way: C looks out of A, A still looks out of B (the partner need not name it back).
    c = portal_entity(world, partner=a)
    assert open_portal_pairs(world) == {a: b, b: a, c: a}

    world.get(b, Portal).enabled = False           # partner disabled: A closed; B itself disabled
    assert open_portal_pairs(world) == {c: a}
    world.get(b, Portal).enabled = True
    world.get(a, Portal).enabled = False           # portal disabled: A closed, and B and C look at a disabled A
    assert open_portal_pairs(world) == {}
    world.get(a, Portal).enabled = True

    world.remove_component(b, Transform)           # partner without a Transform; B itself has none
    assert open_portal_pairs(world) == {c: a}
    world.add_component(b, Transform())
    assert open_portal_pairs(world) == {a: b, b: a, c: a}

    world.get(c, Portal).partner = 9999            # partner that never existed
    assert open_portal_pairs(world) == {a: b, b: a}
    plain = world.spawn(Transform())               # partner without a Portal
    world.get(c, Portal).partner = plain
    assert open_portal_pairs(world) == {a: b, b: a}

    world.delete_entity(b)                         # partner deleted (gone at once, before the next step)
    assert open_portal_pairs(world) == {}


def test_a_partner_needs_a_portal_not_just_a_transform(world):
    a = portal_entity(world)
    plain = world.spawn(Transform())
    world.get(a, Portal).partner = plain
    assert open_portal_pairs(world) == {}


def test_a_portal_paired_with_itself_is_closed(world):
    """Portal refuses its own id as partner; the rule still holds if a write goes around that
    check (as code setting dataclass fields directly could)."""
    a = portal_entity(world)
    object.__setattr__(world.get(a, Portal), "partner", a)
    assert open_portal_pairs(world) == {}


def test_a_portal_without_a_transform_is_closed_and_closes_its_partner(world):
    a, b = pair_up(world, transform=False)
    assert open_portal_pairs(world) == {}


def test_active_camera_is_the_lowest_active_camera_with_a_transform(world):
    assert active_camera(world) is None
    inactive = world.spawn(Transform(), Camera(active=False))
    assert active_camera(world) is None
    world.spawn(Camera())                          # active but with no Transform: cannot be looked through
    assert active_camera(world) is None
    third = world.spawn(Transform(), Camera())
    fourth = world.spawn(Transform(), Camera())
    assert active_camera(world) == third
    world.get(third, Camera).active = False
    assert active_camera(world) == fourth
    world.get(inactive, Camera).active = True
    assert active_camera(world) == inactive
    world.delete_entity(inactive)
    assert active_camera(world) == fourth


def test_world_corners_by_hand():
    # Bounds (-1, -2, -3)..(1, 2, 3); model: a quarter turn about +Y, then 10 along x.  A turn
    # of 90 degrees about Y takes (x, y, z) to (z, y, -x), so a corner lands at (10 + z, y, -x).
    model = glm.translate(glm.vec3(10, 0, 0)) * glm.rotate(glm.radians(90.0), glm.vec3(0, 1, 0))
    corners = world_corners(box((2.0, 4.0, 6.0)), model)
    expected = [  # corner order: x outer, then y, then z
        (7, -2, 1), (13, -2, 1),    # (-1, -2, -3), (-1, -2, 3)
        (7, 2, 1), (13, 2, 1),      # (-1, 2, -3), (-1, 2, 3)
        (7, -2, -1), (13, -2, -1),  # (1, -2, -3), (1, -2, 3)
        (7, 2, -1), (13, 2, -1),    # (1, 2, -3), (1, 2, 3)
    ]
    assert corners.shape == (8, 4) and corners.dtype == np.float64
    np.testing.assert_allclose(corners[:, :3], expected, atol=1e-6)
    np.testing.assert_allclose(corners[:, 3], 1.0)


# --- a pair scaled unevenly by its Transforms ------------------------------------------------------
def test_a_pair_scaled_unevenly_is_open_and_its_view_shows_what_its_carried_rays_meet(scene):
    """B scaled (2, 1, 0.5) by its Transform (twice as wide, as tall, half as deep along its
    facing): the pair is open (no rule refuses it: portal_math.even_scale says it scales
    unevenly, and its carry is applied as it is), and its view, drawn without a GL error (the
    suite's fixture checks), shows through B what each pixel's ray carried back through the
    pair (carry^-1 in float64: stretched twice across, squeezed along the facing) meets: a
    green box in front of A where the ray meets it (a margin in), nowhere it misses (a margin
    out).  Carried as by B scaled 2 every way, the rays would miss a third of those or more."""
    from engine.core.portal_math import even_scale
    from tests.support import box_hits, pixel_rays
    from tests.test_portal_views import TURN_Y_90, glowing_box, lit

    ents = {}
    size = (96, 72)

    def build(world):
        lit(world)
        look_from(world, (15.0, 1.7, 0.8), (10.0, 1.5, 0.0))
        ents["a"], ents["b"] = spawn_portal_pair(world, (0, 1.5, 0), None, (10, 1.5, 0), TURN_Y_90)
        world.get(ents["b"], Transform).scale = glm.vec3(2.0, 1.0, 0.5)
        ents["green"] = glowing_box(world, (0.8, 1.5, 1.5), (0.1, 0.9, 0.1), size=0.8)

    runner = scene(build, size)
    runner.frame()
    assert open_portal_pairs(runner.world) == {ents["a"]: ents["b"], ents["b"]: ents["a"]}
    ids = runner.ids()
    on_b = runner.engine.renderer.targets.read_surface_ids() == ents["b"]
    assert on_b.sum() > 1000 and runner.stats.reflection_views >= 1
    a_world, b_world = (np.array(glm.dmat4(runner.world.get(ents[e], Transform).world).to_list()).T for e in "ab")
    turn = np.array(glm.dmat4(glm.rotate(glm.pi(), glm.vec3(0, 1, 0))).to_list()).T
    carry = b_world @ turn @ np.linalg.inv(a_world)
    assert even_scale(glm.mat4(*carry.T.flatten())) is None
    eye, rays = pixel_rays(runner.engine.main_view, size)
    centre, half = np.array([0.8, 1.5, 1.5]), np.full(3, 0.4)

    def hits(carry, grow):
        back = np.linalg.inv(carry)
        origin = back[:3, :3] @ eye + back[:3, 3]
        directions = rays[on_b] @ back[:3, :3].T
        return box_hits(origin, directions, centre, half + grow)

    inside, outside = hits(carry, -0.03), ~hits(carry, 0.03)
    shown = ids[on_b] == ents["green"]
    assert inside.sum() > 100
    assert shown[inside].all(), int((~shown[inside]).sum())
    assert not shown[outside].any(), int(shown[outside].sum())
    even = b_world @ np.diag([1.0, 2.0, 4.0, 1.0]) @ turn @ np.linalg.inv(a_world)  # B scaled 2 every way
    at_even_scale = hits(even, 0.0)
    assert (at_even_scale ^ shown).sum() > 0.3 * shown.sum(), ((at_even_scale ^ shown).sum(), shown.sum())
