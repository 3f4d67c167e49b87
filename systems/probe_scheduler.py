"""The probes scheduler: which reflection probes there are, and which faces of each to capture
this frame, and why.  GL-free: it holds no renderer and draws nothing.  Each frame it
publishes ``ProbeSchedule`` (``engine/rules/probe_schedule.py``: per probe the faces due and
the reasons) and keeps ``ProbeStates``; the captures (``systems/probe_system.py``) draw what
it publishes.

Every ``ReflectionProbe`` (at its entity's position) and every automatic probe (a
cube-reflective mesh that is not flat, at its bounding box's centre; ``engine/rules/probe_rules.py``)
has a ``ProbeState``.  What is due each frame, per probe:

  - the first frame it exists: all six faces ("first capture");
  - all six when the probe moved ("probe moved"), its settings changed ("settings changed")
    or ``ReflectionProbe.request()`` was called ("requested": the component counts its
    requests and the scheduler compares the count with the one it last saw);
  - ``on_change`` (the default): only the faces whose frustum holds the old or the new
    bounds of an entity that was added, removed or moved (the transform stage's frame sets)
    or whose look changed (``probe_rules.LookChanges``, and the screens whose ``Monitor``
    pictures were drawn since the last update: ``PicturesDrawn``), within the probe's range, either
    directly ("moved: entity 12") or as seen in a mirror or through a portal (the boxes'
    images, up to the probe's ``depth``: ``probe_rules.images_through_surfaces``; "moved:
    entity 12, seen in mirror 5"); all six when the sun or the sky changed
    ("DirectionalLight changed": a sun turning or fading a little, as through a day, only
    once it is a degree or 2% from where it last relit them, or stands still again:
    ``_suns_relight``), the clouds came, went, changed or drifted an eighth of their finest
    detail since they last relit them ("CloudLayer changed": ``clouds.shadows_served``,
    counted by the prepare stage's ``CloudChanges``) or a point light whose range reaches what the probe sees
    changed, came, went or moved, its own Transform or a parent's ("light 7 moved"), or joined
    or left the lights kept or those with shadow cubes (``KeptLights``: past the Lights block's
    places or the cubes the camera chooses, so it may leave as the camera walks away: "light 7 went");
  - ``every_frame``: all six; ``every_n``: all six every n frames; ``once``: nothing more;
    ``scripted``: all six after a request; but a ``once`` or ``scripted`` probe's faces that
    may see a screen whose ``Monitor`` picture was first drawn after its capture (it showed
    the screen black: ``PicturesDrawn.first``) are asked for again ("first picture: entity N");
  - a face due for ``every_frame`` or ``every_n`` alone that no change has reached since it
    was last drawn is published ``unchanged`` (``ProbeDue.unchanged``: the captures keep it
    as it is where nothing they draw with changed either, ``ProbeCaptures.capture``).  What
    reaches a face here is wider than what ``on_change`` asks for: the boxes that changed
    in its frustum, the shadows of every box that changed (one hidden from probes or the
    probe's own object casts too), and every face when a light in reach or the sun or sky
    changed, a point light came or went anywhere (the lights' slots and limits shift), or
    the level has mirrors or portals (``_mark_changes``); a face changes reached is published
    with the rectangle of it they reached since it was drawn (``ProbeDue.regions``: the
    captures draw that part alone where nothing they draw with changed); an ``on_change``
    probe's faces asked for by changes alone get theirs by the same rule (any other reason,
    a request, the probe moving, the view budget, changes a face everywhere: ``ProbeState.ask``);
  - with ``time_slicing="one_face_per_frame"`` the waiting faces go one a frame (after a
    first capture of all six, so an object never shows a cube map with faces missing).
A face leaves the waiting set (``ProbeState.pending``) when it is published as due.
"""
from __future__ import annotations

import math
import weakref

import numpy as np
from pyglm import glm

from components import DirectionalLight, MeshRef, PointLight, ReflectionProbe, Transform, Visibility
from components.limits import NO_SHADOW_BIT, VIEW_PROBE
from components.tracking import warn_component
from components.visibility import SEEN_BY_EVERY_VIEW, visibility_code
from engine.assets.mesh import Mesh
from engine.core.budget import spending_order
from engine.core.world import World
from engine.resources import CloudChanges, PicturesDrawn, RenderStats, Surfaces, ViewBudget
from engine.rules.frame_rules import active_camera_parts
from engine.rules.light_rules import (
    SAME_SUN_DEGREES,
    SAME_SUN_TINT,
    KeptLights,
    shadow_texel_tangent,
    sun_relights,
    sun_states,
)
from engine.rules.probe_rules import (
    ALL_FACES,
    LIGHTING_KINDS,
    LookChanges,
    box_corners,
    box_pair_face_hits,
    change_rects,
    face_hits,
    faces_touched,
    has_own_probe,
    images_through_surfaces,
    lights_reaching,
    pose_bounds,
    probe_samplers,
    world_bounds,
)
from engine.rules.probe_schedule import (
    CAPTURED_ONCE,
    MAX_NAMED,
    PERIODIC,
    WATCHING,
    ProbeDue,
    ProbeSchedule,
    ProbeState,
    ProbeStates,
)
from engine.rules.shadow_rules import (
    SHADOW_MARGIN,
    SHADOW_MARGIN_SHARE,
    ShadowCasters,
    boxes_in_reach,
    directional_shadow_hull,
    point_shadow_bounds,
)
from engine.rules.visibility_rules import ShadowCasting, casts_shadow, drawn_in, entity_code


class ChangedBoxes:
    """The world boxes of this frame's changes, as rows: ``lo``, ``hi`` (world AABB corners),
    ``entity`` and ``what`` (how it changed) of each; an entity has a row where it was and
    one where it is.  ``code``: for a row of an entity that only moved (its look unchanged), where it is drawn
    (``visibility_rules.entity_code`` of its ``Visibility``: a probe whose captures do not draw
    it cannot see it move), with ``NO_SHADOW_BIT`` where it casts no shadow
    (``ShadowCasting``: no shadow of it moved; glass moves the share of a sun's, a lamp's or a
    mirror's light it lets through, so casts while one casts); every other row counts as seen by all
    and casting (``SEEN_BY_EVERY_VIEW``: a look change may be the Visibility itself or
    whether it casts, and what was seen before must go)."""

    def __init__(self, rows: list[tuple[int, str, np.ndarray, np.ndarray, int]]) -> None:
        if not rows:  # a still frame (or only the camera moved): no list made into arrays
            self.entity, self.code = np.zeros(0, np.int64), np.zeros(0, np.int64)
            self.casting = np.zeros(0, bool)
            self.what, self.lo, self.hi = [], np.zeros((0, 3)), np.zeros((0, 3))
            self.entities, self.codes = set(), set()
            return
        rows.sort(key=lambda row: row[0])
        self.entity = np.array([row[0] for row in rows], np.int64)
        self.what = [row[1] for row in rows]
        self.lo = np.array([row[2] for row in rows], np.float64).reshape(-1, 3)
        self.hi = np.array([row[3] for row in rows], np.float64).reshape(-1, 3)
        self.code = np.array([row[4] for row in rows], np.int64)
        self.casting = casts_shadow(self.code)  # the rows whose shadows moved (a row may cast none)
        self.entities = {row[0] for row in rows}
        self.codes = {row[4] for row in rows}  # one code: every row seen by a probe, or none

    def seen_by(self, probe: ReflectionProbe) -> np.ndarray:
        """The rows a probe with these settings may see: those its faces' views (kind probe,
        the probe's layers) draw by the visibility rule."""
        return drawn_in(self.code, visibility_code(VIEW_PROBE, probe.layer_mask))


class ProbeScheduler:
    """Keeps ``ProbeStates`` (a world resource) and publishes ``ProbeSchedule`` each
    ``update``; the module's docstring says what is due when."""

    def __init__(self, world: World) -> None:
        self.world = world
        self.probes = world.resources[ProbeStates] = ProbeStates()
        self._bounds: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # entity -> last world box
        self._lights: dict[int, tuple[np.ndarray, float]] = {}  # point light -> (position, range) last seen
        # The point lights kept (the Lights block's) and those with a shadow cube, last seen (_kept_changes).
        self._kept: tuple[frozenset[int], frozenset[int]] = (frozenset(), frozenset())
        self._looks = LookChanges()
        self._lights_came_or_went = False  # this frame: a point light came or went (periodic probes' changes)
        self._reach: tuple[ShadowCasters | None, float] = (None, 0.0)  # _filter_reach's, for these casters
        self._grown: tuple[tuple | None, float] = (None, 0.0)  # _filter_reach's level box (bytes) -> its grown diagonal
        self._mesh_boxes: dict[int, tuple] = {}  # id(mesh) -> (a weak ref to it, its box's corners): _mesh_corners
        self._watching = False  # the boxes and lights are kept: a watching probe was there last frame
        self._suns: tuple = ()  # the directional lights as the probes were last relit by them (sun_states)
        self._suns_behind = False  # a sun turned a little since: the probes relight once it stands still
        self._clouds = 0  # CloudChanges as the probes were last relit by it
        self._pictures = 0  # PicturesDrawn.count when last looked at

    def update(self) -> ProbeSchedule:
        """This frame's schedule, published as the world's ``ProbeSchedule``."""
        world = self.world
        had_probes = bool(self.probes)
        looks = self._looks.entities(world)  # asked every frame: it follows what each object samples
        pictures = world.resources.get(PicturesDrawn)
        first_pictures: frozenset[int] = frozenset()
        if pictures is not None and pictures.count != self._pictures:
            # Screens whose pictures were drawn after the last update (the monitor stage is later in the frame).
            self._pictures = pictures.count
            looks |= pictures.screens
            first_pictures = pictures.first
        schedule = world.resources[ProbeSchedule] = ProbeSchedule(gone=self._refresh_probes())
        if not self.probes:
            self._bounds.clear()  # nothing to keep boxes for (a world without probes pays nothing)
            self._lights.clear()
            return schedule
        if any(state.settings.refresh in WATCHING for state in self.probes.values()):
            # Where every drawable was when the first probe came (its first capture saw them
            # there), or when the first on_change (or periodic) probe did; after that, only
            # what changed is looked at.
            primed = had_probes and self._watching
            boxes = self._changed_boxes(looks) if primed else self._all_boxes()
            lights = self._changed_lights() if primed else self._all_lights()
            self._lights_came_or_went = any(reason.endswith((" came", " went")) for reason, _, _ in lights)
            everything = [f"{kind.__name__} changed" for kind in LIGHTING_KINDS
                          if (self._suns_relight() if kind is DirectionalLight else world.changed(kind))]
            clouds = world.resources.get(CloudChanges, CloudChanges()).count
            if clouds != self._clouds:   # (came, went, changed, or drifted past what a capture serves)
                self._clouds = clouds
                everything.append("CloudLayer changed")
            self._watching = True
        else:
            # No probe refreshes on change or periodically: what moved matters to none (a
            # probe that turns on_change recaptures every face for its new settings, and the
            # boxes are taken afresh then).
            self._bounds.clear()
            self._lights.clear()
            self._suns, self._suns_behind = (), False
            self._watching = False
            boxes, lights, everything = ChangedBoxes([]), [], []
        surfaces = world.resources.get(Surfaces)
        due = []
        for state in self.probes.values():
            reach = lights_reaching(state.position, state.settings.far, [(p, r) for _, p, r in lights])
            relit = everything + sorted({lights[index][0] for index in reach})
            self._schedule(state, boxes, relit, surfaces)
        if first_pictures:
            self._ask_for_first_pictures(first_pictures, surfaces)
        for state in self.probes.values():
            faces = self._due_faces(state)
            if faces:
                due.append((state, faces))
        for state, faces in self._within_budget(due):
            reasons = state.take(faces)
            unchanged, regions = frozenset(), {}
            if state.captures and state.settings.refresh in PERIODIC:
                # Due only because the period came round, and reached by no change since drawn
                # (unchanged), or by changes within a part of the face alone (regions).
                periodic = faces - frozenset().union(
                    *(waiting for reason, waiting in reasons.items() if reason not in PERIODIC))
                unchanged = periodic - state.changed
                if state.regions:
                    regions = {face: state.regions[face] for face in periodic if face in state.regions}
            elif state.captures and state.settings.refresh == "on_change" and state.regions:
                # Every reason a face waits for is a change whose part the regions follow (any
                # other made it changed everywhere: ProbeState.ask).
                regions = {face: state.regions[face] for face in faces if face in state.regions}
            schedule.due[state.owner] = ProbeDue(state.owner, faces, reasons, first=not state.captures,
                                                 unchanged=unchanged, regions=regions)
        return schedule

    def _suns_relight(self) -> bool:
        """Whether the directional lights relight every probe this frame: one came, went or
        changed past what a capture may lag it (``light_rules.sun_relights``: a degree of turn,
        2% of colour; any change to its shadows or bounces), or, after a turn within that, it
        stands still again (the captures made exact).  A sun turning a tenth of a degree a
        frame (a day) relights the probes every tenth frame, not every frame: the sky pass and
        the direct light follow it every frame, the captures a degree behind at most."""
        world = self.world
        changed = world.changed(DirectionalLight)
        if not changed and not self._suns_behind:
            return False
        now = sun_states(world)
        if changed:
            relight = sun_relights(self._suns, now)
        else:  # standing still since a small change: exact now, unless that was a rounding
            relight = sun_relights(self._suns, now, SAME_SUN_DEGREES, SAME_SUN_TINT)
            self._suns_behind = False
        if relight:
            self._suns, self._suns_behind = now, False
        elif changed:
            self._suns_behind = now != self._suns
        return relight

    def _within_budget(self, due: list[tuple[ProbeState, frozenset[int]]]) -> list[tuple[ProbeState, frozenset[int]]]:
        """The due captures in the order the budget spends on them (``spending_order``: first
        captures, then a probe's own priority plus the frames it has waited, then nearest the camera) and,
        under ``ViewBudget.probe_ms``, those that fit by ``ProbeStates.face_ms`` a face; the
        first always goes, and a probe gains a priority a frame it waits, so none starves.
        What does not fit stays pending, counted in ``RenderStats.probe_faces_deferred``."""
        if len(due) > 1:  # (one alone is in order: no camera or distance asked for)
            eye = _camera_position(self.world)
            order = spending_order([state.settings.priority + state.waiting for state, _ in due],
                                   [-float(np.linalg.norm(np.asarray(state.position) - eye)) for state, _ in due],
                                   first=[not state.captures for state, _ in due])
            due = [due[i] for i in order.tolist()]
        budget = ViewBudget.of(self.world.resources)
        face_ms = self.probes.face_ms
        if budget is None or budget.probe_ms is None or face_ms is None:
            return due
        kept, spent = [], 0.0
        for state, faces in due:
            cost = face_ms * len(faces)
            if kept and spent + cost > budget.probe_ms:
                state.waiting += 1
                stats = self.world.resources.get(RenderStats)
                if stats is not None:
                    stats.probe_faces_deferred += len(faces)
                continue
            state.waiting = 0
            kept.append((state, faces))
            spent += cost
        return kept

    @staticmethod
    def _due_faces(state: ProbeState) -> frozenset[int]:
        faces = state.pending
        if state.settings.time_slicing == "one_face_per_frame" and faces and state.captures:
            faces = {min(faces)}  # the first capture is whole: nothing is shown half-made
        return frozenset(faces)

    # --- which probes -------------------------------------------------------------------------
    def _refresh_probes(self) -> list[int]:
        """Probes found, moved and changed; returns the owners of those gone."""
        world = self.world
        found: dict[int, tuple[ReflectionProbe | None, glm.vec3, bool]] = {}
        for owner, (probe, transform) in world.query(ReflectionProbe, Transform):
            found[owner] = (probe, glm.vec3(transform.world[3]), False)
        # Automatic probes: only what samples a probe can have one (a few, not every
        # drawable: a 10,000-entity world must not pay for them).
        for owner in probe_samplers(world, plain=False):  # (a plain mesh has none of its own)
            if has_own_probe(world, owner) and world.has(owner, Transform):
                mesh_ref, transform = world.get(owner, MeshRef), world.get(owner, Transform)
                lo, hi = world_bounds(mesh_ref.mesh, transform.world, pose_bounds(world, owner, mesh_ref.mesh))
                found[owner] = (None, glm.vec3(*((lo + hi) / 2.0)), True)
        gone = [owner for owner in self.probes if owner not in found]
        for owner in gone:
            del self.probes[owner]
        changed = world.changed(ReflectionProbe)
        for owner, (probe, position, automatic) in found.items():
            state = self.probes.get(owner)
            if probe is not None and (state is None or owner in changed):
                _warn_blend_without_box(owner, probe)
            if state is None or state.automatic != automatic:
                self.probes[owner] = ProbeState(owner, probe or ReflectionProbe(), automatic, position,
                                                requests_seen=probe.requests if probe is not None else 0)
                continue
            if probe is not None:
                if probe is not state.settings:  # a new component: its requests count from 0
                    state.settings, state.requests_seen = probe, 0
                if owner in changed:
                    if probe.requests != state.requests_seen:
                        state.requests_seen = probe.requests
                        state.ask(ALL_FACES, "requested")
                    else:
                        state.ask(ALL_FACES, "settings changed")
            if position != state.position:
                state.position = position
                state.ask(ALL_FACES, "probe moved")
        return gone

    # --- what changed -------------------------------------------------------------------------
    def _changed_boxes(self, looks: set[int]) -> ChangedBoxes:
        """The old and new world boxes of every entity that moved, came, went or changed its look."""
        world = self.world
        frame = world.frame
        removed = frame.removed | world.deleted()
        rows, placed = [], []
        casting: ShadowCasting | None = None
        for entity in frame.moved | frame.added | removed | looks:
            what = ("removed" if entity in removed else "added" if entity in frame.added
                    else "moved" if entity in frame.moved else "look changed")
            mesh_ref = world.try_get(entity, MeshRef) if world.exists(entity) else None
            code = SEEN_BY_EVERY_VIEW
            if what == "moved" and entity not in looks:  # a move with a look change: its old look was seen
                visibility = world.try_get(entity, Visibility)
                if visibility is not None:
                    code = entity_code(visibility)
                if casting is None:  # glass dims a sun's, a lamp's or a mirror's light: its move moves that share
                    lights = world.resources.get(ShadowCasters)
                    casting = ShadowCasting(world, glass_casts=lights is not None
                                            and bool(lights.directional or lights.points or lights.virtual))
                if mesh_ref is not None and not casting.casts(entity, mesh_ref, visibility):
                    code |= NO_SHADOW_BIT  # as it was: its shadow moved nowhere (ChangedBoxes.casting)
            old = self._bounds.pop(entity, None)
            if old is not None:
                rows.append((entity, what, *old, code))
            transform = world.try_get(entity, Transform) if mesh_ref is not None else None
            if transform is not None:
                placed.append((entity, what, code, mesh_ref.mesh, transform.world))
        if placed:
            # Where each is now, all in a few array operations (``world_bounds``' box, each
            # mesh's own box carried by its model matrix).
            corners = np.array([self._mesh_corners(mesh, entity)
                                for entity, _, _, mesh, _ in placed])  # (entity, 8, xyzw)
            # glm's buffer is the matrix's rows; a row vector takes its columns (its to_list).
            models = np.ascontiguousarray(np.array([model for _, _, _, _, model in placed], np.float64)
                                          .transpose(0, 2, 1))
            carried = (corners @ models)[..., :3]
            lo, hi = carried.min(axis=1), carried.max(axis=1)
            for i, (entity, what, code, _, _) in enumerate(placed):
                new = self._bounds[entity] = (lo[i], hi[i])
                rows.append((entity, what, *new, code))
        return ChangedBoxes(rows)

    def _mesh_corners(self, mesh: Mesh, entity: int = 0) -> np.ndarray:
        """The corners of ``mesh.bounds`` (8, xyzw: w = 1, as ``box_corners`` orders them), kept
        by mesh (its vertices are read once, as the renderer uploads them once); ``entity``'s
        pose's box where a Skin or Morph poses it (``pose_bounds``, worked out each time)."""
        posed = pose_bounds(self.world, entity, mesh) if entity and (mesh.skinned or mesh.morph_count) else None
        if posed is not None:
            corners = box_corners(np.asarray(posed[0], np.float64)[None], np.asarray(posed[1], np.float64)[None])[0]
            return np.concatenate([corners, np.ones((8, 1))], axis=1)
        kept = self._mesh_boxes.get(id(mesh))
        if kept is None or kept[0]() is not mesh:
            if len(self._mesh_boxes) > 4096:
                self._mesh_boxes.clear()
            lo, hi = mesh.bounds
            corners = box_corners(np.asarray(lo, np.float64)[None], np.asarray(hi, np.float64)[None])[0]
            # (weakly: a deleted thing's mesh is let go; a new mesh at its id finds the ref dead)
            kept = self._mesh_boxes[id(mesh)] = (weakref.ref(mesh), np.concatenate([corners, np.ones((8, 1))], axis=1))
        return kept[1]

    def _all_boxes(self) -> ChangedBoxes:
        world = self.world
        self._bounds = {entity: world_bounds(mesh_ref.mesh, transform.world, pose_bounds(world, entity, mesh_ref.mesh))
                        for entity, (mesh_ref, transform) in world.query(MeshRef, Transform)}
        return ChangedBoxes([])  # every probe is new: a first capture takes every face anyway

    def _changed_lights(self) -> list[tuple[str, np.ndarray, float]]:
        """(reason, position, range) where each point light that changed, came, went or moved
        this frame was and is."""
        world = self.world
        frame = world.frame
        joined, left, recast = self._kept_changes()
        entities = (frame.moved | frame.added | frame.removed | world.deleted() | world.changed(PointLight)
                    | world.changed(Transform) | joined | left | recast)
        # Only an entity with a point light now, or one when last seen, has a sphere to compare.
        lights = self._lights.keys() | {entity for entity, _ in world.query_one(PointLight)}
        rows = []
        for entity in entities & lights:
            old = self._lights.pop(entity, None)
            new = self._light_sphere(entity)
            if old is None and new is None:
                continue
            what = "came" if old is None or entity in joined else "went" if new is None or entity in left \
                else "moved" if entity in frame.moved else "changed"
            for sphere in (old, new):
                if sphere is not None:
                    rows.append((f"light {entity} {what}", *sphere))
            if new is not None:
                self._lights[entity] = new
        return rows

    def _kept_changes(self) -> tuple[set[int], set[int], set[int]]:
        """The point lights that joined or left the ones kept (``KeptLights``: where there are
        more than the Lights block's places, chosen by the camera and the views' eyes, so a
        light may leave as the camera walks away, nothing of its own changed) and those that
        gained or lost a shadow cube, since the last look: a face they light draws otherwise
        (they count as come, gone or changed)."""
        kept = self.world.resources.get(KeptLights)
        now = (frozenset(), frozenset()) if kept is None else \
            (frozenset(kept.point) - {None}, frozenset(kept.point_shadows) - {None})
        before, self._kept = self._kept, now
        return set(now[0] - before[0]), set(before[0] - now[0]), set(now[1] ^ before[1])

    def _all_lights(self) -> list[tuple[str, np.ndarray, float]]:
        self._kept_changes()  # (as the first capture draws them)
        self._lights = {entity: sphere for entity, _ in self.world.query_one(PointLight)
                        if (sphere := self._light_sphere(entity)) is not None}
        return []  # a first capture takes every face anyway

    def _light_sphere(self, entity: int) -> tuple[np.ndarray, float] | None:
        world = self.world
        if not world.exists(entity):
            return None
        light, transform = world.try_get(entity, PointLight), world.try_get(entity, Transform)
        if light is None or transform is None:
            return None
        return np.array(transform.world[3].xyz, np.float64), float(light.range)

    # --- what is due --------------------------------------------------------------------------
    def _schedule(self, state: ProbeState, boxes: ChangedBoxes, relit: list[str], surfaces: Surfaces | None) -> None:
        settings = state.settings
        state.frames += 1
        mode = settings.refresh
        if mode in PERIODIC:
            self._mark_changes(state, boxes, relit, surfaces)
        elif mode == "on_change" and state.captures:
            # Where in its faces the changes reach, for the faces drawn in part (the same
            # rule as a periodic probe's, wider than the faces asked for below); where no
            # part can be drawn, every face counts as changed everywhere (nothing to work out).
            if state.parts:
                self._mark_changes(state, boxes, relit, surfaces)
            else:
                state.changed |= ALL_FACES
                state.regions.clear()
        if mode == "every_frame":
            state.ask(ALL_FACES, "every_frame")
        elif mode == "every_n" and state.frames % settings.every_n == 0:
            state.ask(ALL_FACES, "every_n")
        elif mode == "on_change":
            if relit:
                for reason in relit:
                    state.ask(ALL_FACES, reason)
                return
            if state.pending == ALL_FACES or not len(boxes.entity):
                return  # every face waits already, or nothing changed
            self._ask_seeing(state, boxes, surfaces)
            casters = self.world.resources.get(ShadowCasters)
            if casters is not None and (casters.directional or casters.points or casters.virtual):
                # Where the shadows of what casts fall: a face showing that place changes even
                # when the thing itself is outside it, or hidden from probes (it casts in
                # every view), or the probe's own object.
                cast = np.flatnonzero(boxes.casting)
                shadow_lo, shadow_hi, of = casters.shadow_bounds(boxes.lo[cast], boxes.hi[cast])
                of = cast[of]
                if len(of):
                    _ask_named(state, face_hits(state.position, settings.far, shadow_lo, shadow_hi),
                               boxes.entity[of],
                               lambda row: f"shadow of entity {boxes.entity[of[row]]} ({boxes.what[of[row]]})")

    def _ask_seeing(self, state: ProbeState, boxes: ChangedBoxes, surfaces: Surfaces | None) -> None:
        """Ask for the faces of ``state``'s probe that may see a row of ``boxes``, directly or
        in a mirror or through a portal (to the probe's ``depth``), each for the row's reason;
        not the probe's own object (in none of its faces) or what its captures hide."""
        settings = state.settings
        own = (boxes.entity != state.owner) & boxes.seen_by(settings)
        lo, hi, entity = boxes.lo[own], boxes.hi[own], boxes.entity[own]
        what = [w for w, keep in zip(boxes.what, own, strict=True) if keep]
        if not len(entity):
            return
        _ask_named(state, face_hits(state.position, settings.far, lo, hi), entity,
                   lambda row: f"{what[row]}: entity {entity[row]}")
        if settings.depth > 0 and surfaces is not None and (surfaces.mirrors or surfaces.portals):
            self._through_surfaces(state, lo, hi, entity, what, surfaces)

    def _ask_for_first_pictures(self, screens: frozenset[int], surfaces: Surfaces | None) -> None:
        """A ``once`` or ``scripted`` probe captured before a screen's first picture was drawn
        (the monitor stage comes after the captures, and a ``when_seen`` screen is drawn only
        once something sees it) shows the screen black, and would for good: the faces that
        may see ``screens`` (``PicturesDrawn.first``) are asked for again, for "first
        picture: entity N".  An ``on_change`` probe asks for them as for any picture drawn,
        a periodic one at its next period."""
        probes = [state for state in self.probes.values() if state.settings.refresh in CAPTURED_ONCE and state.captures]
        if not probes:
            return
        world = self.world
        rows = []
        for entity in sorted(screens):
            mesh_ref = world.try_get(entity, MeshRef) if world.exists(entity) else None
            transform = world.try_get(entity, Transform) if mesh_ref is not None else None
            if transform is None:
                continue
            visibility = world.try_get(entity, Visibility)
            code = SEEN_BY_EVERY_VIEW if visibility is None else entity_code(visibility)
            lo, hi = world_bounds(mesh_ref.mesh, transform.world, pose_bounds(world, entity, mesh_ref.mesh))
            rows.append((entity, "first picture", lo, hi, code))
        boxes = ChangedBoxes(rows)
        for state in probes:
            self._ask_seeing(state, boxes, surfaces)

    def _mark_changes(self, state: ProbeState, boxes: ChangedBoxes, relit: list[str],
                      surfaces: Surfaces | None) -> None:
        """A periodic probe's faces that this frame's changes reach join ``state.changed``
        (the faces whose picture may differ from the one drawn last; the rest are published
        ``unchanged`` when due).  Conservative: every face when anything relights what it
        sees (a light in reach, the sun, the sky: ``relit``), a point light came or went
        anywhere (the Lights block's order and limits and the shadow slots shift), or the
        level has mirrors or portals (their pictures follow the whole level); else the
        faces whose frustum holds a changed box the probe draws, and the faces where the
        shadow of any changed box that casts may fall (drawn by the probe or not: a thing
        hidden from probes, or the probe's own object, casts in every view; one that casts
        none, ``ChangedBoxes.casting``, moved no shadow).

        Where a shadow may fall: every changed box grown by how far a filtered shadow edge
        reaches (``_filter_reach``), then swept along each sun to the level's walls, where a
        face must meet both the sweep's hull and the part of the box bounding it inside the
        level (``directional_shadow_bounds``: nothing outside the level receives a shadow),
        each holding every shadowed point; and within each point light's range
        (``point_shadow_bounds``).  All the hulls through one ``box_pair_face_hits``
        (``hull_face_hits``' booleans, from each hull's two boxes without their corners).

        Where in a face: each row's rectangle in each face it reaches (a box's, a sun hull's
        within its clipped box's: ``face_rects``, ``hull_rects``), their union joining the
        face's ``state.regions`` (grown over the frames until it is drawn); a face changed
        everywhere (relit, or reached so before) has none, and is drawn whole."""
        if state.changed >= ALL_FACES and not state.regions:
            return
        if relit or self._lights_came_or_went or (surfaces is not None and (surfaces.mirrors or surfaces.portals)):
            state.changed |= ALL_FACES
            state.regions.clear()
            return
        if not len(boxes.entity):
            return
        settings = state.settings
        if state.owner in boxes.entities or len(boxes.codes) > 1:
            seen = (boxes.entity != state.owner) & boxes.seen_by(settings)
            near_lo, near_hi = boxes.lo[seen], boxes.hi[seen]
        elif drawn_in(next(iter(boxes.codes)), visibility_code(VIEW_PROBE, settings.layer_mask)):
            near_lo, near_hi = boxes.lo, boxes.hi  # one code, which the probe draws: every row
        else:
            near_lo, near_hi = boxes.lo[:0], boxes.hi[:0]
        # Every hull as the hull of two boxes (the same box twice: the box alone), all through
        # one ``box_pair_face_hits``: the boxes seen, then each sun's hull and clipped box,
        # then each point light's boxes.
        box_lo, box_hi, far_lo, far_hi = [near_lo], [near_hi], [near_lo], [near_hi]
        suns = 0
        casters = self.world.resources.get(ShadowCasters)
        # The rows whose shadows moved (a row may cast none: ChangedBoxes.casting); ``count``
        # of them, each sun's hull and clipped box rows in their order.
        casting = boxes.casting
        count = int(np.count_nonzero(casting))
        if count and casters is not None and (casters.directional or casters.points):
            reach = self._filter_reach(casters)
            lo, hi = (boxes.lo - reach, boxes.hi + reach) if count == len(casting) else \
                (boxes.lo[casting] - reach, boxes.hi[casting] + reach)
            if casters.level is not None:
                for direction in casters.directional:
                    moved_lo, moved_hi, bound_lo, bound_hi = directional_shadow_hull(lo, hi, direction, *casters.level)
                    box_lo += [lo, bound_lo]
                    box_hi += [hi, bound_hi]
                    far_lo += [moved_lo, bound_lo]
                    far_hi += [moved_hi, bound_hi]
                    suns += 1
            for position, light_range in casters.points:
                near = boxes_in_reach(lo, hi, np.array(position), light_range)
                if near.any():
                    shadow_lo, shadow_hi = point_shadow_bounds(lo[near], hi[near], np.array(position), light_range)
                    box_lo.append(shadow_lo)
                    box_hi.append(shadow_hi)
                    far_lo.append(shadow_lo)
                    far_hi.append(shadow_hi)
        rows = len(near_lo)
        if len(box_lo) == 1:
            hits = box_pair_face_hits(state.position, settings.far, near_lo, near_hi, near_lo, near_hi)
        else:
            hits = box_pair_face_hits(state.position, settings.far, np.concatenate(box_lo), np.concatenate(box_hi),
                                      np.concatenate(far_lo), np.concatenate(far_hi))
        # Where in each face: a row's box, or a sun's hull within its clipped box (both hold
        # every shadowed point: the rectangles of each, intersected), where the row reaches
        # the face (probe_rules.change_rects).
        region_hits, plain_lo, plain_hi = [hits[:rows]], [near_lo], [near_hi]
        if len(hits) > rows + 2 * suns * count:  # the point lights' boxes
            region_hits.append(hits[rows + 2 * suns * count:])
            plain_lo += box_lo[1 + 2 * suns:]
            plain_hi += box_hi[1 + 2 * suns:]
        for sun in range(suns):
            region_hits.append(hits[rows + 2 * sun * count:][:count] & hits[rows + (2 * sun + 1) * count:][:count])
        region_hits = np.concatenate(region_hits) if len(region_hits) > 1 else region_hits[0]
        reached = region_hits.any(axis=0).tolist()
        if not any(reached):
            return
        if not state.parts:  # no part can be drawn at the next capture: no rectangles
            for face in range(6):
                if reached[face]:
                    state.changed.add(face)
                    state.regions.pop(face, None)
            return
        swept = None
        if suns:  # each sun's hulls (the grown boxes and the boxes moved) and clipped boxes
            hulls, bounds = slice(1, 1 + 2 * suns, 2), slice(2, 2 + 2 * suns, 2)
            swept = (np.concatenate(box_lo[hulls]), np.concatenate(box_hi[hulls]), np.concatenate(far_lo[hulls]),
                     np.concatenate(far_hi[hulls]), np.concatenate(box_lo[bounds]), np.concatenate(box_hi[bounds]))
        rects = change_rects(state.position, settings.near, np.concatenate(plain_lo), np.concatenate(plain_hi),
                             region_hits, swept).tolist()
        for face in range(6):
            if not reached[face] or (face in state.changed and face not in state.regions):
                continue  # not reached, or changed anywhere in it already
            rect, before = rects[face], state.regions.get(face)
            if before is not None:
                rect = [min(rect[0], before[0]), min(rect[1], before[1]), max(rect[2], before[2]),
                        max(rect[3], before[3])]
            state.regions[face] = tuple(rect)
            state.changed.add(face)

    def _filter_reach(self, casters: ShadowCasters) -> float:
        """How far (world units) past where a shadow falls its filtered edge can change a
        pixel: a lookup reads its map at most 1.5 texels off the surface (the normal offset,
        whatever the softness: the taps follow the receiver's plane) and ``softness / 2``
        texels plus a bilinear texel around that (``shaders/include/shadows.glsl``), at most
        ``2.5 + softness / 2`` texels; a
        directional texel is at most the grown level box's diagonal over the map's side
        (``shadow_rules.directional_fit``), a point light's at most its range times
        ``light_rules.shadow_texel_tangent`` (a cube face's ``2 / resolution``, a spot map's
        its half-width as much again).  The widest of the casting lights' (worked out once a frame: the shadows
        stage publishes new casters each frame)."""
        if self._reach[0] is casters:
            return self._reach[1]
        reach = 0.0
        if casters.directional and casters.level is not None:
            level = (casters.level[0].tobytes(), casters.level[1].tobytes())
            if self._grown[0] != level:  # the grown level's diagonal, kept until the level box changes
                diagonal = float(np.linalg.norm(casters.level[1] - casters.level[0]))
                margin = max(SHADOW_MARGIN, SHADOW_MARGIN_SHARE * diagonal)
                self._grown = (level, diagonal + 2.0 * math.sqrt(3.0) * margin)
            grown = self._grown[1]
            for _, light in self.world.query_one(DirectionalLight):
                if light.shadows:
                    reach = max(reach, grown / light.shadow_resolution * (2.5 + 0.5 * light.shadow_softness))
        if casters.points:
            for _, light in self.world.query_one(PointLight):
                if light.shadows:
                    reach = max(reach, shadow_texel_tangent(light) * light.range
                                * (2.5 + 0.5 * light.shadow_softness))
        self._reach = (casters, reach)
        return reach

    @staticmethod
    def _through_surfaces(state: ProbeState, lo: np.ndarray, hi: np.ndarray, entity: np.ndarray, what: list[str],
                          surfaces: Surfaces) -> None:
        """The faces that may see a change through a mirror or portal (a face's view tree
        draws what its mirrors show): where the changed boxes' images lie
        (``probe_rules.images_through_surfaces``), or, past the images' limit, every face
        that sees a surface."""
        settings = state.settings
        shown = [*surfaces.mirrors.values(), *surfaces.portals.values()]
        images = images_through_surfaces(state.position, lo, hi, shown, settings.depth, settings.far)
        if images is None:
            corners = np.concatenate([s.corners[:, :3] for s in shown])
            state.ask(faces_touched(state.position, settings.far, corners.min(axis=0), corners.max(axis=0)),
                      "changes seen in mirrors and portals (too many images to follow)")
            return
        image_lo, image_hi, of, via = images
        if not len(image_lo):
            return

        def label(row: int) -> str:
            surface = int(via[row])
            seen = f"in mirror {surface}" if surface in surfaces.mirrors else f"through portal {surface}"
            return f"{what[of[row]]}: entity {entity[of[row]]}, seen {seen}"

        _ask_named(state, face_hits(state.position, settings.far, image_lo, image_hi), entity[of] * (1 << 32) + via,
                   label)


def _ask_named(state: ProbeState, hits: np.ndarray, keys: np.ndarray, label) -> None:
    """Ask for the faces ``hits`` (row, face) holds, each row's for the reason ``label(row)``:
    rows of one change share a key (``keys``, per row) and a reason.  Past ``MAX_NAMED``
    keys, the rest together for one reason that counts them."""
    rows = np.flatnonzero(hits.any(axis=1))
    if not len(rows):
        return
    named = np.isin(keys[rows], np.unique(keys[rows])[:MAX_NAMED])
    for row in rows[named]:
        state.ask(np.flatnonzero(hits[row]).tolist(), label(int(row)), part=True)
    rest = rows[~named]
    if len(rest):
        state.ask(np.flatnonzero(hits[rest].any(axis=0)).tolist(), f"{len(np.unique(keys[rest]))} more changes",
                  part=True)


def _warn_blend_without_box(owner: int, probe: ReflectionProbe) -> None:
    """``blend_distance`` falls off inside the ``influence`` box: without one it does
    nothing (the probe serves only its own object), said when the probe comes or changes."""
    if probe.blend_distance > 0.0 and probe.influence is None:
        warn_component(f"ReflectionProbe on entity {owner}: blend_distance = {probe.blend_distance:g} does nothing "
                       "without an influence box (influence=(w, h, d): the box it serves and blends across)")


def _camera_position(world: World) -> np.ndarray:
    """Where the active camera is (the origin without one): probes nearer it go first."""
    parts = active_camera_parts(world)
    return np.zeros(3) if parts is None else np.array(parts[2].world[3].xyz, np.float64)
