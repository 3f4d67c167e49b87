"""The start-up capability check: names what a context lacks, passes the real one."""
from __future__ import annotations

import dataclasses

import pytest

from engine.core.errors import GLCapabilityError
from engine.render.gl_context import REQUIREMENTS, GLCapabilities, check_capabilities, prepare_context

GOOD = GLCapabilities(
    version_code=410,
    renderer="Simulated GPU",
    max_texture_size=4096,
    max_cube_map_size=1024,
    max_color_attachments=4,
    max_draw_buffers=4,
    max_uniform_block_size=16384,
    max_vertex_attribs=16,
    max_geometry_output_vertices=256,
    max_clip_distances=8,
    extensions=frozenset(),
)


def test_exactly_the_minimums_pass():
    minimal = dataclasses.replace(GOOD, **{name: minimum for name, minimum, _ in REQUIREMENTS})
    assert check_capabilities(minimal) is minimal
    assert check_capabilities(GOOD) is GOOD


@pytest.mark.parametrize("version_code, shown", [(330, "3.3"), (400, "4.0"), (210, "2.1")])
def test_old_opengl_version_is_named(version_code, shown):
    caps = dataclasses.replace(GOOD, version_code=version_code)
    with pytest.raises(GLCapabilityError) as info:
        check_capabilities(caps)
    message = str(info.value)
    assert f"OpenGL {shown} < 4.1" in message
    assert "Simulated GPU" in message       # which context
    assert "max_" not in message            # only what is missing


@pytest.mark.parametrize("name, minimum, why", REQUIREMENTS[1:], ids=[r[0] for r in REQUIREMENTS[1:]])
def test_each_limit_below_its_minimum_is_named(name, minimum, why):
    caps = dataclasses.replace(GOOD, **{name: minimum - 1})
    with pytest.raises(GLCapabilityError) as info:
        check_capabilities(caps)
    message = str(info.value)
    assert f"{name} = {minimum - 1} < {minimum}" in message
    assert why in message
    assert "OpenGL 4.1 core:" not in message   # the version was fine


def test_everything_missing_is_named_at_once():
    caps = dataclasses.replace(GOOD, version_code=330, max_texture_size=1024, max_clip_distances=0)
    with pytest.raises(GLCapabilityError) as info:
        check_capabilities(caps)
    message = str(info.value)
    for part in ("OpenGL 3.3 < 4.1", "max_texture_size = 1024 < 2048", "max_clip_distances = 0 < 6"):
        assert part in message
    assert message.count(" < ") == 3


def test_capabilities_are_read_from_the_real_context(ctx):
    caps = GLCapabilities.read(ctx)
    assert caps.version_code == ctx.version_code >= 410
    assert caps.renderer and caps.renderer != "?"
    assert caps.max_texture_size == ctx.info["GL_MAX_TEXTURE_SIZE"]
    assert caps.max_cube_map_size == ctx.info["GL_MAX_CUBE_MAP_TEXTURE_SIZE"]
    assert caps.max_clip_distances == ctx.info["GL_MAX_CLIP_DISTANCES"]
    assert all(getattr(caps, name) > 0 for name, _, _ in REQUIREMENTS)   # nothing read as "absent"
    assert caps.extensions == frozenset(ctx.extensions) and caps.extensions
    assert check_capabilities(caps) is caps


def test_prepare_context_checks_and_returns_capabilities(ctx):
    caps = prepare_context(ctx)
    assert isinstance(caps, GLCapabilities)
    assert caps.version_code == ctx.version_code
    assert ctx.gc_mode is None


def test_capabilities_are_what_the_context_reports(ctx):
    """Each limit is read from its own GL query (a swapped or misspelt name would read 0 or
    another limit's value, and the start-up check would then judge the wrong number)."""
    caps = GLCapabilities.read(ctx)
    info = ctx.info
    assert caps.version_code == ctx.version_code
    assert caps.renderer == info["GL_RENDERER"]
    for name in ("max_texture_size", "max_cube_map_size", "max_color_attachments", "max_draw_buffers",
                 "max_uniform_block_size", "max_vertex_attribs", "max_geometry_output_vertices",
                 "max_clip_distances"):
        gl_name = "GL_MAX_CUBE_MAP_TEXTURE_SIZE" if name == "max_cube_map_size" else f"GL_{name.upper()}"
        assert getattr(caps, name) == info[gl_name] > 0, name
    assert caps.extensions == frozenset(ctx.extensions)


# --- the shaders keep to GLSL 4.10 ---------------------------------------------------------------

SHADER_DIR = __import__("pathlib").Path(__file__).resolve().parent.parent / "shaders"

# What GLSL 4.10 has not (each with the version that brought it): Mesa compiles a #version 410
# shader with some of them as extensions of its own where macOS's 4.1 driver refuses them.
PAST_410 = {
    "layout(binding=) (4.20)": r"layout\s*\([^)]*\bbinding\b",
    "layout(location=) on a uniform (4.30)": r"layout\s*\([^)]*\blocation\b[^)]*\)\s*uniform\b",
    "layout(offset=/align=) (4.40)": r"layout\s*\([^)]*\b(offset|align)\b",
    "std430 (4.30)": r"\bstd430\b",
    "a buffer block, an SSBO (4.30)": r"(^|[;}\s)])buffer\s+\w+\s*\{",
    "image types and loads/stores (4.20)": r"\b[iu]?image(1D|2D|3D|Cube|2DRect|Buffer|1DArray|2DArray|CubeArray|2DMS|"
                                           r"2DMSArray)\b|\bimage(Load|Store|Size|Samples|Atomic\w*)\s*\(",
    "memory qualifiers (4.20)": r"\b(coherent|volatile|restrict|readonly|writeonly)\b",
    "atomic counters and buffer atomics (4.20/4.30)": r"\batomic_uint\b|\batomic(Counter\w*|Add|Min|Max|And|Or|Xor|"
                                                      r"Exchange|CompSwap)\s*\(",
    "compute shaders (4.30)": r"\bgl_(GlobalInvocationID|LocalInvocationID|LocalInvocationIndex|WorkGroupID|"
                              r"NumWorkGroups|WorkGroupSize)\b|\blocal_size_[xyz]\b|\bshared\s+\w+\s+\w+|"
                              r"\bmemoryBarrier\w*\s*\(|\bgroupMemoryBarrier\s*\(",
    "textureQueryLevels (4.30)": r"\btextureQueryLevels\s*\(",
    "textureSamples (4.50)": r"\btextureSamples\s*\(",
    "early_fragment_tests (4.20)": r"\bearly_fragment_tests\b",
    "gl_HelperInvocation (4.50)": r"\bgl_HelperInvocation\b",
    "fine and coarse derivatives (4.50)": r"\b(dFdx|dFdy|fwidth)(Fine|Coarse)\s*\(",
    "packHalf2x16, pack/unpackSnorm2x16 (4.20)": r"\b(un)?packHalf2x16\s*\(|\b(un)?packSnorm2x16\s*\(",
    "initializer lists (4.20)": r"=\s*\{",
    "#extension": r"#\s*extension\b",
}


def _glsl_code(text: str) -> str:
    """``text`` without its comments (what the compiler reads)."""
    import re

    return re.sub(r"//[^\n]*", "", re.sub(r"/\*.*?\*/", " ", text, flags=re.S))


def test_every_shader_is_glsl_410_core_and_uses_nothing_past_it():
    """Each stage file under shaders/ starts ``#version 410 core`` and no file (stages and
    includes, comments left out) uses what GLSL 4.10 lacks: layout(binding=), SSBOs, std430,
    images, atomics, compute, textureQueryLevels, ... (PAST_410: each names the version it
    came in), gl_Layer read in a fragment shader (4.30), or any #extension.  Nothing of 4.2+
    sits behind a define here: the start-up check sets none, so none may."""
    import re

    stages = sorted(p for p in SHADER_DIR.iterdir() if p.suffix in (".vert", ".frag", ".geom"))
    includes = sorted((SHADER_DIR / "include").glob("*.glsl"))
    assert len(stages) > 40 and len(includes) > 40
    assert not [p.name for p in SHADER_DIR.rglob("*") if p.suffix in (".comp", ".tesc", ".tese", ".mesh")]
    found = []
    for path in stages + includes:
        text = path.read_text()
        if path in stages:
            assert text.startswith("#version 410 core\n"), path.name
        else:
            assert "#version" not in text, path.name   # the library inserts the version, includes never repeat it
        code = _glsl_code(text)
        for what, pattern in PAST_410.items():
            for match in re.finditer(pattern, code, flags=re.M):
                line = code[:match.start()].count("\n") + 1
                found.append(f"{path.name}:{line}: {what}: {match.group(0).strip()!r}")
        if path.suffix == ".frag" and re.search(r"\bgl_Layer\b", code):
            found.append(f"{path.name}: gl_Layer read in a fragment shader (4.30)")
    assert not found, "\n".join(found)


@pytest.mark.parametrize("line, what", [
    ("layout(std140, binding = 2) uniform Camera { mat4 m; };", "layout(binding=)"),
    ("layout(std430) buffer Rows { vec4 rows[]; };", "std430"),
    ("readonly buffer Rows { vec4 rows[]; };", "a buffer block"),
    ("layout(rgba16f) uniform image2D target;", "image types"),
    ("float levels = float(textureQueryLevels(probe));", "textureQueryLevels"),
    ("layout(local_size_x = 8) in;", "compute shaders"),
    ("#extension GL_ARB_shading_language_420pack : require", "#extension"),
    ("const float w[3] = {0.25, 0.5, 0.25};", "initializer lists"),
    ("layout(location = 3) uniform float scale;", "layout(location=) on a uniform"),
])
def test_the_shader_scan_sees_each_feature_past_410(line, what):
    """The scan above is not vacuous: each of a sample of 4.2+ lines is caught by the pattern
    for its feature (and a commented-out one is not)."""
    import re

    hits = [name for name, pattern in PAST_410.items() if re.search(pattern, _glsl_code(line), flags=re.M)]
    assert any(name.startswith(what) for name in hits), (line, hits)
    assert not any(re.search(p, _glsl_code("// " + line), flags=re.M) for p in PAST_410.values())
