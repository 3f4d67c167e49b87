"""The overlay's level editor: a click in the world selects the entity seen there, the
inspector lists its components and fields, a drag on a number field edits it through the
editor (one undo step), and a refused value shows the component's message. Headless,
through ImGui with the mouse events a window forwards."""
from __future__ import annotations

import math
from contextlib import contextmanager

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, Material, Transform

pytest.importorskip("imgui_bundle", reason="the debug overlay needs imgui-bundle (not installed here)")
from shell.overlay import DebugOverlay  # noqa: E402
from tests.test_level_edit import edit_scene  # noqa: E402
from tests.test_mirrors import reflected_pixel  # noqa: E402
from tests.test_pick import BOX  # noqa: E402

SIZE = (640, 480)


def test_click_inspect_drag_undo_and_a_refused_value(scene, ctx):
    ents = {}
    runner = scene(lambda world: edit_scene(world, ents), SIZE)
    runner.frame()
    overlay = DebugOverlay(ctx)
    try:
        def draw() -> None:
            runner.frame()
            overlay.record(1 / 60)
            overlay.draw(runner.engine, runner.capture.framebuffer, SIZE)

        assert overlay.click(runner.engine, *reflected_pixel(runner, BOX))  # the box, seen in the mirror
        editor = overlay.editor
        box = ents["box"]
        assert editor.selected == box
        draw()
        assert overlay.inspector_lines[0] == f"entity {box}"
        assert {"Transform", "MeshRef", "Material"} <= set(overlay.inspector_lines)
        assert "  roughness = 0.4" in overlay.inspector_lines

        x, y = overlay.widgets["Material.roughness"]
        overlay.mouse_moved(x, y)
        draw()
        overlay.mouse_button(1, True)
        draw()
        for step in range(1, 6):
            overlay.mouse_moved(x + 8 * step, y)
            draw()
        overlay.mouse_button(1, False)
        draw()
        dragged = runner.world.get(box, Material).roughness
        assert dragged > 0.45, dragged
        assert editor.undo() and runner.world.get(box, Material).roughness == pytest.approx(0.4)
        assert not editor.can_undo  # the whole drag was one edit

        # A rotation drags as angles in degrees; one undo puts it back.  (The inspector is
        # as tall as the window at most: the wheel over it brings the field into view.)
        x, y = _scrolled_to(overlay, draw, "Transform.rotation", SIZE)
        overlay.mouse_moved(x, y)
        draw()
        overlay.mouse_button(1, True)
        draw()
        for step in range(1, 6):
            overlay.mouse_moved(x + 8 * step, y)
            draw()
        overlay.mouse_button(1, False)
        draw()
        turned = runner.world.get(box, Transform).rotation
        assert glm.degrees(glm.angle(turned)) > 5.0, turned
        assert editor.undo() and runner.world.get(box, Transform).rotation == glm.quat()

        with pytest.raises(ComponentValueError) as refused:
            Material(roughness=2.0)
        assert editor.try_set_field(box, "Material", "roughness", 2.0) is not None
        draw()
        assert overlay.inspector_lines[0] == str(refused.value)
        assert runner.world.get(box, Material).roughness == pytest.approx(0.4)

        # Ctrl+click (surface) on the same pixel selects the mirror, and the sky nothing.
        overlay.click(runner.engine, *reflected_pixel(runner, BOX), surface=True)
        assert editor.selected == ents["mirror"]
        overlay.click(runner.engine, SIZE[0] // 2, 3)
        assert editor.selected is None
        draw()
        assert overlay.inspector_lines == []  # no inspector without a selection
        assert ctx.error == "GL_NO_ERROR"
    finally:
        overlay.release()


WINDOW_SCRIPT = r'''
import json, shutil, sys, time
from pathlib import Path

import moderngl_window as mglw
from pyglet.window import key, mouse
from pyglm import glm

from components import Material, Transform
from games.hall_of_mirrors.level import HallOfMirrors
from shell.window import make_window_config

level = Path(sys.argv[1])
game = HallOfMirrors(level)
config = mglw.create_window_config_instance(make_window_config(game), args=["--window", "pyglet", "--size", "960x540"])
window = config.wnd._window
world = config.engine.world
errors = []
w, h = config.wnd.size

def frame():
    config.on_render(0.0, 1 / 60)
    config.wnd.swap_buffers()
    errors.append(config.ctx.error)

def pump():
    window.dispatch_events()
    frame()

def at(x, y):  # the overlay's pixels are from the top, pyglet's from the bottom
    return int(x), int(h - y)

def click(x, y):
    window.dispatch_event("on_mouse_motion", x, y, 0, 0)
    pump()
    window.dispatch_event("on_mouse_press", x, y, mouse.LEFT, 0)
    pump()
    window.dispatch_event("on_mouse_release", x, y, mouse.LEFT, 0)
    pump()

config.engine.place_camera(2.4, 1.5, 1.0, 0.0, -18.0)
frame()
window.dispatch_event("on_key_press", key.F1, 0)
window.dispatch_event("on_key_release", key.F1, 0)
pump()
crate = game.names["blue_crate"]
clip = config.engine.main_view.view_proj * glm.vec4(world.get(crate, Transform).position, 1.0)
click(int((clip.x / clip.w * 0.5 + 0.5) * w), int((clip.y / clip.w * 0.5 + 0.5) * h))
pump()
selected = config.overlay.editor.selected
x, y = config.overlay.widgets["Material.roughness"]
window.dispatch_event("on_mouse_motion", *at(x, y), 0, 0)
pump()
window.dispatch_event("on_mouse_press", *at(x, y), mouse.LEFT, 0)
pump()
for step in range(1, 6):
    window.dispatch_event("on_mouse_drag", *at(x + 8 * step, y), 8, 0, mouse.LEFT, 0)
    pump()
window.dispatch_event("on_mouse_release", *at(x + 40, y), mouse.LEFT, 0)
pump()
roughness = world.get(crate, Material).roughness
click(*at(*config.overlay.widgets["save"]))
message = config.overlay.editor.message
for _ in range(4):  # past two of the level reload's polls: the save is the world, nothing is rebuilt
    time.sleep(0.2)
    pump()
kept = world.exists(crate) and config.engine.level_reload.reloads == 0 and config.overlay.editor.can_undo
mirror = game.names["mirror_4"]
low = world.get(mirror, Transform).position - glm.vec3(0.0, 1.0, 0.0)  # low on the glass: it shows the floor
clip = config.engine.main_view.view_proj * glm.vec4(low, 1.0)
px, py = int((clip.x / clip.w * 0.5 + 0.5) * w), int((clip.y / clip.w * 0.5 + 0.5) * h)
window.dispatch_event("on_mouse_motion", px, py, 0, 0)  # off the inspector first, as a hand would
pump()
window.dispatch_event("on_mouse_press", px, py, mouse.LEFT, 2)  # Ctrl held (pyglet's MOD_CTRL)
window.dispatch_event("on_mouse_release", px, py, mouse.LEFT, 2)
pump()
with_ctrl = config.overlay.editor.selected
window.dispatch_event("on_mouse_press", px, py, mouse.LEFT, 0)
window.dispatch_event("on_mouse_release", px, py, mouse.LEFT, 0)
pump()
plain = config.overlay.editor.selected
window.dispatch_event("on_key_press", key.ESCAPE, 0)
window.dispatch_events()
print(json.dumps({"errors": errors, "selected": selected == crate, "roughness": roughness, "message": message,
                  "released": config.released, "kept": kept,
                  "mirror": [with_ctrl == mirror, plain not in (mirror, None)]}))
config.wnd.destroy()
'''


def test_in_a_real_window_click_edit_save_and_esc(x_display, tmp_path):
    """The sample level in an X window (Xvfb, pyglet), events through pyglet's queue: F1,
    a click on the blue crate selects it, a drag on its roughness edits it, a click on save
    writes the level file (its diff is that one line), Ctrl+click on a mirror selects the
    mirror and a plain click what it shows, Esc ends the run (exit 0), and no
    frame has a GL error. Skipped, saying why, without Xvfb or pyglet."""
    import difflib
    import json
    import os
    import shutil
    import subprocess
    import sys

    from tests.test_level_edit import HALL, ROOT

    level = tmp_path / "hall.toml"
    shutil.copy(HALL, level)
    env = {**os.environ, "DISPLAY": x_display, "PYTHONPATH": str(ROOT), "SPECULUM_DEBUG": "1"}
    result = subprocess.run([sys.executable, "-c", WINDOW_SCRIPT, str(level)], cwd=tmp_path, env=env,
                            capture_output=True, text=True, timeout=180)
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads(result.stdout.strip().splitlines()[-1])
    assert set(report["errors"]) == {"GL_NO_ERROR"}
    assert report["selected"] and report["released"] and report["kept"]
    assert report["mirror"] == [True, True]  # Ctrl+click: the mirror; a plain click: what it shows there
    assert report["roughness"] > 0.65, report
    assert report["message"] == f"saved {level}"
    changed = [line for line in difflib.unified_diff(HALL.read_text().splitlines(), level.read_text().splitlines(),
                                                     lineterm="", n=0) if not line.startswith(("---", "+++", "@@"))]
    assert changed == ["-roughness = 0.6", f"+roughness = {report['roughness']!r}"]


def test_layers_are_typed_as_whole_numbers_and_edited_through_the_component(scene, ctx):
    """A mirror's hides_layers typed in the inspector ("3" then Enter) goes through the
    editor and the component's own check; text that is not numbers changes nothing."""
    from components import Mirror
    from shell.editor_panels import parse_layers

    assert parse_layers("1, 3") == [1, 3] and parse_layers("1 3") == [1, 3] and parse_layers("") == []
    assert parse_layers("one") is None
    ents = {}
    runner = scene(lambda world: edit_scene(world, ents), SIZE)
    runner.frame()
    overlay = DebugOverlay(ctx)
    try:
        mirror = ents["mirror"]
        overlay.click(runner.engine, *runner.project(runner.world.get(mirror, Transform).position), surface=True)
        editor = overlay.editor
        assert editor.selected == mirror
        assert editor.try_set_field(mirror, "Mirror", "hides_layers", parse_layers("3")) is None  # None: taken
        assert runner.world.get(mirror, Mirror).layer_mask & (1 << 3) == 0
        refused = editor.try_set_field(mirror, "Mirror", "hides_layers", [99])   # past the 16 layers
        assert refused and "hides_layers" in refused, refused
        assert tuple(runner.world.get(mirror, Mirror).hides_layers) == (3,)
    finally:
        overlay.release()


def _hands(runner, overlay, size=SIZE):
    """``draw()``: a frame with the overlay over it; ``click(widget)``: the mouse to the
    widget's centre, pressed and let go, a frame at each step and one after."""
    def draw() -> None:
        runner.frame()
        overlay.record(1 / 60)
        overlay.draw(runner.engine, runner.capture.framebuffer, size)

    def click(widget: str) -> None:
        x, y = overlay.widgets[widget]
        overlay.mouse_moved(x, y)
        draw()
        overlay.mouse_button(1, True)
        draw()
        overlay.mouse_button(1, False)
        draw()
        draw()

    return draw, click


def _scrolled_to(overlay, draw, widget: str, size) -> tuple[float, float]:
    """The inspector scrolled by the wheel (the mouse over it) until ``widget`` is inside the
    window's height (down to it, or up to it above the inspector's top); its place then."""
    for _ in range(40):
        x, y = overlay.widgets[widget]
        top = overlay.windows["Inspector"][0][1] + 24 * overlay.scale if "Inspector" in overlay.windows else 0
        if top <= y < size[1] - 12:
            return x, y
        overlay.mouse_moved(x, size[1] - 20)
        overlay.scroll(0.0, -1.0 if y >= top else 1.0)
        draw()
        draw()
        if y < top and overlay.widgets[widget][1] == y:   # at the top already
            return x, y
    raise AssertionError(f"{widget} stayed out of the window: {overlay.widgets[widget]}")


def test_a_tall_inspector_fits_the_window_and_scrolls_to_its_last_field(scene, ctx):
    """In a window too short for every field the inspector ends at the window's bottom (it
    grew past it, so the fields below could not be reached); the wheel over it scrolls to
    the last field, which then takes a click like any other."""
    size = (640, 300)
    with _box_selected(scene, ctx, size) as (runner, overlay, draw, click, editor, box):
        draw()  # (an auto-sized window takes its size a frame after its fields change)
        low, high = overlay.windows["Inspector"]
        assert high[1] <= size[1] and high[1] - low[1] > 100, (low, high)
        last = "Material.reflectance"   # the last field of the last component (Transform is first)
        assert overlay.widgets[last][1] > size[1]  # out of sight at first
        _scrolled_to(overlay, draw, last, size)
        assert overlay.windows["Inspector"][1][1] <= size[1]


def _drag(overlay, draw, points) -> None:
    """The mouse pressed at ``points[0]``, led through the rest and let go, a frame a step."""
    overlay.mouse_moved(*points[0])
    draw()
    overlay.mouse_button(1, True)
    draw()
    for point in points[1:]:
        overlay.mouse_moved(*point)
        draw()
    overlay.mouse_button(1, False)
    draw()


@contextmanager
def _box_selected(scene, ctx, size=(1280, 720)):
    """``edit_scene`` at ``size`` (the box right of the overlay's window), the overlay drawn
    and the box selected: yields (runner, overlay, draw, click, editor, box)."""
    ents = {}
    runner = scene(lambda world: edit_scene(world, ents), size)
    overlay = DebugOverlay(ctx)
    try:
        draw, click = _hands(runner, overlay, size)
        draw()
        editor = overlay.editing(runner.engine)
        editor.select(ents["box"])
        draw()
        yield runner, overlay, draw, click, editor, ents["box"]
    finally:
        overlay.release()


def test_the_entity_list_reaches_the_sky_whose_sun_is_pinned_and_handed_back(scene, ctx):
    """The sky and the lights have no pixel to click: the entity list (ticked open, filtered,
    clicked) selects them.  The Skybox's sun_direction, left to the engine, shows as
    automatic; "pin" writes the direction in use (the frame does not change), so turning the
    light no longer moves the sky; "automatic" hands it back and the sky follows the light."""
    from components import DirectionalLight, Skybox

    ents = {}
    runner = scene(lambda world: edit_scene(world, ents), SIZE)
    world = runner.world
    sky = next(e for e, _ in world.query_one(Skybox))
    light = next(e for e, _ in world.query_one(DirectionalLight))
    overlay = DebugOverlay(ctx)
    try:
        draw, click = _hands(runner, overlay)
        draw()
        assert overlay.listed_entities == []  # not listed until "entities" is ticked
        click("entities")
        assert f"entity {sky}: Skybox" in overlay.listed_entities
        assert f"entity {light}: DirectionalLight" in overlay.listed_entities
        overlay.entity_filter = "SKY"
        draw()
        assert overlay.listed_entities == [f"entity {sky}: Skybox"]
        click(f"entity {sky}")
        editor = overlay.editor
        assert editor.selected == sky
        assert "  sun_direction = automatic" in overlay.inspector_lines

        before = runner.frame()
        sky_pixels = runner.ids() == 0
        for axis in (0, 1):  # two pixels in from anything else (FXAA mixes an edge's neighbours)
            for shift in (-2, -1, 1, 2):
                sky_pixels &= np.roll(sky_pixels, shift, axis)
        assert sky_pixels.mean() > 0.05  # the frame shows sky
        click("Skybox.sun_direction pin")
        pinned = world.get(sky, Skybox).sun_direction
        towards = -glm.normalize(glm.vec3(0.2, -1.0, -0.5))  # base_scene's light, reversed
        assert glm.length(pinned - towards) < 1e-6, pinned
        assert np.array_equal(runner.frame(), before)  # pinned where it stood: nothing moved
        draw()
        assert "  sun_direction = automatic" not in overlay.inspector_lines

        world.get(light, DirectionalLight).direction = (-0.7, -0.3, 0.6)
        turned = runner.frame()
        assert np.array_equal(turned[sky_pixels], before[sky_pixels])  # the sky stays with its pin
        click("Skybox.sun_direction automatic")
        assert world.get(sky, Skybox).sun_direction is None
        followed = runner.frame()
        moved = np.abs(followed[sky_pixels].astype(int) - before[sky_pixels].astype(int)).max(axis=-1)
        assert (moved > 8).mean() > 0.2, (moved > 8).mean()  # the glow went round with the light
        assert editor.undo() and glm.length(world.get(sky, Skybox).sun_direction - towards) < 1e-6
        assert ctx.error == "GL_NO_ERROR"
    finally:
        overlay.release()


def test_automatic_values_and_the_entity_list_in_code(scene):
    """``Editor.automatic`` is the value the engine uses (a reflection's mix by its texture;
    the followed sun); the list stops at its limit and a filter finds the rest."""
    from components import DirectionalLight, Reflective
    from engine.assets.texture_data import checker_texture
    from shell.editor import EditError, Editor

    ents = {}
    runner = scene(lambda world: edit_scene(world, ents), (64, 48))
    world = runner.world
    editor = Editor(world)
    box = ents["box"]
    world.add_component(box, Reflective())
    assert editor.automatic(box, "Reflective", "mix") == 1.0
    world.get(box, Material).texture = checker_texture(8, 2)
    assert editor.automatic(box, "Reflective", "mix") == 0.5
    world.get(box, Reflective).mix = 0.2
    assert editor.automatic(box, "Reflective", "mix") == 0.5  # what the engine would decide
    with pytest.raises(EditError, match="Material.roughness is not a field the engine decides"):
        editor.automatic(box, "Material", "roughness")
    light = next(e for e, _ in world.query_one(DirectionalLight))
    world.get(light, DirectionalLight).intensity = 0.0  # a black light is no sun
    from components.rendering import DEFAULT_SUN_DIRECTION, Skybox

    sky = next(e for e, _ in world.query_one(Skybox))
    assert glm.length(editor.automatic(sky, "Skybox", "sun_direction") - glm.vec3(DEFAULT_SUN_DIRECTION)) < 1e-6

    made = [world.spawn(Transform(position=(float(i), 0.0, 0.0))) for i in range(250)]
    listed, more = editor.listed()
    assert len(listed) == 200 and more
    listed, more = editor.listed(f"entity {made[-1]}:")
    assert listed == [(made[-1], f"entity {made[-1]}: Transform")] and not more
    with pytest.raises(EditError, match="does not exist"):
        editor.select(10**6)
    editor.select(made[3])
    assert editor.selected == made[3]


def test_new_entity_delete_and_undo_from_the_overlay(scene, ctx):
    """"new entity" makes and selects a Transform in front of the camera, "duplicate" a copy
    of it; "delete" takes the copy away and leaves the inspector with undo, which makes it
    again."""
    ents = {}
    runner = scene(lambda world: edit_scene(world, ents), SIZE)
    world = runner.world
    overlay = DebugOverlay(ctx)
    try:
        draw, click = _hands(runner, overlay)
        draw()
        click("entities")
        count = len(world.entities())
        click("new entity")
        editor = overlay.editor
        made = editor.selected
        assert made is not None and len(world.entities()) == count + 1
        assert world.components_of(made) == (world.get(made, Transform),)
        assert f"new (entity {made})" in overlay.inspector_lines
        click("duplicate")
        assert editor.name_of(editor.selected) == "new_copy" and len(world.entities()) == count + 2
        copy = editor.selected
        click("delete")
        assert not world.exists(copy) and editor.selected is None and len(world.entities()) == count + 1
        assert editor.can_undo and overlay.inspector_lines == []  # the inspector holds undo and redo alone
        click("undo")
        assert "new_copy" in editor.names and world.exists(editor.names["new_copy"])
        assert ctx.error == "GL_NO_ERROR"
    finally:
        overlay.release()


def test_a_move_handle_dragged_moves_the_selection_along_its_axis(scene, ctx):
    """The box selected, its x handle pressed and the mouse moved 40 pixels along it on screen:
    the box's origin, projected by the test's own math, moved 40 pixels along that line and
    the box only along world x; the handles take the mouse (no click through to the world)
    while over them; one undo puts it back."""
    size = (1280, 720)
    with _box_selected(scene, ctx, size) as (runner, overlay, draw, _, editor, box):
        world = runner.world
        before = glm.vec3(world.get(box, Transform).position)
        origin = np.array(runner.project(before), float)
        x_end = np.array(runner.project(before + glm.vec3(overlay.handles.length, 0.0, 0.0)), float)
        along = (x_end - origin) / np.linalg.norm(x_end - origin)
        assert np.abs(np.array(overlay.handles.origin) - origin).max() <= 1.0  # where the test's math puts it
        grab = origin + 0.7 * (x_end - origin)
        overlay.mouse_moved(*grab)
        draw()
        assert overlay.wants_mouse  # over a handle: the window does not pick through it
        _drag(overlay, draw, [grab + along * 10.0 * step for step in range(5)])
        after = glm.vec3(world.get(box, Transform).position)
        assert after.y == before.y and after.z == before.z and after.x > before.x
        moved = np.array(runner.project(after), float) - origin
        assert abs(np.dot(moved, along) - 40.0) < 4.0, moved  # the box followed the mouse (perspective: a few px)
        assert abs(moved[0] * along[1] - moved[1] * along[0]) < 1.5, moved  # along the handle's line
        assert editor.undo() and world.get(box, Transform).position == before
        assert not editor.can_undo  # the whole drag was one edit
        overlay.mouse_moved(5, size[1] - 5)  # far from the handles and every window
        draw()
        assert not overlay.wants_mouse


def test_a_child_moves_along_world_axes_whatever_its_parent_turned(scene):
    """``Editor.move`` carries a world offset into the parent's space: a child of a parent
    turned 90 degrees about y and scaled 2x, moved 1 m along world x, ends 1 m along world x
    (its world position by the engine's own chain)."""
    from engine.core.transforms import current_world_matrix
    from shell.editor import Editor

    ents = {}

    def build(world):
        edit_scene(world, ents)
        ents["parent"] = world.spawn(Transform(position=(1.0, 0.0, 0.0), scale=(2.0, 2.0, 2.0),
                                               rotation=glm.angleAxis(glm.radians(90.0), glm.vec3(0, 1, 0))))
        ents["child"] = world.spawn(Transform(position=(0.5, 0.0, 0.0), parent=ents["parent"]))

    runner = scene(build, (64, 48))
    world, child = runner.world, ents["child"]
    editor = Editor(world)
    start = glm.vec3(world.get(child, Transform).position)
    was = glm.vec3(current_world_matrix(world, world.get(child, Transform))[3])
    editor.move(child, start, glm.vec3(1.0, 0.0, 0.0))
    now = glm.vec3(current_world_matrix(world, world.get(child, Transform))[3])
    assert glm.length(now - (was + glm.vec3(1.0, 0.0, 0.0))) < 1e-5, (was, now)


def test_an_hdr_colour_dragged_in_the_inspector_stays_hdr(scene, ctx):
    """A colour past 1 (the sky's sun_color, 6.0 red) dragged in the inspector changes by a
    little and is not clamped into 0-1 (an HDR colour picker, in floats)."""
    from components import Skybox

    ents = {}
    runner = scene(lambda world: edit_scene(world, ents), SIZE)
    world = runner.world
    sky = next(e for e, _ in world.query_one(Skybox))
    overlay = DebugOverlay(ctx)
    try:
        draw, _ = _hands(runner, overlay)
        draw()
        overlay.editing(runner.engine).select(sky)
        draw()
        before = glm.vec4(world.get(sky, Skybox).sun_color)
        x, y = overlay.widgets["Skybox.sun_color"]
        left = overlay.widgets["Skybox.sun_color.left"]
        _drag(overlay, draw, [(left[0] + 8 * step, left[1]) for step in range(6)])
        after = glm.vec4(world.get(sky, Skybox).sun_color)
        assert after != before and min(after.x, after.y, after.z) > 1.0, (before, after)
        assert abs(after.x - before.x) < 1.0, (before, after)  # a drag's step, not a jump to the clamp
    finally:
        overlay.release()


def test_a_portals_partner_is_chosen_from_the_portals_in_the_inspector(scene, ctx):
    """Two unpaired portals: the first's partner chosen in the inspector's list of portals
    (its own entity not offered) opens it, a view drawn through it; a Transform's parent is
    offered every other Transform, and a parent that would make a cycle is refused."""
    from components import MeshRef, Portal
    from engine.assets.mesh import box
    from engine.assets.portals import spawn_portal_pair
    from engine.rules.frame_rules import open_portal_pairs
    from tests.support import look_from

    ents = {}

    def build(world):
        from tests.test_mirrors import base_scene

        base_scene(world)
        look_from(world, (0.0, 1.5, 6.0), target=(0.0, 1.5, 0.0))
        ents["a"], ents["b"] = spawn_portal_pair(world, (0, 1.5, 0), None, (8, 1.5, 0), None)
        for portal in ents.values():
            world.get(portal, Portal).partner = None
        ents["box"] = world.spawn(Transform(position=(8.0, 1.5, 3.0)), MeshRef(box()), Material(color=(0.1, 0.9, 0.1)))

    size = (1280, 720)
    runner = scene(build, size)
    world = runner.world
    overlay = DebugOverlay(ctx)
    try:
        draw, click = _hands(runner, overlay, size)
        draw()
        assert runner.stats.reflection_views == 0 and open_portal_pairs(world) == {}
        editor = overlay.editing(runner.engine)
        editor.select(ents["a"])
        draw()
        choices, more = editor.reference_choices(ents["a"], "Portal", "partner")
        assert [c for c, _ in choices] == [None, ents["b"]] and not more
        click("Material")   # its fields folded away, so the Portal's are in the window, not scrolled past
        click("Portal.partner")
        click(f"Portal.partner {ents['b']}")
        assert world.get(ents["a"], Portal).partner == ents["b"]
        draw()
        assert open_portal_pairs(world) == {ents["a"]: ents["b"]} and runner.stats.reflection_views >= 1
        parents, _ = editor.reference_choices(ents["box"], "Transform", "parent")
        assert ents["box"] not in [c for c, _ in parents] and {ents["a"], ents["b"]} <= {c for c, _ in parents}
        assert editor.try_set_field(ents["a"], "Transform", "parent", ents["box"]) is None
        refused = editor.try_set_field(ents["box"], "Transform", "parent", ents["a"])
        assert refused and "cycle" in refused, refused
    finally:
        overlay.release()


def test_a_new_entity_given_a_mesh_shows_it_and_its_shape_is_chosen(scene, ctx, tmp_path):
    """A new entity given a MeshRef starts as a unit box where the camera looks (pixels there
    change), its shape is then chosen in the inspector (a sphere: its pixel at the box's
    corner goes back to the background) and a save writes it as a generator the file names."""
    from components import MeshRef
    from engine.assets.level_file import load_level

    with _box_selected(scene, ctx) as (runner, overlay, draw, click, editor, _):
        world = runner.world
        empty = runner.frame()
        made = editor.create(name="thing")
        editor.add_component(made, "MeshRef")
        editor.add_component(made, "Material")
        assert editor.mesh_shape(made) == "box"
        centre = glm.vec3(world.get(made, Transform).position)
        corner = centre + glm.vec3(0.45, 0.45, 0.45)  # inside the unit box, outside a 0.5 sphere
        boxed = runner.frame()
        cx, cy = runner.project(centre)
        kx, ky = runner.project(corner)
        assert np.abs(boxed[cy, cx].astype(int) - empty[cy, cx]).max() > 20  # the box stands there
        assert np.abs(boxed[ky, kx].astype(int) - empty[ky, kx]).max() > 20
        draw()
        click("Material")   # its fields folded away, so the MeshRef's are in the window, not scrolled past
        click("MeshRef.mesh")
        click("MeshRef.mesh sphere")
        assert editor.mesh_shape(made) == "sphere"
        round_ = runner.frame()
        assert np.abs(round_[cy, cx].astype(int) - empty[cy, cx]).max() > 20
        assert np.abs(round_[ky, kx].astype(int) - empty[ky, kx]).max() <= 3  # the corner is sky again
        assert editor.undo() and editor.mesh_shape(made) == "box"
        assert editor.redo()
        path = editor.save(tmp_path / "made.toml")
        assert "mesh = { sphere = 0.5 }" in path.read_text()
        again = load_level(path)
        from engine.core.world import World

        other = World("made_again")
        names = again.spawn(other)
        assert other.get(names["thing"], MeshRef).mesh.source == {"sphere": 0.5}
        other.close()


def test_typing_reaches_the_fields_and_the_editors_keys_act_when_none_is_typed_in(scene, ctx):
    """Characters typed into the entity list's filter (the window's text events) filter it,
    and while it is typed in the overlay wants the keyboard (the game and the shortcuts do
    not get the keys); Backspace edits it.  Out of the field: Delete deletes the selection,
    Ctrl+Z brings it back, Ctrl+D duplicates, Ctrl+Y redoes."""
    with _box_selected(scene, ctx) as (runner, overlay, draw, click, editor, box):
        world = runner.world
        click("entities")
        click("entity filter")
        assert overlay.wants_keyboard
        overlay.text("skyx")
        draw()
        assert overlay.entity_filter == "skyx" and overlay.listed_entities == []
        overlay.key("BACKSPACE", True)
        draw()
        overlay.key("BACKSPACE", False)
        draw()
        assert overlay.entity_filter == "sky" and len(overlay.listed_entities) == 1
        overlay.mouse_moved(5, runner.size[1] - 5)
        overlay.mouse_button(1, True)
        draw()
        overlay.mouse_button(1, False)  # a click elsewhere: the field lets go of the keyboard
        draw()
        assert not overlay.wants_keyboard
        editor.select(box)
        assert overlay.shortcut(runner.engine, "DELETE") and not world.exists(box)
        assert overlay.shortcut(runner.engine, "Z", ctrl=True)
        assert len([e for e, _ in world.query_one(Material)]) == 2  # the box is back (with the mirror's)
        assert overlay.shortcut(runner.engine, "Y", ctrl=True) and len([e for e, _ in world.query_one(Material)]) == 1
        assert overlay.shortcut(runner.engine, "Z", ctrl=True, shift=False)
        restored = max(e for e, _ in world.query_one(Material))
        editor.select(restored)
        assert overlay.shortcut(runner.engine, "D", ctrl=True) and len([e for e, _ in world.query_one(Material)]) == 3
        assert not overlay.shortcut(runner.engine, "W")  # the game's key


def test_the_window_gives_typed_keys_to_the_field_and_editor_keys_to_the_editor():
    """Through the window shell (headless moderngl-window, keys sent by name): with a field
    typed in, a letter goes to it and not to the game; with none, Delete and Ctrl+Z act on
    the selection and the game does not see them; other keys reach the game as before; the wheel scrolls the list."""
    import moderngl_window as mglw

    from components import MeshRef
    from engine.assets.mesh import box
    from engine.core.frame_io import Input
    from shell.window import make_window_config
    from tests.support import FunctionGame, look_from

    seen: list[set] = []
    ents = {}

    def build(world):
        from components import Skybox

        look_from(world, (0, 1, 4))
        world.spawn(Skybox())
        ents["box"] = world.spawn(Transform(position=(0.0, 1.0, 0.0)), MeshRef(box()), Material())

    def update(world, dt):
        seen.append(set(world.resources[Input].pressed))

    config = mglw.create_window_config_instance(
        make_window_config(FunctionGame(build, update)),
        args=["--window", "headless", "--backend", "egl", "--size", "1280x720"])
    try:
        keys = config.wnd.keys

        class Mods:
            shift = False
            ctrl = False

        class Ctrl(Mods):
            ctrl = True

        def frame():
            config.on_render(0.0, 1 / 60)

        def press(name, mods=Mods):  # pressed and let go, as a hand does (the modifier let go with it)
            config.on_key_event(name, keys.ACTION_PRESS, mods())
            config.on_key_event(name, keys.ACTION_RELEASE, Mods())

        def click(widget):
            x, y = overlay.widgets[widget]
            config.on_mouse_position_event(int(x), int(y), 0, 0)
            frame()
            config.on_mouse_press_event(int(x), int(y), 1)
            frame()
            config.on_mouse_release_event(int(x), int(y), 1)
            frame()
            frame()

        overlay = config.overlay
        if not overlay.visible:
            overlay.toggle()
        frame()
        frame()
        world = config.engine.world
        overlay.editing(config.engine).select(ents["box"])
        press("DELETE")
        assert not world.exists(ents["box"])
        press("Z", Ctrl)
        frame()
        assert "z" not in seen[-1] and len(world.query_one(MeshRef)) == 1  # undone, and not the game's
        click("entities")
        click("entity filter")
        config.on_unicode_char_entered("k")
        config.on_key_event("W", keys.ACTION_PRESS, Mods())
        frame()
        assert overlay.entity_filter == "k" and "w" not in seen[-1]  # the field's, not the game's
        for n in range(300):  # enough to scroll the list
            world.spawn(Transform(position=(float(n), 0.0, 0.0)))
        config.on_key_event("BACKSPACE", keys.ACTION_PRESS, Mods())
        config.on_key_event("BACKSPACE", keys.ACTION_RELEASE, Mods())
        frame()
        assert overlay.entity_filter == "" and len(overlay.listed_entities) == 200
        top = overlay.widgets["entity 1"][1]
        x, y = overlay.widgets["entity 2"]
        config.on_mouse_position_event(int(x), int(y), 0, 0)
        frame()
        config.on_mouse_scroll_event(0.0, -3.0)  # the wheel turned down, over the list
        frame()
        frame()
        assert overlay.widgets["entity 1"][1] < top - 20  # the list scrolled up its items
        config.on_mouse_position_event(5, 715, 0, 0)
        config.on_mouse_press_event(5, 715, 1)  # in the world, away from every window: the field lets go
        frame()
        config.on_mouse_release_event(5, 715, 1)
        frame()
        config.on_key_event("W", keys.ACTION_PRESS, Mods())
        frame()
        assert "w" in seen[-1]  # the game's key again
    finally:
        config.on_close()


def test_on_a_high_dpi_screen_the_overlay_is_clicked_where_it_is_drawn(monkeypatch):
    """A window of pixel_ratio 2 draws the overlay twice as big (its text and widgets the
    size they are on a screen of ratio 1), and sends the mouse in its points, half the
    framebuffer's pixels the overlay is drawn in: a click at a widget's place in points ticks it."""
    import moderngl_window as mglw
    from moderngl_window.context.base.window import BaseWindow

    from components import Skybox
    from shell.window import make_window_config
    from tests.support import FunctionGame, look_from

    def build(world):
        look_from(world, (0, 1, 4))
        world.spawn(Skybox())

    plain = mglw.create_window_config_instance(
        make_window_config(FunctionGame(build)),
        args=["--window", "headless", "--backend", "egl", "--size", "1600x1100"])
    try:
        plain.overlay.toggle() if not plain.overlay.visible else None
        for _ in range(2):
            plain.on_render(0.0, 1 / 60)
        width_at_1 = plain.overlay.region[2]
    finally:
        plain.on_close()
    monkeypatch.setattr(BaseWindow, "pixel_ratio", property(lambda self: 2.0))
    config = mglw.create_window_config_instance(
        make_window_config(FunctionGame(build)),
        args=["--window", "headless", "--backend", "egl", "--size", "1600x1100"])
    try:
        overlay = config.overlay
        if not overlay.visible:
            overlay.toggle()
        for _ in range(2):
            config.on_render(0.0, 1 / 60)
        assert overlay.scale == 2.0 and overlay.region[2] > 1.8 * width_at_1  # text and widgets twice as big
        x, y = overlay.widgets["entities"]  # framebuffer pixels
        points = (int(x / 2), int(y / 2))
        config.on_mouse_position_event(*points, 0, 0)
        config.on_render(0.0, 1 / 60)
        config.on_mouse_press_event(*points, 1)
        config.on_render(0.0, 1 / 60)
        config.on_mouse_release_event(*points, 1)
        config.on_render(0.0, 1 / 60)
        assert overlay.show_entities
    finally:
        config.on_close()


def test_a_level_built_again_from_its_file_gets_a_new_editor(ctx, tmp_path):
    """The level file reloaded (rebuilt in the same world): the overlay's editor is a new one,
    with the new entities' names and no undo of edits to entities that are gone."""
    from engine.assets.level_file import LevelGame
    from engine.core.frame_io import Output
    from engine.render.targets import CaptureTarget
    from shell.app import Engine
    from tests.test_level_reload import level_text

    path = tmp_path / "level.toml"
    path.write_text(level_text())
    engine = Engine(LevelGame(path), ctx)
    capture = CaptureTarget(ctx, (320, 240))
    overlay = DebugOverlay(ctx)
    try:
        engine.watch_level()
        engine.frame(1 / 60, Output(capture.framebuffer, (320, 240)))
        editor = overlay.editing(engine)
        old_box = editor.names["box"]
        editor.set_field(old_box, "Material", "roughness", 0.9)
        assert editor.can_undo
        engine.level_reload.reload()
        again = overlay.editing(engine)
        assert again is not editor and not again.can_undo
        assert again.names["box"] != old_box and engine.world.exists(again.names["box"])
        assert overlay.editing(engine) is again  # the same editor while nothing is rebuilt
    finally:
        overlay.release()
        capture.release()
        engine.close()


def test_a_texture_is_typed_as_a_level_file_writes_it(scene, ctx, tmp_path):
    """The box's Material.texture typed in the inspector as a level file's table writes it
    ("checker = [64, 4]", Enter): the box shows a checker (two colours where it was one), the
    field shows it back as written, a file beside the level is named relative to it, and text
    the level reader refuses changes nothing and says why in its words."""
    from engine.assets.texture_data import TextureData
    from shell.capture import save_png
    from shell.editor import EditError

    with _box_selected(scene, ctx) as (runner, overlay, draw, click, editor, box):
        world = runner.world
        plain = runner.frame()
        ids = runner.ids()
        face = ids == box
        assert face.sum() > 500
        click("Material.texture")
        overlay.text("checker = [64, 4]")
        draw()
        overlay.key("ENTER", True)
        draw()
        overlay.key("ENTER", False)
        draw()
        texture = world.get(box, Material).texture
        assert isinstance(texture, TextureData) and texture.source == {"checker": [64, 4]}
        assert editor.texture_text(box, "texture") == "checker = [64, 4]"
        chequered = runner.frame()
        spread = lambda rgb: float(rgb[face].astype(float).std(axis=0).max())  # noqa: E731
        assert spread(chequered) > spread(plain) + 20  # dark and light squares where one red was
        with pytest.raises(EditError, match="checker = \\[size, squares\\]"):
            editor.set_texture(box, "texture", "checker = [64]")
        assert world.get(box, Material).texture is texture
        with pytest.raises(EditError, match="Material.texture"):
            editor.set_texture(box, "texture", "checker = [64, 4")  # not TOML
        editor.level_path = tmp_path / "level.toml"
        save_png(np.full((4, 4, 3), 200, np.uint8), tmp_path / "wood.png")
        editor.set_texture(box, "texture", 'file = "wood.png"')
        assert editor.texture_text(box, "texture") == 'file = "wood.png"'
        editor.set_texture(box, "texture", "")
        assert world.get(box, Material).texture is None
        assert editor.undo() and editor.texture_text(box, "texture") == 'file = "wood.png"'


def test_a_turn_ring_dragged_turns_the_selection_by_the_angle_swept_about_it(scene, ctx):
    """"turn" chosen, the mouse led round the z ring (which faces the camera) from its +x
    point to its +y point: the box turns about world z by the angle the mouse swept about
    the box's origin on screen (the test's own projection), counter-clockwise positive as
    z points to the camera; one undo puts it back."""
    with _box_selected(scene, ctx) as (runner, overlay, draw, click, editor, box):
        world = runner.world
        click("handles turn")
        assert overlay.handles.mode == "turn"
        before = glm.quat(world.get(box, Transform).rotation)
        centre = glm.vec3(world.get(box, Transform).position)
        length = overlay.handles.length
        x, y = glm.vec3(1, 0, 0), glm.vec3(0, 1, 0)
        ring = [np.array(runner.project(centre + length * (math.cos(t) * x + math.sin(t) * y)), float)
                for t in np.linspace(0.0, math.pi / 2, 13)]
        origin = np.array(runner.project(centre), float)
        overlay.mouse_moved(*ring[0])
        draw()
        assert overlay.wants_mouse
        _drag(overlay, draw, ring)
        a, b = ring[0] - origin, ring[-1] - origin
        swept = math.atan2(-(a[0] * b[1] - a[1] * b[0]), float(np.dot(a, b)))  # counter-clockwise, rows down
        turned = world.get(box, Transform).rotation * glm.inverse(before)
        assert abs(glm.angle(turned) - swept) < math.radians(1.5), (glm.angle(turned), swept)
        assert glm.dot(glm.axis(turned), glm.vec3(0, 0, 1)) > 0.999, glm.axis(turned)
        assert 60 < math.degrees(swept) < 120
        assert editor.undo() and world.get(box, Transform).rotation == before and not editor.can_undo


def test_a_yaw_dragged_in_the_inspector_goes_on_past_ninety_degrees(scene, ctx):
    """The rotation's middle number (yaw, degrees) dragged from 80 by 60 pixels at half a
    degree a pixel: the box turns about y to about 110 degrees and the field shows it.
    Shown by glm's decomposition alone, the angles flipped to the other triple at 90 and
    the drag turned back there (it ended at 90 or less)."""
    with _box_selected(scene, ctx) as (runner, overlay, draw, click, editor, box):
        world = runner.world
        assert editor.set_angles(box, Transform, "rotation", (0.0, 80.0, 0.0)) is None
        editor.end_drag()
        draw()
        x, y = overlay.widgets["Transform.rotation.middle"]
        _drag(overlay, draw, [(x + 10.0 * step, y) for step in range(7)])
        turned = glm.quat(world.get(box, Transform).rotation)
        angle = math.degrees(glm.angle(turned))
        assert 100.0 < angle < 115.0, angle
        assert abs(glm.dot(glm.axis(turned), glm.vec3(0, 1, 0))) > 0.9999, glm.axis(turned)
        shown = editor.angles(box, Transform, "rotation")
        assert shown.y == pytest.approx(angle, abs=0.05) and abs(shown.x) < 1e-3 and abs(shown.z) < 1e-3, shown
        assert editor.undo()
        assert math.degrees(glm.angle(world.get(box, Transform).rotation)) == pytest.approx(80.0, abs=1e-2)


def test_a_scale_handle_dragged_scales_the_selection_along_its_own_axis(scene, ctx):
    """"scale" chosen, the box's x handle dragged 30 pixels outwards: its x scale grows so that
    the handle's end, scaled with it, lands under the mouse (the test's own projection); y
    and z keep their scale; one undo puts it back."""
    with _box_selected(scene, ctx) as (runner, overlay, draw, click, editor, box):
        world = runner.world
        click("handles scale")
        handles = overlay.handles
        assert handles.mode == "scale"
        before = glm.vec3(world.get(box, Transform).scale)
        centre = glm.vec3(world.get(box, Transform).position)
        origin = np.array(runner.project(centre), float)
        end = np.array(runner.project(centre + glm.vec3(handles.length, 0, 0)), float)
        along = (end - origin) / np.linalg.norm(end - origin)
        grab = end - along * 2.0
        _drag(overlay, draw, [grab + along * 10.0 * step for step in range(4)])
        after = glm.vec3(world.get(box, Transform).scale)
        factor = after.x / before.x
        assert factor > 1.05 and after.y == before.y and after.z == before.z
        landed = np.array(runner.project(centre + glm.vec3(handles.length * factor, 0, 0)), float)
        assert np.linalg.norm(landed - (end + along * 30.0)) < 3.0, (landed, end + along * 30.0)
        assert editor.undo() and world.get(box, Transform).scale == before


def test_a_child_turns_about_a_world_axis_whatever_its_parent_turned(scene):
    """``Editor.turn`` carries a world turn into the parent's space: the child's world
    rotation becomes the turn times what it was (the engine's own chain)."""
    from engine.core.transforms import current_world_matrix
    from shell.editor import Editor

    ents = {}

    def build(world):
        edit_scene(world, ents)
        tilt = glm.angleAxis(glm.radians(70.0), glm.normalize(glm.vec3(1, 2, 0)))
        ents["parent"] = world.spawn(Transform(rotation=tilt))
        ents["child"] = world.spawn(Transform(position=(0.5, 0.0, 0.0), parent=ents["parent"],
                                              rotation=glm.angleAxis(0.3, glm.vec3(0, 0, 1))))

    runner = scene(build, (64, 48))
    world, child = runner.world, ents["child"]

    def world_rotation():
        return glm.quat_cast(glm.mat3(current_world_matrix(world, world.get(child, Transform))))

    was = world_rotation()
    Editor(world).turn(child, glm.quat(world.get(child, Transform).rotation), glm.vec3(0, 1, 0), 0.8)
    want = glm.angleAxis(0.8, glm.vec3(0, 1, 0)) * was
    assert abs(abs(glm.dot(world_rotation(), want)) - 1.0) < 1e-5, (world_rotation(), want)


def test_with_ctrl_held_a_handle_moves_and_turns_in_steps(scene, ctx):
    """Ctrl held through a drag: the move is a whole number of quarter metres, the turn a
    whole number of 15 degrees (and neither is nothing)."""
    with _box_selected(scene, ctx) as (runner, overlay, draw, click, editor, box):
        world = runner.world
        before = glm.vec3(world.get(box, Transform).position)
        handles = overlay.handles
        grab = np.array(handles.lines[0][0]) + 0.7 * (np.array(handles.lines[0][1]) - np.array(handles.lines[0][0]))
        overlay.key("", True, ctrl=True)
        _drag(overlay, draw, [grab, grab + np.array([37.0, 0.0])])
        moved = world.get(box, Transform).position.x - before.x
        assert moved > 0.2 and abs(moved / 0.25 - round(moved / 0.25)) < 1e-4, moved
        click("handles turn")
        centre = glm.vec3(world.get(box, Transform).position)
        start = glm.quat(world.get(box, Transform).rotation)
        length = overlay.handles.length
        ring = [np.array(runner.project(centre + length * (math.cos(t) * glm.vec3(1, 0, 0)
                                                          + math.sin(t) * glm.vec3(0, 1, 0))), float)
                for t in np.linspace(0.0, math.radians(50.0), 6)]
        _drag(overlay, draw, ring)
        overlay.key("", False)
        angle = math.degrees(glm.angle(world.get(box, Transform).rotation * glm.inverse(start)))
        assert angle > 10.0 and abs(angle / 15.0 - round(angle / 15.0)) < 1e-3, angle


def test_f_frames_the_selection_keeping_the_view_direction(scene, ctx):
    """F (the editor's key, no field typed in) moves the camera so that the selected box is
    centred in view and whole (its corners inside the frame, its projected size a good part
    of it), the camera looking the way it looked; a camera selected is not moved."""
    with _box_selected(scene, ctx) as (runner, overlay, draw, click, editor, box):
        world = runner.world
        camera_entity, _, camera = runner.engine.active_camera()
        turned = glm.quat(camera.rotation)
        assert overlay.shortcut(runner.engine, "F")
        draw()
        assert camera.rotation == turned
        centre = glm.vec3(world.get(box, Transform).position)
        cx, cy = runner.project(centre)
        w, h = runner.size
        assert abs(cx - w / 2) <= 2 and abs(cy - h / 2) <= 2
        corners = [runner.project(centre + 0.3 * glm.vec3(x, y, z)) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
        rows = [r for _, r in corners]
        assert all(0 <= c < w and 0 <= r < h for c, r in corners)
        assert max(rows) - min(rows) > 0.3 * h  # framed, not a speck
        editor.select(camera_entity)
        where = glm.vec3(camera.position)
        overlay.shortcut(runner.engine, "F")
        assert camera.position == where


def test_f_frames_the_selection_with_an_orthographic_camera(scene, ctx):
    """With an orthographic camera F centres the selection and spans it (its view's height
    the box's bounding sphere's diameter x FRAME_MARGIN), standing back far enough along the
    axis to see all of it; the direction kept."""
    from components import Camera, MeshRef
    from shell.handles import FRAME_MARGIN

    with _box_selected(scene, ctx) as (runner, overlay, draw, click, editor, box):
        world = runner.world
        camera_entity, lens, camera = runner.engine.active_camera()
        lens.projection, lens.ortho_height = "orthographic", 40.0
        turned = glm.quat(camera.rotation)
        assert overlay.shortcut(runner.engine, "F")
        runner.frame()
        assert camera.rotation == turned
        lo, hi = world.get(box, MeshRef).mesh.bounds
        radius = float(np.linalg.norm(hi - lo)) / 2.0 * float(world.get(box, Transform).scale.x)
        assert world.get(camera_entity, Camera).ortho_height == pytest.approx(2.0 * radius * FRAME_MARGIN, rel=1e-4)
        centre = glm.vec3(world.get(box, Transform).position)
        cx, cy = runner.project(centre)
        w, h = runner.size
        assert abs(cx - w / 2) <= 2 and abs(cy - h / 2) <= 2
        assert (runner.ids() == box).sum() > 0.1 * w * h   # (seen whole, not cut by the near plane)


def test_the_entity_list_is_made_again_on_an_edit_or_a_moment_later_not_every_frame(scene, ctx, monkeypatch):
    """With the list open the editor's ``listed`` runs once over frames where nothing was
    edited and the filter stayed (a filter over 100,000 entities takes a quarter second), at
    once after an edit, and again once ``LIST_REFRESH_S`` has passed (what the game spawned)."""
    import shell.editor_panels as overlay_module
    from shell.editor import Editor

    with _box_selected(scene, ctx) as (runner, overlay, draw, click, editor, box):
        click("entities")
        calls = []
        listed = Editor.listed
        monkeypatch.setattr(Editor, "listed", lambda self, *a, **k: calls.append(1) or listed(self, *a, **k))
        monkeypatch.setattr(overlay_module, "LIST_REFRESH_S", 1e9)  # no wall clock in the count: a loaded
        for _ in range(5):                                          # machine may take 0.5 s for 5 frames
            draw()
        assert len(calls) <= 1
        before = len(overlay.listed_entities)
        made = runner.world.spawn(Transform())  # the game's, not an edit
        editor.duplicate(box)
        draw()
        assert len(overlay.listed_entities) == before + 2 and any(f"entity {made}:" in label
                                                                  for label in overlay.listed_entities)
        monkeypatch.setattr(overlay_module, "LIST_REFRESH_S", 0.0)
        runner.world.spawn(Transform())
        draw()
        assert len(overlay.listed_entities) == before + 3


def test_a_selected_spot_light_shows_its_cone(scene, ctx):
    """A spot light (no pixel to click) selected from code as the entity list would: the
    overlay draws its cone (``reach_outline``) over the frame, in its light-yellow, where the
    test projects the cone's circle; deselected, those pixels are the world's again."""
    from components import PointLight, look_rotation
    from shell.handles import screen_point

    ents = {}

    def build(world):
        edit_scene(world, ents)
        lamp = glm.vec3(2.6, 2.4, 1.0)   # right of the overlay's window
        ents["spot"] = world.spawn(Transform(position=lamp, rotation=look_rotation(glm.vec3(0.0, -1.0, -0.3))),
                                   PointLight(intensity=5.0, range=2.0, spot_angle=25.0))

    size = (1280, 720)
    with _overlay_over(scene, ctx, build, size) as (runner, overlay, draw):
        editor = overlay.editing(runner.engine)
        before = runner.capture.read_rgb()
        editor.select(ents["spot"])
        draw()
        outline = overlay.reach_outline
        assert outline is not None and len(outline.lines) == 5
        shown = runner.capture.read_rgb()
        view = runner.engine.main_view
        circle = [screen_point(view.view_proj, size, p) for p in outline.world[0]]
        assert all(600 < x < size[0] - 2 and 2 < y < size[1] - 2 for x, y in circle)   # in view, clear of the window

        def yellow(frame) -> int:
            count = 0
            for x, y in circle:
                patch = frame[int(y) - 1:int(y) + 2, int(x) - 1:int(x) + 2].reshape(-1, 3).astype(int)
                count += bool(((patch[:, 0] > 170) & (patch[:, 1] > 140) & (patch[:, 2] < patch[:, 1] - 40)).any())
            return count

        assert yellow(shown) >= 0.8 * len(circle) and yellow(before) == 0, (yellow(shown), yellow(before))
        editor.select(None)
        draw()
        assert overlay.reach_outline is None and yellow(runner.capture.read_rgb()) == 0


def test_a_light_or_probe_without_a_mesh_is_a_marker_a_click_selects(scene, ctx):
    """A spot light, a probe, a particle emitter and a decal with no mesh (no pixel in the id
    images) are drawn as markers where the test projects them, a yellow dot, a cyan ring, an
    orange diamond and a violet square; a click on a marker selects
    its entity, and a click away from it picks the world as before (the red box)."""
    from components import Decal, ParticleEmitter, PointLight, ReflectionProbe
    from shell.handles import screen_point

    ents = {}

    def build(world):
        edit_scene(world, ents)
        ents["spot"] = world.spawn(Transform(position=(2.4, 2.2, 1.0)), PointLight(intensity=2.0, range=2.0,
                                                                                     spot_angle=30.0))
        ents["probe"] = world.spawn(Transform(position=(1.6, 0.6, 2.0)), ReflectionProbe(resolution=16))
        ents["emitter"] = world.spawn(Transform(position=(2.0, 1.4, 2.0)),
                                      ParticleEmitter(rate=0.0, burst=0, color=(0.0, 0.0, 0.0, 1.0)))
        ents["decal"] = world.spawn(Transform(position=(2.6, 1.0, 2.4), scale=(0.2, 0.2, 0.2)), Decal())

    size = (1280, 720)
    with _overlay_over(scene, ctx, build, size) as (runner, overlay, _):
        view = runner.engine.main_view
        kinds = {m.entity: m.kind for m in overlay.markers}
        assert kinds == {ents["spot"]: "light", ents["probe"]: "probe", ents["emitter"]: "emitter",
                         ents["decal"]: "decal"}
        frame = runner.capture.read_rgb()
        for name, want in (("spot", lambda p: p[0] > 200 and p[1] > 170 and p[2] < 150),
                           ("probe", lambda p: p[2] > 200 and p[1] > 180 and p[0] < 150),
                           ("emitter", lambda p: p[0] > 200 and 60 < p[1] < 160 and p[2] < 80),
                           ("decal", lambda p: p[0] > 180 and 60 < p[1] < 150 and p[2] > 200)):
            x, y = screen_point(view.view_proj, size, glm.vec3(runner.world.get(ents[name], Transform).position))
            assert x > 700, "clear of the overlay's window"
            patch = frame[int(y) - 6:int(y) + 7, int(x) - 6:int(x) + 7].reshape(-1, 3).astype(int)
            assert any(want(p) for p in patch), name
            assert overlay.click(runner.engine, x + 2.0, y - 1.0)
            assert overlay.editor.selected == ents[name]
        box_x, box_y = runner.project(runner.world.get(ents["box"], Transform).position)
        assert overlay.click(runner.engine, box_x, box_y)
        assert overlay.editor.selected == ents["box"]


@contextmanager
def _overlay_over(scene, ctx, build, size):
    """A scene of ``build`` at ``size`` with the overlay drawn over one frame: yields
    (runner, overlay, draw)."""
    runner = scene(build, size)
    overlay = DebugOverlay(ctx)
    try:
        draw, _ = _hands(runner, overlay, size)
        draw()
        yield runner, overlay, draw
    finally:
        overlay.release()


def test_a_cutoff_shows_off_and_is_switched_on_and_off(scene, ctx):
    """``Material.alpha_cutoff`` unset is shown as off; "on" makes the material a cutout at
    0.5 (the box, given a slatted texture, then shows the wall through its gaps), "off"
    takes it back, and undo puts it on again."""
    from tests.test_alpha_cutout import SLAT_TEXTURE

    size = (1280, 720)
    with _box_selected(scene, ctx, size) as (runner, overlay, draw, click, editor, box):
        world = runner.world
        world.get(box, Material).texture = SLAT_TEXTURE
        draw()
        assert "  alpha_cutoff = off" in overlay.inspector_lines
        whole = (runner.ids() == box).sum()
        assert whole > 2000
        _scrolled_to(overlay, draw, "Material.alpha_cutoff on", size)
        click("Material.alpha_cutoff on")
        assert world.get(box, Material).alpha_cutoff == 0.5
        assert "  alpha_cutoff = 0.5" in overlay.inspector_lines
        cut = (runner.ids() == box).sum()
        assert 0.3 * whole < cut < 0.8 * whole, (cut, whole)   # the gaps show what is behind
        _scrolled_to(overlay, draw, "Material.alpha_cutoff off", size)
        click("Material.alpha_cutoff off")
        assert world.get(box, Material).alpha_cutoff is None
        assert (runner.ids() == box).sum() == whole
        assert editor.undo() and world.get(box, Material).alpha_cutoff == 0.5
        assert ctx.error == "GL_NO_ERROR"


def test_a_models_variant_is_chosen_from_its_files_variants(scene, ctx, tmp_path):
    """The inspector offers a Model's material variants (the file's own look first); the one
    clicked is the Model's, and the next frame its parts wear it."""
    from components import FromModel, Model
    from tests.test_model_variants import BLUE, shoe

    path = shoe(tmp_path / "shoe.glb")
    with _box_selected(scene, ctx) as (runner, overlay, draw, click, editor, _):
        world = runner.world
        root = editor.create(Transform(position=(0.0, 0.5, 0.0)), Model(file=str(path)), name="shoe")
        runner.frame()
        assert editor.model_variants(root) == ["midnight", "forest"]
        draw()
        click("Model.variant")
        assert {"Model.variant ", "Model.variant midnight", "Model.variant forest"} <= set(overlay.widgets)
        click("Model.variant midnight")
        assert world.get(root, Model).variant == "midnight"
        runner.frame()
        ((part, _),) = list(world.query_one(FromModel))
        assert list(world.get(part, Material).color) == pytest.approx(BLUE, abs=0.01)
        assert editor.undo() and world.get(root, Model).variant == ""


def test_an_animations_clip_is_chosen_from_its_models_clips(scene, ctx, tmp_path):
    """The inspector offers the model's animation clips; the one clicked plays, and a clip the
    file lacks is refused saying which it has."""
    from components import Animation, FromModel, Model
    from shell.editor import EditError
    from tests.test_model_animation import door

    path = door(tmp_path / "door.glb")
    with _box_selected(scene, ctx) as (runner, overlay, draw, click, editor, _):
        world = runner.world
        root = editor.create(Transform(position=(0.0, 0.5, 0.0)), Model(file=str(path)),
                             Animation(time=1.0, playing=False), name="door")
        runner.frame()
        assert editor.model_clips(root) == ["Open", "Slide", "Blink"]
        ((part, _),) = list(world.query_one(FromModel))
        rest = glm.quat(world.get(part, Transform).rotation)
        draw()
        click("Animation.clip")
        click("Animation.clip Open")
        assert world.get(root, Animation).clip == "Open"
        runner.frame()
        assert abs(glm.dot(glm.quat(world.get(part, Transform).rotation), rest)) < 0.99   # turned by the clip
        with pytest.raises(EditError, match=r"no clip 'Close' \(its clips: 'Open', 'Slide', 'Blink'\)"):
            editor.set_field(root, "Animation", "clip", "Close")


def test_a_posed_entity_shows_its_skin_and_morph(scene, ctx):
    """An entity a game bent by hand (a Skin and a Morph): the inspector lists both, the
    joint matrices as an array (not four thousand numbers), the weights as numbers."""
    from components import MeshRef, Morph, Skin
    from tests.test_morph_targets import morphed_sheet

    with _box_selected(scene, ctx) as (runner, overlay, draw, click, editor, _):
        world = runner.world
        sheet = morphed_sheet()
        from engine.assets.mesh import Mesh
        posed = world.spawn(Transform(position=(0.0, 0.5, 0.0)),
                            MeshRef(Mesh(sheet.positions, sheet.normals, sheet.uvs, sheet.indices, name="flag",
                                         joints=np.zeros((len(sheet.positions), 1), int),
                                         weights=np.ones((len(sheet.positions), 1)),
                                         morph_positions=sheet.morph_positions)),
                            Material(), Skin(), Morph((0.25, 0.5)))
        runner.frame()
        editor.select(posed)
        draw()
        lines = overlay.inspector_lines
        assert {"Skin", "Morph"} <= set(lines)
        assert "  joint_matrices = array" in lines
        assert any(line.startswith("  weights = ") and "0.25" in line for line in lines), lines


def test_the_maps_read_at_the_second_uv_set_are_ticked(scene, ctx):
    """``Material.second_uv_maps`` is a tick a map: on a box (no second UV set) the tick is
    refused saying why; on a mesh with one it names the map, and undo takes it back."""
    from components import MeshRef
    from tests.test_second_uvs import two_sets

    size = (1280, 720)
    with _box_selected(scene, ctx, size) as (runner, overlay, draw, click, editor, box):
        world = runner.world
        _scrolled_to(overlay, draw, "Material.second_uv_maps occlusion_map", size)
        click("Material.second_uv_maps occlusion_map")
        assert world.get(box, Material).second_uv_maps == ()
        assert "has no second UV set" in editor.message
        world.get(box, MeshRef).mesh = two_sets()
        draw()
        _scrolled_to(overlay, draw, "Material.second_uv_maps occlusion_map", size)
        click("Material.second_uv_maps occlusion_map")
        assert world.get(box, Material).second_uv_maps == ("occlusion_map",)
        draw()
        assert "  second_uv_maps = ['occlusion_map']" in overlay.inspector_lines
        assert editor.undo() and world.get(box, Material).second_uv_maps == ()


def test_an_animation_layers_clip_is_chosen_from_its_models_clips(scene, ctx, tmp_path):
    """An AnimationLayer's clip is offered as the Animation's is (the model's clips); a clip
    the file lacks is refused saying which it has."""
    from components import AnimationLayer, Model
    from shell.editor import EditError
    from tests.test_model_animation import door

    path = door(tmp_path / "door.glb")
    with _box_selected(scene, ctx) as (runner, overlay, draw, click, editor, _):
        world = runner.world
        root = editor.create(Transform(position=(0.0, 0.5, 0.0)), Model(file=str(path)),
                             AnimationLayer(time=1.0, playing=False), name="door")
        runner.frame()
        editor.select(root)
        draw()
        click("AnimationLayer.clip")
        assert {"AnimationLayer.clip Open", "AnimationLayer.clip Slide"} <= set(overlay.widgets)
        click("AnimationLayer.clip Slide")
        assert world.get(root, AnimationLayer).clip == "Slide"
        with pytest.raises(EditError, match=r"AnimationLayer.clip: the model file has no clip 'Wave'"):
            editor.set_field(root, "AnimationLayer", "clip", "Wave")


def _drag_first_number(scene, ctx, component, field: str):
    """An entity with ``component`` selected in the inspector and the first number of its
    ``field`` dragged to the right: the field's value after the drag, and after one undo."""
    ents = {}

    def build(world):
        edit_scene(world, ents)
        ents["it"] = world.spawn(Transform(position=(0.0, 2.5, 0.0)), component)
    runner = scene(build, SIZE)
    overlay = DebugOverlay(ctx)
    try:
        draw, _ = _hands(runner, overlay)
        draw()
        editor = overlay.editing(runner.engine)
        editor.select(ents["it"])
        draw()
        x, y = _scrolled_to(overlay, draw, f"{type(component).__name__}.{field}.left", SIZE)
        _drag(overlay, draw, [(x + 8 * step, y) for step in range(6)])
        dragged = getattr(runner.world.get(ents["it"], type(component)), field)
        editor.undo()
        return dragged, getattr(runner.world.get(ents["it"], type(component)), field)
    finally:
        overlay.release()


def test_a_pair_of_numbers_drags_as_a_vector(scene, ctx):
    """A field that is two numbers (``PointLight.rectangle``'s width and height) drags as a
    vector: its first number dragged moves the width only, through the component (one undo)."""
    from components import PointLight

    (width, height), undone = _drag_first_number(scene, ctx, PointLight(rectangle=(1.0, 0.5)), "rectangle")
    assert width > 1.0 and height == 0.5, (width, height)
    assert undone == (1.0, 0.5)


def test_whole_numbers_drag_as_a_vector_of_ints(scene, ctx):
    """A field of whole numbers (``IrradianceVolume.points`` along x, y and z) drags as a
    vector of ints: its first number dragged raises the points along x only, written as ints
    the component takes (a float there it refuses), one undo back."""
    from components import IrradianceVolume

    points, undone = _drag_first_number(scene, ctx, IrradianceVolume(points=(3, 2, 3)), "points")
    assert points[0] > 3 and points[1:] == (2, 3) and all(type(v) is int for v in points), points
    assert undone == (3, 2, 3)


# --- through a portal ------------------------------------------------------------------------
PORTAL_A, PORTAL_B = (-0.8, 1.5, 0.0), (0.8, 1.5, 0.0)
THROUGH_BOX = (0.8, 1.5, 1.5)       # B + (0, 0, 1.5): in front of B, seen directly too
THROUGH_SEEN_AT = (-0.8, 1.5, -1.5)  # A + (0, 0, -1.5): the pair carries A + (x, y, z) to B + (-x, y, -z)


def _portal_scene(world, ents):
    from components import DirectionalLight, Emissive, MeshRef, Skybox
    from engine.assets.mesh import box
    from engine.assets.portals import spawn_portal_pair
    from tests.support import look_from

    world.spawn(Skybox())
    world.spawn(DirectionalLight(direction=(0.3, -1.0, -0.4), intensity=2.0))
    look_from(world, (0.0, 1.5, 6.0), (0.0, 1.5, 0.0))
    ents["a"], ents["b"] = spawn_portal_pair(world, PORTAL_A, None, PORTAL_B, None, size=(1.2, 1.6))
    ents["box"] = world.spawn(Transform(position=THROUGH_BOX, scale=(0.4, 0.4, 0.4)), MeshRef(box()),
                              Material(color=(0.1, 0.9, 0.1)), Emissive(1.0))


def test_a_click_through_a_portal_selects_what_it_shows_and_the_outline_follows_it_there(scene, ctx):
    """Two portals side by side facing the camera, a green box in front of B: seen directly and,
    through A, where the pair carries it (B + (x, y, z) shows at A + (-x, y, -z), worked out by
    hand).  A click on its image in A selects the box, Ctrl+click there the portal A; the
    overlay's outline of the box is exactly the ring round its pixels in the id image (a 3x3
    dilation in numpy) wherever the overlay's windows and handles leave the frame, round both
    its shapes; of A, the ring round A's own quad in the surface-id image."""
    from engine.render.outline import OUTLINE_COLOR
    from tests.test_pick import dilated

    size = (768, 432)
    ents = {}
    runner = scene(lambda world: _portal_scene(world, ents), size)
    runner.engine.renderer.antialias = "off"
    overlay = DebugOverlay(ctx)
    overlay.set_scale(0.5)   # (small windows: the portals between them)
    try:
        draw, _ = _hands(runner, overlay, size)
        draw()
        ids, surfaces = runner.ids(), runner.engine.renderer.targets.read_surface_ids()
        through, direct = runner.project(THROUGH_SEEN_AT), runner.project(THROUGH_BOX)
        assert ids[through[1], through[0]] == ents["box"] and surfaces[through[1], through[0]] == ents["a"]
        assert ids[direct[1], direct[0]] == ents["box"] == surfaces[direct[1], direct[0]]
        assert overlay.click(runner.engine, *through)
        editor = overlay.editor
        assert editor.selected == ents["box"]
        assert overlay.click(runner.engine, *through, surface=True) and editor.selected == ents["a"]
        assert overlay.click(runner.engine, *direct) and editor.selected == ents["box"]
        orange = tuple(round(c * 255) for c in OUTLINE_COLOR[:3])
        targets = runner.engine.renderer.targets
        for selected, image in ((ents["box"], targets.read_ids), (ents["a"], targets.read_surface_ids)):
            editor.select(selected)
            draw()
            draw()   # (an auto-sized window takes its size a frame after its fields change)
            rgb = runner.capture.read_rgb()
            mask = image() == selected
            ring = dilated(mask) & ~mask
            free = np.ones(mask.shape, bool)   # where the overlay's windows and handles leave the frame
            x, y, w, h = overlay.region
            covered = [*overlay.windows.values(), ((x, y), (x + w, y + h))]
            if overlay.handles is not None:
                points = np.array([p for line in overlay.handles.lines for p in line])
                covered.append((points.min(axis=0) - 8, points.max(axis=0) + 8))
            for (left, top), (right, bottom) in covered:
                free[max(int(top) - 1, 0):int(bottom) + 2, max(int(left) - 1, 0):int(right) + 2] = False
            painted = np.all(rgb == orange, axis=-1) & free
            assert np.array_equal(painted, ring & free), (selected, (painted ^ (ring & free)).sum())
            if selected == ents["box"]:   # round both of its shapes: where it stands and in A
                for column, row in (through, direct):
                    near = painted[max(row - 30, 0):row + 30, max(column - 30, 0):column + 30]
                    assert near.sum() > 20, (column, row, near.sum())
            else:
                assert painted.sum() > 100
        assert ctx.error == "GL_NO_ERROR"
    finally:
        overlay.release()


# --- a tick and a typed choice ---------------------------------------------------------------
def _toned_scene(ents, curve="agx", unlit=False):
    """``edit_scene`` with a Tonemap of ``curve`` on its camera and the box ``unlit`` or not."""
    from components import Tonemap
    from engine.rules.frame_rules import active_camera

    def build(world):
        edit_scene(world, ents)
        ents["camera"] = active_camera(world)
        world.add_component(ents["camera"], Tonemap(curve=curve))
        world.get(ents["box"], Material).unlit = unlit

    return build


def _typed(overlay, draw, click, widget: str, text: str, before_enter=lambda: None) -> None:
    """``widget``'s text field clicked, its text chosen whole (Ctrl+A) and ``text`` typed over it
    (``before_enter`` called then), Enter."""
    click(widget)
    overlay.key("A", True, ctrl=True)
    draw()
    overlay.key("A", False)
    draw()
    overlay.text(text)
    draw()
    before_enter()
    overlay.key("ENTER", True)
    draw()
    overlay.key("ENTER", False)
    draw()


def test_a_boolean_ticks_and_a_choice_is_typed_and_taken_on_enter_as_the_same_edit_in_code(scene, ctx):
    """The box's ``Material.unlit`` ticked in the inspector and the camera's ``Tonemap.curve``
    typed ("aces", Enter): each is one undo step, and the frame is, pixel for pixel, that of the
    scene built with those values in code (a second engine).  A choice that is none of the
    curves ("filmic") is refused: the inspector shows the component's own message (the
    choices named), the curve and the frame stay as they were, and nothing joins the undo list."""
    from components import Tonemap

    size = (640, 360)
    ents, made = {}, {}
    runner = scene(_toned_scene(ents), size)
    unlit_in_code = scene(_toned_scene(made, unlit=True), size)
    aces_in_code = scene(_toned_scene({}, curve="aces", unlit=True), size)
    for each in (runner, unlit_in_code, aces_in_code):
        each.engine.renderer.antialias = "off"
    world, box = runner.world, ents["box"]
    overlay = DebugOverlay(ctx)
    overlay.set_scale(0.5)   # (small windows: a small frame)
    try:
        draw, click = _hands(runner, overlay, size)
        draw()
        lit = runner.frame()
        face = runner.ids() == box
        assert face.sum() > 500
        editor = overlay.editing(runner.engine)
        editor.select(box)
        draw()
        assert "  unlit = False" in overlay.inspector_lines
        _scrolled_to(overlay, draw, "Material.unlit", size)
        click("Material.unlit")
        assert world.get(box, Material).unlit is True and "  unlit = True" in overlay.inspector_lines
        unlit = runner.frame()
        assert np.array_equal(unlit, unlit_in_code.frame())
        assert np.abs(unlit[face].astype(int) - lit[face]).max() > 20   # the box itself changed
        assert editor.undo() and world.get(box, Material).unlit is False
        assert np.array_equal(runner.frame(), lit)
        assert editor.redo() and not editor.can_redo

        editor.select(ents["camera"])
        draw()
        draw()
        assert "  curve = agx" in overlay.inspector_lines
        def not_yet():
            assert world.get(ents["camera"], Tonemap).curve == "agx" and overlay.wants_keyboard

        _typed(overlay, draw, click, "Tonemap.curve", "aces", not_yet)   # taken on Enter, not as typed
        assert world.get(ents["camera"], Tonemap).curve == "aces" and editor.message is None
        aces = runner.frame()
        assert np.array_equal(aces, aces_in_code.frame()) and not np.array_equal(aces, unlit)
        steps = editor.edit_count
        with pytest.raises(ComponentValueError) as refused:
            Tonemap(curve="filmic")
        _typed(overlay, draw, click, "Tonemap.curve", "filmic")
        assert world.get(ents["camera"], Tonemap).curve == "aces"
        assert editor.message == str(refused.value) and "pbr_neutral" in editor.message
        assert str(refused.value) in overlay.inspector_lines
        assert editor.edit_count == steps and np.array_equal(runner.frame(), aces)
        assert editor.undo() and world.get(ents["camera"], Tonemap).curve == "agx"
        assert np.array_equal(runner.frame(), unlit)
        assert ctx.error == "GL_NO_ERROR"
    finally:
        overlay.release()


def test_a_childs_scale_handle_scales_its_own_axis_whatever_its_parent_and_with_ctrl_in_tenths(scene, ctx):
    """A box whose parent is turned and scaled unevenly (its own axes in the world are then
    neither the world's nor square to each other): its scale handle, dragged 30 pixels outwards,
    stretches the child's world matrix along that axis alone (that column times the factor, the
    others as they were: the engine's own chain) by as much as puts the handle's end, scaled
    with it, under the mouse (the test's projection); one undo puts it back.  With Ctrl held the
    factor is a whole number of tenths, and not 1."""
    from components import MeshRef
    from engine.assets.mesh import box
    from engine.core.transforms import current_world_matrix

    size = (960, 540)
    ents = {}

    def build(world):
        edit_scene(world, ents)
        ents["parent"] = world.spawn(Transform(position=(0.2, 1.3, 1.5), scale=(2.0, 0.5, 1.0),
                                               rotation=glm.angleAxis(glm.radians(35.0),
                                                                      glm.normalize(glm.vec3(0.3, 0.2, 1.0)))))
        ents["child"] = world.spawn(Transform(position=(0.1, 0.2, 0.0), parent=ents["parent"], scale=(0.3, 0.3, 0.3),
                                              rotation=glm.angleAxis(0.6, glm.vec3(0, 0, 1))),
                                    MeshRef(box()), Material(color=(0.2, 0.3, 0.9)))

    runner = scene(build, size)
    world, child = runner.world, ents["child"]
    overlay = DebugOverlay(ctx)
    overlay.set_scale(0.5)   # (small windows: the child between them)
    try:
        draw, click = _hands(runner, overlay, size)
        draw()
        editor = overlay.editing(runner.engine)
        editor.select(child)
        draw()
        click("handles scale")
        handles = overlay.handles
        assert handles.mode == "scale" and (runner.ids() == child).sum() > 100

        def columns():
            matrix = current_world_matrix(world, world.get(child, Transform))
            return np.array([list(glm.vec3(matrix[i])) for i in range(4)])

        before, start = columns(), glm.vec3(world.get(child, Transform).scale)
        eye = runner.engine.main_view.eye   # the axis most across the view (the drag's rule is linear on screen)
        axis = min(range(3), key=lambda i: abs(glm.dot(handles.axes[i], glm.normalize(eye - glm.vec3(*before[3])))))
        square = glm.dot(glm.normalize(glm.vec3(*before[0])), glm.normalize(glm.vec3(*before[1])))
        assert abs(square) > 0.5   # the child's own axes are not square to each other in the world
        np.testing.assert_allclose(list(handles.axes[axis]), before[axis] / np.linalg.norm(before[axis]), atol=1e-5)
        centre = glm.vec3(*before[3])
        origin = np.array(handles.lines[axis][0], float)
        end = np.array(handles.lines[axis][1], float)
        along = (end - origin) / np.linalg.norm(end - origin)
        grab = end - along * 2.0
        _drag(overlay, draw, [grab + along * 10.0 * step for step in range(4)])
        after = columns()
        factor = float(np.linalg.norm(after[axis]) / np.linalg.norm(before[axis]))
        assert factor > 1.05, factor
        np.testing.assert_allclose(after[axis], before[axis] * factor, atol=1e-5)
        others = [i for i in range(4) if i != axis]
        np.testing.assert_allclose(after[others], before[others], atol=1e-6)
        landed = np.array(runner.project(centre + handles.axes[axis] * (handles.length * factor)), float)
        assert np.linalg.norm(landed - (end + along * 30.0)) < 3.0, (landed, end + along * 30.0)
        assert editor.undo() and world.get(child, Transform).scale == start and not editor.can_undo

        overlay.key("", True, ctrl=True)
        _drag(overlay, draw, [grab, grab + along * 23.0])
        overlay.key("", False)
        factor = world.get(child, Transform).scale[axis] / start[axis]
        assert factor > 1.05 and abs(factor * 10.0 - round(factor * 10.0)) < 1e-4, factor
        np.testing.assert_allclose(columns()[axis], before[axis] * factor, atol=1e-5)
        assert ctx.error == "GL_NO_ERROR"
    finally:
        overlay.release()


def _combo_item(overlay, index: int) -> tuple[float, float]:
    """The middle of item ``index`` of the combo list open now (ImGui's popup window: items a
    text line and its spacing apart from its inner top)."""
    from imgui_bundle import imgui

    imgui.set_current_context(overlay.context)
    popup = next(w for w in imgui.get_current_context().windows if w.name.startswith("##Combo_") and w.active)
    step = imgui.get_text_line_height_with_spacing()
    top = popup.pos.y + imgui.get_style().window_padding.y
    assert (index + 1) * step < popup.size.y, (index, popup.size)   # in sight without scrolling
    return popup.pos.x + popup.size.x / 2, top + index * step + step / 2


@pytest.mark.filterwarnings("ignore:AmbientOcclusion on entity")   # (said on purpose: the inspector shows it)
def test_a_component_is_added_from_the_inspectors_list_and_removed_by_its_button(scene, ctx):
    """The box given an AmbientOcclusion from the inspector's "add component" list: it joins
    (one undo step), the frame is the same pixel for pixel (a camera reads it from its own
    entity only), and the rule's warning saying so is the inspector's message; its "remove"
    button takes it away, and undo gives it back.  The mirror's "remove MeshRef" is refused:
    the component's words in the inspector, the MeshRef kept, the frame unchanged, no undo step."""
    from components import AmbientOcclusion, MeshRef

    size = (640, 360)
    ents = {}
    runner = scene(lambda world: edit_scene(world, ents), size)
    runner.engine.renderer.antialias = "off"
    world, box = runner.world, ents["box"]
    overlay = DebugOverlay(ctx)
    overlay.set_scale(0.5)   # (small windows: a small frame)
    try:
        draw, click = _hands(runner, overlay, size)
        draw()
        first = runner.frame()
        editor = overlay.editing(runner.engine)
        editor.select(box)
        draw()
        wanted = editor.addable(box).index("AmbientOcclusion")
        _scrolled_to(overlay, draw, "add component", size)
        click("add component")
        x, y = _combo_item(overlay, wanted)
        overlay.mouse_moved(x, y)
        draw()
        overlay.mouse_button(1, True)
        draw()
        overlay.mouse_button(1, False)
        draw()
        draw()
        added = world.try_get(box, AmbientOcclusion)
        assert added is not None and editor.edit_count == 1
        assert editor.message and "AmbientOcclusion" in editor.message and "no Camera" in editor.message
        assert editor.message in overlay.inspector_lines
        assert np.array_equal(runner.frame(), first)
        _scrolled_to(overlay, draw, "remove AmbientOcclusion", size)
        click("remove AmbientOcclusion")
        assert not world.has(box, AmbientOcclusion) and editor.edit_count == 2
        assert editor.undo() and world.get(box, AmbientOcclusion) is added

        mirror = ents["mirror"]
        editor.select(mirror)
        draw()
        draw()
        steps, shape = editor.edit_count, world.get(mirror, MeshRef)
        _scrolled_to(overlay, draw, "remove MeshRef", size)
        click("remove MeshRef")
        assert world.get(mirror, MeshRef) is shape and editor.edit_count == steps
        assert "a Mirror needs a MeshRef" in editor.message and editor.message in overlay.inspector_lines
        assert np.array_equal(runner.frame(), first)
        assert ctx.error == "GL_NO_ERROR"
    finally:
        overlay.release()
