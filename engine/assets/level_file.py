"""Level files: a level as TOML a person can edit, loaded into a world and saved back.

A level file has ``[level]`` (``name``, optional ``game``), an optional free-form ``[rules]``
table the game reads, and ``[[entity]]`` tables: a unique ``name`` and one table per
component, named by its class (``[entity.Transform]``) with the component's fields.
Vectors and colours are lists, a rotation is a quaternion ``[w, x, y, z]`` or
``{ yaw = .., pitch = .. }`` (degrees) or ``{ look = [x, y, z] }``; a mesh is a generator
(``{ box = [w, h, d] }``, ``{ quad = [w, h] }``, ``{ plane = [w, d], uv_repeat = r }``,
``{ sphere = r }``) or ``{ file = "x.obj" }``; a texture (``Material.texture``, ``normal_map``,
``emissive_map``, ``metallic_roughness_map``) ``{ checker = [size, squares] }``,
``{ ripples = [size, rings] }`` (a normal map) or ``{ file = "x.png" }``; paths are relative
to the level file and stay inside its folder (or an asset root: ``LevelGame.asset_roots``,
``--asset-root DIR``). Entity references
(``Transform.parent``, ``Portal.partner``) are entity names. docs/level_files.md has the
whole format with an example.

Loading checks everything before anything is made (``load_level``): a mistake is a
``LevelError`` naming the file, the line, the entity and the field. A level is data a stranger
may have written: whatever file it names (a symlink loop, a FIFO, a device, an image bomb, a
file nested past any parser's depth, a path outside its folder), loading ends in the level or
in a LevelError, within ``LEVEL_MEMORY_BUDGET``. ``Level.spawn`` then
creates the entities all or nothing. The same asset file (and the same generated mesh or
texture) loaded twice is one object, so the renderer uploads it once.

The meshes and textures a level names, its asset roots (``set_asset_roots``) and its memory
budget are engine.assets.level_assets (``LEVEL_MEMORY_BUDGET`` is importable from here too).
"""
from __future__ import annotations

import dataclasses
import math
import os
import re
import types
import typing
from collections.abc import Collection, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from pyglm import glm

import components as _components
from components import ComponentValueError, look_rotation, yaw_pitch_rotation
from engine.assets.level_assets import LEVEL_MEMORY_BUDGET as LEVEL_MEMORY_BUDGET  # named by its error and docs
from engine.assets.level_assets import LevelAssets, is_number, level_mesh, level_texture, user_asset_roots
from engine.assets.mesh import Mesh
from engine.assets.texture_data import TextureData, file_problem
from engine.assets.values import VALUE_KINDS, json_value
from engine.core.budget import ViewBudget, ViewBudgetError
from engine.core.errors import AssetError, SpeculumError
from engine.core.game import Game
from engine.core.world import World, check_components

try:
    import tomllib
except ImportError:  # Python 3.10
    import tomli as tomllib

# The engine's components a level file may hold, by table name. PortalClone and Slice are
# made by the slice stage each frame (derived state), never written by hand.
ENGINE_COMPONENTS: dict[str, type] = {
    name: getattr(_components, name) for name in (
        "Bloom", "Camera", "DirectionalLight", "Emissive", "FlyController", "HemisphereLight", "Material", "MeshRef",
        "Mirror", "PointLight", "Portal", "ReflectionProbe", "Reflective", "Refractive", "ScreenPanel", "ScreenText",
        "Skybox", "Tonemap",
        "Transform", "Traveller", "Visibility", "Water")}
DERIVED_COMPONENTS = ("PortalClone", "Slice")
# Fields holding another entity: a name in the file, an id in the world.
REFERENCE_FIELDS = {("Transform", "parent"), ("Portal", "partner")}
MAX_LEVEL_BYTES = 4 << 20  # a level file's size (the shipped ones are a few KB)
MAX_NESTING = 16  # arrays and inline tables inside one value (a level needs three at most)


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
_KEY = re.compile(r"^\s*([A-Za-z_][\w-]*)\s*=")
_HEADER = re.compile(r"^\s*\[\[?\s*([A-Za-z0-9_-]+)")


def _line_map(text: str) -> dict[tuple, int]:
    """Line numbers of each ``[[entity]]`` (key (i,)), component table ((i, Class)) and field
    ((i, Class, field)), by the entity's index in the file; of the other tables' headers
    (("table", name): ``[level]``, a misspelt ``[[entitty]]``, and a key before any table),
    and their keys (("level", key), ("rules", key))."""
    lines: dict[tuple, int] = {}
    entity, table, section = -1, None, None
    for number, raw in enumerate(text.splitlines(), start=1):
        stripped = raw.strip()
        header = _HEADER.match(raw) if stripped.startswith("[") else None
        if header:
            lines.setdefault(("table", header.group(1)), number)
        if stripped.startswith("[[entity]]"):
            entity, table, section = entity + 1, None, None
            lines[(entity,)] = number
            continue
        match = _TABLE.match(raw)
        if match and entity >= 0:
            table = match.group(1)
            lines[(entity, table)] = number
            continue
        if stripped.startswith("["):
            entity, table = (entity if stripped.startswith("[entity") else -1), None
            section = None if stripped.startswith("[entity") or not header else header.group(1)
            continue
        match = _KEY.match(raw)
        if match and entity >= 0:
            key = match.group(1)
            if table is None:
                lines.setdefault((entity, key), number)  # an inline component table, or name
            else:
                lines.setdefault((entity, table, key), number)
        elif match:
            lines.setdefault((section, match.group(1)) if section else ("table", match.group(1)), number)
    return lines


def _depth(value: Any) -> int:
    """How deep arrays and tables nest in ``value`` (a number is 0, ``[1]`` is 1; past
    MAX_NESTING the walk stops at MAX_NESTING + 1), without recursion."""
    deepest, stack = 0, [(value, 0)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, (list, dict)):
            deepest = max(deepest, depth + 1)
            if deepest > MAX_NESTING:
                return deepest
            stack.extend((child, depth + 1) for child in (item.values() if isinstance(item, dict) else item))
    return deepest


def _deep_line(text: str) -> int | None:
    """The first line where brackets and braces outside strings and comments nest past
    ``MAX_NESTING`` (for a file too deep for the TOML parser to say where)."""
    depth, line, i, n = 0, 1, 0, len(text)
    while i < n:
        c = text[i]
        if c == "\n":
            line += 1
        elif c == "#":
            end = text.find("\n", i)
            i = n if end < 0 else end
            continue
        elif c in "\"'":
            quote = text[i:i + 3] if text[i:i + 3] in ('"""', "'''") else c
            j = i + len(quote)
            while j < n and not text.startswith(quote, j):
                if text[j] == "\\" and c == '"':
                    j += 1
                elif text[j] == "\n":
                    if len(quote) == 1:
                        break
                    line += 1
                j += 1
            i = j + len(quote)
            continue
        elif c in "[{":
            depth += 1
            if depth > MAX_NESTING + 2:  # a [[table]] header is two of them
                return line
        elif c in "]}":
            depth = max(0, depth - 1)
        i += 1
    return None




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
                 entities: list[_EntitySpec], lines: dict[tuple, int], view_budget: ViewBudget | None = None) -> None:
        self.path = path
        self.name = name
        self.game = game
        self.rules = rules
        self.view_budget = view_budget  # [level] view_budget: spawn makes it the world's
        self._entities = entities
        self._lines = lines

    @property
    def entity_names(self) -> list[str]:
        return [e.name for e in self._entities]

    @property
    def has_camera(self) -> bool:
        """Whether an entity has a Camera (not turned off) and a Transform: what the main view
        looks through."""
        return any(any(cls.__name__ == "Camera" and fields.get("active", True) is not False
                       for cls, fields in spec.components)
                   and any(cls.__name__ == "Transform" for cls, _ in spec.components) for spec in self._entities)

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
        if self.view_budget is not None:
            world.resources[ViewBudget] = self.view_budget
        return made



def load_level(path: str | Path, extra_components: Mapping[str, type] | None = None,
               asset_roots: Iterable[str | Path] = (), for_game: str | None = None) -> Level:
    """Read and check the level file at ``path``; nothing is created (``Level.spawn`` does).
    ``extra_components``: a game's own plain-data components allowed in the file, by name.
    ``asset_roots``: folders besides the level's own that its ``file = ...`` may name (a
    game's shared assets); the ones ``set_asset_roots`` gave are allowed too.  ``for_game``:
    the game that will play it (``LevelGame.game``): a level whose ``[level] game`` names
    another is refused as such from its header, before any entity or component is read (its
    components are that game's, and would only be reported as unknown)."""
    if isinstance(path, bytes) or not isinstance(path, (str, os.PathLike)):
        raise LevelError(repr(path), f"a level file path is a str or pathlib.Path, got {type(path).__name__}")
    path = Path(path)
    problem, _info = file_problem(path, MAX_LEVEL_BYTES)
    if problem is not None:
        raise LevelError(path, problem)
    try:
        text = path.read_bytes().decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise LevelError(path, f"cannot be read ({exc})") from None
    except MemoryError:
        raise LevelError(path, "does not fit in memory") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        match = re.search(r"line (\d+)", str(exc))
        raise LevelError(path, f"not valid TOML ({exc})", int(match.group(1)) if match else None) from None
    except RecursionError:
        raise LevelError(path, f"arrays or inline tables nested too deeply (at most {MAX_NESTING})",
                         _deep_line(text)) from None
    except MemoryError:
        raise LevelError(path, "does not fit in memory") from None
    lines = _line_map(text)
    known = {**ENGINE_COMPONENTS, **(extra_components or {})}
    unknown_top = [key for key in data if key not in ("level", "rules", "entity")]
    if unknown_top:
        raise LevelError(path, f"unknown top-level tables {sorted(unknown_top)} (a level has [level], [rules] and "
                               "[[entity]])", lines.get(("table", unknown_top[0])))
    header = data.get("level")
    if not isinstance(header, dict) or not isinstance(header.get("name"), str) or not header["name"]:
        line = lines.get(("level", "name")) if isinstance(header, dict) and "name" in header else \
            lines.get(("table", "level"))
        raise LevelError(path, "[level] needs name = \"...\" (the level's title)", line)
    extra = [key for key in header if key not in ("name", "game", "view_budget")]
    if extra:
        raise LevelError(path, f"[level] has unknown keys {sorted(extra)} (name, game, view_budget)",
                         lines.get(("level", extra[0])))
    budget = _view_budget(path, header.get("view_budget"), lines.get(("level", "view_budget")))
    game = header.get("game")
    if game is not None and not isinstance(game, str):
        raise LevelError(path, f"[level] game must be a string, got {_short(game)}", lines.get(("level", "game")))
    if for_game is not None and game is not None and game != for_game:
        raise LevelError(path, _other_game(game, for_game), lines.get(("level", "game")))
    rules = data.get("rules", {})
    if not isinstance(rules, dict):
        raise LevelError(path, "[rules] must be a table", lines.get(("table", "rules")))
    for key, value in rules.items():
        if _depth(value) > MAX_NESTING:
            raise LevelError(path, f"[rules] {key}: arrays or inline tables nested too deeply (at most {MAX_NESTING})",
                             lines.get(("rules", key), lines.get(("table", "rules"))))
    tables = data.get("entity", [])
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise LevelError(path, "entities are [[entity]] tables", lines.get(("table", "entity")))
    where = LevelAssets(path.parent, [*(Path(r) for r in asset_roots), *user_asset_roots()])
    names: dict[str, int] = {}
    entities = []
    for index, table in enumerate(tables):
        line = lines.get((index,))
        name = table.get("name")
        if not isinstance(name, str) or not name:
            raise LevelError(path, "every [[entity]] needs name = \"...\"", lines.get((index, "name"), line))
        if name in names:
            raise LevelError(path, f"the name is used twice (first at entity {names[name] + 1})", line, name)
        names[name] = index
        entities.append(_entity(path, where, index, name, table, known, lines))
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
    return Level(path, header["name"], game, rules, entities, lines, budget)


def _view_budget(path: Path, table: Any, line: int | None) -> ViewBudget | None:
    """``[level] view_budget = { views = 24, pixels = 400000, probe_ms = 2.0 }``: the
    frame's ``ViewBudget`` (engine.core.budget), each field optional, checked as in Python."""
    if table is None:
        return None
    if not isinstance(table, dict):
        raise LevelError(path, f"[level] view_budget must be a table such as {{ views = 24 }}, got {_short(table)}",
                         line)
    unknown = sorted(set(table) - {"views", "pixels", "probe_ms"})
    if unknown:
        raise LevelError(path, f"[level] view_budget has unknown keys {unknown} (views, pixels, probe_ms)", line)
    try:
        return ViewBudget(**table)
    except ViewBudgetError as exc:
        raise LevelError(path, f"[level] view_budget: {exc}", line) from None


def _other_game(game: str, playing: str) -> str:
    """The refusal of a level made for another game."""
    return f"[level] game = {game!r}: the level is for {game}, not for {playing} (play it with that game)"


def _short(value: Any) -> str:
    """A value for a message, cut short (a stranger's value may be long)."""
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _entity(path: Path, assets: LevelAssets, index: int, name: str, table: dict[str, Any], known: Mapping[str, type],
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
        deep = [f for f, v in fields.items() if _depth(v) > MAX_NESTING] if isinstance(fields, dict) else \
            ([None] if _depth(fields) > MAX_NESTING else [])
        if deep:
            raise LevelError(path, f"arrays or inline tables nested too deeply (at most {MAX_NESTING})",
                             lines.get((index, key, deep[0]), line), name, f"{key}.{deep[0]}" if deep[0] else key)
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
            if key not in ENGINE_COMPONENTS and allowed is not None:
                problem = _annotation_problem(cls, field, value)
                if problem is not None:
                    raise LevelError(path, problem, where, name, f"{key}.{field}")
            try:
                decoded[field] = _decode(key, field, value, assets)
            except (ValueError, TypeError, OverflowError, AssetError) as exc:
                raise LevelError(path, str(exc), where, name, f"{key}.{field}") from None
            except MemoryError:
                raise LevelError(path, "does not fit in memory", where, name, f"{key}.{field}") from None
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
    _check_mirror(path, index, name, parts, lines)
    _check_water(path, index, name, parts, lines)
    return _EntitySpec(name, index, parts, references)


def _check_water(path: Path, index: int, name: str, parts: list[tuple[type, dict[str, Any]]],
                 lines: dict[tuple, int]) -> None:
    """A Water makes its entity's Mirror water (systems/surface_system.py refuses the same in
    a world): it needs one, and a sharp one (the waves break up the image, not a blur)."""
    fields = {cls.__name__: decoded for cls, decoded in parts}
    if "Water" not in fields:
        return
    if "Mirror" not in fields:
        raise LevelError(path, "a Water needs a Mirror on the same entity (the surface it makes water)",
                         lines.get((index, "Water")), name, "Water")
    roughness = fields["Mirror"].get("roughness", 0.0)
    if roughness > 0.0:
        raise LevelError(path, f"a water surface is sharp: its Mirror.roughness must be 0, got {roughness}",
                         lines.get((index, "Mirror", "roughness"), lines.get((index, "Mirror"))), name,
                         "Mirror.roughness")


def _check_mirror(path: Path, index: int, name: str, parts: list[tuple[type, dict[str, Any]]],
                  lines: dict[tuple, int]) -> None:
    """A Mirror needs a MeshRef and a Transform (what the surfaces stage draws it from), and a
    mesh the mirror rule accepts: checked here so the message has the file, line and entity."""
    fields = {cls.__name__: decoded for cls, decoded in parts}
    if "Mirror" not in fields:
        return
    line = lines.get((index, "Mirror"))
    missing = [kind for kind in ("MeshRef", "Transform") if kind not in fields]
    if missing:
        raise LevelError(path, f"a Mirror needs a MeshRef and a Transform (it has no {' and no '.join(missing)})",
                         line, name, "Mirror")
    # The mirror rule itself (engine.rules.mirror_rules, registered with every world), run on
    # the entity's components before any world holds them.
    try:
        check_components(cls(**decoded) for cls, decoded in parts if cls.__name__ in ("Mirror", "MeshRef", "Material"))
    except ComponentValueError as exc:
        raise LevelError(path, str(exc).replace("Mirror on entity 0: its ", ""), line, name, "Mirror") from None


_MATERIAL_MAPS = {("Material", name) for name in ("normal_map", "emissive_map", "metallic_roughness_map")}


def _annotation_problem(cls: type, field: str, value: Any) -> str | None:
    """Why ``value`` from a file does not fit the annotated type of a game's own component's
    ``field`` (``extra_components``: they have no checks of their own, and a wrong kind would
    reach the game's system frames later as a TypeError), or None.  Understood: bool, int,
    float (an int is taken), str, list/tuple/Sequence of those (``tuple[float, float]`` by
    length), Optional and unions; any other annotation (Any, a class of the game's) is the
    component's own business."""
    try:
        hints = typing.get_type_hints(cls)
    except Exception:  # an annotation the game's module cannot resolve: nothing to check by
        return None
    if field not in hints:
        return None
    expected = hints[field]
    if _fits(value, expected) is False:
        return f"must be {_type_name(expected)} (the annotation of {cls.__name__}.{field}), got {_short(value)}"
    return None


def _fits(value: Any, expected: Any) -> bool | None:
    """Whether ``value`` fits ``expected``; None when the annotation is not one understood."""
    origin, args = typing.get_origin(expected), typing.get_args(expected)
    if expected is Any or isinstance(expected, typing.TypeVar):
        return None
    if origin is typing.Union or origin is types.UnionType:
        verdicts = [_fits(value, arg) for arg in args]
        if any(v is True for v in verdicts):
            return True
        return None if any(v is None for v in verdicts) else False
    if expected is type(None):
        return value is None
    if expected is bool:
        return isinstance(value, bool)
    if expected is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if expected is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if expected is str:
        return isinstance(value, str)
    sequence = origin if origin is not None else expected
    if sequence in (list, tuple, Sequence) or sequence is typing.List or sequence is typing.Tuple:  # noqa: UP006
        if not isinstance(value, list):
            return False
        if not args:
            return True
        if sequence is tuple and not (len(args) == 2 and args[1] is Ellipsis):
            if len(args) != len(value):
                return False
            verdicts = [_fits(v, a) for v, a in zip(value, args, strict=True)]
        else:
            verdicts = [_fits(v, args[0]) for v in value]
        return False if any(v is False for v in verdicts) else (True if all(verdicts) else None)
    if expected is dict or origin is dict:
        return isinstance(value, dict)
    return None


def _type_name(expected: Any) -> str:
    if isinstance(expected, type) and typing.get_origin(expected) is None:
        return {"float": "a number", "int": "an integer", "bool": "true or false", "str": "a string",
                "list": "an array", "tuple": "an array", "dict": "a table"}.get(expected.__name__, expected.__name__)
    return str(expected).replace("typing.", "")


def _decode(cls_name: str, field: str, value: Any, where: LevelAssets) -> Any:
    if cls_name == "MeshRef" and field == "mesh":
        return level_mesh(value, where)
    if field == "texture" or (cls_name, field) in _MATERIAL_MAPS:
        # A linear map (normal, metallic-roughness) keeps a 16-bit PNG's 16 bits; colour is 8 bits.
        return level_texture(value, where, normal_map=field in ("normal_map", "metallic_roughness_map"))
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

def save_level(world: World, path: str | Path, names: Mapping[str, int] | None = None, name: str | None = None,
               game: str | None = None, rules: Mapping[str, Any] | None = None,
               extra_components: Mapping[str, type] | None = None, keep: str | Path | None = None,
               only: Collection[tuple[str, str]] | None = None) -> Path:
    """Write ``world`` as a level file: every entity (``names`` gives names by id; others are
    called ``entity_<id>``), each component's fields that differ from their defaults.
    Derived state (portal clones, slices) is left out; a mesh or texture not made by a
    generator or loaded from a file cannot be written and raises a LevelError.

    ``keep``: the level file the world was loaded from (it may be ``path`` itself). Its text
    is kept and only what differs is written into it (a round trip through tomlkit, which
    keeps comments, key order and layout): a changed field is that field's line, an added or
    removed component or entity is its table, entities keep their file's names and order, and
    new entities go at the end. So saving an edit to a file makes a diff that is the edit.
    ``name``, ``game`` and ``rules`` then change the header only where given and different.
    ``only`` (with ``keep``): the (entity name, component class name) pairs whose differences
    are written; the rest keeps the file's text, entities are neither added nor removed (an
    editor saves its edits, not the running game's own motion or the camera flown about).
    Without ``keep`` the file is written afresh (``name`` defaults to "level")."""
    import tomli_w

    path = Path(path)
    by_id, tables = _world_tables(world, path, names, extra_components)
    if keep is not None:
        text = _kept_text(world, path, Path(keep), by_id, tables, name, game, rules, extra_components,
                          None if only is None else set(only))
        path.write_text(text, encoding="utf-8")
        return path
    budget = world.resources.get(ViewBudget)
    header: dict[str, Any] = {"name": name or "level", **({"game": game} if game else {})}
    if isinstance(budget, ViewBudget) and budget != ViewBudget():
        header["view_budget"] = _budget_table(budget)
    text = tomli_w.dumps({"level": header})
    if rules:
        text += "\n" + tomli_w.dumps({"rules": dict(rules)})
    for table in tables.values():
        text += _entity_text(table)
    path.write_text(text, encoding="utf-8")
    return path


def _world_tables(world: World, path: Path, names: Mapping[str, int] | None,
                  extra_components: Mapping[str, type] | None) -> tuple[dict[int, str], dict[int, dict[str, Any]]]:
    """Names by id (``entity_<id>`` for the unnamed) and each entity's table as a level file
    holds it (``name`` and one dict of written fields per component), by id in id order."""
    known = {**ENGINE_COMPONENTS, **(extra_components or {})}
    by_id = {entity: n for n, entity in (names or {}).items()}
    entities = [e for e in sorted(world.entities())
                if not any(type(c).__name__ == "PortalClone" for c in world.components_of(e))]
    for entity in entities:
        by_id.setdefault(entity, f"entity_{entity}")
    tables: dict[int, dict[str, Any]] = {}
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
        tables[entity] = table
    return by_id, tables


def _budget_table(budget: ViewBudget) -> dict[str, Any]:
    return {key: value for key, value in dataclasses.asdict(budget).items() if value is not None}


def _entity_text(table: Mapping[str, Any]) -> str:
    text = f"\n[[entity]]\nname = {_literal(table['name'])}\n"
    for cls_name, fields in table.items():
        if cls_name != "name":
            text += f"[entity.{cls_name}]\n" + "".join(f"{_key(k)} = {_literal(v)}\n" for k, v in fields.items())
    return text


def _kept_text(world: World, path: Path, keep: Path, by_id: Mapping[int, str], tables: Mapping[int, dict[str, Any]],
               name: str | None, game: str | None, rules: Mapping[str, Any] | None,
               extra_components: Mapping[str, type] | None, only: set[tuple[str, str]] | None = None) -> str:
    """``keep``'s text with the world's differences from it written in (see ``save_level``).

    What the file says is compared with the world as both are written (``_encode_component``
    of the file's own components, decoded by ``load_level``), so a field the file writes in
    another form (a rotation as yaw and pitch, a default written out) and left unedited keeps
    its text. File paths are relative to the saved file: saved into another folder, every
    value naming a file is written again."""
    import tomlkit

    level = load_level(keep, extra_components)
    try:
        doc = tomlkit.parse(keep.read_text(encoding="utf-8"))
    except Exception as exc:  # load_level read it; tomlkit is stricter only in odd corners
        raise LevelError(keep, f"its text cannot be kept ({exc}); save without keep to write it afresh") from None
    moved = keep.resolve().parent != path.resolve().parent
    fake = {index + 1: spec.name for index, spec in enumerate(level._entities)}  # ids for the file's references
    ids = {spec_name: entity for entity, spec_name in fake.items()}
    before: dict[str, dict[str, Any]] = {}
    here: dict[str, dict[str, Any]] = {}  # the same, its file paths relative to the saved file
    for spec in level._entities:
        made = {cls.__name__: cls(**fields) for cls, fields in spec.components}
        for cls_name, field, target in spec.references:
            setattr(made[cls_name], field, ids[target])
        before[spec.name] = {cls_name: _encode_component(keep if moved else path, c, fake, spec.name)
                             for cls_name, c in made.items()}
        here[spec.name] = {cls_name: _encode_component(path, c, fake, spec.name) for cls_name, c in made.items()} \
            if moved else before[spec.name]
    files = doc.get("entity")
    now = {table["name"]: table for table in tables.values()}
    for index in reversed(range(len(level._entities))):  # the file's entities the world no longer has
        if level._entities[index].name not in now and only is None:
            del files[index]
    kept = [spec.name for spec in level._entities if spec.name in now or only is not None]
    for position, spec_name in enumerate(kept):
        if spec_name not in now:
            continue
        if only is not None:  # the others as the file has them
            wanted = {c: f for c, f in now[spec_name].items() if c == "name" or (spec_name, c) in only}
            wanted.update({c: f for c, f in here[spec_name].items() if (spec_name, c) not in only})
            _keep_entity(files[position], before[spec_name], wanted, moved)
        else:
            _keep_entity(files[position], before[spec_name], now[spec_name], moved)
    header = doc["level"]
    if name is not None and name != level.name:
        header["name"] = name
    if game is not None and game != level.game:
        header["game"] = game
    budget = world.resources.get(ViewBudget)
    budget = budget if isinstance(budget, ViewBudget) and budget != ViewBudget() else None
    if only is None and (budget or ViewBudget()) != (level.view_budget or ViewBudget()):
        if budget is None:
            del header["view_budget"]
        else:
            header["view_budget"] = _item(_budget_table(budget))
    if rules is not None and not _equal(dict(rules), level.rules):
        if "rules" not in doc:
            doc["rules"] = tomlkit.table()
        table = doc["rules"]
        for key in [k for k in table if k not in rules]:
            del table[key]
        for key, value in rules.items():
            if key not in level.rules or not _equal(value, level.rules[key]):
                table[key] = _item(value)
    text = tomlkit.dumps(doc)
    new = [_entity_text(table) for table in tables.values() if table["name"] not in before and only is None]
    return text if not new else text.rstrip("\n") + "\n" + "".join(new)


def _keep_entity(table: Any, before: Mapping[str, dict], now: Mapping[str, Any], moved: bool) -> None:
    """Write into one entity's tomlkit table what differs between the file's components
    (``before``) and the world's (``now``)."""
    import tomlkit
    from tomlkit.items import InlineTable

    for cls_name in [c for c in before if c not in now]:
        _move_trailing(table, cls_name, None)
        del table[cls_name]
    for cls_name, fields in now.items():
        if cls_name == "name":
            continue
        if cls_name not in before:
            last = [k for k, v in table.items() if isinstance(v, dict)]
            table[cls_name] = tomlkit.table()
            for key, value in fields.items():
                table[cls_name][key] = _item(value)
            if last:
                _move_trailing(table, last[-1], cls_name)
            continue
        old, component = before[cls_name], table[cls_name]
        inline = isinstance(component, InlineTable)
        if inline:  # rewritten whole, in the one-line form (tomlkit spaces an appended key oddly)
            component = component.unwrap()
        changed = False
        for key in [k for k in old if k not in fields]:
            if key in component:
                del component[key]
                changed = True
        for key, value in fields.items():
            names_file = moved and isinstance(value, Mapping) and "file" in value
            if key not in old or names_file or not _equal(value, old[key]):
                component[key] = value if inline else _item(value)
                changed = True
        if inline and changed:
            table[cls_name] = _item(component)


def _move_trailing(entity: Any, source: str, target: str | None) -> None:
    """Move the blank lines and comments ending an entity's table ``source`` (what separates
    it from the next entity) to ``target``, or to the table before ``source`` when it is
    about to be removed (None)."""
    from tomlkit.items import Comment, Whitespace

    tables = [k for k, v in entity.items() if isinstance(v, dict)]
    if target is None:
        if source != tables[-1] or len(tables) < 2:
            return
        target = tables[-2]
    body = entity[source].value.body
    trailing = []
    while body and body[-1][0] is None and isinstance(body[-1][1], (Whitespace, Comment)):
        trailing.insert(0, body.pop()[1])
    for item in trailing:
        entity[target].value.body.append((None, item))


def _item(value: Any) -> Any:
    """A tomlkit value laid out as a fresh save writes it (one line, ``_literal``)."""
    import tomlkit

    return tomlkit.parse(f"x = {_literal(value)}\n")["x"]


def _equal(a: Any, b: Any) -> bool:
    """Plain values equal, NaN equal to NaN (a field holding NaN is not an edit)."""
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    if isinstance(a, Mapping) and isinstance(b, Mapping):
        return a.keys() == b.keys() and all(_equal(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_equal(x, y) for x, y in zip(a, b, strict=True))
    return type(a) is type(b) and a == b or (is_number(a) and is_number(b) and a == b)


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
            if source is not None and "inside" in source:
                raise LevelError(path, f"{type(value).__name__} {value.name!r} is an image inside the model file "
                                       f"{source['inside']!r} (spawn_model), and a level file names image files only: "
                                       "save the image as a file and name it (texture = { file = \"...\" })",
                                 None, entity, where)
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
    """A field value as TOML: scene.json's encoder (``shell.capture.json_value``: vectors as
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
    ``asset_roots``: folders besides a level's own its files may name (shared game assets).
    ``game``: the name a level's ``[level] game`` gives this game; a level for another game
    is refused (one that names no game plays in any).  ``makes_camera``: the game adds the
    player's camera itself; otherwise a level with no camera is refused (its frames would
    be black).  After ``build``: ``level`` (the checked file) and ``names`` (entity ids by name)."""

    components: Mapping[str, type] = {}
    asset_roots: Sequence[str | Path] = ()
    game: str | None = None
    makes_camera: bool = False

    def __init__(self, level_path: str | Path) -> None:
        self.level_path = Path(level_path)
        self.level: Level | None = None
        self.names: dict[str, int] = {}

    def load(self) -> Level:
        """The game's level file, loaded and checked for this game (``check_level``)."""
        level = load_level(self.level_path, self.components, self.asset_roots, for_game=self.game)
        self.check_level(level)
        return level

    def check_level(self, level: Level) -> None:
        """A LevelError (naming the file) for a level made for another game, or one with no
        camera where the game makes none."""
        if self.game is not None and level.game is not None and level.game != self.game:
            raise LevelError(level.path, _other_game(level.game, self.game), level._lines.get(("level", "game")))
        if not self.makes_camera and not level.has_camera:
            raise LevelError(level.path, "no entity has a Camera and a Transform, so every frame would be black (add "
                                         "one: [[entity]] with [entity.Transform] and [entity.Camera])")

    def build(self, world: World) -> None:
        self.level = self.load()
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
