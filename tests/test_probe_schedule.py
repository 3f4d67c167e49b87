"""The probes scheduler without GL, and the probe rules' one owner: which faces of which probes
are due and why (``ProbeSchedule``), a request read without being cleared, what changes a
look defined once and used by the extract stage and the scheduler alike."""
from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

import esper
import pytest
from pyglm import glm

from components import (
    Material,
    MeshRef,
    Mirror,
    PointLight,
    ReflectionProbe,
    Reflective,
    Transform,
    Visibility,
)
from engine.assets.mesh import box, quad
from engine.core.world import World
from engine.rules.probe_rules import ALL_FACES, LOOK_KINDS, PRESENCE_KINDS, LookChanges, probe_for
from engine.rules.probe_schedule import ProbeSchedule, ProbeStates
from systems.frame_rules_system import FrameRulesSystem
from systems.probe_scheduler import ProbeScheduler
from systems.surface_system import SurfaceSystem
from systems.transform_system import TransformSystem

ROOT = Path(__file__).resolve().parents[1]


class Scheduling(esper.Processor):
    def __init__(self, world: World) -> None:
        self.scheduler = ProbeScheduler(world)

    def process(self, dt: float) -> None:
        self.scheduler.update()


@pytest.fixture
def gl_free_world():
    """A world stepping the stages the scheduler reads after (rules, transform, surfaces) and
    the scheduler itself: no renderer, no GL context."""
    world = World("schedule")
    for priority, system in enumerate(reversed([FrameRulesSystem(world), TransformSystem(world),
                                                SurfaceSystem(world), Scheduling(world)])):
        world.add_system(system, priority=priority + 1)
    yield world
    world.close()


def due(world: World) -> dict[int, dict[str, frozenset[int]]]:
    """This frame's schedule: reasons (with their faces) by probe."""
    return {owner: d.reasons for owner, d in world.resources[ProbeSchedule].due.items()}


def test_the_schedule_says_which_faces_of_which_probes_and_why(gl_free_world):
    """A probe at the origin facing a mirror at z = -3 (depth 1), a box on its +X side, a box
    behind it (seen in the mirror only, by the -Z face), a point light in reach, and a second
    probe far off that captures every frame.  Each change is due with its reason and the faces
    it asked for: a moved box its +X face and its mirror image's -Z face, a recoloured one its
    +Z face and the -Z face that sees it in the mirror, a moved light, a request and a moved
    probe every face; nothing else is due."""
    world = gl_free_world
    probe = world.spawn(Transform(), ReflectionProbe(resolution=16, far=20.0, depth=1))
    mirror = world.spawn(Transform(position=(0, 0, -3)), MeshRef(quad(8, 8)), Material(), Mirror())
    side = world.spawn(Transform(position=(2, 0, 0)), MeshRef(box((0.2, 0.2, 0.2))), Material())
    behind = world.spawn(Transform(position=(0, 0, 2)), MeshRef(box((0.2, 0.2, 0.2))), Material())
    light = world.spawn(Transform(position=(0, 2, 0)), PointLight(range=2.0))
    every = world.spawn(Transform(position=(50, 0, 0)), ReflectionProbe(resolution=16, refresh="every_frame"))

    world.step(1 / 60)
    assert due(world) == {probe: {"first capture": ALL_FACES},
                          every: {"first capture": ALL_FACES, "every_frame": ALL_FACES}}
    assert all(d.first for d in world.resources[ProbeSchedule].due.values())
    world.step(1 / 60)
    assert due(world) == {every: {"every_frame": ALL_FACES}}

    world.get(side, Transform).position = glm.vec3(2, 0.1, 0)
    world.step(1 / 60)
    assert due(world)[probe] == {f"moved: entity {side}": {0},
                                 f"moved: entity {side}, seen in mirror {mirror}": {5}}
    world.get(behind, Material).color = (0.9, 0.1, 0.1)
    world.step(1 / 60)
    assert due(world)[probe] == {f"look changed: entity {behind}": {4},
                                 f"look changed: entity {behind}, seen in mirror {mirror}": {5}}
    world.get(light, Transform).position = glm.vec3(0, 2.5, 0)
    world.step(1 / 60)
    assert due(world)[probe] == {f"light {light} moved": ALL_FACES}
    world.get(probe, ReflectionProbe).request()
    world.step(1 / 60)
    assert due(world)[probe] == {"requested": ALL_FACES}
    world.get(probe, Transform).position = glm.vec3(0, 0, 0.5)
    world.step(1 / 60)
    assert due(world)[probe] == {"probe moved": ALL_FACES}
    world.step(1 / 60)
    assert set(due(world)) == {every}
    # The scheduler counts nothing as captured: that is the captures' to say.
    assert world.resources[ProbeStates][probe].captures == 0


def test_what_a_probe_cannot_see_moves_without_a_recapture(gl_free_world):
    """An object hidden in probe captures (``Visibility(in_probes=False)``), or on a layer the
    probe hides, moves without asking for a face; a visible one on the same spot asks for
    its face; hiding an object is a look change that asks for the face that saw it."""
    world = gl_free_world
    probe = world.spawn(Transform(), ReflectionProbe(resolution=16, far=20.0, hides_layers=[3]))
    ghost = world.spawn(Transform(position=(2, 0, 0)), MeshRef(box((0.2, 0.2, 0.2))), Material(),
                        Visibility(in_probes=False))
    layered = world.spawn(Transform(position=(2, 0, 1)), MeshRef(box((0.2, 0.2, 0.2))), Material(),
                          Visibility(layers=[3]))
    plain = world.spawn(Transform(position=(2, 0, -1)), MeshRef(box((0.2, 0.2, 0.2))), Material())
    world.step(1 / 60)
    world.step(1 / 60)
    assert due(world) == {}
    for entity in (ghost, layered):
        world.get(entity, Transform).position = glm.vec3(world.get(entity, Transform).position) + glm.vec3(0, 0.1, 0)
        world.step(1 / 60)
        assert due(world) == {}, entity
    world.get(plain, Transform).position = glm.vec3(2, 0.1, -1)
    world.step(1 / 60)
    assert due(world) == {probe: {f"moved: entity {plain}": {0}}}
    world.add_component(plain, Visibility(in_probes=False))
    world.step(1 / 60)
    assert due(world) == {probe: {f"look changed: entity {plain}": {0}}}
    world.get(plain, Transform).position = glm.vec3(2, 0.2, -1)
    world.step(1 / 60)
    assert due(world) == {}


def test_a_request_is_read_not_cleared(gl_free_world):
    """``ReflectionProbe.request()`` counts; the scheduler compares the count with the one it
    saw, so the component's count is left as it was (another reader sees the request too),
    and one request is due once."""
    world = gl_free_world
    probe = world.spawn(Transform(), ReflectionProbe(resolution=16, refresh="scripted"))
    world.step(1 / 60)
    settings = world.get(probe, ReflectionProbe)
    settings.request()
    settings.request()
    world.step(1 / 60)
    assert due(world) == {probe: {"requested": ALL_FACES}} and settings.requests == 2
    world.step(1 / 60)
    assert due(world) == {}


def test_time_sliced_faces_are_due_one_a_frame_with_their_reasons(gl_free_world):
    """After a whole first capture, a time-sliced probe's waiting faces are due one a frame,
    each with the reason it waits for, and leave the waiting set as they are published."""
    world = gl_free_world
    probe = world.spawn(Transform(), ReflectionProbe(resolution=16, refresh="scripted",
                                                     time_slicing="one_face_per_frame"))
    world.step(1 / 60)
    assert due(world) == {probe: {"first capture": ALL_FACES}}
    world.resources[ProbeStates][probe].record_capture(ALL_FACES)  # as the captures would
    world.get(probe, ReflectionProbe).request()
    for face in range(6):
        world.step(1 / 60)
        assert due(world) == {probe: {"requested": frozenset({face})}}
        assert world.resources[ProbeStates][probe].pending == set(range(face + 1, 6))
    world.step(1 / 60)
    assert due(world) == {}


def test_a_cube_reflective_tile_that_moves_into_another_probes_box_samples_it(gl_free_world):
    """Which probe an object samples follows its position: ``LookChanges`` (the extract
    stage's and the scheduler's) has it when it moves from one probe's influence box into
    another's, when a box shrinks away from it or moves onto it, and not when it moves
    inside one."""
    world = gl_free_world
    a = world.spawn(Transform(position=(-5, 0, 0)), ReflectionProbe(influence=(4, 4, 4)))
    b = world.spawn(Transform(position=(5, 0, 0)), ReflectionProbe(influence=(4, 4, 4)))
    tile = world.spawn(Transform(position=(-5, 0, 0)), MeshRef(quad(1, 1)), Material(), Reflective("cube"))
    looks = LookChanges()

    def step() -> set[int]:
        world.step(1 / 60)
        return looks.entities(world)

    assert tile in step() and probe_for(world, tile) == a
    world.get(tile, Transform).position = glm.vec3(-4.5, 0, 0)
    assert tile not in step()
    world.get(tile, Transform).position = glm.vec3(5, 0, 0)
    assert tile in step() and probe_for(world, tile) == b
    world.get(b, ReflectionProbe).influence = (1, 1, 1)
    world.get(tile, Transform).position = glm.vec3(6, 0, 0)  # out of b's smaller box: the sky
    assert tile in step() and probe_for(world, tile) == 0
    world.get(b, Transform).position = glm.vec3(6, 0, 0)  # the probe's box comes to the tile
    assert tile in step() and probe_for(world, tile) == b


# --- one owner for each probe rule -------------------------------------------------------------
RULES = {
    "probe sampling": r"samples_a_probe|probe_samplers|SAMPLER_KINDS",
    "what changes a look": r"LOOK_KINDS|MATERIAL_KINDS|LookChanges",
    "what relights a probe": r"LIGHTING_KINDS|lights_reach(ing)?",
    "what a probe face sees": r"faces_touched|face_hits|face_planes|images_through_surfaces",
}


@functools.cache
def top_level_names(path: Path) -> frozenset[str]:
    names = set()
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return frozenset(names)


@pytest.mark.parametrize("rule", sorted(RULES))
def test_each_probe_rule_is_defined_in_probe_rules_only(rule):
    defined = {}
    for package in ("components", "engine", "systems", "shell", "games", "benchmarks"):
        for path in sorted((ROOT / package).rglob("*.py")):
            hits = sorted(n for n in top_level_names(path) if re.fullmatch(RULES[rule], n))
            if hits:
                defined[path.relative_to(ROOT).as_posix()] = hits
    assert set(defined) == {"engine/rules/probe_rules.py"}, f"{rule}: defined in {defined}"


def test_no_system_works_out_for_itself_what_samples_a_probe():
    """``Reflective.mode == "cube"`` (half of the sampling rule) is read by the probe rules
    and by material dispatch (which shader variant reflects a cube) only."""
    for path in sorted((ROOT / "systems").rglob("*.py")) + sorted((ROOT / "shell").rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        if path.name != "material_dispatch.py":
            assert not re.search(r"mode\s*==\s*[\"']cube[\"']", text), path


def test_every_component_the_extract_stage_draws_an_instance_from_is_a_look_kind():
    """What the extract stage reads to build an instance row (besides its Transform, which is
    where it is, not how it looks) is in ``LOOK_KINDS``: a kind read there but missing from
    the list would change a picture that neither the rows nor the probes follow."""
    from systems import extract_system

    source = ast.get_source_segment(Path(extract_system.__file__).read_text(encoding="utf-8"),
                                    next(node for node in ast.walk(ast.parse(Path(extract_system.__file__).read_text(
                                        encoding="utf-8"))) if isinstance(node, ast.FunctionDef)
                                         and node.name == "_refresh_instance"))
    read = set(re.findall(r"(?:try_get|has|get)\(entity, (\w+)\)", source))
    assert read, "no component reads found: the pattern no longer matches the extract stage"
    kinds = {kind.__name__ for kind in (*LOOK_KINDS, *PRESENCE_KINDS)}
    assert read - {"Transform"} <= kinds, read - {"Transform"} - kinds
    assert all(isinstance(why, str) and why for why in (*LOOK_KINDS.values(), *PRESENCE_KINDS.values()))


def test_probes_that_refresh_by_request_watch_no_changes_until_one_turns_on_change(gl_free_world):
    """With only a scripted probe the scheduler keeps no boxes (what moves matters to no
    probe: an every-frame probe's does, ``test_an_every_frame_probes_unchanged_faces_are_those_no_change_reached``);
    once it turns on_change it recaptures every face for its new settings, and from then on
    a box that moves from its +X side to its -X side asks for both faces: where the box was
    (kept since the switch) and where it is."""
    world = gl_free_world
    probe = world.spawn(Transform(), ReflectionProbe(resolution=16, far=20.0, refresh="scripted"))
    crate = world.spawn(Transform(position=(2, 0, 0)), MeshRef(box((0.2, 0.2, 0.2))), Material())
    scheduler = world.get_system(Scheduling).scheduler
    for step in range(3):
        world.get(crate, Transform).position = glm.vec3(2, 0.1 * step, 0)
        world.step(1 / 60)
        assert (probe in due(world)) == (step == 0)  # its first capture, then nothing unasked
    assert not scheduler._bounds
    world.get(probe, ReflectionProbe).refresh = "on_change"
    world.step(1 / 60)
    assert due(world)[probe] == {"settings changed": ALL_FACES}
    assert crate in scheduler._bounds
    world.step(1 / 60)
    assert probe not in due(world)
    world.get(crate, Transform).position = glm.vec3(-2, 0, 0)
    world.step(1 / 60)
    assert due(world)[probe] == {f"moved: entity {crate}": {0, 1}}


def test_hiding_an_object_as_it_moves_still_recaptures_where_it_was_seen(gl_free_world):
    """Moved and hidden from probes in the same frame: what the probe saw before must go, so
    the face that saw it is due (a move alone by a hidden object asks for nothing, by the
    object's new Visibility; its old one drew it)."""
    world = gl_free_world
    probe = world.spawn(Transform(), ReflectionProbe(resolution=16, far=20.0))
    plain = world.spawn(Transform(position=(2, 0, -1)), MeshRef(box((0.2, 0.2, 0.2))), Material())
    world.step(1 / 60)
    world.step(1 / 60)
    assert due(world) == {}
    world.get(plain, Transform).position = glm.vec3(2, 0.1, -1)
    world.add_component(plain, Visibility(in_probes=False))
    world.step(1 / 60)
    assert probe in due(world) and 0 in set().union(*due(world)[probe].values())


def test_an_every_frame_probes_unchanged_faces_are_those_no_change_reached(gl_free_world):
    """Every face of an every-frame probe is due each frame; those no change reached since
    they were last drawn are published ``unchanged`` (the captures may keep them): none at
    the first capture, all six in a still frame, all but the +X face when a box there moves,
    both X faces when it crosses to -X, and a face a change reached stays out until it is
    drawn (a face left undrawn, as a view budget may, is not unchanged the frame after).  A
    point light coming anywhere, even out of the probe's reach, reaches every face (the
    lights' order and limits shift)."""
    world = gl_free_world
    probe = world.spawn(Transform(), ReflectionProbe(resolution=16, far=20.0, refresh="every_frame"))
    crate = world.spawn(Transform(position=(2, 0, 0)), MeshRef(box((0.2, 0.2, 0.2))), Material())
    states = world.resources[ProbeStates]

    def step(draw: frozenset[int] | None = None) -> frozenset[int]:
        world.step(1 / 60)
        this = world.resources[ProbeSchedule].due[probe]
        assert this.faces == ALL_FACES and set(this.reasons) <= {"first capture", "every_frame"}
        states[probe].record_capture(this.faces if draw is None else draw)  # what the captures do
        return this.unchanged

    assert step() == frozenset()
    assert step() == ALL_FACES
    world.get(crate, Transform).position = glm.vec3(2, 0.1, 0)
    assert step() == ALL_FACES - {0}
    assert step() == ALL_FACES
    world.get(crate, Transform).position = glm.vec3(-2, 0.1, 0)
    assert step(draw=ALL_FACES - {0, 1}) == ALL_FACES - {0, 1}  # the X faces not drawn: still changed
    assert step() == ALL_FACES - {0, 1}
    assert step() == ALL_FACES
    world.spawn(Transform(position=(500, 0, 0)), PointLight(range=1.0))
    assert step() == frozenset()
    assert step() == ALL_FACES


def test_a_sun_turning_a_little_relights_the_probes_a_degree_at_a_time_and_when_it_stops(gl_free_world):
    """A sun turning 0.3 degrees a frame (a day): the probe is not relit each frame but once
    the sun is past a degree from where it was last relit (the fourth frame, 1.2 degrees),
    then once more the frame it stands still (its capture made exact), then not again.  A
    turn of 5 degrees, a change of colour past 2%, or of its shadows, relights at once; a
    sun that came relights at once too."""
    from components import DirectionalLight

    world = gl_free_world
    start = glm.normalize(glm.vec3(-0.3, -0.8, -0.5))
    axis = glm.normalize(glm.cross(start, glm.vec3(0, 1, 0)))  # square to it: it turns by the angle

    def turned(degrees: float) -> glm.vec3:
        return glm.vec3(glm.rotate(glm.radians(degrees), axis) * glm.vec4(start, 0.0))

    probe = world.spawn(Transform(), ReflectionProbe(resolution=16, far=20.0))
    sun = DirectionalLight(direction=start, intensity=2.0)
    world.spawn(sun)
    world.step(1 / 60)
    world.step(1 / 60)
    assert probe not in due(world)
    relit = []
    for step in range(1, 6):
        sun.direction = turned(0.3 * step)
        world.step(1 / 60)
        relit.append(due(world).get(probe) == {"DirectionalLight changed": ALL_FACES})
    assert relit == [False, False, False, True, False]  # 1.2 degrees from the last relight
    world.step(1 / 60)  # standing still 0.3 degrees from it: made exact
    assert due(world)[probe] == {"DirectionalLight changed": ALL_FACES}
    world.step(1 / 60)
    assert probe not in due(world)
    sun.direction = (0.3, -0.8, -0.5)  # a turn past a degree: at once (and this one's ...
    world.step(1 / 60)
    assert due(world)[probe] == {"DirectionalLight changed": ALL_FACES}
    sun.direction = sun.direction  # ... normalising again moves it by a rounding, once)
    for _ in range(3):  # the rounding, then standing still: no relight for it
        world.step(1 / 60)
        assert probe not in due(world)
    for change in (lambda: setattr(sun, "direction", turned(6.5)),
                   lambda: setattr(sun, "intensity", 2.1),              # 5% brighter
                   lambda: setattr(sun, "shadow_softness", 2.0),
                   lambda: world.spawn(DirectionalLight(direction=(0.0, -1.0, 0.0), intensity=0.5))):
        change()
        world.step(1 / 60)
        assert due(world)[probe] == {"DirectionalLight changed": ALL_FACES}
        world.step(1 / 60)
        assert probe not in due(world)
