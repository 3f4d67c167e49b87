"""What the probes scheduler keeps and publishes (plain data, no GL): every probe's state
(``ProbeStates``, kept across frames) and this frame's captures (``ProbeSchedule``: which
faces of which probes, and why).  The scheduler (``systems/probe_scheduler.py``) writes
them; the captures (``systems/probe_system.py``) draw what the schedule says and count it
in the probe's state; tools read both (``shell.capture`` exports the states).

A reason is a short line a person reads: "first capture", "probe moved", "settings
changed", "requested", "every_frame", "every_n", "DirectionalLight changed", "light 7
moved", "moved: entity 12", "look changed: entity 12, seen in mirror 5", "added: entity 3,
seen through portal 9", "4 more changes" (past ``MAX_NAMED`` entities a probe and frame).
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from pyglm import glm

from components import ReflectionProbe
from engine.rules.probe_rules import ALL_FACES

MAX_NAMED = 8  # entities named in a probe's reasons a frame; the rest are counted in one reason
# Refresh modes (and reasons) that recapture on a period, whatever changed: a face due for
# them alone that no change reached since it was drawn is ``ProbeDue.unchanged``.
PERIODIC = ("every_frame", "every_n")
WATCHING = ("on_change", *PERIODIC)  # the modes whose probes follow what changed each frame
CAPTURED_ONCE = ("once", "scripted")  # the modes whose probes draw again only when asked (or a first picture comes)


@dataclass
class ProbeState:
    """One probe as the scheduler keeps it.  ``pending``: the faces waiting to be captured
    (with ``time_slicing`` some wait for later frames) and ``why`` the reasons they wait
    for (reason -> its faces still waiting).  ``captures`` (frames with a capture) and
    ``faces_captured`` are counted by the captures (``record_capture``): they are the API."""

    owner: int
    settings: ReflectionProbe
    automatic: bool
    position: glm.vec3
    pending: set[int] = field(default_factory=lambda: set(ALL_FACES))
    why: dict[str, set[int]] = field(default_factory=lambda: {"first capture": set(ALL_FACES)})
    captures: int = 0
    faces_captured: int = 0
    frames: int = 0
    requests_seen: int = 0  # settings.requests when last looked at (ReflectionProbe.request)
    waiting: int = 0        # frames its due capture has waited for the time budget (it goes sooner)
    # The frame (``frames``) each face not yet drawn was first asked for: under a view budget
    # the faces that have waited longest go first, so none waits forever.
    asked_at: dict[int, int] = field(default_factory=dict)
    # The faces a change may have reached since they were last drawn (a periodic probe's:
    # the scheduler's ``_mark_changes``); every face until the first capture.
    changed: set[int] = field(default_factory=lambda: set(ALL_FACES))
    # Of ``changed``, the faces every change since they were drawn reached within a part of
    # the face: face -> that part, (s0, t0, s1, t1) in the face's normalised coordinates
    # (``probe_rules.face_rects``).  A changed face not here changed anywhere in it.
    regions: dict[int, tuple[float, float, float, float]] = field(default_factory=dict)
    # Whether the captures could draw a part of a face at its next capture (the last drew
    # faces straight into the cube, six-pass, with the records a part is drawn by): where
    # not, the scheduler works out no rectangles (every face a change reaches is drawn whole).
    parts: bool = False

    def ask(self, faces: Iterable[int], reason: str, part: bool = False) -> None:
        """Faces to capture, and why.  A reason that is no period's, and not a change whose
        part of the face the scheduler follows (``part``: ``_mark_changes`` works out where
        it reaches), changes the faces everywhere: none is drawn in part."""
        faces = set(faces)
        if faces and not part and reason not in PERIODIC:
            self.changed |= faces
            for face in faces:
                self.regions.pop(face, None)
        if faces:
            self.pending |= faces
            self.why.setdefault(reason, set()).update(faces)
            for face in faces:
                self.asked_at.setdefault(face, self.frames)

    def oldest_first(self, faces: Iterable[int]) -> list[int]:
        """``faces`` in the order a budget draws them: longest waiting first, then by number."""
        return sorted(faces, key=lambda face: (self.asked_at.get(face, self.frames), face))

    def take(self, faces: frozenset[int]) -> dict[str, frozenset[int]]:
        """``faces`` leave the waiting set (due this frame); the reasons they waited for."""
        reasons = {}
        for reason, waiting in list(self.why.items()):
            due = waiting & faces
            if due:
                reasons[reason] = frozenset(due)
                waiting -= due
            if not waiting:
                del self.why[reason]
        self.pending -= faces
        return reasons

    def record_capture(self, faces: frozenset[int]) -> None:
        """The captures drew ``faces`` of this probe."""
        self.captures += 1
        self.faces_captured += len(faces)
        self.changed -= faces  # drawn now (or kept: what a drawing now gives)
        for face in faces:
            self.regions.pop(face, None)
        for face in faces:
            self.asked_at.pop(face, None)


class ProbeStates(dict):
    """World resource: every probe the scheduler keeps, by owning entity (``ProbeState``),
    and what a cube face has cost to capture lately (``face_ms``: a running mean of the
    captures' wall time a face, None before the first; the time budget is spent by it)."""

    face_ms: float | None = None

    def measured(self, ms_a_face: float) -> None:
        """One capture's wall time a face, folded into ``face_ms`` (a quarter each time)."""
        self.face_ms = ms_a_face if self.face_ms is None else 0.75 * self.face_ms + 0.25 * ms_a_face


@dataclass
class ProbeDue:
    """One probe's capture this frame: ``faces`` and the ``reasons`` (reason -> the faces it
    asked for).  ``first``: the probe's first capture (drawn before the main view samples
    it); ``drawn`` once a capture stage has drawn it.  ``unchanged``: the faces of ``faces``
    due for a period alone (``PERIODIC``) that no change reached since they were last
    drawn: the captures keep such a face as it is where nothing they draw with changed
    either (``ProbeCaptures.capture``).  ``regions``: of the rest due for a period alone, those
    every change since they were drawn reached within a part of the face (``ProbeState.regions``):
    face -> that part, (s0, t0, s1, t1) in the face's normalised coordinates; the captures
    draw only that part of such a face where nothing they draw with changed either."""

    owner: int
    faces: frozenset[int]
    reasons: dict[str, frozenset[int]]
    first: bool
    drawn: bool = False
    unchanged: frozenset[int] = frozenset()
    regions: dict[int, tuple[float, float, float, float]] = field(default_factory=dict)


@dataclass
class ProbeSchedule:
    """World resource, made by the probes scheduler each frame: the captures due (``due``, by
    probe) and the probes gone since the last frame (``gone``: their cube maps are given
    back)."""

    due: dict[int, ProbeDue] = field(default_factory=dict)
    gone: list[int] = field(default_factory=list)

    def undrawn(self) -> list[ProbeDue]:
        return [due for due in self.due.values() if not due.drawn]
