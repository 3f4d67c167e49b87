// A water's waves (components/water.py): two scrolling layers of its normal map summed, as
// the reflection's composite reads them (water.glsl water_normal) and as the scene's
// caustics do (caustics.glsl), each from its own sampler.

// The second layer's repeats relative to the first: not a whole number or a simple ratio,
// so the two patterns do not line up again for many tiles.
#define WATER_CROSS_TILING 1.7

// The slope of two heightfields summed, in the map's (U, V) frame: the map read at uv moving
// along flow (map tiles, the first layer), and read turned a quarter turn at
// WATER_CROSS_TILING times the repeats, so its waves cross the first's and move across them
// (the same flow in its own turned coordinates is flow turned a quarter turn on the
// surface).  Each layer's tangent-space normal m is its heightfield's slope (m.x, m.y) / m.z
// (the turned layer's slope turned back), and the slopes are averaged by ``share`` (the
// second layer's weight: partial-derivative blending, the slope of the summed height).
// Filtered by the UVs' derivatives uv_dx and uv_dy (a pixel's, or a caustic's footprint).
vec2 water_slope(sampler2D map, vec2 uv, vec2 uv_dx, vec2 uv_dy, vec2 flow, float share) {
    vec3 first = textureGrad(map, uv - flow, uv_dx, uv_dy).xyz * 2.0 - 1.0;
    // Turned coordinates (v, -u): the map's +U runs along the surface's +V.
    vec3 second = textureGrad(map, vec2(uv.y, -uv.x) * WATER_CROSS_TILING - flow,
                              vec2(uv_dx.y, -uv_dx.x) * WATER_CROSS_TILING,
                              vec2(uv_dy.y, -uv_dy.x) * WATER_CROSS_TILING).xyz * 2.0 - 1.0;
    return mix(first.xy / max(first.z, 0.05), vec2(-second.y, second.x) / max(second.z, 0.05), share);
}
