"""A probe recaptured every frame keeps, as it is, a face no change reached since it was last
drawn (``ProbeDue.unchanged``, ``ProbeCaptures.capture``), and draws again a face a moved box
or a moved shadow reaches; the mip chains are built again for the faces drawn alone
(``CubeMipPass.build``'s ``faces``).  Each frame the whole cube, every level, is checked bit
for bit against a capture that draws all six faces and builds every chain (the records
forgotten): a face kept wrongly, or a chain left as it was, shows there."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import DirectionalLight, Material, MeshRef, ReflectionProbe, Transform, Visibility
from engine.assets.mesh import box, plane
from tests.support import look_from, probe_face_of


def _probe_stage(runner):
    return runner.engine.stages["probes"]


def _floor_with_probe(world, hidden_caster: bool = False) -> None:
    """A lit floor, a probe 0.6 m above it that sees 2 m (its -Y face: the floor below), a
    caster beside it out of its reach whose shadow falls into that face (hidden from probes
    with ``hidden_caster``: it casts all the same), a small box inside its -X face (its
    shadow falls away from the probe), and a box far away."""
    look_from(world, (0, 3, 6), (0, 0, 0))
    world.spawn(DirectionalLight(direction=(-1.0, -1.5, 0.0), intensity=2.0))
    world.spawn(Transform(), MeshRef(plane(60, 60)), Material(color=(0.8, 0.8, 0.8)))
    world.resources["probe"] = world.spawn(Transform(position=(0.0, 0.6, 0.0)),
                                           ReflectionProbe(resolution=32, far=2.0, refresh="every_frame"))
    caster = [Transform(position=(2.2, 2.6, 0.0)), MeshRef(box()), Material()]
    if hidden_caster:
        caster.append(Visibility(in_probes=False))
    world.resources["caster"] = world.spawn(*caster)
    world.resources["near"] = world.spawn(Transform(position=(-1.2, 0.6, 0.0)), MeshRef(box((0.3, 0.3, 0.3))),
                                          Material(color=(0.9, 0.2, 0.1)))
    world.resources["far"] = world.spawn(Transform(position=(20.0, 0.5, 20.0)), MeshRef(box()), Material())


def _faces_drawn(cube: _Cube) -> list[int]:
    """The probe faces drawn from now on, by face, appended as they are drawn (the drawing
    itself unchanged)."""
    drawn: list[int] = []
    draw = cube.probes.scene_pass.draw

    def seen_drawing(views, *args, **kwargs):
        drawn.extend(face for face in map(probe_face_of, views) if face is not None)
        return draw(views, *args, **kwargs)

    cube.probes.scene_pass.draw = seen_drawing
    return drawn


class _Cube:
    """The probe's cube, every level of every face, and the same drawn whole."""

    def __init__(self, runner) -> None:
        self.runner = runner
        self.probes = runner.engine.renderer.probes
        self.owner = runner.world.resources["probe"]

    def levels(self) -> list[np.ndarray]:
        from engine.render.raw_gl import read_cube_level

        texture = self.probes.cubes[self.owner].texture
        return [read_cube_level(self.runner.ctx, texture, face, level, 14) for face in range(6) for level in range(6)]

    def drawn_whole(self) -> list[np.ndarray]:
        """What a capture drawing all six faces from the same state leaves."""
        from engine.render.probes import face_view

        state = _probe_stage(self.runner).probes[self.owner]
        settings = state.settings
        views = {face: face_view(face, state.position, settings.near, settings.far, settings.resolution,
                                 skip=self.owner, layers=settings.layer_mask) for face in range(6)}
        self.probes.written_elsewhere(self.owner)
        self.probes.capture(self.owner, views, None, 0, settings.prefilter)
        return self.levels()

    def as_if_drawn_whole(self) -> bool:
        kept = self.levels()
        return all(np.array_equal(a, b) for a, b in zip(kept, self.drawn_whole(), strict=True))


@pytest.mark.parametrize("hidden_caster", [False, True], ids=["caster", "caster_hidden_from_probes"])
def test_an_every_frame_probe_draws_only_the_faces_a_change_reaches(scene, hidden_caster):
    """Still frames draw no face (all six kept: the cube is what drawing them gives); a box
    moving far away draws none; the box inside the -X face moving draws that face, which
    shows it moved; the caster beside the probe, out of its reach, moving draws the -Y face,
    where its shadow falls (also when it is hidden from probes: it casts all the same), and
    that face changes.  After each frame the cube is, bit for bit, a capture of all six."""
    runner = scene(lambda world: _floor_with_probe(world, hidden_caster), (64, 48))
    _probe_stage(runner).path = "six_pass"
    cube = _Cube(runner)
    world = runner.world
    runner.frame()
    assert runner.stats.probe_faces == 6
    for _ in range(2):
        runner.frame()
        assert runner.stats.probe_captures == 1 and runner.stats.probe_faces == 0
    assert cube.as_if_drawn_whole()

    world.get(world.resources["far"], Transform).position += glm.vec3(0.0, 0.0, 0.5)
    runner.frame()
    assert runner.stats.probe_faces == 0
    assert cube.as_if_drawn_whole()

    before = cube.probes.read_face(cube.owner, 1).copy()
    world.get(world.resources["near"], Transform).position += glm.vec3(0.0, 0.15, 0.0)
    runner.frame()
    assert 1 <= runner.stats.probe_faces < 6
    assert not np.array_equal(cube.probes.read_face(cube.owner, 1), before)  # -X: the box moved up
    assert cube.as_if_drawn_whole()

    runner.frame()
    before = cube.probes.read_face(cube.owner, 3).copy()
    world.get(world.resources["caster"], Transform).position += glm.vec3(0.0, 0.0, 0.4)
    runner.frame()
    assert runner.stats.probe_faces >= 1  # (the box its shadow may fall in, swept along the light, holds the probe)
    assert not np.array_equal(cube.probes.read_face(cube.owner, 3), before)  # -Y: the shadow moved
    assert cube.as_if_drawn_whole()


def test_a_new_shadow_filter_draws_every_face_again(scene):
    """What every face is drawn with changes (the shadow maps' filter: other lookups, other
    programs): no face is kept (none shows the sky alone: the caster is in the +Y face's
    frustum, past its far plane), and the cube is a capture of all six."""
    runner = scene(_floor_with_probe, (64, 48))
    _probe_stage(runner).path = "six_pass"
    cube = _Cube(runner)
    for _ in range(3):
        runner.frame()
    assert runner.stats.probe_faces == 0
    maps = runner.engine.renderer.shadows
    maps.filter = "grid" if maps.filter == "single" else "single"
    runner.frame()
    assert runner.stats.probe_faces == 6
    assert cube.as_if_drawn_whole()


def test_a_swept_box_is_left_out_only_of_faces_none_of_its_points_lie_in():
    """``face_hits_swept`` against points sampled through each swept box (a point of the box
    moved along its sweep by a share of it): every face one of them lies in (along the face's
    axis, at least as far as across it, within ``far``) is a face hit; and the hull test
    leaves out faces the box bounding the sweep does not."""
    from engine.core.cube_faces import CUBE_FACES
    from engine.rules.probe_rules import face_hits, face_hits_swept

    rng = np.random.default_rng(7)
    apex, far = np.array([0.3, -0.2, 0.1]), 7.0
    lo = rng.uniform(-6, 6, (300, 3))
    hi = lo + rng.uniform(0.05, 2.0, (300, 3))
    sweep = rng.normal(0.0, 4.0, (300, 3))
    hits = face_hits_swept(apex, far, lo, hi, sweep)
    axes = np.array([forward for forward, _, _ in CUBE_FACES], float)
    grid = np.stack(np.meshgrid(*[np.linspace(0.0, 1.0, 5)] * 3, indexing="ij"), -1).reshape(-1, 3)
    for b in range(len(lo)):
        points = (lo[b] + grid * (hi[b] - lo[b]))[:, None, :] + np.linspace(0.0, 1.0, 9)[None, :, None] * sweep[b]
        d = points.reshape(-1, 3) - apex
        d = d[np.linalg.norm(d, axis=1) <= far]
        along = d @ axes.T
        seen = ((along >= np.abs(d).max(axis=1, keepdims=True) - 1e-12) & (along > 0.0)).any(axis=0)
        assert not (seen & ~hits[b]).any(), (b, seen, hits[b])
    bounding = face_hits(apex, far, np.minimum(lo, lo + sweep), np.maximum(hi, hi + sweep))
    assert not (hits & ~bounding).any() and (bounding & ~hits).sum() > 0


def test_a_batch_drawn_with_another_build_draws_again_every_face_that_shows_it(scene):
    """Two boxes of one batch, one in the probe's +X face and one in its -X face: the +X
    box given an Emissive moves the whole batch to the build of the scene program that
    switches per instance, so the -X face, where nothing changed, is drawn again too (with
    another program its pixels may differ); the cube is a capture of all six."""
    from components import Emissive, Skybox

    def build(world):
        look_from(world, (0, 3, 6), (0, 0, 0))
        world.spawn(Skybox())
        world.spawn(DirectionalLight(direction=(-0.3, -1.5, 0.2), intensity=2.0))
        world.resources["probe"] = world.spawn(Transform(position=(0.0, 0.6, 0.0)),
                                               ReflectionProbe(resolution=32, far=10.0, refresh="every_frame"))
        mesh = box()  # one mesh: one batch
        for name, x in (("east", 3.0), ("west", -3.0)):
            world.resources[name] = world.spawn(Transform(position=(x, 0.6, 0.0)), MeshRef(mesh),
                                                Material(color=(0.8, 0.3, 0.2), roughness=0.3))

    runner = scene(build, (64, 48))
    _probe_stage(runner).path = "six_pass"
    cube = _Cube(runner)
    drawn = _faces_drawn(cube)
    for _ in range(3):
        runner.frame()
    assert runner.stats.probe_faces == 0
    batches = runner.engine.renderer.opaque_batches()
    before = [batch.variants for batch in batches]
    drawn.clear()
    runner.world.add_component(runner.world.resources["east"], Emissive(1.0))
    runner.frame()
    assert len(runner.engine.renderer.opaque_batches()) == 1
    assert [batch.variants for batch in batches] != before  # the boxes' batch: mixed variants now
    assert 0 in drawn and 1 in drawn, drawn  # +X: the box changed; -X: its batch's build did
    assert cube.as_if_drawn_whole()


def test_instances_drawn_in_another_order_draw_again_every_face_that_shows_their_batch(scene):
    """Three boxes of one batch (+X, -X and +Z of the probe): the +X one deleted, the last
    row fills its place, so the batch draws its instances in another order (which decides
    ties of depth), and every face that shows the batch is drawn again, the -X face too;
    the cube is a capture of all six."""
    from components import Skybox

    def build(world):
        look_from(world, (0, 3, 6), (0, 0, 0))
        world.spawn(Skybox())
        world.spawn(DirectionalLight(direction=(-0.3, -1.5, 0.2), intensity=2.0))
        world.resources["probe"] = world.spawn(Transform(position=(0.0, 0.6, 0.0)),
                                               ReflectionProbe(resolution=32, far=10.0, refresh="every_frame"))
        world.spawn(Transform(), MeshRef(plane(60, 60)), Material())  # the level's box, whatever goes
        mesh = box()  # one mesh: one batch
        for name, position in (("east", (3.0, 0.6, 0.0)), ("west", (-3.0, 0.6, 0.0)), ("south", (0.0, 0.6, 3.0))):
            world.resources[name] = world.spawn(Transform(position=position), MeshRef(mesh),
                                                Material(color=(0.8, 0.3, 0.2), roughness=0.3))

    runner = scene(build, (64, 48))
    _probe_stage(runner).path = "six_pass"
    cube = _Cube(runner)
    drawn = _faces_drawn(cube)
    for _ in range(3):
        runner.frame()
    assert runner.stats.probe_faces == 0
    drawn.clear()
    boxes = next(batch for batch in runner.engine.renderer.opaque_batches() if batch.count == 3)
    runner.world.delete_entity(runner.world.resources["east"])
    runner.frame()
    assert boxes.count == 2 and boxes.entity_at[0] == runner.world.resources["south"]  # the last row filled it
    assert 0 in drawn and 1 in drawn, drawn  # +X: the box went; -X: its batch's order changed
    assert cube.as_if_drawn_whole()


def test_a_probe_that_kept_every_face_leaves_its_irradiance_row_as_projected(scene):
    """A probe with an influence box, recaptured every frame in a still room: once every
    face and its chain are kept, its irradiance is not projected again (the row would be the
    same); a request draws the faces and projects it again, to the same row."""
    from tests.test_ambient_light import red_wall_room

    ents = {}
    runner = scene(red_wall_room(ents), (64, 48))
    runner.world.get(ents["probe"], ReflectionProbe).refresh = "every_frame"
    for _ in range(3):
        runner.frame()
    table = runner.engine.renderer.irradiance
    projected, row = table.projections, table.read_row(ents["probe"]).copy()
    for _ in range(2):
        runner.frame()
        assert runner.stats.probe_faces == 0 and table.projections == projected
    runner.world.get(ents["probe"], ReflectionProbe).request()
    runner.frame()
    assert runner.stats.probe_faces >= 1 and table.projections == projected + 1  # (a face of sky alone is kept)
    np.testing.assert_allclose(table.read_row(ents["probe"]), row, rtol=1e-5, atol=1e-6)
