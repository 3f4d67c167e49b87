"""Every sample-level view, README example and benchmark scene against its stored frame.

The cases are in ``tests/golden_scenes.py``; how frames are compared, the tolerance and the
measurements behind it are in ``tests/golden.py``.  A failure writes the rendered frame,
the reference and a diff picture (red: colour differs, yellow: beyond the tolerance,
blue: another entity seen) to
``out/golden/`` and names them.  After a change that is meant to alter pictures, regenerate
with ``python3 -m pytest tests/test_golden.py --update-golden`` and say why in the commit.
"""
from __future__ import annotations

import pytest

from engine.gl_context import prepare_context
from tests import golden
from tests.golden_scenes import cases

CASES = cases()


@pytest.mark.parametrize("case", CASES, ids=[case.name for case in CASES])
def test_frame_matches_its_reference(ctx, case, request):
    frame = golden.render_case(ctx, case)
    assert frame.rgb.max() > 0, f"{case.name}: the frame is black"
    if request.config.getoption("--update-golden"):
        golden.save_reference(case.name, frame)
        return
    reference = golden.load_reference(case.name)
    if reference is None:
        written = golden.write_failure(case.name, frame, None)
        pytest.fail(f"{case.name}: no reference in {golden.GOLDEN_DIR}; rendered frame: {written[0]}. "
                    "Make one with: python3 -m pytest tests/test_golden.py --update-golden")
    tolerance = golden.tolerance_for(prepare_context(ctx).software)
    problems = golden.difference(frame, reference, tolerance).failures(tolerance)
    if problems:
        written = golden.write_failure(case.name, frame, reference)
        pytest.fail(f"{case.name}: " + "; ".join(problems) + "\n  " + "\n  ".join(str(p) for p in written))


def test_every_reference_has_a_case():
    """A reference whose case was renamed or dropped would otherwise linger unchecked."""
    names = {case.name for case in CASES}
    stored = {path.name.removesuffix(".ids.npz").removesuffix(".png") for path in golden.GOLDEN_DIR.iterdir()}
    assert stored <= names, f"references with no case: {sorted(stored - names)}"
