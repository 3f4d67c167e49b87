"""Speculum's engine: context, world, renderer helpers, runner.

A tiny game::

    from engine import Game, run, spawn_camera
    from engine.mesh import box
    from components import Transform, MeshRef, Material, DirectionalLight

    class Tiny(Game):
        def build(self, world):
            spawn_camera(world, position=(0, 1, 4))
            world.spawn(DirectionalLight())
            world.spawn(Transform(), MeshRef(box()), Material(color=(0.8, 0.1, 0.1)))

    run(Tiny())
"""
from __future__ import annotations

import sys
from collections.abc import Sequence

from engine.app import Engine, Game, spawn_camera
from engine.world import World


def run(game: Game, argv: Sequence[str] | None = None) -> None:
    """Run ``game`` from the command line (see engine.runner for the options) and exit."""
    from engine.runner import main

    sys.exit(main(game, argv))


__all__ = ["Engine", "Game", "World", "run", "spawn_camera"]
