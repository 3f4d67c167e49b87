// Scene lights, packed by engine/render/views.py lights_block (keep the two in step:
// tests/test_ambient_light.py reads the block back as GLSL lays it out).  Its array sizes,
// MAX_DIRECTIONAL_LIGHTS and MAX_POINT_LIGHTS, are views.py's, defined by the shader library.
layout(std140) uniform Lights {
    vec4 sky_sh[9];                                 // rgb: the sky's irradiance coefficients E_lm (engine/render/irradiance.py)
    ivec4 counts;                                   // x: directional, y: point; z: 1 where the sky cube is a flat
                                                    // background; w: 1 where materials reflect the light from all round
    vec4 directional_dir[MAX_DIRECTIONAL_LIGHTS];   // xyz: direction the light travels; w: 1 for the sun (the
                                                    // brightest, which contact shadows dim), -1 for a moon, 0 for
                                                    // a fill light (a CloudLayer shades the sun and moons: w != 0)
    vec4 directional_color[MAX_DIRECTIONAL_LIGHTS]; // rgb: colour x intensity
    vec4 point_pos[MAX_POINT_LIGHTS];               // xyz: position, w: range
    vec4 point_color[MAX_POINT_LIGHTS];             // rgb: colour x intensity, w: its sphere's radius (0: a point)
    vec4 point_spot[MAX_POINT_LIGHTS];              // the spot cone (light_rules.spot_cone; 0, 0, 0, 1: all round)
    vec4 point_cookie_u[MAX_POINT_LIGHTS];          // xyz: the cookie's right / tan(angle), w: its layer (-1: none)
    vec4 point_cookie_v[MAX_POINT_LIGHTS];          // xyz: its top / tan(angle) (light_rules.lamp_cookie); w: its
                                                    // contact shadows' channel + 1 (0: none; scene.frag)
    vec4 point_rect_u[MAX_POINT_LIGHTS];            // xyz: a rectangle's half width along its side; w: its front's
                                                    // sign over its area (0: no rectangle; light_rules.lamp_rectangle)
    vec4 point_rect_v[MAX_POINT_LIGHTS];            // xyz: its half height along its other side; w: a tube's
                                                    // radius (its u: the half length; light_rules.lamp_rectangle)
    ivec4 rect_slots[MAX_RECT_LIGHTS / 4];          // the rectangles' slots, lit as rectangles (-1: no more)
} lights;

#include "spot_cone.glsl"
#include "spot_cookie.glsl"

// Point light i's fade to 0 at its range, times its spot cone: its falloff (below) without the
// inverse square, which a rectangle light's form factor takes the place of (rect_lights.glsl).
float lamp_fade(int i, float dist, vec3 l) {
    float fade = clamp(1.0 - pow(dist / lights.point_pos[i].w, 4.0), 0.0, 1.0);
    return fade * fade * spot_factor(lights.point_spot[i], l);
}

// A rectangle light's share of its light along ``l``: Lambert's cosine of its face, 0 behind
// it (so far off it lights as a point light of its intensity straight ahead of it); a tube's
// the sine of l's angle from its axis (its outline's width); 1 for a point or a sphere.  The light shafts' air and lit particles take a rectangle so; a surface
// takes its form factor (rect_lights.glsl).
float lamp_face(int i, vec3 l) {
    vec4 u = lights.point_rect_u[i];
    vec4 v = lights.point_rect_v[i];
    if (u.w == 0.0) return 1.0;
    if (v.w > 0.0) return length(cross(normalize(u.xyz), l));  // a tube: the sine from its axis
    vec3 front = sign(u.w) * normalize(cross(u.xyz, v.xyz));
    return max(-dot(l, front), 0.0);
}

// How much of point light i's light (its colour x intensity) reaches a point ``dist`` from it,
// ``l`` the unit way from the point to the light: the inverse square (kept finite at the
// light) faded smoothly to 0 at its range, times its spot cone and a rectangle's face.  The
// scene's lights, the light shafts' lamps (volumetric_fog.frag) and lit particles alike.
float lamp_falloff(int i, float dist, vec3 l) {
    return lamp_fade(i, dist, l) / (dist * dist + 1.0) * lamp_face(i, l);
}
