// How much of the light meeting a water's surface it reflects (components/water.py): Schlick's
// approximation for a dielectric of reflectance f0 at normal incidence, the light meeting the
// surface at ``cosine`` from its normal.  ``from_water``: the light comes from under the
// surface, so past the critical angle (sin > 1 / index) all of it is reflected (total internal
// reflection), and inside it Schlick's at the angle the light makes in the air (the same
// reflectance either way through).  The one copy: the composite's Fresnel weight (water.glsl)
// and a virtual light's way off a water (virtual_light_ways.glsl virtual_fresnel) both read it;
// Schlick's own is ggx.glsl's.
#include "ggx.glsl"
float water_reflectance(float f0, float cosine, bool from_water) {
    float c = clamp(cosine, 0.0, 1.0);
    if (from_water) {
        float root = sqrt(clamp(f0, 0.0, 0.98));
        float index = (1.0 + root) / (1.0 - root);
        float sin_air_2 = index * index * (1.0 - c * c);
        if (sin_air_2 >= 1.0) return 1.0;
        c = sqrt(1.0 - sin_air_2);
    }
    return schlick_at(vec3(f0), c).x;
}
