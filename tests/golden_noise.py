"""How the golden tolerances were chosen: renderer noise against changes the tests must catch.

    python3 -m tests.golden_noise                         # the software rule (llvmpipe)
    python3 -m tests.golden_noise --hardware [FRAMES]     # the hardware rule
    python3 -m tests.golden_noise --hardware --save DIR   # ... and keep this machine's frames

**Software rule** (no argument).  Every golden case is rendered once as the reference, then
again in a fresh process per variant.  *Noise* variants are the same code on a differently
configured llvmpipe: the instruction sets of older x86 machines (``GALLIUM_OVERRIDE_CPU_CAPS``:
AVX without AVX2/FMA, and SSE4.1 with 128-bit vectors) and other thread counts, i.e. what
another machine's llvmpipe can do to a frame.  (``LP_NATIVE_VECTOR_WIDTH=128`` on an
AVX-512 machine crashes Mesa 22.3 in the sample level, so the narrow width is reached
through the CPU caps.)  *Change* variants are small deliberate edits the suite must catch
(``CHANGES``): one GGX constant (the Fresnel exponent), every reflection's GGX weight 5%
lower, every mirror's tint 5% darker, the sun 5% weaker, the point lights at 0.8x, a crate
moved 2 cm or 20 cm, one mirror switched off.  For each it prints the measures
``tests.golden.difference`` compares (share of pixels over ``pixel_levels``, mean
difference, share of id pixels changed) and whether ``SOFTWARE_TOLERANCE`` calls the case
changed.  The tolerance is right when no noise variant fails a case and every change
variant fails at least the cases it touches.

**Hardware rule** (``--hardware``).  Every case is rendered on this machine's GL (on a GPU:
the GPU) without and with each change, and compared with the stored llvmpipe references in
``tests/golden/`` by ``tests.golden.hardware_difference``: mean SSIM, the share of pixels
whose SSIM is under ``ssim_poor``, each region grid's largest relative change, the id share.
``FRAMES`` is a folder of frames another machine rendered (``NAME.png`` or ``NAME.<tag>.png``,
e.g. ``../shared/measurements/gpu-h200-golden``): each is measured as well, and so is each
change's own difference (this machine's changed frame less its unchanged one) added to it,
which stands for that machine rendering the change.  On llvmpipe the unchanged frames equal
the references and the lines say how far each change moves the hardware measures; on a GPU
the unchanged lines are the GPU's noise.  ``HARDWARE_TOLERANCE`` is right when no unchanged
GPU frame fails and each change still fails in the cases that show it clearly.  ``--save DIR``
writes this machine's unchanged frames as ``DIR/NAME.png`` (ids as ``NAME.ids.npz``), to be
kept as a GPU's measurement and passed as ``FRAMES`` later.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

NOISE = {
    "cpu_avx": {"GALLIUM_OVERRIDE_CPU_CAPS": "avx"},  # no AVX2 / FMA / AVX-512
    "cpu_sse41": {"GALLIUM_OVERRIDE_CPU_CAPS": "sse4.1"},  # 128-bit vectors
    "threads1": {"LP_NUM_THREADS": "1"},
    "threads4": {"LP_NUM_THREADS": "4"},
}
CHANGES = {
    "fresnel_exponent_4": "shader:pow(1.0 - cosine, 5.0)=>pow(1.0 - cosine, 4.0)",
    "ggx_reflect_5pc_darker": "shader:return f * vis * (4.0 *=>return f * vis * (3.8 *",
    "mirror_tint_5pc_darker": "mirror_tint",
    "sun_5pc_weaker": "sun",
    "point_lights_80pc": "point_lights",
    "crate_moved_2cm": "crate",
    "crate_moved_20cm": "crate_20cm",
    "mirror_switched_off": "mirror_off",
}


def patch_shaders(change: str) -> Callable[[], None]:
    """Install a ``shader:old=>new`` change in the shader library's include expansion (programs
    built from now on see it); returns what undoes it."""
    import engine.render.shader_library as library

    old, new = change[len("shader:"):].split("=>")
    expand = library._expand
    # The process's expanded sources (built unpatched) are set aside while the patch stands,
    # and what is expanded under it is dropped with it.
    expanded = library._EXPANDED
    library._EXPANDED = {}

    def patched(name, stack, root, files, *contents, **branches):  # the library's last good copies, if any
        text = expand(name, stack, root, files, *contents, **branches)
        return text.replace(old, new) if name.startswith("include/") else text
    library._expand = patched

    def undo() -> None:
        library._expand = expand
        library._EXPANDED = expanded
    return undo


def edit_world(change: str, engine) -> None:
    """Apply a world change (every ``CHANGES`` value but the shader ones) to a built engine."""
    from components import DirectionalLight, Mirror, PointLight, Transform

    world = engine.world
    if change == "mirror_tint":
        for _, mirror in world.query_one(Mirror):
            mirror.color = tuple(0.95 * c for c in mirror.color)
    elif change == "sun":
        for _, light in world.query_one(DirectionalLight):
            light.intensity *= 0.95
    elif change == "point_lights":
        for _, light in world.query_one(PointLight):
            light.intensity *= 0.8
    elif change == "mirror_off":
        mirrors = sorted(world.query_one(Mirror), key=lambda item: item[0])
        if mirrors:
            mirrors[0][1].enabled = False
    elif change in ("crate", "crate_20cm"):
        step = 0.02 if change == "crate" else 0.2
        for _, transform in world.query_one(Transform):
            if abs(transform.position.y - 0.5) < 1e-6 and transform.parent is None:
                transform.position = transform.position + (step, 0.0, 0.0)
                break
    else:
        raise ValueError(f"unknown change {change!r}")


def changed_case(case, change: str):
    """The golden case with a world change applied after its own setup."""
    from tests.golden_scenes import GoldenCase

    setup = case.setup

    def both(engine) -> None:
        if setup is not None:
            setup(engine)
        edit_world(change, engine)
    return GoldenCase(case.name, case.game, case.camera, both, case.frames)


def render_all(folder: Path, change: str | None) -> None:
    from engine.render.gl_context import create_headless_context
    from tests import golden
    from tests.golden_scenes import cases

    if change and change.startswith("shader:"):
        patch_shaders(change)
    ctx = create_headless_context()
    for case in cases():
        if change and not change.startswith("shader:"):
            case = changed_case(case, change)
        frame = golden.render_case(ctx, case)
        np.savez(folder / f"{case.name}.npz", rgb=frame.rgb, ids=frame.ids)
    ctx.release()


def _render_in_child(folder: Path, env: dict[str, str], change: str | None) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    command = [sys.executable, "-m", "tests.golden_noise", "--render", str(folder)] + ([change] if change else [])
    subprocess.run(command, check=True, env={**os.environ, **env})


def _load(path: Path):
    from tests.golden import Frame

    with np.load(path) as data:
        return Frame(data["rgb"], data["ids"])


def software_main() -> int:
    from tests.golden import TOLERANCE, difference

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
                d = difference(_load(root / name / path.name), _load(path))
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


def stored_frames(folder: Path) -> dict[str, Path]:
    """Case name -> frame in a folder of another machine's frames (``NAME.png``, ``NAME.tag.png``)."""
    from tests.golden_scenes import cases

    names = {case.name for case in cases()}
    found = {}
    for path in sorted(folder.glob("*.png")):
        name = path.name.split(".", 1)[0]
        if name in names:
            found[name] = path
    return found


def load_stored(path: Path):
    """A stored frame (no id image unless ``NAME.ids.npz`` lies beside it)."""
    from PIL import Image

    from tests.golden import Frame

    rgb = np.asarray(Image.open(path).convert("RGB"))
    ids_path = path.with_name(path.name.split(".", 1)[0] + ".ids.npz")
    if ids_path.is_file():
        with np.load(ids_path) as data:
            return Frame(rgb, data["ids"])
    return Frame(rgb, None)


def with_change(frame, unchanged, changed):
    """``frame`` with the difference a change made to another machine's frame added to it."""
    from tests.golden import Frame

    delta = changed.rgb.astype(np.int16) - unchanged.rgb.astype(np.int16)
    return Frame(np.clip(frame.rgb.astype(np.int16) + delta, 0, 255).astype(np.uint8), None)


def _line(label: str, d, tolerance) -> str:
    regions = " ".join(f"{rows}x{columns} {change:.2%}" for (rows, columns, _), change
                       in zip(tolerance.regions, d.region_change, strict=True))
    ids = "" if d.ids_share is None else f" ids {d.ids_share:.3%}"
    return (f"  {label:54} ssim {d.ssim_mean:.4f} poor {d.ssim_poor_share:.3%} regions {regions}{ids}"
            + ("  FAILS" if d.failures(tolerance) else ""))


def hardware_main(frames: Path | None, save: Path | None) -> int:
    from PIL import Image

    from tests.golden import HARDWARE_TOLERANCE, hardware_difference, load_reference

    tolerance = HARDWARE_TOLERANCE
    stored = stored_frames(frames) if frames is not None else {}
    with tempfile.TemporaryDirectory() as temp:
        root = Path(temp)
        _render_in_child(root / "unchanged", {}, None)
        for name, change in CHANGES.items():
            _render_in_child(root / name, {}, change)
        print(f"tolerance: {tolerance}")
        cases = sorted(path.stem for path in (root / "unchanged").glob("*.npz"))
        references = {name: load_reference(name) for name in cases}
        unchanged = {name: _load(root / "unchanged" / f"{name}.npz") for name in cases}
        if save is not None:
            save.mkdir(parents=True, exist_ok=True)
            for name, frame in unchanged.items():
                Image.fromarray(frame.rgb).save(save / f"{name}.png")
                np.savez_compressed(save / f"{name}.ids.npz", ids=frame.ids)
        print("unchanged frames against the references (this machine's, then the stored ones):")
        noise = []
        for name in cases:
            noise.append(hardware_difference(unchanged[name], references[name], tolerance))
            print(_line(f"this machine {name}", noise[-1], tolerance))
        for name, path in stored.items():
            noise.append(hardware_difference(load_stored(path), references[name], tolerance))
            print(_line(f"{path.name}", noise[-1], tolerance))
        print(f"noise  worst: ssim {min(d.ssim_mean for d in noise):.4f} "
              f"poor {max(d.ssim_poor_share for d in noise):.3%} regions "
              + " ".join(f"{max(d.region_change[i] for d in noise):.2%}" for i in range(len(tolerance.regions)))
              + f"; frames failed {sum(bool(d.failures(tolerance)) for d in noise)} of {len(noise)}")
        for change in CHANGES:
            touched, failed, stored_touched, stored_failed = 0, [], 0, []
            for name in cases:
                frame = _load(root / change / f"{name}.npz")
                if np.array_equal(frame.rgb, unchanged[name].rgb):
                    continue
                touched += 1
                d = hardware_difference(frame, references[name], tolerance)
                print(_line(f"{change} {name}", d, tolerance))
                if d.failures(tolerance):
                    failed.append(name)
                if name in stored:
                    stored_touched += 1
                    d = hardware_difference(with_change(load_stored(stored[name]), unchanged[name], frame),
                                            references[name], tolerance)
                    print(_line(f"{change} {stored[name].name} + change", d, tolerance))
                    if d.failures(tolerance):
                        stored_failed.append(name)
            summary = f"change {change:24} fails {len(failed)} of the {touched} cases it touches"
            if stored:
                summary += f"; added to the stored frames {len(stored_failed)} of {stored_touched}"
            print(summary + (f" ({', '.join(failed)})" if failed else ""))
    return 0


def main(argv: list[str]) -> int:
    if argv and argv[0] == "--render":
        render_all(Path(argv[1]), argv[2] if len(argv) > 2 else None)
        return 0
    if argv and argv[0] == "--hardware":
        rest = argv[1:]
        save = None
        if "--save" in rest:
            at = rest.index("--save")
            save = Path(rest[at + 1])
            del rest[at:at + 2]
        return hardware_main(Path(rest[0]) if rest else None, save)
    return software_main()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
