#version 410 core
// The occlusion found (screen_occlusion.frag) smoothed: each texel takes the mean of the
// 4 x 4 found texels about it (one of each of the tile's slice rotations), each weighed by
// how near it lies to the plane of the texel's own surface (a joint bilateral filter: what
// lies off that plane, across a silhouette, does not bleed over), turned into the shares the
// scene pass multiplies (the light from all round's and the direct light's), with the
// texel's distance, which the scene pass's upsampling weighs by (scene.frag), and the sun's
// share past the contact shadows (found with the visibility, smoothed by the same weights).
// A reflection level's build (LEVEL_VIEWS) takes only the texels of the view that drew the
// texel's own (the level's node image says which).
#include "occlusion_geometry.glsl"

uniform sampler2D occlusion_map;   // rgb: visibility, distance along the view axis (-1: the sky), the sun's share
uniform sampler2D lamps_map;       // rgba: each contact lamp channel's share (the find's second image)
uniform float intensity;           // AmbientOcclusion.intensity: visibility ** intensity
uniform float direct_light;        // AmbientOcclusion.direct_light
uniform ivec2 margin;              // the guard band: where this image's texels start in the depth image

layout(location = 0) out vec4 out_shares;  // r: the light from all round's share, g: the direct light's,
                                           // b: the distance (-1: sky), a: the sun's (contact shadows)
layout(location = 1) out vec4 out_lamps;   // rgba: each contact lamp channel's share, smoothed alike

void main() {
    ivec2 here = ivec2(gl_FragCoord.xy);  // this image's texel (the occlusion found is the same size)
    ivec2 pixel = here + margin;          // the depth and normals images' (a guard band about them)
    vec4 geometry = texelFetch(geometry_map, pixel, 0);
    if (geometry.w <= 0.0) {  // nothing drawn: the sky
        out_shares = vec4(1.0, 1.0, -1.0, 1.0);
        out_lamps = vec4(1.0);
        return;
    }
    vec3 p = view_at(vec2(pixel) + 0.5, -1.0 / geometry.w);
    vec3 n = normalize(geometry.xyz);
#ifdef LEVEL_VIEWS
    uint own = node_at(vec2(pixel));
#endif
    float tolerance = 0.02 * -p.z;  // off the plane by 2% of the distance: another surface
    ivec2 size = textureSize(occlusion_map, 0);
    ivec2 base = here - 1;  // 4 x 4 texels, this one the 2nd of its row
    vec2 total = vec2(0.0);   // visibility, the sun's share
    vec4 lamps = vec4(0.0);   // the contact lamps' shares
    float weights = 0.0;
    vec2 nearest = vec2(1.0);
    vec4 nearest_lamps = vec4(1.0);
    float nearest_gap = 1e30;
    for (int y = 0; y < 4; ++y) {
        for (int x = 0; x < 4; ++x) {
            ivec2 texel = clamp(base + ivec2(x, y), ivec2(0), size - 1);
            vec3 found = texelFetch(occlusion_map, texel, 0).rgb;
            if (found.y < 0.0) continue;  // the sky's
#ifdef LEVEL_VIEWS
            if (node_at(vec2(texel + margin)) != own) continue;  // another view's world
#endif
            vec3 q = view_at(vec2(texel + margin) + 0.5, -found.y);  // its point: along its ray, at its distance
            float gap = abs(dot(q - p, n));
            float weight = max(0.0, 1.0 - gap / tolerance);
            vec4 lamps_found = texelFetch(lamps_map, texel, 0);
            total += weight * found.xz;
            lamps += weight * lamps_found;
            weights += weight;
            if (gap < nearest_gap) {
                nearest_gap = gap;
                nearest = found.xz;
                nearest_lamps = lamps_found;
            }
        }
    }
    vec2 smoothed = weights > 1e-3 ? total / weights : nearest;
    float ambient = intensity > 0.0 ? pow(max(smoothed.x, 1e-6), intensity) : 1.0;  // (pow(0, y): undefined)
    out_shares = vec4(ambient, mix(1.0, ambient, direct_light), min(-p.z, 65504.0), smoothed.y);  // (a half float)
    out_lamps = weights > 1e-3 ? lamps / weights : nearest_lamps;
}
