#version 410 core
// Motion blur, step 4 (engine/render/motion_blur.py): each pixel gathered along the longest
// streak near it (motion_neighbours.frag) with the reconstruction filter of McGuire et al.
// 2012 ("A reconstruction filter for plausible motion blur"): a tap counts where its own
// streak reaches the pixel and it lies in front (a moving thing smeared over what is behind
// it), where the pixel's own streak reaches the tap and the tap lies behind (the background a
// moving pixel reveals), or both streak past each other.  In front and behind compare the
// lengths of the light's way (way.glsl), so through a mirror a reflection is behind the frame
// round the glass.  The taps' places are jittered a pixel (interleaved gradient noise,
// Jimenez 2014) to trade banding for noise; taps past the picture's edge read its edge; about one
// tap a pixel of the streak, 3 to 12 (a slow pan costs a few).

uniform sampler2D hdr_image;     // the finished picture (bilinear)
uniform sampler2D streaks;       // each pixel's streak (xy) and way (z) (motion_streaks.frag)
uniform sampler2D neighbours;    // each tile's longest streak near it
uniform int tile;                // pixels a tile side

out vec4 out_color;

// Taps: one a pixel of the longest streak near, 3 to 12 (the streak's whole length).
const int MIN_SAMPLES = 3;
const int MAX_SAMPLES = 12;

// 1 where a lies in front of b (its way shorter), falling to 0 over a few per cent of the way.
float in_front(float a, float b) {
    return clamp(1.0 - (a - b) / (0.02 * min(a, b) + 0.01), 0.0, 1.0);
}

// How much a streak of half-length ``radius`` covers a point ``distance`` from its pixel.
float cone(float distance, float radius) {
    return clamp(1.0 - distance / max(radius, 1e-3), 0.0, 1.0);
}

float cylinder(float distance, float radius) {
    return 1.0 - smoothstep(0.95 * radius, 1.05 * radius, distance);
}

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    ivec2 size = textureSize(hdr_image, 0);
    vec2 longest = texelFetch(neighbours, px / tile, 0).xy;
    vec3 centre = texelFetch(hdr_image, px, 0).rgb;
    if (dot(longest, longest) < 0.25) {   // under half a pixel near here: nothing to smear
        out_color = vec4(centre, 1.0);
        return;
    }
    vec3 own = texelFetch(streaks, px, 0).xyz;
    float own_radius = 0.5 * length(own.xy);
    float own_way = own.z;
    int samples = clamp(int(ceil(length(longest))), MIN_SAMPLES, MAX_SAMPLES);
    float weight = 1.0 / max(own_radius, 0.5);
    vec3 sum = centre * weight;
    float jitter = fract(52.9829189 * fract(dot(gl_FragCoord.xy, vec2(0.06711056, 0.00583715)))) - 0.5;
    vec2 half_texel = 0.5 / vec2(size);
    for (int i = 0; i < samples; ++i) {
        float t = (float(i) + 0.5 + jitter) / float(samples) - 0.5;   // along the whole streak
        vec2 offset = longest * t;
        vec2 uv = clamp((gl_FragCoord.xy + offset) / vec2(size), half_texel, 1.0 - half_texel);
        ivec2 tap = ivec2(uv * vec2(size));
        float distance = length(offset);
        vec3 at_tap = texelFetch(streaks, tap, 0).xyz;
        float tap_radius = 0.5 * length(at_tap.xy);
        float tap_way = at_tap.z;
        float w = in_front(tap_way, own_way) * cone(distance, tap_radius)
                + in_front(own_way, tap_way) * cone(distance, own_radius)
                + 2.0 * cylinder(distance, tap_radius) * cylinder(distance, own_radius);
        sum += w * textureLod(hdr_image, uv, 0.0).rgb;
        weight += w;
    }
    out_color = vec4(sum / weight, 1.0);
}
