"""Shadow cascades (``DirectionalLight.shadow_cascades``): rings about the camera, each a map
of its own in a free tile of the shadow atlas, read wherever a point lies inside one.

On a floor 120 metres wide the level's map has texels of several centimetres; the frame is
checked against float64 shadow rays (a second computation of which floor points the sun
reaches) in a band a few millimetres either side of the box's outline, which only a ring's
texels can resolve.  Then when rings are drawn (the camera crossing a cell, a caster
moving), what happens when the atlas has no tile left, and that turning them off gives the
frame a light without them gives."""
from __future__ import annotations

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
    Monitor,
    Transform,
    look_rotation,
)
from engine.assets.mesh import box, plane, quad
from engine.render.views import camera_view
from engine.rules.shadow_rules import (
    RING_STEP_SHARE,
    changed_region,
    directional_fit,
    map_region,
    ring_cell,
    ring_fit,
    ring_radii,
)
from tests.support import box_hits, look_from, pixel_rays, srgb_to_linear

LIGHT = glm.normalize(glm.vec3(-1.0, -0.75, -0.5))
BOX_CENTRE, BOX_HALF = np.array([-1.0, 0.5, 0.0]), 0.5
EYE, TARGET = (0.3, 1.6, 2.6), (-0.6, 0.0, 0.0)
DISTANCE = 8.0   # the largest ring's radius: rings of 8 and 2 metres with three cascades
BAND = 0.008     # metres either side of the outline left out: a few of the inner ring's texels
EDGE = 0.08      # ... and the floor further than this from it, which any map gets right
MIRROR_Z = -1.0


def _build(cascades: int, suns: int = 1, distance: float = DISTANCE, eye=EYE, target=TARGET, box_at=BOX_CENTRE,
           mirror=False):
    def build(world):
        look_from(world, eye, target)
        ids = world.resources["ids"] = {}
        ids["sun"] = world.spawn(DirectionalLight(direction=LIGHT, intensity=2.5, shadow_cascades=cascades,
                                                  shadow_distance=distance))
        if mirror:   # at z = MIRROR_Z, facing +z
            ids["mirror"] = world.spawn(Transform(position=(0.0, 1.2, MIRROR_Z)), MeshRef(quad(6.0, 2.4)), Material(),
                                        Mirror())
        for k in range(1, suns):   # dim suns from straight above: their shadows fall under the box
            world.spawn(DirectionalLight(direction=(0.0, -1.0, 0.001 * k), intensity=0.05))
        ids["floor"] = world.spawn(Transform(), MeshRef(plane(120, 120)), Material(color=(0.8, 0.8, 0.8),
                                                                                   roughness=1.0))
        ids["box"] = world.spawn(Transform(position=list(box_at)), MeshRef(box()),
                                 Material(color=(0.8, 0.3, 0.2)))
        # Far off, so the level's box (what its map is fitted to) is wide.
        world.spawn(Transform(position=(40.0, 0.5, 30.0)), MeshRef(box()), Material(color=(0.3, 0.5, 0.8)))
    return build


def _runner(scene, cascades: int, suns: int = 1, size=(480, 320), **placing):
    runner = scene(_build(cascades, suns, **placing), size)
    runner.engine.renderer.antialias = "off"
    return runner


def _floor_points(runner) -> np.ndarray:
    """Where each pixel's ray from the main view meets the floor (y = 0), one row a pixel."""
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    return (eye + rays * (-eye[1] / rays[..., 1])[..., None]).reshape(-1, 3)


def _agreement(runner, with_shadows: np.ndarray, without: np.ndarray, points: np.ndarray | None = None,
               mask: np.ndarray | None = None, centre=BOX_CENTRE, linear: bool = False) -> tuple[float, int, int]:
    """(share of ``mask``'s pixels (the floor's), each showing the floor point of its row of
    ``points``, near the box's outline but outside the band, whose shading agrees with the
    float64 shadow rays; pixels counted; pixels the rays put in shadow).  ``linear``: the
    pictures are linear light (a monitor's), not the frame's sRGB."""
    ids = runner.world.resources["ids"]
    points = _floor_points(runner) if points is None else points
    mask = runner.ids() == ids["floor"] if mask is None else mask
    to_light = np.tile(-np.array(LIGHT, np.float64), (len(points), 1))

    def hits(grow: float) -> np.ndarray:
        return box_hits(points, to_light, np.asarray(centre, np.float64), BOX_HALF + grow).reshape(mask.shape)

    inside, outside = hits(-BAND), hits(BAND)
    if not linear:
        with_shadows, without = srgb_to_linear(with_shadows), srgb_to_linear(without)
    ratio = with_shadows[..., :3].mean(axis=-1) / np.maximum(without[..., :3].mean(axis=-1), 1e-6)
    # Only the floor near the outline (within EDGE of it), where the maps' texels decide.
    sure = mask & (inside == outside) & (hits(-EDGE) != hits(EDGE))
    frame_says = np.where(ratio < 0.7, 1, np.where(ratio > 0.95, 0, -1))[sure]
    return float((frame_says == inside[sure]).mean()), int(sure.sum()), int(inside[sure].sum())


def _with_and_without(runner) -> tuple[np.ndarray, np.ndarray]:
    sun = runner.world.get(runner.world.resources["ids"]["sun"], DirectionalLight)
    sun.shadows = False
    without = runner.frame()
    sun.shadows = True
    return runner.frame(), without


@pytest.mark.parametrize("shadow_filter", ["single", "grid"])
def test_rings_resolve_the_shadow_the_levels_map_cannot(scene, shadow_filter):
    """Near the camera the shadow agrees with the rays to within a few millimetres with three
    cascades, and not with the level's map alone (its texels there are centimetres wide)."""
    shares = {}
    for cascades in (1, 3):
        runner = _runner(scene, cascades)
        runner.engine.renderer.shadows.filter = shadow_filter
        with_shadows, without = _with_and_without(runner)
        shares[cascades], counted, in_shadow = _agreement(runner, with_shadows, without)
        assert counted > 1000 and in_shadow > 400, (counted, in_shadow)   # a real floor, a real shadow
    assert ("SHADOW_RINGS", "2") in runner.engine.renderer.shadows.program_defines
    assert shares[3] >= 0.995, shares
    assert shares[1] < 0.95, shares   # the band is too narrow for the level's map: the rings matter


def test_a_mirror_shows_the_rings_sharp_shadow_of_what_stands_behind_the_camera(scene):
    """Rings are about the camera, not its frustum: the box stands behind the camera, seen
    only in the mirror ahead, and its shadow there agrees with the rays (each pixel's ray
    turned at the mirror's plane to the floor) as sharply as a shadow seen directly."""
    box_at = (-0.6, 0.5, 2.0)
    shares = {}
    for cascades in (1, 3):
        runner = _runner(scene, cascades, distance=16.0, eye=(0.0, 1.4, 1.0), target=(-0.4, 0.0, MIRROR_Z),
                         box_at=box_at, mirror=True)
        with_shadows, without = _with_and_without(runner)
        ids = runner.world.resources["ids"]
        in_mirror = (runner.engine.renderer.targets.read_surface_ids() == ids["mirror"]) & \
            (runner.ids() == ids["floor"])
        eye, rays = pixel_rays(runner.engine.main_view, runner.size)
        on_mirror = eye + rays * ((MIRROR_Z - eye[2]) / rays[..., 2])[..., None]
        turned = rays * np.array([1.0, 1.0, -1.0])
        points = (on_mirror + turned * (-on_mirror[..., 1] / turned[..., 1])[..., None]).reshape(-1, 3)
        shares[cascades], counted, in_shadow = _agreement(runner, with_shadows, without, points, in_mirror, box_at)
        assert counted > 500 and in_shadow > 200, (counted, in_shadow)
    assert shares[3] >= 0.99, shares
    assert shares[1] < 0.95, shares


PICTURE_OFF = np.array([30.0, 0.0, 25.0])   # the monitor's box and camera, this far from the camera's


def _watched(cascades: int, suns: int = 1, every: int = 1, screens: int = 1):
    """The camera at EYE looking at a box's shadow (as ``_build``), and 39 metres off, past
    its largest ring's reach, a second box and a monitor's camera looking at its shadow as
    the camera looks at the first's, its picture on a screen behind the camera."""
    def build(world):
        _build(cascades, suns)(world)
        ids = world.resources["ids"]
        eye, target = glm.vec3(*(np.array(EYE) + PICTURE_OFF)), glm.vec3(*(np.array(TARGET) + PICTURE_OFF))
        ids["lens"] = world.spawn(Transform(position=eye, rotation=look_rotation(target - eye)),
                                  Camera(fov_y=60.0, active=False))
        ids["watched"] = world.spawn(Transform(position=list(BOX_CENTRE + PICTURE_OFF)), MeshRef(box()),
                                     Material(color=(0.8, 0.3, 0.2)))
        ids["screen"] = world.spawn(Transform(position=(15.0, 1.6, 45.0)), MeshRef(quad(1.6, 1.0)), Material(),
                                    Monitor(camera=ids["lens"], size=PICTURE_SIZE, every=every))
        ids["screens"] = [ids["screen"]] + [
            world.spawn(Transform(position=(15.0 + 2.0 * k, 1.6, 45.0)), MeshRef(quad(1.6, 1.0)), Material(),
                        Monitor(camera=ids["lens"], size=PICTURE_SIZE, every=every)) for k in range(1, screens)]
    return build


PICTURE_SIZE = (480, 320)


def _pictures_with_and_without(runner) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """((the frame with the sun's shadows, without), (the picture with, without))."""
    ids = runner.world.resources["ids"]
    sun = runner.world.get(ids["sun"], DirectionalLight)
    sun.shadows = False
    without = runner.frame(), runner.engine.renderer.monitors.read(ids["screen"]).copy()
    sun.shadows = True
    with_shadows = runner.frame(), runner.engine.renderer.monitors.read(ids["screen"]).copy()
    return (with_shadows[0], without[0]), (with_shadows[1], without[1])


def _picture_floor(runner, box_at=BOX_CENTRE + PICTURE_OFF) -> tuple[np.ndarray, np.ndarray]:
    """The floor points each picture pixel shows (a row a pixel, rows from the top) and the
    pixels that show the floor (their rays meet it, and not the box at ``box_at`` first)."""
    lens = runner.world.get(runner.world.resources["ids"]["lens"], Transform)
    view = camera_view(lens.world, 60.0, 0.1, 100.0, PICTURE_SIZE)
    eye, rays = pixel_rays(view, PICTURE_SIZE)
    rays = rays.reshape(-1, 3)
    t = -eye[1] / rays[:, 1]
    box_first = box_hits(np.tile(eye, (len(rays), 1)), rays, np.asarray(box_at, np.float64), BOX_HALF + 0.02)
    floor = (rays[:, 1] < 0.0) & ~box_first
    return eye + rays * t[:, None], floor.reshape(PICTURE_SIZE[1], PICTURE_SIZE[0])


def test_a_monitors_picture_reads_rings_about_its_own_camera(scene):
    """The monitor's camera stands 39 metres from the active camera, past its rings: its
    picture's shadow agrees with the float64 rays as sharply as the camera's own frame does
    (the picture's own rings, in the atlas's free tile's quarters), where the level's map
    alone cannot; the camera's frame keeps its rings (the picture's are put back); a still
    frame draws and keeps the same maps."""
    assert np.hypot(*PICTURE_OFF[[0, 2]]) > 2.0 * DISTANCE
    shares = {}
    for cascades in (1, 3):
        runner = scene(_watched(cascades), (240, 160))
        runner.engine.renderer.antialias = "off"
        frame, pictured = _pictures_with_and_without(runner)
        points, floor = _picture_floor(runner)
        share, counted, in_shadow = _agreement(runner, *pictured, points, floor, BOX_CENTRE + PICTURE_OFF,
                                               linear=True)
        assert counted > 1000 and in_shadow > 400, (counted, in_shadow)   # a real floor, a real shadow
        shares[cascades] = share, _agreement(runner, *frame)[0]
        assert runner.stats.picture_cascades_cut == 0
    assert shares[3][0] >= 0.99 and shares[3][1] >= 0.99, shares
    assert shares[1][0] < 0.95 and shares[1][1] < 0.95, shares   # the band is too narrow for the level's map
    # Still: the picture is kept, and every map with it (the level's and the camera's rings;
    # the picture's, drawn again by nothing, are not looked at).
    runner.frame()
    runner.frame()
    assert (runner.stats.shadow_maps_drawn, runner.stats.shadow_maps_kept, runner.stats.monitors_kept) == (0, 3, 1)
    # The monitor's box moved: its footprint drawn again in the level's map and the picture's
    # rings (the camera's rings hold nothing of it: kept).
    watched = runner.world.get(runner.world.resources["ids"]["watched"], Transform)
    watched.position = tuple(BOX_CENTRE + PICTURE_OFF + np.array([0.1, 0.0, 0.0]))
    runner.frame()
    assert (runner.stats.shadow_maps_drawn, runner.stats.shadow_maps_kept) == (3, 2)
    assert runner.stats.monitors_kept == 0


def test_a_picture_drawn_every_other_frame_draws_its_rings_again_after_a_caster_moved_between(scene):
    """A monitor drawn every second frame: its box moves on a frame its picture is not drawn
    (the level's map redrawn under it then), and on the next the picture's rings are drawn
    whole again, so its shadow agrees with the rays at the box's new place (a ring kept
    from before the move would hold the old shadow there)."""
    runner = scene(_watched(3, every=2), (96, 64))
    ids = runner.world.resources["ids"]
    for _ in range(4):
        runner.frame()
    if runner.stats.monitor_views + runner.stats.monitors_kept == 0:   # (due the next frame: one more)
        runner.frame()
    assert runner.stats.monitors_kept == 1   # (due, and still: kept; the next frame it is not due)
    moved = BOX_CENTRE + PICTURE_OFF + np.array([0.12, 0.0, -0.09])
    runner.world.get(ids["watched"], Transform).position = tuple(moved)
    runner.frame()
    assert runner.stats.monitor_views == 0 and runner.stats.shadow_maps_drawn == 1   # (the level's map)
    runner.frame()
    assert runner.stats.monitor_views == 1 and runner.stats.shadow_maps_drawn == 2   # (the picture's rings)
    shown = runner.engine.renderer.monitors.read(ids["screen"]).copy()
    runner.world.get(ids["sun"], DirectionalLight).shadows = False
    for _ in range(2):
        runner.frame()
    without = runner.engine.renderer.monitors.read(ids["screen"])
    points, _ = _picture_floor(runner)
    _, floor = _picture_floor(runner, moved)
    share, counted, _ = _agreement(runner, shown, without, points, floor, moved, linear=True)
    assert counted > 1000 and share >= 0.99, (share, counted)


def test_a_picture_kept_while_the_atlas_was_made_again_draws_its_rings_again(scene):
    """The sun's maps go to 1024 texels and back to 2048 on two frames the picture is not
    drawn: the atlas is made again each time (its texels undefined), so when the picture is
    next drawn its rings are drawn again, though everything they were drawn from is as it was."""
    runner = scene(_watched(3, every=3), (96, 64))
    ids = runner.world.resources["ids"]
    sun = runner.world.get(ids["sun"], DirectionalLight)
    runner.frame()
    assert runner.stats.monitor_views == 1 and runner.stats.shadow_maps_drawn == 5   # level, 2 rings, 2 picture's
    atlas = runner.engine.renderer.shadows.atlases_made
    for resolution in (1024, 2048):
        sun.shadow_resolution = resolution
        runner.frame()
        assert runner.stats.monitor_views == 0   # (not due)
    assert runner.engine.renderer.shadows.atlases_made == atlas + 2
    runner.frame()
    assert runner.stats.monitor_views == 1
    assert (runner.stats.shadow_maps_drawn, runner.stats.shadow_maps_kept) == (2, 3)   # the picture's rings


def test_the_monitors_one_camera_feeds_share_its_rings(scene):
    """Three screens fed by the one camera: its two rings are drawn once (the level's map, the
    active camera's two and the monitors' camera's two), none cut, though the free tile's four
    quarters would hold two of the three monitors' rings each their own; the three pictures
    are one picture.  The next frame, the watched box moved: the camera's rings are drawn
    again under it once, not once a monitor."""
    runner = scene(_watched(3, screens=3), (96, 64))
    runner.frame()
    assert runner.stats.monitor_views == 3
    assert (runner.stats.shadow_maps_drawn, runner.stats.picture_cascades_cut) == (5, 0)
    ids = runner.world.resources["ids"]
    pictures = [runner.engine.renderer.monitors.read(screen) for screen in ids["screens"]]
    assert pictures[0][..., :3].max() > 0.05
    for other in pictures[1:]:
        np.testing.assert_array_equal(other, pictures[0])
    watched = runner.world.get(ids["watched"], Transform)
    watched.position = tuple(BOX_CENTRE + PICTURE_OFF + np.array([0.1, 0.0, 0.0]))
    runner.frame()
    assert runner.stats.monitor_views == 3
    assert (runner.stats.shadow_maps_drawn, runner.stats.shadow_maps_kept) == (3, 2)   # the level's, the camera's 2


def test_a_picture_with_no_free_quarter_reads_the_cameras_rings_and_is_counted(scene):
    """Two suns with four cascades take the atlas's four tiles: no quarter is left for the
    picture's rings, so it reads the camera's (counted in ``picture_cascades_cut``, every
    frame it is drawn), and its picture still shows the level's map's shadow."""
    runner = scene(_watched(4, suns=2), (96, 64))
    runner.frame()
    assert runner.stats.shadow_cascades_cut == 1
    assert runner.stats.picture_cascades_cut == 2
    shown = runner.engine.renderer.monitors.read(runner.world.resources["ids"]["screen"])
    assert shown[..., :3].max() > 0.05   # a lit picture
    from shell.overlay_text import overlay_lines

    assert any("picture cascades 2" in line for line in overlay_lines(runner.engine, [1.0 / 60.0]))


def test_rings_are_drawn_again_only_when_the_camera_leaves_their_cell_or_a_caster_moves(scene):
    runner = _runner(scene, 3, size=(96, 64))
    runner.frame()
    assert runner.stats.shadow_maps_drawn == 3   # the level's map and two rings
    runner.frame()
    assert (runner.stats.shadow_maps_drawn, runner.stats.shadow_maps_kept) == (0, 3)
    inner = ring_radii(DISTANCE, 2)[1]
    step = RING_STEP_SHARE * inner
    eye = runner.world.get(_camera(runner), Transform)
    start = glm.vec3(eye.position)
    # A hundredth of the inner ring's step: the same cells (far from a cell's edge, by luck
    # of the start, checked by the next move), nothing drawn.
    eye.position = start + glm.vec3(0.0, 0.01 * step, 0.0)
    runner.frame()
    small = runner.stats.shadow_maps_drawn
    # Three steps of the inner ring along the ground: the inner ring's cell changes, the
    # outer ring's may, the level's map does not (it does not follow the camera).
    eye.position = start + glm.vec3(3.0 * step, 0.0, 0.0)
    runner.frame()
    moved = runner.stats.shadow_maps_drawn
    assert small == 0 and 1 <= moved <= 2, (small, moved)
    # A caster moving redraws its footprint in every map it is in.
    box_t = runner.world.get(runner.world.resources["ids"]["box"], Transform)
    box_t.position = glm.vec3(box_t.position) + glm.vec3(0.1, 0.0, 0.0)
    runner.frame()
    assert runner.stats.shadow_maps_drawn == 3


@pytest.mark.parametrize("radius, resolution", [(3.0, 2048), (12.0, 2048), (0.7, 512), (5.0, 64)])
def test_a_ring_moved_a_cell_keeps_its_texel_lattice(radius, resolution):
    """A world point lands on texel coordinates a whole number apart in the maps of two
    neighbouring cells (the step is whole texels), so an edge does not crawl when the ring
    follows the camera; and every point within ``radius`` of an eye anywhere in the cell is
    inside the ring's square."""
    level = directional_fit(LIGHT, np.array([-30.0, 0.0, -30.0]), np.array([30.0, 3.0, 30.0]), resolution)
    eye = (1.3, 1.6, -0.4)
    cell = ring_cell(level, eye, radius, resolution)
    rng = np.random.default_rng(5)
    points = rng.uniform(-radius, radius, (200, 3)) + np.array(eye)

    def texels(fit, point) -> np.ndarray:
        clip = fit.view_proj * glm.vec4(*point, 1.0)
        return (np.array([clip.x, clip.y]) * 0.5 + 0.5) * resolution

    here = ring_fit(level, cell, radius, resolution)
    for neighbour in ((cell[0] + 1, cell[1]), (cell[0], cell[1] - 3)):
        there = ring_fit(level, neighbour, radius, resolution)
        for point in points[:20]:
            shift = texels(there, point) - texels(here, point)
            assert np.allclose(shift, np.round(shift), atol=2e-3 * max(1.0, abs(shift).max() / 100)), shift
    near = points[np.linalg.norm(points - np.array(eye), axis=1) <= radius]
    for point in near:
        u = texels(here, point) / resolution
        assert (u > -1e-6).all() and (u < 1 + 1e-6).all(), u


def test_a_ring_keeps_its_cell_while_the_camera_sways_across_a_cell_line():
    """Hysteresis: an eye swaying a fifth of a step either side of the line between two
    cells keeps the ring's cell (no map drawn again each frame); one a step and a half off
    takes the nearest cell; and while a cell is kept, every point within the radius of the
    eye is inside the ring's square."""
    radius, resolution = 3.0, 2048
    level = directional_fit(LIGHT, np.array([-30.0, 0.0, -30.0]), np.array([30.0, 3.0, 30.0]), resolution)
    light_x = np.array([level.view[0][0], level.view[1][0], level.view[2][0]], np.float64)   # light space's x, in world
    start = np.array([0.4, 1.6, -0.3])
    cell = ring_cell(level, tuple(start), radius, resolution)
    centre = ring_fit(level, cell, radius, resolution)
    step = (ring_fit(level, (cell[0] + 1, cell[1]), radius, resolution).proj[3][0]
            - centre.proj[3][0]) / -centre.proj[0][0]   # the grid step in light space, from the fits
    # To the line between this cell and the next along light space's x, then sway across it.
    line = start + light_x * ((cell[0] + 0.5) * step - float(np.dot(light_x, start) + level.view[3][0]))
    kept = cell
    rng = np.random.default_rng(2)
    for sway in rng.uniform(-0.2, 0.2, 40):
        eye = line + light_x * sway * step
        kept = ring_cell(level, tuple(eye), radius, resolution, kept)
        assert kept == cell, sway
        square = ring_fit(level, kept, radius, resolution)
        for point in eye + rng.normal(size=(20, 3)) * radius / 3.0:
            if np.linalg.norm(point - eye) <= radius:
                clip = square.view_proj * glm.vec4(*point, 1.0)
                assert abs(clip.x) <= 1.0 and abs(clip.y) <= 1.0, (clip.x, clip.y)
    far = line + light_x * 1.5 * step
    assert ring_cell(level, tuple(far), radius, resolution, cell) == ring_cell(level, tuple(far), radius, resolution)
    assert ring_cell(level, tuple(far), radius, resolution, cell) != cell


def test_a_ring_redraws_under_the_changes_in_it_not_under_the_box_holding_them_all():
    """Two crates spinning 20 metres apart: the inner ring about the camera (by the near one)
    redraws only the near one's footprint; the box holding both covers the whole ring."""
    level = directional_fit(LIGHT, np.array([-30.0, 0.0, -30.0]), np.array([30.0, 3.0, 30.0]), 2048)
    eye = (0.0, 1.6, 0.0)
    ring = ring_fit(level, ring_cell(level, eye, 2.0, 2048), 2.0, 2048)
    near = ([0.5, 0.0, -0.5], [1.1, 0.6, 0.1])   # the parts as the renderer gives them: floats
    far = ([20.0, 0.0, 5.0], [20.6, 0.6, 5.6])
    union = (np.minimum(near[0], far[0]), np.maximum(near[1], far[1]))
    assert changed_region(ring, union, [near, far], 2048) == map_region(ring, *near, 2048)
    x, y, w, h = map_region(ring, *near, 2048)
    whole = changed_region(ring, union, None, 2048)   # the union alone: a band across the ring, or all of it
    assert whole is None or whole[2] * whole[3] > 5 * w * h, (whole, w * h)
    assert changed_region(ring, far, [far], 2048) == (0, 0, 0, 0)   # outside the ring: nothing
    assert changed_region(ring, None, [], 2048) == (0, 0, 0, 0)
    x, y, w, h = changed_region(level, union, [near, far], 2048)   # the level's map holds both
    for part in (near, far):
        px, py, pw, ph = map_region(level, *part, 2048)
        assert x <= px and y <= py and px + pw <= x + w and py + ph <= y + h


def _camera(runner) -> int:
    from engine.rules.frame_rules import frame_rules

    return frame_rules(runner.world).active_camera


def test_rings_past_the_atlas_tiles_are_cut_and_counted(scene):
    """Four tiles: two suns casting take two, so a sun asking for four cascades gets two
    rings; the third is counted in ``shadow_cascades_cut`` (and the overlay says so)."""
    from shell.overlay_text import overlay_lines

    runner = _runner(scene, 4, suns=2, size=(96, 64))
    runner.frame()
    assert runner.stats.shadow_cascades_cut == 1
    assert runner.stats.shadow_maps_drawn == 4   # two level maps, two rings
    assert ("SHADOW_RINGS", "2") in runner.engine.renderer.shadows.program_defines
    runner.frame()
    assert runner.stats.shadow_cascades_cut == 1   # while it lasts, every frame
    assert any("cascades 1" in line for line in overlay_lines(runner.engine, [1.0 / 60.0]))


def test_turning_the_cascades_off_gives_the_frame_of_a_sun_without_them(scene):
    with_rings = _runner(scene, 3)
    with_rings.frame()
    sun = with_rings.world.get(with_rings.world.resources["ids"]["sun"], DirectionalLight)
    sun.shadow_cascades = 1
    turned_off = with_rings.frame()
    assert not any(name == "SHADOW_RINGS" for name, _ in with_rings.engine.renderer.shadows.program_defines)
    plain = _runner(scene, 1)
    plain.frame()
    assert np.array_equal(turned_off, plain.frame())
    # And back on: the rings drawn again, the sharp shadow back.
    sun.shadow_cascades = 3
    again = with_rings.frame()
    assert with_rings.stats.shadow_maps_drawn == 2
    assert not np.array_equal(again, turned_off)


@pytest.mark.parametrize("field, value", [("shadow_cascades", 0), ("shadow_cascades", 5), ("shadow_cascades", True),
                                          ("shadow_cascades", 2.0), ("shadow_distance", 0.1),
                                          ("shadow_distance", float("nan")), ("shadow_distance", float("inf")),
                                          ("shadow_cascade_blend", -0.1), ("shadow_cascade_blend", 0.6),
                                          ("shadow_cascade_blend", float("nan"))])
def test_bad_cascade_values_are_refused_naming_the_field(field, value):
    with pytest.raises(ComponentValueError, match=f"DirectionalLight.{field}"):
        DirectionalLight(**{field: value})
    light = DirectionalLight()
    with pytest.raises(ComponentValueError, match=f"DirectionalLight.{field}"):
        setattr(light, field, value)


def test_many_movers_redraw_under_their_box_and_a_few_under_each(scene, monkeypatch):
    """The changed boxes a map redraws under are kept apart for a few movers, and past
    ``MAX_CHANGED_PARTS`` in all (over every batch) only their union is used: a map's region
    costs a few calls, not one a mover."""
    import systems.shadow_system as shadow_system
    from engine.render.instances import MAX_CHANGED_PARTS
    from tests.support import own_mesh

    seen = []

    def recording(fit, box, parts, resolution):
        seen.append(None if parts is None else len(parts))
        return changed_region(fit, box, parts, resolution)

    monkeypatch.setattr(shadow_system, "changed_region", recording)

    def build(world):
        _build(3)(world)
        world.resources["movers"] = [world.spawn(Transform(position=(-4.0 + 0.5 * k, 0.3, -3.0)),
                                                 MeshRef(own_mesh(box((0.2, 0.2, 0.2)))), Material())
                                     for k in range(MAX_CHANGED_PARTS)]   # a batch each

    runner = scene(build, (64, 48))
    runner.frame()
    runner.frame()
    movers = runner.world.resources["movers"]
    for count, expected in ((2, 4), (MAX_CHANGED_PARTS, None)):   # each mover's old and new box
        seen.clear()
        for entity in movers[:count]:
            transform = runner.world.get(entity, Transform)
            transform.position = glm.vec3(transform.position) + glm.vec3(0.0, 0.0, 0.05)
        runner.frame()
        assert seen and set(seen) == {expected}, (count, seen)


# --- cascade blending ----------------------------------------------------------------------------
def _band_weights(runner, points: np.ndarray) -> np.ndarray:
    """The shader's share of the ring's own shadow at each floor point (1 past its blend band,
    0 at or past its square's usable edge): from the Shadows block's numbers (the level map's
    matrix, the ring's map, texel, margin and band), the lookup's normal offset and edge
    distance worked out again in float64."""
    from engine.render.shadows import _POINTS_END
    from engine.render.views import MAX_DIRECTIONAL_LIGHTS, MAX_SHADOW_RINGS

    block = runner.engine.renderer.shadows.block.astype(np.float64)
    to_map = block[:16].reshape(4, 4).T           # glm's columns, as rows of its transpose
    texel, softness = block[16 * MAX_DIRECTIONAL_LIGHTS:16 * MAX_DIRECTIONAL_LIGHTS + 2]
    rings = _POINTS_END // 4
    ring_map = block[rings:rings + 4]
    ring_texel, _, band = block[rings + 4 * MAX_SHADOW_RINGS:rings + 4 * MAX_SHADOW_RINGS + 3]
    margin = block[rings + 8 * MAX_SHADOW_RINGS + 3]
    normal = np.array([0.0, 1.0, 0.0])
    grazing = (1.0 + softness) * (1.5 - max(float(normal @ -np.array(LIGHT)), 0.0))
    at = points @ to_map[:3, :3].T + to_map[:3, 3]
    q = at + (to_map[:3, :3] @ normal) * (ring_texel * grazing)
    square = q[:, :2] * ring_map[:2] + ring_map[2:]
    edge = np.minimum(square - margin, 1.0 - margin - square).min(axis=1)
    assert band > 0.0
    return np.clip(edge / band, 0.0, 1.0)


def test_a_rings_blend_band_fades_its_shadow_into_the_larger_maps(scene):
    """A sun with one ring of 1.5 metres (its square 1.9 m each way of its centre), the outer
    half of it a blend band, over a floor whose level map's texels are half a metre: in the
    band each floor pixel's light is the ring's frame (blend 0) and the level map's frame (no
    ring) mixed by the share the lookup gives it there (worked out again from the point's
    place in the ring's square), within the 8-bit frames' rounding; inside the band it is the
    ring's frame, outside the square the level map's."""
    def runner(cascades, blend):
        r = _runner(scene, cascades, distance=1.5, eye=(-1.0, 2.2, 2.0), target=(-1.6, 0.0, -0.2))
        sun = r.world.get(r.world.resources["ids"]["sun"], DirectionalLight)
        sun.shadow_resolution, sun.shadow_cascade_blend = 256, blend
        return r

    blended_runner = runner(2, 0.5)
    blended_rgb = blended_runner.frame()
    assert ("SHADOW_RING_BLEND", "1") in blended_runner.engine.renderer.shadows.program_defines
    ring_runner = runner(2, 0.0)
    ring_rgb = ring_runner.frame()
    assert not any(name == "SHADOW_RING_BLEND" for name, _ in ring_runner.engine.renderer.shadows.program_defines)
    level_rgb = runner(1, 0.5).frame()
    floor = (blended_runner.ids() == blended_runner.world.resources["ids"]["floor"]).reshape(-1)
    w = _band_weights(blended_runner, _floor_points(blended_runner))
    b, r, lv = (srgb_to_linear(x).reshape(-1, 3) for x in (blended_rgb, ring_rgb, level_rgb))
    differ = np.abs(r - lv).max(axis=1) > 0.05          # where the two maps' shadows disagree
    band = floor & (w > 0.02) & (w < 0.98) & differ
    assert band.sum() > 1000, band.sum()
    expected = w[:, None] * r + (1.0 - w[:, None]) * lv
    assert np.abs(b - expected)[band].max() < 0.008     # a unit of the 8-bit sRGB frames, in linear light
    inner, outer = floor & (w >= 0.999), floor & (w <= 0.0)
    assert inner.sum() > 1000 and outer.sum() > 1000, (inner.sum(), outer.sum())
    flat = (x.reshape(-1, 3) for x in (blended_rgb, ring_rgb, level_rgb))
    b8, r8, lv8 = flat
    np.testing.assert_array_equal(b8[inner], r8[inner])
    np.testing.assert_array_equal(b8[outer], lv8[outer])


def test_level_files_carry_the_cascade_blend(tmp_path):
    """A level's DirectionalLight takes shadow_cascade_blend, and refuses one past 0.5 naming
    the file and the field."""
    from engine.assets.level_file import LevelError, load_level
    from engine.core.world import World

    text = """[level]
name = "Sunset"

[[entity]]
name = "sun"
[entity.DirectionalLight]
direction = [-0.7, -0.4, -0.5]
shadow_cascades = 3
shadow_cascade_blend = 0.3
"""
    path = tmp_path / "sun.toml"
    path.write_text(text)
    world = World("sun")
    made = load_level(path).spawn(world)
    assert world.get(made["sun"], DirectionalLight).shadow_cascade_blend == 0.3
    path.write_text(text.replace("0.3", "0.7"))
    with pytest.raises(LevelError, match=r"DirectionalLight\.shadow_cascade_blend") as caught:
        load_level(path).spawn(World("refused"))
    assert str(path) in str(caught.value)


def test_a_portal_shows_the_rings_sharp_shadow_of_what_stands_behind_the_camera(scene):
    """As the mirror's: the box stands behind the camera, seen only through portal A ahead of
    it, whose partner B stands past the box facing back at it; its shadow there agrees with
    the rays (each pixel's ray carried by the pair's transform to the floor) as sharply as a
    shadow seen directly, which the level's map alone cannot."""
    from engine.assets.portals import spawn_portal_pair
    from engine.core.portal_math import pair_transform

    box_at = (-0.6, 0.5, 2.0)
    shares = {}
    for cascades in (1, 3):
        def build(world, cascades=cascades):
            _build(cascades, distance=16.0, eye=(0.0, 1.4, 1.0), target=(-0.4, 0.0, MIRROR_Z), box_at=box_at)(world)
            ids = world.resources["ids"]
            ids["a"], ids["b"] = spawn_portal_pair(world, (0.0, 1.2, MIRROR_Z), None, (0.0, 1.2, 5.0),
                                                   look_rotation(glm.vec3(0.0, 0.0, 1.0)), size=(6.0, 2.4))
        runner = scene(build, (320, 240))
        runner.engine.renderer.antialias = "off"
        with_shadows, without = _with_and_without(runner)
        ids = runner.world.resources["ids"]
        through = (runner.engine.renderer.targets.read_surface_ids() == ids["a"]) & (runner.ids() == ids["floor"])
        carry = np.array(glm.dmat4(pair_transform(runner.world.get(ids["a"], Transform).world,
                                                  runner.world.get(ids["b"], Transform).world)).to_list()).T
        eye, rays = pixel_rays(runner.engine.main_view, runner.size)
        at_a = (eye + rays * ((MIRROR_Z - eye[2]) / rays[..., 2])[..., None]) @ carry[:3, :3].T + carry[:3, 3]
        turned = rays @ carry[:3, :3].T
        points = (at_a + turned * (-at_a[..., 1] / turned[..., 1])[..., None]).reshape(-1, 3)
        shares[cascades], counted, in_shadow = _agreement(runner, with_shadows, without, points, through, box_at)
        assert counted > 300 and in_shadow > 100, (counted, in_shadow)
    assert shares[3] >= 0.99, shares
    assert shares[1] < 0.95, shares
