"""engine.rules.raycast against hits worked out by hand (planes of boxes and quads, a sphere's
distance), its filters, and its cache following moves, mesh swaps and deletions."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import Material, MeshRef, Transform, yaw_pitch_rotation
from engine.assets.mesh import box, quad, sphere
from engine.core.world import World
from engine.rules.raycast import RayCaster, RayCastError, raycast
from systems.transform_system import TransformSystem


@pytest.fixture
def world():
    w = World("raycast")
    w.add_system(TransformSystem(w), priority=1)
    yield w
    w.close()


def _close(a, b, tol=1e-5) -> bool:
    return float(glm.length(glm.vec3(a) - glm.vec3(b))) <= tol


def test_box_face_hit_point_normal_and_distance(world):
    # A 2 m box centred at z=-5: its +Z face is the plane z=-4, 4 m down -Z from the origin.
    crate = world.spawn(Transform(position=(0, 0, -5)), MeshRef(box((2, 2, 2))), Material())
    world.step(1 / 60)
    hit = raycast(world, (0.3, 0.2, 0), (0, 0, -1))
    assert hit is not None and hit.entity == crate
    assert hit.distance == pytest.approx(4.0, abs=1e-9)
    assert _close(hit.point, (0.3, 0.2, -4.0))
    assert _close(hit.normal, (0, 0, 1)) and hit.front
    # Obliquely: from (0, 0, 0) toward (1, 0, -4): the face z=-4 at x=1 (inside |x| <= 1), distance sqrt(17).
    hit = raycast(world, (0, 0, 0), (1, 0, -4))
    assert hit.distance == pytest.approx(math.sqrt(17.0), abs=1e-9) and _close(hit.point, (1, 0, -4))
    # From the side, along +X from x=-10: the face x=-1, normal -X.
    hit = raycast(world, (-10, 0.5, -5.5), (3, 0, 0))  # the direction's length does not matter
    assert hit.distance == pytest.approx(9.0) and _close(hit.normal, (-1, 0, 0))
    # Past the box's edge (|x| > 1 at z=-4 and beyond): no hit.
    assert raycast(world, (0, 0, 0), (1.2, 0, -4)) is None
    assert raycast(world, (0, 0, 0), (0, 0, 1)) is None  # behind the origin


def test_turned_and_scaled_quad_and_its_back(world):
    # A 1x1 quad faces its local +Z; yaw 90 turns +Z to +X; scale 4 makes it 4x4; at (3, 1, 0).
    wall = world.spawn(Transform(position=(3, 1, 0), rotation=yaw_pitch_rotation(90, 0), scale=(4, 4, 4)),
                       MeshRef(quad(1, 1)), Material())
    world.step(1 / 60)
    # From x=10 looking -X: hits the front at x=3 (distance 7), normal +X.
    hit = raycast(world, (10, 2.5, 1.5), (-1, 0, 0))
    assert hit.entity == wall and hit.distance == pytest.approx(7.0) and hit.front
    assert _close(hit.point, (3, 2.5, 1.5)) and _close(hit.normal, (1, 0, 0))
    # From x=0 looking +X: the back side; the normal still faces the ray's origin.
    hit = raycast(world, (0, 1, 0), (1, 0, 0))
    assert hit.distance == pytest.approx(3.0) and not hit.front and _close(hit.normal, (-1, 0, 0))
    assert raycast(world, (0, 1, 0), (1, 0, 0), two_sided=False) is None  # culled from behind
    # Outside the 4x4 square (z = 2.1 > 2): miss.
    assert raycast(world, (10, 1, 2.1), (-1, 0, 0)) is None


def test_sphere_distance_within_its_tessellation(world):
    ball = world.spawn(Transform(position=(0, 0, -5)), MeshRef(sphere(0.5, segments=48, rings=24)), Material())
    world.step(1 / 60)
    hit = raycast(world, (0, 0, 0), (0, 0, -1))
    # The facets lie inside the true sphere by at most r (1 - cos(pi / rings)) at the equator.
    assert hit.entity == ball
    assert 4.5 - 1e-6 <= hit.distance <= 4.5 + 0.5 * (1 - math.cos(math.pi / 24)) + 1e-6
    assert float(glm.dot(hit.normal, glm.vec3(0, 0, 1))) > 0.99


def test_nearest_of_several_filters_and_max_distance(world):
    near = world.spawn(Transform(position=(0, 0, -3)), MeshRef(box((1, 1, 1))), Material())
    far = world.spawn(Transform(position=(0, 0, -8)), MeshRef(box((1, 1, 1))), Material())
    world.step(1 / 60)
    assert raycast(world, (0, 0, 0), (0, 0, -1)).entity == near
    hit = raycast(world, (0, 0, 0), (0, 0, -1), ignore={near})
    assert hit.entity == far and hit.distance == pytest.approx(7.5)
    assert raycast(world, (0, 0, 0), (0, 0, -1), where=lambda e: e != near).entity == far
    assert raycast(world, (0, 0, 0), (0, 0, -1), max_distance=2.4) is None
    assert raycast(world, (0, 0, 0), (0, 0, -1), max_distance=2.5).distance == pytest.approx(2.5)
    assert raycast(world, (0, 0, 0), (0, 0, -1), where=lambda e: False) is None


def test_cache_follows_moves_mesh_swaps_parents_and_deletion(world):
    caster = RayCaster(world)
    parent = world.spawn(Transform(position=(0, 0, -5)))
    child = world.spawn(Transform(position=(0, 0, 0), parent=parent), MeshRef(box((2, 2, 2))), Material())
    world.step(1 / 60)
    assert caster.cast((0, 0, 0), (0, 0, -1)).distance == pytest.approx(4.0)
    built = caster.rebuilds
    for _ in range(3):  # nothing moved: no triangles recomputed
        caster.cast((0, 0, 0), (0, 0, -1))
        world.step(1 / 60)
    assert caster.rebuilds == built
    # Written this frame, before the transform stage ran: the ray sees the new pose already.
    world.get(child, Transform).position = (0, 0, 2)
    assert caster.cast((0, 0, 0), (0, 0, -1)).distance == pytest.approx(2.0)
    world.step(1 / 60)
    # Moving the parent moves the child's triangles (after and before the transform stage).
    world.get(parent, Transform).position = (0, 0, -10)
    assert caster.cast((0, 0, 0), (0, 0, -1)).distance == pytest.approx(7.0)
    world.step(1 / 60)
    assert caster.cast((0, 0, 0), (0, 0, -1)).distance == pytest.approx(7.0)  # cached from the stepped matrix
    # Moved and stepped over several frames unasked: the new matrix object still invalidates the entry.
    world.get(parent, Transform).position = (0, 0, -20)
    world.step(1 / 60)
    world.step(1 / 60)
    assert caster.cast((0, 0, 0), (0, 0, -1)).distance == pytest.approx(17.0)
    # A new mesh on the same entity.
    world.get(child, MeshRef).mesh = box((6, 6, 6))
    assert caster.cast((0, 0, 0), (0, 0, -1)).distance == pytest.approx(15.0)
    tris = caster.triangles(child)
    assert tris.shape == (12, 3, 3) and np.isclose(tris[..., 2].max(), -15.0)
    world.delete_entity(child)
    assert caster.cast((0, 0, 0), (0, 0, -1)) is None
    world.step(1 / 60)
    assert caster.cast((0, 0, 0), (0, 0, -1)) is None


def test_against_a_plain_per_triangle_reference(world):
    # Random triangles; each ray's nearest hit from a scalar line-plane-inside test, triangle by triangle.
    rng = np.random.default_rng(7)
    from engine.assets.mesh import Mesh

    soup = rng.uniform(-2, 2, (40, 3, 3))
    positions = soup.reshape(-1, 3)
    mesh = Mesh(positions, np.tile((0, 0, 1), (len(positions), 1)), np.zeros((len(positions), 2)),
                np.arange(len(positions)).reshape(-1, 3))
    entity = world.spawn(Transform(position=(0.5, -0.25, 0)), MeshRef(mesh), Material())
    world.step(1 / 60)
    tris = soup + np.array([0.5, -0.25, 0.0])
    hits = 0
    for _ in range(60):
        o = rng.uniform(-4, 4, 3)
        d = rng.uniform(-1, 1, 3)
        d /= np.linalg.norm(d)
        expected = None
        for a, b, c in tris:
            n = np.cross(b - a, c - a)
            denom = n @ d
            if abs(denom) < 1e-12:
                continue
            t = n @ (a - o) / denom
            if t < 0:
                continue
            x = o + t * d
            # inside: the point is on the same side of all three edges as the normal says
            if all(np.cross(q - p, x - p) @ n >= 0 for p, q in ((a, b), (b, c), (c, a))):
                expected = t if expected is None else min(expected, t)
        hit = raycast(world, o, d)
        if expected is None:
            assert hit is None
        else:
            hits += 1
            assert hit is not None and hit.entity == entity and hit.distance == pytest.approx(expected, abs=1e-6)
    assert hits >= 5


@pytest.mark.parametrize("origin, direction, word", [
    ((0, 0, 0), (0, 0, 0), "direction"),
    ((0, float("nan"), 0), (0, 0, -1), "origin"),
    ((0, 0, 0), (1, 2), "direction"),
    ("abc", (0, 0, -1), "origin"),
])
def test_bad_rays_are_refused_by_name(world, origin, direction, word):
    with pytest.raises(RayCastError, match=word):
        raycast(world, origin, direction)
