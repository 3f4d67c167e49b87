// The view being rendered (main camera, and later mirror, portal and cube-face views).
layout(std140) uniform Camera {
    mat4 view;
    mat4 proj;
    mat4 view_proj;
    mat4 inv_view_proj;
    vec4 eye;        // xyz: world-space eye position
    vec4 viewport;   // x, y, width, height in pixels of the target
    vec4 clip_plane; // world-space plane; geometry behind it is clipped (mirror views)
    uvec4 skip;      // x: the entity this view never draws (the surface it looks out of); y: one no view
                     // of its tree draws (a probe's own object); 0: none; z: the view's mask (View.view_mask:
                     // its kinds, bits 0-3, and the reflection layers it shows, bits 4-19; visibility.glsl);
                     // w: the view's index in its tree (View.node: the node image's value for its pixels)
} camera;

