#version 410 core
// Second half of preparing a reflection level, one draw per candidate view (a surface seen
// from a parent view) over its rectangle (claim.vert): the pixels where the parent level shows that
// parent view and that surface become the view's (node image) with depth at the far plane.
// A samples-passed query around the draw counts them: zero means nobody sees the surface
// and its view is not rendered. Each parent pixel has one node and one surface, so claims
// never overlap and their order does not matter.  Drawn into the level's claim framebuffer
// (the node image and depth alone, engine/render/targets.py): the reset before it
// (mirror_reset.frag) has already cleared the colour and ids of every pixel of the
// rectangles, which is what a claimed pixel needs of them, so they are not written twice.
uniform usampler2D parent_node_map;
uniform usampler2D parent_surface_map;
flat in uvec3 v_claim;          // the parent view's node index, the surface's entity, this view's index (claim.vert)
uniform vec2 to_parent;        // this level's pixels -> the parent level's (resolution scales)

layout(location = 0) out uint out_node;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy * to_parent);
    if (texelFetch(parent_node_map, px, 0).r != v_claim.x ||
        texelFetch(parent_surface_map, px, 0).r != v_claim.y) discard;
    out_node = v_claim.z;
    gl_FragDepth = 1.0;
}
