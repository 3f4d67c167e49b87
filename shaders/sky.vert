#version 410 core
// The sky: a full-screen triangle on the far plane; drawn after opaque geometry so only
// uncovered pixels are shaded (depth test LEQUAL against a cleared depth of 1).
#include "fullscreen.glsl"

out vec2 v_ndc;

void main() {
    v_ndc = fullscreen_position();
    gl_Position = vec4(v_ndc, 1.0, 1.0);
}
