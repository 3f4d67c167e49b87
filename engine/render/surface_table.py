"""The planner's table of this frame's mirrors and portals (``view_plan.SurfaceTable``), a
world resource of the render stages.

It is made from the surfaces stage's ``Surfaces`` by the first stage that plans views
through them in a frame (the probes stage, for a face that sees mirrors or portals; else
the reflect stage, whose main view tree is its main reader) and kept while the surfaces
stage keeps its ``Surfaces`` (no surface changed): a still scene's table keeps its last
plans (``SurfaceTable.plan``), and ``engine.resources`` stays plain data.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from engine.render.view_plan import SurfaceTable
from engine.resources import Surfaces

__all__ = ["PlannerSurfaces", "surface_table"]


@dataclass(frozen=True, eq=False)
class PlannerSurfaces:
    """The table (``world.resources[PlannerSurfaces].table``) and the ``Surfaces`` it was made
    from (by identity: the surfaces stage makes a new one when a surface changes)."""

    surfaces: Surfaces
    table: SurfaceTable


def surface_table(resources: dict[type, Any], surfaces: Surfaces) -> SurfaceTable:
    """The table of ``surfaces`` (this frame's ``Surfaces`` resource): the published one when
    it was made from them, else made now and published."""
    held: PlannerSurfaces | None = resources.get(PlannerSurfaces)
    if held is None or held.surfaces is not surfaces:
        held = resources[PlannerSurfaces] = PlannerSurfaces(
            surfaces, SurfaceTable([*surfaces.mirrors.values(), *surfaces.portals.values()]))
    return held.table
