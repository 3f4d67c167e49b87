"""One owner per rule (issues 24 and 38): each rule several pieces of code must agree on is
defined in one module, and everything else calls it; a second copy is what drifts.  The first
test reads every module's top-level definitions (no import), so a copy made anywhere fails it;
``test_no_copy_of_a_rules_formula`` looks for a rule's formula itself in every other file; the
others check that what is left of a rule outside its owner (a GLSL function or table, a
system's answer) gives the owner's answers, evaluated on values."""
from __future__ import annotations

import ast
import functools
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    ComponentValueError,
    ComponentWarning,
    Material,
    MeshRef,
    Mirror,
    ReflectionProbe,
    Skybox,
    Transform,
    Visibility,
    Water,
)
from components.limits import (
    ALL_LAYERS,
    NO_RECEIVE_BIT,
    NO_SHADOW_BIT,
    VIEW_DIRECT,
    VIEW_MIRROR,
    VIEW_PORTAL,
    VIEW_PROBE,
)
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
    "the visibility rule": (r"_?(entity_code|drawn_code|drawn_in|hidden_everywhere|casts_shadow|receives_shadow|"
                            r"VIEW_KIND_BITS)",
                            "engine/rules/visibility_rules.py"),
    "the visibility code's packing": (r"_?(visibility_code|DRAWN_EVERYWHERE|SEEN_BY_EVERY_VIEW|KIND_MASK)",
                                      "components/visibility.py"),
    "the budgets' order and coverage": (r"_?(spending_order|screen_coverage|\w*coverage)",
                                        "engine/core/budget.py"),
    "sRGB's transfer functions": (r"_?(srgb_to_linear|linear_to_srgb|srgb_encode|srgb_decode)(_array)?",
                                  "engine/core/color.py"),
    "yaw and pitch of a direction": (r"_?(yaw_pitch_of|heading)", "components/transform.py"),
    "the near and far limits": (r"_?(MIN_NEAR|MAX_FAR|MAX_DEPTH_RATIO|check_near_far)", "components/limits.py"),
    "F0 from an index": (r"_?(f0_from_ior|schlick\w*)", "components/water.py"),
    "the layers a view shows": (r"_?(ShownLayers|LAYER_FIELDS|surface_layers|check_surface_layers)",
                                "components/visibility.py"),
}


@functools.cache
def top_level_names(path: Path) -> set[str]:
    """The names ``path`` defines at its top level (parsed once a worker: each rule's case
    reads every module)."""
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


def _faces_drawn(ctx, tmp_path, fragment: str, n: int = 16):
    """Each face's n x n texels (RGBA floats) drawn by ``fragment`` (given its ``face`` and
    ``level_size``), with shaders/include/cube_faces.glsl built as every program is (its
    table from the defines the shader library makes of CUBE_FACES)."""
    (tmp_path / "include").mkdir()
    (tmp_path / "include" / "cube_faces.glsl").write_bytes((shader_dir() / "include" / "cube_faces.glsl").read_bytes())
    (tmp_path / "probe.frag").write_text(fragment)
    (tmp_path / "probe.vert").write_text(CUBE_PROBE_VERT)
    program = ctx.program(vertex_shader=load_source("probe.vert", root=tmp_path),
                          fragment_shader=load_source("probe.frag", root=tmp_path))
    quad = ctx.buffer(np.array([-1, -1, 1, -1, -1, 1, 1, 1], np.float32).tobytes())
    vao = ctx.vertex_array(program, [(quad, "2f", "in_position")])
    target = ctx.texture((n, n), 4, dtype="f4")
    fbo = ctx.framebuffer([target])
    faces = []
    try:
        fbo.use()
        # No blend, depth test, cull or clip distance another test left on: with blending,
        # a target a GPU hands back unwritten (NaN: SPECULUM_NOISY_GL) stayed NaN.
        bindings.apply_pass_state(ctx, bindings.PassState(), (0, 0, n, n))
        program["level_size"].value = float(n)
        for face in range(6):
            program["face"].value = face
            vao.render(mode=ctx.TRIANGLE_STRIP)
            faces.append(np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(n, n, 4))
    finally:
        release_framebuffer(fbo)  # binds framebuffer 0 first: no deleted name left bound
        for thing in (vao, target, quad, program):
            thing.release()
    return faces


def test_the_glsl_cube_face_directions_are_the_tables_texel_by_texel(ctx, tmp_path):
    """shaders/include/cube_faces.glsl gives each texel of each face the direction
    ``face_directions`` gives it."""
    for face, drawn in enumerate(_faces_drawn(ctx, tmp_path, CUBE_PROBE_FRAG)):
        np.testing.assert_allclose(drawn[..., :3], face_directions(face, 16), atol=1e-6, err_msg=FACE_NAMES[face])


CUBE_FACE_OF_FRAG = """#version 410 core
#include "cube_faces.glsl"
uniform int face;
uniform float level_size;
out vec4 color;
void main() {
    vec2 st = gl_FragCoord.xy / level_size * 2.0 - 1.0;
    vec2 found;
    int found_face = cube_face_of(cube_face_direction(face, st) * 3.7, found);
    color = vec4(float(found_face), found, 1.0);
}
"""


def test_the_glsl_cube_face_of_a_direction_is_the_tables_inverse(ctx, tmp_path):
    """``cube_face_of`` (shaders/include/cube_faces.glsl: the lamps' see-through lookup
    picks a face tile with it) takes each texel's direction of each face, scaled, back to
    that face and that texel's (s, t): the table's axes, written out axis by axis, agree
    with it."""
    c = (np.arange(16) + 0.5) / 16 * 2.0 - 1.0
    t, s = np.meshgrid(c, c, indexing="ij")
    for face, drawn in enumerate(_faces_drawn(ctx, tmp_path, CUBE_FACE_OF_FRAG)):
        assert (drawn[..., 0] == face).all(), FACE_NAMES[face]
        np.testing.assert_allclose(drawn[..., 1], s, atol=1e-5, err_msg=FACE_NAMES[face])
        np.testing.assert_allclose(drawn[..., 2], t, atol=1e-5, err_msg=FACE_NAMES[face])


CUBE_FACE_POINT_FRAG = """#version 410 core
#include "cube_faces.glsl"
uniform int face;
uniform float level_size;
out vec4 color;
void main() {
    vec2 st = gl_FragCoord.xy / level_size * 2.0 - 1.0;
    color = vec4(cube_face_point(cube_face_direction(face, st) * 3.7, vec2(0.5, -0.75) * st.yx), 1.0);
}
"""


def test_the_glsl_point_on_a_directions_face_is_the_tables(ctx, tmp_path):
    """``cube_face_point`` (shaders/include/cube_faces.glsl: a lamp's cube's bilinear
    comparisons gather at the corner of their four texels with it) takes each texel's
    direction of each face, scaled, and another (s, t) to the direction the table gives
    that face at that (s, t): its axes, written out axis by axis, agree with it."""
    c = (np.arange(16) + 0.5) / 16 * 2.0 - 1.0
    t, s = np.meshgrid(c, c, indexing="ij")
    for face, drawn in enumerate(_faces_drawn(ctx, tmp_path, CUBE_FACE_POINT_FRAG)):
        forward, s_axis, t_axis = (np.array(axis, np.float64) for axis in CUBE_FACES[face])
        expected = forward + (0.5 * t)[..., None] * s_axis + (-0.75 * s)[..., None] * t_axis
        np.testing.assert_allclose(drawn[..., :3], expected, atol=1e-6, err_msg=FACE_NAMES[face])


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


# --- issue 38: one owner for each rule the render room wrote more than once --------------------

PY_FILES = [p for package in PACKAGES for p in sorted((ROOT / package).rglob("*.py"))]
GLSL_FILES = [p for p in sorted((ROOT / "shaders").rglob("*.*")) if p.suffix in (".vert", ".frag", ".geom", ".glsl")]

# rule: (a regular expression for the rule's formula itself, the files that may hold it)
FORMULAS = {
    "sRGB's transfer functions": (r"0\.04045|0\.0031308", {"engine/core/color.py", "shaders/include/color.glsl"}),
    "the visibility code's packing": (r"<<\s*VIEW_KINDS|\(1\s*<<\s*VIEW_KINDS\)\s*-\s*1|define\s+VIEW_KIND_BITS",
                                      {"components/visibility.py"}),
    # (The split sum's table integrates Schlick's (1 - v.h)^5 in Python: its A and B are that
    # term's split, so it is the Fresnel's second owner, on the CPU.)
    "Schlick's Fresnel": (r"pow\(\s*1(\.0)?\s*-[^,]*,\s*5(\.0)?\s*\)|\*\*\s*5\b",
                          {"shaders/include/ggx.glsl", "engine/render/environment_brdf.py"}),
    "F0 from an index": (r"\(\s*(self\.)?ior\s*-\s*1(\.0)?\s*\)\s*/\s*\(\s*(self\.)?ior\s*\+\s*1(\.0)?\s*\)",
                         {"components/water.py", "shaders/include/ggx.glsl"}),
    "yaw from a direction": (r"atan2?\(\s*-", {"components/transform.py"}),
    "a budget's ranking": (r"lexsort", {"engine/core/budget.py"}),
    "the near and far limits": (r"\bfar\s*/\s*near\b|\bfar\s*>\s*near\b|\bfar\s*<=\s*near\b", {"components/limits.py"}),
}


@functools.cache
def file_text(path: Path) -> str:
    """``path``'s text, read once a worker."""
    return path.read_text(encoding="utf-8")


@pytest.mark.parametrize("rule", sorted(FORMULAS))
def test_no_copy_of_a_rules_formula(rule):
    """The rule's formula is written in its owners only (Python and GLSL; comments and
    docstrings count too, so a copy cannot hide in one)."""
    pattern, owners = FORMULAS[rule]
    found = {path.relative_to(ROOT).as_posix() for path in PY_FILES + GLSL_FILES
             if re.search(pattern, file_text(path))}
    assert found == owners, f"{rule}: written in {sorted(found - owners)}, owned by {sorted(owners)} only"


# A probe harness for GLSL functions: one fragment a value, an input vec4 a texel of a float
# texture, the function's answer written as a vec4.
EVAL_VERT = CUBE_PROBE_VERT
EVAL_FRAG = """#version 410 core
{includes}
uniform sampler2D inputs;
out vec4 color;
void main() {{
    vec4 a = texelFetch(inputs, ivec2(gl_FragCoord.xy), 0);
    {body}
}}
"""


def evaluate_glsl(ctx, tmp_path, includes: list[str], body: str, inputs: np.ndarray,
                  source_texture=None) -> np.ndarray:
    """``body`` (GLSL setting ``color`` from ``a``, the input row) run on each row of
    ``inputs`` (N x 4 floats), built as every program is (the shader library's includes
    and ``engine_defines``); returns N x 4 floats."""
    folder = tmp_path / "glsl"
    (folder / "include").mkdir(parents=True, exist_ok=True)
    for path in (shader_dir() / "include").iterdir():
        (folder / "include" / path.name).write_bytes(path.read_bytes())
    (folder / "eval.frag").write_text(EVAL_FRAG.format(
        includes="\n".join(f'#include "{name}"' for name in includes), body=body))
    (folder / "eval.vert").write_text(EVAL_VERT)
    n = len(inputs)
    program = ctx.program(vertex_shader=load_source("eval.vert", root=folder),
                          fragment_shader=load_source("eval.frag", root=folder))
    quad_buffer = ctx.buffer(np.array([-1, -1, 1, -1, -1, 1, 1, 1], np.float32).tobytes())
    vao = ctx.vertex_array(program, [(quad_buffer, "2f", "in_position")])
    data = source_texture or ctx.texture((n, 1), 4, np.ascontiguousarray(inputs, np.float32).tobytes(), dtype="f4")
    target = ctx.texture((n, 1), 4, dtype="f4")
    fbo = ctx.framebuffer([target])
    try:
        fbo.use()
        ctx.viewport = (0, 0, n, 1)
        data.use(0)
        if "inputs" in program:
            program["inputs"].value = 0
        vao.render(mode=ctx.TRIANGLE_STRIP)
        return np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(n, 4).astype(np.float64)
    finally:
        release_framebuffer(fbo)
        for thing in (vao, target, quad_buffer, program, data):
            thing.release()


def _visibilities() -> list[Visibility]:
    """Entities' visibilities covering every kind flag and layers at both ends of the range."""
    found = [None]
    warnings.simplefilter("ignore", ComponentWarning)  # hidden in every kind: warned, on purpose
    for hidden in range(16):
        for layers in ([0], [3], [15], [0, 15], list(range(16))):
            found.append(Visibility(direct=not hidden & 1, in_mirrors=not hidden & 2, in_portals=not hidden & 4,
                                    in_probes=not hidden & 8, layers=layers))
    return found


def _view_masks() -> list[tuple[int, int]]:
    """(kinds, shown layers) of views: each kind alone and accumulated, layer sets at both ends."""
    kinds = [VIEW_DIRECT, VIEW_MIRROR, VIEW_PORTAL, VIEW_PROBE, VIEW_MIRROR | VIEW_PORTAL, VIEW_PROBE | VIEW_MIRROR]
    layer_sets = [ALL_LAYERS, 1, 1 << 3, 1 << 15, 0, ALL_LAYERS & ~1]
    return [(k, layers) for k in kinds for layers in layer_sets]


def _drawn_by_meaning(visibility: Visibility | None, kinds: int, layers: int) -> bool:
    """What components/visibility.py says, from the component's flags and layer numbers."""
    if visibility is None:
        return bool(layers & 1)  # every kind of view, layer 0
    hidden = {VIEW_DIRECT: not visibility.direct, VIEW_MIRROR: not visibility.in_mirrors,
              VIEW_PORTAL: not visibility.in_portals, VIEW_PROBE: not visibility.in_probes}
    return not any(hide and kinds & kind for kind, hide in hidden.items()) and any(
        layers >> layer & 1 for layer in visibility.layers)


def test_every_copy_of_the_visibility_rule_answers_as_its_owner(ctx, tmp_path):
    """The view draws this instance: the owner (``visibility_rules.drawn_in``), the scene
    shaders' ``hidden_in_view`` and the shadow pass's ``hidden_everywhere`` (evaluated on the
    GPU, with ``VIEW_KIND_BITS`` from the shader library), the planner's
    ``SurfaceTable.drawn_in`` and the probes' ``ChangedBoxes.seen_by`` all give the answer the
    component's own words give, for every kind flag and layers at both ends, whether the
    instance casts shadows or not (``MeshRef.casts_shadows``: the shadow pass's
    ``casts_no_shadow`` answers as ``casts_shadow``, and it changes no view's answer), and
    whether it receives them or not (``MeshRef.receives_shadows``: the scene shader's
    ``receives_no_shadow`` answers as ``receives_shadow``, changing no other answer), and
    whether it is a portal's opening that carries light or not (``Portal.carries_light``:
    ``opening_casts`` in GLSL answers as its owner, changing no other answer)."""
    from components.limits import OPENING_CASTS_BIT, VIEW_KINDS
    from components.visibility import visibility_code
    from engine.core.reflection_math import reflection_matrix
    from engine.render.view_plan import SurfaceTable
    from engine.resources import SurfaceState
    from engine.rules.visibility_rules import (
        casts_shadow,
        drawn_in,
        entity_code,
        hidden_everywhere,
        opening_casts,
        receives_shadow,
    )
    from systems.probe_scheduler import ChangedBoxes

    assert engine_defines()["VIEW_KIND_BITS"] == f"{VIEW_KINDS}u"
    assert engine_defines()["NO_SHADOW_BIT"] == f"{NO_SHADOW_BIT}u"
    assert engine_defines()["NO_RECEIVE_BIT"] == f"{NO_RECEIVE_BIT}u"
    assert engine_defines()["OPENING_CASTS_BIT"] == f"{OPENING_CASTS_BIT}u"
    base = _visibilities()
    # Every visibility casting shadows or not, receiving them or not; every third an opening
    # carrying light (a third, so it falls on each of the four alike).
    visibilities = base * 4
    index = np.arange(len(visibilities))
    block = index // len(base)
    casting, receiving, opening = block < 2, block % 2 == 0, index % 3 == 0
    codes = np.array([entity_code(v, casts_shadows=bool(c), receives_shadows=bool(r), opening_carries=bool(o))
                      for v, c, r, o in zip(visibilities, casting, receiving, opening, strict=True)], np.int64)
    views = _view_masks()
    masks = np.array([visibility_code(k, layers) for k, layers in views], np.int64)
    meaning = np.array([[_drawn_by_meaning(v, k, layers) for k, layers in views] for v in visibilities])
    owner = drawn_in(codes[:, None], masks[None, :])
    np.testing.assert_array_equal(owner, meaning)

    pairs = np.array([(c, m) for c in codes for m in masks], np.float64)
    rows = np.zeros((len(pairs), 4))
    rows[:, :2] = pairs  # exact: both are integers below 2^22
    glsl = evaluate_glsl(ctx, tmp_path, ["visibility.glsl"],
                         "color = vec4(hidden_in_view(a.x, uint(a.y + 0.5)) ? 1.0 : 0.0, "
                         "hidden_everywhere(a.x) ? 1.0 : 0.0, casts_no_shadow(a.x) ? 1.0 : 0.0, "
                         "(receives_no_shadow(a.x) ? 0.5 : 1.0) - (opening_casts(a.x) ? 0.25 : 0.0));", rows)
    np.testing.assert_array_equal(glsl[:, 0].reshape(owner.shape) == 0.0, owner)
    np.testing.assert_array_equal(glsl[:, 1] == 1.0, np.repeat(hidden_everywhere(codes), len(masks)))
    assert hidden_everywhere(codes).any() and not hidden_everywhere(codes).all()
    casts = casting & ~hidden_everywhere(codes)  # the meaning: drawn somewhere, its switch on
    np.testing.assert_array_equal(casts_shadow(codes), casts)
    assert [casts_shadow(int(code)) for code in codes] == casts.tolist()
    np.testing.assert_array_equal(glsl[:, 2] == 0.0, np.repeat(casts, len(masks)))
    np.testing.assert_array_equal(receives_shadow(codes), receiving)
    np.testing.assert_array_equal(np.isin(glsl[:, 3], (1.0, 0.75)), np.repeat(receiving, len(masks)))
    np.testing.assert_array_equal(opening_casts(codes), opening)
    np.testing.assert_array_equal(np.isin(glsl[:, 3], (0.75, 0.25)), np.repeat(opening, len(masks)))

    plane = glm.vec4(0.0, 0.0, 1.0, 0.0)
    corners = np.array([(x, y, 0.0, 1.0) for x in (-1.0, 1.0) for y in (0.0, 2.0)])
    table = SurfaceTable([SurfaceState(i + 1, "mirror", plane, corners, None, reflection_matrix(plane), plane, i + 1,
                                       2, drawn=int(code)) for i, code in enumerate(codes)])
    for column, mask in enumerate(masks.tolist()):
        planned = table.drawn_in(mask)
        np.testing.assert_array_equal(np.ones(len(codes), bool) if planned is None else planned, meaning[:, column])

    boxes = ChangedBoxes([(i, "moved", np.zeros(3), np.ones(3), int(code)) for i, code in enumerate(codes)])
    for layers in ([0], [3], [0, 15], list(range(16))):
        probe = ReflectionProbe(shows_layers=layers)
        seen = np.array([_drawn_by_meaning(v, VIEW_PROBE, probe.layer_mask) for v in visibilities])
        np.testing.assert_array_equal(boxes.seen_by(probe), seen, err_msg=str(layers))


def test_no_shader_defines_what_python_owns():
    """The numbers GLSL shares with Python come from ``engine_defines`` only: no shader file
    defines one of them itself, and the blocks' array sizes and tone curves' numbers there
    are the Python that packs and picks them."""
    from components.post import TONEMAP_CURVES
    from engine.render import irradiance, shadows, views
    from engine.rules import shadow_rules

    owned = set(engine_defines())
    sizes = {"MAX_DIRECTIONAL_LIGHTS": views.MAX_DIRECTIONAL_LIGHTS, "MAX_POINT_LIGHTS": views.MAX_POINT_LIGHTS,
             "MAX_POINT_SHADOWS": shadows.MAX_POINT_SHADOWS, "MAX_IRRADIANCE_PROBES": irradiance.MAX_IRRADIANCE_PROBES,
             "MAX_VIRTUAL_LIGHTS": shadow_rules.MAX_VIRTUAL_LIGHTS, "MAX_APERTURES": shadow_rules.MAX_APERTURES,
             **{f"TONEMAP_{curve.upper()}": i for i, curve in enumerate(TONEMAP_CURVES)}}
    assert {name: int(engine_defines()[name]) for name in sizes} == sizes
    for path in GLSL_FILES:
        for name in re.findall(r"^\s*#\s*define\s+(\w+)", path.read_text(encoding="utf-8"), re.MULTILINE):
            assert name not in owned, f"{path.name} defines {name}, which the shader library makes from Python"


def test_the_shaders_fresnel_and_f0_are_the_owners(ctx, tmp_path):
    """``f0_from_ior`` in ggx.glsl gives components/water.py's ``f0_from_ior`` (Water.f0) for
    indices across the allowed range, and water's Fresnel and the GGX one are one Schlick: at
    each angle, f0 + (1 - f0)(1 - cos)^5."""
    from components.water import f0_from_ior

    iors = np.linspace(1.0, 4.0, 13)
    angles = np.linspace(0.0, 0.5 * np.pi, 13)
    f0s = np.array([f0_from_ior(float(i)) for i in iors])
    assert Water(ior=1.333).f0 == f0_from_ior(1.333) and abs(f0_from_ior(1.333) - 0.0204) < 1e-4
    rows = np.stack([iors, np.cos(angles), np.sin(angles), f0s], axis=1)
    glsl = evaluate_glsl(ctx, tmp_path, ["ggx.glsl", "normal_map.glsl", "water.glsl"], """
        vec3 n = vec3(0.0, 0.0, 1.0);
        vec3 to_eye = vec3(a.z, 0.0, a.y);
        color = vec4(f0_from_ior(a.x), water_fresnel(n, to_eye, a.w), schlick_fresnel(to_eye, n, vec3(a.w)).x, 1.0);
    """, rows)
    np.testing.assert_allclose(glsl[:, 0], f0s, rtol=1e-5, atol=1e-7)
    schlick = f0s + (1.0 - f0s) * (1.0 - np.clip(np.cos(angles), 0.0, 1.0)) ** 5
    np.testing.assert_allclose(glsl[:, 1], schlick, rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(glsl[:, 2], schlick, rtol=1e-4, atol=1e-6)


def test_srgb_is_decoded_as_the_gl_does_and_encoded_as_the_present_shader_does(ctx, tmp_path):
    """engine/core/color.py's ``srgb_to_linear`` gives every byte of an sRGB texture as the GL's
    own decode reads it back, and its ``linear_to_srgb`` is color.glsl's ``linear_to_srgb``."""
    from engine.core.color import linear_to_srgb, srgb_to_linear
    from engine.render.gpu import GL_SRGB8_ALPHA8

    levels = np.arange(256, dtype=np.uint8)
    texels = np.stack([levels, levels, levels, np.full(256, 255, np.uint8)], axis=1)
    srgb = ctx.texture((256, 1), 4, texels.tobytes(), internal_format=GL_SRGB8_ALPHA8)
    decoded = evaluate_glsl(ctx, tmp_path, [], "color = a;", np.zeros((256, 4)), source_texture=srgb)
    # llvmpipe decodes sRGB with an approximation (1.2e-3 at most from the formula, measured);
    # the NVIDIA H200 (driver 580) to 8 significant bits (steps of 1/128 near 1: 3.7e-3 off at
    # level 251, within 2^-8 of the value).  A drifted copy (a plain 2.2 gamma, say) is 8.5e-3
    # off, 5e-3 past this tolerance.
    np.testing.assert_allclose(decoded[:, 0], srgb_to_linear(levels / 255.0), rtol=4e-3, atol=1.5e-3)
    linear = np.concatenate([np.linspace(0.0, 0.01, 33), np.linspace(0.01, 1.2, 97), [-0.5]])
    rows = np.zeros((len(linear), 4))
    rows[:, 0] = linear
    encoded = evaluate_glsl(ctx, tmp_path, ["color.glsl"], "color = vec4(linear_to_srgb(a.xxx), 1.0);", rows)
    np.testing.assert_allclose(encoded[:, 0], linear_to_srgb(linear), atol=2e-6)


def test_yaw_and_pitch_of_a_direction_invert_the_rotation_they_make():
    """``yaw_pitch_of`` is ``yaw_pitch_rotation``'s inverse: the rotation it gives looks along
    the direction, for directions of any length all round (and ``heading`` of the rotation
    gives the angles back)."""
    from components.transform import heading, yaw_pitch_of, yaw_pitch_rotation

    rng = np.random.default_rng(38)
    for direction in [*rng.normal(size=(64, 3)) * rng.uniform(0.01, 100.0, size=(64, 1)), (0.0, 0.0, -1.0),
                      (1.0, 0.0, 0.0), (0.0, 0.0, 2.0), (-3.0, 0.5, 0.0)]:
        yaw, pitch = yaw_pitch_of(glm.vec3(*direction))
        assert -180.0 <= yaw <= 180.0 and -90.0 <= pitch <= 90.0
        looks = yaw_pitch_rotation(yaw, pitch) * glm.vec3(0.0, 0.0, -1.0)
        np.testing.assert_allclose(looks.to_list(), (np.asarray(direction) / np.linalg.norm(direction)), atol=1e-5)
        yaw_back, pitch_back = heading(yaw_pitch_rotation(yaw, pitch))
        assert abs((yaw_back - yaw + 180.0) % 360.0 - 180.0) < 1e-3 and abs(pitch_back - pitch) < 1e-3


def test_the_budgets_rank_by_one_order_and_the_spenders_call_it():
    """``spending_order``: first captures, then priority, then worth, then the ties in turn,
    then the order given; the view tree's, the probes' and the virtual lights' spenders
    rank by calling it (no sort of their own), and the view tree's coverage is always
    ``screen_coverage``'s."""
    from engine.core.budget import screen_coverage, spending_order

    priority = [0, 2, 2, 0, 2, 0]
    worth = [5.0, 1.0, 3.0, 5.0, 3.0, 9.0]
    np.testing.assert_array_equal(spending_order(priority, worth), [2, 4, 1, 5, 0, 3])
    np.testing.assert_array_equal(spending_order(priority, worth, [0, 0, 7, 0, 3, 0]), [4, 2, 1, 5, 0, 3])
    np.testing.assert_array_equal(spending_order(priority, worth, first=[0, 0, 0, 1, 0, 0]), [3, 2, 4, 1, 5, 0])
    assert len(spending_order([], [])) == 0
    # Rounded, not truncated: a level drawn at half size whose claims scale to 2.9999 pixels is 3.
    assert screen_coverage(3, (100, 100), (100, 100)) == 3
    assert screen_coverage(1, (3, 3), (5, 5)) == round(25 / 9) == 3 != int(25 / 9)
    assert screen_coverage(np.int64(7), (64, 36), (128, 72)) == 28

    spenders = {"engine/render/tree_visibility.py": "within_budgets", "systems/probe_scheduler.py": "_within_budget",
                "engine/rules/shadow_rules.py": "rank_virtual_lights"}
    for name, function in spenders.items():
        tree = ast.parse((ROOT / name).read_text(encoding="utf-8"))
        found = [node for node in ast.walk(tree) if isinstance(node, ast.FunctionDef) and node.name == function]
        assert len(found) == 1, f"{name}: {function}"
        calls = {c.func.id if isinstance(c.func, ast.Name) else c.func.attr
                 for c in ast.walk(found[0])
                 if isinstance(c, ast.Call) and isinstance(c.func, (ast.Name, ast.Attribute))}
        keyed = [c for c in ast.walk(found[0]) if isinstance(c, ast.Call) and any(k.arg == "key" for k in c.keywords)]
        assert "spending_order" in calls and not calls & {"sorted", "lexsort", "argsort"} and not keyed, \
            f"{name}: {function} ranks by itself ({sorted(calls)})"
    written = [node.value for name in ("engine/render/view_tree.py", "engine/render/tree_visibility.py")
               for node in ast.walk(ast.parse((ROOT / name).read_text(encoding="utf-8")))
               if isinstance(node, ast.Assign) and any(
                   isinstance(t, ast.Subscript) and "coverage" in (getattr(t.value, "attr", None),
                                                                   getattr(t.value, "id", None))
                   for t in node.targets)]
    assert len(written) >= 2 and all(isinstance(v, ast.Call) and getattr(v.func, "id", None) == "screen_coverage"
                                     for v in written), ast.dump(written[0]) if written else "no coverage written"


@pytest.mark.parametrize("planes", [(0.05, 200.0), (300.0, 1000.0), (1e-5, 1.0), (10.0, 1.0), (5.0, 5.0),
                                    (1e-4, 1e3), (1e-4, 2e3), (0.05, 1e6), (1.0, 1e7), (1.0, 2e7)])
def test_camera_and_probe_planes_are_held_to_one_limit(planes):
    """A camera's and a probe's near and far planes are checked by ``check_near_far`` with the
    limits of components/limits.py: both accept and refuse the same planes, in the same words."""
    from components.limits import MAX_DEPTH_RATIO, MAX_FAR, MIN_NEAR

    near, far = planes
    allowed = MIN_NEAR <= near < far <= MAX_FAR and far / near <= MAX_DEPTH_RATIO
    words = []
    for kind in (Camera, ReflectionProbe):
        try:
            made = kind(near=near, far=far)
        except ComponentValueError as exc:
            words.append(str(exc).replace(kind.__name__, "X"))
        else:
            assert (made.near, made.far) == planes
            words.append(None)
    assert words[0] == words[1] and (words[0] is None) == allowed, words


def test_the_layer_fields_are_one_definition():
    """Camera, Mirror, Portal and ReflectionProbe take ``shows_layers`` and ``hides_layers``
    from ``ShownLayers`` (no class declares them again) and check them there."""
    import dataclasses

    from components import Portal
    from components.visibility import LAYER_FIELDS, ShownLayers

    base = {f.name: f for f in dataclasses.fields(ShownLayers)}
    assert set(base) == set(LAYER_FIELDS)
    for kind in (Camera, Mirror, Portal, ReflectionProbe):
        assert issubclass(kind, ShownLayers)
        assert not set(LAYER_FIELDS) & set(vars(kind).get("__annotations__", {})), kind.__name__
        assert "layer_mask" not in vars(kind), kind.__name__
        fields = {f.name: f for f in dataclasses.fields(kind)}
        assert all(fields[name].default == base[name].default for name in LAYER_FIELDS)
        assert kind(hides_layers=[3]).layer_mask == ALL_LAYERS & ~(1 << 3)
        assert kind(shows_layers=[1, 2], hides_layers=[2]).layer_mask == 1 << 1
        with pytest.raises(ComponentValueError, match=f"{kind.__name__}.shows_layers must be a list"):
            kind(shows_layers=3)
