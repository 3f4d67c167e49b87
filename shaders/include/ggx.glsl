// GGX microfacet specular (Walter et al. 2007, "Microfacet Models for Refraction through Rough
// Surfaces"): Schlick Fresnel, GGX distribution, Smith visibility.  The one Schlick Fresnel and
// F0-from-index of the shaders (water.glsl and scene.frag's refraction call these).
// Guarded: water_fresnel.glsl includes it for the shaders that have no GGX of their own.
#ifndef GGX_GLSL
#define GGX_GLSL
const float PI = 3.14159265358979;

// Schlick's approximation of the reflectance with reflectance f0 at normal incidence, at the
// cosine ``c`` of the angle of incidence (to the half vector, or the normal): f0 + (1 - f0) (1 - c)^5.
vec3 schlick_at(vec3 f0, float c) {
    float cosine = clamp(c, 0.0, 1.0);
    return f0 + (1.0 - f0) * pow(1.0 - cosine, 5.0);
}

// The same at the angle between unit vectors l and h.
vec3 schlick_fresnel(vec3 l, vec3 h, vec3 f0) {
    return schlick_at(f0, dot(l, h));
}

// Schlick's F0 of a dielectric of index ior against air: ((ior - 1) / (ior + 1))^2, as
// components/water.py f0_from_ior (tests/test_one_owner.py holds them equal).
float f0_from_ior(float ior) {
    return pow((ior - 1.0) / (ior + 1.0), 2.0);
}

// The GGX distribution, its denominator n.h^2 alpha^2 + (1 - n.h^2) with 1 - n.h^2 taken as
// |n x h|^2 (Filament's form): written as n.h^2 (alpha^2 - 1) + 1 it cancels in float32 near
// the peak, where a polished surface (alpha^2 1.6e-7 at roughness 0.02) lost two thirds of
// its highlight to one unit in the last place of n.h.
float ggx_distribution(vec3 n, vec3 h, float roughness) {
    float a2 = max(roughness * roughness, 1e-4);
    a2 *= a2;
    float nh = max(dot(n, h), 0.0);
    vec3 nxh = cross(n, h);
    float d = nh * nh * a2 + dot(nxh, nxh);
    return a2 / (PI * d * d);
}

// Smith-GGX visibility, already divided by 4 (n.l)(n.v).
float ggx_visibility(vec3 n, vec3 l, vec3 v, float roughness) {
    float a2 = max(roughness * roughness, 1e-4);
    a2 *= a2;
    float nl = max(dot(n, l), 1e-4);
    float nv = max(dot(n, v), 1e-4);
    float gl = nl + sqrt(a2 + (1.0 - a2) * nl * nl);
    float gv = nv + sqrt(a2 + (1.0 - a2) * nv * nv);
    return 1.0 / (gl * gv);
}

// Specular radiance reflected towards v from light arriving along l (both unit, away from surface).
vec3 ggx_specular(vec3 n, vec3 l, vec3 v, vec3 f0, float roughness) {
    vec3 h = normalize(l + v);
    return schlick_fresnel(l, h, f0) * ggx_distribution(n, h, roughness) * ggx_visibility(n, l, v, roughness);
}

// The highlight of a sphere light (PointLight.radius): GGX times n.l towards its
// representative point, the point of the sphere nearest the reflected ray ``r`` (Karis, "Real
// Shading in Unreal Engine 4", 2013), the lobe's peak scaled by alpha^2 / alpha'^2 so the
// wider highlight keeps the light's energy: alpha'^2 = alpha^2 + s (2 alpha + s) / (4 v.h),
// s the sine of the sphere's angular radius, its spread as the lobe's half vectors see it.
// Its s^2 / (4 v.h) makes a mirror show the sphere's own radiance at any angle (as Unreal's
// later normalisation, a2 + s (3 alpha + s) / (4 v.h), does); its cross term was chosen by
// measurement against the sphere's light integrated over the lobe by importance sampling
// (tests/test_sphere_lights.py): within 10% of it from roughness 0.05 to 0.7, where 3 alpha
// lost 17% on rough surfaces and Karis's first alpha' = alpha + s / 2 was 1.8 x too bright
// on smooth ones.  ``to_light``: from the point to the sphere's centre (not unit); radius 0:
// a point light's highlight, GGX times n.l along ``to_light``.  The sphere's part only in the
// SPHERE_LIGHTS builds (frames where a kept light has a radius): llvmpipe runs a branch's body
// for every pixel, which cost a frame without sphere lights 3-4% at 640x360.
vec3 sphere_highlight(vec3 n, vec3 v, vec3 r, vec3 to_light, float radius, vec3 f0, float roughness) {
    float dist = max(length(to_light), 1e-4);
    vec3 l = to_light / dist;
    float energy = 1.0;
#ifdef SPHERE_LIGHTS
    if (radius > 0.0) {
        vec3 centre_to_ray = dot(to_light, r) * r - to_light;
        l = normalize(to_light + centre_to_ray * clamp(radius / max(length(centre_to_ray), 1e-6), 0.0, 1.0));
        float alpha = max(roughness * roughness, 1e-4);
        float s = min(radius / dist, 1.0);
        float vh = max(dot(v, normalize(l + v)), 0.0);
        energy = alpha * alpha / min(alpha * alpha + s * (2.0 * alpha + s) / (4.0 * vh + 1e-3), 1.0);
    }
#endif
    return ggx_specular(n, l, v, f0, roughness) * (energy * max(dot(n, l), 0.0));
}

// GGX reflection of one pre-filtered sample: radiance arriving along the reflection direction r, weighted by
// Fresnel and visibility (the distribution term is folded into the pre-filtered sample).
vec3 ggx_reflect(vec3 n, vec3 r, vec3 v, vec3 radiance, vec3 f0, float roughness) {
    vec3 f = schlick_fresnel(r, n, f0);
    float vis = ggx_visibility(n, r, v, roughness);
    return f * vis * (4.0 * max(dot(v, n), 0.0)) * max(dot(n, r), 0.0) * radiance;
}

// Roughness-to-mip bias for a reflection sampled with roughness m from a box-filtered mip
// chain: lod += 2/(1-m)^2 - 1 from m = 0.25 up (the curve rough surfaces were tuned with);
// below it the constant level of that curve fades out (smoothstep), so the bias is 0 at
// m = 0 and a mirror-smooth surface reads the level of its own footprint.  (It was 1 there:
// a chrome ball read a level blurrier than its pixels, and a rough mirror's composite
// jumped a level between roughness 0, read 1:1, and the least roughness above it.)
float roughness_lod_bias(float m) {
    float gloss = max(1.0 - m, 0.05);
    return 2.0 / (gloss * gloss) - 2.0 + smoothstep(0.0, 0.25, m);
}
#endif
