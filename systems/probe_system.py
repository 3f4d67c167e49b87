"""Probes: the two stages that capture reflection probes, from what the scheduler publishes.

Three parts, each with one job:
  - the scheduler (``systems/probe_scheduler.py``, GL-free): which probes there are and which
    faces of each are due this frame, and why; it publishes the world's ``ProbeSchedule``
    and keeps ``ProbeStates`` (``engine/rules/probe_schedule.py``);
  - the captures (``engine.render.probes.ProbeCaptures.capture_probe``): draw the due faces
    into the probe's cube map and set where the cube was captured from and its projection
    box (the cube's data is theirs alone); ``capture_due`` here draws one probe's due faces
    and counts them in its state;
  - the path chooser (``engine.render.probes.ProbePaths``): ``six_pass`` or ``layered``,
    only a path the path self-check trusts; ``auto`` (the default) times both on the first
    full capture either could draw with GL timer queries, read after that frame, never with
    ``ctx.finish()`` in a stage, keeps the faster for the rest of the run and says which
    (``chosen_path``, ``timings``, ``RenderStats.probe_path``, a log line).

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
The "probes_after" stage draws what the schedule holds undrawn: it needs no reference to
the probes stage's system.

The probe's own object is never in its capture (each face view skips it).  Counters per
probe (``ProbeState.captures``: frames with a capture, ``faces_captured``) are the API;
``RenderStats.probe_captures`` and ``probe_faces`` count this frame's.
"""
from __future__ import annotations

import time
import warnings

import esper

from engine.core.world import World
from engine.render.renderer import Renderer
from engine.render.surface_table import NO_BLENDS, SurfaceBlends, surface_table
from engine.resources import RenderStats, Surfaces
from engine.rules.probe_schedule import ProbeDue, ProbeSchedule, ProbeState, ProbeStates
from systems.probe_scheduler import ProbeScheduler

# A recapture's face that has waited this many frames for the view budget is drawn in the
# probes stage, before the main view's tree spends the budget, one face a frame.
STARVING_FRAMES = 2


def capture_due(world: World, renderer: Renderer, due: ProbeDue, only: frozenset[int] | None = None) -> None:
    """Draw one probe's due faces (``ProbeCaptures.capture_probe``; ``only``: these of them,
    the rest left due) and count them in its state.  The frame's view budget
    (``ViewBudget.views``) is spent a face each: faces past it wait for a later frame
    (pending again), those that have waited longest first, so every face is redrawn in
    bounded time; a first capture waits whole (nothing samples a half-made cube), except
    under a budget smaller than a cube (1 to 5 views), which no frame could ever fit: there
    the first capture is drawn whole when it is the frame's first view, past the budget by
    the difference (said once; one probe a frame, so a level's probes all come in bounded
    time).  The capture's wall time a face feeds ``ProbeStates.face_ms``, what the
    scheduler spends its time budget by."""
    probes = world.resources[ProbeStates]
    state = probes[due.owner]
    stats: RenderStats = world.resources[RenderStats]
    faces = due.faces if only is None else only
    left = stats.views_left()
    if left is not None and len(faces) > left:
        whole_past_budget = due.first and 0 < stats.view_budget < len(faces) and stats.views_spent == 0
        if whole_past_budget:
            _say_small_budget(stats.view_budget)
        else:
            kept = frozenset() if due.first else frozenset(state.oldest_first(faces)[:left])
            waiting = faces - kept
            state.ask(waiting, "view budget")
            stats.views_cut += len(waiting)
            stats.probe_faces_deferred += len(waiting)
            faces = kept
    if only is None or only == due.faces:
        due.drawn = True
    else:
        due.faces = due.faces - only
    if not faces:
        return
    stats.views_spent += len(faces)
    start = time.perf_counter()
    surfaces: Surfaces | None = world.resources.get(Surfaces)
    table = surface_table(world.resources, surfaces) \
        if state.settings.depth > 0 and surfaces is not None and (surfaces.mirrors or surfaces.portals) \
        else None  # its faces' view trees plan with it (a water seen by the side each view's eye is on)
    regions = {face: region for face, region in due.regions.items() if face in faces} if due.regions else None
    renderer.probes.capture_probe(due.owner, faces, state.position, state.settings, table,
                                  world.resources.get(SurfaceBlends, NO_BLENDS), due.unchanged & faces, regions)
    spent_ms = (time.perf_counter() - start) * 1e3
    stats.probe_ms_spent += spent_ms
    probes.measured(spent_ms / len(faces))
    state.record_capture(faces)
    state.parts = renderer.probes.parts_possible(due.owner)


_SAID_SMALL: set[int] = set()


def _say_small_budget(views: int) -> None:
    if views not in _SAID_SMALL:
        _SAID_SMALL.add(views)
        warnings.warn(f"ViewBudget.views = {views} is below a probe's six faces: each new probe's first capture is "
                      f"drawn whole anyway, one a frame, {6 - views} view(s) past the budget that frame (a budget of "
                      "at least 6, plus the reflection views wanted, keeps to it)", stacklevel=3)


def starving_face(state: ProbeState, due: ProbeDue) -> frozenset[int] | None:
    """The one face of a recapture that has waited ``STARVING_FRAMES`` or more for the view
    budget (the longest waiting), or None."""
    oldest = state.oldest_first(due.faces)
    if oldest and state.frames - state.asked_at.get(oldest[0], state.frames) >= STARVING_FRAMES:
        return frozenset(oldest[:1])
    return None


def report(world: World, renderer: Renderer) -> None:
    """The path in use, every frame there are probes, and the self-check's verdicts (the
    overlay and frame stats show them)."""
    stats, checks = world.resources[RenderStats], renderer.path_checks
    stats.probe_path = renderer.probes.paths.in_use
    stats.paths_verified, stats.paths_refused = checks.verified(), checks.refused()


class ProbeSystem(esper.Processor):
    """Stage "probes" (before the main view): the scheduler's update, the cube maps of probes
    gone given back, and the captures that must be drawn before the main view samples them
    (first captures; every capture due, with ``recapture_after_present`` False).  The path
    settings (``path``, ``chosen_path``, ``timings``, ``path_used``) are the renderer's
    ``ProbePaths``, shown here where the overlay and tests set and read them."""

    def __init__(self, world: World, renderer: Renderer) -> None:
        self.world = world
        self.renderer = renderer
        self.scheduler = ProbeScheduler(world)
        self.probes = self.scheduler.probes  # ProbeStates, by owner
        # Recaptures drawn after the frame is presented, sampled from the next frame on (the
        # module's docstring says why); False draws them before the main view, as first captures are.
        self.recapture_after_present = True

    @property
    def path(self) -> str:
        """"auto" (the default), "six_pass" or "layered" (``ProbePaths``)."""
        return self.renderer.probes.paths.path

    @path.setter
    def path(self, value: str) -> None:
        self.renderer.probes.paths.path = value

    @property
    def chosen_path(self) -> str | None:
        """What "auto" settled on, once it has timed both."""
        return self.renderer.probes.paths.chosen

    @property
    def timings(self) -> dict[str, float]:
        """Median ms of auto's timed captures, by path."""
        return self.renderer.probes.paths.timings

    @property
    def path_used(self) -> str:
        """The path that drew the last capture."""
        return self.renderer.probes.paths.used

    def process(self, dt: float) -> None:
        probes = self.renderer.probes
        if probes.cubes:
            # The shadow maps drawn just before, to the rasteriser now: it draws them while
            # the scheduler works (on llvmpipe nothing starts them before the main view's
            # first draw waits for them).
            self.renderer.flush()
        probes.paths.settle()  # the timed captures of an earlier frame, if any wait to be read
        schedule = self.scheduler.update()
        for owner in schedule.gone:
            probes.drop(owner)
        if schedule.gone:
            probes.project_waiting()   # (a row freed: a probe the full table left out takes it)
        if not self.probes:
            return
        limited = self.world.resources[RenderStats].view_budget is not None
        for due in schedule.undrawn():
            if due.first or not self.recapture_after_present:
                capture_due(self.world, self.renderer, due)  # a first capture now: nothing to sample yet
            elif limited and (face := starving_face(self.probes[due.owner], due)) is not None:
                # Waited past STARVING_FRAMES for the budget the reflections spend first:
                # one face now, before them (the rest after present, as budget allows).
                capture_due(self.world, self.renderer, due, only=face)
        report(self.world, self.renderer)


class ProbeAfterPresentSystem(esper.Processor):
    """Stage "probes_after": the captures the schedule still holds undrawn (recaptures),
    drawn after present and sampled by the next frame; the last of the frame's GL work, so
    the frame's GPU timing ends here (dynamic resolution: ``GpuFrameTimer``)."""

    def __init__(self, world: World, renderer: Renderer) -> None:
        self.world = world
        self.renderer = renderer

    def process(self, dt: float) -> None:
        try:
            schedule = self.world.resources.get(ProbeSchedule)
            if schedule is None or not self.world.resources.get(ProbeStates):
                return
            for due in schedule.undrawn():
                capture_due(self.world, self.renderer, due)
            report(self.world, self.renderer)
        finally:
            self.renderer.frame_timer.end()
