// How much of a spot light's light goes towards a point (PointLight.spot_angle and
// spot_blend): ``cone`` as engine/rules/light_rules.py spot_cone packs it (its owner:
// spot_factor there gives the same answers), ``l`` the unit vector from the point to the
// light.  0 outside the cone, 1 inside its inner cone, smoothstep between; 1 everywhere for
// a point light, whose cone is (0, 0, 0, 1).  One dot product: no angle, no branch.
float spot_factor(vec4 cone, vec3 l) {
    float t = clamp(dot(-l, cone.xyz) + cone.w, 0.0, 1.0);
    return t * t * (3.0 - 2.0 * t);
}
