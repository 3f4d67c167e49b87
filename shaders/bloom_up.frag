#version 410 core
// Bloom, one step up the mip chain (engine/render/bloom.py): the smaller level, read
// through a 3x3 tent (weights 1 2 1 / 2 4 2 / 1 2 1 over 16, taps ``radius`` texels
// apart), is added (blending ONE, ONE) into the larger one, which so ends up holding the
// sum of its own blur and every smaller level's (Jimenez 2014).  The weights sum to 1.

uniform sampler2D source;     // the smaller level (already holding the sum of those below it)
uniform vec2 source_texel;    // 1 / its size
uniform vec2 target_texel;    // 1 / the larger level's size
uniform float radius;         // tap spacing in texels of the smaller level

out vec4 out_color;

void main() {
    vec2 uv = gl_FragCoord.xy * target_texel;
    vec2 s = source_texel * radius;
    vec3 sum = texture(source, uv).rgb * 4.0;
    sum += (texture(source, uv + vec2(-s.x, 0.0)).rgb + texture(source, uv + vec2(s.x, 0.0)).rgb
            + texture(source, uv + vec2(0.0, -s.y)).rgb + texture(source, uv + vec2(0.0, s.y)).rgb) * 2.0;
    sum += texture(source, uv + vec2(-s.x, -s.y)).rgb + texture(source, uv + vec2(s.x, -s.y)).rgb
         + texture(source, uv + vec2(-s.x, s.y)).rgb + texture(source, uv + vec2(s.x, s.y)).rgb;
    out_color = vec4(sum * (1.0 / 16.0), 1.0);
}
