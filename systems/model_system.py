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

The file is looked for as given (relative to where the program runs) and the files it
names in its own folder and the asset roots (``--asset-root``); one that cannot be loaded
raises an AssetError naming the entity and the file, and leaves its old parts standing.
"""
from __future__ import annotations

from pathlib import Path

import esper

from components.model import Model
from engine.assets.level_assets import user_asset_roots
from engine.assets.models import SpawnedModels, model_key, remove_parts, respawn_parts
from engine.core.world import World


class ModelSystem(esper.Processor):
    def __init__(self, world: World) -> None:
        self.world = world

    def process(self, dt: float) -> None:
        world = self.world
        changed = world.changed(Model)
        if not changed:
            return
        spawned = world.resources.get(SpawnedModels, {})
        for root in sorted(changed):
            model = world.try_get(root, Model) if world.exists(root) else None
            if model is None or not model.file:
                remove_parts(world, root)
                continue
            record = spawned.get(root)
            if record is not None and record.key == model_key(model):
                continue
            respawn_parts(world, root, roots=[Path(model.file).parent, *user_asset_roots()])
