"""What one render of a view tree carries from level to level (``ViewTree.render``).

``TreeSettings`` are a tree's limits and drawing path, ``TreeResult`` what a render drew and
what its limits cut, ``ReflectionView`` one node of the tree.  On its way down a render is a
``TreeWalk``: the root and its settings, and what each level hands the next (its parents as
nodes and rows, their chains of surfaces, the seers of end views); each level it plans and
chooses is a ``TreeLevel``, which its GL half (claims, draws, composite) reads.  Plain data,
apart from the small helpers every step uses (a level's fallbacks, the end-image surfaces
planned at a depth, the surfaces an image shows): the steps live in ``view_tree.py``
(planning ahead: ``plan_ahead.py``; nodes: ``level_nodes.py``; end views: ``end_views.py``;
visibility and budgets: ``tree_visibility.py``; still frames: ``kept_tree.py``), which keeps
them apart from the order the levels run in.
"""
from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import moderngl
import numpy as np
from pyglm import glm

from components.limits import MAX_VIEW_DEPTH
from engine.render.batched_mirrors import PATHS, submitted_triangles
from engine.render.claim_cull import ChainBoxes
from engine.render.gpu import Gpu
from engine.render.mirror_passes import Fallbacks, PreparedComposites, PreparedFallbacks
from engine.render.plan_rows import Candidates, LevelRows
from engine.render.scene_options import REFLECTION_LEVEL, SceneOptions
from engine.render.targets import RenderTargets
from engine.render.tree_visibility import VISIBILITY_MODES, RootVisibility
from engine.render.view_plan import SurfaceTable
from engine.render.views import PlannedView, View
from engine.resources import SurfaceState
from engine.rules.probe_rules import ProbeBlend

# The deepest a tree may go (each level is one more set of root-sized targets); the depth
# limits of Mirror and Portal components take values up to this.
MAX_TREE_DEPTH = MAX_VIEW_DEPTH  # the depth cap's limit: the components' own


@dataclass(frozen=True)
class TreeSettings:
    """The limits and the drawing path of one view tree."""

    depth_cap: int = 8                 # levels below the root, whatever the surfaces' own limits
    level_budget: int | None = None    # most views a level draws (None: every view with pixels)
    path: str = "auto"                 # "per_mirror", "batched" or "auto" (batched_mirrors.choose_path)
    visibility: str = "auto"           # "exact", "predicted" or "auto" (VISIBILITY_MODES, ViewTree says how)

    def __post_init__(self) -> None:
        if not isinstance(self.depth_cap, int) or isinstance(self.depth_cap, bool) \
                or not 0 <= self.depth_cap <= MAX_TREE_DEPTH:
            raise ValueError(f"view tree depth_cap must be an int in [0, {MAX_TREE_DEPTH}], got {self.depth_cap!r}")
        if self.level_budget is not None and (not isinstance(self.level_budget, int) or self.level_budget < 1):
            raise ValueError(f"view tree level_budget must be None or an int >= 1, got {self.level_budget!r}")
        if self.path not in PATHS:
            raise ValueError(f"view tree path must be one of {PATHS}, got {self.path!r}")
        if self.visibility not in VISIBILITY_MODES:
            raise ValueError(f"view tree visibility (ReflectionSystem.visibility, TreeSettings.visibility) must be "
                             f"one of {VISIBILITY_MODES}, got {self.visibility!r}")


@dataclass
class TreeResult:
    """What one render of a tree drew, and what its limits cut."""

    views: list[ReflectionView]   # the root first, then level by level
    paths: set[str]               # how the levels were drawn
    dropped: int = 0              # views with pixels left out by the level budget
    faded: int = 0                # views the mirrors' fades took out (each costs nothing)
    end_views: list[ReflectionView] = field(default_factory=list)  # views past the depth limits shown
                                                                   # as last frame's image (EndImages)
    visibility: str = ""          # "exact" or "predicted": how the levels knew their views' pixels
    count_capped: Callable[[], int] | None = field(default=None, repr=False)  # counts ``capped`` (the
                                                                               # cap was reached)

    @functools.cached_property
    def capped(self) -> int:
        """Views the surfaces' own limits allowed below the depth cap (0: the cap was not
        reached), counted when first asked: one more cull, which the main view's tree
        reports (``RenderStats.reflection_depth_capped``) and a probe face's never needs."""
        return self.count_capped() if self.count_capped is not None else 0


@dataclass
class ReflectionView:
    """One node of the view tree: a view at some level, looking into one mirror or portal."""

    index: int
    level: int
    view: View
    rect: tuple[int, int, int, int]   # where it shows, in screen (level 0) pixels
    surface: SurfaceState | None = None
    parent: ReflectionView | None = None
    fade: float = 1.0                 # the reflection's weight (a mirror's fades)
    unseen: bool = False              # drawn on last frame's word that it had no pixels (predicted visibility)



@dataclass
class TreeLevel:
    """One level of a tree as planned, and what its GL half reads: the claims of its
    candidates, the views kept, the end views, and its composite."""

    candidates: Candidates
    targets: RenderTargets
    parent_targets: RenderTargets
    parents: list[ReflectionView]                 # the level above's views, by candidate parent row
    queries: list[moderngl.Query]                 # each candidate's claim count
    views: list[PlannedView] = field(default_factory=list)
    path: str | None = None                       # how its views are drawn (batched_mirrors.PATHS)
    conditions: list[moderngl.Query] | None = None  # predicted: each view drawn if its claim has pixels
    ended: list[ReflectionView] = field(default_factory=list)  # end views (EndImages)
    end_views: list[PlannedView] = field(default_factory=list)
    end_matrices: list[glm.mat4] = field(default_factory=list)
    composite: list[ReflectionView] | None = None  # what it composites into the level above (None: no
                                                   # views, only claims)
    prepared: PreparedComposites | None = None
    pixels: list[int] | None = None               # exact: each candidate's claimed pixels
    # What the choice made of the candidates (ViewTree._choose): the views (rows of ``candidates``), those
    # of them that get views below (rows of ``chosen``), the views' candidates, their nodes, and
    # (predicted) each candidate's chain of surfaces from the root.
    keep: list[int] | np.ndarray = field(default_factory=list)
    grow: list[int] | range = field(default_factory=list)
    chosen: Candidates | None = None
    children: list[ReflectionView] = field(default_factory=list)
    claim_keys: list[tuple[int, ...]] = field(default_factory=list)
    small: list[int] = field(default_factory=list)  # predicted: candidates with no view for being under
                                                    # ViewBudget.min_pixels last frame (their fallback)
    unlit: frozenset[int] = frozenset()            # mirrors its views draw unlit (shading_replaced)
    options: SceneOptions = REFLECTION_LEVEL       # what its views were drawn with (their transparent slot's)
    apart: bool = False                           # its claims' rectangles overlap no other's (view_tree._APART)
    depth: int = 1                                # its level in the tree (1: the views of the root's surfaces)


@dataclass
class TreeWalk:
    """One render of a tree on its way down: the root and its settings, and what each level
    hands the next (its parents as nodes and rows, their chains of surfaces, their indices
    in the tree's views, and with end views the seers of each surface)."""

    root: View
    surfaces: SurfaceTable
    settings: TreeSettings
    result: TreeResult
    root_proj: np.ndarray
    inv_root_proj: np.ndarray
    ends: tuple[np.ndarray, int] | None      # EndSurfaces.find
    exact: bool                              # this frame's claim counts (else last frame's)
    record: RootVisibility
    renderer: Gpu                            # what triangles() counts
    nodes: list[ReflectionView]              # the parents of the level planned next
    rows: LevelRows                          # their rows
    seers: list[list[int]] | None            # with end views: end_seers
    keys: list[tuple[int, ...]] = field(default_factory=lambda: [()])  # each parent row's chain of surfaces
    parent_at: list[int] = field(default_factory=lambda: [0])          # each parent row's index in the views
    end_seers: list[int] | None = None       # the planned level's end views' seers
    scale: float = 1.0                       # the planned level's resolution factor
    level: int = 0                           # the deepest level drawn
    steps: list[TreeLevel] = field(default_factory=list)  # the levels, in order (exact: drawn as they come;
                                                       # predicted: drawn after the last is planned)
    fallbacks: dict[int, Fallbacks] = field(default_factory=dict)  # each level's, by the level they
                                                                   # are drawn into (fallbacks_at)
    blends: Mapping[int, ProbeBlend] = field(default_factory=dict)      # the fallbacks' probes (SurfaceBlends)
    triangle_count: int | None = None        # what a scene pass submits (triangles(): counted once, if asked)
    chain: ChainBoxes | None = None          # the planned level's claims' bounds (claim_cull), for the next
    # each level's fallbacks as drawn (the root's: KeptTree; every level's: Refill), by level
    drawn_fallbacks: dict[int, tuple[RenderTargets | None, PreparedFallbacks]] = field(default_factory=dict)
    composited: list[PreparedComposites] = field(default_factory=list)  # [d]: level d + 1 into level d
    ahead: dict[int, tuple] = field(default_factory=dict)  # levels planned ahead (plan_ahead), by depth
    whole: dict[int, bool] = field(default_factory=dict)   # the levels whose candidates all grew (ViewTree._whole)
    whole_before: dict[int, bool] = field(default_factory=dict)  # the same root's last render's
    # Each level's one candidate's surface row (-1: none, or more than one), and the same root's
    # last render's (plan_ahead.plan_chain: a chain planned in one run)
    singles: dict[int, int] = field(default_factory=dict)
    singles_before: dict[int, int] = field(default_factory=dict)
    one: tuple[str, frozenset[int]] | None = None  # a level of one view's path and unlit mirrors
                                                   # (ViewTree._choose_one)

    def triangles(self) -> int:
        """The triangles a scene pass submits, counted at the first level that asks (a level
        of a few views never does: ``choose_path``), then kept for the render."""
        if self.triangle_count is None:
            self.triangle_count = submitted_triangles(self.renderer)
        return self.triangle_count



def fallbacks_at(fallbacks: dict[int, Fallbacks], level: int, surfaces: SurfaceTable) -> Fallbacks:
    """The fallbacks drawn into ``level`` (made empty when first asked for)."""
    found = fallbacks.get(level)
    if found is None:
        found = fallbacks[level] = Fallbacks(surfaces.states)
    return found


def seen_surfaces(result: TreeResult) -> frozenset[int]:
    """The surfaces a tree's image shows through a view or an end view (an unseen view's may
    well not be in it; a candidate known empty is no view, so a surface only such candidates
    saw is not kept as shown, as in exact visibility): what ``EndImages.keep`` keeps with it."""
    return frozenset(node.surface.entity for node in (*result.views[1:], *result.end_views) if not node.unseen)


def ends_at(ends: tuple[np.ndarray, int] | None, depth: int) -> np.ndarray | None:
    """The end-image surfaces to plan at ``depth`` (None before the first level a depth limit cuts)."""
    return ends[0] if ends is not None and depth >= ends[1] else None
