"""Caustics under a water (Water.caustics): the sun's light through the waves gathers where
the bent rays converge.  Measured in rendered frames against a ray tracer written here: rays
of sunlight refracted by Snell's law at the waves' normal map (its texels, read as the GPU
filters them) and followed down to the floor, the light on each stretch of floor the share of
the surface whose rays land on it."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    ComponentValueError,
    ComponentWarning,
    DirectionalLight,
    Material,
    MeshRef,
    Mirror,
    PointLight,
    Skybox,
    Transform,
    Water,
)
from engine.assets.mesh import box, quad
from engine.core.errors import CausticLimitWarning, GLLimitWarning
from engine.render.caustics import CAUSTIC_SUN_SPREAD, CausticBlock
from engine.rules.light_rules import KeptLights
from tests.support import look_rotation, srgb_to_linear
from tests.test_water import FLAT, wave_map

SIDE = 4.0        # the pool's quad, metres (its UVs span it once)
TILING = 3.0      # map repeats across it
PERIODS = 4       # wave periods a map tile: waves SIDE / (TILING x PERIODS) = 1/3 m apart
SLOPE = 0.15      # the waves' steepest slope (the map's)
DEPTH = 1.0       # the floor under the surface
ALBEDO = 0.6
SUN = glm.normalize(glm.vec3(0.3, -1.0, 0.0))   # the light's way: slanting along the waves' U (+x)
IOR = 1.333
EYE = (0.0, -0.05, 0.0)   # just under the surface, looking straight down at the floor


def pool(caustics: float, *, eye=EYE, target=(0.0, -DEPTH, -0.001), cross: float = 0.0, scale: float = 1.0,
         position=(0.0, 0.0, 0.0), normal_map=True, sun=SUN, depth: float = 10.0, tiles: float = 1.0,
         fov_y: float = 60.0):
    """A sunlit grey floor DEPTH under a SIDE-metre water of straight waves along x (the
    water's U), under a black sky (the sun is the only light)."""
    def build(world):
        at = glm.vec3(eye)
        world.spawn(Transform(position=at, rotation=look_rotation(glm.vec3(target) - at)), Camera(fov_y=fov_y))
        world.spawn(Skybox(faces=[np.zeros((8, 8, 3), np.float32) for _ in range(6)]))
        world.spawn(DirectionalLight(direction=tuple(sun), intensity=1.0))
        world.spawn(Transform(position=(0.0, -DEPTH, 0.0), rotation=FLAT), MeshRef(quad(60.0, 60.0)),
                    Material(color=(ALBEDO, ALBEDO, ALBEDO, 1.0), roughness=1.0, environment_reflection=0.0))
        world.spawn(Transform(position=position, rotation=FLAT), MeshRef(quad(SIDE * tiles, SIDE * tiles)),
                    Material(color=(1.0, 1.0, 1.0, 0.0), normal_map=wave_map(PERIODS, slope=SLOPE) if normal_map
                             else None, normal_scale=scale),
                    Mirror(), Water(ior=IOR, tiling=TILING * tiles, speed=0.0, cross=cross, caustics=caustics,
                                    depth=depth))
    return build


def render(scene, build, size=(96, 96)):
    runner = scene(build, size)
    runner.engine.renderer.antialias = "off"
    for _ in range(2):
        rgb = runner.frame(1.0 / 60.0)
    return runner, srgb_to_linear(rgb)


def floor_points(runner) -> np.ndarray:
    """Where each pixel centre's ray meets the floor (x, z), [row, column, 2] (NaN: it does not)."""
    view = runner.engine.main_view
    inverse = glm.inverse(view.view_proj)
    w, h = runner.size
    out = np.zeros((h, w, 2))
    for row in range(h):
        for column in range(w):
            ndc = glm.vec4((column + 0.5) / w * 2.0 - 1.0, 1.0 - (row + 0.5) / h * 2.0, -1.0, 1.0)
            near = inverse * ndc
            direction = glm.normalize(glm.vec3(near) / near.w - view.eye)
            t = (-DEPTH - view.eye.y) / direction.y
            out[row, column] = (view.eye.x + direction.x * t, view.eye.z + direction.z * t) if t > 0.0 else math.nan
    return out


def refract(incident: np.ndarray, normal: np.ndarray, eta: float) -> np.ndarray:
    """Snell's law for unit rays (rows) through unit normals (rows): the transmitted ray."""
    cos_i = -np.sum(incident * normal, axis=-1, keepdims=True)
    sin_t2 = eta * eta * (1.0 - cos_i * cos_i)
    return eta * incident + (eta * cos_i - np.sqrt(1.0 - sin_t2)) * normal


def traced_light(xs: np.ndarray) -> np.ndarray:
    """The share of the flat water's sunlight reaching the floor at each x, by tracing: rays
    cross the surface at a fine row of points, each bent by the map's normal there (its
    texels' values, filtered linearly between texel centres and wrapped), land on the floor,
    and the light at a landing is the spacing of the crossings over the spacing of the
    landings (the light through each stretch of surface spread over where it lands)."""
    texels = wave_map(PERIODS, slope=SLOPE).pixels[0, :, :3].astype(np.float64) / 255.0 * 2.0 - 1.0
    size = len(texels)
    step = SIDE / (TILING * size)   # a texel: the finest stretch the renderer tells apart
    centres = np.linspace(xs.min() - 0.5, xs.max() + 0.5, 20001)
    crossings = np.concatenate([centres - step / 2.0, centres + step / 2.0])
    u = (crossings + SIDE / 2.0) / SIDE * TILING * size - 0.5   # texel coordinates (the quad's U runs along +x)
    low = np.floor(u).astype(int)
    share = (u - low)[:, None]
    m = texels[low % size] * (1.0 - share) + texels[(low + 1) % size] * share
    slope_u, slope_v = m[:, 0] / m[:, 2], m[:, 1] / m[:, 2]
    # +U along +x; +V along -z (the quad's +y turned flat)
    normals = np.stack([slope_u, np.ones_like(slope_u), -slope_v], axis=1)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    rays = refract(np.tile(np.array(tuple(SUN)), (len(crossings), 1)), normals, 1.0 / IOR)
    landings = crossings + rays[:, 0] * DEPTH / -rays[:, 1]
    before, after = landings[:len(centres)], landings[len(centres):]
    spread = (after - before) / step
    landings = (before + after) / 2.0
    assert (spread > 0.0).all()   # no fold: each stretch of floor is lit through one stretch of surface
    return np.interp(xs, landings, 1.0 / spread)


def test_the_light_under_rippled_water_is_where_a_ray_tracer_gathers_it(scene):
    """Each floor pixel's light over the same pixel under water that gathers nothing
    (``caustics`` 0) is the traced share at its floor point: their profiles across the waves
    match (within the map's one-texel difference step), the brightest lines where the tracer
    puts them, and the light's mean over the picture is kept (refraction moves light, it does
    not make it)."""
    runner, lit = render(scene, pool(1.0))
    _, flat = render(scene, pool(0.0))
    assert 0.1 < flat.min() and flat.max() < 0.3, (flat.min(), flat.max())   # lit by the sun alone, not clipped
    share = lit[..., 0] / flat[..., 0]
    xs = floor_points(runner)[..., 0]
    traced = traced_light(xs.ravel()).reshape(xs.shape)
    assert traced.max() > 2.0 and traced.min() < 0.7   # strong caustics
    assert np.corrcoef(share.ravel(), traced.ravel())[0, 1] > 0.985
    assert np.median(np.abs(share - traced)) < 0.04
    assert abs(share.mean() - traced.mean()) < 0.03


def test_half_strength_is_half_way_to_the_gathered_light(scene):
    """``caustics`` 0.5: each pixel half way between the water that gathers nothing and the
    one that gathers all (within the output's 8-bit steps)."""
    _, full = render(scene, pool(1.0))
    _, half = render(scene, pool(0.5))
    _, flat = render(scene, pool(0.0))
    np.testing.assert_allclose(half, (full + flat) / 2.0, atol=0.006)
    assert np.abs(full - flat).max() > 0.1



def test_far_off_the_caustics_are_their_mean_over_the_pixel_not_a_shimmer(scene):
    """A pool ten times as wide, seen from under its surface along the floor: near the eye
    the waves' light is gathered in lines, far off (a pixel's footprint past a wave's length)
    each pixel shows the light's mean over it, close to the flat water's."""
    eye, target = (0.0, -0.05, 0.0), (0.0, -1.0, -10.0)
    runner, lit = render(scene, pool(1.0, eye=eye, target=target, tiles=10.0), size=(64, 64))
    _, flat = render(scene, pool(0.0, eye=eye, target=target, tiles=10.0), size=(64, 64))
    points = floor_points(runner)
    distance = np.hypot(points[..., 0], points[..., 1])
    share = lit[..., 0] / np.maximum(flat[..., 0], 1e-3)
    lit_floor = flat[..., 0] > 0.05
    near, far = lit_floor & (distance < 2.0), lit_floor & (distance > 8.0) & (distance < 18.0)
    assert near.sum() > 100 and far.sum() > 100
    assert np.ptp(share[near]) > 1.0   # the lines
    assert np.abs(share[far] - 1.0).max() < 0.15, np.abs(share[far] - 1.0).max()

@pytest.mark.parametrize("case", ["off the outline", "no slope", "below the body", "still water", "off"])
def test_where_no_wave_bends_the_light_it_is_the_flat_waters_to_the_bit(scene, case):
    """The floor is the frame of a water that gathers nothing, bit for bit: seen beside the
    pool (out of its outline), under waves of no slope (``normal_scale`` 0: every ray bent
    alike), under a body half a metre deep (``Water.depth``: the floor is below it); and, with
    no CAUSTICS build at all, under still water (no normal map: no waves, which is said once) and
    with ``caustics`` 0."""
    values = {"off the outline": {"position": (SIDE + 2.0, 0.0, 0.0)}, "no slope": {"scale": 0.0},
              "below the body": {"depth": 0.5}, "still water": {"normal_map": False}, "off": {}}[case]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        runner, with_caustics = render(scene, pool(0.0 if case == "off" else 1.0, **values))
    said = [w for w in caught if issubclass(w.category, ComponentWarning) and "gathers no light" in str(w.message)]
    assert len(said) == (case == "still water")   # (said once, though asked every frame)
    _, without = render(scene, pool(0.0, **values))
    assert bool(runner.engine.renderer.caustics.defines) == (case not in ("off", "still water"))
    np.testing.assert_array_equal(with_caustics, without)


def test_the_caustics_move_with_the_waves(scene):
    """Waves moving at ``speed``: after each frame the light on the floor is that under still
    waves placed where the moving ones are (``Water.offset``), and it moved."""
    runner = scene(pool(1.0), (64, 64))
    runner.engine.renderer.antialias = "off"
    water = max(entity for entity, _ in runner.world.query_one(Water))
    runner.world.get(water, Water).speed = 0.5
    frames = [runner.frame(0.1) for _ in range(3)]
    offset = runner.world.get(water, Water).offset
    assert offset[0] > 0.0
    still = scene(pool(1.0), (64, 64))
    still.engine.renderer.antialias = "off"
    still.world.get(max(entity for entity, _ in still.world.query_one(Water)), Water).offset = offset
    for _ in range(2):
        placed = still.frame(0.1)
    np.testing.assert_array_equal(frames[-1], placed)
    assert np.abs(frames[-1].astype(int) - frames[-2].astype(int)).max() > 20


def another_pool(world, position, *, periods: int = PERIODS, size: int = 64, caustics: float = 1.0) -> int:
    """One more SIDE-metre pool of straight waves (``periods`` a tile, its map ``size`` texels
    a side) at ``position``: its entity."""
    return world.spawn(Transform(position=position, rotation=FLAT), MeshRef(quad(SIDE, SIDE)),
                       Material(color=(1.0, 1.0, 1.0, 0.0), normal_map=wave_map(periods, size=size, slope=SLOPE)),
                       Mirror(), Water(ior=IOR, tiling=TILING, speed=0.0, caustics=caustics))


LEFT, RIGHT = (-SIDE / 2.0 - 0.05, 0.0, 0.0), (SIDE / 2.0 + 0.05, 0.0, 0.0)   # two pools, a hand's width apart


def side_by_side(left: bool, right: bool, caustics: float = 1.0, right_size: int = 64):
    """Pools to the LEFT and RIGHT of the eye over one floor (its one row reaches into both
    bodies), the eye between them just under their plane, looking straight down wide: the
    left pool's waves PERIODS a tile, the right one's 3 (its map ``right_size`` texels)."""
    def build(world):
        pool(0.0, fov_y=100.0, position=(0.0, 40.0, 0.0))(world)   # (its own pool far above: no caustics)
        if left:
            another_pool(world, LEFT, caustics=caustics)
        if right:
            another_pool(world, RIGHT, periods=3, size=right_size, caustics=caustics)
    return build


@pytest.mark.parametrize("right_size", [64, 32])
def test_two_pools_over_one_floor_each_gather_the_sun_through_their_own_waves(scene, right_size):
    """Two pools side by side over one floor, both in the picture: the floor lit through each
    is the floor lit through that pool alone, to the bit (a map of the other's size, resampled to it in
    the maps' array, within its filtering's difference), and each half shows caustics; the
    floor's row reaches into both bodies, so its batch is keyed under both waters."""
    runner, both = render(scene, side_by_side(True, True, right_size=right_size))
    _, left = render(scene, side_by_side(True, False, right_size=right_size))
    _, right = render(scene, side_by_side(False, True, right_size=right_size))
    _, flat = render(scene, side_by_side(True, True, 0.0))
    # Where the light on each floor point crossed the surfaces' plane (the flat water's ray:
    # the sun slants along +x, so light landing just right of the gap came through the left pool).
    t = refract(np.array([tuple(SUN)]), np.array([[0.0, 1.0, 0.0]]), 1.0 / IOR)[0]
    crossed = floor_points(runner)[..., 0] - DEPTH * t[0] / -t[1]
    under_left, under_right = crossed < LEFT[0] + SIDE / 2.0 - 0.01, crossed > RIGHT[0] - SIDE / 2.0 + 0.01
    assert under_left.sum() > 2000 and under_right.sum() > 2000
    assert [water.entity for water in runner.engine.renderer.caustics.waters] == sorted(
        e for e, water in runner.world.query_one(Water) if water.caustics > 0.0)
    np.testing.assert_array_equal(both[under_left], left[under_left])
    if right_size == 64:
        np.testing.assert_array_equal(both[under_right], right[under_right])
    else:
        assert np.median(np.abs(both[under_right] - right[under_right])) < 0.01
        assert np.corrcoef(both[under_right][:, 0], right[under_right][:, 0])[0, 1] > 0.98
    for half in (under_left, under_right):
        assert np.ptp(both[half][:, 0] / flat[half][:, 0]) > 1.0   # its caustics' lines
    np.testing.assert_array_equal(left[under_right], flat[under_right])   # (no light gathered with no pool over it)
    floor = next(e for e, (t, _) in runner.world.query(Transform, MeshRef) if t.position.y == -DEPTH)
    waters = tuple(sorted(e for e, water in runner.world.query_one(Water) if water.caustics > 0.0))
    batch = next(b for b in runner.engine.renderer.batches.values() if floor in b.entity_at[:b.count])
    assert batch.caustic_waters == waters


def test_the_nearest_four_waters_gather_the_sun_and_the_rest_are_said(scene):
    """Six pools with caustics, one under the camera and five farther off in a row: the four
    nearest gather the sun, held by entity; the two farthest are counted and said in a
    CausticLimitWarning; under the camera the floor is as under its pool alone."""
    far = {}

    def build(world):
        pool(1.0)(world)
        for k, x in enumerate((30.0, 40.0, 50.0, 60.0, 70.0)):
            far[x] = another_pool(world, (x, 0.0, 0.0), periods=2 + k % 3)

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        runner, image = render(scene, build)
    said = [w for w in caught if issubclass(w.category, CausticLimitWarning)]
    assert len(said) == 1 and "4 gather the sun at a time" in str(said[0].message)
    assert runner.stats.caustic_waters_cut == 2
    near = min(entity for entity, _ in runner.world.query_one(Water))
    assert [water.entity for water in runner.engine.renderer.caustics.waters] == [
        near, far[30.0], far[40.0], far[50.0]]
    _, alone = render(scene, pool(1.0))
    np.testing.assert_array_equal(image, alone)


def test_the_waters_normal_maps_are_the_layers_of_one_array(ctx):
    """CausticMaps: a map of the layers' size is its layer texel for texel (rows flipped to
    GL's); a smaller one is resampled, wrapping, each new texel the bilinear mean of the old
    ones about its centre; with a 16-bit map among them the layers are 16 bits and an 8-bit
    map's values are scaled to them."""
    from engine.assets.texture_data import TextureData
    from engine.render.caustics import CausticMaps, wrapped_resample

    rng = np.random.default_rng(3)
    big = TextureData(rng.integers(0, 256, (8, 8, 4), dtype=np.uint8), name="big")
    small = TextureData(rng.integers(0, 256, (4, 4, 4), dtype=np.uint8), name="small")
    maps = CausticMaps(ctx)
    assert maps.hold([big, small]) and not maps.hold([big, small])
    layers = np.frombuffer(maps.array.read(), np.uint8).reshape(2, 8, 8, 4)
    np.testing.assert_array_equal(layers[0], big.pixels[::-1])
    p = small.pixels.astype(float)
    # New texel 0 of 8 sits at old coordinate -0.25: 3/4 of old texel 0 and 1/4 of texel 3 (wrapped).
    expect = 0.75 * (0.75 * p[0, 0] + 0.25 * p[0, 3]) + 0.25 * (0.75 * p[3, 0] + 0.25 * p[3, 3])
    np.testing.assert_array_equal(wrapped_resample(small.pixels, (8, 8))[0, 0], np.rint(expect))
    np.testing.assert_array_equal(layers[1], wrapped_resample(small.pixels, (8, 8))[::-1])
    fine = TextureData(rng.integers(0, 65536, (8, 8, 4), dtype=np.uint16), name="fine")
    assert maps.hold([big, fine])
    layers = np.frombuffer(maps.array.read(), np.uint16).reshape(2, 8, 8, 4)
    np.testing.assert_array_equal(layers[0], big.pixels[::-1].astype(np.uint16) * 257)
    np.testing.assert_array_equal(layers[1], fine.pixels[::-1])
    maps.release()
    assert maps.array is None


def test_a_context_with_too_few_texture_units_draws_no_caustics_and_says_so(scene, ctx):
    """On a context with 16 fragment texture units (macOS's OpenGL 4.1) the water gathers no
    light, and a GLLimitWarning names the water and the limit, once."""
    runner = scene(pool(1.0), (48, 48))
    runner.engine.renderer.antialias = "off"
    runner.engine.renderer.caustics.release()
    runner.engine.renderer.caustics = CausticBlock(ctx, texture_units=16)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(3):
            image = runner.frame(1.0 / 60.0)
    said = [w for w in caught if issubclass(w.category, GLLimitWarning)]
    assert len(said) == 1 and "caustics need 19 texture units" in str(said[0].message)
    assert runner.engine.renderer.caustics.defines == ()
    _, flat = render(scene, pool(0.0), size=(48, 48))
    np.testing.assert_array_equal(srgb_to_linear(image), flat)


def test_caustics_values_are_checked_when_given():
    for value in (-0.1, 1.5, math.nan):
        with pytest.raises(ComponentValueError, match="Water.caustics"):
            Water(caustics=value)
        water = Water()
        with pytest.raises(ComponentValueError, match="Water.caustics"):
            water.caustics = value


def test_caustics_given_and_taken_while_running_are_drawn_from_that_frame(scene):
    """A water whose ``caustics`` is set after some frames shows them from the next frame as a
    pool that had them from the start does; set to 0 again, the flat water's frame."""
    runner = scene(pool(0.0), (48, 48))
    runner.engine.renderer.antialias = "off"
    water = max(entity for entity, _ in runner.world.query_one(Water))
    flat = [runner.frame(1.0 / 60.0) for _ in range(2)][-1]
    runner.world.get(water, Water).caustics = 1.0
    gathered = runner.frame(1.0 / 60.0)
    started = scene(pool(1.0), (48, 48))
    started.engine.renderer.antialias = "off"
    np.testing.assert_array_equal(gathered, [started.frame(1.0 / 60.0) for _ in range(2)][-1])
    runner.world.get(water, Water).caustics = 0.0
    np.testing.assert_array_equal(runner.frame(1.0 / 60.0), flat)


def test_only_what_reaches_into_the_waters_body_is_drawn_with_caustics(scene):
    """The floor under the pool is drawn with the CAUSTICS build; a box standing far off
    (out of the box under the water's outline) with the build without (on llvmpipe every
    pixel of a build pays for its caustics, on the water or not), and it looks the same as
    with no caustics at all."""
    def build(caustics):
        def b(world):
            pool(caustics, eye=(0.0, 3.0, 6.0), target=(0.0, -1.0, 0.0))(world)
            world.spawn(Transform(position=(9.0, 0.0, 0.0)), MeshRef(box((1.0, 2.0, 1.0))),
                        Material(color=(0.8, 0.3, 0.2), roughness=1.0))
        return b

    runner, lit = render(scene, build(1.0), size=(96, 64))
    drawn = {}
    for batch in runner.engine.renderer.batches.values():
        for record in batch.draw_records.values():
            drawn.setdefault(batch.entity_at[0], set()).add(record[1][1])
    floor = next(e for e, (t, _) in runner.world.query(Transform, MeshRef) if t.position.y == -DEPTH)
    far = next(e for e, (t, _) in runner.world.query(Transform, MeshRef) if t.position.x == 9.0)
    assert drawn[floor] == {True} and drawn[far] == {False}
    _, flat = render(scene, build(0.0), size=(96, 64))
    col, row = runner.project((9.0, 0.0, 0.0))
    np.testing.assert_array_equal(lit[row - 2:row + 3, col - 2:col + 3], flat[row - 2:row + 3, col - 2:col + 3])


def test_a_meshs_rows_under_the_water_are_a_batch_of_their_own_and_a_mover_changes_batch(scene):
    """Two boxes of one mesh and material (one batch, were it not for the water): the one
    standing in the pool is drawn with the CAUSTICS build in a batch of its own
    (``BatchKey.caustic_waters``), the one far off with the build without, so a level's boxes
    do not all pay for a pond's caustics.  Carried into the pool, the far one joins the
    caustic batch and shows the caustics; carried out again, it goes back; the pool carried
    over it, the two change places."""
    inside, far = (0.8, -0.95, 0.6), (9.0, -0.95, 0.0)   # slabs on the floor
    ids = {}

    def build(world):
        pool(1.0, eye=(0.0, 3.0, 6.0), target=(0.0, -1.0, 0.0))(world)
        for name, at in (("inside", inside), ("far", far)):
            ids[name] = world.spawn(Transform(position=at), MeshRef(box((0.8, 0.1, 0.8))),
                                    Material(color=(0.8, 0.8, 0.8), roughness=1.0))

    runner, _ = render(scene, build, size=(160, 120))
    renderer = runner.engine.renderer

    def batch_of(entity):
        return next(b for b in renderer.batches.values() if entity in b.entity_at[:b.count])

    def builds(batch):
        return {record[1][1] for record in batch.draw_records.values()}

    first, second = batch_of(ids["inside"]), batch_of(ids["far"])
    assert first is not second and first.mesh is second.mesh
    pool_entity = next(e for e, _ in runner.world.query_one(Water))
    assert (first.caustic_waters, second.caustic_waters) == ((pool_entity,), ())
    assert builds(first) == {True} and builds(second) == {False}
    moved = (-0.8, -0.95, 0.9)   # into the pool's near half (the far half's floor shows the surface's reflection)
    runner.world.get(ids["far"], Transform).position = moved
    for _ in range(2):
        rgb = srgb_to_linear(runner.frame(1.0 / 60.0))
    assert batch_of(ids["far"]) is first and first.count == 2 and builds(first) == {True}
    water = runner.world.get(next(e for e, _ in runner.world.query_one(Water)), Water)
    water.caustics = 0.0
    flat = srgb_to_linear(runner.frame(1.0 / 60.0))
    runner.world.get(ids["far"], MeshRef).visible = False
    gone = srgb_to_linear(runner.frame(1.0 / 60.0))
    runner.world.get(ids["far"], MeshRef).visible = True
    seen = np.abs(flat - gone).max(axis=-1) > 0.02   # its pixels, seen through the water
    assert seen.sum() > 30, seen.sum()
    assert np.abs(rgb - flat).max(axis=-1)[seen].max() > 0.05   # the caustics on it
    runner.frame(1.0 / 60.0)
    assert batch_of(ids["far"]) is batch_of(ids["inside"]) is not first   # no water gathers: one batch again
    water.caustics = 1.0
    runner.world.get(ids["far"], Transform).position = far
    runner.frame(1.0 / 60.0)
    assert batch_of(ids["far"]) is not batch_of(ids["inside"])
    assert (batch_of(ids["inside"]).caustic_waters, batch_of(ids["far"]).caustic_waters) == ((pool_entity,), ())
    # The water carried over the far slab (its body moves: the rows keyed again by their boxes).
    runner.world.get(pool_entity, Transform).position = (far[0], 0.0, far[2])
    runner.frame(1.0 / 60.0)
    assert (batch_of(ids["inside"]).caustic_waters, batch_of(ids["far"]).caustic_waters) == ((), (pool_entity,))


def test_the_overlays_switch_takes_the_caustics_off_and_on(scene):
    """The prepare stage's ``caustics`` (the overlay's "caustics" switch): off, the frame of a
    water that gathers nothing; on again, the caustics' frame."""
    runner, lit = render(scene, pool(1.0), size=(48, 48))
    _, flat = render(scene, pool(0.0), size=(48, 48))
    prepare = runner.engine.stages["prepare"]
    prepare.caustics = False
    np.testing.assert_array_equal(srgb_to_linear(runner.frame(1.0 / 60.0)), flat)
    assert runner.engine.renderer.caustics.defines == ()
    prepare.caustics = True
    np.testing.assert_array_equal(srgb_to_linear(runner.frame(1.0 / 60.0)), lit)


def table_at(table: np.ndarray, levels: np.ndarray, grid_x: np.ndarray, level: np.ndarray,
             x: np.ndarray) -> np.ndarray:
    """``table`` ([level, x]: a traced light at each of ``levels``, depths or heights, over
    ``grid_x``) read at points ``level``, ``x`` (any shape), bilinearly."""
    k = np.clip(np.searchsorted(levels, level) - 1, 0, len(levels) - 2)
    w = np.clip((level - levels[k]) / (levels[k + 1] - levels[k]), 0.0, 1.0)
    fx = (x - grid_x[0]) / (grid_x[1] - grid_x[0])
    i = np.clip(np.floor(fx).astype(int), 0, len(grid_x) - 2)
    f = fx - i
    return ((table[k, i] * (1.0 - f) + table[k, i + 1] * f) * (1.0 - w)
            + (table[k + 1, i] * (1.0 - f) + table[k + 1, i + 1] * f) * w)


def traced_light_at(xs: np.ndarray, depth: float, tiles: float = 1.0) -> np.ndarray:
    """``traced_light`` for a floor ``depth`` down under a sun straight down, the pool
    ``tiles`` times as wide (as many more map repeats), the crossings spaced by the larger of
    a texel and the sun's disc at that depth (the renderer's step: caustics.glsl)."""
    texels = wave_map(PERIODS, slope=SLOPE).pixels[0, :, :3].astype(np.float64) / 255.0 * 2.0 - 1.0
    size = len(texels)
    side = SIDE * tiles
    step = max(side / (TILING * tiles * size), depth * CAUSTIC_SUN_SPREAD)
    centres = np.linspace(xs.min() - 0.5, xs.max() + 0.5, 20001)
    crossings = np.concatenate([centres - step / 2.0, centres + step / 2.0])
    u = (crossings + side / 2.0) / side * TILING * tiles * size - 0.5
    low = np.floor(u).astype(int)
    share = (u - low)[:, None]
    m = texels[low % size] * (1.0 - share) + texels[(low + 1) % size] * share
    normals = np.stack([m[:, 0] / m[:, 2], np.ones(len(m)), -m[:, 1] / m[:, 2]], axis=1)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    rays = refract(np.tile(np.array([0.0, -1.0, 0.0]), (len(crossings), 1)), normals, 1.0 / IOR)
    landings = crossings + rays[:, 0] * depth / -rays[:, 1]
    before, after = landings[:len(centres)], landings[len(centres):]
    spread = (after - before) / step
    assert (spread > 0.0).all()   # no fold: above the depth where the bent rays first cross
    return np.interp(xs, (before + after) / 2.0, 1.0 / spread)


@pytest.mark.parametrize("second", [False, True])
def test_the_light_shafts_under_rippled_water_carry_its_caustics(scene, second):
    """Looking straight down from under a sunlit, murky pool 1.2 m deep with light shafts: each march
    texel's light is the ground truth's sum along its ray of density x transmittance x the
    sun's light at each point (through the water over it, times the traced caustic at its
    depth): the bright columns where the waves gather the sun, where the tracer puts them.
    ``second``: the pool moved 12 of its wave tiles along (the same waves over the eye) and
    another pool with caustics, out of the picture, made before it, so that the block (by
    entity) holds this one second: the march reads every water it holds."""
    from components import Fog, VolumetricFog
    from tests.test_volumetric_fog import march_rays, marched_light

    body, air = 0.3, 0.002
    settings = VolumetricFog(steps=64, half_resolution=True)
    DEEP = 1.2   # (the floor, and the body's depth: above where these waves' bent rays first cross)
    tiles = 10.0

    def build(caustics):
        def b(world):
            if second:
                another_pool(world, (3.0, 0.0, 3.0), periods=3)
            pool(caustics, eye=(0.0, -0.2, 0.0), target=(0.0, -DEEP, -0.001), sun=glm.vec3(0.0, -1.0, 0.0),
                 tiles=tiles, depth=DEEP, position=(16.0, 0.0, 0.0) if second else (0.0, 0.0, 0.0))(world)
            camera = next(e for e, _ in world.query_one(Camera))
            world.add_component(camera, Fog(density=air, color=(0.0, 0.0, 0.0)))
            world.add_component(camera, settings)
            water = max(e for e, _ in world.query_one(Water))   # (the pool over the eye)
            world.get(water, Water).fog_density = body
            world.get(water, Water).fog_color = (0.0, 0.0, 0.0)
            floor = next(e for e, (t, _) in world.query(Transform, MeshRef) if t.position.y == -DEPTH)
            world.get(floor, Transform).position = (0.0, -DEEP, 0.0)
        return b

    runner = scene(build(1.0), (96, 64))
    runner.frame()
    marched = marched_light(runner)
    held = [water.entity for water in runner.engine.renderer.caustics.waters]
    assert len(held) == 1 + second and held[-1] == max(e for e, _ in runner.world.query_one(Water))
    origin, way, (rows, columns) = march_rays(runner, (96, 64), 2)
    reach = np.minimum((-DEEP - origin[:, 1]) / way[:, 1], settings.distance)
    points = 400
    t = (np.arange(points) + 0.5) / points
    along = reach[:, None] * t[None, :]
    at = origin[:, None, :] + way[:, None, :] * along[..., None]
    depths = np.linspace(0.0, DEEP, 25)
    grid_x = np.linspace(at[..., 0].min() - 0.1, at[..., 0].max() + 0.1, 4001)
    table = np.stack([traced_light_at(grid_x, d, tiles) for d in depths])   # [depth, x]
    h = -at[..., 1]
    gathered = table_at(table, depths, grid_x, h, at[..., 0])
    density = air + body
    g = settings.anisotropy
    phase = (1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * (way @ np.array([0.0, 1.0, 0.0]))) ** 1.5)
    truth = (1.0 * settings.intensity * phase * (density * np.exp(-density * along) * np.exp(-body * h)
                                                   * gathered).sum(1) * reach / points).reshape(rows, columns)
    assert np.corrcoef(marched[..., 0].ravel(), truth.ravel())[0, 1] > 0.98
    assert np.median(np.abs(marched[..., 0] / truth - 1.0)) < 0.03
    assert truth.max() > 1.5 * np.median(truth)   # the columns


def test_uvs_square_to_the_surface_give_no_caustic_rows():
    """A water whose UV rows have no part along its plane (no frame to read the waves in)
    gives no rows (the prepare stage then says it gathers no light); a level one gives rows
    whose axes are the rows' directions along the plane, unit length."""
    from engine.render.caustics import caustic_rows
    from engine.resources import MirrorBumps

    level = MirrorBumps(wave_map(), 1.0, np.array([[0.25, 0.0, 0.0, 0.5], [0.0, 0.0, -0.25, 0.5]]), 0.0)
    rows = caustic_rows((0.0, 1.0, 0.0, 0.0), level, tiling=3.0, cross=0.5, offset=(0.1, 0.2), ior=1.333,
                        strength=1.0, depth=2.0, map_width=64)
    assert rows is not None and len(rows) == 28
    np.testing.assert_allclose(rows[12:15], (1.0, 0.0, 0.0))   # +U along x
    np.testing.assert_allclose(rows[16:19], (0.0, 0.0, -1.0))  # +V along -z
    np.testing.assert_allclose(rows[25], SIDE / (TILING * 64))  # a map texel, metres
    square = MirrorBumps(wave_map(), 1.0, np.array([[0.0, 0.25, 0.0, 0.5], [0.0, 0.0, -0.25, 0.5]]), 0.0)
    assert caustic_rows((0.0, 1.0, 0.0, 0.0), square, tiling=3.0, cross=0.5, offset=(0.0, 0.0), ior=1.333,
                        strength=1.0, depth=2.0, map_width=64) is None


def test_many_movers_are_keyed_under_the_waters_their_boxes_reach_frame_after_frame(scene):
    """Ninety things wandering in and out of two pools, boxes of several sizes (one batch of 60:
    its movers checked on arrays) and spheres (30: one by one): after every frame each one's
    batch is keyed under exactly the caustic waters whose bodies its world box reaches, the
    box worked out here from its mesh's eight corners through its world matrix."""
    from engine.assets.mesh import sphere
    from engine.resources import Surfaces

    rng = np.random.default_rng(7)
    boxes = {}
    meshes = [box((0.3, 0.3, 0.3)), sphere(0.2, 8, 6)]

    def build(world):
        pool(1.0, eye=(0.0, 6.0, 9.0), target=(2.0, -1.0, 0.0), depth=1.0)(world)
        another_pool(world, (6.0, 0.0, 0.0))
        for k in range(90):
            mesh = box((0.2 + 0.05 * (k % 4), 0.3, 0.4)) if k % 3 == 0 else meshes[k % 2]
            boxes[world.spawn(Transform(position=(float(rng.uniform(-3, 9)), float(rng.uniform(-2, 1)),
                                                  float(rng.uniform(-3, 3)))), MeshRef(mesh),
                              Material(color=(0.8, 0.8, 0.8), roughness=1.0))] = mesh

    runner = scene(build, (32, 24))
    runner.engine.renderer.antialias = "off"
    runner.frame()
    surfaces = runner.world.resources[Surfaces]
    bodies = {}
    for entity, water in runner.world.query_one(Water):
        state = surfaces.mirrors[entity]
        top = np.asarray(state.corners)[:, :3]
        ends = np.concatenate([top, top - np.array(glm.vec3(state.plane)) * water.depth])
        bodies[entity] = (ends.min(axis=0), ends.max(axis=0))
    renderer = runner.engine.renderer
    seen_keys = set()
    for _ in range(6):
        for entity in boxes:
            t = runner.world.get(entity, Transform)
            t.position = t.position + glm.vec3(*rng.uniform(-0.8, 0.8, 3))
            t.rotation = glm.angleAxis(float(rng.uniform(0, 3)), glm.normalize(glm.vec3(*rng.uniform(0.1, 1, 3))))
        runner.frame()
        for entity, mesh in boxes.items():
            lo, hi = (np.asarray(v, np.float64) for v in mesh.bounds)
            corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
            world = np.array(runner.world.get(entity, Transform).world.to_list(), np.float64)   # rows: columns
            placed = corners @ world
            low, high = placed[:, :3].min(axis=0), placed[:, :3].max(axis=0)
            expected = tuple(sorted(w for w, (body_lo, body_hi) in bodies.items()
                                    if (high >= body_lo).all() and (low <= body_hi).all()))
            batch = next(b for b in renderer.batches.values() if entity in b.entity_at[:b.count])
            assert batch.caustic_waters == expected, (entity, batch.caustic_waters, expected)
            seen_keys.add(expected)
    assert len(seen_keys) >= 3   # (in neither, in one, in the other: the movers changed batch)


def test_the_camera_walking_from_one_held_pool_to_another_keeps_the_block_and_maps(scene):
    """Two pools, both held: the camera moved from over one to over the other keeps their slots
    (by entity) and the maps' array (not made again and uploaded as the nearer one changes)."""
    runner, _ = render(scene, side_by_side(True, True), size=(32, 32))
    caustics = runner.engine.renderer.caustics
    slots, array = [water.entity for water in caustics.waters], caustics.maps.array
    camera = next(e for e, _ in runner.world.query_one(Camera))
    for x in (LEFT[0], RIGHT[0], LEFT[0]):
        runner.world.get(camera, Transform).position = (x, -0.05, 0.0)
        runner.frame()
        assert [water.entity for water in caustics.waters] == slots and caustics.maps.array is array


CEILING = 1.0     # the ceiling over the pool, for the light its waves throw back up
CALM = 0.1        # normal_scale for the waves thrown up: a reflection turns a ray twice the slope's
#                   angle, so the map's full slope folds the light within a few centimetres


def reflect(incident: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """The mirror law for unit rays (rows) off unit normals (rows)."""
    return incident - 2.0 * np.sum(incident * normal, axis=-1, keepdims=True) * normal


def traced_reflected_light(xs: np.ndarray, height: float) -> np.ndarray:
    """``traced_light`` for the light the waves throw back up (scaled by CALM) onto a plane
    ``height`` over the surface: rays of sunlight reflected at a fine row of crossings, landed
    on the plane, the light at a landing the spacing of the crossings over that of the landings."""
    texels = wave_map(PERIODS, slope=SLOPE).pixels[0, :, :3].astype(np.float64) / 255.0 * 2.0 - 1.0
    size = len(texels)
    step = SIDE / (TILING * size)
    centres = np.linspace(xs.min() - 1.0, xs.max() + 0.5, 20001)
    crossings = np.concatenate([centres - step / 2.0, centres + step / 2.0])
    u = (crossings + SIDE / 2.0) / SIDE * TILING * size - 0.5
    low = np.floor(u).astype(int)
    share = (u - low)[:, None]
    m = texels[low % size] * (1.0 - share) + texels[(low + 1) % size] * share
    slope_u, slope_v = m[:, 0] / m[:, 2] * CALM, m[:, 1] / m[:, 2] * CALM
    normals = np.stack([slope_u, np.ones_like(slope_u), -slope_v], axis=1)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    rays = reflect(np.tile(np.array(tuple(SUN)), (len(crossings), 1)), normals)
    landings = crossings + rays[:, 0] * height / rays[:, 1]
    before, after = landings[:len(centres)], landings[len(centres):]
    spread = (after - before) / step
    landings = (before + after) / 2.0
    assert (spread > 0.0).all()   # no fold
    return np.interp(xs, landings, 1.0 / spread)


def ceiling_pool(caustics: float, reflects: bool = True):
    """``pool``'s water reflecting the sun (``Mirror.reflects_light``), its waves CALM, under a
    grey ceiling CEILING over it that casts no shadow (the sun reaches the water through it),
    the camera between them looking up: the ceiling is lit by the water's image of the sun alone."""
    def build(world):
        at = glm.vec3(0.0, 0.05, 0.0)
        world.spawn(Transform(position=at, rotation=look_rotation(glm.vec3(0.0, CEILING, -0.001) - at)),
                    Camera(fov_y=70.0))
        world.spawn(Skybox(faces=[np.zeros((8, 8, 3), np.float32) for _ in range(6)]))
        world.spawn(DirectionalLight(direction=tuple(SUN), intensity=30.0))
        world.spawn(Transform(position=(0.0, CEILING, 0.0), rotation=glm.angleAxis(math.pi / 2, glm.vec3(1, 0, 0))),
                    MeshRef(quad(60.0, 60.0), casts_shadows=False),
                    Material(color=(ALBEDO, ALBEDO, ALBEDO, 1.0), roughness=1.0, environment_reflection=0.0))
        world.spawn(Transform(rotation=FLAT), MeshRef(quad(SIDE, SIDE)),
                    Material(color=(1.0, 1.0, 1.0, 0.0), normal_map=wave_map(PERIODS, slope=SLOPE), normal_scale=CALM),
                    Mirror(reflects_light=reflects),
                    Water(ior=IOR, tiling=TILING, speed=0.0, cross=0.0, caustics=caustics))
    return build


def ceiling_points(runner) -> np.ndarray:
    """Where each pixel centre's ray meets the ceiling (x), [row, column] (NaN: it does not)."""
    from tests.support import pixel_rays

    eye, directions = pixel_rays(runner.engine.main_view, runner.size)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (CEILING - eye[1]) / directions[..., 1]
    return np.where(t > 0.0, eye[0] + directions[..., 0] * t, np.nan)


def test_the_light_a_rippled_water_throws_up_is_where_a_ray_tracer_gathers_it(scene):
    """A water that reflects the sun (``Mirror.reflects_light``) and has caustics throws the
    bright moving net of a sunlit pool on the ceiling over it: each ceiling pixel's light over
    the same pixel with ``caustics`` 0 (the flat water's image of the sun, weighed by
    Fresnel's reflectance) is the share a ray tracer reflecting the sunlight off the waves
    gathers at its point, and the mean is kept.  Without the water's light (reflects_light
    off) the ceiling is black: what is measured is the reflection's."""
    runner, lit = render(scene, ceiling_pool(1.0))
    _, flat = render(scene, ceiling_pool(0.0))
    _, dark = render(scene, ceiling_pool(1.0, reflects=False))
    assert runner.stats.virtual_lights == 1
    assert dark.max() < 0.01 and 0.04 < flat.min() and flat.max() < 0.3, (dark.max(), flat.min(), flat.max())
    share = lit[..., 0] / flat[..., 0]
    xs = ceiling_points(runner)
    traced = traced_reflected_light(xs.ravel(), CEILING).reshape(xs.shape)
    assert traced.max() > 1.6 and traced.min() < 0.7, (traced.min(), traced.max())   # marked caustics
    assert np.corrcoef(share.ravel(), traced.ravel())[0, 1] > 0.98, np.corrcoef(share.ravel(), traced.ravel())[0, 1]
    assert np.median(np.abs(share - traced)) < 0.04, np.median(np.abs(share - traced))
    assert abs(share.mean() - traced.mean()) < 0.03


def test_what_stands_over_a_water_that_reflects_light_is_drawn_with_its_caustics(scene):
    """A water that reflects light throws its caustics up too, so its reach (``reach_box``)
    is its body and the air up to ``depth`` over it, widened by ``depth`` along its plane:
    a slab hanging over the pool is keyed under it (drawn with the CAUSTICS build), one far
    off is not; with ``reflects_light`` off only the body is, and the slab over it is not."""
    from engine.render.caustics import body_box, reach_box

    corners = np.array([[-2.0, 0.0, -2.0, 1.0], [2.0, 0.0, -2.0, 1.0], [-2.0, 0.0, 2.0, 1.0], [2.0, 0.0, 2.0, 1.0]])
    assert reach_box(corners, (0.0, 1.0, 0.0), 3.0, False) == body_box(corners, (0.0, -1.0, 0.0), 3.0)
    assert reach_box(corners, (0.0, 1.0, 0.0), 3.0, True) == ((-5.0, -3.0, -5.0), (5.0, 3.0, 5.0))
    ids = {}

    def build(reflects: bool):
        def b(world):
            pool(1.0, eye=(0.0, 3.0, 6.0), target=(0.0, -1.0, 0.0), depth=3.0)(world)
            world.get(next(e for e, _ in world.query_one(Water)), Mirror).reflects_light = reflects
            for name, at in (("over", (3.5, 2.0, 0.0)), ("far", (9.0, 2.0, 0.0))):
                ids[name] = world.spawn(Transform(position=at), MeshRef(box((0.8, 0.1, 0.8))),
                                        Material(color=(0.8, 0.8, 0.8), roughness=1.0))
        return b

    for reflects in (True, False):
        runner, _ = render(scene, build(reflects), size=(64, 48))
        pool_entity = next(e for e, _ in runner.world.query_one(Water))

        batches = list(runner.engine.renderer.batches.values())
        over, far = (next(b for b in batches if ids[name] in b.entity_at[:b.count]).caustic_waters
                     for name in ("over", "far"))
        assert (over, far) == (((pool_entity,), ()) if reflects else ((), ()))


CANOPY = (3.65, 0.7)   # a canopy past the pool's edge (x = 2): its middle (x, height)
CANOPY_TILT = math.radians(10.0)   # facing down, turned 10 degrees towards the pool


def low_sun_pool(caustics: float, elevation: float, ids: dict | None = None):
    """``ceiling_pool``'s water (depth 1) under a sun ``elevation`` degrees up, slanting along
    +x, and past it a grey canopy 1.1 m wide facing down and back towards the pool, tilted
    so that the sun (20 degrees up) misses its face: only the light the water throws up lights
    it, rising along +x, under the water's depth over it where the sun is low."""
    def build(world):
        at = glm.vec3(2.4, 0.15, 0.0)
        world.spawn(Transform(position=at, rotation=look_rotation(glm.vec3(CANOPY[0], CANOPY[1], 0.0) - at)),
                    Camera(fov_y=50.0))
        world.spawn(Skybox(faces=[np.zeros((8, 8, 3), np.float32) for _ in range(6)]))
        e = math.radians(elevation)
        world.spawn(DirectionalLight(direction=(math.cos(e), -math.sin(e), 0.0), intensity=30.0))
        facing = glm.angleAxis(CANOPY_TILT, glm.vec3(0, 0, 1)) * glm.angleAxis(math.pi / 2, glm.vec3(1, 0, 0))
        canopy = world.spawn(Transform(position=(CANOPY[0], CANOPY[1], 0.0), rotation=facing),
                             MeshRef(quad(1.1, 4.0), casts_shadows=False),
                             Material(color=(ALBEDO, ALBEDO, ALBEDO, 1.0), roughness=1.0, environment_reflection=0.0))
        if ids is not None:
            ids["canopy"] = canopy
        world.spawn(Transform(rotation=FLAT), MeshRef(quad(SIDE, SIDE)),
                    Material(color=(1.0, 1.0, 1.0, 0.0), normal_map=wave_map(PERIODS, slope=SLOPE), normal_scale=CALM),
                    Mirror(reflects_light=True),
                    Water(ior=IOR, tiling=TILING, speed=0.0, cross=0.0, caustics=caustics, depth=1.0))
    return build


def test_a_low_suns_light_thrown_up_by_the_water_carries_its_caustics_as_far_as_it_leans(scene):
    """At 20 degrees the sun's light off the pool rises 1 m (the water's depth, as far as its
    caustics reach) over 2.75 m along the plane, so it lights a canopy 1.1-2.2 m past the
    pool's edge under that height: the canopy is keyed under the water (drawn with its
    caustics) and shows the net, the share of the flat water's light swinging about 1.  The
    reach box leans with the sun (``reach_box``): at 45 degrees or higher it is the one a
    high sun gives, which leaves the canopy out (drawn without the net: a share of 1)."""
    from engine.render.caustics import reach_box

    corners = np.array([[-2.0, 0.0, -2.0, 1.0], [2.0, 0.0, -2.0, 1.0], [-2.0, 0.0, 2.0, 1.0], [2.0, 0.0, 2.0, 1.0]])
    high = reach_box(corners, (0.0, 1.0, 0.0), 1.0, True, ((0.5, -0.8, 0.0),))
    assert high == reach_box(corners, (0.0, 1.0, 0.0), 1.0, True) == ((-3.0, -1.0, -3.0), (3.0, 1.0, 3.0))
    e = math.radians(20.0)
    low = reach_box(corners, (0.0, 1.0, 0.0), 1.0, True, ((math.cos(e), -math.sin(e), 0.0),))
    assert low[1][0] >= 2.0 + 1.0 / math.tan(e) and low[0] == high[0]   # (leaning one way: away from the sun)

    ids = {}
    runner, lit = render(scene, low_sun_pool(1.0, 20.0, ids), size=(64, 48))
    _, flat = render(scene, low_sun_pool(0.0, 20.0), size=(64, 48))
    pool_entity = next(entity for entity, _ in runner.world.query_one(Water))
    canopy = next(b for b in runner.engine.renderer.batches.values() if ids["canopy"] in b.entity_at[:b.count])
    assert canopy.caustic_waters == (pool_entity,)
    seen = flat[..., 0] > 0.01   # (the canopy lit by the water's light: nothing else lights anything)
    assert seen.sum() > 400, seen.sum()
    share = lit[..., 0][seen] / flat[..., 0][seen]
    assert share.std() > 0.15 and share.max() > 1.3 and share.min() < 0.8, (share.std(), share.min(), share.max())
    assert 0.75 < share.mean() < 1.25, share.mean()
    # The sun rising to 60 degrees: the reach box is the high sun's again, the canopy keyed out
    # (its light no longer reaches it under the depth); back to 20, keyed in again.
    (light,) = [light for _, light in runner.world.query_one(DirectionalLight)]
    for elevation, keyed in ((60.0, ()), (20.0, (pool_entity,))):
        e = math.radians(elevation)
        light.direction = (math.cos(e), -math.sin(e), 0.0)
        runner.frame(1.0 / 60.0)
        canopy = next(b for b in runner.engine.renderer.batches.values() if ids["canopy"] in b.entity_at[:b.count])
        assert canopy.caustic_waters == keyed, elevation
        held = {water.entity: water.box for water in runner.engine.renderer.caustics.waters}
        assert held[pool_entity] == (high if not keyed else low), elevation
    # A second, low sun new this frame (the first raised again): the canopy is keyed in on its
    # first frame (the extract stage keys rows before the prepare stage chooses the lights: it
    # makes the same choice ahead), under the box the prepare stage holds.
    light.direction = (math.cos(math.radians(60.0)), -math.sin(math.radians(60.0)), 0.0)
    runner.frame(1.0 / 60.0)
    runner.world.spawn(DirectionalLight(direction=(math.cos(e), -math.sin(e), 0.0), intensity=30.0))
    runner.frame(1.0 / 60.0)
    canopy = next(b for b in runner.engine.renderer.batches.values() if ids["canopy"] in b.entity_at[:b.count])
    held = {water.entity: water.box for water in runner.engine.renderer.caustics.waters}
    assert canopy.caustic_waters == (pool_entity,) and held[pool_entity] == low


def test_a_pose_that_reaches_into_the_water_is_keyed_under_it(scene):
    """A morphed sheet standing over the pool, its mesh as modelled 0.2 m over the surface:
    keyed under no water.  Its second target's weight at -1 pulls its right half down 0.5 m,
    into the water's body: it is keyed under the water the frame the weight changes (the box
    holding its pose, not its mesh's), its rows drawn with the CAUSTICS builds; back to 0,
    keyed out again.  The same sheet spawned already posed is keyed under the water at once."""
    from components import Morph
    from tests.test_morph_targets import morphed_sheet

    held = {}

    def build(weights):
        def b(world):
            pool(1.0)(world)
            held["sheet"] = world.spawn(Transform(position=(0.0, -0.3, 0.0)), MeshRef(morphed_sheet()),
                                        Material(color=(0.8, 0.2, 0.2, 1.0)), Morph(weights))
        return b

    def keyed(runner) -> tuple[int, ...]:
        (batch,) = [b for b in runner.engine.renderer.batches.values() if held["sheet"] in b.entity_at[:b.count]]
        return batch.caustic_waters

    runner, _ = render(scene, build((0.0, 0.0)))
    water = next(entity for entity, _ in runner.world.query_one(Water))
    assert keyed(runner) == ()
    for weights, expected in (((0.0, -1.0), (water,)), ((0.0, 0.0), ()), ((0.0, -1.0), (water,))):
        runner.world.get(held["sheet"], Morph).weights = weights
        runner.frame(1.0 / 60.0)
        assert keyed(runner) == expected, weights
    runner, _ = render(scene, build((0.0, -1.0)))
    assert keyed(runner) == (next(entity for entity, _ in runner.world.query_one(Water)),)


LAMP_HEIGHT = 1.5   # the lamp over the pool's surface, for the lamps' caustics


def traced_lamp_light(xs: np.ndarray, lamp_height: float = LAMP_HEIGHT, depth: float | np.ndarray = DEPTH,
                      along_x: tuple[float, ...] = (0.0,), shape: str = "point", crossings: int = 40001) -> np.ndarray:
    """The light at points ``xs`` ``depth`` under the surface (on the line under the lamp,
    along the waves' U) of a lamp ``lamp_height`` over the pool, through the waves, over the
    same through flat water (``traced_lamp_share``: each ray bent by Snell's law, and
    weighed by Fresnel's transmission, unpolarised, at its crossing); ``depth`` an array:
    [depth, x]; ``crossings``: how many rays."""
    def through(incident: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ray = refract(incident, normal, 1.0 / IOR)
        cos_i = -np.sum(incident * normal, axis=1)
        cos_t = -np.sum(ray * normal, axis=1)
        rs = ((cos_i - IOR * cos_t) / (cos_i + IOR * cos_t)) ** 2
        rp = ((IOR * cos_i - cos_t) / (IOR * cos_i + cos_t)) ** 2
        return ray, 1.0 - 0.5 * (rs + rp)

    rays = np.linspace(xs.min() - 0.05, xs.max() + 0.05, crossings)   # (each lands farther out)
    return traced_lamp_share(xs, lamp_height, rays, 1.0, through, -np.asarray(depth), along_x, shape)


def traced_lamp_share(xs: np.ndarray, lamp_height: float, crossings: np.ndarray, scale: float, leave,
                      plane: float, along_x: tuple[float, ...] = (0.0,), shape: str = "point") -> np.ndarray:
    """The light at points ``xs`` of the plane y = ``plane`` (on the line over or under the
    lamp's foot, along the waves' U) of a lamp ``lamp_height`` over the pool, off or through
    its waves (the map's normals, tilted ``scale`` times), over the same off or through flat
    water, by tracing: rays from the lamp meet the surface at ``crossings`` (a fine row),
    each leaves it as ``leave`` (incident, normal) says (the ray on, and the share of the
    light it takes), and lands on the plane; the light at a landing is the light at the
    crossing (the lamp's cos / distance^2 there, times the share) over the area it lands on
    (along the line the spacing of the landings, across it the spread of two rays a
    millimetre apart).  A lamp with a length along x: its points ``along_x`` (evenly over it)
    each traced so, the light the sum of theirs, each weighed as its ``shape`` sends light
    its way ("panel": a face turned down, by the cosine from straight down; "tube": along x,
    by the sine from its axis)."""
    waves = flat = 0.0
    for x in along_x:
        lit = traced_lamp_lights(xs, np.array([x, lamp_height, 0.0]), crossings, scale, leave, plane, shape)
        waves, flat = waves + lit[0], flat + lit[1]
    return waves / flat


def traced_lamp_lights(xs: np.ndarray, lamp: np.ndarray, crossings: np.ndarray, scale: float, leave, plane: float,
                       shape: str) -> tuple[np.ndarray, np.ndarray]:
    """``traced_lamp_share``'s light at ``xs`` of one point of a lamp at ``lamp`` (x, its
    height, 0), through the waves and through flat water (``plane`` an array: [plane, x],
    each ray bent once and landed on each)."""
    texels = wave_map(PERIODS, slope=SLOPE).pixels[0, :, :3].astype(np.float64) / 255.0 * 2.0 - 1.0
    size = len(texels)

    def light(flat: bool) -> np.ndarray:
        u = (crossings + SIDE / 2.0) / SIDE * TILING * size - 0.5
        low = np.floor(u).astype(int)
        share = (u - low)[:, None]
        m = texels[low % size] * (1.0 - share) + texels[(low + 1) % size] * share
        slope_u = np.zeros(len(crossings)) if flat else m[:, 0] / m[:, 2] * scale
        normal = np.stack([slope_u, np.ones_like(slope_u), np.zeros_like(slope_u)], axis=1)
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)

        def land(z: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            at = np.stack([crossings, np.zeros_like(crossings), np.full_like(crossings, z)], axis=1)
            incident = at - lamp
            distance = np.linalg.norm(incident, axis=1)
            incident /= distance[:, None]
            ray, taken = leave(incident, normal)
            t = planes[:, None] / ray[None, :, 1]
            flux = -incident[:, 1] / distance ** 2 * taken   # per unit of surface
            flux *= {"point": 1.0, "panel": -incident[:, 1], "tube": np.sqrt(1.0 - incident[:, 0] ** 2)}[shape]
            return at[:, 0] + ray[:, 0] * t, at[:, 2] + ray[:, 2] * t, flux

        landed, _, flux = land(0.0)
        _, aside, _ = land(1e-3)
        along = np.gradient(landed, crossings, axis=1)
        assert (along > 0.0).all()   # no fold
        lit = np.stack([np.interp(xs, landed[k], flux / (along[k] * (aside[k] / 1e-3))) for k in range(len(planes))])
        return lit if np.ndim(plane) else lit[0]

    planes = np.atleast_1d(np.asarray(plane, np.float64))

    return light(False), light(True)


LAMP_HALF = 0.2   # half the length along x (the waves' U) of the panel and the tube lamps


def spawn_lamp(world, height: float, intensity: float, shape: str = "point") -> int:
    """A lamp ``height`` over the pool's centre: a point, a panel 2 x LAMP_HALF along x and
    2 cm across turned face down, or a tube 2 x LAMP_HALF long along x (each of about the
    same light straight down)."""
    if shape == "panel":
        down = glm.angleAxis(-math.pi / 2.0, glm.vec3(1, 0, 0))   # (its face, -Z, turned to -Y)
        return world.spawn(Transform(position=(0.0, height, 0.0), rotation=down),
                           PointLight(intensity=intensity, range=20.0, rectangle=(2.0 * LAMP_HALF, 0.02)))
    if shape == "tube":
        return world.spawn(Transform(position=(0.0, height, 0.0)),
                           PointLight(intensity=intensity, range=20.0, length=2.0 * LAMP_HALF, radius=0.01))
    return world.spawn(Transform(position=(0.0, height, 0.0)), PointLight(intensity=intensity, range=20.0))


def lamp_along(shape: str) -> tuple[float, ...]:
    """The points along x the tracer sums for a lamp of ``shape`` (``spawn_lamp``'s)."""
    return (0.0,) if shape == "point" else tuple(np.linspace(-LAMP_HALF, LAMP_HALF, 21).tolist())


def lamp_pool(caustics: float, height: float = LAMP_HEIGHT, shape: str = "point"):
    """``pool``'s floor and waves lit by a lamp ``height`` over the surface's centre instead
    of the sun (``spawn_lamp``'s ``shape``), the camera just under the surface looking down at
    the floor under the lamp."""
    def build(world):
        pool(caustics, sun=(0.0, -1.0, 0.0))(world)
        (sun,) = [entity for entity, _ in world.query_one(DirectionalLight)]
        world.delete_entity(sun)
        spawn_lamp(world, height, 12.0 * ((height + DEPTH) / (LAMP_HEIGHT + DEPTH)) ** 2, shape)
    return build


@pytest.mark.parametrize("height", [LAMP_HEIGHT, 0.6])
def test_a_lamps_light_under_rippled_water_is_where_a_ray_tracer_gathers_it(scene, height):
    """A lamp over the pool: its rays fan out from it, and the waves gather them as they
    gather the sun's.  Along the line under the lamp (across the waves), each floor pixel's
    light over the same pixel with ``caustics`` 0 is the traced light through the waves over
    the traced light through flat water (each the light through a crossing over the area it
    lands on): their profiles match, the brightest lines where the tracer puts them.  A lamp
    0.6 m over a floor a metre down spreads its rays more through the water than the waves
    move them (the sun's fixed-point search would run away there; the chord method does not)."""
    runner, lit = render(scene, lamp_pool(1.0, height))
    _, flat = render(scene, lamp_pool(0.0, height))
    assert runner.engine.renderer.caustics.lamps == (0,)
    assert 0.05 < flat.min() and flat.max() < 0.6, (flat.min(), flat.max())
    points = floor_points(runner)
    line = np.abs(points[..., 1]) < 0.04   # floor pixels on the line under the lamp
    assert line.sum() > 100
    share = lit[..., 0][line] / flat[..., 0][line]
    traced = traced_lamp_light(points[..., 0][line], height)
    assert traced.max() > 1.5 and traced.min() < 0.75, (traced.min(), traced.max())
    assert np.corrcoef(share, traced)[0, 1] > 0.98, np.corrcoef(share, traced)[0, 1]
    assert np.median(np.abs(share - traced)) < 0.04, np.median(np.abs(share - traced))


def test_a_lamp_over_the_water_in_the_second_lamp_slot_gathers_its_own_net(scene):
    """``lamp_pool``'s lamp 1.5 m over the pool, with another lamp spawned before it (the
    first point-light slot) whose range stops short of the water: the lamp over the pool is
    held from the second slot (``CausticBlock.lamps`` (1,): the block's first caustic lamp
    names light slot 1), and its net on the floor is the tracer's, as in the one-lamp pool;
    the frame is the one-lamp pool's (the other lamp lights nothing here)."""
    def build(world):
        pool(1.0, sun=(0.0, -1.0, 0.0))(world)
        (sun,) = [entity for entity, _ in world.query_one(DirectionalLight)]
        world.delete_entity(sun)
        world.spawn(Transform(position=(9.0, 1.0, 0.0)), PointLight(intensity=5.0, range=3.0))   # short of it
        spawn_lamp(world, LAMP_HEIGHT, 12.0)

    runner, lit = render(scene, build)
    _, flat = render(scene, lamp_pool(0.0))
    _, alone = render(scene, lamp_pool(1.0))
    kept = runner.world.resources[KeptLights]
    over = [slot for slot, entity in enumerate(kept.point)
            if entity is not None and runner.world.get(entity, Transform).position.x == 0.0]
    assert over == [1] and runner.engine.renderer.caustics.lamps == (1,)
    points = floor_points(runner)
    line = np.abs(points[..., 1]) < 0.04   # floor pixels on the line under the lamp
    assert line.sum() > 100
    share = lit[..., 0][line] / flat[..., 0][line]
    traced = traced_lamp_light(points[..., 0][line], LAMP_HEIGHT)
    assert traced.max() > 1.5 and traced.min() < 0.75, (traced.min(), traced.max())
    assert np.corrcoef(share, traced)[0, 1] > 0.98, np.corrcoef(share, traced)[0, 1]
    assert np.median(np.abs(share - traced)) < 0.04, np.median(np.abs(share - traced))
    np.testing.assert_allclose(lit, alone, atol=1.5 / 255.0)


def traced_reflected_lamp_light(xs: np.ndarray, lamp_height: float = LAMP_HEIGHT, height: float = CEILING,
                                along_x: tuple[float, ...] = (0.0,), shape: str = "point") -> np.ndarray:
    """The light at points ``xs`` ``height`` over the surface (on the line over the lamp's
    foot, along the waves' U) that a lamp ``lamp_height`` over the pool throws up off its
    waves (tilted CALM times), over the same off flat water (``traced_lamp_share``: each ray
    reflected, all of it: Fresnel's reflectance is the flat water's, as the lamp's image
    weighs it, in both)."""
    crossings = np.linspace(xs.min() * 0.5 - 0.2, xs.max() * 0.7 + 0.2, 40001)   # (each lands farther out)
    return traced_lamp_share(xs, lamp_height, crossings, CALM,
                             lambda incident, normal: (reflect(incident, normal), 1.0), height, along_x, shape)


def ceiling_lamp_pool(caustics: float, reflects: bool = True, shape: str = "point"):
    """``ceiling_pool`` lit by a lamp LAMP_HEIGHT over the pool's centre (``spawn_lamp``'s
    ``shape``), over the ceiling (which casts no shadow: its light reaches the water), instead
    of the sun: the ceiling's face is lit by the lamp's image in the water alone."""
    def build(world):
        ceiling_pool(caustics, reflects)(world)
        (sun,) = [entity for entity, _ in world.query_one(DirectionalLight)]
        world.delete_entity(sun)
        spawn_lamp(world, LAMP_HEIGHT, 150.0, shape)
    return build


def test_the_light_a_rippled_water_throws_up_from_a_lamp_is_where_a_ray_tracer_gathers_it(scene):
    """A lamp over a water that reflects light (``Mirror.reflects_light``): its image in the
    water lights the ceiling, and the waves gather its light there as they gather the sun's
    (``caustic_reflected_lamp_light``).  Along the line over the lamp's foot, each ceiling
    pixel's light over the same pixel with ``caustics`` 0 is the traced light off the waves
    over the traced light off flat water: the profiles match, the brightest lines where the
    tracer puts them.  Without the water's light the ceiling is black."""
    from tests.support import pixel_rays

    runner, lit = render(scene, ceiling_lamp_pool(1.0))
    _, flat = render(scene, ceiling_lamp_pool(0.0))
    _, dark = render(scene, ceiling_lamp_pool(1.0, reflects=False))
    assert runner.stats.virtual_lights == 1
    assert dark.max() < 0.01 and 0.03 < flat.min() and flat.max() < 0.5, (dark.max(), flat.min(), flat.max())
    eye, directions = pixel_rays(runner.engine.main_view, runner.size)
    t = (CEILING - eye[1]) / directions[..., 1]
    points = eye + directions * t[..., None]
    line = np.abs(points[..., 2]) < 0.04   # ceiling pixels over the line across the waves, through the lamp's foot
    assert line.sum() > 100
    share = lit[..., 0][line] / flat[..., 0][line]
    traced = traced_reflected_lamp_light(points[..., 0][line])
    assert traced.max() > 1.3 and traced.min() < 0.8, (traced.min(), traced.max())   # (a marked net)
    assert np.corrcoef(share, traced)[0, 1] > 0.97, np.corrcoef(share, traced)[0, 1]
    assert np.median(np.abs(share - traced)) < 0.05, np.median(np.abs(share - traced))
    # What it can reach: the air up to the depth over the water, leaned out from the lamp's
    # foot as its light rises (a corner 2 m out each way: 1.33 m more at 1 m up, then the
    # waves' metre, out to the quarter metre).
    from engine.render.caustics import reach_box

    corners = np.array([[-2.0, 0.0, -2.0, 1.0], [2.0, 0.0, -2.0, 1.0], [-2.0, 0.0, 2.0, 1.0], [2.0, 0.0, 2.0, 1.0]])
    assert reach_box(corners, (0.0, 1.0, 0.0), 1.0, True, (), ((0.0, LAMP_HEIGHT, 0.0),)) == \
        ((-4.5, -1.0, -4.5), (4.5, 1.0, 4.5))


@pytest.mark.parametrize("shape, way", [("panel", "under"), ("tube", "under"), ("panel", "over"), ("tube", "over")])
def test_a_panels_or_a_tubes_net_blurs_as_far_as_its_light_spreads(scene, shape, way):
    """A panel (0.4 m along the waves' U, 2 cm across, face down) or a tube (0.4 m along U)
    over the pool, its net on the floor under the water (``under``) or thrown up on the
    ceiling over it (``over``: its image in a water that reflects light).  The ray tracer sums
    the light of 21 points along the lamp (each weighed as the shape sends light its way):
    the net is much softer than a point's (its std about two thirds), and the shader's
    (``caustic_lamp_radius``: the steps along each axis as far as the lamp spreads its light)
    follows it: the same profile, within 6% at the median, as marked as the traced one
    within a fifth.  A point lamp's gather (the lamp's size left out) is half again as marked."""
    from tests.support import pixel_rays

    build = lamp_pool if way == "under" else ceiling_lamp_pool
    runner, lit = render(scene, build(1.0, shape=shape))
    _, flat = render(scene, build(0.0, shape=shape))
    if way == "under":
        assert runner.engine.renderer.caustics.lamps == (0,)
        points = floor_points(runner)
        line = np.abs(points[..., 1]) < 0.04
        xs = points[..., 0][line]
        traced, point = traced_lamp_light(xs, along_x=lamp_along(shape), shape=shape), traced_lamp_light(xs)
    else:
        assert runner.stats.virtual_lights == 1
        eye, directions = pixel_rays(runner.engine.main_view, runner.size)
        t = (CEILING - eye[1]) / directions[..., 1]
        line = np.abs((eye + directions * t[..., None])[..., 2]) < 0.04
        xs = (eye + directions * t[..., None])[..., 0][line]
        traced = traced_reflected_lamp_light(xs, along_x=lamp_along(shape), shape=shape)
        point = traced_reflected_lamp_light(xs)
    assert line.sum() > 100 and 0.03 < flat.min() and flat.max() < 0.6, (line.sum(), flat.min(), flat.max())
    assert traced.std() < 0.75 * point.std(), (traced.std(), point.std())
    share = lit[..., 0][line] / flat[..., 0][line]
    assert np.corrcoef(share, traced)[0, 1] > 0.92, np.corrcoef(share, traced)[0, 1]
    assert np.median(np.abs(share - traced)) < 0.06, np.median(np.abs(share - traced))
    assert 0.8 < share.std() / traced.std() < 1.2, (share.std(), traced.std())


def test_the_lamps_over_a_water_are_held_up_to_four_and_the_rest_are_said(scene):
    """Six lamps over the pool, each brighter than the one before, and one beside it whose
    range stops short of it: the four brightest over it are held (``CausticBlock.lamps``, the
    CAUSTIC_LAMPS builds), the other two counted and said once; a lamp under the surface or
    out of reach is not held."""
    from engine.render.caustics import MAX_CAUSTIC_LAMPS

    def build(world):
        pool(1.0)(world)
        for k in range(6):
            world.spawn(Transform(position=(-1.5 + 0.6 * k, 1.0, 0.0)),
                        PointLight(intensity=0.1 * (1 + k), range=5.0))
        world.spawn(Transform(position=(9.0, 1.0, 0.0)), PointLight(intensity=0.1, range=3.0))   # short of it
        world.spawn(Transform(position=(0.5, -0.5, 0.5)), PointLight(intensity=0.1, range=5.0))   # under it

    with pytest.warns(CausticLimitWarning, match=r"6 lamps stand over waters with caustics: the light of the 4 bright"):
        runner, _ = render(scene, build, size=(32, 32))
    kept = runner.world.resources[KeptLights]
    held = runner.engine.renderer.caustics.lamps
    assert len(held) == MAX_CAUSTIC_LAMPS and runner.stats.caustic_lamps_cut == 2
    over = sorted((-runner.world.get(entity, PointLight).intensity, slot) for slot, entity in enumerate(kept.point)
                  if entity is not None and 0.9 < runner.world.get(entity, Transform).position.y
                  and runner.world.get(entity, Transform).position.x < 5.0)
    assert len(over) == 6 and list(held) == [slot for _, slot in over[:MAX_CAUSTIC_LAMPS]]
    assert ("CAUSTIC_LAMPS", "1") in runner.engine.renderer.caustics.defines
    from shell.overlay_text import overlay_lines

    assert any("caustic lamps 2" in line for line in overlay_lines(runner.engine, [0.016]))   # (the overlay says it)


def lamp_shafts(scene, shape: str = "point", crossings: int = 40001) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Looking straight down from under ``lamp_pool``'s murky pool (its lamp of ``shape``),
    with light shafts: along the line under the lamp, each march texel's light with caustics
    over its light without, and the ground truth's: the sum along its ray of density x
    transmittance x the lamp's light at each point (its falloff, its face as the shafts take
    it: ``lamp_face``, the phase function, the water over it on its way) times the traced
    caustic at the point's depth (``traced_lamp_light``, the lamp's points summed; of
    ``crossings`` rays), over the same sum without the caustic; and that truth for a point
    lamp."""
    from components import Fog, VolumetricFog
    from tests.test_volumetric_fog import march_rays, marched_light

    body, air = 0.3, 0.002
    settings = VolumetricFog(steps=64, half_resolution=True)
    deep, lamp_range = 1.0, 20.0

    def build(caustics):
        def b(world):
            lamp_pool(caustics, shape=shape)(world)
            camera = next(e for e, _ in world.query_one(Camera))
            world.get(camera, Transform).position = glm.vec3(0.0, -0.2, 0.0)
            world.add_component(camera, Fog(density=air, color=(0.0, 0.0, 0.0)))
            world.add_component(camera, settings)
            water = next(e for e, _ in world.query_one(Water))
            world.get(water, Water).fog_density = body
            world.get(water, Water).fog_color = (0.0, 0.0, 0.0)
        return b

    marched = {}
    for caustics in (1.0, 0.0):
        runner = scene(build(caustics), (96, 64))
        runner.frame()
        marched[caustics] = marched_light(runner)[..., 0]
        assert runner.engine.renderer.caustics.lamps == ((0,) if caustics else ())   # (caustics 0: none held)
    origin, way, (rows, columns) = march_rays(runner, (96, 64), 2)
    reach = np.minimum((-deep - origin[:, 1]) / way[:, 1], settings.distance)
    line = np.abs(origin[:, 2] + way[:, 2] * reach) < 0.03   # the texels whose rays stay near z = 0
    points = 300
    t = (np.arange(points) + 0.5) / points
    along = reach[line, None] * t[None, :]
    at = origin[line, None, :] + way[line, None, :] * along[..., None]
    lamp = np.array([0.0, LAMP_HEIGHT, 0.0])
    to_lamp = lamp - at
    dist = np.linalg.norm(to_lamp, axis=-1)
    l = to_lamp / dist[..., None]
    fade = np.clip(1.0 - (dist / lamp_range) ** 4, 0.0, 1.0)
    face = {"point": 1.0, "panel": np.maximum(l[..., 1], 0.0), "tube": np.sqrt(1.0 - l[..., 0] ** 2)}[shape]
    g = settings.anisotropy
    c = np.einsum("ij,ikj->ik", way[line], l)
    phase = (1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * c) ** 1.5)
    h = -at[..., 1]
    density = air + body
    through = np.exp(-body * h / l[..., 1])   # (the lamp's light down through the water over the point)
    weight = density * np.exp(-density * along) * fade * fade / (dist * dist + 1.0) * face * phase * through
    depths = np.linspace(0.02, deep, 20)
    grid_x = np.linspace(at[..., 0].min() - 0.05, at[..., 0].max() + 0.05, 801)

    def truth(shape: str) -> np.ndarray:
        table = traced_lamp_light(grid_x, LAMP_HEIGHT, depths, along_x=lamp_along(shape), shape=shape,
                                  crossings=crossings)   # [depth, x]
        gathered = table_at(table, depths, grid_x, h, at[..., 0])
        gathered = np.where(h < depths[0], 1.0, gathered)   # (at the surface: the flat water's light)
        return (weight * gathered).sum(1) / weight.sum(1)

    ratio = (marched[1.0] / marched[0.0]).ravel()[line]
    assert line.sum() > 30
    return ratio, truth(shape), truth("point")


def test_the_light_shafts_under_rippled_water_carry_a_lamps_caustics(scene):
    """``lamp_shafts`` of a point lamp: each march texel's light with caustics over its light
    without is the ground truth's."""
    ratio, truth, _ = lamp_shafts(scene)
    assert truth.max() > 1.2, truth.max()
    assert np.corrcoef(ratio, truth)[0, 1] > 0.99, np.corrcoef(ratio, truth)[0, 1]
    assert np.median(np.abs(ratio - truth)) < 0.01, np.median(np.abs(ratio - truth))


@pytest.mark.parametrize("shape", ["panel", "tube"])
def test_the_light_shafts_under_rippled_water_carry_a_panels_or_a_tubes_softer_net(scene, shape):
    """``lamp_shafts`` of a panel or a tube 0.4 m long across the waves (``spawn_lamp``): the
    columns the waves gather in the murky water are as soft as the lamp's size makes them,
    as on the floor (``test_a_panels_or_a_tubes_net_blurs_as_far_as_its_light_spreads``):
    each march texel's ratio is the ground truth's summed over 21 points along the lamp
    (within 1.2% at the median), which is softer than a point lamp's (its spread under nine
    tenths of the point's), and the ratios are more than half as near again to it as to the
    point's truth (a shaft gathered as a point lamp's is not)."""
    ratio, truth, point = lamp_shafts(scene, shape, crossings=5001)
    assert truth.std() < 0.9 * point.std() and truth.max() > 1.15, (truth.std(), point.std(), truth.max())
    assert np.corrcoef(ratio, truth)[0, 1] > 0.98, np.corrcoef(ratio, truth)[0, 1]
    off, off_point = np.median(np.abs(ratio - truth)), np.median(np.abs(ratio - point))
    assert off < 0.012 and off < 0.6 * off_point, (off, off_point)


def test_the_light_shafts_over_a_rippled_water_carry_the_light_it_throws_up(scene):
    """A sunlit pool that reflects light, seen through the foggy air over it with light shafts:
    what the water's image of the sun adds to each march texel (the march less the one with
    ``reflects_light`` off), with caustics over without, is the ground truth's: along the
    texel's ray, density x transmittance x the phase function where the line to the image
    crosses the pool (the image lights nothing else), times the reflected light a ray tracer
    gathers at the point's height, over the same sum without it."""
    from components import Fog, VolumetricFog
    from tests.test_volumetric_fog import march_rays, marched_light

    air = 0.05
    settings = VolumetricFog(steps=64, half_resolution=True)
    wall = 2.5   # (along the waves' lines, +z: each ray keeps to the lines it starts among)

    def build(caustics: float, reflects: bool):
        def b(world):
            eye = glm.vec3(0.0, 0.3, -2.5)
            world.spawn(Transform(position=eye, rotation=look_rotation(glm.vec3(0.0, 0.55, wall) - eye)),
                        Camera(fov_y=20.0), Fog(density=air, color=(0.0, 0.0, 0.0)), settings)
            world.spawn(Skybox(faces=[np.zeros((8, 8, 3), np.float32) for _ in range(6)]))
            world.spawn(DirectionalLight(direction=tuple(SUN), intensity=30.0))
            world.spawn(Transform(position=(0.0, 0.0, wall), rotation=glm.angleAxis(math.pi, glm.vec3(0, 1, 0))),
                        MeshRef(quad(20.0, 20.0)), Material(color=(0.0, 0.0, 0.0, 1.0), roughness=1.0))
            world.spawn(Transform(rotation=FLAT), MeshRef(quad(SIDE, SIDE)),
                        Material(color=(1.0, 1.0, 1.0, 0.0), normal_map=wave_map(PERIODS, slope=SLOPE),
                                 normal_scale=CALM),
                        Mirror(reflects_light=reflects),
                        Water(ior=IOR, tiling=TILING, speed=0.0, cross=0.0, caustics=caustics))
        return b

    marched = {}
    for caustics, reflects in ((1.0, True), (0.0, True), (1.0, False)):
        runner = scene(build(caustics, reflects), (96, 64))
        runner.frame()
        marched[caustics, reflects] = marched_light(runner)[..., 0]
    origin, way, (rows, columns) = march_rays(runner, (96, 64), 2)
    reach = np.minimum((wall - origin[:, 2]) / way[:, 2], settings.distance)
    line = way[:, 1] > 0.02   # the texels over the water
    points = 600
    t = (np.arange(points) + 0.5) / points
    along = reach[line, None] * t[None, :]
    at = origin[line, None, :] + way[line, None, :] * along[..., None]
    thrown = reflect(np.array([tuple(SUN)]), np.array([[0.0, 1.0, 0.0]]))[0]   # the image's light's way
    crossed = at - thrown[None, None, :] * (at[..., 1:2] / thrown[1])   # where its line meets the plane
    lit = (np.abs(crossed[..., 0]) < SIDE / 2.0) & (np.abs(crossed[..., 2]) < SIDE / 2.0)
    g = settings.anisotropy
    c = way[line] @ -thrown
    phase = (1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * c) ** 1.5)
    weight = air * np.exp(-air * along) * phase[:, None] * lit
    heights = np.linspace(0.02, at[..., 1].max() + 0.05, 24)
    grid_x = np.linspace(at[..., 0].min() - 0.05, at[..., 0].max() + 0.05, 801)
    table = np.stack([traced_reflected_light(grid_x, height) for height in heights])   # [height, x]
    gathered = table_at(table, heights, grid_x, at[..., 1], at[..., 0])
    kept = weight.sum(1) > 0.0
    truth = (weight * gathered).sum(1)[kept] / weight.sum(1)[kept]
    off = marched[1.0, False].ravel()[line][kept]
    ratio = (marched[1.0, True].ravel()[line][kept] - off) / (marched[0.0, True].ravel()[line][kept] - off)
    assert kept.sum() > 200 and truth.max() > 1.5, (kept.sum(), truth.max())
    assert np.corrcoef(ratio, truth)[0, 1] > 0.99, np.corrcoef(ratio, truth)[0, 1]
    assert np.median(np.abs(ratio - truth)) < 0.01, np.median(np.abs(ratio - truth))
