"""Screen text and panels (components/screen.py, engine/render/text.py): the glyphs' pixels
where placed, against the atlas's glyph bitmaps blended at the positions in numpy with
advances read from Pillow's font; no mirror shows the text; the values are checked; level
files carry the components; the games show their text."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from components import (
    ComponentValueError,
    DirectionalLight,
    Material,
    MeshRef,
    Mirror,
    ScreenPanel,
    ScreenText,
    Skybox,
    Transform,
)
from engine.assets.level_file import load_level, save_level
from engine.assets.mesh import box, plane, quad
from engine.core.world import World
from engine.render.text import FONT_SIZE, make_atlas
from tests.support import look_from

SIZE = (200, 120)
MIRROR = {}


def room(world) -> None:
    look_from(world, (0.0, 1.4, 4.0), (0.0, 0.9, 0.0))
    world.spawn(Skybox())
    world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.5), intensity=2.0))
    world.spawn(Transform(), MeshRef(plane(8, 8)), Material(color=(0.5, 0.5, 0.5)))
    world.spawn(Transform(position=(0.8, 0.4, 1.0)), MeshRef(box((0.6, 0.6, 0.6))), Material(color=(0.8, 0.2, 0.1)))
    MIRROR["id"] = world.spawn(Transform(position=(0.0, 1.2, -1.0)), MeshRef(quad(3.0, 2.0)), Material(),
                               Mirror(color=(0.95, 0.95, 1.0)))


def srgb(linear) -> np.ndarray:
    c = np.clip(np.asarray(linear, np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, c * 12.92, 1.055 * c ** (1 / 2.4) - 0.055)


def pillow_advances() -> dict[str, int]:
    """The pen's steps, from Pillow's font directly (not the atlas's table)."""
    from PIL import ImageFont

    font = ImageFont.load_default(size=FONT_SIZE)
    return {chr(c): int(round(font.getlength(chr(c)))) for c in range(32, 127)}


def blend(frame: np.ndarray, coverage: np.ndarray, x: int, y: int, color) -> np.ndarray:
    """``coverage`` (0-255) blended over ``frame`` at (x, y) in ``color`` (linear RGBA), as
    src * a + dst * (1 - a) on the sRGB-encoded values the output holds."""
    out = frame.astype(np.float64)
    h, w = coverage.shape
    x0, y0, x1, y1 = max(x, 0), max(y, 0), min(x + w, frame.shape[1]), min(y + h, frame.shape[0])
    a = coverage[y0 - y:y1 - y, x0 - x:x1 - x, None] / 255.0 * color[3]
    rgb = srgb(color[:3]) * 255.0
    out[y0:y1, x0:x1] = rgb * a + out[y0:y1, x0:x1] * (1.0 - a)
    return out


def expected_text(frame: np.ndarray, text: str, x: int, y: int, color, scale: int = 1) -> np.ndarray:
    """``text`` drawn over ``frame`` with its box's top-left at (x, y): each glyph's atlas
    cell (the bitmap) blended at the pen, the pen moved by Pillow's advances."""
    atlas = make_atlas()
    advances = pillow_advances()
    out = frame.astype(np.float64)
    pen = x
    for ch in text:
        if ch != " ":
            cell = np.kron(atlas.glyph(ord(ch)), np.ones((scale, scale), np.uint8))
            out = blend(out, cell, pen - atlas.origin_x * scale, y, color)
        pen += advances[ch] * scale
    return out


def render(scene, extra=(), frames: int = 2):
    def build(world):
        room(world)
        for components in extra:
            world.spawn(*components)

    runner = scene(build, SIZE)
    for _ in range(frames - 1):
        runner.frame()
    return runner.frame(), runner.ids(), runner


def close_to(a: np.ndarray, b: np.ndarray) -> int:
    return int(np.abs(a.astype(np.float64) - b.astype(np.float64)).max())


def test_glyphs_and_panels_are_the_atlas_bitmaps_where_placed(scene):
    plain, _, _ = render(scene)
    color = (1.0, 0.8, 0.2, 1.0)
    framed, _, _ = render(scene, [(ScreenText("Mirror 42: gj!", position=(12, 10), color=color),)])
    expected = expected_text(plain, "Mirror 42: gj!", 12, 10, color)
    assert close_to(framed, expected) <= 1
    changed = np.abs(framed.astype(int) - plain.astype(int)).max(axis=2) > 40
    assert changed.sum() > 150, "the glyphs are drawn"
    ys, xs = np.nonzero(changed)
    assert ys.min() >= 10 and xs.min() >= 11 and ys.max() < 10 + make_atlas().line_height

    # Scale 2 from the bottom-right corner, over a half-transparent panel.
    atlas = make_atlas()
    text, scale, color = "Hi", 2, (0.2, 1.0, 0.4, 0.9)
    width = sum(pillow_advances()[c] for c in text) * scale
    height = atlas.line_height * scale
    panel = (0.0, 0.0, 0.1, 0.5)
    framed, _, _ = render(scene, [(ScreenPanel(size=(60, 50), position=(-4, -4), anchor="bottom_right",
                                               color=panel),),
                                  (ScreenText(text, position=(-10, -8), anchor="bottom_right", color=color,
                                              scale=scale),)])
    w, h = SIZE
    expected = blend(plain, np.full((50, 60), 255, np.uint8), w - 4 - 60, h - 4 - 50, panel)
    expected = expected_text(expected, text, w - 10 - width, h - 8 - height, color, scale)
    assert close_to(framed, expected) <= 1
    assert np.abs(framed.astype(int) - plain.astype(int)).max(axis=2).astype(bool).sum() > 60 * 50 * 0.9

    # A caption: the text's box plus its padding filled under it.
    text, color, back = "Level 3  1.5 s", (1.0, 1.0, 1.0, 1.0), (0.0, 0.0, 0.0, 0.55)
    framed, _, _ = render(scene, [(ScreenText(text, position=(14, 14), color=color, background=back, padding=5),)])
    width = sum(pillow_advances()[c] for c in text)
    expected = blend(plain, np.full((atlas.line_height + 10, width + 10), 255, np.uint8), 9, 9, back)
    assert close_to(framed, expected_text(expected, text, 14, 14, color)) <= 1


def test_no_mirror_shows_the_text(scene):
    """The text is drawn over the final image: the mirror's pixels outside the text's box
    are the same with and without it, and the id image does not change."""
    plain, plain_ids, runner = render(scene)
    surfaces = runner.engine.renderer.targets.read_surface_ids()
    mirror = surfaces == MIRROR["id"]
    assert mirror.sum() > 2000, "the mirror fills part of the frame"
    # A big text right over the mirror's middle: in the mirror it would be in view.
    text = ScreenText("MIRROR", position=(0, 0), anchor="center", scale=3, color=(1.0, 1.0, 1.0, 1.0))
    framed, framed_ids, framed_runner = render(scene, [(text,)])
    assert np.array_equal(framed_runner.engine.renderer.targets.read_surface_ids(), surfaces)
    atlas = make_atlas()
    width = sum(pillow_advances()[c] for c in "MIRROR") * 3
    height = atlas.line_height * 3
    x0, y0 = (SIZE[0] - width) // 2, (SIZE[1] - height) // 2
    outside = np.ones(mirror.shape, bool)
    outside[y0:y0 + height, x0 - 3 * atlas.origin_x:x0 + width + 3 * atlas.cell[0]] = False
    assert (mirror & ~outside).sum() > 500, "the text covers part of the mirror"
    assert np.array_equal(framed[mirror & outside], plain[mirror & outside])
    assert np.array_equal(framed_ids, plain_ids)
    assert close_to(framed, expected_text(plain, "MIRROR", x0, y0, (1.0, 1.0, 1.0, 1.0), 3)) <= 1


def test_text_changes_and_goes(scene):
    """A write shows in the next frame; deleting the entity leaves the plain frame."""
    plain, _, _ = render(scene)
    framed, _, runner = render(scene, [(ScreenText("a", position=(20, 20)),)])
    entity = next(e for e, _ in runner.world.query_one(ScreenText))
    runner.world.get(entity, ScreenText).text = "b"
    assert close_to(runner.frame(), expected_text(plain, "b", 20, 20, (1, 1, 1, 1))) <= 1
    runner.world.delete_entity(entity)
    assert close_to(runner.frame(), plain) == 0


@pytest.mark.parametrize(("make", "words"), [
    (lambda: ScreenText(anchor="middle"), "ScreenText.anchor"),
    (lambda: ScreenText(scale=0), "ScreenText.scale"),
    (lambda: ScreenText(text=5), "ScreenText.text"),
    (lambda: ScreenText(text="x" * 5000), "at most 4096"),
    (lambda: ScreenText(position=(1, 2, 3)), "ScreenText.position"),
    (lambda: ScreenText(color=(1, 1, 1, 2)), "ScreenText.color"),
    (lambda: ScreenPanel(size=(-1, 4)), "ScreenPanel.size"),
])
def test_bad_values_are_refused_by_name(make, words):
    with pytest.raises(ComponentValueError, match=words.replace(".", r"\.")):
        make()


def test_level_files_carry_screen_text(tmp_path):
    with World("text level") as world:
        world.spawn(ScreenText("hello", position=(10, 12), anchor="top_right", scale=2, order=3))
        world.spawn(ScreenPanel(size=(30, 40), color=(0, 0, 0, 0.5)))
        path = save_level(world, tmp_path / "text.toml")
    with World("loaded") as world:
        names = load_level(path).spawn(world)
        text = world.get(names["entity_1"], ScreenText)
        assert (text.text, tuple(text.position), text.anchor, text.scale, text.order) == \
            ("hello", (10.0, 12.0), "top_right", 2, 3)
        assert tuple(world.get(names["entity_2"], ScreenPanel).size) == (30.0, 40.0)


def text_pixels(frame: np.ndarray, runner_frame) -> int:
    return int((np.abs(frame.astype(int) - runner_frame.astype(int)).max(axis=2) > 40).sum())


def hidden_text_frame(engine, output, capture) -> np.ndarray:
    """The same world's next frame with every ScreenText and ScreenPanel made transparent."""
    for _, text in engine.world.query_one(ScreenText):
        text.color = (*tuple(text.color)[:3], 0.0)
        text.background = None
    for _, panel in engine.world.query_one(ScreenPanel):
        panel.color = (*tuple(panel.color)[:3], 0.0)
    engine.frame(0.0, output)
    return capture.read_rgb()


def run_game(ctx, game, frames: int, size=(320, 180)):
    from engine.core.frame_io import Output
    from engine.render.targets import CaptureTarget
    from shell.app import Engine

    engine = Engine(game, ctx)
    capture = CaptureTarget(ctx, size)
    output = Output(capture.framebuffer, size)
    for _ in range(frames):
        engine.frame(1.0 / 60.0, output)
    return engine, capture, output


def test_mirror_beam_shows_its_level_and_solved(ctx):
    from games.mirror_beam.game import MirrorBeam, levels

    engine, capture, output = run_game(ctx, MirrorBeam(levels()[0], autopilot=True, verbose=False), 12)
    try:
        assert engine.game.state.won
        texts = [t.text for _, t in engine.world.query_one(ScreenText)]
        level = engine.game.state.level_name
        assert any(level in t for t in texts) and any("solved" in t for t in texts), texts
        engine.frame(0.0, output)
        shown = capture.read_rgb()
        Path("out/text").mkdir(parents=True, exist_ok=True)
        from shell.capture import save_png

        save_png(shown, Path("out/text/mirror_beam.png"))
        assert text_pixels(shown, hidden_text_frame(engine, output, capture)) > 300
    finally:
        capture.release()
        engine.close()


def test_portal_run_shows_its_level_and_time(ctx):
    from games.portal_run.game import PortalRun, levels

    engine, capture, output = run_game(ctx, PortalRun(levels()[0], verbose=False), 30)
    try:
        texts = [t.text for _, t in engine.world.query_one(ScreenText)]
        assert any(engine.game.level.name in t for t in texts), texts
        assert any("0.5 s" in t for t in texts), texts  # 30 frames of 1/60 s
        shown = capture.read_rgb()
        from shell.capture import save_png

        Path("out/text").mkdir(parents=True, exist_ok=True)
        save_png(shown, Path("out/text/portal_run.png"))
        assert text_pixels(shown, hidden_text_frame(engine, output, capture)) > 300
    finally:
        capture.release()
        engine.close()


def test_an_f12_screenshot_holds_the_text(scene, tmp_path):
    """The window shell's screenshot presents the frame again and draws the text over it: the
    same picture as a headless frame of the same world."""
    import moderngl_window as mglw
    from PIL import Image

    from shell.window import make_window_config
    from tests.support import FunctionGame

    def build(world):
        room(world)
        world.spawn(ScreenText("F12", position=(10, 10), scale=2, color=(1.0, 0.3, 0.3, 1.0),
                               background=(0.0, 0.0, 0.0, 0.5)))

    config = mglw.create_window_config_instance(
        make_window_config(FunctionGame(build)),
        args=["--window", "headless", "--backend", "egl", "--size", f"{SIZE[0]}x{SIZE[1]}"])
    try:
        for _ in range(2):
            config.on_render(0.0, 1 / 60)
        config.screenshots = tmp_path
        shot = np.asarray(Image.open(config.screenshot()))
    finally:
        config.on_close()
        config.wnd.destroy()
    runner = scene(build, SIZE)
    runner.frame(0.0)
    expected = runner.frame(0.0)
    assert close_to(shot, expected) <= 1
    plain, _, _ = render(scene)
    assert (np.abs(shot.astype(int) - plain.astype(int)).max(axis=2) > 40).sum() > 100, "the text is in the shot"


def test_world_text_is_seen_in_a_mirror_when_asked(scene):
    """Text asked for in the world (engine.assets.world_text.spawn_world_text) is an object:
    a label facing the mirror, its back to the camera (culled), shows only in the mirror:
    every pixel it changes is one of the mirror's, and there are plenty of them."""
    from pyglm import glm as _glm

    from components import Material, MeshRef, Mirror, Transform, look_rotation
    from engine.assets.mesh import quad
    from engine.assets.world_text import spawn_world_text
    from tests.support import look_from

    def build_with(label: bool, from_the_image: bool = False):
        def build(world):
            if from_the_image:   # the eye's image in the mirror's plane (z = -3), looking at the target (on it)
                look_from(world, (0.0, 1.4, -9.0), (0.0, 1.3, -3.0))
            else:
                look_from(world, (0.0, 1.4, 3.0), (0.0, 1.3, -3.0))
                world.resources["mirror"] = world.spawn(Transform(position=(0.0, 1.5, -3.0)),
                                                        MeshRef(quad(4.0, 2.5)), Material(), Mirror())
            if label:  # its front (+Z) turned to the mirror: the camera sees its back
                spawn_world_text(world, "EXIT", (0.0, 1.3, 0.0), look_rotation(_glm.vec3(0.0, 0.0, 1.0)),
                                 height=0.6, color=(1.0, 0.2, 0.1))
        return build

    plain = scene(build_with(False), (160, 120))
    labelled = scene(build_with(True), (160, 120))
    for runner in (plain, labelled):
        runner.engine.renderer.antialias = "off"
        # (the albedo filtered inside the mirror's view as in the main view: the direct view's below)
        runner.engine.renderer.reflection_anisotropy = runner.engine.renderer.texture_anisotropy
    before, after = plain.frame(), labelled.frame()
    changed = np.any(before != after, axis=-1)
    mirror = labelled.engine.renderer.targets.read_surface_ids() == labelled.world.resources["mirror"]
    assert changed.sum() > 100, changed.sum()
    assert not (changed & ~mirror).any(), int((changed & ~mirror).sum())
    from PIL import Image
    Image.fromarray(after).save("/tmp/speculum_world_text.png")  # to look at
    seen = after[changed].astype(int)
    assert (seen[:, 0] > seen[:, 1] + 20).mean() > 0.5   # the label's colour (red), in the mirror
    # It reads in the mirror as the eye's image sees it directly (no mirror there), left for
    # right: turned round, as a mirror shows writing, and not as written.
    direct = scene(build_with(True, from_the_image=True), (160, 120))
    direct.engine.renderer.antialias = "off"
    turned = direct.frame()[:, ::-1].astype(int)
    inner = mirror.copy()   # (the mirror's pixels two in from its edges)
    for axis in (0, 1):
        for shift in (-2, 2):
            inner &= np.roll(mirror, shift, axis=axis)
    assert (changed & inner).sum() > 100, (changed & inner).sum()
    assert np.abs(after[inner].astype(int) - turned[inner]).max() <= 2, np.abs(after[inner] - turned[inner]).max()
    as_written = np.abs(after.astype(int) - turned[:, ::-1]).max(axis=-1)[changed & inner]
    assert (as_written > 20).sum() > 20, (as_written > 20).sum()   # (and not as written)


def test_the_hud_lies_over_the_lens_a_picture_panel_takes_the_frames_look_and_plain_ones_their_colour(scene):
    """Under an active camera with a tone curve a stop up, a grade, and every lens effect at
    full strength (a vignette, film grain, colour fringes, a bloom from 0 up and its flare),
    which the grey wall the camera sees shows (its corner darker than its middle, grainy):
    a picture panel (a ``Monitor`` on it: the monitors' studio's red box) in the top-left
    corner, where the vignette is strongest, is the grade of picture x colour x 2 through the
    curve, sRGB-encoded (the numpy formula of tests/test_color_grading.py) within one 8-bit
    step, untouched by the lens (README: "not the lens's bloom, flare, vignette, aberration or
    grain, which the panel lies over"); a plain panel in the bottom-right corner is its own
    linear colour encoded, ungraded and not tone-mapped, and the text over it is the atlas's
    glyphs blended over that colour in numpy."""
    from components import (
        Bloom,
        ChromaticAberration,
        ColorGrading,
        FilmGrain,
        LensFlare,
        Monitor,
        Tonemap,
        Vignette,
    )
    from tests.test_color_grading import grade
    from tests.test_monitors import DT, PICTURE, active_camera, studio
    from tests.test_post_processing import CURVES, expected_srgb8

    size, tint, plain = (160, 120), np.array([1.0, 0.6, 0.9]), (0.2, 0.5, 0.8, 1.0)
    controls = dict(contrast=1.2, slope=(1.1, 1.0, 0.9), saturation=0.6)
    build, parts = studio(None, eye=(0.0, 1.0, 30.0))   # (the lens sees the red box; the main camera a wall)
    held = {}

    def hud(world):
        build(world)
        camera = active_camera(world)
        for component in (Tonemap(curve="agx", exposure=1.0), ColorGrading(**controls), Vignette(intensity=1.0),
                          FilmGrain(intensity=1.0, response=0.0), ChromaticAberration(intensity=1.0),
                          Bloom(intensity=0.8, threshold=0.0), LensFlare(intensity=1.0)):
            world.add_component(camera, component)
        world.spawn(Transform(position=(0.0, 1.0, 20.0)), MeshRef(quad(40, 40)),
                    Material(color=(0.3, 0.3, 0.3, 1.0), unlit=True))
        held["picture"] = world.spawn(ScreenPanel(size=PICTURE, position=(0, 0), color=(*tint, 1.0)),
                                      Monitor(camera=parts["lens"], size=PICTURE))
        held["plain"] = world.spawn(ScreenPanel(size=(60, 24), position=(0, 0), anchor="bottom_right", color=plain))
        world.spawn(ScreenText("HUD", position=(-20, -4), anchor="bottom_right", color=(1.0, 0.9, 0.1, 1.0), order=1))

    runner = scene(hud, size)
    runner.engine.renderer.antialias = "off"
    for _ in range(2):
        rgb = runner.frame(DT).astype(np.int16)
    # The lens acts on the frame: the wall's corner (bottom-left) darker than its middle, and grainy.
    corner, middle = rgb[size[1] - 12:, :12].mean(), rgb[size[1] // 2 + 10:size[1] // 2 + 22, 70:90].mean()
    assert middle - corner > 20, (middle, corner)
    assert rgb[size[1] // 2 + 10:size[1] // 2 + 22, 70:90].std() > 2.0
    # The picture panel: the frame's exposure, grade and curve, nothing of the lens.
    shown = runner.engine.renderer.monitors.read(held["picture"])[..., :3].astype(np.float64) * tint * 2.0
    assert shown[..., 0].max() > 0.3 and (shown.max(axis=-1) == 0.0).mean() > 0.3   # the box, and black about it
    want = expected_srgb8(CURVES["agx"](grade(shown, **controls)))
    drawn = rgb[:PICTURE[1], :PICTURE[0]]
    assert np.abs(drawn - want).max() <= 1, np.abs(drawn - want).max()
    assert np.abs(want - expected_srgb8(CURVES["agx"](shown))).max() > 8   # (the grade shows)
    # The plain panel: its colour encoded; the text over it the glyphs blended over that colour.
    panel = np.zeros((24, 60, 3)) + np.rint(srgb(plain[:3]) * 255.0)
    text_x = 60 - 20 - (sum(pillow_advances()[ch] for ch in "HUD"))   # (anchored by its box's bottom-right)
    drawn = rgb[size[1] - 24:, size[0] - 60:]
    assert (np.abs(drawn - panel).max(axis=-1) <= 1).mean() > 0.8   # (most of it: no text there)
    atlas = make_atlas()
    text_y = 24 - 4 - atlas.line_height
    want = expected_text(panel, "HUD", text_x, text_y, (1.0, 0.9, 0.1, 1.0))
    assert close_to(drawn, want) <= 1
    assert (np.abs(want - panel).max(axis=-1) > 50).sum() > 20   # (the text is there)
