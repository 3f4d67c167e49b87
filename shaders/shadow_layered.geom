#version 410 core
// A point light's six cube faces in one pass (engine/render/shadows.py): each caster
// triangle once per face (invocation i = face i, gl_Layer = i), projected by that face's
// camera.  The clip distances the vertex shader worked out (casts or not, the slice plane)
// are carried to each copy.

layout(triangles, invocations = 6) in;
layout(triangle_strip, max_vertices = 3) out;

uniform mat4 face_view_proj[6];

in vec3 v_world_pos[];
in vec2 v_clip[];
out vec3 g_world_pos;
#ifdef ALPHA_CUTOFF
in vec2 v_uv[];
in float v_alpha[];
out vec2 g_uv;
out float g_alpha;
#endif

void main() {
    for (int c = 0; c < 3; ++c) {
        g_world_pos = v_world_pos[c];
#ifdef ALPHA_CUTOFF
        g_uv = v_uv[c];
        g_alpha = v_alpha[c];
#endif
        gl_Position = face_view_proj[gl_InvocationID] * vec4(v_world_pos[c], 1.0);
        gl_ClipDistance[CLIP_VIEW_PLANE] = v_clip[c].x;
        gl_ClipDistance[CLIP_SLICE] = v_clip[c].y;
        gl_Layer = gl_InvocationID;
        EmitVertex();
    }
    EndPrimitive();
}
