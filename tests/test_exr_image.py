"""OpenEXR panoramas (engine/assets/exr_image.py): files written here with the OpenEXR
library's own writer (every compression, half, float and uint channels, tiles, parts, layers,
windows, primaries) read back to the colours written (exactly where the compression is
lossless); primaries converted to Rec. 709 as OpenColorIO's ACES config does (its published
matrix, not the engine's derivation); bad files refused naming the file and why; ``save_exr``'s
files read back by the library itself; and an .exr sky in a level file and the runner."""
from __future__ import annotations

import sys

import numpy as np
import OpenEXR
import pytest

from components import Skybox
from engine.assets.exr_image import COMPRESSIONS, load_exr, save_exr
from engine.assets.panorama import load_panorama, panorama_faces, sky_faces_from_file
from engine.core.errors import AssetError
from tests.support import look_from

LOSSLESS = ("none", "rle", "zips", "zip", "piz")
# OpenColorIO's ACES 1.x config, "ACES2065-1" to "Linear Rec.709 (sRGB)" (Bradford to D65).
OCIO_AP0_TO_REC709 = np.array([[2.52168618674388, -1.13413098823972, -0.387555198504164],
                               [-0.276479914229922, 1.37271908766826, -0.096239173438334],
                               [-0.0153780649660342, -0.152975335867399, 1.16835340083343]])
AP0 = (0.7347, 0.2653, 0.0, 1.0, 0.0001, -0.077, 0.32168, 0.33767)


def _compression(name: str):
    return getattr(OpenEXR, f"{'NO' if name == 'none' else name.upper()}_COMPRESSION")


def write(path, channels: dict[str, np.ndarray], compression: str = "zip", **header) -> str:
    """The OpenEXR library's writer: each channel a contiguous 2-D array (its dtype its type)."""
    header = {"compression": _compression(compression), "type": OpenEXR.scanlineimage, **header}
    OpenEXR.File(header, {k: np.ascontiguousarray(v) for k, v in channels.items()}).write(str(path))
    return str(path)


def rgb(image: np.ndarray, prefix: str = "") -> dict[str, np.ndarray]:
    return {f"{prefix}{c}": image[..., i] for i, c in enumerate("RGB")}


def smooth(height: int = 32, width: int = 64, dtype=np.float16) -> np.ndarray:
    """A sky-like image: smooth gradients of 0.05 to 20 across and down."""
    y, x = np.mgrid[0:height, 0:width] / np.array([height, width])[:, None, None]
    image = np.stack([0.05 + 20 * x * y, 0.5 + np.sin(3 * x) ** 2, 2.0 * (1 - y) + 0.1], axis=-1)
    return image.astype(dtype)


def noisy(height: int = 12, width: int = 20, seed: int = 0, dtype=np.float16) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (rng.uniform(0.0, 1.0, (height, width, 3)) * 10.0 ** rng.uniform(-3, 3, (height, width, 1))).astype(dtype)


# -- reading ---------------------------------------------------------------------------------
@pytest.mark.parametrize("compression", LOSSLESS)
@pytest.mark.parametrize("dtype", [np.float16, np.float32])
def test_a_lossless_exr_reads_back_exactly(tmp_path, compression, dtype):
    image = noisy(dtype=dtype)
    back = load_exr(write(tmp_path / "sky.exr", rgb(image), compression))
    assert back.dtype == np.float32 and back.shape == image.shape
    np.testing.assert_array_equal(back, image.astype(np.float32))


@pytest.mark.parametrize("compression,tolerance", [("pxr24", 1e-4), ("b44", 2e-3), ("b44a", 2e-3),
                                                   ("dwaa", 0.02), ("dwab", 0.02)])
def test_a_lossy_exr_reads_back_within_its_codecs_error(tmp_path, compression, tolerance):
    """PXR24 keeps 15 of a float's 23 mantissa bits; B44 and DWA (Poly Haven's) are lossy
    codecs: a smooth sky within ``tolerance`` of each value's size."""
    image = smooth(dtype=np.float32 if compression == "pxr24" else np.float16).astype(np.float32)
    back = load_exr(write(tmp_path / "sky.exr", rgb(image), compression))
    assert np.abs(back - image).max() / image.max() <= tolerance
    assert np.median(np.abs(back - image) / image) <= tolerance


def test_uint_channels_and_a_tiled_file_and_bottom_up_rows_read_as_written(tmp_path):
    counts = np.arange(6 * 10 * 3, dtype=np.uint32).reshape(6, 10, 3)
    np.testing.assert_array_equal(load_exr(write(tmp_path / "u.exr", rgb(counts))), counts.astype(np.float32))
    tiles = OpenEXR.TileDescription()
    tiles.xSize, tiles.ySize, tiles.mode = 8, 4, OpenEXR.ONE_LEVEL
    image = noisy(13, 21)
    path = write(tmp_path / "t.exr", rgb(image), "piz", type=OpenEXR.tiledimage, tiles=tiles)
    np.testing.assert_array_equal(load_exr(path), image.astype(np.float32))
    path = write(tmp_path / "d.exr", rgb(image), "zip", lineOrder=OpenEXR.DECREASING_Y)
    np.testing.assert_array_equal(load_exr(path), image.astype(np.float32))   # row 0 still the top


def test_the_colour_part_or_layer_is_found_and_alpha_and_others_left_out(tmp_path):
    image, other = noisy(seed=1), noisy(seed=2)
    depth = OpenEXR.Part({"type": OpenEXR.scanlineimage, "compression": OpenEXR.ZIP_COMPRESSION},
                         {"Z": np.ascontiguousarray(image[..., 0].astype(np.float32))}, name="depth")
    beauty = OpenEXR.Part({"type": OpenEXR.scanlineimage, "compression": OpenEXR.ZIP_COMPRESSION},
                          {k: np.ascontiguousarray(v) for k, v in {**rgb(image), "A": image[..., 0]}.items()},
                          name="beauty")
    fill = OpenEXR.Part({"type": OpenEXR.scanlineimage, "compression": OpenEXR.PIZ_COMPRESSION},
                        {k: np.ascontiguousarray(v) for k, v in rgb(other).items()}, name="fill")
    OpenEXR.File([depth, beauty, fill]).write(str(tmp_path / "parts.exr"))
    np.testing.assert_array_equal(load_exr(tmp_path / "parts.exr"), image.astype(np.float32))
    np.testing.assert_array_equal(load_exr(tmp_path / "parts.exr", layer="fill"), other.astype(np.float32))
    path = write(tmp_path / "layers.exr", {**rgb(image, "sky."), **rgb(other), "A": other[..., 0]})
    np.testing.assert_array_equal(load_exr(path), other.astype(np.float32))
    np.testing.assert_array_equal(load_exr(path, layer="sky"), image.astype(np.float32))
    with pytest.raises(AssetError, match=r"layers\.exr.*has no layer 'ground'.*sky\.R"):
        load_exr(path, layer="ground")
    grey = write(tmp_path / "y.exr", {"Y": image[..., 1]})
    np.testing.assert_array_equal(load_exr(grey), np.repeat(image[..., 1:2], 3, axis=-1).astype(np.float32))


def test_the_display_window_is_the_image_and_the_data_window_sits_in_it(tmp_path):
    """Data at (3, 2) to (22, 13) in a display window (0, 0) to (29, 15), and data partly
    outside one: placed by its coordinates, black where there is none, cut at the edge."""
    image = noisy(12, 20)
    path = write(tmp_path / "w.exr", rgb(image), dataWindow=(np.array([3, 2], np.int32), np.array([22, 13], np.int32)),
                 displayWindow=(np.array([0, 0], np.int32), np.array([29, 15], np.int32)))
    want = np.zeros((16, 30, 3), np.float32)
    want[2:14, 3:23] = image
    np.testing.assert_array_equal(load_exr(path), want)
    path = write(tmp_path / "x.exr", rgb(image), dataWindow=(np.array([-5, 4], np.int32), np.array([14, 15], np.int32)),
                 displayWindow=(np.array([0, 0], np.int32), np.array([9, 9], np.int32)))
    want = np.zeros((10, 10, 3), np.float32)
    want[4:10, 0:10] = image[0:6, 5:15]
    np.testing.assert_array_equal(load_exr(path), want)


def test_aces_and_other_primaries_are_converted_to_rec709(tmp_path):
    """An ACES2065-1 file (AP0 primaries, its white near D60): each colour times OpenColorIO's
    AP0 to Rec. 709 matrix (to 1e-5), the file's white grey, colours outside Rec. 709 clipped
    to 0; a file that names Rec. 709's own primaries is untouched."""
    image = smooth(dtype=np.float32)
    image[0, 0] = (1.0, 1.0, 1.0)   # the white point: grey in Rec. 709
    back = load_exr(write(tmp_path / "aces.exr", rgb(image), chromaticities=AP0))
    want = np.maximum(image.astype(np.float64) @ OCIO_AP0_TO_REC709.T, 0.0)
    assert (image.astype(np.float64) @ OCIO_AP0_TO_REC709.T).min() < -0.01   # (some out of gamut, clipped)
    np.testing.assert_allclose(back, want, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(back[0, 0], (1.0, 1.0, 1.0), atol=1e-5)
    rec709 = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)
    np.testing.assert_array_equal(load_exr(write(tmp_path / "709.exr", rgb(image), chromaticities=rec709)), image)


def _truncated(tmp_path):
    data = open(write(tmp_path / "whole.exr", rgb(noisy())), "rb").read()
    (tmp_path / "cut.exr").write_bytes(data[:len(data) // 2])
    return tmp_path / "cut.exr"


@pytest.mark.parametrize("make,words", [
    (lambda p: (p / "a.exr").write_bytes(b"#?RADIANCE\n") and p / "a.exr", "not an OpenEXR file"),
    (_truncated, "cannot be read as OpenEXR"),
    (lambda p: write(p / "z.exr", {"Z": np.ones((4, 4), np.float32)}), "no an image part with channels R, G and B"),
    (lambda p: write(p / "n.exr", rgb(np.full((4, 4, 3), np.nan, np.float32))), "16 pixels hold NaN"),
    (lambda p: write(p / "b.exr", rgb(np.full((4, 4, 3), 1e6, np.float32))), "past 65504"),
    (lambda p: write(p / "c.exr", rgb(np.ones((20, 4, 3), np.float16)), envmap=OpenEXR.ENVMAP_CUBE),
     "cube-map environment .* of 4 x 20 pixels; its six faces stacked are N x 6N"),
    (lambda p: write(p / "h.exr", rgb(np.ones((4, 4, 3), np.float16)),
                     displayWindow=(np.array([0, 0], np.int32), np.array([9999, 4999], np.int32))),
     "10000 x 5000 pixels"),
    (lambda p: p / "none.exr", "no such file"),
])
def test_a_bad_exr_file_is_refused_naming_it_and_why(tmp_path, make, words):
    path = make(tmp_path)
    with pytest.raises(AssetError, match="OpenEXR file .*" + words.replace("(", r"\(")):
        load_exr(path)


def test_without_the_library_an_exr_is_refused_naming_the_package(tmp_path, monkeypatch):
    path = write(tmp_path / "sky.exr", rgb(noisy()))
    monkeypatch.setitem(sys.modules, "OpenEXR", None)
    with pytest.raises(AssetError, match="needs the 'openexr' package"):
        load_exr(path)


# -- writing ---------------------------------------------------------------------------------
@pytest.mark.parametrize("compression", COMPRESSIONS)
def test_save_exr_writes_what_the_library_reads(tmp_path, compression):
    """Every compression, read back by the OpenEXR library itself (not ``load_exr``): channels
    R, G, B of half floats, Rec. 709 recorded; lossless ones equal to the colours rounded to
    half floats; ``half=False`` keeps float32 exactly."""
    image = smooth(dtype=np.float64)
    path = save_exr(tmp_path / "out.exr", image, compression=compression)
    exr = OpenEXR.File(str(path), separate_channels=True)
    header = exr.header()
    assert str(header["compression"]).endswith(f"{'NO' if compression == 'none' else compression.upper()}_COMPRESSION")
    np.testing.assert_allclose(header["chromaticities"], (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290),
                               atol=1e-6)
    back = np.stack([exr.channels()[c].pixels for c in "RGB"], axis=-1)
    assert back.dtype == np.float16
    if compression in LOSSLESS + ("pxr24",):
        np.testing.assert_array_equal(back, image.astype(np.float16))
    else:
        assert np.median(np.abs(back - image) / image) < 0.02
    full = save_exr(tmp_path / "full.exr", image, half=False)
    back = np.stack([OpenEXR.File(str(full), separate_channels=True).channels()[c].pixels for c in "RGB"], axis=-1)
    np.testing.assert_array_equal(back, image.astype(np.float32))


@pytest.mark.parametrize("image,kwargs,words", [
    (np.zeros((4, 4)), {}, "an \\(height, width, 3\\) image"),
    (np.full((2, 2, 3), np.nan), {}, "colours must be finite"),
    (np.full((2, 2, 3), 1e5), {}, "colours past 65504 .*give half=False"),
    (np.ones((2, 2, 3)), {"compression": "lzw"}, "compression must be one of"),
    (np.ones((2, 2, 3)), {"half": 1}, "half must be True or False"),
])
def test_save_exr_refuses_what_it_cannot_write(tmp_path, image, kwargs, words):
    with pytest.raises(ValueError, match="save_exr: " + words):
        save_exr(tmp_path / "bad.exr", image, **kwargs)


# -- as a sky --------------------------------------------------------------------------------
def test_an_exr_panorama_makes_the_faces_its_colours_make(tmp_path):
    image = smooth(16, 32, np.float32)
    faces = sky_faces_from_file(write(tmp_path / "sky.exr", rgb(image)), face_size=8, yaw=30.0)
    np.testing.assert_array_equal(faces, panorama_faces(image, 8, 30.0))
    assert faces.source == {"panorama": str((tmp_path / "sky.exr").resolve()), "face_size": 8, "yaw": 30.0}


# OpenEXR's cube-map layout as ImfEnvmap.h draws it: each face's corners (top left, top right,
# bottom left, bottom right) as the cube's vertices, vertex v at (bit 0, bit 1, bit 2) of v for
# (x, y, z), 1 for + and 0 for -; the faces +X, -X, +Y, -Y, +Z, -Z from the top.
CUBE_CORNERS = ((3, 7, 1, 5), (6, 2, 4, 0), (6, 7, 2, 3), (0, 1, 4, 5), (7, 6, 5, 4), (2, 3, 0, 1))


def cube_map_of(function, size: int) -> np.ndarray:
    """A cube-map environment (size x 6 size) whose pixels hold ``function`` of their
    direction: each face's pixel centres spread evenly between its corner vertices (the first
    and last on the cube's edges), as the header's diagram places them."""
    vertex = np.array([[1.0 if v >> axis & 1 else -1.0 for axis in range(3)] for v in range(8)])
    t = np.linspace(0.0, 1.0, size)
    across, down = np.meshgrid(t, t)
    faces = []
    for top_left, top_right, bottom_left, bottom_right in CUBE_CORNERS:
        top = vertex[top_left] * (1 - across[..., None]) + vertex[top_right] * across[..., None]
        bottom = vertex[bottom_left] * (1 - across[..., None]) + vertex[bottom_right] * across[..., None]
        point = top * (1 - down[..., None]) + bottom * down[..., None]
        faces.append(function(point / np.linalg.norm(point, axis=-1, keepdims=True)))
    return np.concatenate(faces, axis=0)


def test_a_cube_map_exr_makes_the_sky_its_faces_hold(tmp_path):
    """An OpenEXR cube-map environment (``envmap`` cube, written by the library) whose pixels
    hold a colour linear in their direction: the Skybox faces made from it hold that colour of
    each face texel's own direction (``engine.core.cube_faces``), so every face is where
    OpenEXR's layout puts it, the right way round; turned by yaw as a panorama is."""
    def colour(d):
        return 1.0 + 0.5 * d

    path = write(tmp_path / "cube.exr", rgb(cube_map_of(colour, 32).astype(np.float32)), envmap=OpenEXR.ENVMAP_CUBE)
    from engine.core.cube_faces import face_directions

    faces = sky_faces_from_file(path, face_size=16)
    for face in range(6):
        np.testing.assert_allclose(faces[face], colour(face_directions(face, 16)), atol=0.02)
    turned = sky_faces_from_file(path, face_size=16, yaw=90.0)
    np.testing.assert_allclose(turned, panorama_faces(load_panorama(path), 16, 90.0), atol=1e-6)
    assert not np.allclose(turned, faces, atol=0.1)


def latlong_of(function, height: int, width: int) -> np.ndarray:
    """A latlong environment of ``function(direction)`` as ``ImfEnvmap.cpp`` maps its pixels:
    latitude +pi/2 on the first row to -pi/2 on the last, longitude +pi on the first column
    to -pi on the last, direction (sin lon cos lat, sin lat, cos lon cos lat)."""
    lat = -np.pi * (np.arange(height) / (height - 1) - 0.5)
    lon = -2.0 * np.pi * (np.arange(width) / (width - 1) - 0.5)
    lat, lon = np.meshgrid(lat, lon, indexing="ij")
    d = np.stack([np.sin(lon) * np.cos(lat), np.sin(lat), np.cos(lon) * np.cos(lat)], axis=-1)
    return function(d)


def test_a_latlong_exr_makes_the_sky_its_directions_hold_as_its_cube_twin_does(tmp_path):
    """An OpenEXR latlong environment (``envmap`` latlong) holding a colour linear in each
    pixel's direction, as OpenEXR's ``ImfEnvmap`` maps them (its middle column +Z, where the
    engine's panoramas have -Z): the Skybox faces made from it hold each face texel's own
    direction's colour, and equal those made from the same environment as a cube map.  A file
    without the attribute is a plain image, taken in the engine's wrap as an ``.hdr`` is."""
    def colour(d):
        return 1.0 + 0.5 * d

    from engine.core.cube_faces import face_directions

    image = latlong_of(colour, 64, 128).astype(np.float32)
    latlong = write(tmp_path / "latlong.exr", rgb(image), envmap=OpenEXR.ENVMAP_LATLONG)
    cube = write(tmp_path / "cube.exr", rgb(cube_map_of(colour, 32).astype(np.float32)), envmap=OpenEXR.ENVMAP_CUBE)
    faces = sky_faces_from_file(latlong, face_size=16)
    for face in range(6):
        np.testing.assert_allclose(faces[face], colour(face_directions(face, 16)), atol=0.02)
    np.testing.assert_allclose(faces, sky_faces_from_file(cube, face_size=16), atol=0.02)
    plain = write(tmp_path / "plain.exr", rgb(image))
    np.testing.assert_array_equal(load_panorama(plain), image)
    assert not np.allclose(sky_faces_from_file(plain, face_size=16), faces, atol=0.1)


def test_a_level_file_and_the_runner_take_an_exr_sky(scene, tmp_path):
    from engine.assets.level_read import load_level
    from engine.assets.level_save import save_level
    from engine.core.world import World

    image = smooth(16, 32, np.float32)
    write(tmp_path / "sky.exr", rgb(image), "piz")
    level = tmp_path / "level.toml"
    level.write_text('[level]\nname = "exr"\n[[entity]]\nname = "sky"\n'
                     'Skybox = { faces = { panorama = "sky.exr", face_size = 8 } }\n')
    world = World()
    load_level(level).spawn(world)
    np.testing.assert_array_equal(world.query_one(Skybox)[0][1].faces, panorama_faces(image, 8))
    save_level(world, tmp_path / "saved.toml")
    assert 'panorama = "sky.exr"' in (tmp_path / "saved.toml").read_text()
    runner = scene(lambda world: look_from(world, (0.0, 0.0, 0.0), (0.0, 0.0, -1.0)), (16, 16))
    runner.engine.start_sky(None, panorama=str(tmp_path / "sky.exr"), panorama_yaw=0.0)
    runner.frame()
    sky = runner.world.query_one(Skybox)[0][1]
    assert sky.faces.source["panorama"] == str((tmp_path / "sky.exr").resolve())
    np.testing.assert_allclose(sky.faces, panorama_faces(image, 512), rtol=1e-6)


def test_a_level_file_names_an_exr_layer_and_writes_it_back(tmp_path):
    """``layer`` in a sky's faces table reads that layer (a channel prefix, or a part of that
    name), not the file's first colours, and a saved level keeps it; a layer the file lacks,
    a layer of an .hdr file (which has none) and a layer that is not a name are refused,
    naming the file or the field."""
    from engine.assets.level_read import LevelError, load_level
    from engine.assets.level_save import save_level
    from engine.core.world import World

    image, other = smooth(16, 32, np.float32), smooth(16, 32, np.float32)[:, ::-1] * 0.5
    write(tmp_path / "sky.exr", {**rgb(image, "night."), **rgb(other)}, "zip")
    level = tmp_path / "level.toml"

    def faces_of(table: str):
        level.write_text(f'[level]\nname = "exr"\n[[entity]]\nname = "sky"\nSkybox = {{ faces = {table} }}\n')
        world = World()
        load_level(level).spawn(world)
        return world, world.query_one(Skybox)[0][1].faces

    world, faces = faces_of('{ panorama = "sky.exr", face_size = 8, layer = "night" }')
    np.testing.assert_array_equal(faces, panorama_faces(image, 8))
    assert faces.source["layer"] == "night"
    _, first = faces_of('{ panorama = "sky.exr", face_size = 8 }')
    np.testing.assert_array_equal(first, panorama_faces(np.ascontiguousarray(other), 8))
    save_level(world, tmp_path / "saved.toml")
    assert 'layer = "night"' in (tmp_path / "saved.toml").read_text()
    again = World()
    load_level(tmp_path / "saved.toml").spawn(again)
    np.testing.assert_array_equal(again.query_one(Skybox)[0][1].faces, panorama_faces(image, 8))
    with pytest.raises(LevelError, match=r"Skybox\.faces: OpenEXR file .*sky\.exr.*has no layer 'day'.*night\.R"):
        faces_of('{ panorama = "sky.exr", face_size = 8, layer = "day" }')
    with pytest.raises(LevelError, match=r"Skybox\.faces: sky panorama: layer must be a non-empty string"):
        faces_of('{ panorama = "sky.exr", face_size = 8, layer = 3 }')
    from engine.assets.panorama import save_hdr
    save_hdr(tmp_path / "sky.hdr", image)
    with pytest.raises(LevelError, match=r"Skybox\.faces: panorama file .*sky\.hdr.*layer 'night' given, but only"):
        faces_of('{ panorama = "sky.hdr", face_size = 8, layer = "night" }')


@pytest.mark.parametrize("compression", ["none", "rle", "zip", "piz", "pxr24", "b44", "dwaa"])
def test_a_corrupt_exr_is_read_or_refused_never_anything_else(tmp_path, compression):
    """Bytes past the magic number changed at random (a header's names and attributes, the
    offset table, the compressed pixels) or the file cut short, 30 times: each file reads as
    finite, non-negative colours (pixels changed where nothing checks them) or is refused with
    an AssetError naming it; no other exception (the library's attributes as a corrupt header
    leaves them: names that are not text, values of other types, were once a TypeError)."""
    import random

    data = bytearray(open(save_exr(tmp_path / "sky.exr", smooth(24, 40, np.float64), compression=compression),
                          "rb").read())
    rng, refused = random.Random(compression), 0
    for case in range(30):
        bad = bytearray(data)
        if case % 3 == 0:
            bad = bad[:rng.randrange(4, len(bad))]
        else:
            for _ in range(rng.randint(1, 8)):
                bad[rng.randrange(4, len(bad))] = rng.randrange(256)
        (tmp_path / "bad.exr").write_bytes(bytes(bad))
        try:
            image = load_exr(tmp_path / "bad.exr")
        except AssetError as exc:
            assert "bad.exr" in str(exc)
            refused += 1
            continue
        assert image.dtype == np.float32 and np.isfinite(image).all() and image.min() >= 0.0
    assert refused >= 10   # (every cut file among them)
    # Two the random flips found: the chromaticities attribute given another type's name (the
    # library hands an opaque value), a channel's name not text.
    for old, new in ((b"chromaticities\0chromaticities\0", b"chromaticities\0xhromaticities\0"),
                     (b"chlist\0", None)):
        bad = bytearray(data)
        at = bad.index(old)
        if new is None:   # the first channel's name, just after the list's size
            bad[at + len(old) + 4] = 0xF8
        else:
            bad[at:at + len(old)] = new
        (tmp_path / "bad.exr").write_bytes(bytes(bad))
        with pytest.raises(AssetError, match="bad.exr"):
            load_exr(tmp_path / "bad.exr")
