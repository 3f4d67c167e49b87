// Ripples on waters (components/ripples.py, engine/render/ripples.py): the slope of the
// rippling waters' height fields where a point lies on one, as the composites read it.
// Included by every build of the composite; only RIPPLES builds (while a water's rings are
// alive) declare the block and call it.

#ifdef RIPPLES
layout(std140) uniform Ripples {
    vec4 ripple_u[MAX_RIPPLE_WATERS];       // a world point (x, y, z, 1) -> its texel x in the atlas
    vec4 ripple_v[MAX_RIPPLE_WATERS];       // -> its texel y
    vec4 ripple_plane[MAX_RIPPLE_WATERS];   // the water's plane: its top's normal and w
    vec4 ripple_tile[MAX_RIPPLE_WATERS];    // its tile's texels x0, y0, x1, y1
    vec4 ripple_look[MAX_RIPPLE_WATERS];    // x: the strength its slopes are drawn at
    ivec4 ripple_count;                     // x: the waters held
};
uniform sampler2D ripple_atlas;   // rg: each water's height now and a step ago, metres

// A point this far off a water's plane (metres) is not on it.
#define RIPPLE_PLANE_SLACK 0.01

// The world gradient of the height of the water the point p lies on (a vector along its
// plane: metres of height a metre), times its strength; 0 off every rippling water.  The
// height's slope by central differences over two texels of the filtered field, each axis's
// texel step taken back to the world by the texel rows (their xyz: the texels a metre).
vec3 ripple_gradient(vec3 p) {
    vec4 point = vec4(p, 1.0);
    vec2 size = vec2(textureSize(ripple_atlas, 0));
    for (int i = 0; i < ripple_count.x; ++i) {
        if (abs(dot(point, ripple_plane[i])) > RIPPLE_PLANE_SLACK) continue;
        vec2 t = vec2(dot(point, ripple_u[i]), dot(point, ripple_v[i]));
        vec4 box = ripple_tile[i];
        if (any(lessThan(t, box.xy)) || any(greaterThan(t, box.zw))) continue;
        vec2 c = clamp(t, box.xy + 1.5, box.zw - 1.5);   // (every tap inside the tile)
        float along_u = texture(ripple_atlas, (c + vec2(1.0, 0.0)) / size).r
                      - texture(ripple_atlas, (c - vec2(1.0, 0.0)) / size).r;
        float along_v = texture(ripple_atlas, (c + vec2(0.0, 1.0)) / size).r
                      - texture(ripple_atlas, (c - vec2(0.0, 1.0)) / size).r;
        return 0.5 * ripple_look[i].x * (along_u * ripple_u[i].xyz + along_v * ripple_v[i].xyz);
    }
    return vec3(0.0);
}

// A water's normal ``n`` (its top's, facing up) tilted by the ripples at p.
vec3 rippled_normal(vec3 n, vec3 p) {
    return normalize(n - ripple_gradient(p));
}
#endif
