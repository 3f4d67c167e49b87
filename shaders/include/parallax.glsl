// Parallax occlusion mapping (Material.parallax_depth; Tatarchuk, "Dynamic Parallax Occlusion
// Mapping with Approximate Soft Shadows", 2006): the normal map's alpha is a height map, 1 the
// surface and 0 parallax_depth metres below it, and each pixel's view ray is marched into it
// from the surface in 6 to 16 steps (more the more grazing the view), the crossing found
// between the last step above the heights and the first below (the straight line between the
// two gaps).  Every map is then read where the ray meets the heights (uv_sets.glsl adds the
// shift to MAP_UV).  The surface's outline, depth and shadows stay the mesh's.
// The way in metres turns into UVs by the UVs' gradients along the surface, from the same
// screen derivatives the normal map's frame is made of (scene.frag mapped_normal): no tangent
// attribute, and the depth is in metres whatever the UVs' scale.
// Needs normal_map.glsl (normal_map).  Only the PARALLAX builds hold it.
#ifdef PARALLAX
uniform float parallax_depth;  // its batch's Material.parallax_depth: metres below the surface at alpha 0

const float PARALLAX_MIN_STEPS = 6.0;
const int PARALLAX_MAX_STEPS = 16;

// The UV shift to where the ray from the eye through point p (unit geometric normal n, unit
// way to the eye to_eye, UV uv) meets the heights.
vec2 parallax_offset(vec3 n, vec3 p, vec3 to_eye, vec2 uv) {
    vec3 dp1 = dFdx(p), dp2 = dFdy(p);
    vec2 duv1 = dFdx(uv), duv2 = dFdy(uv);
    float det = dot(n, cross(dp1, dp2));
    float cos_view = dot(to_eye, n);
    if (abs(det) < 1e-20 || cos_view <= 0.0) return vec2(0.0);
    // The gradients of u and v along the surface (dp1, dp2 and their UV steps solved for them).
    vec3 across1 = cross(n, dp1), across2 = cross(dp2, n);
    vec3 grad_u = (across2 * duv1.x + across1 * duv2.x) / det;
    vec3 grad_v = (across2 * duv1.y + across1 * duv2.y) / det;
    // Where the ray is at the full depth, along the surface (its slope held at 20: a glancing ray).
    vec3 sideways = (n * cos_view - to_eye) / max(cos_view, 0.05) * parallax_depth;
    vec2 full = vec2(dot(grad_u, sideways), dot(grad_v, sideways));
    float steps = mix(float(PARALLAX_MAX_STEPS), PARALLAX_MIN_STEPS, cos_view);
    float step_depth = 1.0 / steps;
    float depth = 0.0;                                           // the ray's, 0 at the surface, 1 at full
    float floor_depth = 1.0 - textureGrad(normal_map, uv, duv1, duv2).a;   // the heights' there
    float above = floor_depth;                                   // the gap at the last step above them
    for (int i = 0; i < PARALLAX_MAX_STEPS; ++i) {
        if (depth >= floor_depth || float(i) >= steps) break;
        above = floor_depth - depth;
        depth += step_depth;
        floor_depth = 1.0 - textureGrad(normal_map, uv + full * depth, duv1, duv2).a;
    }
    if (depth == 0.0) return vec2(0.0);                          // the surface's own top: no shift
    float below = max(depth - floor_depth, 0.0);
    float hit = depth - step_depth * below / max(above + below, 1e-6);
    return full * hit;
}
#endif
