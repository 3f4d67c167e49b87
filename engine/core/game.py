"""A game: what the engine runs.  ``build`` spawns the level into a world, ``update`` runs
first in every frame (the "game" stage), and ``systems`` adds the game's own systems to the
frame's schedule (``GameSystem``: a stage or system to run after, and before).  The shell
(``shell.app.Engine``) runs it; the engine core and the level files only need the interface.

The schedule, in the style of Bevy's system sets: the engine's stages
(``shell.app.FRAME_STAGES``, one system each, in that order) are the fixed anchors, and each
game system says which stages (or other game systems) it runs ``after`` and ``before``.
``schedule_order`` checks the constraints and orders the whole frame deterministically: a
game system runs as early as its constraints allow (right after the last thing it must
follow), game systems that could run at the same point run in the order ``systems`` lists
them, and the stages keep their table order.  A name that is no stage or game system, a
pair of constraints the stage table contradicts, or a cycle between game systems is a
``ScheduleError`` naming the system and the reason, raised when the Engine is made.
"""
from __future__ import annotations

import difflib
import inspect
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

from pyglm import glm

from components import Camera, FlyController, Transform, yaw_pitch_rotation
from engine.core.errors import SpeculumError
from engine.core.world import World

# What a game system is: a function of the world and the frame's dt, or an object with a
# ``process(dt)`` method (an esper Processor, made with the world it works on).
SystemFunction = Callable[[World, float], None]


class ScheduleError(SpeculumError, ValueError):
    """A game's systems that cannot be scheduled: an unknown name, constraints the stage table
    contradicts, or a cycle between game systems (the message names the system and why)."""


@dataclass(frozen=True)
class GameSystem:
    """One of a game's systems and where it runs in the frame.

    ``system`` is ``function(world, dt)`` or a processor with ``process(dt)``; ``name`` (by
    default the function's ``__name__`` or the processor's class name) is how the schedule
    lists it and how other game systems order against it.  ``after`` and ``before`` name
    stages of ``shell.app.FRAME_STAGES`` or other game systems of the same game (a name or a
    tuple of names); by default a system runs after the game stage (the game's ``update``)
    and before nothing else, i.e. right after ``update``.  ``after=()`` lets it run first in
    the frame.

    Where to put one: a system that writes components runs before the stage that reads them
    (gameplay that enables portals or switches cameras before "rules"; anything drawn before
    "extract").  Transforms a game system writes after the "transform" stage and before
    "extract" are propagated again before the next engine stage (the schedule's
    "transform_late" entry), so they are drawn in the same frame; a component written after
    the stage that reads it (after "extract", a mesh or material) is not seen by that stage,
    this frame or later, as change sets last one frame.
    """

    system: SystemFunction | object
    after: str | tuple[str, ...] = "game"
    before: str | tuple[str, ...] = ()
    name: str = ""

    def __post_init__(self) -> None:
        if not self.name:
            default = getattr(self.system, "__name__", None) or type(self.system).__name__
            object.__setattr__(self, "name", default)
        for field_name in ("after", "before"):
            value = getattr(self, field_name)
            names = (value,) if isinstance(value, str) else _names(value)
            if names is None or not all(isinstance(name, str) for name in names):
                raise ScheduleError(f"GameSystem {self.name!r}: {field_name} must be a stage or game system name, "
                                    f"or a tuple of names, got {value!r}")
            object.__setattr__(self, field_name, names)

    def runs(self) -> bool:
        """Whether ``system`` can run: a callable, or something with ``process``."""
        return callable(getattr(self.system, "process", None)) or callable(self.system)

    def call_problem(self) -> str | None:
        """Why ``system`` cannot be called as the schedule calls it (``process(dt)`` or
        ``function(world, dt)``), or None; a callable whose signature Python cannot read
        (some built-ins) is taken on trust."""
        process = getattr(self.system, "process", None)
        target, arguments, shape = (process, (0.0,), "process(dt)") if callable(process) else \
            (self.system, (None, 0.0), "function(world, dt)")
        try:
            signature = inspect.signature(target)
        except (TypeError, ValueError):
            return None
        try:
            signature.bind(*arguments)
        except TypeError as exc:
            return f"cannot be called as {shape}: its signature is {signature} ({exc})"
        return None


def _names(value: object) -> tuple | None:
    """``value`` as a tuple, or None when it is not a sequence of names."""
    if isinstance(value, (bytes, dict)) or not isinstance(value, Iterable):
        return None
    return tuple(value)


def schedule_order(stages: Sequence[str], systems: Iterable[GameSystem], where: str = "Game.systems()",
                   reserved: Iterable[str] = ()) -> list[str | GameSystem]:
    """The frame's order: every stage name and every game system, each once.

    ``stages`` run in the order given; each game system after all its ``after`` names and
    before all its ``before`` names, as early as that allows (ties: stages wait for the game
    systems that are ready, which run in the order listed).  ``where`` says whose systems
    they are in errors; ``reserved`` are further names a game system may not take."""
    stages = list(stages)
    if systems is None or isinstance(systems, (str, bytes, dict, GameSystem)) or not isinstance(systems, Iterable):
        raise ScheduleError(f"{where}: returned {systems!r}; return a list of GameSystem (an empty one for none)")
    systems = list(systems)
    stage_at = {name: index for index, name in enumerate(stages)}
    taken = set(stages) | set(reserved)

    def fail(system: GameSystem | None, why: str) -> ScheduleError:
        who = f"game system {system.name!r}" if system is not None else "game systems"
        return ScheduleError(f"{where}: {who} {why}")

    by_name: dict[str, GameSystem] = {}
    for system in systems:
        if not isinstance(system, GameSystem):
            raise ScheduleError(f"{where}: returned {system!r}, which is not a GameSystem")
        if not isinstance(system.name, str) or not system.name:
            raise fail(system, "needs a name (a non-empty string)")
        if system.name in stage_at:
            raise fail(system, f"has the name of an engine stage; name it something else (stages: {', '.join(stages)})")
        if system.name in taken:
            raise fail(system, "has a name the engine's schedule uses for its own entry; name it something else")
        if system.name in by_name:
            raise fail(system, "is listed twice (game system names are unique)")
        if not system.runs():
            raise fail(system, f"is {system.system!r}, which is neither a function(world, dt) nor has process(dt)")
        problem = system.call_problem()
        if problem is not None:
            raise fail(system, problem)
        by_name[system.name] = system
    for system in systems:
        for field_name in ("after", "before"):
            for name in getattr(system, field_name):
                if name == system.name:
                    raise fail(system, f"runs {field_name} itself")
                if name not in stage_at and name not in by_name:
                    known = stages + [s for s in by_name if s != system.name]
                    close = difflib.get_close_matches(name, known, n=1)
                    hint = f" (did you mean {close[0]!r}?)" if close else ""
                    raise fail(system, f"runs {field_name} {name!r}, which is no stage or game system{hint}; "
                                       f"stages: {', '.join(stages)}; game systems: "
                                       f"{', '.join(s for s in by_name if s != system.name) or 'none other'}")
        after = [stage_at[n] for n in system.after if n in stage_at]
        before = [stage_at[n] for n in system.before if n in stage_at]
        if after and before and max(after) >= min(before):
            late, early = stages[max(after)], stages[min(before)]
            if late == early:
                raise fail(system, f"runs both after and before {late!r}")
            raise fail(system, f"runs after {late!r} and before {early!r}, but the stages run {early!r} "
                               f"before {late!r} (FRAME_STAGES)")

    # Edges: each stage to the next, each ``after`` name to its system, each system to its
    # ``before`` names.  Then Kahn's sort, with the ready game systems first.
    nodes: list[str] = stages + [s.name for s in systems]
    successors: dict[str, list[str]] = {n: [] for n in nodes}
    for a, b in zip(stages, stages[1:], strict=False):
        successors[a].append(b)
    for system in systems:
        for name in system.after:
            successors[name].append(system.name)
        for name in system.before:
            successors[system.name].append(name)
    waiting = {n: 0 for n in nodes}
    for n in nodes:
        for m in successors[n]:
            waiting[m] += 1
    rank = {name: index for index, name in enumerate(by_name)}
    order: list[str] = []
    ready_systems = [n for n in by_name if waiting[n] == 0]
    ready_stages = [n for n in stages if waiting[n] == 0]
    while ready_systems or ready_stages:
        if ready_systems:
            ready_systems.sort(key=rank.__getitem__)
            name = ready_systems.pop(0)
        else:
            name = ready_stages.pop(0)
        order.append(name)
        for m in successors[name]:
            waiting[m] -= 1
            if waiting[m] == 0:
                (ready_systems if m in by_name else ready_stages).append(m)
    if len(order) < len(nodes):
        raise _cycle_error(nodes, successors, set(order), by_name, stage_at, where)
    return [by_name.get(name, name) for name in order]


def _cycle_error(nodes: list[str], successors: dict[str, list[str]], done: set[str],
                 by_name: dict[str, GameSystem], stage_at: dict[str, int], where: str) -> ScheduleError:
    """The error for constraints that leave no order: one cycle among what was left, told
    edge by edge (the stages' own order shortened to its ends)."""
    left = [n for n in nodes if n not in done]
    predecessors: dict[str, list[str]] = {n: [] for n in left}
    for n in left:
        for m in successors[n]:
            if m in predecessors:
                predecessors[m].append(n)
    # Every node left has a predecessor left: walk back from the first game system left
    # until a node repeats; the walk from there is a cycle (read backwards).
    start = next((n for n in left if n in by_name), left[0])
    path, seen = [start], {start: 0}
    while True:
        previous = predecessors[path[-1]][0]
        if previous in seen:
            cycle = list(reversed(path[seen[previous]:]))
            break
        seen[previous] = len(path)
        path.append(previous)
    rank = {name: index for index, name in enumerate(by_name)}
    first = min((i for i, n in enumerate(cycle) if n in by_name), key=lambda i: rank[cycle[i]])
    cycle = cycle[first:] + cycle[:first]
    steps = []
    for a, b in zip(cycle, cycle[1:] + cycle[:1], strict=True):
        if a in stage_at and b in stage_at:
            if steps and steps[-1][0] == "stages":
                steps[-1] = ("stages", steps[-1][1], b)
            else:
                steps.append(("stages", a, b))
        elif b in by_name and a in by_name[b].after:
            steps.append(("after", b, a))
        else:
            steps.append(("before", a, b))
    told = [f"the stages run {a!r} before {b!r}" if kind == "stages" else f"{a!r} runs {kind} {b!r}"
            for kind, a, b in steps]
    names = [n for n in cycle if n in by_name]
    if all(n in by_name for n in cycle):
        what = "form a cycle between game systems"
    else:
        what = "have constraints that contradict the stage order (FRAME_STAGES)"
    who = f"game system {names[0]!r}" if len(names) == 1 else "game systems " + ", ".join(map(repr, names))
    return ScheduleError(f"{where}: {who} {what}: {'; '.join(told)}; "
                         f"so {cycle[0]!r} would run before itself")


class Game:
    """Subclass this: ``build`` spawns the level; ``update`` runs first every frame;
    ``systems`` lists the game's own systems and where in the frame each runs."""

    title = "Speculum"
    size: tuple[int, int] = (1280, 720)

    def build(self, world: World) -> None:
        raise NotImplementedError

    def update(self, world: World, dt: float) -> None:
        pass

    def systems(self) -> Sequence[GameSystem]:
        """The game's systems beyond ``update``, each with where it runs (``GameSystem``).
        Asked once, when the Engine is made (before ``build``); none by default."""
        return ()


def spawn_camera(world: World, position: glm.vec3 | Sequence[float] = (0.0, 1.6, 6.0), yaw: float = 0.0,
                 pitch: float = 0.0, fov_y: float = 60.0, fly: bool = True) -> int:
    """A camera entity, with fly controls for windowed runs unless ``fly`` is False."""
    components = [Transform(position=position, rotation=yaw_pitch_rotation(yaw, pitch)), Camera(fov_y=fov_y)]
    if fly:
        components.append(FlyController(yaw=yaw, pitch=pitch))
    return world.spawn(*components)
