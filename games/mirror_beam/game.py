"""Mirror beam: turn the mirrors so a beam of light bounces onto the target.

A level file places a source (the beam leaves it along its -Z, the way a camera looks), a
target, mirrors and walls; its ``[rules]`` say which mirrors turn and by what step.  Each
frame runs, in order:

* in the game stage (``update``), ``input_system``: tab / number keys / a click pick a
  mirror, left and right turn it about the vertical axis by the rules' step, 'r' puts the
  level back as it started, 'n' after a win plays the next level;
* the game's "beam" system (``MirrorBeam.systems``), after the engine's surfaces stage and
  before extract: ``beam_system`` traces the beam through this frame's ``Surfaces`` (the
  renderer's planes, outlines and reflection matrices, ``games.mirror_beam.beam``) and
  re-poses the beam's segments (thin emissive boxes, ordinary entities, so mirrors show
  them) when it changed: a visual aid; ``light_system`` decides whether the laser's light
  reaches the target by the mirrors (below); ``win_system``: the target lit records a
  ``BeamEvent('win')`` once and makes the target glow; ``marker_system`` keeps the
  selection light over the selected mirror.

The light is real: a lamp at the laser's mouth (a ``PointLight``, ``BeamLamp``) whose light
every mirror reflects (``Mirror.reflects_light``, ``bounces`` as many as the engine follows,
up to the level's ``max_bounces``), so the renderer draws each reflection's patch of light
with its shadows.  The target is lit when one of the lamp's virtual lights through the
mirrors (``engine.rules.shadow_rules.virtual_lights``, the rules the shadows stage draws
from, for this frame's surfaces) reaches a point of the target's faces by the same
aperture test the shader makes (``shadow_rules.light_path``: the line to the image
through every mirror's outline, in order, from the front) and no solid stands on any leg
of that way (the engine's ray cast, as for the beam).  The sun is not reflected
(``DirectionalLight.bounces = 0``): the puzzle's light is the laser's.

So the beam drawn in a frame is the one the mirrors of that frame make: it is there from
frame 0, and a turn (or a restart) shows in the beam in the frame of the key press.  The
segments are posed after the transform stage; the engine works their world matrices out
again before extract (the schedule's "transform_late" entry).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pyglm import glm

from components import (
    Bloom,
    Camera,
    DirectionalLight,
    Emissive,
    Material,
    MeshRef,
    Mirror,
    PointLight,
    ScreenText,
    Tonemap,
    Transform,
    look_rotation,
    yaw_pitch_of,
)
from components.limits import MAX_LIGHT_BOUNCES
from engine.assets.level_file import LevelGame
from engine.assets.mesh import box
from engine.core.errors import SpeculumError
from engine.core.frame_io import Input, Output
from engine.core.game import GameSystem, spawn_camera
from engine.core.world import World
from engine.render.frame_views import FrameViews
from engine.resources import Surfaces
from engine.rules.light_rules import lamp_cone
from engine.rules.raycast import raycast
from engine.rules.shadow_rules import VirtualLight, light_path, virtual_lights
from games.mirror_beam.beam import BeamPath, FirstSolid, hit_mirror, trace_beam

LEVEL_DIR = Path(__file__).parent / "levels"
BEAM_WIDTH = 0.07
BEAM_COLOR = (1.0, 0.04, 0.02, 1.0)
BEAM_POWER = 2.0
WIN_GLOW = 4.0  # HDR: a solved target is four times brighter than white, and glows
MAX_BOUNCES_CAP = 16
FRAME_DEPTH = 0.04
# The laser's lamp: just past the housing's front face (inside it, the housing would shadow
# its own light), red like the beam, reaching the longest shipped path (about 19 m), at the
# back of a barrel (a square tube of four plates) that lets out only a narrow cone, as a
# laser's light is: half-width over length, about 4 degrees; the lamp casts shadows, so
# its light leaves only through the barrel, directly and by the mirrors.  It is a spot a
# little wider than that (LAMP_SPOT_ANGLE): the barrel still cuts the cone's edge, and its
# shadow is one perspective map fitted to the cone (light_rules.SPOT_MAP_MAX_ANGLE), not six
# cube faces, drawn again each time a mirror turns.
LAMP_OFFSET = 0.02
LAMP_SPOT_ANGLE = 6.0
BARREL_LENGTH = 0.9
BARREL_HALF = 0.037        # inner half-width (the beam, BEAM_WIDTH wide, runs inside it)
BARREL_WALL = 0.02
LAMP_COLOR = (1.0, 0.35, 0.25, 1.0)
LAMP_INTENSITY = 400.0
LAMP_RANGE = 30.0
# Points of the target a reflection must reach: its faces' centres, this far out from them.
TARGET_PROBE_OUT = 0.01
DEFAULT_CAMERA = {"position": [0.0, 7.5, 7.5], "look_at": [0.0, 0.5, 0.0]}


class LevelRulesError(SpeculumError, ValueError):
    """A level's [rules] table that the game cannot play (names the file, the rule and why)."""


def levels() -> list[Path]:
    """The shipped level files, in play order."""
    return sorted(LEVEL_DIR.glob("*.toml"))


# --- plain data ---------------------------------------------------------------------------

@dataclass
class BeamRules:
    """A level's rules, checked: entity ids of the source, target and turnable mirrors."""

    source: int
    target: int
    rotatable: list[int]
    step: float = 15.0
    max_bounces: int = 8
    solution: dict[int, int] = field(default_factory=dict)  # mirror -> steps (+ left, - right)
    camera: dict[str, list[float]] = field(default_factory=lambda: dict(DEFAULT_CAMERA))


@dataclass
class BeamSegment:
    """Marks one of the beam's segment entities (``index`` along the path)."""

    index: int


@dataclass
class MirrorFrame:
    """Marks the backing the game puts behind a mirror (``mirror`` is its entity)."""

    mirror: int


@dataclass
class Caption:
    """Marks the game's text on the screen (the level's name; "solved" once it is)."""


@dataclass
class BeamLamp:
    """Marks the laser's lamp (a PointLight at the laser's mouth)."""


@dataclass
class LaserBarrel:
    """Marks a plate of the barrel in front of the laser's lamp."""


@dataclass
class SelectionMarker:
    """Marks the small light that hovers over the selected mirror."""


@dataclass
class BeamEvent:
    """Something the game did, for scripts and tests: 'win', 'restart', 'turn', 'select', 'next'
    (the next level asked for)."""

    kind: str
    frame: int
    detail: Any = None


@dataclass
class BeamState:
    """The puzzle's state (a world resource): selection, the beam, won or not, the events."""

    rules: BeamRules
    level_name: str
    start_rotations: dict[int, glm.quat]
    target_glow: float
    selected: int = 0
    path: BeamPath | None = None
    lit: bool = False                      # the laser's reflected light reaches the target
    lit_by: tuple[int, ...] = ()           # the mirrors of the way it came, in order
    light_seen: tuple = ()                 # what ``lit`` was worked out from: (the mirrors' states,)
    won: bool = False
    next_asked: bool = False
    frame: int = 0
    events: list[BeamEvent] = field(default_factory=list)

    def wins(self) -> list[BeamEvent]:
        return [e for e in self.events if e.kind == "win"]


# --- rules --------------------------------------------------------------------------------

RULE_KEYS = ("source", "target", "rotatable", "step", "max_bounces", "solution", "camera")


def parse_rules(rules: dict[str, Any], names: dict[str, int], world: World, where: str) -> BeamRules:
    """Check a level's rules against its entities; every problem is a ``LevelRulesError``
    naming ``where`` (the level file), the rule and the reason."""

    def fail(rule: str, why: str) -> LevelRulesError:
        return LevelRulesError(f"{where}: rules.{rule} {why}")

    def entity(rule: str, name: Any) -> int:
        if not isinstance(name, str):
            raise fail(rule, f"must be an entity name (a string), got {name!r}")
        if name not in names:
            known = ", ".join(sorted(names)) or "none"
            raise fail(rule, f"names {name!r}, which is no entity of the level (its entities: {known})")
        return names[name]

    unknown = sorted(set(rules) - set(RULE_KEYS))
    if unknown:
        raise fail(unknown[0], f"is not a mirror_beam rule (known: {', '.join(RULE_KEYS)})")
    for required in ("source", "target", "rotatable"):
        if required not in rules:
            raise fail(required, "is missing")
    source, target = entity("source", rules["source"]), entity("target", rules["target"])
    for rule, ent in (("source", source), ("target", target)):
        if world.try_get(ent, Transform) is None:
            raise fail(rule, f"names {rules[rule]!r}, which has no Transform")
    if world.try_get(target, MeshRef) is None:
        raise fail("target", f"names {rules['target']!r}, which has no MeshRef (the beam needs something to hit)")
    if source == target:
        raise fail("target", "is the source itself")
    rotatable = rules["rotatable"]
    if not isinstance(rotatable, list) or not rotatable:
        raise fail("rotatable", f"must be a non-empty list of mirror names, got {rotatable!r}")
    if len(rotatable) > 9:
        raise fail("rotatable", f"lists {len(rotatable)} mirrors; at most 9 (keys 1-9 select them)")
    turnable = []
    for name in rotatable:
        ent = entity("rotatable", name)
        if world.try_get(ent, Mirror) is None or world.try_get(ent, Transform) is None:
            raise fail("rotatable", f"names {name!r}, which is not a mirror (needs Mirror and Transform)")
        if ent in turnable:
            raise fail("rotatable", f"names {name!r} twice")
        turnable.append(ent)
    step = rules.get("step", 15.0)
    if isinstance(step, bool) or not isinstance(step, (int, float)) or not 0.0 < step <= 180.0:
        raise fail("step", f"must be degrees in (0, 180], got {step!r}")
    limit = rules.get("max_bounces", 8)
    if isinstance(limit, bool) or not isinstance(limit, int) or not 1 <= limit <= MAX_BOUNCES_CAP:
        raise fail("max_bounces", f"must be an int in [1, {MAX_BOUNCES_CAP}], got {limit!r}")
    solution_table = rules.get("solution", {})
    if not isinstance(solution_table, dict):
        raise fail("solution", f"must be a table of mirror name = steps, got {solution_table!r}")
    solution = {}
    for name, steps in solution_table.items():
        ent = entity("solution", name)
        if ent not in turnable:
            raise fail("solution", f"turns {name!r}, which is not in rules.rotatable")
        if isinstance(steps, bool) or not isinstance(steps, int):
            raise fail("solution", f"{name} must be a whole number of steps, got {steps!r}")
        solution[ent] = steps
    camera = rules.get("camera", DEFAULT_CAMERA)
    if not isinstance(camera, dict) or set(camera) != {"position", "look_at"} or not all(
            isinstance(v, list) and len(v) == 3 and all(isinstance(c, (int, float)) for c in v)
            for v in camera.values()):
        raise fail("camera", f"must be {{ position = [x, y, z], look_at = [x, y, z] }}, got {camera!r}")
    return BeamRules(source, target, turnable, float(step), limit, solution, camera)


# --- systems ------------------------------------------------------------------------------

def input_system(world: World, state: BeamState) -> bool:
    """Selection, turning and restart from the ``Input`` resource; True when a mirror moved."""
    keys = world.resources[Input]
    rules = state.rules
    if "r" in keys.pressed:
        restart(world, state)
        return True
    if state.won:
        if "n" in keys.pressed:
            state.next_asked = True
            state.events.append(BeamEvent("next", state.frame))
        return False  # solved: the mirrors stay put until a restart or the next level
    count = len(rules.rotatable)
    if "tab" in keys.pressed:
        select(state, (state.selected + 1) % count)
    for digit in range(1, count + 1):
        if str(digit) in keys.pressed:
            select(state, digit - 1)
    turn = ("left" in keys.pressed) - ("right" in keys.pressed)
    if keys.clicks & {"left", "right"}:
        picked = pick_mirror(world, rules.rotatable, keys.mouse)
        if picked is not None:
            select(state, rules.rotatable.index(picked))
            turn += ("left" in keys.clicks) - ("right" in keys.clicks)
    if turn:
        mirror = rules.rotatable[state.selected]
        transform = world.get(mirror, Transform)
        transform.rotation = glm.angleAxis(glm.radians(turn * rules.step), glm.vec3(0, 1, 0)) * transform.rotation
        state.events.append(BeamEvent("turn", state.frame, (mirror, turn)))
    return bool(turn)


def select(state: BeamState, index: int) -> None:
    if index != state.selected:
        state.selected = index
        state.events.append(BeamEvent("select", state.frame, state.rules.rotatable[index]))


def restart(world: World, state: BeamState) -> None:
    """The level as it started: mirror rotations, selection, target glow, not won."""
    for mirror, rotation in state.start_rotations.items():
        world.get(mirror, Transform).rotation = glm.quat(rotation)
    state.selected = 0
    state.won = False
    world.get(state.rules.target, Emissive).power = state.target_glow
    state.events.append(BeamEvent("restart", state.frame))


def pick_mirror(world: World, mirrors: list[int], mouse: tuple[float, float]) -> int | None:
    """The turnable mirror under the pointer (output pixels, y down) in the last frame's main
    view: the nearest outline the pointer's ray crosses, front or back."""
    views = world.resources.get(FrameViews)
    output = world.resources.get(Output)
    surfaces = world.resources.get(Surfaces)
    if views is None or views.main is None or output is None or surfaces is None:
        return None
    w, h = output.size
    x, y = 2.0 * mouse[0] / w - 1.0, 1.0 - 2.0 * mouse[1] / h
    inverse = glm.inverse(views.main.view_proj)
    near, far = inverse * glm.vec4(x, y, -1.0, 1.0), inverse * glm.vec4(x, y, 1.0, 1.0)
    origin = glm.vec3(near) / near.w
    direction = glm.normalize(glm.vec3(far) / far.w - origin)
    best, best_t = None, float("inf")
    for mirror in mirrors:
        found = surfaces.mirrors.get(mirror)
        hit = hit_mirror(found, origin, direction) if found is not None else None
        if hit is not None and hit[0] < best_t:
            best, best_t = mirror, hit[0]
    return best


def first_solid(world: World) -> FirstSolid:
    """The first thing drawn that is not a mirror or the beam's own display, by the engine's
    ray cast against world triangles (mirror frames, walls, the target, the source)."""

    def solid(entity: int) -> bool:
        mesh_ref = world.try_get(entity, MeshRef)
        return mesh_ref is not None and mesh_ref.visible and not (
            world.has(entity, Mirror) or world.has(entity, BeamSegment) or world.has(entity, SelectionMarker))

    def cast(origin: glm.vec3, direction: glm.vec3, leave_out: int | None) -> tuple[float, int] | None:
        hit = raycast(world, origin, direction, where=solid, ignore=() if leave_out is None else (leave_out,))
        return None if hit is None else (hit.distance, hit.entity)

    return cast


def beam_system(world: World, state: BeamState) -> None:
    """Trace the beam through the renderer's mirror states and re-pose its segments."""
    surfaces = world.resources.get(Surfaces)
    if surfaces is None:
        return  # no surfaces stage has run (the system called outside the schedule)
    rules = state.rules
    source = world.get(rules.source, Transform).world
    origin = glm.vec3(source[3])
    direction = glm.vec3(source * glm.vec4(0.0, 0.0, -1.0, 0.0))
    path = trace_beam(origin, direction, surfaces.mirrors.values(), first_solid(world), rules.target,
                      rules.max_bounces, skip=rules.source)
    if path.same_as(state.path):
        return
    state.path = path
    # The beam is the laser light's axis: the frame's virtual-light budget goes first to the
    # light by the mirrors it meets (a way through more of them ranks higher; the lamp's light
    # reaches other mirrors too, but only through the barrel's narrow cone, often not at all).
    on_path = {bounce.mirror for bounce in path.bounces}
    for entity, mirror in world.query_one(Mirror):
        wanted = 1 if entity in on_path else 0
        if mirror.priority != wanted:
            mirror.priority = wanted
    for _, (segment, transform, mesh_ref) in world.query(BeamSegment, Transform, MeshRef):
        if segment.index >= len(path.points) - 1:
            if mesh_ref.visible:
                mesh_ref.visible = False
            continue
        a, b = path.points[segment.index], path.points[segment.index + 1]
        length = max(glm.distance(a, b), 1e-4)
        transform.position = (a + b) * 0.5
        transform.rotation = look_rotation(b - a)
        transform.scale = (BEAM_WIDTH, BEAM_WIDTH, length)
        if not mesh_ref.visible:
            mesh_ref.visible = True


def laser_front(world: World, rules: BeamRules) -> float:
    """How far the laser's housing reaches forward (its -Z) in its own space."""
    mesh_ref = world.try_get(rules.source, MeshRef)
    return -float(mesh_ref.mesh.bounds[0][2]) if mesh_ref is not None else 0.0


def spawn_laser_light(world: World, rules: BeamRules) -> int:
    """The laser's lamp and its barrel, children of the laser (they turn with it): the lamp
    just past the housing's front face, the barrel's four plates from there forward."""
    front = laser_front(world, rules)
    look = Material(color=(0.1, 0.1, 0.12, 1.0), metallic=0.6, roughness=0.35)
    centre = -(front + BARREL_LENGTH / 2.0)
    side = BARREL_HALF + BARREL_WALL / 2.0
    outer = 2.0 * (BARREL_HALF + BARREL_WALL)
    for position, size in (((0.0, side, centre), (outer, BARREL_WALL, BARREL_LENGTH)),
                           ((0.0, -side, centre), (outer, BARREL_WALL, BARREL_LENGTH)),
                           ((side, 0.0, centre), (BARREL_WALL, 2.0 * BARREL_HALF, BARREL_LENGTH)),
                           ((-side, 0.0, centre), (BARREL_WALL, 2.0 * BARREL_HALF, BARREL_LENGTH))):
        world.spawn(Transform(position=position, parent=rules.source), MeshRef(box(size, name="laser barrel")),
                    look, LaserBarrel())
    return world.spawn(Transform(position=(0.0, 0.0, -(front + LAMP_OFFSET)), parent=rules.source),
                       PointLight(color=LAMP_COLOR, intensity=LAMP_INTENSITY, range=LAMP_RANGE, shadows=True,
                                  bounces=min(rules.max_bounces, MAX_LIGHT_BOUNCES), spot_angle=LAMP_SPOT_ANGLE,
                                  spot_blend=0.2), BeamLamp())


def target_points(world: World, target: int) -> list[glm.vec3]:
    """The centres of the target's faces (its mesh's box), a little out from them, world."""
    mesh_ref = world.get(target, MeshRef)
    model = world.get(target, Transform).world
    lo, hi = (glm.vec3(*map(float, b)) for b in mesh_ref.mesh.bounds)
    centre = (lo + hi) * 0.5
    points = []
    for axis in range(3):
        for end in (lo, hi):
            face = glm.vec3(centre)
            face[axis] = end[axis]
            out = glm.vec3(0.0)
            out[axis] = 1.0 if end is hi else -1.0
            world_face = glm.vec3(model * glm.vec4(face, 1.0))
            normal = glm.normalize(glm.vec3(model * glm.vec4(out, 0.0)))
            points.append(world_face + normal * TARGET_PROBE_OUT)
    return points


def reflected_light(world: World, surfaces: Surfaces) -> list[VirtualLight]:
    """The laser lamp's virtual lights through this frame's mirrors (the shadows stage's rules)."""
    found: list[VirtualLight] = []
    for entity, (light, transform, _) in world.query(PointLight, Transform, BeamLamp):
        rgb = glm.vec3(light.color) * light.intensity
        found += virtual_lights([], [(entity, glm.vec3(transform.world[3]), light.range, rgb,
                                      lamp_cone(light, transform.world))], surfaces,
                                {entity: light.bounces})
    return found


# What the laser's light is cast against and from: a change to any of them works it out again.
LIGHT_WAY_KINDS = (MeshRef, Transform, PointLight)


def light_system(world: World, state: BeamState) -> None:
    """Whether the laser's reflected light reaches the target this frame: a virtual light of
    the lamp lights a point of the target's faces (``shadow_rules.light_path``, the shader's
    aperture test) and no solid stands on any leg of its way (the engine's ray cast)."""
    surfaces = world.resources.get(Surfaces)
    if surfaces is None:
        return
    rules = state.rules
    # Worked out again only when a mirror changed (a new SurfaceState) or anything the light's
    # way is cast against may have, by the world's change sets (nothing a frame when all stands
    # still): a mesh, a transform or a lamp written or an entity deleted this step, or a world
    # matrix the transform stage moved last frame (a parent's move, an animation, a stage that
    # runs after the game's update).
    mirrors = tuple(surfaces.mirrors.values())
    frame = world.frame
    touched = world.changed_any(LIGHT_WAY_KINDS) or world.deleted() or frame.moved or frame.added or frame.removed
    if state.light_seen and not touched and len(mirrors) == len(state.light_seen[0]) and \
            all(a is b for a, b in zip(mirrors, state.light_seen[0], strict=True)):
        return
    state.light_seen = (mirrors,)
    cast = first_solid(world)
    lit_by: tuple[int, ...] = ()
    for light in sorted(reflected_light(world, surfaces), key=lambda v: v.bounces):
        for point in target_points(world, rules.target):
            way = light_path(light, point)
            if way is not None and _clear(cast, way, light.light):
                lit_by = light.path
                break
        if lit_by:
            break
    state.lit, state.lit_by = bool(lit_by), lit_by


def _clear(cast: FirstSolid, way: list, lamp: int) -> bool:
    """No solid on any leg of ``way`` (its corners, the target's point first)."""
    for start, end in zip(way, way[1:], strict=False):
        a, b = glm.vec3(*start), glm.vec3(*end)
        length = glm.distance(a, b)
        if length < 1e-6:
            continue
        hit = cast(a, (b - a) / length, None)
        if hit is not None and hit[0] < length - 1e-4:
            return False
    return True


def win_system(world: World, state: BeamState) -> None:
    """The laser's light on the target: the win event (once until a restart) and the target glows."""
    if state.won or not state.lit:
        return
    state.won = True
    world.get(state.rules.target, Emissive).power = WIN_GLOW
    state.events.append(BeamEvent("win", state.frame, {"level": state.level_name,
                                                       "bounces": len(state.lit_by)}))


def marker_system(world: World, state: BeamState) -> None:
    """The selection light hovers over the selected mirror (hidden once solved)."""
    mirror = state.rules.rotatable[state.selected]
    transform = world.get(mirror, Transform)
    top = float(world.get(mirror, MeshRef).mesh.bounds[1][1] * transform.scale.y)
    for _, (_, marker_t, marker_mesh) in world.query(SelectionMarker, Transform, MeshRef):
        position = transform.position + glm.vec3(0.0, top + 0.2, 0.0)
        if marker_t.position != position:
            marker_t.position = position
        if marker_mesh.visible == state.won:
            marker_mesh.visible = not state.won


def caption_system(world: World, state: BeamState, has_next: bool) -> None:
    """The caption says the level's name, and "solved" (with the keys) once it is."""
    if state.won:
        keys = "n: next, r: restart" if has_next else "r: restart"
        wanted = f"{state.level_name}: solved! ({keys})"
    else:
        wanted = state.level_name
    for _, (text, _) in world.query(ScreenText, Caption):
        if text.text != wanted:
            text.text = wanted


# --- the game -----------------------------------------------------------------------------

def solution_script(rules: BeamRules, interval: int = 1) -> list[list[str]]:
    """The key presses that solve a level from its start, one frame each, ``interval`` frames
    apart: a mirror's number key, then its turns (left for + steps, right for - steps)."""
    script: list[list[str]] = [[] for _ in range(interval)]
    for mirror, steps in rules.solution.items():
        for keys in [[str(rules.rotatable.index(mirror) + 1)]] + [["left" if steps > 0 else "right"]] * abs(steps):
            script.append(keys)
            script.extend([] for _ in range(interval - 1))
    return script


class MirrorBeam(LevelGame):
    """The puzzle on one level file (``level``; the first shipped level by default).

    ``autopilot`` plays the level's ``rules.solution`` through the ``Input`` resource, one
    key every ``interval`` frames, as a scripted player would (headless runs show the puzzle
    being solved)."""

    title = "Speculum: mirror beam"
    size = (960, 540)
    game = "mirror_beam"  # a level file's [level] game
    makes_camera = True  # rules.camera places one when the level has none

    def __init__(self, level: str | Path | None = None, autopilot: bool = False, interval: int = 1,
                 verbose: bool = True) -> None:
        super().__init__(level if level is not None else levels()[0])
        self.autopilot = autopilot
        self.interval = max(1, int(interval))
        self.verbose = verbose  # print a line when a puzzle is solved
        self.state: BeamState | None = None
        self.script: list[list[str]] = []

    def build(self, world: World) -> None:
        level = self.level = self.load()
        self.title = f"Speculum: mirror beam: {level.name}"  # the window's title follows the level ('n')
        names = self.names = level.spawn(world)
        rules = parse_rules(level.rules, names, world, f"level file {str(self.level_path)!r}")
        if not world.query_one(Camera):
            eye, at = glm.vec3(rules.camera["position"]), glm.vec3(rules.camera["look_at"])
            yaw, pitch = yaw_pitch_of(at - eye)
            spawn_camera(world, position=eye, yaw=yaw, pitch=pitch, fly=False)
        for camera, _ in world.query_one(Camera):
            # Khronos PBR Neutral (it keeps the red beam and the green target their colours,
            # which ACES and AgX wash toward white when bright), and the beam, the lit target
            # and the marker glowing, directly and in the mirrors; unless the level file says
            # how its camera looks.
            if not world.has(camera, Tonemap) and not world.has(camera, Bloom):
                world.add_component(camera, Tonemap(curve="pbr_neutral"))
                world.add_component(camera, Bloom(intensity=0.5, threshold=0.8, composite="additive"))
        # The laser's light is reflected by every mirror, as many times in a row as the level
        # allows and the engine follows (a light goes no deeper than a mirror's max_depth, as
        # its views); the sun by none (the puzzle's light is the laser's).
        bounces = min(rules.max_bounces, MAX_LIGHT_BOUNCES)
        for _, mirror in world.query_one(Mirror):
            mirror.reflects_light = True
            mirror.max_depth = max(mirror.max_depth, bounces)
        for _, sun in world.query_one(DirectionalLight):
            sun.bounces = 0
        spawn_laser_light(world, rules)
        target = world.try_get(rules.target, Emissive)
        if target is None:
            target = Emissive(0.0)
            world.add_component(rules.target, target)
        frame_look = Material(color=(0.12, 0.12, 0.14, 1.0), metallic=0.5, roughness=0.4)
        for entity, (_, mesh_ref) in world.query(Mirror, MeshRef):
            # A dark frame just behind each mirror: a quad has one side (the back is culled), so
            # without it a mirror seen from behind would vanish; the beam stops at it.
            lo, hi = mesh_ref.mesh.bounds
            w, h = float(hi[0] - lo[0]), float(hi[1] - lo[1])
            world.spawn(Transform(position=(0.0, 0.0, -FRAME_DEPTH / 2 - 0.005), parent=entity),
                        MeshRef(box((w + 0.08, h + 0.08, FRAME_DEPTH), name="mirror frame")), frame_look,
                        MirrorFrame(entity))
        unit = box((1.0, 1.0, 1.0), name="beam")
        look = Material(color=BEAM_COLOR, roughness=1.0)
        glow = Emissive(BEAM_POWER)
        for index in range(rules.max_bounces + 1):
            # Light, not a solid: the beam casts no shadow (MeshRef.casts_shadows).
            world.spawn(Transform(scale=(BEAM_WIDTH, BEAM_WIDTH, 1.0)),
                        MeshRef(unit, visible=False, casts_shadows=False), look, glow, BeamSegment(index))
        world.spawn(Transform(), MeshRef(box((0.3, 0.06, 0.3), name="marker")),
                    Material(color=(1.0, 0.85, 0.2, 1.0)), Emissive(2.0), SelectionMarker())
        # The level's name on the screen, over a dark panel; the beam system adds "solved".
        world.spawn(ScreenText(level.name, position=(14, 14), color=(1.0, 0.95, 0.8, 1.0),
                               background=(0.0, 0.0, 0.0, 0.55)), Caption())
        self.state = BeamState(rules, level.name,
                               {m: glm.quat(world.get(m, Transform).rotation) for m in rules.rotatable},
                               target.power)
        world.resources[BeamState] = self.state
        self.script = solution_script(rules, self.interval) if self.autopilot else []

    def next_level(self) -> Path | None:
        """The shipped level after this one (the first after the last); None for a level file
        from elsewhere."""
        shipped = [p.resolve() for p in levels()]
        here = self.level_path.resolve()
        return shipped[(shipped.index(here) + 1) % len(shipped)] if here in shipped else None

    def play_level(self, world: World, level: Path) -> None:
        """Replace the level being played: every entity goes (deleted at the next step, and
        left out of queries until then) and ``level`` is built in the same world."""
        for entity in world.entities():
            world.delete_entity(entity)
        self.level_path = Path(level)
        self.build(world)

    def needs(self, world: World, entity: int, component: str | None = None) -> str | None:
        """The beam's source, its target and the mirrors the player turns: the game's rules
        name them, and its systems trace and turn them (their Transform, mesh and Mirror)."""
        rules = self.state.rules
        roles = {rules.source: "the beam's source", rules.target: "the beam's target",
                 **{mirror: "a mirror the player turns" for mirror in rules.rotatable}}
        role = roles.get(entity)
        if role is None or component not in (None, "Transform", "MeshRef", "Mirror", "Emissive"):
            return None
        what = "it" if component is None else f"its {component}"
        return f"mirror beam cannot do without {what}: it is {role} (the level's rules name it)"

    def systems(self) -> list[GameSystem]:
        """The beam, traced with this frame's ``Surfaces`` (so after the surfaces stage) and
        drawn this frame (so before extract)."""
        return [GameSystem(self.beam, after="surfaces", before="extract", name="beam")]

    def update(self, world: World, dt: float) -> None:
        """The game stage: the autopilot's keys, then the player's input (mirrors turn,
        restart, the next level)."""
        state = self.state
        keys = world.resources[Input]
        if 0 < state.frame <= len(self.script):
            keys.release(*self.script[state.frame - 1])
        if state.frame < len(self.script):
            keys.press(*self.script[state.frame])
        input_system(world, state)
        if state.next_asked:
            state.next_asked = False
            following = self.next_level()
            if following is not None:
                self.play_level(world, following)  # the beam system traces its beam this frame

    def beam(self, world: World, dt: float) -> None:
        """The beam system: trace, win, the selection marker; the frame's last game work."""
        state = self.state
        beam_system(world, state)
        light_system(world, state)
        solved = state.won
        win_system(world, state)
        if state.won and not solved and self.verbose:
            keys = "press n for the next level, r to restart" if self.next_level() is not None \
                else "press r to restart"
            bounces = state.wins()[-1].detail["bounces"]
            print(f"mirror_beam: solved: {state.level_name} with {bounces} bounce{'s' * (bounces != 1)} "
                  f"(frame {state.frame}; {keys})", flush=True)
        marker_system(world, state)
        caption_system(world, state, self.next_level() is not None)
        state.frame += 1
