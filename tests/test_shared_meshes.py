"""Generated shapes of any size drawn as one unit mesh (``Mesh.unit``): boxes, quads and spheres
of many sizes are one batch a shape, each row's model matrix carrying its size, and the frame
is the frame of the same sizes built as meshes of their own (vertex arrays, which the engine
cannot share), within a vertex's rounding; the draws a pass fall."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import DirectionalLight, Material, MeshRef, Mirror, Transform
from engine.assets.mesh import UNIT_SCALES, box, plane, quad, sphere
from tests.support import look_from, own_mesh

SIZES = [(0.5, 1.5, 0.4), (1.0, 0.3, 2.0), (0.25, 0.25, 0.25), (1.0, 1.0, 1.0)]
RADII = [0.3, 0.55]


def _scene(shared: bool):
    def build(world):
        look_from(world, (0.5, 3.0, 6.0), (0.0, 0.6, 0.0))
        world.spawn(DirectionalLight(direction=(-0.4, -1.0, -0.5), intensity=2.5))
        world.spawn(Transform(), MeshRef(plane(12, 12)), Material(color=(0.7, 0.7, 0.7, 1.0), roughness=0.9))
        meshes = [box(size) for size in SIZES] + [sphere(r) for r in RADII] + [quad(1.2, 0.8)]
        for i, mesh in enumerate(meshes):
            turn = glm.angleAxis(0.4 * i, glm.normalize(glm.vec3(0.3, 1.0, 0.2)))
            world.spawn(Transform(position=(-2.6 + 0.85 * i, 0.9, -0.4 * (i % 3)), rotation=turn,
                                  scale=(1.0, 1.0 + 0.2 * (i % 2), 1.0)),
                        MeshRef(mesh if shared else own_mesh(mesh)), Material(color=(0.8, 0.3 + 0.08 * i, 0.2, 1.0)))
        glass = quad(5.0, 2.4)
        world.spawn(Transform(position=(0.0, 1.2, -3.0)), MeshRef(glass if shared else own_mesh(glass)),
                    Material(), Mirror())
    return build


def test_generated_shapes_are_their_units_scaled_and_a_flat_box_is_itsown_mesh():
    a, b = box((0.5, 1.5, 0.4)), box((2.0, 1.0, 3.0))
    assert a.unit is b.unit is box().unit and a.unit is not None and a.unit_scale == (0.5, 1.5, 0.4)
    assert np.allclose(a.unit.positions * np.array(a.unit_scale, np.float32), a.positions)
    assert np.array_equal(a.unit.normals, a.normals) and np.array_equal(a.unit.uvs, a.uvs)
    assert quad(3.0, 2.0).unit is quad().unit and quad(3.0, 2.0).unit_scale == (3.0, 2.0, 1.0)
    assert sphere(0.3).unit is sphere(2.0).unit is not sphere(0.3, segments=12).unit
    assert np.allclose(sphere(0.3).unit.positions * 0.3, sphere(0.3).positions, atol=1e-6)
    # A side of 0 (a flat box: a singular model matrix) or past the range is drawn as it is.
    assert box((1.0, 0.0, 1.0)).unit is None and box((UNIT_SCALES[1] * 10, 1.0, 1.0)).unit is None
    assert plane(4.0, 4.0, uv_repeat=3.0).unit is None  # its UVs depend on what it is made with
    assert a.unit.unit is None  # the unit itself


def test_shapes_of_many_sizes_are_one_draw_a_shape_and_the_frame_of_meshes_of_theirown_mesh(scene):
    """Four box sizes, two sphere radii and a quad, each a shape's unit mesh scaled: one
    batch a shape (the mirror's quad among the quads), so fewer draws in every pass; the
    frame, directly and in the mirror, is that of the same vertices as meshes of their own,
    but for pixels at silhouettes where a vertex's rounding moves an edge."""
    shared = scene(_scene(True), (240, 160))
    shared.engine.renderer.antialias = "off"
    own = scene(_scene(False), (240, 160))
    own.engine.renderer.antialias = "off"
    a, b = shared.frame(), own.frame()
    a, b = shared.frame(), own.frame()
    batches = {batch.key.mesh for batch in shared.engine.renderer.batches.values()}
    assert len(batches) == 5, batches  # the floor, the unit box, quad and sphere, the mirror's own quad
    assert len({batch.key.mesh for batch in own.engine.renderer.batches.values()}) == 9  # one a mesh
    assert shared.stats.draw_calls < own.stats.draw_calls, (shared.stats.draw_calls, own.stats.draw_calls)
    assert shared.stats.reflection_views == own.stats.reflection_views > 0
    ids_differ = shared.ids() != own.ids()
    assert ids_differ.mean() < 0.002, ids_differ.mean()
    colour = np.abs(a.astype(int) - b.astype(int)).max(axis=-1)
    assert (colour > 3).mean() < 0.003, (colour > 3).mean()
    assert np.abs(a.astype(float) - b.astype(float)).mean() < 0.1


def test_a_shape_given_another_size_is_drawn_at_it(scene):
    """``MeshRef.mesh`` written with a box of another size (the same unit, the same batch):
    its row takes the new size at once, as an engine given that box from the start draws it."""
    def build(size):
        def make(world):
            look_from(world, (0.0, 2.0, 5.0), (0.0, 0.5, 0.0))
            world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.4)))
            world.resources["box"] = world.spawn(Transform(position=(0.0, 0.6, 0.0)), MeshRef(box(size)),
                                                 Material(color=(0.2, 0.5, 0.9, 1.0)))
        return make

    changed = scene(build((0.5, 0.5, 0.5)), (160, 120))
    first = changed.frame()
    changed.world.get(changed.world.resources["box"], MeshRef).mesh = box((1.5, 0.4, 0.8))
    after = changed.frame()
    fresh = scene(build((1.5, 0.4, 0.8)), (160, 120))
    fresh.frame()
    expected = fresh.frame()
    assert not np.array_equal(first, after)
    np.testing.assert_array_equal(after, expected)


@pytest.mark.parametrize("side", [UNIT_SCALES[0], UNIT_SCALES[1]])
def test_the_range_ends_are_drawn_scaled(side):
    assert box((side, 1.0, 1.0)).unit is not None
