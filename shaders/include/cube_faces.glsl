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
