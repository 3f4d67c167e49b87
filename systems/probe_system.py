"""Probes: capture the reflection probes that need it, before the main view samples them.

Every ``ReflectionProbe`` (at its entity's position) and every automatic probe (a
cube-reflective mesh that is not flat, at its bounding box's centre; ``engine/rules/probe_rules.py``)
has a ``ProbeState``.  What is captured each frame, per probe:

  - the first frame it exists: all six faces;
  - ``on_change`` (the default): only the faces whose frustum holds the old or the new
    bounds of an entity that was added, removed or moved (the transform stage's frame sets)
    or whose look changed (``probe_rules.LookChanges``), within the probe's range, either directly or as seen in a
    mirror or through a portal (the boxes' images, up to the probe's ``depth``;
    ``engine.rules.probe_rules.images_through_surfaces``); all six when the probe itself moved or
    its settings changed, the sun or the sky changed, or a point light whose range reaches
    what the probe sees changed, came, went or moved (its own Transform or a parent's);
  - ``every_frame``: all six; ``every_n``: all six every n frames; ``once``: nothing more;
    ``scripted``: all six after ``ReflectionProbe.request()``;
  - with ``time_slicing="one_face_per_frame"`` the waiting faces go one a frame (after a
    first capture of all six, so an object never shows a cube map with faces missing).

Two paths draw a capture: ``six_pass`` (each face a view through the scene pass, with a
view tree of the mirrors and portals it sees) and ``layered`` (all six faces in one pass, a
geometry shader choosing each triangle's faces; no view trees).  ``ProbeSystem.path``
``auto`` (the default) times both with ``finish()`` on the first full capture that either
could draw (each drawn once untimed first, so neither pays for building its programs, then
``AUTO_TIMED_CAPTURES`` times each, alternating, and the medians compared), keeps the
faster for the rest of the run and says which (``chosen_path``, ``timings``,
``RenderStats.probe_path``, a log line).  A capture of some faces only, or of a probe
whose faces see mirrors or portals, takes the six-pass path.

When a capture is drawn.  A probe's first capture is drawn in the probes stage, before the
main view samples it.  Every later capture (``on_change``, ``every_frame``, ...) is scheduled
there, from this frame's changes, but drawn in the "probes_after" stage, after the frame is
presented: the next frame samples it, so a reflection in a probe is one frame behind what
it reflects.  The work is the same; what changes is when: drawn before the main view, the
capture's CPU side (per face: binning and vertex work; the mip pass's waits for each level)
runs while the rasteriser has nothing else to do, and the main view waits for the mip
chain; drawn after present, the CPU side overlaps the main view's rasterisation
(measured on llvmpipe, the mirror benchmark's scene with a dynamic 128 probe: 1.0-1.2 ms of
a 16 ms frame; ``python -m benchmarks probes``).  ``ProbeSystem.recapture_after_present =
False`` draws them before the main view instead (no lag, for tests against a ray caster).

The probe's own object is never in its capture (each face view skips it).  Counters per
probe (``ProbeState.captures``: frames with a capture, ``faces_captured``) are the API;
``RenderStats.probe_captures`` and ``probe_faces`` count this frame's.
"""
from __future__ import annotations

import logging
import statistics
import time
from dataclasses import dataclass, field

import esper
import numpy as np
from pyglm import glm

from components import (
    DirectionalLight,
    MeshRef,
    PointLight,
    ReflectionProbe,
    Skybox,
    Transform,
)
from engine.core.world import World
from engine.render.probes import ALL_FACES, ProbeStates, face_view, faces_touched
from engine.render.renderer import Renderer
from engine.resources import Surfaces
from engine.rules.probe_rules import (
    LookChanges,
    has_own_probe,
    images_through_surfaces,
    lights_reach,
    probe_samplers,
    world_bounds,
)

PATHS = ("auto", "six_pass", "layered")
AUTO_TIMED_CAPTURES = 3  # timed captures of each path before "auto" chooses (medians compared)
LOG = logging.getLogger("speculum")
LIGHTING_KINDS = (DirectionalLight, Skybox)  # what changes every face of every probe
# A PointLight relights the probes within its reach (engine.rules.probe_rules.lights_reach) when it
# changes, comes, goes or moves (its own Transform or a parent's: the transform stage's
# moved set holds descendants).


@dataclass
class ProbeState:
    """One probe as the probes stage keeps it."""

    owner: int
    settings: ReflectionProbe
    automatic: bool
    position: glm.vec3
    pending: set[int] = field(default_factory=lambda: set(ALL_FACES))
    captures: int = 0
    faces_captured: int = 0
    frames: int = 0


class ProbeSystem(esper.Processor):
    """Stage "probes" (before the main view): which probes there are, which faces each needs,
    and first captures.  Recaptures are drawn by ``capture_after_present`` (stage
    "probes_after") unless ``recapture_after_present`` is False."""

    def __init__(self, world: World, renderer: Renderer) -> None:
        self.world = world
        self.renderer = renderer
        self.probes = world.resources[ProbeStates] = ProbeStates()
        self.path = "auto"
        self.chosen_path: str | None = None  # what "auto" settled on, once it has timed both
        self.timings: dict[str, float] = {}  # median ms of the timed captures, by path
        self.path_used = ""  # the path of the last capture (RenderStats.probe_path, every frame with probes)
        self._bounds: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # entity -> last world box
        self._lights: dict[int, tuple[np.ndarray, float]] = {}  # point light -> (position, range) last seen
        self._looks = LookChanges()  # what changes a look (probe_rules.LOOK_KINDS), and which probe each samples
        # Recaptures drawn after the frame is presented, sampled from the next frame on (the
        # module's docstring says why); False draws them before the main view, as first captures are.
        self.recapture_after_present = True

    def process(self, dt: float) -> None:
        world = self.world
        had_probes = bool(self.probes)
        looks = self._looks.entities(world)  # asked every frame: it follows what each object samples
        self._refresh_probes()
        if not self.probes:
            self._bounds.clear()  # nothing to keep boxes for (a world without probes pays nothing)
            self._lights.clear()
            return
        # Where every drawable was when the first probe came (its first capture saw them
        # there); after that, only what changed is looked at.
        boxes = self._changed_boxes(looks) if had_probes else self._all_boxes()
        everything = any(world.changed(kind) for kind in LIGHTING_KINDS)
        lights = self._changed_lights() if had_probes else self._all_lights()
        surfaces = world.resources.get(Surfaces)
        for state in self.probes.values():
            self._schedule(state, boxes, everything or lights_reach(state.position, state.settings.far, lights),
                           surfaces)
            if not state.captures or not self.recapture_after_present:
                self._capture_due(state)  # a first capture now: the main view has nothing to sample yet
        self._report()

    def capture_after_present(self) -> None:
        """The "probes_after" stage: the faces due of every probe captured before, drawn after
        this frame is presented and sampled by the next (``recapture_after_present``)."""
        if not self.recapture_after_present:
            return
        for state in self.probes.values():
            if state.captures:
                self._capture_due(state)
        self._report()

    def _report(self) -> None:
        """The path in use, every frame there are probes, and the self-check's verdicts (the
        overlay and frame stats show them)."""
        stats, checks = self.renderer.stats, self.renderer.path_checks
        stats.probe_path = self.path_used
        stats.paths_verified, stats.paths_refused = checks.verified(), checks.refused()

    def _capture_due(self, state: ProbeState) -> None:
        faces = state.pending
        if state.settings.time_slicing == "one_face_per_frame" and faces and state.captures:
            faces = {min(faces)}  # the first capture is whole: nothing is shown half-made
        if faces:
            self._capture(state, faces)
            state.pending = state.pending - faces

    # --- which probes -------------------------------------------------------------------------
    def _refresh_probes(self) -> None:
        world = self.world
        found: dict[int, tuple[ReflectionProbe, glm.vec3, bool]] = {}
        for owner, (probe, transform) in world.query(ReflectionProbe, Transform):
            found[owner] = (probe, glm.vec3(transform.world[3]), False)
        # Automatic probes: only what samples a probe can have one (a few, not every
        # drawable: a 10,000-entity world must not pay for them).
        for owner in probe_samplers(world):
            if has_own_probe(world, owner) and world.has(owner, Transform):
                mesh_ref, transform = world.get(owner, MeshRef), world.get(owner, Transform)
                lo, hi = world_bounds(mesh_ref.mesh, transform.world)
                found[owner] = (None, glm.vec3(*((lo + hi) / 2.0)), True)
        for owner in [o for o in self.probes if o not in found]:
            del self.probes[owner]
            self.renderer.probes.drop(owner)
        changed = world.changed(ReflectionProbe)
        for owner, (probe, position, automatic) in found.items():
            state = self.probes.get(owner)
            if state is None or state.automatic != automatic:
                state = self.probes[owner] = ProbeState(owner, probe or ReflectionProbe(), automatic, position)
                continue
            if probe is not None:
                state.settings = probe
            if owner in changed or position != state.position:
                state.position = position
                state.pending = set(ALL_FACES)

    # --- what to capture ----------------------------------------------------------------------
    def _changed_boxes(self, looks: set[int]) -> dict[int, list[tuple[np.ndarray, np.ndarray]]]:
        """The old and new world boxes of every entity that moved, came, went or changed its look."""
        world = self.world
        frame = world.frame
        entities = set(frame.moved) | set(frame.added) | set(frame.removed) | world.deleted() | looks
        boxes: dict[int, list] = {}
        for entity in entities:
            found = []
            old = self._bounds.pop(entity, None)
            if old is not None:
                found.append(old)
            mesh_ref = world.try_get(entity, MeshRef) if world.exists(entity) else None
            transform = world.try_get(entity, Transform) if mesh_ref is not None else None
            if transform is not None:
                new = self._bounds[entity] = world_bounds(mesh_ref.mesh, transform.world)
                found.append(new)
            if found:
                boxes[entity] = found
        return boxes

    def _changed_lights(self) -> list[tuple[np.ndarray, float]]:
        """(position, range) where each point light that changed, came, went or moved this
        frame was and is."""
        world = self.world
        frame = world.frame
        entities = (set(frame.moved) | set(frame.added) | set(frame.removed) | world.deleted()
                    | world.changed(PointLight) | world.changed(Transform))
        spheres = []
        for entity in entities:
            old = self._lights.pop(entity, None)
            if old is not None:
                spheres.append(old)
            new = self._light_sphere(entity)
            if new is not None:
                self._lights[entity] = new
                spheres.append(new)
        return spheres

    def _all_lights(self) -> list[tuple[np.ndarray, float]]:
        self._lights = {entity: sphere for entity in list(self.world.query_one(PointLight))
                        if (sphere := self._light_sphere(entity[0])) is not None}
        return []  # a first capture takes every face anyway

    def _light_sphere(self, entity: int) -> tuple[np.ndarray, float] | None:
        world = self.world
        if not world.exists(entity):
            return None
        light, transform = world.try_get(entity, PointLight), world.try_get(entity, Transform)
        if light is None or transform is None:
            return None
        return np.array(transform.world[3].xyz, np.float64), float(light.range)

    def _all_boxes(self) -> dict[int, list[tuple[np.ndarray, np.ndarray]]]:
        self._bounds = {entity: world_bounds(mesh_ref.mesh, transform.world)
                        for entity, (mesh_ref, transform) in self.world.query(MeshRef, Transform)}
        return {entity: [box] for entity, box in self._bounds.items()}

    def _schedule(self, state: ProbeState, boxes, everything: bool, surfaces: Surfaces | None) -> None:
        settings = state.settings
        state.frames += 1
        if settings._requested:
            settings._requested = False
            state.pending |= ALL_FACES
        mode = settings.refresh
        if mode == "every_frame" or (mode == "every_n" and state.frames % settings.every_n == 0):
            state.pending |= ALL_FACES
        elif mode == "on_change":
            if everything:
                state.pending |= ALL_FACES
                return
            found = [box for entity, boxes_of in boxes.items() if entity != state.owner for box in boxes_of]
            if found:
                lo, hi = (np.array(side) for side in zip(*found, strict=True))
                state.pending |= faces_touched(state.position, settings.far, lo, hi)
                if settings.depth > 0 and surfaces is not None and (surfaces.mirrors or surfaces.portals):
                    state.pending |= self._faces_through_surfaces(state, lo, hi, surfaces)

    @staticmethod
    def _faces_through_surfaces(state: ProbeState, lo: np.ndarray, hi: np.ndarray, surfaces: Surfaces) -> set[int]:
        """The faces that may see a change through a mirror or portal (a face's view tree
        draws what its mirrors show): where the changed boxes' images lie
        (``probe_rules.images_through_surfaces``), or, past the images' limit, every face that
        sees a surface."""
        settings = state.settings
        shown = [*surfaces.mirrors.values(), *surfaces.portals.values()]
        images = images_through_surfaces(state.position, lo, hi, shown, settings.depth, settings.far)
        if images is None:
            corners = np.concatenate([s.corners[:, :3] for s in shown])
            return faces_touched(state.position, settings.far, corners.min(axis=0), corners.max(axis=0))
        if not len(images[0]):
            return set()
        return faces_touched(state.position, settings.far, *images)

    def _capture(self, state: ProbeState, faces: set[int]) -> None:
        settings = state.settings
        views = {face: face_view(face, state.position, settings.near, settings.far, settings.resolution,
                                 skip=state.owner) for face in faces}
        surfaces = self.world.resources.get(Surfaces)
        sees_surfaces = settings.depth > 0 and surfaces is not None and (surfaces.mirrors or surfaces.portals)
        path = self._path(len(faces) == 6 and not sees_surfaces)
        probes = self.renderer.probes
        if path == "time both":
            paths = {"six_pass": lambda: probes.capture(state.owner, views, None, 0, settings.prefilter),
                     "layered": lambda: probes.capture_layered(state.owner, views, prefilter=settings.prefilter)}
            for capture in paths.values():
                capture()  # untimed: programs built, targets made
            samples: dict[str, list[float]] = {name: [] for name in paths}
            for _ in range(AUTO_TIMED_CAPTURES):
                for name, capture in paths.items():
                    samples[name].append(self._timed(capture))
            self.timings = {name: statistics.median(times) for name, times in samples.items()}
            self.chosen_path = min(self.timings, key=self.timings.get)
            LOG.info("probe capture path: %s (six_pass %.2f ms, layered %.2f ms for %d-texel faces)",
                     self.chosen_path, self.timings["six_pass"], self.timings["layered"], settings.resolution)
        elif path == "layered":
            probes.capture_layered(state.owner, views, prefilter=settings.prefilter)
        else:
            probes.capture(state.owner, views, surfaces.table if sees_surfaces else None, settings.depth,
                           settings.prefilter)
        self.path_used = self.chosen_path if path == "time both" else path
        cube = probes.cubes[state.owner]
        cube.position = tuple(state.position)
        cube.box = None
        if settings.box_projection and settings.influence is not None:
            half = glm.vec3(settings.influence) / 2.0
            cube.box = (tuple(state.position - half), tuple(state.position + half))
        state.captures += 1
        state.faces_captured += len(faces)
        self.renderer.stats.probe_captures += 1

    def _path(self, layered_possible: bool) -> str:
        if self.path not in PATHS:
            raise ValueError(f"ProbeSystem.path must be one of {PATHS}, got {self.path!r}")
        if not layered_possible or self.path == "six_pass":
            return "six_pass"
        # The layered capture only where the path self-check verified it on this context
        # (forced or chosen by auto): a refused path would leave faces unwritten.
        if not self.renderer.path_checks.trusted("layered_capture"):
            return "six_pass"
        if self.path == "layered":
            return "layered"
        return self.chosen_path or "time both"

    def _timed(self, capture) -> float:
        ctx = self.renderer.ctx
        ctx.finish()
        start = time.perf_counter()
        capture()
        ctx.finish()
        return (time.perf_counter() - start) * 1e3


class ProbeAfterPresentSystem(esper.Processor):
    """Stage "probes_after": the recaptures the probes stage scheduled this frame, drawn after
    present (``ProbeSystem.capture_after_present``)."""

    def __init__(self, probes: ProbeSystem) -> None:
        self.probes = probes

    def process(self, dt: float) -> None:
        self.probes.capture_after_present()
