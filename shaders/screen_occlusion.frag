#version 410 core
// Ground-truth ambient occlusion (Jimenez, Wu, Pesce, Jarabo, "Practical Real-Time Strategies
// for Accurate Indirect Occlusion", 2016): the share of the cosine-weighted hemisphere over a
// pixel's surface that no geometry within `radius` hides.  Each of SLICES planes through the
// view direction, turned by a 4 x 4 tile's rotation (the filter after it averages the tile),
// is searched both ways along the screen for its two horizons; the visible arc between them,
// weighted by the cosine to the normal projected into the slice, is integrated in closed form.
// Writes the visibility and the pixel's distance along the view axis (the filter's depth
// test), a texel a pixel of the depth image (half the view's size, or all of it).
// engine/render/screen_occlusion.py runs it.  Built with AMBIENT_OCCLUSION (the camera's
// AmbientOcclusion; without, the visibility is 1) and with CONTACT_SHADOWS (its
// ContactShadows towards the sun: contact_shadow below, into the third channel) and
// CONTACT_LAMPS (towards the lamps that have them, a channel each of the second image).  A reflection level's build
// (LEVEL_VIEWS) is drawn once a view of the level, over its rectangle: it finds the pixels of
// `node` alone, and a sample on another view's pixels ends the search as the image's edge does
// (what lies there is another view's world).
#include "occlusion_geometry.glsl"

#define PI 3.14159265358979
#define HALF_PI 1.57079632679490
#define HALF_MAX 65504.0  // the distance is kept in a half float: a farther one is kept as this

uniform float radius;           // metres (AmbientOcclusion.radius)
uniform float pixels_per_metre; // at a distance of 1 m along the view axis
uniform float max_radius_pixels;
uniform ivec2 margin;           // the guard band: where the view's pixels start in the depth image
#if defined(CONTACT_SHADOWS) || defined(CONTACT_LAMPS)
uniform vec4 contact;           // ContactShadows' length, thickness, opacity and distance
#endif
#ifdef CONTACT_SHADOWS
uniform vec3 sun_view;          // towards the sun, the view's space (unit)
#endif
#ifdef CONTACT_LAMPS
uniform vec4 lamp_view[MAX_CONTACT_LAMPS];  // the lamps with contact shadows (PointLight.contact_shadows):
                                            // xyz where each is in the view's space, w 1 (0: no lamp there)
#endif
#ifdef LEVEL_VIEWS
uniform uint node;              // the level's view found by this draw
#endif

layout(location = 0) out vec4 out_occlusion;  // r: visibility, g: distance along the view axis (-1: the sky),
                                              // b: the sun's share
layout(location = 1) out vec4 out_lamps;      // rgba: each contact lamp channel's share (1 without)

// Whether a sample at `at` (the depth image's pixels) lies off the view: past the image's
// edge, or (a level's) on another view's pixels.
bool off_view(vec2 at) {
    bool outside = any(lessThan(at, vec2(0.0))) || any(greaterThanEqual(at, depth_size));
#ifdef LEVEL_VIEWS
    return outside || node_at(at) != node;
#else
    return outside;
#endif
}

// A 4 x 4 ordered-dither (Bayer) matrix, 0..15: the tile's slice rotations and step offsets.
const float BAYER[16] = float[16](0.0, 8.0, 2.0, 10.0, 12.0, 4.0, 14.0, 6.0,
                                  3.0, 11.0, 1.0, 9.0, 15.0, 7.0, 13.0, 5.0);

#ifdef AMBIENT_OCCLUSION
// The largest cosine, to the view direction v, of the directions from p to the surface
// within `radius` along the screen direction `omega` (pixels), down to `lowest` where nothing
// occludes.  Where the samples cross the radius, the surface between the last sample inside
// and the first outside is taken as straight and the point on it at the radius counts too:
// the horizon is then found at the radius itself, not short of it by up to a step (which
// left creases too light), and it moves smoothly as the geometry does.  Two samples farther
// apart than half the radius lie on different surfaces: nothing is assumed between them.
float horizon_cos(vec3 p, vec3 v, vec2 pixel, vec2 omega, float reach, float jitter, float lowest) {
    float best = lowest;
    vec3 inside = vec3(0.0);    // the last sample within the radius, from p (p itself at first)
    vec3 before = vec3(0.0);    // that sample when the radius was first crossed
    vec3 outside = vec3(0.0);   // the first sample past it
    bool crossed = false;
    float radius2 = radius * radius;
    for (int i = 0; i < STEPS; ++i) {
        float t = (float(i) + jitter) / float(STEPS);
        vec2 at = pixel + omega * (1.0 + t * sqrt(t) * reach);  // nearer samples closer together (t ** 1.5)
        if (off_view(at)) break;
        vec3 delta = position_at(at) - p;
        float gap2 = dot(delta, delta);
        // Selects, not branches: llvmpipe runs both sides of a branch, and the crossing's
        // arithmetic is done once, after the loop.
        bool within = gap2 <= radius2 && gap2 > 1e-12;
        best = within ? max(best, dot(delta, v) * inversesqrt(gap2)) : best;
        bool first_out = !within && !crossed && gap2 > 1e-12;
        before = first_out ? inside : before;
        outside = first_out ? delta : outside;
        crossed = crossed || first_out;
        inside = within ? delta : inside;
    }
    vec3 step_ = outside - before;
    float a = dot(step_, step_);
    if (crossed && a <= 0.25 * radius2) {
        // |before + u step_| = radius for u in [0, 1] (before is within it, outside past it)
        float b = dot(before, step_);
        float u = (-b + sqrt(max(b * b - a * (dot(before, before) - radius2), 0.0))) / a;
        best = max(best, dot(normalize(before + u * step_), v));
    }
    return best;
}

#endif

#if defined(CONTACT_SHADOWS) || defined(CONTACT_LAMPS)
// Contact shadows (ContactShadows; Unreal's and HDRP's): the share of a light's light that
// reaches ``p`` (normal ``n``) from the way ``to_light`` (unit) past what the depth image
// shows.  CONTACT_SAMPLES points along the ray that way, ``reach`` long (the length, or the
// way to a lamp if that is shorter), each set off by ``jitter`` of a step; one behind the
// surface the image shows at its pixel (read bilinearly: a plane's depth there exactly), by
// more than a hair (half a percent of its distance: the image's own rounding) and less than
// ``thickness``, hides the light.  Faded out over the last tenth of ``distance``.
float contact_shadow(vec3 p, vec3 n, vec3 to_light, float reach, float jitter) {
    float fade = clamp((contact.w + p.z) / (0.1 * contact.w), 0.0, 1.0);
    if (fade <= 0.0 || dot(n, to_light) <= 0.0) return 1.0;  // (facing away: the light reaches none of it)
    vec3 start = p + n * (0.002 * -p.z);   // off the surface by a hair, as the shadow maps' normal offset
    float hidden = 0.0;
    for (int i = 0; i < CONTACT_SAMPLES; ++i) {
        vec3 s = start + to_light * ((float(i) + jitter) / float(CONTACT_SAMPLES) * reach);
        vec2 at = view_pixel(s);
        if (s.z >= 0.0 || off_view(at)) break;
        float behind = surface_z(at) - s.z;
        hidden = behind > 0.005 * -s.z && behind < contact.y ? 1.0 : hidden;
    }
    return 1.0 - contact.z * fade * hidden;
}
#endif

// The share of the light from all round that reaches ``p`` (GTAO; 1 without AMBIENT_OCCLUSION).
float ambient_visibility(vec3 p, vec3 v, vec3 n, vec2 centre, int tile, float jitter) {
#ifndef AMBIENT_OCCLUSION
    return 1.0;
#else
    // The reach on the screen: the radius as seen half way from the point's depth to the
    // nearest its sphere comes to the eye.  Occluders nearer the eye than the point (the floor
    // in front of a wall) lie farther out on the screen than the radius at the point's own
    // depth: seen there, a wall's foot kept 0.035 too much of its light.
    float reach = min(radius * pixels_per_metre / max(-p.z - 0.5 * radius, 0.5 * -p.z), max_radius_pixels);
    if (reach < 1.0) return 1.0;  // the radius spans under a pixel: nothing to find
    float rotation = (BAYER[tile] + 0.5) / 16.0;
    float visibility = 0.0;
    for (int s = 0; s < SLICES; ++s) {
        float phi = (float(s) + rotation) * PI / float(SLICES);
        vec2 omega = vec2(cos(phi), sin(phi));
        vec3 direction = vec3(omega, 0.0);  // the slice's screen direction in view space
        vec3 ortho = direction - dot(direction, v) * v;
        vec3 axis = normalize(cross(ortho, v));
        vec3 projected = n - axis * dot(n, axis);  // the normal in the slice's plane
        float projected_length = length(projected);
        if (projected_length < 1e-4) continue;
        float cos_n = clamp(dot(projected, v) / projected_length, 0.0, 1.0);
        float angle_n = sign(dot(ortho, projected)) * acos(cos_n);
        float cos_h1 = horizon_cos(p, v, centre, omega, reach - 1.0, jitter, cos(angle_n + HALF_PI));
        float cos_h0 = horizon_cos(p, v, centre, -omega, reach - 1.0, jitter, cos(angle_n - HALF_PI));
        float h0 = angle_n + max(-acos(clamp(cos_h0, -1.0, 1.0)) - angle_n, -HALF_PI);
        float h1 = angle_n + min(acos(clamp(cos_h1, -1.0, 1.0)) - angle_n, HALF_PI);
        float sin_n = sin(angle_n);
        float arc0 = cos_n + 2.0 * h0 * sin_n - cos(2.0 * h0 - angle_n);
        float arc1 = cos_n + 2.0 * h1 * sin_n - cos(2.0 * h1 - angle_n);
        visibility += projected_length * 0.25 * (arc0 + arc1);
    }
    return clamp(visibility / float(SLICES), 0.0, 1.0);
#endif
}

void main() {
    ivec2 texel = ivec2(gl_FragCoord.xy);  // this image's (the view's pixels)
    ivec2 pixel = texel + margin;          // the depth image's (the guard band about them)
    vec2 centre = vec2(pixel) + 0.5;
#ifdef LEVEL_VIEWS
    if (node_at(centre) != node) discard;  // another view's pixel (its own draw finds it)
#endif
    vec4 geometry = texelFetch(geometry_map, pixel, 0);
    if (geometry.w <= 0.0) {  // nothing drawn: the sky
        out_occlusion = vec4(1.0, -1.0, 1.0, 1.0);
        out_lamps = vec4(1.0);
        return;
    }
    vec3 p = view_at(centre, -1.0 / geometry.w);
    vec3 v = normalize(-p);
    vec3 n = normalize(geometry.xyz);
    int tile = (texel.x & 3) + 4 * (texel.y & 3);
    float jitter = (BAYER[15 - tile] + 0.5) / 16.0;
#ifdef CONTACT_SHADOWS
    float sun = contact_shadow(p, n, sun_view, contact.x, jitter);
#else
    float sun = 1.0;
#endif
    out_lamps = vec4(1.0);
#ifdef CONTACT_LAMPS
    for (int i = 0; i < MAX_CONTACT_LAMPS; ++i) {  // (a channel each of the rgba: at most 4)
        vec3 way = lamp_view[i].xyz - p;
        float far = length(way);
        out_lamps[i] = lamp_view[i].w > 0.0 && far > 1e-4 ? contact_shadow(p, n, way / far, min(contact.x, far), jitter)
                                                        : 1.0;
    }
#endif
    out_occlusion = vec4(ambient_visibility(p, v, n, centre, tile, jitter), min(-p.z, HALF_MAX), sun, 1.0);
}
