#version 410 core
// Blends one mirror's reflection (or one portal's view) into the level above (seed 000's final mix, seed 002's
// GGXReflect and roughness mip bias). The Camera block holds the parent view.
#include "camera.glsl"
#include "ggx.glsl"

uniform sampler2D reflection;        // premultiplied: alpha 0 where nothing was reflected
uniform usampler2D reflection_seen;
uniform usampler2D reflection_nodes;
uniform uint view_index;
uniform vec2 to_reflection;          // this level's pixels -> the reflection level's (resolution scales)
uniform samplerCube sky_map;
uniform vec4 tint;
uniform float reflect_rate;
uniform float roughness;
uniform vec3 mirror_normal;          // world space, facing the parent eye
uniform bool is_portal;              // a portal is a plain window onto its view
uniform mat3 carry;                  // a portal's rotation: directions here -> beyond the partner

layout(location = 0) out vec4 out_color;  // blended: rgb x reflect_rate + own x (1 - reflect_rate)
layout(location = 1) out uint out_seen;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy * to_reflection);
    if (texelFetch(reflection_nodes, px, 0).r != view_index) discard;
    vec2 ndc = gl_FragCoord.xy / camera.viewport.zw * 2.0 - 1.0;
    // A point on the near plane along this pixel's ray (for an oblique projection that is
    // the parent mirror's plane: still in front of the eye, unlike its tilted far plane).
    vec4 near_point = camera.inv_view_proj * vec4(ndc, -1.0, 1.0);
    vec3 view_dir = normalize(near_point.xyz / near_point.w - camera.eye.xyz);
    if (is_portal) {
        vec4 through = textureLod(reflection, gl_FragCoord.xy / camera.viewport.zw, 0.0);
        vec3 beyond = textureLod(sky_map, carry * view_dir, 0.0).rgb;
        out_color = vec4(through.rgb + beyond * (1.0 - through.a), 1.0);
        out_seen = texelFetch(reflection_seen, px, 0).r;
        return;
    }
    vec3 r = reflect(view_dir, mirror_normal);
    // A perfect mirror reads its image 1:1; a rough one reads the blurred mips.
    float lod = roughness > 0.0 ? roughness_lod_bias(roughness) : 0.0;
    vec4 seen = textureLod(reflection, gl_FragCoord.xy / camera.viewport.zw, lod);
    vec3 environment = textureLod(sky_map, r, lod).rgb;
    vec3 radiance = seen.rgb + environment * (1.0 - seen.a);
    vec3 reflected = ggx_reflect(mirror_normal, r, -view_dir, radiance, tint.rgb, roughness);
    out_color = vec4(reflected, reflect_rate);
    out_seen = texelFetch(reflection_seen, px, 0).r;
}
