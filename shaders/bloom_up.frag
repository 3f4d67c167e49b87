#version 410 core
// Bloom, one step up the mip chain (engine/render/bloom.py): the smaller level, read
// through a 3x3 tent (weights 1 2 1 / 2 4 2 / 1 2 1 over 16, taps ``radius`` texels
// apart), is added (blending ONE, ONE) into the larger one, which so ends up holding the
// sum of its own blur and every smaller level's (Jimenez 2014).  The weights sum to 1.
//
// PAIRED (radius 1, the default): the same tent in four bilinear taps, not nine.  Along
// each axis the three taps 1/4, 1/2, 1/4 at x - 1, x, x + 1 (x in texel-centre units of
// the smaller level, i = floor(x), f = x - i) read four texels, i - 1 .. i + 2, with the
// weights (1 - f) / 4, (2 - f) / 4, (1 + f) / 4 and f / 4; one bilinear tap reads each pair
// of them in its ratio (Rákos, "Efficient Gaussian blur with linear sampling", 2010), so
// two taps an axis and four in all give the nine taps' sum (clamped at the edges alike:
// both clamp each texel's index).

uniform sampler2D source;     // the smaller level (already holding the sum of those below it)
#ifndef PAIRED
uniform float radius;         // tap spacing in texels of the smaller level
#endif

in vec2 v_uv;                 // the larger level's pixel centre (present.vert)
out vec4 out_color;

// textureLod: the levels have no mipmaps, and a software rasteriser skips the derivatives.
vec3 tap(vec2 uv) {
    return textureLod(source, uv, 0.0).rgb;
}

void main() {
    vec2 size = vec2(textureSize(source, 0));
#ifdef PAIRED
    vec2 x = v_uv * size - 0.5;
    vec2 i = floor(x);
    vec2 f = x - i;
    vec2 low = (3.0 - 2.0 * f) * 0.25;            // weight of the pair i - 1, i
    vec2 high = 1.0 - low;                         // weight of the pair i + 1, i + 2
    vec2 at_low = (i - 1.0 + (2.0 - f) / (3.0 - 2.0 * f) + 0.5) / size;
    vec2 at_high = (i + 1.0 + f / (1.0 + 2.0 * f) + 0.5) / size;
    vec3 sum = (tap(at_low) * low.x + tap(vec2(at_high.x, at_low.y)) * high.x) * low.y
             + (tap(vec2(at_low.x, at_high.y)) * low.x + tap(at_high) * high.x) * high.y;
    out_color = vec4(sum, 1.0);
#else
    vec2 uv = v_uv;
    vec2 s = radius / size;
    vec3 sum = tap(uv) * 4.0;
    sum += (tap(uv + vec2(-s.x, 0.0)) + tap(uv + vec2(s.x, 0.0)) + tap(uv + vec2(0.0, -s.y))
            + tap(uv + vec2(0.0, s.y))) * 2.0;
    sum += tap(uv + vec2(-s.x, -s.y)) + tap(uv + vec2(s.x, -s.y)) + tap(uv + vec2(-s.x, s.y)) + tap(uv + vec2(s.x, s.y));
    out_color = vec4(sum * (1.0 / 16.0), 1.0);
#endif
}
