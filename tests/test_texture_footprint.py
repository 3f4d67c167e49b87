"""A map read where a pixel's footprint spans thousands of textures (a surface nearly edge-on,
a texture repeated past what a pixel can show) finishes, and gives the texture's mean.

llvmpipe's anisotropic filter (Mesa 22.3) walks every texel of the footprint's bounding box
at the last mip level, with no cap: one textured, unevenly scaled sphere at 64 x 48 drew for
145 s.  Software builds hold the footprint to one texture a pixel
(``shaders/include/footprint.glsl``, BOUNDED_FOOTPRINT); a GPU's filter caps itself.  The
frame is drawn in a child process with a time limit a hundred times what it needs: without
the bound it runs for hours, so the limit tells a hang from a slow machine, not a speed.
The colours are checked against a second quad painted the texture's mean, unlit, in the same
frame; the cutout's shadow against the lit floor beside it.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
HANG_LIMIT_S = 240  # the frame takes about 1 s on llvmpipe; without the bound, hours

CHILD = r"""
import json
import numpy as np
from pyglm import glm
from components import DirectionalLight, Material, MeshRef, Skybox, Transform
from engine.assets.mesh import plane
from engine.assets.texture_data import TextureData
from engine.render.gl_context import create_headless_context
from tests.support import SceneRunner, look_from, srgb_to_linear

SIZE = (64, 48)
REPEAT = 100000.0   # the map's repeats across each quad: thousands of textures a pixel
texels = np.full((8, 8, 4), 255, np.uint8)
texels[..., :3] = np.where(((np.indices((8, 8)).sum(0)) % 2 == 0)[..., None], (150, 170, 130), (170, 150, 150))
TEXTURE = TextureData(texels, name="fine")
MEAN = srgb_to_linear(texels[..., :3].reshape(-1, 3)).mean(0)
FACING = glm.angleAxis(glm.radians(90.0), glm.vec3(1, 0, 0))   # the plane's +Y turned to +Z, the eye's way
ids = {}

def build(world):
    look_from(world, (0.0, 1.2, 3.0), (0.0, -0.3, 0.0), fov=55.0)
    world.spawn(Skybox(faces=[np.full((4, 4, 3), 0.1, np.float32) for _ in range(6)]))
    world.spawn(DirectionalLight(direction=(0.0, -1.0, -0.2), intensity=2.0))
    ids["mapped"] = world.spawn(Transform(position=(-0.75, 0.35, 0.0), rotation=FACING),
                                MeshRef(plane(0.8, 0.8, uv_repeat=REPEAT)),
                                Material(color=(1.0, 1.0, 1.0, 1.0), texture=TEXTURE, unlit=True))
    ids["mean"] = world.spawn(Transform(position=(0.75, 0.35, 0.0), rotation=FACING), MeshRef(plane(0.8, 0.8)),
                              Material(color=(*MEAN, 1.0), unlit=True))
    # A cutout high over the floor, facing the sun, its map repeated as finely: the shadow pass
    # reads it at thousands of textures a shadow texel.  Opaque everywhere: a whole shadow.
    world.spawn(Transform(position=(0.0, 1.5, -1.5)), MeshRef(plane(0.8, 0.8, uv_repeat=REPEAT)),
                Material(color=(1.0, 1.0, 1.0, 1.0), texture=TEXTURE, alpha_cutoff=0.5))
    world.spawn(Transform(position=(0.0, -0.6, -1.0)), MeshRef(plane(4.0, 4.0)),
                Material(color=(0.8, 0.8, 0.8, 1.0), roughness=1.0, environment_reflection=0.0))

runner = SceneRunner(create_headless_context(), build, SIZE)
runner.engine.renderer.antialias = "off"
runner.frame()
frame = runner.frame()
under = runner.project((0.0, -0.6, -1.5 - 0.2 * 2.1))   # the cutout's centre, down the sun's way to the floor
beside = runner.project((0.0, -0.6, -0.7))   # lit: past the shadow's near edge (-1.52)

def around(point):
    x, y = runner.project(point)
    return frame[y - 3:y + 4, x - 3:x + 4].reshape(-1, 3).tolist()

print(json.dumps({
    "mapped": around((-0.75, 0.35, 0.0)),
    "mean": around((0.75, 0.35, 0.0)),
    "under": frame[under[1], under[0]].tolist(),
    "beside": frame[beside[1], beside[0]].tolist(),
}))
"""


def _draw() -> dict:
    try:
        done = subprocess.run([sys.executable, "-c", CHILD], cwd=ROOT, capture_output=True, text=True,
                              timeout=HANG_LIMIT_S, env={**os.environ, "PYTHONPATH": str(ROOT)})
    except subprocess.TimeoutExpired:
        raise AssertionError(f"the frame did not finish in {HANG_LIMIT_S} s: a map read walked its whole "
                             "footprint (shaders/include/footprint.glsl)") from None
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_a_map_read_thousands_of_textures_a_pixel_finishes_and_gives_the_textures_mean():
    found = _draw()
    mapped, mean = np.array(found["mapped"], float), np.array(found["mean"], float)
    assert mean.min() > 100, mean.min()   # the mean quad is there, not the background
    # Every pixel of the mapped quad is the texture's mean (its two colours are 20 apart in
    # each channel: one texel read as it is would be 10 off).
    assert np.abs(mapped - mean.mean(0)).max() <= 3.0, (mapped.min(0), mapped.max(0), mean.mean(0))
    # The cutout read in the shadow pass: its whole square shadows the floor.
    under, beside = np.array(found["under"], float), np.array(found["beside"], float)
    assert beside.mean() > under.mean() + 40, (under, beside)
