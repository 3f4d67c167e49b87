"""Level files reload on save: a run of a level file watches the file and, when it is saved
(by any editor), rebuilds the world from it, keeping the active camera's pose.

Polling, not OS notifications (no new dependency, the same on every platform): each
``poll`` stats the file (modification time in nanoseconds and size), as the shader library's
hot reload does.  A save is acted on once the file's stat has been the same for two polls
in a row: an editor that writes in several chunks (or truncates, then writes) is caught
mid-write by the first poll and left alone until its stat settles.  A stat change whose
bytes are those already loaded (a ``touch``, a save without an edit) rebuilds nothing.

A save is tried before it replaces anything: the game (a shallow copy of it) builds the new
file into a scratch ``World`` of its own, which checks the whole file (``load_level``: every
component value, the game's own rules) without touching the running world or any GL object.
Only when that succeeds is every entity of the running world deleted and the game built
again into it; the renderer releases the old entities' GPU resources as it does for any
deleted entity.  A file that fails keeps the old world running; its error (the
``LevelError``'s ``file:line: entity: field: reason``) is said once by ``poll`` (the shell
prints it) and held in ``error`` until a save loads (the overlay shows it, as it shows
shader errors).  A save the run makes itself (an editor in the window writing its world back)
calls ``follow`` after writing: the file as written counts as loaded, and nothing is rebuilt.

The model files its ``Model`` entities place are watched the same way (their stat, settled
over two polls), and the files they name beside them (a glTF's buffers and images, an OBJ's
material libraries and maps): a model exported again from Blender, or a texture painted
again, rebuilds the level, so its new meshes, materials, images and lights show in the
running game.
"""
from __future__ import annotations

import copy
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from pyglm import glm

from components import ComponentValueError, FlyController, Model, Transform
from engine.assets.models import SpawnedModels
from engine.core.errors import SpeculumError
from engine.core.frame_io import Input
from engine.core.game import Game
from engine.core.world import World
from engine.resources import ViewBudget
from engine.rules.frame_rules import active_camera

POLL_INTERVAL = 0.25  # seconds between two looks at the level file (windowed runs)


@dataclass(frozen=True)
class CameraPose:
    """Where the active camera was: kept across a reload."""

    position: glm.vec3
    rotation: glm.quat
    yaw_pitch: tuple[float, float] | None  # its FlyController's angles, if it has one


class LevelReload:
    """Watches ``game``'s level file and rebuilds ``world`` (the one the game runs in) from it
    when the file is saved (``shell.app.Engine.watch_level`` makes one for its game).

    ``interval``: seconds between two stats (0: every ``poll``).  ``reloads``: the saves
    loaded so far; ``error``: the message of the last save that failed (None once a save
    loads); ``on_reload``: called after each rebuild."""

    def __init__(self, game: Game, world: World, interval: float = POLL_INTERVAL,
                 on_reload: Callable[[], None] | None = None) -> None:
        from engine.assets.level_file import LevelGame

        if not isinstance(game, LevelGame):
            raise SpeculumError(f"level reload: {game.title!r} builds its own world in Python, not from a "
                                "level file, so there is no file to reload")
        self.game = game
        self.world = world
        self.interval = float(interval)
        self.path = Path(game.level_path)
        self.reloads = 0
        self.error: str | None = None
        self.on_reload = on_reload  # called after each rebuild (the engine: a stopped game runs again)
        self._next_poll = 0.0
        self.follow(self.path)

    def follow(self, path: Path) -> None:
        """Watch ``path`` (the level the game plays now) as it is now: its next save reloads."""
        self.path = Path(path)
        self._loaded_stat = self._last_stat = self._stat()
        self._loaded_bytes = self._read()
        self._follow_models()

    def _follow_models(self) -> None:
        """Watch the model files the world's Models place, and the files beside them they name
        (a glTF's buffers and images, an OBJ's material libraries and maps), as they are now."""
        spawned = self.world.resources.get(SpawnedModels, {})
        files = set()
        for root, model in self.world.query_one(Model):
            if model.file:
                files.add(Path(model.file))
                record = spawned.get(root)
                if record is not None and record.loaded is not None:
                    files.update(record.loaded.side_files)
        self._models = {path: _file_stat(path) for path in sorted(files)}  # as loaded
        self._models_last = dict(self._models)                              # as last seen

    def _stat(self) -> tuple[int, int] | None:
        return _file_stat(self.path)

    def _read(self) -> bytes | None:
        try:
            return self.path.read_bytes()
        except OSError:
            return None

    def poll(self, now: float | None = None) -> list[str]:
        """Look at the file (at most every ``interval`` seconds) and reload it once it has
        been saved and its stat is stable; returns what happened, each save once (a line for
        a reload, the error for a save that failed)."""
        now = time.monotonic() if now is None else now
        if now < self._next_poll:
            return []
        self._next_poll = now + self.interval
        playing = Path(self.game.level_path)
        if playing != self.path:  # the game went to another level ('n'): watch that file from now on
            self.follow(playing)
            return []
        stat, last = self._stat(), self._last_stat
        self._last_stat = stat
        if stat == self._loaded_stat and self._models_saved():
            return [self.reload()]  # a model file it places was saved (the level's own is as loaded)
        if stat == self._loaded_stat or stat != last:
            return []  # unchanged, or changed since the last look (maybe mid-write): wait
        self._loaded_stat = stat
        contents = self._read()
        if contents is not None and contents == self._loaded_bytes:
            return []  # saved without a change
        self._loaded_bytes = contents
        return [self.reload()]

    def _models_saved(self) -> bool:
        """Whether a watched model file changed and has held still since the last poll."""
        saved = False
        for path, loaded in self._models.items():
            stat, last = _file_stat(path), self._models_last[path]
            self._models_last[path] = stat
            if stat != loaded and stat == last:
                saved = True
        return saved

    def reload(self) -> str:
        """Build the level from the file now: the world rebuilt with the camera's pose kept,
        or (a file that fails) the old world kept and the error returned and held in ``error``."""
        try:
            self._try_build()
        except (SpeculumError, ComponentValueError, ValueError) as exc:
            self.error = f"level reload failed, previous level kept: {exc}"
            self._models = dict(self._models_last)  # that save of a model is said once
            return self.error
        world = self.world
        pose = camera_pose(world)
        for entity in world.entities():
            world.delete_entity(entity)
        world.resources.pop(ViewBudget, None)  # the new file's [level] view_budget, or none
        self.game.build(world)
        if pose is not None:
            place(world, pose)
        self._follow_models()
        self.error = None
        self.reloads += 1
        if self.on_reload is not None:
            self.on_reload()
        return f"level reloaded: {self.path}"

    def _try_build(self) -> None:
        """The game (a shallow copy) built from the file into a scratch world: every error
        a real build would raise, and nothing running touched."""
        trial = copy.copy(self.game)
        scratch = World(f"{self.world.name} reload check")
        scratch.resources[Input] = Input()
        try:
            trial.build(scratch)
        finally:
            scratch.close()


def _file_stat(path: Path) -> tuple[int, int] | None:
    """A file's modification time (ns) and size; None while it cannot be read (mid-save by
    rename, or removed: looked at again next poll)."""
    try:
        info = os.stat(path)
    except OSError:
        return None
    return info.st_mtime_ns, info.st_size


def camera_pose(world: World) -> CameraPose | None:
    """The active camera's pose (None: no active camera)."""
    entity = active_camera(world)
    if entity is None:
        return None
    transform = world.get(entity, Transform)
    fly = world.try_get(entity, FlyController)
    return CameraPose(glm.vec3(transform.position), glm.quat(transform.rotation),
                      (fly.yaw, fly.pitch) if fly is not None else None)


def place(world: World, pose: CameraPose) -> None:
    """Put the active camera of ``world`` (just built) where ``pose`` says."""
    entity = active_camera(world)
    if entity is None:
        return
    transform = world.get(entity, Transform)
    transform.position = pose.position
    transform.rotation = pose.rotation
    fly = world.try_get(entity, FlyController)
    if fly is not None and pose.yaw_pitch is not None:
        fly.yaw, fly.pitch = pose.yaw_pitch
