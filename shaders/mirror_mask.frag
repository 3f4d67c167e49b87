#version 410 core
// Prepares a reflection level: each pixel learns which view of this level owns it (the
// mirror seen there at the level above), the images start empty (alpha 0 = nothing
// reflected), and depth starts at the far plane inside owned pixels and at the near
// plane elsewhere, so scene fragments outside every mirror fail the depth test early.
#define MAX_LEVEL_VIEWS 32
#define NO_NODE 0xFFFFFFFFu

uniform usampler2D parent_node_map;
uniform usampler2D parent_surface_map;
uniform uvec4 views[MAX_LEVEL_VIEWS];   // x: parent view, y: mirror entity, z: this view's index
uniform int view_count;
uniform vec2 to_parent;                 // this level's pixels -> the parent level's (resolution scales)

layout(location = 0) out vec4 out_color;
layout(location = 1) out uint out_surface;
layout(location = 2) out uint out_seen;
layout(location = 3) out uint out_node;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy * to_parent);
    uint parent = texelFetch(parent_node_map, px, 0).r;
    uint surface = texelFetch(parent_surface_map, px, 0).r;
    uint node = NO_NODE;
    for (int i = 0; i < view_count; ++i) {
        if (views[i].x == parent && views[i].y == surface) node = views[i].z;
    }
    out_color = vec4(0.0);
    out_surface = 0u;
    out_seen = 0u;
    out_node = node;
    gl_FragDepth = node == NO_NODE ? 0.0 : 1.0;
}
