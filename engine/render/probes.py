"""Cube-map probe captures: six views from a point, each drawn by the scene pass (with the
mirrors and portals it sees, through a view tree rooted at the face) and copied into a
face of the probe's mipmapped cube map, or all six in one layered pass.

``ProbeCaptures`` is the GPU side of every probe: the cube maps (``ProbeCube``: the texture
and where it was captured from, set by ``capture_probe`` alone), the targets faces are drawn
into, the mip pass (``CubeMipPass``) and the path chooser (``ProbePaths``: six_pass or
layered, ``auto`` timing both with GL timer queries, never with ``ctx.finish()`` in a frame
stage).  Which faces to capture, and when, is the probes scheduler's
(``systems/probe_scheduler.py``); what a face sees is ``engine.rules.probe_rules``'.

Face views follow GL's cube-map convention (``engine.core.cube_faces.CUBE_FACES``): face i
looks along the face's axis with up its texture's t axis, a 90 degree square frustum, so a
face rendered the usual way (bottom row first) is the face's texture rows in order
(``cube_faces.face_directions`` gives the direction of each texel; tests/test_probes.py
checks one labelled direction per face).
"""
from __future__ import annotations

import logging
import math
import statistics
import time
from collections.abc import Callable, Iterable, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from time import thread_time
from typing import TYPE_CHECKING

import moderngl
import numpy as np
from pyglm import glm

from components import ReflectionProbe
from components.limits import ALL_LAYERS, VIEW_PROBE
from engine.core.cube_faces import CUBE_FACES
from engine.core.errors import GLLimitError, GLPassError
from engine.render.bindings import (
    CUBE_MIP_UNIT,
    PROBE2_UNIT,
    PROBE_REST_UNIT,
    PROBE_UNIT,
    SCRATCH_UNIT,
    PassState,
    apply_pass_state,
    bind_texture,
)
from engine.render.gpu import Gpu, ProbeCube, layered_target
from engine.render.irradiance import IrradianceTable
from engine.render.raw_gl import CubeMipTarget, LayeredArrayTarget, LayeredCubeTarget, inspect_bound_target
from engine.render.scene_options import SceneOptions
from engine.render.scene_pass import ScenePass
from engine.render.slot_order import see_through_surface
from engine.render.surface_table import NO_BLENDS, SurfaceBlends
from engine.render.targets import LevelStack, release_framebuffer
from engine.render.tree_walk import TreeSettings
from engine.render.view_plan import SurfaceTable
from engine.render.view_tree import ViewTree
from engine.render.views import View
from engine.rules.probe_rules import projection_box

if TYPE_CHECKING:
    from engine.render.instances import InstanceBatch
    from engine.render.monitors import MonitorPictures
    from engine.render.raw_gl import RawGL

LOG = logging.getLogger("speculum")
PROBE_PATHS = ("auto", "six_pass", "layered")
AUTO_TIMED_CAPTURES = 3  # timed captures of each path before "auto" chooses (medians compared)

# A face is a root view; its textures filter as reflections do (trilinear on a software
# rasteriser, where anisotropic filtering is most of a view's cost: a probe is a
# reflection, seen blurred by its mips and through a curved surface).
FACE = SceneOptions(reflection_filter=True)
FACE_TREE = SceneOptions(reflection_filter=True, transparent=False)  # a face rooting a view tree (it draws the
                                                                      # face's transparent slot after its composites)
# A face drawn in part: cleared within its scissor first (the scene pass's clear takes the whole face).
FACE_PART = SceneOptions(clear=False, reflection_filter=True)
FACE_CLEAR = PassState()


def face_view(face: int, position: glm.vec3, near: float, far: float, size: int, skip: int = 0,
              layers: int = ALL_LAYERS) -> View:
    """The view of cube face ``face`` from ``position`` (``skip``: the entity left out, the
    probe's own object): a probe view (an entity hidden in probe captures is not drawn in it,
    nor in the mirrors and portals it sees) showing the reflection ``layers`` given (the
    probe's ``layer_mask``).  Its ``node`` is 0: a face drawn into a level target is its own
    tree's root, whose node image is all 0 (the screen refraction's march keeps to the pixels
    of its view's node); the layered pass takes a face's layer from its invocation."""
    forward, _, up = CUBE_FACES[face]
    eye = glm.vec3(position)
    view = glm.lookAt(eye, eye + glm.vec3(forward), glm.vec3(up))
    proj = glm.perspective(glm.radians(90.0), 1.0, near, far)
    return View(view=view, proj=proj, eye=eye, size=(size, size), name=f"probe face {face}", skip=skip,
                hide=skip, kinds=VIEW_PROBE, layers=layers)


def _face_planes() -> np.ndarray:
    """(face, plane, xyz): inward normals of each face frustum's planes through its apex: the
    four 45-degree sides (d.f >= |d.r|, d.f >= |d.u|) and the plane across the apex
    (d.f >= 0, which the near plane lies in front of)."""
    planes = []
    for forward, _, up in CUBE_FACES:
        f, u = np.array(forward, np.float64), np.array(up, np.float64)
        r = np.cross(f, u)
        planes.append([f - r, f + r, f - u, f + u, f])
    return np.array(planes)


_FACE_PLANES = _face_planes()
_FACE_PLANES_BY_COLUMN = _FACE_PLANES.reshape(-1, 3).T.copy()  # (xyz, face * plane): one matrix product


# The planes' normals split by sign, stacked: every entry is 0 or +-1 (``_face_planes``), so a
# box's farthest corner along a plane is ``(hi - c, lo - c) @ _FACE_PLANES_SPLIT``: at most two
# exact terms and one rounding, the farthest corner's own sum bit for bit.
_FACE_PLANES_SPLIT = np.concatenate([np.maximum(_FACE_PLANES_BY_COLUMN, 0.0), np.minimum(_FACE_PLANES_BY_COLUMN, 0.0)])
_TWICE = np.array([0, 1, 2, 0, 1, 2])  # a point's xyz, twice (hi's and lo's)


def face_touches(position: glm.vec3 | Sequence[float], lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(box, face) booleans: which cube faces from ``position`` each world box [lo, hi] (rows)
    may show.  Conservative: a box is left out of a face only when all eight of its corners
    are outside one of the face's planes through the apex (``_face_planes``: the farthest
    corner along the plane's normal is outside); a fragment lies at least half a pixel
    inside the frustum, far from that test's rounding.  The farthest corner is taken axis by
    axis (``hi`` where the normal is positive, ``lo`` where negative: rounding is monotonic,
    so it is the corner whose sum is largest), one matrix product for all boxes and planes."""
    centre = np.array(tuple(position), np.float64)
    ends = np.concatenate([np.atleast_2d(hi), np.atleast_2d(lo)], axis=1) - centre[_TWICE]
    out = (ends @ _FACE_PLANES_SPLIT >= 0.0).reshape(len(ends), 6, 5)
    return out[..., 0] & out[..., 1] & out[..., 2] & out[..., 3] & out[..., 4]


def sky_only_faces(position: glm.vec3, faces: frozenset[int] | set[int], skip: int,
                   batches: Sequence[InstanceBatch]) -> frozenset[int]:
    """The faces of ``faces`` (cube faces from ``position``) that no instance of ``batches``
    can draw a pixel in: no instance's world box (``InstanceBatch.row_boxes``, as of the
    frame's upload) touches the face's frustum (``face_touches``, conservative; the far
    plane is not used, which only keeps more boxes in).  ``skip`` (the probe's own object,
    which no face draws) is left out, as the scene pass leaves it out.  Such a face shows
    the sky alone.  A row not measured yet (NaN) counts as touching every face.  The
    batches' boxes (their rows' union) are tested together first; only a batch of several
    instances whose box touches a face still left has its rows tested."""
    left = set(faces)
    if not left:
        return frozenset()
    live = [batch for batch in batches if batch.count and not (batch.count == 1 and batch.entity_at[0] == skip)]
    if not live:
        return frozenset(left)
    if sum(batch.count for batch in live) <= SKY_ONLY_FEW_ROWS:
        return _sky_only_few(position, left, skip, live)
    unions = [batch.box for batch in live]
    if any(union is None for union in unions):
        return frozenset()
    boxes = np.array(unions)  # (batch, lo/hi, xyz)
    if np.isnan(boxes).any():
        return frozenset()
    near = face_touches(position, boxes[:, 0], boxes[:, 1]).tolist()  # (batch, face): a few, as lists
    for index, touched in enumerate(near):
        if not any(touched[face] for face in left):
            continue
        batch = live[index]
        if batch.count == 1:
            hits = touched  # one instance (not the skipped one): its box is the batch's
        else:
            row = batch.row_of.get(skip) if skip else None
            boxes = batch.row_boxes
            if row is not None:
                boxes = np.delete(boxes, row, axis=0)
            if not len(boxes):
                continue
            hits = face_touches(position, boxes[:, 0], boxes[:, 1]).any(axis=0)
        left = {face for face in left if not hits[face]}
        if not left:
            break
    return frozenset(left)


SKY_ONLY_FEW_ROWS = 64  # instances up to which sky_only_faces tests every row at once


def _sky_only_few(position: glm.vec3, left: set[int], skip: int, live: list[InstanceBatch]) -> frozenset[int]:
    """``sky_only_faces`` for a few instances: every row tested in one ``face_touches``, not
    the batches' unions first (a row's box lies in its batch's union, and a box inside
    another touches no face the other does not: the answer is the same, in fewer calls)."""
    rows = np.concatenate([batch.row_boxes for batch in live])  # (row, lo/hi, xyz)
    if np.isnan(rows).any():
        return frozenset()  # a row not measured yet: its batch's union is NaN too
    if skip:
        start, drop = 0, []
        for batch in live:
            row = batch.row_of.get(skip)
            if row is not None:
                drop.append(start + row)
            start += batch.count
        if drop:
            rows = np.delete(rows, drop, axis=0)
    if not len(rows):
        return frozenset(left)
    hits = face_touches(position, rows[:, 0], rows[:, 1]).any(axis=0).tolist()
    return frozenset(face for face in left if not hits[face])


class _Same:
    """Compares equal to a wrapper of the same object only (a GL object held in a record:
    identity, whatever the object's own ``==`` says)."""

    __slots__ = ("obj",)

    def __init__(self, obj: object) -> None:
        self.obj = obj

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _Same) and other.obj is self.obj

    def __hash__(self) -> int:
        return id(self.obj)


@dataclass
class _KeepPlan:
    """A six-pass capture's faces kept as they are (``kept``), those showing the sky alone
    (``sky_only``), what every face is drawn with (``scene``: ``ProbeCaptures._scene_record``,
    None where faces draw view trees), each face's own record (``records``:
    ``ProbeCaptures._sky_record``, with the monitors' pictures it may show where there are
    any) and the faces drawn in part (``parts``: face -> the
    scissor rectangle, x, y, width, height in texels, where the changes since it was drawn lie)."""

    kept: frozenset[int]
    sky_only: frozenset[int]
    scene: tuple | None
    records: dict[int, tuple]
    direct: bool  # faces drawn straight into the cube (the records say so)
    parts: dict[int, tuple[int, int, int, int]] = field(default_factory=dict)


def texel_rect(region: Sequence[float], size: int) -> tuple[int, int, int, int] | None:
    """The texels of a ``size``-texel face a region (s0, t0, s1, t1, in the face's normalised
    coordinates: ``probe_rules.face_rects``) may cover, as a scissor rectangle (x, y, width,
    height): grown by a texel on each side (a fragment's centre lies inside its primitive,
    whose projection lies inside the region but for rounding) and out to even texels (every
    2 x 2 quad, whose texels take their derivatives from one another, whole inside or
    outside); None where the region is empty."""
    s0, t0, s1, t1 = region
    if not (s0 <= s1 and t0 <= t1):
        return None
    half = size / 2.0
    x0 = max(0, (math.floor((s0 + 1.0) * half) - 1) & ~1)
    y0 = max(0, (math.floor((t0 + 1.0) * half) - 1) & ~1)
    x1 = min(size, (math.ceil((s1 + 1.0) * half) + 2) & ~1)
    y1 = min(size, (math.ceil((t1 + 1.0) * half) + 2) & ~1)
    return (x0, y0, x1 - x0, y1 - y0)


class CubeMipPass:
    """Rebuilds a cube map's mip chain with one layered draw a level (``cube_mip.geom`` and
    ``.frag``: a 2x2 box filter, as ``glGenerateMipmap``'s), where ``build_mipmaps`` costs six
    blits a level (42 for a 128 cube: most of a small probe's capture on llvmpipe).

    Three ways, chosen per build: ``layered`` (one draw a level) once the path self-check
    (``engine/render/path_checks.py``) has verified it on this context; for a GGX chain
    where the layered draw was refused (the NVIDIA H200's driver writes only face 0 of a
    layered cube-map attachment), ``per_face`` (six draws a level, each face attached alone:
    the same shader without the geometry shader); ``build_mipmaps`` (``glGenerateMipmap``)
    for box mips where the layered draw is not trusted, and where the raw GL calls are not
    reachable (box mips only: a GGX chain then cannot be drawn and says so)."""

    STATE = PassState()  # no depth test, no blending, no clip distances

    def __init__(self, renderer: Gpu) -> None:
        self.renderer = renderer
        self.ctx = renderer.ctx
        self._targets: dict[int, CubeMipTarget] = {}  # by probe key
        self._vaos: dict[tuple[bool, bool], moderngl.VertexArray] = {}  # by (GGX, one face a draw)
        self.layered = True  # False once the raw calls turned out unreachable
        self.used = ""  # how the last chain was built: "layered", "per_face" or "build_mipmaps"
        self._warned_box = False

    @staticmethod
    def primitives(size: int) -> int:
        """Primitives the pass emits for a cube of ``size`` (a primitives-generated query
        around a capture counts them too; the per-face pass emits as many)."""
        return 6 * (size.bit_length() - 1)

    def build(self, key: int, cube: moderngl.TextureCube, prefilter: str = "mips", way: str | None = None,
              faces: Iterable[int] | None = None, rect: tuple[int, int, int, int] | None = None) -> str:
        """Levels 1.. of ``cube`` from its level 0: box-filtered (``mips``), or each level the
        one above convolved with a GGX lobe so that level L holds roughness L / top level
        (``ggx``; ``ProbeCube.roughness_levels``).  ``way`` forces "layered" or "per_face"
        (the path self-check compares them); None chooses as the class docstring says.
        ``faces``: box mips of these faces only (the others' chains are built from their
        level 0 as it is: a texel's 2 x 2 box lies inside its face, so each face's chain
        reads that face alone); None, and every GGX chain (its lobes cross the faces' edges),
        all six; ``glGenerateMipmap`` builds all six whatever it is given.  ``rect`` (x0, y0,
        x1, y1 in level 0's texels): box mips where level 0 of those faces changed within it
        alone; each level is drawn within it, halved a level and grown out to whole texels
        (a texel's 2 x 2 box lies in the level above's rectangle), the rest kept.  Returns the
        prefilter built: "mips" where a GGX chain cannot be drawn here (neither of the drawn
        passes is reachable or verified; a warning says so once)."""
        ggx = prefilter == "ggx"
        target = self._target(key, cube)
        if target is None and ggx:
            raise GLLimitError(f"reflection probe of entity {key}: ReflectionProbe.prefilter 'ggx' needs "
                               "layered framebuffer calls this OpenGL loader does not give")
        if target is not None and way is None:
            checks = self.renderer.path_checks
            # Box mips without a trusted layered pass: glGenerateMipmap (the driver's own,
            # one call; the per-face pass would be 42 attachments and draws for a 128 cube).
            way = ("layered" if checks.trusted("layered_mips") else
                   "per_face" if ggx and checks.trusted("face_mips") else None)
        if target is None or way is None:
            if ggx and not self._warned_box:
                LOG.warning("speculum: no mip pass this OpenGL draws right was found (path self-check): "
                            "GGX-prefiltered probes are box-filtered instead")
                self._warned_box = True
            cube.build_mipmaps()
            self.used = "build_mipmaps"
            return "mips"
        one_face = way == "per_face"
        vao = self._program_vao(ggx, one_face)
        program = vao.program
        drawn = range(6) if faces is None or ggx else sorted(faces)
        if not one_face:
            program["face_mask"].value = sum(1 << face for face in drawn)
        apply_pass_state(self.ctx, self.STATE, (0, 0, *cube.size))
        for unit in (PROBE_UNIT, PROBE2_UNIT, PROBE_REST_UNIT, SCRATCH_UNIT):
            bind_texture(self.ctx, self.renderer.sky, unit)  # the cube is bound only where the pass reads it
        self.renderer.sky.use(self.ctx.default_texture_unit)  # moderngl's own unit: not in the record
        top = cube.size[0].bit_length() - 1
        try:
            for level in range(1, top + 1):
                if ggx:
                    alpha, above = (level / top) ** 2, ((level - 1) / top) ** 2
                    program["alpha"].value = math.sqrt(alpha * alpha - above * above)
                scissor = None
                if rect is not None and not ggx:
                    step = 1 << level
                    x0, y0 = rect[0] >> level, rect[1] >> level
                    scissor = (x0, y0, -(-rect[2] // step) - x0, -(-rect[3] // step) - y0)
                for face in (drawn if one_face else (None,)):
                    size = (target.bind_level(level, CUBE_MIP_UNIT, face) if scissor is None else
                            target.bind_level(level, CUBE_MIP_UNIT, face, scissor))
                    program["level_size"].value = float(size)
                    if face is not None:
                        program["face"].value = face
                    elif self.renderer.debug:
                        self._check_bound(target, level, scissor)
                    vao.render(moderngl.TRIANGLES, vertices=3)
        finally:
            target.done(CUBE_MIP_UNIT)
            # not left bound where the next capture draws into it
            bind_texture(self.ctx, self.renderer.sky, CUBE_MIP_UNIT)
        self.used = way
        self.renderer.checkpoint("probe mip chain")
        return prefilter

    def _check_bound(self, target: CubeMipTarget, level: int,
                     scissor: tuple[int, int, int, int] | None = None) -> None:
        """Debug mode: the driver has the level attached layered, the framebuffer bound, the
        cube sampled only through the pass's source unit (``raw_gl.inspect_bound_target``)."""
        size = max(1, target.cube.size[0] >> level)
        state = inspect_bound_target(self.ctx, target.cube, depth=False)
        problems = state.problems(target.framebuffer, target.cube.glo, level, size, depth=False,
                                  source_units=(CUBE_MIP_UNIT,), scissor=scissor)
        if problems:
            raise GLPassError(f"probe mip pass, level {level}: " + "; ".join(problems))

    def _target(self, key: int, cube: moderngl.TextureCube) -> CubeMipTarget | None:
        if not self.layered:
            return None
        target = self._targets.get(key)
        if target is None or target.cube is not cube:
            self.drop(key)
            cube.build_mipmaps()  # allocates levels 1.. (a level must exist to be attached)
            try:
                target = self._targets[key] = CubeMipTarget(self.ctx, cube)
            except RuntimeError:
                self.layered = False
                return None
        return target

    def _program_vao(self, ggx: bool, one_face: bool) -> moderngl.VertexArray:
        vao = self._vaos.get((ggx, one_face))
        if vao is None:
            defines = {"GGX_PREFILTER": "1"} if ggx else {}
            if one_face:
                defines["ONE_FACE"] = "1"
            geometry = None if one_face else "cube_mip.geom"
            program = self.renderer.shaders.program("fullscreen.vert", "cube_mip.frag", geometry,
                                                    defines=defines or None)
            program["source"].value = CUBE_MIP_UNIT
            vao = self._vaos[(ggx, one_face)] = self.ctx.vertex_array(program, [])
        return vao

    def drop(self, key: int) -> None:
        target = self._targets.pop(key, None)
        if target is not None:
            target.release()

    def release(self) -> None:
        for key in list(self._targets):
            self.drop(key)
        for vao in self._vaos.values():
            vao.release()
        self._vaos.clear()


@dataclass
class FaceTarget:
    """A target the scene pass draws one probe face into: one framebuffer (the cube face as
    colour, a depth texture) serving as the clear, view and sky framebuffer alike, so a
    face is one uninterrupted pass.  It has no id images, so it roots no view tree."""

    framebuffer: moderngl.Framebuffer
    size: tuple[int, int]

    @property
    def view_framebuffer(self) -> moderngl.Framebuffer:
        return self.framebuffer

    def begin_glass(self) -> None:
        """The glass slot's framebuffer (``RenderTargets.begin_glass``): depth not written (a
        face has no seen image whose way to keep)."""
        self.framebuffer.depth_mask = False
        self.framebuffer.use()

    def end_glass(self) -> None:
        self.framebuffer.depth_mask = True
        self.framebuffer.use()


class CubeFaceTargets:
    """Six framebuffers drawing straight into the faces of one probe's cube map (raw GL:
    ``RawGL.attach_cube_face``), sharing one depth texture (faces are drawn one after
    another, each cleared first).  Against drawing into a 2D target and copying, a face
    costs no copy and, on llvmpipe, neither the copy's wait for the face's rasterisation
    nor the framebuffer switches between clear, scene and sky."""

    def __init__(self, ctx: moderngl.Context, raw_gl: RawGL, cube: moderngl.TextureCube) -> None:
        self.cube = cube
        size = cube.size
        self.depth = ctx.depth_texture(size)
        placeholder = ctx.texture(size, 1, dtype="f1")  # moderngl needs a colour texture to make it
        self.faces: list[FaceTarget] = []
        try:
            for face in range(6):
                framebuffer = ctx.framebuffer([placeholder], self.depth)
                self.faces.append(FaceTarget(framebuffer, size))
                raw_gl.attach_cube_face(framebuffer, cube, face)
        except BaseException:
            self.release()
            raise
        finally:
            placeholder.release()  # attached to none of them any more

    def release(self) -> None:
        for target in self.faces:
            release_framebuffer(target.framebuffer)
        self.faces.clear()
        self.depth.release()


class ProbePaths:
    """Which path draws a probe capture: ``six_pass`` (each face a view through the scene
    pass, with a view tree of the mirrors and portals it sees) or ``layered`` (all six faces
    in one pass, a geometry shader choosing each triangle's faces; no view trees).  ``path``
    is one of them, or ``auto`` (the default): both measured on the real scene, the faster
    kept.

    Only a path the path self-check (``Gpu.path_checks``) trusts on this context is
    drawn.  ``layered`` draws into the cube map itself where ``layered_capture`` is
    verified, else into a six-layer 2D array copied into the cube where
    ``layered_array_capture`` is (the NVIDIA H200's driver takes a layered draw into an
    array but not into a cube map: ``layered_target``); where neither is, a forced or
    chosen ``layered`` takes ``six_pass`` (a refused layered capture would leave faces
    unwritten), and ``auto`` never times it.  A capture of some faces only (a face kept as
    it is, or one the scheduler says no change reached, counts: ``ProbeCaptures.capture_probe``),
    or of a probe whose faces see mirrors or portals, or whose faces are finished as a root
    is (``ProbeCaptures._finished``: foam, screen-refracting glass, a see-through mirror or
    portal about), takes ``six_pass``.

    How ``auto`` measures, with no ``ctx.finish()`` in a frame stage.  On the first full
    capture either path could draw, each path draws it once untimed (programs built, targets
    made), then ``AUTO_TIMED_CAPTURES`` times each, alternating, each inside a GL timer
    query (``GL_TIME_ELAPSED``: the time the GPU took over the capture's commands).  Wall
    clock around a capture without ``finish()`` would time only the issuing of its commands
    on a GPU, which draws them later, and the paths differ most in the drawing (the layered
    path's geometry shader); on llvmpipe the query gave, for 64- to 512-texel faces on both
    paths, within 7% of the capture's wall time with ``finish()`` on both sides (the old
    way of timing it) and the same order of the two.  The CPU's time issuing each capture
    is taken too (wall clock around it): a capture costs the frame the larger of the two
    (the NVIDIA H200 draws a 512 probe faster in six passes, but issues the layered one
    17% faster, and its frames wait for the CPU), so that is what is compared.  Nothing
    waits for the queries where they are drawn: they are read when the next frame's probes stage starts (``settle``),
    or when ``chosen`` or ``timings`` are read, by when the frame that drew them has been
    presented and the GPU is through with them (were it not, the read would wait until it
    is, once in a run).  Until then captures take ``six_pass``.  The medians are compared,
    and the faster is kept for the rest of the run and said (``chosen``, ``timings``,
    ``in_use``, a log line)."""

    def __init__(self, renderer: Gpu) -> None:
        self.renderer = renderer
        self.path = "auto"
        self.used = ""  # the path that drew the last capture
        self._chosen: str | None = None
        self._timings: dict[str, float] = {}  # median ms of the timed captures, by path
        # timed, not read yet: each capture's timer query and its CPU ms, by path
        self._queries: dict[str, list[tuple[moderngl.Query, float]]] | None = None
        self.samples: dict[str, list[tuple[float, float]]] = {}  # (GPU ms, CPU ms) of each timed capture
        self.thread_ms: dict[str, list[float]] = {}  # the issuing thread's CPU ms of each timed capture
        self._resolution = 0

    @property
    def chosen(self) -> str | None:
        """What ``auto`` settled on, once it has timed both (None before)."""
        self.settle()
        return self._chosen

    @property
    def timings(self) -> dict[str, float]:
        """Median ms of the timed captures, by path: of each capture the larger of its GPU
        time and its CPU time (empty before ``auto`` timed them)."""
        self.settle()
        return dict(self._timings)

    @property
    def fill_bound(self) -> bool:
        """Whether drawing fewer texels of a capture saves time here: the GPU took longer
        over the timed six-pass captures than the CPU spent issuing them (their medians; the
        thread's CPU time, not the wall clock, which holds a software rasteriser's waits), or
        nothing was timed (a software rasteriser, where fill is most of a capture, is the
        case to serve).  False on a GPU that draws a capture faster than it is issued: there
        a face drawn in part saves nothing, and working out its part costs CPU.  Timings not
        read yet count as none (they are read at the next frame's probes stage, ``settle``:
        reading them now would wait for the GPU)."""
        timed, own = self.samples.get("six_pass"), self.thread_ms.get("six_pass")
        if self._queries is not None or not timed or not own:
            return True
        return statistics.median(gpu for gpu, _ in timed) > statistics.median(own)

    @property
    def in_use(self) -> str:
        """The path the frame statistics report: what ``auto`` chose, once it has; else the
        path of the last capture."""
        return self._chosen if self.path == "auto" and self._chosen else self.used

    def draw(self, draws: dict[str, Callable[[], None]], layered_possible: bool, resolution: int) -> str:
        """Draw a capture by the path this one takes (``draws``: each path's drawing of it);
        the path that drew it."""
        path = self._path(layered_possible)
        if path == "time both":
            self._time_both(draws, resolution)
            path = list(draws)[-1]  # drawn last: the cube holds its picture
        else:
            draws[path]()
        self.used = path
        return path

    def layered_target(self) -> str | None:
        """The target the layered path draws into on this context (``gpu.layered_target``):
        "cube", "array", or None (six_pass only)."""
        return layered_target(self.renderer.path_checks)

    def settle(self) -> None:
        """Read the timed captures' queries, if any wait, and choose (the class docstring)."""
        if self._queries is None:
            return
        queries, self._queries = self._queries, None
        self.samples = {name: [(query.elapsed / 1e6, cpu) for query, cpu in timed] for name, timed in queries.items()}
        self._timings = {name: statistics.median(max(pair) for pair in pairs) for name, pairs in self.samples.items()}
        self._chosen = min(self._timings, key=self._timings.get)
        LOG.info("probe capture path: %s (six_pass %.2f ms, layered into the %s %.2f ms for %d-texel faces)",
                 self._chosen, self._timings["six_pass"], self.layered_target(), self._timings["layered"],
                 self._resolution)

    def _path(self, layered_possible: bool) -> str:
        if self.path not in PROBE_PATHS:
            raise ValueError(f"ProbeSystem.path must be one of {PROBE_PATHS}, got {self.path!r}")
        if not layered_possible or self.path == "six_pass":
            return "six_pass"
        # The layered capture only where the path self-check verified one of its targets on
        # this context (forced or chosen by auto): a refused path would leave faces unwritten.
        if self.layered_target() is None:
            return "six_pass"
        if self.path == "layered":
            return "layered"
        if self._chosen is not None:
            return self._chosen
        return "six_pass" if self._queries is not None else "time both"

    def _time_both(self, draws: dict[str, Callable[[], None]], resolution: int) -> None:
        ctx = self.renderer.ctx
        for draw in draws.values():
            draw()  # untimed: programs built, targets made
        queries: dict[str, list[tuple[moderngl.Query, float]]] = {name: [] for name in draws}
        self.thread_ms = {name: [] for name in draws}
        for _ in range(AUTO_TIMED_CAPTURES):
            for name, draw in draws.items():
                query = ctx.query(time=True)
                start, own = time.perf_counter(), thread_time()
                with query:
                    draw()
                queries[name].append((query, (time.perf_counter() - start) * 1e3))
                self.thread_ms[name].append((thread_time() - own) * 1e3)
        self._queries, self._resolution = queries, resolution


class ProbeCaptures:
    """The GPU side of every probe: cube maps by probe key (``Gpu.probe_cubes``, which the
    passes sample), and the targets faces draw into (one LevelStack per resolution, shared
    by all probes: captures run one after another).  Faces are drawn through ``scene_pass``;
    a probe with an influence box gets its irradiance from ``irradiance``; the monitors'
    ``pictures`` a face may show are part of what it was drawn with (None: none is)."""

    def __init__(self, renderer: Gpu, scene_pass: ScenePass, irradiance: IrradianceTable,
                 pictures: MonitorPictures | None = None) -> None:
        self.renderer = renderer
        self.scene_pass = scene_pass
        self.irradiance = irradiance
        self.pictures = pictures
        self.ctx = renderer.ctx
        self.cubes = renderer.probe_cubes  # made and released here alone
        # the one-pass path's targets, by probe (the cube map itself, or a 2D array copied into it)
        self._layered: dict[int, LayeredCubeTarget | LayeredArrayTarget] = {}
        self._faces: dict[int, CubeFaceTargets] = {}  # the six-pass path's face targets, by probe
        self.direct_faces = renderer.raw_gl.can_attach_cube_faces  # False: draw in a 2D target, copy
        self._stacks: dict[int, LevelStack] = {}
        self.tree = ViewTree(renderer, scene_pass)
        self.mips = CubeMipPass(renderer)
        self.paths = ProbePaths(renderer)
        # By probe, face -> what the face was last drawn with where it showed the sky alone
        # (``_sky_record``): such a face is not drawn again while that holds (``capture``).
        self._sky_faces: dict[int, dict[int, tuple]] = {}
        # By probe, face -> what the face was last drawn with (``_sky_record``, ``_scene_record``):
        # a face the scheduler says no change reached is not drawn again while that holds.
        self._scene_faces: dict[int, dict[int, tuple]] = {}
        self._versions: dict[int, int] = {}  # by probe: counts writes of its cube (what samples it changes)
        # By probe: its six face views and each one's camera as a record reads it, for the
        # place and settings they were made for (face_views).
        self._views: dict[int, tuple[tuple, dict[int, View], dict[int, tuple]]] = {}
        self._projected: dict[int, int] = {}  # by probe: its cube's version its irradiance row was projected from
        # By probe whose mip chain was built from its faces: the faces drawn since (their
        # chains are built again; absent: the whole chain is).
        self._mips_stale: dict[int, set[int]] = {}
        self.faces_kept = 0  # faces left as they were, the sky alone as before (counted over the run)
        self.moved_on = 0  # what the reflection probes' captures moved Gpu.scene_version on by (capture_probe)
        # By probe, ``moved_on`` as its last capture that moved the version left it (a stamp:
        # it only grows, so a probe made again under a dropped one's entity never matches an
        # old record), and the probes whose last capture had an influence box: what a
        # monitor's picture read of the probes is theirs alone (``MonitorPictures.probes_read``),
        # so a capture of a probe its drawing could not sample does not draw it again.
        self.moved_by: dict[int, int] = {}
        self.boxed: set[int] = set()
        self.faces_in_part = 0  # faces drawn in part (within the changes' rectangle), over the run
        self.texels_in_part = 0  # the texels those parts covered

    def cube(self, key: int, resolution: int) -> ProbeCube:
        """The cube map of probe ``key`` at ``resolution`` (made, or remade at a new size)."""
        cube = self.cubes.get(key)
        if cube is None or cube.resolution != resolution:
            limit = self.renderer.caps.max_cube_map_size
            if resolution > limit:
                raise GLLimitError(f"reflection probe of entity {key}: ReflectionProbe.resolution {resolution} is "
                                   f"over this OpenGL's GL_MAX_CUBE_MAP_TEXTURE_SIZE {limit}")
            if cube is not None:
                cube.texture.release()
            self._forget_faces(key)
            self._mips_stale.pop(key, None)
            texture = self.ctx.texture_cube((resolution, resolution), 4, dtype="f2")
            texture.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
            old, cube = cube, ProbeCube(texture, resolution)
            self.cubes[key] = cube
            if old is not None:
                self._let_go_levels(old.resolution)
            self.renderer.note_scene_change()
        return cube

    def face_views(self, key: int, faces: Iterable[int], position: glm.vec3,
                   settings: ReflectionProbe) -> dict[int, View]:
        """The views of ``faces`` of probe ``key`` from ``position`` (``face_view``), made
        once for a place and the settings they depend on and given again while those hold
        (a View is not changed after it is made; its Camera block is packed once)."""
        ident = (tuple(position), settings.near, settings.far, settings.resolution, settings.layer_mask)
        made = self._views.get(key)
        if made is None or made[0] != ident:
            views = {face: face_view(face, position, settings.near, settings.far, settings.resolution, skip=key,
                                     layers=settings.layer_mask) for face in range(6)}
            cameras = {face: (view.view.to_tuple(), view.proj.to_tuple(), tuple(view.eye), view.size)
                       for face, view in views.items()}
            made = self._views[key] = (ident, views, cameras)
        return {face: made[1][face] for face in faces}

    def capture_probe(self, key: int, faces: frozenset[int], position: glm.vec3, settings: ReflectionProbe,
                      surfaces: SurfaceTable | None = None, blends: SurfaceBlends = NO_BLENDS,
                      unchanged: frozenset[int] = frozenset(),
                      regions: dict[int, tuple[float, float, float, float]] | None = None) -> str:
        """Capture ``faces`` of probe ``key`` (the entity owning it, whose own object every
        face leaves out) from ``position`` with ``settings``, by the path ``paths`` takes
        (``blends``: what a surface no face view reaches shows, the extract stage's;
        ``surfaces``: the planner's table of this frame's mirrors and portals,
        ``engine.render.surface_table``, that a face's view tree draws, up to
        ``settings.depth``; ``unchanged``: the faces no change reached since they were last
        drawn, the scheduler's ``ProbeDue.unchanged``, kept as ``capture`` says; ``regions``:
        the part of a face changes reached, ``ProbeDue.regions``, drawn alone); then the
        cube's record of where it was captured from and its projection box
        (``probe_rules.projection_box``): the cube's fields are set here only.  Returns the
        path that drew it.

        A capture where the six-pass path keeps a face, or where the scheduler says a face
        is unchanged, is a capture of some faces: it takes ``six_pass`` (the layered pass
        draws all six, and leaves no face a record to be kept by).  So a probe recaptured
        every frame in a scene where some faces see no change draws six-pass from its
        second capture on, whichever path ``auto`` timed faster on its first (at 128 texels
        on llvmpipe the two are within a few per cent there, which is why ``auto``'s choice
        flips from run to run: the choice no longer changes such a probe's frames)."""
        before = self.renderer.scene_version
        views = self.face_views(key, faces, position, settings)
        sees_surfaces = settings.depth > 0 and surfaces is not None and bool(surfaces.states)
        table = surfaces if sees_surfaces else None
        finishes = sees_surfaces or self._finished()
        plan = None
        if key in self.cubes and self.cubes[key].resolution == settings.resolution:  # else a new cube: none kept
            plan = self._keep_plan(key, views, unchanged, self._direct(finishes), finishes, regions)
        draws = {"six_pass": lambda: self.capture(key, views, table, settings.depth, settings.prefilter,
                                                  blends=blends, unchanged=unchanged, plan=plan,
                                                  regions=regions, finishes=finishes),
                 "layered": lambda: self.capture_layered(key, views, prefilter=settings.prefilter)}
        # A face kept, or one no change reached (kept from the next capture on, once drawn
        # with a record): a capture of some faces, which the six-pass path draws.
        kept = plan is not None and (plan.kept or plan.parts)
        path = self.paths.draw(draws, len(faces) == 6 and not finishes and not kept and not unchanged,
                               settings.resolution)
        cube = self.cubes[key]
        box = projection_box(position, settings)
        if cube.position != tuple(position) or cube.box != box:
            self.renderer.note_scene_change()  # where its lookups are parallax-corrected from
        cube.position = tuple(position)
        cube.box = box
        if settings.influence is not None and self._projected.get(key) != self._versions.get(key, 0):
            # Its irradiance, from the new mip chain (engine/render/irradiance.py); a capture
            # that kept every face and its chain leaves the row as it was projected.
            if self.irradiance.project(key, cube):
                self._projected[key] = self._versions.get(key, 0)
        self.renderer.stats.probe_captures += 1
        moved = self.renderer.scene_version - before
        self.moved_on += moved
        if moved:
            self.moved_by[key] = self.moved_on
        if settings.influence is not None:
            self.boxed.add(key)
        else:
            self.boxed.discard(key)
        return path

    def capture(self, key: int, views: dict[int, View], surfaces: SurfaceTable | None, depth: int,
                prefilter: str = "mips", direct: bool | None = None, build_mips: bool = True,
                blends: SurfaceBlends = NO_BLENDS, unchanged: frozenset[int] = frozenset(),
                plan: _KeepPlan | None = None, regions: dict[int, tuple[float, float, float, float]] | None = None,
                finishes: bool | None = None) -> None:
        """Draw each face view of ``views`` (face -> view, all of the probe's resolution) into
        the probe's cube, then rebuild the cube's mips.  A face that sees mirrors or portals
        (``surfaces`` given, ``depth`` > 0) roots a view tree, which needs the id images of a
        full level: it is drawn into a 2D level target and copied into its face; so is a face
        finished as a root is with no tree (``_finished``: its foam, its glass, a see-through
        mirror's fallback); any other face is drawn straight into its face
        (``CubeFaceTargets``) once the path self-check has verified that on this context
        (``direct`` forces one way: the check itself).

        A face that shows the sky alone (``sky_only_faces``: no instance's box touches its
        frustum) and showed the sky alone at its last drawing, with the same camera, sky,
        sky program and path (``_sky_record``), is not drawn again: its pixels would be the
        ones it holds.  It is still fresh (a capture of it now gives the same picture), so a
        dynamic probe keeps its meaning.  Likewise a face of ``unchanged`` (due for a period
        alone, and no change the scheduler follows reached it since it was drawn:
        ``ProbeDue.unchanged``) drawn last by this path with the same camera, sky and
        programs and the same instances' order, shadow maps' blocks and lookups, filtering
        and cubes of the probes it may show (``_scene_record``); and a face of ``regions``
        (the rectangle of the face every change since its drawing reached:
        ``ProbeDue.regions``) drawn last with those same records is drawn within that
        rectangle alone (``_draw_part``; straight into the face only).  Its mips are rebuilt with
        the others'; when no face was drawn and the chain was built from the faces as they
        are, not even that.  ``plan``: what is kept, worked out already (``capture_probe``,
        for a capture drawn now, before any other); None works it out here.  ``finishes``:
        whether its faces are drawn as a tree's root is, answered already (``capture_probe``
        asks ``_finished`` once, a look over the transparent batches); None asks here."""
        renderer = self.renderer
        resolution = next(iter(views.values())).size[0]
        cube = self.cube(key, resolution)
        trees = surfaces is not None and depth > 0
        # (a face that roots a tree, or finishes as a root does; ``direct`` forced: the path check's faces)
        if finishes is None:
            finishes = trees or (direct is None and self._finished())
        if direct is None:
            direct = self._direct(finishes)
        targets_direct = self._face_targets(key, cube.texture) if direct and not finishes else None
        direct = targets_direct is not None
        if plan is None or plan.direct != direct:  # (a face target refused just now: the copy path)
            plan = self._keep_plan(key, views, unchanged, direct, finishes, regions)
        records = self._sky_faces.setdefault(key, {})
        scene_records = self._scene_faces.setdefault(key, {})
        kept, sky_only, scene = plan.kept, plan.sky_only, plan.scene
        drawn = set()
        with self._drawing_into(key):
            for face, view in sorted(views.items()):
                if face in kept:
                    self.faces_kept += 1
                    continue
                record = plan.records[face]
                drawn.add(face)
                part = plan.parts.get(face)
                if part is not None:
                    self._draw_part(view, targets_direct.faces[face], part)
                elif targets_direct is not None:
                    self.scene_pass.draw([view], targets_direct.faces[face], FACE)
                else:
                    levels = self._stacks.setdefault(resolution, LevelStack(self.ctx))
                    targets = levels.get(0, view.size)
                    if trees:
                        self.scene_pass.draw([view], targets, FACE_TREE)
                        self.tree.render(view, levels, surfaces, TreeSettings(depth_cap=depth), blends, FACE_TREE)
                    elif finishes:   # (no mirror or portal view: its foam, glass and slot as a root's)
                        self.scene_pass.draw([view], targets, FACE_TREE)
                        self.scene_pass.finish_root(view, targets, FACE_TREE)
                    else:
                        self.scene_pass.draw([view], targets, FACE)
                    renderer.raw_gl.copy_to_cube_face(targets.framebuffer, cube.texture, face, SCRATCH_UNIT)
                    renderer.checkpoint(f"probe face {face} copy")
                if face in sky_only:
                    records[face] = record
                else:
                    records.pop(face, None)
                if scene is None:
                    scene_records.pop(face, None)
                else:
                    scene_records[face] = (record, scene)
                renderer.stats.probe_faces += 1
        stale = self._mips_stale.get(key)
        # The chains were built from the faces as they were, and every face drawn now was
        # drawn in part: the chains change within the parts' rectangle alone (their union).
        parts = [plan.parts[face] for face in drawn] if stale == set() and drawn <= plan.parts.keys() else []
        rect = None
        if parts:
            rect = (min(x for x, _, _, _ in parts), min(y for _, y, _, _ in parts),
                    max(x + w for x, _, w, _ in parts), max(y + h for _, y, _, h in parts))
        if stale is not None:
            stale |= drawn
        if build_mips and (stale is None or stale or cube.prefilter != prefilter):
            faces = stale if stale is not None and cube.prefilter == prefilter else None
            cube.prefilter = self.mips.build(key, cube.texture, prefilter, faces=faces,
                                             rect=rect if faces is not None and prefilter == "mips" else None)
            self._mips_stale[key] = set()
            drawn.add(-1)
        if drawn:
            self._versions[key] = self._versions.get(key, 0) + 1
            renderer.note_scene_change()

    def _draw_part(self, view: View, target: FaceTarget, rect: tuple[int, int, int, int]) -> None:
        """Draw the part ``rect`` (a scissor rectangle) of a face, the rest left as it is: the
        colour and depth cleared within it, then the scene pass with the view scissored to it.
        A fragment's value does not depend on the scissor (only which are written), so the
        texels within are those a whole drawing gives."""
        part = replace(view, scissor=rect)
        part._block = view.camera_block()  # the same camera: the block as packed
        target.framebuffer.use()
        apply_pass_state(self.ctx, FACE_CLEAR, (0, 0, *target.size), rect)
        target.framebuffer.clear(depth=1.0, viewport=rect)
        self.scene_pass.draw([part], target, FACE_PART)
        self.faces_in_part += 1
        self.texels_in_part += rect[2] * rect[3]

    def parts_possible(self, key: int) -> bool:
        """Whether a face of probe ``key`` could be drawn in part at its next capture: its
        faces are drawn straight into its cube (``CubeFaceTargets``) and some face holds the
        records a part is drawn by (a six-pass capture without view trees drew it), and
        drawing fewer texels saves time here (``ProbePaths.fill_bound``)."""
        return key in self._faces and bool(self._scene_faces.get(key)) and self.paths.fill_bound

    def written_elsewhere(self, key: int) -> None:
        """Probe ``key``'s cube was written by something other than a capture (a test's
        sentinel, a tool): no face is kept as it is at its next capture, nor its mips."""
        self.renderer.note_scene_change()
        self._forget_faces(key)
        self._mips_stale.pop(key, None)

    def _forget_faces(self, key: int) -> None:
        """No face of probe ``key`` holds what a record says: none is kept at its next
        capture, and what samples its cube changed."""
        self._sky_faces.pop(key, None)
        self._scene_faces.pop(key, None)
        self._versions[key] = self._versions.get(key, 0) + 1

    def _finished(self) -> bool:
        """Whether a face with no view tree (``depth`` 0, or none in sight) is still finished as
        a tree's root is (drawn into a 2D level target, copied into its face,
        ``ScenePass.finish_root``): while a water has shore foam, a surface refracts the screen
        (``Refractive.screen``) or a mirror or portal is see-through (water), which a view
        drawn whole leaves out (it showed no foam, glass refracting the probe's image, and a
        see-through mirror's material alone, without its fallback's reflection), so a probe
        shows them at any ``depth`` as the camera does."""
        renderer = self.renderer
        return bool(renderer.foam.entities) or bool(renderer.refracting_batches()) \
            or any(see_through_surface(batch) for batch in renderer.transparent_batches())

    def _direct(self, trees: bool) -> bool:
        """Whether faces are drawn straight into the cube (else into a 2D target, copied)."""
        return not trees and self.direct_faces and self.renderer.path_checks.trusted("direct_faces")

    def _keep_plan(self, key: int, views: dict[int, View], unchanged: frozenset[int], direct: bool,
                   trees: bool, regions: dict[int, tuple[float, float, float, float]] | None = None) -> _KeepPlan:
        """Which faces of ``views`` a six-pass capture keeps as they are (``capture``): those
        showing the sky alone as they did at their last drawing from the same record, and,
        where no face draws a view tree (``trees``), those of ``unchanged`` last drawn with
        the same records as now; and the records a face drawn now is given."""
        renderer = self.renderer
        first = next(iter(views.values()))
        made = self._views.get(key)
        cameras = made[2] if made is not None else {}
        records = {face: self._sky_record(view, direct, cameras.get(face) if made[1][face] is view else None)
                   if made is not None else self._sky_record(view, direct) for face, view in views.items()}
        if self.pictures is not None and self.pictures.entities:
            # A monitor's picture drawn again since a face was drawn changes the face where
            # its screen shows, a change no scheduler's box or rectangle follows (the picture
            # may be drawn after the schedule, this frame): the pictures a face may show, with
            # their versions, are in its record, and a face showing one drawn since is drawn whole.
            faces = list(views)
            shown = self.pictures.versions_shown([views[face] for face in faces])
            records = {face: (records[face], pictures) for face, pictures in zip(faces, shown, strict=True)}
        kept = set()
        scene = None if trees else self._scene_record(key)
        if scene is not None and unchanged:
            scene_records = self._scene_faces.get(key, {})
            kept.update(face for face in unchanged
                        if face in views and scene_records.get(face) == (records[face], scene))
        # The sky-alone faces of the rest (the faces drawn need it too: their records).
        rest = frozenset(views) - kept
        sky_only = sky_only_faces(first.eye, rest, first.skip,
                                  [*renderer.opaque_batches(), *renderer.transparent_batches()]) if rest else rest
        sky_records = self._sky_faces.get(key, {})
        kept.update(face for face in sky_only if face in sky_records and sky_records[face] == records[face])
        parts = {}
        if regions and scene is not None and direct:
            # Faces every change since their drawing reached within a part (the scheduler's
            # ``ProbeDue.regions``), drawn last with the same records as now: that part alone
            # is drawn, straight into the face (the copy path's 2D target holds another face).
            scene_records = self._scene_faces.get(key, {})
            size = first.size[0]
            for face, region in regions.items():
                if face in views and face not in kept and scene_records.get(face) == (records[face], scene):
                    rect = texel_rect(region, size)
                    if rect is None:
                        kept.add(face)  # no texel of it can show a change
                    elif rect != (0, 0, size, size):
                        parts[face] = rect
        return _KeepPlan(frozenset(kept), sky_only, scene, records, direct, parts)

    def _scene_record(self, key: int) -> tuple:
        """What every face of probe ``key`` is drawn with besides its camera and the sky: the
        batches in drawing order with their instances' order (``InstanceBatch.layout``) and
        material variants (which build of the scene program draws each: one instance's
        change of variant may move its whole batch to the build that switches), the
        shadow maps' blocks (fits, slots, filter sizes), their lookups and filter, the
        virtual lights shining, the reflection filtering, the fog, and the cubes (with how often each
        was written) of the other probes the batches sample.  What the instances themselves
        are, where shadows fall and the lights are the scheduler's to follow
        (``ProbeDue.unchanged``)."""
        renderer = self.renderer
        shadows = self.scene_pass.shadows
        batches = (*renderer.opaque_batches(), *renderer.transparent_batches())
        cubes = renderer.probe_cubes
        sampled = sorted({probe for batch in batches for probe in (batch.probe, batch.second_probe, batch.rest_probe)
                          if probe and probe != key})
        return (tuple((_Same(batch), batch.layout, batch.variants) for batch in batches), shadows.block.tobytes(),
                shadows.virtual_block.tobytes(), shadows.program_defines, shadows.filter, shadows.virtual_shining,
                renderer.reflection_anisotropy, renderer.fog.block,
                tuple((probe, _Same(cubes.get(probe)), self._versions.get(probe, 0)) for probe in sampled))

    def _sky_record(self, view: View, direct: bool, camera: tuple | None = None) -> tuple:
        """What a face showing the sky alone is drawn from: the view's camera (the sky pass's
        directions), its size, the sky texture, the shader library's reloads (the sky
        program) and the path (straight into the face, or copied from a 2D target).  Equal
        records draw equal pixels.  ``camera``: the view's part, made already (``face_views``)."""
        renderer = self.renderer
        if camera is None:
            camera = (view.view.to_tuple(), view.proj.to_tuple(), tuple(view.eye), view.size)
        return (*camera, direct, _Same(renderer.sky), renderer.shaders.reloads, renderer.fog.block)

    @contextmanager
    def _drawing_into(self, key: int):
        """While probe ``key``'s cube is drawn into: nothing samples it (the scene pass gives
        what samples it the sky), and it is bound on no texture unit a pass reads or a
        copy left it on (a texture drawn into while bound for sampling is a rendering
        feedback loop, undefined on a GPU; llvmpipe forgives it)."""
        renderer = self.renderer
        for unit in (PROBE_UNIT, PROBE2_UNIT, PROBE_REST_UNIT, SCRATCH_UNIT, CUBE_MIP_UNIT):
            bind_texture(self.ctx, renderer.sky, unit)
        renderer.sky.use(self.ctx.default_texture_unit)  # moderngl's own unit: not in the record
        renderer.capturing = key
        try:
            yield
        finally:
            renderer.capturing = 0
            bind_texture(self.ctx, renderer.sky, SCRATCH_UNIT)  # the copies bound the cube there

    def _face_targets(self, key: int, cube: moderngl.TextureCube) -> CubeFaceTargets | None:
        """The probe's direct face targets (made, or remade for a new cube), or None where a
        cube face cannot be attached (then faces are copied)."""
        if not self.direct_faces:
            return None
        targets = self._faces.get(key)
        if targets is None or targets.cube is not cube:
            if targets is not None:
                targets.release()
                del self._faces[key]
            try:
                targets = self._faces[key] = CubeFaceTargets(self.ctx, self.renderer.raw_gl, cube)
            except RuntimeError:
                self.direct_faces = False
                return None
        return targets

    def capture_layered(self, key: int, views: dict[int, View], culled: bool = True, prefilter: str = "mips",
                        build_mips: bool = True, into: str | None = None) -> None:
        """All six faces in one pass (``ScenePass.draw_layered``), then the cube's mips.  No
        view trees: mirrors and portals show their own surface.  ``into`` is where the pass
        draws: "cube" (straight into the cube map) or "array" (a six-layer 2D array, each
        layer then copied into its face); None takes what ``ProbePaths.layered_target``
        trusts on this context, the cube where neither is (a caller asked for this path)."""
        into = into or self.paths.layered_target() or "cube"
        kind = {"cube": LayeredCubeTarget, "array": LayeredArrayTarget}[into]
        resolution = views[0].size[0]
        cube = self.cube(key, resolution)
        target = self._layered.get(key)
        if target is None or target.cube is not cube.texture or type(target) is not kind:
            if target is not None:
                target.release()
                del self._layered[key]
            target = self._layered[key] = kind(self.ctx, cube.texture)
        self._forget_faces(key)  # every face drawn by the layered programs: no record holds
        self._mips_stale.pop(key, None)
        with self._drawing_into(key):
            self.scene_pass.draw_layered([views[face] for face in range(6)], target, culled)
            if isinstance(target, LayeredArrayTarget):
                target.copy_to_cube(SCRATCH_UNIT)  # a unit no pass reads; _drawing_into rebinds the sky there
                self.renderer.checkpoint("layered capture's copy into the cube")
        if build_mips:
            cube.prefilter = self.mips.build(key, cube.texture, prefilter)
            self._mips_stale[key] = set()
        self.renderer.stats.probe_faces += 6
        self.renderer.note_scene_change()

    def read_face(self, key: int, face: int) -> np.ndarray:
        """Face ``face`` of probe ``key``'s cube map, linear RGB float32 (rows in texture order:
        row t of ``engine.core.cube_faces.face_directions``)."""
        cube = self.cubes[key]
        n = cube.resolution
        data = np.frombuffer(cube.texture.read(face), np.float16).reshape(n, n, 4)
        return data[..., :3].astype(np.float32)

    def project_waiting(self) -> None:
        """Project the captures the full irradiance table refused a row (their probes' boxes
        lit nothing), now that rows may be free: a probe captured once (``refresh="once"``)
        is not captured again to take one.  Whole chains only (a chain stale since its last
        build waits for the capture that builds it again)."""
        for key in sorted(self.boxed):
            cube = self.cubes.get(key)
            version = self._versions.get(key, 0)
            if cube is None or self._projected.get(key) == version or self._mips_stale.get(key):
                continue
            if not self.irradiance.project(key, cube):
                return   # (the table is full again)
            self._projected[key] = version

    def drop(self, key: int) -> None:
        self.renderer.note_scene_change()
        self._forget_faces(key)
        self._versions.pop(key, None)
        self._views.pop(key, None)
        self._projected.pop(key, None)
        self._mips_stale.pop(key, None)
        self.boxed.discard(key)
        self.moved_by.pop(key, None)   # (a later probe of this entity stamps past every record of this one)
        self.mips.drop(key)
        self.irradiance.drop(key)
        faces = self._faces.pop(key, None)
        if faces is not None:
            faces.release()
        target = self._layered.pop(key, None)
        if target is not None:
            target.release()
        cube = self.cubes.pop(key, None)
        if cube is not None:
            cube.texture.release()
            self._let_go_levels(cube.resolution)

    def _let_go_levels(self, resolution: int) -> None:
        """Release the level stack the faces of ``resolution`` root their view trees in once no
        probe of that resolution is left (kept while one is: its next capture draws into it)."""
        if not any(cube.resolution == resolution for cube in self.cubes.values()):
            levels = self._stacks.pop(resolution, None)
            if levels is not None:
                levels.release()

    def release(self) -> None:
        for key in list(self.cubes):
            self.drop(key)
        for levels in self._stacks.values():
            levels.release()
        self._stacks.clear()
        self.tree.release()
        self.mips.release()
