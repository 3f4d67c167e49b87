"""A periodic probe draws only the part of a face its changes reach: the scheduler keeps, for
each face a change reached, the rectangle of the face where the changes' boxes (and their
shadows' boxes) lie (``ProbeState.regions``, ``probe_rules.face_rects``), and the captures
draw that rectangle alone, scissored, the rest of the face left as it is
(``ProbeCaptures._draw_part``).  Each capture is checked bit for bit, every level of every
face, against a capture that draws all six faces whole (``tests/test_probe_keeping.py``'s
``_Cube``): a rectangle too small, or one not grown over the frames a face waited, shows there."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import DirectionalLight, Material, MeshRef, ReflectionProbe, Transform
from engine.assets.mesh import box, plane
from engine.core.cube_faces import CUBE_FACES
from engine.rules.probe_rules import NO_RECT, face_rects
from engine.rules.probe_schedule import ProbeSchedule
from tests.support import look_from, probe_face_of
from tests.test_probe_keeping import _Cube, _probe_stage

RESOLUTION = 64


def test_every_point_of_a_box_in_front_of_the_near_plane_lies_in_its_face_rectangles():
    """Points sampled through random boxes (some across the probe, some behind a face):
    each point at least ``near`` along a face's axis and inside the face's frustum projects
    (s / depth, t / depth along the face's axes) inside the box's rectangle for that face;
    a box with no point in front of the near plane has ``NO_RECT``; the rectangles are
    tight (a box's own corners reach their edges, within the face)."""
    rng = np.random.default_rng(11)
    apex, near = np.array([0.4, 1.0, -0.3]), 0.05
    lo = rng.uniform(-5.0, 5.0, (250, 3))
    hi = lo + rng.uniform(0.01, 3.0, (250, 3))
    rects = face_rects(apex, near, lo, hi)
    grid = np.stack(np.meshgrid(*[np.linspace(0.0, 1.0, 9)] * 3, indexing="ij"), -1).reshape(-1, 3)
    widths = []
    for b in range(len(lo)):
        points = lo[b] + grid * (hi[b] - lo[b]) - apex
        for face, (forward, s_axis, t_axis) in enumerate(CUBE_FACES):
            depth = points @ np.array(forward)
            front = depth >= near
            rect = rects[b, face]
            if not front.any():
                assert tuple(rect) == NO_RECT, (b, face, rect)
                continue
            s = points[front] @ np.array(s_axis) / depth[front]
            t = points[front] @ np.array(t_axis) / depth[front]
            inside = (np.abs(s) <= 1.0) & (np.abs(t) <= 1.0)
            if not inside.any():
                continue
            s, t = s[inside], t[inside]
            assert rect[0] <= s.min() + 1e-12 and s.max() <= rect[2] + 1e-12, (b, face, rect, s.min(), s.max())
            assert rect[1] <= t.min() + 1e-12 and t.max() <= rect[3] + 1e-12, (b, face, rect, t.min(), t.max())
            widths.append((s.max() - s.min()) / max(rect[2] - rect[0], 1e-12))
    assert np.median(widths) > 0.9  # (the grid holds the box's corners: the edges are reached)


def test_every_point_of_a_swept_box_in_front_of_the_near_plane_lies_in_its_hull_rectangles():
    """``hull_rects`` against points sampled through random boxes swept by random vectors
    (some along a face's plane, some not moving): each point in front of the near plane and
    inside a face's frustum projects inside the hull's rectangle; the hull's rectangles are
    smaller than those of the box bounding the sweep; a box not swept has its own
    ``face_rects``, and boxes given first keep theirs, ahead of the hulls'."""
    from engine.rules.probe_rules import hull_rects

    rng = np.random.default_rng(5)
    apex, near = np.array([0.3, 1.0, -0.2]), 0.05
    lo = rng.uniform(-4.0, 4.0, (200, 3))
    hi = lo + rng.uniform(0.01, 2.0, (200, 3))
    sweep = rng.normal(0.0, 3.0, (200, 3))
    sweep[:20, 1] = 0.0  # along the +-Y faces' planes
    sweep[20:30] = 0.0
    rects = hull_rects(apex, near, lo, hi, lo + sweep, hi + sweep)
    bounding = face_rects(apex, near, np.minimum(lo, lo + sweep), np.maximum(hi, hi + sweep))
    grid = np.stack(np.meshgrid(*[np.linspace(0.0, 1.0, 5)] * 3, indexing="ij"), -1).reshape(-1, 3)
    shares = np.linspace(0.0, 1.0, 17)
    for b in range(len(lo)):
        points = ((lo[b] + grid * (hi[b] - lo[b]))[:, None, :] + shares[None, :, None] * sweep[b]).reshape(-1, 3) - apex
        for face, (forward, s_axis, t_axis) in enumerate(CUBE_FACES):
            depth = points @ np.array(forward)
            front = depth >= near
            s = points[front] @ np.array(s_axis) / depth[front]
            t = points[front] @ np.array(t_axis) / depth[front]
            inside = (np.abs(s) <= 1.0) & (np.abs(t) <= 1.0)
            if not inside.any():
                continue
            rect = rects[b, face]
            assert rect[0] <= s[inside].min() + 1e-12 and s[inside].max() <= rect[2] + 1e-12, (b, face)
            assert rect[1] <= t[inside].min() + 1e-12 and t[inside].max() <= rect[3] + 1e-12, (b, face)
    area = np.clip(rects[..., 2] - rects[..., 0], 0, None) * np.clip(rects[..., 3] - rects[..., 1], 0, None)
    box_area = np.clip(bounding[..., 2] - bounding[..., 0], 0, None) * np.clip(bounding[..., 3] - bounding[..., 1],
                                                                                0, None)
    assert area.sum() < 0.9 * box_area.sum()
    np.testing.assert_array_equal(hull_rects(apex, near, lo, hi, lo, hi), face_rects(apex, near, lo, hi))
    both = hull_rects(apex, near, lo[:5], hi[:5], lo[:5] + sweep[:5], hi[:5] + sweep[:5], lo[5:9], hi[5:9])
    np.testing.assert_array_equal(both[:4], face_rects(apex, near, lo[5:9], hi[5:9]))
    np.testing.assert_array_equal(both[4:], rects[:5])


def test_a_faces_change_rectangle_is_the_union_of_its_rows_rectangles_that_reach_it():
    """``change_rects`` (the scheduler's one pass) against the rows' own rectangles: each
    box's ``face_rects``, each sun row's ``hull_rects`` cut to its clipped box's, unioned
    over the rows ``hits`` says reach the face; a face none reaches has ``NO_RECT``."""
    from engine.rules.probe_rules import change_rects, hull_rects

    rng = np.random.default_rng(9)
    apex, near = (0.0, 1.0, 0.0), 0.05
    lo = rng.uniform(-8.0, 8.0, (12, 3))
    lo[:, 1] = rng.uniform(0.0, 3.0, 12)
    hi = lo + rng.uniform(0.2, 1.0, (12, 3))
    sweep = rng.normal(0.0, 1.0, (12, 3))
    sweep[:, 1] = -4.0  # down through the floor (y = 0), as a sun's sweep to the level's walls
    # Each hull's box cut at the floor: the part of it a shadow can fall in.
    bound_lo = np.maximum(np.minimum(lo[6:], lo[6:] + sweep[6:]), [-20.0, 0.0, -20.0])
    bound_hi = np.maximum(hi[6:], hi[6:] + sweep[6:])
    hits = rng.uniform(0.0, 1.0, (12, 6)) > 0.4
    hits[:, 2] = False  # a face no row reaches
    got = change_rects(apex, near, lo[:6], hi[:6], hits, (lo[6:], hi[6:], lo[6:] + sweep[6:], hi[6:] + sweep[6:],
                                                         bound_lo, bound_hi))
    rows = list(face_rects(apex, near, lo[:6], hi[:6]))
    hulls = hull_rects(apex, near, lo[6:], hi[6:], lo[6:] + sweep[6:], hi[6:] + sweep[6:])
    bounds = face_rects(apex, near, bound_lo, bound_hi)
    for hull, bound in zip(hulls, bounds, strict=True):
        cut = np.concatenate([np.maximum(hull[:, :2], bound[:, :2]), np.minimum(hull[:, 2:], bound[:, 2:])], axis=1)
        cut[(cut[:, 0] > cut[:, 2]) | (cut[:, 1] > cut[:, 3])] = NO_RECT
        rows.append(cut)
    rows = np.array(rows)
    for face in range(6):
        reaching = rows[hits[:, face], face]
        reaching = reaching[np.isfinite(reaching[:, 0])]
        if not len(reaching):
            assert tuple(got[face]) == NO_RECT, face
            continue
        want = (*reaching[:, :2].min(axis=0), *reaching[:, 2:].max(axis=0))
        np.testing.assert_allclose(got[face], want, atol=1e-12, err_msg=f"face {face}")
    assert tuple(got[2]) == NO_RECT
    assert (hulls != bounds).any()  # (the cut matters)


def test_a_texel_rectangle_holds_every_texel_whose_centre_lies_in_the_region_and_a_texel_more():
    from engine.render.probes import texel_rect

    rng = np.random.default_rng(3)
    centres = (np.arange(RESOLUTION) + 0.5) / RESOLUTION * 2.0 - 1.0
    for _ in range(200):
        s0, s1 = np.sort(rng.uniform(-1.2, 1.2, 2))
        t0, t1 = np.sort(rng.uniform(-1.2, 1.2, 2))
        x, y, w, h = texel_rect((s0, t0, s1, t1), RESOLUTION)
        assert x % 2 == 0 and y % 2 == 0 and w % 2 == 0 and h % 2 == 0  # whole 2 x 2 quads
        assert 0 <= x and x + w <= RESOLUTION and 0 <= y and y + h <= RESOLUTION
        step = 2.0 / RESOLUTION
        cols = np.flatnonzero((centres >= s0 - step) & (centres <= s1 + step))
        rows = np.flatnonzero((centres >= t0 - step) & (centres <= t1 + step))
        assert (not len(cols) or (x <= cols.min() and cols.max() < x + w))
        assert (not len(rows) or (y <= rows.min() and rows.max() < y + h))
    assert texel_rect(NO_RECT, RESOLUTION) is None


def _floor_and_boxes(refresh: str = "every_frame", every_n: int = 1):
    """A lit floor, a probe 0.6 m above it seeing 6 m, a small box in its +X face and a
    caster above and behind the probe whose shadow falls in its -Y face."""
    def build(world):
        look_from(world, (0, 3, 6), (0, 0, 0))
        world.resources["sun"] = world.spawn(DirectionalLight(direction=(-1.0, -1.5, 0.3), intensity=2.0))
        world.spawn(Transform(), MeshRef(plane(60, 60)), Material(color=(0.8, 0.8, 0.8)))
        world.resources["probe"] = world.spawn(
            Transform(position=(0.0, 0.6, 0.0)),
            ReflectionProbe(resolution=RESOLUTION, far=6.0, refresh=refresh, every_n=every_n))
        world.resources["near"] = world.spawn(Transform(position=(2.5, 0.5, -0.6)), MeshRef(box((0.3, 0.3, 0.3))),
                                              Material(color=(0.9, 0.2, 0.1)))
        world.resources["caster"] = world.spawn(Transform(position=(1.9, 2.4, -0.3)), MeshRef(box((0.4, 0.4, 0.4))),
                                                Material(color=(0.2, 0.3, 0.9)))
    return build


def _parts_drawn(cube: _Cube) -> list[tuple[int, tuple[int, int, int, int]]]:
    """The faces drawn in part from now on, with their rectangles (the drawing unchanged)."""
    parts: list[tuple[int, tuple[int, int, int, int]]] = []
    draw = cube.probes._draw_part

    def recorded(view, target, rect):
        parts.append((probe_face_of(view), rect))
        return draw(view, target, rect)

    cube.probes._draw_part = recorded
    return parts


def _save(cube: _Cube, face: int, name: str) -> None:
    from PIL import Image

    rgb = np.clip(cube.probes.read_face(cube.owner, face), 0.0, 1.0) ** (1.0 / 2.2)
    Image.fromarray((rgb[::-1] * 255).astype(np.uint8)).resize((256, 256), Image.NEAREST).save(f"/tmp/{name}.png")


def test_a_box_moving_in_a_face_draws_the_part_of_it_the_box_and_its_shadow_cover(scene):
    """The box in the +X face moves: the +X face is drawn in part, a rectangle smaller than
    the face holding the box where it was and is, and shows the box moved; the caster
    moves: the faces its shadow may fall in are drawn in part.  After each frame the cube
    is, bit for bit, a capture of all six drawn whole."""
    runner = scene(_floor_and_boxes(), (64, 48))
    _probe_stage(runner).path = "six_pass"
    cube = _Cube(runner)
    world = runner.world
    for _ in range(3):
        runner.frame()
    assert runner.stats.probe_faces == 0
    parts = _parts_drawn(cube)
    chains = []  # the mip builds' rectangles (None: whole)
    build = cube.probes.mips.build

    def built(*args, **kwargs):
        chains.append(kwargs.get("rect"))
        return build(*args, **kwargs)

    cube.probes.mips.build = built

    before = cube.probes.read_face(cube.owner, 0).copy()
    world.get(world.resources["near"], Transform).position += glm.vec3(0.0, 0.0, 0.3)
    runner.frame()
    drawn = dict(parts)
    assert 0 in drawn, parts
    x, y, w, h = drawn[0]
    assert w * h < RESOLUTION * RESOLUTION / 4, drawn[0]  # a small box: a small part
    assert len(parts) == 1 and chains == [(x, y, x + w, y + h)], chains  # its mip chain within the part
    changed = np.argwhere((cube.probes.read_face(cube.owner, 0) != before).any(axis=2))
    assert len(changed)  # the box moved in it ...
    rows, cols = changed[:, 0], changed[:, 1]
    assert x <= cols.min() and cols.max() < x + w and y <= rows.min() and rows.max() < y + h  # ... within the part
    _save(cube, 0, "probe_part_face0")
    assert cube.as_if_drawn_whole()

    runner.frame()  # (the whole capture above forgot the faces' records: all drawn whole again)
    parts.clear()
    before = cube.probes.read_face(cube.owner, 3).copy()
    world.get(world.resources["caster"], Transform).position += glm.vec3(0.0, 0.0, -0.3)
    runner.frame()
    drawn = dict(parts)
    assert 3 in drawn, parts  # -Y: where its shadow falls
    assert all(w * h < RESOLUTION * RESOLUTION for _, (_, _, w, h) in parts)
    assert not np.array_equal(cube.probes.read_face(cube.owner, 3), before)
    _save(cube, 3, "probe_part_face3")
    assert cube.as_if_drawn_whole()


def _every_third_frame_probe(scene):
    """The floor-and-boxes scene with an ``every_n`` = 3 probe on the six-pass path, run past
    its first capture to a frame with a capture: the runner, the cube recorder, the probe's
    state and the parts recorder."""
    runner = scene(_floor_and_boxes("every_n", 3), (64, 48))
    _probe_stage(runner).path = "six_pass"
    cube = _Cube(runner)
    runner.frame()
    state = _probe_stage(runner).probes[runner.world.resources["probe"]]
    while True:  # the first capture, then to a frame with a capture
        runner.frame()
        if state.captures >= 2 and runner.stats.probe_captures:
            break
    return runner, cube, state, _parts_drawn(cube)


def test_a_face_waiting_for_its_period_draws_the_part_every_change_since_reached(scene):
    """``every_n`` = 3: the box moves on two frames between captures, far enough that its
    three places do not overlap; the capture draws the +X face in part, the rectangle
    holding all three places (only the last move's would leave the first place showing the
    box), and the cube is a capture of all six."""
    runner, cube, state, parts = _every_third_frame_probe(scene)
    world = runner.world
    for _ in range(2):
        world.get(world.resources["near"], Transform).position += glm.vec3(0.0, 0.0, 0.45)
        runner.frame()
        assert runner.stats.probe_captures == 0
    runner.frame()
    assert runner.stats.probe_captures == 1
    assert [face for face, _ in parts] == [0], parts
    assert cube.as_if_drawn_whole()


def test_a_relit_face_is_drawn_whole_though_a_move_reached_a_part_of_it_first(scene):
    """``every_n`` = 3: the box moves (a part of the +X face), then the sun dims (every face
    changes everywhere): the capture draws every face whole, none in part."""
    runner, cube, state, parts = _every_third_frame_probe(scene)
    world = runner.world
    world.get(world.resources["near"], Transform).position += glm.vec3(0.0, 0.0, 0.3)
    runner.frame()
    assert state.regions.keys() == {0} or 0 in state.regions
    world.get(world.resources["sun"], DirectionalLight).intensity = 1.5
    runner.frame()
    assert not state.regions and state.changed >= set(range(6))
    runner.frame()
    assert runner.stats.probe_captures == 1 and not parts
    assert cube.as_if_drawn_whole()


@pytest.mark.parametrize("path", ["layered", "auto"])
def test_parts_take_the_six_pass_path(scene, path):
    """A capture with faces drawn in part is a capture of some faces: six-pass whatever the
    path setting (the layered pass draws all six whole).  ``auto`` times both paths on the
    first frames; whether this host then draws parts is its timings' (``fill_bound``, read
    into ``ProbeState.parts`` after each capture), so they are set afterwards as a
    fill-bound host measures them, with ``auto`` settled on the layered path (the case
    where the part's path differs from the chosen one), and a frame is drawn by them."""
    runner = scene(_floor_and_boxes(), (64, 48))
    _probe_stage(runner).path = path
    cube = _Cube(runner)
    for _ in range(3):
        runner.frame()
    paths = cube.probes.paths
    paths.settle()
    paths.samples, paths.thread_ms = {"six_pass": [(5.0, 6.0)] * 3}, {"six_pass": [1.0] * 3}
    if path == "auto":
        assert paths.chosen is not None  # timed and settled in the first frames
        paths._chosen = "layered"
    assert paths.fill_bound
    runner.frame()
    parts = _parts_drawn(cube)
    runner.world.get(runner.world.resources["near"], Transform).position += glm.vec3(0.0, 0.0, 0.3)
    runner.frame()
    assert parts and _probe_stage(runner).path_used == "six_pass"
    assert cube.as_if_drawn_whole()


def test_no_rectangles_are_worked_out_where_no_part_can_be_drawn(scene):
    """Faces copied from a 2D target (no face target straight into the cube: a part would
    leave the copy's other texels wrong) are drawn whole: the captures say no part can be
    drawn (``ProbeState.parts``), so the scheduler works out no rectangle for the faces the
    box reaches; the cube is a capture of all six."""
    runner = scene(_floor_and_boxes(), (64, 48))
    _probe_stage(runner).path = "six_pass"
    cube = _Cube(runner)
    cube.probes.direct_faces = False
    world = runner.world
    for _ in range(3):
        runner.frame()
    state = _probe_stage(runner).probes[world.resources["probe"]]
    assert not state.parts
    parts = _parts_drawn(cube)
    world.get(world.resources["near"], Transform).position += glm.vec3(0.0, 0.0, 0.3)
    runner.frame()
    due = world.resources[ProbeSchedule].due[world.resources["probe"]]
    assert 0 in due.faces and 0 not in due.unchanged and not due.regions  # reached, drawn whole
    assert not parts and runner.stats.probe_faces >= 1
    assert cube.as_if_drawn_whole()


def test_an_on_change_probe_draws_the_part_of_a_face_a_moved_box_reaches(scene):
    """An ``on_change`` probe (the default refresh) recaptures the faces a change asks for;
    the +X face, asked for by the box moving in it, is drawn in part, and the cube is a
    capture of all six.  A request (a reason that is no change's) draws every face whole."""
    runner = scene(_floor_and_boxes("on_change"), (64, 48))
    _probe_stage(runner).path = "six_pass"
    cube = _Cube(runner)
    world = runner.world
    for _ in range(3):
        runner.frame()
    parts = _parts_drawn(cube)
    world.get(world.resources["near"], Transform).position += glm.vec3(0.0, 0.0, 0.3)
    runner.frame()
    assert 0 in dict(parts), parts
    assert cube.as_if_drawn_whole()
    runner.frame()
    parts.clear()
    world.get(world.resources["near"], Transform).position += glm.vec3(0.0, 0.0, 0.3)
    world.get(world.resources["probe"], ReflectionProbe).request()
    runner.frame()
    assert runner.stats.probe_faces >= 1 and not parts
    assert cube.as_if_drawn_whole()


@pytest.mark.parametrize("gpu_ms", [0.1, 5.0], ids=["issuing_bound", "fill_bound"])
def test_parts_are_drawn_only_where_the_gpu_takes_longer_than_issuing_a_capture(scene, gpu_ms):
    """A host whose GPU drew the timed captures faster than the CPU issued them (a GPU:
    fill is nearly free, the CPU is what a capture costs) draws no parts and works out no
    rectangles; one whose GPU took longer (llvmpipe: fill is most of a capture) does.  The
    timings are ``ProbePaths``' (auto's timed captures: the GPU's by timer query, the
    issuing thread's CPU time), set here as such a host would have measured them."""
    runner = scene(_floor_and_boxes(), (64, 48))
    stage = _probe_stage(runner)
    stage.path = "six_pass"
    cube = _Cube(runner)
    paths = cube.probes.paths
    paths.samples, paths.thread_ms = {"six_pass": [(gpu_ms, 6.0)] * 3}, {"six_pass": [1.0] * 3}
    assert paths.fill_bound == (gpu_ms > 1.0)
    world = runner.world
    for _ in range(3):
        runner.frame()
    parts = _parts_drawn(cube)
    world.get(world.resources["near"], Transform).position += glm.vec3(0.0, 0.0, 0.3)
    runner.frame()
    due = world.resources[ProbeSchedule].due[world.resources["probe"]]
    assert bool(parts) == bool(due.regions) == paths.fill_bound
    assert cube.as_if_drawn_whole()
