"""Mirror fades (issue 27 item 2): a distance and an angle fade, off by default.  The weight
is checked against its formula (linear from start to end, the product of the two, from each
view's own eye), the image against a second path (a mirror without fades whose reflect rate
is the faded weight), and a fully faded mirror against the counters of no mirror at all."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from benchmarks.mirrors import MirrorRing
from components import ComponentValueError, DirectionalLight, Emissive, Material, MeshRef, Mirror, Transform
from engine.assets.level_file import LevelError, load_level
from engine.assets.mesh import box, quad
from engine.assets.portals import spawn_portal_pair
from engine.core.world import World
from tests.support import SceneRunner, linear_to_srgb8, look_from, srgb_to_linear

MIRROR_AT = glm.vec3(0.0, 1.5, -2.0)
HALF = 0.6  # the mirror is 1.2 x 1.2


def _room(mirror: Mirror, eye):
    """A mirror on a wall facing the camera at ``eye``, and a red glowing panel behind the
    camera for it to reflect; the mirror's own material is dark blue."""
    def build(world: World) -> None:
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=1.0))
        look_from(world, eye, target=MIRROR_AT, fov=50.0)
        world.spawn(Transform(position=MIRROR_AT), MeshRef(quad(2 * HALF, 2 * HALF)),
                    Material(color=(0.05, 0.1, 0.6)), mirror)
        world.spawn(Transform(position=(0.0, 1.5, 14.0), scale=(60, 30, 0.1)), MeshRef(box()),
                    Material(color=(0.9, 0.1, 0.1)), Emissive(1.0))
    return build


def _expected_weight(eye, distance=None, angle=None) -> float:
    """The fades' formula, worked out here from the mirror's geometry: distance to the
    mirror's bounding sphere, angle between its normal (+Z) and the direction to the eye."""
    eye = glm.vec3(eye)
    to_eye = eye - MIRROR_AT
    weight = 1.0
    if distance is not None:
        d = max(glm.length(to_eye) - math.sqrt(2.0) * HALF, 0.0)
        weight *= min(max((distance[1] - d) / (distance[1] - distance[0]), 0.0), 1.0)
    if angle is not None:
        a = math.degrees(math.acos(glm.dot(glm.normalize(to_eye), glm.vec3(0, 0, 1))))
        weight *= min(max((angle[1] - a) / (angle[1] - angle[0]), 0.0), 1.0)
    return weight


def _mirror_pixels(ctx, mirror: Mirror, eye) -> tuple[np.ndarray, SceneRunner]:
    runner = SceneRunner(ctx, _room(mirror, eye), (160, 120))
    image = runner.frame()
    x, y = runner.project(MIRROR_AT)
    return image[y - 6:y + 6, x - 6:x + 6].reshape(-1, 3).astype(float), runner


@pytest.mark.parametrize("eye, fades", [
    ((0.0, 1.5, 4.0), {"fade_distance": (3.0, 8.0)}),                      # halfway down the distance fade
    ((3.2, 1.5, 1.2), {"fade_angle": (20.0, 60.0)}),                       # seen at ~48 degrees
    ((2.0, 1.5, 3.0), {"fade_distance": (2.0, 9.0), "fade_angle": (10.0, 70.0)}),  # both at once
])
def test_a_partly_faded_mirror_shows_its_reflection_at_the_faded_weight(ctx, eye, fades):
    weight = _expected_weight(eye, fades.get("fade_distance"), fades.get("fade_angle"))
    assert 0.15 < weight < 0.85, f"the case should sit inside its fade, got weight {weight}"
    faded, runner = _mirror_pixels(ctx, Mirror(reflect_rate=0.9, **fades), eye)
    (view,) = runner.engine.reflection_system.views[1:]
    assert view.fade == pytest.approx(weight, abs=1e-6)
    runner.close()
    # The second path: the mirror unfaded and switched off (its fallback, the sky's
    # reflection: issue 36), mixed by the weight in linear light: the faded share of the
    # reflection is the fallback's, not the mirror's own shading.
    off, runner = _mirror_pixels(ctx, Mirror(reflect_rate=0.9, enabled=False), eye)
    runner.close()
    unfaded, runner = _mirror_pixels(ctx, Mirror(reflect_rate=0.9), eye)
    runner.close()
    second = linear_to_srgb8(weight * srgb_to_linear(unfaded) + (1.0 - weight) * srgb_to_linear(off))
    assert np.abs(faded - second).max() <= 2.0
    assert faded[:, 0].mean() < unfaded[:, 0].mean() - 20.0  # less of the red panel than unfaded


def test_a_mirror_past_its_fades_costs_no_view_and_shows_its_fallback(ctx):
    """Past its fades a mirror costs no view and shows its fallback (the sky's reflection,
    issue 36), as a mirror switched off does, not its own dark blue."""
    eye = (0.0, 1.5, 4.0)
    faded, runner = _mirror_pixels(ctx, Mirror(fade_distance=(1.0, 3.0)), eye)  # 6 m away, past 3
    stats = runner.engine.renderer.stats
    assert stats.reflection_views == 0 and stats.reflection_views_faded == 1
    assert stats.reflection_fallbacks == 1
    passes, draws = stats.passes, stats.draw_calls
    runner.close()
    plain, runner = _mirror_pixels(ctx, Mirror(enabled=False), eye)
    assert (runner.stats.passes, runner.stats.draw_calls) == (passes, draws)
    runner.close()
    assert np.abs(faded - plain).max() <= 1.0
    material, runner = _mirror_pixels(ctx, Mirror(reflect_rate=0.0), eye)  # the mirror's own shading
    runner.close()
    assert np.abs(faded - material).max(axis=1).mean() > 20.0


def test_every_mirror_faded_out_costs_what_no_mirror_costs(ctx):
    """The 8-mirror benchmark ring with every mirror faded: no view, and the passes and draws
    of the same ring with its mirrors switched off (the frame's cost is the benchmark's,
    ``python -m benchmarks mirrors --faded``)."""
    counts = {}
    for case in ("faded", "off"):
        game = MirrorRing(8)
        runner = SceneRunner(ctx, game.build, (160, 90))
        runner.engine.game = game
        for _, mirror in runner.world.query_one(Mirror):
            if case == "faded":
                mirror.fade_distance = (0.0, 0.5)
            else:
                mirror.enabled = False
        runner.frame()
        stats = runner.stats
        counts[case] = (stats.reflection_views, stats.passes, stats.draw_calls)
        if case == "faded":
            assert stats.reflection_views_faded >= 4
        runner.close()
    assert counts["faded"] == counts["off"] and counts["faded"][0] == 0


def test_a_mirror_seen_in_a_mirror_fades_by_the_reflected_eye(ctx):
    """Two mirrors side by side facing a third, all with a distance fade: each view's weight
    is the formula from its own parent's eye (a reflected eye from the second level on, one
    per mirror it was seen in), not the camera's."""
    def build(world: World) -> None:
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=1.0))
        look_from(world, (0.5, 1.5, 0.5), target=(0.0, 1.5, -3.0), fov=80.0)
        for x, z, turn in ((-1.3, -3.0, 0.0), (1.3, -4.0, 0.0), (0.0, 3.0, math.pi)):
            world.spawn(Transform(position=(x, 1.5, z), rotation=glm.angleAxis(turn, glm.vec3(0, 1, 0))),
                        MeshRef(quad(2.4, 2.0)), Material(color=(0.2, 0.2, 0.2)),
                        Mirror(fade_distance=(2.0, 16.0), max_depth=3))
    runner = SceneRunner(ctx, build, (160, 120))
    runner.frame()
    views = runner.engine.reflection_system.views[1:]
    assert len({v.parent.index for v in views if v.level == 2}) >= 2  # several reflected eyes on one level
    for v in views:
        corners = v.surface.corners[:, :3]
        centre = corners.mean(axis=0)
        radius = np.linalg.norm(corners - centre, axis=1).max()
        eye = np.array(v.parent.view.eye)
        d = max(np.linalg.norm(eye - centre) - radius, 0.0)
        assert v.fade == pytest.approx(min(max((16.0 - d) / 14.0, 0.0), 1.0), abs=1e-5)
    assert len({round(v.fade, 4) for v in views}) >= 2  # deeper views are farther: they fade more
    runner.close()


@pytest.mark.parametrize("field, value", [
    ("fade_distance", (5.0, 2.0)), ("fade_distance", (-1.0, 2.0)), ("fade_distance", (1.0, float("inf"))),
    ("fade_angle", (10.0, 95.0)), ("fade_angle", (30.0, 30.0)), ("fade_angle", "far"),
])
def test_bad_fades_are_refused_naming_the_field(field, value):
    with pytest.raises(ComponentValueError, match=f"Mirror.{field}"):
        Mirror(**{field: value})


def test_level_files_carry_fades(tmp_path):
    text = """
[level]
name = "fades"

[[entity]]
name = "glass"
[entity.Transform]
[entity.MeshRef]
mesh = { quad = [1.0, 1.0] }
[entity.Mirror]
fade_distance = [4.0, 12.0]
fade_angle = [30.0, 75.0]
"""
    path = tmp_path / "fades.toml"
    path.write_text(text)
    world = World()
    load_level(path).spawn(world)
    ((_, mirror),) = world.query_one(Mirror)
    assert mirror.fade_distance == (4.0, 12.0) and mirror.fade_angle == (30.0, 75.0)
    path.write_text(text.replace("75.0", "120.0"))
    with pytest.raises(LevelError, match="fade_angle"):
        load_level(path)


# A portal pair: A before the camera, B far off behind it and turned a quarter about y.
PORTAL_A, PORTAL_B = glm.vec3(0.0, 1.5, 1.0), glm.vec3(40.0, 1.5, 40.0)
B_TURN = glm.angleAxis(-math.pi / 2, glm.vec3(0, 1, 0))
CAMERA_AT = glm.vec3(0.0, 1.5, 4.0)


def _beyond(local) -> glm.vec3:
    """A point in portal B's frame (x right, z out of its front) in the world."""
    return PORTAL_B + B_TURN * glm.vec3(local)


def _carried(point) -> glm.vec3:
    """``point`` before A as the view through A sees it beyond B: B x a half turn x A^-1 (so
    looking into A's front shows what lies before B's: ``spawn_portal_pair``)."""
    carry = glm.translate(PORTAL_B) * glm.mat4_cast(B_TURN) * glm.mat4_cast(glm.angleAxis(math.pi, glm.vec3(0, 1, 0))) \
        * glm.translate(-PORTAL_A)
    return glm.vec3(carry * glm.vec4(point, 1.0))


BEYOND_MIRROR = _beyond((1.0, 0.0, 4.0))   # 4 m before B, turned 30 degrees from facing it
BEYOND_TURN = B_TURN * glm.angleAxis(math.pi + math.radians(30.0), glm.vec3(0, 1, 0))
BEYOND_FADES = {"fade_distance": (4.0, 9.0), "fade_angle": (10.0, 50.0)}


def _mirror_beyond_a_portal(mirror: Mirror, through_portal: bool = True):
    """The camera 3 m before portal A, looking into it; beyond B a mirror and, off to B's
    left, a red glowing wall it reflects.  ``through_portal`` False: no portals, the camera
    standing where the carried camera stands (at the carried eye, looking at B)."""
    def build(world: World) -> None:
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=1.0))
        if through_portal:
            look_from(world, tuple(CAMERA_AT), target=tuple(PORTAL_A), fov=60.0)
            spawn_portal_pair(world, PORTAL_A, None, PORTAL_B, B_TURN, size=(2.4, 2.4), max_depth=1)
        else:
            look_from(world, tuple(_carried(CAMERA_AT)), target=tuple(PORTAL_B), fov=60.0)
        world.spawn(Transform(position=BEYOND_MIRROR, rotation=BEYOND_TURN), MeshRef(quad(2 * HALF, 2 * HALF)),
                    Material(color=(0.05, 0.1, 0.6)), mirror)
        world.spawn(Transform(position=_beyond((-12.0, 0.0, 0.0)), rotation=B_TURN, scale=(0.1, 30, 60)),
                    MeshRef(box()), Material(color=(0.9, 0.1, 0.1)), Emissive(1.0))
    return build


def test_a_mirror_seen_through_a_portal_fades_by_the_eye_carried_through_it(ctx):
    """A mirror 4 m beyond portal B, the camera 3 m before portal A (and 56 m from the mirror
    itself, past its fade's end): its view's weight is the fades' formula from the eye
    carried through the pair (worked out here by hand: B x a half turn x A^-1, and checked
    against the portal view's eye), whose distance to the mirror is the way from the camera
    through the portal's opening to the mirror; a second path, a camera standing at the
    carried eye with no portal at all, gives its view of the mirror the same weight and
    shows the mirror's pixels as the portal does; the unfaded mirror through the portal
    shows more of the red wall."""
    eye = _carried(CAMERA_AT)
    # The way through the opening: from the camera to where it crosses A, then on from the
    # point B's plane has there to the mirror (the straight line from the carried eye
    # crosses B's plane inside the opening).
    local_eye = glm.inverse(B_TURN) * (eye - PORTAL_B)
    local_mirror = glm.inverse(B_TURN) * (BEYOND_MIRROR - PORTAL_B)
    crossing = glm.mix(local_eye, local_mirror, -local_eye.z / (local_mirror.z - local_eye.z))
    assert abs(crossing.x) < 1.2 and abs(crossing.y) < 1.2
    way = glm.length(local_eye - crossing) + glm.length(local_mirror - crossing)
    assert glm.length(CAMERA_AT - PORTAL_A) == pytest.approx(3.0)
    assert way == pytest.approx(glm.distance(eye, BEYOND_MIRROR))
    d = max(way - math.sqrt(2.0) * HALF, 0.0)
    normal = BEYOND_TURN * glm.vec3(0, 0, 1)
    angle = math.degrees(math.acos(glm.dot(glm.normalize(eye - BEYOND_MIRROR), normal)))
    (near, far), (low, high) = BEYOND_FADES["fade_distance"], BEYOND_FADES["fade_angle"]
    weight = min(max((far - d) / (far - near), 0.0), 1.0) * min(max((high - angle) / (high - low), 0.0), 1.0)
    assert 0.15 < weight < 0.85, weight
    assert glm.distance(CAMERA_AT, BEYOND_MIRROR) - math.sqrt(2.0) * HALF > far   # from the camera: faded out

    size = (96, 72)
    runner = SceneRunner(ctx, _mirror_beyond_a_portal(Mirror(reflect_rate=0.9, **BEYOND_FADES)), size)
    through = runner.frame()
    portal_view, mirror_view = runner.engine.reflection_system.views[1:]
    assert (portal_view.level, mirror_view.level, mirror_view.parent) == (1, 2, portal_view)
    assert tuple(portal_view.view.eye) == pytest.approx(tuple(eye), abs=1e-4)
    assert mirror_view.fade == pytest.approx(weight, abs=1e-5)
    runner.close()
    direct = SceneRunner(ctx, _mirror_beyond_a_portal(Mirror(reflect_rate=0.9, **BEYOND_FADES), False), size)
    seen = direct.frame()
    (view,) = direct.engine.reflection_system.views[1:]
    assert view.fade == pytest.approx(weight, abs=1e-5)
    x, y = direct.project(BEYOND_MIRROR)
    direct.close()
    patch = (slice(y - 4, y + 4), slice(x - 4, x + 4))
    np.testing.assert_allclose(through[patch].astype(float), seen[patch].astype(float), atol=2.0)
    unfaded = SceneRunner(ctx, _mirror_beyond_a_portal(Mirror(reflect_rate=0.9)), size)
    whole = unfaded.frame()[patch].astype(float)
    unfaded.close()
    shown = through[patch].astype(float)
    assert shown[..., 0].mean() > shown[..., 1].mean() + 40.0   # (the red wall, in the mirror)
    assert whole[..., 0].mean() > shown[..., 0].mean() + 20.0


def _three_mirrors_and_a_box(world: World) -> None:
    """``test_a_mirror_seen_in_a_mirror_fades_by_the_reflected_eye``'s three mirrors, and a red
    glowing box behind the camera that the two before it show."""
    world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=1.0))
    look_from(world, (0.5, 1.5, 0.5), target=(0.0, 1.5, -3.0), fov=80.0)
    for x, z, turn in ((-1.3, -3.0, 0.0), (1.3, -4.0, 0.0), (0.0, 3.0, math.pi)):
        world.spawn(Transform(position=(x, 1.5, z), rotation=glm.angleAxis(turn, glm.vec3(0, 1, 0))),
                    MeshRef(quad(2.4, 2.0)), Material(color=(0.2, 0.2, 0.2)),
                    Mirror(fade_distance=(2.0, 16.0), max_depth=3))
    world.spawn(Transform(position=(0.0, 1.2, 1.6), scale=(3.0, 1.4, 0.3)), MeshRef(box()),
                Material(color=(0.9, 0.1, 0.1)), Emissive(1.0))


@pytest.mark.parametrize("case", ["through_portal", "in_mirrors"])
def test_fades_from_carried_and_reflected_eyes_are_the_same_on_the_batched_path(ctx, case):
    """The batched path (a level's views in one draw per mesh) fades each view as the
    per-mirror path does: the mirror beyond a portal by the eye carried through the pair (the
    weight worked out by hand as in the test above), the three mirrors' views by each parent's
    reflected eye (levels of several views, one draw); on either path each view's weight is the
    formula from its parent's eye, the same views are drawn, and the frames agree within 2
    levels.  The reflection is there: the red wall in the mirror beyond the portal, the red
    box's id in the mirrors' pixels at each level's composite."""
    results = {}
    for path in ("per_mirror", "batched"):
        if case == "through_portal":
            runner = SceneRunner(ctx, _mirror_beyond_a_portal(Mirror(reflect_rate=0.9, **BEYOND_FADES)), (96, 72))
        else:
            runner = SceneRunner(ctx, _three_mirrors_and_a_box, (96, 72))
        runner.engine.reflection_system.path = path
        runner.engine.reflection_system.visibility = "exact"
        rgb = runner.frame()
        assert runner.stats.reflection_path == path
        views = runner.engine.reflection_system.views[1:]
        for v in views:
            if v.surface.kind != "mirror":
                continue
            corners = v.surface.corners[:, :3]
            centre = corners.mean(axis=0)
            to_eye = np.array(v.parent.view.eye) - centre
            d = max(np.linalg.norm(to_eye) - np.linalg.norm(corners - centre, axis=1).max(), 0.0)
            if case == "through_portal":
                assert tuple(v.parent.view.eye) == pytest.approx(tuple(_carried(CAMERA_AT)), abs=1e-4)
                normal = np.array(BEYOND_TURN * glm.vec3(0, 0, 1))
                angle = math.degrees(math.acos(np.dot(to_eye, normal) / np.linalg.norm(to_eye)))
                weight = min(max((9.0 - d) / 5.0, 0.0), 1.0) * min(max((50.0 - angle) / 40.0, 0.0), 1.0)
                assert 0.15 < weight < 0.85
            else:
                weight = min(max((16.0 - d) / 14.0, 0.0), 1.0)
            assert v.fade == pytest.approx(weight, abs=1e-5), (path, v.level)
        if case == "through_portal":
            assert [v.level for v in views] == [1, 2]
            carry = glm.translate(PORTAL_B) * glm.mat4_cast(B_TURN) \
                * glm.mat4_cast(glm.angleAxis(math.pi, glm.vec3(0, 1, 0))) * glm.translate(-PORTAL_A)
            x, y = runner.project(glm.vec3(glm.inverse(carry) * glm.vec4(BEYOND_MIRROR, 1.0)))  # where it shows
            patch = rgb[y - 3:y + 3, x - 3:x + 3].astype(float)
            assert patch[..., 0].mean() > patch[..., 1].mean() + 40.0  # the red wall in the faded mirror
        else:
            assert max(v.level for v in views) == 3 and len([v for v in views if v.level == 2]) >= 2
            assert len({round(v.fade, 4) for v in views}) >= 3
            ids = runner.ids()
            mirrors = [entity for entity, _ in runner.world.query_one(Mirror)]
            ((box_id, _),) = runner.world.query_one(Emissive)
            on_glass = np.isin(runner.engine.renderer.targets.read_surface_ids(), mirrors)
            assert (ids[on_glass] == box_id).sum() > 20
        results[path] = rgb.astype(int), [(v.level, v.surface.entity, round(v.fade, 6)) for v in views]
        runner.close()
    (rgb, views), (batched_rgb, batched_views) = results["per_mirror"], results["batched"]
    assert views == batched_views
    assert np.abs(batched_rgb - rgb).max() <= 2


def _scaled_carry(scale: float) -> glm.mat4:
    """The pair's carry with B scaled ``scale`` by its Transform: B (its scale too) x a half
    turn x A^-1, worked out here from the placements."""
    return glm.translate(PORTAL_B) * glm.mat4_cast(B_TURN) * glm.scale(glm.vec3(scale)) \
        * glm.mat4_cast(glm.angleAxis(math.pi, glm.vec3(0, 1, 0))) * glm.translate(-PORTAL_A)


def _mirror_beyond_a_scaled_portal(scale: float, mirror: Mirror, through_portal: bool = True):
    """``_mirror_beyond_a_portal`` with portal B scaled ``scale`` by its Transform and what
    stands beyond it (the mirror, its place, the red wall) made ``scale`` times larger with
    it: the world beyond B is the one-size scene's at ``scale``.  ``through_portal`` False:
    no portals, the camera at the carried eye looking at B."""
    def beyond(local) -> glm.vec3:
        return PORTAL_B + B_TURN * (scale * glm.vec3(local))

    def build(world: World) -> None:
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=1.0))
        if through_portal:
            look_from(world, tuple(CAMERA_AT), target=tuple(PORTAL_A), fov=60.0)
            _, b = spawn_portal_pair(world, PORTAL_A, None, PORTAL_B, B_TURN, size=(2.4, 2.4), max_depth=1)
            world.get(b, Transform).scale = glm.vec3(scale)
        else:
            eye = glm.vec3(_scaled_carry(scale) * glm.vec4(CAMERA_AT, 1.0))
            look_from(world, tuple(eye), target=tuple(PORTAL_B), fov=60.0)
        world.spawn(Transform(position=beyond((1.0, 0.0, 4.0)), rotation=BEYOND_TURN),
                    MeshRef(quad(2 * HALF * scale, 2 * HALF * scale)), Material(color=(0.05, 0.1, 0.6)), mirror)
        world.spawn(Transform(position=beyond((-12.0, 0.0, 0.0)), rotation=B_TURN, scale=(0.1 * scale, 30 * scale,
                                                                                       60 * scale)),
                    MeshRef(box()), Material(color=(0.9, 0.1, 0.1)), Emissive(1.0))
    return build


@pytest.mark.parametrize("scale", [2.0, 0.5])
def test_a_mirror_beyond_a_pair_of_two_sizes_fades_by_the_carried_eyes_distance_in_its_own_sides_metres(ctx, scale):
    """Portal B scaled 2 (or 0.5) by its Transform, the mirror and wall beyond it that much
    larger with it (4 m before B times the scale, fades from 4 to 9 m times it): the mirror's
    view's weight is the fades' formula from the eye carried through the pair (its carry,
    B's scale in it, worked out here by hand and checked against the portal view's eye), by
    the distance in B's side's metres, the way through the opening times the scale (here the
    one-size case's weight; by A's metres, the way unscaled, it would be another); a second
    path, a camera standing at the carried eye with no portal, gives the mirror the same
    weight and shows its pixels as the portal does (the red wall in it, less of it than the
    unfaded mirror shows)."""
    carry = _scaled_carry(scale)
    eye = glm.vec3(carry * glm.vec4(CAMERA_AT, 1.0))
    mirror_at = PORTAL_B + B_TURN * (scale * glm.vec3(1.0, 0.0, 4.0))
    local_eye = glm.inverse(B_TURN) * (eye - PORTAL_B)
    local_mirror = glm.inverse(B_TURN) * (mirror_at - PORTAL_B)
    crossing = glm.mix(local_eye, local_mirror, -local_eye.z / (local_mirror.z - local_eye.z))
    assert abs(crossing.x) < 1.2 * scale and abs(crossing.y) < 1.2 * scale   # (through B's opening, scaled)
    at_a = glm.vec3(glm.inverse(carry) * glm.vec4(PORTAL_B + B_TURN * crossing, 1.0))   # the crossing, on A
    assert abs(at_a.z - PORTAL_A.z) < 1e-5
    way_here = glm.distance(CAMERA_AT, at_a) + glm.length(local_mirror - crossing) / scale   # in A's metres
    distance = glm.distance(eye, mirror_at)
    assert distance == pytest.approx(scale * way_here, rel=1e-5)                # B's metres: the way times the scale
    fades = {"fade_distance": (4.0 * scale, 9.0 * scale), "fade_angle": BEYOND_FADES["fade_angle"]}
    (near, far), (low, high) = fades["fade_distance"], fades["fade_angle"]
    normal = BEYOND_TURN * glm.vec3(0, 0, 1)
    angle = math.degrees(math.acos(glm.dot(glm.normalize(eye - mirror_at), normal)))
    by_angle = min(max((high - angle) / (high - low), 0.0), 1.0)

    def weight_at(d):
        d = max(d - math.sqrt(2.0) * HALF * scale, 0.0)
        return min(max((far - d) / (far - near), 0.0), 1.0) * by_angle

    weight = weight_at(distance)
    assert 0.15 < weight < 0.85, weight
    assert abs(weight_at(way_here) - weight) > 0.1      # (A's metres would fade it otherwise)

    size = (96, 72)
    runner = SceneRunner(ctx, _mirror_beyond_a_scaled_portal(scale, Mirror(reflect_rate=0.9, **fades)), size)
    through = runner.frame()
    portal_view, mirror_view = runner.engine.reflection_system.views[1:]
    assert (portal_view.level, mirror_view.level, mirror_view.parent) == (1, 2, portal_view)
    assert tuple(portal_view.view.eye) == pytest.approx(tuple(eye), abs=1e-4 * max(scale, 1.0))
    assert mirror_view.fade == pytest.approx(weight, abs=1e-5)
    runner.close()
    direct = SceneRunner(ctx, _mirror_beyond_a_scaled_portal(scale, Mirror(reflect_rate=0.9, **fades), False), size)
    seen = direct.frame()
    (view,) = direct.engine.reflection_system.views[1:]
    assert view.fade == pytest.approx(weight, abs=1e-5)
    x, y = direct.project(mirror_at)
    direct.close()
    patch = (slice(y - 4, y + 4), slice(x - 4, x + 4))
    np.testing.assert_allclose(through[patch].astype(float), seen[patch].astype(float), atol=2.0)
    unfaded = SceneRunner(ctx, _mirror_beyond_a_scaled_portal(scale, Mirror(reflect_rate=0.9)), size)
    whole = unfaded.frame()[patch].astype(float)
    unfaded.close()
    shown = through[patch].astype(float)
    assert shown[..., 0].mean() > shown[..., 1].mean() + 40.0   # (the red wall, in the mirror)
    assert whole[..., 0].mean() > shown[..., 0].mean() + 20.0
