"""Views and lights: a camera looks down its Transform's -Z; lights light the scene."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pyglm import glm

from components.limits import (
    MAX_COOKIE_SPOT_ANGLE,
    MAX_FAR,
    MAX_LIGHT_BOUNCES,
    MAX_LIGHT_RADIUS,
    MAX_LIGHT_SIDE,
    MAX_SHADOW_CASCADE_BLEND,
    MAX_SHADOW_CASCADES,
    MAX_SUN_ANGULAR_DIAMETER,
    MIN_LIGHT_SIDE,
    MIN_SHADOW_DISTANCE,
    MIN_SPOT_ANGLE,
    check_near_far,
)
from components.tracking import (
    HALF_MAX,
    ComponentValueError,
    TrackedComponent,
    boolean,
    choice,
    color,
    direction,
    finite,
    integer,
    warn_component,
)
from components.visibility import LAYER_FIELDS, ShownLayers

_DEFAULT_FAR = 200.0
CAMERA_PROJECTIONS = ("perspective", "orthographic")  # Camera.projection
CELESTIAL_BODIES = ("sun", "moon")  # DirectionalLight.body

# An image (engine.assets.texture_data.TextureData): components import none of the engine
# (rendering.py's note), a cookie is checked by its class's ASSET_KIND.
TextureData = Any


@dataclass(eq=False)
class Camera(ShownLayers):
    """A camera. The active camera with the lowest entity id renders.

    ``projection`` "perspective" (the default: ``fov_y`` degrees top to bottom) or
    "orthographic" (parallel rays, ``ortho_height`` world units top to bottom whatever the
    distance: isometric, top-down and side-on games, as Unity's and Godot's orthographic
    cameras).  Mirrors, portals, probes, shadows, fog and the sky draw alike in both; an
    orthographic camera's screen-space ambient occlusion and reflections are refused (they
    rebuild positions from a perspective depth image), and a bumpy mirror or water seen in one
    reflects flat (its bent lookup is a perspective vanishing point).

    ``shows_layers`` (None: all) and ``hides_layers`` are the reflection layers its view
    shows (a camera's culling mask, ``components.visibility``); the mirrors and portals it
    sees show at most those too."""

    SHAREABLE = False  # one entity's own state: see components.tracking
    fov_y: float = 60.0
    near: float = 0.05
    far: float = _DEFAULT_FAR
    active: bool = True
    projection: str = "perspective"
    ortho_height: float = 10.0

    def _validate(self, name: str, value: Any) -> Any:
        if name in LAYER_FIELDS:
            return super()._validate(name, value)  # ShownLayers' check
        if name == "fov_y":
            return finite(self, name, value, low=1.0, high=179.0)
        if name in ("near", "far"):
            return check_near_far(self, name, value, _DEFAULT_FAR)
        if name == "active":
            return boolean(self, name, value)
        if name == "projection":
            value = choice(self, name, value, CAMERA_PROJECTIONS)
            world = getattr(self, "_world_ref", None)
            if world is not None:
                for entity in self._entities:  # its screen passes need a perspective, as at spawn
                    world.check_invariants(entity, Camera, projection=value)
            return value
        if name == "ortho_height":
            return finite(self, name, value, low=1e-3, high=1e6)
        return value


@dataclass(eq=False)
class FlyController(TrackedComponent):
    """WASD + mouse fly controls for the entity's Transform (used by windowed runs).
    ``speed`` is in the entity's own units a second: its Transform's scale multiplies it.
    ``yaw`` and ``pitch`` are degrees (``yaw_pitch_rotation``'s); ``pitch`` from -90 (straight
    down) to 90 (straight up): past them a view is upside down, and the first mouse move held
    it to 89 either way, a jump."""

    SHAREABLE = False  # one entity's own state: see components.tracking
    speed: float = 4.0
    mouse_sensitivity: float = 0.15
    yaw: float = 0.0
    pitch: float = 0.0

    def _validate(self, name: str, value: Any) -> Any:
        if name == "speed":
            # Bounded so speed x dt x Shift can never carry the camera past float32.
            return finite(self, name, value, low=0.0, high=1e6)
        if name == "mouse_sensitivity":
            return finite(self, name, value, low=0.0, high=1e3)
        if name == "yaw":
            return finite(self, name, value, low=-1e6, high=1e6)
        if name == "pitch":
            return finite(self, name, value, low=-90.0, high=90.0)
        return value


# Shadow maps (engine/render/shadows.py): sides in texels, and the PCF filter's reach.
MIN_SHADOW_RESOLUTION = 64
MAX_SHADOW_RESOLUTION = 4096   # a 4096^2 depth map is 64 MiB: past that, fit the level instead
MAX_SHADOW_SOFTNESS = 8.0      # texels; a wider filter would need more taps than it takes
MAX_LAMP_SCATTER = 100.0       # PointLight.volumetric: at most this many times its light in the air


def _shadow_field(owner: TrackedComponent, name: str, value: Any) -> Any:
    """The shadow fields DirectionalLight and PointLight share (None: not a shadow field)."""
    if name == "shadows":
        return boolean(owner, name, value)
    if name == "shadow_resolution":
        value = integer(owner, name, value, low=MIN_SHADOW_RESOLUTION, high=MAX_SHADOW_RESOLUTION)
        if value & (value - 1):
            raise ComponentValueError(
                f"{type(owner).__name__}.shadow_resolution must be a power of two (texels a side), got {value}")
        return value
    if name == "shadow_softness":
        return finite(owner, name, value, low=0.0, high=MAX_SHADOW_SOFTNESS)
    if name == "bounces":
        return integer(owner, name, value, low=0, high=MAX_LIGHT_BOUNCES)
    return None


@dataclass(eq=False)
class DirectionalLight(TrackedComponent):
    """Light from infinitely far along ``direction`` (the way the light travels).

    ``shadows`` (on by default): things cast shadows in its light, from one shadow map a
    frame fitted to the whole level and shared by every view (the main camera, every mirror,
    portal and probe face), redrawn only when a caster or the light changed
    (``engine/render/shadows.py``).  ``shadow_resolution``: the map's side in texels (a power
    of two); ``shadow_softness``: how far, in texels, the edge is filtered (percentage-closer
    filtering; 0 is the hardest edge the map's texels allow).

    ``shadow_cascades`` (default 1: the level's map alone): with 2 to 4, the map is joined by
    up to three more of the same resolution, each a square about the active camera (shadow
    cascades: a small map near the eye, where a texel covers many pixels), the largest
    ``shadow_distance`` metres round it, each next a quarter of that.  A point takes the
    smallest map holding it, whatever view shows it, so a mirror shows the same sharp shadow
    as the camera does (a ring, not the camera's frustum: a mirror looks behind the camera).
    A ring is drawn again when the camera is more than a quarter of its radius from where it
    was centred (on a grid of that step: a camera swaying on the spot keeps it), or a caster
    in it changed.  The maps share the shadow atlas's four tiles with the other suns: where they
    do not fit, the light has fewer (``RenderStats.shadow_cascades_cut``).
    ``shadow_cascade_blend`` (default 0.15, 0 to 0.5): the outer share of each ring's square
    over which its shadow fades into the next larger map's, so the sharper shadow gives way
    without a seam (cascade blending, as Unity's cascade border and Godot's blend splits);
    0 switches maps at the edge.  A point in the band reads both maps.

    ``angular_diameter`` (degrees, default 0: a point-like sun, the hardest edge the map and
    ``shadow_softness`` allow; the real sun is 0.53): the sun's size, so its shadows are an
    area light's (Unreal's source angle, HDRP's angular diameter, Godot's angular distance):
    hard where the caster meets the ground, wider the farther it stands, a penumbra of
    2 tan(angular_diameter / 2) metres a metre between them (percentage-closer soft shadows:
    the blockers' mean depth found in 12 taps of the map read as it is, then 16 comparisons
    over the penumbra that gives; ``shaders/include/shadows.glsl`` ``soft_sun_shadow``).  In
    every map, the level's and the cascades'; with the "grid" shadow filter (a GPU's default;
    a software rasteriser's "single" keeps one tap).  The map read as it is is one sampler
    more for the scene programs (the 18th of the fullest build): on an OpenGL with fewer
    than 18 (``GL_MAX_TEXTURE_IMAGE_UNITS``) the edge stays hard and a ``GLLimitWarning``
    says so.  At most ``MAX_SUN_ANGULAR_DIAMETER`` (20 degrees); the penumbra is at most 64
    of the level map's (longer side's) texels across (a cascade's finer texels do not narrow
    it), round in metres where the level's map has longer texels one way.

    ``bounces`` (default 1): how many mirrors and portals that carry light
    (``Mirror.reflects_light``, ``Portal.carries_light``) its light goes through in a row:
    0 none, 1 one (a mirror throws it on the floor), up to ``MAX_LIGHT_BOUNCES`` = 4 (mirror
    to mirror); never deeper than a surface's own ``max_depth`` or the view tree's depth cap.
    Each bounce is a virtual light of its own (``engine/rules/shadow_rules.py``).

    ``body`` (default "sun"): what shines.  The brightest "sun" is the one a generated sky
    follows (its disc, its glow, an atmosphere's colours) and a camera's contact shadows and
    fog glow take.  A "moon" (HDRP's celestial bodies, Unreal's second atmosphere light) is
    never the sky's sun: a generated sky draws its disc (``Skybox.moon_color``, the size of the
    sun's) lit from the sky's sun as a ball is, so its phase follows their angle (full when
    opposite it, half at a right angle, gone beside it); an atmosphere dims and reddens it and
    its light as the sun's; a ``TimeOfDay`` on its entity puts it where the moon stands
    (``TimeOfDay.moon_age``).  Its light is its own ``color`` x ``intensity`` (a full moon
    lights a night at about 1/400,000 of the sun: a game picks what reads)."""

    direction: Any = field(default_factory=lambda: glm.vec3(-0.3, -1.0, -0.4))
    color: Any = field(default_factory=lambda: glm.vec4(1.0))
    intensity: float = 1.0
    shadows: bool = True
    shadow_resolution: int = 2048
    shadow_softness: float = 1.0
    shadow_cascades: int = 1
    shadow_distance: float = 20.0
    shadow_cascade_blend: float = 0.15
    angular_diameter: float = 0.0
    bounces: int = 1
    body: str = "sun"

    def _validate(self, name: str, value: Any) -> Any:
        if name == "direction":
            return direction(self, name, value)
        if name == "body":
            return choice(self, name, value, CELESTIAL_BODIES)
        if name == "angular_diameter":
            return finite(self, name, value, low=0.0, high=MAX_SUN_ANGULAR_DIAMETER)
        if name == "shadow_cascades":
            return integer(self, name, value, low=1, high=MAX_SHADOW_CASCADES)
        if name == "shadow_distance":
            return finite(self, name, value, low=MIN_SHADOW_DISTANCE, high=MAX_FAR)
        if name == "shadow_cascade_blend":
            return finite(self, name, value, low=0.0, high=MAX_SHADOW_CASCADE_BLEND)
        if name == "color":
            return color(self, name, value)
        if name == "intensity":
            return finite(self, name, value, low=0.0, high=HALF_MAX)  # lit colour lands in half floats
        shadow = _shadow_field(self, name, value)
        return value if shadow is None else shadow


@dataclass(eq=False)
class PointLight(TrackedComponent):
    """Light from the entity's position, falling off smoothly to zero at ``range`` (metres, at
    most ``MAX_FAR``, as a camera's far plane: it is the shadow cube's).

    ``shadows`` (off by default, as in most engines: six views a light): things within its
    range cast shadows, from a cube shadow map of ``shadow_resolution`` texels a face,
    redrawn only when a caster in its range or the light changed.  The light's own entity's
    mesh is its body (a glowing bulb with the light on it, the sample level's lamp) and casts
    none of its shadow, nor its image's through a mirror or portal; other lights' maps keep it.  ``bounces`` as
    ``DirectionalLight.bounces`` (default 1; 0 to 4 mirrors and portals in a row).

    ``spot_angle`` (degrees, default 180: all round) makes it a spot light: it shines only
    within that angle of the entity's -Z (its forward, as a camera looks; turn the Transform
    to aim it), a cone ``2 * spot_angle`` across, like Godot's ``spot_angle`` and half of
    Unity's ``spotAngle``.  ``spot_blend`` (0 to 1, default 0.15) is the share of that angle
    over which its light fades out towards the edge (three.js's ``penumbra``): 0 a hard
    edge.  Through a mirror or portal the cone is carried with the light (a flashlight aimed
    at a mirror lights what the mirror faces, within the reflected cone)
    (``engine/rules/light_rules.py`` ``spot_cone``).  A spot up to ``SPOT_MAP_MAX_ANGLE``
    (45 degrees) casts from one perspective map fitted to its cone, ``shadow_resolution``
    texels a side (several times sharper than a cube face for a narrow cone); a wider one
    from the cube, only its faces the cone lights.

    ``cookie`` (a TextureData, sRGB colour as ``Material.texture``; None: none) is an image
    the spot projects, as a slide projector or a gobo does (Unity's and Godot's light cookies,
    Unreal's light functions): its light at each point is times the image's colour where the
    line from the light meets it, the image filling the square that holds the cone's circle
    (its top towards the entity's +Y, its right towards +X, seen from behind the light).  Black
    where it should not shine, coloured for stained glass.  A spot light up to
    ``MAX_COOKIE_SPOT_ANGLE`` (80 degrees) takes one, and so does an all-round light
    (``spot_angle`` 180, Unity's point-light cookie): its image is wrapped about it as a
    panorama (equirectangular: longitude across, latitude up), its middle ahead of the light
    (the entity's -Z), its right towards +X and its top row straight up (+Y), as a lamp
    shade with holes, a caged bulb or a disco ball throws light all round.  Through a mirror or portal the image is
    carried with the light: a mirror shows it the other way round, as a real one does; lit
    particles take the colour at their centres, the shafts' air at each step.  The
    renderer draws it from a ``COOKIE_SIZE`` (512) square copy with mipmaps
    (``engine/render/spot_cookies.py``).  A rectangle light's cookie is the picture on its
    face instead, a screen's or a stained-glass window's (Unity HDRP's area light cookie,
    Unreal's rect light source texture): each part of the panel shines in its colour there,
    the picture's right towards the entity's -X and its top towards +Y, so it reads as a
    screen does from in front; a polished floor shows it, a rough one takes the colours of
    the parts nearest it, the shafts' air and lit particles the picture's mean colour.  Each
    integral of the panel's light times the picture's colour its lobe sees,
    read from the picture's mip chain where the lobe's mean way in meets the face
    (``rect_face`` in ``shaders/include/rect_lights.glsl``): exact for one colour all over, an
    approximation of the colours' weights otherwise (``tests/test_rect_light_images.py``).

    ``radius`` (metres, default 0: a point) makes it a sphere of light, as a bulb is (Unreal's
    source radius, Unity's and Godot's light size): its highlights on smooth surfaces are the
    sphere's reflection, a disc as wide as the bulb a chrome ball shows in a mirror, not a
    pin-point, and wider and dimmer on rough ones, the light's energy kept (the representative
    point of the sphere nearest each reflected ray, ``shaders/include/ggx.glsl``
    ``sphere_highlight``).  Its diffuse light is a point's; its shadow from its cube is soft,
    the sphere's penumbra (percentage-closer soft shadows: ``shaders/include/shadows.glsl``
    ``soft_cube_shadow``, with the "grid" shadow filter).  At most ``MAX_LIGHT_RADIUS`` (10 m);
    its range is measured from its centre, so a radius reaching it (the light falls to zero
    inside the sphere) is warned.

    ``rectangle`` (metres, (width, height); default (0, 0): a point) makes it a rectangle of
    light, as a ceiling panel, a softbox or a window's glow is (Unreal's and three.js's rect
    lights, Unity HDRP's rectangle area light): its width along the entity's X, its height
    along its Y, shining from its front (the entity's -Z, where a spot aims) into the half
    space before it, each point of it as bright from every side (Lambertian), its intensity
    spread over its area: seen from far ahead it lights as a point light of that intensity
    does.  A surface takes the light of the whole rectangle above its horizon: its diffuse
    light exactly (the polygon's form factor), its highlight by linearly transformed cosines
    (Heitz et al. 2016, fitted to the engine's GGX: ``engine/render/ltc_fit.py``), so a
    glossy floor shows the panel's stretched reflection and a mirror-smooth one its outline.
    Its shadow from its cube is soft, as a disc of its area casts it, and nothing behind its
    plane blocks it; its range, spot cone and contact shadows are taken from its centre, as a
    point light's, its cookie is the picture on its face (above), and the shafts' air and lit
    particles take its light by
    Lambert's cosine of its face (``shaders/include/lights.glsl`` ``lamp_face``).  Both
    sides from ``MIN_LIGHT_SIDE`` (1 mm) to ``MAX_LIGHT_SIDE`` (50 m); not with a ``radius``
    or a ``length``.
    Through a mirror or portal its image is the rectangle's (``Mirror.reflects_light``).  At
    most ``MAX_RECT_LIGHTS`` (8) of the lights that reach the scene are lit as rectangles at
    once (the first by the lights' slots); the rest light as points from their centres,
    counted in ``RenderStats.rect_lights_cut`` and said by a ``LightLimitWarning``.

    ``length`` (metres; default 0: not a tube) makes it a tube of light along the entity's X,
    centred on its position, as a fluorescent tube or a neon bar is (Unreal's source length,
    Unity HDRP's tube light), its ``radius`` the tube's (0: a line, drawn as a tube
    ``MIN_LIGHT_SIDE`` across): each point of its surface as bright from every side, its
    intensity spread over its length, so seen broadside from far off it lights as a point light
    of that intensity does, and end on not at all.  Lit as a rectangle is, through its axis and
    turned about it to face each shaded point (the outline a thin cylinder shows from there,
    whose light is exactly the cylinder's): its diffuse light exact, its highlight the stretched
    streak a glossy floor shows; it shines to both sides and its shadow cube has every face.
    It counts among the ``MAX_RECT_LIGHTS``; not with a ``rectangle``.  From ``MIN_LIGHT_SIDE``
    to ``MAX_LIGHT_SIDE``.

    ``contact_shadows`` (off by default; HDRP's per-light switch, Unreal's contact shadow
    length): where the active camera has ``ContactShadows``, this light's light is taken from
    a point where something the view shows lies across a short ray from it towards the light,
    as the sun's is (the camera's component sets the ray).  At most ``MAX_CONTACT_LAMPS`` (4)
    of the lights that reach the scene at once have them (the ones that matter most to the
    camera); the rest are counted in ``RenderStats.contact_lamps_cut`` and a
    ``LightLimitWarning`` says so.

    ``volumetric`` (1 by default, 0 to 100; Unreal's volumetric scattering intensity, Godot's
    volumetric fog energy): how much of its light the active camera's ``VolumetricFog``
    scatters towards the eye, in its shadow where it casts one: a lantern's glow in the haze,
    a torch's beam, its cone cut by what stands in it (0: none).  At most
    ``MAX_VOLUMETRIC_LAMPS`` (4) of the lights that reach the scene at once (the first by
    the lights' slots); where the camera has shafts, the rest are counted in
    ``RenderStats.volumetric_lamps_cut`` and a ``LightLimitWarning`` says so.  Its cookie
    colours its light in the air as on a wall."""

    color: Any = field(default_factory=lambda: glm.vec4(1.0))
    intensity: float = 1.0
    range: float = 10.0
    shadows: bool = False
    shadow_resolution: int = 512
    shadow_softness: float = 1.0
    bounces: int = 1
    spot_angle: float = 180.0
    spot_blend: float = 0.15
    cookie: TextureData | None = None
    radius: float = 0.0
    rectangle: tuple[float, float] = (0.0, 0.0)
    length: float = 0.0
    contact_shadows: bool = False
    volumetric: float = 1.0

    def _validate(self, name: str, value: Any) -> Any:
        if name == "color":
            return color(self, name, value)
        if name == "cookie" and value is not None:
            if getattr(type(value), "ASSET_KIND", None) != "texture":
                raise ComponentValueError(
                    f"PointLight.cookie must be an engine.assets.texture_data.TextureData, got {type(value).__name__}")
            if MAX_COOKIE_SPOT_ANGLE < self.spot_angle < 180.0:
                raise ComponentValueError(
                    f"PointLight.cookie: a cookie is projected by a spot light up to {MAX_COOKIE_SPOT_ANGLE:g} degrees "
                    f"(spot_angle) or wrapped about an all-round light (180), and this light's spot_angle is "
                    f"{self.spot_angle:g}: narrow the spot first, or make it all round")
            return value
        if name == "intensity":
            return finite(self, name, value, low=0.0, high=HALF_MAX)  # lit colour lands in half floats
        if name == "range":
            # At most a camera's far plane: the range is the shadow cube's far plane, whose
            # perspective overflows float32 near its top (3.4e38 cast no shadow, silently).
            value = finite(self, name, value, positive=True, high=MAX_FAR)
            _say_sphere_past_range(getattr(self, "radius", 0.0), value)
            return value
        if name == "spot_angle":
            value = finite(self, name, value, low=MIN_SPOT_ANGLE, high=180.0)
            if MAX_COOKIE_SPOT_ANGLE < value < 180.0 and getattr(self, "cookie", None) is not None:
                raise ComponentValueError(
                    f"PointLight.spot_angle = {value:g}: this light has a cookie, which a spot light up to "
                    f"{MAX_COOKIE_SPOT_ANGLE:g} degrees projects or an all-round light (180) wraps about it: take "
                    "the cookie off (cookie = None) first")
            return value
        if name == "spot_blend":
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "radius":
            value = finite(self, name, value, low=0.0, high=MAX_LIGHT_RADIUS)
            if value > 0.0 and getattr(self, "rectangle", (0.0, 0.0)) != (0.0, 0.0):
                raise ComponentValueError(
                    f"PointLight.radius = {value:g}: this light is a rectangle (rectangle = {self.rectangle!r}); a "
                    "light is a sphere, a tube or a rectangle, not two: set rectangle = (0, 0) first")
            _say_sphere_past_range(value, getattr(self, "range", 10.0))
            return value
        if name == "rectangle":
            return self._rectangle(value)
        if name == "length":
            value = finite(self, name, value, low=0.0, high=MAX_LIGHT_SIDE)
            if 0.0 < value < MIN_LIGHT_SIDE:
                raise ComponentValueError(
                    f"PointLight.length must be at least {MIN_LIGHT_SIDE:g} m (or 0: not a tube), got {value!r}")
            if value > 0.0 and getattr(self, "rectangle", (0.0, 0.0)) != (0.0, 0.0):
                raise ComponentValueError(
                    f"PointLight.length = {value:g}: this light is a rectangle (rectangle = {self.rectangle!r}); a "
                    "light is a sphere, a tube or a rectangle, not two: set rectangle = (0, 0) first")
            return value
        if name == "contact_shadows":
            return boolean(self, name, value)
        if name == "volumetric":
            return finite(self, name, value, low=0.0, high=MAX_LAMP_SCATTER)
        shadow = _shadow_field(self, name, value)
        return value if shadow is None else shadow

    def _rectangle(self, value: Any) -> tuple[float, float]:
        """(width, height), both from MIN_LIGHT_SIDE to MAX_LIGHT_SIDE metres, or (0, 0)."""
        if _not_pair(value):
            raise ComponentValueError(f"PointLight.rectangle must be (width, height) in metres, got {value!r}")
        width, height = (finite(self, "rectangle", side, low=0.0, high=MAX_LIGHT_SIDE) for side in value)
        if (width, height) == (0.0, 0.0):
            return (0.0, 0.0)
        if min(width, height) < MIN_LIGHT_SIDE:
            raise ComponentValueError(
                f"PointLight.rectangle: both sides must be at least {MIN_LIGHT_SIDE:g} m (or both 0: a point), got "
                f"{value!r}")
        if getattr(self, "radius", 0.0) > 0.0:
            raise ComponentValueError(
                f"PointLight.rectangle = {value!r}: this light is a sphere (radius = {self.radius:g}); a light is a "
                "sphere, a tube or a rectangle, not two: set radius = 0 first")
        if getattr(self, "length", 0.0) > 0.0:
            raise ComponentValueError(
                f"PointLight.rectangle = {value!r}: this light is a tube (length = {self.length:g}); a light is a "
                "sphere, a tube or a rectangle, not two: set length = 0 first")
        return (width, height)


def _say_sphere_past_range(radius: float, reach: float) -> None:
    """Warn of a sphere light whose ``radius`` reaches its ``range``: its light falls to zero
    at the range from its centre, inside the sphere, so it lights nothing outside it (said
    once, when the second of the two is given)."""
    if radius > 0.0 and radius >= reach:
        warn_component(f"PointLight.radius = {radius:g} reaches its range = {reach:g}: its light falls to zero "
                       "at the range from its centre, inside the sphere, so it lights nothing outside it; give it "
                       "a range past its radius")


def _not_pair(value: Any) -> bool:
    """Whether ``value`` is not a sequence of exactly two items (text is not one)."""
    if isinstance(value, (str, bytes, dict)):
        return True
    try:
        return len(value) != 2
    except TypeError:
        return True
