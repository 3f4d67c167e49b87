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
in vec4 in_params;           // reflect_rate, roughness, is_portal (0/1), the view's index
                             // (water: eye.w and normal.w are the waves' offset, tint.a the
                             // second layer's share, params.y F0: mirror_passes.composite_rows)
in vec4 in_normal;           // xyz: the mirror's normal, world, facing the parent eye; w: tile y
in mat3 in_carry;            // a portal's rotation: directions here -> beyond the partner

flat out vec4 v_rect;
flat out mat4 v_inv_view_proj;
flat out vec4 v_eye;
flat out vec4 v_tint;
flat out vec4 v_params;
flat out vec4 v_normal;
flat out mat3 v_carry;
flat out uint v_view;        // the view's index (its pixels in the level's node image)
#ifdef COMPOSITE_BUMPY
flat out mat3 v_project_dir; // rows x, y, w of the parent's view-projection for directions (w = 0)
#endif
#ifdef COMPOSITE_FALLBACK
// A fallback row's values the composite's row has no room for (a vertex shader has 16
// attribute slots, all taken), by instance (mirror_passes.fallback_extras): ids x the
// surface's entity, y its end view + 1 (0: none); weights[2i] the probes' weights (x, y)
// and the fallback's share (z), weights[2i + 1] the plane's w and, for a portal, the pair's
// offset (yzw: the translation of the carry).
uniform uvec4 fallback_ids[FALLBACK_ROWS];
uniform vec4 fallback_weights[2 * FALLBACK_ROWS];
flat out uvec4 v_ids;
flat out vec4 v_weights;
flat out vec4 v_place;
#endif

uniform vec2 parent_size;     // pixels of the level composited into
uniform vec2 to_reflection;   // those pixels -> the reflection level's

void main() {
    vec4 position = in_corners[gl_VertexID];
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
#endif
#ifdef COMPOSITE_BUMPY
    mat4 view_proj = inverse(in_inv_view_proj);
    v_project_dir = mat3(view_proj[0].xyw, view_proj[1].xyw, view_proj[2].xyw);
#endif
}
