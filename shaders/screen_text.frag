#version 410 core
// Screen text and panels: the atlas's coverage at this pixel's texel (no filtering: every
// quad is on the pixel grid, a whole number of pixels a texel) times the colour's alpha.
// With PICTURE, a picture panel (engine/render/text.py): the monitor's picture across the
// quad, filtered, times its linear colour, then exposed and tone-mapped as the frame under
// it was (the present's exposure, AUTO_EXPOSURE's adapted EV, the TONEMAP_CURVE:
// PresentPass.look), graded as it was (GRADE before the curve, LUT after the encoding:
// include/grade.glsl) and sRGB-encoded here (the output holds encoded values), so a rear-view
// panel looks as the view does.
#include "color.glsl"

in vec2 v_texel;
in vec2 v_corner;
flat in vec4 v_color;

out vec4 frag_color;

#ifdef PICTURE
#include "tonemap.glsl"
#include "grade.glsl"

uniform sampler2D picture;
uniform float exposure;   // linear
#ifdef AUTO_EXPOSURE
uniform sampler2D exposure_state;   // 1x1, r: the adapted automatic exposure in EV
#endif

void main() {
    float scale = exposure;
#ifdef AUTO_EXPOSURE
    scale *= exp2(texelFetch(exposure_state, ivec2(0), 0).r);
#endif
    vec3 light = texture(picture, vec2(v_corner.x, 1.0 - v_corner.y)).rgb * v_color.rgb * scale;
#ifdef GRADE
    light = grade(light);
#endif
    vec3 srgb = linear_to_srgb(tone_map(light));
#ifdef LUT
    srgb = lut_graded(srgb);
#endif
    frag_color = vec4(srgb, v_color.a);
}
#else
uniform sampler2D atlas;

void main() {
    ivec2 last = textureSize(atlas, 0) - 1;
    float coverage = texelFetch(atlas, clamp(ivec2(floor(v_texel)), ivec2(0), last), 0).r;
    frag_color = vec4(v_color.rgb, v_color.a * coverage);
}
#endif
