"""Stage "ripples": each rippling water's height field moved on by the frame's seconds, with
the drops its ``Wake``s and its rain push in (``components/ripples.py``).

After the prepare stage, before any view is drawn: the composites of this frame's views read
the fields as this stage leaves them (``engine/render/ripples.py``: the atlas, the step, and
how the composites see it).  What is decided here, on the CPU:

- which waters ripple: those with ``Ripples`` and a water surface with an outline (a flat
  quad), at most ``MAX_RIPPLE_WATERS`` (the first by entity; the rest counted and said once),
  each field's texels (about ``cell`` apart along each edge of the outline, coarser where a
  side would pass ``MAX_RIPPLE_TEXELS``: said once);
- the frame's drops: where each ``Wake`` crosses a water's plane inside its outline, pushed
  down by its strength times the metres it moved since the last frame, and the rain (its
  drops a second over the water's area, the fraction carried to the next frame, placed at
  random), at most ``MAX_RIPPLE_DROPS`` a water a frame;
- how many steps the frame takes (each at most ``MAX_COURANT`` texels of travel) and when a
  water's rings have died away: the height its drops could still have (their depths summed,
  falling by exp(-damping t): the rings only ever spread and fade) under ``RIPPLE_CALM``,
  its tile is cleared and no longer stepped, and the composites' plain builds come back.
A paused frame (dt 0) moves nothing (a ``Splash`` waits for the next frame that does); with no
rippling water a Splash is taken off as it comes, landing nowhere."""
from __future__ import annotations

import math
import warnings

import esper
import numpy as np

from components import MeshRef, Ripples, Splash, Transform, Wake, Water
from components.tracking import ComponentWarning
from engine.core.errors import GLLimitWarning, WaterLimitWarning
from engine.core.world import World
from engine.render.gpu import Gpu
from engine.render.ripples import (
    MAX_COURANT,
    MAX_RIPPLE_DROPS,
    MAX_RIPPLE_STEPS,
    MAX_RIPPLE_WATERS,
    RIPPLE_CAUSTIC_SAMPLERS,
    RippleWater,
    field_texels,
    outline_edges,
)
from engine.resources import Surfaces
from engine.rules.frame_rules import world_corners

RIPPLE_CALM = 1e-5        # metres: rings whose height may be no more than this are gone (a 0.01 mm swell)
MAX_RIPPLE_FRAME = 1.0 / 15.0   # seconds a frame moves the ripples at most (a hitch is not a flood of steps)
MIN_DROP_TEXELS = 1.5     # a drop's radius in texels at least (a narrower one would miss every texel's centre)
RAIN_SEED = 20261206      # where the rain falls: the same on every run


class RippleSystem(esper.Processor):
    """Moves every rippling water's rings on, with the frame's drops."""

    def __init__(self, world: World, renderer: Gpu) -> None:
        super().__init__()
        self.world = world
        self.renderer = renderer
        self.loudness: dict[int, float] = {}      # water -> the height its rings may still have (metres)
        self._crossed: dict[int, np.ndarray] = {}  # Wake entity -> its box's corners last frame
        self._owed: dict[int, float] = {}          # water -> the rain's fraction of a drop carried over
        self._rain = np.random.default_rng(RAIN_SEED)
        self._said: set[tuple[str, int]] = set()   # (what, entity) said once
        self._cut = 0

    def process(self, dt: float) -> None:
        self._forget_deleted()
        stats = self.renderer.stats
        atlas = self.renderer.ripples
        found = sorted(self.world.query_one(Ripples), key=lambda pair: pair[0])
        if not found:
            if atlas.waters:
                atlas.release()
            self.loudness.clear()
            self._crossed.clear()
            self._owed.clear()
            for entity, _ in self.world.query_one(Splash):   # (no rippling water to land in)
                self.world.remove_component(entity, Splash)
            return
        waters = self._waters(found)
        cut = max(0, len(waters) - MAX_RIPPLE_WATERS)
        if cut > self._cut:
            warnings.warn(WaterLimitWarning(
                f"{len(waters)} waters have Ripples: {MAX_RIPPLE_WATERS} ripple at a time (the first by entity: "
                f"{[w.entity for w, _ in waters[:MAX_RIPPLE_WATERS]]}), so {cut} stay still "
                "(RenderStats.ripple_waters_cut)"), stacklevel=2)
        self._cut = stats.ripple_waters_cut = cut
        waters = waters[:MAX_RIPPLE_WATERS]
        atlas.set([water for water, _ in waters], self.renderer.shaders)
        for entity in list(self.loudness):
            if atlas.tile_of(entity) is None:
                del self.loudness[entity]
        if dt <= 0.0:
            return
        dt = min(dt, MAX_RIPPLE_FRAME)
        drops = self._drops(waters, dt)
        for water, ripples in waters:
            entity = water.entity
            these = drops.get(entity, [])
            if len(these) > MAX_RIPPLE_DROPS:
                stats.ripple_drops_cut += len(these) - MAX_RIPPLE_DROPS
                if ("drops", entity) not in self._said:
                    self._note_said("drops", entity)
                    warnings.warn(WaterLimitWarning(
                        f"Ripples on entity {entity}: {len(these)} drops in one frame, {MAX_RIPPLE_DROPS} are taken "
                        "(the rest counted in RenderStats.ripple_drops_cut)"), stacklevel=2)
                drops[entity] = these = these[:MAX_RIPPLE_DROPS]
            stats.ripple_drops += len(these)
            loud = self.loudness.get(entity, 0.0) * math.exp(-ripples.damping * dt) + sum(d[3] for d in these)
            if loud > RIPPLE_CALM:
                self.loudness[entity] = loud
                atlas.wake(entity)
            else:
                self.loudness.pop(entity, None)
                atlas.sleep(entity)
        awake = [(water, ripples) for water, ripples in waters if water.entity in atlas.awake]
        if not awake:
            return
        fastest = max(ripples.speed / min(_spacing(water)) for water, ripples in awake)
        wanted = max(1, math.ceil(fastest * dt / MAX_COURANT))
        steps = min(MAX_RIPPLE_STEPS, wanted)
        # Past the most steps a frame, each stays a stable one: the rings spread slower than
        # their speed (said once), never blow up.
        step = min(dt / steps, MAX_COURANT / fastest)
        if wanted > MAX_RIPPLE_STEPS:
            self._say_once("steps", awake[0][0].entity, WaterLimitWarning(
                f"Ripples: {wanted} steps this frame would keep the fastest rings (speed / cell "
                f"{fastest:.0f} texels a second) stable, {MAX_RIPPLE_STEPS} are taken, so they spread slower than "
                "their speed; a larger Ripples.cell or a lower speed keeps up"))
        rates = {}
        for water, ripples in awake:
            du, dv = _spacing(water)
            rates[water.entity] = ((ripples.speed * step / du) ** 2, (ripples.speed * step / dv) ** 2,
                                   math.exp(-2.0 * ripples.damping * step))
        atlas.step(rates, drops, steps)
        stats.ripple_steps = steps

    def _waters(self, found: list[tuple[int, Ripples]]) -> list[tuple[RippleWater, Ripples]]:
        """Each water of ``found`` that can ripple, as the atlas holds it."""
        surfaces = self.world.resources.get(Surfaces)
        waters = []
        for entity, ripples in found:
            state = surfaces.mirrors.get(entity) if surfaces is not None else None
            if state is None or state.water is None:
                continue   # (its Water or Mirror taken off: the water rule says so)
            if state.outline is None:
                self._say_once("flat", entity, ComponentWarning(
                    f"Ripples on entity {entity}: its water's mesh is not one flat quad (no outline), so it does not "
                    "ripple; give the water a quad mesh"))
                continue
            if not self.renderer.ripples.in_caustics and (water := self.world.try_get(entity, Water)) is not None \
                    and water.caustics > 0.0:
                self._say_once("caustics", entity, GLLimitWarning(
                    f"Ripples on entity {entity}: its caustics would need {RIPPLE_CAUSTIC_SAMPLERS} fragment texture "
                    f"units to gather the rings' light too and this OpenGL has {self.renderer.ripples.texture_units} "
                    "(GL_MAX_TEXTURE_IMAGE_UNITS): its caustics are its waves' alone"))
            origin, edge_u, edge_v = outline_edges(state.outline)
            texels, coarse = field_texels(edge_u, edge_v, ripples.cell)
            if coarse:
                self._say_once("coarse", entity, WaterLimitWarning(
                    f"Ripples on entity {entity}: a field {ripples.cell} m a texel over this water would pass "
                    f"{max(texels)} texels a side, so its texels are coarser ({texels[0]} x {texels[1]})"))
            plane = tuple(float(v) for v in state.plane)
            waters.append((RippleWater(entity, plane, tuple(map(float, origin)), tuple(map(float, edge_u)),
                                       tuple(map(float, edge_v)), texels, ripples.strength), ripples))
        return waters

    def _drops(self, waters: list[tuple[RippleWater, Ripples]], dt: float) -> dict[int, list[tuple[float, ...]]]:
        """The frame's drops on each water (texel x, y in its tile, radius in texels, depth in
        metres): its Wakes' and its rain's."""
        drops: dict[int, list[tuple[float, ...]]] = {water.entity: [] for water, _ in waters}
        atlas = self.renderer.ripples
        crossed: dict[int, np.ndarray] = {}
        for entity, wake in self.world.query_one(Wake):
            transform = self.world.try_get(entity, Transform)
            if transform is None:
                self._say_once("wake", entity, ComponentWarning(
                    f"Wake on entity {entity}: it has no Transform to say where it is, so it makes no ripples"))
                continue
            centre, half, corners = self._placed(entity, transform)
            if not half.any() and wake.radius <= 0.0:
                self._say_once("point", entity, ComponentWarning(
                    f"Wake on entity {entity}: it has no mesh to take a size from and its radius is 0, so it makes "
                    "no ripples; give it a MeshRef or a Wake.radius"))
                continue
            last = self._crossed.get(entity)
            crossed[entity] = corners
            # The farthest any corner of its box went: a thing that turns where it stands
            # (a spinning top, a boat swinging its stern) stirs the water as one that wades.
            moved = 0.0 if last is None or last.shape != corners.shape \
                else float(np.sqrt(((corners - last) ** 2).sum(axis=1).max()))
            if moved <= 0.0 or wake.strength <= 0.0:
                continue
            for water, _ in waters:
                normal, w = np.asarray(water.plane[:3]), water.plane[3]
                height = float(normal @ centre + w)
                reach = float(np.abs(normal) @ half)
                if abs(height) > max(reach, wake.radius):
                    continue   # not across this water's plane
                point = centre - height * normal
                x, y = atlas.to_texels(water.entity, point)[0]
                nu, nv = water.texels
                if not (0.0 <= x <= nu and 0.0 <= y <= nv):
                    continue   # beside its outline
                radius = wake.radius or max(float(np.abs(edge) @ half) / float(np.linalg.norm(edge))
                                            for edge in (np.asarray(water.edge_u), np.asarray(water.edge_v)))
                drops[water.entity].append((x, y, max(radius / min(_spacing(water)), MIN_DROP_TEXELS),
                                            wake.strength * moved))
        self._crossed = crossed
        for entity, splash in self.world.query_one(Splash):
            self.world.remove_component(entity, Splash)   # (one frame's: taken in now, or nowhere)
            transform = self.world.try_get(entity, Transform)
            if transform is None:
                self._say_once("splash", entity, ComponentWarning(
                    f"Splash on entity {entity}: it has no Transform to say where it lands, so it makes no ripples "
                    "(it was taken off)"))
                continue
            place = np.array([float(transform.world[3][r]) for r in range(3)])
            landed = self._landing(waters, place)
            if landed is not None:
                water, x, y = landed
                drops[water.entity].append((x, y, max(splash.radius / min(_spacing(water)), MIN_DROP_TEXELS),
                                            splash.depth))
        owed_now: dict[int, float] = {}   # (the waters raining now only: a deleted one's fraction goes)
        for water, ripples in waters:
            if ripples.rain <= 0.0 or ripples.drop_depth <= 0.0:
                continue
            area = float(np.linalg.norm(np.cross(water.edge_u, water.edge_v)))
            owed = self._owed.get(water.entity, 0.0) + ripples.rain * area * dt
            count = int(owed)
            owed_now[water.entity] = owed - count
            if count:
                nu, nv = water.texels
                places = self._rain.random((count, 2)) * (nu, nv)
                radius = max(ripples.drop_radius / min(_spacing(water)), MIN_DROP_TEXELS)
                drops[water.entity] += [(float(x), float(y), radius, ripples.drop_depth) for x, y in places]
        self._owed = owed_now
        return drops

    def _landing(self, waters: list[tuple[RippleWater, Ripples]], place: np.ndarray
                 ) -> tuple[RippleWater, float, float] | None:
        """Where a point lands on the nearest rippling water straight across its plane (the
        water and the texel there), or None where no outline holds it."""
        best = None
        for water, _ in waters:
            normal = np.asarray(water.plane[:3])
            height = float(normal @ place + water.plane[3])
            x, y = self.renderer.ripples.to_texels(water.entity, place - height * normal)[0]
            nu, nv = water.texels
            if 0.0 <= x <= nu and 0.0 <= y <= nv and (best is None or abs(height) < best[0]):
                best = (abs(height), water, x, y)
        return None if best is None else best[1:]

    def _placed(self, entity: int, transform: Transform) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Where a Wake's entity stands: its mesh's box as placed (the world box's centre and
        half sides, and the mesh box's 8 corners in the world, (8, 3)), or its Transform's
        point with no box (half sides 0, the point its one corner)."""
        ref = self.world.try_get(entity, MeshRef)
        matrix = transform.world
        if ref is None or ref.mesh is None:
            point = np.array([float(matrix[3][r]) for r in range(3)])
            return point, np.zeros(3), point[None, :]
        corners = world_corners(ref.mesh, matrix)[:, :3]
        low, high = corners.min(axis=0), corners.max(axis=0)
        return (low + high) * 0.5, (high - low) * 0.5, corners

    def _say_once(self, what: str, entity: int, warning: Warning) -> None:
        if (what, entity) not in self._said:
            self._note_said(what, entity)
            warnings.warn(warning, stacklevel=4)

    def _note_said(self, what: str, entity: int) -> None:
        """Remember ``what`` said of ``entity``, letting go of what was said of entities
        deleted since (by a stage after this one, after ``World.deleted`` was read): the set
        holds what was said of live entities, plus this."""
        world = self.world
        self._said = {key for key in self._said if world.exists(key[1])}
        self._said.add((what, entity))

    def _forget_deleted(self) -> None:
        """What was said once of an entity is let go when it is deleted, so a long run that
        makes and deletes waters, wakes and splashes holds no more (ids are never given twice
        in a world: a new entity is said to again)."""
        deleted = self.world.deleted()
        if deleted and self._said:
            self._said = {key for key in self._said if key[1] not in deleted}


def _spacing(water: RippleWater) -> tuple[float, float]:
    """Metres between a water's texels along its outline's two edges."""
    return (float(np.linalg.norm(water.edge_u)) / water.texels[0],
            float(np.linalg.norm(water.edge_v)) / water.texels[1])
