"""Probe image quality: the mip level a roughness reads (box mips and a GGX-prefiltered chain,
checked against the probe's own levels sampled in numpy at the level worked out here), and
the solid glass ball that refracts twice (checked against the ray math in numpy)."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import (
    ComponentValueError,
    Emissive,
    Material,
    MeshRef,
    ReflectionProbe,
    Reflective,
    Refractive,
    Skybox,
    Transform,
)
from engine.assets.mesh import quad, sphere
from engine.core.cube_faces import CUBE_FACES
from tests.support import look_from, srgb_to_linear
from tests.test_probes import read_cube_level

SIZE = 40          # the frame, square: the chrome quad fills it
RESOLUTION = 128   # the probe's faces
FACE = 4           # +Z: where the quad's reflections look
FOV = 60.0
EYE = 1.2          # the camera's distance in front of the quad


def edge_room(prefilter: str, roughness: float, ents: dict):
    """A chrome quad facing +z at the origin with a probe of its own (flat: the probe is its
    ReflectionProbe); behind the camera a wall, red left of x = 0.3 and blue right of it: a
    sharp edge in the probe's +Z face, which the quad shows."""
    def build(world):
        look_from(world, (0.0, 0.0, EYE), target=(0.0, 0.0, 0.0), fov=FOV)
        ents["quad"] = world.spawn(Transform(), MeshRef(quad(4, 4)),
                                   Material(color=(1, 1, 1), metallic=1.0, roughness=roughness), Reflective("cube"),
                                   ReflectionProbe(resolution=RESOLUTION, refresh="once", prefilter=prefilter))
        facing_back = glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))
        for x, colour in ((-4.7, (0.7, 0.04, 0.04)), (5.3, (0.04, 0.04, 0.7))):
            world.spawn(Transform(position=(x, 0.0, 5.0), rotation=facing_back), MeshRef(quad(10, 12)),
                        Material(color=colour), Emissive(1.0))
    return build


def pixel_rays(runner) -> np.ndarray:
    """The camera's ray through each pixel centre, (row, col, xyz), unit."""
    inverse = glm.inverse(runner.engine.main_view.view_proj)
    eye = np.array(runner.engine.main_view.eye)
    rays = np.zeros((SIZE, SIZE, 3))
    for row in range(SIZE):
        for col in range(SIZE):
            far = inverse * glm.vec4((col + 0.5) / SIZE * 2 - 1, 1 - (row + 0.5) / SIZE * 2, 1.0, 1.0)
            rays[row, col] = np.array(glm.vec3(far) / far.w) - eye
    return rays / np.linalg.norm(rays, axis=-1, keepdims=True)


def footprint_level(directions: np.ndarray, face_size: int) -> np.ndarray:
    """The level a lookup's footprint asks for: how far the direction moves from one pixel to
    the next (the larger of the two screen axes, differences over each 2 x 2 quad as a GPU's
    derivatives), in texels of a face ``face_size`` wide (2 / face_size across at its centre)."""
    dx = np.zeros(directions.shape[:2])
    dy = np.zeros(directions.shape[:2])
    for r0 in range(0, SIZE, 2):
        for c0 in range(0, SIZE, 2):
            gx = np.linalg.norm(directions[r0, c0 + 1] - directions[r0, c0])
            gy = np.linalg.norm(directions[r0 + 1, c0] - directions[r0, c0])
            dx[r0:r0 + 2, c0:c0 + 2], dy[r0:r0 + 2, c0:c0 + 2] = gx, gy
    return np.log2(np.maximum(dx, dy) * face_size * 0.5)


def bilinear(level: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """``level`` (one face's texels, row = t) sampled bilinearly along ``direction`` (GL's
    cube-map face coordinates: s, t = the axes over the major one)."""
    forward, s_axis, t_axis = (np.array(a) for a in CUBE_FACES[FACE])
    n = level.shape[0]
    major = direction @ forward
    s, t = direction @ s_axis / major, direction @ t_axis / major
    x, y = (s + 1) / 2 * n - 0.5, (t + 1) / 2 * n - 0.5
    x0, y0 = int(np.floor(x)), int(np.floor(y))
    fx, fy = x - x0, y - y0

    def texel(r, c):
        return level[min(max(r, 0), n - 1), min(max(c, 0), n - 1)]

    top = texel(y0, x0) * (1 - fx) + texel(y0, x0 + 1) * fx
    bottom = texel(y0 + 1, x0) * (1 - fx) + texel(y0 + 1, x0 + 1) * fx
    return top * (1 - fy) + bottom * fy


def trilinear(levels: list[np.ndarray], direction: np.ndarray, lod: float) -> np.ndarray:
    """GL's LINEAR_MIPMAP_LINEAR at ``lod`` (clamped to the chain; at or below 0, level 0)."""
    lod = min(max(lod, 0.0), len(levels) - 1.0)
    low = int(np.floor(lod))
    high = min(low + 1, len(levels) - 1)
    return bilinear(levels[low], direction) * (1 - (lod - low)) + bilinear(levels[high], direction) * (lod - low)


def visibility_factor(cos_angle: np.ndarray, roughness: float) -> np.ndarray:
    """ggx_reflect's weight for a white metal (F0 = 1, so Fresnel is 1): Smith-GGX visibility
    x 4 (n.v)(n.r), with n.v = n.r on a flat mirror; 1 at roughness 0."""
    a2 = max(roughness * roughness, 1e-4) ** 2
    g = cos_angle + np.sqrt(a2 + (1 - a2) * cos_angle ** 2)
    return 4 * cos_angle * cos_angle / (g * g)


def render_edge_room(scene, ctx, prefilter: str, roughness: float):
    """The frame (linear), the footprint level of each pixel's lookup, and ``expected``: a
    function of ``level_of`` (footprint level -> level read) giving, per pixel, the probe's
    levels (read back) sampled in numpy at that level, times ggx_reflect's weight."""
    ents = {}
    runner = scene(edge_room(prefilter, roughness, ents), (SIZE, SIZE))
    runner.engine.renderer.antialias = "off"
    rgb = srgb_to_linear(runner.frame())
    cube = runner.engine.renderer.probes.cubes[ents["quad"]]
    levels = [read_cube_level(ctx, cube.texture, FACE, level)[..., :3].astype(np.float64)
              for level in range(RESOLUTION.bit_length())]
    rays = pixel_rays(runner)
    reflected = rays * np.array([1.0, 1.0, -1.0])  # about the quad's normal, +z
    footprint = footprint_level(reflected, RESOLUTION)
    weight = visibility_factor(reflected[..., 2], roughness)

    def expected(level_of) -> np.ndarray:
        out = np.zeros_like(rgb)
        for row in range(SIZE):
            for col in range(SIZE):
                out[row, col] = weight[row, col] * trilinear(levels, reflected[row, col],
                                                             level_of(footprint[row, col]))
        return out

    return rgb, footprint, expected


def edge_contrast(image: np.ndarray) -> float:
    """The largest red-minus-blue step between neighbouring columns, over the frame's rows."""
    balance = image[..., 0] - image[..., 2]
    return float(np.abs(np.diff(balance, axis=1)).max())


def test_a_mirror_smooth_surface_reads_box_mips_at_its_footprint_level(scene, ctx):
    """Box mips, roughness 0: each pixel is the probe's mip chain read at the footprint's own
    level (no roughness bias), sampled in numpy; a level blurrier (the bias it had) is
    clearly further off and softens the edge."""
    rgb, footprint, sampled = render_edge_room(scene, ctx, "mips", 0.0)
    assert 0.3 < footprint.mean() < 1.5  # the footprint is about a texel: a level more is visible
    expected, blurrier = sampled(lambda lod: lod), sampled(lambda lod: lod + 1.0)
    error = np.abs(rgb - expected).mean(axis=-1)
    error_blurrier = np.abs(rgb - blurrier).mean(axis=-1)
    assert error.max() < 0.01, error.max()
    assert error_blurrier.max() > 3 * error.max()
    assert edge_contrast(rgb) == pytest.approx(edge_contrast(expected), rel=0.1)
    assert edge_contrast(rgb) > 1.2 * edge_contrast(blurrier)


@pytest.mark.parametrize("roughness", [0.0, 2.0 / 7.0, 0.5])
def test_a_ggx_chain_is_read_at_the_level_prefiltered_for_the_roughness(scene, ctx, roughness):
    """A GGX-prefiltered chain of a 128-texel probe (top level 7): level L was convolved for
    roughness L / 7 (engine/render/probes.py, cube_mip.frag), so roughness r reads level
    7 r and nothing else: roughness 0 reads level 0, the capture itself, where its footprint
    (about a level here) would have mixed in level 1, convolved for roughness 1/7, and
    bled the colours across the edge."""
    top = RESOLUTION.bit_length() - 1
    rgb, footprint, sampled = render_edge_room(scene, ctx, "ggx", roughness)
    expected = sampled(lambda lod: roughness * top)
    error = np.abs(rgb - expected).mean(axis=-1)
    assert error.max() < 0.01, (roughness, error.max())
    if roughness == 0.0:
        assert footprint.mean() > 0.3  # the footprint alone would have read past level 0
        footprint_read = sampled(lambda lod: max(lod, 0.0))  # the old reading: never sharper than the footprint
        assert np.abs(rgb - footprint_read).mean(axis=-1).max() > 3 * error.max()
        assert edge_contrast(rgb) > 1.2 * edge_contrast(footprint_read)


# --- the solid glass ball ------------------------------------------------------------------------
IOR = 1.5
RADIUS = 0.6


def refract(i: np.ndarray, n: np.ndarray, eta: float) -> np.ndarray:
    """Snell's law as GLSL's refract (unit ``i`` towards the surface, ``n`` against it)."""
    cos = -(n @ i)
    k = 1.0 - eta * eta * (1.0 - cos * cos)
    return eta * i + (eta * cos - np.sqrt(k)) * n


def up_down_sky() -> Skybox:
    """A sky whose colour says how far up a direction points: linear (1 + y, 0.1, 1 - y) / 2
    for the unit direction's y, so (red - blue) / (red + blue) is y wherever it is seen,
    whatever a surface's transmittance scales it by."""
    from engine.core.cube_faces import face_directions

    faces = []
    for face in range(6):
        y = face_directions(face, 64)[..., 1]
        faces.append(np.stack([(1 + y) / 2, np.full_like(y, 0.05), (1 - y) / 2], axis=-1))
    return Skybox(faces=np.stack(faces).astype(np.float32))


def ball_view(scene, solid: bool) -> tuple[np.ndarray, np.ndarray, list]:
    """A clear glass ball (alpha 0, its own automatic probe, which sees only the sky) before
    the up/down sky: the heights (y) each ball pixel shows, and per pixel the camera's ray
    and its hit on the sphere (row, col, ray, point)."""
    ents = {}

    def build(world):
        world.spawn(up_down_sky())
        look_from(world, (0.0, 0.0, 4.0), target=(0.0, 0.0, 0.0), fov=40.0)
        # (Reflecting nothing of the sky: each pixel's colour is its refracted ray's alone.)
        ents["ball"] = world.spawn(Transform(), MeshRef(sphere(RADIUS, 64, 32)),
                                   Material(color=(1, 1, 1, 0), roughness=0.0, environment_reflection=0.0),
                                   Refractive(ior=IOR, solid=solid))

    runner = scene(build, (160, 120))
    runner.engine.renderer.antialias = "off"
    rgb = srgb_to_linear(runner.frame())
    seen_y = (rgb[..., 0] - rgb[..., 2]) / np.maximum(rgb[..., 0] + rgb[..., 2], 1e-6)
    ids = runner.ids()
    view = runner.engine.main_view
    inverse = glm.inverse(view.view_proj)
    eye = np.array(view.eye)
    pixels = []
    for row, col in np.argwhere(ids == ents["ball"]):
        far = inverse * glm.vec4((col + 0.5) / 160 * 2 - 1, 1 - (row + 0.5) / 120 * 2, 1.0, 1.0)
        d = np.array(glm.normalize(glm.vec3(far) / far.w - view.eye))
        b = d @ eye
        disc = b * b - (eye @ eye - RADIUS * RADIUS)
        if disc <= 0:
            continue
        p = eye + (-b - np.sqrt(disc)) * d
        if -(d @ (p / RADIUS)) < 0.45:
            continue  # near the outline: the pixel mixes several rays
        pixels.append((row, col, d, p))
    return seen_y, rgb, pixels


def thin_exit(d: np.ndarray, p: np.ndarray) -> np.ndarray:
    return refract(d, p / RADIUS, 1.0 / IOR)


def solid_exit(d: np.ndarray, p: np.ndarray) -> np.ndarray:
    """In at p, along the chord to where the ray meets the sphere again (the far root of
    |p + s r| = R), out there: Snell's law twice."""
    inside = refract(d, p / RADIUS, 1.0 / IOR)
    inside /= np.linalg.norm(inside)
    q = p + (-2.0 * (inside @ p)) * inside
    return refract(inside, -q / RADIUS, IOR)


@pytest.mark.parametrize("solid", [False, True])
def test_a_glass_ball_shows_the_heights_its_ray_math_predicts(scene, solid):
    """Each ball pixel shows the sky's height y along the ray numpy traces: in and along
    the chord and out for the solid ball, in only for the thin one; the other model's
    prediction is clearly further off where the two differ.  The solid ball shows the sky
    upside down and steeply (its top sees well below the horizon, its bottom well above).
    The thin model bends the ray once, towards the ball's axis: seen against a sky at
    infinity it turns the sky over too, but about half as steeply (measured: the height
    shown falls 0.53 per unit of height on the ball, 1.27 through the solid one)."""
    seen_y, rgb, pixels = ball_view(scene, solid)
    assert len(pixels) > 800
    assert rgb[[r for r, *_ in pixels], [c for _, c, *_ in pixels]].mean() > 0.05  # not a black ball
    right, wrong, heights, shown = [], [], [], []
    for row, col, d, p in pixels:
        ours, other = (solid_exit(d, p), thin_exit(d, p)) if solid else (thin_exit(d, p), solid_exit(d, p))
        ours /= np.linalg.norm(ours)
        other /= np.linalg.norm(other)
        right.append(abs(seen_y[row, col] - ours[1]))
        if abs(ours[1] - other[1]) > 0.25:
            wrong.append(abs(seen_y[row, col] - other[1]))
        heights.append(p[1])
        shown.append(seen_y[row, col])
    right = np.array(right)
    assert np.median(right) < 0.01 and np.percentile(right, 95) < 0.02, (np.median(right), np.percentile(right, 95))
    assert len(wrong) > 100 and np.median(wrong) > 0.2
    heights, shown = np.array(heights), np.array(shown)
    slope = np.polyfit(heights, shown, 1)[0]  # how the height shown follows the height on the ball
    if solid:  # upside down and steep: the top sees well below the horizon, the bottom well above
        assert slope < -1.0 and shown[heights > 0.3].mean() < -0.4 and shown[heights < -0.3].mean() > 0.4
    else:  # one bend: turned over too, but half as steeply
        assert -0.8 < slope < -0.2 and shown[heights > 0.3].mean() > -0.3


def test_solid_is_a_checked_refractive_field_a_level_carries(tmp_path):
    from engine.assets.level_file import LevelError, load_level
    from engine.core.world import World

    assert Refractive().solid is False
    with pytest.raises(ComponentValueError, match=r"Refractive\.solid"):
        Refractive(solid="yes")
    path = tmp_path / "ball.toml"
    text = """
[level]
name = "ball"

[[entity]]
name = "ball"
[entity.Transform]
position = [0.0, 1.0, 0.0]
[entity.MeshRef]
mesh = { sphere = 0.5 }
[entity.Refractive]
ior = 1.5
solid = true
"""
    path.write_text(text, encoding="utf-8")
    world = World("ball-level")
    try:
        names = load_level(path).spawn(world)
        assert world.get(names["ball"], Refractive).solid is True
    finally:
        world.close()
    path.write_text(text.replace("solid = true", "solid = 2"), encoding="utf-8")
    with pytest.raises(LevelError, match=r"solid"):
        load_level(path)
