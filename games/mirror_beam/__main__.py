"""python -m games.mirror_beam [--level FILE] [--interval N] [runner options]

Headless runs play the level's solution (the autopilot) so the frames show it solved;
windowed runs are played with the keys (tab or 1-9 pick a mirror, left/right turn it, r restarts)."""
import argparse
import sys

from engine import run
from games.mirror_beam.game import MirrorBeam


def main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--level", default=None)
    parser.add_argument("--interval", type=int, default=1, help="autopilot: frames between key presses")
    parser.add_argument("--headless", action="store_true")
    ours, rest = parser.parse_known_args(argv)
    if "-h" in rest or "--help" in rest:
        print("mirror beam options: --level FILE (a level file; default the first shipped level), "
              "--interval N (headless autopilot: frames between key presses)\n")
    if ours.headless:
        rest.append("--headless")
    run(MirrorBeam(ours.level, autopilot=ours.headless, interval=ours.interval), rest)


main(sys.argv[1:])
