"""``python -m benchmarks <name> [--json]``: run one benchmark suite."""
from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from benchmarks import SUITES


def build_parser() -> tuple[argparse.ArgumentParser, dict]:
    """The command line of every suite: (parser, {suite name: its module})."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks", description="Speculum benchmarks")
    commands = parser.add_subparsers(dest="suite", required=True, metavar="<name>")
    modules = {}
    for name, (module_name, help_text) in SUITES.items():
        module = modules[name] = importlib.import_module(module_name)
        sub = commands.add_parser(name, help=help_text, description=module.__doc__,
                                  formatter_class=argparse.RawDescriptionHelpFormatter)
        sub.add_argument("--json", action="store_true", help="print one JSON object per line instead of a table")
        module.add_arguments(sub)
    return parser, modules


def main(argv: Sequence[str] | None = None) -> int:
    parser, modules = build_parser()
    args = parser.parse_args(argv)
    return modules[args.suite].main(args)


if __name__ == "__main__":
    sys.exit(main())
