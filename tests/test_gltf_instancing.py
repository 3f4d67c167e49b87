"""glTF's ``EXT_mesh_gpu_instancing``: a node's mesh drawn at each instance's place.  A file
with three instances (rotations as floats, and as normalised shorts as glTF-Transform packs
them) loads as three parts sharing one mesh, each placed by the node's transform times its
own translation, rotation and scale (worked out here with glm); a malformed one is refused
naming the node."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from engine.assets.mesh import load_model
from engine.assets.models import spawn_model
from engine.core.errors import AssetError
from engine.core.world import World
from tests.test_gltf_accessors import FLAT, GlbWriter, float_positions

TRANSLATIONS = np.array([[0.0, 0.0, 0.0], [3.0, 0.0, -1.0], [-2.0, 0.5, 1.0]], np.float32)
TURNS = [glm.quat(), glm.angleAxis(math.radians(90.0), glm.vec3(0, 1, 0)),
         glm.angleAxis(math.radians(-30.0), glm.normalize(glm.vec3(1, 1, 0)))]
ROTATIONS = np.array([[q.x, q.y, q.z, q.w] for q in TURNS], np.float32)
SCALES = np.array([[1.0, 1.0, 1.0], [2.0, 2.0, 2.0], [0.5, 1.0, 1.5]], np.float32)


def instanced(tmp_path, packed_rotations: bool = False, change: dict | None = None):
    writer = GlbWriter()
    rotation = writer.accessor(np.round(ROTATIONS * 32767).astype(np.int16), "VEC4", 5122, normalized=True) \
        if packed_rotations else writer.accessor(ROTATIONS, "VEC4", 5126)
    attributes = {"TRANSLATION": writer.accessor(TRANSLATIONS, "VEC3", 5126), "ROTATION": rotation,
                  "SCALE": writer.accessor(SCALES, "VEC3", 5126)}
    attributes.update(change or {})
    node = {"translation": [0.0, 1.0, 0.0], "extensions": {"EXT_mesh_gpu_instancing": {"attributes": attributes}}}
    return writer.write(tmp_path / "forest.glb", {"POSITION": float_positions(writer)}, FLAT.indices, node=node,
                        extra={"extensionsUsed": ["EXT_mesh_gpu_instancing"],
                               "extensionsRequired": ["EXT_mesh_gpu_instancing"]})


@pytest.mark.parametrize("packed", [False, True])
def test_each_instance_is_a_part_placed_by_the_node_and_its_own_transform(tmp_path, packed):
    parts = load_model(instanced(tmp_path, packed))
    assert len(parts) == 3 and len({id(part.mesh) for part in parts}) == 1   # one mesh, drawn instanced
    places = zip(TRANSLATIONS.tolist(), TURNS, SCALES.tolist(), strict=True)
    expected = [glm.translate(glm.vec3(0, 1, 0)) * glm.translate(glm.vec3(*t)) * glm.mat4_cast(q)
                * glm.scale(glm.vec3(*s)) for t, q, s in places]
    found = sorted((np.array(part.local) for part in parts), key=lambda m: (m[0, 3], m[2, 3]))
    wanted = sorted((np.array(m) for m in expected), key=lambda m: (m[0, 3], m[2, 3]))
    for got, want in zip(found, wanted, strict=True):
        np.testing.assert_allclose(got, want, atol=1e-4 if packed else 1e-6)
    world = World("forest")
    spawn_model(world, instanced(tmp_path, packed))
    from components import MeshRef
    meshes = [ref.mesh for _, ref in world.query_one(MeshRef)]
    assert len(meshes) == 3 and len({id(m) for m in meshes}) == 1


@pytest.mark.parametrize("change, message", [
    ({"SCALE": 3}, r"its attributes' counts differ"),   # (accessor 3: the quad's four positions)
    ({"ROTATION": 2}, r"ROTATION must be VEC4"),
    ({"TRANSLATION": 99}, r"TRANSLATION: names accessor 99, which the file does not have"),
])
def test_a_malformed_instancing_is_refused_naming_the_node(tmp_path, change, message):
    with pytest.raises(AssetError, match=rf"forest\.glb.*node 0: EXT_mesh_gpu_instancing.*{message}"):
        load_model(instanced(tmp_path, change=change))


@pytest.mark.parametrize("clip", [False, True])
def test_an_instanced_nodes_own_morph_weights_and_their_clip_go_with_every_instance(tmp_path, clip):
    """The morphed sheet's node (its own weights (0.5, 1.0) over the mesh's (0.25, 0)) made two
    instances by EXT_mesh_gpu_instancing: each instance wears the node's weights, not the
    mesh's, and the node's "weights" clip (Breathe: (0, 0) to (1, 0.5) over 2 s) plays on each
    (half way: (0.5, 0.25))."""
    import base64

    from components import Animation, FromModel, Morph
    from engine.assets.mesh import load_model_file
    from systems.model_system import ModelSystem
    from tests.test_model_variants import edit_glb
    from tests.test_morph_targets import sheet_glb

    places = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]], np.float32)

    def instanced_node(doc: dict) -> None:
        blob = places.tobytes()
        doc["buffers"].append({"byteLength": len(blob),
                               "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()})
        doc["bufferViews"].append({"buffer": len(doc["buffers"]) - 1, "byteOffset": 0, "byteLength": len(blob)})
        doc["accessors"].append({"bufferView": len(doc["bufferViews"]) - 1, "componentType": 5126, "count": 2,
                                 "type": "VEC3"})
        doc["nodes"][0]["extensions"] = {"EXT_mesh_gpu_instancing": {
            "attributes": {"TRANSLATION": len(doc["accessors"]) - 1}}}
        doc["extensionsUsed"] = [*doc.get("extensionsUsed", []), "EXT_mesh_gpu_instancing"]
        if not clip:
            del doc["animations"]

    path = edit_glb(sheet_glb(tmp_path / "sheet.glb", node_weights=[0.5, 1.0]), instanced_node)
    parts = load_model_file(path).parts
    assert len(parts) == 2 and all(part.morph_weights == (0.5, 1.0) for part in parts), \
        [part.morph_weights for part in parts]
    world = World("instanced sheets")
    root = spawn_model(world, path)
    morphed = [world.get(part, Morph) for part, _ in world.query_one(FromModel)]
    assert len(morphed) == 2 and all(m.weights == (0.5, 1.0) for m in morphed)
    if clip:
        world.add_component(root, Animation(clip="Breathe", time=1.0, playing=False))
        ModelSystem(world).process(1 / 60)
        assert all(m.weights == pytest.approx((0.5, 0.25)) for m in morphed), [m.weights for m in morphed]
    world.close()
