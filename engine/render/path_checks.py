"""A start-up self-check of the engine's alternative GL paths: each compared once per
context with its plain counterpart on a tiny built-in scene before it is trusted.

Shipping engines keep a list of driver bugs and work around them by vendor and version.
That list is never complete, and the layered cube-map capture proved it: on an NVIDIA H200
(driver 580) it wrote face +X only and left the five other faces uninitialised, while Mesa
drew all six (`../shared/measurements/gpu-h200-2026-11-26.md`).  A probe on that machine
(2026-11-26) narrowed it down: with a cube map attached by ``glFramebufferTexture`` the
framebuffer is complete and reports itself layered, yet a clear and a draw reach face 0
only, for a moderngl cube, a raw ``glTexImage2D`` cube and the engine's target alike, while a
2D array texture attached the same way takes all six layers.  Both layered paths are
refused there.  Hence ``layered_array_capture``: the same one-pass draw into a six-layer
2D array (and a depth array), each layer then copied into its cube face
(``raw_gl.LayeredArrayTarget``); checked only where ``layered_capture`` is refused, it
gives such a driver the one-pass capture back instead of six scene passes a probe (about
0.47 ms of CPU a dynamic probe on the H200).  So instead of trusting a
path because the spec allows it, each path that has a plainer way to the same picture is
run once on this context and compared with it, texel by texel:

  - ``direct_faces``: probe faces drawn straight into the cube map (a face attached as a
    colour attachment) against faces drawn into a 2D target and copied;
  - ``layered_capture``: all six faces in one layered pass (``gl_Layer``) against the six
    faces drawn and copied one by one;
  - ``layered_array_capture``: the same pass into a 2D array, its layers copied into the
    faces, against the same six faces drawn and copied one by one;
  - ``layered_mips``: the mip chain drawn one layered draw a level against
    ``glGenerateMipmap``, every face and every level;
  - ``face_mips``: the same chain drawn a face at a time (the layered one's fallback)
    against ``glGenerateMipmap``.

The scene is six differently coloured emissive quads, one off the centre of each face of a
16-texel cube (so a face swapped, flipped or left unwritten differs), the sky behind them.
Every cube is filled with a sentinel value first, so a face or level a path leaves
untouched is caught, not mistaken for the reference left there.  A path that differs is
refused for the rest of the run: ``trusted`` says False, one warning line names the path,
the GL renderer and driver, and what differed; ``RenderStats.paths_verified`` and
``paths_refused`` and the debug overlay show the verdicts.

A check runs at the first moment its path would be used (inside the probes stage, which
then waits for it: a few small draws and read-backs, once per context), or all at once with
``run_all`` (``python -m benchmarks gpu-report``).  Verdicts are kept per context, so a
second engine on the same context does not check again.
"""
from __future__ import annotations

import logging
import weakref
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import asdict, dataclass, fields

import moderngl
import numpy as np
from pyglm import glm

from components.visibility import DRAWN_EVERYWHERE
from engine.assets.mesh import quad
from engine.core.errors import GLPassError
from engine.core.material_slots import EmissiveVariant, ReflectVariant, RefractVariant
from engine.render.bindings import SCRATCH_UNIT, PassState, apply_pass_state
from engine.render.gpu import Gpu
from engine.render.instances import InstanceBatch
from engine.render.probes import ProbeCaptures, face_view
from engine.render.raw_gl import (
    LayeredCubeTarget,
    MissingEntryPoints,
    inspect_bound_target,
    read_cube_level,
    write_cube_level,
)
from engine.render.views import lights_block

LOG = logging.getLogger("speculum")

PATH_NAMES = ("direct_faces", "layered_capture", "layered_array_capture", "layered_mips", "face_mips")
CHECK_SIZE = 16                 # texels along a face of the check cube
MIN_QUAD_SHARE = 0.05          # of a check face's texels that must show its quad (it covers about a fifth)
SENTINEL = 1234.0               # what a cube holds before a path draws into it (half floats hold it exactly)
CHECK_KEYS = (-101, -102)       # probe keys of the check's two cubes (never an entity)
CHECK_ENTITY = 0x7FFFFF00       # the entity id the check's quads carry
# How close two ways to the same picture must be.  The two draw the same triangles with
# the same programs, so on a conforming driver they agree to half-float rounding; an edge
# texel may still round the other way, hence a share rather than every texel.  Unwritten
# faces hold the sentinel (or a driver's garbage) and miss by orders of magnitude.
TEXEL_TOLERANCE = 0.02          # |difference| / (1 + |reference|) above which a texel differs
DIFFERING_SHARE = 0.02          # faces (and levels) with more differing texels than this fail
# A mip level may differ from glGenerateMipmap's by its filter's rounding; a level left
# unwritten or filtered from the wrong level above misses by far more.
MIP_MEAN_TOLERANCE = 0.02       # mean |difference| / mean |reference| of one face's level


@dataclass
class PathVerdict:
    """What the self-check found for one path."""

    status: str = "unchecked"   # "verified", "refused", "unavailable" (its GL calls are not reachable), "unchecked"
    detail: str = ""


_BY_CONTEXT: weakref.WeakKeyDictionary[moderngl.Context, dict[str, PathVerdict]] = weakref.WeakKeyDictionary()


class PathChecks:
    """The verdicts of this renderer's context, and the checks that make them (module
    docstring): each check draws through the probe captures (``probes``) both ways.  The
    passes below ask it as their ``Gpu.path_checks`` (``gpu.PathTrust``)."""

    def __init__(self, renderer: Gpu, probes: ProbeCaptures) -> None:
        self.renderer = renderer
        self.probes = probes
        self.ctx = renderer.ctx
        self.verdicts: dict[str, PathVerdict] = _BY_CONTEXT.setdefault(
            renderer.ctx, {name: PathVerdict() for name in PATH_NAMES})
        self._running: set[str] = set()

    def trusted(self, path: str) -> bool:
        """Whether ``path`` may be used: checked now if it never was on this context."""
        if path in self._running:
            return True  # the check itself is drawing with it
        if self.verdicts[path].status == "unchecked":
            self.check(path)
        return self.verdicts[path].status == "verified"

    def run_all(self) -> dict[str, PathVerdict]:
        """Check every path not checked yet on this context; returns the verdicts."""
        for path in PATH_NAMES:
            if self.verdicts[path].status == "unchecked":
                self.check(path)
        return self.verdicts

    def verified(self) -> tuple[str, ...]:
        return tuple(p for p in PATH_NAMES if self.verdicts[p].status == "verified")

    def refused(self) -> tuple[str, ...]:
        return tuple(p for p in PATH_NAMES if self.verdicts[p].status == "refused")

    def forget(self) -> None:
        """Check every path again at its next use (tests that swap a path for a broken one)."""
        for path in PATH_NAMES:
            self.verdicts[path] = PathVerdict()

    def check(self, path: str) -> PathVerdict:
        """Run ``path``'s comparison now and record (and return) its verdict."""
        checks: dict[str, Callable[[], str | None]] = {
            "direct_faces": self._check_direct_faces,
            "layered_capture": lambda: self._check_layered_capture("cube"),
            "layered_array_capture": lambda: self._check_layered_capture("array"),
            "layered_mips": lambda: self._check_mips("layered"),
            "face_mips": lambda: self._check_mips("per_face"),
        }
        self._running.add(path)
        try:
            with self._scene():
                problem = checks[path]()
        except _Unavailable as missing:
            verdict = PathVerdict("unavailable", str(missing))
        except (RuntimeError, GLPassError) as error:  # a framebuffer the driver would not complete, a GL error
            verdict = PathVerdict("refused", str(error))
        else:
            verdict = PathVerdict("refused", problem) if problem else PathVerdict("verified")
        finally:
            self._running.discard(path)
            self.renderer.note_scene_change()  # its own scene drew with the shared state: redraw after
        self.verdicts[path] = verdict
        if verdict.status == "refused":
            info = self.ctx.info
            LOG.warning("speculum: refusing the %s path on %s (OpenGL %s): %s; using its plain counterpart",
                        path, info.get("GL_RENDERER", "?"), info.get("GL_VERSION", "?"), verdict.detail)
        return verdict

    def layered_target_state(self) -> dict:
        """What the driver reports with a layered capture target bound as a capture binds it
        (``raw_gl.inspect_bound_target``), and what of it differs from what a layered draw
        needs: for reports from machines where the layered capture is refused."""
        probes = self.probes
        key = CHECK_KEYS[1]
        cube = probes.cube(key, CHECK_SIZE).texture
        target = LayeredCubeTarget(self.ctx, cube)
        try:
            with probes._drawing_into(key):
                apply_pass_state(self.ctx, PassState(depth_func="<", cull=True), (0, 0, CHECK_SIZE, CHECK_SIZE))
                target.bind()
                state = inspect_bound_target(self.ctx, cube, depth=True)
                target.unbind()
            problems = state.problems(target.framebuffer, cube.glo, 0, CHECK_SIZE, depth=True)
            return {**asdict(state), "problems": problems}
        finally:
            target.release()
            probes.drop(key)

    # --- the checks -------------------------------------------------------------------------
    def _check_direct_faces(self) -> str | None:
        probes = self.probes
        if not probes.direct_faces:
            raise _Unavailable("attaching a cube-map face needs GL entry points the loader lacks")
        reference = self._capture(lambda key, views: probes.capture(key, views, None, 0, direct=False,
                                                                     build_mips=False))
        drawn = self._capture(lambda key, views: probes.capture(key, views, None, 0, direct=True,
                                                                 build_mips=False))
        return _compare_faces(drawn, reference, "faces drawn straight into the cube")

    def _check_layered_capture(self, into: str) -> str | None:
        probes = self.probes
        reference = self._capture(lambda key, views: probes.capture(key, views, None, 0, direct=False,
                                                                     build_mips=False))
        try:
            drawn = self._capture(lambda key, views: probes.capture_layered(key, views, build_mips=False,
                                                                             into=into))
        except MissingEntryPoints as missing:
            raise _Unavailable(str(missing)) from missing
        what = "the layered capture" if into == "cube" else "the layered capture into a 2D array, copied"
        return _compare_faces(drawn, reference, what)

    def _check_mips(self, way: str) -> str | None:
        probes = self.probes
        if not probes.mips.layered:
            raise _Unavailable("drawing a cube map's mip levels needs GL entry points the loader lacks")
        key = CHECK_KEYS[0]
        cube = probes.cube(key, CHECK_SIZE).texture
        try:
            for face, image in enumerate(_level0_pattern()):
                cube.write(face, image.tobytes())
            cube.build_mipmaps()
            levels = CHECK_SIZE.bit_length()
            reference = [[self._read(cube, face, level) for level in range(levels)] for face in range(6)]
            probes.mips.build(key, cube, "mips", way=way)  # makes the pass's target and programs
            for face in range(6):
                for level in range(1, levels):
                    n = CHECK_SIZE >> level
                    write_cube_level(self.ctx, cube, face, level, np.full((n, n, 4), SENTINEL, np.float32),
                                     SCRATCH_UNIT)
            probes.mips.build(key, cube, "mips", way=way)
            for face in range(6):
                for level in range(1, levels):
                    drawn = self._read(cube, face, level)
                    ref = reference[face][level]
                    error = float(np.abs(drawn - ref).mean() / max(float(np.abs(ref).mean()), 1e-6))
                    if not np.isfinite(drawn).all() or error > MIP_MEAN_TOLERANCE:
                        return (f"the {way.replace('_', '-')} mip pass differs from glGenerateMipmap at face {face} "
                                f"level {level} (mean relative difference {error:.3g})")
            return None
        finally:
            probes.drop(key)

    def _read(self, cube: moderngl.TextureCube, face: int, level: int) -> np.ndarray:
        return read_cube_level(self.ctx, cube, face, level, SCRATCH_UNIT)[..., :3]

    # --- the scene and captures -------------------------------------------------------------
    def _capture(self, draw: Callable[[int, dict], None]) -> list[np.ndarray]:
        """Draw the six faces of a fresh check cube (filled with the sentinel first) with
        ``draw(key, views)`` and read them back."""
        probes = self.probes
        key = CHECK_KEYS[0]
        cube = probes.cube(key, CHECK_SIZE).texture
        try:
            for face in range(6):
                cube.write(face, _sentinel(CHECK_SIZE))
            views = {face: face_view(face, glm.vec3(0.0), 0.05, 10.0, CHECK_SIZE) for face in range(6)}
            draw(key, views)
            return [self._read(cube, face, 0) for face in range(6)]
        finally:
            probes.drop(key)

    @contextmanager
    def _scene(self):
        """Inside the block every scene pass draws the check scene only, lit by no light,
        through no fog (the world's fog builds read the world's block: a water's body about
        the origin, where the quads stand, took a tinted water's colours off their hues), and
        the frame's counters and stack of probe targets are as they were after it."""
        renderer = self.renderer
        probes = self.probes
        batch = InstanceBatch(self.ctx, _check_mesh(self.ctx), None)
        for face in range(6):
            _fill_row(batch.add(CHECK_ENTITY + face), face)
        batch.upload()
        lights = self.ctx.buffer(lights_block(np.zeros((9, 3)), [], []))
        saved_lights, renderer.lights_ubo = renderer.lights_ubo, lights
        saved_fog, renderer.fog.defines = renderer.fog.defines, ()
        stats = renderer.stats
        saved_stats = {f.name: getattr(stats, f.name) for f in fields(stats)}
        stacks = set(probes._stacks)
        renderer.scene_only = [batch]
        try:
            yield
        finally:
            renderer.scene_only = None
            renderer.lights_ubo = saved_lights
            renderer.fog.defines = saved_fog
            for name, value in saved_stats.items():
                setattr(stats, name, value)
            for resolution in set(probes._stacks) - stacks:
                probes._stacks.pop(resolution).release()
            batch.release()
            batch.mesh.release()
            lights.release()


class _Unavailable(Exception):
    """The path's GL entry points are not reachable: it is never used, so nothing is refused."""


# The six quads: colour per face (+X red, -X green, +Y blue, -Y yellow, +Z cyan, -Z magenta).
_COLOURS = ((1.0, 0.1, 0.1), (0.1, 1.0, 0.1), (0.1, 0.1, 1.0), (1.0, 1.0, 0.1), (0.1, 1.0, 1.0), (1.0, 0.1, 1.0))
_AXES = ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1))


def _check_mesh(ctx: moderngl.Context):
    from engine.render.instances import GpuMesh

    return GpuMesh(ctx, quad(0.8, 0.5, name="path check quad"))


def _fill_row(row: np.void, face: int) -> None:
    """Quad ``face``: 1 unit out along the face's axis, facing the centre, shifted off the
    face's centre along both of its other axes (so a flip or a turn shows)."""
    axis = glm.vec3(*_AXES[face])
    normal = -axis
    side = glm.vec3(*_AXES[(face + 2) % 6])
    up = glm.cross(normal, side)
    centre = axis + 0.35 * side + 0.2 * up
    model = glm.mat4(glm.vec4(side, 0.0), glm.vec4(up, 0.0), glm.vec4(normal, 0.0), glm.vec4(centre, 1.0))
    row["model"] = np.frombuffer(model.to_bytes(), np.float32)
    row["normal_matrix"] = np.frombuffer(glm.transpose(glm.inverse(glm.mat3(model))).to_bytes(), np.float32)
    row["color"] = (*_COLOURS[face], 1.0)
    row["surface"] = (0.0, 1.0, 2.0, 0.0)  # not metallic, rough, emissive power 2
    row["reflect"] = (0.0, 1.0, 0.0, 0.0)
    row["tint"] = (1.0, 1.0, 1.0, DRAWN_EVERYWHERE)
    row["slice"] = (0.0, 0.0, 0.0, 1.0)
    row["slots"] = (EmissiveVariant.EMISSIVE, RefractVariant.NONE, ReflectVariant.NONE, CHECK_ENTITY + face)


def _sentinel(size: int) -> bytes:
    return np.full((size, size, 4), SENTINEL, np.float16).tobytes()


def _level0_pattern() -> list[np.ndarray]:
    """Six different level-0 faces with structure at every scale (a mip chain filtered from
    the wrong level, or a face swapped, shows)."""
    n = CHECK_SIZE
    t, s = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    faces = []
    for face in range(6):
        image = np.zeros((n, n, 4), np.float16)
        image[..., 0] = (s / n) * (face + 1) / 6
        image[..., 1] = ((s // 2 + t // 3 + face) % 2) * 0.8
        image[..., 2] = (t / n) ** 2 + 0.1 * face
        image[..., 3] = 1.0
        faces.append(image)
    return faces


def _quad_share(image: np.ndarray, face: int) -> float:
    """The share of a face's texels showing its check quad's colour (hue, whatever the light)."""
    rgb = np.asarray(image, np.float32)[..., :3]
    colour = np.array(_COLOURS[face], np.float32)
    hue = rgb / np.maximum(rgb.max(axis=-1, keepdims=True), 1e-6)
    return float(np.mean(np.abs(hue - colour / colour.max()).max(axis=-1) < 0.15))


def _compare_faces(drawn: list[np.ndarray], reference: list[np.ndarray], what: str) -> str | None:
    """None when every face of ``drawn`` is ``reference``'s, else which face differs and how."""
    for face, (image, ref) in enumerate(zip(drawn, reference, strict=True)):
        if not np.isfinite(ref).all() or (ref >= SENTINEL / 2).any():
            return f"the plain counterpart left face {face} unwritten: nothing to compare {what} with"
        if _quad_share(ref, face) < MIN_QUAD_SHARE:
            # Two paths that both draw nothing but the sky agree, and prove nothing.
            return f"the plain counterpart shows no check quad on face {face}: nothing to compare {what} with"
        if not np.isfinite(image).all():
            return f"{what} left face {face} holding non-numbers (unwritten memory)"
        differs = (np.abs(image - ref) / (1.0 + np.abs(ref)) > TEXEL_TOLERANCE).any(axis=-1)
        if differs.mean() > DIFFERING_SHARE:
            untouched = float(np.mean((image >= SENTINEL / 2).any(axis=-1)))
            how = f"{untouched:.0%} of it never written" if untouched else f"{differs.mean():.0%} of its texels differ"
            return f"{what} differs from the plain capture on face {face}: {how}"
    return None
