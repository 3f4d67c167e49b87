// The direction through point (s, t) of cube-map face `face` (0-5: +X, -X, +Y, -Y, +Z, -Z),
// s and t in [-1, 1] along the face's texture axes: GL's cube-map face table (the faces are
// left-handed; engine/render/sky.py face_directions is the same table in numpy).
vec3 cube_face_direction(int face, vec2 st) {
    float s = st.x;
    float t = st.y;
    if (face == 0) return vec3(1.0, -t, -s);
    if (face == 1) return vec3(-1.0, -t, s);
    if (face == 2) return vec3(s, 1.0, t);
    if (face == 3) return vec3(s, -1.0, -t);
    if (face == 4) return vec3(s, -t, 1.0);
    return vec3(-s, -t, -1.0);
}
