"""Text: the screen text and panels (``components/screen.py``) laid out and drawn over the
presented frame (``engine/render/text.py``), so no mirror, portal or probe shows them."""
from __future__ import annotations

from dataclasses import replace

import esper

from components import Monitor
from components.screen import SCREEN_ANCHORS, ScreenPanel, ScreenText
from engine.core.frame_io import Output
from engine.core.world import World
from engine.render.renderer import Renderer
from engine.render.text import ScreenItem, layout


class TextSystem(esper.Processor):
    """Every ScreenPanel and ScreenText, in drawing order (``order``, panels first, entity),
    as quads blended over the output; a panel with a ``Monitor`` on its entity filled with the
    monitor's picture (while it has one: a monitor with no camera yet leaves its panel plain)."""

    def __init__(self, world: World, renderer: Renderer) -> None:
        self.world = world
        self.renderer = renderer
        self._laid_out: tuple[list[ScreenItem], tuple[int, int]] | None = None  # what the last quads are of
        self._quads = None
        self.pictures: list[int] = []   # the monitors whose pictures the panels show, by their items' index

    def items(self) -> list[ScreenItem]:
        """The world's screen items in drawing order (``pictures``: the monitors the picture
        panels among them show, in their order)."""
        found = []
        shown = self.renderer.monitors.entities
        for entity, panel in self.world.query_one(ScreenPanel):
            found.append(((panel.order, 0, entity), ScreenItem(
                None, tuple(panel.position), SCREEN_ANCHORS[panel.anchor], tuple(panel.color),
                size=tuple(panel.size), picture=-1 if entity in shown and self.world.has(entity, Monitor) else 0)))
        for entity, text in self.world.query_one(ScreenText):
            found.append(((text.order, 1, entity), ScreenItem(
                text.text, tuple(text.position), SCREEN_ANCHORS[text.anchor], tuple(text.color), text.scale,
                background=None if text.background is None else tuple(text.background), padding=text.padding)))
        ordered = sorted(found, key=lambda pair: pair[0])
        self.pictures = [key[2] for key, item in ordered if item.picture]
        numbered = iter(range(1, len(self.pictures) + 1))
        return [replace(item, picture=next(numbered)) if item.picture else item for _, item in ordered]

    def process(self, dt: float) -> None:
        output: Output | None = self.world.resources.get(Output)
        if output is None:
            return
        items = self.items()
        if not items and not len(self.renderer.screen_quads):
            return  # no text, and none last frame: no atlas is made
        if self._laid_out != (items, output.size):  # laid out again only when a value or the size changed
            self._quads = layout(self.renderer.text().atlas, items, output.size)
            self._laid_out = (items, output.size)
        monitors = self.renderer.monitors
        self.renderer.draw_screen_text(self._quads, output.framebuffer, output.size,
                                       tuple(monitors.texture(entity) for entity in self.pictures))
