#version 410 core
// The claims' rectangles, two clip-space triangles each, all of a level's in one buffer built
// on the CPU (engine/render/mirror_passes.py); each claim is drawn as its own six vertices,
// between its samples query's begin and end.  Each vertex carries its claim's ids, so the
// draw needs no uniform and no scissor.  It runs in the scene pass's clip and cull state (the
// claims' PassState, mirror_passes.py: nothing to switch off and on again between a level's
// claims and its views), so it writes the clip distances that state enables, keeping all.
in vec2 in_position;
in uvec3 in_claim;   // the parent view's node index, the surface's entity, this view's index

flat out uvec3 v_claim;

void main() {
    v_claim = in_claim;
    gl_Position = vec4(in_position, 0.0, 1.0);
    gl_ClipDistance[CLIP_VIEW_PLANE] = 1.0;
    gl_ClipDistance[CLIP_SLICE] = 1.0;
}
