"""HDR post-processing on the camera (components/post.py, engine/render/present.py,
engine/render/bloom.py, engine/render/post.py): each tone curve against its published
formula written here in numpy, exposure in stops, bloom's black and mean, automatic
exposure's target and speed, the plain look kept byte for byte, the fields' checks and
level files.

Known HDR images go through the real present stage: a game system between the reflect and
present stages writes them into the main view's level 0 (where the views' composited image
is), and the frame's present stage reads the camera's components as in any game.
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from pyglm import glm

from components import Camera, Transform
from components.post import BLOOM_COMPOSITES, TONEMAP_CURVES, Bloom, Tonemap
from components.tracking import ComponentValueError
from engine.assets.level_file import load_level, save_level
from engine.core.frame_io import Output
from engine.core.game import Game, GameSystem
from engine.render.bloom import FIRST_STEPS, level_sizes
from engine.render.bloom import LEVEL_DTYPE as LEVEL_GL_DTYPE
from engine.render.gl_context import GLCapabilities
from engine.render.post import adapt_blend
from engine.render.targets import CaptureTarget
from shell.app import Engine
from tests.support import linear_to_srgb8, srgb_to_linear

ROOT = Path(__file__).resolve().parents[1]
LEVEL_DTYPE = {"f2": np.float16, "f4": np.float32}[LEVEL_GL_DTYPE]   # the bloom levels' texels


# --- the curves, from their references (row-major matrices, as the references write them) ---

def curve_none(c: np.ndarray) -> np.ndarray:
    return np.clip(c, 0.0, 1.0)


ACES_IN = np.array([[0.59719, 0.35458, 0.04823], [0.07600, 0.90834, 0.01566], [0.02840, 0.13383, 0.83777]])
ACES_OUT = np.array([[1.60475, -0.53108, -0.07367], [-0.10208, 1.10813, -0.00605], [-0.00327, -0.07276, 1.07602]])


def curve_aces(c: np.ndarray) -> np.ndarray:
    """Stephen Hill's RRT + ODT fit (BakingLab ACES.hlsl), input scaled by 1 / 0.6 (three.js)."""
    v = (c / 0.6) @ ACES_IN.T
    v = (v * (v + 0.0245786) - 0.000090537) / (v * (0.983729 * v + 0.4329510) + 0.238081)
    return np.clip(v @ ACES_OUT.T, 0.0, 1.0)


REC2020_TO_709 = np.array([[1.6605, -0.5876, -0.0728], [-0.1246, 1.1329, -0.0083], [-0.0182, -0.1006, 1.1187]])
AGX_INSET = np.array([[0.856627153315983, 0.137318972929847, 0.11189821299995],
                      [0.0951212405381588, 0.761241990602591, 0.0767994186031903],
                      [0.0482516061458583, 0.101439036467562, 0.811302368396859]]).T  # three.js lists columns
AGX_OUTSET_INV = np.array([[0.899796955911611, 0.11142098895748, 0.11142098895748],
                           [0.0871996192028351, 0.875575586156966, 0.0871996192028349],
                           [0.013003424885555, 0.0130034248855548, 0.801379391839686]]).T


def curve_agx(c: np.ndarray) -> np.ndarray:
    """AgX base, default look (three.js r162+ after Filament): the matrices inverted here."""
    v = np.maximum(c @ np.linalg.inv(REC2020_TO_709).T, 0.0)
    v = np.maximum(v @ AGX_INSET.T, 1e-10)
    low, high = -12.47393, 4.026069
    x = np.clip((np.log2(v) - low) / (high - low), 0.0, 1.0)
    v = (15.5 * x ** 6 - 40.14 * x ** 5 + 31.96 * x ** 4 - 6.868 * x ** 3 + 0.4298 * x ** 2 + 0.1191 * x
         - 0.00232)
    v = np.maximum(v @ np.linalg.inv(AGX_OUTSET_INV).T, 0.0) ** 2.2
    return np.clip(v @ REC2020_TO_709.T, 0.0, 1.0)


def curve_pbr_neutral(c: np.ndarray) -> np.ndarray:
    """The Khronos PBR Neutral specification's formulas (KhronosGroup/ToneMapping README)."""
    f90, ks, kd = 0.04, 0.8 - 0.04, 0.15
    x = c.min(axis=-1, keepdims=True)
    f = np.where(x <= 2 * f90, x - x * x / (4 * f90), f90)
    p = (c - f).max(axis=-1, keepdims=True)
    pn = 1.0 - (1.0 - ks) ** 2 / (p + 1.0 - 2.0 * ks)
    g = 1.0 / (kd * (p - pn) + 1.0)
    compressed = (c - f) * pn / np.maximum(p, 1e-30) * g + pn * (1.0 - g)
    return np.clip(np.where(p <= ks, c - f, compressed), 0.0, 1.0)


CURVES = {"none": curve_none, "aces": curve_aces, "agx": curve_agx, "pbr_neutral": curve_pbr_neutral}
TINTS = ((1.0, 1.0, 1.0), (1.0, 0.5, 0.2), (0.2, 0.6, 1.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.3), (0.9, 0.8, 0.1))


def ramp(width: int = 256, low: float = -8.0, high: float = 6.0, rows_per_tint: int = 2) -> np.ndarray:
    """(rows, width, 4) float16, GL row order: a log ramp from 2^low to 2^high across, one tint
    a band of rows."""
    values = 2.0 ** np.linspace(low, high, width)
    rows = [np.concatenate([np.outer(values, tint), np.ones((width, 1))], axis=1) for tint in TINTS
            for _ in range(rows_per_tint)]
    return np.stack(rows).astype(np.float16)


# --- a game whose level 0 is a given image -----------------------------------------------------

class KnownImage(Game):
    """A camera with the given components; its level 0 overwritten with ``image`` (GL row
    order, float16 RGBA) after the reflect stage, so the present stage reads exactly it."""

    def __init__(self, image: np.ndarray, *components) -> None:
        self.image = image
        self.components = components
        self.engine: Engine | None = None
        self.camera = 0

    def build(self, world) -> None:
        self.camera = world.spawn(Transform(), Camera(), *self.components)

    def systems(self) -> list[GameSystem]:
        return [GameSystem(self.fill, after="reflect", before="present")]

    def fill(self, world, dt: float) -> None:
        color = self.engine.renderer.targets.color
        assert color.size == (self.image.shape[1], self.image.shape[0])
        color.write(np.ascontiguousarray(self.image).tobytes())


class Known:
    """An engine presenting ``KnownImage`` into a capture target (no FXAA unless asked)."""

    def __init__(self, ctx, image: np.ndarray, *components, aa: str = "off") -> None:
        self.ctx = ctx
        self.game = KnownImage(image, *components)
        self.engine = Engine(self.game, ctx)
        self.game.engine = self.engine
        self.engine.renderer.antialias = aa
        self.size = (image.shape[1], image.shape[0])
        self.capture = CaptureTarget(ctx, self.size)

    @property
    def world(self):
        return self.engine.world

    def frame(self, dt: float = 1 / 60) -> np.ndarray:
        """The presented frame, uint8 (rows, width, 3) in GL row order (as the image)."""
        self.engine.frame(dt, Output(self.capture.framebuffer, self.size))
        return np.flipud(self.capture.read_rgb())

    def level0(self) -> np.ndarray:
        w, h = self.size
        return np.frombuffer(self.engine.renderer.targets.color.read(), np.float16).reshape(h, w, 4)

    def close(self) -> None:
        self.capture.release()
        self.engine.close()


@pytest.fixture
def known(ctx):
    made: list[Known] = []

    def make(image, *components, aa: str = "off") -> Known:
        runner = Known(ctx, image, *components, aa=aa)
        made.append(runner)
        return runner

    yield make
    for runner in made:
        runner.close()


def expected_srgb8(linear: np.ndarray) -> np.ndarray:
    return np.rint(linear_to_srgb8(linear)).astype(np.int16)


# --- tone curves and exposure ---------------------------------------------------------------------

@pytest.mark.parametrize("curve", TONEMAP_CURVES)
def test_each_curve_matches_its_formula_on_an_hdr_ramp(known, curve):
    """2^-8 .. 2^6 in six tints through the real present stage: every pixel within one
    8-bit step of the curve's formula (GLSL float32 pow/log2 against float64), and the
    curves differ from each other by far more than that, so the wrong curve fails."""
    image = ramp()
    runner = known(image, Tonemap(curve=curve))
    got = runner.frame().astype(np.int16)
    hdr = image[..., :3].astype(np.float64)
    want = expected_srgb8(CURVES[curve](hdr))
    diff = np.abs(got - want)
    assert diff.max() <= 1, (curve, diff.max(), np.argwhere(diff > 1)[:5])
    for other, formula in CURVES.items():
        if other != curve:
            assert np.abs(expected_srgb8(formula(hdr)) - want).max() > 20, (curve, other)
    assert got.std() > 30  # a ramp, not a flat frame


@pytest.mark.parametrize("curve", ("none", "aces", "agx", "pbr_neutral"))
def test_one_more_stop_of_exposure_doubles_the_linear_input(known, curve):
    """exposure=+1 EV on an image v presents exactly what exposure 0 does on 2v (doubling is
    exact in half floats), and +1 EV is not a no-op."""
    image = ramp(high=5.0)
    doubled = image.copy()
    doubled[..., :3] *= np.float16(2.0)
    plus_one = known(image, Tonemap(curve=curve, exposure=1.0)).frame()
    same = known(doubled, Tonemap(curve=curve, exposure=0.0)).frame()
    base = known(image, Tonemap(curve=curve, exposure=0.0)).frame()
    assert np.array_equal(plus_one, same)
    assert np.abs(plus_one.astype(int) - base).max() > 20
    # And the half-stop between: 2^0.5 times the input, against the formula.
    half = known(image, Tonemap(curve=curve, exposure=0.5)).frame().astype(np.int16)
    want = expected_srgb8(CURVES[curve](image[..., :3].astype(np.float64) * 2.0 ** 0.5))
    assert np.abs(half - want).max() <= 1


# --- the plain look ------------------------------------------------------------------------------

PLAIN_PRESENT = """#version 410 core
uniform sampler2D hdr_image;
uniform float exposure;
in vec2 v_uv;
out vec4 out_color;
void main() {
    vec3 srgb = linear_to_srgb(texture(hdr_image, v_uv).rgb * exposure);
    out_color = vec4(srgb, 1.0);
}
"""


def plain_program(ctx):
    """Today's present.frag (before post-processing), with the unchanged include inlined:
    the program a camera without Tonemap and Bloom must still match byte for byte."""
    color = (ROOT / "shaders" / "include" / "color.glsl").read_text()
    fullscreen = (ROOT / "shaders" / "include" / "fullscreen.glsl").read_text()
    vertex = (ROOT / "shaders" / "present.vert").read_text().replace('#include "fullscreen.glsl"', fullscreen)
    fragment = PLAIN_PRESENT.replace("#version 410 core\n", "#version 410 core\n" + color + "\n")
    return ctx.program(vertex_shader=vertex, fragment_shader=fragment)


def test_a_camera_without_the_components_presents_todays_frame_byte_for_byte(known, ctx):
    image = ramp(low=-10.0, high=3.0)
    runner = known(image)
    runner.engine.renderer.exposure = 0.7
    got = runner.frame()
    program = plain_program(ctx)
    vao = ctx.vertex_array(program, [])
    target = CaptureTarget(ctx, runner.size)
    try:
        program["hdr_image"].value = 0
        program["exposure"].value = 0.7
        runner.engine.renderer.targets.color.use(0)
        target.framebuffer.use()
        ctx.viewport = (0, 0, *runner.size)
        ctx.disable(ctx.BLEND | ctx.DEPTH_TEST | ctx.CULL_FACE)
        vao.render(vertices=3)
        plain = np.flipud(target.read_rgb())
    finally:
        vao.release()
        program.release()
        target.release()
        from engine.render.bindings import invalidate
        invalidate(ctx)
    assert np.array_equal(got, plain)
    assert runner.engine.renderer.resource_counts()["post_targets"] == 0
    # A Tonemap of curve "none" at 0 EV is the same picture too (exposure 1).
    runner.engine.renderer.exposure = 1.0
    plain_one = runner.frame()
    runner.world.add_component(runner.game.camera, Tonemap(curve="none"))
    assert np.array_equal(runner.frame(), plain_one)


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -0.5, 2.0 ** 25, "2", None, True, np.array([1.0, 2.0])])
def test_the_renderers_exposure_refuses_a_bad_value_when_it_is_given(known, bad):
    """``Renderer.exposure`` (the camera without a Tonemap) is checked as it is set, naming it:
    a NaN or negative one presented a black frame and an infinite one a white frame, with no
    word, and a string failed later, inside the present stage.  A refused value leaves the
    last good one, which the next frame presents (the same picture as before the bad write)."""
    image = ramp(low=-6.0, high=0.0)
    runner = known(image)
    runner.engine.renderer.exposure = 0.5
    before = runner.frame()
    with pytest.raises(ValueError, match=r"Renderer\.exposure must be a finite number in \[0, 2\*\*24\]"):
        runner.engine.renderer.exposure = bad
    assert runner.engine.renderer.exposure == 0.5
    assert np.array_equal(runner.frame(), before)
    got = before.astype(np.int16)
    assert np.abs(got - expected_srgb8(image[..., :3].astype(np.float64) * 0.5)).max() <= 1


def test_a_tonemap_replaces_the_renderers_exposure(known):
    image = ramp(low=-6.0, high=0.0)
    runner = known(image, Tonemap(curve="none", exposure=-1.0))
    runner.engine.renderer.exposure = 8.0  # ignored under a Tonemap
    got = runner.frame().astype(np.int16)
    assert np.abs(got - expected_srgb8(image[..., :3].astype(np.float64) * 0.5)).max() <= 1


# --- bloom -----------------------------------------------------------------------------------------

def start_at(runner, first_step: str):
    """The runner with its bloom chain starting at ``first_step`` (engine/render/bloom.py:
    "half" is a GPU's default, "quarter" a software rasteriser's): tests run both."""
    runner.engine.renderer.present_pass.bloom.first_step = first_step
    return runner


@pytest.mark.parametrize("first_step", FIRST_STEPS)
@pytest.mark.parametrize("composite", BLOOM_COMPOSITES)
def test_bloom_of_a_black_frame_is_black(known, composite, first_step):
    image = np.zeros((90, 160, 4), np.float16)
    runner = start_at(known(image, Tonemap(curve="none"), Bloom(intensity=1.0, composite=composite)), first_step)
    assert not runner.frame().any()
    bloom = runner.engine.renderer.present_pass.bloom
    # half: 80x45 .. 5x2, a sixth would be 2x1; quarter: 40x22 .. 5x2 (drawn from the image)
    assert bloom.levels == {"half": 5, "quarter": 4}[first_step]
    assert len(bloom.textures) == bloom.target_count() == bloom.levels
    for texture in bloom.textures:
        assert not np.frombuffer(texture.read(), LEVEL_DTYPE).reshape(-1, 4)[:, :3].any()


def smooth_image(size=(320, 180)) -> np.ndarray:
    """A smooth HDR image (values 0.2 .. 7.8, waves a few dozen pixels long): GL row order."""
    w, h = size
    x, y = np.meshgrid(np.arange(w) / w, np.arange(h) / h)
    base = 4.0 + 3.0 * np.sin(2 * np.pi * 1.5 * x + 0.3) * np.cos(2 * np.pi * y) + 0.8 * (x - 0.5)
    image = np.stack([base, 0.5 * base + 1.0, 8.0 - base, np.ones_like(base)], axis=-1)
    return image.astype(np.float16)


@pytest.mark.parametrize("first_step", FIRST_STEPS)
def test_bloom_keeps_the_images_mean(known, first_step):
    """The chain's result, divided by its levels, has the image's mean within 0.5% per channel
    on a smooth image: every filter's weights sum to 1, so what is lost is only at the
    edges (taps past them read the edge), the odd-sized levels' half-texel shifts, half-float
    storage and Karis's weights (on a smooth image its boxes differ by the square of the
    slope).  Energy-conserving at intensity 1 the frame is the bloom alone, and its mean
    (read as 8-bit sRGB, exposed by 1/8 so nothing clips) agrees within 1%."""
    image = smooth_image()
    runner = start_at(known(image, Tonemap(curve="none", exposure=-3.0), Bloom(intensity=1.0, levels=5)), first_step)
    frame = runner.frame()
    bloom = runner.engine.renderer.present_pass.bloom
    assert bloom.levels == {"half": 5, "quarter": 4}[first_step]   # both end at 10x5
    w, h = bloom.textures[0].size
    summed = np.frombuffer(bloom.textures[0].read(), LEVEL_DTYPE).reshape(h, w, 4)[..., :3].astype(np.float64)
    mean_in = image[..., :3].astype(np.float64).mean(axis=(0, 1))
    mean_bloom = summed.mean(axis=(0, 1)) / bloom.levels
    assert np.all(np.abs(mean_bloom / mean_in - 1.0) < 0.005), (mean_bloom, mean_in)
    shown = srgb_to_linear(frame).mean(axis=(0, 1)) * 8.0
    assert np.all(np.abs(shown / mean_in - 1.0) < 0.01), (shown, mean_in)
    # The bloom is a blur: the frame is smoother than the image it came from.
    plain = srgb_to_linear(known(image, Tonemap(curve="none", exposure=-3.0)).frame())
    assert np.abs(np.diff(srgb_to_linear(frame), axis=1)).mean() < 0.8 * np.abs(np.diff(plain, axis=1)).mean()


@pytest.mark.parametrize("first_step", FIRST_STEPS)
def test_bloom_spreads_a_bright_point_and_leaves_level_0_as_it_was(known, first_step):
    """A 4x4 patch of 200 on black: additive bloom lights pixels tens of pixels away (the
    deepest levels) falling off with distance; the threshold keeps dim light out; and the
    main image the end images keep is the image written, untouched."""
    image = np.zeros((128, 192, 4), np.float16)
    image[..., 3] = 1.0
    image[62:66, 94:98, :3] = 200.0
    bloom = Bloom(intensity=0.5, threshold=1.0, composite="additive")
    runner = start_at(known(image, Tonemap(curve="none"), bloom), first_step)
    frame = runner.frame().astype(np.int16)
    row = frame[64, :, 0]
    assert row[96] == 255 and row[96 - 24] > row[96 - 48] > 0, row[40:100]
    assert np.array_equal(runner.level0(), image)
    dim = np.zeros_like(image)
    dim[..., 3] = 1.0
    dim[62:66, 94:98, :3] = 0.9   # below the threshold: shown as it is, no glow
    frame = start_at(known(dim, Tonemap(curve="none"), bloom), first_step).frame()
    assert frame[63, 95, 0] == expected_srgb8(np.array(0.9)) and not frame[:60].any() and not frame[:, :90].any()
    # Bloom comes before exposure: 2 EV up shows the patch at 3.6 (clipped white), and still
    # no glow, since the threshold is in the scene's units.
    frame = start_at(known(dim, Tonemap(curve="none", exposure=2.0), bloom), first_step).frame()
    assert frame[63, 95, 0] == 255 and not frame[:60].any() and not frame[:, :90].any()


@pytest.mark.parametrize("first_step", FIRST_STEPS)
def test_the_up_steps_four_paired_taps_sum_the_nine_tap_tent(known, first_step):
    """At radius 1 the up step reads its 3x3 tent in four bilinear taps, each weighing a pair
    of texels (bloom_up.frag PAIRED); any other radius takes the nine taps.  On an odd-sized
    image with bright specks (every level odd somewhere, so the taps' offsets vary texel to
    texel) the chain's sum is the nine taps' to float rounding."""
    rng = np.random.default_rng(7)
    image = np.ones((117, 203, 4), np.float16)
    image[..., :3] = rng.random((117, 203, 3)) ** 8 * 50.0
    sums = {}
    for radius in (1.0, 1.0 + 2.0 ** -20):   # the second rounds to no float32 1.0: the nine taps
        runner = start_at(known(image, Tonemap(curve="none"), Bloom(radius=radius, levels=5)), first_step)
        runner.frame()
        bloom = runner.engine.renderer.present_pass.bloom
        paired = any(("PAIRED", "1") in defines for _, defines in bloom._vaos)
        assert paired == (radius == 1.0)
        w, h = bloom.textures[0].size
        sums[radius] = np.frombuffer(bloom.textures[0].read(), LEVEL_DTYPE).reshape(h, w, 4)[..., :3]
    nine, four = sums[1.0 + 2.0 ** -20].astype(np.float64), sums[1.0].astype(np.float64)
    assert nine.std() > 0.1 * nine.mean() > 0   # not a flat sum
    # llvmpipe weighs a float texture's texels by float weights: the two agree to rounding.
    # The GL spec leaves a filter's weight precision to the implementation (GPUs commonly
    # keep 8 bits of the fraction), so there they agree to that.
    tolerance = 1e-5 if GLCapabilities.read(runner.ctx).software else 1.0 / 128.0
    assert np.abs(four - nine).max() <= tolerance * nine.max(), np.abs(four - nine).max() / nine.max()


def test_fxaa_runs_after_the_tone_map(known):
    """With FXAA on, the tone-mapped frame is encoded with its luma and filtered: a flat
    image comes through unchanged, and an edge of two tone-mapped values is blended."""
    flat = grey(0.4, (64, 32))
    assert np.array_equal(known(flat, Tonemap(curve="aces"), Bloom(), aa="fxaa").frame(),
                          known(flat, Tonemap(curve="aces"), Bloom(), aa="off").frame())
    edge = grey(0.05, (64, 32))
    edge[:, 32:, :3] = 4.0
    edge[16:, 31, :3] = 4.0   # a step in the edge: FXAA blends its pixels
    on = known(edge, Tonemap(curve="agx"), aa="fxaa").frame()
    off = known(edge, Tonemap(curve="agx"), aa="off").frame()
    assert not np.array_equal(on, off) and set(np.unique(off)) <= set(np.unique(off[:, [0, 63]]))


def test_bloom_level_sizes_stop_at_two_pixels():
    assert level_sizes((640, 360), 6) == [(320, 180), (160, 90), (80, 45), (40, 22), (20, 11), (10, 5)]
    assert level_sizes((640, 360), 8) == level_sizes((640, 360), 7) == [*level_sizes((640, 360), 6), (5, 2)]
    assert level_sizes((3, 100), 4) == []
    # A quarter start: the half start's chain less its first level (as of a 320x180 image).
    # The quarter start leaves the half level out and ends where the half start does.
    assert level_sizes((640, 360), 6, "quarter") == level_sizes((320, 180), 5) == level_sizes((640, 360), 6)[1:]
    assert level_sizes((640, 360), 1, "quarter") == [(160, 90)]
    assert level_sizes((7, 100), 4, "quarter") == []


def test_bloom_first_step_is_checked(ctx):
    from engine.render.bloom import BloomPass
    from engine.render.shader_library import ShaderLibrary

    bloom = BloomPass(ctx, ShaderLibrary(ctx))
    assert bloom.first_step == "half" and BloomPass(ctx, ShaderLibrary(ctx), software=True).first_step == "quarter"
    with pytest.raises(ValueError, match="first_step"):
        bloom.first_step = "eighth"


def test_a_bloomed_frame_is_the_same_whatever_state_came_before(known, ctx):
    """The chain is two passes (down, up), each applying its state once at its start; from
    level to level only the target (whose framebuffer sets its own viewport) and the source
    change.  With blending, depth, culling, clip distances, scissor and viewport scrambled
    before each present (as tests/test_pass_state.py does to the scene passes), the frame and
    the chain's sum are those of a clean run, bit for bit.  (The down pass's state left
    unapplied, its steps blend into the levels: this fails.)"""
    import random

    import moderngl

    from engine.render.bindings import invalidate

    image = np.zeros((90, 160, 4), np.float16)
    image[..., 3] = 1.0
    image[40:50, 70:90, :3] = 30.0
    components = (Tonemap(curve="agx"), Bloom(intensity=0.3, threshold=1.0, composite="additive"))

    def run(scramble: bool):
        runner = known(image, *components)
        rng = random.Random(3)
        renderer = runner.engine.renderer
        present = renderer.present

        def scrambled_present(*args, **kwargs):
            ctx.enable_only(moderngl.BLEND | moderngl.DEPTH_TEST | moderngl.CULL_FACE)
            ctx.blend_func = rng.choice([moderngl.ADDITIVE_BLENDING, moderngl.PREMULTIPLIED_ALPHA])
            ctx.depth_func = ">"
            for index in range(6):
                ctx.enable_direct(0x3000 + index)
            invalidate(ctx)
            ctx.scissor = (rng.randrange(20), rng.randrange(20), rng.randrange(1, 30), rng.randrange(1, 30))
            ctx.viewport = (rng.randrange(20), rng.randrange(20), rng.randrange(1, 60), rng.randrange(1, 40))
            return present(*args, **kwargs)

        if scramble:
            renderer.present = scrambled_present
        shots = []
        for _ in range(3):
            frame = runner.frame()
            bloom = runner.engine.renderer.present_pass.bloom
            w, h = bloom.textures[0].size
            shots.append((frame, np.frombuffer(bloom.textures[0].read(), LEVEL_DTYPE).reshape(h, w, 4).copy()))
        return shots

    clean, scrambled = run(False), run(True)
    assert clean[0][0][45, 80].max() > 0 and clean[0][1][..., :3].max() > 0   # a lit frame and a bloom
    for (frame, summed), (want_frame, want_summed) in zip(scrambled, clean, strict=True):
        np.testing.assert_array_equal(summed, want_summed)
        np.testing.assert_array_equal(frame, want_frame)


def test_a_bloom_chain_can_stand_in_for_another_sizes(known):
    """``BloomPass.chain_of`` (for measuring: benchmarks/lighting.py): a tiny frame draws the
    chain a frame of another size would, as many levels and draws, each level that size's
    scaled to this image (no side under two pixels); off again, the image's own chain."""
    from engine.render.bloom import MIN_LEVEL_SIDE, stand_in_sizes

    assert stand_in_sizes((4, 2), (640, 360), 6) == [(MIN_LEVEL_SIDE, MIN_LEVEL_SIDE)] * 6
    assert stand_in_sizes((64, 36), (640, 360), 6) == [(32, 18), (16, 9), (8, 4), (4, 2), (2, 2), (2, 2)]
    assert stand_in_sizes((64, 36), (640, 360), 6, "quarter") == [(16, 9), (8, 4), (4, 2), (2, 2), (2, 2)]
    runner = start_at(known(grey(0.5, (8, 4)), Tonemap(curve="none"), Bloom()), "half")
    bloom = runner.engine.renderer.present_pass.bloom
    runner.frame()
    assert bloom.levels == len(level_sizes((8, 4), 6)) == 1 == bloom.passes()   # 4x2 (then 2x1: too small)
    bloom.chain_of = (640, 360)
    runner.frame()
    assert bloom.levels == len(level_sizes((640, 360), 6)) == 6
    assert runner.engine.renderer.present_pass.post_passes == bloom.passes() == 11
    assert [t.size for t in bloom.textures] == stand_in_sizes((8, 4), (640, 360), 6)
    bloom.chain_of = None
    runner.frame()
    assert bloom.levels == 1 and [t.size for t in bloom.textures] == [(4, 2)]
    for bad in ((640,), (0, 360), (640.0, 360), "640x360"):
        with pytest.raises(ValueError, match="chain_of"):
            bloom.chain_of = bad


def test_bloom_resources_go_with_the_component(known):
    runner = known(smooth_image((64, 48)), Bloom(), Tonemap(auto_exposure=True))
    runner.frame()
    counts = runner.engine.renderer.resource_counts()
    # The chain (a half start: 32x24 .. 4x3; a quarter start: 16x12 .. 4x3); luminance 64
    # and two 1x1.
    levels = {"half": 4, "quarter": 3}[runner.engine.renderer.present_pass.bloom.first_step]
    assert counts["post_targets"] == levels + 3
    runner.world.remove_component(runner.game.camera, Bloom)
    runner.frame()
    assert runner.engine.renderer.resource_counts()["post_targets"] == 3
    runner.world.remove_component(runner.game.camera, Tonemap)
    runner.frame()
    assert runner.engine.renderer.resource_counts()["post_targets"] == 0


# --- automatic exposure ---------------------------------------------------------------------------

def grey(level: float, size=(96, 64)) -> np.ndarray:
    image = np.full((size[1], size[0], 4), level, np.float16)
    image[..., 3] = 1.0
    return image


def test_auto_exposure_brings_a_constant_image_to_the_key_and_adapts_at_its_speed(known):
    """A constant image of luminance L: the first frame starts at the target log2(key / L);
    then the image is 16x darker and each frame of dt closes 1 - exp(-speed dt) of the gap
    (checked frame by frame against the closed form), converging to the new target; the
    frame shows the key's grey once converged."""
    key, speed, dt = 0.18, 2.0, 0.1
    runner = known(grey(2.0), Tonemap(curve="none", auto_exposure=True, key=key, adapt_speed=speed))
    auto = runner.engine.renderer.present_pass.auto_exposure
    frame = runner.frame(dt)
    first = math.log2(key / 2.0)
    assert auto.adapted_ev() == pytest.approx(first, abs=2e-3)
    assert np.abs(frame.astype(int) - expected_srgb8(np.array(key))).max() <= 1
    runner.game.image = grey(0.125)
    target = math.log2(key / 0.125)
    for n in range(1, 16):
        runner.frame(dt)
        want = target + (first - target) * math.exp(-speed * dt * n)
        assert auto.adapted_ev() == pytest.approx(want, abs=2e-3), n
    for _ in range(40):
        frame = runner.frame(0.25)
    assert auto.adapted_ev() == pytest.approx(target, abs=2e-3)
    assert np.abs(frame.astype(int) - expected_srgb8(np.array(key))).max() <= 1
    assert adapt_blend(speed, dt) == pytest.approx(1 - math.exp(-0.2))


def test_auto_exposure_is_clamped_to_its_range_and_uses_the_mean_log_luminance(known):
    """Half the image at 8, half at 1/8: the mean of log2 L is 0, so the target is log2(key)
    (an arithmetic mean would give about log2(key / 4)); a nearly black image stops at
    max_ev; compensation (exposure) adds to the adapted value in the frame."""
    image = grey(8.0, (128, 64))   # 2 pixels a luminance texel: its taps fall on pixel centres
    image[:, :64, :3] = 0.125
    runner = known(image, Tonemap(curve="none", auto_exposure=True, key=0.25))
    auto = runner.engine.renderer.present_pass.auto_exposure
    runner.frame()
    assert auto.adapted_ev() == pytest.approx(-2.0, abs=0.02)
    dark = known(grey(1e-4), Tonemap(curve="none", auto_exposure=True, max_ev=3.0, exposure=-1.0))
    frame = dark.frame()
    assert dark.engine.renderer.present_pass.auto_exposure.adapted_ev() == pytest.approx(3.0, abs=1e-4)
    assert np.abs(frame.astype(int) - expected_srgb8(np.array(1e-4 * 2.0 ** 2))).max() <= 1


# --- the components ---------------------------------------------------------------------------------

@pytest.mark.parametrize(("make", "field"), [
    (lambda: Tonemap(curve="filmic"), "Tonemap.curve"),
    (lambda: Tonemap(curve=None), "Tonemap.curve"),
    (lambda: Tonemap(exposure=float("nan")), "Tonemap.exposure"),
    (lambda: Tonemap(exposure=30.0), "Tonemap.exposure"),
    (lambda: Tonemap(exposure="1"), "Tonemap.exposure"),
    (lambda: Tonemap(auto_exposure=1), "Tonemap.auto_exposure"),
    (lambda: Tonemap(key=0.0), "Tonemap.key"),
    (lambda: Tonemap(key=1.5), "Tonemap.key"),
    (lambda: Tonemap(adapt_speed=0.0), "Tonemap.adapt_speed"),
    (lambda: Tonemap(adapt_speed=float("inf")), "Tonemap.adapt_speed"),
    (lambda: Tonemap(min_ev=9.0), "Tonemap.min_ev"),
    (lambda: Tonemap(min_ev=2.0, max_ev=1.0), "Tonemap.max_ev"),
    (lambda: Tonemap(max_ev=-30.0), "Tonemap.max_ev"),
    (lambda: Bloom(intensity=-0.1), "Bloom.intensity"),
    (lambda: Bloom(intensity=1.5), "Bloom.intensity"),
    (lambda: Bloom(threshold=-1.0), "Bloom.threshold"),
    (lambda: Bloom(threshold=1e6), "Bloom.threshold"),
    (lambda: Bloom(knee=2.0), "Bloom.knee"),
    (lambda: Bloom(levels=0), "Bloom.levels"),
    (lambda: Bloom(levels=9), "Bloom.levels"),
    (lambda: Bloom(levels=3.0), "Bloom.levels"),
    (lambda: Bloom(radius=0.0), "Bloom.radius"),
    (lambda: Bloom(composite="screen"), "Bloom.composite"),
])
def test_bad_fields_are_refused_naming_the_field(make, field):
    with pytest.raises(ComponentValueError, match=re.escape(field)):
        make()


def test_a_field_write_is_checked_too():
    tonemap, bloom = Tonemap(), Bloom()
    with pytest.raises(ComponentValueError, match="Tonemap.max_ev"):
        tonemap.max_ev = -9.0
    with pytest.raises(ComponentValueError, match="Bloom.levels"):
        bloom.levels = True
    tonemap.curve = "pbr_neutral"
    assert tonemap.curve == "pbr_neutral"


LEVEL = """
[level]
name = "post"

[[entity]]
name = "camera"
[entity.Transform]
position = [0.0, 1.0, 3.0]
[entity.Camera]
[entity.Tonemap]
curve = "aces"
exposure = -0.5
auto_exposure = true
key = 0.12
adapt_speed = 3.0
min_ev = -4.0
max_ev = 6.0
[entity.Bloom]
intensity = 0.3
threshold = 1.5
knee = 0.25
levels = 4
radius = 1.5
composite = "additive"
"""


def test_level_files_carry_tonemap_and_bloom(tmp_path):
    from engine.core.world import World

    path = tmp_path / "post.toml"
    path.write_text(LEVEL)
    level = load_level(path)
    world = World("post level")
    try:
        names = level.spawn(world)
        camera = names["camera"]
        tonemap, bloom = world.get(camera, Tonemap), world.get(camera, Bloom)
        assert (tonemap.curve, tonemap.exposure, tonemap.auto_exposure, tonemap.key, tonemap.adapt_speed,
                tonemap.min_ev, tonemap.max_ev) == ("aces", -0.5, True, 0.12, 3.0, -4.0, 6.0)
        assert (bloom.intensity, bloom.threshold, bloom.knee, bloom.levels, bloom.radius,
                bloom.composite) == (0.3, 1.5, 0.25, 4, 1.5, "additive")
        saved = save_level(world, tmp_path / "again.toml", names, name="post")
        again = World("post level again")
        try:
            names2 = load_level(saved).spawn(again)
            for kind in (Tonemap, Bloom):
                a, b = world.get(camera, kind), again.get(names2["camera"], kind)
                assert vars(a) == vars(b) or all(getattr(a, f) == getattr(b, f) for f in a.__dataclass_fields__)
        finally:
            again.close()
    finally:
        world.close()
    bad = tmp_path / "bad.toml"
    bad.write_text(LEVEL.replace('curve = "aces"', 'curve = "filmic"'))
    with pytest.raises(Exception, match="Tonemap.curve"):
        load_level(bad)


# --- the present stage's switches and the overlay -----------------------------------------------------

def test_the_present_stages_switches_turn_bloom_off_and_override_the_curve(known):
    """``PresentSystem.bloom = False`` draws no camera's bloom (its textures go), ``curve``
    sets every camera's curve; the overlay's text says which, with the adapted exposure."""
    from shell.overlay_text import post_lines

    def post_line(engine) -> str:
        return "; ".join(post_lines(engine))

    image = ramp()
    runner = start_at(known(image, Tonemap(curve="agx", auto_exposure=True), Bloom(intensity=0.3)), "half")
    present = runner.engine.stages["present"]
    bloomed = runner.frame()
    adapted = runner.engine.renderer.present_pass.auto_exposure.adapted_ev()
    line = post_line(runner.engine)
    assert line.startswith(f"post: agx (camera), +0.00 EV, auto {adapted:+.2f}; "), line
    # 12 rows: levels 6x128 and 3x64 (3 passes), and 2 exposure passes
    assert line.endswith("; bloom 0.3 x2, 5 passes; screen: AO off; SSR off"), line
    present.bloom = False
    plain = runner.frame()
    assert not np.array_equal(plain, bloomed)
    assert runner.engine.renderer.resource_counts()["post_targets"] == 3  # the exposure's only
    assert "bloom off (set)" in post_line(runner.engine)
    present.curve = "none"
    runner.world.get(runner.game.camera, Tonemap).auto_exposure = False
    got = runner.frame().astype(np.int16)
    assert np.abs(got - expected_srgb8(CURVES["none"](image[..., :3].astype(np.float64)))).max() <= 1
    assert post_line(runner.engine) == \
        "post: none (set; camera agx), +0.00 EV; bloom off (set), 0 passes; screen: AO off; SSR off"
    with pytest.raises(ValueError, match="PresentSystem.curve"):
        present.curve = "filmic"
    bare = known(image)
    bare.frame()
    assert post_line(bare.engine) == "post: none (camera), x1; bloom off, 0 passes; screen: AO off; SSR off"


def test_the_overlay_toggles_bloom_the_grade_and_occlusion_and_picks_the_curve(known, ctx):
    pytest.importorskip("imgui_bundle", reason="the debug overlay needs imgui-bundle (not installed here)")
    from shell.overlay import DebugOverlay

    image = ramp(width=640, rows_per_tint=100)   # room for the whole overlay
    runner = known(image, Tonemap(curve="agx"), Bloom())
    present = runner.engine.stages["present"]
    runner.frame()
    overlay = DebugOverlay(ctx)
    try:
        def click(widget: str) -> None:
            for down in (None, True, False):
                x, y = overlay.widgets[widget]
                overlay.mouse_moved(x, y)
                if down is not None:
                    overlay.mouse_button(1, down)
                overlay.draw(runner.engine, runner.capture.framebuffer, runner.size)

        overlay.draw(runner.engine, runner.capture.framebuffer, runner.size)
        assert any(line.startswith("post: agx (camera)") for line in overlay.lines)
        assert overlay.region[3] < runner.size[1] - 8, overlay.region
        click("bloom")
        assert present.bloom is False, overlay.widgets
        click("grade")            # the second row: the grade, ambient occlusion and the curve
        assert present.grade is False
        click("AO")
        assert runner.engine.stages["main"].occlusion is False
        click("AO only")
        assert present.show_occlusion is True
        click("curve")            # opens the drop-down
        click("curve aces")
        assert present.curve == "aces"
        click("curve")
        click("curve camera")
        assert present.curve is None
    finally:
        overlay.release()


def test_a_lamp_seen_only_in_a_mirror_glows_there(scene):
    """Bloom runs on the image with every reflection composited in: a lamp hidden from the
    camera but shown by a mirror glows around its reflection (pixels next to its image, which
    the ids say is the lamp, are brighter than without Bloom), and far from it the frame is
    as without."""
    from components import DirectionalLight, Emissive, Material, MeshRef, Mirror, Visibility
    from engine.assets.mesh import plane, quad, sphere
    from tests.support import look_from

    lamp = {}

    def build(bloom: bool):
        def make(world) -> None:
            camera = look_from(world, (0.0, 1.2, 4.0), (0.0, 1.0, 0.0))
            world.add_component(camera, Tonemap(curve="none"))
            if bloom:
                world.add_component(camera, Bloom(intensity=0.5, threshold=1.0, composite="additive"))
            world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.5), intensity=1.0))
            world.spawn(Transform(), MeshRef(plane(10, 10)), Material(color=(0.3, 0.3, 0.3)))
            world.spawn(Transform(position=(0.0, 1.2, -2.0)), MeshRef(quad(3.0, 2.2)), Material(), Mirror())
            lamp["id"] = world.spawn(Transform(position=(0.4, 1.1, 1.0)), MeshRef(sphere(0.2)),
                                     Material(color=(1.0, 0.9, 0.7)), Emissive(20.0), Visibility(direct=False))
        return make

    runs = {}
    for bloom in (False, True):
        runner = scene(build(bloom), (192, 128))
        runner.engine.renderer.antialias = "off"
        runs[bloom] = (runner.frame().astype(int), runner.ids())
    (plain, ids), (glowing, _) = runs[False], runs[True]
    lit = ids == lamp["id"]
    assert 5 <= lit.sum() < 200, lit.sum()   # the lamp's image, in the mirror only
    rows, columns = np.nonzero(lit)
    assert 30 < rows.mean() < 100   # inside the mirror, above the floor
    near = np.zeros_like(lit)
    near[max(rows.min() - 6, 0):rows.max() + 7, max(columns.min() - 6, 0):columns.max() + 7] = True
    near &= ~lit
    gain = (glowing - plain).sum(axis=2)
    assert gain[near].mean() > 20, gain[near].mean()
    assert np.abs(glowing[:16, :16] - plain[:16, :16]).max() <= 2


def test_a_lamp_seen_only_through_a_portal_glows_there(scene):
    """As in a mirror, through a portal: a lamp beyond the partner (behind the camera, out of
    its view) shows through the near portal, which the ids and surface ids say, and glows
    round its image there (the neighbouring pixels brighter than without Bloom); far from it
    the frame is as without."""
    from components import DirectionalLight, Emissive, Material, MeshRef
    from engine.assets.mesh import plane, sphere
    from engine.assets.portals import spawn_portal_pair
    from tests.support import look_from

    ents = {}

    def build(bloom: bool):
        def make(world) -> None:
            camera = look_from(world, (0.0, 1.2, 4.0), (0.0, 1.2, 0.0))
            world.add_component(camera, Tonemap(curve="none"))
            if bloom:
                world.add_component(camera, Bloom(intensity=0.5, threshold=1.0, composite="additive"))
            world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.5), intensity=1.0))
            world.spawn(Transform(), MeshRef(plane(10, 10)), Material(color=(0.3, 0.3, 0.3)))
            # a faces the camera; b stands 30 m behind it, looking away (+z), its world beyond out of view
            ents["a"], ents["b"] = spawn_portal_pair(world, (0.0, 1.2, -2.0), None, (0.0, 1.2, 30.0), None,
                                                     size=(3.0, 2.2))
            ents["lamp"] = world.spawn(Transform(position=(-0.4, 1.1, 33.0)), MeshRef(sphere(0.2)),
                                       Material(color=(1.0, 0.9, 0.7)), Emissive(20.0))
        return make

    runs = {}
    for bloom in (False, True):
        runner = scene(build(bloom), (192, 128))
        runner.engine.renderer.antialias = "off"
        runs[bloom] = (runner.frame().astype(int), runner.ids(), runner.engine.renderer.targets.read_surface_ids())
    (plain, ids, surfaces), (glowing, _, _) = runs[False], runs[True]
    lit = ids == ents["lamp"]
    assert 5 <= lit.sum() < 200, lit.sum()
    assert (surfaces[lit] == ents["a"]).all()   # seen through a, and only there
    rows, columns = np.nonzero(lit)
    near = np.zeros_like(lit)
    near[max(rows.min() - 6, 0):rows.max() + 7, max(columns.min() - 6, 0):columns.max() + 7] = True
    near &= ~lit
    gain = (glowing - plain).sum(axis=2)
    assert gain[near].mean() > 20, gain[near].mean()
    assert np.abs(glowing[:16, :16] - plain[:16, :16]).max() <= 2


def _hdr_frame(runner) -> np.ndarray:
    """The main view's level 0 as the present stage read it (every reflection composited in),
    linear RGB float64, row 0 at the top."""
    color = runner.engine.renderer.targets.color
    w, h = color.size
    return np.flipud(np.frombuffer(color.read(), np.float16).reshape(h, w, 4)[..., :3]).astype(np.float64)


@pytest.mark.parametrize("through", ["mirror", "portal"])
def test_auto_exposure_meters_a_lamp_seen_only_in_a_mirror_or_through_a_portal_as_the_frames_pixels(scene, through):
    """A bright tile (emissive 40) the camera cannot see directly, shown by a mirror (or through
    a portal) filling the upper right of a 128 x 128 frame (each of the meter's taps on a pixel's
    centre).  The first frame's exposure (no adaptation yet) is the one worked out here in numpy
    from the composited frame's own luminance: log2(key) less the mean of its clamped log2
    Rec. 709 luminance, within its range.  The tile is there (ids say so, inside the mirror or
    portal's pixels, and bright), and it counts: with its pixels' luminance left out of the
    mean the exposure would be more than a third of a stop higher, and the tile made dark
    brings the metered exposure up as the numpy mean of that frame says."""
    from components import DirectionalLight, Emissive, Material, MeshRef, Mirror, Visibility
    from engine.assets.mesh import plane, quad
    from engine.assets.portals import spawn_portal_pair
    from tests.support import look_from

    size, key, low, high = (128, 128), 0.18, -6.0, 6.0
    ents = {}

    def build(glow: float):
        def make(world) -> None:
            camera = look_from(world, (0.0, 1.5, 4.0), (0.0, 1.5, 0.0))
            world.add_component(camera, Tonemap(curve="aces", auto_exposure=True, key=key, min_ev=low, max_ev=high))
            world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.5), intensity=1.0))
            world.spawn(Transform(), MeshRef(plane(20, 20)), Material(color=(0.3, 0.3, 0.3)))
            world.spawn(Transform(position=(0, 1.5, -0.3)), MeshRef(quad(20, 20)), Material(color=(0.2, 0.2, 0.2)))
            where, tile, extent = glm.vec3(1.2, 2.55, 0.0), glm.vec3(1.5, 2.9, 1.5), (2.2, 2.0)
            behind = glm.angleAxis(glm.radians(180.0), glm.vec3(0, 1, 0))
            if through == "mirror":
                ents["surface"] = world.spawn(Transform(position=where), MeshRef(quad(*extent)), Material(), Mirror())
                hidden = (Visibility(direct=False),)
                tile = Transform(position=tile, rotation=behind)
            else:   # b 30 m behind, facing away from the camera: the tile before it out of the camera's view
                ents["surface"], _ = spawn_portal_pair(world, where, None, where + glm.vec3(0, 0, 30), behind,
                                                       size=extent)
                hidden = ()
                tile = Transform(position=where + glm.vec3(0, 0, 30) + (tile - where) * glm.vec3(1, 1, -1))
            ents["tile"] = world.spawn(tile, MeshRef(quad(*extent)), Material(color=(1.0, 0.9, 0.8)), Emissive(glow),
                                       *hidden)
        return make

    def metered(glow: float):
        runner = scene(build(glow), size)
        runner.engine.renderer.antialias = "off"
        runner.frame()
        hdr = _hdr_frame(runner)
        logs = np.clip(np.log2(np.maximum(hdr @ [0.2126, 0.7152, 0.0722], 1e-10)),
                       math.log2(key) - high, math.log2(key) - low)
        return runner, hdr, logs, runner.engine.renderer.present_pass.auto_exposure.adapted_ev()

    def expected(logs):
        return float(np.clip(math.log2(key) - logs.mean(), low, high))

    runner, hdr, logs, ev = metered(40.0)
    tile = runner.ids() == ents["tile"]
    assert 800 < tile.sum() < 4000, tile.sum()
    assert (runner.engine.renderer.targets.read_surface_ids()[tile] == ents["surface"]).all()
    rows, columns = np.nonzero(tile)
    assert rows.max() < size[1] / 2 and columns.min() > size[0] / 2   # (upper right)
    assert (hdr[tile] @ [0.2126, 0.7152, 0.0722]).min() > 10.0
    assert ev == pytest.approx(expected(logs), abs=0.02)
    assert expected(logs[~tile]) - expected(logs) > 0.35   # (the tile's pixels count)
    _, dark_hdr, dark_logs, dark_ev = metered(0.0)
    assert dark_ev == pytest.approx(expected(dark_logs), abs=0.02) and dark_ev - ev > 0.35


@pytest.mark.parametrize("first_step", FIRST_STEPS)
def test_the_bloom_threshold_fades_light_in_over_its_soft_knee(known, first_step):
    """``Bloom(threshold=1, knee=0.5)`` on constant images of one colour (r, r/2, r/4): every
    filter of the chain keeps a constant (its weights sum to 1, Karis's boxes all alike), so
    the chain's sum over its levels is the colour times the soft threshold's share, worked out
    here: Unity's and Unreal's quadratic from threshold - knee to threshold + knee (its
    brightness the largest channel), then the light above the threshold; nothing below
    0.5, and at 0.9 light a hard threshold would keep out."""
    threshold, knee = 1.0, 0.5
    tint = np.array([1.0, 0.5, 0.25])

    def share(bright: float) -> float:
        soft = np.clip(bright - threshold * (1 - knee), 0.0, 2 * threshold * knee) ** 2 / (4 * threshold * knee)
        return max(soft, bright - threshold) / bright

    def constant(bright: float) -> np.ndarray:
        image = np.ones((64, 128, 4), np.float16)
        image[..., :3] = bright * tint
        return image

    runner = start_at(known(constant(0.3), Tonemap(curve="none", exposure=-4.0),
                            Bloom(intensity=0.5, threshold=threshold, knee=knee, composite="additive")), first_step)
    bloom = runner.engine.renderer.present_pass.bloom
    for bright in (0.3, 0.6, 0.9, 1.2, 1.45, 2.0, 4.0):
        runner.game.image = constant(bright)
        runner.frame()
        w, h = bloom.textures[0].size
        summed = np.frombuffer(bloom.textures[0].read(), LEVEL_DTYPE).reshape(h, w, 4)[..., :3].astype(np.float64)
        want = bright * tint * share(bright)
        np.testing.assert_allclose(summed / bloom.levels, np.broadcast_to(want, summed.shape), rtol=4e-3, atol=2e-4,
                                   err_msg=str(bright))
    assert share(0.9) > 0.08 and share(0.3) == 0.0 and share(4.0) == pytest.approx(0.75)


@pytest.mark.parametrize("intensity", [0.3, 0.8])
def test_additive_bloom_adds_what_energy_conserving_bloom_takes_from_the_image(known, intensity):
    """The two composites of one bloom on a smooth HDR image (curve none, 4 stops down: nothing
    clips): "additive" is image + bloom x intensity, "energy_conserving" image x (1 - intensity)
    + bloom x intensity, so in linear light the first frame less the second is the image x
    intensity x 2^-4 at every pixel (the bloom cancels), within the 8-bit encoding's steps;
    and each frame is not the image alone (the bloom shows)."""
    image = smooth_image()
    linear, steps = {}, 0.0
    for composite in BLOOM_COMPOSITES:
        runner = known(image, Tonemap(curve="none", exposure=-4.0), Bloom(intensity=intensity, composite=composite))
        code = runner.frame().astype(np.float64)
        linear[composite] = srgb_to_linear(code)
        steps = steps + srgb_to_linear(np.minimum(code + 1.0, 255.0)) - srgb_to_linear(np.maximum(code - 1.0, 0.0))
    assert set(linear) == {"additive", "energy_conserving"}
    scaled = image[..., :3].astype(np.float64) / 16.0
    assert linear["additive"].max() < 0.98   # (nothing clipped)
    off = np.abs(linear["additive"] - linear["energy_conserving"] - scaled * intensity)
    assert (off <= 0.5 * steps + 1e-4).all(), (off.max(), np.argwhere(off > 0.5 * steps + 1e-4)[:5])   # (a step each)
    for frame in linear.values():
        assert np.abs(frame - scaled).mean() > 0.004
