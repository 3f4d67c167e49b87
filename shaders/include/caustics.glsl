// Caustics under a water (components/water.py Water.caustics; CAUSTICS builds of the scene;
// engine/render/caustics.py writes the block and owns the rules, tests/test_caustics.py
// holds them against a ray tracer).  The sun's light through a rippled surface is bent
// by each wave and gathers where the bent rays converge: what reaches a point under the
// water is the light through a patch of surface spread over the patch of floor it lands on,
// so the point's light is the flat water's times the ratio of the two areas, 1 / |det J|,
// J the derivative of where the rays land with respect to where they crossed (the Jacobian
// of the refraction map, as in Evan Wallace's WebGL water; here evaluated per shaded point
// from the waves' normal map, not by a mesh of rays).
//
// For a point x at depth h under the plane: the surface point s its light came through is
// found by fixed-point iteration s <- x' - D(s) (x' is x on the plane, D(s) the sideways
// offset of the bent ray from s down to depth h), started from the flat surface's ray, then
// J from D half a step either side of s along each axis of the surface.  The step is the
// largest of a map texel, the sun's disc at that depth (CAUSTIC_SUN_SPREAD x h: the sun is no
// point, so a caustic blurs with its depth) and the pixel's footprint (a far floor shows the
// caustics' mean over its pixel, not a shimmer of samples).  Outside the water's outline,
// above its plane or deeper than its body (Water.depth), the light is the flat water's: 1.
// Deeper than where the bent rays first cross (the focal depth) a point is lit through
// several places on the surface and the search finds one: the net stays, its brightness
// there is that branch's, not the sum's.
// Up to MAX_CAUSTIC_WATERS waters (a define the block's owner gives), by entity; a draw names
// the ones its batch reaches into (caustic_waters).  A lamp's light is gathered the same way
// (caustic_lamp_light, CAUSTIC_LAMPS builds: up to four lamps over a held water, caustic_lamps),
// its rays fanning out from it: the ratio is the flat water's spread over the waves'; and the
// light a water that reflects light throws back up, the sun's and a lamp's
// (caustic_reflected_light, caustic_reflected_lamp_light: virtual_lights.glsl).
layout(std140) uniform Caustics {
    vec4 caustic_plane[MAX_CAUSTIC_WATERS];   // xyz: the water's up normal (out of its top), w: its plane's d
    vec4 caustic_u[MAX_CAUSTIC_WATERS];       // the mirror's UV u as dot(xyz, p) + w (the UV square, before tiling)
    vec4 caustic_v[MAX_CAUSTIC_WATERS];       // ... and v
    vec4 caustic_axis_u[MAX_CAUSTIC_WATERS];  // xyz: the unit world direction of +U on the surface, w: the second layer's share
    vec4 caustic_axis_v[MAX_CAUSTIC_WATERS];  // xyz: +V, w: normal_scale
    vec4 caustic_flow[MAX_CAUSTIC_WATERS];    // xy: the waves' offset (Water.offset), z: 1 / ior, w: strength (Water.caustics)
    vec4 caustic_sizes[MAX_CAUSTIC_WATERS];   // x: tiling, y: a map texel in metres, z: the body's depth, w: the sun's spread (radians)
    ivec4 caustic_held;                       // x: how many waters the block holds
    ivec4 caustic_lamps;                      // the Lights block's slots of the lamps over a held water, -1 after
};
// Each water's normal map (Material.normal_map) a layer, at one size (engine/render/caustics.py CausticMaps).
uniform sampler2DArray caustic_maps;

#define CAUSTIC_MAX_FOCUS 16.0   // the most a caustic gathers (1 / |det J| where rays cross)
// Turns of the search for the crossing: each shrinks its error by |1 - J| (measured against
// tests/test_caustics.py's tracer: two left the brightest lines a texel off, four do not).
#define CAUSTIC_ITERATIONS 4

// The normal of water w's waves at surface point s (its map read at mip ``lod``), and, in
// RIPPLES builds, its ripples' (ripples.glsl: the height field's slope there, if it ripples).
vec3 caustic_normal(int w, vec3 s, float lod) {
    vec2 uv = vec2(dot(caustic_u[w].xyz, s) + caustic_u[w].w, dot(caustic_v[w].xyz, s) + caustic_v[w].w)
              * caustic_sizes[w].x;
    vec2 slope = water_slope_lod(caustic_maps, float(w), uv, lod, caustic_flow[w].xy, caustic_axis_u[w].w);
    vec3 tilted = (caustic_axis_u[w].xyz * slope.x + caustic_axis_v[w].xyz * slope.y) * caustic_axis_v[w].w
                  + caustic_plane[w].xyz;
#ifdef RIPPLES
    tilted -= ripple_gradient(s);
#endif
    return normalize(tilted);
}

// The sideways offset (along the plane) of the light met at surface point s of water w,
// coming from the unit direction l (towards the light), on its way to h metres from the
// plane: down through the water, refracted (``reflected`` false), or back up off it,
// reflected (true).  (Called with a constant ``reflected``: each build keeps one way.)
vec3 caustic_offset(int w, vec3 s, vec3 l, float h, float lod, bool reflected) {
    vec3 up = caustic_plane[w].xyz;
    vec3 n = caustic_normal(w, s, lod);
    vec3 t = reflected ? reflect(-l, n) : refract(-l, n, caustic_flow[w].z);
    vec3 along = reflected ? up : -up;   // the way the light leaves the surface
    float away = max(dot(along, t), 0.05);
    return (t - along * away) * (h / away);
}

// The share of the flat water's light from the direction l (unit, towards the light) that
// reaches x, h metres from water w's plane on the side the light leaves it by (under it,
// ``reflected`` false; over it, true): 1 / |det J| mixed in by the strength (1: all of
// it), 1 off the water or past its reach; over ``footprint`` metres at least (the pixel's).
float caustic_gather(int w, vec3 x, vec3 l, float footprint, bool reflected) {
    vec3 up = caustic_plane[w].xyz;
    vec3 along = reflected ? up : -up;
    float h = dot(along, x) + (reflected ? caustic_plane[w].w : -caustic_plane[w].w);
    if (h <= 0.0 || h > caustic_sizes[w].z || dot(l, up) <= 0.0) return 1.0;
    vec3 on_plane = x - along * h;
    vec3 t0 = reflected ? reflect(-l, up) : refract(-l, up, caustic_flow[w].z);
    vec3 s = on_plane - (t0 - along * dot(along, t0)) * (h / dot(along, t0));   // the flat water's crossing
    vec2 uv0 = vec2(dot(caustic_u[w].xyz, s) + caustic_u[w].w, dot(caustic_v[w].xyz, s) + caustic_v[w].w);
    if (any(lessThan(uv0, vec2(0.0))) || any(greaterThan(uv0, vec2(1.0)))) return 1.0;
    // The surface's two axes, the second made square to the first (J's frame).
    vec3 e1 = caustic_axis_u[w].xyz;
    vec3 e2 = normalize(caustic_axis_v[w].xyz - dot(caustic_axis_v[w].xyz, e1) * e1);
    float stride = max(max(caustic_sizes[w].y, h * caustic_sizes[w].w), footprint);
    float lod = log2(stride / caustic_sizes[w].y);   // (the map's texels a step spans, along U)
    for (int k = 0; k < CAUSTIC_ITERATIONS; ++k) s = on_plane - caustic_offset(w, s, l, h, lod, reflected);
    // (central differences: the derivative at s itself, not half a step on)
    vec3 half1 = e1 * (0.5 * stride), half2 = e2 * (0.5 * stride);
    vec3 d1 = caustic_offset(w, s + half1, l, h, lod, reflected) - caustic_offset(w, s - half1, l, h, lod, reflected);
    vec3 d2 = caustic_offset(w, s + half2, l, h, lod, reflected) - caustic_offset(w, s - half2, l, h, lod, reflected);
    float det = (1.0 + dot(d1, e1) / stride) * (1.0 + dot(d2, e2) / stride) - dot(d1, e2) / stride * (dot(d2, e1) / stride);
    return mix(1.0, 1.0 / max(abs(det), 1.0 / CAUSTIC_MAX_FOCUS), caustic_flow[w].w);
}

// Under water w: the share of the flat water's light from l (towards the light) the waves
// gather at x (caustic_gather, refracted).
float caustic_light(int w, vec3 x, vec3 l, float footprint) {
    return caustic_gather(w, x, l, footprint, false);
}

// Over water w: the share of the light it reflects from l (towards the light: the sun, not
// its image) that its waves gather at x (caustic_gather, reflected), up to its depth over it:
// the bright net a sunlit pool throws on the walls and ceilings over it
// (virtual_lights.glsl, for a water that reflects light).
float caustic_reflected_light(int w, vec3 x, vec3 l, float footprint) {
    return caustic_gather(w, x, l, footprint, true);
}

// The share of a lamp's light that the waves of water w gather at x (the lamp at ``lamp``,
// world, over the water; ``radius`` its sphere's, which blurs the net as the sun's disc does):
// under the water (``reflected`` false) through it, or over it (true) thrown back up off
// it; the flat water's spread of the lamp's rays at x over the waves' (|det J_flat| / |det J|:
// its rays fan out off or through a flat surface too), mixed in by the strength; 1 off the
// water, past its depth under or over it, or with the lamp under it.  The flat water's
// crossing lies on the line from the lamp's foot through x's: thrown up, on the straight
// line from the lamp's image (its stretch (a + h) / a both ways); through the water, where
// Snell's law puts it (symmetric about that line: Newton's method on r + h tan t = R), and
// J_flat there in closed form (across the line its stretch is R / r); the waves' crossing
// then by the chord method with J_flat (the sun's fixed-point search, whose J_flat is 1),
// from the flat one.  (Called with a constant ``reflected``: each build keeps one way.)
float caustic_lamp_gather(int w, vec3 x, vec3 lamp, vec2 radius, float footprint, bool reflected) {
    vec3 up = caustic_plane[w].xyz;
    vec3 along = reflected ? up : -up;   // the way the light leaves the surface
    float h = reflected ? dot(up, x) + caustic_plane[w].w : -(dot(up, x) + caustic_plane[w].w);
    float a = dot(up, lamp) + caustic_plane[w].w;   // the lamp's height over the plane
    if (h <= 0.0 || h > caustic_sizes[w].z || a <= 1e-4) return 1.0;
    float eta = caustic_flow[w].z;
    vec3 on_plane = x - along * h;
    vec3 foot = lamp - up * a;
    vec3 outward = on_plane - foot;
    float far_out = length(outward);   // R
    vec3 radial = far_out > 1e-6 ? outward / far_out : caustic_axis_u[w].xyz;
    vec3 across = cross(up, radial);
    float r = far_out * a / (a + h);   // the straight line's crossing
    float stretch_along = (a + h) / a;
    if (!reflected) {
        for (int k = 0; k < 5; ++k) {
            float hyp = sqrt(r * r + a * a);
            float sin_t = r / hyp * eta;
            float cos_t = sqrt(max(1.0 - sin_t * sin_t, 1e-6));
            stretch_along = 1.0 + h * (a * a / (hyp * hyp * hyp) * eta) / (cos_t * cos_t * cos_t);
            r = max(r - (r + h * sin_t / cos_t - far_out) / stretch_along, 0.0);
        }
        float hyp = sqrt(r * r + a * a);   // (the stretch where the search ended)
        float sin_t = r / hyp * eta;
        float cos_t = sqrt(max(1.0 - sin_t * sin_t, 1e-6));
        stretch_along = 1.0 + h * (a * a / (hyp * hyp * hyp) * eta) / (cos_t * cos_t * cos_t);
    }
    float stretch_across = r > 1e-4 * (a + h) ? far_out / r : stretch_along;
    vec3 s = foot + radial * r;
    vec2 uv0 = vec2(dot(caustic_u[w].xyz, s) + caustic_u[w].w, dot(caustic_v[w].xyz, s) + caustic_v[w].w);
    if (any(lessThan(uv0, vec2(0.0))) || any(greaterThan(uv0, vec2(1.0)))) return 1.0;
    vec3 e1 = caustic_axis_u[w].xyz;
    vec3 e2 = normalize(caustic_axis_v[w].xyz - dot(caustic_axis_v[w].xyz, e1) * e1);
    // The lamp's size seen from the surface, along each axis (caustic_lamp_radius): the steps.
    vec2 spread = h * radius / max(length(lamp - s), 1e-3);
    vec2 stride = max(max(vec2(caustic_sizes[w].y), spread), vec2(footprint));
    float lod = log2(min(stride.x, stride.y) / caustic_sizes[w].y);   // (the longer step's differences blur the rest)
    for (int k = 0; k < CAUSTIC_ITERATIONS; ++k) {
        vec3 miss = s + caustic_offset(w, s, normalize(lamp - s), h, lod, reflected) - on_plane;
        s -= radial * (dot(radial, miss) / stretch_along) + across * (dot(across, miss) / stretch_across);
    }
    vec3 half1 = e1 * (0.5 * stride.x), half2 = e2 * (0.5 * stride.y);
    vec3 d1 = caustic_offset(w, s + half1, normalize(lamp - s - half1), h, lod, reflected)
              - caustic_offset(w, s - half1, normalize(lamp - s + half1), h, lod, reflected);
    vec3 d2 = caustic_offset(w, s + half2, normalize(lamp - s - half2), h, lod, reflected)
              - caustic_offset(w, s - half2, normalize(lamp - s + half2), h, lod, reflected);
    float det = (1.0 + dot(d1, e1) / stride.x) * (1.0 + dot(d2, e2) / stride.y)
                - dot(d1, e2) / stride.x * (dot(d2, e1) / stride.y);
    float flat_det = stretch_along * stretch_across;
    return mix(1.0, flat_det / max(abs(det), flat_det / CAUSTIC_MAX_FOCUS), caustic_flow[w].w);
}

// How far a lamp's light comes from about its centre along each axis of water w's surface
// (+U, +V), as the radius of a sphere that spreads as much along it: a sphere's ``sphere``
// itself; a rectangle's (half sides ``rect_u``.xyz and ``rect_v``.xyz: lights.glsl's
// point_rect_u / _v rows) or a tube's (its half length in rect_u, its radius in rect_v.w)
// the radius whose sphere's light has the same mean square offset along the axis (a side's
// uniform light |U.e|^2 / 3, a disc's R^2 / 4), so a panel's or a tube's net blurs as far
// along each axis as its light spreads: along a tube, not across it.
vec2 caustic_lamp_radius(int w, float sphere, vec4 rect_u, vec4 rect_v) {
    vec3 e1 = caustic_axis_u[w].xyz;
    vec3 e2 = normalize(caustic_axis_v[w].xyz - dot(caustic_axis_v[w].xyz, e1) * e1);
    float tube = max(rect_v.w, 0.0);   // (a rectangle's w is 0, or its face's image: below 0)
    vec2 square = vec2(dot(rect_u.xyz, e1) * dot(rect_u.xyz, e1) + dot(rect_v.xyz, e1) * dot(rect_v.xyz, e1),
                       dot(rect_u.xyz, e2) * dot(rect_u.xyz, e2) + dot(rect_v.xyz, e2) * dot(rect_v.xyz, e2))
                  + tube * tube;
    return max(vec2(sphere), sqrt(square * (4.0 / 3.0)));
}

// A lamp's light under water w (caustic_lamp_gather through it): CAUSTIC_LAMPS builds, up
// to four lamps over a held water (caustic_lamps); ``sphere``, ``rect_u``, ``rect_v`` its
// shape (caustic_lamp_radius).
float caustic_lamp_light(int w, vec3 x, vec3 lamp, float sphere, vec4 rect_u, vec4 rect_v, float footprint) {
    return caustic_lamp_gather(w, x, lamp, caustic_lamp_radius(w, sphere, rect_u, rect_v), footprint, false);
}

// Over water w: the share of a lamp's light it reflects that its waves gather at x
// (caustic_lamp_gather thrown up): the net a lamp over a pool throws on the ceiling over it
// (virtual_lights.glsl, the lamp's image in a water that reflects light; its shape's rows
// are the image's, whose sides along the surface are the lamp's).
float caustic_reflected_lamp_light(int w, vec3 x, vec3 lamp, float sphere, vec4 rect_u, vec4 rect_v,
                                   float footprint) {
    return caustic_lamp_gather(w, x, lamp, caustic_lamp_radius(w, sphere, rect_u, rect_v), footprint, true);
}
