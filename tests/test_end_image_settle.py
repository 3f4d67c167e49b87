"""A still tree whose end images have not settled keeps what its views drew and redoes only
what depends on the end images (``StillTree.keep``'s refill, ``engine/render/level_copies.py``):
the end views filled from the new image, then from the deepest level with end views up,
each level put back as its views drew it, its fallbacks, the level below composited in and
its transparent slot, the root's last.

Every test runs the same level twice on the test context, in lockstep, as
``tests/test_kept_views.py`` does: one engine keeps still views, the other
(``keep_still_views = False``) draws its whole tree every frame.  Every frame's presented
colour, HDR main image and entity-id image must be bit for bit the drawn engine's, and its
report and budget ledger too; the report says which frames refilled
(``RenderStats.reflection_end_refills``: the drawn engine's end views) with fewer passes than
the drawn frame (no reflection view's scene pass), and which kept the whole tree once the
image settled.  Each scene's end images change the picture while it settles (frames differ
from each other), so a refill that did nothing, or left a level's old composites in, shows."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import Camera, DirectionalLight, Emissive, Material, MeshRef, Mirror, Skybox, Transform, Visibility
from engine.assets.mesh import box, plane, quad
from engine.assets.portals import spawn_portal_pair
from engine.assets.texture_data import checker_texture
from engine.render.targets import CaptureTarget
from shell.overlay_text import overlay_lines
from tests.support import look_from

SIZE = (64, 40)
BACK = glm.angleAxis(math.pi, glm.vec3(0, 1, 0))
REPORT = ("reflection_views", "views_spent", "pixels_spent", "views_cut", "levels_downscaled", "reflection_fallbacks",
          "reflection_end_views", "reflection_views_faded", "reflection_depth_capped", "reflection_visibility",
          "reflection_views_unseen", "reflection_path")


def _portals(world) -> None:
    """The benchmark's facing portal pair (benchmarks/portals.py): the camera between them
    looking into one, every level the other again, down to depth 8 and its end view."""
    world.resources["camera"] = look_from(world, (0.3, 1.5, 3.0), (0.2, 1.4, 0.0))
    world.spawn(Skybox())
    world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.4), intensity=2.5))
    world.spawn(Transform(), MeshRef(plane(40, 40, uv_repeat=10)), Material(texture=checker_texture(64, 8)))
    spawn_portal_pair(world, (0, 1.25, 0), None, (0, 1.25, 6), BACK, size=(2.0, 2.5), max_depth=8)
    for i, (x, z) in enumerate(((-0.6, 1.0), (0.7, 2.0), (-0.3, 4.5), (0.5, 5.2))):
        entity = world.spawn(Transform(position=(x, 0.25, z)), MeshRef(box((0.5, 0.5, 0.5))),
                             Material(color=(0.2 + 0.2 * i, 0.5, 0.9 - 0.2 * i)))
        world.resources.setdefault("box", entity)


def _mirrors(rate: float = 1.0, fade=None, rough: bool = False, glass: bool = False):
    """A facing pair of tinted mirrors 6 m apart (depth 5, then end views), boxes between
    them; ``rate`` and ``fade`` (fade_distance) for both; ``rough``: a rough mirror on the
    left wall that sees the pair (its rough composites blur what the end views change);
    ``glass``: a pane of red glass between them (seen at every level, over the reflections
    behind it) and one just in front of the camera (over the root's composite)."""
    def build(world) -> None:
        world.resources["camera"] = look_from(world, (0.4, 1.6, 1.5), (-0.2, 1.4, -3.0))
        world.spawn(Skybox())
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=1.5))
        world.spawn(Transform(), MeshRef(plane(20, 20, uv_repeat=8)), Material(texture=checker_texture(64, 8)))
        world.resources["box"] = world.spawn(Transform(position=(0.8, 1.0, 0.0), scale=(0.4, 2.0, 0.4)),
                                             MeshRef(box()), Material(color=(0.9, 0.2, 0.1)), Emissive(0.6))
        world.spawn(Transform(position=(-0.9, 0.6, 0.5), scale=(0.5, 1.2, 0.5)), MeshRef(box()),
                    Material(color=(0.1, 0.3, 0.9)), Emissive(0.6))
        for z, turn in ((-3.0, 0.0), (3.0, math.pi)):
            world.spawn(Transform(position=(0.0, 1.5, z), rotation=glm.angleAxis(turn, glm.vec3(0, 1, 0))),
                        MeshRef(quad(4.0, 3.0)), Material(color=(0.15, 0.6, 0.15)),
                        Mirror(max_depth=5, color=(0.9, 0.95, 0.8), reflect_rate=rate, fade_distance=fade,
                               end_image=True))
        if rough:
            world.spawn(Transform(position=(-1.8, 1.4, -0.5), rotation=glm.angleAxis(math.pi / 2, glm.vec3(0, 1, 0))),
                        MeshRef(quad(3.0, 2.0)), Material(color=(0.2, 0.2, 0.2)),
                        Mirror(max_depth=6, roughness=0.3, color=(0.8, 0.8, 1.0), reflect_rate=0.8))
        if glass:
            world.resources["glass"] = world.spawn(Transform(position=(-1.0, 0.5, -1.0)), MeshRef(quad(1.6, 1.0)),
                                                   Material(color=(0.9, 0.15, 0.1, 0.5)), Emissive(0.4))
            world.spawn(Transform(position=(0.5, 1.2, 0.9)), MeshRef(quad(0.2, 0.2)),
                        Material(color=(0.2, 0.9, 0.9, 0.4)))
    return build


SCENES = {"portals": _portals, "mirrors": _mirrors(), "faded_tinted_rough": _mirrors(0.95, (20.0, 200.0), rough=True),
          "glass": _mirrors(glass=True)}


class _Pair:
    """The same level in two engines, one keeping still views, one drawing every frame."""

    def __init__(self, scene, build, size=SIZE) -> None:
        self.keeping = scene(build, size)
        self.drawing = scene(build, size)
        self.drawing.engine.reflection_system.keep_still_views = False
        self.images: list[np.ndarray] = []  # the keeping engine's HDR image, frame by frame

    def both(self, change) -> None:
        for runner in (self.keeping, self.drawing):
            change(runner)

    def frame(self) -> str:
        """A frame of each; asserts pixels, report and ledger equal; returns how the keeping
        engine did it: "drawn", "refilled" or "kept"."""
        images = []
        for runner in (self.keeping, self.drawing):
            rgb = runner.frame()
            images.append((rgb, np.frombuffer(runner.engine.renderer.targets.color.read(), np.float16), runner.ids()))
            assert runner.ctx.error == "GL_NO_ERROR"
        for name, kept, drawn in zip(("colour", "HDR image", "ids"), images[0], images[1], strict=True):
            assert np.array_equal(kept, drawn), f"the {name} differs from the frame drawn whole"
        self.images.append(images[0][1])
        stats, drawn = self.keeping.stats, self.drawing.stats
        for name in REPORT:
            assert getattr(stats, name) == getattr(drawn, name), name
        assert drawn.reflection_end_refills == 0 and drawn.reflection_views_kept == 0
        if stats.reflection_end_refills:
            assert stats.reflection_views_kept == 0
            assert stats.reflection_end_refills == drawn.reflection_end_views > 0
            assert stats.passes < drawn.passes  # no reflection view's scene pass
            return "refilled"
        if stats.reflection_views_kept:
            assert stats.reflection_views_kept == drawn.reflection_views > 0 and stats.passes == 1
            return "kept"
        assert stats.passes == drawn.passes
        return "drawn"


@pytest.mark.parametrize("name", list(SCENES))
def test_a_still_tree_refills_its_end_images_until_they_settle_with_a_drawn_frames_pixels(scene, name):
    """The first frame draws (no image to end in), the second draws and copies its levels
    (a still frame: it compares its image), and from the third every frame until the image
    settles refills; once kept whole it stays kept."""
    pair = _Pair(scene, SCENES[name])
    tree = pair.keeping.engine.reflection_system.tree.still
    kinds = [pair.frame() for _ in range(5)]
    # A level down to the deepest with end views is copied where its composites or
    # fallbacks blend over its own pixels (a reflect rate or fade below 1) or glass is drawn
    # over them; none where every pixel they write is painted whole (portals, rate 1).
    deepest = max(view.level for view in tree.kept.result.end_views)
    if name in ("faded_tinted_rough", "glass"):
        assert 0 < len(tree.copies) <= deepest
    else:
        assert len(tree.copies) == 0
    kinds += [pair.frame() for _ in range(67)]
    assert kinds[:2] == ["drawn", "drawn"]
    settled = kinds.index("kept") if "kept" in kinds else len(kinds)
    assert settled > 8 and kinds[2:settled] == ["refilled"] * (settled - 2)
    assert all(kind == "kept" for kind in kinds[settled:])
    # The refills changed the picture (the end images converge), and it is not black.
    assert not np.array_equal(pair.images[2], pair.images[3]) and not np.array_equal(pair.images[3], pair.images[8])
    assert pair.keeping.capture.read_rgb().mean() > 20
    if settled < len(kinds):
        assert len(tree.copies) == 0  # let go once settled
    if name == "glass":
        assert (pair.keeping.ids() == pair.keeping.world.resources["glass"]).sum() > 20
    if name == "faded_tinted_rough":
        assert pair.keeping.stats.reflection_views_faded + pair.keeping.stats.reflection_fallbacks > 0


def test_the_refill_is_reported_on_the_overlay(scene):
    pair = _Pair(scene, _portals)
    while pair.frame() != "refilled":
        pass
    lines = overlay_lines(pair.keeping.engine, [0.02])
    refills = pair.keeping.stats.reflection_end_refills
    assert refills > 0 and f"views kept 0, end views refilled {refills} (keep still views: on)" in lines


def _move_camera(runner):
    t = runner.world.get(runner.world.resources["camera"], Transform)
    t.position = t.position + glm.vec3(0.02, 0.0, 0.0)


def _move_box(runner):
    t = runner.world.get(runner.world.resources["box"], Transform)
    t.position = t.position + glm.vec3(0.0, 0.0, 0.1)


def _resize(runner):
    runner.capture.release()
    runner.size = (SIZE[0] + 8, SIZE[1] + 6)
    runner.capture = CaptureTarget(runner.ctx, runner.size)


def _depth(runner):
    runner.engine.reflection_system.max_depth_cap = 6


CHANGES = {"camera_moves": _move_camera, "object_moves": _move_box, "resize": _resize, "depth_cap": _depth}


@pytest.mark.parametrize("name", ["portals", "glass"])
@pytest.mark.parametrize("change", list(CHANGES))
def test_a_change_while_refilling_draws_the_tree_whole(scene, name, change):
    """A change among the refilled frames: that frame draws its whole tree (and lets its
    copies go: nothing is copied on a frame that moved), the next still frame draws and
    copies again, and the ones after refill again, every frame with a drawn frame's pixels."""
    pair = _Pair(scene, SCENES[name])
    assert [pair.frame() for _ in range(5)] == ["drawn", "drawn", "refilled", "refilled", "refilled"]
    pair.both(CHANGES[change])
    assert pair.frame() == "drawn"
    tree = pair.keeping.engine.reflection_system.tree.still
    assert len(tree.copies) == 0
    assert pair.frame() == "drawn"
    assert [pair.frame() for _ in range(3)] == ["refilled"] * 3
    assert (len(tree.copies) > 0) == (name == "glass")


def test_a_predicted_tree_refills_too(scene):
    """Predicted visibility: a tree drawn on last frame's counts (from the second frame) is
    refilled as an exact one is, its levels' transparent slots on the render's conditions,
    every frame the drawn engine's."""
    pair = _Pair(scene, SCENES["glass"])
    for runner in (pair.keeping, pair.drawing):
        runner.engine.reflection_system.visibility = "predicted"
    kinds = [pair.frame() for _ in range(12)]
    assert pair.keeping.stats.reflection_visibility == "predicted"
    # (the first frame has no counts: every candidate drawn, not the tree the next one draws)
    assert kinds[:2] == ["drawn"] * 2 and kinds[2:8] == ["refilled"] * 6


def test_the_level_copies_go_when_the_pair_is_removed_mid_refill(scene):
    """The facing mirrors deleted while their still tree refills (copies of its levels held):
    the next frame has no mirror to draw, and lets the copies go rather than holding a
    level's colour and id images until some later still tree is drawn (found by
    ``benchmarks/still_fuzz.py``, which checks resource counts come back after each case)."""
    pair = _Pair(scene, SCENES["glass"])
    assert [pair.frame() for _ in range(4)] == ["drawn", "drawn", "refilled", "refilled"]
    tree = pair.keeping.engine.reflection_system.tree.still
    assert len(tree.copies) > 0

    def remove_mirrors(runner):
        for entity, _ in runner.world.query_one(Mirror):
            runner.world.delete_entity(entity)

    pair.both(remove_mirrors)
    assert [pair.frame() for _ in range(2)] == ["drawn", "drawn"]
    assert pair.keeping.stats.reflection_views == 0 and len(tree.copies) == 0


def _camera(runner, active: bool) -> None:
    runner.world.get(runner.world.resources["camera"], Camera).active = active


def _mirrors_on(runner, enabled: bool) -> None:
    for _, mirror in runner.world.query_one(Mirror):
        mirror.enabled = enabled


def _mirrors_shown(runner, shown: bool) -> None:
    for entity, _ in runner.world.query_one(Mirror):
        if shown:
            runner.world.remove_component(entity, Visibility)
        else:
            runner.world.add_component(entity, Visibility(direct=False))


def _size(runner, other: bool) -> None:
    runner.capture.release()
    runner.size = (SIZE[0] + 8, SIZE[1] + 6) if other else SIZE
    runner.capture = CaptureTarget(runner.ctx, runner.size)


def _minimised(runner, shown: bool) -> None:
    runner.size = SIZE if shown else (0, 0)  # (a minimised window's output: no pixels to draw)


# What takes away the frame a still tree's level copies are for, and gives it back.
TOGGLES = {"camera_inactive": _camera, "minimised": _minimised, "mirrors_disabled": _mirrors_on,
           "mirrors_hidden": _mirrors_shown, "resized": _size}


@pytest.mark.filterwarnings("ignore::engine.core.errors.NoCameraWarning")
@pytest.mark.parametrize("toggle", list(TOGGLES))
def test_level_copies_go_with_the_frame_they_are_for_and_never_pile_up(scene, toggle):
    """The frame that refills a still tree gone (its camera switched off, the window
    minimised, its mirrors switched off or hidden from the camera) or of another size (the
    window resized): the next frame holds no level copy (``Renderer.resource_counts``'
    "level_copies") rather than keeping a level's colour and id images for a frame that may
    never come (resized: until the next still frame copies the new size's levels); given
    back, it draws, copies and refills again.  With no frame to draw at all (camera off,
    minimised) the end images' history is let go too.
    Toggled again and again, the renderer's resources come back to the same counts each time,
    and every frame is the drawn engine's."""
    pair = _Pair(scene, SCENES["glass"])
    renderer = pair.keeping.engine.reflection_system.tree.renderer
    off, on = (lambda runner: TOGGLES[toggle](runner, False)), (lambda runner: TOGGLES[toggle](runner, True))
    if toggle == "resized":  # (its "off" is the other size)
        off, on = on, off
    counts = []
    for _ in range(4):
        assert [pair.frame() for _ in range(4)] == ["drawn", "drawn", "refilled", "refilled"]
        held = renderer.resource_counts()
        assert held["level_copies"] > 0
        counts.append(held)
        pair.both(off)
        pair.frame()
        assert renderer.resource_counts()["level_copies"] == 0
        if toggle in ("camera_inactive", "minimised"):  # no frame to draw: the end images' history goes too
            assert pair.keeping.engine.reflection_system.tree.ends.history is None
        pair.frame()  # (resized: the next still frame, of the new size, copies its levels again)
        assert renderer.resource_counts()["level_copies"] == (held["level_copies"] if toggle == "resized" else 0)
        pair.both(on)
    assert all(held == counts[0] for held in counts[1:]), counts
