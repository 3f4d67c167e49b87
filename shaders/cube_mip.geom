#version 410 core
// One mip level of all six faces of a cube map in one draw: the full-screen triangle once
// per face (invocation i = face i = gl_Layer), the face number passed on to the fragment.

layout(triangles, invocations = 6) in;
layout(triangle_strip, max_vertices = 3) out;

flat out int g_face;

void main() {
    for (int c = 0; c < 3; ++c) {
        gl_Position = gl_in[c].gl_Position;
        gl_Layer = gl_InvocationID;
        g_face = gl_InvocationID;
        EmitVertex();
    }
    EndPrimitive();
}
