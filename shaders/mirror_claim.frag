#version 410 core
// Second half of preparing a reflection level, one draw per candidate view (a surface seen
// from a parent view) over its rectangle (claim.vert): the pixels where the parent level shows that
// parent view and that surface become the view's (node image) with depth at the far plane.
// A samples-passed query around the draw counts them: zero means nobody sees the surface
// and its view is not rendered. Each parent pixel has one node and one surface, so claims
// never overlap and their order does not matter.
uniform usampler2D parent_node_map;
uniform usampler2D parent_surface_map;
flat in uvec3 v_claim;          // the parent view's node index, the surface's entity, this view's index (claim.vert)
uniform vec2 to_parent;        // this level's pixels -> the parent level's (resolution scales)

layout(location = 0) out vec4 out_color;
layout(location = 1) out uint out_surface;
layout(location = 2) out uvec4 out_seen;
layout(location = 3) out uint out_node;

void main() {
    // Inside the parent whatever the two sizes: the last centre, (c - 0.5) p / c, is half a
    // pixel of this level inside p (tests/test_fetch_bounds.py checks that and the fetches).
    ivec2 px = ivec2(gl_FragCoord.xy * to_parent);
    if (texelFetch(parent_node_map, px, 0).r != v_claim.x ||
        texelFetch(parent_surface_map, px, 0).r != v_claim.y) discard;
    out_color = vec4(0.0);
    out_surface = 0u;
    out_seen = uvec4(0u);
    out_node = v_claim.z;
    gl_FragDepth = 1.0;
}
