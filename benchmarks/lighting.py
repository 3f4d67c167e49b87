"""Lighting benchmark: what the light a game ships with costs, on the mirrors
benchmark's scene (``benchmarks/mirrors.py``: the ring of mirrors, boxes, a sun and a lamp,
the orbiting camera).

Each **variant** is a function that configures a freshly made engine of that scene (the
camera's components, lights' settings, a moving object...); every (mirror count, variant)
engine runs its frames interleaved with all the others in one process (frame i of each, in
an order shuffled each round, then frame i + 1), so the drift of a shared machine lands on
every variant alike and the ratios hold.  Frame time is wall clock around ``Engine.frame`` plus ``ctx.finish()``.
Each row gives the median and its ratio to the ``off`` variant of the same mirror count;
``process_ms_median`` and ``process_ratio_to_off`` are the same for the process's CPU time
over the frame (every thread's: on llvmpipe its rasteriser's too, so the frame's whole
work), which other processes on a shared machine do not lengthen: the steadier ratio there.

Variants now (``VARIANTS``; add a row by appending a ``Variant``):

* ``off``: the scene lit as before shadows and post-processing (the sun's shadows off, no
  Tonemap, no Bloom); in every variant the scene's spinning boxes stand still (only the
  camera moves), so what a variant moves is all that moves;
* ``shadows``: the sun casts shadows; nothing but the camera moves, so its map is drawn
  once and kept (the still scene);
* ``subsurface``: shadows, and every box's material scatters light under its surface
  (``Material.subsurface``): its cost against ``shadows``' (boxes are flat, so they look
  the same: the build's lookups and shadow tests are what is measured);
* ``glass``: no shadows; three solid glass balls and a pane (``Refractive(screen=False)``)
  refracting the sky; ``glass_screen``: the same refracting what each view drew behind
  them (screen-space refraction: a copy and a march in every view that sees them): its
  cost against ``glass``';
* ``clouds``: shadows, and a CloudLayer over the sky, half cover, drifting at 30 m/s:
  the sky pass's clouds, the scene's cloud shadows and the cube map made again as they
  drift: its cost against ``shadows``';
* ``shafts_clouds``: the ``shafts`` variant (below) under the same drifting CloudLayer (its
  shadow read at every step of the march): its cost against ``shafts``';
* ``shadows_moving``: the same with a box sliding to and fro under the sun every frame
  (its map drawn again each frame);
* ``mirror_light``: shadows, and the mirror of the ring the sun reaches most throws its
  light (``Mirror.reflects_light``: one virtual light with its own shadow map); still;
* ``mirror_light_moving``: the same with the sliding box (at most two maps a frame: the
  sun's and the virtual light's);
* ``cascades``: shadows, the sun with three cascades (``DirectionalLight.shadow_cascades``:
  rings of 12 and 3 metres about the camera); the orbiting camera leaves the inner ring's
  cell every few frames, which draws that ring again;
* ``cascades_moving``: the same with the sliding box (its footprint redrawn in each map it is in);
* ``grid_sun``: shadows, still, read by the "grid" filter (2 x 2 taps);
* ``soft_sun``: the same with the sun 2 degrees across (``DirectionalLight.angular_diameter``:
  percentage-closer soft shadows, 12 blocker taps and 16 over the penumbra): its cost against
  ``grid_sun``'s;
* ``spot_shadows``: no sun shadows; the ring's lamp a 30-degree spot aimed down, casting
  from one perspective map fitted to its cone; still (the map kept);
* ``spot_moving``: the same with the sliding box (the map drawn again each frame);
* ``sphere_lamp``: no shadows; the ring's lamp a sphere of 0.2 m (``PointLight.radius``);
* ``rect_lamp``: no shadows; the ring's lamp a 1 x 0.5 m panel facing down
  (``PointLight.rectangle``): its cost is its ratio to ``off`` against ``sphere_lamp``'s;
* ``picture_lamp``: ``rect_lamp`` with a picture on its face (``PointLight.cookie`` on a
  rectangle: each integral times the picture's colour its lobe sees, a mip lookup each);
* ``tube_lamp``: no shadows; the ring's lamp a 1.2 m tube of 2 cm radius (``PointLight.length``:
  lit as a rectangle turned to face each point);
* ``lamps_8``: no shadows; eight more lamps in a ring over the floor;
* ``lamps_8_rect``: the same with the first of them a panel (its cost against ``lamps_8``: the
  rectangle's integrals paid by it alone);
* ``lamp_shadows``: no sun shadows; the ring's lamp casts from its cube, the "grid" filter;
* ``soft_lamp``: the same with the lamp a sphere of 0.2 m: its shadows soft (percentage-closer
  soft shadows): its cost is its ratio to ``off`` against ``lamp_shadows``';
* ``volume``: no shadows; an ``IrradianceVolume`` of 6 x 2 x 6 points over the ring, baked in
  the first frame (its lookups, 18 filtered reads a pixel, are the cost measured);
* ``fog``: no shadows; height fog with sun scatter on the camera (``Fog``: every view, the
  sky and the composites fogged);
* ``fog_uniform``: the same with fog the same everywhere and no glow (the cheapest fog build);
* ``fog_volumes``: no shadows, no camera fog; four ``FogVolume``s over the ring (each pixel of
  every view integrates each one along its way);
* ``post``: no shadows, the camera gets ``Tonemap(curve="agx")`` and ``Bloom()`` (six levels on a
  GPU; a software rasteriser's quarter-size start makes five, ending at the same smallest level:
  ``engine/render/bloom.py``);
* ``flared``: ``post`` with a ``LensFlare`` beside the bloom (four ghosts and a halo read by the
  present draw) and lens dirt (``Bloom.dirt``);
* ``post_auto``: ``post`` with ``Tonemap(auto_exposure=True)``;
* ``graded``: no shadows; ``Tonemap(curve="agx")``, a ``ColorGrading`` with every control
  moved and a 33-point colour table, and a ``Vignette`` (the present draw's GRADE, LUT and
  VIGNETTE build);
* ``occlusion``: no shadows; ``AmbientOcclusion()`` on the camera (its depth and normals
  pass, the occlusion found at half size, the filter to every pixel);
* ``occlusion_camera``: the same for the camera's own view alone (``reflection_depth=0``: the
  mirrors' views unoccluded, as ``occlusion`` does for the first level's);
* ``occlusion_full``: the same found at full size (``half_resolution=False``);
* ``occlusion_low``: the same at half size with ``quality="low"`` (half the find pass's samples);
* ``contact``: no shadows; ``ContactShadows()`` on the camera (the depth and normals pass and
  the march at full size, the filter);
* ``contact_lamp``: the same with the scene's lamp's contact shadows too
  (``PointLight.contact_shadows``: a second march a pixel, a second image);
* ``contact_half``: the same found at half size (``half_resolution=True``);
* ``contact_occlusion``: the same with ``AmbientOcclusion()`` (one depth pass for both, at half size);
* ``polished``: no shadows; the checker floor reflects the sky (``Reflective(mix=0.35)``);
* ``reflections``: the same with ``ScreenReflections()`` on the camera (the root's draw
  writes their images, the colour is copied with its mips and the composite marches the
  floor's rays): its cost is its ratio to ``polished``;
* ``reflections_camera``: the same for the camera's own view alone (``reflection_depth=0``: the
  mirrors' views keep the sky's reflections, as ``reflections`` does not for the first level's);
* ``reflections_low``: the same with ``quality="low"`` (16 steps a ray, not 32);
* ``reflections_half``: the same with ``half_resolution=True`` (a ray a 2 x 2 block).

**Targets** (``TARGETS``), each a ratio of two variants' medians at a mirror count against
its limit, printed as value, limit, met, and judged on the kind of machine it is set for
(``applies``), as the cpu suite (``benchmarks/cpu.py``) judges its own:

* ``post_0_mirrors``: ``post`` / ``off`` with no mirror at 640x360 (bloom and tone mapping
  together add at most 10%), and ``shadows_still``: ``shadows`` / ``off`` (a still scene
  with shadows costs at most 1.05x: its maps are kept), both set for a GPU: measured here
  (the ``frames`` part) at ``--size``; on a software rasteriser (llvmpipe) every post pass
  and shadow lookup is pixel work of its CPU, so they are reported there, not judged;
* ``cpu_post_0_mirrors`` and ``cpu_shadows_still``: the same two ratios and limits, set for
  this machine (a software rasteriser) and measured the way the cpu suite measures a GPU
  host's frame (the ``cpu`` part): in a process of its own started with ``LP_NUM_THREADS=0``
  (no rasteriser threads) at a tiny output (``STAND_IN_SIZE``, 4x2), where next to nothing is
  rasterised, so the frame is the CPU's work.  A tiny frame alone would not issue the 640x360
  frame's passes: a GPU's bloom chain starts at half the image and has six levels at 640x360
  (eleven draws), where a 4x2 image has none.  So each of its engines is set to draw what a
  GPU draws at 640x360 (``gpu_passes``): the bloom chain of a 640x360 image, from a half-size
  start (``BloomPass.chain_of``: six levels, eleven draws, each level at most a few texels),
  the GPU's shadow filter ("grid") and FXAA walk (8 steps), and shadow maps as small as the
  cpu suite makes them (a still scene draws none a frame; the lookups are the same).  The
  process then draws one frame of each variant at 640x360 itself with the same settings (the
  chain of its own size) and checks that the tiny frame made the same passes, draws and GL
  calls (``GLCallCounter``) as it did, and the post variant's chain a GPU's eleven draws: a
  run where they differ fails.  What it measures is then the CPU a frame of those passes
  costs (Python, numpy, the driver's calls), plus what llvmpipe spends on each pass and draw
  of a few texels (a GPU driver queues them: about 2.5 us a bloom step here, its framebuffer,
  source and draw).  Why 4x2 and not the cpu suite's 32x18: at 32x18 the frame still
  rasterises a third of itself (the 0-mirror frame, LP_NUM_THREADS=0: 0.146 ms at 1x1, 0.148
  at 4x2, 0.175 at 16x9, 0.204 at 32x18), and the shadow lookups and bloom taps are pixel
  work (the still shadows' cost: 6 us at 4x2, 21 at 16x9 with the grid filter); the camera's
  aspect (2:1) draws the same batches as 16:9 here, which the check above confirms.  Each
  engine draws ``STAND_IN_BLOCK`` frames in a row, the first untimed: engines share the
  context, and a frame after another engine's binds again what that one displaced;
  the process also times ``pass_floor_ms``: as many bare passes as the GPU's chain has (a
  framebuffer switch and a 3-vertex draw each, nothing bound), the least such a chain can
  cost llvmpipe, which flushes and draws on the calling thread at every switch where a GPU
  driver queues.  The post target prints it as ``least_possible``: (off + floor) / off.
  Measured at 4x2: the floor is about 21 us, 1.16x the 0.13 ms ``off`` frame, so no chain of
  eleven dependent passes meets the 1.10 limit on this stand-in; the post variant adds about
  twice the floor (its texture binds, and Python);
* ``shadow_maps_moving`` (a count, judged everywhere): the shadow maps a frame of
  ``shadows_moving`` draws, at most 1 whatever the number of mirrors; ``shadows`` draws 0;
  ``mirror_light`` 0 and ``mirror_light_moving`` at most 2 (one more for the virtual light).

Parts (``--parts``): ``frames`` (the variants at ``--size`` and ``--mirrors`` in this
process) and ``cpu`` (the stand-in process: ``off``, ``shadows`` and ``post`` with no
mirror, ``--cpu-frames`` frames each).  Exit status 1 when a target that applies here is not
met (``--report-only``: 0 whatever the values).

::

    python -m benchmarks lighting                     # both parts: 0 mirrors at 640x360, the 4x2 stand-in
    python -m benchmarks lighting --mirrors 0,8 --frames 60 --parts frames
    python -m benchmarks lighting --parts cpu         # the GPU host's CPU, judged here
    python -m benchmarks lighting --json --report-only
"""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import random
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from pyglm import glm

from benchmarks import (
    add_size_argument,
    format_size,
    names_from,
    non_negative_int,
    positive_int,
    rows_without_rasteriser,
)
from benchmarks.mirrors import DT, OUTPUT_SIZE, MirrorRing
from components import (
    AmbientOcclusion,
    Bloom,
    Camera,
    CloudLayer,
    ColorGrading,
    ContactShadows,
    DirectionalLight,
    Fog,
    FogVolume,
    IrradianceVolume,
    LensFlare,
    Material,
    MeshRef,
    Mirror,
    PointLight,
    Reflective,
    Refractive,
    ScreenReflections,
    Skybox,
    Tonemap,
    Transform,
    Vignette,
    VolumetricFog,
    look_rotation,
)
from engine.assets.color_lut import ColorLut, identity_lut
from engine.assets.mesh import box, sphere
from engine.assets.texture_data import TextureData, puff_texture
from engine.core.frame_io import Output
from engine.render.bloom import level_sizes
from engine.render.gl_context import GLCapabilities, create_headless_context
from engine.render.present import GPU_SEARCH_STEPS
from engine.render.targets import CaptureTarget
from shell.app import Engine

ROOT = Path(__file__).resolve().parents[1]
PARTS = ("frames", "cpu")
STAND_IN_SIZE = (4, 2)          # the cpu part's output: next to no pixels
STAND_IN_FOR = (640, 360)       # the frame whose passes it issues
STAND_IN_VARIANTS = ("off", "shadows", "post")
STAND_IN_BLOCK = 8              # frames an engine draws in a row there (the first untimed: run_variants)


@dataclass(frozen=True)
class Variant:
    """A named way to set up the scene: ``configure(engine)`` runs once, after the engine is
    made and before its first frame."""

    name: str
    configure: Callable[[Engine], None]
    about: str = ""
    step: Callable[[Engine, int], None] | None = None   # before each frame i (a moving caster)


def camera_entity(engine: Engine) -> int:
    (entity, _), = engine.world.query_one(Camera)
    return entity


def _sun_shadows(engine: Engine, on: bool) -> None:
    """The sun's shadows on or off, and the scene's spinning boxes stopped: every variant is a
    still scene but for what it moves itself."""
    for _, light in engine.world.query_one(DirectionalLight):
        light.shadows = on
    engine.game.spinning.clear()


def _plain(engine: Engine) -> None:
    _sun_shadows(engine, False)


def _shadows(engine: Engine) -> None:
    _sun_shadows(engine, True)


def _moving_caster(engine: Engine) -> None:
    _sun_shadows(engine, True)
    engine.world.resources["lighting caster"] = engine.world.spawn(
        Transform(position=(0.0, 0.6, 2.0)), MeshRef(box((0.8, 0.8, 0.8))), Material(color=(0.7, 0.7, 0.7)))


def _slide_caster(engine: Engine, frame: int) -> None:
    transform = engine.world.get(engine.world.resources["lighting caster"], Transform)
    transform.position = glm.vec3(math.sin(frame * 0.1) * 1.5, 0.6, 2.0)


def _mirror_light(engine: Engine) -> None:
    """The sun's shadows on, and the ring's mirror the sun reaches most throws its light."""
    _sun_shadows(engine, True)
    (_, sun), = engine.world.query_one(DirectionalLight)
    facing = [(glm.dot(-sun.direction, glm.vec3(glm.mat3(engine.world.get(entity, Transform).world)
                                                  * glm.vec3(0.0, 0.0, 1.0))), entity)
              for entity, _ in engine.world.query_one(Mirror)]
    if facing:
        engine.world.get(max(facing)[1], Mirror).reflects_light = True


def _mirror_light_moving(engine: Engine) -> None:
    _mirror_light(engine)
    _moving_caster(engine)


def _cascades(engine: Engine) -> None:
    _sun_shadows(engine, True)
    for _, light in engine.world.query_one(DirectionalLight):
        light.shadow_cascades, light.shadow_distance = 3, 12.0


def _grid_sun(engine: Engine) -> None:
    """Shadows, still, read by the "grid" filter (the soft sun's baseline)."""
    _sun_shadows(engine, True)
    engine.renderer.shadows.filter = "grid"


def _soft_sun(engine: Engine) -> None:
    """The same with the sun 2 degrees across (DirectionalLight.angular_diameter: the
    SOFT_SUN_SHADOWS builds, the map read as it is too)."""
    _grid_sun(engine)
    for _, light in engine.world.query_one(DirectionalLight):
        light.angular_diameter = 2.0


def _cascades_moving(engine: Engine) -> None:
    _cascades(engine)
    _moving_caster(engine)


def _spot(engine: Engine) -> None:
    """No sun shadows; the ring's lamp made a 30-degree spot aimed down that casts (one
    perspective map fitted to its cone: ``light_rules.SPOT_MAP_MAX_ANGLE``)."""
    _sun_shadows(engine, False)
    for entity, light in engine.world.query_one(PointLight):
        light.shadows, light.spot_angle = True, 30.0
        engine.world.get(entity, Transform).rotation = look_rotation((0.0, -1.0, 0.0), (0.0, 0.0, -1.0))


def _spot_moving(engine: Engine) -> None:
    _spot(engine)
    _moving_caster(engine)


def _sphere_lamp(engine: Engine) -> None:
    """No shadows; the ring's lamp a sphere of 0.2 m (PointLight.radius: the SPHERE_LIGHTS builds)."""
    _sun_shadows(engine, False)
    for _, light in engine.world.query_one(PointLight):
        light.radius = 0.2


def _lamps_8(engine: Engine, rect: bool = False) -> None:
    """No shadows; eight more lamps in a ring over the floor (``rect``: the first a panel:
    its integrals paid once, in the scene shader's loop over rectangles, not by every lamp)."""
    _sun_shadows(engine, False)
    down = look_rotation((0.0, -1.0, 0.0), (0.0, 0.0, -1.0))
    for k in range(8):
        a = k * math.tau / 8
        panel = (0.8, 0.4) if rect and k == 0 else (0.0, 0.0)
        engine.world.spawn(Transform(position=(3.0 * math.cos(a), 2.5, 3.0 * math.sin(a)), rotation=down),
                           PointLight(intensity=2.0, range=8.0, rectangle=panel))


def _lamps_8_rect(engine: Engine) -> None:
    _lamps_8(engine, rect=True)


def _lamp_shadows(engine: Engine) -> None:
    """No sun shadows; the ring's lamp casts from its cube, read by the "grid" filter (four taps)."""
    _sun_shadows(engine, False)
    engine.renderer.shadows.filter = "grid"
    for _, light in engine.world.query_one(PointLight):
        light.shadows = True


def _soft_lamp(engine: Engine) -> None:
    """The same with the lamp a sphere of 0.2 m: its cube read by percentage-closer soft
    shadows (SOFT_POINT_SHADOWS: 12 blocker taps and 16 over the penumbra)."""
    _lamp_shadows(engine)
    for _, light in engine.world.query_one(PointLight):
        light.radius = 0.2


def _rect_lamp(engine: Engine) -> None:
    """No shadows; the ring's lamp a 1 x 0.5 m panel facing down (PointLight.rectangle: the
    RECT_LIGHTS builds, a clipped form factor and an LTC highlight a pixel)."""
    _sun_shadows(engine, False)
    for entity, light in engine.world.query_one(PointLight):
        light.rectangle = (1.0, 0.5)
        engine.world.get(entity, Transform).rotation = look_rotation((0.0, -1.0, 0.0), (0.0, 0.0, -1.0))


def _picture_lamp(engine: Engine) -> None:
    """``_rect_lamp`` with eight colour bars on the panel's face (PointLight.cookie on a
    rectangle: the PANEL_PICTURES builds, two lookups of the picture a pixel)."""
    _rect_lamp(engine)
    pixels = np.zeros((8, 64, 4), np.uint8)
    pixels[..., 3] = 255
    for bar in range(8):
        pixels[:, bar * 8:(bar + 1) * 8, :3] = (255 * (bar & 1), 255 * (bar >> 1 & 1), 255 * (bar >> 2 & 1))
    for _, light in engine.world.query_one(PointLight):
        light.cookie = TextureData(pixels, name="bars")


def _volume(engine: Engine) -> None:
    """No shadows; an irradiance volume of 6 x 2 x 6 points over the ring, baked whole in the
    first frame: the frames measured read it (the IRRADIANCE_VOLUME builds)."""
    _sun_shadows(engine, False)
    engine.world.spawn(Transform(position=(0.0, 1.5, 0.0)),
                       IrradianceVolume(size=(12.0, 3.0, 12.0), points=(6, 2, 6), points_per_frame=72))


def _tube_lamp(engine: Engine) -> None:
    """No shadows; the ring's lamp a 1.2 m tube of 2 cm radius (PointLight.length: the
    RECT_LIGHTS builds, the rectangle through its axis facing each pixel's point)."""
    _sun_shadows(engine, False)
    for _, light in engine.world.query_one(PointLight):
        light.length, light.radius = 1.2, 0.02


def _fog(engine: Engine) -> None:
    """No shadows; height fog on the camera (its FOG builds: each view, the sky and the
    composites)."""
    _sun_shadows(engine, False)
    engine.world.add_component(camera_entity(engine), Fog(density=0.04, height=0.0, height_falloff=0.2,
                                                          sun_scatter=0.5))


def _fog_uniform(engine: Engine) -> None:
    """No shadows; fog the same everywhere (its build has no falloff or glow term)."""
    _sun_shadows(engine, False)
    engine.world.add_component(camera_entity(engine), Fog(density=0.04))


def _fog_volumes(engine: Engine) -> None:
    """No shadows; four FogVolumes over the ring, no camera fog (the FOG_VOLUMES builds)."""
    _sun_shadows(engine, False)
    for k in range(4):
        angle = k * math.pi / 2.0
        engine.world.spawn(Transform(position=(4.0 * math.cos(angle), 0.5, 4.0 * math.sin(angle))),
                           FogVolume(size=(5.0, 2.0, 5.0), density=0.4))


def _atmosphere(engine: Engine) -> None:
    """No shadows; the scene's Skybox a physically based sky (Skybox.model "atmosphere")."""
    _plain(engine)
    for _, sky in engine.world.query_one(Skybox):
        sky.model = "atmosphere"


def _subsurface(engine: Engine) -> None:
    """Shadows; every box scatters light under its surface (Material.subsurface): the
    SUBSURFACE build's table lookups, and past each light's terminator its own shadow lookup."""
    _sun_shadows(engine, True)
    for _, material in engine.world.query_one(Material):
        if material.texture is None and material.color[0] != 0.1:   # (the boxes: not the floor, not the glass)
            material.subsurface, material.subsurface_scale = 1.0, 0.1


def _clouds(engine: Engine) -> None:
    """Shadows; a CloudLayer over the sky (half cover, its shadows on: the sky pass's CLOUDS
    build and the scene's CLOUD_SHADOWS), drifting on its wind (the cube map made again every
    two of its texels' drift)."""
    _sun_shadows(engine, True)
    for entity, _ in engine.world.query_one(Skybox):
        engine.world.add_component(entity, CloudLayer(coverage=0.5, wind=(30.0, 0.0)))


def _sun_setting(engine: Engine, frame: int) -> None:
    """The sun sinking a tenth of a degree a frame from 20 degrees up (a day in a minute at
    60 frames a second): an atmosphere's table made again every two or three frames, any
    generated sky's cube map every ten."""
    for _, light in engine.world.query_one(DirectionalLight):
        elevation = math.radians(20.0 - 0.1 * frame)
        light.direction = glm.vec3(0.3 * math.cos(elevation), -math.sin(elevation), -0.95 * math.cos(elevation))


def _shafts(engine: Engine, half: bool = True) -> None:
    """Shadows, height fog and light shafts on the camera (VolumetricFog: its march, at half
    size or a ray a pixel, and its filter)."""
    _shadows(engine)
    engine.world.add_component(camera_entity(engine), Fog(density=0.04, height=0.0, height_falloff=0.2))
    engine.world.add_component(camera_entity(engine), VolumetricFog(half_resolution=half))


def _shafts_clouds(engine: Engine) -> None:
    """The shafts under a drifting CloudLayer (its shadow read at each of the march's steps)."""
    _shafts(engine)
    for entity, _ in engine.world.query_one(Skybox):
        engine.world.add_component(entity, CloudLayer(coverage=0.5, wind=(30.0, 0.0)))


def _shafts_fog(engine: Engine) -> None:
    """What the shafts are measured against: the same shadows and fog without them."""
    _shadows(engine)
    engine.world.add_component(camera_entity(engine), Fog(density=0.04, height=0.0, height_falloff=0.2))


def _shafts_full(engine: Engine) -> None:
    _shafts(engine, half=False)


def _shafts_sun(engine: Engine) -> None:
    """The shafts of the sun alone (the lamp's PointLight.volumetric 0)."""
    _shafts(engine)
    for _, light in engine.world.query_one(PointLight):
        light.volumetric = 0.0


def _post(engine: Engine) -> None:
    _sun_shadows(engine, False)
    engine.world.add_component(camera_entity(engine), Tonemap(curve="agx"))
    engine.world.add_component(camera_entity(engine), Bloom())


def _flared(engine: Engine) -> None:
    """``_post`` with a lens flare beside the bloom (LensFlare: its ghosts read by the present
    draw) and lens dirt (Bloom.dirt: a puff)."""
    _post(engine)
    engine.world.add_component(camera_entity(engine), LensFlare())
    engine.world.get(camera_entity(engine), Bloom).dirt = puff_texture(64, 3, name="smudges")


def _graded(engine: Engine) -> None:
    _sun_shadows(engine, False)
    table = identity_lut(33).table.copy()
    table[..., 0] = table[..., 0] ** 0.9   # a little warmer: red lifted, blue lowered
    table[..., 2] = table[..., 2] ** 1.1
    lut = ColorLut(table, name="warm")
    engine.world.add_component(camera_entity(engine), Tonemap(curve="agx"))
    engine.world.add_component(camera_entity(engine), ColorGrading(
        temperature=0.2, tint=-0.1, contrast=1.1, slope=(1.05, 1.0, 0.95), offset=(0.0, 0.0, 0.01),
        power=(1.0, 1.0, 1.05), saturation=1.2, lut=lut))
    engine.world.add_component(camera_entity(engine), Vignette(intensity=0.4))


def _occlusion(engine: Engine, half: bool = True, quality: str = "medium", depth: int = 1) -> None:
    _sun_shadows(engine, False)
    engine.world.add_component(camera_entity(engine), AmbientOcclusion(half_resolution=half, quality=quality,
                                                                       reflection_depth=depth))


def _occlusion_camera(engine: Engine) -> None:
    _occlusion(engine, depth=0)


def _occlusion_full(engine: Engine) -> None:
    _occlusion(engine, half=False)


def _occlusion_low(engine: Engine) -> None:
    _occlusion(engine, quality="low")


def _contact(engine: Engine, occlusion: bool = False, half: bool = False) -> None:
    _sun_shadows(engine, False)
    engine.world.add_component(camera_entity(engine), ContactShadows(half_resolution=half))
    if occlusion:
        engine.world.add_component(camera_entity(engine), AmbientOcclusion())


def _contact_lamp(engine: Engine) -> None:
    _contact(engine)
    for _, light in engine.world.query_one(PointLight):
        light.contact_shadows = True


def _contact_half(engine: Engine) -> None:
    _contact(engine, half=True)


def _contact_occlusion(engine: Engine) -> None:
    _contact(engine, occlusion=True)


def _polished(engine: Engine) -> None:
    _sun_shadows(engine, False)
    for entity, mesh in engine.world.query_one(MeshRef):
        if mesh.mesh.name == "plane":  # the scene's floor
            engine.world.add_component(entity, Reflective(mode="skybox", mix=0.35))


def _glass(engine: Engine, screen: bool = False) -> None:
    """No shadows; three solid glass balls and a pane of glass in the ring (``Refractive``),
    refracting the probe's or sky's image (``screen`` False) or what each view drew behind
    them (True: screen-space refraction, its copy and march in the camera's view and every
    level that sees them)."""
    _sun_shadows(engine, False)
    world = engine.world
    for x in (-2.5, 0.0, 2.5):
        world.spawn(Transform(position=(x, 1.0, 0.0)), MeshRef(sphere(1.0)),
                    Material(color=(1.0, 1.0, 1.0, 0.0), roughness=0.0), Refractive(ior=1.5, solid=True, screen=screen))
    world.spawn(Transform(position=(0.0, 1.5, 3.0)), MeshRef(box((4.0, 3.0, 0.05))),
                Material(color=(1.0, 1.0, 1.0, 0.0), roughness=0.0), Refractive(ior=1.5, screen=screen))


def _glass_screen(engine: Engine) -> None:
    _glass(engine, screen=True)


def _reflections(engine: Engine, quality: str = "medium", half: bool = False, depth: int = 1) -> None:
    _polished(engine)
    engine.world.add_component(camera_entity(engine), ScreenReflections(quality=quality, half_resolution=half,
                                                                        reflection_depth=depth))


def _reflections_camera(engine: Engine) -> None:
    _reflections(engine, depth=0)


def _reflections_low(engine: Engine) -> None:
    _reflections(engine, "low")


def _reflections_half(engine: Engine) -> None:
    _reflections(engine, half=True)


def _post_auto(engine: Engine) -> None:
    _sun_shadows(engine, False)
    engine.world.add_component(camera_entity(engine), Tonemap(curve="agx", auto_exposure=True))
    engine.world.add_component(camera_entity(engine), Bloom())


def _temporal(engine: Engine, scale: float = 1.0) -> None:
    _plain(engine)
    engine.renderer.antialias = "taa"
    engine.renderer.render_scale = scale


def _temporal_half(engine: Engine) -> None:
    _temporal(engine, 0.5)


def _half_scale(engine: Engine) -> None:
    _plain(engine)
    engine.renderer.render_scale = 0.5


def _sharpened(engine: Engine) -> None:
    _plain(engine)
    engine.renderer.sharpness = 0.5


VARIANTS: list[Variant] = [
    Variant("off", _plain, "no shadows, no Tonemap, no Bloom (the plain look)"),
    Variant("shadows", _shadows, "the sun casts shadows; a still scene (its map kept)"),
    Variant("subsurface", _subsurface, "shadows, every box scattering light under its surface (Material.subsurface)"),
    Variant("clouds", _clouds, "shadows, a drifting CloudLayer over the sky shading the scene"),
    Variant("shadows_moving", _moving_caster, "the sun casts shadows; a box slides under it every frame",
            _slide_caster),
    Variant("mirror_light", _mirror_light, "shadows, and one mirror throws the sun (a virtual light); still"),
    Variant("mirror_light_moving", _mirror_light_moving, "the same with a box sliding under the sun",
            _slide_caster),
    Variant("cascades", _cascades, "shadows with three cascades about the orbiting camera"),
    Variant("grid_sun", _grid_sun, "the sun casts shadows, read by the grid filter; still"),
    Variant("soft_sun", _soft_sun, "the same with the sun 2 degrees across (angular_diameter): soft shadows"),
    Variant("cascades_moving", _cascades_moving, "the same with a box sliding under the sun", _slide_caster),
    Variant("spot_shadows", _spot, "the lamp a 30-degree spot casting from its map; still"),
    Variant("spot_moving", _spot_moving, "the same with a box sliding under it", _slide_caster),
    Variant("sphere_lamp", _sphere_lamp, "no shadows; the lamp a sphere of 0.2 m (PointLight.radius)"),
    Variant("rect_lamp", _rect_lamp, "no shadows; the lamp a 1 x 0.5 m panel (PointLight.rectangle)"),
    Variant("picture_lamp", _picture_lamp, "rect_lamp with a picture on its face (PointLight.cookie)"),
    Variant("tube_lamp", _tube_lamp, "no shadows; the lamp a 1.2 m tube (PointLight.length)"),
    Variant("lamps_8", _lamps_8, "no shadows; eight more lamps over the floor"),
    Variant("lamps_8_rect", _lamps_8_rect, "the same, the first of them a 0.8 x 0.4 m panel"),
    Variant("lamp_shadows", _lamp_shadows, "no sun shadows; the lamp casts from its cube (the grid filter)"),
    Variant("soft_lamp", _soft_lamp, "the same with the lamp a sphere of 0.2 m: soft shadows"),
    Variant("volume", _volume, "no shadows; an irradiance volume of 6 x 2 x 6 points over the ring"),
    Variant("fog", _fog, "height fog with sun scatter on the camera"),
    Variant("fog_uniform", _fog_uniform, "fog the same everywhere on the camera"),
    Variant("fog_volumes", _fog_volumes, "four FogVolumes over the ring, no camera fog"),
    Variant("atmosphere", _atmosphere, "no shadows; a physically based sky (Skybox(model='atmosphere'))"),
    Variant("gradient_setting", _plain, "no shadows; the sun sinking 0.1 degrees a frame", _sun_setting),
    Variant("atmosphere_setting", _atmosphere, "the atmosphere with the sun sinking 0.1 degrees a frame",
            _sun_setting),
    Variant("shafts_fog", _shafts_fog, "shadows and height fog on the camera (the shafts' baseline)"),
    Variant("shafts", _shafts, "the same with VolumetricFog() (marched at half size; the sun's and the lamp's)"),
    Variant("shafts_clouds", _shafts_clouds, "the shafts under a drifting CloudLayer shading them and the scene"),
    Variant("shafts_sun", _shafts_sun, "the same with the sun's shafts alone (the lamp's volumetric 0)"),
    Variant("shafts_full", _shafts_full, "the same with VolumetricFog(half_resolution=False)"),
    Variant("post", _post, "Tonemap(curve='agx') and Bloom() on the camera"),
    Variant("post_auto", _post_auto, "Tonemap(curve='agx', auto_exposure=True) and Bloom()"),
    Variant("flared", _flared, "post with a lens flare beside the bloom"),
    Variant("graded", _graded, "Tonemap(curve='agx') and a ColorGrading with a colour table"),
    Variant("occlusion", _occlusion, "AmbientOcclusion() on the camera (found at half size)"),
    Variant("occlusion_camera", _occlusion_camera, "AmbientOcclusion(reflection_depth=0): the camera's view alone"),
    Variant("occlusion_full", _occlusion_full, "AmbientOcclusion(half_resolution=False) on the camera"),
    Variant("occlusion_low", _occlusion_low, "AmbientOcclusion(quality='low') on the camera"),
    Variant("contact", _contact, "ContactShadows() on the camera (found at full size)"),
    Variant("contact_lamp", _contact_lamp, "ContactShadows() and the lamp's contact shadows"),
    Variant("contact_half", _contact_half, "ContactShadows(half_resolution=True) on the camera"),
    Variant("contact_occlusion", _contact_occlusion, "ContactShadows() and AmbientOcclusion() (at half size)"),
    Variant("polished", _polished, "the floor reflects the sky (Reflective(mix=0.35))"),
    Variant("glass", _glass, "no shadows; three glass balls and a pane refracting the sky (Refractive(screen=False))"),
    Variant("glass_screen", _glass_screen, "the same refracting what each view drew behind them (screen-space)"),
    Variant("reflections", _reflections, "the polished floor and ScreenReflections() on the camera"),
    Variant("reflections_camera", _reflections_camera, "ScreenReflections(reflection_depth=0): the camera view alone"),
    Variant("reflections_low", _reflections_low, "the same with ScreenReflections(quality='low')"),
    Variant("reflections_half", _reflections_half, "the same with ScreenReflections(half_resolution=True)"),
    Variant("taa", _temporal, "temporal AA in place of FXAA"),
    Variant("taa_half", _temporal_half, "temporal AA at render scale 0.5 (temporal upsampling)"),
    Variant("half_scale", _half_scale, "FXAA at render scale 0.5 (a Catmull-Rom upscale)"),
    Variant("sharpened", _sharpened, "FXAA and contrast-adaptive sharpening 0.5"),
]
BASELINE = "off"


@dataclass(frozen=True)
class Target:
    """A ratio of two variants' median frames with no mirror, against ``limit``."""

    variant: str
    over: str
    mirrors: int
    size: tuple[int, int]   # the frame it is set for
    limit: float
    set_for: str            # "gpu": that frame on a GPU; "software": its stand-in on this machine
    part: str               # "frames": measured at --size here; "cpu": by the LP_NUM_THREADS=0 stand-in


TARGETS: dict[str, Target] = {
    "post_0_mirrors": Target("post", "off", 0, STAND_IN_FOR, 1.10, "gpu", "frames"),
    "shadows_still": Target("shadows", "off", 0, STAND_IN_FOR, 1.05, "gpu", "frames"),
    "cpu_post_0_mirrors": Target("post", "off", 0, STAND_IN_FOR, 1.10, "software", "cpu"),
    "cpu_shadows_still": Target("shadows", "off", 0, STAND_IN_FOR, 1.05, "software", "cpu"),
}
# name -> (variant, limit): the most shadow maps a frame of it may draw, at every mirror count.
COUNT_TARGETS: dict[str, tuple[str, int]] = {"shadow_maps_moving": ("shadows_moving", 1),
                                             "shadow_maps_still": ("shadows", 0),
                                             "shadow_maps_mirror_light_still": ("mirror_light", 0),
                                             "shadow_maps_mirror_light_moving": ("mirror_light_moving", 2)}


def gpu_passes(engine: Engine, size: tuple[int, int] | None) -> None:
    """Make ``engine`` draw what a GPU's frame draws: the bloom chain from a half-size start
    (a software rasteriser's starts at a quarter), the "grid" shadow filter and FXAA's walk
    of ``GPU_SEARCH_STEPS``; with ``size``, the bloom chain of an image of that size
    (``BloomPass.chain_of``) whatever the output's.  Shadow maps as small as the cpu suite
    makes them (``scale_shadows_down``: a still scene draws none a frame, and the lookups are
    the same at any resolution)."""
    from benchmarks.cpu import scale_shadows_down

    present = engine.renderer.present_pass
    present.bloom.first_step = "half"
    present.bloom.chain_of = size
    present.search_steps = GPU_SEARCH_STEPS
    engine.renderer.shadows.filter = "grid"
    scale_shadows_down(engine)


@dataclass
class Row:
    n_mirrors: int
    variant: str
    frame_ms_median: float
    cpu_ms_median: float
    ratio_to_off: float
    process_ms_median: float
    process_ratio_to_off: float
    passes: int
    shadow_maps: int   # drawn a frame (median)
    frames: int
    size: str
    part: str = "frames"           # "frames": this process at --size; "cpu": the LP_NUM_THREADS=0 stand-in
    stands_in_for: str = ""        # the cpu part: the frame size whose passes it issues
    draw_calls: int = 0            # a frame's (median)
    gl_calls: int | None = None    # the cpu part: calls into the GL a frame (GLCallCounter)
    lp_num_threads: str | None = None


def run_variants(ctx, variants: list[Variant], mirror_counts: tuple[int, ...], frames: int, warmup: int,
                 size: tuple[int, int] = OUTPUT_SIZE, stand_in_for: tuple[int, int] | None = None,
                 seed: int = 0, block: int = 1) -> list[Row]:
    """One engine per (mirror count, variant), frames interleaved: each round, in a shuffled
    order, every engine draws ``block`` frames; a row each.  Engines share the context, so
    an engine's frame after another's binds again what that one displaced (a few GL calls,
    next to nothing at 640x360); with ``block`` > 1 each block's first frame is not timed,
    so the rows time an engine's frames as it draws them alone.  With ``stand_in_for`` (the
    cpu part), each engine draws what a GPU's frame of that size draws (``gpu_passes``),
    and its row counts a frame's GL calls (one drawn after one of its own)."""
    cases = [(mirrors, variant) for mirrors in mirror_counts for variant in variants]
    engines, captures = [], []
    counter = None
    try:
        if stand_in_for is not None:
            from benchmarks.cpu import GLCallCounter

            counter = GLCallCounter()
        with counter.raw_gl_loading() if counter is not None else contextlib.nullcontext():
            for mirrors, variant in cases:
                engine = Engine(MirrorRing(mirrors), ctx)
                variant.configure(engine)
                if stand_in_for is not None:
                    gpu_passes(engine, stand_in_for)
                engines.append(engine)
                captures.append(CaptureTarget(ctx, size))
        outputs = [Output(capture.framebuffer, size) for capture in captures]
        times: list[list[float]] = [[] for _ in cases]
        cpu: list[list[float]] = [[] for _ in cases]
        work: list[list[float]] = [[] for _ in cases]
        passes: list[list[int]] = [[] for _ in cases]
        draws: list[list[int]] = [[] for _ in cases]
        shadow_maps: list[list[int]] = [[] for _ in cases]
        order = list(range(len(cases)))
        rng = random.Random(seed)
        drawn = [0] * len(cases)
        while min(len(t) for t in times) < frames:
            rng.shuffle(order)   # each engine follows every other alike (the caches it finds)
            for i in order:
                engine, output = engines[i], outputs[i]
                for run in range(block):
                    frame = drawn[i]
                    drawn[i] += 1
                    step = cases[i][1].step
                    if step is not None:
                        step(engine, frame)
                    ctx.finish()
                    start, start_work = time.perf_counter(), time.process_time()
                    engine.frame(DT, output)
                    returned = time.perf_counter()
                    ctx.finish()
                    if frame < warmup or (block > 1 and run == 0) or len(times[i]) == frames:
                        continue
                    times[i].append((time.perf_counter() - start) * 1e3)
                    work[i].append((time.process_time() - start_work) * 1e3)
                    cpu[i].append((returned - start) * 1e3)
                    passes[i].append(engine.renderer.stats.passes + engine.renderer.present_pass.post_passes)
                    draws[i].append(engine.renderer.stats.draw_calls)
                    shadow_maps[i].append(engine.renderer.stats.shadow_maps_drawn)
        counted = [None] * len(cases)
        if counter is not None:
            counted = [gl_calls(ctx, counter, engine, output) for engine, output in zip(engines, outputs, strict=True)]
        if ctx.error != "GL_NO_ERROR":
            raise RuntimeError(f"OpenGL error: {ctx.error}")
    finally:
        for capture in captures:
            capture.release()
        for engine in engines:
            engine.close()
    medians = {(m, v.name): statistics.median(times[i]) for i, (m, v) in enumerate(cases)}
    work_medians = {(m, v.name): statistics.median(work[i]) for i, (m, v) in enumerate(cases)}
    rows = []
    for i, (mirrors, variant) in enumerate(cases):
        base = medians.get((mirrors, BASELINE))
        work_base = work_medians.get((mirrors, BASELINE))
        median = medians[mirrors, variant.name]
        work_median = work_medians[mirrors, variant.name]
        rows.append(Row(n_mirrors=mirrors, variant=variant.name, frame_ms_median=round(median, 4),
                        cpu_ms_median=round(statistics.median(cpu[i]), 4),
                        ratio_to_off=round(median / base, 3) if base else float("nan"),
                        process_ms_median=round(work_median, 4),
                        process_ratio_to_off=round(work_median / work_base, 3) if work_base else float("nan"),
                        passes=round(statistics.median(passes[i])),
                        shadow_maps=round(statistics.median(shadow_maps[i])), frames=frames, size=format_size(size),
                        part="frames" if stand_in_for is None else "cpu",
                        stands_in_for="" if stand_in_for is None else format_size(stand_in_for),
                        draw_calls=round(statistics.median(draws[i])), gl_calls=counted[i],
                        lp_num_threads=os.environ.get("LP_NUM_THREADS")))
    return rows


def gl_calls(ctx, counter, engine: Engine, output: Output) -> int:
    """The calls ``engine``'s next frame makes into the GL (``GLCallCounter``, as the cpu
    suite counts them: moderngl's methods and properties written, and raw GL calls of an
    engine made inside the counter's ``raw_gl_loading``)."""
    engine.frame(DT, output)   # after a frame of its own: what it binds drawing alone
    ctx.finish()
    with counter:
        counter.reset()
        engine.frame(DT, output)
        total = counter.total
    ctx.finish()
    return total


def frame_passes(ctx, variants: list[Variant], size: tuple[int, int], warmup: int) -> dict[str, tuple[int, int, int]]:
    """Per variant, (passes, draw calls, GL calls) of a frame at ``size`` drawn here with a
    GPU's settings and the bloom chain of its own size (``gpu_passes(engine, None)``): what
    the cpu part's stand-in must issue."""
    from benchmarks.cpu import GLCallCounter

    counter = GLCallCounter()
    found = {}
    capture = CaptureTarget(ctx, size)
    try:
        output = Output(capture.framebuffer, size)
        for variant in variants:
            with counter.raw_gl_loading():
                engine = Engine(MirrorRing(0), ctx)
            try:
                variant.configure(engine)
                gpu_passes(engine, None)
                for _ in range(warmup + 1):
                    engine.frame(DT, output)
                stats = engine.renderer.stats
                drawn = (stats.passes + engine.renderer.present_pass.post_passes, stats.draw_calls)
                found[variant.name] = (*drawn, gl_calls(ctx, counter, engine, output))
            finally:
                engine.close()
    finally:
        capture.release()
    return found


def _gpu_bloom_draws() -> int:
    """The draws of a GPU's bloom chain at ``STAND_IN_FOR``: from a half-size start, as many
    levels as fit."""
    return 2 * len(level_sizes(STAND_IN_FOR, Bloom().levels, "half")) - 1


def stand_in_rows(ctx, frames: int, warmup: int) -> list[Row]:
    """The cpu part (run in an ``LP_NUM_THREADS=0`` process): ``STAND_IN_VARIANTS`` with no
    mirror at ``STAND_IN_SIZE``, each drawing what a GPU's ``STAND_IN_FOR`` frame draws;
    raises if a variant's frame made other passes, draws or GL calls than one drawn at
    ``STAND_IN_FOR`` here, or if the post variant's bloom made other draws than a GPU's chain
    at that size (a half-size start)."""
    chosen = [v for v in VARIANTS if v.name in STAND_IN_VARIANTS]
    rows = run_variants(ctx, chosen, (0,), frames, warmup, STAND_IN_SIZE, stand_in_for=STAND_IN_FOR,
                        block=STAND_IN_BLOCK)
    wanted = frame_passes(ctx, chosen, STAND_IN_FOR, max(warmup, 3))
    bloom_draws = _gpu_bloom_draws()
    by = {row.variant: row for row in rows}
    if by["post"].passes - by["off"].passes != bloom_draws:
        raise RuntimeError(f"the stand-in's bloom made {by['post'].passes - by['off'].passes} draws, a GPU's chain "
                           f"at {format_size(STAND_IN_FOR)} {bloom_draws}")
    for row in rows:
        got = (row.passes, row.draw_calls, row.gl_calls)
        if got != wanted[row.variant]:
            raise RuntimeError(f"the {format_size(STAND_IN_SIZE)} stand-in of {row.variant} made (passes, draws, "
                               f"GL calls) {got} a frame, the {format_size(STAND_IN_FOR)} frame "
                               f"{wanted[row.variant]}: it does not measure that frame's passes")
    return rows


# A bare pass of ``pass_floor_ms``: a 3-vertex draw of a one-line program, no texture read.
_BARE_VERTEX = ("#version 410 core\nvoid main() { gl_Position = vec4(vec2(gl_VertexID & 1, gl_VertexID >> 1) "
                "* 4.0 - 1.0, 0.0, 1.0); }")
_BARE_FRAGMENT = "#version 410 core\nout vec4 colour;\nvoid main() { colour = vec4(1.0); }"


def pass_floor_ms(ctx, passes: int, repeats: int = 2000) -> float:
    """The least ``passes`` dependent full-screen passes cost here, in ms (median of
    ``repeats``, ``ctx.finish()`` included): each binds a framebuffer of its own (a 2 x 2
    target) and draws a bare program, with no texture bound, no uniform written and no state
    changed; nothing a bloom step could do less of.  In the stand-in's process it is what
    llvmpipe charges a pass for leaving one target for the next (it flushes, and with no
    rasteriser threads draws, on the calling thread), which a GPU driver queues instead: a
    bloom chain of that many steps costs the stand-in at least this much over the ``off``
    frame, whatever its shaders."""
    program = ctx.program(vertex_shader=_BARE_VERTEX, fragment_shader=_BARE_FRAGMENT)
    vao = ctx.vertex_array(program, [])
    textures = [ctx.texture((2, 2), 4, dtype="f4") for _ in range(passes)]
    framebuffers = [ctx.framebuffer([texture]) for texture in textures]
    times = []
    try:
        for _ in range(repeats):
            start = time.perf_counter()
            for framebuffer in framebuffers:
                framebuffer.use()
                vao.render(vertices=3)
            ctx.finish()
            times.append(time.perf_counter() - start)
    finally:
        for item in (*framebuffers, *textures, vao, program):
            item.release()
    return round(statistics.median(times) * 1e3, 4)


def cpu_part(frames: int, warmup: int) -> list[dict]:
    """The cpu part's rows, from a subprocess started with ``LP_NUM_THREADS=0``, as the cpu
    suite runs its own."""
    return rows_without_rasteriser(["lighting", "--json", "--child", "--cpu-frames", str(frames),
                                    "--warmup", str(warmup)])


def target_rows(rows: list[Row], size: tuple[int, int], software: bool, floor: dict | None = None) -> list[dict]:
    """Each target measured in ``rows`` (a frames part target from the frames rows, at
    ``size``; a cpu part target from the stand-in's): value, limit, met, and whether it
    applies here (a gpu target at its size on a GPU, a software target on a software
    rasteriser).  With ``floor`` (the stand-in's ``pass_floor_ms`` of a GPU's chain), the
    post target also gives ``least_possible``: the ratio a chain of that many passes cannot
    go under on the stand-in, (off + floor) / off."""
    found = []
    for name, target in TARGETS.items():
        by = {(r.n_mirrors, r.variant): r for r in rows if r.part == target.part}
        key, over = (target.mirrors, target.variant), (target.mirrors, target.over)
        if key not in by or over not in by:
            continue
        value = round(by[key].frame_ms_median / by[over].frame_ms_median, 3)
        measured_at = by[key].size
        at_size = measured_at == format_size(target.size) if target.part == "frames" else \
            by[key].stands_in_for == format_size(target.size)
        where = f"{measured_at}" if target.part == "frames" else \
            f"{measured_at} issuing a GPU's {by[key].stands_in_for} passes, LP_NUM_THREADS={by[key].lp_num_threads}"
        found.append({"target": name, "value": value, "limit": target.limit, "unit": "x", "met": value <= target.limit,
                      "at_its_size": at_size, "set_for": target.set_for, "part": target.part,
                      "applies": at_size and (target.set_for == "software") == software,
                      "measured": f"{target.variant} {by[key].frame_ms_median} ms / {target.over} "
                                  f"{by[over].frame_ms_median} ms, {target.mirrors} mirrors, {where}"})
        if floor is not None and target.part == "cpu" and target.variant == "post":
            off = by[over].frame_ms_median
            found[-1]["least_possible"] = round((off + floor["pass_floor_ms"]) / off, 3)
            found[-1]["measured"] += (f"; {floor['passes']} bare passes cost {floor['pass_floor_ms']} ms here "
                                      f"(pass_floor_ms), so that chain cannot go under "
                                      f"{found[-1]['least_possible']}x")
    frames = [r for r in rows if r.part == "frames"]
    for name, (variant, limit) in COUNT_TARGETS.items():
        measured = [r for r in frames if r.variant == variant]
        if not measured:
            continue
        value = max(r.shadow_maps for r in measured)
        found.append({"target": name, "value": value, "limit": limit, "unit": "maps", "met": value <= limit,
                      "at_its_size": True, "set_for": "any", "part": "frames", "applies": True,
                      "measured": f"{variant}: shadow maps a frame at "
                                  + ", ".join(f"{r.n_mirrors} mirrors {r.shadow_maps}" for r in measured)})
    return found


def _ints(text: str) -> tuple[int, ...]:
    return tuple(int(v) for v in text.split(","))


def _variants(text: str) -> tuple[str, ...]:
    names = tuple(v.strip() for v in text.split(",") if v.strip())
    known = [v.name for v in VARIANTS]
    unknown = sorted(set(names) - set(known))
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"unknown variants {unknown}; choose from {','.join(known)}")
    return names


def _parts(text: str) -> tuple[str, ...]:
    return names_from(text, PARTS, "parts")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--mirrors", type=_ints, default=(0,), help="comma-separated mirror counts (default 0)")
    parser.add_argument("--variants", type=_variants, default=tuple(v.name for v in VARIANTS),
                        help=f"comma-separated variants (default all: {','.join(v.name for v in VARIANTS)})")
    parser.add_argument("--frames", type=positive_int, default=60, help="timed frames per engine (default 60)")
    parser.add_argument("--warmup", type=non_negative_int, default=5, help="untimed frames first (default 5)")
    parser.add_argument("--parts", type=_parts, default=PARTS, metavar="NAME[,NAME...]",
                        help="frames (the variants at --size here), cpu (the LP_NUM_THREADS=0 stand-in of a GPU's "
                             f"{format_size(STAND_IN_FOR)} frame at {format_size(STAND_IN_SIZE)}); default both")
    parser.add_argument("--cpu-frames", type=positive_int, default=600,
                        help="timed frames per engine of the cpu part (default 600: a frame is a fraction of a ms)")
    parser.add_argument("--report-only", action="store_true",
                        help="exit 0 whatever the targets (they are still printed, met or not)")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)  # the LP_NUM_THREADS=0 process
    add_size_argument(parser, OUTPUT_SIZE)


COLUMNS = (("part", "part", 6), ("n_mirrors", "mirrors", 8), ("variant", "variant", 10), ("size", "size", 8),
           ("frame_ms_median", "ms med", 9), ("cpu_ms_median", "cpu ms", 9), ("ratio_to_off", "/ off", 7),
           ("process_ms_median", "proc ms", 9), ("process_ratio_to_off", "p / off", 8), ("passes", "passes", 7),
           ("draw_calls", "draws", 6), ("gl_calls", "GL", 5), ("shadow_maps", "shadows", 8))


def main(args: argparse.Namespace) -> int:
    if args.child:  # the LP_NUM_THREADS=0 process: the stand-in's rows
        ctx = create_headless_context()
        try:
            rows = stand_in_rows(ctx, args.cpu_frames, max(args.warmup, 20))
            floor = {"pass_floor_ms": pass_floor_ms(ctx, _gpu_bloom_draws()), "passes": _gpu_bloom_draws()}
        finally:
            ctx.release()
        for row in rows:
            print(json.dumps(asdict(row)), flush=True)
        print(json.dumps(floor), flush=True)
        return 0
    if any(n < 0 for n in args.mirrors):
        raise SystemExit("--mirrors must be >= 0")
    chosen = [v for v in VARIANTS if v.name in args.variants]
    if BASELINE not in args.variants:
        chosen.insert(0, next(v for v in VARIANTS if v.name == BASELINE))  # every ratio is to it
    rows: list[Row] = []
    floor = None
    if "cpu" in args.parts:
        for row in cpu_part(args.cpu_frames, args.warmup):
            if "pass_floor_ms" in row:
                floor = row
            else:
                rows.append(Row(**row))
    ctx = create_headless_context()
    try:
        renderer = ctx.info.get("GL_RENDERER", "?")
        software = GLCapabilities.read(ctx).software
        if "frames" in args.parts:
            rows = run_variants(ctx, chosen, args.mirrors, args.frames, args.warmup, args.size) + rows
    finally:
        ctx.release()
    targets = target_rows(rows, args.size, software, floor)
    missed = [t for t in targets if t["applies"] and not t["met"]]
    if args.json:
        for row in rows:
            print(json.dumps(asdict(row)), flush=True)
        for target in targets:
            print(json.dumps(target), flush=True)
        return 1 if missed and not args.report_only else 0
    print(f"Lighting on {renderer}: whole frame incl. ctx.finish(), variants interleaved; frames part at "
          f"{format_size(args.size)} ({args.frames} frames after {args.warmup} warm-up), cpu part at "
          f"{format_size(STAND_IN_SIZE)} with LP_NUM_THREADS=0 issuing a GPU's {format_size(STAND_IN_FOR)} passes "
          f"({args.cpu_frames} frames)")
    print(" ".join(f"{title:>{width}}" for _, title, width in COLUMNS))
    for row in rows:
        values = asdict(row)
        print(" ".join(f"{values[key]!s:>{width}}" for key, _, width in COLUMNS))
    for target in targets:
        met = "yes" if target["met"] else "no"
        if not target["at_its_size"]:
            met += " (not at the target's size)"
        elif not target["applies"]:
            met += f" (set for a {target['set_for']} rasteriser: reported, not judged here)" \
                if target["set_for"] == "software" else f" (set for a {target['set_for']}: reported, not judged here)"
        print(f"target {target['target']}: {target['value']}{target['unit'] if target['unit'] == 'x' else ''}, "
              f"limit {target['limit']}{target['unit'] if target['unit'] == 'x' else ''}, met: {met}  "
              f"({target['measured']})")
    sys.stdout.flush()
    if missed:
        print(f"not met: {', '.join(t['target'] for t in missed)}", file=sys.stderr)
    return 1 if missed and not args.report_only else 0
