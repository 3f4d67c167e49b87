"""Travel through portals: crossings, the carried pose, near-plane protection, dead partners.

The pair used throughout: A at (0, 1.5, 0) facing +Z, B at (10, 1.5, 0) turned 90 deg about Y
(facing +X).  By hand, going into A's front and out of B's front maps
    a point (x, y, z)  ->  (10 - z, y, x)        a direction (x, y, z)  ->  (-z, y, x)
(A-local, half turn about up, turn 90 deg about Y, move to B) and turns orientations by
-90 deg about Y.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    DirectionalLight,
    Emissive,
    FlyController,
    Material,
    MeshRef,
    Portal,
    Skybox,
    Transform,
    Traveller,
    look_rotation,
    yaw_pitch_rotation,
)
from engine.assets.mesh import box, sphere
from engine.assets.portals import spawn_portal_pair
from engine.core.frame_io import Input
from engine.core.game import spawn_camera
from engine.core.world import World
from engine.resources import PortalCrossing, PortalCrossings
from systems import PortalTravelSystem, TransformSystem

TURN_Y_90 = glm.angleAxis(glm.radians(90), glm.vec3(0, 1, 0))
A_POS, B_POS = (0.0, 1.5, 0.0), (10.0, 1.5, 0.0)
SIZE = (2.0, 3.0)
ASPECT = 16 / 9
DT = 1 / 60


def carry_point(p):
    x, y, z = p
    return glm.vec3(10 - z, y, x)


def carry_dir(d):
    x, y, z = d
    return glm.vec3(-z, y, x)


def forward(rotation):
    return rotation * glm.vec3(0, 0, -1)


@pytest.fixture
def world():
    w = World("travel-test")
    w.add_system(PortalTravelSystem(w, aspect=ASPECT), 70)
    w.add_system(TransformSystem(w), 50)
    yield w
    w.close()


def pair(world):
    return spawn_portal_pair(world, A_POS, None, B_POS, TURN_Y_90, size=SIZE)


def crossings(world) -> list[PortalCrossing]:
    return list(world.resources[PortalCrossings])


# --- geometry the tests check independently of the system ----------------------------------------
def near_corners(position, rotation, fov_y, near, aspect):
    hh = near * math.tan(math.radians(fov_y) / 2)
    hw = hh * aspect
    return [glm.vec3(position) + rotation * glm.vec3(sx * hw, sy * hh, -near)
            for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]


def near_plane_cuts_quad(corners, quad_world, size) -> bool:
    """Whether the near-plane rectangle meets the portal quad (a rectangle in local XY)."""
    inv = glm.inverse(quad_world)
    local = [glm.vec3(inv * glm.vec4(c, 1.0)) for c in corners]
    hits = []
    for a, b in zip(local, local[1:] + local[:1], strict=True):
        if a.z == 0.0:
            hits.append(a)
        elif (a.z < 0) != (b.z < 0) and b.z != 0.0:
            hits.append(a + (b - a) * (a.z / (a.z - b.z)))
    if not hits:
        return False
    start, end = hits[0], hits[-1]
    for t in np.linspace(0.0, 1.0, 401):
        p = start + (end - start) * float(t)
        if abs(p.x) <= size[0] / 2 and abs(p.y) <= size[1] / 2:
            return True
    return False


def camera_cuts_a_portal(world, cam, aspect, portals) -> bool:
    t = world.get(cam, Transform)
    c = world.get(cam, Camera)
    corners = near_corners(t.position, t.rotation, c.fov_y, c.near, aspect)
    return any(near_plane_cuts_quad(corners, world.get(p, Transform).world, SIZE) for p in portals)


# --- (a) the carried pose -----------------------------------------------------------------------
def test_traveller_walking_into_a_comes_out_of_b_with_turned_pose_velocity_and_yaw(world):
    a, b = pair(world)
    mover = world.spawn(Transform(position=(0.3, 2.0, 1.0), rotation=yaw_pitch_rotation(0.0, 20.0)),
                        Traveller(velocity=(0, 0, -6)), FlyController(yaw=0.0, pitch=20.0))
    world.step(0.1)  # z 1.0 -> 0.4
    assert crossings(world) == []
    world.step(0.1)  # z 0.4 -> -0.2: 0.2 behind A, inside its rectangle
    assert crossings(world) == [PortalCrossing(mover, a, b)]
    crossing = crossings(world)[0]
    # The crossing carries the pair's turn (a quarter turn about +Y here: -Z goes to +X) and
    # its carry, which took the mover where it is.
    np.testing.assert_allclose(crossing.turn * glm.vec3(0, 0, -1), (1, 0, 0), atol=1e-5)
    np.testing.assert_allclose(glm.vec3(crossing.carry * glm.vec4(0.3, 2.0, -0.2, 1.0)), (10.2, 2.0, 0.3), atol=1e-5)
    t = world.get(mover, Transform)
    # 0.2 m behind A comes out 0.2 m in front of B: (10 - (-0.2), 2.0, 0.3).
    np.testing.assert_allclose(t.position, (10.2, 2.0, 0.3), atol=1e-5)
    np.testing.assert_allclose(world.get(mover, Traveller).velocity, (6, 0, 0), atol=1e-5)  # out of B's front
    # Looking down -Z pitched up 20 deg now looks down +X pitched up 20 deg; up stays up-ish.
    s, c = math.sin(math.radians(20)), math.cos(math.radians(20))
    np.testing.assert_allclose(forward(t.rotation), (c, s, 0), atol=1e-5)
    np.testing.assert_allclose(t.rotation * glm.vec3(0, 1, 0), (-s, c, 0), atol=1e-5)
    np.testing.assert_allclose(t.scale, (1, 1, 1))
    fly = world.get(mover, FlyController)
    assert fly.yaw == pytest.approx(-90.0) and fly.pitch == pytest.approx(20.0)
    # Mouse look rebuilds the same orientation from yaw / pitch: no jump on the next mouse move.
    np.testing.assert_allclose(forward(yaw_pitch_rotation(fly.yaw, fly.pitch)), (c, s, 0), atol=1e-5)
    world.step(0.1)  # walks on away from B, no second crossing
    assert crossings(world) == []
    np.testing.assert_allclose(world.get(mover, Transform).position, (10.8, 2.0, 0.3), atol=1e-5)
    np.testing.assert_allclose(world.get(mover, Transform).world[3].xyz, (10.8, 2.0, 0.3), atol=1e-5)


def test_a_traveller_spawned_with_a_velocity_crosses_in_its_first_frame(world):
    a, b = pair(world)
    mover = world.spawn(Transform(position=(0, 1.5, 0.1)), Traveller(velocity=(0, 0, -3)))
    world.step(0.1)
    assert crossings(world) == [PortalCrossing(mover, a, b)]
    np.testing.assert_allclose(world.get(mover, Transform).position, carry_point((0, 1.5, -0.2)), atol=1e-5)


def test_a_portal_sliding_over_a_thing_standing_still_swallows_it(world):
    """A portal is a door that may move: one sliding forwards over a traveller standing still
    takes it in when the traveller's origin passes from its front to its back as the portal
    stood then, and it comes out of the partner where the pair puts it (the same as walking
    in); beside the rectangle the portal slides by it."""
    a, b = pair(world)
    still = world.spawn(Transform(position=(0.4, 1.2, 0.5)), Traveller())
    beside = world.spawn(Transform(position=(1.4, 1.2, 0.5)), Traveller())
    world.step(DT)
    door = world.get(a, Transform)
    for step in range(1, 4):  # A slides forwards 0.2 m a frame: 0.2, 0.4, 0.6
        door.position = glm.vec3(0.0, 1.5, 0.2 * step)
        world.step(DT)
        if step < 3:
            assert crossings(world) == []
    assert crossings(world) == [PortalCrossing(still, a, b)]
    # 0.1 m behind A (at z 0.6): A-local (0.4, -0.3, -0.1) comes out 0.1 m in front of B.
    np.testing.assert_allclose(world.get(still, Transform).position, (10.1, 1.2, 0.4), atol=1e-5)
    np.testing.assert_allclose(world.get(beside, Transform).position, (1.4, 1.2, 0.5), atol=1e-6)


@pytest.mark.parametrize("move", ["placed", "backwards", "turned"])
def test_a_portal_placed_anew_or_moving_away_swallows_nothing(world, move):
    """A portal that jumps further than SLIDE of its rectangle's larger side in a frame (shot
    to another place) or turns past SLIDE_TURN was placed anew: what stood in front of where it
    was, and is now behind it, stays.  One moving away from a thing behind it takes nothing."""
    from engine.rules.portal_gates import SLIDE, SLIDE_TURN

    a, _ = pair(world)
    start = {"placed": (0.0, 1.5, 0.5), "backwards": (0.0, 1.5, -0.1), "turned": (0.0, 1.5, 0.3)}[move]
    mover = world.spawn(Transform(position=start), Traveller())
    world.step(DT)
    door = world.get(a, Transform)
    if move == "placed":  # further than the slide in one frame: 2 x SLIDE x 3 m
        door.position = glm.vec3(0.0, 1.5, 0.5 + 2.0 * SLIDE * max(SIZE) + 0.1)
    elif move == "backwards":  # A slides back, away from what stands behind it
        door.position = glm.vec3(0.0, 1.5, -0.3)
    else:  # about the vertical through the mover, past the turn a slide may make
        door.position = glm.vec3(0.0, 1.5, 0.6)
        door.rotation = glm.angleAxis(glm.radians(SLIDE_TURN + 5.0), glm.vec3(1, 0, 0))
    world.step(DT)
    assert crossings(world) == []
    np.testing.assert_allclose(world.get(mover, Transform).position, start, atol=1e-6)


# --- (b) what does not travel ---------------------------------------------------------------------
@pytest.mark.parametrize("start, velocity", [
    ((1.3, 1.5, 1.0), (0, 0, -6)),   # beside the rectangle (half width 1)
    ((0.0, 3.2, 1.0), (0, 0, -6)),   # above it (top at 1.5 + 1.5)
    ((0.0, 1.5, -1.0), (0, 0, 6)),   # from the back to the front
    ((0.0, 1.5, 1.0), (0, 0, 6)),    # walking away from the front
])
def test_passing_outside_the_rectangle_or_from_behind_does_not_travel(world, start, velocity):
    pair(world)
    mover = world.spawn(Transform(position=start), Traveller(velocity=velocity))
    for _ in range(4):
        world.step(0.1)
        assert crossings(world) == []
    np.testing.assert_allclose(world.get(mover, Transform).position,
                               glm.vec3(start) + 0.4 * glm.vec3(velocity), atol=1e-5)


@pytest.mark.parametrize("which", ["in", "out"])
def test_a_disabled_portal_or_partner_does_not_travel(world, which):
    a, b = pair(world)
    world.get(a if which == "in" else b, Portal).enabled = False
    mover = world.spawn(Transform(position=(0, 1.5, 1.0)), Traveller(velocity=(0, 0, -6)))
    for _ in range(3):
        world.step(0.1)
        assert crossings(world) == []
    assert world.get(mover, Transform).position.z == pytest.approx(-0.8)


def test_no_ping_pong_through_the_exit_in_the_next_frame_but_later_travel_works(world):
    a, b = pair(world)
    mover = world.spawn(Transform(position=(0, 1.5, 0.4)), Traveller(velocity=(0, 0, -6)))
    world.step(0.1)
    assert crossings(world) == [PortalCrossing(mover, a, b)]
    world.get(mover, Traveller).velocity = (-6, 0, 0)  # straight back across B at once
    world.step(0.1)
    assert crossings(world) == []
    world.get(mover, Transform).position = (10.7, 1.5, 0.3)  # back in front of B (from its back: no travel)
    world.step(0.1)
    assert crossings(world) == []
    world.step(0.1)  # 10.1 -> 9.5: into B's front, out of A's front
    assert crossings(world) == [PortalCrossing(mover, b, a)]
    # 0.5 m behind B is 0.5 m in front of A; -X becomes +Z.
    np.testing.assert_allclose(world.get(mover, Transform).position, (0.3, 1.5, 0.5), atol=1e-5)
    np.testing.assert_allclose(world.get(mover, Traveller).velocity, (0, 0, 6), atol=1e-5)


def test_a_parented_traveller_moves_but_does_not_teleport(world):
    pair(world)
    root = world.spawn(Transform())
    mover = world.spawn(Transform(position=(0, 1.5, 1.0), parent=root), Traveller(velocity=(0, 0, -6)))
    for _ in range(3):
        world.step(0.1)
        assert crossings(world) == []
    assert world.get(mover, Transform).position.z == pytest.approx(-0.8)


# --- (c) the camera: near-plane protection --------------------------------------------------------
@pytest.mark.parametrize("yaw, pitch, offset, move", [
    (0.0, 0.0, (0.2, 0.1), "forward"),      # straight in
    (35.0, -20.0, (0.6, 1.0), "forward"),   # diagonally, looking down
    (-60.0, 10.0, (-0.5, -0.8), "forward"),
    (180.0, 0.0, (0.0, 0.0), "backward"),   # backing into the portal, looking away from it
    (90.0, 0.0, (0.3, 0.0), "sideways"),    # looking along the portal, stepping into it
])
def test_the_camera_goes_through_before_its_near_plane_cuts_either_portal(world, yaw, pitch, offset, move):
    a, b = pair(world)
    rotation = yaw_pitch_rotation(yaw, pitch)
    direction = {"forward": forward(rotation), "backward": -forward(rotation),
                 "sideways": glm.vec3(0, 0, -1)}[move]
    # Start 0.6 m before the point of A the path goes through.
    target = glm.vec3(offset[0], 1.5 + offset[1], 0.0)
    start = target - glm.normalize(direction) * 0.6
    velocity = glm.normalize(direction) * 1.5
    cam = world.spawn(Transform(position=start, rotation=rotation), Camera(fov_y=70.0, near=0.05),
                      Traveller(velocity=velocity))
    seen = []
    for _ in range(50):
        before = glm.vec3(world.get(cam, Transform).position)
        world.step(DT)
        assert not camera_cuts_a_portal(world, cam, ASPECT, (a, b)), f"frame {world.frame_index}"
        seen += crossings(world)
        t = world.get(cam, Transform)
        if crossings(world):
            moved = before + velocity * DT
            assert moved.z > 0.0  # went through while the eye was still in front of A
            expected = carry_point(moved)
            # Carried, then pushed straight out of B (+X): at most the eye's distance in front of A
            # plus the near pyramid's reach (eye to a near corner), plus a little.
            np.testing.assert_allclose((t.position.y, t.position.z), (expected.y, expected.z), atol=1e-5)
            c = world.get(cam, Camera)
            hh = c.near * math.tan(math.radians(c.fov_y / 2))
            reach = math.sqrt(c.near ** 2 + hh ** 2 + (hh * ASPECT) ** 2)
            assert 0.0 <= t.position.x - expected.x <= 2 * reach + 0.01
            assert t.position.x > 10.0  # in front of B
            np.testing.assert_allclose(forward(t.rotation), carry_dir(forward(rotation)), atol=1e-5)
            np.testing.assert_allclose(t.rotation * glm.vec3(0, 1, 0), carry_dir(rotation * glm.vec3(0, 1, 0)),
                                       atol=1e-5)
            np.testing.assert_allclose(world.get(cam, Traveller).velocity, carry_dir(velocity), atol=1e-5)
    assert seen == [PortalCrossing(cam, a, b)]
    assert world.get(cam, Transform).position.x > 10.2  # kept going, out of B


def test_the_camera_passing_beside_a_portal_stays_on_its_side(world):
    a, b = pair(world)
    cam = world.spawn(Transform(position=(1.25, 1.5, 0.5)), Camera(near=0.05), Traveller(velocity=(0, 0, -1.5)))
    for _ in range(40):
        world.step(DT)
        assert crossings(world) == []
        assert not camera_cuts_a_portal(world, cam, ASPECT, (a, b))
    assert world.get(cam, Transform).position.z < -0.4


MAGENTA_WALL = (0.0, 1.5, -0.15)


def portal_scene(ents, speed=1.0):
    def build(world):
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))
        world.spawn(Skybox())
        ents["a"], ents["b"] = pair(world)
        # Magenta right behind A, a little smaller than it: hidden by A from anywhere in front of
        # it on this path, so it shows only if A's quad is clipped or seen through from behind.
        ents["wall"] = world.spawn(Transform(position=MAGENTA_WALL), MeshRef(box((1.8, 2.8, 0.1))),
                                   Material(color=(1.0, 0.0, 1.0)), Emissive(1.0))
        ents["ball"] = world.spawn(Transform(position=(13, 1.5, 0.3)), MeshRef(sphere(0.4)),
                                   Material(color=(0.9, 0.6, 0.1)))
        ents["cam"] = spawn_camera(world, position=(0.2, 1.6, 0.45), yaw=0.0)
        world.get(ents["cam"], FlyController).speed = speed
        world.resources[Input].held = {"w"}

    return build


def magenta(rgb) -> np.ndarray:
    px = rgb.astype(int)
    return (px[..., 0] > 120) & (px[..., 2] > 120) & (px[..., 1] < 0.5 * np.minimum(px[..., 0], px[..., 2]))


def test_flying_the_camera_through_a_never_shows_its_back_or_a_clipped_portal(scene):
    ents = {}
    frame_size = (160, 120)
    runner = scene(portal_scene(ents), frame_size)
    world, cam = runner.world, ents["cam"]
    crossed_at = None
    for i in range(40):  # 1 m/s at 60 fps from 0.45 m: the near plane reaches A at frame ~24
        before = glm.vec3(world.get(cam, Transform).position)
        rgb = runner.frame(DT)
        assert not magenta(rgb).any(), f"frame {i} shows what is behind portal A"
        assert not camera_cuts_a_portal(world, cam, frame_size[0] / frame_size[1], (ents["a"], ents["b"]))
        if crossings(world):
            assert crossings(world) == [PortalCrossing(cam, ents["a"], ents["b"])] and crossed_at is None
            crossed_at = i
            moved_z = before.z - DT  # the fly camera's step before the teleport
            assert 0.0 < moved_z < 0.05 + 0.01  # went through once the near plane (0.05) reached A
            t = world.get(cam, Transform)
            # Carried (10 - z, y, x), then out to just in front of B, looking down +X.
            np.testing.assert_allclose((t.position.y, t.position.z), (1.6, 0.2), atol=1e-5)
            assert 10.0 < t.position.x < 10.0 + 0.01
            np.testing.assert_allclose(forward(t.rotation), (1, 0, 0), atol=1e-5)
            assert world.get(cam, FlyController).yaw == pytest.approx(-90.0)
        elif crossed_at is None:
            assert world.get(cam, Transform).position.z > 0.0  # the eye stays in front of A until then
    assert crossed_at is not None and crossed_at < 35
    # The fly camera carries on along its new heading, out of B.
    assert world.get(cam, Transform).position.x > 10.0 + 0.05
    assert runner.ids()[frame_size[1] // 2, frame_size[0] // 2] == ents["ball"]  # ahead of B, on +X
    # The detector works: magenta in front of the camera is seen.
    world.get(ents["wall"], Transform).position = (12.0, 1.6, 0.2)
    assert magenta(runner.frame(DT)).sum() > 100


def test_without_travel_the_near_plane_cuts_the_portal_and_shows_what_is_behind(scene):
    """The control for the test above: the magenta wall is there to be seen."""
    ents = {}
    runner = scene(portal_scene(ents), (160, 120))
    import esper

    runner.world._use()
    esper.remove_processor(PortalTravelSystem)
    shown = []
    for _ in range(30):
        shown.append(magenta(runner.frame(DT)).any())
    assert any(shown) and not shown[0]


# --- (d) a partner deleted at run time ------------------------------------------------------------
def test_deleting_a_portal_at_run_time_keeps_running_and_stops_travel(scene):
    ents = {}

    def build(world):
        world.spawn(DirectionalLight())
        ents["a"], ents["b"] = pair(world)
        ents["ball"] = world.spawn(Transform(position=(0.0, 1.5, 0.5)), MeshRef(sphere(0.2)), Material(),
                                   Traveller(velocity=(0, 0, -3)))
        ents["cam"] = spawn_camera(world, position=(0.0, 1.6, 4.0), fly=False)

    runner = scene(build, (64, 48))
    world = runner.world
    for _ in range(12):
        runner.frame(DT)
        if crossings(world):
            break
    assert crossings(world) == [PortalCrossing(ents["ball"], ents["a"], ents["b"])]
    world.delete_entity(ents["b"])
    world.get(ents["ball"], Transform).position = (0.0, 1.5, 0.5)  # in front of A again
    world.get(ents["ball"], Traveller).velocity = (0, 0, -3)
    for _ in range(20):
        runner.frame(DT)
        assert crossings(world) == []
    assert world.get(ents["ball"], Transform).position.z < -0.4  # walked through A's quad: no partner
    assert world.get(ents["a"], Portal).partner == ents["b"]  # dangling, harmless
    # The camera flying into the partnerless portal does not travel either.
    world.get(ents["cam"], Transform).position = (0.0, 1.6, 0.3)
    world.get(ents["cam"], Camera).near = 0.05
    world.add_component(ents["cam"], Traveller(velocity=(0, 0, -2)))
    for _ in range(20):
        runner.frame(DT)
        assert crossings(world) == []
    assert world.get(ents["cam"], Transform).position.z < 0.0
    world.delete_entity(ents["a"])
    runner.frame(DT)


def test_the_image_through_the_portal_matches_the_image_after_the_teleport(scene):
    """Needs the ReflectionSystem's portal views: the last frame before the teleport looks
    through A at B's side, the first one after is rendered there directly."""
    ents = {}
    runner = scene(portal_scene(ents), (160, 120))
    frames = []
    for _ in range(30):
        frames.append(runner.frame(DT).astype(int))
        if crossings(runner.world):
            break
        views = runner.stats.reflection_views
    assert crossings(runner.world) and views >= 1  # the frame before looked through a portal view
    diff = np.abs(frames[-1] - frames[-2])
    assert diff.mean() < 1.5 and np.percentile(diff, 99) < 12, (diff.mean(), np.percentile(diff, 99))
    assert np.abs(frames[-2] - frames[0]).mean() < 5  # the whole approach showed B's side through A


# --- (e) a pair of two scales -----------------------------------------------------------------------
def scaled_pair(world, scale_b=2.0):
    a, b = pair(world)
    world.get(b, Transform).scale = glm.vec3(scale_b)
    return a, b


def carry_point_scaled(p, k=2.0):
    """The pair's carry with B scaled ``k``: the unscaled carry, then ``k`` times as far from B."""
    return glm.vec3(B_POS) + k * (carry_point(p) - glm.vec3(B_POS))


def test_a_pair_of_two_scales_carries_a_traveller_at_the_size_and_speed_its_view_showed(world):
    """B twice A's size by its Transform: the view through A shows B's side at half size, so
    what goes in comes out twice as big and twice as fast (the pose the slice's clone had),
    and going back through B halves it again, exactly."""
    a, b = scaled_pair(world)
    ball = world.spawn(Transform(position=(0.3, 1.8, 0.5), rotation=yaw_pitch_rotation(10.0, 0.0),
                                 scale=(1.0, 0.5, 1.0)), Traveller(velocity=(0, 0, -6)))
    world.step(0.1)  # z 0.5 -> -0.1: inside A's rectangle
    assert crossings(world) == [PortalCrossing(ball, a, b)]
    t = world.get(ball, Transform)
    np.testing.assert_allclose(t.position, carry_point_scaled((0.3, 1.8, -0.1)), atol=1e-5)
    np.testing.assert_allclose(t.scale, (2.0, 1.0, 2.0), atol=1e-5)
    np.testing.assert_allclose(world.get(ball, Traveller).velocity, 2.0 * carry_dir((0, 0, -6)), atol=1e-5)
    np.testing.assert_allclose(forward(t.rotation), carry_dir(forward(yaw_pitch_rotation(10.0, 0.0))), atol=1e-5)
    # Back in through B's front (after a step out, as no exit takes it back in the next frame):
    # half the size again, exactly as it was (portal_math.even_scale: 2 and 0.5, not 1.9999998).
    world.get(ball, Traveller).velocity = glm.vec3(6, 0, 0)
    world.step(0.1)
    world.get(ball, Traveller).velocity = glm.vec3(-6, 0, 0)
    for _ in range(6):
        world.step(0.1)
        if crossings(world):
            break
    assert crossings(world) == [PortalCrossing(ball, b, a)]
    assert tuple(world.get(ball, Transform).scale) == (1.0, 0.5, 1.0)
    np.testing.assert_allclose(world.get(ball, Traveller).velocity, (0, 0, 3), atol=1e-5)  # half as fast


def test_a_pair_scaled_unevenly_carries_the_model_matrix_as_its_view_does(world):
    """B scaled (2, 1, 0.5): what goes in comes out with the carry applied to its model
    matrix (its world matrix after is the carry times its world matrix before, the pose the
    clone had), stretched 2 across B and flattened to half along B's facing."""
    a, b = pair(world)
    world.get(b, Transform).scale = glm.vec3(2.0, 1.0, 0.5)
    ball = world.spawn(Transform(position=(0.3, 1.8, 0.5), scale=(0.5, 1.0, 1.0)), Traveller(velocity=(0, 0, -6)))
    world.step(0.05)
    model = glm.translate(glm.vec3(0.3, 1.8, 0.2)) * glm.scale(glm.vec3(0.5, 1.0, 1.0))  # where it is before
    world.step(0.05)  # z 0.2 -> -0.1: in
    assert crossings(world) == [PortalCrossing(ball, a, b)]
    crossing = crossings(world)[0]
    t = world.get(ball, Transform)
    after = glm.translate(t.position) * glm.mat4_cast(t.rotation) * glm.scale(t.scale)
    expected = crossing.carry * glm.translate(glm.vec3(0, 0, -0.3)) * model  # moved on 0.3, then carried
    np.testing.assert_allclose(np.array(after), np.array(expected), atol=1e-5)
    np.testing.assert_allclose(t.scale, (1.0, 1.0, 0.5), atol=1e-6)  # across B (z here) x 2, along its facing x 0.5


def test_a_pair_of_one_scale_keeps_a_travellers_scale_bit_for_bit(world):
    a, b = pair(world)
    ball = world.spawn(Transform(position=(0.3, 1.8, 0.5), scale=(0.7, 1.3, 0.9)), Traveller(velocity=(0, 0, -6)))
    world.step(0.1)
    assert crossings(world) == [PortalCrossing(ball, a, b)]
    assert tuple(world.get(ball, Transform).scale) == tuple(glm.vec3(0.7, 1.3, 0.9))


@pytest.mark.parametrize("yaw, pitch, target, move", [
    (35.0, -20.0, (0.6, 2.5), "forward"),  # at a slant: the near rectangle meets A's plane before the eye
    (90.0, 0.0, (0.3, 1.5), "sideways"),   # looking along the portal: the rectangle reaches out of B's front
])
def test_a_scaled_camera_goes_through_before_its_longer_near_plane_cuts_a_portal(world, yaw, pitch, target, move):
    """A camera scaled 2 (as a scaled pair leaves one) sees nothing nearer than twice its
    ``near``: it goes through when that longer tip touches, and comes out that far clear."""
    a, b = pair(world)
    rotation = yaw_pitch_rotation(yaw, pitch)
    direction = glm.normalize(forward(rotation)) if move == "forward" else glm.vec3(0, 0, -1)
    velocity = direction * 1.5
    start = glm.vec3(target[0], target[1], 0.0) - direction * 0.6
    cam = world.spawn(Transform(position=start, rotation=rotation, scale=(2.0, 2.0, 2.0)),
                      Camera(fov_y=70.0, near=0.05), Traveller(velocity=velocity))
    crossed = False
    for _ in range(40):
        world.step(DT)
        t = world.get(cam, Transform)
        corners = near_corners(t.position, t.rotation, 70.0, 2 * 0.05, ASPECT)  # the view's near plane
        assert not any(near_plane_cuts_quad(corners, world.get(p, Transform).world, SIZE) for p in (a, b)), \
            f"frame {world.frame_index}"
        if crossings(world):
            crossed = True
            assert crossings(world) == [PortalCrossing(cam, a, b)]
            assert t.position.x > 10.0 and tuple(t.scale) == (2.0, 2.0, 2.0)
            break
    assert crossed


def test_what_went_into_a_scaled_pair_is_the_size_its_clone_showed(scene):
    """A bar walking into A, B scaled 2: its clone beyond B is twice its size, and the frame
    after it crosses shows it at that size there, not popping back to its own.  (The id
    target gives a clone its source's id, so the bar is counted by where it is on the screen:
    the side of B's picture.)"""
    ents = {}

    def build(world):
        world.spawn(Skybox())
        world.spawn(DirectionalLight(direction=(0.3, -1.0, -0.4), intensity=2.0))
        eye = glm.vec3(13.0, 3.5, 8.0)  # before both fronts (A faces +Z, B +X)
        ents["cam"] = world.spawn(Transform(position=eye, rotation=look_rotation(glm.vec3(5.0, 1.5, 0.0) - eye)),
                                  Camera())
        ents["a"], ents["b"] = scaled_pair(world)
        ents["bar"] = world.spawn(Transform(position=(0.2, 1.5, 0.6)), MeshRef(box((0.4, 0.4, 1.0))),
                                  Material(color=(0.9, 0.5, 0.1)), Emissive(1.0), Traveller(velocity=(0, 0, -1.2)))

    runner = scene(build, (200, 150))
    world = runner.world
    seen = []  # (the bar's pixels on B's side of the screen, crossed this frame)
    for _ in range(60):
        runner.frame(DT)
        split = (runner.project(A_POS)[0] + runner.project(B_POS)[0]) // 2
        on_b = runner.ids()[:, split:] == ents["bar"]
        seen.append((int(on_b.sum()), bool(crossings(world))))
        if len(seen) > 3 and seen[-3][1]:
            break
    crossed = [i for i, (_, c) in enumerate(seen) if c]
    assert len(crossed) == 1, seen
    i = crossed[0]
    before, after = seen[i - 1][0], seen[i][0]
    assert before > 40, seen  # the clone beyond B was seen
    assert 0.75 < after / before < 1.35, seen[i - 3:i + 3]


def test_the_fly_camera_out_of_a_portal_scaled_2_flies_twice_as_fast(scene):
    """Seen through A, B's side is at half size, so the camera flying in at 1 m/s seemed to
    cover it at 2 m/s: out of B (scaled 2) it is twice as big and keeps that pace, its
    FlyController's speed in its own units."""
    ents = {}
    build = portal_scene(ents)

    def scaled(world):
        build(world)
        world.get(ents["b"], Transform).scale = glm.vec3(2.0)

    runner = scene(scaled, (64, 48))
    world, cam = runner.world, ents["cam"]
    for _ in range(40):
        before = glm.vec3(world.get(cam, Transform).position)
        runner.frame(DT)
        step = glm.vec3(world.get(cam, Transform).position) - before
        if crossings(world):
            break
        np.testing.assert_allclose(step, (0, 0, -DT), atol=1e-6)  # 1 m/s down -Z towards A
    assert crossings(world) == [PortalCrossing(cam, ents["a"], ents["b"])]
    assert tuple(world.get(cam, Transform).scale) == (2.0, 2.0, 2.0)
    before = glm.vec3(world.get(cam, Transform).position)
    runner.frame(DT)
    np.testing.assert_allclose(glm.vec3(world.get(cam, Transform).position) - before, (2 * DT, 0, 0), atol=1e-5)


def test_a_crossing_past_what_a_transform_holds_is_not_made_and_is_said_once(world):
    """Through a pair scaled 2, a ball of scale 6e5 would come out at 1.2e6, past
    Transform's SCALE_RANGE (1e6): the crossing is not made (no error inside the frame), the
    ball goes on behind A as through a closed portal, and that is said once; a ball that
    fits goes through the same frame."""
    import warnings

    from components import ComponentWarning
    from components.transform import SCALE_RANGE

    a, b = scaled_pair(world)
    big = world.spawn(Transform(position=(0.3, 1.8, 0.5), scale=(6e5, 1.0, 1.0)), Traveller(velocity=(0, 0, -6)))
    small = world.spawn(Transform(position=(-0.3, 1.8, 0.5)), Traveller(velocity=(0, 0, -6)))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        world.step(0.1)
        assert crossings(world) == [PortalCrossing(small, a, b)]
        t = world.get(big, Transform)
        np.testing.assert_allclose(t.position, (0.3, 1.8, -0.1), atol=1e-6)   # behind A, not carried
        assert tuple(t.scale) == (6e5, 1.0, 1.0) and 2 * 6e5 > SCALE_RANGE[1]
        said = [str(w.message) for w in caught if issubclass(w.category, ComponentWarning)]
        assert len(said) == 1 and said[0].startswith(f"entity {big}: going through portal {a}"), said
        world.get(big, Transform).position = glm.vec3(0.3, 1.8, 0.5)   # again: not said again
        world.step(0.1)
        assert crossings(world) == [] and len([w for w in caught if issubclass(w.category, ComponentWarning)]) == 1


@pytest.mark.parametrize("scale_a, scale_b", [(1.0, 2.0), (2.0, 0.5)])
def test_crossing_a_pair_of_two_scales_back_and_forth_never_drifts(world, scale_a, scale_b):
    """A ball goes into A and out of B, turns back, in through B and out of A, 100 times over
    (A and B scaled by their Transforms: B twice A's size, or a quarter): each time out of B
    it is k = scale_b / scale_a times its size, exactly (portal_math.even_scale), k times as
    fast and as far across B's face as it was across A's (worked out here: the unscaled pair's
    map, then k times as far from B), and each time out of A its own size, exactly, at its
    own speed, as near as float32 holds one crossing's: the 200th crossing is the 2nd's, as a
    pair of one scale keeps it (a velocity carried by the scaled carry's float32 matrix lost
    2.4e-7 of its speed each time round: 5e-5 m/s of 6 after 200 crossings)."""
    k = scale_b / scale_a
    a, b = pair(world)
    world.get(a, Transform).scale = glm.vec3(scale_a)
    world.get(b, Transform).scale = glm.vec3(scale_b)
    across = (0.3 * scale_a, 1.5 + 0.3 * scale_a)  # inside A's rectangle, whatever its scale
    ball = world.spawn(Transform(position=(*across, 0.5), rotation=yaw_pitch_rotation(10.0, 0.0),
                                 scale=(1.0, 0.5, 1.0)), Traveller(velocity=(0, 0, -6)))
    out_of_a, out_of_b = [], []
    for _ in range(200):
        for _ in range(10):
            world.step(0.1)
            if crossings(world):
                break
        (crossing,) = crossings(world)
        t, traveller = world.get(ball, Transform), world.get(ball, Traveller)
        if crossing.from_portal == a:
            assert tuple(t.scale) == (k, 0.5 * k, k)
            np.testing.assert_allclose(t.position - glm.vec3(B_POS),
                                       k * (carry_point((*across, 0.5 - 0.6)) - glm.vec3(B_POS)), atol=5e-4)
            out_of_b.append((np.array(t.position), np.array(traveller.velocity), np.array(t.rotation)))
        else:
            assert tuple(t.scale) == (1.0, 0.5, 1.0)
            out_of_a.append((np.array(t.position), np.array(traveller.velocity), np.array(t.rotation)))
        world.step(0.1)   # a step out (no exit takes it back in the next frame), then back
        traveller.velocity = -traveller.velocity
    assert len(out_of_a) == len(out_of_b) == 100
    np.testing.assert_allclose(out_of_b[0][1], k * carry_dir((0, 0, -6)), rtol=1e-6, atol=1e-5)
    np.testing.assert_allclose(out_of_a[0][1], (0, 0, 6), atol=1e-5)
    for outs, speed in ((out_of_a, 6.0), (out_of_b, 6.0 * k)):
        (first_at, first_velocity, first_turn), (last_at, last_velocity, last_turn) = outs[0], outs[-1]
        # (one float32 step of a speed of 6 or 12 is 1e-6)
        assert abs(np.linalg.norm(last_velocity) - speed) < 3e-6, (np.linalg.norm(last_velocity), speed)
        np.testing.assert_allclose(last_velocity, first_velocity, atol=1e-4 * speed)
        np.testing.assert_allclose(last_turn, first_turn, atol=1e-5)
        # (float32 steps of a position 10 m out round by 1e-6: 2e-4 over the 100 trips out of B and back, as
        # with a pair of one scale, whose 200th crossing is 1e-5 off its 2nd)
        np.testing.assert_allclose(last_at, first_at, atol=5e-4)


def test_a_turned_thing_through_a_pair_scaled_unevenly_keeps_its_axes_and_drops_the_shear(world):
    """B scaled (2, 1, 0.5) and a ball turned 45 degrees about up: the carry times its model
    matrix is sheared (B's stretch is along axes the ball's are turned from), which a
    Transform cannot hold, so (portal_math.decompose_pose) the ball comes out where the carry
    puts its centre, with that matrix less its shear: worked out here as the QR decomposition
    of its 3 x 3 part in float64 (Gram-Schmidt on its columns in order: the ball's own x axis
    keeps the carried one's direction and length, y is made square to it, then z), so the
    rotation is the orthonormal Q and the scale the diagonal of R.  What is dropped is real:
    the model matrix after differs from the carried one (its clone's) by the shear."""
    a, b = pair(world)
    world.get(b, Transform).scale = glm.vec3(2.0, 1.0, 0.5)
    turned = glm.angleAxis(glm.radians(45.0), glm.vec3(0, 1, 0))
    ball = world.spawn(Transform(position=(0.3, 1.8, 0.5), rotation=turned, scale=(0.5, 1.0, 1.0)),
                       Traveller(velocity=(0, 0, -6)))
    world.step(0.05)
    model = glm.translate(glm.vec3(0.3, 1.8, 0.2)) * glm.mat4_cast(turned) * glm.scale(glm.vec3(0.5, 1.0, 1.0))
    world.step(0.05)  # z 0.2 -> -0.1: in
    (crossing,) = crossings(world)
    assert (crossing.from_portal, crossing.to_portal) == (a, b)
    def as_array(matrix):
        return np.array(glm.dmat4(matrix).to_list()).T

    # moved on 0.3, then carried: the clone's matrix
    carried = as_array(crossing.carry) @ as_array(glm.translate(glm.vec3(0, 0, -0.3))) @ as_array(model)
    q, r = np.linalg.qr(carried[:3, :3])
    signs = np.sign(np.diag(r))
    q, r = q * signs, r * signs[:, None]    # (a positive diagonal: the scale)
    assert np.abs(r[np.triu_indices(3, 1)]).max() > 0.1   # a shear
    t = world.get(ball, Transform)
    np.testing.assert_allclose(t.position, carried[:3, 3], atol=1e-5)
    np.testing.assert_allclose(t.scale, np.diag(r), atol=1e-5)
    np.testing.assert_allclose(as_array(glm.mat4_cast(t.rotation))[:3, :3], q, atol=1e-5)
    after = as_array(glm.translate(t.position) * glm.mat4_cast(t.rotation) * glm.scale(t.scale))
    np.testing.assert_allclose(after[:3, 0], carried[:3, 0], atol=1e-5)   # its x axis as carried
    assert np.abs(after - carried).max() > 0.1


def test_a_games_gravity_on_a_traveller_goes_on_from_the_velocity_a_pair_of_two_scales_carried(world):
    """The engine pulls no Traveller down (Traveller.velocity alone moves it); a game's gravity
    is its own, written into the velocity before the travel stage.  A ball falling with one
    (9.8 m/s^2, world down) into A, then on past B (scaled 2): each frame is the game's pull,
    then the move, then, where the step went into A, the carry (twice as far from B, the
    velocity turned and doubled: README), worked out here in float64 frame by frame; the
    pull after goes on from the carried velocity (the game's next write reads it), in world
    metres, not scaled again."""
    import esper

    a, b = scaled_pair(world)
    g = np.array([0.0, -9.8, 0.0])

    class Gravity(esper.Processor):
        def process(self, dt):
            for _, traveller in world.query_one(Traveller):
                traveller.velocity = traveller.velocity + glm.vec3(*g) * dt

    world.add_system(Gravity(), 90)
    # (A faces +Z: the ball comes at it from the front, arcing down through its rectangle.)
    ball = world.spawn(Transform(position=(0.2, 2.5, 1.2)), Traveller(velocity=(0.0, 0.0, -2.4)))
    p, v = np.array([0.2, 2.5, 1.2]), np.array([0.0, 0.0, -2.4])
    crossed = []
    for frame in range(60):
        world.step(DT)
        v = v + g * DT
        before, p = p, p + v * DT
        if before[2] > 0.0 >= p[2]:                   # into A's front (its rectangle: checked below)
            assert abs(p[0]) < 1.0 and abs(p[1] - 1.5) < 1.5
            p, v = np.array(carry_point_scaled(p)), 2.0 * np.array(carry_dir(v))
            crossed.append(frame)
        assert [c.entity for c in crossings(world)] == ([ball] if crossed and crossed[-1] == frame else [])
        np.testing.assert_allclose(world.get(ball, Transform).position, p, atol=2e-4)
        np.testing.assert_allclose(world.get(ball, Traveller).velocity, v, atol=2e-4)
    assert len(crossed) == 1 and world.get(ball, Transform).scale == glm.vec3(2.0)
    assert p[0] > B_POS[0] + 1.0   # flown out of B (+X) at twice the speed, falling as before
