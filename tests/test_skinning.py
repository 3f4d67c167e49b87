"""Skinned meshes: a mesh bent by its joints (``Mesh.joints``/``weights``, ``Skin``), drawn
in every view and shadow map as the sum written out here by hand, from a glTF's skins and
clips, and refused plainly where the data cannot be drawn."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from pyglm import glm

from components import (
    AmbientOcclusion,
    Animation,
    ComponentValueError,
    DirectionalLight,
    FromModel,
    Material,
    MeshRef,
    Mirror,
    ScreenReflections,
    Skin,
    Transform,
)
from engine.assets.mesh import Mesh, load_model_file, plane, quad
from engine.assets.models import spawn_model
from engine.core.errors import AssetError
from engine.core.world import World
from engine.rules.raycast import raycast
from tests.support import look_from
from tests.test_materials_from_files import write_glb
from tests.test_model_variants import add_accessors, edit_glb

RED = (0.8, 0.25, 0.15, 1.0)


def bar_arrays(segments: int = 8, height: float = 2.0, half: float = 0.15):
    """A square tube along +y from 0 to ``height`` (four flat sides, open ends): positions,
    normals, uvs, triangles, and each vertex's weight on the elbow joint (0 below y = 0.75,
    1 above y = 1.25, linear between)."""
    positions, normals, uvs, triangles = [], [], [], []
    for n, t in (((1, 0, 0), (0, 0, -1)), ((0, 0, 1), (1, 0, 0)), ((-1, 0, 0), (0, 0, 1)), ((0, 0, -1), (-1, 0, 0))):
        n, t = np.array(n, float), np.array(t, float)
        base = len(positions)
        for i in range(segments + 1):
            for s in (-1.0, 1.0):
                positions.append(n * half + t * half * s + (0.0, height * i / segments, 0.0))
                normals.append(n)
                uvs.append((0.5 + 0.5 * s, i / segments))
        for i in range(segments):
            a = base + 2 * i
            triangles += [(a, a + 1, a + 3), (a, a + 3, a + 2)]
    positions = np.array(positions)
    elbow = np.clip((positions[:, 1] - 0.75) / 0.5, 0.0, 1.0)
    return positions, np.array(normals), np.array(uvs), np.array(triangles), elbow


def skinned_bar() -> Mesh:
    positions, normals, uvs, triangles, elbow = bar_arrays()
    return Mesh(positions, normals, uvs, triangles, name="arm", joints=np.tile([0, 1], (len(positions), 1)),
                weights=np.stack([1.0 - elbow, elbow], axis=1))


def elbow_matrix(angle: float) -> np.ndarray:
    """The elbow joint's matrix: turned by ``angle`` about +z at (0, 1, 0) (its pose, a turn
    at its place, times its inverse bind matrix, a move back to the origin)."""
    c, s = math.cos(angle), math.sin(angle)
    turn = np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], float)
    there, back = np.eye(4), np.eye(4)
    there[1, 3], back[1, 3] = 1.0, -1.0
    return there @ turn @ back


def bent_by_hand(angle: float, at: np.ndarray | None = None) -> Mesh:
    """The bar bent at the elbow, vertex by vertex: (1 - w) x p + w x (E p), its normal by the
    inverse transpose of the blend (the test's own sum, not the engine's)."""
    positions, normals, uvs, triangles, elbow = bar_arrays()
    moved = elbow_matrix(angle) if at is None else at
    out_p, out_n = [], []
    for p, n, w in zip(positions, normals, elbow, strict=True):
        blend = (1.0 - w) * np.eye(4) + w * moved
        out_p.append((blend @ np.append(p, 1.0))[:3])
        turned = np.linalg.inv(blend[:3, :3]).T @ n
        out_n.append(turned / np.linalg.norm(turned))
    return Mesh(np.array(out_p), np.array(out_n), uvs, triangles, name="by hand")


def arm_glb(path: Path, weights_kind: str = "float") -> Path:
    """The bar as a glTF: node 0 the skinned mesh (its own transform, a move of 5 along x,
    left out as glTF says), node 1 the shoulder at the origin, node 2 the elbow at (0, 1, 0)
    under it; skin 0 the two joints with their inverse bind matrices; clip "Bend" turns the
    elbow a quarter about +z over 1 s.  ``weights_kind`` "normalized": WEIGHTS_0 as
    normalised unsigned bytes (KHR_mesh_quantization's packing); "split": the elbow's
    weight in a JOINTS_1/WEIGHTS_1 set, with a stray small weight on the shoulder."""
    positions, normals, uvs, triangles, elbow = bar_arrays()
    write_glb(path, Mesh(positions, normals, uvs, triangles, name="arm"),
              {"name": "paint", "pbrMetallicRoughness": {"baseColorFactor": list(RED)}}, [])
    count = len(positions)
    joints = np.zeros((count, 4), np.uint8)
    joints[:, 1] = 1
    weights = np.zeros((count, 4), np.float32)
    weights[:, 0], weights[:, 1] = 1.0 - elbow, elbow
    sets = [(joints, weights)]
    if weights_kind == "normalized":
        sets = [(joints, np.round(weights * 255.0).astype(np.uint8))]
    elif weights_kind == "split":
        first = np.zeros((count, 4), np.float32)
        first[:, 0] = 1.0 - elbow
        second_joints = np.zeros((count, 4), np.uint8)
        second_weights = np.zeros((count, 4), np.float32)
        second_joints[:, 0], second_weights[:, 0] = 1, elbow
        sets = [(np.zeros((count, 4), np.uint8), first), (second_joints, second_weights)]
    binds = np.stack([np.eye(4), np.linalg.inv(np.array([[1, 0, 0, 0], [0, 1, 0, 1], [0, 0, 1, 0], [0, 0, 0, 1.0]]))])
    quarter = [0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)]
    arrays = [*(a for pair in sets for a in pair), binds.transpose(0, 2, 1).astype(np.float32).reshape(2, 16),
              np.array([0.0, 1.0], np.float32), np.array([[0, 0, 0, 1], quarter], np.float32)]

    def change(doc: dict) -> None:
        first = add_accessors(doc, arrays, frozenset({1}) if weights_kind == "normalized" else frozenset())
        attributes = doc["meshes"][0]["primitives"][0]["attributes"]
        for n in range(len(sets)):
            attributes[f"JOINTS_{n}"], attributes[f"WEIGHTS_{n}"] = first + 2 * n, first + 2 * n + 1
        a = first + 2 * len(sets)
        doc["nodes"] = [{"name": "arm", "mesh": 0, "skin": 0, "translation": [5.0, 0.0, 0.0]},
                        {"name": "shoulder", "children": [2]},
                        {"name": "elbow", "translation": [0.0, 1.0, 0.0]}]
        doc["scenes"] = [{"nodes": [0, 1]}]
        doc["skins"] = [{"name": "rig", "joints": [1, 2], "inverseBindMatrices": a}]
        doc["animations"] = [{"name": "Bend", "samplers": [{"input": a + 1, "output": a + 2}],
                              "channels": [{"sampler": 0, "target": {"node": 2, "path": "rotation"}}]}]
    return edit_glb(path, change)


def lit(build, eye=(0.6, 1.4, 5.0), target=(0.3, 1.0, 0.0), fov=50.0, camera=()):
    """A floor under a sun (with shadows), the camera at ``eye`` (with the components
    ``camera``), then ``build``."""
    def made(world):
        eye_entity = look_from(world, eye, target, fov=fov)
        for component in camera:
            world.add_component(eye_entity, component)
        world.spawn(DirectionalLight(direction=(-0.4, -1.0, -0.6), intensity=2.0))
        world.spawn(Transform(), MeshRef(plane(8, 8)), Material(color=(0.6, 0.6, 0.6, 1.0)))
        build(world)
    return made


def frame_of(scene, build, size=(160, 120), frames=2) -> np.ndarray:
    runner = scene(build, size)
    for _ in range(frames - 1):
        runner.frame()
    return runner.frame().astype(int)


def same_picture(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal but for rounding at a few edge pixels (the GPU's float32 blend against float64)."""
    differ = np.abs(a - b).max(axis=-1) > 12
    return differ.sum() <= 0.002 * differ.size


def test_a_skin_bends_the_mesh_as_the_sum_written_out(scene):
    """The bar bent a quarter at the elbow by its Skin, seen directly, in a mirror behind it
    and by its shadow on the floor, draws what the bar bent vertex by vertex does."""
    def mirror(world):
        world.spawn(Transform(position=(0.0, 1.0, -1.5)), MeshRef(quad(4.0, 2.5)), Mirror())

    def skinned(world):
        mirror(world)
        world.spawn(Transform(), MeshRef(skinned_bar()), Material(color=RED),
                    Skin(np.stack([np.eye(4), elbow_matrix(math.pi / 2)])))

    def by_hand(world):
        mirror(world)
        world.spawn(Transform(), MeshRef(bent_by_hand(math.pi / 2)), Material(color=RED))

    def straight(world):
        mirror(world)
        world.spawn(Transform(), MeshRef(skinned_bar()), Material(color=RED))

    bent, hand, modelled = (frame_of(scene, lit(b)) for b in (skinned, by_hand, straight))
    assert same_picture(bent, hand)
    assert not same_picture(bent, modelled)  # (without a Skin: drawn as modelled, straight up)
    red = (bent[..., 0] > bent[..., 2] + 60)
    assert red.sum() > 300  # the bar, its reflection and no black frame
    # The shadow: the floor darker where the bent arm's shadow falls than the straight one's
    # leaves it, in both frames alike (the caster build bends it too).
    shade = np.abs(bent - modelled).max(axis=-1) > 20
    assert (shade & ~red & ~(modelled[..., 0] > modelled[..., 2] + 60)).sum() > 20


def test_a_chrome_balls_probe_sees_the_pose(scene):
    """A mirror ball looking back at the arm behind the camera (its own cube-map probe): the
    bent arm in its reflection, as the arm bent by hand is there, and not where the straight
    one would stand."""
    from components import Reflective
    from engine.assets.mesh import sphere

    def ball(world):
        world.spawn(Transform(position=(0.3, 1.0, 1.2)), MeshRef(sphere(0.45)),
                    Material(color=(1, 1, 1), metallic=1.0, roughness=0.0), Reflective("cube"))

    view = {"eye": (0.3, 1.0, 3.5), "target": (0.3, 1.0, 1.2), "fov": 30.0}   # the ball fills the frame

    def skinned(world):
        ball(world)
        world.spawn(Transform(position=(0.0, 0.0, 4.5)), MeshRef(skinned_bar()), Material(color=RED),
                    Skin(np.stack([np.eye(4), elbow_matrix(math.pi / 2)])))

    def by_hand(world, mesh):
        ball(world)
        world.spawn(Transform(position=(0.0, 0.0, 4.5)), MeshRef(mesh), Material(color=RED))

    bent = frame_of(scene, lit(skinned, **view), frames=3)
    hand = frame_of(scene, lit(lambda w: by_hand(w, bent_by_hand(math.pi / 2)), **view), frames=3)
    straight = frame_of(scene, lit(lambda w: by_hand(w, bent_by_hand(0.0)), **view), frames=3)
    assert same_picture(bent, hand) and not same_picture(bent, straight)


def test_the_screen_passes_see_the_pose(scene):
    """With ambient occlusion (its depth-and-normals pass) and screen reflections (the
    builds that write what they read) on the camera, the bent arm and its occlusion on the
    floor are drawn as the bar bent by hand."""
    def extras():  # (occlusion dimming the sun too: the arm's on the floor is plain to see)
        return (AmbientOcclusion(radius=1.0, intensity=2.0, direct_light=1.0, half_resolution=False),
                ScreenReflections())

    down = 2.4  # the forearm bent down to near the floor
    bent = frame_of(scene, lit(lambda w: w.spawn(Transform(), MeshRef(skinned_bar()), Material(color=RED),
                                                  Skin(np.stack([np.eye(4), elbow_matrix(down)]))), camera=extras()))
    hand = frame_of(scene, lit(lambda w: w.spawn(Transform(), MeshRef(bent_by_hand(down)), Material(color=RED)),
                               camera=extras()))
    plain = frame_of(scene, lit(lambda w: w.spawn(Transform(), MeshRef(bent_by_hand(down)), Material(color=RED))))
    assert same_picture(bent, hand)
    assert (np.abs(hand - plain).max(axis=-1) > 40).sum() > 200   # (the occlusion is there to see)


def test_a_pose_reaching_past_the_mesh_as_modelled_is_held_by_its_box(scene):
    """The instance's world box (what per-view culling, the probes' empty faces and the sun's
    map fit go by) holds every vertex of the bar bent by hand, though the bent forearm reaches
    past the bar as modelled; and the arm is drawn where only the forearm is in view."""
    holder = {}

    def skinned(world):
        holder["arm"] = world.spawn(Transform(position=(0.0, 0.0, 0.5)), MeshRef(skinned_bar()),
                                    Material(color=RED), Skin(np.stack([np.eye(4), elbow_matrix(-math.pi / 2)])))

    runner = scene(lit(skinned, eye=(0.8, 1.0, 2.5), target=(0.8, 1.0, 0.0), fov=20.0), (64, 48))
    runner.frame()
    frame = runner.frame().astype(int)
    assert (frame[..., 0] > frame[..., 2] + 60).sum() > 100
    (batch,) = [b for b in runner.engine.renderer.batches.values() if b.skinned]
    lo, hi = batch.row_boxes[0]
    placed = bent_by_hand(-math.pi / 2).positions + (0.0, 0.0, 0.5)
    assert (placed >= lo - 1e-5).all() and (placed <= hi + 1e-5).all()
    assert hi[0] > 0.99   # (the bar as modelled stops at x = 0.15)
    level_lo, level_hi = runner.engine.renderer.level_bounds()
    assert (placed >= level_lo - 1e-5).all() and (placed <= level_hi + 1e-5).all()


def test_the_shadow_and_probe_stages_box_a_posed_mesh_where_its_pose_puts_it(scene):
    """The boxes the point lights' shadow cubes and the probes' recaptures go by (which faces
    a change touches) hold the arm bent past the mesh as modelled, after a new pose too."""
    from components import PointLight, ReflectionProbe

    holder = {}

    def build(world):
        world.spawn(Transform(position=(0.0, 3.5, 1.0)), PointLight(intensity=6.0, range=10.0, shadows=True))
        world.spawn(Transform(position=(1.5, 1.0, 1.5)), ReflectionProbe())
        holder["arm"] = world.spawn(Transform(), MeshRef(skinned_bar()), Material(color=RED),
                                    Skin(np.stack([np.eye(4), elbow_matrix(0.0)])))

    runner = scene(lit(build), (64, 48))
    runner.frame()
    runner.world.get(holder["arm"], Skin).joint_matrices = np.stack([np.eye(4), elbow_matrix(-math.pi / 2)])
    runner.frame()
    placed = bent_by_hand(-math.pi / 2).positions
    for boxes in (runner.engine.stages["shadows"]._bounds, runner.engine.stages["probes"].scheduler._bounds):
        lo, hi = boxes[holder["arm"]]
        assert (placed >= lo - 1e-5).all() and (placed <= hi + 1e-5).all()


def test_the_pose_changes_from_frame_to_frame_and_its_shadow_follows(scene, monkeypatch):
    """A Skin given new matrices is drawn bent the new way in the next frame (its shadow too),
    its pose written alone (the entity's whole row is not worked out again for it)."""
    from systems.extract_system import ExtractSystem

    holder = {}
    refreshed = []
    original = ExtractSystem._refresh_instance
    monkeypatch.setattr(ExtractSystem, "_refresh_instance",
                        lambda self, entity: refreshed.append(entity) or original(self, entity))

    def skinned(world):
        holder["arm"] = world.spawn(Transform(), MeshRef(skinned_bar()), Material(color=RED),
                                    Skin(np.stack([np.eye(4), elbow_matrix(0.0)])))

    runner = scene(lit(skinned), (160, 120))
    runner.frame()
    straight = runner.frame().astype(int)
    runner.world.get(holder["arm"], Skin).joint_matrices = np.stack([np.eye(4), elbow_matrix(math.pi / 2)])
    refreshed.clear()
    bent = runner.frame().astype(int)
    assert holder["arm"] not in refreshed
    hand = frame_of(scene, lit(lambda w: w.spawn(Transform(), MeshRef(bent_by_hand(math.pi / 2)),
                                                  Material(color=RED))))
    assert same_picture(bent, hand) and not same_picture(bent, straight)


def test_a_models_skin_plays_its_clip(scene, tmp_path):
    """A glTF's skinned mesh: at rest where its joints' rest pose puts it (its node's own move
    of 5 left out), and at 0.5 s into "Bend" the elbow turned an eighth, drawn as the bar bent
    by hand there."""
    path = arm_glb(tmp_path / "arm.glb")
    loaded = load_model_file(path)
    (part,) = loaded.parts
    assert part.skin == 0 and part.mesh.skinned and [s.joints for s in loaded.skins] == [[1, 2]]
    world = World("arm")
    root = spawn_model(world, path)
    ((entity, _),) = list(world.query_one(FromModel))
    assert world.get(entity, Transform).position == glm.vec3(0.0)   # the skinned node's own move is left out
    np.testing.assert_allclose(world.get(entity, Skin).joint_matrices, np.stack([np.eye(4)] * 2), atol=1e-6)
    world.add_component(root, Animation(clip="Bend", time=0.5, playing=False))
    from systems.model_system import ModelSystem
    ModelSystem(world).process(1 / 60)
    np.testing.assert_allclose(world.get(entity, Skin).joint_matrices[1], elbow_matrix(math.pi / 4), atol=1e-5)

    def animated(world):
        model_root = spawn_model(world, path)
        world.add_component(model_root, Animation(clip="Bend", time=0.5, playing=False))

    bent = frame_of(scene, lit(animated), frames=3)
    hand = frame_of(scene, lit(lambda w: w.spawn(Transform(), MeshRef(bent_by_hand(math.pi / 4)), Material(color=RED))))
    assert same_picture(bent, hand)
    assert (bent[..., 0] > bent[..., 2] + 60).sum() > 150


@pytest.mark.parametrize("kind", ["normalized", "split"])
def test_packed_and_split_weights_are_read_as_the_file_means(tmp_path, kind):
    """Normalised byte weights are read as fractions of 255; a second JOINTS/WEIGHTS set
    folds into the four strongest joints, the weights made to sum to 1."""
    (part,) = load_model_file(arm_glb(tmp_path / "arm.glb", kind)).parts
    _, _, _, _, elbow = bar_arrays()
    mesh = part.mesh
    np.testing.assert_allclose(mesh.weights.sum(axis=1), 1.0, atol=1e-6)
    on_elbow = np.where(mesh.joints == 1, mesh.weights, 0.0).sum(axis=1)
    np.testing.assert_allclose(on_elbow, elbow, atol=1.0 / 255.0 if kind == "normalized" else 1e-6)


def test_a_ray_hits_the_arm_where_it_is_bent(ctx):
    world = World("aim")
    world.spawn(Transform(), MeshRef(skinned_bar()), Skin(np.stack([np.eye(4), elbow_matrix(-math.pi / 2)])))
    from systems.transform_system import TransformSystem
    TransformSystem(world).process(0.0)
    hit = raycast(world, (0.8, 1.0, 5.0), (0.0, 0.0, -1.0))   # where the bent forearm lies along +x
    assert hit is not None and hit.distance == pytest.approx(5.0 - 0.15, abs=1e-4)
    assert raycast(world, (0.0, 1.9, 5.0), (0.0, 0.0, -1.0)) is None   # where the straight one stood


def test_skins_given_and_taken_keep_their_rows_and_release_the_palette(scene):
    """Five arms (past the palette's first rows), each bent its own way, each drawn as bent by
    hand; all deleted, the palette texture and their batches go."""
    angles = [0.3, -0.6, 0.9, -1.2, 1.5]

    def arms(world, skinned):
        for i, angle in enumerate(angles):
            at = Transform(position=(1.2 * i - 2.4, 0.0, 0.0))
            if skinned:
                world.spawn(at, MeshRef(skinned_bar()), Material(color=RED),
                            Skin(np.stack([np.eye(4), elbow_matrix(angle)])))
            else:
                world.spawn(at, MeshRef(bent_by_hand(angle)), Material(color=RED))

    view = {"eye": (0.0, 1.5, 7.0), "target": (0.0, 1.0, 0.0)}
    runner = scene(lit(lambda w: arms(w, True), **view), (200, 100))
    runner.frame()
    bent = runner.frame().astype(int)
    hand = frame_of(scene, lit(lambda w: arms(w, False), **view), (200, 100))
    assert same_picture(bent, hand)
    renderer = runner.engine.renderer
    assert len(renderer.pose_rows) == 5 and renderer.resource_counts()["pose_rows"] == 1
    for entity, _ in list(runner.world.query_one(Skin)):
        runner.world.delete_entity(entity)
    runner.frame()
    assert len(renderer.pose_rows) == 0 and renderer.resource_counts()["pose_rows"] == 0
    assert not [b for b in renderer.batches.values() if b.skinned]


def test_bad_skins_are_refused_when_given():
    world = World("refusals")
    arm = skinned_bar()
    with pytest.raises(ComponentValueError, match=r"shape \(J, 4, 4\)"):
        Skin(np.eye(4))
    with pytest.raises(ComponentValueError, match="affine"):
        Skin(np.stack([np.eye(4), np.ones((4, 4))]))
    with pytest.raises(ComponentValueError, match="finite"):
        Skin(np.full((1, 4, 4), np.nan))
    with pytest.raises(ComponentValueError, match=r"holds 1 matrices, but mesh 'arm' names joints up to 1"):
        world.spawn(Transform(), MeshRef(arm), Skin())
    with pytest.raises(ComponentValueError, match="has no joints and weights a vertex"):
        world.spawn(Transform(), MeshRef(quad(1, 1)), Skin())
    entity = world.spawn(Transform(), MeshRef(arm), Skin(np.stack([np.eye(4)] * 2)))
    with pytest.raises(ComponentValueError, match="holds 1 matrices"):
        world.get(entity, Skin).joint_matrices = np.eye(4)[None]
    flat = quad(1.0, 1.0)
    sheet = world.spawn(Transform(), Skin(), MeshRef(Mesh(flat.positions, flat.normals, flat.uvs, flat.indices,
                                                          joints=np.zeros((4, 1), int), weights=np.ones((4, 1)))))
    with pytest.raises(ComponentValueError, match="a Skin on a Mirror"):
        world.add_component(sheet, Mirror())
    positions, normals, uvs, triangles, _ = bar_arrays()
    with pytest.raises(AssetError, match="needs both joints and weights"):
        Mesh(positions, normals, uvs, triangles, joints=np.zeros((len(positions), 4), int))
    with pytest.raises(AssetError, match="weights summing to 0"):
        Mesh(positions, normals, uvs, triangles, joints=np.zeros((len(positions), 4), int),
             weights=np.zeros((len(positions), 4)))
    with pytest.raises(AssetError, match=r"joints must be integers in 0..255"):
        Mesh(positions, normals, uvs, triangles, joints=np.full((len(positions), 4), 300),
             weights=np.ones((len(positions), 4)))


@pytest.mark.parametrize(("change", "message"), [
    (lambda doc: doc["nodes"][0].update(skin=3), r"node 0 names skin 3, which the file does not have"),
    (lambda doc: doc["skins"][0].update(joints=[1, 9]), r"skin 0 \('rig'\): names joint node 9"),
    (lambda doc: doc["skins"][0].update(joints=[1, 2, 0]), r"inverseBindMatrices must be 3 MAT4"),
    (lambda doc: doc["skins"][0].update(joints=list(range(300))), r"has 300 joints; .* at most 256"),
    (lambda doc: doc["skins"][0].update(joints=[2]) or doc["skins"][0].pop("inverseBindMatrices"),
     r"a vertex names joint 1 of skin 'rig', which has 1"),
    (lambda doc: doc["meshes"][0]["primitives"][0]["attributes"].pop("WEIGHTS_0"),
     r"node 0 is skinned \(skin 0\) but mesh 0's primitive 0 has no JOINTS_0 and WEIGHTS_0"),
])
def test_malformed_skins_in_a_file_are_refused_naming_them(tmp_path, change, message):
    path = edit_glb(arm_glb(tmp_path / "arm.glb"), change)
    with pytest.raises(AssetError, match=message):
        load_model_file(path)


def test_a_level_places_the_skinned_model_the_editor_picks_it_and_a_save_keeps_the_model_alone(scene, tmp_path):
    """A level file's skinned model with its clip: drawn bent (its part's id where the bent
    forearm is), a click there selects the model, and the saved file holds the Model and its
    Animation, not the part or its Skin, and loads to the same frame."""
    from engine.assets.level_file import load_level, save_level
    from shell.editor import Editor

    arm_glb(tmp_path / "arm.glb")
    text = ('[level]\nname = "gym"\n\n[[entity]]\nname = "eye"\n[entity.Transform]\nposition = [0.6, 1.4, 5.0]\n'
            'rotation = { look = [-0.3, -0.4, -5.0] }\n[entity.Camera]\nfov_y = 50.0\n\n'
            '[[entity]]\nname = "arm"\n[entity.Transform]\n[entity.Model]\nfile = "arm.glb"\n'
            '[entity.Animation]\nclip = "Bend"\ntime = 1.0\nplaying = false\n')
    (tmp_path / "gym.toml").write_text(text)
    names: dict[str, int] = {}
    runner = scene(lambda world: names.update(load_level(tmp_path / "gym.toml").spawn(world)), (160, 120))
    runner.frame()
    first = runner.frame().astype(int)
    world = runner.world
    ((part, _),) = list(world.query_one(FromModel))
    np.testing.assert_allclose(world.get(part, Skin).joint_matrices[1], elbow_matrix(math.pi / 2), atol=1e-5)
    column, row = runner.project((-0.6, 1.0, 0.15))   # on the forearm, bent to -x
    ids = runner.ids()
    assert ids[row, column] == part
    assert ids[runner.project((0.0, 1.8, 0.15))[::-1]] != part   # where the straight arm would stand
    editor = Editor(world, names=names, level_path=tmp_path / "gym.toml")
    assert editor.pick(ids, None, column, row) == names["arm"]
    save_level(world, tmp_path / "saved.toml", names)
    saved = (tmp_path / "saved.toml").read_text()
    assert "[entity.Model]" in saved and 'clip = "Bend"' in saved and "Skin" not in saved
    assert saved.count("[[entity]]") == 2
    again = scene(lambda w: load_level(tmp_path / "saved.toml").spawn(w), (160, 120))
    again.frame()
    assert same_picture(again.frame().astype(int), first)


def test_a_skinned_traveller_comes_out_of_the_partner_bent_as_it_is(scene):
    """The arm pushed elbow first into portal A: its clone beyond B carries its Skin, is drawn
    bent there (its forearm's id where the bend puts it past B) and follows a new pose."""
    from components import PortalClone, Traveller
    from tests.test_portal_slice import SIZE, build_pair

    ents: dict[str, int] = {}
    into = glm.angleAxis(-math.pi / 2, glm.vec3(1.0, 0.0, 0.0))   # the bar's +y along -z, into A

    def build(world):
        build_pair(world, ents, (0.0, 3.0, 7.0), (0.0, 1.5, 0.0))
        world.delete_entity(ents["bar"])
        ents["arm"] = world.spawn(Transform(position=(-3.0, 1.5, 0.6), rotation=into), MeshRef(skinned_bar()),
                                  Material(color=RED), Traveller(),
                                  Skin(np.stack([np.eye(4), elbow_matrix(math.pi / 2)])))

    def past_b(angle: float) -> glm.vec3:
        """Where the forearm's middle (its top face) comes out in front of B: A's point
        turned a half about +y and moved from A to B."""
        local = glm.vec3(0.0, 1.0, 0.0) + 0.6 * glm.vec3(-math.sin(angle), math.cos(angle), 0.0) + glm.vec3(0, 0, 0.15)
        at_a = glm.vec3(-3.0, 1.5, 0.6) + into * local
        return glm.vec3(-at_a.x, at_a.y, -at_a.z)

    runner = scene(build, SIZE)
    runner.frame()
    world = runner.world
    ((clone, _),) = list(world.query_one(PortalClone))
    np.testing.assert_array_equal(world.get(clone, Skin).joint_matrices, world.get(ents["arm"], Skin).joint_matrices)
    ids = runner.ids()
    column, row = runner.project(past_b(math.pi / 2))
    assert ids[row, column] == ents["arm"]
    world.get(ents["arm"], Skin).joint_matrices = np.stack([np.eye(4), elbow_matrix(-math.pi / 2)])
    runner.frame()
    np.testing.assert_allclose(world.get(clone, Skin).joint_matrices[1], elbow_matrix(-math.pi / 2), atol=1e-6)
    ids = runner.ids()
    assert ids[runner.project(past_b(-math.pi / 2))[::-1]] == ents["arm"]
    assert ids[row, column] != ents["arm"]   # (where the old bend put it: empty now)


def test_a_skinned_mesh_with_vertex_colours_and_a_cutout_draws_as_bent_by_hand(scene):
    """The fullest vertex inputs (the SKINNED build with a colour a vertex: all sixteen GL 4.1
    promises) and a cutout's shadow build: the bar striped by its vertex colours, holes cut by
    its texture, bent by its Skin, draws (and shadows) as the same bar bent by hand."""
    from engine.assets.texture_data import TextureData

    stripes = np.zeros((8, 8, 4), np.uint8)
    stripes[..., :3] = 255
    stripes[..., 3] = np.where(np.arange(8) % 4 == 0, 0, 255)[:, None]   # a row in four cut away
    holes = TextureData(stripes, name="holes")
    positions, normals, uvs, triangles, elbow = bar_arrays()
    colours = np.where((positions[:, 1] * 2).astype(int)[:, None] % 2 == 0, (1.0, 0.9, 0.2, 1.0), (0.2, 0.5, 1.0, 1.0))
    skinned = Mesh(positions, normals, uvs, triangles, name="striped", colors=colours,
                   joints=np.tile([0, 1], (len(positions), 1)), weights=np.stack([1.0 - elbow, elbow], axis=1))
    hand = bent_by_hand(math.pi / 2)
    hand = Mesh(hand.positions, hand.normals, hand.uvs, hand.indices, name="striped by hand", colors=colours)

    def cutout():
        return Material(color=(1.0, 1.0, 1.0, 1.0), texture=holes, alpha_cutoff=0.5)

    bent = frame_of(scene, lit(lambda w: w.spawn(Transform(), MeshRef(skinned), cutout(),
                                                  Skin(np.stack([np.eye(4), elbow_matrix(math.pi / 2)])))))
    by_hand = frame_of(scene, lit(lambda w: w.spawn(Transform(), MeshRef(hand), cutout())))
    assert same_picture(bent, by_hand)
    assert (np.abs(bent - bent[0, 0]).max(axis=-1) > 60).sum() > 300


ELSEWHERE_A, ELSEWHERE_B = glm.vec3(0.0, 1.2, -0.5), glm.vec3(20.0, 1.2, 0.0)
ELSEWHERE_TURN = glm.angleAxis(math.pi / 2, glm.vec3(0.0, 1.0, 0.0))


def seen_elsewhere(scene, where: str, mesh, *posed, size=(96, 72), frames=3, change=None, after=0,
                   kept=None, configure=None, casts=True) -> np.ndarray:
    """``mesh`` (with the components ``posed``) drawn where the camera sees it only in a view of
    its own: ``where`` "per_mirror" or "batched", behind the camera (at z = 2.5, turned to face
    -z) and seen in a mirror ahead (z = -0.5, either reflection path); "portal", beyond portal
    B (20 m off, turned a quarter) where the view through A (ahead, at z = -0.5) puts it 3 m
    behind A; "probe", behind the camera seen in a chrome ball's cube probe ahead.  Under a
    sun with shadows over a floor (lit's) and a second sun lighting the side those views see.
    ``change(world, entity)``, given, is called after ``frames`` - 1 frames, then ``after`` more
    and the last are drawn; ``kept`` (a list) is given the mirror views kept the frame before;
    ``configure(runner)``, given, is called before the first frame; ``casts``: the mesh's
    MeshRef.casts_shadows."""
    from components import Reflective
    from engine.assets.mesh import sphere
    from engine.assets.portals import spawn_portal_pair
    from engine.core.portal_math import pair_transform

    behind = glm.translate(glm.vec3(0.0, 0.0, 2.5)) * glm.mat4_cast(glm.angleAxis(math.pi, glm.vec3(0.0, 1.0, 0.0)))
    if where == "portal":
        carry = pair_transform(glm.translate(ELSEWHERE_A), glm.translate(ELSEWHERE_B) * glm.mat4_cast(ELSEWHERE_TURN))
        place = carry * glm.translate(glm.vec3(0.0, 0.0, -3.5))
    else:
        place = behind

    def build(world):
        world.spawn(DirectionalLight(direction=(0.3, -0.6, 1.0), intensity=2.0))
        if where in ("per_mirror", "batched"):
            world.spawn(Transform(position=ELSEWHERE_A), MeshRef(quad(5.0, 3.0)), Mirror())
        elif where == "portal":
            spawn_portal_pair(world, ELSEWHERE_A, None, ELSEWHERE_B, ELSEWHERE_TURN, size=(5.0, 3.0))
        else:
            world.spawn(Transform(position=(0.0, 1.2, 0.0)), MeshRef(sphere(0.5, 48, 24)),
                        Material(color=(1, 1, 1), metallic=1.0, roughness=0.0), Reflective("cube"))
        world.thing = world.spawn(Transform(position=glm.vec3(place[3]), rotation=glm.quat_cast(place)),
                                  MeshRef(mesh, casts_shadows=casts), Material(color=RED), *posed)

    eye = (0.0, 1.2, 1.6) if where == "probe" else (0.0, 1.2, 1.5)
    runner = scene(lit(build, eye=eye, target=(0.0, 1.2, 0.0), fov=25.0 if where == "probe" else 35.0), size)
    if where != "probe":
        runner.engine.reflection_system.path = "per_mirror" if where == "portal" else where
    if configure is not None:
        configure(runner)
    for _ in range(frames - 1):
        runner.frame()
    if kept is not None:
        kept.append(runner.stats.reflection_views_kept)
    if change is not None:
        change(runner.world, runner.world.thing)
        for _ in range(after):
            runner.frame()
    frame = runner.frame().astype(int)
    if where != "probe":
        stats = runner.stats
        assert stats.reflection_views >= 1 and stats.reflection_path == runner.engine.reflection_system.path
    return frame


@pytest.mark.parametrize("where", ["per_mirror", "batched", "portal"])
def test_a_skin_is_bent_in_a_mirror_by_either_path_and_through_a_portal(scene, where):
    """The bar bent a quarter at the elbow, where the camera sees it only in a mirror's view
    (per mirror and batched) or through a portal: drawn there as the bar bent vertex by
    vertex is (and not as the bar as modelled); the bar is there to see (red)."""
    posed = seen_elsewhere(scene, where, skinned_bar(), Skin(np.stack([np.eye(4), elbow_matrix(math.pi / 2)])))
    by_hand = seen_elsewhere(scene, where, bent_by_hand(math.pi / 2))
    modelled = seen_elsewhere(scene, where, skinned_bar())
    assert same_picture(posed, by_hand)
    assert not same_picture(posed, modelled)
    assert (posed[..., 0] > posed[..., 2] + 40).sum() > 60   # (the bar there: no empty view)


def lamp_shadow(scene, spot: bool, mesh, *posed, size=(96, 72)) -> tuple[np.ndarray, np.ndarray]:
    """``mesh`` (with the components ``posed``) at the origin over a floor, lit only by a lamp
    above and to its right casting shadows: all round (its cube's faces, drawn in one
    layered pass) or, ``spot``, a 40-degree spot aimed past it (its one perspective map);
    seen from above.  The frame and the pixels the mesh itself covers (its id)."""
    from components import PointLight, look_rotation

    held = {}

    def build(world):
        look_from(world, (0.0, 4.5, 4.0), (-0.8, 0.0, -0.3), fov=55.0)
        lamp = glm.vec3(1.5, 3.0, 0.5)
        world.spawn(Transform(position=lamp, rotation=look_rotation(glm.vec3(-1.0, 0.0, 0.0) - lamp)),
                    PointLight(intensity=12.0, range=15.0, shadows=True, spot_angle=40.0 if spot else 180.0))
        world.spawn(Transform(), MeshRef(plane(8, 8)), Material(color=(0.6, 0.6, 0.6, 1.0)))
        held["mesh"] = world.spawn(Transform(), MeshRef(mesh), Material(color=RED), *posed)

    runner = scene(build, size)
    runner.frame()
    frame = runner.frame().astype(int)
    return frame, runner.ids() == held["mesh"]


@pytest.mark.parametrize("spot", [False, True], ids=["cube", "spot"])
def test_a_lamps_cube_and_a_spots_map_cast_the_bent_arms_shadow(scene, spot):
    """Lit only by a lamp (its shadow cube) or a spot (its one map): the floor round the arm
    bent a quarter at the elbow (every pixel the arm itself covers in none of the frames) is
    as the arm bent by hand leaves it, and not as the straight arm's shadow does."""
    bent, bent_at = lamp_shadow(scene, spot, skinned_bar(), Skin(np.stack([np.eye(4), elbow_matrix(math.pi / 2)])))
    hand, hand_at = lamp_shadow(scene, spot, bent_by_hand(math.pi / 2))
    straight, straight_at = lamp_shadow(scene, spot, skinned_bar())
    floor = ~(bent_at | hand_at | straight_at)
    assert bent_at.sum() > 50   # (the arm is in view)
    assert (np.abs(bent - hand).max(axis=-1)[floor] > 12).sum() <= 0.002 * floor.size
    assert (np.abs(bent - straight).max(axis=-1)[floor] > 20).sum() > 40   # (the shadows differ: the test sees them)


@pytest.mark.parametrize("where, watch_world", [("per_mirror", True), ("per_mirror", False), ("batched", True),
                                               ("probe", True)], ids=["per_mirror", "scene_version_alone", "batched",
                                                                      "probe"])
def test_a_new_pose_is_drawn_in_a_still_mirror_the_next_frame_and_in_a_probe_soon_after(scene, where, watch_world):
    """The camera and everything else still (the mirror's views kept from frame to frame), the
    arm given a new pose: the next frame's mirror shows the arm bent the new way, as the arm
    bent by hand does (so too with the reflect stage's check of the world's writes off and
    no shadow map drawn again, the arm casting none: the pose's upload moves the scene's
    version on); a chrome ball's probe (its faces recaptured after that frame's views,
    sampled from the next) the frame after."""
    def bend(world, entity):
        world.get(entity, Skin).joint_matrices = np.stack([np.eye(4), elbow_matrix(math.pi / 2)])

    def watch(runner):
        runner.engine.reflection_system.watch_world = watch_world

    kept = []
    posed = seen_elsewhere(scene, where, skinned_bar(), Skin(np.stack([np.eye(4), elbow_matrix(0.0)])),
                           frames=4, change=bend, after=1 if where == "probe" else 0, kept=kept, configure=watch,
                           casts=watch_world)
    if where != "probe":
        assert kept[0] >= 1   # (still before the new pose: the mirror's view was being kept)
    by_hand = seen_elsewhere(scene, where, bent_by_hand(math.pi / 2), casts=watch_world)
    modelled = seen_elsewhere(scene, where, skinned_bar(), casts=watch_world)
    assert same_picture(posed, by_hand) and not same_picture(posed, modelled)
