#version 410 core
// A shadow map's texels: depth only for a directional light's map; with DISTANCE (a point
// light's cube), the distance from the light over its range, in a colour channel, so one
// comparison per tap works in every face and any direction (the depth of a perspective
// face is not comparable across faces).
#ifdef ALPHA_CUTOFF
// A cutout's holes cast nothing: the alpha scene.frag discards below, the colour's times
// the albedo map's (a batch without one binds the blank white image).
uniform sampler2D albedo_map;
uniform float alpha_cutoff;
#include "footprint.glsl"
#ifdef LAYERED
in vec2 g_uv;
in float g_alpha;
#define v_uv g_uv
#define v_alpha g_alpha
#else
in vec2 v_uv;
in float v_alpha;
#endif
#endif
#ifdef DISTANCE
#include "camera.glsl"
#ifdef LAYERED
in vec3 g_world_pos;
#define v_world_pos g_world_pos
#else
in vec3 v_world_pos;
#endif
uniform float light_range;
layout(location = 0) out float out_distance;
#endif

void main() {
#ifdef ALPHA_CUTOFF
    if (v_alpha * texture(albedo_map, bounded_footprint(v_uv)).a < alpha_cutoff) discard;
#endif
#ifdef DISTANCE
    out_distance = length(v_world_pos - camera.eye.xyz) / light_range;
#endif
}
