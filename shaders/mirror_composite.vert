#version 410 core
// One instance per view of a reflection level: a quad over the surface (its outline in the
// parent view's clip space, or its screen rectangle), carrying the view's composite
// parameters to mirror_composite.frag. All views of a level composite in one draw.  A
// COMPOSITE_FALLBACK build draws a surface seen with no view (its fallback) the same way,
// over its parent view's pixels.
in mat4 in_corners;          // 4 clip-space corners as a 2 x 2 grid (a triangle strip)
in vec4 in_rect;             // the view's rectangle in its own level's pixels: x0, y0, x1, y1
in mat4 in_inv_view_proj;    // the parent view's
in vec4 in_eye;              // xyz: the parent view's eye; w: a rough view's tile, first texel x
in vec4 in_tint;             // rgb: tint; a: a rough view's tile scale (0: no tile, read the level)
in vec4 in_params;           // reflect_rate, roughness, the surface plane's w (in_normal its xyz), the view's index
                             // (water: eye.w and normal.w are the waves' offset, tint.a the
                             // second layer's share, params.y F0; a portal: eye.w, tint.a and
                             // normal.w its carry's translation: mirror_passes.composite_rows)
in vec4 in_normal;           // xyz: the mirror's normal, world, facing the parent eye; w: tile y
in mat3 in_carry;            // a portal's rotation: directions here -> beyond the partner
#include "composite_bent.glsl"
#include "view_axis.glsl"

flat out vec4 v_rect;
flat out mat4 v_inv_view_proj;
flat out vec4 v_eye;
flat out vec4 v_tint;
flat out vec4 v_params;
flat out vec4 v_normal;
flat out mat3 v_carry;
flat out uint v_view;        // the view's index (its pixels in the level's node image)
#ifdef COMPOSITE_BENT
flat out mat3 v_project_dir; // rows x, y, w of the parent's view-projection for directions (w = 0)
#endif
#ifdef COMPOSITE_FALLBACK
// A fallback row's values the composite's row has no room for (a vertex shader has 16
// attribute slots, all taken), by instance (mirror_passes.prepare_fallbacks): ids x the
// surface's entity, y its end view + 1 (0: none), z its parent view's way scale's bits
// (view_axis.glsl; 0: 1, a metre a metre); weights[2i] the probes' weights (x, y)
// and the fallback's share (z), weights[2i + 1] the plane's w and, for a portal, the pair's
// offset (yzw: the translation of the carry).  A uniform block (FALLBACK_ROWS of 256 rows is
// 12 KiB, inside GL 4.1's least block size of 16 KiB), so a level's fallbacks of one build
// are one draw: as uniform arrays (1024 components at least, 32 rows) they were a draw each
// 32 rows, 5 to 9 draws a frame for the 16-mirror ring in predicted visibility.
layout(std140) uniform FallbackRows {
    uvec4 fallback_ids[FALLBACK_ROWS];
    vec4 fallback_weights[2 * FALLBACK_ROWS];
};
flat out uvec4 v_ids;
flat out vec4 v_weights;
flat out vec4 v_place;
flat out float v_way_scale;  // the parent view's metres in the root's (view_axis.glsl way_scale)
#endif

uniform vec2 parent_size;     // pixels of the level composited into
uniform vec2 to_reflection;   // those pixels -> the reflection level's

#define OUTLINE_MARGIN 0.125  // pixels
// The quad's corners in the order they go round it (a 2 x 2 grid: 0 1 3 2).
const int NEXT[4] = int[4](1, 3, 0, 2);
const int PREVIOUS[4] = int[4](2, 0, 3, 1);

// The unit normal of the edge a -> b pointing away from c (a point inside the quad), in pixels.
vec2 outward(vec2 a, vec2 b, vec2 c) {
    vec2 n = vec2(b.y - a.y, a.x - b.x);
    float len = length(n);
    if (len < 1e-6) return vec2(0.0);
    n /= len;
    return dot(n, c - a) > 0.0 ? -n : n;
}

// Corner ``i`` with both edges through it moved OUTLINE_MARGIN pixels outwards: every pixel
// the surface's own triangles cover in the parent view is inside the quad, whatever the
// rounding of its two transforms (the scene pass's of the mesh, this row's of the outline:
// apart by far less than the margin), so no pixel of the surface keeps its own shading (a
// mirror drawn unlit, unlit_mirrors.shading_replaced, shows black there); the few pixels it
// adds (centres within the margin of an edge) are not the view's and are discarded in
// mirror_composite.frag (its node).
// A corner behind the eye (w <= 0) leaves the quad as it is, and so does a level drawn at
// another resolution than its parent (one of its pixels is several of the parent's: the quad
// keeps the reflection off the parent's pixels beside the surface).
vec4 conservative_corner(int i) {
    vec4 p = in_corners[i];
#if defined(COMPOSITE_PORTAL) || defined(COMPOSITE_FALLBACK)
    return p;  // a portal is never drawn unlit; a fallback's quad is its pixel rectangle
#endif
    if (to_reflection != vec2(1.0)) return p;
    vec2 px[4];
    for (int k = 0; k < 4; ++k) {
        vec4 q = in_corners[k];
        if (q.w <= 1e-6) return p;
        px[k] = (q.xy / q.w * 0.5 + 0.5) * parent_size;
    }
    vec2 c = 0.25 * (px[0] + px[1] + px[2] + px[3]);
    vec2 n1 = outward(px[PREVIOUS[i]], px[i], c);
    vec2 n2 = outward(px[i], px[NEXT[i]], c);
    vec2 moved = px[i] + OUTLINE_MARGIN * (n1 + n2) / max(1.0 + dot(n1, n2), 0.25);  // each edge moved out
    return vec4((moved / parent_size * 2.0 - 1.0) * p.w, p.z, p.w);
}

void main() {
    vec4 position = conservative_corner(gl_VertexID);
    gl_Position = position;
    // The CLIP_RECT_* distances trim the quad to the view's rectangle, so the pixels of the
    // surface outside it (hidden by the parent's own rectangle) are never shaded; the
    // others are off in this pass (bindings.RECT_CLIPS) and written as "inside".
    vec4 ndc_rect = in_rect / vec4(to_reflection, to_reflection) / vec4(parent_size, parent_size) * 2.0 - 1.0;
    gl_ClipDistance[CLIP_VIEW_PLANE] = 1.0;
    gl_ClipDistance[CLIP_RECT_LEFT] = position.x - ndc_rect.x * position.w;
    gl_ClipDistance[CLIP_RECT_RIGHT] = ndc_rect.z * position.w - position.x;
    gl_ClipDistance[CLIP_RECT_BOTTOM] = position.y - ndc_rect.y * position.w;
    gl_ClipDistance[CLIP_RECT_TOP] = ndc_rect.w * position.w - position.y;
    gl_ClipDistance[CLIP_SLICE] = 1.0;
    v_rect = in_rect;
    v_inv_view_proj = in_inv_view_proj;
    v_eye = in_eye;
    v_tint = in_tint;
    v_params = in_params;
    v_normal = in_normal;
    v_carry = in_carry;
    v_view = uint(in_params.w + 0.5);
#ifdef COMPOSITE_FALLBACK
    v_ids = fallback_ids[gl_InstanceID];
    v_weights = fallback_weights[2 * gl_InstanceID];
    v_place = fallback_weights[2 * gl_InstanceID + 1];
    uint scale = fallback_ids[gl_InstanceID].z;   // the parent's way scale's bits (0: 1)
    v_way_scale = scale == 0u ? 1.0 : uintBitsToFloat(scale);
#endif
#ifdef COMPOSITE_BENT
    mat4 view_proj = inverse(in_inv_view_proj);
    v_project_dir = mat3(view_proj[0].xyw, view_proj[1].xyw, view_proj[2].xyw);
#endif
}
