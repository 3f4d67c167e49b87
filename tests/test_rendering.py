"""System tests of the foundation renderer: real frames on llvmpipe, facts about pixels."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    DirectionalLight,
    Emissive,
    Material,
    MeshRef,
    PointLight,
    Reflective,
    Skybox,
    Transform,
)
from engine.assets.mesh import box, plane, quad, sphere
from engine.assets.texture_data import checker_texture
from engine.render.sky import build_faces, sky_radiance
from engine.rules.light_rules import SkySun
from tests.support import srgb_to_linear

SIZE = (160, 120)
EYE = glm.vec3(0.0, 0.0, 5.0)


def camera(world, eye=EYE, fov=60.0):
    return world.spawn(Transform(position=eye), Camera(fov_y=fov))


def pixel_ray(runner, col: int, row: int) -> np.ndarray:
    """World direction through the centre of pixel (col, row from top), from the camera math."""
    view = runner.engine.main_view
    w, h = runner.size
    ndc = glm.vec4((col + 0.5) / w * 2 - 1, 1 - (row + 0.5) / h * 2, 1.0, 1.0)
    far = glm.inverse(view.view_proj) * ndc
    d = glm.normalize(glm.vec3(far) / far.w - view.eye)
    return np.array(d)


def test_frame_is_lit_and_not_black(scene):
    def build(world):
        camera(world)
        world.spawn(DirectionalLight(direction=(0, 0, -1), intensity=2.0))
        world.spawn(Transform(), MeshRef(box()), Material(color=(0.8, 0.2, 0.2)))

    runner = scene(build, SIZE)
    rgb = runner.frame()
    col, row = runner.project((0, 0, 0.5))
    r, g, b = rgb[row, col].astype(int)
    assert r > 100 and r > g + 40 and r > b + 40, rgb[row, col]
    assert rgb.std() > 5.0  # not one flat colour


def test_emissive_adds_power_times_diffuse(scene):
    diffuse = (0.2, 0.1, 0.05)
    power = 1.5

    def build(world):
        camera(world)
        world.spawn(DirectionalLight(direction=(0, 0, -1), intensity=1.0))
        world.spawn(Transform(position=(-1.2, 0, 0)), MeshRef(box()), Material(color=diffuse))
        world.spawn(Transform(position=(1.2, 0, 0)), MeshRef(box()), Material(color=diffuse), Emissive(power))

    runner = scene(build, SIZE)
    rgb = runner.frame()
    plain = srgb_to_linear(rgb[runner.project((-1.2, 0, 0.5))[::-1]])
    glowing = srgb_to_linear(rgb[runner.project((1.2, 0, 0.5))[::-1]])
    np.testing.assert_allclose(glowing - plain, np.array(diffuse) * power, atol=0.012)


def test_toggling_emissive_changes_the_pixels_next_frame(scene):
    entity = {}

    def build(world):
        camera(world)
        world.spawn(DirectionalLight(direction=(0, 0, -1)))
        entity["box"] = world.spawn(Transform(), MeshRef(box()), Material(color=(0.3, 0.3, 0.1)))

    runner = scene(build, SIZE)
    runner.frame()
    px = runner.project((0, 0, 0.5))
    before = srgb_to_linear(runner.frame()[px[::-1]])

    runner.world.add_component(entity["box"], Emissive(2.0))
    lit = srgb_to_linear(runner.frame()[px[::-1]])
    # The emissive term is power x diffuse on top of the lit colour, from the next frame on.
    np.testing.assert_allclose(lit - before, 2.0 * np.array([0.3, 0.3, 0.1]), atol=0.015)

    runner.world.remove_component(entity["box"], Emissive)
    after = srgb_to_linear(runner.frame()[px[::-1]])
    np.testing.assert_allclose(after, before, atol=0.004)


def _sphere_hit(origin, direction, centre, radius):
    oc = origin - centre
    b = np.dot(oc, direction)
    c = np.dot(oc, oc) - radius * radius
    disc = b * b - c
    if disc < 0:
        return None
    return origin + direction * (-b - np.sqrt(disc))


def test_chrome_sphere_shows_sky_along_the_reflected_direction(scene):
    sky = Skybox()
    eye = glm.vec3(0.0, 2.5, 4.0)  # from above, so the centre reflects the smooth upper sky

    def build(world):
        from components import look_rotation

        world.spawn(Transform(position=eye, rotation=look_rotation(-eye)), Camera(fov_y=40.0))
        world.spawn(sky)
        world.spawn(Transform(), MeshRef(sphere(1.0, 96, 48)), Material(roughness=0.0), Reflective("skybox"))

    runner = scene(build, SIZE)
    rgb = runner.frame()
    cx, cy = runner.project((0, 0, 0))
    radius_px = abs(cx - runner.project((1.0, 0, 0))[0])
    checked = 0
    # The centre, and points near the rim whose reflections go up into the smooth part of the
    # sky (towards the horizon line the footprint blur is legitimately large).
    for dx, dy in ((0, 0), (0, 0.85), (0.6, 0.6), (-0.6, 0.6), (0.0, 0.5)):
        col, row = int(cx + dx * radius_px), int(cy - dy * radius_px)
        d = pixel_ray(runner, col, row)
        hit = _sphere_hit(np.array(eye), d, np.zeros(3), 1.0)
        assert hit is not None
        n = hit / np.linalg.norm(hit)
        r = d - 2 * np.dot(d, n) * n
        expected = sky_radiance(sky, r)
        got = srgb_to_linear(rgb[row, col])
        np.testing.assert_allclose(got, expected, atol=0.03, err_msg=f"pixel {(col, row)} reflect {r}")
        checked += 1
    assert checked == 5
    # And the background: each corner shows the sky along its own view ray.
    for col, row in ((2, 2), (SIZE[0] - 3, 2), (2, SIZE[1] - 3), (SIZE[0] - 3, SIZE[1] - 3)):
        expected = sky_radiance(sky, pixel_ray(runner, col, row))
        np.testing.assert_allclose(srgb_to_linear(rgb[row, col]), expected, atol=0.02)


def test_sky_faces_are_oriented(scene):
    """Looking along each axis shows the sky of that axis (a wrong face order fails this).
    The cube map is the generated sky's faces given as faces: a generated Skybox's background
    is drawn from its function, not its cube (tests/test_generated_sky.py)."""
    sky = Skybox(zenith=(0.0, 0.0, 0.9), horizon=(0.5, 0.5, 0.5), ground=(0.0, 0.6, 0.0),
                 sun_direction=(1.0, 0.2, 0.0))
    cam = {}

    def build(world):
        cam["e"] = camera(world, eye=glm.vec3(0.0), fov=30.0)
        world.spawn(Skybox(faces=build_faces(sky)))

    runner = scene(build, (32, 32))
    from components import look_rotation

    for axis in ((1, 0, 0), (-1, 0, 0), (0, 1, 0.001), (0, -1, 0.001), (0, 0, 1), (0, 0, -1)):
        runner.world.get(cam["e"], Transform).rotation = look_rotation(axis)
        rgb = runner.frame()
        expected = sky_radiance(sky, np.array(axis, float))
        np.testing.assert_allclose(srgb_to_linear(rgb[16, 16]), expected, atol=0.03, err_msg=str(axis))


def test_textured_reflector_is_the_average_of_texture_and_sky(scene):
    sky = Skybox()
    texture = checker_texture(64, 1, (180, 120, 60), (180, 120, 60))  # one flat colour
    entity = {}

    def build(world):
        camera(world, eye=glm.vec3(0, 0, 3))
        world.spawn(sky)
        world.spawn(DirectionalLight(direction=(0, 0, -1), intensity=1.5))
        entity["quad"] = world.spawn(Transform(rotation=glm.angleAxis(glm.radians(90), glm.vec3(1, 0, 0))),
                                     MeshRef(plane(2, 2)),
                                     Material(color=(1, 1, 1), texture=texture, roughness=0.0))

    runner = scene(build, SIZE)
    runner.frame()
    col, row = runner.project((0.3, 0.2, 0))
    plain = srgb_to_linear(runner.frame()[row, col])
    runner.world.add_component(entity["quad"], Reflective("skybox"))
    mixed = srgb_to_linear(runner.frame()[row, col])
    d = pixel_ray(runner, col, row)
    r = d - 2 * np.dot(d, [0, 0, 1]) * np.array([0, 0, 1])
    expected = 0.5 * plain + 0.5 * sky_radiance(sky, r, sun=SkySun((0, 0, 1)))  # (the sky's sun: against the light)
    np.testing.assert_allclose(mixed, expected, atol=0.02)


def test_id_image_marks_the_visible_entity(scene):
    ids = {}

    def build(world):
        camera(world)
        ids["left"] = world.spawn(Transform(position=(-1.5, 0, 0)), MeshRef(box()), Material())
        ids["right"] = world.spawn(Transform(position=(1.5, 0, 0)), MeshRef(sphere()), Material())
        ids["front"] = world.spawn(Transform(position=(1.5, 0, 1.5), scale=(0.3, 0.3, 0.3)), MeshRef(box()),
                                   Material())

    runner = scene(build, SIZE)
    runner.frame()
    image = runner.ids()
    assert image.shape == (SIZE[1], SIZE[0]) and image.dtype == np.uint32
    assert image[runner.project((-1.5, 0, 0.5))[::-1]] == ids["left"]
    assert image[runner.project((1.5, 0.4, 0.3))[::-1]] == ids["right"]
    assert image[runner.project((1.5, 0, 1.65))[::-1]] == ids["front"]  # in front of the sphere
    assert image[2, 2] == 0  # sky
    assert set(np.unique(image)) == {0, ids["left"], ids["right"], ids["front"]}
    # Oriented like the PNG: the top row is above the objects, i.e. sky.
    assert (image[0] == 0).all()


def test_static_frame_uploads_nothing_and_draws_per_mesh(scene):
    moving = {}

    def build(world):
        camera(world, eye=glm.vec3(0, 0, 30))
        crate = box((0.5, 0.5, 0.5))
        ball = sphere(0.3, 12, 6)
        for i in range(200):
            e = world.spawn(Transform(position=(i % 20 - 10, i // 20 - 5, 0)), MeshRef(crate if i % 2 else ball),
                            Material())
            if i == 7:
                moving["e"] = e

    runner = scene(build, SIZE)
    runner.frame()
    assert runner.stats.uploaded_bytes > 0
    assert runner.stats.draw_calls == 3  # two meshes + sky
    runner.frame()
    assert runner.stats.uploaded_bytes == 0
    runner.world.get(moving["e"], Transform).position += glm.vec3(0, 0, 1)
    runner.frame()
    from engine.render.instances import INSTANCE_DTYPE

    assert runner.stats.uploaded_bytes == INSTANCE_DTYPE.itemsize


def test_moving_a_parent_moves_its_child(scene):
    ents = {}

    def build(world):
        camera(world)
        ents["parent"] = world.spawn(Transform(position=(-1.5, 0, 0)))
        ents["child"] = world.spawn(Transform(position=(0, 0, 0), parent=ents["parent"], scale=(0.6, 0.6, 0.6)),
                                    MeshRef(box()), Material(color=(0.9, 0.9, 0.1)))

    runner = scene(build, SIZE)
    runner.frame()
    assert runner.ids()[runner.project((-1.5, 0, 0.3))[::-1]] == ents["child"]
    runner.world.get(ents["parent"], Transform).position = (1.5, 0, 0)
    runner.frame()
    assert ents["child"] in runner.world.frame.moved
    image = runner.ids()
    assert image[runner.project((1.5, 0, 0.3))[::-1]] == ents["child"]
    assert image[runner.project((-1.5, 0, 0.3))[::-1]] == 0


def _lit_floor(ents, light_at, parent_at=None, sun=1.0):
    def build(world):
        camera(world, eye=glm.vec3(0.0, 3.0, 6.0))
        world.spawn(Transform(position=(0, -1, 0)), MeshRef(plane(12.0, 12.0)), Material(color=(0.8, 0.8, 0.8)))
        ents["sun"] = world.spawn(DirectionalLight(direction=(0.3, -1.0, -0.2), intensity=sun))
        ents["parent"] = world.spawn(Transform(position=parent_at or (0, 0, 0)))
        ents["light"] = world.spawn(Transform(position=light_at, parent=ents["parent"]),
                                    PointLight(color=(1.0, 0.5, 0.2), intensity=6.0, range=6.0))
    return build


def test_the_lights_follow_a_parent_moved_and_a_light_changed(scene):
    """The lights block is worked out again only when a light changes or moves; a point light
    moved by its parent alone (its own Transform untouched) and a sun made dimmer each give
    the frame of a scene built with them so from the start."""
    ents = {}
    runner = scene(_lit_floor(ents, (-2.0, 0.0, 0.0)), SIZE)
    first = runner.frame()
    assert np.array_equal(runner.frame(), first)  # nothing changed: the same frame
    runner.world.get(ents["parent"], Transform).position = (3.0, 0.0, 0.0)
    moved = runner.frame()
    assert np.abs(moved.astype(int) - first.astype(int)).max() > 20
    fresh = scene(_lit_floor({}, (-2.0, 0.0, 0.0), parent_at=(3.0, 0.0, 0.0)), SIZE)
    fresh.frame()
    assert np.abs(fresh.frame().astype(int) - moved.astype(int)).max() <= 1
    runner.world.get(ents["sun"], DirectionalLight).intensity = 0.5
    dimmer = runner.frame()
    fresh = scene(_lit_floor({}, (-2.0, 0.0, 0.0), parent_at=(3.0, 0.0, 0.0), sun=0.5), SIZE)
    fresh.frame()
    assert np.abs(fresh.frame().astype(int) - dimmer.astype(int)).max() <= 1
    assert dimmer.mean() < moved.mean() - 2


def test_entities_release_their_gpu_resources(scene):
    def build(world):
        camera(world)

    runner = scene(build, (32, 32))
    renderer = runner.engine.renderer
    texture = checker_texture(16, 2)
    for cycle in range(3):
        spawned = [runner.world.spawn(Transform(position=(i, 0, 0)), MeshRef(box() if i % 2 else sphere(0.3, 8, 4)),
                                      Material(texture=texture if i % 3 == 0 else None))
                   for i in range(12)]
        runner.frame()
        counts = renderer.resource_counts()
        # Every box and every sphere is its shape's unit mesh scaled: two meshes, a batch for
        # each with the texture and without.
        assert counts["meshes"] == 2 and counts["textures"] == 1 and counts["batches"] == 4
        for e in spawned:
            runner.world.delete_entity(e)
        runner.frame()
        counts = renderer.resource_counts()
        assert (counts["meshes"], counts["textures"], counts["batches"]) == (0, 0, 0), cycle


def test_minimised_output_renders_nothing_and_does_not_crash(scene, ctx):
    from engine.core.frame_io import Output

    def build(world):
        camera(world)
        world.spawn(Transform(), MeshRef(box()), Material())

    runner = scene(build, SIZE)
    runner.engine.frame(1 / 60, Output(runner.capture.framebuffer, (0, 0)))
    assert runner.stats.passes == 0
    runner.frame()
    assert runner.stats.passes == 1


@pytest.mark.parametrize("size", [(64, 48), (97, 31)])
def test_resizing_follows_the_output_size(scene, size):
    """The picture, not only the targets, follows the size: a unit cube seen face on covers
    exactly the pixels whose centres fall inside its front face's projection (worked out
    here from the field of view and the aspect ratio of ``size``), and is lit there."""
    box_entity = {}

    def build(world):
        camera(world)
        world.spawn(DirectionalLight(direction=(0, 0, -1), intensity=2.0))
        box_entity["id"] = world.spawn(Transform(), MeshRef(box()), Material(color=(0.8, 0.2, 0.2)))

    runner = scene(build, size)
    rgb = runner.frame()
    w, h = size
    assert runner.engine.renderer.targets.size == size
    ids = runner.ids()
    assert ids.shape == (h, w)
    # Front face z = 0.5 at distance 4.5 from the eye; 60 degree vertical field of view.
    half_h = 0.5 / (4.5 * np.tan(np.radians(30.0)))  # half the face's height in NDC
    half_w = half_h * h / w
    cols = (np.arange(w) + 0.5) / w * 2 - 1
    rows = 1 - (np.arange(h) + 0.5) / h * 2
    inside = (np.abs(rows)[:, None] < half_h) & (np.abs(cols)[None, :] < half_w)
    drawn = ids == box_entity["id"]
    assert drawn.sum() > 0
    assert (drawn != inside).sum() <= 2  # llvmpipe: 0; a pixel centre on an edge may round either way
    assert rgb[drawn].mean(axis=0)[0] > 100 and rgb[~drawn].mean() < rgb[drawn].mean(axis=0)[0]


def test_scattered_movers_in_one_batch_upload_only_their_rows(scene):
    from engine.render.instances import INSTANCE_DTYPE

    spawned = []

    def build(world):
        camera(world, eye=glm.vec3(0, 0, 40))
        crate = box((0.3, 0.3, 0.3))
        spawned.extend(world.spawn(Transform(position=(i % 20 - 10, i // 20 - 10, 0)), MeshRef(crate), Material())
                       for i in range(400))

    runner = scene(build, (32, 32))
    runner.frame()
    for e in spawned[::100]:
        runner.world.get(e, Transform).position += glm.vec3(0, 0, 0.5)
    runner.frame()
    assert runner.stats.uploaded_bytes == 4 * INSTANCE_DTYPE.itemsize


def test_big_surfaces_draw_last_so_hidden_pixels_are_not_shaded(scene, ctx):
    """A ground spawned first, boxes standing on it: the boxes draw first, so no ground
    pixel under a box passes the depth test. A samples-passed query around the main view
    counts every fragment that was shaded and written (the sky fills where depth is far):
    with no overdraw that is exactly one per pixel."""
    def build(world):
        world.spawn(Transform(position=(0, 2, 8), rotation=glm.angleAxis(-0.3, glm.vec3(1, 0, 0))), Camera())
        world.spawn(Transform(), MeshRef(plane(40, 40)), Material(texture=checker_texture(64, 8)))
        crate = box()
        for x in (-2.0, 0.0, 2.0):
            world.spawn(Transform(position=(x, 0.5, 0)), MeshRef(crate), Material(color=(0.7, 0.3, 0.2)))

    runner = scene(build, SIZE)
    runner.frame()
    renderer = runner.engine.renderer
    query = ctx.query(samples=True)
    with query:
        renderer.scene_pass.draw([runner.engine.main_view], renderer.targets)
    ids = runner.ids()
    boxes = (ids != 0).sum() - (ids == ids[-1, SIZE[0] // 2]).sum()
    assert boxes > 500  # the boxes cover ground
    assert query.samples == SIZE[0] * SIZE[1]


@pytest.mark.parametrize("renderer_name, anisotropic", [
    ("llvmpipe (LLVM 15.0.6, 256 bits)", False),
    ("NVIDIA H100 80GB HBM3/PCIe/SSE2", True),
])
def test_reflections_filter_trilinearly_on_a_software_rasteriser_only(ctx, renderer_name, anisotropic):
    """The rule, for both answers whatever machine runs the tests (and under
    SPECULUM_AS_GPU, which answers ``software`` False for llvmpipe): on a software rasteriser
    anisotropic filtering of reflection views and normal maps costs more than it shows (and
    llvmpipe's is not the GL's: ``filters_anisotropically``), so they filter trilinearly; on
    a GPU they filter like the main view."""
    import dataclasses

    from engine.render.gl_context import GLCapabilities
    from engine.render.renderer import Renderer

    caps = dataclasses.replace(GLCapabilities.read(ctx), renderer=renderer_name)
    assert caps.filters_anisotropically is anisotropic
    renderer = Renderer(ctx, caps)
    try:
        assert renderer.texture_anisotropy > 1.0
        expected = renderer.texture_anisotropy if anisotropic else 1.0
        assert renderer.reflection_anisotropy == expected
        assert renderer.normal_map_anisotropy == expected
    finally:
        renderer.release()


def test_camera_block_columns_named_in_views_hold_what_they_say():
    """composite_rows reads the view-projection, its inverse and the eye straight out of a
    packed Camera block by these column ranges; the block's layout must match them."""
    from engine.render.views import (
        CAMERA_BLOCK_BYTES,
        CAMERA_BLOCK_EYE,
        CAMERA_BLOCK_INVERSE,
        CAMERA_BLOCK_VIEW_PROJ,
        camera_view,
    )

    world_matrix = glm.translate(glm.vec3(1.0, 2.0, 3.0)) * glm.mat4_cast(glm.angleAxis(0.4, glm.vec3(0, 1, 0)))
    view = camera_view(world_matrix, 60.0, 0.1, 50.0, (320, 200))
    block = np.frombuffer(view.camera_block(), np.float32)
    assert block.size * 4 == CAMERA_BLOCK_BYTES
    vp = np.array(view.view_proj.to_list(), np.float32).reshape(16)  # column-major, as packed
    assert np.allclose(block[CAMERA_BLOCK_VIEW_PROJ], vp)
    assert np.allclose(block[CAMERA_BLOCK_INVERSE].reshape(4, 4).T @ vp.reshape(4, 4).T, np.eye(4), atol=1e-4)
    assert np.allclose(block[CAMERA_BLOCK_EYE], (1.0, 2.0, 3.0))


def test_the_camera_glsl_block_is_the_camera_dtype():
    """shaders/include/camera.glsl's Camera block and ``views.CAMERA_DTYPE`` (every writer's
    and reader's schema) name the same members in the same order at the same std140 offsets
    (worked out here from the GLSL types: a mat4 or a vec4 is 16-byte aligned), with the
    same size, and a scalar type that agrees (float against f4, uint against u4)."""
    import re
    from pathlib import Path

    from engine.render.views import CAMERA_BLOCK_BYTES, CAMERA_DTYPE

    text = Path(__file__).resolve().parents[1].joinpath("shaders", "include", "camera.glsl").read_text()
    body = re.search(r"uniform\s+Camera\s*\{(.*?)\}", text, re.S).group(1)
    body = re.sub(r"//[^\n]*", "", body)
    members = re.findall(r"\b(mat4|vec4|uvec4|ivec4)\s+(\w+)\s*;", body)
    sizes = {"mat4": 64, "vec4": 16, "uvec4": 16, "ivec4": 16}
    kinds = {"mat4": "f", "vec4": "f", "uvec4": "u", "ivec4": "i"}
    offset, found = 0, []
    for kind, name in members:
        offset = -(-offset // 16) * 16
        found.append((name, offset, sizes[kind], kinds[kind]))
        offset += sizes[kind]
    expected = [(name, CAMERA_DTYPE.fields[name][1], CAMERA_DTYPE.fields[name][0].itemsize,
                 CAMERA_DTYPE.fields[name][0].base.kind) for name in CAMERA_DTYPE.names]
    assert found == expected
    assert offset == CAMERA_BLOCK_BYTES == CAMERA_DTYPE.itemsize


def test_a_view_packs_its_camera_block_field_by_field_as_the_dtype_reads_it():
    """``View.camera_block`` (joined bytes) read through ``CAMERA_DTYPE`` gives each of the
    view's own values in its field."""
    from engine.render.views import CAMERA_DTYPE, CAMERA_IDS, View

    eye = glm.vec3(1.0, 2.0, 3.0)
    view = View(glm.lookAt(eye, glm.vec3(0.0), glm.vec3(0, 1, 0)), glm.perspective(0.9, 1.5, 0.1, 40.0), eye,
                (300, 200), clip_plane=glm.vec4(0.0, 1.0, 0.0, -0.5), node=7, skip=11, hide=13, kinds=2, layers=5)
    record = np.frombuffer(view.camera_block(), CAMERA_DTYPE)[0]

    def column_major(matrix: glm.mat4) -> np.ndarray:
        return np.array(matrix.to_list(), np.float32).reshape(16)
    assert np.array_equal(record["view"], column_major(view.view))
    assert np.array_equal(record["proj"], column_major(view.proj))
    assert np.array_equal(record["view_proj"], column_major(view.proj * view.view))
    assert np.allclose(record["inv_view_proj"], column_major(glm.inverse(view.proj * view.view)), atol=1e-5)
    assert record["eye"].tolist() == [1.0, 2.0, 3.0, 1.0]
    assert record["viewport"].tolist() == [0.0, 0.0, 300.0, 200.0]
    assert record["clip_plane"].tolist() == [0.0, 1.0, 0.0, -0.5]
    assert dict(zip(CAMERA_IDS, record["skip"].tolist(), strict=True)) == \
        {"skip": 11, "hide": 13, "view_mask": view.view_mask, "node": 7}


def test_composite_rows_hold_each_views_quad_and_parameters_where_the_shader_reads_them():
    """composite_rows packs a row per view with struct (mirror_composite.vert's attributes,
    in order); checked here against numpy arithmetic done independently: the outline's
    corners in the parent's clip space flattened onto z = 0, a rectangle's corners in NDC,
    the parent's inverse view-projection and eye, and the surface's and tile's numbers (its
    plane's w in params z: where the parent's rays meet it, for the fog)."""
    from engine.render.mirror_passes import COMPOSITE_DTYPE, Composite, composite_rows, composite_surface
    from engine.render.rough_atlas import Tile
    from engine.render.views import camera_view

    parent = camera_view(glm.translate(glm.vec3(0.5, 1.0, 6.0)), 60.0, 0.1, 50.0, (200, 100))
    outline = np.array([(x, y, 0.0, 1.0) for x in (-1.0, 1.0) for y in (0.0, 1.5)])
    mirror = composite_surface(glm.vec4(0.9, 0.8, 0.7, 1.0), 0.75, 0.5, glm.vec3(0.0, 0.0, 1.0), outline)
    carry = glm.mat3(glm.rotate(0.3, glm.vec3(0, 1, 0)))
    portal = composite_surface(glm.vec4(1.0), 1.0, 0.0, glm.vec3(1.0, 0.0, 0.0), None, portal=True, carry=carry,
                               plane_w=-2.5)
    rows = composite_rows([
        Composite(7, (10, 20, 30, 40), (11, 21, 31, 41), parent, mirror, Tile(256, 512, 0.5)),
        Composite(9, (50, 60, 20, 10), (50, 60, 20, 10), parent, portal),
    ], (200, 100))
    table = np.frombuffer(rows, COMPOSITE_DTYPE)  # the row's schema, read by field name
    assert len(table) == 2
    corners, rect, inverse = table["corners"].reshape(2, 4, 4), table["rect"], table["inv_view_proj"].reshape(2, 4, 4)
    eye = np.column_stack([table["eye"], table["tile_x"]])
    tint = np.column_stack([table["tint"], table["tile_scale"]])
    params = np.column_stack([table[name] for name in ("reflect_rate", "roughness", "params_z", "view_index")])
    normal = np.column_stack([table["normal"], table["tile_y"]])
    carried = table["carry"]

    view_proj = np.array(parent.view_proj.to_list(), np.float64)       # rows = columns of the GL matrix
    expected = outline @ view_proj
    expected[:, 2] = 0.0
    assert np.allclose(corners[0], expected, atol=1e-5)
    x0, y0, x1, y1 = 2 * 50 / 200 - 1, 2 * 60 / 100 - 1, 2 * 70 / 200 - 1, 2 * 70 / 100 - 1
    assert np.allclose(corners[1], [(x0, y0, 0, 1), (x0, y1, 0, 1), (x1, y0, 0, 1), (x1, y1, 0, 1)])
    assert np.allclose(rect, [(11, 21, 42, 62), (50, 60, 70, 70)])
    assert np.allclose(inverse[0] @ view_proj, np.eye(4), atol=1e-4) and np.allclose(inverse[1], inverse[0])
    assert np.allclose(eye[:, :3], (0.5, 1.0, 6.0))
    assert np.allclose(eye[:, 3], (256, 0)) and np.allclose(normal[:, 3], (512, 0))   # tile x, y
    assert np.allclose(tint, [(0.9, 0.8, 0.7, 0.5), (1.0, 1.0, 1.0, 0.0)])           # rgb, tile scale
    assert np.allclose(params, [(0.75, 0.5, 0.0, 7.0), (1.0, 0.0, -2.5, 9.0)])        # rate, roughness, portal, index
    assert np.allclose(normal[:, :3], [(0, 0, 1), (1, 0, 0)])
    assert np.allclose(carried[0], np.eye(3).ravel()) and np.allclose(carried[1], np.array(carry.to_list()).ravel())


def test_another_context_made_current_does_not_take_the_engines_draws(scene, ctx):
    """A window or a tool may make its own GL context current between two frames (or before
    the engine is built): the engine draws on its own context, the same picture."""
    import moderngl

    def build(world):
        camera(world)
        world.spawn(DirectionalLight(direction=(0, 0, -1), intensity=2.0))
        world.spawn(Transform(), MeshRef(box()), Material(color=(0.8, 0.2, 0.2)))

    first = scene(build, SIZE)
    before = first.frame()
    other = moderngl.create_standalone_context(backend="egl")  # current from now on
    try:
        after = first.frame()
        other.__enter__()  # current again before the next engine is built
        built_later = scene(build, SIZE).frame()
        assert ctx.error == "GL_NO_ERROR"
    finally:
        other.release()
        ctx.__enter__()  # the test session's context, for the tests that follow
    np.testing.assert_array_equal(after, before)
    np.testing.assert_array_equal(built_later, before)


def test_see_through_materials_blend_over_what_is_behind_them_farthest_first(scene):
    """Two half-transparent quads (alpha 0.5) in front of an emissive wall, the nearer one
    spawned first: where both cover the wall, the linear colour is
    0.5 near + 0.5 (0.5 far + 0.5 wall), each term taken from a scene that draws it alone
    and opaque; where only the far quad covers it, 0.5 far + 0.5 wall."""
    def quads(alpha, which=("near", "far")):
        def build(world):
            camera(world)
            world.spawn(Transform(position=(0, 0, -3)), MeshRef(quad(10, 10)), Material(color=(0.1, 0.1, 0.8)),
                        Emissive(1.0))
            if "near" in which:
                world.spawn(Transform(position=(0.5, 0, 1)), MeshRef(quad(2, 2)),
                            Material(color=(0.1, 0.7, 0.1, alpha)), Emissive(0.5))
            if "far" in which:
                world.spawn(Transform(position=(-0.5, 0, 0)), MeshRef(quad(2, 2)),
                            Material(color=(0.8, 0.1, 0.1, alpha)), Emissive(0.5))
        return build

    def colours(build):
        runner = scene(build, SIZE)
        rgb = runner.frame()
        both = runner.project((0.0, 0.0, 1.0))  # covered by both (and the wall)
        far_only = runner.project((-1.2, 0.0, 0.0))
        return srgb_to_linear(rgb[both[::-1]]), srgb_to_linear(rgb[far_only[::-1]])

    both, far_only = colours(quads(0.5))
    wall, _ = colours(quads(1.0, ()))
    near_opaque, _ = colours(quads(1.0, ("near",)))
    far_opaque, far_opaque_alone = colours(quads(1.0, ("far",)))
    np.testing.assert_allclose(both, 0.5 * near_opaque + 0.5 * (0.5 * far_opaque + 0.5 * wall), atol=0.02)
    np.testing.assert_allclose(far_only, 0.5 * far_opaque_alone + 0.5 * wall, atol=0.02)
