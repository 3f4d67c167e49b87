"""Helpers shared by the system tests: run a level on the test context, read pixels back."""
from __future__ import annotations

import contextlib
import io
import os
import runpy
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import moderngl
import numpy as np
import pytest
from pyglm import glm

from components import Camera, ReflectionProbe, Transform, look_rotation
from engine.core.frame_io import Output
from engine.core.game import Game
from engine.render.shader_library import FreePrograms
from engine.render.targets import CaptureTarget
from shell.app import Engine

ROOT = Path(__file__).resolve().parents[1]


@contextlib.contextmanager
def programs_linked_anew(ctx: moderngl.Context | None = None) -> Iterator[FreePrograms]:
    """Inside: every shader library made links its own programs, and hands them to a free
    list of its own, released at the end (``FreePrograms``): for hooks on
    ``moderngl.Context.program`` that must see every program an engine uses, and whose
    programs (rewritten, recorded) must not be handed to engines made after.  The list
    yielded is ``ctx``'s (None: the first context an engine asks for); an engine on any
    other context (a test's own, a benchmark's) gives its programs back to a list that
    releases them at once: one list for two contexts handed a program linked on one to an
    engine on the other (moderngl: "the program belongs to a different context")."""
    own = FreePrograms()
    owner = [ctx] if ctx is not None else []
    of = FreePrograms.__dict__["of"]

    def per_context(cls, asking: moderngl.Context) -> FreePrograms:
        if not owner:
            owner.append(asking)
        if asking is owner[0]:
            return own
        unkept = FreePrograms()
        unkept.released = True  # (given back, released: none kept for another engine)
        return unkept

    FreePrograms.of = classmethod(per_context)
    try:
        yield own
    finally:
        FreePrograms.of = of
        own.release()


class FunctionGame(Game):
    """A Game whose level is one function (and an optional per-frame update)."""

    def __init__(self, build, update=None) -> None:
        self._build = build
        self._update = update

    def build(self, world) -> None:
        self._build(world)

    def update(self, world, dt: float) -> None:
        if self._update:
            self._update(world, dt)


class SceneRunner:
    """An Engine rendering into an RGBA8 capture target of ``size``."""

    def __init__(self, ctx, build, size=(160, 120), update=None) -> None:
        self.ctx = ctx
        self.size = size
        self.engine = Engine(FunctionGame(build, update), ctx)
        self.world = self.engine.world
        self.capture = CaptureTarget(ctx, size)
        self._closed = False

    def frame(self, dt: float = 1.0 / 60.0) -> np.ndarray:
        """Render one frame; sRGB uint8 (h, w, 3), row 0 at the top."""
        self.engine.frame(dt, Output(self.capture.framebuffer, self.size))
        return self.capture.read_rgb()

    def ids(self) -> np.ndarray:
        return self.engine.renderer.targets.read_ids()

    @property
    def stats(self):
        return self.engine.renderer.stats

    def project(self, point) -> tuple[int, int]:
        """Pixel (column, row from the top) where world ``point`` lands in the main view."""
        view = self.engine.main_view
        clip = view.view_proj * glm.vec4(glm.vec3(point), 1.0)
        ndc = glm.vec3(clip) / clip.w
        w, h = self.size
        return int((ndc.x * 0.5 + 0.5) * w), int((1.0 - (ndc.y * 0.5 + 0.5)) * h)

    def close(self) -> None:
        if not self._closed:
            self.capture.release()
            self.engine.close()
            self._closed = True


def own_mesh(mesh):
    """The same vertices as a mesh of its own (made from arrays): the renderer draws it in a
    batch of its own, where a generated box, quad or sphere shares its shape's unit mesh."""
    from engine.assets.mesh import Mesh

    return Mesh(mesh.positions.copy(), mesh.normals.copy(), mesh.uvs.copy(), mesh.indices.copy(), name=mesh.name)


def probe_face_of(view) -> int | None:
    """The cube face a probe's face view draws (``engine.render.probes.face_view`` names it
    "probe face N"; its ``node`` is 0, as its own tree's root), or None for another view."""
    prefix = "probe face "
    return int(view.name.removeprefix(prefix)) if view.name.startswith(prefix) else None


_SPLIT_GRID = np.linspace(0.0, 1.0, 513)
_split_tables: dict[float, np.ndarray] = {}


def split_sum(roughness: float, nv) -> np.ndarray:
    """``environment_brdf(roughness, nv)`` (its (A, B), shape (..., 2)) for many n.v at one
    roughness, read linearly off a 513-entry table of it made once a roughness: within 1e-4 of
    the integral itself, for a fraction of its cost (2048 half vectors a pixel)."""
    from engine.render.environment_brdf import environment_brdf

    table = _split_tables.get(float(roughness))
    if table is None:
        table = _split_tables[float(roughness)] = environment_brdf(float(roughness), _SPLIT_GRID)
    nv = np.asarray(nv, np.float64)
    return np.stack([np.interp(nv, _SPLIT_GRID, table[:, i]) for i in range(2)], -1)


def srgb_to_linear(values) -> np.ndarray:
    c = np.asarray(values, np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb8(values) -> np.ndarray:
    c = np.clip(np.asarray(values, np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, c * 12.92, 1.055 * c ** (1 / 2.4) - 0.055) * 255.0


def look_from(world, eye, target=(0, 1.5, 0), fov: float = 60.0) -> int:
    """A camera entity at ``eye`` looking at ``target``."""
    eye = glm.vec3(eye)
    return world.spawn(Transform(position=eye, rotation=look_rotation(glm.vec3(target) - eye)), Camera(fov_y=fov))


def skip_unless_trusted(renderer, path: str) -> None:
    """Skip a test of ``path``'s own output where this context's self-check does not trust it
    (``engine/render/path_checks.py``): the NVIDIA H200's driver writes only face 0 of a
    layered cube-map attachment, so the engine draws the plain path there and a test of the
    layered output has nothing to test.  On llvmpipe every path is verified
    (``tests/test_path_checks.py`` holds it to that), so these tests always run in CI."""
    checks = renderer.path_checks
    if not checks.trusted(path):
        verdict = checks.verdicts[path]
        pytest.skip(f"{path} is {verdict.status} on {renderer.ctx.info['GL_RENDERER']}: {verdict.detail}")


# The largest motion on the picture (0.5 x NDC) a still thing may carry: a GPU's fused
# multiply-adds project one point by two equal matrices a little apart (the NVIDIA H200's
# driver 580: 1.5e-8), where llvmpipe gives exactly 0.  A millionth of the picture is a
# hundredth of a pixel at the largest target a context allows (16384 pixels a side).
STILL_MOTION = 1e-6


def still_motion(motion: np.ndarray) -> bool:
    """Whether a motion image (``RenderTargets.read_motion``) moves nothing (``STILL_MOTION``)."""
    return float(np.abs(motion).max()) < STILL_MOTION


def skip_unless_layered(renderer) -> None:
    """Skip a test of a layered cube draw where this context draws cubes a face a pass (both
    layered targets refused by the self-check: ``gpu.layered_target`` None)."""
    from engine.render.gpu import layered_target

    if layered_target(renderer.path_checks) is None:
        verdicts = renderer.path_checks.verdicts
        pytest.skip(f"no layered cube draw on {renderer.ctx.info['GL_RENDERER']}: "
                    f"{verdicts['layered_capture'].detail}; {verdicts['layered_array_capture'].detail}")


def six_pass_only(monkeypatch) -> None:
    """Make every renderer refuse both layered cube draws (into the cube map and into a 2D
    array copied into it: ``gpu.layered_target`` None), so cubes are drawn a face a pass."""
    from engine.render.path_checks import PathChecks

    real = PathChecks.trusted
    monkeypatch.setattr(PathChecks, "trusted", lambda self, name: False if name in (
        "layered_capture", "layered_array_capture") else real(self, name))


def pixel_rays(view, size) -> tuple[np.ndarray, np.ndarray]:
    """Eye and unit direction (float64) through each pixel centre of ``view`` at ``size``,
    rows from the top: the primary rays a second computation casts."""
    w, h = size
    inverse = np.array(glm.inverse(glm.dmat4(view.view_proj)).to_list(), np.float64).T
    xs = (np.arange(w) + 0.5) / w * 2.0 - 1.0
    ys = 1.0 - (np.arange(h) + 0.5) / h * 2.0
    gx, gy = np.meshgrid(xs, ys)
    far = np.stack([gx, gy, np.ones_like(gx), np.ones_like(gx)], axis=-1) @ inverse.T
    far = far[..., :3] / far[..., 3:]
    eye = np.array(view.eye, np.float64)
    direction = far - eye
    return eye, direction / np.linalg.norm(direction, axis=-1, keepdims=True)


def box_hits(origin: np.ndarray, direction: np.ndarray, centre: np.ndarray, half: np.ndarray,
             limit: np.ndarray | None = None) -> np.ndarray:
    """Whether rays (rows) from ``origin`` along ``direction`` meet the axis-aligned box
    (``centre``, ``half`` sizes) ahead of them, before ``limit`` (in units of ``direction``)
    if given: the slab test, in float64."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (centre - half - origin) / direction
        t2 = (centre + half - origin) / direction
    near = np.nanmax(np.minimum(t1, t2), axis=1)
    far = np.nanmin(np.maximum(t1, t2), axis=1)
    hit = (near <= far) & (far > 1e-6)
    if limit is not None:
        hit &= near < limit
    return hit


def pcf_edge_profile(t: np.ndarray, softness: float) -> np.ndarray:
    """The light a grid-filtered shadow map (``shaders/include/shadows.glsl`` filtered_shadow,
    "grid") leaves at ``t`` map texels from a straight shadow edge's middle, towards the lit
    side: a bilinear comparison ramps over one texel (between the two texel centres astride
    the edge), and the grid's taps (2 a side, 3 past a softness of 1) spread ``softness``
    texels apart average that ramp shifted to each: ``softness`` + 1 texels from dark to lit."""
    n = 3 if softness > 1.0 else 2
    offsets = (np.arange(n) - (n - 1) / 2.0) * (softness / (n - 1))
    return np.mean([np.clip(t - o + 0.5, 0.0, 1.0) for o in offsets], axis=0)


def drawn_over_near_depth(runner, atlas: moderngl.Texture, shining) -> np.ndarray:
    """The frame whose map is drawn again into ``atlas`` (a depth texture) after the whole of
    it was cleared to the near depth, as texels no draw wrote may hold on a GPU (llvmpipe
    zero-fills a new one, a reused one holds an earlier engine's maps): ``shining(False)``
    for a frame, then ``shining(True)`` (the map's owner turned off and on: drawn again)."""
    cleared = runner.ctx.framebuffer(depth_attachment=atlas)
    cleared.clear(depth=0.0)
    cleared.release()
    shining(False)
    runner.frame()
    shining(True)
    return runner.frame()


def kept_frames_equal_drawn(keeping, drawing, frames: int = 4) -> int:
    """Run two scene runners (``conftest.scene``) of the same scene side by side, ``drawing``
    with ``keep_still_views`` off, asserting every frame's colour, HDR image and ids equal bit
    for bit; returns how many of ``keeping``'s frames kept their reflection levels (the
    drawing runner must keep none)."""
    drawing.engine.reflection_system.keep_still_views = False
    kept = 0
    for _ in range(frames):
        images = []
        for runner in (keeping, drawing):
            rgb = runner.frame()
            images.append((rgb, np.frombuffer(runner.engine.renderer.targets.color.read(), np.float16), runner.ids()))
        for kept_image, drawn_image in zip(images[0], images[1], strict=True):
            assert np.array_equal(kept_image, drawn_image)
        kept += keeping.stats.reflection_views_kept > 0
        assert drawing.stats.reflection_views_kept == 0
    return kept


def engine_frames(ctx, game, frames: int, sizes, configure=None, step=None, after=None,
                  dt: float = 1.0 / 60.0) -> list[np.ndarray]:
    """Run ``game`` for ``frames`` frames at each of ``sizes`` in turn (a resize between):
    ``configure(engine)`` once first, ``step(engine, i)`` before and ``after(engine, i)``
    after frame i (counted over the whole run); every size's last frame and ids."""
    engine = Engine(game, ctx)
    out = []
    try:
        if configure is not None:
            configure(engine)
        count = 0
        for size in sizes:
            capture = CaptureTarget(ctx, size)
            try:
                for _ in range(frames):
                    if step is not None:
                        step(engine, count)
                    engine.frame(dt, Output(capture.framebuffer, size))
                    if after is not None:
                        after(engine, count)
                    count += 1
                out += [capture.read_rgb(), engine.renderer.targets.read_ids()]
            finally:
                capture.release()
    finally:
        engine.close()
    return out


def green_and_rays(scene, build, size) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``build``'s second frame at ``size`` (FXAA off) as linear green, a value a pixel, rows
    from the top, with the eye and each pixel's unit ray (``pixel_rays``): what a test that
    casts the pixels' rays at a surface compares."""
    runner = scene(build, size)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    shown = srgb_to_linear(runner.frame())[..., 1].reshape(-1)
    eye, rays = pixel_rays(runner.engine.main_view, size)
    return shown, eye, rays.reshape(-1, 3)


def camera_level_round_trip(tmp_path, tables: str, bad: tuple[str, str], match: str):
    """A level file of one camera entity with ``tables`` (its component lines, as a level file
    writes them) read, saved and read again (``entity_level_round_trip``): the world read again
    and the camera's entity there; the same text with ``bad`` (old, new) put in is refused on
    load with a LevelError matching ``match``."""
    return entity_level_round_trip(tmp_path, "Transform = { position = [0.0, 1.5, 4.0] }\nCamera = {}\n" + tables,
                                   bad, match)


def entity_level_round_trip(tmp_path, tables: str, bad: tuple[str, str], match: str):
    """A level file of one entity, "it", with ``tables`` (its component lines, as a level file
    writes them) read, saved and read again: returns the world read again and the entity
    there.  The same text with ``bad`` (old, new) put in is refused on load with a LevelError
    matching ``match`` (the field's name)."""
    from engine.assets.level_file import LevelError, load_level, save_level
    from engine.core.world import World

    text = '[level]\nname = "it"\n\n[[entity]]\nname = "it"\n' + tables.strip() + "\n"
    (tmp_path / "it.toml").write_text(text)
    world = World()
    saved = save_level(world, tmp_path / "again.toml", load_level(tmp_path / "it.toml").spawn(world), name="it")
    again = World()
    entity = load_level(saved).spawn(again)["it"]
    assert bad[0] in text
    (tmp_path / "bad.toml").write_text(text.replace(*bad))
    with pytest.raises(LevelError, match=match):
        load_level(tmp_path / "bad.toml").spawn(World())
    return again, entity


def fragment_row(ctx, source: str, width: int, defines: dict | None = None, bind=None) -> np.ndarray:
    """Fragment shader ``source`` (its whole text; its includes found in ``shaders/``) run once
    a pixel over a ``width`` x 1 float target, read back as (width, 4) float32: how a test reads
    the GLSL's own numbers.  ``bind(program)`` binds the program's inputs and returns the GL
    objects to release after."""
    import pathlib
    import tempfile

    from engine.render.bindings import invalidate
    from engine.render.shader_library import load_source
    from engine.render.targets import release_framebuffer

    with tempfile.TemporaryDirectory() as folder:
        path = pathlib.Path(folder) / "reader.frag"
        path.write_text(source)
        fragment = load_source(str(path), defines or {})
    vertex = "#version 410 core\nvoid main() { gl_Position = vec4(vec2[3](vec2(-1,-1), vec2(3,-1), " \
             "vec2(-1,3))[gl_VertexID], 0.0, 1.0); }"
    program = ctx.program(vertex_shader=vertex, fragment_shader=fragment)
    target = ctx.texture((width, 1), 4, dtype="f4")
    framebuffer = ctx.framebuffer([target])
    vao = ctx.vertex_array(program, [])
    made: list = []
    try:
        made = list(bind(program) if bind is not None else [])
        framebuffer.use()
        ctx.viewport = (0, 0, width, 1)
        ctx.disable(ctx.DEPTH_TEST | ctx.CULL_FACE | ctx.BLEND)
        vao.render(vertices=3)
        return np.frombuffer(target.read(), np.float32).reshape(width, 4).copy()
    finally:
        release_framebuffer(framebuffer)
        for obj in (vao, target, program, *made):
            obj.release()
        invalidate(ctx)


def ball_normals(size: int, fov: float = 30.0, distance: float = 3.0, radius: float = 0.5,
                 margin: float = 0.08) -> tuple[np.ndarray, np.ndarray]:
    """(inside, normal) for a ball of ``radius`` at the origin seen from (0, 0, ``distance``)
    looking down -Z with a ``fov`` degree square view of ``size`` pixels: each pixel's ray met
    with the sphere; ``inside`` the pixels whose ray meets it by more than ``margin`` (the
    discriminant: away from the outline), ``normal`` there (size, size, 3)."""
    half = np.tan(np.radians(fov / 2.0))
    rows, columns = np.mgrid[0:size, 0:size]
    ray = np.stack([((columns + 0.5) / (size / 2) - 1) * half, (1 - (rows + 0.5) / (size / 2)) * half,
                    -np.ones((size, size))], -1)
    ray /= np.linalg.norm(ray, axis=-1, keepdims=True)
    eye = np.array([0.0, 0.0, distance])
    b = ray @ eye
    disc = b * b - (eye @ eye - radius * radius)
    normal = (eye + ray * (-b - np.sqrt(np.maximum(disc, 0.0)))[..., None]) / radius
    return disc > margin, normal


def grey_ball_under_sky(scene, faces: np.ndarray, *lights, size: int = 64) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A matte grey ball (albedo 0.8, diffuse only, radius 0.5) under a Skybox of ``faces`` and
    ``lights``, seen as ``ball_normals`` sees it: (the frame's linear colours, inside, normal)."""
    from components import Material, MeshRef, Skybox
    from engine.assets.mesh import sphere

    def ball(world):
        look_from(world, (0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov=30.0)
        world.spawn(Skybox(faces=faces))
        for light in lights:
            world.spawn(light)
        world.spawn(Transform(), MeshRef(sphere(0.5, 64, 32)),
                    Material(color=(0.8, 0.8, 0.8, 1.0), reflectance=0.0, roughness=1.0, environment_reflection=0.0))
    runner = scene(ball, (size, size))
    runner.frame()
    return (srgb_to_linear(runner.frame()), *ball_normals(size))


def run_level(*args: str, env_extra: dict | None = None) -> subprocess.CompletedProcess:
    """``python -m games.hall_of_mirrors ARGS``: its exit status and what it printed.  Run in
    this process as ``python -m`` runs the module (``runpy``, ``sys.argv`` set: the engine's
    imports and shader sources are this process's already, a second or two of each run), or
    in a process of its own where ``env_extra`` changes its environment.  (tests/test_runner.py's
    first test starts a real ``python -m`` as a user does.)"""
    if env_extra is not None:
        return run_level_process(*args, env_extra=env_extra)
    out, err = io.StringIO(), io.StringIO()
    argv, folder = sys.argv, os.getcwd()
    sys.argv = ["games.hall_of_mirrors", *args]
    os.chdir(ROOT)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                runpy.run_module("games.hall_of_mirrors", run_name="__main__", alter_sys=True)
                status = 0
            except SystemExit as exit_:
                status = exit_.code if isinstance(exit_.code, int) else (0 if exit_.code is None else 1)
    finally:
        sys.argv = argv
        os.chdir(folder)
    return subprocess.CompletedProcess(["python", "-m", "games.hall_of_mirrors", *args], status, out.getvalue(),
                                       err.getvalue())


def run_level_process(*args: str, env_extra: dict | None = None) -> subprocess.CompletedProcess:
    """``python -m games.hall_of_mirrors ARGS`` in a process of its own."""
    env = {**os.environ, **(env_extra or {})}
    return subprocess.run([sys.executable, "-m", "games.hall_of_mirrors", *args], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)


def small_probes(world, resolution: int = 32) -> None:
    """Every reflection probe's faces ``resolution`` texels a side: for a test of the sample
    level that reads nothing from its probes (at 128 their captures are much of each frame)."""
    for _, probe in world.query_one(ReflectionProbe):
        probe.resolution = resolution
