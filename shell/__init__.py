"""The app shell: the engine that runs a game (``shell.app``: the frame's stages, one system
each), the command line and headless loop (``shell.runner``), the window (``shell.window``),
the debug overlay (``shell.overlay``) and frame capture and scene export (``shell.capture``).
It is the one package that imports ``systems``; nothing below it imports it."""
from __future__ import annotations

import sys
from collections.abc import Sequence

from engine.core.game import Game, spawn_camera
from shell.app import Engine


def run(game: Game, argv: Sequence[str] | None = None) -> None:
    """Run ``game`` from the command line (see shell.runner for the options) and exit."""
    from shell.runner import main

    sys.exit(main(game, argv))


__all__ = ["Engine", "Game", "run", "spawn_camera"]
