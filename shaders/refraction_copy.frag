#version 410 core
// The copy screen-space refraction marches (engine/render/screen_refraction.py): a view's
// colour and its window depth in one image, so the scene builds that read it spend one
// sampler on both (their fullest builds are near the fragment stage's 16).  A pixel the view
// drew nothing in (a reflection level's sky, left empty for its composite's environment:
// alpha 0) holds its depth plus 2 (3): the sky there is not in the copy
// (screen_refraction.glsl's refraction_sky reads only the sky a view drew).

uniform sampler2D level_color;  // the level's colour (HDR)
uniform sampler2D level_depth;  // its depth image, read as values (a sampler that compares nothing)

out vec4 copy;

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    vec4 color = texelFetch(level_color, p, 0);
    copy = vec4(color.rgb, texelFetch(level_depth, p, 0).r + (color.a > 0.0 ? 0.0 : 2.0));
}
