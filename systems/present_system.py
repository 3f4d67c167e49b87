"""Present: the finished level-0 image (reflections composited in) goes to the output."""
from __future__ import annotations

import esper

from engine.render.renderer import Renderer
from systems.render_system import RenderSystem


class PresentSystem(esper.Processor):
    def __init__(self, render_system: RenderSystem, renderer: Renderer) -> None:
        self.render_system = render_system
        self.renderer = renderer

    def process(self, dt: float) -> None:
        output = self.render_system.output
        if self.render_system.main_view is not None and output is not None:
            self.renderer.present(output.framebuffer, output.size)
