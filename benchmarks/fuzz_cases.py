"""Running fuzz cases: the loop the component fuzz (``benchmarks/fuzz.py``), the level-file
fuzz (``benchmarks/level_fuzz.py``) and the still-frame fuzz (``benchmarks/still_fuzz.py``)
share, the check of a frame's HDR image they all make, and the pool of awkward values the
component and still-frame fuzzes draw from."""
from __future__ import annotations

import random
from typing import Any

import numpy as np
from pyglm import glm

from components.tracking import HALF_MAX
from engine.assets.mesh import box, quad, sphere
from engine.assets.texture_data import checker_texture

FRAMES = 3  # frames each fuzz renders a case: probes, time-sliced captures and uploads settle over a few


def run_cases(fuzzer, make_case, cases: int, seed: int, report=None) -> tuple[int, list[tuple[str, str]],
                                                                             dict[str, int]]:
    """``cases`` cases from ``make_case(rng)`` through ``fuzzer.run(case, index)``, then the
    fuzzer closed; the count run, the failures (case, why) and passes by kind."""
    rng = random.Random(seed)
    failures: list[tuple[str, str]] = []
    try:
        for index in range(cases):
            case = make_case(rng)
            why = fuzzer.run(case, index)
            if why is not None:
                failures.append((case.describe(), why))
                if report is not None:
                    report(index, case, why)
        passes = {"refused": fuzzer.refused, "rendered": fuzzer.rendered}
    finally:
        fuzzer.close()
    return cases, failures, passes


def hdr_image(targets) -> np.ndarray:
    """The main image's HDR colour as stored (flat): half floats, or float32 where
    ``--hdr32`` widened the colour images (``engine.render.targets.HDR_FORMAT``)."""
    texture = targets.color
    return np.frombuffer(texture.read(), np.dtype(texture.dtype))


def hdr_problem(hdr: np.ndarray) -> str | None:
    """What is wrong with an HDR image: values not finite, or (float32 images: ``--hdr32``)
    past a half float's 65504, which a GPU whose conversion rounds correctly stores as +inf
    (llvmpipe saturates them: only float32 images show them).  None: nothing."""
    bad = ~np.isfinite(hdr)
    if bad.any():
        return f"{int(bad.sum())} non-finite values in the HDR colour target"
    past = hdr > HALF_MAX
    if past.any():
        return (f"{int(past.sum())} values past 65504 in the HDR colour target (up to {float(hdr.max()):.6g}: "
                f"a half float stores them as +inf where its conversion rounds correctly)")
    return None


_NUMBERS: list[Any] = [0, 1, -1, 0.5, 2.0, 1e-30, 1e-4, 3.0, 16, 100.0, 1e5, 65504.0, 65505.0, 1e7, 1e20,
                       3.4e38, 1e39, float("nan"), float("inf"), -float("inf"), 10 ** 400, 2 ** 63, 2 ** 64 + 5,
                       -(2 ** 63), 179.0, 0.1]
_OTHER: list[Any] = [None, True, False, "x", "skybox", "cube", "on_change", b"1", [], {}, (), object()]


def _vectors(rng: random.Random) -> Any:
    n = rng.choice((2, 3, 3, 4, 4, 5))
    return tuple(rng.choice(_NUMBERS) for _ in range(n))


def random_value(rng: random.Random) -> Any:
    """One adversarial value for any field (kinds mixed on purpose)."""
    if rng.random() < 0.35:
        # Plausible values too, so a good share of cases get as far as a frame.
        return rng.choice((rng.uniform(0.0, 1.0), rng.randint(1, 8), rng.random() < 0.5,
                           tuple(rng.uniform(0.0, 1.0) for _ in range(3)),
                           tuple(rng.uniform(0.0, 1.0) for _ in range(4)),
                           (1.0, rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)),
                           rng.choice((64, 128)), rng.uniform(1.0, 3.0)))
    roll = rng.random()
    if roll < 0.35:
        return rng.choice(_NUMBERS)
    if roll < 0.65:
        return _vectors(rng)
    if roll < 0.75:
        return rng.choice(_OTHER)
    if roll < 0.82:
        return rng.choice((glm.quat(1e20, 0, 1e20, 0), glm.quat(0, 0, 0, 0), glm.quat(), (0, 90, 0),
                           glm.vec3(1e39, 0, 0), glm.vec3(0), glm.vec4(1, 1, 1, 1)))
    if roll < 0.88:
        return rng.choice((box(), quad(0, 0), quad(1, 1), sphere(0.5, 8, 4), checker_texture(8, 2)))
    if roll < 0.94:
        return rng.choice(("skybox", "planar", "cube", "portal", "once", "every_frame", "never", "atmosphere"))
    return rng.uniform(-10, 10)


_FUZZ_RIPPLES: list = []


def fuzz_ripples():
    """One small normal map for every water the fuzz makes (made once)."""
    if not _FUZZ_RIPPLES:
        from engine.assets.texture_data import ripple_normal_map
        _FUZZ_RIPPLES.append(ripple_normal_map(16))
    return _FUZZ_RIPPLES[0]
