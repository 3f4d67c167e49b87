"""The picture in README's "Edit a level": docs/edit_a_level.png, remade by running this
from the repository's root (headless, no window needed)::

    python3 docs/edit_a_level.py

The sample level (games/hall_of_mirrors) runs at 1280x720 with the debug overlay on
(shell/overlay.py), and a user's hand goes through its widgets as a window would forward
it (the mouse moved, pressed and let go over a widget's place, ``overlay.widgets``; keys
pressed and let go; characters typed), a frame drawn at every step:

1. the overlay's "entities" box ticked: the entity list opens at the top right;
2. its filter clicked and "crate" typed into it: the crates are listed;
3. red_crate clicked in the list: it is selected, outlined wherever it shows (where it
   stands and in the mirror behind it), its move handles at its origin, and the inspector
   opens below the list (its Transform first);
4. the red number of the Material's colour double-clicked (a drag field then takes typed
   text) and 0.2 typed, Tab to the green number, 0.75, Tab to the blue one, 0.3, Enter: the
   crate is green (the field's edits go through the editor, as every inspector edit does);
5. the mouse moved off the overlay onto the floor (no widget left highlighted), and the
   frame written with the overlay drawn over it.

Every step goes through the overlay's widgets; nothing is set in code but the camera's
pose at the start (the runner's ``--camera``).  The script checks that each step did what
it says (the filter's text, the list, the selection, the colour) and stops if one did not.
"""
from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # this checkout's engine, wherever the script is run from

from PIL import Image  # noqa: E402

from components import Material  # noqa: E402
from engine.core.frame_io import Output  # noqa: E402
from engine.render.gl_context import create_headless_context  # noqa: E402
from engine.render.targets import CaptureTarget  # noqa: E402
from games.hall_of_mirrors.level import HallOfMirrors  # noqa: E402
from shell.app import Engine  # noqa: E402
from shell.overlay import DebugOverlay  # noqa: E402

SIZE = (1280, 720)
DT = 1.0 / 60.0                        # game seconds a frame (the crates spin on as we work)
CAMERA = (-4.6, 1.7, 2.6, -12.0, -12.0)  # x, y, z, yaw, pitch: the red crate before mirror_2
GREEN = (0.2, 0.75, 0.3)               # typed into the colour's red, green and blue numbers
RESTING = (700, 690)                   # where the mouse is left: the floor, clear of the handles
OUT = ROOT / "docs" / "edit_a_level.png"


def main() -> None:
    ctx = create_headless_context()
    game = HallOfMirrors()
    game.load()
    engine = Engine(game, ctx)
    engine.start("fxaa", CAMERA)
    capture = CaptureTarget(ctx, SIZE)
    output = Output(capture.framebuffer, SIZE)
    overlay = DebugOverlay(ctx)
    try:
        def draw() -> None:
            """One frame of the game, the overlay drawn over it (what a window shows)."""
            engine.frame(DT, output)
            overlay.record(DT)
            overlay.draw(engine, capture.framebuffer, SIZE)

        def press(x: float, y: float, clicks: int = 1) -> None:
            """The mouse to (x, y), then pressed and let go ``clicks`` times."""
            overlay.mouse_moved(x, y)
            draw()
            for _ in range(clicks):
                overlay.mouse_button(1, True)
                draw()
                overlay.mouse_button(1, False)
                draw()
            draw()

        def key(name: str, ctrl: bool = False) -> None:
            overlay.key(name, True, ctrl=ctrl)
            draw()
            overlay.key(name, False)
            draw()

        def typed(text: str) -> None:
            overlay.text(text)
            draw()

        draw()
        draw()
        press(*overlay.widgets["entities"])              # 1. the entity list
        press(*overlay.widgets["entity filter"])         # 2. its filter, "crate" typed
        typed("crate")
        assert overlay.entity_filter == "crate", overlay.entity_filter
        crate = game.names["red_crate"]
        assert any(label.startswith("red_crate:") for label in overlay.listed_entities), overlay.listed_entities
        press(*overlay.widgets[f"entity {crate}"])       # 3. the red crate chosen
        assert overlay.editor.selected == crate
        draw()  # (the inspector takes its size a frame after it opens)
        field = scrolled_to(overlay, draw, "Material.color.left")
        press(*field, clicks=2)                          # 4. the red number: typed, Tab, ...
        for n, value in enumerate(GREEN):
            key("A", ctrl=True)   # (its text chosen whole: what is typed replaces it)
            typed(f"{value:g}")
            key("TAB" if n < len(GREEN) - 1 else "ENTER")
        colour = tuple(round(c, 3) for c in engine.world.get(crate, Material).color)
        assert colour == (*GREEN, 1.0), colour
        overlay.mouse_moved(*RESTING)                    # 5. the hand off the overlay
        draw()
        draw()
        Image.fromarray(capture.read_rgb()).save(OUT, optimize=True)
        print(f"wrote {OUT.relative_to(ROOT)}")
    finally:
        overlay.release()
        capture.release()
        engine.close()
        ctx.release()


def scrolled_to(overlay: DebugOverlay, draw, widget: str) -> tuple[float, float]:
    """The inspector scrolled by the mouse wheel over it until ``widget`` shows (the
    inspector is as tall as the window at most); the widget's place then."""
    for _ in range(40):
        x, y = overlay.widgets[widget]
        top = overlay.windows["Inspector"][0][1] + 24 * overlay.scale
        if top <= y < SIZE[1] - 12:
            return x, y
        overlay.mouse_moved(x, SIZE[1] - 20)
        overlay.scroll(0.0, -1.0 if y >= top else 1.0)
        draw()
        draw()
    raise SystemExit(f"{widget} stayed out of the inspector's sight: {overlay.widgets[widget]}")


if __name__ == "__main__":
    main()
