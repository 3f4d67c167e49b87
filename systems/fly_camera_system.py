"""WASD + mouse fly camera for windowed runs: reads the Input resource, writes the Transform."""
from __future__ import annotations

import esper
from pyglm import glm

from components import FlyController, Transform, yaw_pitch_rotation
from engine.core.frame_io import Input
from engine.core.world import World


class FlyCameraSystem(esper.Processor):
    def __init__(self, world: World) -> None:
        self.world = world
        world.resources.setdefault(Input, Input())

    def process(self, dt: float) -> None:
        state: Input = self.world.resources[Input]
        for _, (fly, transform) in self.world.query(FlyController, Transform):
            if state.mouse_dx or state.mouse_dy:
                fly.yaw -= state.mouse_dx * fly.mouse_sensitivity
                fly.pitch = max(-89.0, min(89.0, fly.pitch - state.mouse_dy * fly.mouse_sensitivity))
                transform.rotation = yaw_pitch_rotation(fly.yaw, fly.pitch)
            move = glm.vec3(("d" in state.held) - ("a" in state.held), ("e" in state.held) - ("q" in state.held),
                            ("s" in state.held) - ("w" in state.held))
            if glm.length(move) > 0.0:
                speed = fly.speed * (3.0 if "shift" in state.held else 1.0)
                transform.position += transform.rotation * glm.normalize(move) * speed * dt
