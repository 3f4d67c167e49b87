"""Screen-space refraction: glass (``Refractive.screen``, the default) shows what its view drew
behind it, bent, where three.js's transmission, Godot's refraction and HDRP's screen-space
refraction read the frame behind a transparent surface.

Speculum draws forward, so what lies behind a refracting surface is known only once the rest
of the view is drawn.  Every view a view tree draws (the camera's, its mirror and portal
views, a probe face, which roots a tree or is finished as a root) leaves its refracting
batches out of its opaque draws
(``Gpu.tree_opaque_batches``) and draws them last but its glass, in the tree's finish of its
level (``ScenePass.refract``, from ``finish_root`` and ``finish_level``: after the levels
below, the screen reflections and the light shafts are composited into it):

1. **The copy** (``RefractionCopy.take``): the level's colour and window depth into one
   RGBA32F image (``shaders/refraction_copy.frag``: one sampler for both, in scene builds
   already near the fragment stage's 16), with its mip chain for rough glass.
2. **The draws**: each view's refracting batches with their ``SCREEN_REFRACTION`` builds,
   depth tested and written as opaque surfaces are; the refraction (``refracted_light`` in
   ``shaders/scene.frag``) marches its refracted ray (a solid ball's: the ray out of it)
   across the copy (``shaders/include/screen_refraction.glsl``) and reads the colour where
   the ray goes behind what was drawn, the sky the view drew where it runs on over that
   (``refraction_sky``: at the ray's vanishing point; a reflection level leaves its sky to
   its composite, so its copy marks those pixels: ``shaders/refraction_copy.frag``), the
   probe's or sky's image where it finds nothing, faded between.

Glass behind glass (``refraction_layers``): a view's refracting instances are drawn in
layers, farthest first, each instance a layer after the farther ones whose rectangles on
screen (widened: ``LAYER_REACH``) its own overlaps, and each layer over a copy taken after
the layers before it, so the nearer glass shows the farther (three.js's transmission leaves
transmissive objects out of its one copy; this is depth peeling by object, at most
``MAX_REFRACTION_LAYERS`` copies a level).  A layer's run of a batch's rows is drawn alone
by the ``drawn_instances`` uniform of the ``SCREEN_REFRACTION`` builds (GL 4.1 has no base
instance): the other rows' vertices are clipped away.

The transparent slot (blended glass, decals, particles) is drawn in two parts about the
refracting surfaces, each in its back-to-front order: before them, into the copy, its things
that lie behind every glass they meet on screen (``behind_the_glass``) and meet none of the
things drawn after (``ScenePass._slot_before``: things apart on screen blend in either
order), so the glass shows them; after them the rest, which blends over the glass (what of
it lies behind glass is unseen through it). What the
copy cannot hold is not seen through the glass: what the view did not draw (off its edges,
behind what it shows). A refracting surface's own reflection is found the same way: its
reflected ray marched across the copy (``screen_found`` in ``shaders/scene.frag``; HDRP's
screen-space reflection of transparent surfaces), the probe's or sky's image where it finds
nothing. Either find gives way to the probe's or sky's image where the rays of neighbouring
pixels land far apart in the copy (``REFRACTION_SPREAD``: a ball's reflection, minified most
towards its rim, would be one texel of the copy a pixel, speckled; the cube is read at the
mip level of that footprint). Drawn after them, it takes no part in the screen reflections
of the surfaces around it (they do not show it) nor in the screen's ambient occlusion. A
probe's faces, each the root of its own tree (node 0: the march keeps to its view's node),
march their own copies as the camera's view does (``ProbeCaptures._finished``); only a view
drawn whole (the paths' self-checks) draws its refracting batches with its opaque draws,
reading the probe or the sky. Where a build with the march would read more samplers than the
fragment stage has (a 16-unit driver's fullest builds), the build without serves and a
``GLLimitWarning`` says so.

Cost: one full-screen copy and its mips a level that draws a refracting batch (a layer of
glass behind glass, one more), and the march
(at most ``REFRACTION_STEPS`` steps and ``REFRACTION_REFINE`` halvings of a ray, three rays
with dispersion) in the refracting surfaces' pixels."""
from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from typing import TYPE_CHECKING, NamedTuple

import moderngl
import numpy as np

from engine.core.errors import GLLimitWarning
from engine.render.bindings import (
    REFRACTION_COPY_UNIT,
    REFRACTION_SOURCE_UNITS,
    PassState,
    apply_pass_state,
    bind_sampler,
    bind_texture,
)
from engine.render.gpu import Gpu
from engine.render.targets import RenderTargets, release_framebuffer
from engine.rules.probe_rules import box_corners
from engine.rules.screen_rects import ndc_extents, view_matrix

if TYPE_CHECKING:
    from engine.render.instances import InstanceBatch
    from engine.render.views import View

# The copy's mip chain for rough glass: at most this many levels above the image.
MAX_COPY_LOD = 6
# How many sizes' copies are kept at once (the main tree's levels share one; a probe face's
# tree and a resized output others); the one used longest ago goes first.
KEPT_SIZES = 3
_PASS = PassState()
# Layers of refracting surfaces a level draws at most, each over a copy that holds the layers
# behind it (refraction_layers); surfaces past it are drawn in the last, which does not see
# the others of that layer behind them (RenderStats.refraction_layers_cut).
MAX_REFRACTION_LAYERS = 4
# A surface's rectangle on screen, widened by this share of its width and height each side for
# the layers: a lens shows what lies around it (a ball inverts and magnifies a field wider
# than itself), so glass beside it on screen, not only behind it, goes in a layer before it.
LAYER_REACH = 0.5
ALL_INSTANCES = (0, 2 ** 31 - 1)   # the instances a refraction draw draws, where it is not a layer's run
KEPT_LAYOUTS = 64   # refraction_layers' answers kept (a frame's views with glass behind glass)
LAYOUT_IN_PYTHON = 24   # instances up to which refraction_layers orders them in plain Python, numpy past it
# The GL types of sampler uniforms (GL 4.1's tables 2.10 and 2.11: the float, shadow, integer
# and unsigned samplers of every target), for sampler_count.
_SAMPLER_TYPES = frozenset((*range(0x8B5D, 0x8B65), *range(0x8DC0, 0x8DD9), *range(0x900C, 0x9010),
                            *range(0x9108, 0x910E)))


def sampler_count(program: moderngl.Program) -> int:
    """How many sampler uniforms ``program`` reads (an array's elements each)."""
    return sum(member.array_length for member in (program[name] for name in program)
               if isinstance(member, moderngl.Uniform) and member.gl_type in _SAMPLER_TYPES)


def refuse_screen_refraction(needed: int, units: int) -> None:
    """Say that a scene build refracts the probe's or sky's image only: with the march it
    would read ``needed`` samplers, and the fragment stage has ``units``."""
    warnings.warn(GLLimitWarning(
        f"Refractive.screen: a scene build with screen-space refraction reads {needed} samplers and this "
        f"OpenGL's fragment stage has {units} (GL_MAX_TEXTURE_IMAGE_UNITS): its surfaces refract the probe's "
        "or sky's image only (fewer maps or kinds of shadowed light on them make room)"), stacklevel=4)


class RefractionLayers(NamedTuple):
    """A view's refracting instances in the order they are drawn (``refraction_layers``):
    each layer's runs, a run a batch's rows ``first`` to ``past`` (drawn together), the
    pixels each layer can draw in (x0, y0, x1, y1: its instances' rectangles on screen, not
    widened: what the next layer's copy must take again), and how many instances past
    ``MAX_REFRACTION_LAYERS`` were drawn in the last layer."""

    runs: list[list[tuple[InstanceBatch, int, int]]]
    drawn: list[tuple[int, int, int, int]]
    cut: int


def refraction_layers(view: View, size: tuple[int, int], batches: Sequence[InstanceBatch],
                      kept: dict | None = None) -> RefractionLayers:
    """Glass behind glass: ``batches``' instances (refracting, reaching ``view`` drawn into a
    viewport of ``size``) in layers, farthest first by their boxes' centres, each instance one
    layer in front of the nearest-to-it farther instances its widened rectangle on screen
    (``LAYER_REACH``) overlaps: a layer's copy holds the layers drawn before it, so a glass ball
    behind a pane shows through the pane (depth peeling by object, as engines sort their
    transparent objects back to front).  One instance, or none overlapping: one layer, drawn as
    before.  What a layer cannot see is its own layer's other glass, which none of its rectangles
    reaches, and glass past the limit in the last layer.  ``kept``: answers kept by the view's
    camera, the batches and their boxes (a still view's glass is not laid out again)."""
    if sum(batch.count for batch in batches) <= 1:
        return RefractionLayers([[(batch, 0, batch.count) for batch in batches]], [], 0)
    boxes = np.concatenate([batch.row_boxes for batch in batches])           # [n, lo/hi, xyz]
    key = None
    if kept is not None:
        key = (view.camera_block(), size, view.scissor, tuple(batches), boxes.tobytes())
        found = kept.get(key)
        if found is not None:
            return found
    x, y, w, h = view.scissor or (0, 0, *size)
    n = len(boxes)
    drawn = box_rects(view, size, boxes)
    reach = (drawn[:, 2:] - drawn[:, :2]) * LAYER_REACH
    rects = np.concatenate([drawn[:, :2] - reach, drawn[:, 2:] + reach], axis=1)
    over = meets(rects, rects)
    unmeasured = np.isnan(boxes).any(axis=(1, 2))
    centres = np.where(unmeasured[:, None], 0.0, boxes.mean(axis=1))
    distance = np.where(unmeasured, 0.0, np.linalg.norm(centres - np.asarray(view.eye, np.float64), axis=1))
    order = np.argsort(-distance, kind="stable").tolist()   # (ties in the batches' order)
    if n <= LAYOUT_IN_PYTHON:   # (a few instances: plain Python over the table is the cheaper)
        table, layer = over.tolist(), [0] * n
        for position, i in enumerate(order):
            row = table[i]
            layer[i] = max((layer[j] + 1 for j in order[:position] if row[j]), default=0)
    else:   # (many: a row of the table at a time)
        placed, drawn_layer = np.zeros(n, bool), np.full(n, -1, np.int64)
        for i in order:
            behind = over[i] & placed
            drawn_layer[i] = drawn_layer[behind].max() + 1 if behind.any() else 0
            placed[i] = True
        layer = drawn_layer.tolist()
    cut = sum(1 for k in layer if k >= MAX_REFRACTION_LAYERS)
    layer = [min(k, MAX_REFRACTION_LAYERS - 1) for k in layer]
    count = max(layer) + 1
    runs: list[list[tuple[InstanceBatch, int, int]]] = [[] for _ in range(count)]
    spans = [[math.inf, math.inf, -math.inf, -math.inf] for _ in range(count)]
    for k, (x0, y0, x1, y1) in zip(layer, drawn.tolist(), strict=True):
        span = spans[k]
        span[0], span[1], span[2], span[3] = min(span[0], x0), min(span[1], y0), max(span[2], x1), max(span[3], y1)
    # (a pixel more each side: the rasteriser's rounding)
    bounds = [(max(math.floor(x0) - 1, x), max(math.floor(y0) - 1, y), min(math.ceil(x1) + 1, x + w),
               min(math.ceil(y1) + 1, y + h)) for x0, y0, x1, y1 in spans]
    start = 0
    for batch in batches:
        rows = layer[start:start + batch.count]
        start += batch.count
        first = 0
        for row in range(1, batch.count + 1):   # (runs of rows in one layer)
            if row == batch.count or rows[row] != rows[first]:
                runs[rows[first]].append((batch, first, row))
                first = row
    found = RefractionLayers(runs, bounds, cut)
    if kept is not None:
        if len(kept) >= KEPT_LAYOUTS:
            kept.clear()
        kept[key] = found
    return found


def box_rects(view: View, size: tuple[int, int], boxes: np.ndarray, widen: float = 0.0) -> np.ndarray:
    """The rectangles on screen (x0, y0, x1, y1 in pixels, within the view's) of world
    ``boxes`` ([n, lo/hi, xyz]) seen by ``view`` drawn into a viewport of ``size``, each
    widened by ``widen`` of its width and height each side; a box reaching behind the eye, or
    not measured (NaN), the whole view."""
    width, height = size
    x, y, w, h = view.scissor or (0, 0, width, height)
    unmeasured = np.isnan(boxes).any(axis=(1, 2))
    boxes = np.where(unmeasured[:, None, None], 0.0, boxes)
    corners = np.ones((len(boxes), 8, 4))
    corners[:, :, :3] = box_corners(boxes[:, 0], boxes[:, 1])
    low, high, behind, _ = ndc_extents(corners, view_matrix(view))
    scale = np.array([width, height], np.float64)
    rects = np.concatenate([(low * 0.5 + 0.5) * scale, (high * 0.5 + 0.5) * scale], axis=1)
    ahead = ~behind & ~unmeasured
    if widen:
        reach = (rects[:, 2:] - rects[:, :2]) * widen
        rects[:, :2] -= reach
        rects[:, 2:] += reach
    rects[~ahead] = (x, y, x + w, y + h)
    rects[:, [0, 2]] = rects[:, [0, 2]].clip(x, x + w)
    rects[:, [1, 3]] = rects[:, [1, 3]].clip(y, y + h)
    return rects


def _box_distances(eye: np.ndarray, boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The nearest and farthest distances from ``eye`` of each of ``boxes`` ([n, lo/hi, xyz]);
    a box not measured (NaN): 0 and infinity."""
    unmeasured = np.isnan(boxes).any(axis=(1, 2))
    lo, hi = np.where(unmeasured[:, None], 0.0, boxes[:, 0]), np.where(unmeasured[:, None], 0.0, boxes[:, 1])
    near = np.linalg.norm(np.clip(eye, lo, hi) - eye, axis=1)
    far = np.linalg.norm(np.maximum(np.abs(eye - lo), np.abs(eye - hi)), axis=1)
    return np.where(unmeasured, 0.0, near), np.where(unmeasured, np.inf, far)


def behind_the_glass(view: View, size: tuple[int, int], glass: np.ndarray, others: np.ndarray,
                     other_rects: np.ndarray | None = None) -> np.ndarray:
    """For each of the world boxes ``others`` ([n, lo/hi, xyz]: a view's see-through things),
    whether it may be drawn before the refracting ``glass`` boxes, into the copy they march,
    and so show through them: whether it lies wholly farther from ``view``'s eye than every
    glass box whose widened rectangle on screen (``LAYER_REACH``) its own rectangle meets
    (true where it meets none).  A see-through thing in front of glass it meets must blend
    over the glass, after it (``ScenePass.draw_transparent``'s ``part``).  ``other_rects``:
    ``others``' rectangles (``box_rects``), where the caller has them."""
    if not len(glass) or not len(others):
        return np.ones(len(others), bool)
    eye = np.asarray(view.eye, np.float64)
    glass_rects = box_rects(view, size, glass, LAYER_REACH)
    if other_rects is None:
        other_rects = box_rects(view, size, others)
    _, glass_far = _box_distances(eye, glass)
    other_near, _ = _box_distances(eye, others)
    return ~(meets(other_rects, glass_rects) & (other_near[:, None] <= glass_far[None, :])).any(axis=1)


def meets(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """[i, j]: whether rectangle i of ``first`` and j of ``second`` (x0, y0, x1, y1) overlap."""
    a, b = first[:, None], second[None, :]
    return (a[..., 0] < b[..., 2]) & (b[..., 0] < a[..., 2]) & (a[..., 1] < b[..., 3]) & (b[..., 1] < a[..., 3])


class _Copy:
    """One size's copy image (colour and window depth, with mips) and its framebuffer."""

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int]) -> None:
        self.size = size
        self.top_lod = max(0, min(MAX_COPY_LOD, max(size).bit_length() - 1))
        self.texture = ctx.texture(size, 4, dtype="f4")
        self.texture.repeat_x = self.texture.repeat_y = False
        self.texture.build_mipmaps(0, self.top_lod)  # (the chain's storage; built again at each copy)
        self.texture.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        self.framebuffer = ctx.framebuffer([self.texture])

    def release(self) -> None:
        release_framebuffer(self.framebuffer)
        self.texture.release()


class RefractionCopy:
    """The copies screen-space refraction marches, one a size, and the pass that makes them."""

    def __init__(self, gpu: Gpu) -> None:
        self.gpu = gpu
        self.ctx = gpu.ctx
        self._copies: dict[tuple[int, int], _Copy] = {}  # by size, the one used last at the end
        self._vao: moderngl.VertexArray | None = None
        self._vao_of = -1  # the shader library's reloads when it was made
        self.copies = 0  # copies taken so far (tests count them)
        # Frames are told apart by the frame's RenderStats (Engine.frame gives each its own).
        self._frame: object = None
        self._took_this_frame = self._took_last_frame = False
        self._whole_of: RenderTargets | None = None   # the targets the last whole copy was of, and its frame
        self._whole_frame: object = None

    def take(self, targets: RenderTargets, rough: bool, region: tuple[int, int, int, int] | None = None) -> None:
        """Copy ``targets``' colour and depth into the copy of its size and bind it at
        ``REFRACTION_COPY_UNIT``; with ``rough`` (a surface drawn over it has a roughness)
        build its mips, else its chain ends at the image (every lod reads it: on llvmpipe the
        chain is about a tenth of a glass-filled frame's refraction).  ``region`` (x, y,
        width, height): copy only those pixels again, the rest as the last copy of this size
        took them (a layer of glass behind glass: what the layer before drew)."""
        ctx, gpu = self.ctx, self.gpu
        self._count_frames()
        self._took_this_frame = True
        copy = self._copies.pop(targets.size, None)
        if copy is None:
            copy = _Copy(ctx, targets.size)
            while len(self._copies) >= KEPT_SIZES:
                self._copies.pop(next(iter(self._copies))).release()
        self._copies[targets.size] = copy
        vao = self._program()
        color_unit, depth_unit = REFRACTION_SOURCE_UNITS
        bind_texture(ctx, targets.color, color_unit)
        bind_texture(ctx, targets.depth, depth_unit)
        bind_sampler(ctx, gpu.depth_values(), depth_unit)  # (its depths as values, compared with nothing)
        copy.framebuffer.use()
        apply_pass_state(ctx, _PASS, (0, 0, *targets.size), region)
        vao.render(moderngl.TRIANGLES, vertices=3)
        copy.texture.build_mipmaps(0, copy.top_lod if rough else 0)
        bind_texture(ctx, copy.texture, REFRACTION_COPY_UNIT)
        gpu.stats.draw_calls += 1  # (a copy, as the screen reflections' is: not a pass of its own)
        self.copies += 1
        self._whole_of = targets if region is None else None   # (holds_depth_of)
        self._whole_frame = self._frame
        if gpu.debug:
            gpu.checkpoint("refraction copy")

    def _program(self) -> moderngl.VertexArray:
        shaders = self.gpu.shaders
        if self._vao is None or self._vao_of != shaders.reloads:
            if self._vao is not None:
                self._vao.release()
            program = shaders.program("fullscreen.vert", "refraction_copy.frag")
            program["level_color"].value, program["level_depth"].value = REFRACTION_SOURCE_UNITS
            self._vao = self.ctx.vertex_array(program, [])
            self._vao_of = shaders.reloads
        return self._vao

    def holds_depth_of(self, targets: RenderTargets) -> bool:
        """Whether the copy last taken, this frame, was of all of ``targets`` (so its depth is
        theirs now, while nothing has written depth there since: a level's composites and its
        foam write colour alone).  The foam pass reads it so rather than copy again
        (``ScenePass.draw_foam``)."""
        self._count_frames()
        return self._whole_of is targets and self._whole_frame is self._frame

    def drawn_over(self, targets: RenderTargets) -> None:
        """``targets`` were cleared for another view (a probe's next face in the same level
        target): the copy taken of them holds their depth no longer (``holds_depth_of``)."""
        if self._whole_of is targets:
            self._whole_of = None

    def held(self) -> int:
        """Copy images held now."""
        return len(self._copies)

    def let_go_unused(self) -> None:
        """Release the copies once a whole frame has gone by without a take: asked by a level's
        finish where nothing refracts (``ScenePass.refract``).  Not at once: water takes its copy
        in a composite (``MirrorPasses.composite_level``), which for the root's level comes after
        the finishes of the levels below, and a copy let go there would be made again each
        frame."""
        self._count_frames()
        if self._copies and not self._took_this_frame and not self._took_last_frame:
            self.release()

    def _count_frames(self) -> None:
        stats = self.gpu.stats
        if stats is not self._frame:
            self._frame = stats
            self._took_last_frame, self._took_this_frame = self._took_this_frame, False

    def release(self) -> None:
        """Let the copies go (made again when next taken) and the pass's vertex array."""
        self._whole_of = None
        for copy in self._copies.values():
            copy.release()
        self._copies.clear()
        if self._vao is not None:
            self._vao.release()
            self._vao = None
