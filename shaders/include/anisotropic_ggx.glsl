// Anisotropic GGX (Material.anisotropy, anisotropy_direction; glTF's KHR_materials_anisotropy,
// as Filament and the glTF sample viewer draw it): brushed metal, whose highlights stretch
// along the direction it was brushed.  The roughness along the surface's direction t is
// alpha_t = mix(alpha, 1, anisotropy^2), across it (b = n x t) alpha_b = alpha, alpha =
// roughness^2 (glTF's mapping).  D is Burley's anisotropic GGX (Filament's form), the
// visibility the separable Smith term ggx.glsl's is, with each direction's alpha projected
// onto it (so at anisotropy 0 both are ggx.glsl's exactly).  main sets the frame: t and b
// unit and in the surface, and the two alphas.  Needs ggx.glsl (schlick_fresnel, PI).
#ifdef ANISOTROPY
uniform vec2 anisotropy;            // x: its batch's Material.anisotropy, y: its direction (radians from u)
vec3 aniso_t = vec3(1.0, 0.0, 0.0);  // the direction of stretch, unit, in the surface
vec3 aniso_b = vec3(0.0, 0.0, 1.0);  // n x t
float aniso_at = 1.0, aniso_ab = 1.0;

float anisotropic_distribution(vec3 n, vec3 h) {
    float a2 = aniso_at * aniso_ab;
    vec3 d = vec3(aniso_ab * dot(aniso_t, h), aniso_at * dot(aniso_b, h), a2 * max(dot(n, h), 0.0));
    float w2 = a2 / dot(d, d);
    return a2 * w2 * w2 / PI;
}

// Divided by 4 (n.l)(n.v), as ggx_visibility.
float anisotropic_visibility(vec3 n, vec3 l, vec3 v) {
    float nl = max(dot(n, l), 1e-4), nv = max(dot(n, v), 1e-4);
    float gl = nl + length(vec3(aniso_at * dot(aniso_t, l), aniso_ab * dot(aniso_b, l), nl));
    float gv = nv + length(vec3(aniso_at * dot(aniso_t, v), aniso_ab * dot(aniso_b, v), nv));
    return 1.0 / (gl * gv);
}

// As ggx_specular: the light reflected towards v from light arriving along l.
vec3 anisotropic_specular(vec3 n, vec3 l, vec3 v, vec3 f0) {
    vec3 h = normalize(l + v);
    return schlick_fresnel(l, h, f0) * anisotropic_distribution(n, h) * anisotropic_visibility(n, l, v);
}

// The frame at a pixel: t from the UVs' u gradient in the surface (a cotangent frame from
// screen derivatives, as normal_map.glsl's: no tangent attribute), turned by ``angle`` about
// n towards v; where the UVs do not vary, any direction in the surface.
void anisotropic_frame(vec3 n, vec3 p, vec2 uv, float angle, float alpha) {
    vec3 dp1 = dFdx(p), dp2 = dFdy(p);
    vec2 duv1 = dFdx(uv), duv2 = dFdy(uv);
    vec3 u = cross(dp2, n) * duv1.x + cross(n, dp1) * duv2.x;  // the gradient of u in the surface
    u -= n * dot(n, u);
    if (dot(u, u) < 1e-30) u = abs(n.x) < 0.9 ? cross(n, vec3(1.0, 0.0, 0.0)) : cross(n, vec3(0.0, 1.0, 0.0));
    u = normalize(u);
    vec3 w = cross(n, u);
    // towards +v, also where the UVs are mirrored (glTF's bitangent: the tangent's w of -1)
    if (dot(w, cross(dp2, n) * duv1.y + cross(n, dp1) * duv2.y) < 0.0) w = -w;
    aniso_t = cos(angle) * u + sin(angle) * w;
    aniso_b = cross(n, aniso_t);
    aniso_ab = max(alpha, 1e-2);
    aniso_at = mix(aniso_ab, 1.0, anisotropy.x * anisotropy.x);
}

// The ray the light from all round is read along: reflected about a normal bent towards the
// one the stretched lobe sees (the glTF sample viewer's bent normal), by more the stronger
// the anisotropy and the smoother the surface.
vec3 anisotropic_reflect_dir(vec3 n, vec3 v, float roughness) {
    vec3 across = cross(aniso_t, v);
    vec3 seen = cross(across, aniso_t);
    float bend = 1.0 - anisotropy.x * (1.0 - roughness);
    bend *= bend;
    return reflect(-v, normalize(mix(seen, n, bend * bend)));
}
#endif  // ANISOTROPY
