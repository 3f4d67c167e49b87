"""Lights past the limit (engine/rules/light_rules.py): with more point lights than the
Lights block has slots, the ones kept are those that matter to the camera, not the first
made; a kept light keeps its slot (a still scene's block and shadow maps stay as they are);
two lights of equal importance do not swap as the camera sways; and a light's shadow is the
shadow of the light that is lit.

Real frames on llvmpipe.  What a kept light gives is checked against a second path: the
same scene made with only the lights that should be kept (and without the one that should
light the box), whose pixels the first must equal (and exceed); shadows against float64
shadow rays cast in numpy; slots against the Lights block read back from the GPU."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm
from scipy import ndimage

from components import Camera, Material, MeshRef, Mirror, Monitor, PointLight, Transform, look_rotation
from engine.assets.mesh import box, plane, quad
from engine.assets.portals import spawn_portal_pair
from engine.core.errors import LightLimitWarning
from engine.render.views import (
    LIGHTS_BLOCK_BYTES,
    MAX_DIRECTIONAL_LIGHTS,
    MAX_POINT_LIGHTS,
    SKY_SH_COEFFICIENTS,
    camera_view,
)
from engine.rules.light_rules import KeptLights, PictureEyes
from tests.support import box_hits, look_from, pixel_rays, srgb_to_linear

BOX_A, BOX_B = np.array([0.0, 0.5, 0.0]), np.array([40.0, 0.5, 0.0])
EYE_A, EYE_B = (0.0, 2.0, 5.0), (40.0, 2.0, 5.0)
LAMP_A, LAMP_B = (0.0, 1.5, 1.5), (40.0, 1.5, 1.5)   # each in front of its box, the eye inside its range
FILLERS = MAX_POINT_LIGHTS - 1
# Every scene here has a light past the limit, on purpose (the first test checks the warning).
pytestmark = pytest.mark.filterwarnings("ignore::engine.core.errors.LightLimitWarning")


def _filler_positions(count: int, centre=(20.0, 8.0, -10.0), radius: float = 0.5) -> list[tuple]:
    """A ring of lamps high up between the two boxes: about as far from either eye (25.7 m),
    each lighting nothing the cameras see (range 1)."""
    return [(centre[0] + radius * math.cos(2 * math.pi * i / count), centre[1],
             centre[2] + radius * math.sin(2 * math.pi * i / count)) for i in range(count)]


def _two_boxes(world, lamp_a: bool = True, lamp_b: bool = True, fillers: int = FILLERS) -> dict:
    """Two white boxes 40 m apart; LAMP_B (in front of box B) made first, then ``fillers`` dim
    far lamps, then LAMP_A (the 17th made, in front of box A)."""
    ids = {"camera": look_from(world, EYE_A, target=BOX_A.tolist())}
    for position in (BOX_A, BOX_B):
        world.spawn(Transform(position=position.tolist()), MeshRef(box()), Material(color=(1, 1, 1), roughness=1.0))
    if lamp_b:
        ids["lamp_b"] = world.spawn(Transform(position=LAMP_B), PointLight(color=(1.0, 0.8, 0.6), intensity=3.0,
                                                                           range=4.0))
    ids["fillers"] = [world.spawn(Transform(position=p), PointLight(intensity=2.0, range=1.0))
                      for p in _filler_positions(fillers)]
    if lamp_a:
        ids["lamp_a"] = world.spawn(Transform(position=LAMP_A), PointLight(color=(1.0, 0.8, 0.6), intensity=3.0,
                                                                           range=4.0))
    world.resources["ids"] = ids
    return ids


def _front_face(runner, centre: np.ndarray) -> np.ndarray:
    """The pixels showing the box at ``centre``'s front face (z = +0.5, facing its lamp), away
    from its edges: float64 rays through each pixel meet that face's inner square first."""
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    t = (centre[2] + 0.5 - eye[2]) / rays[..., 2]
    hit = eye + rays * t[..., None]
    inside = (np.abs(hit[..., 0] - centre[0]) < 0.4) & (np.abs(hit[..., 1] - centre[1]) < 0.4) & (t > 0)
    assert inside.sum() > 200, "the box's face is in view"
    return inside


def _move_camera(world, eye, target) -> None:
    camera = world.get(world.resources["ids"]["camera"], Transform)
    camera.position = glm.vec3(eye)
    camera.rotation = look_rotation(glm.vec3(target) - glm.vec3(eye))


def _point_rows(runner) -> np.ndarray:
    """The Lights block's point-light rows as the GPU holds them: (MAX_POINT_LIGHTS, 2, 4)
    floats, per slot its position and range, its colour; and the point count."""
    data = np.frombuffer(runner.engine.renderer.lights_ubo.read(), np.float32)
    assert data.size * 4 == LIGHTS_BLOCK_BYTES
    base = 4 * SKY_SH_COEFFICIENTS
    count = int(data[base:base + 4].view(np.int32)[1])
    base += 4 + 8 * MAX_DIRECTIONAL_LIGHTS
    rows = data[base:base + 8 * MAX_POINT_LIGHTS].reshape(2, MAX_POINT_LIGHTS, 4).transpose(1, 0, 2)
    return count, rows.copy()


def _save(name: str, rgb: np.ndarray) -> None:
    """The frame as a PNG under /tmp (to look at; the assertions do not read it)."""
    try:
        from PIL import Image
        Image.fromarray(rgb).save(f"/tmp/lights_kept_{name}.png")
    except ImportError:  # pragma: no cover - Pillow is optional
        pass


def test_the_lamp_nearest_the_camera_is_kept_and_lights_its_box(scene):
    """Seventeen lamps, the 17th made in front of box A with the camera inside its range: it
    is kept and lights the box, pixel for pixel as a scene made with only the sixteen the rule
    keeps (LAMP_B, the least important to this camera, left out), and brighter than the
    sixteen made first (the old rule's)."""
    runner = scene(_two_boxes)
    with pytest.warns(LightLimitWarning, match="17 point lights.*matter most to the active camera.*1 point lights"):
        rgb = runner.frame()
    ids = runner.world.resources["ids"]
    kept = runner.world.resources[KeptLights]
    assert runner.stats.lights_cut == 1 and kept.cut == (0, 1)
    assert ids["lamp_a"] in kept.point and ids["lamp_b"] not in kept.point
    face = _front_face(runner, BOX_A)
    only_kept = scene(lambda world: _two_boxes(world, lamp_b=False)).frame()
    first_made = scene(lambda world: _two_boxes(world, lamp_a=False)).frame()
    _save("seventeen", rgb)
    _save("first_made", first_made)
    np.testing.assert_array_equal(rgb[face], only_kept[face])
    lit, unlit = srgb_to_linear(rgb[face]).mean(), srgb_to_linear(first_made[face]).mean()
    assert lit > unlit + 0.1, (lit, unlit)


def test_moving_the_camera_to_the_other_lamp_swaps_which_is_kept_in_the_same_slot(scene):
    """The camera goes from box A to box B: LAMP_B, inside whose range it now is, is kept in
    place of LAMP_A (now the least important), in the slot LAMP_A left, every other lamp in
    its slot (the block's other rows unchanged); box B is lit as in a scene without LAMP_A.
    Back at box A, LAMP_A is kept again in that slot."""
    runner = scene(_two_boxes)
    ids = runner.world.resources["ids"]
    runner.frame()
    before = runner.world.resources[KeptLights].point
    count, rows_before = _point_rows(runner)
    assert count == MAX_POINT_LIGHTS
    _move_camera(runner.world, EYE_B, BOX_B)
    rgb = runner.frame()
    after = runner.world.resources[KeptLights].point
    slot = before.index(ids["lamp_a"])
    assert after == before[:slot] + (ids["lamp_b"],) + before[slot + 1:]
    count, rows_after = _point_rows(runner)
    changed = np.flatnonzero((rows_before != rows_after).any(axis=(1, 2)))
    assert changed.tolist() == [slot]
    np.testing.assert_allclose(rows_after[slot, 0, :3], LAMP_B)
    assert runner.stats.lights_cut == 1

    def without_a(world):
        _two_boxes(world, lamp_a=False)
        _move_camera(world, EYE_B, BOX_B)

    second = scene(without_a)
    reference = second.frame()
    _save("camera_at_b", rgb)
    face = _front_face(runner, BOX_B)
    np.testing.assert_array_equal(rgb[face], reference[face])
    assert srgb_to_linear(rgb[face]).mean() > 0.1
    _move_camera(runner.world, EYE_A, BOX_A)   # and back: LAMP_A takes the slot again
    runner.frame()
    assert runner.world.resources[KeptLights].point == before


def test_two_lamps_of_equal_importance_do_not_swap_as_the_camera_sways(scene):
    """Fifteen lamps near the camera and two more, P and Q, mirror images across the plane
    the camera sways through: each sway makes the other one the more important by a hair.
    The one kept stays kept (the block's bytes do not change, no shadow map is drawn); a
    decisive move towards the other swaps them once."""
    p, q = (6.0, 1.5, -20.0), (-6.0, 1.5, -20.0)

    def build(world):
        ids = {"camera": look_from(world, (0.1, 2.0, 5.0), target=(0.0, 0.5, 0.0))}
        world.spawn(Transform(position=(0, 0.5, 0)), MeshRef(box()), Material(color=(1, 1, 1)))
        ids["fillers"] = [world.spawn(Transform(position=position), PointLight(intensity=5.0, range=1.0))
                          for position in _filler_positions(FILLERS, centre=(0.0, 6.0, -6.0))]
        ids["p"] = world.spawn(Transform(position=p), PointLight(intensity=1.0, range=1.0))
        ids["q"] = world.spawn(Transform(position=q), PointLight(intensity=1.0, range=1.0))
        world.resources["ids"] = ids

    runner = scene(build)
    ids = runner.world.resources["ids"]
    runner.frame()
    first = runner.world.resources[KeptLights].point
    assert ids["p"] in first and ids["q"] not in first   # x = +0.1: P the nearer
    block = runner.engine.renderer.lights_ubo.read()
    for frame in range(6):
        x = -0.1 if frame % 2 == 0 else 0.1   # Q, then P, the nearer by a hair
        _move_camera(runner.world, (x, 2.0, 5.0), (0.0, 0.5, 0.0))
        runner.frame()
        assert runner.world.resources[KeptLights].point == first, f"swapped at sway {frame}"
        assert runner.engine.renderer.lights_ubo.read() == block
        assert runner.stats.lights_cut == 1
    _move_camera(runner.world, (-6.0, 2.0, -14.0), (-6.0, 0.5, -20.0))   # right by Q
    runner.frame()
    now = runner.world.resources[KeptLights].point
    assert ids["q"] in now and ids["p"] not in now and now.index(ids["q"]) == first.index(ids["p"])


def _lamp_over_floor(world, near: bool = True) -> dict:
    """A floor and a box on it; sixteen far lamps that cast shadows made first, then LAMP
    (casting too) above and beside the box, the camera inside its range."""
    ids = {"camera": look_from(world, (0.0, 5.5, 6.0), target=(0.0, 0.0, 0.0))}
    ids["floor"] = world.spawn(Transform(), MeshRef(plane(14, 14)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
    ids["box"] = world.spawn(Transform(position=(-1.0, 0.5, 0.0)), MeshRef(box()), Material(color=(0.8, 0.3, 0.2)))
    ids["fillers"] = [world.spawn(Transform(position=position), PointLight(intensity=2.0, range=1.0, shadows=True))
                      for position in _filler_positions(MAX_POINT_LIGHTS, centre=(30.0, 8.0, -30.0))]
    if near:
        ids["lamp"] = world.spawn(Transform(position=(1.2, 2.0, 0.6)),
                                  PointLight(intensity=10.0, range=9.0, shadows=True))
    world.resources["ids"] = ids
    return ids


def test_the_shadow_of_a_caster_is_under_the_lit_lamp_past_the_limit(scene):
    """Seventeen lamps casting shadows, LAMP the 17th: it is lit, holds a shadow cube (the
    Shadows block's cube -> light is its slot in the Lights block), and the box's shadow
    from it lies on the floor where float64 shadow rays to LAMP say: the floor points the box
    hides from it are darker with its shadows on than off, the points it reaches unchanged."""
    runner = scene(_lamp_over_floor, (320, 240))
    runner.engine.renderer.antialias = "off"
    ids = runner.world.resources["ids"]
    lamp = runner.world.get(ids["lamp"], PointLight)
    lamp.shadows = False
    without = runner.frame()
    lamp.shadows = True
    with_shadows = runner.frame()
    _save("shadow_off", without)
    _save("shadow_on", with_shadows)
    kept = runner.world.resources[KeptLights]
    slot = kept.point_slot(ids["lamp"])
    assert slot >= 0 and ids["lamp"] in kept.point_shadows
    cube = kept.point_shadows.index(ids["lamp"])
    assert runner.engine.renderer.shadows._cube_lights[cube] == slot
    assert runner.stats.lights_cut == 1 and runner.stats.shadows_cut == MAX_POINT_LIGHTS + 1 - 2
    # The floor point each pixel shows, and whether the box stands between it and LAMP.
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    points = (eye + rays * (-eye[1] / rays[..., 1])[..., None]).reshape(-1, 3)
    position = np.array([1.2, 2.0, 0.6])
    to_lamp = position - points
    distance = np.linalg.norm(to_lamp, axis=1)
    direction = to_lamp / distance[:, None]
    centre = np.array([-1.0, 0.5, 0.0])
    hidden_in = box_hits(points, direction, centre, np.full(3, 0.5 - 0.06), distance).reshape(runner.size[::-1])
    hidden_out = box_hits(points, direction, centre, np.full(3, 0.5 + 0.06), distance).reshape(runner.size[::-1])
    floor = (runner.ids() == ids["floor"]) & (distance < 5.0).reshape(runner.size[::-1])
    on = srgb_to_linear(with_shadows).mean(axis=-1)
    off = srgb_to_linear(without).mean(axis=-1)
    ratio = on / np.maximum(off, 1e-6)
    umbra, open_floor = floor & hidden_in, floor & ~hidden_out
    assert umbra.sum() > 500 and open_floor.sum() > 5000, (umbra.sum(), open_floor.sum())
    assert (ratio[umbra] < 0.7).mean() >= 0.95, f"{(ratio[umbra] < 0.7).mean():.3f} of the umbra is shadowed"
    assert (ratio[open_floor] > 0.95).mean() >= 0.99
    # LAMP lights the floor: the frame with it is brighter than the scene made without it.
    alone = scene(lambda world: _lamp_over_floor(world, near=False), (320, 240))
    alone.engine.renderer.antialias = "off"
    dark = srgb_to_linear(alone.frame()).mean(axis=-1)
    assert (off[open_floor] > dark[open_floor] + 0.01).mean() >= 0.99


def test_a_still_scene_keeps_its_slots_block_and_shadow_maps(scene):
    """Seventeen casting lamps: after the first frames, a still frame leaves the Lights block
    as it was and draws no shadow map; so does a camera moving a little (the rule is asked
    again, the same lamps stay kept in the same slots); a filler lamp going frees its slot,
    the lamp left out takes it, and the rest of the block is unchanged."""
    runner = scene(_lamp_over_floor)
    ids = runner.world.resources["ids"]
    runner.frame()
    runner.frame()
    count, rows = _point_rows(runner)
    kept = runner.world.resources[KeptLights]
    for _ in range(3):
        runner.frame()
        assert runner.stats.shadow_maps_drawn == 0 and runner.stats.shadow_maps_kept == 2
        assert _point_rows(runner)[1].tobytes() == rows.tobytes()
        assert runner.world.resources[KeptLights] is kept   # nothing moved: nothing ranked
    for step in range(3):
        _move_camera(runner.world, (0.1 * (step + 1), 5.5, 6.0), (0.0, 0.0, 0.0))
        runner.frame()
        assert runner.world.resources[KeptLights].point == kept.point
        assert runner.stats.shadow_maps_drawn == 0
        assert _point_rows(runner)[1].tobytes() == rows.tobytes()
    left_out = next(e for e in ids["fillers"] if e not in kept.point)
    gone = next(e for e in ids["fillers"] if e in kept.point and e not in kept.point_shadows)
    runner.world.delete_entity(gone)
    runner.frame()
    now = runner.world.resources[KeptLights].point
    slot = kept.point.index(gone)
    assert now == kept.point[:slot] + (left_out,) + kept.point[slot + 1:]
    assert runner.stats.lights_cut == 0 and runner.stats.shadow_maps_drawn == 0
    changed = np.flatnonzero((_point_rows(runner)[1] != rows).any(axis=(1, 2)))
    assert changed.tolist() == [slot]


def test_the_rules_falloff_is_the_scene_shaders(scene):
    """The importance the rule gives a point light is measured with the scene shader's own
    falloff (``light_rules.falloff``): a floor under one lamp, nothing else lighting it (a
    black sky), shows at each pixel albedo / pi x intensity x cos x ``falloff(distance)``
    (a rough dielectric's specular adds a few percent), across the lamp's whole range, and
    black past it."""
    from components import Skybox
    from engine.rules.light_rules import falloff
    from tests.support import linear_to_srgb8

    lamp, light_range, intensity, albedo = np.array([0.0, 1.5, 0.0]), 4.0, 6.0, 0.8

    def build(world):
        world.spawn(Skybox(faces=np.zeros((6, 16, 16, 3), np.float32)))
        world.resources["ids"] = {"camera": look_from(world, (0.0, 6.0, 6.0), target=(0.0, 0.0, 0.0)),
                                  "floor": world.spawn(Transform(), MeshRef(plane(14, 14)),
                                                       Material(color=(albedo,) * 3, roughness=1.0))}
        world.spawn(Transform(position=lamp.tolist()), PointLight(intensity=intensity, range=light_range))

    runner = scene(build, (320, 240))
    runner.engine.renderer.antialias = "off"
    rgb = runner.frame()
    _save("falloff", rgb)
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    points = eye + rays * (-eye[1] / rays[..., 1])[..., None]
    to_lamp = lamp - points
    distance = np.linalg.norm(to_lamp, axis=-1)
    expected = albedo / np.pi * intensity * (to_lamp[..., 1] / distance) * falloff(distance, light_range)
    floor = runner.ids() == runner.world.resources["ids"]["floor"]
    shown = srgb_to_linear(rgb).mean(axis=-1)
    steps = np.abs(srgb_to_linear(linear_to_srgb8(expected) + 1.5) - expected)  # 1.5 sRGB steps at each value
    inside = floor & (distance < light_range) & (expected > 0.01)
    assert inside.sum() > 10000, inside.sum()
    error = np.abs(shown[inside] - expected[inside]) - steps[inside]
    assert (error <= 0.06 * expected[inside]).mean() >= 0.99, np.percentile(error / expected[inside], [50, 99])
    assert (shown[floor & (distance > light_range + 0.05)] == 0.0).all()


def test_a_lamp_that_loses_or_gets_its_transform_leaves_or_takes_a_slot(scene):
    """A PointLight lights from its Transform: a kept lamp whose Transform is taken away
    leaves its slot to the lamp left out (no frame reads the gone Transform), and given one
    back it is ranked again (here: the least important, so it stays out)."""
    runner = scene(_two_boxes)
    ids = runner.world.resources["ids"]
    runner.frame()
    before = runner.world.resources[KeptLights].point
    slot = before.index(ids["lamp_a"])
    runner.world.remove_component(ids["lamp_a"], Transform)
    runner.frame()
    after = runner.world.resources[KeptLights].point
    assert after == before[:slot] + (ids["lamp_b"],) + before[slot + 1:]
    assert runner.stats.lights_cut == 0
    runner.world.add_component(ids["lamp_a"], Transform(position=(20.0, 30.0, -60.0)))
    runner.frame()
    assert runner.world.resources[KeptLights].point == after and runner.stats.lights_cut == 1


# -- lights that matter in what a portal shows -------------------------------------------------

HALF_TURN = glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))


def _portal_to_box_b(world, fillers: bool = True, lamp_b: bool = True) -> dict:
    """``_two_boxes`` with a portal between the camera and box A whose partner, 40 m off,
    looks back at box B's lit face: through it the camera sees what LAMP_B lights, though
    LAMP_B is the lamp farthest from the camera (the portal's view's eye is 6 m from it)."""
    ids = _two_boxes(world, lamp_b=lamp_b, fillers=FILLERS if fillers else 0)
    ids["portals"] = spawn_portal_pair(world, (0.0, 1.6, 2.0), None, (40.0, 1.6, 4.5), HALF_TURN, size=(2.4, 2.4))
    ids["box_b"] = next(entity for entity, (t, _) in world.query(Transform, MeshRef)
                        if tuple(t.position) == tuple(BOX_B))
    return ids


def test_a_lamp_far_from_the_camera_is_kept_when_a_portal_shows_what_it_lights(scene):
    """Seventeen lamps, the camera before a portal onto box B: from the second frame (the
    first portal view's eye published) LAMP_B, 40 m away, is kept instead of a filler lamp
    (each lights nothing in view), and box B through the portal is lit pixel for pixel as in
    the scene with no fillers (every lamp kept), brighter than without LAMP_B.  The
    camera's choice alone (the first frame's) cut LAMP_B."""
    runner = scene(_portal_to_box_b)
    ids = runner.world.resources["ids"]
    runner.frame()
    assert ids["lamp_b"] not in runner.world.resources[KeptLights].point  # no view seen yet
    runner.frame()
    kept = runner.world.resources[KeptLights]
    assert ids["lamp_b"] in kept.point and ids["lamp_a"] in kept.point and kept.cut == (0, 1)
    assert len(kept.views) == 1 and kept.views[0][3] > 0.2  # the portal's view, a fifth of the screen
    rgb = runner.frame()
    # Box B's pixels, all of them through the portal (box A stands behind it, the id image
    # follows the portal's view), its edges left out.
    box_b = ndimage.binary_erosion(runner.ids() == ids["box_b"])
    assert box_b.sum() > 100
    every_lamp = scene(lambda world: _portal_to_box_b(world, fillers=False))
    every_lamp.frame()
    every_lamp.frame()
    no_lamp_b = scene(lambda world: _portal_to_box_b(world, lamp_b=False))
    no_lamp_b.frame()
    no_lamp_b.frame()
    np.testing.assert_array_equal(rgb[box_b], every_lamp.frame()[box_b])
    lit, unlit = srgb_to_linear(rgb[box_b]).mean(), srgb_to_linear(no_lamp_b.frame()[box_b]).mean()
    assert lit > unlit + 0.1, (lit, unlit)
    runner.frame()
    assert runner.world.resources[KeptLights] is kept  # still: nothing ranked again


# -- lights that matter in what a monitor shows -------------------------------------------------

LENS_SIZE = (160, 120)


def _monitor_on_box_b(world, fillers: bool = True, lamp_b: bool = True) -> dict:
    """``_two_boxes`` with a screen between the camera and box A (a fifth of the frame) whose
    monitor's camera stands at EYE_B looking at box B's lit face: the picture shows what LAMP_B
    lights, though LAMP_B is the lamp farthest from the active camera."""
    ids = _two_boxes(world, lamp_b=lamp_b, fillers=FILLERS if fillers else 0)
    eye = glm.vec3(EYE_B)
    ids["lens"] = world.spawn(Transform(position=eye, rotation=look_rotation(glm.vec3(*BOX_B) - eye)),
                              Camera(fov_y=60.0, active=False))
    ids["screen"] = world.spawn(Transform(position=(0.0, 1.6, 2.0)), MeshRef(quad(2.4, 1.8)),
                                Material(color=(0.0, 0.0, 0.0, 1.0), roughness=1.0),
                                Monitor(camera=ids["lens"], size=LENS_SIZE))
    return ids


def _picture_front_face(runner) -> np.ndarray:
    """The picture's pixels (rows from the top) showing box B's front face, away from its edges."""
    lens = runner.world.get(runner.world.resources["ids"]["lens"], Transform)
    eye, rays = pixel_rays(camera_view(lens.world, 60.0, 0.1, 100.0, LENS_SIZE), LENS_SIZE)
    t = (BOX_B[2] + 0.5 - eye[2]) / rays[..., 2]
    hit = eye + rays * t[..., None]
    inside = (np.abs(hit[..., 0] - BOX_B[0]) < 0.4) & (np.abs(hit[..., 1] - BOX_B[1]) < 0.4) & (t > 0)
    assert inside.sum() > 200, "the box's face is in the picture"
    return inside


def test_a_lamp_far_from_the_camera_is_kept_when_a_monitor_shows_what_it_lights(scene):
    """Seventeen lamps, a screen before the camera showing box B: from the second frame (the
    picture's camera's eye published with its screen's share of the frame) LAMP_B, 40 m
    away, is kept instead of a filler lamp, and box B in the picture is lit as in the scene
    with no fillers (every lamp kept), brighter than without LAMP_B.  The camera's choice
    alone (the first frame's) cut LAMP_B; a still frame ranks nothing again."""
    runner = scene(_monitor_on_box_b)
    ids = runner.world.resources["ids"]
    runner.frame()
    assert ids["lamp_b"] not in runner.world.resources[KeptLights].point  # no picture's eye yet
    runner.frame()
    kept = runner.world.resources[KeptLights]
    assert ids["lamp_b"] in kept.point and ids["lamp_a"] in kept.point and kept.cut == (0, 1)
    assert len(kept.views) == 1 and kept.views[0][:3] == pytest.approx(EYE_B) and kept.views[0][3] > 0.15, kept.views
    face = _picture_front_face(runner)
    picture = runner.engine.renderer.monitors.read(ids["screen"])[..., :3][face]
    shown = {}
    for name, build in (("every_lamp", lambda world: _monitor_on_box_b(world, fillers=False)),
                        ("no_lamp_b", lambda world: _monitor_on_box_b(world, lamp_b=False))):
        other = scene(build)
        other.frame()
        other.frame()
        shown[name] = other.engine.renderer.monitors.read(other.world.resources["ids"]["screen"])[..., :3][face]
    np.testing.assert_allclose(picture, shown["every_lamp"], atol=2e-3)
    assert picture.mean() > shown["no_lamp_b"].mean() + 0.1, (picture.mean(), shown["no_lamp_b"].mean())
    eyes = runner.world.resources[PictureEyes]
    runner.frame()
    assert runner.world.resources[KeptLights] is kept  # still: nothing ranked again
    assert runner.world.resources[PictureEyes] is eyes  # ... and no snapshot of the eyes made again
    _move_camera(runner.world, (0.0, 2.0, 5.2), BOX_A)
    runner.frame()
    assert runner.world.resources[PictureEyes] is not eyes  # (the camera moved: the screen's share may have)


def test_the_choice_made_ahead_is_the_prepare_stages_every_frame(scene, monkeypatch):
    """``lights_this_frame`` (what the extract stage asks, before the prepare stage chooses)
    gives the prepare stage's choice on every frame of a walk from lamp A to lamp B and back
    past the lamps' limit (the choice swaps, stands while the camera stands), and on a still
    frame it is the published choice itself: nothing ranked."""
    from engine.render.shadows import LIGHT_LIMITS
    from engine.rules.light_rules import lights_this_frame
    from systems.extract_system import ExtractSystem

    runner = scene(_two_boxes)
    ahead = []
    extract = runner.world.get_system(ExtractSystem)
    process = extract.process

    def asking(dt):
        ahead.append(lights_this_frame(runner.world, LIGHT_LIMITS))
        process(dt)
    monkeypatch.setattr(extract, "process", asking)
    ids = runner.world.resources["ids"]
    chosen = []
    walk = [EYE_A] * 2 + [tuple(np.array(EYE_A) + (np.array(EYE_B) - EYE_A) * t) for t in np.linspace(0, 1, 9)] \
        + [EYE_B] * 2 + [EYE_A] * 2
    for eye in walk:
        _move_camera(runner.world, eye, (eye[0], 0.5, 0.0))
        runner.frame()
        chosen.append(runner.world.resources[KeptLights])
    assert [k.point for k in ahead] == [k.point for k in chosen]
    kept_a = {k.point.count(ids["lamp_a"]) for k in chosen}
    assert kept_a == {0, 1}   # (the choice did swap: lamp A cut at B's end)
    # Still (the camera not moved): the published choice, the same object, both stages.
    before = runner.world.resources[KeptLights]
    runner.frame()
    assert ahead[-1] is before and runner.world.resources[KeptLights] is before


def test_a_pictures_eye_is_weighed_by_its_screens_or_its_panels_share_of_the_frame(scene):
    """``PictureEyes.points``: a screen's share is its box's rectangle on the frame (its four
    corners projected by glm, a second path, the rectangle's area in whole pixels over the
    frame's); a HUD panel's, its pixels over the frame's; a screen off the frame counts for
    nothing (under ``MIN_VIEW_SHARE``: left out)."""
    from components import ScreenPanel
    from engine.rules.light_rules import MIN_VIEW_SHARE, PictureEyes

    size = (160, 120)

    def build(world):
        ids = {"camera": look_from(world, (0.0, 1.6, 5.0), (0.0, 1.6, 0.0))}
        lens = world.spawn(Transform(position=(20.0, 1.0, 0.0)), Camera(active=False))
        ids["seen"] = world.spawn(Transform(position=(0.7, 1.4, 0.0)), MeshRef(quad(1.6, 0.9)), Material(),
                                  Monitor(camera=lens, size=(32, 18)))
        ids["behind"] = world.spawn(Transform(position=(0.0, 1.4, 9.0)), MeshRef(quad(1.6, 0.9)), Material(),
                                    Monitor(camera=lens, size=(32, 18)))
        ids["panel"] = world.spawn(ScreenPanel(size=(64, 30)), Monitor(camera=lens, size=(32, 18)))
        world.resources["ids"] = ids

    runner = scene(build, size)
    runner.frame()
    points = runner.world.resources[PictureEyes].points
    # The seen screen's corners through the main view, by glm: its rectangle in whole pixels.
    view = runner.engine.main_view
    xs, ys = [], []
    for dx in (-0.8, 0.8):
        for dy in (-0.45, 0.45):
            clip = view.view_proj * glm.vec4(0.7 + dx, 1.4 + dy, 0.0, 1.0)
            xs.append((clip.x / clip.w * 0.5 + 0.5) * size[0])
            ys.append((clip.y / clip.w * 0.5 + 0.5) * size[1])
    seen = (math.ceil(max(xs)) - math.floor(min(xs))) * (math.ceil(max(ys)) - math.floor(min(ys))) / (size[0] * size[1])
    panel = 64 * 30 / (size[0] * size[1])
    assert seen > MIN_VIEW_SHARE and panel > MIN_VIEW_SHARE
    assert sorted(share for *_, share in points) == pytest.approx(sorted([seen, panel]))
    assert all(eye == pytest.approx((20.0, 1.0, 0.0)) for *eye, _ in points)


PORTAL_A, PORTAL_B = (0.0, 1.6, 2.0), (-30.0, 1.6, 4.5)   # B turned half about y: the carry is a shift
SCREEN_BEYOND, SCREEN_BEYOND_SIZE = (-30.0, 1.6, 3.0), (4.8, 2.4)   # wider than the portal shows


def _screen_through_a_portal(world, portal: bool = True) -> dict:
    """``_monitor_on_box_b``'s monitor, its screen 30 m off to the side where the camera
    (before a portal) cannot see it directly: only through the portal, whose partner stands
    1.5 m before the screen's face (``portal`` False: no portal, the screen seen nowhere)."""
    ids = _two_boxes(world)
    _move_camera(world, (0.0, 1.6, 4.5), (0.0, 1.6, 0.0))
    if portal:
        ids["portals"] = spawn_portal_pair(world, PORTAL_A, None, PORTAL_B, HALF_TURN, size=(2.4, 2.4))
    eye = glm.vec3(EYE_B)
    ids["lens"] = world.spawn(Transform(position=eye, rotation=look_rotation(glm.vec3(*BOX_B) - eye)),
                              Camera(fov_y=60.0, active=False))
    ids["screen"] = world.spawn(Transform(position=SCREEN_BEYOND), MeshRef(quad(*SCREEN_BEYOND_SIZE)),
                                Material(color=(0.0, 0.0, 0.0, 1.0), roughness=1.0),
                                Monitor(camera=ids["lens"], size=(32, 24)))
    return ids


def _pixel_rect(view, corners, size) -> np.ndarray:
    """(x0, y0, x1, y1): the whole pixels holding world ``corners`` projected by glm through
    ``view``, on a frame of ``size``."""
    xs, ys = [], []
    for corner in corners:
        clip = view.view_proj * glm.vec4(*corner, 1.0)
        assert clip.w > 0.0
        xs.append((clip.x / clip.w * 0.5 + 0.5) * size[0])
        ys.append((clip.y / clip.w * 0.5 + 0.5) * size[1])
    return np.array([math.floor(min(xs)), math.floor(min(ys)), math.ceil(max(xs)), math.ceil(max(ys))], float)


def test_a_pictures_eye_counts_its_screen_seen_only_through_a_portal(scene):
    """The screen stands where the camera cannot see it, but the portal before the camera
    shows it: its share of the frame is its rectangle through the portal, worked out here
    as the screen carried back through the pair (the partner turned half about y: a shift
    by A - B) seen by the main view through glm, cut to the portal's own rectangle (the
    screen is wider than the portal shows); from the second frame (last frame's portal view
    published) the picture's eye counts so, and from the third (the lights chosen by the
    eyes published the frame before) LAMP_B, which lights what the picture shows, is kept
    in place of a filler (as with the screen before the camera); without the portal the eye
    counts for nothing and LAMP_B stays cut.  The screen's entity is in the id image where
    the portal shows it."""
    runner = scene(_screen_through_a_portal)
    ids = runner.world.resources["ids"]
    runner.frame()
    assert runner.world.resources[PictureEyes].points == ()   # (no portal view yet: the screen is not seen)
    _save("screen_through_a_portal", runner.frame())
    assert (runner.ids() == ids["screen"]).sum() > 200   # seen, through the portal
    view, size = runner.engine.main_view, runner.size
    shift = np.array(PORTAL_A) - np.array(PORTAL_B)
    half = np.array([SCREEN_BEYOND_SIZE[0] / 2, SCREEN_BEYOND_SIZE[1] / 2, 0.0])
    screen = [np.array(SCREEN_BEYOND) + half * (sx, sy, 0) + shift for sx in (-1, 1) for sy in (-1, 1)]
    portal = [np.array(PORTAL_A) + (1.2 * sx, 1.2 * sy, 0.0) for sx in (-1, 1) for sy in (-1, 1)]
    seen, opening = _pixel_rect(view, screen, size), _pixel_rect(view, portal, size)
    inside = np.maximum(np.minimum(seen[2:], opening[2:]) - np.maximum(seen[:2], opening[:2]), 0.0)
    expected = inside[0] * inside[1] / (size[0] * size[1])
    assert seen[0] < opening[0] and seen[2] > opening[2] and seen[3] < opening[3]   # cut at the portal's sides
    assert expected > 0.2
    (point,) = runner.world.resources[PictureEyes].points
    assert point[:3] == pytest.approx(EYE_B) and point[3] == pytest.approx(expected, rel=0.03)
    runner.frame()   # (the lights are chosen before the monitors stage: by the eyes it published the frame before)
    kept = runner.world.resources[KeptLights]
    assert ids["lamp_b"] in kept.point and ids["lamp_a"] in kept.point and kept.cut == (0, 1)
    assert (*EYE_B, point[3]) in kept.views
    unseen = scene(lambda world: _screen_through_a_portal(world, portal=False))
    for _ in range(3):
        unseen.frame()
    assert unseen.world.resources[PictureEyes].points == ()
    assert unseen.world.resources["ids"]["lamp_b"] not in unseen.world.resources[KeptLights].point


def _pictures_before_the_camera(screen_at=(0.7, 1.4, 0.0), lens_at=(20.0, 1.0, 0.0), behind: bool = False,
                                mirror: bool = False, monitors: int = 1):
    """The camera at (0, 1.6, 5) looking down -z; ``monitors`` screens in a row from
    ``screen_at`` (``behind``: one screen at z = 6, behind the camera, turned to face -z),
    fed by one camera at ``lens_at``; ``mirror``: a mirror at z = 2 facing the camera,
    which shows the screen behind it."""
    def build(world):
        world.resources["ids"] = ids = {"camera": look_from(world, (0.0, 1.6, 5.0), (0.0, 1.6, 0.0))}
        ids["lens"] = world.spawn(Transform(position=lens_at), Camera(active=False))
        if mirror:
            ids["mirror"] = world.spawn(Transform(position=(0.0, 1.5, 2.0)), MeshRef(quad(4.0, 3.0)), Material(),
                                        Mirror())
        if behind:
            ids["screens"] = [world.spawn(Transform(position=(0.3, 1.4, 6.0), rotation=HALF_TURN),
                                          MeshRef(quad(3.2, 1.8)), Material(),
                                          Monitor(camera=ids["lens"], size=(8, 8)))]
        else:
            ids["screens"] = [world.spawn(Transform(position=(screen_at[0] - 1.7 * k, screen_at[1], screen_at[2])),
                                          MeshRef(quad(1.6, 0.9)), Material(), Monitor(camera=ids["lens"], size=(8, 8)))
                              for k in range(monitors)]
    return build


def _move(runner, name, position) -> None:
    ids = runner.world.resources["ids"]
    runner.world.get(ids[name] if name != "screen" else ids["screens"][0], Transform).position = position


def _resize(runner, size) -> None:
    from engine.render.targets import CaptureTarget

    runner.capture.release()
    runner.size, runner.capture = size, CaptureTarget(runner.ctx, size)


SIZE = (64, 48)
REMADE = {   # what changes, the build before, the change, the build after (and the frame's size after)
    "the screen moved": ({}, lambda runner: _move(runner, "screen", (-0.9, 1.2, 2.0)),
                         {"screen_at": (-0.9, 1.2, 2.0)}, SIZE),
    "the pictures camera moved": ({}, lambda runner: _move(runner, "lens", (25.0, 2.0, 3.0)),
                                  {"lens_at": (25.0, 2.0, 3.0)}, SIZE),
    "the output resized": ({}, lambda runner: _resize(runner, (32, 48)), {}, (32, 48)),
    "a mirror placed": ({"behind": True}, lambda runner: runner.world.spawn(
        Transform(position=(0.0, 1.5, 2.0)), MeshRef(quad(4.0, 3.0)), Material(), Mirror()),
        {"behind": True, "mirror": True}, SIZE),
    "a mirror removed": ({"behind": True, "mirror": True},
                         lambda runner: runner.world.delete_entity(runner.world.resources["ids"]["mirror"]),
                         {"behind": True}, SIZE),
}


@pytest.mark.parametrize("change", list(REMADE))
def test_a_pictures_eye_is_worked_out_again_after_each_change_it_depends_on(scene, change):
    """``PictureEyes`` is kept while nothing it is made from changed (a still frame: the
    same snapshot) and made again after each change its screen's share or its eye depends
    on: the screen or the picture's camera moved, the frame resized, a mirror showing the
    screen placed or removed (last frame's mirror views: the frame after).  Two frames
    after the change, the eyes are those of the scene built as it now stands (a second
    engine, run as long), and not those from before the change."""
    before, act, after, size = REMADE[change]
    runner = scene(_pictures_before_the_camera(**before), SIZE)
    for _ in range(3):
        runner.frame()
    eyes = runner.world.resources[PictureEyes]
    old = eyes.points
    runner.frame()
    assert runner.world.resources[PictureEyes] is eyes   # still: kept
    act(runner)
    for _ in range(2):
        runner.frame()
    fresh = scene(_pictures_before_the_camera(**after), size)
    for _ in range(3):
        fresh.frame()
    expected = fresh.world.resources[PictureEyes].points
    assert np.shape(expected) != np.shape(old) or not np.allclose(expected, old, atol=1e-3), (expected, old)
    points = runner.world.resources[PictureEyes].points
    assert np.shape(points) == np.shape(expected) and np.allclose(points, expected, atol=1e-6), (points, expected)

