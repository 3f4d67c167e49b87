#version 410 core
// Automatic exposure, step 2 (engine/render/post.py): each texel the mean of a 4x4 block
// of the level above (64 -> 16 -> 4 texels a side): an exact mean, not left to how a
// driver's glGenerateMipmap filters.

uniform sampler2D source;

out vec4 out_color;

void main() {
    ivec2 base = ivec2(gl_FragCoord.xy) * 4;
    float sum = 0.0;
    for (int y = 0; y < 4; ++y) {
        for (int x = 0; x < 4; ++x) {
            sum += texelFetch(source, base + ivec2(x, y), 0).r;
        }
    }
    out_color = vec4(sum * (1.0 / 16.0), 0.0, 0.0, 1.0);
}
