"""Cookies on all-round lights (``PointLight(spot_angle=180, cookie=...)``): the image wrapped
about the light as a panorama (longitude across, latitude up, its middle ahead of the light).
A lamp in front of a white wall, turned or not, lights each pixel of the wall with the colour
of the cell its direction from the lamp falls in, worked out here with numpy (the rays cast
at the wall, the direction put in the lamp's frame, longitude and latitude taken); and the
same through a mirror that reflects light, whose image of the lamp wraps the picture the
other way round."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import Material, MeshRef, Mirror, PointLight, Transform, look_rotation
from engine.assets.mesh import quad
from engine.assets.texture_data import TextureData
from tests.support import look_from, pixel_rays, srgb_to_linear
from tests.test_spot_cookies import dark_sky, matte

SIZE = (200, 150)
# 8 columns of longitude x 2 rows of latitude, the colours the lit wall shows
CELLS = np.array([[(255, 0, 0), (0, 255, 0), (0, 0, 255), (255, 255, 255)] * 2,
                  [(0, 0, 255), (255, 255, 255), (255, 0, 0), (0, 255, 0)] * 2], np.uint8)
COLOURS = np.array([(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 1)], np.float64) / np.sqrt([1, 1, 1, 3])[:, None]


def panorama(scale: int = 16) -> TextureData:
    pixels = np.repeat(np.repeat(CELLS, scale, axis=0), scale, axis=1)
    return TextureData(np.ascontiguousarray(pixels), name="panorama")


def expected_cells(points: np.ndarray, lamp: np.ndarray, frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The cell each point's direction from the lamp falls in (its colour's index in COLOURS)
    and whether it is clear of the cells' edges; ``frame``: the lamp's right, top, forward."""
    d = points - lamp
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    right, up, forward = frame
    u = 0.5 + np.arctan2(d @ right, d @ forward) / (2.0 * math.pi)
    v = 0.5 + np.arcsin(np.clip(d @ up, -1.0, 1.0)) / math.pi   # up from the image's bottom
    column = np.floor(u * 8).astype(int) % 8
    row = np.where(v >= 0.5, 0, 1)   # row 0 of the image is its top
    colours = {tuple(c): i for i, c in enumerate([(255, 0, 0), (0, 255, 0), (0, 0, 255), (255, 255, 255)])}
    index = np.array([colours[tuple(CELLS[r, c])] for r, c in zip(row, column, strict=True)])
    clear = (np.abs(u * 8 - np.round(u * 8)) > 0.08) & (np.abs(v - 0.5) > 0.03)
    return index, clear


def seen_cells(frame: np.ndarray) -> np.ndarray:
    rgb = frame.reshape(-1, 3).astype(np.float64)
    rgb /= np.maximum(np.linalg.norm(rgb, axis=1, keepdims=True), 1e-9)
    return np.argmax(rgb @ COLOURS.T, axis=1)


def wall_frame(scene, build) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``build``'s second frame (FXAA off) as linear RGB a pixel, where each pixel's ray meets
    the wall's plane (z = 0), and whether that is on the wall."""
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    frame = srgb_to_linear(runner.frame())
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    rays = rays.reshape(-1, 3)
    points = eye + (-eye[2] / rays[:, 2])[:, None] * rays
    return frame, points, (np.abs(points[:, 0]) < 4.4) & (np.abs(points[:, 1]) < 3.4)


@pytest.mark.parametrize("yaw", [0.0, 30.0, 180.0])
def test_an_all_round_lights_cookie_is_wrapped_about_it(scene, yaw):
    lamp = np.array([0.3, 0.2, 2.0])
    turn = glm.angleAxis(math.radians(yaw), glm.vec3(0.0, 1.0, 0.0))

    def build(world):
        look_from(world, (0.0, 0.0, 6.0), (0.0, 0.0, 0.0))
        world.spawn(dark_sky())
        world.spawn(Transform(), MeshRef(quad(9.0, 7.0)), matte())
        world.spawn(Transform(position=tuple(lamp), rotation=turn),
                    PointLight(intensity=8.0, range=30.0, cookie=panorama()))
    frame, points, on_wall = wall_frame(scene, build)
    m = np.array(glm.mat3_cast(turn).to_list(), np.float64).T   # its columns: right, top, back
    index, clear = expected_cells(points, lamp, (m[:, 0], m[:, 1], -m[:, 2]))
    bright = frame.reshape(-1, 3).max(axis=1) > 0.02
    judged = on_wall & clear & bright
    assert judged.sum() > 5000
    assert len(set(index[judged].tolist())) == 4   # every colour lands somewhere on the wall
    agree = seen_cells(frame)[judged] == index[judged]
    assert agree.mean() > 0.98, agree.mean()


def test_a_mirror_carries_an_all_round_cookie_the_other_way_round(scene):
    """A lamp behind the wall's plane and left of it (its light never reaches the wall's
    front, and passes the wall on its way to the mirror) faces a mirror across the room that
    reflects light: the wall is lit by the lamp's image behind the mirror, whose frame the
    mirror turned inside out (its forward +z where the lamp's is -z, its right and top as the
    lamp's).  Each pixel shows the cell of the lamp's own picture the ray from the image,
    mirrored back, falls in (the panorama's back: with the forward left unturned it would be
    its front, other colours)."""
    lamp = np.array([-6.0, 0.2, -1.0])

    def build(world):
        look_from(world, (0.0, 0.0, 3.5), (0.0, 0.0, 0.0))
        world.spawn(dark_sky())
        world.spawn(Transform(), MeshRef(quad(9.0, 7.0)), matte())
        world.spawn(Transform(position=(0.0, 0.0, 4.0), rotation=look_rotation(glm.vec3(0.0, 0.0, 1.0))),
                    MeshRef(quad(14.0, 12.0)), Material(), Mirror(reflects_light=True))   # its front to -z
        world.spawn(Transform(position=tuple(lamp)), PointLight(intensity=150.0, range=40.0, cookie=panorama()))
    frame, points, on_wall = wall_frame(scene, build)
    image = np.array([lamp[0], lamp[1], 8.0 - lamp[2]])
    index, clear = expected_cells(points, image, (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]),
                                                  np.array([0.0, 0.0, 1.0])))
    bright = frame.reshape(-1, 3).max(axis=1) > 0.02
    judged = on_wall & clear & bright
    assert judged.sum() > 5000 and len(set(index[judged].tolist())) >= 2
    agree = seen_cells(frame)[judged] == index[judged]
    assert agree.mean() > 0.97, agree.mean()


def test_a_portal_carries_an_all_round_cookie_turned_not_mirrored(scene):
    """A lamp turned 30 degrees before portal A (which carries light) shines out of B onto a
    wall beyond it, the wall's back to the lamp itself.  Each lit pixel shows the cell of the
    lamp's picture that the ray from the lamp's image (the lamp carried by the pair's
    transform, its frame turned with it) to the wall point falls in, for points whose line to
    the image crosses B's opening; the frame turned inside out (as a mirror's) names other
    cells on a share of them."""
    from components import Portal
    from engine.assets.portals import spawn_portal_pair
    from engine.core.portal_math import pair_transform

    lamp = np.array([0.2, 1.5, 5.5])
    turn = glm.angleAxis(math.radians(30.0), glm.vec3(0.0, 1.0, 0.0))
    names = {}

    def build(world):
        look_from(world, (-5.0, 1.5, 3.0), (-2.0, 1.5, 0.0), fov=70.0)
        world.spawn(dark_sky())
        world.spawn(Transform(position=(-2.0, 1.5, 0.0), rotation=glm.angleAxis(glm.radians(-90.0), glm.vec3(0, 1, 0))),
                    MeshRef(quad(8.0, 6.0)), matte())
        world.spawn(Transform(position=tuple(lamp), rotation=turn), PointLight(intensity=60.0, range=30.0,
                                                                              cookie=panorama()))
        names["a"], names["b"] = spawn_portal_pair(world, (0.0, 1.5, 4.0), None, (-6.0, 1.5, 0.0),
                                                   look_rotation(glm.vec3(-1, 0, 0)), size=(3.0, 3.0))
        world.get(names["a"], Portal).carries_light = True
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    frame = srgb_to_linear(runner.frame())
    assert runner.engine.renderer.stats.virtual_lights == 1
    world = runner.engine.world
    carry = np.array(glm.dmat4(pair_transform(world.get(names["a"], Transform).world,
                                              world.get(names["b"], Transform).world)).to_list(), np.float64).T
    image = carry[:3, :3] @ lamp + carry[:3, 3]
    m = carry[:3, :3] @ np.array(glm.mat3_cast(turn).to_list(), np.float64).T   # the image's right, top, back
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    rays = rays.reshape(-1, 3)
    t = (-2.0 - eye[0]) / rays[:, 0]
    wall = eye + rays * t[:, None]
    towards = image - wall
    crossing = wall + towards * ((-6.0 - wall[:, 0]) / towards[:, 0])[:, None]   # on B's plane
    through = (t > 0) & (np.abs(crossing[:, 1] - 1.5) < 1.4) & (np.abs(crossing[:, 2]) < 1.4) \
        & (np.abs(wall[:, 1] - 1.5) < 2.9) & (np.abs(wall[:, 2]) < 3.9)
    index, clear = expected_cells(wall, image, (m[:, 0], m[:, 1], -m[:, 2]))
    bright = frame.reshape(-1, 3).max(axis=1) > 0.02
    judged = through & clear & bright
    assert judged.sum() > 3000 and len(set(index[judged].tolist())) >= 2, judged.sum()
    agree = seen_cells(frame)[judged] == index[judged]
    assert agree.mean() > 0.97, agree.mean()
    mirrored, _ = expected_cells(wall, image, (m[:, 0], m[:, 1], m[:, 2]))
    assert (mirrored[judged] != index[judged]).mean() > 0.3
