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
and round the grid for as long as it stands; with ``refresh = "scripted"`` only after
``request()``, its first bake too; and a ``once`` or ``scripted`` volume's again, the grid
lighting meanwhile, when a screen within ``far`` of its grid has its first ``Monitor``
picture drawn after the bake began (``PicturesDrawn.first``: its captures showed the screen
black, which its light would keep for good).  ``points_per_frame`` a frame, each six views
of the frame's view budget (``ViewBudget.views``): the points past it wait for the next
frame (under a budget below six views, one point a frame is drawn past it, when it is the
frame's first view, so the bake ends); and within its capture time (``ViewBudget.probe_ms``,
spent with the probes' faces by each point's measured time: past it, the rest wait, one
point a frame at least).  Changing only ``blend_distance`` or ``normal_bias``
captures nothing.

Where each point is captured from is worked out when a bake starts (a new grid, a request):
a point inside a solid object is captured from just outside it (``engine/rules/volume_rules.py``:
a probe in a wall would see through it).  A continuous volume's later rounds keep those
places: finding them walks every mesh in the world (37 ms for 1,000 boxes here), which a
round every few frames would pay again and again.

At most ``MAX_IRRADIANCE_VOLUMES`` (4) a world, each baked as above in a slot of the table's
rows: the lowest entities'; more are said once (``VolumeLimitWarning``) and ignored.  Each
volume's scratch cube is released when it goes.
"""
from __future__ import annotations

import time
import warnings

import esper
import numpy as np
from pyglm import glm

from components import IrradianceVolume, MeshRef, Transform
from components.limits import MAX_IRRADIANCE_VOLUMES
from engine.core.errors import VolumeLimitWarning
from engine.core.world import World
from engine.render.irradiance import VolumeGrid
from engine.render.probes import face_view
from engine.render.renderer import Renderer
from engine.resources import PicturesDrawn
from engine.rules.probe_rules import pose_bounds, world_bounds
from engine.rules.volume_rules import capture_margin, pushed_out, solid_boxes

FACES = 6  # views a point's capture spends of the view budget


def volume_grid(volume: IrradianceVolume, centre: glm.vec3, slot: int = 0) -> VolumeGrid:
    """Where ``volume``'s grid lies with its box centred on ``centre``, in table slot ``slot``."""
    half = glm.vec3(volume.size) / 2.0
    low, high = centre - half, centre + half
    return VolumeGrid(tuple(map(float, low)), tuple(map(float, high)), tuple(volume.points),
                      float(volume.blend_distance), float(volume.normal_bias), slot)


def grid_points(points: tuple[int, int, int]) -> list[tuple[int, int, int]]:
    """Every point's index (i, j, k), x fastest."""
    nx, ny, nz = points
    return [(i, j, k) for k in range(nz) for j in range(ny) for i in range(nx)]


class VolumeBake:
    """One volume's bake: where its captures are taken and drawn, what is still due, and
    whether its grid is whole (lights the scene)."""

    def __init__(self, owner: int, slot: int) -> None:
        self.owner = owner
        self.slot = slot
        self.capture: tuple | None = None    # what places and draws its captures, as last baked
        self.grid: VolumeGrid | None = None  # the grid those captures fill
        self.due: list[tuple[int, int, int]] = []   # points still to capture, in order
        self.taken_from: dict[tuple[int, int, int], np.ndarray] = {}  # where each is captured from
        self.whole = False                   # every point of the grid holds a capture
        self.requests = 0
        self.points_moved = 0                # points of its last bake captured from outside a solid object
        self.round = 1                       # the round of its bake under way (IrradianceVolume.bounces)
        self.taken = 0                       # points captured since its bake last started

    @property
    def key(self) -> int:
        """Its scratch cube among the probes' cubes (a negative key: no entity's)."""
        return -self.owner


class IrradianceVolumeSystem(esper.Processor):
    """Stage "volume" (after the probes, before the main view): each volume's due points
    captured and projected, and its grid handed to the irradiance table once whole."""

    def __init__(self, world: World, renderer: Renderer) -> None:
        self.world = world
        self.renderer = renderer
        self.volumes: dict[int, VolumeBake] = {}   # by owner
        self._said_more = False
        self.points_captured = 0               # over the run (tests, the overlay)
        self.bakes = 0                         # whole grids captured, over the run
        self._pictures = 0                     # PicturesDrawn.count when last looked at

    @property
    def points_moved(self) -> int:
        """Points of the volumes' last bakes captured from outside a solid object."""
        return sum(bake.points_moved for bake in self.volumes.values())

    def process(self, dt: float) -> None:
        volumes = sorted(self.world.query_one(IrradianceVolume), key=lambda pair: pair[0])
        if len(volumes) > MAX_IRRADIANCE_VOLUMES and not self._said_more:
            warnings.warn(f"{len(volumes)} IrradianceVolume entities: at most {MAX_IRRADIANCE_VOLUMES} light a world, "
                          f"the lowest entities'; entities {[e for e, _ in volumes[MAX_IRRADIANCE_VOLUMES:]]} are "
                          "ignored (MAX_IRRADIANCE_VOLUMES)", VolumeLimitWarning, stacklevel=2)
            self._said_more = True
        kept = dict(volumes[:MAX_IRRADIANCE_VOLUMES])
        for owner in [owner for owner in self.volumes if owner not in kept]:
            self._drop(self.volumes.pop(owner))
        first = self._first_pictures()
        for owner, volume in kept.items():
            bake = self.volumes.get(owner)
            if bake is None:
                taken = {b.slot for b in self.volumes.values()}
                bake = self.volumes[owner] = VolumeBake(owner, next(s for s in range(MAX_IRRADIANCE_VOLUMES)
                                                                    if s not in taken))
            if first and self._showed_black(bake, volume, first):
                self._start(bake, volume.near)   # (the grid lights the scene meanwhile, as after a request)
            self._update(bake, volume)
        if not any(bake.due and bake.round > 1 for bake in self.volumes.values()):
            self.renderer.irradiance.end_bounces()   # (no bounce round under way: the table's copy let go)

    def _update(self, bake: VolumeBake, volume: IrradianceVolume) -> None:
        transform = self.world.try_get(bake.owner, Transform)
        centre = glm.vec3(transform.world[3]) if transform is not None else glm.vec3(0.0)
        grid = volume_grid(volume, centre, bake.slot)
        capture = (grid.low, grid.high, grid.points, volume.resolution, volume.near, volume.far, volume.layer_mask)
        table = self.renderer.irradiance
        if capture != bake.capture:
            # A new grid: its tiles hold nothing it means until every point is captured.
            if bake.capture is not None:   # (a new volume's requests so far ask for its first bake)
                bake.requests = volume.requests
            bake.capture, bake.grid, bake.whole = capture, grid, False
            bake.due = []
            if volume.refresh != "scripted":  # (a scripted one waits for its request)
                self._start(bake, volume.near)
            table.set_volume(bake.slot, None)
        elif grid != bake.grid:  # its blend distance or normal bias alone
            bake.grid = grid
            if bake.whole:
                table.set_volume(bake.slot, grid)
        if volume.requests != bake.requests:
            bake.requests = volume.requests
            self._start(bake, volume.near)
        if bake.round > volume.bounces and volume.refresh == "once":
            self._start(bake, volume.near)   # fewer bounces than its grid holds: baked again (more: rounds added)
        if not bake.due and bake.whole and (bake.round < volume.bounces
                                            or volume.refresh == "continuous" and volume.bounces > 1):
            # Another bounce: a round lit by the grid as the last one left it (a continuous
            # volume's every round past the first: its light settles to every bounce).
            bake.round += 1
            bake.due = grid_points(grid.points)
            table.begin_bounce()
        elif not bake.due and volume.refresh == "continuous":
            bake.round = 1
            bake.due = grid_points(grid.points)  # another round, from the places this grid's bake found
        self._capture_due(bake, volume)

    def _first_pictures(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """The world boxes of the screens whose ``Monitor`` pictures were first drawn since the
        last look (``PicturesDrawn.first``: the monitor stage comes later in the frame)."""
        world = self.world
        pictures = world.resources.get(PicturesDrawn)
        if pictures is None or pictures.count == self._pictures:
            return []
        self._pictures = pictures.count
        boxes = []
        for entity in sorted(pictures.first):
            mesh_ref = world.try_get(entity, MeshRef) if world.exists(entity) else None
            transform = world.try_get(entity, Transform) if mesh_ref is not None else None
            if transform is not None:
                boxes.append(world_bounds(mesh_ref.mesh, transform.world, pose_bounds(world, entity, mesh_ref.mesh)))
        return boxes

    @staticmethod
    def _showed_black(bake: VolumeBake, volume: IrradianceVolume, screens: list[tuple[np.ndarray, np.ndarray]]
                      ) -> bool:
        """Whether a ``once`` or ``scripted`` volume's bake captured points before a screen of
        ``screens`` had its first picture, within ``far`` of its grid (its captures may show
        the screen black, and would for good): it is baked again.  A continuous one's next
        round captures it anyway."""
        if volume.refresh == "continuous" or bake.grid is None:
            return False
        if not bake.whole and not bake.taken:
            return False   # (nothing captured yet: the bake to come sees the picture)
        low, high = np.array(bake.grid.low) - volume.far, np.array(bake.grid.high) + volume.far
        return any(bool(np.all(lo <= high) and np.all(hi >= low)) for lo, hi in screens)

    def _start(self, bake: VolumeBake, near: float) -> None:
        """A bake of every point of its grid, each captured from its place or from outside the
        solid object it lies in (``volume_rules.pushed_out``)."""
        grid = bake.grid
        bake.due = grid_points(grid.points)
        bake.round = 1
        bake.taken = 0
        places = np.array([grid.position(index) for index in bake.due])
        low, high = np.array(grid.low), np.array(grid.high)
        margin = capture_margin(near)
        taken = pushed_out(places, *solid_boxes(self.world, low, high, margin), toward=(low + high) / 2.0,
                           margin=margin)
        bake.taken_from = dict(zip(bake.due, taken, strict=True))
        bake.points_moved = int(np.count_nonzero(np.any(taken != places, axis=1)))

    def _capture_due(self, bake: VolumeBake, volume: IrradianceVolume) -> None:
        stats = self.renderer.stats
        left = stats.views_left()
        count = volume.points_per_frame if left is None else min(volume.points_per_frame, left // FACES)
        if not count and left is not None and stats.view_budget < FACES and stats.views_spent == 0:
            count = 1  # a budget no point fits: one a frame past it, so the bake ends
        count = min(count, len(bake.due))
        if not count:
            return
        probes, table, grid = self.renderer.probes, self.renderer.irradiance, bake.grid
        drawn = 0
        for index in bake.due[:count]:
            if drawn and stats.probe_ms_budget is not None and stats.probe_ms_spent >= stats.probe_ms_budget:
                break  # the frame's capture time is spent: the rest next frame (one a frame at least)
            start = time.perf_counter()
            position = glm.vec3(*bake.taken_from[index])
            views = {face: face_view(face, position, volume.near, volume.far, volume.resolution, skip=bake.owner,
                                     layers=volume.layer_mask) for face in range(FACES)}
            table.bounce_lit = bake.round > 1   # (a bounce round: lit by the grid's last round)
            try:
                probes.capture(bake.key, views, None, 0)
            finally:
                table.bounce_lit = False
            table.project_volume_point(grid, index, probes.cubes[bake.key])
            stats.probe_ms_spent += (time.perf_counter() - start) * 1e3
            drawn += 1
        count = drawn
        del bake.due[:count]
        bake.taken += count
        stats.views_spent += FACES * count
        stats.volume_points += count
        self.points_captured += count
        if not bake.due:
            self.bakes += 1
            if not bake.whole:
                bake.whole = True
                table.set_volume(bake.slot, grid)

    def _drop(self, bake: VolumeBake) -> None:
        """A volume gone (or past the limit now): its cube released, its grid lighting nothing."""
        self.renderer.probes.drop(bake.key)
        self.renderer.irradiance.set_volume(bake.slot, None)
