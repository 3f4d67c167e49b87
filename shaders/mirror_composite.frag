#version 410 core
// Blends a mirror's reflection (or a portal's view) into the level above (the reflection mixed
// over the surface, weighted by the GGX specular term, blurred by a roughness mip bias). mirror_composite.vert sends the view.
//
// Built in three variants, one program each (MirrorPasses draws each level's views grouped
// by variant), so a pixel runs only its own path: a software rasteriser such as llvmpipe
// executes both sides of every branch, even one no pixel of the draw takes.
//   COMPOSITE_PORTAL: a plain window onto the view, the sky beyond the partner behind it;
//   COMPOSITE_ROUGH:  a rough mirror, reading the blurred mips of its own atlas tile;
//   neither:          a sharp mirror, reading its level 1:1.
#include "ggx.glsl"

uniform sampler2D reflection;        // premultiplied: alpha 0 where nothing was reflected
uniform usampler2D reflection_seen;
uniform usampler2D reflection_nodes;
uniform samplerCube sky_map;
uniform vec2 parent_size;            // pixels of the level composited into
uniform vec2 to_reflection;          // those pixels -> the reflection level's (resolution scales)
#ifdef COMPOSITE_ROUGH
uniform sampler2D rough_atlas;       // rough views' own blur sources (engine/render/rough_atlas.py)
uniform vec2 atlas_size;
#endif

flat in vec4 v_rect;
flat in mat4 v_inv_view_proj;
flat in vec4 v_eye;        // w: tile x
flat in vec4 v_tint;       // a: tile scale
flat in vec4 v_params;
flat in vec4 v_normal;     // w: tile y
flat in mat3 v_carry;
flat in uint v_view;

layout(location = 0) out vec4 out_color;  // blended: rgb x reflect_rate + own x (1 - reflect_rate)
layout(location = 1) out uint out_seen;

void main() {
    // Only this frame's claims wrote the node image, inside the views' rectangles.
    vec2 level_px = gl_FragCoord.xy * to_reflection;
    if (any(lessThan(level_px, v_rect.xy)) || any(greaterThanEqual(level_px, v_rect.zw))) discard;
    ivec2 px = ivec2(level_px);
    if (texelFetch(reflection_nodes, px, 0).r != v_view) discard;
    vec2 uv = gl_FragCoord.xy / parent_size;
    // A point on the near plane along this pixel's ray (for an oblique projection that is
    // the parent mirror's plane: still in front of the eye, unlike its tilted far plane).
    vec4 near = v_inv_view_proj * vec4(uv * 2.0 - 1.0, -1.0, 1.0);
    vec3 view_dir = normalize(near.xyz / near.w - v_eye.xyz);
    out_seen = texelFetch(reflection_seen, px, 0).r;
#ifdef COMPOSITE_PORTAL
    vec4 through = textureLod(reflection, uv, 0.0);
    vec3 beyond = textureLod(sky_map, v_carry * view_dir, 0.0).rgb;
    out_color = vec4(through.rgb + beyond * (1.0 - through.a), 1.0);
#else
    float reflect_rate = v_params.x;
    float roughness = v_params.y;
    vec3 normal = v_normal.xyz;
    vec3 r = reflect(view_dir, normal);
#ifdef COMPOSITE_ROUGH
    // A rough mirror reads the blurred mips of its own tile (the level's would mix in its
    // neighbours' reflections).
    float lod = roughness_lod_bias(roughness);
    float scale = v_tint.a;
    float tile_lod = clamp(lod + log2(scale), 0.0, log2(ROUGH_TILE));
    float inset = 0.5 * exp2(ceil(tile_lod));  // keep every tap of that mip inside the tile
    vec2 local = clamp((level_px - v_rect.xy) * scale, vec2(inset), vec2(ROUGH_TILE - inset));
    vec4 seen = textureLod(rough_atlas, (vec2(v_eye.w, v_normal.w) + local) / atlas_size, tile_lod);
#else
    // A perfect mirror reads its image 1:1.
    float lod = 0.0;
    vec4 seen = textureLod(reflection, uv, 0.0);
#endif
    vec3 environment = textureLod(sky_map, r, lod).rgb;
    vec3 radiance = seen.rgb + environment * (1.0 - seen.a);
    vec3 reflected = ggx_reflect(normal, r, -view_dir, radiance, v_tint.rgb, roughness);
    out_color = vec4(reflected, reflect_rate);
#endif
}
