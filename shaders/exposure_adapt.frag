#version 410 core
// Automatic exposure, step 3 (engine/render/post.py): the mean of the last 4x4 level is
// the frame's mean log2 luminance; the target exposure brings it to the key, in EV,
// clamped to the camera's range; the 1x1 exposure moves the share ``blend``
// (1 - exp(-adapt_speed dt)) of the way from last frame's value to it.  blend >= 1 starts
// at the target (a camera's first frame), whatever the texture held.

uniform sampler2D mean_source;    // 4x4 level of mean log2 luminance
uniform sampler2D previous;       // 1x1: last frame's exposure in EV
uniform float key_log2;
uniform vec2 ev_range;            // (min_ev, max_ev)
uniform float blend;

out vec4 out_color;

void main() {
    float sum = 0.0;
    for (int y = 0; y < 4; ++y) {
        for (int x = 0; x < 4; ++x) {
            sum += texelFetch(mean_source, ivec2(x, y), 0).r;
        }
    }
    float target = clamp(key_log2 - sum * (1.0 / 16.0), ev_range.x, ev_range.y);
    float ev = blend >= 1.0 ? target : mix(texelFetch(previous, ivec2(0), 0).r, target, blend);
    out_color = vec4(ev, 0.0, 0.0, 1.0);
}
