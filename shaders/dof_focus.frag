#version 410 core
// Depth of field, step 1 (engine/render/depth_of_field.py): the focus distance, a 1x1 texture.
// Manual focus writes DepthOfField.focus_distance; autofocus reads the length of the light's
// way at the focus point (way.glsl: through mirrors and portals, the image's distance) and
// moves last frame's focus the share ``blend`` of the way to it, in dioptres (1 / distance),
// as a lens's focus ring turns: a jump from 1 m to the sky takes as long as one from 1 m to
// 0.5 m.  blend >= 1 starts there (a camera's first frame).  Two 1x1 textures written in turn.

uniform usampler2D seen_image;   // the main view's seen pair (entity, way)
uniform sampler2D previous;      // 1x1: last frame's focus distance
uniform ivec2 focus_pixel;
uniform float manual_focus;      // > 0: this distance; 0: autofocus
uniform float blend;

out vec4 out_focus;

void main() {
    float target = manual_focus > 0.0 ? manual_focus
                                      : uintBitsToFloat(texelFetch(seen_image, focus_pixel, 0).g);
    target = clamp(target, MIN_FOCUS, MAX_FOCUS);  // (nothing drawn: 0, the sky: SKY_WAY)
    float before = texelFetch(previous, ivec2(0), 0).r;
    float focus = blend >= 1.0 ? target : 1.0 / mix(1.0 / before, 1.0 / target, blend);
    out_focus = vec4(focus, 0.0, 0.0, 1.0);
}
