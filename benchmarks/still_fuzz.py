"""Still-frame fuzz: a facing mirror or portal pair with end images, seen by a camera that
stands still long enough for its view tree to be kept and its end images refilled
(``StillTree.keep``'s refill, ``engine/render/level_copies.py``), then one random change
among the refilled frames, and still frames again (now and then a second and third change,
each after the frames of the one before).

Each case is run in two engines of the same level, in lockstep (as
``tests/test_end_image_settle.py`` does): one keeps still views, the other
(``keep_still_views = False``) draws its whole tree every frame, and draws every shadow map
whole every frame too (its shadow stage's record of what each map was drawn from wiped before
each frame; not in a case with a monitor: ``StillFuzzer.run`` says why), so a map kept on a
still frame, or drawn again only where casters moved, must
equal one drawn from scratch (its ambient occlusion found every frame too:
``ScreenOcclusion.keep_still``); and it plans each reflection level after its parent's claims
(``ViewTree.plan_ahead = False``), so levels the keeping engine planned ahead
(``plan_ahead.plan_ahead``) must come out the same.  A case runs exact or predicted
visibility (``ReflectionSystem.visibility``) in both.  The level, around the pair,
has glass panes of random alpha (the transparent slot ordered by the planes of see-through
surfaces, ``slot_order.back_to_front``), now and then still water (a see-through mirror:
``InstanceBatch.plane``) or a see-through mirror, or a pane of random alpha between a raised
pond and a far see-through mirror (``RenderStats.glass_between_surfaces``), a lit box, now
and then a point light casting shadows, Bloom, ambient occlusion and screen reflections on
the camera (the box then reflecting the sky).  The change is one of:

- ``component``: a field of the pair, a pane, the water, a light or the box written with a
  value from the component fuzz's pool (``benchmarks.fuzz_cases.random_value``), or a light's colour
  or direction edited in place (``light.color.r = ...``, seen one stage later), or the point
  light moved in place (its shadow cube drawn again);
- ``remove``: a mirror or portal of the pair, a pane, the water, the far see-through mirror or
  the box (or, in half the cases, its twin: the same mesh, its batch's last row) deleted mid-refill;
- ``resize``: the output's size changed;
- ``depth_cap``: ``ReflectionSystem.max_depth_cap`` set to 0..8;
- ``keep_toggle``: the keeping engine's ``keep_still_views`` turned off for a while, then on;
- ``camera_off``: the camera made inactive for a frame or three (no view at all), then active;
- ``surface``: a see-through surface (still water, a see-through mirror) or a glass pane of
  random alpha added among the refilled frames;
- ``turn``: the box (an L, its box centred on its origin) turned by an exact quarter or half
  turn about y, or flipped by a scale of -1 on x and z: a half turn and the flip leave its
  world box the same to the bit, while its shadow changes;
- ``min_pixels``: the frame's ``ViewBudget(min_pixels=...)`` set, 1 to 5000 pixels (the
  views under it show their fallback).

Now and then a monitor stands in the level too: a screen the camera sees, its picture drawn
from a lens watching the box and the pair, to depth 0-2, drawn always or when seen
(``monitor``), the lens with the camera's ambient occlusion, screen reflections and light
shafts where the case gives the camera them; the drawing engine draws every due picture
(``MonitorSystem.keep_still_pictures`` off), so a picture kept must equal one drawn again.
Its Monitor, Material and Transform, and the lens's Camera and Transform, are among the
components written, and both among the entities removed.

A case passes when a refused write is refused with a ``ComponentValueError`` naming
``Class.field`` in both engines, and every frame of both renders with no NaN in the HDR
colour target and ``ctx.error`` clean, the keeping engine's colour, HDR image and
entity-id image equal bit for bit to the drawing engine's; and when the case's entities are
deleted, each engine's ``Renderer.resource_counts`` (its tree's level copies among them) come back
to what they were before the case (programs aside: a variant compiled once is kept; past
``PROGRAMS_BEFORE_RESTART`` both engines are made afresh and the programs released, so a
long run's memory stays bounded).

    python -m benchmarks fuzz --still-cases 100
"""
from __future__ import annotations

import dataclasses
import math
import random
import traceback
import warnings
from typing import Any

import numpy as np
from pyglm import glm

from benchmarks.fuzz_cases import fuzz_ripples, hdr_image, hdr_problem
from components import (
    AmbientOcclusion,
    Bloom,
    Camera,
    ComponentValueError,
    DirectionalLight,
    Emissive,
    Fog,
    Material,
    MeshRef,
    Mirror,
    Monitor,
    PointLight,
    Portal,
    Reflective,
    Refractive,
    ScreenReflections,
    Skybox,
    Transform,
    VolumetricFog,
    Water,
    look_rotation,
)
from engine.assets.mesh import plane, quad, sphere
from engine.assets.portals import spawn_portal_pair
from engine.core.budget import ViewBudget
from engine.core.frame_io import Output
from engine.core.game import Game
from engine.render.shader_library import FreePrograms
from engine.render.targets import CaptureTarget
from shell.app import Engine

SIZE = (48, 32)
CHANGES = ("component", "remove", "resize", "depth_cap", "keep_toggle", "surface", "camera_off", "turn",
           "min_pixels")
# The box's turns (``turn``): exact quaternions (w, x, y, z) and scales, not angleAxis's
# rounding, which moves the box.
BOX_SCALE = (0.4, 1.2, 0.4)
BOX_TURNS = {"quarter": (glm.quat(math.sqrt(0.5), 0.0, math.sqrt(0.5), 0.0), BOX_SCALE),
             "half": (glm.quat(0.0, 0.0, 1.0, 0.0), BOX_SCALE),
             "flip": (glm.quat(), (-BOX_SCALE[0], BOX_SCALE[1], -BOX_SCALE[2]))}
_BOX_MESH: list = []


def l_mesh():
    """An L of two boxes (made once), its box x -0.5..0.5, y -0.5..0.5, z -0.5..0.5 about
    its origin: a tall arm at -x, a low arm to +x.  A half turn about y, or a scale of -1
    on x and z, leaves its box the same to the bit and its shadow not (tests use it too)."""
    if not _BOX_MESH:
        import trimesh

        from engine.assets.mesh import Mesh

        tall = trimesh.creation.box((0.3, 1.0, 1.0))
        tall.apply_translation((-0.35, 0.0, 0.0))
        low = trimesh.creation.box((0.7, 0.4, 1.0))
        low.apply_translation((0.15, -0.3, 0.0))
        _BOX_MESH.append(Mesh.from_trimesh(trimesh.util.concatenate([tall, low]), name="fuzz L"))
    return _BOX_MESH[0]
TURN = glm.angleAxis(math.pi, glm.vec3(0, 1, 0))
FLAT = glm.angleAxis(-math.pi / 2, glm.vec3(1, 0, 0))


@dataclasses.dataclass
class StillCase:
    """One still case: the pair (``"mirrors"`` or ``"portals"``), its depth, the panes
    (position, size, rgba), whether still water or a see-through mirror stands in the
    level, the still frames before the change, the change and its details."""

    pair: str
    depth: int
    panes: list[tuple[tuple[float, float, float], float, tuple[float, float, float, float]]]
    water: bool
    see_through_mirror: bool
    sandwich: float | None  # a pane's alpha between a raised pond and a far see-through mirror, or None
    still: int
    change: str
    detail: dict[str, Any]
    after: int
    rate: float = 1.0  # the mirror pair's reflect_rate (below 1: composites blend over the level's own pixels)
    point_light: bool = False  # a point light casting shadows (a shadow cube) between the mirrors
    bloom: bool = False  # Bloom on the camera (its chain planned once a size: a resize changes it)
    visibility: str = "exact"  # the reflect stage's visibility mode, in both engines
    cascades: int = 1  # the sun's shadow cascades (rings about the camera besides its level map)
    spot_angle: float = 180.0  # the lamp's cone (PointLight.spot_angle; 180: all round, a panel), aimed at the box
    fog: bool = False  # height fog on the camera (each view's stretch, each composite's)
    occlusion: bool = False  # ambient occlusion on the camera (the root's passes before its draw)
    reflections: bool = False  # screen reflections on the camera, the box reflecting the sky (its composite)
    shafts: bool = False  # with fog: light shafts on the camera, in the root and two levels down (added)
    # A solid glass ball refracting what each view drew behind it (Refractive.screen: its copy
    # and march in every level, drawn again by a refill over its level's copy), this rough; None: none.
    glass: float | None = None
    # With the ball, a refracting pane behind it (glass behind glass: the ball drawn in a layer
    # after the pane's, over a copy that holds it: screen_refraction.refraction_layers).
    glass_behind: bool = False
    # A monitor the camera sees, fed by a lens watching the box and the pair, its picture drawn
    # to this depth (0-2), every frame or every second, always or when seen; None: none.  The
    # drawing engine draws every due picture (``MonitorSystem.keep_still_pictures`` off).
    monitor: int | None = None
    # Further changes, each (change, detail) after the last one's ``after`` frames (the tree
    # kept again, or refilling again, when the next comes); none after a refused one.
    then: list[tuple[str, dict[str, Any]]] = dataclasses.field(default_factory=list)

    def describe(self) -> str:
        return (f"still {self.pair} depth {self.depth}, {len(self.panes)} panes {self.panes}, water {self.water}, "
                f"see-through mirror {self.see_through_mirror}, sandwich {self.sandwich}; {self.still} still frames, "
                f"rate {self.rate}, point light {self.point_light}, bloom {self.bloom}, {self.visibility}, "
                f"cascades {self.cascades}, spot {self.spot_angle}, fog {self.fog}, occlusion {self.occlusion}, "
                f"reflections {self.reflections}, shafts {self.shafts}, glass {self.glass} "
                f"(behind {self.glass_behind}), monitor {self.monitor}; then "
                f"{self.change} {self.detail}, {self.after} frames" + "".join(
                    f"; then {change} {detail}, {self.after} frames" for change, detail in self.then))


def _alpha(rng: random.Random) -> float:
    return rng.choice((rng.uniform(0.05, 0.95), 0.0, 1e-4, 0.999, 1.0, 0.5))


def _pane(rng: random.Random) -> tuple[tuple[float, float, float], float, tuple[float, float, float, float]]:
    position = (rng.uniform(-1.5, 1.5), rng.uniform(0.2, 2.0), rng.uniform(-2.5, 2.5))
    return position, rng.uniform(0.2, 1.6), (rng.random(), rng.random(), rng.random(), _alpha(rng))


def random_still_case(rng: random.Random) -> StillCase:
    change, detail = _random_change(rng)
    then = [_random_change(rng) for _ in range(rng.choice((0, 0, 1, 2)))]
    return StillCase(pair=rng.choice(("mirrors", "portals")), depth=rng.randint(1, 6),
                     panes=[_pane(rng) for _ in range(rng.randint(0, 3))], water=rng.random() < 0.4,
                     see_through_mirror=rng.random() < 0.3,
                     sandwich=_alpha(rng) if rng.random() < 0.35 else None, still=rng.randint(3, 7), change=change,
                     detail=detail, after=rng.randint(3, 6), rate=rng.choice((1.0, 1.0, 0.95, 0.7)),
                     point_light=rng.random() < 0.4, bloom=rng.random() < 0.3,
                     visibility="predicted" if rng.random() < 0.25 else "exact", then=then,
                     cascades=rng.choice((1, 1, 2, 3, 4)), spot_angle=rng.choice((180.0, 180.0, 25.0, 60.0, 110.0)),
                     fog=rng.random() < 0.3, occlusion=rng.random() < 0.3, reflections=rng.random() < 0.3,
                     shafts=rng.random() < 0.5, glass=rng.choice((0.0, 0.0, 0.3)) if rng.random() < 0.35 else None,
                     glass_behind=rng.random() < 0.5, monitor=rng.choice((None, None, 0, 1, 2)))


def _random_change(rng: random.Random) -> tuple[str, dict[str, Any]]:
    from benchmarks.fuzz_cases import random_value

    change = rng.choice(CHANGES)
    detail: dict[str, Any] = {}
    if change == "component":
        target = rng.choice(("pair", "pane", "water", "light", "box", "light_in_place", "point", "point_in_place",
                             "monitor", "lens"))
        classes = {"pair": (Mirror, Material, Transform), "pane": (Material, Transform),
                   "monitor": (Monitor, Material, Transform), "lens": (Camera, Transform),
                   "water": (Water, Mirror, Material), "light": (DirectionalLight,), "box": (Transform, Material),
                   "light_in_place": (DirectionalLight,), "point": (PointLight, Transform),
                   "point_in_place": (Transform,)}[target]
        cls = rng.choice(classes)
        names = [f.name for f in dataclasses.fields(cls) if f.init and not f.name.startswith("_")]
        if target in ("light_in_place", "point_in_place"):
            detail = {"target": target, "field": rng.choice(("color", "direction") if target == "light_in_place"
                                                            else ("position", "turn")),
                      "value": rng.choice((rng.uniform(0.0, 2.0), float("nan"), 1e39, -1.0, 0.0))}
        else:
            field = rng.choice(names)
            value = random_value(rng) if rng.random() < 0.7 else _plausible(rng)
            if target in ("pane", "water") and cls is Material and rng.random() < 0.5:
                field, value = "color", (rng.random(), rng.random(), rng.random(), _alpha(rng))  # see-through or not
            detail = {"target": target, "cls": cls.__name__, "field": field, "value": value}
    elif change == "remove":
        detail = {"target": rng.choice(("first", "second", "pane", "water", "box", "far_glass_mirror", "pond",
                                        "pane_between", "monitor", "lens"))}
    elif change == "resize":
        detail = {"size": rng.choice(((56, 38), (32, 24), (48, 33), (1, 1), (97, 61)))}
    elif change == "depth_cap":
        detail = {"cap": rng.randint(0, 8)}
    elif change in ("keep_toggle", "camera_off"):
        detail = {"off_frames": rng.randint(1, 3)}
    elif change == "turn":
        detail = {"how": rng.choice(tuple(BOX_TURNS))}
    elif change == "min_pixels":
        detail = {"min": rng.choice((1, 8, 40, 200, 5000))}
    else:
        detail = {"add": rng.choice(("water", "mirror", "pane")), "pane": _pane(rng), "alpha": _alpha(rng)}
    return change, detail


def _plausible(rng: random.Random) -> Any:
    return rng.choice((rng.uniform(0.0, 1.0), rng.randint(0, 6), rng.random() < 0.5,
                       tuple(rng.uniform(0.0, 1.0) for _ in range(3)),
                       tuple(rng.uniform(0.0, 1.0) for _ in range(4))))


class _Base(Game):
    """What every case stands in: a camera between where the pair goes, a sky, a light, a
    floor."""

    title = "fuzz: still frames"

    def build(self, world) -> None:
        eye = glm.vec3(0.4, 1.5, 1.2)
        self.camera = world.spawn(Transform(position=eye, rotation=look_rotation(glm.vec3(-0.2, 1.3, -3.0) - eye)),
                                  Camera())
        world.resources["camera"] = self.camera
        world.spawn(Skybox(face_size=8))
        self.light = world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=1.5, shadow_resolution=512))
        world.spawn(Transform(), MeshRef(plane(20, 20, uv_repeat=4)), Material(color=(0.5, 0.5, 0.45)))


class _Side:
    """One engine of the two: its capture target and the entities a case spawned."""

    def __init__(self, ctx) -> None:
        self.ctx = ctx
        self.game = _Base()
        self.engine = Engine(self.game, ctx)
        self.world = self.engine.world
        self.size = SIZE
        self.capture = CaptureTarget(ctx, SIZE)
        self.named: dict[str, int] = {}
        self.redraw_shadows = False

    def frame(self) -> tuple[np.ndarray, ...]:
        if self.redraw_shadows:  # the second path: every shadow map drawn whole, none kept
            shadows = self.engine.stages["shadows"]
            shadows._still = None
            for kept in (shadows._directional, shadows._point, shadows._virtual, shadows._rings):
                kept.clear()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            self.engine.frame(1.0 / 60.0, Output(self.capture.framebuffer, self.size))
        error = self.ctx.error
        if error != "GL_NO_ERROR":
            raise AssertionError(f"ctx.error {error}")
        hdr = hdr_image(self.engine.renderer.targets)
        return self.capture.read_rgb(), hdr, self.engine.renderer.targets.read_ids()

    def resize(self, size: tuple[int, int]) -> None:
        self.capture.release()
        self.size = size
        self.capture = CaptureTarget(self.ctx, size)

    def counts(self) -> dict[str, int]:
        counts = dict(self.engine.renderer.resource_counts())
        for pooled in ("programs", "levels"):  # (a variant compiled once, a level's targets: kept for reuse)
            counts.pop(pooled)
        return counts

    def close(self) -> None:
        self.capture.release()
        self.engine.close()


def _spawn(world, case: StillCase) -> dict[str, int]:
    """The case's entities in ``world``, by name."""
    named: dict[str, int] = {}
    if case.pair == "mirrors":
        for name, z, turn in (("first", -3.0, glm.quat()), ("second", 3.0, TURN)):
            named[name] = world.spawn(Transform(position=(0.0, 1.5, z), rotation=turn), MeshRef(quad(4.0, 3.0)),
                                      Material(color=(0.15, 0.6, 0.15)),
                                      Mirror(max_depth=case.depth, color=(0.9, 0.95, 0.8), reflect_rate=case.rate,
                                             end_image=True))
    else:
        named["first"], named["second"] = spawn_portal_pair(world, (0, 1.25, -3.0), None, (0, 1.25, 3.0), TURN,
                                                            size=(2.0, 2.5), max_depth=case.depth)
        for name in ("first", "second"):
            world.get(named[name], Portal).end_image = True
    if case.cascades > 1:   # rings of 3 metres and less about the camera, over the box and the pond
        for _, light in world.query_one(DirectionalLight):
            light.shadow_cascades, light.shadow_distance = case.cascades, 3.0
    if case.point_light:
        lamp = glm.vec3(-0.3, 2.2, 0.4)
        named["point"] = world.spawn(Transform(position=lamp, rotation=look_rotation(glm.vec3(0.8, 0.6, 0.0) - lamp)),
                                     PointLight(color=(1.0, 0.8, 0.6), intensity=3.0, range=6.0, shadows=True,
                                                shadow_resolution=64, spot_angle=case.spot_angle,
                                                # (all round: a panel, its RECT_LIGHTS builds and soft shadows)
                                                rectangle=(0.6, 0.3) if case.spot_angle >= 180.0 else (0.0, 0.0)))
    if case.bloom:
        world.add_component(world.resources["camera"], Bloom(intensity=0.2))
    if case.fog:
        world.add_component(world.resources["camera"], Fog(density=0.06, height=1.0, height_falloff=0.4))
        if case.shafts:
            world.add_component(world.resources["camera"], VolumetricFog(steps=8, reflection_depth=2))
    if case.occlusion:
        world.add_component(world.resources["camera"], AmbientOcclusion(radius=0.8))
    named["box"] = world.spawn(Transform(position=(0.8, 0.6, 0.0), scale=BOX_SCALE), MeshRef(l_mesh()),
                               Material(color=(0.9, 0.2, 0.1)), Emissive(0.6))
    # Its twin (the same mesh: the batch's last row), inside the level; "remove" of the box
    # takes the twin instead in half the cases: a row gone that writes no other row.
    named["box_twin"] = world.spawn(Transform(position=(-1.2, 0.6, 1.4), scale=BOX_SCALE), MeshRef(l_mesh()),
                                    Material(color=(0.2, 0.5, 0.9)))
    if case.reflections:  # the box reflects the sky, the screen's in its place where its rays find it
        world.add_component(named["box"], Reflective(mix=0.5))
        world.add_component(world.resources["camera"], ScreenReflections(thickness=0.5))
    if case.glass is not None:
        named["glass"] = world.spawn(Transform(position=(-0.6, 0.9, 0.8)), MeshRef(sphere(0.4, 24, 12)),
                                     Material(color=(1.0, 1.0, 1.0, 0.0), roughness=case.glass),
                                     Refractive(ior=1.5, solid=True))
        if case.glass_behind:
            named["glass_behind"] = world.spawn(
                Transform(position=(-0.7, 1.0, -0.4)), MeshRef(quad(1.2, 1.2)),
                Material(color=(0.8, 0.9, 1.0, 0.0), roughness=case.glass, double_sided=True), Refractive(ior=1.3))
    for i, pane in enumerate(case.panes):
        named[f"pane{i}"] = _spawn_pane(world, pane)
    if case.monitor is not None:   # a lens by the first of the pair watching the box, its screen out of its sight
        lens = glm.vec3(1.5, 1.8, -2.0)
        named["lens"] = world.spawn(Transform(position=lens, rotation=look_rotation(glm.vec3(0.8, 0.6, 0.0) - lens)),
                                    Camera(fov_y=50.0, active=False))
        # The camera's screen effects on the lens too (its picture's own: kept, it must equal one drawn).
        if case.occlusion:
            world.add_component(named["lens"], AmbientOcclusion(radius=0.8))
        if case.reflections:
            world.add_component(named["lens"], ScreenReflections(thickness=0.5))
        if case.fog and case.shafts:
            world.add_component(named["lens"], VolumetricFog(steps=8))
        screen = glm.vec3(-0.9, 1.5, -1.4)
        facing = look_rotation(screen - glm.vec3(0.4, 1.5, 1.2))   # (its +z, its face, to the camera)
        named["monitor"] = world.spawn(Transform(position=screen, rotation=facing),
                                       MeshRef(quad(0.8, 0.45)), Material(color=(0.0, 0.0, 0.0, 1.0)),
                                       Monitor(camera=named["lens"], size=(32, 18), depth=case.monitor,
                                               every=1 + case.still % 2,
                                               update="when_seen" if case.after % 2 else "always"))
    if case.water:
        named["water"] = _spawn_water(world, 0.3)
    if case.see_through_mirror:
        named["glass_mirror"] = _spawn_see_through_mirror(world, 0.4)
    if case.sandwich is not None:
        # A pane under a raised pond, reaching onto a far see-through mirror behind it: glass
        # between two see-through surfaces (RenderStats.glass_between_surfaces).
        named["pond"] = world.spawn(Transform(position=(-0.4, 0.6, -0.6), rotation=FLAT), MeshRef(quad(1.6, 1.6)),
                                     Material(color=(0.2, 0.3, 0.6, 0.6), normal_map=fuzz_ripples()),
                                     Mirror(reflect_rate=0.7), Water(speed=0.0))
        named["far_glass_mirror"] = world.spawn(Transform(position=(0.2, 0.9, -2.4)), MeshRef(quad(2.6, 1.6)),
                                                Material(color=(0.3, 0.3, 0.3, 0.6)),
                                                Mirror(reflect_rate=0.7, max_depth=2))
        named["pane_between"] = world.spawn(Transform(position=(0.5, 0.4, -1.2)), MeshRef(quad(1.6, 0.6)),
                                            Material(color=(0.9, 0.15, 0.1, case.sandwich)), Emissive(0.6))
    return named


def _spawn_pane(world, pane) -> int:
    position, size, rgba = pane
    return world.spawn(Transform(position=position), MeshRef(quad(size, size * 0.7)), Material(color=rgba))


def _spawn_water(world, alpha: float) -> int:
    return world.spawn(Transform(position=(-0.5, 0.05, 0.5), rotation=FLAT), MeshRef(quad(2.0, 2.0)),
                       Material(color=(0.2, 0.3, 0.4, alpha), normal_map=fuzz_ripples()), Mirror(), Water(speed=0.0))


def _spawn_see_through_mirror(world, alpha: float) -> int:
    return world.spawn(Transform(position=(-1.6, 1.2, -0.5), rotation=glm.angleAxis(math.pi / 2, glm.vec3(0, 1, 0))),
                       MeshRef(quad(1.5, 1.5)), Material(color=(0.3, 0.3, 0.35, alpha)),
                       Mirror(max_depth=2, reflect_rate=0.7))


# How many programs the keeping engine may hold as a case starts; past it both engines are
# made afresh and the context's free programs past its ``FreePrograms.keep`` (the suite's)
# are released.  Each case's scene-wide features (shadow rings, kinds of lamp, fog, the screen
# effects) make builds of their own, about 35 new a case in each engine, 3-7 MB each on
# llvmpipe: the process of ``--still-cases 60`` (seed 322, after the other parts) reached
# 13.5 GB; 24 cases alone peaked at 4.1 GB, and at 2.9 GB with this bound (two restarts,
# their builds linked again from Mesa's shader cache: 57 s, the unbounded run 33 s).
PROGRAMS_BEFORE_RESTART = 400


class StillFuzzer:
    """Two engines of ``_Base`` (one keeping still views, one drawing every frame); each case
    spawns its level in both, runs it still, changes it, runs it still again, deletes it and
    checks the resource counts came back."""

    def __init__(self, ctx) -> None:
        self.ctx = ctx
        self.keeping = _Side(ctx)
        self.drawing = _Side(ctx)
        self.drawing.engine.reflection_system.keep_still_views = False
        self.drawing.redraw_shadows = True
        self.drawing.engine.renderer.occlusion.keep_still = False  # its ambient occlusion found every frame
        self.drawing.engine.renderer.volumetric_fog.keep_still = False  # its light shafts marched every frame
        self.drawing.engine.reflection_system.tree.plan_ahead = False  # each level planned after its parent's claims
        self.drawing.engine.stages["monitors"].keep_still_pictures = False  # every due picture drawn
        for _ in range(2):
            self.keeping.frame()
            self.drawing.frame()
        self.baseline = (self.keeping.counts(), self.drawing.counts())
        self.refused = self.rendered = 0
        # Frames the keeping engine refilled, and frames that drew glass between see-through
        # surfaces, over all cases: that the paths were reached.
        self.refills = self.glass_between = 0
        self.glass_layered = 0  # ... and frames that drew glass behind glass in layers (refraction_layers)
        self.slot_cut = 0  # ... and frames with see-through things drawn in part after the glass (slot_after_glass)
        self.pictures_kept = 0  # ... and frames that kept a monitor's picture (RenderStats.monitors_kept)
        self.restarts = 0  # ... and times both engines were made afresh for the programs they held

    def close(self) -> None:
        self.keeping.close()
        self.drawing.close()

    def _frames(self, count: int, refusal: str | None = None) -> str | None:
        """``count`` frames of both engines, compared; "refused" where both refused a frame
        with a ``ComponentValueError`` naming ``refusal`` (an in-place edit, seen at the
        transform stage), else None or why the frames failed."""
        for _ in range(count):
            outcomes = []
            for side in (self.keeping, self.drawing):
                try:
                    outcomes.append(side.frame())
                except ComponentValueError as exc:
                    if refusal is None or refusal not in str(exc):
                        raise
                    outcomes.append(None)
            if outcomes[0] is None or outcomes[1] is None:
                if outcomes[0] is not None or outcomes[1] is not None:
                    return f"only one engine refused the in-place edit of {refusal}"
                return "refused"
            kept, drawn = outcomes
            for name, a, b in zip(("HDR image", "colour", "ids"), (kept[1], kept[0], kept[2]),
                                  (drawn[1], drawn[0], drawn[2]), strict=True):
                if a.shape != b.shape or not np.array_equal(a, b):
                    return f"the kept engine's {name} differs from the frame drawn whole"
            problem = hdr_problem(kept[1])
            if problem is not None:
                return problem
            stats = self.keeping.engine.renderer.stats
            self.refills += stats.reflection_end_refills > 0
            self.glass_between += stats.glass_between_surfaces > 0
            self.glass_layered += stats.refraction_layers > 1
            self.slot_cut += stats.slot_after_glass > 0
            self.pictures_kept += stats.monitors_kept > 0
        return None

    def run(self, case: StillCase, index: int = 0) -> str | None:
        if self.keeping.engine.renderer.resource_counts()["programs"] > PROGRAMS_BEFORE_RESTART:
            self._restart()
            free = FreePrograms.of(self.ctx)
            free.shrink(free.keep or 0)
            self.restarts += 1
        sides = (self.keeping, self.drawing)
        refused = False
        # With a monitor, the drawing engine keeps its shadow maps as the keeping one does.
        # Drawn whole every frame, each map's drawing moves the scene's version on, so every
        # picture drawn would be a new look of its screen (``PicturesDrawn``), which the
        # probes that see it recapture; the keeping engine publishes only a picture that
        # changed for more than the probes' own captures (``MonitorSystem``: a picture
        # showing a probe's reflection, which that probe sees, would loop).  The two then
        # differ by design wherever a probe sees a screen that shows it.
        self.drawing.redraw_shadows = case.monitor is None
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                for side in sides:
                    side.named = _spawn(side.world, case)
                    side.engine.reflection_system.visibility = case.visibility
            problem = self._frames(case.still)
            for change, detail in ((case.change, case.detail), *case.then):
                if problem is not None or refused:
                    break
                problem, refused = self._phase(dataclasses.replace(case, change=change, detail=detail))
        except Exception as exc:  # noqa: BLE001 - any exception is what the fuzz is looking for
            problem = f"raised {type(exc).__name__}: {exc}\n{traceback.format_exc(limit=-4)}"
        problem = self._undo() or problem if problem is None else problem
        if problem is None:
            if refused:
                self.refused += 1
            else:
                self.rendered += 1
        else:
            self._restart()
        return problem

    def _phase(self, case: StillCase) -> tuple[str | None, bool]:
        """The case's change in both engines, then its frames: (why it failed or None,
        whether the change was refused naming its field)."""
        sides = (self.keeping, self.drawing)
        outcome = [self._change(side, case) for side in sides]
        if outcome[0] != outcome[1]:
            return f"the two engines took the change differently: {outcome}", False
        if outcome[0] is not None:
            return (None, True) if outcome[0] == "refused" else (outcome[0], False)
        if case.change in ("keep_toggle", "camera_off"):
            problem = self._frames(case.detail["off_frames"])
            if problem is not None:
                return problem, False
            self.keeping.engine.reflection_system.keep_still_views = True
            for side in sides:
                side.world.get(side.game.camera, Camera).active = True
        in_place = {"light_in_place": "DirectionalLight", "point_in_place": "Transform"}.get(case.detail.get("target"))
        problem = self._frames(case.after, f"{in_place}.{case.detail['field']}" if in_place else None)
        return (None, True) if problem == "refused" else (problem, False)

    def _change(self, side: _Side, case: StillCase) -> str | None:
        """The case's change in one engine: None, "refused" (a ComponentValueError naming the
        field), or why it failed."""
        world, detail, change = side.world, case.detail, case.change
        if change == "resize":
            side.resize(detail["size"])
        elif change == "depth_cap":
            side.engine.reflection_system.max_depth_cap = detail["cap"]
        elif change == "min_pixels":
            side.world.resources[ViewBudget] = ViewBudget(min_pixels=detail["min"])
        elif change == "keep_toggle":
            if side is self.keeping:
                side.engine.reflection_system.keep_still_views = False
        elif change == "camera_off":
            world.get(side.game.camera, Camera).active = False
        elif change == "remove":
            target = detail["target"]
            if target == "box" and case.after % 2 == 0:   # (by the case's own numbers: the seeded cases stay)
                target = "box_twin"
            name = target if target != "pane" else next((n for n in side.named if n.startswith("pane")), None)
            if name in side.named:
                world.delete_entity(side.named.pop(name))
        elif change == "turn":
            if "box" in side.named:
                transform = world.get(side.named["box"], Transform)
                transform.rotation, transform.scale = BOX_TURNS[detail["how"]]
        elif change == "surface":
            # (a name of its own: a case may add two, and remove others between)
            add, name = detail["add"], f"added{sum(1 for other in side.named if other.startswith('added'))}"
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                if add == "water":
                    side.named[name] = _spawn_water(world, detail["alpha"])
                elif add == "mirror":
                    side.named[name] = _spawn_see_through_mirror(world, detail["alpha"])
                else:
                    side.named[name] = _spawn_pane(world, detail["pane"])
        else:
            return self._write(side, case)
        return None

    def _write(self, side: _Side, case: StillCase) -> str | None:
        world, detail = side.world, case.detail
        target = detail["target"]
        if target in ("light", "light_in_place"):
            entity = side.game.light
        elif target in ("point", "point_in_place"):
            entity = side.named.get("point")
        elif target == "pane":
            entity = next((e for n, e in side.named.items() if n.startswith("pane")), None)
        elif target == "pair":
            entity = side.named.get("first")  # (None once a change before removed it)
        else:
            entity = side.named.get(target)
        if entity is None:
            return None
        if target == "light_in_place":
            light = world.get(entity, DirectionalLight)
            vector = light.color if detail["field"] == "color" else light.direction
            vector.x = detail["value"]  # an in-place edit: checked at the transform stage
            return None
        if target == "point_in_place":
            transform = world.get(entity, Transform)
            if detail["field"] == "turn":   # aimed elsewhere (a spot's cone turns; a lamp all round is the same)
                value = detail["value"]
                turn = value if value == value and abs(value) < 10.0 else 0.5
                transform.rotation = glm.angleAxis(turn, glm.vec3(0.0, 1.0, 0.0)) * transform.rotation
                return None
            transform.position.x = detail["value"]  # the light moved, in place
            return None
        cls = {"Mirror": Mirror, "Material": Material, "Transform": Transform, "Water": Water,
               "DirectionalLight": DirectionalLight, "PointLight": PointLight, "Monitor": Monitor,
               "Camera": Camera}[detail["cls"]]
        if cls is Mirror and case.pair == "portals" and target == "pair":
            cls = Portal
        component = world.try_get(entity, cls)
        field = detail["field"]
        if component is None or not hasattr(component, field):
            return None
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                setattr(component, field, detail["value"])
        except ComponentValueError as exc:
            text = str(exc)
            if f"{cls.__name__}.{field}" in text or f"{cls.__name__} on entity" in text or "Transform.parent" in text:
                return "refused"
            return f"refused without naming {cls.__name__}.{field}: {text}"
        return None

    def _undo(self) -> str | None:
        """Delete the case's entities and put the engines' settings back; the resource counts
        must come back to the baseline."""
        for side in (self.keeping, self.drawing):
            for entity in side.named.values():
                if side.world.exists(entity):
                    side.world.delete_entity(entity)
            side.named = {}
            system = side.engine.reflection_system
            system.max_depth_cap = 8
            system.visibility = "exact"
            side.world.resources.pop(ViewBudget, None)
            if side.size != SIZE:
                side.resize(SIZE)
            light = side.world.get(side.game.light, DirectionalLight)
            side.world.add_component(side.game.light, DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=1.5,
                                                                        shadow_resolution=512))
            for post in (Bloom, Fog, AmbientOcclusion, ScreenReflections, VolumetricFog):
                side.world.remove_component(side.game.camera, post)
            del light
        self.keeping.engine.reflection_system.keep_still_views = True
        problem = self._frames(3)
        if problem is not None:
            return f"after the case's entities went: {problem}"
        for side, baseline, name in ((self.keeping, self.baseline[0], "keeping"),
                                     (self.drawing, self.baseline[1], "drawing")):
            counts = side.counts()
            if counts != baseline:
                grown = {k: (baseline.get(k), v) for k, v in counts.items() if baseline.get(k) != v}
                return f"the {name} engine's resources did not come back (baseline, now): {grown}"
        return None

    def _restart(self) -> None:
        try:
            self.close()
        except Exception:  # noqa: BLE001 - a case that broke the engine: start fresh ones
            pass
        counts = (self.refused, self.rendered, self.refills, self.glass_between, self.glass_layered, self.slot_cut,
                  self.pictures_kept, self.restarts)
        self.__init__(self.ctx)
        (self.refused, self.rendered, self.refills, self.glass_between, self.glass_layered, self.slot_cut,
         self.pictures_kept, self.restarts) = counts


def fuzz_still(ctx, cases: int, seed: int = 0, report=None) -> tuple[int, list[tuple[str, str]], dict[str, int]]:
    """Run ``cases`` still cases (``benchmarks.fuzz_cases.run_cases``)."""
    from benchmarks.fuzz_cases import run_cases

    fuzzer = StillFuzzer(ctx)
    ran, failures, passes = run_cases(fuzzer, random_still_case, cases, seed, report)
    passes["refill_frames"], passes["glass_between_frames"] = fuzzer.refills, fuzzer.glass_between
    passes["glass_layered_frames"], passes["slot_cut_frames"] = fuzzer.glass_layered, fuzzer.slot_cut
    passes["pictures_kept_frames"] = fuzzer.pictures_kept
    passes["program_restarts"] = fuzzer.restarts
    return ran, failures, passes
