"""A game: what the engine runs.  ``build`` spawns the level into a world, ``update`` runs
first in every frame (the "game" stage).  The shell (``shell.app.Engine``) runs it; the
engine core and the level files only need the interface."""
from __future__ import annotations

from components import Camera, FlyController, Transform, yaw_pitch_rotation
from engine.core.world import World


class Game:
    """Subclass this: ``build`` spawns the level; ``update`` runs first every frame."""

    title = "Speculum"
    size: tuple[int, int] = (1280, 720)

    def build(self, world: World) -> None:
        raise NotImplementedError

    def update(self, world: World, dt: float) -> None:
        pass


def spawn_camera(world: World, position=(0.0, 1.6, 6.0), yaw: float = 0.0, pitch: float = 0.0,
                 fov_y: float = 60.0, fly: bool = True) -> int:
    """A camera entity, with fly controls for windowed runs unless ``fly`` is False."""
    components = [Transform(position=position, rotation=yaw_pitch_rotation(yaw, pitch)), Camera(fov_y=fov_y)]
    if fly:
        components.append(FlyController(yaw=yaw, pitch=pitch))
    return world.spawn(*components)
