"""Models: the parts of every ``Model`` placed, changed or taken away since the last frame.

Runs right after the game's update (which, like the editor or a level file, may place a
``Model``, change its file or scale, or delete it) and before anything reads the entities:
a root whose ``Model`` is new or changed gets its parts made again
(``engine.assets.models.respawn_parts``: the file loaded, every part built, then the old
parts deleted and the new ones spawned under it, each with a ``FromModel``), so they are
placed and drawn this frame; a root whose ``Model`` went (or the root itself) takes its
parts with it, their GPU resources released as any entity's.  A Model that
``spawn_model`` or a level file's spawn already made parts for, from the same values, is
left alone (the world's ``SpawnedModels`` says what was made from what).

Then each ``Animation`` on a model's root moves on by the frame's time and puts the parts
where its clip puts their nodes (``engine.assets.models.pose_parts``): before the transform
stage, so the pose is drawn in this frame.  The ``AnimationEvents`` the playback passed are
this frame's ``FiredEvents`` (``engine/core/clip_events.py``).  A model whose root's Transform was written has
its directional lights pointed again (``turn_suns``: a direction is not a place the
transform stage carries).

The file is looked for as given (relative to where the program runs) and the files it
names in its own folder and the asset roots (``--asset-root``); one that cannot be loaded
raises an AssetError naming the entity and the file, and leaves its old parts standing.
"""
from __future__ import annotations

import math
from pathlib import Path

import esper
from pyglm import glm

from components import Transform
from components.model import Animation, AnimationEvents, AnimationLayer, Model
from engine.assets.level_assets import user_asset_roots
from engine.assets.models import (
    SpawnedModels,
    clip_duration,
    model_key,
    pose_parts,
    remove_parts,
    respawn_parts,
    root_start,
    root_travel,
    root_turn,
    turn_suns,
)
from engine.core.clip_events import events_problem, passed_events
from engine.core.errors import AssetError
from engine.core.world import World
from engine.resources import FiredEvent, FiredEvents


class ModelSystem(esper.Processor):
    def __init__(self, world: World) -> None:
        self.world = world
        self._posed: dict[int, str] = {}  # root -> the clip its parts were last posed by

    def process(self, dt: float) -> None:
        world = self.world
        changed = world.changed(Model)
        if changed:
            self._place(changed)
        self._animate(dt, changed)
        turned = world.changed(Transform)
        if turned:  # a model turned by its root, or by an entity it hangs under: its suns' directions with it
            spawned = world.resources.get(SpawnedModels, {})
            for root in [root for root, record in spawned.items() if record.suns and root not in changed]:
                if _moved_above(world, root, turned):
                    turn_suns(world, root)

    def _animate(self, dt: float, remade: set[int]) -> None:
        """Move each playing ``Animation`` on by ``dt`` x its speed (wrapped at the clip's end
        when it loops, held there when not) and pose its model's parts; a changed Animation,
        or a model whose parts were just made, is posed even when paused.  A cross-fade's
        clip faded from moves on the same way and its ``faded`` by ``dt``; the fade ends (its
        clip dropped) once it has lasted its ``fade_seconds``.  An ``AnimationLayer`` on the
        root moves on the same way, by its own speed, and is laid over that pose."""
        world = self.world
        fired = world.resources[FiredEvents] = FiredEvents()  # (this frame's: the last frame's are gone)
        self._check_events(remade)
        changed = world.changed(Animation) | world.changed(AnimationLayer)
        roots = {root for root, _ in world.query_one(Animation)} | {root for root, _ in world.query_one(AnimationLayer)}
        roots |= {root for root in changed if world.exists(root)}  # (one taken away: its parts posed without it)
        for root in sorted(roots):
            animation = world.try_get(root, Animation) or _AT_REST
            layer = world.try_get(root, AnimationLayer)
            record = world.resources.get(SpawnedModels, {}).get(root)
            moving = animation.playing and (animation.clip or animation.fade_from) and dt and animation.speed
            layer_moving = layer is not None and layer.playing and layer.clip and dt and layer.speed
            if not (moving or layer_moving or root in changed or root in remade):
                continue
            fade = None
            before = animation.time
            layer_before = layer.time if layer is not None else 0.0
            if moving and record is not None and record.loaded is not None:
                animation.time = _moved_on(record.loaded, animation.clip, animation.time, dt, animation)
                if animation.fade_from:
                    animation.fade_from_time = _moved_on(record.loaded, animation.fade_from, animation.fade_from_time,
                                                         dt, animation)
                    animation.faded = min(animation.faded + dt, animation.fade_seconds)
            if layer_moving and record is not None and record.loaded is not None:
                layer.time = _moved_on(record.loaded, layer.clip, layer.time, dt, layer)
            if animation.fade_from:
                share = animation.faded / animation.fade_seconds if animation.fade_seconds > 0.0 else 1.0
                if share >= 1.0:
                    animation.fade_from = ""  # (faded in: the clip alone from here)
                else:
                    fade = (animation.fade_from, animation.fade_from_time, share)
            laid = (layer.clip, layer.time, layer.weight, layer.blend, layer.root) if layer is not None else None
            # (a clip only moved on rewrites only the parts it moves; another clip, a fade, a
            # layer or new parts, all)
            every = root in remade or self._posed.get(root) != animation.clip or fade is not None
            walking = bool(animation.root_motion and animation.clip)
            pose_parts(world, root, animation.clip, animation.time, every, fade, laid,
                       animation.root_motion if walking else "", walking and animation.root_turn)
            self._posed[root] = animation.clip if layer is None else None
            if walking and moving:
                _walk_root(world, root, animation, before, dt)
            cues = world.try_get(root, AnimationEvents)
            if cues is not None and record is not None and record.loaded is not None:
                if moving:
                    fired.dropped += _fire(fired, root, cues, record.loaded, animation, before, dt, False)
                if layer_moving:
                    fired.dropped += _fire(fired, root, cues, record.loaded, layer, layer_before, dt, True)

    def _check_events(self, remade: set[int]) -> None:
        """Each ``AnimationEvents`` given or changed, or on a model just made: every event's
        clip is one of the model's and its time within it, else an AssetError naming the
        entity, the event and the clip's length or the model's clips."""
        world = self.world
        spawned = world.resources.get(SpawnedModels, {})
        for root in sorted(world.changed(AnimationEvents) | remade):
            cues = world.try_get(root, AnimationEvents) if world.exists(root) else None
            record = spawned.get(root)
            if cues is None or not cues.events or record is None or record.loaded is None:
                continue
            problem = events_problem(cues.events, {clip.name: clip.duration for clip in record.loaded.animations})
            if problem is not None:
                raise AssetError(f"entity {root}'s AnimationEvents: {problem}")

    def _place(self, changed: set[int]) -> None:
        world = self.world
        spawned = world.resources.get(SpawnedModels, {})
        for root in sorted(changed):
            model = world.try_get(root, Model) if world.exists(root) else None
            if model is None or not model.file:
                remove_parts(world, root)
                self._posed.pop(root, None)
                continue
            record = spawned.get(root)
            if record is not None and record.key == model_key(model):
                continue
            respawn_parts(world, root, roots=[Path(model.file).parent, *user_asset_roots()])


def _walk_root(world: World, root: int, animation: Animation, before: float, dt: float) -> None:
    """Move ``root`` by what its clip carried the root-motion node across the ground this
    frame (``Animation.root_motion``): the travel at the new time less at ``before``, plus a
    whole clip's travel for each time a loop wrapped (forwards or back), turned and scaled as
    the root is (model space to its parent's); with ``root_turn`` turned as well (``_turn_root``)."""
    duration = clip_duration(world, root, animation.clip)
    wraps = 0
    if animation.loop and duration > 0.0:
        wraps = math.floor((before + dt * animation.speed) / duration)
    if animation.root_turn:
        _turn_root(world, root, animation, before, wraps, duration)
        return
    travel = root_travel(world, root, animation.clip, animation.root_motion, animation.time) \
        - root_travel(world, root, animation.clip, animation.root_motion, before)
    if wraps:
        travel = travel + wraps * root_travel(world, root, animation.clip, animation.root_motion, duration)
    transform = world.get(root, Transform)
    transform.position = transform.position + transform.rotation * (transform.scale * glm.vec3(*travel))


# Clip time a step of a turning walk covers at most (``_turn_root``): a step turns the root by
# the clip's turn less a whole turn or more, so a clip spinning fast is followed round.
_TURN_STEP = 1.0 / 30.0


def _turn_root(world: World, root: int, animation: Animation, before: float, wraps: int, duration: float) -> None:
    """Move and turn ``root`` by what its clip carried and turned the root-motion node from
    ``before`` to its time now (``Animation.root_turn``), through ``wraps`` loop wraps: in
    steps of at most ``_TURN_STEP`` of clip time, each step's travel (model space) turned back
    by the turn the pose has taken out at its start and then as the root stands (the two
    together the root's turn less the clip's so far: the step goes where the clip walks it),
    and the root turned by the step's turn about its own vertical."""
    clip, node, now = animation.clip, animation.root_motion, animation.time
    if wraps > 0:
        spans = [(before, duration), *[(0.0, duration)] * (wraps - 1), (0.0, now)]
    elif wraps < 0:
        spans = [(before, 0.0), *[(duration, 0.0)] * (-wraps - 1), (duration, now)]
    else:
        spans = [(before, now)]
    transform = world.get(root, Transform)
    position, rotation = glm.vec3(transform.position), glm.quat(transform.rotation)
    up = glm.vec3(0.0, 1.0, 0.0)
    start = root_start(world, root, clip, node)
    pivot = glm.vec3(float(start[0]), 0.0, float(start[2]))   # (the pose is turned back about it, the root about 0)
    for start, end in spans:
        steps = max(1, min(256, math.ceil(abs(end - start) / _TURN_STEP)))
        times = [start + (end - start) * i / steps for i in range(steps + 1)]
        travels = [root_travel(world, root, clip, node, t) for t in times]
        turns = [root_turn(world, root, clip, node, t) for t in times]
        for i in range(steps):
            turned = math.remainder(turns[i + 1] - turns[i], 2.0 * math.pi)
            # The step's travel, less how the root's turn about its origin moves the pivot the
            # pose stands on, turned back as the pose has it at the step's start.
            step = glm.vec3(*(travels[i + 1] - travels[i])) + glm.angleAxis(turns[i], up) * pivot \
                - glm.angleAxis(turns[i] + turned, up) * pivot
            position = position + rotation * (transform.scale * (glm.angleAxis(-turns[i], up) * step))
            rotation = rotation * glm.angleAxis(turned, up)
    transform.position, transform.rotation = position, glm.normalize(rotation)


def _fire(fired: FiredEvents, root: int, cues: AnimationEvents, loaded, playback: Animation | AnimationLayer,
          before: float, dt: float, layer: bool) -> int:
    """Add to ``fired`` the events of ``playback``'s clip its step from ``before`` by ``dt``
    x its speed passed (``clip_events.passed_events``); returns how many it left out."""
    events = cues.of_clip(playback.clip)
    clip = next((c for c in loaded.animations if c.name == playback.clip), None)
    if not events or clip is None:
        return 0
    passed, dropped = passed_events(events, before, dt * playback.speed, clip.duration, playback.loop)
    fired.extend(FiredEvent(root, playback.clip, name, time, layer) for time, name in passed)
    return dropped


def _moved_above(world: World, entity: int, turned: set[int]) -> bool:
    """Whether ``entity``'s Transform or one of its parents' is among ``turned``."""
    seen = 0
    walk: int | None = entity
    while walk is not None and world.exists(walk) and seen <= 256:  # (a cycle is refused elsewhere)
        if walk in turned:
            return True
        transform = world.try_get(walk, Transform)
        walk = transform.parent if transform is not None else None
        seen += 1
    return False


_AT_REST = Animation(playing=False)  # a root with a layer and no Animation: the layer over the rest pose


def _moved_on(loaded, name: str, time: float, dt: float, animation: Animation | AnimationLayer) -> float:
    """Clip ``name``'s time ``time`` moved on by ``dt`` x the animation's (or layer's) speed:
    wrapped at the clip's end when it loops, held at its ends when not (a clip the file lacks:
    as it is)."""
    clip = next((c for c in loaded.animations if c.name == name), None)
    if clip is None or not name:
        return time
    moved = time + dt * animation.speed
    if clip.duration > 0.0:
        moved = moved % clip.duration if animation.loop else min(max(moved, 0.0), clip.duration)
    return max(moved, 0.0)
