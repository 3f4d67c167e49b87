"""How the active camera's image is exposed, graded, tone mapped and bloomed: components on
the camera entity, as Bevy puts ``Tonemapping``, ``ColorGrading`` and ``Bloom`` on its camera.

The frame is drawn in linear HDR (half floats: a lamp may be 20 times brighter than white
paper); the present stage turns it into the picture.  Its order (``engine/render/present.py``):
every mirror and portal view is composited into the main image first, then **bloom** (on
that finished HDR image, so a lamp glows directly and in every reflection, for the same
cost whatever the number of mirrors), then **exposure**, the **grade** (``ColorGrading``)
and the **tone curve**, then the sRGB encoding and the grade's colour table, then FXAA.  A
camera with none of these components keeps the plain look: no curve, the renderer's linear
``Renderer.exposure``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pyglm import glm

from components.tracking import (
    HALF_MAX,
    ComponentValueError,
    TrackedComponent,
    _items,
    boolean,
    choice,
    finite,
    integer,
    vec3,
)

# "none": clamp to [0, 1] (today's look); "aces": Stephen Hill's fit of the ACES RRT + sRGB
# ODT (BakingLab's ACES.hlsl, with three.js's input scale of 1 / 0.6); "agx": Troy
# Sobotka's AgX, base with the default (identity) look, as three.js r162+ writes it
# (Filament's Rec. 2020 inset/outset matrices, the 6th-order sigmoid fit of Benjamin
# Wrensch's minimal AgX); "pbr_neutral": the Khronos PBR Neutral tone mapper (2024).
TONEMAP_CURVES = ("none", "aces", "agx", "pbr_neutral")
BLOOM_COMPOSITES = ("energy_conserving", "additive")
MAX_EXPOSURE_EV = 24.0      # 2**24: a moonlit scene brought to daylight and more
MAX_ADAPT_SPEED = 100.0     # per second: faster is a jump, not an adaptation
MAX_BLOOM_LEVELS = 8        # half-size steps below the screen: 8 spread a glow over ~1/2 of a 1080p frame
MAX_BLOOM_RADIUS = 4.0      # the upsample tent's reach in texels of the smaller level
_DEFAULT_MAX_EV = 8.0
MAX_GRADE_CONTRAST = 4.0    # ColorGrading.contrast and saturation: 4x is past any look
MAX_GRADE_SLOPE = 16.0      # ColorGrading.slope: four stops up
MAX_GRADE_POWER = 8.0
MAX_VIGNETTE_FALLOFF = 16.0  # Vignette.falloff: cos^16 is black a third of the way out at 90 degrees

# The engine's colour table (engine.assets.color_lut.ColorLut); components import none of the
# engine: ColorGrading.lut is checked by the class's ASSET_KIND ("lut").
ColorLut = Any


@dataclass(eq=False)
class Tonemap(TrackedComponent):
    """Exposure and tone curve of a camera's image (on the camera's entity).

    - ``curve``: one of ``TONEMAP_CURVES`` ("agx" by default; "none" clamps, as a camera
      without a Tonemap does).
    - ``exposure``: in EV, stops: the linear image is scaled by ``2 ** exposure`` before the
      curve (+1 doubles it).  With ``auto_exposure`` it is the compensation added to the
      automatic value.  A Tonemap replaces ``Renderer.exposure`` for its camera.
    - ``auto_exposure``: expose from the frame's mean log luminance (computed on the GPU,
      never read back): the target is ``log2(key) - mean(log2 L)`` EV, clamped to
      ``[min_ev, max_ev]``, reached at ``adapt_speed`` (each frame the exposure moves the
      share ``1 - exp(-adapt_speed * dt)`` of the way to its target, so the gap shrinks
      by ``e`` every ``1 / adapt_speed`` seconds).  ``key`` is the grey the mean is
      brought to (0.18, middle grey).  A camera's first frame starts at its target.
    """

    curve: str = "agx"
    exposure: float = 0.0
    auto_exposure: bool = False
    key: float = 0.18
    adapt_speed: float = 1.5
    min_ev: float = -8.0
    max_ev: float = _DEFAULT_MAX_EV

    def _validate(self, name: str, value: Any) -> Any:
        if name == "curve":
            return choice(self, name, value, TONEMAP_CURVES)
        if name == "exposure":
            return finite(self, name, value, low=-MAX_EXPOSURE_EV, high=MAX_EXPOSURE_EV)
        if name == "auto_exposure":
            return boolean(self, name, value)
        if name == "key":
            return finite(self, name, value, positive=True, high=1.0)
        if name == "adapt_speed":
            return finite(self, name, value, positive=True, high=MAX_ADAPT_SPEED)
        if name in ("min_ev", "max_ev"):
            value = finite(self, name, value, low=-MAX_EXPOSURE_EV, high=MAX_EXPOSURE_EV)
            low = value if name == "min_ev" else self.__dict__.get("min_ev")
            high = value if name == "max_ev" else self.__dict__.get("max_ev")
            if low is not None and high is not None and low > high:
                # During construction min_ev comes first: Tonemap(min_ev=9) is wrong about
                # min_ev, not about the default max_ev (as Camera blames near and far).
                if name == "max_ev" and "max_ev" not in self.__dict__ and value == _DEFAULT_MAX_EV:
                    name = "min_ev"
                raise ComponentValueError(f"Tonemap.{name} must keep min_ev <= max_ev, got min_ev={low} "
                                          f"max_ev={high}")
            return value
        return value


@dataclass(eq=False)
class Bloom(TrackedComponent):
    """A glow around bright things (on the camera's entity): Jimenez's mip-chain bloom (Call
    of Duty: Advanced Warfare, SIGGRAPH 2014).  The finished HDR image is halved ``levels``
    times with a 13-tap filter (the first step weighs its five boxes by Karis's
    1 / (1 + luma), so a lone bright pixel does not flicker into a blob), then each level is
    added into the next larger one through a 3x3 tent of ``radius`` texels; the result is
    the mean of the levels' blurs, so it keeps the image's mean brightness.  A software
    rasteriser starts the chain at a quarter of the screen, drawn straight from the image
    (its levels a quarter of the screen and below, one fewer, ending where a GPU's do:
    ``engine/render/bloom.py`` ``BloomPass.first_step``).

    - ``intensity`` (0..1): the bloom's share.  ``composite`` "energy_conserving" (the
      default) mixes: ``image * (1 - intensity) + bloom * intensity`` (the mean is kept:
      bright things spread light, nothing is added); "additive" adds ``bloom * intensity``.
    - ``threshold`` (scene HDR units, before exposure; 0: everything blooms) with a soft
      ``knee`` (a share of the threshold over which light fades in): only what is
      brighter feeds the bloom.
    - ``levels`` (1..8): how far a glow spreads (each level doubles it); fewer are made where
      the image is too small to halve that often (a level is at least 2 pixels a side).
    - ``dirt`` (a TextureData, sRGB colour as ``Material.texture``; None: none) and
      ``dirt_intensity`` (0 to 100, default 1): lens dirt (Unreal's bloom dirt mask, HDRP's
      lens dirt): the picture of smudges and dust on the lens, stretched over the whole
      frame, lit by the bloom's light (and a ``LensFlare``'s) where it falls: the glow and the
      ghosts times the image's colour there times ``dirt_intensity`` are added on top, so the
      dirt shows only where bright light crosses it.
    """

    intensity: float = 0.1
    threshold: float = 0.0
    knee: float = 0.5
    levels: int = 6
    radius: float = 1.0
    composite: str = "energy_conserving"
    dirt: Any = None
    dirt_intensity: float = 1.0

    def _validate(self, name: str, value: Any) -> Any:
        if name == "dirt" and value is not None:
            if getattr(type(value), "ASSET_KIND", None) != "texture":
                raise ComponentValueError(
                    f"Bloom.dirt must be an engine.assets.texture_data.TextureData, got {type(value).__name__}")
            return value
        if name == "dirt_intensity":
            return finite(self, name, value, low=0.0, high=100.0)
        if name == "intensity":
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "threshold":
            return finite(self, name, value, low=0.0, high=HALF_MAX)
        if name == "knee":
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "levels":
            return integer(self, name, value, low=1, high=MAX_BLOOM_LEVELS)
        if name == "radius":
            return finite(self, name, value, low=0.25, high=MAX_BLOOM_RADIUS)
        if name == "composite":
            return choice(self, name, value, BLOOM_COMPOSITES)
        return value


@dataclass(eq=False)
class ColorGrading(TrackedComponent):
    """The grade of a camera's image (on the camera's entity), as a colourist's controls and
    Bevy's, Unity's and Godot's colour grading give it: in the linear HDR image after
    exposure and before the tone curve, in this order,

    - **white balance**: ``temperature`` (-1 to 1; more is warmer) and ``tint`` (-1 to 1;
      more is magenta, less green).  The image is adapted (von Kries, in CAT02's cone
      space) from a white of ``6504 K x 2 ** temperature`` on the CIE daylight locus,
      moved by ``0.05 x tint`` in y, to D65: the white of a bluer light (temperature > 0)
      is made neutral, so everything looks warmer.  0 and 0 change nothing;
    - **contrast** about middle grey (0.18): each channel ``0.18 x (c / 0.18) ** contrast``
      (a power in log space: 1 changes nothing, more spreads the tones apart);
    - the ASC Color Decision List: ``(c x slope + offset) ** power`` a channel (RGB
      triples: ``slope`` scales, ``offset`` adds, ``power`` bends the tones; 1, 0, 1
      change nothing), then **saturation** about Rec. 709 luma (0: grey, 1: unchanged);

    then the tone curve and the sRGB encoding, and last the **colour table** ``lut`` (an
    ``engine.assets.color_lut.ColorLut``, ``load_cube_lut("grade.cube")``: a ``.cube``
    3D LUT exported from a grading application, applied to the encoded sRGB picture, as
    such tables are made), mixed in by ``lut_strength`` (0 to 1).
    """

    temperature: float = 0.0
    tint: float = 0.0
    contrast: float = 1.0
    slope: Any = field(default_factory=lambda: glm.vec3(1.0))
    offset: Any = field(default_factory=lambda: glm.vec3(0.0))
    power: Any = field(default_factory=lambda: glm.vec3(1.0))
    saturation: float = 1.0
    lut: ColorLut | None = None
    lut_strength: float = 1.0

    def _validate(self, name: str, value: Any) -> Any:
        if name in ("temperature", "tint"):
            return finite(self, name, value, low=-1.0, high=1.0)
        if name in ("contrast", "saturation"):
            return finite(self, name, value, low=0.0, high=MAX_GRADE_CONTRAST)
        if name == "slope":
            return _triple(self, name, value, 0.0, MAX_GRADE_SLOPE)
        if name == "offset":
            return _triple(self, name, value, -1.0, 1.0)
        if name == "power":
            value = _triple(self, name, value, 0.0, MAX_GRADE_POWER)
            if min(value) <= 0.0:
                raise ComponentValueError(f"ColorGrading.power must be > 0 a channel, got {value}")
            return value
        if name == "lut" and value is not None and getattr(type(value), "ASSET_KIND", None) != "lut":
            raise ComponentValueError(f"ColorGrading.lut must be an engine.assets.color_lut.ColorLut "
                                      f"(load_cube_lut), got {type(value).__name__}")
        if name == "lut_strength":
            return finite(self, name, value, low=0.0, high=1.0)
        return value


def _triple(owner: object, name: str, value: Any, low: float, high: float) -> glm.vec3:
    """Three finite numbers in [low, high] (one number: the same for each channel), as a
    glm.vec3 (the inspector drags it, a level file writes it as float32 at its shortest)."""
    items = _items(value)
    if items and len(items) != 3:
        raise ComponentValueError(f"{type(owner).__name__}.{name} must be three numbers (or one for all three), "
                                  f"got {len(items)}")
    v = vec3(owner, name, value, low=low)  # finite numbers, each >= low
    if max(v) > high:
        raise ComponentValueError(f"{type(owner).__name__}.{name} must have every component <= {high}, "
                                  f"got {tuple(v)}")
    return v


@dataclass(eq=False)
class Vignette(TrackedComponent):
    """The picture darkened towards its edges (on the camera's entity) as a lens darkens it:
    its natural vignetting, the cos^4 law (light reaching the film at an angle theta from the
    optical axis falls as cos^4 theta), in the linear image before the grade and the tone
    curve.  Each pixel is multiplied by ``1 - intensity + intensity x cos(theta) ** falloff``,
    theta the angle of its ray from the camera's view axis, so a wider lens darkens more, as a
    real one does (Unity's and three.js's vignettes are the same darkening drawn on the screen).

    - ``intensity`` (0..1): 0 none, 1 the whole falloff;
    - ``falloff`` (0..16): the power of the cosine; 4 is a lens's natural vignetting, more
      darkens nearer the middle.
    """

    intensity: float = 0.5
    falloff: float = 4.0

    def _validate(self, name: str, value: Any) -> Any:
        if name == "intensity":
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "falloff":
            return finite(self, name, value, low=0.0, high=MAX_VIGNETTE_FALLOFF)
        return value


MIN_FOCUS_DISTANCE = 0.01    # metres (DepthOfField.focus_distance): a centimetre, a macro lens's closest
MAX_FOCUS_DISTANCE = 1.0e6   # metres: a million is infinity to any lens
MAX_F_STOP = 64.0
MIN_F_STOP = 0.5             # faster than any real lens (f/0.7 is the fastest made)
MAX_FOCAL_LENGTH = 2000.0    # millimetres
MAX_BLUR = 0.1               # the largest disc's diameter, as a share of the picture's height


def _screen_point(owner: object, name: str, value: Any) -> glm.vec2:
    """Two numbers in [0, 1]: a share of the picture's width and height from its top-left."""
    parts = _items(value) if not isinstance(value, (str, bytes, dict)) else []
    if len(parts) != 2 or any(isinstance(p, bool) for p in parts):
        raise ComponentValueError(f"{type(owner).__name__}.{name} must be two numbers (shares of the picture's "
                                  f"width and height from its top-left), got {value!r}")
    return glm.vec2(finite(owner, name, parts[0], low=0.0, high=1.0), finite(owner, name, parts[1], low=0.0, high=1.0))


@dataclass(eq=False)
class DepthOfField(TrackedComponent):
    """The camera's lens focused at one distance, blurring what lies nearer or farther (on the
    camera's entity), as Unity's and Unreal's physical cameras do: each point is spread into
    the disc a thin lens images it as (its circle of confusion, ``engine/rules/lens_rules.py``),
    in the linear image before bloom and the tone curve.  The distance is the length of the
    light's way: a face seen in a mirror lies as far as the mirror plus the mirror to the face,
    so focusing on the mirror's frame blurs the reflection and focusing on the reflection
    blurs the frame, as a real camera's photograph does (a depth buffer holds only the glass).

    - ``focus_distance`` (metres, 0.01 to a million): what is sharp, along the light's way;
    - ``f_stop`` (0.5..64): the aperture's f-number; a smaller number blurs more;
    - ``focal_length`` (millimetres, or None): the lens; None: the one whose field of view on
      a full-frame sensor is the camera's (a wide camera has a short lens and a deep focus);
      a longer one blurs more (an orthographic camera without one: 50 mm);
    - ``max_blur`` (0..0.1): the largest disc's diameter as a share of the picture's height
      (a lens at f/1 can spread the sky over much of the frame; this keeps it a look);
    - ``autofocus``: focus on what the picture shows at ``focus_point`` (shares of its width
      and height from its top-left; the middle by default), through mirrors and portals too,
      following it at ``focus_speed`` (per second: each frame the focus moves the share
      ``1 - exp(-focus_speed * dt)`` of the way, in dioptres as a lens's focus ring turns; a
      camera's first frame starts there).  Without it the focus is ``focus_distance`` at once.
    - ``half_resolution`` (default True): the blur gathered at half the picture's size, each
      pixel whose disc is under a pixel or so keeping its own sharp colour (a quarter of the
      gather's cost; a sharp edge before a blurred background may take a pixel's fringe);
      False: every pixel gathered at full size.
    - ``blades`` (0, or 3..16): the aperture's blades; 0 a round aperture (round bokeh), else
      the blurred shape is the polygon its straight blades close to (a lamp out of focus a
      hexagon with 6), its corners on the round disc's edge, its light kept whole;
      ``blade_rotation`` (degrees) turns it (0: a corner to the right).
    """

    focus_distance: float = 10.0
    f_stop: float = 2.8
    focal_length: float | None = None
    max_blur: float = 0.02
    autofocus: bool = False
    focus_point: Any = field(default_factory=lambda: glm.vec2(0.5, 0.5))
    focus_speed: float = 4.0
    half_resolution: bool = True
    blades: int = 0
    blade_rotation: float = 0.0

    def _validate(self, name: str, value: Any) -> Any:
        if name == "half_resolution":
            return boolean(self, name, value)
        if name == "blades":
            blades = integer(self, name, value, low=0, high=MAX_BLADES)
            if blades in (1, 2):
                raise ComponentValueError(f"DepthOfField.blades must be 0 (round) or 3 to {MAX_BLADES} "
                                          f"(an aperture's polygon), got {value!r}")
            return blades
        if name == "blade_rotation":
            return finite(self, name, value, low=-360.0, high=360.0)
        if name == "focus_distance":
            return finite(self, name, value, low=MIN_FOCUS_DISTANCE, high=MAX_FOCUS_DISTANCE)
        if name == "f_stop":
            return finite(self, name, value, low=MIN_F_STOP, high=MAX_F_STOP)
        if name == "focal_length":
            return None if value is None else finite(self, name, value, low=1.0, high=MAX_FOCAL_LENGTH)
        if name == "max_blur":
            return finite(self, name, value, positive=True, high=MAX_BLUR)
        if name == "autofocus":
            return boolean(self, name, value)
        if name == "focus_point":
            return _screen_point(self, name, value)
        if name == "focus_speed":
            return finite(self, name, value, positive=True, high=MAX_ADAPT_SPEED)
        return value


MAX_BLADES = 16          # DepthOfField.blades: past this a polygon is as round as the disc
MAX_MOTION_BLUR = 0.25   # MotionBlur.max_blur: a streak at most a quarter of the picture's height


@dataclass(eq=False)
class MotionBlur(TrackedComponent):
    """The picture streaked by motion while the shutter is open (on the camera's entity), as
    Unity's and Unreal's motion blur: each pixel is smeared along the way what it shows moved on
    screen since the last frame, ``shutter`` of it, and a moving thing smears out over what lies
    behind it (a reconstruction filter: McGuire et al. 2012).  The camera's motion moves a point
    where the light's way puts it (``shaders/include/way.glsl``): in a mirror, the
    reflection's image behind the glass, so a reflection streaks by its own distance as the
    camera moves, not as the glass does; through a portal, the image beyond it; a camera
    carried through a portal keeps its motion across (last frame's view carried with it).

    - ``shutter`` (0..1): the share of a frame the shutter is open (0.5: a film camera's
      180-degree shutter; 0: none);
    - ``max_blur`` (0..0.25): the longest streak, as a share of the picture's height (a turn
      of the camera in one frame does not smear the picture away);
    - ``objects``: things that move streak by their own motion too (an entity's model matrix
      since the last frame, and a skinned or morphed mesh's pose, seen directly, in mirrors
      and through portals as each view projects it; ``engine/render/object_motion.py``); a
      mirror or portal that moves streaks what it shows by the camera's motion alone.
    """

    shutter: float = 0.5
    max_blur: float = 0.05
    objects: bool = True

    def _validate(self, name: str, value: Any) -> Any:
        if name == "shutter":
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "max_blur":
            return finite(self, name, value, positive=True, high=MAX_MOTION_BLUR)
        if name == "objects":
            return boolean(self, name, value)
        return value


MAX_ABERRATION = 0.02   # ChromaticAberration.intensity 1: red and blue images 2% larger and smaller than green
MAX_GRAIN = 1.0


MAX_FLARE_GHOSTS = 8


@dataclass(eq=False)
class LensFlare(TrackedComponent):
    """Lens flare (on the camera's entity, beside its ``Bloom``): the ghosts a real lens's
    inner reflections throw of bright lights, the image turned about the picture's middle and
    repeated along the line through it, and a halo ring (image-based lens flare: Chapman's
    pseudo lens flare, Unreal's image-based lens flares).  It is made of the bloom's blurred
    image, so only what blooms flares (set the Bloom's ``threshold`` to flare only the sun
    and lamps), and a light on one side of the picture throws its ghosts across the middle to
    the other, as the sun in a real camera does.

    - ``intensity`` (0 to 10, default 0.5): how bright the ghosts are, over the bloom's image.
    - ``ghosts`` (0 to 8, default 4): how many; the k-th of a light at p in the picture stands
      at 1 - (p - s k / 2) / (1 - s k), s the ``ghost_spacing`` (0 to 1, default 0.3): the
      first is the light turned about the middle, each next nearer the middle; a ghost fades
      towards the picture's edges.
    - ``halo`` (0 to 1, default 0.45; 0: none): the halo ring's radius about each point turned
      about the middle, as a share of the picture; ``halo_intensity`` (0 to 10, default 0.3).
    - ``fringe`` (0 to 0.05, default 0.01): each ghost's red and blue read that far apart along
      its line (a share of the picture): its colour fringes.

    Without a ``Bloom`` with an intensity on the camera it adds nothing and says so once (a
    ``ComponentWarning``).  Drawn at the bloom image's size (``engine/render/lens_flare.py``).
    """

    intensity: float = 0.5
    ghosts: int = 4
    ghost_spacing: float = 0.3
    halo: float = 0.45
    halo_intensity: float = 0.3
    fringe: float = 0.01

    def _validate(self, name: str, value: Any) -> Any:
        if name in ("intensity", "halo_intensity"):
            return finite(self, name, value, low=0.0, high=10.0)
        if name == "ghosts":
            return integer(self, name, value, low=0, high=MAX_FLARE_GHOSTS)
        if name in ("ghost_spacing", "halo"):
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "fringe":
            return finite(self, name, value, low=0.0, high=0.05)
        return value


@dataclass(eq=False)
class ChromaticAberration(TrackedComponent):
    """Colour fringes towards the picture's edges (on the camera's entity), as a real lens's
    lateral chromatic aberration makes them: its magnification differs with the wavelength, so
    the red image is a little larger than the green and the blue a little smaller, about the
    picture's middle.  Nothing moves at the middle; at the edges a bright edge splits into a red
    and a blue fringe (Unity's and Unreal's chromatic aberration).

    - ``intensity`` (0..1): the red image ``intensity x 2%`` larger than the green, the blue as
      much smaller (at 1920 pixels wide, up to about 19 pixels at the corners).
    """

    intensity: float = 0.25

    def _validate(self, name: str, value: Any) -> Any:
        if name == "intensity":
            return finite(self, name, value, low=0.0, high=1.0)
        return value


@dataclass(eq=False)
class FilmGrain(TrackedComponent):
    """Film's grain over the picture (on the camera's entity): noise a pixel, new each frame,
    added to the encoded picture after the tone curve, as Unity's and Unreal's film grain.

    - ``intensity`` (0..1): the grain's strength (its spread: ``intensity x 0.1`` of full
      white either way);
    - ``response`` (0..1): how much less grain the bright parts take (film's grain shows most in
      the shadows and mid-tones: 0 the same everywhere, 1 none on white);
    - ``size`` (1..8): a grain's size in pixels (a high-resolution picture's grain stays visible).
    """

    intensity: float = 0.3
    response: float = 0.8
    size: float = 1.0

    def _validate(self, name: str, value: Any) -> Any:
        if name in ("intensity", "response"):
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "size":
            return finite(self, name, value, low=1.0, high=8.0)
        return value
