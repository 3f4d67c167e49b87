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

#ifdef DUAL_QUATERNION_SKINNING
// Dual quaternion skinning (Skin.skinning "dual_quaternion"; Kavan, Collins, Zara and
// O'Sullivan, "Geometric Skinning with Approximate Dual Quaternion Blending", 2008), with
// their two-phase blend for joints that are not rigid (Blender's and Maya's DQ with scale):
// engine/core/skinning.py dual_quaternion_matrices is its twin.  Each joint's matrix is taken
// as a stretch (its scale and shear, uneven or not), then a rotation (its columns made
// orthonormal) and a translation; the stretches blend by weight, the rotations and
// translations as unit dual quaternions (each turned into the first's hemisphere, summed by
// weight, normalised), so a twisted wrist keeps its thickness where linear blending
// collapses it, and a joint squashed and stretched bends its vertices as its matrix does.

// A rotation matrix's unit quaternion (x, y, z, w), from its largest diagonal term.
vec4 rotation_quaternion(mat3 r) {
    float trace = r[0][0] + r[1][1] + r[2][2];
    vec4 q;
    if (trace > 0.0) {
        q = vec4(r[1][2] - r[2][1], r[2][0] - r[0][2], r[0][1] - r[1][0], trace + 1.0);
    } else if (r[0][0] >= r[1][1] && r[0][0] >= r[2][2]) {
        q = vec4(1.0 + r[0][0] - r[1][1] - r[2][2], r[1][0] + r[0][1], r[2][0] + r[0][2], r[1][2] - r[2][1]);
    } else if (r[1][1] >= r[2][2]) {
        q = vec4(r[1][0] + r[0][1], 1.0 + r[1][1] - r[0][0] - r[2][2], r[2][1] + r[1][2], r[2][0] - r[0][2]);
    } else {
        q = vec4(r[2][0] + r[0][2], r[2][1] + r[1][2], 1.0 + r[2][2] - r[0][0] - r[1][1], r[0][1] - r[1][0]);
    }
    return normalize(q);
}

vec4 quaternion_product(vec4 a, vec4 b) {
    return vec4(a.w * b.xyz + b.w * a.xyz + cross(a.xyz, b.xyz), a.w * b.w - dot(a.xyz, b.xyz));
}

// A joint's rotation from its matrix's linear part: Gram-Schmidt on its columns (x the
// first's way, y the second's less its x, z = x cross y), a column squashed to nothing
// replaced (x by the other two's cross product, else the x axis; y by a way square to x).
// Any rotation is exact with its stretch (transpose(rotation) * linear): this one blends well.
mat3 joint_rotation(mat3 linear) {
    float tiny = 1e-6 * max(max(length(linear[0]), length(linear[1])), length(linear[2]));
    vec3 x = linear[0];
    if (length(x) <= tiny) x = cross(linear[1], linear[2]);
    if (length(x) <= tiny * tiny) x = vec3(1.0, 0.0, 0.0);
    x = normalize(x);
    vec3 y = linear[1] - dot(linear[1], x) * x;
    if (length(y) <= tiny) y = cross(x, abs(x.x) < 0.9 ? vec3(1.0, 0.0, 0.0) : vec3(0.0, 1.0, 0.0));
    y = normalize(y);
    return mat3(x, y, cross(x, y));
}

// Joint j's dual quaternion (real, dual) and its stretch (the rotation's transpose times
// its linear part: the identity for a rigid joint).
void joint_dual_quaternion(sampler2D rows, uint joint, out vec4 real, out vec4 dual, out mat3 stretch) {
    mat4 m = joint_matrix(rows, joint);
    mat3 linear = mat3(m);
    mat3 rotation = joint_rotation(linear);
    stretch = transpose(rotation) * linear;
    real = rotation_quaternion(rotation);
    dual = 0.5 * quaternion_product(vec4(m[3].xyz, 0.0), real);
}

// The vertex's blended matrix: the mesh as modelled -> as posed by ``rows`` (pose_rows;
// pose_before: as it was), the blended rotation and translation after the blended stretch.
mat4 skin_matrix(sampler2D rows) {
    vec4 real0, dual0, real, dual;
    mat3 stretch0, stretch;
    joint_dual_quaternion(rows, in_joints.x, real0, dual0, stretch0);
    vec4 blend_real = in_weights.x * real0, blend_dual = in_weights.x * dual0;
    mat3 blend_stretch = in_weights.x * stretch0;
    for (int k = 1; k < 4; ++k) {
        joint_dual_quaternion(rows, in_joints[k], real, dual, stretch);
        float w = dot(real, real0) < 0.0 ? -in_weights[k] : in_weights[k];   // the same hemisphere
        blend_real += w * real;
        blend_dual += w * dual;
        blend_stretch += in_weights[k] * stretch;
    }
    float norm = length(blend_real);
    blend_real /= norm;
    blend_dual /= norm;
    vec3 t = 2.0 * (blend_real.w * blend_dual.xyz - blend_dual.w * blend_real.xyz + cross(blend_real.xyz, blend_dual.xyz));
    vec4 q = blend_real;
    mat3 rotation = mat3(1.0 - 2.0 * (q.y * q.y + q.z * q.z), 2.0 * (q.x * q.y + q.w * q.z), 2.0 * (q.x * q.z - q.w * q.y),
                         2.0 * (q.x * q.y - q.w * q.z), 1.0 - 2.0 * (q.x * q.x + q.z * q.z), 2.0 * (q.y * q.z + q.w * q.x),
                         2.0 * (q.x * q.z + q.w * q.y), 2.0 * (q.y * q.z - q.w * q.x), 1.0 - 2.0 * (q.x * q.x + q.y * q.y));
    mat4 skin = mat4(rotation * blend_stretch);
    skin[3] = vec4(t, 1.0);
    return skin;
}
#else
// The vertex's blended matrix (linear blend skinning): the mesh as modelled -> as posed by
// ``rows`` (pose_rows; pose_before: as it was).
mat4 skin_matrix(sampler2D rows) {
    return in_weights.x * joint_matrix(rows, in_joints.x) + in_weights.y * joint_matrix(rows, in_joints.y)
        + in_weights.z * joint_matrix(rows, in_joints.z) + in_weights.w * joint_matrix(rows, in_joints.w);
}
#endif
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
