"""Depth of field (``components/post.py`` DepthOfField, ``engine/render/depth_of_field.py``):
the way's length each level's seen image carries (against ray casts through a mirror and a
portal), the lens's radii against ``engine/rules/lens_rules.py``, the picture's blur where the
lens says (a mirror's frame against its reflection), the two layers at an edge, autofocus
through a mirror and a portal, and the component's checks."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    ComponentValueError,
    DepthOfField,
    DirectionalLight,
    Emissive,
    Material,
    MeshRef,
    Mirror,
    Skybox,
    Tonemap,
    Transform,
    Water,
    look_rotation,
)
from engine.assets.mesh import box, plane, quad
from engine.assets.portals import spawn_portal_pair
from engine.assets.texture_data import checker_texture
from engine.core.portal_math import pair_transform
from engine.render.depth_of_field import focus_pixel, tile_size
from engine.resources import Surfaces
from engine.rules.lens_rules import SKY_WAY, blur_radius, focal_length, focus_step, max_blur_radius
from tests.support import camera_level_round_trip, look_from, pixel_rays

SIZE = (128, 96)
TURN_Y_90 = glm.angleAxis(glm.radians(90), glm.vec3(0, 1, 0))


def lit(world):
    world.spawn(Skybox())
    world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))


def slab(origin, direction, lo, hi):
    """The distance along each ray (rows, unit directions) to the axis-aligned box lo..hi
    ahead of it, inf where it misses."""
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (np.asarray(lo) - origin) / direction
        b = (np.asarray(hi) - origin) / direction
    near = np.nanmax(np.minimum(a, b), axis=-1)
    far = np.nanmin(np.maximum(a, b), axis=-1)
    return np.where((near <= far) & (far > 1e-6), near, np.inf)


def test_the_way_is_the_length_of_the_lights_way_through_a_mirror(scene):
    """Direct floor pixels hold their distance from the eye, a box seen in a mirror the eye to
    the mirror plus the mirror to the box (ray cast in float64), the sky SKY_WAY."""
    ents = {}

    def build(world):
        lit(world)
        look_from(world, (0.5, 1.5, 4.0), (0, 1.5, 0))
        ents["mirror"] = world.spawn(Transform(position=(0, 1.5, -2)), MeshRef(quad(4, 3)),
                                     Material(color=(0.1, 0.1, 0.1)), Mirror())
        ents["floor"] = world.spawn(Transform(), MeshRef(plane(20, 20)), Material(color=(0.5, 0.5, 0.5)))
        ents["box"] = world.spawn(Transform(position=(-0.5, 1.2, 6.0)), MeshRef(box()), Material(color=(0.9, 0.1, 0.1)))

    runner = scene(build, SIZE)
    runner.frame()
    targets = runner.engine.renderer.targets
    ids, ways, surfaces = targets.read_ids(), targets.read_ways(), targets.read_surface_ids()
    eye, d = pixel_rays(runner.engine.main_view, SIZE)
    floor = (ids == ents["floor"]) & (surfaces == ents["floor"])
    assert floor.sum() > 1000
    np.testing.assert_allclose(ways[floor], (eye[1] / -d[..., 1])[floor], rtol=1e-4)
    # Through the mirror (the plane z = -2, facing +z): on along the reflected ray.
    in_mirror = (ids == ents["box"]) & (surfaces == ents["mirror"])
    assert in_mirror.sum() > 30
    t1 = (-2.0 - eye[2]) / d[..., 2]
    hit = eye + d * t1[..., None]
    reflected = d * np.array([1.0, 1.0, -1.0])
    t2 = slab(hit, reflected, (-1.0, 0.7, 5.5), (0.0, 1.7, 6.5))
    np.testing.assert_allclose(ways[in_mirror], (t1 + t2)[in_mirror], rtol=1e-4)
    sky = ids == 0
    assert sky.sum() > 300 and (ways[sky] == np.float32(SKY_WAY)).all()


def test_the_way_goes_on_through_a_portal(scene):
    """A box beyond the look-out portal: the eye to the look-in portal plus, carried through
    the pair (``pair_transform``), the partner to the box."""
    ents = {}
    green = ((12.7, 0.9, 0.1), (13.3, 1.5, 0.7))

    def build(world):
        lit(world)
        look_from(world, (0.5, 1.6, 6.0), (0, 1.5, 0))
        ents["a"], ents["b"] = spawn_portal_pair(world, (0, 1.5, 0), None, (10, 1.5, 0), TURN_Y_90)
        ents["green"] = world.spawn(Transform(position=(13.0, 1.2, 0.4), scale=(0.6, 0.6, 0.6)), MeshRef(box()),
                                    Material(color=(0.1, 0.9, 0.1)), Emissive(1.0))

    runner = scene(build, SIZE)
    runner.frame()
    targets = runner.engine.renderer.targets
    ids, ways = targets.read_ids(), targets.read_ways()
    seen = ids == ents["green"]
    assert seen.sum() > 20
    eye, d = pixel_rays(runner.engine.main_view, SIZE)
    t1 = -eye[2] / d[..., 2]   # A's plane: z = 0
    hit = eye + d * t1[..., None]
    world = runner.world
    carry = np.array(pair_transform(world.get(ents["a"], Transform).world, world.get(ents["b"], Transform).world))
    carried = hit @ carry[:3, :3].T + carry[:3, 3]
    direction = d @ carry[:3, :3].T
    t2 = slab(carried, direction, *green)
    np.testing.assert_allclose(ways[seen], (t1 + t2)[seen], rtol=1e-4)


def test_glass_leaves_the_way_of_what_shows_through_it(scene):
    """A pane of glass before a wall: its pixels' entity is the glass's, their way the wall's."""
    ents = {}

    def build(world):
        lit(world)
        look_from(world, (0.0, 1.5, 4.0), (0, 1.5, 0))
        ents["wall"] = world.spawn(Transform(position=(0, 1.5, -3.0)), MeshRef(quad(20, 10)),
                                   Material(color=(0.6, 0.6, 0.6)))
        ents["glass"] = world.spawn(Transform(position=(0, 1.5, 1.0)), MeshRef(quad(1.5, 1.5)),
                                    Material(color=(0.2, 0.4, 0.9, 0.4), blend="transparent"))

    runner = scene(build, SIZE)
    runner.frame()
    targets = runner.engine.renderer.targets
    ids, ways = targets.read_ids(), targets.read_ways()
    eye, d = pixel_rays(runner.engine.main_view, SIZE)
    to_wall = (-3.0 - eye[2]) / d[..., 2]
    glass = ids == ents["glass"]
    assert glass.sum() > 200
    np.testing.assert_allclose(ways[glass], to_wall[glass], rtol=1e-4)   # (the glass is 3 m nearer)
    wall = ids == ents["wall"]
    np.testing.assert_allclose(ways[wall], to_wall[wall], rtol=1e-4)


FRAMED_BLUR = 0.1


def framed_mirror(world, focus: float, autofocus: bool = False, fov: float = 60.0, **lens):
    """A mirror 2 m before the camera in a checker frame, reflecting a checker wall 6 m behind
    the camera (10 m along the way: 2 to the mirror, 8 back to the wall)."""
    lit(world)
    camera = look_from(world, (0.0, 1.5, 2.0), (0, 1.5, 0), fov=fov)
    world.add_component(camera, DepthOfField(focus_distance=focus, autofocus=autofocus,
                                             **({"f_stop": 1.4, "focal_length": 85.0, "max_blur": FRAMED_BLUR} | lens)))
    frame = world.spawn(Transform(position=(0, 1.5, -0.01)), MeshRef(quad(2.6, 2.0)),
                        Material(color=(0.9, 0.8, 0.2), texture=checker_texture(64, 16)), Emissive(0.5))
    mirror = world.spawn(Transform(position=(0, 1.5, 0)), MeshRef(quad(1.6, 1.0)), Material(color=(0.1, 0.1, 0.1)),
                         Mirror())
    wall = world.spawn(Transform(position=(0, 1.5, 8.0), rotation=glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))),
                       MeshRef(quad(30, 20)), Material(color=(0.9, 0.9, 0.9), texture=checker_texture(64, 16)),
                       Emissive(0.5))
    return {"camera": camera, "frame": frame, "mirror": mirror, "wall": wall}


def edge_strength(rgb: np.ndarray, mask: np.ndarray) -> float:
    """The mean step in brightness between pixels side by side, both in ``mask``."""
    grey = rgb.mean(axis=-1)
    pairs = mask[:, 1:] & mask[:, :-1]
    return float(np.abs(np.diff(grey, axis=1))[pairs].mean())


def sharp_and_blurred(runner) -> tuple[np.ndarray, np.ndarray]:
    """The same still frame presented without the lens (its overlay switch off) and with it,
    unantialiased: sRGB as floats (h, w, 3)."""
    runner.engine.renderer.antialias = "off"
    present = runner.engine.stages["present"]
    present.depth_of_field = False
    sharp = runner.frame().astype(float)
    present.depth_of_field = True
    return sharp, runner.frame().astype(float)


def erode(mask: np.ndarray, steps: int) -> np.ndarray:
    out = mask.copy()
    for _ in range(steps):
        out[1:-1, 1:-1] &= out[:-2, 1:-1] & out[2:, 1:-1] & out[1:-1, :-2] & out[1:-1, 2:]
        out[[0, -1], :] = False
        out[:, [0, -1]] = False
    return out


@pytest.mark.parametrize("focus_on", ["reflection", "frame"])
def test_focusing_on_the_reflection_blurs_the_mirrors_frame_and_the_other_way(scene, focus_on):
    """Focused at 10 m (the reflected wall's way) the reflection is as drawn and the frame 2 m
    away blurred; focused at 2 m the other way round: the blur follows the light's way, not the
    glass's distance (which a depth buffer would give both)."""
    ents = {}
    focus = 10.0 if focus_on == "reflection" else 2.0

    def build(world):
        ents.update(framed_mirror(world, focus))

    runner = scene(build, SIZE)
    sharp, blurred = sharp_and_blurred(runner)
    targets = runner.engine.renderer.targets
    ids, surfaces = targets.read_ids(), targets.read_surface_ids()
    reach = int(np.ceil(max_blur_radius(FRAMED_BLUR, SIZE[1]))) + 1
    reflection = erode((surfaces == ents["mirror"]) & (ids == ents["wall"]), reach)
    frame = erode(ids == ents["frame"], reach)
    assert reflection.sum() > 150 and frame.sum() > 150
    in_focus, out_of_focus = (reflection, frame) if focus_on == "reflection" else (frame, reflection)
    # (Sharp: where the lens's disc is under a pixel wide; the slanting reflection's far edge is not.)
    radii = runner.engine.renderer.present_pass.depth_of_field.prepared_radii()
    sharp_here = in_focus & (np.abs(radii) < 0.5)
    assert sharp_here.sum() > 200
    assert np.abs(blurred[sharp_here] - sharp[sharp_here]).max() <= 2.0
    # Out of focus: the checker's edges are gone (the step from pixel to pixel inside it shrinks).
    assert edge_strength(blurred, out_of_focus) < 0.75 * edge_strength(sharp, out_of_focus)
    assert runner.engine.renderer.present_pass.post_passes >= 4


def test_the_lens_radii_are_the_thin_lens_rules(scene):
    """The prepare step's radius at each pixel is ``lens_rules.blur_radius`` of the way the
    seen image holds there (the rule evaluated in float64 on the read-back ways)."""

    def build(world):
        lit(world)   # a narrow camera (a 68 mm lens) focused at 1 m: a box nearer, a wall 22 m away
        camera = look_from(world, (0.0, 1.5, 2.0), (0, 1.5, 0), fov=20.0)
        world.add_component(camera, DepthOfField(focus_distance=1.0, f_stop=2.0, max_blur=0.08))
        world.spawn(Transform(position=(0.1, 1.45, 1.2), scale=(0.1, 0.1, 0.1)), MeshRef(box()), Material())
        world.spawn(Transform(position=(0, 1.5, -20.0)), MeshRef(quad(40, 30)), Material())

    runner = scene(build, SIZE)
    runner.frame()
    ways = runner.engine.renderer.targets.read_ways()
    dof = runner.engine.renderer.present_pass.depth_of_field
    radii = dof.prepared_radii()
    f = focal_length(20.0)   # the camera's field of view: a 68 mm lens
    expected = blur_radius(ways, 1.0, f, 2.0, SIZE[1], max_blur_radius(0.08, SIZE[1]))
    assert (expected > 1.0).any() and (expected < -1.0).any()
    np.testing.assert_allclose(radii, expected, atol=0.01, rtol=2e-3)   # (half floats)


def edge_scene(world, focus: float, max_blur: float = 0.08):
    """A bright square 3 m from the camera before a dark wall 10 m away."""
    lit(world)
    camera = look_from(world, (0.0, 1.5, 3.0), (0, 1.5, 0))
    world.add_component(camera, DepthOfField(focus_distance=focus, f_stop=1.4, focal_length=85.0, max_blur=max_blur,
                                             half_resolution=False))
    square = world.spawn(Transform(position=(0.4, 1.5, 0.0)), MeshRef(quad(0.8, 0.8)), Material(color=(1.0, 1.0, 1.0)),
                         Emissive(1.0))
    world.spawn(Transform(position=(0, 1.5, -7.0)), MeshRef(quad(40, 30)), Material(color=(0.02, 0.02, 0.02)))
    return square


def _row_profile(runner, square):
    """The picture's red along the middle row, and the column of the square's left edge."""
    ids = runner.engine.renderer.targets.read_ids()
    row = SIZE[1] // 2
    columns = np.nonzero(ids[row] == square)[0]
    return row, columns[0]


def test_a_blurred_foreground_spreads_over_a_sharp_background(scene):
    """Focused on the wall, the near square's light spreads over the wall beside its edge, about
    half of it at the edge, fading out within the largest radius; far from the edge the wall
    is as drawn."""
    ents = {}

    def build(world):
        ents["square"] = edge_scene(world, 10.0)

    runner = scene(build, SIZE)
    sharp, blurred = (image[..., 0] for image in sharp_and_blurred(runner))
    row, edge = _row_profile(runner, ents["square"])
    reach = max_blur_radius(0.08, SIZE[1])
    radius = abs(float(runner.engine.renderer.present_pass.depth_of_field.prepared_radii()[row, edge + 2]))
    assert radius > 2.0
    outside = edge - 1
    assert blurred[row, outside] > sharp[row, outside] + 40    # its light over the sharp wall beside it
    far = int(edge - radius - 3)
    assert far > 0 and abs(blurred[row, far] - sharp[row, far]) <= 2.0
    assert reach >= radius


def test_a_sharp_foreground_leaves_no_halo_on_a_blurred_background(scene):
    """Focused on the square, it stays as drawn and the blurred wall beside it takes none of
    its light (a background's disc does not spread over what is in front of it, nor a sharp
    thing's over what lies behind)."""
    ents = {}

    def build(world):
        ents["square"] = edge_scene(world, 3.0)

    runner = scene(build, SIZE)
    sharp, blurred = (image[..., 0] for image in sharp_and_blurred(runner))
    row, edge = _row_profile(runner, ents["square"])
    radius = runner.engine.renderer.present_pass.depth_of_field.prepared_radii()[row, edge - 3]
    assert radius > 2.0   # the wall is blurred
    assert abs(blurred[row, edge - 1] - sharp[row, edge - 1]) <= 3.0
    assert abs(blurred[row, edge + 1] - sharp[row, edge + 1]) <= 2.0


def test_a_sharp_edge_stays_sharp_where_a_blurred_foreground_widens_the_gather(scene):
    """Focused on the square, with a tiny box nearer still just above its edge (so the
    gather about the edge reaches as far as that box's disc): the square's edge pixel keeps
    its colour; the blurred wall behind does not spread into it past the square's own (nil)
    disc."""
    ents = {}

    def build(world):
        ents["square"] = edge_scene(world, 3.0, max_blur=0.1)
        # 1.2 m from the eye, 7 pixels above the square's left edge, about two pixels wide.
        ents["near"] = world.spawn(Transform(position=(0.004, 1.5 + 7 / 69.3, 1.8), scale=(0.03, 0.03, 0.03)),
                                   MeshRef(box()), Material(color=(0.0, 0.0, 0.0)))

    runner = scene(build, SIZE)
    sharp, blurred = (image[..., 0] for image in sharp_and_blurred(runner))
    row, edge = _row_profile(runner, ents["square"])
    dof = runner.engine.renderer.present_pass.depth_of_field
    radii = dof.prepared_radii()
    tile = tile_size(max_blur_radius(0.1, SIZE[1]))
    # (What the test needs: the nearer box blurred, in the 3x3 tiles about the edge pixel but
    # its disc short of it; the wall's disc wide enough to reach the edge from beside it.)
    gl_row = SIZE[1] - 1 - row
    rows = slice(SIZE[1] - 1 - min((gl_row // tile + 2) * tile - 1, SIZE[1] - 1),
                 SIZE[1] - (gl_row // tile - 1) * tile)
    columns = slice(max((edge // tile - 1) * tile, 0), (edge // tile + 2) * tile)
    near = radii[rows, columns] < -2.0
    assert near.any()
    ys, xs = np.nonzero(radii < -0.5)
    assert np.hypot(ys - row, xs - edge).min() > abs(radii.min()) + 0.5
    assert radii[row, edge - 3] > 1.5 and abs(radii[row, edge]) < 0.3
    assert abs(blurred[row, edge] - sharp[row, edge]) <= 3.0


def test_autofocus_finds_the_reflection_and_follows_in_dioptres(scene):
    """Autofocus at the middle of a mirror focuses at the reflected wall's way (10 m, with the
    ray's slant), starting there on the camera's first frame; moved to the frame's corner it
    follows by ``focus_step`` each frame; a frame of dt 0 (a screenshot) does not move it."""
    ents = {}

    def build(world):
        ents.update(framed_mirror(world, 1.0, autofocus=True, focus_speed=3.0))

    runner = scene(build, SIZE)
    runner.frame()
    ways = runner.engine.renderer.targets.read_ways()
    dof = runner.engine.renderer.present_pass.depth_of_field
    col, gl_row = focus_pixel((0.5, 0.5), SIZE)
    target = float(ways[SIZE[1] - 1 - gl_row, col])
    assert 9.9 < target < 10.2
    assert dof.focused() == pytest.approx(target, rel=1e-6)
    # Aim at the frame (2 m away): the focus follows it in dioptres.
    lens = runner.world.get(ents["camera"], DepthOfField)
    lens.focus_point = (0.5, 0.08)
    focus = dof.focused()
    for dt in (1 / 60, 1 / 30, 0.0, 1 / 60):
        runner.frame(dt)
        ways = runner.engine.renderer.targets.read_ways()
        col, gl_row = focus_pixel(lens.focus_point, SIZE)
        near = float(ways[SIZE[1] - 1 - gl_row, col])
        assert 1.9 < near < 2.3
        blend = 1.0 - np.exp(-3.0 * dt)
        expected = focus_step(focus, near, blend)
        assert dof.focused() == pytest.approx(expected, rel=1e-4)
        if dt == 0.0:
            assert dof.focused() == focus
        focus = dof.focused()
    assert 2.3 < focus < 9.9   # on its way
    # Manual focus is at once.
    lens.autofocus = False
    lens.focus_distance = 5.0
    runner.frame()
    assert dof.focused() == 5.0


def test_an_orthographic_camera_has_a_lens_too(scene):
    """With no field of view the lens is lens_rules' orthographic one; the picture blurs."""
    def build(world):
        lit(world)
        world.spawn(Transform(position=(0, 1.5, 6), rotation=look_rotation(glm.vec3(0, 0, -1))),
                    Camera(projection="orthographic", ortho_height=4.0),
                    DepthOfField(focus_distance=2.0, f_stop=1.0, max_blur=0.05))
        world.spawn(Transform(position=(0, 1.5, 0)), MeshRef(quad(3, 3)),
                    Material(color=(0.9, 0.9, 0.9), texture=checker_texture(64, 16)), Emissive(0.5))

    runner = scene(build, SIZE)
    runner.frame()
    radii = runner.engine.renderer.present_pass.depth_of_field.prepared_radii()
    ways = runner.engine.renderer.targets.read_ways()
    expected = blur_radius(ways, 2.0, focal_length(None), 1.0, SIZE[1], max_blur_radius(0.05, SIZE[1]))
    np.testing.assert_allclose(radii, expected, atol=0.01, rtol=2e-3)
    assert np.abs(radii[SIZE[1] // 2, SIZE[0] // 2]) > 1.0


def test_the_images_go_with_the_component(scene):
    """Removing the DepthOfField lets its images go; the pass counts drop back."""
    ents = {}

    def build(world):
        ents.update(framed_mirror(world, 10.0))

    runner = scene(build, SIZE)
    runner.frame()
    present = runner.engine.renderer.present_pass
    # prepared, half size, tiles, the two layers, result and the two 1x1 focuses
    assert present.post_target_count() == 8 and present.post_passes == 6
    runner.world.remove_component(ents["camera"], DepthOfField)
    runner.frame()
    assert present.post_target_count() == 0 and present.post_passes == 0


@pytest.mark.parametrize(("field", "value"), [
    ("focus_distance", 0.0), ("focus_distance", float("inf")), ("f_stop", 0.1), ("f_stop", 100.0),
    ("focal_length", 0.5), ("focal_length", "50"), ("max_blur", 0.0), ("max_blur", 0.5), ("autofocus", 1),
    ("focus_point", (0.5, 1.5)), ("focus_point", (0.5,)), ("focus_point", "middle"), ("focus_speed", 0.0),
    ("blades", 2), ("blades", 17), ("blades", 6.0), ("blade_rotation", float("nan")),
])
def test_depth_of_field_values_are_checked(field, value):
    with pytest.raises(ComponentValueError, match=f"DepthOfField.{field}"):
        DepthOfField(**{field: value})


BOKEH_SIZE = 192


def lamp_picture(scene, half: bool = False, **lens) -> np.ndarray:
    """A bright square lamp 8 m away before a black wall, in linear light (96, 96 about its
    middle): sharp without ``lens``, else through a DepthOfField focused at 1 m (every pixel's
    disc the largest, ``max_blur`` 0.1 of the height) with ``lens``."""
    def build(world):
        camera = look_from(world, (0.0, 1.5, 8.0), (0, 1.5, 0))
        if lens:
            world.add_component(camera, DepthOfField(focus_distance=1.0, f_stop=1.4, focal_length=85.0,
                                                     max_blur=0.1, half_resolution=half, **lens))
        world.add_component(camera, Tonemap(exposure=1.0, curve="none"))
        world.spawn(Transform(position=(0, 1.5, 0)), MeshRef(quad(0.25, 0.25)), Material(color=(1.0, 1.0, 1.0)),
                    Emissive(0.4))
        world.spawn(Transform(position=(0, 1.5, -2.0)), MeshRef(quad(40, 40)), Material(color=(0.0, 0.0, 0.0)))

    runner = scene(build, (BOKEH_SIZE, BOKEH_SIZE))
    runner.engine.renderer.antialias = "off"
    encoded = runner.frame().astype(float).mean(axis=-1) / 255.0
    middle = slice(BOKEH_SIZE // 2 - 48, BOKEH_SIZE // 2 + 48)
    return np.where(encoded <= 0.04045, encoded / 12.92, ((encoded + 0.055) / 1.055) ** 2.4)[middle, middle]


def aperture_kernel(radius: float, blades: int, rotation: float = 0.0) -> np.ndarray:
    """The aperture's shape as a normalised kernel (y up, 8 x 8 samples a pixel): a disc of
    ``radius`` pixels, or the polygon of ``blades`` corners on it, the first ``rotation``
    degrees from the right."""
    reach = int(np.ceil(radius)) + 1
    fine = (np.arange(-reach * 8, reach * 8 + 8) + 0.5) / 8.0 - 0.5
    x, y = np.meshgrid(fine, fine)
    inside = np.hypot(x, y) <= radius
    if blades:
        wedge = 2.0 * math.pi / blades
        turned = np.mod(np.arctan2(y, x) - math.radians(rotation), wedge) - 0.5 * wedge
        inside = np.hypot(x, y) * np.cos(turned) / math.cos(0.5 * wedge) <= radius
    kernel = inside.reshape(2 * reach + 1, 8, 2 * reach + 1, 8).mean(axis=(1, 3))
    return kernel / kernel.sum()


def convolved(picture: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """``picture`` (row 0 at the top) spread by ``kernel`` (y up), each pixel's light over it."""
    size = picture.shape[0] + kernel.shape[0]
    flipped = kernel[::-1]   # (rows down)
    spread = np.fft.irfft2(np.fft.rfft2(picture, (size, size)) * np.fft.rfft2(flipped, (size, size)), (size, size))
    half = kernel.shape[0] // 2
    return spread[half: half + picture.shape[0], half: half + picture.shape[1]]


@pytest.mark.parametrize(("blades", "rotation", "half"), [(6, 0.0, False), (5, 20.0, False), (5, 20.0, True)])
def test_a_bladed_aperture_blurs_a_lamp_into_its_polygon(scene, blades, rotation, half):
    """A lamp far out of focus is the sharp lamp spread by the aperture's shape (a second
    path: the sharp picture convolved here): with blades, it matches the polygon's spread
    better than the round disc's where the two differ, and round the other way about; its
    light is kept."""
    sharp = lamp_picture(scene)
    radius = max_blur_radius(0.1, BOKEH_SIZE)
    by_polygon = convolved(sharp, aperture_kernel(radius, blades, rotation))
    by_disc = convolved(sharp, aperture_kernel(radius, 0))
    bladed = lamp_picture(scene, half, blades=blades, blade_rotation=rotation)
    rounded = lamp_picture(scene, half, blades=0)
    apart = np.abs(by_polygon - by_disc)
    near = apart > 0.25 * apart.max()   # (where the two shapes' spreads differ: about its corners and edges)
    polygon_error, disc_error = (np.abs(bladed - by_polygon)[near].mean(), np.abs(bladed - by_disc)[near].mean())
    assert polygon_error < 0.7 * disc_error, (polygon_error, disc_error)
    round_disc, round_polygon = (np.abs(rounded - by_disc)[near].mean(), np.abs(rounded - by_polygon)[near].mean())
    assert round_disc < round_polygon, (round_disc, round_polygon)
    assert bladed.sum() == pytest.approx(sharp.sum(), rel=0.1) and rounded.sum() == pytest.approx(sharp.sum(), rel=0.1)


def test_a_level_file_keeps_the_lens(tmp_path):
    """[entity.DepthOfField] read, saved and read again; a bad value names the field."""
    again, eye = camera_level_round_trip(
        tmp_path, "DepthOfField = { focus_distance = 3.5, f_stop = 1.8, focal_length = 50.0, autofocus = true, "
                  "focus_point = [0.25, 0.75] }", ("f_stop = 1.8", "f_stop = 0.1"), "f_stop")
    lens = again.get(eye, DepthOfField)
    assert (lens.focus_distance, lens.f_stop, lens.focal_length, lens.autofocus) == (3.5, 1.8, 50.0, True)
    assert tuple(lens.focus_point) == (0.25, 0.75)


def test_the_overlay_names_the_lens_and_its_switch_turns_it_off(scene):
    """The overlay's screen line gives the f-number and the focus (autofocus's read back);
    ``PresentSystem.depth_of_field = False`` (its "DoF" switch) draws none and says so."""
    from shell.overlay_text import post_lines

    def build(world):
        framed_mirror(world, 1.0, autofocus=True)

    runner = scene(build, SIZE)
    runner.frame()
    line = post_lines(runner.engine)[1]
    focus = runner.engine.renderer.present_pass.depth_of_field.focused()
    assert line.endswith(f"; DoF f/1.4 at {focus:.3g} m auto"), line
    runner.engine.stages["present"].depth_of_field = False
    runner.frame()
    assert post_lines(runner.engine)[1].endswith("; DoF off (set)")
    assert runner.engine.renderer.present_pass.post_target_count() == 0


def test_the_half_size_gather_agrees_with_the_full_size_one(scene):
    """The same lens gathered at half size and at full size: the sharp frame identical, the
    blurred reflection close (a half-size blur of a blur), and both far from the sharp one."""
    ents = {}

    def build(world):
        ents.update(framed_mirror(world, 2.0))

    runner = scene(build, SIZE)
    lens = runner.world.get(ents["camera"], DepthOfField)
    sharp, half = sharp_and_blurred(runner)
    lens.half_resolution = False
    full = runner.frame().astype(float)
    assert runner.engine.renderer.present_pass.post_passes == 4
    targets = runner.engine.renderer.targets
    ids, surfaces = targets.read_ids(), targets.read_surface_ids()
    reach = int(np.ceil(max_blur_radius(FRAMED_BLUR, SIZE[1]))) + 1
    reflection = erode((surfaces == ents["mirror"]) & (ids == ents["wall"]), reach)
    radii = runner.engine.renderer.present_pass.depth_of_field.prepared_radii()
    frame = erode(ids == ents["frame"], reach) & (np.abs(radii) < 0.5)
    assert frame.sum() > 100
    assert np.abs(half[frame] - full[frame]).max() <= 1.0
    apart = np.abs(half[reflection] - full[reflection]).mean()
    assert apart < 4.0
    assert np.abs(full[reflection] - sharp[reflection]).mean() > 3.0 * apart


@pytest.mark.parametrize("pose", ["start", "back_mirror", "partner_side"])
def test_every_pixel_of_the_sample_level_has_a_way_no_shorter_than_its_first_surface(ctx, pose):
    """The sample level (mirrors facing with end images, portals, the pond's water, glass,
    probes): every pixel's way is finite and positive; where the main view's depth buffer holds
    a surface, the way is at least the eye's distance to it (a second path: the depth read
    back and carried out by the inverse projection), equal where that surface is the thing seen
    (not a mirror, portal or water); the sky's is SKY_WAY."""
    from engine.core.frame_io import Output
    from engine.render.targets import CaptureTarget
    from games.hall_of_mirrors.level import HallOfMirrors
    from shell.app import Engine
    from tests.golden_scenes import HALL_POSES

    engine = Engine(HallOfMirrors(), ctx)
    size = (160, 90)
    capture = CaptureTarget(ctx, size)
    try:
        if HALL_POSES[pose] is not None:
            engine.place_camera(*HALL_POSES[pose])
        for _ in range(3):
            engine.frame(1 / 60, Output(capture.framebuffer, size))
        targets = engine.renderer.targets
        ways, surfaces = targets.read_ways(), targets.read_surface_ids()
        w, h = targets.size
        depth = np.flipud(np.frombuffer(targets.depth.read(), np.float32).reshape(h, w))
        view = engine.main_view
        eye, directions = pixel_rays(view, (w, h))
        inverse = np.array(glm.inverse(glm.dmat4(view.view_proj)).to_list(), np.float64).T
        xs, ys = np.meshgrid((np.arange(w) + 0.5) / w * 2 - 1, 1 - (np.arange(h) + 0.5) / h * 2)
        clip = np.stack([xs, ys, depth * 2.0 - 1.0, np.ones_like(xs)], axis=-1) @ inverse.T
        first = np.linalg.norm(clip[..., :3] / clip[..., 3:] - eye, axis=-1)
        surfaced = depth < 1.0
        assert np.isfinite(ways).all() and (ways > 0.0).all()
        assert (ways[~surfaced] == np.float32(SKY_WAY)).all()
        state = engine.world.resources
        looking_on = set(state[Surfaces].mirrors) | set(state[Surfaces].portals)
        water = {entity for entity, _ in engine.world.query_one(Water)}
        looking_on |= water
        # (Water is drawn see-through, writing no depth: the depth there is the basin's under it.)
        solid = surfaced & ~np.isin(surfaces, list(water))
        assert (ways[solid] >= first[solid] * (1 - 2e-3) - 2e-3).all()
        direct = surfaced & ~np.isin(surfaces, list(looking_on))
        assert direct.sum() > 0.3 * w * h
        np.testing.assert_allclose(ways[direct], first[direct], rtol=3e-3, atol=3e-3)
        reflected = surfaced & np.isin(surfaces, list(looking_on))
        assert reflected.sum() > 200 and (ways[reflected] > first[reflected] * 1.01).mean() > 0.5
    finally:
        capture.release()
        engine.close()


@pytest.mark.parametrize("path, target", [("per_mirror", "wall"), ("batched", "wall"),
                                          ("per_mirror", "cut_mirror")])
@pytest.mark.parametrize("scale", [1.0, 2.0])
def test_autofocus_through_a_portal_focuses_on_what_lies_beyond_its_partner(scene, scale, path, target):
    """Autofocus at the middle of portal a, which shows a wall 4 m beyond its partner b (10 m
    to the side, turned 90 degrees): the focus is the way cast here in float64 at the focus
    pixel (the eye to a's plane, then carried through the pair, b to the wall), about 10 m, not
    a's 6 m; the wall's pixels there are the wall's through a.  With b scaled 2 the pair shows
    the wall half as far beyond a (the image's way, 6 + 4 / 2 m: the carried ray's parameter,
    its direction twice as long), not the carried eye's 2 x 6 + 4; on either path (the batched
    one reads the view's scale from its row of the Views block).  "cut_mirror": a mirror
    switched off stands there, drawn as its fallback over the portal's view, whose way is the
    way to its glass."""
    ents = {}

    def build(world):
        lit(world)
        camera = look_from(world, (0.0, 1.5, 6.0), (0, 1.5, 0))
        world.add_component(camera, DepthOfField(autofocus=True, f_stop=1.4, focal_length=85.0))
        ents["a"], ents["b"] = spawn_portal_pair(world, (0, 1.5, 0), None, (10, 1.5, 0), TURN_Y_90)
        world.get(ents["b"], Transform).scale = glm.vec3(scale)
        ents["wall"] = world.spawn(Transform(position=(14.0, 1.5, 0.0), rotation=glm.angleAxis(-glm.pi() / 2,
                                                                                               glm.vec3(0, 1, 0))),
                                   MeshRef(quad(6, 6)), Material(color=(0.9, 0.9, 0.9), texture=checker_texture(64, 8)),
                                   *([Mirror(enabled=False)] if target == "cut_mirror" else [Emissive(0.5)]))

    runner = scene(build, SIZE)
    runner.engine.reflection_system.path = path
    runner.frame()
    stats = runner.engine.renderer.stats
    assert stats.reflection_path == path and (stats.reflection_fallbacks > 0) == (target == "cut_mirror")
    col, gl_row = focus_pixel((0.5, 0.5), SIZE)
    row = SIZE[1] - 1 - gl_row
    targets = runner.engine.renderer.targets
    assert targets.read_ids()[row, col] == ents["wall"]
    assert targets.read_surface_ids()[row, col] == ents["a"]
    eye, d = pixel_rays(runner.engine.main_view, SIZE)
    ray = d[row, col]
    t1 = -eye[2] / ray[2]
    world = runner.world
    carry = np.array(pair_transform(world.get(ents["a"], Transform).world, world.get(ents["b"], Transform).world))
    carried = carry[:3, :3] @ (eye + ray * t1) + carry[:3, 3]
    direction = carry[:3, :3] @ ray
    t2 = (14.0 - carried[0]) / direction[0]   # the wall: the plane x = 14 (in the ray's parameter: a's metres)
    assert 6.0 + 4.0 / scale - 0.5 < t1 + t2 < 6.0 + 4.0 / scale + 0.5
    assert runner.engine.renderer.present_pass.depth_of_field.focused() == pytest.approx(t1 + t2, rel=1e-4)
