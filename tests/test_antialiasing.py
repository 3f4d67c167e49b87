"""Anti-aliasing (``Renderer.antialias``, ``engine/render/present.py``): FXAA on the final
colour, on by default.  A tilted edge gets intermediate colours with it and none without;
the id image is the same either way; the setting and the runner's ``--aa`` refuse what
they do not know."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from pyglm import glm

from components import Camera, Emissive, Material, MeshRef, Transform
from engine.assets.mesh import box
from engine.render.present import MAX_SEARCH_STEPS
from tests.support import linear_to_srgb8, run_level, srgb_to_linear

ROOT = Path(__file__).resolve().parents[1]
SIZE = (160, 120)


def tilted_box(degrees: float):
    """A flat-coloured (emissive, unlit) card facing the camera, turned ``degrees`` about the
    view axis, on the flat background: two colours and nothing between them without AA."""
    def build(world):
        world.spawn(Transform(position=(0.0, 0.0, 6.0)), Camera(fov_y=40.0))
        world.spawn(Transform(rotation=glm.angleAxis(glm.radians(degrees), glm.vec3(0, 0, 1))),
                    MeshRef(box((2.4, 1.6, 0.1))), Material(color=(0.9, 0.7, 0.3)), Emissive(1.0))
    return build


def frames(runner, *modes):
    """The frame and id image for each ``antialias`` mode, in order."""
    out = []
    for mode in modes:
        runner.engine.renderer.antialias = mode
        out.append((runner.frame().astype(int), runner.ids()))
    return out


def outline(ids):
    """Pixels whose 4-neighbourhood sees both the card and the background."""
    inside = ids != 0
    found = np.zeros_like(inside)
    found[1:] |= inside[1:] != inside[:-1]
    found[:-1] |= inside[1:] != inside[:-1]
    found[:, 1:] |= inside[:, 1:] != inside[:, :-1]
    found[:, :-1] |= inside[:, 1:] != inside[:, :-1]
    return found


def between(frame, low, high):
    """Pixels strictly between two colours in every channel that differs (a blend of them)."""
    lo, hi = np.minimum(low, high), np.maximum(low, high)
    inside = ((frame >= lo) & (frame <= hi)).all(axis=2)
    return inside & (frame != low).any(axis=2) & (frame != high).any(axis=2)


def test_a_tilted_edge_gets_intermediate_colours_with_aa_and_none_without(scene):
    runner = scene(tilted_box(10.0), SIZE)
    (off, ids_off), (fxaa, ids_fxaa) = frames(runner, "off", "fxaa")
    colours = np.unique(off.reshape(-1, 3), axis=0)
    assert len(colours) == 2, f"without AA the frame is two colours, got {len(colours)}"
    background, card = off[0, 0], off[SIZE[1] // 2, SIZE[0] // 2]
    assert (background != card).any()
    np.testing.assert_array_equal(ids_fxaa, ids_off)

    edge = outline(ids_off)
    blended = between(fxaa, background, card)
    assert blended[edge].sum() > 0.25 * edge.sum(), (blended[edge].sum(), edge.sum())
    np.testing.assert_array_equal(fxaa[~edge], off[~edge])  # away from the outline nothing moved


def test_the_edge_walk_brings_a_long_nearly_level_edge_closer_to_its_coverage(scene):
    """A GPU's FXAA walks along an edge (``search_steps``; none on a software rasteriser):
    on a 3-degree edge, a staircase of 19-pixel steps, it shades each step's pixels by
    their distance from its end.  Against a 4x4-supersampled frame (the pixels' true
    coverage) the walk is clearly closer along the outline than no AA and than the
    small-feature blend alone (which helps on steeper edges, not on this one: measured
    off / blend / walk 19.6 / 19.8 / 15.5 levels here, 20.1 / 17.0 / 15.1 at 10 degrees)."""
    runner = scene(tilted_box(3.0), SIZE)
    present = runner.engine.renderer.present_pass
    present.search_steps = 0
    (off, ids_off), (short, _) = frames(runner, "off", "fxaa")
    present.search_steps = MAX_SEARCH_STEPS
    ((walked, ids_walked),) = frames(runner, "fxaa")
    np.testing.assert_array_equal(ids_walked, ids_off)

    big = scene(tilted_box(3.0), (SIZE[0] * 4, SIZE[1] * 4))
    big.engine.renderer.antialias = "off"
    w, h = SIZE
    coverage = linear_to_srgb8(srgb_to_linear(big.frame()).reshape(h, 4, w, 4, 3).mean(axis=(1, 3)))
    edge = outline(ids_off)
    error = {name: np.abs(frame - coverage)[edge].mean() for name, frame in
             (("off", off), ("short", short), ("walked", walked))}
    assert error["walked"] < 0.85 * min(error["short"], error["off"]), error


def test_present_fills_the_output_whatever_viewport_it_finds(scene, ctx):
    """The FXAA pass sets its own viewport: a framebuffer's use() brings back the viewport
    last set while moderngl took it for bound (a raw-GL mip pass leaves a cube face's)."""
    runner = scene(tilted_box(10.0), SIZE)
    runner.engine.renderer.antialias = "fxaa"
    expected = runner.frame()
    runner.capture.framebuffer.use()
    ctx.viewport = (0, 0, 4, 4)
    runner.capture.framebuffer.clear(1.0, 0.0, 1.0, 1.0)
    runner.engine.renderer.present(runner.capture.framebuffer, SIZE)
    np.testing.assert_array_equal(runner.capture.read_rgb(), expected)


def test_the_settings_refuse_what_they_do_not_know(scene):
    runner = scene(tilted_box(10.0), SIZE)
    renderer = runner.engine.renderer
    assert renderer.antialias == "fxaa"  # on by default
    with pytest.raises(ValueError, match=r"antialias must be one of 'fxaa', 'taa', 'off', got 'msaa'"):
        renderer.antialias = "msaa"
    with pytest.raises(ValueError, match=r"search_steps must be an int from 0 to 8, got 9"):
        renderer.present_pass.search_steps = 9
    assert renderer.antialias == "fxaa" and renderer.present_pass.search_steps in (0, MAX_SEARCH_STEPS)


def test_runner_aa_flag(tmp_path, capsys):
    """``--aa off`` and ``--aa fxaa`` write the same ids; the frames differ, only at edges;
    ``--aa taa`` (its third frame) likewise, its ids moved by its sub-pixel offsets at edges
    alone; an unknown mode is refused by the command line."""
    written = {}
    for mode in ("off", "fxaa", "taa"):
        out = tmp_path / mode
        done = run_level("--headless", "--frames", "3", "--size", "160x90", "--ids", "--out", str(out), "--aa", mode)
        assert done.returncode == 0, done.stderr
        written[mode] = (np.asarray(Image.open(out / "frame_0002.png")).astype(int), np.load(out / "ids_0002.npy"))
    np.testing.assert_array_equal(written["off"][1], written["fxaa"][1])
    for mode in ("fxaa", "taa"):
        changed = np.abs(written["off"][0] - written[mode][0]).max(axis=2) > 8
        assert 0.005 < changed.mean() < 0.5, (mode, changed.mean())
    assert (written["off"][1] == written["taa"][1]).mean() > 0.9
    from games.hall_of_mirrors.level import HallOfMirrors
    from shell.runner import parse_args

    with pytest.raises(SystemExit) as refused:
        parse_args(HallOfMirrors(), ["--headless", "--aa", "msaa"])
    assert refused.value.code == 2 and "--aa: invalid choice: 'msaa'" in capsys.readouterr().err
