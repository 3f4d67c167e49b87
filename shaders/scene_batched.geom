#version 410 core
// Batched mirror views (geometry-shader instancing of views): one draw per mesh draws every view of a reflection level.
// Each invocation takes VIEWS_PER_INVOCATION views and emits, for each view that can see
// the triangle, the triangle as that view's reflected camera sees it (its view_proj holds
// the oblique near plane).  Per view: triangles wholly outside the view's frustum or screen
// rectangle, or behind its mirror plane, are culled here; the rest get gl_ClipDistance for
// the mirror plane (CLIP_VIEW_PLANE) and the rectangle's four sides (CLIP_RECT_*), which
// stands in for the per-view scissor of the per-mirror path.  A mirrored view (odd reflection count) emits
// its vertices in reverse order, so with front faces counter-clockwise the same faces are
// culled and gl_FrontFacing matches the per-mirror path's clockwise front faces.
// scene.frag (compiled with BATCHED_VIEWS) discards pixels whose node image names another
// view and shades with the view's eye from here.
//
// Built with MAX_LEVEL_VIEWS, VIEWS_PER_INVOCATION, GS_INVOCATIONS and GS_MAX_VERTICES defines
// (engine/render/scene_pass.py; layout qualifiers take literals only before GLSL 4.40).
//
// With LAYERED it captures the six faces of a cube-map probe in one pass (the OpenGL 4 course
// chapter "Texture Effects"' one-pass cube map): invocation i is face i and writes gl_Layer = i
// into a layered cube-map target; the per-view frustum tests are then per-face culling (a
// triangle goes only to the faces it can be seen in), unless NO_FACE_CULLING (the naive
// capture, six copies of every triangle, kept to measure the culling against).

#include "visibility.glsl"
#include "view_axis.glsl"

layout(triangles, invocations = GS_INVOCATIONS) in;
layout(triangle_strip, max_vertices = GS_MAX_VERTICES) out;  // 3 x VIEWS_PER_INVOCATION
invariant gl_Position;  // every build the same pixels and depths (scene.vert says why)

struct MirrorView {
    mat4 view_proj;   // the reflected camera's projection x view
    vec4 clip_plane;  // world-space mirror plane; geometry behind it is clipped
    vec4 eye;         // xyz: world-space eye; w: 1 if mirrored (front faces clockwise)
    vec4 rect;        // the view's screen rectangle in NDC: x0, y0, x1, y1
    uvec4 node;       // x: the view's index in the node image; y: the entity it never draws (its surface);
                      // z: one no view of its tree draws (a probe's own object); 0: none;
                      // w: the view's kinds and the layers it shows (visibility.glsl)
};

layout(std140) uniform Views {
    ivec4 view_count;  // x: views in this level
    MirrorView views[MAX_LEVEL_VIEWS];
};

in vec3 g_world_pos[];
in vec3 g_normal[];
in vec2 g_uv[];
#ifdef SECOND_UV_MAPS
in vec2 g_uv2[];
out vec2 v_uv2;
#endif
flat in vec4 g_color[];
flat in vec4 g_surface[];
flat in vec4 g_reflect[];
flat in vec4 g_tint[];
flat in uvec4 g_slots[];

in float g_slice_distance[];
#ifdef OBJECT_MOTION
in vec3 g_world_before[];  // last frame's place (scene.vert: the instance's own motion)
out vec4 v_clip_now;       // where this view projects the point this frame and last (way.glsl seen_moved)
out vec4 v_clip_before;
#endif
#ifdef VERTEX_COLOR
in vec4 g_vertex_color[];
out vec4 v_vertex_color;
#endif

out float gl_ClipDistance[CLIP_DISTANCE_COUNT];  // indices: engine/render/bindings.py
out vec3 v_world_pos;
out vec3 v_normal;
out vec2 v_uv;
flat out vec4 v_color;
flat out vec4 v_surface;
flat out vec4 v_reflect;
flat out vec4 v_tint;
flat out uvec4 v_slots;
flat out uint v_node;
flat out vec3 v_eye;
flat out vec3 v_eye_axis;  // the view's axis where it is orthographic (view_axis.glsl; 0: perspective)
#ifdef FOG
flat out vec4 v_clip;  // the view's clip plane: where its rays enter it, for the fog (fog.glsl)
#endif

// All three points on the outer side of plane a.p < 0.
bool outside(vec4 a, vec4 p0, vec4 p1, vec4 p2) {
    return dot(a, p0) < 0.0 && dot(a, p1) < 0.0 && dot(a, p2) < 0.0;
}

void emit_corner(int c, vec4 position, MirrorView v) {
    gl_Position = position;
    vec4 world = vec4(g_world_pos[c], 1.0);
    gl_ClipDistance[CLIP_VIEW_PLANE] = dot(world, v.clip_plane);
    gl_ClipDistance[CLIP_RECT_LEFT] = position.x - v.rect.x * position.w;
    gl_ClipDistance[CLIP_RECT_RIGHT] = v.rect.z * position.w - position.x;
    gl_ClipDistance[CLIP_RECT_BOTTOM] = position.y - v.rect.y * position.w;
    gl_ClipDistance[CLIP_RECT_TOP] = v.rect.w * position.w - position.y;
    gl_ClipDistance[CLIP_SLICE] = g_slice_distance[c];  // scene.vert's, passed on
    v_world_pos = g_world_pos[c];
#ifdef OBJECT_MOTION
    v_clip_now = position;
    v_clip_before = v.view_proj * vec4(g_world_before[c], 1.0);
#endif
    v_normal = g_normal[c];
    v_uv = g_uv[c];
#ifdef SECOND_UV_MAPS
    v_uv2 = g_uv2[c];
#endif
    v_color = g_color[c];
    v_surface = g_surface[c];
    v_reflect = g_reflect[c];
    v_tint = g_tint[c];
    v_slots = g_slots[c];
#ifdef VERTEX_COLOR
    v_vertex_color = g_vertex_color[c];
#endif
    v_node = v.node.x;
    v_eye = v.eye.xyz;
    v_eye_axis = view_axis(v.view_proj);
#ifdef FOG
    v_clip = v.clip_plane;
#endif
#ifdef LAYERED
    gl_Layer = int(v.node.x);  // the face (a face view's node index is its face)
#endif
    EmitVertex();
}

void main() {
    vec4 w0 = vec4(g_world_pos[0], 1.0);
    vec4 w1 = vec4(g_world_pos[1], 1.0);
    vec4 w2 = vec4(g_world_pos[2], 1.0);
    for (int k = 0; k < VIEWS_PER_INVOCATION; ++k) {
        int i = gl_InvocationID * VIEWS_PER_INVOCATION + k;
        if (i >= view_count.x) return;
        MirrorView v = views[i];
        if (g_slots[0].w == v.node.y) continue;  // the surface the view looks out of
        if (v.node.z != 0u && g_slots[0].w == v.node.z) continue;  // hidden in the whole tree (a probe's own object)
        if (hidden_in_view(g_tint[0].w, v.node.w)) continue;  // hidden in this kind of view, or on none of its layers
        vec4 p0 = v.view_proj * w0;
        vec4 p1 = v.view_proj * w1;
        vec4 p2 = v.view_proj * w2;
#ifndef NO_FACE_CULLING
        if (outside(v.clip_plane, w0, w1, w2)) continue;  // behind the mirror
        // Frustum near / far planes, then the four sides of the view's rectangle (planes
        // through the eye in clip space: x >= x0 w, x <= x1 w, y >= y0 w, y <= y1 w).
        if (outside(vec4(0.0, 0.0, 1.0, 1.0), p0, p1, p2) || outside(vec4(0.0, 0.0, -1.0, 1.0), p0, p1, p2)
            || outside(vec4(1.0, 0.0, 0.0, -v.rect.x), p0, p1, p2)
            || outside(vec4(-1.0, 0.0, 0.0, v.rect.z), p0, p1, p2)
            || outside(vec4(0.0, 1.0, 0.0, -v.rect.y), p0, p1, p2)
            || outside(vec4(0.0, -1.0, 0.0, v.rect.w), p0, p1, p2)) continue;
#endif
        emit_corner(0, p0, v);
        if (v.eye.w > 0.5) {
            emit_corner(2, p2, v);
            emit_corner(1, p1, v);
        } else {
            emit_corner(1, p1, v);
            emit_corner(2, p2, v);
        }
        EndPrimitive();
    }
}
