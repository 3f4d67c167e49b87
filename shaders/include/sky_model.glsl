// The generated sky as a function of direction: the GLSL twin of engine/render/sky.py's
// sky_radiance, which owns the rule (tests/test_generated_sky.py checks that the two agree,
// pixel by pixel, the sun's disc included).  The sky pass draws a generated Skybox with it at
// the screen's own resolution (sky.frag's GENERATED_SKY build); a Skybox of given faces, and
// every reflection of the sky, read the cube map made from the same function.
uniform vec3 sky_zenith;         // linear RGB
uniform vec3 sky_horizon;
uniform vec3 sky_ground;
uniform vec3 sky_sun_direction;  // unit, towards the sun
uniform vec3 sky_sun_color;

vec3 generated_sky(vec3 d) {
    float y = d.y;
    vec3 color = y >= 0.0
        ? sky_horizon + (sky_zenith - sky_horizon) * pow(clamp(y, 0.0, 1.0), 0.6)
        : sky_horizon + (sky_ground - sky_horizon) * clamp(-y * 4.0, 0.0, 1.0);
    // A warm band around the sun's azimuth so that left and right of the sky differ.
    float cos_sun = clamp(dot(d, sky_sun_direction), -1.0, 1.0);
    vec3 glow = 0.25 * pow(clamp(cos_sun, 0.0, 1.0), 4.0) * vec3(1.0, 0.55, 0.25);
    // The disc: cos 0.9990 (2.6 degrees from its centre) to 0.9995 (1.8 degrees) ramps up.
    vec3 disc = clamp((cos_sun - 0.9990) / 0.0005, 0.0, 1.0) * sky_sun_color;
    return color + glow + disc;
}
