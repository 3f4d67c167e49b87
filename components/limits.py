"""The engine's limits on component values, one constant each: the components refuse a value
past them when it is given, and the systems that honour them read the same constant.  A limit
several components share is checked here too (``check_near_far``: a camera's and a probe's
planes), so no component words or bounds it its own way."""
from __future__ import annotations

from typing import Any

from components.tracking import ComponentValueError, finite

# Views deep a mirror, portal or probe face sees into mirrors and portals (Mirror.max_depth,
# Portal.max_depth, ReflectionProbe.depth, the view tree's depth cap).  Each level is one more
# set of views drawn into one more level of targets; Valve's Portal stops at 10 views.
MAX_VIEW_DEPTH = 16
# Mirrors and portals in a row a light's light goes through (DirectionalLight.bounces,
# PointLight.bounces): each bounce is one more virtual light (a shadow map and a light's
# shading), and the shader tests one aperture a bounce (shaders/include/virtual_lights.glsl).
MAX_LIGHT_BOUNCES = 4
# A sun's shadow maps (DirectionalLight.shadow_cascades): the level's and up to three rings
# about the camera, sharing the shadow atlas's four tiles (engine/render/shadows.py).
MAX_SHADOW_CASCADES = 4
# The smallest largest ring (metres; DirectionalLight.shadow_distance): its innermost ring is
# a sixteenth of it, a few centimetres for a map a few hundred texels wide at the least.
MIN_SHADOW_DISTANCE = 0.5
# The widest cascade blend (DirectionalLight.shadow_cascade_blend): the outer half of a ring's
# square, past which the next ring in would find little of its own left unblended.
MAX_SHADOW_CASCADE_BLEND = 0.5
# Local fog volumes at once (FogVolume): the Fog block holds each one's matrix and colour, and
# every fogged pixel integrates each one's density along its stretch of air.
MAX_FOG_VOLUMES = 8
# The widest sun (DirectionalLight.angular_diameter, degrees): the real one is 0.53; past a
# few degrees the sky is overcast rather than a disc, and the blocker search's reach (64 of
# the level map's texels across, shaders/include/shadows.glsl) caps the penumbra before 20.
MAX_SUN_ANGULAR_DIAMETER = 20.0
# The narrowest spot light (PointLight.spot_angle, degrees from its axis to its edge): a
# tenth of a degree is a 2 cm disk at ten metres, past which float32's cosines of the cone's
# edge (1 - 1.5e-6) stop telling the edge from the axis.
MIN_SPOT_ANGLE = 0.1
# The widest spot light a cookie may ride on (PointLight.cookie, degrees from its axis to its
# edge): the cookie is a perspective projection whose square's half-width is tan(angle), so
# at 80 degrees a texel at the edge is stretched 33 times a middle one's (1 / cos^2), and at
# 90 the projection has no square at all.
MAX_COOKIE_SPOT_ANGLE = 80.0
# The largest sphere a point light may be (PointLight.radius, metres): a light's size, not a room's.
MAX_LIGHT_RADIUS = 10.0
# A rectangle light's sides (PointLight.rectangle, metres): from a millimetre (below it the
# rectangle's radiance, its intensity over its area, leaves float16's range) to a wall of
# windows.
MIN_LIGHT_SIDE = 0.001
MAX_LIGHT_SIDE = 50.0
# Rectangle lights lit as rectangles at once (of the kept point lights, the first by slot; the
# rest light as points, said once): each one the scene shader loops over apart (a multiple of 4).
MAX_RECT_LIGHTS = 8
# The largest index of refraction (Refractive.ior): diamond is 2.42, germanium 4.0; past it
# almost all light is reflected (Schlick's f0 over 0.36) and the refracted ray barely bends more.
MAX_IOR = 4.0
# Skybox.rayleigh and haze (an atmosphere's molecules and aerosols): at most this many times
# Earth's.  Twenty times the haze is a thick fog's air, twenty times the molecules a sky
# whose sunsets are dark red by 20 degrees up; past that the tables' steps cannot follow it.
MAX_AIR_SCALE = 20.0
# Skybox.altitude's largest, metres: an airliner's (the sky-view table holds the ways above the
# horizon; from higher the horizon dips more than a few degrees below it, into the ground's fade).
MAX_ALTITUDE = 10_000.0
# Refractive.dispersion (glTF's KHR_materials_dispersion, 20 / the Abbe number): 10 is an
# Abbe number of 2, past any glass or gem (diamond's is 55, dense flint's about 20).
MAX_DISPERSION = 10.0
# Material.iridescence_thickness, nanometres: past a few thousand a film's fringes are finer
# than the eye's colour bands and it shows white (the thin-film model's two orders say nothing more).
MAX_FILM_THICKNESS = 5000.0
# Material.subsurface_scale, metres: the distance light wanders under a surface (skin's red a
# few millimetres, wax and jade a centimetre or two); past a metre the light under a wall would
# wrap round a room's corners: a thing that large is fog, not a surface.
MAX_SUBSURFACE_SCALE = 1.0
# Joints one skin may have (Skin.joint_matrices, a mesh's joints a vertex): a row of the
# pose texture, three texels a joint (engine/render/pose_rows.py); a character rig has 20
# to 150, Unreal's limit a section is 256 too.
MAX_JOINTS = 256
# Morph targets one mesh may have (Mesh.morph_positions, Morph.weights): their weights in
# four texels of its pose row; a face's expressions are a dozen or two (three.js's limit
# with the targets in a texture is larger; glTF's own viewer blends every one, as here).
MAX_MORPH_TARGETS = 16
# A morph weight's reach either side of 0 (glTF's are usually 0 to 1; past a few is a mistake).
MAX_MORPH_WEIGHT = 16.0

# Reflection layers (show/hide lists): an entity belongs to some of REFLECTION_LAYERS layers
# and a mirror, portal, probe or camera shows some of them; a view shows an entity when they
# share one.  16 layers keep the entity's bits exact in the float slot the scene pass reads.
REFLECTION_LAYERS = 16
ALL_LAYERS = (1 << REFLECTION_LAYERS) - 1
# The kinds of view an entity can be hidden in.  A view's kinds are those of the surfaces its
# chain of views passed through (the main camera's own view is DIRECT, a probe face's tree is
# PROBE throughout), so a vampire hidden in mirrors is hidden in a portal seen in a mirror too.
VIEW_DIRECT, VIEW_MIRROR, VIEW_PORTAL, VIEW_PROBE = 1, 2, 4, 8
VIEW_KINDS = 4         # bits 0-3 of a view mask; the layers it shows are bits 4-19
# Bits 20 and 21 of an entity's code (never of a view's mask): it casts no shadow
# (MeshRef.casts_shadows), it receives none (MeshRef.receives_shadows); bit 22: a portal's
# opening that carries light (Portal.carries_light) casts a shadow, the light it takes in
# going out of its partner instead of on behind it.  The code stays below 2^24, exact in the
# float slot it rides in.
NO_SHADOW_BIT = 1 << (VIEW_KINDS + REFLECTION_LAYERS)
NO_RECEIVE_BIT = NO_SHADOW_BIT << 1
OPENING_CASTS_BIT = NO_RECEIVE_BIT << 1

# Depth range the 24-bit depth buffer still resolves, for every view with a near and a far
# plane (Camera, ReflectionProbe): far / near up to 1e7 keeps surfaces a few percent of their
# distance apart distinct at the far end; beyond, entity pixels vanish.
MIN_NEAR = 1e-4
MAX_FAR = 1e7
MAX_DEPTH_RATIO = 1e7


def check_near_far(owner: Any, name: str, value: Any, default_far: float) -> float:
    """``_validate`` of a ``near`` or ``far`` plane (``name``) of ``owner`` (a Camera, a
    ReflectionProbe): a finite distance > 0, near at least ``MIN_NEAR``, far at most
    ``MAX_FAR``, far beyond near and far / near at most ``MAX_DEPTH_RATIO``.  Checked on every
    write, not only at construction (the other plane is in ``__dict__`` once set; during
    ``__init__`` near comes first); ``default_far`` is the class's, to blame the right field."""
    kind = type(owner).__name__
    value = finite(owner, name, value, positive=True, high=MAX_FAR if name == "far" else None)
    if name == "near" and value < MIN_NEAR:
        raise ComponentValueError(f"{kind}.near must be >= {MIN_NEAR} (depth precision), got {value!r}")
    near = value if name == "near" else owner.__dict__.get("near")
    far = value if name == "far" else owner.__dict__.get("far")
    if near is None or far is None:
        return value
    if far <= near:
        # Blame the field the user set: during construction (far not yet in __dict__)
        # Camera(near=500) is wrong about near, not about the default far (both given, as in
        # Camera(near=10, far=1), the later one, far, is blamed).
        blamed = "near" if name == "far" and "far" not in owner.__dict__ and value == default_far else name
        raise ComponentValueError(f"{kind}.{blamed} must keep far > near, got near={near} far={far}")
    if far / near > MAX_DEPTH_RATIO:
        raise ComponentValueError(
            f"{kind}.{name} must keep far / near <= {MAX_DEPTH_RATIO:.0e} (beyond it the depth buffer "
            f"cannot tell surfaces apart), got near={near} far={far}")
    return value

# Living particles one emitter may hold (ParticleEmitter.max_particles): each is a row of 48
# bytes uploaded a frame and four vertices a view; an emitter asked for more spawns none past
# it (counted in RenderStats.particles_capped, said once with a ParticleLimitWarning).
MAX_PARTICLES = 65536
# A particle's longest life (ParticleEmitter.lifetime, seconds): an hour is a still cloud.
MAX_PARTICLE_LIFETIME = 3600.0
# A flipbook's most columns or rows (ParticleEmitter.sheet): 64 x 64 frames of a 4096 texture
# are 64 texels each.
MAX_SHEET_CELLS = 64
# Point and spot lights with contact shadows at once (PointLight.contact_shadows): each a
# channel of the images screen-space occlusion's march writes (engine/render/screen_occlusion.py):
# at most 4.
MAX_CONTACT_LAMPS = 4
# The point and spot lights whose light the camera's VolumetricFog scatters at once
# (PointLight.volumetric; the first by the Lights block's slots).
MAX_VOLUMETRIC_LAMPS = 4
# An IrradianceVolume's grid: at least 2 and at most this many points along each axis (its
# light lives in the irradiance table's rows: nine tiles of x points across, y x z rows down,
# engine/render/views.py VOLUME_ROW).  Each point is a six-face capture: 4096 of them are a
# bake of seconds on a GPU and minutes on llvmpipe.
MAX_VOLUME_AXIS_POINTS = 16
# An IrradianceVolume's bounces: each a round of the whole grid's captures, lit by the round
# before it (a bake of eight rounds is eight times one round's time).
MAX_VOLUME_BOUNCES = 8
# Irradiance volumes lighting a world at once (the lowest entities'; the rest said once and
# ignored): each a slot of the irradiance table's rows, the scene shader weighing each at a point.
MAX_IRRADIANCE_VOLUMES = 4
# CloudLayer.density, the optical depth straight through its thickest cloud: 64 lets through
# e^-64 of the sun (nothing); a storm's is a few hundred, which draws no differently.
MAX_CLOUD_DENSITY = 64.0
# CloudLayer.wind, metres a second: the jet stream blows at 100; past 200 the clouds flicker by.
MAX_CLOUD_WIND = 200.0
