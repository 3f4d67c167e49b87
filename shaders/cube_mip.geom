#version 410 core
// One mip level of all six faces of a cube map in one draw: the full-screen triangle once
// per face (invocation i = face i = gl_Layer), the face number passed on to the fragment.
// Only the faces in ``face_mask`` (bit i: face i) are drawn: a box-filtered face's chain
// reads that face alone, so a face whose level 0 is as it was keeps the levels it has.

layout(triangles, invocations = 6) in;
layout(triangle_strip, max_vertices = 3) out;

uniform int face_mask;

flat out int g_face;

void main() {
    if (((face_mask >> gl_InvocationID) & 1) == 0) return;
    for (int c = 0; c < 3; ++c) {
        gl_Position = gl_in[c].gl_Position;
        gl_Layer = gl_InvocationID;
        g_face = gl_InvocationID;
        EmitVertex();
    }
    EndPrimitive();
}
