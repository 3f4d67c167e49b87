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
// The heights shadow themselves from the directional lights (after Tatarchuk's soft shadows):
// from where the view ray met them, a ray towards the light is marched up to the surface
// (parallax_shadow), and where heights stand above it the light is cut: bricks' edges throw
// the sun's shadow across the mortar.  (Not the lamps': scene.frag PARALLAX_LIT.)
// Needs normal_map.glsl (normal_map).  Only the PARALLAX builds hold it.
#ifdef PARALLAX
uniform float parallax_depth;  // its batch's Material.parallax_depth: metres below the surface at alpha 0

const float PARALLAX_MIN_STEPS = 6.0;
const int PARALLAX_MAX_STEPS = 16;
const int PARALLAX_SHADOW_STEPS = 6;
// A height standing this share of the depth over the light's ray takes all of the light: the
// shadow's soft edge, where the ray grazes a height's top.  (Tatarchuk's weighing of each step
// down by its distance, a wider penumbra farther off, shortened a low sun's shadows across
// 10 cm stripes to a third of the ray-cast ones: tests/test_parallax.py.)
const float PARALLAX_SHADOW_EDGE = 0.1;

// What parallax_offset found, for parallax_shadow: the UVs' gradients along the surface, the
// plain UVs' screen derivatives, the geometric normal, where the view ray met the heights
// (its UV and depth, 0 the surface, 1 the full depth).
vec3 parallax_grad_u = vec3(0.0), parallax_grad_v = vec3(0.0), parallax_normal = vec3(0.0, 0.0, 1.0);
vec2 parallax_duv1 = vec2(0.0), parallax_duv2 = vec2(0.0), parallax_hit_uv = vec2(0.0);
float parallax_hit = 0.0;

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
    parallax_grad_u = grad_u; parallax_grad_v = grad_v; parallax_normal = n;
    parallax_duv1 = duv1; parallax_duv2 = duv2;
    parallax_hit_uv = uv + full * hit;
    parallax_hit = hit;
    return full * hit;
}

// The share of the light arriving along unit ``l`` (towards the light) that reaches where the
// view ray met the heights: the ray from there to the light marched up to the surface in
// PARALLAX_SHADOW_STEPS, the most a step's height stands over it (in shares of the depth)
// taking the light by PARALLAX_SHADOW_EDGE.  1 at the heights' top (nothing above) and for a
// light below the horizon (n.l takes it).
float parallax_shadow(vec3 l) {
    float cos_l = dot(l, parallax_normal);
    if (parallax_hit <= 0.0 || cos_l <= 0.0) return 1.0;
    vec3 sideways = (l - parallax_normal * cos_l) / max(cos_l, 0.05) * parallax_depth;  // per unit of rise
    vec2 way = vec2(dot(parallax_grad_u, sideways), dot(parallax_grad_v, sideways));
    float rise = parallax_hit / float(PARALLAX_SHADOW_STEPS);
    float over = 0.0;
    for (int i = 1; i <= PARALLAX_SHADOW_STEPS; ++i) {
        float up = rise * float(i);
        float height_depth = 1.0 - textureGrad(normal_map, parallax_hit_uv + way * up, parallax_duv1, parallax_duv2).a;
        float ray_depth = parallax_hit - up;
        over = max(over, ray_depth - height_depth);
    }
    return 1.0 - clamp(over / PARALLAX_SHADOW_EDGE, 0.0, 1.0);
}
#endif
