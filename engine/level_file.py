"""Level files: a level as TOML a person can edit, loaded into a world and saved back.

A level file has ``[level]`` (``name``, optional ``game``), an optional free-form ``[rules]``
table the game reads, and ``[[entity]]`` tables: a unique ``name`` and one table per
component, named by its class (``[entity.Transform]``) with the component's fields.
Vectors and colours are lists, a rotation is a quaternion ``[w, x, y, z]`` or
``{ yaw = .., pitch = .. }`` (degrees) or ``{ look = [x, y, z] }``; a mesh is a generator
(``{ box = [w, h, d] }``, ``{ quad = [w, h] }``, ``{ plane = [w, d], uv_repeat = r }``,
``{ sphere = r }``) or ``{ file = "x.obj" }``; a texture (``Material.texture``, ``Material.normal_map``)
``{ checker = [size, squares] }``, ``{ ripples = [size, rings] }`` (a normal map) or
``{ file = "x.png" }``; paths are relative to the level file. Entity references
(``Transform.parent``, ``Portal.partner``) are entity names. docs/level_files.md has the
whole format with an example.

Loading checks everything before anything is made (``load_level``): a mistake is a
``LevelError`` naming the file, the line, the entity and the field. ``Level.spawn`` then
creates the entities all or nothing. The same asset file (and the same generated mesh or
texture) loaded twice is one object, so the renderer uploads it once.
"""
from __future__ import annotations

import dataclasses
import math
import os
import re
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from pyglm import glm

import components as _components
from components import ComponentValueError, look_rotation, yaw_pitch_rotation
from engine.app import Game
from engine.capture import VALUE_KINDS, json_value
from engine.errors import AssetError, SpeculumError
from engine.mesh import Mesh, box, load_model, plane, quad, sphere
from engine.texture_data import TextureData, checker_texture, load_texture, ripple_normal_map
from engine.world import World

try:
    import tomllib
except ImportError:  # Python 3.10
    import tomli as tomllib

# The engine's components a level file may hold, by table name. PortalClone and Slice are
# made by the slice stage each frame (derived state), never written by hand.
ENGINE_COMPONENTS: dict[str, type] = {
    name: getattr(_components, name) for name in (
        "Camera", "DirectionalLight", "Emissive", "FlyController", "Material", "MeshRef", "Mirror", "PointLight",
        "Portal", "ReflectionProbe", "Reflective", "Refractive", "Skybox", "Transform", "Traveller")}
DERIVED_COMPONENTS = ("PortalClone", "Slice")
# Fields holding another entity: a name in the file, an id in the world.
REFERENCE_FIELDS = {("Transform", "parent"), ("Portal", "partner")}
_MESH_MAKERS: dict[str, Callable[..., Mesh]] = {"box": box, "quad": quad, "plane": plane, "sphere": sphere}


class LevelError(SpeculumError):
    """A level file that cannot be loaded: names the file, line, entity and field."""

    def __init__(self, file: str | Path, reason: str, line: int | None = None, entity: str | None = None,
                 field: str | None = None) -> None:
        self.file, self.line, self.entity, self.field, self.reason = str(file), line, entity, field, reason
        where = self.file + (f":{line}" if line else "")
        parts = [where]
        if entity is not None:
            parts.append(f"entity {entity!r}")
        if field is not None:
            parts.append(field)
        super().__init__(": ".join(parts) + f": {reason}")


# --- where things are in the text (tomllib gives no positions) ------------------------------

_TABLE = re.compile(r"^\s*\[\s*entity\.([A-Za-z_]\w*)\s*\]")
_KEY = re.compile(r"^\s*([A-Za-z_][\w]*)\s*=")


def _line_map(text: str) -> dict[tuple, int]:
    """Line numbers of each ``[[entity]]`` (key (i,)), component table ((i, Class)) and field
    ((i, Class, field)), by the entity's index in the file."""
    lines: dict[tuple, int] = {}
    entity, table = -1, None
    for number, raw in enumerate(text.splitlines(), start=1):
        stripped = raw.strip()
        if stripped.startswith("[[entity]]"):
            entity, table = entity + 1, None
            lines[(entity,)] = number
            continue
        match = _TABLE.match(raw)
        if match and entity >= 0:
            table = match.group(1)
            lines[(entity, table)] = number
            continue
        if stripped.startswith("["):
            entity, table = (entity if stripped.startswith("[entity") else -1), None
            continue
        match = _KEY.match(raw)
        if match and entity >= 0:
            key = match.group(1)
            if table is None:
                lines.setdefault((entity, key), number)  # an inline component table, or name
            else:
                lines.setdefault((entity, table, key), number)
    return lines


# --- assets ------------------------------------------------------------------------------------

_ASSETS: dict[tuple, Any] = {}  # one Mesh / TextureData per file (and modification time) or generator call


def _cached(key: tuple, make: Callable[[], Any]) -> Any:
    value = _ASSETS.get(key)
    if value is None:
        value = _ASSETS[key] = make()
    return value


def _mesh(spec: Any, folder: Path) -> Mesh:
    if not isinstance(spec, Mapping):
        raise ValueError(f"a mesh is a table such as {{ box = [1, 1, 1] }} or {{ file = \"x.obj\" }}, got {spec!r}")
    spec = dict(spec)
    name = spec.pop("name", None)
    if "file" in spec:
        path = _asset_path(spec.pop("file"), folder)
        part = spec.pop("part", None)
        _no_more(spec, "mesh file")
        if not path.is_file():
            raise ValueError(f"mesh file {str(path)!r}: no such file")
        parts = _cached(("model", str(path), path.stat().st_mtime_ns), lambda: load_model(path))
        names = [p.mesh.name for p in parts]
        if part is None and len(parts) > 1:
            raise ValueError(f"mesh file {str(path)!r} has {len(parts)} parts {names}: say which with part = \"...\"")
        # A part by its name in the file ("left") or as the engine names it ("two.obj:left").
        chosen = parts[0] if part is None else next(
            (p for p in parts if part in (p.mesh.name, p.mesh.name.split(":", 1)[-1])), None)
        if chosen is None:
            raise ValueError(f"mesh file {str(path)!r} has no part {part!r} (parts: {names})")
        chosen.mesh.source = {"file": str(path), **({"part": part} if part is not None else {})}
        return chosen.mesh
    kinds = [k for k in spec if k in _MESH_MAKERS]
    if len(kinds) != 1:
        raise ValueError(f"a mesh names one of {sorted(_MESH_MAKERS)} or file, got {sorted(spec)}")
    kind = kinds[0]
    size = spec.pop(kind)
    options = {k: spec.pop(k) for k in ("uv_repeat", "segments", "rings") if k in spec}
    _no_more(spec, f"{kind} mesh")
    if kind == "box":
        args: tuple = (tuple(float(v) for v in size),)
        if len(args[0]) != 3:
            raise ValueError(f"box = [w, h, d], got {size!r}")
    elif kind == "sphere":
        args = (float(size),)
    else:
        args = tuple(float(v) for v in size)
        if len(args) != 2:
            raise ValueError(f"{kind} = [w, {'h' if kind == 'quad' else 'd'}], got {size!r}")
    if name is not None:
        options["name"] = str(name)
    key = ("mesh", kind, args, tuple(sorted(options.items())))
    return _cached(key, lambda: _MESH_MAKERS[kind](*args, **options))  # the generator records its source


def _texture(spec: Any, folder: Path) -> TextureData:
    if not isinstance(spec, Mapping):
        raise ValueError(f"a texture is a table such as {{ checker = [128, 8] }}, {{ ripples = [256, 6] }} or "
                         f"{{ file = \"x.png\" }}, got {spec!r}")
    spec = dict(spec)
    name = spec.pop("name", None)
    if "file" in spec:
        path = _asset_path(spec.pop("file"), folder)
        _no_more(spec, "texture file")
        if not path.is_file():
            raise ValueError(f"texture file {str(path)!r}: no such file")
        return _cached(("texture", str(path), path.stat().st_mtime_ns), lambda: load_texture(path))
    if "ripples" in spec and "checker" not in spec:
        return _ripples(spec, name)
    if "checker" not in spec:
        raise ValueError(f"a texture names one of checker, ripples or file, got {sorted(spec)}")
    size, squares = (int(v) for v in spec.pop("checker"))
    colours = {k: tuple(int(c) for c in spec.pop(k)) for k in ("a", "b") if k in spec}
    _no_more(spec, "checker texture")
    if name is not None:
        colours["name"] = str(name)
    key = ("checker", size, squares, tuple(sorted(colours.items())))
    return _cached(key, lambda: checker_texture(size, squares, **colours))


def _ripples(spec: dict, name: Any) -> TextureData:
    """``{ ripples = [size, rings] }`` with optional ``slope`` and ``name``: engine.texture_data's
    ripple_normal_map (it checks the ranges; here only the kinds, so the cache key is plain)."""
    size_rings = spec.pop("ripples")
    if not isinstance(size_rings, list) or len(size_rings) != 2 or \
            not all(isinstance(v, int) and not isinstance(v, bool) for v in size_rings):
        raise ValueError(f"ripples = [size, rings] (two integers), got {size_rings!r}")
    options: dict[str, Any] = {}
    if "slope" in spec:
        slope = spec.pop("slope")
        if isinstance(slope, bool) or not isinstance(slope, (int, float)):
            raise ValueError(f"ripples normal map: slope must be a number, got {slope!r}")
        options["slope"] = float(slope)
    _no_more(spec, "ripples normal map")
    if name is not None:
        if not isinstance(name, str):
            raise ValueError(f"ripples normal map: name must be a string, got {name!r}")
        options["name"] = name
    size, rings = size_rings
    defaults = {"slope": 0.5, "name": "ripples"}  # written or left out: one map
    options = {k: v for k, v in options.items() if v != defaults[k]}
    key = ("ripples", size, rings, tuple(sorted(options.items())))
    return _cached(key, lambda: ripple_normal_map(size, rings, **options))


def _asset_path(value: Any, folder: Path) -> Path:
    if not isinstance(value, str):
        raise ValueError(f"a file is a path string, got {value!r}")
    return (folder / value).resolve()


def _no_more(spec: dict, what: str) -> None:
    if spec:
        raise ValueError(f"{what}: unknown keys {sorted(spec)}")


def _rotation(value: Any) -> glm.quat:
    if isinstance(value, Mapping):
        extra = set(value) - {"yaw", "pitch", "look", "up"}
        if extra or not ({"yaw", "pitch"} & set(value) or "look" in value):
            raise ValueError(f"a rotation table is {{ yaw = deg, pitch = deg }} or {{ look = [x, y, z] }}, "
                             f"got {dict(value)!r}")
        if "look" in value:
            return look_rotation(tuple(value["look"]), tuple(value.get("up", (0.0, 1.0, 0.0))))
        return yaw_pitch_rotation(float(value.get("yaw", 0.0)), float(value.get("pitch", 0.0)))
    if isinstance(value, (list, tuple)) and len(value) == 4 and not any(isinstance(v, (bool, str)) for v in value):
        return glm.quat(*(float(v) for v in value))
    raise ValueError(f"a rotation is [w, x, y, z] or {{ yaw = .., pitch = .. }} or {{ look = [..] }}, got {value!r}")


# --- the level ---------------------------------------------------------------------------------

@dataclasses.dataclass
class _EntitySpec:
    name: str
    index: int
    components: list[tuple[type, dict[str, Any]]]   # class, constructor fields (references left out)
    references: list[tuple[str, str, str]]          # (class name, field, entity name)


class Level:
    """A checked level file: ``name``, ``game``, ``rules`` and the entities to spawn."""

    def __init__(self, path: Path, name: str, game: str | None, rules: dict[str, Any],
                 entities: list[_EntitySpec], lines: dict[tuple, int]) -> None:
        self.path = path
        self.name = name
        self.game = game
        self.rules = rules
        self._entities = entities
        self._lines = lines

    @property
    def entity_names(self) -> list[str]:
        return [e.name for e in self._entities]

    def spawn(self, world: World) -> dict[str, int]:
        """Create every entity (fresh components each call); returns ids by name. All or
        nothing: a failure deletes what this call made and raises a LevelError."""
        made: dict[str, int] = {}
        spec: _EntitySpec | None = None
        try:
            for spec in self._entities:
                made[spec.name] = world.spawn(*(cls(**fields) for cls, fields in spec.components))
            for spec in self._entities:
                for cls_name, field, target in spec.references:
                    component = next(c for c in world.components_of(made[spec.name])
                                     if type(c).__name__ == cls_name)
                    setattr(component, field, made[target])
        except (ComponentValueError, SpeculumError, ValueError) as exc:
            for entity in made.values():
                if world.exists(entity):
                    world.delete_entity(entity)
            line = self._lines.get((spec.index,)) if spec is not None else None
            raise LevelError(self.path, str(exc), line, spec.name if spec is not None else None) from exc
        return made


def load_level(path: str | Path, extra_components: Mapping[str, type] | None = None) -> Level:
    """Read and check the level file at ``path``; nothing is created (``Level.spawn`` does).
    ``extra_components``: a game's own plain-data components allowed in the file, by name."""
    if isinstance(path, bytes) or not isinstance(path, (str, os.PathLike)):
        raise LevelError(repr(path), f"a level file path is a str or pathlib.Path, got {type(path).__name__}")
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise LevelError(path, "no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise LevelError(path, f"cannot be read ({exc})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        match = re.search(r"line (\d+)", str(exc))
        raise LevelError(path, f"not valid TOML ({exc})", int(match.group(1)) if match else None) from None
    lines = _line_map(text)
    known = {**ENGINE_COMPONENTS, **(extra_components or {})}
    unknown_top = set(data) - {"level", "rules", "entity"}
    if unknown_top:
        raise LevelError(path, f"unknown top-level tables {sorted(unknown_top)} (a level has [level], [rules] and "
                               "[[entity]])")
    header = data.get("level")
    if not isinstance(header, dict) or not isinstance(header.get("name"), str) or not header["name"]:
        raise LevelError(path, "[level] needs name = \"...\" (the level's title)")
    extra = set(header) - {"name", "game"}
    if extra:
        raise LevelError(path, f"[level] has unknown keys {sorted(extra)} (name, game)")
    game = header.get("game")
    if game is not None and not isinstance(game, str):
        raise LevelError(path, f"[level] game must be a string, got {game!r}")
    rules = data.get("rules", {})
    if not isinstance(rules, dict):
        raise LevelError(path, "[rules] must be a table")
    tables = data.get("entity", [])
    if not isinstance(tables, list):
        raise LevelError(path, "entities are [[entity]] tables")
    folder = path.parent
    names: dict[str, int] = {}
    entities = []
    for index, table in enumerate(tables):
        line = lines.get((index,))
        name = table.get("name")
        if not isinstance(name, str) or not name:
            raise LevelError(path, "every [[entity]] needs name = \"...\"", line)
        if name in names:
            raise LevelError(path, f"the name is used twice (first at entity {names[name] + 1})", line, name)
        names[name] = index
        entities.append(_entity(path, folder, index, name, table, known, lines))
    for spec in entities:
        for cls_name, field, target in spec.references:
            if target not in names:
                raise LevelError(path, f"names no entity in this file, got {target!r}",
                                 lines.get((spec.index, cls_name, field), lines.get((spec.index, cls_name))),
                                 spec.name, f"{cls_name}.{field}")
            if target == spec.name:
                raise LevelError(path, "names the entity itself", lines.get((spec.index, cls_name, field)), spec.name,
                                 f"{cls_name}.{field}")
    _check_parent_cycles(path, entities, lines)
    return Level(path, header["name"], game, rules, entities, lines)


def _entity(path: Path, folder: Path, index: int, name: str, table: dict[str, Any], known: Mapping[str, type],
            lines: dict[tuple, int]) -> _EntitySpec:
    parts: list[tuple[type, dict[str, Any]]] = []
    references: list[tuple[str, str, str]] = []
    for key, fields in table.items():
        if key == "name":
            continue
        line = lines.get((index, key))
        if key in DERIVED_COMPONENTS:
            raise LevelError(path, f"{key} is made by the engine each frame, not written in a level", line, name)
        cls = known.get(key)
        if cls is None:
            raise LevelError(path, f"no component {key!r} (components: {', '.join(sorted(known))})", line, name)
        if not isinstance(fields, dict):
            raise LevelError(path, f"[entity.{key}] must be a table of fields, got {fields!r}", line, name)
        allowed = {f.name: f for f in dataclasses.fields(cls) if f.init and not f.name.startswith("_")} \
            if dataclasses.is_dataclass(cls) else None
        decoded: dict[str, Any] = {}
        for field, value in fields.items():
            where = lines.get((index, key, field), line)
            if allowed is not None and field not in allowed:
                raise LevelError(path, f"{key} has no field {field!r} (fields: {', '.join(sorted(allowed))})", where,
                                 name, f"{key}.{field}")
            if (key, field) in REFERENCE_FIELDS:
                if not isinstance(value, str):
                    raise LevelError(path, f"must be an entity's name, got {value!r}", where, name, f"{key}.{field}")
                references.append((key, field, value))
                continue
            try:
                decoded[field] = _decode(key, field, value, folder)
            except (ValueError, TypeError, OverflowError, AssetError) as exc:
                raise LevelError(path, str(exc), where, name, f"{key}.{field}") from None
        try:
            cls(**decoded)  # the component's own checks, now, not at spawn
        except ComponentValueError as exc:
            match = re.match(r"(\w+)\.(\w+)", str(exc))
            field = match.group(2) if match and match.group(1) == key else None
            raise LevelError(path, str(exc), lines.get((index, key, field), line) if field else line, name,
                             f"{key}.{field}" if field else key) from None
        except TypeError as exc:
            raise LevelError(path, str(exc), line, name, key) from None
        parts.append((cls, decoded))
    return _EntitySpec(name, index, parts, references)


def _decode(cls_name: str, field: str, value: Any, folder: Path) -> Any:
    if cls_name == "MeshRef" and field == "mesh":
        return _mesh(value, folder)
    if field == "texture" or (cls_name, field) == ("Material", "normal_map"):
        return _texture(value, folder)
    if cls_name == "Transform" and field == "rotation":
        return _rotation(value)
    if cls_name == "Skybox" and field == "faces":
        raise ValueError("Skybox.faces (generated pixel data) is not written in level files; leave it out")
    return value


def _check_parent_cycles(path: Path, entities: list[_EntitySpec], lines: dict[tuple, int]) -> None:
    parent = {s.name: t for s in entities for c, f, t in s.references if (c, f) == ("Transform", "parent")}
    for spec in entities:
        seen, walk = {spec.name}, parent.get(spec.name)
        while walk is not None:
            if walk in seen:
                raise LevelError(path, f"parents make a cycle through {walk!r}",
                                 lines.get((spec.index, "Transform", "parent")), spec.name, "Transform.parent")
            seen.add(walk)
            walk = parent.get(walk)


# --- saving ------------------------------------------------------------------------------------

def save_level(world: World, path: str | Path, names: Mapping[str, int] | None = None, name: str = "level",
               game: str | None = None, rules: Mapping[str, Any] | None = None,
               extra_components: Mapping[str, type] | None = None) -> Path:
    """Write ``world`` as a level file: every entity (``names`` gives names by id; others are
    called ``entity_<id>``), each component's fields that differ from their defaults.
    Derived state (portal clones, slices) is left out; a mesh or texture not made by a
    generator or loaded from a file cannot be written and raises a LevelError."""
    import tomli_w

    path = Path(path)
    known = {**ENGINE_COMPONENTS, **(extra_components or {})}
    by_id = {entity: n for n, entity in (names or {}).items()}
    entities = [e for e in sorted(world.entities())
                if not any(type(c).__name__ == "PortalClone" for c in world.components_of(e))]
    for entity in entities:
        by_id.setdefault(entity, f"entity_{entity}")
    tables = []
    for entity in entities:
        table: dict[str, Any] = {"name": by_id[entity]}
        for component in sorted(world.components_of(entity), key=_component_order):
            cls_name = type(component).__name__
            if cls_name in DERIVED_COMPONENTS or known.get(cls_name) is not type(component):
                if cls_name in DERIVED_COMPONENTS:
                    continue
                raise LevelError(path, f"component {cls_name} is not one a level file holds (pass the game's own "
                                       "with extra_components)", entity=by_id[entity])
            table[cls_name] = _encode_component(path, component, by_id, by_id[entity])
        tables.append(table)
    text = tomli_w.dumps({"level": {"name": name, **({"game": game} if game else {})}})
    if rules:
        text += "\n" + tomli_w.dumps({"rules": dict(rules)})
    for table in tables:
        text += f"\n[[entity]]\nname = {_literal(table['name'])}\n"
        for cls_name, fields in table.items():
            if cls_name != "name":
                text += f"[entity.{cls_name}]\n" + "".join(f"{_key(k)} = {_literal(v)}\n" for k, v in fields.items())
    path.write_text(text, encoding="utf-8")
    return path


def _key(key: str) -> str:
    import tomli_w

    return tomli_w.dumps({key: 0}).split(" = ")[0]


def _literal(value: Any) -> str:
    """One value on one line: tomli-w writes each list item on a line of its own, which
    makes a level of vectors unreadable, so the layout is ours and tomli-w formats only
    strings (its escaping)."""
    import tomli_w

    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value) if not isinstance(value, float) or math.isfinite(value) else \
            ("nan" if math.isnan(value) else ("inf" if value > 0 else "-inf"))
    if isinstance(value, str):
        return tomli_w.dumps({"s": value})[4:].rstrip("\n")
    if isinstance(value, list):
        return "[" + ", ".join(_literal(v) for v in value) + "]"
    if isinstance(value, Mapping):
        return "{ " + ", ".join(f"{_key(k)} = {_literal(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {type(value).__name__} in a level file")


def _component_order(component: Any) -> tuple[int, str]:
    """Where an entity's tables go in a file: where it is, what it looks like, then the rest."""
    name = type(component).__name__
    first = ("Transform", "MeshRef", "Material")
    return (first.index(name) if name in first else len(first), name)


def _encode_component(path: Path, component: Any, by_id: Mapping[int, str], entity: str) -> dict[str, Any]:
    cls = type(component)
    out: dict[str, Any] = {}
    fields = [f for f in dataclasses.fields(cls) if f.init and not f.name.startswith("_")] \
        if dataclasses.is_dataclass(cls) else []
    try:
        defaults = cls()  # the defaults as the component holds them (a direction normalised, ...)
    except (TypeError, ComponentValueError):
        defaults = None
    for f in fields:
        value = getattr(component, f.name)
        if defaults is not None:
            default = getattr(defaults, f.name)
        else:
            default = f.default if f.default is not dataclasses.MISSING else (
                f.default_factory() if f.default_factory is not dataclasses.MISSING else dataclasses.MISSING)
        if default is not dataclasses.MISSING and _same(value, default):
            continue
        where = f"{cls.__name__}.{f.name}"
        if value is None:
            raise LevelError(path, f"is None where the default is {default!r}: TOML has no None", None, entity, where)
        if (cls.__name__, f.name) in REFERENCE_FIELDS:
            out[f.name] = by_id.get(value, f"entity_{value}")
        elif isinstance(value, (Mesh, TextureData)):
            source = getattr(value, "source", None)
            if source is None:
                raise LevelError(path, f"{type(value).__name__} {value.name!r} was not made by a generator or loaded "
                                       "from a file, so a level file cannot name it", None, entity, where)
            out[f.name] = _relative(source, path.parent)
        else:
            out[f.name] = _plain(value, path, entity, where)
    return out


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return a is b
    try:
        return bool(a == b) and type(a) is type(b) or (_plain_or_none(a) == _plain_or_none(b) is not None)
    except (TypeError, ValueError):
        return False


def _plain_or_none(value: Any) -> Any:
    try:
        return _plain(value, Path("."), "", "")
    except LevelError:
        return None


def _plain(value: Any, path: Path, entity: str, where: str) -> Any:
    """A field value as TOML: scene.json's encoder (``engine.capture.json_value``: vectors as
    lists, quaternions ``[w, x, y, z]``), floats kept as numbers (TOML has inf and nan) and
    float32 vectors at their shortest decimal; meshes, textures, arrays, matrices and other
    objects cannot be written in a level."""
    if isinstance(value, (list, tuple)):
        return [_plain(v, path, entity, where) for v in value]
    data, kind = json_value(value)
    if kind in ("bool", "int", "str"):
        return data
    if kind == "float":
        return float(value)
    if kind in ("vec2", "vec3", "vec4", "quat"):
        return [_f32(v) for v in data]
    raise LevelError(path, f"a {type(value).__name__} ({kind}: {VALUE_KINDS[kind]}) cannot be written in a level "
                           "file", None, entity, where)


def _f32(value: float) -> float:
    """The shortest decimal that reads back as the same float32 (1.7, not 1.7000000476837158)."""
    return float(np.format_float_positional(np.float32(value), unique=True, trim="0"))


def _relative(source: dict[str, Any], folder: Path) -> dict[str, Any]:
    if "file" not in source:
        return dict(source)
    return {**source, "file": Path(os.path.relpath(source["file"], folder)).as_posix()}


# --- a game whose level is a file -------------------------------------------------------------

class LevelGame(Game):
    """A game that builds its world from a level file (``--level FILE`` replaces it).

    ``components``: the game's own plain-data components its files may hold, by name.
    After ``build``: ``level`` (the checked file) and ``names`` (entity ids by name)."""

    components: Mapping[str, type] = {}

    def __init__(self, level_path: str | Path) -> None:
        self.level_path = Path(level_path)
        self.level: Level | None = None
        self.names: dict[str, int] = {}

    def build(self, world: World) -> None:
        self.level = load_level(self.level_path, self.components)
        self.names = self.level.spawn(world)


def same_floats(a: Any, b: Any, tolerance: float = 1e-6) -> bool:
    """Whether two plain values (numbers, lists of them, strings, tables) are equal, floats
    within ``tolerance`` (a level saved and loaded again passes its numbers through float32)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same_floats(a[k], b[k], tolerance) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same_floats(x, y, tolerance) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) or isinstance(b, float):
        return isinstance(a, (int, float)) and isinstance(b, (int, float)) and math.isclose(
            a, b, rel_tol=tolerance, abs_tol=tolerance)
    return a == b
