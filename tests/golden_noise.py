"""How the golden tolerance was chosen: renderer noise against changes the tests must catch.

    python3 -m tests.golden_noise            # prints one line per (variant, case) and a summary

Every golden case is rendered once as the reference, then again in a fresh process per
variant.  *Noise* variants are the same code on a differently configured llvmpipe: the instruction
sets of older x86 machines (``GALLIUM_OVERRIDE_CPU_CAPS``: AVX without AVX2/FMA, and
SSE4.1 with 128-bit vectors) and other thread counts, i.e. what another machine's llvmpipe
can do to a frame.  (``LP_NATIVE_VECTOR_WIDTH=128`` on an AVX-512 machine crashes Mesa
22.3 in the sample level, so the narrow width is reached through the CPU caps.)
*Change* variants are small deliberate edits the suite must catch: one GGX constant (the
Fresnel exponent), every reflection's GGX weight 5% lower, every mirror's tint 5% darker,
the sun 5% weaker, a crate moved 2 cm.  For each it prints the measures ``tests.golden``
compares (share of pixels over ``pixel_levels``, mean difference, share of id pixels
changed) and whether the current tolerance calls the case changed.  The tolerance is right
when no noise variant fails a case and every change variant fails at least the cases it
touches.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

NOISE = {
    "cpu_avx": {"GALLIUM_OVERRIDE_CPU_CAPS": "avx"},  # no AVX2 / FMA / AVX-512
    "cpu_sse41": {"GALLIUM_OVERRIDE_CPU_CAPS": "sse4.1"},  # 128-bit vectors
    "threads1": {"LP_NUM_THREADS": "1"},
    "threads4": {"LP_NUM_THREADS": "4"},
}
CHANGES = {
    "fresnel_exponent_4": "shader:pow(1.0 - lh, 5.0)=>pow(1.0 - lh, 4.0)",
    "ggx_reflect_5pc_darker": "shader:return f * vis * (4.0 *=>return f * vis * (3.8 *",
    "mirror_tint_5pc_darker": "mirror_tint",
    "sun_5pc_weaker": "sun",
    "crate_moved_2cm": "crate",
}


def _apply_change(change: str) -> None:
    """Install one deliberate change in this process (before any engine is built)."""
    import engine.shader_library as library
    from components import DirectionalLight, Mirror, Transform
    from tests import golden, golden_scenes

    if change.startswith("shader:"):
        old, new = change[len("shader:"):].split("=>")
        resolve = library._resolve

        def patched(name, stack):
            text = resolve(name, stack)
            return text.replace(old, new) if name.startswith("include/") else text
        library._resolve = patched
        return

    def edit(engine) -> None:
        world = engine.world
        if change == "mirror_tint":
            for _, mirror in world.query_one(Mirror):
                mirror.color = tuple(0.95 * c for c in mirror.color)
        elif change == "sun":
            for _, light in world.query_one(DirectionalLight):
                light.intensity *= 0.95
        elif change == "crate":
            for _, transform in world.query_one(Transform):
                if abs(transform.position.y - 0.5) < 1e-6 and transform.parent is None:
                    transform.position = transform.position + (0.02, 0.0, 0.0)
                    break

    original = golden.render_case

    def render_case(ctx, case):
        setup = case.setup

        def both(engine):
            if setup is not None:
                setup(engine)
            edit(engine)
        return original(ctx, golden_scenes.GoldenCase(case.name, case.game, case.camera, both, case.frames))
    golden.render_case = render_case


def render_all(folder: Path, change: str | None) -> None:
    from engine.gl_context import create_headless_context
    from tests import golden
    from tests.golden_scenes import cases

    if change:
        _apply_change(change)
    ctx = create_headless_context()
    for case in cases():
        frame = golden.render_case(ctx, case)
        np.savez(folder / f"{case.name}.npz", rgb=frame.rgb, ids=frame.ids)
    ctx.release()


def _render_in_child(folder: Path, env: dict[str, str], change: str | None) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    command = [sys.executable, "-m", "tests.golden_noise", "--render", str(folder)] + ([change] if change else [])
    subprocess.run(command, check=True, env={**os.environ, **env})


def main() -> int:
    from tests.golden import TOLERANCE, Frame, difference

    with tempfile.TemporaryDirectory() as temp:
        root = Path(temp)
        _render_in_child(root / "reference", {}, None)
        variants = {name: (env, None) for name, env in NOISE.items()}
        variants.update({name: ({}, change) for name, change in CHANGES.items()})
        for name, (env, change) in variants.items():
            _render_in_child(root / name, env, change)
        print(f"tolerance: {TOLERANCE}")
        for name in variants:
            kind = "noise" if name in NOISE else "change"
            failed, worst = [], (0.0, 0.0, 0.0, 0)
            for path in sorted((root / "reference").glob("*.npz")):
                with np.load(path) as a, np.load(root / name / path.name) as b:
                    d = difference(Frame(b["rgb"], b["ids"]), Frame(a["rgb"], a["ids"]))
                worst = tuple(max(x, y) for x, y in zip(worst, (d.changed_share, d.mean_levels, d.ids_share,
                                                                  d.max_levels), strict=True))
                if d.max_levels or d.ids_share:
                    print(f"  {name:24} {path.stem:26} changed {d.changed_share:.4%} mean {d.mean_levels:.3f} "
                          f"max {d.max_levels} ids {d.ids_share:.4%}" + ("  FAILS" if d.failures() else ""))
                if d.failures():
                    failed.append(path.stem)
            print(f"{kind:6} {name:24} worst: changed {worst[0]:.4%} mean {worst[1]:.3f} ids {worst[2]:.4%} "
                  f"max {worst[3]}; cases failed {len(failed)}")
    return 0


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "--render":
        render_all(Path(sys.argv[2]), sys.argv[3] if len(sys.argv) > 3 else None)
        sys.exit(0)
    sys.exit(main())
