"""The pass-state cache (``bindings.apply_pass_state`` sets only what changed): a state
applied twice sets nothing the second time, it stays true across framebuffer switches
(moderngl keeps a viewport and scissor per framebuffer), and after ``invalidate`` a pass
draws the right picture whatever raw GL or the debug overlay set in between."""
from __future__ import annotations

import ctypes
import random

import moderngl
import numpy as np
import pytest

from engine.render import bindings
from engine.render.bindings import PassState, apply_pass_state, bind_uniform_block, invalidate, set_front_face
from engine.render.raw_gl import _load
from engine.render.targets import release_framebuffer
from tests.test_pass_state import CAMERAS, frames, hall

_SETTERS = ("depth_func", "blend_func", "front_face", "viewport", "scissor")


@pytest.fixture
def setter_calls(monkeypatch):
    """Counts of moderngl's Context setters (and enable_only, enable_direct, disable_direct) called."""
    calls = dict.fromkeys((*_SETTERS, "enable_only", "enable_direct", "disable_direct"), 0)
    for name in _SETTERS:
        prop = getattr(moderngl.Context, name)

        def setter(self, value, _name=name, _set=prop.fset):
            calls[_name] += 1
            _set(self, value)
        monkeypatch.setattr(moderngl.Context, name, property(prop.fget, setter))
    for name in ("enable_only", "enable_direct", "disable_direct"):
        method = getattr(moderngl.Context, name)

        def counted(self, value, _name=name, _method=method):
            calls[_name] += 1
            _method(self, value)
        monkeypatch.setattr(moderngl.Context, name, counted)
    return calls


_WHITE_VS = "#version 410 core\nvoid main() { vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);" \
            " gl_Position = vec4(p * 2.0 - 1.0, 0.5, 1.0); }"
_WHITE_FS = "#version 410 core\nout vec4 colour; void main() { colour = vec4(1.0); }"


def _covered(ctx, framebuffer, draw) -> np.ndarray:
    """Pixels a full-screen triangle drawn by ``draw`` covers in ``framebuffer`` (cleared first)."""
    framebuffer.clear(0.0, 0.0, 0.0, 0.0, viewport=(0, 0, *framebuffer.size))
    draw()
    data = np.frombuffer(framebuffer.read(components=1), dtype=np.uint8)
    return data.reshape(framebuffer.size[1], framebuffer.size[0]) > 0


def test_a_state_applied_again_sets_nothing(ctx, setter_calls):
    target = ctx.simple_framebuffer((32, 32))
    try:
        target.use()
        invalidate(ctx)
        state = PassState(depth_func="<", cull=True, clips=frozenset((0, 5)))
        apply_pass_state(ctx, state, (0, 0, 32, 32))
        assert sum(setter_calls.values()) > 0
        setter_calls.update(dict.fromkeys(setter_calls, 0))
        apply_pass_state(ctx, state, (0, 0, 32, 32))
        apply_pass_state(ctx, PassState(depth_func="<", cull=True, clips=frozenset((0, 5))), (0, 0, 32, 32))
        set_front_face(ctx, "ccw")
        assert sum(setter_calls.values()) == 0, setter_calls
        # A change sets that piece only.
        apply_pass_state(ctx, PassState(depth_func="<=", cull=True, clips=frozenset((0,))), (0, 0, 16, 32))
        assert setter_calls == {**dict.fromkeys(setter_calls, 0), "depth_func": 1, "disable_direct": 1,
                                "viewport": 1}, setter_calls
        # A winding set within a pass makes the next apply set the state's own again.
        set_front_face(ctx, "cw")
        setter_calls.update(dict.fromkeys(setter_calls, 0))
        apply_pass_state(ctx, PassState(depth_func="<=", cull=True, clips=frozenset((0,))), (0, 0, 16, 32))
        assert setter_calls["front_face"] == 1 and ctx.front_face == "ccw"
    finally:
        release_framebuffer(target)


def test_a_uniform_buffer_is_bound_once_until_another_or_invalidate(ctx, monkeypatch):
    binds = []
    method = moderngl.Buffer.bind_to_uniform_block

    def counted(self, binding=0, **kwargs):
        binds.append((self, binding))
        return method(self, binding, **kwargs)
    monkeypatch.setattr(moderngl.Buffer, "bind_to_uniform_block", counted)
    one, two = ctx.buffer(reserve=64), ctx.buffer(reserve=64)
    try:
        invalidate(ctx)
        for _ in range(3):
            bind_uniform_block(ctx, one, 0)
        bind_uniform_block(ctx, one, 1)
        assert binds == [(one, 0), (one, 1)]
        bind_uniform_block(ctx, two, 0)
        bind_uniform_block(ctx, one, 0)
        invalidate(ctx)
        bind_uniform_block(ctx, one, 0)
        assert binds[2:] == [(two, 0), (one, 0), (one, 0)]
    finally:
        one.release()
        two.release()


_BLOCK_FS = "#version 410 core\nlayout(std140) uniform Block { vec4 tint; };\nout vec4 colour;" \
            " void main() { colour = tint; }"


def test_a_uniform_range_is_bound_once_and_holds_when_the_buffer_is_written_anew(ctx, monkeypatch):
    """``bind_uniform_range`` binds a range only when another is bound there: the same range
    again binds nothing and still reads the buffer's new contents after the storage is
    orphaned and written (a binding names the buffer object), another offset or the whole
    buffer (``bind_uniform_block``) binds again, and so does a buffer made anew."""
    binds = []
    method = moderngl.Buffer.bind_to_uniform_block

    def counted(self, binding=0, **kwargs):
        binds.append((self, binding, kwargs.get("offset", 0)))
        return method(self, binding, **kwargs)
    monkeypatch.setattr(moderngl.Buffer, "bind_to_uniform_block", counted)
    program = ctx.program(vertex_shader=_WHITE_VS, fragment_shader=_BLOCK_FS)
    program["Block"].binding = 3
    vao = ctx.vertex_array(program, [])
    target = ctx.simple_framebuffer((8, 8))
    step = 256  # a multiple of any GL_UNIFORM_BUFFER_OFFSET_ALIGNMENT

    def tints(*rows):
        data = bytearray(2 * step)
        for at, row in enumerate(rows):
            data[at * step:at * step + 16] = np.array(row, "f4").tobytes()
        return bytes(data)

    def drawn() -> tuple:
        target.use()
        apply_pass_state(ctx, PassState(), (0, 0, 8, 8))
        target.clear()
        vao.render(vertices=3)
        return tuple(np.frombuffer(target.read(components=4), np.uint8)[:4])

    buffer = ctx.buffer(tints((1, 0, 0, 1), (0, 0, 1, 1)))
    other = None
    try:
        invalidate(ctx)
        bindings.bind_uniform_range(ctx, buffer, 3, 0, 16)
        assert drawn() == (255, 0, 0, 255)
        buffer.orphan()
        buffer.write(tints((0, 1, 0, 1), (0, 0, 1, 1)))
        bindings.bind_uniform_range(ctx, buffer, 3, 0, 16)
        assert len(binds) == 1
        assert drawn() == (0, 255, 0, 255)
        bindings.bind_uniform_range(ctx, buffer, 3, step, 16)
        assert drawn() == (0, 0, 255, 255)
        bind_uniform_block(ctx, buffer, 3)  # the whole buffer: its first tint
        assert drawn() == (0, 255, 0, 255)
        bindings.bind_uniform_range(ctx, buffer, 3, 0, 16)
        other = ctx.buffer(tints((1, 1, 0, 1)))
        bindings.bind_uniform_range(ctx, other, 3, 0, 16)
        assert drawn() == (255, 255, 0, 255)
        assert [(b is other, offset) for b, _, offset in binds] == [
            (False, 0), (False, step), (False, 0), (False, 0), (True, 0)]
    finally:
        for obj in (buffer, other, vao, program):
            if obj is not None:
                obj.release()
        release_framebuffer(target)
        invalidate(ctx)


def test_a_scissor_in_place_is_not_set_again(ctx, setter_calls):
    """``set_scissor`` (a view's scissor within a pass) sets nothing when moderngl's record
    of the bound framebuffer already clips so, and sets one that differs: the pixels drawn
    are the scissor's."""
    program = ctx.program(vertex_shader=_WHITE_VS, fragment_shader=_WHITE_FS)
    vao = ctx.vertex_array(program, [])
    target = ctx.simple_framebuffer((32, 32))
    try:
        invalidate(ctx)
        target.use()
        apply_pass_state(ctx, PassState(), (0, 0, 32, 32), (0, 0, 10, 10))
        before = setter_calls["scissor"]
        bindings.set_scissor(ctx, (0, 0, 10, 10))
        assert setter_calls["scissor"] == before
        assert _covered(ctx, target, lambda: vao.render(vertices=3)).sum() == 100
        bindings.set_scissor(ctx, (0, 0, 4, 4))
        assert setter_calls["scissor"] == before + 1
        assert _covered(ctx, target, lambda: vao.render(vertices=3)).sum() == 16
        bindings.set_scissor(ctx, None)
        bindings.set_scissor(ctx, None)
        assert setter_calls["scissor"] == before + 2
        assert _covered(ctx, target, lambda: vao.render(vertices=3)).all()
    finally:
        release_framebuffer(target)
        vao.release()
        program.release()


def test_the_cache_holds_across_framebuffer_switches(ctx):
    """moderngl keeps a viewport and scissor per framebuffer and ``Framebuffer.use`` sets them
    again: a scissor left on one framebuffer is found there, not assumed gone."""
    program = ctx.program(vertex_shader=_WHITE_VS, fragment_shader=_WHITE_FS)
    vao = ctx.vertex_array(program, [])
    big, small = ctx.simple_framebuffer((64, 48)), ctx.simple_framebuffer((32, 32))
    state = PassState()
    try:
        invalidate(ctx)
        big.use()
        apply_pass_state(ctx, state, (0, 0, 64, 48), (0, 0, 10, 10))
        small.use()
        apply_pass_state(ctx, state, (0, 0, 32, 32))
        assert _covered(ctx, small, lambda: vao.render(vertices=3)).all()
        big.use()  # its scissor (10 x 10) is back
        apply_pass_state(ctx, state, (0, 0, 64, 48))
        assert _covered(ctx, big, lambda: vao.render(vertices=3)).all()
        apply_pass_state(ctx, state, (0, 0, 32, 24), (0, 0, 8, 8))
        small.use()
        apply_pass_state(ctx, state, (0, 0, 16, 16))
        assert _covered(ctx, small, lambda: vao.render(vertices=3)).sum() == 16 * 16
        big.use()
        apply_pass_state(ctx, state, (0, 0, 32, 24), (0, 0, 8, 8))
        assert _covered(ctx, big, lambda: vao.render(vertices=3)).sum() == 8 * 8
    finally:
        for framebuffer in (big, small):
            release_framebuffer(framebuffer)
        vao.release()
        program.release()


def test_after_raw_gl_and_invalidate_a_pass_sets_everything_again(ctx):
    """State changed behind moderngl's back (raw glViewport, glDisable, glDepthFunc): the
    cache cannot see it; ``invalidate`` makes the next apply set it all."""
    gl = {name: _load(ctx, name, ctypes.CFUNCTYPE(None, *args)) for name, args in (
        ("glViewport", (ctypes.c_int,) * 4), ("glEnable", (ctypes.c_uint,)), ("glDisable", (ctypes.c_uint,)),
        ("glScissor", (ctypes.c_int,) * 4), ("glDepthFunc", (ctypes.c_uint,)))}
    program = ctx.program(vertex_shader=_WHITE_VS, fragment_shader=_WHITE_FS)
    vao = ctx.vertex_array(program, [])
    target = ctx.framebuffer(
        color_attachments=[ctx.renderbuffer((32, 32))], depth_attachment=ctx.depth_renderbuffer((32, 32)))
    state = PassState(depth_func="<")
    try:
        target.use()
        invalidate(ctx)
        apply_pass_state(ctx, state, (0, 0, 32, 32))

        def draw():
            target.clear(depth=1.0)
            vao.render(vertices=3)
        assert _covered(ctx, target, draw).all()
        gl["glViewport"](0, 0, 4, 4)
        gl["glEnable"](0x0C11)      # GL_SCISSOR_TEST
        gl["glScissor"](0, 0, 2, 2)
        gl["glDepthFunc"](0x0200)   # GL_NEVER
        invalidate(ctx)
        apply_pass_state(ctx, state, (0, 0, 32, 32))
        assert _covered(ctx, target, draw).all()
    finally:
        release_framebuffer(target)
        vao.release()
        program.release()


def test_passes_draw_the_same_pixels_after_raw_gl_state_and_invalidate(ctx):
    """The hall of mirrors, with raw GL state set before every scene pass, claim, composite
    and present, then ``invalidate``: the same pixels and ids as without."""
    plain = hall(ctx)
    try:
        expected = frames(plain)
    finally:
        plain.close()
    gl = {name: _load(ctx, name, ctypes.CFUNCTYPE(None, *args)) for name, args in (
        ("glViewport", (ctypes.c_int,) * 4), ("glEnable", (ctypes.c_uint,)), ("glDisable", (ctypes.c_uint,)),
        ("glScissor", (ctypes.c_int,) * 4), ("glDepthFunc", (ctypes.c_uint,)), ("glFrontFace", (ctypes.c_uint,)))}
    rng = random.Random(3)

    def before():
        gl["glViewport"](rng.randrange(20), rng.randrange(20), rng.randrange(1, 90), rng.randrange(1, 60))
        gl["glScissor"](rng.randrange(20), rng.randrange(20), rng.randrange(1, 90), rng.randrange(1, 60))
        for cap in (0x0C11, 0x0B71, 0x0B44, 0x0BE2, 0x3000, 0x3005):  # scissor, depth, cull, blend, clips
            gl["glEnable" if rng.random() < 0.5 else "glDisable"](cap)
        gl["glDepthFunc"](rng.choice((0x0200, 0x0201, 0x0204, 0x0207)))
        gl["glFrontFace"](rng.choice((0x0900, 0x0901)))
        invalidate(ctx)

    shuffled = hall(ctx)
    try:
        renderer = shuffled.engine.renderer
        passes = shuffled.engine.reflection_system.tree.passes
        for owner, name in ((renderer.scene_pass, "draw"), (passes, "prepare_level"), (passes, "composite_level"),
                            (renderer, "present")):
            method = getattr(owner, name)

            def wrapped(*args, _method=method, **kwargs):
                before()
                return _method(*args, **kwargs)
            setattr(owner, name, wrapped)
        got = frames(shuffled)
    finally:
        shuffled.close()
    assert len(got) == len(CAMERAS)
    for (rgb, ids), (want_rgb, want_ids) in zip(got, expected, strict=True):
        np.testing.assert_array_equal(ids, want_ids)
        np.testing.assert_array_equal(rgb, want_rgb)


def test_the_frame_after_the_overlay_is_the_frame_without_it(ctx):
    """The debug overlay sets blending, scissor and viewport with moderngl's setters after a
    frame and then invalidates the cache (``Engine.frame`` keeps it), so the next frame is
    the same picture."""
    pytest.importorskip("imgui_bundle", reason="the debug overlay needs imgui-bundle")
    from shell.overlay import DebugOverlay

    plain = hall(ctx)
    try:
        expected = frames(plain)
    finally:
        plain.close()
    runner = hall(ctx)
    overlay = DebugOverlay(ctx)
    try:
        # Each frame after the first is drawn after the overlay drew over the one before.
        for camera, (want_rgb, want_ids) in zip(CAMERAS, expected, strict=True):
            runner.engine.place_camera(*camera)
            rgb = runner.frame()
            np.testing.assert_array_equal(runner.ids(), want_ids)
            np.testing.assert_array_equal(rgb, want_rgb)
            overlay.record(0.02)
            overlay.draw(runner.engine, runner.capture.framebuffer, runner.size)
    finally:
        overlay.release()
        runner.close()


def test_the_uncached_path_draws_the_same(ctx, monkeypatch):
    """``CACHE_STATE = False`` (every setter every time, the path before the cache) is kept
    for measurement: it draws the same pixels."""
    cached = hall(ctx)
    try:
        expected = frames(cached)
    finally:
        cached.close()
    monkeypatch.setattr(bindings, "CACHE_STATE", False)
    uncached = hall(ctx)
    try:
        got = frames(uncached)
    finally:
        uncached.close()
    for (rgb, ids), (want_rgb, want_ids) in zip(got, expected, strict=True):
        np.testing.assert_array_equal(ids, want_ids)
        np.testing.assert_array_equal(rgb, want_rgb)


# --- programs built when a level loads -----------------------------------------------------
def _compiles(runner) -> list:
    """Records each program the engine's shader library builds from now on."""
    library = runner.engine.renderer.shaders
    built = []
    build = library._build

    def counted(key, files, **options):  # (a program taken from the context's free list too)
        built.append(key)
        return build(key, files, **options)
    library._build = counted
    return built


@pytest.mark.parametrize("path", ["batched", "per_mirror", "auto"])
@pytest.mark.parametrize("visibility", ["exact", "predicted"])
def test_a_mirror_coming_into_view_compiles_no_program(scene, path, visibility, monkeypatch):
    """After the engine is made and one frame drawn looking away from the mirror, turning to
    it builds nothing: the level's batches got their programs (every batched invocation
    count too, and the masked builds a predicted level draws with, a GPU's default) and
    vertex arrays, and the first reflection level its targets, after that first frame
    (``Renderer.prepare_programs``)."""
    from tests.test_hot_reload import room

    runner = scene(room, (160, 120))
    runner.engine.reflection_system.path = path
    runner.engine.reflection_system.visibility = visibility
    runner.engine.place_camera(0.0, 1.4, 4.0, 180.0, 0.0)  # the mirror is behind
    runner.frame()
    assert runner.stats.reflection_views == 0
    built = _compiles(runner)
    made = []
    for name in ("framebuffer", "texture", "vertex_array"):
        method = getattr(moderngl.Context, name)

        def counted(self, *args, _name=name, _method=method, **kwargs):
            made.append(_name)
            return _method(self, *args, **kwargs)
        monkeypatch.setattr(moderngl.Context, name, counted)
    runner.engine.place_camera(0.0, 1.4, 4.0, 0.0, -5.0)
    runner.frame()
    assert runner.stats.reflection_views > 0
    assert built == []
    assert made == []


def test_without_preparing_the_first_mirror_compiles(scene):
    """The check above is not empty: without ``prepare_programs`` the same turn builds the
    batched path's programs."""
    from tests.test_hot_reload import room

    runner = scene(room, (160, 120))
    runner.engine.reflection_system.path = "batched"
    runner.engine.renderer.prepare_programs = lambda *args, **kwargs: 0
    runner.engine.place_camera(0.0, 1.4, 4.0, 180.0, 0.0)
    runner.frame()
    built = _compiles(runner)
    runner.engine.place_camera(0.0, 1.4, 4.0, 0.0, -5.0)
    runner.frame()
    assert runner.stats.reflection_views > 0
    assert built


def _plain_room(world) -> None:
    """A lit box on a floor under a sun that casts."""
    from components import DirectionalLight, Material, MeshRef, Skybox, Transform
    from engine import spawn_camera
    from engine.assets.mesh import box, plane

    world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.4)))
    world.spawn(Skybox())
    world.spawn(Transform(), MeshRef(plane(8, 8)), Material(color=(0.6, 0.6, 0.6)))
    world.spawn(Transform(position=(0.0, 0.5, 0.0)), MeshRef(box()), Material(color=(0.9, 0.3, 0.2)))
    spawn_camera(world, position=(0.0, 2.0, 5.0), pitch=-15.0, fly=False)


def test_a_frame_binds_only_what_another_pass_displaced(ctx, monkeypatch):
    """The record carries over from one frame to the next (``Engine.frame`` does not forget
    it): a still frame binds fewer textures and uniform blocks than the same frame after
    ``invalidate``, and draws the same picture."""
    from tests.support import SceneRunner

    calls = {"binds": 0}
    for owner, name in ((moderngl.Texture, "use"), (moderngl.TextureCube, "use"),
                        (moderngl.Buffer, "bind_to_uniform_block")):
        method = getattr(owner, name)

        def counted(self, *args, _method=method, **kwargs):
            calls["binds"] += 1
            return _method(self, *args, **kwargs)
        monkeypatch.setattr(owner, name, counted)
    runner = SceneRunner(ctx, _plain_room, (96, 64))
    try:
        runner.frame()
        kept_picture = runner.frame()
        calls["binds"] = 0
        runner.frame()
        kept = calls["binds"]
        invalidate(ctx)
        calls["binds"] = 0
        forgot_picture = runner.frame()
        forgot = calls["binds"]
        np.testing.assert_array_equal(forgot_picture, kept_picture)
        assert kept < forgot, (kept, forgot)
    finally:
        runner.close()
