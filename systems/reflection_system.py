"""Mirrors and portals of the main view: the reflect stage of a frame.

Each frame, after the main view is drawn, this system has the view tree
(``engine/render/view_tree.py``) render and composite every level of the mirrors and
portals (the ``Surfaces`` resource, from the surfaces stage, as the planner's table:
``engine/render/surface_table.py``) below the main view, rooted at the main stage's
``FrameViews``.  Its
settings are the main tree's limits and path; ``RenderStats`` reports the views drawn,
dropped by the level budget and cut by the depth cap.

Still views are kept (dirty flags, as the probes keep faces no change reached: the design's
"dirty flags to skip static cubemaps"): when nothing the tree's views show changed since
its last render, its levels 1 and below keep the images they hold and only the root's part
is done again (``StillTree.keep``: the root's fallbacks, level 1's composite and the root's
transparent slot over it; the main stage draws level 0 anew every frame).  "Nothing changed" is one comparison
(``_still_key``): the renderer's ``scene_version`` (moved on by every upload or redraw of
what a scene pass, fallback or composite reads: instance rows and batches, lights, sky,
irradiance, shadow maps, probe cubes; ``Gpu.note_scene_change``), shader hot reloads, the
root's Camera block, this stage's settings, the budgets left, the water's waves, and the
planner's table, the surfaces' probes and the level targets as the same objects (each
remade when a surface, its fallback probes or a level's size changes); besides, no component
of the world was written, added or removed since the last render looked (``World.change_count``,
``World.last_step_changes``: a write the version missed still redraws).  A render that drew a
view on last frame's counts is not kept, nor one that drew an end view (it shows last
frame's image, which the render changes) until that image settles: a frame that saw no
change draws its tree and counts the pixels where its image differs from last frame's
(``EndImages.keep(compare=True)``); none, and the next frame keeps the tree.  Until then the
frames that see no change keep it too but do again what depends on the end images (the end
views filled from the new image, each level's composites over the copy of its views' pixels
the first still frame made: ``StillTree.keep``, ``engine/render/level_copies.py``), and count
again.  ``RenderStats.reflection_views_kept`` counts the views kept whole,
``reflection_end_refills`` the end views filled again over a kept tree; ``keep_still_views = False``
draws every frame.

A mirror or portal that moved since the last frame (``SurfaceMotion``, from the surfaces
stage) moves what its view shows on the picture; while temporal AA or motion blur follows
motion (``ObjectMotion.on``), each one's motion (last frame's carry inverted, times this
frame's) goes to the tree's composites (``MirrorPasses.surface_motion``), which add it to
the seen image's own motion over the view's pixels.
"""
from __future__ import annotations

import weakref
from dataclasses import replace

import esper
from pyglm import glm

from engine.core.errors import MirrorError  # raised by the surfaces stage; named here as before
from engine.core.world import World
from engine.render.frame_views import FrameViews
from engine.render.renderer import Renderer
from engine.render.surface_table import NO_BLENDS, SurfaceBlends, surface_table
from engine.render.targets import LevelStack
from engine.render.tree_walk import ReflectionView, TreeSettings
from engine.render.view_plan import SurfaceTable
from engine.render.view_tree import ViewTree
from engine.render.views import View
from engine.resources import PortalCrossings, RenderStats, SurfaceMotion, Surfaces
from engine.rules.frame_rules import frame_rules
from engine.rules.light_rules import ViewEyes

__all__ = ["MirrorError", "ReflectionSystem"]


class ReflectionSystem(esper.Processor):
    """Renders and composites mirror reflections after the main view, before present."""

    def __init__(self, world: World, renderer: Renderer, max_depth_cap: int = 8) -> None:
        self.world = world
        self.renderer = renderer
        self.tree = ViewTree(renderer, renderer.scene_pass, end_images=True, copies=renderer.level_copies)
        # (the levels the camera's AmbientOcclusion, ContactShadows and ScreenReflections reach)
        self.tree.occlusion = renderer.occlusion
        self.tree.reflections = renderer.screen_reflections
        self.settings = TreeSettings(max_depth_cap)
        self.views: list[ReflectionView] = []   # last frame's view tree, level order
        self._cut = False                        # camera_cut() was called since the last frame
        self._camera: int | None = None          # the camera last frame's tree was seen from
        self._keep_still_views = True
        self._watch_world = True
        self.tree.remember = True
        self._still: tuple[tuple, tuple] | None = None  # (values, objects) the tree was last drawn for
        self._changes_seen = -1  # World.change_count() when this stage last looked (-1: never)
        # the water flows of a table, which it names weakly (a table of hundreds of surfaces
        # holds tens of MB, and no render may come to replace it: every mirror deleted)
        self._waves: tuple[weakref.ref | None, list] = (None, [])

    # --- the main tree's settings, checked when they are set --------------------------------------
    @property
    def max_depth_cap(self) -> int:
        """Levels of mirrors and portals below the main view, whatever the surfaces' own
        ``max_depth`` (default 8, at most MAX_TREE_DEPTH = 16; each level is one more set of
        screen-sized targets).  Reaching it shows in ``RenderStats.reflection_depth_capped``."""
        return self.settings.depth_cap

    @max_depth_cap.setter
    def max_depth_cap(self, value: int) -> None:
        self.settings = replace(self.settings, depth_cap=value)

    @property
    def level_budget(self) -> int | None:
        """The most views a level draws, keeping those with the most pixels (None: every view
        with pixels).  Views left out show in ``RenderStats.reflection_views_dropped``."""
        return self.settings.level_budget

    @level_budget.setter
    def level_budget(self, value: int | None) -> None:
        self.settings = replace(self.settings, level_budget=value)

    @property
    def path(self) -> str:
        """How a level's views are drawn: "per_mirror" (each view its own draws), "batched"
        (one instanced draw per mesh for the whole level's views) or "auto" (chosen per level
        by view and triangle count; the rule and its numbers: batched_mirrors.choose_path)."""
        return self.settings.path

    @path.setter
    def path(self, value: str) -> None:
        self.settings = replace(self.settings, path=value)

    @property
    def visibility(self) -> str:
        """How each level learns which of its candidate views have pixels: "exact" (this
        frame's claim counts: the CPU waits for the GPU once a level), "predicted" (last
        frame's: nothing waits; a view hidden last frame is drawn but gets no views of its
        own surfaces until a frame counted it visible, so a mirror uncovered this frame shows
        the mirrors inside it a frame late) or "auto" (exact on a software rasteriser,
        predicted on a GPU).  A view or pixel budget always counts exactly."""
        return self.settings.visibility

    @visibility.setter
    def visibility(self, value: str) -> None:
        self.settings = replace(self.settings, visibility=value)

    @property
    def keep_still_views(self) -> bool:
        """Keep a still frame's reflection levels (the module docstring); False: the tree is
        drawn every frame."""
        return self._keep_still_views

    @keep_still_views.setter
    def keep_still_views(self, value: bool) -> None:
        self._keep_still_views = _flag("keep_still_views", value)

    @property
    def watch_world(self) -> bool:
        """Also redraw on any world change (written, added, removed) since the last look,
        which ``scene_version`` may not follow; False: the version and the key alone (tests
        check that they suffice for what reaches the GPU)."""
        return self._watch_world

    @watch_world.setter
    def watch_world(self, value: bool) -> None:
        self._watch_world = _flag("watch_world", value)

    def camera_cut(self) -> None:
        """Say the camera jumps this frame (a teleport, a cut to another shot): predicted
        visibility forgets last frame's counts, which describe another place (the first
        frame after draws every candidate, so no mirror inside a mirror appears a frame
        late).  Done by itself when the active camera changes or goes through a portal."""
        self._cut = True

    # --- schedule and render -----------------------------------------------------------------
    def process(self, dt: float) -> None:
        views = self.world.resources.get(FrameViews)
        surfaces: Surfaces = self.world.resources.get(Surfaces) or Surfaces({}, {})
        main = views.main if views is not None else None
        renderer = self.renderer
        self.tree.passes.surface_motion = self._surface_motion(surfaces)
        if main is None or views.levels is None:
            self.views = []
            self.world.resources.pop(ViewEyes, None)
            self._still = None
            self.tree.still.let_go()
            return
        if surfaces.mirrors or surfaces.portals:
            # The main view rasterises while the CPU culls and works out the first level's
            # cameras; the same after each level's views (engine/render/raw_gl.py says why).
            renderer.flush()
        else:  # no level to find or reflect: the screen passes' level images go (their surfaces went)
            renderer.occlusion.release_levels()
            renderer.screen_reflections.release_levels()
            renderer.volumetric_fog.release_levels()
        camera = frame_rules(self.world).active_camera
        crossed = any(crossing.entity == camera for crossing in self.world.resources.get(PortalCrossings, ()))
        cut = self._cut or crossed or camera != self._camera
        if cut:
            self.tree.visibility.forget()
        self._cut, self._camera = False, camera
        settings = self.settings
        # (a water seen by the side each view's eye is on: its top and underside both in the table)
        table = surface_table(self.world.resources, surfaces)
        blends = self.world.resources.get(SurfaceBlends, NO_BLENDS)
        stats: RenderStats = self.world.resources[RenderStats]
        world = self.world
        # Nothing written, added or removed in the world since this stage last looked: not
        # after it in the last frame, nor before it in this one.
        changes = world.change_count()
        unchanged = not self.watch_world or (changes == 0 and world.last_step_changes == self._changes_seen)
        self._changes_seen = changes
        # (no mirror or portal: nothing to keep, and the key is not worth making)
        still = self._still_key(main, views.levels, table, blends, stats) if table.states else None
        result = None
        # Nothing changed since the tree was last drawn (or kept): keep it if it settled;
        # else draw it, comparing its end images (if any) to know when it settles.
        same = self.keep_still_views and unchanged and not cut and still is not None and self._still is not None \
            and _same(still, self._still)
        if same and self.tree.still.kept is not None and self.tree.still.kept.settled:
            result = self.tree.still.keep(views.levels, main, views.options)
        kept = result is not None
        if not kept:
            self.tree.check_history = same
            result = self.tree.render(main, views.levels, table, settings, blends, views.options)
        self._still = still if self.keep_still_views else None
        refilled = self.tree.still.refilled if kept else 0
        stats.reflection_views_kept = len(result.views) - 1 if kept and not refilled else 0
        stats.reflection_end_refills = refilled
        self.views = result.views
        eyes = self.world.resources.get(ViewEyes)  # for next frame's lights: a kept tree's kept
        if eyes is None or eyes.views is not result.views or eyes.size != main.size:
            self.world.resources[ViewEyes] = ViewEyes(result.views, main.size)
        stats.reflection_views = len(result.views) - 1
        stats.reflection_views_dropped = result.dropped
        stats.reflection_depth_capped = result.capped
        stats.reflection_views_faded = result.faded
        stats.reflection_end_views = len(result.end_views)
        stats.reflection_visibility = result.visibility
        stats.reflection_views_unseen = sum(1 for view in result.views if view.unseen)
        paths = result.paths  # (a kept tree's: the paths it was drawn by)
        stats.reflection_path = next(iter(paths)) if len(paths) == 1 else ("mixed" if paths else "")

    def _surface_motion(self, surfaces: Surfaces) -> dict[int, glm.mat4]:
        """Each surface that moved since the last frame: the matrix taking where its view shows
        a point now to where it showed it then (empty unless motion is followed)."""
        motion = self.world.resources.get(SurfaceMotion)
        if motion is None or not motion.before or not self.renderer.object_motion.on:
            return {}
        moved = {}
        for entity, before in motion.before.items():
            state = surfaces.mirrors.get(entity) or surfaces.portals.get(entity)
            if state is not None:
                moved[entity] = glm.inverse(before) * state.carry
        return moved

    def _still_key(self, main: View, levels: LevelStack, table: SurfaceTable, blends: SurfaceBlends,
                   stats: RenderStats) -> tuple[tuple, tuple]:
        """What the tree's views show, as (values compared equal, objects compared as the same
        object): the module docstring's list.  Equal to the last render's: nothing changed."""
        renderer = self.renderer
        waves = self._waves
        if waves[0] is None or waves[0]() is not table:
            flows = [state.water.flow for state in table.states if state.water is not None]
            waves = self._waves = (weakref.ref(table), flows)
        values = (renderer.scene_version, renderer.drawing_settings(), main.camera_block(), main.name, main.mirrored,
                  main.scissor, self.settings, self.tree.unlit, stats.views_left(), stats.pixels_left(),
                  stats.min_view_pixels, tuple(flow.offset for flow in waves[1]),
                  tuple(self.tree.passes.surface_motion))
        return values, (table, blends.by_surface, levels)

    def prepare(self) -> None:
        """Make the main tree's claim and composite buffers now (``Engine.frame`` calls it
        when a level's batches get their programs) rather than when the first mirror comes
        into view."""
        self.tree.passes.prepare()

    def mirror_planes(self) -> dict[int, tuple[list[float], list[float]]]:
        """Each mirror's world plane as (point on it, unit normal towards its front)."""
        surfaces = self.world.resources.get(Surfaces)
        return surfaces.mirror_planes() if surfaces is not None else {}

    def close(self) -> None:
        self.tree.release()


def _same(key: tuple[tuple, tuple], other: tuple[tuple, tuple]) -> bool:
    """Two ``_still_key``s agree: values equal, objects the same."""
    return key[0] == other[0] and all(a is b for a, b in zip(key[1], other[1], strict=True))


def _flag(name: str, value: object) -> bool:
    """``value`` for the switch ``ReflectionSystem.<name>``, refused unless a bool."""
    if not isinstance(value, bool):
        raise TypeError(f"ReflectionSystem.{name} must be True or False, got {value!r}")
    return value
