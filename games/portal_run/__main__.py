"""python -m games.portal_run [--level FILE] [--autopilot | --no-autopilot] [runner options]

Runner options are every game's (``--headless --frames N --out DIR --size WxH ...``).  With
no ``--level`` the first shipped level is played.  A headless run (or one with no display)
plays the level's scripted solution unless ``--no-autopilot`` is given, so its frames show
the game; a windowed run is played by a person (``--autopilot`` to watch the solution)."""
from __future__ import annotations

import argparse
import sys

from engine import run
from engine.errors import SpeculumError
from engine.gl_context import have_display
from games.portal_run.game import PortalRun


def main(argv: list[str] | None = None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(prog="python -m games.portal_run", add_help=False)
    parser.add_argument("--level", default=None, help="level file (.toml) to play")
    parser.add_argument("--autopilot", dest="autopilot", action="store_true", default=None,
                        help="play the level's scripted solution")
    parser.add_argument("--no-autopilot", dest="autopilot", action="store_false")
    ours, rest = parser.parse_known_args(argv)
    if "-h" in rest or "--help" in rest:
        parser.print_help()
        print("\nrunner options:")
    headless = "--headless" in rest or not have_display()
    autopilot = headless if ours.autopilot is None else ours.autopilot
    try:
        game = PortalRun(ours.level, autopilot=autopilot)
    except (SpeculumError, ValueError) as exc:
        print(f"speculum: error: {exc}", file=sys.stderr)
        sys.exit(2)
    run(game, rest)


main()
