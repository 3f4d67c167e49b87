"""Ambient light: every surface gets the irradiance of the sky (or, without a sky, of a
sky/ground hemisphere), or, inside a probe's influence box, of the probe's capture, as
order-2 spherical harmonics (engine/render/irradiance.py).  The expectations are worked out
here on their own: cosine-weighted sums over cube texels in numpy (solid angles by the
differential formula, not the engine's exact one), the blending rule written out, and the
basis for the few normals the tests evaluate."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import (
    ComponentValueError,
    DirectionalLight,
    Emissive,
    HemisphereLight,
    Material,
    MeshRef,
    PointLight,
    ReflectionProbe,
    Skybox,
    Transform,
)
from components.limits import MAX_RECT_LIGHTS
from engine.assets.mesh import box, quad
from engine.core.cube_faces import face_directions
from engine.render.irradiance import evaluate_sh, hemisphere_sh, project_faces
from engine.render.sky import build_faces
from engine.render.views import LIGHTS_BLOCK_BYTES, MAX_DIRECTIONAL_LIGHTS, MAX_POINT_LIGHTS, lights_block
from engine.rules.light_rules import SkySun
from tests.support import linear_to_srgb8, look_from, srgb_to_linear


# --- independent references -----------------------------------------------------------------------
def cube_texels(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every texel of six faces (6, n, n, 3): unit directions, radiance and solid angle, the
    solid angle by the differential formula dw = (2/n)^2 / (1 + s^2 + t^2)^(3/2)."""
    n = faces.shape[1]
    c = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    t, s = np.meshgrid(c, c, indexing="ij")
    dw = np.tile(((2.0 / n) ** 2 / (1.0 + s * s + t * t) ** 1.5).reshape(-1), 6)
    directions = np.concatenate([face_directions(face, n).reshape(-1, 3) for face in range(6)])
    return directions, np.asarray(faces, np.float64).reshape(-1, 3), dw


def cosine_irradiance(faces: np.ndarray, normal) -> np.ndarray:
    """E(n) = sum of L(w) max(0, n.w) dw over the cube's texels: brute force, no harmonics."""
    directions, radiance, dw = cube_texels(faces)
    n = np.asarray(normal, np.float64) / np.linalg.norm(normal)
    return (radiance * (np.clip(directions @ n, 0.0, None) * dw)[:, None]).sum(axis=0)


def sh_at_plus_z(coefficients: np.ndarray) -> np.ndarray:
    """sum E_lm Y_lm(+z) for coefficients in the engine's order: at (0, 0, 1) only Y_00 =
    0.282095, Y_10 = 0.488603 and Y_20 = 0.315392 (3 - 1) are not zero."""
    c = np.asarray(coefficients, np.float64)
    return 0.282095 * c[0] + 0.488603 * c[2] + 0.315392 * 2.0 * c[6]


def pixel_linear(rgb: np.ndarray, column: int, row: int, radius: int = 2) -> np.ndarray:
    """The median linear colour of a small patch around a pixel (FXAA leaves a flat patch alone)."""
    patch = rgb[row - radius:row + radius + 1, column - radius:column + radius + 1].reshape(-1, 3)
    return srgb_to_linear(np.median(patch, axis=0))


def srgb_tolerance(linear: np.ndarray, levels: float = 1.5) -> np.ndarray:
    """The linear difference ``levels`` sRGB steps make at ``linear``."""
    return np.abs(srgb_to_linear(linear_to_srgb8(linear) + levels) - np.asarray(linear))


# --- the projection --------------------------------------------------------------------------------
def test_a_constant_sky_gives_pi_l_for_every_normal():
    """Radiance L from every direction: E(n) = pi L whatever n (the band-1 and band-2
    coefficients vanish), so a white Lambertian surface, E / pi, shows L."""
    radiance = np.array([0.3, 0.5, 0.9])
    faces = np.tile(radiance, (6, 16, 16, 1))
    coefficients = project_faces(faces)
    normals = np.random.default_rng(3).normal(size=(50, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    np.testing.assert_allclose(evaluate_sh(coefficients, normals), np.tile(math.pi * radiance, (50, 1)), rtol=1e-6)
    np.testing.assert_allclose(coefficients[1:], 0.0, atol=1e-9)


def test_the_generated_skys_harmonics_agree_with_a_cosine_integral_over_its_texels():
    """The default generated sky (a gradient, a sun glow and a disc): E(n) from the nine
    coefficients against the brute-force cosine integral over the cube's 6 x 64 x 64 texels,
    for normals all round.  Order-2 harmonics blur the sky's sharp features (the horizon, a
    step from the bright horizon to the dark ground, and the sun's disc): Ramamoorthi and
    Hanrahan's few percent.  Stated tolerance: within 2% of the brightest irradiance of the
    sky for every normal (the largest errors here, 1.5-1.8%, are under the straight up and
    straight down normals), and within 0.5% under horizontal normals."""
    sky = build_faces(Skybox(face_size=64))
    coefficients = project_faces(sky)
    normals = [(0, 1, 0), (0, -1, 0), (1, 0, 0), (-1, 0, 0), (0, 0, 1), (0, 0, -1), (0.4, 0.6, -0.7),
               (-0.4, -0.6, 0.7), (0.7, 0.2, 0.7), (-0.3, 0.9, 0.3)]
    exact = np.array([cosine_irradiance(sky, n) for n in normals])
    approx = np.array([evaluate_sh(coefficients, np.array(n) / np.linalg.norm(n)) for n in normals])
    brightest = exact.max()
    assert np.abs(approx - exact).max() <= 0.02 * brightest
    horizontal = [i for i, n in enumerate(normals) if n[1] == 0]
    assert np.abs(approx[horizontal] - exact[horizontal]).max() <= 0.005 * brightest


def test_a_generated_skys_light_in_closed_form_is_what_its_texels_converge_to():
    """``generated_sky_sh`` (each part of the sky a zonal function, by the Funk-Hecke theorem)
    against ``project_faces`` of the sky's numpy faces, texel by texel, for suns high, low,
    below the horizon and tinted, and other colours: within 5e-4 of the largest coefficient
    at 128 texels a face (the default), and closer as the texels get finer (the faces sample
    the 2.6-degree disc coarsely: 32 texels a face are 2.8 degrees a texel)."""
    from engine.render.irradiance import generated_sky_sh
    from engine.render.sky import sky_model
    from engine.rules.light_rules import SkySun

    colours = [{}, {"zenith": (0.02, 0.05, 0.2), "horizon": (0.9, 0.4, 0.2), "ground": (0.05, 0.2, 0.05),
                    "sun_color": (20.0, 12.0, 5.0)}]
    suns = [None, SkySun((0.3, 0.8, 0.2)), SkySun((0.0, 0.05, -1.0), (1.0, 0.5, 0.3)), SkySun((0.6, -0.3, 0.2))]
    for colour in colours:
        for sun in suns:
            got = generated_sky_sh(sky_model(Skybox(**colour), sun))
            errors = {}
            for size in (32, 128, 256):
                want = project_faces(build_faces(Skybox(face_size=size, **colour), sun))
                errors[size] = np.abs(got - want).max() / np.abs(want).max()
            assert errors[128] < 5e-4 and errors[256] < errors[32] / 10, (colour, sun, errors)


def test_the_frames_sky_light_is_the_closed_form(scene):
    """The Lights block a frame binds holds the generated sky's coefficients in closed form,
    with the sun where the sky has it (against the light)."""
    from engine.render.irradiance import generated_sky_sh
    from engine.render.sky import sky_model
    from engine.rules.light_rules import SkySun

    skybox = Skybox(face_size=32)

    def build(world):
        world.spawn(skybox)
        world.spawn(DirectionalLight(direction=(1.0, -1.0, 0.0), intensity=3.0))
        look_from(world, (3.0, 1.2, 1.5), target=(0, 0.5, 0))

    runner = scene(build)
    runner.frame()
    sun = SkySun((-math.sqrt(0.5), math.sqrt(0.5), 0.0))
    want = np.frombuffer(lights_block(generated_sky_sh(sky_model(skybox, sun)), [], [])[:9 * 16], np.float32)
    bound = np.frombuffer(runner.engine.renderer.lights_ubo.read()[:9 * 16], np.float32)
    np.testing.assert_allclose(bound, want, rtol=1e-5, atol=1e-6)
    # ... and not the texels' projection to the last digit (a second path, close but not equal)
    assert not np.array_equal(bound, np.frombuffer(lights_block(project_faces(build_faces(skybox, sun)), [], [])
                                                   [:9 * 16], np.float32))


def test_the_hemisphere_is_three_js_hemisphere_light():
    """Sky above the horizon and ground below, projected to order 2: E(n) / pi is exactly
    mix(ground, sky, (1 + n.y) / 2), and agrees with the brute-force integral under an up,
    down or sideways normal (where the two agree exactly: a half-sphere's cosine weight)."""
    sky, ground = np.array([0.5, 0.6, 0.9]), np.array([0.2, 0.1, 0.05])
    coefficients = hemisphere_sh(sky, ground)
    for n in ((0, 1, 0), (0, -1, 0), (1, 0, 0), (0.6, 0.8, 0), (0, -0.6, 0.8)):
        n = np.array(n, np.float64)
        np.testing.assert_allclose(evaluate_sh(coefficients, n) / math.pi,
                                   ground + (sky - ground) * (1 + n[1]) / 2, rtol=1e-5)
    size = 64
    faces = np.stack([np.where(face_directions(f, size)[..., 1:2] > 0, sky, ground) for f in range(6)])
    for n in ((0, 1, 0), (0, -1, 0), (1, 0, 0)):
        np.testing.assert_allclose(evaluate_sh(coefficients, np.array(n, float)), cosine_irradiance(faces, n),
                                   rtol=2e-3)


# --- the Lights block ------------------------------------------------------------------------------
_BLOCK_READER = """#version 410 core
#include "lights.glsl"
out vec4 value;
void main() {
    int i = int(gl_FragCoord.x);
    if (i < 9) value = lights.sky_sh[i];
    else if (i == 9) value = vec4(lights.counts);
    else if (i < 10 + MAX_DIRECTIONAL_LIGHTS) value = lights.directional_dir[i - 10];
    else if (i < 10 + 2 * MAX_DIRECTIONAL_LIGHTS) value = lights.directional_color[i - 10 - MAX_DIRECTIONAL_LIGHTS];
    else if (i < 10 + 2 * MAX_DIRECTIONAL_LIGHTS + MAX_POINT_LIGHTS)
        value = lights.point_pos[i - 10 - 2 * MAX_DIRECTIONAL_LIGHTS];
    else if (i < 10 + 2 * MAX_DIRECTIONAL_LIGHTS + 2 * MAX_POINT_LIGHTS)
        value = lights.point_color[i - 10 - 2 * MAX_DIRECTIONAL_LIGHTS - MAX_POINT_LIGHTS];
    else if (i < 10 + 2 * MAX_DIRECTIONAL_LIGHTS + 3 * MAX_POINT_LIGHTS)
        value = lights.point_spot[i - 10 - 2 * MAX_DIRECTIONAL_LIGHTS - 2 * MAX_POINT_LIGHTS];
    else if (i < 10 + 2 * MAX_DIRECTIONAL_LIGHTS + 4 * MAX_POINT_LIGHTS)
        value = lights.point_cookie_u[i - 10 - 2 * MAX_DIRECTIONAL_LIGHTS - 3 * MAX_POINT_LIGHTS];
    else if (i < 10 + 2 * MAX_DIRECTIONAL_LIGHTS + 5 * MAX_POINT_LIGHTS)
        value = lights.point_cookie_v[i - 10 - 2 * MAX_DIRECTIONAL_LIGHTS - 4 * MAX_POINT_LIGHTS];
    else if (i < 10 + 2 * MAX_DIRECTIONAL_LIGHTS + 6 * MAX_POINT_LIGHTS)
        value = lights.point_rect_u[i - 10 - 2 * MAX_DIRECTIONAL_LIGHTS - 5 * MAX_POINT_LIGHTS];
    else if (i < 10 + 2 * MAX_DIRECTIONAL_LIGHTS + 7 * MAX_POINT_LIGHTS)
        value = lights.point_rect_v[i - 10 - 2 * MAX_DIRECTIONAL_LIGHTS - 6 * MAX_POINT_LIGHTS];
    else value = vec4(lights.rect_slots[i - 10 - 2 * MAX_DIRECTIONAL_LIGHTS - 7 * MAX_POINT_LIGHTS]);
}
"""


def test_the_lights_packer_and_the_glsl_block_agree(ctx):
    """lights_block's bytes, bound as the Lights block, read back field by field by a shader
    that includes lights.glsl: every coefficient, count, direction and colour where the GLSL
    finds it, and the block's size as the GL lays it out."""
    from tests.support import fragment_row

    rng = np.random.default_rng(7)
    sh = rng.uniform(-1, 1, (9, 3))
    directional = [(tuple(rng.uniform(-1, 1, 3)), tuple(rng.uniform(0, 4, 3))) for _ in range(MAX_DIRECTIONAL_LIGHTS)]
    # (each with its sphere's radius, its contact shadows' channel + 1: the cookie's up row's w,
    # and its rectangle's rows)
    point = [(tuple(rng.uniform(-9, 9, 3)), float(rng.uniform(1, 20)), tuple(rng.uniform(0, 4, 3)),
              tuple(rng.uniform(-5, 5, 4)), (tuple(rng.uniform(-5, 5, 4)), tuple(rng.uniform(-5, 5, 3))),
              float(rng.uniform(0, 2)), float(rng.integers(0, 4)),
              (tuple(rng.uniform(-5, 5, 4)), tuple(rng.uniform(-5, 5, 4))))
             for _ in range(MAX_POINT_LIGHTS)]
    rect_slots = [int(v) for v in rng.choice(MAX_POINT_LIGHTS, MAX_RECT_LIGHTS - 1, replace=False)]
    block = lights_block(sh, directional, point, rect_slots=rect_slots)
    assert len(block) == LIGHTS_BLOCK_BYTES
    width = 10 + 2 * MAX_DIRECTIONAL_LIGHTS + 7 * MAX_POINT_LIGHTS + MAX_RECT_LIGHTS // 4

    def bind(program):
        assert program["Lights"].size == LIGHTS_BLOCK_BYTES
        ubo = ctx.buffer(block)
        program["Lights"].binding = 7
        ubo.bind_to_uniform_block(7)
        return [ubo]
    read = fragment_row(ctx, _BLOCK_READER, width, bind=bind)
    np.testing.assert_allclose(read[:9, :3], sh, rtol=1e-6)
    assert read[9, :2].tolist() == [MAX_DIRECTIONAL_LIGHTS, MAX_POINT_LIGHTS]
    rows = 10
    for i, (direction, rgb) in enumerate(directional):
        np.testing.assert_allclose(read[rows + i, :3], direction, rtol=1e-6)
        np.testing.assert_allclose(read[rows + MAX_DIRECTIONAL_LIGHTS + i, :3], rgb, rtol=1e-6)
    rows += 2 * MAX_DIRECTIONAL_LIGHTS
    for i, (position, reach, rgb, cone, (right, up), radius, contact, (half_u, half_v)) in enumerate(point):
        np.testing.assert_allclose(read[rows + i], (*position, reach), rtol=1e-6)
        np.testing.assert_allclose(read[rows + MAX_POINT_LIGHTS + i], (*rgb, radius), rtol=1e-6)
        np.testing.assert_allclose(read[rows + 2 * MAX_POINT_LIGHTS + i], cone, rtol=1e-6)
        np.testing.assert_allclose(read[rows + 3 * MAX_POINT_LIGHTS + i], right, rtol=1e-6)
        np.testing.assert_allclose(read[rows + 4 * MAX_POINT_LIGHTS + i], (*up, contact), rtol=1e-6)
        np.testing.assert_allclose(read[rows + 5 * MAX_POINT_LIGHTS + i], half_u, rtol=1e-6)
        np.testing.assert_allclose(read[rows + 6 * MAX_POINT_LIGHTS + i], half_v, rtol=1e-6)
    # The rectangles' slots, the rest -1 (one short of the limit: the last is -1).
    assert read[rows + 7 * MAX_POINT_LIGHTS:].reshape(-1).tolist() == [*rect_slots, -1]


def test_the_irradiance_block_is_as_big_in_glsl_as_in_python(ctx):
    """ambient.glsl's Irradiance block (its MAX_IRRADIANCE_PROBES boxes and the volume's
    grid) has the size irradiance_block packs, as the GL lays it out."""
    import pathlib
    import tempfile

    from engine.render.irradiance import IRRADIANCE_BLOCK_BYTES, irradiance_block
    from engine.render.shader_library import load_source

    source = ('#version 410 core\n#include "lights.glsl"\n#include "ambient.glsl"\nout vec4 value;\n'
              "void main() { value = vec4(ambient_irradiance(ambient_boxes(gl_FragCoord.xyz, vec3(0.0, 1.0, 0.0)), "
              "vec3(0.0, 1.0, 0.0)), "
              "1.0); }\n")
    with tempfile.TemporaryDirectory() as folder:
        path = pathlib.Path(folder) / "reader.frag"
        path.write_text(source)
        fragment = load_source(str(path), {"AMBIENT_PROBES": "1", "IRRADIANCE_VOLUME": "1"})
    vertex = "#version 410 core\nvoid main() { gl_Position = vec4(0.0, 0.0, 0.0, 1.0); }"
    program = ctx.program(vertex_shader=vertex, fragment_shader=fragment)
    try:
        assert program["Irradiance"].size == IRRADIANCE_BLOCK_BYTES == len(irradiance_block(()))
    finally:
        program.release()


# --- in frames -------------------------------------------------------------------------------------
def test_a_white_surface_under_a_constant_sky_shows_the_skys_radiance(scene):
    """A white Lambertian box under a sky of one radiance L, no light: every face shows L."""
    radiance = np.array([0.25, 0.35, 0.5])

    def build(world):
        world.spawn(Skybox(faces=np.tile(radiance.astype(np.float32), (6, 16, 16, 1))))
        look_from(world, (2.5, 2.0, 3.0), target=(0, 0.5, 0))
        world.spawn(Transform(position=(0, 0.5, 0)), MeshRef(box()), Material(color=(1, 1, 1), roughness=1.0))

    runner = scene(build)
    rgb = runner.frame()
    for point in ((0.0, 1.0, 0.0), (0.5, 0.5, 0.0), (0.0, 0.5, 0.5)):  # top, +x and +z faces
        column, row = runner.project(point)
        # The face's centre: nudged inside the face towards the camera's side
        np.testing.assert_allclose(pixel_linear(rgb, column, row, 1), radiance,
                                   atol=float(srgb_tolerance(radiance).max()))


def test_the_side_of_a_box_away_from_the_sun_is_lit_by_the_sky(scene):
    """A grey box under the default generated sky and a sun from -x: its +x face gets no
    sunlight, and shows albedo x E(+x) / pi, E from the brute-force cosine integral over the
    sky's texels (no floor: nothing hides any of the sky from it).  Against the old constant
    ambient (0.03 whatever the sky), which left it nearly black."""
    albedo = np.array([0.6, 0.6, 0.6])
    skybox = Skybox(face_size=64)

    def build(world):
        world.spawn(skybox)
        world.spawn(DirectionalLight(direction=(1.0, -1.0, 0.0), intensity=3.0))
        look_from(world, (3.0, 1.2, 1.5), target=(0, 0.5, 0))
        world.spawn(Transform(position=(0, 0.5, 0)), MeshRef(box()), Material(color=tuple(albedo), roughness=1.0))

    runner = scene(build)
    rgb = runner.frame()
    column, row = runner.project((0.5, 0.5, 0.0))
    seen = pixel_linear(rgb, column, row)
    sun = SkySun((-math.sqrt(0.5), math.sqrt(0.5), 0.0))  # the sky's sun: against the light (sun_direction)
    expected = albedo * cosine_irradiance(build_faces(skybox, sun), (1, 0, 0)) / math.pi
    # The harmonics' error under a sideways normal (under 1%) and the sRGB steps.
    np.testing.assert_allclose(seen, expected, rtol=0.02, atol=float(srgb_tolerance(expected).max()))
    assert seen.min() > 0.15  # not the old 0.03 x albedo (the sun's warm glow is on the other side)


def red_wall_room(ents):
    """A probe at (0, 1, 0) whose box holds a white box and a white floor; a bright red wall
    at x = -3 and nothing else but the default hemisphere.  The camera looks at the white box's -x face,
    which faces the wall."""
    def build(world):
        ents["camera"] = look_from(world, (-2.8, 1.4, 1.4), target=(-1.75, 1.0, 0.0))
        ents["probe"] = world.spawn(Transform(position=(0.0, 1.0, 0.0)),
                                    ReflectionProbe(resolution=32, influence=(8.0, 4.0, 8.0)))
        world.spawn(Transform(position=(-3.2, 1.0, 0.0), scale=(0.2, 4.0, 8.0)), MeshRef(box()),
                    Material(color=(1.0, 0.1, 0.1)), Emissive(2.0))
        world.spawn(Transform(position=(0.0, -0.05, 0.0), scale=(6.0, 0.1, 6.0)), MeshRef(box()),
                    Material(color=(0.9, 0.9, 0.9), roughness=1.0))  # a white floor: half of what the probe sees
        ents["white"] = world.spawn(Transform(position=(-1.5, 1.0, 0.0), scale=(0.5, 0.5, 0.5)), MeshRef(box()),
                                    Material(color=(1.0, 1.0, 1.0), roughness=1.0))
    return build


def test_an_object_in_a_probes_box_takes_the_probes_irradiance(scene):
    """The white box's face towards the red wall is red: albedo x E(-x) / pi with E the
    cosine integral of the probe's own faces, read back (ProbeCaptures.read_face), and the
    GPU's nine coefficients (IrradianceTable.read_row) equal the faces' projection."""
    ents = {}
    runner = scene(red_wall_room(ents), (160, 120))
    rgb = runner.frame()
    renderer = runner.engine.renderer
    faces = np.stack([renderer.probes.read_face(ents["probe"], face) for face in range(6)])
    row = renderer.irradiance.read_row(ents["probe"])
    np.testing.assert_allclose(row, project_faces(faces), rtol=0.03, atol=0.01 * np.abs(row).max())
    column, pixel_row = runner.project((-1.75, 1.0, 0.0))
    seen = pixel_linear(rgb, column, pixel_row)
    expected = cosine_irradiance(faces, (-1, 0, 0)) / math.pi
    assert seen[0] > 3.0 * seen[1] and seen[0] > 3.0 * seen[2]  # reddish
    # The harmonics against the exact integral (a half-red sphere: a sharp edge) and sRGB steps.
    np.testing.assert_allclose(seen, expected, rtol=0.08, atol=float(srgb_tolerance(expected).max()))
    # Outside the probe's box the same face takes the hemisphere's light: grey, not red.
    runner.world.get(ents["white"], Transform).position = (-1.5, 4.5, 0.0)
    runner.world.get(ents["camera"], Transform).position = (-2.8, 4.9, 1.4)
    rgb = runner.frame()
    column, pixel_row = runner.project((-1.75, 4.5, 0.0))
    outside = pixel_linear(rgb, column, pixel_row)
    assert outside[0] < 0.1 and outside[0] < 1.5 * outside[1]


def test_a_still_scene_settles_in_one_capture(scene):
    """Captures are lit by the sky's irradiance alone (no probe's): a probe recaptured every
    frame writes the same coefficients each time.  Were the probe's own irradiance in its
    captures, the white floor that fills half of them would turn redder capture after
    capture (one more bounce of the red wall's light each time).  (Requested each frame:
    an every-frame probe in a still scene keeps its faces as they are, tests/test_probe_keeping.py,
    and projects nothing again.)"""
    ents = {}
    runner = scene(red_wall_room(ents), (64, 48))
    runner.frame()
    runner.world.get(ents["probe"], ReflectionProbe).refresh = "every_frame"
    table = runner.engine.renderer.irradiance
    rows = []
    for _ in range(3):
        runner.world.get(ents["probe"], ReflectionProbe).request()  # every face drawn again
        runner.frame()
        rows.append(table.read_row(ents["probe"]))
    projections = table.projections
    assert projections >= 3
    np.testing.assert_allclose(rows[1], rows[0], rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(rows[2], rows[0], rtol=1e-4, atol=1e-5)


# Two rooms along x (tests/test_probe_blending.py's): A's box spans x in [-7, 1], B's x in
# [-1, 7], y in [-2, 2]; each probe sees its own colour of wall in front (+z).
CENTRES = {"a": (-3.0, 0.0, 0.0), "b": (3.0, 0.0, 0.0)}
INFLUENCE = (8.0, 4.0, 4.0)
BLEND = 1.0


def expected_weights(point) -> tuple[float, float, float]:
    """The blending rule, written out: each box's weight is the point's distance inside its
    nearest wall over the blend distance, at most 1 (0 outside); the two are divided by their
    sum where it passes 1; the sky has what is left."""
    weights = []
    for centre in CENTRES.values():
        inside = min(INFLUENCE[axis] / 2 - abs(point[axis] - centre[axis]) for axis in range(3))
        weights.append(0.0 if inside < 0 else min(1.0, inside / BLEND))
    total = max(1.0, sum(weights))
    return weights[0] / total, weights[1] / total, 1.0 - (weights[0] + weights[1]) / total


def test_diffuse_light_blends_the_probes_by_the_reflection_weights(scene):
    """White quads facing +z across the two boxes' overlap and near a wall of one box: each
    shows (wA E_A + wB E_B + w_sky E_sky)(+z) / pi, the weights from the rule written out
    here, E_A and E_B the probes' coefficients as the GPU wrote them, E_sky pi x the constant
    green sky."""
    ents = {}
    green = np.array([0.05, 0.4, 0.05])
    points = [(-2.5, 0.0, 0.0), (-0.75, 0.0, 0.0), (-0.25, 0.0, 0.0), (0.0, 0.0, 0.0), (0.5, 0.0, 0.0),
              (2.5, 0.0, 0.0), (-2.5, 1.5, 0.0), (2.0, -1.7, 0.0)]

    def build(world):
        world.spawn(Skybox(faces=np.tile(green.astype(np.float32), (6, 8, 8, 1))))
        look_from(world, (0.0, 0.0, 4.5), target=(0.0, 0.0, 0.0), fov=60.0)
        for name, centre in CENTRES.items():
            ents[name] = world.spawn(Transform(position=centre),
                                     ReflectionProbe(resolution=32, refresh="once", influence=INFLUENCE,
                                                     blend_distance=BLEND))
        facing_back = glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))
        for x, colour in ((-6.0, (0.6, 0.05, 0.05)), (6.0, (0.05, 0.05, 0.6))):
            world.spawn(Transform(position=(x, 0.0, 6.0), rotation=facing_back), MeshRef(quad(12, 12)),
                        Material(color=colour), Emissive(1.0))
        for point in points:
            world.spawn(Transform(position=point), MeshRef(quad(0.3, 0.3)), Material(color=(1, 1, 1), roughness=1.0))

    runner = scene(build, (320, 200))
    rgb = runner.frame()
    table = runner.engine.renderer.irradiance
    e_a, e_b = sh_at_plus_z(table.read_row(ents["a"])), sh_at_plus_z(table.read_row(ents["b"]))
    e_sky = math.pi * green
    assert e_a[0] > 2 * e_b[0] and e_b[2] > 2 * e_a[2]  # the two rooms differ: the weights can be told apart
    for point in points:
        w_a, w_b, w_sky = expected_weights(point)
        expected = (w_a * e_a + w_b * e_b + w_sky * e_sky) / math.pi
        column, row = runner.project(point)
        np.testing.assert_allclose(pixel_linear(rgb, column, row, 1), expected, rtol=0.03,
                                   atol=float(srgb_tolerance(expected).max()), err_msg=f"at {point}")


def test_the_hemisphere_fallback(scene):
    """No Skybox: a HemisphereLight's sky lights a white box's top, the mean of sky and
    ground its sides; without one, the dim default's mean lights a side."""
    sky, ground = np.array([0.5, 0.45, 0.4]), np.array([0.1, 0.2, 0.05])
    light = HemisphereLight(sky=tuple(sky), ground=tuple(ground))

    def build(world):
        world.spawn(light)
        look_from(world, (2.5, 2.5, 3.0), target=(0, 0.5, 0))
        world.spawn(Transform(position=(0, 0.5, 0)), MeshRef(box()), Material(color=(1, 1, 1), roughness=1.0))

    runner = scene(build)
    rgb = runner.frame()
    for point, expected in (((0.0, 1.0, 0.0), sky), ((0.5, 0.5, 0.0), (sky + ground) / 2)):
        column, row = runner.project(point)
        np.testing.assert_allclose(pixel_linear(rgb, column, row, 1), expected,
                                   atol=float(srgb_tolerance(expected).max()))
    light.intensity = 0.5  # a change is seen
    rgb = runner.frame()
    column, row = runner.project((0.0, 1.0, 0.0))
    np.testing.assert_allclose(pixel_linear(rgb, column, row, 1), sky / 2, atol=float(srgb_tolerance(sky / 2).max()))
    runner.world.delete_entity(next(e for e, _ in runner.world.query_one(HemisphereLight)))
    rgb = runner.frame()
    column, row = runner.project((0.5, 0.5, 0.0))
    from components.ambient import DEFAULT_GROUND, DEFAULT_SKY

    default = (np.array(DEFAULT_SKY) + np.array(DEFAULT_GROUND)) / 2
    np.testing.assert_allclose(pixel_linear(rgb, column, row, 1), default, atol=float(srgb_tolerance(default).max()))


def test_hemisphere_light_refuses_bad_values():
    with pytest.raises(ComponentValueError, match="HemisphereLight.sky"):
        HemisphereLight(sky=(1, -1, 0))
    with pytest.raises(ComponentValueError, match="HemisphereLight.intensity"):
        HemisphereLight(intensity=float("nan"))


def test_the_sample_level_has_no_black_surface(ctx):
    """Every pose of the sample level: under 0.2% of the pixels showing an entity are darker
    than 16/255 in every channel.  With the old constant ambient 0.7% of the mirror-wall pose
    and 1.1% of the doorway pose were (the sides of things away from the sun).  Looked at:
    what comes nearest now is the checker floor's dark cells (40/255, near black) in the
    boxes' shadows, lit by the sky alone, about 20/255: dark, not black."""
    from PIL import Image

    from tests.golden import render_case
    from tests.golden_scenes import HALL_POSES, GoldenCase, _hall

    for pose, camera in HALL_POSES.items():
        frame = render_case(ctx, GoldenCase(pose, _hall, camera))
        Image.fromarray(frame.rgb).save(f"/tmp/speculum_ambient_{pose}.png")  # to look at
        entity = frame.ids != 0
        dark = frame.rgb.max(axis=2) < 16
        assert entity.mean() > 0.3, pose  # a frame of things, not of sky
        assert (dark & entity).sum() / entity.sum() < 0.002, pose


def test_a_probe_gone_gives_back_its_row_and_its_light(scene):
    """Deleting the probe frees its row of the table (Renderer.resource_counts) and the white
    box's face towards the red wall goes back to the hemisphere's grey."""
    ents = {}
    runner = scene(red_wall_room(ents), (160, 120))
    runner.frame()
    assert runner.engine.renderer.resource_counts()["irradiance_rows"] == 1
    runner.world.delete_entity(ents["probe"])
    rgb = runner.frame()
    assert runner.engine.renderer.resource_counts()["irradiance_rows"] == 0
    column, row = runner.project((-1.75, 1.0, 0.0))
    seen = pixel_linear(rgb, column, row)
    assert seen[0] < 1.5 * seen[1] and seen[0] < 0.1


def test_more_boxes_than_the_shader_blends_are_reported(scene, caplog):
    """MAX_IRRADIANCE_PROBES boxes at most reach the shader; the probe the full table leaves
    out is said in a warning, once, naming the limit, its value, how many probes have
    boxes and the entity of each probe left out (the one holding no row: not the last by
    entity here, the later entities nearer and captured first), and the frame is drawn.  When
    a probe holding a row goes, the one left out takes it, though it is never captured again."""
    from engine.render.irradiance import MAX_IRRADIANCE_PROBES
    probes = []

    def build(world):
        look_from(world, (0.0, 1.0, 4.0), target=(0.0, 1.0, 0.0))
        world.spawn(Transform(position=(0, 1, 0)), MeshRef(box()), Material())
        for i in range(MAX_IRRADIANCE_PROBES + 1):
            probes.append(world.spawn(Transform(position=((MAX_IRRADIANCE_PROBES - i) * 3.0, 1.0, -10.0)),
                                      ReflectionProbe(resolution=8, refresh="once", influence=(2.0, 2.0, 2.0))))

    runner = scene(build, (32, 24))
    irradiance = runner.engine.renderer.irradiance
    with caplog.at_level("WARNING", logger="speculum"):
        runner.frame()
        runner.frame()
    said = [r.getMessage() for r in caplog.records if "MAX_IRRADIANCE_PROBES" in r.getMessage()]
    left_out = [probe for probe in probes if probe not in irradiance.rows]
    assert len(left_out) == 1 and len(irradiance.rows) == MAX_IRRADIANCE_PROBES and left_out != probes[-1:]
    assert len(said) == 1, said
    assert f"MAX_IRRADIANCE_PROBES = {MAX_IRRADIANCE_PROBES} " in said[0]
    assert f"and {MAX_IRRADIANCE_PROBES + 1} have influence boxes" in said[0]
    assert f"the probes of entities {left_out} are left out" in said[0]
    assert irradiance._count == MAX_IRRADIANCE_PROBES
    # A probe holding a row deleted: the one left out (captured once, never again) takes it.
    runner.world.delete_entity(next(probe for probe in probes if probe in irradiance.rows))
    runner.frame()
    assert left_out[0] in irradiance.rows and len(irradiance.rows) == MAX_IRRADIANCE_PROBES
    assert irradiance._count == MAX_IRRADIANCE_PROBES


def test_lights_past_the_blocks_slots_light_nothing_and_are_counted(scene):
    """Four bright suns shining up (they light no top face), then a dim one shining down: the
    block keeps the MAX_DIRECTIONAL_LIGHTS brightest (engine/rules/light_rules.py), so the
    white box's top face shows the sky's light alone, as with no fifth sun; the fifth is
    counted in RenderStats.lights_cut every frame and warned about once, when it comes; so
    are point lights past MAX_POINT_LIGHTS.  Made the brightest, the fifth sun is kept in
    place of one of the four and lights the top; taking lights away brings the count to 0."""
    from engine.core.errors import LightLimitWarning

    radiance = np.array([0.2, 0.2, 0.2])
    suns, lamps = [], []

    def build(world):
        world.spawn(Skybox(faces=np.tile(radiance.astype(np.float32), (6, 16, 16, 1))))
        look_from(world, (2.5, 2.0, 3.0), target=(0, 0.5, 0))
        world.spawn(Transform(position=(0, 0.5, 0)), MeshRef(box()), Material(color=(1, 1, 1), roughness=1.0))
        for _ in range(MAX_DIRECTIONAL_LIGHTS):
            suns.append(world.spawn(DirectionalLight(direction=(0, 1, 0), intensity=1.0, shadows=False)))

    runner = scene(build)
    rgb = runner.frame()
    top = runner.project((0.0, 1.0, 0.0))
    assert runner.stats.lights_cut == 0
    dark = pixel_linear(rgb, *top, 1)
    np.testing.assert_allclose(dark, radiance, atol=float(srgb_tolerance(radiance).max()))
    world = runner.world
    suns.append(world.spawn(DirectionalLight(direction=(0, -1, 0), intensity=0.5)))
    with pytest.warns(LightLimitWarning, match="1 directional and 0 point lights light nothing"):
        rgb = runner.frame()
    assert runner.stats.lights_cut == 1
    np.testing.assert_array_equal(pixel_linear(rgb, *top, 1), dark)   # the fifth sun lights nothing
    import warnings as warnings_module
    with warnings_module.catch_warnings():
        warnings_module.simplefilter("error")   # said once: a still frame counts without a warning
        runner.frame()
    assert runner.stats.lights_cut == 1
    # Brighter than the four: kept in place of one of them (still one cut), it lights the top.
    world.get(suns[-1], DirectionalLight).intensity = 3.0
    rgb = runner.frame()
    assert runner.stats.lights_cut == 1
    assert (pixel_linear(rgb, *top, 1) > dark + 0.3).all()
    world.get(suns[-1], DirectionalLight).intensity = 0.5
    rgb = runner.frame()
    np.testing.assert_array_equal(pixel_linear(rgb, *top, 1), dark)
    for i in range(MAX_POINT_LIGHTS + 2):
        lamps.append(world.spawn(Transform(position=(5.0 + i, 3.0, 0.0)), PointLight(intensity=1.0, range=0.5)))
    with pytest.warns(LightLimitWarning, match="1 directional and 2 point lights light nothing"):
        runner.frame()
    assert runner.stats.lights_cut == 3
    # A bright sun goes: the dim one takes its slot and lights the top face.
    world.delete_entity(suns[0])
    for lamp in lamps[:2]:
        world.delete_entity(lamp)
    rgb = runner.frame()
    assert runner.stats.lights_cut == 0
    assert (pixel_linear(rgb, *top, 1) > dark + 0.05).all()
