#version 410 core
// One instance per rough view of a reflection level: a quad over the view's tile of the
// rough atlas (engine/render/rough_atlas.py), telling rough_isolate.frag where to copy from.
in vec4 in_tile;     // the tile in atlas NDC: x0, y0, x1, y1
in vec4 in_source;   // the view's rectangle in the level's pixels: x, y, width, height
in vec2 in_place;    // the tile's first texel in the atlas
in float in_scale;   // level pixels -> tile texels (<= 1)
in float in_view;    // the view's index (exact as a float below 2**24)

flat out vec4 v_source;
flat out vec2 v_origin;
flat out float v_scale;
flat out uint v_view;

void main() {
    vec2 corner = vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1));
    gl_Position = vec4(mix(in_tile.xy, in_tile.zw, corner), 0.0, 1.0);
    v_source = in_source;
    v_origin = in_place;
    v_scale = in_scale;
    v_view = uint(in_view + 0.5);
}
