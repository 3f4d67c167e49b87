"""Irradiance volumes (``IrradianceVolume``): a grid of light probes baked into the irradiance
table, read by the scene's light from all round.  The references are computed here, apart
from the engine: each point's light is the room around it found by casting each direction's
ray to the wall it meets, its colours projected on the harmonics in numpy; the shaded floor
is the grid's coefficients as the GPU holds them, blended between points in numpy."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from pyglm import glm

from components import (
    ComponentValueError,
    Emissive,
    HemisphereLight,
    IrradianceVolume,
    Material,
    MeshRef,
    Mirror,
    Skybox,
    Transform,
    Visibility,
)
from engine.assets.mesh import box, plane, quad
from engine.assets.portals import spawn_portal_pair
from engine.core.budget import ViewBudget
from engine.core.cube_faces import face_directions
from engine.core.errors import VolumeLimitWarning
from engine.render.irradiance import evaluate_sh, project_faces, sh_basis
from systems.irradiance_volume_system import volume_grid
from tests.support import look_from, pixel_rays, srgb_to_linear

ROOM = 1.5   # the room's inner half size: walls at +-1.5 on each axis
# Each wall's colour (unlit: its radiance), by axis and side (-, +).
WALLS = {(0, 0): (0.9, 0.1, 0.1), (0, 1): (0.1, 0.8, 0.2), (1, 0): (0.3, 0.3, 0.3),
         (1, 1): (0.9, 0.9, 0.6), (2, 0): (0.1, 0.2, 0.9), (2, 1): (0.6, 0.4, 0.1)}


def room(world, walls=WALLS, black_sky: bool = True) -> None:
    """A closed cube room of unlit walls, each a thick box whose inner face lies on the room's
    side (no sky reaches inside), under a black sky (``black_sky``)."""
    if black_sky:
        world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
    for (axis, side), colour in walls.items():
        centre = [0.0, 0.0, 0.0]
        centre[axis] = (ROOM + 0.1) * (1 if side else -1)
        size = [2 * ROOM + 0.4] * 3
        size[axis] = 0.2
        world.spawn(Transform(position=tuple(centre)), MeshRef(box(tuple(size))),
                    Material(color=(*colour, 1.0), unlit=True))


def room_light(point: np.ndarray, walls=WALLS, size: int = 64) -> np.ndarray:
    """The irradiance coefficients (9, 3) at ``point`` inside the room: every texel of a cube
    map there shows the wall its direction's ray meets first."""
    faces = np.zeros((6, size, size, 3))
    for face in range(6):
        d = face_directions(face, size)
        with np.errstate(divide="ignore"):
            t = np.where(d > 0, (ROOM - point) / d, (-ROOM - point) / d)  # each axis's wall along the ray
        t = np.where(np.abs(d) < 1e-12, np.inf, t)
        axis = np.argmin(t, axis=-1)
        side = np.take_along_axis(d, axis[..., None], -1)[..., 0] > 0
        for (a, s), colour in walls.items():
            faces[face][(axis == a) & (side == bool(s))] = colour
    return project_faces(faces)


def volume_light(runner, volume: IrradianceVolume, centre=(0.0, 0.0, 0.0)) -> np.ndarray:
    """The grid's coefficients as the GPU holds them, (x, y, z, 9, 3)."""
    return runner.engine.renderer.irradiance.read_volume(volume_grid(volume, glm.vec3(centre)))


def test_each_points_light_is_the_room_around_it(scene):
    """A 3 x 2 x 2 grid (x, y and z told apart by their counts) in a closed room of six
    coloured walls: each point's nine coefficients, captured and projected on the GPU into its
    texels of the table, are those of the room seen from the point, cast and projected in
    numpy (within 2% of the constant term's largest: the capture's 16-texel level against 64
    texels here)."""
    volume = IrradianceVolume(size=(2.0, 1.6, 1.2), points=(3, 2, 2), points_per_frame=12)

    def build(world):
        room(world)
        look_from(world, (0.0, 0.0, 1.0), (0.0, 0.0, -1.0))
        world.spawn(Transform(position=(0.2, -0.3, 0.1)), volume)
    runner = scene(build, (32, 24))
    runner.frame()
    grid = volume_grid(volume, glm.vec3(0.2, -0.3, 0.1))
    shown = runner.engine.renderer.irradiance.read_volume(grid)
    scale = max(abs(room_light(np.zeros(3))[0]).max(), 1e-6)
    worst = 0.0
    for index in np.ndindex(3, 2, 2):
        expected = room_light(np.array(grid.position(index)))
        worst = max(worst, abs(shown[index] - expected).max() / scale)
    assert worst < 0.02, worst
    # The corners differ from each other (the test would pass on one point copied everywhere).
    assert abs(shown[0, 0, 0] - shown[2, 1, 1]).max() > 0.1 * scale


def test_points_in_the_walls_are_captured_from_inside_the_room(scene):
    """A 2 x 2 x 2 grid whose corner points lie on the room's corners, in its walls: each is
    captured from a tenth of a metre inside (twice the near plane past every wall it touched),
    and its light is the room seen from there (a capture in the wall would see through it: the
    black sky outside)."""
    volume = IrradianceVolume(size=(3.0, 3.0, 3.0), points=(2, 2, 2), points_per_frame=8)

    def build(world):
        room(world)
        look_from(world, (0.0, 0.0, 1.0), (0.0, 0.0, -1.0))
        world.spawn(Transform(), volume)
    runner = scene(build, (32, 24))
    runner.frame()
    assert runner.engine.stages["volume"].points_moved == 8
    shown = volume_light(runner, volume)
    scale = abs(room_light(np.zeros(3))[0]).max()
    for index in np.ndindex(2, 2, 2):
        inside = (np.array(index) * 2.0 - 1.0) * (ROOM - 0.1)
        assert abs(shown[index] - room_light(inside)).max() < 0.02 * scale


def test_a_point_in_a_solid_box_is_moved_out_through_its_nearest_face():
    """``volume_rules.pushed_out`` against the box's own geometry: a turned, stretched box
    (2 x 1 x 0.5 m after scaling); a point in it leaves through the face nearest in metres,
    ``margin`` past it (the y faces, 0.1 m off, not the x faces 0.2 local units off: 0.4 m);
    one as near two faces leaves towards ``toward``; one nearer the face away from ``toward``
    (0.2 m against 0.3 m) leaves towards it all the same; one outside every box (and past the
    margin) stays; a point in two boxes leaves both, through a face towards ``toward``."""
    from engine.rules.volume_rules import pushed_out

    turn = glm.rotate(glm.mat4(1.0), glm.radians(30.0), glm.vec3(0.0, 1.0, 0.0))
    model = glm.translate(glm.mat4(1.0), glm.vec3(1.0, 0.0, 0.0)) * turn * glm.scale(glm.mat4(1.0),
                                                                                       glm.vec3(2.0, 1.0, 0.5))
    matrix = np.array(model.to_list()).T
    lows, highs = np.array([[-0.5, -0.5, -0.5]]), np.array([[0.5, 0.5, 0.5]])
    inverse = np.linalg.inv(matrix)

    def local(p):
        return inverse[:3, :3] @ p + inverse[:3, 3]

    def world(p):
        return matrix[:3, :3] @ p + matrix[:3, 3]

    nearest = world(np.array([0.3, 0.4, 0.0]))      # 0.1 m from the +y face
    middle = world(np.array([0.0, 0.0, 0.0]))       # 0.25 m from both z faces (and 0.5 from the y faces)
    away = world(np.array([0.0, 0.0, -0.1]))        # 0.2 m from the -z face, 0.3 m from the +z face
    outside = world(np.array([0.0, 0.0, 0.9]))
    toward = world(np.array([0.0, 3.0, 3.0]))
    moved = pushed_out(np.array([nearest, middle, away, outside]), matrix[None], lows, highs, toward, margin=0.1)
    np.testing.assert_allclose(local(moved[0]), [0.3, 0.5 + 0.1, 0.0], atol=1e-9)
    np.testing.assert_allclose(local(moved[1]), [0.0, 0.0, 0.5 + 0.1 / 0.5], atol=1e-9)
    np.testing.assert_allclose(local(moved[2]), [0.0, 0.0, 0.5 + 0.1 / 0.5], atol=1e-9)
    np.testing.assert_allclose(moved[3], outside)
    # Two overlapping axis-aligned boxes: a point in both ends outside both.
    two = np.stack([np.eye(4), np.eye(4)])
    two[1, :3, 3] = (0.8, 0.0, 0.0)
    both = pushed_out(np.array([[0.45, 0.0, 0.0]]), two, np.tile(lows, (2, 1)), np.tile(highs, (2, 1)),
                      np.array([0.6, 5.0, 0.0]), margin=0.05)[0]
    assert both[1] == pytest.approx(0.55)  # out of the first through +x, of the second through the top
    for centre in ((0.0, 0.0, 0.0), (0.8, 0.0, 0.0)):
        assert np.max(np.abs(both - centre)) > 0.5 + 0.04


def floor_scene(volume: IrradianceVolume | None, sky=(0.5, 0.5, 0.5), reflection: float = 0.0, roughness=1.0,
                camera: bool = True):
    """A white floor under a hemisphere sky, a red wall and a blue wall of light standing on
    it (unlit: their colours are their radiance), seen from above (with ``camera``); ``volume``
    centred at ``VOLUME_AT``."""
    def build(world):
        if camera:
            look_from(world, (0.0, 5.0, 2.0), (0.0, 0.0, 0.0), fov=70.0)
        world.spawn(HemisphereLight(sky=sky, ground=(0.0, 0.0, 0.0)))
        world.spawn(Transform(), MeshRef(plane(12.0, 12.0)),
                    Material(color=(1.0, 1.0, 1.0, 1.0), roughness=roughness, environment_reflection=reflection))
        world.spawn(Transform(position=(-1.5, 1.0, 0.0)), MeshRef(box((0.1, 2.0, 3.0))),
                    Material(color=(1.0, 0.2, 0.1, 1.0), unlit=True))
        world.spawn(Transform(position=(0.0, 1.0, -1.5)), MeshRef(box((3.0, 2.0, 0.1))),
                    Material(color=(0.1, 0.2, 1.0, 1.0), unlit=True))
        if volume is not None:
            world.spawn(Transform(position=VOLUME_AT), volume)
    return build


# The floor volumes' centre: a box 2 m high from 0.1 m over the floor (its lowest points above
# it; the floor within by the normal bias).
VOLUME_AT = (0.0, 1.1, 0.0)


def floor_pixels(runner, size) -> tuple[np.ndarray, np.ndarray]:
    """The floor's pixels of the runner's next frame (FXAA off): linear RGB and their points."""
    runner.engine.renderer.antialias = "off"
    runner.frame()
    shown = srgb_to_linear(runner.frame()).reshape(-1, 3)
    eye, rays = pixel_rays(runner.engine.main_view, size)
    rays = rays.reshape(-1, 3)
    t = -eye[1] / rays[:, 1]
    points = eye + rays * t[:, None]
    ids = runner.ids().reshape(-1)
    floor = ids == ids[np.argmax(t * (np.abs(points[:, 0]) < 0.5) * (np.abs(points[:, 2] - 1.0) < 0.5))]
    return shown[floor], points[floor]


def grid_at(runner, volume: IrradianceVolume, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The grid's coefficients as the GPU holds them at floor ``points`` moved up by the normal
    bias, blended between the eight points about each (trilinear, in numpy), (n, 9, 3), and the
    volume's weight there (the distance inside the box's walls over the blend distance)."""
    grid = volume_grid(volume, glm.vec3(VOLUME_AT))
    coefficients = volume_light(runner, volume, VOLUME_AT)
    low, high = np.array(grid.low), np.array(grid.high)
    q = points + np.array([0.0, volume.normal_bias, 0.0])
    counts = np.array(grid.points)
    g = np.clip((q - low) / (high - low), 0.0, 1.0) * (counts - 1)
    base = np.minimum(np.floor(g), counts - 2).astype(int)
    f = g - base
    blended = np.zeros((len(points), 9, 3))
    for corner in np.ndindex(2, 2, 2):
        weight = np.prod(np.where(np.array(corner) == 1, f, 1.0 - f), axis=1)
        i, j, k = (base + np.array(corner)).T
        blended += weight[:, None, None] * coefficients[i, j, k]
    inside = np.min(np.minimum(q - low, high - q), axis=1)
    w = np.where(inside < 0.0, 0.0, np.minimum(1.0, inside / volume.blend_distance)) if volume.blend_distance > 0 \
        else (inside >= 0.0).astype(float)
    return blended, w


def floor_from_grid(runner, volume: IrradianceVolume, points: np.ndarray, sky: float = 0.5):
    """What a white floor at ``points`` shows: the grid's E(+y) / pi by the volume's weight,
    the hemisphere sky's ``sky`` (its E(+y) / pi) by the rest; and the weights."""
    blended, w = grid_at(runner, volume, points)
    up = np.array([0.0, 1.0, 0.0])
    grid_e = np.stack([evaluate_sh(c, up) for c in blended])
    return w[:, None] * grid_e / np.pi + (1.0 - w[:, None]) * sky, w  # a white floor under the sky shows it


def test_the_floor_reads_the_grid_between_its_points(scene):
    """A white floor's light from all round, through a 4 x 2 x 3 grid with a blend distance:
    the grid's coefficients as the GPU holds them, at each floor point moved up by the normal
    bias, blended between the eight points about it (trilinear, in numpy) and weighed against
    the sky by the distance inside the box's walls, then E(+y) / pi: within 0.02 of each
    pixel's colour, in 99% of the floor's pixels (the rest on the box's edges and the walls'
    feet, where a pixel straddles them)."""
    size = (96, 72)
    volume = IrradianceVolume(size=(3.0, 2.0, 3.0), points=(4, 2, 3), points_per_frame=24, blend_distance=0.15,
                              normal_bias=0.3)
    runner = scene(floor_scene(volume), size)
    shown, points = floor_pixels(runner, size)
    expected, w = floor_from_grid(runner, volume, points)
    error = np.abs(shown - expected).max(axis=1)
    assert np.mean(error < 0.02) > 0.99, (np.mean(error < 0.02), np.percentile(error, 99))
    # The grid's light is not one colour: the floor by the red wall (x = -1.5) is redder than
    # by the blue one (z = -1.5).
    near_red = (w > 0.99) & (points[:, 0] < -1.0) & (np.abs(points[:, 2]) < 0.5)
    near_blue = (w > 0.99) & (points[:, 2] < -1.0) & (np.abs(points[:, 0]) < 0.5)
    redness = shown[:, 0] - shown[:, 2]
    assert near_red.sum() > 10 and near_blue.sum() > 10
    assert redness[near_red].mean() > redness[near_blue].mean() + 0.1


# A mirror or portal B standing on the floor at z = 1.6 (out of the volume's box), facing the
# room (-z); the eye whose view B shows: the camera's image in the mirror, or the camera
# carried through the pair (portal A far off along +x, facing +x).
SURFACE_AT, SURFACE_SIZE = glm.vec3(0.0, 0.75, 1.6), (3.2, 1.3)
FACING_ROOM = glm.angleAxis(glm.pi(), glm.vec3(0.0, 1.0, 0.0))
SEEN_FROM, SEEN_AT = glm.vec3(0.0, 3.2, 4.2), glm.vec3(0.0, 0.3, 0.6)
PORTAL_A, PORTAL_A_TURN = glm.vec3(12.0, 0.75, 0.0), glm.angleAxis(glm.pi() / 2, glm.vec3(0.0, 1.0, 0.0))


def _carried_to_b(point) -> glm.vec3:
    """The point before portal A that the pair carries to ``point`` (B's local (x, y, z) is A's
    (-x, y, -z): spawn_portal_pair)."""
    half_turn = glm.angleAxis(glm.pi(), glm.vec3(0.0, 1.0, 0.0))
    at_a = glm.translate(PORTAL_A) * glm.mat4_cast(PORTAL_A_TURN) * glm.mat4_cast(half_turn)
    at_b = glm.translate(SURFACE_AT) * glm.mat4_cast(FACING_ROOM)
    return glm.vec3(at_a * glm.inverse(at_b) * glm.vec4(glm.vec3(point), 1.0))


@pytest.mark.parametrize("way", ["mirror", "portal"])
def test_the_floor_in_a_mirror_or_through_a_portal_reads_the_grid_as_seen_directly(scene, way):
    """The floor of ``test_the_floor_reads_the_grid_between_its_points`` seen in a mirror, or
    through a portal pair, whose surface stands outside the volume: each of the surface's floor
    pixels is the floor point its ray meets after the surface (the eye's image in the mirror's
    plane, or carried through the pair, cast in numpy to y = 0), lit as a floor seen directly:
    the grid's read-back coefficients blended there in numpy, E(+y) / pi, weighed against the
    sky.  The grid's light is there: the floor near the red wall (x < -0.8) is redder than far
    from it (x > 0.8).  (The surfaces are left out of the captures.)"""
    size = (80, 60)
    volume = IrradianceVolume(size=(3.0, 2.0, 3.0), points=(4, 2, 3), points_per_frame=24, blend_distance=0.15,
                              normal_bias=0.3)
    floor_build = floor_scene(volume, camera=False)
    names = {}

    def build(world):
        floor_build(world)
        hidden = Visibility(in_probes=False)
        if way == "mirror":
            look_from(world, tuple(SEEN_FROM * glm.vec3(1.0, 1.0, -1.0) + glm.vec3(0.0, 0.0, 2.0 * SURFACE_AT.z)),
                      tuple(SEEN_AT * glm.vec3(1.0, 1.0, -1.0) + glm.vec3(0.0, 0.0, 2.0 * SURFACE_AT.z)), fov=60.0)
            names["surface"] = world.spawn(Transform(position=SURFACE_AT, rotation=FACING_ROOM),
                                           MeshRef(quad(*SURFACE_SIZE)), Material(), Mirror(), hidden)
        else:
            look_from(world, tuple(_carried_to_b(SEEN_FROM)), tuple(_carried_to_b(SEEN_AT)), fov=60.0)
            a, b = spawn_portal_pair(world, PORTAL_A, PORTAL_A_TURN, SURFACE_AT, FACING_ROOM, size=SURFACE_SIZE)
            world.add_component(a, hidden)
            world.add_component(b, Visibility(in_probes=False))
            names["surface"] = a

    runner = scene(build, size)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    shown = srgb_to_linear(runner.frame()).reshape(-1, 3)
    assert runner.stats.reflection_views >= 1
    inside = runner.engine.renderer.targets.read_surface_ids() == names["surface"]
    shrunk = inside.copy()  # a pixel in from the outline
    shrunk[1:, :] &= inside[:-1, :]
    shrunk[:-1, :] &= inside[1:, :]
    shrunk[:, 1:] &= inside[:, :-1]
    shrunk[:, :-1] &= inside[:, 1:]
    # Each pixel's ray from the eye B's view is seen from (the camera's ray carried past B).
    eye, rays = pixel_rays(runner.engine.main_view, size)
    rays = rays.reshape(-1, 3)
    if way == "mirror":
        flip = np.array([1.0, 1.0, -1.0])
        eye, rays = eye * flip + np.array([0.0, 0.0, 2.0 * SURFACE_AT.z]), rays * flip
    else:
        eye = np.array(SEEN_FROM)
        carry = np.array(glm.inverse(glm.mat3(glm.mat4_cast(PORTAL_A_TURN) * glm.mat4_cast(FACING_ROOM))).to_list()).T
        rays = rays @ (carry @ np.diag([-1.0, 1.0, -1.0])).T
    points = eye + rays * (-eye[1] / rays[:, 1])[:, None]
    # The floor's pixels: in from the surface's outline, clear of the walls and their feet.
    floor = shrunk.reshape(-1) & (points[:, 0] > -1.3) & (points[:, 2] > -1.3) & (rays[:, 1] < 0.0)
    assert floor.sum() > 400, floor.sum()
    expected, w = floor_from_grid(runner, volume, points[floor])
    error = np.abs(shown[floor] - expected).max(axis=1)
    assert np.mean(error < 0.02) > 0.98, (np.mean(error < 0.02), np.percentile(error, 99))
    redness = shown[floor][:, 0] - shown[floor][:, 2]
    near_red = (w > 0.99) & (points[floor][:, 0] < -0.8)
    far_from_it = (w > 0.99) & (points[floor][:, 0] > 0.8)
    assert near_red.sum() > 10 and far_from_it.sum() > 10, (near_red.sum(), far_from_it.sum())
    assert redness[near_red].mean() > redness[far_from_it].mean() + 0.1


def test_a_dark_room_dims_the_skys_reflection(scene):
    """A polished floor inside a closed black room under a bright sky reflects the sky where
    nothing says the room is dark; with a volume whose captures see the black walls (its points
    on the room's corners, so captured from just inside them), its reflection is the grid's
    light over the sky's (Unreal's and HDRP's normalisation): nothing."""
    black = {key: (0.0, 0.0, 0.0) for key in WALLS}

    def build(with_volume):
        def make(world):
            room(world, black, black_sky=False)
            world.spawn(HemisphereLight(sky=(2.0, 2.0, 2.0), ground=(2.0, 2.0, 2.0)))
            world.spawn(Transform(position=(0.0, 0.01 - ROOM, 0.0)), MeshRef(plane(3.0, 3.0)),
                        Material(color=(1.0, 1.0, 1.0, 1.0), metallic=1.0, roughness=0.2),
                        Visibility(in_probes=False))  # (the captures see the black room alone)
            look_from(world, (0.0, 0.0, 1.2), (0.0, -ROOM, 0.0))
            if with_volume:
                world.spawn(Transform(), IrradianceVolume(size=(3.0, 3.0, 3.0), points=(2, 2, 2), points_per_frame=8))
        return make
    bright = scene(build(False), (48, 36))
    bright.frame()
    plain = srgb_to_linear(bright.frame()).mean()
    dark = scene(build(True), (48, 36))
    dark.frame()
    dimmed = srgb_to_linear(dark.frame()).mean()
    assert plain > 0.3
    assert dimmed < 0.03 * plain, (dimmed, plain)


def test_the_skys_reflection_is_scaled_by_the_grids_light_over_the_skys_along_the_reflected_ray(scene):
    """A smooth white metal floor (no diffuse light: its reflection alone) under a uniform sky of
    radiance S, the red and blue walls of light standing on it, seen low so the reflected rays
    lean towards the walls: without a volume each pixel shows the sky's reflection; with one, that
    times (1 - w) + w E(r) / (pi S), E the grid's read-back coefficients blended at the pixel's
    floor point (moved up by the normal bias) and evaluated along the reflected ray r (in numpy),
    pi S the sky's irradiance, w the volume's weight.  Along the normal instead of r the answer
    differs by more than the tolerance at most pixels (the test tells them apart)."""
    size = (80, 60)
    sky = 0.8
    eye = np.array([0.0, 2.2, 3.2])

    def build(volume):
        def make(world):
            look_from(world, tuple(eye), (0.0, 0.0, -0.6), fov=60.0)
            floor_scene(volume, camera=False)(world)
            world.spawn(Skybox(faces=np.full((6, 4, 4, 3), sky, np.float32)))
            floor = world.query_one(MeshRef)  # (the floor is the first mesh floor_scene spawns)
            world.get(floor[0][0], Material).metallic = 1.0
            world.get(floor[0][0], Material).roughness = 0.1
            world.get(floor[0][0], Material).environment_reflection = 1.0
        return make

    plain_shown, points = floor_pixels(scene(build(None), size), size)
    volume = IrradianceVolume(size=(3.0, 2.0, 3.0), points=(4, 2, 3), points_per_frame=24, blend_distance=0.15,
                              normal_bias=0.3)
    runner = scene(build(volume), size)
    shown, same_points = floor_pixels(runner, size)
    np.testing.assert_allclose(same_points, points)
    assert np.median(plain_shown) > 0.5 * sky  # the sky's reflection, bright
    view = points - eye
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    reflected = view * np.array([1.0, -1.0, 1.0])
    blended, w = grid_at(runner, volume, points)
    along_r = np.einsum("nk,nkc->nc", sh_basis(reflected), blended)
    along_n = np.einsum("k,nkc->nc", sh_basis(np.array([0.0, 1.0, 0.0])), blended)
    expected = plain_shown * ((1.0 - w)[:, None] + w[:, None] * along_r / (np.pi * sky))
    error = np.abs(shown - expected).max(axis=1)
    assert np.mean(error < 0.02) > 0.98, (np.mean(error < 0.02), np.percentile(error, 99))
    # The grid is darker than the sky here, and not the same along the normal.
    inside = w > 0.99
    assert inside.sum() > 300 and np.median(shown[inside] / plain_shown[inside], axis=0)[1] < 0.8
    wrong = plain_shown * ((1.0 - w)[:, None] + w[:, None] * along_n / (np.pi * sky))
    assert np.mean(np.abs(wrong - expected).max(axis=1)[inside] > 0.05) > 0.5


def test_the_bake_takes_points_per_frame_under_the_view_budget_and_lights_once_whole(scene):
    """Twelve points, five a frame: three frames of captures (5, 5, 2), the grid lighting the
    scene only from the third (the IRRADIANCE_VOLUME builds with it); then nothing more is
    captured ("once").  Under a budget of 12 views, two points a frame; under a capture time of
    a microsecond (``ViewBudget.probe_ms``), one."""
    volume = IrradianceVolume(size=(2.0, 2.0, 2.0), points=(3, 2, 2), points_per_frame=5)
    runner = scene(floor_scene(volume), (32, 24))
    renderer = runner.engine.renderer
    counts, lit = [], []
    for _ in range(5):
        runner.frame()
        counts.append(runner.stats.volume_points)
        lit.append(bool(renderer.irradiance.volumes))
    assert counts == [5, 5, 2, 0, 0]
    assert lit == [False, False, True, True, True]
    assert ("IRRADIANCE_VOLUME", "1") in renderer.ambient_defines
    assert runner.stats.view_budget is None

    volume_budget = IrradianceVolume(size=(2.0, 2.0, 2.0), points=(3, 2, 2), points_per_frame=5)
    limited = scene(floor_scene(volume_budget), (32, 24))
    limited.world.resources[ViewBudget] = ViewBudget(views=12)
    limited.frame()
    assert limited.stats.volume_points == 2 and limited.stats.views_spent <= 12
    # Within the frame's capture time: a microsecond's budget leaves one point a frame.
    timed = scene(floor_scene(IrradianceVolume(size=(2.0, 2.0, 2.0), points=(3, 2, 2), points_per_frame=5)),
                  (32, 24))
    timed.world.resources[ViewBudget] = ViewBudget(probe_ms=0.001)
    timed.frame()
    assert timed.stats.volume_points == 1 and timed.stats.probe_ms_spent > 0.001


def test_moving_the_volume_bakes_it_again_and_its_blend_alone_does_not(scene):
    """Moved, the volume's grid is captured whole again (not lighting the scene meanwhile);
    a new blend distance or normal bias reaches the block with no capture."""
    volume = IrradianceVolume(size=(2.0, 2.0, 2.0), points=(2, 2, 2), points_per_frame=4)
    runner = scene(floor_scene(volume), (32, 24))
    table = runner.engine.renderer.irradiance
    runner.frame()
    runner.frame()
    assert table.volumes
    entity = runner.world.query_one(IrradianceVolume)[0][0]
    runner.world.get(entity, Transform).position = glm.vec3(0.5, 0.0, 0.0)
    runner.frame()
    assert runner.stats.volume_points == 4 and not table.volumes
    runner.frame()
    assert table.volumes[0].low[0] == pytest.approx(-0.5)
    volume.blend_distance = 0.3
    volume.normal_bias = 0.2
    runner.frame()
    assert runner.stats.volume_points == 0
    assert (table.volumes[0].blend, table.volumes[0].normal_bias) == (pytest.approx(0.3), pytest.approx(0.2))


def test_a_bake_again_gives_the_same_light_and_continuous_keeps_capturing(scene):
    """The captures see neither the grid nor the probes' light (one bounce), so a bake after
    ``request()`` writes the coefficients the first wrote, while the grid lights the scene; a
    "continuous" volume captures every frame."""
    volume = IrradianceVolume(size=(2.0, 2.0, 2.0), points=(2, 2, 2), points_per_frame=8)
    runner = scene(floor_scene(volume), (32, 24))
    runner.frame()
    first = volume_light(runner, volume)
    volume.request()
    runner.frame()
    assert runner.stats.volume_points == 8 and runner.engine.renderer.irradiance.volumes
    np.testing.assert_allclose(volume_light(runner, volume), first, rtol=1e-5, atol=1e-6)
    assert np.abs(first).max() > 0.1
    volume.refresh = "continuous"
    volume.points_per_frame = 3
    captured = []
    for _ in range(3):
        runner.frame()
        captured.append(runner.stats.volume_points)
    assert captured == [3, 3, 2] or captured == [3, 3, 3]


def _furnace(world, albedo: float, volume: IrradianceVolume) -> None:
    """The closed room with every wall grey ``albedo``, rough and glowing its own colour
    (``Emissive``: radiance ``albedo``), under a black sky, the volume filling it."""
    room(world, walls=dict.fromkeys(WALLS, (albedo,) * 3))
    for entity, material in world.query_one(Material):
        material.unlit, material.roughness, material.metallic = False, 1.0, 0.0
        world.add_component(entity, Emissive(power=1.0))
    look_from(world, (0.0, 0.0, 1.0), (0.0, 0.0, -1.0))
    world.spawn(Transform(), volume)


def test_each_bounce_is_a_round_lit_by_the_last_a_furnace_sums_the_series(scene):
    """A furnace: a closed room whose walls glow e (their albedo a) and reflect a of the
    light they take.  Round 1 sees the walls' glow, e; each later round sees the walls lit by
    the grid as the round before left it, e + r x (the last round's light), r the walls'
    diffuse reflectance as the scene shader has it (a, less what its Fresnel term keeps for
    the specular).  So the grid's light after n rounds is e (1 + r + ... + r^(n-1)): the
    steps between rounds fall by r each time, and r is the albedo within the Fresnel's share."""
    albedo = 0.6
    volume = IrradianceVolume(size=(3.0, 3.0, 3.0), points=(2, 2, 2), points_per_frame=8, bounces=4, near=0.02)
    runner = scene(lambda world: _furnace(world, albedo, volume), (32, 24))
    table = runner.engine.renderer.irradiance
    light = []   # the grid's constant coefficient after each round (every point alike)
    for _ in range(4):
        runner.frame()
        assert runner.stats.volume_points == 8
        grid = volume_light(runner, volume)[..., 0, :]
        assert np.allclose(grid, grid[0, 0, 0], rtol=0.01), grid   # (uniform: the furnace)
        light.append(float(grid.mean()))
    runner.frame()
    assert runner.stats.volume_points == 0 and table.bounce_copies == 0   # four rounds: done, its copy let go
    glow = room_light(np.zeros(3), walls=dict.fromkeys(WALLS, (albedo,) * 3))[0].mean()
    assert light[0] == pytest.approx(glow, rel=0.02)   # round 1: the glow alone
    steps = np.diff([0.0, *light])
    ratios = steps[1:] / steps[:-1]
    assert np.allclose(ratios, ratios[0], rtol=0.03), ratios   # a geometric series
    assert albedo * 0.9 < ratios[0] <= albedo * 1.001, ratios  # r: the albedo less the specular's share
    # Fewer bounces bake it again (one: the default, which stops after its round); more add rounds.
    volume.bounces = 1
    runner.frame()
    assert runner.stats.volume_points == 8
    runner.frame()
    assert runner.stats.volume_points == 0
    assert float(volume_light(runner, volume)[..., 0, :].mean()) == pytest.approx(light[0], rel=1e-4)
    volume.bounces = 2
    runner.frame()
    assert runner.stats.volume_points == 8
    assert float(volume_light(runner, volume)[..., 0, :].mean()) == pytest.approx(light[1], rel=1e-3)


def test_a_continuous_volume_with_bounces_settles_to_every_bounce(scene):
    """``continuous`` with ``bounces`` above 1: every round after the first is lit by the
    last, so the furnace's light climbs towards e / (1 - r)."""
    volume = IrradianceVolume(size=(3.0, 3.0, 3.0), points=(2, 2, 2), points_per_frame=8, bounces=2,
                              refresh="continuous", near=0.02)
    runner = scene(lambda world: _furnace(world, 0.5, volume), (32, 24))
    light = []
    for _ in range(8):
        runner.frame()
        light.append(float(volume_light(runner, volume)[..., 0, :].mean()))
    assert all(b > a for a, b in zip(light, light[1:], strict=False)), light
    assert light[-1] > 1.9 * light[0] * 0.95 and light[-1] - light[-2] < 0.02 * light[-1], light
    # Removed with a round under way (two points a frame): its copy of the table goes with it.
    volume.points_per_frame = 2
    runner.frame()
    table = runner.engine.renderer.irradiance
    assert table.bounce_copies == 1 == runner.engine.renderer.resource_counts()["bounce_copies"]
    runner.world.delete_entity(next(e for e, _ in runner.world.query_one(IrradianceVolume)))
    runner.frame()
    assert table.bounce_copies == 0 and not table.volumes
    assert runner.engine.renderer.resource_counts()["bounce_copies"] == 0


def test_a_scripted_volume_bakes_only_when_asked(scene):
    """``refresh="scripted"``: nothing captured until ``request()``, then the whole grid (a
    request made before its first frame too)."""
    volume = IrradianceVolume(size=(2.0, 2.0, 2.0), points=(2, 2, 2), points_per_frame=8, refresh="scripted")
    runner = scene(floor_scene(volume), (32, 24))
    runner.frame()
    runner.frame()
    assert runner.stats.volume_points == 0 and not runner.engine.renderer.irradiance.volumes
    volume.request()
    runner.frame()
    assert runner.stats.volume_points == 8 and runner.engine.renderer.irradiance.volumes
    # A request made before the volume's first frame asks for that bake too.
    asked = IrradianceVolume(size=(2.0, 2.0, 2.0), points=(2, 2, 2), points_per_frame=8, refresh="scripted")
    asked.request()
    runner = scene(floor_scene(asked), (32, 24))
    runner.frame()
    assert runner.stats.volume_points == 8
    runner.frame()
    assert runner.stats.volume_points == 0


def test_removing_the_volume_releases_its_cube_and_its_light(scene):
    volume = IrradianceVolume(size=(2.0, 2.0, 2.0), points=(2, 2, 2), points_per_frame=8)
    runner = scene(floor_scene(volume), (32, 24))
    renderer = runner.engine.renderer
    runner.frame()
    entity = runner.world.query_one(IrradianceVolume)[0][0]
    assert -entity in renderer.probe_cubes and renderer.irradiance.volumes
    runner.world.delete_entity(entity)
    runner.frame()
    assert -entity not in renderer.probe_cubes
    assert not renderer.irradiance.volumes and renderer.ambient_defines == ()


def test_volumes_light_their_own_rooms_and_a_fifth_is_said_and_ignored(scene):
    """Two rooms side by side (open above, under a black sky), one with red walls and one with
    blue, a volume filling each: each volume's coefficients are its own room's (its slot of
    the table), and each white floor's light is its room's colour.  Five volumes: the lowest
    four light, the fifth is said once (``VolumeLimitWarning``) and captures nothing."""
    floors: list[int] = []

    def two_rooms(count):
        def build(world):
            world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
            for x, colour in ((-2.0, (0.8, 0.1, 0.1)), (2.0, (0.1, 0.1, 0.8))):
                for axis, side in ((0, -1), (0, 1), (2, -1), (2, 1)):   # (open above: the eye sees the floor)
                    centre = [x, 1.0, 0.0]
                    centre[axis] += 1.05 * side
                    size = [2.2, 2.2, 2.2]
                    size[axis] = 0.1
                    world.spawn(Transform(position=tuple(centre)), MeshRef(box(tuple(size))),
                                Material(color=(*colour, 1.0), unlit=True))
                floors.append(world.spawn(Transform(position=(x, 0.0, 0.0)), MeshRef(plane(2.0, 2.0)),
                                          Material(color=(1.0, 1.0, 1.0, 1.0), roughness=1.0,
                                                   environment_reflection=0.0)))
            for k in range(count):
                world.spawn(Transform(position=(-2.0 if k == 0 else 2.0 + 10.0 * (k - 1), 1.0, 0.0)),
                            IrradianceVolume(size=(1.8, 1.9, 1.8), points=(2, 2, 2), points_per_frame=8))
            look_from(world, (0.0, 6.0, 0.5), (0.0, 0.0, 0.0), fov=70.0)
        return build

    runner = scene(two_rooms(2), (96, 48))
    runner.frame()
    table = runner.engine.renderer.irradiance
    assert sorted(table.volumes) == [0, 1]
    for slot, (red, blue) in ((0, (0, 2)), (1, (2, 0))):
        light = table.read_volume(table.volumes[slot])
        assert (light[..., 0, red] > 2.0 * light[..., 0, blue]).all()   # each point's own room's colour
    image = srgb_to_linear(runner.frame())
    shown = []
    for x, floor in zip((-2.0, 2.0), floors[:2], strict=True):
        column, row = runner.project((x, 0.0, 0.3))
        assert (runner.ids()[row - 2:row + 3, column - 2:column + 3] == floor).all()
        shown.append(image[row - 2:row + 3, column - 2:column + 3].reshape(-1, 3).mean(0))
    left, right = shown
    assert left.max() > 0.05 and right.max() > 0.05
    assert left[0] > 2.0 * left[2] and right[2] > 2.0 * right[0], (left, right)

    crowded = scene(two_rooms(5), (48, 24))
    with pytest.warns(VolumeLimitWarning, match="at most 4 light a world"):
        crowded.frame()
    assert crowded.stats.volume_points == 32 and len(crowded.engine.renderer.irradiance.volumes) == 4
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        crowded.frame()  # said once


@pytest.mark.parametrize("field, value, match", [
    ("points", (1, 2, 2), r"points must be an int in \[2, 16\]"),
    ("points", (2, 2), "three ints"),
    ("points", (2, 2, 17), r"\[2, 16\]"),
    ("size", (1.0, 0.0, 1.0), r"every side in \(0, 1e5\]"),
    ("resolution", 24, "power of two"),
    ("resolution", 8, r"\[16, 128\]"),
    ("normal_bias", -0.1, ">= 0"),
    ("refresh", "sometimes", "must be one of"),
    ("points_per_frame", 0, r"\[1, 4096\]"),
    ("bounces", 0, r"\[1, 8\]"),
    ("bounces", 9, r"\[1, 8\]"),
    ("blend_distance", 3.0, "at most half the box's smallest side"),
])
def test_values_are_checked(field, value, match):
    with pytest.raises(ComponentValueError, match=match):
        IrradianceVolume(**{field: value})
    volume = IrradianceVolume()
    with pytest.raises(ComponentValueError, match=match):
        setattr(volume, field, value)


def test_a_level_file_keeps_a_volume(tmp_path):
    from tests.support import entity_level_round_trip

    again, entity = entity_level_round_trip(
        tmp_path, "Transform = { position = [0.0, 1.5, 0.0] }\nIrradianceVolume = { size = [6.0, 3.0, 4.0], "
        'points = [6, 3, 4], blend_distance = 0.5, refresh = "continuous" }\n',
        ("points = [6, 3, 4]", "points = [6, 3, 40]"), "points")
    volume = again.get(entity, IrradianceVolume)
    assert (tuple(volume.size), volume.points, volume.blend_distance, volume.refresh) == \
        ((6.0, 3.0, 4.0), (6, 3, 4), 0.5, "continuous")


def test_the_editor_outlines_the_volumes_box_and_marks_it():
    """``reach_outline`` of a selected volume (shell/handles.py): the twelve edges of its box
    about its entity, whose corners are the grid's corner points, and twelve of the box
    ``blend_distance`` inside; ``markers`` marks it (it has no mesh to click)."""
    from engine.core.world import World
    from shell.handles import markers, reach_outline
    from systems.transform_system import TransformSystem

    world = World("volume-outline")
    world.add_system(TransformSystem(world), priority=1)
    volume = IrradianceVolume(size=(4.0, 2.0, 6.0), points=(3, 2, 4), blend_distance=0.5)
    entity = world.spawn(Transform(position=(1.0, 1.0, -2.0)), volume)
    world.step(1 / 60)
    view_proj = glm.perspective(glm.radians(60.0), 1.0, 0.1, 100.0) * glm.lookAt(
        glm.vec3(2.0, 6.0, 12.0), glm.vec3(1.0, 1.0, -2.0), glm.vec3(0.0, 1.0, 0.0))
    outline = reach_outline(world, entity, view_proj, (640, 480))
    assert len(outline.world) == 24
    grid = volume_grid(volume, glm.vec3(1.0, 1.0, -2.0))
    corners = {tuple(round(v, 6) for v in grid.position((i, j, k))) for i in (0, 2) for j in (0, 1) for k in (0, 3)}
    inside = {(round(1.0 + x, 6), round(1.0 + y, 6), round(-2.0 + z, 6))
              for x in (-1.5, 1.5) for y in (-0.5, 0.5) for z in (-2.5, 2.5)}   # half the size less the blend
    outer = {tuple(round(float(v), 6) for v in p) for edge in outline.world[:12] for p in edge}
    inner = {tuple(round(float(v), 6) for v in p) for edge in outline.world[12:] for p in edge}
    assert outer == corners and inner == inside
    assert [m.kind for m in markers(world, view_proj, (640, 480)) if m.entity == entity] == ["volume"]
    world.close()


@pytest.mark.parametrize("refresh", ["once", "scripted"])
def test_a_bake_that_showed_a_screen_before_its_first_picture_is_baked_again(scene, refresh):
    """The closed room with a screen on its floor facing up, its monitor's camera inside
    looking at the yellow wall.  The volume's first bake (all its points on the first frame)
    is drawn before the monitors: the screen black in it.  The next frame the picture is there
    and the bake is taken again (``PicturesDrawn.first``): the grid then equals the first bake
    of a volume made only after the picture was drawn, and differs from the black screen's
    where the screen's light reaches."""
    from components import Camera, Monitor
    from engine.assets.mesh import quad

    volume_at = (0.0, 0.0, 0.0)

    def build(world, with_volume: bool, held: dict):
        room(world)
        look_from(world, (0.0, 0.0, 1.0), (0.0, 0.0, -1.0))
        lens = look_from(world, (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), fov=60.0)   # the yellow wall, above
        world.get(lens, Camera).active = False
        world.spawn(Transform(position=(0.0, -ROOM + 0.01, 0.0), rotation=glm.angleAxis(-np.pi / 2, glm.vec3(1, 0, 0))),
                    MeshRef(quad(2.0, 2.0)), Material(color=(0.0, 0.0, 0.0, 1.0), roughness=1.0),
                    Monitor(camera=lens, size=(32, 32), brightness=4.0))
        if with_volume:
            held["volume"] = IrradianceVolume(size=(2.0, 1.6, 1.2), points=(3, 2, 2), points_per_frame=12,
                                              refresh=refresh)
            world.spawn(Transform(position=volume_at), held["volume"])
            if refresh == "scripted":
                held["volume"].request()

    early, late = {}, {}
    runner = scene(lambda world: build(world, True, early), (32, 24))
    twin = scene(lambda world: build(world, False, late), (32, 24))
    runner.frame()
    twin.frame()
    black = volume_light(runner, early["volume"], volume_at).copy()
    late["volume"] = IrradianceVolume(size=(2.0, 1.6, 1.2), points=(3, 2, 2), points_per_frame=12, refresh=refresh)
    twin.world.spawn(Transform(position=volume_at), late["volume"])
    if refresh == "scripted":
        late["volume"].request()
    runner.frame()
    twin.frame()
    assert runner.stats.volume_points == 12 and twin.stats.volume_points == 12, twin.stats.volume_points
    baked = volume_light(runner, early["volume"], volume_at)
    np.testing.assert_allclose(baked, volume_light(twin, late["volume"], volume_at), atol=1e-5)
    assert abs(baked[:, 0] - black[:, 0]).max() > 0.1   # the lower points see the lit screen below them
    runner.frame()
    assert runner.stats.volume_points == 0   # (once: nothing more)
