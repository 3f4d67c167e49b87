#version 410 core
// Bloom, one step up the mip chain (engine/render/bloom.py): the smaller level, read
// through a 3x3 tent (weights 1 2 1 / 2 4 2 / 1 2 1 over 16, taps ``radius`` texels
// apart), is added (blending ONE, ONE) into the larger one, which so ends up holding the
// sum of its own blur and every smaller level's (Jimenez 2014).  The weights sum to 1.

uniform sampler2D source;     // the smaller level (already holding the sum of those below it)
uniform float radius;         // tap spacing in texels of the smaller level

in vec2 v_uv;                 // the larger level's pixel centre (present.vert)
out vec4 out_color;

// textureLod: the levels have no mipmaps, and a software rasteriser skips the derivatives.
vec3 tap(vec2 uv) {
    return textureLod(source, uv, 0.0).rgb;
}

void main() {
    vec2 uv = v_uv;
    vec2 s = radius / vec2(textureSize(source, 0));
    vec3 sum = tap(uv) * 4.0;
    sum += (tap(uv + vec2(-s.x, 0.0)) + tap(uv + vec2(s.x, 0.0)) + tap(uv + vec2(0.0, -s.y))
            + tap(uv + vec2(0.0, s.y))) * 2.0;
    sum += tap(uv + vec2(-s.x, -s.y)) + tap(uv + vec2(s.x, -s.y)) + tap(uv + vec2(-s.x, s.y)) + tap(uv + vec2(s.x, s.y));
    out_color = vec4(sum * (1.0 / 16.0), 1.0);
}
