// Light through mirrors and portals (engine/rules/shadow_rules.py VirtualLight): each light's
// image through a surface that carries light, lighting a point only on the exit surface's
// front and only when the line from the point to the image crosses the exit's outline (the
// light came through the mirror or the portal's opening), shadowed by a map drawn from the
// image (engine/render/shadows.py draw_virtual).  Light reflected more than once (mirror to
// mirror) is the image of the image: the line from the point must then also pass through
// each earlier surface's outline as the later surfaces carry it, in order along the line,
// each entered from its front (virtual_more: up to MAX_APERTURES - 1 of them a light).
// Only the VIRTUAL_LIGHTS builds hold it (engine/render/scene_pass.py): frames where one shines.
#ifdef VIRTUAL_LIGHTS
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
    vec4 virtual_u[MAX_VIRTUAL_LIGHTS];             // xyz: an edge of the outline over its length squared
    vec4 virtual_v[MAX_VIRTUAL_LIGHTS];             // xyz: the other edge likewise
    vec4 virtual_params[MAX_VIRTUAL_LIGHTS];        // x: an atlas texel in uv, y: softness, z: taps a side,
                                                    // w: how many further outlines (virtual_more)
    vec4 virtual_spot[MAX_VIRTUAL_LIGHTS];          // a point image's spot cone, carried (spot_cone.glsl spot_factor)
    vec4 virtual_cookie_u[MAX_VIRTUAL_LIGHTS];      // its cookie's right / tan(angle), carried; w: layer (-1: none)
    vec4 virtual_cookie_v[MAX_VIRTUAL_LIGHTS];      // xyz: its cookie's top / tan(angle), carried (spot_cookie.glsl);
                                                    // w: a point image's sphere radius (PointLight.radius)
    vec4 virtual_more[MAX_VIRTUAL_LIGHTS * (MAX_APERTURES - 1) * 4];  // per outline: plane, corner, u, v (as above)
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
    vec4 p = virtual_lights.virtual_matrix[i] * vec4(position + normal * texel * (1.0 + params.y) * (1.5 - nl), 1.0);
    p.xyz /= p.w;
    if (any(lessThan(p.xyz, vec3(0.0))) || any(greaterThan(p.xyz, vec3(1.0)))) return 1.0;
    return filtered_shadow(virtual_atlas, p.xyz, int(params.z), vec2(params.x), params.y);  // shadows.glsl
}

// The light of every virtual light at a surface point: ``diffuse`` its Lambertian share,
// ``normal`` the shading normal, ``geometric`` the mesh's (for the shadow lookup),
// ``energy_compensation`` the highlight's (scene.frag's); ``shadowed``
// false: no map looked up (MeshRef.receives_shadows off), the light's way in still its opening's.
vec3 virtual_lighting(vec3 position, vec3 normal, vec3 geometric, vec3 to_eye, vec3 diffuse, vec3 f0,
                      float roughness, vec3 energy_compensation, bool shadowed) {
    vec3 total = vec3(0.0);
    for (int i = 0; i < virtual_lights.virtual_count.x; ++i) {
        vec4 exit_plane = virtual_lights.virtual_exit[i];
        float height = dot(exit_plane.xyz, position) + exit_plane.w;
        vec4 image = virtual_lights.virtual_position[i];
        vec3 l = -image.xyz;
        float dist = 1e30;
        float falloff = 1.0;
        if (image.w > 0.5) {
            vec3 d = image.xyz - position;
            dist = length(d);
            l = d / max(dist, 1e-4);
            float range = virtual_lights.virtual_color[i].w;
            float fade = clamp(1.0 - pow(dist / range, 4.0), 0.0, 1.0);  // lights.glsl's falloff, along the whole path
            falloff = fade * fade / (dist * dist + 1.0) * spot_factor(virtual_lights.virtual_spot[i], l);
        }
#ifdef SPOT_COOKIES
        // (before any branch a pixel's neighbours may not take: spot_cookie.glsl)
        vec3 cookie_at = cookie_place(virtual_lights.virtual_cookie_u[i], virtual_lights.virtual_cookie_v[i],
                                      virtual_lights.virtual_spot[i], l);
        vec2 cookie_dx = cookie_derivative(dFdx(cookie_at.xy)), cookie_dy = cookie_derivative(dFdy(cookie_at.xy));
#endif
        if (height <= 0.0) continue;  // behind the exit: the light never comes out there
        float nl = dot(normal, l);
        float towards = dot(exit_plane.xyz, l);
        if (nl <= 0.0 || falloff <= 0.0 || towards >= 0.0) continue;
        // Where the line to the image crosses the exit's plane: inside its outline?
        vec3 x = position + l * (height / -towards) - virtual_lights.virtual_origin[i].xyz;
        float a = dot(x, virtual_lights.virtual_u[i].xyz);
        float b = dot(x, virtual_lights.virtual_v[i].xyz);
        if (a < 0.0 || a > 1.0 || b < 0.0 || b > 1.0 || height / -towards > dist) continue;
        if (!virtual_through(i, position, l, height / -towards, dist)) continue;
#ifdef SPOT_COOKIES
        vec3 cookie = cookie_light(cookie_at, cookie_dx, cookie_dy);
#else
        const vec3 cookie = vec3(1.0);
#endif
        vec3 arriving = virtual_lights.virtual_color[i].rgb * cookie * falloff
                        * (shadowed ? virtual_shadow(i, position, geometric, l, dist) : 1.0);
        // A point image's sphere (its light's radius, in the cookie row's w; ggx.glsl sphere_highlight)
#ifdef ANISOTROPY
        vec3 highlight = anisotropic_specular(normal, l, to_eye, f0) * (nl * energy_compensation);  // (scene.frag's)
#else
        vec3 highlight = (image.w > 0.5 ? sphere_highlight(normal, to_eye, reflect(-to_eye, normal), image.xyz - position,
                                                           virtual_lights.virtual_cookie_v[i].w, f0, roughness)
                                        : ggx_specular(normal, l, to_eye, f0, roughness) * nl) * energy_compensation;
#endif
        total += (diffuse * nl + highlight) * arriving;
        highlight_light += highlight * arriving;  // (scene.frag's: the highlights summed apart)
#ifdef CLEARCOAT
        coat_light += arriving * (image.w > 0.5  // (scene.frag's clear coat, as the highlight above)
            ? sphere_highlight(coat_normal, to_eye, reflect(-to_eye, coat_normal), image.xyz - position,
                               virtual_lights.virtual_cookie_v[i].w, vec3(0.04), coat_roughness)
            : ggx_specular(coat_normal, l, to_eye, vec3(0.04), coat_roughness) * max(dot(coat_normal, l), 0.0));
#endif
#ifdef SHEEN
        sheen_light += sheen_lobe(normal, l, to_eye) * arriving;  // (scene.frag's sheen)
#endif
    }
    return total;
}
#endif
