"""Temporal anti-aliasing (``Renderer.antialias = "taa"``; ``engine/render/temporal_aa.py``,
``shaders/temporal_resolve.frag``): the jitter's offsets against the Halton sequence and the
main view's projection; a still edge settling to the picture drawn four times larger and
averaged down (a second path); a panning camera, a reflection and a moving box reprojected
with no trail against that reference too; a cut starting the history again."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import Camera, Material, MeshRef, Mirror, Transform
from engine.assets.mesh import quad
from engine.render.temporal_aa import JITTER_SAMPLES, halton, jitter_offset
from tests.support import look_from
from tests.test_mirrors import base_scene

SIZE = (96, 72)
SCALE = 4   # the reference is drawn this many times larger and averaged down


def linear(rgb: np.ndarray) -> np.ndarray:
    encoded = rgb.astype(float) / 255.0
    return np.where(encoded <= 0.04045, encoded / 12.92, ((encoded + 0.055) / 1.055) ** 2.4)


def averaged_down(rgb: np.ndarray) -> np.ndarray:
    """A picture SCALE times larger, each SCALE x SCALE block averaged in linear light."""
    h, w = rgb.shape[0] // SCALE, rgb.shape[1] // SCALE
    return linear(rgb).reshape(h, SCALE, w, SCALE, 3).mean(axis=(1, 3))


def edge_scene(world):
    """A white square turned 12 degrees on a dark wall: long slanted edges."""
    base_scene(world)
    look_from(world, (0.0, 1.5, 4.0), (0, 1.5, 0))
    world.spawn(Transform(position=(0, 1.5, -1.0)), MeshRef(quad(20, 20)), Material(color=(0.05, 0.05, 0.05)))
    world.spawn(Transform(position=(0.2, 1.5, 0.0), rotation=glm.angleAxis(glm.radians(12.0), glm.vec3(0, 0, 1))),
                MeshRef(quad(1.6, 1.6)), Material(color=(1.0, 1.0, 1.0)))


def runs(scene, build, mode: str, size=SIZE, scale: float = 1.0):
    runner = scene(build, size)
    runner.engine.renderer.antialias = mode
    runner.engine.renderer.render_scale = scale
    return runner


def test_the_offsets_are_the_halton_points_and_move_the_main_projection(scene):
    """Eight offsets, each the Halton (2, 3) point less a half pixel, all within the pixel and
    apart; the main view's projection is the camera's moved by the frame's offset."""
    offsets = [jitter_offset(frame, SIZE) for frame in range(JITTER_SAMPLES)]
    assert len(set(offsets)) == JITTER_SAMPLES and jitter_offset(JITTER_SAMPLES, SIZE) == offsets[0]
    for frame, (x, y) in enumerate(offsets):
        assert x * SIZE[0] / 2.0 == pytest.approx(halton(frame + 1, 2) - 0.5)
        assert y * SIZE[1] / 2.0 == pytest.approx(halton(frame + 1, 3) - 0.5)
        assert abs(x * SIZE[0] / 2.0) < 0.5 and abs(y * SIZE[1] / 2.0) < 0.5
    assert [halton(i, 2) for i in (1, 2, 3, 4)] == [0.5, 0.25, 0.75, 0.125]
    plain, jittered = runs(scene, edge_scene, "off"), runs(scene, edge_scene, "taa")
    for _ in range(3):
        plain.frame()
        jittered.frame()
    x, y = jitter_offset(2, SIZE)
    moved = glm.translate(glm.vec3(x, y, 0.0)) * plain.engine.main_view.proj
    for column in range(4):
        np.testing.assert_allclose(list(jittered.engine.main_view.proj[column]), list(moved[column]), atol=1e-6)


def test_a_still_edge_settles_to_the_picture_drawn_larger_and_averaged_down(scene):
    """Sixteen frames of a still camera: the slanted edges' pixels hold their coverage, as the
    picture drawn four times larger and averaged down has them, much nearer than a frame
    without anti-aliasing (and nearer than FXAA's)."""
    reference = averaged_down(runs(scene, edge_scene, "off", (SIZE[0] * SCALE, SIZE[1] * SCALE)).frame())
    errors = {}
    for mode in ("off", "fxaa", "taa"):
        runner = runs(scene, edge_scene, mode)
        for _ in range(16):
            picture = runner.frame()
        errors[mode] = np.abs(linear(picture) - reference)
    edges = errors["off"].max(axis=2) > 0.05   # (where drawing larger changes anything)
    assert edges.sum() > 40
    mean = {mode: float(error[edges].mean()) for mode, error in errors.items()}
    assert mean["taa"] < 0.5 * mean["off"] and mean["taa"] < mean["fxaa"], mean


def bright_centre(picture: np.ndarray) -> tuple[float, float]:
    """The centre of the picture's light above the dark wall's (linear), in pixels."""
    weight = np.clip(picture.mean(axis=2) - 0.1, 0.0, None)
    rows, columns = np.indices(weight.shape)
    return float((weight * columns).sum() / weight.sum()), float((weight * rows).sum() / weight.sum())


def mirrored_square(world):
    """The white square behind the camera, seen only in a mirror before it."""
    base_scene(world)
    look_from(world, (0.0, 1.5, 3.0), (0, 1.5, 0))
    world.spawn(Transform(position=(0, 1.5, -0.5)), MeshRef(quad(20, 20)), Material(color=(0.05, 0.05, 0.05)))
    world.spawn(Transform(position=(0, 1.5, 0.0)), MeshRef(quad(3.0, 2.4)), Material(color=(0.05, 0.05, 0.05)),
                Mirror())
    world.spawn(Transform(position=(0.2, 1.5, 6.0), rotation=glm.angleAxis(glm.radians(180.0), glm.vec3(0, 1, 0))
                          * glm.angleAxis(glm.radians(12.0), glm.vec3(0, 0, 1))),
                MeshRef(quad(1.6, 1.6)), Material(color=(1.0, 1.0, 1.0)))


@pytest.mark.parametrize("scale", [1.0, 0.5])
@pytest.mark.parametrize(("build", "moving"), [(edge_scene, "camera"), (edge_scene, "square"),
                                               (mirrored_square, "camera")])
def test_reprojected_history_follows_what_moves_and_leaves_no_trail(scene, build, moving, scale):
    """Sixteen frames of the camera panning (or the square sliding; or the camera panning
    before a mirror that shows the square behind it): the resolved square stands where the
    picture drawn four times larger and averaged down has it (its light's centre within a
    third of a pixel: the history fetched where each point was, by the light's way through the
    mirror and the thing's own motion), as near that picture as a still frame's is; nothing
    of it stays where it was eight frames ago.  At half scale too (temporal upsampling: the
    history the output's size, each frame's samples half as many a side)."""
    def run(mode: str, size: tuple[int, int], scale: float = 1.0) -> list[np.ndarray]:
        runner = runs(scene, build, mode, size, scale)
        camera = next(entity for entity, _ in runner.world.query_one(Camera))
        square = max(entity for entity, (_, material) in runner.world.query(MeshRef, Material)
                     if material.color[0] == 1.0)
        runner.frame()
        pictures = []
        for _ in range(16):
            if moving == "camera":
                runner.world.get(camera, Transform).position += glm.vec3(0.05, 0.0, 0.0)
            else:
                runner.world.get(square, Transform).position += glm.vec3(0.05, 0.0, 0.0)
            pictures.append(runner.frame())
        return pictures

    resolved = linear(run("taa", SIZE, scale)[-1])
    references = [averaged_down(picture) for picture in run("off", (SIZE[0] * SCALE, SIZE[1] * SCALE))[-9::8]]
    reference = references[-1]
    found, wanted = bright_centre(resolved), bright_centre(reference)
    assert abs(found[0] - wanted[0]) < 0.35 and abs(found[1] - wanted[1]) < 0.35, (found, wanted)
    error = np.abs(resolved - reference)
    assert error.mean() < 0.01, error.mean()
    # Where the square was eight frames ago and is not now (two pixels clear of it): no white left.
    now = np.pad(reference.mean(axis=2) > 0.2, 2)
    near = np.zeros(reference.shape[:2], bool)
    for dy in range(5):
        for dx in range(5):
            near |= now[dy: dy + near.shape[0], dx: dx + near.shape[1]]
    trail = (references[0].mean(axis=2) > 0.2) & ~near
    assert trail.sum() > 10
    assert error.max(axis=2)[trail].max() < 0.05, error.max(axis=2)[trail].max()


def test_a_cut_starts_the_history_again(scene):
    """Another camera made the active one: the next frame is the new view alone, with
    nothing of the old one's history in it (as a first frame is)."""
    ents = {}

    def build(world):
        edge_scene(world)
        ents["camera"] = next(entity for entity, _ in world.query_one(Camera))
        ents["other"] = world.spawn(Transform(position=(3.0, 1.5, 3.0)), Camera(active=False))

    runner = runs(scene, build, "taa")
    for _ in range(4):
        runner.frame()
    assert runner.engine.renderer.present_pass.temporal.resolved == 4
    runner.world.get(ents["camera"], Camera).active = False
    runner.world.get(ents["other"], Camera).active = True
    runner.frame()
    assert runner.engine.renderer.present_pass.temporal.resolved == 1
    runner.engine.renderer.antialias = "off"
    runner.frame()
    assert runner.engine.renderer.present_pass.temporal.target_count() == 0


def test_the_offsets_are_not_motion_to_the_motion_blur(scene):
    """A still camera with motion blur under temporal AA: the frames' sub-pixel offsets are
    not motion, so no motion blur pass is drawn (the resolve's is the one post pass)."""
    from components import MotionBlur

    def build(world):
        edge_scene(world)
        camera = next(entity for entity, _ in world.query_one(Camera))
        world.add_component(camera, MotionBlur(shutter=1.0))

    runner = runs(scene, build, "taa")
    for _ in range(4):
        runner.frame()
        present = runner.engine.renderer.present_pass
        assert present.motion_blur.passes == 0 and present.post_passes == 1


def spark_stream(world, sparks: bool = True):
    """Bright additive sparks flying across a dark wall, 6 m/s, about 2 px a frame at 96x72
    (``sparks`` False: the wall alone)."""
    from components import ParticleEmitter

    base_scene(world)
    look_from(world, (0.0, 1.5, 4.0), (0, 1.5, 0))
    world.spawn(Transform(position=(0, 1.5, -1.0)), MeshRef(quad(20, 20)), Material(color=(0.05, 0.05, 0.05)))
    if sparks:
        world.spawn(Transform(position=(-2.0, 1.5, 0.0)),
                    ParticleEmitter(rate=40.0, speed=6.0, spread=0.0, direction=(1.0, 0.0, 0.0), lifetime=0.7,
                                    size=0.12, color=(4.0, 3.0, 1.0, 1.0), blend="additive", angle=(0.0, 0.0)))


def mirrored_sparks(world, sparks: bool = True):
    """The same sparks flying behind the camera, seen only in a mirror before it."""
    from components import ParticleEmitter

    base_scene(world)
    look_from(world, (0.0, 1.5, 3.0), (0, 1.5, 0))
    world.spawn(Transform(position=(0, 1.5, -0.5)), MeshRef(quad(20, 20)), Material(color=(0.05, 0.05, 0.05)))
    world.spawn(Transform(position=(0, 1.5, 0.0)), MeshRef(quad(3.6, 2.4)), Material(color=(0.05, 0.05, 0.05)),
                Mirror())
    world.spawn(Transform(position=(0, 1.5, 6.0), rotation=glm.angleAxis(glm.radians(180.0), glm.vec3(0, 1, 0))),
                MeshRef(quad(20, 20)), Material(color=(0.05, 0.05, 0.05)))
    if sparks:
        world.spawn(Transform(position=(-2.0, 1.5, 5.0)),
                    ParticleEmitter(rate=40.0, speed=6.0, spread=0.0, direction=(1.0, 0.0, 0.0), lifetime=0.7,
                                    size=0.2, color=(4.0, 3.0, 1.0, 1.0), blend="additive", angle=(0.0, 0.0)))


@pytest.mark.parametrize(("build", "scale"), [(spark_stream, 1.0), (spark_stream, 0.5), (mirrored_sparks, 1.0)],
                         ids=["seen", "seen_half", "in_a_mirror"])
def test_particles_keep_their_light_through_the_reactive_mask(scene, build, scale):
    """Particles write no motion, so their history is fetched from where the wall behind them
    was: the reactive mask (the main view's particles drawn again, how much each changes its
    pixel) gives this frame most of those pixels.  Twenty frames of fast sparks: the light they
    add to the wall is most of what a frame without anti-aliasing shows (at half scale too; and
    sparks seen only in a mirror, whose level's particles are drawn into the mask too, seen
    through the glass); with no live particle no mask is made."""
    def picture(mode: str, sparks: bool, scale: float = 1.0) -> np.ndarray:
        runner = runs(scene, lambda world: build(world, sparks), mode, SIZE, scale)
        for _ in range(20):
            frame = linear(runner.frame())
        assert (runner.engine.renderer.present_pass.temporal._reactive is not None) == (mode == "taa" and sparks)
        return frame

    wall = picture("off", False)
    shown = float(np.clip(picture("off", True) - wall, 0.0, None).sum())
    resolved = float(np.clip(picture("taa", True, scale) - wall, 0.0, None).sum())
    assert shown > 5.0 and resolved > 0.75 * shown, (resolved, shown)
    picture("taa", False)   # (no particle: no mask)


def portal_square(world, scale: float) -> dict:
    """The camera before portal a (3 x 2.4 m, on a dark wall); its partner b 20 m off, ``scale``
    times a's size; the white square turned 12 degrees before b and a dark wall behind it, both
    ``scale`` times as large and far, so the picture through a is the same at either scale."""
    from engine.assets.portals import spawn_portal_pair

    base_scene(world)
    look_from(world, (0.0, 1.5, 3.0), (0, 1.5, 0))
    world.spawn(Transform(position=(0, 1.5, -0.5)), MeshRef(quad(20, 20)), Material(color=(0.05, 0.05, 0.05)))
    a, b = spawn_portal_pair(world, (0, 1.5, 0), None, (20, 1.5, 0), None, size=(3.0, 2.4))
    ents = {"a": a, "b": b}
    world.get(ents["b"], Transform).scale = glm.vec3(scale)
    facing = glm.angleAxis(glm.radians(180.0), glm.vec3(0, 1, 0))
    world.spawn(Transform(position=(20, 1.5, 6.0 * scale), rotation=facing), MeshRef(quad(40 * scale, 40 * scale)),
                Material(color=(0.05, 0.05, 0.05)))
    ents["square"] = world.spawn(Transform(position=(20 + 0.2 * scale, 1.5, 2.5 * scale), scale=glm.vec3(scale),
                                           rotation=facing * glm.angleAxis(glm.radians(12.0), glm.vec3(0, 0, 1))),
                                 MeshRef(quad(1.6, 1.6)), Material(color=(1.0, 1.0, 1.0)))
    return ents


@pytest.mark.parametrize("scale", [1.0, 2.0])
@pytest.mark.parametrize("moving", ["near", "far", "camera"])
def test_a_still_square_through_a_moving_or_scaled_portal_settles_sharp_where_it_stands(scene, moving, scale):
    """Sixteen frames of portal a sliding 5 cm a frame (or its partner b, by 5 cm x its scale;
    or the camera panning) with the square still beyond the pair (about 0.9 px a frame on the
    picture): round the square's image the resolved picture is near the picture of the same
    pose drawn four times larger without anti-aliasing and averaged down, nearer than a plain
    frame (its history fetched where the pair showed each point last frame: with the pair's
    motion left out of the composite the edges smear, mean error 0.036, 90th percentile 0.16;
    and through the pair scaled 2, by the image's distance: by the carried eye's, 0.024 /
    0.092).  The motion the picture holds at the square's pixels is the image's own, cast here
    in float64: the image moved by the change of the pair's carry (inverse(carry) of the square's
    points, the same shift for each point), projected this frame; none when only the camera moves."""
    from engine.core.portal_math import pair_transform
    from tests.support import pixel_rays

    def run(mode: str, size: tuple[int, int]):
        ents = {}
        runner = runs(scene, lambda world: ents.update(portal_square(world, scale)), mode, size)
        camera = next(entity for entity, _ in runner.world.query_one(Camera))
        thing = {"near": ents["a"], "far": ents["b"], "camera": camera}[moving]
        step = glm.vec3(0.05 * (scale if moving == "far" else 1.0), 0.0, 0.0)
        runner.frame()
        for _ in range(16):
            carry = pair_transform(*(runner.world.get(ents[name], Transform).world for name in "ab"))
            runner.world.get(thing, Transform).position += step
            picture = runner.frame()
        return runner, ents, picture, carry

    large, ents, picture, _ = run("off", (SIZE[0] * SCALE, SIZE[1] * SCALE))
    reference = averaged_down(picture)
    covered = np.pad((large.ids() == ents["square"]).reshape(SIZE[1], SCALE, SIZE[0], SCALE).any(axis=(1, 3)), 2)
    near = np.zeros(reference.shape[:2], bool)   # the square's pixels and two round them
    for dy in range(5):
        for dx in range(5):
            near |= covered[dy: dy + near.shape[0], dx: dx + near.shape[1]]
    assert 300 < near.sum() < 900
    assert reference[covered[2:-2, 2:-2]].mean() > 0.3   # (the square is seen through the pair, white)
    _, _, plain, _ = run("off", SIZE)
    runner, ents, resolved, before = run("taa", SIZE)
    error = np.abs(linear(resolved) - reference).max(axis=2)[near]
    plain_error = np.abs(linear(plain) - reference).max(axis=2)[near]
    assert error.mean() < 0.018 and np.percentile(error, 90) < 0.05, (error.mean(), np.percentile(error, 90))
    assert error.mean() < 0.8 * plain_error.mean(), (error.mean(), plain_error.mean())
    # The square's own motion on the picture this last frame, against its image's cast here.
    now = pair_transform(*(runner.world.get(ents[name], Transform).world for name in "ab"))
    to_image = [np.array(glm.dmat4(glm.inverse(carry)).to_list(), np.float64).T for carry in (now, before)]
    shift = (to_image[0] - to_image[1])[:3, 3]   # (the same linear part: one shift for every point)
    assert (np.abs(to_image[0][:3, :3] - to_image[1][:3, :3]).max() < 1e-6
            and (np.linalg.norm(shift) > 0.04) == (moving != "camera"))
    square = np.array(glm.dmat4(runner.world.get(ents["square"], Transform).world).to_list(), np.float64).T
    image = to_image[0] @ square   # the square's image now, its plane z = 0 in its own frame
    normal, point = np.linalg.inv(image[:3, :3]).T @ (0.0, 0.0, 1.0), image[:3, 3]
    eye, direction = pixel_rays(runner.engine.main_view, SIZE)
    at = eye + direction * (((point - eye) @ normal) / (direction @ normal))[..., None]
    view_proj = np.array(glm.dmat4(runner.engine.main_view.view_proj).to_list(), np.float64).T

    def on_picture(points):
        clip = np.c_[points, np.ones(len(points))] @ view_proj.T
        return clip[:, :2] / clip[:, 3:] * 0.5

    shown = (runner.ids() == ents["square"])
    shown[[0, -1]] = shown[:, [0, -1]] = False
    assert shown.sum() > 100
    expected = on_picture(at[shown]) - on_picture(at[shown] - shift)   # picture widths and heights, y up
    motion = runner.engine.renderer.targets.read_motion()[shown]
    if moving != "camera":
        assert np.abs(expected[:, 0] * SIZE[0]).min() > 0.5
    np.testing.assert_allclose(motion * SIZE, expected * SIZE, atol=0.03)
