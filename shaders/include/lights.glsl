// Scene lights, packed by engine/gpu/frame_uniforms.py (keep the sizes in step).
#define MAX_DIRECTIONAL_LIGHTS 4
#define MAX_POINT_LIGHTS 16
layout(std140) uniform Lights {
    vec4 ambient;                                   // rgb: ambient radiance
    ivec4 counts;                                   // x: directional, y: point
    vec4 directional_dir[MAX_DIRECTIONAL_LIGHTS];   // xyz: direction the light travels
    vec4 directional_color[MAX_DIRECTIONAL_LIGHTS]; // rgb: colour x intensity
    vec4 point_pos[MAX_POINT_LIGHTS];               // xyz: position, w: range
    vec4 point_color[MAX_POINT_LIGHTS];             // rgb: colour x intensity
} lights;
