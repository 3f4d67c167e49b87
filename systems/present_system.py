"""Present: the finished level-0 image (reflections composited in) goes to the output."""
from __future__ import annotations

import esper

from engine.core.frame_io import Output
from engine.core.world import World
from engine.render.renderer import Renderer
from engine.resources import FrameViews


class PresentSystem(esper.Processor):
    def __init__(self, world: World, renderer: Renderer) -> None:
        self.world = world
        self.renderer = renderer

    def process(self, dt: float) -> None:
        output: Output | None = self.world.resources.get(Output)
        views: FrameViews | None = self.world.resources.get(FrameViews)
        if output is not None and views is not None and views.main is not None:
            self.renderer.present(output.framebuffer, output.size)
