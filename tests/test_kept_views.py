"""A still frame keeps the main view tree's levels (``ReflectionSystem.keep_still_views``,
``StillTree.keep``): when nothing its views show changed since they were drawn, levels 1 and
below stay as they are and only the root's fallbacks and level 1's composite are done again.

Every test runs the same level twice on the test context, in lockstep: one engine keeps
still views, the other (``keep_still_views = False``) draws its whole tree every frame.
The kept frames' pixels (the presented colour, the HDR main image and the entity-id image)
must equal the drawn ones bit for bit, and the pass counts say which frames kept: a still
frame keeps (one scene pass, the main view), and a frame after each kind of change draws
its tree again.  With the world-change check off (``ReflectionSystem.watch_world``), the
renderer's ``scene_version`` alone must catch each change made on the GPU side."""
from __future__ import annotations

import math
import random

import numpy as np
import pytest
from pyglm import glm

from components import (
    DirectionalLight,
    Material,
    MeshRef,
    Mirror,
    Portal,
    ReflectionProbe,
    Reflective,
    Skybox,
    Transform,
    Visibility,
    Water,
)
from engine.assets.mesh import box, plane, quad, sphere
from engine.assets.portals import spawn_portal_pair
from engine.assets.texture_data import TextureData, checker_texture
from engine.core.budget import ViewBudget
from shell.overlay_text import overlay_lines
from tests.support import look_from
from tests.test_predicted_visibility import (
    SCALED_SIZE,
    _assert_the_box_where_the_scaled_carry_says,
    _covered_mirrors,
    _scaled_facing_pair,
)

SIZE = (96, 64)
TURN = glm.angleAxis(math.pi / 2, glm.vec3(0, 1, 0))  # a quad facing +X
BACK = glm.angleAxis(math.pi, glm.vec3(0, 1, 0))      # facing -Z


def _hall(world, end_image=False) -> None:
    """A lit floor; a mirror on the left facing +X (depth 3); a facing portal pair ahead of
    the camera, one behind it (depth 4: every level shows the other again); boxes, a chrome
    sphere sampling a probe, and a caster above the floor, all seen in the mirror."""
    world.resources["camera"] = look_from(world, (0.3, 1.5, 3.0), (-0.2, 1.2, -1.5))
    world.resources["sky"] = world.spawn(Skybox())
    world.resources["sun"] = world.spawn(DirectionalLight(direction=(-0.4, -1.0, -0.3), intensity=2.0))
    world.spawn(Transform(), MeshRef(plane(20, 20, uv_repeat=10)), Material(texture=checker_texture(64, 8)))
    world.resources["mirror"] = world.spawn(
        Transform(position=(-1.6, 1.2, 0.5), rotation=TURN), MeshRef(quad(2.5, 2.0)), Material(color=(0.1, 0.1, 0.1)),
        Mirror(max_depth=3, end_image=end_image))
    a, b = spawn_portal_pair(world, (0.8, 1.2, -1.5), None, (0.8, 1.2, 4.5), BACK, size=(1.2, 1.8), max_depth=4)
    for portal in (a, b):
        world.get(portal, Portal).end_image = end_image
    world.resources["box"] = world.spawn(Transform(position=(0.6, 0.3, 0.2)), MeshRef(box((0.6, 0.6, 0.6))),
                                         Material(color=(0.8, 0.3, 0.2)))
    world.resources["caster"] = world.spawn(Transform(position=(-0.3, 1.4, 0.8)), MeshRef(box((0.4, 0.4, 0.4))),
                                            Material(color=(0.2, 0.3, 0.9)))
    world.resources["probe"] = world.spawn(Transform(position=(-0.5, 0.6, -0.3)),
                                           ReflectionProbe(resolution=16, refresh="on_change"))
    world.spawn(Transform(position=(-0.5, 0.6, -0.3)), MeshRef(sphere(0.35, 24, 12)),
                Material(color=(1.0, 1.0, 1.0), metallic=1.0, roughness=0.0), Reflective("cube"))


class _Pair:
    """The same level in two engines, keeping and drawing every frame, in ``visibility``:
    exact unless a test says otherwise, so each test counts the same frames to the first
    keep on llvmpipe and on a GPU (whose "auto" predicts, and keeps a frame later)."""

    def __init__(self, scene, build, size=SIZE, visibility: str = "exact") -> None:
        self.keeping = scene(build, size)
        self.drawing = scene(build, size)
        self.drawing.engine.reflection_system.keep_still_views = False
        for runner in (self.keeping, self.drawing):
            runner.engine.reflection_system.visibility = visibility

    def first(self) -> None:
        """The frames a still level draws before it keeps: one, or with predicted visibility
        two (the first has no counts to predict from)."""
        assert not self.frame()
        if self.keeping.engine.reflection_system.visibility == "predicted":
            assert not self.frame()

    def both(self, change) -> None:
        """``change(world)`` in both worlds (before their next frame)."""
        for runner in (self.keeping, self.drawing):
            change(runner.world)

    def frame(self) -> bool:
        """A frame of each; asserts their pixels are equal; returns whether the keeping one kept."""
        images = []
        for runner in (self.keeping, self.drawing):
            rgb = runner.frame()
            images.append((rgb, np.frombuffer(runner.engine.renderer.targets.color.read(), np.float16), runner.ids()))
        for name, kept, drawn in zip(("colour", "HDR image", "ids"), images[0], images[1], strict=True):
            assert np.array_equal(kept, drawn), f"the kept frame's {name} differs from the frame drawn whole"
        stats = self.keeping.stats
        drawn_views = self.drawing.stats.reflection_views
        assert stats.reflection_views == drawn_views
        # The report and the budget ledger as a drawn frame's (a probe face after the tree
        # spends what the tree left either way).
        for name in ("views_spent", "pixels_spent", "views_cut", "levels_downscaled", "reflection_fallbacks",
                     "reflection_end_views", "reflection_views_faded", "reflection_depth_capped"):
            assert getattr(stats, name) == getattr(self.drawing.stats, name), name
        if stats.reflection_views_kept:
            assert stats.reflection_views_kept == drawn_views > 0 and not stats.reflection_end_refills
            assert stats.passes == 1  # the main view alone: no reflection view drawn
            return True
        if stats.reflection_end_refills:  # kept but for its end images (tests/test_end_image_settle.py)
            assert stats.reflection_end_refills == self.drawing.stats.reflection_end_views > 0
            assert stats.passes < self.drawing.stats.passes
            return False
        assert stats.passes == self.drawing.stats.passes
        return False


def test_a_still_hall_draws_its_tree_once_then_keeps_it_with_the_same_pixels(scene):
    pair = _Pair(scene, _hall)
    assert not pair.frame()
    drawn = pair.drawing.stats
    # the mirror, and the portal with the portal in it again down to depth 4
    assert drawn.reflection_views >= 6 and max(v.level for v in pair.drawing.engine.reflection_system.views) == 4
    assert drawn.passes >= 1 + drawn.reflection_views  # (the probe's first capture draws faces too)
    for _ in range(3):
        assert pair.frame()
    kept = pair.keeping.stats.reflection_views_kept
    assert f"views kept {kept}, end views refilled 0 (keep still views: on)" in overlay_lines(
        pair.keeping.engine, [0.02])
    # The picture is not black: the mirror and the portals show the lit hall.
    assert pair.keeping.capture.read_rgb().mean() > 20
    # Keeping off draws every frame.
    assert pair.drawing.stats.reflection_views_kept == 0


def _move_camera(world):
    t = world.get(world.resources["camera"], Transform)
    t.position = t.position + glm.vec3(0.01, 0.0, 0.0)


def _move_box(world):
    t = world.get(world.resources["box"], Transform)
    t.position = t.position + glm.vec3(0.0, 0.0, 0.2)


def _recolour_box(world):
    world.get(world.resources["box"], Material).color = (0.2, 0.8, 0.3, 1.0)


def _dim_sun(world):
    world.get(world.resources["sun"], DirectionalLight).intensity = 1.2


def _move_caster(world):
    t = world.get(world.resources["caster"], Transform)
    t.position = t.position + glm.vec3(0.3, 0.0, 0.0)


def _new_sky(world):
    world.get(world.resources["sky"], Skybox).faces = [np.full((8, 8, 3), 0.3 + 0.1 * i, np.float32)
                                                       for i in range(6)]


def _mirror_rate(world):
    world.get(world.resources["mirror"], Mirror).reflect_rate = 0.6


def _mirror_fade(world):
    world.get(world.resources["mirror"], Mirror).fade_distance = (0.5, 3.0)


def _hide_box_in_mirrors(world):
    world.add_component(world.resources["box"], Visibility(in_mirrors=False))


def _box_layers(world):
    world.get(world.resources["mirror"], Mirror).shows_layers = [1]  # nothing of layer 0 (all) in it now


def _portal_scale(world):
    """The hall's portal behind the camera (the one its partner ahead looks out of) made 1.5
    times larger: what the portal ahead shows is carried by another transform."""
    behind = next(e for e, (_, t) in world.query(Portal, Transform) if t.position.z > 4.0)
    world.get(behind, Transform).scale = glm.vec3(1.5)


def _budget(world):
    world.resources[ViewBudget] = ViewBudget(views=3)


def _probe_recaptures(world):
    """A box moved where the probe sees it (and not the main view's tree alone): the probe
    recaptures after present, so the frame after shows the new capture in the sphere."""
    t = world.get(world.resources["box"], Transform)
    t.position = glm.vec3(-0.5, 0.3, 0.5)


CHANGES = {"camera_step": _move_camera, "object_moves": _move_box, "material_colour": _recolour_box,
           "light": _dim_sun, "shadow_caster": _move_caster, "sky": _new_sky, "reflect_rate": _mirror_rate,
           "fade": _mirror_fade, "visibility": _hide_box_in_mirrors, "layers": _box_layers, "budget": _budget,
           "portal_scale": _portal_scale,
           "probe_recaptures": _probe_recaptures}


@pytest.mark.parametrize("visibility", ["exact", "predicted"])
@pytest.mark.parametrize("watch_world", [True, False], ids=["rule", "scene_version_alone"])
@pytest.mark.parametrize("kind", list(CHANGES))
def test_each_kind_of_change_draws_the_tree_again_with_the_pixels_of_a_drawn_frame(scene, kind, watch_world,
                                                                                    visibility):
    pair = _Pair(scene, _hall, visibility=visibility)
    pair.keeping.engine.reflection_system.watch_world = watch_world
    pair.first()
    assert pair.frame()  # still: kept
    pair.both(CHANGES[kind])
    assert not pair.frame()  # the change: drawn again
    kept = [pair.frame() for _ in range(3)]  # (the probe's recapture after present: the next one drawn too)
    assert kept[-1], "a still frame after the change keeps its tree again"
    if kind == "probe_recaptures":
        assert not kept[0], "the frame after a probe's recapture draws its tree again"


def _water(speed: float):
    def build(world) -> None:
        look_from(world, (0.0, 2.0, 3.0), (0.0, 0.0, -1.0))
        world.spawn(Skybox())
        world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.2), intensity=2.0))
        waves = np.zeros((32, 32, 4), np.uint8)
        u = (np.arange(32) + 0.5) / 32
        waves[..., 0] = np.round((0.5 - 0.15 * np.cos(4 * math.pi * u)) * 255)[None, :]
        waves[..., 1], waves[..., 2], waves[..., 3] = 128, 240, 255
        world.spawn(Transform(rotation=glm.angleAxis(-math.pi / 2, glm.vec3(1, 0, 0))), MeshRef(quad(8, 8)),
                    Material(color=(0.0, 0.1, 0.1, 1.0), normal_map=TextureData(waves, name="waves")),
                    Mirror(), Water(speed=speed, direction=(1.0, 0.0), tiling=2.0))
        world.spawn(Transform(position=(0.0, 0.5, -1.5)), MeshRef(box()), Material(color=(0.9, 0.6, 0.1)))
    return build


@pytest.mark.parametrize("watch_world", [True, False], ids=["rule", "key_alone"])
def test_animated_water_draws_its_tree_every_frame_and_still_water_keeps_it(scene, watch_world):
    """The waves move on every frame (the composite's rows read their offset): no frame
    keeps.  Still water (speed 0) keeps from the second frame."""
    moving = _Pair(scene, _water(0.5))
    moving.keeping.engine.reflection_system.watch_world = watch_world
    assert not any(moving.frame() for _ in range(4))
    still = _Pair(scene, _water(0.0))
    still.keeping.engine.reflection_system.watch_world = watch_world
    assert [still.frame() for _ in range(3)] == [False, True, True]


def test_with_end_images_a_still_tree_is_kept_once_its_image_settles(scene):
    """End views repeat last frame's image, so a still facing pair's picture changes a
    little every frame until it settles: no frame keeps its tree whole before then (each
    would differ from the drawn one; they fill their end views again over the rest kept),
    and the frames after keep, bit for bit the same."""
    pair = _Pair(scene, lambda world: _hall(world, end_image=True), size=(48, 32))
    kept = [pair.frame() for _ in range(90)]
    assert pair.drawing.stats.reflection_end_views > 0
    assert not kept[0] and kept[-1]
    first = kept.index(True)
    assert all(kept[first:]), "once kept, a still tree stays kept"


def test_a_level_resized_is_not_kept(scene):
    """A surface's resolution scale remakes level 1's targets: nothing is kept from the old ones."""
    pair = _Pair(scene, _hall)
    pair.frame()
    assert pair.frame()
    renderer = pair.keeping.engine.renderer
    renderer.levels.get(1, (SIZE[0] // 2, SIZE[1] // 2))  # another size: remade (what a level drawn smaller does)
    assert pair.keeping.engine.reflection_system.tree.still.keep(renderer.levels) is None


def test_a_shader_hot_reload_draws_the_tree_again(scene):
    """A program rebuilt from its files (the window shell's hot reload) may draw otherwise:
    the frame after draws its tree again, then still frames keep it."""
    pair = _Pair(scene, _hall)
    pair.frame()
    assert pair.frame()
    shaders = pair.keeping.engine.renderer.shaders
    before = shaders.reloads
    shaders.reload({"scene.frag"})
    assert shaders.reloads > before
    assert not pair.frame()
    assert pair.frame()


def test_a_predicted_tree_is_kept_from_the_first_frame_drawn_on_counts(scene):
    """Predicted visibility: the first frame has no counts (every candidate drawn and grown,
    not the tree the next frame draws), so the second draws again, from its counts; the third
    keeps, with the pixels and the report of a drawn frame."""
    pair = _Pair(scene, _hall)
    for runner in (pair.keeping, pair.drawing):
        runner.engine.reflection_system.visibility = "predicted"
    assert [pair.frame() for _ in range(4)] == [False, False, True, True]
    assert pair.keeping.stats.reflection_visibility == "predicted"


def _covered(world) -> None:
    """tests/test_predicted_visibility.py's mirror behind a cover (its view: no pixels)."""
    ents: dict = {}
    _covered_mirrors(world, ents, False)
    world.resources["cover"] = ents["cover"]


def test_a_predicted_tree_with_a_view_drawn_unseen_is_kept_once_its_counts_hold(scene):
    """Predicted visibility, a mirror behind a cover: its view is drawn unseen every frame
    (hidden last frame: on its claim's condition).  The second frame's tree is the one the
    third would draw once its counts are read the same (``StillTree.keep``): the third keeps,
    with a drawn frame's pixels and report; the cover moved aside, the tree draws again."""
    pair = _Pair(scene, _covered, size=(80, 60), visibility="predicted")
    assert [pair.frame() for _ in range(4)] == [False, False, True, True]
    assert pair.keeping.stats.reflection_views == pair.keeping.stats.reflection_views_unseen == 1

    def uncover(world) -> None:
        world.get(world.resources["cover"], Transform).position = (0.0, 1.5, 30.0)
    pair.both(uncover)
    assert not pair.frame()


@pytest.mark.parametrize("seed", [3, 7])
def test_changes_at_random_among_still_frames_always_show_a_drawn_frames_pixels(scene, seed):
    """The kinds of change at random, between runs of still frames (end images on, so some
    runs end before the image settles): every frame equals the frame drawn whole, and the
    still runs keep."""
    rng = random.Random(seed)
    pair = _Pair(scene, lambda world: _hall(world, end_image=True), size=(48, 32))
    kept = []
    for _ in range(40):
        if rng.random() < 0.3:
            pair.both(CHANGES[rng.choice(list(CHANGES))])
        kept.append(pair.frame())
    assert any(kept) and not all(kept)


@pytest.mark.parametrize("name", ["keep_still_views", "watch_world"])
def test_the_switches_refuse_what_is_not_a_bool_when_set(scene, name):
    """``keep_still_views`` and ``watch_world`` take True or False; anything else (a string
    such as "no", truthy) is refused when given, naming the switch, and the switch keeps its value."""
    pair = _Pair(scene, _hall)
    system = pair.keeping.engine.reflection_system
    with pytest.raises(TypeError, match=rf"ReflectionSystem\.{name} must be True or False, got 'no'"):
        setattr(system, name, "no")
    assert getattr(system, name) is True
    setattr(system, name, False)
    assert getattr(system, name) is False


@pytest.mark.parametrize("visibility", ["exact", "predicted"])
def test_a_still_scaled_portal_pair_keeps_its_tree_and_a_new_scale_draws_it_again(scene, visibility):
    """A facing pair, one portal scaled 2 (tests/test_predicted_visibility.py's): once still,
    the tree is kept, with a drawn frame's pixels, and the kept frame shows the box where
    the pair's scaled carry puts it (rays cast in float64).  Scaled 1.5 instead, the next
    frame draws again, then keeps again, the box where the new carry puts it."""
    ents: dict = {}

    def build(world):
        found: dict = {}
        _scaled_facing_pair(world, found)
        ents.setdefault("worlds", []).append((world, found))
    pair = _Pair(scene, build, size=SCALED_SIZE, visibility=visibility)
    found = dict(ents["worlds"])[pair.keeping.world]
    pair.first()
    assert pair.frame() and pair.frame()
    assert pair.keeping.stats.reflection_views == 4
    _assert_the_box_where_the_scaled_carry_says(pair.keeping, found)

    def rescale(world):
        world.get(dict(ents["worlds"])[world]["b"], Transform).scale = glm.vec3(1.5)
    pair.both(rescale)
    assert not pair.frame()
    kept = [pair.frame() for _ in range(2)]
    assert kept[-1]
    _assert_the_box_where_the_scaled_carry_says(pair.keeping, found, scale=1.5)


def test_a_still_scaled_portal_pair_with_end_images_is_kept_once_its_image_settles(scene):
    """The facing pair with one portal scaled 2 (tests/test_predicted_visibility.py's), two
    levels deep and ending in images (each period of its tunnel half the last's): its
    picture changes while the end images fill in, and no frame keeps its tree whole before
    it settles; then the frames keep, bit for bit as the engine that draws every frame, and
    level 1 shows the box where the scaled carry says."""
    ents: dict = {}

    def build(world):
        found: dict = {}
        _scaled_facing_pair(world, found)
        for portal in found["a"], found["b"]:
            world.get(portal, Portal).max_depth = 2
            world.get(portal, Portal).end_image = True
        ents.setdefault("worlds", []).append((world, found))
    pair = _Pair(scene, build, size=SCALED_SIZE)
    found = dict(ents["worlds"])[pair.keeping.world]
    kept = [pair.frame() for _ in range(10)]
    assert pair.drawing.stats.reflection_end_views > 0
    assert not kept[0] and not kept[1] and kept[-1]
    first = kept.index(True)
    assert all(kept[first:]), "once kept, a still tree stays kept"
    _assert_the_box_where_the_scaled_carry_says(pair.keeping, found)
