#version 410 core
// Temporal anti-aliasing (engine/render/temporal_aa.py): each frame is drawn with its
// projection moved by a sub-pixel offset (a Halton sequence), and this pass blends it into
// the history of the frames before, each history texel fetched where the point it shows was
// last frame (Karis 2014, "High quality temporal supersampling"): the camera's part by the
// light's way (way.glsl: a reflection moves as its image behind the glass does), the thing's
// own motion from the seen image.  What the history holds is clipped to the box of this
// frame's colours round the pixel (in YCoCg, by their mean and spread), so what was uncovered
// or changed does not ghost (its sides, a plus: five fetches, not nine, halve the pass on
// llvmpipe); the blend weighs each by 1 / (1 + luma) so a bright speck does
// not flicker.  A point that was off the picture, or a cut, takes this frame alone.
#include "catmull_rom.glsl"
#include "view_axis.glsl"
#include "way.glsl"

uniform sampler2D current_image;   // this frame, drawn with its jitter
uniform sampler2D history_image;   // the resolved frames before (bilinear)
uniform usampler2D seen_image;     // the main view's seen image (way, own motion)
uniform mat4 inv_view_proj;        // this frame's main view, without its jitter
uniform mat4 previous_view_proj;   // last frame's, without its jitter
uniform vec3 eye;
uniform vec3 axis;                 // an orthographic view's axis (view_axis.glsl); 0: perspective
uniform bool objects;              // the seen image holds each thing's own motion (b, a)
uniform float blend;               // this frame's share (1: a cut, the history dropped)
#ifdef UPSAMPLE
uniform vec2 jitter;               // this frame's offset (normalised device units: View.jitter)
#endif
uniform sampler2D reactive_image;  // how much the main view's particles change each pixel (0 to 1)
uniform bool reactive;             // the mask was drawn this frame (particles live)

out vec4 out_color;

const float REACTIVE_SHARE = 0.9;   // this frame's share where a particle covers the pixel whole

vec3 to_ycocg(vec3 c) {
    return vec3(0.25 * c.r + 0.5 * c.g + 0.25 * c.b, 0.5 * c.r - 0.5 * c.b, -0.25 * c.r + 0.5 * c.g - 0.25 * c.b);
}

vec3 from_ycocg(vec3 c) {
    return vec3(c.x + c.y - c.z, c.x + c.z, c.x - c.y - c.z);
}

float luma(vec3 c) {
    return dot(c, vec3(0.2126, 0.7152, 0.0722));
}

void main() {
    ivec2 last = textureSize(current_image, 0) - 1;
    vec2 size = vec2(textureSize(history_image, 0));   // the output's (the history's)
    vec2 uv = gl_FragCoord.xy / size;
#ifdef UPSAMPLE
    // Temporal upsampling: this frame has fewer samples than the output has pixels.  Each sits
    // at its texel's centre less the jitter (the picture was drawn moved by it); the texel whose
    // sample lies nearest this pixel's centre, and the 3x3 round it, each weighed by its
    // distance from the centre (a Gaussian fit of a Blackman-Harris window, exp(-2.29 d^2), as
    // Unreal's upsampling takes it): in output pixels for what this frame adds (a sample that
    // lands in the pixel counts fully, one a pixel away a tenth: over the jitter's phases each
    // pixel gathers the samples that fell in it), in its own pixels for the picture a cut
    // starts from (a smooth upscale).  The same nine give the clip box.
    vec2 input_size = vec2(last + 1);
    vec2 at = (uv + 0.5 * jitter) * input_size - 0.5;
    ivec2 px = clamp(ivec2(floor(at + 0.5)), ivec2(0), last);   // (a jitter can put the nearest past an edge)
    vec2 to_output = size / input_size;
    vec3 direct = vec3(0.0);
    vec3 spread_out = vec3(0.0);
    float direct_weight = 0.0;
    float spread_weight = 0.0;
    float nearest = 0.0;
    vec3 mean = vec3(0.0);
    vec3 square = vec3(0.0);
    for (int i = 0; i < 9; ++i) {
        ivec2 tap = px + ivec2(i % 3, i / 3) - 1;
        vec3 c = texelFetch(current_image, clamp(tap, ivec2(0), last), 0).rgb;
        vec2 d = vec2(tap) - at;
        float w_input = exp(-2.29 * dot(d, d));
        vec2 d_output = d * to_output;
        float w_output = exp(-2.29 * dot(d_output, d_output));
        direct += c * w_output;
        direct_weight += w_output;
        spread_out += c * w_input;
        spread_weight += w_input;
        nearest = max(nearest, w_output);
        vec3 y = to_ycocg(c);
        mean += y * w_input;
        square += y * y * w_input;
    }
    vec3 now = direct_weight > 1e-4 ? direct / direct_weight : spread_out / spread_weight;
    vec3 cut_picture = spread_out / spread_weight;
    mean /= spread_weight;
    vec3 spread = sqrt(max(square / spread_weight - mean * mean, 0.0));
    float share = blend * nearest;   // this frame's share: less where no sample fell near the pixel
#else
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec3 now = texelFetch(current_image, px, 0).rgb;
    vec3 cut_picture = now;
    float share = blend;
#endif
    // Where the pixel's point was last frame.
    vec4 near = inv_view_proj * vec4(uv * 2.0 - 1.0, -1.0, 1.0);
    vec4 far = inv_view_proj * vec4(uv * 2.0 - 1.0, 1.0, 1.0);
    vec3 start = near.xyz / near.w;
    vec3 dir = normalize(far.xyz / far.w - start);
    // The motion of the nearest thing round the pixel (the shortest way of it and its four
    // corners: Karis's dilation), so a pixel a moving thing just uncovered fetches from behind
    // where it was, not the thing's old colour.
    uvec4 seen = texelFetch(seen_image, px, 0);
    float way = uintBitsToFloat(seen.g);
    for (int i = 0; i < 4; ++i) {
        ivec2 corner = ivec2(i & 1, i >> 1) * 2 - 1;
        uvec4 near_seen = texelFetch(seen_image, clamp(px + corner, ivec2(0), last), 0);
        float near_way = uintBitsToFloat(near_seen.g);
        if (near_way > 0.0 && (way <= 0.0 || near_way < way)) {
            seen = near_seen;
            way = near_way;
        }
    }
    bool beyond = way_beyond(way);
    vec4 before = beyond ? previous_view_proj * vec4(dir, 0.0)
                         : previous_view_proj * vec4(ray_eye(eye, axis, start) + dir * way, 1.0);
    vec2 was = before.w > 1e-6 ? before.xy / before.w * 0.5 + 0.5 : vec2(-1.0);
    if (objects) was -= uintBitsToFloat(seen.ba);
    if (blend >= 1.0 || any(lessThan(was, vec2(0.0))) || any(greaterThan(was, vec2(1.0)))) {
        out_color = vec4(cut_picture, 1.0);
        return;
    }
#ifndef UPSAMPLE
    // This frame's colours round the pixel (it and its four sides): their mean and spread (YCoCg).
    vec3 centre = to_ycocg(now);
    vec3 mean = centre;
    vec3 square = centre * centre;
    for (int i = 0; i < 4; ++i) {
        ivec2 side = i < 2 ? ivec2(i * 2 - 1, 0) : ivec2(0, i * 2 - 5);
        vec3 c = to_ycocg(texelFetch(current_image, clamp(px + side, ivec2(0), last), 0).rgb);
        mean += c;
        square += c * c;
    }
    mean /= 5.0;
    vec3 spread = sqrt(max(square / 5.0 - mean * mean, 0.0));
#endif
    vec3 lo = mean - 1.25 * spread;
    vec3 hi = mean + 1.25 * spread;
    // The history, clipped towards the mean into that box (variance clipping).
    vec3 kept = to_ycocg(max(catmull_rom(history_image, was, size), vec3(0.0)));
    vec3 offset = kept - mean;
    vec3 reach = max(hi - mean, vec3(1e-5));
    float over = max(max(abs(offset.x) / reach.x, abs(offset.y) / reach.y), abs(offset.z) / reach.z);
    if (over > 1.0) kept = mean + offset / over;
    vec3 history = max(from_ycocg(kept), vec3(0.0));
    // Where particles are (the reactive mask, as AMD's FSR 2 takes one): they write no motion,
    // so their history would be fetched from where the things behind them were: this frame
    // takes most of the pixel, as much as the particle changes it.
    if (reactive) share = mix(share, REACTIVE_SHARE, texelFetch(reactive_image, px, 0).r);
    float w_now = share / (1.0 + luma(now));
    float w_history = (1.0 - share) / (1.0 + luma(history));
    out_color = vec4((now * w_now + history * w_history) / (w_now + w_history), 1.0);
}
