"""Speculum benchmarks: ``python -m benchmarks <name> [--json]``.

Each benchmark is a module of this package with ``add_arguments(parser)`` and
``main(args) -> int``; ``SUITES`` names them.
"""
from __future__ import annotations

# name -> (module, one-line description)
SUITES: dict[str, tuple[str, str]] = {
    "ecs": ("benchmarks.ecs", "ECS systems + instance upload per frame at 100 / 1,000 / 10,000 entities"),
    "portals": ("benchmarks.portals", "whole frame of a facing portal pair at recursion depth 0-8"),
    "mirrors": ("benchmarks.mirrors", "whole frame with 0-16 mirrors on a ring, per-mirror vs batched vs auto path"),
    "soak": ("benchmarks.soak", "the sample level on a camera tour: GL resources and memory must stay flat"),
    "churn": ("benchmarks.churn", "mirrors, portals, probes, meshes and textures made and deleted in waves"),
    "fuzz": ("benchmarks.fuzz", "adversarial component values: each refused naming Class.field or drawn clean"),
    "probes": ("benchmarks.probes", "probe captures at 128 / 512; whole frames with no / static / dynamic probe"),
    "normal_maps": ("benchmarks.normal_maps", "whole frame with a plain vs a normal-mapped ground (trilinear, 8x)"),
}
