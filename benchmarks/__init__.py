"""Speculum benchmarks: ``python -m benchmarks <name> [--json]``.

Each benchmark is a module of this package with ``add_arguments(parser)`` and
``main(args) -> int``; ``SUITES`` names them (``portals`` comes later).
"""
from __future__ import annotations

# name -> (module, one-line description)
SUITES: dict[str, tuple[str, str]] = {
    "ecs": ("benchmarks.ecs", "ECS systems + instance upload per frame at 100 / 1,000 / 10,000 entities"),
    "mirrors": ("benchmarks.mirrors", "whole frame with 0-16 mirrors on a ring, per-mirror vs batched vs auto path"),
}
