#version 410 core
#include "color.glsl"

uniform sampler2D hdr_image;
uniform float exposure;

in vec2 v_uv;
out vec4 out_color;

void main() {
    out_color = vec4(linear_to_srgb(texture(hdr_image, v_uv).rgb * exposure), 1.0);
}
