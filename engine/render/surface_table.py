"""The planner's table of this frame's mirrors and portals (``view_plan.SurfaceTable``), a
world resource of the render stages.

It is made from the surfaces stage's ``Surfaces`` by the first stage that plans views
through them in a frame (the probes stage, for a face that sees mirrors or portals; else
the reflect stage, whose main view tree is its main reader) and kept while the surfaces
stage keeps its ``Surfaces`` (no surface changed): a still scene's table keeps its last
plans (``SurfaceTable.plan``), and ``engine.resources`` stays plain data.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from engine.render.view_plan import SurfaceTable
from engine.resources import Surfaces
from engine.rules.probe_rules import ProbeBlend

__all__ = ["NO_BLENDS", "PlannerSurfaces", "SurfaceBlends", "surface_table"]


@dataclass(frozen=True, eq=False)
class PlannerSurfaces:
    """The table (``world.resources[PlannerSurfaces].table``) and the ``Surfaces`` it was made
    from (by identity: the surfaces stage makes a new one when a surface changes)."""

    surfaces: Surfaces
    table: SurfaceTable


@dataclass(frozen=True, eq=False)
class SurfaceBlends:
    """What each mirror and portal shows where it gets no view of its own (cut by the budget,
    faded out, past the depth limits): the probes whose influence boxes hold it and their
    weights (``probe_rules.surface_blend``, by surface entity; absent: the sky).  The extract
    stage publishes it each frame; the view trees draw their fallbacks with it."""

    by_surface: Mapping[int, ProbeBlend] = field(default_factory=dict)


NO_BLENDS = SurfaceBlends()  # every surface without a view shows the sky (a tree drawn outside the stages)


def surface_table(resources: dict[type, Any], surfaces: Surfaces) -> SurfaceTable:
    """The table of ``surfaces`` (this frame's ``Surfaces`` resource): the published one when
    it was made from them, else made now and published."""
    held: PlannerSurfaces | None = resources.get(PlannerSurfaces)
    if held is None or held.surfaces is not surfaces:
        held = resources[PlannerSurfaces] = PlannerSurfaces(surfaces, _table(surfaces))
    return held.table


def _table(surfaces: Surfaces) -> SurfaceTable:
    """Every mirror, each water's underside beside its top, and every portal: a water is two
    surfaces of one entity facing opposite ways, and a view sees the one facing its eye (the
    cull's facing test), so a view under the water, at any level, sees its underside."""
    return SurfaceTable([*surfaces.mirrors.values(), *surfaces.undersides.values(), *surfaces.portals.values()])
