"""A moving mirror or portal moves what its view shows (``SurfaceMotion``, the surfaces stage;
``MirrorPasses.surface_motion``, the composite's ``SURFACE_MOTION`` builds): a still box seen
in a turning mirror, or through a portal whose partner slides, streaks by where the surface
shows it now and showed it last frame (worked out from the two carries), by either reflection
path; nothing is left once the surface stops; and temporal AA keeps the reflection of a
turning mirror as sharp as the picture drawn four times larger and averaged down."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import Material, MeshRef, Mirror, Transform
from engine.assets.mesh import box, plane, quad
from engine.assets.portals import spawn_portal_pair
from engine.core.portal_math import pair_transform
from engine.core.reflection_math import plane_from_point_normal, reflection_matrix, transform_plane
from engine.resources import SurfaceMotion
from tests.support import still_motion
from tests.test_object_motion import SIZE, at, gl_pixel, mirror_scene, streaking_camera, streaks
from tests.test_temporal_aa import SCALE, averaged_down, linear, mirrored_square

TURN = glm.angleAxis(glm.radians(3.0), glm.vec3(0, 1, 0))


def mirror_carry(transform: Transform) -> glm.mat4:
    """The reflection about a quad mirror's plane (its local XY plane, facing +Z)."""
    return reflection_matrix(transform_plane(transform.world, plane_from_point_normal((0, 0, 0), (0, 0, 1))))


def started(scene, build, path: str = "per_mirror"):
    runner = scene(build, SIZE)
    runner.engine.reflection_system.path = path
    runner.engine.renderer.antialias = "off"
    runner.frame()
    runner.frame()
    return runner


@pytest.mark.parametrize("path", ["per_mirror", "batched"])
def test_a_still_box_in_a_turning_mirror_streaks_as_the_mirror_turns_it(scene, path):
    """The mirror turns 3 degrees about its upright: where it shows the box (which stands
    still), the streak is the box's reflection's motion on screen, from last frame's
    reflection to this frame's (about 11 pixels; none without the surface's motion)."""
    ents = {}
    runner = started(scene, lambda world: mirror_scene(world, ents), path)
    transform = runner.world.get(ents["mirror"], Transform)
    before = mirror_carry(transform)
    transform.rotation = TURN * transform.rotation
    runner.frame()
    assert runner.stats.reflection_path == path
    moved = runner.world.resources[SurfaceMotion].before
    assert list(moved) == [ents["mirror"]] and moved[ents["mirror"]] == before
    view_proj = glm.mat4(runner.engine.main_view.view_proj)
    face = runner.world.get(ents["box"], Transform).position - glm.vec3(0.0, 0.0, 0.3)  # the face towards the glass
    pixel = gl_pixel(view_proj, glm.vec3(mirror_carry(transform) * glm.vec4(face, 1.0)))
    assert at(runner.ids(), pixel) == ents["box"]
    expected = pixel - gl_pixel(view_proj, glm.vec3(before * glm.vec4(face, 1.0)))
    assert abs(expected.x) > 8.0
    np.testing.assert_allclose(at(streaks(runner), pixel), expected, rtol=0.03, atol=0.05)


@pytest.mark.parametrize("path", ["per_mirror", "batched"])
def test_a_box_seen_in_a_turning_mirror_seen_in_a_still_one_streaks_as_both_put_it(scene, path):
    """Two mirrors face each other; the one behind the camera turns 2 degrees.  Where the front
    mirror shows the back one showing the box (a second level), the streak is the motion of
    the box's image through both (front x back now, against front x back last frame): the
    second level's composite adds the turn, the first carries it up."""
    ents = {}

    def build(world):
        ents["camera"] = streaking_camera(world, (0.3, 1.5, 1.0), (0.0, 1.5, -3.0))
        ents["front"] = world.spawn(Transform(position=(0, 1.5, -3)), MeshRef(quad(4, 3)),
                                    Material(color=(0.1, 0.1, 0.1)), Mirror())
        ents["back"] = world.spawn(Transform(position=(0, 1.5, 3), rotation=glm.angleAxis(glm.radians(180.0),
                                                                                           glm.vec3(0, 1, 0))),
                                   MeshRef(quad(4, 3)), Material(color=(0.1, 0.1, 0.1)), Mirror())
        world.spawn(Transform(), MeshRef(plane(40, 40)), Material(color=(0.8, 0.8, 0.8)))
        ents["box"] = world.spawn(Transform(position=(-0.8, 1.5, -1.0), scale=(0.4, 0.4, 0.4)), MeshRef(box()),
                                  Material(color=(0.9, 0.1, 0.1)))

    runner = started(scene, build, path)
    front, back = (runner.world.get(ents[name], Transform) for name in ("front", "back"))
    before = mirror_carry(front) * mirror_carry(back)
    back.rotation = glm.angleAxis(glm.radians(2.0), glm.vec3(0, 1, 0)) * back.rotation
    runner.frame()
    view_proj = glm.mat4(runner.engine.main_view.view_proj)
    face = runner.world.get(ents["box"], Transform).position + glm.vec3(0.0, 0.0, 0.2)  # the face the back mirror sees
    pixel = gl_pixel(view_proj, glm.vec3(mirror_carry(front) * mirror_carry(back) * glm.vec4(face, 1.0)))
    assert at(runner.ids(), pixel) == ents["box"]
    expected = pixel - gl_pixel(view_proj, glm.vec3(before * glm.vec4(face, 1.0)))
    assert abs(expected.x) > 2.0
    np.testing.assert_allclose(at(streaks(runner), pixel), expected, rtol=0.03, atol=0.05)


def test_a_still_box_through_a_portal_whose_partner_slides_streaks_as_the_pair_moved(scene):
    """The partner portal slides 0.2 m along x: through the near portal, the box standing
    before the partner moves on screen as the pair's carry moved it (both portals' carries
    changed: each looks out of the other)."""
    ents = {}

    def build(world):
        ents["camera"] = streaking_camera(world, (0.0, 1.5, 4.0), (0.0, 1.5, 0.0))
        ents["near"], ents["far"] = spawn_portal_pair(world, (0, 1.5, 0), None, (8, 1.5, 0), None, size=(3.0, 2.4))
        world.spawn(Transform(), MeshRef(plane(60, 60)), Material(color=(0.6, 0.6, 0.6)))
        ents["box"] = world.spawn(Transform(position=(8.3, 1.5, 2.5), scale=(0.5, 0.5, 0.5)), MeshRef(box()),
                                  Material(color=(0.9, 0.1, 0.1)))

    runner = started(scene, build)
    near, far = (runner.world.get(ents[name], Transform) for name in ("near", "far"))
    before = pair_transform(near.world, far.world)
    far.position += glm.vec3(0.2, 0.0, 0.0)
    runner.frame()
    assert set(runner.world.resources[SurfaceMotion].before) == {ents["near"], ents["far"]}
    view_proj = glm.mat4(runner.engine.main_view.view_proj)
    face = runner.world.get(ents["box"], Transform).position - glm.vec3(0.0, 0.0, 0.25)  # the face towards the portal
    pixel = gl_pixel(view_proj, glm.vec3(glm.inverse(pair_transform(near.world, far.world)) * glm.vec4(face, 1.0)))
    assert at(runner.ids(), pixel) == ents["box"]
    expected = pixel - gl_pixel(view_proj, glm.vec3(glm.inverse(before) * glm.vec4(face, 1.0)))
    assert abs(expected.x) > 3.0
    np.testing.assert_allclose(at(streaks(runner), pixel), expected, rtol=0.03, atol=0.05)


def test_nothing_moves_once_the_mirror_stops(scene):
    """The frame after the mirror stops turning: no surface listed, no motion in the seen image
    (the reflection is composited again without it, not kept from the frame it moved), and the
    picture is the one a runner whose mirror always stood there draws."""
    ents = {}
    runner = started(scene, lambda world: mirror_scene(world, ents))
    transform = runner.world.get(ents["mirror"], Transform)
    transform.rotation = TURN * transform.rotation
    runner.frame()
    assert np.abs(runner.engine.renderer.targets.read_motion()).max() > 1e-3
    stopped = runner.frame()
    assert runner.world.resources[SurfaceMotion].before == {}
    assert still_motion(runner.engine.renderer.targets.read_motion())
    other = {}

    def turned(world):
        mirror_scene(world, other)
        mirror = world.get(other["mirror"], Transform)
        mirror.rotation = TURN * mirror.rotation

    fresh = scene(turned, SIZE)
    fresh.engine.renderer.antialias = "off"
    fresh.frame()
    np.testing.assert_array_equal(stopped, fresh.frame())


@pytest.mark.parametrize("scale", [1.0, 0.5])
def test_temporal_aa_keeps_a_turning_mirrors_reflection_sharp(scene, scale):
    """Sixteen frames of the mirror turning a degree a frame (the square behind the camera
    sweeps across it, about 1.5 pixels a frame): round the square's reflection the resolved
    picture is near the picture drawn four times larger and averaged down (its history
    fetched where the mirror showed each point last frame; by the camera's motion alone the
    square's edges smear: mean error 0.028 / 0.043 at full / half scale, 90th percentile
    0.10 / 0.14)."""
    def run(mode: str, size: tuple[int, int], scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        runner = scene(mirrored_square, size)
        runner.engine.renderer.antialias = mode
        runner.engine.renderer.render_scale = scale
        mirror = next(entity for entity, _ in runner.world.query_one(Mirror))
        square = max(entity for entity, (_, material) in runner.world.query(MeshRef, Material)
                     if material.color[0] == 1.0)
        runner.frame()
        for _ in range(16):
            transform = runner.world.get(mirror, Transform)
            transform.rotation = glm.angleAxis(glm.radians(1.0), glm.vec3(0, 1, 0)) * transform.rotation
            picture = runner.frame()
        return picture, runner.ids() == square

    large, square = run("off", (SIZE_AA[0] * SCALE, SIZE_AA[1] * SCALE))
    reference = averaged_down(large)
    covered = np.pad(square.reshape(SIZE_AA[1], SCALE, SIZE_AA[0], SCALE).any(axis=(1, 3)), 2)
    near = np.zeros(reference.shape[:2], bool)   # the square's pixels and two round them
    for dy in range(5):
        for dx in range(5):
            near |= covered[dy: dy + near.shape[0], dx: dx + near.shape[1]]
    assert 150 < near.sum() < 600
    error = np.abs(linear(run("taa", SIZE_AA, scale)[0]) - reference).max(axis=2)[near]
    limits = {1.0: (0.018, 0.05), 0.5: (0.03, 0.1)}[scale]
    assert error.mean() < limits[0] and np.percentile(error, 90) < limits[1], (error.mean(), np.percentile(error, 90))


SIZE_AA = (96, 72)   # test_temporal_aa's


def test_every_composite_build_has_a_surface_motion_build(scene):
    """Each composite variant's ``SURFACE_MOTION`` build, with fog and without, builds and reads
    the two matrices (the sample scenes above reach only some of them)."""
    from engine.render.mirror_passes import COMPOSITE_VARIANTS

    runner = started(scene, lambda world: mirror_scene(world, {}))
    passes = runner.engine.reflection_system.tree.passes
    for fogging in ((), (("FOG", "1"),)):
        for variant in COMPOSITE_VARIANTS:
            program = passes._moving_draw(fogging, variant).program
            assert "parent_view_proj" in program and "moved_view_proj" in program, (variant, fogging)
