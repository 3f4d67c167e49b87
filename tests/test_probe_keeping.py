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


# --- each change README lists, against an engine built where the change leaves the world -----
def _room_with_probe(world) -> None:
    """A lit floor, an every-frame probe 0.6 m above it that sees 6 m, a small box in its
    +X face, and a caster hidden from probes high over the -Z side (its shadow on the
    floor there, out of the -Y face: the probe sees the floor within 0.6 m of its foot)."""
    look_from(world, (0, 3, 6), (0, 0, 0))
    world.resources["sun"] = world.spawn(DirectionalLight(direction=(-1.0, -1.5, 0.3), intensity=2.0))
    world.spawn(Transform(), MeshRef(plane(60, 60)), Material(color=(0.8, 0.8, 0.8)))
    world.resources["probe"] = world.spawn(Transform(position=(0.0, 0.6, 0.0)),
                                           ReflectionProbe(resolution=32, far=6.0, refresh="every_frame"))
    world.resources["near"] = world.spawn(Transform(position=(2.5, 0.5, -0.6)), MeshRef(box((0.3, 0.3, 0.3))),
                                          Material(color=(0.9, 0.2, 0.1)))
    world.resources["caster"] = world.spawn(Transform(position=(1.9, 2.4, -3.0)), MeshRef(box((0.5, 0.5, 0.5))),
                                            Material(), Visibility(in_probes=False))


def _lamp(world) -> None:
    from components import PointLight

    world.resources["lamp"] = world.spawn(Transform(position=(2.0, 1.5, 0.5)),
                                          PointLight(color=(1.0, 0.5, 0.2), intensity=6.0, range=5.0))


def _spot_with_cookie(world) -> None:
    from components import PointLight
    from engine.assets.texture_data import checker_texture

    world.resources["lamp"] = world.spawn(
        Transform(position=(2.0, 2.5, 0.0), rotation=glm.angleAxis(-1.5708, glm.vec3(1, 0, 0))),
        PointLight(intensity=12.0, range=6.0, spot_angle=60.0, cookie=checker_texture(16, 4)))


def _sky(world) -> None:
    from components import Skybox

    world.resources["sky"] = world.spawn(Skybox())


def _far_lamps(world) -> None:
    """The lamp beside the probe and, 140 m away, sixteen lamps: one more than the Lights
    block's sixteen places, so which are kept follows the camera."""
    from components import PointLight

    _lamp(world)
    for i in range(16):
        world.spawn(Transform(position=(100.0 + i % 4, 1.0, 100.0 + i // 4)),
                    PointLight(color=(0.2, 0.2, 1.0), intensity=1.0, range=4.0))


def _casting_lamps(world) -> None:
    """A lamp casting shadows over the +X face (a post beside the probe casts one) and, 140 m
    away, two more: one more than the two shadow cubes, so which cast follows the camera."""
    from components import PointLight

    world.resources["lamp"] = world.spawn(Transform(position=(1.5, 1.8, 0.5)),
                                          PointLight(color=(1.0, 0.5, 0.2), intensity=8.0, range=6.0, shadows=True))
    world.spawn(Transform(position=(1.5, 0.4, 0.0)), MeshRef(box((0.4, 0.8, 0.4))), Material())
    for i in range(2):
        world.spawn(Transform(position=(100.0 + i, 1.0, 100.0)),
                    PointLight(color=(0.2, 0.2, 1.0), intensity=1.0, range=4.0, shadows=True))


def _portal(world) -> None:
    from components.transform import look_rotation
    from engine.assets.portals import spawn_portal_pair

    world.resources["portal"], _ = spawn_portal_pair(world, (2.5, 1.0, 0.0), look_rotation((1, 0, 0)),
                                                     (-20.0, 1.0, 0.0), look_rotation((1, 0, 0)), size=(1.5, 1.5))
    world.spawn(Transform(position=(-22.0, 1.0, 0.0)), MeshRef(box((1, 2, 2))), Material(color=(0.1, 0.1, 0.9)))


def _monitor(world) -> None:
    """A screen in the +X face whose camera, 30 m away (out of the probe's reach), watches a box."""
    from components import Camera, Monitor
    from components.transform import look_rotation
    from engine.assets.mesh import quad

    lens = world.resources["lens"] = world.spawn(Transform(position=(30.0, 1.0, 5.0),
                                                           rotation=look_rotation((0, 0, -1))),
                                                 Camera(fov_y=40.0, active=False))
    world.resources["subject"] = world.spawn(Transform(position=(30.0, 1.0, 0.0)), MeshRef(box()),
                                             Material(color=(0.1, 0.9, 0.1)))
    world.resources["screen"] = world.spawn(
        Transform(position=(2.5, 1.0, 0.0), rotation=glm.angleAxis(-1.5708, glm.vec3(0, 1, 0))),
        MeshRef(quad(2.0, 1.5)), Material(color=(0, 0, 0, 1), roughness=1.0, environment_reflection=0.0),
        Monitor(camera=lens, size=(16, 12)))


def _set(name, kind, field, value):
    def change(world):
        setattr(world.get(world.resources[name], kind), field, value)
    return change


def _moved(name, by):
    def change(world):
        world.get(world.resources[name], Transform).position += glm.vec3(*by)
    return change


def _came(world):
    world.spawn(Transform(position=(2.5, 0.5, 0.8)), MeshRef(box((0.3, 0.3, 0.3))), Material(color=(0.1, 0.9, 0.2)))


def _went(world):
    world.delete_entity(world.resources["near"])


def _textured(world):
    from engine.assets.texture_data import checker_texture

    world.get(world.resources["near"], Material).texture = checker_texture(16, 4, (255, 255, 0), (0, 0, 255))


def _decal(world):
    from components import Decal

    world.spawn(Transform(position=(1.5, 0.05, 0.0), rotation=glm.angleAxis(-1.5708, glm.vec3(1, 0, 0)),
                          scale=(1.0, 1.0, 0.4)), Decal(color=(0.0, 0.2, 1.0, 1.0)))


def _new_cookie(world):
    from components import PointLight
    from engine.assets.texture_data import checker_texture

    world.get(world.resources["lamp"], PointLight).cookie = checker_texture(16, 2, (255, 0, 0), (0, 255, 0))


def _camera_walks_to_the_far_lamps(world):
    from components import Camera

    (camera, _), = world.query_one(Camera)
    world.get(camera, Transform).position = glm.vec3(101.5, 1.5, 101.5)


def _portal_closed(world):
    from components import Portal

    world.get(world.resources["portal"], Portal).enabled = False


def _skybox_zenith(world):
    from components import Skybox

    world.get(world.resources["sky"], Skybox).zenith = (0.9, 0.1, 0.1)


def _lamp_brighter(world):
    from components import PointLight

    world.get(world.resources["lamp"], PointLight).intensity = 20.0


def _subject_recoloured(world):
    world.get(world.resources["subject"], Material).color = (0.9, 0.1, 0.9)


# name: (what the scene has besides the room, the change, the faces it may draw: None, any)
CHANGES = {
    "moved": (None, _moved("near", (0.0, 0.0, 0.3)), {0}),
    "came": (None, _came, {0}),
    "went": (None, _went, None),   # (its batch goes: every face showing a batch)
    "look_changed": (None, _set("near", Material, "color", (0.1, 0.9, 0.1)), {0}),
    "texture_swapped": (None, _textured, None),   # (its batch changes: every face showing a batch)
    "shadow_in": (None, _moved("caster", (0.0, 0.0, 2.7)), None),
    "shadow_out": (lambda w: _moved("caster", (0.0, 0.0, 2.7))(w), _moved("caster", (0.0, 0.0, -2.7)), None),
    "lamp_changed": (_lamp, _lamp_brighter, None),
    "sun_changed": (None, _set("sun", DirectionalLight, "intensity", 1.0), None),
    "sky_changed": (_sky, _skybox_zenith, None),
    "decal_added": (None, _decal, None),
    "cookie_swapped": (_spot_with_cookie, _new_cookie, None),
    "portal_closed": (_portal, _portal_closed, None),
    "picture_changed": (_monitor, _subject_recoloured, None),
    "lamp_left_behind": (_far_lamps, _camera_walks_to_the_far_lamps, None),
    "lamp_lost_its_shadow_cube": (_casting_lamps, _camera_walks_to_the_far_lamps, None),
}


# Scenes whose every-frame probe draws faces in still frames too: a level with a portal (every
# face that sees a batch, as README says).  (A face showing a monitor's screen settles: the
# picture is not drawn again for a capture of a probe it cannot sample,
# test_an_every_frame_probe_seeing_a_screen_draws_nothing_once_both_settled.)
REDRAWN_STILL = {"portal_closed"}


def _cube_faces(runner) -> list[np.ndarray]:
    probes, owner = runner.engine.renderer.probes, runner.world.resources["probe"]
    return [probes.read_face(owner, face) for face in range(6)]


def _kept_and_fresh(scene, change, refresh="every_frame"):
    """The room (with the change's extra), run three frames, then changed and run two: the
    faces before the change, the faces after, those a second engine built changed draws
    (five frames on), and the faces the first drew after the change."""
    extra, change_world, _ = CHANGES[change]

    def build(world):
        _room_with_probe(world)
        world.get(world.resources["probe"], ReflectionProbe).refresh = refresh
        if extra is not None:
            extra(world)

    def built_changed(world):
        build(world)
        change_world(world)

    runner = scene(build, (48, 32))
    _probe_stage(runner).path = "six_pass"
    for _ in range(3):
        runner.frame()
    if change not in REDRAWN_STILL:
        assert runner.stats.probe_faces == 0  # still: every face kept
    before = _cube_faces(runner)
    drawn = _faces_drawn(_Cube(runner))
    change_world(runner.world)
    for _ in range(2):
        runner.frame()
    kept = _cube_faces(runner)
    fresh_runner = scene(built_changed, (48, 32))
    _probe_stage(fresh_runner).path = "six_pass"
    for _ in range(5):
        fresh_runner.frame()
    return before, kept, _cube_faces(fresh_runner), set(drawn)


def _stale_faces(kept, fresh) -> dict[int, float]:
    return {face: float(np.abs(kept[face] - fresh[face]).max()) for face in range(6)
            if not np.array_equal(kept[face], fresh[face])}


@pytest.mark.filterwarnings("ignore::engine.core.errors.LightLimitWarning")  # (the lamps past the limits)
@pytest.mark.parametrize("change", list(CHANGES))
def test_an_every_frame_probe_redraws_each_face_a_change_reaches_as_a_fresh_engine_draws_it(scene, change):
    """Each change README lists (a thing in a face that moved, came, went or changed its look,
    a shadow moving into or out of a face, a light or the sky changing) and some it does not
    name (a texture swapped, a decal added, a spot's cookie swapped, a portal closed, a
    monitor's picture changing, a lamp left out of the Lights block as the camera walks
    away): one engine runs still frames (every face kept), then the change and a frame; a
    second engine is built with the change already made.  Every face of the first is, bit
    for bit, the second's (a face kept that the change reached would hold what it showed
    before); the change shows in some face; each face it changed was drawn again, and a
    change within one face draws that face alone."""
    before, kept, fresh, drawn = _kept_and_fresh(scene, change)
    changed = {face for face in range(6) if not np.array_equal(before[face], fresh[face])}
    assert changed, "the change shows in no face"
    assert changed <= drawn, (sorted(changed), sorted(drawn))
    assert not _stale_faces(kept, fresh)
    allowed = CHANGES[change][2]
    if allowed is not None:
        assert drawn <= allowed, sorted(drawn)


@pytest.mark.filterwarnings("ignore::engine.core.errors.LightLimitWarning")  # (the lamps past the limits)
@pytest.mark.parametrize("refresh", ["on_change", "every_n"])
@pytest.mark.parametrize("change", ["lamp_left_behind", "lamp_lost_its_shadow_cube"])
def test_a_lamp_the_camera_leaves_out_of_the_lights_relights_the_faces_it_lit(scene, change, refresh):
    """Nothing of the lamp beside the probe changes, but the camera walks 140 m away to
    other lamps, which take its place: with seventeen lamps, the Lights block's sixteen
    places (it lights nothing any more), or with three casting, the two shadow cubes (it
    lights without its shadow) (``KeptLights``).  An ``on_change`` probe (and an ``every_n``
    one, 1) recaptures the faces that changed, which then equal a second engine's built
    with the camera there: a probe keeping them would show the lamp's light, or its
    shadow, for good."""
    before, kept, fresh, drawn = _kept_and_fresh(scene, change, refresh)
    lit = {face for face in range(6) if not np.array_equal(before[face], fresh[face])}
    assert lit and lit <= drawn, (sorted(lit), sorted(drawn))
    assert not _stale_faces(kept, fresh)


# --- a probe that sees a monitor's screen: still frames settle, a loop through a chrome ball does not ---
TOWARDS_SCREEN = 0   # the probe's +X face: the room's screen (``_monitor``) stands 2.5 m that way


def _screen_room(world, refresh="every_frame", ball=False) -> None:
    """The room, its probe (``refresh``) and the screen in its +X face (``_monitor``); with
    ``ball`` the probe's entity is a chrome ball sampling its own cube (what it reflects is
    the room, the screen in it), and the monitor's camera stands 1 m from it, looking at it:
    the picture shows the ball, the ball the picture; with ``ball="box"`` the probe has an
    influence box over the room instead (no ball): the floor the camera looks at is lit by
    its irradiance row, and reflects its cube."""
    from components import Reflective
    from components.transform import look_rotation
    from engine.assets.mesh import sphere

    _room_with_probe(world)
    _monitor(world)
    # (The box the monitor watches casts no shadow: its move reaches the probe only through
    # the screen, not through a shadow swept along the sun to the floor's edge.)
    world.get(world.resources["subject"], MeshRef).casts_shadows = False
    probe = world.resources["probe"]
    world.get(probe, ReflectionProbe).refresh = refresh
    if ball == "box":
        world.get(probe, ReflectionProbe).influence = (8.0, 4.0, 8.0)
    elif ball:
        for component in (MeshRef(sphere(0.3, 16, 8)), Material(color=(1, 1, 1), metallic=1.0, roughness=0.0),
                          Reflective(mode="cube")):
            world.add_component(probe, component)
    if ball:
        lens = world.get(world.resources["lens"], Transform)
        lens.position = glm.vec3(0.9, 0.7, 0.5)
        lens.rotation = look_rotation(glm.vec3(0.0, 0.6, 0.0) - lens.position)


def _two_screen_rooms(scene, refresh="every_frame", ball=False, change=None):
    """Two engines of ``_screen_room``: the first keeps still pictures, the second draws every
    due picture (``keep_still_pictures`` False: each frame's picture drawn afresh, what the
    first must equal).  ``change`` (a world's edit) is made in both before their first frame."""
    runners = []
    for keep in (True, False):
        def build(world):
            _screen_room(world, refresh, ball)
            if change is not None:
                change(world)
        runner = scene(build, (48, 32))
        _probe_stage(runner).path = "six_pass"
        runner.engine.stages["monitors"].keep_still_pictures = keep
        runners.append(runner)
    return runners


def _frame_counts(runner) -> tuple[int, int, int]:
    """One frame; (probe faces drawn, monitor views drawn, how far the scene's version moved)."""
    before = runner.engine.renderer.scene_version
    runner.frame()
    return runner.stats.probe_faces, runner.stats.monitor_views, runner.engine.renderer.scene_version - before


def _picture_and_faces(runner) -> list[np.ndarray]:
    return [runner.engine.renderer.monitors.read(runner.world.resources["screen"]), *_cube_faces(runner)]


def _assert_same(runner, other, what) -> None:
    for index, (a, b) in enumerate(zip(_picture_and_faces(runner), _picture_and_faces(other), strict=True)):
        np.testing.assert_array_equal(a, b, err_msg=f"{what}: {'the picture' if index == 0 else f'face {index - 1}'}")


def test_an_every_frame_probe_seeing_a_screen_draws_nothing_once_both_settled(scene):
    """An every-frame probe whose +X face shows a monitor's screen; the monitor's camera, 30 m
    away, sees nothing that samples the probe (a plain floor, a box: a probe with no
    influence box lights neither).  Frame 0 captures the screen black and draws the
    picture; frame 1 recaptures the face showing it; from frame 2 on nothing is drawn, the
    scene's version stands, the picture is kept.  (Before, each capture moved the version
    the picture's stillness was judged by, so it was drawn again, and the face showing the
    new picture too: a face and a picture every frame, the version 2 on.)  Every frame the
    picture and the six faces are, bit for bit, those of an engine that draws every due
    picture afresh; the face shows the picture (the subject's green)."""
    runner, afresh = _two_screen_rooms(scene)
    counts = []
    for frame in range(5):
        counts.append(_frame_counts(runner))
        afresh.frame()
        _assert_same(runner, afresh, f"frame {frame}")
        assert afresh.stats.monitor_views == 1   # (the other draws it every frame)
    assert [faces for faces, _, _ in counts[2:]] == [0, 0, 0], counts
    assert [views for _, views, _ in counts[2:]] == [0, 0, 0], counts
    assert [moved for _, _, moved in counts[2:]] == [0, 0, 0], counts
    assert runner.stats.monitors_kept == 1
    face = _cube_faces(runner)[TOWARDS_SCREEN]
    assert ((face[..., 1] > 2.0 * face[..., 0]) & (face[..., 1] > 0.02)).sum() > 3   # the subject's green
    assert _Cube(runner).as_if_drawn_whole()


@pytest.mark.parametrize("change", ["lens_turned", "subject_moved"])
def test_a_settled_screen_whose_picture_changes_redraws_the_face_showing_it_as_a_fresh_engine(scene, change):
    """The settled scene of the test above; then the monitor's camera turns (or the box it
    watches moves, down and towards it: within the level's box, so the sun's map is fitted
    as a fresh engine's, ``level_fit_box``; both 30 m out of the probe's reach).
    That frame the picture is drawn again, and the probe's face showing the screen with it,
    that face alone, after present (its record holds the picture's version): the next frame
    samples it.  The frame after, the scheduler hears of the picture and draws the faces the
    screen's box (and its shadow) may reach as they are; then nothing is drawn again.  The
    picture and all six faces are then, bit for bit, those of a second engine built with
    the change made (run as many frames), and the face differs from what it showed before."""
    def edit(world):
        if change == "lens_turned":
            world.get(world.resources["lens"], Transform).rotation = glm.angleAxis(0.12, glm.vec3(0, 1, 0))
        else:
            world.get(world.resources["subject"], Transform).position += glm.vec3(0.0, -0.2, 0.6)

    runner = _two_screen_rooms(scene)[0]
    for _ in range(4):
        runner.frame()
    before = _cube_faces(runner)[TOWARDS_SCREEN]
    drawn = _faces_drawn(_Cube(runner))
    edit(runner.world)
    counts = [_frame_counts(runner)]
    assert counts[0][:2] == (1, 1) and drawn == [TOWARDS_SCREEN], (counts, drawn)
    counts += [_frame_counts(runner) for _ in range(2)]
    # (The frame after, the scheduler hears of the picture (``PicturesDrawn``) and counts the
    # screen's box as a look changed: the faces it and its shadow may reach are drawn again,
    # as they were; the picture is kept.  Then nothing.)
    assert counts[1][1] == 0 and counts[2][:2] == (0, 0), counts
    fresh = _two_screen_rooms(scene, change=edit)[0]
    for _ in range(7):
        fresh.frame()
    _assert_same(runner, fresh, change)
    assert not np.array_equal(_cube_faces(runner)[TOWARDS_SCREEN], before)


@pytest.mark.parametrize("refresh", ["every_frame", "on_change"])
@pytest.mark.parametrize("sampler", ["ball", "box"])
def test_a_camera_that_sees_the_probes_reflection_of_its_screen_draws_with_the_probe(scene, refresh, sampler):
    """The probe's entity is a chrome ball that samples its own cube, and the monitor's
    camera looks at the ball, whose +X side reflects the screen: the picture shows the
    probe's capture, the capture shows the picture.  That is a loop, drawn as a camera that
    sees its own screen is (README: each picture shows the one before): an every-frame
    probe's face and the picture draw each other every frame, one face and one picture a
    frame from frame 2 on.  An on-change probe is asked for the face only by a picture
    drawn as a new look of its screen (``PicturesDrawn``), and the picture drawn again for
    the probe's capture alone is none: both settle.  Every frame, bit for bit, the picture
    and the six faces are those of an engine drawing every due picture afresh (a picture
    kept while the probe it shows was recaptured would differ from frame 2 on), and the
    picture did change with the probe (frame 2's is not frame 1's: the ball shows the
    screen's picture).  The same where the probe has an influence box instead and the
    camera looks at the floor in it (the floor's batch samples the box's probe, and its
    irradiance row lights the floor: ``MonitorPictures.probes_read`` follows both)."""
    runner, afresh = _two_screen_rooms(scene, refresh, ball=sampler if sampler == "box" else True)
    counts, pictures = [], []
    for frame in range(6):
        counts.append(_frame_counts(runner))
        afresh.frame()
        _assert_same(runner, afresh, f"frame {frame}")
        pictures.append(_picture_and_faces(runner)[0])
    assert not np.array_equal(pictures[1], pictures[2])
    if refresh == "every_frame":
        assert [count[:2] for count in counts[2:]] == [(1, 1)] * 4, counts
    else:
        assert [count[:2] for count in counts[3:]] == [(0, 0)] * 3, counts
