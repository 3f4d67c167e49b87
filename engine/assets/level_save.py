"""Writing a world back to a level file (``save_level``), keeping the file's own text.

A fresh save writes every entity and each component's fields that differ from their
defaults, one value a line in the layout ``_literal`` gives (tomli-w only escapes strings:
its lists of a line per item make a level of vectors unreadable). Saving over the file a
world was loaded from (``keep``) keeps the person's own layout, comments and key order
through tomlkit and writes only what differs, so saving an edit makes a diff that is the
edit; an editor (shell/editor.py) saves only the components it changed (``only``). It reads
the kept file with engine.assets.level_read's ``load_level`` and writes the components that
module reads (``ENGINE_COMPONENTS``, names for ``REFERENCE_FIELDS``); a value a level file
cannot hold is a ``LevelError`` naming the entity and field. ``same_floats`` compares what a
save and a load give back (its floats pass through float32).
"""
from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Collection, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from components import ComponentValueError, FromModel
from engine.assets.color_lut import ColorLut
from engine.assets.level_assets import is_number
from engine.assets.level_read import (
    DERIVED_COMPONENTS,
    ENGINE_COMPONENTS,
    FILE_FIELDS,
    REFERENCE_FIELDS,
    REFERENCE_KINDS,
    LevelError,
    load_level,
)
from engine.assets.mesh import Mesh
from engine.assets.texture_data import TextureData
from engine.assets.values import VALUE_KINDS, json_value
from engine.core.budget import ViewBudget
from engine.core.world import World


def save_level(world: World, path: str | Path, names: Mapping[str, int] | None = None, name: str | None = None,
               game: str | None = None, rules: Mapping[str, Any] | None = None,
               extra_components: Mapping[str, type] | None = None, keep: str | Path | None = None,
               only: Collection[tuple[str, str]] | None = None, added: Collection[str] = (),
               removed: Collection[str] = ()) -> Path:
    """Write ``world`` as a level file: every entity (``names`` gives names by id; others are
    called ``entity_<id>``), each component's fields that differ from their defaults.
    Derived state (portal clones, slices, a model's parts: its root's ``Model`` names the
    file they are made from) is left out; a mesh or texture not made by a generator or
    loaded from a file cannot be written and raises a LevelError.

    ``keep``: the level file the world was loaded from (it may be ``path`` itself). Its text
    is kept and only what differs is written into it (a round trip through tomlkit, which
    keeps comments, key order and layout): a changed field is that field's line, an added or
    removed component or entity is its table, entities keep their file's names and order, and
    new entities go at the end. So saving an edit to a file makes a diff that is the edit.
    ``name``, ``game`` and ``rules`` then change the header only where given and different.
    ``only`` (with ``keep``): the (entity name, component class name) pairs whose differences
    are written; the rest keeps the file's text, and entities are neither added nor removed
    (an editor saves its edits, not the running game's own motion or the camera flown about)
    but those named in ``added`` (the world's, written whole at the end) and ``removed`` (the
    file's, taken out).
    Without ``keep`` the file is written afresh (``name`` defaults to "level")."""
    import tomli_w

    path = Path(path)
    by_id, tables = _world_tables(world, path, names, extra_components)
    if keep is not None:
        text = _kept_text(world, path, Path(keep), by_id, tables, name, game, rules, extra_components,
                          None if only is None else set(only), set(added), set(removed))
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
    # A portal's clone, a model's parts and a decal's cut mesh are made again from what the
    # file holds (the portal, the Model on the parts' root, the Decal): none is written.
    made_again = {e for e in world.entities()
                  if any(type(c).__name__ in ("PortalClone", "FromModel", "FromDecal") for c in world.components_of(e))}
    entities = [e for e in sorted(world.entities()) if e not in made_again]
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
            for field in (f for c, f in REFERENCE_FIELDS if c == cls_name):
                target = getattr(component, field, None)
                if target is not None:
                    _check_reference(world, path, target, REFERENCE_KINDS.get((cls_name, field)), by_id[entity],
                                     f"{cls_name}.{field}")
                if target in made_again and world.has(target, FromModel):
                    root = world.get(target, FromModel).model
                    raise LevelError(path, f"names entity {target}, a part of the model on "
                                           f"{by_id.get(root, f'entity_{root}')!r}: a level file holds the model's "
                                           "file, not its parts (they are made again as it loads), so it cannot name "
                                           "one; name the model's entity instead", None, by_id[entity],
                                     f"{cls_name}.{field}")
            table[cls_name] = _encode_component(path, component, by_id, by_id[entity])
        tables[entity] = table
    return by_id, tables


def _check_reference(world: World, path: Path, target: int, kind: str | None, entity: str, field: str) -> None:
    """Refuse a field naming an entity the file could not name back as it reads: one gone from
    the world, or one without the component ``kind`` the field wants (a Monitor's camera, a
    portal's partner, a sub-emitter), which the file would be refused for as it loads."""
    if not world.exists(target):
        raise LevelError(path, f"names entity {target}, which no longer exists: a level file cannot name it "
                               "(set it to None or to an entity that exists)", None, entity, field)
    if kind is not None and all(type(c).__name__ != kind for c in world.components_of(target)):
        raise LevelError(path, f"names entity {target}, which has no {kind}: a level file's {field} names one "
                               f"(give it a {kind}, or set the field to None)", None, entity, field)


def _budget_table(budget: ViewBudget) -> dict[str, Any]:
    """The budget's fields that are not their defaults (a key the file leaves out)."""
    default = dataclasses.asdict(ViewBudget())
    return {key: value for key, value in dataclasses.asdict(budget).items() if value != default[key]}


def _entity_text(table: Mapping[str, Any]) -> str:
    text = f"\n[[entity]]\nname = {_literal(table['name'])}\n"
    for cls_name, fields in table.items():
        if cls_name != "name":
            text += f"[entity.{cls_name}]\n" + "".join(f"{_key(k)} = {_literal(v)}\n" for k, v in fields.items())
    return text


def _kept_text(world: World, path: Path, keep: Path, by_id: Mapping[int, str], tables: Mapping[int, dict[str, Any]],
               name: str | None, game: str | None, rules: Mapping[str, Any] | None,
               extra_components: Mapping[str, type] | None, only: set[tuple[str, str]] | None = None,
               added: set[str] | None = None, removed: set[str] | None = None) -> str:
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
    added, removed = added or set(), removed or set()
    for index in reversed(range(len(level._entities))):  # the file's entities the world no longer has
        if level._entities[index].name not in now and (only is None or level._entities[index].name in removed):
            _pass_on_lead_comments(doc, files, index)
            del files[index]
    if files is not None and len(files) == 0:  # every entity of the file gone: no empty `entity = []`
        del doc["entity"]                       # left for the new ones' [[entity]] tables to clash with
    kept = [spec.name for spec in level._entities
            if spec.name in now or (only is not None and spec.name not in removed)]
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
    new = [_entity_text(table) for table in tables.values()
           if table["name"] not in before and (only is None or table["name"] in added)]
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
            names_file = moved and isinstance(value, Mapping) and ("file" in value or "ies" in value)
            if key not in old or names_file or not _equal(value, old[key]):
                component[key] = value if inline else _item(value)
                changed = True
        if inline and changed:
            table[cls_name] = _item(component)


def _last_body(item: Any) -> list:
    """The body list a table's text ends in: its last sub-table's (an entity's last component),
    or its own."""
    tables = [v for _, v in item.value.body if isinstance(v, dict)] if hasattr(item, "value") else []
    return tables[-1].value.body if tables else item.value.body


def _lead_start(body: list) -> int:
    """Where the comments leading the next table begin at the end of ``body``: after the last
    blank line of its closing run of blank lines and comments (tomlkit keeps the comments
    above an ``[[entity]]`` header in the table before it; those before a blank line are that
    table's own, a commented-out field)."""
    from tomlkit.items import Comment, Whitespace

    start = len(body)
    while start and body[start - 1][0] is None and isinstance(body[start - 1][1], (Whitespace, Comment)):
        start -= 1
    lead = len(body)
    for position in range(start, len(body)):
        if isinstance(body[position][1], Whitespace):
            lead = position + 1
    return lead if lead < len(body) else len(body)


def _pass_on_lead_comments(doc: Any, files: Any, index: int) -> None:
    """Before the file's entity ``index`` is deleted: the comments above its header (at the end
    of the table before it) go with it, and those above the next entity's header (at the end
    of its own last table) take their place, so a deleted entity takes its own comments and
    leaves its neighbour's."""
    if index > 0:
        before = _last_body(files[index - 1])
    else:  # the first entity: the comments above it end the top-level table before the entities
        tables = [v for k, v in doc.body if k is not None and k.key != "entity" and isinstance(v, dict)]
        if not tables:
            return
        before = _last_body(tables[-1])
    own = _last_body(files[index])
    del before[_lead_start(before):]
    start = _lead_start(own)
    before.extend(own[start:])
    del own[start:]


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
        elif (cls.__name__, f.name) in FILE_FIELDS:
            out[f.name] = Path(os.path.relpath(os.path.abspath(value), path.parent)).as_posix()
        elif isinstance(value, tuple) and value and all(isinstance(v, Mesh) for v in value):  # LevelOfDetail.meshes
            out[f.name] = [_asset_source(mesh, path, entity, where) for mesh in value]
        elif isinstance(value, (Mesh, TextureData, ColorLut)):
            out[f.name] = _asset_source(value, path, entity, where)
        elif isinstance(value, np.ndarray) and getattr(value, "source", None) is not None:  # a panorama's SkyFaces
            out[f.name] = _relative(value.source, path.parent)
        else:
            out[f.name] = _plain(value, path, entity, where)
    return out


def _asset_source(value: Any, path: Path, entity: str, where: str) -> Any:
    """How a level file names a mesh, texture or colour table: how it was made (a generator's
    table, a file relative to ``path``'s folder), or a LevelError saying why it cannot."""
    source = getattr(value, "source", None)
    if source is not None and "inside" in source:
        raise LevelError(path, f"{type(value).__name__} {value.name!r} is an image inside the model file "
                               f"{source['inside']!r} (spawn_model), and a level file names image files only: "
                               "save the image as a file and name it (texture = { file = \"...\" })",
                         None, entity, where)
    if source is None:
        raise LevelError(path, f"{type(value).__name__} {value.name!r} was not made by a generator or loaded "
                               "from a file, so a level file cannot name it", None, entity, where)
    return _relative(source, path.parent)


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
    """A source's file (an image's, a model's, a table's: ``file``; an IES profile's: ``ies``;
    a sky's panorama: ``panorama``) relative to the level's folder."""
    key = next((k for k in ("file", "ies", "panorama") if k in source), None)
    if key is None:
        return dict(source)
    return {**source, key: Path(os.path.relpath(source[key], folder)).as_posix()}


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
