"""The particle simulation (``engine/core/particle_cloud.py``), without GL: what a stream
spawns, where its particles fly (against the closed forms of ballistic flight and a second,
tiny-step integration with drag), the cone and shapes they start in, their life, the cap,
bursts, local and world space, a moving emitter's trail, and the drawn rows' size, colour
and flipbook frame from age; the component's refusals."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, ParticleEmitter
from engine.core.particle_cloud import ROW_ANGLE, ROW_COLOR, ROW_FRAME, ROW_POSITION, ROW_SIZE, ParticleCloud

DT = 1.0 / 60.0


def run(emitter: ParticleEmitter, frames: int, dt: float = DT, matrix: glm.mat4 | None = None,
        cloud: ParticleCloud | None = None) -> ParticleCloud:
    cloud = cloud or ParticleCloud(emitter.seed, emitter.max_particles)
    for _ in range(frames):
        cloud.step(emitter, matrix if matrix is not None else glm.mat4(1.0), dt)
    return cloud


def test_a_stream_spawns_its_rate_spread_evenly_through_each_frame():
    emitter = ParticleEmitter(rate=90.0, lifetime=(10.0, 10.0), speed=(0.0, 0.0))
    cloud = run(emitter, 60)  # one second
    assert cloud.count == 90
    ages = np.sort(cloud.age)
    # Born every 1/90 s through the second, across the frames' edges (1.5 a frame).
    np.testing.assert_allclose(np.diff(ages), 1.0 / 90.0, rtol=1e-6)
    assert ages[0] < 1.0 / 90.0
    # 1.5 a frame: the half particle is carried, not lost or rounded up.
    assert run(ParticleEmitter(rate=90.0, lifetime=10.0), 1).count == 1
    assert run(ParticleEmitter(rate=90.0, lifetime=10.0), 2).count == 3


def test_ballistic_flight_is_the_closed_form_whatever_the_frame_rate():
    g = glm.vec3(0.5, -9.81, 0.0)
    emitter = ParticleEmitter(rate=30.0, lifetime=5.0, speed=3.0, spread=0.0, direction=(0.0, 1.0, 1.0), gravity=g)
    start = glm.vec3(1.0, 2.0, 3.0)
    v0 = np.array(glm.normalize(glm.vec3(0.0, 1.0, 1.0))) * 3.0
    for dt in (1.0 / 20.0, 1.0 / 144.0):
        cloud = run(emitter, round(1.5 / dt), dt, glm.translate(start))
        t = cloud.age[:, None]
        expected = np.array(start) + v0 * t + 0.5 * np.array(g) * t * t
        np.testing.assert_allclose(cloud.position, expected, atol=1e-6)  # (glm holds float32s)
        np.testing.assert_allclose(cloud.velocity, v0 + np.array(g) * t, atol=1e-6)


def test_drag_follows_a_tiny_step_integration():
    g = np.array((0.0, -9.81, 0.0))
    k = 1.7
    emitter = ParticleEmitter(rate=0.0, burst=1, lifetime=5.0, speed=4.0, spread=0.0, direction=(1.0, 0.0, 0.0),
                              gravity=tuple(g), drag=k)
    cloud = run(emitter, 45, 1.0 / 30.0)  # born at the first frame's end: 44 frames of 1/30 s in flight
    steps = 146667
    x, v, h = np.zeros(3), np.array((4.0, 0.0, 0.0)), (44.0 / 30.0) / steps
    for _ in range(steps):  # the same time, a hundred-thousandth of a second at a time
        v = v + (g - k * v) * h
        x = x + v * h
    np.testing.assert_allclose(cloud.position[0], x, atol=2e-4)
    np.testing.assert_allclose(cloud.velocity[0], v, atol=2e-4)


@pytest.mark.parametrize("spread", [0.0, 20.0, 90.0, 180.0])
def test_headings_fill_the_cone_and_no_more(spread):
    axis = glm.normalize(glm.vec3(1.0, 2.0, -0.5))
    emitter = ParticleEmitter(rate=0.0, burst=4000, max_particles=4000, lifetime=10.0, speed=1.0, spread=spread,
                              direction=axis)
    cloud = run(emitter, 1)
    cosines = cloud.velocity @ np.array(axis)
    assert cosines.min() >= math.cos(math.radians(spread)) - 1e-6
    # Uniform over the cap: the cosines spread evenly between cos(spread) and 1.
    expected_mean = (1.0 + math.cos(math.radians(spread))) / 2.0
    assert abs(cosines.mean() - expected_mean) < 0.03
    np.testing.assert_allclose(np.linalg.norm(cloud.velocity, axis=1), 1.0)


def test_shapes_start_inside_their_extent_filling_it():
    ball = run(ParticleEmitter(rate=0.0, burst=3000, max_particles=3000, speed=0.0, lifetime=9.0, shape="sphere",
                               extent=(2.0, 0.0, 0.0)), 1)
    radii = np.linalg.norm(ball.position, axis=1)
    assert radii.max() <= 2.0 and radii.max() > 1.95
    assert abs(np.mean(radii < 1.0) - 1.0 / 8.0) < 0.03  # a uniform ball: 1/8 of it within half the radius
    box = run(ParticleEmitter(rate=0.0, burst=3000, max_particles=3000, speed=0.0, lifetime=9.0, shape="box",
                              extent=(1.0, 0.5, 0.25)), 1)
    assert (np.abs(box.position) <= np.array((1.0, 0.5, 0.25))).all()
    assert (np.abs(box.position).max(axis=0) > np.array((0.95, 0.47, 0.23))).all()
    point = run(ParticleEmitter(rate=0.0, burst=10, speed=0.0, lifetime=9.0), 1,
                matrix=glm.translate(glm.vec3(4, 5, 6)))
    np.testing.assert_allclose(point.position, [[4.0, 5.0, 6.0]] * 10)


def test_particles_live_between_their_lifetimes_then_go():
    emitter = ParticleEmitter(rate=200.0, lifetime=(0.5, 1.0))
    cloud = run(emitter, 120)
    assert (cloud.life >= 0.5).all() and (cloud.life <= 1.0).all()
    assert (cloud.age < cloud.life).all()
    emitter.playing = False
    run(emitter, 25, cloud=cloud)
    assert 0 < cloud.count  # the last frame's births live at least 0.5 s
    run(emitter, 36, cloud=cloud)  # 1.017 s since the last birth: past every life
    assert cloud.count == 0


def test_the_cap_holds_counts_and_warns_once_at_the_system(scene):
    from components import Transform
    emitter = ParticleEmitter(rate=600.0, lifetime=10.0, max_particles=50)
    cloud = run(emitter, 6)
    assert cloud.count == 50 and cloud.capped == 10  # 60 asked for
    run(emitter, 1, cloud=cloud)
    assert cloud.count == 50 and cloud.capped == 10

    def build(world):
        world.spawn(Transform(), ParticleEmitter(rate=600.0, lifetime=10.0, max_particles=50))
    runner = scene(build, (32, 18))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(8):
            runner.frame()
    from engine.core.errors import ParticleLimitWarning
    limits = [w for w in caught if issubclass(w.category, ParticleLimitWarning)]
    assert len(limits) == 1 and "max_particles (50)" in str(limits[0].message)
    assert runner.stats.particles == 50 and runner.stats.particles_capped == 10


def test_a_burst_comes_each_time_it_starts_playing():
    emitter = ParticleEmitter(rate=0.0, burst=25, lifetime=10.0)
    cloud = run(emitter, 3)
    assert cloud.count == 25
    emitter.playing = False
    run(emitter, 1, cloud=cloud)
    emitter.playing = True
    run(emitter, 1, cloud=cloud)
    assert cloud.count == 50
    # A burst is born at once: no age, all at the emitter.
    assert (cloud.age[-25:] == 0.0).all()


def test_world_space_stays_behind_local_space_moves_with_the_emitter():
    kw = dict(rate=0.0, burst=5, lifetime=10.0, speed=1.0, spread=0.0, direction=(0.0, 1.0, 0.0))
    here, there = glm.translate(glm.vec3(0.0)), glm.translate(glm.vec3(10.0, 0.0, 0.0)) * glm.rotate(
        math.pi / 2.0, glm.vec3(0.0, 0.0, 1.0))
    world = ParticleEmitter(**kw)
    cloud = run(world, 30, matrix=here)
    run(world, 30, matrix=there, cloud=cloud)
    rows = cloud.rows(world, there)
    up = 59.0 / 60.0  # born at the first frame's end, flown 59 frames
    np.testing.assert_allclose(rows[:, ROW_POSITION], [[0.0, up, 0.0]] * 5, atol=1e-5)  # up from the origin
    local = ParticleEmitter(**kw, space="local")
    cloud = run(local, 30, matrix=here)
    run(local, 30, matrix=there, cloud=cloud)
    rows = cloud.rows(local, there)
    # As far along the emitter's up, which now points along -x, from where the emitter is now.
    np.testing.assert_allclose(rows[:, ROW_POSITION], [[10.0 - up, 0.0, 0.0]] * 5, atol=1e-5)


def test_a_moving_emitter_leaves_an_even_trail():
    emitter = ParticleEmitter(rate=600.0, lifetime=10.0, speed=0.0, max_particles=5000)
    cloud = ParticleCloud(0, 5000)
    for frame in range(11):  # 10 m/s along x, 10 particles a frame
        cloud.step(emitter, glm.translate(glm.vec3(frame * 10.0 * DT, 0.0, 0.0)), DT)
    assert cloud.count == 110
    # Born after the first frame (which has no place before it): each where the emitter was
    # at its birth, x = 10 m/s x (now - age), one every 1/600 s: 1/60 m apart.
    moved = cloud.age < 10 * DT - 1e-9
    np.testing.assert_allclose(cloud.position[moved, 0], 10.0 * (10 * DT - cloud.age[moved]), atol=1e-6)
    np.testing.assert_allclose(np.diff(np.sort(cloud.position[moved, 0])), 10.0 / 600.0, atol=1e-6)


def test_rows_carry_size_colour_and_frame_by_age():
    emitter = ParticleEmitter(rate=0.0, burst=1, lifetime=2.0, speed=0.0, size=(0.2, 1.0),
                              color=(2.0, 1.0, 0.0, 1.0), end_color=(0.0, 1.0, 1.0, 0.5), sheet=(4, 2),
                              spin=(90.0, 90.0))
    cloud = run(emitter, 1)
    angle0 = cloud.rows(emitter, glm.mat4(1.0))[0, ROW_ANGLE]
    run(emitter, 45, cloud=cloud)  # 0.75 s of 2: t = 0.375
    row = cloud.rows(emitter, glm.mat4(1.0))[0]
    t = 0.375
    assert row[ROW_SIZE] == pytest.approx(0.2 + 0.8 * t, rel=1e-5)
    np.testing.assert_allclose(row[ROW_COLOR], [2.0 - 2.0 * t, 1.0, t, 1.0 - 0.5 * t], rtol=1e-5)
    assert row[ROW_FRAME] == math.floor(t * 8)
    assert row[ROW_ANGLE] - angle0 == pytest.approx(math.radians(90.0) * 0.75, rel=1e-4)
    fade = ParticleEmitter(color=(1.0, 0.5, 0.25, 0.8))
    assert tuple(fade.final_color) == (1.0, 0.5, 0.25, 0.0)  # end_color None: the colour, faded out


def test_the_same_seed_makes_the_same_cloud():
    def cloud(seed):
        e = ParticleEmitter(rate=100.0, spread=60.0, speed=(1.0, 2.0), lifetime=(1.0, 2.0), seed=seed)
        return run(e, 20).rows(e, glm.mat4(1.0))
    np.testing.assert_array_equal(cloud(3), cloud(3))
    assert not np.array_equal(cloud(3), cloud(4))


@pytest.mark.parametrize("field, value, words", [
    ("rate", -1.0, ">= 0"), ("burst", 1.5, "int"), ("lifetime", (2.0, 1.0), "least <= most"),
    ("lifetime", 0.0, "> 0"), ("speed", (1.0, float("nan")), "finite"), ("direction", (0, 0, 0), "zero vector"),
    ("spread", 181.0, "<= 180"), ("shape", "cone", "one of"), ("blend", "multiply", "one of"),
    ("sheet", (0, 1), "int in [1, 64]"), ("sheet", 3, "two ints"), ("max_particles", 10 ** 6, "int in [1, 65536]"),
    ("color", (1.0, 1.0, 1.0, 2.0), "alpha <= 1"), ("texture", "smoke.png", "TextureData"),
    ("gravity", (0.0, -1e5, 0.0), "within"), ("space", "screen", "one of"), ("translucency", 1.5, "<= 1"),
])
def test_bad_values_are_refused_naming_the_field(field, value, words):
    with pytest.raises(ComponentValueError, match=f"ParticleEmitter.{field}") as caught:
        ParticleEmitter(**{field: value})
    assert words in str(caught.value)


def test_a_ground_bounces_particles_keeping_its_share_of_their_fall():
    """Dropped from 2 m onto ground 0.5 with bounce 0.5: never below it, and back up to a
    quarter of the fall (the speed kept, squared: 0.375 m above it), then lower each time."""
    emitter = ParticleEmitter(rate=0.0, burst=1, lifetime=100.0, speed=0.0, gravity=(0.0, -9.81, 0.0), ground=0.5,
                              bounce=0.5)
    cloud = ParticleCloud(0, 10)
    heights = []
    for _ in range(480):  # 2 s at 240 Hz
        cloud.step(emitter, glm.translate(glm.vec3(0.0, 2.0, 0.0)), 1.0 / 240.0)
        heights.append(cloud.position[0, 1])
    heights = np.array(heights)
    assert heights.min() >= 0.5
    first_landing = int(np.argmax(heights < 0.52))
    assert heights[first_landing:].max() == pytest.approx(0.5 + 1.5 * 0.25, rel=0.03)
    flat = ParticleEmitter(rate=0.0, burst=1, lifetime=100.0, speed=1.0, spread=0.0, direction=(1.0, -1.0, 0.0),
                           gravity=(0.0, -9.81, 0.0), ground=0.0, bounce=0.0)
    cloud = run(flat, 60)
    assert cloud.position[0, 1] == 0.0 and cloud.velocity[0, 1] == 0.0 and cloud.velocity[0, 0] > 0.7  # sliding
    with pytest.raises(ComponentValueError, match="ParticleEmitter.ground is a world height"):
        ParticleEmitter(space="local", ground=0.0)
    with pytest.raises(ComponentValueError, match='ParticleEmitter.space cannot be "local"'):
        ParticleEmitter(ground=0.0).space = "local"


def test_colour_and_size_keys_make_a_curve_over_life():
    """Fire: yellow to orange at 30%, red at 60%, grey smoke at the end; size growing to 70%
    then shrinking: each row the straight line between the two keys about its life share."""
    keys = ((0.0, 1.0, 0.9, 0.2, 1.0), (0.3, 1.0, 0.5, 0.1, 1.0), (0.6, 0.8, 0.1, 0.0, 0.8), (1.0, 0.3, 0.3, 0.3, 0.0))
    emitter = ParticleEmitter(rate=0.0, burst=1, lifetime=2.0, speed=0.0, color_keys=keys,
                              size_keys=((0.0, 0.1), (0.7, 0.5), (1.0, 0.2)))
    for share in (0.1, 0.25, 0.45, 0.75):  # ages 0.2, 0.5, 0.9, 1.5 s of 2
        cloud = run(emitter, 1)
        run(emitter, int(round(share * 2.0 * 60)), cloud=cloud)
        row = cloud.rows(emitter, glm.mat4(1.0))[0]
        t = cloud.age[0] / cloud.life[0]
        below = max(k for k in keys if k[0] <= t)
        above = min(k for k in keys if k[0] >= t)
        f = 0.0 if above[0] == below[0] else (t - below[0]) / (above[0] - below[0])
        np.testing.assert_allclose(row[ROW_COLOR], [b + (a - b) * f for b, a in zip(below[1:], above[1:],
                                                                                       strict=True)], atol=1e-6)
        size = 0.1 + (0.5 - 0.1) * t / 0.7 if t <= 0.7 else 0.5 + (0.2 - 0.5) * (t - 0.7) / 0.3
        assert row[ROW_SIZE] == pytest.approx(size, abs=1e-6)
    with pytest.raises(ComponentValueError, match="life shares must increase"):
        ParticleEmitter(size_keys=((0.5, 1.0), (0.2, 2.0)))
    with pytest.raises(ComponentValueError, match=r"ParticleEmitter.color_keys"):
        ParticleEmitter(color_keys=((0.0, 1.0, 1.0),))


def test_a_mesh_emitter_is_born_on_its_surface_by_area_flying_along_its_normals(scene):
    """A 4 x 1 x 1 box turned a quarter about y and moved: every particle on its surface, its
    velocity the outward normal of the face it was born on (spread 0), and the long faces
    (4 x 1, four of them) taking 16/18 of the births, as their area."""
    from components import Transform
    from engine.assets.mesh import box

    mesh = box((4.0, 1.0, 1.0))
    turn = glm.angleAxis(glm.radians(90.0), glm.vec3(0.0, 1.0, 0.0))
    matrix = glm.translate(glm.vec3(1.0, 2.0, 3.0)) * glm.mat4_cast(turn)
    emitter = ParticleEmitter(rate=0.0, burst=6000, max_particles=6000, lifetime=10.0, speed=1.0, spread=0.0,
                              shape="mesh")
    cloud = ParticleCloud(0, 6000)
    cloud.step(emitter, matrix, DT, mesh=mesh)
    assert cloud.count == 6000
    inverse = np.array(glm.inverse(matrix))
    local = cloud.position @ inverse[:3, :3].T + inverse[:3, 3]
    on_face = np.isclose(np.abs(local), (2.0, 0.5, 0.5), atol=1e-6)
    assert on_face.any(axis=1).all()  # on the surface
    local_velocity = cloud.velocity @ inverse[:3, :3].T
    expected = np.where(on_face, np.sign(local), 0.0)  # the outward normal of its face
    one = on_face.sum(axis=1) == 1  # (a point on an edge is on two faces: left out)
    assert one.mean() > 0.99
    np.testing.assert_allclose(local_velocity[one], expected[one], atol=1e-6)
    long_faces = (on_face[:, 1] | on_face[:, 2]).mean()
    assert long_faces == pytest.approx(16.0 / 18.0, abs=0.02)

    def build(world):
        world.spawn(Transform(), ParticleEmitter(shape="mesh"))
    with pytest.raises(ComponentValueError, match="give the entity a MeshRef too"):
        scene(build, (16, 16))
    from engine.core.world import World
    world = World("mesh")
    entity = world.spawn(Transform(), ParticleEmitter())
    with pytest.raises(ComponentValueError, match="it has no MeshRef; give it one first"):
        world.get(entity, ParticleEmitter).shape = "mesh"


def test_the_particles_stage_gives_a_mesh_emitter_its_mesh_and_says_when_it_went(scene):
    from components import Material, MeshRef, Transform
    from engine.assets.mesh import box
    from engine.core.errors import ParticleLimitWarning
    from tests.support import look_from

    def build(world):
        look_from(world, (0.0, 1.0, 6.0), (0.0, 1.0, 0.0))
        world.log = world.spawn(Transform(position=glm.vec3(0.0, 1.0, 0.0)), MeshRef(box((2.0, 0.4, 0.4))),
                                Material(), ParticleEmitter(rate=60.0, burst=50, lifetime=10.0, speed=0.0,
                                                            shape="mesh"))
    runner = scene(build, (32, 24))
    runner.frame()
    (cloud, _), = runner.engine.stages["particles"].clouds.values()
    assert cloud.count == 51  # the burst and a frame's one
    local = np.abs(cloud.position - np.array((0.0, 1.0, 0.0)))
    assert np.isclose(local, (1.0, 0.2, 0.2), atol=1e-5).any(axis=1).all()
    runner.world.remove_component(runner.world.log, MeshRef)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(3):
            runner.frame()
    said = [w for w in caught if issubclass(w.category, ParticleLimitWarning)]
    assert len(said) == 1 and "its MeshRef is gone" in str(said[0].message)
    assert cloud.count == 51  # none born since


def test_a_prewarmed_cloud_starts_a_lifetime_in(scene):
    """Prewarmed, 40 a second living 1.5 s: the first frame already holds about 60, of every
    age up to the lifetime; not prewarmed, the frame's one."""
    from components import Transform
    from tests.support import look_from

    def build(world):
        look_from(world, (0.0, 1.0, 6.0), (0.0, 1.0, 0.0))
        world.warm = world.spawn(Transform(), ParticleEmitter(rate=40.0, lifetime=1.5, prewarm=True))
        world.cold = world.spawn(Transform(), ParticleEmitter(rate=40.0, lifetime=1.5))
    runner = scene(build, (16, 16))
    runner.frame()
    clouds = runner.engine.stages["particles"].clouds
    warm, cold = clouds[runner.world.warm][0], clouds[runner.world.cold][0]
    assert 58 <= warm.count <= 61 and cold.count <= 1
    assert warm.age.min() < 0.05 and warm.age.max() > 1.4


def test_the_overlay_says_how_many_live_and_how_many_the_cap_kept_from_being_born(scene):
    from components import Transform
    from shell.overlay_text import overlay_lines
    from tests.support import look_from

    def build(world):
        look_from(world, (0.0, 1.0, 6.0), (0.0, 1.0, 0.0))
        world.spawn(Transform(), ParticleEmitter(rate=600.0, lifetime=10.0, max_particles=25))
    runner = scene(build, (16, 16))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for _ in range(4):  # 10 asked a frame: the third takes the last 5, the fourth none
            runner.frame()
    assert "particles 25, 10 not born (max_particles)" in overlay_lines(runner.engine, [0.02])


def test_a_sub_emitter_bursts_where_each_particle_dies(scene):
    """Fireworks: a rocket (one particle up at 5 m/s, living 0.5 s) whose on_death is a burst of
    20 sparks (every way, 2 m/s): the frame the rocket dies, 20 sparks at age 0 where it was,
    flying 2 m/s; a sub-emitter that names no emitter is said once."""
    from components import Transform
    from engine.core.errors import ParticleLimitWarning
    from tests.support import look_from

    def build(world):
        look_from(world, (0.0, 1.0, 8.0), (0.0, 1.0, 0.0))
        world.sparks = world.spawn(Transform(position=glm.vec3(5.0, 0.0, 0.0)),
                                   ParticleEmitter(rate=0.0, burst=20, speed=2.0, spread=180.0, lifetime=5.0,
                                                   max_particles=100, playing=False))  # (no burst of its own)
        world.rocket = world.spawn(Transform(), ParticleEmitter(rate=0.0, burst=1, speed=5.0, spread=0.0,
                                                                lifetime=0.5, on_death=world.sparks))
    runner = scene(build, (16, 16))
    runner.frame(1.0 / 60.0)
    clouds = runner.engine.stages["particles"].clouds
    world = runner.world
    rocket, sparks = clouds[world.rocket][0], clouds[world.sparks][0]
    for _ in range(40):
        before = rocket.position.copy()
        runner.frame(1.0 / 60.0)
        if sparks.count:
            break
    assert rocket.count == 0 and sparks.count == 20
    # Born where the rocket was when it died (the last place it stood: its step's start).
    np.testing.assert_allclose(sparks.position, np.repeat(before, 20, axis=0), atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(sparks.velocity, axis=1), 2.0, rtol=1e-6)
    assert (sparks.age == 0.0).all() and before[0, 1] > 2.0
    world.get(world.rocket, ParticleEmitter).on_death = 9999
    world.get(world.rocket, ParticleEmitter).playing = False
    runner.frame(1.0 / 60.0)
    world.get(world.rocket, ParticleEmitter).playing = True  # another rocket
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(40):
            runner.frame(1.0 / 60.0)
    said = [w for w in caught if issubclass(w.category, ParticleLimitWarning) and "names entity 9999" in str(w.message)]
    assert len(said) == 1


def test_a_level_file_names_a_sub_emitter_by_its_entitys_name(tmp_path):
    import textwrap

    from engine.assets.level_file import LevelError, load_level, save_level
    from engine.core.world import World

    text = textwrap.dedent("""
        [level]
        name = "fireworks"

        [[entity]]
        name = "rocket"
        [entity.Transform]
        [entity.ParticleEmitter]
        rate = 0.5
        on_death = "burst"

        [[entity]]
        name = "burst"
        [entity.Transform]
        [entity.ParticleEmitter]
        rate = 0.0
        burst = 40
        playing = false
        """)
    path = tmp_path / "fireworks.toml"
    path.write_text(text)
    world = World("fireworks")
    names = load_level(path).spawn(world)
    assert world.get(names["rocket"], ParticleEmitter).on_death == names["burst"]
    saved = save_level(world, tmp_path / "saved.toml", names, name="fireworks")
    assert 'on_death = "burst"' in saved.read_text()
    path.write_text(text.replace('on_death = "burst"', 'on_death = "nobody"'))
    with pytest.raises(LevelError, match="nobody"):
        load_level(path)


def test_the_editor_offers_the_other_emitters_as_a_sub_emitter(scene):
    from components import Transform
    from shell.editor import Editor

    def build(world):
        world.a = world.spawn(Transform(), ParticleEmitter())
        world.b = world.spawn(Transform(), ParticleEmitter(playing=False))
        world.plain = world.spawn(Transform())
    runner = scene(build, (16, 16))
    editor = Editor(runner.world)
    choices, more = editor.reference_choices(runner.world.a, "ParticleEmitter", "on_death")
    assert [entity for entity, _ in choices] == [None, runner.world.b] and not more
    editor.set_field(runner.world.a, "ParticleEmitter", "on_death", runner.world.b)
    assert runner.world.get(runner.world.a, ParticleEmitter).on_death == runner.world.b


def test_each_capped_emitter_is_named_in_its_own_warning_once_and_again_after_a_run_uncapped(scene):
    """Two emitters past their max_particles: one ParticleLimitWarning each, naming its entity
    and its cap, over frames of being capped; the first, no longer capped (paused until its
    particles die) and then capped again, is said again; ``particles_capped`` is the frame's
    sum of both (600 and 1200 a second asked at 60 Hz: 10 and 20 not born a frame)."""
    from components import Transform
    from engine.core.errors import ParticleLimitWarning

    held = {}

    def build(world):
        held["a"] = world.spawn(Transform(), ParticleEmitter(rate=600.0, lifetime=0.2, max_particles=50))
        held["b"] = world.spawn(Transform(), ParticleEmitter(rate=1200.0, lifetime=10.0, max_particles=30))
    runner = scene(build, (16, 16))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(8):
            runner.frame()
        capped = runner.stats.particles_capped
        emitter = runner.world.get(held["a"], ParticleEmitter)
        emitter.playing = False
        for _ in range(20):   # (0.33 s: every one of its particles gone)
            runner.frame()
        emitter.playing = True
        for _ in range(8):
            runner.frame()
    said = [str(w.message) for w in caught if issubclass(w.category, ParticleLimitWarning)]
    assert capped == 30
    a, b = f"entity {held['a']}:", f"entity {held['b']}:"
    assert [m.startswith(a) for m in said].count(True) == 2 and all("max_particles (50)" in m for m in said if a in m)
    assert [m.startswith(b) for m in said].count(True) == 1 and all("max_particles (30)" in m for m in said if b in m)
