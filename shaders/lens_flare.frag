#version 410 core
uniform sampler2D bloom_image;   // the bloom chain's sum (engine/render/bloom.py)
// Image-based lens flare (components/post.py LensFlare; Chapman's pseudo lens flare): the bloom's
// image turned about the picture's middle, FLARE_GHOSTS ghosts along the line through it, each
// fading towards the picture's edges, and a halo ring; each tap's red and blue apart along the
// ghost's line (colour fringes).
uniform vec4 flare;   // x: the ghosts' weight (over the bloom image's sum), y: the spacing,
                      // z: the halo's radius (a share of the picture), w: the halo's weight
uniform float flare_fringe;

// The bloom's image at ``at`` with its red and blue ``apart`` either side; 0 outside the picture.
vec3 flare_tap(vec2 at, vec2 apart) {
    if (any(lessThan(at, vec2(0.0))) || any(greaterThan(at, vec2(1.0)))) return vec3(0.0);
    return vec3(textureLod(bloom_image, at - apart, 0.0).r, textureLod(bloom_image, at, 0.0).g,
                textureLod(bloom_image, at + apart, 0.0).b);
}

// How much a ghost at ``at`` keeps: 1 at the picture's middle, falling to 0 at its corners.
float flare_fade(vec2 at) {
    float out_of_middle = min(length(at - 0.5) / 0.70710678, 1.0);
    return pow(1.0 - out_of_middle, 4.0);
}

vec3 lens_flare(vec2 uv) {
    vec2 turned = 1.0 - uv;   // the picture through the lens's middle
    vec2 way = (vec2(0.5) - turned) * flare.y;
    vec2 apart = length(way) > 0.0 ? normalize(way) * flare_fringe : vec2(0.0);
    vec3 sum = vec3(0.0);
    for (int k = 0; k < FLARE_GHOSTS; ++k) {
        vec2 at = turned + way * float(k);
        sum += flare_tap(at, apart) * flare_fade(at);
    }
    sum *= flare.x;
    if (flare.w > 0.0) {
        vec2 towards = vec2(0.5) - turned;
        vec2 at = turned + (length(towards) > 1e-6 ? normalize(towards) : vec2(0.0)) * flare.z;
        sum += flare_tap(at, apart) * (flare_fade(at) * flare.w);
    }
    return sum;
}

// Drawn at the bloom image's size (engine/render/lens_flare.py): the present draw reads it
// with one tap a pixel.
in vec2 v_uv;
out vec4 out_color;

void main() {
    out_color = vec4(lens_flare(v_uv), 1.0);
}
