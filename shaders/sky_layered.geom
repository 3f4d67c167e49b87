#version 410 core
// The sky of a one-pass cube-map capture: the full-screen triangle once per face (invocation
// i = face i, gl_Layer = i), each corner carrying its world direction through that face's
// view (sky.frag built with LAYERED reads it instead of the Camera block).

layout(triangles, invocations = 6) in;
layout(triangle_strip, max_vertices = 3) out;

#include "views_block.glsl"

in vec2 v_ndc[];
out vec3 g_direction;
flat out vec3 g_eye;

void main() {
    MirrorView v = views[gl_InvocationID];
    mat4 to_world = inverse(v.view_proj);
    for (int c = 0; c < 3; ++c) {
        vec4 far_point = to_world * vec4(v_ndc[c], 1.0, 1.0);
        g_direction = far_point.xyz / far_point.w - v.eye.xyz;
        g_eye = v.eye.xyz;
        gl_Position = gl_in[c].gl_Position;
        gl_Layer = gl_InvocationID;
        EmitVertex();
    }
    EndPrimitive();
}
