#version 410 core
// Automatic exposure, step 2 (engine/render/post.py): the mean of the 64x64 log2 luminance
// texture is the frame's mean log2 luminance; the target exposure brings it to the key, in
// EV, clamped to the camera's range; the 1x1 exposure moves the share ``blend``
// (1 - exp(-adapt_speed dt)) of the way from last frame's value to it.  blend >= 1 starts
// at the target (a camera's first frame), whatever the texture held.
//
// The mean is taken here, in the one-texel draw, not by a chain of reduction draws (each
// a pass a software rasteriser pays for in flushes): 32x32 bilinear taps, each at the
// corner of four texels (their exact mean: weights of 1/2 along each axis), summed by
// rows and the rows summed, so no float sum grows over more than 32 terms.

uniform sampler2D mean_source;    // 64x64 log2 luminance (bilinear)
uniform sampler2D previous;       // 1x1: last frame's exposure in EV
uniform float key_log2;
uniform vec2 ev_range;            // (min_ev, max_ev)
uniform float blend;

out vec4 out_color;

const int SIDE = 64;              // engine/render/post.py LUMINANCE_SIDE

void main() {
    float sum = 0.0;
    for (int y = 0; y < SIDE / 2; ++y) {
        float row = 0.0;
        for (int x = 0; x < SIDE / 2; ++x) {
            row += textureLod(mean_source, vec2(2 * x + 1, 2 * y + 1) * (1.0 / float(SIDE)), 0.0).r;
        }
        sum += row;
    }
    float target = clamp(key_log2 - sum * (4.0 / float(SIDE * SIDE)), ev_range.x, ev_range.y);
    float ev = blend >= 1.0 ? target : mix(texelFetch(previous, ivec2(0), 0).r, target, blend);
    out_color = vec4(ev, 0.0, 0.0, 1.0);
}
