"""Programs outlive their library on its context (``FreePrograms``): a library released
hands them on, each uniform back at 0 and each block at binding 0, and the next library
that needs the same key from the same sources takes one instead of linking again; edited
sources, relinked programs and failed builds are never handed on, and the list keeps no
more than it is told."""
from __future__ import annotations

from pathlib import Path

import moderngl
import numpy as np
import pytest

from components import Bloom, DirectionalLight, Fog, Material, MeshRef, Mirror, Skybox, Tonemap, Transform
from engine.assets.mesh import box, plane, quad
from engine.render.gl_context import create_headless_context
from engine.render.shader_library import FreePrograms, ShaderLibrary
from tests.support import SceneRunner, look_from, programs_linked_anew

VERTEX = """#version 410 core
in vec2 in_position;
void main() { gl_Position = vec4(in_position, 0.0, 1.0); }
"""
FRAGMENT = """#version 410 core
uniform float gain;
uniform vec3 tints[3];
uniform mat4 turn;
uniform ivec2 cell;
uniform sampler2D image;
layout(std140) uniform Extra { vec4 extra; };
out vec4 c;
void main() {
    c = texture(image, vec2(cell)) * gain + vec4(tints[0] + tints[2], 1.0) + turn[1] + extra;
}
"""


@pytest.fixture
def free() -> FreePrograms:
    """A free list of this test's own (its programs released after)."""
    with programs_linked_anew() as own:
        yield own


@pytest.fixture
def root(tmp_path) -> Path:
    other = FRAGMENT.replace("gain", "boost")
    for name, text in {"main.vert": VERTEX, "main.frag": FRAGMENT, "other.frag": other}.items():
        (tmp_path / name).write_text(text)
    return tmp_path


def _written(program) -> None:
    program["gain"].value = 2.5
    program["tints"].value = [(1.0, 2.0, 3.0), (4.0, 5.0, 6.0), (7.0, 8.0, 9.0)]
    program["turn"].value = tuple(float(i + 1) for i in range(16))
    program["cell"].value = (3, 4)
    program["image"].value = 7
    program["Extra"].binding = 5


def test_a_released_librarys_program_is_taken_by_the_next_with_every_uniform_at_zero(ctx, free, root):
    first = ShaderLibrary(ctx, root)
    program = first.program("main.vert", "main.frag")
    glo = program.glo
    _written(program)
    first.release()
    assert free.count == 1 and program.mglo is not None

    second = ShaderLibrary(ctx, root)
    again = second.program("main.vert", "main.frag")
    assert again is program and again.glo == glo and free.taken == 1 and free.count == 0
    for name in ("gain", "tints", "turn", "cell", "image"):
        data = again[name].read()
        assert data == bytes(len(data)), f"{name} kept {data!r}: a new program's uniforms are 0"
    assert again["Extra"].binding == 0
    # What a program linked now reads: the same.
    fresh = ctx.program(vertex_shader=VERTEX, fragment_shader=FRAGMENT)
    try:
        for name in ("gain", "tints", "turn", "cell", "image"):
            assert again[name].read() == fresh[name].read()
    finally:
        fresh.release()
    second.release()


def test_inside_the_hook_a_library_on_another_context_never_takes_this_ones_programs(ctx, root):
    """``programs_linked_anew`` (the strict GL sweep's and the fetch-bounds check's hook) holds
    the list of one context: a library on a second context (a benchmark's, a test's own
    window) links its own programs and keeps none of them, where one list for both handed it
    the first context's program ("the program belongs to a different context")."""
    other = create_headless_context()
    try:
        with programs_linked_anew(ctx) as own:
            first = ShaderLibrary(ctx, root)
            program = first.program("main.vert", "main.frag")
            first.release()
            assert own.count == 1
            elsewhere = ShaderLibrary(other, root)
            linked = elsewhere.program("main.vert", "main.frag")
            assert linked is not program and own.count == 1 and own.taken == 0
            elsewhere.release()
            assert linked.mglo is None or isinstance(linked.mglo, moderngl.InvalidObject)  # released, not kept
            assert own.count == 1
            again = ShaderLibrary(ctx, root)
            assert again.program("main.vert", "main.frag") is program and own.taken == 1
            again.release()
    finally:
        other.release()


def test_another_key_or_edited_sources_are_linked_anew(ctx, free, root):
    free.keep = 10
    first = ShaderLibrary(ctx, root)
    program = first.program("main.vert", "main.frag")
    first.release()

    second = ShaderLibrary(ctx, root)
    other = second.program("main.vert", "other.frag")                        # another file
    variant = second.program("main.vert", "main.frag", defines={"SOME_SWITCH": "1"})  # another build
    assert program not in (other, variant) and free.taken == 0
    second.release()

    (root / "main.frag").write_text(FRAGMENT.replace("* gain", "* gain * 0.5"))
    third = ShaderLibrary(ctx, root)
    edited = third.program("main.vert", "main.frag")
    assert edited is not program and free.taken == 0  # linked from the files as they are now
    assert type(program.mglo).__name__ != "InvalidObject"  # (it was there to take)
    third.release()


def test_the_list_keeps_as_many_as_the_fullest_library_held_and_lets_the_longest_unused_go(ctx, free, root):
    first = ShaderLibrary(ctx, root)
    oldest = first.program("main.vert", "main.frag")
    kept = [first.program("main.vert", "main.frag", defines={"N": str(n)}) for n in range(2)]
    first.release()
    assert free.count == 3 and free.most == 3

    second = ShaderLibrary(ctx, root)
    newer = [second.program("main.vert", "other.frag", defines={"N": str(n)}) for n in range(2)]
    second.release()
    assert free.count == 3  # the fullest library held 3: the two longest unused released
    assert [type(p.mglo).__name__ == "InvalidObject" for p in [oldest, *kept, *newer]] == [True, True, False,
                                                                                          False, False]

    free.keep = 1
    third = ShaderLibrary(ctx, root)
    third.release()
    assert free.count == 1 and type(newer[-1].mglo).__name__ != "InvalidObject"

    free.release()  # (as the fixture does) what is given after goes at once
    assert free.count == 0 and type(newer[-1].mglo).__name__ == "InvalidObject"
    late = ShaderLibrary(ctx, root)
    last = late.program("main.vert", "main.frag")
    late.release()
    assert free.count == 0 and type(last.mglo).__name__ == "InvalidObject"


def test_shrink_lets_the_longest_unused_go_below_what_trim_keeps(ctx, free, root):
    """``shrink``: a run past scenes it will not see again (the still fuzz) gives back more
    than ``trim``'s rule (the fullest library's count) would: the longest unused first."""
    library = ShaderLibrary(ctx, root)
    programs = [library.program("main.vert", "main.frag", defines={"N": str(n)}) for n in range(4)]
    library.release()
    assert free.count == 4 and free.most == 4   # (trim keeps them all)
    free.shrink(1)
    assert free.count == 1
    assert [type(p.mglo).__name__ == "InvalidObject" for p in programs] == [True, True, True, False]
    again = ShaderLibrary(ctx, root)
    assert again.program("main.vert", "main.frag", defines={"N": "3"}) is programs[3]   # (still there to take)
    again.release()


def test_a_relinked_program_and_a_library_with_errors_hand_nothing_on(ctx, free, root):
    library = ShaderLibrary(ctx, root)
    program = library.program("main.vert", "main.frag")
    (root / "main.frag").write_text(FRAGMENT.replace("* gain", "* gain * 0.5"))
    assert library.reload({"main.frag"})  # relinked in place under its own name
    assert library.reloads == 1
    library.release()
    assert free.count == 0 and type(program.mglo).__name__ == "InvalidObject"

    broken = ShaderLibrary(ctx, root)
    kept = broken.program("main.vert", "main.frag")
    (root / "main.frag").write_text(FRAGMENT.replace("* gain", "* undeclared"))
    broken.reload({"main.frag"})
    assert broken.errors  # the old build keeps drawing
    broken.release()
    assert free.count == 0 and type(kept.mglo).__name__ == "InvalidObject"


def _room(world) -> int:
    camera = look_from(world, (0.0, 1.4, 4.0), (0.0, 0.8, 0.0))
    world.spawn(Skybox())
    world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.5), intensity=2.0))
    world.spawn(Transform(), MeshRef(plane(8, 8)), Material(color=(0.5, 0.5, 0.5)))
    world.spawn(Transform(position=(0.9, 0.5, 0.5)), MeshRef(box((0.6, 0.6, 0.6))), Material(color=(0.2, 0.6, 0.2)))
    world.spawn(Transform(position=(0, 1.3, -1.5)), MeshRef(quad(3, 2)), Material(), Mirror(color=(0.9, 0.9, 1.0)))
    return camera


def _foggy_room(world) -> None:
    camera = _room(world)
    world.add_component(camera, Fog(density=0.2, color=(0.8, 0.3, 0.2)))
    world.add_component(camera, Tonemap(curve="aces", exposure=1.0))
    world.add_component(camera, Bloom(intensity=0.8, threshold=0.2))


def test_an_engine_on_programs_another_engine_drew_with_draws_what_one_on_new_programs_draws(ctx, free):
    foggy = SceneRunner(ctx, _foggy_room, (96, 72))
    for _ in range(2):
        foggy.frame()
    foggy.close()
    handed_on = free.count
    assert handed_on > 10

    taking = SceneRunner(ctx, _room, (96, 72))
    frames = [taking.frame() for _ in range(2)]
    taking.close()
    assert free.taken > 10  # most of what the room needs, the foggy room had built

    with programs_linked_anew() as fresh:
        new = SceneRunner(ctx, _room, (96, 72))
        expected = [new.frame() for _ in range(2)]
        new.close()
    assert fresh.taken == 0
    for got, want in zip(frames, expected, strict=True):
        assert np.array_equal(got, want)
