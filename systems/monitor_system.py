"""Stage "monitors": each ``Monitor``'s picture drawn from its camera (``components/monitor.py``,
``engine/render/monitors.py``).

After the probes and the irradiance volume (the pictures' views sample them as any view
does), before the main view (which shows the screens with this frame's pictures).  What is
decided here:

- which monitors are due: a monitor is drawn on the frame it comes and then every
  ``every`` frames; at most ``MAX_MONITORS`` a frame, those that have waited longest first
  (then by entity): the rest keep their pictures a frame more and are drawn first the next
  (counted in ``RenderStats.monitors_cut``, said when the count grows);
- each one's view: its camera entity's ``Camera`` (field of view or orthographic height,
  near, far, layers) from its ``Transform``, at the picture's size and aspect; a camera that
  is missing (no entity, no ``Camera`` or no ``Transform`` on it) is said once, and the
  picture kept as it is (black at first);
- whether its mirrors and portals get views: to ``Monitor.depth`` levels, planned with the
  frame's surfaces as a probe face's tree is, outside the frame's ``ViewBudget``
  (``outside_the_budget``: the monitors' own limits bound them, and drawn before the main
  view they would take the budget the frame's reflections share first).

The pictures of monitors gone (or deleted) are let go here; the extract stage makes a
screen's picture when it first draws the screen (its emissive map is the picture)."""
from __future__ import annotations

import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import fields

import esper

from components import Camera, ComponentWarning, Monitor, Transform
from engine.core.errors import MonitorLimitWarning
from engine.core.world import World
from engine.frame_stats import BudgetLedger
from engine.render.monitors import MAX_MONITORS
from engine.render.renderer import Renderer
from engine.render.surface_table import NO_BLENDS, SurfaceBlends, surface_table
from engine.render.views import camera_view
from engine.resources import Surfaces


class MonitorSystem(esper.Processor):
    """Draws the due monitors' pictures, from their cameras."""

    def __init__(self, world: World, renderer: Renderer) -> None:
        super().__init__()
        self.world = world
        self.renderer = renderer
        self.drawn: dict[int, int] = {}         # monitor -> the frame its picture was last drawn
        self._said: set[tuple[int, int | None]] = set()  # (monitor, the camera it named) said once
        self._cut = 0

    def process(self, dt: float) -> None:
        world = self.world
        pictures = self.renderer.monitors
        stats = self.renderer.stats
        monitors = sorted(world.query_one(Monitor), key=lambda pair: pair[0])
        present = {entity for entity, _ in monitors}
        for gone in pictures.entities - present:
            pictures.drop(gone)
        for gone in set(self.drawn) - present:
            del self.drawn[gone]
        self._said = {(entity, camera) for entity, camera in self._said if entity in present}
        frame = world.frame_index
        # The longest waiting first (a new one first of all), then by entity: past MAX_MONITORS
        # those left wait a frame and are drawn first the next.
        due = sorted(((entity, monitor) for entity, monitor in monitors
                      if entity not in self.drawn or frame - self.drawn[entity] >= monitor.every),
                     key=lambda pair: (self.drawn.get(pair[0], -1), pair[0]))
        cut = max(0, len(due) - MAX_MONITORS)
        if cut > self._cut:
            warnings.warn(MonitorLimitWarning(
                f"{len(due)} monitors are due this frame: {MAX_MONITORS} are drawn a frame (those waiting longest), "
                f"so {cut} keep their pictures a frame more (RenderStats.monitors_cut)"), stacklevel=2)
        self._cut = stats.monitors_cut = cut
        surfaces: Surfaces | None = world.resources.get(Surfaces)
        table = None
        for entity, monitor in due[:MAX_MONITORS]:
            parts = self._camera(entity, monitor)
            if parts is None:
                continue
            camera, transform = parts
            pictures.picture(entity, monitor.size)   # (made here too for a monitor with no screen yet)
            view = camera_view(transform.world, camera.fov_y, camera.near, camera.far, monitor.size,
                               name=f"monitor {entity}",
                               ortho_height=camera.ortho_height if camera.projection == "orthographic" else None)
            view.layers = camera.layer_mask
            trees = monitor.depth > 0 and surfaces is not None and bool(surfaces.mirrors or surfaces.portals)
            if trees and table is None:
                table = surface_table(world.resources, surfaces)
            with outside_the_budget(stats):
                views = pictures.draw(entity, view, table if trees else None, monitor.depth,
                                      world.resources.get(SurfaceBlends, NO_BLENDS))
            stats.monitor_views += views
            self.drawn[entity] = frame

    def _camera(self, entity: int, monitor: Monitor) -> tuple[Camera, Transform] | None:
        """The Camera and Transform of the entity ``monitor`` shows, or None, said once for each
        entity it names that is not a camera."""
        world = self.world
        camera = monitor.camera
        if camera is None or not world.exists(camera):
            why = "names no camera (Monitor.camera is None)" if camera is None else \
                f"names entity {camera}, which does not exist"
        elif world.try_get(camera, Camera) is None or world.try_get(camera, Transform) is None:
            lacking = "Camera" if world.try_get(camera, Camera) is None else "Transform"
            why = f"names entity {camera}, which has no {lacking}"
        else:
            return world.get(camera, Camera), world.get(camera, Transform)
        if (entity, camera) not in self._said:   # (said once for each camera it names)
            self._said.add((entity, camera))
            warnings.warn(ComponentWarning(f"Monitor on entity {entity} {why}: its picture is not drawn (it keeps "
                                           "what it showed, black at first)"), stacklevel=3)
        return None


@contextmanager
def outside_the_budget(ledger: BudgetLedger) -> Iterator[None]:
    """Within the block the view trees drawn see no ``ViewBudget`` (no view, pixel or
    smallest-view limit) and what they spend is not kept: a monitor's picture has limits of
    its own (its size and depth, ``every``, ``MAX_MONITORS``), and drawn before the main
    view it would otherwise take the budget the frame's reflections share first."""
    kept = {field.name: getattr(ledger, field.name) for field in fields(BudgetLedger)}
    ledger.view_budget = ledger.pixel_budget = ledger.min_view_pixels = None
    try:
        yield
    finally:
        for name, value in kept.items():
            setattr(ledger, name, value)
