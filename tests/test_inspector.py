"""The overlay's level editor: a click in the world selects the entity seen there, the
inspector lists its components and fields, a drag on a number field edits it through the
editor (one undo step), and a refused value shows the component's message. Headless,
through ImGui with the mouse events a window forwards."""
from __future__ import annotations

import pytest

from components import ComponentValueError, Material

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
