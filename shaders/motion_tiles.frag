#version 410 core
// Motion blur, step 2 (engine/render/motion_blur.py): for each tile of TILE x TILE pixels, its
// longest streak (McGuire et al. 2012, "A reconstruction filter for plausible motion blur":
// the tile's dominant motion).

uniform sampler2D streaks;  // motion_streaks.frag: xy a pixel's streak in pixels
uniform int tile;           // pixels a side

out vec4 out_longest;

void main() {
    ivec2 size = textureSize(streaks, 0);
    ivec2 first = ivec2(gl_FragCoord.xy) * tile;
    ivec2 last = min(first + tile, size) - 1;
    vec2 longest = vec2(0.0);
    for (int y = first.y; y <= last.y; ++y) {
        for (int x = first.x; x <= last.x; ++x) {
            vec2 streak = texelFetch(streaks, ivec2(x, y), 0).xy;
            if (dot(streak, streak) > dot(longest, longest)) longest = streak;
        }
    }
    out_longest = vec4(longest, 0.0, 1.0);
}
