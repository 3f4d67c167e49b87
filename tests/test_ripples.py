"""Ripples on water (``Ripples``, ``Wake``, ``Splash``): the height field the ripple stage
steps on the GPU, read back and held to the wave equation's own facts (a ring spreads at the
ripples' speed, dies out by exp(-damping t), and a wall reflects it as a second drop beyond
the wall would), and the frames the composites draw from it (the reflection bent where the
rings are and only there; the plain frame back once they die away)."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    ComponentValueError,
    DirectionalLight,
    Material,
    MeshRef,
    Mirror,
    Ripples,
    Skybox,
    Splash,
    Transform,
    Wake,
    Water,
    look_rotation,
)
from engine.assets.level_file import LevelError, load_level, save_level
from engine.assets.mesh import box, quad
from engine.core.errors import GLLimitWarning, WaterLimitWarning
from engine.core.world import World
from engine.render.ripples import (
    MAX_RIPPLE_TEXELS,
    MAX_RIPPLE_WATERS,
    RIPPLE_CAUSTIC_SAMPLERS,
    RIPPLES_BLOCK_BYTES,
    RippleAtlas,
)
from shell.overlay_text import overlay_lines
from tests.support import pixel_rays, small_probes, srgb_to_linear

FLAT = glm.angleAxis(-math.pi / 2, glm.vec3(1, 0, 0))
DT = 1.0 / 60.0


def pond(ripples: Ripples | None, size=(4.0, 4.0), centre=(0.0, 0.0, 0.0), splashes=(), wall: bool = False,
         things=(), eye=(0.0, 0.8, 3.0), target=(0.0, 0.3, -2.0)):
    """A still pond (a quad ``size`` metres about ``centre``, y up) with ``ripples``, a
    ``Splash`` at each of ``splashes`` (radius, depth, point), ``things`` (components of an
    entity each); ``wall``: a checkered wall behind it for the water to reflect, under a sun,
    seen from ``eye`` (low over the water) towards ``target`` (from an eye under the water,
    the wall reaches a metre under the surface).  Returns the build and a dict it fills with the water's entity."""
    held = {}

    def build(world):
        world.spawn(Transform(position=eye, rotation=look_rotation(glm.vec3(target) - glm.vec3(eye))),
                    Camera(fov_y=55.0))
        if wall:
            world.spawn(Skybox(faces=[np.full((8, 8, 3), 0.3, np.float32) for _ in range(6)]))
            world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.4), intensity=1.5))
            for i in range(8):
                for j in range(-2 if eye[1] < 0.0 else 0, 4):   # (seen from below: under the surface too)
                    world.spawn(Transform(position=(-2.0 + i * 0.5 + 0.25, 0.25 + j * 0.5, -2.0)),
                                MeshRef(quad(0.5, 0.5)),
                                Material(color=(0.9, 0.2, 0.1, 1) if (i + j) % 2 else (0.1, 0.3, 0.9, 1),
                                         roughness=1.0))
        parts = [Transform(position=centre, rotation=FLAT), MeshRef(quad(*size)),
                 Material(color=(0.05, 0.2, 0.25, 0.3), roughness=0.2), Mirror(), Water()]
        held["water"] = world.spawn(*parts, *([ripples] if ripples is not None else []))
        for radius, depth, point in splashes:
            world.spawn(Transform(position=point), Splash(radius=radius, depth=depth))
        held["things"] = [world.spawn(*components) for components in things]
    return build, held


def run(scene, build, frames: int, size=(32, 24), antialias: str | None = None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # (a still water: no waves, said)
        runner = scene(build, size)
        if antialias is not None:
            runner.engine.renderer.antialias = antialias
        rgb = None
        for _ in range(frames):
            rgb = runner.frame(DT)
    return runner, rgb


def heights(runner, held) -> np.ndarray:
    return runner.engine.renderer.ripples.heights(held["water"])


def field_normals(runner, held, strength: float = 1.0) -> np.ndarray:
    """The normal of a flat water's surface (y up) at each texel of its field read back: up
    less the height's world gradient (central differences, each texel axis taken to the world
    by the atlas's texel rows) times ``strength`` (``Ripples.strength``: the slopes drawn),
    [row, column, 3]."""
    atlas = runner.engine.renderer.ripples
    tile, water = atlas.waters[held["water"]]
    u_row, v_row = water.texel_rows(tile)
    along_v, along_u = np.gradient(heights(runner, held).astype(np.float64))   # (metres a texel)
    normal = np.array([0.0, 1.0, 0.0]) - strength * (along_u[..., None] * u_row[:3] + along_v[..., None] * v_row[:3])
    return normal / np.linalg.norm(normal, axis=-1, keepdims=True)


def texel_centres(runner, held) -> tuple[np.ndarray, float]:
    """Each texel centre of a water at y = 0 as world (x, z), [row, column, 2] (the atlas's
    rows taken back to the world), and a texel's area in square metres."""
    atlas = runner.engine.renderer.ripples
    water = held["water"]
    corner = atlas.to_texels(water, np.zeros((1, 3)))[0]
    dx = atlas.to_texels(water, np.array([[1.0, 0.0, 0.0]]))[0] - corner
    dz = atlas.to_texels(water, np.array([[0.0, 0.0, 1.0]]))[0] - corner
    to_world = np.linalg.inv(np.array([[dx[0], dz[0]], [dx[1], dz[1]]]))
    rows, columns = np.mgrid[0:atlas.waters[water][1].texels[1], 0:atlas.waters[water][1].texels[0]] + 0.5
    return np.stack([columns - corner[0], rows - corner[1]], axis=-1) @ to_world.T, abs(np.linalg.det(to_world))


def traced_gathering(xz: np.ndarray, normal: np.ndarray, sun, depth: float, area: float, reflected: bool = False
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Where the sun's rays (``sun``, the light's way) crossing the surface at texel centres
    ``xz`` with ``normal``s land ``depth`` under it (Snell's law for water's index; with
    ``reflected``, thrown back up off it, ``depth`` over it), and the light there over the
    flat water's: 1 / |det J| of the landings on the texel grid (a texel of ``area`` square
    metres)."""
    from tests.test_caustics import IOR, reflect, refract

    light = np.broadcast_to(np.array(tuple(sun), np.float64), normal.shape)
    rays = reflect(light, normal) if reflected else refract(light, normal, 1.0 / IOR)
    landed = xz + rays[..., [0, 2]] * (depth / np.abs(rays[..., 1:2]))
    d_rows, d_columns = np.gradient(landed, axis=0), np.gradient(landed, axis=1)
    det = (d_rows[..., 0] * d_columns[..., 1] - d_rows[..., 1] * d_columns[..., 0]) / area
    return landed, 1.0 / np.abs(det)


def splashed_pool(on: bool, held: dict | None = None, **pool_values):
    """``tests.test_caustics``'s sunlit pool gathering the sun (its waves flattened:
    ``normal_scale`` 0, so rings alone bend the light), with Ripples (``on``) and a splash in
    its middle; ``held`` gets the water's entity."""
    from tests.test_caustics import pool

    build = pool(1.0, scale=0.0, **pool_values)

    def with_ripples(world):
        build(world)
        (entity, _), = world.query_one(Water)
        if held is not None:
            held["water"] = entity
        if on:
            world.add_component(entity, Ripples(speed=0.4, damping=0.0, cell=0.02))
        world.spawn(Transform(position=(0.0, 0.0, 0.0)), Splash(radius=0.12, depth=0.006))
    return with_ripples


def test_a_drop_spreads_as_a_ring_at_the_ripples_speed_and_dies_out_by_the_damping(scene):
    """A splash in the middle of a pond: the ring's crest stands ``speed`` x t from where it
    fell, at two times (the ring's radius grows with time as the wave equation's front does),
    and a pond with ``damping`` holds the undamped pond's field times exp(-damping t)."""
    cell, speed = 0.02, 0.5
    drop = [(0.1, 0.01, (0.0, 0.0, 0.0))]
    still_build, still = pond(Ripples(speed=speed, damping=0.0, cell=cell), splashes=drop)
    damped_build, damped = pond(Ripples(speed=speed, damping=0.8, cell=cell), splashes=drop)
    runners = [scene(still_build, (32, 24)), scene(damped_build, (32, 24))]
    texels = int(4.0 / cell)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for runner in runners:
            runner.frame(DT)
    centre = runners[0].engine.renderer.ripples.to_texels(still["water"], (0.0, 0.0, 0.0))[0]
    yy, xx = np.mgrid[0:texels, 0:texels] + 0.5
    radius = np.hypot(xx - centre[0], yy - centre[1]) * cell
    rings = np.round(radius / cell).astype(int)
    seen = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for frame in range(2, 61):
            for runner in runners:
                runner.frame(DT)
            if frame in (30, 60):
                t = frame * DT
                field, weaker = heights(runners[0], still), heights(runners[1], damped)
                profile = np.bincount(rings.ravel(), np.abs(field).ravel()) / np.bincount(rings.ravel())
                crest = (np.argmax(profile[4:]) + 4) * cell   # (past the middle, where the drop fell)
                seen.append((t, crest))
                assert abs(crest - speed * t) < 0.06, (t, crest, speed * t)
                strong = np.abs(field) > 0.2 * np.abs(field).max()
                kept = float((weaker[strong] * field[strong]).sum() / (field[strong] ** 2).sum())
                assert kept == pytest.approx(math.exp(-0.8 * t), rel=0.04), (t, kept)
    assert seen[1][1] > 1.6 * seen[0][1]
    assert runners[0].stats.ripple_steps == 1   # (0.5 m/s over 2 cm texels: one step a frame keeps it stable)


def test_a_wall_reflects_the_rings_as_a_drop_beyond_it_would(scene):
    """A drop 0.3 m from a pond's edge, against a pond twice as long with a second drop as far
    beyond where that edge was: by symmetry the wave equation's field with a reflecting wall
    is the two drops' field on the wall's side, texel for texel, where the rings have met the
    wall and come back; without the reflected drop it is not."""
    cell, d = 0.04, 0.3
    near = pond(Ripples(speed=0.5, damping=0.0, cell=cell), splashes=[(0.12, 0.01, (-2.0 + d, 0.0, 0.0))])
    long_pond = dict(size=(8.0, 4.0), centre=(-2.0, 0.0, 0.0))
    both = pond(Ripples(speed=0.5, damping=0.0, cell=cell),
                splashes=[(0.12, 0.01, (-2.0 + d, 0.0, 0.0)), (0.12, 0.01, (-2.0 - d, 0.0, 0.0))], **long_pond)
    alone = pond(Ripples(speed=0.5, damping=0.0, cell=cell), splashes=[(0.12, 0.01, (-2.0 + d, 0.0, 0.0))],
                 **long_pond)
    runners = [(scene(build, (32, 24)), held) for build, held in (near, both, alone)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for _ in range(75):
            for runner, _ in runners:
                runner.frame(DT)
    fields = []
    for runner, held in runners:
        atlas = runner.engine.renderer.ripples
        # Each field over the near pond's square, [-2, 2] along x: its texels' columns there.
        xs = -2.0 + cell * (np.arange(int(4.0 / cell)) + 0.5)
        ts = atlas.to_texels(held["water"], np.stack([xs, 0 * xs, 0 * xs], axis=1))
        axis = int(np.argmax(np.abs(ts[-1] - ts[0])))   # (the texel axis x runs along)
        field = heights(runner, held)
        field = field if axis == 0 else field.T   # (x along columns)
        columns = np.floor(ts[:, axis]).astype(int)
        fields.append(field[:, columns])
    walled, mirrored, free = fields
    scale = np.abs(walled).max()
    assert np.abs(walled - mirrored).max() < 1e-4 * scale
    assert np.abs(walled - free).max() > 0.2 * scale


def test_a_wading_thing_leaves_rings_and_a_still_one_none(scene):
    """A box with a ``Wake`` moving through the pond makes rings along its way, growing as it
    goes; the same box standing still makes none (no step, a calm field); a moving box with no
    Wake makes none."""
    def moving(wake: bool):
        parts = (Transform(position=(-1.0, 0.0, 0.3)), MeshRef(box((0.2, 0.3, 0.2))),
                 Material(color=(0.9, 0.9, 0.2, 1.0)), *([Wake(strength=0.5)] if wake else []))
        return pond(Ripples(speed=0.35, damping=0.5, cell=0.03), things=[parts])

    results = {}
    for name, wake, speed in (("wading", True, 1.0), ("standing", True, 0.0), ("no wake", False, 1.0)):
        build, held = moving(wake)
        runner = scene(build, (32, 24))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for _ in range(40):
                thing = runner.world.get(held["things"][0], Transform)
                thing.position = thing.position + glm.vec3(speed * DT, 0.0, 0.0)
                runner.frame(DT)
        atlas = runner.engine.renderer.ripples
        results[name] = (heights(runner, held), runner.stats.ripple_steps, set(atlas.awake), runner, held)
    field, steps, awake, runner, held = results["wading"]
    assert steps >= 1 and awake
    atlas = runner.engine.renderer.ripples
    # Along its way (x from -1 to -0.33 at z = 0.3) the water is stirred; far from it, calm.
    way = atlas.to_texels(held["water"], [(-0.7, 0.0, 0.3)])[0].astype(int)
    far = atlas.to_texels(held["water"], [(1.5, 0.0, -1.5)])[0].astype(int)
    assert np.abs(field[way[1] - 3:way[1] + 4, way[0] - 3:way[0] + 4]).max() > 1e-3
    assert np.abs(field[far[1] - 3:far[1] + 4, far[0] - 3:far[0] + 4]).max() < 1e-6
    for name in ("standing", "no wake"):
        field, steps, awake, *_ = results[name]
        assert steps == 0 and not awake, name
        assert np.abs(field).max() == 0.0, name


def test_a_thing_turning_where_it_stands_stirs_the_water_as_far_as_its_corners_went(scene):
    """A box with a ``Wake`` that turns about its upright axis without moving stirs the water
    by the farthest any corner of its box went: the field is the one a ``Splash`` makes at
    its place, of the Wake's radius (half its turned box's side) and its strength times the
    corners' chord, 2 r sin(turn / 2) at r = the corners' distance from the axis."""
    place, turn = (0.3, 0.0, -0.2), math.radians(20.0)
    half_side, strength = 0.1, 0.5

    def field(turning: bool) -> np.ndarray:
        things = [(Transform(position=place), MeshRef(box((2 * half_side, 0.3, 2 * half_side))),
                   Material(color=(0.9, 0.9, 0.2, 1.0)), Wake(strength=strength))] if turning else []
        build, held = pond(Ripples(speed=0.35, damping=0.5, cell=0.03), things=things)
        runner, _ = run(scene, build, 1)   # (its corners' first place: nothing stirred yet)
        if turning:
            runner.world.get(held["things"][0], Transform).rotation = glm.angleAxis(turn, glm.vec3(0.0, 1.0, 0.0))
        else:
            chord = 2.0 * math.hypot(half_side, half_side) * math.sin(turn / 2.0)
            radius = half_side * (math.cos(turn) + math.sin(turn))
            runner.world.spawn(Transform(position=place), Splash(radius=radius, depth=strength * chord))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for _ in range(5):
                runner.frame(DT)
        assert runner.stats.ripple_steps >= 1
        return heights(runner, held).astype(np.float64)

    turned, splashed = field(True), field(False)
    assert np.abs(splashed).max() > 1e-4
    assert np.abs(turned - splashed).max() < 1e-3 * np.abs(splashed).max()


@pytest.mark.parametrize("side", ["above", "below"])
def test_ripples_bend_the_reflection_where_the_rings_are_and_nowhere_else(scene, side):
    """A pond reflecting a checkered wall, a splash in it, seen from above and from under the
    water: against the same pond with no Ripples, the frame changes where the rings tilt the
    surface (each pixel's point on the water found along its ray, the field's slope there read
    back) and is the same (within a filter's rounding) wherever the field is flat.  Frames a
    moment apart differ while the rings spread, the camera standing still (a kept frame would
    not)."""
    drop = [(0.1, 0.03, (0.3, 0.0, -0.6))]
    size = (240, 180)
    view = {"above": {}, "below": {"eye": (0.0, -0.5, 2.0), "target": (0.0, 0.1, -1.5)}}[side]
    rippled_build, held = pond(Ripples(speed=0.5, damping=0.0, cell=0.02), splashes=drop, wall=True, **view)
    plain_build, _ = pond(None, splashes=drop, wall=True, **view)
    rippled, frame = run(scene, rippled_build, 24, size)
    _, plain = run(scene, plain_build, 24, size)
    field = heights(rippled, held)
    slope = np.hypot(*np.gradient(field.astype(np.float64), 0.02))
    # The field's slope under each pixel (a pixel's ray to the plane y = 0), the largest near it.
    eye, directions = pixel_rays(rippled.engine.main_view, size)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -eye[1] / directions[..., 1]
    on = (t > 0) & np.isfinite(t)
    at = eye + directions * np.where(on, t, 0.0)[..., None]
    on &= (np.abs(at[..., 0]) < 1.9) & (np.abs(at[..., 2]) < 1.9)
    texel = rippled.engine.renderer.ripples.to_texels(held["water"], at.reshape(-1, 3)).reshape(*size[::-1], 2)
    ix = np.clip(texel[..., 0].astype(int), 0, field.shape[1] - 1)
    iy = np.clip(texel[..., 1].astype(int), 0, field.shape[0] - 1)
    near = slope.copy()
    for axis in (0, 1):
        for shift in (-2, -1, 1, 2):
            near = np.maximum(near, np.roll(slope, shift, axis=axis))
    under = near[iy, ix]
    changed = np.abs(frame.astype(int) - plain.astype(int)).max(axis=-1)
    flat = on & (under < 1e-5)
    tilted = on & (under > 0.02)
    assert flat.sum() > 10000 and tilted.sum() > 120, (flat.sum(), tilted.sum())
    assert changed[flat].max() <= 2
    assert (changed[tilted] > 2).mean() > 0.3   # (where what the tilt moves to looks the same, no change)
    assert (changed > 2)[on].sum() > 80
    # Still camera, spreading rings: the frames are drawn again (not kept: StillTree), and move.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for _ in range(6):
            after = rippled.frame(DT)
    assert (np.abs(after.astype(int) - frame.astype(int)).max(axis=-1) > 2).sum() > 30


def test_a_second_water_shows_its_own_rings_where_its_field_slopes(scene):
    """Two rippling ponds side by side before the checkered wall, a splash in the second (held
    in the atlas's second tile, the Ripples block's second row): against the same ponds with
    no Ripples, the frame changes on the second water where its own field read back slopes
    (each pixel's point on it found along its ray) and nowhere on the first."""
    size, cell = (128, 96), 0.02
    other = (Transform(position=(1.0, 0.0, -0.6), rotation=FLAT), MeshRef(quad(1.8, 3.0)),
             Material(color=(0.05, 0.2, 0.25, 0.3), roughness=0.2), Mirror(), Water())
    drop = [(0.15, 0.03, (1.1, 0.0, -0.7))]

    def ponds(rippling: bool):
        ripples = (lambda: Ripples(speed=0.5, damping=0.0, cell=cell)) if rippling else (lambda: None)
        build, held = pond(ripples(), size=(1.8, 3.0), centre=(-1.0, 0.0, -0.6), splashes=drop, wall=True,
                           things=[other + ((ripples(),) if rippling else ())], eye=(0.0, 1.4, 2.5),
                           target=(0.0, 0.0, -1.0))
        return build, held
    rippled_build, held = ponds(True)
    plain_build, _ = ponds(False)
    rippled, frame = run(scene, rippled_build, 24, size)
    _, plain = run(scene, plain_build, 24, size)
    atlas = rippled.engine.renderer.ripples
    second = {"water": held["things"][0]}
    assert atlas.tile_of(held["water"]) == 0 and atlas.tile_of(second["water"]) == 1
    assert np.abs(heights(rippled, held)).max() == 0.0   # (the first's field is flat)
    field = heights(rippled, second)
    slope = np.hypot(*np.gradient(field.astype(np.float64), cell))
    near = slope.copy()
    for axis in (0, 1):
        for shift in (-2, -1, 1, 2):
            near = np.maximum(near, np.roll(slope, shift, axis=axis))
    eye, directions = pixel_rays(rippled.engine.main_view, size)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -eye[1] / directions[..., 1]
    ahead = (t > 0) & np.isfinite(t)
    at = eye + directions * np.where(ahead, t, 0.0)[..., None]
    on_first = ahead & (np.abs(at[..., 0] + 1.0) < 0.85) & (np.abs(at[..., 2] + 0.6) < 1.45)
    on_second = ahead & (np.abs(at[..., 0] - 1.0) < 0.85) & (np.abs(at[..., 2] + 0.6) < 1.45)
    texel = atlas.to_texels(second["water"], at.reshape(-1, 3)).reshape(*size[::-1], 2)
    ix = np.clip(texel[..., 0].astype(int), 0, field.shape[1] - 1)
    iy = np.clip(texel[..., 1].astype(int), 0, field.shape[0] - 1)
    under = near[iy, ix]
    changed = np.abs(frame.astype(int) - plain.astype(int)).max(axis=-1)
    flat, tilted = on_second & (under < 1e-5), on_second & (under > 0.02)
    assert on_first.sum() > 1000 and flat.sum() > 1000 and tilted.sum() > 80, (on_first.sum(), flat.sum(),
                                                                              tilted.sum())
    assert changed[on_first].max() <= 2 and changed[flat].max() <= 2
    assert (changed[tilted] > 2).mean() > 0.4


def test_the_rings_fall_calm_and_then_cost_nothing(scene):
    """With damping, once a splash's rings have died away (their height under 0.01 mm) the
    water is no longer stepped, the composites' plain builds come back, and the frame is the
    frame with no Ripples at all, bit for bit."""
    drop = [(0.08, 0.001, (0.3, 0.0, -0.6))]
    rippled_build, held = pond(Ripples(speed=0.5, damping=4.0, cell=0.02), splashes=drop, wall=True)
    plain_build, _ = pond(None, wall=True)
    rippled, _ = run(scene, rippled_build, 2, (64, 48))
    atlas = rippled.engine.renderer.ripples
    assert rippled.stats.ripple_steps == 1 and atlas.defines
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        frames = 0
        while atlas.awake and frames < 200:
            rippled.frame(DT)
            frames += 1
    assert not atlas.awake and frames > 40   # (0.001 x exp(-4 t) < 1e-5: t > 1.15 s)
    assert rippled.stats.ripple_steps == 0 and atlas.defines == ()
    assert np.abs(heights(rippled, held)).max() == 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        last = rippled.frame(DT)
    _, plain = run(scene, plain_build, 3, (64, 48))
    np.testing.assert_array_equal(last, plain)


def test_rain_falls_at_its_rate_over_the_waters_area(scene):
    """``rain`` drops a square metre a second over the pond's 16 square metres: a second of
    frames takes in rain x 16 drops (the fraction carried over), each ringing the field."""
    build, held = pond(Ripples(rain=5.0, damping=0.0))
    runner = scene(build, (32, 24))
    drops = 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for _ in range(60):
            runner.frame(DT)
            drops += runner.stats.ripple_drops
    assert abs(drops - 5.0 * 16.0) <= 1
    field = heights(runner, held)
    assert (np.abs(field) > 1e-5).mean() > 0.3   # (rings all over the pond)


def test_ripple_values_and_limits_are_checked_and_said(scene):
    """Bad values are refused naming the field; Ripples without a Water are refused; past
    ``MAX_RIPPLE_WATERS`` waters the rest stay still, counted and said; a field finer than
    ``MAX_RIPPLE_TEXELS`` a side is made coarser and said; the block's size is the GLSL's."""
    for field, value in (("speed", 0.0), ("speed", float("nan")), ("damping", -1.0), ("cell", 0.0),
                         ("rain", -1.0), ("drop_depth", 2.0)):
        with pytest.raises(ComponentValueError, match=f"Ripples.{field}"):
            Ripples(**{field: value})
    with pytest.raises(ComponentValueError, match="Wake.strength"):
        Wake(strength=-1.0)
    with pytest.raises(ComponentValueError, match="Splash.radius"):
        Splash(radius=0.0)

    def no_water(world):
        world.spawn(Transform(), Camera())
        world.spawn(Transform(rotation=FLAT), MeshRef(quad(1.0, 1.0)), Mirror(), Ripples())
    with pytest.raises(ComponentValueError, match="Ripples need a Water"):
        scene(no_water, (32, 24)).frame(DT)

    def many(world):
        world.spawn(Transform(position=(0, 3, 3), rotation=look_rotation(glm.vec3(0, -3, -3))), Camera())
        for i in range(MAX_RIPPLE_WATERS + 2):
            world.spawn(Transform(position=(i * 1.5, 0.0, 0.0), rotation=FLAT), MeshRef(quad(1.0, 1.0)),
                        Material(color=(0.1, 0.2, 0.3, 0.5)), Mirror(), Water(),
                        Ripples(cell=0.001 if i == 0 else 0.03))
    runner = scene(many, (32, 24))
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        runner.frame(DT)
    messages = [str(w.message) for w in said if issubclass(w.category, WaterLimitWarning)]
    assert any("6 waters have Ripples" in m and "so 2 stay still" in m for m in messages), messages
    assert any(f"{MAX_RIPPLE_TEXELS} texels a side" in m for m in messages), messages
    assert runner.stats.ripple_waters_cut == 2
    assert any("rippling waters 2" in line for line in overlay_lines(runner.engine, [0.016]))   # (the overlay says it)
    atlas = runner.engine.renderer.ripples
    assert len(atlas.waters) == MAX_RIPPLE_WATERS
    assert max(max(water.texels) for _, water in atlas.waters.values()) == MAX_RIPPLE_TEXELS
    # Rings too fast for their cell: the most steps a frame, each stable (the field stays
    # bounded), said once.
    def fast(world):
        world.spawn(Transform(position=(0, 3, 3), rotation=look_rotation(glm.vec3(0, -3, -3))), Camera())
        held["fast"] = world.spawn(Transform(rotation=FLAT), MeshRef(quad(0.5, 0.5)), Material(), Mirror(), Water(),
                                   Ripples(speed=20.0, cell=0.002, damping=0.0))
        world.spawn(Transform(), Splash(radius=0.02, depth=0.01))
    held = {}
    quick = scene(fast, (32, 24))
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        for _ in range(30):
            quick.frame(DT)
    assert sum("steps this frame would keep the fastest rings" in str(w.message) for w in said) == 1
    assert quick.stats.ripple_steps == 16
    field = heights(quick, held | {"water": held["fast"]})
    assert np.isfinite(field).all() and np.abs(field).max() <= 0.01 and np.abs(field).max() > 1e-4
    # A Splash with no Transform has no place: said and taken off.
    lost = runner.world.spawn(Splash())
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        runner.frame(DT)
    assert sum("no Transform to say where it lands" in str(w.message) for w in said) == 1
    assert not runner.world.has(lost, Splash)
    # A Wake with no Transform has no place: said, once.
    runner.world.spawn(Wake(radius=0.1))
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        runner.frame(DT)
        runner.frame(DT)
    assert sum("Wake on entity" in str(w.message) and "no Transform" in str(w.message) for w in said) == 1
    # A Wake with no mesh and no radius has no size: said, once.
    runner.world.spawn(Transform(position=(0.0, 0.0, 0.0)), Wake())
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        runner.frame(DT)
        runner.frame(DT)
    assert sum("no mesh to take a size from" in str(w.message) for w in said) == 1
    # The block as ripples.glsl lays it out (std140) is what the atlas writes.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        runner.world.spawn(Transform(position=(1.5, 0.0, 0.0)), Splash())
        for _ in range(30):
            runner.frame(DT)
    # Each water's tile is its own: the splash rings the second water's field alone, out to its
    # edges, and the others' stay flat.
    stirred = {entity: np.abs(atlas.heights(entity)).max() for entity in atlas.waters}
    splashed = max(stirred, key=stirred.get)
    water = atlas.waters[splashed][1]
    assert water.origin[0] + (water.edge_u[0] + water.edge_v[0]) / 2 == pytest.approx(1.5)   # (the one at x = 1.5)
    assert stirred[splashed] > 1e-4 and all(v == 0.0 for e, v in stirred.items() if e != splashed), stirred
    programs = [draw.program for draws in runner.engine.reflection_system.tree.passes._draws.values()
                for draw in draws[0].values() if "Ripples" in draw.program]
    assert programs and all(program["Ripples"].size == RIPPLES_BLOCK_BYTES for program in programs)


def test_ripples_release_their_fields_when_they_go(scene):
    """Taking the Ripples off the last rippling water releases the atlas's textures and block;
    a Splash is taken off its entity the frame it lands (on water or not)."""
    build, held = pond(Ripples(), splashes=[(0.05, 0.01, (0.0, 0.0, 0.0)), (0.05, 0.01, (9.0, 0.0, 0.0))])
    runner, _ = run(scene, build, 2)
    atlas = runner.engine.renderer.ripples
    assert atlas._images and atlas.awake
    world = runner.world
    assert not [entity for entity, _ in world.query_one(Splash)]
    world.remove_component(held["water"], Ripples)
    stone = world.spawn(Transform(), Splash())   # (no rippling water left: it lands nowhere)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        runner.frame(DT)
    assert atlas._images == [] and atlas._ubo is None and atlas.waters == {} and atlas.defines == ()
    assert not world.has(stone, Splash)


def test_level_files_carry_ripples_and_wakes(tmp_path):
    """A level file's Ripples and Wake are loaded, checked (Ripples with no Water refused,
    naming the line) and saved again; a Splash in a file is loaded too (dropped on the first
    frame)."""
    level = tmp_path / "pond.toml"
    level.write_text("""
[level]
name = "pond"

[[entity]]
name = "pond"
[entity.Transform]
[entity.MeshRef]
mesh = { quad = [2.0, 2.0] }
[entity.Mirror]
[entity.Water]
[entity.Ripples]
speed = 0.4
damping = 1.5
cell = 0.05
rain = 8.0

[[entity]]
name = "boat"
[entity.Transform]
position = [0.0, 0.0, 0.5]
[entity.Wake]
radius = 0.2
strength = 0.8

[[entity]]
name = "stone"
[entity.Transform]
[entity.Splash]
depth = 0.02
""")
    world = World("pond")
    names = load_level(level).spawn(world)
    ripples = world.get(names["pond"], Ripples)
    assert (ripples.speed, ripples.damping, ripples.cell, ripples.rain) == (0.4, 1.5, 0.05, 8.0)
    assert (world.get(names["boat"], Wake).radius, world.get(names["boat"], Wake).strength) == (0.2, 0.8)
    assert world.get(names["stone"], Splash).depth == 0.02
    saved = save_level(world, tmp_path / "again.toml", names, name="pond")
    again = World("again")
    names_again = load_level(saved).spawn(again)
    kept = again.get(names_again["pond"], Ripples)
    assert (kept.speed, kept.damping, kept.cell, kept.rain) == (0.4, 1.5, 0.05, 8.0)
    assert again.get(names_again["boat"], Wake).strength == 0.8
    text = level.read_text()
    for good, bad, message in (("rain = 8.0", "rain = -8.0", r"Ripples.rain must be >= 0.0"),
                               ("[entity.Water]\n", "", "Ripples need a Water")):
        level.write_text(text.replace(good, bad))
        with pytest.raises(LevelError, match=message):
            load_level(level)


def test_a_moving_water_carries_its_rings_along(scene):
    """A water that moves (a pond on a moving platform) keeps its rings in its own frame: the
    field after the move is the field a still pond has one step later, and the composites
    read it where the water now is."""
    drop = [(0.1, 0.01, (0.5, 0.0, 0.3))]
    moving_build, moving = pond(Ripples(damping=0.0), splashes=drop)
    still_build, still = pond(Ripples(damping=0.0), splashes=drop)
    runners = [(scene(moving_build, (32, 24)), moving), (scene(still_build, (32, 24)), still)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for _ in range(10):
            for runner, _ in runners:
                runner.frame(DT)
        runners[0][0].world.get(moving["water"], Transform).position = glm.vec3(1.0, 0.0, 0.0)
        for runner, _ in runners:
            runner.frame(DT)
    carried, kept = (heights(runner, held) for runner, held in runners)
    assert np.abs(kept).max() > 1e-4
    np.testing.assert_array_equal(carried, kept)
    atlas = runners[0][0].engine.renderer.ripples
    _, water = atlas.waters[moving["water"]]
    assert water.origin[0] == pytest.approx(runners[1][0].engine.renderer.ripples.waters[still["water"]][1].origin[0]
                                            + 1.0)


def test_the_rings_tilt_the_surface_the_way_their_slopes_go_as_far_as_their_strength_says(scene):
    """Over a dark floor under a bright, even sky a pixel of the water is as bright as the
    share Fresnel reflects at the angle between its eye ray and the surface's normal, so the
    rings' brightening and darkening follow where each ring's side faces: the frame's change
    (against the same pond with no Ripples) against Schlick's weight at the normal the field
    read back gives (up less the height's gradient: the surface of the height field; taken
    bilinearly between texel centres, as the filtered field is read) over the flat one's,
    times the sky less what the calm water shows under its reflection, pixel by pixel, in
    size as well as in sign.  A tilt the wrong way would turn the correlation over.
    ``Ripples.strength`` scales the slopes drawn: the same field drawn at 2 tilts the surface
    as twice its slopes do, at 0 not at all (the calm water's frame)."""
    def dark_floor(ripples):
        build, held = pond(ripples, splashes=[(0.1, 0.03, (0.0, 0.0, 0.0))], eye=(0.0, 1.2, 2.0),
                           target=(0.0, 0.0, 0.0),
                           things=[(Transform(position=(0.0, -1.0, 0.0), rotation=FLAT), MeshRef(quad(8.0, 8.0)),
                                    Material(color=(0.0, 0.0, 0.0, 1.0), roughness=1.0))])

        def lit(world):
            build(world)
            world.spawn(Skybox(faces=[np.full((8, 8, 3), 0.8, np.float32) for _ in range(6)]))
        return lit, held

    size = (160, 120)
    rippled_build, held = dark_floor(Ripples(speed=0.5, damping=0.0, cell=0.02))
    plain_build, _ = dark_floor(None)
    rippled, frame = run(scene, rippled_build, 20, size, antialias="off")
    _, plain = run(scene, plain_build, 20, size, antialias="off")
    atlas = rippled.engine.renderer.ripples
    eye, directions = pixel_rays(rippled.engine.main_view, size)
    t = -eye[1] / directions[..., 1]
    at = eye + directions * t[..., None]
    on = (t > 0) & (np.abs(at[..., 0]) < 1.9) & (np.abs(at[..., 2]) < 1.9)
    texel = atlas.to_texels(held["water"], at.reshape(-1, 3)).reshape(*size[::-1], 2)
    sky = 0.8

    def schlick(n):
        cosine = np.clip(np.sum(n * -directions, axis=-1), 0.0, 1.0)
        return 0.02 + 0.98 * (1.0 - cosine) ** 5

    flat = schlick(np.array([0.0, 1.0, 0.0]))
    calm = srgb_to_linear(plain).mean(axis=-1)
    below = (calm - flat * sky) / (1.0 - flat)   # (what the calm water shows under its reflection)

    def held_to(strength: float, frame: np.ndarray) -> tuple[float, float]:
        """The frame's change against the prediction at the field's slopes times
        ``strength``: their correlation, and the least-squares gain of the one on the other."""
        normals = field_normals(rippled, held, strength)
        x = np.clip(texel[..., 0] - 0.5, 1.0, normals.shape[1] - 3.0)   # (texel centres at + 0.5)
        y = np.clip(texel[..., 1] - 0.5, 1.0, normals.shape[0] - 3.0)
        x0, y0 = x.astype(int), y.astype(int)
        ax, ay = (x - x0)[..., None], (y - y0)[..., None]
        normal = (normals[y0, x0] * (1 - ax) * (1 - ay) + normals[y0, x0 + 1] * ax * (1 - ay)
                  + normals[y0 + 1, x0] * (1 - ax) * ay + normals[y0 + 1, x0 + 1] * ax * ay)
        normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
        predicted = (schlick(normal) - flat) * (sky - below)
        seen = srgb_to_linear(frame).mean(axis=-1) - calm
        ringed = on & (np.abs(predicted) > 0.002)
        assert ringed.sum() > 150, ringed.sum()
        p, s = predicted[ringed], seen[ringed]
        return np.corrcoef(p, s)[0, 1], float(p @ s / (p @ p))

    field = heights(rippled, held).copy()
    (_, ripples), = rippled.world.query_one(Ripples)
    for strength in (1.0, 2.0, 0.0):
        if strength != 1.0:   # (the same field drawn again: no time passes)
            ripples.strength = strength
            frame = rippled.frame(0.0)
            np.testing.assert_array_equal(heights(rippled, held), field)
        if strength > 0.0:
            correlation, gain = held_to(strength, frame)
            assert correlation > 0.97 and abs(gain - 1.0) < 0.05, (strength, correlation, gain)
        else:
            np.testing.assert_allclose(srgb_to_linear(frame), srgb_to_linear(plain), atol=1e-6)


def test_the_rings_gather_the_suns_light_under_the_water_where_a_ray_tracer_does(scene):
    """A pool whose caustics gather the sun (its waves flattened: ``normal_scale`` 0, so the
    rings alone bend the light) and a splash in it: each floor pixel's light over the same
    pool's with no Ripples is, where the rings bend the light, the traced share where the
    rays crossing the surface there land (Snell's law at the normal the field read back
    gives, the light through each texel of surface over the area its rays land on: 1 / |det
    J| of the landings on the texel grid)."""
    from tests.test_caustics import DEPTH, SUN, render

    size = (128, 128)
    held = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        runner, _ = render(scene, splashed_pool(True, held), size)
        for _ in range(28):
            frame = runner.frame(DT)
        _, flat = render(scene, splashed_pool(False), size)
    lit = srgb_to_linear(frame)
    assert runner.engine.renderer.ripples.caustic_defines
    xz, area = texel_centres(runner, held)
    landed, traced = traced_gathering(xz, field_normals(runner, held), SUN, DEPTH, area)
    bent = np.abs(traced - 1.0) > 0.05
    pixels = np.array([runner.project((x, -DEPTH, z)) for x, z in landed[bent]])
    inside = (pixels >= 0).all(axis=1) & (pixels[:, 0] < size[0]) & (pixels[:, 1] < size[1])
    share = lit[pixels[inside, 1], pixels[inside, 0], 0] / flat[pixels[inside, 1], pixels[inside, 0], 0]
    expected = traced[bent][inside]
    assert inside.sum() > 300, inside.sum()
    correlation = np.corrcoef(share, expected)[0, 1]
    assert np.median(np.abs(share - expected)) < 0.02
    assert correlation > 0.9, correlation


def test_the_rings_throw_the_suns_light_up_where_a_ray_tracer_does(scene):
    """A water that reflects the sun (``Mirror.reflects_light``) under a ceiling, its waves
    flattened (so the rings alone bend the light), a splash in it: each ceiling pixel's light
    over the same pool's with no Ripples is, where the rings bend the light, the traced share
    where the sun's rays reflected off the surface there land on the ceiling (the mirror law
    at the normal the field read back gives, 1 / |det J| of the landings on the texel grid)."""
    from tests.test_caustics import CEILING, SUN, ceiling_pool, render

    def splashed(on: bool, held: dict | None = None):
        build = ceiling_pool(1.0)

        def with_ripples(world):
            build(world)
            (entity, _), = world.query_one(Water)
            world.get(entity, Material).normal_scale = 0.0
            if held is not None:
                held["water"] = entity
            if on:
                world.add_component(entity, Ripples(speed=0.4, damping=0.0, cell=0.02))
            world.spawn(Transform(position=(0.0, 0.0, 0.0)), Splash(radius=0.12, depth=0.003))
        return with_ripples

    size = (128, 128)
    held = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        runner, _ = render(scene, splashed(True, held), size)
        for _ in range(28):
            frame = runner.frame(DT)
        _, flat = render(scene, splashed(False), size)
    lit = srgb_to_linear(frame)
    assert runner.engine.renderer.ripples.caustic_defines and runner.stats.virtual_lights == 1
    xz, area = texel_centres(runner, held)
    landed, traced = traced_gathering(xz, field_normals(runner, held), SUN, CEILING, area, reflected=True)
    bent = np.abs(traced - 1.0) > 0.05
    pixels = np.array([runner.project((x, CEILING, z)) for x, z in landed[bent]])
    inside = (pixels >= 0).all(axis=1) & (pixels[:, 0] < size[0]) & (pixels[:, 1] < size[1])
    share = lit[pixels[inside, 1], pixels[inside, 0], 0] / flat[pixels[inside, 1], pixels[inside, 0], 0]
    expected = traced[bent][inside]
    assert inside.sum() > 300, inside.sum()
    correlation = np.corrcoef(share, expected)[0, 1]
    assert np.median(np.abs(share - expected)) < 0.03, np.median(np.abs(share - expected))
    assert correlation > 0.9, correlation


def test_a_context_one_unit_short_keeps_the_caustics_the_waves_alone_and_says_so(scene, ctx):
    """On a context with texture units enough for the caustics and the foam but not the
    heights too (``RIPPLE_CAUSTIC_SAMPLERS``) the water still ripples (its composites) while
    its caustics are its waves' alone: the floor's light is the ripple-less pool's, bit for
    bit, and a GLLimitWarning names the water and the limit, once."""
    from tests.test_caustics import render

    runner = scene(splashed_pool(True), (48, 48))
    runner.engine.renderer.antialias = "off"
    runner.engine.renderer.ripples.release()
    runner.engine.renderer.ripples = RippleAtlas(ctx, texture_units=RIPPLE_CAUSTIC_SAMPLERS - 1)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(10):
            image = runner.frame(DT)
    said = [w for w in caught if issubclass(w.category, GLLimitWarning)]
    assert len(said) == 1 and f"would need {RIPPLE_CAUSTIC_SAMPLERS} fragment texture units" in str(said[0].message)
    atlas = runner.engine.renderer.ripples
    assert atlas.awake and atlas.defines and atlas.caustic_defines == ()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, flat = render(scene, splashed_pool(False), size=(48, 48))
    np.testing.assert_array_equal(srgb_to_linear(image), flat)


def test_the_light_shafts_under_the_rings_carry_the_light_they_gather(scene):
    """Looking straight down from under a sunlit, murky pool with light shafts and a splash in
    it (its waves flattened: the rings alone bend the light): each march texel's light over
    the same pool's with no splash is the ground truth's ratio, its sum along its ray of
    density x transmittance x the sun's light at each point with the light the rings gather
    at the point's depth (traced as the floor's is: Snell's law at the field read back, 1 /
    |det J| of the landings on the texel grid, at each of 13 depths) over the sum with none.
    The camera stands still: the march's kept image must follow the rings (its still key)."""
    from scipy.interpolate import LinearNDInterpolator

    from components import Camera, Fog, MeshRef, VolumetricFog
    from tests.test_caustics import DEPTH
    from tests.test_volumetric_fog import march_rays, marched_light

    body, air, deep = 0.3, 0.002, 1.2
    settings = VolumetricFog(steps=64, half_resolution=True)
    splash = (0.1, 0.0, -0.05)

    def build(held, splashed: bool):
        pool = splashed_pool(True, held, eye=(0.0, -0.2, 0.0), target=(0.0, -deep, -0.001),
                             sun=glm.vec3(0.0, -1.0, 0.0), depth=deep)

        def b(world):
            pool(world)
            camera = next(e for e, _ in world.query_one(Camera))
            world.add_component(camera, Fog(density=air, color=(0.0, 0.0, 0.0)))
            world.add_component(camera, settings)
            world.get(held["water"], Water).fog_density = body
            world.get(held["water"], Water).fog_color = (0.0, 0.0, 0.0)
            stone = next(e for e, _ in world.query_one(Splash))
            if splashed:
                world.get(stone, Transform).position = splash
            else:
                world.remove_component(stone, Splash)
            floor = next(e for e, (t, _) in world.query(Transform, MeshRef) if t.position.y == -DEPTH)
            world.get(floor, Transform).position = (0.0, -deep, 0.0)
        return b

    held = {}
    runners = [scene(build(held, True), (96, 64)), scene(build({}, False), (96, 64))]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for _ in range(24):
            for runner in runners:
                runner.frame(DT)
    runner = runners[0]
    assert runner.engine.renderer.ripples.caustic_defines and not runners[1].engine.renderer.ripples.awake
    seen = marched_light(runner)[..., 0] / marched_light(runners[1])[..., 0]
    atlas = runner.engine.renderer.ripples
    # The field about the splash (the rings' reach and more): its normals and texel centres.
    centre = atlas.to_texels(held["water"], np.array([splash]))[0].astype(int)
    near = (slice(centre[1] - 35, centre[1] + 35), slice(centre[0] - 35, centre[0] + 35))
    xz, area = texel_centres(runner, held)
    xz, normal = xz[near], field_normals(runner, held)[near]
    origin, way, (grid_rows, grid_columns) = march_rays(runner, (96, 64), 2)
    depths = np.linspace(0.0, deep, 13)
    table = []
    for d in depths:   # the traced light where each march ray is at depth d
        landed, gathered = traced_gathering(xz, normal, (0.0, -1.0, 0.0), d, area)
        light = LinearNDInterpolator(landed.reshape(-1, 2), gathered.ravel(), fill_value=1.0)
        t = (-d - origin[:, 1]) / way[:, 1]
        table.append(light(origin[:, [0, 2]] + way[:, [0, 2]] * t[:, None]))
    table = np.array(table)   # [depth, ray]
    reach = np.minimum((-deep - origin[:, 1]) / way[:, 1], settings.distance)
    points = 400
    along = reach[:, None] * ((np.arange(points) + 0.5) / points)[None, :]
    h = -(origin[:, 1:2] + way[:, 1:2] * along)
    level = np.clip(h / deep * (len(depths) - 1), 0.0, len(depths) - 1 - 1e-9)
    k = np.floor(level).astype(int)
    w = level - k
    ray = np.arange(len(origin))[:, None]
    gathered = table[k, ray] * (1.0 - w) + table[k + 1, ray] * w
    weight = (air + body) * np.exp(-(air + body) * along) * np.exp(-body * h)
    truth = ((weight * gathered).sum(1) / weight.sum(1)).reshape(grid_rows, grid_columns)
    ringed = np.abs(truth - 1.0) > 0.005
    assert ringed.sum() > 100, ringed.sum()
    assert np.corrcoef(seen[ringed], truth[ringed])[0, 1] > 0.98
    assert np.median(np.abs(seen - truth)) < 0.005


def test_the_sample_levels_koi_rings_its_pond_each_time_it_rises(ctx):
    """The hall's koi breaks the pond's surface at its mouth (``Rise``: first at ``first``
    seconds, then every ``every``; the script drops a Splash there): no drop before ``first``,
    one on the frame that reaches it, the deepest dent of the field straight under the mouth
    as the koi has turned by then, the next drop not before ``first + every``.  A bad Rise is
    refused naming its field."""
    from engine.core.frame_io import Output
    from engine.render.targets import CaptureTarget
    from games.hall_of_mirrors.level import HallOfMirrors, Rise
    from shell.app import Engine

    with pytest.raises(ValueError, match="Rise.every"):
        Rise(every=0.0)
    with pytest.raises(ValueError, match="Rise.depth"):
        Rise(depth=float("nan"))
    game = HallOfMirrors()
    engine = Engine(game, ctx)
    capture = CaptureTarget(ctx, (32, 18))
    try:
        small_probes(engine.world)   # (what is checked here is not in them)
        pond, mouth = game.names["pond"], game.names["koi_mouth"]
        rise = engine.world.get(mouth, Rise)
        drops, step = [], 0.1
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for _ in range(40):   # 4 seconds
                engine.frame(step, Output(capture.framebuffer, (32, 18)))
                drops.append(engine.renderer.stats.ripple_drops)
                if drops[-1] and len([count for count in drops if count]) == 1:
                    # Where the mouth is now (the koi has turned 35 degrees a second), straight
                    # across the pond's plane: the field's deepest texel.
                    mouth_at = [float(engine.world.get(mouth, Transform).world[3][r]) for r in range(3)]
                    atlas = engine.renderer.ripples
                    field = atlas.heights(pond)
                    row, column = np.unravel_index(np.argmin(field), field.shape)
                    x, y = atlas.to_texels(pond, [mouth_at])[0]
                    assert field.min() < -1e-4
                    assert math.hypot(column + 0.5 - x, row + 0.5 - y) < 2.0
        # (the game's clock sums each frame's 0.1 s: a time due may fall a rounding after a frame)
        times = [(n + 1) * step for n, count in enumerate(drops) if count]
        assert len(times) == 2
        assert rise.first - 1e-9 <= times[0] < rise.first + step + 1e-9
        assert rise.first + rise.every - 1e-9 <= times[1] < rise.first + rise.every + step + 1e-9
        assert all(drops[n] == 1 for n, count in enumerate(drops) if count)
    finally:
        capture.release()
        engine.close()


def test_a_first_drop_builds_no_program(scene):
    """A level with a rippling water whose waves gather the sun builds its RIPPLES programs with
    the level (the scene's CAUSTICS builds, the composites', the generated sky's): the frames of
    the first drop, and the rings after it, build none."""
    from tests.test_caustics import pool

    build = pool(1.0, scale=0.0)
    held = {}

    def rippling(world):
        build(world)
        (held["water"], _), = world.query_one(Water)
        world.add_component(held["water"], Ripples(speed=0.4, damping=0.0, cell=0.02))

    runner = scene(rippling, (48, 48))
    shaders = runner.engine.renderer.shaders
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for _ in range(3):
            runner.frame(DT)
        before = len(shaders._programs)
        assert not runner.engine.renderer.ripples.defines   # (calm: the plain builds drawn so far)
        runner.world.spawn(Transform(position=(0.0, 0.0, 0.0)), Splash(radius=0.12, depth=0.006))
        for _ in range(3):
            runner.frame(DT)
    assert runner.engine.renderer.ripples.caustic_defines and runner.stats.ripple_steps >= 1
    assert len(shaders._programs) == before


def carried_pond(ripples: bool, place: glm.mat4, enabled: bool = True, floor: bool = False):
    """``pond``'s rippling water (a splash in it; ``enabled`` False: its Mirror switched off, so
    its fallback shows; ``floor``: a checkered floor 0.4 m under it) and checkered wall under
    the sun and a grey sky, each placed by ``place`` (rigid) after its own transform; a build
    of (world, carry) for ``tests.test_particles.through_a_portal_and_from_its_eye``, or of a
    world alone (``world.water``: the water's entity)."""
    turn = glm.quat_cast(place)

    def at(x, y, z) -> glm.vec3:
        return glm.vec3(place * glm.vec4(x, y, z, 1.0))

    def build(world, carry=None):
        world.spawn(Skybox(faces=[np.full((8, 8, 3), 0.3, np.float32) for _ in range(6)]))
        world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.4), intensity=1.5))
        for i in range(8):
            for j in range(4):
                world.spawn(Transform(position=at(-2.0 + i * 0.5 + 0.25, 0.25 + j * 0.5, -2.0), rotation=turn),
                            MeshRef(quad(0.5, 0.5)),
                            Material(color=(0.9, 0.2, 0.1, 1) if (i + j) % 2 else (0.1, 0.3, 0.9, 1), roughness=1.0))
                if floor:
                    world.spawn(Transform(position=at(-2.0 + i * 0.5 + 0.25, -0.4, -2.0 + j * 0.5 + 0.25),
                                          rotation=turn * FLAT), MeshRef(quad(0.5, 0.5)),
                                Material(color=(0.9, 0.8, 0.2, 1) if (i + j) % 2 else (0.1, 0.5, 0.2, 1),
                                         roughness=1.0))
        world.water = world.spawn(Transform(position=at(0.0, 0.0, 0.0), rotation=turn * FLAT),
                                  MeshRef(quad(4.0, 4.0)), Material(color=(0.05, 0.2, 0.25, 0.3), roughness=0.2),
                                  Mirror(enabled=enabled), Water(),
                                  *([Ripples(speed=0.5, damping=0.0, cell=0.02)] if ripples else []))
        world.spawn(Transform(position=at(0.2, 0.0, -0.4)), Splash(radius=0.12, depth=0.04))
    return build


@pytest.mark.parametrize("path", ["per_mirror", "batched"])
def test_a_portal_shows_the_rings_as_the_eye_it_carries_sees_them(scene, path):
    """A splashed rippling pond reflecting a checkered wall beyond portal B, seen through portal
    A (the pond's reflection a level below the portal's view), and the same world without
    portals rendered directly from the eye the pair carries the camera's to, the same frames
    stepped: inside A's opening the two are the same pixels (the portal's level composites
    the water with its rings), and the rings are there (the opening differs from the same
    pond's without Ripples)."""
    from tests.test_particles import through_a_portal_and_from_its_eye

    def content(ripples):
        def make(world, carry):
            carried_pond(ripples, carry * glm.translate(glm.vec3(0.0, -0.5, -4.6)))(world)
        return make

    shot = dict(path=path, eye=glm.vec3(0.0, 0.6, -1.0), target=(0.2, -0.5, -5.0), fov=40.0, frames=20)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # (a still water: no waves, said)
        rippled, direct, opening, runners = through_a_portal_and_from_its_eye(scene, content(True), **shot)
        plain, _, _, _ = through_a_portal_and_from_its_eye(scene, content(False), **shot)
    assert runners[True].stats.reflection_views >= 2   # (the portal's view and the pond's below it)
    shown = np.abs(rippled - plain).max(axis=-1)[opening]
    assert (shown > 0.02).sum() > 20, (shown > 0.02).sum()   # (the rings are there)
    apart = np.abs(rippled - direct).max(axis=-1)[opening]
    assert np.quantile(apart, 0.99) <= 0.01 and apart.max() <= 0.04, (np.quantile(apart, 0.99), apart.max())


def test_a_waters_fallback_shows_the_rings_where_they_are_and_nowhere_else(scene):
    """The splashed pond over a checkered floor with its Mirror switched off (no view: its
    fallback, the sky's reflection and the floor bent below it), against the same pond with no
    Ripples: the frame changes where the rings tilt the surface (each pixel's point on the
    water found along its ray, the field's slope there read back) and not where it is flat."""
    def build(ripples):
        def make(world):
            world.spawn(Transform(position=(0.0, 1.2, 2.2), rotation=look_rotation(glm.vec3(0.2, -1.2, -2.6))),
                        Camera(fov_y=40.0))
            carried_pond(ripples, glm.mat4(), enabled=False, floor=True)(world)
        return make

    size = (96, 72)
    rippled, frame = run(scene, build(True), 20, size)
    _, plain = run(scene, build(False), 20, size)
    stats = rippled.stats
    assert (stats.reflection_views, stats.reflection_fallbacks) == (0, 1)
    field = heights(rippled, {"water": rippled.world.water})
    slope = np.hypot(*np.gradient(field.astype(np.float64), 0.02))
    eye, directions = pixel_rays(rippled.engine.main_view, size)
    at = eye + directions * (-eye[1] / directions[..., 1])[..., None]
    on = (directions[..., 1] < 0) & (np.abs(at[..., 0]) < 1.9) & (np.abs(at[..., 2]) < 1.9)
    texel = rippled.engine.renderer.ripples.to_texels(rippled.world.water, at.reshape(-1, 3)).reshape(*size[::-1], 2)
    near = slope.copy()
    for axis in (0, 1):
        for shift in (-3, -2, -1, 1, 2, 3):
            near = np.maximum(near, np.roll(slope, shift, axis=axis))
    under = near[np.clip(texel[..., 1].astype(int), 0, field.shape[0] - 1),
                 np.clip(texel[..., 0].astype(int), 0, field.shape[1] - 1)]
    changed = np.abs(frame.astype(int) - plain.astype(int)).max(axis=-1)
    flat, tilted = on & (under < 1e-5), on & (under > 0.02)
    assert flat.sum() > 1000 and tilted.sum() > 30, (flat.sum(), tilted.sum())
    assert changed[flat].max() <= 2
    assert (changed[tilted] > 2).mean() > 0.3


def test_a_wake_faster_than_the_ripples_leaves_a_v_of_half_angle_asin_of_their_speed_over_its_own(scene):
    """A thin post with a ``Wake`` (radius 4 cm: a drop 1.5 texels wide, ``MIN_DROP_TEXELS``)
    wading along x at ``u`` through still water whose rings spread at ``c`` (no damping): past
    the ripples' speed its rings, each from where it was, are enveloped by Mach's V, whose
    sides stand at asin(c / u) from its way and which nothing crosses ahead of it (for a point
    source; a drop of radius r moves the sides out by r / cos of that).  Read back after 1.6 s:
    ahead of it the water is still; the V's edge (the farthest a disturbance of 5% of the
    field's greatest reaches from the way, at each distance behind the post, fitted by a line)
    stands at that angle within 1.5 degrees and starts r / cos of it out, within a texel, for
    u = 2c (30 degrees) and 4c (14.5 degrees); slower than the ripples (u = c / 2) the rings
    run ahead of it, and there is no V."""
    c, cell, radius, start, frames, dt = 0.3, 0.03, 0.04, -1.4, 48, 1.0 / 30.0

    def wade(u: float):
        post = (Transform(position=(start, 0.0, 0.0)), MeshRef(box((0.1, 0.3, 0.1))),
                Material(color=(0.9, 0.9, 0.2, 1.0)), Wake(strength=0.5, radius=radius))
        build, held = pond(Ripples(speed=c, damping=0.0, cell=cell), things=[post])
        runner = scene(build, (32, 24))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for k in range(frames):
                runner.world.get(held["things"][0], Transform).position = glm.vec3(start + u * dt * k, 0.0, 0.0)
                runner.frame(dt)
        assert runner.stats.ripple_steps >= 1
        xz, _ = texel_centres(runner, held)
        behind = start + u * dt * (frames - 1) - xz[..., 0]   # (metres behind the post along its way)
        spacing = 4.0 / runner.engine.renderer.ripples.waters[held["water"]][1].texels[0]
        return np.abs(heights(runner, held).astype(np.float64)), behind, np.abs(xz[..., 1]), spacing

    for u in (2.0 * c, 4.0 * c):
        field, behind, off_the_way, spacing = wade(u)
        assert field.max() > 1e-3
        assert field[behind < -2.0 * spacing].max() < 1e-6 * field.max()   # (nothing ahead of it)
        stirred = field > 0.05 * field.max()
        distances = np.arange(0.1, 0.8 * u * dt * frames, spacing)
        edges = [off_the_way[(np.abs(behind - s) < spacing / 2) & stirred].max() for s in distances]
        slope, start_out = np.polyfit(distances, edges, 1)
        half_angle = math.asin(c / u)
        assert math.degrees(abs(math.atan(slope) - half_angle)) < 1.5, (u, math.degrees(math.atan(slope)))
        assert abs(start_out - max(radius, 1.5 * spacing) / math.cos(half_angle)) < spacing, (u, start_out)
    field, behind, _, _ = wade(0.5 * c)
    assert field[behind < -0.15].max() > 0.2 * field.max()   # (slower than its rings: they run ahead)
