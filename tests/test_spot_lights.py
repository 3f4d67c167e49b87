"""Spot lights (``PointLight.spot_angle`` and ``spot_blend``): a point light whose light goes
only within a cone about its entity's -Z.

Real frames on llvmpipe against a second computation: each floor pixel's angle from the
spot's axis, worked out in float64 from the pixel's ray, says where the frame must equal the
same lamp shining all round (inside the inner cone), the frame without the lamp (outside
the cone) or lie between them (the fading edge); through a mirror, the lamp's image and its
axis reflected by hand say where the reflected cone lands on the floor.  The cone's GLSL
(``shaders/include/spot_cone.glsl``) is evaluated against its owner, ``light_rules``."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, Material, MeshRef, Mirror, PointLight, Portal, Transform, look_rotation
from engine.assets.level_file import LevelError, load_level
from engine.assets.mesh import box, plane, quad
from engine.assets.portals import spawn_portal_pair
from engine.core.cube_faces import CUBE_FACES
from engine.core.portal_math import pair_transform
from engine.core.world import World
from engine.rules.light_rules import ALL_ROUND, cone_reaches, cube_faces_lit, lamp_cone, spot_cone, spot_factor
from shell.overlay_text import overlay_lines
from tests.support import box_hits, look_from, pixel_rays, srgb_to_linear
from tests.test_one_owner import evaluate_glsl

LAMP = np.array([0.0, 3.0, 0.0])
ANGLE, BLEND = 30.0, 0.4
INNER = ANGLE * (1.0 - BLEND)
MARGIN = 2.5   # degrees either side of an edge left out (a pixel's footprint and FXAA)


def _floor(world, spot_angle: float | None, aim=(0.0, -1.0, 0.0)) -> dict:
    """A grey floor seen from above, and a lamp 3 m over its centre aimed along ``aim``
    (``spot_angle`` None: no lamp)."""
    ids = {"camera": look_from(world, (0.0, 7.0, 4.0), (0.0, 0.0, 0.0))}
    world.spawn(Transform(), MeshRef(plane(16, 16)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
    if spot_angle is not None:
        ids["lamp"] = world.spawn(Transform(position=LAMP.tolist(), rotation=look_rotation(aim, (0.0, 0.0, -1.0))),
                                  PointLight(intensity=12.0, range=15.0, spot_angle=spot_angle, spot_blend=BLEND))
    world.resources["ids"] = ids
    return ids


def _floor_angles(runner, apex: np.ndarray, axis) -> np.ndarray:
    """Each pixel's floor point's angle (degrees) from ``axis`` seen from ``apex``."""
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    t = -eye[1] / rays[..., 1]
    points = eye + rays * t[..., None]
    to = points - apex
    to /= np.linalg.norm(to, axis=-1, keepdims=True)
    axis = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    return np.degrees(np.arccos(np.clip(to @ axis, -1.0, 1.0)))


def _frames(scene, aim=(0.0, -1.0, 0.0)):
    """The spot, the same lamp all round, and no lamp: three frames of one pose."""
    spot = scene(lambda w: _floor(w, ANGLE, aim))
    round_ = scene(lambda w: _floor(w, 180.0, aim))
    dark = scene(lambda w: _floor(w, None))
    return spot, spot.frame(), round_.frame(), dark.frame()


def _check_cone(spot_rgb, round_rgb, dark_rgb, angles) -> None:
    inside = angles < INNER - MARGIN
    outside = angles > ANGLE + MARGIN
    edge = (angles > INNER + MARGIN) & (angles < ANGLE - MARGIN)
    assert inside.sum() > 300 and outside.sum() > 3000 and edge.sum() > 100, (inside.sum(), outside.sum(), edge.sum())
    # The lamp lights the floor (not a black frame), and the spot as the lamp all round inside.
    assert srgb_to_linear(round_rgb[inside]).mean() > srgb_to_linear(dark_rgb[inside]).mean() + 0.2
    np.testing.assert_array_equal(spot_rgb[inside], round_rgb[inside])
    # Outside the cone: as though there were no lamp, though the lamp all round lights there.
    np.testing.assert_array_equal(spot_rgb[outside], dark_rgb[outside])
    assert (round_rgb[outside].astype(int) - dark_rgb[outside]).max() > 20
    # The edge fades: between the two, and strictly for most of it.
    s, r, d = (x[edge].astype(int) for x in (spot_rgb, round_rgb, dark_rgb))
    assert (s >= d - 1).all() and (s <= r + 1).all()
    assert ((s > d + 2) & (s < r - 2)).all(axis=-1).mean() > 0.6


def test_a_spot_lights_its_cone_as_the_lamp_all_round_and_nothing_outside(scene):
    """A lamp 3 m over the floor aimed straight down with a 30-degree cone, 0.2 of it a fading
    edge: inside 24 degrees of its axis each floor pixel is the lamp-all-round frame's, past 30
    the lamp-less frame's, and between them it fades from one to the other."""
    spot, spot_rgb, round_rgb, dark_rgb = _frames(scene)
    _check_cone(spot_rgb, round_rgb, dark_rgb, _floor_angles(spot, LAMP, (0.0, -1.0, 0.0)))


def test_turning_a_spot_moves_its_light(scene):
    """Turning the lamp's Transform (its position kept) aims the cone elsewhere, the next
    frame: the lit disc follows the new axis, as a scene made aimed that way draws it."""
    aim = (1.2, -3.0, 0.8)
    spot = scene(lambda w: _floor(w, ANGLE))
    spot.frame()
    lamp = spot.world.get(spot.world.resources["ids"]["lamp"], Transform)
    lamp.rotation = look_rotation(aim, (0.0, 0.0, -1.0))
    turned = spot.frame()
    _, _, round_rgb, dark_rgb = _frames(scene, aim)
    _check_cone(turned, round_rgb, dark_rgb, _floor_angles(spot, LAMP, aim))


# --- through a mirror ----------------------------------------------------------------------
# A mirror standing at z = 0 facing +z, 3 m wide and 2 m tall from the floor; the lamp in
# front of it at 2 m up, aimed down at the mirror so its reflected cone falls on the floor in
# front, away from where its own cone does.
MIRROR_HALF = np.array([1.5, 1.0])   # half width (x), half height (y)
MIRROR_CENTRE = np.array([0.0, 1.0, 0.0])
SPOT_LAMP = np.array([0.0, 2.0, 2.5])
SPOT_AIM = np.array([0.0, 1.0, 0.0]) - SPOT_LAMP   # at a point low on the mirror
MIRROR_ANGLE = 15.0


def _mirror_room(world, reflects: bool = True) -> None:
    look_from(world, (2.5, 4.0, 7.0), (0.0, 0.0, 2.5))
    world.spawn(Transform(), MeshRef(plane(16, 16)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
    world.spawn(Transform(position=MIRROR_CENTRE.tolist()), MeshRef(quad(2 * MIRROR_HALF[0], 2 * MIRROR_HALF[1])),
                Material(), Mirror(reflects_light=reflects))
    world.spawn(Transform(position=SPOT_LAMP.tolist(), rotation=look_rotation(SPOT_AIM.tolist())),
                PointLight(intensity=60.0, range=15.0, spot_angle=MIRROR_ANGLE, spot_blend=BLEND))


def test_a_spot_aimed_at_a_mirror_lights_the_floor_within_the_reflected_cone(scene):
    """The lamp's image behind the mirror (its position and axis reflected in z = 0, by hand)
    lights a floor point in front when the line to the image crosses the mirror and the
    point lies within the reflected cone: there the floor is brighter than with a mirror that
    carries no light; past the cone, or where the line misses the mirror, the same."""
    lit = scene(_mirror_room)
    unlit = scene(lambda w: _mirror_room(w, reflects=False))
    lit_rgb, unlit_rgb = lit.frame(), unlit.frame()
    eye, rays = pixel_rays(lit.engine.main_view, lit.size)
    t_floor = -eye[1] / rays[..., 1]
    t_mirror = -eye[2] / rays[..., 2]
    at_mirror = eye + rays * t_mirror[..., None]
    hides = (t_mirror > 0) & (t_mirror < t_floor) & (np.abs(at_mirror[..., 0]) < MIRROR_HALF[0] + 0.1) \
        & (at_mirror[..., 1] < 2 * MIRROR_HALF[1] + 0.1)
    points = eye + rays * t_floor[..., None]
    floor = ~hides & (points[..., 2] > 0.2)   # floor seen directly, in front of the mirror
    image = SPOT_LAMP * np.array([1.0, 1.0, -1.0])
    axis = SPOT_AIM * np.array([1.0, 1.0, -1.0])
    to_image = image - points
    s = points[..., 2] / -to_image[..., 2]   # where the line to the image meets z = 0
    crossing = points + to_image * s[..., None]
    margin = 0.08
    through = (np.abs(crossing[..., 0]) < MIRROR_HALF[0] - margin) & (crossing[..., 1] > margin) \
        & (crossing[..., 1] < 2 * MIRROR_HALF[1] - margin)
    missed = (np.abs(crossing[..., 0]) > MIRROR_HALF[0] + margin) | (crossing[..., 1] > 2 * MIRROR_HALF[1] + margin)
    angles = _floor_angles(lit, image, axis)
    inner = MIRROR_ANGLE * (1.0 - BLEND)
    # The lamp's own cone (the real axis) reaches none of these floor points.
    direct = _floor_angles(lit, SPOT_LAMP, SPOT_AIM)
    assert (direct[floor] > MIRROR_ANGLE + MARGIN).all()
    inside = floor & through & (angles < inner - MARGIN)
    outside = floor & (missed | (angles > MIRROR_ANGLE + MARGIN))
    assert inside.sum() > 150 and outside.sum() > 3000, (inside.sum(), outside.sum())
    brighter = srgb_to_linear(lit_rgb[inside]).mean(-1) > srgb_to_linear(unlit_rgb[inside]).mean(-1) + 0.03
    assert brighter.all(), brighter.mean()
    assert np.abs(lit_rgb[outside].astype(int) - unlit_rgb[outside]).max() <= 1
    assert lit.stats.virtual_lights == 1


def test_a_spot_aimed_away_from_a_mirror_makes_no_virtual_light(scene):
    """A spot whose cone cannot reach the mirror's outline makes no image (no map, no light),
    though a lamp all round there would."""
    def build(world, angle):
        _mirror_room(world)
        for _, (light, transform) in world.query(PointLight, Transform):
            transform.rotation = look_rotation((0.0, -1.0, 1.0))   # down and away from the mirror
            light.spot_angle = angle
    away = scene(lambda w: build(w, MIRROR_ANGLE))
    away.frame()
    assert away.stats.virtual_lights == 0
    round_ = scene(lambda w: build(w, 180.0))
    round_.frame()
    assert round_.stats.virtual_lights == 1


def test_a_spot_through_a_portal_lights_within_the_cone_the_pair_carries(scene):
    """A spot aimed into portal A (at z = 4, facing +z) shines out of portal B (at x = -6,
    facing +x): its image and its axis carried by the pair's transform (worked out here from
    the two portals' matrices) say which floor points beyond B it lights: brighter than with
    a portal that carries no light inside the carried inner cone, the same outside it."""
    lamp = np.array([0.0, 1.6, 6.0])
    aim = np.array([0.0, 0.9, 4.0]) - lamp

    def build(world):
        look_from(world, (-2.0, 6.0, 5.0), (-3.5, 0.0, 0.0))
        ids = world.resources["ids"] = {}
        ids["floor"] = world.spawn(Transform(), MeshRef(plane(20, 20)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
        world.spawn(Transform(position=lamp.tolist(), rotation=look_rotation(aim.tolist())),
                    PointLight(intensity=40.0, range=14.0, spot_angle=MIRROR_ANGLE, spot_blend=BLEND))
        ids["a"], ids["b"] = spawn_portal_pair(world, (0.0, 1.5, 4.0), None, (-6.0, 1.5, 0.0),
                                               look_rotation(glm.vec3(-1, 0, 0)))

    runner = scene(build, (240, 180))
    ids = runner.world.resources["ids"]
    portal = runner.world.get(ids["a"], Portal)
    off = runner.frame()
    portal.carries_light = True
    on = runner.frame()
    assert runner.stats.virtual_lights == 1
    carry = np.array(glm.dmat4(pair_transform(runner.world.get(ids["a"], Transform).world,
                                              runner.world.get(ids["b"], Transform).world)).to_list()).T
    image = carry[:3, :3] @ lamp + carry[:3, 3]
    axis = carry[:3, :3] @ aim
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    points = eye + rays * (-eye[1] / rays[..., 1])[..., None]
    seen = runner.ids() == ids["floor"]
    to_image = image - points
    t = (-6.0 - points[..., 0]) / to_image[..., 0]   # where the line to the image meets B's plane
    crossing = points + to_image * t[..., None]
    margin = 0.08
    through = (points[..., 0] > -6.0) & (t > 0) & (t < 1) & (np.abs(crossing[..., 1] - 1.5) < 1.5 - margin) \
        & (np.abs(crossing[..., 2]) < 1.0 - margin)
    angles = _floor_angles(runner, image, axis)
    inner = MIRROR_ANGLE * (1.0 - BLEND)
    # The floor in front of B seen directly: the camera sees the floor behind A (x near 0)
    # through A's opening, i.e. out of B, where these rays do not go.
    floor = seen & (points[..., 0] > -5.8) & (points[..., 0] < -1.5)
    inside = floor & through & (angles < inner - MARGIN)
    outside = floor & (angles > MIRROR_ANGLE + MARGIN)
    assert inside.sum() > 150 and outside.sum() > 2000, (inside.sum(), outside.sum())
    brighter = srgb_to_linear(on[inside]).mean(-1) > srgb_to_linear(off[inside]).mean(-1) + 0.03
    assert brighter.all(), brighter.mean()
    assert np.abs(on[outside].astype(int) - off[outside]).max() <= 1


# --- the shadow cube -----------------------------------------------------------------------
def _shadowed(world, spot_angle: float | None, aim, target, crate: bool = True) -> None:
    """``_floor`` looked at ``target``, the lamp casting shadows, a crate in its light
    between it and the floor (``crate``)."""
    look_from(world, (target[0], 7.0, target[2] + 4.0), target)
    world.spawn(Transform(), MeshRef(plane(16, 16)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
    if crate:
        toward = np.asarray(aim, np.float64) / np.linalg.norm(aim)
        centre = LAMP + toward * (1.6 / -toward[1])    # on the axis, 1.4 m over the floor
        world.spawn(Transform(position=centre.tolist()), MeshRef(box((0.5, 0.5, 0.5))), Material(color=(0.6, 0.5, 0.4)))
    world.spawn(Transform(position=LAMP.tolist(), rotation=look_rotation(aim, (0.0, 0.0, -1.0))),
                PointLight(intensity=12.0, range=15.0, spot_angle=spot_angle, spot_blend=BLEND, shadows=True,
                           shadow_resolution=256))


WIDE = 50.0   # degrees: past SPOT_MAP_MAX_ANGLE, a spot that casts from its cube


@pytest.mark.parametrize("aim, target, faces", [((0.0, -1.0, 0.0), (0.0, 0.0, 0.0), 5),
                                                ((1.0, -1.0, 1.0), (2.0, 0.0, 2.0), 3)],
                         ids=["down", "corner"])
def test_a_wide_spots_shadow_cube_draws_only_the_faces_its_cone_lights(scene, aim, target, faces):
    """A 50-degree spot casting shadows (too wide for a map of its own) draws five cube faces
    aimed straight down (all but the one looking up), three aimed at a cube corner (the
    faces its cone meets), not six; inside its cone the frame, the crate's shadow in it, is
    the frame of the same lamp all round, whose cube has all six."""
    spot = scene(lambda w: _shadowed(w, WIDE, aim, target))
    round_ = scene(lambda w: _shadowed(w, 180.0, aim, target))
    bare = scene(lambda w: _shadowed(w, WIDE, aim, target, crate=False))
    spot_rgb, round_rgb, bare_rgb = spot.frame(), round_.frame(), bare.frame()
    assert spot.stats.shadow_faces_drawn == faces and round_.stats.shadow_faces_drawn == 6
    assert f"shadow maps 1 ({faces} cube faces) + " in "\n".join(overlay_lines(spot.engine, [1 / 60]))
    inside = _floor_angles(spot, LAMP, aim) < WIDE * (1.0 - BLEND) - MARGIN
    np.testing.assert_array_equal(spot_rgb[inside], round_rgb[inside])
    # The crate's shadow is there (darker than the floor without it) where the cone lights.
    darker = srgb_to_linear(spot_rgb[inside]).mean(-1) < 0.5 * srgb_to_linear(bare_rgb[inside]).mean(-1)
    assert darker.sum() > 50, darker.sum()
    spot.frame()
    assert spot.stats.shadow_faces_drawn == 0   # nothing moved: the cube is kept
    assert "shadow maps 0 + 1 kept" in "\n".join(overlay_lines(spot.engine, [1 / 60]))


def test_cube_faces_lit_holds_every_face_a_direction_in_the_cone_falls_on():
    """Directions drawn inside random cones (to their very edge): the cube face each falls on
    (its largest component's axis, the GL's face selection) is always among the faces lit."""
    rng = np.random.default_rng(5)
    axes = [face.forward for face in CUBE_FACES]
    for _ in range(300):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = float(rng.uniform(0.5, 179.0))
        lit = cube_faces_lit(spot_cone(axis, angle, 0.2), axes)
        side = np.cross(axis, rng.normal(size=(400, 3)))
        side /= np.linalg.norm(side, axis=1, keepdims=True)
        theta = np.radians(angle * np.sqrt(rng.uniform(0.0, 1.0, 400)))
        theta[:40] = math.radians(angle)   # on the edge itself
        d = axis * np.cos(theta)[:, None] + side * np.sin(theta)[:, None]
        major = np.abs(d).argmax(axis=1)
        face = 2 * major + (d[np.arange(len(d)), major] < 0)
        assert all(lit[f] for f in set(face.tolist())), (axis, angle, lit)
    assert cube_faces_lit(spot_cone((0.0, -1.0, 0.0), 30.0, 0.2), axes) == (False, False, False, True, False, False)
    assert cube_faces_lit(ALL_ROUND, axes) == (True,) * 6


# --- the spot's map ---------------------------------------------------------------------------
# A crate turned about the vertical, 1.4 m under a lamp aimed straight down: its shadow's
# slanted edges show a map's texels as steps.
CRATE_DROP = 1.4   # metres under the lamp
CRATE_HALF = np.array([0.1, 0.1, 0.1])
CRATE_TURN = 0.5   # radians about +y
NARROW = 20.0   # degrees: the spot's cone
RESOLUTION = 128   # its shadow map's (a cube face's) texels a side
DOWN = (0.0, -1.0, 0.0)


def _crates_under_spots(world, spot_angle: float, lamps=(LAMP,), resolutions=(RESOLUTION,), crates: bool = True,
                        eye=(0.0, 3.6, 1.4)) -> None:
    """A floor, and over it lamps aimed straight down casting shadows (``lamps``, each
    ``spot_angle`` and a resolution of ``resolutions``), a crate under each (``crates``)."""
    look_from(world, eye, (float(np.mean([p[0] for p in lamps])), 0.0, 0.0))
    world.resources["floor"] = world.spawn(Transform(), MeshRef(plane(16, 16)),
                                           Material(color=(0.8, 0.8, 0.8), roughness=1.0))
    world.resources["lamps"] = []
    for lamp, resolution in zip(lamps, resolutions, strict=True):
        if crates:
            world.spawn(Transform(position=(lamp[0], lamp[1] - CRATE_DROP, lamp[2]),
                                  rotation=glm.angleAxis(CRATE_TURN, glm.vec3(0.0, 1.0, 0.0))),
                        MeshRef(box(tuple(2.0 * CRATE_HALF))), Material(color=(0.6, 0.5, 0.4)))
        world.resources["lamps"].append(world.spawn(
            Transform(position=tuple(lamp), rotation=look_rotation(DOWN, (0.0, 0.0, -1.0))),
            PointLight(intensity=12.0, range=15.0, spot_angle=spot_angle, spot_blend=0.2, shadows=True,
                       shadow_resolution=resolution)))


def _crate_under_spot(world, spot_angle: float = NARROW, crate: bool = True) -> None:
    _crates_under_spots(world, spot_angle, crates=crate)


def _crate_shadow(runner, lamp=LAMP) -> np.ndarray:
    """Whether each pixel's floor point is in the shadow of the crate under ``lamp``: its
    segment to the lamp meets the crate (ray cast in the crate's frame, float64)."""
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    points = (eye + rays * (-eye[1] / rays[..., 1])[..., None]).reshape(-1, 3)
    c, s = math.cos(CRATE_TURN), math.sin(CRATE_TURN)
    to_crate = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])   # the turn undone
    local = (points - (lamp - (0.0, CRATE_DROP, 0.0))) @ to_crate.T
    towards = (lamp - points) @ to_crate.T
    return box_hits(local, towards, np.zeros(3), CRATE_HALF, limit=np.ones(len(points))).reshape(runner.size[::-1])


def _misplaced(runner, frame, bare, lamp=LAMP) -> tuple[int, int]:
    """(pixels shaded against the ray cast, pixels judged) inside the full light of the spot
    at ``lamp``, a pixel either side of the cast shadow's edge left out."""
    cast = _crate_shadow(runner, lamp)
    near_edge = np.zeros_like(cast)
    for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        near_edge |= cast != np.roll(cast, (dy, dx), axis=(0, 1))
    judged = (_floor_angles(runner, lamp, DOWN) < NARROW * (1.0 - 0.2) - MARGIN) & ~near_edge \
        & (runner.ids() == runner.world.resources["floor"])   # the floor itself, not the crate before it
    dark = srgb_to_linear(frame).mean(-1) < 0.5 * srgb_to_linear(bare).mean(-1)
    return int((dark != cast)[judged].sum()), int(judged.sum())


def test_a_narrow_spot_casts_from_a_map_fitted_to_its_cone_sharper_than_the_cube(scene, monkeypatch):
    """A 20-degree spot (within ``SPOT_MAP_MAX_ANGLE``) draws one perspective map, no cube
    face, and the crate's shadow on the floor lies where a ray cast from each pixel's floor
    point to the lamp meets the crate, to the pixel (its texels are 1.8 cm on the floor,
    two pixels).  The same lamp made to cast from its cube (the limit set to 0) at the
    same resolution draws one face, and its shadow's slanted edges step a cube texel (4.7 cm,
    five pixels) across the cast one."""
    import engine.rules.light_rules as light_rules

    def misplaced():
        spot = scene(lambda w: _crate_under_spot(w, NARROW), (640, 480))
        bare = scene(lambda w: _crate_under_spot(w, NARROW, crate=False), (640, 480))
        frame = spot.frame()
        return spot, _misplaced(spot, frame, bare.frame())

    spot, (wrong, judged) = misplaced()
    assert spot.stats.shadow_path == "spot_map" and spot.stats.shadow_faces_drawn == 0
    assert judged > 10000 and _crate_shadow(spot).sum() > 2000   # the crate's shadow is in the judged light
    assert wrong <= 0.0005 * judged, wrong
    monkeypatch.setattr(light_rules, "SPOT_MAP_MAX_ANGLE", 0.0)
    cube, (cube_wrong, _) = misplaced()
    assert cube.stats.shadow_path != "spot_map" and cube.stats.shadow_faces_drawn == 1
    assert cube_wrong >= 40, cube_wrong


def test_two_spots_with_maps_of_two_sizes_each_cast_their_own_crates_shadow(scene):
    """Both shadow slots hold spot maps (128 and 256 texels: the atlas's tiles are the larger
    and a border, side by side): under each lamp its crate's shadow lies where the ray cast
    puts it."""
    from engine.render.shadows import SPOT_GUTTER

    lamps = (np.array([-1.5, 3.0, 0.0]), np.array([1.5, 3.0, 0.0]))

    def build(crates):
        return lambda w: _crates_under_spots(w, NARROW, lamps, (128, 256), crates, eye=(0.0, 5.5, 2.5))

    runner, bare = scene(build(True), (640, 480)), scene(build(False), (640, 480))
    frame, bare_frame = runner.frame(), bare.frame()
    maps = runner.engine.renderer.shadows
    side = 256 + 2 * SPOT_GUTTER
    assert maps.spot_atlas.size == (2 * side, side) and not maps.cubes
    assert {("SPOT_MAP0", "1"), ("SPOT_MAP1", "1")} <= set(maps.program_defines)
    for lamp in lamps:
        wrong, judged = _misplaced(runner, frame, bare_frame, lamp)
        assert judged > 2000 and _crate_shadow(runner, lamp).sum() > 300
        assert wrong <= 0.001 * judged, (lamp, wrong)


def test_a_spot_map_is_kept_while_still_drawn_again_when_turned_and_freed_when_the_spot_goes(scene):
    """Still: the map is kept (nothing drawn).  Turned: drawn again, the frame a fresh
    engine's aimed that way.  Widened past the limit: the cube takes over and the atlas is
    released, the frame a fresh engine's; narrowed again, back to a map.  Its shadows off,
    or the lamp deleted: no atlas, no cube left."""
    runner = scene(_crate_under_spot, (320, 240))
    runner.frame()
    maps = runner.engine.renderer.shadows
    assert maps.spot_atlas is not None and runner.stats.shadow_maps_drawn == 1
    runner.frame()
    assert runner.stats.shadow_maps_drawn == 0 and runner.stats.shadow_maps_kept == 1
    lamp_id = runner.world.resources["lamps"][0]
    aim = (0.3, -1.0, 0.1)
    runner.world.get(lamp_id, Transform).rotation = look_rotation(aim, (0.0, 0.0, -1.0))
    turned = runner.frame()
    assert runner.stats.shadow_maps_drawn == 1 and runner.stats.shadow_path == "spot_map"

    def aimed(world):
        _crate_under_spot(world, NARROW)
        world.get(world.resources["lamps"][0], Transform).rotation = look_rotation(aim, (0.0, 0.0, -1.0))
    np.testing.assert_array_equal(turned, scene(aimed, (320, 240)).frame())
    light = runner.world.get(lamp_id, PointLight)
    light.spot_angle = WIDE
    wide = runner.frame()
    assert maps.spot_atlas is None and set(maps.cubes) == {0} and runner.stats.shadow_faces_drawn > 0
    assert not any(name.startswith("SPOT_MAP") for name, _ in maps.program_defines)

    def widened(world):
        aimed(world)
        world.get(world.resources["lamps"][0], PointLight).spot_angle = WIDE
    np.testing.assert_array_equal(wide, scene(widened, (320, 240)).frame())
    light.spot_angle = NARROW
    runner.frame()
    assert maps.spot_atlas is not None and not maps.cubes
    light.shadows = False
    runner.frame()
    assert maps.spot_atlas is None and not maps.cubes
    light.shadows = True
    runner.frame()
    assert maps.spot_atlas is not None
    assert runner.engine.renderer.resource_counts()["spot_atlases"] == 1
    runner.world.delete_entity(lamp_id)
    runner.frame()
    assert maps.spot_atlas is None and not maps.cubes
    assert runner.engine.renderer.resource_counts()["spot_atlases"] == 0


def test_a_narrow_spots_image_through_a_mirror_has_its_map_fitted_to_the_cone(scene, monkeypatch):
    """A 6-degree spot aimed at a wide mirror: its image's shadow camera looks along the
    carried axis and spans the cone, not the whole outline (a texel several times narrower),
    and every direction within the cone lands inside the map; a 42-degree one (its cone wider
    than the outline seen from the image) keeps the outline's camera.  In the frame, the
    crate's shadow in the reflected light lies where a ray cast from each floor point to the
    lamp's image, through the mirror, meets the crate."""
    from engine.render.shadows import VIRTUAL_RESOLUTION
    from engine.rules import shadow_rules

    lamp, aim_at = np.array([0.0, 2.6, 3.0]), np.array([0.0, 1.3, 0.0])
    crate = np.array([0.0, 0.45, 2.1])

    def build(angle):
        def run(world):
            look_from(world, (1.0, 2.0, 4.2), (0.0, 0.0, 2.6))
            world.resources["floor"] = world.spawn(Transform(), MeshRef(plane(16, 16)),
                                                   Material(color=(0.8, 0.8, 0.8), roughness=1.0))
            world.spawn(Transform(position=(0.0, 1.5, 0.0)), MeshRef(quad(4.0, 3.0)), Material(),
                        Mirror(reflects_light=True))
            world.spawn(Transform(position=crate.tolist()), MeshRef(box((0.1, 0.1, 0.1))),
                        Material(color=(0.6, 0.5, 0.4)))
            world.spawn(Transform(position=lamp.tolist(), rotation=look_rotation((aim_at - lamp).tolist())),
                        PointLight(intensity=30.0, range=12.0, spot_angle=angle, spot_blend=0.1, shadows=True))
        return run

    fits = []
    original = shadow_rules.virtual_shadow_camera

    def spy(light, lo, hi, resolution):
        fit = original(light, lo, hi, resolution)
        fits.append((light, fit))
        return fit
    monkeypatch.setattr("systems.shadow_system.virtual_shadow_camera", spy)
    narrow = scene(build(6.0), (480, 360))
    frame = narrow.frame()
    light, fit = fits[-1]
    assert light.cone != ALL_ROUND
    axis, _ = shadow_rules.opened_cone(light.cone)
    image = np.array(light.position)
    assert fit.texel == pytest.approx(2.0 * np.tan(np.radians(6.0)) / (1.0 - 8.0 / VIRTUAL_RESOLUTION)
                                      / VIRTUAL_RESOLUTION, rel=1e-6)
    # Directions within the cone (to its edge) land inside the map's square.
    rng = np.random.default_rng(3)
    side = np.cross(axis, rng.normal(size=(300, 3)))
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    theta = np.radians(6.0 * np.sqrt(rng.uniform(0.0, 1.0, 300)))
    theta[:30] = np.radians(6.0)
    points = image + 5.0 * (axis * np.cos(theta)[:, None] + side * np.sin(theta)[:, None])
    clip = np.column_stack([points, np.ones(len(points))]) @ np.array(glm.dmat4(fit.view_proj).to_list())
    ndc = clip[:, :2] / clip[:, 3:]
    assert (np.abs(ndc) < 1.0).all(), np.abs(ndc).max()
    outline_fit = original(dataclasses.replace(light, cone=ALL_ROUND), np.zeros(3), np.ones(3), VIRTUAL_RESOLUTION)
    assert outline_fit.texel > 3.0 * fit.texel
    # The frame: the crate's shadow where the ray cast through the mirror puts it.
    eye, rays = pixel_rays(narrow.engine.main_view, narrow.size)
    floor_points = (eye + rays * (-eye[1] / rays[..., 1])[..., None]).reshape(-1, 3)
    to_image = image - floor_points
    t = -floor_points[:, 2] / to_image[:, 2]   # where the line to the image meets the mirror (z = 0)
    cast = box_hits(floor_points, to_image, crate, np.full(3, 0.05), limit=t).reshape(narrow.size[::-1])
    lit_share = shadow_rules.spot_factor(light.cone, to_image / np.linalg.norm(to_image, axis=1, keepdims=True))
    near_edge = np.zeros_like(cast)
    for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (-1, -1), (1, -1), (-1, 1)):
        near_edge |= cast != np.roll(cast, (dy, dx), axis=(0, 1))
    judged = (lit_share.reshape(cast.shape) > 0.99) & ~near_edge & (narrow.ids() == narrow.world.resources["floor"])
    bare = scene(lambda w: (build(6.0)(w), w.delete_entity(w.query_one(MeshRef)[2][0])), (480, 360))
    assert judged.sum() > 1500 and cast[judged].sum() > 100, (judged.sum(), cast[judged].sum())
    dark = srgb_to_linear(frame).mean(-1) < 0.6 * srgb_to_linear(bare.frame()).mean(-1)
    wrong = (dark != cast)[judged].sum()
    assert wrong <= 0.002 * judged.sum(), wrong
    fits.clear()
    scene(build(42.0), (160, 120)).frame()
    wide_light, wide_fit = fits[-1]
    assert wide_fit.texel == pytest.approx(
        original(dataclasses.replace(wide_light, cone=ALL_ROUND), np.zeros(3), np.ones(3), VIRTUAL_RESOLUTION).texel)


# --- the editor's outline ---------------------------------------------------------------------
def test_the_editors_outline_of_a_spot_is_its_cone_and_of_a_lamp_its_range(scene):
    """``reach_outline``: a spot's far circle lies ``range`` from the apex at ``spot_angle``
    from its axis all round, its edges run from the apex to that circle; a light all round
    shows three circles of its range about it; each point on screen where the view puts it."""
    from shell.handles import CONE_EDGES, reach_outline, screen_point

    spot = scene(lambda w: _floor(w, ANGLE))
    spot.frame()
    lamp = spot.world.resources["ids"]["lamp"]
    view, size = spot.engine.main_view, spot.size
    outline = reach_outline(spot.world, lamp, view.view_proj, size)
    circle, *edges = outline.world
    assert len(edges) == CONE_EDGES and len(outline.lines) == 1 + CONE_EDGES
    to = np.array([list(p) for p in circle]) - LAMP
    np.testing.assert_allclose(np.linalg.norm(to, axis=1), 15.0, rtol=1e-5)    # the lamp's range
    angles = np.degrees(np.arccos(to @ np.array([0.0, -1.0, 0.0]) / np.linalg.norm(to, axis=1)))
    np.testing.assert_allclose(angles, ANGLE, atol=1e-3)
    assert all(np.allclose(list(a), LAMP, atol=1e-5) and any(b == c for c in circle) for a, b in edges)
    for line, points in zip(outline.lines, outline.world, strict=True):
        assert line == tuple(screen_point(view.view_proj, size, p) for p in points)
    assert reach_outline(spot.world, spot.world.resources["ids"]["camera"], view.view_proj, size) is None
    light = spot.world.get(lamp, PointLight)
    light.spot_angle, light.range = 180.0, 2.0
    rings = reach_outline(spot.world, lamp, view.view_proj, size).world
    assert len(rings) == 3
    for ring in rings:
        np.testing.assert_allclose(np.linalg.norm(np.array([list(p) for p in ring]) - LAMP, axis=1), 2.0, rtol=1e-5)
    light.range = 15.0   # a sphere reaching behind the eye: those circles are left out, not drawn wrong
    assert len(reach_outline(spot.world, lamp, view.view_proj, size).world) < 3


def test_the_editors_outline_of_a_sun_is_an_arrow_the_way_its_light_goes(scene):
    """A sun has no place: its outline is an arrow from the middle of the view, 5 m ahead of
    the eye, along its direction (a shaft and four barbs at its tip)."""
    from components import DirectionalLight
    from shell.handles import SUN_ARROW_AHEAD, SUN_ARROW_LENGTH, reach_outline, screen_point

    runner = scene(lambda w: _floor(w, None))
    sun = runner.world.spawn(DirectionalLight(direction=(0.3, -1.0, -0.4)))
    runner.frame()
    view, size = runner.engine.main_view, runner.size
    shaft, *barbs = reach_outline(runner.world, sun, view.view_proj, size).world
    start, tip = (np.array(list(p)) for p in shaft)
    direction = np.array([0.3, -1.0, -0.4]) / np.linalg.norm([0.3, -1.0, -0.4])
    np.testing.assert_allclose((tip - start) / SUN_ARROW_LENGTH, direction, atol=1e-5)
    np.testing.assert_allclose(np.linalg.norm(start - np.array(list(view.eye))), SUN_ARROW_AHEAD, rtol=1e-4)
    np.testing.assert_allclose(screen_point(view.view_proj, size, glm.vec3(*start)), (size[0] / 2, size[1] / 2),
                               atol=1e-3)
    assert len(barbs) == 4 and all(np.allclose(list(b[0]), tip) for b in barbs)


# --- the rule -------------------------------------------------------------------------------
def test_the_glsl_cone_is_the_rules(ctx, tmp_path):
    """``spot_factor`` in spot_cone.glsl gives light_rules' ``spot_factor`` for cones of
    every width and blend, all round included, at directions all over the sphere."""
    rng = np.random.default_rng(11)
    cones, directions = [], []
    for angle in (0.1, 5.0, 30.0, 89.0, 90.0, 120.0, 179.0, 180.0):
        for blend in (0.0, 0.15, 1.0):
            axis = rng.normal(size=3)
            cone = spot_cone(axis, angle, blend)
            for _ in range(24):
                # Directions near the cone's edge as well as anywhere.
                d = rng.normal(size=3)
                if rng.random() < 0.5 and angle < 180.0:
                    a = axis / np.linalg.norm(axis)
                    side = np.cross(a, d)
                    side /= np.linalg.norm(side)
                    theta = math.radians(angle * rng.uniform(1.0 - blend - 0.05, 1.05))
                    d = a * math.cos(theta) + side * math.sin(theta)
                cones.append(cone)
                directions.append(-d / np.linalg.norm(d))   # from the point to the light
    cones, directions = np.array(cones), np.array(directions)
    owner = np.array([spot_factor(c, d) for c, d in zip(cones, directions, strict=True)])
    glsl = _evaluate_pairs(ctx, tmp_path, cones, directions)
    np.testing.assert_allclose(glsl, owner, atol=2e-4)
    assert spot_cone((0.0, -1.0, 0.0), 180.0, 0.5) == ALL_ROUND
    assert (owner == 0.0).any() and (owner == 1.0).any() and ((owner > 0.01) & (owner < 0.99)).any()


def _evaluate_pairs(ctx, tmp_path, cones: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """spot_factor(cone, l) in GLSL for each row: the cones and the directions interleaved as
    two texels a row (the evaluator's input is a row of texels; texel 2i the cone, 2i + 1 l)."""
    inputs = np.empty((2 * len(cones), 4))
    inputs[0::2] = cones
    inputs[1::2, :3] = directions
    inputs[1::2, 3] = 0.0
    body = ("ivec2 at = ivec2(gl_FragCoord.xy); int i = at.x - at.x % 2;"
            " vec4 cone = texelFetch(inputs, ivec2(i, 0), 0);"
            " vec3 l = texelFetch(inputs, ivec2(i + 1, 0), 0).xyz;"
            " color = vec4(spot_factor(cone, l));")
    out = evaluate_glsl(ctx, tmp_path / "pairs", ["spot_cone.glsl"], body, inputs)
    return out[0::2, 0]


def test_cone_reaches_rules_out_only_what_the_cone_misses():
    """``cone_reaches``: a ball straight ahead, one just past the edge by less than its
    radius (reached), one well outside (not), one holding the apex (reached)."""
    cone = spot_cone((0.0, 0.0, -1.0), 20.0, 0.1)
    assert cone_reaches(cone, (0, 0, 0), (0, 0, -5), 0.5)
    edge = np.array([math.sin(math.radians(22.0)), 0.0, -math.cos(math.radians(22.0))]) * 5.0
    assert cone_reaches(cone, (0, 0, 0), edge, 0.5)       # 2 degrees past, the ball 5.7 degrees wide
    assert not cone_reaches(cone, (0, 0, 0), edge * np.array([3.0, 1.0, 1.0]), 0.5)
    assert not cone_reaches(cone, (0, 0, 0), (0, 0, 5), 0.5)
    assert cone_reaches(cone, (0, 0, 0), (0, 0, 0.3), 0.5)
    assert cone_reaches(ALL_ROUND, (0, 0, 0), (0, 0, 5), 0.5)


# --- values -------------------------------------------------------------------------------
@pytest.mark.parametrize("field, value", [("spot_angle", 0.0), ("spot_angle", 0.05), ("spot_angle", 180.5),
                                          ("spot_angle", float("nan")), ("spot_angle", "wide"),
                                          ("spot_blend", -0.1), ("spot_blend", 1.5), ("spot_blend", float("inf"))])
def test_a_cone_past_its_limits_is_refused_naming_the_field(field, value):
    with pytest.raises(ComponentValueError, match=f"PointLight.{field}"):
        PointLight(**{field: value})
    light = PointLight()
    with pytest.raises(ComponentValueError, match=f"PointLight.{field}"):
        setattr(light, field, value)


def test_level_files_carry_the_cone(tmp_path):
    """A level's PointLight takes spot_angle and spot_blend, and refuses a bad one naming the
    file, the entity and the field."""
    text = """[level]
name = "A torch"

[[entity]]
name = "torch"
[entity.Transform]
position = [0.0, 3.0, 0.0]
rotation = { yaw = 0, pitch = -90 }
[entity.PointLight]
spot_angle = 40.0
spot_blend = 0.3
"""
    path = tmp_path / "spot.toml"
    path.write_text(text)
    world = World("spot")
    made = load_level(path).spawn(world)
    light = world.get(made["torch"], PointLight)
    assert (light.spot_angle, light.spot_blend) == (40.0, 0.3)
    transform = world.get(made["torch"], Transform)
    cone = lamp_cone(light, glm.mat4_cast(transform.rotation))   # pitched down: it shines down
    np.testing.assert_allclose(np.array(cone[:3]) / np.linalg.norm(cone[:3]), (0.0, -1.0, 0.0), atol=1e-6)
    path.write_text(text.replace("40.0", "200.0"))
    with pytest.raises(LevelError, match=r"PointLight\.spot_angle") as caught:
        load_level(path).spawn(World("refused"))
    assert str(path) in str(caught.value) and caught.value.entity == "torch"
