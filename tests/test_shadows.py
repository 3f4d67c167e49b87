"""Shadows: the frame against float64 shadow rays cast in numpy (a second computation of
which floor points the light reaches), directly, in a mirror and for a point light; the
maps' caching (a still scene draws no shadow pass); a probe face recaptured when a shadow
it shows moves; the components' checks."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    ComponentValueError,
    DirectionalLight,
    Material,
    MeshRef,
    Mirror,
    PointLight,
    ReflectionProbe,
    Refractive,
    Transform,
    Visibility,
)
from components.limits import MAX_FAR
from engine.assets.mesh import box, plane, quad, sphere
from engine.assets.portals import spawn_portal_pair
from engine.core.errors import LightLimitWarning
from engine.core.portal_math import pair_transform
from engine.rules.probe_schedule import ProbeSchedule
from tests.support import box_hits, look_from, pixel_rays, six_pass_only, skip_unless_layered, srgb_to_linear

LIGHT = glm.normalize(glm.vec3(-1.0, -0.75, -0.5))
BOX_CENTRE, BOX_HALF = np.array([-1.0, 0.5, 0.0]), 0.5
SPHERE_CENTRE, SPHERE_RADIUS = np.array([1.2, 0.7, 0.5]), 0.7
PENUMBRA = 0.06   # metres either side of an occluder's outline left out (the filter's reach and more)


def _floor_scene(world, eye, target, sun=True, point=None, mirror=False):
    ids = {}
    look_from(world, eye, target)
    if sun:
        ids["sun"] = world.spawn(DirectionalLight(direction=LIGHT, intensity=2.5))
    if point is not None:
        ids["lamp"] = world.spawn(Transform(position=point), PointLight(intensity=10.0, range=9.0, shadows=True))
    ids["floor"] = world.spawn(Transform(), MeshRef(plane(14, 14)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
    ids["box"] = world.spawn(Transform(position=BOX_CENTRE.tolist()), MeshRef(box()), Material(color=(0.8, 0.3, 0.2)))
    ids["sphere"] = world.spawn(Transform(position=SPHERE_CENTRE.tolist()), MeshRef(sphere(SPHERE_RADIUS, segments=48)),
                                Material(color=(0.3, 0.5, 0.8)))
    if mirror:
        ids["mirror"] = world.spawn(Transform(position=(0.0, 1.5, -3.0)), MeshRef(quad(6.0, 3.0)), Material(),
                                    Mirror())
    return ids


CASTERS = ("box", "sphere")


def _hits(origin: np.ndarray, direction: np.ndarray, grow: float, segment: np.ndarray | None = None,
          casters: tuple[str, ...] = CASTERS) -> np.ndarray:
    """Whether rays (rows) from ``origin`` along unit ``direction`` meet the box or the sphere
    (each grown by ``grow`` metres, negative shrinks; those of ``casters``), within
    ``segment`` (a length per ray) if given."""
    limit = np.full(len(origin), np.inf) if segment is None else segment
    # The sphere: |o + t d - c|^2 = r^2.
    r = SPHERE_RADIUS + grow
    oc = origin - SPHERE_CENTRE
    b = np.einsum("ij,ij->i", oc, direction)
    c = np.einsum("ij,ij->i", oc, oc) - r * r
    disc = b * b - c
    root = np.sqrt(np.maximum(disc, 0.0))
    t_far = -b + root
    sphere = (disc > 0.0) & (t_far > 1e-6) & (-b - root < limit) & ("sphere" in casters)
    return sphere | (box_hits(origin, direction, BOX_CENTRE, BOX_HALF + grow, limit) & ("box" in casters))


def _classified(lit_frame: np.ndarray, dark_frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels the shadows darkened (shadowed) and left as they were (lit)."""
    on = srgb_to_linear(dark_frame).mean(axis=-1)
    off = srgb_to_linear(lit_frame).mean(axis=-1)
    ratio = on / np.maximum(off, 1e-6)
    return ratio < 0.7, ratio > 0.95


def _agreement(shadowed, lit, mask, occluded_in, occluded_out):
    """The share of ``mask``'s pixels outside the penumbra band where the frame says what the rays say."""
    sure = mask & (occluded_in == occluded_out)
    frame_says = np.where(shadowed, 1, np.where(lit, 0, -1))[sure]
    rays_say = occluded_in[sure].astype(int)
    return float((frame_says == rays_say).mean()), int(sure.sum()), int(rays_say.sum())


def _floor_points_seen(runner) -> np.ndarray:
    """Where each pixel's ray from the main view meets the floor (y = 0), one row a pixel."""
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    t = -eye[1] / rays[..., 1]
    return (eye + rays * t[..., None]).reshape(-1, 3)


def _sun_rays_agree(shadowed, lit, mask, points: np.ndarray, casters: tuple[str, ...] = CASTERS
                    ) -> tuple[float, int, int, np.ndarray]:
    """``mask``'s pixels, each showing the floor point of its row of ``points``, classified
    by the frame against float64 shadow rays towards the sun (LIGHT) meeting ``casters``:
    (agreeing share, pixels counted, pixels in shadow, the umbra: pixels every ray of the
    band says shadowed)."""
    to_light = np.tile(-np.array(LIGHT, np.float64), (len(points), 1))
    occluded_in = _hits(points, to_light, -PENUMBRA, casters=casters).reshape(mask.shape)
    occluded_out = _hits(points, to_light, PENUMBRA, casters=casters).reshape(mask.shape)
    share, counted, in_shadow = _agreement(shadowed, lit, mask, occluded_in, occluded_out)
    return share, counted, in_shadow, mask & occluded_in & occluded_out


def _render_both(scene, build, size=(320, 240), light="sun", shadow_filter="single"):
    """The frame with the light's shadows off, then on (same scene, one runner), the edges
    filtered by ``shadow_filter`` (ShadowMaps.filter: the software default, or the GPU's)."""
    runner = scene(build, size)
    runner.engine.renderer.antialias = "off"
    runner.engine.renderer.shadows.filter = shadow_filter
    ids = runner.world.resources["ids"]
    caster = runner.world.get(ids[light], DirectionalLight if light == "sun" else PointLight)
    caster.shadows = False
    without = runner.frame()
    caster.shadows = True
    with_shadows = runner.frame()
    return runner, ids, without, with_shadows


@pytest.mark.parametrize("shadow_filter", ["single", "grid"])
def test_directional_shadows_agree_with_shadow_rays(scene, shadow_filter):
    def build(world):
        world.resources["ids"] = _floor_scene(world, (0.5, 5.0, 6.5), (0.0, 0.0, 0.0))

    runner, ids, without, with_shadows = _render_both(scene, build, shadow_filter=shadow_filter)
    shadowed, lit = _classified(without, with_shadows)
    floor = runner.ids() == ids["floor"]
    points = _floor_points_seen(runner)
    share, counted, in_shadow, _ = _sun_rays_agree(shadowed, lit, floor, points)
    assert counted > 40000 and in_shadow > 800, (counted, in_shadow, share)   # a real floor, real shadows
    assert share >= 0.99, f"{share:.4f} of {counted} floor pixels agree with the shadow rays"


def test_a_later_directional_lights_shadow_is_looked_up_when_an_earlier_one_casts_none(scene):
    """Each directional slot's lookup is made before the lights' loop, for slots 0 to the last
    casting one (``DIRECTIONAL_SHADOWS`` is that count): a second sun casting while the first
    does not still has its shadow, and it agrees with the float64 shadow rays."""
    def build(world):
        world.spawn(DirectionalLight(direction=(0.3, -1.0, 0.2), intensity=0.3, shadows=False))  # slot 0: casts none
        world.resources["ids"] = _floor_scene(world, (0.5, 5.0, 6.5), (0.0, 0.0, 0.0))

    runner, ids, without, with_shadows = _render_both(scene, build)
    assert ("DIRECTIONAL_SHADOWS", "2") in runner.engine.renderer.shadows.program_defines
    shadowed, lit = _classified(without, with_shadows)
    floor = runner.ids() == ids["floor"]
    points = _floor_points_seen(runner)
    share, counted, in_shadow, umbra = _sun_rays_agree(shadowed, lit, floor, points)
    assert counted > 40000 and in_shadow > 800, (counted, in_shadow, share)
    assert share >= 0.99, f"{share:.4f} of {counted} floor pixels agree with the second sun's shadow rays"
    assert shadowed[umbra].mean() >= 0.95, f"{shadowed[umbra].mean():.3f} of the umbra's pixels are shadowed"


@pytest.mark.parametrize("shadow_filter", ["single", "grid"])
def test_the_shadow_seen_in_a_mirror_is_the_mirrored_points_shadow(scene, shadow_filter):
    def build(world):
        world.resources["ids"] = _floor_scene(world, (0.0, 3.0, 5.0), (0.0, 1.2, -3.0), mirror=True)

    runner, ids, without, with_shadows = _render_both(scene, build, shadow_filter=shadow_filter)
    shadowed, lit = _classified(without, with_shadows)
    targets = runner.engine.renderer.targets
    in_mirror = (targets.read_surface_ids() == ids["mirror"]) & (runner.ids() == ids["floor"])
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    # The ray meets the mirror's plane (z = -3, facing +z), turns (z flips) and meets the floor.
    t = (-3.0 - eye[2]) / rays[..., 2]
    on_mirror = eye + rays * t[..., None]
    turned = rays * np.array([1.0, 1.0, -1.0])
    s = -on_mirror[..., 1] / turned[..., 1]
    points = (on_mirror + turned * s[..., None]).reshape(-1, 3)
    share, counted, in_shadow, _ = _sun_rays_agree(shadowed, lit, in_mirror, points)
    assert counted > 4000 and in_shadow > 300, (counted, in_shadow, share)
    assert share >= 0.99, f"{share:.4f} of {counted} floor pixels in the mirror agree with the shadow rays"


def test_the_shadow_seen_through_a_portal_is_the_carried_points_shadow(scene):
    """Looking into portal A (at z = 5, facing the camera) shows what lies in front of
    portal B (at z = -6, facing the box and the sphere): the floor point each pixel shows is
    the ray carried by the pair's transform to where it meets the floor."""
    def build(world):
        ids = world.resources["ids"] = _floor_scene(world, (0.0, 2.6, 9.5), (0.0, 1.2, 5.0))
        ids["a"], ids["b"] = spawn_portal_pair(world, (0.0, 1.5, 5.0), None, (0.0, 1.5, -6.0), None)

    runner, ids, without, with_shadows = _render_both(scene, build)
    shadowed, lit = _classified(without, with_shadows)
    targets = runner.engine.renderer.targets
    through = (targets.read_surface_ids() == ids["a"]) & (runner.ids() == ids["floor"])
    carry = glm.dmat4(pair_transform(runner.world.get(ids["a"], Transform).world,
                                     runner.world.get(ids["b"], Transform).world))
    m = np.array(carry.to_list(), np.float64).T   # rows act on column vectors
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    t = (5.0 - eye[2]) / rays[..., 2]
    at_a = eye + rays * t[..., None]
    carried = at_a @ m[:3, :3].T + m[:3, 3]
    turned = rays @ m[:3, :3].T
    s = -carried[..., 1] / turned[..., 1]
    points = (carried + turned * s[..., None]).reshape(-1, 3)
    share, counted, in_shadow, _ = _sun_rays_agree(shadowed, lit, through, points)
    assert counted > 4000 and in_shadow > 200, (counted, in_shadow, share)
    assert share >= 0.99, f"{share:.4f} of {counted} floor pixels through the portal agree with the shadow rays"


def test_a_mesh_that_casts_no_shadow_is_drawn_and_leaves_the_sun_on_the_floor(scene):
    """``MeshRef.casts_shadows = False`` on the box: it is drawn as before (its pixels, in
    the frame and in the mirror), but the floor directly and in the mirror agrees with shadow
    rays that meet the sphere alone, so where the box alone stood in the sun's way is lit
    (behind the mirror's plane, z < -3, the mirror's own shadow is left out); switched on
    again, the kept map is drawn again and the frame is the first one."""
    def build(world):
        world.resources["ids"] = _floor_scene(world, (0.0, 3.0, 5.0), (0.0, 1.2, -3.0), mirror=True)

    runner, ids, without, with_shadows = _render_both(scene, build)
    box_pixels = int((runner.ids() == ids["box"]).sum())
    box_mesh = runner.world.get(ids["box"], MeshRef)
    box_mesh.casts_shadows = False
    no_box_shadow = runner.frame()
    assert int((runner.ids() == ids["box"]).sum()) == box_pixels > 500
    shadowed, lit = _classified(without, no_box_shadow)
    floor = runner.ids() == ids["floor"]
    in_mirror = (runner.engine.renderer.targets.read_surface_ids() == ids["mirror"]) & floor
    points = _floor_points_seen(runner)
    direct = floor & ~in_mirror & (points[:, 2] > -3.0).reshape(floor.shape)
    share, counted, in_shadow, _ = _sun_rays_agree(shadowed, lit, direct, points, ("sphere",))
    assert counted > 20000 and in_shadow > 300, (counted, in_shadow, share)
    assert share >= 0.99, f"{share:.4f} of {counted} floor pixels agree with rays that meet the sphere alone"
    # Where the box alone shadowed the floor (every ray of the band meets it, none the sphere) is lit now.
    _, _, _, box_umbra = _sun_rays_agree(shadowed, lit, direct, points)
    _, _, _, sphere_umbra = _sun_rays_agree(shadowed, lit, direct, points, ("sphere",))
    box_alone = box_umbra & ~sphere_umbra
    assert box_alone.sum() > 300 and lit[box_alone].mean() >= 0.95, (box_alone.sum(), lit[box_alone].mean())
    was_shadowed, _ = _classified(without, with_shadows)
    assert was_shadowed[box_alone].mean() >= 0.95  # it was the box's shadow

    eye, rays = pixel_rays(runner.engine.main_view, runner.size)  # the floor in the mirror (z = -3)
    t = (-3.0 - eye[2]) / rays[..., 2]
    on_mirror = eye + rays * t[..., None]
    turned = rays * np.array([1.0, 1.0, -1.0])
    mirrored = (on_mirror + turned * (-on_mirror[..., 1] / turned[..., 1])[..., None]).reshape(-1, 3)
    share, counted, _, _ = _sun_rays_agree(shadowed, lit, in_mirror, mirrored, ("sphere",))
    assert counted > 4000 and share >= 0.99, (counted, share)

    box_mesh.casts_shadows = True
    again = runner.frame()
    assert runner.stats.shadow_maps_drawn >= 1
    np.testing.assert_array_equal(again, with_shadows)


def test_a_mesh_that_casts_no_shadow_leaves_a_lamps_light_on_the_floor(scene):
    """The same for a point light's cube map (a lamp between the box and the sphere): with
    the box's ``casts_shadows`` off the floor agrees with shadow rays to the lamp that meet
    the sphere alone, and no longer with rays that meet both."""
    lamp = np.array([0.0, 2.0, 1.2])

    def build(world):
        world.resources["ids"] = _floor_scene(world, (0.0, 5.5, 6.0), (0.0, 0.0, 0.0), sun=False,
                                              point=lamp.tolist())

    runner, ids, without, with_shadows = _render_both(scene, build, light="lamp")
    share, _, box_and_sphere, _ = _lamp_rays_agree(runner, ids, without, with_shadows, lamp)
    assert share >= 0.99, share
    runner.world.get(ids["box"], MeshRef).casts_shadows = False
    no_box_shadow = runner.frame()
    share, counted, in_shadow, umbra_dark = _lamp_rays_agree(runner, ids, without, no_box_shadow, lamp, ("sphere",))
    assert counted > 10000 and in_shadow > 300 and umbra_dark >= 0.95, (counted, in_shadow, umbra_dark)
    assert box_and_sphere > in_shadow + 300, (box_and_sphere, in_shadow)  # the box's shadow was there
    assert share >= 0.99, f"{share:.4f} of {counted} floor pixels agree with rays to the lamp meeting the sphere alone"
    share_both, _, _, _ = _lamp_rays_agree(runner, ids, without, no_box_shadow, lamp)
    assert share_both < 0.99, share_both  # the box's shadow is gone: the rays that meet it disagree


@pytest.mark.parametrize("change", ["casts_shadows", "hidden_everywhere", "glass"])
def test_a_caster_that_stops_casting_where_it_stands_draws_the_kept_maps_again(scene, change):
    """A caster whose box stays where it was but stops casting (its MeshRef's
    ``casts_shadows`` off, hidden in every kind of view, made glass: its shadow then lies in
    the sun's see-through map, softer, alpha 1 letting none through): the kept sun's map is
    drawn again, and the frame is the one an engine given that world from the start draws.
    (The maps were drawn again only where a box changed, so hiding the box left its shadow.)"""
    import warnings

    from components import Refractive, Visibility
    from components.tracking import ComponentWarning

    def stop(world, box_entity):
        if change == "casts_shadows":
            world.get(box_entity, MeshRef).casts_shadows = False
        elif change == "hidden_everywhere":
            world.add_component(box_entity, Visibility(direct=False, in_mirrors=False, in_portals=False,
                                                       in_probes=False))
        else:
            world.add_component(box_entity, Refractive())

    def build(late):
        def make(world):
            ids = world.resources["ids"] = _floor_scene(world, (0.0, 3.0, 5.0), (0.0, 1.2, -3.0))
            if not late:
                stop(world, ids["box"])
        return make

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ComponentWarning)  # hidden everywhere: warned, on purpose
        late = scene(build(True), (160, 120))
        late.engine.renderer.antialias = "off"
        cast = late.frame()
        stop(late.world, late.world.resources["ids"]["box"])
        stopped = late.frame()
        assert late.stats.shadow_maps_drawn >= 1
        fresh = scene(build(False), (160, 120))
        fresh.engine.renderer.antialias = "off"
        fresh.frame()
        expected = fresh.frame()
    assert not np.array_equal(cast, stopped)
    np.testing.assert_array_equal(stopped, expected)


def _lamp_rays_agree(runner, ids, without, with_shadows, lamp: np.ndarray, casters: tuple[str, ...] = CASTERS
                     ) -> tuple[float, int, int, float]:
    """The floor's pixels within 5 of ``lamp`` (where the lamp gives a visible share of the
    light: near the end of its range the difference is below the 8-bit output's steps),
    classified shadowed or lit from the frames ``without`` and ``with_shadows``, against
    float64 shadow rays to the lamp: (agreeing share, pixels counted, pixels in shadow, share
    of the umbra's pixels shadowed)."""
    shadowed, lit = _classified(without, with_shadows)
    points = _floor_points_seen(runner)
    to_lamp = lamp - points
    distance = np.linalg.norm(to_lamp, axis=1)
    floor = (runner.ids() == ids["floor"]) & (distance < 5.0).reshape(runner.ids().shape)
    direction = to_lamp / distance[:, None]
    occluded_in = _hits(points, direction, -PENUMBRA, distance, casters).reshape(floor.shape)
    occluded_out = _hits(points, direction, PENUMBRA, distance, casters).reshape(floor.shape)
    share, counted, in_shadow = _agreement(shadowed, lit, floor, occluded_in, occluded_out)
    umbra = floor & occluded_in & occluded_out
    return share, counted, in_shadow, float(shadowed[umbra].mean())


@pytest.mark.parametrize("path, shadow_filter", [("layered", "single"), ("six_pass", "grid")])
def test_point_light_shadows_agree_with_shadow_rays(scene, monkeypatch, path, shadow_filter):
    lamp = np.array([3.2, 1.3, 0.9])
    if path == "six_pass":
        six_pass_only(monkeypatch)

    def build(world):
        world.resources["ids"] = _floor_scene(world, (0.0, 5.5, 6.0), (0.0, 0.0, 0.0), sun=False,
                                              point=lamp.tolist())

    runner, ids, without, with_shadows = _render_both(scene, build, light="lamp", shadow_filter=shadow_filter)
    if path == "layered":  # (a driver refusing both layered targets draws six passes)
        skip_unless_layered(runner.engine.renderer)
    assert runner.stats.shadow_path == path
    share, counted, in_shadow, _ = _lamp_rays_agree(runner, ids, without, with_shadows, lamp)
    assert counted > 10000 and in_shadow > 800, (counted, in_shadow, share)
    assert share >= 0.99, f"{share:.4f} of {counted} floor pixels agree with the shadow rays ({path})"


def test_the_second_cubes_point_light_is_looked_up_at_its_own_position(scene):
    """The cubes are looked up before the lights' loop, each at the position of the light it
    holds (the Shadows block's point_light): a lamp in the second cube, third in the Lights
    block (a lamp casting and one not before it), casts the shadow the float64 rays give."""
    lamp = np.array([3.2, 1.3, 0.9])

    def build(world):
        world.spawn(Transform(position=(-4.0, 2.5, -3.0)), PointLight(intensity=1.0, range=6.0, shadows=True))
        world.spawn(Transform(position=(0.0, 3.0, -4.0)), PointLight(intensity=1.0, range=6.0, shadows=False))
        world.resources["ids"] = _floor_scene(world, (0.0, 5.5, 6.0), (0.0, 0.0, 0.0), sun=False,
                                              point=lamp.tolist())

    runner, ids, without, with_shadows = _render_both(scene, build, light="lamp")
    assert ("POINT_SHADOWS", "2") in runner.engine.renderer.shadows.program_defines
    share, counted, in_shadow, umbra_shadowed = _lamp_rays_agree(runner, ids, without, with_shadows, lamp)
    assert counted > 10000 and in_shadow > 800, (counted, in_shadow, share)
    assert share >= 0.99, f"{share:.4f} of {counted} floor pixels agree with the second cube's shadow rays"
    assert umbra_shadowed >= 0.95, f"{umbra_shadowed:.3f} of the umbra's pixels are shadowed"


@pytest.mark.parametrize("shadow_filter", ["single", "grid"])
def test_lit_surfaces_have_no_acne(scene, shadow_filter):
    """Every surface the light reaches unblocked (the rays say so, well away from any outline)
    is as bright with shadows as without: the sphere's lit side, the box's lit faces, the floor."""
    def build(world):
        world.resources["ids"] = _floor_scene(world, (2.5, 2.5, 4.0), (0.0, 0.5, 0.0))

    runner, ids, without, with_shadows = _render_both(scene, build, shadow_filter=shadow_filter)
    _, lit = _classified(without, with_shadows)
    seen = runner.ids()
    sphere = seen == ids["sphere"]
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    oc = eye - SPHERE_CENTRE
    b = (rays * oc).sum(-1)
    c = oc @ oc - SPHERE_RADIUS ** 2
    t = -b - np.sqrt(np.maximum(b * b - c, 0.0))
    normal = (eye + rays * t[..., None] - SPHERE_CENTRE) / SPHERE_RADIUS
    facing = normal @ -np.array(LIGHT, np.float64) > 0.25
    assert (sphere & facing).sum() > 500
    assert lit[sphere & facing].mean() >= 0.99
    top = eye + rays * ((1.0 - eye[1]) / rays[..., 1])[..., None]   # where each ray meets the box's top plane
    inside = np.all(np.abs(top[..., [0, 2]] - BOX_CENTRE[[0, 2]]) < BOX_HALF - 0.03, axis=-1)
    box_top = (seen == ids["box"]) & inside
    assert box_top.sum() > 200
    assert lit[box_top].mean() >= 0.99


def test_a_still_scene_draws_no_shadow_pass_and_a_moved_caster_draws_one(scene):
    def build(world):
        world.resources["ids"] = _floor_scene(world, (0.5, 5.0, 6.5), (0.0, 0.0, 0.0))

    runner = scene(build)
    ids = runner.world.resources["ids"]
    runner.frame()
    assert runner.stats.shadow_maps_drawn == 1
    runner.frame()
    runner.frame()
    assert (runner.stats.shadow_maps_drawn, runner.stats.shadow_maps_kept) == (0, 1)
    first = runner.frame()
    camera = runner.engine.active_camera()[0]
    runner.world.get(camera, Transform).position += glm.vec3(0.3, 0.0, 0.0)  # only the camera moves
    runner.frame()
    assert runner.stats.shadow_maps_drawn == 0
    runner.world.get(ids["box"], Transform).position += glm.vec3(0.0, 0.0, 0.8)
    moved = runner.frame()
    assert runner.stats.shadow_maps_drawn == 1
    runner.frame()
    assert runner.stats.shadow_maps_drawn == 0
    assert not np.array_equal(first, moved)


def test_a_still_suns_map_is_drawn_again_when_the_sun_changes_and_kept_otherwise(scene):
    """A still frame keeps the sun's map without looking at the sun's fields (the prepare
    stage's test: no DirectionalLight written this frame); each change to the sun draws it
    again: its direction assigned or edited in place (seen by the in-place watch), its
    softness, its resolution, and its shadows turned off and on; the frames before and after
    a turn differ, and turning back draws the first frame again."""
    def build(world):
        world.resources["ids"] = _floor_scene(world, (0.5, 5.0, 6.5), (0.0, 0.0, 0.0))

    runner = scene(build)
    runner.engine.renderer.antialias = "off"
    sun = runner.world.get(runner.world.resources["ids"]["sun"], DirectionalLight)
    runner.frame()
    runner.frame()
    first = runner.frame()
    assert (runner.stats.shadow_maps_drawn, runner.stats.shadow_maps_kept) == (0, 1)

    def drawn_after(change) -> np.ndarray:
        change()
        frame = runner.frame()
        assert runner.stats.shadow_maps_drawn == 1, change
        runner.frame()
        assert (runner.stats.shadow_maps_drawn, runner.stats.shadow_maps_kept) == (0, 1), change
        return frame

    turned = drawn_after(lambda: setattr(sun, "direction", glm.normalize(glm.vec3(1.0, -0.75, -0.5))))
    assert not np.array_equal(turned, first)
    back = drawn_after(lambda: setattr(sun, "direction", LIGHT))
    assert np.array_equal(back, first)
    direction = sun.direction
    edited = drawn_after(lambda: setattr(direction, "x", 0.4))   # in place, as a game's ``sun.direction.x = 0.4``
    assert not np.array_equal(edited, first)
    drawn_after(lambda: setattr(sun, "shadow_softness", 2.0))
    drawn_after(lambda: setattr(sun, "shadow_resolution", 1024))
    sun.shadows = False
    runner.frame()
    assert runner.stats.shadow_maps_drawn == runner.stats.shadow_maps_kept == 0
    drawn_after(lambda: setattr(sun, "shadows", True))


def _scene_programs(runner) -> list:
    """The scene programs built for the shadow lookups the maps now ask for."""
    scene_pass = runner.engine.renderer.scene_pass
    wanted = runner.engine.renderer.shadows.program_defines   # (a key's third from last: the fog's, the cookies' after)
    return [program for key, program in scene_pass.programs.built.items() if key[-3] == wanted]


def test_the_scene_programs_read_a_kind_of_map_only_while_a_light_of_that_kind_casts(scene):
    """No light casts: the scene programs are built without the shadow lookups (no atlas or
    cube sampler in them: llvmpipe would run a lookup that gives 1 for every pixel).  The sun
    casts: its build reads the atlas and its shadow shows; the lamp too: the cubes as well;
    both off again: the first frame's programs and pixels come back, byte for byte."""
    def build(world):
        world.resources["ids"] = _floor_scene(world, (0.5, 5.0, 6.5), (0.0, 0.0, 0.0), point=(0.5, 3.0, 1.5))

    runner = scene(build, (320, 240))
    runner.engine.renderer.antialias = "off"
    ids = runner.world.resources["ids"]
    sun = runner.world.get(ids["sun"], DirectionalLight)
    lamp = runner.world.get(ids["lamp"], PointLight)
    maps = runner.engine.renderer.shadows

    def samplers() -> set[tuple[bool, bool]]:
        built = _scene_programs(runner)
        assert built, "no scene program was built for the maps' lookups"
        return {("shadow_atlas" in program, "point_shadow0" in program) for program in built}

    sun.shadows = lamp.shadows = False
    plain = runner.frame()
    assert not {"DIRECTIONAL_SHADOWS", "POINT_SHADOWS"} & {name for name, _ in maps.program_defines}
    assert samplers() == {(False, False)}
    sun.shadows = True
    sunlit = runner.frame()
    assert samplers() == {(True, False)}
    shadowed, _ = _classified(plain, sunlit)
    assert shadowed[runner.ids() == ids["floor"]].sum() > 800   # the sun's shadow on the floor
    lamp.shadows = True
    both = runner.frame()
    assert samplers() == {(True, True)}
    shadowed, _ = _classified(sunlit, both)
    assert shadowed[runner.ids() == ids["floor"]].sum() > 200   # and now the lamp's
    sun.shadows = lamp.shadows = False
    assert np.array_equal(runner.frame(), plain)
    assert samplers() == {(False, False)}


@pytest.mark.parametrize("change", ["moved", "removed", "added"])
def test_a_changed_caster_redraws_only_its_footprint_and_the_frame_is_a_fresh_engines(scene, change):
    """The box moves (is deleted, or a second box comes) inside the level's box: the map's
    texels under where it was and is are drawn again, a small share of the map, and the frame
    is the one an engine made with the box already there draws (every texel as a whole
    redraw leaves it)."""
    def build_with(box_at, extra=False):
        def build(world):
            world.resources["ids"] = _floor_scene(world, (0.5, 5.0, 6.5), (0.0, 0.0, 0.0))
            box_id = world.resources["ids"]["box"]
            if box_at is None:
                world.delete_entity(box_id)
            else:
                world.get(box_id, Transform).position = glm.vec3(box_at)
            if extra:
                world.spawn(Transform(position=(2.5, 0.4, -2.0)), MeshRef(box((0.8, 0.8, 0.8))), Material())
        return build

    start, end = BOX_CENTRE.tolist(), [-1.6, 0.5, -0.7]
    runner = scene(build_with(start), (320, 240))
    runner.engine.renderer.antialias = "off"
    runner.frame()
    box_id = runner.world.resources["ids"]["box"]
    if change == "moved":
        runner.world.get(box_id, Transform).position = glm.vec3(end)
        fresh_build = build_with(end)
    elif change == "removed":
        runner.world.delete_entity(box_id)
        fresh_build = build_with(None)
    else:
        runner.world.spawn(Transform(position=(2.5, 0.4, -2.0)), MeshRef(box((0.8, 0.8, 0.8))), Material())
        fresh_build = build_with(start, extra=True)
    changed = runner.frame()
    resolution = DirectionalLight().shadow_resolution
    assert runner.stats.shadow_maps_drawn == 1
    assert 0 < runner.stats.shadow_texels_drawn < 0.1 * resolution * resolution
    fresh = scene(fresh_build, (320, 240))
    fresh.engine.renderer.antialias = "off"
    assert np.array_equal(changed, fresh.frame())


@pytest.mark.parametrize("turn", ["half_turn", "flipped"])
def test_a_caster_turned_within_its_own_box_draws_the_map_again(scene, turn):
    """The L (the still fuzz's, its box centred on its origin) turned half round exactly
    (the quaternion (0, 0, 1, 0)) or flipped by scale (-1, 1, -1) keeps its world box to the
    bit, so the box alone says nothing changed; its shadow did: the map is drawn again and
    the frame is a fresh engine's."""
    from benchmarks.still_fuzz import l_mesh

    mesh = l_mesh()

    def build_with(turned: bool):
        def build(world):
            look_from(world, (0.0, 6.0, 7.0), (0.0, 0.0, 0.0))
            world.spawn(DirectionalLight(direction=(-0.3, -0.8, -0.5), intensity=2.5))
            world.spawn(Transform(), MeshRef(plane(14, 14)), Material(color=(0.8, 0.8, 0.8)))
            transform = Transform(position=(0.0, 1.0, 0.0), scale=(2.0, 2.0, 2.0))  # standing on the floor
            if turned:
                transform.rotation, transform.scale = _TURNS[turn]
            world.resources["L"] = world.spawn(transform, MeshRef(mesh), Material())
        return build

    runner = scene(build_with(False))
    runner.engine.renderer.antialias = "off"
    first = runner.frame()
    runner.frame()
    transform = runner.world.get(runner.world.resources["L"], Transform)
    transform.rotation, transform.scale = _TURNS[turn]
    turned = runner.frame()
    assert runner.stats.shadow_maps_drawn == 1
    fresh = scene(build_with(True))
    fresh.engine.renderer.antialias = "off"
    np.testing.assert_array_equal(turned, fresh.frame())
    assert not np.array_equal(turned, first)


_TURNS = {"half_turn": (glm.quat(0.0, 0.0, 1.0, 0.0), glm.vec3(2.0)),
          "flipped": (glm.quat(), glm.vec3(-2.0, 2.0, -2.0))}


@pytest.mark.parametrize("change", ["raised", "removed_near", "removed_far"])
def test_a_caster_that_grows_or_shrinks_the_level_fits_the_map_again(scene, change):
    """The map covers the level's box (with slack: ``level_fit_box``), which the shadows
    stage keeps from frame to frame while no upload wrote a row and no row or batch went.

    - A box raised above the level's top (a row written) fits the map anew, with slack: a
      whole map is drawn, and the floor's shadows agree with float64 shadow rays from the
      raised box and the sphere.
    - The tallest box removed (its batch's last row: nothing is written, its old box is what
      changed), 4 m up: the level shrinks a little, so the fit is kept and only the texels
      under the removed box are drawn; the shadows agree with the rays.
    - The same 40 m up: the fit is over FIT_LOOSE times the level left, so it is fitted tight
      again (a whole map), and the frame is the one an engine built that way draws."""
    raised_centre = np.array([-1.0, 4.0, 0.0])
    tall_height = 40.0 if change == "removed_far" else 4.0

    def build_with(tall: bool, raised: bool = False, shadows: bool = True):
        def build(world):
            ids = world.resources["ids"] = _floor_scene(world, (0.5, 5.0, 6.5), (0.0, 0.0, 0.0))
            world.get(ids["sun"], DirectionalLight).shadows = shadows
            if raised:
                world.get(ids["box"], Transform).position = glm.vec3(*raised_centre)
            if tall:  # the box's twin (its batch), high over the floor: the level's top
                ids["tall"] = world.spawn(Transform(position=(2.0, tall_height, -2.0)),
                                          MeshRef(world.get(ids["box"], MeshRef).mesh), world.get(ids["box"], Material))
        return build

    def fresh(**how):
        runner = scene(build_with(**how), (320, 240))
        runner.engine.renderer.antialias = "off"
        return runner

    runner = fresh(tall=change != "raised")
    runner.frame()
    runner.frame()
    assert runner.stats.shadow_maps_drawn == 0 and runner.stats.shadow_maps_kept == 1
    ids = runner.world.resources["ids"]
    if change == "raised":
        runner.world.get(ids["box"], Transform).position = glm.vec3(*raised_centre)
    else:
        runner.world.delete_entity(ids["tall"])
    changed = runner.frame()
    resolution = DirectionalLight().shadow_resolution
    assert runner.stats.shadow_maps_drawn == 1
    if change == "removed_far":
        assert runner.stats.shadow_texels_drawn == resolution * resolution
        assert np.array_equal(changed, fresh(tall=False).frame())
        return
    if change == "raised":
        assert runner.stats.shadow_texels_drawn == resolution * resolution
    else:
        assert 0 < runner.stats.shadow_texels_drawn < resolution * resolution / 4
    runner.frame()
    assert runner.stats.shadow_maps_drawn == 0   # kept from here on
    raised = change == "raised"
    without = fresh(tall=False, raised=raised, shadows=False).frame()
    shadowed, lit = _classified(without, changed)
    floor = runner.ids() == ids["floor"]
    points = _floor_points_seen(runner)
    to_light = np.tile(-np.array(LIGHT, np.float64), (len(points), 1))

    def occluded(grow):
        box_centre = raised_centre if raised else BOX_CENTRE
        return (_hits(points, to_light, grow, casters=("sphere",))
                | box_hits(points, to_light, box_centre, BOX_HALF + grow)).reshape(floor.shape)

    share, counted, in_shadow = _agreement(shadowed, lit, floor, occluded(-PENUMBRA), occluded(PENUMBRA))
    assert counted > 40000 and in_shadow > 800, (counted, in_shadow, share)
    assert share >= 0.99, f"{share:.4f} of {counted} floor pixels agree with the shadow rays"


def test_a_point_light_ignores_changes_outside_its_reach(scene):
    def build(world):
        world.resources["ids"] = _floor_scene(world, (0.0, 5.5, 6.0), (0.0, 0.0, 0.0), sun=False,
                                              point=[3.2, 1.3, 0.9])
        world.resources["ids"]["far"] = world.spawn(Transform(position=(40.0, 0.5, 0.0)), MeshRef(box()), Material())

    runner = scene(build)
    ids = runner.world.resources["ids"]
    runner.world.get(ids["lamp"], PointLight).range = 9.0
    runner.frame()
    runner.frame()
    assert runner.stats.shadow_maps_drawn == 0
    runner.world.get(ids["far"], Transform).position += glm.vec3(1.0, 0.0, 0.0)  # 40 m away: out of reach
    runner.frame()
    assert runner.stats.shadow_maps_drawn == 0
    runner.world.get(ids["sphere"], Transform).position += glm.vec3(0.0, 0.2, 0.0)
    runner.frame()
    assert runner.stats.shadow_maps_drawn == 1
    runner.world.get(ids["lamp"], PointLight).shadow_softness = 2.0
    runner.frame()
    assert runner.stats.shadow_maps_drawn == 1


def test_point_lights_past_the_limit_are_counted_as_cut_and_said_once(scene):
    """Three lamps cast shadows and two cubes hold them: the third casts none, counted in
    ``shadows_cut`` every frame and said by a LightLimitWarning when it comes (not again when
    the lights are chosen again with the same cut)."""
    def build(world):
        look_from(world, (0, 3, 5), (0, 0, 0))
        world.spawn(Transform(), MeshRef(plane(6, 6)), Material())
        for x in (-2.0, 0.0, 2.0):
            world.spawn(Transform(position=(x, 1.5, 0.0)), PointLight(range=5.0, shadows=True))

    runner = scene(build)
    with pytest.warns(LightLimitWarning, match="3 point lights cast shadows: at most 2 have shadow cubes .* so 1 cast "
                                               r"none \(RenderStats.shadows_cut\)"):
        runner.frame()
    assert (runner.stats.shadow_maps_drawn, runner.stats.shadows_cut) == (2, 1)
    lamp = next(entity for entity, _ in runner.world.query_one(PointLight))
    runner.world.get(lamp, Transform).position += glm.vec3(0.0, 0.1, 0.0)   # (the lights chosen again)
    with warnings.catch_warnings():
        warnings.simplefilter("error", LightLimitWarning)
        runner.frame()
    assert runner.stats.shadows_cut == 1


@pytest.mark.parametrize("hidden_from_probes", [False, True])
def test_a_probe_face_recaptures_when_a_shadow_it_shows_moves(scene, hidden_from_probes):
    """The probe's -Y face sees the floor below it; the caster stands beside the probe, out of
    the probe's reach, but its shadow falls into that face; a thing moving far from the probe
    (its shadow far too) asks for nothing.  A caster hidden from probes
    (``Visibility(in_probes=False)``) is in no capture but casts in every view: the same."""
    def build(world):
        look_from(world, (0, 3, 6), (0, 0, 0))
        world.spawn(DirectionalLight(direction=(-1.0, -1.5, 0.0), intensity=2.0))
        world.spawn(Transform(), MeshRef(plane(60, 60)), Material())
        world.resources["probe"] = world.spawn(Transform(position=(0.0, 0.6, 0.0)),
                                               ReflectionProbe(resolution=16, far=2.0))
        world.resources["caster"] = world.spawn(Transform(position=(2.2, 2.6, 0.0)), MeshRef(box()), Material(),
                                                *([Visibility(in_probes=False)] if hidden_from_probes else []))
        world.resources["far"] = world.spawn(Transform(position=(20.0, 0.5, 20.0)), MeshRef(box()), Material())

    runner = scene(build)
    runner.frame()
    runner.frame()
    probe = runner.world.resources["probe"]
    assert probe not in runner.world.resources[ProbeSchedule].due
    runner.world.get(runner.world.resources["far"], Transform).position += glm.vec3(0.0, 0.0, 0.5)
    runner.frame()
    assert probe not in runner.world.resources[ProbeSchedule].due
    runner.world.get(runner.world.resources["caster"], Transform).position += glm.vec3(0.0, 0.0, 0.2)
    runner.frame()
    due = runner.world.resources[ProbeSchedule].due
    assert probe in due and 3 in due[probe].faces, due   # face 3: -Y, the floor the shadow falls on
    assert any(reason.startswith("shadow of entity") for reason in due[probe].reasons), due[probe].reasons


def test_the_filter_is_checked_and_a_new_one_draws_the_maps_again(scene):
    def build(world):
        world.resources["ids"] = _floor_scene(world, (0.5, 5.0, 6.5), (0.0, 0.0, 0.0))

    runner = scene(build)
    runner.frame()
    before = runner.frame()
    assert runner.stats.shadow_maps_drawn == 0
    maps = runner.engine.renderer.shadows
    maps.filter = "grid" if maps.filter == "single" else "single"
    after = runner.frame()
    assert runner.stats.shadow_maps_drawn == 1
    # The scene programs are built for the new filter (one tap known at build time, or the
    # grid): the shadow's edges change.
    assert (("SHADOW_SINGLE_TAP", "1") in maps.program_defines) == (maps.filter == "single")
    assert not np.array_equal(before, after)
    with pytest.raises(ValueError, match="shadow filter"):
        maps.filter = "pcss"


def test_shadow_fields_refuse_bad_values():
    with pytest.raises(ComponentValueError, match="power of two"):
        DirectionalLight(shadow_resolution=1000)
    with pytest.raises(ComponentValueError, match="shadow_resolution"):
        PointLight(shadow_resolution=1 << 14)
    with pytest.raises(ComponentValueError, match="shadow_softness"):
        DirectionalLight(shadow_softness=-1.0)
    with pytest.raises(ComponentValueError, match="shadows"):
        PointLight(shadows="yes")
    assert DirectionalLight().shadows and not PointLight().shadows


def _lamp_over_a_box(light_range: float, shadows: bool):
    def build(world) -> None:
        look_from(world, (0.0, 2.0, 4.0), (0.0, 0.5, 0.0))
        world.spawn(Transform(), MeshRef(plane(10, 10)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
        world.spawn(Transform(position=(0.0, 0.5, 0.0)), MeshRef(box()), Material(color=(0.5, 0.2, 0.2)))
        world.spawn(Transform(position=(0.5, 1.5, 0.5)), PointLight(intensity=10.0, range=light_range,
                                                                     shadows=shadows))
    return build


def test_a_point_lights_range_is_at_most_max_far_and_casts_its_shadow_there(scene):
    """A point light's range is its shadow cube's far plane: past float32's half range its
    perspective overflowed and the light cast no shadow at all, silently (a range of 3.4e38
    drew the frame of a light without shadows).  Refused past ``MAX_FAR`` as a camera's far
    plane is, naming the field; at ``MAX_FAR`` the box's shadow darkens the floor."""
    for bad in (3.4e38, 1e20, MAX_FAR * 1.5):
        with pytest.raises(ComponentValueError, match=r"PointLight\.range must be <= "):
            PointLight(range=bad)
    lamp = PointLight()
    with pytest.raises(ComponentValueError, match=r"PointLight\.range"):
        lamp.range = 1e30
    frames = [scene(_lamp_over_a_box(MAX_FAR, shadows), (48, 32)) for shadows in (True, False)]
    for runner in frames:  # (a GPU's FXAA searches along edges: a shadow by the box's edge moves its blend)
        runner.engine.renderer.antialias = "off"
    shadowed, lit = (runner.frame().astype(np.int32) for runner in frames)
    assert lit.mean() > 20
    darker = (lit - shadowed).sum(axis=-1)
    assert (darker > 0).sum() > 20 and (darker < 0).sum() == 0


LEVEL = """
[level]
name = "shadowed"

[[entity]]
name = "sun"
[entity.DirectionalLight]
direction = [-0.4, -1.0, -0.3]
shadows = false
shadow_resolution = 1024
shadow_softness = 2.5

[[entity]]
name = "lamp"
[entity.Transform]
position = [0.0, 2.0, 0.0]
[entity.PointLight]
range = 6.0
shadows = true
shadow_resolution = 256

[[entity]]
name = "beam"
[entity.Transform]
[entity.MeshRef]
mesh = { box = [0.05, 0.05, 2.0] }
casts_shadows = false
receives_shadows = false
"""


def test_level_files_carry_the_shadow_fields_and_refuse_bad_ones(tmp_path):
    from engine.assets.level_file import LevelError, load_level, save_level
    from engine.core.world import World

    path = tmp_path / "shadowed.toml"
    path.write_text(LEVEL)
    world = World("shadow level")
    names = load_level(path).spawn(world)
    sun, lamp = world.get(names["sun"], DirectionalLight), world.get(names["lamp"], PointLight)
    assert (sun.shadows, sun.shadow_resolution, sun.shadow_softness) == (False, 1024, 2.5)
    assert (lamp.shadows, lamp.shadow_resolution) == (True, 256)
    saved = save_level(world, tmp_path / "again.toml", names)
    again = World("again")
    names_again = load_level(saved).spawn(again)
    assert again.get(names_again["lamp"], PointLight).shadow_resolution == 256
    assert again.get(names_again["sun"], DirectionalLight).shadow_softness == 2.5
    for loaded, beam in ((world, names["beam"]), (again, names_again["beam"])):
        assert (loaded.get(beam, MeshRef).casts_shadows, loaded.get(beam, MeshRef).receives_shadows) == (False, False)
    path.write_text(LEVEL.replace("shadow_resolution = 1024", "shadow_resolution = 1000"))
    with pytest.raises(LevelError, match="shadow_resolution"):
        load_level(path)
    for field in ("casts_shadows", "receives_shadows"):
        path.write_text(LEVEL.replace(f"{field} = false", f"{field} = 0"))
        with pytest.raises(LevelError, match=field):
            load_level(path)


def test_a_redrawn_region_holds_the_box_corners_texels_and_only_its_padding_more():
    """``shadow_rules.map_region`` works the footprint out from the fit's two rows (lower and
    higher term per axis); the eight corners placed by glm, one at a time, say the same: the
    region holds every corner's texel with ``REGION_PAD`` around it and no more (a texel of
    rounding either side), and is None exactly when that padded box is most of the map."""
    import math

    from engine.rules.shadow_rules import REGION_PAD, REGION_WHOLE_SHARE, directional_fit, map_region

    rng = np.random.default_rng(11)
    wholes = 0
    for _ in range(2000):
        level_lo = rng.uniform(-30.0, 0.0, 3)
        level_hi = level_lo + rng.uniform(1.0, 60.0, 3)
        resolution = int(rng.choice([64, 512, 2048]))
        fit = directional_fit(glm.vec3(*[float(v) for v in rng.normal(size=3)]), level_lo, level_hi, resolution)
        lo = rng.uniform(level_lo, level_hi)
        hi = lo + rng.uniform(0.0, 4.0, 3) if rng.random() < 0.8 else level_hi  # some most of the level
        texels = []
        for x in (lo[0], hi[0]):
            for y in (lo[1], hi[1]):
                for z in (lo[2], hi[2]):
                    clip = fit.view_proj * glm.vec4(float(x), float(y), float(z), 1.0)
                    texels.append(((clip.x * 0.5 + 0.5) * resolution, (clip.y * 0.5 + 0.5) * resolution))
        xs, ys = [t[0] for t in texels], [t[1] for t in texels]
        x0, y0 = max(math.floor(min(xs)) - REGION_PAD, 0), max(math.floor(min(ys)) - REGION_PAD, 0)
        x1, y1 = min(math.ceil(max(xs)) + REGION_PAD, resolution), min(math.ceil(max(ys)) + REGION_PAD, resolution)
        region = map_region(fit, lo, hi, resolution)
        area = max(x1 - x0, 0) * max(y1 - y0, 0)
        if region is None:
            wholes += 1
            assert area >= REGION_WHOLE_SHARE * resolution * resolution * 0.99
            continue
        rx, ry, rw, rh = region
        assert rw > 0 and rh > 0
        assert abs(rx - x0) <= 1 and abs(ry - y0) <= 1 and abs(rx + rw - x1) <= 1 and abs(ry + rh - y1) <= 1
        # Every corner's texel is inside (the padding covers rounding).
        assert rx <= max(math.floor(min(xs)), 0) and rx + rw >= min(math.ceil(max(xs)), resolution)
        assert ry <= max(math.floor(min(ys)), 0) and ry + rh >= min(math.ceil(max(ys)), resolution)
    assert 0 < wholes < 2000


def test_a_batch_reads_its_rows_casting_only_while_one_casts_nothing(scene):
    """``InstanceBatch.may_not_cast`` (a moved row's box counts only if it casts) holds
    while some row of the batch casts no shadow, and goes when none does: the row turned
    back to casting, or deleted."""
    def build(world):
        world.resources["ids"] = _floor_scene(world, (0.5, 5.0, 6.5), (0.0, 0.0, 0.0))
        world.resources["ids"]["other"] = world.spawn(Transform(position=(2.0, 0.5, -1.0)), MeshRef(box()),
                                                      Material(color=(0.2, 0.8, 0.3)))

    runner = scene(build, (64, 48))
    runner.frame()
    ids = runner.world.resources["ids"]
    batch = next(b for b in runner.engine.renderer.batches.values() if ids["box"] in b.row_of)
    assert ids["other"] in batch.row_of and not batch.may_not_cast
    runner.world.get(ids["box"], MeshRef).casts_shadows = False
    runner.frame()
    assert batch.may_not_cast
    runner.world.get(ids["box"], MeshRef).casts_shadows = True
    runner.frame()
    assert not batch.may_not_cast
    runner.world.get(ids["other"], MeshRef).casts_shadows = False
    runner.frame()
    assert batch.may_not_cast
    runner.world.delete_entity(ids["other"])
    runner.frame()
    assert not batch.may_not_cast and ids["box"] in batch.row_of


def test_a_thing_that_casts_nothing_moving_at_the_levels_top_does_not_redraw_the_suns_map(ctx):
    """A screen that casts no shadow, held before the orbiting camera of the mirrors ring at the
    level's top: its box's top wobbles by float noise as the camera turns (the level's box
    with it, by about 2e-7 m), which fitted the sun's level map anew and drew it whole every
    frame (4,194,304 texels against about 170,000).  The level's box is on a millimetre grid
    (``level_on_grid``): after the first frames only the spinning boxes' texels are drawn, and
    the box read from the batches does wobble (what the grid absorbs)."""
    from benchmarks.cpu import make_scene
    from engine.core.frame_io import Output
    from engine.render.targets import CaptureTarget
    from engine.rules.shadow_rules import LEVEL_GRID

    engine = make_scene("mirrors_0", ctx)
    (camera, _), = engine.world.query_one(Camera)
    engine.world.spawn(Transform(position=(0.9, -0.45, -2.0), parent=camera),
                       MeshRef(quad(0.64, 0.36), casts_shadows=False), Material(color=(0.01, 0.01, 0.01)))
    capture = CaptureTarget(ctx, (64, 36))
    try:
        drawn, tops = [], []
        for _ in range(10):
            engine.frame(1.0 / 60.0, Output(capture.framebuffer, (64, 36)))
            drawn.append(engine.renderer.stats.shadow_texels_drawn)
            tops.append(float(engine.renderer.level_bounds()[1][1]))
        whole = engine.renderer.shadows.tile ** 2
        assert max(drawn[:2]) >= whole   # (the first frames draw the map whole)
        assert len(set(tops[2:])) > 1 and max(tops) - min(tops) < LEVEL_GRID / 100   # it wobbles, by noise
        assert all(0 < texels < whole / 4 for texels in drawn[2:]), drawn
    finally:
        capture.release()
        engine.close()


def test_the_suns_fit_follows_a_growing_level_with_slack_and_shrinks_back():
    """``level_fit_box`` against its own rules, on boxes worked out here: the first fit and a
    still level are the level's box; the fit always holds the level; a side the level
    outgrew moves FIT_SLACK of the diagonal past it; a thing climbing 10 cm a frame for 200
    frames refits a handful of times, not 200; a level back to its first size is fitted
    tight again once the fit is more than FIT_LOOSE times it."""
    from engine.rules.shadow_rules import FIT_LOOSE, FIT_SLACK, LEVEL_GRID, level_fit_box, level_on_grid

    def diagonal(box):
        return float(np.linalg.norm(box[1] - box[0]))

    floor = level_on_grid((np.array([-7.0, 0.0, -7.0]), np.array([7.0, 1.4, 7.0])))
    fitted = level_fit_box(None, floor)
    assert fitted is floor and level_fit_box(fitted, floor) is floor
    fits = [fitted]
    for frame in range(200):
        top = 1.5 + 0.1 * frame
        level = level_on_grid((floor[0], np.array([7.0, max(1.4, top), 7.0])))
        fitted = level_fit_box(fitted, level)
        assert np.all(fitted[0] <= level[0]) and np.all(fitted[1] >= level[1])
        assert diagonal(fitted) <= FIT_LOOSE * diagonal(level) + 4 * LEVEL_GRID
        if fitted is not fits[-1]:
            fits.append(fitted)
            # The side it outgrew moved FIT_SLACK of the level's diagonal past the level.
            assert abs(fitted[1][1] - (level[1][1] + FIT_SLACK * diagonal(level))) <= 2 * LEVEL_GRID
            assert np.array_equal(fitted[0], level[0]) and fitted[1][0] == 7.0 and fitted[1][2] == 7.0
    assert 3 <= len(fits) <= 8, len(fits)   # 1.4 m to 21.4 m: a handful of fits (each a quarter or more wider)
    # The thing gone: a fit within FIT_LOOSE times the level's diagonal is kept (the floor's
    # level: 1.6 times), one over it is the level's box again (a 6 m room's: 3.5 times).
    assert 1.0 < diagonal(fitted) / diagonal(floor) <= FIT_LOOSE and level_fit_box(fitted, floor) is fitted
    room = level_on_grid((np.array([-3.0, 0.0, -3.0]), np.array([3.0, 1.4, 3.0])))
    assert diagonal(fitted) / diagonal(room) > FIT_LOOSE and level_fit_box(fitted, room) is room
    # A level that shrinks a little keeps its fit (no refit for a thing that sank 10 cm).
    lower = level_on_grid((floor[0], np.array([7.0, 1.3, 7.0])))
    assert level_fit_box(floor, lower) is floor


@pytest.mark.parametrize("casts", [True, False], ids=["casting", "casting_nothing"])
def test_a_ball_thrown_up_out_of_the_level_does_not_redraw_the_suns_map_every_frame(scene, casts):
    """A ball rising 15 cm a frame out of the top of the level (its box's top is the level's):
    fitted to the level's box the sun's map was fitted anew and drawn whole every frame, and
    every shadow in the level slid with its texels.  With the fit's slack
    (``level_fit_box``) it is drawn whole on the first frame and once when the ball first
    outgrows the level; after that only the ball's texels (a casting ball) or nothing (one
    that casts nothing).  At the end the box's and sphere's shadows on the floor agree with
    float64 shadow rays (the ball stands where its shadow misses the floor)."""
    def build(world):
        ids = world.resources["ids"] = _floor_scene(world, (0.5, 5.0, 6.5), (0.0, 0.0, 0.0))
        ids["ball"] = world.spawn(Transform(position=(-6.5, 1.0, -6.5)),
                                  MeshRef(sphere(0.2, segments=16), casts_shadows=casts),
                                  Material(color=(0.9, 0.9, 0.2)))

    runner = scene(build, (320, 240))
    runner.engine.renderer.antialias = "off"
    runner.engine.renderer.shadows.filter = "single"
    ids = runner.world.resources["ids"]
    sun = runner.world.get(ids["sun"], DirectionalLight)
    sun.shadows = False
    without = runner.frame()
    sun.shadows = True
    whole = sun.shadow_resolution ** 2
    drawn = []
    for frame in range(24):
        runner.world.get(ids["ball"], Transform).position = (-6.5, 1.0 + 0.15 * frame, -6.5)
        with_shadows = runner.frame()
        drawn.append(runner.stats.shadow_texels_drawn)
    wholes = [frame for frame, texels in enumerate(drawn) if texels >= whole]
    assert wholes[0] == 0 and len(wholes) == 2, drawn   # the first frame, then the ball outgrowing the level
    later = drawn[wholes[1] + 1:]
    assert len(later) >= 18
    assert all(0 < texels < whole / 20 for texels in later) if casts else all(texels == 0 for texels in later), drawn
    shadowed, lit = _classified(without, with_shadows)
    floor = runner.ids() == ids["floor"]
    share, counted, in_shadow, umbra = _sun_rays_agree(shadowed, lit, floor, _floor_points_seen(runner))
    assert counted > 40000 and in_shadow > 800, (counted, in_shadow, share)
    assert share >= 0.99, f"{share:.4f} of {counted} floor pixels agree with the shadow rays"
    assert shadowed[umbra].mean() >= 0.95


@pytest.mark.parametrize("cascades", [1, 3])
def test_the_second_of_two_crates_removed_takes_its_shadow_with_it(scene, cascades):
    """Two crates of one mesh (one batch), the second removed inside the level: its batch's
    last row goes, no row is written (``casters_version`` stays), only the changed box says
    so.  The sun's map (and its cascades) kept it: the crate's shadow stayed on the floor
    (145 pixels at 160x120 before the fix).  Now the texels under it are drawn again and
    the frame is the one an engine built without the second crate draws."""
    def build_with(twin: bool):
        def build(world):
            ids = world.resources["ids"] = _floor_scene(world, (0.5, 5.0, 6.5), (0.0, 0.0, 0.0))
            world.get(ids["sun"], DirectionalLight).shadow_cascades = cascades
            if twin:
                ids["twin"] = world.spawn(Transform(position=(2.5, 0.5, -2.0)),
                                          MeshRef(world.get(ids["box"], MeshRef).mesh), world.get(ids["box"], Material))
        return build

    runner = scene(build_with(True))
    runner.engine.renderer.antialias = "off"
    runner.frame()
    before = runner.frame()
    assert runner.stats.shadow_maps_drawn == 0
    runner.world.delete_entity(runner.world.resources["ids"]["twin"])
    after = runner.frame()
    resolution = DirectionalLight().shadow_resolution
    assert runner.stats.shadow_maps_drawn >= 1 and 0 < runner.stats.shadow_texels_drawn < resolution * resolution
    fresh = scene(build_with(False))
    fresh.engine.renderer.antialias = "off"
    without = fresh.frame()
    assert (np.abs(before.astype(int) - without).max(axis=-1) > 3).sum() > 100   # the crate and its shadow were there
    assert np.array_equal(after, without)


# --- see-through things: the share of a sun's light they let through (ShadowMaps.see_through_atlas)
PANE_AT, PANE_HALF = np.array([0.0, 2.0, 0.0]), 1.0    # a 2 m square pane, flat, 2 m over the floor
SUN_DOWN = glm.normalize(glm.vec3(0.0, -1.0, -0.3))


# Where ``_pane_scene``'s ``lamp`` stands: a point light 0.9 m over the pane (which spans
# three of its cube's faces), a spot 4 m over it (its cone reaches past the pane's shadow).
LAMPS_AT = {"point": np.array([-0.3, 2.9, 0.2]), "spot": np.array([-0.3, 6.0, 0.2])}


def _pane_scene(alpha, casts=True, glass=False, sun=2.5, second=None, above=False, post=True, lamp=None,
                turn=None, lamp_before=False, sun_before=False):
    """A floor, a sun nearly overhead, a flat see-through pane (``alpha``; ``glass``: a
    Refractive, drawn with the opaque batches), a second one under it (``second``: its alpha;
    both cast or neither: ``casts``),
    a box hanging over the pane (``above``) and a 3 m post (the level's top, so the pane
    moving or going leaves the level's box as it is).  ``lamp`` ("point", or "spot": a cone
    40 degrees a side, looking down) lights it instead of the sun, from LAMPS_AT (``sun``:
    its intensity over 2.5, the sun's).  ``turn`` (a glm quaternion) turns the whole scene,
    camera and lamp too, about the origin.  ``lamp_before``: a casting point light spawned
    first, in a corner, whose 3 m range reaches neither the pane nor the floor under it.
    ``sun_before``: a weak sun from elsewhere spawned first, casting no shadow."""
    def build(world):
        ids = world.resources["ids"] = {}
        look_from(world, (0.0, 6.0, 6.0), (0.0, 0.0, 0.0))
        if sun_before:
            world.spawn(DirectionalLight(direction=(0.5, -1.0, 0.4), intensity=0.4, shadows=False))
        if lamp_before:
            ids["lamp_before"] = world.spawn(Transform(position=(-6.0, 1.5, 6.0)),
                                             PointLight(intensity=4.0, range=3.0, shadows=True))
        if lamp is None:
            world.spawn(DirectionalLight(direction=tuple(SUN_DOWN), intensity=sun))
        else:
            down = glm.angleAxis(-math.pi / 2, glm.vec3(1, 0, 0))   # its -Z (a spot's axis) down
            ids["lamp"] = world.spawn(Transform(position=tuple(LAMPS_AT[lamp]), rotation=down),
                                      PointLight(intensity=(12.0 if lamp == "point" else 40.0) * sun, range=14.0,
                                                 shadows=True, **({"spot_angle": 40.0} if lamp == "spot" else {})))
        ids["floor"] = world.spawn(Transform(), MeshRef(plane(14, 14)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
        flat = glm.angleAxis(-math.pi / 2, glm.vec3(1, 0, 0))
        parts = [Transform(position=tuple(PANE_AT), rotation=flat),
                 MeshRef(quad(2 * PANE_HALF, 2 * PANE_HALF), casts_shadows=casts),
                 Material(color=(0.2, 0.3, 0.9, alpha), double_sided=True)]
        ids["pane"] = world.spawn(*parts, *([Refractive(screen=False)] if glass else []))
        if second is not None:
            ids["second"] = world.spawn(Transform(position=tuple(PANE_AT - [0.0, 1.0, 0.0]), rotation=flat),
                                        MeshRef(quad(2 * PANE_HALF, 2 * PANE_HALF), casts_shadows=casts),
                                        Material(color=(0.9, 0.3, 0.2, second), double_sided=True))
        if above:
            ids["above"] = world.spawn(Transform(position=(0.0, 2.6, 0.0)), MeshRef(box((0.5, 0.2, 0.5))),
                                       Material(color=(0.9, 0.8, 0.2)))
        if post:
            world.spawn(Transform(position=(-5.0, 1.5, -5.0)), MeshRef(box((0.2, 3.0, 0.2))), Material())
        if turn is not None:
            for _, (transform,) in world.query(Transform):
                transform.position = turn * glm.vec3(transform.position)
                transform.rotation = turn * transform.rotation
    return build


def _pane_frames(scene, shadow_filter="single", size=(320, 240), **how):
    """The frame (``size``) with the pane (``how``), and the floor's share of the direct sunlight (or
    lamplight) the pane's dimming took away at each pixel: (without - with) / (without -
    sunless), where "without" has a pane that casts nothing and "sunless" no light: engines
    built apart.  (A pixel the light does not reach: 0.)"""
    frames = {}
    for name, extra in (("with", {}), ("without", {"casts": False}), ("sunless", {"casts": False, "sun": 0.0})):
        runner = scene(_pane_scene(**{**how, **extra}), size)
        runner.engine.renderer.antialias = "off"
        runner.engine.renderer.shadows.filter = shadow_filter
        runner.frame()
        frames[name] = (runner, srgb_to_linear(runner.frame()).mean(axis=-1))
    with_, without, sunless = (frames[name][1] for name in ("with", "without", "sunless"))
    lit = without - sunless
    return frames["with"][0], np.where(lit > 0.02, (without - with_) / np.maximum(lit, 1e-6), 0.0), lit > 0.02


def _under_pane(runner, margin: float, lamp: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The floor pixels whose ray to the sun (``lamp``: to LAMPS_AT's) meets the pane (shrunk by
    ``margin`` metres), and those whose ray misses it grown by ``margin``, worked out in float64."""
    ids = runner.world.resources["ids"]
    floor = runner.ids() == ids["floor"]
    points = _floor_points_seen(runner)
    to_sun = LAMPS_AT[lamp] - points if lamp else -np.array(SUN_DOWN, np.float64)[None, :]
    t = (PANE_AT[1] - points[:, 1]) / to_sun[:, 1]
    at = points + to_sun * t[:, None]
    reach = np.maximum(np.abs(at[:, 0] - PANE_AT[0]), np.abs(at[:, 2] - PANE_AT[2])).reshape(floor.shape)
    return floor & (reach < PANE_HALF - margin), floor & (reach > PANE_HALF + margin)


def _assert_share(taken: np.ndarray, under: np.ndarray, beside: np.ndarray, alpha: float,
                  least: tuple[int, int] = (3000, 3000)) -> None:
    """Under the pane (``under``: more than ``least[0]`` pixels) the floor lost ``alpha`` of the
    light (``taken``, ``_pane_frames``'): the median to 0.03, 95% of the pixels to 0.05; beside
    it (more than ``least[1]``) none of it, to 0.02."""
    assert under.sum() > least[0] and beside.sum() > least[1], (under.sum(), beside.sum())
    assert abs(float(np.median(taken[under])) - alpha) < 0.03, np.percentile(taken[under], [5, 50, 95])
    assert np.percentile(np.abs(taken[under] - alpha), 95) < 0.05, np.percentile(taken[under], [5, 50, 95])
    assert np.abs(taken[beside]).max() < 0.02


@pytest.mark.parametrize("alpha, glass, shadow_filter", [(0.25, False, "single"), (0.7, False, "grid"),
                                                        (0.4, True, "single")])
def test_a_see_through_pane_takes_its_alpha_of_the_suns_light(scene, alpha, glass, shadow_filter):
    """A see-through pane (the transparent slot's; or glass, drawn with the opaque batches)
    lets 1 - alpha of the sun's light through, as much as shows through it: under it, by the
    rays, the floor loses alpha of its direct sunlight (to 0.03: the map's half floats and the
    8-bit frames); beside it, nothing."""
    runner, taken, _ = _pane_frames(scene, shadow_filter, alpha=alpha, glass=glass)
    under, beside = _under_pane(runner, 0.08)
    _assert_share(taken, under, beside, alpha, least=(800, 20000))
    assert ("SEE_THROUGH_SHADOWS", "1") in runner.engine.renderer.shadows.program_defines


@pytest.mark.parametrize("lamp, alpha, glass, shadow_filter", [("point", 0.5, False, "single"),
                                                              ("point", 0.4, True, "grid"),
                                                              ("spot", 0.6, False, "single")])
def test_a_see_through_pane_takes_its_alpha_of_a_lamps_light(scene, lamp, alpha, glass, shadow_filter):
    """The same under a point light 0.9 m over the pane, which spans three of its cube's faces
    (the lamps' see-through tiles: a face each, the one GL's cube lookup takes), and under a
    spot's map 4 m over it: under the pane, by the rays to the lamp, the floor the lamp reaches loses
    alpha of its light; beside it, nothing."""
    runner, taken, lit = _pane_frames(scene, shadow_filter, alpha=alpha, glass=glass, lamp=lamp)
    under, beside = _under_pane(runner, 0.08, lamp=lamp)
    _assert_share(taken, under & lit, beside & lit, alpha)
    defines = dict(runner.engine.renderer.shadows.program_defines)
    assert defines.get("LAMP_SEE_THROUGH_SHADOWS") == "1" and ("SPOT_MAP0" in defines) == (lamp == "spot")


# A half turn about (1, 0, 1): the lamp's -Y, +X and -Z faces, the ones the pane spans as
# it stands, become its +Y, +Z and -X: the two scenes between them put the pane in all six.
HALF_TURN_XZ = glm.angleAxis(math.pi, glm.normalize(glm.vec3(1.0, 0.0, 1.0)))


@pytest.mark.parametrize("turned", [False, True], ids=["-Y+X-Z", "+Y+Z-X"])
def test_a_see_through_pane_takes_its_alpha_of_a_point_lights_light_through_every_face(scene, turned):
    """The point light over the pane, the scene as it stands and turned half about (1, 0, 1)
    (HALF_TURN_XZ): between them the pane lies in each of the six faces of the lamp's cube,
    and in each face's own share of the floor under the pane (the face GL's cube lookup takes
    for the ray from the lamp, worked out here by the largest of its axes) the floor loses
    alpha of the lamp's light.  A face whose see-through tile is drawn or read as another's
    lets the whole light through there, or dims where no pane is."""
    alpha, turn = 0.5, HALF_TURN_XZ if turned else glm.quat()
    runner, taken, lit = _pane_frames(scene, alpha=alpha, lamp="point", turn=turn, size=(480, 360))
    rotation = np.array(glm.mat3_cast(turn).to_list(), np.float64).T   # column-major -> rows: R @ x
    normal = rotation @ np.array([0.0, 1.0, 0.0])
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    t = -(eye @ normal) / (rays @ normal)
    points = (eye + rays * t[..., None]).reshape(-1, 3)        # the (turned) floor's points, world space
    local = points @ rotation                                  # R^T: the scene as it stands
    to_lamp = LAMPS_AT["point"] - local
    at = local + to_lamp * ((PANE_AT[1] - local[:, 1]) / to_lamp[:, 1])[:, None]
    reach = np.maximum(np.abs(at[:, 0] - PANE_AT[0]), np.abs(at[:, 2] - PANE_AT[2])).reshape(lit.shape)
    floor = (runner.ids() == runner.world.resources["ids"]["floor"]) & lit
    under, beside = floor & (reach < PANE_HALF - 0.08), floor & (reach > PANE_HALF + 0.08)
    away = points - rotation @ LAMPS_AT["point"]                 # lamp to floor, world space
    axis = np.abs(away).argmax(axis=1)
    face = (2 * axis + (away[np.arange(len(away)), axis] < 0)).reshape(lit.shape)   # +X -X +Y -Y +Z -Z
    names = ("+X", "-X", "+Y", "-Y", "+Z", "-Z")
    expected = ("-Y", "+X", "-Z") if not turned else ("+Y", "+Z", "-X")
    for name in expected:
        mine = under & (face == names.index(name))
        assert mine.sum() > 300, (name, mine.sum())
        assert abs(float(np.median(taken[mine])) - alpha) < 0.03, (name, np.percentile(taken[mine], [5, 50, 95]))
        assert np.percentile(np.abs(taken[mine] - alpha), 95) < 0.05, (name, np.percentile(taken[mine], [5, 50, 95]))
    assert beside.sum() > 3000 and np.abs(taken[beside]).max() < 0.02


def test_a_sun_in_the_second_shadow_slot_reads_its_own_see_through_map(scene):
    """A sun casting no shadow spawned first (directional slot 0), the pane's sun second
    (slot 1, DIRECTIONAL_SHADOWS 2): under the pane the floor loses alpha of the second
    sun's light, beside it nothing."""
    alpha = 0.4
    runner, taken, _ = _pane_frames(scene, alpha=alpha, sun_before=True)
    assert ("DIRECTIONAL_SHADOWS", "2") in runner.engine.renderer.shadows.program_defines
    under, beside = _under_pane(runner, 0.08)
    _assert_share(taken, under, beside, alpha, least=(800, 20000))


@pytest.mark.parametrize("lamp", ["point", "spot"])
def test_a_lamp_in_the_second_shadow_slot_reads_its_own_see_through_tiles(scene, lamp):
    """A casting lamp in a far corner, its range short of the pane, takes the first shadow
    slot; the lamp over the pane takes the second, whose row of see-through tiles (a point
    light's six, a spot's first) holds the pane: under it the floor loses alpha of that
    lamp's light, beside it nothing (a lookup in the first slot's row reads no pane)."""
    alpha = 0.5
    runner, taken, lit = _pane_frames(scene, alpha=alpha, lamp=lamp, lamp_before=True)
    shadows = runner.engine.renderer.shadows
    assert shadows._lamp_through[0, 2] == 0.0 and shadows._lamp_through[1, 2] > 0.0   # (slot 1's tiles hold it)
    under, beside = _under_pane(runner, 0.08, lamp=lamp)
    _assert_share(taken, under & lit, beside & lit, alpha)


def test_two_see_through_panes_let_through_the_product_and_what_is_over_them_keeps_its_light(scene):
    """Two panes one over the other (alphas 0.5 and 0.4): the floor under both keeps
    (1 - 0.5) x (1 - 0.4) = 0.3 of its sunlight, a share of 0.7 taken; a box hanging over
    the upper pane (nearer the sun than either) loses none of its light."""
    runner, taken, _ = _pane_frames(scene, alpha=0.5, second=0.4, above=True)
    under, _ = _under_pane(runner, 0.15)
    # (under the box's own shadow too: only where the box does not shade)
    ids = runner.world.resources["ids"]
    assert abs(float(np.median(taken[under & (taken < 0.9)])) - 0.7) < 0.03
    top = runner.ids() == ids["above"]
    assert top.sum() > 50 and np.abs(taken[top]).max() < 0.02


@pytest.mark.parametrize("lamp, glass", [(None, False), (None, True), ("point", False), ("point", True),
                                         ("spot", False)])
def test_a_see_through_pane_moved_faded_or_removed_draws_what_a_fresh_engine_draws(scene, lamp, glass):
    """The pane (or a glass one, among the opaque batches) slides 1.5 m: its share is drawn
    again under where it was and is (a sun's: a region of the map; a lamp's: its map whole),
    and the frame is the one an engine built with the pane there draws; its alpha goes from
    0.6 to 0.3 (a row's alpha, the share it lets through: the map drawn again), the same;
    then it is removed: the frame is one with no pane at all, and the see-through atlas is
    let go.  (The alpha's change was kept out of the map at first: the still fuzz's seed 12,
    case 16.)"""
    runner = scene(_pane_scene(0.6, glass=glass, lamp=lamp), (160, 120))
    runner.engine.renderer.antialias = "off"
    runner.frame()
    runner.frame()
    ids = runner.world.resources["ids"]
    runner.world.get(ids["pane"], Transform).position = (1.5, 2.0, 0.0)
    moved = runner.frame()
    resolution = DirectionalLight().shadow_resolution

    def drawn_again() -> bool:
        if lamp is not None:
            return runner.stats.shadow_maps_drawn == 1
        return runner.stats.shadow_maps_drawn == 1 and 0 < runner.stats.shadow_texels_drawn < resolution ** 2 / 4

    assert drawn_again()

    def there(alpha):
        def build(world):
            _pane_scene(alpha, glass=glass, lamp=lamp)(world)
            world.get(world.resources["ids"]["pane"], Transform).position = (1.5, 2.0, 0.0)
        return build

    fresh = scene(there(0.6), (160, 120))
    fresh.engine.renderer.antialias = "off"
    assert np.array_equal(moved, fresh.frame())
    runner.world.get(ids["pane"], Material).color = (0.2, 0.3, 0.9, 0.3)
    faded = runner.frame()
    assert drawn_again()
    fresh = scene(there(0.3), (160, 120))
    fresh.engine.renderer.antialias = "off"
    assert np.array_equal(faded, fresh.frame())
    runner.world.delete_entity(ids["pane"])
    gone = runner.frame()
    bare = scene(_pane_scene(0.6, casts=False, lamp=lamp), (160, 120))
    bare.engine.renderer.antialias = "off"
    bare.world.delete_entity(bare.world.resources["ids"]["pane"])
    assert np.array_equal(gone, bare.frame())
    shadows = runner.engine.renderer.shadows   # none casts: its atlas let go
    assert shadows.see_through_atlas is None and shadows.lamp_see_through_atlas is None


@pytest.mark.parametrize("lamp", [None, "point"])
def test_without_a_unit_for_the_see_through_map_the_pane_casts_nothing_and_says_so(scene, lamp):
    """A context whose fragment stage has too few texture units (macOS's 16) for the
    see-through map (a sun's; a lamp's, one more): a GLLimitWarning names the count, once,
    and the pane dims nothing."""
    from engine.core.errors import GLLimitWarning
    from engine.render.bindings import LAMP_SEE_THROUGH_SAMPLERS, SEE_THROUGH_SAMPLERS

    runner = scene(_pane_scene(0.6, lamp=lamp), (160, 120))
    runner.engine.renderer.antialias = "off"
    shadows = runner.engine.renderer.shadows
    if lamp is None:
        shadows.see_through_supported, needed, define = False, SEE_THROUGH_SAMPLERS, "SEE_THROUGH_SHADOWS"
    else:
        shadows.lamp_see_through_supported, needed, define = False, LAMP_SEE_THROUGH_SAMPLERS, \
            "LAMP_SEE_THROUGH_SHADOWS"
    with pytest.warns(GLLimitWarning, match=f"need[s]? {needed} texture units"):
        frame = runner.frame()
    with warnings.catch_warnings():
        warnings.simplefilter("error", GLLimitWarning)
        runner.frame()
    bare = scene(_pane_scene(0.6, casts=False, lamp=lamp), (160, 120))
    bare.engine.renderer.antialias = "off"
    assert np.array_equal(frame, bare.frame())
    assert not any(name == define for name, _ in shadows.program_defines)


def test_a_lamp_draws_only_the_see_through_things_in_its_reach(scene):
    """The pane 20 m from a point light of range 14: the lamps' see-through map is made (a
    see-through thing and a casting lamp), but the lamp's tiles draw nothing and its slot
    reads none; the same pane under it costs its six faces' draws, one a face."""
    def build(far: bool):
        def make(world):
            _pane_scene(0.6, lamp="point")(world)
            if far:
                world.get(world.resources["ids"]["pane"], Transform).position = (20.0, 2.0, 0.0)
        return make

    draws = {}
    for far in (False, True):
        runner = scene(build(far), (64, 48))
        runner.frame()
        shadows = runner.engine.renderer.shadows
        assert shadows.lamp_see_through_atlas is not None
        lamp_row = shadows._lamp_through[0]
        assert (lamp_row[2] == 0.0) == far, lamp_row
        draws[far] = runner.stats.shadow_draw_calls
    assert draws[False] - draws[True] == 6, draws


def test_a_lamps_own_glass_bulb_dims_none_of_its_light(scene):
    """A point light on the entity of a glass sphere round it (its bulb: a light's own mesh
    casts none of its shadow) lights the floor as the light alone does, though the bulb is in
    the lamps' see-through map (which the pane under it keeps in use)."""
    def build(bulb: bool):
        def make(world):
            _pane_scene(0.6, lamp="point")(world)
            lamp = world.resources["ids"]["lamp"]
            if bulb:
                world.add_component(lamp, MeshRef(sphere(0.15)))
                world.add_component(lamp, Material(color=(1.0, 1.0, 1.0, 0.5)))
                world.add_component(lamp, Refractive(screen=False))
        return make

    frames = []
    for bulb in (False, True):
        runner = scene(build(bulb), (160, 120))
        runner.engine.renderer.antialias = "off"
        runner.frame()
        frame = runner.frame()
        assert runner.engine.renderer.shadows.lamp_see_through_atlas is not None
        floor = runner.ids() == runner.world.resources["ids"]["floor"]
        frames.append((frame, floor))
    (alone, floor), (with_bulb, floor_with) = frames
    both = floor & floor_with
    assert both.sum() > 5000
    assert np.array_equal(alone[both], with_bulb[both])


def test_only_the_glass_of_an_opaque_batch_goes_into_the_see_through_map(scene):
    """Glass is drawn with the opaque batches: a glass pane and a solid pane of the same mesh
    share a batch, and only the glass's instance is drawn into the see-through map (the solid
    one is the depth map's): the texels it dims are those of the glass pane alone."""
    mesh = quad(2 * PANE_HALF, 2 * PANE_HALF)
    flat = glm.angleAxis(-math.pi / 2, glm.vec3(1, 0, 0))

    def dimmed_texels(solid_twin: bool) -> int:
        def build(world):
            _pane_scene(0.0, casts=False)(world)
            world.spawn(Transform(position=(-2.5, 2.0, 0.0), rotation=flat), MeshRef(mesh),
                        Material(color=(0.2, 0.3, 0.9, 0.4), double_sided=True), Refractive(screen=False))
            if solid_twin:
                world.spawn(Transform(position=(2.5, 2.0, 0.0), rotation=flat), MeshRef(mesh),
                            Material(color=(0.2, 0.3, 0.9, 1.0), double_sided=True))
        runner = scene(build, (64, 48))
        runner.frame()
        glass = [batch for batch in runner.engine.renderer.see_through_casters() if not batch.transparent]
        assert len(glass) == 1 and glass[0].count == (2 if solid_twin else 1)
        atlas = runner.engine.renderer.shadows.see_through_atlas
        texels = np.frombuffer(atlas.read(), np.float16).reshape(atlas.size[1], atlas.size[0], 4)
        return int((texels[..., 0] < 0.99).sum())

    alone = dimmed_texels(False)
    assert alone > 1000 and dimmed_texels(True) == alone
