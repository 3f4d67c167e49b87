"""Still frames: a view tree kept from one frame to the next instead of drawn again.

A tree that ``remember``s (the main view's) leaves what its render did as a ``KeptTree``
(``StillTree.remember``); on a frame whose views show nothing new (the reflect stage
decides: ``systems/reflection_system.py``) ``StillTree.keep`` does only what the root, drawn
anew each frame, needs again (its fallbacks, level 1's composite, its transparent slot) and
levels 1 and below stay as they are.  A still tree with end views whose image has not
settled yet is kept too, less what depends on the end images: those are filled again from
the new image and the render's step 5 (``ViewTree._composite``) is done again from the
deepest level with end views up, over each level as its views drew it (``Refill``, the
copies in ``engine/render/level_copies.py``), until the settle check finds the image the
same as the one it was drawn from (``EndImages.compared``).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import moderngl
from pyglm import glm

from engine.render.end_images import EndImages
from engine.render.gpu import Gpu
from engine.render.level_copies import LevelCopies
from engine.render.mirror_passes import MirrorPasses, PreparedComposites, PreparedFallbacks
from engine.render.scene_options import TREE_ROOT, SceneOptions
from engine.render.scene_pass import ScenePass
from engine.render.targets import LevelStack, RenderTargets
from engine.render.tree_visibility import claimed_pixels
from engine.render.tree_walk import TreeResult, TreeWalk, seen_surfaces
from engine.render.views import PlannedView, View
from engine.resources import SurfaceState

# The frame's counts a tree's render adds, which a frame that keeps it adds again (KeptTree.spent).
LEDGER = ("views_spent", "pixels_spent", "views_cut", "levels_downscaled", "reflection_fallbacks", "views_small")


@dataclass
class KeptTree:
    """What a tree's last render left for a frame that keeps its levels (``StillTree.keep``):
    the targets it drew into (levels 0 to its deepest, each as it was), what it did into the
    root (the root's own fallbacks, then level 1 composited over them), and the counts it
    added to the frame's report and budget ledger, added again by a kept frame (a probe face
    drawn after it spends the same budget either way)."""

    result: TreeResult
    targets: tuple[RenderTargets, ...]
    composite: PreparedComposites | None               # level 1 into the root (None: no views)
    fallbacks: tuple[RenderTargets | None, PreparedFallbacks] | None  # the root's own, with level 1
    spent: tuple[int, int, int, int, int, int]         # views, pixels, cut, downscaled, fallbacks, small
    # Nothing of it depends on last frame (exact visibility, or predicted from counts that
    # ``prediction`` checks; and no end view drawn, or ``history``: end views drawn from an
    # image the settle check may find this one equal to).
    settled: bool
    history: moderngl.Query | None = None  # the settle check of its end images (EndImages.compared)
    ends: tuple | None = None  # the end images' state it was drawn with (StillTree.ends_state): the same, or redraw
    refill: Refill | None = None  # with end views not settled yet: what a kept frame does again (keep)
    prediction: Prediction | None = None  # predicted visibility: the counts it was drawn on, checked once


@dataclass
class Prediction:
    """What a tree drawn on predicted visibility took from last frame's claim counts: for
    each candidate they decided (a view: whether it grows, the pixels it spends; one left
    out for being under the budget's smallest), the count it read (None: not counted then)
    and the query counting its claim this frame.  The next frame draws the same tree only
    if this frame's counts are those: a first or cut frame's tree, or one drawn after the
    camera moved, is not the one the next frame draws (``StillTree.keep`` reads them).  An
    end view's count decides nothing (it is drawn if claimed, and never grows)."""

    queries: list[moderngl.Query]
    read: list[int | None]


@dataclass
class Refill:
    """What a frame that keeps a still tree whose end images have not settled does again
    (``StillTree.keep``): from the deepest level with end views up to the root, each level
    put back as its views drew it (``LevelCopies``, within ``rects``), its end views filled
    from the new image, its fallbacks, the level below composited in, its transparent slot;
    then the finished image kept and compared again (``EndImages.keep``).  Levels below the
    deepest with end views do not change: they stay as they are, composited anew into it."""

    deepest: int                                        # the deepest level with end views
    rects: dict[int, tuple[int, int, int, int]]         # each level's copy (1 to deepest): its views' bounds
    ends: dict[int, tuple[list[PlannedView], list[int], list[glm.mat4]]]  # each level's end views
    transparent: dict[int, tuple[list[PlannedView], SceneOptions, list[moderngl.Query] | None]]  # levels >= 1
    seen: frozenset[int]                                # the surfaces the image shows (EndImages.keep)
    see_through: bool                                   # some batch is transparent: the slots are drawn
    fallbacks: dict[int, tuple[RenderTargets | None, PreparedFallbacks]] = field(default_factory=dict)
    composites: list[PreparedComposites] = field(default_factory=list)  # [d]: level d + 1 into level d


class StillTree:
    """What a tree that ``remember``s (``ViewTree.remember``: the main view's) keeps for the
    frames whose views show nothing new: its last render (``kept``), the copies of its levels
    while its end images settle (``copies``), and the frames that keep it (``keep``).  It
    draws through the tree's own ``passes``, ``scene_pass`` and end images (``ends``)."""

    def __init__(self, renderer: Gpu, passes: MirrorPasses, scene_pass: ScenePass, ends: EndImages | None,
                 copies: LevelCopies) -> None:
        self.renderer = renderer
        self.passes = passes
        self.scene_pass = scene_pass
        self.ends = ends
        # What the last render left (``KeptTree``), for a frame whose views show nothing new
        # (``keep``); None after any other render.
        self.kept: KeptTree | None = None
        # The levels of a still tree as its views drew them, while its end images settle
        # (``save_for_refill``), and the end views the last ``keep`` filled again (0: none).
        self.copies = copies
        self.refilled = 0

    def before(self, size: tuple[int, int]) -> tuple[tuple[int, ...], tuple | None]:
        """What a render that remembers reads before it draws: the frame's ledger so far
        (``LEDGER``), and the end images' state (``ends_state``) for its root's ``size``."""
        stats = self.renderer.stats
        return tuple(getattr(stats, name) for name in LEDGER), self.ends_state(size)

    def remember(self, walk: TreeWalk, levels: LevelStack, before: tuple[tuple[int, ...], tuple | None],
                 refill: Refill | None) -> None:
        """What ``walk``'s render into ``levels`` left, kept (``kept``): its targets, level 1's
        composite and the root's fallbacks, the counts it added since ``before``, whether it
        is settled, and with end views not settled yet what a kept frame does again
        (``refill``, from ``save_for_refill``: here given the fallbacks and composites step 5
        drew)."""
        result, stats = walk.result, self.renderer.stats
        ledger, ends_before = before
        if refill is not None:
            refill.fallbacks, refill.composites = walk.drawn_fallbacks, walk.composited
        history = self.ends.compared if result.end_views and self.ends is not None else None
        self.kept = KeptTree(result, (levels[0], *(step.targets for step in walk.steps)),
                             walk.steps[0].prepared if walk.steps else None, walk.drawn_fallbacks.get(0),
                             tuple(getattr(stats, name) - at_start for name, at_start in zip(LEDGER, ledger,
                                                                                             strict=True)),
                             (not result.end_views or history is not None) and drawn_on_counts(walk),
                             history, ends_before, refill if history is not None else None,
                             None if walk.exact else prediction_of(walk))

    def ends_state(self, size: tuple[int, int]) -> tuple | None:
        """What end views would be drawn from: whether an image is kept, the surfaces it
        shows, its camera (a render that finds them other than its own left them draws other
        end views, or any at all, next frame)."""
        ends = self.ends
        if ends is None:
            return None
        return ends.ready(size), ends.seen, ends.view_proj

    def let_go(self) -> None:
        """No frame draws or keeps this tree now (its camera switched off, no pixels to draw
        into): the kept tree, the copies of its levels and the end images' history are let go,
        not held for a still frame that may never come (the next frame with a view draws the
        tree whole, its end views closed until a history is kept again)."""
        self.kept = None
        if len(self.copies):
            self.copies.release()
        if self.ends is not None:
            self.ends.let_go()

    def keep(self, levels: LevelStack, root: View | None = None,
             root_options: SceneOptions = TREE_ROOT) -> TreeResult | None:
        """The last render's tree again without drawing it: its levels 1 and below hold what
        they held (their images already hold the deeper levels' composites, fallbacks, end
        views and their own transparent slots), and only what the root needs again is done
        (the root is drawn anew each frame, with ``root_options``): its own fallbacks, then
        level 1 composited over them, then its transparent slot (``root``'s: the kept
        render's root view where None).  The frame's report and ledger get the counts the
        render added.  None (nothing done) where there is nothing kept or a level's targets
        are not those drawn into (remade, resized).  The caller decides that nothing those
        levels show changed (``ReflectionSystem``)."""
        kept = self.kept
        self.refilled = 0
        if kept is None or len(levels) < len(kept.targets) or any(
                levels[level] is not targets for level, targets in enumerate(kept.targets)) or \
                self.ends_state(levels[0].size) != kept.ends:
            self.kept = None
            return None
        if kept.prediction is not None:  # drawn on last frame's counts: were they its own?
            if claimed_pixels(self.passes, kept.prediction.queries) != kept.prediction.read:
                self.kept = None
                return None
            self.kept = kept = replace(kept, prediction=None)
        unsettled = kept.history is not None and not EndImages.settled(kept.history)
        if unsettled and kept.refill is None:
            self.kept = None
            return None
        stats = self.renderer.stats
        ledger = [getattr(stats, name) for name in LEDGER]
        if unsettled:
            self._refill(kept, levels, root or kept.result.views[0].view, root_options)
        else:
            if kept.refill is not None:  # settled: no frame refills it any more
                self.kept = replace(kept, refill=None)
                self.copies.release()
            if kept.fallbacks is not None:
                child, prepared = kept.fallbacks
                self.passes.draw_fallbacks(levels[0], child, prepared, parent_is_root=True)
            if kept.composite is not None:
                self.passes.composite_level(levels[0], levels[1], kept.composite, parent_is_root=True)
            self.scene_pass.finish_root(root or kept.result.views[0].view, levels[0], root_options)
            if kept.fallbacks is not None or kept.composite is not None:
                self.renderer.flush()
        # The render's counts (fallbacks too: those drawn now are of the render's, the rest kept).
        for name, before, spent in zip(LEDGER, ledger, kept.spent, strict=True):
            setattr(stats, name, before + spent)
        return kept.result

    def _refill(self, kept: KeptTree, levels: LevelStack, root: View, root_options: SceneOptions) -> None:
        """A kept still tree whose end images have not settled (``Refill``): what depends on
        them done again, level by level from the deepest with end views up, as the render's
        step 5 did it over each level put back as its views drew it; then the finished image
        kept and compared again, and the tree kept with that check."""
        refill, passes = kept.refill, self.passes
        for depth in range(refill.deepest, -1, -1):
            targets = levels[depth]
            if depth:
                if depth in refill.rects:  # (else every pixel the level's composites write is painted whole)
                    self.copies.restore(depth, targets, refill.rects[depth])
                filled = refill.ends.get(depth)
                if filled is not None:
                    self.ends.draw(*filled, targets, root)
            drawn = refill.fallbacks.get(depth)
            if drawn is not None:
                passes.draw_fallbacks(targets, *drawn, parent_is_root=depth == 0)
            if depth < len(refill.composites):
                passes.composite_level(targets, levels[depth + 1], refill.composites[depth], parent_is_root=depth == 0)
            if not depth:  # the screen's reflections, then the glass (none: nothing drawn)
                self.scene_pass.finish_root(root, targets, root_options)
            else:
                views, options, conditions = refill.transparent[depth]
                self.scene_pass.finish_level(depth, views, targets, options, conditions, refill.see_through)
        self.renderer.flush()
        ends_before = self.ends_state(levels[0].size)
        self.ends.keep(levels[0], root, refill.seen, compare=True)
        self.kept = replace(kept, history=self.ends.compared, ends=ends_before)
        self.refilled = sum(len(filled[0]) for filled in refill.ends.values())

    def save_for_refill(self, walk: TreeWalk, check_history: bool) -> Refill | None:
        """For a tree drawn on a still frame (``check_history``: ``ViewTree.check_history``) whose end views the settle
        check will compare: each level down to the deepest with end views copied as its views
        drew it, before its composites (``LevelCopies``), and what the frames that keep the
        tree until it settles do again (``Refill``).  None otherwise, and the copies are let
        go: a frame whose camera or scene moved copies nothing."""
        result, ends = walk.result, self.ends
        if not (check_history and ends is not None and result.end_views and walk.surfaces.has_end_images
                and drawn_on_counts(walk)) or not ends.compares(walk.root, seen_surfaces(result)):
            if len(self.copies):
                self.copies.release()
            return None
        deepest = max(node.level for node in result.end_views)
        see_through = self.scene_pass.slot_drawn()
        refracting = bool(self.scene_pass.renderer.refracting_batches())  # (drawn over the level's copy: refract)
        rects, transparent, filled = {}, {}, {}
        for level in range(1, deepest + 1):
            step = walk.steps[level - 1]
            # (a level's screen reflections and light shafts, as its glass, blend over what its pixels hold)
            shafts = self.scene_pass.volumetric_fog is not None and level <= self.scene_pass.volumetric_fog.reach
            if see_through or refracting or step.options.reflections or shafts or not painted_whole(walk, level):
                rects[level] = rect = bounds([view.scissor for view in (*step.views, *step.end_views)])
                self.copies.save(level, step.targets, rect)
            transparent[level] = (step.views, step.options, step.conditions)
            if step.ended:
                filled[level] = (step.end_views, [node.surface.entity for node in step.ended], step.end_matrices)
        self.copies.keep_only(rects)
        return Refill(deepest, rects, filled, transparent, seen_surfaces(result), see_through)


def prediction_of(walk: TreeWalk) -> Prediction:
    """The counts a predicted ``walk`` decided its views by, and their claims' queries now."""
    seen, queries, read = walk.record.seen, [], []
    for step in walk.steps:
        for row in (*step.keep, *step.small):
            queries.append(step.queries[row])
            read.append(seen.get(step.claim_keys[row]))
    return Prediction(queries, read)


def drawn_on_counts(walk: TreeWalk) -> bool:
    """Whether the views drawn may be the next frame's: exact, or predicted from last
    frame's counts (not a first or cut frame's, which has none), which the next frame checks
    (``Prediction``)."""
    return walk.exact or bool(walk.record.seen)


def painted_whole(walk: TreeWalk, level: int) -> bool:
    """Whether every pixel ``level``'s fallbacks and the composite of the level below write
    is written whole: a blend weight of exactly 1 (reflection x 1 + own x 0), so what the
    pixel held before does not matter (a refill need not put the level back, given no
    transparent slot and no screen reflections, which blend over what its pixels hold, and
    the end views' fill, which blends nothing).  That holds for a portal (mirror_composite.frag writes alpha 1)
    and for a mirror of reflect rate 1 (times a view's fade of 1), unfaded, not water
    (Fresnel), the weights ``shading_replaced`` trusts; a partly faded share is a quotient
    of floats.  (A pixel's own colour is finite: an infinite one times 0 is no number.)"""
    below = walk.steps[level] if level < len(walk.steps) else None
    if below is not None and below.composite is not None and any(
            node.fade != 1.0 or not weighs_one(node.surface) for node in below.composite):
        return False
    fallbacks = walk.fallbacks.get(level)
    if fallbacks:
        states = fallbacks.states
        if (fallbacks.share is not None and any(share != 1.0 for share in fallbacks.share)) or not all(
                weighs_one(states[row]) for row in set(fallbacks.surface)):
            return False
    return True


def weighs_one(state: SurfaceState) -> bool:
    """A surface whose composite and fallback blend at a weight of exactly 1 (``painted_whole``)."""
    return state.kind == "portal" or (state.reflect_rate == 1.0 and state.fade is None and state.water is None)


def bounds(rects: Sequence[tuple[int, int, int, int]]) -> tuple[int, int, int, int]:
    """The smallest rectangle (x, y, width, height) holding every one of ``rects``."""
    x0, y0 = min(x for x, _, _, _ in rects), min(y for _, y, _, _ in rects)
    return x0, y0, max(x + w for x, _, w, _ in rects) - x0, max(y + h for _, y, _, h in rects) - y0
