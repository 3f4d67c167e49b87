"""Morph targets: a mesh wearing its blend shapes by a ``Morph``'s weights (``Mesh.morph_positions``,
``morph_normals``), drawn in every view and shadow map as the offsets added here by hand, with
a Skin after them, from a glTF's targets (sparse ones too), its mesh's and nodes' weights and
a clip's ``weights`` channel, and refused plainly where they cannot be drawn."""
from __future__ import annotations

import base64
import math
from pathlib import Path

import numpy as np
import pytest

from components import ComponentValueError, FromModel, Material, MeshRef, Mirror, Morph, Skin, Transform
from engine.assets.mesh import Mesh, load_model_file, quad
from engine.assets.models import spawn_model
from engine.core.errors import AssetError
from engine.core.world import World
from engine.rules.raycast import raycast
from tests.test_materials_from_files import write_glb
from tests.test_model_variants import edit_glb
from tests.test_skinning import (
    RED,
    bar_arrays,
    elbow_matrix,
    frame_of,
    lamp_shadow,
    lit,
    same_picture,
    seen_elsewhere,
)

N = 12  # a sheet's cells a side


def sheet_arrays():
    """A 2 x 2 sheet standing in the xy plane at z = 0 from y = 0.5 to 2.5, facing +z, (N+1)^2
    vertices; and its two targets: 0 a round bump out towards +z in its middle (its normals
    tilted), 1 its right half pushed up by 0.5."""
    u, v = np.meshgrid(np.linspace(0.0, 1.0, N + 1), np.linspace(0.0, 1.0, N + 1), indexing="xy")
    positions = np.stack([u.ravel() * 2 - 1, v.ravel() * 2 + 0.5, np.zeros(u.size)], axis=1)
    normals = np.tile([0.0, 0.0, 1.0], (u.size, 1))
    uvs = np.stack([u.ravel(), v.ravel()], axis=1)
    triangles = []
    for row in range(N):
        for column in range(N):
            a = row * (N + 1) + column
            triangles += [(a, a + 1, a + N + 2), (a, a + N + 2, a + N + 1)]
    r2 = (positions[:, 0] ** 2 + (positions[:, 1] - 1.5) ** 2)
    bump = np.zeros((u.size, 3))
    bump[:, 2] = 0.6 * np.exp(-3.0 * r2)
    bump_normals = np.zeros((u.size, 3))
    bump_normals[:, 0] = 0.5 * positions[:, 0] * np.exp(-3.0 * r2)
    bump_normals[:, 1] = 0.5 * (positions[:, 1] - 1.5) * np.exp(-3.0 * r2)
    lift = np.zeros((u.size, 3))
    lift[:, 1] = np.where(positions[:, 0] > 0.0, 0.5, 0.0)
    return positions, normals, uvs, np.array(triangles), np.stack([bump, lift]), np.stack([bump_normals,
                                                                                           np.zeros_like(lift)])


def morphed_sheet() -> Mesh:
    positions, normals, uvs, triangles, offsets, normal_offsets = sheet_arrays()
    return Mesh(positions, normals, uvs, triangles, name="sheet", morph_positions=offsets,
                morph_normals=normal_offsets)


def sheet_by_hand(weights) -> Mesh:
    """The sheet with each target's offsets times its weight added, vertex by vertex."""
    positions, normals, uvs, triangles, offsets, normal_offsets = sheet_arrays()
    moved_p, moved_n = positions.copy(), normals.copy()
    for weight, offset, normal_offset in zip(weights, offsets, normal_offsets, strict=True):
        moved_p += weight * offset
        moved_n += weight * normal_offset
    moved_n /= np.linalg.norm(moved_n, axis=1, keepdims=True)
    return Mesh(moved_p, moved_n, uvs, triangles, name="sheet by hand")


def test_a_morph_wears_the_targets_as_the_offsets_added_by_hand(scene):
    """The sheet at weights (0.8, 0.6): its bump and lifted half, lit, shadowed on the floor and
    with its bump's shading from the tilted normals, draw as the sheet moved by hand; at
    (0, 0) as modelled."""
    def wearing(weights):
        return lambda w: w.spawn(Transform(), MeshRef(morphed_sheet()), Material(color=RED), Morph(weights))

    def by_hand(weights):
        return lambda w: w.spawn(Transform(), MeshRef(sheet_by_hand(weights)), Material(color=RED))

    worn, hand = frame_of(scene, lit(wearing((0.8, 0.6)))), frame_of(scene, lit(by_hand((0.8, 0.6))))
    flat = frame_of(scene, lit(by_hand((0.0, 0.0))))
    assert same_picture(worn, hand) and not same_picture(worn, flat)
    assert same_picture(frame_of(scene, lit(wearing((0.0, 0.0)))), flat)
    assert (worn[..., 0] > worn[..., 2] + 60).sum() > 300


def test_a_new_weight_is_drawn_the_next_frame_and_its_box_holds_it(scene):
    holder = {}

    def build(world):
        holder["sheet"] = world.spawn(Transform(), MeshRef(morphed_sheet()), Material(color=RED), Morph((0.0, 0.0)))

    runner = scene(lit(build), (160, 120))
    runner.frame()
    runner.world.get(holder["sheet"], Morph).weights = (1.0, -1.0)   # (a negative weight: the half pulled down)
    worn = runner.frame().astype(int)
    assert same_picture(worn, frame_of(scene, lit(lambda w: w.spawn(Transform(), MeshRef(sheet_by_hand((1.0, -1.0))),
                                                                    Material(color=RED)))))
    (batch,) = [b for b in runner.engine.renderer.batches.values() if b.morphed]
    lo, hi = batch.row_boxes[0]
    placed = sheet_by_hand((1.0, -1.0)).positions
    assert (placed >= lo - 1e-5).all() and (placed <= hi + 1e-5).all()
    assert lo[1] < 0.1 and hi[2] > 0.55   # (the sheet as modelled: y from 0.5, z 0)


def test_morph_targets_then_joints(scene):
    """The bar with a target that swells its middle, worn at 0.5 and then bent at the elbow:
    the swelling is bent with it, as the bar swollen then bent by hand."""
    positions, normals, uvs, triangles, elbow = bar_arrays()
    swell = np.zeros_like(positions)
    swell[:, [0, 2]] = positions[:, [0, 2]] * np.exp(-8.0 * (positions[:, 1] - 0.6) ** 2)[:, None]
    mesh = Mesh(positions, normals, uvs, triangles, name="arm", joints=np.tile([0, 1], (len(positions), 1)),
                weights=np.stack([1.0 - elbow, elbow], axis=1), morph_positions=swell[None])
    swollen = positions + 0.5 * swell
    moved = elbow_matrix(math.pi / 2)
    bent = [((1 - w) * np.eye(4) + w * moved) @ np.append(p, 1.0) for p, w in zip(swollen, elbow, strict=True)]
    turned = [np.linalg.inv(((1 - w) * np.eye(4) + w * moved)[:3, :3]).T @ n
              for n, w in zip(normals, elbow, strict=True)]
    hand = Mesh(np.array(bent)[:, :3], np.array(turned), uvs, triangles, name="by hand")
    posed = frame_of(scene, lit(lambda w: w.spawn(Transform(), MeshRef(mesh), Material(color=RED), Morph((0.5,)),
                                                   Skin(np.stack([np.eye(4), moved])))))
    assert same_picture(posed, frame_of(scene, lit(lambda w: w.spawn(Transform(), MeshRef(hand), Material(color=RED)))))


def test_a_ray_hits_the_bump_where_it_is_worn(ctx):
    world = World("aim")
    entity = world.spawn(Transform(), MeshRef(morphed_sheet()), Morph((1.0, 0.0)))
    from systems.transform_system import TransformSystem
    TransformSystem(world).process(0.0)
    hit = raycast(world, (0.0, 1.5, 5.0), (0.0, 0.0, -1.0))
    assert hit is not None and hit.distance == pytest.approx(5.0 - 0.6, abs=0.02)
    world.get(entity, Morph).weights = (0.0, 0.0)
    assert raycast(world, (0.0, 1.5, 5.0), (0.0, 0.0, -1.0)).distance == pytest.approx(5.0, abs=1e-6)


def test_a_morphed_entity_gone_takes_its_row_and_textures(scene):
    holder = {}
    runner = scene(lit(lambda w: holder.update(sheet=w.spawn(Transform(), MeshRef(morphed_sheet()), Material(color=RED),
                                                             Morph((0.5, 0.5))))), (64, 48))
    runner.frame()
    renderer = runner.engine.renderer
    before = renderer.resource_counts()
    assert before["pose_rows"] == 1 and len(renderer.pose_rows) == 1
    runner.world.delete_entity(holder["sheet"])
    runner.frame()
    after = renderer.resource_counts()
    assert after["pose_rows"] == 0 and after["meshes"] == before["meshes"] - 1
    assert not [b for b in renderer.batches.values() if b.morphed]


def test_bad_morphs_are_refused_when_given():
    world = World("refusals")
    sheet = morphed_sheet()
    for bad, match in (((math.nan, 0.0), "finite"), ((99.0, 0.0), r"within \+-16"), ("ab", "numbers"),
                       (tuple([0.0] * 17), "at most 16")):
        with pytest.raises(ComponentValueError, match=match):
            Morph(bad)
    with pytest.raises(ComponentValueError, match=r"holds 1 weights, but mesh 'sheet' has 2 morph targets"):
        world.spawn(Transform(), MeshRef(sheet), Morph((1.0,)))
    with pytest.raises(ComponentValueError, match="which has no morph targets"):
        world.spawn(Transform(), MeshRef(quad(1.0, 1.0)), Morph(()))
    entity = world.spawn(Transform(), MeshRef(sheet), Morph((0.0, 0.0)))
    with pytest.raises(ComponentValueError, match="holds 3 weights"):
        world.get(entity, Morph).weights = (0.0, 0.0, 0.0)
    with pytest.raises(ComponentValueError, match="a Morph on a Mirror"):
        world.add_component(entity, Mirror())
    positions, normals, uvs, triangles, offsets, _ = sheet_arrays()
    with pytest.raises(AssetError, match=r"morph_positions must be 1 to 16 targets .* shape \(T, 169, 3\)"):
        Mesh(positions, normals, uvs, triangles, morph_positions=offsets[:, :5])
    with pytest.raises(AssetError, match="NaN or infinite offsets"):
        Mesh(positions, normals, uvs, triangles, morph_positions=offsets * np.nan)
    with pytest.raises(AssetError, match="morph_normals without morph_positions"):
        Mesh(positions, normals, uvs, triangles, morph_normals=offsets)


# --- glTF ------------------------------------------------------------------------------------

def sheet_glb(path: Path, sparse: bool = True, node_weights: list | None = None) -> Path:
    """The sheet as a glTF: target 0 (the bump) dense, target 1 (the lift) sparse (only the
    vertices it moves stored) unless ``sparse`` is False; the mesh's weights (0.25, 0.0),
    ``node_weights`` the node's own; clip "Breathe" takes the weights linearly from (0, 0) at
    0 s to (1, 0.5) at 2 s."""
    positions, normals, uvs, triangles, offsets, normal_offsets = sheet_arrays()
    write_glb(path, Mesh(positions, normals, uvs, triangles, name="sheet"),
              {"name": "paint", "pbrMetallicRoughness": {"baseColorFactor": list(RED)}}, [])
    moved = np.flatnonzero(np.abs(offsets[1]).sum(axis=1) > 0).astype(np.uint16)
    arrays = [offsets[0].astype(np.float32), normal_offsets[0].astype(np.float32),
              moved if sparse else offsets[1].astype(np.float32),
              offsets[1][moved].astype(np.float32) if sparse else np.zeros((1, 3), np.float32),
              np.array([0.0, 2.0], np.float32), np.array([0.0, 0.0, 1.0, 0.5], np.float32)]

    def change(doc: dict) -> None:
        blob = bytearray()
        views = []
        for array in arrays:
            while len(blob) % 4:
                blob.append(0)
            views.append(len(doc["bufferViews"]))
            doc["bufferViews"].append({"buffer": len(doc["buffers"]), "byteOffset": len(blob),
                                       "byteLength": array.nbytes})
            blob.extend(array.tobytes())
        doc["buffers"].append({"byteLength": len(blob),
                               "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(blob)).decode()})
        first = len(doc["accessors"])
        count = len(positions)
        doc["accessors"] += [
            {"bufferView": views[0], "componentType": 5126, "count": count, "type": "VEC3",
             "min": offsets[0].min(0).tolist(), "max": offsets[0].max(0).tolist()},
            {"bufferView": views[1], "componentType": 5126, "count": count, "type": "VEC3"},
            ({"componentType": 5126, "count": count, "type": "VEC3",
              "sparse": {"count": len(moved), "indices": {"bufferView": views[2], "componentType": 5123},
                         "values": {"bufferView": views[3]}}} if sparse else
             {"bufferView": views[2], "componentType": 5126, "count": count, "type": "VEC3"}),
            {"bufferView": views[4], "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0.0], "max": [2.0]},
            {"bufferView": views[5], "componentType": 5126, "count": 4, "type": "SCALAR"}]
        doc["meshes"][0]["primitives"][0]["targets"] = [{"POSITION": first, "NORMAL": first + 1},
                                                        {"POSITION": first + 2}]
        doc["meshes"][0]["weights"] = [0.25, 0.0]
        if node_weights is not None:
            doc["nodes"][0]["weights"] = node_weights
        doc["animations"] = [{"name": "Breathe", "samplers": [{"input": first + 3, "output": first + 4}],
                              "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}]}]
    return edit_glb(path, change)


@pytest.mark.parametrize("sparse", [True, False])
def test_a_files_targets_dense_or_sparse_are_read_as_the_offsets(tmp_path, sparse):
    (part,) = load_model_file(sheet_glb(tmp_path / "sheet.glb", sparse)).parts
    _, _, _, _, offsets, normal_offsets = sheet_arrays()
    np.testing.assert_allclose(part.mesh.morph_positions, offsets, atol=1e-6)
    np.testing.assert_allclose(part.mesh.morph_normals[0], normal_offsets[0], atol=1e-6)
    assert part.morph_weights == (0.25, 0.0)
    (own,) = load_model_file(sheet_glb(tmp_path / "own.glb", sparse, [0.5, 1.0])).parts
    assert own.morph_weights == (0.5, 1.0)   # the node's weights over its mesh's


def test_a_models_clip_plays_its_weights(scene, tmp_path):
    """The file's weights at rest; half way through "Breathe" (0.5, 0.25), drawn as the sheet
    moved by hand there."""
    from components import Animation
    from systems.model_system import ModelSystem

    path = sheet_glb(tmp_path / "sheet.glb")
    world = World("breathing")
    root = spawn_model(world, path)
    ((part, _),) = list(world.query_one(FromModel))
    assert world.get(part, Morph).weights == (0.25, 0.0)
    world.add_component(root, Animation(clip="Breathe", time=1.0, playing=False))
    ModelSystem(world).process(1 / 60)
    assert world.get(part, Morph).weights == pytest.approx((0.5, 0.25))

    def animated(w):
        w.add_component(spawn_model(w, path), Animation(clip="Breathe", time=1.0, playing=False))

    worn = frame_of(scene, lit(animated), frames=3)
    assert same_picture(worn, frame_of(scene, lit(lambda w: w.spawn(Transform(), MeshRef(sheet_by_hand((0.5, 0.25))),
                                                                   Material(color=RED)))))


@pytest.mark.parametrize(("change", "message"), [
    (lambda doc: doc["meshes"][0].update(weights=[1.0]), r"mesh 0: weights must be 2 finite numbers"),
    (lambda doc: doc["nodes"][0].update(weights=[1.0, 2.0, 3.0]), r"node 0: weights must be 2 finite numbers"),
    (lambda doc: doc["meshes"][0]["primitives"][0].update(targets=[{}] * 17), r"has 17 morph targets; .* at most 16"),
    (lambda doc: doc["meshes"][0]["primitives"].append(dict(doc["meshes"][0]["primitives"][0], targets=[{}])),
     r"its primitives' targets must be lists of one length"),
    (lambda doc: doc["accessors"][-3]["sparse"].update(count=500), r"sparse.count must be an integer in 1..169"),
    (lambda doc: doc["meshes"][0]["primitives"][0].pop("targets") and doc["meshes"][0].pop("weights"),
     r"animates the morph weights of node 0, whose mesh has no morph targets"),
])
def test_malformed_targets_in_a_file_are_refused_naming_them(tmp_path, change, message):
    with pytest.raises(AssetError, match=message):
        load_model_file(edit_glb(sheet_glb(tmp_path / "sheet.glb"), change))


def test_targets_past_what_the_offsets_texture_holds_are_refused_naming_the_mesh(scene):
    """A context whose textures are at most 2 rows (its reported limit lowered): the sheet's
    169 vertices x 2 targets need a 1024 x 1 texture of offsets (drawn); with 16 targets, past
    the limit, the entity is refused naming the mesh and the limit, and nothing is made."""
    from dataclasses import replace

    from engine.core.errors import GLLimitError

    positions, normals, uvs, triangles, offsets, _ = sheet_arrays()
    many = Mesh(positions, normals, uvs, triangles, name="many targets", morph_positions=np.repeat(offsets, 8, axis=0))
    runner = scene(lit(lambda w: None), (32, 24))
    renderer = runner.engine.renderer
    runner.frame()   # (the sun's shadow atlas made first: under the lowered limit it would be refused too)
    renderer.caps = replace(renderer.caps, max_texture_size=2)
    runner.world.spawn(Transform(), MeshRef(morphed_sheet()), Material(color=RED), Morph((0.5, 0.5)))
    runner.frame()
    meshes = renderer.resource_counts()["meshes"]
    crowd = runner.world.spawn(Transform(), MeshRef(many), Material(color=RED), Morph(tuple([0.1] * 16)))
    with pytest.raises(GLLimitError, match=rf"entity {crowd}: mesh 'many targets': 169 vertices x 16 morph targets "
                                           r"need a 1024x6 texture .* 2 rows at most \(GL_MAX_TEXTURE_SIZE\)"):
        runner.frame()
    assert renderer.resource_counts()["meshes"] == meshes


@pytest.mark.parametrize("where", ["per_mirror", "batched", "portal", "probe"])
def test_a_morph_is_worn_in_a_mirror_by_either_path_through_a_portal_and_in_a_probe(scene, where):
    """The sheet at weights (0.8, 0.6), where the camera sees it only in a mirror's view (per
    mirror and batched), through a portal or in a chrome ball's cube probe: drawn there as
    the sheet moved by hand is (its lifted half, its bump), and not as the flat sheet."""
    worn = seen_elsewhere(scene, where, morphed_sheet(), Morph((0.8, 0.6)))
    hand = seen_elsewhere(scene, where, sheet_by_hand((0.8, 0.6)))
    flat = seen_elsewhere(scene, where, sheet_by_hand((0.0, 0.0)))
    assert same_picture(worn, hand) and not same_picture(worn, flat)
    assert (worn[..., 0] > worn[..., 2] + 40).sum() > 300   # (the sheet there: no empty view)


@pytest.mark.parametrize("spot", [False, True], ids=["cube", "spot"])
def test_a_lamps_cube_and_a_spots_map_cast_the_worn_sheets_shadow(scene, spot):
    """Lit only by a lamp (its shadow cube) or a spot (its one map): the floor round the sheet
    at weights (0.8, 0.6) (every pixel the sheet itself covers in none of the frames) is as
    the sheet moved by hand leaves it, and not as the flat sheet's shadow does."""
    worn, worn_at = lamp_shadow(scene, spot, morphed_sheet(), Morph((0.8, 0.6)))
    hand, hand_at = lamp_shadow(scene, spot, sheet_by_hand((0.8, 0.6)))
    flat, flat_at = lamp_shadow(scene, spot, sheet_by_hand((0.0, 0.0)))
    floor = ~(worn_at | hand_at | flat_at)
    assert worn_at.sum() > 100   # (the sheet is in view)
    assert (np.abs(worn - hand).max(axis=-1)[floor] > 12).sum() <= 0.002 * floor.size
    assert (np.abs(worn - flat).max(axis=-1)[floor] > 20).sum() > 40   # (the shadows differ: the test sees them)
