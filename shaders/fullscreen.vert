#version 410 core
// A full-screen triangle for passes that work per pixel of a level (mask, query, composite).
#include "fullscreen.glsl"

void main() {
    gl_Position = vec4(fullscreen_position(), 0.0, 1.0);
}
