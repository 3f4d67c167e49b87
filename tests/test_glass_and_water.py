"""See-through things around a see-through mirror (a pond: water, or a Mirror whose material
is see-through) blend in the order of their depth, with the pond's reflection composited
where it belongs: a pane standing on the pond blends over the pond's composited reflection,
a pane under the pond is seen through the water and under its reflection, wherever their
centres are (a pond's centre says little about what is in front of it: the transparent
slot orders a batch against a see-through surface by the surface's plane,
``slot_order.back_to_front``).  Directly, in a mirror (level 1), in a probe face's own
view tree, per mirror and batched, exact and predicted, kept frames; glass seen through a
portal; a pane in front of a far see-through mirror beside a near pond.

Checked as ``tests/test_glass_over_reflection.py`` checks glass over a mirror: what the
engine shows at a pixel is an "over" blend of the pane on whatever lies behind it, then of
whatever lies in front of it (the pond's material and its reflection, at their weights),
each affine in what is under it, so with the panes at alpha ``a`` every pixel of the
composited HDR image (level 0, linear, before present) must be
``a x (the panes opaque) + (1 - a) x (no panes)``, the same scene drawn twice more (no
pane is seen through another, which would blend a x a: the scenes keep them apart; "opaque"
is an alpha a ten-thousandth short of 1, ``SOLID``).  A pane
blended in the wrong place (water drawn over a pane standing on it, a pane under the water
blended over its reflection, a pane taking a far mirror's pixels before its claim) misses
by tenths."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import Emissive, Material, MeshRef, Mirror, ReflectionProbe, Skybox, Transform, Water
from engine.assets.mesh import quad
from engine.assets.portals import spawn_portal_pair
from engine.core.cube_faces import FACE_NAMES
from engine.resources import ViewBudget
from tests.support import kept_frames_equal_drawn, look_from

SIZE = (240, 135)
ALPHA = 0.5
# The panes "opaque": as near as makes no difference, yet see-through glass in the same slot
# as at ALPHA (an opaque pane would write its depth, and water bends what lies below it by
# the depth drawn there: a pane at alpha 1 would be seen bent elsewhere than one at ALPHA).
SOLID = 1.0 - 1e-4
FLAT = glm.angleAxis(-math.pi / 2, glm.vec3(1, 0, 0))  # a quad turned to lie flat, facing up
Y = glm.vec3(0.0, 1.0, 0.0)
RTOL, ATOL = 4e-3, 2e-3  # float16 images (RGBA16F), three of them and a blend
PROBE_AT = (0.0, 1.2, 3.0)


def _pond(ents: dict, alpha: float | None, water: bool = True, probe: int | None = None):
    """A pond at y = 0 (8 x 6 m, centre (0, 0, -1)): water (Fresnel-weighted) or a plain
    see-through mirror at reflect rate 0.7, its material at alpha 0.6; an orange floor a metre
    under it, a green wall beyond it (what it reflects), mirror A on the left wall (the pond
    and the panes seen in it: level 1).  Unless ``alpha`` is None, two panes of emissive red
    glass: one standing on the pond's far side (its centre farther than the pond's: by the
    centres it would blend under the water) and one lying under the water near the camera
    (its centre nearer: by the centres it would blend over the reflection)."""
    def build(world) -> None:
        world.spawn(Skybox())
        ents["camera"] = look_from(world, (0.0, 2.0, 5.0), target=(-0.6, 0.2, -2.0))
        world.spawn(Transform(position=(0.0, -1.0, -1.0), rotation=FLAT), MeshRef(quad(14.0, 14.0)),
                    Material(color=(0.8, 0.5, 0.2)), Emissive(0.4))
        ents["wall"] = world.spawn(Transform(position=(0.0, 1.0, -6.0)), MeshRef(quad(20.0, 6.0)),
                                   Material(color=(0.1, 0.8, 0.1)), Emissive(1.0))
        parts = [Transform(position=(0.0, 0.0, -1.0), rotation=FLAT), MeshRef(quad(8.0, 6.0)),
                 Material(color=(0.2, 0.3, 0.6, 0.6)), Mirror(reflect_rate=1.0 if water else 0.7)]
        ents["pond"] = world.spawn(*parts, *([Water()] if water else []))
        ents["a"] = world.spawn(Transform(position=(-4.0, 1.0, -1.0), rotation=glm.angleAxis(glm.half_pi(), Y)),
                                MeshRef(quad(5.0, 2.2)), Material(color=(0.3, 0.3, 0.3)), Mirror())
        if alpha is not None:
            ents["standing"] = world.spawn(Transform(position=(-0.4, 0.6, -3.0)), MeshRef(quad(2.0, 1.0)),
                                           Material(color=(0.9, 0.15, 0.1, alpha)), Emissive(0.6))
            ents["under"] = world.spawn(Transform(position=(-1.5, -0.4, 0.8), rotation=FLAT),
                                        MeshRef(quad(1.6, 1.6)), Material(color=(0.9, 0.1, 0.5, alpha)), Emissive(0.6))
        if probe is not None:  # its -Z face sees the pond, the panes and A (with a depth: a face that roots a tree)
            ents["probe"] = world.spawn(Transform(position=PROBE_AT), ReflectionProbe(resolution=128, depth=probe))
    return build


def _render(scene, build, ents: dict, path: str = "per_mirror", visibility: str = "exact", frames: int = 3,
            probe_path: str | None = None):
    """The last of ``frames`` frames: level 0's linear colour (h, w, 3; row 0 at the top),
    its seen and surface ids, level 1's surface ids, the runner."""
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    if probe_path is not None:
        if probe_path == "layered" and runner.engine.renderer.probes.paths.layered_target() is None:
            pytest.skip(f"no layered capture target is trusted on {runner.engine.renderer.ctx.info['GL_RENDERER']}")
        runner.engine.stages["probes"].path = probe_path
    runner.engine.reflection_system.path = path
    runner.engine.reflection_system.visibility = visibility
    for _ in range(frames):
        rgb = runner.frame()
    levels = runner.engine.renderer.levels
    w, h = SIZE
    colour = np.frombuffer(levels[0].color.read(), np.float16).reshape(h, w, 4)[::-1, :, :3].astype(np.float64)
    return {"colour": colour, "rgb": rgb, "seen": runner.ids(), "surface": levels[0].read_surface_ids(),
            "level1": levels[1].read_surface_ids() if len(levels) > 1 else None, "runner": runner, "ents": ents}


def _blend_agrees(got: np.ndarray, opaque: np.ndarray, without: np.ndarray) -> None:
    want = ALPHA * opaque + (1.0 - ALPHA) * without
    bad = ~np.isclose(got, want, rtol=RTOL, atol=ATOL).all(axis=-1)
    assert not bad.any(), (f"{int(bad.sum())} pixels are not the panes blended in depth order; worst "
                           f"{np.abs(got - want).max():.4f}, e.g. got {got[bad][0]} want {want[bad][0]}")


def _three(scene, make, solid: float = SOLID, **kwargs) -> tuple[dict, dict, dict]:
    """The scene ``make(ents, alpha)`` builds drawn with its panes at ALPHA, without them and
    with them opaque (at alpha ``solid``)."""
    out = []
    for alpha in (ALPHA, None, solid):
        ents: dict = {}
        out.append(_render(scene, make(ents, alpha), ents, **kwargs))
    return out[0], out[1], out[2]


@pytest.mark.parametrize("path,visibility,water", [
    ("per_mirror", "exact", True), ("batched", "exact", True), ("per_mirror", "predicted", True),
    ("batched", "predicted", False), ("per_mirror", "exact", False)])
def test_panes_on_and_under_a_pond_blend_in_depth_order(scene, path, visibility, water):
    glass, without, opaque = _three(scene, lambda ents, alpha: _pond(ents, alpha, water),
                                    path=path, visibility=visibility)
    ents = glass["ents"]
    stats = glass["runner"].stats
    assert stats.reflection_path == path and stats.reflection_visibility == visibility
    assert len(glass["runner"].engine.renderer.transparent_batches()) == 3
    pond, a = ents["pond"], ents["a"]
    # Where each pane is seen, the pond is behind the standing one (its lower edge) and in
    # front of the one under it, directly and in mirror A.
    standing = glass["seen"] == ents["standing"]
    on_pond = standing & (without["surface"] == pond)       # the standing pane, the pond behind it
    in_a = standing & (glass["surface"] == a)                # seen in A
    under = (without["surface"] == pond) & (np.abs(opaque["colour"] - without["colour"]).max(axis=-1) > 0.05) \
        & (glass["surface"] == pond)                          # the pane under the water, through it
    assert on_pond.sum() > 60 and in_a.sum() > 20 and under.sum() > 300, (on_pond.sum(), in_a.sum(), under.sum())
    assert (without["level1"][in_a] == pond).sum() > 5  # the pond behind the pane in A, too
    # Every pixel: the panes blended in depth order around the pond and its reflection.
    _blend_agrees(glass["colour"], opaque["colour"], without["colour"])
    # The ids where the pane under the water is: the pond's surface, and what its reflection
    # shows (the water is in front of the pane: what is seen there is reflected), never the pane.
    assert (glass["surface"][under] == pond).all() and not (glass["seen"][under] == ents["under"]).any()
    assert glass["rgb"].max() > 100  # a picture, not a black frame
    assert stats.glass_between_surfaces == 0


def test_panes_around_a_pond_the_budget_cuts(scene):
    """With no views in the frame's budget, the pond and mirror A show their fallbacks (the
    sky's reflection) instead of views: drawn over their pixels before the tree's glass, so
    the panes still blend in depth order around them."""
    def make(ents: dict, alpha: float | None):
        pond = _pond(ents, alpha)

        def build(world) -> None:
            pond(world)
            world.resources[ViewBudget] = ViewBudget(views=0)
        return build

    glass, without, opaque = _three(scene, make)
    assert glass["runner"].stats.reflection_fallbacks == 2 and glass["runner"].stats.views_cut == 2
    assert (glass["seen"] == glass["ents"]["standing"]).sum() > 60
    _blend_agrees(glass["colour"], opaque["colour"], without["colour"])


@pytest.mark.parametrize("depth,probe_path", [(2, "six_pass"), (0, "six_pass"), (0, "layered")])
def test_panes_around_a_pond_in_a_probe_face(scene, depth, probe_path):
    """A probe whose faces see the pond and mirror A: at depth 2 each face roots a view
    tree (the pond's reflection composited in it); at depth 0 a face is finished as a root
    with no tree (the see-through pond shows its fallback, as a view the budget cut does),
    so even a capture asked of the layered path (all six faces in one pass, which finishes
    none) takes the six-pass path.  Its -Z face, read back in linear float, is the panes
    blended in depth order either way."""
    face = FACE_NAMES.index("-Z")
    faces = {}
    for alpha in (ALPHA, None, SOLID):
        ents: dict = {}
        rendered = _render(scene, _pond(ents, alpha, probe=depth), ents, probe_path=probe_path)
        assert rendered["runner"].stats.probe_path == "six_pass"
        faces[alpha] = rendered["runner"].engine.renderer.probes.read_face(ents["probe"], face).astype(np.float64)
    covered = np.abs(faces[SOLID] - faces[None]).max(axis=-1) > 0.05  # where a pane is in the face
    assert covered.sum() > 300, covered.sum()
    _blend_agrees(faces[ALPHA], faces[SOLID], faces[None])


def test_a_kept_pond_frame_is_the_frame_drawn_whole(scene):
    """A still frame keeps levels 1 and below (``StillTree.keep``) and draws the root's slot
    again: the panes around the pond come out bit for bit as in frames drawn whole (a
    see-through mirror: water's waves move on every frame, so nothing it shows is kept)."""
    keeping, drawing = scene(_pond({}, ALPHA, water=False), SIZE), scene(_pond({}, ALPHA, water=False), SIZE)
    assert kept_frames_equal_drawn(keeping, drawing) >= 2


def test_glass_seen_through_a_portal_and_in_front_of_it(scene):
    """A portal pair: a pane in front of the entry portal (over the portal's composite) and
    one beyond the exit, seen through the portal (in the portal's level, under what lies in
    front of it there), with a see-through pond beyond the exit too; every pixel the blend
    rule, and the far pane is seen through the portal."""
    def room(ents: dict, alpha: float | None):
        def build(world) -> None:
            world.spawn(Skybox())
            look_from(world, (0.0, 1.5, 4.0), target=(0.0, 1.2, -3.0))
            ents["entry"], ents["exit"] = spawn_portal_pair(world, (0.0, 1.5, -3.0), None, (20.0, 1.5, 0.0),
                                                            glm.angleAxis(glm.half_pi(), Y), size=(3.0, 3.0))
            world.spawn(Transform(position=(28.0, 1.5, 0.0), rotation=glm.angleAxis(-glm.half_pi(), Y)),
                        MeshRef(quad(20.0, 8.0)), Material(color=(0.1, 0.8, 0.1)), Emissive(1.0))
            world.spawn(Transform(position=(24.0, 0.0, 0.0), rotation=FLAT), MeshRef(quad(6.0, 6.0)),
                        Material(color=(0.2, 0.3, 0.6, 0.6)), Mirror(reflect_rate=0.7))
            if alpha is not None:
                ents["near"] = world.spawn(Transform(position=(-0.9, 1.0, -2.0)), MeshRef(quad(1.0, 1.0)),
                                           Material(color=(0.9, 0.15, 0.1, alpha)), Emissive(0.6))
                ents["far"] = world.spawn(Transform(position=(23.0, 1.2, 0.4), rotation=glm.angleAxis(
                    -glm.half_pi(), Y)), MeshRef(quad(1.2, 1.2)), Material(color=(0.9, 0.1, 0.5, alpha)), Emissive(0.6))
        return build

    glass, without, opaque = _three(scene, room)
    ents = glass["ents"]
    far = (glass["seen"] == ents["far"]) & (glass["surface"] == ents["entry"])
    near = (glass["seen"] == ents["near"]) & (without["surface"] == ents["entry"])
    assert far.sum() > 100 and near.sum() > 100, (far.sum(), near.sum())
    _blend_agrees(glass["colour"], opaque["colour"], without["colour"])


def test_a_pane_in_front_of_a_far_see_through_mirror_beside_a_near_pond(scene):
    """Two see-through surfaces: a pond near the camera and a see-through mirror on the far
    wall, and a pane below the pond's plane, in front of the far mirror, off the pond on
    the screen.  By their centres the pane is between the two, so it was blended before
    the claims with the pond, over the far mirror's own colour, and its ids took the far
    mirror's pixels from its claim (no reflection behind it); it covers no pixel of the
    pond, so it is not ordered against it and blends over the far mirror's reflection."""
    def room(ents: dict, alpha: float | None):
        def build(world) -> None:
            world.spawn(Skybox())
            look_from(world, (0.0, 2.0, 5.0), target=(0.0, 0.5, -4.0))
            ents["floor"] = world.spawn(Transform(position=(0.0, -1.5, -2.0), rotation=FLAT), MeshRef(quad(14.0, 16.0)),
                                        Material(color=(0.8, 0.5, 0.2)), Emissive(0.4))
            world.spawn(Transform(position=(0.0, 2.0, 9.0), rotation=glm.angleAxis(glm.pi(), Y)),
                        MeshRef(quad(30.0, 12.0)), Material(color=(0.1, 0.8, 0.1)), Emissive(1.0))
            ents["pond"] = world.spawn(Transform(position=(-1.5, 0.0, 1.0), rotation=FLAT), MeshRef(quad(2.0, 2.0)),
                                       Material(color=(0.2, 0.3, 0.6, 0.6)), Mirror(reflect_rate=0.7))
            ents["far"] = world.spawn(Transform(position=(1.0, 0.5, -6.0)), MeshRef(quad(6.0, 4.0)),
                                      Material(color=(0.3, 0.3, 0.3, 0.6)), Mirror(reflect_rate=0.7))
            if alpha is not None:
                ents["pane"] = world.spawn(Transform(position=(1.8, -0.6, -4.5)), MeshRef(quad(1.4, 1.4)),
                                           Material(color=(0.9, 0.15, 0.1, alpha)), Emissive(0.6))
        return build

    glass, without, opaque = _three(scene, room)
    ents = glass["ents"]
    pane = (glass["seen"] == ents["pane"]) & (without["surface"] == ents["far"])
    assert pane.sum() > 150, pane.sum()
    assert (without["seen"][pane] == ents["floor"]).all()  # behind the pane: the far mirror's reflection
    assert not ((glass["seen"] == ents["pane"]) & (without["surface"] == ents["pond"])).any()
    _blend_agrees(glass["colour"], opaque["colour"], without["colour"])


def test_a_pane_under_a_pond_and_in_front_of_a_far_see_through_mirror_is_reported(scene):
    """The limit of one claim a pixel (``slot_order.split_slot``): a pane under a near pond
    and in front of a far see-through mirror, covering both on the screen, must blend after
    the far mirror's reflection and before the pond's own colour; the claims come before
    either composite, so it is blended with the pond, before them, and where it covers the
    far mirror (not the pond) it shows over the mirror's own colour.  Reported a view:
    ``RenderStats.glass_between_surfaces``; every other pixel is still the blend rule (under
    the pond, what is behind it blends in order), and the scenes above report none."""
    def room(ents: dict, alpha: float | None):
        def build(world) -> None:
            world.spawn(Skybox())
            look_from(world, (0.0, 2.0, 5.0), target=(0.0, 0.0, -3.0))
            world.spawn(Transform(position=(0.0, -2.0, -2.0), rotation=FLAT), MeshRef(quad(14.0, 16.0)),
                        Material(color=(0.8, 0.5, 0.2)), Emissive(0.4))
            world.spawn(Transform(position=(0.0, 2.0, 9.0), rotation=glm.angleAxis(glm.pi(), Y)),
                        MeshRef(quad(30.0, 12.0)), Material(color=(0.1, 0.8, 0.1)), Emissive(1.0))
            ents["pond"] = world.spawn(Transform(position=(-1.0, 0.0, 0.0), rotation=FLAT), MeshRef(quad(4.0, 4.0)),
                                       Material(color=(0.2, 0.3, 0.6, 0.6)), Mirror(reflect_rate=0.7))
            ents["far"] = world.spawn(Transform(position=(0.0, 0.0, -6.0)), MeshRef(quad(8.0, 4.0)),
                                      Material(color=(0.3, 0.3, 0.3, 0.6)), Mirror(reflect_rate=0.7))
            if alpha is not None:  # under the pond's plane, reaching past its right edge onto the far mirror
                ents["pane"] = world.spawn(Transform(position=(0.8, -0.5, -1.0)), MeshRef(quad(2.4, 1.0)),
                                           Material(color=(0.9, 0.15, 0.1, alpha)), Emissive(0.6))
        return build

    glass, without, opaque = _three(scene, room, solid=1.0)  # (no water: opaque panes are no glass to report)
    ents = glass["ents"]
    assert glass["runner"].stats.glass_between_surfaces >= 1
    for rendered in (without, opaque):
        assert rendered["runner"].stats.glass_between_surfaces == 0
    pane = glass["seen"] == ents["pane"]
    over_far = pane & (without["surface"] == ents["far"])
    under_pond = (glass["surface"] == ents["pond"]) & (np.abs(opaque["colour"] - without["colour"]).max(axis=-1) > 0.05)
    assert over_far.sum() > 50 and under_pond.sum() > 50, (over_far.sum(), under_pond.sum())
    # The far mirror's claim lost the pane's pixels: its reflection is not behind the pane there.
    assert (glass["surface"][over_far] == ents["pane"]).all()
    # Everywhere else, the blend rule.
    _blend_agrees(glass["colour"][~over_far], opaque["colour"][~over_far], without["colour"][~over_far])
