"""Running fuzz cases: the loop the component fuzz (``benchmarks/fuzz.py``) and the level-file
fuzz (``benchmarks/level_fuzz.py``) share."""
from __future__ import annotations

import random

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
