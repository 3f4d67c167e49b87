"""Dual quaternion skinning (``Skin.skinning = "dual_quaternion"``; shaders/include/pose.glsl,
engine/core/skinning.py): two joints turning about one axis blend to a turn about that axis
by the normalised sum of their quaternions, 2 atan2(w sin(a / 2), 1 - w + w cos(a / 2)) at
weight w (the closed form written here), so a twisted bar keeps its thickness where linear
blending pinches it; drawn (directly, in a mirror and by its shadow) as the bar turned vertex
by vertex by that formula; a joint alone, scaled or not, moves its vertices as its matrix;
joints that only stretch (unevenly, sheared) and move blend as linear skinning does (their
stretches blend apart from their turns), drawn so; the far way round is never taken; boxes,
ray casts and bad values."""
from __future__ import annotations

import math

import numpy as np
import pytest

from components import ComponentValueError, Material, MeshRef, Mirror, Skin, Transform
from engine.assets.mesh import Mesh, quad
from engine.core.skinning import (
    blend_matrices,
    dual_quaternion_matrices,
    posed_bounds,
    posed_positions,
    skin_positions,
)
from engine.core.world import World
from engine.rules.raycast import raycast
from tests.test_skinning import RED, bar_arrays, bent_by_hand, elbow_matrix, frame_of, lit, same_picture, skinned_bar


def turn(axis: np.ndarray, angle: float, about: np.ndarray | None = None) -> np.ndarray:
    """A 4 x 4 turn by ``angle`` about ``axis`` (Rodrigues), through the point ``about``."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    m = np.eye(4)
    m[:3, :3] = np.eye(3) + math.sin(angle) * cross + (1 - math.cos(angle)) * cross @ cross
    if about is not None:
        m[:3, 3] = np.asarray(about) - m[:3, :3] @ np.asarray(about)
    return m


def blended_angle(weight: np.ndarray, angle: float) -> np.ndarray:
    """The turn two joints (none, and ``angle`` about one axis) blend to at ``weight`` on the
    second: the angle of the normalised sum of their quaternions."""
    return 2.0 * np.arctan2(weight * math.sin(angle / 2.0), 1.0 - weight + weight * math.cos(angle / 2.0))


TWIST = math.radians(160.0)
UP = np.array([0.0, 1.0, 0.0])


def twisted_by_hand(angle: float, axis=UP, about=None) -> Mesh:
    """The bar, each vertex turned about ``axis`` (through ``about``) by the blended angle at
    its elbow weight, its normal with it."""
    positions, normals, uvs, triangles, elbow = bar_arrays()
    out_p, out_n = [], []
    for p, n, w in zip(positions, normals, elbow, strict=True):
        m = turn(axis, float(blended_angle(w, angle)), about)
        out_p.append((m @ np.append(p, 1.0))[:3])
        out_n.append(m[:3, :3] @ n)
    return Mesh(np.array(out_p), np.array(out_n), uvs, triangles, name="turned by hand")


def test_two_joints_about_one_axis_blend_to_the_turn_the_formula_gives():
    positions, _, _, _, elbow = bar_arrays()
    joints = np.tile([0, 1], (len(positions), 1))
    weights = np.stack([1.0 - elbow, elbow], axis=1)
    for matrix, about in ((turn(UP, TWIST), None), (elbow_matrix(2.2), np.array([0.0, 1.0, 0.0]))):
        axis = UP if about is None else np.array([0.0, 0.0, 1.0])
        angle = TWIST if about is None else 2.2
        dual = skin_positions(positions, joints, weights, np.stack([np.eye(4), matrix]), dual_quaternion=True)
        expected = np.array([(turn(axis, float(blended_angle(w, angle)), about) @ np.append(p, 1.0))[:3]
                             for p, w in zip(positions, elbow, strict=True)])
        np.testing.assert_allclose(dual, expected, atol=1e-9)
    # Thickness: at the middle of the twist the bar's corners stay 0.15 sqrt 2 from its axis
    # (dual quaternions); linearly blended they come to |cos 80 degrees| of that.
    middle = np.abs(elbow - 0.5) < 1e-9
    twist = np.stack([np.eye(4), turn(UP, TWIST)])
    dual = skin_positions(positions, joints, weights, twist, dual_quaternion=True)[middle]
    linear = skin_positions(positions, joints, weights, twist)[middle]
    assert np.allclose(np.hypot(dual[:, 0], dual[:, 2]), 0.15 * math.sqrt(2.0))
    assert np.allclose(np.hypot(linear[:, 0], linear[:, 2]), 0.15 * math.sqrt(2.0) * abs(math.cos(TWIST / 2)))


def test_a_joint_alone_moves_its_vertices_as_its_matrix_scaled_or_not():
    rng = np.random.default_rng(4)
    matrices = []
    for scale in (1.0, 2.5, 0.4, -1.0):   # (-1: mirrored whole)
        m = turn(rng.normal(size=3), rng.uniform(-3.0, 3.0))
        m[:3, :3] *= scale
        m[:3, 3] = rng.normal(size=3)
        matrices.append(m)
    matrices = np.stack(matrices)
    joints = np.arange(4)[:, None].repeat(4, axis=1)
    weights = np.zeros((4, 4))
    weights[:, 0] = 1.0
    np.testing.assert_allclose(dual_quaternion_matrices(joints, weights, matrices), matrices, atol=1e-12)


def stretch_about(scale, shear: float = 0.0, about=(0.0, 1.0, 0.0)) -> np.ndarray:
    """A joint that squashes and stretches, not turning: ``scale`` along x, y, z, x sheared
    by ``shear`` along y, about the point ``about``."""
    m = np.eye(4)
    m[:3, :3] = np.diag(scale)
    m[0, 1] = shear
    m[:3, 3] = np.asarray(about, float) - m[:3, :3] @ np.asarray(about, float)
    return m


def test_a_joint_alone_stretched_unevenly_sheared_mirrored_or_flat_moves_its_vertices_as_its_matrix():
    rng = np.random.default_rng(7)
    twist = turn(rng.normal(size=3), 2.0)
    cases = [twist @ stretch_about((2.0, 0.5, 1.0)), stretch_about((2.0, 0.5, 1.0)) @ twist,   # stretched, turned
             twist @ stretch_about((1.5, 0.7, 1.2), shear=0.8),                                 # sheared
             twist @ stretch_about((-1.0, 1.0, 1.0)), stretch_about((0.5, -3.0, 2.0)) @ twist,  # mirrored
             twist @ stretch_about((0.0, 1.0, 1.0)), twist @ stretch_about((1.0, 0.0, 1.0)),    # flat
             twist @ stretch_about((0.0, 0.0, 2.0)), stretch_about((0.0, 0.0, 0.0))]           # a line, a point
    matrices = np.stack(cases)
    joints = np.arange(len(cases))[:, None].repeat(4, axis=1)
    weights = np.zeros((len(cases), 4))
    weights[:, 0] = 1.0
    np.testing.assert_allclose(dual_quaternion_matrices(joints, weights, matrices), matrices, atol=1e-12)


@pytest.mark.parametrize("turned", [False, True])
def test_joints_that_only_stretch_and_move_blend_as_linear_skinning(turned):
    """Joints sharing one turn (or none), each stretched its own way (uneven, sheared) and
    moved its own way: the dual quaternions blend to that turn and the weighted move, the
    stretches by weight, so each vertex goes where the matrices' weighted sum takes it (a
    mean scale a joint would not)."""
    rng = np.random.default_rng(11)
    common = turn(rng.normal(size=3), 1.3) if turned else np.eye(4)
    matrices = []
    for _ in range(4):
        m = common @ stretch_about(rng.uniform(0.3, 3.0, size=3), shear=rng.uniform(-1.0, 1.0),
                                   about=rng.normal(size=3))
        m[:3, 3] += rng.normal(size=3)
        matrices.append(m)
    matrices = np.stack(matrices)
    joints = np.stack([rng.permutation(4) for _ in range(60)])
    weights = rng.dirichlet(np.ones(4), size=60)
    np.testing.assert_allclose(dual_quaternion_matrices(joints, weights, matrices),
                               blend_matrices(joints, weights, matrices), atol=1e-9)


def test_the_short_way_round_is_taken():
    """A joint turned 350 degrees blends with one at rest as a turn of -10 degrees does (its
    quaternion, on the far side of the sphere, is turned back before the sum)."""
    positions, _, _, _, elbow = bar_arrays()
    joints = np.tile([0, 1], (len(positions), 1))
    weights = np.stack([1.0 - elbow, elbow], axis=1)
    far = skin_positions(positions, joints, weights, np.stack([np.eye(4), turn(UP, math.radians(350.0))]), True)
    near = skin_positions(positions, joints, weights, np.stack([np.eye(4), turn(UP, math.radians(-10.0))]), True)
    np.testing.assert_allclose(far, near, atol=1e-9)


@pytest.mark.parametrize("pose", ["twist", "bend"])
def test_the_gpu_draws_the_turn_the_formula_gives(scene, pose):
    """The bar on its Skin, blended as dual quaternions, seen directly, in a mirror behind it
    and by its shadow, draws the bar turned vertex by vertex by the formula; blended linearly
    (the twist pinches it thin) it does not.  Both ways of a bar bent about its elbow too."""
    matrix = turn(UP, TWIST) if pose == "twist" else elbow_matrix(2.2)
    by_hand = twisted_by_hand(TWIST) if pose == "twist" else \
        twisted_by_hand(2.2, np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]))

    def mirror(world):
        world.spawn(Transform(position=(0.0, 1.0, -1.5)), MeshRef(quad(4.0, 2.5)), Mirror())

    def skinned(skinning):
        def build(world):
            mirror(world)
            world.spawn(Transform(), MeshRef(skinned_bar()), Material(color=RED),
                        Skin(np.stack([np.eye(4), matrix]), skinning=skinning))
        return build

    def hand(world):
        mirror(world)
        world.spawn(Transform(), MeshRef(by_hand), Material(color=RED))

    dual, linear, drawn_by_hand = (frame_of(scene, lit(b)) for b in
                                   (skinned("dual_quaternion"), skinned("linear"), hand))
    assert same_picture(dual, drawn_by_hand)
    if pose == "twist":   # (a bend's linear blend differs at the elbow's inside, a few pixels here)
        assert not same_picture(linear, drawn_by_hand)
    assert (dual[..., 0] > dual[..., 2] + 60).sum() > 300   # (the bar and its reflection: no black frame)


def posed_by_the_twin(matrix: np.ndarray) -> Mesh:
    """The bar posed by the numpy twin's dual quaternion blend (joint 0 at rest, the elbow
    ``matrix``), its normals by the inverse transpose of each vertex's blended matrix."""
    positions, normals, uvs, triangles, elbow = bar_arrays()
    joints = np.tile([0, 1], (len(positions), 1))
    blended = dual_quaternion_matrices(joints, np.stack([1.0 - elbow, elbow], axis=1), np.stack([np.eye(4), matrix]))
    moved = np.einsum("vrc,vc->vr", blended[:, :3, :3], positions) + blended[:, :3, 3]
    turned = np.einsum("vcr,vc->vr", np.linalg.inv(blended[:, :3, :3]), normals)
    return Mesh(moved, turned / np.linalg.norm(turned, axis=1, keepdims=True), uvs, triangles, name="by the twin")


@pytest.mark.parametrize("pose", ["stretch", "twist_and_stretch"])
def test_a_joint_squashed_and_stretched_is_drawn_as_its_blend(scene, pose):
    """The elbow stretched unevenly and sheared about itself (no turn), blended as dual
    quaternions: drawn as the bar bent by linear skinning written out by hand (the same
    blend for joints that do not turn); twisted besides: as the numpy twin poses it.  Both
    seen directly and in a mirror behind."""
    stretch = stretch_about((2.2, 1.4, 0.5), shear=0.6)
    matrix = stretch if pose == "stretch" else turn(UP, TWIST) @ stretch
    by_hand = bent_by_hand(0.0, at=matrix) if pose == "stretch" else posed_by_the_twin(matrix)

    def build(mesh, *skin):
        def spawn(world):
            world.spawn(Transform(position=(0.0, 1.0, -1.5)), MeshRef(quad(4.0, 2.5)), Mirror())
            world.spawn(Transform(), MeshRef(mesh), Material(color=RED), *skin)
        return lit(spawn)

    dual = frame_of(scene, build(skinned_bar(), Skin(np.stack([np.eye(4), matrix]), skinning="dual_quaternion")))
    drawn_by_hand = frame_of(scene, build(by_hand))
    assert same_picture(dual, drawn_by_hand)
    assert (dual[..., 0] > dual[..., 2] + 60).sum() > 300   # (the bar and its reflection: no black frame)


def test_switching_a_skin_to_dual_quaternions_redraws_it(scene):
    runner = scene(lit(lambda world: world.spawn(Transform(), MeshRef(skinned_bar()), Material(color=RED),
                                                 Skin(np.stack([np.eye(4), turn(UP, TWIST)])))), (160, 120))
    runner.frame()
    linear = runner.frame().astype(int)
    ((_, skin),) = runner.world.query_one(Skin)
    skin.skinning = "dual_quaternion"
    runner.frame()
    dual = runner.frame().astype(int)
    by_hand = frame_of(scene, lit(lambda world: world.spawn(Transform(), MeshRef(twisted_by_hand(TWIST)),
                                                              Material(color=RED))))
    assert same_picture(dual, by_hand) and not same_picture(linear, by_hand)


def test_the_box_and_ray_casts_hold_the_dual_quaternion_pose():
    mesh = skinned_bar()
    matrices = np.stack([np.eye(4), turn(UP, TWIST)])
    points = posed_positions(mesh, matrices, None, dual_quaternion=True)
    low, high = posed_bounds(mesh, matrices, None, dual_quaternion=True)
    assert (points >= low - 1e-9).all() and (points <= high + 1e-9).all()
    # A ray at the twist's middle, 0.12 m beside the axis: through the bar (dual quaternions
    # keep it 0.15 m thick there), past it (blended linearly it is pinched to 0.05 m).
    for skinning, hits in (("dual_quaternion", True), ("linear", False)):
        world = World()
        entity = world.spawn(Transform(), MeshRef(mesh), Material(), Skin(matrices, skinning=skinning))
        hit = raycast(world, (0.12, 1.0, 5.0), (0.0, 0.0, -1.0))
        assert (hit is not None and hit.entity == entity) == hits, skinning


def test_a_bad_skinning_is_refused_when_given():
    with pytest.raises(ComponentValueError, match="Skin.skinning"):
        Skin(skinning="dq")
    skin = Skin()
    with pytest.raises(ComponentValueError, match="Skin.skinning"):
        skin.skinning = "spherical"


def test_a_models_skinned_parts_take_its_skinning(tmp_path):
    """``spawn_model(..., skinning="dual_quaternion")`` and ``Model.skinning`` give each
    skinned part's Skin that blend; changing it makes the parts again with the new one; a
    level file names it; a bad one is refused."""
    from components import FromModel, Model
    from engine.assets.level_read import load_level
    from engine.assets.models import spawn_model
    from engine.core.errors import AssetError
    from systems.model_system import ModelSystem
    from tests.test_skinning import arm_glb

    path = arm_glb(tmp_path / "arm.glb")
    world = World("arm")
    root = spawn_model(world, path, skinning="dual_quaternion")
    ((part, _),) = list(world.query_one(FromModel))
    assert world.get(part, Skin).skinning == "dual_quaternion"
    world.get(root, Model).skinning = "linear"
    ModelSystem(world).process(1 / 60)
    skins = [world.get(entity, Skin).skinning for entity, _ in world.query_one(FromModel) if world.has(entity, Skin)]
    assert skins == ["linear"]
    level = tmp_path / "arm.toml"
    level.write_text('[level]\nname = "arm"\n[[entity]]\nname = "arm"\nTransform = {}\n'
                     'Model = { file = "arm.glb", skinning = "dual_quaternion" }\n')
    loaded = World("level")
    load_level(level).spawn(loaded)
    ModelSystem(loaded).process(1 / 60)
    assert [s.skinning for _, s in loaded.query_one(Skin)] == ["dual_quaternion"]
    with pytest.raises(AssetError, match="Model.skinning"):
        spawn_model(World("bad"), path, skinning="dq")
