"""The shader library: includes resolve, cycles and missing files are named, and a compile
error points at the file and line a person edits, not at the expanded text."""
from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from engine.core.errors import ShaderError
from engine.render.shader_library import ShaderBuildError, ShaderLibrary, SourceFiles, load_source, shader_dir

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


BRANCHED = """#version 410 core
#ifdef A
#include "a.glsl"
#elif B_EXPRESSION
#include "b.glsl"
#else
#include "c.glsl"
#endif
#ifndef A
#define LOCAL
#endif
#ifdef LOCAL
#include "local.glsl"
#endif
#if defined(A) && defined(Z)
#include "expression.glsl"
#endif
#ifdef A
#ifdef Z
#include "nested.glsl"
#endif
#else
#include "not_a.glsl"
#endif
out vec4 c;
void main() { c = vec4(value()); }
"""


@pytest.mark.parametrize("defines, expected", [
    ({}, {"c", "local", "expression", "not_a"}),
    ({"A": "1"}, {"a", "expression"}),
    ({"A": "1", "Z": "1"}, {"a", "expression", "nested"}),
])
def test_an_include_in_a_branch_the_build_leaves_out_is_not_one_of_its_files(ctx, tmp_path, defines, expected):
    """An ``#include`` in an ``#ifdef`` branch the build's defines leave out is not expanded (its
    file is none of the program's: an edit to it rebuilds nothing); one behind an ``#if``
    expression (or an ``#elif``, unknown) is, as the driver may keep it.  The numbering still
    names the right line: each build compiles, and an error after the branches is placed."""
    root = write(tmp_path, {"main.frag": BRANCHED, "main.vert": VERTEX, **{
        f"include/{name}.glsl": "#ifndef VALUE\n#define VALUE\nfloat value() { return 1.0; }\n#endif\n"
        for name in ("a", "b", "c", "local", "expression", "nested", "not_a")}})
    files = SourceFiles()
    text = load_source("main.frag", defines, root=root, files=files)
    assert {Path(name).stem for name in files.names[2:]} == expected | ({"b"} if "A" not in defines else set())
    assert files.names[:2] == ["(generated defines)", "main.frag"]
    assert "#include" not in text
    library = ShaderLibrary(ctx, root)
    try:
        library.program("main.vert", "main.frag", None, defines)
        (root / "main.frag").write_text(BRANCHED + "float broken = undeclared_name;\n")
        fresh = ShaderLibrary(ctx, root)  # (no cached program)
        with pytest.raises(ShaderBuildError, match=f"main.frag:{BRANCHED.count(chr(10)) + 1}:"):
            fresh.program("main.vert", "main.frag", None, defines)
        fresh.release()
    finally:
        library.release()


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


def test_no_program_text_ends_with_a_line_directive(ctx, tmp_path):
    """The numbering is resumed after each ``#endif``; a stage file ending with one left a
    ``#line`` as the last line of its program's text, with no line to number, which NVIDIA's
    compiler refuses ("#line line number invalid": particle.vert on the H200).  The text of
    every stage file, with and without its switches, ends with a line of its own, and a file
    ending with ``#endif`` builds."""
    for path in sorted(shader_dir().glob("*.*")):
        if path.suffix not in (".vert", ".frag", ".geom"):
            continue
        switches = set(re.findall(r"^\s*#\s*if(?:n?def)?\s+(\w+)", path.read_text(), re.MULTILINE))
        for defines in ({}, dict.fromkeys(switches, "1")):
            last = load_source(path.name, defines).rstrip("\n").rsplit("\n", 1)[-1]
            assert not last.startswith("#line"), (path.name, defines, last)
    root = write(tmp_path, {"main.vert": VERTEX,
                            "main.frag": "#version 410 core\nout vec4 c;\n#ifdef RED\nvoid main() { c = vec4(1.0); }\n"
                                         "#else\nvoid main() { c = vec4(0.5); }\n#endif\n"})
    assert load_source("main.frag", root=root).endswith("#endif\n")
    build(ctx, root)


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


# --- every driver's log, rewritten in the engine's one form ------------------------------------
# The engine's form of a compiler message (engine.render.shader_library.Diagnostic): the file a person
# edits, its line, the column where the driver gives one, the severity, the driver's text.
ONE_FORM = re.compile(r"^(?P<file>[\w./-]+):(?P<line>\d+)(?::(?P<column>\d+))?: (?P<severity>error|warning): "
                      r"(?P<text>.*)$")

PROGRAM = {
    "main.frag": ('#version 410 core\n'            # 1
                  '// main\n'                      # 2
                  '#include "outer.glsl"\n'        # 3
                  'out vec4 c;\n'                  # 4
                  '\n'                             # 5
                  'void main() {\n'                # 6
                  '    c = vec4(main_marker);\n'   # 7
                  '}\n'),
    "include/outer.glsl": ('// outer\n'                 # 1
                           '#include "inner.glsl"\n'    # 2
                           '\n'                         # 3
                           'float outer_marker = 1.0;\n'),  # 4
    "include/inner.glsl": ('// inner\n'                      # 1
                           '\n'                              # 2
                           'float inner_marker = 2.0;\n'),   # 3
}
WHERE = {"main": ("main.frag", 7), "outer": ("include/outer.glsl", 4), "inner": ("include/inner.glsl", 3)}


def driver_lines(expanded: str) -> dict[str, int]:
    """The line number a GLSL compiler gives each marker's line of ``expanded`` (``#line N``
    makes the next line N), as the driver would write it in its log."""
    found, number = {}, 1
    for text in expanded.split("\n"):
        for marker in WHERE:
            if f"{marker}_marker" in text:
                found[marker] = number
        directive = re.match(r"\s*#line\s+(\d+)\s*$", text)
        number = int(directive.group(1)) if directive else number + 1
    return found


# Raw info logs as each vendor writes them (several errors, warnings, the lines around them),
# with {main}, {outer}, {inner} standing for the line numbers the driver reports, and what each
# message must become: (marker, column, severity, a piece of the text), in order.
VENDOR_LOGS = {
    "mesa": ("GLSL Compiler failed\n\nfragment_shader\n===============\n"
             "0:{main}(14): error: `main_marker' undeclared\n"
             "0:{main}(7): error: operands to arithmetic operators must be numeric\n"
             "0:{inner}(7): warning: `inner_marker' used uninitialized\n"
             "0:{outer}(1): preprocessor error: syntax error, unexpected IDENTIFIER\n\n",
             [("main", 14, "error", "`main_marker' undeclared"),
              ("main", 7, "error", "operands to arithmetic operators must be numeric"),
              ("inner", 7, "warning", "`inner_marker' used uninitialized"),
              ("outer", 1, "error", "syntax error, unexpected IDENTIFIER")]),
    "nvidia": ("GLSL Compiler failed\n\nfragment_shader\n===============\n"
               '0({main}) : error C1503: undefined variable "main_marker"\n'
               '0({outer}) : error C1038: declaration of "outer_marker" conflicts with previous '
               'declaration at 0({inner})\n'
               '0({inner}) : warning C7050: "inner_marker" might be used before being initialized\n'
               "0({main}) : error C0000: syntax error, unexpected '}}', expecting ',' or ';' at token \"}}\"\n"
               "(0) : error C5145: must write to gl_Position\n",
               [("main", None, "error", 'undefined variable "main_marker" [C1503]'),
                ("outer", None, "error", 'conflicts with previous declaration at include/inner.glsl:3 [C1038]'),
                ("inner", None, "warning", '"inner_marker" might be used before being initialized [C7050]'),
                ("main", None, "error", "syntax error, unexpected '}', expecting ',' or ';' at token \"}\" [C0000]"),
                (None, None, "error", "must write to gl_Position [C5145]")]),
    "amd_intel_glslang": ("ERROR: 0:{main}: 'main_marker' : undeclared identifier \n"
                          "ERROR: 0:{main}: 'assign' :  cannot convert from ' const float' to ' out 4-component "
                          "vector of float'\n"
                          "WARNING: 0:{inner}: 'inner_marker' : variable may be used before initialised\n"
                          "ERROR: 0:{outer}: '' : compilation terminated \n"
                          "ERROR: 3 compilation errors.  No code generated.\n",
                          [("main", None, "error", "'main_marker' : undeclared identifier"),
                           ("main", None, "error", "'assign' :  cannot convert from ' const float'"),
                           ("inner", None, "warning", "'inner_marker' : variable may be used before initialised"),
                           ("outer", None, "error", "'' : compilation terminated")]),
    "amd_catalyst": ("Fragment shader failed to compile with the following errors:\r\n"
                     "ERROR: 0:{main}: error(#143) Undeclared identifier: main_marker\r\n"
                     "WARNING: 0:{inner}: warning(#402) Implicit truncation of vector from size: 4 to size: 3\r\n"
                     "ERROR: 0:{outer}: error(#216) Vector field selection out of range \"xyz\"\r\n"
                     "ERROR: error(#273) 2 compilation errors.  No code generated\r\n",
                     [("main", None, "error", "Undeclared identifier: main_marker [#143]"),
                      ("inner", None, "warning", "Implicit truncation of vector from size: 4 to size: 3 [#402]"),
                      ("outer", None, "error", 'Vector field selection out of range "xyz" [#216]')]),
    "apple": ("ERROR: 0:{main}: Use of undeclared identifier 'main_marker'\n"
              "WARNING: 0:{outer}: Overflow in implicit constant conversion, minimum range for lowp float is (-2,2)\n"
              "ERROR: 0:{inner}: Invalid call of undeclared identifier 'texture2D'\n",
              [("main", None, "error", "Use of undeclared identifier 'main_marker'"),
               ("outer", None, "warning", "Overflow in implicit constant conversion"),
               ("inner", None, "error", "Invalid call of undeclared identifier 'texture2D'")]),
}


@pytest.mark.parametrize("vendor", sorted(VENDOR_LOGS))
def test_every_vendors_log_is_rewritten_at_the_edited_file_and_line(tmp_path, vendor):
    """Each vendor's raw log, with the line numbers a driver reports for this program (a line
    of main.frag, of an include and of an include's include), comes out in the engine's one
    form at the file and line a person edits; the other lines are kept, the rules dropped."""
    root = write(tmp_path, PROGRAM)
    files = SourceFiles()
    lines = driver_lines(load_source("main.frag", root=root, files=files))
    assert set(lines) == set(WHERE) and len(set(lines.values())) == 3, lines
    raw, expected = VENDOR_LOGS[vendor]
    log = raw.format(**lines)

    found = files.diagnostics(log)
    assert len(found) == len(expected), found
    for diagnostic, (marker, column, severity, text) in zip(found, expected, strict=True):
        where = WHERE[marker] if marker else (None, None)
        assert (diagnostic.file, diagnostic.line) == where, (diagnostic, log)
        assert (diagnostic.column, diagnostic.severity) == (column, severity), diagnostic
        assert text in diagnostic.text, diagnostic

    readable = files.readable(log).split("\n")
    formed = [ONE_FORM.match(line) for line in readable]
    assert [m.group("file", "line") for m in formed if m] == \
        [(d.file, str(d.line)) for d in found if d.file is not None], readable
    in_form = [line for line, match in zip(readable, formed, strict=True) if match]
    assert in_form == [str(d) for d in found if d.file is not None], readable
    for line in readable:  # nothing left in a driver's numbering, no blank lines or rules
        assert line.strip() and not re.fullmatch(r"[=-]+", line.strip()), readable
        assert not re.search(r"\b\d+[:(]\d{6}", line) and "\r" not in line, line


def test_a_line_number_no_file_has_is_left_as_the_driver_wrote_it():
    files = SourceFiles(["(generated defines)", "main.frag"])
    log = "0:900012(3): error: from nowhere\n0:100002(3): error: `x' undeclared"
    assert files.readable(log).split("\n") == ["0:900012(3): error: from nowhere",
                                                "main.frag:2:3: error: `x' undeclared"]


def test_a_build_error_carries_its_messages_in_the_one_form(ctx, tmp_path):
    """Whatever the driver here is, the ShaderError of a failed build names the include file
    and line of the mistake, in the engine's form, and carries it as a Diagnostic."""
    root = write(tmp_path, {**PROGRAM, "main.vert": VERTEX,
                            "include/inner.glsl": "// inner\n\nfloat inner_marker = inner_undeclared;\n"})
    with pytest.raises(ShaderBuildError) as info:
        build(ctx, root)
    errors = [d for d in info.value.diagnostics if d.severity == "error"]
    assert any((d.file, d.line) == ("include/inner.glsl", 3) and "inner_undeclared" in d.text for d in errors), \
        errors
    assert any(ONE_FORM.match(line) and line.startswith("include/inner.glsl:3")
               for line in str(info.value).split("\n")), str(info.value)
