#version 410 core
// One step of a water's ripples (engine/render/ripples.py says the scheme): the damped wave
// equation's leapfrog step on the water's tile of the height atlas, and the frame's drops
// pushed in at its first step.  Drawn over the tile's texels alone (its viewport).

uniform sampler2D heights;   // rg: the height now and a step ago, metres
uniform vec4 tile;           // the tile's texels: x0, y0, x1, y1 (x1, y1 past its last)
uniform vec3 rates;          // (speed x step / spacing)^2 along x and y, and the share of the motion a step keeps
uniform int drop_count;
uniform vec4 drops[MAX_RIPPLE_DROPS];   // texel x, y (the atlas's), radius in texels, depth in metres

layout(location = 0) out vec2 out_heights;

// The height at a texel, the edge's own past the tile's edges (the walls reflect the rings).
float height_at(ivec2 texel) {
    return texelFetch(heights, clamp(texel, ivec2(tile.xy), ivec2(tile.zw) - 1), 0).r;
}

void main() {
    ivec2 texel = ivec2(gl_FragCoord.xy);
    vec2 now_before = texelFetch(heights, texel, 0).rg;
    float now = now_before.r;
    float along_x = height_at(texel + ivec2(1, 0)) + height_at(texel - ivec2(1, 0)) - 2.0 * now;
    float along_y = height_at(texel + ivec2(0, 1)) + height_at(texel - ivec2(0, 1)) - 2.0 * now;
    float next = now + (now - now_before.g) * rates.z + rates.x * along_x + rates.y * along_y;
    // Each drop a raised cosine over its disc, pushed into the height now and a step ago
    // alike: a dent at rest, which the step then lets go (pushed into one alone it would be a
    // velocity too, and the water's mean height would sink on with every step).
    float push = 0.0;
    for (int i = 0; i < drop_count; ++i) {
        float r = length(gl_FragCoord.xy - drops[i].xy) / drops[i].z;
        if (r < 1.0) push += drops[i].w * 0.5 * (1.0 + cos(3.14159265 * r));
    }
    out_heights = vec2(next, now) - push;
}
