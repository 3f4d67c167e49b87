"""Reading and checking a level file: ``load_level`` makes a ``Level``, ``Level.spawn`` a world's entities.

What a level file may hold is here: ``ENGINE_COMPONENTS`` (the engine's components, by
table name; a game adds its own with ``extra_components``), the ``DERIVED_COMPONENTS`` no
file holds and the ``REFERENCE_FIELDS`` that name another entity; engine.assets.level_save
writes the same. The format is in engine.assets.level_file's docstring and
docs/level_files.md.

Loading checks everything before anything is made (``load_level``): a mistake is a
``LevelError`` naming the file, the line, the entity and the field (tomllib gives no
positions: the lines come from engine.assets.level_lines). A level is data a stranger may
have written: whatever file it names (a symlink loop, a FIFO, a device, an image bomb, a
file nested past any parser's depth, a path outside its folder), loading ends in the level
or in a LevelError, within ``LEVEL_MEMORY_BUDGET`` (engine.assets.level_assets loads the
meshes and textures it names). Each component is built once from its fields while
checking, so its own ``_validate`` speaks with the file's line; ``Level.spawn`` then creates
the entities all or nothing.
"""
from __future__ import annotations

import dataclasses
import os
import re
import types
import typing
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from pyglm import glm

import components as _components
from components import ComponentValueError, look_rotation, yaw_pitch_rotation
from engine.assets.level_assets import (
    LevelAssets,
    level_lut,
    level_mesh,
    level_model,
    level_model_path,
    level_sky_faces,
    level_texture,
    user_asset_roots,
)
from engine.assets.level_lines import MAX_NESTING, deep_line, line_map, nesting_depth
from engine.assets.models import remove_parts, respawn_parts
from engine.assets.texture_data import file_problem
from engine.core.budget import ViewBudget, ViewBudgetError
from engine.core.clip_events import events_problem
from engine.core.errors import AssetError, SpeculumError
from engine.core.world import World, check_components

try:
    import tomllib
except ImportError:  # Python 3.10
    import tomli as tomllib

# The engine's components a level file may hold, by table name. PortalClone and Slice are
# made by the slice stage each frame, FromModel on the parts a Model makes, FromDecal on a
# decal's cut mesh (derived state), never written by hand.
ENGINE_COMPONENTS: dict[str, type] = {
    name: getattr(_components, name) for name in (
        "AmbientOcclusion", "Animation", "AnimationEvents", "AnimationLayer", "Bloom", "Camera", "ChromaticAberration",
        "CloudLayer", "ColorGrading", "ContactShadows",
        "Decal", "DepthOfField", "DirectionalLight",
        "Emissive", "FilmGrain", "FlyController", "Fog", "FogVolume", "HemisphereLight", "IrradianceVolume",
        "LensFlare", "LevelOfDetail",
        "Material", "MeshRef",
        "Mirror", "Model", "Monitor", "MotionBlur", "ParticleEmitter",
        "PointLight", "Portal", "ReflectionProbe", "Reflective", "Refractive", "Ripples", "ScreenPanel",
        "ScreenReflections", "ScreenText",
        "Skybox", "Splash", "TimeOfDay", "Tonemap",
        "Transform", "Traveller", "Vignette", "Visibility", "VolumetricFog", "Wake", "Water")}
DERIVED_COMPONENTS = ("PortalClone", "Slice", "FromModel", "FromDecal")
# Fields holding another entity: a name in the file, an id in the world.
REFERENCE_FIELDS = {("Transform", "parent"), ("Portal", "partner"), ("ParticleEmitter", "on_death"),
                    ("Monitor", "camera")}
# What the entity such a field names must hold in the file (a world that lacks it says so each
# frame it looks; a file is whole when read, so it is refused there).
REFERENCE_KINDS = {("Portal", "partner"): "Portal", ("ParticleEmitter", "on_death"): "ParticleEmitter",
                   ("Monitor", "camera"): "Camera"}
# Fields holding a file's path: relative to the level's folder in the file, absolute in the world.
FILE_FIELDS = {("Model", "file")}
MAX_LEVEL_BYTES = 4 << 20  # a level file's size (the shipped ones are a few KB)


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


def _rotation(value: Any) -> glm.quat:
    if isinstance(value, Mapping):
        extra = set(value) - {"yaw", "pitch", "look", "up"}
        if extra or not ({"yaw", "pitch"} & set(value) or "look" in value):
            raise ValueError(f"a rotation table is {{ yaw = deg, pitch = deg }} or {{ look = [x, y, z] }}, "
                             f"got {dict(value)!r}")
        if "look" in value:
            return look_rotation(value["look"], value.get("up", (0.0, 1.0, 0.0)))
        for key in ("yaw", "pitch"):  # numbers as written: a string or true is a mistake, not an angle
            if isinstance(value.get(key, 0.0), (bool, str)):
                raise ValueError(f"a rotation's {key} is a number of degrees, got {value[key]!r}")
        return yaw_pitch_rotation(value.get("yaw", 0.0), value.get("pitch", 0.0))
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
                 entities: list[_EntitySpec], lines: dict[tuple, int], view_budget: ViewBudget | None = None,
                 assets: LevelAssets | None = None) -> None:
        self.path = path
        self.name = name
        self.game = game
        self.rules = rules
        self.view_budget = view_budget  # [level] view_budget: spawn makes it the world's
        self._entities = entities
        self._lines = lines
        self._assets = assets if assets is not None else LevelAssets(path.parent, [])

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
        """Create every entity (fresh components each call), and the parts of each Model
        (``engine.assets.models.respawn_parts``, from the file the reader loaded); returns
        ids by name (the entities the file names: a model's parts are its root's). All or
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
            for spec in self._entities:
                model = next((fields for cls, fields in spec.components if cls.__name__ == "Model"), None)
                if model is not None and model.get("file"):
                    respawn_parts(world, made[spec.name], roots=self._assets.roots,
                                  loaded=self._assets.models.get((model["file"], model.get("variant", ""))))
        except (ComponentValueError, SpeculumError, ValueError) as exc:
            for entity in made.values():
                remove_parts(world, entity)
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
                         deep_line(text)) from None
    except MemoryError:
        raise LevelError(path, "does not fit in memory") from None
    lines = line_map(text)
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
        raise LevelError(path, other_game_refusal(game, for_game), lines.get(("level", "game")))
    rules = data.get("rules", {})
    if not isinstance(rules, dict):
        raise LevelError(path, "[rules] must be a table", lines.get(("table", "rules")))
    for key, value in rules.items():
        if nesting_depth(value) > MAX_NESTING:
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
            kind = REFERENCE_KINDS.get((cls_name, field))
            if kind is not None and all(cls.__name__ != kind for cls, _ in entities[names[target]].components):
                raise LevelError(path, f"names {target!r}, which has no {kind} (it must be one)",
                                 lines.get((spec.index, cls_name, field), lines.get((spec.index, cls_name))),
                                 spec.name, f"{cls_name}.{field}")
    _check_parent_cycles(path, entities, lines)
    skies = [spec for spec in entities if any(cls.__name__ == "Skybox" for cls, _ in spec.components)]
    if len(skies) > 1:  # (engine.rules.light_rules.check_one_sky refuses the second at spawn)
        raise LevelError(path, f"entity {skies[0].name!r} holds the level's Skybox already, and a world has one sky "
                               "(change that one's fields, or take one out)",
                         lines.get((skies[1].index, "Skybox"), lines.get((skies[1].index,))), skies[1].name, "Skybox")
    return Level(path, header["name"], game, rules, entities, lines, budget, where)


def _view_budget(path: Path, table: Any, line: int | None) -> ViewBudget | None:
    """``[level] view_budget = { views = 24, pixels = 400000, probe_ms = 2.0, min_pixels = 64, frame_ms = 16.7 }``: the
    frame's ``ViewBudget`` (engine.core.budget), each field optional, checked as in Python."""
    if table is None:
        return None
    if not isinstance(table, dict):
        raise LevelError(path, f"[level] view_budget must be a table such as {{ views = 24 }}, got {_short(table)}",
                         line)
    known = [f.name for f in dataclasses.fields(ViewBudget)]
    unknown = sorted(set(table) - set(known))
    if unknown:
        raise LevelError(path, f"[level] view_budget has unknown keys {unknown} ({', '.join(known)})", line)
    try:
        return ViewBudget(**table)
    except ViewBudgetError as exc:
        raise LevelError(path, f"[level] view_budget: {exc}", line) from None


def other_game_refusal(game: str, playing: str) -> str:
    """The refusal of a level made for another game."""
    return f"[level] game = {game!r}: the level is for {game}, not for {playing} (play it with that game)"


def _short(value: Any) -> str:
    """A value for a message, cut short (a stranger's value may be long)."""
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _entity(path: Path, assets: LevelAssets, index: int, name: str, table: dict[str, Any], known: Mapping[str, type],
            lines: dict[tuple, int]) -> _EntitySpec:
    parts: list[tuple[type, dict[str, Any]]] = []
    built: list[Any] = []  # the components as made while checking, for the whole entity's rules
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
        deep = [f for f, v in fields.items() if nesting_depth(v) > MAX_NESTING] if isinstance(fields, dict) else \
            ([None] if nesting_depth(fields) > MAX_NESTING else [])
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
            built.append(cls(**decoded))  # the component's own checks, now, not at spawn
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
    _check_model(path, index, name, parts, lines, assets)
    _check_entity_rules(path, index, name, built, lines)
    return _EntitySpec(name, index, parts, references)


def _check_entity_rules(path: Path, index: int, name: str, built: list[Any], lines: dict[tuple, int]) -> None:
    """The rules a world holds an entity's components to together (engine/rules: a Portal and
    a Mirror on one entity, a mirrored portal, a LevelOfDetail without a MeshRef, a mesh
    emitter without a mesh, second UVs the mesh lacks, ...), run on the entity's components
    now, so the file is refused when it loads with its line, not when it spawns as "entity N"
    (a world's id, which the file does not have).  The refusal names the component the rule
    names (``Portal on entity 0: ...``) or the field it starts with (``Material.alpha_cutoff``)."""
    try:
        check_components(built)
    except ComponentValueError as exc:
        message = str(exc)
        match = re.match(r"(?:(\w+) on )?entity 0: (.*)", message, re.S)
        kind, reason = (match.group(1), match.group(2)) if match else (None, message)
        held = {type(c).__name__ for c in built}
        named = re.match(r"(\w+)\.(\w+)\b", reason)
        if kind is None and named and named.group(1) in held:
            kind, field = named.group(1), named.group(2)
            where = lines.get((index, kind, field), lines.get((index, kind), lines.get((index,))))
            raise LevelError(path, reason, where, name, f"{kind}.{field}") from None
        kind = kind if kind in held else None
        where = lines.get((index, kind), lines.get((index,))) if kind else lines.get((index,))
        raise LevelError(path, reason, where, name, kind) from None


def _check_water(path: Path, index: int, name: str, parts: list[tuple[type, dict[str, Any]]],
                 lines: dict[tuple, int]) -> None:
    """A Water makes its entity's Mirror water (systems/surface_system.py refuses the same in
    a world): it needs one, and a sharp one (the waves break up the image, not a blur)."""
    fields = {cls.__name__: decoded for cls, decoded in parts}
    if "Ripples" in fields and "Water" not in fields:
        raise LevelError(path, "Ripples need a Water on the same entity (the surface that ripples)",
                         lines.get((index, "Ripples")), name, "Ripples")
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


def _check_model(path: Path, index: int, name: str, parts: list[tuple[type, dict[str, Any]]],
                 lines: dict[tuple, int], assets: LevelAssets) -> None:
    """A Model with a file needs a Transform (where the model stands, its parts under it),
    and its file is loaded (and so checked) now, in its variant, for the spawn.  One without
    (the editor's newly added Model, before its file is chosen) places nothing."""
    fields = {cls.__name__: decoded for cls, decoded in parts}
    model = fields.get("Model", {})
    if not model.get("file"):
        return
    if "Transform" not in fields:
        raise LevelError(path, "a Model needs a Transform on the same entity (where the model stands)",
                         lines.get((index, "Model")), name, "Model")
    variant = model.get("variant", "")
    problem = _model_problem(model["file"], variant, assets)
    if problem is not None:
        field = "variant" if variant and "has no material variant" in problem else "file"
        raise LevelError(path, problem, lines.get((index, "Model", field), lines.get((index, "Model"))), name,
                         f"Model.{field}")
    loaded = assets.models[(model["file"], variant)]
    clips = [c.name for c in loaded.animations]
    for kind in ("Animation", "AnimationLayer"):
        clip = fields.get(kind, {}).get("clip", "")
        if clip and clip not in clips:
            having = f"its clips: {', '.join(repr(c) for c in clips)}" if clips else "it has none"
            raise LevelError(path, f"the model file has no animation clip {clip!r} ({having})",
                             lines.get((index, kind, "clip"), lines.get((index, kind))), name, f"{kind}.clip")
    events = fields.get("AnimationEvents", {}).get("events")
    if events:
        problem = events_problem(_components.AnimationEvents(events=events).events,
                                 {c.name: c.duration for c in loaded.animations})
        if problem is not None:
            raise LevelError(path, problem, lines.get((index, "AnimationEvents", "events"),
                                                      lines.get((index, "AnimationEvents"))), name,
                             "AnimationEvents.events")
    nodes = [n for n in (loaded.node_tree.names if loaded.node_tree is not None else []) if n]
    for kind, field in (("AnimationLayer", "root"), ("Animation", "root_motion")):
        node = fields.get(kind, {}).get(field, "")
        if node and node not in nodes:
            raise LevelError(path, f"the model file has no node {node!r} (its nodes: "
                             f"{', '.join(repr(n) for n in nodes[:12]) or 'none named'})",
                             lines.get((index, kind, field), lines.get((index, kind))), name, f"{kind}.{field}")


def _model_problem(file: str, variant: str, assets: LevelAssets) -> str | None:
    """Why the model file cannot be loaded in ``variant`` (None: it is, and kept for the spawn)."""
    try:
        level_model(file, assets, variant)
    except (ValueError, AssetError) as exc:
        return str(exc)
    except MemoryError:
        return "does not fit in memory"
    return None


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


_MATERIAL_MAPS = {("Material", name) for name in ("normal_map", "emissive_map", "metallic_roughness_map", "lightmap",
                                                  "occlusion_map")} | {("Decal", "normal_map")}
_LINEAR_MAPS = ("normal_map", "metallic_roughness_map", "occlusion_map")  # data, not colour: 16 bits kept


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
    if cls_name == "LevelOfDetail" and field == "meshes":
        if not isinstance(value, list):
            raise ValueError(f"LevelOfDetail.meshes is a list of meshes, finest first, got {value!r}")
        return tuple(level_mesh(item, where) for item in value)
    if field == "texture" or (cls_name, field) in _MATERIAL_MAPS or (cls_name, field) in (("PointLight", "cookie"),
                                                                                          ("Bloom", "dirt")):
        # A linear map (normal, metallic-roughness) keeps a 16-bit PNG's 16 bits; colour is 8 bits.
        return level_texture(value, where, normal_map=field in _LINEAR_MAPS)
    if cls_name == "ColorGrading" and field == "lut":
        return level_lut(value, where)
    if (cls_name, field) in FILE_FIELDS:
        return level_model_path(value, where)  # (loaded with its variant: _check_model)
    if cls_name == "Transform" and field == "rotation":
        return _rotation(value)
    if cls_name == "Skybox" and field == "faces":
        return level_sky_faces(value, where)
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
