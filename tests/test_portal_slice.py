"""Things partly through a portal: sliced at the portal, the rest drawn beyond the partner."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    DirectionalLight,
    Emissive,
    FromDecal,
    Material,
    MeshRef,
    Mirror,
    Morph,
    PortalClone,
    Reflective,
    Refractive,
    Skin,
    Skybox,
    Slice,
    Transform,
    Traveller,
    look_rotation,
)
from components.decal import Decal
from engine.assets.mesh import Mesh, box, quad
from engine.assets.portals import spawn_portal_pair
from engine.resources import PortalCrossings
from tests.support import look_from

SIZE = (200, 150)


def build_pair(world, ents, eye, target):
    world.spawn(Skybox())
    world.spawn(DirectionalLight(direction=(0.3, -1.0, -0.4), intensity=2.0))
    eye = glm.vec3(eye)
    ents["camera"] = world.spawn(Transform(position=eye, rotation=look_rotation(glm.vec3(target) - eye)), Camera())
    # A at x = -3 and B at x = +3, both facing +Z: what goes into A comes out of B.
    ents["a"], ents["b"] = spawn_portal_pair(world, (-3, 1.5, 0), None, (3, 1.5, 0), None)
    # A long bar pushed halfway into A: z from -1 to +1.
    ents["bar"] = world.spawn(Transform(position=(-2.8, 1.5, 0.0)), MeshRef(box((0.4, 0.4, 2.0))),
                              Material(color=(0.9, 0.5, 0.1)), Emissive(1.0), Traveller())


def test_a_box_halfway_through_shows_both_halves(scene):
    ents = {}
    runner = scene(lambda world: build_pair(world, ents, (0, 3.0, 7.0), (0, 1.5, 0)), SIZE)
    runner.frame()
    ids = runner.ids()
    # The half still in front of A, where it is.
    col, row = runner.project((-2.8, 1.7, 0.6))
    assert ids[row, col] == ents["bar"]
    # The half that went in comes out in front of B: B + half turn of (0.2, 0, -0.6) = (2.8, 1.5, 0.6).
    col, row = runner.project((2.8, 1.7, 0.6))
    assert ids[row, col] == ents["bar"]
    world = runner.world
    assert world.get(ents["bar"], Slice).plane == glm.vec4(0, 0, 1, 0)  # A's front is kept
    (clone, _), = world.query_one(PortalClone)
    assert world.get(clone, PortalClone).source == ents["bar"]
    assert abs(world.get(clone, Slice).plane.w - 0.0) < 1e-6 and world.get(clone, Slice).plane.z > 0.99


def test_the_part_behind_the_portal_is_not_drawn_there(scene):
    ents = {}
    # From the side, A is seen edge-on: an unsliced bar would show its back half at z < 0.
    runner = scene(lambda world: build_pair(world, ents, (-7.0, 1.6, -0.5), (-2.8, 1.5, -0.5)), SIZE)
    runner.frame()
    ids = runner.ids()
    col, row = runner.project((-2.8, 1.5, 0.6))
    assert ids[row, col] == ents["bar"]          # the front half is there
    col, row = runner.project((-2.8, 1.5, -0.6))
    assert ids[row, col] != ents["bar"]          # the back half is not


def test_slice_and_clone_go_when_the_box_is_pulled_back_out(scene):
    """Pulled back out of the portal, the bar is whole again and its clone beyond the
    partner is gone: the frame (ids and colours) and the live GPU objects are those of a
    fresh scene where the bar never touched the portal."""
    ents = {}
    runner = scene(lambda world: build_pair(world, ents, (0, 3.0, 7.0), (0, 1.5, 0)), SIZE)
    runner.frame()
    assert runner.world.query_one(PortalClone)
    runner.world.get(ents["bar"], Transform).position = (-2.8, 1.5, 3.0)  # pulled back out
    runner.frame()
    assert not runner.world.query_one(PortalClone)  # deleted (gone from queries at once)
    rgb = runner.frame()
    assert not runner.world.has(ents["bar"], Slice)

    fresh_ents = {}

    def fresh(world):
        build_pair(world, fresh_ents, (0, 3.0, 7.0), (0, 1.5, 0))
        world.get(fresh_ents["bar"], Transform).position = (-2.8, 1.5, 3.0)

    never_through = scene(fresh, SIZE)
    expected_rgb = never_through.frame()
    ids = runner.ids()
    assert fresh_ents["bar"] == ents["bar"] and (ids == ents["bar"]).sum() > 100
    np.testing.assert_array_equal(ids, never_through.ids())
    assert np.abs(rgb.astype(int) - expected_rgb).max() <= 1
    kinds = ("meshes", "textures", "batches")  # (programs built differ: slicing needed other variants)
    counts = runner.engine.renderer.resource_counts()
    assert [counts[k] for k in kinds] == [never_through.engine.renderer.resource_counts()[k] for k in kinds]


def test_a_box_pushed_into_the_back_of_a_portal_is_drawn_whole(scene):
    """A portal is one-way (travel carries what crosses its front): a bar pushed into A
    from behind, its origin behind A, is not going through, so it is not sliced and has no
    clone beyond B; seen from the side, both its halves show where they are."""
    ents = {}

    def build(world):
        build_pair(world, ents, (-7.0, 1.6, -0.5), (-2.8, 1.5, -0.5))
        world.get(ents["bar"], Transform).position = (-2.8, 1.5, -0.2)  # origin 0.2 m behind A

    runner = scene(build, SIZE)
    runner.frame()
    assert not runner.world.has(ents["bar"], Slice)
    assert runner.world.query_one(PortalClone) == []
    ids = runner.ids()
    for z in (0.6, -0.6):  # the half through A's plane (in front) and the half behind it
        col, row = runner.project((-2.8, 1.5, z))
        assert ids[row, col] == ents["bar"]
    # Moved so its origin is in front of A (by as much), the same bar is sliced again.
    runner.world.get(ents["bar"], Transform).position = (-2.8, 1.5, 0.2)
    runner.frame()
    assert runner.world.get(ents["bar"], Slice).plane == glm.vec4(0, 0, 1, 0)
    assert len(runner.world.query_one(PortalClone)) == 1


def _top_faces(runner) -> tuple[np.ndarray, np.ndarray]:
    """The frame's colour on the bar's top face in front of A and on its clone's beyond B:
    the same face of the same box (a half turn about +Y keeps it facing up), under the same
    sun and sky, so the same colour when the clone looks as its source does."""
    rgb = runner.frame()
    front, beyond = (runner.project(point) for point in ((-2.8, 1.7, 0.4), (2.8, 1.7, 0.4)))
    return rgb[front[1], front[0]].astype(int), rgb[beyond[1], beyond[0]].astype(int)


def test_the_clone_looks_as_its_source_does_and_follows_its_changes(scene):
    """The clone beyond B takes its source's Material, Emissive, Reflective and Refractive,
    and keeps them the same while it lasts: the bar glows (it was drawn unlit there) and,
    recoloured, dimmed or given a new mesh while halfway through, is drawn so on both sides."""
    ents = {}
    runner = scene(lambda world: build_pair(world, ents, (0, 3.0, 7.0), (0, 1.5, 0)), SIZE)
    runner.frame()
    front, beyond = _top_faces(runner)
    assert np.abs(front - beyond).max() <= 3, (front, beyond)
    world = runner.world
    (clone, _), = world.query_one(PortalClone)
    assert world.get(clone, Emissive).power == 1.0

    world.get(ents["bar"], Material).color = (0.1, 0.3, 0.9)
    world.get(ents["bar"], Emissive).power = 0.2
    front_after, beyond_after = _top_faces(runner)
    assert np.abs(front_after - beyond_after).max() <= 3, (front_after, beyond_after)
    assert front_after[2] > front_after[0] + 40 and np.abs(front_after - front).max() > 40  # it did change

    world.remove_component(ents["bar"], Emissive)
    runner.frame()
    assert not world.has(clone, Emissive)

    longer = box((0.4, 0.4, 3.0))
    world.get(ents["bar"], MeshRef).mesh = longer
    runner.frame()
    (clone, _), = world.query_one(PortalClone)
    assert world.get(clone, MeshRef).mesh is longer
    ids = runner.ids()
    col, row = runner.project((2.8, 1.5, 1.3))  # the longer bar's far end, 1.3 m out of B
    assert ids[row, col] == ents["bar"]


def test_the_clone_goes_when_its_source_loses_its_mesh(scene):
    ents = {}
    runner = scene(lambda world: build_pair(world, ents, (0, 3.0, 7.0), (0, 1.5, 0)), SIZE)
    runner.frame()
    assert runner.world.query_one(PortalClone)
    runner.world.remove_component(ents["bar"], MeshRef)
    runner.frame()
    assert runner.world.query_one(PortalClone) == []
    assert not runner.world.has(ents["bar"], Slice)
    assert not (runner.ids() == ents["bar"]).any()


def build_model_like(world, ents, eye, target):
    """``build_pair``'s portals and camera, and a traveller with no mesh of its own (a model's
    root) whose two parts are below it: the bar halfway into A, and a block a metre further
    on, wholly through A's plane."""
    world.spawn(Skybox())
    world.spawn(DirectionalLight(direction=(0.3, -1.0, -0.4), intensity=2.0))
    eye = glm.vec3(eye)
    ents["camera"] = world.spawn(Transform(position=eye, rotation=look_rotation(glm.vec3(target) - eye)), Camera())
    ents["a"], ents["b"] = spawn_portal_pair(world, (-3, 1.5, 0), None, (3, 1.5, 0), None)
    ents["root"] = root = world.spawn(Transform(position=(-2.8, 1.5, 0.0)), Traveller())
    ents["bar"] = world.spawn(Transform(parent=root), MeshRef(box((0.4, 0.4, 2.0))),
                              Material(color=(0.9, 0.5, 0.1)), Emissive(1.0))
    ents["block"] = world.spawn(Transform(position=(0.0, 0.0, -1.5), parent=root), MeshRef(box((0.3, 0.3, 0.3))),
                                Material(color=(0.1, 0.8, 0.2)))


def test_a_travellers_parts_are_sliced_and_cloned_with_it(scene):
    """A traveller's meshes below it (a model's parts) go through a portal with it: the box
    about them all straddles A, so each part is cut at A, a part wholly through included (it is
    not drawn behind A), and each comes out of B as a clone, carried by the pair."""
    ents = {}
    side = scene(lambda world: build_model_like(world, ents, (-7.0, 1.6, -0.5), (-2.8, 1.5, -0.5)), SIZE)
    side.frame()  # (its first: the parts are found below the traveller before the transform stage links them)
    ids = side.ids()
    col, row = side.project((-2.8, 1.5, 0.6))
    assert ids[row, col] == ents["bar"]            # in front of A: drawn
    for point in ((-2.8, 1.5, -0.6), (-2.8, 1.5, -1.5)):
        col, row = side.project(point)
        assert ids[row, col] not in (ents["bar"], ents["block"])  # behind A: the bar's far half, the block
    world = side.world
    for part in ("bar", "block"):
        assert world.get(ents[part], Slice).plane == glm.vec4(0, 0, 1, 0)
    assert not world.has(ents["root"], Slice)
    clones = {clone.source: entity for entity, clone in world.query_one(PortalClone)}
    assert set(clones) == {ents["bar"], ents["block"]}
    # A-local (0.2, 0, -1.5) comes out of B (half turned) at (2.8, 1.5, 1.5).
    np.testing.assert_allclose(world.get(clones[ents["block"]], Transform).position, (2.8, 1.5, 1.5), atol=1e-5)

    front = scene(lambda world: build_model_like(world, {}, (0, 3.0, 7.0), (0, 1.5, 0)), SIZE)
    front.frame()
    ids = front.ids()
    for point, part in (((2.8, 1.65, 1.5), "block"), ((2.8, 1.7, 0.6), "bar")):
        col, row = front.project(point)
        assert ids[row, col] == ents[part], part   # the clones report their sources

    # Taken out of the portal, every part is whole again and every clone goes.
    world.get(ents["root"], Transform).position = (-2.8, 1.5, 3.0)
    side.frame()
    assert not world.query_one(PortalClone)
    assert not world.has(ents["bar"], Slice) and not world.has(ents["block"], Slice)


def test_a_part_taken_from_under_a_traveller_is_whole_on_the_frame_it_goes(scene):
    """The block, re-parented to a still entity of its own (placed where it was, wholly
    through A's plane), is no longer the traveller's part on that very frame: not cut, no
    clone beyond B (the transform stage's index of children still held its old link), while
    the bar, still a part, stays cut."""
    ents = {}
    side = scene(lambda world: build_model_like(world, ents, (-7.0, 1.6, -0.5), (-2.8, 1.5, -0.5)), SIZE)
    side.frame()
    side.frame()
    world = side.world
    assert world.has(ents["block"], Slice)
    holder = world.spawn(Transform(position=(-2.8, 1.5, 0.0)))
    world.get(ents["block"], Transform).parent = holder
    side.frame()
    assert not world.has(ents["block"], Slice)
    assert {clone.source for _, clone in world.query_one(PortalClone)} == {ents["bar"]}
    assert world.has(ents["bar"], Slice)


def test_a_traveller_below_a_traveller_is_cut_once_a_frame(scene):
    """The bar below the model-like root made a Traveller too (a thing a traveller carries
    that travels alone once dropped): both straddle A, and each part is cut, and its clone
    posed, once a frame, not once for each traveller above it."""
    from systems.portal_slice_system import PortalSliceSystem

    ents = {}
    side = scene(lambda world: build_model_like(world, ents, (-7.0, 1.6, -0.5), (-2.8, 1.5, -0.5)), SIZE)
    side.world.add_component(ents["bar"], Traveller())
    side.frame()
    system = side.world.get_system(PortalSliceSystem)
    cuts = []
    cut = system._slice
    system._slice = lambda entity, plane: (cuts.append(entity), cut(entity, plane))[1]
    side.frame()
    clones = {clone.source: entity for entity, clone in side.world.query_one(PortalClone)}
    assert sorted(cuts) == sorted([ents["bar"], ents["block"], clones[ents["bar"]], clones[ents["block"]]])
    assert side.world.get(ents["bar"], Slice).plane == glm.vec4(0, 0, 1, 0)


def test_a_decal_on_a_traveller_is_cut_at_the_portal_with_it(scene):
    """A sticker on the bar's side (a Decal parented to the bar; its cut is an entity below it)
    goes through with the bar: cut at A (it does not float where the bar's far half is cut
    away), and drawn beyond B as a decal's cut (the clone takes its FromDecal)."""
    ents = {}

    def build(world):
        build_pair(world, ents, (-7.0, 1.6, -0.5), (-2.8, 1.5, -0.5))
        ents["decal"] = world.spawn(Transform(position=(-0.4, 0.0, 0.0), rotation=look_rotation((1, 0, 0)),
                                              scale=(1.8, 0.3, 0.5), parent=ents["bar"]),
                                    Decal(color=(0.1, 0.2, 1.0, 1.0)))

    runner = scene(build, SIZE)
    for _ in range(3):
        runner.frame()
    world = runner.world
    (cut, _), = [(e, c) for e, c in world.query_one(FromDecal) if not world.has(e, PortalClone)]
    ids = runner.ids()
    col, row = runner.project((-3.0, 1.5, 0.6))
    assert ids[row, col] == cut                    # the sticker in front of A
    col, row = runner.project((-3.0, 1.5, -0.6))
    assert ids[row, col] not in (cut, ents["bar"])  # nothing behind A: the sky
    assert world.get(cut, Slice).plane == glm.vec4(0, 0, 1, 0)
    clones = {clone.source: entity for entity, clone in world.query_one(PortalClone)}
    assert set(clones) == {ents["bar"], cut}
    assert world.get(clones[cut], FromDecal).decal == ents["decal"]


# --- the cut and the clone against the two halves built by hand -----------------------------------
FACING_MINUS_X = glm.angleAxis(glm.radians(-90.0), glm.vec3(0, 1, 0))  # local +Z to world -X
CUT_EYES = {  # (eye, target): where each look of the cut scene stands
    "before both portals": ((0.0, 3.5, 7.0), (0.0, 1.0, -0.5)),  # both halves, and each through the other portal
    "behind A": ((-8.0, 2.5, -3.5), (-2.8, 0.8, -0.5)),          # where the part gone in would stand
    "in the mirror": ((0.0, 3.0, 7.0), (-1.0, 1.5, -4.0)),       # the mirror behind both portals
}
CUT_SIZE = (128, 96)


def open_half(length: float = 1.0) -> Mesh:
    """``box((0.4, 0.4, length))`` without its -Z face (box's last two triangles): a part of
    the bar open where the portal cuts it (a slice plane clips the bar; it does not cap it)."""
    whole = box((0.4, 0.4, length))
    return Mesh(whole.positions[:20], whole.normals[:20], whole.uvs[:20], whole.indices[:10], name="open half")


CUT_LOOKS = {  # the bar's (and its halves') look: (Material colour, its other look components)
    "matte": ((0.9, 0.5, 0.1), ()),
    "chrome": ((0.9, 0.5, 0.1), (Reflective,)),
    "glass": ((0.9, 0.5, 0.1, 0.3), (Refractive,)),  # refracting: drawn over a copy of the frame
    "see-through": ((0.9, 0.5, 0.1, 0.3), ()),  # drawn in the transparent slot
}


def build_cut(world, ents, scale: float, by_hand: bool, look: str = "matte") -> None:
    """A at (-3, 1.5, 0) facing +Z, B at (3, 1.5, -1) facing -X (scaled ``scale``), over a
    matte floor, a mirror behind both, and the 2 m bar halfway into A (x -3..-2.6, y
    1.3..1.7, z -1..1); ``by_hand``: no bar, but its two halves where they should be drawn.
    By hand: the pair carries A + (x, y, z) to B-local (-x, y, -z), and B's turn takes
    B-local (x, y, z) to world (-z, y, x), times ``scale``; so the half behind A (its centre
    A + (0.2, 0, -0.5)) stands at B + scale (-0.5, 0, -0.2), turned as B, open towards B.
    ``look``: a ``CUT_LOOKS`` key."""
    color, kinds = CUT_LOOKS[look]
    world.spawn(Skybox())
    world.spawn(DirectionalLight(direction=(0.3, -1.0, -0.4), intensity=2.0))
    ents["camera"] = look_from(world, *CUT_EYES["before both portals"])
    ents["a"], ents["b"] = spawn_portal_pair(world, (-3, 1.5, 0), None, (3, 1.5, -1), FACING_MINUS_X)
    world.get(ents["b"], Transform).scale = (scale, scale, scale)
    if by_hand:
        ents["bar"] = world.spawn(Transform(position=(-2.8, 1.5, 0.5)), MeshRef(open_half()),
                                  Material(color=color), *(kind() for kind in kinds))
    else:
        ents["bar"] = world.spawn(Transform(position=(-2.8, 1.5, 0.0)), MeshRef(box((0.4, 0.4, 2.0))),
                                  Material(color=color), Traveller(), *(kind() for kind in kinds))
    ents["floor"] = world.spawn(Transform(position=(0, -0.05, 0)), MeshRef(box((20, 0.1, 20))),
                                Material(color=(0.25, 0.25, 0.25)))
    ents["mirror"] = world.spawn(Transform(position=(0, 2, -5)), MeshRef(quad(14, 4)),
                                 Material(color=(0.1, 0.1, 0.1)), Mirror())
    if by_hand:
        ents["half"] = world.spawn(Transform(position=(3 - 0.5 * scale, 1.5, -1 - 0.2 * scale), rotation=FACING_MINUS_X,
                                             scale=(scale, scale, scale)),
                                   MeshRef(open_half()), Material(color=color), *(kind() for kind in kinds))


@pytest.mark.parametrize("scale, path, look", [(1.0, "per_mirror", "matte"), (1.0, "batched", "matte"),
                                               (2.0, "per_mirror", "matte"), (1.0, "batched", "chrome"),
                                               (1.0, "per_mirror", "glass"), (1.0, "per_mirror", "see-through"),
                                               (1.0, "batched", "see-through")])
def test_a_box_halfway_through_is_drawn_as_its_two_halves_built_by_hand(scene, scale, path, look):
    """The bar halfway into A, B turned to face -X (and scaled 2: the clone twice the size,
    cut on B's front), its views drawn each alone or batched, matte, chrome, refracting glass
    or see-through (the transparent slot), is drawn, seamlessly, as the
    same scene with the bar's two halves built
    by hand (``build_cut``: the half in front of A where it is, the half gone in at the pose
    worked out by hand beyond B, no Traveller, no slicing): colours and ids alike (the clone
    reports its source), seen before both portals (each half directly and the other half
    through the portal it went into), from behind A (where the part gone in is cut away and
    casts no shadow) and in a mirror behind both (whose view sees behind A and behind B)."""
    sliced, hand = {}, {}
    cut = scene(lambda world: build_cut(world, sliced, scale, False, look), CUT_SIZE)
    reference = scene(lambda world: build_cut(world, hand, scale, True, look), CUT_SIZE)
    assert [hand[k] for k in sliced] == list(sliced.values())  # one id each (the clone's comes after)
    for runner in (cut, reference):
        runner.engine.reflection_system.path = path
    for view in CUT_EYES:
        seen = []
        for runner, ents in ((cut, sliced), (reference, hand)):
            place_camera(runner.world, ents, view)
            rgb = runner.frame()
            ids = runner.ids()
            ids[ids == ents.get("half", -1)] = ents["bar"]
            seen.append((rgb.astype(int), ids, runner.engine.renderer.targets.read_surface_ids()))
            assert list(runner.world.resources[PortalCrossings]) == []
            assert runner.stats.reflection_path == path
        (rgb, ids, surfaces), (expected_rgb, expected_ids, _) = seen
        differ = ids != expected_ids
        assert differ.sum() <= 3, (view, int(differ.sum()))
        assert np.abs(rgb - expected_rgb)[~differ].max() <= 4, view
        bar = ids == sliced["bar"]
        where = {name: int((bar & (surfaces == sliced[name])).sum()) for name in ("a", "b", "mirror")}
        where["directly"] = int((bar & (surfaces == sliced["bar"])).sum())
        if view == "behind A":
            assert where["directly"] > 20, where
        else:
            assert min(where.values()) >= 5, (view, where)  # directly, through A, through B, in the mirror
    world = cut.world
    (clone, _), = world.query_one(PortalClone)
    assert world.get(sliced["bar"], Slice).plane == glm.vec4(0, 0, 1, 0)
    np.testing.assert_allclose(world.get(clone, Slice).plane, (-1, 0, 0, 3), atol=1e-6)  # B's front, x < 3, kept


def bar_parts_by_hand(world, low: float, high: float) -> list[int]:
    """The bar from A + (0.2, 0, ``low``) to A + (0.2, 0, ``high``) along A's axis, as the parts
    a person sees (``build_cut``'s pair, worked out by hand): the part in front of A (z 0 up)
    where it is, and the part gone into A (z below 0) beyond B, at B-local (-0.2, 0, -z) turned
    as B (world: B + (z, 0, -0.2)); each open where A's plane cuts it.  Their entities."""
    parts = []
    look = (0.9, 0.5, 0.1)
    if high > 0.0:  # in front of A
        start = max(low, 0.0)
        mesh = open_half(high - start) if low < 0.0 else box((0.4, 0.4, high - low))
        parts.append(world.spawn(Transform(position=(-2.8, 1.5, (start + high) / 2)), MeshRef(mesh),
                                 Material(color=look)))
    if low < 0.0:  # gone in: B-local z from -min(high, 0) to -low, open at B-local z = 0
        end = min(high, 0.0)
        mesh = open_half(end - low) if high > 0.0 else box((0.4, 0.4, high - low))
        parts.append(world.spawn(Transform(position=(3.0 + (low + end) / 2, 1.5, -1.2), rotation=FACING_MINUS_X),
                                 MeshRef(mesh), Material(color=look)))
    return parts


def build_bare(world, ents, eye: str) -> None:
    """``build_cut``'s scene without the bar or its halves, seen from ``CUT_EYES[eye]``."""
    build_cut(world, ents, 1.0, by_hand=True)
    for name in ("bar", "half"):
        world.delete_entity(ents.pop(name))
    place_camera(world, ents, eye)


def place_camera(world, ents, eye: str) -> None:
    position, target = (glm.vec3(v) for v in CUT_EYES[eye])
    camera = world.get(ents["camera"], Transform)
    camera.position, camera.rotation = position, look_rotation(target - position)


def assert_drawn_as_by_hand(rgb, ids, expected_rgb, expected_ids, bar: int, parts: list[int], why) -> None:
    """A frame (sRGB, ids) is the hand-built one, its parts' ids read as ``bar``'s (a clone
    reports its source): a few edge pixels may differ, and it shows the bar."""
    expected_ids = expected_ids.copy()
    expected_ids[np.isin(expected_ids, parts)] = bar
    differ = ids != expected_ids
    assert differ.sum() <= 3, (why, int(differ.sum()))
    assert np.abs(rgb.astype(int) - expected_rgb.astype(int))[~differ].max() <= 4, why
    assert (ids == bar).sum() > 20, why


@pytest.mark.parametrize("step", [0.6, 1.4])
def test_a_bar_going_through_fast_is_drawn_every_frame_as_its_parts_built_by_hand(scene, step):
    """The 2 m bar walking into A at ``step`` metres a frame (36 and 84 m/s: 1.4 m takes it
    from wholly in front of A to its middle past A's plane in one frame) is drawn, frame by
    frame, as the parts worked out by hand from where its centre has got to along A's axis
    (``bar_parts_by_hand``, its ends a metre either side): before A, cut at A with the rest
    beyond B; on the frame its middle goes through, carried to B and cut there with the rest
    still in front of A (a clone at A); then wholly beyond B, whole.  Seen from behind A and
    in the mirror behind both portals (which sees behind B)."""
    eyes = ("behind A", "in the mirror")
    start, dt = 1.3 + step, 1.0 / 60.0
    runners, ents = [], []
    for eye in eyes:
        found = {}

        def build(world, found=found, eye=eye):
            build_bare(world, found, eye)
            found["bar"] = world.spawn(Transform(position=(-2.8, 1.5, start)), MeshRef(box((0.4, 0.4, 2.0))),
                                       Material(color=(0.9, 0.5, 0.1)), Traveller(velocity=(0, 0, -step / dt)))

        runners.append(scene(build, CUT_SIZE))
        ents.append(found)
    states = []  # (the centre along A's axis, crossed this frame, the bar cut, its clones)
    for frame in range(1, 20):
        centre = start - step * frame
        if centre < -1.0 - step:
            break
        seen = [(runner.frame(dt), runner.ids()) for runner in runners]
        world, bar = runners[0].world, ents[0]["bar"]
        clones = world.query_one(PortalClone)
        states.append((round(centre, 2), bool(world.resources[PortalCrossings]), world.has(bar, Slice), len(clones)))
        if centre < 0.0 and world.has(bar, Slice):  # carried to B, still straddling it: cut at B, the rest at A
            np.testing.assert_allclose(world.get(bar, Slice).plane, (-1, 0, 0, 3), atol=1e-5)
            assert world.get(clones[0][0], Slice).plane == glm.vec4(0, 0, 1, 0)
        for (rgb, ids), eye, found in zip(seen, eyes, ents, strict=True):
            hand = {}

            def build_hand(world, hand=hand, eye=eye, centre=centre):
                build_bare(world, hand, eye)
                hand["parts"] = bar_parts_by_hand(world, centre - 1.0, centre + 1.0)

            reference = scene(build_hand, CUT_SIZE)
            assert_drawn_as_by_hand(rgb, ids, reference.frame(dt), reference.ids(), found["bar"], hand["parts"],
                                    (eye, states[-1]))
            reference.close()
    crossed = [state for state in states if state[1]]
    assert len(crossed) == 1 and -1.0 < crossed[0][0] < 0.0 and crossed[0][2:] == (True, 1), states
    assert states[-1][2:] == (False, 0), states  # wholly through: whole, no clone


@pytest.mark.parametrize("pose", ["morph", "skin"])
def test_a_bar_stretched_into_a_by_its_pose_is_cut_by_its_posed_box(scene, pose):
    """A 1 m bar standing 0.1 m in front of A (z 0.1..1.1: its mesh's box does not reach A),
    stretched by its pose (a morph target, or a second joint, moving its back end 1 m along
    -Z: z -0.9..1.1) is cut at A and comes out of B as the stretched bar's parts worked out by
    hand (``bar_parts_by_hand``), seen from behind A (where the stretched end would stand) and
    before both portals: its straddling is read from its posed box, not its mesh's."""
    ents = {}
    plain = box((0.4, 0.4, 1.0))
    back = plain.positions[:, 2] < 0.0
    if pose == "morph":
        offsets = np.where(back[:, None], (0.0, 0.0, -1.0), 0.0)[None]
        mesh = Mesh(plain.positions, plain.normals, plain.uvs, plain.indices, name="stretched", morph_positions=offsets)
        posing = Morph((1.0,))
    else:
        mesh = Mesh(plain.positions, plain.normals, plain.uvs, plain.indices, name="stretched",
                    joints=np.stack([back.astype(int), np.zeros(len(back), int)], axis=1),
                    weights=np.tile([1.0, 0.0], (len(back), 1)))
        posing = Skin(np.stack([np.eye(4), np.array(glm.translate(glm.vec3(0, 0, -1)).to_list()).T]))

    def build(world):
        build_bare(world, ents, "behind A")
        ents["bar"] = world.spawn(Transform(position=(-2.8, 1.5, 0.6)), MeshRef(mesh), Material(color=(0.9, 0.5, 0.1)),
                                  Traveller(), posing)

    hand = {}

    def build_hand(world):
        build_bare(world, hand, "behind A")
        hand["parts"] = bar_parts_by_hand(world, -0.9, 1.1)

    cut, reference = scene(build, CUT_SIZE), scene(build_hand, CUT_SIZE)
    for look in ("behind A", "before both portals"):
        for runner, found in ((cut, ents), (reference, hand)):
            place_camera(runner.world, found, look)
        rgb, ids = cut.frame(), cut.ids()
        assert_drawn_as_by_hand(rgb, ids, reference.frame(), reference.ids(), ents["bar"], hand["parts"], look)
    assert cut.world.get(ents["bar"], Slice).plane == glm.vec4(0, 0, 1, 0)
    (clone, _), = cut.world.query_one(PortalClone)
    assert cut.world.has(clone, Morph if pose == "morph" else Skin)


def test_a_box_halfway_through_is_whole_again_from_the_frame_its_pair_closes(scene):
    """The bar halfway into A (cut there, its clone beyond B), B disabled: from that frame
    on nothing is cut at A, so seen from behind A the bar's far half stands where it is again
    (its id 0.6 m behind A), and the frame is the one of the same scene whose B was disabled
    from the start (the bar never cut); enabled again, it is cut again."""
    from components import Portal

    ents, never = {}, {}
    cut = scene(lambda world: build_cut(world, ents, 1.0, by_hand=False), CUT_SIZE)

    def closed_from_the_start(world):
        build_cut(world, never, 1.0, by_hand=False)
        world.get(never["b"], Portal).enabled = False

    reference = scene(closed_from_the_start, CUT_SIZE)
    for runner, found in ((cut, ents), (reference, never)):
        place_camera(runner.world, found, "behind A")
    cut.frame()
    world = cut.world
    assert world.has(ents["bar"], Slice) and world.query_one(PortalClone)
    far_half = cut.project((-2.8, 1.5, -0.6))
    assert cut.ids()[far_half[::-1]] != ents["bar"]
    world.get(ents["b"], Portal).enabled = False
    rgb = cut.frame().astype(int)
    ids = cut.ids()
    assert not world.has(ents["bar"], Slice) and world.query_one(PortalClone) == []
    assert ids[far_half[::-1]] == ents["bar"]
    expected_rgb = reference.frame().astype(int)
    np.testing.assert_array_equal(ids, reference.ids())
    assert np.abs(rgb - expected_rgb).max() <= 2
    world.get(ents["b"], Portal).enabled = True
    cut.frame()
    assert world.has(ents["bar"], Slice) and cut.ids()[far_half[::-1]] != ents["bar"]
