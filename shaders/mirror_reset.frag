#version 410 core
// First half of preparing a reflection level, drawn over every candidate view's rectangle
// (one draw, rects.vert):
// no view owns the pixel yet, nothing is reflected there (alpha 0), and depth is the near
// plane, so scene fragments fail the depth test here unless a claim (mirror_claim.frag)
// takes the pixel.
#define NO_NODE 0xFFFFFFFFu

layout(location = 0) out vec4 out_color;
layout(location = 1) out uint out_surface;
layout(location = 2) out uvec4 out_seen;
layout(location = 3) out uint out_node;

void main() {
    out_color = vec4(0.0);
    out_surface = 0u;
    out_seen = uvec4(0u);
    out_node = NO_NODE;
    gl_FragDepth = 0.0;
}
