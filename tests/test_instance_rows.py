"""The instance rows' matrices and boxes, whichever path writes them (engine/render/instances.py).

Many movers a frame take array paths (normal matrices by cofactors over all rows at once,
boxes axis by axis without placing corners); a few take GLM's calls.  Both must give what
GLM and the eight placed corners give, computed here independently.
"""
from __future__ import annotations

import numpy as np
from pyglm import glm

from engine.assets.mesh import box
from engine.render.instances import _NORMALS_ON_ARRAYS, GpuMesh, InstanceBatch, normal_matrices


def _models(count: int, seed: int) -> list[glm.mat4]:
    """Poses with every kind of scale (tiny, huge, negative) and some arbitrary matrices."""
    rng = np.random.default_rng(seed)
    models = []
    for i in range(count):
        if i % 4 == 3:
            models.append(glm.mat4(*[float(v) for v in rng.normal(size=16)]))
            continue
        rotation = glm.normalize(glm.quat(*[float(v) for v in rng.normal(size=4)]))
        scale = glm.vec3(*[float(v) for v in np.exp(rng.normal(size=3) * 2.0) * rng.choice([-1.0, 1.0], 3)])
        position = glm.vec3(*[float(v) for v in rng.normal(size=3) * 50.0])
        models.append(glm.translate(position) * glm.mat4_cast(rotation) * glm.scale(scale))
    return models


def _flat(models: list[glm.mat4]) -> np.ndarray:
    return np.frombuffer(glm.array(models).to_bytes(), np.float32).reshape(-1, 16)


def test_normal_matrices_on_arrays_are_glms_bits():
    models = _models(2000, seed=1)
    expected = np.frombuffer(glm.array([glm.transpose(glm.inverse(glm.mat3(m))) for m in models]).to_bytes(),
                             np.float32).reshape(-1, 9)
    got = normal_matrices(_flat(models).copy())
    assert got.dtype == np.float32 and got.shape == (2000, 9)
    assert np.array_equal(got.view(np.uint32), expected.view(np.uint32))  # the same bits, not just close
    # And what they mean: the inverse transpose of the upper 3x3, by numpy in double.
    upper = _flat(models).astype(np.float64).reshape(-1, 4, 4)[:, :3, :3]  # [column, row]
    # The matrix as maths writes it is upper transposed; its inverse transpose, stored by
    # columns, is its inverse's [row][column]: the inverse read as [column][row].
    want = np.linalg.inv(upper.transpose(0, 2, 1))
    assert np.allclose(got.reshape(-1, 3, 3), want, rtol=1e-3, atol=1e-3 * np.abs(want).max(axis=(1, 2))[:, None, None])


def test_rows_and_boxes_agree_with_placed_corners_on_both_paths(ctx):
    mesh = box((0.8, 1.2, 0.4))
    batch = InstanceBatch(ctx, GpuMesh(ctx, mesh), None)
    try:
        many, few = _NORMALS_ON_ARRAYS + 8, 3
        entities = list(range(1, many + few + 1))
        for entity in entities:
            batch.add(entity)
        models = _models(many + few, seed=2)
        batch.write_transforms(entities[:many], models[:many])   # the array path
        batch.write_transforms(entities[many:], models[many:])   # GLM's, a row at a time
        batch.upload()
        normals = np.frombuffer(glm.array([glm.transpose(glm.inverse(glm.mat3(m))) for m in models]).to_bytes(),
                                np.float32).reshape(-1, 9)
        rows = [batch.row_of[entity] for entity in entities]
        assert np.array_equal(batch.rows["model"][rows], _flat(models))
        assert np.array_equal(batch.rows["normal_matrix"][rows].view(np.uint32), normals.view(np.uint32))
        # Each row's box: the mesh's eight box corners placed by its matrix, least and most.
        lo, hi = mesh.positions.min(axis=0), mesh.positions.max(axis=0)
        corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        placed = np.array([[corners @ m for m in _flat([model]).astype(np.float64).reshape(-1, 4, 4)][0]
                           for model in models])[..., :3]
        assert np.allclose(batch._row_boxes[rows, 0], placed.min(axis=1), rtol=1e-12, atol=1e-9)
        assert np.allclose(batch._row_boxes[rows, 1], placed.max(axis=1), rtol=1e-12, atol=1e-9)
        box_lo, box_hi = batch.box
        assert np.allclose(box_lo, placed.min(axis=(0, 1))) and np.allclose(box_hi, placed.max(axis=(0, 1)))
        # Moving one row moves the changed box to hold where it was and where it is.
        batch.take_changed_box()
        was = batch._row_boxes[rows[0]].copy()
        batch.write_transforms([entities[0]], [glm.translate(glm.vec3(500.0, 0.0, 0.0)) * models[0]])
        batch.upload()
        changed_lo, changed_hi = batch.take_changed_box()
        now = batch._row_boxes[rows[0]]
        assert np.allclose(changed_lo, np.minimum(was[0], now[0]))
        assert np.allclose(changed_hi, np.maximum(was[1], now[1]))
        assert now[0][0] > was[0][0] + 499.0
    finally:
        batch.release()


def test_the_same_movers_every_frame_keep_their_rows_right_when_one_changes_batch_or_goes(scene):
    """The extract stage reuses last frame's movers by batch, and a batch its movers' rows,
    while the same entities move and none changed batch or place: each row must still hold
    its entity's world matrix when a mover changes mesh (another batch), one is deleted (a
    row filled from the last) and one more starts moving."""
    from components import Material, MeshRef, Transform
    from engine.assets.mesh import sphere
    from tests.support import own_mesh

    # Meshes of their own (a generated shape of another size shares its unit's batch).
    cube, ball, post = own_mesh(box((0.3, 0.3, 0.3))), own_mesh(sphere(0.2)), own_mesh(box((0.1, 0.5, 0.1)))
    movers: list[int] = []
    posts: list[int] = []
    clock = [0.0]

    def build(world):
        from engine.core.game import spawn_camera
        spawn_camera(world, position=(0.0, 6.0, 12.0), pitch=-25.0, fly=False)
        for i in range(60):
            entity = world.spawn(Transform(position=(i % 10 - 5.0, 0.0, i // 10 - 3.0)), MeshRef(cube), Material())
            if i % 3 == 0:
                movers.append(entity)
        for i in range(5):  # a batch of few movers (their rows stay where they are), the last one moving
            posts.append(world.spawn(Transform(position=(i - 2.0, 0.0, 4.0)), MeshRef(post), Material()))
            if i % 2 == 0:
                movers.append(posts[-1])

    def update(world, dt):
        clock[0] += dt
        for n, entity in enumerate(movers):
            if world.exists(entity):
                t = world.get(entity, Transform)
                t.rotation = glm.angleAxis(clock[0] * (1.0 + n), glm.vec3(0.0, 1.0, 0.0))
                t.position = glm.vec3(t.position.x, 0.3 * np.sin(clock[0] * 3.0 + n), t.position.z)

    runner = scene(build)
    runner.engine.game._update = update  # tests.support.FunctionGame's update
    world = runner.world

    def check():
        batches = runner.engine.renderer.batches.values()
        seen = 0
        for batch in batches:
            for entity, row in batch.row_of.items():
                t = world.get(entity, Transform)  # a root: its pose is its world matrix
                pose = glm.translate(t.position) * glm.mat4_cast(t.rotation) * glm.scale(t.scale)
                model = np.frombuffer(glm.array([pose]).to_bytes(), np.float32)
                assert np.array_equal(batch.rows["model"][row], model), entity
                normal = glm.transpose(glm.inverse(glm.mat3(pose)))
                assert np.array_equal(batch.rows["normal_matrix"][row],
                                      np.frombuffer(glm.array([normal]).to_bytes(), np.float32)), entity
                seen += 1
        assert seen == len([e for e, _ in world.query(MeshRef, Transform)])

    for _ in range(4):
        runner.frame()
    check()
    world.get(movers[3], MeshRef).mesh = ball    # a mover to another batch
    runner.frame()
    check()
    world.delete_entity(movers[0])               # a mover's row refilled from the batch's last
    runner.frame()
    check()
    # A still post deleted: its row is refilled from the batch's last, a mover's (the same
    # movers, one on another row).
    batch = next(b for b in runner.engine.renderer.batches.values() if posts[0] in b.row_of)
    assert batch.entity_at[-1] == posts[-1] and posts[-1] in movers and batch.count == 5
    world.delete_entity(posts[1])
    for _ in range(3):
        runner.frame()
        check()


def test_a_few_movers_rows_are_the_array_paths_bits_and_a_kept_union_is_the_rows_union(ctx, monkeypatch):
    """A frame's few movers are measured in Python floats (``_measure_few``), many on arrays:
    two batches given the same moves, one each way, hold the same boxes bit for bit and the
    same changed box; the union a batch keeps while its movers leave it the same numbers
    is, every frame, the least and greatest of its rows (moves that reach past the union,
    leave its faces, and stay inside it)."""
    import engine.render.instances as instances

    mesh = box((0.8, 1.2, 0.4))
    few, arrays = (InstanceBatch(ctx, GpuMesh(ctx, mesh), None) for _ in range(2))
    rng = np.random.default_rng(5)
    entities = list(range(1, 21))
    poses = _models(20, seed=3)
    few_rows = instances._FEW_ROWS
    assert few_rows >= 5  # the movers below are a few
    try:
        for batch in (few, arrays):
            for entity in entities:
                batch.add(entity)
            batch.write_transforms(entities, poses)
            batch.upload()
            assert batch.box is not None  # the union, worked out once: later frames may keep it
        for batch in (few, arrays):
            batch.take_changes()   # the first upload's: all twenty rows
        kept = 0
        for frame in range(300):
            movers = sorted(int(e) for e in rng.choice(entities, size=int(rng.integers(1, 6)), replace=False))
            models = []
            for entity in movers:
                if rng.random() < 0.3:  # a jump, sometimes past the union
                    poses[entity - 1] = glm.translate(glm.vec3(*[float(v) for v in rng.normal(size=3) * 60.0])) \
                        * poses[entity - 1]
                spin = glm.rotate(float(rng.uniform(0.0, 6.3)), glm.vec3(0.0, 1.0, 0.0))
                models.append(poses[entity - 1] * spin)
            for batch, limit in ((few, few_rows), (arrays, 0)):
                monkeypatch.setattr(instances, "_FEW_ROWS", limit)
                batch.write_transforms(movers, models, moving=True)
                batch.upload()
            assert np.array_equal(few._row_boxes[:20], arrays._row_boxes[:20]), frame
            (got, parts), (want, array_parts) = few.take_changes(), arrays.take_changes()
            assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1]), frame
            assert sorted(np.concatenate(p).tolist() for p in parts) == \
                sorted(np.concatenate(p).tolist() for p in array_parts), frame   # the same boxes either way
            # The box's parts (what the shadow maps redraw under): each mover's old and new
            # box, whose union is the box to the bit.
            assert parts is not None and len(parts) <= 2 * len(movers), (frame, len(parts))
            assert np.array_equal(np.min([lo for lo, _ in parts], axis=0), got[0]), frame
            assert np.array_equal(np.max([hi for _, hi in parts], axis=0), got[1]), frame
            for entity in movers:
                row = few._row_boxes[few.row_of[entity]]
                assert any(np.array_equal(row[0], lo) and np.array_equal(row[1], hi) for lo, hi in parts), frame
            assert np.isclose(few.extent, arrays.extent, rtol=1e-12)
            kept += few._box is not None
            rows = few._row_boxes[:20]
            union = few.box
            assert np.array_equal(union[0], rows[:, 0].min(axis=0)) and np.array_equal(union[1], rows[:, 1].max(axis=0))
        assert 0 < kept < 300  # the union was kept on some frames and worked out again on others
    finally:
        few.release()
        arrays.release()
