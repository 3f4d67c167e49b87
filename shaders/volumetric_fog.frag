#version 410 core
// Light shafts (components/fog.py VolumetricFog, engine/render/volumetric_fog.py): the sun's
// single scattering by the fog's air along each ray of the main view, summed in STEPS steps.
// At each step t (the step's start moved by ``start``, a different offset each texel):
//   density(x) x exp(-fog_depth(origin, x)) x shadow(x) x step
// (the air's density, what reaches the eye of what it scatters there, whether the sun reaches
// it: its shadow map and cascades), times the sun's light (colour x intensity), the
// Henyey-Greenstein phase function of the angle between the sun's light and the ray, and
// VolumetricFog.intensity.  The texel's ray is that of the first pixel of its RATIO x RATIO
// block; alpha keeps how far it went, which the filter (volumetric_fog_filter.frag) compares.
#include "lights.glsl"
#include "shadows.glsl"
#include "fog.glsl"
#include "volumetric_ray.glsl"

uniform int ratio;           // the view's pixels a march texel, each way (2 at half resolution)
uniform float scatter;       // VolumetricFog.intensity
uniform float anisotropy;    // VolumetricFog.anisotropy: the phase function's g
uniform float frame_offset;  // added to each texel's start (a new one each frame under temporal AA)
uniform vec4 map_tiles[MAX_DIRECTIONAL_LIGHTS];  // each directional light's level map in the atlas:
                                                 // corner u, v and side (0: it casts no shadow)

out vec4 out_light;  // rgb: the light the air sends towards the eye, a: the ray's length (metres)

// Jimenez's interleaved gradient noise: neighbouring texels' starts far apart.
float interleaved_gradient_noise(vec2 p) {
    return fract(52.9829189 * fract(dot(p, vec2(0.06711056, 0.00583715))));
}

// How much of the sun (directional light ``sun``) reaches the point ``x`` of the air: its
// shadow where its level map holds the point and the filter's taps about it, else 1 (outside
// the map's fit no caster stands between the point and the light; the atlas's other tiles
// there are other maps, and texels no map wrote).
float sun_reaches(int sun, vec3 x, vec3 towards) {
    vec4 tile = map_tiles[sun];
    vec4 params = shadows.directional_params[sun];
    float margin = (params.y + 2.0) * params.z;   // the filter's reach and the normal offset, in uv
    vec2 uv = (shadows.directional_matrix[sun] * vec4(x, 1.0)).xy;
    bool held = tile.z > 0.0 && all(greaterThanEqual(uv, tile.xy + margin))
        && all(lessThanEqual(uv, tile.xy + tile.z - margin));
    return held ? directional_shadow(sun, x, towards, towards) : 1.0;
}

// The share of light scattered through an angle whose cosine is ``c`` (per steradian).
float henyey_greenstein(float c, float g) {
    float k = 1.0 + g * g - 2.0 * g * c;
    return (1.0 - g * g) / (4.0 * 3.14159265 * k * sqrt(k));
}

void main() {
    ivec2 pixel = min(ivec2(gl_FragCoord.xy) * ratio, ivec2(depth_size) - 1);
    vec3 origin, dir;
    float reach;
    volumetric_ray(pixel, origin, dir, reach);
    int sun = -1;  // the sun's slot (the Lights block marks it)
    for (int k = 0; k < MAX_DIRECTIONAL_LIGHTS; ++k)
        sun = k < lights.counts.x && lights.directional_dir[k].w > 0.5 ? k : sun;
    out_light = vec4(0.0, 0.0, 0.0, reach);
    if (sun < 0) return;
    vec3 towards = -lights.directional_dir[sun].xyz;
    float step_length = reach / float(STEPS);
    float start = fract(interleaved_gradient_noise(gl_FragCoord.xy) + frame_offset);
    float sum = 0.0;
    for (int i = 0; i < STEPS; ++i) {
        vec3 x = origin + dir * ((float(i) + start) * step_length);
        sum += fog_density(x) * exp(-fog_depth(origin, x)) * sun_reaches(sun, x, towards);
    }
    float phase = henyey_greenstein(dot(dir, towards), anisotropy);
    out_light.rgb = lights.directional_color[sun].rgb * (scatter * phase * sum * step_length);
}
