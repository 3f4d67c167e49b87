"""python -m games.mirror_beam [--level FILE] [--interval N] [runner options]

Headless runs, and runs with no display (which go headless), play the level's solution (the
autopilot) so the frames show it solved; windowed runs are played with the keys (tab or 1-9
pick a mirror, left/right turn it, r restarts, n after a win plays the next level).  A solved
puzzle is said in one line.  ``--help`` lists every option, the game's and the runner's."""
import argparse
import sys

from engine.render.gl_context import have_display
from games.mirror_beam.game import MirrorBeam
from shell.runner import build_parser
from shell.runner import main as run


def _count(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"--interval must be a whole number of frames >= 1, got {text!r}")
    return value


def main(argv: list[str]) -> None:
    parser = build_parser(MirrorBeam)
    ours = parser.add_argument_group("mirror beam")
    ours.add_argument("--interval", type=_count, default=1, metavar="N",
                      help="headless autopilot: frames between its key presses (default 1)")
    args = parser.parse_args(argv)
    headless = args.headless or not have_display()  # the runner goes headless without a display
    sys.exit(run(MirrorBeam(args.level, autopilot=headless, interval=args.interval), argv, parser))


main(sys.argv[1:])
