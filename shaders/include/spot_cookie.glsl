// Spot light cookies (PointLight.cookie; engine/render/spot_cookies.py): the colour a spot's
// image gives its light along ``l``, the unit vector from a lit point to the light.  ``right``
// and ``up`` are its cookie rows (engine/rules/light_rules.py lamp_cookie: the image's right
// and top over the tangent of the spot's angle, the layer in right.w, -1 for none), ``cone``
// its spot cone (its axis along cone.xyz).  The point's place in the image is where the line
// from the light meets the square about the cone's circle: 0.5 + 0.5 (d.right, d.up) / d.axis,
// d = -l, a slide projector's perspective.  White where the light has no cookie.  Only the
// SPOT_COOKIES builds hold it: frames where a kept light has one.
//
// The caller samples it before any branch a pixel's neighbours may not take (its mip level
// comes from the uv's derivatives across the 2 x 2 quad).
#ifdef SPOT_COOKIES
uniform sampler2DArray spot_cookies;

vec3 cookie_light(vec4 right, vec4 up, vec4 cone, vec3 l) {
    vec3 d = -l;
    float along = max(dot(d, normalize(cone.xyz)), 1e-3);
    vec2 uv = 0.5 + 0.5 * vec2(dot(d, right.xyz), dot(d, up.xyz)) / along;
    vec3 image = texture(spot_cookies, vec3(uv, max(right.w, 0.0))).rgb;
    return right.w < 0.0 ? vec3(1.0) : image;
}
#endif
