"""Stage "volume": the irradiance volume's bake, a few grid points a frame.

An ``IrradianceVolume`` (``components/probe.py``) is a grid of light probes: each point is a
cube map captured there (the probes' capture, ``ProbeCaptures.capture``, into one scratch
cube the volume owns, drawn as a probe's faces are: lit by the sky's irradiance alone, no
probe's or volume's), projected on the GPU into nine spherical-harmonic coefficients, one
texel in each coefficient's tile of the irradiance table
(``IrradianceTable.project_volume_point``).  Nothing is read back.  Once every point holds a
capture the table's Irradiance block names the grid and the scene's light from all round
reads it (``shaders/include/ambient.glsl``: the eight points about each shaded point).

When points are captured: all of them when the volume is made, moved, or any field that
places or draws its captures changes (its tiles then hold nothing the new grid means: the
scene is lit without the grid until the new bake is whole); all of them again, the grid
lighting the scene meanwhile, after ``request()``; and with ``refresh = "continuous"`` round
and round the grid for as long as it stands.  ``points_per_frame`` a frame, each six views
of the frame's view budget (``ViewBudget.views``): the points past it wait for the next
frame (under a budget below six views, one point a frame is drawn past it, when it is the
frame's first view, so the bake ends).  Changing only ``blend_distance`` or ``normal_bias``
captures nothing.

Where each point is captured from is worked out when its bake starts: a point inside a solid
object is captured from just outside it (``engine/rules/volume_rules.py``: a probe in a wall
would see through it).

One volume a world: the lowest entity's; another is said once (``VolumeLimitWarning``) and
ignored.  Its scratch cube is released when the volume goes.
"""
from __future__ import annotations

import warnings

import esper
import numpy as np
from pyglm import glm

from components import IrradianceVolume, Transform
from engine.core.errors import VolumeLimitWarning
from engine.core.world import World
from engine.render.irradiance import VolumeGrid
from engine.render.probes import face_view
from engine.render.renderer import Renderer
from engine.rules.volume_rules import capture_margin, pushed_out, solid_boxes

FACES = 6  # views a point's capture spends of the view budget


def volume_grid(volume: IrradianceVolume, centre: glm.vec3) -> VolumeGrid:
    """Where ``volume``'s grid lies with its box centred on ``centre``."""
    half = glm.vec3(volume.size) / 2.0
    low, high = centre - half, centre + half
    return VolumeGrid(tuple(map(float, low)), tuple(map(float, high)), tuple(volume.points),
                      float(volume.blend_distance), float(volume.normal_bias))


def grid_points(points: tuple[int, int, int]) -> list[tuple[int, int, int]]:
    """Every point's index (i, j, k), x fastest."""
    nx, ny, nz = points
    return [(i, j, k) for k in range(nz) for j in range(ny) for i in range(nx)]


class IrradianceVolumeSystem(esper.Processor):
    """Stage "volume" (after the probes, before the main view): the volume's due points
    captured and projected, and the grid handed to the irradiance table once whole."""

    def __init__(self, world: World, renderer: Renderer) -> None:
        self.world = world
        self.renderer = renderer
        self.owner: int | None = None          # the volume's entity
        self._capture: tuple | None = None     # what places and draws its captures, as last baked
        self._grid: VolumeGrid | None = None   # the grid those captures fill
        self._due: list[tuple[int, int, int]] = []  # points still to capture, in order
        self._from: dict[tuple[int, int, int], np.ndarray] = {}  # where each is captured from (this bake's)
        self.points_moved = 0                  # points of the last bake captured from outside a solid object
        self._whole = False                    # every point of _grid holds a capture
        self._requests = 0
        self._said_more = False
        self.points_captured = 0               # over the run (tests, the overlay)
        self.bakes = 0                         # whole grids captured, over the run

    @property
    def key(self) -> int:
        """The volume's scratch cube among the probes' cubes (a negative key: no entity's)."""
        return -(self.owner or 0)

    def process(self, dt: float) -> None:
        volumes = sorted(self.world.query_one(IrradianceVolume), key=lambda pair: pair[0])
        if len(volumes) > 1 and not self._said_more:
            warnings.warn(f"{len(volumes)} IrradianceVolume entities: one lights a world, the lowest entity's "
                          f"({volumes[0][0]}); entities {[e for e, _ in volumes[1:]]} are ignored",
                          VolumeLimitWarning, stacklevel=2)
            self._said_more = True
        owner, volume = volumes[0] if volumes else (None, None)
        if owner != self.owner:
            self._drop()
            self.owner = owner
        if volume is None:
            return
        transform = self.world.try_get(owner, Transform)
        centre = glm.vec3(transform.world[3]) if transform is not None else glm.vec3(0.0)
        grid = volume_grid(volume, centre)
        capture = (grid.low, grid.high, grid.points, volume.resolution, volume.near, volume.far, volume.layer_mask)
        if capture != self._capture:
            # A new grid: its tiles hold nothing it means until every point is captured.
            self._capture, self._grid, self._whole = capture, grid, False
            self._requests = volume.requests
            self._start(grid, volume.near)
            self.renderer.irradiance.set_volume(None)
        elif grid != self._grid:  # its blend distance or normal bias alone
            self._grid = grid
            if self._whole:
                self.renderer.irradiance.set_volume(grid)
        if volume.requests != self._requests:
            self._requests = volume.requests
            self._start(grid, volume.near)
        if not self._due and volume.refresh == "continuous":
            self._start(grid, volume.near)
        self._capture_due(volume, grid)

    def _start(self, grid: VolumeGrid, near: float) -> None:
        """A bake of every point of ``grid``, each captured from its place or from outside the
        solid object it lies in (``volume_rules.pushed_out``)."""
        self._due = grid_points(grid.points)
        places = np.array([grid.position(index) for index in self._due])
        low, high = np.array(grid.low), np.array(grid.high)
        margin = capture_margin(near)
        taken = pushed_out(places, *solid_boxes(self.world, low, high, margin), toward=(low + high) / 2.0,
                           margin=margin)
        self._from = dict(zip(self._due, taken, strict=True))
        self.points_moved = int(np.count_nonzero(np.any(taken != places, axis=1)))

    def _capture_due(self, volume: IrradianceVolume, grid: VolumeGrid) -> None:
        stats = self.renderer.stats
        left = stats.views_left()
        count = volume.points_per_frame if left is None else min(volume.points_per_frame, left // FACES)
        if not count and left is not None and stats.view_budget < FACES and stats.views_spent == 0:
            count = 1  # a budget no point fits: one a frame past it, so the bake ends
        count = min(count, len(self._due))
        if not count:
            return
        probes, table = self.renderer.probes, self.renderer.irradiance
        key = self.key
        for index in self._due[:count]:
            position = glm.vec3(*self._from[index])
            views = {face: face_view(face, position, volume.near, volume.far, volume.resolution, skip=self.owner,
                                     layers=volume.layer_mask) for face in range(FACES)}
            probes.capture(key, views, None, 0)
            table.project_volume_point(grid, index, probes.cubes[key])
        del self._due[:count]
        stats.views_spent += FACES * count
        stats.volume_points += count
        self.points_captured += count
        if not self._due:
            self.bakes += 1
            if not self._whole:
                self._whole = True
                table.set_volume(grid)

    def _drop(self) -> None:
        """The volume is gone (or another took its place): its cube released, the grid no
        longer lights the scene."""
        if self.owner is not None:
            self.renderer.probes.drop(self.key)
            self.renderer.irradiance.set_volume(None)
        self.owner, self._capture, self._grid, self._due, self._whole = None, None, None, [], False
