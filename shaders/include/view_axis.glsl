// Orthographic views (Camera.projection "orthographic", and every mirror and portal view of
// one): their rays are parallel.  Shared by scene.frag (the per-view passes) and
// scene_batched.geom (each view of a batched level), so both shade an orthographic view alike.
// The axis of a view whose view-projection is ``view_proj``, where it is orthographic (an
// affine view-projection: its fourth row 0, 0, 0, 1; Camera.projection "orthographic", and
// every mirror and portal view of one), unit, sign unknown; vec3(0) for a perspective view.
vec3 view_axis(mat4 view_proj) {
    vec3 w_row = vec3(view_proj[0][3], view_proj[1][3], view_proj[2][3]);
    if (dot(w_row, w_row) > 1e-10) return vec3(0.0);  // (a perspective view's is its axis over its scale)
    return normalize(cross(vec3(view_proj[0][0], view_proj[1][0], view_proj[2][0]),
                           vec3(view_proj[0][1], view_proj[1][1], view_proj[2][1])));
}

// How long a metre of a view's world is in its tree root's: a view beyond portals of two
// sizes sees that world scaled by their ratio k (its view matrix scales by 1 / k); mirrors
// keep lengths (1).  The light's way (way.glsl) is measured in the root's metres by it, the
// image's distance.  Read off the view matrix (a column's length), not the view-projection:
// an orthographic one holds no scale where a perspective one's fourth row does.  The views
// of a batched level carry it in their rows (views_block.glsl eye.w), a fallback its
// parent's (mirror_composite.vert).
float way_scale(mat4 view) {
    return length(view[0].xyz);
}

// Where the view's ray to ``p`` starts: a perspective view's eye (``axis`` 0); an
// orthographic view's rays are parallel to its axis, each from the plane across it through
// its eye.  The direction towards the viewer and the air a ray crosses follow from it.
vec3 ray_eye(vec3 eye, vec3 axis, vec3 p) {
    return dot(axis, axis) > 0.0 ? p + axis * dot(eye - p, axis) : eye;
}
