"""What llvmpipe forgives and a GPU driver may not, checked on real frames of the sample
level, the README examples, the games and the benchmark scenes (mirrors, portals, shadows,
virtual lights, probes, post-processing, a resize).

1. **Every draw is legal GL 4.1** (``tests/gl_strict.py``, wrapping ``VertexArray.render`` and
   ``Framebuffer.clear`` for the test only): each active sampler finds a complete texture of
   its own type on its unit (mip levels, integer formats filtered NEAREST, shadow samplers on
   depth textures with comparison on and the reverse), no two sampler types share a unit, no
   sampled image is attached to the framebuffer drawn into (a rendering feedback loop), and
   no integer image is cleared with glClear.  Broken on purpose: with the scene pass binding
   no blank albedo map for batches without one, the check names the float sampler finding
   the node image another pass left on unit 0; with the fallback composite binding no blank
   id images, it names the feedback loop on the parent's seen image; with the level clear
   back to ``Framebuffer.clear``, the glClear of the id images.
2. **No texel is read before it is written**: every texture the engine makes without data
   is made full of NaN (float images) or noise instead (a test-only hook around moderngl's
   texture constructors, where llvmpipe would zero-fill; a GPU hands back whatever memory
   held), every buffer made with room only (``reserve``) full of random bytes, and the
   frames, colour and ids, must be those of a run without it, bit for bit.
   Broken on purpose: without the clear of a level's images when they are made
   (``RenderTargets``), hall_start's frame 2 differs in every pixel with NaN (the water
   composite's bilinear taps beside the claimed pixels read the first frame's unwritten
   texels, and the NaN spreads through the next frame's end images and bloom), and in 21
   pixels of the water's edge with finite noise.
"""
from __future__ import annotations

from collections.abc import Callable

import moderngl
import numpy as np
import pytest

from engine.render import bindings
from engine.render.targets import CaptureTarget, release_framebuffer
from tests import golden
from tests.gl_strict import noisy_textures, strict_draws
from tests.golden_scenes import cases
from tests.support import engine_frames

DT = 1.0 / 60.0
SIZE = (160, 90)
CASE_BY_NAME = {case.name: case for case in cases()}


def _golden(name: str) -> Callable[[moderngl.Context], list[np.ndarray]]:
    def run(ctx: moderngl.Context) -> list[np.ndarray]:
        frame = golden.render_case(ctx, CASE_BY_NAME[name])
        return [frame.rgb, frame.ids]
    return run


def _engine_frames(ctx: moderngl.Context, game, frames: int, configure=None, step=None,
                   sizes: tuple[tuple[int, int], ...] = (SIZE,)) -> list[np.ndarray]:
    """Run ``game`` for ``frames`` frames at each of ``sizes`` in turn (a resize between);
    every size's last frame and ids."""
    return engine_frames(ctx, game, frames, sizes, configure, step, dt=DT)


def _lighting(variant: str, mirrors: int = 2, gpu: bool = False):
    def run(ctx):
        from benchmarks.lighting import VARIANTS, gpu_passes
        from benchmarks.mirrors import MirrorRing

        chosen = next(v for v in VARIANTS if v.name == variant)

        def configure(engine):
            chosen.configure(engine)
            if gpu:
                gpu_passes(engine, None)
        return _engine_frames(ctx, MirrorRing(mirrors), 3, configure, chosen.step)
    return run


def _soft_sun(ctx):
    """The mirror ring's sun 2 degrees across with three cascades and a blend band (the
    SOFT_SUN_SHADOWS builds: the atlas read as it is on a unit of its own through a sampler
    that compares nothing, beside its comparisons), the grid filter, a box sliding under it."""
    from benchmarks.lighting import _cascades, _moving_caster, _slide_caster
    from benchmarks.mirrors import MirrorRing
    from components import DirectionalLight

    def configure(engine):
        _cascades(engine)
        _moving_caster(engine)
        engine.renderer.shadows.filter = "grid"
        for _, light in engine.world.query_one(DirectionalLight):
            light.angular_diameter = 2.0
    return _engine_frames(ctx, MirrorRing(2), 3, configure, _slide_caster)


def _point_shadows(ctx):
    """The mirror ring with its lamp's shadows on (distance cube maps) and a mirror throwing
    the sun (a virtual light), the boxes spinning."""
    from benchmarks.lighting import _mirror_light
    from benchmarks.mirrors import MirrorRing
    from components import PointLight

    def configure(engine):
        _mirror_light(engine)
        for _, light in engine.world.query_one(PointLight):
            light.shadows = True
    return _engine_frames(ctx, MirrorRing(3), 3, configure)


def _spot_shadows(ctx):
    """The mirror ring's lamp made a spot aimed down and a second spot beside it (each within
    SPOT_MAP_MAX_ANGLE: both shadow slots perspective maps, tiles of the spot atlas, of two
    sizes), casting, the boxes spinning; the grid filter at the widest softness, a hard
    edge, so lookups at the cone's edge reach into the maps' borders; a ball scattering light
    under its surface under them (SUBSURFACE: each slot's map read again where the light enters it)."""
    from benchmarks.mirrors import MirrorRing
    from components import Material, MeshRef, PointLight, Transform, look_rotation
    from engine.assets.mesh import sphere

    def configure(engine):
        world = engine.world
        for entity, light in world.query_one(PointLight):
            light.shadows, light.spot_angle = True, 30.0
            world.get(entity, Transform).rotation = look_rotation((0.0, -1.0, 0.0), (0.0, 0.0, -1.0))
        world.spawn(Transform(position=(3.0, 3.0, 1.0), rotation=look_rotation((-0.5, -1.0, 0.0), (0.0, 0.0, -1.0))),
                    PointLight(intensity=6.0, range=12.0, spot_angle=20.0, spot_blend=0.0, shadows=True,
                               shadow_resolution=256, shadow_softness=8.0))
        world.spawn(Transform(position=(1.5, 0.5, 0.5)), MeshRef(sphere(0.5)), Material(subsurface=1.0))
        engine.renderer.shadows.filter = "grid"
    return _engine_frames(ctx, MirrorRing(3), 3, configure)


def _rect_lights(ctx):
    """The mirror ring's lamp a panel (PointLight.rectangle: the RECT_LIGHTS builds, the LTC
    rows of the irradiance table) showing a picture on its face (PANEL_PICTURES: its mip chain
    read by textureLod) and a tube beside it, casting soft shadows from their cubes (the grid filter), with
    contact shadows, a mirror
    throwing the sun and the lamp (virtual lights, one a rectangle's image), and balls with a
    clear coat, a sheen and anisotropic highlights lit by it, one lightmapped (LIGHTMAP)
    beside its own occlusion map, and one scattering light under its surface (SUBSURFACE)."""
    from benchmarks.lighting import _mirror_light
    from benchmarks.mirrors import MirrorRing
    from components import Camera, ContactShadows, Material, MeshRef, PointLight, Transform
    from engine.assets.mesh import sphere
    from tests.test_rect_light_images import quadrant_image

    def configure(engine):
        _mirror_light(engine)
        world = engine.world
        for _, light in world.query_one(PointLight):
            light.rectangle, light.shadows, light.contact_shadows = (1.0, 0.5), True, True
            light.cookie = quadrant_image()
        engine.renderer.shadows.filter = "grid"   # (its soft shadows: SOFT_POINT_SHADOWS)
        for camera, _ in world.query_one(Camera):
            world.add_component(camera, ContactShadows())
        world.spawn(Transform(position=(0.0, 2.0, 1.5)), PointLight(intensity=3.0, length=1.2, radius=0.02,
                                                                     shadows=True, volumetric=0.0))  # a tube too
        from engine.assets.texture_data import TextureData
        from tests.test_lightmaps import gradient_image
        occlusion = TextureData(np.full((4, 4, 4), 200, np.uint8), name="occlusion")
        for x, material in ((-1.0, Material(clearcoat=1.0, clearcoat_roughness=0.1, sheen_color=(0.5, 0.2, 0.2))),
                            (1.0, Material(metallic=1.0, roughness=0.3, anisotropy=0.8)),
                            (0.0, Material(lightmap=gradient_image(), occlusion_map=occlusion)),  # (17 samplers)
                            (2.0, Material(color=(0.9, 0.6, 0.5), subsurface=1.0, subsurface_scale=0.2))):
            world.spawn(Transform(position=(x, 0.5, 0.5)), MeshRef(sphere(0.4)), material)
    return _engine_frames(ctx, MirrorRing(3), 3, configure)


def _irradiance_volume(ctx):
    """The mirror ring in an irradiance volume (its points captured a few a frame, one inside
    a box moved out of it; then the IRRADIANCE_VOLUME builds, in the mirrors' levels too, and
    its second bounce's round: captures lit by the table's copy) with
    a reflection probe's influence box over part of it (AMBIENT_PROBES with it), and a lit
    particle cloud reading both."""
    from benchmarks.mirrors import MirrorRing
    from components import IrradianceVolume, ParticleEmitter, ReflectionProbe, Transform

    def configure(engine):
        world = engine.world
        world.spawn(Transform(position=(0.0, 1.0, 0.0)),
                    IrradianceVolume(size=(8.0, 2.0, 8.0), points=(3, 2, 3), points_per_frame=8, resolution=16,
                                     blend_distance=0.5, bounces=2))
        world.spawn(Transform(position=(2.0, 1.0, 0.0)), ReflectionProbe(resolution=16, influence=(3.0, 3.0, 3.0)))
        world.spawn(Transform(position=(0.0, 0.5, 1.0)), ParticleEmitter(rate=200.0, lit=True))
    return _engine_frames(ctx, MirrorRing(3), 4, configure)


def _cutouts(ctx):
    """The mirror ring with two cutout grates (two cutoffs, one double-sided, one with an
    occlusion map) and a vertex-coloured quad over its boxes, the lamp casting (the layered cube's cutout build) and a
    mirror throwing the sun (the virtual light's caster passes), reflected in the batched
    levels; the camera with ambient occlusion (its depth and normals pass, the find and
    filter passes, the root's SCREEN_OCCLUSION builds: the cutout with an occlusion map
    there is the fullest build of all; and the first level's, drawn view by view: its masked
    depth and normals, the LEVEL_VIEWS find a view and filter, the masked SCREEN_OCCLUSION
    builds; contact shadows towards the sun and the lamp, CONTACT_LAMPS) and screen
    reflections (the root's builds with both,
    the unlit mirrors' reflected builds, the colour copy and composite)."""
    from benchmarks.lighting import _mirror_light
    from benchmarks.mirrors import MirrorRing
    from components import (
        AmbientOcclusion,
        Camera,
        ContactShadows,
        Material,
        MeshRef,
        PointLight,
        Reflective,
        ScreenReflections,
        Transform,
    )
    from engine.assets.mesh import Mesh, plane, quad
    from tests.test_alpha_cutout import SLAT_TEXTURE
    from tests.test_occlusion_maps import OCCLUSION

    def configure(engine):
        _mirror_light(engine)
        world = engine.world
        for _, light in world.query_one(PointLight):
            light.shadows = True
            light.contact_shadows = True   # (the CONTACT_LAMPS builds: the lamps' image, a sampler more)
        colours = quad(1.0, 1.0)   # a mesh with a colour a vertex (the VERTEX_COLOR builds, batched too)
        world.spawn(Transform(position=(0.0, 2.4, 0.0)), MeshRef(Mesh(
            colours.positions, colours.normals, colours.uvs, colours.indices, name="coloured",
            colors=np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 0.0]]))), Material())
        for camera, _ in world.query_one(Camera):
            world.add_component(camera, AmbientOcclusion(radius=0.8))
            world.add_component(camera, ContactShadows())
            world.add_component(camera, ScreenReflections())
        for entity, mesh in world.query_one(MeshRef):
            if mesh.mesh.name == "plane":  # the floor reflects the sky: the reflecting draws and their images
                world.add_component(entity, Reflective(mix=0.35))
        for x, cutoff, occlusion in ((-1.0, 0.5, None), (1.0, 0.3, OCCLUSION)):
            world.spawn(Transform(position=(x, 1.6, 0.0)), MeshRef(plane(1.6, 1.6)),
                        Material(texture=SLAT_TEXTURE, alpha_cutoff=cutoff, occlusion_map=occlusion,
                                 double_sided=occlusion is None))
    return _engine_frames(ctx, MirrorRing(4), 3, configure)


def _fog(path: str):
    """The mirror ring seen through height fog on the camera and a local fog volume (the FOG
    builds of the scene programs, the batched ones' geometry stage too; the sky's and the
    composites' reads of the block), a chrome ball reflecting the sky, screen reflections on the camera (their
    FOG builds) and light shafts (the march's FOG_FALLOFF build with the sun's shadow
    lookups, its filter; at half size on the batched path, a ray a pixel on the other)."""
    def run(ctx):
        from benchmarks.mirrors import MirrorRing
        from components import (
            Camera,
            Fog,
            FogVolume,
            Material,
            MeshRef,
            Reflective,
            ScreenReflections,
            Transform,
            VolumetricFog,
        )
        from engine.assets.mesh import sphere

        def configure(engine):
            engine.reflection_system.path = path
            for entity, _ in engine.world.query_one(Camera):
                engine.world.add_component(entity, Fog(density=0.08, height=1.0, height_falloff=0.3))
                # (batched: the rays marched at half size, their pass and the composite's build)
                engine.world.add_component(entity, ScreenReflections(half_resolution=path == "batched"))
                engine.world.add_component(entity, VolumetricFog(steps=8, half_resolution=path == "batched"))
            engine.world.spawn(Transform(position=(0.0, 0.6, 0.0)), MeshRef(sphere(0.5)),
                               Material(color=(0.9, 0.9, 0.9), metallic=1.0, roughness=0.1), Reflective())
            engine.world.spawn(Transform(position=(1.0, 0.8, 1.0)), FogVolume(size=(3.0, 1.6, 2.0), density=0.8,
                                                                            color=(0.8, 0.6, 0.4)))  # (FOG_VOLUMES)
        return _engine_frames(ctx, MirrorRing(4), 3, configure)
    return run


def _probes(refresh: str, resolution: int = 32):
    def run(ctx):
        from benchmarks.probes import ProbeRing

        return _engine_frames(ctx, ProbeRing(refresh, resolution), 3)
    return run


def _probes_sliced_ggx(ctx):
    """A probe captured a face a frame, GGX-prefiltered, box-projected, an influence box the
    ring's boxes sample it through (eight frames: past a whole slicing round)."""
    from benchmarks.probes import ProbeRing
    from components import ReflectionProbe

    def configure(engine):
        for _, probe in engine.world.query_one(ReflectionProbe):
            probe.time_slicing = "one_face_per_frame"
            probe.prefilter = "ggx"
            probe.influence = (30.0, 10.0, 30.0)
            probe.box_projection = True
    return _engine_frames(ctx, ProbeRing("every_frame", 32), 8, configure)


def _mirror_beam(ctx):
    from games.mirror_beam.game import MirrorBeam, levels

    return _engine_frames(ctx, MirrorBeam(levels()[-1], autopilot=True, verbose=False), 3)


def _portal_run(ctx):
    from games.portal_run.game import PortalRun, levels

    return _engine_frames(ctx, PortalRun(levels()[-1], autopilot=True, verbose=False), 3)


def _moonlit_hall(ctx):
    """The sample level by moonlight under an atmosphere with stars (the MOON_AIR builds: the
    sky-view table twice), with clouds over it (CLOUDS, CLOUD_SHADOWS) and light shafts."""
    from games.hall_of_mirrors import HallOfMirrors

    def configure(engine):
        engine.start_sky("atmosphere", 21.5, 10.0, moon_age=14.77, clouds=0.4)
        engine.start(shafts=True)
    return _engine_frames(ctx, HallOfMirrors(), 2, configure)


def _resized(ctx):
    """The mirror ring resized twice, its floor polished and screen reflections at half size on
    the camera (their images made again with the level's, an odd size's half-size rays)."""
    from benchmarks.lighting import _reflections
    from benchmarks.mirrors import MirrorRing

    return _engine_frames(ctx, MirrorRing(4), 2, lambda engine: _reflections(engine, half=True),
                          sizes=((160, 90), (95, 121), (160, 90)))


def _glass_screen(ctx):
    """The mirror ring with glass balls and a frosted pane refracting what each view drew
    behind them (screen-space refraction: the copy, its mips, the march, in the camera's
    view and its mirror levels)."""
    from benchmarks.lighting import _glass_screen
    from benchmarks.mirrors import MirrorRing
    from components import Material, Refractive

    def configure(engine):
        _glass_screen(engine)
        for entity, refractive in engine.world.query_one(Refractive):
            if not refractive.solid:  # (the pane)
                engine.world.get(entity, Material).roughness = 0.3
    return _engine_frames(ctx, MirrorRing(4), 3, configure)


def _pond_faded(ctx):
    """The sample level with its pond partly faded (the water's fallback bending what is below
    from a copy of its level, its view's composite blended over it)."""
    from games.hall_of_mirrors import HallOfMirrors

    def configure(engine):
        from components import Mirror, Water

        for entity, _ in engine.world.query_one(Water):
            engine.world.get(entity, Mirror).fade_distance = (0.0, 40.0)
    return _engine_frames(ctx, HallOfMirrors(), 2, configure)


def _see_through_lamps(ctx):
    """The mirror ring's lamp casting (a cube), a spot casting from its map beside it, the sun,
    a see-through pane and a glass one over the boxes (each light's see-through map: the
    suns' atlas, the lamps' six face tiles and a spot's one, read by the scene pass), the
    mirrors throwing the lights (the virtual lights' see-through tiles), light shafts from
    both lamps (the march reads the lamps' maps) and lit particles (their lighting too), the
    boxes spinning."""
    from benchmarks.mirrors import MirrorRing
    from components import (
        Camera,
        Fog,
        Material,
        MeshRef,
        Mirror,
        ParticleEmitter,
        PointLight,
        Refractive,
        Transform,
        VolumetricFog,
        look_rotation,
    )
    from engine.assets.mesh import quad

    def configure(engine):
        world = engine.world
        for _, light in world.query_one(PointLight):
            light.shadows, light.volumetric = True, 1.0
        for _, mirror in world.query_one(Mirror):
            mirror.reflects_light = True
        world.spawn(Transform(position=(2.5, 3.5, 1.0), rotation=look_rotation((-0.3, -1.0, 0.0), (0.0, 0.0, -1.0))),
                    PointLight(intensity=6.0, range=12.0, spot_angle=30.0, shadows=True, volumetric=1.0))
        flat = look_rotation((0.0, -1.0, 0.0), (0.0, 0.0, -1.0))
        world.spawn(Transform(position=(0.8, 2.2, 0.3), rotation=flat), MeshRef(quad(1.5, 1.5)),
                    Material(color=(0.3, 0.5, 0.9, 0.5), double_sided=True))
        world.spawn(Transform(position=(-0.8, 2.0, -0.3), rotation=flat), MeshRef(quad(1.2, 1.2)),
                    Material(color=(0.9, 0.9, 0.9, 0.3), double_sided=True), Refractive(screen=False))
        world.spawn(Transform(position=(0.0, 0.5, 1.0)), ParticleEmitter(rate=200.0, lit=True))
        for camera, _ in world.query_one(Camera):
            world.add_component(camera, Fog(density=0.06))
            world.add_component(camera, VolumetricFog())
    return _engine_frames(ctx, MirrorRing(3), 3, configure)


SCENES: dict[str, Callable[[moderngl.Context], list[np.ndarray]]] = {
    **{name: _golden(name) for name in ("hall_start", "hall_mirror_wall", "hall_doorway", "hall_partner_side",
                                        "mirror_ring_8_batched", "portals_depth_8", "portals_partner_disabled",
                                        "readme_bricks")},
    "shadows_moving": _lighting("shadows_moving"),
    "mirror_light_moving": _lighting("mirror_light_moving"),
    "post_auto_gpu_passes": _lighting("post_auto", gpu=True),
    "post": _lighting("post"),
    "flared": _lighting("flared"),
    "graded": _lighting("graded"),
    "atmosphere_setting": _lighting("atmosphere_setting"),
    "point_shadows": _point_shadows,
    "soft_sun": _soft_sun,
    "spot_shadows": _spot_shadows,
    "rect_lights": _rect_lights,
    "irradiance_volume": _irradiance_volume,
    "cutouts_occlusion": _cutouts,
    "fog_per_mirror": _fog("per_mirror"),
    "fog_batched": _fog("batched"),
    "probes_dynamic": _probes("every_frame"),
    "probes_once": _probes("once"),
    "probes_sliced_ggx": _probes_sliced_ggx,
    "mirror_beam": _mirror_beam,
    "portal_run": _portal_run,
    "resized": _resized,
    "clouds": _lighting("clouds"),
    "shafts_clouds": _lighting("shafts_clouds"),
    "moonlit_hall": _moonlit_hall,
    "glass_screen": _glass_screen,
    "pond_faded": _pond_faded,
    "see_through_lamps": _see_through_lamps,
}


@pytest.mark.parametrize("name", SCENES)
def test_every_draw_is_legal_gl_41(ctx, name):
    with strict_draws(ctx) as strict:
        SCENES[name](ctx)
    assert strict.draws > 0
    # A sampler finding no texture at all reads (0, 0, 0, 1), defined, yet no pass means it:
    # a texture never given, or released while the record held it.
    found = {**strict.problems, **strict.unbound}
    assert not found, f"{name}: " + "\n".join(f"{where}: {problem}" for problem, where in found.items())


def test_uniform_blocks_are_the_size_the_engine_writes(ctx):
    """Every uniform block the scenes draw with has, in the GLSL (std140, as the driver lays it
    out), the size of the bytes the engine packs for it: a block the blocks of tests/
    test_rendering.py and test_ambient_light.py do not cover (Views, Shadows, VirtualLights, Fog,
    FallbackRows, Caustics and Foam: the sample level's pond) included."""
    from engine.render.batched_mirrors import VIEWS_BLOCK_BYTES
    from engine.render.caustics import CAUSTICS_BLOCK_BYTES
    from engine.render.foam import FOAM_BLOCK_BYTES
    from engine.render.fog import FOG_BLOCK_BYTES
    from engine.render.irradiance import IRRADIANCE_BLOCK_BYTES
    from engine.render.mirror_passes import _FALLBACK_IDS_BYTES, _FALLBACK_WEIGHTS, FALLBACK_ROWS
    from engine.render.shadows import SHADOWS_BLOCK_BYTES, VIRTUAL_BLOCK_BYTES
    from engine.render.views import CAMERA_BLOCK_BYTES, LIGHTS_BLOCK_BYTES

    packed = {"Camera": CAMERA_BLOCK_BYTES, "Lights": LIGHTS_BLOCK_BYTES, "Irradiance": IRRADIANCE_BLOCK_BYTES,
              "Views": VIEWS_BLOCK_BYTES, "Shadows": SHADOWS_BLOCK_BYTES, "VirtualLights": VIRTUAL_BLOCK_BYTES,
              "Fog": FOG_BLOCK_BYTES, "Caustics": CAUSTICS_BLOCK_BYTES, "Foam": FOAM_BLOCK_BYTES,
              "FallbackRows": _FALLBACK_IDS_BYTES + FALLBACK_ROWS * _FALLBACK_WEIGHTS.size}
    with strict_draws(ctx) as strict:
        for name in ("hall_start", "mirror_ring_8_batched", "mirror_light_moving", "fog_batched"):
            SCENES[name](ctx)
    assert set(strict.block_sizes) == set(packed), "a uniform block with no packed size here, or one not drawn"
    for name, sizes in strict.block_sizes.items():
        assert sizes == {packed[name]}, f"uniform block {name}: the GLSL lays out {sizes} bytes, the engine packs " \
                                        f"{packed[name]}"


_CHECK_VS = ("#version 410 core\nvoid main() { "
             "gl_Position = vec4(vec2(gl_VertexID & 1, gl_VertexID >> 1) * 4.0 - 1.0, 0.0, 1.0); }\n")
_CHECK_FS = {"float": "uniform sampler2D image;", "uint": "uniform usampler2D image;"}


@pytest.mark.draws_illegal
@pytest.mark.parametrize("case", ["legal", "no_mips", "linear_ids", "float_on_ids", "feedback", "unwritten_ids"])
def test_the_check_names_each_kind_of_illegal_draw(ctx, case):
    """The checker itself, on hand-made draws: a legal one passes, each broken one is named."""
    kind = "uint" if case in ("linear_ids", "legal") else "float"
    fragment = (f"#version 410 core\n{_CHECK_FS[kind]}\nout vec4 colour;\n"
                "void main() { colour = vec4(texture(image, vec2(0.5))); }\n")
    program = ctx.program(vertex_shader=_CHECK_VS, fragment_shader=fragment)
    vao = ctx.vertex_array(program, [])
    target = CaptureTarget(ctx, (4, 4))
    objects = [vao, program, target]
    try:
        if case in ("legal", "linear_ids", "float_on_ids"):
            texture = ctx.texture((8, 8), 1, bytes(4 * 64), dtype="u4")
            texture.filter = (moderngl.LINEAR, moderngl.LINEAR) if case == "linear_ids" else \
                (moderngl.NEAREST, moderngl.NEAREST)
        else:
            texture = ctx.texture((8, 8), 4, bytes(4 * 64))
            texture.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)  # no mip levels made
        objects.append(texture)
        framebuffer = target.framebuffer
        if case == "feedback":
            texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
            framebuffer = ctx.framebuffer([texture])
            objects.insert(0, framebuffer)
        if case == "unwritten_ids":  # a second, integer, attachment no output writes
            texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
            ids = ctx.texture((4, 4), 1, dtype="u4")
            framebuffer = ctx.framebuffer([target.texture, ids])
            objects[:0] = [framebuffer, ids]
        texture.use(3)
        program["image"].value = 3
        with strict_draws(ctx) as strict:
            framebuffer.use()
            vao.render(moderngl.TRIANGLES, vertices=3)
        text = " ".join(strict.problems)
        expected = {"legal": None, "no_mips": "reaches level 1", "linear_ids": "integer format filtered",
                    "float_on_ids": "a float sampler on a uint format", "feedback": "rendering feedback loop",
                    "unwritten_ids": "draw buffer 1 (uint attachment, write mask on) has no fragment output"}[case]
        if expected is None:
            assert not strict.problems, text
        else:
            assert expected in text, text
    finally:
        for obj in objects:
            if isinstance(obj, moderngl.Framebuffer):
                release_framebuffer(obj)  # (the bound one: framebuffer 0 bound first)
            else:
                obj.release()
        bindings.invalidate(ctx)
    assert ctx.error == "GL_NO_ERROR"


# --- texels never written ---------------------------------------------------------------------
# NaN everywhere a float image is made; finite noise on a few scenes too (a NaN a shader
# clamps or compares away would hide a read that finite noise shows).
_NOISE = [(name, True) for name in SCENES] + [(name, False) for name in ("hall_start", "portals_depth_8",
                                                                          "post_auto_gpu_passes", "probes_dynamic")]


@pytest.mark.parametrize("name,nan", _NOISE, ids=[f"{name}-{'nan' if nan else 'noise'}" for name, nan in _NOISE])
def test_no_texel_is_read_before_it_is_written(ctx, name, nan):
    plain = SCENES[name](ctx)
    with noisy_textures(nan=nan) as filled:
        noisy = SCENES[name](ctx)
    assert filled, "no texture was made without data: the hook saw nothing"
    assert plain[0].max() > 0, f"{name}: the frame is black"
    for index, (a, b) in enumerate(zip(plain, noisy, strict=True)):
        kind = "ids" if index % 2 else "colour"
        differ = a != b if a.ndim == 2 else (a != b).any(axis=-1)
        assert not differ.any(), (f"{name}: {kind} of frame {index // 2} differs at {int(differ.sum())} pixels "
                                  f"with new textures made full of noise (first at row, column "
                                  f"{tuple(int(v) for v in np.argwhere(differ)[0])}): a texel read before it is "
                                  "written")


def test_a_batch_without_a_probe_finds_a_cube_on_the_probes_unit_after_an_engine_with_one(scene, ctx):
    """An engine whose chrome ball read its reflection probe from unit 7 is closed (its cube
    released there); the next engine's glass pane, with no probe and a uniform build that
    declares the probe's sampler, finds the sky bound there, not an empty unit.  (Found by
    the see-through lamps scene after probes_dynamic: its pane was the frame's first draw
    reading unit 7.)"""
    from components import Material, MeshRef, ReflectionProbe, Reflective, Refractive, Transform
    from engine.assets.mesh import plane, quad, sphere
    from tests.support import look_from

    def probed(world):
        look_from(world, (0.0, 2.0, 5.0), (0.0, 0.5, 0.0))
        world.spawn(Transform(), MeshRef(plane(8, 8)), Material())
        world.spawn(Transform(position=(0.0, 1.0, 0.0)), MeshRef(sphere(0.5)), Material(metallic=1.0),
                    Reflective(), ReflectionProbe(resolution=16))

    def pane(world):
        look_from(world, (0.0, 2.0, 5.0), (0.0, 0.5, 0.0))
        world.spawn(Transform(position=(0.0, 1.0, 0.0)), MeshRef(quad(2.0, 2.0)),
                    Material(color=(0.8, 0.9, 1.0, 0.2)), Refractive(screen=False))

    first = scene(probed, (64, 48))
    first.frame()
    first.close()
    with strict_draws(ctx) as strict:
        scene(pane, (64, 48)).frame()
    found = {**strict.problems, **strict.unbound}
    assert strict.draws > 0 and not found, "\n".join(f"{where}: {problem}" for problem, where in found.items())


def test_the_debug_overlay_draws_legal_gl_after_a_frame(scene, ctx):
    """The overlay draws after the engine's frame, which leaves the reflections' mipmapped
    albedo sampler object on unit 0: the overlay's font atlas (no mip levels) must not be
    filtered by it (incomplete: no text on a GPU).  Broken on purpose: binding the atlas with
    ``texture.use(0)`` (the sampler stays) is named here."""
    pytest.importorskip("imgui_bundle", reason="the debug overlay needs imgui-bundle (not installed here)")
    from shell.overlay import DebugOverlay
    from tests.test_overlay import SIZE as OVERLAY_SIZE
    from tests.test_overlay import room_with_probe

    runner = scene(room_with_probe, OVERLAY_SIZE)
    runner.frame()
    runner.frame()
    overlay = DebugOverlay(ctx)
    try:
        with strict_draws(ctx) as strict:
            overlay.record(0.02)
            overlay.draw(runner.engine, runner.capture.framebuffer, OVERLAY_SIZE)
    finally:
        overlay.release()
    assert strict.draws > 0
    assert not strict.problems, "\n".join(f"{where}: {problem}" for problem, where in strict.problems.items())


def test_a_level_is_made_and_cleared_with_each_image_at_its_clear_value(ctx):
    """A level's images made full of noise (as a GPU may hand them back) are colour 0, ids 0
    and depth far once made (``RenderTargets`` clears them), and again after ``clear_images``
    (glClearBufferuiv for the id images, glClearBufferfv for colour and depth) over noise
    written into every image; the framebuffer bound before stays bound.  Broken on purpose:
    ``clear_images`` skipping the id images fails here (glClearBufferfv on them instead
    would not: llvmpipe converts, as GL leaves it undefined)."""
    from engine.render.raw_gl import clear_images
    from engine.render.targets import RenderTargets

    size = (24, 10)
    rng = np.random.default_rng(3)
    other = CaptureTarget(ctx, (4, 4))
    other.framebuffer.use()
    with noisy_textures(nan=True):
        targets = RenderTargets(ctx, size)
    try:
        assert ctx.fbo is other.framebuffer

        def read_all() -> list[np.ndarray]:
            ids = [np.frombuffer(t.read(), np.uint32) for t in (targets.surface, targets.seen, targets.node)]
            return [np.frombuffer(targets.color.read(), np.float16), *ids,
                    np.frombuffer(targets.depth.read(), np.float32)]

        def check() -> None:
            colour, surface, seen, node, depth = read_all()
            assert (colour == 0).all(), "colour not 0"
            for name, ids in (("surface", surface), ("seen", seen), ("node", node)):
                assert (ids == 0).all(), f"{name} ids not 0"
            assert (depth == 1.0).all(), "depth not far"

        check()
        for texture in (targets.surface, targets.seen, targets.node):
            texture.write(rng.integers(1, 2**32, size[0] * size[1] * texture.components, dtype=np.uint32).tobytes())
        targets.color.write(rng.uniform(1.0, 5.0, size[0] * size[1] * 4).astype(np.float16).tobytes())
        targets.depth.write(np.full(size[0] * size[1], 0.25, np.float32).tobytes())
        targets.framebuffer.use()
        clear_images(ctx, targets.framebuffer)
        check()
    finally:
        targets.release()
        other.release()
        bindings.invalidate(ctx)


@pytest.mark.parametrize("name", ["glClearBufferuiv", "glClearBufferfv", "glFlush"])
def test_a_loader_without_an_entry_point_every_frame_needs_is_refused_at_start(ctx, name, monkeypatch):
    """The raw GL calls every frame makes (a level's clears, the flush) are looked up when
    the engine's GL state is made, and a loader that lacks one is refused there, naming it:
    before, a missing glClearBuffer* fell back to glClear, which leaves the id images
    undefined (GL 4.1), and a missing glFlush did nothing, both silently."""
    from engine.render import raw_gl

    real = raw_gl._load
    monkeypatch.setattr(raw_gl, "_load", lambda c, n, p: None if n == name else real(c, n, p))
    with pytest.raises(raw_gl.MissingEntryPoints, match=name):
        raw_gl.RawGL(ctx)
    monkeypatch.undo()
    raw_gl.RawGL(ctx).flush()  # the real loader gives all three
