// Linear blend skinning (engine/core/skinning.py is the same sum on arrays; components/skin.py
// says what the matrices are).  The SKINNED builds of scene.vert and shadow.vert read a
// vertex's four joints and weights (Mesh.joints, Mesh.weights) and blend its joints'
// matrices, each a joint's pose times its inverse bind matrix in the mesh's space, which the
// joint palette holds: one row a skinned entity (its draw's joint_row), three texels a joint,
// the matrix's first three rows (engine/render/joint_palettes.py).  A skinned instance is a
// batch of its own, so its row is the draw's uniform.

#ifdef SKINNED
in uvec4 in_joints;
in vec4 in_weights;
uniform sampler2D joint_palette;
uniform int joint_row;

// Joint j's matrix: its rows from the palette (texelFetch: exact floats, no filtering).
mat4 joint_matrix(uint joint) {
    int x = int(joint) * 3;
    vec4 r0 = texelFetch(joint_palette, ivec2(x, joint_row), 0);
    vec4 r1 = texelFetch(joint_palette, ivec2(x + 1, joint_row), 0);
    vec4 r2 = texelFetch(joint_palette, ivec2(x + 2, joint_row), 0);
    return transpose(mat4(r0, r1, r2, vec4(0.0, 0.0, 0.0, 1.0)));
}

// The vertex's blended matrix: model space as modelled -> model space as posed.
mat4 skin_matrix() {
    return in_weights.x * joint_matrix(in_joints.x) + in_weights.y * joint_matrix(in_joints.y)
        + in_weights.z * joint_matrix(in_joints.z) + in_weights.w * joint_matrix(in_joints.w);
}
#endif
