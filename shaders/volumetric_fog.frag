#version 410 core
// Light shafts (components/fog.py VolumetricFog, engine/render/volumetric_fog.py): the sun's
// (or by night the moon's: the directional light in slot ``sky_light``, engine/render/sky.py air_light)
// single scattering by the fog's air along each ray of the main view, summed in STEPS steps,
// and the VOLUMETRIC_LAMPS lamps' (PointLight.volumetric; MAX_VOLUMETRIC_LAMPS at most).
// At each step t (the step's start moved by ``start``, a different offset each texel):
//   density(x) x exp(-fog_depth(origin, x)) x shadow(x) x step
// (the air's density, what reaches the eye of what it scatters there (in each channel: a
// water's body takes some colours faster, Water.absorption), whether the sun reaches
// it: its shadow map and cascades, read with one bilinear comparison, SHADOW_SINGLE_TAP, as
// the steps' offsets and the filter soften the shafts' edges as a wider filter would, and
// under CLOUD_SHADOWS the share a CloudLayer's cloud on the way lets through, and under
// FOG_WATER what a water's body on the way leaves, fog.glsl water_light, and under CAUSTICS
// what a rippled water over it gathers there, caustics.glsl), times
// the sun's light (colour x intensity), the Henyey-Greenstein phase function of the angle
// between the sun's light and the ray, and VolumetricFog.intensity and albedo.  Under
// VIRTUAL_LIGHTS the light of those lights through mirrors and portals
// (shadow_rules.VirtualLight: the sun's image, a volumetric lamp's) is scattered as theirs
// is, where it comes out of its exit's outline (virtual_light_ways.glsl), in its own shadow
// map.  The texel's ray is that of the first pixel of its ``ratio`` x ``ratio`` block; alpha
// keeps how far it went, which the filter (volumetric_fog_filter.frag) compares.  A mirror or portal view's rays start on its oblique near plane: the surface.
#ifndef VOLUMETRIC_LAMPS
#define VOLUMETRIC_LAMPS 0
#endif
#include "lights.glsl"
#include "shadows.glsl"
#include "fog.glsl"
#include "volumetric_ray.glsl"
#ifdef CAUSTICS  // a water's caustics: the sun's light at each point under it, gathered by its waves
#include "water_waves.glsl"
#include "ripples.glsl"
#include "caustics.glsl"
#endif
#ifdef CLOUD_SHADOWS  // a CloudLayer's shadows: the sun's light at each point through the cloud on its way
#include "clouds.glsl"
uniform int cloud_stride;    // the steps between two reads of the clouds' share (engine/render/clouds.py cloud_stride)
#endif
#ifdef VIRTUAL_LIGHTS  // light through mirrors and portals: the images of the lights the shafts scatter
#include "virtual_light_ways.glsl"
uniform float virtual_scatter[MAX_VIRTUAL_LIGHTS];  // each image's share: its light's (0: it lights no air)
#endif
#ifdef LEVEL_VIEWS  // a mirror or portal level's: drawn once a view, over its own pixels only
#include "level_nodes.glsl"
uniform uint node;  // the view's node (its pixels' value in the level's node image)
#endif

uniform int sky_light;       // the sun's or the moon's slot in the Lights block (-1: neither lights the air)
uniform int ratio;           // the view's pixels a march texel, each way (2 at half resolution)
uniform float scatter;       // VolumetricFog.intensity
uniform vec3 albedo;         // VolumetricFog.albedo: the share of each colour scattered
uniform float anisotropy;    // VolumetricFog.anisotropy: the phase function's g
uniform float frame_offset;  // added to each texel's start (a new one each frame under temporal AA)
uniform vec4 map_tiles[MAX_DIRECTIONAL_LIGHTS];  // each directional light's level map in the atlas:
                                                 // corner u, v and side (0: it casts no shadow)
#if VOLUMETRIC_LAMPS > 0
uniform ivec4 lamp_slots;    // the lamps the shafts scatter: their slots in the Lights block
uniform vec4 lamp_scatter;   // ... and each one's PointLight.volumetric
#endif

out vec4 out_light;  // rgb: the light the air sends towards the eye, a: the ray's length (metres)

// Jimenez's interleaved gradient noise: neighbouring texels' starts far apart.
float interleaved_gradient_noise(vec2 p) {
    return fract(52.9829189 * fract(dot(p, vec2(0.06711056, 0.00583715))));
}

// The share of light scattered through an angle whose cosine is ``c`` (per steradian).
float henyey_greenstein(float c, float g) {
    float k = 1.0 + g * g - 2.0 * g * c;
    return (1.0 - g * g) / (4.0 * 3.14159265 * k * sqrt(k));
}

void main() {
    ivec2 pixel = min(ivec2(gl_FragCoord.xy) * ratio, ivec2(depth_size) - 1);
#ifdef LEVEL_VIEWS
    if (node_at(vec2(pixel)) != node) discard;   // another view's pixel: another world
#endif
    vec3 origin, dir;
    float reach;
    volumetric_ray(pixel, origin, dir, reach);
    int sun = sky_light;        // ("the sun" below: the sun or the moon, whichever lights the air)
    int lit_by = max(sun, 0);  // (a slot to read where there is none: its light counts 0)
    vec3 towards = -lights.directional_dir[lit_by].xyz;
    float step_length = reach / float(STEPS);
    float start = fract(interleaved_gradient_noise(gl_FragCoord.xy) + frame_offset);
    // What reaches the eye of the light scattered at each point: exact to the first, then
    // carried from point to point by the air between them (one exponential a step; the
    // density at a point times the step, exact where the fog is the same everywhere).
    vec3 x = origin + dir * (start * step_length);
    FogDepth seen = exp(-fog_depth(origin, x));   // (in each channel in FOG_TINTED builds: fog.glsl)
    FogDepth sum = FogDepth(0.0);
#ifdef DIRECTIONAL_SHADOWS
    // The sun's shadow where its level map holds the point and the filter's taps about it,
    // else 1 (outside the map's fit no caster stands between the point and the sun; the
    // atlas's other tiles there are other maps, and texels no map wrote).  The point's
    // coordinates in the map step along with it (they are affine in the point); it is moved
    // off towards the sun by half the filter's reach.
    vec4 params = shadows.directional_params[lit_by];
    mat4 to_map = shadows.directional_matrix[lit_by];
    vec3 at = (to_map * vec4(x, 1.0)).xyz;
    vec3 at_step = mat3(to_map) * (dir * step_length);
    vec3 along = mat3(to_map) * towards;
    float grazing = 0.5 * (1.0 + params.y);
    vec4 tile = map_tiles[lit_by];
    float margin = (params.y + 2.0) * params.z;   // the filter's reach and the offset, in uv
    vec2 low = tile.xy + margin, high = tile.xy + tile.z - margin;
    bool casts = sun >= 0 && params.w != 0.0 && tile.z > 0.0;
#endif
#ifdef CLOUD_SHADOWS
    // The clouds' share read every cloud_stride steps and taken linearly between (their finest
    // octave spans many strides, so the line between two reads is the share within a few
    // thousandths): the march's noise divided by the stride.
    vec3 cloud_step = dir * (step_length * float(cloud_stride));
    vec3 cloud_at = x;
    float cloud_from = cloud_shadow(cloud_at, towards);
    float cloud_to = cloud_shadow(cloud_at + cloud_step, towards);
#endif
#if VOLUMETRIC_LAMPS > 0
    // The lamps the shafts scatter (PointLight.volumetric): each one's light at the point
    // (its falloff and cone, its cookie's colour, its shadow where it casts, looked up with
    // no offset: the air has no surface to lift the lookup off), by the phase function of
    // the angle between its light and the ray, times its own share.
    vec3 lamp_sum = vec3(0.0);
#endif
#ifdef VIRTUAL_LIGHTS
    // The lights' images through mirrors and portals, as the lamps: each one's light where
    // the line towards it comes out of its exit (else none), its falloff, cone and cookie (a
    // lamp's image), its own map's shadow (no offset), a water's body on its way, by the
    // phase function of the angle to it, times its light's share.
    vec3 image_sum = vec3(0.0);
#endif
    // The steps a stride at a time (the clouds' share read once a stride: a loop of its own,
    // as llvmpipe runs a branch's body for every step whether or not any pixel takes it).
#ifdef CLOUD_SHADOWS
    int stride = cloud_stride;
#else
    int stride = STEPS;
#endif
    for (int base = 0; base < STEPS; base += stride) {
#ifdef CLOUD_SHADOWS
        if (base > 0) {
            cloud_at += cloud_step;
            cloud_from = cloud_to;
            cloud_to = cloud_shadow(cloud_at + cloud_step, towards);
        }
#endif
        int end = min(base + stride, STEPS);
        for (int i = base; i < end; ++i) {
            FogDepth density = fog_extinction(x);
            FogDepth lit = FogDepth(1.0);
#ifdef DIRECTIONAL_SHADOWS
            bool held = casts && all(greaterThanEqual(at.xy, low)) && all(lessThanEqual(at.xy, high));
            lit = FogDepth(held ? directional_shadow_at(lit_by, params, at, along, grazing) : 1.0);
#ifdef SEE_THROUGH_SHADOWS   // (the share of it the see-through things over the point let through)
            lit *= held ? see_through_in_map(at) : 1.0;
#endif
            at += at_step;
#endif
#ifdef CLOUD_SHADOWS
            lit *= mix(cloud_from, cloud_to, float(i - base) / float(cloud_stride));
#endif
#ifdef FOG_WATER
            lit *= water_light(x, towards, 1e30);   // (under a water's body: the light down through it)
#endif
#ifdef CAUSTICS
            for (int w = 0; w < caustic_held.x; ++w)   // (the shafts under rippled water: its caustics)
                lit *= caustic_light(w, x, towards, 0.0);
#endif
            sum += density * seen * lit;
#if VOLUMETRIC_LAMPS > 0
            vec4 lamp_lit = point_shadows(x, vec3(0.0));
            vec3 lamps = vec3(0.0);
            for (int k = 0; k < VOLUMETRIC_LAMPS; ++k) {
                int j = lamp_slots[k];
                vec3 d = lights.point_pos[j].xyz - x;
                float dist = length(d);
                vec3 l = d / max(dist, 1e-4);
#ifdef SPOT_COOKIES  // its image, as sharp as it is (the steps' offsets and the filter blur it)
                vec3 cookie = cookie_light(cookie_place(lights.point_cookie_u[j], lights.point_cookie_v[j],
                                                        lights.point_spot[j], l), vec2(0.0), vec2(0.0));
#else
                vec3 cookie = vec3(1.0);
#endif
#ifdef PANEL_PICTURES
                cookie *= face_mean(lights.point_rect_v[j]);   // (a panel's picture: its mean colour)
#endif
#ifdef CAUSTIC_LAMPS
                for (int c = 0; c < 4; ++c) {   // (a lamp over rippled water: the columns its waves gather)
                    if (caustic_lamps[c] != j) continue;
                    for (int w = 0; w < caustic_held.x; ++w)
                        cookie *= caustic_lamp_light(w, x, lights.point_pos[j].xyz, lights.point_color[j].w,
                                                     lights.point_rect_u[j], lights.point_rect_v[j], 0.0);
                }
#endif
                lamps += lights.point_color[j].rgb * cookie * (lamp_scatter[k] * lamp_falloff(j, dist, l)
                         * henyey_greenstein(dot(dir, l), anisotropy) * point_shadow(j, lamp_lit)
                         * water_light(x, l, dist));   // (1 but in FOG_WATER builds: a water's body on the way)
            }
            lamp_sum += lamps * (density * seen);
#endif
#ifdef VIRTUAL_LIGHTS
            vec3 images = vec3(0.0);
            for (int k = 0; k < virtual_lights.virtual_count.x; ++k) {
                vec3 l;
                float dist;
                float falloff = virtual_falloff(k, x, l, dist) * virtual_scatter[k];
                if (falloff <= 0.0 || !virtual_comes_through(k, x, l, dist)) continue;
#ifdef SPOT_COOKIES
                vec3 cookie = cookie_light(cookie_place(virtual_lights.virtual_cookie_u[k],
                                                        virtual_lights.virtual_cookie_v[k],
                                                        virtual_lights.virtual_spot[k], l), vec2(0.0), vec2(0.0));
#else
                vec3 cookie = vec3(1.0);
#endif
#ifdef CAUSTICS
                // (the sun's image in a rippled water: the light its waves throw up, virtual_lights.glsl's)
                int caustic = int(virtual_lights.virtual_v[k].w) - 1;
                if (caustic >= 0) cookie *= caustic_reflected_light(caustic, x, reflect(l, caustic_plane[caustic].xyz), 0.0);
#endif
                images += virtual_lights.virtual_color[k].rgb * cookie * virtual_kept(k, x, l, dist)
                          * (falloff * henyey_greenstein(dot(dir, l), anisotropy) * virtual_shadow(k, x, vec3(0.0), l, dist));
            }
            image_sum += images * (density * seen);
#endif
            seen *= exp(-density * step_length);
            x += dir * step_length;
        }
    }
    float phase = henyey_greenstein(dot(dir, towards), anisotropy);
    vec3 sun_light = sun >= 0 ? lights.directional_color[lit_by].rgb * (phase * sum) : vec3(0.0);
#if VOLUMETRIC_LAMPS > 0
    sun_light += lamp_sum;
#endif
#ifdef VIRTUAL_LIGHTS
    sun_light += image_sum;
#endif
    out_light = vec4(sun_light * albedo * (scatter * step_length), reach);
}
