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
#ifdef SEE_THROUGH
// A see-through caster (a batch of the transparent slot, or glass) into a sun's see-through
// map (engine/render/shadows.py): the share of the light it lets through, 1 - its alpha
// (what shows through it in every view), multiplied into the texel's (the target blends by
// the destination colour: every layer's share), and its depth, the nearest kept (the alpha
// channel blends by MIN): a point lit through it lies deeper than that (shadows.glsl
// see_through_shadows).  With DISTANCE, into a point or spot light's: its distance over the
// range in place of the depth (shadows.glsl lamp_see_through_at).
layout(location = 0) out vec4 out_through;
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
#ifndef SEE_THROUGH
layout(location = 0) out float out_distance;
#endif
#endif

void main() {
    // What the map compares: the distance from the light over its range, or the depth.
#ifdef DISTANCE
    float depth = length(v_world_pos - camera.eye.xyz) / light_range;
#else
    float depth = gl_FragCoord.z;
#endif
#ifdef SEE_THROUGH
    float alpha = clamp(v_alpha * texture(albedo_map, bounded_footprint(v_uv)).a, 0.0, 1.0);
    out_through = vec4(vec3(1.0 - alpha), depth);
#else
#ifdef ALPHA_CUTOFF
    if (v_alpha * texture(albedo_map, bounded_footprint(v_uv)).a < alpha_cutoff) discard;
#endif
#ifdef DISTANCE
    out_distance = depth;
#endif
#endif
}
