#version 410 core
// Copies one rough view's pixels of its level into the view's own atlas tile, and nothing
// else: pixels of the level that other views own, or that no view owns this frame, become
// empty (alpha 0: nothing reflected). The tile's mips then blur this view's reflection
// only (a level's image is shared by many mirrors, so each rough one needs its own tile).
uniform sampler2D level_color;
uniform usampler2D level_nodes;

flat in vec4 v_source;
flat in vec2 v_origin;
flat in float v_scale;
flat in uint v_view;

out vec4 out_color;

void main() {
    vec2 local = (gl_FragCoord.xy - v_origin) / v_scale;   // level pixels from the rectangle's corner
    ivec2 px = ivec2(v_source.xy + local);
    bool inside = all(lessThan(local, v_source.zw));  // then px is in the view's rectangle, in the level
    out_color = inside && texelFetch(level_nodes, px, 0).r == v_view ? texelFetch(level_color, px, 0) : vec4(0.0);
}
