#version 410 core
// Recursion that ends in an image (Valve's "end of the line", Unity3DPortals' fallback): a
// view cut by the depth limit is filled, in the pixels its claim gave it, from the previous
// frame's finished main image.  Each pixel's ray meets the plane the view looks out of at x;
// to_ancestor takes x (back through the surface) into the eye space of the view that saw
// the same surface last up the chain, and reproject (previous main view-projection x
// inverse(main view): the chain's carries undone on last frame's camera) finds where that
// view showed the surface at x.  There the previous image holds the levels beyond it: the
// recursion's image repeats, shrunk, one period deeper (engine/render/end_images.py).  Where
// it holds nothing (x off its edge or behind its camera) the pixel is marked NO_END_IMAGE and
// keeps its surface's closed look (the composite leaves it).
#include "camera.glsl"
#include "end_image.glsl"
#include "view_axis.glsl"
#include "way.glsl"

uniform sampler2D history;      // the previous frame's main image (linear HDR, alpha 1)
uniform usampler2D node_map;    // this level's node image (the claims)
uniform uint view_index;        // this view's node index
uniform uint surface;           // the surface it looks into (the pixel's seen id, as without the image)
uniform mat4 reproject;         // previous main view-projection x inverse(main view)
uniform mat4 to_ancestor;       // exit plane -> eye space of the last view through this surface
uniform vec2 level_size;

layout(location = 0) out vec4 out_color;
layout(location = 1) out uint out_surface;
layout(location = 2) out uvec4 out_seen;  // the way: to the surface it looks out of (way.glsl)

void main() {
    if (texelFetch(node_map, ivec2(gl_FragCoord.xy), 0).r != view_index) discard;  // (drawn at the level's size)
    vec2 ndc = gl_FragCoord.xy / level_size * 2.0 - 1.0;
    vec4 a = camera.inv_view_proj * vec4(ndc, -1.0, 1.0);
    vec4 b = camera.inv_view_proj * vec4(ndc, 1.0, 1.0);
    vec3 origin = a.xyz / a.w;
    vec3 dir = b.xyz / b.w - origin;
    float along = dot(camera.clip_plane.xyz, dir);
    float t = abs(along) > 1e-8 ? -(dot(camera.clip_plane.xyz, origin) + camera.clip_plane.w) / along : 0.0;
    vec3 on_surface = origin + dir * t;
    vec4 previous = reproject * (to_ancestor * vec4(on_surface, 1.0));
    vec2 uv = previous.w > 1e-6 ? previous.xy / previous.w * 0.5 + 0.5 : vec2(-1.0);
    bool held = all(greaterThanEqual(uv, vec2(0.0))) && all(lessThanEqual(uv, vec2(1.0)));
    // (Where nothing is held the colour is the nearest edge's, only for a rough mirror's
    // blur to read beside the pixels it does show.)
    out_color = vec4(textureLod(history, clamp(uv, 0.0, 1.0), 0.0).rgb, 1.0);
    out_surface = 0u;
    out_seen = seen_at(held ? surface : NO_END_IMAGE,
                       length(on_surface - ray_eye(camera.eye.xyz, view_axis(camera.view_proj), on_surface))
                       * way_scale(camera.view));
}
