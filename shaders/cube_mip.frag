#version 410 core
// A cube map's next mip level from the one above it, on all six faces at once (gl_Layer),
// or, built with ONE_FACE, on the one face attached (six draws a level: for a driver whose
// layered draw the start-up check refused, engine/render/path_checks.py).
// The source is limited to the level above (base = max level), so the level written is
// never one being read; seamless cube filtering blends across face edges.
//
// Box mips (the default): the 2x2 box filter glGenerateMipmap uses. Each texel samples the
// level above bilinearly in the direction of its centre, which falls where the four texels
// it covers meet, so the four weigh a quarter each.
//
// GGX_PREFILTER: the level above convolved with a GGX lobe (split-sum prefiltering with
// N = V = R, importance-sampled over Hammersley points, weighted by N.L, as Karis 2013,
// "Real Shading in Unreal Engine 4"). Lobes of GGX roughness widen roughly as alpha^2 adds
// up, so a level one step rougher than the level above needs a lobe of
// alpha_step^2 = alpha_level^2 - alpha_above^2 (the `alpha` uniform).
#include "cube_faces.glsl"

uniform samplerCube source;
uniform float level_size;  // texels along a face at the level written
#ifdef GGX_PREFILTER
uniform float alpha;       // the GGX lobe's alpha (perceptual roughness squared) for this step
const int SAMPLES = 32;
const float PI = 3.14159265358979;
#endif

#ifdef ONE_FACE
uniform int face;          // one face a draw (no geometry shader: the per-face pass)
#define g_face face
#else
flat in int g_face;
#endif
out vec4 color;

#ifdef GGX_PREFILTER
vec2 hammersley(int i) {
    uint bits = uint(i);
    bits = (bits << 16u) | (bits >> 16u);
    bits = ((bits & 0x55555555u) << 1u) | ((bits & 0xAAAAAAAAu) >> 1u);
    bits = ((bits & 0x33333333u) << 2u) | ((bits & 0xCCCCCCCCu) >> 2u);
    bits = ((bits & 0x0F0F0F0Fu) << 4u) | ((bits & 0xF0F0F0F0u) >> 4u);
    bits = ((bits & 0x00FF00FFu) << 8u) | ((bits & 0xFF00FF00u) >> 8u);
    return vec2(float(i) / float(SAMPLES), float(bits) * 2.3283064365386963e-10);
}

vec3 ggx_prefiltered(vec3 n) {
    vec3 up = abs(n.z) < 0.999 ? vec3(0.0, 0.0, 1.0) : vec3(1.0, 0.0, 0.0);
    vec3 x = normalize(cross(up, n));
    vec3 y = cross(n, x);
    float a2 = alpha * alpha;
    vec3 sum = vec3(0.0);
    float weight = 0.0;
    for (int i = 0; i < SAMPLES; ++i) {
        vec2 u = hammersley(i);
        float phi = 2.0 * PI * u.x;
        float cos_theta = sqrt((1.0 - u.y) / (1.0 + (a2 - 1.0) * u.y));
        float sin_theta = sqrt(1.0 - cos_theta * cos_theta);
        vec3 h = x * (cos(phi) * sin_theta) + y * (sin(phi) * sin_theta) + n * cos_theta;
        vec3 l = 2.0 * dot(n, h) * h - n;
        float nl = dot(n, l);
        if (nl > 0.0) {
            sum += textureLod(source, l, 0.0).rgb * nl;
            weight += nl;
        }
    }
    return sum / max(weight, 1e-6);
}
#endif

void main() {
    vec2 st = gl_FragCoord.xy / level_size * 2.0 - 1.0;
    vec3 direction = cube_face_direction(g_face, st);
#ifdef GGX_PREFILTER
    color = vec4(ggx_prefiltered(normalize(direction)), 1.0);
#else
    color = textureLod(source, direction, 0.0);
#endif
}
