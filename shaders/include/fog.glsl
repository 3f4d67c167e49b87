// Exponential height fog (components/fog.py Fog, the active camera's; engine/render/fog.py
// writes the block).  The air's density is d exp(-k (y - h)) per metre: d at height h, falling
// by e every 1 / k metres above it (k = 0: the same everywhere).  Along a straight stretch
// from a to b its optical depth has a closed form, d exp(-k (a.y - h)) |b - a| (1 - e^-x) / x
// with x = k (b.y - a.y) (the integral of the density along the stretch), and what is seen
// at b keeps exp(-depth) of its light, the rest becoming the fog's colour.
//
// Each stretch of a light's way is fogged where it is drawn: a view fogs from where its rays
// enter it (its eye, or for a mirror or portal view the surface it looks out of: its clip
// plane) to each surface it shows (fog_view); a composite fogs the stretch of its parent view
// from the parent's start to the surface (fog_depth, fogged: mirror_composite.frag), over the
// reflection as a whole, and the sky a view leaves to its composite from the surface
// outwards (fog_sky).  Fog over a
// way in pieces is the fog over the whole way: exp(-(t1 + t2)) = exp(-t1) exp(-t2), and what
// the nearer piece adds covers what the farther one left.  Only FOG builds (while the active
// camera's fog has a density: engine/render/fog.py) read the block; in the others each
// function below is the identity and compiles away.  FOG_FALLOFF (a height falloff) and
// FOG_GLOW (sun scatter with a sun) add their terms only where the fog has them: llvmpipe
// runs every exponential for every pixel.
#ifdef FOG
layout(std140) uniform Fog {
    vec4 fog_color;   // rgb: the fog's linear colour; a: how much of its fog the sky takes
    vec4 fog_params;  // x: density at the base height (per metre; 0: none), y: falloff (per metre),
                      // z: the base height, w: unused
    vec4 fog_sun;     // xyz: towards the sun (the brightest directional light)
    vec4 fog_glow;    // rgb: the sun's light x Fog.sun_scatter (0: no glow)
} fog;

#define FOG_MAX_EXPONENT 80.0   // exp(80) ~ 5.5e34: past that the air is opaque anyway

// The fog's optical depth along the straight stretch from a to b (FOG_FALLOFF builds: the
// density changes with height; the others: the same everywhere, density x length).
float fog_depth(vec3 a, vec3 b) {
    float density = fog.fog_params.x;
#ifdef FOG_FALLOFF
    float falloff = fog.fog_params.y;
    float at_a = density * exp(min(-falloff * (a.y - fog.fog_params.z), FOG_MAX_EXPONENT));
    float x = falloff * (b.y - a.y);
    float spread = abs(x) > 1e-4 ? (1.0 - exp(min(-x, FOG_MAX_EXPONENT))) / x : 1.0 - 0.5 * x;
    return at_a * length(b - a) * spread;
#else
    return density * length(b - a);
#endif
}

// The air's density at ``x`` (per metre): what fog_depth sums along a stretch.
float fog_density(vec3 x) {
#ifdef FOG_FALLOFF
    return fog.fog_params.x * exp(min(-fog.fog_params.y * (x.y - fog.fog_params.z), FOG_MAX_EXPONENT));
#else
    return fog.fog_params.x;
#endif
}

// The fog's optical depth from a along the unit direction r to infinity (the sky): finite only
// where the air thins upwards and r climbs.
float fog_depth_to_sky(vec3 a, vec3 r) {
    float density = fog.fog_params.x;
    if (density <= 0.0) return 0.0;
#ifdef FOG_FALLOFF
    float falloff = fog.fog_params.y;
    float at_a = density * exp(min(-falloff * (a.y - fog.fog_params.z), FOG_MAX_EXPONENT));
    return falloff > 0.0 && r.y > 1e-6 ? at_a / (falloff * r.y) : 1e30;
#else
    return 1e30;
#endif
}

// The light the air scatters towards an eye looking along the unit direction ``dir``: the
// fog's colour, and a glow towards the sun (max(cos, 0)^8 of the angle from it).
vec3 fog_light(vec3 dir) {
#ifdef FOG_GLOW
    float towards = max(dot(dir, fog.fog_sun.xyz), 0.0);
    towards *= towards;
    towards *= towards;
    return fog.fog_color.rgb + fog.fog_glow.rgb * (towards * towards);
#else
    return fog.fog_color.rgb;
#endif
}

// ``color`` seen along the unit direction ``dir`` through the fog of optical depth ``depth``.
vec3 fogged(vec3 color, float depth, vec3 dir) {
    return mix(fog_light(dir), color, exp(-depth));
}

// Where a view's rays enter it, on the way to ``p``: its eye, or where the ray from its eye
// to ``p`` crosses ``plane`` (the clip plane of a mirror or portal view: the surface it looks
// out of; a root view's plane is (0, 0, 0, 1), which clips nothing).
vec3 fog_start(vec3 eye, vec4 plane, vec3 p) {
    if (dot(plane.xyz, plane.xyz) == 0.0) return eye;
    float at_eye = dot(plane.xyz, eye) + plane.w;     // behind the plane (the eye is an image)
    float across = at_eye - (dot(plane.xyz, p) + plane.w);
    return across < -1e-12 ? eye + (p - eye) * clamp(at_eye / across, 0.0, 1.0) : eye;
}

// A surface at ``p`` seen in a view whose eye is ``eye`` and clip plane ``plane``.
vec3 fog_view(vec3 color, vec3 eye, vec4 plane, vec3 p) {
    vec3 start = fog_start(eye, plane, p);
    return fogged(color, fog_depth(start, p), normalize(p - eye));
}

// The sky seen from ``a`` along the unit direction ``r``: its share (``fog_color.a``) of the fog.
vec3 fog_sky(vec3 color, vec3 a, vec3 r) {
    return mix(color, fogged(color, fog_depth_to_sky(a, r), r), fog.fog_color.a);
}
#else
float fog_depth(vec3 a, vec3 b) { return 0.0; }
float fog_density(vec3 x) { return 0.0; }
float fog_depth_to_sky(vec3 a, vec3 r) { return 0.0; }
vec3 fogged(vec3 color, float depth, vec3 dir) { return color; }
vec3 fog_view(vec3 color, vec3 eye, vec4 plane, vec3 p) { return color; }
vec3 fog_sky(vec3 color, vec3 a, vec3 r) { return color; }
#endif
