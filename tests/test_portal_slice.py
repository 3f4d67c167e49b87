"""Things partly through a portal: sliced at the portal, the rest drawn beyond the partner."""
from __future__ import annotations

import numpy as np
from pyglm import glm

from components import (
    Camera,
    DirectionalLight,
    Emissive,
    FromDecal,
    Material,
    MeshRef,
    PortalClone,
    Skybox,
    Slice,
    Transform,
    Traveller,
    look_rotation,
)
from components.decal import Decal
from engine.assets.mesh import box
from engine.assets.portals import spawn_portal_pair

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
