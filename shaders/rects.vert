#version 410 core
// Rectangles given as clip-space triangles (two per rectangle, built on the CPU: the claims'
// buffer, claim.vert), for passes that write whole pixel rectangles of a level in one draw
// (mirror_reset.frag), in the claims' clip and cull state (claim.vert says why): the clip
// distances it enables keep every pixel.
in vec2 in_position;

void main() {
    gl_Position = vec4(in_position, 0.0, 1.0);
    gl_ClipDistance[CLIP_VIEW_PLANE] = 1.0;
    gl_ClipDistance[CLIP_SLICE] = 1.0;
}
