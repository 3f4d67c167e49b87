"""Vertex and face colours (``Mesh.colors``, glTF's ``COLOR_0``, PLY's and OBJ's colours):
interpolated across each triangle and multiplied into the material's colour, where a model
with them was drawn in their mean colour before.

Second computations: each pixel's place on a quad coloured red at its left edge and blue
at its right, found by casting its ray in float64, gives the share of red its linear
colour must have; a face-coloured PLY box draws as the engine's own box with that colour
as its material (sRGB decoded, as PLY colours are kept); a mirror shows the same colours by
its batched (instanced) path as by its per-mirror one."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

from components import HemisphereLight, Material, MeshRef, Mirror, Transform
from engine.assets.mesh import Mesh, box, load_model, quad
from engine.assets.models import spawn_model
from engine.core.errors import AssetError
from tests.support import look_from, pixel_rays, srgb_to_linear
from tests.test_materials_from_files import write_glb

SIZE = (160, 120)
RED_TO_BLUE = np.array([[1, 0, 0, 1], [0, 0, 1, 1], [0, 0, 1, 1], [1, 0, 0, 1]], np.float32)  # quad's corners


def _gradient_glb(tmp_path):
    return write_glb(tmp_path / "gradient.glb", quad(2.0, 2.0), None, [], colors=RED_TO_BLUE)


def _lit_evenly(world) -> None:
    world.spawn(HemisphereLight(sky=(1.0, 1.0, 1.0), ground=(1.0, 1.0, 1.0), intensity=0.6))


def test_a_gltf_quad_coloured_red_to_blue_shades_by_where_each_pixel_lies(scene, tmp_path):
    """Lit evenly from all round, a pixel's red share of red + blue (each less the white
    reflection of the light from all round) is 1 - u, u its place across the quad (glTF's
    COLOR_0 is linear, interpolated across the triangle)."""
    path = _gradient_glb(tmp_path)
    (part,) = load_model(path)
    np.testing.assert_allclose(part.mesh.colors, RED_TO_BLUE[:, :3])
    assert part.color == (1.0, 1.0, 1.0, 1.0)

    def build(world):
        look_from(world, (0.0, 1.0, 2.6), (0.0, 1.0, 0.0))
        _lit_evenly(world)
        spawn_model(world, path, position=(0.0, 1.0, 0.0))
    runner = scene(build, SIZE)
    linear = srgb_to_linear(runner.frame())
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    t = -eye[2] / rays[..., 2]
    points = eye + rays * t[..., None]
    inside = (np.abs(points[..., 0]) < 0.95) & (np.abs(points[..., 1] - 1.0) < 0.95)
    assert inside.sum() > 5000
    u = (points[..., 0] + 1.0) / 2.0
    red, green, blue = linear[..., 0], linear[..., 1], linear[..., 2]
    # The environment's white reflection adds the same to each channel: green alone (the
    # colours have none), taken out of red and blue.
    red, blue = red - green, blue - green
    share = red[inside] / (red[inside] + blue[inside])
    np.testing.assert_allclose(share, 1.0 - u[inside], atol=0.03)
    assert green[inside].max() < 0.05 and (red[inside] + blue[inside]).min() > 0.2


def test_a_face_coloured_ply_box_draws_as_the_engines_box_in_that_colour(scene, tmp_path):
    """A box whose faces are all sRGB (150, 90, 40) in a PLY file (its colours sRGB, as PLY
    files keep them) draws the frame of the engine's box with that colour, decoded, as its
    material: each face flat, no colour bled across its edges."""
    tm = trimesh.creation.box((1.0, 1.0, 1.0))
    tm.visual.face_colors = np.tile([150, 90, 40, 255], (len(tm.faces), 1))
    tm.export(tmp_path / "box.ply")
    (part,) = load_model(tmp_path / "box.ply")
    assert part.mesh.colors.shape == (3 * len(tm.faces), 3)
    colour = tuple(float(c) for c in srgb_to_linear(np.array([150, 90, 40])))

    def build(world, from_file):
        look_from(world, (1.6, 1.9, 2.4), (0.0, 0.5, 0.0))
        _lit_evenly(world)
        if from_file:
            spawn_model(world, tmp_path / "box.ply", position=(0.0, 0.5, 0.0))
        else:
            world.spawn(Transform(position=(0.0, 0.5, 0.0)), MeshRef(box()), Material(color=(*colour, 1.0)))
    filed = scene(lambda w: build(w, True), SIZE)
    made = scene(lambda w: build(w, False), SIZE)
    filed_rgb, made_rgb = filed.frame(), made.frame()
    assert (made_rgb.astype(int) - made_rgb[0, 0]).any()   # the box is drawn
    assert np.abs(filed_rgb.astype(int) - made_rgb).max() <= 1


def test_a_mirror_shows_vertex_colours_by_either_path(scene, tmp_path):
    """The batched mirror program's geometry stage passes the colours on: the frame equals
    the per-mirror path's, and the mirror's pixels hold both red and blue."""
    path = _gradient_glb(tmp_path)

    def build(world):   # the quad turned to face the mirror, beside the camera's way to it
        look_from(world, (0.6, 1.2, 3.2), (0.0, 1.0, -1.5))
        _lit_evenly(world)
        spawn_model(world, path, position=(-1.6, 1.0, 1.5), rotation=(0.0, 0.0, 1.0, 0.0))
        world.spawn(Transform(position=(0.0, 1.0, -1.5)), MeshRef(quad(5.0, 3.0)), Material(), Mirror())
    frames = {}
    for choice in ("batched", "per_mirror"):
        runner = scene(build, (240, 180))
        runner.engine.reflection_system.path = choice
        frames[choice] = runner.frame()
        assert runner.stats.reflection_views >= 1
    np.testing.assert_array_equal(frames["batched"], frames["per_mirror"])
    linear = srgb_to_linear(frames["batched"])
    assert ((linear[..., 0] > 0.3) & (linear[..., 2] < 0.1)).sum() > 100
    assert ((linear[..., 2] > 0.3) & (linear[..., 0] < 0.1)).sum() > 100


@pytest.mark.parametrize("colors, reason", [(np.ones((3, 3)), r"shape \(4, 3\)"),
                                            (np.full((4, 3), np.nan), "finite"),
                                            (np.full((4, 3), -1.0), "finite, in")])
def test_bad_vertex_colours_are_refused_naming_the_mesh(colors, reason):
    q = quad()
    with pytest.raises(AssetError, match=rf"mesh 'coloured': colors must .*{reason}"):
        Mesh(q.positions, q.normals, q.uvs, q.indices, name="coloured", colors=colors)
