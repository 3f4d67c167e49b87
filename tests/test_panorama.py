"""Panorama skies (engine/assets/panorama.py): Radiance .hdr files written here by an encoder
of the tests' own (flat and run-length, RGBE and XYZE, every orientation) read back to the
value Radiance's colr_color gives each byte; bad files refused naming the file and the
reason; faces of an analytic panorama holding its function direction by direction (turned by
``yaw``); the sky drawn from it and the light it gives a ball (a linear sky's irradiance in
closed form: pi a + 2 pi / 3 b.n); level files and the runner's --panorama."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from components import Skybox
from engine.assets.panorama import SkyFaces, load_hdr, panorama_faces, sky_faces_from_file
from engine.core.errors import AssetError
from tests.support import grey_ball_under_sky, look_from, srgb_to_linear


# -- an encoder of the tests' own -----------------------------------------------------------
def _runs(channel: np.ndarray) -> bytes:
    """One channel of a scanline in the new run-length encoding: runs of 3 or more equal bytes
    as (128 + n, byte), the rest as literal stretches of up to 128."""
    out, i, n = bytearray(), 0, len(channel)
    while i < n:
        j = i
        while j < n and j - i < 127 and channel[j] == channel[i]:
            j += 1
        if j - i >= 3:
            out += bytes([128 + j - i, int(channel[i])])
            i = j
            continue
        k = i
        while k < n and k - i < 128 and not (k + 2 < n and channel[k] == channel[k + 1] == channel[k + 2]):
            k += 1
        out += bytes([k - i]) + bytes(channel[i:k].tolist())
        i = k
    return bytes(out)


def write_hdr(path: Path, rgbe: np.ndarray, rle: bool = True, resolution: str | None = None,
              header: str = "FORMAT=32-bit_rle_rgbe\n") -> Path:
    """``rgbe`` (height, width, 4) uint8 as a Radiance file, rows as given."""
    height, width = rgbe.shape[:2]
    body = bytearray(f"#?RADIANCE\n# written by the tests\n{header}\n"
                     f"{resolution or f'-Y {height} +X {width}'}\n".encode())
    for row in rgbe:
        if rle:
            body += bytes([2, 2, width >> 8, width & 255])
            for channel in range(4):
                body += _runs(row[:, channel])
        else:
            body += row.tobytes()
    path.write_bytes(bytes(body))
    return path


def expected(rgbe: np.ndarray) -> np.ndarray:
    """What each RGBE pixel holds: (m + 0.5) 2^(e - 136), nothing where e is 0."""
    e = rgbe[..., 3:4].astype(np.float64)
    return np.where(e > 0, (rgbe[..., :3] + 0.5) * 2.0 ** (e - 136.0), 0.0)


def random_rgbe(height: int, width: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    rgbe = np.concatenate([rng.integers(0, 256, (height, width, 3)), rng.integers(118, 140, (height, width, 1))], -1)
    rgbe[0, :12] = (40, 50, 60, 130)     # a run, for the encoder's run bytes
    rgbe[1, 3] = (0, 0, 0, 0)            # black
    return rgbe.astype(np.uint8)


# -- reading ---------------------------------------------------------------------------------
@pytest.mark.parametrize("rle,width", [(True, 40), (False, 40), (True, 7)])   # (7: too narrow to run-length encode)
def test_an_hdr_file_reads_as_radiance_reads_each_byte(tmp_path, rle, width):
    rgbe = random_rgbe(6, width)
    pixels = load_hdr(write_hdr(tmp_path / "sky.hdr", rgbe, rle=rle and width >= 8))
    assert pixels.dtype == np.float32 and pixels.shape == (6, width, 3)
    np.testing.assert_array_equal(pixels, expected(rgbe).astype(np.float32))


def test_exposure_divides_and_xyze_turns_to_rgb(tmp_path):
    rgbe = random_rgbe(4, 16, seed=1)
    halved = load_hdr(write_hdr(tmp_path / "a.hdr", rgbe, header="FORMAT=32-bit_rle_rgbe\nEXPOSURE=4\nEXPOSURE=0.5\n"))
    np.testing.assert_allclose(halved, expected(rgbe) / 2.0, rtol=1e-6)
    xyz = load_hdr(write_hdr(tmp_path / "b.hdr", rgbe, header="FORMAT=32-bit_rle_xyze\n"))
    matrix = np.array([[3.2409699419, -1.5373831776, -0.4986107603], [-0.9692436363, 1.8759675015, 0.0415550574],
                       [0.0556300797, -0.2039769589, 1.0569715142]])   # CIE XYZ to linear Rec. 709 (OpenColorIO's)
    np.testing.assert_allclose(xyz, np.maximum(expected(rgbe) @ matrix.T, 0.0), rtol=1e-5, atol=1e-30)


@pytest.mark.parametrize("resolution,flip", [("+Y 5 +X 9", (True, False)), ("-Y 5 -X 9", (False, True)),
                                             ("+Y 5 -X 9", (True, True))])
def test_every_row_order_reads_with_row_0_at_the_top(tmp_path, resolution, flip):
    rgbe = random_rgbe(5, 9, seed=2)
    pixels = load_hdr(write_hdr(tmp_path / "o.hdr", rgbe, resolution=resolution))
    want = expected(rgbe)
    want = want[::-1] if flip[0] else want
    want = want[:, ::-1] if flip[1] else want
    np.testing.assert_array_equal(pixels, want.astype(np.float32))


def _bad(tmp_path, name: str, data: bytes) -> Path:
    path = tmp_path / name
    path.write_bytes(data)
    return path


@pytest.mark.parametrize("data,reason", [
    (b"P6\n4 4\n255\n", "not a Radiance .hdr file"),
    (b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n", "header never ends"),
    (b"#?RADIANCE\nFORMAT=16-bit_nonsense\n\n-Y 1 +X 1\n\x00\x00\x00\x00", "neither 32-bit_rle_rgbe"),
    (b"#?RADIANCE\n\n+X 4 -Y 2\n" + bytes(32), "X first"),
    (b"#?RADIANCE\n\n-Y 20000 +X 20000\n", "a panorama may be 1 to 16384"),
    (b"#?RADIANCE\n\n-Y 8192 +X 16384\n\x02\x02\x40\x00", "more than the 33554432"),
    (b"#?RADIANCE\n\n-Y 2 +X 4\n" + bytes(20), "cut short"),
    (b"#?RADIANCE\nEXPOSURE=-1\n\n-Y 1 +X 1\n\x10\x10\x10\x80", "EXPOSURE lines multiply"),
    (b"#?RADIANCE\n\n-Y 1 +X 4\n\x10\x10\x10\x80\x01\x01\x01\x02" + bytes(8), "old run-length encoding"),
    (b"#?RADIANCE\n\n-Y 1 +X 8\n\x02\x02\x00\x08\xff\x10", "passes its width"),
])
def test_a_bad_hdr_file_is_refused_naming_it_and_why(tmp_path, data, reason):
    path = _bad(tmp_path, "bad.hdr", data)
    with pytest.raises(AssetError, match=f"panorama file .*bad.hdr.*{reason}"):
        load_hdr(path)


def test_a_missing_file_is_refused_naming_it(tmp_path):
    with pytest.raises(AssetError, match="panorama file .*nothing.hdr.*no such file"):
        sky_faces_from_file(tmp_path / "nothing.hdr")


# -- faces ------------------------------------------------------------------------------------
def sky_function(d: np.ndarray) -> np.ndarray:
    """A sky linear in the direction: each channel 0.5 + 0.4 times one of its components."""
    return 0.5 + 0.4 * d


def analytic_panorama(height: int = 256) -> np.ndarray:
    """``sky_function`` as an equirectangular image: column u's longitude (u - 0.5) 2 pi from
    ahead (-Z) towards +X, row v's latitude (0.5 - v) pi (the top straight up)."""
    width = 2 * height
    lon = ((np.arange(width) + 0.5) / width - 0.5) * 2.0 * np.pi
    lat = (0.5 - (np.arange(height) + 0.5) / height) * np.pi
    lat, lon = np.meshgrid(lat, lon, indexing="ij")
    d = np.stack([np.sin(lon) * np.cos(lat), np.sin(lat), -np.cos(lon) * np.cos(lat)], -1)
    return sky_function(d).astype(np.float32)


def gl_face_direction(face: int, size: int) -> np.ndarray:
    """The texel centres' directions of a cube face as the OpenGL specification's face table
    gives them (major axis, sc, tc: direction = major + sc s + tc t), written out here."""
    c = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    t, s = np.meshgrid(c, c, indexing="ij")
    one = np.ones_like(s)
    d = [np.stack([one, -t, -s], -1), np.stack([-one, -t, s], -1), np.stack([s, one, t], -1),
         np.stack([s, -one, -t], -1), np.stack([s, -t, one], -1), np.stack([-s, -t, -one], -1)][face]
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


@pytest.mark.parametrize("yaw", [0.0, 90.0, -35.0])
def test_each_face_texel_holds_the_panorama_where_it_looks(yaw):
    faces = panorama_faces(analytic_panorama(), 32, yaw)
    turn = math.radians(yaw)
    for face in range(6):
        d = gl_face_direction(face, 32)
        # yaw turns the image to the left seen from above: a texel looking along d shows what
        # the image holds along d turned back to the right.
        looked = np.stack([d[..., 0] * math.cos(turn) - d[..., 2] * math.sin(turn), d[..., 1],
                           d[..., 0] * math.sin(turn) + d[..., 2] * math.cos(turn)], -1)
        np.testing.assert_allclose(faces[face], sky_function(looked), atol=0.006)
    if yaw == 90.0:   # the image's middle (ahead, -Z: blue 0.1) comes round to the left (-X)
        assert faces[1][16, 16, 2] == pytest.approx(0.1, abs=0.02)


def test_a_small_sun_in_a_large_panorama_keeps_its_light_in_small_faces():
    """Each face texel averages its footprint: a 2 x 2-pixel sun in a 2048-wide panorama keeps
    its whole light in 16-texel faces (the faces' sum weighed by each texel's solid angle)."""
    height = 1024
    image = np.zeros((height, 2 * height, 3), np.float32)
    image[300:302, 700:702] = 1000.0
    lat = (0.5 - (np.arange(height) + 0.5) / height) * np.pi
    in_image = float((image[..., 0] * np.cos(lat)[:, None]).sum() * (np.pi / height) * (2 * np.pi / (2 * height)))
    faces = panorama_faces(image, 16)
    c = (np.arange(16) + 0.5) / 16 * 2 - 1
    t, s = np.meshgrid(c, c, indexing="ij")
    solid = (2.0 / 16) ** 2 / (1.0 + s * s + t * t) ** 1.5
    in_faces = float(sum((faces[f][..., 0] * solid).sum() for f in range(6)))
    assert in_faces == pytest.approx(in_image, rel=0.1)
    assert np.count_nonzero(faces[..., 0] > 0) <= 8   # (not smeared over the sky)


def test_faces_from_a_file_remember_it_and_a_view_does_not(tmp_path):
    path = write_hdr(tmp_path / "sky.hdr", random_rgbe(8, 16))
    faces = sky_faces_from_file(path, 8, 15.0)
    assert isinstance(faces, SkyFaces) and faces.shape == (6, 8, 8, 3)
    assert faces.source == {"panorama": str(path.resolve()), "face_size": 8, "yaw": 15.0}
    assert faces[0].source is None and (faces * 2).source is None
    sky = Skybox(faces=faces)
    assert sky.faces.source == faces.source   # (kept as given)
    brighter = sky_faces_from_file(path, 8, 15.0, intensity=2.5)
    np.testing.assert_allclose(brighter, faces * 2.5, rtol=1e-6)
    assert brighter.source["intensity"] == 2.5
    for bad in (-1.0, float("nan"), 1e5):
        with pytest.raises(ValueError, match="intensity must be a number"):
            sky_faces_from_file(path, 8, intensity=bad)


@pytest.mark.parametrize("kwargs,match", [
    ({"panorama": np.zeros((4, 8)), "face_size": 4}, "an \\(height, width, 3\\) image"),
    ({"panorama": np.full((4, 8, 3), -1.0), "face_size": 4}, "non-negative"),
    ({"panorama": np.zeros((4, 8, 3)), "face_size": 0}, "face_size"),
    ({"panorama": np.zeros((4, 8, 3)), "face_size": 4, "yaw": float("nan")}, "yaw"),
])
def test_bad_panorama_arguments_are_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        panorama_faces(**kwargs)


# -- drawn --------------------------------------------------------------------------------------
def test_the_sky_and_the_light_it_gives_are_the_panoramas(scene):
    """Looking ahead, right and up, the sky is the function there; a white ball lit by nothing
    else shows a linear sky's irradiance, pi a + 2 pi / 3 b.n, times its albedo over pi."""
    faces = panorama_faces(analytic_panorama(), 64)

    def build(target):
        def make(world):
            look_from(world, (0.0, 0.0, 0.0), target, fov=20.0)
            world.spawn(Skybox(faces=faces))
        return make

    for target in ((0.0, 0.0, -1.0), (1.0, 0.0, 0.0), (0.0, 1.0, -0.001), (-0.6, -0.3, 0.7)):
        runner = scene(build(target), (32, 32))
        runner.frame()
        seen = srgb_to_linear(runner.frame()[12:20, 12:20]).reshape(-1, 3).mean(axis=0)
        d = np.array(target) / np.linalg.norm(target)
        np.testing.assert_allclose(seen, sky_function(d), atol=0.012)

    image, inside, normal = grey_ball_under_sky(scene, faces)   # (inside: away from its outline)
    irradiance = np.pi * 0.5 + 2.0 * np.pi / 3.0 * 0.4 * normal   # per channel: a = 0.5, b = 0.4 along one axis
    error = np.abs(image[inside] - (0.8 / np.pi * irradiance)[inside])
    assert inside.sum() > 400 and np.percentile(error, 95) < 0.015 and error.max() < 0.03, error.max()


# -- level files and the runner -------------------------------------------------------------------
def test_a_level_file_names_a_panorama_and_writes_it_back(tmp_path):
    from engine.assets.level_read import load_level
    from engine.assets.level_save import save_level
    from engine.core.world import World

    (tmp_path / "skies").mkdir()
    write_hdr(tmp_path / "skies" / "dusk.hdr", random_rgbe(8, 16))
    level = tmp_path / "sky.toml"
    level.write_text('[level]\nname = "sky"\n[[entity]]\nname = "sky"\n'
                     'Skybox = { faces = { panorama = "skies/dusk.hdr", face_size = 8, yaw = 30, intensity = 2 } }\n')
    world = World()
    load_level(level).spawn(world)
    sky = world.query_one(Skybox)[0][1]
    np.testing.assert_array_equal(sky.faces, sky_faces_from_file(tmp_path / "skies" / "dusk.hdr", 8, 30.0, 2.0))
    saved = tmp_path / "saved.toml"
    save_level(world, saved)
    text = saved.read_text()
    assert 'panorama = "skies/dusk.hdr"' in text and "face_size = 8" in text and "intensity = 2.0" in text, text
    again = World()
    load_level(saved).spawn(again)
    np.testing.assert_array_equal(again.query_one(Skybox)[0][1].faces, sky.faces)


@pytest.mark.parametrize("table,match", [
    ('{ panorama = 3 }', "a file is a path string"),
    ('{ panorama = "../outside.hdr" }', "outside the level's folder"),
    ('{ panorama = "sky.hdr", face_size = 0 }', "face_size must be an int from 1 to 2048"),
    ('{ panorama = "sky.hdr", yaw = "west" }', "yaw must be a finite number"),
    ('{ panorama = "sky.hdr", size = 4 }', "unknown keys"),
    ('{ panorama = "sky.hdr", intensity = -2 }', "intensity must be a number from 0"),
    ('[1, 2]', "Skybox.faces in a level file is a panorama"),
])
def test_a_bad_sky_panorama_in_a_level_file_is_one_error(tmp_path, table, match):
    from engine.assets.level_file import LevelError
    from engine.assets.level_read import load_level

    write_hdr(tmp_path / "sky.hdr", random_rgbe(4, 8))
    level = tmp_path / "bad.toml"
    level.write_text(f'[level]\nname = "bad"\n[[entity]]\nname = "sky"\nSkybox = {{ faces = {table} }}\n')
    with pytest.raises(LevelError, match=match):
        load_level(level)


def test_the_runners_panorama_becomes_the_levels_sky(scene, tmp_path):
    path = write_hdr(tmp_path / "sky.hdr", random_rgbe(16, 32))
    runner = scene(lambda world: look_from(world, (0.0, 0.0, 0.0), (0.0, 0.0, -1.0)), (16, 16))
    runner.engine.start_sky(None, panorama=str(path), panorama_yaw=45.0)
    runner.frame()
    sky = runner.world.query_one(Skybox)[0][1]
    assert sky.faces.source == {"panorama": str(path.resolve()), "face_size": 512, "yaw": 45.0}


def test_the_sample_level_takes_a_panorama_from_the_command_line(tmp_path):
    from PIL import Image

    from tests.support import run_level

    path = write_hdr(tmp_path / "sky.hdr", np.tile(np.array([200, 40, 40, 129], np.uint8), (16, 32, 1)))   # red
    result = run_level("--headless", "--frames", "1", "--size", "64x36", "--aa", "off", "--panorama", str(path),
                       "--panorama-yaw", "-30", "--out", str(tmp_path / "red"))
    assert result.returncode == 0, result.stderr
    frame = np.asarray(Image.open(tmp_path / "red" / "frame_0000.png")).astype(float)
    assert frame[..., 0].mean() > 1.3 * frame[..., 2].mean()   # (the hall lit and reflecting a red sky)
    for bad, words in ((("--panorama", str(tmp_path / "none.hdr")), "--panorama: panorama file"),
                       (("--panorama-yaw", "10"), "--panorama-yaw needs --panorama"),
                       (("--panorama", str(path), "--panorama-yaw", "west"), "--panorama-yaw must be")):
        result = run_level("--headless", "--frames", "1", "--size", "16x12", "--out", str(tmp_path / "bad"), *bad)
        assert result.returncode != 0 and words in result.stderr.splitlines()[-1], result.stderr


def test_save_hdr_writes_what_radiance_reads(tmp_path):
    """Colours written by ``save_hdr``, read back by a decoder of the test's own (the header,
    then flat RGBE pixels, (m + 0.5) 2^(e - 136)): within 1/128 of each pixel's largest channel;
    and ``load_hdr`` reads the file to the same values; bad images refused."""
    from engine.assets.panorama import save_hdr

    rng = np.random.default_rng(7)
    image = rng.uniform(0.0, 1.0, (12, 20, 3)) * 10.0 ** rng.uniform(-3.0, 3.0, (12, 20, 1))
    image[0, 0] = 0.0
    path = save_hdr(tmp_path / "out.hdr", image)
    data = path.read_bytes()
    header, _, body = data.partition(b"\n\n")
    assert header.startswith(b"#?RADIANCE") and b"FORMAT=32-bit_rle_rgbe" in header
    resolution, _, pixels = body.partition(b"\n")
    assert resolution == b"-Y 12 +X 20" and len(pixels) == 12 * 20 * 4
    rgbe = np.frombuffer(pixels, np.uint8).reshape(12, 20, 4)
    decoded = expected(rgbe)
    largest = image.max(axis=-1, keepdims=True)
    assert (np.abs(decoded - image) <= largest / 128.0 + 1e-30).all()
    np.testing.assert_array_equal(load_hdr(path), decoded.astype(np.float32))
    for bad in (np.zeros((4, 4)), np.full((2, 2, 3), -1.0), np.full((2, 2, 3), np.inf)):
        with pytest.raises(ValueError, match="save_hdr"):
            save_hdr(tmp_path / "bad.hdr", bad)


def test_an_8_bit_panorama_is_read_as_srgb(tmp_path):
    """A PNG panorama (four bands of sRGB colour down it) is read as linear light: its faces'
    straight-up, level and straight-down texels hold the bands' colours made linear."""
    from PIL import Image

    from engine.core.color import srgb_to_linear as linear

    bands = np.array([[200, 40, 40], [40, 200, 40], [40, 40, 200], [90, 90, 90]], np.uint8)
    image = np.repeat(bands, 16, axis=0)[:, None, :].repeat(128, axis=1)   # 64 rows, 128 columns
    Image.fromarray(image).save(tmp_path / "bands.png")
    faces = sky_faces_from_file(tmp_path / "bands.png", 16)
    np.testing.assert_allclose(faces[2][8, 8], linear(bands[0] / 255.0), rtol=1e-3)   # +Y: the top band
    np.testing.assert_allclose(faces[3][8, 8], linear(bands[3] / 255.0), rtol=1e-3)   # -Y: the bottom band
    above, below = faces[5][7, 8], faces[5][8, 8]   # -Z, just over and under the horizon: bands two and three
    assert above[1] > 5 * max(above[0], above[2]) and below[2] > 5 * max(below[0], below[1])
    assert faces.source["panorama"].endswith("bands.png")
