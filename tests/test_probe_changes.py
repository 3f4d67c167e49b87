"""The probes scheduler's change tests, made cheaper, give the same answers: the hulls tested
from their boxes and sweeps (``swept_box_face_hits``) against their sixteen corners
(``hull_face_hits``), and a sun's sweep, whose light-and-level parts are kept, against a
walk of each corner to the level's walls, after the sun turned or the level grew."""
from __future__ import annotations

import numpy as np
import pytest

from engine.rules.probe_rules import box_corners, hull_face_hits, swept_box_face_hits
from engine.rules.shadow_rules import directional_shadow_sweep


def test_boxes_and_sweeps_hit_the_faces_their_sixteen_corners_hit():
    rng = np.random.default_rng(7)
    hit_some = missed_some = 0
    for trial in range(400):
        n = int(rng.integers(1, 20))
        centre = rng.normal(size=3) * 3.0
        lo = rng.normal(size=(n, 3)) * 6.0
        if trial % 2:
            lo, centre = np.round(lo), np.round(centre)  # box faces lying in a face's planes
        hi = lo + np.abs(rng.normal(size=(n, 3))) * 2.0
        sweep = rng.normal(size=(n, 3)) * 8.0 * (rng.random((n, 1)) < 0.6)  # some rows a box alone
        far = float(rng.uniform(2.0, 30.0))
        corners = box_corners(lo, hi)
        points = np.concatenate([corners, corners + sweep[:, None, :]], axis=1)
        expected = hull_face_hits(centre, far, points, np.minimum(lo, lo + sweep), np.maximum(hi, hi + sweep))
        got = swept_box_face_hits(centre, far, lo, hi, sweep)
        np.testing.assert_array_equal(got, expected)
        hit_some += int(expected.any())
        missed_some += int((~expected).any())
    assert hit_some > 100 and missed_some > 100  # both answers were asked for


def _walked_sweep(lo, hi, direction, level_lo, level_hi):
    """Each corner stepped along the light until it leaves the level (per axis the distance
    to the wall ahead), the farthest corner's distance, at most the level's diagonal."""
    d = np.asarray(direction, np.float64) / np.linalg.norm(direction)
    out = []
    for box_lo, box_hi in zip(lo, hi, strict=True):
        longest = 0.0
        for corner in box_corners(box_lo[None], box_hi[None])[0]:
            ahead = [((level_hi if d[a] > 0 else level_lo)[a] - corner[a]) / d[a] for a in range(3) if abs(d[a]) > 1e-9]
            longest = max(longest, min(ahead))
        out.append(d * min(longest, float(np.linalg.norm(level_hi - level_lo))))
    return np.array(out)


@pytest.mark.parametrize("turned", [(0.3, -1.0, 0.5), (0.0, -1.0, 0.0), (-0.7, -0.2, 0.0), (1.0, -0.15, 0.2)])
def test_a_turned_sun_or_a_grown_level_sweeps_anew(turned):
    rng = np.random.default_rng(3)
    lo = rng.uniform((-4.0, 0.0, -4.0), (3.0, 4.0, 3.0), (6, 3))  # inside the level: each casts
    hi = lo + rng.uniform(0.2, 1.5, (6, 3))
    level = (np.array([-5.0, -1.0, -5.0]), np.array([5.0, 6.0, 5.0]))
    first = (-0.4, -1.0, -0.3)
    assert not np.allclose(_walked_sweep(lo, hi, first, *level), _walked_sweep(lo, hi, turned, *level))
    np.testing.assert_allclose(directional_shadow_sweep(lo, hi, first, *level), _walked_sweep(lo, hi, first, *level))
    # The same level, the sun turned: the kept parts must be the new direction's.
    np.testing.assert_allclose(directional_shadow_sweep(lo, hi, turned, *level), _walked_sweep(lo, hi, turned, *level))
    # The same sun, the level grown on one side, then the other: the walls are the new level's.
    # (The walls behind the sun move nothing: at least one side's growth must.)
    moved = []
    for grown in ((level[0] - 3.0, level[1]), (level[0], level[1] + 3.0)):
        walked = _walked_sweep(lo, hi, turned, *grown)
        np.testing.assert_allclose(directional_shadow_sweep(lo, hi, turned, *grown), walked)
        moved.append(not np.allclose(walked, _walked_sweep(lo, hi, turned, *level)))
    assert any(moved)


def test_a_cube_face_is_touched_where_a_corner_of_the_box_is_farthest_along_each_plane():
    """``face_touches`` (the farthest corner taken axis by axis) against every corner's dot
    product with each of ``_face_planes``' normals, bit for bit."""
    from engine.render.probes import _face_planes, face_touches

    planes = _face_planes()  # (face, plane, xyz)
    rng = np.random.default_rng(11)
    touched_some = missed_some = 0
    for trial in range(400):
        n = int(rng.integers(1, 25))
        apex = rng.normal(size=3) * 2.0
        lo = rng.normal(size=(n, 3)) * 5.0
        if trial % 2:
            lo, apex = np.round(lo), np.round(apex)  # box faces lying in a face's planes
        hi = lo + np.abs(rng.normal(size=(n, 3))) * 2.0
        corners = box_corners(lo - apex, hi - apex)  # (box, corner, xyz)
        farthest = np.einsum("bck,fpk->bcfp", corners, planes).max(axis=1)
        expected = (farthest >= 0.0).all(axis=2)
        np.testing.assert_array_equal(face_touches(apex, lo, hi), expected)
        touched_some += int(expected.any())
        missed_some += int((~expected).any())
    assert touched_some > 100 and missed_some > 100


@pytest.mark.parametrize("rows_seen", ["all", "none", "some", "own"])
@pytest.mark.parametrize("sun", [False, True, "point", "both"])
def test_the_faces_a_change_reaches_are_its_corners_and_its_shadows_hulls(rows_seen, sun):
    """``ProbeScheduler._mark_changes`` against the corners: the faces a changed box the probe
    draws touches (``face_hits``), and with a sun each box's filtered shadow: the faces both
    its sweep's hull (``face_hits_swept``) and its box clipped to the level
    (``directional_shadow_bounds``) touch, for boxes hidden from probes too.  Rows all drawn
    by the probe, none (hidden from probes), some, and the probe's own object among them."""
    from pyglm import glm

    from components import PointLight, ReflectionProbe, Transform, Visibility
    from engine.core.world import World
    from engine.rules.probe_rules import face_hits, face_hits_swept
    from engine.rules.probe_schedule import ProbeState
    from engine.rules.shadow_rules import (
        ShadowCasters,
        boxes_in_reach,
        directional_shadow_bounds,
        directional_shadow_sweep,
        point_shadow_bounds,
    )
    from engine.rules.visibility_rules import entity_code
    from systems.probe_scheduler import ChangedBoxes, ProbeScheduler

    hidden = entity_code(Visibility(in_probes=False))
    shown = entity_code(Visibility())
    rng = np.random.default_rng(5)
    world = World("changes")
    scheduler = ProbeScheduler(world)
    level = (np.array([-12.0, 0.0, -12.0]), np.array([12.0, 4.0, 12.0]))
    direction = (-0.5, -1.0, 0.2)
    light = ((1.0, 3.0, 2.0), 7.0)  # a shadowed point light: (position, range)
    if sun:
        world.resources[ShadowCasters] = ShadowCasters(level=level, directional=[] if sun == "point" else [direction],
                                                       points=[light] if sun in ("point", "both") else [])
        if sun in ("point", "both"):
            world.spawn(PointLight(range=light[1], shadows=True), Transform(position=light[0]))
    position = glm.vec3(0.5, 1.0, -0.5)
    reached_any = missed_any = 0
    for _ in range(40):
        n = int(rng.integers(1, 7))
        lo = rng.uniform((-9.0, 0.0, -9.0), (8.0, 3.0, 8.0), (n, 3))
        hi = lo + rng.uniform(0.1, 1.0, (n, 3))
        seen = {"all": np.ones(n, bool), "none": np.zeros(n, bool), "some": rng.random(n) < 0.5,
                "own": np.ones(n, bool)}[rows_seen]
        entity = np.arange(10, 10 + n)
        if rows_seen == "own":
            entity[0], seen[0] = 7, False
        # (The probe's own object is drawn by other views: left out by its entity alone.)
        boxes = ChangedBoxes([(int(entity[i]), "moved", lo[i], hi[i],
                               shown if seen[i] or rows_seen == "own" else hidden) for i in range(n)])
        state = ProbeState(7, ReflectionProbe(far=6.0, refresh="every_frame"), False, position)
        state.changed = set()
        scheduler._mark_changes(state, boxes, [], None)
        expected = face_hits(position, 6.0, lo[seen], hi[seen]).any(axis=0)
        if sun:
            reach = scheduler._filter_reach(world.resources[ShadowCasters])
            grown_lo, grown_hi = lo - reach, hi + reach
        if sun in (True, "both"):
            bound_lo, bound_hi = directional_shadow_bounds(grown_lo, grown_hi, direction, *level)
            sweep = directional_shadow_sweep(grown_lo, grown_hi, direction, *level)
            expected |= (face_hits_swept(position, 6.0, grown_lo, grown_hi, sweep)
                         & face_hits(position, 6.0, bound_lo, bound_hi)).any(axis=0)
        if sun in ("point", "both"):
            near = boxes_in_reach(grown_lo, grown_hi, np.array(light[0]), light[1])
            if near.any():
                expected |= face_hits(position, 6.0, *point_shadow_bounds(grown_lo[near], grown_hi[near],
                                                                           np.array(light[0]), light[1])).any(axis=0)
        assert state.changed == set(np.flatnonzero(expected).tolist())
        reached_any += int(expected.any())
        missed_any += int(not expected.all())
    assert missed_any > 5 and (reached_any > 5 or (rows_seen == "none" and not sun))  # (nothing seen, no shadow)


def test_the_filter_reach_follows_the_level_box_and_the_light():
    """``ProbeScheduler._filter_reach`` keeps the grown level's diagonal by the level box:
    a level grown on either side, or back as it was, and a light's map made finer, give
    the reach worked out afresh (the grown diagonal over the map's side, times 2.5 + softness / 2
    texels)."""
    from components import DirectionalLight
    from engine.core.world import World
    from engine.rules.shadow_rules import SHADOW_MARGIN, SHADOW_MARGIN_SHARE, ShadowCasters
    from systems.probe_scheduler import ProbeScheduler

    world = World("reach")
    light = DirectionalLight(direction=(-0.3, -1.0, 0.2), shadows=True, shadow_resolution=512, shadow_softness=1.0)
    world.spawn(light)
    scheduler = ProbeScheduler(world)

    def expected(level):
        diagonal = float(np.sqrt(((level[1] - level[0]) ** 2).sum()))
        grown = diagonal + 2.0 * np.sqrt(3.0) * max(SHADOW_MARGIN, SHADOW_MARGIN_SHARE * diagonal)
        return grown / light.shadow_resolution * (2.5 + 0.5 * light.shadow_softness)

    small = (np.array([-5.0, 0.0, -5.0]), np.array([5.0, 3.0, 5.0]))
    for level in (small, (small[0] - 20.0, small[1]), (small[0], small[1] + 20.0), small):
        casters = ShadowCasters(level=level, directional=[tuple(light.direction)])  # a new one a frame
        assert scheduler._filter_reach(casters) == pytest.approx(expected(level), rel=1e-12)
    light.shadow_resolution = 2048
    assert scheduler._filter_reach(ShadowCasters(level=small, directional=[tuple(light.direction)])) == \
        pytest.approx(expected(small), rel=1e-12)


class _Rows:
    """What ``sky_only_faces`` reads of an instance batch (``InstanceBatch``'s fields of the
    same names): its entities in row order and each row's world box."""

    def __init__(self, entities: list[int], boxes: np.ndarray) -> None:
        self.count = len(entities)
        self.entity_at = entities
        self.row_of = {entity: row for row, entity in enumerate(entities)}
        self.row_boxes = boxes
        self.box = (boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0))


@pytest.mark.parametrize("few", [True, False], ids=["every_row_at_once", "unions_first"])
def test_sky_only_faces_are_those_no_rows_box_touches(monkeypatch, few):
    """``sky_only_faces`` on a few instances (every row in one test) and on many (the
    batches' unions first) against each row's corners: a face is sky-only where no row's
    box (the skipped entity's left out) has a corner on the inner side of all its planes;
    a row never measured (NaN) leaves none sky-only."""
    import engine.render.probes as probes

    if not few:
        monkeypatch.setattr(probes, "SKY_ONLY_FEW_ROWS", 0)
    planes = probes._face_planes()
    rng = np.random.default_rng(13)
    sky_some = sky_none = 0
    for trial in range(60):
        apex = rng.normal(size=3)
        batches, entity = [], 1
        for _ in range(int(rng.integers(1, 4))):
            count = int(rng.integers(1, 5))
            lo = rng.normal(size=(count, 3)) * 4.0 + rng.normal(size=3) * 6.0
            boxes = np.stack([lo, lo + rng.uniform(0.1, 1.0, (count, 3))], axis=1)
            batches.append(_Rows(list(range(entity, entity + count)), boxes))
            entity += count
        skip = int(rng.integers(0, entity))  # 0: nothing skipped
        faces = frozenset(int(f) for f in np.flatnonzero(rng.random(6) < 0.7))
        touched = set()
        for batch in batches:
            for row, owner in enumerate(batch.entity_at):
                if owner == skip:
                    continue
                corners = box_corners(batch.row_boxes[row:row + 1, 0] - apex, batch.row_boxes[row:row + 1, 1] - apex)
                inside = np.einsum("ck,fpk->cfp", corners[0], planes) >= 0.0  # (corner, face, plane)
                touched |= set(np.flatnonzero(inside.any(axis=0).all(axis=1)).tolist())
        expected = frozenset(faces - touched)
        assert probes.sky_only_faces(apex, faces, skip, batches) == expected
        sky_some += bool(expected)
        sky_none += bool(faces - expected)  # some face shows a box
        if trial % 10 == 0:  # a row not measured yet
            batches[-1].row_boxes[0, 0, 1] = np.nan
            batches[-1].box = (batches[-1].row_boxes[:, 0].min(axis=0), batches[-1].row_boxes[:, 1].max(axis=0))
            skipped_alone = batches[-1].count == 1 and batches[-1].entity_at[0] == skip
            assert probes.sky_only_faces(apex, faces, skip, batches) == (expected if skipped_alone or not faces
                                                                          else frozenset())
    assert sky_some > 5 and sky_none > 5  # both answers asked for
