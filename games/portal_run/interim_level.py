"""A stand-in reader for this game's level files, used only until ``engine.level_file``
lands (it is being written alongside): the same TOML layout (``[level]``, ``[rules]``,
``[[entity]]`` with one table per component), only the parts these levels use.
``games.portal_run.level.load`` prefers the engine's loader whenever it exists."""
from __future__ import annotations

from pathlib import Path
from typing import Any

try:
    import tomllib
except ImportError:  # Python 3.10
    import tomli as tomllib

import components
from components import look_rotation, yaw_pitch_rotation
from engine import mesh as meshes
from engine.errors import SpeculumError
from engine.texture_data import checker_texture
from engine.world import World


class InterimLevelError(SpeculumError):
    """A level file this reader cannot read (named, with the reason)."""


class InterimLevel:
    """A read level file: its name, rules and entity tables."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        try:
            data = tomllib.loads(self.path.read_text())
        except (OSError, tomllib.TOMLDecodeError) as exc:
            raise InterimLevelError(f"level file {str(self.path)!r}: {exc}") from None
        self.name = str(data.get("level", {}).get("name", self.path.stem))
        self.rules: dict[str, Any] = dict(data.get("rules", {}))
        self.entities: list[dict[str, Any]] = list(data.get("entity", []))

    def spawn(self, world: World) -> dict[str, int]:
        """Spawn every entity; returns entity ids by name."""
        names: dict[str, int] = {}
        for index, table in enumerate(self.entities):
            name = str(table.get("name", f"entity {index}"))
            parts = [self._component(name, kind, fields) for kind, fields in table.items() if kind != "name"]
            names[name] = world.spawn(*parts)
        return names

    def _component(self, entity: str, kind: str, fields: dict[str, Any]) -> Any:
        cls = getattr(components, kind, None)
        if cls is None:
            raise InterimLevelError(f"level file {str(self.path)!r}: entity {entity!r}: no component {kind!r}")
        fields = dict(fields)
        if kind == "Transform" and isinstance(fields.get("rotation"), dict):
            r = fields["rotation"]
            fields["rotation"] = look_rotation(r["look"]) if "look" in r else yaw_pitch_rotation(
                float(r.get("yaw", 0.0)), float(r.get("pitch", 0.0)))
        if kind == "MeshRef":
            ((shape, size),) = fields["mesh"].items()
            make = getattr(meshes, shape)
            fields["mesh"] = make(tuple(size)) if shape == "box" else (
                make(*size) if isinstance(size, list) else make(size))
        if kind == "Material" and isinstance(fields.get("texture"), dict):
            size, squares = fields["texture"]["checker"]
            fields["texture"] = checker_texture(int(size), int(squares))
        return cls(**fields)
