"""Level-file fuzz: a small level's text mutated at random, loaded, spawned and rendered.

Each case applies one to three mutations to ``BASE`` (a field's value replaced by an awkward
TOML value, a component or field renamed, a name or reference changed, a mesh or texture
spec replaced, a line broken, a table emptied) and writes the result to a file.  A case
passes when either loading or spawning raises a ``LevelError`` that names the file (and the
entity where the mutation touched one), or the level spawns and renders ``FRAMES`` 48 x 32 frames
with no NaN in the HDR target and ``ctx.error`` clean.  Any other exception is a failure,
as is an entity left in the world by a refused level, or a case still running after
``CASE_SECONDS`` (a hang).

A quarter of the cases are file cases (``FILE_CASES``, made in the fuzz folder once): the
crate's mesh or the floor's texture or normal map names an adversarial file (a symlink
loop, a FIFO, a directory, a link to /dev/zero, an image bomb, a glTF nested 100,000 deep,
an OBJ whose faces pass its vertices or whose material reaches outside, a path outside the
level's folder, existing or not) or a value nested thousands deep; each must be refused
saying what it is, or (16-bit and float images) load with the texel the file holds and
render.  The sky's cases (``SKY_FILE_CASES``) name a panorama in its ``faces`` table: an
OpenEXR or Radiance file of random bytes, cut short, holding NaN, past half floats, declaring
10,000 pixels, a FIFO, outside, a layer it lacks or cannot have; each refused saying so, or
(a plain file, a named layer) loaded as the grey it holds.  ``python -m benchmarks fuzz``
also runs every file case once.

    python -m benchmarks fuzz --level-cases 2000
"""
from __future__ import annotations

import contextlib
import json
import os
import random
import re
import signal
import struct
import threading
import traceback
import warnings
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks.fuzz_cases import FRAMES, hdr_image, hdr_problem
from engine.assets.level_file import LevelError, load_level
from engine.core.frame_io import Output
from engine.core.game import Game
from engine.render.targets import CaptureTarget
from shell.app import Engine

SIZE = (48, 32)
BASE = """\
[level]
name = "fuzz"

[[entity]]
name = "camera"
[entity.Transform]
position = [0.0, 1.5, 5.0]
rotation = { yaw = 0, pitch = -10 }
[entity.Camera]
fov_y = 60.0

[[entity]]
name = "sky"
[entity.Skybox]
face_size = 8

[[entity]]
name = "sun"
[entity.DirectionalLight]
direction = [-0.3, -1.0, -0.5]
intensity = 2.0

[[entity]]
name = "floor"
[entity.Transform]
position = [0.0, 0.0, 0.0]
[entity.MeshRef]
mesh = { plane = [6.0, 6.0], uv_repeat = 2.0 }
[entity.Material]
texture = { checker = [32, 4] }
roughness = 0.8

[[entity]]
name = "crate"
[entity.Transform]
position = [0.8, 0.5, 0.0]
scale = [1.0, 1.0, 1.0]
parent = "floor"
[entity.MeshRef]
mesh = { box = [1.0, 1.0, 1.0] }
[entity.Material]
color = [0.8, 0.3, 0.1, 1.0]
[entity.Emissive]
power = 0.5

[[entity]]
name = "mirror"
[entity.Transform]
position = [0.0, 1.0, -2.0]
[entity.MeshRef]
mesh = { quad = [2.0, 1.5] }
[entity.Material]
[entity.Mirror]
color = [0.9, 1.0, 0.9]
roughness = 0.1

[[entity]]
name = "door_a"
[entity.Transform]
position = [-2.0, 1.0, -1.0]
rotation = { look = [1.0, 0.0, 0.0] }
[entity.MeshRef]
mesh = { quad = [1.0, 2.0] }
[entity.Material]
[entity.Portal]
partner = "door_b"
size = [1.0, 2.0]

[[entity]]
name = "door_b"
[entity.Transform]
position = [2.5, 1.0, 1.0]
rotation = [0.7071, 0.0, -0.7071, 0.0]
[entity.MeshRef]
mesh = { quad = [1.0, 2.0] }
[entity.Material]
[entity.Portal]
partner = "door_a"
size = [1.0, 2.0]

[[entity]]
name = "ball"
[entity.Transform]
position = [-0.8, 0.6, 0.5]
[entity.MeshRef]
mesh = { sphere = 0.5, segments = 16, rings = 8 }
[entity.Material]
metallic = 1.0
roughness = 0.05
[entity.Reflective]
mode = "cube"
[entity.ReflectionProbe]
resolution = 16

[[entity]]
name = "spot"
[entity.Transform]
position = [0.5, 2.5, 1.0]
rotation = { look = [0.0, -1.0, -0.5] }
[entity.PointLight]
intensity = 4.0
range = 6.0
spot_angle = 30.0
spot_blend = 0.2
shadows = true
shadow_resolution = 64

[[entity]]
name = "sparks"
[entity.Transform]
position = [0.0, 0.5, 0.0]
[entity.ParticleEmitter]
rate = 60.0
lifetime = [0.5, 1.0]
speed = [1.0, 2.0]
gravity = [0.0, -9.8, 0.0]
size = [0.1, 0.02]
color = [3.0, 1.0, 0.2, 1.0]
ground = 0.0
stretch = 0.02
blend = "additive"

[[entity]]
name = "smoke"
[entity.Transform]
position = [1.0, 0.5, 0.0]
[entity.ParticleEmitter]
rate = 20.0
size = [0.2, 0.6]
color = [0.6, 0.6, 0.6, 0.5]
blend = "alpha"
lit = true
softness = 0.2
sheet = [2, 2]
texture = { checker = [8, 2] }

[[entity]]
name = "statue"
[entity.Transform]
position = [-1.0, 0.5, 0.0]
[entity.MeshRef]
mesh = { box = [0.5, 1.0, 0.5] }
[entity.LevelOfDetail]
meshes = [{ box = [0.5, 1.0, 0.5] }, { sphere = 0.4 }]
distances = [4.0]

[[entity]]
name = "stain"
[entity.Transform]
position = [0.0, 0.0, 0.0]
rotation = { pitch = -90.0 }
scale = [2.0, 2.0, 1.0]
[entity.Decal]
texture = { checker = [8, 2] }
color = [0.2, 0.1, 0.05, 0.8]
region = [0.0, 0.0, 0.5, 0.5]
angle_fade = [40.0, 70.0]
layers = [0]
"""

_VALUES = ["0", "1", "-1", "0.5", "1e-30", "65505.0", "1e20", "3.4e38", "1e39", "nan", "inf", "-inf",
           "99999999999999999999", "true", "\"x\"", "\"cube\"", "\"door_a\"", "\"nobody\"", "[]", "[1.0]",
           "[1.0, 2.0]", "[0.0, 0.0, 0.0]", "[1.0, nan, 0.0]", "[1e39, 0.0, 0.0]", "[1.0, 1.0, 1.0, 1.0]",
           "[0.0, 0.0, 0.0, 0.0]", "[\"a\", 1, 2]", "{ yaw = 90 }", "{ look = [0.0, 0.0, 0.0] }", "{}",
           "{ box = [1.0, 0.0, 1.0] }", "{ quad = [0.0, 0.0] }", "{ sphere = -1.0 }", "{ file = \"gone.obj\" }",
           "{ checker = [0, 0] }", "{ checker = [100000, 2] }", "{ checker = [inf, 2] }", "{ checker = [8.5, 2] }",
           "{ box = [inf, 1.0, 1.0] }", "{ sphere = 1e39 }", "{ plane = [1.0, 1.0], uv_repeat = nan }",
           "{ sphere = 0.5, segments = 100000000 }", "{ file = \"gone.png\" }", "1979-05-27",
           "[" * 3000 + "]" * 3000, "{ a = " * 1000 + "1" + " }" * 1000, "[" * 20 + "1.0" + "]" * 20,
           "{ file = \"../outside/there.png\" }", "{ file = \"assets/loop.png\" }", "{ file = \"assets/fifo.obj\" }",
           "{ box = [-1.0, 1.0, 1.0] }", "{ plane = [1.0, 1.0], uv_repeat = \"x\" }", "{ checker = [2.5, 1] }",
           "{ panorama = \"assets/cut.exr\" }", "{ panorama = \"assets/plain.exr\", face_size = 4, layer = \"x\" }",
           "{ panorama = \"assets/plain.hdr\", face_size = 4, without_sun = true }"]
_NAMES = ["Transform", "MeshRef", "Material", "Mirror", "Portal", "Camera", "Skybox", "Emissive", "Slice",
          "PortalClone", "Nope", "transform", "ParticleEmitter", "LevelOfDetail", "AnimationEvents", "Decal",
          "FromDecal"]
_FIELDS = ["position", "rotation", "scale", "parent", "partner", "color", "colour", "mesh", "texture", "size",
           "enabled", "mode", "resolution", "refresh", "fov_y", "near", "far", "power", "spot_angle", "spot_blend",
           "bogus", "rate", "lifetime", "meshes", "distances", "sheet", "softness", "events", "region", "angle_fade",
           "layers", "depth_fade"]


CASE_SECONDS = 30.0  # a case still loading or rendering after this long has hung
OUTSIDE = "@OUTSIDE@"  # in a case's text: the folder outside the level's, made absolute when it runs


@dataclass
class LevelCase:
    text: str
    mutations: list[str]
    expect: str | None = None   # words the refusal must hold (a file case)
    texel: tuple[int, ...] | None = None  # or: it loads, and texel (0, 0) of the floor's map is this RGBA
    sky: float | None = None    # or: it loads, and every texel of the sky's faces is this grey

    def describe(self) -> str:
        return "; ".join(self.mutations)


@dataclass(frozen=True)
class FileCase:
    """A file a level may name: ``slot`` says where (the crate's ``mesh``, the floor's
    ``texture`` or ``normal_map``), ``spec`` the TOML value written there."""

    what: str
    slot: str
    spec: str
    expect: str | None = None
    texel: tuple[int, ...] | None = None
    sky: float | None = None


def _file(name: str) -> str:
    return f'{{ file = "{name}" }}'


def _sky(name: str, layer: str | None = None) -> str:
    """A sky's faces table naming the panorama ``name`` (and ``layer``), 4 texels a face."""
    return f'{{ panorama = "{name}", face_size = 4' + ("" if layer is None else f', layer = "{layer}"') + " }"


_OUT = "outside the level's folder"
FILE_CASES: tuple[FileCase, ...] = (
    FileCase("a symlink loop (texture)", "texture", _file("assets/loop.png"), "symlink loop"),
    FileCase("a symlink loop (mesh)", "mesh", _file("assets/loop.obj"), "symlink loop"),
    FileCase("a FIFO (texture)", "texture", _file("assets/fifo.png"), "is a FIFO"),
    FileCase("a FIFO (mesh)", "mesh", _file("assets/fifo.obj"), "is a FIFO"),
    FileCase("an OBJ naming a FIFO material library", "mesh", _file("assets/fifo_mtl.obj"), "is a FIFO"),
    FileCase("a directory", "texture", _file("assets/folder.png"), "is a directory"),
    FileCase("a link to /dev/zero", "normal_map", _file("assets/zero.png"), _OUT),
    FileCase("a PNG declaring 30000 x 30000", "texture", _file("assets/bomb.png"), "16384x16384"),
    FileCase("a PNG wider than GL takes", "texture", _file("assets/wide.png"), "16384x16384"),
    FileCase("a glTF nested 100,000 deep", "mesh", _file("assets/deep.gltf"), "nested too deeply"),
    FileCase("a glTF whose buffer is outside", "mesh", _file("assets/reach.gltf"), _OUT),
    FileCase("an OBJ whose image is outside", "mesh", _file("assets/reach.obj"), _OUT),
    FileCase("an OBJ face past its vertices", "mesh", _file("assets/index.obj"), "face index 9"),
    FileCase("a mesh file of random bytes", "mesh", _file("assets/noise.glb"), "cannot be parsed"),
    FileCase("an image of random bytes", "texture", _file("assets/noise.png"), "cannot be read as an image"),
    FileCase("../ outside, there", "texture", _file("../outside/there.png"), _OUT),
    FileCase("../ outside, not there", "texture", _file("../outside/gone.png"), _OUT),
    FileCase("an absolute path outside", "texture", _file(f"{OUTSIDE}/there.png"), _OUT),
    FileCase("a link leading outside", "texture", _file("assets/out.png"), _OUT),
    FileCase("a float TIFF with NaN", "texture", _file("assets/nan.tiff"), "NaN"),
    FileCase("a 32-bit integer TIFF", "texture", _file("assets/int32.tiff"), "32-bit integer"),
    FileCase("a value nested 3000 deep", "mesh", "[" * 3000 + "]" * 3000, "nested too deeply"),
    FileCase("a 16-bit grey PNG at 50%", "texture", _file("assets/grey16.png"), texel=(128, 128, 128, 255)),
    FileCase("a float TIFF at 0.5", "texture", _file("assets/half.tiff"), texel=(128, 128, 128, 255)),
    FileCase("a 16-bit flat normal map", "normal_map", _file("assets/flat16.png"),
             texel=(32768, 32768, 65535, 65535)),  # a normal map keeps a 16-bit file's values
    FileCase("a plain PNG", "texture", _file("assets/plain.png"), texel=(200, 100, 50, 255)),
    FileCase("a plain OBJ", "mesh", _file("assets/plain.obj")),
)

# Models and material maps (issue 41): what a model names obeys the level's rules, and no name
# reaches a FIFO through a library's own lookup; the Material's other map slots take files too.
MODEL_FILE_CASES: tuple[FileCase, ...] = (
    FileCase("an OBJ map whose bare name is a FIFO", "mesh", _file("assets/fallback.obj"), "does not exist"),
    FileCase("an OBJ whose mtllib comment names a FIFO", "mesh", _file("assets/comment.obj")),
    FileCase("a glTF image data: URI not base64", "mesh", _file("assets/data_uri.gltf"), "not base64"),
    FileCase("an MTL norm outside", "mesh", _file("assets/norm_out.obj"), _OUT),
    FileCase("an MTL past its size limit", "mesh", _file("assets/sparse.obj"), "more than"),
    FileCase("an MTL map with options", "mesh", _file("assets/options.obj")),
    FileCase("an OBJ with forward normals, no UVs, a continued line", "mesh", _file("assets/real.obj")),
    FileCase("a FIFO (emissive map)", "emissive_map", _file("assets/fifo.png"), "is a FIFO"),
    FileCase("a plain PNG (emissive map)", "emissive_map", _file("assets/plain.png"), texel=(200, 100, 50, 255)),
    FileCase("a 16-bit metallic-roughness map", "metallic_roughness_map", _file("assets/flat16.png"),
             texel=(32768, 32768, 65535, 65535)),
    FileCase("an image of random bytes (metallic-roughness map)", "metallic_roughness_map",
             _file("assets/noise.png"), "cannot be read as an image"),
    FileCase("a 16-bit occlusion map", "occlusion_map", _file("assets/flat16.png"), texel=(32768, 32768, 65535, 65535)),
    FileCase("a FIFO (occlusion map)", "occlusion_map", _file("assets/fifo.png"), "is a FIFO"),
)
FILE_CASES += MODEL_FILE_CASES

# Skies: a panorama a level's Skybox names (OpenEXR and Radiance files; make_sky_files).
SKY_FILE_CASES: tuple[FileCase, ...] = (
    FileCase("an EXR of random bytes", "faces", _sky("assets/noise.exr"), "not an OpenEXR file"),
    FileCase("an EXR cut in half", "faces", _sky("assets/cut.exr"), "cannot be read as OpenEXR"),
    FileCase("an EXR holding NaN", "faces", _sky("assets/nan.exr"), "hold NaN"),
    FileCase("an EXR past half floats", "faces", _sky("assets/bright.exr"), "past 65504"),
    FileCase("an EXR declaring 10000 x 5000", "faces", _sky("assets/huge.exr"), "10000 x 5000 pixels"),
    FileCase("an EXR without the layer named", "faces", _sky("assets/plain.exr", "night"), "has no layer 'night'"),
    FileCase("a FIFO (EXR sky)", "faces", _sky("assets/fifo.exr"), "is a FIFO"),
    FileCase("an .hdr of random bytes", "faces", _sky("assets/noise.hdr"), "not a Radiance .hdr file"),
    FileCase("an .hdr cut short", "faces", _sky("assets/cut.hdr"), "cut short"),
    FileCase("a layer of an .hdr", "faces", _sky("assets/plain.hdr", "night"), "only an OpenEXR"),
    FileCase("a panorama outside", "faces", _sky("../outside/there.exr"), _OUT),
    FileCase("a plain EXR sky", "faces", _sky("assets/plain.exr"), sky=0.5),
    FileCase("an EXR sky's layer", "faces", _sky("assets/plain.exr", "dusk"), sky=0.25),
    # (RGBE keeps 0.5 as mantissa 128, exponent 128, which Radiance reads as (128 + 0.5) / 256)
    FileCase("a plain .hdr sky", "faces", _sky("assets/plain.hdr"), sky=128.5 / 256),
)
FILE_CASES += SKY_FILE_CASES


def make_sky_files(assets: Path, outside: Path) -> None:
    """The panoramas SKY_FILE_CASES name, in ``assets`` (beside make_files' FIFOs) and ``outside``."""
    import OpenEXR

    from engine.assets.exr_image import save_exr
    from engine.assets.panorama import save_hdr

    grey = np.full((8, 16, 3), 0.5, np.float32)

    def exr(path: Path, channels: dict[str, np.ndarray], **header) -> None:
        header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage, **header}
        OpenEXR.File(header, {k: np.ascontiguousarray(v) for k, v in channels.items()}).write(str(path))

    def rgb(image: np.ndarray, prefix: str = "") -> dict[str, np.ndarray]:
        return {f"{prefix}{c}": image[..., i] for i, c in enumerate("RGB")}

    exr(assets / "plain.exr", {**rgb(grey.astype(np.float16)), **rgb(np.full_like(grey, 0.25, np.float16), "dusk.")})
    save_exr(outside / "there.exr", grey)
    save_hdr(assets / "plain.hdr", grey)
    noise = np.random.default_rng(27).integers(0, 256, 600, dtype=np.uint8).tobytes()
    (assets / "noise.exr").write_bytes(noise)
    (assets / "noise.hdr").write_bytes(noise)
    whole = (assets / "plain.exr").read_bytes()
    (assets / "cut.exr").write_bytes(whole[: len(whole) // 2])
    (assets / "cut.hdr").write_bytes(b"#?RADIANCE\n\n-Y 2 +X 4\n" + bytes(20))
    exr(assets / "nan.exr", rgb(np.full((4, 4, 3), np.nan, np.float32)))
    exr(assets / "bright.exr", rgb(np.full((4, 4, 3), 1e6, np.float32)))
    exr(assets / "huge.exr", rgb(np.ones((4, 4, 3), np.float16)),
        displayWindow=(np.array([0, 0], np.int32), np.array([9999, 4999], np.int32)))


def make_model_files(assets: Path) -> None:
    """The files MODEL_FILE_CASES name, in ``assets`` (beside make_files' FIFOs)."""
    from engine.assets.model_files import MAX_MTL_BYTES

    triangle = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
    (assets / "fallback.mtl").write_text("newmtl m\nKd 1 1 1\nmap_Kd textures/fifo.png\n")
    (assets / "fallback.obj").write_text("mtllib fallback.mtl\n" + triangle + "usemtl m\nf 1/1 2/2 3/3\n")
    (assets / "comment.obj").write_text("# mtllib fifo.mtl\n" + triangle + "f 1 2 3\n")
    (assets / "data_uri.gltf").write_text(json.dumps({
        "asset": {"version": "2.0"}, "images": [{"uri": "data:,fifo.png"}], "textures": [{"source": 0}],
        "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
        "meshes": [{"primitives": [{"attributes": {}, "material": 0}]}]}))
    (assets / "norm_out.mtl").write_text("newmtl m\nKd 1 1 1\nnorm ../../outside/there.png\n")
    (assets / "norm_out.obj").write_text("mtllib norm_out.mtl\n" + triangle + "usemtl m\nf 1/1 2/2 3/3\n")
    with open(assets / "sparse.mtl", "wb") as f:
        f.truncate(MAX_MTL_BYTES + 1)
    (assets / "sparse.obj").write_text("mtllib sparse.mtl\n" + triangle + "f 1 2 3\n")
    (assets / "options.mtl").write_text("newmtl m\nKd 1 1 1\nmap_Kd -s 2 2 1 -clamp on plain.png\n"
                                        "map_Bump -bm 0.5 -o 0.1 plain.png\n")
    (assets / "options.obj").write_text("mtllib options.mtl\n" + triangle + "usemtl m\nf 1/1 2/2 3/3\n")
    (assets / "real.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1/1 2/2/1 \\\n3/3/1\nvn 0 0 1\n")


def make_files(level_folder: Path, outside: Path) -> None:
    """The files FILE_CASES name: in ``level_folder / "assets"``, and ``outside``."""
    from PIL import Image

    assets = level_folder / "assets"
    assets.mkdir(parents=True, exist_ok=True)
    outside.mkdir(parents=True, exist_ok=True)
    Image.new("RGB", (4, 4), (255, 0, 0)).save(outside / "there.png")
    (outside / "there.bin").write_bytes(bytes(36))

    def link(name: str, target: str | Path) -> None:
        if not os.path.lexists(assets / name):
            (assets / name).symlink_to(target)

    link("loop.png", assets / "loop.png")
    link("loop.obj", assets / "loop2.obj")
    link("loop2.obj", assets / "loop.obj")
    link("zero.png", "/dev/zero")
    link("out.png", outside / "there.png")
    for name in ("fifo.png", "fifo.obj", "fifo.mtl", "fifo.exr"):
        if not os.path.lexists(assets / name):
            os.mkfifo(assets / name)
    (assets / "folder.png").mkdir(exist_ok=True)
    triangle = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
    (assets / "fifo_mtl.obj").write_text("mtllib fifo.mtl\n" + triangle + "f 1 2 3\n")
    (assets / "reach.mtl").write_text("newmtl m\nKd 1 1 1\nmap_Kd ../../outside/there.png\n")
    (assets / "reach.obj").write_text("mtllib reach.mtl\nusemtl m\n" + triangle + "vt 0 0\nf 1/1 2/1 3/1\n")
    (assets / "index.obj").write_text(triangle + "f 1 2 9\n")
    (assets / "plain.obj").write_text(triangle + "f 1 2 3\n")
    (assets / "deep.gltf").write_text("[" * 100_000 + "]" * 100_000)
    (assets / "reach.gltf").write_text('{"asset": {"version": "2.0"}, "buffers": [{"uri": "../../outside/there.bin", '
                                       '"byteLength": 36}]}')
    noise = np.random.default_rng(26).integers(0, 256, 600, dtype=np.uint8).tobytes()
    (assets / "noise.glb").write_bytes(noise)
    (assets / "noise.png").write_bytes(noise)
    _png(assets / "bomb.png", np.zeros((4, 4), np.uint8), 0, 8, (30000, 30000))
    _png(assets / "wide.png", np.zeros((4, 4), np.uint8), 0, 8, (16385, 4))
    _png(assets / "grey16.png", np.full((4, 4), 32768, np.uint16), 0, 16)
    _png(assets / "flat16.png", np.tile(np.array([32768, 32768, 65535], np.uint16), (4, 4, 1)), 2, 16)
    Image.fromarray(np.full((4, 4), 0.5, np.float32)).save(assets / "half.tiff")
    Image.fromarray(np.array([[0.5, np.nan]], np.float32)).save(assets / "nan.tiff")
    Image.fromarray(np.full((2, 2), 7, np.int32)).save(assets / "int32.tiff")
    Image.new("RGB", (4, 4), (200, 100, 50)).save(assets / "plain.png")
    make_model_files(assets)
    make_sky_files(assets, outside)


def _png(path: Path, pixels, colour_type: int, depth: int, declared: tuple[int, int] | None = None) -> None:
    """A PNG by hand (Pillow writes neither 48-bit RGB nor a header that lies about its size)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    h, w = pixels.shape[:2]
    raw = b"".join(b"\0" + pixels[y].astype(">u2" if depth == 16 else "u1").tobytes() for y in range(h))
    w, h = declared or (w, h)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, depth, colour_type, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


_SLOTS = {"mesh": "mesh = { box = [1.0, 1.0, 1.0] }", "texture": "texture = { checker = [32, 4] }",
          "normal_map": "texture = { checker = [32, 4] }", "emissive_map": "texture = { checker = [32, 4] }",
          "metallic_roughness_map": "texture = { checker = [32, 4] }",
          "occlusion_map": "texture = { checker = [32, 4] }", "faces": "face_size = 8"}


def file_level_case(case: FileCase) -> LevelCase:
    """BASE with ``case``'s file named in its slot (the crate's mesh, the floor's texture or
    normal map): one mutation, so the refusal must be the file's."""
    key = case.slot
    line = f"{key} = {case.spec}"
    if case.slot == "faces":  # (beside the sky's face_size)
        line = f"{_SLOTS['faces']}\n{line}"
    text = BASE.replace(_SLOTS[case.slot], line, 1)
    return LevelCase(text, [f"file case: {case.what}"], case.expect, case.texel, case.sky)


def mutate(rng: random.Random, text: str) -> tuple[str, str]:
    """One random change to a level's text, and what it was."""
    lines = text.splitlines()
    kind = rng.choice(["value", "value", "value", "table", "field", "name", "break", "drop"])
    assignments = [i for i, line in enumerate(lines) if re.match(r"^\w+ = ", line)]
    tables = [i for i, line in enumerate(lines) if line.startswith("[entity.")]
    if kind == "value":
        i = rng.choice(assignments)
        key = lines[i].split(" = ")[0]
        value = rng.choice(_VALUES)
        lines[i] = f"{key} = {value}"
        return "\n".join(lines), f"line {i + 1}: {key} = {value}"
    if kind == "table":
        i = rng.choice(tables)
        name = rng.choice(_NAMES)
        lines[i] = f"[entity.{name}]"
        return "\n".join(lines), f"line {i + 1}: table [entity.{name}]"
    if kind == "field":
        i = rng.choice([j for j in assignments if not lines[j].startswith("name")])
        field = rng.choice(_FIELDS)
        lines[i] = f"{field} = {lines[i].split(' = ', 1)[1]}"
        return "\n".join(lines), f"line {i + 1}: field renamed {field}"
    if kind == "name":
        names = [i for i, line in enumerate(lines) if line.startswith("name = ") and i > 2]
        i = rng.choice(names)
        new = rng.choice(["\"camera\"", "\"door_b\"", "\"\"", "\"x y\"", "5"])
        lines[i] = f"name = {new}"
        return "\n".join(lines), f"line {i + 1}: name = {new}"
    if kind == "break":
        i = rng.randrange(len(lines))
        lines[i] = lines[i][: rng.randrange(len(lines[i]) + 1)] + rng.choice(["[", "= ", "\"", "}", ""])
        return "\n".join(lines), f"line {i + 1}: broken"
    i = rng.choice(assignments + tables)
    dropped = lines.pop(i)
    return "\n".join(lines), f"line {i + 1}: dropped {dropped!r}"


def random_level_case(rng: random.Random) -> LevelCase:
    if rng.random() < 0.25:
        return file_level_case(rng.choice(FILE_CASES))
    text, done = BASE, []
    for _ in range(rng.randint(1, 3)):
        text, what = mutate(rng, text)
        done.append(what)
    return LevelCase(text, done)


class _Empty(Game):
    title = "level fuzz"

    def build(self, world) -> None:
        pass


class _Hung(Exception):
    pass


def render_checked(ctx, engine, framebuffer, problem: str | None = None) -> str | None:
    """``FRAMES`` frames of a fuzz case into ``framebuffer`` (at its size), each under the case
    deadline and checked (``frame_problem``): the first problem found (``problem`` if one was
    already), or None.  The level and model fuzzes share it."""
    try:
        for _ in range(FRAMES):
            with warnings.catch_warnings(), _deadline(CASE_SECONDS):
                warnings.simplefilter("ignore")
                engine.frame(1.0 / 60.0, Output(framebuffer, framebuffer.size))
            problem = problem or frame_problem(ctx, engine)
    except _Hung:
        return f"a frame hung for more than {CASE_SECONDS:g} s"
    except Exception as exc:  # noqa: BLE001
        return f"frame raised {type(exc).__name__}: {exc}\n{traceback.format_exc(limit=-3)}"
    return problem


def frame_problem(ctx, engine) -> str | None:
    """What is wrong with the frame just drawn: a GL error left, or a NaN or infinity in the
    HDR colour target, or a value past a half float's range (``hdr_problem``); None: nothing,
    or nothing drawn."""
    error = ctx.error
    if error != "GL_NO_ERROR":
        return f"ctx.error {error}"
    targets = engine.renderer.targets
    if targets is None:
        return None  # nothing drawn (no camera left): nothing to be NaN
    return hdr_problem(hdr_image(targets))


@contextlib.contextmanager
def _deadline(seconds: float) -> Iterator[None]:
    """Raise _Hung in the block after ``seconds`` (a SIGALRM timer; only on the main thread,
    where Python runs signal handlers: elsewhere there is no deadline)."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "setitimer"):
        yield
        return

    def hung(signum, frame):
        raise _Hung

    previous = signal.signal(signal.SIGALRM, hung)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


class LevelFuzzer:
    """One engine on an empty world; each case's level is spawned, rendered and deleted. Its
    files are written in ``folder / "level"``, FILE_CASES' files in ``folder / "level" /
    "assets"`` and ``folder / "outside"``."""

    def __init__(self, ctx, folder: Path) -> None:
        self.ctx = ctx
        self.folder = folder / "level"
        self.outside = folder / "outside"
        make_files(self.folder, self.outside)
        self.engine = Engine(_Empty(), ctx)
        self.world = self.engine.world
        self.capture = CaptureTarget(ctx, SIZE)
        self.refused = self.rendered = 0

    def close(self) -> None:
        self.capture.release()
        self.engine.close()

    def run(self, case: LevelCase, index: int = 0) -> str | None:
        """None when the case passed, else why it failed."""
        path = self.folder / f"case_{index}.toml"
        path.write_text(case.text.replace(OUTSIDE, str(self.outside.resolve())))
        try:
            with warnings.catch_warnings(), _deadline(CASE_SECONDS):
                warnings.simplefilter("ignore")
                names = load_level(path).spawn(self.world)
        except LevelError as exc:
            if str(path) not in str(exc):
                return f"LevelError without the file's name: {exc}"
            if self.world.entities():
                return f"refused, but left entities {self.world.entities()} in the world"
            if case.expect is not None and case.expect not in exc.reason:
                return f"refused, but without saying {case.expect!r}: {exc}"
            if case.texel is not None or case.sky is not None:
                return f"refused a file that should load: {exc}"
            self.refused += 1
            return None
        except _Hung:
            return f"loading hung for more than {CASE_SECONDS:g} s"
        except Exception as exc:  # noqa: BLE001 - any other kind is what the fuzz is looking for
            return f"load raised {type(exc).__name__}: {exc}\n{traceback.format_exc(limit=-3)}"
        problem = None
        if case.expect is not None:
            problem = f"loaded, but should be refused saying {case.expect!r}"
        elif case.texel is not None:
            problem = self._check_texel(names, case.texel)
        elif case.sky is not None:
            problem = self._check_sky(names, case.sky)
        try:
            problem = render_checked(self.ctx, self.engine, self.capture.framebuffer, problem)
        finally:
            for entity in list(self.world.entities()):
                self.world.delete_entity(entity)
        if problem is None:
            self.rendered += 1
        return problem

    def _check_texel(self, names: dict[str, int], texel: tuple[int, ...]) -> str | None:
        """The floor's texture or normal map holds ``texel`` at (0, 0): the file's value, scaled."""
        from components import Material

        material = self.world.try_get(names.get("floor", -1), Material)
        texture = material and (material.normal_map or material.emissive_map or material.metallic_roughness_map
                                or material.occlusion_map or material.texture)
        if texture is None:
            return "the floor has no texture or normal map"
        got = tuple(int(v) for v in texture.pixels[0, 0])
        if any(abs(a - b) > 1 for a, b in zip(got, texel, strict=True)):
            return f"texel (0, 0) is {got}, the file holds {texel}"
        return None



    def _check_sky(self, names: dict[str, int], grey: float) -> str | None:
        """The sky's faces are the panorama's grey everywhere (its every texel ``grey``)."""
        from components import Skybox

        sky = self.world.try_get(names.get("sky", -1), Skybox)
        if sky is None or sky.faces is None:
            return "the sky has no faces"
        faces = np.asarray(sky.faces)
        if not np.allclose(faces, grey, rtol=1e-3):
            return f"the sky's faces hold {faces.min():g} to {faces.max():g}, the file {grey:g}"
        return None


def fuzz_levels(ctx, folder: Path, cases: int, seed: int = 0, report=None) -> tuple[int, list, dict[str, int]]:
    """Run ``cases`` level cases (``benchmarks.fuzz_cases.run_cases``), their files in ``folder``."""
    from benchmarks.fuzz_cases import run_cases

    return run_cases(LevelFuzzer(ctx, folder), random_level_case, cases, seed, report)


def fuzz_files(ctx, folder: Path, report=None) -> tuple[int, list, dict[str, int]]:
    """Run every FILE_CASES case once (``benchmarks.fuzz_cases.run_cases``), their files in ``folder``."""
    from benchmarks.fuzz_cases import run_cases

    cases = iter(FILE_CASES)
    return run_cases(LevelFuzzer(ctx, folder), lambda rng: file_level_case(next(cases)), len(FILE_CASES), 0, report)
