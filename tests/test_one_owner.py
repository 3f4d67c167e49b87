"""One owner per rule (issue 24): each rule several pieces of code must agree on is defined
in one module, and everything else calls it; a second copy is what drifts.  The first test
reads every module's top-level definitions (no import), so a copy made anywhere fails it;
the others check that what is left of a rule outside its owner (a GLSL table, a system's
answer) is the owner's."""
from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
import pytest
from pyglm import glm

from components import Camera, ComponentValueError, Material, MeshRef, Mirror, Skybox, Transform
from engine.assets.mesh import box, quad
from engine.core.cube_faces import CUBE_FACES, FACE_NAMES, face_directions
from engine.core.transforms import current_world_matrix
from engine.core.world import World
from engine.render import bindings
from engine.render.shader_library import engine_defines, load_source, shader_dir
from engine.render.targets import release_framebuffer
from engine.rules.frame_rules import active_camera, active_camera_parts
from engine.rules.mirror_rules import mirror_mesh
from systems.surface_system import MirrorError
from systems.transform_system import TransformSystem
from tests.support import look_from

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("components", "engine", "systems", "shell", "games", "benchmarks")

# rule: (the pattern a top-level function or constant of the rule is named by, its one owner)
OWNERS = {
    "the active camera": (r"_?active_camera(_\w+)?", "engine/rules/frame_rules.py"),
    "the world matrix": (r"_?current_world_matrix", "engine/core/transforms.py"),
    "the cube-face table": (r"CUBE_FACES|FACE_AXES|FACE_ORDER|FACE_NAMES|face_directions",
                            "engine/core/cube_faces.py"),
    "the clip-distance indices": (r"_?(CLIP_(VIEW_PLANE|RECT|RECT_SIDES|SLICE|DISTANCE_COUNT)|SLICE_CLIP)",
                                  "engine/render/bindings.py"),
}


def top_level_names(path: Path) -> set[str]:
    names = set()
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return names


@pytest.mark.parametrize("rule", sorted(OWNERS))
def test_each_rule_is_defined_in_one_module(rule):
    pattern, owner = OWNERS[rule]
    defined = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            hits = sorted(n for n in top_level_names(path) if re.fullmatch(pattern, n))
            if hits:
                defined[path.relative_to(ROOT).as_posix()] = hits
    assert set(defined) == {owner}, f"{rule}: defined in {defined}, owned by {owner} only"


def test_active_camera_parts_is_the_rules_camera():
    world = World("one owner")
    try:
        assert active_camera_parts(world) is None
        cameras = [world.spawn(Transform(), Camera(active=active)) for active in (False, True, True)]
        entity, camera, transform = active_camera_parts(world)
        assert entity == active_camera(world) == cameras[1]
        assert camera is world.get(entity, Camera) and transform is world.get(entity, Transform)
    finally:
        world.close()


def test_current_world_matrix_is_the_transform_stages_matrix():
    """Worked out before the transform stage, the matrix is the one the stage then writes,
    through a chain with a parent that has no Transform and one that was deleted."""
    world = World("one owner")
    try:
        turn = glm.angleAxis(0.7, glm.vec3(0.0, 1.0, 0.0))
        root = world.spawn(Transform(position=(1.0, 2.0, 3.0), rotation=turn, scale=(2.0, 2.0, 2.0)))
        child = world.spawn(Transform(position=(0.5, 0.0, -1.0), parent=root))
        grandchild = world.spawn(Transform(position=(0.0, 1.0, 0.0), rotation=turn, parent=child))
        bare = world.spawn(Camera(active=False))             # an entity with no Transform
        under_bare = world.spawn(Transform(position=(4.0, 0.0, 0.0), parent=bare))
        gone = world.spawn(Transform(position=(9.0, 9.0, 9.0)))
        under_gone = world.spawn(Transform(position=(0.0, 0.0, 5.0), parent=gone))
        world.delete_entity(gone)
        entities = (root, child, grandchild, under_bare, under_gone)
        before = {e: current_world_matrix(world, world.get(e, Transform)) for e in entities}
        TransformSystem(world).process(0.0)
        for entity in entities:
            written = world.get(entity, Transform).world
            np.testing.assert_allclose(before[entity].to_list(), written.to_list(), atol=1e-6, err_msg=str(entity))
        assert before[under_bare][3] == glm.vec4(4.0, 0.0, 0.0, 1.0)
        assert before[under_gone][3] == glm.vec4(0.0, 0.0, 5.0, 1.0)
    finally:
        world.close()


# The OpenGL spec's cube-map face selection ("Cube Map Texture Selection"): the face is the
# direction's largest component and its sign; sc, tc (before s = (sc / |ma| + 1) / 2) are
# these components of the direction r.
GL_SPEC_FACES = {
    "+X": lambda r: (-r[..., 2], -r[..., 1]), "-X": lambda r: (r[..., 2], -r[..., 1]),
    "+Y": lambda r: (r[..., 0], r[..., 2]), "-Y": lambda r: (r[..., 0], -r[..., 2]),
    "+Z": lambda r: (r[..., 0], -r[..., 1]), "-Z": lambda r: (-r[..., 0], -r[..., 1]),
}


def test_the_cube_face_table_is_the_gl_specs():
    """Every texel direction of the table selects its own face and lands on its own texel
    by the spec's selection rule; a face view looking along the face's axis with up its t
    axis has the s axis on its right."""
    n = 8
    c = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    for face, name in enumerate(FACE_NAMES):
        r = face_directions(face, n)
        major = np.argmax(np.abs(r), axis=-1)
        assert (2 * major + (r[np.arange(n)[:, None], np.arange(n)[None, :], major] < 0) == face).all(), name
        ma = np.abs(r).max(axis=-1)
        sc, tc = GL_SPEC_FACES[name](r)
        np.testing.assert_allclose(sc / ma, np.broadcast_to(c[None, :], (n, n)), atol=1e-12, err_msg=name)
        np.testing.assert_allclose(tc / ma, np.broadcast_to(c[:, None], (n, n)), atol=1e-12, err_msg=name)
        forward, s_axis, t_axis = (glm.vec3(a) for a in CUBE_FACES[face])
        assert glm.cross(forward, t_axis) == s_axis, name


CUBE_PROBE_FRAG = """#version 410 core
#include "cube_faces.glsl"
uniform int face;
uniform float level_size;
out vec4 color;
void main() {
    vec2 st = gl_FragCoord.xy / level_size * 2.0 - 1.0;  // as shaders/cube_mip.frag
    color = vec4(normalize(cube_face_direction(face, st)), 1.0);
}
"""
CUBE_PROBE_VERT = """#version 410 core
in vec2 in_position;
void main() { gl_Position = vec4(in_position, 0.0, 1.0); }
"""


def test_the_glsl_cube_face_directions_are_the_tables_texel_by_texel(ctx, tmp_path):
    """shaders/include/cube_faces.glsl, built as every program is (its table from the
    defines the shader library makes of CUBE_FACES), gives each texel of each face the
    direction ``face_directions`` gives it."""
    (tmp_path / "include").mkdir()
    (tmp_path / "include" / "cube_faces.glsl").write_bytes((shader_dir() / "include" / "cube_faces.glsl").read_bytes())
    (tmp_path / "probe.frag").write_text(CUBE_PROBE_FRAG)
    (tmp_path / "probe.vert").write_text(CUBE_PROBE_VERT)
    n = 16
    program = ctx.program(vertex_shader=load_source("probe.vert", root=tmp_path),
                          fragment_shader=load_source("probe.frag", root=tmp_path))
    quad = ctx.buffer(np.array([-1, -1, 1, -1, -1, 1, 1, 1], np.float32).tobytes())
    vao = ctx.vertex_array(program, [(quad, "2f", "in_position")])
    target = ctx.texture((n, n), 4, dtype="f4")
    fbo = ctx.framebuffer([target])
    try:
        fbo.use()
        ctx.viewport = (0, 0, n, n)
        program["level_size"].value = float(n)
        for face in range(6):
            program["face"].value = face
            vao.render(mode=ctx.TRIANGLE_STRIP)
            drawn = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(n, n, 4)[..., :3]
            np.testing.assert_allclose(drawn, face_directions(face, n), atol=1e-6, err_msg=FACE_NAMES[face])
    finally:
        release_framebuffer(fbo)  # binds framebuffer 0 first: no deleted name left bound
        for thing in (vao, target, quad, program):
            thing.release()


def test_the_glsl_names_every_clip_distance_and_numbers_none():
    """Every gl_ClipDistance a shader writes is indexed by a name the shader library defines
    from engine/render/bindings.py (never a number, never a define of the shader's own), and
    those defines are the indices the passes enable."""
    defines = engine_defines()
    clip_names = {name for name in defines if name.startswith("CLIP_")}
    used = set()
    for path in sorted(shader_dir().rglob("*.*")):
        if path.suffix not in (".vert", ".frag", ".geom", ".glsl"):
            continue
        text = path.read_text(encoding="utf-8")
        name = path.relative_to(shader_dir()).as_posix()
        for index in re.findall(r"gl_ClipDistance\s*\[([^\]]*)\]", text):
            assert index.strip() in clip_names, f"{name}: gl_ClipDistance[{index}] (use a CLIP_ name)"
            used.add(index.strip())
        assert not re.search(r"^\s*#\s*define\s+\w*CLIP\w*", text, re.MULTILINE), f"{name} defines a clip index"
    assert used == clip_names, f"defined, never used: {sorted(clip_names - used)}"
    rect = dict(zip(bindings.CLIP_RECT_SIDES, bindings.CLIP_RECT, strict=True))
    assert {name: int(defines[name]) for name in clip_names} == {
        "CLIP_VIEW_PLANE": bindings.CLIP_VIEW_PLANE, "CLIP_SLICE": bindings.CLIP_SLICE,
        "CLIP_LEG_PLANE": bindings.CLIP_LEG_PLANE, "CLIP_DISTANCE_COUNT": bindings.CLIP_DISTANCE_COUNT,
        **{f"CLIP_RECT_{side}": i for side, i in rect.items()}}
    assert sorted((bindings.CLIP_VIEW_PLANE, bindings.CLIP_SLICE, *bindings.CLIP_RECT)) == list(
        range(bindings.CLIP_DISTANCE_COUNT))


@pytest.mark.parametrize("bad", ["not flat", "no area"])
def test_the_surfaces_stage_takes_the_mirror_rules_plane_and_refuses_with_its_reason(scene, bad):
    """The surfaces stage's plane is the mirror rule's, and a mesh the world would refuse
    (here put in behind its back, past the MeshRef setter) is refused there with the words
    the world's invariant uses."""
    ents = {}

    def build(world):
        world.spawn(Skybox())
        look_from(world, (0.0, 1.0, 4.0), target=(0.0, 1.0, 0.0))
        ents["mirror"] = world.spawn(Transform(position=(0.0, 1.0, 0.0)), MeshRef(quad(2.0, 2.0)), Material(),
                                     Mirror())

    runner = scene(build, (32, 24))
    runner.frame()
    world, entity = runner.world, ents["mirror"]
    state = runner.engine.stages["surfaces"].mirrors[entity]  # the SurfaceSystem's row
    rule = mirror_mesh(world.get(entity, Mirror), world.get(entity, MeshRef).mesh)
    np.testing.assert_allclose(np.array(state.plane.to_list())[:3], rule.normal, atol=1e-6)
    mesh = box(name="crate") if bad == "not flat" else quad(0.0, 0.0, name="dot")
    with pytest.raises(ComponentValueError) as refused:
        world.check_invariants(entity, MeshRef, mesh=mesh)
    object.__setattr__(world.get(entity, MeshRef), "mesh", mesh)  # what the setter would refuse
    world.get(entity, Transform).position = (0.0, 1.5, 0.0)       # moved: the stage looks again
    with pytest.raises(MirrorError) as stage:
        runner.frame()
    assert str(stage.value) == str(refused.value) and bad in str(stage.value)
