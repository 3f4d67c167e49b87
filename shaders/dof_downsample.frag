#version 410 core
// Depth of field at half size (engine/render/depth_of_field.py, DepthOfField.half_resolution):
// each texel of the half-size image from its four full-size ones (dof_prepare.frag): their
// mean colour, and the nearest one's radius (the smallest signed one: a thing in front keeps
// its edge against what lies behind it), halved into half-size pixels.

uniform sampler2D prepared;      // full size: rgb colour, a signed radius (full-size pixels)

out vec4 out_prepared;

void main() {
    ivec2 at = ivec2(gl_FragCoord.xy) * 2;
    ivec2 last = textureSize(prepared, 0) - 1;
    vec4 a = texelFetch(prepared, min(at, last), 0);
    vec4 b = texelFetch(prepared, min(at + ivec2(1, 0), last), 0);
    vec4 c = texelFetch(prepared, min(at + ivec2(0, 1), last), 0);
    vec4 d = texelFetch(prepared, min(at + ivec2(1, 1), last), 0);
    out_prepared = vec4((a.rgb + b.rgb + c.rgb + d.rgb) * 0.25, 0.5 * min(min(a.a, b.a), min(c.a, d.a)));
}
