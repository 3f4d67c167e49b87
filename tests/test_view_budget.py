"""One view budget a frame (issue 27 item 3): mirror views, portal views and probe faces
spend it in drawing order; within a level, surfaces of higher priority and larger coverage
first; probes by first capture, priority and distance, under a time budget too; what is
cut is counted.  Counts come from the frame's own views, not from the budget's ledger only."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import (
    DirectionalLight,
    Emissive,
    Material,
    MeshRef,
    Mirror,
    Portal,
    ReflectionProbe,
    Reflective,
    Transform,
)
from engine.assets.mesh import box, quad, sphere
from engine.assets.portals import spawn_portal_pair
from engine.resources import ViewBudget
from engine.rules.probe_schedule import ProbeStates
from shell.overlay_text import overlay_lines
from tests.support import look_from, pixel_rays
from tests.test_view_tree import mirror_grid


def test_a_frame_budget_of_n_views_keeps_the_frames_views_at_most_n(scene):
    ents = {}
    runner = scene(mirror_grid(ents), (320, 200))
    runner.world.resources[ViewBudget] = ViewBudget(views=12)
    runner.frame()
    stats = runner.stats
    views = runner.engine.reflection_system.views[1:]
    assert len(views) == stats.reflection_views == 12 == stats.views_spent
    assert stats.views_cut == 60 - 12
    # The ones kept cover the most pixels (no priorities set): none cut covers more.
    surface = runner.engine.renderer.targets.read_surface_ids()
    pixels = {m: int((surface == m).sum()) for m in ents["mirrors"]}
    kept = {v.surface.entity for v in views}
    assert min(pixels[m] for m in kept) >= max(pixels[m] for m in pixels if m not in kept)


def test_a_surfaces_priority_comes_before_its_coverage(scene):
    ents = {}
    runner = scene(mirror_grid(ents), (320, 200))
    runner.frame()
    surface = runner.engine.renderer.targets.read_surface_ids()
    smallest = min(ents["mirrors"], key=lambda m: (surface == m).sum())
    runner.world.get(smallest, Mirror).priority = 5
    runner.world.resources[ViewBudget] = ViewBudget(views=3)
    runner.frame()
    kept = [v.surface.entity for v in runner.engine.reflection_system.views[1:]]
    assert len(kept) == 3 and smallest in kept


def test_deeper_levels_are_cut_first(scene):
    """Two facing mirrors to depth 4: a budget of 3 draws levels 1 to 3 and cuts the rest."""
    def build(world):
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=1.0))
        look_from(world, (0.3, 1.5, 1.0), target=(0.0, 1.5, -3.0), fov=50.0)
        for z, turn in ((-3.0, 0.0), (3.0, math.pi)):
            world.spawn(Transform(position=(0.0, 1.5, z), rotation=glm.angleAxis(turn, glm.vec3(0, 1, 0))),
                        MeshRef(quad(3.0, 2.5)), Material(color=(0.2, 0.2, 0.2)), Mirror(max_depth=4))
    runner = scene(build, (160, 120))
    runner.frame()
    unlimited = [v.level for v in runner.engine.reflection_system.views[1:]]
    assert max(unlimited) == 4
    runner.world.resources[ViewBudget] = ViewBudget(views=3)
    runner.frame()
    levels = sorted(v.level for v in runner.engine.reflection_system.views[1:])
    assert levels == sorted(unlimited)[:3] and runner.stats.views_cut >= 1


def _probe_room(world, probes):
    """Probes at x = -4, 0, 4 over chrome balls, a glowing box to see, and the camera."""
    world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=1.0))
    look_from(world, (0.0, 1.5, 8.0), target=(0.0, 1.0, 0.0), fov=60.0)
    world.spawn(Transform(position=(0.0, 1.0, -4.0)), MeshRef(box()), Material(color=(0.9, 0.2, 0.1)), Emissive(1.0))
    owners = []
    for x, settings in zip((-4.0, 0.0, 4.0), probes, strict=True):
        owners.append(world.spawn(Transform(position=(x, 1.0, 0.0)), MeshRef(sphere(0.5)),
                                  Material(color=(1.0, 1.0, 1.0), metallic=1.0, roughness=0.0),
                                  Reflective(mode="cube"), settings))
    return owners


def test_probe_faces_spend_the_views_budget_first_captures_whole(scene):
    """Two new probes and a budget of 8 views: one first capture (6 faces) fits; the other
    waits whole (nothing samples a half-made cube) and is captured next frame."""
    owners = []
    runner = scene(lambda world: owners.extend(_probe_room(world, [
        ReflectionProbe(resolution=16, refresh="once", depth=0),
        ReflectionProbe(resolution=16, refresh="once", depth=0),
        ReflectionProbe(resolution=16, refresh="once", depth=0, priority=-1)])), (160, 120))
    runner.world.resources[ViewBudget] = ViewBudget(views=8)
    runner.frame()
    states = runner.world.resources[ProbeStates]
    assert sum(states[owner].faces_captured for owner in owners) == 6 <= runner.stats.views_spent <= 8
    assert runner.stats.probe_faces_deferred == 12
    captured = [owner for owner in owners if states[owner].faces_captured]
    assert len(captured) == 1 and owners[2] not in captured  # the lowest priority waits
    runner.frame()
    assert sum(1 for owner in owners if states[owner].faces_captured == 6) == 2
    runner.frame()
    assert all(states[owner].faces_captured == 6 for owner in owners)


def test_the_probe_time_budget_takes_one_probe_a_frame_by_priority_and_none_starves(scene):
    owners = []
    runner = scene(lambda world: owners.extend(_probe_room(world, [
        ReflectionProbe(resolution=16, refresh="every_frame", depth=0),
        ReflectionProbe(resolution=16, refresh="every_frame", depth=0, priority=3),
        ReflectionProbe(resolution=16, refresh="every_frame", depth=0)])), (160, 120))
    runner.frame()  # first captures: all three (no cost measured yet)
    states = runner.world.resources[ProbeStates]
    assert states.face_ms is not None and states.face_ms > 0.0
    order = []
    for _ in range(6):
        # Under one probe's cost by the estimate the scheduler spends by: set from it each
        # frame (the estimate follows the measured captures, so a budget fixed once from the
        # first frame's could fit two probes on a machine whose load eased: relative, not timed).
        runner.world.resources[ViewBudget] = ViewBudget(probe_ms=states.face_ms * 0.5)
        before = {owner: states[owner].captures for owner in owners}
        runner.frame()
        done = [owner for owner in owners if states[owner].captures > before[owner]]
        assert len(done) == 1, done
        order.append(done[0])
        assert runner.stats.probe_faces_deferred == 12
    assert order[0] == owners[1]               # the highest priority goes first
    assert set(order) == set(owners)           # and the others still get their turn


def test_portal_views_spend_the_same_budget(scene):
    def build(world):
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=1.0))
        look_from(world, (0.0, 1.5, 3.0), target=(0.0, 1.5, -3.0), fov=60.0)
        a = world.spawn(Transform(position=(0.0, 1.5, -3.0)), MeshRef(quad(2.0, 2.0)), Portal(size=(2.0, 2.0)))
        b = world.spawn(Transform(position=(0.0, 1.5, 3.5), rotation=glm.angleAxis(math.pi, glm.vec3(0, 1, 0))),
                        MeshRef(quad(2.0, 2.0)), Portal(size=(2.0, 2.0), partner=a))
        world.get(a, Portal).partner = b
    runner = scene(build, (160, 120))
    runner.frame()
    assert runner.stats.reflection_views >= 3
    runner.world.resources[ViewBudget] = ViewBudget(views=2)
    runner.frame()
    assert runner.stats.reflection_views == 2 and runner.stats.views_cut >= 1


def test_the_overlay_reports_the_budget(scene):
    ents = {}
    runner = scene(mirror_grid(ents, columns=4, rows=2), (320, 200))
    runner.world.resources[ViewBudget] = ViewBudget(views=5, probe_ms=2.0)
    runner.frame()
    lines = overlay_lines(runner.engine, [0.02])
    assert f"view budget 5: spent 5, cut {8 - 5}" in lines
    assert "probe budget 2 ms: spent 0.0 ms, 0 faces wait" in lines
    assert f"pixel budget none: spent {runner.stats.pixels_spent}, 0 levels smaller" in lines


@pytest.mark.parametrize("kwargs", [{"views": -1}, {"views": 2.5}, {"views": True}, {"probe_ms": 0.0},
                                    {"probe_ms": float("inf")}, {"probe_ms": "1"}, {"min_pixels": 0},
                                    {"min_pixels": 2.5}, {"min_pixels": True}])
def test_bad_budgets_are_refused_naming_the_field(kwargs):
    with pytest.raises(ValueError, match=f"ViewBudget.{next(iter(kwargs))}"):
        ViewBudget(**kwargs)


def test_priorities_are_checked():
    from components import ComponentValueError
    for component in (Mirror, Portal, ReflectionProbe):
        with pytest.raises(ComponentValueError, match=f"{component.__name__}.priority"):
            component(priority=1.5)


def eight_mirrors_drawn_whole(scene, ents):
    """Eight mirrors drawn one frame without a budget: the runner, the reflection pixels
    that frame drew (counted exactly, on a GPU too) and the renderer's levels."""
    runner = scene(mirror_grid(ents, columns=4, rows=2), (320, 200))
    runner.engine.reflection_system.visibility = "exact"
    runner.frame()
    return runner, runner.stats.pixels_spent, runner.engine.renderer.levels


def test_a_pixel_budget_draws_a_level_at_lower_resolution_instead_of_cutting_it(scene):
    """Last frame's coverage of level 1 is known; a budget of a quarter of it draws level 1
    at half resolution (scale sqrt(1/4)): every view kept, each still showing the panel,
    and the pixels drawn within the budget."""
    ents = {}
    runner, full, levels = eight_mirrors_drawn_whole(scene, ents)
    assert full > 0 and levels[1].size == (320, 200)
    runner.world.resources[ViewBudget] = ViewBudget(pixels=full // 4)
    runner.frame()
    stats = runner.stats
    assert stats.levels_downscaled == 1 and stats.views_cut == 0 and stats.reflection_views == 8
    assert levels[1].size == (160, 100)
    assert stats.pixels_spent <= full // 4
    surface = runner.engine.renderer.targets.read_surface_ids()
    seen = runner.ids()
    on_mirrors = np.isin(surface, ents["mirrors"])
    assert (seen[on_mirrors] == ents["panel"]).mean() > 0.75  # half resolution loses edge pixels (as resolution_scale)
    for mirror in ents["mirrors"]:
        assert (seen[surface == mirror] == ents["panel"]).mean() > 0.5
    # A budget below what the lowest resolution needs cuts views instead.
    runner.world.resources[ViewBudget] = ViewBudget(pixels=full // 100)
    runner.frame()
    assert runner.stats.views_cut >= 1 and runner.stats.pixels_spent <= full // 100


def test_a_level_drawn_at_two_sizes_in_turn_keeps_both_target_sets(scene):
    """The pixel budget's scales come in steps, and a level keeps its targets of the size
    before: alternating between full and half resolution makes no GPU targets after the
    first round."""
    ents = {}
    runner, full, levels = eight_mirrors_drawn_whole(scene, ents)
    sizes, made = [], []
    for frame in range(6):
        runner.world.resources[ViewBudget] = ViewBudget(pixels=full // 4 if frame % 2 == 0 else None)
        runner.frame()
        sizes.append(levels[1].size)
        made.append(levels.made)
    assert sizes == [(160, 100), (320, 200)] * 3
    assert made[1] == made[-1]



def test_a_resize_releases_the_targets_kept_for_the_old_size(scene):
    """A level keeps its previous size's set only while the window keeps its size: after a
    resize the sets kept for the old size are released (at 1920x1080 one is about 50 MB of
    GPU memory), the levels follow the new size, and the pixel budget's alternation keeps
    one set a level again."""
    from engine.render.targets import CaptureTarget, RenderTargets

    ents = {}
    runner, full, levels = eight_mirrors_drawn_whole(scene, ents)
    for frame in range(2):
        runner.world.resources[ViewBudget] = ViewBudget(pixels=full // 4 if frame % 2 == 0 else None)
        runner.frame()
    assert levels.kept() >= 1
    released = []
    original = RenderTargets.release

    def spy(self):
        released.append(self.size)
        original(self)

    RenderTargets.release = spy
    try:
        runner.world.resources[ViewBudget] = ViewBudget()
        runner.capture.release()
        runner.size = (200, 120)
        runner.capture = CaptureTarget(runner.ctx, runner.size)
        runner.frame()
    finally:
        RenderTargets.release = original
    assert levels.kept() == 0 and levels[0].size == (200, 120) and levels[1].size == (200, 120)
    assert (160, 100) in released and (320, 200) in released  # the kept half-size set and the old full ones


# --- budgets that never starve (issue 41 item 3) ----------------------------------------------

def _faces_drawn(monkeypatch):
    """Records every capture's (probe, faces) through the renderer's captures, frame by frame."""
    from engine.render.probes import ProbeCaptures

    drawn: list[list[tuple[int, frozenset[int]]]] = [[]]
    original = ProbeCaptures.capture_probe

    def recorded(self, key, faces, *args, **kwargs):
        drawn[-1].append((key, frozenset(faces)))
        return original(self, key, faces, *args, **kwargs)

    monkeypatch.setattr(ProbeCaptures, "capture_probe", recorded)
    return drawn


@pytest.mark.parametrize("views", [1, 4, 5])
def test_a_budget_smaller_than_a_cube_still_captures_every_probe_one_a_frame(scene, monkeypatch, views):
    """Under 6 views no frame could fit a first capture, and none was ever drawn: now each
    is drawn whole as the frame's first view (a half-made cube is never sampled), one probe
    a frame, past the budget by the difference, said once."""
    import warnings

    owners = []
    runner = scene(lambda world: owners.extend(_probe_room(world, [
        ReflectionProbe(resolution=16, refresh="once", depth=0) for _ in range(3)])), (64, 48))
    runner.world.resources[ViewBudget] = ViewBudget(views=views)
    drawn = _faces_drawn(monkeypatch)
    states = None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(3):
            runner.frame()
            states = runner.world.resources[ProbeStates]
            assert [len(faces) for _, faces in drawn[-1]] == [6], drawn[-1]  # one probe, whole
            assert runner.stats.views_spent == 6
            drawn.append([])
    assert all(states[owner].faces_captured == 6 for owner in owners)
    said = [str(w.message) for w in caught if "below a probe's six faces" in str(w.message)]
    assert len(said) == 1 and f"ViewBudget.views = {views}" in said[0]
    runner.frame()
    assert drawn[-1] == []  # once-probes: nothing more


def test_a_budget_of_zero_views_captures_nothing(scene):
    owners = []
    runner = scene(lambda world: owners.extend(_probe_room(world, [
        ReflectionProbe(resolution=16, depth=0) for _ in range(3)])), (64, 48))
    runner.world.resources[ViewBudget] = ViewBudget(views=0)
    for _ in range(3):
        runner.frame()
    states = runner.world.resources[ProbeStates]
    assert all(states[owner].faces_captured == 0 for owner in owners) and runner.stats.views_spent == 0


def test_recaptures_left_part_of_a_cube_redraw_the_faces_that_waited_longest(scene, monkeypatch):
    """An every-frame probe with 5 views a frame for its six faces: the lowest five were
    redrawn every frame and face 5 never; now every face is redrawn at least every other frame."""
    owners = []
    runner = scene(lambda world: owners.extend(_probe_room(world, [
        ReflectionProbe(resolution=16, refresh="every_frame", depth=0),
        ReflectionProbe(resolution=16, refresh="once", depth=0),
        ReflectionProbe(resolution=16, refresh="once", depth=0)])), (64, 48))
    runner.frame()  # first captures, no budget
    runner.world.resources[ViewBudget] = ViewBudget(views=5)
    drawn = _faces_drawn(monkeypatch)
    for _ in range(8):
        runner.frame()
        drawn.append([])
    per_frame = [set().union(*(faces for key, faces in frame if key == owners[0])) for frame in drawn[:-1]]
    assert all(len(faces) <= 5 for faces in per_frame)
    for face in range(6):
        frames = [index for index, faces in enumerate(per_frame) if face in faces]
        assert frames and max(b - a for a, b in zip([-1, *frames], [*frames, len(per_frame)], strict=True)) <= 2, \
            (face, per_frame)


def test_recaptures_get_a_face_a_frame_when_reflections_spend_the_whole_budget(scene, monkeypatch):
    """Eight mirrors and a budget of eight views: the main view's tree spends it all before
    the recaptures (drawn after present), which never got one; now a face that has waited
    STARVING_FRAMES is drawn in the probes stage, before the tree, so every face of the
    probe is redrawn in bounded time, and the frame keeps to its budget."""
    from systems.probe_system import STARVING_FRAMES

    ents = {}

    def build(world):
        mirror_grid(ents, columns=4, rows=2)(world)
        ents["probe"] = world.spawn(Transform(position=(0.0, 1.0, 1.0)), MeshRef(sphere(0.3)),
                                    Material(color=(1, 1, 1), metallic=1.0, roughness=0.0), Reflective(mode="cube"),
                                    ReflectionProbe(resolution=16, refresh="every_frame", depth=0))
    runner = scene(build, (160, 100))
    runner.frame()
    runner.world.resources[ViewBudget] = ViewBudget(views=8)
    drawn = _faces_drawn(monkeypatch)
    frames = 6 * (STARVING_FRAMES + 1) + 2
    for _ in range(frames):
        runner.frame()
        assert runner.stats.views_spent <= 8
        drawn.append([])
    faces = set().union(*(f for frame in drawn for key, f in frame if key == ents["probe"]))
    assert faces == set(range(6)), faces
    assert runner.stats.reflection_views >= 7  # the mirrors still get the rest of the budget


# --- the smallest view worth a pass (ViewBudget.min_pixels) -----------------------------------

def _two_mirrors(ents):
    """A large and a small mirror side by side, facing the camera, and a red wall behind
    the camera for both to show; neither sees the other."""
    def build(world):
        look_from(world, (0.0, 1.5, 4.0), target=(0.0, 1.5, -3.0), fov=60.0)
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))
        world.spawn(Transform(position=(0.0, 1.5, 8.0)), MeshRef(box((12.0, 4.0, 0.5))),
                    Material(color=(0.9, 0.2, 0.1)))
        ents["big"] = world.spawn(Transform(position=(-1.2, 1.5, -3.0)), MeshRef(quad(2.0, 2.0)), Mirror())
        ents["small"] = world.spawn(Transform(position=(1.6, 1.5, -3.0)), MeshRef(quad(0.4, 0.4)), Mirror())
    return build


def _seen_sizes(runner, ents):
    """Each mirror's pixels in the frame (the surface id buffer), with the frame drawn whole."""
    runner.world.resources.pop(ViewBudget, None)
    whole = runner.frame()
    surface = runner.engine.renderer.targets.read_surface_ids()
    big, small = (surface == ents["big"]), (surface == ents["small"])
    assert 0 < small.sum() < big.sum() and runner.stats.reflection_views == 2
    assert runner.stats.pixels_spent == big.sum() + small.sum()  # a view's claim: its surface's pixels
    return whole, big, small


@pytest.mark.parametrize("visibility", ["exact", "predicted"])
def test_a_view_under_the_smallest_worth_a_pass_shows_its_fallback(scene, visibility):
    """A view that would show fewer pixels than ``min_pixels`` is not drawn: its mirror
    shows the fallback, pixel for pixel what a view budget that cuts it shows (the budget
    cuts the view covering fewer pixels first), and the large mirror its reflection as
    before.  Predicted visibility goes by last frame's count, so the view goes the frame
    after; a view of exactly ``min_pixels`` stays."""
    ents = {}
    runner = scene(_two_mirrors(ents), (160, 120))
    runner.engine.reflection_system.visibility = visibility
    runner.frame()
    whole, big, small = _seen_sizes(runner, ents)
    runner.world.resources[ViewBudget] = ViewBudget(min_pixels=int(small.sum()))
    runner.frame()
    assert runner.stats.reflection_views == 2 and runner.stats.views_small == 0
    runner.world.resources[ViewBudget] = ViewBudget(min_pixels=int(small.sum()) + 1)
    frames = [runner.frame() for _ in range(2)]
    cut = frames[-1]
    stats = runner.stats
    assert stats.reflection_views == 1 and stats.views_small == 1 and stats.views_cut == 0
    assert [v.surface.entity for v in runner.engine.reflection_system.views[1:]] == [ents["big"]]
    assert stats.pixels_spent == big.sum() and stats.reflection_fallbacks >= 1
    assert np.array_equal(cut[big], whole[big])
    assert np.abs(cut[small].astype(int) - whole[small].astype(int)).max() > 40  # the red wall is gone there
    runner.world.resources[ViewBudget] = ViewBudget(views=1)
    budgeted = runner.frame()
    assert runner.stats.views_cut == 1 and runner.stats.reflection_views == 1
    assert np.array_equal(cut, budgeted)


def test_probe_faces_leave_out_their_small_views_too(scene):
    """The budget's smallest view holds in every tree: a probe whose faces see a small
    mirror draws no view of it (the main camera sees no mirror), and says so."""
    def build(world):
        look_from(world, (0.0, 1.5, 4.0), target=(0.0, 1.5, 8.0))  # away from the mirror
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))
        world.spawn(Transform(position=(0.0, 1.5, -1.0)), MeshRef(sphere(0.3)), Material(metallic=1.0, roughness=0.0),
                    ReflectionProbe(resolution=32, refresh="every_frame"), Reflective(mode="cube"))
        world.spawn(Transform(position=(0.0, 1.5, -4.0)), MeshRef(quad(0.6, 0.6)), Mirror())
        world.spawn(Transform(position=(0.0, 1.5, 1.0)), MeshRef(box((4.0, 3.0, 0.3))), Material(color=(0.2, 0.8, 0.3)))
    runner = scene(build, (160, 120))
    runner.frame()
    runner.frame()
    passes, faces, spent = runner.stats.passes, runner.stats.probe_faces, runner.stats.views_spent
    assert faces >= 1 and runner.stats.views_small == 0 and runner.stats.reflection_views == 0
    runner.world.resources[ViewBudget] = ViewBudget(min_pixels=32 * 32)  # more than a face holds
    runner.frame()
    stats = runner.stats
    assert stats.views_small >= 1 and stats.probe_faces == faces and stats.reflection_views == 0
    assert stats.views_spent == spent - stats.views_small and stats.passes == passes - stats.views_small


HALF_TURN = glm.angleAxis(math.pi, glm.vec3(0, 1, 0))
SMALL_SIZE = (128, 96)
BIG = ((-0.5, 1.5, -1.0), (1.6, 1.2))    # a mirror facing the camera: centre, half sizes
BEHIND = ((2.2, 1.7, 5.5), (0.8, 0.6))   # a mirror behind the camera facing it, seen in BIG
DOOR = ((1.7, 1.0, -1.0), (0.2, 0.2))    # a small portal beside BIG


def _small_portal_and_level_two(ents):
    """A large mirror (level 1, depth 1), a small portal beside it (level 1: its partner
    faces a green wall) and, behind the camera, a mirror seen in the large one (level 2,
    depth 2), whose image straddles the large mirror's right edge.  A red wall behind the
    camera is what the large mirror shows, a yellow one behind the large mirror what the
    mirror behind shows (each distinct from the sky a skipped view's fallback shows)."""
    def build(world):
        look_from(world, (0.0, 1.5, 4.0), target=(0.0, 1.5, -1.0))
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))
        world.spawn(Transform(position=(0.0, 1.5, 9.0)), MeshRef(box((16.0, 6.0, 0.5))),
                    Material(color=(0.9, 0.2, 0.1)))
        world.spawn(Transform(position=(0.0, 1.5, -6.0)), MeshRef(box((16.0, 8.0, 0.5))),
                    Material(color=(0.9, 0.8, 0.1)), Emissive(0.6))
        ents["big"] = world.spawn(Transform(position=BIG[0]), MeshRef(quad(2 * BIG[1][0], 2 * BIG[1][1])),
                                  Mirror(max_depth=1, end_image=False))
        ents["behind"] = world.spawn(Transform(position=BEHIND[0], rotation=HALF_TURN),
                                     MeshRef(quad(2 * BEHIND[1][0], 2 * BEHIND[1][1])),
                                     Mirror(max_depth=2, end_image=False))
        ents["door"], _ = spawn_portal_pair(world, DOOR[0], None, (30.0, 1.5, 0.0),
                                            glm.angleAxis(math.pi / 2, glm.vec3(0, 1, 0)),
                                            size=(2 * DOOR[1][0], 2 * DOOR[1][1]), max_depth=1)
        world.spawn(Transform(position=(33.0, 1.5, 0.0)), MeshRef(box((0.3, 6.0, 6.0))),
                    Material(color=(0.1, 0.9, 0.2)), Emissive(1.0))
    return build


def _rect_hits(origin, directions, rect):
    """Whether rays meet the rectangle ``rect`` (centre, half sizes) in the plane z = centre.z."""
    (x, y, z), (hw, hh) = rect
    t = (z - origin[..., 2]) / directions[..., 2]
    at = origin + t[..., None] * directions
    return (t > 0) & (np.abs(at[..., 0] - x) < hw) & (np.abs(at[..., 1] - y) < hh)


def _grown(mask):
    """``mask`` and the pixels next to it (the antialiasing pass blends an edge's neighbours)."""
    padded = np.pad(mask, 1)
    return np.any([padded[1 + dy:padded.shape[0] - 1 + dy, 1 + dx:padded.shape[1] - 1 + dx]
                   for dy in (-1, 0, 1) for dx in (-1, 0, 1)], axis=0)


@pytest.mark.parametrize("visibility", ["exact", "predicted"])
def test_a_small_portal_view_and_a_small_level_two_view_go_by_their_projected_pixels(scene, visibility):
    """``min_pixels`` holds for a portal's view and for a view below a mirror's, by the pixels
    each would show, cast in float64 at pixel centres (no renderer): the portal's rectangle
    hit by the camera's rays; the mirror behind hit by the rays the large mirror reflects,
    only where they come off the large mirror (its image straddles the large mirror's edge:
    what lies past it is no pixel of the view).  A budget of exactly a view's pixels keeps
    it, one more skips it: counted (``views_small``), no pass, its surface shows its
    fallback there (the sky, not the green wall or the yellow one) and every other pixel (but
    its antialiased edge) is as drawn whole.  Predicted visibility goes by last frame's counts: two frames a step
    (the second not kept from the first, so its passes are counted)."""
    ents = {}
    runner = scene(_small_portal_and_level_two(ents), SMALL_SIZE)
    runner.engine.reflection_system.visibility = visibility
    runner.engine.reflection_system.keep_still_views = False

    def frames(budget):
        if budget is None:
            runner.world.resources.pop(ViewBudget, None)
        else:
            runner.world.resources[ViewBudget] = ViewBudget(min_pixels=budget)
        runner.frame()
        rgb = runner.frame()
        views = [(v.level, v.surface.entity) for v in runner.engine.reflection_system.views[1:]]
        return rgb, views, runner.stats

    whole, views, stats = frames(None)
    eye, rays = pixel_rays(runner.engine.main_view, SMALL_SIZE)
    big, door = _rect_hits(eye, rays, BIG), _rect_hits(eye, rays, DOOR)
    flip = np.array([1.0, 1.0, -1.0])
    reflected = (eye * flip + (0.0, 0.0, 2.0 * BIG[0][2]), rays * flip)  # in the large mirror's plane
    behind = big & _rect_hits(*reflected, BEHIND)
    assert _rect_hits(*reflected, BEHIND).sum() > behind.sum() + 20  # the image crosses the large mirror's edge
    assert 30 < door.sum() < behind.sum() < big.sum()
    assert sorted(views) == sorted([(1, ents["big"]), (1, ents["door"]), (2, ents["behind"])])
    assert stats.views_small == 0 and stats.passes == 1 + 3
    assert stats.pixels_spent == big.sum() + door.sum() + behind.sum()
    surface = runner.engine.renderer.targets.read_surface_ids()
    assert np.array_equal(surface == ents["big"], big) and np.array_equal(surface == ents["door"], door)
    green, yellow = whole[door].astype(int), whole[behind].astype(int)
    assert (green[:, 1] > green[:, 0] + 60).all() and (yellow[:, 2] < yellow[:, 0] - 60).all()

    rgb, views, stats = frames(int(door.sum()))  # exactly the portal's pixels: kept
    assert len(views) == 3 and stats.views_small == 0 and np.array_equal(rgb, whole)

    rgb, views, stats = frames(int(door.sum()) + 1)
    assert sorted(views) == sorted([(1, ents["big"]), (2, ents["behind"])])
    assert stats.views_small == 1 and stats.passes == 1 + 2 and stats.views_cut == 0
    assert stats.pixels_spent == big.sum() + behind.sum() and stats.reflection_fallbacks >= 1
    elsewhere = ~_grown(door)
    assert np.array_equal(rgb[elsewhere], whole[elsewhere])
    shown = rgb[door].astype(int)
    assert (shown[:, 1] < shown[:, 0] + 30).all() and (shown.sum(axis=1) > 100).all()  # the sky's grey, not green

    rgb, views, stats = frames(int(behind.sum()))  # exactly the level-2 view's pixels: kept
    assert len(views) == 2 and stats.views_small == 1 and np.array_equal(rgb[elsewhere], whole[elsewhere])

    rgb, views, stats = frames(int(behind.sum()) + 1)
    assert views == [(1, ents["big"])]
    assert stats.views_small == 2 and stats.passes == 1 + 1 and stats.pixels_spent == big.sum()
    elsewhere = ~_grown(door | behind)
    assert np.array_equal(rgb[elsewhere], whole[elsewhere])
    shown = rgb[behind].astype(int)
    assert (shown[:, 2] > shown[:, 0] - 30).all() and (shown.sum(axis=1) > 100).all()  # the sky's, not yellow


def test_min_pixels_leaves_out_the_same_small_views_on_the_batched_path_as_on_the_per_mirror_path(scene):
    """The small portal (level 1) and the small level-2 view above, on both reflection
    paths: at each budget (none; exactly the portal's pixels; one more; one more than the
    level-2 view's, pixels cast in float64 as there) the same views are drawn, the same
    counted small, the pixels spent are the rays' count, and the passes are the paths' own
    (per mirror: one a view; batched: one a level and winding, the large mirror's view
    mirrored, the portal's not, the level-2 view reflected twice: worked out from the views
    kept); the batched frame is the per-mirror one's within 2 levels, and a skipped view's
    surface shows the sky there, not the green or yellow wall its view shows."""
    runs = {}
    for path in ("per_mirror", "batched"):
        ents = {}
        runner = scene(_small_portal_and_level_two(ents), SMALL_SIZE)
        runner.engine.reflection_system.path = path
        runner.engine.reflection_system.visibility = "exact"
        runner.engine.reflection_system.keep_still_views = False
        runs[path] = runner, ents
    runner, ents = runs["per_mirror"]
    runner.frame()
    eye, rays = pixel_rays(runner.engine.main_view, SMALL_SIZE)
    big, door = _rect_hits(eye, rays, BIG), _rect_hits(eye, rays, DOOR)
    flip = np.array([1.0, 1.0, -1.0])
    behind = big & _rect_hits(eye * flip + (0.0, 0.0, 2.0 * BIG[0][2]), rays * flip, BEHIND)
    assert 30 < door.sum() < behind.sum() < big.sum()
    windings = {"big": (1, True), "door": (1, False), "behind": (2, False)}
    for budget, kept in ((None, ("big", "door", "behind")), (int(door.sum()), ("big", "door", "behind")),
                         (int(door.sum()) + 1, ("big", "behind")), (int(behind.sum()) + 1, ("big",))):
        frames = {}
        for path, (runner, ents) in runs.items():
            if budget is None:
                runner.world.resources.pop(ViewBudget, None)
            else:
                runner.world.resources[ViewBudget] = ViewBudget(min_pixels=budget)
            runner.frame()
            rgb = frames[path] = runner.frame().astype(int)
            stats = runner.stats
            assert stats.reflection_path == path
            views = sorted((v.level, v.surface.entity, v.view.mirrored)
                           for v in runner.engine.reflection_system.views[1:])
            expected = sorted((windings[name][0], ents[name], windings[name][1]) for name in kept)
            assert views == expected, (path, budget)
            assert stats.views_small == 3 - len(kept) and stats.views_cut == 0
            assert stats.pixels_spent == sum(int({"big": big, "door": door, "behind": behind}[name].sum())
                                             for name in kept)
            groups = len(kept) if path == "per_mirror" else len({windings[name] for name in kept})
            assert stats.passes == 1 + groups, (path, budget, stats.passes)
            green, yellow = rgb[door], rgb[behind]
            assert ((green[:, 1] > green[:, 0] + 60).all()) == ("door" in kept), (path, budget)
            assert ((yellow[:, 2] < yellow[:, 0] - 60).all()) == ("behind" in kept), (path, budget)
            if "door" not in kept:  # the sky's grey
                assert (green[:, 1] < green[:, 0] + 30).all() and (green.sum(axis=1) > 100).all()
            if "behind" not in kept:
                assert (yellow[:, 2] > yellow[:, 0] - 30).all() and (yellow.sum(axis=1) > 100).all()
        assert np.abs(frames["batched"] - frames["per_mirror"]).max() <= 2, budget
