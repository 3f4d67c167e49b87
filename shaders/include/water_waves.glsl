// A water's waves (components/water.py): two scrolling layers of its normal map summed, as
// the reflection's composite reads them (water.glsl water_normal) and as the scene's
// caustics do (caustics.glsl), each from its own sampler.

// The second layer's repeats relative to the first: not a whole number or a simple ratio,
// so the two patterns do not line up again for many tiles.
#define WATER_CROSS_TILING 1.7

// The slope of two heightfields summed, in the map's (U, V) frame, from its two layers'
// texels: ``first`` read at uv moving along the flow (map tiles), ``second`` read turned a
// quarter turn at WATER_CROSS_TILING times the repeats, so its waves cross the first's and
// move across them (the same flow in its own turned coordinates is flow turned a quarter turn
// on the surface).  Each layer's tangent-space normal m is its heightfield's slope (m.x, m.y)
// / m.z (the turned layer's slope turned back), and the slopes are averaged by ``share`` (the
// second layer's weight: partial-derivative blending, the slope of the summed height).
vec2 water_layers_slope(vec4 first_texel, vec4 second_texel, float share) {
    vec3 first = first_texel.xyz * 2.0 - 1.0, second = second_texel.xyz * 2.0 - 1.0;
    return mix(first.xy / max(first.z, 0.05), vec2(-second.y, second.x) / max(second.z, 0.05), share);
}

// The second layer's coordinates of uv (turned: the map's +U runs along the surface's +V).
vec2 water_turned(vec2 uv) {
    return vec2(uv.y, -uv.x) * WATER_CROSS_TILING;
}

// The waves' slope at uv, filtered by the UVs' derivatives uv_dx and uv_dy (a pixel's: the
// composite's).
vec2 water_slope(sampler2D map, vec2 uv, vec2 uv_dx, vec2 uv_dy, vec2 flow, float share) {
    return water_layers_slope(textureGrad(map, uv - flow, uv_dx, uv_dy),
                              textureGrad(map, water_turned(uv) - flow, water_turned(uv_dx), water_turned(uv_dy)),
                              share);
}

// The waves' slope at uv on ``layer`` of ``maps``, the first layer's texels read at mip level
// ``lod`` (the second's, finer by WATER_CROSS_TILING, a level that much higher): a footprint
// the same along every axis (the caustics', caustics.glsl, whose waters' maps are the layers
// of one array), one level a read, cheaper than derivatives on llvmpipe.
vec2 water_slope_lod(sampler2DArray maps, float layer, vec2 uv, float lod, vec2 flow, float share) {
    return water_layers_slope(textureLod(maps, vec3(uv - flow, layer), lod),
                              textureLod(maps, vec3(water_turned(uv) - flow, layer), lod + log2(WATER_CROSS_TILING)),
                              share);
}
