#version 410 core
// The one-pass cube-map capture (the OpenGL 4 course chapter "Texture Effects"' one-pass cube
// map): invocation i is face i of a probe and writes gl_Layer = i into a layered cube-map
// target, projecting the triangle as that face's view sees it (the Views block, one view a
// face).  Faces whose frustum the triangle lies wholly outside are left out (per-face
// culling), unless NO_FACE_CULLING (the naive capture, six copies of every triangle, kept to
// measure the culling against).  scene.frag (compiled with BATCHED_VIEWS) shades with the
// face's eye from here.
//
// Built with MAX_LEVEL_VIEWS and GS_INVOCATIONS (the faces) defines
// (engine/render/scene_programs.py; layout qualifiers take literals only before GLSL 4.40).
// A reflection level's views drawn at once take no geometry shader: scene.vert's
// INSTANCED_VIEWS build draws each instance once a view.

#include "visibility.glsl"
#include "view_axis.glsl"

layout(triangles, invocations = GS_INVOCATIONS) in;
layout(triangle_strip, max_vertices = 3) out;
invariant gl_Position;  // every build the same pixels and depths (scene.vert says why)

#include "views_block.glsl"

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
flat out vec4 v_eye;      // w: the view's way_scale (view_axis.glsl)
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
    v_eye = vec4(v.eye.xyz, abs(v.eye.w));
    v_eye_axis = view_axis(v.view_proj);
#ifdef FOG
    v_clip = v.clip_plane;
#endif
    gl_Layer = gl_InvocationID;  // the face (views[i] is face i)
    EmitVertex();
}

void main() {
    vec4 w0 = vec4(g_world_pos[0], 1.0);
    vec4 w1 = vec4(g_world_pos[1], 1.0);
    vec4 w2 = vec4(g_world_pos[2], 1.0);
    MirrorView v = views[gl_InvocationID];
    if (g_slots[0].w == v.node.y) return;  // the probe's own object
    if (v.node.z != 0u && g_slots[0].w == v.node.z) return;  // hidden in the whole tree
    if (hidden_in_view(g_tint[0].w, v.node.w)) return;  // hidden in this kind of view, or on none of its layers
    vec4 p0 = v.view_proj * w0;
    vec4 p1 = v.view_proj * w1;
    vec4 p2 = v.view_proj * w2;
#ifndef NO_FACE_CULLING
    if (outside(v.clip_plane, w0, w1, w2)) return;  // behind the view's plane
    // Frustum near / far planes, then the four sides of the face's rectangle (planes
    // through the eye in clip space: x >= x0 w, x <= x1 w, y >= y0 w, y <= y1 w).
    if (outside(vec4(0.0, 0.0, 1.0, 1.0), p0, p1, p2) || outside(vec4(0.0, 0.0, -1.0, 1.0), p0, p1, p2)
        || outside(vec4(1.0, 0.0, 0.0, -v.rect.x), p0, p1, p2)
        || outside(vec4(-1.0, 0.0, 0.0, v.rect.z), p0, p1, p2)
        || outside(vec4(0.0, 1.0, 0.0, -v.rect.y), p0, p1, p2)
        || outside(vec4(0.0, -1.0, 0.0, v.rect.w), p0, p1, p2)) return;
#endif
    emit_corner(0, p0, v);
    if (v.eye.w < 0.0) {   // mirrored
        emit_corner(2, p2, v);
        emit_corner(1, p1, v);
    } else {
        emit_corner(1, p1, v);
        emit_corner(2, p2, v);
    }
    EndPrimitive();
}
