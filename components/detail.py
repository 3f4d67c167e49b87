"""Levels of detail: lighter meshes for an entity the further it is from every view."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from components.tracking import ComponentValueError, TrackedComponent, finite

# Assets are the engine's types (engine.assets.mesh.Mesh); components import none of it.
Mesh = Any
MAX_DETAIL_LEVELS = 8           # LevelOfDetail.meshes: a model's LOD chain is 3 to 5 deep
MAX_DETAIL_HYSTERESIS = 0.5     # LevelOfDetail.hysteresis: a wider band would hold the fine mesh twice as far
MAX_SCREEN_HEIGHT = 100.0       # LevelOfDetail.screen_heights: a hundred views tall is closer than any eye gets


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
    portal (their mesh is their surface).

    Or by the share of the view's height it covers, as Unity's LOD Group measures:
    ``screen_heights`` (decreasing, one fewer than the meshes, instead of ``distances``)
    where each next mesh takes over, the share being its size (the largest side of the
    finest mesh's box, as placed) over the height the view sees at its distance from the
    nearest eye (2 d tan(fov / 2) for the active camera's fov; an orthographic camera's
    ``ortho_height``, whatever the distance): a camera zoomed in keeps the fine mesh further
    out, and an orthographic view picks by its zoom alone.  ``hysteresis`` is then a share of
    the size the entity must grow back past."""

    meshes: Any
    distances: Any = ()
    hysteresis: float = 0.1
    screen_heights: Any = ()

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
            self._check_counts(meshes, self.__dict__.get("distances"), self.__dict__.get("screen_heights"))
            return meshes
        if name == "distances":
            try:
                distances = tuple(finite(self, name, d, positive=True) for d in value)
            except TypeError:
                raise ComponentValueError(f"LevelOfDetail.distances must be numbers (metres), got {value!r}") \
                    from None
            if any(b <= a for a, b in zip(distances, distances[1:], strict=False)):
                raise ComponentValueError(f"LevelOfDetail.distances must increase, got {value!r}")
            self._check_counts(self.__dict__.get("meshes"), distances, self.__dict__.get("screen_heights"))
            return distances
        if name == "screen_heights":
            try:
                shares = tuple(finite(self, name, h, positive=True, high=MAX_SCREEN_HEIGHT) for h in value)
            except TypeError:
                raise ComponentValueError(f"LevelOfDetail.screen_heights must be numbers (shares of the view's "
                                          f"height), got {value!r}") from None
            if any(b >= a for a, b in zip(shares, shares[1:], strict=False)):
                raise ComponentValueError(f"LevelOfDetail.screen_heights must decrease (the lighter mesh as it "
                                          f"covers less of the view), got {value!r}")
            self._check_counts(self.__dict__.get("meshes"), self.__dict__.get("distances"), shares)
            return shares
        if name == "hysteresis":
            return finite(self, name, value, low=0.0, high=MAX_DETAIL_HYSTERESIS)
        return value

    @staticmethod
    def _check_counts(meshes: tuple | None, distances: tuple | None, heights: tuple | None) -> None:
        """One fewer thresholds than meshes, by distance or by screen height (not both); once
        all three are given (a new component sets its fields in turn)."""
        if meshes is None or distances is None or heights is None:
            return
        if distances and heights:
            raise ComponentValueError("LevelOfDetail takes distances or screen_heights, not both (set the other "
                                      "to ())")
        name, given = ("screen_heights", heights) if heights else ("distances", distances)
        if len(given) != len(meshes) - 1:
            raise ComponentValueError(f"LevelOfDetail.{name} must be one fewer than its meshes "
                                      f"({len(meshes)} meshes: {len(meshes) - 1} {name}), got {len(given)} "
                                      f"(to change how many, give both at once: a new LevelOfDetail(meshes=..., "
                                      f"{name}=...), or dataclasses.replace)")

    @property
    def by_screen(self) -> bool:
        """Whether it picks by the share of the view's height it covers (``screen_heights``)."""
        return bool(self.screen_heights)

    def level_at(self, distance: float, current: int) -> int:
        """The mesh to draw at ``distance`` (metres) when ``current`` is drawn now: further
        out at once, finer only ``hysteresis`` within the threshold."""
        level = current
        while level < len(self.distances) and distance > self.distances[level]:
            level += 1
        while level > 0 and distance < self.distances[level - 1] * (1.0 - self.hysteresis):
            level -= 1
        return level
