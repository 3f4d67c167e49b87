"""WASD + mouse fly camera for windowed runs: reads the Input resource, writes the Transform.
The mouse wheel flies a perspective camera forward or back (a quarter second's flight a
step) and zooms an orthographic one (its ``ortho_height`` a tenth smaller a step away), as
an editor's view does.  It flies in the entity's own units (its Transform's scale): a camera
that a portal pair of two scales made twice as big flies twice as fast, as the view through
that portal showed it moving."""
from __future__ import annotations

import math

import esper
from pyglm import glm

from components import Camera, FlyController, Transform, yaw_pitch_rotation
from engine.core.frame_io import Input
from engine.core.world import World


class FlyCameraSystem(esper.Processor):
    def __init__(self, world: World) -> None:
        self.world = world
        world.resources.setdefault(Input, Input())

    def process(self, dt: float) -> None:
        state: Input = self.world.resources[Input]
        for entity, (fly, transform) in self.world.query(FlyController, Transform):
            if state.mouse_dx or state.mouse_dy:
                # Kept within a half turn either way (the same rotation): a player turning round and
                # round would otherwise reach FlyController's bound on yaw and be refused.
                fly.yaw = math.remainder(fly.yaw - state.mouse_dx * fly.mouse_sensitivity, 360.0)
                fly.pitch = max(-89.0, min(89.0, fly.pitch - state.mouse_dy * fly.mouse_sensitivity))
                transform.rotation = yaw_pitch_rotation(fly.yaw, fly.pitch)
            if state.wheel:
                self._wheel(entity, fly, transform, state.wheel)
            move = glm.vec3(("d" in state.held) - ("a" in state.held), ("e" in state.held) - ("q" in state.held),
                            ("s" in state.held) - ("w" in state.held))
            if glm.length(move) > 0.0:
                speed = fly.speed * (3.0 if "shift" in state.held else 1.0)
                transform.position += transform.rotation * (transform.scale * glm.normalize(move)) * (speed * dt)

    def _wheel(self, entity: int, fly: FlyController, transform: Transform, steps: float) -> None:
        """The wheel's ``steps``: an orthographic camera zooms (0.9 of its height a step
        away, held within Camera's range), anything else flies forward a quarter second a step."""
        camera = self.world.try_get(entity, Camera)
        if camera is not None and camera.projection == "orthographic":
            camera.ortho_height = min(max(camera.ortho_height * WHEEL_ZOOM ** steps, 1e-3), 1e6)
        else:
            transform.position += transform.rotation * (transform.scale * glm.vec3(0.0, 0.0, -1.0)) \
                * (fly.speed * WHEEL_FLIGHT * steps)


WHEEL_ZOOM = 0.9     # an orthographic camera's height a wheel step away
WHEEL_FLIGHT = 0.25  # seconds of flight a wheel step
