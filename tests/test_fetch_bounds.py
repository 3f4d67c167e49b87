"""Every ``texelFetch`` the engine's shaders run stays inside its texture, or its value does
not matter (the pixel is discarded, a select throws it away): out of range, GL 4.1 core
leaves the result undefined, and where llvmpipe returns zeros a GPU may return garbage.

The second path (``tests/fetch_bounds.py``): the same frames built with every fetch bounded,
an outside one returning a poison (a float of 4093, a uint that is no id), must be the
frames of the plain build bit for bit, colour and ids.  The scenes are those where level
and texture sizes part: odd frame sizes (161x97, 97x161), a resize mid-run, the pixel
budget drawing levels downscaled (and at two sizes in turn), mirrors at resolution scales
that divide nothing, rough mirrors (the atlas copy), water and normal-mapped composites (the
bent lookup), end images (the fallback's look into the child level), portals, probes, post
(present's and FXAA's fetches), a render scale (temporal upsampling, the lens and motion
blur reading the smaller seen image, the upscale), the selection outline.

Broken on purpose: the claim reading its parent one pixel to the right (``px + ivec2(1, 0)``
in mirror_claim.frag) fails hall_start, hall_mirror_wall and hall_doorway with the edge
mode (374, 1 and 709 pixels of frame 0): past the parent's last column the edge texel is a
surface the claim takes, where llvmpipe's zero is none (the constant poison, no id either,
passes: the check needs both modes).  Without the water's bent lookup's rectangle test
(mirror_composite.frag), hall_start's ids differ at 2 pixels with the edge mode.
"""
from __future__ import annotations

from collections.abc import Callable

import moderngl
import numpy as np
import pytest

from engine.render.targets import release_framebuffer
from engine.resources import ViewBudget
from tests.fetch_bounds import MODES, POISON_UINT, poisoned_fetches
from tests.golden_scenes import cases
from tests.support import engine_frames

DT = 1.0 / 60.0
ODD = ((161, 97), (97, 161), (161, 97))
CASE_BY_NAME = {case.name: case for case in cases()}


def _run(ctx: moderngl.Context, game, sizes, frames: int, setup=None, budget: float | None = None,
         step=None) -> tuple[list[np.ndarray], int]:
    """``game`` run ``frames`` frames at each of ``sizes`` (a resize between), from the
    second frame on with a pixel budget of ``budget`` x the reflection pixels the first drew,
    halved every other frame (levels downscaled, and drawn at two sizes in turn); every
    size's last frame and ids, and the levels downscaled over the run."""
    seen = {"full": None, "downscaled": 0}

    def configure(engine) -> None:
        engine.renderer.present_pass.search_steps = 2  # FXAA's walk too (textureGather, its clamped fetches)
        if setup is not None:
            setup(engine)

    def before(engine, count: int) -> None:
        if budget is not None and seen["full"]:
            pixels = max(1, int(budget * seen["full"] / (1 + count % 2)))
            engine.world.resources[ViewBudget] = ViewBudget(pixels=pixels)
        if step is not None:
            step(engine, count)

    def after(engine, count: int) -> None:
        stats = engine.renderer.stats
        seen["full"] = seen["full"] or stats.pixels_spent
        seen["downscaled"] += stats.levels_downscaled

    out = engine_frames(ctx, game, frames, sizes, configure, before, after, dt=DT)
    return out, seen["downscaled"]


def _case(name: str, budget: float | None = 0.6, frames: int = 3):
    def run(ctx):
        case = CASE_BY_NAME[name]

        def setup(engine):
            if case.camera is not None:
                engine.place_camera(*case.camera)
            if case.setup is not None:
                case.setup(engine)
        return _run(ctx, case.game(), ODD, frames, setup, budget)
    return run


def _ring_scaled(ctx):
    """Four mirrors at resolution scales that divide neither odd size, two of them rough
    (their atlas tiles)."""
    from benchmarks.mirrors import MirrorRing
    from components import Mirror

    def setup(engine):
        mirrors = sorted(engine.world.query_one(Mirror), key=lambda item: item[0])
        for (_, mirror), scale, rough in zip(mirrors, (0.37, 0.73, 0.61, 0.51), (0.0, 0.45, 0.0, 0.3),
                                                  strict=True):
            mirror.resolution_scale = scale
            mirror.roughness = rough
    return _run(ctx, MirrorRing(4), ODD, 3, setup, budget=0.6)


def _post(ctx):
    """Bloom and automatic exposure (present's fetch of the HDR image, the 1x1 exposure)."""
    from benchmarks.lighting import VARIANTS
    from benchmarks.mirrors import MirrorRing

    chosen = next(v for v in VARIANTS if v.name == "post_auto")
    return _run(ctx, MirrorRing(2), ODD, 3, chosen.configure, budget=0.5, step=chosen.step)


def _render_scaled(ctx):
    """A render scale that divides neither odd size: temporal upsampling (its nearest sample
    past an edge), then depth of field and motion blur reading the smaller seen image; at the
    second size FXAA and the Catmull-Rom upscale; sharpened throughout."""
    from benchmarks.mirrors import MirrorRing
    from components import DepthOfField, MotionBlur
    from engine.rules.frame_rules import active_camera_parts

    def setup(engine):
        renderer = engine.renderer
        renderer.render_scale, renderer.antialias, renderer.sharpness = 0.61, "taa", 0.4
        camera = active_camera_parts(engine.world)[0]
        engine.world.add_component(camera, DepthOfField(f_stop=1.4, autofocus=True))
        engine.world.add_component(camera, MotionBlur())

    def step(engine, count: int) -> None:   # (two frames a size: the second size's FXAA's)
        engine.renderer.antialias = "fxaa" if count // 2 == 1 else "taa"

    return _run(ctx, MirrorRing(2), ODD, 2, setup, budget=0.5, step=step)


def _probes(ctx):
    from benchmarks.probes import ProbeRing

    return _run(ctx, ProbeRing("every_frame", 32), ODD[:2], 2, budget=0.5)


SCENES: dict[str, Callable[[moderngl.Context], tuple[list[np.ndarray], int]]] = {
    "hall_start": _case("hall_start"),              # water (bent lookup), portals, probes
    "hall_mirror_wall": _case("hall_mirror_wall"),  # tinted, rough, the facing pair (end images)
    "hall_doorway": _case("hall_doorway"),
    "portals_depth_8": _case("portals_depth_8"),
    "ring_scaled": _ring_scaled,
    "post": _post,
    "render_scaled": _render_scaled,
    "probes": _probes,
}


@pytest.mark.parametrize("name", SCENES)
def test_no_fetch_leaves_its_texture(ctx, name):
    plain, downscaled = SCENES[name](ctx)
    assert plain[0].max() > 0, f"{name}: the frame is black"
    for mode in MODES:
        with poisoned_fetches(mode) as rewritten:
            poisoned, _ = SCENES[name](ctx)
        assert rewritten, "no program calls texelFetch: the hook saw nothing"
        for index, (a, b) in enumerate(zip(plain, poisoned, strict=True)):
            kind = "ids" if index % 2 else "colour"
            differ = a != b if a.ndim == 2 else (a != b).any(axis=-1)
            assert not differ.any(), (
                f"{name}: {kind} of frame {index // 2} ({a.shape[1]}x{a.shape[0]}) differs at {int(differ.sum())} "
                f"pixels with out-of-range texelFetch returning {mode} values (first at row, column "
                f"{tuple(int(v) for v in np.argwhere(differ)[0])}): a fetch outside its texture whose value is used")
    if name not in ("post", "probes", "render_scaled"):
        assert downscaled > 0, f"{name}: the pixel budget downscaled no level"


@pytest.mark.parametrize("mode,expected", [("constant", [5, POISON_UINT, POISON_UINT, POISON_UINT]),
                                           ("edge", [5, 5, 0, 3])])
def test_the_poison_shows_an_out_of_range_fetch(ctx, mode, expected):
    """The hook itself: a fetch inside reads its texel, one a texel past an edge the poison
    (or the edge's texel)."""
    from tests.fetch_bounds import with_prelude

    source = ("#version 410 core\nuniform usampler2D ids;\nuniform ivec2 at;\nout uvec4 value;\n"
              "void main() { value = texelFetch(ids, at, 0); }\n")
    vertex = ("#version 410 core\nvoid main() { gl_Position = vec4(vec2(gl_VertexID & 1, gl_VertexID >> 1) * 4.0 - 1.0,"
              " 0.0, 1.0); }\n")
    program = ctx.program(vertex_shader=vertex, fragment_shader=with_prelude(source, mode))
    ids = ctx.texture((3, 2), 1, np.arange(6, dtype=np.uint32).tobytes(), dtype="u4")
    ids.filter = (moderngl.NEAREST, moderngl.NEAREST)
    out = ctx.texture((1, 1), 4, dtype="u4")
    fbo = ctx.framebuffer([out])
    vao = ctx.vertex_array(program, [])
    try:
        ids.use(0)
        program["ids"].value = 0
        seen = []
        for at in ((2, 1), (3, 1), (-1, 0), (0, 2)):
            program["at"].value = at
            fbo.use()
            ctx.viewport = (0, 0, 1, 1)
            vao.render(moderngl.TRIANGLES, vertices=3)
            seen.append(int(np.frombuffer(out.read(), np.uint32)[0]))
        assert seen == expected
    finally:
        release_framebuffer(fbo)
        for obj in (vao, out, ids, program):
            obj.release()


# --- the invariants the shaders' fetches rest on -------------------------------------------------
def test_a_pixel_centre_scaled_into_another_level_lands_inside_it():
    """mirror_claim.frag (``gl_FragCoord * to_parent``), mirror_composite.frag
    (``* to_reflection``, a fallback's ``* to_child``): a pixel centre of a level ``c`` pixels
    wide times the float32 of ``p / c`` (Python's quotient, uploaded as a float) truncates to a
    pixel of the level ``p`` wide: the last centre, (c - 0.5) p / c = p - p / 2c, lies half a
    source pixel inside, far more than float32's rounding.  Every pair of sizes up to 2048,
    and random ones up to GL's 16384."""
    sizes = np.arange(1, 2049, dtype=np.float64)
    grid = np.meshgrid(sizes, sizes, indexing="ij")
    rng = np.random.default_rng(3)
    big = rng.integers(1, 16385, (2, 200_000)).astype(np.float64)
    for p, c in ((grid[0].ravel(), grid[1].ravel()), (big[0], big[1])):
        scale = (p / c).astype(np.float32)
        last = np.float32(c - 0.5).astype(np.float32) * scale  # float32 product, as the GPU's
        assert last.dtype == np.float32
        assert (last.astype(np.int64) <= p - 1).all()


def test_a_views_rectangle_in_a_level_of_another_size_stays_inside_it():
    """mirror_composite.frag's bent lookup (water, normal maps) fetches wherever the bent ray
    lands once it is inside the view's rectangle in the level (``v_rect``), and
    rough_isolate.frag copies inside it: ``level_rects`` keeps every rectangle of the screen
    inside every level size the pixel budget and resolution scales make (``_level_size``)."""
    from engine.render.view_plan import _level_size, level_rects

    rng = np.random.default_rng(5)
    for _ in range(300):
        screen = (int(rng.integers(1, 400)), int(rng.integers(1, 400)))
        level = _level_size(screen, float(rng.uniform(0.1, 1.0)))
        x0 = rng.integers(0, screen[0], 50)
        y0 = rng.integers(0, screen[1], 50)
        x1 = x0 + 1 + (rng.integers(0, screen[0], 50) % (screen[0] - x0))
        y1 = y0 + 1 + (rng.integers(0, screen[1], 50) % (screen[1] - y0))
        rects = level_rects(np.stack([x0, y0, x1, y1], axis=1).astype(np.float64), screen, level)
        assert (rects[:, 0:2] >= 0).all() and (rects[:, 2:4] >= 1).all()
        assert (rects[:, 0] + rects[:, 2] <= level[0]).all() and (rects[:, 1] + rects[:, 3] <= level[1]).all(), (
            screen, level)

