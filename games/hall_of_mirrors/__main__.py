"""python -m games.hall_of_mirrors [--level FILE] [runner options]

With no ``--level`` the shipped ``hall.toml`` is played.  Headless runs follow the level's
camera tour unless ``--camera`` places the camera (``--gif FILE`` writes it as an animation,
``--dt`` sets the game seconds per frame); windowed runs fly freely."""
from __future__ import annotations

import argparse
import sys

from engine import run
from engine.gl_context import have_display
from games.hall_of_mirrors.level import LEVEL, HallOfMirrors


def main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--level", default=str(LEVEL))
    ours, rest = parser.parse_known_args(argv)
    if "-h" in rest or "--help" in rest:
        print("hall of mirrors options: --level FILE (a level file; default the shipped hall.toml)\n")
    headless = "--headless" in rest or not have_display()
    placed = any(arg == "--camera" or arg.startswith("--camera=") for arg in rest)
    run(HallOfMirrors(ours.level, tour=headless and not placed), rest)


main(sys.argv[1:])
