"""The transparent slot's blending order (``slot_order.back_to_front``, ``split_slot``) on
random scenes of glass panes, ponds and see-through mirrors, from random eyes (outside the
scene and among its batches, where boxes reach behind the eye), is the order a brute-force
reference written here gives: every pair of batches tested in turn (their boxes' screen
rectangles through glm, a see-through surface's plane against the other's box corners, the
centres' order otherwise), the least order Kahn's rule allows picked by scanning every
position, the planes alone where both kinds make a cycle, what must blend before a surface
by walking the graph.  That is the order the slot had when every pair was tested in every
view (O(n^2) a view; since, the pairs of two panes are found by a sweep, only where a plane
holds a farther batch back): it must come out the same, few batches and many, with a view
and without, whatever the view skips.  The blend rule with many batches, in frames:
``test_many_panes_around_a_pond_blend_in_depth_order``."""
from __future__ import annotations

import math
import random

import numpy as np
import pytest
from pyglm import glm

from components import Emissive, Material, MeshRef, Mirror, Skybox, Transform, Water
from engine.assets.mesh import quad
from engine.assets.texture_data import ripple_normal_map
from engine.core.material_slots import ReflectVariant
from engine.render import slot_order
from engine.render.slot_order import SlotGeometry, back_to_front, split_slot
from engine.render.views import View
from tests.support import look_from
from tests.test_glass_and_water import ALPHA, FLAT, Y, _blend_agrees, _render

EPS = 1e-4  # slot_order.PLANE_EPS: how far a box may reach past a plane and still lie on one side


# -- the reference ---------------------------------------------------------------------------

def _corners(batch) -> list[glm.vec4] | None:
    box = batch.box
    if box is None or not np.isfinite(box[0]).all():
        return None
    lo, hi = box[0].tolist(), box[1].tolist()
    return [glm.vec4(x, y, z, 1.0) for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]


def _rect(corners, view_proj):
    """The box's screen rectangle, or None (no box, or a corner at or behind the eye)."""
    if corners is None:
        return None
    points = [view_proj * corner for corner in corners]
    if min(p.w for p in points) <= 1e-6:
        return None
    xs, ys = [p.x / p.w for p in points], [p.y / p.w for p in points]
    return min(xs), min(ys), max(xs), max(ys)


def _side(plane: glm.vec4, corners, centre: glm.vec3) -> int:
    """Which side of ``plane`` a box lies on: 1 / -1 wholly (within EPS), else its centre's
    side; 0 on the plane."""
    if corners is not None:
        normal = np.array(glm.vec3(plane).to_list(), np.float64)
        d = np.array([c.to_list()[:3] for c in corners], np.float64) @ normal + float(plane.w)
        if d.min() > -EPS and d.max() > EPS:
            return 1
        if d.max() < EPS and d.min() < -EPS:
            return -1
        if d.max() - d.min() < 2 * EPS:
            return 0
    d = glm.dot(glm.vec3(plane), centre) + plane.w
    return 1 if d > EPS else -1 if d < -EPS else 0


def _least_order(before: list[set[int]], cycles: bool) -> list[int] | None:
    """The lowest position whose every ``before`` is placed, step by step; where none is,
    None, or (``cycles``) the lowest left."""
    placed: list[int] = []
    left = list(range(len(before)))
    while left:
        done = set(placed)
        free = [i for i in left if before[i] <= done]
        if not free and not cycles:
            return None
        pick = free[0] if free else left[0]
        placed.append(pick)
        left.remove(pick)
    return placed


def _reference(batches: list, eye: glm.vec3, view: View | None):
    """(the batches in blending order, the split (first, rest, torn) or None without a view)."""
    centres = [batch.centre() for batch in batches]
    ordered = sorted(range(len(batches)), key=lambda k: -glm.distance(centres[k], eye))
    count = len(ordered)
    planes = [batch.plane if batch.surface else None for batch in batches]
    corners = [_corners(batch) for batch in batches]
    rects = [None if view is None else _rect(corners[k], view.view_proj) for k in ordered]
    by_plane = [set() for _ in range(count)]
    by_centre = [set() for _ in range(count)]
    for i in range(count):
        for j in range(i + 1, count):
            r, s = rects[i], rects[j]
            apart = r is not None and s is not None and not (r[0] <= s[2] and s[0] <= r[2]
                                                             and r[1] <= s[3] and s[1] <= r[3])
            if apart:
                continue
            a, b = ordered[i], ordered[j]
            says = set()  # True: i (the farther centre) first
            for one, two, i_is_one in ((a, b, True), (b, a, False)):
                plane = planes[one]
                if plane is None:
                    continue
                side = _side(plane, corners[two], centres[two])
                if side:
                    eye_side = 1 if glm.dot(glm.vec3(plane), eye) + plane.w > 0.0 else -1
                    two_in_front = side == eye_side
                    says.add(two_in_front if i_is_one else not two_in_front)
            if says == {True}:
                by_plane[j].add(i)
            elif says == {False}:
                by_plane[i].add(j)
            else:
                by_centre[j].add(i)
    before = [p | c for p, c in zip(by_plane, by_centre, strict=True)]
    order = _least_order(before, False)
    if order is None:
        before = by_plane
        order = _least_order(before, False) or _least_order(before, True)
    in_order = [batches[ordered[i]] for i in order]
    if view is None:
        return in_order, None

    def ancestors(start: list[int]) -> set[int]:
        found, grew = set(start), True
        while grew:
            more = set().union(*(before[i] for i in found)) - found
            found |= more
            grew = bool(more)
        return found

    skipped = (view.skip, view.hide)
    see_through = [batch.surface or batch.variants is None
                   or batch.variants[2] in (int(ReflectVariant.PLANAR), int(ReflectVariant.PORTAL))
                   for batch in batches]
    seeds = [i for i, k in enumerate(ordered) if see_through[k]
             and not (batches[k].count == 1 and batches[k].entity_at[0] in skipped)]
    if not seeds:
        return in_order, ([], [batches[k] for k in ordered], 0)
    if count == 1:
        return in_order, (list(batches), [], 0)
    needed = ancestors(seeds)
    torn = sum(1 for i in needed - set(seeds) if set(seeds) & (ancestors([i]) - {i}))
    return in_order, ([batches[ordered[i]] for i in order if i in needed],
                      [batches[ordered[i]] for i in order if i not in needed], torn)


# -- random scenes ---------------------------------------------------------------------------

def _random_level(seed: int, panes: int, ponds: int, walls: int, ents: dict):
    """Panes of every size and turn, ponds (flat, some tilted, some water) and upright
    see-through mirrors, all in a 12 m cube, each its own transparent batch."""
    rng = random.Random(seed)
    waves = ripple_normal_map(32)

    def build(world) -> None:
        world.spawn(Skybox())
        look_from(world, (0.0, 3.0, 14.0), target=(0.0, 0.0, 0.0))
        ents["surfaces"] = []
        for i in range(ponds):
            tilt = glm.angleAxis(rng.uniform(-0.3, 0.3) if i % 3 == 2 else 0.0, glm.vec3(0, 0, 1))
            parts = [Transform(position=(rng.uniform(-4, 4), rng.uniform(-2, 1), rng.uniform(-4, 4)),
                               rotation=tilt * FLAT), MeshRef(quad(rng.uniform(1, 5), rng.uniform(1, 5))),
                     Material(color=(0.2, 0.3, 0.6, 0.6), normal_map=waves if i % 2 else None),
                     Mirror(reflect_rate=1.0 if i % 2 else 0.7)]
            ents["surfaces"].append(world.spawn(*parts, *([Water()] if i % 2 else [])))
        for _ in range(walls):
            yaw = glm.angleAxis(rng.uniform(0, 2 * math.pi), Y)
            ents["surfaces"].append(world.spawn(
                Transform(position=(rng.uniform(-5, 5), rng.uniform(0, 2), rng.uniform(-5, 5)), rotation=yaw),
                MeshRef(quad(rng.uniform(1, 4), rng.uniform(1, 3))), Material(color=(0.3, 0.3, 0.3, 0.5)),
                Mirror(reflect_rate=0.7)))
        for _ in range(panes):
            axis = glm.normalize(glm.vec3(rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)) + 1e-3)
            world.spawn(Transform(position=(rng.uniform(-6, 6), rng.uniform(-3, 3), rng.uniform(-6, 6)),
                                  rotation=glm.angleAxis(rng.uniform(0, 2 * math.pi), axis)),
                        MeshRef(quad(rng.uniform(0.3, 3), rng.uniform(0.3, 3))),
                        Material(color=(0.9, 0.2, 0.1, 0.5)))
    return build


def _random_views(rng: random.Random, count: int, surfaces: list[int]) -> list[View]:
    views = []
    for n in range(count):
        # Half outside the cube, half among its batches (boxes reaching behind the eye).
        reach = 16.0 if n % 2 else 5.0
        eye = glm.vec3(rng.uniform(-reach, reach), rng.uniform(-4, 8), rng.uniform(-reach, reach))
        target = glm.vec3(rng.uniform(-3, 3), rng.uniform(-2, 2), rng.uniform(-3, 3))
        if glm.length(target - eye) < 0.5:
            target += glm.vec3(1.0, 0.0, 0.0)
        skip = rng.choice(surfaces) if surfaces and rng.random() < 0.4 else 0
        views.append(View(glm.lookAt(eye, target, Y), glm.perspective(rng.uniform(0.4, 1.6), 16 / 9, 0.05, 100.0),
                          eye, (64, 36), skip=skip))
    return views


@pytest.mark.parametrize("seed,panes,ponds,walls", [
    (1, 3, 1, 1), (2, 6, 2, 0), (3, 14, 1, 1), (4, 24, 2, 2), (5, 40, 3, 1), (6, 30, 0, 3), (7, 60, 1, 0)])
def test_the_slot_order_is_the_every_pair_reference_on_random_scenes(scene, seed, panes, ponds, walls):
    ents: dict = {}
    runner = scene(_random_level(seed, panes, ponds, walls, ents), (64, 36))
    runner.frame()
    runner.frame()
    batches = runner.engine.renderer.transparent_batches()
    assert len(batches) == panes + ponds + walls
    assert sum(batch.plane is not None for batch in batches) == ponds + walls  # the surfaces' planes are known
    geometry = SlotGeometry(batches)
    rng = random.Random(seed)
    kinds = {"reordered": 0, "held back": 0, "cycles": 0, "torn": 0, "behind the eye": 0}
    for view in _random_views(rng, 60, ents["surfaces"]):
        want, (first, rest, torn) = _reference(batches, view.eye, view)
        assert back_to_front(batches, view.eye, view, geometry) == want
        assert back_to_front(batches, view.eye, None, geometry) == _reference(batches, view.eye, None)[0]
        got = split_slot(batches, view, geometry)
        assert (got.first, got.rest, got.torn) == (first, rest, torn)
        assert split_slot(batches, view, geometry) is got  # kept for the view's second call
        centres = sorted(batches, key=lambda b: -glm.distance(b.centre(), view.eye))
        kinds["reordered"] += want != centres
        kinds["held back"] += len(first) > sum(b.surface for b in first)
        kinds["torn"] += torn > 0
        kinds["behind the eye"] += any(_rect(_corners(b), view.view_proj) is None for b in batches)
        kinds["cycles"] += slot_order.slot_order(geometry, geometry.back_to_front(view.eye), view.eye,
                                                  view).planes_only
    # What the order must get right is there (in every scene with a surface; cycles and
    # batches torn between two surfaces where there are two).
    assert kinds["reordered"] >= 10 and kinds["held back"] >= 10 and kinds["behind the eye"] >= 10, kinds
    if ponds + walls >= 2:
        assert kinds["cycles"] and kinds["torn"], kinds


# -- the blend rule with many batches --------------------------------------------------------

def _many_panes(ents: dict, alpha: float | None):
    """A wide see-through pond (centre (0, 0, -1)) and ten small panes in columns across it, none
    in front of another or of another's reflection: standing on it at its far side (their
    centres farther than the pond's) and lying under it near the camera (nearer), the
    order the centres get wrong both ways, plus an orange floor and a green wall."""
    def build(world) -> None:
        world.spawn(Skybox())
        look_from(world, (0.0, 2.5, 6.0), target=(0.0, 0.0, -2.0))
        world.spawn(Transform(position=(0.0, -1.0, -1.0), rotation=FLAT), MeshRef(quad(24.0, 14.0)),
                    Material(color=(0.8, 0.5, 0.2)), Emissive(0.4))
        world.spawn(Transform(position=(0.0, 1.0, -8.0)), MeshRef(quad(30.0, 6.0)),
                    Material(color=(0.1, 0.8, 0.1)), Emissive(1.0))
        ents["pond"] = world.spawn(Transform(position=(0.0, 0.0, -1.0), rotation=FLAT), MeshRef(quad(14.0, 8.0)),
                                   Material(color=(0.2, 0.3, 0.6, 0.6)), Mirror(reflect_rate=0.7))
        ents["panes"] = []
        if alpha is None:
            return
        for i in range(10):
            x = -4.5 + i
            if i % 2:  # standing on the pond, its lower edge 0.2 m above the water
                parts = [Transform(position=(x, 0.55, -3.5)), MeshRef(quad(0.6, 0.7))]
            else:  # lying under the water, near the camera
                parts = [Transform(position=(x, -0.4, 1.2), rotation=FLAT), MeshRef(quad(0.6, 0.6))]
            ents["panes"].append(world.spawn(*parts, Material(color=(0.9, 0.15, 0.1 + 0.08 * i, alpha)),
                                             Emissive(0.6)))
    return build


@pytest.mark.parametrize("path", ["per_mirror", "batched"])
def test_many_panes_around_a_pond_blend_in_depth_order(scene, path):
    """More batches than the pairwise order takes (``slot_order.FEW_BATCHES``): the slot
    is ordered in arrays, and every pixel of the frame is still the blend rule of
    ``tests/test_glass_and_water.py``."""
    out = []
    for alpha in (ALPHA, None, 1.0):
        ents: dict = {}
        out.append(_render(scene, _many_panes(ents, alpha), ents, path=path))
    glass, without, opaque = out
    assert len(glass["runner"].engine.renderer.transparent_batches()) == 11 > slot_order.FEW_BATCHES
    pond = glass["ents"]["pond"]
    standing = np.isin(glass["seen"], glass["ents"]["panes"][1::2])
    under = (glass["surface"] == pond) & (np.abs(opaque["colour"] - without["colour"]).max(axis=-1) > 0.05) \
        & ~standing
    assert standing.sum() > 300 and under.sum() > 100, (standing.sum(), under.sum())
    _blend_agrees(glass["colour"], opaque["colour"], without["colour"])
    assert glass["rgb"].max() > 100
    assert glass["runner"].stats.glass_between_surfaces == 0


def test_the_slot_geometry_is_kept_while_the_glass_stands_and_worked_out_when_a_pane_moves(scene):
    """``ScenePass._slot_geometry`` keeps its ``SlotGeometry`` across frames while the
    transparent batches stand (other things moving), and works it out again when a pane
    moves (its uploads), with the pane's new centre; the frames' blend order follows."""
    ents: dict = {}
    spinning: list = []

    def build(world) -> None:
        _random_level(3, 14, 1, 1, ents)(world)
        spinning.append(world.spawn(Transform(position=(0.0, 8.0, 0.0)), MeshRef(quad(1.0, 1.0)),
                                    Material(color=(0.5, 0.5, 0.5))))

    runner = scene(build, (64, 36))
    runner.frame()
    passes = runner.engine.renderer.scene_pass
    kept = passes._slot_kept
    assert kept is not None and len(kept.batches) == 16
    spinner = runner.world.get(spinning[0], Transform)
    spinner.position = (1.0, 8.0, 0.0)  # an opaque thing moves: the glass stands
    runner.frame()
    assert passes._slot_kept is kept
    batches = runner.engine.renderer.transparent_batches()
    pane = next(b for b in batches if not b.surface)
    entity = pane.entity_at[0]
    runner.world.get(entity, Transform).position = (0.5, 7.0, -0.5)
    runner.frame()
    assert passes._slot_kept is not kept
    at = passes._slot_kept.batches.index(pane)
    assert glm.distance(passes._slot_kept.centres[at], glm.vec3(0.5, 7.0, -0.5)) < 1e-5
