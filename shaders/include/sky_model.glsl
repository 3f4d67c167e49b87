// The generated sky as a function of direction: the GLSL twin of engine/render/sky.py's
// sky_radiance, which owns the rule (tests/test_generated_sky.py checks that the two agree,
// pixel by pixel, the sun's disc included).  The sky pass draws a generated Skybox with it at
// the screen's own resolution (sky.frag's GENERATED_SKY build); a Skybox of given faces, and
// every reflection of the sky, read the cube map made from the same function.
uniform vec3 sky_ground;          // an atmosphere's: the ground's radiance (its albedo lit)
uniform vec3 sky_sun_direction;   // unit, towards the sun
uniform vec3 sky_sun_color;       // the disc (an atmosphere's: through the air)

// The disc: cos 0.9990 (2.6 degrees from its centre) to 0.9995 (1.8 degrees) ramps up.
float disc_strength(float cosine) {
    return clamp((cosine - 0.9990) / 0.0005, 0.0, 1.0);
}

vec3 sun_disc(float cos_sun) {
    return disc_strength(cos_sun) * sky_sun_color;
}

#if defined(MOON) || defined(MOON_AIR)
uniform vec3 sky_moon_direction;  // unit, towards the moon (its disc, MOON; its light in the air, MOON_AIR)
#endif
#ifdef MOON
// The moon's disc (the MOON builds: a sky with a DirectionalLight whose body is "moon"): a
// hard disc out to the sun's outer edge, its rim anti-aliased over 2% of its radius, lit from
// the sun as a ball of dust is (Lommel and Seeliger: 2 mu0 / (mu0 + mu),
// mu0 the sunlight's cosine at the ball's point seen, mu the eye's): a full moon even to its
// edge, a crescent, and all across it the Earth's light (earthshine: EARTHSHINE times a Lambert
// sphere's phase function at the Earth's phase seen from the moon, the angle between the ways
// towards the sun and the moon), which shows past the terminator.  sky.py's moon_share is its twin.
uniform vec3 sky_moon_color;      // its disc lit head on (an atmosphere's: through the air)
uniform vec3 sky_moon_light;      // its light: the disc's colour times its phase's share (the clouds it lights)
const float MOON_RADIUS_SINE = 0.0447101778;   // sin of the disc's edge from its centre (cos 0.9990)
const float MOON_RIM = 0.02;   // its rim fades over this share of its radius, about the edge (sky.py moon_cover)
const float MOON_LIMB = 0.999;

float earthshine() {
    const float PI = 3.14159265;
    float a = acos(clamp(dot(sky_moon_direction, sky_sun_direction), -1.0, 1.0));
    return EARTHSHINE * (sin(a) + (PI - a) * cos(a)) / PI;
}

vec3 moon_disc(vec3 d) {
    float cos_moon = clamp(dot(d, sky_moon_direction), -1.0, 1.0);
    vec3 across = (d - cos_moon * sky_moon_direction) / MOON_RADIUS_SINE;
    float reach = length(across);
    float cover = clamp((1.0 + 0.5 * MOON_RIM - reach) / MOON_RIM, 0.0, 1.0) * step(0.0, cos_moon);
    across *= min(reach, MOON_LIMB) / max(reach, 1e-30);   // (the rim: the law read at the limb, sky.py MOON_LIMB)
    float facing = sqrt(max(1.0 - dot(across, across), 0.0));
    float lit = max(dot(across - sky_moon_direction * facing, sky_sun_direction), 0.0);
    return cover * (2.0 * lit / max(lit + facing, 1e-4) + earthshine()) * sky_moon_color;
}
#define MOON_DISC(d) + moon_disc(d)
#else
#define MOON_DISC(d)
#endif

#ifdef ATMOSPHERE
// A physically based sky (engine/render/atmosphere.py, Hillaire 2020): the sky-view table's
// radiance per unit of sunlight, by the way's elevation (rows: sqrt of it over 90 degrees) and
// its azimuth from the sun's (columns: 0 to 180 degrees), times the sunlight above the air,
// and (SPACE) what lies beyond the air times the share of it the air lets through; below the
// true horizon (from up high, below the level one: the ways between read the horizon's row)
// the ground fades in as the gradient's does.  air_radiance is its twin.
uniform sampler2D sky_view;       // rgb: the air's light; a: what crosses it from beyond (green's)
uniform vec3 sky_light;           // the sunlight above the air (Skybox.sun_color x the light's colour)
uniform float sky_horizon_sine;   // how far below the level the true horizon is (atmosphere.horizon_sine)
#ifdef SPACE
uniform samplerCube sky_space;    // what lies beyond the air (the Skybox's given faces: stars, a galaxy)
#endif
#ifdef MOON_AIR
// (MOON_AIR builds: a moon's light scattered by the air as the sun's is, read from the same
// table drawn at the moon's elevation: SkyModel.moon_air)
uniform sampler2D moon_view;      // the sky-view table at the moon's elevation
uniform vec3 moon_air_light;      // the moon's light above the air (its disc's colour x its phase's share)
#endif

// The sky-view table ``view`` (drawn for a light at the elevation of ``towards``, the unit way
// towards it) along unit way ``d``: by d's elevation and its azimuth from the light's.
vec4 air_table(sampler2D view, vec3 d, vec3 towards) {
    const float HALF_PI = 1.57079633;
    float elevation = asin(clamp(d.y, 0.0, 1.0));
    vec2 flat_way = d.xz, flat_light = towards.xz;
    float lengths = length(flat_way) * length(flat_light);
    float cos_azimuth = lengths > 1e-10 ? dot(flat_way, flat_light) / lengths : 1.0;
    vec2 at = vec2(acos(clamp(cos_azimuth, -1.0, 1.0)) / (2.0 * HALF_PI), sqrt(elevation / HALF_PI));
    vec2 size = vec2(textureSize(view, 0));
    return textureLod(view, (at * (size - 1.0) + 0.5) / size, 0.0);
}

vec3 clear_sky(vec3 d) {
    vec4 table = air_table(sky_view, d, sky_sun_direction);
    vec3 air = sky_light * table.rgb;
#ifdef MOON_AIR
    air += moon_air_light * air_table(moon_view, d, sky_moon_direction).rgb;
#endif
#ifdef SPACE
    // It crosses the air by the table's share, and shows where the air is dark: at night
    // (atmosphere.space_shown, SPACE_DARK from engine/render/sky_draw.py sky_build).
    float bright = dot(table.rgb, vec3(0.2126, 0.7152, 0.0722)) / SPACE_DARK;
    vec3 beyond = textureLod(sky_space, d, 0.0).rgb * (table.a / (1.0 + bright * bright));
#else
    vec3 beyond = vec3(0.0);
#endif
    float below = -d.y - sky_horizon_sine;   // (under the true horizon: from up high, below the level one)
    return below <= 0.0 ? air + beyond : air + (sky_ground - air) * clamp(below * 4.0, 0.0, 1.0);
}
#else
uniform vec3 sky_zenith;          // linear RGB
uniform vec3 sky_horizon;

vec3 clear_sky(vec3 d) {
    float y = d.y;
    vec3 color = y >= 0.0
        ? sky_horizon + (sky_zenith - sky_horizon) * pow(clamp(y, 0.0, 1.0), 0.6)
        : sky_horizon + (sky_ground - sky_horizon) * clamp(-y * 4.0, 0.0, 1.0);
    // A warm band around the sun's azimuth so that left and right of the sky differ.
    float cos_sun = clamp(dot(d, sky_sun_direction), -1.0, 1.0);
    vec3 glow = 0.25 * pow(clamp(cos_sun, 0.0, 1.0), 4.0) * vec3(1.0, 0.55, 0.25);
    return color + glow;
}
#endif

#ifdef CLOUDS
#include "clouds.glsl"
#endif

// The sky without its discs (clear_sky), the sun's and the moon's discs, and (CLOUDS) the
// CloudLayer's clouds over both (clouds.glsl: the share of what is behind them they hide, and
// their own light, lit by the sun and the clear sky overhead).
vec3 generated_sky(vec3 d) {
    vec3 discs = sun_disc(clamp(dot(d, sky_sun_direction), -1.0, 1.0)) MOON_DISC(d);
#ifdef CLOUDS
    vec3 light;
#ifdef MOON
    float hidden = cloud_cover(d, sky_sun_direction, sky_sun_color, sky_moon_direction, sky_moon_light,
                               clear_sky(vec3(0.0, 1.0, 0.0)), light);
#else
    float hidden = cloud_cover(d, sky_sun_direction, sky_sun_color, vec3(0.0, 1.0, 0.0), vec3(0.0),
                               clear_sky(vec3(0.0, 1.0, 0.0)), light);
#endif
    return mix(clear_sky(d), light, hidden) + discs * (1.0 - hidden);
#else
    return clear_sky(d) + discs;
#endif
}
