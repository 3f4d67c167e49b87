"""Water (components.Water on a Mirror): the reflection weighted by Schlick's Fresnel for the
water's index, the waves' normal map moving at its speed, and what lies below seen through
the surface.  Each is measured in rendered frames against the formula or a second render."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    ComponentValueError,
    Emissive,
    Material,
    MeshRef,
    Mirror,
    Skybox,
    Transform,
    Water,
    look_rotation,
)
from engine.assets.level_file import LevelError, load_level, save_level
from engine.assets.mesh import box, quad
from engine.assets.texture_data import TextureData
from engine.core.cube_faces import face_directions
from engine.core.world import World
from tests.support import srgb_to_linear

# A quad faces +Z; turned this way it lies flat, facing up (its U along +X, V along -Z).
FLAT = glm.angleAxis(-math.pi / 2, glm.vec3(1, 0, 0))
SKY = 0.8      # the uniform sky's linear radiance: all the water reflects
FLOOR = 0.05   # the pool floor's emitted colour (linear), under the surface
# What the floor shows: its emission plus the uniform sky's ambient light (a white surface
# under a sky of radiance SKY shows SKY: engine/render/irradiance.py), both times its colour
# (it reflects none of the sky: the same colour from every direction).
FLOOR_SEEN = FLOOR * (1.0 + SKY)


def schlick(f0: float, cos_theta: float) -> float:
    return f0 + (1.0 - f0) * (1.0 - cos_theta) ** 5


def uniform_sky(value: float) -> Skybox:
    return Skybox(faces=[np.full((8, 8, 3), value, np.float32) for _ in range(6)])


def pool(world, water: bool, eye, target, *, water_colour=(1.0, 1.0, 1.0, 0.0), ior: float = 1.333,
         reflect_rate: float = 1.0, tint=(1.0, 1.0, 1.0)) -> None:
    """A uniform sky over a flat pond at y = 0 (a clear water surface unless ``water_colour``
    says otherwise, its reflection tinted ``tint``: ``Mirror.color``) with a floor of colour
    FLOOR a metre below it, lit by no light but the sky's ambient light."""
    eye = glm.vec3(eye)
    world.spawn(Transform(position=eye, rotation=look_rotation(glm.vec3(target) - eye)), Camera(fov_y=60.0))
    world.spawn(uniform_sky(SKY))
    world.spawn(Transform(position=(0.0, -1.0, 0.0), rotation=FLAT), MeshRef(quad(200.0, 200.0)),
                Material(color=(FLOOR, FLOOR, FLOOR, 1.0), roughness=1.0, environment_reflection=0.0), Emissive(1.0))
    if water:
        world.spawn(Transform(rotation=FLAT), MeshRef(quad(200.0, 200.0)), Material(color=water_colour),
                    Mirror(reflect_rate=reflect_rate, color=tint), Water(ior=ior))


def render(scene, build, size=(64, 96), frames: int = 2, dt: float = 1.0 / 60.0):
    runner = scene(build, size)
    runner.engine.renderer.antialias = "off"  # pixels as shaded: no filter across the water's rows
    for _ in range(frames):
        rgb = runner.frame(dt)
    return runner, srgb_to_linear(rgb)


def pixel_rays(runner, column: int) -> list[tuple[int, float]]:
    """(row, cosine between the eye ray and the water's up normal) for each row of a column
    whose pixel centre's ray meets the water plane y = 0 in front of the eye."""
    view = runner.engine.main_view
    inverse = glm.inverse(view.view_proj)
    w, h = runner.size
    out = []
    for row in range(h):
        ndc = glm.vec4((column + 0.5) / w * 2.0 - 1.0, 1.0 - (row + 0.5) / h * 2.0, -1.0, 1.0)
        near = inverse * ndc
        direction = glm.normalize(glm.vec3(near) / near.w - view.eye)
        if direction.y < -1e-3:
            out.append((row, -direction.y))
    return out


@pytest.mark.parametrize("eye, target", [((0.0, 3.0, 0.0), (0.0, 0.0, -0.6)),      # looking down
                                         ((0.0, 0.4, 0.0), (0.0, 0.05, -10.0))])  # grazing
def test_the_reflection_is_weighted_by_schlicks_fresnel_for_the_waters_index(scene, eye, target):
    """Over a uniform sky, a pixel of clear water is F x sky + (1 - F) x what is below, F by
    Schlick's formula at the pixel's angle with F0 = ((n - 1) / (n + 1))^2; the floor's
    colour is the same frame without the water, pixel for pixel."""
    runner_water, water = render(scene, lambda w: pool(w, True, eye, target))
    runner_floor, floor = render(scene, lambda w: pool(w, False, eye, target))
    f0 = ((1.333 - 1.0) / (1.333 + 1.0)) ** 2
    column = runner_water.size[0] // 2
    rays = pixel_rays(runner_water, column)
    assert len(rays) > 20
    measured, expected = [], []
    for row, cos_theta in rays:
        if cos_theta > 0.999 or cos_theta < 0.02:
            continue
        below = floor[row, column, 0]
        assert abs(below - FLOOR_SEEN) < 0.02, (row, below)  # the floor shows where there is no water
        measured.append((water[row, column, 0] - below) / (SKY - below))
        expected.append(schlick(f0, cos_theta))
    measured, expected = np.array(measured), np.array(expected)
    # 8-bit sRGB steps: at most 0.004 of weight near the floor's dark colour, 0.01 near the sky's.
    np.testing.assert_allclose(measured, expected, atol=0.012)
    if eye[1] > 1.0:
        assert expected.max() < 0.03  # straight down: a few percent, the floor shows
    else:
        assert expected.max() > 0.5   # grazing: the reflection dominates


@pytest.mark.parametrize("ior, reflect_rate, tint", [(1.5, 1.0, (1.0, 1.0, 1.0)), (2.0, 1.0, (1.0, 1.0, 1.0)),
                                                     (2.0, 0.5, (1.0, 0.5, 0.1))])
def test_the_weight_follows_the_index_and_reflect_rate_scales_it(scene, ior, reflect_rate, tint):
    """Looking straight down the weight is F0 for the index given (0.04 for glass's 1.5, 1/9
    for 2), not a constant, times the Mirror's reflect_rate; the Mirror's colour tints what
    is reflected, channel by channel (F x tint x sky over (1 - F) x what is below)."""
    eye, target = (0.0, 3.0, 0.0), (0.0, 0.0, -0.01)
    runner, water = render(scene, lambda w: pool(w, True, eye, target, ior=ior, reflect_rate=reflect_rate, tint=tint))
    _, floor = render(scene, lambda w: pool(w, False, eye, target))
    col, row = runner.project((0.0, 0.0, 0.0))  # straight below the eye: normal incidence
    weight = (water[row, col, 0] - floor[row, col, 0]) / (SKY - floor[row, col, 0])
    f = reflect_rate * ((ior - 1.0) / (ior + 1.0)) ** 2
    assert weight == pytest.approx(f, abs=0.004)
    expected = f * np.asarray(tint) * SKY + (1.0 - f) * floor[row, col]
    np.testing.assert_allclose(water[row, col], expected, atol=0.004)


def test_looking_down_shows_what_is_under_the_surface_and_grazing_shows_the_reflection(scene):
    """A red stone on the pool floor under tinted water: seen from above, the pixel over it
    is the stone's colour through the water (the water's alpha of its own colour over it,
    plus the few percent reflected); seen at a grazing angle, the water shows mostly the
    lit wall it reflects."""
    water_colour = (0.1, 0.4, 0.35, 0.25)

    def build(water: bool, eye, target):
        def b(world):
            pool(world, water, eye, target, water_colour=water_colour)
            # Dark enough that its emission plus the sky's ambient light (1 + SKY times its
            # colour) stays under 1: a clipped stone would tell nothing about the blend.
            world.spawn(Transform(position=(0.0, -0.9, -1.0)), MeshRef(box((0.8, 0.2, 0.8))),
                        Material(color=(0.5, 0.03, 0.03, 1.0), roughness=1.0), Emissive(1.0))
            # A bright green wall across the pond, above the water: what it reflects.
            world.spawn(Transform(position=(0.0, 2.0, -12.0)), MeshRef(quad(40.0, 4.0)),
                        Material(color=(0.05, 0.45, 0.1, 1.0), roughness=1.0), Emissive(1.0))
        return b

    down = ((0.0, 3.0, -0.98), (0.0, 0.0, -1.0))
    runner, seen = render(scene, build(True, *down))
    _, dry = render(scene, build(False, *down))
    col, row = runner.project((0.0, 0.0, -1.0))
    stone = dry[row, col]
    assert stone[0] > 0.5 and stone[1] < 0.1  # the stone, without the water
    # Blended over it: the water's own colour by its alpha (its shading: ambient-lit at most
    # its colour), and the reflection of a uniform sky by F at normal incidence (0.02).
    f = schlick(0.02, 1.0)
    a = water_colour[3]
    low = (1.0 - f) * (1.0 - a) * stone
    high = low + f * SKY + (1.0 - f) * a * np.array(water_colour[:3]) * 2.0
    assert np.all(seen[row, col] >= low - 0.01) and np.all(seen[row, col] <= high + 0.01), (seen[row, col], low, high)
    assert seen[row, col][0] > 0.5  # red: the stone shows through

    graze = ((0.0, 0.3, 0.0), (0.0, 0.2, -12.0))
    runner, seen = render(scene, build(True, *graze), size=(96, 64))
    _, dry = render(scene, build(False, *graze), size=(96, 64))
    # The wall's mirror image: where the ray from the eye to the wall's image below the plane
    # crosses the water.
    image = glm.vec3(0.0, -0.5, -12.0)  # the wall half a metre up, in the water
    eye = glm.vec3(graze[0])
    crossing = eye + (image - eye) * (eye.y / (eye.y - image.y))
    col, row = runner.project(crossing)
    wall = np.array([0.05, 0.45, 0.1]) * (1.0 + SKY)  # its emission and the sky's ambient light (facing sideways)
    cos_theta = -glm.normalize(crossing - eye).y
    f = schlick(0.02, cos_theta)
    assert f > 0.6
    assert seen[row, col][1] > 0.6 * wall[1] * f and seen[row, col][1] > 3.0 * dry[row, col][1], (seen[row, col], f)
    np.testing.assert_allclose(seen[row, col], f * wall + (1.0 - f) * dry[row, col], atol=0.05)


def wave_map(periods: int = 2, size: int = 64, slope: float = 0.35) -> TextureData:
    """A tileable normal map of straight waves along U: height A sin(2 pi periods u), so the
    normal leans along U only and every column of texels is one normal."""
    u = (np.arange(size) + 0.5) / size
    tilt = -slope * np.cos(2.0 * math.pi * periods * u)
    n = np.stack([tilt, np.zeros(size), np.ones(size)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    row = np.concatenate([np.round((n * 0.5 + 0.5) * 255), np.full((size, 1), 255)], axis=-1).astype(np.uint8)
    return TextureData(np.tile(row[None], (size, 1, 1)), name="waves")


def direction_sky() -> Skybox:
    """A sky whose colour is its direction: a reflection's colour says where its ray went."""
    return Skybox(faces=[face_directions(face, 32) * 0.5 + 0.5 for face in range(6)])


SIDE = 4.0       # the wave pond's quad, metres (its UVs span it once)
TILING = 3.0     # map repeats across it: waves 4 / 3 / 2 m apart (2 periods a tile)
HEIGHT = 2.0     # the camera above it, looking straight down


def wave_pond(speed: float, cross: float = 0.0, scale: float = 1.0):
    """Straight waves along U under a sky that shows their slope, seen straight down (+X on
    the screen's right, the water's +V up); a high index (F0 0.36) so the reflection is
    bright straight down."""
    def b(world):
        world.spawn(Transform(position=(0.0, HEIGHT, 0.0), rotation=glm.angleAxis(-math.pi / 2, glm.vec3(1, 0, 0))),
                    Camera(fov_y=60.0))
        world.spawn(direction_sky())
        world.spawn(Transform(rotation=FLAT), MeshRef(quad(SIDE, SIDE)),
                    Material(color=(0.0, 0.0, 0.0, 1.0), normal_map=wave_map(), normal_scale=scale),
                    Mirror(), Water(ior=4.0, speed=speed, direction=(1.0, 0.0), tiling=TILING, cross=cross))
    return b


class WaveCamera:
    """The wave pond's frames, each less the same view of still water (normal_scale 0): what
    is left is the waves' pattern, without the sky's gradient across the view.  The sky's
    red says how far a reflected ray leans along x (the water's U), its blue along z (-V)."""

    def __init__(self, scene, speed: float, cross: float, size: int = 128) -> None:
        self.runner = scene(wave_pond(speed, cross), (size, size))
        still = scene(wave_pond(speed, cross, scale=0.0), (size, size))
        for runner in (self.runner, still):
            runner.engine.renderer.antialias = "off"
        self.still = srgb_to_linear(still.frame(0.0))
        # Pixels a metre across the water (the view is 2 tan 30 x HEIGHT wide at its distance).
        self.per_metre = size / (2.0 * HEIGHT * math.tan(math.radians(30.0)))

    def frame(self, dt: float) -> np.ndarray:
        return srgb_to_linear(self.runner.frame(dt)) - self.still


def phase(profile: np.ndarray, period: float) -> float:
    """The phase (radians) of ``profile``'s component of ``period`` pixels: a least-squares fit
    of a cos + b sin + a straight line; a pattern moved s pixels forward adds 2 pi s / period."""
    x = np.arange(len(profile), dtype=float)
    w = 2.0 * math.pi / period
    basis = np.stack([np.cos(w * x), np.sin(w * x), np.ones_like(x), x], axis=1)
    (a, b, _, _), *_ = np.linalg.lstsq(basis, profile, rcond=None)
    return math.atan2(b, a)


def moved(before: np.ndarray, after: np.ndarray, period: float) -> float:
    turn = (phase(after, period) - phase(before, period) + math.pi) % (2.0 * math.pi) - math.pi
    return turn / (2.0 * math.pi) * period


def test_the_waves_move_at_their_speed_along_their_direction(scene):
    """Frames at different times differ on the water, and its pattern has moved speed x dt
    tiles of the map along +U: on the screen, that fraction of a tile to the right."""
    speed = 0.05
    waves = WaveCamera(scene, speed, cross=0.0)
    first = waves.frame(0.0)[..., 0]
    np.testing.assert_array_equal(first, waves.frame(0.0)[..., 0])  # time stands still: so does the water
    tile = SIDE / TILING * waves.per_metre  # pixels a tile of the map spans (two crests)
    rows = slice(40, 88)
    assert np.ptp(first[rows].mean(axis=0)) > 0.1  # the waves show (a reflection's colour says its ray)
    for dt in (1.0, 2.0, 0.5):
        later = waves.frame(dt)[..., 0]
        assert np.abs(later - first).max() > 0.02  # the water changed (8-bit steps here are ~0.003)
        shift = moved(first[rows].mean(axis=0), later[rows].mean(axis=0), tile / 2)
        assert shift == pytest.approx(speed * dt * tile, abs=0.3), (dt, shift, speed * dt * tile)
        assert np.ptp(later[:, 40:88].mean(axis=1)) < 0.01  # straight waves along U, nothing along V
        first = later


def test_the_cross_layer_crosses_the_waves_and_moves_across_them(scene):
    """The second layer alone (cross = 1): the map's waves along U turned to run along V,
    1.7 times smaller, moving speed x dt of its own tiles up the screen (+V, the direction
    turned a quarter turn); with both, the picture changes along both axes."""
    speed = 0.05
    waves = WaveCamera(scene, speed, cross=1.0)
    first = waves.frame(0.0)
    tile = SIDE / TILING / 1.7 * waves.per_metre
    columns, rows = slice(40, 88), slice(40, 88)
    assert np.ptp(first[:, columns, 2].mean(axis=1)) > 0.1   # the rays lean along z, row by row...
    assert np.ptp(first[rows, :, 0].mean(axis=0)) < 0.01     # ...and not along x
    later = waves.frame(2.0)
    # Moved up the screen: along the rows read from the bottom.
    shift = moved(first[::-1, columns, 2].mean(axis=1), later[::-1, columns, 2].mean(axis=1), tile / 2)
    assert shift == pytest.approx(speed * 2.0 * tile, abs=0.3), (shift, speed * 2.0 * tile)
    both = WaveCamera(scene, speed, cross=0.5).frame(0.0)
    assert np.ptp(both[rows, :, 0].mean(axis=0)) > 0.05 and np.ptp(both[:, columns, 2].mean(axis=1)) > 0.05


def test_the_waves_are_where_water_offset_says(scene):
    """The waves' state is the component's: water moved on for a second and water given that
    second's offset (no time passing) draw the same frame, and a different one than at rest."""
    moving = scene(wave_pond(0.05, cross=0.5), (64, 64))
    placed = scene(wave_pond(0.0, cross=0.5), (64, 64))
    moving.frame(0.0)
    at_rest = moving.frame(0.0)
    moved = moving.frame(1.0)
    ((_, water),) = placed.world.query_one(Water)
    water.offset = (0.05, 0.0)
    np.testing.assert_array_equal(placed.frame(0.0), moved)
    assert np.abs(moved.astype(int) - at_rest).max() > 5


def test_water_values_are_checked_when_given():
    with pytest.raises(ComponentValueError, match=r"Water.ior must be >= 1.0"):
        Water(ior=0.5)
    with pytest.raises(ComponentValueError, match=r"Water.speed must be >= 0.0"):
        Water(speed=-1.0)
    with pytest.raises(ComponentValueError, match=r"Water.tiling must be > 0"):
        Water(tiling=0.0)
    with pytest.raises(ComponentValueError, match=r"Water.direction must not be the zero vector"):
        Water(direction=(0.0, 0.0))
    with pytest.raises(ComponentValueError, match=r"Water.direction must be two numbers"):
        Water(direction=(1.0, 0.0, 0.0))
    with pytest.raises(ComponentValueError, match=r"Water.cross must be <= 1.0"):
        Water(cross=2.0)
    with pytest.raises(ComponentValueError, match=r"Water.offset must be finite"):
        Water(offset=(math.inf, 0.0))
    water = Water(direction=(3.0, 4.0), offset=(2.25, -0.25))
    assert water.direction == pytest.approx((0.6, 0.8))
    assert water.offset == pytest.approx((0.25, 0.75))  # whole tiles dropped: the map repeats
    assert water.f0 == pytest.approx(0.02, abs=0.001)


def test_water_needs_a_sharp_mirror(scene):
    def lone(world):
        world.spawn(Transform(), MeshRef(quad(1.0, 1.0)), Material(), Water())

    def rough(world):
        world.spawn(Transform(), MeshRef(quad(1.0, 1.0)), Material(), Mirror(roughness=0.3), Water())

    # Refused at the spawn that makes the mistake (issue 41 item 2), not as a MirrorError in
    # every frame after: tests/test_hardening_rules.py has the writes and joins.
    for build, message in ((lone, "a Water needs a Mirror"), (rough, "Mirror.roughness on entity 1 must be 0")):
        with pytest.raises(ComponentValueError, match=message):
            scene(build, (16, 16))


def test_the_waves_stop_when_the_water_goes_and_a_new_water_starts_still(scene):
    """A water's waves belong to its entity: taken off, the mirror is a plain mirror again
    (no flow kept); put back, they start from rest."""
    runner = scene(wave_pond(0.05), (32, 32))
    runner.frame(1.0)
    system = runner.engine.stages["surfaces"]
    (entity,) = system.flows
    assert system.flows[entity].offset == pytest.approx((0.05, 0.0))
    assert runner.world.get(entity, Water).offset == system.flows[entity].offset  # the component's state
    runner.world.remove_component(entity, Water)
    runner.frame(1.0)
    assert system.flows == {} and system.mirrors[entity].water is None
    runner.world.add_component(entity, Water(speed=0.1))
    runner.frame(0.5)
    assert system.flows[entity].offset == pytest.approx((0.05, 0.0))


def test_level_files_carry_water(tmp_path):
    level = tmp_path / "pond.toml"
    level.write_text("""
[level]
name = "pond"

[[entity]]
name = "pond"
[entity.Transform]
[entity.MeshRef]
mesh = { quad = [2.0, 2.0] }
[entity.Material]
color = [0.1, 0.3, 0.3, 0.3]
normal_map = { ripples = [64, 4] }
[entity.Mirror]
[entity.Water]
ior = 1.33
speed = 0.2
direction = [0.0, 2.0]
tiling = 4.0
cross = 0.25
fog_density = 0.3
fog_color = [0.1, 0.2, 0.25]
depth = 1.5
caustics = 0.8
foam = 0.6
foam_depth = 0.4
foam_scale = 0.3
foam_color = [0.7, 0.8, 0.9]
""")
    world = World("pond")
    names = load_level(level).spawn(world)
    water = world.get(names["pond"], Water)
    assert (water.ior, water.speed, water.tiling, water.cross) == (1.33, 0.2, 4.0, 0.25)
    assert water.direction == pytest.approx((0.0, 1.0))
    assert (water.fog_density, water.depth, *water.fog_color) == pytest.approx((0.3, 1.5, 0.1, 0.2, 0.25, 1.0))
    assert water.caustics == 0.8
    assert (water.foam, water.foam_depth, water.foam_scale, *water.foam_color) == pytest.approx(
        (0.6, 0.4, 0.3, 0.7, 0.8, 0.9, 1.0))
    saved = save_level(world, tmp_path / "again.toml", names, name="pond")
    again = World("again")
    names_again = load_level(saved).spawn(again)
    kept = again.get(names_again["pond"], Water)
    assert kept.direction == pytest.approx((0.0, 1.0))
    assert (kept.fog_density, kept.depth, *kept.fog_color) == pytest.approx((0.3, 1.5, 0.1, 0.2, 0.25, 1.0))
    assert kept.caustics == 0.8
    assert (kept.foam, kept.foam_depth, kept.foam_scale, *kept.foam_color) == pytest.approx(
        (0.6, 0.4, 0.3, 0.7, 0.8, 0.9, 1.0))
    text = level.read_text()
    for good, bad, message in (("ior = 1.33", "ior = 0.5", r"Water.ior must be >= 1.0"),
                               ("depth = 1.5", "depth = -1.5", r"Water.depth must be >= 0.01"),
                               ("caustics = 0.8", "caustics = 2.0", r"Water.caustics must be <= 1.0"),
                               ("[entity.Mirror]\n", "", "a Water needs a Mirror"),
                               ("[entity.Mirror]\n", "[entity.Mirror]\nroughness = 0.2\n",
                                "Mirror.roughness must be 0")):
        level.write_text(text.replace(good, bad))
        with pytest.raises(LevelError, match=message):
            load_level(level)


def striped_pool(world, **mirror_values) -> None:
    """``pool`` seen from the side, with a red stripe across its floor 1.5 m ahead (and
    ``mirror_values`` set on the water's Mirror)."""
    pool(world, True, (0.0, 1.5, 2.0), (0.0, -1.0, -1.5))
    if mirror_values:
        for _, mirror in world.query_one(Mirror):
            for name, value in mirror_values.items():
                setattr(mirror, name, value)
    world.spawn(Transform(position=(0.0, -0.99, -1.5)), MeshRef(box((6.0, 0.02, 0.3))),
                Material(color=(0.5, 0.03, 0.03, 1.0), roughness=1.0, environment_reflection=0.0), Emissive(1.0))


SHOWN_BY = {"view": {}, "fallback": {"enabled": False},
            # (the eye 53 degrees off the pool's normal from its middle: its view's weight about 1/2)
            "faded": {"fade_angle": (40.0, 66.0)}}


@pytest.mark.parametrize("shown_by", SHOWN_BY)
def test_what_is_below_is_seen_bent_where_snells_law_puts_it(scene, shown_by):
    """A red stripe across a flat pool floor a metre under clear, still water, seen from the
    side: down a column, the stripe shows where the pixels' rays, refracted at the surface by
    the water's index (in numpy), meet the floor: nearer the surface than where it lies (a
    pool looks shallower), well away from where the unbent rays would show it.  The same where
    the water has no view of its own (its mirror switched off: its fallback, which reflects
    the same uniform sky, gives the view's frame), and where it is partly faded (its view's
    composite over its fallback: what is below bent once, by the view's)."""
    size = (48, 96)
    runner, seen = render(scene, lambda world: striped_pool(world, **SHOWN_BY[shown_by]), size=size)
    stats = runner.engine.renderer.stats
    assert (stats.reflection_fallbacks, stats.reflection_views) == \
        {"view": (0, 1), "fallback": (1, 0), "faded": (1, 1)}[shown_by]
    if shown_by != "view":
        _, by_view = render(scene, striped_pool, size=size)
        assert np.abs(seen - by_view).max() < 0.02
    view = runner.engine.main_view
    inverse = np.array(glm.inverse(glm.dmat4(view.view_proj)).to_list(), np.float64).T
    column = size[0] // 2
    eye = np.array(view.eye, np.float64)
    expected, straight = [], []
    for row in range(size[1]):
        far = inverse @ np.array([(column + 0.5) / size[0] * 2 - 1, 1 - (row + 0.5) / size[1] * 2, 1.0, 1.0])
        d = far[:3] / far[3] - eye
        d /= np.linalg.norm(d)
        t = -eye[1] / d[1]
        at = eye + t * d
        eta, n = 1.0 / 1.333, np.array([0.0, 1.0, 0.0])
        cos_i = -d @ n
        bent = eta * d + (eta * cos_i - math.sqrt(1.0 - eta ** 2 * (1.0 - cos_i ** 2))) * n
        on_floor = at + bent * (-0.98 - at[1]) / bent[1]       # (the stripe's top)
        expected.append(abs(on_floor[2] + 1.5) < 0.15)
        unbent = at + d * (-0.98 - at[1]) / d[1]
        straight.append(abs(unbent[2] + 1.5) < 0.15)
    expected, straight = np.array(expected), np.array(straight)
    red = (seen[:, column, 0] > 2.0 * seen[:, column, 1] + 0.05)
    assert expected.sum() >= 3 and abs(np.flatnonzero(expected).mean() - np.flatnonzero(straight).mean()) > 4
    assert (red != expected).sum() <= 2, (np.flatnonzero(red), np.flatnonzero(expected), np.flatnonzero(straight))


def test_a_post_standing_in_the_water_shows_below_it_where_snells_law_puts_it(scene):
    """A green post standing in clear, still water: down its column, below the waterline, the
    post shows exactly where the pixels' refracted rays meet its part under water (traced in
    numpy): its foot seen rows higher than the unbent rays would put it (a pool looks
    shallower), the water drawn in front of it, what stands above the surface left out."""
    from tests.support import box_hits

    post = (np.array([0.0, 0.0, -1.5]), np.array([0.15, 1.0, 0.15]))   # (from the floor, y -1, to y 1)
    under = (post[0] + np.array([0.0, -0.5, 0.0]), post[1] * np.array([1.0, 0.5, 1.0]))  # y -1 to 0
    above = (post[0] + np.array([0.0, 0.5, 0.0]), post[1] * np.array([1.0, 0.5, 1.0]))   # y 0 to 1

    def build(world):
        pool(world, True, (0.0, 1.2, 1.5), (0.0, -0.6, -1.5))
        world.spawn(Transform(position=tuple(post[0])), MeshRef(box(tuple(2.0 * post[1]))),
                    Material(color=(0.03, 0.5, 0.03, 1.0), roughness=1.0, environment_reflection=0.0), Emissive(1.0))

    size = (64, 96)
    runner, seen = render(scene, build, size=size)
    view = runner.engine.main_view
    inverse = np.array(glm.inverse(glm.dmat4(view.view_proj)).to_list(), np.float64).T
    eye = np.array(view.eye, np.float64)
    column = runner.project(tuple(post[0]))[0]
    rows, expected, straight = [], [], []
    for row in range(size[1]):
        far = inverse @ np.array([(column + 0.5) / size[0] * 2 - 1, 1 - (row + 0.5) / size[1] * 2, 1.0, 1.0])
        d = far[:3] / far[3] - eye
        d /= np.linalg.norm(d)
        if d[1] >= 0.0 or box_hits(eye[None], d[None], *above)[0]:
            continue  # (the sky, or the post above the water seen directly)
        at = eye + (-eye[1] / d[1]) * d
        eta, n = 1.0 / 1.333, np.array([0.0, 1.0, 0.0])
        cos_i = -d @ n
        bent = eta * d + (eta * cos_i - math.sqrt(1.0 - eta ** 2 * (1.0 - cos_i ** 2))) * n
        rows.append(row)
        expected.append(bool(box_hits(at[None], bent[None], *under)[0]))
        straight.append(bool(box_hits(at[None], d[None], *under)[0]))
    expected, straight = np.array(expected), np.array(straight)
    green = seen[rows, column, 1] > 2.0 * seen[rows, column, 0] + 0.05
    assert expected.sum() >= 3 and (expected != straight).sum() >= 3, (expected.sum(), (expected != straight).sum())
    assert (green != expected).sum() <= 2, (np.flatnonzero(green), np.flatnonzero(expected), np.flatnonzero(straight))


def test_waters_copy_of_what_is_below_is_made_once_and_goes_with_the_water(scene, monkeypatch):
    """Water bends what is below by a copy of the level it goes into (the refraction copy):
    one image made once and kept from frame to frame while the water is seen (with no glass
    in the world: nothing else takes it), let go once a whole frame has taken none."""
    from engine.render import screen_refraction

    made = []
    real = screen_refraction._Copy.__init__

    def counted(self, *args, **kwargs):
        made.append(args)
        real(self, *args, **kwargs)

    monkeypatch.setattr(screen_refraction._Copy, "__init__", counted)
    water = []

    def build(world):
        pool(world, True, (0.0, 1.5, 2.0), (0.0, -1.0, -1.5))
        water.append(world.query_one(Water)[0][0])

    runner = scene(build, (48, 64))
    copy = runner.engine.renderer.scene_pass.refraction_copy
    for _ in range(5):
        runner.frame()
    assert copy.copies == 5 and len(made) == 1 and copy.held() == 1
    runner.world.delete_entity(water[0])
    runner.frame()
    runner.frame()
    assert copy.held() == 0 and copy.copies == 5 and len(made) == 1


def test_near_the_pictures_edge_what_is_below_fades_from_bent_to_unbent(scene):
    """Where a pixel's bent ray meets the floor off the picture, the copy of what is below
    holds nothing there and the pixel shows it unbent; within WATER_EDGE_BAND (a share of the
    picture's smaller side) of the edge the two blend by how far in the bent place lies (or,
    for a pixel nearer the edge than that, by its share of the pixel's own distance), so a
    deep pool seen steeply has no seam across its floor where the bent rays leave the picture.
    The floor is red beyond a line and grey on the near side; near the bottom edge a column's
    bent rays meet the grey and its unbent rays the red: down the column, each pixel's share of
    the red is what numpy's Snell refraction and the fade's rule give (1 where the bent place is
    well inside, falling with the band, then the unbent floor's colour past the edge)."""
    size, band_share, line = (96, 64), 0.08, 0.645

    def build(world):
        eye = glm.vec3(0.0, 1.5, 2.0)
        world.spawn(Transform(position=eye, rotation=look_rotation(glm.vec3(0.0, -1.0, -1.5) - eye)),
                    Camera(fov_y=60.0))
        world.spawn(uniform_sky(SKY))
        for z0, z1, colour in ((-100.0, line, (0.5, 0.03, 0.03)), (line, 100.0, (FLOOR, FLOOR, FLOOR))):
            world.spawn(Transform(position=(0.0, -1.0, (z0 + z1) / 2), rotation=FLAT), MeshRef(quad(200.0, z1 - z0)),
                        Material(color=(*colour, 1.0), roughness=1.0, environment_reflection=0.0), Emissive(1.0))
        world.spawn(Transform(rotation=FLAT), MeshRef(quad(200.0, 200.0)), Material(color=(1.0, 1.0, 1.0, 0.0)),
                    Mirror(), Water())

    runner, seen = render(scene, build, size=size)
    view = runner.engine.main_view
    view_proj = np.array(glm.dmat4(view.view_proj).to_list(), np.float64).T
    inverse = np.linalg.inv(view_proj)
    column, eye = size[0] // 2, np.array(view.eye, np.float64)
    band = band_share * min(size)
    rows = []  # (row, the red share expected, F)
    for row in range(size[1]):
        far = inverse @ np.array([(column + 0.5) / size[0] * 2 - 1, 1 - (row + 0.5) / size[1] * 2, 1.0, 1.0])
        d = far[:3] / far[3] - eye
        d /= np.linalg.norm(d)
        at = eye + d * (-eye[1] / d[1])
        eta, cos_i = 1.0 / 1.333, -d[1]
        bent = eta * d + (eta * cos_i - math.sqrt(1.0 - eta ** 2 * (1.0 - cos_i ** 2))) * np.array([0.0, 1.0, 0.0])
        bent_hit, unbent_hit = at + bent * (-1.0 - at[1]) / bent[1], at + d * (-1.0 - at[1]) / d[1]
        if min(abs(bent_hit[2] - line), abs(unbent_hit[2] - line)) < 0.02:
            continue  # too near the line to say which side a texel shows
        clip = view_proj @ np.array([*bent_hit, 1.0])
        pixel = (clip[:2] / clip[3] * 0.5 + 0.5) * np.array(size)
        here = np.array([column + 0.5, size[1] - row - 0.5])  # (GL's rows count up)
        reach = np.maximum(np.minimum(band, np.concatenate([here, np.array(size) - here])), 0.5)
        kept = float(np.clip(np.concatenate([pixel, np.array(size) - pixel]) / reach, 0.0, 1.0).min())
        red = kept * (bent_hit[2] < line) + (1.0 - kept) * (unbent_hit[2] < line)
        rows.append((row, red, schlick(0.02, cos_i), kept))
    # The red floor's red over green, seen through the water: what the rows showing it whole
    # give (the sky's reflection, grey, adds nothing to it), against which each row's is a share.
    excess = np.array([seen[row, column, 0] - seen[row, column, 1] for row, *_ in rows]) / \
        np.array([1.0 - f for _, _, f, _ in rows])
    expected = np.array([red for _, red, _, _ in rows])
    whole = np.median(excess[expected > 0.99])
    assert whole > 0.3
    between = (expected > 0.05) & (expected < 0.95)
    assert between.sum() >= 3, rows  # the band's rows: bent and unbent both show there
    assert (expected < 0.01).any() and (expected > 0.99).any()
    np.testing.assert_allclose(excess / whole, expected, atol=0.12)


def test_a_waters_sky_is_the_generated_skys_along_its_reflected_rays_pixel_by_pixel(scene):
    """A still pond (no normal map) over a black floor under a generated sky, the sun's disc
    in its reflection: where nothing else is reflected, each water pixel (level 0's HDR
    colour) is F x ``sky_radiance`` along the pixel's ray reflected at y = 0, F Schlick's
    for the water's index at the pixel's angle (what is below is black: the floor alone is
    checked so), the disc's sharp edge included (the composite draws the sky per pixel, not
    from the cube map's texels); above the horizon, the sky itself."""
    from engine.render.sky import sky_radiance
    from engine.rules.light_rules import SkySun
    from tests.test_generated_sky import SIZE, SKY, SUN, _read

    sun = np.array(SUN, np.float64)
    look = sun * np.array([1.0, -1.0, 1.0]) + np.array([0.0, 0.25, 0.0])   # at the sun's image, the horizon in view

    def build(water: bool):
        def b(world):
            world.spawn(Transform(position=(0.0, 1.5, 0.0), rotation=look_rotation(glm.vec3(*look))),
                        Camera(fov_y=50.0, near=0.1, far=500.0))
            world.spawn(Skybox(**SKY))
            world.spawn(Transform(position=(0.0, -1.0, 0.0), rotation=FLAT), MeshRef(quad(400.0, 400.0)),
                        Material(color=(0.0, 0.0, 0.0, 1.0), roughness=1.0, environment_reflection=0.0))
            if water:
                world.spawn(Transform(rotation=FLAT), MeshRef(quad(400.0, 400.0)), Material(color=(1.0, 1.0, 1.0, 0.0)),
                            Mirror(), Water(ior=1.333, speed=0.0))
        return b

    colours = {}
    for water in (True, False):
        runner = scene(build(water), SIZE)
        runner.engine.renderer.antialias = "off"
        runner.frame()
        colours[water], rays = _read(runner)
        if water:
            assert runner.stats.reflection_views == 1
    colour, dry = colours[True], colours[False]
    eye = np.array(runner.engine.main_view.eye, np.float64)
    down = rays[..., 1] < -0.02
    hit = eye + rays * (-eye[1] / np.where(down, rays[..., 1], -1.0))[..., None]
    on_water = down & (np.abs(hit[..., 0]) < 150.0) & (np.abs(hit[..., 2]) < 150.0)
    assert on_water.sum() > 5000 and (rays[..., 1] > 0.02).sum() > 1000
    assert dry[on_water].max() < 1e-3                                     # (black below)
    reflected = rays * np.array([1.0, -1.0, 1.0])
    sky = sky_radiance(Skybox(**SKY), reflected, SkySun(tuple(sun)))
    f0 = ((1.333 - 1.0) / (1.333 + 1.0)) ** 2
    weight = schlick(f0, -rays[..., 1:2])
    np.testing.assert_allclose(colour[on_water], (weight * sky)[on_water], rtol=1e-2, atol=2e-3)
    disc = sky_radiance(Skybox(**SKY), reflected, SkySun(tuple(sun))).max(axis=-1) > 3.0
    assert (disc & on_water).sum() >= 10                                   # (the sun's disc in the water)
    up = rays[..., 1] > 0.02
    np.testing.assert_allclose(colour[up], sky_radiance(Skybox(**SKY), rays, SkySun(tuple(sun)))[up],
                               rtol=1e-2, atol=2e-3)


def _level0_hdr(runner) -> np.ndarray:
    """Level 0's linear HDR colour (h, w, 3; row 0 at the top), at the runner's size."""
    w, h = runner.size
    colour = np.frombuffer(runner.engine.renderer.levels[0].color.read(), np.float16)
    return colour.reshape(h, w, 4)[::-1, :, :3].astype(np.float64)


def test_a_waters_sky_seen_through_a_portal_is_the_generated_skys_along_the_carried_then_reflected_rays(scene):
    """The still pond of the test above lies beyond portal B, far off; the camera looks into
    portal A (filling the view) along another way, the pair turning it towards the sun's
    image in the pond.  Each pixel's ray is carried through the pair (float64, from the
    Transforms: where it crosses A's plane and its direction), and where the carried ray
    meets the pond beyond B, the pixel (level 0's HDR colour) is F x ``sky_radiance`` along
    the carried ray reflected at y = 0, F Schlick's at the carried ray's angle, the sun's
    disc's sharp edge included; above the horizon the sky along the carried ray.  Not the
    camera's own rays' sky (the pair turned them), and what is below is black (the floor
    alone, seen through the pair, is)."""
    from engine.assets.portals import spawn_portal_pair
    from engine.render.sky import sky_radiance
    from engine.rules.light_rules import SkySun
    from tests.support import pixel_rays
    from tests.test_generated_sky import SKY, SUN

    sun = np.array(SUN, np.float64)
    target = glm.normalize(glm.vec3(*(sun * np.array([1.0, -1.0, 1.0]) + np.array([0.0, 0.25, 0.0]))))
    look = glm.normalize(glm.vec3(0.5, -0.2, 1.0))    # the camera's own way (towards +z, away from the sun)
    camera_at, b_at = glm.vec3(0.0, 1.5, 0.0), glm.vec3(300.0, 1.5, 0.0)
    ents = {}

    def build(water: bool):
        def b(world):
            world.spawn(Transform(position=camera_at, rotation=look_rotation(look)),
                        Camera(fov_y=50.0, near=0.1, far=500.0))
            world.spawn(Skybox(**SKY))
            ents["a"], ents["b"] = spawn_portal_pair(world, camera_at + 2.0 * look, look_rotation(look), b_at,
                                                     look_rotation(-target), size=(40.0, 40.0), max_depth=1)
            world.spawn(Transform(position=(b_at.x, -1.0, b_at.z), rotation=FLAT), MeshRef(quad(400.0, 400.0)),
                        Material(color=(0.0, 0.0, 0.0, 1.0), roughness=1.0, environment_reflection=0.0))
            if water:
                world.spawn(Transform(position=(b_at.x, 0.0, b_at.z), rotation=FLAT), MeshRef(quad(400.0, 400.0)),
                            Material(color=(1.0, 1.0, 1.0, 0.0)), Mirror(), Water(ior=1.333, speed=0.0))
        return b

    size = (96, 72)
    colours = {}
    for water in (True, False):
        runner = scene(build(water), size)
        runner.engine.renderer.antialias = "off"
        runner.frame()
        colours[water] = _level0_hdr(runner)
        if water:
            assert runner.stats.reflection_views == 2        # the portal's view and the water's in it
            assert (runner.engine.renderer.targets.read_surface_ids() == ents["a"]).all()
    colour, dry = colours[True], colours[False]
    eye, rays = pixel_rays(runner.engine.main_view, size)
    a_world, b_world = (np.array(glm.dmat4(runner.world.get(ents[e], Transform).world).to_list()).T for e in "ab")
    turn = np.array(glm.dmat4(glm.rotate(glm.pi(), glm.vec3(0, 1, 0))).to_list()).T
    carry = b_world @ turn @ np.linalg.inv(a_world)
    a_normal = a_world[:3, 2] / np.linalg.norm(a_world[:3, 2])
    t_a = np.dot(a_world[:3, 3] - eye, a_normal) / (rays @ a_normal)
    assert (t_a > 0.0).all()
    start = (eye + rays * t_a[..., None]) @ carry[:3, :3].T + carry[:3, 3]   # on B's plane
    carried = rays @ carry[:3, :3].T
    np.testing.assert_allclose(carry[:3, :3] @ np.array(look), np.array(target), atol=1e-5)
    down = carried[..., 1] < -0.02
    hit = start + carried * (-start[..., 1] / np.where(down, carried[..., 1], -1.0))[..., None]
    on_water = down & (np.abs(hit[..., 0] - b_at.x) < 150.0) & (np.abs(hit[..., 2] - b_at.z) < 150.0)
    up = carried[..., 1] > 0.02
    assert on_water.sum() > 0.4 * on_water.size and up.sum() > 0.1 * up.size
    assert dry[on_water].max() < 1e-3                                     # (black below)
    skybox, sky_sun = Skybox(**SKY), SkySun(tuple(sun))
    reflected = carried * np.array([1.0, -1.0, 1.0])
    sky = sky_radiance(skybox, reflected, sky_sun)
    f0 = ((1.333 - 1.0) / (1.333 + 1.0)) ** 2
    want = schlick(f0, -carried[..., 1:2]) * sky
    np.testing.assert_allclose(colour[on_water], want[on_water], rtol=1e-2, atol=2e-3)
    assert ((sky.max(axis=-1) > 3.0) & on_water).sum() >= 10              # (the sun's disc in the water)
    np.testing.assert_allclose(colour[up], sky_radiance(skybox, carried, sky_sun)[up], rtol=1e-2, atol=2e-3)
    own = np.where(rays[..., 1:2] < 0.0, schlick(f0, np.abs(rays[..., 1:2])) * sky_radiance(
        skybox, rays * np.array([1.0, -1.0, 1.0]), sky_sun), sky_radiance(skybox, rays, sky_sun))
    assert np.abs(colour - own)[on_water].max() > 0.2                     # (not the camera's own rays' water)
