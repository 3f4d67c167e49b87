#version 410 core
// The light shafts brought to every pixel of the main view (engine/render/volumetric_fog.py),
// added to its colour: the march's 3 x 3 texels about the pixel, each weighed by a
// Gaussian of its distance in texels (which hides the steps' offsets) times how near its
// ray's length is to the pixel's own (so a shaft behind a near edge does not bleed onto it).
#include "volumetric_ray.glsl"
#ifdef LEVEL_VIEWS  // a mirror or portal level's: drawn once a view, its own pixels and texels only
#include "level_nodes.glsl"
uniform uint node;
#endif

uniform sampler2D light_map;  // the march's image: rgb light, a: its ray's length
uniform int ratio;            // the view's pixels a march texel, each way

out vec4 out_color;  // added to the view's colour (alpha: nothing added)

void main() {
    ivec2 pixel = ivec2(gl_FragCoord.xy);
#ifdef LEVEL_VIEWS
    if (node_at(vec2(pixel)) != node) discard;
#endif
    vec3 origin, dir;
    float reach;
    volumetric_ray(pixel, origin, dir, reach);
    ivec2 size = textureSize(light_map, 0);
    vec2 at = vec2(pixel) / float(ratio);      // the pixel in the march's texels (texel i: pixel ratio x i)
    ivec2 base = ivec2(floor(at + 0.5)) - 1;  // (the nearest texel in the middle)
    float tolerance = 0.05 * reach + 0.05;     // metres of length difference that halve a weight
    vec3 sum = vec3(0.0);
    float weights = 0.0;
    vec3 nearest = vec3(0.0);
    float nearest_gap = 1e30;
    for (int y = 0; y < 3; ++y) {
        for (int x = 0; x < 3; ++x) {
            ivec2 q = clamp(base + ivec2(x, y), ivec2(0), size - 1);
            vec4 found = texelFetch(light_map, q, 0);
#ifdef LEVEL_VIEWS
            // Another view's texel, or one no view marched (whatever it holds: not even read
            // as a number), weighs nothing.
            found = node_at(vec2(q * ratio)) == node ? found : vec4(0.0, 0.0, 0.0, 1e30);
#endif
            vec2 d = vec2(base + ivec2(x, y)) - at;
            float gap = abs(found.a - reach);
            float w = exp(-0.5 * dot(d, d)) * exp2(-gap / tolerance);
            sum += found.rgb * w;
            weights += w;
            nearest = gap < nearest_gap ? found.rgb : nearest;
            nearest_gap = min(gap, nearest_gap);
        }
    }
    out_color = vec4(weights > 1e-6 ? sum / weights : nearest, 0.0);
}
