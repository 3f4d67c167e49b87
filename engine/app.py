"""A game and the engine that runs it: one world, its systems in order, one renderer."""
from __future__ import annotations

import esper
import moderngl

from components import Camera, FlyController, Transform, yaw_pitch_rotation
from engine.gl_context import prepare_context
from engine.raw_gl import make_current
from engine.render.renderer import Renderer
from engine.world import World
from systems import FlyCameraSystem, Output, PortalTravelSystem, PresentSystem, RenderSystem, TransformSystem
from systems.portal_slice_system import PortalSliceSystem
from systems.reflection_system import ReflectionSystem

# System order, high priority first (see ARCHITECTURE.md).
PRIORITY_GAME = 100
PRIORITY_INPUT = 90
PRIORITY_TRAVEL = 70  # after input moved the camera, before world matrices
PRIORITY_SLICE = 60  # things partly through portals: after travel, before world matrices
PRIORITY_TRANSFORM = 50
PRIORITY_RENDER = 0
PRIORITY_REFLECT = -10
PRIORITY_PRESENT = -100


class Game:
    """Subclass this: ``build`` spawns the level; ``update`` runs first every frame."""

    title = "Speculum"
    size: tuple[int, int] = (1280, 720)

    def build(self, world: World) -> None:
        raise NotImplementedError

    def update(self, world: World, dt: float) -> None:
        pass


class _GameUpdateSystem(esper.Processor):
    def __init__(self, game: Game, world: World) -> None:
        self.game = game
        self.world = world

    def process(self, dt: float) -> None:
        self.game.update(self.world, dt)


class Engine:
    """Owns a game's world and renderer on a given GL context."""

    def __init__(self, game: Game, ctx: moderngl.Context) -> None:
        make_current(ctx)  # everything below makes GL objects on it
        caps = prepare_context(ctx)
        self.game = game
        self.ctx = ctx
        self.world = World(game.title)
        self.renderer = Renderer(ctx, caps)
        self.render_system = RenderSystem(self.world, self.renderer)
        self.world.add_system(_GameUpdateSystem(game, self.world), PRIORITY_GAME)
        self.world.add_system(FlyCameraSystem(self.world), PRIORITY_INPUT)
        self.world.add_system(PortalTravelSystem(self.world, self.render_system), PRIORITY_TRAVEL)
        self.world.add_system(TransformSystem(self.world), PRIORITY_TRANSFORM)
        self.world.add_system(PortalSliceSystem(self.world), PRIORITY_SLICE)
        self.world.add_system(self.render_system, PRIORITY_RENDER)
        self.reflection_system = ReflectionSystem(self.world, self.render_system, self.renderer)
        self.world.add_system(self.reflection_system, PRIORITY_REFLECT)
        self.world.add_system(PresentSystem(self.render_system, self.renderer), PRIORITY_PRESENT)
        try:
            game.build(self.world)
        except BaseException:
            self.close()
            raise

    def frame(self, dt: float, output: Output | None) -> None:
        """Run every system once; the render system draws into ``output``.

        The engine's context is made current first (``raw_gl.make_current``): another GL
        context made in the process (a window, a tool's) would otherwise receive this
        engine's draws."""
        self.render_system.output = output
        make_current(self.ctx)
        self.world.step(dt)
        error = self.ctx.error
        if error != "GL_NO_ERROR":
            raise RuntimeError(f"OpenGL error after frame {self.world.frame_index}: {error}")

    def place_camera(self, x: float, y: float, z: float, yaw: float, pitch: float) -> None:
        """Move the active camera (``--camera``); yaw 0 looks down -Z, degrees."""
        active = self.render_system.active_camera()
        if active is None:
            raise ValueError("--camera given but the level has no active Camera")
        entity, _, transform = active
        transform.position = (x, y, z)
        transform.rotation = yaw_pitch_rotation(yaw, pitch)
        fly = self.world.try_get(entity, FlyController)
        if fly is not None:
            fly.yaw, fly.pitch = yaw, pitch

    def close(self) -> None:
        """Delete every entity, release every GL resource, drop the world."""
        make_current(self.ctx)
        self.world.close()
        self.renderer.release()


def spawn_camera(world: World, position=(0.0, 1.6, 6.0), yaw: float = 0.0, pitch: float = 0.0,
                 fov_y: float = 60.0, fly: bool = True) -> int:
    """A camera entity, with fly controls for windowed runs unless ``fly`` is False."""
    components = [Transform(position=position, rotation=yaw_pitch_rotation(yaw, pitch)), Camera(fov_y=fov_y)]
    if fly:
        components.append(FlyController(yaw=yaw, pitch=pitch))
    return world.spawn(*components)
