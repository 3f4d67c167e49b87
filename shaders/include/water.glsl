// Water (components/water.py) in the reflection's composite: the rippled normal from two
// scrolling layers of the mirror's normal map, and the reflection's Fresnel weight.
// Needs normal_map.glsl (the map) and ggx.glsl (schlick_fresnel). Included by every build of the composite, only
// COMPOSITE_WATER calls it: an include inside an #ifdef would hide its errors from every
// build that leaves it out.

#include "water_waves.glsl"

// The normal of the waves (water_waves.glsl water_slope: the two layers of the mirror's
// normal map) scaled by ``scale`` (normal_scale) in the frame t (+U), b (+V), n (out of the
// surface).  With share 0 it is bent_normal's.  Filtered by the UVs' screen derivatives uv_dx
// and uv_dy, taken before the composite leaves any pixel out (bent_normal says why).
vec3 water_normal(vec3 t, vec3 b, vec3 n, vec2 uv, vec2 uv_dx, vec2 uv_dy, vec2 flow, float share, float scale) {
    vec2 slope = water_slope(normal_map, uv, uv_dx, uv_dy, flow, share);
    return normalize((t * slope.x + b * slope.y) * scale + n);
}

// Schlick's approximation of the reflectance of a dielectric with reflectance f0 at normal
// incidence, for a surface of normal n seen from direction to_eye (both unit).
float water_fresnel(vec3 n, vec3 to_eye, float f0) {
    return schlick_fresnel(n, to_eye, vec3(f0)).x;
}

// The reflectance of the water's underside, seen from the water (the camera under it): past
// the critical angle (sin > 1 / index) all of it (total internal reflection, the bright ring
// about Snell's window); inside the window Schlick's approximation at the angle the light
// makes in the air (the larger of the two: the same reflectance either way through).
float water_fresnel_inside(vec3 n, vec3 to_eye, float f0) {
    float root = sqrt(clamp(f0, 0.0, 0.98));
    float index = (1.0 + root) / (1.0 - root);
    float cos_water = clamp(dot(n, to_eye), 0.0, 1.0);
    float sin_air_2 = index * index * (1.0 - cos_water * cos_water);
    if (sin_air_2 >= 1.0) return 1.0;
    return schlick_at(vec3(f0), sqrt(1.0 - sin_air_2)).x;
}
