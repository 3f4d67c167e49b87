#version 410 core
// Anti-aliasing of the final image: FXAA (T. Lottes, NVIDIA 2011; the "quality" path of
// FXAA 3.11, written anew).  It runs once, after the present pass, on the sRGB frame that
// pass wrote with its luma in alpha, so on mirror and portal images already composited (no
// seams where a surface's image meets the room), and it reads colour only: the id images
// are never touched.
//
// Per pixel: the luma of its 3x3 neighbourhood says whether it sits on an edge (contrast
// above a share of the brightest luma), whether the edge runs along x or y, and on which
// side of the pixel it lies.  A feature smaller than a pixel (a stair step, a dash) is
// blended toward the neighbour across the edge by how much it stands out from its
// neighbourhood.  With SEARCH_STEPS > 0, a walk along the edge both ways finds where it
// ends (where the luma along it leaves the average of its two sides), and the pixel is
// moved across the edge by how far it is from the nearer end, so a long nearly level edge
// becomes a ramp.  Every fetch costs on a software rasteriser (a filtered one most), so the
// 3x3 lumas are single texel fetches, the corners only past the early exit, the walk reads
// four lumas a fetch (textureGather of alpha), and the blend is a mix with one neighbour.

#ifndef SEARCH_STEPS
#define SEARCH_STEPS 0
#endif

uniform sampler2D frame;   // rgb: sRGB colour, a: its luma; clamped to the edge

out vec4 out_color;

const float EDGE_THRESHOLD = 0.125;       // no edge below this share of the neighbourhood's highest luma...
const float EDGE_THRESHOLD_MIN = 0.0625;  // ...nor below this contrast (dark areas)
const float SUBPIXEL = 0.75;              // strength of the small-feature blend (0 off, 1 softest)
// Where the walk along an edge looks, in pixels from this one: each gather sits between two
// pixels along the edge and two across it, and averages the four.
const float SEARCH[8] = float[](1.5, 3.5, 5.5, 7.5, 9.5, 13.5, 17.5, 25.5);

float luma_at(ivec2 p, ivec2 last) {
    return texelFetch(frame, clamp(p, ivec2(0), last), 0).a;
}

float luma_between(vec2 uv) {
    return dot(textureGather(frame, uv, 3), vec4(0.25));
}

void main() {
    ivec2 last = textureSize(frame, 0) - 1;
    vec2 texel = 1.0 / vec2(last + 1);
    vec2 uv = gl_FragCoord.xy * texel;
    ivec2 p = ivec2(gl_FragCoord.xy);
    vec4 centre = texelFetch(frame, p, 0);
    float m = centre.a;
    float n = luma_at(p + ivec2(0, 1), last);
    float s = luma_at(p + ivec2(0, -1), last);
    float e = luma_at(p + ivec2(1, 0), last);
    float w = luma_at(p + ivec2(-1, 0), last);
    float lo = min(m, min(min(n, s), min(e, w)));
    float hi = max(m, max(max(n, s), max(e, w)));
    float range = hi - lo;
    if (range < max(EDGE_THRESHOLD_MIN, hi * EDGE_THRESHOLD)) {
        out_color = vec4(centre.rgb, 1.0);
        return;
    }
    float ne = luma_at(p + ivec2(1, 1), last);
    float nw = luma_at(p + ivec2(-1, 1), last);
    float se = luma_at(p + ivec2(1, -1), last);
    float sw = luma_at(p + ivec2(-1, -1), last);

    // An edge along x changes luma along y: second differences down the three columns,
    // against those along the three rows.
    float along_x = 2.0 * abs(n + s - 2.0 * m) + abs(nw + sw - 2.0 * w) + abs(ne + se - 2.0 * e);
    float along_y = 2.0 * abs(e + w - 2.0 * m) + abs(nw + ne - 2.0 * n) + abs(sw + se - 2.0 * s);
    bool horizontal = along_x >= along_y;
    // The side of the pixel the edge lies on: the neighbour across it that differs most.
    float before = horizontal ? s : w;
    float after = horizontal ? n : e;
    bool toward_after = abs(after - m) >= abs(before - m);
    ivec2 across = (horizontal ? ivec2(0, 1) : ivec2(1, 0)) * (toward_after ? 1 : -1);

    float edge_shift = 0.0;
#if SEARCH_STEPS > 0
    // Walk along the edge, half a pixel across it, until the luma leaves the edge's
    // average by a quarter of the step across it (or the steps run out).
    float gradient = max(abs(after - m), abs(before - m));
    float edge_luma = 0.5 * (m + (toward_after ? after : before));
    vec2 along = horizontal ? vec2(texel.x, 0.0) : vec2(0.0, texel.y);
    vec2 start = uv + 0.5 * vec2(across) * texel;
    float limit = 0.25 * gradient;
    float dist_neg = SEARCH[0], dist_pos = SEARCH[0], end_neg = 0.0, end_pos = 0.0;
    bool done_neg = false, done_pos = false;
    for (int i = 0; i < SEARCH_STEPS && !(done_neg && done_pos); ++i) {
        if (!done_neg) {
            dist_neg = SEARCH[i];
            end_neg = luma_between(start - dist_neg * along) - edge_luma;
            done_neg = abs(end_neg) >= limit;
        }
        if (!done_pos) {
            dist_pos = SEARCH[i];
            end_pos = luma_between(start + dist_pos * along) - edge_luma;
            done_pos = abs(end_pos) >= limit;
        }
    }
    // Only an end where the luma crosses to the other side of the average from this
    // pixel's is where the edge steps toward this pixel; at the other kind it stays put.
    bool neg_nearer = dist_neg < dist_pos;
    bool good_end = ((neg_nearer ? end_neg : end_pos) < 0.0) != (m < edge_luma);
    edge_shift = good_end ? 0.5 - min(dist_neg, dist_pos) / (dist_neg + dist_pos) : 0.0;
#endif

    // Small features: how far the pixel stands out from its neighbourhood's weighted average.
    float average = (2.0 * (n + s + e + w) + (ne + nw + se + sw)) / 12.0;
    float stand_out = clamp(abs(average - m) / range, 0.0, 1.0);
    stand_out = (-2.0 * stand_out + 3.0) * stand_out * stand_out;
    float shift = max(edge_shift, stand_out * stand_out * SUBPIXEL);

    // A shift across the edge of less than a pixel, as bilinear filtering would do it.
    vec3 beyond = texelFetch(frame, clamp(p + across, ivec2(0), last), 0).rgb;
    out_color = vec4(mix(centre.rgb, beyond, shift), 1.0);
}
