#version 410 core
// Rectangles given as clip-space triangles (two per rectangle, built on the CPU: the claims'
// buffer, claim.vert), for passes that write whole pixel rectangles of a level in one draw
// (mirror_reset.frag).
in vec2 in_position;

void main() {
    gl_Position = vec4(in_position, 0.0, 1.0);
}
