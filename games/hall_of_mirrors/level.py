"""Hall of mirrors, the sample level: the level itself is data (``hall.toml``, a level file:
docs/level_files.md); this script adds what moves.

The hall: a checkered floor, spinning crates, an emissive lamp with a point light, a chrome
ball that reflects only the sky and a crate that mixes its texture with the sky; a wall of
mirrors with different tints and roughness whose centre mirror faces one behind the camera
(a corridor of reflections); a portal doorway that opens far across the hall, where a crate
stands half in it and half out of its partner, and a facing pair of portals that shows a
tunnel to the recursion limit; a chrome ball whose probe is captured every frame, a brass
statue hammered by a normal map whose probe follows what moves near it, a glass ball in
front of a red crate, a pond in the foreground (a Water surface: Fresnel-weighted
reflection, moving waves, the sun's caustics on its tiles, a koi turning under it that
breaks the surface every few seconds and rings it: ``Rise``, ``Ripples``), a security
camera whose monitor by the start shows the tunnel of portals (``Monitor``), and
before the mirror wall a vampire that no mirror or probe shows and a ghost that only the
mirrors show (Visibility).

Headless runs follow a camera tour (the level's ``[rules] tour``: poses ``[x, y, z, yaw,
pitch]``, each held ``tour_seconds`` while the camera pans ``tour_pan`` degrees) unless
``--camera`` places the camera; windowed runs fly freely.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from pyglm import glm

from components import FlyController, Splash, Transform, yaw_pitch_rotation
from engine.assets.level_file import LevelError, LevelGame
from engine.core.world import World

LEVEL = Path(__file__).with_name("hall.toml")


@dataclass
class Spin:
    """Marks an entity that turns about +Y at ``speed`` degrees per second."""

    speed: float = 20.0


@dataclass
class Rise:
    """Marks a point under a rippling water that breaks its surface every ``every`` seconds
    (``first`` the first time): the koi's mouth taking a breath.  Each time the script drops a
    ``Splash`` of ``radius`` and ``depth`` metres there, and the pond's ``Ripples`` ring out
    from it (the ripple stage: a Splash lands straight across the water from its entity)."""

    every: float = 3.0
    first: float = 1.0
    radius: float = 0.03
    depth: float = 0.003

    def __post_init__(self) -> None:
        for name in ("every", "first", "radius", "depth"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value < 1e4 \
                    or (name in ("every", "radius") and not value > 0.0):
                raise ValueError(f"Rise.{name} must be a {'positive' if name in ('every', 'radius') else 'finite'} "
                                 f"number of {'seconds' if name in ('every', 'first') else 'metres'} "
                                 f"in [0, 1e4), got {value!r}")


class HallOfMirrors(LevelGame):
    title = "Speculum: hall of mirrors"
    size = (960, 540)
    game = "hall_of_mirrors"  # a level file's [level] game
    components = {"Spin": Spin, "Rise": Rise}

    def __init__(self, level_path: str | Path = LEVEL, tour: bool = False) -> None:
        super().__init__(level_path)
        self.tour = tour  # follow the level's camera tour (the runner turns it on for headless runs)
        self.time = 0.0

    def build(self, world: World) -> None:
        super().build(world)
        self.poses = tour_poses(self.level.path, self.level.rules)
        self.seconds = float(self.level.rules.get("tour_seconds", 2.0))
        self.pan = float(self.level.rules.get("tour_pan", 0.0))
        self.time = 0.0
        self.rises: dict[int, float] = {}   # Rise entity -> the game time of its next breath

    def update(self, world: World, dt: float) -> None:
        for _, (spin, transform) in world.query(Spin, Transform):
            transform.rotation = glm.angleAxis(glm.radians(spin.speed * dt), glm.vec3(0, 1, 0)) * transform.rotation
        for entity, rise in world.query_one(Rise):
            due = self.rises.setdefault(entity, rise.first)
            if self.time + dt >= due:   # (this frame's seconds reach its next breath)
                world.add_component(entity, Splash(radius=rise.radius, depth=rise.depth))
                self.rises[entity] = due + rise.every * (1 + int((self.time + dt - due) // rise.every))
        if self.tour and self.poses:
            self._follow_tour(world)
        self.time += dt

    def _follow_tour(self, world: World) -> None:
        """Hold each pose of the tour for tour_seconds, panning across ``tour_pan`` degrees of
        yaw (eased), then cut to the next: flying between poses would pass through objects
        and, crossing a portal, be carried through it."""
        camera = self.names.get("camera")
        if camera is None:
            return
        span = self.time / self.seconds
        x, y, z, yaw, pitch = self.poses[int(span) % len(self.poses)]
        t = span - int(span)
        t = t * t * (3.0 - 2.0 * t)
        yaw += self.pan * (t - 0.5)
        transform = world.get(camera, Transform)
        transform.position = (x, y, z)
        transform.rotation = yaw_pitch_rotation(yaw, pitch)
        fly = world.try_get(camera, FlyController)
        if fly is not None:
            fly.yaw, fly.pitch = yaw, pitch


def tour_poses(path: Path, rules: dict) -> list[list[float]]:
    """The ``[rules] tour`` of a hall level: a list of [x, y, z, yaw, pitch] (may be absent)."""
    tour = rules.get("tour", [])
    if not isinstance(tour, list) or not all(
            isinstance(p, list) and len(p) == 5 and all(isinstance(v, (int, float)) for v in p) for p in tour):
        raise LevelError(path, f"[rules] tour must be a list of [x, y, z, yaw, pitch] poses, got {tour!r}")
    for key, default in (("tour_seconds", 2.0), ("tour_pan", 0.0)):
        value = rules.get(key, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value < 1e4 \
                or (key == "tour_seconds" and not value > 0):
            raise LevelError(path, f"[rules] {key} must be a {'positive ' if key == 'tour_seconds' else ''}number "
                                   f"of {'seconds' if key == 'tour_seconds' else 'degrees'}, got {value!r}")
    return [[float(v) for v in pose] for pose in tour]
