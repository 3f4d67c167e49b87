"""Colour grading on the camera (``ColorGrading``): white balance, contrast, the ASC CDL's
slope, offset and power, saturation, and a ``.cube`` colour table, through the real present
stage on known HDR images (``tests/test_post_processing.py``'s ``KnownImage``), each against
its formula written here in numpy; the white balance against the CIE's tabulated daylight
whites; the table against its own trilinear lookup on the CPU; the ``.cube`` reader's
refusals; level files."""
from __future__ import annotations

import numpy as np
import pytest

from components import ColorGrading, ComponentValueError, Tonemap
from engine.assets.color_lut import ColorLut, identity_lut, load_cube_lut
from engine.assets.level_file import LevelError, load_level, save_level
from engine.core.errors import AssetError
from engine.core.world import World
from tests import test_post_processing as post_tests
from tests.support import linear_to_srgb8, srgb_to_linear
from tests.test_post_processing import CURVES, expected_srgb8, ramp

known = post_tests.known  # the fixture: a camera's known HDR image through the present stage

LUMA = np.array([0.2126, 0.7152, 0.0722])
# Linear sRGB -> XYZ (IEC 61966-2-1), for the white balance's check.
SRGB_TO_XYZ = np.array([[0.4124564, 0.3575761, 0.1804375],
                        [0.2126729, 0.7151522, 0.0721750],
                        [0.0193339, 0.1191920, 0.9503041]])


def grade(c: np.ndarray, contrast=1.0, slope=(1, 1, 1), offset=(0, 0, 0), power=(1, 1, 1), saturation=1.0):
    """ColorGrading's steps after the white balance, as its docstring gives them."""
    c = np.maximum(c, 0.0)
    c = 0.18 * (np.maximum(c, 1e-10) / 0.18) ** contrast
    c = np.maximum(c * np.array(slope) + np.array(offset), 0.0) ** np.array(power)
    luma = (c * LUMA).sum(axis=-1, keepdims=True)
    return np.maximum(luma + saturation * (c - luma), 0.0)


def _present(known, image, *components) -> np.ndarray:
    return known(image, *components).frame().astype(np.int16)


@pytest.mark.parametrize("settings", [
    dict(contrast=1.5), dict(contrast=0.6), dict(saturation=0.0), dict(saturation=1.8),
    dict(slope=(1.3, 1.0, 0.7)), dict(offset=(0.02, -0.01, 0.0)), dict(power=(1.0, 0.7, 1.4)),
    dict(contrast=1.2, slope=(0.9, 1.1, 1.0), offset=(0.01, 0.0, 0.02), power=(1.1, 1.0, 0.9), saturation=0.7),
], ids=lambda s: ",".join(s))
@pytest.mark.parametrize("curve", ["none", "agx"])
def test_each_control_matches_its_formula(known, settings, curve):
    image = ramp(low=-7.0, high=3.0)
    hdr = image[..., :3].astype(np.float64)
    got = _present(known, image, Tonemap(curve=curve), ColorGrading(**settings))
    want = expected_srgb8(CURVES[curve](grade(hdr, **settings)))
    diff = np.abs(got - want)
    assert diff.max() <= 1, (settings, diff.max(), np.argwhere(diff > 1)[:5])
    plain = expected_srgb8(CURVES[curve](hdr))
    assert np.abs(plain - want).max() > 8, "the setting changes the picture (else the test could not fail)"


def test_the_neutral_grade_changes_nothing(known):
    image = ramp()
    assert np.array_equal(_present(known, image, Tonemap(curve="agx"), ColorGrading()),
                          _present(known, image, Tonemap(curve="agx")))
    # Alone (no Tonemap): the plain curve, the renderer's exposure.
    assert np.array_equal(_present(known, image, ColorGrading()), _present(known, image))


@pytest.mark.parametrize("kelvin, xy", [
    (5003.0, (0.34567, 0.35850)),   # D50
    (5503.0, (0.33242, 0.34743)),   # D55
    (7504.0, (0.29902, 0.31485)),   # D75
])
def test_white_balance_makes_the_daylight_of_its_temperature_neutral(known, kelvin, xy):
    """A grey lit by CIE daylight of a temperature (its white from the CIE's tables, not the
    engine's locus formula) comes out neutral at temperature log2(T / 6504); with the
    temperature at 0 it keeps its cast."""
    x, y = xy
    white = np.linalg.solve(SRGB_TO_XYZ, np.array([x / y, 1.0, (1.0 - x - y) / y]))
    image = np.zeros((8, 16, 4), np.float16)
    image[..., :3] = (0.18 * white / white[1]).astype(np.float16)
    image[..., 3] = 1.0
    temperature = float(np.log2(kelvin / 6504.0))
    balanced = srgb_to_linear(_present(known, image, ColorGrading(temperature=temperature))[2:6, 4:12])
    cast = srgb_to_linear(_present(known, image, ColorGrading())[2:6, 4:12])
    spread = lambda rgb: float((rgb.max(axis=-1) - rgb.min(axis=-1)).max())  # noqa: E731
    assert spread(cast) > 0.01
    assert spread(balanced) < 0.004
    # Warmer and cooler: a bluer light's white balanced makes a neutral grey warmer (red up, blue down).
    grey = np.full((8, 16, 4), 0.18, np.float16)
    grey[..., 3] = 1.0
    warm = srgb_to_linear(_present(known, grey, ColorGrading(temperature=0.5))[4, 8])
    assert warm[0] > warm[1] > warm[2]
    magenta = srgb_to_linear(_present(known, grey, ColorGrading(tint=0.5))[4, 8])
    assert magenta[1] < magenta[0] and magenta[1] < magenta[2]


def _function_lut(size: int) -> ColorLut:
    """A table of a curved function of the input (not linear, so the interpolation shows)."""
    identity = identity_lut(size).table
    r, g, b = identity[..., 0], identity[..., 1], identity[..., 2]
    return ColorLut(np.stack([0.25 + 0.5 * b * b, (r + g) * 0.5, 1.0 - 0.8 * g * g], axis=-1), name="curved")


@pytest.mark.parametrize("size", [2, 9, 33])
def test_a_colour_table_is_looked_up_trilinearly_in_the_encoded_picture(known, size):
    image = ramp(low=-7.0, high=0.5)
    lut = _function_lut(size)
    got = _present(known, image, ColorGrading(lut=lut))
    encoded = linear_to_srgb8(np.clip(image[..., :3].astype(np.float64), 0, 1)) / 255.0  # (before rounding)
    want = np.rint(np.clip(lut.apply(encoded), 0, 1) * 255.0)
    # A GPU filters with fixed-point weights (8 bits of a texel's step): in the 2-texel
    # table, whose texels lie a whole range apart, that is a level more here and there (the
    # NVIDIA H200: 26 of 9216 values 2 levels off; llvmpipe: none).  A nearest lookup is tens
    # of levels off.
    off = np.abs(got - want)
    assert off.max() <= 2 and (off > 1).mean() < 0.01
    half = _present(known, image, ColorGrading(lut=lut, lut_strength=0.5))
    want_half = np.rint(np.clip(0.5 * lut.apply(encoded) + 0.5 * encoded, 0, 1) * 255.0)
    assert np.abs(half - want_half).max() <= 1
    assert np.abs(want - want_half).max() > 20


def test_an_identity_table_changes_nothing_and_its_texture_goes_with_it(known):
    image = ramp(low=-7.0, high=0.5)
    runner = known(image, ColorGrading(lut=identity_lut(17)))
    got = runner.frame().astype(np.int16)
    assert np.abs(got - _present(known, image)).max() <= 1
    renderer = runner.engine.renderer
    with_table = renderer.resource_counts()["post_targets"]
    grading = runner.world.get(runner.game.camera, ColorGrading)
    grading.lut = None
    runner.frame()
    assert renderer.resource_counts()["post_targets"] == with_table - 1


def _cube(path, size: int = 2, rows=None, header: str = "") -> str:
    axis = np.linspace(0.0, 1.0, size)
    lines = [f"{r:.4f} {g:.4f} {b:.4f}" for b in axis for g in axis for r in axis] if rows is None else rows
    path.write_text(f"TITLE \"t\"\n{header}LUT_3D_SIZE {size}\n" + "\n".join(lines) + "\n")
    return str(path)


def test_a_cube_file_is_read_red_fastest_with_its_domain(tmp_path):
    axis = np.linspace(0.0, 1.0, 3)
    rows = [f"{b} {g} {r}" for b in axis for g in axis for r in axis]  # red and blue swapped
    lut = load_cube_lut(_cube(tmp_path / "swap.cube", 3, rows, header="# a comment\nDOMAIN_MIN 0 0 0\n"
                                                                    "DOMAIN_MAX 2 2 2\n"))
    assert lut.size == 3 and lut.name == "t" and lut.domain_max == (2.0, 2.0, 2.0)
    np.testing.assert_allclose(lut.table[0, 1, 2], [0.0, 0.5, 1.0])   # [b][g][r]: r=1, g=0.5, b=0
    np.testing.assert_allclose(lut.apply(np.array([2.0, 1.0, 0.0])), [0.0, 0.5, 1.0])


@pytest.mark.parametrize("text, message", [
    ("LUT_1D_SIZE 4\n0 0 0\n", "1D table"),
    ("LUT_3D_SIZE 1\n0 0 0\n", "LUT_3D_SIZE must be an integer from 2"),
    ("LUT_3D_SIZE 2\n" + "0 0 0\n" * 7, "needs 8 rows"),
    ("LUT_3D_SIZE 2\n" + "0 0 0\n" * 6 + "0 0 x\n0 0 0\n", "line 8"),
    ("LUT_3D_SIZE 2\n" + "0 0 0\n" * 6 + "0 0\n0 0 0 0\n", "line 8"),
    ("LUT_3D_SIZE 2\n" + "0 0 0\n" * 7 + "nan 0 0\n", "not finite"),
    ("LUT_3D_SIZE 2\n" + "0 0 0\n" * 7 + "1e6 0 0\n", "half float"),
    ("LUT_3D_SIZE 2\nDOMAIN_MIN 1 0 0\n" + "0 0 0\n" * 8, "min < max"),
    ("LUT_3D_SIZE 2\nSHAPE round\n" + "0 0 0\n" * 8, "unknown keyword 'SHAPE'"),
    ("0 0 0\n", "no LUT_3D_SIZE"),
    ("LUT_3D_SIZE 2\n" + "0 0 0\n" * 4 + "LUT_3D_SIZE 2\n" + "0 0 0\n" * 4, "after the table's first row"),
])
def test_a_bad_cube_file_is_refused_naming_the_file_and_line(tmp_path, text, message):
    path = tmp_path / "bad.cube"
    path.write_text(text)
    with pytest.raises(AssetError, match="bad.cube") as caught:
        load_cube_lut(path)
    assert message in str(caught.value)


def test_a_missing_or_binary_cube_file_is_refused(tmp_path):
    with pytest.raises(AssetError, match="no.cube"):
        load_cube_lut(tmp_path / "no.cube")
    (tmp_path / "binary.cube").write_bytes(b"\xff\xfe\x00LUT")
    with pytest.raises(AssetError, match="not a text file"):
        load_cube_lut(tmp_path / "binary.cube")


@pytest.mark.parametrize("field, value", [
    ("temperature", 1.5), ("tint", -2.0), ("contrast", -0.1), ("contrast", float("nan")), ("saturation", 5.0),
    ("slope", (1.0, -1.0, 1.0)), ("slope", (20.0, 1.0, 1.0)), ("offset", (2.0, 0.0, 0.0)),
    ("power", (1.0, 0.0, 1.0)), ("power", "bright"), ("offset", (0.0, 0.0, 0.0, 0.0)), ("slope", (1.0, 2.0, 10 ** 400)),
    ("lut", "grade.cube"), ("lut_strength", 1.5),
])
def test_bad_values_are_refused_naming_the_field(field, value):
    with pytest.raises(ComponentValueError, match=f"ColorGrading.{field}"):
        ColorGrading(**{field: value})


def test_a_level_file_keeps_it(tmp_path):
    _cube(tmp_path / "grade.cube", 3)
    (tmp_path / "room.toml").write_text("""[level]
name = "room"

[[entity]]
name = "camera"
Transform = { position = [0.0, 1.0, 3.0] }
Camera = {}
ColorGrading = { temperature = 0.3, slope = [1.1, 1.0, 0.9], lut = { file = "grade.cube" }, lut_strength = 0.5 }
Vignette = { intensity = 0.3, falloff = 6.0 }
""")
    world = World()
    names = load_level(tmp_path / "room.toml").spawn(world)
    grading = world.get(names["camera"], ColorGrading)
    assert tuple(grading.slope) == pytest.approx((1.1, 1.0, 0.9)) and grading.lut.size == 3
    assert grading.lut_strength == 0.5
    saved = save_level(world, tmp_path / "again.toml", names, name="room")
    assert 'lut = { file = "grade.cube" }' in saved.read_text()
    assert "slope = [1.1, 1.0, 0.9]" in saved.read_text()
    again = World()
    names = load_level(saved).spawn(again)
    assert again.get(names["camera"], ColorGrading).temperature == pytest.approx(0.3)
    from components import Vignette
    assert (again.get(names["camera"], Vignette).intensity, again.get(names["camera"], Vignette).falloff) == (0.3, 6.0)
    (tmp_path / "bad.toml").write_text('[level]\nname = "bad"\n\n[[entity]]\nname = "camera"\nCamera = {}\n'
                                       'ColorGrading = { lut = { file = "missing.cube" } }\n')
    with pytest.raises(LevelError, match="missing.cube"):
        load_level(tmp_path / "bad.toml")


def test_the_overlay_line_and_the_present_stages_switch(known):
    """The overlay's post line names the grade and its table; ``PresentSystem.grade = False``
    presents every camera ungraded (the debug overlay's "grade" switch)."""
    from shell.overlay_text import post_lines

    image = ramp(low=-7.0, high=0.5)
    lut = _function_lut(5)
    runner = known(image, ColorGrading(saturation=0.2, lut=lut))
    graded = runner.frame()
    assert post_lines(runner.engine)[0].endswith("; graded, table 'curved'")
    assert post_lines(runner.engine)[1] == "screen: AO off; SSR off"
    runner.engine.stages["present"].grade = False
    assert np.array_equal(runner.frame(), _present(known, image))
    assert "grade off (set)" in post_lines(runner.engine)[0]
    assert not np.array_equal(graded, _present(known, image))


# --- vignette -------------------------------------------------------------------------------

@pytest.mark.parametrize("intensity, falloff", [(1.0, 4.0), (0.5, 4.0), (0.8, 8.0)])
def test_the_vignette_darkens_each_pixel_by_cos_theta_to_the_falloff(known, intensity, falloff):
    """A grey frame through a camera with a Vignette: each pixel's linear value is the grey
    times 1 - intensity + intensity cos(theta) ** falloff, theta the angle between the
    pixel's ray (cast here from the view's matrices) and the view axis."""
    from components import Vignette
    from tests.support import pixel_rays

    image = np.full((72, 128, 4), 0.5, np.float16)
    image[..., 3] = 1.0
    runner = known(image, Vignette(intensity=intensity, falloff=falloff))
    got = srgb_to_linear(runner.frame()).mean(axis=-1)
    view = runner.engine.main_view
    _, rays = pixel_rays(view, runner.size)
    forward = -np.array(view.view.to_list(), np.float64)[:3, 2]   # the view axis, world space
    cos_theta = np.flipud(rays @ (forward / np.linalg.norm(forward)))   # (GL row order, as the frame)
    want = 0.5 * (1.0 - intensity + intensity * cos_theta ** falloff)
    np.testing.assert_allclose(got, want, atol=0.004)
    assert want.min() < 0.45   # the corners are darker than the middle by far more than the tolerance
    assert got[36, 64] == pytest.approx(0.5, abs=0.004)


def test_a_vignette_of_no_intensity_or_switched_off_changes_nothing(known):
    from components import Vignette

    image = ramp()
    plain = _present(known, image)
    assert np.array_equal(_present(known, image, Vignette(intensity=0.0)), plain)
    runner = known(image, Vignette())
    runner.engine.stages["present"].grade = False   # the overlay's grade switch turns it off too
    assert np.array_equal(runner.frame().astype(np.int16), plain)


@pytest.mark.parametrize("field, value", [("intensity", 1.5), ("intensity", -0.1), ("falloff", 20.0),
                                          ("falloff", float("inf"))])
def test_bad_vignette_values_are_refused_naming_the_field(field, value):
    from components import Vignette

    with pytest.raises(ComponentValueError, match=f"Vignette.{field}"):
        Vignette(**{field: value})


def test_a_tables_edit_in_place_raises_at_the_edit_and_a_callers_array_is_not_shared():
    """The GPU's copy of a table is made once, so an edit in place would never show: it is
    refused where it is made; the table is the ColorLut's own copy (the caller's array
    changed afterwards changes nothing)."""
    source = identity_lut(5).table.copy()
    lut = ColorLut(source)
    with pytest.raises(ValueError, match="read-only"):
        lut.table[0, 0, 0] = (1.0, 0.0, 0.0)
    source[0, 0, 0] = (1.0, 0.0, 0.0)
    assert lut.table[0, 0, 0].tolist() == [0.0, 0.0, 0.0]


def test_a_picture_panel_is_white_balanced_and_graded_as_the_frame_and_ungraded_with_it(scene):
    """A picture panel (a ``ScreenPanel`` with a ``Monitor``: the monitors' studio's red box
    on black, tinted) under a camera whose ``ColorGrading`` uses every control the panel test
    of tests/test_monitors.py leaves out: white balance (temperature and tint), the CDL's
    offset and power.  Each panel pixel is ``grade`` here (after the white balance's matrix,
    the one the daylight test above checks against the CIE's whites) of picture x colour x
    exposure, through the curve, encoded: within one 8-bit step, and far from the panel
    without the white balance or without the rest.  The present stage's grade switch off
    (the overlay's): the panel is ungraded as the frame is, the curve of the picture alone."""
    from components import Monitor, ScreenPanel
    from engine.render.grading import white_balance
    from tests.test_monitors import DT, PICTURE, active_camera, studio

    build, parts = studio(None, eye=(0.0, 1.0, 30.0))   # (the main camera sees black: the box is far off)
    tint = np.array([1.0, 0.8, 0.6])
    controls = dict(offset=(0.01, 0.02, 0.0), power=(0.8, 1.0, 1.25), contrast=1.1)
    temperature, hue = 0.8, 0.6
    held = {}

    def hud(world):
        build(world)
        camera = active_camera(world)
        world.add_component(camera, Tonemap(curve="agx", exposure=1.0))
        world.add_component(camera, ColorGrading(temperature=temperature, tint=hue, **controls))
        held["panel"] = world.spawn(ScreenPanel(size=PICTURE, position=(10, 6), color=(*tint, 1.0)),
                                    Monitor(camera=parts["lens"], size=PICTURE))

    runner = scene(hud, (128, 72))
    runner.engine.renderer.antialias = "off"
    for _ in range(2):
        rgb = runner.frame(DT)
    shown = runner.engine.renderer.monitors.read(held["panel"])[..., :3].astype(np.float64) * tint * 2.0
    assert shown[..., 0].max() > 0.3 and (shown.max(axis=-1) == 0.0).mean() > 0.3   # the box, and black about it
    balance = white_balance(temperature, hue)
    assert np.abs(balance - np.eye(3)).max() > 0.05

    def panel(linear):
        return expected_srgb8(CURVES["agx"](linear))

    drawn = rgb[6:6 + PICTURE[1], 10:10 + PICTURE[0]].astype(np.int16)
    want = panel(grade(shown @ balance.T, **controls))
    off = np.abs(drawn - want)
    assert off.max() <= 1, (off.max(), np.argwhere(off > 1)[:5])
    assert np.abs(want - panel(grade(shown, **controls))).max() > 5   # (the white balance shows)
    assert np.abs(want - panel(shown @ balance.T)).max() > 8           # (and the CDL's steps)
    runner.engine.stages["present"].grade = False
    drawn = runner.frame(DT)[6:6 + PICTURE[1], 10:10 + PICTURE[0]].astype(np.int16)
    assert np.abs(drawn - panel(shown)).max() <= 1
