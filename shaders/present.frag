#version 410 core
// Present: the linear HDR image, times exposure, encoded to sRGB.  With LUMA_IN_ALPHA (the
// frame the FXAA pass filters) alpha holds the pixel's luma, else 1.
#include "color.glsl"

uniform sampler2D hdr_image;
uniform float exposure;

in vec2 v_uv;
out vec4 out_color;

void main() {
    vec3 srgb = linear_to_srgb(texture(hdr_image, v_uv).rgb * exposure);
#ifdef LUMA_IN_ALPHA
    out_color = vec4(srgb, dot(srgb, vec3(0.299, 0.587, 0.114)));
#else
    out_color = vec4(srgb, 1.0);
#endif
}
