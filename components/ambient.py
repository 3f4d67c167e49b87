"""Ambient light: a sky/ground hemisphere where there is no sky, and the camera's
screen-space ambient occlusion and contact shadows."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pyglm import glm

from components.limits import MAX_VIEW_DEPTH
from components.tracking import HALF_MAX, TrackedComponent, boolean, choice, color, finite, integer

# The hemisphere a world with neither a Skybox nor a HemisphereLight is lit by: dim, a
# little bluer above than below (a wall facing sideways gets their mean, 0.03 0.03 0.035).
DEFAULT_SKY = (0.04, 0.04, 0.045)
DEFAULT_GROUND = (0.02, 0.02, 0.025)
# Ambient occlusion's reach: at most this many metres (a room's corner, not a valley), and
# its intensity's largest exponent (visibility ** 8 is black wherever anything occludes).
MAX_OCCLUSION_RADIUS = 100.0
MAX_OCCLUSION_INTENSITY = 8.0
# AmbientOcclusion.quality: how many directions and samples a pixel looks along
# (engine/render/screen_occlusion.py QUALITY_SAMPLES).
OCCLUSION_QUALITIES = ("low", "medium", "high")
# Contact shadows' rays: at most this many metres long, and between these many depth samples.
MAX_CONTACT_LENGTH = 5.0
CONTACT_SAMPLES = (4, 32)


@dataclass(eq=False)
class HemisphereLight(TrackedComponent):
    """Ambient light from a sky above and a ground below, for a world without a ``Skybox``
    (with one, the sky's own irradiance lights the world, and this is not used).

    ``sky`` is the linear radiance arriving from every direction above the horizon,
    ``ground`` from every direction below, both times ``intensity``: an upward-facing white
    surface shows ``sky``, a downward-facing one ``ground``, one facing sideways their mean
    (three.js's HemisphereLight; the engine represents it as the sky's spherical harmonics,
    ``engine/render/irradiance.py``).  Inside a reflection probe's influence box the probe's
    capture lights things instead.  One a world (the lowest entity's, if several).
    """

    sky: Any = field(default_factory=lambda: glm.vec4(*DEFAULT_SKY, 1.0))
    ground: Any = field(default_factory=lambda: glm.vec4(*DEFAULT_GROUND, 1.0))
    intensity: float = 1.0

    def _validate(self, name: str, value: Any) -> Any:
        if name in ("sky", "ground"):
            return color(self, name, value)
        if name == "intensity":
            return finite(self, name, value, low=0.0, high=HALF_MAX)
        return value


@dataclass(eq=False)
class AmbientOcclusion(TrackedComponent):
    """Screen-space ambient occlusion for the camera whose entity holds it (the active
    camera's, and a ``Monitor`` camera's for its picture): the light from all round (the
    sky's or a probe's irradiance, and the sky's and probes' reflections) is dimmed where
    nearby geometry hides part of the sky from a point, in corners, creases and under
    things, as every engine ships it (Unity's and Godot's SSAO, three.js's GTAOPass,
    Panda3D's ambient occlusion filter).

    Ground-truth ambient occlusion (Jimenez et al., "Practical Real-Time Strategies for
    Accurate Indirect Occlusion", 2016): the share of the cosine-weighted hemisphere over
    each pixel's surface that no geometry within ``radius`` hides, found from the camera's
    depth by the horizons of a few slices through the view direction
    (``engine/render/screen_occlusion.py``).  It multiplies what a material's own
    ``occlusion_map`` gives.

    - ``radius``: metres; geometry farther than this from a point does not occlude it.
    - ``intensity``: the visibility ``v`` is applied as ``v ** intensity``: 1 is the
      measured share (a point at the foot of a tall wall keeps half its light from all
      round), more darkens, 0 turns it off.
    - ``direct_light``: the share of the occlusion applied to the lights' direct light too
      (0: none, as is physically right; Unity's "direct lighting strength", Godot's
      "light affect"), a look for scenes that have little light from all round.
    - ``half_resolution``: found at half the screen's size in each direction (a quarter of
      the work) and brought to full size by a depth-aware filter; False: at full size.
    - ``quality``: "low", "medium" (the default) or "high": 2, 3 or 4 directions a pixel and
      6, 8 or 12 depth samples each way along each (the low one half the medium's work, the
      high one twice it; all three within 0.02 of the ground truth on a floor and wall, the
      higher smoother where small things occlude).

    - ``reflection_depth``: the levels of mirror and portal views below the camera's that are
      occluded too (0 to 16; 1, the default: the views of the mirrors and portals the camera
      sees, so the world through a portal or in a mirror looks as it does seen directly; 0:
      the camera's own view alone).  Each level costs about what the camera's view does, its
      pixels' share of it; a mirror's view is found from what that view shows, its outline
      the edge of its screen.

    Probe views and glass (the transparent slot) are not occluded.
    """

    radius: float = 1.0
    intensity: float = 1.0
    direct_light: float = 0.0
    half_resolution: bool = True
    quality: str = "medium"
    reflection_depth: int = 1

    def _validate(self, name: str, value: Any) -> Any:
        if name == "radius":
            return finite(self, name, value, positive=True, high=MAX_OCCLUSION_RADIUS)
        if name == "intensity":
            return finite(self, name, value, low=0.0, high=MAX_OCCLUSION_INTENSITY)
        if name == "direct_light":
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "half_resolution":
            return boolean(self, name, value)
        if name == "quality":
            return choice(self, name, value, OCCLUSION_QUALITIES)
        if name == "reflection_depth":
            return integer(self, name, value, low=0, high=MAX_VIEW_DEPTH)
        return value


@dataclass(eq=False)
class ContactShadows(TrackedComponent):
    """Contact shadows for the camera whose entity holds it (the active camera's, and a
    ``Monitor`` camera's for its picture): the
    sun's direct light (the brightest ``DirectionalLight``'s), and that of each point or spot
    light with ``PointLight.contact_shadows`` (at most ``MAX_CONTACT_LAMPS``, 4), is taken from
    a point where something the camera sees lies across a short ray from the point towards
    the light (a lamp's no longer than the way to it), so a
    thing standing on the floor, a crease or a small object casts the tight shadow its sun's
    shadow map is too coarse to hold (Unreal's and Unity HDRP's contact shadows).

    The ray is marched through the camera's depth (the depth and normals pass of
    ``engine/render/screen_occlusion.py``, which ambient occlusion shares): a sample behind
    what the depth image shows there, by less than ``thickness``, is in shadow.  Only what the
    camera sees can cast one (what is off the screen or hidden behind something does not).

    - ``length``: metres of the ray towards the sun (up to 5): the farthest a contact shadow
      reaches from what casts it.
    - ``thickness``: metres a surface in the depth image is taken to reach behind itself: a
      sample farther behind it than this is not hidden (a thin pole does not shadow the
      ground a long way behind it as seen from the camera).  The default, 0.5, keeps a prop
      up to that deep whole (a ray entering its far side, hidden from the camera, is still
      shadowed); less leaves holes there (at 0.2 a 0.5 m crate's contact shadow is mottled).
    - ``opacity``: the share of the sun's light a contact shadow takes (0 to 1).
    - ``distance``: metres from the camera past which there are none (faded out over the last
      tenth of it).
    - ``samples``: depth samples along the ray (4 to 32), each pixel's set off by a fraction of
      a step from its neighbours' (a 4 x 4 pattern the filter averages).

    - ``half_resolution``: found at half the screen's size in each direction (a quarter of the
      work, the depth pass's too; softer edges), brought to full size by the ambient
      occlusion's depth-aware filter.  With an ``AmbientOcclusion`` on the camera they share
      its images, at its size (its ``half_resolution`` decides).

    - ``reflection_depth``: the levels of mirror and portal views below the camera's that have
      them too (0 to 16; 1 by default: the views of the mirrors and portals the camera sees,
      each marched through its own view's depth towards the sun as its world has it; 0: the
      camera's own view alone).

    Probe views and glass do not have them.
    """

    length: float = 0.3
    thickness: float = 0.5
    opacity: float = 1.0
    distance: float = 50.0
    samples: int = 12
    half_resolution: bool = False
    reflection_depth: int = 1

    def _validate(self, name: str, value: Any) -> Any:
        if name == "length":
            return finite(self, name, value, positive=True, high=MAX_CONTACT_LENGTH)
        if name == "thickness":
            return finite(self, name, value, positive=True, high=HALF_MAX)
        if name == "opacity":
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "distance":
            return finite(self, name, value, positive=True, high=HALF_MAX)
        if name == "samples":
            return integer(self, name, value, low=CONTACT_SAMPLES[0], high=CONTACT_SAMPLES[1])
        if name == "half_resolution":
            return boolean(self, name, value)
        if name == "reflection_depth":
            return integer(self, name, value, low=0, high=MAX_VIEW_DEPTH)
        return value
