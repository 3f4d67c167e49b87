"""Targeted tests for changes that used to pass the suite or be caught by a golden frame
only (issue 26 item 10).  Each asserts a fact worked out apart from the code under test:
by math, by a second path, by entity ids or by which pixels a rule must touch.  Each
docstring's last line is the change the test was checked against ("Fails when ...")."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

import engine.render.shader_library as shader_library
from components import (
    DirectionalLight,
    Emissive,
    Material,
    MeshRef,
    Mirror,
    ReflectionProbe,
    Reflective,
    Skybox,
    Transform,
)
from components.ambient import DEFAULT_GROUND, DEFAULT_SKY
from engine.assets.level_file import load_level
from engine.assets.mesh import box, plane, quad, sphere
from tests import test_hot_reload
from tests.support import linear_to_srgb8, look_from, srgb_to_linear


def yaw(degrees: float) -> glm.quat:
    return glm.angleAxis(glm.radians(degrees), glm.vec3(0, 1, 0))


# --- 1. the batched mirror path keeps each object's tint ------------------------------------------

def tinted_in_mirrors(ents):
    """Two mirrors side by side (one level of two views) and, behind the camera (seen only
    in the mirrors), a chrome sphere tinted red and a half-glazed box tinted green
    (Reflective.tint)."""
    def build(world):
        world.spawn(Skybox())
        world.spawn(DirectionalLight(direction=(0.3, -1.0, -0.4), intensity=2.0))
        look_from(world, (0.0, 1.5, 0.0), target=(0.0, 1.4, -4.0), fov=60.0)
        ents["mirrors"] = [world.spawn(Transform(position=(x, 1.4, -4.0)), MeshRef(quad(2.3, 2.6)),
                                       Material(color=(0.1, 0.1, 0.1)), Mirror()) for x in (-1.2, 1.2)]
        ents["chrome"] = world.spawn(Transform(position=(-0.7, 1.4, 1.5)), MeshRef(sphere(0.7, 16, 8)),
                                     Material(color=(1.0, 1.0, 1.0), metallic=1.0, roughness=0.0),
                                     Reflective("skybox", tint=(1.0, 0.2, 0.2)))
        ents["glazed"] = world.spawn(Transform(position=(0.8, 1.4, 1.5), rotation=yaw(30), scale=(1.0, 1.0, 1.0)),
                                     MeshRef(box()), Material(color=(0.2, 0.2, 0.8)),
                                     Reflective("skybox", mix=0.7, tint=(0.2, 1.0, 0.3)))
    return build


def test_the_batched_path_draws_tinted_objects_in_mirrors_as_the_per_mirror_path_does(scene):
    """The same scene by both reflection paths: where a mirror shows a tinted object, the
    two frames agree pixel for pixel (and the tint shows: the chrome is red in the mirror).
    Fails when the batched build drops the tint (v_tint = vec4(1.0) after in_tint's under
    scene.vert's INSTANCED_VIEWS; a geometry shader once did)."""
    ents = {}
    frames = {}
    for path in ("per_mirror", "batched"):
        runner = scene(tinted_in_mirrors(ents), (200, 150))
        runner.engine.reflection_system.path = path
        rgb = runner.frame()
        assert runner.stats.reflection_path == path and runner.stats.reflection_views == 2
        frames[path] = (rgb.astype(int), runner.ids(), runner.engine.renderer.targets.read_surface_ids())
    (a, ids_a, surface_a), (b, ids_b, surface_b) = frames["per_mirror"], frames["batched"]
    in_mirrors = np.isin(surface_a, ents["mirrors"]) & np.isin(surface_b, ents["mirrors"])
    for name in ("chrome", "glazed"):
        seen = in_mirrors & (ids_a == ents[name]) & (ids_b == ents[name])
        assert seen.sum() > 150, (name, seen.sum())  # the object is reflected, by both paths
        diff = np.abs(a[seen] - b[seen])
        assert np.percentile(diff, 99) <= 2 and diff.mean() < 0.5, (name, np.percentile(diff, 99), diff.mean())
    chrome = srgb_to_linear(b[in_mirrors & (ids_b == ents["chrome"])])
    assert np.median(chrome[:, 0] - chrome[:, 1]) > 0.1  # the red tint is in the reflection


# --- 2. time slicing captures the faces that wait, one a frame -----------------------------------

SENTINEL = 1234.0
FACE_AXES = [np.array(a, float) for a in ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1))]


def faces_seeing(points: np.ndarray) -> set[int]:
    """GL cube faces (+X, -X, +Y, -Y, +Z, -Z) whose pyramid from the origin holds some of
    ``points``: the face of a direction is its largest component's axis and sign."""
    axis = np.argmax(np.abs(points), axis=1)
    negative = points[np.arange(len(points)), axis] < 0
    return set((2 * axis + negative).tolist())


def wall_points(z_offset: float) -> np.ndarray:
    """Points all over the 12 x 12 m wall at x = 1.6 (y, z in [-6, 6] + z_offset)."""
    y, z = np.meshgrid(np.linspace(-6, 6, 49), np.linspace(-6, 6, 49) + z_offset)
    return np.stack([np.full(y.size, 1.6), y.ravel(), z.ravel()], axis=1)


def test_time_slicing_captures_a_waiting_face_each_frame_and_every_face_that_saw_the_change(scene):
    """A probe at the origin, time-sliced; a wall beside it moves.  Every face whose pyramid
    saw the wall before or after the move (worked out here from the wall's points) must be
    recaptured, one a frame.  Which face a frame drew is read from the cube itself: every
    face is set to a sentinel before the frame, and the face drawn is the one that lost it.
    Each frame's face must be one that was waiting (it leaves the pending set that frame).
    Fails when capture_due (systems/probe_system.py) draws {(f + 1) % 6} while retiring face f."""
    ents = {}

    def build(world):
        world.spawn(Skybox())
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.4)))
        look_from(world, (0.0, 0.0, 4.0), target=(0.0, 0.0, 0.0), fov=40.0)
        ents["sphere"] = world.spawn(Transform(), MeshRef(sphere(0.6, 16, 8)),
                                     Material(color=(1, 1, 1), metallic=1.0, roughness=0.0), Reflective("cube"),
                                     ReflectionProbe(resolution=16, time_slicing="one_face_per_frame"))
        ents["wall"] = world.spawn(Transform(position=(1.6, 0.0, 0.0), rotation=yaw(-90)), MeshRef(quad(12, 12)),
                                   Material(color=(0.9, 0.05, 0.05)), Emissive(1.5))

    runner = scene(build, (48, 36))
    runner.engine.stages["probes"].path = "six_pass"
    runner.frame()
    state = runner.engine.stages["probes"].probes[ents["sphere"]]
    probes = runner.engine.renderer.probes
    cube = probes.cubes[ents["sphere"]]
    assert state.faces_captured == 6 and not state.pending  # a whole first capture

    must = faces_seeing(wall_points(0.0)) | faces_seeing(wall_points(0.3))
    assert must == {0, 2, 3, 4, 5}  # every face but -X sees the wall
    runner.world.get(ents["wall"], Transform).position = (1.6, 0.0, 0.3)
    drawn = []
    for _ in range(8):
        for face in range(6):
            cube.texture.write(face, np.full((16, 16, 4), SENTINEL, np.float16).tobytes())
        probes.written_elsewhere(ents["sphere"])  # else a face of sky alone is kept, holding the sentinel
        pending_before = set(state.pending)
        runner.frame()
        written = [face for face in range(6) if not (probes.read_face(ents["sphere"], face) == SENTINEL).all()]
        assert len(written) <= 1, written  # one face a frame
        if not written:
            break
        (face,) = written
        # The face drawn was waiting (from before this frame, or scheduled by it) and is no longer.
        assert face not in state.pending, (face, state.pending)
        assert face in pending_before | must, (face, pending_before)
        drawn.append(face)
    assert not state.pending and len(drawn) == len(set(drawn))
    assert must <= set(drawn), (drawn, must)


# --- 3. a relink that fails is rolled back --------------------------------------------------------

shader_copy = test_hot_reload.shader_copy  # the fixture: a copy of shaders/ the engine reads


def test_a_relink_that_cannot_keep_the_vertex_inputs_leaves_the_old_program_drawing(scene, shader_copy):
    """An edit that builds on its own but cannot be relinked in place: ``in_slots`` (at
    location 15, the last) becomes a two-slot array, both slots read (a driver drops an
    array slot nothing reads: NVIDIA's linked the edit when only the first was), one other
    input goes so the count stays 16; bound at 15 it needs location 16, so the relink fails.  Every scene program must
    then be the old one again: same uniforms, blocks and samplers, the same frame.
    Fails when _swap_in's except branch skips _locate/_restore, or relink() skips re-attaching the old shaders."""
    runner = scene(test_hot_reload.room, (96, 72))
    library = runner.engine.renderer.shaders
    first = runner.frame()
    assert np.array_equal(runner.frame(), first)  # a still scene repeats exactly
    program = library.program("scene.vert", "scene.frag")
    if program._attribute_locations.get("in_slots") != 15:  # where llvmpipe puts it; drivers choose
        pytest.skip(f"this driver put in_slots at {program._attribute_locations.get('in_slots')}, not the last "
                    f"location: the edit below would not make the relink fail")

    path = shader_copy / "scene.vert"
    text = path.read_text()
    edits = [("in uvec4 in_slots;", "in uvec4 in_slots[2];"), ("in vec4 in_reflect;", ""),
             ("v_reflect = in_reflect;", "v_reflect = vec4(0.0);"),
             ("v_slots = in_slots;", "v_slots = in_slots[0] ^ in_slots[1];"),
             ("in_slots.w == camera", "in_slots[0].w == camera")]
    for old, new in edits:
        assert text.count(old) >= 1, old
        text = text.replace(old, new)
    path.write_text(text)
    scene_programs = [key for key in library._programs if key[0] == "scene.vert"]
    vertex, fragment, geometry, defines = scene_programs[0]
    fresh = shader_library.ShaderLibrary(runner.ctx)
    try:
        fresh.program(vertex, fragment, geometry, dict(defines))  # the edit builds as a new program
    finally:
        fresh.release()

    messages = library.poll(now=1000.0)
    assert len(messages) == 1 and "could not keep its vertex inputs" in messages[0], messages
    assert set(library.errors) == set(scene_programs)
    assert library.program("scene.vert", "scene.frag") is program
    assert runner.ctx.error == "GL_NO_ERROR"
    assert np.array_equal(runner.frame(), first), "the old programs must keep drawing the same frame"


# --- 4. a level file's parent ---------------------------------------------------------------------

PARENT_LEVEL = """
[level]
name = "parent and child"

[[entity]]
name = "camera"
[entity.Transform]
position = [0.0, 3.0, 9.0]
rotation = { look = [0.0, -0.25, -1.0] }
[entity.Camera]
fov_y = 60.0

[[entity]]
name = "base"
[entity.Transform]
position = [-1.5, 0.5, 0.0]
rotation = [0.70710677, 0.0, 0.70710677, 0.0]   # 90 degrees about +Y
scale = [2.0, 1.0, 2.0]
[entity.MeshRef]
mesh = { box = [0.6, 0.6, 0.6] }
[entity.Material]
color = [0.8, 0.1, 0.1]
[entity.Emissive]

[[entity]]
name = "arm"
[entity.Transform]
position = [1.0, 1.0, 0.0]   # in base's frame
parent = "base"
[entity.MeshRef]
mesh = { box = [0.5, 0.5, 0.5] }
[entity.Material]
color = [0.1, 0.8, 0.1]
[entity.Emissive]
"""


def test_a_level_files_child_is_placed_and_moved_by_its_parent(scene, tmp_path):
    """The child's world position is the parent's translation + rotation x scale x its own
    position, worked out by hand: (1, 1, 0) scaled by (2, 1, 2) and turned 90 degrees about
    +Y is (0, 1, -2).  The child's id is where that point projects, not where its own
    position would put it; and when the parent moves, the child goes with it.
    Fails when Level.spawn skips the Transform.parent reference, or TransformSystem links every entity as a root."""
    path = tmp_path / "parent.toml"
    path.write_text(PARENT_LEVEL)
    names = {}

    def build(world):
        names.update(load_level(path).spawn(world))

    runner = scene(build, (160, 120))
    runner.frame()
    world = runner.world
    arm = names["arm"]
    expected = np.array([-1.5, 0.5, 0.0]) + np.array([0.0, 1.0, -2.0])
    ids = runner.ids()
    col, row = runner.project(tuple(expected))
    assert ids[row, col] == arm
    np.testing.assert_allclose(np.array(world.get(arm, Transform).world[3].xyz), expected, atol=1e-5)
    col, row = runner.project((1.0, 1.0, 0.0))  # where the child would be without its parent
    assert ids[row, col] != arm

    world.get(names["base"], Transform).position = (1.0, 0.5, -1.0)
    runner.frame()
    expected = np.array([1.0, 0.5, -1.0]) + np.array([0.0, 1.0, -2.0])
    np.testing.assert_allclose(np.array(world.get(arm, Transform).world[3].xyz), expected, atol=1e-5)
    col, row = runner.project(tuple(expected))
    assert runner.ids()[row, col] == arm
    assert world.get(arm, Transform).parent == names["base"]


# --- 5. a mirror's tint is applied once -----------------------------------------------------------

def test_a_tinted_mirror_shows_tint_times_what_it_reflects(scene):
    """A sharp mirror seen head-on reflects an emissive wall behind the camera.  With no
    light, the wall's radiance is albedo x (power + ambient), the ambient of a wall facing
    sideways under the default hemisphere the mean of its sky and ground; at normal incidence the mirror's
    Fresnel term is its tint and GGX's visibility is 1, so the mirror's pixel is
    tint x albedo x (power + ambient), encoded to sRGB.
    Fails when mirror_composite.frag multiplies the reflection by v_tint.rgb a second time."""
    tint, albedo, power = np.array([0.5, 0.8, 1.0]), np.array([0.8, 0.6, 0.4]), 1.0

    def build(world):
        look_from(world, (0.0, 1.5, 4.0), target=(0.0, 1.5, -2.0))
        world.spawn(Transform(position=(0, 1.5, 6.0), scale=(12, 12, 0.1)), MeshRef(box()),
                    Material(color=tuple(albedo)), Emissive(power))  # behind the camera
        world.spawn(Transform(position=(0, 1.5, -2.0)), MeshRef(quad(4, 3)), Material(color=(0.1, 0.1, 0.1)),
                    Mirror(color=tuple(tint)))

    runner = scene(build, (96, 72))
    rgb = runner.frame()
    col, row = runner.project((0.0, 1.5, -2.0))
    patch = rgb[row - 4:row + 5, col - 4:col + 5].reshape(-1, 3).astype(float)  # within 3 degrees of the normal
    ambient = (np.array(DEFAULT_SKY) + np.array(DEFAULT_GROUND)) / 2
    expected = linear_to_srgb8(tint * albedo * (power + ambient))
    np.testing.assert_allclose(patch, np.broadcast_to(expected, patch.shape), atol=1.5)


# --- 6. FXAA's edge threshold ---------------------------------------------------------------------

EDGE_THRESHOLD, EDGE_THRESHOLD_MIN = 0.125, 0.0625  # fxaa.frag's constants, as FXAA 3.11 sets them
LUMA = np.array([0.299, 0.587, 0.114])


def grey_card_on_grey(card: float, background: float):
    """A grey card turned 10 degrees about the view axis on a grey wall, both emissive and
    unlit: two flat colours, their contrast set by the two linear greys."""
    def build(world):
        look_from(world, (0.0, 0.0, 6.0), target=(0.0, 0.0, 0.0), fov=40.0)
        world.spawn(Transform(position=(0.0, 0.0, -1.0)), MeshRef(box((20.0, 20.0, 0.1))),
                    Material(color=(background,) * 3), Emissive(1.0))
        world.spawn(Transform(rotation=glm.angleAxis(glm.radians(10.0), glm.vec3(0, 0, 1))),
                    MeshRef(box((2.4, 1.6, 0.1))), Material(color=(card,) * 3), Emissive(1.0))
    return build


def edge_pixels(frame: np.ndarray) -> np.ndarray:
    """FXAA's rule worked out on the unfiltered sRGB frame: a pixel is on an edge when the luma
    range of it and its four neighbours is at least max(EDGE_THRESHOLD_MIN, EDGE_THRESHOLD x
    their highest luma)."""
    luma = np.pad(frame @ LUMA / 255.0, 1, mode="edge")
    around = np.stack([luma[1:-1, 1:-1], luma[:-2, 1:-1], luma[2:, 1:-1], luma[1:-1, :-2], luma[1:-1, 2:]])
    hi, lo = around.max(axis=0), around.min(axis=0)
    return (hi - lo) >= np.maximum(EDGE_THRESHOLD_MIN, hi * EDGE_THRESHOLD)


@pytest.mark.parametrize("card, background, filtered", [(0.7, 0.35, True), (0.7, 0.55, False)])
def test_fxaa_filters_an_edge_exactly_when_its_contrast_passes_the_threshold(scene, card, background, filtered):
    """Edges of known contrast (luma range over the brighter side's luma about 0.27, twice
    the threshold, and about 0.1, under it, both above the dark-area minimum): FXAA changes
    only the pixels its rule calls edges, and it does change those.
    Fails when fxaa.frag's EDGE_THRESHOLD is 0.5 (x4): the 0.27 edge is left alone."""
    runner = scene(grey_card_on_grey(card, background), (160, 120))
    runner.engine.renderer.antialias = "off"
    off = runner.frame().astype(int)
    runner.engine.renderer.antialias = "fxaa"
    fxaa = runner.frame().astype(int)
    colours = np.unique(off.reshape(-1, 3), axis=0)
    assert len(colours) == 2
    lumas = np.sort(colours @ LUMA / 255.0)
    contrast = (lumas[1] - lumas[0]) / lumas[1]
    assert lumas[1] - lumas[0] > 1.3 * EDGE_THRESHOLD_MIN  # the dark-area minimum plays no part
    assert (contrast > 2 * EDGE_THRESHOLD) if filtered else (contrast < 0.85 * EDGE_THRESHOLD), contrast

    edges = edge_pixels(off)
    changed = (fxaa != off).any(axis=2)
    assert not changed[~edges].any()  # nothing but an edge is touched
    if filtered:
        assert edges.sum() > 100 and changed[edges].mean() > 0.25, (edges.sum(), changed[edges].mean())
    else:
        assert not edges.any() and not changed.any()


# --- 7. a mirror view's near plane is the mirror ---------------------------------------------------

def test_a_mirror_views_near_plane_is_the_mirror_plane(scene):
    """Lengyel's oblique near plane puts the mirror's plane at depth 0 of the reflected view.
    Worked out on the view itself (the mirror's corners, on its plane, map to NDC z = -1) and
    on the pixels: the floor seen in the mirror meets the glass along the mirror's lower edge,
    so the level-1 depth there is near 0 (a plain projection gives ~0.98 at 5 m).  And a box
    behind the glass (between it and the reflected camera) never shows in the reflection (that
    check alone fails only with the view's clip distance off too: either one hides the box).
    Fails when ViewTree._surface_view keeps the root's projection (oblique near plane off)."""
    ents = {}

    def build(world):
        world.spawn(Skybox())
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))
        look_from(world, (0.0, 1.8, 3.0), target=(0.0, 1.0, -2.0))
        world.spawn(Transform(), MeshRef(plane(20, 20)), Material(color=(0.6, 0.6, 0.6)))
        ents["mirror"] = world.spawn(Transform(position=(0.0, 1.5, -2.0)), MeshRef(quad(4, 3)),
                                     Material(color=(0.1, 0.1, 0.1)), Mirror())
        ents["behind"] = world.spawn(Transform(position=(0.0, 1.2, -3.0)), MeshRef(box((1.0, 1.0, 1.0))),
                                     Material(color=(0.05, 0.9, 0.05)), Emissive(1.0))

    size = (160, 120)
    runner = scene(build, size)
    runner.frame()
    (reflection,) = runner.engine.reflection_system.views[1:]
    view = reflection.view
    for corner in ((-2, 0, -2), (2, 0, -2), (2, 3, -2), (-2, 3, -2)):
        clip = view.view_proj * glm.vec4(*corner, 1.0)
        assert abs(clip.z / clip.w + 1.0) < 1e-3, (corner, clip.z / clip.w)

    level = runner.engine.renderer.levels[1]
    w, h = size
    depth = np.flipud(np.frombuffer(level.depth.read(), np.float32).reshape(h, w))
    ids = runner.ids()
    surface = runner.engine.renderer.targets.read_surface_ids()
    in_mirror = surface == ents["mirror"]
    assert in_mirror.sum() > 3000
    assert not (ids == ents["behind"]).any()
    # The floor just above the mirror's lower edge (y = 0.05 .. 0.15 on the glass).
    _, low_row = runner.project((0.0, 0.05, -2.0))
    _, high_row = runner.project((0.0, 0.15, -2.0))
    band = in_mirror[high_row:low_row + 1, w // 4:3 * w // 4]
    floor_depth = depth[high_row:low_row + 1, w // 4:3 * w // 4][band]
    assert band.sum() > 50 and floor_depth.max() < 0.2, (band.sum(), floor_depth.max())
