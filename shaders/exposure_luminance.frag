#version 410 core
// Automatic exposure, step 1 (engine/render/post.py): the frame's log2 luminance into a
// small square texture, each texel the mean of four bilinear taps of the HDR image (a
// quarter of its block apart), each tap's log2 of Rec. 709 luminance clamped to the range
// the exposure limits can bring to the key (darker or brighter counts as that end).

uniform sampler2D hdr_image;
uniform vec2 target_texel;    // 1 / this texture's size
uniform vec2 log_range;       // (lowest, highest) log2 luminance counted

out vec4 out_color;

float log_luminance(vec2 uv) {
    float luminance = dot(texture(hdr_image, uv).rgb, vec3(0.2126, 0.7152, 0.0722));
    return clamp(log2(max(luminance, 1e-10)), log_range.x, log_range.y);
}

void main() {
    vec2 uv = gl_FragCoord.xy * target_texel;
    vec2 q = 0.25 * target_texel;
    float sum = log_luminance(uv + vec2(-q.x, -q.y)) + log_luminance(uv + vec2(q.x, -q.y))
              + log_luminance(uv + vec2(-q.x, q.y)) + log_luminance(uv + vec2(q.x, q.y));
    out_color = vec4(0.25 * sum, 0.0, 0.0, 1.0);
}
