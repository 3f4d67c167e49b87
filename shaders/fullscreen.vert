#version 410 core
// A full-screen triangle for passes that work per pixel of a level, limited by a scissor (the claims).
#include "fullscreen.glsl"

void main() {
    gl_Position = vec4(fullscreen_position(), 0.0, 1.0);
}
