"""Shader hot reload: editing a file under ``shaders/`` rebuilds the programs built from it;
a build that fails leaves the old program drawing and names the file and line; and a
compile error names the right file and line in every program the engine builds.

The tests work on a copy of ``shaders/`` in a temporary folder (the library's files are
found through ``engine.render.shader_library.shader_dir``, pointed at the copy), render real
frames and compare their pixels."""
from __future__ import annotations

import contextlib
import os
import re
import shutil
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from pyglm import glm

import engine.render.shader_library as shader_library
from components import DirectionalLight, Material, MeshRef, Mirror, ReflectionProbe, Skybox, Transform
from engine.assets.mesh import box, plane, quad, sphere
from engine.assets.portals import spawn_portal_pair
from engine.assets.texture_data import ripple_normal_map
from engine.core.errors import ShaderError
from engine.render.shader_library import POLL_INTERVAL, ShaderLibrary, load_source
from tests.support import linear_to_srgb8, look_from

SIZE = (96, 72)
SCENE_COLOUR = "out_color = vec4(hdr_store(color),"  # scene.frag's colour write, where edits go before
BOX_AT = (0.9, 0.5, 0.5)


@pytest.fixture
def shader_copy(tmp_path, monkeypatch) -> Path:
    """A copy of ``shaders/`` every ShaderLibrary made in the test reads."""
    root = tmp_path / "shaders"
    shutil.copytree(shader_library.shader_dir(), root, ignore=shutil.ignore_patterns("__pycache__", "*.py"))
    monkeypatch.setattr(shader_library, "shader_dir", lambda: root)
    return root


def room(world) -> None:
    look_from(world, (0.0, 1.4, 4.0), (0.0, 0.8, 0.0))
    world.spawn(Skybox())
    world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.5), intensity=2.0))
    world.spawn(Transform(), MeshRef(plane(8, 8)), Material(color=(0.5, 0.5, 0.5)))
    world.spawn(Transform(position=BOX_AT), MeshRef(box((0.6, 0.6, 0.6))), Material(color=(0.2, 0.6, 0.2)))
    world.spawn(Transform(position=(0, 1.3, -1.5)), MeshRef(quad(3, 2)), Material(), Mirror(color=(0.9, 0.9, 1.0)))


def edit(root: Path, name: str, before: str, new_line: str | None) -> int:
    """Put ``new_line`` just before the first line containing ``before`` (None: remove that
    line); returns the new line's number (1-based)."""
    path = root / name
    lines = path.read_text().split("\n")
    at = next(i for i, line in enumerate(lines) if before in line)
    if new_line is None:
        del lines[at]
    else:
        lines.insert(at, new_line)
    path.write_text("\n".join(lines))
    return at + 1


def test_a_broken_edit_keeps_the_old_program_and_names_file_and_line_then_a_fix_is_drawn(scene, shader_copy):
    runner = scene(room, SIZE)
    library: ShaderLibrary = runner.engine.renderer.shaders
    first = runner.frame()
    assert np.array_equal(runner.frame(), first)  # a still scene: frames repeat exactly
    assert library.poll(now=1000.0) == []  # nothing edited, nothing rebuilt or said

    # A name that does not exist, on a known line of scene.frag, after its three includes.
    line = edit(shader_copy, "scene.frag", SCENE_COLOUR, "    color += undefined_hot_reload_name;")
    messages = library.poll(now=1001.0)
    scene_programs = [key for key in library._programs if key[1] == "scene.frag"]
    assert len(scene_programs) > 1 and len(messages) == 1, messages  # the variants fail alike: said once
    found = [m for m in map(DIAGNOSTIC.search, messages[0].split("\n")) if m]
    assert any(m.group("file", "line", "severity") == ("scene.frag", str(line), "error")
               and "undefined_hot_reload_name" in m.group("text") for m in found), messages
    assert set(library.errors) == set(scene_programs)
    assert library.poll(now=1002.0) == []  # said once per change
    assert np.array_equal(runner.frame(), first), "the previous programs must keep drawing"

    # The fix, with a visible change: every lit surface magenta.
    edit(shader_copy, "scene.frag", "    color += undefined_hot_reload_name;", None)
    edit(shader_copy, "scene.frag", SCENE_COLOUR, "    color = vec3(1.0, 0.0, 1.0);")
    messages = library.poll(now=1003.0)
    assert messages == [f"shader reloaded: scene.frag ({len(scene_programs)} programs rebuilt)"], messages
    assert library.errors == {} and library.reloads == len(scene_programs)
    magenta = runner.frame()
    column, row = runner.project(BOX_AT)
    assert magenta[row, column].tolist() == [255, 0, 255], magenta[row, column]
    assert np.array_equal(magenta[0, 0], first[0, 0])  # the sky's own program did not change

    # Back to the shipped text: the same frame as at the start, so every sampler unit, block
    # binding and vertex input the engine set up once survived two rebuilds (the magenta
    # build dropped most of them).
    shutil.copy(Path(__file__).parents[1] / "shaders" / "scene.frag", shader_copy / "scene.frag")
    assert library.poll(now=1004.0)
    assert np.array_equal(runner.frame(), first)


def test_reordered_vertex_inputs_keep_every_vertex_array_working(scene, shader_copy):
    """The relinked program keeps each vertex input at its old location (the batches' vertex
    arrays were made for those): declaring in_normal before in_position changes nothing."""
    runner = scene(room, SIZE)
    library = runner.engine.renderer.shaders
    first = runner.frame()
    text = (shader_copy / "scene.vert").read_text()
    a, b = "in vec3 in_position;", "in vec3 in_normal;"
    assert a in text and b in text
    (shader_copy / "scene.vert").write_text(text.replace(a, "@").replace(b, a).replace("@", b))
    assert library.poll(now=1000.0) and library.errors == {}
    assert np.array_equal(runner.frame(), first)


def test_files_are_looked_at_at_most_every_poll_interval(ctx, shader_copy):
    library = ShaderLibrary(ctx)
    try:
        program = library.program("present.vert", "present.frag")
        assert library.poll(now=50.0) == []
        edit(shader_copy, "include/color.glsl", "", "// an edit")
        assert library.poll(now=50.0 + POLL_INTERVAL / 2) == []  # too soon: not looked at
        assert library.poll(now=50.0 + POLL_INTERVAL) == ["shader reloaded: include/color.glsl (1 program rebuilt)"]
        assert library.program("present.vert", "present.frag") is program  # the same object, relinked
        assert library.poll(now=60.0) == []
    finally:
        library.release()


def test_a_deleted_file_is_an_error_until_it_is_back(ctx, shader_copy):
    library = ShaderLibrary(ctx)
    try:
        library.program("fullscreen.vert", "mirror_claim.frag")
        saved = (shader_copy / "mirror_claim.frag").read_text()
        (shader_copy / "mirror_claim.frag").unlink()
        (message,) = library.poll(now=1.0)
        assert "'mirror_claim.frag' not found" in message
        (shader_copy / "mirror_claim.frag").write_text(saved)
        assert library.poll(now=2.0) == ["shader reloaded: mirror_claim.frag (1 program rebuilt)"]
        assert library.errors == {}
    finally:
        library.release()


def test_an_include_inside_a_dropped_branch_does_not_shift_later_lines(ctx, tmp_path):
    """The preprocessor skips the #line directives of a branch it drops but counts its
    lines; the numbering is resumed after the branch."""
    (tmp_path / "include").mkdir()
    (tmp_path / "include" / "long.glsl").write_text("".join(f"float f{i}() {{ return {i}.0; }}\n" for i in range(30)))
    (tmp_path / "main.vert").write_text("#version 410 core\nvoid main() { gl_Position = vec4(0.0); }\n")
    (tmp_path / "main.frag").write_text('#version 410 core\n#ifdef UNSET\n#include "long.glsl"\n#endif\n'
                                        "out vec4 c;\nvoid main() { c = vec4(missing_name); }\n")
    library = ShaderLibrary(ctx, tmp_path)
    with pytest.raises(ShaderError, match=r"main\.frag:6(:\d+)?: error: .*missing_name"):
        library.program("main.vert", "main.frag")
    library.release()


def every_program_scene(world) -> None:
    """A mirror (sharp and rough, one with a normal map), a portal pair, a probe captured
    both ways: the engine builds most of its programs, geometry-shader and specialised
    variants included."""
    room(world)
    world.spawn(Transform(position=(-1.5, 1.0, -1.0)), MeshRef(quad(1, 1)), Material(), Mirror(roughness=0.3))
    world.spawn(Transform(position=(1.5, 1.0, -1.0)), MeshRef(quad(1, 1)),
                Material(normal_map=ripple_normal_map(32, 2)), Mirror())
    spawn_portal_pair(world, (-2.5, 1.0, 0.0), glm.angleAxis(0.5, glm.vec3(0, 1, 0)), (2.5, 1.0, 0.0),
                      glm.angleAxis(-0.5, glm.vec3(0, 1, 0)), size=(1.0, 1.6))
    world.spawn(Transform(position=(-0.8, 0.5, 0.8)), MeshRef(sphere(0.4)), Material(metallic=1.0, roughness=0.1),
                ReflectionProbe(resolution=16, refresh="every_frame", prefilter="ggx"))


def probe_scene(world) -> None:
    look_from(world, (0.0, 1.0, 3.0), (0.0, 0.5, 0.0))
    world.spawn(Skybox())
    world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.5), intensity=2.0))
    world.spawn(Transform(position=BOX_AT), MeshRef(box((0.6, 0.6, 0.6))), Material(color=(0.2, 0.6, 0.2)))
    world.spawn(Transform(position=(-0.5, 0.5, 0.0)), MeshRef(sphere(0.4)), Material(metallic=1.0, roughness=0.0),
                ReflectionProbe(resolution=16, refresh="every_frame"))


PROBE = "hot_reload_line_probe_"


def test_every_program_the_engine_builds_reports_errors_at_the_edited_file_and_line(scene, shader_copy):
    """Each file of each program gets an undeclared name on a new last line; the build's
    log must name that file and line for every error, and every file of every stage must
    be reached (files of a stage that compiled are probed again until none is left)."""
    runner = scene(every_program_scene, (64, 48))
    runner.engine.stages["probes"].path = "six_pass"
    runner.engine.reflection_system.path = "batched"
    runner.frame()
    layered = scene(probe_scene, (64, 48))  # a probe that sees no mirror or portal can take the layered path
    layered.engine.stages["probes"].path = "layered"
    layered.frame()
    renderer = layered.engine.renderer
    if not renderer.path_checks.trusted("layered_capture"):  # a driver whose layered draws were refused
        # (the H200's): its programs are still built and reported
        renderer.scene_pass.sky_draw.vertex_array(layered=True)
    if not renderer.path_checks.trusted("layered_mips"):
        renderer.probes.mips._program_vao(ggx=False, one_face=False)
    programs = list(dict.fromkeys([*runner.engine.renderer.shaders._programs,
                                   *layered.engine.renderer.shaders._programs]))
    geometry = {key[2] for key in programs}
    assert {"scene_layered.geom", "sky_layered.geom", "cube_mip.geom"} <= geometry, geometry
    assert any(key[3] for key in programs)  # specialised with defines
    originals = {p.relative_to(shader_copy).as_posix(): p.read_text()
                 for p in shader_copy.rglob("*") if p.suffix in (".vert", ".frag", ".geom", ".glsl")}
    checked = 0
    for vertex, fragment, geometry, defines in programs:
        library = ShaderLibrary(runner.ctx)  # a fresh cache, so each build compiles
        files = shader_library.SourceFiles()
        for name in filter(None, (vertex, fragment, geometry)):
            load_source(name, dict(defines), files=files)
        waiting = {}
        for name in files.names[1:]:
            text = originals[name].rstrip("\n")
            marker = PROBE + re.sub(r"\W", "_", name)
            waiting[name] = (marker, text.count("\n") + 2)
            (shader_copy / name).write_text(f"{text}\nfloat {marker} = {marker}_undeclared;\n")
        try:
            while waiting:
                with pytest.raises(ShaderError) as info:
                    library.program(vertex, fragment, geometry, dict(defines))
                message = str(info.value)
                reported = {(m.group("file"), m.group("line"), marker.group(1))
                            for m in map(DIAGNOSTIC.match, message.split("\n")) if m and m.group("severity") == "error"
                            for marker in [re.search(rf"({PROBE}\w+?)_undeclared", m.group("text"))] if marker}
                assert reported, message
                for where, line, marker in reported:
                    name = next(n for n, (m, _) in waiting.items() if m == marker)
                    assert (where, int(line)) == (name, waiting[name][1]), message
                    checked += 1
                for name in {n for n, (m, _) in waiting.items() if m in {r[2] for r in reported}}:
                    (shader_copy / name).write_text(originals[name])
                    del waiting[name]
        finally:
            library.release()
            for name in files.names[1:]:
                (shader_copy / name).write_text(originals[name])
    assert checked >= len(programs) * 2


def test_the_window_shell_polls_and_says_each_reload_once(shader_copy, capsys):
    """Windowed runs poll the library each frame: an edit is drawn, and said in one line
    (however many variants were rebuilt), without the variants' defines."""
    with window_shell() as config:
        library = config.engine.renderer.shaders
        config.on_render(0.0, 1 / 60)
        before = np.frombuffer(config.wnd.fbo.read(components=3), np.uint8).copy()
        edit(shader_copy, "scene.frag", SCENE_COLOUR, "    color = vec3(0.0, 1.0, 1.0);")
        library._next_poll = 0.0  # as if half a second had passed
        for _ in range(3):
            config.on_render(0.0, 1 / 60)
        after = np.frombuffer(config.wnd.fbo.read(components=3), np.uint8)
        assert (after != before).any() and library.reloads > 1
        said = [line for line in capsys.readouterr().err.splitlines() if "shader" in line]
        assert said == [f"speculum: shader reloaded: scene.frag ({library.reloads} programs rebuilt)"], said


def test_a_uniform_the_first_build_dropped_is_fed_after_a_reload(scene, shader_copy):
    """The plain box's program never read sky_face_size (only sky-reflecting variants do),
    so the linker dropped it; an edit that reads it gets its value on the next frame, not a
    0 left from a cache made before the reload."""
    runner = scene(room, SIZE)
    library = runner.engine.renderer.shaders
    runner.frame()
    sky_size = runner.engine.renderer.sky.size[0]
    assert sky_size > 0
    edit(shader_copy, "scene.frag", SCENE_COLOUR, "    color = vec3(sky_face_size / 1024.0, 0.0, 0.0);")
    assert library.poll(now=1000.0) and library.errors == {}
    rgb = runner.frame()
    column, row = runner.project(BOX_AT)
    expected = linear_to_srgb8(np.array([sky_size / 1024.0]))[0]  # present: linear -> sRGB
    assert abs(int(rgb[row, column, 0]) - int(expected)) <= 2 and rgb[row, column, 1] == 0, \
        (rgb[row, column].tolist(), expected)


def test_a_vertex_input_the_first_build_dropped_is_fed_after_a_reload(scene, shader_copy):
    """The plain box's program never read its instances' tint (only reflecting variants do),
    so the linker dropped the input and the box's vertex array was made without it; an edit
    that reads it gets the instance's tint on the next frame (the vertex arrays are made
    again for the relinked programs), not the default (0, 0, 0, 1) of an unfed input."""
    runner = scene(room, SIZE)
    library = runner.engine.renderer.shaders
    runner.frame()
    edit(shader_copy, "scene.frag", SCENE_COLOUR, "    color = v_tint.rgb * 0.5;")
    assert library.poll(now=1000.0) and library.errors == {}
    rgb = runner.frame()
    column, row = runner.project(BOX_AT)
    box_entity = next(e for e, t in runner.world.query_one(Transform) if np.allclose(tuple(t.position), BOX_AT))
    batch = next(b for b in runner.engine.renderer.batches.values() if box_entity in list(b.entity_at[:b.count]))
    tint = batch.row(box_entity)["tint"][:3] * 0.5
    assert tint.max() > 0.1  # a tint that shows (an unfed input reads 0)
    expected = linear_to_srgb8(np.asarray(tint, np.float64))
    assert np.abs(rgb[row, column].astype(int) - expected.astype(int)).max() <= 2, (rgb[row, column].tolist(), expected)


def test_a_composite_column_the_first_build_dropped_is_fed_after_a_reload(scene, shader_copy):
    """The sharp mirror composite never read the portal's carry rotation, so its rows' vertex
    format skipped that column; an edit that reads it (a mirror's carry is the identity: its
    first column is red) gets the rows' values once the format and array are made again."""
    runner = scene(room, SIZE)
    library = runner.engine.renderer.shaders
    before = runner.frame()
    column, row = runner.project((0.0, 1.3, -1.5))  # the mirror's centre
    edit(shader_copy, "mirror_composite.frag",
         "out_color = vec4(hdr_store(fog_over(reflected, parent_fog)), weight);", "    reflected = v_carry[0];")
    assert library.poll(now=1000.0) and library.errors == {}
    rgb = runner.frame().astype(int)
    red, green = rgb[row, column, 0], rgb[row, column, 1]
    assert red > green + 60 and red > int(before[row, column, 0]) + 30, (rgb[row, column].tolist(),
                                                                          before[row, column].tolist())


# --- hot reload never raises, hangs, or says a thing twice (issue 26) ---------------------------
DIAGNOSTIC = re.compile(r"(?P<file>[\w./-]+):(?P<line>\d+)(?::\d+)?: (?P<severity>error|warning): (?P<text>.*)")


def test_a_file_saved_in_latin1_is_one_error_line_once_and_the_old_program_keeps_drawing(ctx, shader_copy):
    """A Latin-1 "é" in a comment is no UnicodeDecodeError out of every poll: one line, naming
    the file and the reason, said once; the program keeps its build until the file is fixed."""
    library = ShaderLibrary(ctx)
    try:
        program = library.program("present.vert", "present.frag")
        glo = program.glo
        path = shader_copy / "include" / "color.glsl"
        saved = path.read_bytes()
        path.write_bytes(b"// caf\xe9 au lait\n" + saved)
        (message,) = library.poll(now=1.0)
        assert "\n" not in message and "include/color.glsl" in message and "UTF-8" in message, message
        assert "0xe9" in message and "line 1" in message, message
        assert library.errors and library.program("present.vert", "present.frag") is program
        assert program.glo == glo
        assert library.poll(now=2.0) == [] and library.poll(now=3.0) == []  # said once, not every frame
        path.write_bytes(saved)
        assert library.poll(now=4.0) == ["shader reloaded: include/color.glsl (1 program rebuilt)"]
        assert library.errors == {}
    finally:
        library.release()


@contextlib.contextmanager
def _watch_fifo(path: Path):
    """Yields a list that gets True if anything opened the FIFO at ``path`` for reading (a
    non-blocking writer open succeeds only then); that writer also frees a reader blocked in
    ``open``, so a regression fails the test instead of hanging it."""
    opened, done = [], threading.Event()

    def watch() -> None:
        while not done.is_set():
            try:
                fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
            except OSError:  # ENXIO: no reader (the only answer when nothing opens it)
                time.sleep(0.01)
                continue
            opened.append(True)
            os.close(fd)
            time.sleep(0.01)

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    try:
        yield opened
    finally:
        done.set()
        thread.join()


@pytest.mark.parametrize("kind", ["fifo", "directory"])
def test_an_include_that_is_not_a_regular_file_is_refused_without_being_opened(ctx, shader_copy, kind):
    """An include that became a named pipe (whose open would wait for a writer forever) or a
    directory is refused by what os.stat says, on a rebuild and on a first build; the old
    program keeps drawing and the error is said once."""
    if kind == "fifo" and not hasattr(os, "mkfifo"):
        pytest.skip("no named pipes on this system")
    library = ShaderLibrary(ctx)
    try:
        program = library.program("present.vert", "present.frag")
        path = shader_copy / "include" / "color.glsl"
        saved = path.read_text()
        path.unlink()
        os.mkfifo(path) if kind == "fifo" else path.mkdir()
        what = "a named pipe (FIFO)" if kind == "fifo" else "a directory"
        with (_watch_fifo(path) if kind == "fifo" else contextlib.nullcontext([])) as opened:
            (message,) = library.poll(now=1.0)
            assert not opened, "the named pipe was opened"
            assert "\n" not in message and "'include/color.glsl'" in message and what in message, message
            assert library.errors and library.program("present.vert", "present.frag") is program
            assert library.poll(now=2.0) == []
            # A variant first needed now is built from the include as it was (issue 41 item 4:
            # it used to raise and close the window); the error is recorded, the pipe unopened.
            key = ("present.vert", "present.frag", None, (("A_NEW_VARIANT", "1"),))
            library.program("present.vert", "present.frag", defines={"A_NEW_VARIANT": "1"})
            assert re.search(rf"'include/color\.glsl'.* is {re.escape(what)}, not a regular", library.errors[key])
        assert not opened, "the named pipe was opened"
        path.unlink() if kind == "fifo" else path.rmdir()
        path.write_text(saved)
        news, reloaded = library.poll(now=3.0)
        assert news.startswith("shader error: a new variant of (present.vert, present.frag) is built from the files "
                               "before the edit"), news
        assert reloaded == "shader reloaded: include/color.glsl (2 programs rebuilt)" and not library.errors
    finally:
        library.release()


def test_an_include_written_before_its_file_is_built_once_the_file_comes(ctx, shader_copy):
    """A broken build still watches every file it reached: an #include of a file not yet made
    is an error, and making the file rebuilds the program."""
    library = ShaderLibrary(ctx)
    try:
        library.program("present.vert", "present.frag")
        edit(shader_copy, "present.frag", "uniform sampler2D hdr_image;", '#include "later.glsl"')
        (message,) = library.poll(now=1.0)
        assert "'include/later.glsl' not found" in message, message
        (shader_copy / "include" / "later.glsl").write_text("float later() { return 1.0; }\n")
        assert library.poll(now=2.0) == ["shader reloaded: include/later.glsl (1 program rebuilt)"]
        assert library.errors == {}
    finally:
        library.release()


@contextlib.contextmanager
def window_shell(build=None):
    """The windowed shell (headless EGL window) running a game of ``build`` (``room``)."""
    import moderngl_window as mglw

    from shell.window import make_window_config
    from tests.support import FunctionGame

    config = mglw.create_window_config_instance(
        make_window_config(FunctionGame(build or room)),
        args=["--window", "headless", "--backend", "egl", "--size", "96x72"])
    try:
        yield config
    finally:
        config.on_close()
        config.wnd.destroy()


def test_an_error_in_present_frag_is_printed_once(shader_copy, capsys):
    """present.frag is built twice (with and without LUMA_IN_ALPHA), and the two builds of a
    broken edit warn differently: the shell still prints the error once, each of its lines
    once, in the engine's form, and then nothing while the file stays as it is."""
    with window_shell() as config:
        library = config.engine.renderer.shaders
        config.on_render(0.0, 1 / 60)
        capsys.readouterr()
        path = shader_copy / "present.frag"
        text = path.read_text()
        # srgb is now broken, and each variant warns of its use at its own line (#ifdef LUMA_IN_ALPHA)
        path.write_text(text.replace("* exposure);", "* exposure) + present_undeclared_name;"))
        line = 1 + text[:text.index("* exposure);")].count("\n")
        for _ in range(3):
            library._next_poll = 0.0  # as if half a second had passed each frame
            config.on_render(0.0, 1 / 60)
        printed = capsys.readouterr().err.splitlines()
        errors = [text for text in printed if "shader error" in text]
        assert len(errors) == 1, printed
        found = [m for m in map(DIAGNOSTIC.search, printed) if m]
        assert len({m.group(0) for m in found}) == len(found), printed  # no line twice
        assert "present.vert + present.frag (2 variants)" in errors[0], printed
        assert found and all(m.group("severity") == "error" for m in found), printed
        assert any(m.group("file", "line") == ("present.frag", str(line)) and "present_undeclared_name" in
                   m.group("text") for m in found), printed
        assert len(library.errors) == 2


def test_a_variant_first_needed_after_a_broken_edit_is_built_from_the_files_before_it(scene, shader_copy):
    """Issue 41 item 4: after an edit that does not build, a batch that needs a program
    variant never built before (a normal-mapped crate spawned then) made Engine.frame raise
    and the window close.  Now the variant is built from the files as they were before the
    edit: the frame draws the crate as the second path (a fresh engine on the shipped files)
    does, the error is recorded and said by the next poll, and the fix rebuilds it."""
    def crate(world):
        return world.spawn(Transform(position=(-1.0, 0.4, 0.5)), MeshRef(box((0.6, 0.6, 0.6))),
                           Material(color=(0.8, 0.5, 0.2), normal_map=ripple_normal_map(32)))

    runner = scene(room, SIZE)
    library: ShaderLibrary = runner.engine.renderer.shaders
    runner.frame()
    before = set(library._programs)
    edit(shader_copy, "scene.frag", SCENE_COLOUR, "    color += undefined_hot_reload_name;")
    assert library.poll(now=1001.0)  # the existing variants: kept, said
    entity = crate(runner.world)
    shown = runner.frame()  # no ShaderError: the new variant comes from the files before the edit
    new = set(library._programs) - before
    assert new and new <= set(library.errors), (new, set(library.errors))
    assert all("built from the files before it" in library.errors[key] for key in new)
    said = library.poll(now=1001.1)
    assert len(said) == len(new) and all("built from the files before the edit" in line for line in said), said
    assert library.poll(now=1001.2) == []  # said once

    # The second path: the same room and crate drawn by an engine on the shipped files.
    shutil.copy(Path(__file__).parents[1] / "shaders" / "scene.frag", shader_copy / "scene.frag")
    reference = scene(lambda world: (room(world), crate(world)), SIZE)
    expected = reference.frame()
    on_crate = runner.ids() == entity
    assert on_crate.sum() > 50
    np.testing.assert_array_equal(shown[on_crate], expected[reference.ids() == entity])

    # The fix (the shipped text again) rebuilds every scene.frag program, the new one too.
    messages = library.poll(now=1003.0)
    assert messages and messages[-1].startswith("shader reloaded: scene.frag"), messages
    assert library.errors == {}
    np.testing.assert_array_equal(runner.frame(), expected)


def test_a_first_build_that_fails_with_no_edit_still_raises(ctx, shader_copy):
    """Only an edit falls back: a program that never built (a missing file) is an error."""
    library = ShaderLibrary(ctx)
    try:
        with pytest.raises(ShaderError, match="not found"):
            library.program("scene.vert", "no_such_file.frag")
    finally:
        library.release()
