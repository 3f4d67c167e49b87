#version 410 core
// Present: the linear HDR image is encoded to sRGB into the window or capture target.
#include "fullscreen.glsl"

out vec2 v_uv;

void main() {
    vec2 p = fullscreen_position();
    v_uv = p * 0.5 + 0.5;
    gl_Position = vec4(p, 0.0, 1.0);
}
