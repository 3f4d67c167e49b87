"""Local fog volumes (``FogVolume``): ellipsoids of air whose density falls from the centre as
1 - r^2.  Real frames on llvmpipe against a second computation (``tests/test_fog.py``'s
scene and way): each pixel's way from the eye cast in float64 (to the floor, the sky, or the
mirror and on), each volume's density (its ellipsoid from the component's own numbers, not
the engine's matrix) integrated numerically along each straight stretch, and the fogged
frame the clear one mixed towards the air's light by exp(-depth), that light each fog's
colour weighed by its own depth (the engine's model: exact where one fog lies on a way)."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, Fog, FogVolume, Transform, VolumetricFog
from components.limits import MAX_FOG_VOLUMES
from engine.core.errors import FogLimitWarning
from engine.render.fog import ROW_FLOATS
from tests.support import pixel_rays, srgb_to_linear
from tests.test_fog import FOG_COLOR, MIRROR_Z, _close, _depth, _floor_hits, _scene

# (centre, size, yaw in degrees, density, colour): an orange bank lying on the floor in front
# of the crate, turned 30 degrees; a blue ball to its left and behind, overlapping it.
ORANGE = ((0.5, 0.6, 1.0), (4.0, 1.6, 3.0), 30.0, 0.6, (0.9, 0.6, 0.3))
BLUE = ((-1.8, 1.0, -0.5), (3.0, 3.0, 3.0), 0.0, 0.45, (0.3, 0.5, 0.9))
BEHIND = ((0.5, 1.0, 3.0), (3.0, 2.0, 2.0), 0.0, 0.8, (0.8, 0.8, 0.8))   # behind the eye, seen in the mirror


def _with(volumes, fog: Fog | None = None, mirror: bool = False, scale=(1.0, 1.0, 1.0)):
    """``_scene`` with ``volumes`` on entities of their own, each Transform scaled by ``scale``
    (which a volume leaves out: its ``size`` alone gives its ellipsoid)."""
    base = _scene(fog, mirror)

    def build(world):
        base(world)
        for centre, size, yaw, density, colour in volumes:
            world.spawn(Transform(position=centre, rotation=glm.angleAxis(math.radians(yaw), glm.vec3(0, 1, 0)),
                                  scale=scale),
                        FogVolume(size=size, density=density, color=colour))
    return build


def _frame(scene, build, size=(160, 100)):
    runner = scene(build, size)
    runner.engine.renderer.antialias = "off"
    return runner, srgb_to_linear(runner.frame()).reshape(-1, 3)


def _volume_depth(a: np.ndarray, b: np.ndarray, volume, samples: int = 600) -> np.ndarray:
    """One volume's optical depth along each stretch a -> b (rows), by the trapezoid rule:
    the point taken into the ellipsoid's frame (turned back by its yaw, over its half sides),
    density (1 - r^2) inside."""
    centre, size, yaw, density, _ = volume
    t = np.linspace(0.0, 1.0, samples)
    c, s = math.cos(math.radians(yaw)), math.sin(math.radians(yaw))
    out = np.empty(len(a))
    for first in range(0, len(a), 2048):
        part = slice(first, first + 2048)
        points = a[part, None, :] + (b - a)[part, None, :] * t[None, :, None] - np.asarray(centre)
        # (a turn by yaw about +y takes x to (c, 0, -s) and z to (s, 0, c): the point's
        # coordinates along those axes)
        local = np.stack([points[..., 0] * c - points[..., 2] * s, points[..., 1],
                          points[..., 0] * s + points[..., 2] * c], axis=-1) / (np.asarray(size) / 2.0)
        out[part] = np.trapezoid(np.maximum(1.0 - (local ** 2).sum(axis=-1), 0.0), t, axis=1)
    return density * out * np.linalg.norm(b - a, axis=1)


def _over(colour: np.ndarray, a: np.ndarray, b: np.ndarray, volumes, fog: Fog | None) -> np.ndarray:
    """``colour`` seen through the stretches a -> b: each fog's depth, the light they add their
    colours weighed by their depths."""
    depths = [_volume_depth(a, b, v) for v in volumes]
    light = sum(d[:, None] * np.asarray(v[4]) for d, v in zip(depths, volumes, strict=True))
    total = sum(depths)
    if fog is not None:
        height = _depth(a, b, fog)
        light = light + height[:, None] * FOG_COLOR
        total = total + height
    keep = np.exp(-total)[:, None]
    air = np.where(total[:, None] > 0.0, light / np.maximum(total[:, None], 1e-30), 0.0)
    return colour * keep + air * (1.0 - keep)


@pytest.mark.parametrize("case", ["one", "two_and_height_fog"])
def test_the_floor_is_fogged_by_the_volumes_it_is_seen_through(scene, case):
    """Each floor pixel is the clear frame's fogged by the orange bank (alone, no camera Fog:
    the FOG build comes for the volume), or by the bank, the blue ball it overlaps and the
    camera's uniform fog, along its way from the eye, the volumes' entities scaled (2, 0.5,
    1.5): a volume leaves its entity's scale out, so the fog is the same ellipsoids' (the
    ground truth's, from the components' numbers alone)."""
    volumes, fog = ([ORANGE], None) if case == "one" else ([ORANGE, BLUE], Fog(color=tuple(FOG_COLOR), density=0.03))
    clear_runner, clear = _frame(scene, _scene(None))
    runner, foggy = _frame(scene, _with(volumes, fog, scale=(1.0, 1.0, 1.0) if case == "one" else (2.0, 0.5, 1.5)))
    assert ("FOG_VOLUMES", str(len(volumes))) in runner.engine.renderer.fog.defines
    floor = (runner.ids() == runner.world.resources["ids"]["floor"]).reshape(-1)
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    points = _floor_hits(eye, rays).reshape(-1, 3)[floor]
    starts = np.tile(eye, (len(points), 1))
    depth = _volume_depth(starts, points, ORANGE)
    assert depth.max() > 1.0 and (depth < 1e-6).mean() > 0.2   # (thick fog and clear floor both)
    _close(np.abs(foggy[floor] - np.minimum(_over(clear[floor], starts, points, volumes, fog), 1.0)).max(axis=1))


def test_the_sky_seen_through_a_volume_is_fogged_by_its_whole_chord(scene):
    """Sky pixels whose ray passes through the blue ball: the clear sky fogged by its density
    along the whole chord (a volume's far side is never the sky's)."""
    tall = ((0.0, 2.6, 1.0), (5.0, 3.0, 3.0), 0.0, 0.7, (0.3, 0.5, 0.9))
    _, clear = _frame(scene, _scene(None))
    runner, foggy = _frame(scene, _with([tall]))
    sky = (runner.ids() == 0).reshape(-1)
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    rays = rays.reshape(-1, 3)[sky]
    starts = np.tile(eye, (len(rays), 1))
    ends = starts + rays * 20.0
    assert (_volume_depth(starts, ends, tall) > 0.5).sum() > 120
    _close(np.abs(foggy[sky] - _over(clear[sky], starts, ends, [tall], None)).max(axis=1))


def test_a_mirror_shows_the_floor_fogged_by_the_volumes_on_the_lights_way(scene):
    """A perfect mirror across the floor: a floor point it shows is fogged by what lies
    between the mirror and the point (the bank before the mirror and one behind the eye, only
    the mirror's view sees through) and then by what lies between the eye and the mirror."""
    volumes = [ORANGE, BEHIND]
    _, clear = _frame(scene, _scene(None, mirror=True))
    runner, foggy = _frame(scene, _with(volumes, mirror=True))
    ids = runner.world.resources["ids"]
    in_mirror = ((runner.engine.renderer.targets.read_surface_ids() == ids["mirror"])
                 & (runner.ids() == ids["floor"])).reshape(-1)
    assert in_mirror.sum() > 750
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    rays = rays.reshape(-1, 3)[in_mirror]
    starts = np.tile(eye, (len(rays), 1))
    on_mirror = eye + rays * ((MIRROR_Z - eye[2]) / rays[:, 2])[:, None]
    points = _floor_hits(on_mirror, rays * np.array([1.0, 1.0, -1.0]))
    assert (_volume_depth(on_mirror, points, BEHIND) > 0.3).sum() > 75   # (the eye's side of the room, mirrored)
    beyond = _over(clear[in_mirror], on_mirror, points, volumes, None)
    _close(np.abs(foggy[in_mirror] - _over(beyond, starts, on_mirror, volumes, None)).max(axis=1))


def test_past_the_limit_the_nearest_fog_and_the_rest_are_said_and_counted(scene):
    """``MAX_FOG_VOLUMES`` + 1 volumes in a row going away from the eye: the farthest is left
    out (its pixels clear), counted and said; removed, the one past the limit is back."""
    row = [((0.0, 0.5, 4.0 - 1.5 * k), (1.0, 1.0, 1.0), 0.0, 0.5, (1.0, 1.0, 1.0)) for k in range(MAX_FOG_VOLUMES + 1)]
    runner = scene(_with(row), (160, 100))
    with pytest.warns(FogLimitWarning, match="fog_volumes_cut"):
        runner.frame()
    assert runner.stats.fog_volumes_cut == 1
    assert runner.engine.renderer.fog.volume_count == MAX_FOG_VOLUMES
    rows = np.array(runner.engine.renderer.fog.block[16:], np.float64).reshape(-1, ROW_FLOATS)
    centres = [np.linalg.inv(row[:16].reshape(4, 4).T)[:3, 3] for row in rows]   # (GL's columns)
    assert sorted(round(c[2], 3) for c in centres) == sorted(round(4.0 - 1.5 * k, 3) for k in range(MAX_FOG_VOLUMES))
    nearest = [e for e, (v,) in runner.world.query(FogVolume)][0]
    runner.world.delete_entity(nearest)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        runner.frame()
    assert runner.stats.fog_volumes_cut == 0 and runner.engine.renderer.fog.volume_count == MAX_FOG_VOLUMES


def test_the_last_volume_gone_takes_the_fog_builds_with_it(scene):
    runner = scene(_with([ORANGE]), (160, 100))
    runner.frame()
    assert runner.engine.renderer.fog.defines == (("FOG", "1"), ("FOG_VOLUMES", "1"))
    for entity, _ in runner.world.query(FogVolume):
        runner.world.delete_entity(entity)
    runner.frame()
    assert runner.engine.renderer.fog.defines == ()


def test_shafts_light_a_volumes_air_without_a_camera_fog(scene):
    """A camera with ``VolumetricFog`` and no Fog: the bank's air scatters the sun (the march
    adds light where rays cross it, none where they miss it), and nothing is said."""
    base = _with([ORANGE])

    def build(world):
        base(world)
        camera = next(e for e, _ in world.query(Transform) if world.has(e, __import__("components").Camera))
        world.add_component(camera, VolumetricFog(steps=32))
    runner = scene(build, (160, 100))
    with warnings.catch_warnings():
        warnings.simplefilter("error", category=UserWarning)
        runner.frame()
    assert runner.engine.renderer.volumetric_fog.composites == 1


def test_values_are_checked():
    assert FogVolume(size=(1.0, 2.0, 3.0)).size == glm.vec3(1.0, 2.0, 3.0)
    for field, bad in (("size", (0.0, 1.0, 1.0)), ("size", (1.0, 1.0)), ("size", (1e5, 1.0, 1.0)),
                       ("density", -1.0), ("density", float("nan")), ("color", (-1.0, 0.0, 0.0))):
        with pytest.raises(ComponentValueError, match=f"FogVolume.{field}"):
            FogVolume(**{field: bad})


def test_a_level_file_keeps_a_volume(tmp_path):
    from tests.support import entity_level_round_trip

    world, it = entity_level_round_trip(
        tmp_path, "[entity.Transform]\nposition = [0.0, 1.0, 0.0]\n[entity.FogVolume]\nsize = [4.0, 2.0, 3.0]\n"
        "density = 0.25\n", ("density = 0.25", "density = -0.25"), "density")
    volume = world.get(it, FogVolume)
    assert volume.size == glm.vec3(4.0, 2.0, 3.0) and volume.density == pytest.approx(0.25)


def test_the_editor_outlines_the_ellipsoid_and_marks_it():
    """``reach_outline`` of a selected fog volume (shell/handles.py): three closed ellipses
    where its axes' planes cut it, turned with its entity, every point on its surface;
    ``markers`` marks it (it has no mesh to click)."""
    from engine.core.world import World
    from shell.handles import markers, reach_outline
    from systems.transform_system import TransformSystem

    world = World("fog-outline")
    world.add_system(TransformSystem(world), priority=1)
    centre, size, yaw = (1.0, 1.0, -2.0), (4.0, 2.0, 3.0), 30.0
    entity = world.spawn(Transform(position=centre, rotation=glm.angleAxis(math.radians(yaw), glm.vec3(0, 1, 0))),
                         FogVolume(size=size))
    world.step(1 / 60)
    view_proj = glm.perspective(glm.radians(60.0), 1.0, 0.1, 100.0) * glm.lookAt(
        glm.vec3(2.0, 6.0, 12.0), glm.vec3(*centre), glm.vec3(0.0, 1.0, 0.0))
    outline = reach_outline(world, entity, view_proj, (640, 480))
    assert len(outline.world) == 3
    points = np.array([[float(v) for v in p] for line in outline.world for p in line])
    c, s = math.cos(math.radians(yaw)), math.sin(math.radians(yaw))
    d = points - np.asarray(centre)
    local = np.stack([d[:, 0] * c - d[:, 2] * s, d[:, 1], d[:, 0] * s + d[:, 2] * c], axis=1) / (np.asarray(size) / 2)
    np.testing.assert_allclose((local ** 2).sum(axis=1), 1.0, atol=1e-5)
    assert all(np.allclose(line[0], line[-1]) for line in outline.world)
    assert [m.kind for m in markers(world, view_proj, (640, 480)) if m.entity == entity] == ["fog"]
    world.close()


def test_a_still_volume_is_packed_once_and_a_moved_one_again(scene):
    """The prepare stage packs the volumes' rows when one comes, changes or moves, not on a still
    frame (the same rows kept); moved, its matrix follows it; its density edited, the block too."""
    runner = scene(_with([ORANGE]), (80, 50))
    runner.frame()
    prepare = runner.engine.stages["prepare"]
    packed = prepare._fog_packed
    runner.frame()
    assert prepare._fog_packed is packed
    (entity, volume), = runner.world.query_one(FogVolume)
    runner.world.get(entity, Transform).position = glm.vec3(3.0, 0.6, 1.0)
    runner.frame()
    rows = np.array(runner.engine.renderer.fog.block[16:], np.float64).reshape(-1, ROW_FLOATS)
    np.testing.assert_allclose(np.linalg.inv(rows[0, :16].reshape(4, 4).T)[:3, 3], (3.0, 0.6, 1.0), atol=1e-5)
    volume.density = 0.2
    runner.frame()
    assert runner.engine.renderer.fog.block[16 + 19] == pytest.approx(0.2)
