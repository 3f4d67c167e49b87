"""Level files and assets from strangers (issue 26): whatever file a level names, loading it
ends in the level, or in one ``LevelError`` naming the file (and the line, entity and field
where known), never a traceback, a hang or a memory blow-up, and an image loads as the
picture it holds.

Everything here is made in tmp_path at test time and checked without a GL context, except
the runner cases, which stop at the level check (before any context is made)."""
from __future__ import annotations

import os
import struct
import subprocess
import sys
import textwrap
import tracemalloc
import zlib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from engine.assets.level_file import LevelError, load_level
from engine.assets.mesh import box, load_model, plane, quad, sphere
from engine.assets.texture_data import (
    ASSET_MEMORY_BUDGET,
    MAX_TEXTURE_SIDE,
    checker_texture,
    load_texture,
    ripple_normal_map,
)
from engine.core.errors import AssetError
from engine.core.world import World

ROOT = Path(__file__).resolve().parents[1]
HEAD = '[level]\nname = "untrusted"\n\n'


def entity(mesh: str = "{ quad = [1.0, 1.0] }", texture: str | None = None, normal_map: str | None = None) -> str:
    text = f'[[entity]]\nname = "thing"\n[entity.Transform]\n[entity.MeshRef]\nmesh = {mesh}\n[entity.Material]\n'
    if texture is not None:
        text += f"texture = {texture}\n"
    if normal_map is not None:
        text += f"normal_map = {normal_map}\n"
    return text


def write_level(folder: Path, text: str, name: str = "level.toml") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(text)
    return path


def refusal(path: Path, **kwargs) -> LevelError:
    """The LevelError loading ``path`` raises (and it must raise one, naming the file)."""
    with pytest.raises(LevelError) as info:
        load_level(path, **kwargs).spawn(World("refused"))
    assert str(path) in str(info.value), info.value
    return info.value


def line_of(path: Path, text: str) -> int:
    return next(i for i, line in enumerate(path.read_text().splitlines(), 1) if text in line)


def png(path: Path, pixels: np.ndarray, colour_type: int, depth: int = 8, declared: tuple | None = None) -> Path:
    """A PNG written by hand (Pillow writes no 48-bit RGB): ``colour_type`` 0 grey, 2 RGB, 6
    RGBA; ``declared`` (w, h) puts another size in the header than the data has (a bomb)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    h, w = pixels.shape[:2]
    dtype = ">u2" if depth == 16 else "u1"
    raw = b"".join(b"\0" + pixels[y].astype(dtype).tobytes() for y in range(h))
    w, h = declared or (w, h)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, depth, colour_type, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))
    return path


# --- 1. files that used to escape as tracebacks ---------------------------------------------

def test_a_symlink_loop_is_named_as_one(tmp_path):
    (tmp_path / "a.png").symlink_to(tmp_path / "b.png")
    (tmp_path / "b.png").symlink_to(tmp_path / "a.png")
    (tmp_path / "self.obj").symlink_to(tmp_path / "self.obj")
    for spec, field in (('{ file = "a.png" }', "Material.texture"), ('{ file = "self.obj" }', "MeshRef.mesh")):
        texture, mesh = (spec, None) if field == "Material.texture" else (None, spec)
        path = write_level(tmp_path, HEAD + entity(**({"mesh": mesh} if mesh else {}), texture=texture))
        error = refusal(path)
        assert error.field == field and error.entity == "thing" and error.line == line_of(path, spec)
        assert "symlink loop" in error.reason, error
    with pytest.raises(AssetError, match="symlink loop"):
        load_texture(tmp_path / "a.png")
    with pytest.raises(AssetError, match="symlink loop"):
        load_model(tmp_path / "self.obj")


@pytest.mark.parametrize("value", ["[" * 5000 + "]" * 5000, "{ a = " * 3000 + "1" + " }" * 3000,
                                   "[" * 40 + "1.0" + "]" * 40],
                         ids=["arrays", "inline-tables", "forty-deep"])
def test_values_nested_deep_are_refused_with_their_line(tmp_path, value):
    path = write_level(tmp_path, HEAD + f'[[entity]]\nname = "deep"\n[entity.Transform]\nposition = {value}\n')
    error = refusal(path)
    assert "nested" in error.reason and error.line == line_of(path, "position ="), error


def test_a_png_declaring_30000_square_is_refused_before_decoding(tmp_path):
    bomb = png(tmp_path / "bomb.png", np.zeros((4, 4), np.uint8), 0, declared=(30000, 30000))
    assert bomb.stat().st_size < 200
    wide = png(tmp_path / "wide.png", np.zeros((4, 4), np.uint8), 0, declared=(MAX_TEXTURE_SIDE + 1, 4))
    for path in (bomb, wide):
        with pytest.raises(AssetError) as info:
            load_texture(path)
        assert str(path) in str(info.value) and f"{MAX_TEXTURE_SIDE}x{MAX_TEXTURE_SIDE}" in str(info.value)
    level = write_level(tmp_path, HEAD + entity(texture='{ file = "bomb.png" }'))
    assert refusal(level).field == "Material.texture"


def test_pillows_pixel_limit_is_the_gl_texture_limit(tmp_path):
    from PIL import Image as PillowImage

    png(tmp_path / "ok.png", np.zeros((2, 2), np.uint8), 0)
    load_texture(tmp_path / "ok.png")
    assert PillowImage.MAX_IMAGE_PIXELS == MAX_TEXTURE_SIDE ** 2


def test_a_gltf_nested_100000_deep_is_refused(tmp_path):
    (tmp_path / "deep.gltf").write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(AssetError, match="nested too deeply"):
        load_model(tmp_path / "deep.gltf")
    path = write_level(tmp_path, HEAD + entity(mesh='{ file = "deep.gltf" }'))
    error = refusal(path)
    assert error.field == "MeshRef.mesh" and "nested too deeply" in error.reason


def test_a_file_the_process_may_not_read_is_named(tmp_path, monkeypatch):
    """The tests run as root, who reads anything: the refusal is simulated at the open."""
    Image.new("RGB", (2, 2)).save(tmp_path / "locked.png")
    (tmp_path / "locked.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    real_open = os.open
    locked = {str(tmp_path / "locked.png"), str(tmp_path / "locked.obj")}

    def refuse(path, *args, **kwargs):
        if os.fspath(path) in locked:
            raise PermissionError(13, "Permission denied", os.fspath(path))
        return real_open(path, *args, **kwargs)

    monkeypatch.setattr(os, "open", refuse)
    with pytest.raises(AssetError, match="permission denied"):
        load_texture(tmp_path / "locked.png")
    with pytest.raises(AssetError, match="permission denied"):
        load_model(tmp_path / "locked.obj")
    path = write_level(tmp_path, HEAD + entity(mesh='{ file = "locked.obj" }', texture='{ file = "locked.png" }'))
    error = refusal(path)
    assert error.field == "MeshRef.mesh" and "permission denied" in error.reason


def test_running_out_of_memory_is_an_error_line_naming_the_field(tmp_path, monkeypatch):
    import engine.assets.level_assets as level_assets

    def no_memory(*args, **kwargs):
        raise MemoryError

    monkeypatch.setattr(level_assets, "checker_texture", no_memory)
    path = write_level(tmp_path, HEAD + entity(texture="{ checker = [64, 8] }"))
    error = refusal(path)
    assert error.field == "Material.texture" and "memory" in error.reason

    Image.new("RGB", (2, 2)).save(tmp_path / "fine.png")
    monkeypatch.setattr(Image.Image, "convert", no_memory)
    with pytest.raises(AssetError, match="memory"):
        load_texture(tmp_path / "fine.png")


# --- 2. memory before allocation ---------------------------------------------------------------

def peak_bytes(make) -> tuple[int, object]:
    tracemalloc.start()
    try:
        made = make()
        return tracemalloc.get_traced_memory()[1], made
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize("make", [lambda: checker_texture(1024, 1), lambda: checker_texture(1024, 7, name="c"),
                                  lambda: ripple_normal_map(1024, 3)], ids=["checker", "checker-7", "ripples"])
def test_a_texture_generator_allocates_about_what_it_returns(make):
    peak, texture = peak_bytes(make)
    assert peak <= 1.25 * texture.pixels.nbytes + (8 << 20), (peak, texture.pixels.nbytes)


def test_a_sphere_allocates_about_what_it_returns():
    peak, mesh = peak_bytes(lambda: sphere(1.0, 512, 512))
    size = mesh.positions.nbytes + mesh.normals.nbytes + mesh.uvs.nbytes + mesh.indices.nbytes
    assert peak <= 1.5 * size, (peak, size)


def test_the_checker_still_draws_the_same_board():
    tex = checker_texture(8, 4, a=(200, 10, 20), b=(1, 2, 3))
    yy, xx = np.mgrid[0:8, 0:8]
    odd = ((xx // 2 + yy // 2) % 2).astype(bool)
    assert (tex.pixels[odd][:, :3] == (1, 2, 3)).all() and (tex.pixels[~odd][:, :3] == (200, 10, 20)).all()
    assert (tex.pixels[..., 3] == 255).all()


def test_the_memory_budget_is_checked_before_allocating(monkeypatch):
    import engine.assets.texture_data as texture_data

    monkeypatch.setattr(texture_data, "ASSET_MEMORY_BUDGET", 1 << 20)
    for make in (lambda: checker_texture(1024, 1), lambda: ripple_normal_map(1024, 2)):
        peak, _ = None, None
        tracemalloc.start()
        try:
            with pytest.raises(AssetError, match="memory budget"):
                make()
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert peak < 1 << 20
    assert checker_texture(512, 2).pixels.nbytes == 1 << 20  # exactly the budget is allowed


def test_a_level_of_many_big_textures_stays_in_its_budget(tmp_path, monkeypatch):
    import engine.assets.level_assets as level_assets

    monkeypatch.setattr(level_assets, "LEVEL_MEMORY_BUDGET", 3 << 20)
    text = HEAD + "".join(f'[[entity]]\nname = "t{i}"\n[entity.Material]\ntexture = {{ checker = [512, {i + 1}] }}\n'
                          for i in range(4))
    path = write_level(tmp_path, text)
    error = refusal(path)
    assert error.entity == "t3" and "memory budget" in error.reason and error.line == line_of(path, "[512, 4]")
    # The same texture named again costs nothing more.
    same = HEAD + "".join(f'[[entity]]\nname = "t{i}"\n[entity.Material]\ntexture = {{ checker = [512, 1] }}\n'
                          for i in range(6))
    load_level(write_level(tmp_path, same, "same.toml"))


def test_the_documented_generator_limits_are_within_the_budget():
    assert MAX_TEXTURE_SIDE ** 2 * 4 <= ASSET_MEMORY_BUDGET


# --- 3. a level's assets stay in its folder ------------------------------------------------------

@pytest.fixture
def outside(tmp_path) -> Path:
    """A level folder ``tmp_path/game/level`` and an image outside it, ``tmp_path/secret.png``."""
    Image.new("RGB", (2, 2), (255, 0, 0)).save(tmp_path / "secret.png")
    (tmp_path / "game" / "level").mkdir(parents=True)
    return tmp_path


@pytest.mark.parametrize("file", ["../../secret.png", "../../missing.png", "{abs}/secret.png", "{abs}/missing.png",
                                  "link.png", "sub/../../../secret.png"])
def test_a_path_outside_the_level_folder_is_refused_without_saying_if_it_exists(outside, file):
    folder = outside / "game" / "level"
    (folder / "link.png").symlink_to(outside / "secret.png")
    file = file.format(abs=outside)
    path = write_level(folder, HEAD + entity(texture=f'{{ file = "{file}" }}'))
    error = refusal(path)
    assert error.field == "Material.texture" and error.line == line_of(path, "texture =")
    assert "outside the level's folder" in error.reason and "--asset-root" in error.reason
    assert "no such file" not in error.reason and "image" not in error.reason
    assert str(outside / "secret.png") not in error.reason or file.startswith(str(outside))


def test_the_refusal_reads_the_same_whether_or_not_the_file_is_there(outside):
    folder = outside / "game" / "level"
    there = refusal(write_level(folder, HEAD + entity(texture='{ file = "../../secret.png" }'), "a.toml"))
    gone = refusal(write_level(folder, HEAD + entity(texture='{ file = "../../secreT.png" }'), "b.toml"))
    assert there.reason.replace("secret", "X") == gone.reason.replace("secreT", "X")


def test_asset_roots_let_a_level_use_shared_assets(outside):
    folder = outside / "game" / "level"
    path = write_level(folder, HEAD + entity(texture='{ file = "../../secret.png" }'))
    level = load_level(path, asset_roots=[outside])
    assert level.entity_names == ["thing"]
    from engine.assets.level_assets import set_asset_roots

    set_asset_roots([outside])
    try:
        load_level(path)
    finally:
        set_asset_roots([])
    refusal(path)


def test_a_mesh_file_may_not_reach_outside_either(outside):
    folder = outside / "game" / "level"
    (outside / "outside.mtl").write_text("newmtl m\nKd 1 0 0\n")
    (folder / "reach.obj").write_text("mtllib ../../outside.mtl\nusemtl m\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (folder / "inside.mtl").write_text("newmtl m\nKd 1 1 1\nmap_Kd ../../secret.png\n")
    (folder / "texture.obj").write_text("mtllib inside.mtl\nusemtl m\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\n"
                                        "f 1/1 2/1 3/1\n")
    (folder / "reach.gltf").write_text('{"asset": {"version": "2.0"}, "buffers": [{"uri": "../../secret.bin", '
                                       '"byteLength": 36}]}')
    for name in ("reach.obj", "texture.obj", "reach.gltf"):
        path = write_level(folder, HEAD + entity(mesh=f'{{ file = "{name}" }}'), f"{name}.toml")
        error = refusal(path)
        assert error.field == "MeshRef.mesh" and "outside the level's folder" in error.reason, error


# --- 4. not a regular file ------------------------------------------------------------------------

@pytest.mark.parametrize("kind", ["directory", "fifo", "device"])
def test_a_file_that_is_not_a_regular_file_says_so_and_nothing_blocks(tmp_path, kind):
    for name in ("thing.png", "thing.obj"):
        target = tmp_path / name
        if kind == "directory":
            target.mkdir()
        elif kind == "fifo":
            os.mkfifo(target)
        else:
            target.symlink_to("/dev/zero")
    words = {"directory": "is a directory", "fifo": "is a FIFO", "device": "is a character device"}[kind]
    for spec, field in (('{ file = "thing.png" }', "Material.texture"), ('{ file = "thing.obj" }', "MeshRef.mesh")):
        parts = {"texture": spec} if field == "Material.texture" else {"mesh": spec}
        path = write_level(tmp_path, HEAD + entity(**parts))
        # /dev/zero is outside the level's folder: the device check is reached with /dev a root.
        error = refusal(path, **({"asset_roots": ["/dev"]} if kind == "device" else {}))
        assert error.field == field and words in error.reason and "no such file" not in error.reason, error
    with pytest.raises(AssetError, match=words):
        load_texture(tmp_path / "thing.png")
    with pytest.raises(AssetError, match=words):
        load_model(tmp_path / "thing.obj")


def test_a_level_file_that_is_a_fifo_or_directory_is_refused(tmp_path):
    os.mkfifo(tmp_path / "fifo.toml")
    (tmp_path / "dir.toml").mkdir()
    for name, words in (("fifo.toml", "is a FIFO"), ("dir.toml", "is a directory")):
        with pytest.raises(LevelError, match=words):
            load_level(tmp_path / name)
    with pytest.raises(LevelError, match="is a character device"):
        load_level("/dev/zero")


def test_an_obj_naming_a_fifo_material_library_does_not_block(tmp_path):
    os.mkfifo(tmp_path / "fifo.mtl")
    (tmp_path / "m.obj").write_text("mtllib fifo.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(AssetError, match="fifo.mtl.*is a FIFO"):
        load_model(tmp_path / "m.obj")


# --- 5. image formats convert with scaling ------------------------------------------------------------

def test_a_16_bit_grey_png_at_half_loads_as_half_grey(tmp_path):
    path = png(tmp_path / "grey16.png", np.array([[0, 32768, 65535, 257]], np.uint16), 0, depth=16)
    pixels = load_texture(path).pixels
    np.testing.assert_array_equal(pixels[0, :, 0], [0, 128, 255, 1])
    assert (pixels[..., 0] == pixels[..., 1]).all() and (pixels[..., 3] == 255).all()


def test_a_float_tiff_loads_scaled_from_zero_one(tmp_path):
    values = np.array([[0.0, 0.5, 1.0, 2.0, -1.0]], np.float32)
    Image.fromarray(values).save(tmp_path / "float.tiff")
    np.testing.assert_array_equal(load_texture(tmp_path / "float.tiff").pixels[0, :, 0], [0, 128, 255, 255, 0])
    Image.fromarray(np.array([[0.5, np.nan]], np.float32)).save(tmp_path / "nan.tiff")
    with pytest.raises(AssetError, match="NaN"):
        load_texture(tmp_path / "nan.tiff")


def test_16_bit_tiffs_and_32_bit_integers(tmp_path):
    Image.fromarray(np.array([[40000, 0]], np.uint16)).save(tmp_path / "u16.tiff")
    assert load_texture(tmp_path / "u16.tiff").pixels[0, 0, 0] == round(40000 * 255 / 65535)
    Image.fromarray(np.array([[40000, 0]], np.int32)).save(tmp_path / "i32.tiff")
    with pytest.raises(AssetError, match="32-bit integer"):
        load_texture(tmp_path / "i32.tiff")


def test_a_16_bit_rgb_normal_map_keeps_its_normal(tmp_path):
    """A flat 16-bit normal map (0.5, 0.5, 1.0) in a level keeps its 16-bit values (not
    tilted, not rounded to 8 bits); a 16-bit grey file as a normal map is three equal channels."""
    flat = np.tile(np.array([32768, 32768, 65535], np.uint16), (4, 4, 1))
    png(tmp_path / "flat16.png", flat, 2, depth=16)
    grey = np.full((4, 4), 32768, np.uint16)
    png(tmp_path / "grey16.png", grey, 0, depth=16)
    path = write_level(tmp_path, HEAD + entity(normal_map='{ file = "flat16.png" }'))
    pixels = load_level(path)._entities[0].components[2][1]["normal_map"].pixels
    assert pixels.dtype == np.uint16 and (pixels[..., :3] == (32768, 32768, 65535)).all()
    path = write_level(tmp_path, HEAD + entity(normal_map='{ file = "grey16.png" }'), "grey.toml")
    pixels = load_level(path)._entities[0].components[2][1]["normal_map"].pixels
    assert (pixels[..., :3] == 32768).all()


# --- 6. generator arguments ----------------------------------------------------------------------

@pytest.mark.parametrize("spec, field, words", [
    ('{ plane = [1.0, 1.0], uv_repeat = "x" }', "MeshRef.mesh", "uv_repeat must be a finite number"),
    ('{ plane = [1.0, 1.0], uv_repeat = nan }', "MeshRef.mesh", "uv_repeat must be a finite number"),
    ("{ box = [-1.0, 1.0, 1.0] }", "MeshRef.mesh", ">= 0"),
    ('{ box = [1.0, "a", 1.0] }', "MeshRef.mesh", "three numbers"),
    ("{ box = [1.0, 1.0] }", "MeshRef.mesh", "three numbers"),
    ("{ sphere = -1.0 }", "MeshRef.mesh", ">= 0"),
    ("{ sphere = true }", "MeshRef.mesh", "a number"),
    ("{ sphere = 0.5, segments = 8.5 }", "MeshRef.mesh", "segments must be an int"),
    ("{ quad = [-1.0, 1.0] }", "MeshRef.mesh", ">= 0"),
    ("{ quad = [1.0, -2.0] }", "MeshRef.mesh", ">= 0"),
    ("{ plane = [1.0, -1.0] }", "MeshRef.mesh", ">= 0"),
    ("{ quad = [inf, 1.0] }", "MeshRef.mesh", "finite"),
    ("{ checker = [2.5, 1] }", "Material.texture", "two integers"),
    ("{ checker = [64, 1.5] }", "Material.texture", "two integers"),
    ('{ checker = ["64", 1] }', "Material.texture", "two integers"),
    ("{ checker = [64] }", "Material.texture", "two integers"),
    ("{ checker = [64, 2], a = [300, 0, 0] }", "Material.texture", "a must be three integers in [0, 255]"),
    ("{ checker = [64, 2], b = [0.5, 0, 0] }", "Material.texture", "b must be three integers in [0, 255]"),
    ("{ checker = [64, 2], name = 5 }", "Material.texture", "name must be a string"),
    ("{ checker = [20000, 2] }", "Material.texture", "16384"),
])
def test_generator_arguments_are_checked_naming_file_line_entity_field(tmp_path, spec, field, words):
    parts = {"texture": spec} if field == "Material.texture" else {"mesh": spec}
    path = write_level(tmp_path, HEAD + entity(**parts))
    error = refusal(path)
    assert (error.entity, error.field, error.line) == ("thing", field, line_of(path, spec)), error
    assert words in error.reason, error


@pytest.mark.parametrize("make, words", [
    (lambda: box((-1, 1, 1)), "size"), (lambda: box((1, float("nan"), 1)), "size"), (lambda: box((1, 1)), "size"),
    (lambda: quad(-1, 1), "width"), (lambda: quad(1, float("inf")), "height"), (lambda: plane(1, -1), "depth"),
    (lambda: plane(1, 1, uv_repeat="x"), "uv_repeat"), (lambda: sphere(-1), "radius"), (lambda: sphere("1"), "radius"),
    (lambda: checker_texture(8, 2, a=(300, 0, 0)), "a must"), (lambda: checker_texture(8, 2, b=(1, 2)), "b must"),
])
def test_the_generators_check_their_arguments_from_python_too(make, words):
    with pytest.raises(AssetError, match=words):
        make()


def test_zero_sizes_are_still_meshes_with_no_area():
    """A zero quad is the mirror checks' test case (no area): allowed here, refused there."""
    assert quad(0, 0).positions.shape == (4, 3) and box((0, 1, 1)).positions.shape == (24, 3)


# --- 9. level-file messages with a line ------------------------------------------------------------

@pytest.mark.parametrize("text, marker, words", [
    ('[level]\nname = "t"\ntitle = "x"\n', "title =", "unknown keys ['title']"),
    (HEAD + '[[entitty]]\nname = "x"\n', "[[entitty]]", "unknown top-level tables ['entitty']"),
    ('[level]\ngame = "x"\n', "[level]", "needs name"),
    ('[level]\nname = 5\n', "name = 5", "needs name"),
    ('[level]\nname = "t"\ngame = 5\n', "game = 5", "game must be a string"),
    ('[level]\nname = "t"\nrules = 5\n', "rules = 5", "unknown keys"),
    ('stray = 1\n[level]\nname = "t"\n', "stray = 1", "unknown top-level tables ['stray']"),
    (HEAD + '[entity]\nname = "x"\n', "[entity]", "[[entity]] tables"),
    ('rules = 5\n[level]\nname = "t"\n', "rules = 5", "[rules] must be a table"),
])
def test_header_mistakes_name_their_line(tmp_path, text, marker, words):
    path = write_level(tmp_path, text)
    error = refusal(path)
    assert error.line == line_of(path, marker) and words in error.reason, error


def test_a_mirror_without_a_mesh_or_transform_is_refused_at_load_naming_the_entity(tmp_path):
    for missing in ("MeshRef", "Transform"):
        parts = {"Transform": "[entity.Transform]\n", "MeshRef": "[entity.MeshRef]\nmesh = { quad = [1.0, 1.0] }\n"}
        del parts[missing]
        path = write_level(tmp_path, HEAD + '[[entity]]\nname = "glass"\n' + "".join(parts.values())
                           + "[entity.Material]\n[entity.Mirror]\n", f"{missing}.toml")
        error = refusal(path)
        assert (error.entity, error.field, error.line) == ("glass", "Mirror", line_of(path, "[entity.Mirror]"))
        assert f"needs a MeshRef and a Transform (it has no {missing})" in error.reason


def test_a_mirror_on_a_mesh_that_is_not_flat_is_refused_at_load(tmp_path):
    path = write_level(tmp_path, HEAD + '[[entity]]\nname = "ball"\n[entity.Transform]\n[entity.MeshRef]\n'
                       'mesh = { sphere = 0.5 }\n[entity.Mirror]\n')
    error = refusal(path)
    assert (error.entity, error.field) == ("ball", "Mirror") and "not flat" in error.reason


@pytest.mark.parametrize("name, text, words", [
    ("index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 5\n", "line 4: face index 5, but 3 vertices"),
    ("negative.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -5 -6 -7\n", "line 4: face index -5, but 3 vertices"),
    ("uv.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/3 2/1 3/1\n", "line 5: texture coordinate index 3, but 1"),
    ("short.obj", "v 0 0\nv 1 0\nv 0 1\nf 1 2 3\n", "line 1: a vertex is 'v x y z'"),
    ("words.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf a b c\n", "line 4: a face index is a number"),
    ("index.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                  "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n",
     "face index 7 is out of range (3 vertices)"),
])
def test_a_garbage_mesh_file_is_named_with_what_is_wrong(tmp_path, capfd, name, text, words):
    (tmp_path / name).write_text(text)
    path = write_level(tmp_path, HEAD + entity(mesh=f'{{ file = "{name}" }}'))
    error = refusal(path)
    assert error.field == "MeshRef.mesh" and words in error.reason and "IndexError" not in error.reason, error
    assert "Traceback" not in capfd.readouterr().err


# --- through the runner: one line, exit 2 ----------------------------------------------------------

def test_the_runner_prints_one_line_and_exits_2_for_each_kind_of_file(tmp_path):
    folder = tmp_path / "level"
    folder.mkdir()
    (folder / "loop.png").symlink_to(folder / "loop.png")
    os.mkfifo(folder / "fifo.obj")
    png(folder / "bomb.png", np.zeros((4, 4), np.uint8), 0, declared=(30000, 30000))
    cases = {
        "loop": entity(texture='{ file = "loop.png" }'),
        "fifo": entity(mesh='{ file = "fifo.obj" }'),
        "bomb": entity(texture='{ file = "bomb.png" }'),
        "outside": entity(texture='{ file = "../elsewhere.png" }'),
        "deep": '[[entity]]\nname = "x"\n[entity.Transform]\nposition = ' + "[" * 3000 + "]" * 3000 + "\n",
    }
    script = textwrap.dedent("""\
        import sys
        from shell.runner import main
        from games.hall_of_mirrors.level import HallOfMirrors
        codes = []
        for path in sys.argv[1:]:
            codes.append(main(HallOfMirrors(), ["--level", path, "--headless", "--frames", "1", "--size", "8x8",
                                                "--out", path + ".out"]))
        print(codes)
        """)
    paths = [str(write_level(folder, HEAD + text, f"{name}.toml")) for name, text in cases.items()]
    result = subprocess.run([sys.executable, "-c", script, *paths], cwd=ROOT, capture_output=True, text=True,
                            timeout=120, env={**os.environ, "DISPLAY": "", "WAYLAND_DISPLAY": ""})
    assert result.stdout.strip() == str([2] * len(cases)), result.stdout + result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == len(cases), result.stderr
    for line, path in zip(lines, paths, strict=True):
        assert line.startswith(f"speculum: error: {path}:"), line


def test_asset_root_on_the_command_line(tmp_path):
    from games.hall_of_mirrors.level import HallOfMirrors
    from shell.runner import parse_args

    Image.new("RGB", (2, 2)).save(tmp_path / "shared.png")
    camera = '\n[[entity]]\nname = "camera"\n[entity.Transform]\nposition = [0.0, 0.0, 3.0]\n[entity.Camera]\n'
    level = write_level(tmp_path / "level", HEAD + entity(texture='{ file = "../shared.png" }') + camera)
    args = parse_args(HallOfMirrors(), ["--asset-root", str(tmp_path), "--asset-root", str(tmp_path / "level")])
    assert args.asset_root == [tmp_path, tmp_path / "level"]
    script = ("import sys; from shell.runner import main; from games.hall_of_mirrors.level import HallOfMirrors; "
              "sys.exit(main(HallOfMirrors(), sys.argv[1:]))")
    base = [sys.executable, "-c", script, "--level", str(level), "--headless", "--frames", "1", "--size", "8x8",
            "--out", str(tmp_path / "out")]
    refused = subprocess.run(base, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert refused.returncode == 2 and "--asset-root" in refused.stderr, refused.stderr
    played = subprocess.run(base + ["--asset-root", str(tmp_path)], cwd=ROOT, capture_output=True, text=True,
                            timeout=120)
    assert played.returncode == 0, played.stderr
    missing = subprocess.run(base + ["--asset-root", str(tmp_path / "nowhere")], cwd=ROOT, capture_output=True,
                             text=True, timeout=120)
    assert missing.returncode == 2 and "--asset-root" in missing.stderr and "not a folder" in missing.stderr


# --- the fuzz's file cases --------------------------------------------------------------------------

def test_every_file_case_of_the_level_fuzz_is_refused_saying_what_or_loads_right(ctx, tmp_path):
    """``python -m benchmarks fuzz`` runs these too (benchmarks/level_fuzz.py FILE_CASES):
    each refused saying what the file is, or loaded with the file's texel and drawn clean."""
    from benchmarks.level_fuzz import FILE_CASES, fuzz_files

    ran, failures, passes = fuzz_files(ctx, tmp_path)
    assert ran == len(FILE_CASES) and not failures, failures
    assert passes["rendered"] == sum(case.expect is None for case in FILE_CASES)
