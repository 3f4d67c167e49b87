"""Every GL object a component makes goes when its entity goes, when the component is taken off,
replaced by a new one or resized; and nothing the engine keeps holds on to a deleted entity's
components or assets, so churn does not grow memory.

The GL objects are counted by the driver, not by the engine's own registries: every name the
context has given out since the test began is asked ``glIsTexture``, ``glIsFramebuffer``,
``glIsBuffer``, ... (``GLNames``; Mesa gives each new object a name above every name given
before, so the names of a test's objects lie above the floor taken at its start).  A thing is
added and taken away in cycles, a few frames each at a tiny size: the first cycle may leave
what is made once and kept for all (programs, a tree's level targets, the text pass's atlas);
from the second on, each cycle must make its objects afresh (non-vacuous) and nothing it made
may outlive it, the counts flat."""
from __future__ import annotations

import ctypes
import gc
import math
import warnings
import weakref

import numpy as np
import pytest
from pyglm import glm

from components import (
    AmbientOcclusion,
    Bloom,
    Camera,
    ContactShadows,
    Decal,
    DepthOfField,
    DirectionalLight,
    FogVolume,
    IrradianceVolume,
    LevelOfDetail,
    Material,
    MeshRef,
    Mirror,
    Model,
    Monitor,
    Morph,
    MotionBlur,
    ParticleEmitter,
    PointLight,
    ReflectionProbe,
    Reflective,
    Refractive,
    Ripples,
    ScreenPanel,
    ScreenReflections,
    Skin,
    Skybox,
    Transform,
    VolumetricFog,
    Wake,
    Water,
    look_rotation,
    yaw_pitch_rotation,
)
from engine.assets.mesh import box, plane, quad, sphere
from engine.assets.portals import spawn_portal_pair
from engine.assets.texture_data import TextureData
from engine.resources import Surfaces
from tests.support import own_mesh
from tests.test_model_placement import textured_box
from tests.test_morph_targets import morphed_sheet
from tests.test_skinning import elbow_matrix, skinned_bar

SIZE = (32, 24)
KINDS = ("Texture", "Framebuffer", "Renderbuffer", "Buffer", "VertexArray", "Program", "Sampler", "Query")
# Kept on the context for the next engine by design (engine/render/context_kept.py): the released
# samples queries, a pool that grows to the most a frame has used.
POOLED = ("Query",)
FLAT = yaw_pitch_rotation(0.0, -90.0)
DOWN = look_rotation((0.0, -1.0, 0.0), (0.0, 0.0, -1.0))


class GLNames:
    """The live GL objects of the current context by kind, as the driver answers ``glIs*`` for
    every name above ``floor`` (the names given out before this was made) up to the next name
    it would give."""

    def __init__(self, ctx) -> None:
        load = ctx.mglo._context.load_opengl_function
        is_ = ctypes.CFUNCTYPE(ctypes.c_ubyte, ctypes.c_uint)
        gen = ctypes.CFUNCTYPE(None, ctypes.c_int, ctypes.POINTER(ctypes.c_uint))
        self._is = {kind: is_(load(f"glIs{kind}")) for kind in KINDS}
        self._gen = {kind: (gen(load(f"glGen{kind}s")), gen(load(f"glDelete{kind}s"))) for kind in KINDS
                     if kind != "Program"}
        self._program = (ctypes.CFUNCTYPE(ctypes.c_uint)(load("glCreateProgram")),
                         ctypes.CFUNCTYPE(None, ctypes.c_uint)(load("glDeleteProgram")))
        self.floor = {kind: self._next(kind) for kind in KINDS}
        # Names are read as a rising count (Mesa's way); a driver that gives a deleted name out
        # again (some GPU drivers) leaves nothing to count by: the sweep skips there, saying so.
        reused = [kind for kind in KINDS if kind not in POOLED and self._next(kind) <= self.floor[kind]]
        if reused:
            pytest.skip(f"this driver gives deleted GL names out again ({', '.join(reused)}): the sweep "
                        "counts names as they rise")
        self.floor = {kind: self._next(kind) for kind in KINDS}

    def _next(self, kind: str) -> int:
        if kind == "Program":
            name = self._program[0]()
            self._program[1](name)
            return name
        name = ctypes.c_uint(0)
        make, delete = self._gen[kind]
        make(1, ctypes.byref(name))
        delete(1, ctypes.byref(name))
        return name.value

    def __call__(self) -> dict[str, frozenset[int]]:
        return {kind: frozenset(n for n in range(self.floor[kind], self._next(kind)) if self._is[kind](n))
                for kind in KINDS}


def counts(names) -> dict[str, int]:
    return {kind: len(names[kind]) for kind in KINDS}


def stage(world):
    world.spawn(Transform(position=(0.0, 1.5, 4.0), rotation=look_rotation(glm.vec3(0.0, -0.3, -1.0))),
                Camera(fov_y=60.0))
    world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.4), shadow_resolution=64))
    world.spawn(Transform(), MeshRef(plane(10.0, 10.0)), Material(color=(0.6, 0.6, 0.6, 1.0)))


def image(name: str, value: int = 100) -> TextureData:
    return TextureData(np.full((4, 4, 4), value, np.uint8), name=name)


def own(mesh, n: int):
    """``mesh``'s vertices as a mesh of its own, named for cycle ``n`` (its own batch and buffers)."""
    made = own_mesh(mesh)
    made.name = f"{mesh.name} {n}"
    return made


def camera_of(world) -> int:
    return next(entity for entity, camera in world.query_one(Camera) if camera.active)


def lens(world) -> int:
    return world.spawn(Transform(position=(0.0, 1.0, 3.0)), Camera(fov_y=50.0, active=False))


def skinned(n: int):
    mesh = skinned_bar()
    mesh.name = f"arm {n}"
    return mesh


def model_file(tmp_path_factory):
    return str(textured_box(tmp_path_factory.mktemp("crate") / "crate.glb"))


# Each kind: what it spawns in cycle n (its entities), and the GL objects each cycle must make.
SPAWNS = {
    "mirror": (lambda w, n, _: [w.spawn(Transform(position=(0.0, 1.0, -1.0)), MeshRef(own(quad(2.0, 1.5), n)),
                                        Material(), Mirror())], {"Buffer", "VertexArray"}),
    "portal pair": (lambda w, n, _: list(spawn_portal_pair(w, (-1.0, 1.0, -1.0), None, (1.0, 1.0, -1.0),
                                                           look_rotation((0.0, 0.0, 1.0)), size=(1.0, 1.4),
                                                           max_depth=1)), {"Buffer", "VertexArray"}),
    "probe": (lambda w, n, _: [w.spawn(Transform(position=(0.0, 1.0, 0.0)), MeshRef(own(sphere(0.4, 8, 4), n)),
                                       Material(metallic=1.0, roughness=0.1), Reflective("cube"),
                                       ReflectionProbe(resolution=16))], {"Texture", "Framebuffer"}),
    "probe with a tree": (lambda w, n, _: [
        w.spawn(Transform(position=(0.0, 1.0, 0.0)), MeshRef(own(sphere(0.4, 8, 4), n)),
                Material(metallic=1.0, roughness=0.1), Reflective("cube"), ReflectionProbe(resolution=16, depth=2)),
        w.spawn(Transform(position=(0.0, 1.0, -1.5)), MeshRef(own(quad(2.0, 1.5), n)), Material(), Mirror())],
        {"Texture", "Framebuffer"}),
    "monitor with screen effects": (lambda w, n, _: [
        w.spawn(Transform(position=(0.0, 1.0, 0.0)), MeshRef(own(quad(1.0, 0.6), n)), Material(),
                Monitor(camera=(camera := w.spawn(Transform(position=(0.0, 1.0, 3.0)),
                                                  Camera(fov_y=50.0, active=False), AmbientOcclusion(),
                                                  ContactShadows(), ScreenReflections(), VolumetricFog())),
                        size=(16, 8))),
        camera], {"Texture", "Framebuffer"}),
    "panel monitor": (lambda w, n, _: [w.spawn(ScreenPanel(size=(16, 8)), Monitor(camera=(c := lens(w)), size=(16, 8))),
                                       c], {"Texture", "Framebuffer"}),
    "particles": (lambda w, n, _: [
        w.spawn(Transform(position=(0.0, 1.0, 0.0)), ParticleEmitter(
            rate=60.0, lifetime=(0.01, 0.02), max_particles=32, texture=image(f"sprite {n}"), lit=True,
            on_death=(child := w.spawn(Transform(position=(0.0, 1.0, 0.0)), ParticleEmitter(
                rate=0.0, burst=3, playing=False, max_particles=32, ribbon=True))))), child],
        {"Texture", "Buffer", "VertexArray"}),
    "decal": (lambda w, n, _: [w.spawn(Transform(rotation=DOWN), Decal(texture=image(f"decal {n}"),
                                                                       normal_map=image(f"bumps {n}", 128)))],
              {"Texture", "Buffer", "VertexArray"}),
    "fog volume and lamp": (lambda w, n, _: [
        w.spawn(Transform(position=(0.0, 1.0, 0.0)), FogVolume(size=(2.0, 2.0, 2.0))),
        w.spawn(Transform(position=(1.0, 2.0, 1.0)), PointLight(intensity=3.0, range=6.0, shadows=True,
                                                                shadow_resolution=64))],
        {"Texture", "Framebuffer"}),
    "spot with a cookie": (lambda w, n, _: [w.spawn(Transform(position=(0.0, 3.0, 0.0), rotation=DOWN), PointLight(
        intensity=3.0, range=6.0, spot_angle=40.0, shadows=True, shadow_resolution=64, cookie=image(f"cookie {n}")))],
        {"Texture", "Framebuffer"}),
    "rectangle light": (lambda w, n, _: [w.spawn(Transform(position=(0.0, 2.0, 0.0), rotation=DOWN), PointLight(
        intensity=3.0, range=6.0, rectangle=(1.0, 0.5), shadows=True, shadow_resolution=64))],
        {"Texture", "Framebuffer"}),
    "irradiance volume": (lambda w, n, _: [w.spawn(Transform(position=(0.0, 1.0, 0.0)), IrradianceVolume(
        size=(4.0, 2.0, 4.0), points=(2, 2, 2), resolution=16, points_per_frame=8))], {"Texture", "Framebuffer"}),
    "water": (lambda w, n, _: [w.spawn(
        Transform(position=(0.0, 0.05, 0.0), rotation=FLAT), MeshRef(own(quad(2.0, 2.0), n)),
        Material(color=(0.1, 0.3, 0.3, 0.3), normal_map=image(f"waves {n}", 128)), Mirror(),
        Water(caustics=1.0, foam=1.0, fog_density=0.5))], {"Texture", "Framebuffer", "Buffer"}),
    "ripples": (lambda w, n, _: [w.spawn(
        Transform(position=(0.0, 0.05, 0.0), rotation=FLAT), MeshRef(own(quad(2.0, 2.0), n)),
        Material(color=(0.1, 0.3, 0.3, 0.3)), Mirror(), Water(), Ripples())], {"Texture", "Framebuffer"}),
    "material maps": (lambda w, n, _: [w.spawn(
        Transform(position=(0.0, 0.5, 0.0)), MeshRef(own(box((0.5, 0.5, 0.5)), n)),
        Material(texture=image(f"colour {n}"), lightmap=image(f"light {n}"), occlusion_map=image(f"occlusion {n}"),
                 emissive_map=image(f"glow {n}")))], {"Texture", "Buffer", "VertexArray"}),
    "refracting glass": (lambda w, n, _: [w.spawn(Transform(position=(0.0, 1.0, 0.0)), MeshRef(own(quad(1.0, 1.0), n)),
                                                  Material(color=(1.0, 1.0, 1.0, 0.2)), Refractive())],
                         {"Texture", "Framebuffer"}),
    "skin": (lambda w, n, _: [w.spawn(Transform(), MeshRef(skinned(n)), Material(),
                                      Skin(np.stack([np.eye(4), elbow_matrix(math.pi / 2)])))], {"Texture", "Buffer"}),
    "morph": (lambda w, n, _: [w.spawn(Transform(position=(0.0, 1.0, 0.0)), MeshRef(morphed_sheet()), Material(),
                                       Morph((0.8, 0.6)))], {"Texture", "Buffer"}),
    "level of detail": (lambda w, n, _: [w.spawn(
        Transform(position=(0.0, 0.5, 0.0)), MeshRef(own(box((1.0, 1.0, 1.0)), n)), Material(),
        LevelOfDetail(meshes=(own(box((1.0, 1.0, 1.0)), n), own(sphere(0.5, 6, 3), n)), distances=(3.0,)))],
        {"Buffer", "VertexArray"}),
    "model": (lambda w, n, file: [w.spawn(Transform(), Model(file=file))], {"Texture", "Buffer", "VertexArray"}),
    "sky": (lambda w, n, _: [w.spawn(Skybox(faces=[np.full((8, 8, 3), 0.1 * (n + 1), np.float32)] * 6))],
            {"Texture"}),
    "atmosphere": (lambda w, n, _: [w.spawn(Skybox(model="atmosphere"))], {"Texture", "Framebuffer"}),
}


def cycles(runner, names, spawn, undo, count=3, frames=2):
    """``count`` cycles of ``spawn(world, n)`` drawn ``frames`` frames then ``undo(world, made)``
    and drawn twice: (what each cycle made while its thing was there, what of it outlived
    the undo, the names after the undo)."""
    world = runner.world
    before = names()
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # (a water's caustics with no waves, a monitor's effects: said once)
        for n in range(count):
            made = spawn(world, n)
            for _ in range(frames):
                runner.frame()
            held = names()
            undo(world, made)
            runner.frame()
            runner.frame()
            after = names()
            new = {kind: held[kind] - before[kind] for kind in KINDS}
            rows.append((new, {kind: new[kind] & after[kind] for kind in KINDS}, after))
            before = after
    return rows


def delete_all(world, made) -> None:
    for entity in made:
        if world.exists(entity):
            world.delete_entity(entity)


def assert_all_given_back(rows, makes, label) -> None:
    for n, (new, outlived, after) in enumerate(rows):
        made = {kind for kind in KINDS if new[kind]}
        assert makes <= made, f"{label}, cycle {n}: made {counts(new)}, not all of {sorted(makes)}"
        if n == 0:
            continue
        kept = {kind: sorted(outlived[kind]) for kind in KINDS if outlived[kind] and kind not in POOLED}
        assert kept == {}, f"{label}, cycle {n}: GL objects made for it outlived it: {kept}"
        grown = {kind: (len(rows[n - 1][2][kind]), len(after[kind])) for kind in KINDS
                 if kind not in POOLED and len(after[kind]) != len(rows[n - 1][2][kind])}
        assert grown == {}, f"{label}, cycle {n}: live GL objects (before, after) changed: {grown}"


@pytest.mark.parametrize("kind", list(SPAWNS))
def test_every_kind_that_makes_gl_objects_gives_them_all_back_when_its_entity_goes(scene, ctx, kind,
                                                                                   tmp_path_factory):
    """Spawned (with meshes and images of its own each time), drawn, deleted, three times: the
    driver's live objects of every kind made for it are gone again after each deletion, and
    from the second time on the live counts stand still."""
    names = GLNames(ctx)
    runner = scene(stage, SIZE)
    runner.frame()
    spawn, makes = SPAWNS[kind]
    file = model_file(tmp_path_factory) if kind == "model" else None
    rows = cycles(runner, names, lambda w, n: spawn(w, n, file), delete_all)
    assert_all_given_back(rows, makes, kind)


def _screen(w):
    return w.spawn(Transform(position=(0.0, 1.0, 0.0)), MeshRef(quad(1.0, 0.6)), Material())


# Each: the entity spawned once (without the component), the component(s) put on it each cycle
# and taken off again, and what each cycle must make.
TAKEN_OFF = {
    "Monitor": (_screen, lambda w, e: [Monitor(camera=lens(w), size=(16, 8))], {"Texture", "Framebuffer"}),
    "ReflectionProbe": (lambda w: w.spawn(Transform(position=(0.0, 1.0, 0.0)), MeshRef(sphere(0.4, 8, 4)),
                                          Material(metallic=1.0, roughness=0.1), Reflective("cube")),
                        lambda w, e: [ReflectionProbe(resolution=16)], {"Texture", "Framebuffer"}),
    "Ripples": (lambda w: w.spawn(Transform(position=(0.0, 0.05, 0.0), rotation=FLAT), MeshRef(quad(2.0, 2.0)),
                                  Material(color=(0.1, 0.3, 0.3, 0.3)), Mirror(), Water()),
                lambda w, e: [Ripples()], {"Texture", "Framebuffer"}),
    "ParticleEmitter": (lambda w: w.spawn(Transform(position=(0.0, 1.0, 0.0))),
                        lambda w, e: [ParticleEmitter(rate=60.0, max_particles=32, texture=image("sprite"))],
                        {"Texture", "Buffer"}),
    "camera's lens and post": (camera_of, lambda w, e: [Bloom(), DepthOfField(), MotionBlur()],
                               {"Texture", "Framebuffer"}),
    "camera's screen effects": (camera_of, lambda w, e: [AmbientOcclusion(), ContactShadows(), ScreenReflections(),
                                                         VolumetricFog()], {"Texture", "Framebuffer"}),
}


@pytest.mark.filterwarnings("ignore")
@pytest.mark.parametrize("kind", list(TAKEN_OFF))
def test_a_component_taken_off_its_entity_gives_back_what_it_made(scene, ctx, kind):
    """The entity stays; its component is put on, drawn with and taken off three times: what it
    made goes with it each time (its monitor's camera deleted with it), the counts flat."""
    names = GLNames(ctx)
    runner = scene(stage, SIZE)
    make_entity, components, makes = TAKEN_OFF[kind]
    entity = make_entity(runner.world)
    runner.frame()
    runner.frame()

    def put_on(world, n):
        added = components(world, entity)
        for component in added:
            world.add_component(entity, component)
        return added

    def take_off(world, added):
        for component in added:
            world.remove_component(entity, type(component))
            if isinstance(component, Monitor):
                world.delete_entity(component.camera)

    assert_all_given_back(cycles(runner, names, put_on, take_off), makes, kind)


def _field(kind, name, values):
    def change(world, entity, n):
        setattr(world.get(entity, kind), name, values[n % len(values)])
    return change


def _replace(make):
    def change(world, entity, n):
        world.add_component(entity, make(world, entity, n))
    return change


# Each: what is spawned once, the change made each cycle, and what each change must make anew.
CHANGED = {
    "probe resolution": ("probe", _field(ReflectionProbe, "resolution", [32, 16]), {"Texture", "Framebuffer"}),
    "probe replaced": ("probe", _replace(lambda w, e, n: ReflectionProbe(resolution=(32, 16)[n % 2])),
                       {"Texture", "Framebuffer"}),
    "monitor size": ("panel monitor", _field(Monitor, "size", [(24, 12), (16, 8)]), {"Texture", "Framebuffer"}),
    "monitor replaced": ("panel monitor", _replace(lambda w, e, n: Monitor(camera=w.get(e, Monitor).camera,
                                                                            size=((24, 12), (16, 8))[n % 2])),
                         {"Texture", "Framebuffer"}),
    "lamp shadow resolution": ("fog volume and lamp", None, {"Texture", "Framebuffer"}),
    "volume resolution": ("irradiance volume", _field(IrradianceVolume, "resolution", [32, 16]),
                          {"Texture", "Framebuffer"}),
    "emitter replaced": ("particles", _replace(lambda w, e, n: ParticleEmitter(
        rate=60.0, max_particles=32, texture=image(f"new sprite {n}", n))), {"Texture"}),
    "emitter grown": ("particles", None, {"Buffer"}),
    "decal replaced": ("decal", _replace(lambda w, e, n: Decal(texture=image(f"new decal {n}", n))),
                       {"Texture", "Buffer"}),
    "material replaced": ("material maps", _replace(lambda w, e, n: Material(
        texture=image(f"new colour {n}", n), lightmap=image(f"new light {n}", n))), {"Texture"}),
}


@pytest.mark.filterwarnings("ignore")
@pytest.mark.parametrize("change", list(CHANGED))
def test_a_component_replaced_or_resized_gives_back_what_the_old_one_had(scene, ctx, change):
    """Spawned once; then each cycle a field that sizes a GL resource is changed (or a new
    component put over the old with world.add_component): each change makes its resources
    anew and gives back the old ones, as many as it made, from the second change on."""
    names = GLNames(ctx)
    runner = scene(stage, SIZE)
    spawn_kind, mutate, makes = CHANGED[change]
    made = SPAWNS[spawn_kind][0](runner.world, 0, None)
    entity = made[0]
    if change == "lamp shadow resolution":
        entity = made[1]
        mutate = _field(PointLight, "shadow_resolution", [128, 64])
    if change == "emitter grown":   # (more live particles each time: its rows' buffer made bigger)
        emitter = runner.world.get(entity, ParticleEmitter)
        emitter.lifetime, emitter.rate, emitter.on_death = (5.0, 5.0), 6000.0, None

        def mutate(world, entity, n):
            world.get(entity, ParticleEmitter).max_particles = 64 * 4 ** (n + 1)
    runner.frame()
    runner.frame()
    before = names()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for n in range(3):
            mutate(runner.world, entity, n)
            runner.frame()
            runner.frame()
            after = names()
            new = {kind: after[kind] - before[kind] for kind in KINDS}
            gone = {kind: before[kind] - after[kind] for kind in KINDS}
            assert makes <= {kind for kind in KINDS if new[kind]}, f"{change}, change {n}: made {counts(new)}"
            if n > 0:
                assert counts(new) == counts(gone), f"{change}, change {n}: made {counts(new)}, gone {counts(gone)}"
            before = after


# (A wave's kinds: those with meshes, images and surfaces of their own; the lights are left out,
# whose every combination links the scene's programs again, minutes on llvmpipe.)
WAVE = ("mirror", "probe", "level of detail", "water", "decal", "particles", "model", "skin",
        "monitor with screen effects")


def test_nothing_the_engine_keeps_holds_a_deleted_entitys_components_or_assets(scene, ctx, tmp_path_factory):
    """A wave of things spawned, drawn and deleted, three times: once the garbage is collected,
    not one of the first two waves' components, meshes or images is alive (each is watched by
    a weak reference; a pass may keep what it drew last until it draws again, so the last wave
    is not judged), so a long run that makes and deletes things holds no more memory.  Found
    held before: every LevelOfDetail's finest mesh (the detail stage, for good), up to 4096
    meshes (the probes' scheduler) and 64 waters' surface states with their normal maps (the
    caustics' reach boxes)."""
    runner = scene(stage, SIZE)
    runner.frame()
    file = model_file(tmp_path_factory)
    watched = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for n in range(3):
            made = [entity for kind in WAVE for entity in SPAWNS[kind][0](runner.world, n, file)]
            runner.frame()
            runner.frame()
            watched += _watch(runner.world, made, f"wave {n}") if n < 2 else []
            delete_all(runner.world, made)
            runner.frame()
            runner.frame()
    gc.collect()
    assert len(watched) > 40
    assert [label for label, ref in watched if ref() is not None] == []


def _watch(world, entities, label):
    """A weak reference to each component of ``entities`` and each mesh and image they name."""
    watched = []
    for entity in entities:
        for component in world.components_of(entity):
            kind = type(component).__name__
            watched.append((f"{label}: {kind}", weakref.ref(component)))
            for name, value in vars(component).items():
                for asset in value if isinstance(value, (tuple, list)) else (value,):
                    if type(asset).__name__ in ("Mesh", "TextureData"):
                        watched.append((f"{label}: {kind}.{name}", weakref.ref(asset)))
    return watched


def _warned_water(world) -> int:
    """A water said to once by the prepare and ripple stages: caustics with no waves (no
    normal map), a fog under an outline it has not (a box, its plane given) and ripples
    on it (no outline to ripple in)."""
    return world.spawn(Transform(position=(0.0, 0.5, 0.0)), MeshRef(box((1.0, 1.0, 1.0))),
                       Material(color=(0.1, 0.3, 0.3, 0.3)),
                       Mirror(plane_point=(0.0, 0.5, 0.0), plane_normal=(0.0, 1.0, 0.0)),
                       Water(caustics=1.0, fog_density=0.5), Ripples())


def _rainy_water(world) -> int:
    """A flat water that ripples in the rain (the ripple stage keeps the drop it owes)."""
    return world.spawn(Transform(position=(0.0, 0.05, 0.0), rotation=FLAT), MeshRef(quad(2.0, 2.0)),
                       Material(color=(0.1, 0.3, 0.3, 0.3)), Mirror(), Water(), Ripples(rain=7.0))


def _said_of(engine) -> dict[str, set[int]]:
    """The entities each stage's said-once (and owed) state names."""
    prepare, ripples = engine.stages["prepare"], engine.stages["ripples"]
    return {"caustics with no waves": set(prepare._caustic_still), "fog with no outline": set(prepare._unboxed),
            "ripples said": {entity for _, entity in ripples._said}, "rain owed": set(ripples._owed)}


class _LateDeleter:
    """A system run after the ripple stage that deletes what it is given, in the frame (after
    the stages before it read ``World.deleted``)."""

    def __init__(self, world) -> None:
        self.world = world
        self.due: list[int] = []

    def process(self, dt: float) -> None:
        for entity in self.due:
            self.world.delete_entity(entity)
        self.due = []


def test_what_is_said_once_of_an_entity_is_let_go_when_the_entity_is_deleted(scene):
    """Warned waters (caustics with no waves, a fog and ripples with no outline), wakes with
    no Transform and a water owed rain, spawned, drawn and deleted in rounds beside a water
    that ripples throughout: each round's are warned about anew (a world never gives an id
    twice, so each is a new entity), and once they are deleted the prepare and ripple stages
    hold none of their ids, so a long run's warnings hold no more memory.  Deleted by a
    system after those stages, in the frame (round 1), they are let go when the next one is
    said to (round 2)."""
    runner = scene(stage, SIZE)
    world = runner.world
    engine = runner.engine
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # (its want of waves: said at its spawn)
        keeper = _rainy_water(world)
        runner.frame()
    late = _LateDeleter(world)
    ripple_priority = next(len(engine.schedule) - i for i, (name, _) in enumerate(engine.schedule) if name == "ripples")
    world.add_system(late, priority=ripple_priority - 0.5)
    seen: set[int] = set()
    for n in range(3):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            waters = [_warned_water(world) for _ in range(2)]
            wakes = [world.spawn(Wake(radius=0.2)) for _ in range(2)]
            made = [*waters, *wakes, _rainy_water(world)]
            runner.frame()
            runner.frame()
        assert min(made) > max(seen | {keeper}), f"round {n}: ids {made} given before ({sorted(seen)})"
        seen |= set(made)
        said = [str(w.message) for w in caught]
        for water in waters:
            for what in ("Water on entity {}: its caustics", "Water on entity {}: its fog_density",
                         "Ripples on entity {}: its water's mesh is not one flat quad"):
                assert sum(what.format(water) in s for s in said) == 1, f"round {n}: {what.format(water)} in {said}"
        for wake in wakes:
            assert sum(f"Wake on entity {wake}: it has no Transform" in s for s in said) == 1, said
        held = _said_of(engine)
        assert held["rain owed"] == {keeper, made[-1]} and set(waters) <= held["caustics with no waves"]
        if n == 1:
            late.due = made   # (deleted after the prepare and ripple stages read World.deleted)
        else:
            delete_all(world, made)
        runner.frame()
        runner.frame()
        assert not any(world.exists(entity) for entity in made)
        if n != 1:
            assert {what: ids & seen for what, ids in _said_of(engine).items()} == \
                {"caustics with no waves": set(), "fog with no outline": set(), "ripples said": set(),
                 "rain owed": set()}, f"round {n}"


def test_the_reflection_fallbacks_hold_nothing_of_surfaces_deleted_once_the_level_has_none(scene):
    """A bumpy mirror and a water, each with no view of its own (``max_depth=0``: a fallback
    shows the probe's reflection in them), drawn, then deleted with the probe: once the
    garbage is collected no normal map, surface state or component of theirs is alive
    (weak references), though no fallback is drawn again to replace what the last ones
    were packed from."""
    runner = scene(stage, SIZE)
    world = runner.world
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        made = [world.spawn(Transform(position=(0.0, 1.0, -1.0)), MeshRef(quad(2.0, 1.5)),
                            Material(normal_map=image("mirror bumps", 128)), Mirror(max_depth=0)),
                world.spawn(Transform(position=(0.0, 0.05, 0.0), rotation=FLAT), MeshRef(quad(2.0, 2.0)),
                            Material(color=(0.1, 0.3, 0.3, 0.3), normal_map=image("waves", 128)),
                            Mirror(max_depth=0), Water()),
                world.spawn(Transform(position=(0.0, 1.0, 0.0)), ReflectionProbe(resolution=16,
                                                                                 influence=(8.0, 8.0, 8.0)))]
        runner.frame()
        runner.frame()
    assert runner.stats.reflection_fallbacks >= 2
    states = world.resources[Surfaces].mirrors
    watched = _watch(world, made, "level") + [(f"state of {e}", weakref.ref(states[e])) for e in made[:2]]
    del states
    delete_all(world, made)
    runner.frame()
    runner.frame()
    assert runner.stats.reflection_fallbacks == 0
    gc.collect()
    alive = [label for label, ref in watched if ref() is not None]
    assert alive == [], alive
