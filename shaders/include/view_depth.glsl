// A pixel's view-space position from a depth image drawn with a perspective projection
// (screen-space ambient occlusion: engine/render/screen_occlusion.py), in closed form, not a
// matrix product a sample: with P the projection, a point at view depth z lands at
// ndc.z = -(P[2][2] z + P[3][2]) / z, ndc.xy = -(P[0][0] x + P[2][0] z, P[1][1] y + P[2][1] z) / z
// (and an oblique near plane's terms: `oblique`).
uniform vec4 unproject;   // P[0][0], P[1][1], P[2][0], P[2][1]
uniform vec2 unproject_z; // P[2][2], P[3][2]
uniform vec2 depth_size;  // the depth image's size in pixels
// A view drawn with an oblique near plane (a mirror's or portal's: its projection's third row
// holds x and y terms too) adds, to every point's NDC depth at a pixel, an amount affine on
// the screen: P[0][2] / P[0][0] and P[1][2] / P[1][1] times the pixel's NDC x and y, plus
// P[0][2] P[2][0] / P[0][0] + P[1][2] P[2][1] / P[1][1].  All 0 for any other projection.
uniform vec3 oblique;

// What the view's oblique near plane adds to the NDC depth at `pixel_centre` (0: none).
float oblique_at(vec2 pixel_centre) {
    vec2 ndc = pixel_centre / depth_size * 2.0 - 1.0;
    return dot(oblique.xy, ndc) + oblique.z;
}

// The view-space point along `pixel_centre`'s ray at view depth `z` (< 0).
vec3 view_at(vec2 pixel_centre, float z) {
    vec2 ndc = pixel_centre / depth_size * 2.0 - 1.0;
    return vec3(-z * (ndc + unproject.zw) / unproject.xy, z);
}

// The view depth (< 0) of a depth image's value at `pixel_centre`.
float view_z(float depth, vec2 pixel_centre) {
    return -unproject_z.y / (depth * 2.0 - 1.0 - oblique_at(pixel_centre) + unproject_z.x);
}

vec3 view_position(vec2 pixel_centre, float depth) {
    return view_at(pixel_centre, view_z(depth, pixel_centre));
}

// Where the view-space point ``p`` (z < 0) lands in the depth image, in pixels (view_at's
// inverse).
vec2 view_pixel(vec3 p) {
    vec2 ndc = -(unproject.xy * p.xy + unproject.zw * p.z) / p.z;
    return (ndc * 0.5 + 0.5) * depth_size;
}
