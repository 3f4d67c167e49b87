#version 410 core
// The claims' rectangles, two clip-space triangles each, all of a level's in one buffer built
// on the CPU (engine/render/mirror_passes.py); each claim is drawn as its own six vertices,
// between its samples query's begin and end.  Each vertex carries its claim's ids, so the
// draw needs no uniform and no scissor.
in vec2 in_position;
in uvec3 in_claim;   // the parent view's node index, the surface's entity, this view's index

flat out uvec3 v_claim;

void main() {
    v_claim = in_claim;
    gl_Position = vec4(in_position, 0.0, 1.0);
}
