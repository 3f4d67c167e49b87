"""Hall of mirrors: a checkered floor, a few objects, an emissive lamp, a chrome sphere that
reflects only the sky, a textured crate that mixes its texture with the sky (50/50), a
wall of mirrors with different tints and roughness, and a facing pair (the wall's centre
mirror and one behind the camera) that shows a corridor of reflections; a portal pair (the
left doorway opens far across the hall, where a crate stands half in it and half out of
its partner), and a facing pair of portals on the right that shows a tunnel; a chrome ball
with a probe captured every frame by the mirror wall, a brass statue whose probe follows
what moves near it, and a glass ball in front of a red crate (cube-map probes)."""
from __future__ import annotations

from pyglm import glm

from components import (
    DirectionalLight,
    Emissive,
    Material,
    MeshRef,
    Mirror,
    PointLight,
    ReflectionProbe,
    Reflective,
    Refractive,
    Skybox,
    Transform,
    Traveller,
)
from engine import Game, World, spawn_camera
from engine.mesh import box, plane, quad, sphere
from engine.portals import spawn_portal_pair
from engine.texture_data import checker_texture


class Spin:
    """Marks an entity that turns about +Y at ``speed`` degrees per second."""

    def __init__(self, speed: float) -> None:
        self.speed = speed


class HallOfMirrors(Game):
    title = "Speculum: hall of mirrors"
    size = (960, 540)

    def build(self, world: World) -> None:
        spawn_camera(world, position=(0.0, 1.7, 6.5), yaw=0.0, pitch=-8.0)
        world.spawn(Skybox())
        world.spawn(DirectionalLight(direction=(-0.4, -1.0, -0.5), color=(1.0, 0.96, 0.9), intensity=2.6))

        floor_texture = checker_texture(256, 16, name="floor")
        world.spawn(Transform(), MeshRef(plane(40.0, 40.0, uv_repeat=10.0)),
                    Material(color=(1.0, 1.0, 1.0), texture=floor_texture, roughness=0.8))

        crate = box((1.0, 1.0, 1.0))
        for x, z, c in ((-3.2, -1.5, (0.75, 0.12, 0.1)), (3.0, -2.0, (0.1, 0.35, 0.8)),
                        (-1.6, -3.8, (0.2, 0.6, 0.2))):
            world.spawn(Transform(position=(x, 0.5, z)), MeshRef(crate), Material(color=c, roughness=0.6),
                        Spin(20.0))

        # The lamp: emissive globe on a post, with a point light at its centre.
        world.spawn(Transform(position=(2.0, 0.75, 0.5)), MeshRef(box((0.12, 1.5, 0.12))),
                    Material(color=(0.2, 0.2, 0.22), metallic=0.8, roughness=0.3))
        world.spawn(Transform(position=(2.0, 1.7, 0.5)), MeshRef(sphere(0.22)),
                    Material(color=(1.0, 0.75, 0.35)), Emissive(2.5),
                    PointLight(color=(1.0, 0.75, 0.4), intensity=6.0, range=8.0))

        # One object that reflects only the sky, one that mixes texture and sky.
        world.spawn(Transform(position=(-0.9, 1.0, 0.0)), MeshRef(sphere(0.8)),
                    Material(color=(1.0, 1.0, 1.0), metallic=1.0, roughness=0.05), Reflective("skybox"))
        world.spawn(Transform(position=(0.9, 0.6, 1.2), rotation=glm.angleAxis(glm.radians(30), glm.vec3(0, 1, 0))),
                    MeshRef(box((1.2, 1.2, 1.2))),
                    Material(texture=checker_texture(128, 4, (200, 150, 60), (90, 50, 20), name="crate"),
                             color=(1.0, 1.0, 1.0), roughness=0.5),
                    Reflective("skybox"))

        self._probes(world)
        self._mirrors(world)
        self._portals(world)

    @staticmethod
    def _probes(world: World) -> None:
        """Things that reflect or refract the room through cube-map probes: a chrome ball by
        the mirror wall whose probe is captured every frame (the crates spin), a brass
        statue on a plinth whose probe is recaptured only where something moved, and a
        glass ball in front of the red crate."""
        world.spawn(Transform(position=(1.5, 0.65, -3.9)), MeshRef(sphere(0.65)),
                    Material(color=(0.95, 0.95, 0.95), metallic=1.0, roughness=0.02), Reflective("cube"),
                    ReflectionProbe(resolution=128, refresh="every_frame"))
        world.spawn(Transform(position=(-2.3, 0.3, 1.8)), MeshRef(box((0.7, 0.6, 0.7))),
                    Material(color=(0.3, 0.28, 0.26), roughness=0.7))
        world.spawn(Transform(position=(-2.3, 1.25, 1.8), scale=(0.32, 0.65, 0.32)), MeshRef(sphere(1.0)),
                    Material(color=(1.0, 0.71, 0.29), metallic=1.0, roughness=0.25), Reflective("cube"),
                    ReflectionProbe(resolution=64))
        world.spawn(Transform(position=(-2.6, 0.55, -0.2)), MeshRef(sphere(0.5)),
                    Material(color=(0.95, 1.0, 0.97, 0.05), roughness=0.0), Refractive(ior=1.5))

    @staticmethod
    def _mirrors(world: World) -> None:
        frame = Material(color=(0.15, 0.12, 0.1), roughness=0.4)
        glass = Material(color=(0.05, 0.05, 0.05))
        # The wall: (x, width, tint, roughness). The centre one faces the mirror behind the camera.
        wall = ((-5.2, 2.0, (1.0, 0.85, 0.85), 0.0), (-2.9, 2.0, (0.8, 0.9, 1.0), 0.25),
                (0.0, 3.2, (0.95, 0.97, 0.95), 0.0), (2.9, 2.0, (0.9, 1.0, 0.85), 0.5),
                (5.2, 2.0, (1.0, 0.95, 0.75), 0.1))
        for x, width, tint, roughness in wall:
            world.spawn(Transform(position=(x, 1.6, -6.0)), MeshRef(quad(width, 2.8)), glass,
                        Mirror(color=tint, roughness=roughness))
            world.spawn(Transform(position=(x, 1.6, -6.06)), MeshRef(box((width + 0.2, 3.0, 0.1))), frame)
        back = glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))
        world.spawn(Transform(position=(0.0, 1.6, 11.0), rotation=back), MeshRef(quad(4.0, 3.0)), glass,
                    Mirror(color=(0.95, 0.95, 1.0)))
        world.spawn(Transform(position=(0.0, 1.6, 11.06), rotation=back), MeshRef(box((4.2, 3.2, 0.1))), frame)

    @staticmethod
    def _portals(world: World) -> None:
        frame = Material(color=(0.35, 0.3, 0.5), roughness=0.3)

        def doorway(portal: int, width: float, height: float) -> None:
            for x in (-width / 2 - 0.05, width / 2 + 0.05):
                world.spawn(Transform(position=(x, 0.05, 0.0), parent=portal),
                            MeshRef(box((0.1, height + 0.1, 0.1))), frame)
            world.spawn(Transform(position=(0.0, height / 2 + 0.05, 0.0), parent=portal),
                        MeshRef(box((width + 0.2, 0.1, 0.1))), frame)

        def yaw(degrees: float) -> glm.quat:
            return glm.angleAxis(glm.radians(degrees), glm.vec3(0, 1, 0))

        # The doorway on the left opens far across the hall (the partner stands at x = 16).
        door, _ = spawn_portal_pair(world, (-5.5, 1.25, -0.5), yaw(38), (16.0, 1.25, -9.0), yaw(-90),
                                    size=(1.6, 2.5))
        doorway(door, 1.6, 2.5)
        # Beyond the partner: a lantern to look at, and a crate pushed half through it.
        world.spawn(Transform(position=(13.5, 0.5, -8.4)), MeshRef(box((0.8, 1.0, 0.8))),
                    Material(color=(0.9, 0.2, 0.6)), Emissive(0.6))
        world.spawn(Transform(position=(16.0, 0.4, -9.2)), MeshRef(box((0.8, 0.8, 0.8))),
                    Material(color=(0.2, 0.7, 0.9)), Traveller())
        # The tunnel on the right: two portals facing each other across the camera, each
        # showing the other smaller and smaller, to the recursion limit.
        tunnel, _ = spawn_portal_pair(world, (5.5, 1.25, -0.5), yaw(-38), (-0.68, 1.25, 7.36), yaw(142),
                                      size=(1.6, 2.5), max_depth=4)
        doorway(tunnel, 1.6, 2.5)

    def update(self, world: World, dt: float) -> None:
        for _, (spin, transform) in world.query(Spin, Transform):
            transform.rotation = glm.angleAxis(glm.radians(spin.speed * dt), glm.vec3(0, 1, 0)) * transform.rotation
