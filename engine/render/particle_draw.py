"""Particles on the GPU: each emitter's rows in a buffer of its own, drawn into a view as one
instanced strip of four vertices a particle (``shaders/particle.vert``: a square facing the
view, made from the vertex's index; ``shaders/particle.frag``).

The particles stage (``systems/particle_system.py``) hands each emitter's rows here once a
frame (``update``: sizes, colours and frames worked out on the CPU,
``engine/core/particle_cloud.py``); the scene pass draws them into each view in among its glass
(``ScenePass``: the main view, every mirror and portal view, per view or batched level alike),
with the view's Camera block, so a particle in a mirror faces the mirror's image camera and
is cut at the mirror's plane as any geometry is.  Blending is premultiplied (the glass's
``BLEND_PREMULTIPLIED``), so "additive" (alpha written 0) and "alpha" emitters draw with one
state, in any order among each other; an "alpha" emitter's own particles are drawn farthest
first in each view (its rows sorted by distance from the view's ``sorting_eye`` and written
again before its draw, only those that can reach the view: ``in_view``, so a mirror that sees
part of a cloud draws that part), an "additive" one's as they are (a sum has no order);
emitters are drawn farthest first by the middles of their boxes (two clouds that mix are
sorted as wholes), and among the view's glass batches by the same measure (``ScenePass``: an
emitter goes in before the first glass batch whose middle is nearer).  They test the view's
depth and write none, and write only the colour image: a particle is no entity, so the
surface and seen ids (what the claims, the outline and picking read) keep what is behind it.
An emitter whose box (its particles' centres, grown by the largest half-diagonal) cannot reach
a view (``batch_cull.batch_reach``), or whose ``Visibility`` hides it there, draws nothing there.
A ribbon (``ParticleEmitter.ribbon``) is drawn as a strip of four a segment, from each
particle to the next born (the ``RIBBON`` build: each segment reads four rows of the one
buffer, bound four times a row apart, ``_ribbon_array``), unsorted.

Limits: particles beyond a see-through surface (water, a see-through mirror or portal) blend
after it, over its reflection; a probe's capture leaves them out (``ParticleEmitter``'s
docstring says why); a lit particle's light is its centre's (the sun's and lamps' shadows, the light from all round at
that point, and the light through mirrors and portals there).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from contextlib import nullcontext
from dataclasses import dataclass, field

import moderngl
import numpy as np

from components.particles import ParticleEmitter
from engine.core.particle_cloud import ROW_FLOATS, ROW_POSITION, ROW_SIZE, ROW_STREAK
from engine.render.batch_cull import batch_reach
from engine.render.bindings import (
    BLEND_PREMULTIPLIED,
    CAMERA_BINDING,
    CLIP_VIEW_PLANE,
    CLOUDS_BINDING,
    COOKIE_UNIT,
    FOG_BINDING,
    IRRADIANCE_BINDING,
    IRRADIANCE_UNIT,
    LAMP_SEE_THROUGH_UNIT,
    LIGHTS_BINDING,
    NODE_UNIT,
    PARTICLE_DEPTH_UNIT,
    PARTICLE_UNIT,
    POINT_SHADOW_UNITS,
    SEE_THROUGH_UNIT,
    SHADOW_ATLAS_UNIT,
    SHADOWS_BINDING,
    SKY_UNIT,
    SPOT_SHADOW_UNIT,
    VIRTUAL_LIGHTS_BINDING,
    VIRTUAL_SEE_THROUGH_UNIT,
    VIRTUAL_SHADOW_UNIT,
    PassState,
    apply_pass_state,
    bind_texture,
    set_scissor,
)
from engine.render.gpu import Gpu
from engine.render.instances import read_by
from engine.render.shadows import ShadowMaps
from engine.render.targets import LevelStack, RenderTargets
from engine.render.view_plan import level_rects
from engine.render.views import View
from engine.rules.visibility_rules import drawn_in

ROW_BYTES = ROW_FLOATS * 4
_FORMAT = "3f 1f 4f 1f 1f 3f/i"
_ATTRIBUTES = ("in_center", "in_size", "in_color", "in_angle", "in_frame", "in_streak")
# A ribbon's segment's inputs: each of the four rows it reads (particle.vert's RIBBON build:
# in_prev_*, in_*, in_next_*, in_after_*) and each field of a row (its offset, its format).
_RIBBON_ROWS = ("in_prev_", "in_", "in_next_", "in_after_")
_RIBBON_FIELDS = (("center", 0, "3f"), ("size", 12, "1f"), ("color", 16, "4f"), ("angle", 32, "1f"),
                  ("frame", 36, "1f"))
# Depth tested, not written (the framebuffer's mask, set by the caller's pass), no culling (a
# mirror's view turns the winding), the view's plane clipped, blended premultiplied.
PARTICLE_PASS = PassState(depth_func="<", cull=False, clips=frozenset((CLIP_VIEW_PLANE,)),
                          blend=BLEND_PREMULTIPLIED)
# A reflection level's particles drawn again into the main view's reactive mask: that image's
# depth is the main view's, in front of every mirror's world, so untested; clipped by the
# view's plane and its rectangle (scaled to the mask) only.
_THROUGH_PASS = PassState(cull=False, clips=frozenset((CLIP_VIEW_PLANE,)), blend=BLEND_PREMULTIPLIED)
# The colour image alone of a view's framebuffer (colour, surface ids, seen ids) takes writes.
_COLOUR_ONLY = ((True, True, True, True), (False, False, False, False), (False, False, False, False))


@dataclass
class GpuEmitter:
    """One emitter's particles on the GPU: its rows (a CPU copy for sorting), its buffer
    (grown by doubling), its look, its box and where it is drawn (``drawn_code``)."""

    buffer: moderngl.Buffer
    rows: np.ndarray
    blend: str
    lit: bool
    translucency: float
    sheet: tuple[int, int]
    texture: object | None              # the TextureData, while it holds a share of it
    gl_texture: moderngl.Texture | None
    code: int
    row_boxes: np.ndarray = field(default_factory=lambda: np.zeros((1, 2, 3)))
    vertex_arrays: dict = field(default_factory=dict)  # by program build
    count: int = 1  # boxes (batch_cull reads an emitter as a batch of one box)
    uploaded: bool = False  # its rows are in its buffer
    softness: float = 0.0
    written: tuple | None = None  # (rows, Camera block, count) an alpha emitter's buffer holds, sorted for that view
    ribbon: bool = False  # its rows joined into a band (ParticleEmitter.ribbon): uploaded with the ends repeated

    @property
    def particles(self) -> int:
        return len(self.rows)


class ParticleDraw:
    """Every emitter's GPU record by entity, and their draw into a view."""

    def __init__(self, gpu: Gpu, shadows: ShadowMaps) -> None:
        self.gpu = gpu
        self.ctx = gpu.ctx
        self.shadows = shadows
        self.emitters: dict[int, GpuEmitter] = {}
        self._programs: dict[tuple, moderngl.Program] = {}
        self._reloads = gpu.shaders.reloads
        # Temporal AA's reactive mask this frame: (the main view's level, the mask's framebuffer:
        # its R8 image and that level's depth, the main tree's levels), set by the main stage
        # while TAA is on; the particles drawn into that level are drawn into it too
        # (``REACTIVE``), and so are those of the tree's reflection levels, seen through their
        # surfaces (the same build, unmasked and not soft: untested against its depth, only
        # inside each view's rectangle, so a particle hidden in a mirror's world still marks
        # its pixels: a pixel taking more of this frame than it needs, never a particle's light
        # dimmed).
        # None: off.
        self.reactive: tuple[RenderTargets, moderngl.Framebuffer, LevelStack] | None = None

    # --- what the particles stage hands over ---------------------------------------------
    def update(self, entity: int, emitter: ParticleEmitter, rows: np.ndarray, code: int) -> None:
        """``entity``'s emitter (a ParticleEmitter) now has ``rows`` (``ROW_FLOATS`` float32 a
        particle) and is drawn where ``code`` says (``visibility_rules.drawn_code``)."""
        record = self.emitters.get(entity)
        texture = emitter.texture
        retextured = record is not None and record.texture is not texture
        if retextured:
            self._let_go_texture(record)
        if record is None:
            record = self.emitters[entity] = GpuEmitter(
                self.ctx.buffer(reserve=max(len(rows), 16) * ROW_BYTES), rows, emitter.blend, emitter.lit,
                emitter.translucency, emitter.sheet, None, None, code)
        if record.texture is not texture and texture is not None:
            record.gl_texture = self.gpu.shared_texture(texture, "ParticleEmitter.texture")
            record.texture = texture
        look = (emitter.blend, emitter.lit, emitter.translucency, emitter.sheet, code, texture, emitter.softness,
                emitter.ribbon)
        if not retextured and record.uploaded and np.array_equal(rows, record.rows) \
                and look == (record.blend, record.lit, record.translucency, record.sheet, record.code, record.texture,
                             record.softness, record.ribbon):
            return  # (a still cloud, a paused game: nothing a view shows changed)
        record.blend, record.lit, record.translucency = emitter.blend, emitter.lit, emitter.translucency
        record.softness, record.ribbon = emitter.softness, emitter.ribbon
        record.sheet, record.code, record.rows, record.uploaded = emitter.sheet, code, rows, True
        # A ribbon's segment reads four rows (the point before it, its two ends, the point
        # after: the band bends through each point along the line through its neighbours),
        # so its rows go up with the first and last repeated.
        uploaded = np.concatenate([rows[:1], rows, rows[-1:]]) if emitter.ribbon and len(rows) else rows
        if len(uploaded) * ROW_BYTES > record.buffer.size:
            record.buffer.release()
            record.buffer = self.ctx.buffer(reserve=_grown(len(uploaded)) * ROW_BYTES)
            self._drop_arrays(record)
        record.written = None
        if len(rows):
            record.buffer.write(uploaded.tobytes())
            # (its square's half-diagonal, and a streak's whole length behind it)
            reach = float(rows[:, ROW_SIZE].max()) * (0.5 * math.sqrt(2.0)) + float(
                np.sqrt(np.square(rows[:, ROW_STREAK]).sum(axis=1).max()))
            centres = rows[:, ROW_POSITION]
            record.row_boxes = np.array([[centres.min(axis=0) - reach, centres.max(axis=0) + reach]])
        self.gpu.note_scene_change()

    def drop(self, entity: int) -> None:
        """``entity``'s emitter is gone: its buffer, arrays and share of its texture released."""
        record = self.emitters.pop(entity, None)
        if record is None:
            return
        self._drop_arrays(record)
        self._let_go_texture(record)
        record.buffer.release()
        self.gpu.note_scene_change()

    @property
    def particles(self) -> int:
        """Living particles of every emitter (what a view may draw)."""
        return sum(record.particles for record in self.emitters.values())

    # --- the draw --------------------------------------------------------------------------
    def visible(self, views: Sequence[View], size: tuple[int, int]) -> list[list[tuple[float, GpuEmitter]]]:
        """For each of ``views`` (of a target of ``size``), the emitters it draws: with living
        particles, whose box can reach it (``batch_reach``) and that its kinds and layers show,
        each with the squared distance of its box's middle from the view's ``sorting_eye``,
        farthest first (how emitters are ordered, among themselves and among the glass)."""
        live = [record for record in self.emitters.values() if record.particles]
        if not live or not views:
            return [[] for _ in views]
        reach = batch_reach(views, size, live)
        found = []
        for index, view in enumerate(views):
            eye = np.array(view.sorting_eye, dtype=np.float64)
            drawn = [(float(np.square(record.row_boxes[0].mean(axis=0) - eye).sum()), record)
                     for record, reaches in zip(live, reach[index], strict=True)
                     if reaches and drawn_in(record.code, view.view_mask)]
            drawn.sort(key=lambda pair: -pair[0])
            found.append(drawn)
        return found

    def draw(self, views: Sequence[View], targets: RenderTargets, masked: bool, ambient_probes: bool,
             first_index: int = 0, conditions: Sequence[moderngl.Query] | None = None,
             chosen: Sequence[Sequence[GpuEmitter]] | None = None, copy_depth: bool = True) -> None:
        """Each of ``views`` (its Camera block at ``first_index`` + its place, uploaded by the
        caller) draws its emitters (``chosen``, one list a view, in order; else all it draws:
        ``visible``), into ``targets``' view framebuffer (colour, surface and seen ids, depth;
        bound now, its depth mask off); ``masked``: a reflection level's views, each only
        where the node image names it.  Where a soft emitter draws, the depth is copied first
        (``RenderTargets.depth_copy``; ``copy_depth`` False: copied already for these views,
        whose depth the transparent slot does not change).  ``conditions``: a samples query a
        view, its draws conditional on it (as the scene pass's).  The pass state is this
        module's afterwards."""
        if chosen is None:
            chosen = [[record for _, record in drawn] for drawn in self.visible(views, targets.size)]
        if not any(chosen):
            return
        gpu, ctx = self.gpu, self.ctx
        framebuffer = targets.view_framebuffer
        if copy_depth and any(record.softness > 0.0 for drawn in chosen for record in drawn):
            gpu.raw_gl.copy_depth(framebuffer, targets.depth_copy(), PARTICLE_DEPTH_UNIT)
        writes = framebuffer.color_mask  # (the glass slot's: back to it after)
        framebuffer.color_mask = _COLOUR_ONLY
        apply_pass_state(ctx, PARTICLE_PASS, (0, 0, *targets.size), views[0].scissor)
        mask = self.reactive
        reactive = mask if mask is not None and mask[0] is targets and not masked else None
        through = mask if mask is not None and mask[0] is not targets and mask[2].holds(targets) else None
        try:
            for index, view in enumerate(views):
                if not chosen[index]:
                    continue
                with nullcontext() if conditions is None else conditions[index].crender:
                    set_scissor(ctx, view.scissor)
                    gpu.bind_view_at(first_index + index)
                    for record in chosen[index]:
                        self._draw_one(record, view, masked, ambient_probes)
                    if reactive is not None:   # (the same again into temporal AA's reactive mask)
                        reactive[1].use()
                        for record in chosen[index]:
                            self._draw_one(record, view, masked, ambient_probes, reactive=True)
                        framebuffer.use()
                    elif through is not None:   # (a reflection level's, seen through its surfaces)
                        through[1].use()
                        apply_pass_state(ctx, _THROUGH_PASS, (0, 0, *through[0].size),
                                         _in_mask(view.scissor, targets.size, through[0].size))
                        for record in chosen[index]:
                            self._draw_one(record, view, False, ambient_probes, reactive=True, through=True)
                        framebuffer.use()
                        apply_pass_state(ctx, PARTICLE_PASS, (0, 0, *targets.size), view.scissor)
        finally:
            framebuffer.color_mask = writes

    def _draw_one(self, record: GpuEmitter, view: View, masked: bool, ambient_probes: bool,
                  reactive: bool = False, through: bool = False) -> None:
        """One emitter's particles in ``view``: an "alpha" emitter's rows written again for the
        view, only those whose squares can reach it (``in_view``), farthest first; an
        "additive" one's as uploaded.  ``reactive``: its ``REACTIVE`` build (temporal AA's
        mask), into whatever is bound; ``through``: a reflection level's into that mask (no
        softness: the mask's depth is the main view's)."""
        count = record.particles
        if record.ribbon:  # its segments, a point to the next, drawn as a whole
            count -= 1
            if count < 1:
                return
        elif record.blend == "alpha" and count > 1:
            written = (record.rows, view.camera_block())  # (a still frame's one view: the buffer holds it)
            if record.written is None or record.written[0] is not written[0] or record.written[1] != written[1]:
                rows = record.rows[in_view(record.rows, view)]
                eye = np.array(view.sorting_eye, dtype=np.float32)
                far = np.square(rows[:, ROW_POSITION] - eye).sum(axis=1)
                record.buffer.write(rows[np.argsort(-far, kind="stable")].tobytes())
                record.written = (*written, len(rows))
            count = record.written[2]
            if not count:
                return
        vao = self._vertex_array(record, masked, ambient_probes, reactive, through)
        if record.gl_texture is not None:
            bind_texture(self.ctx, record.gl_texture, PARTICLE_UNIT)
        if "fog_sky_map" in vao.program:   # (Fog.aerial_perspective's colours: the sky's cube map)
            bind_texture(self.ctx, self.gpu.sky, SKY_UNIT)
        vao.render(moderngl.TRIANGLE_STRIP, vertices=4, instances=count)
        self.gpu.stats.draw_calls += 1

    def _vertex_array(self, record: GpuEmitter, masked: bool, ambient_probes: bool,
                      reactive: bool = False, through: bool = False) -> moderngl.VertexArray:
        if self.gpu.shaders.reloads != self._reloads:
            self.forget()
        program = self._program(record.gl_texture is not None, record.lit, masked, ambient_probes,
                                record.softness > 0.0 and not through, record.ribbon, reactive)
        vao = record.vertex_arrays.get(program.glo)
        if vao is None:
            if record.ribbon:
                vao = record.vertex_arrays[program.glo] = self._ribbon_array(program, record.buffer)
            else:
                vao = record.vertex_arrays[program.glo] = self.ctx.vertex_array(
                    program, [read_by(program, record.buffer, _FORMAT, *_ATTRIBUTES)])  # (gl_VertexID read)
        for name, value in (("sheet", record.sheet), ("coverage", 1.0 if record.blend == "alpha" else 0.0),
                            ("translucency", record.translucency), ("softness", record.softness)):
            if name in program:  # (a build without a texture reads no sheet; an unlit one no translucency)
                program[name].value = value
        return vao

    def _ribbon_array(self, program: moderngl.Program, buffer: moderngl.Buffer) -> moderngl.VertexArray:
        """A ribbon's vertex array: segment ``i`` (an instance) reads rows ``i`` to ``i + 3`` of
        its buffer (the point before it, its start, its end, the point after), each input
        bound at its row's offset (the one buffer four times; what the build dropped left out)."""
        vao = self.ctx.vertex_array(program, [])
        for row, prefix in enumerate(_RIBBON_ROWS):
            for name, offset, fmt in _RIBBON_FIELDS:
                if prefix + name in program:
                    vao.bind(program[prefix + name].location, "f", buffer, fmt, offset=row * ROW_BYTES + offset,
                             stride=ROW_BYTES, divisor=1)
        return vao

    def _program(self, sprite: bool, lit: bool, masked: bool, ambient_probes: bool, soft: bool,
                 ribbon: bool = False, reactive: bool = False) -> moderngl.Program:
        """The build for a textured emitter or not (``SPRITE``), lit or not (``LIT``, with the
        shadow lookups the shadows stage compiled in, and the probes' boxes and an irradiance
        volume where they light the scene: ``Gpu.ambient_defines``), soft or not (``SOFT``), a
        ribbon or not (``RIBBON``), masked or not, fogged while the camera's fog is (not the reactive mask's,
        ``REACTIVE``: the particle's own cover and light)."""
        shadowing = self.shadows.program_defines if lit else ()
        virtual = lit and self.shadows.virtual_shining  # light through mirrors and portals, while one shines
        fog = () if reactive else self.gpu.fog.defines
        ambient = self.gpu.ambient_defines if lit and ambient_probes else ()  # the boxes', a volume's light
        cookies = self.gpu.spot_cookies.defines if lit else ()   # the lamps' cookies and panels' pictures
        clouds = self.gpu.clouds.shadow_defines if lit else ()   # a CloudLayer's shadows on the sun and moons
        key = (sprite, lit, masked, ambient, soft, shadowing, fog, ribbon, virtual, reactive, cookies, clouds)
        program = self._programs.get(key)
        if program is None:
            defines = dict(fog)
            if reactive:
                defines["REACTIVE"] = "1"
            if ribbon:
                defines["RIBBON"] = "1"
            if sprite:
                defines["SPRITE"] = "1"
            if masked:
                defines["MASKED"] = "1"
            if soft:
                defines["SOFT"] = "1"
            if lit:
                defines["LIT"] = "1"
                defines.update(shadowing)
                defines.update(ambient)
                defines.update(cookies)
                defines.update(clouds)
                if virtual:
                    defines["VIRTUAL_LIGHTS"] = "1"
            program = self.gpu.shaders.program("particle.vert", "particle.frag", defines=defines)
            program["Camera"].binding = CAMERA_BINDING
            for block, binding in (("Lights", LIGHTS_BINDING), ("Shadows", SHADOWS_BINDING),
                                   ("Irradiance", IRRADIANCE_BINDING), ("Fog", FOG_BINDING),
                                   ("VirtualLights", VIRTUAL_LIGHTS_BINDING), ("Clouds", CLOUDS_BINDING)):
                if block in program:
                    program[block].binding = binding
            for name, unit in (("sprite_map", PARTICLE_UNIT), ("node_map", NODE_UNIT),
                               ("scene_depth", PARTICLE_DEPTH_UNIT),
                               ("shadow_atlas", SHADOW_ATLAS_UNIT), ("point_shadow0", POINT_SHADOW_UNITS[0]),
                               ("point_shadow1", POINT_SHADOW_UNITS[1]), ("spot_atlas", SPOT_SHADOW_UNIT),
                               ("irradiance_table", IRRADIANCE_UNIT), ("virtual_atlas", VIRTUAL_SHADOW_UNIT),
                               ("spot_cookies", COOKIE_UNIT), ("fog_sky_map", SKY_UNIT),
                               ("lamp_see_through_atlas", LAMP_SEE_THROUGH_UNIT),
                               ("see_through_atlas", SEE_THROUGH_UNIT),
                               ("virtual_see_through_atlas", VIRTUAL_SEE_THROUGH_UNIT)):
                if name in program:
                    program[name].value = unit
            self._programs[key] = program
        return program

    # --- resources -------------------------------------------------------------------------
    def _drop_arrays(self, record: GpuEmitter) -> None:
        for vao in record.vertex_arrays.values():
            vao.release()
        record.vertex_arrays.clear()

    def _let_go_texture(self, record: GpuEmitter) -> None:
        if record.texture is not None:
            self.gpu.let_go_texture(record.texture)
        record.texture = record.gl_texture = None

    def forget(self) -> None:
        """After a shader hot reload: programs and vertex arrays made again."""
        for record in self.emitters.values():
            self._drop_arrays(record)
        self._programs.clear()  # (the library owns and releases them)
        self._reloads = self.gpu.shaders.reloads

    def release(self) -> None:
        """Every emitter's buffer and arrays (the renderer releases the textures it shares)."""
        for record in self.emitters.values():
            self._drop_arrays(record)
            record.buffer.release()
        self.emitters.clear()
        self._programs.clear()


def in_view(rows: np.ndarray, view: View) -> np.ndarray:
    """Which of ``rows`` (drawn particles) can put a pixel in ``view``: the sphere about each
    (its square's half-diagonal, and a streak's length) not wholly outside one of the view's
    side planes, its near plane or its clip plane (a mirror's or portal's surface): the planes
    of the view-projection's rows (Gribb and Hartmann), each scaled to metres.  Conservative:
    what it drops cannot be drawn."""
    m = np.array(view.view_proj, dtype=np.float64)  # (row by row)
    planes = np.stack([m[3] + m[0], m[3] - m[0], m[3] + m[1], m[3] - m[1], m[3] + m[2],
                       np.array(view.clip_plane, dtype=np.float64)])
    lengths = np.linalg.norm(planes[:, :3], axis=1)
    planes = planes / np.where(lengths > 0.0, lengths, 1.0)[:, None]  # (the clip plane of a root: 0, 0, 0, 1)
    radius = rows[:, ROW_SIZE].astype(np.float64) * (0.5 * math.sqrt(2.0)) \
        + np.sqrt(np.square(rows[:, ROW_STREAK].astype(np.float64)).sum(axis=1))
    distance = rows[:, ROW_POSITION].astype(np.float64) @ planes[:, :3].T + planes[:, 3]
    return (distance >= -(radius[:, None] + 1e-4)).all(axis=1)


def _grown(n: int) -> int:
    """Rows a buffer holds for ``n``: the next power of two (a growing cloud reallocates a few times)."""
    return max(16, 1 << (n - 1).bit_length())


def _in_mask(scissor: tuple[int, int, int, int] | None, size: tuple[int, int],
             mask: tuple[int, int]) -> tuple[int, int, int, int] | None:
    """A reflection level's view's ``scissor`` (in its level of ``size`` pixels) in the reactive
    mask's pixels (``mask``: the main view's size), rounded outwards (``level_rects``)."""
    if scissor is None:
        return None
    x, y, w, h = scissor
    return tuple(level_rects(np.array([[x, y, x + w, y + h]], np.float64), size, mask)[0].tolist())
