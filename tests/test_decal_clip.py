"""A decal's cut (``engine/core/decal_clip.py``): triangles cut to the box against a second
path (the share of a fine grid of points inside both the triangle and the box's square),
every piece inside the box with its winding kept, attributes interpolated as the source
triangle's barycentric blend of them, the fades (angle, depth) and the image's region."""
from __future__ import annotations

import math

import numpy as np
import pytest

from engine.core.decal_clip import angle_fade, clip_plane, clip_to_box, decal_geometry, soup


def flat_soup(points: np.ndarray, z: float = 0.0, facing: float = 1.0) -> np.ndarray:
    """Triangles (T, 3, 2) in the plane z, normal +z, all facing the decal by ``facing``."""
    count = len(points)
    positions = np.concatenate([points.reshape(-1, 2), np.full((count * 3, 1), z)], axis=1)
    normals = np.tile((0.0, 0.0, 1.0), (count * 3, 1))
    return soup(positions, normals, np.full(count * 3, facing), np.arange(count * 3).reshape(-1, 3))


def area(triangles: np.ndarray) -> float:
    p = triangles[:, :, :3]
    return float(0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum())


def turn(triangles: np.ndarray) -> np.ndarray:
    """Twice each 2D triangle's signed area (> 0: counter-clockwise)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])


def grid_area(triangle: np.ndarray, n: int = 600) -> float:
    """The area of ``triangle`` (3, 2) inside the square [-0.5, 0.5]^2 by counting grid points
    (a second path: no clipping)."""
    lo = np.minimum(triangle.min(axis=0), -0.5)
    hi = np.maximum(triangle.max(axis=0), 0.5)
    xs = np.linspace(lo[0], hi[0], n, endpoint=False) + (hi[0] - lo[0]) / (2 * n)
    ys = np.linspace(lo[1], hi[1], n, endpoint=False) + (hi[1] - lo[1]) / (2 * n)
    x, y = np.meshgrid(xs, ys)
    a, b, c = triangle

    def side(p, q):
        return (q[0] - p[0]) * (y - p[1]) - (q[1] - p[1]) * (x - p[0])

    s1, s2, s3 = side(a, b), side(b, c), side(c, a)
    inside = ((s1 >= 0) & (s2 >= 0) & (s3 >= 0)) | ((s1 <= 0) & (s2 <= 0) & (s3 <= 0))
    inside &= (np.abs(x) <= 0.5) & (np.abs(y) <= 0.5)
    return float(inside.sum() * (hi[0] - lo[0]) * (hi[1] - lo[1]) / n ** 2)


def test_a_quad_covering_the_box_is_cut_to_its_square():
    quad = np.array([[[-3, -2], [4, -2], [4, 3]], [[-3, -2], [4, 3], [-3, 3]]], float)
    cut = clip_to_box(flat_soup(quad))
    assert area(cut) == pytest.approx(1.0, abs=1e-12)
    assert np.abs(cut[:, :, :3]).max() <= 0.5 + 1e-12


def test_random_triangles_cut_as_the_grid_counts_them_inside_and_wound_as_before():
    rng = np.random.default_rng(7)
    for _ in range(40):
        triangle = rng.uniform(-1.2, 1.2, (1, 3, 2))
        cut = clip_to_box(flat_soup(triangle))
        expected = grid_area(triangle[0])
        assert area(cut) == pytest.approx(expected, abs=0.01), triangle
        if len(cut):
            assert np.abs(cut[:, :, :3]).max() <= 0.5 + 1e-9
            source_turn = np.sign(turn(triangle)[0])
            turns = turn(cut[:, :, :2])
            big = np.abs(turns) > 1e-9
            assert (np.sign(turns[big]) == source_turn).all()  # each piece wound as its triangle


def test_attributes_are_the_source_triangles_barycentric_blend():
    rng = np.random.default_rng(3)
    corners = rng.uniform(-1.0, 1.0, (3, 3))
    corners -= corners.mean(axis=0)  # through the box's middle: cut on several sides
    normals = rng.normal(size=(3, 3))
    facing = rng.uniform(0.2, 1.0, 3)
    triangles = soup(corners, normals, facing, np.array([[0, 1, 2]]))
    cut = clip_to_box(triangles)
    assert len(cut)
    # Solve each output vertex's barycentric weights from its position, then compare its other attributes.
    basis = np.stack([corners[1] - corners[0], corners[2] - corners[0]], axis=1)
    for vertex in cut.reshape(-1, 7):
        uv, *_ = np.linalg.lstsq(basis, vertex[:3] - corners[0], rcond=None)
        weights = np.array([1 - uv.sum(), uv[0], uv[1]])
        assert vertex[3:6] == pytest.approx(weights @ normals, abs=1e-9)
        assert vertex[6] == pytest.approx(weights @ facing, abs=1e-9)


def test_one_plane_keeps_the_side_asked_for():
    triangle = flat_soup(np.array([[[-1.0, -1.0], [1.0, -1.0], [0.0, 1.0]]]))
    left = clip_plane(triangle, 0, 1.0, 0.0)   # x <= 0
    right = clip_plane(triangle, 0, -1.0, 0.0)  # x >= 0
    assert left[:, :, 0].max() <= 1e-12 and right[:, :, 0].min() >= -1e-12
    assert area(left) + area(right) == pytest.approx(area(triangle))


def test_the_depth_fade_splits_at_its_planes_and_falls_linearly_to_the_ends():
    # A triangle standing up through the box (in the x-z plane, facing the decal by 1).
    positions = np.array([[-0.4, 0.0, -0.9], [0.4, 0.0, -0.9], [0.0, 0.0, 0.9]])
    triangles = soup(positions, np.tile((0.0, 0.0, 1.0), (3, 1)), np.ones(3), np.array([[0, 1, 2]]))
    geometry = decal_geometry(triangles, (60.0, 80.0), 0.2, (0.0, 0.0, 1.0, 1.0))
    z = geometry.positions[:, 2]
    expected = np.clip((0.5 - np.abs(z)) / 0.2, 0.0, 1.0)
    assert geometry.alphas == pytest.approx(expected, abs=1e-6)
    for plane in (0.3, -0.3):  # the fade's inner planes are edges of the pieces
        assert np.isclose(z, plane, atol=1e-6).any()
    assert np.abs(z).max() <= 0.5 + 1e-6


def test_the_angle_fade_by_the_angle_between_the_surface_and_the_decal():
    angles = np.array([0.0, 30.0, 60.0, 65.0, 70.0, 79.0, 80.0, 85.0])
    faded = angle_fade(np.cos(np.radians(angles)), 60.0, 80.0)
    assert faded == pytest.approx(np.clip((80.0 - angles) / 20.0, 0.0, 1.0), abs=1e-9)
    # A surface turned away past the end takes nothing: no geometry at all.
    turned = flat_soup(np.array([[[-0.3, -0.3], [0.3, -0.3], [0.0, 0.3]]]), facing=math.cos(math.radians(85.0)))
    assert decal_geometry(turned, (60.0, 80.0), 0.0, (0.0, 0.0, 1.0, 1.0)) is None
    facing = flat_soup(np.array([[[-0.3, -0.3], [0.3, -0.3], [0.0, 0.3]]]), facing=math.cos(math.radians(70.0)))
    geometry = decal_geometry(facing, (60.0, 80.0), 0.0, (0.0, 0.0, 1.0, 1.0))
    assert geometry.alphas == pytest.approx(0.5, abs=1e-6)


def test_uvs_map_the_box_square_onto_the_region():
    square = np.array([[[-2, -2], [2, -2], [2, 2]], [[-2, -2], [2, 2], [-2, 2]]], float)
    geometry = decal_geometry(flat_soup(square), (60.0, 80.0), 0.0, (0.25, 0.5, 0.75, 1.0))
    x, y = geometry.positions[:, 0], geometry.positions[:, 1]
    assert geometry.uvs[:, 0] == pytest.approx(0.25 + (x + 0.5) * 0.5, abs=1e-6)
    assert geometry.uvs[:, 1] == pytest.approx(0.5 + (y + 0.5) * 0.5, abs=1e-6)
    assert geometry.triangle_count == len(geometry.positions) // 3 >= 2
    assert np.linalg.norm(geometry.normals, axis=1) == pytest.approx(1.0, abs=1e-6)


def test_nothing_in_the_box_is_none():
    far = flat_soup(np.array([[[3.0, 3.0], [4.0, 3.0], [3.0, 4.0]]]))
    assert decal_geometry(far, (60.0, 80.0), 0.1, (0.0, 0.0, 1.0, 1.0)) is None
    beside = flat_soup(np.array([[[-0.3, -0.3], [0.3, -0.3], [0.0, 0.3]]]), z=0.7)  # above the box
    assert decal_geometry(beside, (60.0, 80.0), 0.1, (0.0, 0.0, 1.0, 1.0)) is None
