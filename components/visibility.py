"""Show and hide in reflections: which kinds of view draw an entity, and its reflection layers.

Two controls, as engines with planar reflections and probes offer them (Unreal's hidden-in-
reflections flags and show-only lists, Godot's ``reflection_mask``, three.js's layers):

- **Kinds of view.**  A view is *direct* (the camera's own), or it looks through mirrors and
  portals (its kinds are those of every surface its chain passed), or it is a probe's capture
  (a cube face, and every mirror and portal seen from it).  ``Visibility`` says in which of
  these the entity is drawn: a vampire is ``Visibility(in_mirrors=False)``; a ghost seen only
  in mirrors is ``Visibility(direct=False, in_portals=False, in_probes=False)``.  Kinds
  accumulate: the vampire is hidden in a mirror seen through a portal too.
- **Layers.**  An entity belongs to some of ``REFLECTION_LAYERS`` numbered layers (layer 0
  unless told); a mirror, portal or probe shows some layers (all unless told:
  ``shows_layers`` / ``hides_layers``), and a view shows the layers every surface of its
  chain shows.  A view draws the entity when they share a layer.

The id image follows what is drawn: a hidden entity is absent from the views that hide it.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from components.limits import (
    ALL_LAYERS,
    REFLECTION_LAYERS,
    VIEW_DIRECT,
    VIEW_KINDS,
    VIEW_MIRROR,
    VIEW_PORTAL,
    VIEW_PROBE,
)
from components.tracking import ComponentValueError, TrackedComponent, boolean, warn_component

DEFAULT_LAYERS = (0,)

# The packed code the visibility rule (engine/rules/visibility_rules.py) and the scene shaders
# read: plain bits of this component's fields, here so frame data (engine/resources.py) can
# name an entity drawn everywhere without importing the rules a floor above it.
KIND_MASK = (1 << VIEW_KINDS) - 1  # the kinds' bits of a code


def visibility_code(kinds: int | np.ndarray, layers: int | np.ndarray) -> int | np.ndarray:
    """The packed code of ``kinds`` (bits 0 to VIEW_KINDS - 1) and ``layers`` (the bits above):
    an entity's hidden kinds and layers, or a view's kinds and shown layers (ints, or numpy
    integer arrays: the planner packs a level's view masks at once)."""
    return kinds | (layers << VIEW_KINDS)


DRAWN_EVERYWHERE = visibility_code(0, 1)          # an entity without a Visibility: hidden in no view, on layer 0
SEEN_BY_EVERY_VIEW = visibility_code(0, ALL_LAYERS)  # hidden in no view, on every layer: what any view draws


def layer_list(owner: object, name: str, value: Any) -> tuple[int, ...]:
    """A list of distinct layer numbers in [0, REFLECTION_LAYERS), sorted, as a tuple.

    A bare number is refused rather than guessed at (layer 3, or the mask 3?): ``[3]``."""
    what = f"{type(owner).__name__}.{name}"
    if isinstance(value, (str, bytes, dict)) or not hasattr(value, "__iter__"):
        raise ComponentValueError(f"{what} must be a list of layer numbers in [0, {REFLECTION_LAYERS - 1}] "
                                  f"(e.g. [3]), got {value!r}")
    try:
        layers = list(value)
    except TypeError:  # (a 0-d numpy array has __iter__ but no items)
        raise ComponentValueError(f"{what} must be a list of layer numbers in [0, {REFLECTION_LAYERS - 1}] "
                                  f"(e.g. [3]), got {value!r}") from None
    for layer in layers:
        if isinstance(layer, (bool, np.bool_)) or not isinstance(layer, (int, np.integer)) \
                or not 0 <= layer < REFLECTION_LAYERS:
            raise ComponentValueError(f"{what} must hold layer numbers in [0, {REFLECTION_LAYERS - 1}] "
                                      f"(there are {REFLECTION_LAYERS} reflection layers), got {layer!r} in {value!r}")
    if not layers and name == "layers":
        raise ComponentValueError(f"{what} must name at least one layer (an entity on none is drawn nowhere: "
                                  f"MeshRef.visible = False says that), got {value!r}")
    return tuple(sorted({int(layer) for layer in layers}))


def layer_mask(layers: tuple[int, ...] | list[int]) -> int:
    """The bit mask of ``layers`` (bit n: layer n)."""
    mask = 0
    for layer in layers:
        mask |= 1 << layer
    return mask


def surface_layers(shows: tuple[int, ...] | None, hides: tuple[int, ...]) -> int:
    """The layers a mirror, portal or probe shows: ``shows`` (None: all) less ``hides``."""
    return (ALL_LAYERS if shows is None else layer_mask(shows)) & ~layer_mask(hides)


def check_surface_layers(owner: object, name: str, value: Any) -> Any:
    """``_validate`` for the ``shows_layers`` (None or a list) and ``hides_layers`` (a list)
    fields of a surface component."""
    if name == "shows_layers" and value is None:
        return None
    layers = layer_list(owner, name, value)
    if name == "shows_layers" and not layers:
        warn_component(f"{type(owner).__name__}.shows_layers = {value!r} shows no layer, so its view draws nothing "
                       "(None shows every layer; hides_layers=[n] hides one)")
    return layers


LAYER_FIELDS = ("shows_layers", "hides_layers")


@dataclass(eq=False)
class ShownLayers(TrackedComponent):
    """The reflection layers a view shows, one definition for every component that makes
    views (Camera, Mirror, Portal, ReflectionProbe): ``shows_layers`` (None: all) less
    ``hides_layers`` (``hides_layers=[3]`` shows all but layer 3), as bits in ``layer_mask``.
    Keyword-only fields (``Mirror(hides_layers=[3])``), checked by ``check_surface_layers``:
    a component's own ``_validate`` hands these names to this one."""

    shows_layers: Any = field(default=None, kw_only=True)
    hides_layers: Any = field(default=(), kw_only=True)

    @property
    def layer_mask(self) -> int:
        """The reflection layers its view shows, as bits."""
        return surface_layers(self.shows_layers, self.hides_layers)

    def _validate(self, name: str, value: Any) -> Any:
        if name in LAYER_FIELDS:
            checked = check_surface_layers(self, name, value)
            shows = checked if name == "shows_layers" else getattr(self, "shows_layers", None)
            hides = checked if name == "hides_layers" else getattr(self, "hides_layers", ())
            if hides and (shows is None or shows) and not surface_layers(shows, hides):
                # (shows_layers=[] is said by check_surface_layers: no second word for it)
                warn_component(f"{type(self).__name__}.hides_layers = {list(hides)} hides every layer its "
                               f"shows_layers = {'None (all)' if shows is None else list(shows)} shows, so its "
                               "view draws nothing")
            return checked
        return value


@dataclass(eq=False)
class Visibility(TrackedComponent):
    """Where the entity is drawn: directly (``direct``), in mirrors (``in_mirrors``), through
    portals (``in_portals``), in probe captures (``in_probes``), each True unless told, and
    the reflection ``layers`` it belongs to (layer numbers, [0] unless told).

    A view hides the entity when the view is of a kind the entity is hidden in, or shares no
    layer with it (``shows_layers`` / ``hides_layers`` on Mirror, Portal, ReflectionProbe).
    Kinds accumulate along a chain of views: a view through a portal then a mirror is both,
    so an entity hidden in either is not drawn there; a probe's capture, and every mirror and
    portal seen in it, is a probe view.  Without the component an entity is drawn everywhere,
    on layer 0.  Its shadow is the world's, not a view's: hidden in a view, it still casts
    its shadow there (a ghost seen only in a mirror darkens the floor in front of it too);
    ``MeshRef(casts_shadows=False)`` takes the shadow away everywhere."""

    direct: bool = True
    in_mirrors: bool = True
    in_portals: bool = True
    in_probes: bool = True
    layers: Any = field(default_factory=lambda: DEFAULT_LAYERS)

    @property
    def hidden_kinds(self) -> int:
        """The kinds of view (``components.limits`` VIEW_*) it is not drawn in, as bits."""
        return ((0 if self.direct else VIEW_DIRECT) | (0 if self.in_mirrors else VIEW_MIRROR)
                | (0 if self.in_portals else VIEW_PORTAL) | (0 if self.in_probes else VIEW_PROBE))

    @property
    def layer_mask(self) -> int:
        """The layers it belongs to, as bits (bit n: layer n)."""
        return layer_mask(self.layers)

    def _validate(self, name: str, value: Any) -> Any:
        if name in ("direct", "in_mirrors", "in_portals", "in_probes"):
            value = boolean(self, name, value)
            kinds = {kind: value if kind == name else self.__dict__.get(kind)
                     for kind in ("direct", "in_mirrors", "in_portals", "in_probes")}
            if not value and all(shown is False for shown in kinds.values()):
                warn_component("Visibility hides the entity in every kind of view (direct, in_mirrors, in_portals "
                               "and in_probes all False), so it is drawn nowhere; MeshRef.visible = False says "
                               "that plainly")
            return value
        if name == "layers":
            return layer_list(self, name, value)
        return value
