"""Screen-space reflections in mirror and portal views (``ScreenReflections.reflection_depth``;
``ScreenReflectionPass.begin_level`` and ``composite_level``): a polished floor seen through a
portal reflects what stands on it as it does seen directly.

The second path is the camera itself: the portal pair is placed so that looking into A shows
what a camera at ``tests/test_screen_reflections.py``'s eye sees (B stands in front of that
eye, facing the boxes; "looking into either shows the other's front side" carries A's
local (x, y, z) to B's (-x, y, -z), and B is turned half round, so a camera 1.5 m before A
is carried to that eye, turned the same way).  The frame through the portal must match the
frame of that camera in the portal's pixels whose rays meet the world past B's plane (the
floor between the eye and B is behind the portal's view)."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, MeshRef, Mirror, Reflective, ScreenReflections, Transform, look_rotation
from engine.assets.portals import spawn_portal_pair
from shell.overlay_text import post_lines
from tests.support import pixel_rays
from tests.test_screen_reflections import EYE, SIZE, TARGET, _eroded, _scene

PORTAL_A = (20.0, 1.2, 20.0)   # alone, facing +z
PORTAL_B = (0.0, 1.2, 3.0)     # before the eye, facing the boxes (-z)
B_PLANE_Z = 3.0
THROUGH_A = (20.0, EYE[1], 20.0 + (EYE[2] - B_PLANE_Z))   # the camera before A that is carried to EYE


def _frame(scene, reflections: ScreenReflections | None, portal: bool, eye=EYE,
           extra=None, way=None) -> tuple[np.ndarray, object, dict]:
    """The second frame of the scene (``reflections`` on its camera, the portal pair where
    ``portal``) from ``eye`` looking along ``way`` (EYE's towards TARGET by default), its
    runner and names; ``extra(world, names)`` adds to it."""
    names: dict = {}

    def build(world):
        names.update(_scene(world, reflections=reflections))
        if portal:
            names["a"], names["b"] = spawn_portal_pair(
                world, PORTAL_A, None, PORTAL_B, glm.angleAxis(glm.radians(180.0), glm.vec3(0, 1, 0)),
                size=(3.0, 3.0))
        if extra is not None:
            extra(world, names)

    runner = scene(build, SIZE)
    transform = runner.world.get(names["camera"], Transform)
    transform.position = glm.vec3(eye)
    transform.rotation = look_rotation(glm.vec3(way) if way is not None else glm.vec3(TARGET) - glm.vec3(EYE))
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return runner.frame().astype(np.int32), runner, names


def _judged(runner, direct_runner, names) -> np.ndarray:
    """The portal's pixels (away from its outline) whose ray, cast from the eye, meets the
    world past B's plane: the floor before it (nearer than z = 3) is not in the portal's view."""
    through = runner.engine.renderer.targets.read_surface_ids() == names["a"]
    eye, rays = pixel_rays(direct_runner.engine.main_view, SIZE)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_plane = (B_PLANE_Z - eye[2]) / rays[..., 2]
        t_floor = -eye[1] / rays[..., 1]
    past = (t_plane > 0) & ((t_floor <= 0) | (t_floor > t_plane + 0.05))
    return _eroded(through, 3) & past


def test_through_a_portal_the_polished_floor_reflects_as_seen_directly(scene):
    image, runner, names = _frame(scene, ScreenReflections(), portal=True, eye=THROUGH_A)
    direct, direct_runner, direct_names = _frame(scene, ScreenReflections(), portal=False)
    plain, _, _ = _frame(scene, ScreenReflections(reflection_depth=0), portal=True, eye=THROUGH_A)
    assert runner.stats.reflection_views >= 1
    _assert_reflects_as_seen_directly(image, plain, runner, names, direct, direct_runner, direct_names)


def _assert_reflects_as_seen_directly(image, plain, runner, names, direct, direct_runner, direct_names) -> np.ndarray:
    """``image`` through the portal (drawn by ``runner``'s active camera's pose) matches the
    ``direct`` frame in the judged pixels (``_judged``), and where the direct view's floor
    reflects a box, where the portal's view without the level's reflections (``plain``) shows
    the sky's reflection, far from it (what the test stands on).  Returns the judged pixels."""
    judged = _judged(runner, direct_runner, names)
    assert judged.sum() > 8000
    difference = np.abs(image[judged] - direct[judged]).max(axis=-1)
    assert np.mean(difference <= 3) > 0.97, np.percentile(difference, [50, 90, 99])
    floor = direct_runner.ids() == direct_names["floor"]
    reflecting = judged & floor & (np.abs(direct - plain).max(axis=-1) > 40)
    assert reflecting.sum() > 300, reflecting.sum()
    difference = np.abs(image[reflecting] - direct[reflecting]).max(axis=-1)
    assert np.mean(difference <= 3) > 0.97, np.percentile(difference, [50, 90, 99])
    return judged


def test_a_mirror_level_reflects_and_its_images_go_with_the_depth(scene):
    """A mirror beside the floor: its level's images are made (the three, the colour copy and
    the node image's stand-in), its composite drawn once a frame with the camera's, and both
    let go when the depth no longer reaches it; the overlay says how deep they go."""
    reflections = ScreenReflections()

    def extra(world):
        from components import Material, MeshRef
        from engine.assets.mesh import quad
        return {"mirror": world.spawn(Transform(position=(2.5, 1.0, -1.0), rotation=glm.angleAxis(
            glm.radians(-60.0), glm.vec3(0, 1, 0))), MeshRef(quad(2.0, 2.0)), Material(), Mirror())}

    names: dict = {}
    runner = scene(lambda world: names.update(_scene(world, reflections=reflections, extra=extra)), SIZE)
    runner.engine.reflection_system.keep_still_views = False  # (a still frame keeps its levels: no composite)
    runner.frame()
    passes = runner.engine.renderer.screen_reflections
    assert runner.stats.reflection_views == 1
    assert passes.target_count() == 4 + 5 and sorted(passes._levels) == [1]
    composites = passes.composites
    runner.frame()
    assert passes.composites == composites + 2
    assert any("SSR 30 m medium, 1 mirror level" in line for line in post_lines(runner.engine))
    reflections.reflection_depth = 0
    runner.frame()
    assert passes.target_count() == 4 and not passes._levels
    assert passes.composites == composites + 3
    reflections.reflection_depth = 1
    runner.frame()
    assert passes.target_count() == 9
    runner.world.delete_entity(names["mirror"])   # the mirror goes: its level's images with it
    runner.frame()
    assert passes.target_count() == 4


@pytest.mark.parametrize("value", [-1, 17, 0.5, False])
def test_a_bad_depth_is_refused_naming_the_field(value):
    with pytest.raises(ComponentValueError, match="reflection_depth"):
        ScreenReflections(reflection_depth=value)


def _two_mirrors(right_reflects: bool):
    """Two mirrors side by side over the boxes, tipped to look down and turned apart, each
    showing the polished floor and the boxes from its side; the right one a mirror or a
    plain quad."""
    def extra(world):
        from components import Material, MeshRef
        from engine.assets.mesh import quad
        names = {}
        for name, x, turn in (("left", -1.05, 12.0), ("right", 1.05, -12.0)):
            parts = (Mirror(),) if name == "left" or right_reflects else ()
            tilt = glm.angleAxis(glm.radians(turn), glm.vec3(0, 1, 0)) * glm.angleAxis(glm.radians(30.0),
                                                                                      glm.vec3(1, 0, 0))
            names[name] = world.spawn(Transform(position=(x, 2.6, -2.0), rotation=tilt), MeshRef(quad(2.1, 2.0)),
                                      Material(), *parts)
        return names
    return extra


def test_two_mirrors_side_by_side_each_reflect_their_own_world(scene):
    """Two views of one level, edge to edge on the screen: the left mirror's pixels are the
    same whether the right one's view shares its level (a mirror) or not (a plain quad), so
    a ray marched in one view ends at the other's pixels; and its floor does reflect the
    boxes (its pixels differ from depth 0's)."""
    frames = {}
    for case, reflects, depth in (("both", True, 1), ("alone", False, 1), ("none", True, 0)):
        names: dict = {}
        runner = scene(lambda world, names=names, reflects=reflects, depth=depth: names.update(_scene(
            world, reflections=ScreenReflections(reflection_depth=depth), extra=_two_mirrors(reflects))), SIZE)
        runner.engine.renderer.antialias = "off"
        runner.frame()
        frames[case] = (runner.frame().astype(np.int32), runner, names)
    image, runner, names = frames["both"]
    assert runner.stats.reflection_views == 2 and frames["alone"][1].stats.reflection_views == 1
    left = runner.engine.renderer.targets.read_surface_ids() == names["left"]
    assert left.sum() > 1500
    np.testing.assert_array_equal(image[left], frames["alone"][0][left])
    # Its floor reflects the boxes where its view shows them over it, and keeps the sky's
    # reflection elsewhere (most of it: as drawn at depth 0).
    change = np.abs(image - frames["none"][0]).max(axis=-1)[left]
    assert (change > 20).sum() > 100 and np.mean(change <= 1) > 0.5, (np.sum(change > 20), np.mean(change <= 1))


# A mirror standing where B stands (z = 3, facing the boxes), and the camera before it whose
# image in it is the eye: the mirror's view is the eye's view turned left for right.
MIRROR_Z = 3.0
BEFORE_MIRROR = (EYE[0], EYE[1], 2.0 * MIRROR_Z - EYE[2])
INTO_MIRROR = tuple(np.subtract(TARGET, EYE) * np.array([1.0, 1.0, -1.0]))


@pytest.mark.parametrize("who", ["camera", "picture"])
def test_a_mirror_level_reflects_the_polished_floor_as_the_eye_sees_it_turned(scene, who):
    """The camera (``who`` "picture": a monitor's camera posed the same, the active one bare)
    before a mirror standing where the eye's image puts it, with ``ScreenReflections`` of
    ``reflection_depth`` 1: the mirror's view shows the polished floor reflecting the boxes as
    the camera at the eye sees it directly, left for right (its pixels whose ray meets the
    world past the mirror's plane, within 3 levels for 97%), where at ``reflection_depth`` 0
    it shows the sky's reflection there."""
    from components import Camera, Material, Monitor
    from engine.assets.mesh import quad
    from tests.support import linear_to_srgb8

    def mirrored(reflections: ScreenReflections):
        def extra(world, names):
            names["mirror"] = world.spawn(
                Transform(position=(0.0, 1.2, MIRROR_Z), rotation=glm.angleAxis(glm.radians(180.0), glm.vec3(0, 1, 0))),
                MeshRef(quad(4.0, 3.0), casts_shadows=False), Material(), Mirror())
            if who == "picture":
                pose = dict(position=glm.vec3(BEFORE_MIRROR), rotation=look_rotation(glm.vec3(INTO_MIRROR)))
                names["lens"] = world.spawn(Transform(**pose), Camera(active=False), reflections)
                names["screen"] = world.spawn(Transform(position=(0.0, 1.0, 9.0)), MeshRef(quad(1.6, 0.9)),
                                              Material(color=(0.0, 0.0, 0.0, 1.0), roughness=1.0,
                                                       environment_reflection=0.0),
                                              Monitor(camera=names["lens"], size=SIZE, depth=1))

        frame, runner, names = _frame(scene, reflections if who == "camera" else None, portal=False,
                                      eye=BEFORE_MIRROR, extra=extra, way=INTO_MIRROR)
        if who == "picture":
            shown = runner.engine.renderer.monitors.read(names["screen"])[..., :3]
            frame = linear_to_srgb8(np.clip(shown, 0.0, 1.0)).astype(np.int32)
        return frame, runner, names

    image, runner, names = mirrored(ScreenReflections())
    plain, _, _ = mirrored(ScreenReflections(reflection_depth=0))
    direct, direct_runner, direct_names = _frame(scene, ScreenReflections(), portal=False)
    assert runner.stats.reflection_views >= 1
    direct = direct[:, ::-1]   # (the eye's view turned left for right: the mirror's)
    through = runner.engine.renderer.targets.read_surface_ids() == names["mirror"]
    eye, rays = pixel_rays(direct_runner.engine.main_view, SIZE)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_plane = (MIRROR_Z - eye[2]) / rays[..., 2]
        t_floor = -eye[1] / rays[..., 1]
    past = ((t_plane > 0) & ((t_floor <= 0) | (t_floor > t_plane + 0.05)))[:, ::-1]
    judged = _eroded(through, 3) & past
    assert judged.sum() > 8000, judged.sum()
    difference = np.abs(image[judged] - direct[judged]).max(axis=-1)
    assert np.mean(difference <= 3) > 0.97, np.percentile(difference, [50, 90, 99])
    floor = (direct_runner.ids() == direct_names["floor"])[:, ::-1]
    reflecting = judged & floor & (np.abs(direct - plain).max(axis=-1) > 40)
    assert reflecting.sum() > 300, reflecting.sum()
    difference = np.abs(image[reflecting] - direct[reflecting]).max(axis=-1)
    assert np.mean(difference <= 3) > 0.97, np.percentile(difference, [50, 90, 99])


def test_a_still_tree_with_end_images_keeps_its_levels_reflections_and_occlusion(scene):
    """``tests/test_kept_views.py``'s hall (a mirror with end images, facing portals), its floor
    polished, the camera with ambient occlusion and screen reflections reaching two levels: a
    still tree is kept (and refilled while its end images settle) with every frame's pixels
    those of a tree drawn whole each frame (the refill composites a level's reflections again,
    ``ScenePass.finish_level``)."""
    from components import AmbientOcclusion
    from tests.support import kept_frames_equal_drawn
    from tests.test_kept_views import _hall

    def build(world):
        _hall(world, end_image=True)
        camera = world.resources["camera"]
        world.add_component(camera, AmbientOcclusion(radius=0.5, reflection_depth=2))
        world.add_component(camera, ScreenReflections(reflection_depth=2))
        for entity, mesh in world.query_one(MeshRef):
            if mesh.mesh.name == "plane":
                world.add_component(entity, Reflective(mode="skybox", mix=0.5))

    keeping, drawing = scene(build, (48, 32)), scene(build, (48, 32))
    assert kept_frames_equal_drawn(keeping, drawing, frames=60) >= 2
    assert drawing.stats.reflection_end_views > 0
    assert keeping.engine.renderer.screen_reflections.target_count() > 5   # (a level's images: it reflects)


@pytest.mark.parametrize("active", [False, True], ids=["lens_alone", "both"])
def test_a_monitors_picture_through_a_portal_reflects_as_seen_directly(scene, active):
    """A monitor whose camera (not active) stands before portal A at ``THROUGH_A`` with
    ``ScreenReflections`` (its ``reflection_depth`` 1) and sees its mirrors and portals (depth
    1): its picture through the portal shows the polished floor reflecting the boxes as the
    camera at the eye sees it directly (the active camera, posed as the lens, gives the
    portal's pixels), its level's images its own; at ``reflection_depth`` 0 the portal's view
    in the picture shows the sky's reflection where the boxes' stood.  ``both``: the active
    camera has the same component, and its own frame through the portal still matches."""
    from components import Camera, Material, Monitor
    from engine.assets.mesh import quad
    from tests.support import linear_to_srgb8

    def picture(reflections: ScreenReflections | None):
        def lens(world, names):
            pose = dict(position=glm.vec3(THROUGH_A), rotation=look_rotation(glm.vec3(TARGET) - glm.vec3(EYE)))
            names["lens"] = world.spawn(Transform(**pose), Camera(active=False),
                                        *([reflections] if reflections is not None else []))
            names["screen"] = world.spawn(Transform(position=(0.0, 1.0, 9.0)), MeshRef(quad(1.6, 0.9)),
                                          Material(color=(0.0, 0.0, 0.0, 1.0), roughness=1.0,
                                                   environment_reflection=0.0),
                                          Monitor(camera=names["lens"], size=SIZE, depth=1))

        frame, runner, names = _frame(scene, ScreenReflections() if active else None, portal=True, eye=THROUGH_A,
                                      extra=lens)
        names["frame"] = frame
        shown = runner.engine.renderer.monitors.read(names["screen"])[..., :3]
        return linear_to_srgb8(np.clip(shown, 0.0, 1.0)).astype(np.int32), runner, names

    image, runner, names = picture(ScreenReflections())
    plain, _, _ = picture(ScreenReflections(reflection_depth=0))
    direct, direct_runner, direct_names = _frame(scene, ScreenReflections(), portal=False)
    judged = _assert_reflects_as_seen_directly(image, plain, runner, names, direct, direct_runner, direct_names)
    counts = runner.engine.renderer.resource_counts()["reflection_targets"]
    assert counts == (4 + 5) * (2 if active else 1), counts   # (the picture's root and level, and the camera's)
    if active:
        difference = np.abs(names["frame"][judged] - direct[judged]).max(axis=-1)
        assert np.mean(difference <= 3) > 0.97, np.percentile(difference, [50, 90, 99])



# A periscope of two mirrors: the camera looks sideways into a small mirror turned 45 degrees
# about y (the first), which sends its rays along z, over the boxes, to a tall mirror at
# z = 3 facing them (the second), which sends them back onto the floor and the boxes.  Two
# reflections in vertical planes are a turn about y (here, half a turn and a quarter), so
# what the second's view (level 2) shows is the world seen from the eye carried back through
# both: ``CARRIED``, looking ``DOWN_THE_HALL`` (the camera's pose is worked out from it).
CARRIED, DOWN_THE_HALL = np.array([0.0, 3.0, 10.0]), np.array([0.0, -2.5, -10.0]) / np.hypot(2.5, 10.0)
SECOND_Z, SECOND_SIZE = 3.0, (6.0, 3.6)                      # facing -z, its foot on the floor
FIRST_NORMAL, FIRST_SIZE = np.array([-1.0, 0.0, 1.0]) / np.sqrt(2.0), (1.6, 0.8)


def _reflect(v: np.ndarray, normal: np.ndarray) -> np.ndarray:
    return v - 2.0 * (v @ normal)[..., None] * normal


def _periscope() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(the first mirror's centre, the camera's eye, its way): the carried eye's image in the
    second mirror is 0.6 m along its way from the first mirror's centre, and the camera that
    image's image in the first."""
    across = np.array([0.0, 0.0, -1.0])
    image = _reflect(CARRIED - (0.0, 0.0, SECOND_Z), across) + (0.0, 0.0, SECOND_Z)
    image_way = _reflect(DOWN_THE_HALL, across)
    centre = image + 0.6 * image_way
    return centre, centre + _reflect(image - centre, FIRST_NORMAL), _reflect(image_way, FIRST_NORMAL)


def _rect_hits(origin: np.ndarray, direction: np.ndarray, centre, normal: np.ndarray, size) -> np.ndarray:
    """The distance along each ray (rows) to the vertical rectangle (``centre``, facing
    ``normal`` in the x-z plane, ``size`` wide and high) where it meets it ahead; inf: not."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((np.asarray(centre) - origin) @ normal) / (direction @ normal)
    point = origin + np.where(np.isfinite(t), t, 0.0)[:, None] * direction - centre
    across = np.array([normal[2], 0.0, -normal[0]])
    inside = (np.abs(point @ across) < size[0] / 2) & (np.abs(point[:, 1]) < size[1] / 2)
    return np.where((t > 1e-6) & inside, t, np.inf)


def _nearest_box(origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """The distance along each ray (rows) to the nearest box of the scene it meets ahead (the
    slab test; inf: none)."""
    from tests.test_screen_reflections import BOXES

    nearest = np.full(len(direction), np.inf)
    for centre, size, _ in BOXES:
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (np.subtract(centre, np.multiply(size, 0.5)) - origin) / direction
            t2 = (np.add(centre, np.multiply(size, 0.5)) - origin) / direction
        near, far = np.nanmax(np.minimum(t1, t2), axis=1), np.nanmin(np.maximum(t1, t2), axis=1)
        nearest = np.where((near <= far) & (far > 1e-6), np.minimum(nearest, np.maximum(near, 0.0)), nearest)
    return nearest


def test_two_mirror_levels_deep_the_polished_floor_reflects_as_the_carried_eye_sees_it(scene):
    """``ScreenReflections(reflection_depth=2)`` on a camera looking into a periscope of two
    mirrors (above): in the second mirror seen in the first (level 2) the polished floor
    reflects the boxes as the camera at ``CARRIED`` sees it directly in the scene without the
    mirrors.  Judged: the pixels whose ray, cast here segment by segment, meets the first
    mirror, then the second over the boxes and the floor, then the floor, a box or the sky
    without meeting the first mirror again, and, on the floor, whose reflected ray misses the
    first mirror too (3 pixels from any edge of that set): within 3 levels for 97%; and where
    the ground truth's floor reflects a box, far (40 levels) from the same periscope with
    ``reflection_depth`` 1 (level 2 shows the sky's reflection there)."""
    from components import Camera, Material
    from engine.assets.mesh import quad

    centre, eye, way = _periscope()
    turn = float(np.degrees(np.arctan2(FIRST_NORMAL[0], FIRST_NORMAL[2])))   # (a quad faces +z)
    placed = (("first", tuple(centre), turn, FIRST_SIZE),
              ("second", (0.0, SECOND_SIZE[1] / 2, SECOND_Z), 180.0, SECOND_SIZE))

    def narrow(world, names):
        world.get(names["camera"], Camera).fov_y = 30.0

    def periscope(world, names):
        narrow(world, names)
        for name, at, angle, size in placed:
            names[name] = world.spawn(
                Transform(position=at, rotation=glm.angleAxis(glm.radians(angle), glm.vec3(0, 1, 0))),
                MeshRef(quad(*size), casts_shadows=False), Material(), Mirror())

    image, runner, names = _frame(scene, ScreenReflections(reflection_depth=2), portal=False, eye=tuple(eye),
                                  extra=periscope, way=tuple(way))
    plain, _, _ = _frame(scene, ScreenReflections(reflection_depth=1), portal=False, eye=tuple(eye),
                         extra=periscope, way=tuple(way))
    direct, direct_runner, direct_names = _frame(scene, ScreenReflections(), portal=False, eye=tuple(CARRIED),
                                                 extra=narrow, way=tuple(DOWN_THE_HALL))
    assert runner.stats.reflection_views >= 2
    origin, rays = pixel_rays(runner.engine.main_view, SIZE)
    rays = rays.reshape(-1, 3)
    into = _rect_hits(origin[None], rays, centre, FIRST_NORMAL, FIRST_SIZE)
    first = origin + np.where(np.isfinite(into), into, 0.0)[:, None] * rays
    along = _reflect(rays, FIRST_NORMAL)
    facing = np.array([0.0, 0.0, -1.0])
    across = _rect_hits(first, along, (0.0, SECOND_SIZE[1] / 2, SECOND_Z), facing, SECOND_SIZE)
    second = first + np.where(np.isfinite(across), across, 0.0)[:, None] * along
    back = _reflect(along, facing)
    crossed = np.isfinite(into) & np.isfinite(across) & (first[:, 1] > 0.0) & (_nearest_box(first, along) > across)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_floor = np.where(back[:, 1] < 0.0, -second[:, 1] / back[:, 1], np.inf)
    met = np.minimum(t_floor, _nearest_box(second, back))
    on_floor = np.isfinite(t_floor) & (t_floor <= met)
    ground = second + np.where(on_floor, t_floor, 0.0)[:, None] * back
    bounced = back * (1.0, -1.0, 1.0)
    clear = (_rect_hits(second, back, centre, FIRST_NORMAL, FIRST_SIZE) > met) \
        & ~(on_floor & np.isfinite(_rect_hits(ground, bounced, centre, FIRST_NORMAL, FIRST_SIZE)))
    judged = _eroded((crossed & clear).reshape(SIZE[1], SIZE[0]), 3)
    assert judged.sum() > 8000, judged.sum()
    difference = np.abs(image[judged] - direct[judged]).max(axis=-1)
    assert np.mean(difference <= 3) > 0.97, np.percentile(difference, [50, 90, 99])
    floor = direct_runner.ids() == direct_names["floor"]
    reflecting = judged & floor & (np.abs(direct - plain).max(axis=-1) > 40)
    assert reflecting.sum() > 300, reflecting.sum()
    difference = np.abs(image[reflecting] - direct[reflecting]).max(axis=-1)
    assert np.mean(difference <= 3) > 0.97, np.percentile(difference, [50, 90, 99])
