"""python -m games.portal_run [--level FILE] [--autopilot | --no-autopilot] [runner options]

Runner options are every game's (``--headless --frames N --out DIR --size WxH ...``;
``--help`` lists them all with the game's).  With no ``--level`` the first shipped level is
played.  A headless run (or one with no display) plays the level's scripted solution unless
``--no-autopilot`` is given, so its frames show the game; a windowed run is played by a
person (``--autopilot`` to watch the solution)."""
from __future__ import annotations

import sys

from engine.assets.level_assets import set_asset_roots
from engine.core.errors import SpeculumError
from engine.render.gl_context import have_display
from games.portal_run.game import PortalRun
from shell.runner import build_parser
from shell.runner import main as run


def main(argv: list[str] | None = None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(PortalRun)
    ours = parser.add_argument_group("portal run")
    ours.add_argument("--autopilot", dest="autopilot", action="store_true", default=None,
                      help="play the level's scripted solution (headless runs do unless --no-autopilot)")
    ours.add_argument("--no-autopilot", dest="autopilot", action="store_false",
                      help="no scripted player, headless too (the player stands at the start)")
    args = parser.parse_args(argv)
    headless = args.headless or not have_display()
    autopilot = headless if args.autopilot is None else args.autopilot
    try:
        set_asset_roots(args.asset_root)  # the game loads its level now, before the runner reads the option
        game = PortalRun(args.level, autopilot=autopilot)
    except (SpeculumError, ValueError) as exc:
        print(f"speculum: error: {exc}", file=sys.stderr)
        sys.exit(2)
    sys.exit(run(game, argv, parser))


main()
