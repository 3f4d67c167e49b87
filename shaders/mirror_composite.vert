#version 410 core
// One instance per view of a reflection level: a quad over the view's rectangle in the
// parent level, carrying the view's composite parameters to mirror_composite.frag.
// All views of a level composite in one draw.
in vec4 in_rect;             // NDC x0, y0, x1, y1 of the rectangle in the parent level
in mat4 in_inv_view_proj;    // the parent view's
in vec4 in_eye;              // xyz: the parent view's eye
in vec4 in_tint;
in vec4 in_params;           // reflect_rate, roughness, is_portal (0/1), -
in vec4 in_normal;           // xyz: the mirror's normal, world, facing the parent eye
in mat3 in_carry;            // a portal's rotation: directions here -> beyond the partner
in uint in_view;             // the view's index (its pixels in the level's node image)

noperspective out vec4 v_near;   // homogeneous world point on the near plane along the pixel's ray
flat out vec3 v_eye;
flat out vec4 v_tint;
flat out vec4 v_params;
flat out vec3 v_normal;
flat out mat3 v_carry;
flat out uint v_view;

void main() {
    vec2 corner = vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1));
    vec2 ndc = mix(in_rect.xy, in_rect.zw, corner);
    gl_Position = vec4(ndc, 0.0, 1.0);
    // The near plane, not the far one: for an oblique projection (the parent is itself a
    // mirror view) the near plane is the parent mirror's plane, still in front of the eye.
    // Unprojection is linear in NDC, so the homogeneous point interpolates exactly.
    v_near = in_inv_view_proj * vec4(ndc, -1.0, 1.0);
    v_eye = in_eye.xyz;
    v_tint = in_tint;
    v_params = in_params;
    v_normal = in_normal.xyz;
    v_carry = in_carry;
    v_view = in_view;
}
