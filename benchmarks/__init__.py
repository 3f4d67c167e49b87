"""Speculum benchmarks: ``python -m benchmarks <name> [--json]``.

Each benchmark is a module of this package with ``add_arguments(parser)`` and
``main(args) -> int``; ``SUITES`` names them.  Every suite that renders takes
``--size WxH`` (its output size; ``add_size_argument``), and ``gpu-report`` runs several of
them on one machine and writes what it found (see ``benchmarks/README.md``).
"""
from __future__ import annotations

import argparse

# name -> (module, one-line description)
SUITES: dict[str, tuple[str, str]] = {
    "ecs": ("benchmarks.ecs", "ECS systems + instance upload per frame at 100 / 1,000 / 10,000 entities"),
    "portals": ("benchmarks.portals", "whole frame of a facing portal pair at recursion depth 0-8"),
    "mirrors": ("benchmarks.mirrors", "whole frame with 0-16 mirrors on a ring, per-mirror vs batched vs auto path"),
    "soak": ("benchmarks.soak", "the sample level on a camera tour: GL resources and memory must stay flat"),
    "churn": ("benchmarks.churn", "mirrors, portals, probes, meshes and textures made and deleted in waves"),
    "fuzz": ("benchmarks.fuzz", "adversarial component values and view budgets, several frames a case: each "
             "refused naming Class.field or drawn clean"),
    "probes": ("benchmarks.probes", "probe captures at 128 / 512; whole frames with no / static / dynamic probe"),
    "normal_maps": ("benchmarks.normal_maps", "whole frame with a plain vs a normal-mapped ground (trilinear, 8x)"),
    "stages": ("benchmarks.stages", "each frame stage's CPU time and GPU time (timer queries): mirrors 0/8/16, "
               "a dynamic probe"),
    "profile": ("benchmarks.cpu_profile", "where a frame's CPU time goes, function by function (cProfile): 16 "
                "mirrors, portals at depth 8, a dynamic probe"),
    "cpu": ("benchmarks.cpu", "the frame a GPU host pays for (32x18, LP_NUM_THREADS=0: the engine's CPU) with its "
            "GL calls and profile, and every speed target against its limit"),
    "ab": ("benchmarks.ab", "the cpu suite's scenes from two code trees, interleaved in alternating processes: "
           "new/old ratios and each process's median (how a speed change is judged)"),
    "lighting": ("benchmarks.lighting", "the mirrors scene with shadows and post-processing (tone mapping, "
                 "bloom) on and off, interleaved, and a 4x2 LP_NUM_THREADS=0 stand-in issuing a GPU's 640x360 "
                 "passes: medians, ratios and the lighting cost targets"),
    "gpu-report": ("benchmarks.gpu_report", "GL renderer and limits, rendering-path checks, the mirrors / portals / "
                   "probes / stages / profile / lighting benchmarks at two sizes, the cpu suite and its targets, "
                   "and the whole test suite (minutes: --no-tests leaves it out), as report.md + report.json; exit 1 "
                   "when a test fails or a target that applies here is not met"),
}

# The suites that draw frames: each takes --size WxH.
RENDERING_SUITES = ("ecs", "portals", "mirrors", "soak", "churn", "probes", "normal_maps", "stages", "profile",
                    "lighting")

MAX_SIDE = 16384  # no OpenGL this engine runs on offers a larger render target


def parse_size(text: str) -> tuple[int, int]:
    """``"640x360"`` -> ``(640, 360)``; anything else is an ``argparse.ArgumentTypeError``
    that says what was expected (argparse prints it as ``argument --size: ...``)."""
    parts = text.strip().lower().split("x")
    if len(parts) != 2 or not all(part.strip().isdigit() for part in parts):
        raise argparse.ArgumentTypeError(f"{text!r} is not WIDTHxHEIGHT in pixels (e.g. 640x360)")
    width, height = (int(part) for part in parts)
    if not (1 <= width <= MAX_SIDE and 1 <= height <= MAX_SIDE):
        raise argparse.ArgumentTypeError(f"{text!r}: width and height must be 1 to {MAX_SIDE} pixels")
    return width, height


def parse_sizes(text: str) -> tuple[tuple[int, int], ...]:
    """``"640x360,1920x1080"`` -> ``((640, 360), (1920, 1080))`` (each as ``parse_size``)."""
    sizes = tuple(parse_size(part) for part in text.split(","))
    if len(set(sizes)) != len(sizes):
        raise argparse.ArgumentTypeError(f"{text!r} names a size twice")
    return sizes


def format_size(size: tuple[int, int]) -> str:
    return f"{size[0]}x{size[1]}"


def add_size_argument(parser: argparse.ArgumentParser, default: tuple[int, int], what: str = "output") -> None:
    """``--size WxH`` (stored as ``args.size``, a ``(width, height)`` tuple)."""
    parser.add_argument("--size", type=parse_size, default=default, metavar="WxH",
                        help=f"{what} size in pixels (default {format_size(default)})")


def names_from(text: str, allowed: tuple[str, ...], what: str) -> tuple[str, ...]:
    """``"a,b"`` -> ``("a", "b")``, each one of ``allowed``; else an
    ``argparse.ArgumentTypeError`` naming the unknown ones and the choices."""
    names = tuple(name.strip() for name in text.split(",") if name.strip())
    unknown = sorted(set(names) - set(allowed))
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"unknown {what} {unknown}; choose from {','.join(allowed)}")
    return names


def positive_int(text: str) -> int:
    """An argparse type: an int >= 1 (else an error saying so)."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text} is not >= 1")
    return value


def non_negative_int(text: str) -> int:
    """An argparse type: an int >= 0 (else an error saying so)."""
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text} is not >= 0")
    return value
