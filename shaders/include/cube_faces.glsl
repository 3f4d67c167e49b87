#ifndef CUBE_FACES_GLSL
#define CUBE_FACES_GLSL
// The direction through point (s, t) of cube-map face `face` (0-5: +X, -X, +Y, -Y, +Z, -Z),
// s and t in [-1, 1] along the face's texture axes: the face's axis plus s and t times its
// texture axes. The table is GL's cube-map face table, kept once in engine/core/cube_faces.py;
// the shader library defines CUBE_FACE_FORWARD, CUBE_FACE_S and CUBE_FACE_T from it for
// every program (tests/test_one_owner.py checks this function against it texel by texel).
vec3 cube_face_direction(int face, vec2 st) {
    const vec3 forward[6] = CUBE_FACE_FORWARD;
    const vec3 s_axis[6] = CUBE_FACE_S;
    const vec3 t_axis[6] = CUBE_FACE_T;
    return forward[face] + st.x * s_axis[face] + st.y * t_axis[face];
}

// The face (0-5) direction ``d`` falls in and its point (s, t) there, each in [-1, 1]: the
// inverse of ``cube_face_direction`` (GL's cube-map face selection: the largest component's
// axis, ties to x before y before z), the table's axes written out one major axis at a time
// (a software rasteriser pays for a table's dynamic index at every pixel: the lamps'
// see-through lookup cost 1.12x a frame with it, 1.07x without).  tests/test_one_owner.py
// holds it to the table.
int cube_face_of(vec3 d, out vec2 st) {
    vec3 a = abs(d);
    bool x = a.x >= a.y && a.x >= a.z;
    bool y = !x && a.y >= a.z;
    vec3 st_major = x ? vec3(-sign(d.x) * d.z, -d.y, a.x) : y ? vec3(d.x, sign(d.y) * d.z, a.y)
        : vec3(sign(d.z) * d.x, -d.y, a.z);
    st = st_major.xy / max(st_major.z, 1e-30);
    return x ? (d.x < 0.0 ? 1 : 0) : y ? (d.y < 0.0 ? 3 : 2) : (d.z < 0.0 ? 5 : 4);
}

// The direction through point ``st`` of the face direction ``d`` falls in (the face
// ``cube_face_of`` gives): ``cube_face_direction`` of that face, written out one major axis
// at a time as ``cube_face_of`` is (no table index).  tests/test_one_owner.py holds it to the
// table.
vec3 cube_face_point(vec3 d, vec2 st) {
    vec3 a = abs(d);
    bool x = a.x >= a.y && a.x >= a.z;
    bool y = !x && a.y >= a.z;
    return x ? vec3(sign(d.x), -st.y, -sign(d.x) * st.x) : y ? vec3(st.x, sign(d.y), sign(d.y) * st.y)
        : vec3(sign(d.z) * st.x, -st.y, sign(d.z));
}
#endif
