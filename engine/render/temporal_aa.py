"""Temporal anti-aliasing (``Renderer.antialias = "taa"``): each frame drawn from a camera
moved by a sub-pixel offset, blended into the history of the frames before
(``shaders/temporal_resolve.frag``), the first pass after the views are drawn.

The offsets are the Halton (2, 3) sequence's first ``JITTER_SAMPLES`` points, one a frame, as
Unreal's and Unity's temporal AA take them: over those frames every pixel has been sampled
across its area, so an edge's pixels settle to its coverage (supersampling spread over
time).  The main view's projection is moved (``jittered``); the mirror and portal views are
built from it, so they move alike, and their composites stay aligned.  The history is
fetched where each pixel's point was last frame (the light's way for the camera's motion,
the seen image's own motion for a thing's: ``engine/render/object_motion.py`` is on while
this is) and clipped to this frame's colours round the pixel, so moving things leave no
trail.  At a render scale below 1 (``engine/render/resample.py``) the history is the
output's size and the resolve is temporal upsampling: each output pixel takes the frame's
samples near its centre, weighed by their distance (a sample that lands in it counts fully),
so over the jitter's offsets (more of them: ``jitter_phases``) it gathers what a full-size
picture would hold.  A cut (another camera, a new size, the first frame) starts the history again.  A
frame of dt 0 (a screenshot) does not move the offset on and blends as the frame before.

Particles write no motion (a cloud has no one surface to follow), so their history would be
fetched from where the things behind them were and clipped away: the main view's particle
draws are drawn again into a reactive mask (``begin_reactive``; ``particle.frag``'s
``REACTIVE`` build: how much each particle changes its pixel), and where it is set this
frame takes most of the pixel (AMD's FSR 2 takes a reactive mask the same way).  Particles
seen in a mirror or through a portal are drawn into it too, through their view's camera,
untested against the main view's depth but inside the view's rectangle
(``ParticleDraw.reactive``): a pixel there may take more of this frame than it needs (a
particle hidden in the mirror's world), never less.

Costs: one full-screen pass of 15 fetches a pixel (and the main view's particles drawn
twice while any live); the main view changes every frame, so a
still camera's reflection levels are drawn again each frame rather than kept
(``systems/reflection_system.py``'s still trees), as a GPU engine's temporal AA does.
"""
from __future__ import annotations

import math

import moderngl
from pyglm import glm

from engine.render.bindings import (
    DOF_SEEN_UNIT,
    PRESENT_UNIT,
    TEMPORAL_HISTORY_UNIT,
    TEMPORAL_REACTIVE_UNIT,
    PassState,
    apply_pass_state,
    bind_texture,
)
from engine.render.shader_library import ShaderLibrary
from engine.render.targets import SEEN_MOVING_CHANNELS, RenderTargets, release_framebuffer
from engine.render.views import View

JITTER_SAMPLES = 8     # offsets before the sequence repeats
BLEND = 0.1            # this frame's share of the resolved picture
_PASS = PassState()


def halton(index: int, base: int) -> float:
    """The ``index``-th (from 1) point of the radical inverse in ``base``, in (0, 1)."""
    result, fraction = 0.0, 1.0
    while index > 0:
        fraction /= base
        result += fraction * (index % base)
        index //= base
    return result


def jitter_phases(size: tuple[int, int], output: tuple[int, int] | None = None) -> int:
    """How many offsets the sequence runs through before it repeats for a picture of ``size``
    shown at ``output``: ``JITTER_SAMPLES``, times the output's pixels a drawn pixel covers
    when it is brought up (temporal upsampling: each output pixel then still has samples
    land in it, as AMD's FSR 2 counts them)."""
    if output is None or output[1] <= size[1]:
        return JITTER_SAMPLES
    return math.ceil(JITTER_SAMPLES * (output[1] / size[1]) ** 2)


def jitter_offset(frame: int, size: tuple[int, int], phases: int = JITTER_SAMPLES) -> tuple[float, float]:
    """Frame ``frame``'s offset of the projection in normalised device units (the picture is
    2 wide): a point of the Halton (2, 3) sequence less a half, in pixels of a picture of
    ``size``, over the size; the sequence repeats after ``phases`` points."""
    index = frame % phases + 1
    return ((halton(index, 2) - 0.5) * 2.0 / size[0], (halton(index, 3) - 0.5) * 2.0 / size[1])


def jittered(view: View, offset: tuple[float, float]) -> View:
    """``view`` with its projection moved by ``offset`` (normalised device units)."""
    view.proj = glm.translate(glm.vec3(offset[0], offset[1], 0.0)) * view.proj
    view.jitter = offset
    return view


class TemporalPass:
    """The resolve and its history: ``draw`` returns the anti-aliased HDR image."""

    def __init__(self, ctx: moderngl.Context, shaders: ShaderLibrary) -> None:
        self.ctx = ctx
        self._shaders = shaders
        self._resolves: dict[bool, moderngl.VertexArray] = {}   # by upsampling, made on first use
        # The reactive mask: an R8 image the main view's particles write how much they change
        # each pixel into (particle_draw's REACTIVE builds), with the main view's level's depth;
        # made for that level (its depth texture), cleared each frame it is asked for.
        self._reactive: tuple[moderngl.Texture, moderngl.Framebuffer, moderngl.Texture] | None = None
        self._reactive_now = False   # this frame's mask was asked for (begin_reactive)
        self._history: list[tuple[moderngl.Texture, moderngl.Framebuffer]] = []   # [written last, the other]
        self.frame = 0                              # the jitter's frame (moved on by frames of dt > 0)
        self.previous: glm.mat4 | None = None       # last frame's view-projection without its jitter
        self.camera: int | None = None
        self.resolved = 0                           # frames blended into the history since its last cut

    def offset(self, size: tuple[int, int], output: tuple[int, int] | None = None) -> tuple[float, float]:
        """This frame's jitter for a picture of ``size`` (shown at ``output``; None: its own size)."""
        return jitter_offset(self.frame, size, jitter_phases(size, output))

    def _make(self, size: tuple[int, int]) -> None:
        if self._history and self._history[0][0].size == size:
            return
        self.release_targets(keep_view=True)
        for _ in range(2):
            texture = self.ctx.texture(size, 4, dtype="f2")
            texture.filter = (moderngl.LINEAR, moderngl.LINEAR)   # (the history is fetched between texels)
            texture.repeat_x = texture.repeat_y = False
            self._history.append((texture, self.ctx.framebuffer([texture])))

    def begin_reactive(self, targets: RenderTargets) -> moderngl.Framebuffer:
        """This frame's reactive mask for the main view's level ``targets`` (its size, testing
        its depth), cleared to 0: the framebuffer the level's particles are drawn into again."""
        kept = self._reactive
        if kept is None or kept[2] is not targets.depth or kept[0].size != targets.size:
            self._release_reactive()
            texture = self.ctx.texture(targets.size, 1)
            texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
            framebuffer = self.ctx.framebuffer([texture], targets.depth)
            framebuffer.depth_mask = False   # (the level's depth: tested, never cleared or written here)
            self._reactive = kept = (texture, framebuffer, targets.depth)
        kept[1].use()
        kept[1].clear(0.0, 0.0, 0.0, 0.0)
        self._reactive_now = True
        return kept[1]

    def _release_reactive(self) -> None:
        if self._reactive is not None:
            release_framebuffer(self._reactive[1])
            self._reactive[0].release()
            self._reactive = None
        self._reactive_now = False

    def _resolve(self, upsample: bool) -> moderngl.VertexArray:
        vao = self._resolves.get(upsample)
        if vao is None:
            vao = self._resolves[upsample] = self._shaders.fullscreen(
                "temporal_resolve.frag", {"UPSAMPLE": "1"} if upsample else None, current_image=PRESENT_UNIT,
                history_image=TEMPORAL_HISTORY_UNIT, seen_image=DOF_SEEN_UNIT, reactive_image=TEMPORAL_REACTIVE_UNIT)
        return vao

    def draw(self, hdr: moderngl.Texture, seen: moderngl.Texture, view: View, camera: int | None,
             dt: float, size: tuple[int, int] | None = None) -> moderngl.Texture:
        """Blend ``hdr`` (drawn through ``view``, jittered) into the history, which is ``size``
        (the output's; None: ``hdr``'s; larger: temporal upsampling); returns the resolved
        image (the history now, kept until the next draw)."""
        size = size if size is not None else hdr.size
        upsample = size != hdr.size
        steady = view.steady_view_proj
        cut = camera != self.camera or not self._history or self._history[0][0].size != size \
            or self.previous is None
        self._make(size)
        written, other = self._history
        resolve = self._resolve(upsample)
        program = resolve.program
        other[1].use()
        apply_pass_state(self.ctx, _PASS, (0, 0, *size))
        bind_texture(self.ctx, hdr, PRESENT_UNIT)
        bind_texture(self.ctx, written[0], TEMPORAL_HISTORY_UNIT)
        bind_texture(self.ctx, seen, DOF_SEEN_UNIT)
        program["inv_view_proj"].write(glm.inverse(steady))
        program["previous_view_proj"].write(steady if cut else self.previous)
        program["eye"].value = tuple(view.eye)
        program["axis"].value = tuple(view.axis)
        program["objects"].value = seen.components == SEEN_MOVING_CHANNELS
        program["blend"].value = 1.0 if cut else BLEND
        if upsample:
            program["jitter"].value = view.jitter
        program["reactive"].value = self._reactive_now
        if self._reactive_now:
            bind_texture(self.ctx, self._reactive[0], TEMPORAL_REACTIVE_UNIT)
            self._reactive_now = False
        resolve.render(moderngl.TRIANGLES, vertices=3)
        if dt > 0.0 or cut:   # (a frame of dt 0 leaves the history as it was: the next blends from it)
            self._history.reverse()
            self.previous, self.camera = steady, camera
            self.resolved = 1 if cut else self.resolved + 1
        if dt > 0.0:
            self.frame += 1
        return other[0]

    def release_targets(self, keep_view: bool = False) -> None:
        if not keep_view:
            self._release_reactive()
        for texture, framebuffer in self._history:
            release_framebuffer(framebuffer)
            texture.release()
        self._history.clear()
        if not keep_view:
            self.previous, self.camera, self.resolved = None, None, 0

    def target_count(self) -> int:
        return len(self._history) + (self._reactive is not None)

    def release(self) -> None:
        self.release_targets()
        for vao in self._resolves.values():
            vao.release()
        self._resolves.clear()
