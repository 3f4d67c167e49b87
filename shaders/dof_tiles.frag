#version 410 core
// Depth of field, step 3 (engine/render/depth_of_field.py): for each tile of TILE x TILE pixels
// (TILE at least the largest radius), the largest blur radius of what in it lies nearer than
// the focus: how far a blurred foreground can reach over its neighbours (the gather looks at
// the 3x3 tiles about a pixel's own).

uniform sampler2D prepared;      // dof_prepare.frag: a = the signed radius
uniform int tile;                // pixels a side

out vec4 out_reach;

void main() {
    ivec2 size = textureSize(prepared, 0);
    ivec2 first = ivec2(gl_FragCoord.xy) * tile;
    ivec2 last = min(first + tile, size) - 1;
    float reach = 0.0;
    for (int y = first.y; y <= last.y; ++y) {
        for (int x = first.x; x <= last.x; ++x) {
            reach = max(reach, -texelFetch(prepared, ivec2(x, y), 0).a);
        }
    }
    out_reach = vec4(reach, 0.0, 0.0, 1.0);
}
