#version 410 core
// Screen text and panels: the atlas's coverage at this pixel's texel (no filtering: every
// quad is on the pixel grid, a whole number of pixels a texel) times the colour's alpha.
in vec2 v_texel;
flat in vec4 v_color;

uniform sampler2D atlas;

out vec4 frag_color;

void main() {
    ivec2 last = textureSize(atlas, 0) - 1;
    float coverage = texelFetch(atlas, clamp(ivec2(floor(v_texel)), ivec2(0), last), 0).r;
    frag_color = vec4(v_color.rgb, v_color.a * coverage);
}
