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
#include "view_axis.glsl"

uniform sampler2D current_image;   // this frame, drawn with its jitter
uniform sampler2D history_image;   // the resolved frames before (bilinear)
uniform usampler2D seen_image;     // the main view's seen image (way, own motion)
uniform mat4 inv_view_proj;        // this frame's main view, without its jitter
uniform mat4 previous_view_proj;   // last frame's, without its jitter
uniform vec3 eye;
uniform vec3 axis;                 // an orthographic view's axis (view_axis.glsl); 0: perspective
uniform bool objects;              // the seen image holds each thing's own motion (b, a)
uniform float blend;               // this frame's share (1: a cut, the history dropped)

out vec4 out_color;

vec3 to_ycocg(vec3 c) {
    return vec3(0.25 * c.r + 0.5 * c.g + 0.25 * c.b, 0.5 * c.r - 0.5 * c.b, -0.25 * c.r + 0.5 * c.g - 0.25 * c.b);
}

vec3 from_ycocg(vec3 c) {
    return vec3(c.x + c.y - c.z, c.x + c.z, c.x - c.y - c.z);
}

// The history between texels by a Catmull-Rom spline (five bilinear fetches, Jimenez's
// arrangement in "Filmic SMAA", 2016): a bilinear fetch would soften the picture a little
// more every frame it is carried.
vec3 history_at(vec2 uv, vec2 size) {
    vec2 position = uv * size;
    vec2 centre = floor(position - 0.5) + 0.5;
    vec2 f = position - centre;
    vec2 f2 = f * f;
    vec2 f3 = f2 * f;
    vec2 w0 = -0.5 * f3 + f2 - 0.5 * f;
    vec2 w1 = 1.5 * f3 - 2.5 * f2 + 1.0;
    vec2 w2 = -1.5 * f3 + 2.0 * f2 + 0.5 * f;
    vec2 w3 = 0.5 * f3 - 0.5 * f2;
    vec2 w12 = w1 + w2;
    vec2 at12 = (centre + w2 / w12) / size;
    vec2 at0 = (centre - 1.0) / size;
    vec2 at3 = (centre + 2.0) / size;
    vec4 sum = vec4(textureLod(history_image, vec2(at12.x, at0.y), 0.0).rgb, 1.0) * (w12.x * w0.y)
             + vec4(textureLod(history_image, vec2(at0.x, at12.y), 0.0).rgb, 1.0) * (w0.x * w12.y)
             + vec4(textureLod(history_image, at12, 0.0).rgb, 1.0) * (w12.x * w12.y)
             + vec4(textureLod(history_image, vec2(at3.x, at12.y), 0.0).rgb, 1.0) * (w3.x * w12.y)
             + vec4(textureLod(history_image, vec2(at12.x, at3.y), 0.0).rgb, 1.0) * (w12.x * w3.y);
    return max(sum.rgb / sum.a, vec3(0.0));
}

float luma(vec3 c) {
    return dot(c, vec3(0.2126, 0.7152, 0.0722));
}

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    ivec2 last = textureSize(current_image, 0) - 1;
    vec2 size = vec2(textureSize(current_image, 0));
    vec2 uv = gl_FragCoord.xy / size;
    vec3 now = texelFetch(current_image, px, 0).rgb;
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
    bool beyond = way <= 0.0 || way >= 0.5 * SKY_WAY;
    vec4 before = beyond ? previous_view_proj * vec4(dir, 0.0)
                         : previous_view_proj * vec4(ray_eye(eye, axis, start) + dir * way, 1.0);
    vec2 was = before.w > 1e-6 ? before.xy / before.w * 0.5 + 0.5 : vec2(-1.0);
    if (objects) was -= uintBitsToFloat(seen.ba);
    if (blend >= 1.0 || any(lessThan(was, vec2(0.0))) || any(greaterThan(was, vec2(1.0)))) {
        out_color = vec4(now, 1.0);
        return;
    }
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
    vec3 lo = mean - 1.25 * spread;
    vec3 hi = mean + 1.25 * spread;
    // The history, clipped towards the mean into that box (variance clipping).
    vec3 kept = to_ycocg(history_at(was, size));
    vec3 offset = kept - mean;
    vec3 reach = max(hi - mean, vec3(1e-5));
    float over = max(max(abs(offset.x) / reach.x, abs(offset.y) / reach.y), abs(offset.z) / reach.z);
    if (over > 1.0) kept = mean + offset / over;
    vec3 history = max(from_ycocg(kept), vec3(0.0));
    float w_now = blend / (1.0 + luma(now));
    float w_history = (1.0 - blend) / (1.0 + luma(history));
    out_color = vec4((now * w_now + history * w_history) / (w_now + w_history), 1.0);
}
