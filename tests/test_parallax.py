"""Parallax occlusion mapping (``Material.parallax_depth``): the normal map's alpha a height
map, each pixel's view ray marched into it.  The reference is the heights ray-cast in numpy,
apart from the engine: each floor pixel's ray continued below the floor in 1,000 steps until
it is under the heights (the texture read as GL filters it, bilinear between texel centres),
the colour the albedo there."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from components import ComponentValueError, Material, MeshRef, Skybox, Transform
from engine.assets.mesh import plane
from engine.assets.texture_data import TextureData
from tests.support import look_from, pixel_rays, srgb_to_linear

SIZE = (160, 120)
TEXELS = 64
STRIPES = 8          # across the texture along v: raised, sunk, ...
DEPTH = 0.1          # metres
FLOOR = 2.0          # the plane's side: one texture across it


def stripes() -> tuple[np.ndarray, np.ndarray]:
    """The normal map (flat normals, alpha the heights: 1 on the raised stripes, 0 on the
    sunk ones) and the albedo (red raised, blue sunk), rows top first, stripes along v."""
    v = 1.0 - (np.arange(TEXELS) + 0.5) / TEXELS          # row 0 at the top: v near 1
    raised = np.floor(v * STRIPES) % 2 == 0
    normal = np.zeros((TEXELS, TEXELS, 4), np.uint8)
    normal[..., :3] = (128, 128, 255)
    normal[..., 3] = np.where(raised, 255, 0)[:, None]
    albedo = np.zeros((TEXELS, TEXELS, 4), np.uint8)
    albedo[..., 3] = 255
    albedo[..., 0] = np.where(raised, 255, 0)[:, None]
    albedo[..., 2] = np.where(raised, 0, 255)[:, None]
    return normal, albedo


def bilinear_v(values: np.ndarray, v: np.ndarray) -> np.ndarray:
    """A column of texels (row 0 at the top) read at ``v`` by GL's bilinear filtering with
    repeat (v = 0 the bottom row)."""
    column = values[::-1].astype(np.float64)               # GL's rows: v = 0 first
    at = v * TEXELS - 0.5
    low = np.floor(at)
    f = at - low
    return column[low.astype(int) % TEXELS] * (1.0 - f) + column[(low.astype(int) + 1) % TEXELS] * f


def floor_frame(scene, depth: float):
    """The floor's pixels (unlit: each shows its albedo as it is) as linear red, their rays'
    hits on the floor and the rays."""
    normal, albedo = stripes()

    def build(world):
        look_from(world, (0.0, 1.2, 2.0), (0.0, 0.0, 0.0), fov=50.0)
        world.spawn(Skybox(faces=np.full((6, 4, 4, 3), 0.5, np.float32)))
        world.spawn(Transform(), MeshRef(plane(FLOOR, FLOOR)),
                    Material(color=(1.0, 1.0, 1.0, 1.0), texture=TextureData(albedo, name="stripes"),
                             normal_map=TextureData(normal, name="heights"), parallax_depth=depth, unlit=True))
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    shown = srgb_to_linear(runner.frame())[..., 0].reshape(-1)
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    rays = rays.reshape(-1, 3)
    t = -eye[1] / rays[:, 1]
    hits = eye + rays * t[:, None]
    on = (t > 0) & (np.abs(hits[:, 0]) < 0.8 * FLOOR / 2) & (np.abs(hits[:, 2]) < 0.8 * FLOOR / 2)
    return shown[on], hits[on], rays[on]


def uv_v(points: np.ndarray) -> np.ndarray:
    """The plane's v at world points (its mesh's UVs: v = 0 at its +z edge, found from them)."""
    mesh = plane(FLOOR, FLOOR)
    z, v = mesh.positions[:, 2].astype(np.float64), mesh.uvs[:, 1].astype(np.float64)
    slope = (v.max() - v.min()) / (z[np.argmax(v)] - z[np.argmin(v)])
    return v[0] + (points[:, 2] - z[0]) * slope


def ray_cast(hits: np.ndarray, rays: np.ndarray, depth: float) -> np.ndarray:
    """Where each ray, continued below the floor, first lies under the heights: its v."""
    normal, _ = stripes()
    heights = normal[:, 0, 3] / 255.0
    reach = depth / -rays[:, 1]                              # the ray's length down to the full depth
    found = np.full(len(hits), np.nan)
    for k in range(1001):
        along = reach * (k / 1000.0) * 1.01   # (past the full depth: the last step always under)
        at = hits + rays * along[:, None]
        below = -at[:, 1] >= (1.0 - bilinear_v(heights, uv_v(at) % 1.0)) * depth
        found = np.where(np.isnan(found) & below, uv_v(at), found)
    return found


def test_the_floor_shows_the_stripes_where_each_ray_meets_the_heights(scene):
    """A floor of raised red and sunk blue stripes (10 cm apart in height), seen at about 30
    degrees: its red against the albedo where each pixel's ray, cast through the heights in
    numpy, meets them.  Within 0.1 in 88% of the pixels (measured 95.8%; the flat floor drawn
    without heights is as close to its own colours in 87%: the rest is the stripes' edges,
    where the texture's filtering and the march's 6 to 16 steps blur them); the flat floor's
    colours (no parallax) miss it in 41%."""
    shown, hits, rays = floor_frame(scene, DEPTH)
    _, albedo = stripes()
    red = albedo[:, 0, 0] / 255.0
    expected = bilinear_v(red, ray_cast(hits, rays, DEPTH) % 1.0)
    flat = bilinear_v(red, uv_v(hits) % 1.0)
    close = np.abs(shown - expected) < 0.1
    assert len(shown) > 3000 and close.mean() > 0.88, close.mean()
    assert (np.abs(flat - expected) < 0.1).mean() < 0.7
    # Nothing to march: with no depth the floor is the flat one (as close to its colours as the
    # marched one is to the heights': the rest is the texture's filtering at the edges).
    flat_shown, _, _ = floor_frame(scene, 0.0)
    assert (np.abs(flat_shown - flat) < 0.1).mean() > 0.85


def test_parallax_depth_is_checked():
    assert Material(parallax_depth=0.0).parallax_depth == 0.0
    for bad in (-0.01, 1.5, float("nan"), "0.1"):
        with pytest.raises(ComponentValueError, match="Material.parallax_depth"):
            Material(parallax_depth=bad)


def test_a_depth_with_no_heights_to_march_is_said():
    """``parallax_depth`` without a normal map, or with one whose alpha is one value (an RGB
    file's), would change nothing: a ComponentWarning says so; a map with heights is quiet."""
    from components import ComponentWarning

    normal, _ = stripes()
    flat = normal.copy()
    flat[..., 3] = 255
    with pytest.warns(ComponentWarning, match="without a normal_map"):
        Material(parallax_depth=0.05)
    with pytest.warns(ComponentWarning, match="no heights in its alpha"):
        Material(normal_map=TextureData(flat, name="flat"), parallax_depth=0.05)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        material = Material(normal_map=TextureData(normal, name="heights"), parallax_depth=0.05)
    with pytest.warns(ComponentWarning, match="no heights in its alpha"):
        material.normal_map = TextureData(flat, name="flat")   # (the map given later: said then)
