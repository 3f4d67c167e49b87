#version 410 core
// Bloom, one step down the mip chain (engine/render/bloom.py): the 13-tap downsample of
// Jimenez, "Next Generation Post Processing in Call of Duty: Advanced Warfare" (SIGGRAPH
// 2014).  Thirteen bilinear taps of the level above, two texels apart, make five 4-tap
// boxes: the centre one (weight 1/2) and four overlapping corner ones (1/8 each), which
// cover the half-size texel's footprint without the aliasing a plain 2x2 average leaves.
// The weights sum to 1: each level keeps the image's mean.
//
// FIRST (the step from the HDR image): each box is weighted by 1 / (1 + luma) (Karis's
// average), so a single very bright pixel cannot outweigh its neighbourhood and flicker
// as it moves; THRESHOLD: then only light above the threshold, faded in over a soft knee,
// goes on down the chain.  QUARTER (with FIRST: the quarter-size start, BloomPass.first_step):
// this level is a quarter of the image's size, each texel over 4 x 4 of the image's, and is
// drawn from the image by the nine outer taps alone, one texel apart (each a bilinear tap at
// a corner, so the mean of 2 x 2 texels): the four overlapping corner boxes, a quarter each
// and Karis-weighted, a tent over the 6 x 6 texels around this texel's 4 x 4 (every texel of
// its own and a one-texel ring of its neighbours'), in one draw from the image.

uniform sampler2D source;     // the level above (the HDR image for FIRST): bilinear
#ifdef THRESHOLD
uniform vec4 threshold;       // (threshold, threshold - knee, 2 knee, 1 / (4 knee))
#endif

in vec2 v_uv;                 // this level's pixel centre (present.vert)
out vec4 out_color;

// Taps past the edge read the edge (clamped here, not by the source's wrap mode: the HDR
// image is the main view's level 0, whose sampler state other passes own).
vec3 tap(vec2 uv, vec2 texel, vec2 offset) {
    return textureLod(source, clamp(uv + offset * texel, 0.5 * texel, 1.0 - 0.5 * texel), 0.0).rgb;
}

#ifdef FIRST
float karis_weight(vec3 c) {
    return 1.0 / (1.0 + dot(c, vec3(0.2126, 0.7152, 0.0722)));
}
#endif

void main() {
    vec2 uv = v_uv;
    vec2 t = 1.0 / vec2(textureSize(source, 0));
    vec3 a = tap(uv, t, vec2(-2.0, 2.0)), b = tap(uv, t, vec2(0.0, 2.0)), c = tap(uv, t, vec2(2.0, 2.0));
    vec3 d = tap(uv, t, vec2(-2.0, 0.0)), e = tap(uv, t, vec2(0.0, 0.0)), f = tap(uv, t, vec2(2.0, 0.0));
    vec3 g = tap(uv, t, vec2(-2.0, -2.0)), h = tap(uv, t, vec2(0.0, -2.0)), i = tap(uv, t, vec2(2.0, -2.0));
    vec3 top_left = (a + b + d + e) * 0.25, top_right = (b + c + e + f) * 0.25;
    vec3 bottom_left = (d + e + g + h) * 0.25, bottom_right = (e + f + h + i) * 0.25;
#if defined(FIRST) && defined(QUARTER)
    float w0 = karis_weight(top_left), w1 = karis_weight(top_right);
    float w2 = karis_weight(bottom_left), w3 = karis_weight(bottom_right);
    vec3 sum = (top_left * w0 + top_right * w1 + bottom_left * w2 + bottom_right * w3) / (w0 + w1 + w2 + w3);
#else
    vec3 j = tap(uv, t, vec2(-1.0, 1.0)), k = tap(uv, t, vec2(1.0, 1.0));
    vec3 l = tap(uv, t, vec2(-1.0, -1.0)), m = tap(uv, t, vec2(1.0, -1.0));
    vec3 centre = (j + k + l + m) * 0.25;
#ifdef FIRST
    float wc = 0.5 * karis_weight(centre);
    float w0 = 0.125 * karis_weight(top_left), w1 = 0.125 * karis_weight(top_right);
    float w2 = 0.125 * karis_weight(bottom_left), w3 = 0.125 * karis_weight(bottom_right);
    vec3 sum = (centre * wc + top_left * w0 + top_right * w1 + bottom_left * w2 + bottom_right * w3)
             / (wc + w0 + w1 + w2 + w3);
#else
    vec3 sum = centre * 0.5 + (top_left + top_right + bottom_left + bottom_right) * 0.125;
#endif
#endif
#ifdef THRESHOLD
    // The soft threshold of Unity's and Unreal's bloom: a quadratic from threshold - knee
    // to threshold + knee, then the light above the threshold.
    float bright = max(sum.r, max(sum.g, sum.b));
    float soft = clamp(bright - threshold.y, 0.0, threshold.z);
    soft = soft * soft * threshold.w;
    sum *= max(soft, bright - threshold.x) / max(bright, 1e-5);
#endif
    out_color = vec4(sum, 1.0);
}
