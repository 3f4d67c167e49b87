#version 410 core
// Present: the linear HDR image is encoded to sRGB into the window or capture target.
//
// With POST and AUTO_EXPOSURE the adapted exposure is read here, once a vertex, not once a
// pixel (a software rasteriser runs the fetch and its exp2 for every pixel otherwise): the
// scale, ``exposure * 2^EV``, goes to the fragments as a flat value.
#include "fullscreen.glsl"

out vec2 v_uv;
#if defined(POST) && defined(AUTO_EXPOSURE)
uniform float exposure;
uniform sampler2D exposure_state;   // 1x1, r: the adapted automatic exposure in EV
flat out float v_scale;
#endif

void main() {
    vec2 p = fullscreen_position();
    v_uv = p * 0.5 + 0.5;
#if defined(POST) && defined(AUTO_EXPOSURE)
    v_scale = exposure * exp2(texelFetch(exposure_state, ivec2(0), 0).r);
#endif
    gl_Position = vec4(p, 0.0, 1.0);
}
