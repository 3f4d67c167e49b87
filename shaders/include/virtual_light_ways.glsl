// The ways of light through mirrors and portals (engine/rules/shadow_rules.py VirtualLight), as
// every shader lit by them reads them: the VirtualLights block, whether a line from a point to
// a light's image comes out of its exit's front through its outline (and each earlier
// surface's: virtual_through), how much of its light the distance and its spot cone leave
// there (virtual_falloff) and its shadow map's lookup (virtual_shadow).  Included by
// virtual_lights.glsl (the scene's lighting) and particle.vert (a lit particle's sheet).
// Only builds with VIRTUAL_LIGHTS hold it: frames where one shines.
#ifdef VIRTUAL_LIGHTS
#include "water_fresnel.glsl"
// MAX_VIRTUAL_LIGHTS: engine/rules/shadow_rules.py's, defined by the shader library; so is
// MAX_APERTURES (components/limits.py MAX_LIGHT_BOUNCES): the exit's outline and
// MAX_APERTURES - 1 more a light.
layout(std140) uniform VirtualLights {
    ivec4 virtual_count;                            // x: how many
    mat4 virtual_matrix[MAX_VIRTUAL_LIGHTS];        // world -> atlas uv and depth (divide by w)
    vec4 virtual_position[MAX_VIRTUAL_LIGHTS];      // xyz: the image (w 1), or the direction it travels (w 0)
    vec4 virtual_color[MAX_VIRTUAL_LIGHTS];         // rgb: colour x intensity x tint x rate; w: range (point)
    vec4 virtual_exit[MAX_VIRTUAL_LIGHTS];          // the exit surface's plane, its front positive
    vec4 virtual_origin[MAX_VIRTUAL_LIGHTS];        // xyz: a corner of the exit's outline; w: a texel's size
                                                    // (metres for a directional image, radians for a point)
    vec4 virtual_u[MAX_VIRTUAL_LIGHTS];             // xyz: an edge of the outline over its length squared;
                                                    // w: its water (shadow_rules.water_code: virtual_fresnel)
    vec4 virtual_v[MAX_VIRTUAL_LIGHTS];             // xyz: the other edge likewise; w: the caustic water
                                                    // it is the sun's image in, its slot + 1 (0: none)
    vec4 virtual_params[MAX_VIRTUAL_LIGHTS];        // x: an atlas texel in uv, y: softness, z: taps a side,
                                                    // w: how many further outlines (virtual_more)
    vec4 virtual_spot[MAX_VIRTUAL_LIGHTS];          // a point image's spot cone, carried (spot_cone.glsl spot_factor)
    vec4 virtual_cookie_u[MAX_VIRTUAL_LIGHTS];      // its cookie's right / tan(angle), carried; w: layer (-1: none)
    vec4 virtual_cookie_v[MAX_VIRTUAL_LIGHTS];      // xyz: its cookie's top / tan(angle), carried (spot_cookie.glsl);
                                                    // w: a point image's sphere radius (PointLight.radius)
    vec4 virtual_rect_u[MAX_VIRTUAL_LIGHTS];        // a point image's rectangle rows, carried (light_rules
    vec4 virtual_rect_v[MAX_VIRTUAL_LIGHTS];        // carried_rectangle; lights.glsl point_rect_u / _v)
    vec4 virtual_tile[MAX_VIRTUAL_LIGHTS];          // its tile in the atlas: corner (uv), side (its map
                                                    // inside it, a gutter of far depth round it)
    vec4 virtual_more[MAX_VIRTUAL_LIGHTS * (MAX_APERTURES - 1) * 4];  // per outline: plane, corner, u, v (as above,
                                                                      // u's w its water)
    mat4 virtual_unfold[MAX_VIRTUAL_LIGHTS * MAX_APERTURES];  // per outline: the line past it -> where that
                                                              // stretch of the light's way runs (virtual_water)
} virtual_lights;

// Whether the line from ``position`` along ``l`` (towards the image), already through the
// exit at ``t``, passes each further outline of light ``i`` in order, from its front, before
// ``dist`` (the image).
bool virtual_through(int i, vec3 position, vec3 l, float t, float dist) {
    int count = int(virtual_lights.virtual_params[i].w);
    for (int k = 0; k < count; ++k) {
        int at = (i * (MAX_APERTURES - 1) + k) * 4;
        vec4 plane = virtual_lights.virtual_more[at];
        float towards = dot(plane.xyz, l);
        float h = dot(plane.xyz, position) + plane.w;
        if (towards >= 0.0 || h <= 0.0) return false;
        float s = h / -towards;
        if (s <= t || s > dist) return false;
        vec3 x = position + l * s - virtual_lights.virtual_more[at + 1].xyz;
        float a = dot(x, virtual_lights.virtual_more[at + 2].xyz);
        float b = dot(x, virtual_lights.virtual_more[at + 3].xyz);
        if (a < 0.0 || a > 1.0 || b < 0.0 || b > 1.0) return false;
        t = s;
    }
    return true;
}

uniform sampler2DShadow virtual_atlas;

float virtual_shadow(int i, vec3 position, vec3 normal, vec3 l, float dist) {
    vec4 params = virtual_lights.virtual_params[i];
    float nl = clamp(dot(normal, l), 0.0, 1.0);
    float texel = virtual_lights.virtual_origin[i].w;
    if (virtual_lights.virtual_position[i].w > 0.5) texel *= dist;  // an angle: its size here
    // Off the surface by a texel, more as the light grazes it; the filter's taps follow the
    // receiver's plane carried into the map (a push as wide as the filter moved the edges in).
    mat4 to_map = virtual_lights.virtual_matrix[i];
    vec4 p = to_map * vec4(position + normal * texel * (1.5 - nl), 1.0);
    p.xyz /= p.w;
    // Outside its tile (past the map's widest angle: VIRTUAL_MAX_FOV) or its depth range: no
    // caster of its is between the point and the image.
    if (outside_tile(p.xy, virtual_lights.virtual_tile[i].xyz) || p.z < 0.0 || p.z > 1.0) return 1.0;
    float lit = filtered_shadow(virtual_atlas, p.xyz, int(params.z), vec2(params.x), params.y,  // shadows.glsl
                                receiver_slope_in_map(to_map, p.xyz, normal));
#ifdef VIRTUAL_SEE_THROUGH_SHADOWS
    lit *= virtual_see_through_at(p.xyz);  // what see-through things on its way let through (shadows.glsl)
#endif
    return lit;
}

// How much of virtual light ``i``'s light reaches ``position`` by distance and spot cone
// (1 for a directional image), with ``l`` the unit way towards its image and ``dist`` the
// distance to it (1e30 for a directional one).
float virtual_falloff(int i, vec3 position, out vec3 l, out float dist) {
    vec4 image = virtual_lights.virtual_position[i];
    l = -image.xyz;
    dist = 1e30;
    if (image.w <= 0.5) return 1.0;
    vec3 d = image.xyz - position;
    dist = length(d);
    l = d / max(dist, 1e-4);
    float range = virtual_lights.virtual_color[i].w;
    float fade = clamp(1.0 - pow(dist / range, 4.0), 0.0, 1.0);  // lights.glsl's falloff, along the whole path
    return fade * fade / (dist * dist + 1.0) * spot_factor(virtual_lights.virtual_spot[i], l);
}

// What of virtual light ``i``'s light a water's body leaves on its way to ``position``, in
// each channel (fog.glsl water_light's, 1 but in FOG_WATER builds): the line from the point
// towards the image is the way unfolded, each stretch past an outline (the exit's at t, then
// virtual_through's) taken back to where the light ran by that stretch's virtual_unfold (a
// mirror's reflection, a portal's carry back), the water's depth summed over every stretch,
// the last to the image (``dist``; 1e30 for a directional one).  Past virtual_comes_through.
FogDepth virtual_water(int i, vec3 position, vec3 l, float dist) {
#ifdef FOG_WATER
    vec4 plane = virtual_lights.virtual_exit[i];
    float t = (dot(plane.xyz, position) + plane.w) / -dot(plane.xyz, l);
    FogDepth depth = water_depth(position, l, t);
    int count = int(virtual_lights.virtual_params[i].w);
    for (int k = 0; k <= count; ++k) {
        float s = dist;
        if (k < count) {
            plane = virtual_lights.virtual_more[(i * (MAX_APERTURES - 1) + k) * 4];
            s = (dot(plane.xyz, position) + plane.w) / -dot(plane.xyz, l);
        }
        mat4 back = virtual_lights.virtual_unfold[i * MAX_APERTURES + k];
        vec3 r = mat3(back) * l;
        float stretch = length(r);   // (a portal pair of two scales: its lengths over k)
        depth += water_depth((back * vec4(position + l * t, 1.0)).xyz, r / stretch, (s - t) * stretch);
        t = s;
    }
    return exp(-min(depth, FogDepth(FOG_MAX_EXPONENT)));
#else
    return FogDepth(1.0);
#endif
}

// The share of the light a surface on the way reflects, the line towards the image meeting it
// ``towards`` (the dot of its plane's normal and the line, negative: from its front): all of
// it for a mirror or a portal (``code`` 0: their tint and rate are in the colour), for a water
// Fresnel's at that angle (1 + F0 its top's, -(1 + F0) its underside's: shadow_rules.water_code).
float virtual_surface_share(float code, float towards) {
    if (code == 0.0) return 1.0;
    return water_reflectance(abs(code) - 1.0, -towards, code < 0.0);
}

// What the surfaces on virtual light ``i``'s way (the exit's outline and every further one)
// leave of its light along ``l``: the line from a point to an image crosses each as the light
// met the real surface, at the same angle (a reflection and a pair's carry keep angles), so a
// water reflects a lamp's light as it reflects a view of it: a few percent straight down, all
// of it at grazing angles and, from below, past the critical angle.
float virtual_fresnel(int i, vec3 l) {
    float share = virtual_surface_share(virtual_lights.virtual_u[i].w, dot(virtual_lights.virtual_exit[i].xyz, l));
    int count = int(virtual_lights.virtual_params[i].w);
    for (int k = 0; k < count; ++k) {
        int at = (i * (MAX_APERTURES - 1) + k) * 4;
        share *= virtual_surface_share(virtual_lights.virtual_more[at + 2].w, dot(virtual_lights.virtual_more[at].xyz, l));
    }
    return share;
}

// What reaches ``position`` of virtual light ``i``'s colour through the surfaces and waters on
// its way (virtual_fresnel, virtual_water), before its distance, cone, cookie and shadow.
FogDepth virtual_kept(int i, vec3 position, vec3 l, float dist) {
    return virtual_water(i, position, l, dist) * virtual_fresnel(i, l);
}

// Whether virtual light ``i``'s line from ``position`` along ``l`` (towards its image,
// ``dist`` away) comes out of its exit: ``position`` in front of the exit's plane, the line
// crossing that plane inside its outline before the image, and then every further outline
// (virtual_through): the light came through the mirror or the portal's opening.
bool virtual_comes_through(int i, vec3 position, vec3 l, float dist) {
    vec4 exit_plane = virtual_lights.virtual_exit[i];
    float height = dot(exit_plane.xyz, position) + exit_plane.w;
    float towards = dot(exit_plane.xyz, l);
    if (height <= 0.0 || towards >= 0.0) return false;  // behind the exit, or the line leaves it
    vec3 x = position + l * (height / -towards) - virtual_lights.virtual_origin[i].xyz;
    float a = dot(x, virtual_lights.virtual_u[i].xyz);
    float b = dot(x, virtual_lights.virtual_v[i].xyz);
    if (a < 0.0 || a > 1.0 || b < 0.0 || b > 1.0 || height / -towards > dist) return false;
    return virtual_through(i, position, l, height / -towards, dist);
}
#endif
