"""Speculum's engine: world, math, assets, GPU helpers, and the app shell that runs a game.

The core (``engine.world``, ``engine.render``, assets and math) never imports ``systems``;
the app shell (``engine.app``: Game, Engine; ``engine.runner``; ``engine.window``) wires the
systems into a world.  So that ``import systems`` works first, this package loads the shell
only when one of its names is asked for.

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
from typing import TYPE_CHECKING, Any

from engine.world import World

if TYPE_CHECKING:
    from engine.app import Engine, Game, spawn_camera

_SHELL = ("Engine", "Game", "spawn_camera")


def __getattr__(name: str) -> Any:
    if name in _SHELL:
        import engine.app

        return getattr(engine.app, name)
    raise AttributeError(f"module 'engine' has no attribute {name!r}")


def run(game: Game, argv: Sequence[str] | None = None) -> None:
    """Run ``game`` from the command line (see engine.runner for the options) and exit."""
    from engine.runner import main

    sys.exit(main(game, argv))


__all__ = ["Engine", "Game", "World", "run", "spawn_camera"]
