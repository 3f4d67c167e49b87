"""The meshes and textures a level file names, loaded for it within a budget.

A level's ``MeshRef.mesh`` and ``Material`` textures are tables (engine.assets.level_read
decodes the rest of the file): a generator (``{ box = [w, h, d] }``, ``{ checker = [size,
squares] }``, ``{ ripples = [size, rings] }``, ...) or ``{ file = "x.obj" }``. They live
apart from the reader because they are the part of a level that reaches the disk and the
memory: a file is followed only inside the level's folder or an asset root (the game's
``LevelGame.asset_roots``, the user's ``--asset-root DIR``: ``set_asset_roots``), each file
is checked before it is read (engine.assets.texture_data.check_asset_file), and what a
level's assets take together is held to ``LEVEL_MEMORY_BUDGET``, counted before a generator
runs. The same file (and the same generator call) loaded twice is one object, so the
renderer uploads it once. A mistake is a ValueError (or an AssetError) the reader turns
into a LevelError naming the file, line, entity and field.
"""
from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from engine.assets.color_lut import MAX_LUT_FILE_BYTES, ColorLut, load_cube_lut
from engine.assets.ies_profile import COOKIE_HEIGHT, COOKIE_WIDTH, ies_cookie, load_ies
from engine.assets.mesh import LoadedModel, Mesh, box, load_model, load_model_file, model_bytes, plane, quad, sphere
from engine.assets.panorama import (
    FACE_SIZE,
    MAX_FACE_SIZE,
    MAX_INTENSITY,
    MAX_PANORAMA_FILE_BYTES,
    SkyFaces,
    sky_faces_from_file,
)
from engine.assets.texture_data import (
    MAX_TEXTURE_SIDE,
    TextureData,
    check_asset_file,
    checker_texture,
    contained_path,
    load_texture,
    puff_texture,
    ripple_normal_map,
    texture_bytes,
    wave_normal_map,
)

# The meshes a level file (and the editor's shape choice) makes by name, at their default sizes unless told.
MESH_MAKERS: dict[str, Callable[..., Mesh]] = {"box": box, "quad": quad, "plane": plane, "sphere": sphere}
LEVEL_MEMORY_BUDGET = 2 << 30  # bytes a level's meshes and textures may take together (each is held to
#                                 engine.assets.texture_data.ASSET_MEMORY_BUDGET), counted before a generator runs

_ASSETS: dict[tuple, Any] = {}  # one Mesh / TextureData per file (and modification time) or generator call


def _cached(key: tuple, make: Callable[[], Any]) -> Any:
    value = _ASSETS.get(key)
    if value is None:
        value = _ASSETS[key] = make()
    return value


class _Budget:
    """What a level's assets take together (each distinct asset once), checked against
    LEVEL_MEMORY_BUDGET before a generator runs (files: once loaded, each held to the
    asset budget as it loads)."""

    def __init__(self) -> None:
        self.used, self.keys = 0, set()

    def take(self, key: tuple, size: int) -> None:
        if key in self.keys:
            return
        if self.used + size > LEVEL_MEMORY_BUDGET:
            raise ValueError(f"the level's meshes and textures would take {_mib(self.used + size)} MiB, over the "
                             f"memory budget of {_mib(LEVEL_MEMORY_BUDGET)} MiB a level may have "
                             "(engine.assets.level_assets.LEVEL_MEMORY_BUDGET)")
        self.keys.add(key)
        self.used += size


def _mib(size: int) -> str:
    return f"{size / (1 << 20):.0f}"


class LevelAssets:
    """Where a level's assets are looked for: its folder and any asset roots (the game's and
    the user's), and what they take so far."""

    def __init__(self, folder: Path, roots: Sequence[Path]) -> None:
        self.folder = folder
        self.roots = [folder, *roots]
        self.budget = _Budget()
        self.models: dict[tuple[str, str], LoadedModel] = {}  # the model files its Models place, by (path, variant)


def is_number(value: Any) -> bool:
    """A TOML number (an int or a float, not a bool)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _asset_table(spec: Any, what: str, examples: str) -> tuple[dict, Any]:
    """A mesh's or texture's table (``what``) as a dict of its own, and its ``name`` taken out
    of it (None, or a string)."""
    if not isinstance(spec, Mapping):
        raise ValueError(f"a {what} is a table such as {examples}, got {spec!r}")
    spec = dict(spec)
    name = spec.pop("name", None)
    if name is not None and not isinstance(name, str):
        raise ValueError(f"a {what}'s name must be a string, got {name!r}")
    return spec, name


def _side_stats(loaded: Any) -> tuple:
    """The modification time and size of each file a loaded model names beside it (None: gone)."""
    stats = []
    for side in loaded.side_files:
        try:
            info = os.stat(side)
            stats.append((info.st_mtime_ns, info.st_size))
        except OSError:
            stats.append(None)
    return tuple(stats)


def level_model_path(value: Any, where: LevelAssets) -> str:
    """A ``Model.file``: the model file's path (inside the level's folder or an asset root),
    made absolute.  "" is no file (a Model placing nothing yet)."""
    if value == "":
        return ""
    return str(_asset_path(value, where))


def level_model(value: Any, where: LevelAssets, variant: str = "") -> str:
    """A ``Model.file`` (``level_model_path``) with the file loaded whole in its material
    ``variant`` (its materials' images decoded, its lights read: what its parts will be) and
    counted in the level's budget; ``where.models`` keeps it for the spawn."""
    path = level_model_path(value, where)
    if not path:
        return ""
    info = check_asset_file(Path(path), f"model file {path!r}")
    key = ("model file", path, variant, info.st_mtime_ns, info.st_size, info.st_ino, tuple(map(str, where.roots)))
    kept = _ASSETS.get(key)
    if kept is None or kept[1] != _side_stats(kept[0]):  # (a buffer or image beside it saved again: loaded again)
        loaded = load_model_file(path, roots=where.roots, variant=variant)
        kept = _ASSETS[key] = (loaded, _side_stats(loaded))
    loaded = kept[0]
    where.budget.take(key, model_bytes(loaded.parts))
    where.models[(path, variant)] = loaded
    return path


def level_mesh(spec: Any, where: LevelAssets) -> Mesh:
    """The mesh a ``MeshRef.mesh`` table names: a generator's (cached by its arguments) or a
    model file's (one part of it, ``part = "..."`` where it has several)."""
    spec, name = _asset_table(spec, "mesh", '{ box = [1, 1, 1] } or { file = "x.obj" }')
    if "file" in spec:
        path = _asset_path(spec.pop("file"), where)
        part = spec.pop("part", None)
        _no_more(spec, "mesh file")
        info = check_asset_file(path, f"mesh file {str(path)!r}")
        key = ("model", str(path), info.st_mtime_ns, info.st_size, info.st_ino, tuple(map(str, where.roots)))
        # The mesh alone: a level draws a file's mesh with its own Material, so the images the
        # model's materials name are checked but neither decoded nor cached.
        parts = _cached(key, lambda: load_model(path, roots=where.roots, materials=False))
        where.budget.take(key, model_bytes(parts))
        names = [p.name for p in parts]
        if part is None and len(parts) > 1:
            raise ValueError(f"mesh file {str(path)!r} has {len(parts)} parts {names}: say which with part = \"...\"")
        # A part by its name in the file ("left") or as the engine names it ("two.obj:left").
        chosen = parts[0] if part is None else next(
            (p for p in parts if part in (p.name, p.name.split(":", 1)[-1])), None)
        if chosen is None:
            raise ValueError(f"mesh file {str(path)!r} has no part {part!r} (parts: {names})")
        chosen.mesh.source = {"file": str(path), **({"part": part} if part is not None else {})}
        return chosen.mesh
    kinds = [k for k in spec if k in MESH_MAKERS]
    if len(kinds) != 1:
        raise ValueError(f"a mesh names one of {sorted(MESH_MAKERS)} or file, got {sorted(spec)}")
    kind = kinds[0]
    size = spec.pop(kind)
    options = {k: spec.pop(k) for k in ("uv_repeat", "segments", "rings") if k in spec}
    _no_more(spec, f"{kind} mesh")
    allowed = {"plane": ("uv_repeat",), "sphere": ("segments", "rings")}.get(kind, ())
    for option, value in options.items():
        if option not in allowed:
            raise ValueError(f"a {kind} mesh has no {option} ({kind} takes {', '.join(allowed) or 'no options'})")
        if option == "uv_repeat" and not (is_number(value) and math.isfinite(value)):
            raise ValueError(f"plane mesh: uv_repeat must be a finite number, got {value!r}")
        if option in ("segments", "rings") and not _is_int(value):
            raise ValueError(f"sphere mesh: {option} must be an int, got {value!r}")
    if kind == "sphere":
        if not is_number(size):
            raise ValueError(f"sphere = r (a number, the radius), got {size!r}")
        args: tuple = (float(size),)
    else:
        count = 3 if kind == "box" else 2
        if not isinstance(size, list) or len(size) != count or not all(is_number(v) for v in size):
            shape = {"box": "[w, h, d] (three numbers)", "quad": "[w, h] (two numbers)",
                     "plane": "[w, d] (two numbers)"}[kind]
            raise ValueError(f"{kind} = {shape}, got {size!r}")
        args = (tuple(float(v) for v in size),) if kind == "box" else tuple(float(v) for v in size)
    if name is not None:
        options["name"] = name
    key = ("mesh", kind, args, tuple(sorted(options.items())))
    if kind == "sphere":  # the others are a few hundred bytes
        segments, rings = options.get("segments", 48), options.get("rings", 24)
        where.budget.take(key, (segments + 1) * (rings + 1) * 32 + segments * rings * 24)
    return _cached(key, lambda: MESH_MAKERS[kind](*args, **options))  # the generator records its source


def level_texture(spec: Any, where: LevelAssets, normal_map: bool = False) -> TextureData:
    """The texture a ``Material`` table names (``texture`` or a map), a particle emitter's or
    a light's cookie: checker, ripples, puff (``puff_texture``), an image file or an IES
    profile (``ies_cookie``: an all-round light's); ``normal_map``: a linear map, which keeps
    a 16-bit file's 16 bits."""
    spec, name = _asset_table(spec, "texture", '{ checker = [128, 8] }, { ripples = [256, 6] }, { puff = [64, 0] }, '
                                                   '{ file = "x.png" } or { ies = "lamp.ies" }')
    if "ies" in spec and normal_map:
        raise ValueError("an IES profile is a light's cookie (its candelas by direction), not a normal map")
    if "ies" in spec:   # an IES profile as an all-round light's cookie (engine/assets/ies_profile.py)
        path = _asset_path(spec.pop("ies"), where)
        _no_more(spec, "IES profile")
        info = check_asset_file(path, f"IES profile {str(path)!r}")
        key = ("ies", str(path), info.st_mtime_ns, info.st_size, info.st_ino)
        where.budget.take(key, texture_bytes(COOKIE_WIDTH, COOKIE_HEIGHT))
        return _cached(key, lambda: ies_cookie(load_ies(path)))
    if "file" in spec:
        path = _asset_path(spec.pop("file"), where)
        _no_more(spec, "texture file")
        info = check_asset_file(path, f"texture file {str(path)!r}")
        # A normal map keeps a 16-bit file's finer slopes (no terraces); a colour is 8 bits.
        key = ("texture", str(path), info.st_mtime_ns, info.st_size, info.st_ino, normal_map)
        texture = _cached(key, lambda: load_texture(path, keep_16_bits=normal_map))
        where.budget.take(key, texture.pixels.nbytes)
        return texture
    if "ripples" in spec and "checker" not in spec:
        return _ripples(spec, name, where)
    if "waves" in spec and "checker" not in spec:
        return _waves(spec, name, where)
    if "puff" in spec and "checker" not in spec:
        size_seed = spec.pop("puff")
        if not isinstance(size_seed, list) or len(size_seed) != 2 or not all(_is_int(v) for v in size_seed):
            raise ValueError(f"puff = [size, seed] (two integers), got {size_seed!r}")
        _no_more(spec, "puff texture")
        size, seed = size_seed
        options = {} if name is None or name == "puff" else {"name": name}
        key = ("puff", size, seed, tuple(sorted(options.items())))
        if 1 <= size <= MAX_TEXTURE_SIDE:
            where.budget.take(key, texture_bytes(size, size))
        return _cached(key, lambda: puff_texture(size, seed, **options))
    if "checker" not in spec:
        raise ValueError(f"a texture names one of checker, ripples, waves, puff, file or ies, got {sorted(spec)}")
    size_squares = spec.pop("checker")
    if not isinstance(size_squares, list) or len(size_squares) != 2 or not all(_is_int(v) for v in size_squares):
        raise ValueError(f"checker = [size, squares] (two integers), got {size_squares!r}")
    size, squares = size_squares
    colours: dict[str, Any] = {}
    for k in ("a", "b"):
        if k in spec:
            value = spec.pop(k)
            if not isinstance(value, list) or len(value) != 3 or not all(_is_int(c) and 0 <= c <= 255 for c in value):
                raise ValueError(f"checker texture: {k} must be three integers in [0, 255], got {value!r}")
            colours[k] = tuple(value)
    _no_more(spec, "checker texture")
    if name is not None:
        colours["name"] = name
    key = ("checker", size, squares, tuple(sorted(colours.items())))
    if 1 <= size <= MAX_TEXTURE_SIDE:  # else checker_texture says what is wrong
        where.budget.take(key, texture_bytes(size, size))
    return _cached(key, lambda: checker_texture(size, squares, **colours))


def level_sky_faces(spec: Any, where: LevelAssets) -> SkyFaces:
    """A ``Skybox.faces`` table: ``{ panorama = "sky.hdr" }`` with optional ``face_size``
    (default 256: FACE_SIZE), ``yaw`` (degrees), ``intensity`` (default 1), ``without_sun`` (default
    false: its sun taken out, for a DirectionalLight to give) and ``layer`` (an OpenEXR file's
    part or layer of that name): the panorama made into six faces
    (``engine/assets/panorama.py``; a star field or faces made in code are not written in files)."""
    if not isinstance(spec, dict) or "panorama" not in spec:
        raise ValueError("Skybox.faces in a level file is a panorama: { panorama = \"sky.hdr\", face_size = 256, "
                         f"yaw = 0 }} (faces made in code are not written in files), got {spec!r}")
    spec = dict(spec)
    path = _asset_path(spec.pop("panorama"), where)
    face_size, yaw, intensity = spec.pop("face_size", FACE_SIZE), spec.pop("yaw", 0.0), spec.pop("intensity", 1.0)
    without_sun, layer = spec.pop("without_sun", False), spec.pop("layer", None)
    _no_more(spec, "sky panorama")
    if layer is not None and not (isinstance(layer, str) and layer):
        raise ValueError(f"sky panorama: layer must be a non-empty string (an OpenEXR part or layer), got {layer!r}")
    if not isinstance(without_sun, bool):
        raise ValueError(f"sky panorama: without_sun must be true or false, got {without_sun!r}")
    if not (is_number(intensity) and 0.0 <= intensity <= MAX_INTENSITY):
        raise ValueError(f"sky panorama: intensity must be a number from 0 to {MAX_INTENSITY:g}, got {intensity!r}")
    if not _is_int(face_size) or not 1 <= face_size <= MAX_FACE_SIZE:
        raise ValueError(f"sky panorama: face_size must be an int from 1 to {MAX_FACE_SIZE}, got {face_size!r}")
    if not (is_number(yaw) and math.isfinite(yaw)):
        raise ValueError(f"sky panorama: yaw must be a finite number of degrees, got {yaw!r}")
    info = check_asset_file(path, f"panorama file {str(path)!r}", MAX_PANORAMA_FILE_BYTES)
    key = ("panorama", str(path), info.st_mtime_ns, info.st_size, info.st_ino, face_size, float(yaw), float(intensity),
           without_sun, layer)
    where.budget.take(key, 6 * face_size * face_size * 3 * 4)
    return _cached(key, lambda: sky_faces_from_file(path, face_size, float(yaw), float(intensity), without_sun,
                                                    layer))


def level_lut(spec: Any, where: LevelAssets) -> ColorLut:
    """The colour table ``ColorGrading.lut`` names: ``{ file = "grade.cube" }``, a ``.cube``
    3D table (engine/assets/color_lut.py)."""
    spec, _ = _asset_table(spec, "lut", '{ file = "grade.cube" }')
    if "file" not in spec:
        raise ValueError(f"a colour table names a .cube file: {{ file = \"grade.cube\" }}, got {sorted(spec)}")
    path = _asset_path(spec.pop("file"), where)
    _no_more(spec, "colour table")
    info = check_asset_file(path, f"colour table {str(path)!r}", MAX_LUT_FILE_BYTES)
    key = ("lut", str(path), info.st_mtime_ns, info.st_size, info.st_ino)
    lut = _cached(key, lambda: load_cube_lut(path))
    where.budget.take(key, lut.table.nbytes)
    return lut


def _ripples(spec: dict, name: Any, where: LevelAssets) -> TextureData:
    """``{ ripples = [size, rings] }`` with optional ``slope`` and ``name``: engine.assets.texture_data's
    ripple_normal_map."""
    return _generated_normal_map(spec, name, where, "ripples", "rings", {"slope": 0.5, "name": "ripples"},
                                 ripple_normal_map)


def _waves(spec: dict, name: Any, where: LevelAssets) -> TextureData:
    """``{ waves = [size, trains] }`` with optional ``slope``, ``seed`` and ``name``:
    engine.assets.texture_data's wave_normal_map."""
    return _generated_normal_map(spec, name, where, "waves", "trains", {"slope": 0.5, "seed": 0, "name": "waves"},
                                 wave_normal_map)


def _generated_normal_map(spec: dict, name: Any, where: LevelAssets, kind: str, count: str,
                          defaults: dict[str, Any], make: Callable[..., TextureData]) -> TextureData:
    """``{ <kind> = [size, <count>] }`` and the options ``defaults`` names (``slope`` a number,
    ``seed`` an integer, and ``name``): the generator ``make``'s map, one object for one call
    (it checks the ranges; here only the kinds, so the cache key is plain)."""
    size_count = spec.pop(kind)
    if not isinstance(size_count, list) or len(size_count) != 2 or not all(_is_int(v) for v in size_count):
        raise ValueError(f"{kind} = [size, {count}] (two integers), got {size_count!r}")
    options: dict[str, Any] = {}
    for option, fits, what in (("slope", is_number, "a number"), ("seed", _is_int, "an integer")):
        if option in defaults and option in spec:
            value = spec.pop(option)
            if not fits(value):
                raise ValueError(f"{kind} normal map: {option} must be {what}, got {value!r}")
            options[option] = float(value) if option == "slope" else value
    _no_more(spec, f"{kind} normal map")
    if name is not None:
        options["name"] = name
    size, number = size_count
    options = {k: v for k, v in options.items() if v != defaults[k]}  # written or left out: one map
    key = (kind, size, number, tuple(sorted(options.items())))
    if 1 <= size <= MAX_TEXTURE_SIDE:
        where.budget.take(key, texture_bytes(size, size))
    return _cached(key, lambda: make(size, number, **options))


def _asset_path(value: Any, where: LevelAssets) -> Path:
    """The file a level names, made absolute with its links followed, when it is inside the
    level's folder or an asset root; the refusal reads the same whether the file is there or not."""
    if not isinstance(value, str):
        raise ValueError(f"a file is a path string, got {value!r}")
    if not value or "\0" in value:
        raise ValueError(f"a file is a path, got {value!r}")
    path = contained_path(where.folder / value, where.roots)
    if path is None:
        roots = "" if len(where.roots) == 1 else f" and its asset roots ({', '.join(str(r) for r in where.roots[1:])})"
        raise ValueError(f"file {value!r} is outside the level's folder{roots}: a level's assets stay inside it "
                         "(a game may declare more asset roots, a player may pass --asset-root DIR)")
    return path


def _no_more(spec: dict, what: str) -> None:
    if spec:
        raise ValueError(f"{what}: unknown keys {sorted(spec)}")


_USER_ASSET_ROOTS: list[Path] = []


def set_asset_roots(roots: Iterable[str | Path]) -> None:
    """Folders every level loaded from now on may take assets from, besides its own folder
    and its game's ``asset_roots`` (the runner's ``--asset-root DIR``, the user's choice)."""
    _USER_ASSET_ROOTS[:] = [Path(root) for root in roots]


def user_asset_roots() -> list[Path]:
    """The folders ``set_asset_roots`` gave (what ``--asset-root`` allows)."""
    return list(_USER_ASSET_ROOTS)

