// Shore foam on a water (components/water.py Water.foam; the FOAM builds of the scene, which
// draw a foamy water's batch once more over its view's level once the level below is
// composited into it: engine/render/scene_pass.py ScenePass.draw_foam; engine/render/foam.py
// writes the block).  Where the water is shallow, along its shores and round what stands in
// it, white water covers the surface: how much of the water lies under a point of the surface
// (the level's window depth at the pixel, copied first: refraction_copy, where the water wrote
// none, so it holds what lies below) against the foam's depth gives the shore's share (1 at
// the edge, 0 from foam_depth down), and a pattern of cells (two octaves of value noise,
// foam_scale metres across, drifting with the waves) keeps the cells whose value passes what
// the share leaves: all of the surface at the edge, patches further out, none past the depth.
// MAX_FOAM_WATERS is engine/render/foam.py's, defined by its owner.
layout(std140) uniform Foam {
    vec4 foam_plane[MAX_FOAM_WATERS];    // xyz: the water's up normal, w: its plane's d
    vec4 foam_axis_u[MAX_FOAM_WATERS];   // xyz: a unit direction along the surface, w: the pattern's drift along it (m)
    vec4 foam_axis_v[MAX_FOAM_WATERS];   // xyz: the other, w: the drift along it
    vec4 foam_params[MAX_FOAM_WATERS];   // x: its strength (Water.foam), y: 1 / foam_depth, z: 1 / foam_scale
    vec4 foam_colour[MAX_FOAM_WATERS];   // rgb: its albedo (Water.foam_color, linear)
    uvec4 foam_entities;                 // the waters' entities
    ivec4 foam_held;                     // x: how many the block holds
};
#ifndef SCREEN_REFRACTION
uniform sampler2D refraction_copy;   // (screen_refraction.glsl's: rgb the level's colour, a its window depth)
#endif

// The block's slot of the water ``entity`` (-1: none).
int foam_slot(uint entity) {
    for (int k = 0; k < MAX_FOAM_WATERS; ++k) {
        if (k < foam_held.x && foam_entities[k] == entity) return k;
    }
    return -1;
}

// A value in [0, 1) for each whole point of the plane (a hash: no texture read).
float foam_hash(vec2 cell) {
    return fract(sin(dot(cell, vec2(127.1, 311.7))) * 43758.5453);
}

// Value noise: the hashes of the four corners about p, mixed smoothly.
float foam_noise(vec2 p) {
    vec2 cell = floor(p);
    vec2 f = p - cell;
    vec2 w = f * f * (3.0 - 2.0 * f);
    return mix(mix(foam_hash(cell), foam_hash(cell + vec2(1.0, 0.0)), w.x),
               mix(foam_hash(cell + vec2(0.0, 1.0)), foam_hash(cell + vec2(1.0, 1.0)), w.x), w.y);
}

// How much of the surface at ``x`` (world) the foam of slot ``k`` covers, seen at ``pixel``
// (window coordinates): the shore's share under it (1 at the water's edge, 0 from foam_depth
// under the surface down; none where the level holds nothing under it) passed by the pattern,
// times the strength.
float foam_cover(int k, vec3 x, vec2 pixel) {
    float window = texelFetch(refraction_copy, ivec2(pixel), 0).a;
    if (window >= 1.0) return 0.0;   // (the far plane, or a reflection level's sky: nothing under it)
    vec2 ndc = (pixel - camera.viewport.xy) / camera.viewport.zw * 2.0 - 1.0;
    vec4 below = camera.inv_view_proj * vec4(ndc, window * 2.0 - 1.0, 1.0);
    float thickness = dot(x - below.xyz / below.w, foam_plane[k].xyz);   // metres of water under the point
    float shore = 1.0 - clamp(thickness * foam_params[k].y, 0.0, 1.0);
    vec2 at = vec2(dot(foam_axis_u[k].xyz, x) - foam_axis_u[k].w, dot(foam_axis_v[k].xyz, x) - foam_axis_v[k].w)
              * foam_params[k].z;
    float pattern = 0.65 * foam_noise(at) + 0.35 * foam_noise(at * 2.7 + vec2(17.3, 5.1));
    return foam_params[k].x * clamp((pattern + shore - 1.0) * 4.0, 0.0, 1.0);
}
