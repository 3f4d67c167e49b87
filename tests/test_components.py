"""Component values are checked where they are written, and writes are tracked by the world."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    ComponentValueError,
    DirectionalLight,
    Emissive,
    FlyController,
    Material,
    MeshRef,
    Mirror,
    ParticleEmitter,
    PointLight,
    Portal,
    Reflective,
    Refractive,
    Skybox,
    Slice,
    TimeOfDay,
    Transform,
    Visibility,
    Water,
)
from engine.assets.mesh import box
from engine.core.world import World

NAN = float("nan")
INF = float("inf")


@pytest.fixture
def world():
    w = World("test")
    try:
        yield w
    finally:
        w.close()


# --- bad values at construction ------------------------------------------------------------

BAD_CONSTRUCTIONS = [
    # (class, kwargs, field the message must name)
    (Transform, {"scale": (1.0, 0.0, 1.0)}, "scale"),
    (Transform, {"scale": 0}, "scale"),
    (Transform, {"position": (NAN, 0.0, 0.0)}, "position"),
    (Transform, {"position": (0.0, INF, 0.0)}, "position"),
    (Transform, {"position": (1.0, 2.0)}, "position"),
    (Transform, {"position": "abc"}, "position"),
    (Transform, {"rotation": glm.quat(NAN, 0.0, 0.0, 0.0)}, "rotation"),
    (Transform, {"rotation": glm.quat(0.0, 0.0, 0.0, 0.0)}, "rotation"),
    (Transform, {"rotation": "abc"}, "rotation"),
    (Transform, {"parent": -3}, "parent"),
    (Transform, {"parent": 1.5}, "parent"),
    (Transform, {"parent": True}, "parent"),
    (Material, {"roughness": 2.0}, "roughness"),
    (Material, {"roughness": NAN}, "roughness"),
    (Material, {"metallic": -0.1}, "metallic"),
    (Material, {"metallic": "0.5"}, "metallic"),
    (Material, {"metallic": True}, "metallic"),
    (Material, {"color": (NAN, 0.5, 0.5)}, "color"),
    (Material, {"color": (0.5, INF, 0.5)}, "color"),
    (Material, {"color": (-0.5, 0.5, 0.5)}, "color"),
    (Material, {"color": (0.5, 0.5, 0.5, 1.5)}, "color"),
    (Material, {"color": (0.5, 0.5)}, "color"),
    (Material, {"color": "123"}, "color"),
    (Material, {"color": 0.5}, "color"),
    (Material, {"texture": np.zeros((2, 2, 4), np.uint8)}, "texture"),
    (Emissive, {"power": -1.0}, "power"),
    (Emissive, {"power": NAN}, "power"),
    (Emissive, {"power": INF}, "power"),
    (Emissive, {"power": None}, "power"),
    (Emissive, {"power": "2"}, "power"),
    (Camera, {"fov_y": 0.0}, "fov_y"),
    (Camera, {"fov_y": 180.0}, "fov_y"),
    (Camera, {"fov_y": NAN}, "fov_y"),
    (Camera, {"near": 0.0}, "near"),
    (Camera, {"near": -1.0}, "near"),
    (Camera, {"near": 10.0, "far": 1.0}, "far"),
    (Camera, {"near": 1.0, "far": 1.0}, "far"),
    (Camera, {"far": INF}, "far"),
    (Camera, {"active": "yes"}, "active"),
    (PointLight, {"range": 0.0}, "range"),
    (PointLight, {"range": -2.0}, "range"),
    (PointLight, {"intensity": -1.0}, "intensity"),
    (PointLight, {"color": (1.0, NAN, 1.0)}, "color"),
    (DirectionalLight, {"direction": (0.0, 0.0, 0.0)}, "direction"),
    (DirectionalLight, {"intensity": NAN}, "intensity"),
    (Reflective, {"mode": "bogus"}, "mode"),
    (Reflective, {"mode": ["skybox"]}, "mode"),
    (Reflective, {"mix": 1.5}, "mix"),
    (Reflective, {"tint": (1.0, -1.0, 1.0)}, "tint"),
    (Refractive, {"ior": 0.5}, "ior"),
    (Refractive, {"ior": NAN}, "ior"),
    (Skybox, {"face_size": 0}, "face_size"),
    (Skybox, {"face_size": 3}, "face_size"),
    (Skybox, {"face_size": 4096}, "face_size"),
    (Skybox, {"face_size": 64.0}, "face_size"),
    (Skybox, {"face_size": True}, "face_size"),
    (Skybox, {"sun_direction": (0.0, 0.0, 0.0)}, "sun_direction"),
    (Skybox, {"zenith": (NAN, 0.0, 0.0)}, "zenith"),
    (Skybox, {"faces": [1, 2]}, "faces"),
    (Skybox, {"faces": np.zeros((6, 8, 4, 3), np.float32)}, "faces"),
    (Skybox, {"faces": np.full((6, 4, 4, 3), NAN, np.float32)}, "faces"),
    (Skybox, {"faces": np.full((6, 4, 4, 3), -1.0, np.float32)}, "faces"),
    (FlyController, {"speed": -1.0}, "speed"),
    (FlyController, {"yaw": NAN}, "yaw"),
    (MeshRef, {"mesh": None}, "mesh"),
    (MeshRef, {"mesh": "box.obj"}, "mesh"),
    # Three numbers are three: glm.vec3 took four (a glm.vec4 among them) and dropped the last.
    (Transform, {"position": (1.0, 2.0, 3.0, 4.0)}, "position"),
    (Transform, {"position": glm.vec4(1.0, 2.0, 3.0, 1.0)}, "position"),
    (Transform, {"scale": (2.0, 2.0, 2.0, 0.0)}, "scale"),
    (DirectionalLight, {"direction": (0.0, -1.0, 0.0, 9.0)}, "direction"),
    (Water, {"absorption": (1.0, 1.0, 1.0, 1.0)}, "absorption"),
    (Material, {"sheen_color": (1.0, 1.0, 1.0, 1.0)}, "sheen_color"),
    # One number is no direction (it was read as (n, n, n): a diagonal nobody meant).
    (DirectionalLight, {"direction": 5.0}, "direction"),
    (Mirror, {"plane_normal": -1.0}, "plane_normal"),
    (Skybox, {"sun_direction": 1.0}, "sun_direction"),
    (ParticleEmitter, {"direction": 1.0}, "direction"),
    (TimeOfDay, {"north": 1.0}, "north"),
    # Pitch past straight up or down (the fly system held it to 89 at the first mouse move).
    (FlyController, {"pitch": 90.5}, "pitch"),
    (FlyController, {"pitch": -120.0}, "pitch"),
    # A particle born, or a floor, further out than any Transform may stand.
    (ParticleEmitter, {"extent": (1e30, 1.0, 1.0)}, "extent"),
    (ParticleEmitter, {"ground": 3.4e38}, "ground"),
    (ParticleEmitter, {"ground": -2e9}, "ground"),
    # numpy values that raised numpy's own TypeError or ValueError (no class, no field named).
    (Mirror, {"shows_layers": np.array(1)}, "shows_layers"),
    (Visibility, {"layers": np.array(3)}, "layers"),
    (Mirror, {"end_image": np.array([1.0, 2.0])}, "end_image"),
    (Portal, {"partner": np.array([1, 2])}, "partner"),
    (Material, {"second_uv_maps": np.zeros((1, 3))}, "second_uv_maps"),
]


def _case_id(case) -> str:
    cls, kwargs, _ = case
    def show(v):
        return f"array{v.shape}" if isinstance(v, np.ndarray) else repr(v)[:24]

    return f"{cls.__name__}-" + "-".join(f"{k}={show(v)}" for k, v in kwargs.items())


@pytest.mark.parametrize("cls, kwargs, field", BAD_CONSTRUCTIONS, ids=[_case_id(c) for c in BAD_CONSTRUCTIONS])
def test_bad_value_at_construction_names_class_and_field(cls, kwargs, field):
    if cls is MeshRef:
        kwargs = {"mesh": kwargs["mesh"]}
    with pytest.raises(ComponentValueError, match=rf"\b{cls.__name__}\.{field}\b"):
        cls(**kwargs)


def test_a_bad_component_value_in_a_level_stops_the_runner_with_one_line(tmp_path):
    """What a user sees of a ComponentValueError raised while a level builds: one line naming
    the class and the field, exit status 2, no traceback, and no frame written."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    level = tmp_path / "rough_level.py"
    level.write_text(
        "from components import Material, MeshRef, Transform\n"
        "from engine import Game, spawn_camera\nfrom shell import run\n"
        "from engine.assets.mesh import box\n"
        "class Rough(Game):\n"
        "    def build(self, world):\n"
        "        spawn_camera(world)\n"
        "        world.spawn(Transform(), MeshRef(box()), Material(roughness=2.0))\n"
        "run(Rough())\n")
    out = tmp_path / "frames"
    result = subprocess.run([sys.executable, str(level), "--headless", "--frames", "1", "--size", "32x32",
                             "--out", str(out)], cwd=root, env={**os.environ, "PYTHONPATH": str(root)},
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("speculum: error: Material.roughness"), result.stderr
    assert not list(out.glob("*.png"))


# --- bad values assigned later --------------------------------------------------------------

BAD_ASSIGNMENTS = [
    (Transform, "scale", (0.0, 1.0, 1.0)),
    (Transform, "position", (NAN, 0.0, 0.0)),
    (Transform, "rotation", glm.quat(0.0, 0.0, 0.0, 0.0)),
    # glm values take Transform's inline checks (its __setattr__): refused the same way.
    (Transform, "position", glm.vec3(NAN, 0.0, 0.0)),
    (Transform, "position", glm.vec3(0.0, 0.0, -INF)),
    (Transform, "position", glm.vec3(0.0, 2e9, 0.0)),     # past POSITION_MAX
    (Transform, "rotation", glm.quat(NAN, 0.0, 0.0, 0.0)),
    (Transform, "rotation", glm.quat(1.0, INF, 0.0, 0.0)),
    (Material, "roughness", 2.0),
    (Material, "color", (NAN, NAN, NAN)),
    (Emissive, "power", -1.0),
    (Camera, "fov_y", 0.0),
    (Camera, "far", 0.01),     # below the default near (0.05)
    (Camera, "near", 500.0),   # beyond the default far (200)
    (PointLight, "range", 0.0),
    (Reflective, "mode", "bogus"),
    (Skybox, "face_size", 1),
    (Skybox, "faces", np.zeros((5, 4, 4, 3), np.float32)),
    (MeshRef, "visible", "no"),
    (Transform, "position", glm.vec4(1.0, 2.0, 3.0, 1.0)),   # (takes the general path: not a glm.vec3)
    (DirectionalLight, "direction", 1.0),
    (FlyController, "pitch", 95.0),
    (ParticleEmitter, "ground", 1e30),
]


@pytest.mark.parametrize("cls, field, value", BAD_ASSIGNMENTS,
                         ids=[f"{c.__name__}.{f}" for c, f, _ in BAD_ASSIGNMENTS])
def test_bad_value_assigned_later_is_rejected_and_old_value_kept(cls, field, value):
    component = cls(box()) if cls is MeshRef else cls()
    before = getattr(component, field)
    with pytest.raises(ComponentValueError, match=rf"\b{cls.__name__}\.{field}\b"):
        setattr(component, field, value)
    after = getattr(component, field)
    if isinstance(before, np.ndarray) or before is None:
        assert after is before
    else:
        assert after == before


def test_a_view_budgets_min_pixels_past_a_float_is_refused_when_given():
    """``ViewBudget(min_pixels=10**400)`` was taken and raised an OverflowError from inside the
    frame's view-tree pass (its coverage test is in floats; found by the budget fuzz, seed 21):
    refused at once now, naming the field; 2**53 (no view has as many pixels) still taken."""
    from engine.core.budget import ViewBudget, ViewBudgetError

    for too_many in (10 ** 400, 2 ** 53 + 1):
        with pytest.raises(ViewBudgetError, match=r"ViewBudget\.min_pixels must be at most 2\*\*53"):
            ViewBudget(min_pixels=too_many)
    assert ViewBudget(min_pixels=2 ** 53).min_pixels == 2 ** 53


def test_camera_planes_can_move_together_in_a_valid_order():
    cam = Camera(near=300.0, far=1000.0)   # near beyond the *default* far is fine when far is larger
    assert (cam.near, cam.far) == (300.0, 1000.0)
    cam.far = 2000.0
    cam.near = 1500.0
    assert (cam.near, cam.far) == (1500.0, 2000.0)


def test_misspelt_field_is_an_error_not_silently_ignored():
    light = PointLight()
    with pytest.raises(AttributeError, match="intesity"):
        light.intesity = 5.0
    assert not hasattr(light, "intesity")


# --- good values are normalised to the kinds systems expect ---------------------------------

def test_good_values_are_converted():
    t = Transform(position=[1, 2, 3], rotation=glm.quat(2.0, 0.0, 0.0, 0.0), scale=2.0, parent=np.int64(4))
    assert isinstance(t.position, glm.vec3) and t.position == glm.vec3(1, 2, 3)
    assert t.scale == glm.vec3(2.0)
    assert math.isclose(glm.length(t.rotation), 1.0, rel_tol=1e-6)   # normalised
    assert t.parent == 4 and type(t.parent) is int

    m = Material(color=(0.5, 0.25, 0.125), metallic=np.float32(0.25), roughness=1)
    assert m.color == glm.vec4(0.5, 0.25, 0.125, 1.0)
    assert m.metallic == 0.25 and isinstance(m.metallic, float)
    assert Material(color=np.array([0.1, 0.2, 0.3, 0.4])).color.w == pytest.approx(0.4)

    d = DirectionalLight(direction=(0.0, -3.0, 0.0))
    assert d.direction == glm.vec3(0.0, -1.0, 0.0)

    sky = Skybox(face_size=np.int64(32), faces=[np.ones((4, 4, 3))] * 6)
    assert sky.face_size == 32 and type(sky.face_size) is int
    assert sky.faces.shape == (6, 4, 4, 3) and sky.faces.dtype == np.float32

    assert Reflective(mix=None).mix is None
    assert Emissive(0).power == 0.0


def test_one_number_stands_for_three_except_in_a_direction():
    """What ``vec3`` still takes: one number for all three where that means something (a
    uniform scale, no gravity, a cube), a pitch of exactly straight up or down."""
    assert Transform(scale=2.0).scale == glm.vec3(2.0)
    assert ParticleEmitter(gravity=0.0).gravity == glm.vec3(0.0)
    assert Transform(position=glm.dvec3(1.0, 2.0, 3.0)).position == glm.vec3(1.0, 2.0, 3.0)
    assert Transform(position=np.array([1.0, 2.0, 3.0])).position == glm.vec3(1.0, 2.0, 3.0)
    assert (FlyController(pitch=-90.0).pitch, FlyController(pitch=90).pitch) == (-90.0, 90.0)
    with pytest.raises(ComponentValueError, match=r"Transform\.position must be three numbers, not 4"):
        Transform(position=[0.0, 1.0, 2.0, 3.0])
    with pytest.raises(ComponentValueError, match=r"Skybox\.sun_direction must be three numbers \(a direction"):
        Skybox(sun_direction=np.float32(1.0))


DIRECTION_FIELDS = [(DirectionalLight, "direction"), (Mirror, "plane_normal"), (ParticleEmitter, "direction"),
                    (Skybox, "sun_direction")]


@pytest.mark.parametrize("cls, field", DIRECTION_FIELDS, ids=lambda v: getattr(v, "__name__", v))
def test_a_direction_of_any_finite_length_becomes_a_unit_vector_or_is_refused(cls, field):
    """A direction is normalised without float32's overflow and underflow: (1e20, 0, 0) was
    the zero vector (its squared length infinite in float32) and (1e-22, 0, 0) came out 1%
    long; each is now the unit vector it points along, given at construction or written
    after.  One that is zero in float32 is refused naming the field."""
    for given, unit in (((0.0, -1e20, 0.0), (0.0, -1.0, 0.0)), ((3e19, 0.0, 3e19), (0.5 ** 0.5, 0.0, 0.5 ** 0.5)),
                        ((1e38, 1e38, 1e38), (3 ** -0.5,) * 3), ((1e-22, 0.0, 0.0), (1.0, 0.0, 0.0))):
        made, written = cls(**{field: given}), cls()
        setattr(written, field, given)
        for component in (made, written):
            assert tuple(getattr(component, field)) == pytest.approx(unit, abs=1e-6), (given, component)
    with pytest.raises(ComponentValueError, match=rf"{cls.__name__}\.{field} must not be the zero vector"):
        cls(**{field: (1e-46, 0.0, 0.0)})
    with pytest.raises(ComponentValueError, match=rf"{cls.__name__}\.{field} must not be the zero vector"):
        setattr(cls(), field, (1e-46, 0.0, 0.0))


@pytest.mark.parametrize("plane", [(True, 0, 0, 1), b"abcd", 5.0, (0.0, 1.0, 0.0),
                                   ("0", 1, 0, 0), (NAN, 1, 0, 0)], ids=repr)
def test_a_bad_slice_plane_is_refused_when_given_and_when_written(plane):
    """Slice.plane is four numbers each through float(): glm.vec4 alone took True as 1, bytes
    as their codes and one number as four, and read (2**64, 0, 0, -1) as (0, 0, 0, -1) (a
    wrapped int: a plane that hides the whole entity)."""
    with pytest.raises(ComponentValueError, match=r"Slice\.plane must"):
        Slice(plane=plane)
    written = Slice(plane=(0.0, 1.0, 0.0, -0.5))
    with pytest.raises(ComponentValueError, match=r"Slice\.plane must"):
        written.plane = plane
    assert written.plane == glm.vec4(0.0, 1.0, 0.0, -0.5)
    assert Slice(plane=np.array([0.0, 0.0, 1.0, 2.0])).plane == glm.vec4(0.0, 0.0, 1.0, 2.0)
    written.plane = (2 ** 64, 0, 0, -1)
    assert written.plane == glm.vec4(2.0 ** 64, 0.0, 0.0, -1.0)

# --- change tracking ------------------------------------------------------------------------

def test_field_writes_are_reported_to_the_world(world):
    e = world.spawn(Transform(), Material())
    world.step(0.0)                       # forget the spawn itself
    assert world.changed(Transform) == set() and world.changed(Material) == set()

    world.get(e, Transform).position = (1.0, 2.0, 3.0)
    assert world.changed(Transform) == {e}
    assert world.changed(Material) == set()   # per type

    world.step(0.0)
    assert world.changed(Transform) == set()
    mat = world.get(e, Material)
    mat.color.x = 0.1                     # in-place edit is invisible ...
    assert world.changed(Material) == set()
    mat.touch()                           # ... until touched
    assert world.changed(Material) == {e}


def test_glm_writes_are_checked_copied_and_reported_like_any_other(world):
    """Transform's inline path for glm positions and rotations (its ``__setattr__``) keeps
    what the general one does: a copy of the vector, the rotation normalised, the write
    reported, a bound value kept, a refused one not reported."""
    from components.transform import POSITION_MAX
    e = world.spawn(Transform())
    world.step(0.0)
    t = world.get(e, Transform)
    p = glm.vec3(POSITION_MAX, -POSITION_MAX, 1.0)
    t.position = p
    assert t.position == p and t.position is not p        # a copy: editing p later is not the field
    assert world.changed(Transform) == {e}
    t.rotation = glm.quat(2.0, 0.0, 0.0, 0.0)
    assert t.rotation == glm.quat(1.0, 0.0, 0.0, 0.0)
    assert t.rotation == Transform(rotation=(2.0, 0.0, 0.0, 0.0)).rotation  # as the general path gives
    world.step(0.0)
    with pytest.raises(ComponentValueError, match=r"Transform\.position must be within"):
        t.position = glm.vec3(0.0, 0.0, POSITION_MAX * 2.0)
    with pytest.raises(ComponentValueError, match=r"Transform\.rotation must not be the zero quaternion"):
        t.rotation = glm.quat(0.0, 0.0, 0.0, 0.0)
    assert world.changed(Transform) == set()
    assert t.position == p and t.rotation == glm.quat(1.0, 0.0, 0.0, 0.0)


def test_the_transform_stage_uses_the_entitys_transform_whatever_happened_after_a_write(world):
    """A glm write leaves its component in ``World.written`` (the transform stage finds it
    there, not through esper): a component replaced, removed or deleted with its entity after
    the write, in the same frame, must not be the one the stage places the entity by."""
    from systems.transform_system import TransformSystem
    system = TransformSystem(world)
    a, b, c, d = (world.spawn(Transform(position=(float(i), 0.0, 0.0))) for i in range(4))
    system.process(0.0)
    world.step(0.0)
    old_a, old_b = world.get(a, Transform), world.get(b, Transform)
    old_a.position = glm.vec3(10.0, 0.0, 0.0)      # a hot write, then the component replaced
    world.add_component(a, Transform(position=(20.0, 0.0, 0.0)))
    old_b.rotation = glm.quat(0.0, 0.0, 1.0, 0.0)  # a hot write, then the component removed
    world.remove_component(b, Transform)
    world.get(c, Transform).position = glm.vec3(30.0, 0.0, 0.0)  # a hot write, then the entity deleted
    world.delete_entity(c)
    world.get(d, Transform).position = glm.vec3(40.0, 0.0, 0.0)  # a hot write alone
    assert set(world.written(Transform)) == {a, b, c, d}
    system.process(0.0)
    assert world.get(a, Transform).world[3].xyz == glm.vec3(20.0, 0.0, 0.0)   # the new component's
    assert old_a.world[3].xyz == glm.vec3(0.0, 0.0, 0.0)                      # the old one untouched
    assert old_b.world[3].xyz == glm.vec3(1.0, 0.0, 0.0)
    assert world.get(d, Transform).world[3].xyz == glm.vec3(40.0, 0.0, 0.0)
    assert world.frame.removed == {b, c} and world.frame.moved == {a, d}
    world.step(0.0)
    assert world.written(Transform) == {}                  # a step's hint, forgotten with its changes


def test_changed_any_is_the_union_of_the_change_sets_and_a_set_of_its_own(world):
    a = world.spawn(Transform(), Material())
    b = world.spawn(Emissive(1.0))
    world.step(0.0)
    world.get(a, Material).roughness = 0.5
    world.get(b, Emissive).power = 2.0
    found = world.changed_any((Material, Emissive, Camera))
    assert found == world.changed(Material) | world.changed(Emissive) == {a, b}
    found.add(99)                                   # the caller's to change
    assert world.changed(Material) == {a} and world.changed(Emissive) == {b}
    assert world.changed_any(()) == set() and world.changed_any((Camera,)) == set()


def test_failed_write_is_not_reported(world):
    e = world.spawn(Emissive(1.0))
    world.step(0.0)
    with pytest.raises(ComponentValueError):
        world.get(e, Emissive).power = -1.0
    assert world.changed(Emissive) == set()
    assert world.get(e, Emissive).power == 1.0


def test_spawn_add_and_remove_are_changes(world):
    e = world.spawn(Transform())
    assert e in world.changed(Transform)
    world.step(0.0)
    world.add_component(e, Emissive(2.0))
    assert world.changed(Emissive) == {e}
    world.step(0.0)
    removed = world.remove_component(e, Emissive)
    assert isinstance(removed, Emissive) and world.changed(Emissive) == {e}
    assert world.remove_component(e, Emissive) is None


def test_removed_component_is_detached(world):
    e = world.spawn(Transform(), Emissive(1.0))
    emissive = world.remove_component(e, Emissive)
    world.step(0.0)
    emissive.power = 3.0                  # no longer part of the world
    assert world.changed(Emissive) == set()
    emissive.touch()
    assert world.changed(Emissive) == set()


def test_replaced_component_is_detached(world):
    e = world.spawn(Emissive(1.0))
    old = world.get(e, Emissive)
    world.add_component(e, Emissive(2.0))
    world.step(0.0)
    old.power = 5.0
    assert world.changed(Emissive) == set()
    world.get(e, Emissive).power = 4.0
    assert world.changed(Emissive) == {e}


def test_deleted_entity_components_are_detached(world):
    keep = world.spawn(Transform())
    gone = world.spawn(Transform())
    transform = world.get(gone, Transform)
    world.step(0.0)
    world.delete_entity(gone)
    assert gone in world.deleted() and gone in world.changed(Transform)
    assert not world.exists(gone) and world.exists(keep)
    assert world.entities() == [keep]
    world.step(0.0)
    transform.position = (5.0, 5.0, 5.0)
    assert world.changed(Transform) == set()
    assert world.deleted() == set()


def test_two_worlds_do_not_see_each_other():
    a, b = World("a"), World("b")
    try:
        ea = a.spawn(Transform(position=(1.0, 0.0, 0.0)), Emissive(1.0))
        eb = b.spawn(Transform(position=(2.0, 0.0, 0.0)))
        assert [e for e, _ in a.query_one(Emissive)] == [ea]
        assert b.query_one(Emissive) == []
        assert a.get(ea, Transform).position.x == 1.0
        assert b.get(eb, Transform).position.x == 2.0
        assert len(a.entities()) == 1 and len(b.entities()) == 1
        b.step(0.0)
        a.get(ea, Transform).position = (3.0, 0.0, 0.0)   # reported to a only
        assert a.changed(Transform) == {ea}
        assert b.changed(Transform) == set()
    finally:
        a.close()
        b.close()


def test_close_detaches_everything_and_refuses_further_use():
    w = World("closing")
    t = Transform()
    w.spawn(t, Material())
    w.close()
    w.close()                              # idempotent
    t.position = (1.0, 1.0, 1.0)           # detached: reports to nobody, raises nothing
    with pytest.raises(RuntimeError, match="closed"):
        w.spawn(Transform())
    with World("after") as fresh:          # a new world starts empty
        assert fresh.entities() == []
