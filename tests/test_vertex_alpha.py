"""A mesh's alpha a vertex (``Mesh.colors`` RGBA, glTF's ``COLOR_0`` with alpha): multiplied
into the material's alpha as a texture's is.  A quad whose left edge is opaque and right edge
clear fades across: each pixel is the opaque quad's frame and the wall's mixed by the alpha
interpolated at the point its ray meets (worked out from the rays), and as a cutout it is
drawn, and casts its shadow, only where that alpha passes the cutoff."""
from __future__ import annotations

import numpy as np
import pytest

from components import DirectionalLight, Emissive, Material, MeshRef, Transform
from engine.assets.mesh import Mesh, plane, quad
from engine.core.errors import AssetError
from tests.support import look_from, pixel_rays, srgb_to_linear

SIZE = (96, 72)


def faded(mesh: Mesh) -> Mesh:
    """``mesh`` with a white colour a vertex, its alpha 1 at x = -1 falling to 0 at x = +1."""
    alpha = (1.0 - mesh.positions[:, 0]) / 2.0
    colors = np.column_stack([np.ones((len(alpha), 3)), alpha]).astype(np.float32)
    return Mesh(mesh.positions, mesh.normals, mesh.uvs, mesh.indices, name="faded", colors=colors)


def test_a_vertex_alpha_blends_as_the_alpha_interpolated_where_each_ray_meets_the_quad(scene):
    def build(pane: Material | None, mesh: Mesh | None = None):
        def make(world):
            look_from(world, (0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov=50.0)
            world.spawn(Transform(position=(0.0, 0.0, -1.0)), MeshRef(quad(8.0, 6.0)),
                        Material(color=(0.05, 0.1, 0.6, 1.0), environment_reflection=0.0), Emissive(power=1.0))
            if pane is not None:
                world.spawn(Transform(), MeshRef(mesh), pane, Emissive(power=1.0))
        return make

    def frame(make) -> tuple[np.ndarray, object]:
        runner = scene(make, SIZE)
        runner.engine.renderer.antialias = "off"
        runner.frame()
        return srgb_to_linear(runner.frame()), runner.engine.main_view

    mesh = faded(quad(2.0, 2.0))
    wall, view = frame(build(None))
    opaque, _ = frame(build(Material(color=(0.9, 0.6, 0.2, 1.0), environment_reflection=0.0), mesh))
    blended, _ = frame(build(Material(color=(0.9, 0.6, 0.2, 0.999), environment_reflection=0.0), mesh))
    eye, rays = pixel_rays(view, SIZE)
    t = -eye[2] / rays[..., 2]
    hit = eye + t[..., None] * rays
    inside = (np.abs(hit[..., 0]) < 0.95) & (np.abs(hit[..., 1]) < 0.95)
    alpha = 0.999 * (1.0 - hit[..., 0]) / 2.0
    expected = alpha[..., None] * opaque + (1.0 - alpha[..., None]) * wall
    assert inside.sum() > 500 and (opaque[inside] - wall[inside]).max() > 0.3
    np.testing.assert_allclose(blended[inside], expected[inside], atol=0.012)


def test_a_vertex_alpha_cuts_a_cutout_and_its_shadow(scene):
    """A horizontal sheet 1 m over the floor, cut at 0.5, under a sun straight above: seen from
    the side below it, the floor is shadowed under its opaque half (x < 0) and lit under its
    clear one (x > 0), as it is under no sheet at all."""
    def build(world):
        look_from(world, (0.0, 0.45, 3.5), (0.0, 0.0, 0.0), fov=50.0)
        world.spawn(DirectionalLight(direction=(0.0, -1.0, 0.0), intensity=1.0, shadow_softness=0.0))
        world.spawn(Transform(), MeshRef(plane(10.0, 10.0)), Material(color=(0.6, 0.6, 0.6, 1.0)))
        world.spawn(Transform(position=(0.0, 1.0, 0.0)), MeshRef(faded(plane(2.0, 2.0))),
                    Material(color=(0.8, 0.8, 0.8, 1.0), alpha_cutoff=0.5))
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    floor = srgb_to_linear(runner.frame())[..., 1]
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    t = -eye[1] / np.minimum(rays[..., 1], -1e-6)
    hit = eye + t[..., None] * rays
    under = (np.abs(hit[..., 2]) < 0.8) & (rays[..., 1] < -0.02)
    shade = under & (hit[..., 0] > -0.85) & (hit[..., 0] < -0.2)
    lit = under & (hit[..., 0] > 0.2) & (hit[..., 0] < 0.85)
    open_floor = (np.abs(hit[..., 2]) < 0.8) & (np.abs(hit[..., 0]) > 1.3) & (rays[..., 1] < -0.02)
    assert shade.sum() > 20 and lit.sum() > 20 and open_floor.sum() > 20
    assert floor[shade].max() < 0.5 * floor[lit].min()
    assert floor[lit].min() > 0.9 * np.median(floor[open_floor])


def test_colors_alpha_is_checked_and_a_gltf_colour_alpha_blends_a_blend_material(tmp_path):
    flat = quad(1.0, 1.0)
    with pytest.raises(AssetError, match=r"a colour's alpha must be in \[0, 1\], got up to 2"):
        Mesh(flat.positions, flat.normals, flat.uvs, flat.indices, colors=np.full((4, 4), 2.0, np.float32))
    from engine.assets.mesh import load_model
    from tests.test_materials_from_files import write_glb

    colours = np.array([[1, 0, 0, 1], [0, 1, 0, 0.25], [0, 0, 1, 1], [1, 1, 1, 1]], np.float32)
    for mode, alpha in (("BLEND", pytest.approx(0.999)), ("OPAQUE", 1.0)):
        material = {"name": "m", "alphaMode": mode, "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1]}}
        (part,) = load_model(write_glb(tmp_path / f"{mode}.glb", flat, material, [], colors=colours))
        np.testing.assert_allclose(part.mesh.colors, colours, atol=1e-6)
        assert part.color[3] == alpha   # BLEND: the transparent slot; OPAQUE: the alpha ignored
