"""Orthographic cameras (``Camera.projection = "orthographic"``): parallel rays, for
isometric and top-down games.  The picture is checked against a second path, the limit it
is of: a perspective camera far back along the same axis with a field of view that spans the
same height at the scene (its rays all but parallel), which the engine already draws right:
the same floor, shadows, sky, highlights, a mirror's reflection by both reflection paths and
a chrome ball's probe.  Then the projection's own facts (a thing's size on screen whatever
its distance), the transparent slot's order, refusals, a glTF's orthographic camera and a
level file's."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import (
    AmbientOcclusion,
    Camera,
    ComponentValueError,
    DepthOfField,
    DirectionalLight,
    Emissive,
    HemisphereLight,
    Material,
    MeshRef,
    Mirror,
    Reflective,
    ScreenReflections,
    Transform,
)
from engine.assets.mesh import box, plane, quad, sphere
from engine.assets.portals import spawn_portal_pair
from engine.assets.texture_data import checker_texture
from engine.core.portal_math import pair_transform
from engine.core.world import World
from engine.render.depth_of_field import focus_pixel
from tests.support import look_rotation
from tests.test_skinning import same_picture

TARGET = glm.vec3(0.0, 0.8, 0.0)
AXIS = glm.normalize(glm.vec3(-0.55, -0.6, -1.0))   # the way the camera looks
HEIGHT = 6.0                                        # world units the view spans top to bottom
FOV = 1.0                                           # the stand-in's field of view (the least a Camera takes)
FAR_BACK = HEIGHT / 2.0 / math.tan(math.radians(FOV / 2.0))  # its distance: HEIGHT across at TARGET


def camera(world, kind: str) -> int:
    """The orthographic camera 10 back from TARGET, or its stand-in FAR_BACK back."""
    if kind == "orthographic":
        eye = TARGET - AXIS * 10.0
        lens = Camera(projection="orthographic", ortho_height=HEIGHT, near=0.1, far=40.0)
    else:
        eye = TARGET - AXIS * FAR_BACK
        lens = Camera(fov_y=FOV, near=FAR_BACK - 30.0, far=FAR_BACK + 30.0)
    return world.spawn(Transform(position=eye, rotation=look_rotation(AXIS)), lens)


def things(world) -> None:
    """A brushed-metal floor under a sun (one shadow map over the level) shining along the
    view axis mirrored in it (an orthographic view sees its highlight on all of the floor at
    once: its rays are parallel; from a near eye it would be a spot) and a second sun doing
    the same for the mirror's view, light from all round, a red box, a blue ball, a chrome
    ball with its own probe and a mirror behind them."""
    world.spawn(DirectionalLight(direction=glm.vec3(-AXIS.x, AXIS.y, -AXIS.z), intensity=0.25))
    # ... and a second sun doing the same for the mirror's view (the axis mirrored in its plane)
    world.spawn(DirectionalLight(direction=glm.vec3(-AXIS.x, AXIS.y, AXIS.z), intensity=0.25, shadows=False))
    world.spawn(HemisphereLight(intensity=1.0))
    world.spawn(Transform(), MeshRef(plane(40, 40)), Material(color=(0.7, 0.7, 0.7, 1.0), metallic=0.8,
                                                              roughness=0.45))
    world.spawn(Transform(position=(-1.2, 0.5, 0.6)), MeshRef(box()),
                Material(color=(0.8, 0.15, 0.1, 1.0), roughness=0.35))
    world.spawn(Transform(position=(0.9, 0.6, 0.9)), MeshRef(sphere(0.6)),
                Material(color=(0.1, 0.2, 0.8, 1.0), roughness=0.25))
    world.spawn(Transform(position=(0.2, 0.5, -0.4)), MeshRef(sphere(0.5)),
                Material(color=(1, 1, 1), metallic=1.0, roughness=0.05), Reflective("cube"))
    world.spawn(Transform(position=(1.6, 1.2, -1.8)), MeshRef(quad(3.0, 2.4)), Mirror())


def same_but_edges(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal but where an edge moved by a pixel (the stand-in's rays are a degree apart: what
    lies nearer or farther than TARGET is a fraction of a percent larger or smaller): each
    pixel of ``a`` within 12 levels of ``b``'s at it or one of its eight neighbours, but for a
    few: 1% (an edge a metre off TARGET moves by a third of a pixel, and its pixel blends two
    sides; measured 0.4%; an orthographic view shaded from its camera's place, as a
    perspective one is, differs on 44%: its floor's highlight a spot)."""
    padded = np.pad(b, ((1, 1), (1, 1), (0, 0)), mode="edge")
    h, w = a.shape[:2]
    best = np.full((h, w), 1 << 30)
    for dy in range(3):
        for dx in range(3):
            best = np.minimum(best, np.abs(a - padded[dy:dy + h, dx:dx + w]).max(axis=-1))
    return (best > 12).sum() <= 0.01 * best.size


def frame(scene, kind: str, path: str | None = None, size=(160, 120)) -> np.ndarray:
    def build(world):
        camera(world, kind)
        things(world)
    runner = scene(build, size)
    if path is not None:
        runner.engine.reflection_system.path = path
    for _ in range(3):
        image = runner.frame()
    if path is not None:
        assert runner.stats.reflection_path == path and runner.stats.reflection_views >= 1
    return image.astype(int)


@pytest.mark.parametrize("path", ["per_mirror", "batched"])
def test_an_orthographic_view_is_a_far_narrow_perspectives_limit(scene, path):
    ortho, standin = frame(scene, "orthographic", path), frame(scene, "perspective", path)
    assert same_but_edges(ortho, standin) and same_but_edges(standin, ortho)
    assert not same_picture(ortho, standin)   # (the stand-in's edges do move: the comparison is not vacuous)
    assert (np.abs(ortho - ortho[5, 5]).max(axis=-1) > 40).sum() > 2000   # (the things and the mirror are there)


def ortho_camera(world, position, height: float, axis=(0.0, 0.0, -1.0)) -> int:
    return world.spawn(Transform(position=glm.vec3(position), rotation=look_rotation(glm.vec3(axis))),
                       Camera(projection="orthographic", ortho_height=height, near=0.1, far=60.0))


def test_a_thing_is_its_size_on_screen_whatever_its_distance(scene):
    """Two 1 m boxes, one 2 m and one 25 m down the axis: both 1/6 of the view's 6 m height
    across (20 of 120 pixels), as a perspective camera would not draw them."""
    def build(world):
        ortho_camera(world, (0.0, 0.0, 5.0), 6.0)
        world.spawn(Transform(position=(-1.5, 0.0, 3.0)), MeshRef(box()), Material(color=(1, 0, 0, 1), unlit=True))
        world.spawn(Transform(position=(1.5, 0.0, -20.0)), MeshRef(box()), Material(color=(0, 1, 0, 1), unlit=True))

    runner = scene(build, (160, 120))
    image = runner.frame().astype(int)
    for channel, other in ((0, 1), (1, 0)):
        mask = (image[..., channel] > 200) & (image[..., other] < 60)
        rows, columns = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
        assert abs(len(rows) - 20) <= 1 and abs(len(columns) - 20) <= 1, (channel, len(rows), len(columns))


def test_the_transparent_slot_orders_an_orthographic_view_by_depth(scene):
    """Two half-transparent panes, the red one 1 m in front of the blue one but farther from
    the camera's place (the camera stands 10 m to the side of them, its view wide): where they
    overlap the red is over the blue, as depth says (from the camera's place the blue would
    be nearer)."""
    def build(world):
        ortho_camera(world, (10.0, 0.0, 0.0), 30.0)
        world.spawn(Transform(position=(0.0, 0.0, -5.0)), MeshRef(quad(4.0, 4.0)),
                    Material(color=(1.0, 0.0, 0.0, 0.5), unlit=True))
        world.spawn(Transform(position=(1.5, 0.0, -6.0)), MeshRef(quad(4.0, 4.0)),
                    Material(color=(0.0, 0.0, 1.0, 0.5), unlit=True))

    runner = scene(build, (160, 120))
    image = runner.frame().astype(int)
    column, row = runner.project(glm.vec3(0.75, 0.0, -5.5))   # (inside both panes on screen)
    red, _, blue = image[row, column]
    assert red > blue + 40, (red, blue)


def test_screen_passes_are_refused_on_an_orthographic_camera():
    world = World("ortho")
    entity = world.spawn(Transform(), Camera(projection="orthographic"))
    with pytest.raises(ComponentValueError, match=r"AmbientOcclusion on an orthographic Camera"):
        world.add_component(entity, AmbientOcclusion())
    seeing = world.spawn(Transform(), Camera(), ScreenReflections())
    with pytest.raises(ComponentValueError, match=r"ScreenReflections on an orthographic Camera"):
        world.get(seeing, Camera).projection = "orthographic"
    assert world.get(seeing, Camera).projection == "perspective"
    with pytest.raises(ComponentValueError, match=r"Camera.projection"):
        Camera(projection="fisheye")
    with pytest.raises(ComponentValueError, match=r"Camera.ortho_height"):
        Camera(ortho_height=0.0)


def test_a_level_file_places_an_orthographic_camera(tmp_path):
    from engine.assets.level_file import load_level
    from engine.assets.level_save import save_level

    (tmp_path / "iso.toml").write_text('[level]\nname = "iso"\n\n[[entity]]\nname = "camera"\n[entity.Transform]\n'
                                       '[entity.Camera]\nprojection = "orthographic"\northo_height = 12.0\n')
    world = World("iso")
    names = load_level(tmp_path / "iso.toml").spawn(world)
    lens = world.get(names["camera"], Camera)
    assert (lens.projection, lens.ortho_height) == ("orthographic", 12.0)
    saved = save_level(world, tmp_path / "again.toml", names, name="iso").read_text()
    assert 'projection = "orthographic"' in saved and "ortho_height = 12.0" in saved


def test_the_mouse_wheel_zooms_an_orthographic_fly_camera_and_flies_a_perspective_one():
    """Two wheel steps away: an orthographic camera's height times 0.9^2, its place kept; a
    perspective one half a second's flight forward (a quarter a step), its lens kept; the
    wheel forgotten after the frame."""
    from components import FlyController
    from engine.core.frame_io import Input
    from systems.fly_camera_system import FlyCameraSystem

    world = World("wheel")
    flat = world.spawn(Transform(position=(0.0, 5.0, 0.0)), Camera(projection="orthographic", ortho_height=10.0),
                       FlyController(speed=4.0))
    deep = world.spawn(Transform(), Camera(), FlyController(speed=4.0))
    stage = FlyCameraSystem(world)
    world.resources[Input].wheel = 2.0
    stage.process(1 / 60)
    assert world.get(flat, Camera).ortho_height == pytest.approx(8.1)
    assert list(world.get(flat, Transform).position) == [0.0, 5.0, 0.0]
    assert list(world.get(deep, Transform).position) == pytest.approx([0.0, 0.0, -2.0])
    world.resources[Input].end_frame()
    assert world.resources[Input].wheel == 0.0


def test_the_editors_handles_are_one_size_on_screen_in_an_orthographic_view():
    """The move handles of a thing near and of one far down an orthographic view's axis are
    equally long on screen, a share of the view's height as a 60-degree camera's are (their
    world length from the view's height, not from the distance to the camera's place)."""
    from engine.render.views import camera_view
    from shell.handles import transform_handles

    world = World("handles")
    near = world.spawn(Transform(position=(0.0, 0.0, -2.0)))
    far = world.spawn(Transform(position=(1.0, 0.0, -30.0)))
    eye = glm.mat4(1.0)  # (at the origin, looking down -z)
    view = camera_view(eye, 60.0, 0.1, 100.0, (200, 150), ortho_height=8.0)
    lengths = []
    for entity in (near, far):
        handles = transform_handles(world, entity, view.view_proj, view.eye, (200, 150))
        (x0, y0), (x1, y1) = handles.lines[1]   # the y axis: straight up the screen
        lengths.append(math.hypot(x1 - x0, y1 - y0))
    assert lengths[0] == pytest.approx(lengths[1], rel=1e-4)
    perspective = camera_view(eye, 60.0, 0.1, 100.0, (200, 150))
    handles = transform_handles(world, near, perspective.view_proj, perspective.eye, (200, 150))
    (x0, y0), (x1, y1) = handles.lines[1]
    assert lengths[0] == pytest.approx(math.hypot(x1 - x0, y1 - y0), rel=0.02)


@pytest.mark.parametrize("target", ["wall", "cut_mirror"])
@pytest.mark.parametrize("scale, path", [(1.0, "per_mirror"), (1.0, "batched"), (2.0, "per_mirror"),
                                         (2.0, "batched")])
def test_an_orthographic_view_through_a_pair_of_two_sizes_focuses_on_the_images_distance(scene, scale, path,
                                                                                        target):
    """An orthographic camera 6 m before portal a, whose partner b (10 m to the side, turned
    90 degrees, scaled ``scale``) shows an emissive wall 4 m beyond it: the way each pixel
    through a holds, and the autofocus at its middle, is the image's distance, worked out here
    in float64 along each parallel ray (its start on the plane across the axis through the
    eye, to a's plane, then carried through the pair to the wall, in the ray's parameter: a's
    metres): 6 + 4 / scale, not the carried eye's 6 x scale + 4, as a perspective camera's is
    (tests/test_depth_of_field.py); on either reflection path (the view's metres in the root's
    read off its view matrix, or its row of the Views block).  "cut_mirror": a mirror switched
    off stands there, drawn as its fallback over the portal's view (its row's parent scale),
    whose way is the way to its glass."""
    size = (96, 64)
    ents = {}

    def build(world):
        world.spawn(HemisphereLight(intensity=1.0))
        camera = ortho_camera(world, (0.0, 1.5, 6.0), 2.4)
        world.add_component(camera, DepthOfField(autofocus=True, f_stop=1.4, focal_length=85.0))
        ents["a"], ents["b"] = spawn_portal_pair(world, (0, 1.5, 0), None, (10, 1.5, 0),
                                                 glm.angleAxis(glm.radians(90), glm.vec3(0, 1, 0)))
        world.get(ents["b"], Transform).scale = glm.vec3(scale)
        ents["wall"] = world.spawn(Transform(position=(14.0, 1.5, 0.0),
                                             rotation=glm.angleAxis(-glm.pi() / 2, glm.vec3(0, 1, 0))),
                                   MeshRef(quad(10, 10)),
                                   Material(color=(0.9, 0.9, 0.9), texture=checker_texture(64, 8)),
                                   *([Mirror(enabled=False)] if target == "cut_mirror" else [Emissive(0.5)]))

    runner = scene(build, size)
    runner.engine.reflection_system.path = path
    runner.frame()
    assert runner.stats.reflection_path == path
    assert (runner.stats.reflection_fallbacks > 0) == (target == "cut_mirror")
    targets = runner.engine.renderer.targets
    ids, surfaces, ways = targets.read_ids(), targets.read_surface_ids(), targets.read_ways()
    through = surfaces == ents["a"]
    assert through.sum() > 0.3 * size[0] * size[1] and (ids[through] == ents["wall"]).all()
    # each pixel's parallel ray: from the near plane, along the axis (float64)
    view = runner.engine.main_view
    inverse = np.array(glm.inverse(glm.dmat4(view.view_proj)).to_list(), np.float64).T
    w, h = size
    xs, ys = np.meshgrid((np.arange(w) + 0.5) / w * 2 - 1, 1 - (np.arange(h) + 0.5) / h * 2)
    ends = [np.stack([xs, ys, np.full_like(xs, z), np.ones_like(xs)], axis=-1) @ inverse.T for z in (-1.0, 1.0)]
    near, far = (end[..., :3] / end[..., 3:] for end in ends)
    ray = (far - near) / np.linalg.norm(far - near, axis=-1, keepdims=True)
    eye = np.array(view.eye, np.float64)
    start = near + ray * ((eye - near) * ray).sum(axis=-1, keepdims=True)   # on the plane across the axis at the eye
    t1 = -start[..., 2] / ray[..., 2]                                          # to a's plane z = 0
    world = runner.world
    carry = np.array(pair_transform(world.get(ents["a"], Transform).world, world.get(ents["b"], Transform).world),
                     np.float64)
    carried = (start + ray * t1[..., None]) @ carry[:3, :3].T + carry[:3, 3]
    direction = ray @ carry[:3, :3].T
    t2 = (14.0 - carried[..., 0]) / direction[..., 0]                          # the wall: x = 14
    expected = t1 + t2
    assert abs(expected[through].mean() - (6.0 + 4.0 / scale)) < 1e-3
    np.testing.assert_allclose(ways[through], expected[through], rtol=2e-3)
    col, gl_row = focus_pixel((0.5, 0.5), size)
    assert through[h - 1 - gl_row, col]
    assert runner.engine.renderer.present_pass.depth_of_field.focused() == pytest.approx(
        expected[h - 1 - gl_row, col], rel=1e-4)
