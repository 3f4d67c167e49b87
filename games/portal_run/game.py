"""Portal run: a first-person walk to an exit that cannot be reached on foot, through two
portals the player shoots onto the level's walls.

A level file places the room (every entity with a mesh is solid unless the rules say not),
the exit pad, and says in ``[rules]`` where the player starts, which walls take portals and
how big portals are (``load_rules`` lists them all).  Each frame runs, in order:

* the game stage (``update``):
  * ``travelled``: a crossing the travel stage made last frame (``PortalCrossings``) turned
    the player's camera; the game turns the player's velocity by the same rotation and reads
    its heading back from the new orientation, so momentum goes out of the exit portal;
  * the frame's input: mouse look now, key presses and clicks kept for the next physics step;
* the game's "physics" system (``PortalRun.systems``), after the game stage and before the
  engine's rules stage: the body moves in fixed steps of ``PHYSICS_STEP`` (as many as the
  frame's time holds, the rest carried to the next frame), so the game plays the same at
  any frame rate or ``--dt``; the autopilot gives its input every ``SCRIPT_STEPS`` steps (a
  script counts 60ths of a second).  Each step, with its input:
  * ``restart``: 'r' (or falling below ``kill_y``) deletes everything and builds the level
    again from its file; 'n' after a win plays the next shipped level;
  * ``move``: WASD on the ground (air control in the air), gravity and jumping, then the body
    (an AABB, ``games.portal_run.physics``) is moved through the level's solids; the wall a
    portal sits on lets the body through while it is in front of the portal's opening, so
    the camera can reach the portal plane;
  * ``place portals``: a left / right click casts a ray from the eye (``engine.rules.raycast``)
    and places portal A / B on the wall (or, where the rules allow, the floor) it hits, or
    refuses it (a red marker flashes at the hit and a 'refused' event names the reason);
  * ``win``: the body touching the exit pad records a 'win' event once and lights the pad.

The engine's portal travel system carries the camera (the player) through an open pair in
the same frame, before anything is drawn, so there is no frame with the player on both
sides; the game never teleports the player itself.  That is why physics runs where it does:
before travel, so a step that takes the eye through a portal's opening stops the frame's
steps and travel carries the eye at once (the steps left run from the other side next
frame); and before the rules stage, so a portal placed by a step is open to this frame's
travel, views and slicing (the rules stage works out the open pairs once a frame).
"""
from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pyglm import glm

from components import (
    Bloom,
    Camera,
    Emissive,
    Material,
    MeshRef,
    Portal,
    ScreenText,
    Tonemap,
    Transform,
    look_rotation,
    yaw_pitch_rotation,
)
from components.transform import heading
from engine.assets.level_file import LevelGame
from engine.assets.mesh import box, quad
from engine.assets.portals import spawn_portal_pair
from engine.core.errors import SpeculumError
from engine.core.frame_io import Input
from engine.core.game import GameSystem
from engine.core.world import World
from engine.resources import PortalCrossings
from engine.rules.raycast import shared_caster
from games.portal_run.autopilot import Autopilot, ScriptError, parse_script
from games.portal_run.physics import BodyShape, Solid, move_body

LEVEL_DIR = Path(__file__).parent / "levels"

# Body and motion (metres, seconds).
HALF_WIDTH = 0.3
HEIGHT = 1.8
EYE_HEIGHT = 1.6
WALK_SPEED = 4.5
AIR_ACCEL = 8.0
GRAVITY = 15.0
JUMP_SPEED = 5.5  # about a metre high: no ledge in the levels is that low
EXIT_SPEED = 2.0  # m/s: the least speed out of an exit portal until the body is clear of its wall
MOUSE_SENSITIVITY = 0.15  # degrees per pixel

# Time.  The body moves in fixed steps whatever the frame's dt, so a level plays the same at
# 30, 60 or 144 frames a second and at ``--dt 0.1``: a frame runs as many steps as its time
# holds (the rest carries over), at most MAX_STEPS (a slower frame plays the game slower
# rather than in coarser steps).  A scripted player (the autopilot) gives its input once
# every SCRIPT_STEPS steps: a script's frame counts are 60ths of a second at any frame rate.
PHYSICS_STEP = 1.0 / 120.0
MAX_STEPS = 30  # 0.25 s of game time a frame at most
SCRIPT_STEPS = 2  # physics steps per autopilot frame (1/60 s)

# Portals.
REACH = 60.0  # m: how far a portal shot goes
PORTAL_OFFSET = 0.01  # m off the wall, so the portal never fights the wall for depth
RIM = 0.08  # m of coloured frame round a placed portal
CORNER_INSET = 0.03  # m: the fit test's probe points are this far inside the portal's edges
FRONT_CLEARANCE = 0.3  # m in front of a portal that must be free of solids
WALL_SLOPE = 0.05  # |normal.y| above this is a floor, ceiling or slope: no portals
PORTAL_COLORS = ((0.15, 0.45, 1.0), (1.0, 0.45, 0.05))  # A blue, B orange
REFUSED_SECONDS = 0.65  # how long the red marker of a refused shot shows
REFUSED_COLOR = (1.0, 0.05, 0.03)
WIN_GLOW = 10.0  # HDR: the won pad flashes ten times brighter than white (and glows)
DEFAULT_PORTAL_SIZE = (1.2, 2.0)
CROSSHAIR_DISTANCE = 0.06  # m in front of the eye (the camera's near plane is 0.05)
CROSSHAIR_SIZE = 0.0012  # m: about 1.5% of the view's height at that distance


class LevelRulesError(SpeculumError, ValueError):
    """A level's [rules] table that the game cannot play (names the file, the rule and why)."""


class CoarseCollisionWarning(UserWarning):
    """A solid turned off the world axes: the body collides with its world-axis bounding box
    (``games.portal_run.physics`` is axis-aligned), which is larger than the solid."""


def off_axis(world: World, entity: int) -> bool:
    """Whether ``entity`` is turned off the world axes (by any rotation but quarter turns),
    its rotation composed up its parents (from the Transforms themselves: a level just built
    has no world matrices until the transform stage runs)."""
    rotation = glm.quat()
    seen: set[int] = set()
    while entity and entity not in seen and world.exists(entity):
        seen.add(entity)
        transform = world.try_get(entity, Transform)
        if transform is None:
            break
        rotation = glm.quat(transform.rotation) * rotation
        entity = transform.parent or 0
    columns = np.array([list(column) for column in glm.mat3_cast(rotation)], np.float64)
    return bool((np.abs(columns).max(axis=1) < 1.0 - 1e-4).any())


def levels() -> list[Path]:
    """The shipped level files, easiest first."""
    return sorted(LEVEL_DIR.glob("*.toml"))


# --- plain data ---------------------------------------------------------------------------

@dataclass
class RunRules:
    """A level's rules, checked (``load_rules``)."""

    exit: str
    start: tuple[float, float, float]  # the player's feet
    yaw: float = 0.0
    pitch: float = 0.0
    portal_walls: tuple[str, ...] | None = None  # None: every solid wall
    portal_floors: bool = False  # portals also go on floors (upward faces) of those walls
    not_solid: tuple[str, ...] = ()
    portal_size: tuple[float, float] = DEFAULT_PORTAL_SIZE
    kill_y: float = -20.0
    solution: tuple[str, ...] = ()
    portal_light: bool = True  # the placed portals carry light (Portal.carries_light)


@dataclass
class PlayerBody:
    """The player's own state (the camera entity carries it): heading, velocity, contact."""

    yaw: float = 0.0
    pitch: float = 0.0
    velocity: Any = field(default_factory=lambda: np.zeros(3))
    on_ground: bool = False
    rotation: Any = field(default_factory=glm.quat)  # the orientation the game last wrote
    exit_portal: int | None = None  # index of the portal just come out of, while the body is still in its wall
    mouse_sensitivity: float = MOUSE_SENSITIVITY


@dataclass
class PlacedPortal:
    """Where a portal sits: its wall, centre on the wall's face, and its axes."""

    host: int
    center: np.ndarray
    right: np.ndarray
    up: np.ndarray
    normal: np.ndarray


@dataclass(frozen=True)
class RunEvent:
    """Something that happened: 'placed', 'refused', 'travelled', 'win', 'restart', 'fell'."""

    kind: str
    frame: int
    detail: str = ""
    portal: int | None = None  # 0 for A, 1 for B
    point: tuple[float, float, float] | None = None


def body_heading(rotation: glm.quat) -> tuple[float, float]:
    """(yaw, pitch) in degrees of the direction an orientation looks (``heading``: its -Z,
    roll dropped), the pitch kept within the body's +-89 degrees."""
    yaw, pitch = heading(rotation)
    return yaw, max(-89.0, min(89.0, pitch))


# --- rules ----------------------------------------------------------------------------------

def load_rules(rules: dict[str, Any], names: dict[str, int], where: str) -> RunRules:
    """Check a level's [rules]: every name must be an entity of the level, numbers finite.

    Rules: ``exit`` (entity name, required), ``start`` ([x, y, z] of the feet, required),
    ``yaw`` / ``pitch`` (degrees), ``portal_walls`` (entity names, or "all"), ``portal_floors``
    (true: their upward faces take portals too), ``portal_light`` (true, the default: the
    portals the player places carry the lights in front of them out of the other one,
    ``Portal.carries_light``), ``not_solid``
    (entity names the body passes through), ``portal_size`` ([w, h] m), ``kill_y`` (falling
    below it restarts), ``solution`` (autopilot commands that win the level)."""
    def fail(rule: str, why: str) -> LevelRulesError:
        return LevelRulesError(f"{where}: rule {rule!r} {why}")

    known = {"exit", "start", "yaw", "pitch", "portal_walls", "portal_floors", "not_solid", "portal_size", "kill_y",
             "solution", "portal_light"}
    unknown = sorted(set(rules) - known)
    if unknown:
        raise fail(unknown[0], f"is not a portal_run rule (known: {', '.join(sorted(known))})")

    def number(rule: str, value: Any, low: float = -1e6, high: float = 1e6) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                or not low <= value <= high:
            raise fail(rule, f"must be a number in [{low:g}, {high:g}], got {value!r}")
        return float(value)

    def vector(rule: str, value: Any, n: int, low: float = -1e6, high: float = 1e6) -> tuple[float, ...]:
        if not isinstance(value, list) or len(value) != n:
            raise fail(rule, f"must be a list of {n} numbers, got {value!r}")
        return tuple(number(rule, v, low, high) for v in value)

    def entity_names(rule: str, value: Any) -> tuple[str, ...]:
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise fail(rule, f"must be a list of entity names, got {value!r}")
        for name in value:
            if name not in names:
                raise fail(rule, f"names {name!r}, which is no entity of the level")
        return tuple(value)

    if "exit" not in rules:
        raise fail("exit", "is missing (the name of the exit pad entity)")
    exit_name = rules["exit"]
    if not isinstance(exit_name, str) or exit_name not in names:
        raise fail("exit", f"must name an entity of the level, got {exit_name!r}")
    if "start" not in rules:
        raise fail("start", "is missing ([x, y, z] where the player's feet start)")
    out = RunRules(exit=exit_name, start=vector("start", rules["start"], 3))
    if "yaw" in rules:
        out.yaw = number("yaw", rules["yaw"], -360.0, 360.0)
    if "pitch" in rules:
        out.pitch = number("pitch", rules["pitch"], -89.0, 89.0)
    walls = rules.get("portal_walls", "all")
    out.portal_walls = None if walls == "all" else entity_names("portal_walls", walls)
    out.not_solid = entity_names("not_solid", rules.get("not_solid", []))
    floors = rules.get("portal_floors", False)
    if not isinstance(floors, bool):
        raise fail("portal_floors", f"must be true or false, got {floors!r}")
    out.portal_floors = floors
    light = rules.get("portal_light", True)
    if not isinstance(light, bool):
        raise fail("portal_light", f"must be true or false, got {light!r}")
    out.portal_light = light
    if "portal_size" in rules:
        out.portal_size = vector("portal_size", rules["portal_size"], 2, 0.5 + 2 * CORNER_INSET, 20.0)
        if out.portal_size[0] < 2 * HALF_WIDTH + 0.1 or out.portal_size[1] < HEIGHT + 0.1:
            raise fail("portal_size", f"must let the player through (at least {2 * HALF_WIDTH + 0.1:g} x "
                                      f"{HEIGHT + 0.1:g} m), got {rules['portal_size']!r}")
    if "kill_y" in rules:
        out.kill_y = number("kill_y", rules["kill_y"])
    if out.kill_y >= out.start[1]:
        raise fail("kill_y", f"must be below the start ({out.start[1]:g}), got {out.kill_y:g}")
    try:
        out.solution = tuple(s for s in rules.get("solution", []))
        parse_script(list(out.solution), f"{where}: rule 'solution'")
    except (ScriptError, TypeError) as exc:
        raise LevelRulesError(str(exc)) from None
    return out


# --- the game ---------------------------------------------------------------------------------

class PortalRun(LevelGame):
    """One level of portal run, from a level file (``engine.assets.level_file``).

    ``autopilot=True`` plays the level's ``solution`` (headless runs with no person);
    ``events`` lists every RunEvent since the game was built (restarts included);
    ``show_caption=False`` leaves the level's name and time off the screen."""

    title = "portal run"
    size = (1280, 720)
    game = "portal_run"  # a level file's [level] game
    makes_camera = True  # the player is the camera
    mouse_look = True  # the window shell captures the pointer on the first click (shell/window.py)

    def __init__(self, level: str | Path | None = None, autopilot: bool = False,
                 script: Sequence[str] | None = None, verbose: bool = True, show_caption: bool = True) -> None:
        super().__init__(level if level is not None else levels()[0])
        self.level = self.load()  # checked now: a bad file is an error before any window opens
        self.title = f"portal run: {self.level.name}"
        self.verbose = verbose
        self.show_caption = show_caption  # the level's name and time on the screen
        self.caption: int | None = None
        self.elapsed = 0.0
        self.events: list[RunEvent] = []
        self.pilot: Autopilot | None = None
        self._want_pilot = autopilot
        self._script_source = script  # None: the level's own solution
        self.won = False
        self.frame = 0

    # --- build / restart -----------------------------------------------------------------------
    def needs(self, world: World, entity: int, component: str | None = None) -> str | None:
        """The level's solids (the body stands on and portals open on them, by ray casts
        against their meshes) and its exit pad: held from the build."""
        if entity != self.exit and entity not in self.solids:
            return None
        if component not in (None, "Transform", "MeshRef"):
            return None
        what = "it" if component is None else f"its {component}"
        role = "the exit pad" if entity == self.exit else "a solid the body stands on and portals open on"
        return f"portal run cannot do without {what}: it is {role} (the level's physics holds it from its start)"

    def build(self, world: World) -> None:
        self.world = world
        where = f"level file {str(self.level_path)!r}"
        super().build(world)  # loads the file again (a restart reads it afresh) and spawns it: self.names
        self.rules = load_rules(dict(self.level.rules), self.names, where)
        if self._want_pilot and self.pilot is None:
            self.pilot = Autopilot(self._script_source if self._script_source is not None else self.rules.solution,
                                   f"{where}: rule 'solution'")
        self.caster = shared_caster(world)
        level_entities = set(self.names.values())
        skip = {self.names[n] for n in self.rules.not_solid}
        self.solids = {e for e in level_entities if world.has(e, MeshRef) and world.has(e, Transform)} - skip
        self.portal_walls = self.solids if self.rules.portal_walls is None else \
            {self.names[n] for n in self.rules.portal_walls}
        for name in self.rules.portal_walls or ():
            if self.names[name] not in self.solids:
                raise LevelRulesError(f"{where}: rule 'portal_walls' names {name!r}, which is not solid (it needs a "
                                      "MeshRef and a Transform and must not be in not_solid)")
        self.exit = self.names[self.rules.exit]
        if not (world.has(self.exit, MeshRef) and world.has(self.exit, Transform)):
            raise LevelRulesError(f"{where}: rule 'exit' names {self.rules.exit!r}, which has no MeshRef and "
                                  "Transform (the pad is where its mesh is)")
        self.shape = BodyShape.standing(HALF_WIDTH, HEIGHT, EYE_HEIGHT)
        r = self.rules
        body = PlayerBody(yaw=r.yaw, pitch=r.pitch, rotation=yaw_pitch_rotation(r.yaw, r.pitch))
        eye = (r.start[0], r.start[1] + EYE_HEIGHT, r.start[2])
        # Khronos PBR Neutral: it keeps the colours the rules are read by (cyan and orange
        # rims, the green pad, the red refusal marker), which ACES and AgX wash toward white
        # when bright; and a glow round what is brighter than white (rims, the won pad).
        self.player = world.spawn(Transform(position=eye, rotation=body.rotation), Camera(fov_y=70.0, near=0.05),
                                  Tonemap(curve="pbr_neutral"),
                                  Bloom(intensity=0.5, threshold=1.0, composite="additive"), body)
        # A crosshair: a small bright dot just past the near plane, a child of the camera.
        self.crosshair = world.spawn(Transform(position=(0.0, 0.0, -CROSSHAIR_DISTANCE), parent=self.player),
                                     MeshRef(quad(CROSSHAIR_SIZE, CROSSHAIR_SIZE, name="crosshair")),
                                     Material(color=(1.0, 1.0, 1.0, 1.0), roughness=1.0), Emissive(1.0))
        w, h = r.portal_size
        hidden = (0.0, -1000.0, 0.0)
        self.portals = spawn_portal_pair(world, hidden, None, (5.0, -1000.0, 0.0), None, size=(w, h))
        self.rims = []
        for portal, rgb in zip(self.portals, PORTAL_COLORS, strict=True):
            p = world.get(portal, Portal)
            p.enabled = False
            p.carries_light = self.rules.portal_light
            p.closed_color = (*(0.35 * c for c in rgb), 1.0)
            world.get(portal, MeshRef).visible = False
            self.rims.append(world.spawn(Transform(position=(0.0, 0.0, -0.4 * PORTAL_OFFSET), parent=portal),
                                         MeshRef(quad(w + 2 * RIM, h + 2 * RIM, name="portal_rim"), visible=False),
                                         Material(color=(*rgb, 1.0), roughness=1.0), Emissive(1.5)))
        self.placed: list[PlacedPortal | None] = [None, None]
        self.marker = world.spawn(Transform(position=hidden), MeshRef(box((0.5, 0.5, 0.5)), visible=False),
                                  Material(color=(*REFUSED_COLOR, 1.0), roughness=1.0), Emissive(0.5))
        self.marker_time = 0.0  # seconds the refused marker still shows
        # The level's name and the time on the screen, top left over a dark panel (unless show_caption is off).
        self.elapsed = 0.0  # seconds of game time since the build (stopped by a win)
        self.caption = world.spawn(ScreenText(self.caption_text(), position=(14, 14), color=(1.0, 1.0, 1.0, 1.0),
                                              background=(0.0, 0.0, 0.0, 0.55))) if self.show_caption else None
        self._exit_glow = world.try_get(self.exit, Emissive)
        self.won = False
        self.travels = 0
        self._consumed: object = None  # the PortalCrossings list already taken in
        self._exiting: int | None = None  # the portal the body is coming out of, during a move
        self._in_front: set[int] = set()  # portals the eye was in front of when the move started
        self._boxes: tuple[int, list[Solid]] | None = None  # (frame, solid boxes) of the latest frame
        self._axes_checked = False  # off-axis solids reported (once a build, from world matrices)
        self._clock = 0.0  # game time not yet run as a physics step
        self._steps = 0  # physics steps since the build (the autopilot gives input every SCRIPT_STEPS)
        self._pending = Input()  # the person's input for the next step
        self._script = Input()  # the autopilot's input of its current frame
        self._moved_in_frame = -1  # the frame whose first move decided self._in_front
        self._came_out_of: set[int] = set()  # portals the player came out of last frame (closed to it this frame)

    def restart(self, world: World, why: str = "restart") -> None:
        """Delete everything and build the level again from its file (the autopilot goes on)."""
        for entity in world.entities():
            world.delete_entity(entity)
        self.build(world)
        self._event(why, "level reloaded")

    # --- per frame ---------------------------------------------------------------------------
    def systems(self) -> list[GameSystem]:
        """The body's physics, after the game stage and before the rules stage (and so before
        travel): see the module's docstring."""
        return [GameSystem(self.physics, after="game", before="rules", name="physics")]

    def update(self, world: World, dt: float) -> None:
        """The game stage: follow last frame's crossing and take the frame's input (the
        physics system then runs its steps)."""
        self.frame += 1
        person: Input = world.resources[Input]
        self._travelled(world)  # first: this frame's turning starts from the heading the portal gave
        # The frame's edges (presses, clicks) wait for the next step, even past a frame too
        # short to hold one; its mouse motion turns the view now.
        self._pending.pressed |= person.pressed
        self._pending.clicks |= person.clicks
        self._pending.held = set(person.held)
        if self._piloted() is None and (person.mouse_dx or person.mouse_dy):
            self._look(world, person.mouse_dx, person.mouse_dy)
        self._flash(world, dt)
        if not self.won:
            self.elapsed += dt
        caption = world.try_get(self.caption, ScreenText) if self.caption is not None else None
        if caption is not None and caption.text != self.caption_text():
            caption.text = self.caption_text()

    def caption_text(self) -> str:
        """What the screen says: the level's name and its time (complete: the time it took)."""
        if self.won:
            return f"{self.level.name}: complete in {self.elapsed:.1f} s"
        return f"{self.level.name}   {self.elapsed:.1f} s"

    def physics(self, world: World, dt: float) -> None:
        """The physics system: the fixed steps ``dt`` holds (``PHYSICS_STEP``; see the
        constants), each with its input."""
        steps = self._take_steps(dt)
        for done in range(1, steps + 1):
            outcome = self._step(world)
            if outcome == "rebuilt":
                # The level was built again (restart, fall, next level): the frame goes on as
                # a fresh game's first frame does, with no input.
                for _ in range(self._take_steps(dt)):
                    self._step(world, quiet=True)
                break
            if outcome in ("crossed", "held"):
                # The eye went through an open portal: the travel stage carries it at the end
                # of this frame, and the frame's steps left run from the other side next frame.
                # Or it would have gone back into the portal it came out of last frame, which
                # the travel stage does not allow (no ping-pong): that step is run next frame.
                left = steps - done + (outcome == "held")
                self._clock = min(self._clock + left * PHYSICS_STEP, MAX_STEPS * PHYSICS_STEP)
                break

    def _piloted(self) -> Autopilot | None:
        """The autopilot while it has commands left (then the person's input plays)."""
        return self.pilot if self.pilot is not None and not self.pilot.done else None

    def _take_steps(self, dt: float) -> int:
        """How many physics steps ``dt`` more of game time makes (the rest is kept)."""
        self._clock = min(self._clock + dt, MAX_STEPS * PHYSICS_STEP)
        steps = int(self._clock / PHYSICS_STEP + 1e-6)
        self._clock = max(0.0, self._clock - steps * PHYSICS_STEP)
        return steps

    def _step(self, world: World, quiet: bool = False) -> str | None:
        """One physics step with its input (the autopilot's, or the person's: the frame's edges
        on its first step, held keys on every step; none when ``quiet``).  Returns "rebuilt"
        when the level was built again, "crossed" when the eye went through an open portal's
        opening (the travel stage carries it after the game stage), else None."""
        if quiet:
            state = Input()
        elif self._piloted() is not None:
            if self._steps % SCRIPT_STEPS == 0:
                self._script = Input()
                self.pilot.fill(self._script, self)
                state = self._script
                self._look(world, state.mouse_dx, state.mouse_dy)
            else:
                state = Input(held=set(self._script.held))
        else:
            state, self._pending = self._pending, Input(held=set(self._pending.held))
        self._steps += 1
        if "r" in state.pressed:
            self.restart(world)
            return "rebuilt"
        if self.won and "n" in state.pressed:
            following = self.next_level()
            if following is not None:
                self.play_level(world, following)
                return "rebuilt"
        transform = world.get(self.player, Transform)
        body = world.get(self.player, PlayerBody)
        before = np.array(transform.position, np.float64)
        kept = (transform.position, np.array(body.velocity), body.on_ground, body.exit_portal)
        self._move(world, state, PHYSICS_STEP)
        after = np.array(transform.position, np.float64)
        if after[1] < self.rules.kill_y:
            self.restart(world, "fell")
            return "rebuilt"
        through = self._through_portal(before, after)
        if through is not None and through in self._came_out_of:
            transform.position, body.velocity, body.on_ground, body.exit_portal = kept
            through = "held"
        for index, button in enumerate(("left", "right")):
            if button in state.clicks:
                self.place(world, index)
        self._check_win(world)
        return through if through == "held" else "crossed" if through is not None else None

    def _through_portal(self, before: np.ndarray, after: np.ndarray) -> int | None:
        """The open portal (0 = A, 1 = B) whose opening the eye went through from front to back
        between ``before`` and ``after``, or None."""
        if None in self.placed:
            return None  # a lone portal is closed
        w, h = self.rules.portal_size
        for index, placed in enumerate(self.placed):
            plane = placed.center + placed.normal * PORTAL_OFFSET
            d0, d1 = float((before - plane) @ placed.normal), float((after - plane) @ placed.normal)
            if d0 >= 0.0 > d1:
                hit = before + (after - before) * (d0 / (d0 - d1)) - plane
                if abs(float(hit @ placed.right)) <= w / 2 and abs(float(hit @ placed.up)) <= h / 2:
                    return index
        return None

    def next_level(self) -> Path | None:
        """The shipped level after this one (the first after the last); None for a level file
        from elsewhere."""
        shipped = [p.resolve() for p in levels()]
        here = self.level_path.resolve()
        return shipped[(shipped.index(here) + 1) % len(shipped)] if here in shipped else None

    def play_level(self, world: World, level: str | Path) -> None:
        """Play ``level`` from its start in the same world ('n' after a win: the next level).
        An autopilot playing a level's own solution plays the new level's."""
        self.level_path = Path(level)
        self.level = self.load()
        self.title = f"portal run: {self.level.name}"
        for entity in world.entities():
            world.delete_entity(entity)
        if self._script_source is None:
            self.pilot = None  # build makes the new level's
        self.build(world)
        self._event("next", self.level.name)
        if self.verbose:
            print(f"portal_run: next level: {self.level.name}", flush=True)

    # --- Pilotable ----------------------------------------------------------------------------
    def player_view(self) -> tuple[tuple[float, float, float], float, float, float]:
        """Eye, heading (read from the camera's orientation, which a portal may have turned
        since the game last wrote it) and mouse sensitivity, for a scripted player."""
        transform = self.world.get(self.player, Transform)
        eye = transform.position
        yaw, pitch = body_heading(transform.rotation)
        return (eye.x, eye.y, eye.z), yaw, pitch, self.world.get(self.player, PlayerBody).mouse_sensitivity

    def travel_count(self) -> int:
        """Crossings so far, counting one the travel stage made last frame that this frame's
        update has not taken in yet (a script filling the input before the frame sees it)."""
        crossings = self.world.resources.get(PortalCrossings) or ()
        pending = crossings is not self._consumed and any(c.entity == self.player for c in crossings)
        return self.travels + int(pending)

    # --- travel ---------------------------------------------------------------------------------
    def _travelled(self, world: World) -> None:
        """Follow a crossing the travel stage made last frame: turn the velocity by the pair's
        turn (``PortalCrossing.turn``, what the engine turned the camera by), and read the
        heading back, dropping any roll."""
        crossings = world.resources.get(PortalCrossings) or ()
        if crossings is self._consumed:
            return
        self._consumed = crossings
        self._came_out_of = {self.portals.index(c.to_portal) for c in crossings
                             if c.entity == self.player and c.to_portal in self.portals}
        body = world.get(self.player, PlayerBody)
        transform = world.get(self.player, Transform)
        for crossing in crossings:
            if crossing.entity != self.player:
                continue
            v = crossing.turn * glm.vec3(*body.velocity)  # the pair's turn, which turned the camera
            body.velocity = np.array([v.x, v.y, v.z])
            body.yaw, body.pitch = body_heading(transform.rotation)
            body.on_ground = False  # the contact was on the other side: the next move finds the new one
            body.rotation = yaw_pitch_rotation(body.yaw, body.pitch)
            transform.rotation = body.rotation
            self.travels += 1
            if crossing.to_portal in self.portals:
                body.exit_portal = self.portals.index(crossing.to_portal)
            self._event("travelled", f"through portal {'AB'[self.portals.index(crossing.from_portal)]}",
                        portal=self.portals.index(crossing.from_portal))

    # --- moving -----------------------------------------------------------------------------------
    def solid_boxes(self) -> list[Solid]:
        """The level's solids as world AABBs (from the ray caster's cached triangles), worked
        out once a frame."""
        if not self._axes_checked:
            self._axes_checked = True
            names = {entity: name for name, entity in self.names.items()}
            turned = [names.get(e, str(e)) for e in sorted(self.solids)
                      if off_axis(self.world, e)]
            if turned:
                warnings.warn(CoarseCollisionWarning(
                    f"portal_run, level file {str(self.level_path)!r}: solid(s) {', '.join(map(repr, turned))} "
                    "turned off the world axes collide as their world-axis bounding box, larger than the mesh "
                    "(the player's physics is axis-aligned: games/portal_run/physics.py); keep solids to quarter "
                    "turns, or list them in [rules] not_solid"), stacklevel=2)
        if self._boxes is None or self._boxes[0] != self.frame:
            boxes = []
            for entity in sorted(self.solids):
                tris = self.caster.triangles(entity).reshape(-1, 3)
                boxes.append(Solid(entity, tris.min(axis=0), tris.max(axis=0)))
            self._boxes = (self.frame, boxes)
        return self._boxes[1]

    def _look(self, world: World, dx: float, dy: float) -> None:
        """Mouse look: ``dx`` / ``dy`` pixels of motion turn the player (and the camera)."""
        body = world.get(self.player, PlayerBody)
        if dx or dy:
            body.yaw = (body.yaw - dx * body.mouse_sensitivity + 180.0) % 360.0 - 180.0
            body.pitch = max(-89.0, min(89.0, body.pitch - dy * body.mouse_sensitivity))
        body.rotation = yaw_pitch_rotation(body.yaw, body.pitch)
        world.get(self.player, Transform).rotation = body.rotation

    def _move(self, world: World, state: Input, dt: float) -> None:
        """One physics step of ``dt``: walking (on the ground) or air control, jumping,
        gravity, and the body moved through the solids."""
        body = world.get(self.player, PlayerBody)
        transform = world.get(self.player, Transform)
        if dt <= 0.0:
            return
        yaw = math.radians(body.yaw)
        forward = np.array([-math.sin(yaw), 0.0, -math.cos(yaw)])
        right = np.array([math.cos(yaw), 0.0, -math.sin(yaw)])
        held = state.held
        wish = forward * (("w" in held) - ("s" in held)) + right * (("d" in held) - ("a" in held))
        length = float(np.linalg.norm(wish))
        wish = wish / length if length > 0 else wish
        v = np.array(body.velocity, np.float64)
        if body.on_ground:
            v[0], v[2] = wish[0] * WALK_SPEED, wish[2] * WALK_SPEED
            if "space" in state.pressed:
                v[1] = JUMP_SPEED
        elif length > 0:
            before = math.hypot(v[0], v[2])
            v[0] += wish[0] * AIR_ACCEL * dt
            v[2] += wish[2] * AIR_ACCEL * dt
            after = math.hypot(v[0], v[2])
            cap = max(before, WALK_SPEED)
            if after > cap:
                v[0], v[2] = v[0] * cap / after, v[2] * cap / after
        eye = transform.position
        self._step_out(body, v, np.array(eye, np.float64))
        self._exiting = body.exit_portal
        if self._moved_in_frame != self.frame:
            self._moved_in_frame = self.frame
            start = np.array(eye, np.float64)
            # Which portals the eye is in front of as the frame's first step starts: their walls
            # may let the body through. (Decided once a frame: within the frame the eye may pass
            # a portal's plane, the travel stage then carries it through at the frame's end, and
            # the wall must not close on the body half way.)
            self._in_front = {index for index, placed in enumerate(self.placed)
                              if placed is not None and float((start - placed.center) @ placed.normal) >= -0.02}
        v[1] -= GRAVITY * dt
        moved = move_body((eye.x, eye.y, eye.z), v, dt, self.shape, self.solid_boxes(), self._passable)
        body.velocity = moved.velocity
        body.on_ground = moved.on_ground
        transform.position = tuple(moved.position)

    def _step_out(self, body: PlayerBody, v: np.ndarray, eye: np.ndarray) -> None:
        """Just out of a portal the body is still partly inside the exit's wall (the camera
        came out, the body behind it did not): keep it moving out along the portal's normal
        at ``EXIT_SPEED`` at least until it is clear, so a player who stops or turns on
        arrival does not stand in the opening (where turning the view would touch the
        portal again and carry the camera back)."""
        placed = self.placed[body.exit_portal] if body.exit_portal is not None else None
        if placed is None:
            body.exit_portal = None
            return
        tris = self.caster.triangles(placed.host).reshape(-1, 3)
        if not (np.all(eye + self.shape.lo < tris.max(axis=0)) and np.all(eye + self.shape.hi > tris.min(axis=0))):
            body.exit_portal = None
            return
        out = float(v @ placed.normal)
        if out < EXIT_SPEED:
            v += placed.normal * (EXIT_SPEED - out)

    def _passable(self, entity: int, lo: np.ndarray, hi: np.ndarray) -> bool:
        """A wall with a portal on it lets the body through while the body came at it from the
        front (the eye not behind the portal's plane when the move started) and fits inside
        its opening."""
        w, h = self.rules.portal_size
        center = (lo + hi) / 2.0
        half = (hi - lo) / 2.0
        eye = center + np.array([0.0, (self.shape.hi[1] + self.shape.lo[1]) / -2.0, 0.0])
        for index, placed in enumerate(self.placed):
            if placed is None or placed.host != entity or None in self.placed:
                continue  # a lone portal is closed: its wall stays solid
            offset = center - placed.center
            if index not in self._in_front:
                continue  # from behind a wall there is no way in
            if index == self._exiting:
                # Just come out of it: the camera (the eye) is through the opening, the rest of
                # the body follows it out wherever it hangs past the opening's edges.
                eye_offset = eye - placed.center
                if abs(float(eye_offset @ placed.right)) <= w / 2 and abs(float(eye_offset @ placed.up)) <= h / 2:
                    return True
            reach_u = float(np.abs(placed.right) @ half)
            if abs(float(offset @ placed.right)) + reach_u > w / 2 + 0.05:
                continue
            v = float(offset @ placed.up)
            reach_v = float(np.abs(placed.up) @ half)
            if abs(v) + reach_v <= h / 2 + 0.15:
                return True
        return False

    # --- placing portals -----------------------------------------------------------------------
    def place(self, world: World, index: int) -> bool:
        """Shoot portal ``index`` (0 = A, 1 = B) along the player's view; True if it was placed."""
        transform = world.get(self.player, Transform)
        eye = np.array(transform.position, np.float64)
        view = transform.rotation * glm.vec3(0.0, 0.0, -1.0)
        hit = self.caster.cast(eye, (view.x, view.y, view.z), REACH, where=self.solids.__contains__)
        if hit is None:
            return self._refuse(world, index, "the shot hit nothing", None, None)
        point = np.array(hit.point, np.float64)
        normal = np.array(hit.normal, np.float64)
        if hit.entity not in self.portal_walls:
            return self._refuse(world, index, f"{self._name(hit.entity)} does not take portals", point, normal)
        if abs(normal[1]) <= WALL_SLOPE:  # a wall: the portal stands upright
            normal[1] = 0.0
            normal /= np.linalg.norm(normal)
            up = np.array([0.0, 1.0, 0.0])
            length_word = "high"
        elif normal[1] >= 1.0 - WALL_SLOPE and self.rules.portal_floors:
            # A floor: the portal lies flat, its top edge away from the player along the level's
            # nearest axis (so it lines up with the floor's edges and slides to fit them).
            normal = np.array([0.0, 1.0, 0.0])
            yaw = math.radians(world.get(self.player, PlayerBody).yaw)
            ahead = np.array([-math.sin(yaw), 0.0, -math.cos(yaw)])
            axis = 0 if abs(ahead[0]) >= abs(ahead[2]) else 2
            up = np.zeros(3)
            up[axis] = math.copysign(1.0, ahead[axis])
            length_word = "long"
        else:
            faces = "upright faces and floors" if self.rules.portal_floors else "upright faces"
            return self._refuse(world, index, f"{self._name(hit.entity)} is not a wall there (portals go on "
                                              f"{faces})", point, normal)
        right = np.cross(up, normal)
        w, h = self.rules.portal_size
        # The face: the wall's triangles in the hit plane; the portal slides to lie inside it.
        tris = self.caster.triangles(hit.entity)
        n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        coplanar = (np.abs(n @ normal) > 0.999) & (np.abs((tris[:, 0] - point) @ normal) < 1e-3)
        corners = tris[coplanar].reshape(-1, 3) - point
        us, vs = corners @ right, corners @ up
        center = point.copy()
        for axis, values, size, name in ((right, us, w, "wide"), (up, vs, h, length_word)):
            lo, hi = float(values.min()), float(values.max())
            if hi - lo < size:
                return self._refuse(world, index, f"{self._name(hit.entity)} is {hi - lo:.2f} m {name} there, the "
                                                  f"portal needs {size:g} m", point, normal)
            shift = min(max(0.0, lo + size / 2), hi - size / 2)
            center = center + axis * shift
        # Nothing in front of the face at the portal's corners, edges and centre.
        a, b = w / 2 - CORNER_INSET, h / 2 - CORNER_INSET
        for su, sv in ((0, 0), (-1, -1), (1, -1), (1, 1), (-1, 1), (0, -1), (0, 1), (-1, 0), (1, 0)):
            probe = center + right * su * a + up * sv * b + normal * 0.25
            got = self.caster.cast(probe, -normal, 0.5, where=self.solids.__contains__)
            if got is None or got.entity != hit.entity or abs(got.distance - 0.25) > 2e-3:
                return self._refuse(world, index, f"the portal does not fit on {self._name(hit.entity)} there "
                                                  "(something covers or the face ends)", point, normal)
        # Nothing standing in the space just in front of the portal (a crate flush with the
        # wall meets the probes at the wall's own distance, so it is found by its box).
        slab = np.array([center + right * su * a + up * sv * b + normal * depth
                         for su in (-1, 1) for sv in (-1, 1) for depth in (0.002, FRONT_CLEARANCE)])
        slab_lo, slab_hi = slab.min(axis=0), slab.max(axis=0)
        for solid in self.solid_boxes():
            if solid.entity != hit.entity and np.all(slab_lo < solid.hi) and np.all(slab_hi > solid.lo):
                return self._refuse(world, index, f"{self._name(solid.entity)} is in front of "
                                                  f"{self._name(hit.entity)} there", point, normal)
        other = self.placed[1 - index]
        if other is not None and other.host == hit.entity and abs(float((center - other.center) @ normal)) < 0.05:
            d = center - other.center
            if abs(float(d @ right)) < w and abs(float(d @ up)) < h:
                return self._refuse(world, index, "it would overlap the other portal", point, normal)
        self._put(world, index, PlacedPortal(hit.entity, center, right, up, normal))
        self._event("placed", f"portal {'AB'[index]} on {self._name(hit.entity)}", index,
                    tuple(float(c) for c in center))
        return True

    def _put(self, world: World, index: int, placed: PlacedPortal) -> None:
        portal = self.portals[index]
        transform = world.get(portal, Transform)
        transform.position = tuple(placed.center + placed.normal * PORTAL_OFFSET)
        transform.rotation = look_rotation(tuple(-placed.normal), tuple(placed.up))
        world.get(portal, Portal).enabled = True
        world.get(portal, MeshRef).visible = True
        world.get(self.rims[index], MeshRef).visible = True
        self.placed[index] = placed

    def _refuse(self, world: World, index: int, why: str, point: np.ndarray | None,
                normal: np.ndarray | None) -> bool:
        if point is not None:
            world.get(self.marker, Transform).position = tuple(point + normal * 0.3)
            world.get(self.marker, MeshRef).visible = True
            self.marker_time = REFUSED_SECONDS
        self._event("refused", f"portal {'AB'[index]}: {why}", index,
                    tuple(float(c) for c in point) if point is not None else None)
        return False

    def _flash(self, world: World, dt: float) -> None:
        if self.marker_time > 0.0:
            self.marker_time -= dt
            if self.marker_time <= 0.0:
                world.get(self.marker, MeshRef).visible = False

    # --- winning -------------------------------------------------------------------------------
    def _check_win(self, world: World) -> None:
        if self.won:
            return
        eye = np.array(world.get(self.player, Transform).position, np.float64)
        lo, hi = eye + self.shape.lo, eye + self.shape.hi
        tris = self.caster.triangles(self.exit).reshape(-1, 3)
        pad_lo, pad_hi = tris.min(axis=0), tris.max(axis=0) + np.array([0.0, 0.05, 0.0])
        if np.all(lo <= pad_hi) and np.all(hi >= pad_lo):
            self.won = True
            if self._exit_glow is None:
                self._exit_glow = Emissive(WIN_GLOW)
                world.add_component(self.exit, self._exit_glow)
            else:
                self._exit_glow.power = WIN_GLOW
            self._event("win", f"reached {self.rules.exit}")
            if self.verbose:
                keys = "press n for the next level, r to restart" if self.next_level() is not None \
                    else "press r to restart"
                print(f"portal_run: level complete: {self.level.name} (frame {self.frame}; {keys})", flush=True)

    # --- helpers ----------------------------------------------------------------------------------
    def _name(self, entity: int) -> str:
        for name, e in self.names.items():
            if e == entity:
                return name
        return f"entity {entity}"

    def _event(self, kind: str, detail: str = "", portal: int | None = None,
               point: tuple[float, float, float] | None = None) -> None:
        self.events.append(RunEvent(kind, self.frame, detail, portal, point))

    def event_kinds(self) -> list[str]:
        return [e.kind for e in self.events]
