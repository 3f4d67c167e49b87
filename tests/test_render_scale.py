"""Render scale and sharpening (``Renderer.render_scale``, ``Renderer.sharpness``;
``engine/render/resample.py``, ``shaders/resample.frag``, temporal upsampling in
``shaders/temporal_resolve.frag``): the main view drawn smaller and brought up by a
Catmull-Rom spline (against the half-size picture upscaled in numpy), sharpening against the
same filter in numpy, temporal upsampling settling nearer the picture drawn larger than a
spatial upscale does, depth of field and motion blur reading the smaller seen image in the
right place, a click picking at the drawn size, the command line; and supersampling (a scale
above 1) brought down by an area box in linear light, against a runner of the larger size
averaged down in numpy."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from pyglm import glm

from components import Camera, DepthOfField, MotionBlur, Transform
from engine.render.resample import RENDER_SCALE_RANGE, check_render_scale, render_size
from engine.resources import ViewBudget
from tests.test_temporal_aa import SCALE, averaged_down, edge_scene, linear

SIZE = (96, 72)
HALF = (48, 36)
ROOT = Path(__file__).resolve().parents[1]


def catmull_rom_up(picture: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``picture`` (h, w, 3) resampled to ``size`` by the full 4x4 Catmull-Rom spline at each
    output pixel's centre, its edge texels repeated (the GPU's clamp), clamped to [0, 255]."""
    source = picture.astype(np.float64)
    h, w = source.shape[:2]

    def taps(count: int, out: int) -> tuple[np.ndarray, np.ndarray]:
        position = (np.arange(out) + 0.5) * count / out - 0.5
        first = np.floor(position).astype(int)
        f = position - first
        weights = np.stack([-0.5 * f ** 3 + f ** 2 - 0.5 * f, 1.5 * f ** 3 - 2.5 * f ** 2 + 1.0,
                            -1.5 * f ** 3 + 2.0 * f ** 2 + 0.5 * f, 0.5 * f ** 3 - 0.5 * f ** 2], axis=1)
        index = np.clip(first[:, None] + np.arange(-1, 3)[None, :], 0, count - 1)
        return index, weights

    rows, row_weights = taps(h, size[1])
    columns, column_weights = taps(w, size[0])
    across = np.einsum("hwkc,wk->hwc", source[:, columns], column_weights)
    up = np.einsum("hkwc,hk->hwc", across[rows], row_weights)
    return np.clip(up, 0.0, 255.0)


def sharpened(picture: np.ndarray, sharpness: float) -> np.ndarray:
    """Contrast-adaptive sharpening as resample.frag words it, in numpy: the pixel less a share
    of its four neighbours, the share smaller where the neighbourhood nears black or white."""
    c = picture.astype(np.float64) / 255.0
    padded = np.pad(c, ((1, 1), (1, 1), (0, 0)), mode="edge")
    n, s = padded[:-2, 1:-1], padded[2:, 1:-1]
    w, e = padded[1:-1, :-2], padded[1:-1, 2:]
    lo = np.minimum.reduce([c, n, s, e, w])
    hi = np.maximum.reduce([c, n, s, e, w])
    room = np.sqrt(np.clip(np.minimum(lo, 1.0 - hi) / np.maximum(hi, 1e-5), 0.0, 1.0))
    lobe = -room * 0.2 * sharpness
    return np.clip((c + lobe * (n + s + e + w)) / (1.0 + 4.0 * lobe), 0.0, 1.0) * 255.0


def runner_at(scene, size, scale=1.0, mode="off", sharpness=0.0, build=edge_scene):
    runner = scene(build, size)
    renderer = runner.engine.renderer
    renderer.antialias, renderer.render_scale, renderer.sharpness = mode, scale, sharpness
    return runner


def test_the_scale_and_the_sharpness_are_checked_when_set(scene):
    """Out of range, not a number, NaN or a bool: refused naming the setting; the drawn size
    is each side rounded, at least a pixel."""
    renderer = runner_at(scene, SIZE).engine.renderer
    for bad in (0.2, 2.5, float("nan"), True, "0.5"):
        with pytest.raises(ValueError, match=r"Renderer.render_scale must be a number in \[0.25, 2\]"):
            renderer.render_scale = bad
    for bad in (-0.1, 1.01, float("inf"), None):
        with pytest.raises(ValueError, match=r"Renderer.sharpness must be a number in \[0, 1\]"):
            renderer.sharpness = bad
    assert renderer.render_scale == 1.0 and renderer.sharpness == 0.0
    assert check_render_scale(RENDER_SCALE_RANGE[0]) == 0.25
    assert render_size((97, 73), 0.5) == (48, 36) and render_size((3, 2), 0.25) == (1, 1)
    assert render_size(SIZE, 1.0) == SIZE


@pytest.mark.parametrize("mode", ["off", "fxaa"])
def test_a_smaller_picture_is_brought_up_by_a_catmull_rom_spline(scene, mode):
    """At half scale the main view is drawn at half the size (its proportions the output's)
    and the output is that picture (drawn by a runner of half the size: a second path), with
    FXAA's filtering where it is on, upscaled through the Catmull-Rom spline: within a level of
    the full 16-tap spline in numpy on average (the shader's five bilinear fetches leave out
    its corner taps), much nearer it than a nearest-texel upscale."""
    small = runner_at(scene, HALF, mode=mode).frame()
    runner = runner_at(scene, SIZE, 0.5, mode)
    picture = runner.frame().astype(np.float64)
    assert runner.engine.renderer.targets.size == HALF
    assert runner.engine.renderer.present_pass.post_passes == 1   # (the upscale)
    proj = runner.engine.main_view.proj
    assert proj[1][1] / proj[0][0] == pytest.approx(SIZE[0] / SIZE[1])
    expected = catmull_rom_up(small, SIZE)
    nearest = np.kron(small, np.ones((2, 2, 1))).astype(np.float64)
    error = np.abs(picture - expected)
    assert error.mean() < 1.0 and np.percentile(error, 99) < 8.0, (error.mean(), np.percentile(error, 99))
    assert np.abs(picture - nearest).mean() > 2.0 * error.mean()


def area_box_down(picture: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``picture`` (h, w, 3, encoded) brought down to ``size`` by an area box filter in linear
    light: each output pixel the mean of the texels under its footprint, each weighed by the
    share of it covered; encoded again as 8-bit sRGB values (floats)."""
    def weights(count: int, out: int) -> np.ndarray:
        edges = np.arange(out + 1) * count / out
        lo, hi = edges[:-1, None], edges[1:, None]
        texels = np.arange(count)[None, :]
        covered = np.clip(np.minimum(hi, texels + 1) - np.maximum(lo, texels), 0.0, None)
        return covered / covered.sum(axis=1, keepdims=True)

    h, w = picture.shape[:2]
    light = np.einsum("yh,hwc,xw->yxc", weights(h, size[1]), linear(picture), weights(w, size[0]))
    encoded = np.where(light <= 0.0031308, light * 12.92, 1.055 * np.power(light, 1.0 / 2.4) - 0.055)
    return encoded * 255.0


@pytest.mark.parametrize("scale", [2.0, 1.5])
def test_a_larger_picture_is_brought_down_by_an_area_box_in_linear_light(scene, scale):
    """Supersampled: at scale 2 (and 1.5) the main view is drawn that many times larger and
    the output is that picture (drawn by a runner of the larger size: a second path) averaged
    down over each pixel's footprint in linear light (numpy), within a level; its slanted
    edges nearer the picture drawn four times larger and averaged down than a frame drawn at
    scale 1 is."""
    large = (round(SIZE[0] * scale), round(SIZE[1] * scale))
    drawn_large = runner_at(scene, large).frame()
    runner = runner_at(scene, SIZE, scale)
    picture = runner.frame().astype(np.float64)
    assert runner.engine.renderer.targets.size == large
    assert runner.engine.renderer.present_pass.post_passes == 1   # (the box filter)
    expected = area_box_down(drawn_large, SIZE)
    assert np.abs(picture - expected).max() <= 1.01, np.abs(picture - expected).max()
    if scale == 2.0:
        reference = averaged_down(runner_at(scene, (SIZE[0] * SCALE, SIZE[1] * SCALE)).frame())
        plain = runner_at(scene, SIZE).frame()
        errors = {name: np.abs(linear(p) - reference) for name, p in (("plain", plain), ("super", picture))}
        edges = errors["plain"].max(axis=2) > 0.05
        assert edges.sum() > 40
        assert errors["super"][edges].mean() < 0.6 * errors["plain"][edges].mean()


def test_supersampling_under_temporal_aa_resolves_at_the_drawn_size(scene):
    """Temporal AA with a scale of 2: its history is the drawn (larger) size and the last
    pass brings the resolved picture down; forty still frames settle near the picture drawn
    four times larger and averaged down (nearer than a supersampled frame without it), and
    sharpening on top draws."""
    reference = averaged_down(runner_at(scene, (SIZE[0] * SCALE, SIZE[1] * SCALE)).frame())
    large = (SIZE[0] * 2, SIZE[1] * 2)
    runner = runner_at(scene, SIZE, 2.0, "taa", sharpness=0.3)
    for _ in range(40):
        picture = runner.frame()
    temporal = runner.engine.renderer.present_pass.temporal
    assert temporal._history[0][0].size == large and runner.engine.renderer.targets.size == large
    assert picture.shape[:2] == (SIZE[1], SIZE[0])
    plain = runner_at(scene, SIZE, 2.0).frame()
    error, plain_error = np.abs(linear(picture) - reference), np.abs(linear(plain) - reference)
    edges = plain_error.max(axis=2) > 0.02
    assert edges.sum() > 20 and error[edges].mean() < 0.6 * plain_error[edges].mean()


def test_sharpening_is_the_contrast_adaptive_filter(scene):
    """At scale 1 the sharpened frame is the unsharpened one put through the filter (numpy, on
    the same encoded values) within a level: the square's edges steeper, the flat wall as it
    was; with sharpness 0 no pass is drawn (the picture is the same as without it)."""
    plain = runner_at(scene, SIZE).frame()
    sharp = runner_at(scene, SIZE, sharpness=0.8).frame().astype(np.float64)
    np.testing.assert_allclose(sharp, sharpened(plain, 0.8), atol=1.01)
    steepest = {name: np.abs(np.diff(p.astype(np.float64).mean(axis=2), axis=1)).max()
                for name, p in (("plain", plain), ("sharp", sharp))}
    assert steepest["sharp"] > 1.15 * steepest["plain"], steepest
    inner = plain[1:-1, 1:-1].astype(int)
    flat = np.ones(inner.shape[:2], bool)
    for dy, dx in ((0, 1), (2, 1), (1, 0), (1, 2)):
        flat &= (plain[dy: dy + inner.shape[0], dx: dx + inner.shape[1]] == inner).all(axis=2)
    assert flat.sum() > 100
    np.testing.assert_array_equal(sharp[1:-1, 1:-1][flat], inner[flat])


def test_temporal_upsampling_settles_nearer_the_picture_drawn_larger(scene):
    """Forty frames of a still camera at half scale under temporal AA: the history is the
    output's size, and the slanted edges' pixels are much nearer the picture drawn four times
    larger and averaged down than the spatial upscale's (with or without FXAA), as near it as
    a frame drawn at full size without anti-aliasing."""
    reference = averaged_down(runner_at(scene, (SIZE[0] * SCALE, SIZE[1] * SCALE)).frame())
    errors = {}
    for name, scale, mode, frames in (("full", 1.0, "off", 1), ("spatial", 0.5, "off", 1),
                                      ("fxaa", 0.5, "fxaa", 1), ("temporal", 0.5, "taa", 40)):
        runner = runner_at(scene, SIZE, scale, mode)
        for _ in range(frames):
            picture = runner.frame()
        errors[name] = np.abs(linear(picture) - reference)
        if mode == "taa":
            temporal = runner.engine.renderer.present_pass.temporal
            assert temporal._history[0][0].size == SIZE and runner.engine.renderer.targets.size == HALF
    edges = errors["spatial"].max(axis=2) > 0.05
    assert edges.sum() > 40
    mean = {name: float(error[edges].mean()) for name, error in errors.items()}
    assert mean["temporal"] < 0.7 * min(mean["spatial"], mean["fxaa"]), mean
    assert mean["temporal"] < 1.1 * mean["full"], mean


def panning(build):
    """``build`` with the camera given a MotionBlur and an autofocusing DepthOfField."""
    def made(world):
        build(world)
        camera = next(entity for entity, _ in world.query_one(Camera))
        world.add_component(camera, MotionBlur(shutter=1.0, objects=False))
        world.add_component(camera, DepthOfField(f_stop=1.4, autofocus=True, focus_point=(0.6, 0.5),
                                                 half_resolution=False))
    return made


def test_the_lens_and_the_motion_blur_read_the_drawn_seen_image_where_each_pixel_is(scene):
    """Temporal upsampling brings the picture up before depth of field and motion blur, which
    then run at the output's size reading the seen image at the drawn size: the focus found,
    each pixel's blur radius and each pixel's streak are those of the same frames drawn at
    full size (where the two sizes' pixels see the same thing)."""
    found = {}
    for scale in (1.0, 0.5):
        runner = runner_at(scene, SIZE, scale, "taa", build=panning(edge_scene))
        camera = next(entity for entity, _ in runner.world.query_one(Camera))
        for _ in range(4):
            runner.world.get(camera, Transform).position += glm.vec3(0.05, 0.0, 0.0)
            runner.frame()
        present = runner.engine.renderer.present_pass
        streaks = present.motion_blur._images.streaks
        assert streaks.size == SIZE
        found[scale] = (present.depth_of_field.focused(), present.depth_of_field.prepared_radii(),
                        np.frombuffer(streaks.read(), np.float16).reshape(SIZE[1], SIZE[0], 4)[..., :2])
        assert found[scale][1].shape == (SIZE[1], SIZE[0])
    assert found[0.5][0] == pytest.approx(found[1.0][0], rel=0.02)
    radius = np.abs(found[0.5][1].astype(float) - found[1.0][1].astype(float))
    assert np.median(radius) < 0.05 * np.abs(found[1.0][1].astype(float)).max() + 0.05, np.median(radius)
    streak = found[0.5][2].astype(float)[..., 0], found[1.0][2].astype(float)[..., 0]
    assert np.median(np.abs(streak[1])) > 0.5
    np.testing.assert_allclose(np.median(streak[0]), np.median(streak[1]), rtol=0.05)


def test_a_click_picks_at_the_drawn_size(scene, ctx):
    """The editor's click at an output pixel reads the id images at the drawn size: at half
    scale a click on the box seen in the mirror selects the box."""
    pytest.importorskip("imgui_bundle", reason="the debug overlay needs imgui-bundle (not installed here)")
    from shell.overlay import DebugOverlay
    from tests.test_level_edit import edit_scene
    from tests.test_mirrors import reflected_pixel
    from tests.test_pick import BOX

    ents = {}
    runner = runner_at(scene, (320, 240), build=lambda world: edit_scene(world, ents))
    runner.frame()
    x, y = reflected_pixel(runner, BOX)
    runner.engine.renderer.render_scale = 0.5
    runner.frame()
    assert runner.engine.renderer.targets.size == (160, 120)
    overlay = DebugOverlay(ctx)
    try:
        assert overlay.click(runner.engine, x, y)
        assert overlay.editor.selected == ents["box"]
    finally:
        overlay.release()


def test_the_command_line_scale_and_sharpening(scene, tmp_path, capsys):
    """``--render-scale 0.5 --sharpen 0.5``: frames of the output's size, ids of half of it; a
    scale out of range is refused by the command line, naming it; ``--frame-ms`` likewise."""
    from games.hall_of_mirrors.level import HallOfMirrors
    from shell.runner import parse_args

    out = tmp_path / "half"
    done = subprocess.run([sys.executable, "-m", "games.hall_of_mirrors", "--headless", "--frames", "1",
                           "--size", "160x90", "--ids", "--out", str(out), "--render-scale", "0.5",
                           "--sharpen", "0.5"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    picture = np.asarray(Image.open(out / "frame_0000.png"))
    assert picture.shape[:2] == (90, 160) and picture.std() > 10.0
    assert np.load(out / "ids_0000.npy").shape == (45, 80)
    for flag, value, words in (("--render-scale", "3", "Renderer.render_scale must be a number"),
                               ("--frame-ms", "0", "ViewBudget.frame_ms must be None or a finite number > 0")):
        with pytest.raises(SystemExit) as refused:
            parse_args(HallOfMirrors(), ["--headless", flag, value])
        assert refused.value.code == 2 and f"{flag} {value!r}: {words}" in capsys.readouterr().err
    # --frame-ms: the level's budget (its other fields kept) with the frame time; its effect is
    # tests/test_dynamic_resolution.py's.
    engine = scene(edge_scene, HALF).engine
    engine.world.resources[ViewBudget] = ViewBudget(views=7)
    engine.start_from(parse_args(HallOfMirrors(), ["--headless", "--frame-ms", "12.5"]))
    assert engine.world.resources[ViewBudget] == ViewBudget(views=7, frame_ms=12.5)

