#version 410 core
// Instanced scene geometry: per-vertex mesh data, per-instance transform and material record.
#include "camera.glsl"
#include "visibility.glsl"
#include "pose.glsl"
#include "object_motion.glsl"

// Invariant: every build of this program (glass or opaque, masked or not, unlit, with or
// without each effect) puts a vertex at the same position, so their triangles cover the
// same pixels and depths.  GLSL promises that across programs only for an output declared
// invariant in both (4.10 section 4.6.1); a GPU compiler may otherwise fuse the two matrix
// products differently in each build (llvmpipe happens not to).
invariant gl_Position;

// Clip distances (indices defined from engine/render/bindings.py): CLIP_VIEW_PLANE is the
// view's plane (mirror and portal views), CLIP_RECT_* a view's rectangle where several views
// share a draw, CLIP_SLICE the instance's slice plane.
//
// Three ways to the views: one view, the Camera block's (plain builds); with BATCHED_VIEWS
// and INSTANCED_VIEWS, every view of a reflection level in one draw, each instance drawn once
// a view (instanced views, as single-pass instanced stereo draws two eyes: the instance
// attributes advance every view_count.x instances, so instance i is row i / n seen by view
// i % n: engine/render/batched_mirrors.py); with BATCHED_VIEWS alone, the six faces of a
// one-pass cube-map capture, projected by scene_layered.geom (a capture draws no
// OBJECT_MOTION build).
#if defined(BATCHED_VIEWS) && !defined(INSTANCED_VIEWS)
#define VIEWS_BY_GEOMETRY
#endif
#ifdef INSTANCED_VIEWS
#include "views_block.glsl"
#include "view_axis.glsl"
flat out uint v_node;     // the view's node index, its eye and axis (scene.frag's BATCHED_VIEWS inputs)
flat out vec4 v_eye;      // w: the view's way_scale (view_axis.glsl)
flat out vec3 v_eye_axis;
#ifdef FOG
flat out vec4 v_clip;     // the view's clip plane: where its rays enter it (fog.glsl)
#endif
#endif

#ifdef VIEWS_BY_GEOMETRY
// The one-pass capture: scene_layered.geom projects each triangle once per face, reading
// these outputs under their g_ names and writing the v_ names scene.frag reads.
#define v_world_pos g_world_pos
#define v_normal g_normal
#define v_uv g_uv
#define v_uv2 g_uv2
#define v_color g_color
#define v_surface g_surface
#define v_reflect g_reflect
#define v_tint g_tint
#define v_slots g_slots
#define v_vertex_color g_vertex_color
#endif
#ifdef OBJECT_MOTION
out vec4 v_clip_now;      // where the view projects the point this frame and last (way.glsl seen_moved)
out vec4 v_clip_before;
#endif

in vec3 in_position;
in vec3 in_normal;
in vec4 in_uv;             // xy: its UVs; zw: its second set (Mesh.second_uvs; (0, 1) without one)

in mat4 in_model;          // model -> world
#if !defined(VERTEX_COLOR) && !defined(SKINNED) && !defined(MORPHED)
in mat3 in_normal_matrix;  // inverse-transpose of the model's upper 3x3
#endif
in vec4 in_color;          // linear base colour, alpha
in vec4 in_surface;        // metallic, roughness, emissive power, normal-map scale
in vec4 in_reflect;        // reflection mix, refraction ior, -, -
in vec4 in_tint;           // reflection tint; w: where it is drawn (visibility.glsl)
in vec4 in_slice;          // world plane: only its front is drawn (things partly through a portal)
in uvec4 in_slots;         // emissive variant, refract variant, reflect variant, entity id
#ifdef VERTEX_COLOR
// The mesh's colour a vertex (Mesh.colors), linear.  The sixteen vertex inputs GL 4.1
// promises are all taken, so this build works the normal matrix out here instead of
// reading the instance's (three inputs freed for one; a SKINNED build frees them too, for its
// joints and weights: pose.glsl).
in vec4 in_vertex_color;
out vec4 v_vertex_color;
#endif

#ifdef VIEWS_BY_GEOMETRY
out float g_slice_distance;  // the geometry shader re-emits it as gl_ClipDistance[CLIP_SLICE]
#endif
out vec3 v_world_pos;
out vec3 v_normal;
out vec2 v_uv;
#ifdef SECOND_UV_MAPS
out vec2 v_uv2;            // the second set, read by the maps Material.second_uv_maps names (uv_sets.glsl)
#endif
flat out vec4 v_color;
flat out vec4 v_surface;
flat out vec4 v_reflect;
flat out vec4 v_tint;
flat out uvec4 v_slots;
#ifdef SCREEN_REFRACTION
flat out vec3 v_centre;  // the instance's origin in the world: a solid ball's centre (scene.frag refraction_origin)
// The batch's rows this draw draws (first, past): a layer of glass behind glass draws its own
// alone (engine/render/screen_refraction.py refraction_layers); the others are clipped away.
uniform ivec2 drawn_instances;
#endif

void main() {
#if defined(SKINNED) || defined(MORPHED)
    vec3 position = in_position;
    vec3 normal = in_normal;
#ifdef OBJECT_MOTION
    vec3 position_before = in_position;   // (posed as last frame's rows have it: posed_before)
    vec3 normal_before = in_normal;
#endif
#ifdef MORPHED
    morph(pose_rows, position, normal);  // its morph targets weighed in (as shadow.vert)
#ifdef OBJECT_MOTION
    morph(pose_before, position_before, normal_before);
#endif
#endif
#ifdef SKINNED
    mat4 skin = skin_matrix(pose_rows);  // bent by its joints, then placed
    vec4 world = in_model * (skin * vec4(position, 1.0));
#ifdef OBJECT_MOTION
    vec4 posed_before = in_model * (skin_matrix(pose_before) * vec4(position_before, 1.0));
#endif
    v_normal = transpose(inverse(mat3(in_model) * mat3(skin))) * normal;
#else
    vec4 world = in_model * vec4(position, 1.0);
    v_normal = transpose(inverse(mat3(in_model))) * normal;
#ifdef OBJECT_MOTION
    vec4 posed_before = in_model * vec4(position_before, 1.0);
#endif
#endif
#else
    vec4 world = in_model * vec4(in_position, 1.0);
#ifdef OBJECT_MOTION
    vec4 posed_before = world;   // (its shape does not change: only its matrix moves)
#endif
#ifdef VERTEX_COLOR
    v_normal = transpose(inverse(mat3(in_model))) * in_normal;
#else
    v_normal = in_normal_matrix * in_normal;
#endif
#endif
    v_world_pos = world.xyz;
#ifdef SCREEN_REFRACTION
    v_centre = in_model[3].xyz;
#endif
    v_uv = in_uv.xy;
#ifdef SECOND_UV_MAPS
    v_uv2 = in_uv.zw;
#endif
    v_color = in_color;
    v_surface = in_surface;
    v_reflect = in_reflect;
    v_tint = in_tint;
    v_slots = in_slots;
#ifdef VERTEX_COLOR
    v_vertex_color = in_vertex_color;
#endif
    gl_ClipDistance[CLIP_SLICE] = dot(world, in_slice);
#ifdef VIEWS_BY_GEOMETRY
    g_slice_distance = dot(world, in_slice);
#elif defined(INSTANCED_VIEWS)
    // This instance's view: its camera, and its rectangle as four clip planes through the
    // eye (x >= x0 w, x <= x1 w, y >= y0 w, y <= y1 w), which stand in for the per-view
    // scissor of a view drawn alone.  The view's own surface, and an instance hidden in
    // this kind of view or on none of its layers, are clipped away, as there.
    MirrorView v = views[gl_InstanceID % view_count.x];
    gl_Position = v.view_proj * world;
#ifdef OBJECT_MOTION
    v_clip_now = gl_Position;
    v_clip_before = v.view_proj * vec4(world_before(in_slots.w, posed_before), 1.0);
#endif
    bool hidden = in_slots.w == v.node.y || (v.node.z != 0u && in_slots.w == v.node.z)
        || hidden_in_view(in_tint.w, v.node.w);
    gl_ClipDistance[CLIP_VIEW_PLANE] = hidden ? -1.0 : dot(world, v.clip_plane);
    gl_ClipDistance[CLIP_RECT_LEFT] = gl_Position.x - v.rect.x * gl_Position.w;
    gl_ClipDistance[CLIP_RECT_RIGHT] = v.rect.z * gl_Position.w - gl_Position.x;
    gl_ClipDistance[CLIP_RECT_BOTTOM] = gl_Position.y - v.rect.y * gl_Position.w;
    gl_ClipDistance[CLIP_RECT_TOP] = v.rect.w * gl_Position.w - gl_Position.y;
    v_node = v.node.x;
    v_eye = vec4(v.eye.xyz, abs(v.eye.w));
    v_eye_axis = view_axis(v.view_proj);
#ifdef FOG
    v_clip = v.clip_plane;
#endif
#else
    gl_Position = camera.view_proj * world;
#ifdef OBJECT_MOTION
    v_clip_now = gl_Position;
    v_clip_before = camera.view_proj * vec4(world_before(in_slots.w, posed_before), 1.0);
#endif
    // Behind the view's plane is clipped; so is all of the surface the view looks out of
    // (a mirror's own glass, a portal's partner), which lies on that plane: the plane itself
    // needs no offset, so nothing touching the mirror opens a crack in its reflection.  An
    // instance hidden in this kind of view, or on none of the layers it shows, goes the same way.
    bool hidden = in_slots.w == camera.skip.x || (camera.skip.y != 0u && in_slots.w == camera.skip.y)
        || hidden_in_view(in_tint.w, camera.skip.z);
#ifdef SCREEN_REFRACTION
    hidden = hidden || gl_InstanceID < drawn_instances.x || gl_InstanceID >= drawn_instances.y;
#endif
    gl_ClipDistance[CLIP_VIEW_PLANE] = hidden ? -1.0 : dot(world, camera.clip_plane);
#endif
}
