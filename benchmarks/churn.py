"""Churn: mirrors, portals, probes, meshes and textures made and deleted in waves; the
engine's GL resources and the world's entities must come back to where they started.

Each wave spawns ``--entities`` things in a ring around the camera, cycling through six
kinds: a mirror (its own quad mesh), a portal pair, a chrome sphere (its own automatic
probe), a box with its own new mesh, a box with its own new texture, a particle emitter
with its own sprite (its particles' buffer and the texture), and a decal on the floor with
its own image (its cut mesh on a part it makes, the texture); and once a wave: an irradiance
volume over the ring (its scratch cube, its grid in the irradiance table), and the weather
(``spawn_weather``: a pond with caustics and a murky body under its own wave map, a shadowed
lamp, a spot projecting its own cookie, a cloud layer and a fog volume); renders
``--frames`` frames (320 x 180, ``--size``), deletes every one of them, renders one more frame, and
prints the renderer's live GL resources (``resource_counts``), the entity count and the
resident memory.  The exit status is 1 when, after the last wave, a count is not back to
its value before the first (memory, after the garbage is collected and the C heap trimmed:
more than ``--rss-slack`` MiB above its value after the second wave, since the first two
warm the driver and the allocator; with one wave, memory is not judged).

    python -m benchmarks churn --entities 1000
"""
from __future__ import annotations

import argparse
import ctypes
import gc
import json
import math

import numpy as np

from benchmarks import add_size_argument
from benchmarks.soak import resident_mib
from components import (
    Camera,
    CloudLayer,
    Decal,
    DirectionalLight,
    FogVolume,
    IrradianceVolume,
    Material,
    MeshRef,
    Mirror,
    ParticleEmitter,
    PointLight,
    ReflectionProbe,
    Reflective,
    Skybox,
    Transform,
    Water,
    look_rotation,
    yaw_pitch_rotation,
)
from engine.assets.mesh import box, plane, quad, sphere
from engine.assets.portals import spawn_portal_pair
from engine.assets.texture_data import TextureData, checker_texture, wave_normal_map
from engine.core.frame_io import Output
from engine.core.game import Game
from engine.core.world import World
from engine.render.gl_context import create_headless_context
from engine.render.targets import CaptureTarget
from shell.app import Engine

SIZE = (320, 180)


class Arena(Game):
    title = "benchmark: churn"

    def build(self, world: World) -> None:
        world.spawn(Transform(position=(0, 6, 0.01), rotation=look_rotation((0, -1, -0.001))), Camera(fov_y=100))
        world.spawn(Skybox())
        world.spawn(DirectionalLight(direction=(-0.3, -1, -0.4)))
        world.spawn(Transform(), MeshRef(plane(40, 40)), Material(texture=checker_texture(64, 8, name="floor")))


KINDS = 7  # mirror, portal pair, chrome sphere, own mesh, own texture, particle emitter, decal (spawn_wave)


def of_kind(kind: int, count: int) -> int:
    """How many of a wave of ``count`` are of ``kind`` (0 to KINDS - 1, ``spawn_wave``'s order)."""
    return len(range(kind, count, KINDS))


def spawn_wave(world: World, count: int, wave: int) -> list[int]:
    made: list[int] = []
    if count:  # one volume a wave, baked in its first frame, and the weather
        made.append(world.spawn(Transform(position=(0.0, 1.0, 0.0)), IrradianceVolume(
            size=(20.0, 2.0, 20.0), points=(2, 2, 2), resolution=16, points_per_frame=8)))
        made += spawn_weather(world, wave)
    for i in range(count):
        angle = 2 * math.pi * i / max(count, 1)
        radius = 3 + (i % 7)
        at = (radius * math.cos(angle), 0.75, radius * math.sin(angle))
        facing = look_rotation((math.cos(angle), 0, math.sin(angle)))  # +Z towards the middle
        kind = i % KINDS
        if kind == 0:
            made.append(world.spawn(Transform(position=at, rotation=facing), MeshRef(quad(1.2, 1.0, name=f"m{i}")),
                                    Material(), Mirror(max_depth=1)))
        elif kind == 1:
            a, b = spawn_portal_pair(world, at, facing, (at[0], at[1] + 3, at[2]), facing, size=(1, 1.4), max_depth=1)
            made += [a, b]
        elif kind == 2:
            made.append(world.spawn(Transform(position=at), MeshRef(sphere(0.4, 16, 8)),
                                    Material(metallic=1.0, roughness=0.1), Reflective("cube"),
                                    ReflectionProbe(resolution=16, refresh="once")))
        elif kind == 3:
            made.append(world.spawn(Transform(position=at), MeshRef(box((0.5, 0.5, 0.5), name=f"box {wave}.{i}")),
                                    Material(color=(0.8, 0.3, 0.2))))
        elif kind == 4:
            pixels = np.full((8, 8, 4), (wave * 40 + i) % 256, np.uint8)
            made.append(world.spawn(Transform(position=at), MeshRef(box((0.5, 0.5, 0.5))),
                                    Material(texture=TextureData(pixels, name=f"texture {wave}.{i}"))))
        elif kind == 5:
            pixels = np.full((4, 4, 4), (wave * 40 + i) % 256, np.uint8)
            made.append(world.spawn(Transform(position=at), ParticleEmitter(
                rate=60.0, size=0.2, texture=TextureData(pixels, name=f"sprite {wave}.{i}"))))
        else:  # a decal on the floor with its own image (its cut mesh, its part, the texture)
            pixels = np.full((4, 4, 4), (wave * 40 + i) % 256, np.uint8)
            down = look_rotation((0, -1, 0), (0, 0, -1))
            made.append(world.spawn(Transform(position=(at[0], 0.0, at[2]), rotation=down, scale=(1.0, 1.0, 0.5)),
                                    Decal(texture=TextureData(pixels, name=f"decal {wave}.{i}"))))
    return made


WEATHER_MIRRORS = 1  # the pond (spawn_weather: a Water on a Mirror)
WEATHER_TEXTURES = 1  # the pond's wave map (spawn_weather; the spot's cookie is drawn into the cookie atlas)


def spawn_weather(world: World, wave: int) -> list[int]:
    """A wave's weather, each thing owning what it is drawn with: a pond (a Water mirror with
    caustics and a murky body: its fog row, its caustic block, the level copy its refraction
    reads) under a wave map of its own, a lamp with a shadow cube, a spot projecting a cookie
    of its own (its spot map and cookie atlas), a cloud layer (its shadows on the floor) and
    a fog volume."""
    waves = wave_normal_map(16, 3, seed=wave, name=f"waves {wave}")
    cookie = TextureData(np.full((8, 8, 4), 40 * wave % 256, np.uint8), name=f"cookie {wave}")
    down = look_rotation((0.0, -1.0, 0.0), (0.0, 0.0, -1.0))
    return [
        world.spawn(Transform(position=(0.0, 0.05, 0.0), rotation=yaw_pitch_rotation(0.0, -90.0)),  # facing up
                    MeshRef(quad(3.0, 3.0, name=f"pond {wave}")),
                    Material(color=(0.1, 0.3, 0.35, 0.3), normal_map=waves), Mirror(max_depth=1),
                    Water(caustics=1.0, fog_density=0.5, depth=1.0)),
        world.spawn(Transform(position=(2.0, 2.0, 2.0)), PointLight(intensity=3.0, range=8.0, shadows=True,
                                                                    shadow_resolution=64)),
        world.spawn(Transform(position=(-2.0, 4.0, 0.0), rotation=down),
                    PointLight(intensity=5.0, range=8.0, spot_angle=50.0, shadows=True, shadow_resolution=64,
                               cookie=cookie)),
        world.spawn(CloudLayer(seed=wave)),
        world.spawn(Transform(position=(0.0, 1.0, 3.0)), FogVolume(size=(3.0, 2.0, 3.0), density=0.3)),
    ]


def snapshot(engine: Engine) -> dict:
    """The engine's live GL resources and entities, and the resident memory once the garbage
    is collected and the C heap's free pages are handed back (``trim_heap``): what is live,
    not what the allocator keeps for later."""
    gc.collect()
    trim_heap()
    return {"gl_resources": engine.renderer.resource_counts(), "entities": len(engine.world.entities()),
            "rss_mib": round(resident_mib(), 1)}


def trim_heap() -> None:
    """Hand the C heap's free pages back to the system (glibc's ``malloc_trim``; nothing
    elsewhere).  Without it a wave's freed memory stays resident, scattered, and the resident
    size after a wave of 1000 things wanders by 60-80 MiB from wave to wave with nothing
    live growing (Python's traced memory flat)."""
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


def run(entities: int, waves: int, frames: int, size: tuple[int, int] = SIZE) -> list[dict]:
    ctx = create_headless_context()
    engine = Engine(Arena(), ctx)
    capture = CaptureTarget(ctx, size)
    output = Output(capture.framebuffer, size)
    rows = []
    try:
        engine.frame(1 / 60, output)
        rows.append({"wave": 0, **snapshot(engine)})
        for wave in range(1, waves + 1):
            made = spawn_wave(engine.world, entities, wave)
            for _ in range(frames):
                engine.frame(1 / 60, output)
            peak = engine.renderer.resource_counts()
            for entity in made:
                if engine.world.exists(entity):
                    engine.world.delete_entity(entity)
            engine.frame(1 / 60, output)
            rows.append({"wave": wave, "peak_gl_resources": peak, **snapshot(engine)})
    finally:
        capture.release()
        engine.close()
        ctx.release()
    return rows


def leftovers(rows: list[dict], rss_slack: float) -> list[str]:
    """GL resources and entities against before the first wave; memory against after the
    second (the first two waves warm the driver's caches and the allocator: measured, heap
    trimmed, 400 things 353 -> 374 MiB, then 376-393 over five more waves, no trend; 1000
    things 516 -> 614, then 627-636).  With two waves, against after the first; with one,
    memory is not judged (what the first wave warms is not a leak, and there is nothing
    after it to compare)."""
    first, last = rows[0], rows[-1]
    warm = rows[min(2, len(rows) - 2)] if len(rows) > 2 else None
    found = [f"{kind} {first['gl_resources'][kind]} -> {count}" for kind, count in last["gl_resources"].items()
             if kind not in ("levels", "probe_levels", "programs") and count != first["gl_resources"][kind]]
    if last["entities"] != first["entities"]:
        found.append(f"entities {first['entities']} -> {last['entities']}")
    if warm is not None and last["rss_mib"] - warm["rss_mib"] > rss_slack:
        found.append(f"resident memory {warm['rss_mib']} (after wave {warm['wave']}) -> {last['rss_mib']} MiB")
    return found


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--entities", type=int, default=1000, help="things spawned per wave")
    parser.add_argument("--waves", type=int, default=5)
    parser.add_argument("--frames", type=int, default=3, help="frames rendered while a wave lives")
    parser.add_argument("--rss-slack", type=float, default=40.0, help="MiB of growth tolerated")
    add_size_argument(parser, SIZE)


def main(args: argparse.Namespace) -> int:
    rows = run(args.entities, args.waves, args.frames, args.size)
    for row in rows:
        print(json.dumps(row) if args.json else "  ".join(f"{k}={v}" for k, v in row.items()), flush=True)
    problems = leftovers(rows, args.rss_slack)
    print(json.dumps({"left_over": problems}) if args.json else ("left over: " + "; ".join(problems) if problems
                                                                   else "everything came back"))
    return 1 if problems else 0
