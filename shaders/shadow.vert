#version 410 core
// Shadow casters seen from a light (engine/render/shadows.py): depth only, every opaque
// batch, the light's camera in the Camera block.  What casts is what a person sees as solid:
// not a portal's opening (unless it carries light: what goes in leaves by its partner), not
// glass (a refracting instance), not something hidden in every kind of view or with
// MeshRef.casts_shadows off.  The transparent slot's batches (see-through paint and glass)
// are drawn by the SEE_THROUGH build into the lights' see-through maps (shadow.frag), glass too.
// Things partly through a portal are cut at their slice plane, as in every view, so the part
// that came out of the partner casts its own shadow there.  A cutout (the ALPHA_CUTOFF
// build, a batch's Material.alpha_cutoff its uniform) casts only where it is drawn:
// shadow.frag reads its alpha as scene.frag does.
#include "camera.glsl"
#include "visibility.glsl"
#include "pose.glsl"

in vec3 in_position;
in mat4 in_model;
in vec4 in_tint;    // w: where it is drawn (visibility.glsl)
in vec4 in_slice;
in uvec4 in_slots;  // emissive, refract, reflect variants, entity id

#ifdef ALPHA_CUTOFF
in vec4 in_uv;      // xy: its UVs; zw: its second set (Mesh.second_uvs)
in vec4 in_color;   // alpha: the colour's share of the cutout's alpha
out vec2 v_uv;
out float v_alpha;
#endif
#ifdef VERTEX_ALPHA
in vec4 in_vertex_color;  // a. the mesh's share a vertex (Mesh.colors), as scene.frag multiplies it in
#endif
// The light's own entity (0: none): its mesh is the light's body (a bulb round a lamp), which
// casts no shadow of its own light (engine/render/shadows.py, Shadows._draw_casters).
uniform uint light_body;
#ifdef SEE_THROUGH
uniform bool glass_only;  // an opaque batch's refracting instances only (engine/render/shadows.py)
#endif
#ifdef LEG
// A middle stretch of a virtual light's way (between two surfaces): its second plane, world.
uniform vec4 leg_plane;
#endif
#ifdef DISTANCE
out vec3 v_world_pos;
#endif
#ifdef LAYERED
out vec2 v_clip;  // shadow_layered.geom writes them per face
#endif

void main() {
    vec3 position = in_position;
#ifdef MORPHED
    vec3 normal = vec3(0.0);  // (unread: a caster's depth is all it draws)
    morph(pose_rows, position, normal);  // its morph targets weighed in, as scene.vert
#endif
#ifdef SKINNED
    vec4 world = in_model * (skin_matrix(pose_rows) * vec4(position, 1.0));  // bent by its joints, as scene.vert
#else
    vec4 world = in_model * vec4(position, 1.0);
#endif
    gl_Position = camera.view_proj * world;
    // A virtual light's map (light through a mirror or portal) leaves out the surfaces it
    // passes through (camera.skip) and what lies behind them (camera.clip_plane); a light's
    // own map has neither.  Every map leaves out the light's own body.
#ifdef SEE_THROUGH
    // A see-through batch whole; of an opaque batch, its glass alone (the depth map holds the rest).
    bool solid = !glass_only || in_slots.y != REFRACT_NONE;
#else
    bool solid = in_slots.y == REFRACT_NONE;
#endif
    bool casts = (in_slots.z != REFLECT_PORTAL || opening_casts(in_tint.w)) && solid
        && !casts_no_shadow(in_tint.w)
        && in_slots.w != camera.skip.x && in_slots.w != camera.skip.y && in_slots.w != light_body;
    float plane = dot(world, camera.clip_plane);
    gl_ClipDistance[CLIP_VIEW_PLANE] = casts ? plane : -1.0;
    gl_ClipDistance[CLIP_SLICE] = dot(world, in_slice);
#ifdef LEG
    gl_ClipDistance[CLIP_LEG_PLANE] = casts ? dot(world, leg_plane) : -1.0;
#endif
#ifdef DISTANCE
    v_world_pos = world.xyz;
#endif
#ifdef ALPHA_CUTOFF
    v_uv = in_uv.xy;
#ifdef SECOND_UV_MAPS
#if ((SECOND_UV_MAPS) & UV_BIT_TEXTURE) != 0
    v_uv = in_uv.zw;  // its albedo map reads the second set (Material.second_uv_maps)
#endif
#endif
    v_alpha = in_color.a;
#endif
#ifdef VERTEX_ALPHA
    v_alpha *= in_vertex_color.a;
#endif
#ifdef LAYERED
    v_clip = vec2(casts ? plane : -1.0, dot(world, in_slice));
#endif
}
