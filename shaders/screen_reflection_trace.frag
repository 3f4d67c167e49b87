#version 410 core
// Screen-space reflections marched at half size (engine/render/screen_reflections.py,
// ScreenReflections.half_resolution): a texel a 2 x 2 block of the view's pixels, its ray
// the first of them that reflects (screen_march.glsl); the composite
// (screen_reflection.frag's HALF_RESOLUTION build) brings them to every pixel.
#include "screen_march.glsl"

uniform sampler2D weight_map;      // rgb: W, a: roughness
uniform float max_roughness;       // ScreenReflections.max_roughness

out vec4 out_hit;  // xy: the pixel found, z: the confidence (0: none), w: the traced pixel's window depth (-1: none)

void main() {
    ivec2 block = ivec2(gl_FragCoord.xy) * 2;
    ivec2 last = ivec2(depth_size) - 1;
    ivec2 chosen = ivec2(-1);
    float chosen_depth = 1.0;
    for (int i = 0; i < 4; ++i) {
        ivec2 pixel = min(block + ivec2(i & 1, i >> 1), last);
        vec4 weight = texelFetch(weight_map, pixel, 0);
        float depth = texelFetch(depth_map, pixel, 0).r;
        bool reflects = max(weight.r, max(weight.g, weight.b)) > 0.0 && weight.a <= max_roughness && depth < 1.0;
        bool first = reflects && chosen.x < 0;
        chosen = first ? pixel : chosen;
        chosen_depth = first ? depth : chosen_depth;
    }
    out_hit = vec4(0.0, 0.0, 0.0, -1.0);
    // (A loop run once or not at all: llvmpipe skips it where no pixel of a group reflects.)
    int todo = chosen.x >= 0 ? 1 : 0;
    for (int once = 0; once < todo; ++once) {
        vec2 found;
        float confidence = march(vec2(chosen) + 0.5, chosen_depth, texelFetch(normal_map, chosen, 0).xyz, found);
        out_hit = vec4(found, confidence, chosen_depth);
    }
}
