#version 410 core
// The copy screen-space refraction marches (engine/render/screen_refraction.py): a view's
// colour and its window depth in one image, so the scene builds that read it spend one
// sampler on both (their fullest builds are near the fragment stage's 16).

uniform sampler2D level_color;  // the level's colour (HDR)
uniform sampler2D level_depth;  // its depth image, read as values (a sampler that compares nothing)

out vec4 copy;

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    copy = vec4(texelFetch(level_color, p, 0).rgb, texelFetch(level_depth, p, 0).r);
}
