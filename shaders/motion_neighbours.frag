#version 410 core
// Motion blur, step 3 (engine/render/motion_blur.py): for each tile, the longest streak of the
// tiles about it within ``reach`` tiles (as many as half the longest streak can cross): the
// longest motion that may smear anything over the tile's pixels, which the gather follows
// (so a moving thing smears out over the still background round it, not only within itself).

uniform sampler2D tiles;  // motion_tiles.frag: each tile's longest streak
uniform int reach;        // tiles each way

out vec4 out_longest;

void main() {
    ivec2 size = textureSize(tiles, 0);
    ivec2 at = ivec2(gl_FragCoord.xy);
    vec2 longest = vec2(0.0);
    for (int y = max(at.y - reach, 0); y <= min(at.y + reach, size.y - 1); ++y) {
        for (int x = max(at.x - reach, 0); x <= min(at.x + reach, size.x - 1); ++x) {
            vec2 streak = texelFetch(tiles, ivec2(x, y), 0).xy;
            if (dot(streak, streak) > dot(longest, longest)) longest = streak;
        }
    }
    out_longest = vec4(longest, 0.0, 1.0);
}
