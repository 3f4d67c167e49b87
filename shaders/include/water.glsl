// Water (components/water.py) in the reflection's composite: the rippled normal from two
// scrolling layers of the mirror's normal map, and the reflection's Fresnel weight.
// Needs normal_map.glsl (the map). Included by every build of the composite, only
// COMPOSITE_WATER calls it: an include inside an #ifdef would hide its errors from every
// build that leaves it out.

#include "water_waves.glsl"
#include "water_fresnel.glsl"

// The normal of the waves (water_waves.glsl water_slope: the two layers of the mirror's
// normal map) scaled by ``scale`` (normal_scale) in the frame t (+U), b (+V), n (out of the
// surface).  With share 0 it is bent_normal's.  Filtered by the UVs' screen derivatives uv_dx
// and uv_dy, taken before the composite leaves any pixel out (bent_normal says why).
vec3 water_normal(vec3 t, vec3 b, vec3 n, vec2 uv, vec2 uv_dx, vec2 uv_dy, vec2 flow, float share, float scale) {
    vec2 slope = water_slope(normal_map, uv, uv_dx, uv_dy, flow, share);
    return normalize((t * slope.x + b * slope.y) * scale + n);
}

// The reflectance of the water's top for a surface of normal n seen from direction to_eye
// (both unit): Schlick's approximation for f0 (water_fresnel.glsl).
float water_fresnel(vec3 n, vec3 to_eye, float f0) {
    return water_reflectance(f0, dot(n, to_eye), false);
}

// The reflectance of the water's underside, seen from the water (the camera under it): all of
// it past the critical angle (the bright ring about Snell's window), Schlick's inside it
// (water_fresnel.glsl).
float water_fresnel_inside(vec3 n, vec3 to_eye, float f0) {
    return water_reflectance(f0, dot(n, to_eye), true);
}
