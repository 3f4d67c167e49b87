// Spot light cookies (PointLight.cookie; engine/render/spot_cookies.py): the colour a spot's
// image gives its light along ``l``, the unit vector from a lit point to the light.  ``right``
// and ``up`` are its cookie rows (engine/rules/light_rules.py lamp_cookie: the image's right
// and top over the tangent of the spot's angle, the layer in right.w, -1 for none), ``cone``
// its spot cone (its axis along cone.xyz).  The point's place in the image is where the line
// from the light meets the square about the cone's circle: 0.5 + 0.5 (d.right, d.up) / d.axis,
// d = -l, a slide projector's perspective.  White where the light has no cookie.  Only the
// SPOT_COOKIES builds hold it: frames where a kept light projects one (not a panel's picture).
//
// Its place is worked out before any branch a pixel's neighbours may not take (its screen
// derivatives choose the image's mip level), the image read only where the light reaches
// (textureGrad in the branch): on llvmpipe a block of pixels outside every cone skips the read.
#if defined(SPOT_COOKIES) || defined(PANEL_PICTURES)
uniform sampler2DArray spot_cookies;   // (PANEL_PICTURES: the rectangles' pictures, rect_lights.glsl)
#endif
#ifdef PANEL_PICTURES
// A rectangle light's picture on its face (rect_lights.glsl rect_face; its rectangle row v's
// w: -1 - layer) as the light shafts' air takes it: the picture's mean colour (its last mip
// level, one texel).  White for any other light.
vec3 face_mean(vec4 rect_v) {
    return rect_v.w < 0.0 ? textureLod(spot_cookies, vec3(0.5, 0.5, -rect_v.w - 1.0), 16.0).rgb : vec3(1.0);
}
#endif
#ifdef SPOT_COOKIES

// (u, v, layer) of the image the line along ``l`` meets; a layer below 0: no cookie.  An
// all-round light's (right.w -2 - layer, a half more where its frame is mirrored:
// light_rules.lamp_cookie, carried_cookie) is wrapped about it: longitude and latitude in its
// frame, the image's middle ahead of it (its forward cross(up, right), turned back where mirrored).
vec3 cookie_place(vec4 right, vec4 up, vec4 cone, vec3 l) {
    vec3 d = -l;
    if (right.w < -1.5) {
        float code = -right.w - 2.0;
        float layer = floor(code + 0.25);
        vec3 forward = cross(up.xyz, right.xyz) * (code - layer > 0.25 ? -1.0 : 1.0);
        float x = dot(d, right.xyz), y = dot(d, up.xyz), z = dot(d, forward);
        return vec3(0.5 + atan(x, z) * 0.15915494, 0.5 + asin(clamp(y, -1.0, 1.0)) * 0.31830989, layer);  // 1/2pi, 1/pi
    }
    float along = max(dot(d, normalize(cone.xyz)), 1e-3);
    return vec3(0.5 + 0.5 * vec2(dot(d, right.xyz), dot(d, up.xyz)) / along, right.w);
}

// A cookie place's screen derivative (dFdx or dFdy of cookie_place's uv) across a wrapped
// image's seam, where u jumps by 1 between neighbours: the short way round.
vec2 cookie_derivative(vec2 change) {
    return vec2(change.x - round(change.x), change.y);
}

// The image's colour at ``place`` (cookie_place), its uv's screen derivatives ``dx``, ``dy``.
vec3 cookie_light(vec3 place, vec2 dx, vec2 dy) {
    if (place.z < 0.0) return vec3(1.0);
    return textureGrad(spot_cookies, place, dx, dy).rgb;
}
#endif
