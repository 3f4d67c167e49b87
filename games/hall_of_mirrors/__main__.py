"""python -m games.hall_of_mirrors [--level FILE] [runner options]

With no ``--level`` the shipped ``hall.toml`` is played (the runner's ``--level`` replaces
it).  Headless runs follow the level's camera tour unless ``--camera`` places the camera
(``--gif FILE`` writes it as an animation, ``--dt`` sets the game seconds per frame);
windowed runs fly freely."""
from __future__ import annotations

import sys

from engine.render.gl_context import have_display
from games.hall_of_mirrors.level import HallOfMirrors
from shell import run


def main(argv: list[str]) -> None:
    headless = "--headless" in argv or not have_display()
    placed = any(arg == "--camera" or arg.startswith("--camera=") for arg in argv)
    run(HallOfMirrors(tour=headless and not placed), argv)


main(sys.argv[1:])
