// Light through mirrors and portals (engine/rules/shadow_rules.py VirtualLight): each light's
// image through a surface that carries light, lighting a point only on the exit surface's
// front and only when the line from the point to the image crosses the exit's outline (the
// light came through the mirror or the portal's opening), shadowed by a map drawn from the
// image (engine/render/shadows.py draw_virtual).  Light reflected more than once (mirror to
// mirror) is the image of the image: the line from the point must then also pass through
// each earlier surface's outline as the later surfaces carry it, in order along the line,
// each entered from its front (virtual_more: up to MAX_APERTURES - 1 of them a light).
// Only the VIRTUAL_LIGHTS builds hold it (engine/render/scene_pass.py): frames where one shines.
#include "virtual_light_ways.glsl"
#ifdef VIRTUAL_LIGHTS

// The light of every virtual light at a surface point: ``diffuse`` its Lambertian share,
// ``normal`` the shading normal, ``geometric`` the mesh's (for the shadow lookup),
// ``energy_compensation`` the highlight's (scene.frag's); ``shadowed``
// false: no map looked up (MeshRef.receives_shadows off), the light's way in still its opening's.
vec3 virtual_lighting(vec3 position, vec3 normal, vec3 geometric, vec3 to_eye, vec3 diffuse, vec3 f0,
                      float roughness, vec3 energy_compensation, bool shadowed) {
    vec3 total = vec3(0.0);
#ifdef CAUSTICS
    // (the pixel's footprint, for a water's reflected caustics: taken before any branch, caustics.glsl)
    float caustic_footprint = max(length(dFdx(position)), length(dFdy(position)));
#endif
    for (int i = 0; i < virtual_lights.virtual_count.x; ++i) {
        vec3 l;
        float dist;
        float falloff = virtual_falloff(i, position, l, dist);
#ifdef SPOT_COOKIES
        // (before any branch a pixel's neighbours may not take: spot_cookie.glsl)
        vec3 cookie_at = cookie_place(virtual_lights.virtual_cookie_u[i], virtual_lights.virtual_cookie_v[i],
                                      virtual_lights.virtual_spot[i], l);
        vec2 cookie_dx = cookie_derivative(dFdx(cookie_at.xy)), cookie_dy = cookie_derivative(dFdy(cookie_at.xy));
#endif
        float nl = dot(normal, l);
        vec3 face = vec3(1.0);   // (scene.frag's: a rectangle's image on its face, rect_face)
        vec4 image = virtual_lights.virtual_position[i];
#ifdef RECT_LIGHTS
        // A rectangle's image (rect_lights.glsl): its light from all of it above the horizon,
        // through the opening as the line to its centre comes.
        RectLight rect = rect_light(virtual_lights.virtual_rect_u[i], virtual_lights.virtual_rect_v[i],
                                    image.xyz - position);
        float centre_nl = nl;
        if (rect.shape && image.w > 0.5) {
            falloff *= (dist * dist + 1.0) * rect.radiance;  // the inverse square out: the form factor's
            nl = rect_form_factor(rect, normal, face);
        }
#endif
#ifdef SUBSURFACE
        // (scene.frag's: the diffuse light scattered under the surface wraps past the terminator)
        if (falloff <= 0.0 || !virtual_comes_through(i, position, l, dist)) continue;
#else
        if (nl <= 0.0 || falloff <= 0.0 || !virtual_comes_through(i, position, l, dist)) continue;
#endif
#ifdef SPOT_COOKIES
        vec3 cookie = cookie_light(cookie_at, cookie_dx, cookie_dy);
#else
        const vec3 cookie = vec3(1.0);
#endif
        // (a water's body on its way: fog.glsl water_light's, virtual_light_ways.glsl)
        vec3 color = virtual_lights.virtual_color[i].rgb * virtual_kept(i, position, l, dist);
#ifdef CAUSTICS
        // The sun's or a lamp's image in a rippled water that gathers it: the light its waves
        // throw up (caustics.glsl caustic_reflected_light, from the sun itself: l turned back
        // up through the plane; caustic_reflected_lamp_light, from the lamp: its image turned
        // back over the plane); the water's slot + 1 in the v row's w (shadow_system), 0 none.
        int caustic = int(virtual_lights.virtual_v[i].w) - 1;
        if (caustic >= 0) {
            vec4 plane = caustic_plane[caustic];
            color *= image.w > 0.5
                ? caustic_reflected_lamp_light(caustic, position, image.xyz - 2.0 * (dot(plane.xyz, image.xyz) + plane.w)
                                               * plane.xyz, virtual_lights.virtual_cookie_v[i].w,
                                               virtual_lights.virtual_rect_u[i], virtual_lights.virtual_rect_v[i],
                                               caustic_footprint)
                : caustic_reflected_light(caustic, position, reflect(l, plane.xyz), caustic_footprint);
        }
#endif
        float shade = shadowed ? virtual_shadow(i, position, geometric, l, dist) : 1.0;
        vec3 arriving = color * cookie * falloff * shade;
#ifdef SUBSURFACE
        float shade_under = shade;
        if (shadowed && dot(geometric, l) < 0.0) {
            vec3 under_normal;
            vec3 under_at = subsurface_shadow_point(position, geometric, l, under_normal);
            shade_under = virtual_shadow(i, under_at, under_normal, l, dist);
        }
        total += diffuse * face * subsurface_diffuse(nl, shade, shade_under)
                 * (color * cookie * falloff);
        if (nl <= 0.0) continue;
#endif
        // A point image's sphere (its light's radius, in the cookie row's w; ggx.glsl sphere_highlight)
#ifdef ANISOTROPY
        vec3 highlight = anisotropic_specular(normal, l, to_eye, f0) * (nl * energy_compensation);  // (scene.frag's)
#else
        vec3 highlight = (image.w > 0.5 ? sphere_highlight(normal, to_eye, reflect(-to_eye, normal), image.xyz - position,
                                                           virtual_lights.virtual_cookie_v[i].w, f0, roughness)
                                        : ggx_specular(normal, l, to_eye, f0, roughness) * nl) * energy_compensation;
#ifdef RECT_LIGHTS
        if (rect.shape) highlight = rect_highlight(rect, normal, to_eye, f0, roughness) * energy_compensation;
#endif
#endif
#ifdef SUBSURFACE
        total += highlight * arriving;  // (its diffuse light above)
#else
        total += (diffuse * nl * face + highlight) * arriving;
#endif
        highlight_light += highlight * arriving;  // (scene.frag's: the highlights summed apart)
#ifdef CLEARCOAT
        vec3 coat = image.w > 0.5  // (scene.frag's clear coat, as the highlight above)
            ? sphere_highlight(coat_normal, to_eye, reflect(-to_eye, coat_normal), image.xyz - position,
                               virtual_lights.virtual_cookie_v[i].w, vec3(0.04), coat_roughness)
            : ggx_specular(coat_normal, l, to_eye, vec3(0.04), coat_roughness) * max(dot(coat_normal, l), 0.0);
#ifdef RECT_LIGHTS
        if (rect.shape) coat = rect_highlight(rect, coat_normal, to_eye, vec3(0.04), coat_roughness);
#endif
        coat_light += coat * arriving;
#endif
#ifdef SHEEN
        float sheen_share = 1.0;  // (scene.frag's sheen: a rectangle's form factor for n.l)
#ifdef RECT_LIGHTS
        if (rect.shape) sheen_share = nl / max(centre_nl, 1e-3);
#endif
        sheen_light += sheen_lobe(normal, l, to_eye) * (arriving * face * sheen_share);  // (scene.frag's sheen)
#endif
    }
    return total;
}
#endif
