"""Levels of detail: lighter meshes for an entity the further it is from every view."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from components.tracking import ComponentValueError, TrackedComponent, finite

# Assets are the engine's types (engine.assets.mesh.Mesh); components import none of it.
Mesh = Any
MAX_DETAIL_LEVELS = 8           # LevelOfDetail.meshes: a model's LOD chain is 3 to 5 deep
MAX_DETAIL_HYSTERESIS = 0.5     # LevelOfDetail.hysteresis: a wider band would hold the fine mesh twice as far


@dataclass(eq=False)
class LevelOfDetail(TrackedComponent):
    """Draws the entity with lighter meshes as it gets further away, as Unity's LOD Group,
    Godot's visibility ranges and glTF's ``MSFT_lod`` do: ``meshes`` from the most detailed
    to the lightest, ``distances`` (metres, increasing, one fewer) where each next one takes
    over.  The distance is from the nearest eye that sees the entity: the camera, and each
    mirror's and portal's view of last frame (an object close behind a portal's far side is
    close, however far it is from the camera), to the centre of the finest mesh's box.  A
    switch back to a finer mesh waits until the entity is ``hysteresis`` (a share) nearer
    than the distance it left it at, so an entity at a threshold does not flicker.  The
    detail stage (``systems/detail_system.py``) writes the entity's ``MeshRef.mesh``; give
    it a MeshRef (its ``visible`` and shadow switches stay the game's).  Not on a mirror or
    portal (their mesh is their surface)."""

    meshes: Any
    distances: Any = ()
    hysteresis: float = 0.1

    def _validate(self, name: str, value: Any) -> Any:
        if name == "meshes":
            try:
                meshes = tuple(value)
            except TypeError:
                raise ComponentValueError(f"LevelOfDetail.meshes must be meshes, finest first, got {value!r}") \
                    from None
            if not 1 <= len(meshes) <= MAX_DETAIL_LEVELS:
                raise ComponentValueError(f"LevelOfDetail.meshes must hold 1 to {MAX_DETAIL_LEVELS} meshes, "
                                          f"got {len(meshes)}")
            for mesh in meshes:
                if getattr(type(mesh), "ASSET_KIND", None) != "mesh":
                    raise ComponentValueError("LevelOfDetail.meshes must be engine.assets.mesh.Mesh objects, got "
                                              f"a {type(mesh).__name__}")
            self._check_counts(meshes, self.__dict__.get("distances"))
            return meshes
        if name == "distances":
            try:
                distances = tuple(finite(self, name, d, positive=True) for d in value)
            except TypeError:
                raise ComponentValueError(f"LevelOfDetail.distances must be numbers (metres), got {value!r}") \
                    from None
            if any(b <= a for a, b in zip(distances, distances[1:], strict=False)):
                raise ComponentValueError(f"LevelOfDetail.distances must increase, got {value!r}")
            self._check_counts(self.__dict__.get("meshes"), distances)
            return distances
        if name == "hysteresis":
            return finite(self, name, value, low=0.0, high=MAX_DETAIL_HYSTERESIS)
        return value

    @staticmethod
    def _check_counts(meshes: tuple | None, distances: tuple | None) -> None:
        if meshes is not None and distances is not None and len(distances) != len(meshes) - 1:
            raise ComponentValueError(f"LevelOfDetail.distances must be one fewer than its meshes "
                                      f"({len(meshes)} meshes: {len(meshes) - 1} distances), got {len(distances)} "
                                      "(to change how many, give both at once: a new LevelOfDetail(meshes=..., "
                                      "distances=...), or dataclasses.replace)")

    def level_at(self, distance: float, current: int) -> int:
        """The mesh to draw at ``distance`` (metres) when ``current`` is drawn now: further
        out at once, finer only ``hysteresis`` within the threshold."""
        level = current
        while level < len(self.distances) and distance > self.distances[level]:
            level += 1
        while level > 0 and distance < self.distances[level - 1] * (1.0 - self.hysteresis):
            level -= 1
        return level
