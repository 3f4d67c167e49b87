"""Camera motion blur (``components/post.py`` MotionBlur, ``engine/render/motion_blur.py``):
each pixel's streak against the screen motion of the point it shows, worked out from the
geometry (a reflection's image behind the glass, a box's image through a portal pair, by the
camera's motion and by its own, a direct point, the sky's direction); a still
camera leaves the picture as it was; a camera carried through a portal keeps its motion; the
component's checks, its level-file table and its images' release."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, Material, MeshRef, Mirror, MotionBlur, Transform
from engine.assets.mesh import box, plane, quad
from engine.assets.portals import spawn_portal_pair
from engine.assets.texture_data import checker_texture
from engine.core.reflection_math import plane_from_point_normal, reflection_matrix
from tests.support import camera_level_round_trip, look_from
from tests.test_mirrors import base_scene

SIZE = (160, 120)
BOX = glm.vec3(0.3, 1.5, 12.0)   # behind the camera: seen in the mirror only
FRAME_POINT = glm.vec3(-1.1, 1.8, -0.01)   # on the mirror's frame, seen directly


def mirror_scene(world, ents, shutter=1.0):
    base_scene(world)
    ents["camera"] = look_from(world, (0.0, 1.5, 2.0), (0, 1.5, 0))
    world.add_component(ents["camera"], MotionBlur(shutter=shutter, max_blur=0.2))
    ents["frame"] = world.spawn(Transform(position=(0, 1.5, -0.01)), MeshRef(quad(2.6, 2.0)),
                                Material(color=(0.9, 0.8, 0.2), texture=checker_texture(64, 16)))
    ents["mirror"] = world.spawn(Transform(position=(0, 1.5, 0)), MeshRef(quad(2.0, 1.4)),
                                 Material(color=(0.1, 0.1, 0.1)), Mirror())
    world.spawn(Transform(), MeshRef(plane(40, 40)), Material(color=(0.8, 0.8, 0.8), texture=checker_texture(256, 32)))
    ents["box"] = world.spawn(Transform(position=BOX, scale=(0.6, 0.6, 0.6)), MeshRef(box()),
                              Material(color=(0.9, 0.1, 0.1), texture=checker_texture(64, 4)))


def gl_pixel(view_proj: glm.mat4, point: glm.vec4) -> glm.vec2:
    """Where a point (w 1) or direction (w 0) lands, in pixels, y up (GL's)."""
    clip = view_proj * point
    return (glm.vec2(clip) / clip.w * 0.5 + 0.5) * glm.vec2(*SIZE)


def streak_at(runner, pixel: glm.vec2) -> np.ndarray:
    streaks = runner.engine.renderer.present_pass.motion_blur.streaks()
    return streaks[SIZE[1] - 1 - int(pixel.y), int(pixel.x)]


@pytest.mark.parametrize("shutter", [1.0, 0.5])
def test_a_reflection_streaks_as_its_image_moves_not_as_the_glass(scene, shutter):
    """The camera steps sideways: the box seen in the mirror streaks by the motion of its
    image behind the glass (14 m along the way), the frame by its own (2 m), each times the
    shutter; a depth buffer's point on the glass would give the box the frame's streak."""
    ents = {}
    runner = scene(lambda world: mirror_scene(world, ents, shutter), SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    before = glm.mat4(runner.engine.main_view.view_proj)
    runner.world.get(ents["camera"], Transform).position += glm.vec3(0.1, 0.0, 0.0)
    runner.frame()
    now = glm.mat4(runner.engine.main_view.view_proj)
    image = glm.vec4(glm.vec3(reflection_matrix(plane_from_point_normal((0, 1.5, 0), (0, 0, 1)))
                              * glm.vec4(BOX, 1.0)), 1.0)
    at = gl_pixel(now, image)
    assert runner.ids()[SIZE[1] - 1 - int(at.y), int(at.x)] == ents["box"]
    expected = (at - gl_pixel(before, image)) * shutter
    np.testing.assert_allclose(streak_at(runner, at), expected, rtol=0.03, atol=0.02)
    on_frame = gl_pixel(now, glm.vec4(FRAME_POINT, 1.0))
    assert runner.ids()[SIZE[1] - 1 - int(on_frame.y), int(on_frame.x)] == ents["frame"]
    frame_expected = (on_frame - gl_pixel(before, glm.vec4(FRAME_POINT, 1.0))) * shutter
    np.testing.assert_allclose(streak_at(runner, on_frame), frame_expected, rtol=0.03, atol=0.02)
    assert abs(frame_expected.x) > 4.0 * abs(expected.x) > 0.5   # (nearer moves more)


def test_the_sky_streaks_by_the_cameras_turn_alone(scene):
    """A yaw of the camera: a sky pixel's streak is its direction's motion on screen."""
    ents = {}
    runner = scene(lambda world: mirror_scene(world, ents), SIZE)
    runner.frame()
    before = glm.mat4(runner.engine.main_view.view_proj)
    transform = runner.world.get(ents["camera"], Transform)
    transform.rotation = glm.angleAxis(glm.radians(2.0), glm.vec3(0, 1, 0)) * transform.rotation
    runner.frame()
    now = glm.mat4(runner.engine.main_view.view_proj)
    pixel = glm.vec2(SIZE[0] * 0.5 + 0.5, SIZE[1] - 6.5)   # the top middle: sky
    assert runner.ids()[5, SIZE[0] // 2] == 0
    ndc = glm.vec4(pixel / glm.vec2(*SIZE) * 2.0 - 1.0, 1.0, 1.0)
    far = glm.inverse(now) * ndc
    direction = glm.vec4(glm.normalize(glm.vec3(far) / far.w - runner.engine.main_view.eye), 0.0)
    expected = pixel - gl_pixel(before, direction)
    np.testing.assert_allclose(streak_at(runner, pixel), expected, rtol=0.03, atol=0.05)
    assert abs(expected.x) > 2.0


def test_a_still_camera_leaves_the_picture_as_it_was_and_draws_no_pass(scene):
    ents = {}
    runner = scene(lambda world: mirror_scene(world, ents), SIZE)
    present = runner.engine.stages["present"]
    present.motion_blur = False
    runner.frame()
    sharp = runner.frame()
    present.motion_blur = True
    for _ in range(2):
        np.testing.assert_array_equal(runner.frame(), sharp)
        assert runner.engine.renderer.present_pass.post_passes == 0
    assert runner.engine.renderer.present_pass.motion_blur.streaks() is None   # (never drawn)
    runner.world.get(ents["camera"], Transform).position += glm.vec3(0.05, 0.0, 0.0)
    runner.frame()
    assert runner.engine.renderer.present_pass.post_passes == 4   # streaks, tiles, neighbours, gather


def test_stepping_through_a_portal_keeps_the_motion(scene):
    """The camera walks through a portal pair (a 90-degree turn between them): on the frame
    it comes out, the picture's streaks are the step's, not the jump from one end to the other."""
    ents = {}
    turn = glm.angleAxis(glm.radians(90), glm.vec3(0, 1, 0))

    def build(world):
        base_scene(world)
        ents["camera"] = look_from(world, (0.0, 1.5, 0.6), (0, 1.5, -5))
        world.add_component(ents["camera"], MotionBlur(shutter=1.0, max_blur=0.25))
        ents["a"], ents["b"] = spawn_portal_pair(world, (0, 1.5, 0), None, (10, 1.5, 0), turn, size=(3.0, 3.0))
        world.spawn(Transform(), MeshRef(plane(60, 60)), Material(texture=checker_texture(256, 32)))

    runner = scene(build, SIZE)
    runner.frame()
    transform = runner.world.get(ents["camera"], Transform)
    longest = []
    for _ in range(5):
        transform.position += glm.vec3(0.0, 0.0, -0.25)
        runner.frame()
        streaks = runner.engine.renderer.present_pass.motion_blur.streaks()
        longest.append(float(np.hypot(streaks[..., 0], streaks[..., 1]).max()))
    assert runner.world.get(ents["camera"], Transform).position.x > 5.0   # it came out of the other end
    assert max(longest) < 0.5 * 0.25 * SIZE[1], longest   # never near the longest streak there is: no jump


@pytest.mark.parametrize(("field", "value"), [("shutter", -0.1), ("shutter", 1.5), ("max_blur", 0.0),
                                              ("max_blur", 0.3), ("shutter", "half")])
def test_motion_blur_values_are_checked(field, value):
    with pytest.raises(ComponentValueError, match=f"MotionBlur.{field}"):
        MotionBlur(**{field: value})


def test_a_level_file_keeps_the_shutter_and_the_images_go_with_the_component(tmp_path, scene):
    again, eye = camera_level_round_trip(tmp_path, "MotionBlur = { shutter = 0.25, max_blur = 0.1 }",
                                         ("shutter = 0.25", "shutter = 2.0"), "shutter")
    blur = again.get(eye, MotionBlur)
    assert (blur.shutter, blur.max_blur) == (0.25, 0.1)
    ents = {}
    runner = scene(lambda world: mirror_scene(world, ents), SIZE)
    runner.frame()
    runner.world.get(ents["camera"], Transform).position += glm.vec3(0.05, 0.0, 0.0)   # (a still camera draws none)
    runner.frame()
    present = runner.engine.renderer.present_pass
    assert present.post_target_count() == 4 and present.post_passes == 4   # (result, streaks, two tile images)
    runner.world.remove_component(ents["camera"], MotionBlur)
    runner.frame()
    assert present.post_target_count() == 0 and present.post_passes == 0


def test_a_streak_at_the_pictures_edge_reads_the_edge_not_the_far_side(scene):
    """The camera turns fast: along the left edge, where the streak runs off the picture, the
    smeared pixels are mixed from what is near that edge (a bright wall's right half never
    bleeds into the left column)."""
    def build(world):
        camera = look_from(world, (0.0, 1.5, 4.0), (0, 1.5, 0))
        world.add_component(camera, MotionBlur(shutter=1.0, max_blur=0.25))
        world.spawn(Transform(position=(0, 1.5, -2)), MeshRef(quad(40, 20)), Material(color=(0.02, 0.02, 0.02)))
        world.spawn(Transform(position=(6.0, 1.5, -1.9)), MeshRef(quad(8, 20)), Material(color=(1.0, 1.0, 1.0)),
                    Emissive(3.0))   # bright, filling the right edge only
        ents["camera"] = camera

    from components import Emissive
    ents = {}
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    transform = runner.world.get(ents["camera"], Transform)
    transform.rotation = glm.angleAxis(glm.radians(-3.0), glm.vec3(0, 1, 0)) * transform.rotation
    rgb = runner.frame().astype(float)
    streaks = runner.engine.renderer.present_pass.motion_blur.streaks()
    assert np.abs(streaks[:, :3, 0]).max() > 5.0          # (a long streak at the left edge)
    assert rgb[:, :3].mean() < 40.0, rgb[:, :3].mean()    # dark: the bright right edge stays on its side
    assert rgb[:, -3:].mean() > 150.0


PORTAL_BOX = ((13.1, 1.1, 0.0), (13.9, 1.9, 0.8))   # beyond the look-out portal b, seen only through a


def portal_scene(world, ents, scale=1.0):
    """The camera before portal a (z = 0, facing +z); its partner b 10 m to the side, turned
    90 degrees (and ``scale`` times a's size); a green box before b, the sky all round."""
    from components import DirectionalLight, Emissive, Skybox

    world.spawn(Skybox())
    world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))
    ents["camera"] = look_from(world, (0.5, 1.6, 6.0), (0, 1.5, 0))
    world.add_component(ents["camera"], MotionBlur(shutter=1.0, max_blur=0.2))
    ents["a"], ents["b"] = spawn_portal_pair(world, (0, 1.5, 0), None, (10, 1.5, 0),
                                             glm.angleAxis(glm.radians(90), glm.vec3(0, 1, 0)))
    world.get(ents["b"], Transform).scale = glm.vec3(scale)
    lo, hi = np.array(PORTAL_BOX)
    ents["box"] = world.spawn(Transform(position=tuple((lo + hi) / 2), scale=tuple(hi - lo)), MeshRef(box()),
                              Material(color=(0.1, 0.9, 0.1)), Emissive(1.0))


def through_portal(runner, ents, lo, hi):
    """Each pixel's point on the box lo..hi beyond the pair, cast in float64 from this frame's
    main view: the ray to a's plane (z = 0), carried through the pair (``pair_transform``),
    on to the box.  The box's pixels (ids and cast agreeing) and their points, carried back:
    in b's world and as the eye sees them in a's (the image: where the picture puts it), and
    the carry back (b's world to a's)."""
    from engine.core.portal_math import pair_transform
    from tests.support import pixel_rays
    from tests.test_depth_of_field import slab

    eye, d = pixel_rays(runner.engine.main_view, SIZE)
    t1 = -eye[2] / d[..., 2]
    hit = eye + d * t1[..., None]
    carry = np.array(pair_transform(runner.world.get(ents["a"], Transform).world,
                                    runner.world.get(ents["b"], Transform).world), np.float64)
    carried = hit @ carry[:3, :3].T + carry[:3, 3]
    direction = d @ carry[:3, :3].T
    direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
    t2 = slab(carried, direction, lo, hi)
    shown = (runner.ids() == ents["box"]) & np.isfinite(t2) & (t1 > 0)
    beyond = carried[shown] + direction[shown] * t2[shown][:, None]
    back = np.linalg.inv(carry)
    return shown, beyond, beyond @ back[:3, :3].T + back[:3, 3], back


def gl_pixels(view_proj: glm.mat4, points: np.ndarray) -> np.ndarray:
    """``gl_pixel`` of rows of points (w 1), in float64."""
    matrix = np.array(glm.dmat4(view_proj).to_list(), np.float64).T
    clip = np.c_[points, np.ones(len(points))] @ matrix.T
    return (clip[:, :2] / clip[:, 3:] * 0.5 + 0.5) * np.array(SIZE)


@pytest.mark.parametrize("scale", [1.0, 2.0])
def test_a_box_seen_through_a_portal_streaks_as_its_image_beyond_moves(scene, scale):
    """The camera steps sideways before a portal: each pixel of the box beyond it streaks by
    the motion of the box's image as the pair shows it (the box's point carried back through
    the pair, cast per pixel in float64, projected last frame and this one), not as the
    portal's glass moves, nor as the box would at its distance in b's world; a pair of two
    sizes (b twice a's) shows the box half as far beyond a, and streaks it so (its way is the
    image's, eye to a plus b to the box over 2: the carried eye's distance, 2 x eye to a plus b
    to the box, streaked it half as far)."""
    ents = {}
    runner = scene(lambda world: portal_scene(world, ents, scale), SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    before = glm.mat4(runner.engine.main_view.view_proj)
    runner.world.get(ents["camera"], Transform).position += glm.vec3(0.3, 0.0, 0.0)
    runner.frame()
    now = glm.mat4(runner.engine.main_view.view_proj)
    shown, _, image, _ = through_portal(runner, ents, *PORTAL_BOX)
    assert shown.sum() > 20
    rows, columns = np.nonzero(shown)   # (the image is where the picture shows the box: each its pixel's centre)
    np.testing.assert_allclose(gl_pixels(now, image), np.c_[columns + 0.5, SIZE[1] - 0.5 - rows], atol=1e-3)
    expected = gl_pixels(now, image) - gl_pixels(before, image)
    streaks = runner.engine.renderer.present_pass.motion_blur.streaks()[shown][:, :2]
    np.testing.assert_allclose(streaks, expected, rtol=0.03, atol=0.03)
    assert np.abs(expected[:, 0]).min() > 1.5


def test_a_box_moving_beyond_a_portal_streaks_as_its_image_through_it_moves(scene):
    """A still camera; the box beyond the pair steps (along b's facing and sideways): where
    portal a shows it, its streak is the motion of its image through the pair (its point now
    and that point less the step, carried back through the pair and projected), not its step
    as a direct view would see it; the portal's pixels round it have no streak."""
    ents = {}
    runner = scene(lambda world: portal_scene(world, ents), SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    runner.frame()
    step = np.array([0.25, 0.05, -0.3])
    runner.world.get(ents["box"], Transform).position += glm.vec3(*step)
    runner.frame()
    assert runner.world.get(ents["camera"], Transform).position == glm.vec3(0.5, 1.6, 6.0)
    lo, hi = np.array(PORTAL_BOX) + step
    shown, beyond, _, back = through_portal(runner, ents, lo, hi)
    assert shown.sum() > 40
    view_proj = glm.mat4(runner.engine.main_view.view_proj)
    now_px = gl_pixels(view_proj, beyond @ back[:3, :3].T + back[:3, 3])
    then_px = gl_pixels(view_proj, (beyond - step) @ back[:3, :3].T + back[:3, 3])
    streaks = runner.engine.renderer.present_pass.motion_blur.streaks()
    np.testing.assert_allclose(streaks[shown][:, :2], now_px - then_px, rtol=0.03, atol=0.05)
    assert np.hypot(*(now_px - then_px).T).min() > 2.0
    portal = runner.engine.renderer.targets.read_surface_ids() == ents["a"]
    still = portal & (runner.ids() != ents["box"])
    assert still.sum() > 200 and np.abs(streaks[still][:, :2]).max() < 1e-3
