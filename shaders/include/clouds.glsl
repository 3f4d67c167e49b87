// A CloudLayer's clouds: the GLSL twin of engine/render/clouds.py, which owns the rules and
// says why (tests/test_clouds.py holds the two together).  The sky's CLOUDS builds draw them
// (sky_model.glsl), the scene's CLOUD_SHADOWS builds dim the sun by them.
layout(std140) uniform Clouds {
    vec4 cloud_shape;    // x: the noise's threshold for the coverage, y: its edge's softness, z: optical depth, w: seed
    vec4 cloud_sheet;    // x: height (m), y: the first octave's cell (m), z: the sheet's depth (m), w: coverage
    vec4 cloud_offset;   // xy: the wind's drift, in first-octave cells (wrapped to the pattern's period)
    vec4 cloud_albedo;   // rgb
};

const float EARTH_RADIUS = 6.36e6;
const uint NOISE_PERIOD = 64u;
const int CLOUD_OCTAVES = 5;
const int SUN_OCTAVES = 2;
const float LOD_ANGLE = 0.005;
const float HAZE_DISTANCE = 60000.0;
const float SILVER_LINING = 0.6;
const float MIN_CROSSING = 0.05;
const float FULL_DETAIL = 1e30;

// How far along unit way w from point p (below the sheet) the sheet is met (x) and the
// cosine between w and the sheet's normal there (y): layer_distance's stable root.
vec2 layer_distance(vec3 p, vec3 w) {
    float h = cloud_sheet.x;
    float b = dot(p, w) + EARTH_RADIUS * w.y;
    float c = max((h - p.y) * (2.0 * EARTH_RADIUS + h + p.y) - p.x * p.x - p.z * p.z, 0.0);
    float root = sqrt(b * b + c);
    float t = b > 0.0 ? c / max(b + root, 1e-30) : root - b;
    return vec2(t, (b + t) / (EARTH_RADIUS + h));
}

float lattice_value(uvec2 i, uint salt) {
    uint h = (i.x * 0x8DA6B343u) ^ (i.y * 0xD8163841u) ^ salt;
    h = (h ^ (h >> 15u)) * 0x2C1B3C6Du;
    h = (h ^ (h >> 12u)) * 0x297A2D39u;
    h ^= h >> 15u;
    return float(h >> 8u) * (1.0 / 16777216.0);
}

float value_noise(vec2 u, uint period, uint salt) {
    vec2 cell = floor(u);
    vec2 f = u - cell;
    uvec2 i0 = uvec2(ivec2(cell)) & uvec2(period - 1u);
    uvec2 i1 = (i0 + 1u) & uvec2(period - 1u);
    vec2 s = f * f * f * (f * (f * 6.0 - 15.0) + 10.0);
    float low = mix(lattice_value(i0, salt), lattice_value(uvec2(i1.x, i0.y), salt), s.x);
    float high = mix(lattice_value(uvec2(i0.x, i1.y), salt), lattice_value(i1, salt), s.x);
    return mix(low, high, s.y);
}

// The fractal noise at first-octave cells u, each octave faded to its mean as detail (the
// first octave's cell's angle seen from the eye) falls below twice LOD_ANGLE x its frequency.
float cloud_noise(vec2 u, float detail, int octaves) {
    float total = 0.0;
    float amplitude = 1.0;
    float frequency = 1.0;
    uint salt = uint(cloud_shape.w) * 16u;
    for (int k = 0; k < octaves; ++k) {
        float weight = clamp(detail / (frequency * LOD_ANGLE) - 1.0, 0.0, 1.0);
        total += amplitude * weight * (value_noise(u * frequency, NOISE_PERIOD << uint(k), salt + uint(k)) - 0.5);
        amplitude *= 0.5;
        frequency *= 2.0;
    }
    return 0.5 + total / 1.9375;   // (the amplitudes' sum)
}

float cloud_thickness(float noise, float detail) {
    float x = clamp((noise - cloud_shape.x + cloud_shape.y) / (2.0 * cloud_shape.y), 0.0, 1.0);
    return mix(cloud_sheet.w, x * x * (3.0 - 2.0 * x), clamp(detail / LOD_ANGLE - 1.0, 0.0, 1.0));
}

#ifdef CLOUDS
// The share of a light from unit way ``towards`` a cloud seen along d (its cells, detail and
// thickness) sends the eye: through the cloud beside it towards the light, by the silver
// lining's phase, 0 once the light is well below the clouds' horizon (clouds.py _lit).
float cloud_lit(vec2 cells, float detail, float thick, vec3 d, vec3 towards) {
    float rise = max(towards.y, 0.1);
    vec2 step = towards.xz * (cloud_sheet.z / rise / cloud_sheet.y);
    float beside = 0.5 * (cloud_thickness(cloud_noise(cells + 0.5 * step, detail, SUN_OCTAVES), detail)
                          + cloud_thickness(cloud_noise(cells + step, detail, SUN_OCTAVES), detail));
    float depth = cloud_shape.z * (thick + beside) / (2.0 * rise);
    float through = 0.4 * exp(-depth) + 0.6 * exp(-depth / 16.0);
    const float g = SILVER_LINING;
    float mu = clamp(dot(d, towards), -1.0, 1.0);
    float phase = 0.6 + 0.4 * (1.0 - g * g) / pow(1.0 + g * g - 2.0 * g * mu, 1.5);
    return through * phase * clamp((towards.y + 0.05) / 0.1, 0.0, 1.0);
}

// The share of the sky behind the clouds they hide along unit way d from the world's origin,
// and (light) their own light: lit by the sun (unit way towards it, its disc's colour), a moon
// as the sun (its way, its disc's colour times its phase's share; black: none) and the clear
// sky overhead.
float cloud_cover(vec3 d, vec3 sun, vec3 sunlight, vec3 moon, vec3 moonlight, vec3 overhead, out vec3 light) {
    vec2 tc = layer_distance(vec3(0.0), d);
    float cosine = max(tc.y, MIN_CROSSING);
    vec2 cells = d.xz * (tc.x / cloud_sheet.y) + cloud_offset.xy;
    float detail = cloud_sheet.y * sqrt(cosine) / max(tc.x, 1e-6);
    float thick = cloud_thickness(cloud_noise(cells, detail, CLOUD_OCTAVES), detail);
    float hidden = d.y >= 0.0 ? (1.0 - exp(-cloud_shape.z * thick / cosine)) * exp(-tc.x / HAZE_DISTANCE) : 0.0;
    light = sunlight * (cloud_lit(cells, detail, thick, d, sun) / 3.14159265) + overhead * (1.0 - 0.5 * thick);
    if (any(greaterThan(moonlight, vec3(0.0))))
        light += moonlight * (cloud_lit(cells, detail, thick, d, moon) / 3.14159265);
    light *= cloud_albedo.rgb;
    return hidden;
}
#endif

#ifdef CLOUD_SHADOWS
// The share of the sun's light (unit way towards it) the clouds let reach world point p.
float cloud_shadow(vec3 p, vec3 towards) {
    vec2 tc = layer_distance(p, towards);
    vec2 cells = (p.xz + tc.x * towards.xz) / cloud_sheet.y + cloud_offset.xy;
    float thick = cloud_thickness(cloud_noise(cells, FULL_DETAIL, CLOUD_OCTAVES), FULL_DETAIL);
    return exp(-cloud_shape.z * thick / max(tc.y, MIN_CROSSING));
}
#endif
