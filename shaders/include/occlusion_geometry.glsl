// The depth and normals pass's image that screen-space ambient occlusion and contact shadows
// are found from (engine/render/screen_occlusion.py; scene.frag's DEPTH_NORMALS build): xyz
// the surface's geometric normal in its view's space, w one over its distance along the view
// axis (gl_FragCoord.w: affine on the screen across a plane, so read bilinearly it is exact
// there, and the same whatever a view's near plane, a mirror's oblique one too), 0 where
// nothing was drawn.  A reflection level's image (LEVEL_VIEWS) holds all its views: which
// view drew a texel is the level's node image's, NODE_STEP of its pixels to a texel each way.
#include "view_depth.glsl"

uniform sampler2D geometry_map;  // bilinear (position_at); texelFetch elsewhere

// The farthest distance kept: a texel with nothing drawn (w 0) lies this far off.
#define NOTHING_DISTANCE 1e6

// The view-space point drawn at `pixel` (a position, not a texel), the image read bilinearly.
vec3 position_at(vec2 pixel) {
    float w = textureLod(geometry_map, pixel / depth_size, 0.0).w;  // (no derivatives in loops)
    return view_at(pixel, -1.0 / max(w, 1.0 / NOTHING_DISTANCE));
}

// The view depth (< 0) of the surface at `pixel`, bilinear as position_at.
float surface_z(vec2 pixel) {
    return -1.0 / max(textureLod(geometry_map, pixel / depth_size, 0.0).w, 1.0 / NOTHING_DISTANCE);
}

#ifdef LEVEL_VIEWS
#include "level_nodes.glsl"
#endif
