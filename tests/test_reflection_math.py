"""Reflection and oblique-projection math against independent derivations."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from engine.core.reflection_math import (
    MIRROR_X,
    mirrored_view,
    oblique_projection,
    plane_from_point_normal,
    reflect_camera,
    reflection_matrix,
    transform_plane,
)

rng = np.random.default_rng(7)
PLANES = [plane_from_point_normal(rng.normal(size=3), rng.normal(size=3)) for _ in range(5)]


@pytest.mark.parametrize("plane", PLANES)
def test_reflection_matrix_mirrors_points(plane):
    n = np.array(glm.vec3(plane))
    for x in rng.normal(size=(10, 3)) * 5:
        expected = x - 2 * (n @ x + plane.w) * n  # the textbook point reflection
        got = glm.vec3(reflection_matrix(plane) * glm.vec4(*x, 1.0))
        np.testing.assert_allclose(got, expected, atol=1e-4)


@pytest.mark.parametrize("plane", PLANES)
def test_reflecting_a_view_twice_gives_the_original(plane):
    view = glm.lookAt(glm.vec3(3, 2, 5), glm.vec3(0, 0.5, 0), glm.vec3(0, 1, 0))
    twice = mirrored_view(mirrored_view(view, plane), plane)
    np.testing.assert_allclose(np.array(twice.to_list()), np.array(view.to_list()), atol=1e-4)
    eye, fwd, up = glm.vec3(3, 2, 5), glm.normalize(glm.vec3(-3, -1.5, -5)), glm.vec3(0, 1, 0)
    back = reflect_camera(*reflect_camera(eye, fwd, up, plane), plane)
    for a, b in zip(back, (eye, fwd, up), strict=True):
        np.testing.assert_allclose(a, b, atol=1e-4)


@pytest.mark.parametrize("plane", PLANES)
def test_mirrored_view_is_the_reflected_look_at_camera_with_image_swapped(plane):
    """The other way to build a mirror's camera: reflect the eye, the look-at target and the
    up vector about the plane and look from there (a camera of the mirrored scene, not a
    mirrored camera); mirrored_view equals it with the image's x flipped."""
    eye = glm.vec3(1, 2, 6)
    fwd = glm.normalize(glm.vec3(-0.2, -0.3, -1))
    up = glm.normalize(glm.cross(glm.cross(fwd, glm.vec3(0, 1, 0)), fwd))
    view = glm.lookAt(eye, eye + fwd, up)
    r_eye, r_fwd, r_up = reflect_camera(eye, fwd, up, plane)
    reflected_look_at = glm.lookAt(r_eye, r_eye + r_fwd, r_up)
    np.testing.assert_allclose(np.array(mirrored_view(view, plane).to_list()),
                               np.array((MIRROR_X * reflected_look_at).to_list()), atol=1e-4)
    # The reflected eye is the mirror image of the eye; forward and up are reflected vectors.
    n = np.array(glm.vec3(plane))
    np.testing.assert_allclose(r_eye, np.array(eye) - 2 * (n @ np.array(eye) + plane.w) * n, atol=1e-5)


def _setup():
    proj = glm.perspective(glm.radians(60.0), 16 / 9, 0.1, 100.0)
    view = glm.lookAt(glm.vec3(0.5, 1.5, 6), glm.vec3(0, 1, 0), glm.vec3(0, 1, 0))
    mirror = plane_from_point_normal((0.2, 1.0, 0.0), (0.1, 0.05, 1.0))
    mview = mirrored_view(view, mirror)
    view_plane = transform_plane(mview, mirror)
    return proj, mview, mirror, view_plane


def test_oblique_projection_puts_the_mirror_plane_at_the_near_plane():
    proj, mview, mirror, view_plane = _setup()
    assert view_plane.w < 0  # the virtual eye is behind the mirror plane
    oblique = oblique_projection(proj, view_plane)
    n = glm.vec3(mirror)
    tangent = glm.normalize(glm.cross(n, glm.vec3(0, 1, 0)))
    bitangent = glm.cross(n, tangent)
    origin = -mirror.w * n
    for u, v in rng.uniform(-1.5, 1.5, size=(12, 2)):
        p = origin + tangent * float(u) + bitangent * float(v)
        clip = oblique * mview * glm.vec4(p, 1.0)
        assert clip.z / clip.w == pytest.approx(-1.0, abs=1e-3)


def test_oblique_projection_keeps_rows_1_2_4_and_clips_behind_the_mirror():
    proj, mview, mirror, view_plane = _setup()
    oblique = oblique_projection(proj, view_plane)
    for col in range(4):
        for row in (0, 1, 3):
            assert oblique[col][row] == pytest.approx(proj[col][row])
    n = glm.vec3(mirror)
    origin = -mirror.w * n
    in_front = glm.vec4(origin + n * 0.5, 1.0)   # the camera's side: visible in the mirror
    behind = glm.vec4(origin - n * 0.5, 1.0)     # behind the mirror: must be clipped
    cf = oblique * mview * in_front
    cb = oblique * mview * behind
    assert cf.z >= -cf.w and cb.z < -cb.w
