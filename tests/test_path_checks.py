"""The path self-check (engine/render/path_checks.py): every alternative GL path is compared
with its plain counterpart before it is trusted, and a broken one is refused while the
picture stays right.

llvmpipe draws every path right, so the broken paths here are stand-ins injected for the
test: a layered target whose attachments are single faces (what the NVIDIA H200 did: face
+X written, the other five untouched), a 2D-array capture whose copy puts layer 0 in every
face or whose attachment is layer 0 alone, a mip pass that skips a level, face attachments
swapped.  Each is refused, named in one warning, and the frame is drawn by the next path
that is trusted: the 2D-array capture where only the cube-map one is refused (the H200),
six passes where both are.
"""
from __future__ import annotations

import logging
import re
import warnings
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from components import Material, ReflectionProbe
from engine.core.errors import GLPassError
from engine.render.bindings import PROBE_UNIT, SCRATCH_UNIT
from engine.render.gl_context import prepare_context
from engine.render.path_checks import PATH_NAMES, SENTINEL, PathChecks
from engine.render.probes import ProbeCaptures, face_view
from engine.render.raw_gl import (
    GL_COLOR_ATTACHMENT0,
    GL_DEPTH_ATTACHMENT,
    GL_FRAMEBUFFER,
    GL_TEXTURE_CUBE_MAP_POSITIVE_X,
    CubeMipTarget,
    LayeredArrayTarget,
    LayeredCubeTarget,
    RawGL,
    read_cube_level,
)
from engine.render.targets import release_framebuffer
from tests.support import srgb_to_linear
from tests.test_probes import chrome_scene, ggx_reference, marked_chrome_scene, probe_stage

SHADERS = Path(__file__).resolve().parent.parent / "shaders"


@pytest.fixture
def fresh_checks(ctx):
    """Verdicts are kept per context: forget them before the test (so its stand-in is
    checked) and after it (so later tests check the real paths again)."""
    from engine.render import path_checks

    verdicts = path_checks._BY_CONTEXT.get(ctx)
    if verdicts is not None:
        verdicts.clear()
        verdicts.update({name: path_checks.PathVerdict() for name in PATH_NAMES})
    yield
    verdicts = path_checks._BY_CONTEXT.get(ctx)
    if verdicts is not None:
        verdicts.update({name: path_checks.PathVerdict() for name in PATH_NAMES})


def face_zero_only(monkeypatch):
    """The H200's layered capture: the target's attachments are face +X alone, so gl_Layer
    is ignored, every face's triangles land in face 0 and faces 1-5 are never written."""
    original = LayeredCubeTarget.bind

    def bind(self):
        original(self)
        self.gl["glFramebufferTexture2D"](GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_CUBE_MAP_POSITIVE_X,
                                          self.cube.glo, 0)
        self.gl["glFramebufferTexture2D"](GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_TEXTURE_CUBE_MAP_POSITIVE_X,
                                          self.depth, 0)

    monkeypatch.setattr(LayeredCubeTarget, "bind", bind)


def copy_layer_zero_everywhere(monkeypatch):
    """A 2D-array capture whose copy is wrong: layer 0 (face +X) copied into all six faces."""
    original = LayeredArrayTarget.copy_to_cube

    def copy(self, unit):
        kept = self.read_framebuffers
        self.read_framebuffers = [kept[0]] * 6
        try:
            original(self, unit)
        finally:
            self.read_framebuffers = kept

    monkeypatch.setattr(LayeredArrayTarget, "copy_to_cube", copy)


def array_layer_zero_only(monkeypatch):
    """A 2D-array capture whose attachment is layer 0 alone (the H200's cube-map fault, on
    the array): every triangle lands in layer 0, layers 1-5 are never cleared or drawn."""
    original = LayeredArrayTarget.bind

    def bind(self):
        original(self)
        self.gl["glFramebufferTextureLayer"](GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, self.texture, 0, 0)
        self.gl["glFramebufferTextureLayer"](GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, self.depth, 0, 0)

    monkeypatch.setattr(LayeredArrayTarget, "bind", bind)


def cube_faces(ctx, probes, key, level=0):
    texture = probes.cubes[key].texture
    return [read_cube_level(ctx, texture, face, level, SCRATCH_UNIT)[..., :3] for face in range(6)]


def test_every_path_is_checked_once_per_context_and_verified_on_llvmpipe(scene, ctx, fresh_checks, monkeypatch):
    """Each path the engine would use is checked once per context, before its first use, and
    the frame's stats say the verdicts.  On llvmpipe every check passes; a GPU driver may
    refuse some (the NVIDIA H200's writes only face 0 of a layered cube-map attachment, so
    both layered paths are refused there, and the layered capture into a 2D array, checked
    only then, is what its layered probe captures draw)."""
    ran = []
    original = PathChecks.check
    monkeypatch.setattr(PathChecks, "check", lambda self, path: ran.append(path) or original(self, path))
    ents = {}
    runner = scene(marked_chrome_scene(ents), (64, 48))
    runner.frame()
    verdicts = runner.engine.renderer.path_checks.verdicts
    status = {name: v.status for name, v in verdicts.items()}
    if prepare_context(ctx).software:
        # The layered capture and mip pass were verified: their fallbacks never needed checking.
        assert status == dict.fromkeys(PATH_NAMES, "verified") | {
            "face_mips": "unchecked", "layered_array_capture": "unchecked"}
    # The per-face mip pass is only a GGX chain's fallback (box mips fall back to
    # glGenerateMipmap): this probe's box mips never need it checked.  The array capture is
    # checked only where the layered capture into the cube map was refused.
    expected = ["direct_faces", "layered_capture", "layered_mips"]
    if status["layered_capture"] == "refused":
        expected.append("layered_array_capture")
    else:
        assert status["layered_array_capture"] == "unchecked"
    assert status["face_mips"] == "unchecked"
    assert sorted(ran) == sorted(expected)
    assert all(status[name] in ("verified", "refused") for name in expected), status
    assert set(runner.stats.paths_verified) == {name for name in expected if status[name] == "verified"}
    assert set(runner.stats.paths_refused) == {name for name in expected if status[name] == "refused"}
    second = scene(marked_chrome_scene({}), (64, 48))  # another engine on the same context
    second.frame()
    assert len(ran) == len(expected) and set(second.stats.paths_verified) == set(runner.stats.paths_verified)


def test_the_checks_draw_through_no_fog(scene, ctx, fresh_checks):
    """The check quads stand about the origin, where a pond usually lies: a tinted water's
    body there (red taken five times faster than blue) took the yellow quad below off its
    hue, and the plain path, drawn through it, was said to show no quad.  The checks' scene is
    drawn through no fog, so each capture path is verified there (on llvmpipe, which draws
    them all right), and the frame after draws through the water's fog as before."""
    from components import MeshRef, Mirror, Transform, Water, yaw_pitch_rotation
    from engine.assets.mesh import quad

    def build(world):
        marked_chrome_scene({})(world)
        world.spawn(Transform(position=(0.0, 0.05, 0.0), rotation=yaw_pitch_rotation(0.0, -90.0)),
                    MeshRef(quad(3.0, 3.0)), Material(color=(0.1, 0.3, 0.35, 0.3)), Mirror(max_depth=1),
                    Water(fog_density=0.5, depth=2.0, absorption=(2.5, 1.0, 0.5)))

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (a still water: no waves, said)
        runner = scene(build, (64, 48))
        before = runner.frame()
    fog = runner.engine.renderer.fog
    assert "FOG_TINTED" in dict(fog.defines)
    if not prepare_context(ctx).software:
        pytest.skip("on a GPU a path may be refused for its own faults")
    checks = runner.engine.renderer.path_checks
    for path in ("direct_faces", "layered_capture", "layered_array_capture"):
        assert checks.check(path).status == "verified", (path, checks.verdicts[path])
    assert "FOG_TINTED" in dict(fog.defines)
    np.testing.assert_array_equal(runner.frame(), before)


def test_a_layered_capture_that_writes_one_face_is_refused_and_the_sphere_stays_right(
        scene, ctx, fresh_checks, monkeypatch, caplog):
    """Both layered targets broken (the cube map's attachment face +X alone, the 2D array's
    copy layer 0 into every face): both refused, and every capture takes six passes."""
    face_zero_only(monkeypatch)
    copy_layer_zero_everywhere(monkeypatch)
    ents = {}
    runner = scene(chrome_scene(ents), (96, 72))
    with caplog.at_level(logging.WARNING, logger="speculum"):
        rgb = runner.frame()
    stage = probe_stage(runner)
    checks = runner.engine.renderer.path_checks
    assert checks.verdicts["layered_capture"].status == "refused"
    assert checks.verdicts["layered_array_capture"].status == "refused"
    assert "face 1" in checks.verdicts["layered_array_capture"].detail  # face 0 is right: the copy's is layer 0
    assert {"layered_capture", "layered_array_capture"} <= set(runner.stats.paths_refused)
    assert runner.stats.probe_path == "six_pass"
    assert stage.timings == {}  # auto never timed (so never used) the refused path
    for path in ("layered_capture", "layered_array_capture"):
        warnings = [r.getMessage() for r in caplog.records if f"the {path} path" in r.getMessage()]
        assert len(warnings) == 1 and ctx.info["GL_RENDERER"] in warnings[0] and ctx.info["GL_VERSION"] in warnings[0]
    # Every face written, none left at the sentinel or unwritten memory, and equal to a
    # capture drawn again by the plain path.
    probes = runner.engine.renderer.probes
    owner = ents["sphere"]
    drawn = cube_faces(ctx, probes, owner)
    position = stage.probes[owner].position
    views = {face: face_view(face, position, 0.05, 100.0, 128, skip=owner) for face in range(6)}
    probes.capture(owner, views, None, 0, direct=False)
    for face in range(6):
        assert np.isfinite(drawn[face]).all() and drawn[face].max() < SENTINEL / 2
        np.testing.assert_allclose(drawn[face], cube_faces(ctx, probes, owner)[face], atol=2e-3)
    # The sphere's right half reflects the red wall on its +X side.
    side = runner.ids() == ents["sphere"]
    side[:, :48] = False
    colour = srgb_to_linear(rgb[side])
    assert float(np.median(colour[:, 0] - colour[:, 1])) > 0.2
    # A forced layered path is not used either once refused.
    stage.path = "layered"
    runner.world.get(ents["wall"], Material).color = (0.05, 0.9, 0.05)
    runner.frame()
    runner.frame()
    assert runner.stats.probe_path == "six_pass" or runner.stats.probe_faces == 0


def test_where_only_the_cube_map_target_is_refused_probes_draw_one_pass_into_the_2d_array(
        scene, ctx, fresh_checks, monkeypatch, caplog):
    """The H200's case: the layered cube-map attachment writes face +X alone, a 2D array
    takes every layer.  The array capture is checked (only then) and verified, a probe's
    layered capture draws into the array and copies it into the cube, and every face is the
    six-pass capture's, texel for texel within half-float rounding (each face filled with a
    sentinel first, so a face the copy missed shows); auto times six_pass against it."""
    face_zero_only(monkeypatch)
    ents = {}
    runner = scene(marked_chrome_scene(ents), (64, 48))
    stage = probe_stage(runner)
    stage.path = "layered"
    with caplog.at_level(logging.WARNING, logger="speculum"):
        runner.frame()
    renderer = runner.engine.renderer
    verdicts = renderer.path_checks.verdicts
    assert verdicts["layered_capture"].status == "refused"
    assert verdicts["layered_array_capture"].status == "verified", verdicts["layered_array_capture"]
    assert not [r for r in caplog.records if "layered_array_capture" in r.getMessage()]
    assert runner.stats.probe_path == "layered" and "layered_array_capture" in runner.stats.paths_verified
    probes = renderer.probes
    owner = ents["sphere"]
    assert isinstance(probes._layered[owner], LayeredArrayTarget)
    state = stage.probes[owner]
    fill = np.full((128, 128, 4), SENTINEL, np.float16).tobytes()
    for face in range(6):
        probes.cubes[owner].texture.write(face, fill)
    assert probes.capture_probe(owner, frozenset(range(6)), state.position, state.settings) == "layered"
    layered = cube_faces(ctx, probes, owner)
    for face in range(6):
        probes.cubes[owner].texture.write(face, fill)
    stage.path = "six_pass"
    assert probes.capture_probe(owner, frozenset(range(6)), state.position, state.settings) == "six_pass"
    six_pass = cube_faces(ctx, probes, owner)
    for face in range(6):
        assert six_pass[face].max() < SENTINEL / 2 and six_pass[face].std() > 0.01  # a marker or the wall
        # (a half float's step is 2^-10 of its value: 0.0039 at 6.4, where the H200's faces differ by one)
        np.testing.assert_allclose(layered[face], six_pass[face], atol=2e-3, rtol=1e-3, err_msg=f"face {face}")
    # Auto times six_pass against the array capture (the layered path this context has).
    auto = scene(marked_chrome_scene({}), (64, 48))
    auto.frame()
    auto.frame()
    assert set(probe_stage(auto).timings) == {"six_pass", "layered"}
    assert probe_stage(auto).chosen_path in ("six_pass", "layered")


@pytest.mark.parametrize("stand_in", [copy_layer_zero_everywhere, array_layer_zero_only])
def test_a_broken_2d_array_capture_is_refused_and_a_verified_one_is_not(scene, ctx, fresh_checks, monkeypatch,
                                                                         stand_in):
    """On llvmpipe the 2D-array capture is verified; with its copy putting layer 0 in every
    face (face 0 right, face 1 the first wrong), or its attachment layer 0 alone (every
    face's triangles in face 0), the check refuses it on what the faces show.  Debug mode
    names the single-layer attachment at the clear."""
    runner = scene(lambda world: None, (32, 32))
    renderer = runner.engine.renderer
    checks = renderer.path_checks
    assert renderer.debug and checks.check("layered_array_capture").status == "verified"  # no misfire
    stand_in(monkeypatch)
    renderer.debug = False  # the pixels decide
    verdict = checks.check("layered_array_capture")
    first_wrong = "face 1" if stand_in is copy_layer_zero_everywhere else "face 0"
    assert verdict.status == "refused" and f"differs from the plain capture on {first_wrong}" in verdict.detail, verdict
    renderer.debug = True
    verdict = checks.check("layered_array_capture")
    assert verdict.status == "refused"
    if stand_in is array_layer_zero_only:
        assert "layered 2D-array capture, at the clear: the colour attachment is not layered" in verdict.detail
    else:  # the attachments are right: only the copy is wrong, and only the pixels show it
        assert "on face 1" in verdict.detail, verdict


def test_the_stand_in_is_what_the_check_catches(scene, ctx, fresh_checks, monkeypatch):
    """The face-0 stand-in really leaves five faces unwritten (so the refusal above is the
    check's doing); without the check the capture shows the sentinel there.  Debug mode
    names why at the clear: the attachment is not layered."""
    ents = {}
    runner = scene(marked_chrome_scene(ents), (64, 48))
    runner.frame()
    face_zero_only(monkeypatch)
    renderer = runner.engine.renderer
    probes = renderer.probes
    owner = ents["sphere"]
    views = {face: face_view(face, probe_stage(runner).probes[owner].position, 0.05, 100.0, 128, skip=owner)
             for face in range(6)}
    renderer.debug = True
    with pytest.raises(GLPassError, match=r"at the clear: .*colour attachment is not layered"):
        probes.capture_layered(owner, views, into="cube")
    renderer.debug = False
    for face in range(6):
        probes.cubes[owner].texture.write(face, np.full((128, 128, 4), SENTINEL, np.float16).tobytes())
    probes.capture_layered(owner, views, build_mips=False, into="cube")
    faces = cube_faces(ctx, probes, owner)
    assert faces[0].max() < SENTINEL / 2
    assert all((faces[face] == SENTINEL).all() for face in range(1, 6))


def layered_mips_skip_level_two(monkeypatch) -> None:
    """A stand-in for a driver whose layered mip pass draws nothing of level 2."""
    original = CubeMipTarget.bind_level

    def skip_level_two(self, level, unit, face=None):
        size = original(self, level, unit, face)
        if level == 2 and face is None:
            self.gl["glViewport"](0, 0, 0, 0)  # nothing of level 2 is drawn
        return size

    monkeypatch.setattr(CubeMipTarget, "bind_level", skip_level_two)


def test_box_mips_fall_back_to_glGenerateMipmap_where_the_layered_mip_pass_is_refused(
        scene, ctx, fresh_checks, monkeypatch):
    """Box mips need no drawn pass: where the layered one is refused (the H200), a probe's
    chain is the driver's own ``glGenerateMipmap`` (one call, where the per-face pass is 42
    attachments and draws for a 128 cube) and the per-face pass is never checked; each
    level is the 2x2 box average of the one above (numpy, from the level read back)."""
    layered_mips_skip_level_two(monkeypatch)
    ents = {}
    runner = scene(marked_chrome_scene(ents), (64, 48))
    runner.frame()
    renderer = runner.engine.renderer
    assert renderer.path_checks.verdicts["layered_mips"].status == "refused"
    assert renderer.path_checks.verdicts["face_mips"].status == "unchecked"
    probes = renderer.probes
    assert probes.mips.used == "build_mipmaps" and probes.cubes[ents["sphere"]].prefilter == "mips"
    above = np.stack(cube_faces(ctx, probes, ents["sphere"]))
    assert_box_filtered_chain(ctx, probes, ents["sphere"], above)


def assert_box_filtered_chain(ctx, probes, owner: int, above: np.ndarray) -> None:
    """Probe ``owner``'s mip levels 1 to 3 each the 2 x 2 box mean of the level above
    (``above``: its level 0's faces), within 4e-3."""
    for level in (1, 2, 3):
        drawn = np.stack(cube_faces(ctx, probes, owner, level))
        n = above.shape[1] // 2
        box = above.reshape(6, n, 2, n, 2, -1).mean(axis=(2, 4))
        assert np.abs(drawn - box).max() < 4e-3, level
        above = drawn


def rough_probe_sphere_scene(ents: dict):
    """``marked_chrome_scene``'s sphere at roughness 0.5 with a GGX-filtered probe of its own."""
    def build(world):
        marked_chrome_scene(ents)(world)
        world.get(ents["sphere"], Material).roughness = 0.5
        world.add_component(ents["sphere"], ReflectionProbe(resolution=32, prefilter="ggx"))
    return build


def test_a_mip_pass_that_skips_a_level_is_refused_and_the_per_face_pass_draws_the_ggx_chain(
        scene, ctx, fresh_checks, monkeypatch):
    layered_mips_skip_level_two(monkeypatch)
    ents = {}
    build = rough_probe_sphere_scene(ents)

    runner = scene(build, (96, 72))
    runner.frame()
    renderer = runner.engine.renderer
    verdicts = renderer.path_checks.verdicts
    assert verdicts["layered_mips"].status == "refused" and "level 2" in verdicts["layered_mips"].detail
    assert verdicts["face_mips"].status == "verified"
    probes = renderer.probes
    assert probes.mips.used == "per_face" and probes.cubes[ents["sphere"]].prefilter == "ggx"
    level0 = cube_faces(ctx, probes, ents["sphere"])
    for level in (2, 3):
        reference = ggx_reference(level0, 32, (level / 5) ** 2, 32 >> level)
        drawn = np.stack(cube_faces(ctx, probes, ents["sphere"], level))
        for face in range(6):
            assert np.abs(drawn[face] - reference[face]).mean() / reference.max() < 0.02, (level, face)


def test_swapped_face_attachments_are_refused_and_faces_are_copied(scene, ctx, fresh_checks, monkeypatch):
    original = RawGL.attach_cube_face
    monkeypatch.setattr(RawGL, "attach_cube_face",
                        lambda self, framebuffer, cube, face, level=0: original(self, framebuffer, cube, face ^ 1,
                                                                                level))
    ents = {}
    runner = scene(marked_chrome_scene(ents), (64, 48))
    probe_stage(runner).path = "six_pass"
    runner.frame()
    renderer = runner.engine.renderer
    assert renderer.path_checks.verdicts["direct_faces"].status == "refused"
    assert "direct_faces" in runner.stats.paths_refused
    probes = renderer.probes
    owner = ents["sphere"]
    drawn = cube_faces(ctx, probes, owner)
    position = probe_stage(runner).probes[owner].position
    views = {face: face_view(face, position, 0.05, 100.0, 128, skip=owner) for face in range(6)}
    probes.capture(owner, views, None, 0, direct=False)
    for face in range(6):
        np.testing.assert_array_equal(drawn[face], cube_faces(ctx, probes, owner)[face], err_msg=f"face {face}")


def test_debug_mode_names_a_cube_bound_for_sampling_while_it_is_drawn_into(scene, ctx, monkeypatch):
    """Drawing into a cube map a program may sample is a rendering feedback loop (undefined
    on a GPU): captures unbind it first; without that, debug mode says so at the clear."""
    ents = {}
    runner = scene(marked_chrome_scene(ents), (64, 48))
    runner.frame()
    renderer = runner.engine.renderer
    probes = renderer.probes
    owner = ents["sphere"]

    @contextmanager
    def keeps_it_bound(self, key):
        self.cubes[key].texture.use(PROBE_UNIT)
        yield

    monkeypatch.setattr(ProbeCaptures, "_drawing_into", keeps_it_bound)
    views = {face: face_view(face, probe_stage(runner).probes[owner].position, 0.05, 100.0, 128, skip=owner)
             for face in range(6)}
    assert renderer.debug
    with pytest.raises(GLPassError, match=r"feedback loop"):
        probes.capture_layered(owner, views, into="cube")  # drawn into the cube itself (the 2D array is not sampled)
    message = str(pytest.raises(GLPassError, probes.capture_layered, owner, views, into="cube").value)
    units = re.search(r"texture units \(([^)]*)\)", message)
    # PROBE_UNIT named (a driver that refused the layered mip pass has glGenerateMipmap's
    # binding on moderngl's default unit too, which the real _drawing_into would clear).
    assert units and PROBE_UNIT in {int(u) for u in units.group(1).replace(",", " ").split()}, message


def test_every_layered_geometry_shader_writes_gl_layer_before_each_vertex():
    """gl_Layer, like every output, is undefined after EmitVertex: a layered geometry shader
    must write it again for every vertex (a driver may take it from any vertex)."""
    for path in sorted(SHADERS.glob("*.geom")):
        text = path.read_text()
        if "gl_Layer" not in text:
            continue
        for body in re.split(r"EmitVertex\(\);", text)[:-1]:
            last = body.rsplit("gl_Layer", 1)
            assert len(last) == 2 and "EndPrimitive" not in last[1], f"{path.name}: a vertex emitted without gl_Layer"


def test_scene_and_composite_pixels_are_left_out_only_after_their_derivatives_are_taken():
    """A discard ends its pixel's invocation, and GLSL leaves the derivatives of the rest of
    its 2x2 quad undefined after it (an H200 shaded the pixels beside another view's
    otherwise while the node test discarded first; llvmpipe keeps every pixel of a quad
    running, so no frame here can show it).  scene.frag leaves another view's pixels and a
    cutout's holes out at DISCARD_DROPPED only, with nothing after it that takes a
    derivative (its early discards, a decal's clear part and a water's surface with no foam
    in the FOAM builds, are a software rasteriser's builds', which says why; a GPU's,
    DISCARDS_LAST, drop them there too); the bumpy
    composite takes its map's UV derivatives before its first discard and reads the map
    through them."""
    scene = (SHADERS / "scene.frag").read_text()
    main = scene[scene.index("void main() {"):]
    early = [line.strip() for line in main.splitlines() if "discard" in line and not line.strip().startswith("//")]
    assert early == ["if (s.alpha <= 0.0) discard;",   # (FOAM builds' only)
                     "if (transparent == 3 && s.alpha < 0.5 / 255.0) discard;"], early
    assert ("#ifdef DISCARDS_LAST\n    dropped_pixel = dropped_pixel || (transparent == 3 && s.alpha < 0.5 / 255.0);"
            "\n#else\n    if (transparent == 3") in main
    assert ("#ifdef DISCARDS_LAST\n    dropped_pixel = dropped_pixel || s.alpha <= 0.0;\n#else\n"
            "    if (s.alpha <= 0.0)") in main
    derivatives = re.compile(r"dFdx|dFdy|fwidth|texture\(|MAP_TEXTURE|textureQueryLod")
    for after in main.split("DISCARD_DROPPED();")[1:]:
        rest = re.split(r"\breturn\b|\n}", after, maxsplit=1)[0]
        assert not derivatives.search(rest), rest
    composite = (SHADERS / "mirror_composite.frag").read_text()
    body = composite[composite.index("void main() {"):]
    assert body.index("dFdx(mirror_uv)") < body.index("discard;")
    for name in ("normal_map.glsl", "water.glsl", "water_waves.glsl"):
        assert "texture(normal_map" not in (SHADERS / "include" / name).read_text(), name


def test_the_layered_target_state_is_what_a_layered_draw_needs_here_and_names_a_face_attachment(
        scene, ctx, monkeypatch):
    """What ``gpu-report`` prints where the layered capture is refused: llvmpipe binds and
    attaches it as the draw needs; the H200-like stand-in shows up as attachments that are
    not layered."""
    runner = scene(marked_chrome_scene({}), (32, 24))
    checks = runner.engine.renderer.path_checks
    state = checks.layered_target_state()
    assert state["problems"] == [] and state["colour_layered"] and state["depth_layered"]
    assert state["viewport"] == (0, 0, 16, 16) and state["cube_bound_on_units"] == ()
    face_zero_only(monkeypatch)
    problems = checks.layered_target_state()["problems"]
    assert "the colour attachment is not layered" in problems and "the depth attachment is not layered" in problems


def test_paths_that_both_draw_only_the_sky_prove_nothing_and_are_refused(scene, ctx, fresh_checks, monkeypatch):
    """With the check's quads hidden from every view, the plain capture and the alternative
    agree on a sky-only cube; the check must not take that for a verified path."""
    from components.visibility import visibility_code
    from engine.render import path_checks

    original = path_checks._fill_row

    def hidden(row, face):
        original(row, face)
        row["tint"] = (1.0, 1.0, 1.0, visibility_code(0xF, 1))  # hidden in every kind of view
    monkeypatch.setattr(path_checks, "_fill_row", hidden)
    runner = scene(lambda world: None, (32, 32))
    checks = runner.engine.renderer.path_checks
    for name in ("direct_faces", "layered_capture"):
        verdict = checks.check(name)
        assert verdict.status == "refused" and "shows no check quad" in verdict.detail, verdict
    monkeypatch.setattr(path_checks, "_fill_row", original)
    assert checks.check("direct_faces").status == "verified"  # with its quads shown, the check passes again


def test_where_only_the_cube_map_target_is_refused_point_shadows_draw_one_pass_into_the_2d_array(
        scene, ctx, fresh_checks, monkeypatch):
    """The H200's case for a point light's distance cube: not six passes but one layered
    pass into a six-layer R32F array whose layers are copied into the cube's faces; every
    face is the six-pass cube's (each face filled with a sentinel before either draw, so a
    face the copy missed shows)."""
    from pyglm import glm

    from components import PointLight
    from tests.test_shadows import _floor_scene

    face_zero_only(monkeypatch)
    lamp = (3.2, 1.3, 0.9)
    runner = scene(lambda world: _floor_scene(world, (0.0, 5.5, 6.0), (0.0, 0.0, 0.0), sun=False, point=lamp),
                   (64, 48))
    runner.frame()
    renderer = runner.engine.renderer
    verdicts = renderer.path_checks.verdicts
    assert verdicts["layered_capture"].status == "refused"
    assert verdicts["layered_array_capture"].status == "verified", verdicts["layered_array_capture"]
    assert runner.stats.shadow_path == "layered" and runner.stats.shadow_faces_drawn == 6
    maps = renderer.shadows
    (slot, cube), = maps.cubes.items()
    assert isinstance(maps._layered[slot], LayeredArrayTarget)
    light = next(light for _, light in runner.world.query_one(PointLight))
    faces = {}
    for into in ("array", None):
        for face in range(6):
            cube.write(face, np.full((cube.size[0], cube.size[1]), SENTINEL, np.float32).tobytes())
        assert maps.draw_point(slot, 0, glm.vec3(lamp), light.range, light.shadow_resolution, light.shadow_softness,
                               into) == ("layered" if into else "six_pass")
        faces[into] = [read_cube_level(ctx, cube, face, 0, SCRATCH_UNIT)[..., 0] for face in range(6)]
    assert sum(faces[None][face].min() < 1.0 for face in range(6)) >= 2  # the floor, the box: something casts
    for face in range(6):
        assert faces[None][face].max() < SENTINEL / 2
        np.testing.assert_allclose(faces["array"][face], faces[None][face], rtol=1e-6, atol=1e-7,
                                   err_msg=f"face {face}")


def test_a_ggx_chain_where_both_mip_passes_are_refused_is_box_filtered_and_said_once(
        scene, ctx, fresh_checks, monkeypatch, caplog):
    """A driver whose layered and per-face mip passes both leave level 2 undrawn: both are
    refused (each naming level 2), a GGX probe's chain is then the driver's glGenerateMipmap
    (``prefilter`` "mips", said in one warning however many builds), each level the 2x2 box
    average of the one above (numpy, from the level read back), level 2 included."""
    original = CubeMipTarget.bind_level

    def skip_level_two(self, level, unit, face=None, *rest):
        size = original(self, level, unit, face, *rest)
        if level == 2:
            self.gl["glViewport"](0, 0, 0, 0)  # nothing of level 2 is drawn, a face at a time or all at once
        return size

    monkeypatch.setattr(CubeMipTarget, "bind_level", skip_level_two)
    ents = {}
    build = rough_probe_sphere_scene(ents)

    runner = scene(build, (64, 48))
    with caplog.at_level(logging.WARNING, logger="speculum"):
        runner.frame()
        runner.world.get(ents["wall"], Material).color = (0.05, 0.9, 0.05)   # captured and built again
        runner.frame()
    renderer = runner.engine.renderer
    verdicts = renderer.path_checks.verdicts
    for path in ("layered_mips", "face_mips"):
        assert verdicts[path].status == "refused" and "level 2" in verdicts[path].detail, verdicts[path]
    probes = renderer.probes
    assert probes.mips.used == "build_mipmaps" and probes.cubes[ents["sphere"]].prefilter == "mips"
    said = [r.getMessage() for r in caplog.records if "box-filtered instead" in r.getMessage()]
    assert len(said) == 1 and "GGX-prefiltered probes" in said[0]
    above = np.stack(cube_faces(ctx, probes, ents["sphere"]))
    assert above.max() < SENTINEL / 2 and (above[..., 1] > 2 * above[..., 0]).any()   # the green wall, drawn
    assert_box_filtered_chain(ctx, probes, ents["sphere"], above)


def _draw_framebuffer_binding(ctx) -> int:
    import ctypes

    from engine.render.raw_gl import GL_DRAW_FRAMEBUFFER_BINDING, _load

    get = _load(ctx, "glGetIntegerv", ctypes.CFUNCTYPE(None, ctypes.c_uint, ctypes.POINTER(ctypes.c_int)))
    value = ctypes.c_int(0)
    get(GL_DRAW_FRAMEBUFFER_BINDING, ctypes.byref(value))
    return value.value


def test_a_cube_face_attachment_the_driver_refuses_is_named_and_leaves_moderngls_framebuffer_bound(ctx):
    """``RawGL.attach_cube_face`` checks its calls with glGetError: a face of a mip level the
    cube does not have (level 10 of a 16-texel cube: Mesa says incomplete, a GPU may say
    GL_INVALID_VALUE) is a RuntimeError naming the face, the level, the framebuffer status and
    the error, no error is left for the next pass, and the
    framebuffer moderngl last bound is the one the driver has bound (read back with glGet)."""
    raw = RawGL(ctx)
    cube = ctx.texture_cube((16, 16), 4, dtype="f2")
    colour = ctx.texture((16, 16), 4, dtype="f2")
    target = ctx.framebuffer([colour])
    other_colour = ctx.texture((8, 8), 4)
    other = ctx.framebuffer([other_colour])
    try:
        other.use()
        assert ctx.error == "GL_NO_ERROR"
        with pytest.raises(RuntimeError, match=r"cube-map face 2 level 10 of 16 as a colour attachment: "
                                               r"framebuffer status 0x[0-9a-f]+, GL error 0x[0-9a-f]+") as info:
            raw.attach_cube_face(target, cube, 2, level=10)
        assert "status 0x8cd5, GL error 0x0" not in str(info.value)   # something was wrong, and said
        assert ctx.error == "GL_NO_ERROR"
        assert ctx.fbo is other and _draw_framebuffer_binding(ctx) == other.glo
        raw.attach_cube_face(target, cube, 3)   # a face it has: attached, and still moderngl's bound
        assert _draw_framebuffer_binding(ctx) == other.glo and ctx.error == "GL_NO_ERROR"
        target.use()
        target.clear(0.25, 0.5, 0.75, 1.0)
        ctx.finish()
        face = read_cube_level(ctx, cube, 3, 0, SCRATCH_UNIT)
        np.testing.assert_allclose(face, np.broadcast_to((0.25, 0.5, 0.75, 1.0), face.shape), atol=1e-3)
    finally:
        release_framebuffer(target)   # (bound ones unbound first: a deleted name left bound breaks the next pass)
        release_framebuffer(other)
        for thing in (colour, other_colour, cube):
            thing.release()


def test_a_layered_target_clears_every_face_whole_whatever_moderngls_framebuffer_left_set(ctx):
    """``LayeredCubeTarget.bind`` sets the viewport, scissor and write masks for its own
    framebuffer: bound after a moderngl framebuffer with a 2x2 scissor box, its colour
    mask off but for red and depth writes off, its clear reaches every texel of all six
    faces; after ``unbind`` moderngl's framebuffer is bound again with its own state, so its
    next clear still keeps to its scissor box and mask."""
    cube = ctx.texture_cube((16, 16), 4, dtype="f2")
    colour = ctx.texture((16, 16), 4, dtype="f2")
    depth = ctx.depth_texture((16, 16))
    other = ctx.framebuffer([colour], depth)
    layered = None
    try:
        other.use()
        other.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        other.scissor = (0, 0, 2, 2)
        other.color_mask = (True, False, False, False)
        other.depth_mask = False
        other.use()
        for face in range(6):
            cube.write(face, np.full((16, 16, 4), SENTINEL, np.float16).tobytes())
        layered = LayeredCubeTarget(ctx, cube)
        layered.bind()
        layered.clear((0.25, 0.5, 0.75, 1.0))
        layered.unbind()
        assert ctx.error == "GL_NO_ERROR" and _draw_framebuffer_binding(ctx) == other.glo
        for face in range(6):
            texels = read_cube_level(ctx, cube, face, 0, SCRATCH_UNIT)
            np.testing.assert_allclose(texels, np.broadcast_to((0.25, 0.5, 0.75, 1.0), texels.shape), atol=1e-3,
                                       err_msg=f"face {face}")
        other.clear(1.0, 1.0, 1.0, 1.0)   # moderngl's own state again: red, in the 2x2 box alone
        image = np.frombuffer(other.read(components=4, dtype="f2"), np.float16).reshape(16, 16, 4)
        assert (image[:2, :2] == (1, 0, 0, 0)).all() and (image[2:] == 0).all() and (image[:, 2:] == 0).all()
    finally:
        if layered is not None:
            layered.release()
        release_framebuffer(other)
        for thing in (colour, depth, cube):
            thing.release()
