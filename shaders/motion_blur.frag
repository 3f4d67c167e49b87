#version 410 core
// Motion blur, step 4 (engine/render/motion_blur.py): each pixel gathered along the longest
// streak near it (motion_neighbours.frag) with a reconstruction filter after McGuire et al.
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

// The share of a tap's weight that goes as in front of the pixel (a's way shorter than b's):
// 1 well in front, 0 well behind, a half at the same way (a tap of the same surface is as much
// in front as behind, so it counts once), over a few per cent of the way.
float in_front(float a, float b) {
    return clamp(0.5 + (b - a) / (0.04 * min(a, b) + 0.02), 0.0, 1.0);
}

// Whether a streak of half-length ``radius`` reaches a point ``distance`` from its pixel (soft
// at its end).
float reaches(float distance, float radius) {
    return 1.0 - smoothstep(0.95 * radius, 1.05 * radius, distance);
}

// The reconstruction (McGuire et al. 2012, each term as the share of the shutter's time a tap
// is what the pixel shows): a tap in front whose own streak reaches the pixel covers it for its
// spacing over its streak's length; a tap behind shows where the pixel's own streak reaches
// it (the background a moving pixel reveals), for its spacing over the pixel's streak.  The
// shares add to 1 where everything moves alike (a box filter along the streak, the shutter's
// average); less is what the pixel keeps of its own colour (a still pixel a moving thing
// passes over part of the time; a tap on the pixel itself is left to that); more, they are
// normalised.
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
    float own_radius = max(0.5 * length(own.xy), 0.5);
    float own_way = own.z;
    int samples = clamp(int(ceil(length(longest))), MIN_SAMPLES, MAX_SAMPLES);
    float spacing = length(longest) / float(samples);   // pixels of streak a tap stands for
    float weight = 0.0;
    vec3 sum = vec3(0.0);
    float jitter = fract(52.9829189 * fract(dot(gl_FragCoord.xy, vec2(0.06711056, 0.00583715)))) - 0.5;
    vec2 half_texel = 0.5 / vec2(size);
    for (int i = 0; i < samples; ++i) {
        float t = (float(i) + 0.5 + jitter) / float(samples) - 0.5;   // along the whole streak
        vec2 offset = longest * t;
        vec2 uv = clamp((gl_FragCoord.xy + offset) / vec2(size), half_texel, 1.0 - half_texel);
        ivec2 tap = ivec2(uv * vec2(size));
        if (tap == px) continue;   // (the pixel itself: what the shares leave it)
        float distance = length(offset);
        vec3 at_tap = texelFetch(streaks, tap, 0).xyz;
        float tap_radius = max(0.5 * length(at_tap.xy), 0.5);
        float front = in_front(at_tap.z, own_way);
        float w = front * reaches(distance, tap_radius) * spacing / (2.0 * tap_radius)
                + (1.0 - front) * reaches(distance, own_radius) * spacing / (2.0 * own_radius);
        sum += w * textureLod(hdr_image, uv, 0.0).rgb;
        weight += w;
    }
    out_color = vec4(weight >= 1.0 ? sum / weight : sum + (1.0 - weight) * centre, 1.0);
}
