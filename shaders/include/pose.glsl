// A posed mesh: bent by its joints (SKINNED: components/pose.py Skin) and wearing its morph
// targets (MORPHED: Morph), the morph targets first.  engine/core/skinning.py is the same sum
// on arrays.  The pose texture holds a row a posed entity (engine/render/pose_rows.py): three
// texels a joint, the first three rows of its matrix (a joint's pose times its inverse bind
// matrix, in the mesh's space), then at POSE_WEIGHTS_AT its morph weights, four a texel.  A
// posed instance is a batch of its own, so its row is its draw's pose_row.  OBJECT_MOTION
// builds read last frame's rows too (pose_before: engine/render/pose_rows.py track), the same
// sums over them placing the vertex where it was.

#if defined(SKINNED) || defined(MORPHED)
uniform sampler2D pose_rows;
uniform int pose_row;
#ifdef OBJECT_MOTION
uniform sampler2D pose_before;
#endif
#endif

#ifdef SKINNED
in uvec4 in_joints;   // Mesh.joints: the four joints it follows
in vec4 in_weights;   // Mesh.weights: how much, summing to 1

// Joint j's matrix: its rows from the pose row (texelFetch: exact floats, no filtering).
mat4 joint_matrix(sampler2D rows, uint joint) {
    int x = int(joint) * 3;
    vec4 r0 = texelFetch(rows, ivec2(x, pose_row), 0);
    vec4 r1 = texelFetch(rows, ivec2(x + 1, pose_row), 0);
    vec4 r2 = texelFetch(rows, ivec2(x + 2, pose_row), 0);
    return transpose(mat4(r0, r1, r2, vec4(0.0, 0.0, 0.0, 1.0)));
}

// The vertex's blended matrix (linear blend skinning): the mesh as modelled -> as posed by
// ``rows`` (pose_rows; pose_before: as it was).
mat4 skin_matrix(sampler2D rows) {
    return in_weights.x * joint_matrix(rows, in_joints.x) + in_weights.y * joint_matrix(rows, in_joints.y)
        + in_weights.z * joint_matrix(rows, in_joints.z) + in_weights.w * joint_matrix(rows, in_joints.w);
}
#endif

#ifdef MORPHED
uniform sampler2D morph_offsets;  // the mesh's (Mesh.morph_texels): a vertex's targets, position then normal
uniform int morph_targets;        // how many it has

vec4 morph_texel(int index) {
    int width = textureSize(morph_offsets, 0).x;
    return texelFetch(morph_offsets, ivec2(index % width, index / width), 0);
}

// The vertex (gl_VertexID: its index in the mesh) with each target's offsets times its weight
// in ``rows``.
void morph(sampler2D rows, inout vec3 position, inout vec3 normal) {
    int first = gl_VertexID * morph_targets * 2;
    for (int t = 0; t < morph_targets; ++t) {
        float weight = texelFetch(rows, ivec2(POSE_WEIGHTS_AT + t / 4, pose_row), 0)[t % 4];
        position += weight * morph_texel(first + 2 * t).xyz;
        normal += weight * morph_texel(first + 2 * t + 1).xyz;
    }
}
#endif
