#version 410 core
// The copy screen-space refraction marches (engine/render/screen_refraction.py): a view's
// colour and its window depth in one image, so the scene builds that read it spend one
// sampler on both (their fullest builds are near the fragment stage's 16).  A pixel the view
// did not cover (a reflection level's sky, left empty for its composite's environment: its
// colour premultiplied, its alpha the share see-through things drawn over it cover, 0 where
// none) holds its depth (1) plus 2 plus that share: the sky there is not in the copy, and
// screen_refraction.glsl's refraction_sky lays what is drawn there over the probe's or sky's
// image by it, as the composite does.  A view that draws its sky covers every pixel.

uniform sampler2D level_color;  // the level's colour (HDR)
uniform sampler2D level_depth;  // its depth image, read as values (a sampler that compares nothing)

out vec4 copy;

// Covered: alpha past what a half float's blending of an opaque pixel may leave short of 1.
const float COVERED = 0.998;

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    vec4 color = texelFetch(level_color, p, 0);
    copy = vec4(color.rgb, texelFetch(level_depth, p, 0).r + (color.a > COVERED ? 0.0 : 2.0 + max(color.a, 0.0)));
}
