#version 410 core
// Counts (with a samples-passed query) the pixels where a parent view shows a mirror:
// the "does anyone see this mirror?" test before its reflection is rendered.
uniform usampler2D parent_node_map;
uniform usampler2D parent_surface_map;
uniform uint parent_node;
uniform uint mirror_id;

out vec4 out_color;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    if (texelFetch(parent_node_map, px, 0).r != parent_node ||
        texelFetch(parent_surface_map, px, 0).r != mirror_id) discard;
    out_color = vec4(0.0);
}
