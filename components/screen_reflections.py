"""Screen-space reflections: the camera's view reflected in its own glossy surfaces."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from components.limits import MAX_VIEW_DEPTH
from components.tracking import TrackedComponent, boolean, choice, finite, integer

# How far a reflected ray is followed (metres) and how thick a surface is taken to be
# behind what the depth image shows: at most these.
MAX_REFLECTION_DISTANCE = 1000.0
MAX_REFLECTION_THICKNESS = 100.0
# ScreenReflections.quality: how many steps a ray takes across the screen
# (engine/render/screen_reflections.py QUALITY_STEPS).
REFLECTION_QUALITIES = ("low", "medium", "high")


@dataclass(eq=False)
class ScreenReflections(TrackedComponent):
    """Screen-space reflections for the camera whose entity holds it (the active camera's, and
    a ``Monitor`` camera's for its picture): a surface that reflects the sky or a probe (every material's environment
    reflection, ``Material.environment_reflection``, and a ``Reflective`` with mode "skybox"
    or "cube") shows what the camera's own image holds along its reflected ray, where the ray
    finds it, in place of the sky's or probe's reflection there: the box standing on a
    polished floor, the wall beside a chrome ball, at the place and size a ray trace would
    put them, as Unity's, Unreal's and Godot's SSR and three.js's SSRPass do.  Where the ray
    leaves the screen, passes behind what is drawn or finds nothing, the sky's or probe's
    reflection stays, with a fade between the two.

    The ray is marched across the main view's depth image after its mirrors and portals are
    composited and before its glass is drawn (``engine/render/screen_reflections.py``): a
    polished floor reflects what a mirror shows too, and glass keeps its own look over it.
    Mirrors, portals and water keep their exact planar reflections.

    - ``max_distance``: metres along the reflected ray it is followed (and faded out over
      its last quarter).
    - ``thickness``: metres behind a drawn surface a ray may pass and still be taken to hit
      it (thin things are missed with less, halos of what stands in front appear with more).
    - ``max_roughness``: surfaces rougher than this keep the probe's or sky's reflection; the
      screen's fades out over the last quarter up to it.  A rougher surface reads a blurrier
      level of the image (the cone its roughness spreads a reflection over).
    - ``edge_fade``: the share of the screen's width and height at each edge over which a
      reflection found near it fades to the probe's or sky's (no seam where the image ends).
    - ``quality``: "low", "medium" (the default) or "high": 16, 32 or 64 steps a ray across
      the screen, each then refined by halving.
    - ``half_resolution``: the rays marched at half the screen's size in each direction (a
      quarter of them, a ray a 2 x 2 block of pixels) and brought to every pixel by a
      depth-aware filter: about a quarter of the march's work, the reflections' edges
      softer (a reflection's detail at half the screen's).  False (the default): a ray a pixel.

    - ``reflection_depth``: the levels of mirror and portal views below the camera's whose
      surfaces reflect their own view's image too (0 to 16; 1 by default: the views of the
      mirrors and portals the camera sees, so a polished floor in a mirror or through a
      portal reflects what stands on it as it does seen directly; 0: the camera's view
      alone).  A level's rays are marched a pixel each (its ``half_resolution`` is the
      camera's view's alone) and end at their view's outline.

    Probe views, glass and what is off the screen show the probes' and sky's reflections.  A
    camera with it in a world where nothing reflects the sky or a probe (only mirrors and
    portals are drawn) is told so once (a ``ComponentWarning`` from the main stage).
    """

    max_distance: float = 30.0
    thickness: float = 0.3
    max_roughness: float = 0.6
    edge_fade: float = 0.1
    quality: str = "medium"
    half_resolution: bool = False
    reflection_depth: int = 1

    def _validate(self, name: str, value: Any) -> Any:
        if name == "max_distance":
            return finite(self, name, value, positive=True, high=MAX_REFLECTION_DISTANCE)
        if name == "thickness":
            return finite(self, name, value, positive=True, high=MAX_REFLECTION_THICKNESS)
        if name == "max_roughness":
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "edge_fade":
            return finite(self, name, value, low=0.0, high=0.5)
        if name == "quality":
            return choice(self, name, value, REFLECTION_QUALITIES)
        if name == "half_resolution":
            return boolean(self, name, value)
        if name == "reflection_depth":
            return integer(self, name, value, low=0, high=MAX_VIEW_DEPTH)
        return value
