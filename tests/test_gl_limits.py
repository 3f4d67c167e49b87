"""Limits of the GL context are checked before anything is made, and named; debug mode
names the pass that raised a GL error; an error left by other code is not the engine's."""
from __future__ import annotations

import numpy as np
import pytest

from components import Camera, Material, MeshRef, Transform
from engine.assets.mesh import box
from engine.assets.texture_data import TextureData
from engine.core.errors import GLLimitError, GLPassError
from engine.core.frame_io import Output
from engine.render.gl_context import GLCapabilities
from engine.render.targets import CaptureTarget, RenderTargets


def test_a_texture_wider_than_the_gl_limit_is_named_with_its_entity(scene, ctx):
    limit = GLCapabilities.read(ctx).max_texture_size
    wide = TextureData(np.zeros((1, limit + 1, 4), np.uint8), name="too wide.png")
    ents = {}

    def build(world):
        world.spawn(Transform(position=(0, 0, 3)), Camera())
        world.spawn(Transform(), MeshRef(box()), Material())
        ents["crate"] = world.spawn(Transform(), MeshRef(box()), Material(texture=wide))

    runner = scene(build, (32, 32))
    before = runner.engine.renderer.resource_counts()
    with pytest.raises(GLLimitError, match=rf"entity {ents['crate']}: Material.texture: texture 'too wide.png' "
                                           rf"is {limit + 1}x1.*at most {limit}x{limit}"):
        runner.frame()
    assert ctx.error == "GL_NO_ERROR"  # refused before any GL call
    counts = runner.engine.renderer.resource_counts()
    assert counts["textures"] == 0 and counts["meshes"] <= before["meshes"] + 1  # nothing half-made for it


@pytest.mark.parametrize("make", [CaptureTarget, RenderTargets])
def test_a_target_over_the_gl_limit_is_refused_before_it_is_made(ctx, make):
    limit = GLCapabilities.read(ctx).max_texture_size
    with pytest.raises(GLLimitError, match=rf"{limit + 1}x1 pixels.*at most"):
        make(ctx, (limit + 1, 1))
    assert ctx.error == "GL_NO_ERROR"


def test_an_output_over_the_limit_fails_the_frame_cleanly_and_the_next_frame_works(scene, ctx):
    runner = scene(lambda world: world.spawn(Transform(position=(0, 0, 3)), Camera()), (16, 16))
    limit = GLCapabilities.read(ctx).max_texture_size
    with pytest.raises(GLLimitError):
        runner.engine.frame(1 / 60, Output(runner.capture.framebuffer, (limit + 1, 1)))
    assert ctx.error == "GL_NO_ERROR"
    runner.frame()  # the right size again: no error pending from the refused one


def test_debug_mode_names_the_pass_that_left_a_gl_error(scene, ctx):
    runner = scene(lambda world: world.spawn(Transform(position=(0, 0, 3)), Camera()), (16, 16))
    renderer = runner.engine.renderer
    assert renderer.debug  # the tests run in debug mode (tests/conftest.py)
    ctx.enable_direct(0xFFFF)  # not a capability: GL_INVALID_ENUM
    with pytest.raises(GLPassError, match="GL_INVALID_ENUM in the composite pass"):
        renderer.checkpoint("composite")
    assert ctx.error == "GL_NO_ERROR"  # reading it cleared it


def test_an_error_left_by_other_code_is_reported_as_not_the_engines(scene, ctx):
    runner = scene(lambda world: world.spawn(Transform(position=(0, 0, 3)), Camera()), (16, 16))
    runner.frame()
    ctx.enable_direct(0xFFFF)
    with pytest.raises(GLPassError, match="pending before frame 2 .*not by the engine"):
        runner.frame()
    runner.frame()  # the report cleared it; the engine goes on


@pytest.mark.parametrize("name", ["texture_anisotropy", "reflection_anisotropy", "normal_map_anisotropy"])
@pytest.mark.parametrize("bad", [float("nan"), float("inf"), 0.5, 0, "8", None, True, "past"])
def test_a_filtering_setting_refuses_what_the_driver_cannot_filter_with(scene, ctx, name, bad):
    """The renderer's anisotropy settings are checked when set, naming the setting and the
    context's reach: a NaN or a value past max_anisotropy was clamped in silence, and a
    string failed inside a scene pass.  A refused value leaves the one before, and the next
    frame draws as the one before it."""
    most = max(float(ctx.max_anisotropy), 1.0)
    if bad == "past":
        bad = most + 1.0

    def build(world):
        world.spawn(Transform(position=(0, 0, 3)), Camera())
        world.spawn(Transform(), MeshRef(box()), Material(color=(0.8, 0.4, 0.2)))

    runner = scene(build, (32, 32))
    renderer = runner.engine.renderer
    before = runner.frame()
    kept = getattr(renderer, name)
    with pytest.raises(ValueError, match=rf"{name} must be a number from 1 \(off\) to {most:g}"):
        setattr(renderer, name, bad)
    assert getattr(renderer, name) == kept
    assert np.array_equal(runner.frame(), before)
    setattr(renderer, name, most)   # the context's own reach is taken
    assert getattr(renderer, name) == most


# --- limits past what the start-up check asks, checked when the thing needing them is given ---------

def _limit_scene(extra):
    """A camera on a lit box with ``extra(world)`` spawned: the thing whose size meets a limit."""
    from components import DirectionalLight

    def build(world):
        world.spawn(Transform(position=(0, 0, 4)), Camera())
        world.spawn(Transform(), MeshRef(box()), Material(color=(0.8, 0.5, 0.3)))
        world.spawn(DirectionalLight(direction=(0.3, -1.0, -0.4), shadows=False))
        return extra(world)
    return build


def _sun(world):
    from components import DirectionalLight

    world.spawn(DirectionalLight(direction=(-0.3, -1.0, 0.2), shadow_resolution=1024))   # atlas of 2 x 2 tiles
    return world.query_one(DirectionalLight)


def _lamp(angle):
    def spawn(world):
        from components import PointLight

        return world.spawn(Transform(position=(0.5, 2.0, 1.0)),
                           PointLight(shadows=True, shadow_resolution=1024, spot_angle=angle))
    return spawn


def _lamp_through_glass(world):
    """An all-round lamp and a pane of glass casting into its light (the lamps' see-through atlas)."""
    world.spawn(Transform(position=(0.0, 1.0, 0.0)), MeshRef(box((1.0, 0.1, 1.0))),
                Material(color=(0.3, 0.6, 0.9, 0.4)))
    return _lamp(180.0)(world)


def _probe(world):
    from components import ReflectionProbe, Reflective

    return world.spawn(Transform(position=(1.5, 0, 0)), MeshRef(box()), Material(metallic=1.0, roughness=0.0),
                       Reflective("cube"), ReflectionProbe(resolution=64))


def _monitor(world):
    from components import Monitor

    lens = world.spawn(Transform(position=(0, 0, 5)), Camera(active=False))
    return world.spawn(Transform(position=(-1.5, 0, 0)), MeshRef(box()), Material(color=(0, 0, 0, 1)),
                       Monitor(camera=lens, size=(64, 48)))


def _sky(world):
    from components import Skybox

    return world.spawn(Skybox(face_size=64))


def _sky_faces(world):
    from components import Skybox

    return world.spawn(Skybox(faces=np.full((6, 64, 64, 3), 0.5, np.float32)))


def _smaller(runner, what):
    """The thing made to fit the pretended limit again."""
    from components import DirectionalLight, Monitor, PointLight, ReflectionProbe, Skybox

    world = runner.world
    if what == "sun":
        for _, light in world.query_one(DirectionalLight):
            light.shadow_resolution = 256
    elif what in ("lamp", "lamp_glass", "spot"):
        for _, light in world.query_one(PointLight):
            light.shadow_resolution = 256
    elif what == "probe":
        for _, probe in world.query_one(ReflectionProbe):
            probe.resolution = 32
    elif what == "monitor":
        for _, monitor in world.query_one(Monitor):
            monitor.size = (16, 16)
    elif what == "sky":
        for _, sky in world.query_one(Skybox):
            sky.face_size = 32
    else:
        for _, sky in world.query_one(Skybox):
            sky.faces = np.full((6, 32, 32, 3), 0.5, np.float32)


LIMIT_CASES = [
    # (name, spawn, pretended caps, what the error says)
    ("sun", _sun, {"max_texture_size": 1024},
     r"DirectionalLight.shadow_resolution 1024: the suns' shadow atlas .* is 2048x2048 texels: .* takes at most 1024 "
     r"\(GL_MAX_TEXTURE_SIZE\)"),
    ("lamp", _lamp(180.0), {"max_cube_map_size": 512},
     r"PointLight.shadow_resolution 1024: a point light's shadow cube map is 1024x1024 texels a face: .* at most 512 "
     r"\(GL_MAX_CUBE_MAP_TEXTURE_SIZE\)"),
    ("lamp_glass", _lamp_through_glass, {"max_texture_size": 2048},
     r"PointLight.shadow_resolution 1024: the lamps' see-through atlas is 3096x1032 texels: .* at most 2048 "
     r"\(GL_MAX_TEXTURE_SIZE\)"),
    ("spot", _lamp(40.0), {"max_texture_size": 2048},
     r"PointLight.shadow_resolution 1024: the spot lights' shadow atlas is 2128x1064 texels: .* at most 2048 "
     r"\(GL_MAX_TEXTURE_SIZE\)"),
    ("probe", _probe, {"max_cube_map_size": 32},
     r"reflection probe of entity \d+: ReflectionProbe.resolution 64 is over this OpenGL's "
     r"GL_MAX_CUBE_MAP_TEXTURE_SIZE 32"),
    ("monitor", _monitor, {"max_texture_size": 32},
     r"Monitor on entity \d+: a picture of 64x48 pixels is over this OpenGL's \(.*\) 32 \(GL_MAX_TEXTURE_SIZE\)"),
    ("sky", _sky, {"max_cube_map_size": 32},
     r"Skybox.face_size: a sky cube map of 64x64 texels a face is over this OpenGL's \(.*\) 32 "
     r"\(GL_MAX_CUBE_MAP_TEXTURE_SIZE\)"),
    ("sky_faces", _sky_faces, {"max_cube_map_size": 32},
     r"Skybox.faces: a sky cube map of 64x64 texels a face is over this OpenGL's \(.*\) 32"),
]


@pytest.mark.parametrize("what, spawn, caps, message", LIMIT_CASES, ids=[case[0] for case in LIMIT_CASES])
def test_a_size_past_a_pretended_smaller_limit_is_refused_naming_it_and_the_frame_after_a_fix_draws(
        scene, ctx, what, spawn, caps, message):
    """The start-up check asks only GL 4.1's least of each limit (2048 texels a texture, 512 a
    cube map face), while components take more (a shadow map up to 4096, a sky face and a
    probe up to 2048, a monitor's picture 2048): each thing whose texture a limit bounds is
    checked against this context's limit when it is given, on a context pretending a smaller
    one (its caps replaced), refused with a GLLimitError naming the field, the size and the
    GL limit, with no GL error left; made to fit, the next frame draws it and equals the
    frame drawn with the real limits."""
    import dataclasses

    runner = scene(_limit_scene(spawn), (32, 24))
    renderer = runner.engine.renderer
    real = renderer.caps
    renderer.caps = dataclasses.replace(real, **caps)
    with pytest.raises(GLLimitError, match=message):
        runner.frame()
    assert ctx.error == "GL_NO_ERROR"
    _smaller(runner, what)
    for _ in range(3):
        pretended = runner.frame()   # (a monitor seeing its own screen settles two frames later)
    renderer.caps = real
    assert np.array_equal(runner.frame(), pretended)   # nothing left half-made by the refusal


def test_posed_entities_past_the_pose_texture_rows_are_refused_naming_the_entity(scene, ctx):
    """The pose texture has a row a posed (skinned or morphed) entity and GL_MAX_TEXTURE_SIZE
    rows at most: pretending one row, the second morphed sheet is refused naming its entity
    and the limit, and with it gone the first draws as before."""
    from components import Morph
    from tests.test_morph_targets import RED, lit, morphed_sheet

    runner = scene(lit(lambda world: None), (32, 24))
    renderer = runner.engine.renderer
    renderer.pose_rows.max_rows = 1
    runner.world.spawn(Transform(), MeshRef(morphed_sheet()), Material(color=RED), Morph((0.5, 0.5)))
    before = runner.frame()
    second = runner.world.spawn(Transform(position=(0.3, 0, 0)), MeshRef(morphed_sheet()), Material(color=RED),
                                Morph((0.2, 0.2)))
    with pytest.raises(GLLimitError, match=rf"entity {second}: a Skin or Morph past this OpenGL's 1 posed entities "
                                           r"\(the pose texture's rows: GL_MAX_TEXTURE_SIZE\)"):
        runner.frame()
    assert ctx.error == "GL_NO_ERROR"
    runner.world.delete_entity(second)
    assert np.array_equal(runner.frame(), before)
