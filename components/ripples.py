"""Ripples: rings of waves that what moves through a water (``Wake``), and rain, make on it."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from components.tracking import TrackedComponent, finite

MAX_RIPPLE_SPEED = 20.0   # Ripples.speed, metres a second (a wave speed; water's fastest ripples are ~0.25)
MAX_RAIN = 10000.0        # Ripples.rain, drops a square metre a second (a cloudburst is a few hundred)


@dataclass(eq=False)
class Ripples(TrackedComponent):
    """Makes a ``Water`` ripple: the rings of waves a stone dropped in a pond makes, the wake
    behind a boat, rain on a pool.  The surface's height is simulated on the GPU as the wave
    equation on a grid (``engine/render/ripples.py``: the height field of Tessendorf's and
    Crest's interactive water, a texel every ``cell`` metres over the water's outline), each
    frame, and its slopes bend the water's normal where the composite reads it: the
    reflection, what is seen through the surface and Fresnel's weight all move with the
    rings, from above and from below, in every view (mirrors and portals that see the water
    included), and a water with ``caustics`` gathers the light through them too (rings of
    light on a sunny pool's floor, and in the light shafts under it).  The waves of
    ``Material.normal_map`` carry on under them.

    - ``speed``: metres a second the rings spread (0.25 to 0.5 for ripples on a pond).
    - ``damping``: how fast they die out: their height falls by exp(-damping x seconds).
    - ``cell``: metres between the grid's points (finer: smaller ripples, more texels; a
      side of the outline over ``MAX_RIPPLE_TEXELS`` points is drawn coarser and said once).
    - ``strength``: scales the slopes drawn, in the reflection and in the caustics alike (1: as
      simulated; 0: none drawn).
    - ``rain``: drops a square metre a second falling on the whole surface, each pushing it
      down ``drop_depth`` metres over a disc of ``drop_radius`` metres.

    Things that move through the surface make rings where they cross it: give them a
    ``Wake``; a stone that lands in it, a ``Splash`` when it does.  A water whose rings have
    died away (their height under 0.01 mm) costs nothing until the next drop (no
    simulation step, the composite's plain build).  Needs a ``Water`` on the same entity,
    and a flat water mesh (a quad: its outline); up to ``MAX_RIPPLE_WATERS`` ripple at
    once (the first by entity; more are counted in
    ``RenderStats.ripple_waters_cut`` and said once)."""

    SHAREABLE = False   # its height field is its own
    speed: float = 0.35
    damping: float = 0.6
    cell: float = 0.03
    strength: float = 1.0
    rain: float = 0.0
    drop_radius: float = 0.02
    drop_depth: float = 0.002

    def _validate(self, name: str, value: Any) -> Any:
        if name == "speed":
            return finite(self, name, value, positive=True, high=MAX_RIPPLE_SPEED)
        if name == "damping":
            return finite(self, name, value, low=0.0, high=100.0)
        if name == "cell":
            return finite(self, name, value, low=0.001, high=10.0)
        if name == "strength":
            return finite(self, name, value, low=0.0, high=100.0)
        if name == "rain":
            return finite(self, name, value, low=0.0, high=MAX_RAIN)
        if name == "drop_radius":
            return finite(self, name, value, low=0.001, high=10.0)
        if name == "drop_depth":
            return finite(self, name, value, low=0.0, high=1.0)
        return value


@dataclass(eq=False)
class Wake(TrackedComponent):
    """Makes its entity ripple any water with ``Ripples`` it moves through: each frame it
    stands across the surface (its mesh's box reaching both sides of the plane, inside the
    outline), the surface over a disc of ``radius`` metres about where it crosses is pushed
    down by ``strength`` times the metres it moved since the last frame (the farthest any
    corner of its mesh's box went: a boat swinging its stern, a top spinning where it
    stands, stir the water as one that wades), so a thing that wades leaves rings behind it
    and a thing standing still makes none.  ``radius`` 0: half
    the widest side of its mesh's box as placed (an entity with no mesh needs a radius)."""

    radius: float = 0.0
    strength: float = 0.5

    def _validate(self, name: str, value: Any) -> Any:
        if name == "radius":
            return finite(self, name, value, low=0.0, high=100.0)
        if name == "strength":
            return finite(self, name, value, low=0.0, high=10.0)
        return value


@dataclass(eq=False)
class Splash(TrackedComponent):
    """A one-off drop into the water under (or over) its entity's Transform: the ripple stage
    pushes the surface down ``depth`` metres over a disc of ``radius`` metres about the point
    straight across the nearest rippling water's plane from it (inside its outline), then
    takes the Splash off (a stone landing in a pond: ``world.add_component(stone, Splash())``).
    Off every rippling water it is taken off and makes nothing, as a stone landing on grass."""

    radius: float = 0.05
    depth: float = 0.01

    def _validate(self, name: str, value: Any) -> Any:
        if name == "radius":
            return finite(self, name, value, low=0.001, high=100.0)
        if name == "depth":
            return finite(self, name, value, low=0.0, high=1.0)
        return value
