"""Bloom: Jimenez's mip-chain bloom ("Next Generation Post Processing in Call of Duty:
Advanced Warfare", SIGGRAPH 2014), run by the present pass on the finished HDR image.

Down: the image is halved ``levels`` times, each level drawn from the one above by the
13-tap filter (``shaders/bloom_down.frag``; the first step with Karis's firefly weighting
and the optional soft threshold).  Where the chain starts is ``BloomPass.first_step``:
"half" (Jimenez's chain) or "quarter" (as Unity URP's quarter downscale: the first level is
a quarter of the image's size, drawn straight from the image by a 9-tap tent, four
Karis-weighted boxes of 2 x 2 texel means over the 6 x 6 texels around the level's texel,
so the levels are a quarter of the image's size and below; the half-start chain's tightest
blur is left out).  Up: from
the smallest, each level is added (blending ONE, ONE) into the next larger through a 3x3
tent (``shaders/bloom_up.frag``), so the largest level ends up holding the sum of every
level's blur.  The present shader takes that sum times ``1 / levels`` (the mean of the
blurs: it keeps the image's mean) and mixes it in.  The image itself is only read: the main image the end images keep
(``engine/render/end_images.py``) stays the linear HDR the views drew.

Its cost is that of ``2 levels - 1`` small full-screen draws over at most a third of the
screen's pixels (a twelfth from a quarter), whatever the number of mirrors and portals
composited into the image.  The half-size level is most of it: its 13-tap step reads the
whole image and the last step up writes it.  On a software rasteriser, where that is pixel
work of the CPU (about 4.5 of the chain's 5.5 ms at 640x360 on llvmpipe), the chain starts at
a quarter; a GPU keeps the half-size start.  The quarter start's chain ends at the
GPU's smallest level (``level_sizes``: one level fewer), so ``Bloom.levels`` spreads a glow
as far on either.  The quarter start is one draw from the image
(an earlier form drew the image's 2 x 2 means at half size first, then the 13-tap step on
them: two draws, 1.4 ms of CPU at 640x360 on llvmpipe against 0.55 for the one 9-tap draw).
The chain's textures are made at the first bloomed frame of a size and released when no
camera asks for bloom (``release``).

What a frame's chain asks of the GL is kept small, since on a GPU those calls are its whole
cost on the CPU: the targets, their framebuffers and the order of the steps are made once
for an image size, level count, start, threshold and radius (``_make_plan``), and a frame
runs them: the down steps are one pass and the up steps another, each applying its state
once at its start (a level's framebuffer, used by nothing else, brings its whole-level
viewport and no scissor when bound), and each step binds its target, its source (on
``BLOOM_UNIT``, a unit no other pass uses: the HDR image stays on ``PRESENT_UNIT`` for the
present draw, and the sky on its unit for the next frame's scene pass) and draws: three
calls a step, ``2 levels - 1`` steps.  ``chain_of`` (for measuring) draws the chain of
another image size on this one: ``benchmarks/lighting.py`` times a tiny frame issuing the
draws of a 640x360 frame's chain.

What each draw reads is made cheap for a software rasteriser, where every tap is CPU work:
the levels are float32 (``LEVEL_DTYPE``: a half-float texel is converted at every tap,
and llvmpipe reads them at about half the cost; at most a third of the screen's pixels, so
a GPU pays little bandwidth for it, and the sums lose no precision), and the up step at
the default radius 1 reads its tent in four bilinear taps, not nine (``bloom_up.frag``
PAIRED: the same sum, each tap weighing a pair of texels; 640x360 on llvmpipe, measured
interleaved: the chain 1.56 -> 1.28 ms, the present draw's bloom tap 0.38 -> 0.18 ms).
"""
from __future__ import annotations

import moderngl

from components.post import Bloom
from engine.render.bindings import BLOOM_UNIT, PRESENT_UNIT, PassState, apply_pass_state, bind_texture
from engine.render.shader_library import ShaderLibrary
from engine.render.targets import release_framebuffer

MIN_LEVEL_SIDE = 2   # no level smaller than this many pixels a side: fewer levels are made
FIRST_STEPS = ("half", "quarter")   # where the chain starts (BloomPass.first_step)
LEVEL_DTYPE = "f4"   # the levels' texels: float32 RGBA (see the module's docstring)
_DOWN = PassState()
_UP = PassState(blend=(moderngl.ONE, moderngl.ONE))


def level_sizes(size: tuple[int, int], levels: int, first_step: str = "half") -> list[tuple[int, int]]:
    """The chain's sizes below ``size``: the first half the image (a quarter with
    ``first_step`` "quarter"), each next half the one above (rounded down), as many of
    ``levels`` as keep both sides at least ``MIN_LEVEL_SIDE``.  The quarter start leaves
    the half-size level out and ends where the half start does (``levels - 1`` of them, at
    least one): its widest glow reaches as far as a GPU's, not twice as far."""
    sizes = []
    width, height = size
    if first_step == "quarter":
        levels = max(levels - 1, 1)
    for index in range(levels):
        divisor = 4 if index == 0 and first_step == "quarter" else 2
        width, height = width // divisor, height // divisor
        if width < MIN_LEVEL_SIDE or height < MIN_LEVEL_SIDE:
            break
        sizes.append((width, height))
    return sizes


def stand_in_sizes(size: tuple[int, int], chain_of: tuple[int, int], levels: int,
                   first_step: str = "half") -> list[tuple[int, int]]:
    """The chain ``BloomPass.chain_of`` draws on an image of ``size``: the levels of an
    image of ``chain_of`` (``level_sizes``), each scaled by ``size`` over ``chain_of``, no
    side under ``MIN_LEVEL_SIDE``."""
    return [(max(MIN_LEVEL_SIDE, w * size[0] // chain_of[0]), max(MIN_LEVEL_SIDE, h * size[1] // chain_of[1]))
            for w, h in level_sizes(chain_of, levels, first_step)]


class BloomPass:
    """The mip chain and its two programs (and the first step's builds)."""

    def __init__(self, ctx: moderngl.Context, shaders: ShaderLibrary, software: bool = False) -> None:
        self.ctx = ctx
        self.shaders = shaders
        self.first_step = "quarter" if software else "half"
        self._vaos: dict[tuple, moderngl.VertexArray] = {}
        self.textures: list[moderngl.Texture] = []
        self._framebuffers: list[moderngl.Framebuffer] = []
        self.levels = 0   # levels drawn by the last ``draw``
        # What ``draw`` runs (``_make_plan``) and what it was made for: made again only when
        # the image's size, the levels, the start, the threshold's use or the radius change.
        self._plan: tuple | None = None
        self._plan_for: tuple | None = None
        self._written: dict[tuple[int, str], object] = {}   # (vao id, uniform) -> the value last written
        self._chain_of: tuple[int, int] | None = None

    @property
    def first_step(self) -> str:
        """Where the chain starts: "half" (a GPU's default) or "quarter" (a software
        rasteriser's: the two dearest steps draw a quarter of the pixels, and the first reads
        the image 9 times a quarter-size pixel, not 13 times a half-size one; the look loses
        its tightest blur)."""
        return self._first_step

    @first_step.setter
    def first_step(self, value: str) -> None:
        if value not in FIRST_STEPS:
            raise ValueError(f"bloom first_step must be one of {', '.join(map(repr, FIRST_STEPS))}, got {value!r}")
        self._first_step = value
        self._plan_for = None

    @property
    def chain_of(self) -> tuple[int, int] | None:
        """For measuring only (None, the default: the image's own chain).  An image size whose
        chain is drawn instead: as many levels as ``level_sizes`` gives an image of this size
        (with ``first_step``), each as large as that level scaled by the real image's size over
        this one, no side under ``MIN_LEVEL_SIDE``.  The same draws a frame of that size makes,
        over next to no pixels: ``benchmarks/lighting.py`` times a tiny frame with the chain of
        a 640x360 one (``stand_in_sizes``) to measure what the chain costs a GPU host's CPU.
        The image it blooms is not that size's look."""
        return self._chain_of

    @chain_of.setter
    def chain_of(self, size: tuple[int, int] | None) -> None:
        if size is not None:
            if (not isinstance(size, tuple) or len(size) != 2
                    or not all(isinstance(v, int) and v >= 1 for v in size)):
                raise ValueError(f"bloom chain_of must be None or a (width, height) of positive ints, got {size!r}")
        self._chain_of = size
        self._plan_for = None

    def _vao(self, fragment: str, **defines: str) -> moderngl.VertexArray:
        key = (fragment, tuple(sorted(defines.items())))
        vao = self._vaos.get(key)
        if vao is None:
            program = self.shaders.program("present.vert", fragment, defines=defines or None)
            # The first step reads the HDR image where the present pass will; the others a level.
            program["source"].value = PRESENT_UNIT if "FIRST" in defines else BLOOM_UNIT
            vao = self._vaos[key] = self.ctx.vertex_array(program, [])
        return vao

    def _set(self, vao: moderngl.VertexArray, name: str, value) -> None:
        """Write a uniform only when its value changes (each write is a GL call)."""
        key = (id(vao), name)
        if self._written.get(key) != value:
            vao.program[name].value = value
            self._written[key] = value

    def _target(self, size: tuple[int, int]) -> tuple[moderngl.Texture, moderngl.Framebuffer]:
        texture = self.ctx.texture(size, 4, dtype=LEVEL_DTYPE)
        texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
        texture.repeat_x = texture.repeat_y = False
        return texture, self.ctx.framebuffer([texture])

    def draw(self, hdr: moderngl.Texture, bloom: Bloom) -> moderngl.Texture | None:
        """Bloom ``hdr`` (read only): returns the largest level (half or a quarter of the
        image's size, ``first_step``), holding the sum of the levels' blurs (``self.levels``
        of them), or None where the image is too small to halve even once."""
        threshold = bloom.threshold > 0.0
        key = (hdr.size, bloom.levels, self._first_step, threshold, bloom.radius == 1.0)
        plan = self._plan if key == self._plan_for else self._make_plan(key)
        self.levels = len(self.textures)
        if plan is None:
            return None
        first, down, up, steps, rise = plan
        ctx = self.ctx
        if threshold:
            knee = bloom.threshold * bloom.knee
            self._set(first, "threshold", (bloom.threshold, bloom.threshold - knee, 2.0 * knee, 0.25 / max(knee, 1e-5)))
        if not key[4]:
            self._set(up, "radius", bloom.radius)
        # Down, then up: a pass each, its state applied at its start; from one level to the
        # next only the target and the source change (a level's framebuffer, made here and
        # used by nothing else, sets its whole-level viewport and no scissor when used).
        (framebuffer, viewport, _), *rest = steps
        framebuffer.use()
        apply_pass_state(ctx, _DOWN, viewport)
        bind_texture(ctx, hdr, PRESENT_UNIT)
        first.render(moderngl.TRIANGLES, vertices=3)
        for framebuffer, _, source in rest:
            framebuffer.use()
            bind_texture(ctx, source, BLOOM_UNIT)
            down.render(moderngl.TRIANGLES, vertices=3)
        state = _UP
        for framebuffer, viewport, source in rise:
            framebuffer.use()
            if state is not None:
                apply_pass_state(ctx, state, viewport)
                state = None
            bind_texture(ctx, source, BLOOM_UNIT)
            up.render(moderngl.TRIANGLES, vertices=3)
        return self.textures[0]

    def _make_plan(self, key: tuple) -> tuple | None:
        """The chain's targets and programs for ``key`` (image size, levels, start, threshold
        on, radius 1): the first step's build, the down and up builds, each step down's
        (target, its viewport, source level) and each step up's; None where no level fits."""
        size, levels, first_step, threshold, paired = key
        sizes = level_sizes(size, levels, first_step) if self._chain_of is None else \
            stand_in_sizes(size, self._chain_of, levels, first_step)
        if [t.size for t in self.textures] != sizes:
            self.release_targets()
            for level in sizes:
                texture, framebuffer = self._target(level)
                self.textures.append(texture)
                self._framebuffers.append(framebuffer)
        self._plan_for = key
        if not sizes:
            self._plan = None
            return None
        defines = {"FIRST": "1"}
        if first_step == "quarter":
            defines["QUARTER"] = "1"
        if threshold:
            defines["THRESHOLD"] = "1"
        up = self._vao("bloom_up.frag", PAIRED="1") if paired else self._vao("bloom_up.frag")
        textures, framebuffers = self.textures, self._framebuffers
        steps = [(framebuffers[index], (0, 0, *sizes[index]), textures[index - 1] if index else None)
                 for index in range(len(sizes))]
        rise = [(framebuffers[index], (0, 0, *sizes[index]), textures[index + 1])
                for index in range(len(sizes) - 2, -1, -1)]
        self._plan = (self._vao("bloom_down.frag", **defines), self._vao("bloom_down.frag"), up, steps, rise)
        return self._plan

    def passes(self) -> int:
        """Draws the last ``draw`` made (levels down, levels - 1 up)."""
        if not self.levels:
            return 0
        return 2 * self.levels - 1

    def target_count(self) -> int:
        """Textures the chain holds now."""
        return len(self.textures)

    def release_targets(self) -> None:
        for framebuffer in self._framebuffers:
            release_framebuffer(framebuffer)
        for texture in self.textures:
            texture.release()
        self._framebuffers.clear()
        self.textures.clear()
        self._plan_for = self._plan = None

    def release(self) -> None:
        self.release_targets()
        for vao in self._vaos.values():
            vao.release()
        self._vaos.clear()
        self._written.clear()
