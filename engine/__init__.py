"""Speculum's engine: the core (``engine.core``: world, game interface, math), assets
(``engine.assets``: meshes, textures, model and level files), the rules systems agree on
(``engine.rules``) and every GL call (``engine.render``).  It never imports ``systems`` or
the app shell (``shell``), which wires the systems into a world and runs a game.

A tiny game::

    from components import DirectionalLight, Material, MeshRef, Transform
    from engine import Game, spawn_camera
    from engine.assets.mesh import box
    from shell import run

    class Tiny(Game):
        def build(self, world):
            spawn_camera(world, position=(0, 1, 4))
            world.spawn(DirectionalLight())
            world.spawn(Transform(), MeshRef(box()), Material(color=(0.8, 0.1, 0.1)))

    run(Tiny())
"""
from __future__ import annotations

import engine.rules.camera_rules  # noqa: F401  (registers the orthographic camera's rule with every world)
import engine.rules.detail_rules  # noqa: F401  (registers the level-of-detail rule with every world)
import engine.rules.glass_rules  # noqa: F401  (registers the opaque-glass warning with every world)
import engine.rules.light_rules  # noqa: F401  (registers the one-sky rule with every world)
import engine.rules.mirror_rules  # noqa: F401  (registers the mirror-mesh and one-surface invariants with every world)
import engine.rules.particle_rules  # noqa: F401  (registers the mesh-emitter rule with every world)
import engine.rules.pose_rules  # noqa: F401  (registers the Skin and Morph rules with every world)
import engine.rules.uv_rules  # noqa: F401  (registers the second-UV rule with every world)
import engine.rules.water_rules  # noqa: F401  (registers the water rule with every world)
from engine.core.game import Game, GameSystem, spawn_camera
from engine.core.world import World

__all__ = ["Game", "GameSystem", "World", "spawn_camera"]
