"""Stage "clouds": each ``CloudLayer``'s drift moved on by its wind over the frame's seconds.

Before the prepare stage, which draws the sky's clouds and their shadows where the drift puts
them (``engine/render/clouds.py``).  The drift is kept within the pattern's period (it repeats
every ``NOISE_PERIOD`` x ``scale`` metres), so a long run's numbers stay small for the GPU's
floats; a layer with no wind, or a paused frame, writes nothing (no change flag: the sky's
cube map is kept)."""
from __future__ import annotations

import esper

from components import CloudLayer
from engine.core.world import World
from engine.render.clouds import NOISE_PERIOD


class CloudSystem(esper.Processor):
    """Moves each CloudLayer's clouds on the wind."""

    def __init__(self, world: World) -> None:
        super().__init__()
        self.world = world

    def process(self, dt: float) -> None:
        if dt <= 0.0:
            return
        for _, layer in self.world.query_one(CloudLayer):
            wind_x, wind_z = layer.wind
            if wind_x == 0.0 and wind_z == 0.0:
                continue
            period = NOISE_PERIOD * layer.scale
            x, z = layer.drift
            layer.drift = ((x + wind_x * dt) % period, (z + wind_z * dt) % period)
