"""The view tree: mirrors and portals seen from a root view, level by level.

A root is any view with its own targets: the main camera (``ReflectionSystem``), and a
cube-map probe's face that sees mirrors or portals (``engine/render/probes.py``; its tree draws
no end views).  From it, ``ViewTree.render`` runs the loop of planar reflections
and portals:

  1. plan   - for every view of level L and every mirror or portal at once, in arrays
              (``engine/render/view_plan.py``): skip it if disabled, too deep, facing away,
              behind the view's own mirror, outside the frustum or off the view's rectangle;
              for each pair kept, its camera and packed Camera block;
  2. claim  - each candidate takes, in level L+1's node image and depth mask, the pixels
              where level L shows it; a samples query counts them (MirrorPasses.prepare_level).
              With exact visibility the CPU reads the counts now and a candidate with none
              gets no view; with predicted visibility it reads them at the root's next
              render and draws every candidate now (but those known empty: claim_cull),
              growing views below only those that had pixels last frame (or were not
              claimed then) (``tree_visibility.py``);
  3. render - the level's views through the scene pass (``ScenePass.draw``): the parent's
              camera carried through the surface, oblique near plane (or clip distance
              close up), only its claimed pixels; view by view, or all in one draw per
              mesh, each instance drawn once a view (the batched path);
  4. repeat for surfaces seen in those views, up to the depth limits (exact: plan, claim,
              read, render, level after level, the levels below one whose candidates all
              grew last frame planned ahead; predicted: every level planned first, back
              to back, then claimed and rendered in one run);
  5. composite, deepest level first: blend each level's views into their surfaces' pixels
              one level up (one instanced draw per level and composite variant), after the
              level's fallbacks: a surface seen with no view of its own (cut by a budget,
              faded out, past the depth limits without an end image, a mirror switched off)
              shows the probe's or the sky's reflection at its reflect rate, tint and
              roughness (``MirrorPasses.draw_fallbacks``), as does the faded share of a partly
              faded mirror and an end view's pixel its image does not hold; then the
              level's transparent slot (``ScenePass.draw_transparent``; the root's too, at
              level 0), which its views were drawn without (``SceneOptions.transparent``):
              what is see-through blends over the reflections behind it, as over anything
              else behind it, before the level is composited into the one above.

Levels are the size of the root's targets (times the largest resolution_scale of their
surfaces), so memory is bounded by (levels x one root image), however many surfaces.
Limits, each a setting and each reported in ``RenderStats`` when reached: the depth cap
(``TreeSettings.depth_cap``, at most ``MAX_TREE_DEPTH``) and an optional view budget per
level (``TreeSettings.level_budget``: the views with the most claimed pixels are kept).

Ordering, for the CPU and the GPU to overlap: on llvmpipe a draw that samples a texture a
queued pass still writes waits for that pass, so each level costs the CPU two waits (the
claims read the level above, the counts read the claims) and the composites one each.
Work that needs no pixels (the next level's plan, this level's composite rows) is done
between a flush and the next wait.  A chain of levels of one view each (a facing pair) goes
on a lean path (``ViewTree.lean_levels``): what a level of one candidate is chosen by, with
no lists of a level of many; the nodes, claims and Camera blocks of the levels planned ahead
read out for all of them at once, their claims written to the GPU in one run; their
composite rows packed together in step 5, one after another (in a frame, CPU work done
between GL calls costs two to four times what it costs in a row, measured), and no flush
after a level whose next level is planned already (no CPU work there to overlap).

``ViewTree`` runs those steps in order; the pieces live beside it: what a render carries
from level to level (``engine/render/tree_walk.py``), which candidates have pixels and the
budgets (``tree_visibility.py``), the levels planned ahead (``plan_ahead.py``), a level's
views and nodes (``level_nodes.py``), end views (``end_views.py``).  A tree that
``remember``s (the main view's) is kept on frames whose views show nothing new, its levels
1 and below as they are (``StillTree``, ``engine/render/kept_tree.py``).
"""
from __future__ import annotations

import weakref
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from pyglm import glm

from engine.core.budget import screen_coverage
from engine.render.batched_mirrors import choose_path
from engine.render.claim_cull import empty_claims
from engine.render.end_images import EndImages
from engine.render.end_views import EndSurfaces, child_seers, end_seers, end_views, keep_end_images
from engine.render.gpu import Gpu
from engine.render.kept_tree import StillTree
from engine.render.level_copies import LevelCopies
from engine.render.level_nodes import level_nodes, parent_and_surface
from engine.render.mirror_passes import Claims, Fallbacks, MirrorPasses, PreparedComposites
from engine.render.plan_ahead import plan_ahead, plan_chain
from engine.render.plan_rows import Candidates, LevelRows
from engine.render.scene_options import REFLECTION_LEVEL, TREE_ROOT, SceneOptions
from engine.render.scene_pass import ScenePass
from engine.render.screen_occlusion import ScreenOcclusion
from engine.render.screen_reflections import ScreenReflectionPass
from engine.render.surface_table import NO_BLENDS, SurfaceBlends
from engine.render.targets import LevelStack
from engine.render.tree_visibility import (
    TreeVisibility,
    chosen_by_prediction,
    claimed_pixels,
    level_scale,
    waits_for_counts,
    within_budgets,
)
from engine.render.tree_walk import (
    MAX_TREE_DEPTH,
    ReflectionView,
    TreeLevel,
    TreeResult,
    TreeSettings,
    TreeWalk,
    ends_at,
    fallbacks_at,
)
from engine.render.unlit_mirrors import shading_replaced
from engine.render.view_plan import SurfaceTable, _mat, level_rects
from engine.render.views import View

_BATCHED = SceneOptions(clear=False, masked=True, sky=False, batched=True, reflection_filter=True, transparent=False)
# A level whose claims' rectangles overlap none of the others' (_claims_apart) draws unmasked:
# there its depth alone is the claim test.  The reset wrote the near plane (depth 0) over every
# claim's rectangle and each claim the far plane (1) where it took the pixel, so within a
# view's rectangle, which no other claim's reaches, a fragment passes the depth test ("<")
# only on its own view's claimed pixels, as the node image's test would let it through; the
# build without that test (ScenePrograms.program's MASKED) runs no fetch and no discard a pixel,
# and llvmpipe's depth test, before the shader, rejects the other pixels' fragments unshaded.
# A level drawn on its claims' conditions (predicted visibility) keeps the node test: its views
# are skipped by the GPU only where the claims' counts are in when they draw (GL_QUERY_NO_WAIT
# may draw anyway), and llvmpipe finishes the claims before a pass samples the node image they
# wrote (measured: without that read a hidden view's draws were made, tests/test_predicted_visibility.py).
_APART = {options: replace(options, masked=False) for options in (REFLECTION_LEVEL, _BATCHED)}
_DEFAULT_SETTINGS = TreeSettings()  # (frozen: one for every render given none)


class ViewTree:
    """Renders the reflection levels below a root view into a ``LevelStack`` and composites
    them back into the root's targets, drawing every view through ``scene_pass``.  With
    ``end_images`` (the main view's tree) a view the depth limits cut shows its surface's
    image from the previous frame (``EndImages``)."""

    def __init__(self, renderer: Gpu, scene_pass: ScenePass, end_images: bool = False,
                 copies: LevelCopies | None = None) -> None:
        self.renderer = renderer
        self.scene_pass = scene_pass
        self.passes = MirrorPasses(renderer, scene_pass.refraction_copy)
        self.ends = EndImages(renderer) if end_images else None
        self.coverage: dict[int, int] = {}  # level -> its views' claimed pixels last frame (screen pixels)
        self._projections: tuple[bytes, np.ndarray, np.ndarray] | None = None  # the last root's projection
        self._roots: dict[tuple, tuple[tuple, LevelRows]] = {}  # each root's camera and row (_root_rows)
        self._end_surfaces = EndSurfaces(self.ends)  # the surfaces that may get end views, kept
        self.visibility = TreeVisibility(renderer, self.passes)  # each root's claim counts, frame to frame
        self._software = renderer.caps.software  # a software rasteriser (the context's, read once)
        # Draw the mirrors this tree paints over entirely unlit (unlit_mirrors.shading_replaced);
        # False: every view shades them (the second path the tests compare against).
        self.unlit = True
        # (the table and pixel budget they were found for, the set: the same at every depth)
        self._unlit: tuple[tuple, frozenset[int]] = ((None, False), frozenset())
        self._level_options: dict[tuple, SceneOptions] = {}  # a level's options with its unlit mirrors
        # Plan the levels below a level ahead where the root's last render made every candidate
        # of theirs a view that grew (plan_ahead); False: each level after its parent's claims
        # (the second path the tests compare against).
        self.plan_ahead = True
        # Per root (as TreeVisibility.roots), per level, whether its last render's level made every
        # candidate a view that grew (its rows the parents of the next level).
        self._whole: dict[tuple[str, int], dict[int, bool]] = {}
        self._singles: dict[tuple[str, int], dict[int, int]] = {}  # per root as _whole: TreeWalk.singles
        # Plan a chain of one view a level ahead in one run (SurfaceTable.plan_chain); False:
        # level by level (the second path the tests compare against).
        self.plan_chains = True
        # Choose a level of one candidate on a lean path (_choose_one); False: through the
        # lists of a level of many (the second path the tests compare against).
        self.lean_levels = True
        # With ``remember`` (the main view's tree), what the last render left, for a frame
        # whose views show nothing new (``still``: ``StillTree.keep``).
        self.remember = False
        # The next render compares its finished image with the end images' history (the
        # reflect stage sets it where the frame's views show what the last frame's did).
        self.check_history = False
        # What it keeps for still frames, with the copies of its levels while its end images
        # settle (``copies``: where the renderer counts them, the main view's tree's; else the
        # tree's own).
        self.still = StillTree(renderer, self.passes, scene_pass, self.ends,
                               copies if copies is not None else LevelCopies(renderer.ctx))
        # The camera's screen-space ambient occlusion and contact shadows, found for each
        # level its components reach before the level is drawn, and its screen-space
        # reflections, which such a level's views draw for (the main view's tree; None:
        # levels drawn without).
        self.occlusion: ScreenOcclusion | None = None
        self.reflections: ScreenReflectionPass | None = None

    def render(self, root: View, levels: LevelStack, surfaces: SurfaceTable,
               settings: TreeSettings = _DEFAULT_SETTINGS, blends: SurfaceBlends = NO_BLENDS,
               root_options: SceneOptions = TREE_ROOT) -> TreeResult:
        """Draw every level below ``root`` (already drawn into ``levels[0]`` with
        ``root_options``, its transparent slot left to the tree) and composite them: the
        module's five steps, a level at a time, each level's transparent slot drawn once the
        level below is composited into it (the root's last).  A surface that gets no view
        shows the probes ``blends`` gives it (the extract stage's), else the sky."""
        if root_options.transparent:
            raise ValueError("ViewTree.render: the root must be drawn with SceneOptions(transparent=False): the "
                             "tree draws its transparent slot over the reflections composited into it")
        root_node = ReflectionView(0, 0, root, (0, 0, *root.size))
        result = TreeResult([root_node], set())
        self.still.kept = None
        if not surfaces.states:  # no mirror or portal anywhere: the root is the whole tree
            if self.ends is not None:
                self.ends.forget()
            if len(self.still.copies):  # (the pair whose levels were copied went mid-refill: let the copies go)
                self.still.copies.release()
            self.scene_pass.finish_root(root, levels[0], root_options)
            return result
        before = self.still.before(root.size) if self.remember else None  # (what a kept frame adds again)
        walk = self._start(root, root_node, surfaces, settings, result)
        walk.blends = blends.by_surface
        candidates = self._plan(walk, first_index=1)                  # 1. plan the first level
        while candidates is not None:
            step = self._choose(walk, levels, candidates)             # 2. claim (exact), 3. choose
            if step is None:
                break
            if walk.exact:
                self._draw_level(step, root, walk)                    # 4. draw, level by level
            candidates = self._descend(walk, step)                    # 1. plan the next level
        if not walk.exact:  # predicted: the whole tree, planned, claimed and drawn in one run (2, 4)
            for step in walk.steps:
                self._claim(surfaces, step)  # (a last level without views still counts its claims)
                if step.composite is not None:
                    self._draw_level(step, root, walk)
        self._note_cap(walk)
        refill = self.still.save_for_refill(walk, self.check_history) if before is not None else None
        self._composite(walk, levels, root_options)                   # 5. composite
        keep_end_images(self.ends, walk, levels, self.check_history)
        if before is not None:  # kept for a frame whose views show nothing new (StillTree.keep)
            self.still.remember(walk, levels, before, refill)
        return result

    def _start(self, root: View, root_node: ReflectionView, surfaces: SurfaceTable, settings: TreeSettings,
               result: TreeResult) -> TreeWalk:
        """A render's walk from its root: the root's projection and row, the end views it may
        have, how it learns its views' pixels."""
        root_proj, inv_root_proj = self._projection(root.proj)
        ends = self._end_surfaces.find(surfaces, root, settings.depth_cap)
        exact = waits_for_counts(settings.visibility, settings.level_budget, self.renderer.stats, self._software)
        result.visibility = "exact" if exact else "predicted"
        renderer = self.renderer
        walk = TreeWalk(root, surfaces, settings, result, root_proj, inv_root_proj, ends, exact,
                     self.visibility.of(root), renderer, [root_node],
                     self._root_rows(root),
                     # With end views: for each row of the level, the index in result.views of the
                     # view that saw each surface last up its chain (-1: none), what an end view repeats.
                     None if ends is None else [[-1] * len(surfaces.states)])
        key = (root.name, root.skip)
        walk.whole_before = self._whole.get(key) or walk.whole_before
        walk.singles_before = self._singles.get(key) or walk.singles_before
        if len(self._whole) > 64:
            self._whole.clear()
            self._singles.clear()
        self._whole[key] = walk.whole
        self._singles[key] = walk.singles
        return walk

    def _plan(self, walk: TreeWalk, first_index: int) -> Candidates | None:
        """Step 1: the candidates of the level below ``walk``'s parents (``SurfaceTable.plan``),
        and the fallbacks of the surfaces those parents see that get no view there."""
        depth = walk.level + 1
        settings, surfaces, root = walk.settings, walk.surfaces, walk.root
        walk.scale = level_scale(self.renderer.stats, self.coverage, depth)
        ahead = walk.ahead.pop(depth, None) if walk.ahead else None
        if ahead is None and len(walk.rows.data) == 1 and walk.whole_before.get(depth) \
                and self.plan_ahead and self.plan_chains and walk.rows.data.flags.writeable \
                and not surfaces.fading and self.renderer.stats.pixels_left() is None:
            # One parent (a moving root's row), and its level a chain last render: planned as
            # one from here, with the levels below it ahead (plan_ahead).
            chain = plan_chain(walk, depth - 1, walk.rows, first_index)
            if chain:
                plan_ahead(walk, depth - 1 + len(chain), chain[-1], self.coverage, self.plan_chains, chain)
                ahead = walk.ahead.pop(depth, None)
        unviewed = None
        if ahead is not None and ahead[0] is walk.rows.data and ahead[1] == first_index and ahead[2] == walk.scale:
            (candidates, faded), unviewed = ahead[3], ahead[4]
        else:
            candidates, faded = surfaces.plan(walk.rows, depth, root, walk.root_proj, walk.inv_root_proj,
                                              first_index, settings.depth_cap, root.hide,
                                              ends=ends_at(walk.ends, depth), scale=walk.scale, lazy=True)
            if candidates is not None and walk.whole_before.get(depth) and self.plan_ahead \
                    and not surfaces.fading and self.renderer.stats.pixels_left() is None:
                plan_ahead(walk, depth, candidates, self.coverage, self.plan_chains)
        if unviewed is None:
            self._unviewed(walk.fallbacks, surfaces, walk.rows, walk.nodes, walk.level, walk.root_proj, root,
                           settings.depth_cap, walk.ends)
        elif len(unviewed[0]):  # (found with the level, planned ahead)
            fallbacks_at(walk.fallbacks, walk.level, surfaces).add(walk.nodes, *unviewed)
        walk.result.faded += faded
        walk.singles[depth] = parent_and_surface(candidates)[1] if candidates is not None and len(candidates) == 1 \
            else -1
        candidates, walk.end_seers, dropped = end_seers(candidates, walk.seers)
        if dropped:  # end candidates with nothing to repeat: their fallback, never the bare surface
            fallbacks_at(walk.fallbacks, walk.level, surfaces).add(walk.nodes, [p for p, _ in dropped],
                                                                    [s for _, s in dropped])
        return candidates

    def _choose(self, walk: TreeWalk, levels: LevelStack, candidates: Candidates) -> TreeLevel | None:
        """Steps 2 and 3 for a planned level: its candidates' claims (exact: drawn and read
        now; predicted: last frame's counts), which become views, which of those grow views
        below, its end views and fallbacks, and its drawing path; None where it has no view
        (the tree ends there)."""
        surfaces, settings, result, root = walk.surfaces, walk.settings, walk.result, walk.root
        if len(candidates) == 1 and self.lean_levels and settings.level_budget is None:
            stats = self.renderer.stats
            if stats.view_budget is None and stats.pixels_left() is None and stats.min_view_pixels is None:
                return self._choose_one(walk, levels, candidates)
        level = walk.level
        if walk.scale < 1.0:
            self.renderer.stats.levels_downscaled += 1
        step = TreeLevel(candidates, levels.get(level + 1, candidates.size), levels[level], walk.nodes,
                      walk.record.take(len(candidates), self.renderer.ctx), depth=level + 1)
        walk.steps.append(step)
        self._skip_empty_claims(walk, step)
        is_end = candidates.end.tolist() if candidates.end is not None else [False] * len(candidates)
        if walk.exact:  # this frame's counts: the CPU waits for the GPU to draw the claims
            step.keep, step.grow, end_rows = self._chosen_by_counts(surfaces, step, is_end, settings, result,
                                                                    level + 1, root.size)
        else:  # last frame's counts: nothing waits; the GPU counts this frame's for the next
            step.keep, step.grow, end_rows, step.claim_keys, step.conditions, step.small = chosen_by_prediction(
                candidates, step.queries, self.passes.no_pixels, is_end, walk.keys, walk.record,
                surfaces.entity_list, self.renderer.stats, self.coverage, level + 1, root.size)
        keep, grow = step.keep, step.grow
        chosen = step.chosen = candidates if len(keep) == len(candidates) else \
            candidates.select(np.asarray(keep, np.int64))
        step.views, step.children = level_nodes(surfaces, chosen, walk.nodes, level + 1, root.hide)
        children = step.children
        if len(grow) < len(children):
            grown = set(grow)
            for at, child in enumerate(children):
                child.unseen = at not in grown
            # A view drawn unseen gets no views of its surfaces this frame: should it show
            # now, they show their fallback (every surface it sees, as if past every limit).
            unseen = [at for at in range(len(children)) if at not in grown]
            self._unviewed(walk.fallbacks, surfaces, chosen.select(np.asarray(unseen, np.int64)).rows,
                           [children[at] for at in unseen], level + 1, walk.root_proj, root, 0, None)
        self._fallbacks_of_level(walk.fallbacks, surfaces, step, keep, is_end, children, level, walk.exact)
        if end_rows:
            end_views(walk, step, end_rows)
        if not children and not step.ended:
            return None
        if children:
            step.path = choose_path(settings.path, len(children), walk.triangles, self._software)
            step.unlit = self._unlit_mirrors(surfaces)
        step.composite = children + step.ended
        return step

    def _choose_one(self, walk: TreeWalk, levels: LevelStack, candidates: Candidates) -> TreeLevel | None:
        """``_choose`` for a level of one candidate with no budget (a chain's levels): the
        same steps and the same level, without the lists a level of many views is chosen
        through (its node straight from what its planning kept, the path and the unlit
        mirrors found once a render: the same for every level of one view).  Exact
        visibility reads its claim's count now; predicted visibility takes last frame's, as
        ``chosen_by_prediction`` does for a level of many (a view unless its claim is known
        empty or it is an end view; it grows unless hidden last frame).  At portal depth 8
        with a swaying camera, 32x18, ``lean_levels`` in all (this path, the lean descent
        and plan, the claims' and Camera blocks' runs, the composite rows in step 5) takes
        about 11% off the frame in exact visibility (measured: one process, frames
        alternating)."""
        renderer = self.renderer
        stats = renderer.stats
        level = walk.level
        if walk.scale < 1.0:
            stats.levels_downscaled += 1
        step = TreeLevel(candidates, levels.get(level + 1, candidates.size), levels[level], walk.nodes,
                      walk.record.take(1, renderer.ctx), depth=level + 1)
        walk.steps.append(step)
        self._skip_empty_claims(walk, step)
        end = candidates.end is not None and bool(candidates.end[0])
        surfaces = walk.surfaces
        query = step.queries[0]
        claimed = query is not self.passes.no_pixels
        if walk.exact:  # this frame's count: the CPU waits for the GPU to draw the claim
            self._claim(surfaces, step)
            pixels = query.samples if claimed else 0
            step.pixels = [pixels]
            drawn = 0 if end else pixels
            viewed, grows = drawn > 0, True
        else:  # last frame's count; the GPU counts this frame's for the next (chosen_by_prediction)
            one = candidates.derived.get("one") or parent_and_surface(candidates)
            key = walk.keys[one[0]] + (surfaces.entity_list[one[1]],)
            record = walk.record
            record.pending.append(key)
            record.counted.append(query)
            step.claim_keys = [key]
            seen = record.seen.get(key)
            viewed = claimed and not end
            pixels = (seen or 0) if claimed else 0
            drawn = pixels if viewed else 0
            grows = seen != 0
            step.conditions = [query] if viewed else []
        root = walk.root
        self.coverage[level + 1] = screen_coverage(drawn, candidates.size, root.size)
        if viewed:
            stats.views_spent += 1
            stats.pixels_spent += drawn
            step.keep, step.grow, step.chosen = [0], range(1) if grows else range(0), candidates
            kept = candidates.derived.get(("nodes", root.hide))  # (planned ahead: ahead_columns)
            if kept is not None:
                (view,), ((node, rect, state, p, fade),) = kept
                step.views, children = kept[0], [ReflectionView(node, level + 1, view, rect, state, walk.nodes[p],
                                                                fade)]
            else:
                step.views, children = level_nodes(surfaces, candidates, walk.nodes, level + 1, root.hide)
            step.children = children
            if not grows:  # predicted: drawn, hidden last frame; its surfaces wait for a count (as _choose)
                children[0].unseen = True
                self._unviewed(walk.fallbacks, surfaces, candidates.rows, children, level + 1, walk.root_proj, root,
                               0, None)
            if children[0].fade < 1.0:  # its faded share shows the fallback
                fallbacks_at(walk.fallbacks, level, surfaces).add(step.parents, candidates.parent, candidates.surface,
                                                                   1.0 - candidates.fade)
            if walk.one is None:  # the path and unlit mirrors of a level of one view: the same at every depth
                walk.one = (choose_path(walk.settings.path, 1, walk.triangles, self._software),
                            self._unlit_mirrors(surfaces))
            step.path, step.unlit = walk.one
            step.composite = children
            return step
        step.keep, step.grow, step.chosen = [], range(0), candidates.select(_NO_ROWS)
        if not (end and (pixels if walk.exact else claimed)):
            return None
        end_views(walk, step, [0])
        step.composite = list(step.ended)
        return step

    def _unlit_mirrors(self, surfaces: SurfaceTable) -> frozenset[int]:
        """The mirrors the views of a level draw unlit, those this tree paints over entirely
        at any depth (``shading_replaced``), kept while the table and whether a pixel budget
        applies stand."""
        if not self.unlit:
            return frozenset()
        pixel_budget = self.renderer.stats.pixels_left() is not None
        kept, found = self._unlit
        if kept[0] is None or kept[0]() is not surfaces or kept[1] != pixel_budget:
            found = shading_replaced(surfaces.states, pixel_budget)
            self._unlit = ((weakref.ref(surfaces), pixel_budget), found)
            self._level_options.clear()
        return found

    def _skip_empty_claims(self, walk: TreeWalk, step: TreeLevel) -> None:
        """The claims of ``step`` that cannot take a pixel (``claim_cull``: no pixel centre in
        the bounding boxes of its surface and its parents' up the chain) count 0 without a
        draw: their queries become ``MirrorPasses.no_pixels``, and in either visibility they
        get no view (no claim or reset, no draw, no views below).  The boxes are in the root's
        pixels: a level at another resolution than the root's, or below one, is not tested
        and breaks the chain."""
        candidates = step.candidates
        box = candidates.__dict__.get("box")  # the plan's (SurfaceTable._plan), or end_seers'
        if box is None or candidates.size != walk.root.size or step.parent_targets.size != walk.root.size:
            walk.chain = None
            return
        empty, walk.chain = empty_claims(walk.surfaces, box, candidates.surface, walk.rows.data, candidates.parent,
                                         walk.chain, candidates.rows.node)
        if empty is not None:
            none = self.passes.no_pixels
            step.queries = [none if skip else query for query, skip in zip(step.queries, empty, strict=True)]

    def _descend(self, walk: TreeWalk, step: TreeLevel) -> Candidates | None:
        """A chosen level's views join the tree, and those that grow become the parents of
        the next level, planned now (step 1): exact, while the GPU draws this level's views
        (measured: on the critical path when done after the views finish); predicted, every
        level before any is drawn, the planner's array work back to back (in a frame, numpy
        calls between GL calls cost 2-3 times what they cost in a row), and the GPU gets the
        tree in one run.  None where no view grows."""
        result, grow, children = walk.result, step.grow, step.children
        child_offset = len(result.views)
        result.views.extend(children)
        walk.level += 1
        if not grow:
            return None
        if step.chosen is step.candidates and len(children) == 1 and self.lean_levels:
            # A level of one candidate that became a view (a chain's): the same, for one row.
            walk.whole[walk.level] = True
            if not walk.exact:
                walk.keys = step.claim_keys
            if walk.seers is not None:
                p, s = parent_and_surface(step.candidates)
                row = walk.seers[p].copy()
                row[s] = walk.parent_at[p]
                walk.seers = [row]
            walk.parent_at = [child_offset]
            walk.nodes, walk.rows = children, step.candidates.rows
            return self._plan(walk, first_index=children[0].index + 1)
        chosen = step.chosen
        parents = chosen if len(grow) == len(children) else chosen.select(np.asarray(grow, np.int64))
        walk.whole[walk.level] = parents is step.candidates  # the next level planned from its candidates' rows
        if walk.seers is not None:  # each child saw its own surface from its parent
            walk.seers = child_seers(walk.seers, parents, walk.parent_at)
        if not walk.exact:
            walk.keys = [step.claim_keys[step.keep[at]] for at in grow]
        walk.parent_at = [child_offset + at for at in grow]
        walk.nodes, walk.rows = [children[at] for at in grow], parents.rows
        return self._plan(walk, first_index=int(step.candidates.rows.node[-1]) + 1)

    def _note_cap(self, walk: TreeWalk) -> None:
        """Reaching the depth cap is reported: how many views the surfaces' own limits still
        allowed below it (counted when asked: ``TreeResult.capped``)."""
        deepest = max((node.level for node in walk.result.views), default=0)
        if deepest and deepest == walk.settings.depth_cap:
            surfaces, rows, root_proj, size = walk.surfaces, walk.rows, walk.root_proj, walk.root.size
            walk.result.count_capped = lambda: len(surfaces.cull(rows, deepest + 1, root_proj, size,
                                                                 MAX_TREE_DEPTH)[0])

    def _composite(self, walk: TreeWalk, levels: LevelStack, root_options: SceneOptions) -> None:
        """Step 5, deepest level first: a level's fallbacks, then the views of the level
        below composited over it (a partly faded view's over its fallback), then the level's
        own transparent slot over both (its views', the root's at level 0: they were drawn
        without it), before the level is composited into the one above.  First the rows of
        the levels of one view, which ``_draw_level`` left: packed one after another, not
        each between GL calls (a chain at portal depth 8, 32x18: with the flushes that had
        no CPU work to overlap left out, about 2% of the frame)."""
        steps, fallbacks = walk.steps, walk.fallbacks
        for step in steps:
            if step.prepared is None and step.composite is not None:
                step.prepared = self._prepare_composite(step.composite, walk.root, step.parent_targets.size)
        composites = walk.composited = [step.prepared for step in steps if step.prepared is not None][:walk.level]
        see_through = self.scene_pass.slot_drawn()  # else no level has a slot to draw
        for depth in range(walk.level, -1, -1):
            if fallbacks.get(depth):
                child = steps[depth].targets if depth < len(steps) else None
                prepared = self.passes.prepare_fallbacks(fallbacks[depth], levels[depth].size, walk.blends)
                self.passes.draw_fallbacks(levels[depth], child, prepared, parent_is_root=depth == 0)
                walk.drawn_fallbacks[depth] = (child, prepared)
            if depth < walk.level:
                self.passes.composite_level(levels[depth], levels[depth + 1], composites[depth],
                                            parent_is_root=depth == 0)
            if not depth:  # the screen's reflections, then the glass (none: nothing drawn)
                self.scene_pass.finish_root(walk.root, levels[0], root_options)
            else:
                step = steps[depth - 1]
                self.scene_pass.finish_level(depth, step.views, step.targets, step.options, step.conditions,
                                             see_through)
        if walk.level:
            self.renderer.flush()  # the composites, level after level, to the GPU at once

    def _chosen_by_counts(self, surfaces: SurfaceTable, step: TreeLevel, is_end: list[bool], settings: TreeSettings,
                          result: TreeResult, level: int,
                          screen: tuple[int, int]) -> tuple[list[int] | np.ndarray, range, list[int]]:
        """Exact visibility: a level's candidates claimed and their counts read now (the CPU
        waits for the GPU), and which become views (those with pixels that the budgets
        keep), which of those get views below them (all), and which end views have pixels;
        each a list of rows of ``step.candidates``."""
        self._claim(surfaces, step)
        pixels = step.pixels = claimed_pixels(self.passes, step.queries)
        keep, dropped = within_budgets(surfaces, step.candidates,
                                       [0 if end else n for n, end in zip(pixels, is_end, strict=True)],
                                       settings.level_budget, self.renderer.stats, self.coverage, level, screen)
        result.dropped += dropped
        end_rows = [i for i, (n, end) in enumerate(zip(pixels, is_end, strict=True)) if end and n > 0]
        return keep, range(len(keep)), end_rows  # every view kept has pixels: each gets its own surfaces

    @staticmethod
    def _unviewed(fallbacks: dict[int, Fallbacks], surfaces: SurfaceTable, rows: LevelRows,
                  nodes: list[ReflectionView], level: int, root_proj: np.ndarray, root: View, depth_cap: int,
                  ends: tuple[np.ndarray, int] | None) -> None:
        """The fallbacks of the surfaces the views ``nodes`` (``rows``, of ``level``) see but
        that the next level plans no view for (``SurfaceTable.unviewed``: past their depth
        limits, switched off, faded out; a ``depth_cap`` of 0: all of them), as the planner's
        columns: its parent rows are rows of ``nodes`` (a level planned ahead found them with
        it: ``_plan`` adds those)."""
        p, s = surfaces.unviewed(rows, level + 1, root_proj, root.size, depth_cap, ends_at(ends, level + 1))
        if len(p):
            fallbacks_at(fallbacks, level, surfaces).add(nodes, p, s)

    @staticmethod
    def _fallbacks_of_level(fallbacks: dict[int, Fallbacks], surfaces: SurfaceTable, step: TreeLevel,
                            keep: list[int] | np.ndarray, is_end: list[bool], children: list[ReflectionView],
                            level: int, exact: bool) -> None:
        """The fallbacks of a level's candidates: the views kept partly faded (the faded
        share) and those with pixels the budgets cut or found too small (their whole
        reflection), as rows of its candidates (whose parents are ``step.parents``)."""
        faded = [at for at, child in enumerate(children) if child.fade < 1.0]
        if faded:
            chosen, rows = step.chosen, np.asarray(faded, np.int64)
            fallbacks_at(fallbacks, level, surfaces).add(step.parents, chosen.parent.take(rows),
                                                          chosen.surface.take(rows), 1.0 - chosen.fade.take(rows))
        cut = None
        if exact and step.pixels is not None and len(keep) < sum(1 for n in step.pixels if n):
            kept = set(np.asarray(keep).tolist())
            cut = np.array([i for i, (n, end) in enumerate(zip(step.pixels, is_end, strict=True))
                            if n and not end and i not in kept], np.int64)
        elif step.small:  # predicted: those last frame counted under the smallest view worth one
            cut = np.asarray(step.small, np.int64)
        if cut is not None and len(cut):
            candidates = step.candidates
            fallbacks_at(fallbacks, level, surfaces).add(step.parents, candidates.parent.take(cut),
                                                          candidates.surface.take(cut))

    def _root_rows(self, root: View) -> LevelRows:
        """``LevelRows.root(root)``, kept per root (its name and skip: the main camera, each
        probe's faces) while its camera stands still from one render to the next (a probe
        face's every frame): the same read-only row, so the plans kept for it are found again
        (``SurfaceTable.plan``).  A camera that moved since the root's last render gets a
        writeable copy, for which nothing is kept, even where it stood a few renders ago: a
        camera going round a loop (a swaying camera, 60 places a second) came back to each
        place past more plans than are kept (``PLANS_KEPT``), so every plan was made again,
        and a kept row's levels are planned one by one, never as a chain (``plan_chain``):
        the portal pair at depth 8 under the cpu suite's swaying camera, once its sway came
        round, now takes 0.77 of the frame it took (interleaved, ``benchmarks ab``)."""
        key = (root.view.to_bytes(), root.proj.to_bytes(), tuple(root.eye), root.size, tuple(root.clip_plane),
               root.view_mask, root.mirrored)
        who = (root.name, root.skip)
        last = self._roots.get(who)
        if last is not None and last[0] == key:
            return last[1]
        if len(self._roots) >= 64:
            self._roots.clear()
        rows = LevelRows.root(root)
        rows.data.flags.writeable = False
        self._roots[who] = (key, rows)
        return LevelRows(rows.data.copy())

    def _projection(self, proj: glm.mat4) -> tuple[np.ndarray, np.ndarray]:
        """A root's projection and its inverse as numpy rows, kept while it is the same (a
        camera's from frame to frame, a probe's six faces)."""
        key = proj.to_bytes()
        if self._projections is None or self._projections[0] != key:
            self._projections = (key, _mat(proj), _mat(glm.inverse(proj)))
            for kept in self._projections[1:]:  # read-only: the planner knows them again by identity
                kept.flags.writeable = False
        return self._projections[1], self._projections[2]

    def _claim(self, surfaces: SurfaceTable, step: TreeLevel) -> None:
        """Every candidate's claim in the level's targets, its pixels counted in its query.
        The claim shader's (parent view, surface, view index) of every candidate: a level's
        few claims, so lists (a few numpy calls cost more), kept with a kept plan.  The claims
        known empty (claim_cull) are left out: they get no view in either visibility, so
        nothing reads their rectangles (no claim, no reset)."""
        candidates, parents = step.candidates, step.parents
        kept = not candidates.rows.data.flags.writeable
        columns = candidates.derived.get("claims")  # a kept plan's, or one planned ahead (ahead_columns)
        if columns is None:  # each candidate's parent row, surface entity and node, and its scissor
            entities = surfaces.entity_list
            columns = (candidates.parent.tolist(), [entities[s] for s in candidates.surface.tolist()],
                       candidates.rows.node.astype(np.int64).tolist(), candidates.scissor.tolist())
            if kept:  # a kept plan's: the same columns every frame it is found again
                candidates.derived["claims"] = columns
        rows, entities, nodes, scissors = columns
        queries, none = step.queries, self.passes.no_pixels
        run = candidates.derived.get("claim_run") if self.lean_levels else None  # (planned ahead: ahead_columns)
        if len(queries) == 1 and queries[0] is not none:  # (a chain's level: one claim, apart from any other)
            step.apart = True
            claims = Claims([(parents[rows[0]].index, entities[0], nodes[0])], scissors)
            if run is None:
                self.passes.prepare_level(step.targets, step.parent_targets, claims, queries)
            else:
                self.passes.prepare_level(step.targets, step.parent_targets, claims, queries, run)
            return
        if none in queries:  # the claims drawn, in one pass over the columns
            ids, rects, drawn = [], [], []
            for p, entity, node, rect, query in zip(rows, entities, nodes, scissors, queries, strict=True):
                if query is not none:
                    ids.append((parents[p].index, entity, node))
                    rects.append(rect)
                    drawn.append(query)
            claims, scissors, queries = Claims(ids, rects), rects, drawn
        else:
            claims = Claims([(parents[p].index, entity, node) for p, entity, node in
                             zip(rows, entities, nodes, strict=True)], scissors)
        step.apart = _claims_apart(scissors)
        if run is None or len(claims) < len(candidates):
            self.passes.prepare_level(step.targets, step.parent_targets, claims, queries)
        else:
            self.passes.prepare_level(step.targets, step.parent_targets, claims, queries, run)

    def _draw_level(self, step: TreeLevel, root: View, walk: TreeWalk) -> None:
        """A planned level's views (and end views) into its targets, then its composite's
        rows (CPU work while the GPU draws).  The levels of one render are one scene-pass
        run (``ScenePass.draw``: the pass-wide bindings once, while nothing rebinds them).
        A level of one view (``lean_levels``) leaves its row to step 5 (``_composite``), and
        is flushed only where the next level's plan is still to be made."""
        renderer = self.renderer
        if step.views:
            # Its ambient occlusion and contact shadows first, where the camera's reach it, and
            # its screen reflections' images: its views then read and write them, drawn one by
            # one (the batched builds do not).
            occluded = self.occlusion is not None and \
                self.occlusion.draw_level(step.depth, step.views, step.targets) is not None
            reflecting = self.reflections is not None and self.reflections.begin_level(step.depth, step.targets)
            options = _BATCHED if step.path == "batched" and not (occluded or reflecting) else REFLECTION_LEVEL
            walk.result.paths.add("batched" if options.batched else "per_mirror")  # (as drawn: the stats say it)
            if step.apart and step.conditions is None:  # depth alone tells the claimed pixels (_APART)
                options = _APART[options]
            if step.unlit or occluded or reflecting:
                key = (options, step.unlit, occluded, reflecting)
                options = self._level_options.get(key) or self._level_options.setdefault(
                    key, replace(options, unlit=step.unlit, occlusion=occluded, reflections=reflecting))
            step.options = options  # its transparent slot is drawn with them (_composite)
            derived = step.candidates.derived
            run = derived.get("view_run") if self.lean_levels else None
            if run is not None and step.views is derived[("nodes", walk.root.hide)][0]:  # (the views planned)
                renderer.upload_run(run)  # every level of one view's Camera block, at the first
            self.scene_pass.draw(step.views, step.targets, options, step.conditions, run=walk)
            if occluded:
                self.occlusion.restore_root()
            if reflecting:
                self.reflections.end_level()
        if step.ended:
            self.ends.draw(step.end_views, [node.surface.entity for node in step.ended], step.end_matrices,
                           step.targets, root)
        if len(step.composite) > 1 or not self.lean_levels:
            renderer.flush()
            step.prepared = self._prepare_composite(step.composite, root, step.parent_targets.size)
        elif not walk.exact or walk.level + 2 not in walk.ahead:  # (walk.level: the level above this one)
            renderer.flush()  # the next level's plan is CPU work to overlap (planned ahead, it is done)

    def _prepare_composite(self, children: list[ReflectionView], root: View,
                           parent_size: tuple[int, int]) -> PreparedComposites:
        """The composite of a level's views into the level above (``parent_size`` pixels: a
        view's rectangle as it is when that is the screen's size)."""
        if parent_size == root.size:
            rects = [child.rect for child in children]
        else:
            rects = list(map(tuple, level_rects(np.array([(x, y, x + w, y + h) for x, y, w, h in
                                                          (c.rect for c in children)], np.float64),
                                                root.size, parent_size).tolist()))
        return self.passes.prepare_views(children, rects, parent_size)

    def release(self) -> None:
        self.visibility.release()
        self.passes.release()
        if self.ends is not None:
            self.ends.release()
        self.still.copies.release()


_NO_ROWS = np.zeros(0, np.int64)


def _claims_apart(rects: Sequence[Sequence[int]]) -> bool:
    """Whether no two of a level's claim rectangles (x, y, width, height) share a pixel:
    a sweep along x over them sorted (a level's few claims; it stops at the first overlap).
    An empty rectangle covers no pixel."""
    if len(rects) < 2:  # (a chain's levels: one claim each)
        return True
    ordered = sorted(rect for rect in rects if rect[2] > 0 and rect[3] > 0)
    count = len(ordered)
    for i in range(count):
        x, y, w, h = ordered[i]
        right, top = x + w, y + h
        for j in range(i + 1, count):
            other_x, other_y, _, other_h = ordered[j]
            if other_x >= right:
                break
            if other_y < top and y < other_y + other_h:
                return False
    return True
