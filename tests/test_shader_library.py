"""The shader library: includes resolve, cycles and missing files are named, and a compile
error points at the file and line a person edits, not at the expanded text."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from engine.errors import ShaderError
from engine.shader_library import ShaderLibrary, load_source, shader_dir

VERTEX = """#version 410 core
in vec2 in_position;
void main() { gl_Position = vec4(in_position, 0.0, 1.0); }
"""


def write(root: Path, files: dict[str, str]) -> Path:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root


def build(ctx, root: Path, fragment: str = "main.frag"):
    library = ShaderLibrary(ctx, root)
    try:
        return library.program("main.vert", fragment)
    finally:
        library.release()


def test_includes_resolve_in_place_and_nested(ctx, tmp_path):
    root = write(tmp_path, {
        "main.vert": VERTEX,
        "include/colour.glsl": '#include "base.glsl"\nvec3 colour() { return base() * 0.5; }\n',
        "include/base.glsl": "vec3 base() { return vec3(1.0, 0.5, 0.25); }\n",
        "main.frag": '#version 410 core\n#include "colour.glsl"\nout vec4 c;\nvoid main() { c = vec4(colour(), 1); }\n',
    })
    text = load_source("main.frag", root=root)
    assert text.index("vec3 base()") < text.index("vec3 colour()") < text.index("void main()")
    build(ctx, root)  # compiles: every function arrived before its use


def test_an_include_cycle_is_named(tmp_path):
    root = write(tmp_path, {
        "main.frag": '#version 410 core\n#include "a.glsl"\n',
        "include/a.glsl": '#include "b.glsl"\n',
        "include/b.glsl": '#include "a.glsl"\n',
    })
    with pytest.raises(ShaderError, match=r"include cycle: main\.frag -> include/a\.glsl -> include/b\.glsl "
                                          r"-> include/a\.glsl"):
        load_source("main.frag", root=root)


def test_a_missing_include_names_the_file_and_who_includes_it(tmp_path):
    root = write(tmp_path, {"main.frag": '#version 410 core\n#include "gone.glsl"\n'})
    with pytest.raises(ShaderError, match=r"'include/gone\.glsl' not found .*included from 'main\.frag'"):
        load_source("main.frag", root=root)


def test_a_shader_without_the_baseline_version_is_refused(tmp_path):
    root = write(tmp_path, {"main.frag": "#version 460 core\nvoid main() {}\n"})
    with pytest.raises(ShaderError, match="must start with '#version 410 core'"):
        load_source("main.frag", root=root)


def test_an_error_after_an_include_names_the_files_own_line(ctx, tmp_path):
    root = write(tmp_path, {
        "main.vert": VERTEX,
        "include/long.glsl": "".join(f"float f{i}() {{ return {i}.0; }}\n" for i in range(40)),
        "main.frag": ('#version 410 core\n#include "long.glsl"\nout vec4 c;\n\nvoid main() {\n'
                      '    c = vec4(1.0);\n    c.x = undefined_name;\n}\n'),
    })
    with pytest.raises(ShaderError) as info:
        build(ctx, root)
    message = str(info.value)
    assert "main.frag:7" in message and "undefined_name" in message, message


def test_an_error_inside_an_include_names_the_include_and_its_line(ctx, tmp_path):
    root = write(tmp_path, {
        "main.vert": VERTEX,
        "include/broken.glsl": "float ok() { return 1.0; }\n\nfloat bad() { return 1.0 }\n",
        "main.frag": '#version 410 core\nout vec4 c;\n#include "broken.glsl"\nvoid main() { c = vec4(ok()); }\n',
    })
    with pytest.raises(ShaderError) as info:
        build(ctx, root)
    assert "include/broken.glsl:3" in str(info.value), str(info.value)


def test_an_error_in_the_real_scene_shader_is_reported_at_its_line(ctx, tmp_path):
    """The case that used to read "line 74": scene.frag's line 8 comes after its includes."""
    root = tmp_path / "shaders"
    shutil.copytree(shader_dir(), root, ignore=shutil.ignore_patterns("__pycache__", "*.py"))
    lines = (root / "scene.frag").read_text().split("\n")
    assert any('#include' in line for line in lines[:7]), "line 8 should come after an include"
    lines[7] = "float broken_on_line_eight = ;"
    (root / "scene.frag").write_text("\n".join(lines))
    library = ShaderLibrary(ctx, root)
    with pytest.raises(ShaderError) as info:
        library.program("scene.vert", "scene.frag")
    library.release()
    assert "scene.frag:8" in str(info.value), str(info.value)
