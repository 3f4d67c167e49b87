"""Each pass sets the GL state it needs when it starts: run after any other pass, or after
any state at all, it draws the same pixels.  The state is cached (``bindings.apply_pass_state``
sets only what changed): state set outside the engine is followed by ``invalidate``, except
the viewport, scissor and bound framebuffer set through moderngl, which the cache reads from
moderngl and so needs no invalidate (the ``rects_only`` run scrambles only those).

Checked by breaking ``apply_pass_state``: leaving flags enabled (``enable`` instead of
``enable_only``) or the depth function unset fails here.  Two breakages pass on llvmpipe
and are not observable by this test: an unset viewport (moderngl's ``Framebuffer.use``
sets it) and clip distances left enabled that a pass's shader does not write (llvmpipe
reads them as 0, which clips nothing; a GPU may not)."""
from __future__ import annotations

import random

import moderngl
import numpy as np
import pytest

from engine.core.frame_io import Output
from engine.render.bindings import invalidate
from engine.render.targets import CaptureTarget
from games.hall_of_mirrors.level import HallOfMirrors
from tests.support import SceneRunner

SIZE = (192, 108)
CAMERAS = ((0.0, 1.7, 6.5, 0.0, -8.0), (-1.5, 1.6, -1.0, 10.0, 0.0), (2.5, 1.5, 2.0, -50.0, -5.0))


def hall(ctx) -> SceneRunner:
    level = HallOfMirrors()
    return SceneRunner(ctx, level.build, SIZE, update=level.update)


def frames(runner: SceneRunner) -> list[tuple[np.ndarray, np.ndarray]]:
    shots = []
    for camera in CAMERAS:
        runner.engine.place_camera(*camera)
        shots.append((runner.frame(), runner.ids()))
    return shots


def scrambled(ctx, rng: random.Random, other: SceneRunner, scratch: CaptureTarget, rects_only: bool = False):
    """Before each pass: another engine's pass (its scene pass or its present), then GL
    state set at random (flags, depth and blend functions, winding, clip distances, then
    ``invalidate``; or, ``rects_only``, none of these), then scissor, viewport and bound
    framebuffer through moderngl."""
    def before():
        if rng.random() < 0.5:
            if other.engine.main_view is not None:
                other.engine.renderer.scene_pass.draw([other.engine.main_view],
                                                      other.engine.renderer.targets)
        else:
            other.engine.renderer.present(scratch.framebuffer, scratch.size)
        if not rects_only:
            scramble_fixed_function(ctx, rng)
            invalidate(ctx)
        ctx.scissor = (rng.randrange(50), rng.randrange(30), rng.randrange(1, 60), rng.randrange(1, 40))
        ctx.viewport = (rng.randrange(20), rng.randrange(20), rng.randrange(1, 100), rng.randrange(1, 60))
        scratch.framebuffer.use()

    def wrap(owner, name):
        method = getattr(owner, name)

        def wrapped(*args, **kwargs):
            before()
            return method(*args, **kwargs)
        setattr(owner, name, wrapped)
    return wrap


def scramble_fixed_function(ctx, rng: random.Random) -> None:
    """Flags, depth and blend functions, winding and clip distances set at random."""
    flags = moderngl.NOTHING
    for flag in (moderngl.DEPTH_TEST, moderngl.CULL_FACE, moderngl.BLEND):
        if rng.random() < 0.5:
            flags |= flag
    ctx.enable_only(flags)
    ctx.depth_func = rng.choice(["<", "<=", ">", "1", "0"])
    ctx.blend_func = rng.choice([moderngl.ADDITIVE_BLENDING, moderngl.PREMULTIPLIED_ALPHA,
                                 (moderngl.ONE, moderngl.ZERO)])
    ctx.front_face = rng.choice(["cw", "ccw"])
    for index in range(6):
        (ctx.enable_direct if rng.random() < 0.5 else ctx.disable_direct)(0x3000 + index)


@pytest.mark.parametrize("rects_only", [False, True], ids=["all_state", "rects_only"])
def test_passes_draw_the_same_pixels_whatever_ran_before_them(ctx, rects_only):
    plain = hall(ctx)
    try:
        expected = frames(plain)
    finally:
        plain.close()

    shuffled, other = hall(ctx), hall(ctx)
    scratch = CaptureTarget(ctx, (64, 48))
    try:
        other.engine.place_camera(*CAMERAS[1])
        other.engine.frame(1 / 60, Output(other.capture.framebuffer, SIZE))
        wrap = scrambled(ctx, random.Random(7), other, scratch, rects_only)
        renderer = shuffled.engine.renderer
        passes = shuffled.engine.reflection_system.tree.passes
        for owner, name in ((renderer.scene_pass, "draw"), (passes, "prepare_level"), (passes, "composite_level"),
                            (passes.rough_atlas, "isolate"), (renderer, "present")):
            wrap(owner, name)
        got = frames(shuffled)
    finally:
        scratch.release()
        other.close()
        shuffled.close()
    assert shuffled.stats.reflection_views > 0
    for (rgb, ids), (want_rgb, want_ids) in zip(got, expected, strict=True):
        np.testing.assert_array_equal(ids, want_ids)
        np.testing.assert_array_equal(rgb, want_rgb)


def test_the_sky_pass_enables_no_clip_distance_its_shaders_do_not_write():
    """A clip distance that is on but not written by the shaders is undefined in OpenGL
    (llvmpipe reads 0 and keeps the pixel; a GPU may clip it away): the sky's shaders write
    none, so its passes turn none on."""
    from pathlib import Path

    from engine.render import scene_pass

    shaders = Path(__file__).resolve().parents[1] / "shaders"
    for state, files in ((scene_pass._SKY, ("sky.vert",)), (scene_pass._LAYERED_SKY, ("sky.vert", "sky_layered.geom"))):
        writes = any("gl_ClipDistance" in (shaders / name).read_text() for name in files)
        assert writes or not state.clips, (files, state.clips)
