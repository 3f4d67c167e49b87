"""Parallax occlusion mapping (``Material.parallax_depth``): the normal map's alpha a height
map, each pixel's view ray marched into it.  The reference is the heights ray-cast in numpy,
apart from the engine: each floor pixel's ray continued below the floor in 1,000 steps until
it is under the heights (the texture read as GL filters it, bilinear between texel centres),
the colour the albedo there."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, Material, MeshRef, Skybox, Transform, look_rotation
from engine.assets.mesh import plane, quad
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
    return floor_pixels(scene(build, SIZE), 0)


def floor_pixels(runner, channel: int):
    """``runner``'s second frame (FXAA off): the floor's middle pixels' linear ``channel``,
    their rays' hits on the floor and the rays."""
    runner.engine.renderer.antialias = "off"
    runner.frame()
    shown = srgb_to_linear(runner.frame())[..., channel].reshape(-1)
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


# Low suns across the stripes (v falls along +z), as (its way towards the sun, elevation):
# from behind the camera, each raised stripe throws its shadow onto the sunk one beyond it,
# the part the camera sees there half in it; from before it, towards the camera onto the
# sunk ones before them.
SUNS = {"behind": (1.0, 25.0), "before": (-1.0, 30.0)}


def sun_towards(sun: str) -> np.ndarray:
    side, elevation = SUNS[sun]
    e = np.radians(elevation)
    return np.array([0.0, np.sin(e), side * np.cos(e)])


def lit_floor(scene, depth: float, sun: str):
    """The white, rough floor of raised and sunk stripes lit by the low ``sun`` alone (no sky
    light), as linear green a pixel, the rays' hits on the floor and the rays."""
    from components import DirectionalLight

    normal, _ = stripes()
    towards = sun_towards(sun)

    def build(world):
        look_from(world, (0.0, 1.2, 2.0), (0.0, 0.0, 0.0), fov=50.0)
        world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
        world.spawn(DirectionalLight(direction=tuple(float(x) for x in -towards), intensity=2.0))
        world.spawn(Transform(), MeshRef(plane(FLOOR, FLOOR)),
                    Material(color=(1.0, 1.0, 1.0, 1.0), roughness=1.0, environment_reflection=0.0,
                             normal_map=TextureData(normal, name="heights"), parallax_depth=depth))
    return floor_pixels(scene(build, SIZE), 1)


def sun_reaches(points: np.ndarray, depth: float, sun: str) -> np.ndarray:
    """Whether the ray from each point (under the floor, on the heights) to the sun leaves
    the heights without passing under them: 1,000 steps up to the floor's plane."""
    normal, _ = stripes()
    heights = normal[:, 0, 3] / 255.0
    towards = sun_towards(sun)
    reach = -points[:, 1] / towards[1]
    clear = np.ones(len(points), bool)
    for k in range(1, 1001):
        at = points + towards * (reach * k / 1000.0)[:, None]
        under = -at[:, 1] > (1.0 - bilinear_v(heights, uv_v(at) % 1.0)) * depth + 1e-4
        clear &= ~under
    return clear


@pytest.mark.parametrize("sun", sorted(SUNS))
def test_the_raised_stripes_shadow_the_sunk_ones_from_a_low_sun(scene, sun):
    """A low sun across the stripes: each pixel's point on the heights (its ray cast in
    numpy, the last point above them) in the sun or in a raised stripe's shadow, the sun's way
    from it cast through the heights in numpy too: the floor's light, taken as lit above half
    the lit floor's, agrees in 90% of the pixels (measured 93.9% from behind, 97.5% from
    before; the rest the shadows' soft edges and the stripes' filtered ones); without
    the heights' shadows every pixel is lit and agrees only where the sun reaches (82%, 40%)."""
    shown, hits, rays = lit_floor(scene, DEPTH, sun)
    reach = DEPTH / -rays[:, 1]
    points = np.full_like(hits, np.nan)
    normal, _ = stripes()
    heights = normal[:, 0, 3] / 255.0
    above = hits
    for k in range(1001):   # (ray_cast's march, keeping the last point above the heights)
        at = hits + rays * (reach * (k / 1000.0) * 1.01)[:, None]
        below = -at[:, 1] >= (1.0 - bilinear_v(heights, uv_v(at) % 1.0)) * DEPTH
        points = np.where(np.isnan(points[:, :1]) & below[:, None], above, points)
        above = at
    sunlit = sun_reaches(points, DEPTH, sun)
    assert 0.3 < sunlit.mean() < 0.85, sunlit.mean()   # (lit all over would agree in that share)
    bright = shown > 0.5 * np.percentile(shown, 95)
    agree = (bright == sunlit).mean()
    assert agree > 0.9, agree


def waves() -> tuple[TextureData, TextureData]:
    """Smooth heights and albedo (each a cosine along v, four waves across, a quarter wave
    apart): what a view's march shifts changes the colour smoothly, so two views drawn at
    different footprints still agree pixel by pixel (the stripes' edges would not)."""
    v = 1.0 - (np.arange(TEXELS) + 0.5) / TEXELS
    normal = np.zeros((TEXELS, TEXELS, 4), np.uint8)
    normal[..., :3] = (128, 128, 255)
    normal[..., 3] = np.round(255 * (0.5 + 0.5 * np.cos(2 * np.pi * 4 * v)))[:, None]
    albedo = np.full((TEXELS, TEXELS, 4), 255, np.uint8)
    albedo[..., 0] = np.round(255 * (0.5 + 0.5 * np.sin(2 * np.pi * 4 * v)))[:, None]
    albedo[..., 2] = 255 - albedo[..., 0]
    return TextureData(normal, name="wave heights"), TextureData(albedo, name="wave colours")


@pytest.mark.parametrize("way", ["mirror", "portal"])
def test_a_parallax_sheet_in_a_mirror_and_through_a_portal_is_marched_from_that_views_eye(scene, way):
    """A sheet of smooth raised and sunk waves (10 cm deep), leant back 40 degrees from the
    eye so its rays run along the waves, seen only in a mirror (or through a portal): the
    frame a camera at the mirror's image eye (the eye carried through the portal) draws of
    it, turned left for right for the mirror (tests/test_clearcoat.py's
    assert_shown_as_from_its_eye): each view marches its own eye's rays into the heights, the
    way along the surface turned into UVs the same in a mirror's view, whose screen is the
    world turned; and the march is there (the sheet without depth differs).  Within 0.08
    (99th percentile) and 0.15: a reflection's textures are filtered trilinearly where the
    main view's are not (the sheet without depth is 0.05 and 0.07 apart; a march turned the
    wrong way in the mirror was 0.32 and 0.51)."""
    from tests.test_clearcoat import IMAGE_EYE, SEEN, assert_shown_as_from_its_eye
    heights, colours = waves()
    towards = glm.normalize(IMAGE_EYE - SEEN)
    turn = look_rotation(-towards) * glm.angleAxis(glm.radians(40.0), glm.vec3(1.0, 0.0, 0.0))
    base = dict(color=(1.0, 1.0, 1.0, 1.0), roughness=0.8, texture=colours, normal_map=heights)
    assert_shown_as_from_its_eye(scene, dict(base, parallax_depth=0.1), base, way, mesh=quad(1.4, 1.4), turn=turn,
                                 at_most=(0.08, 0.15))
