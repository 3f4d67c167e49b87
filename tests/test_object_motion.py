"""Per-object motion blur (``MotionBlur.objects``; ``engine/render/object_motion.py``, the
scene pass's ``OBJECT_MOTION`` builds, ``shaders/motion_*.frag``): a moving thing's streak
against the screen motion of its point worked out from the geometry (directly, turning, in a
mirror by either reflection path), the smear out over the background round it, nothing left
once it stops (a kept reflection level included), the motion table's matrices and limits,
and the component's switch."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import Material, MeshRef, Mirror, MotionBlur, Transform
from engine.assets.mesh import box, plane, quad
from engine.assets.texture_data import checker_texture
from engine.core.errors import GLLimitError
from engine.core.reflection_math import plane_from_point_normal, reflection_matrix
from engine.render.object_motion import ObjectMotion
from engine.render.pose_rows import PoseRows
from engine.resources import PortalCrossing
from tests.support import look_from, still_motion
from tests.test_mirrors import base_scene

SIZE = (200, 150)
EYE = glm.vec3(0.0, 1.5, 6.0)


def gl_pixel(view_proj: glm.mat4, point: glm.vec3) -> glm.vec2:
    """Where a point lands, in pixels, y up (GL's)."""
    clip = view_proj * glm.vec4(point, 1.0)
    return (glm.vec2(clip) / clip.w * 0.5 + 0.5) * glm.vec2(*SIZE)


def at(image: np.ndarray, pixel: glm.vec2):
    """``image`` (row 0 at the top) at a GL pixel."""
    return image[SIZE[1] - 1 - int(pixel.y), int(pixel.x)]


def streaks(runner) -> np.ndarray:
    return runner.engine.renderer.present_pass.motion_blur.streaks()


def streaking_camera(world, eye, target, shutter: float = 1.0, objects: bool = True) -> int:
    """A lit sky and a camera at ``eye`` looking at ``target`` with a MotionBlur (streaks up
    to a fifth of the height)."""
    base_scene(world)
    camera = look_from(world, tuple(eye), tuple(target))
    world.add_component(camera, MotionBlur(shutter=shutter, max_blur=0.2, objects=objects))
    return camera


def wall_scene(world, ents, shutter=1.0, objects=True):
    """A still camera before a checkered wall, a red box in front of it."""
    ents["camera"] = streaking_camera(world, EYE, (0, 1.5, 0), shutter, objects)
    world.spawn(Transform(position=(0, 1.5, -3)), MeshRef(quad(30, 12)),
                Material(color=(0.8, 0.8, 0.8), texture=checker_texture(256, 32)))
    world.spawn(Transform(), MeshRef(plane(40, 40)), Material(color=(0.5, 0.5, 0.5)))
    ents["box"] = world.spawn(Transform(position=(-1.0, 1.5, 0.0), scale=(0.8, 0.8, 0.8)), MeshRef(box()),
                              Material(color=(0.9, 0.1, 0.1)))


def started(build):
    """A runner two frames in: the first draws the motion blur, which turns the per-object
    motion on for the next (the first frame of a motion blur has no last frame to streak from)."""
    def make(scene):
        runner = scene(build, SIZE)
        runner.engine.renderer.antialias = "off"
        runner.frame()
        runner.frame()
        return runner
    return make


@pytest.mark.parametrize("shutter", [1.0, 0.5])
def test_a_moving_box_streaks_by_its_own_motion(scene, shutter):
    """The camera stands still; the box steps 0.3 m right.  At the middle of its front face the
    streak is that point's motion on screen (from where it was to where it is) times the
    shutter; the wall's pixels have none."""
    ents = {}
    runner = started(lambda world: wall_scene(world, ents, shutter))(scene)
    assert runner.engine.renderer.object_motion.on
    assert runner.engine.renderer.targets.seen.components == 4
    transform = runner.world.get(ents["box"], Transform)
    step = glm.vec3(0.3, 0.0, 0.0)
    transform.position += step
    runner.frame()
    view_proj = glm.mat4(runner.engine.main_view.view_proj)
    face = transform.position + glm.vec3(0.0, 0.0, 0.4)   # the front face's middle, now
    pixel = gl_pixel(view_proj, face)
    assert at(runner.ids(), pixel) == ents["box"]
    expected = (pixel - gl_pixel(view_proj, face - step)) * shutter
    np.testing.assert_allclose(at(streaks(runner), pixel), expected, rtol=0.03, atol=0.05)
    wall = gl_pixel(view_proj, glm.vec3(3.0, 2.5, -3.0))
    assert np.abs(at(streaks(runner), wall)).max() < 1e-3
    assert runner.engine.renderer.object_motion.count == 1


def test_a_turning_box_streaks_as_its_matrix_turned(scene):
    """The box turns 12 degrees about its vertical: a point on its face off the axis moves on
    screen as the turn carries it back (last frame's matrix times the inverse of this one)."""
    ents = {}
    runner = started(lambda world: wall_scene(world, ents))(scene)
    transform = runner.world.get(ents["box"], Transform)
    before = glm.mat4(transform.world)
    transform.rotation = glm.angleAxis(glm.radians(12.0), glm.vec3(0, 1, 0))
    runner.frame()
    now = glm.mat4(runner.world.get(ents["box"], Transform).world)
    view_proj = glm.mat4(runner.engine.main_view.view_proj)
    point = glm.vec3(now * glm.vec4(0.25, 0.1, 0.5, 1.0))   # on the front face (a unit box's z 0.5), right of the axis
    pixel = gl_pixel(view_proj, point)
    assert at(runner.ids(), pixel) == ents["box"]
    was = glm.vec3(before * glm.inverse(now) * glm.vec4(point, 1.0))
    expected = pixel - gl_pixel(view_proj, was)
    assert abs(expected.y) < 0.5 < abs(expected.x)
    np.testing.assert_allclose(at(streaks(runner), pixel), expected, rtol=0.05, atol=0.1)


def test_a_moving_box_smears_out_over_the_still_wall_round_it(scene):
    """The box's streak reaches past its edges: the wall's pixels within half a streak ahead of
    its leading edge turn red (what moves in front covers them part of the shutter's time),
    the wall's pixels beyond the streak's reach are as the still picture has them."""
    ents = {}
    runner = started(lambda world: wall_scene(world, ents))(scene)
    transform = runner.world.get(ents["box"], Transform)
    transform.position += glm.vec3(0.8, 0.0, 0.0)
    blurred = runner.frame().astype(float)
    length = float(np.hypot(*at(streaks(runner), gl_pixel(runner.engine.main_view.view_proj,
                                                            transform.position + glm.vec3(0, 0, 0.4)))))
    still = runner.frame().astype(float)   # the next frame: nothing moved, nothing smeared
    assert runner.engine.renderer.present_pass.post_passes == 0
    ids = runner.ids()
    row = SIZE[1] // 2 + 2
    box_columns = np.flatnonzero(ids[row] == ents["box"])
    right_edge = int(box_columns.max())
    assert length > 16.0
    near = np.arange(right_edge + 1, right_edge + int(0.35 * length))
    redder = (blurred[row, near, 0] - blurred[row, near, 1]) - (still[row, near, 0] - still[row, near, 1])
    assert (redder > 8.0).all(), redder
    far = np.arange(right_edge + int(0.5 * length) + 3, SIZE[0])
    assert np.abs(blurred[row, far] - still[row, far]).max() <= 2.0
    left = np.arange(0, int(box_columns.min()) - int(0.5 * length) - 3)
    assert np.abs(blurred[row, left] - still[row, left]).max() <= 2.0


def mirror_scene(world, ents):
    """A mirror ahead of a still camera; a box behind the camera, seen only in the mirror."""
    ents["camera"] = streaking_camera(world, (0.0, 1.5, 2.0), (0, 1.5, 0))
    ents["mirror"] = world.spawn(Transform(position=(0, 1.5, 0)), MeshRef(quad(2.6, 1.8)),
                                 Material(color=(0.1, 0.1, 0.1)), Mirror())
    world.spawn(Transform(), MeshRef(plane(40, 40)), Material(color=(0.8, 0.8, 0.8), texture=checker_texture(256, 32)))
    ents["box"] = world.spawn(Transform(position=(0.2, 1.5, 8.0), scale=(0.6, 0.6, 0.6)), MeshRef(box()),
                              Material(color=(0.9, 0.1, 0.1), texture=checker_texture(64, 4)))


MIRROR = reflection_matrix(plane_from_point_normal((0, 1.5, 0), (0, 0, 1)))


@pytest.mark.parametrize("path", ["per_mirror", "batched"])
def test_a_box_moving_in_a_mirror_streaks_as_its_reflection_moves(scene, path):
    """The box (behind the camera) steps sideways and towards the glass: where the mirror shows
    it, the streak is its reflection's motion on screen (the view that drew it projects it),
    by either reflection path."""
    ents = {}

    def build(world):
        mirror_scene(world, ents)

    runner = scene(build, SIZE)
    runner.engine.reflection_system.path = path
    runner.engine.renderer.antialias = "off"
    runner.frame()
    runner.frame()
    transform = runner.world.get(ents["box"], Transform)
    step = glm.vec3(-0.25, 0.05, -0.3)
    transform.position += step
    runner.frame()
    assert runner.stats.reflection_path == path
    view_proj = glm.mat4(runner.engine.main_view.view_proj)
    face = transform.position - glm.vec3(0.0, 0.0, 0.3)   # the face towards the mirror
    image = glm.vec3(MIRROR * glm.vec4(face, 1.0))
    image_before = glm.vec3(MIRROR * glm.vec4(face - step, 1.0))
    pixel = gl_pixel(view_proj, image)
    assert at(runner.ids(), pixel) == ents["box"]
    assert at(runner.engine.renderer.targets.read_surface_ids(), pixel) == ents["mirror"]
    expected = pixel - gl_pixel(view_proj, image_before)
    np.testing.assert_allclose(at(streaks(runner), pixel), expected, rtol=0.03, atol=0.05)


def test_nothing_streaks_once_it_stops_a_kept_reflection_level_included(scene):
    """The frame after the box in the mirror stops: no motion is left in the seen image (the
    reflection level drawn with the last motion is not kept), no pass is drawn, and the
    picture is the one a runner that never moved it draws."""
    ents = {}
    runner = scene(lambda world: mirror_scene(world, ents), SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    runner.frame()
    runner.world.get(ents["box"], Transform).position += glm.vec3(-0.3, 0.0, 0.0)
    runner.frame()
    motion = runner.engine.renderer.targets.read_motion()
    assert np.abs(motion).max() > 1e-3    # (moving: the mirror's pixels carry it up)
    stopped = runner.frame()
    assert still_motion(runner.engine.renderer.targets.read_motion())
    assert runner.engine.renderer.present_pass.post_passes == 0
    other = {}

    def moved(world):
        mirror_scene(world, other)
        world.get(other["box"], Transform).position += glm.vec3(-0.3, 0.0, 0.0)

    fresh = scene(moved, SIZE)
    fresh.engine.renderer.antialias = "off"
    fresh.frame()
    np.testing.assert_array_equal(stopped, fresh.frame())


def test_objects_off_keeps_two_channels_and_streaks_the_camera_only(scene):
    """``objects=False``: the seen images keep two channels, no OBJECT_MOTION builds, the
    moving box has no streak of its own; switched on, the next frames have it.  The overlay's
    screen line says which."""
    from shell.overlay_text import post_lines

    ents = {}
    runner = started(lambda world: wall_scene(world, ents, objects=False))(scene)
    renderer = runner.engine.renderer
    assert not renderer.object_motion.on and renderer.targets.seen.components == 2
    assert post_lines(runner.engine)[1].endswith("; motion blur 1, camera only")
    assert renderer.targets.read_motion() is None
    transform = runner.world.get(ents["box"], Transform)
    transform.position += glm.vec3(0.3, 0.0, 0.0)
    runner.frame()
    assert renderer.present_pass.post_passes == 0 and renderer.object_motion.texture is None
    runner.world.get(ents["camera"], MotionBlur).objects = True
    runner.frame()   # (presented with objects: the next frame's scene pass writes them)
    transform.position += glm.vec3(0.3, 0.0, 0.0)
    runner.frame()
    assert renderer.object_motion.on and renderer.targets.seen.components == 4
    assert renderer.present_pass.post_passes == 4
    assert post_lines(runner.engine)[1].endswith("; motion blur 1, 1 moving")
    runner.world.remove_component(ents["camera"], MotionBlur)
    runner.frame()
    runner.frame()
    assert not renderer.object_motion.on and renderer.object_motion.texture is None
    assert renderer.targets.seen.components == 2


def test_a_frame_of_dt_0_keeps_the_last_frames_movers(scene):
    ents = {}
    runner = started(lambda world: wall_scene(world, ents))(scene)
    runner.world.get(ents["box"], Transform).position += glm.vec3(0.3, 0.0, 0.0)
    runner.frame()
    first = streaks(runner).copy()
    runner.frame(dt=0.0)
    assert runner.engine.renderer.object_motion.count == 1
    np.testing.assert_array_equal(streaks(runner), first)


def _columns(matrix: glm.mat4) -> np.ndarray:
    """A glm matrix as an instance row holds it: column-major float32."""
    return np.array(matrix.to_list(), np.float32).reshape(16)


def test_the_records_take_a_point_now_back_to_where_it_was(ctx):
    """Each record's matrix carries a point of the mover's place now to its place last frame;
    a crossing's transform is put before last frame's matrix (it moved across with it); an
    unmoved or singular one leaves no record; they are sorted by entity, any id held exactly."""
    motion = ObjectMotion(ctx, 16384, PoseRows(ctx, 16384))
    carry = glm.translate(glm.vec3(10, 0, 0)) * glm.mat4_cast(glm.angleAxis(glm.radians(90), glm.vec3(0, 1, 0)))
    motion.begin(True, 1 / 60, [PortalCrossing(7, 1, 2, carry)])
    before = [glm.translate(glm.vec3(1, 2, 3)) * glm.mat4_cast(glm.angleAxis(0.3, glm.vec3(1, 0, 0))),
              glm.translate(glm.vec3(0, 0, 1)), glm.mat4(), glm.scale(glm.vec3(2.0))]
    now = [glm.translate(glm.vec3(1.2, 2, 3)) * glm.mat4_cast(glm.angleAxis(0.5, glm.vec3(1, 0, 0))),
           carry * glm.translate(glm.vec3(0, 0, 1.1)), glm.mat4(), glm.scale(glm.vec3(0.0))]
    motion.note([9, 7, 3, 5], np.stack([_columns(m) for m in before]), np.stack([_columns(m) for m in now]))
    entities, back = motion.records()
    assert entities.tolist() == [7, 9]   # 3 did not move; 5 has no inverse (scaled to nothing)
    local = glm.vec4(0.3, -0.2, 0.4, 1.0)
    for entity, matrix in zip(entities.tolist(), back, strict=True):
        i = [9, 7, 3, 5].index(entity)
        was = before[i] * local if entity == 9 else carry * before[i] * local
        np.testing.assert_allclose(matrix @ np.array(now[i] * local), np.array(was), atol=1e-5)
    assert motion.upload() and motion.count == 2
    assert not motion.upload()   # the same records: nothing sent again
    # An id past what one float holds exactly: its high and low bits apart, each exact.
    big = (1 << 30) + 4097
    motion.note([big], _columns(before[0])[None], _columns(now[0])[None])
    assert motion.upload() and motion.count == 3
    texels = np.frombuffer(motion.texture.read(), np.float32).reshape(-1, 4)
    ids = texels[4 + 3: 4 + 4 * 3: 4, 2:4]   # (each record's fourth texel: z high bits, w low 12)
    assert [int(hi) * 4096 + int(lo) for hi, lo in ids] == [7, 9, big]
    motion.release()


def test_more_movers_than_the_texture_holds_are_refused(ctx):
    motion = ObjectMotion(ctx, 1, PoseRows(ctx, 1))   # (a one-row texture: 1,023 records)
    motion.begin(True, 1 / 60)
    count = 1100
    models = np.tile(_columns(glm.mat4()), (count, 1))
    moved = models.copy()
    moved[:, 12] = 1.0   # (a step along x)
    motion.note(list(range(1, count + 1)), models, moved)
    with pytest.raises(GLLimitError, match="1100 moving entities"):
        motion.upload()
    motion.release()


def test_a_box_carried_through_a_portal_streaks_by_its_step_not_across_the_room(scene):
    """A travelling box goes into one portal and comes out of the other, 6 m to the side,
    before a still camera: on every frame, the crossing's included, its streak is about its
    step (its last place carried through the portal with it), never the jump."""
    from components import Traveller
    from engine.assets.portals import spawn_portal_pair

    ents = {}

    def build(world):
        ents["camera"] = streaking_camera(world, (6.0, 1.5, 5.0), (6.0, 1.5, 0.0))
        spawn_portal_pair(world, (0, 1.5, 0), None, (6, 1.5, 0), None, size=(2.0, 2.0))
        world.spawn(Transform(), MeshRef(plane(60, 60)), Material(color=(0.6, 0.6, 0.6)))
        ents["box"] = world.spawn(Transform(position=(0.0, 1.5, 0.8), scale=(0.5, 0.5, 0.5)), MeshRef(box()),
                                  Material(color=(0.9, 0.1, 0.1)), Traveller(velocity=(0.0, 0.0, -3.0)))

    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    longest = []
    for _ in range(30):
        runner.frame()
        box_pixels = runner.ids() == ents["box"]
        if box_pixels.any():
            found = streaks(runner)
            longest.append(float(np.hypot(found[..., 0], found[..., 1])[box_pixels].max()))
    position = runner.world.get(ents["box"], Transform).position
    assert position.x > 5.0, position   # it came out of the other portal
    assert longest and max(longest) < 4.0, longest   # (the jump would streak 30 pixels: max_blur)


def test_alike_motion_is_the_shutters_average_along_the_streak(scene):
    """The camera steps sideways before a flat striped wall: every pixel moves alike, and the
    blurred picture is the still picture averaged along the streak (a box filter, what an open
    shutter integrates), not weighted to the middle."""
    ents = {}

    def build(world):
        ents["camera"] = streaking_camera(world, (0.0, 1.5, 4.0), (0, 1.5, 0))
        world.spawn(Transform(position=(0, 1.5, 0)), MeshRef(quad(40, 20)),
                    Material(color=(0.8, 0.8, 0.8), texture=checker_texture(256, 64)))

    runner = started(build)(scene)
    runner.world.get(ents["camera"], Transform).position += glm.vec3(0.25, 0.0, 0.0)
    blurred = runner.frame().astype(float).mean(axis=-1)
    length = float(np.abs(streaks(runner)[SIZE[1] // 2, SIZE[0] // 2, 0]))
    sharp = runner.frame().astype(float).mean(axis=-1)   # the same pose, nothing moving: no pass
    assert runner.engine.renderer.present_pass.post_passes == 0
    assert 5.0 < length < 12.0
    rows = slice(SIZE[1] // 2 - 10, SIZE[1] // 2 + 10)
    inner = slice(12, SIZE[0] - 12)

    def boxed(span: float) -> np.ndarray:
        """The still picture averaged over ``span`` pixels (its ends by their fractions)."""
        half = 0.5 * span
        reach = int(np.ceil(half))
        offsets = np.arange(-reach, reach + 1)
        weights = np.clip(half + 0.5 - np.abs(offsets), 0.0, 1.0)
        weights /= weights.sum()
        return sum(w * np.roll(sharp[rows], -k, axis=1) for k, w in zip(offsets, weights, strict=True))[:, inner]

    errors = {share: np.abs(blurred[rows, inner] - boxed(share * length)).mean() for share in (0.5, 0.75, 1.0, 1.25)}
    assert min(errors, key=errors.get) == 1.0, errors   # (a filter weighted to the middle fits a shorter box)
    assert np.abs(blurred[rows, inner] - sharp[rows, inner]).mean() > 2.0 * errors[1.0]


@pytest.mark.parametrize("path", ["per_mirror", "batched"])
def test_a_bending_arm_streaks_by_its_pose_seen_directly_and_in_a_mirror(scene, path):
    """A skinned bar standing still bends at its elbow from one frame to the next: a point
    near its tip streaks as the two poses put it on screen (its joints' matrices last frame
    and now, the sum written out here), directly and in a mirror behind it; once it holds its
    pose, nothing is left."""
    from components import Skin
    from tests.test_skinning import RED, elbow_matrix, skinned_bar

    ents = {}

    def build(world):
        ents["camera"] = streaking_camera(world, (0.0, 1.2, 5.0), (0, 1.2, 0))
        world.spawn(Transform(position=(0, 1.2, -2.5)), MeshRef(quad(6.0, 3.0)), Material(color=(0.1, 0.1, 0.1)),
                    Mirror())
        ents["arm"] = world.spawn(Transform(position=(-0.8, 0.0, 0.0)), MeshRef(skinned_bar()), Material(color=RED),
                                  Skin(np.stack([np.eye(4), elbow_matrix(0.2)])))

    runner = scene(build, SIZE)
    runner.engine.reflection_system.path = path
    runner.engine.renderer.antialias = "off"
    runner.frame()
    runner.frame()
    runner.world.get(ents["arm"], Skin).joint_matrices = np.stack([np.eye(4), elbow_matrix(0.35)])
    runner.frame()
    view_proj = glm.mat4(runner.engine.main_view.view_proj)
    local = np.array([0.0, 1.85, 0.15, 1.0])   # on the front face near its tip (the elbow's alone)
    place = glm.translate(glm.vec3(-0.8, 0.0, 0.0))
    now = place * glm.vec4(*(elbow_matrix(0.35) @ local))
    was = place * glm.vec4(*(elbow_matrix(0.2) @ local))
    pixel = gl_pixel(view_proj, glm.vec3(now))
    assert at(runner.ids(), pixel) == ents["arm"]
    expected = pixel - gl_pixel(view_proj, glm.vec3(was))
    assert glm.length(expected) > 2.0
    np.testing.assert_allclose(at(streaks(runner), pixel), expected, rtol=0.05, atol=0.1)
    mirror = reflection_matrix(plane_from_point_normal((0, 1.2, -2.5), (0, 0, 1)))
    back = local * np.array([1.0, 1.0, -1.0, 1.0])   # (the back face, towards the mirror)
    image_now = glm.vec3(mirror * place * glm.vec4(*(elbow_matrix(0.35) @ back)))
    image_was = glm.vec3(mirror * place * glm.vec4(*(elbow_matrix(0.2) @ back)))
    reflected = gl_pixel(view_proj, image_now)
    assert at(runner.ids(), reflected) == ents["arm"]
    np.testing.assert_allclose(at(streaks(runner), reflected), reflected - gl_pixel(view_proj, image_was),
                               rtol=0.05, atol=0.1)
    runner.frame()   # (held: the pose as last frame)
    assert still_motion(runner.engine.renderer.targets.read_motion())
    assert runner.engine.renderer.present_pass.post_passes == 0


def test_a_morph_changing_its_weights_streaks_by_them(scene):
    """A standing sheet's right half lifted by its morph target from one frame to the next: a
    point on it streaks as the two weights put it on screen; the left half, which no target
    moves, has no streak."""
    from components import Morph
    from tests.test_morph_targets import morphed_sheet
    from tests.test_skinning import RED

    ents = {}

    def build(world):
        ents["camera"] = streaking_camera(world, (0.0, 1.5, 4.0), (0, 1.5, 0))
        ents["sheet"] = world.spawn(Transform(), MeshRef(morphed_sheet()), Material(color=RED), Morph((0.0, 0.0)))

    runner = started(build)(scene)
    runner.world.get(ents["sheet"], Morph).weights = (0.0, 0.4)
    runner.frame()
    view_proj = glm.mat4(runner.engine.main_view.view_proj)
    now, was = glm.vec3(0.5, 1.2, 0.0), glm.vec3(0.5, 1.0, 0.0)   # (the lift: 0.5 x 0.4)
    pixel = gl_pixel(view_proj, now)
    assert at(runner.ids(), pixel) == ents["sheet"]
    np.testing.assert_allclose(at(streaks(runner), pixel), pixel - gl_pixel(view_proj, was), rtol=0.05, atol=0.1)
    still = gl_pixel(view_proj, glm.vec3(-0.5, 1.2, 0.0))
    assert at(runner.ids(), still) == ents["sheet"] and np.abs(at(streaks(runner), still)).max() < 1e-3


def test_a_skinned_thing_spawned_while_streaking_does_not_streak_from_nowhere(scene):
    """The first posed entity comes while motion blur streaks moving things: last frame's pose
    texture is made for it in the same frame, its pose as it is (no streak at all)."""
    from components import Skin
    from tests.test_skinning import RED, elbow_matrix, skinned_bar

    ents = {}
    runner = started(lambda world: wall_scene(world, ents))(scene)
    renderer = runner.engine.renderer
    assert renderer.pose_rows.texture is None and renderer.object_motion.on
    arm = runner.world.spawn(Transform(position=(1.0, 0.5, 0.5)), MeshRef(skinned_bar()), Material(color=RED),
                             Skin(np.stack([np.eye(4), elbow_matrix(0.6)])))
    runner.frame()
    assert renderer.pose_rows.before is not None
    view_proj = glm.mat4(runner.engine.main_view.view_proj)
    pixel = gl_pixel(view_proj, glm.vec3(1.0, 0.5 + 0.4, 0.5 + 0.15))   # (low on its front: the elbow's below)
    assert at(runner.ids(), pixel) == arm
    assert still_motion(runner.engine.renderer.targets.read_motion())
