#version 410 core
// Screen text and panels: the atlas's coverage at this pixel's texel (no filtering: every
// quad is on the pixel grid, a whole number of pixels a texel) times the colour's alpha; a
// picture panel (engine/render/text.py) the monitor's picture across the quad, filtered,
// times its linear colour, sRGB-encoded here (the output holds encoded values).
#include "color.glsl"

in vec2 v_texel;
in vec2 v_corner;
flat in vec4 v_color;

uniform sampler2D atlas;
uniform sampler2D picture;
uniform bool showing_picture;

out vec4 frag_color;

void main() {
    if (showing_picture) {
        vec3 light = texture(picture, vec2(v_corner.x, 1.0 - v_corner.y)).rgb * v_color.rgb;
        frag_color = vec4(linear_to_srgb(light), v_color.a);
        return;
    }
    ivec2 last = textureSize(atlas, 0) - 1;
    float coverage = texelFetch(atlas, clamp(ivec2(floor(v_texel)), ivec2(0), last), 0).r;
    frag_color = vec4(v_color.rgb, v_color.a * coverage);
}
