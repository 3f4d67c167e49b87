"""A sun's cascades (rings about an eye), kept or drawn again: one rule for the active
camera's (the shadows stage, ``systems/shadow_system.py``) and each monitor's camera's (the
monitors stage, ``systems/monitor_system.py``).

A ring is kept while what it was drawn from is the same (its light's level map, its square
in the atlas, its grid cell about the eye: ``shadow_rules.ring_cell``) and no caster
changed; drawn again only under the changed casters (``shadow_rules.changed_region``) when
they did; drawn whole otherwise.

A monitor's camera may stand far from the active camera, where the camera's rings do not
reach: its picture read only the level's map there (a coarse shadow, 3 cm texels over the
sample level's floor).  So each monitor's camera gets the same rings about itself (the
pictures of the monitors it feeds share them), in the atlas's free tiles' quarters
(``Cascades.places``: half the tile's side; a picture's few hundred pixels a side want no
more), read in place of the active camera's while a picture of it is drawn
(``ShadowMaps.swap_ring_rows``); rings not brought up to date on a frame casters changed in
(no picture of the camera drawn then: a slow ``Monitor.every``, a kept or unseen picture)
are drawn whole when next used.  Where the quarters run out, a picture reads the active
camera's rings (still right where they reach; coarser where they do not) and
``RenderStats.picture_cascades_cut`` counts its rings."""
from __future__ import annotations

import numpy as np

from engine.frame_stats import RenderStats
from engine.render.shadows import ShadowMaps
from engine.rules.shadow_rules import Cascades, DirectionalFit, changed_region, ring_cell, ring_fit


def ring_to_draw(kept: tuple | None, key: tuple, casters_changed: bool, changes: tuple,
                 resolution: int) -> tuple[DirectionalFit | None, tuple | None] | None:
    """What of a ring (``kept``: its last (key, fit), or None) is drawn this frame: None
    (kept as it is: its ``key`` is the same and no caster changed, ``casters_changed``, or
    what changed casts nothing there), else (the fit to draw from: the kept one, or None for
    a new one; the region: under the changed casters, ``changes``, or None for the whole)."""
    if kept is None or kept[0] != key:
        return None, None
    if not casters_changed:
        return None
    region = changed_region(kept[1], *changes, resolution)
    if region is not None and region[2] * region[3] == 0:
        return None
    return kept[1], region


class PictureRings:
    """Each monitor's camera's rings: the atlas squares they hold, its rings' keys and fits,
    their cells."""

    def __init__(self) -> None:
        self._places: tuple = ()   # the free squares and the atlas as last published
        self._held: dict[int, tuple[tuple[int, int], ...]] = {}   # camera -> its squares
        self._rings: dict[int, dict[int, tuple]] = {}    # camera -> ring -> (key, fit)
        self._cells: dict[int, dict[int, tuple[int, int]]] = {}   # camera -> ring -> its cell
        self._stamps: dict[int, int] = {}   # camera -> the Cascades.stamp its rings were last brought to
        self._counted: dict[int, RenderStats] = {}   # camera -> the frame's stats its rings were counted in

    def keep(self, cameras: set[int]) -> None:
        """Only ``cameras`` (the monitors' now) keep their squares: the others' are free again."""
        for gone in [camera for camera in self._held if camera not in cameras]:
            self._held.pop(gone, None)
            self._rings.pop(gone, None)
            self._cells.pop(gone, None)
            self._stamps.pop(gone, None)
            self._counted.pop(gone, None)

    def rows(self, camera: int, eye: tuple[float, float, float], cascades: Cascades, maps: ShadowMaps,
             stats: RenderStats) -> dict[int, np.ndarray]:
        """The rings about ``eye`` of ``camera`` (a monitor's: the monitors it feeds share
        them), kept or drawn into its squares: ring -> its rows of the Shadows block
        (``ShadowMaps.ring_rows``), to be read while a picture of it is drawn.  Empty where no
        square is left for it (counted)."""
        if not cascades.rings:
            return {}
        if (cascades.places, cascades.atlas) != self._places:   # (another atlas or layout: all drawn anew)
            self._places = (cascades.places, cascades.atlas)
            self._held.clear()
            self._rings.clear()
            self._cells.clear()
            self._stamps.clear()
            self._counted.clear()
        places = self._held.get(camera)
        if places is None or len(places) != len(cascades.rings):
            self._held.pop(camera, None)
            taken = {place for held in self._held.values() for place in held}
            free = [place for place in cascades.places if place not in taken]
            if len(free) < len(cascades.rings):
                stats.picture_cascades_cut += len(cascades.rings)
                return {}
            places = self._held[camera] = tuple(free[:len(cascades.rings)])
            self._rings[camera] = {}
            self._cells[camera] = {}
        rings, cells = self._rings[camera], self._cells[camera]
        # Casters that changed on a frame no picture of the camera was drawn: its rings drawn
        # whole; brought up to this frame's already (another monitor it feeds): kept.
        seen = self._stamps.get(camera, cascades.stamp)
        if cascades.stamp - seen > int(cascades.casters_changed):
            rings.clear()
        changed = cascades.casters_changed and seen != cascades.stamp
        self._stamps[camera] = cascades.stamp
        counted = self._counted.get(camera) is stats   # (a frame's stats: its rings counted once)
        self._counted[camera] = stats
        rows = {}
        for ring, place in zip(cascades.rings, places, strict=True):
            level = cascades.levels[ring.slot]
            resolution = min(ring.resolution, cascades.side)
            cell = cells[ring.ring] = ring_cell(level, eye, ring.radius, resolution, cells.get(ring.ring))
            key = (cascades.keys[ring.slot], place, ring.radius, resolution, cell)
            todo = ring_to_draw(rings.get(ring.ring), key, changed, cascades.changes, resolution)
            if todo is None:
                stats.shadow_maps_kept += not counted
            else:
                fit = todo[0] or ring_fit(level, cell, ring.radius, resolution)
                stats.shadow_texels_drawn += maps.draw_picture_ring(ring.ring, place, fit, resolution, todo[1])
                stats.shadow_maps_drawn += 1
                rings[ring.ring] = (key, fit)
            rows[ring.ring] = maps.ring_rows(place, ring.slot, rings[ring.ring][1], resolution, ring.softness)
        return rows
