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
//
// Local fog volumes (components/fog.py FogVolume; FOG_VOLUMES builds, its value how many):
// ellipsoids of air, each density_k (1 - r^2) at r, its distance from the centre over its
// radius that way (0 outside).  Along a line p + t v in its unit ball (v per metre) that is
// disc / A - A u^2 (A = v.v, disc = (p.v)^2 - A (p.p - 1), u = t less the closest approach),
// so its optical depth over the chord's part [u0, u1] is disc / A (u1 - u0) - A (u1^3 - u0^3) / 3,
// in closed form and without the cancellation of the expanded cubic far off.  Each stretch's
// fog is the height fog's and every volume's: its depth their sum, what the air adds their
// colours weighed by their depths (fog_way: exact where they share a colour, a blend where
// not, whichever lies nearer).  An optical depth is a colour in FOG_TINTED builds (while a
// water's body takes its channels apart, Water.absorption): a volume's density in each
// channel is its density times that channel's share (volume_absorption; a mist's 1 in each),
// so water seen through, and light come down through it, keeps more of one colour than
// another (the height fog takes every channel alike).  In the other builds it is one number
// for every channel (FogDepth: llvmpipe runs a vec3's exponential three times over, and the
// fogged examples' frames cost 3-4% more so).
#ifdef FOG_TINTED
#define FogDepth vec3
#define FOG_SHARE(k) fog.volume_absorption[k].rgb
#else
#define FogDepth float
#define FOG_SHARE(k) 1.0
#endif
#ifdef FOG
layout(std140) uniform Fog {
    vec4 fog_color;   // rgb: the fog's linear colour; a: how much of its fog the sky takes
    vec4 fog_params;  // x: density at the base height (per metre; 0: none), y: falloff (per metre),
                      // z: the base height, w: the share of its colour that is the sky's (aerial perspective)
    vec4 fog_sun;     // xyz: towards the sun (the brightest directional light)
    vec4 fog_glow;    // rgb: the sun's light x Fog.sun_scatter (0: no glow)
    mat4 volume_to_unit[MAX_FOG_VOLUMES];  // world -> each FogVolume's unit ball (engine/render/fog.py)
    vec4 volume_color[MAX_FOG_VOLUMES];    // rgb: its linear colour, a: its density at the centre (per metre)
    vec4 volume_absorption[MAX_FOG_VOLUMES];  // rgb: each channel's share of that density (FOG_TINTED builds)
} fog;

// A stretch of air: its optical depth (in each channel, FOG_TINTED), and the light it adds
// times that depth (each fog's light times its own depth: the weights fog_over divides out).
struct FogWay {
    vec3 light;
    FogDepth depth;
};

#define FOG_MAX_EXPONENT 80.0   // exp(80) ~ 5.5e34: past that the air is opaque anyway

// The height fog's optical depth along the straight stretch from a to b (FOG_FALLOFF builds:
// the density changes with height; the others: the same everywhere, density x length).
float height_fog_depth(vec3 a, vec3 b) {
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

// The height fog's optical depth from a along the unit direction r to infinity (the sky):
// finite only where the air thins upwards and r climbs.
float height_fog_depth_to_sky(vec3 a, vec3 r) {
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

#ifdef FOG_VOLUMES
// The integral of max(1 - |p + t v|^2, 0) over t in [0, reach]: a FogVolume's density (over
// its density at the centre) along a line in its unit ball (above).
float ball_depth(vec3 p, vec3 v, float reach) {
    float a = dot(v, v), b = dot(p, v);
    float disc = b * b - a * (dot(p, p) - 1.0);
    if (disc <= 0.0 || a <= 0.0) return 0.0;
    float half_chord = sqrt(disc) / a, closest = -b / a;
    float u0 = max(-half_chord, -closest), u1 = min(half_chord, reach - closest);
    if (u1 <= u0) return 0.0;
    return disc / a * (u1 - u0) - a * (u1 * u1 * u1 - u0 * u0 * u0) / 3.0;
}

// The length of the line p + t v, t in [0, reach], inside the cube [-1, 1]^3: a water's body
// (Water.fog_density, its row's density negated: the same density throughout), by the slab
// test (v's components kept off 0: the GLSL spec leaves x / 0 undefined).
float box_depth(vec3 p, vec3 v, float reach) {
    vec3 towards = mix(vec3(-1.0), vec3(1.0), greaterThanEqual(v, vec3(0.0)));
    vec3 per_unit = towards / max(abs(v), vec3(1e-12));  // 1 / v, sign kept
    vec3 t0 = (-1.0 - p) * per_unit, t1 = (1.0 - p) * per_unit;
    vec3 lo = min(t0, t1), hi = max(t0, t1);
    float enter = max(max(max(lo.x, lo.y), lo.z), 0.0);
    float leave = min(min(min(hi.x, hi.y), hi.z), reach);
    return max(leave - enter, 0.0);
}

// The volumes' fog along the line from a along the unit direction r for ``reach`` metres:
// their depths in each channel, and their colours times those depths.
FogWay volumes_along(vec3 a, vec3 r, float reach) {
    FogWay sum = FogWay(vec3(0.0), FogDepth(0.0));
    for (int k = 0; k < FOG_VOLUMES; ++k) {
        mat4 to_unit = fog.volume_to_unit[k];
        float density = fog.volume_color[k].a;
        vec3 p = (to_unit * vec4(a, 1.0)).xyz, v = mat3(to_unit) * r;
        FogDepth depth = (density >= 0.0 ? density * ball_depth(p, v, reach) : -density * box_depth(p, v, reach))
                         * FOG_SHARE(k);
        sum.light += fog.volume_color[k].rgb * depth;
        sum.depth += depth;
    }
    return sum;
}

#ifdef FOG_WATER
// What of the light a water's body (Water.fog_density, a volume of negative density) leaves
// on its way to ``x``, in each channel: from along the unit direction r, ``reach`` metres off
// (the suns', 1e30; a lamp's, its distance), exp(-density x the channel's share x the length
// of the way in each body); water_depth: that exponent, for a way of several straight
// stretches (a light through mirrors and portals: virtual_light_ways.glsl virtual_water).
// The ellipsoid volumes (mist) take none: their air is thin.
FogDepth water_depth(vec3 x, vec3 r, float reach) {
    FogDepth depth = FogDepth(0.0);
    for (int k = 0; k < FOG_VOLUMES; ++k) {
        float density = fog.volume_color[k].a;
        if (density >= 0.0) continue;
        mat4 to_unit = fog.volume_to_unit[k];
        depth -= density * box_depth((to_unit * vec4(x, 1.0)).xyz, mat3(to_unit) * r, reach) * FOG_SHARE(k);
    }
    return depth;
}

FogDepth water_light(vec3 x, vec3 r, float reach) {
    return exp(-min(water_depth(x, r, reach), FogDepth(FOG_MAX_EXPONENT)));
}

// What of the sky's light a water's body leaves at ``x``, in each channel: along the way up
// to its surface (the box's top: its unit cube's -w face, the third row of its matrix the way down).
FogDepth water_skylight(vec3 x) {
    FogDepth depth = FogDepth(0.0);
    for (int k = 0; k < FOG_VOLUMES; ++k) {
        float density = fog.volume_color[k].a;
        if (density >= 0.0) continue;
        mat4 to_unit = fog.volume_to_unit[k];
        vec3 up = -normalize(vec3(to_unit[0][2], to_unit[1][2], to_unit[2][2]));
        depth -= density * box_depth((to_unit * vec4(x, 1.0)).xyz, mat3(to_unit) * up, 1e30) * FOG_SHARE(k);
    }
    return exp(-min(depth, FogDepth(FOG_MAX_EXPONENT)));
}
#else  // (no water's body among the volumes: FOG_WATER builds only, engine/render/fog.py)
FogDepth water_depth(vec3 x, vec3 r, float reach) { return FogDepth(0.0); }
FogDepth water_light(vec3 x, vec3 r, float reach) { return FogDepth(1.0); }
FogDepth water_skylight(vec3 x) { return FogDepth(1.0); }
#endif

// The volumes' density at ``x`` in each channel (per metre).
FogDepth volumes_extinction(vec3 x) {
    FogDepth sum = FogDepth(0.0);
    for (int k = 0; k < FOG_VOLUMES; ++k) {
        vec3 p = (fog.volume_to_unit[k] * vec4(x, 1.0)).xyz;
        float density = fog.volume_color[k].a;
        sum += (density >= 0.0 ? density * max(1.0 - dot(p, p), 0.0)
                               : (all(lessThanEqual(abs(p), vec3(1.0))) ? -density : 0.0))
               * FOG_SHARE(k);
    }
    return sum;
}
#else
FogWay volumes_along(vec3 a, vec3 r, float reach) { return FogWay(vec3(0.0), FogDepth(0.0)); }
FogDepth volumes_extinction(vec3 x) { return FogDepth(0.0); }
FogDepth water_depth(vec3 x, vec3 r, float reach) { return FogDepth(0.0); }
FogDepth water_light(vec3 x, vec3 r, float reach) { return FogDepth(1.0); }
FogDepth water_skylight(vec3 x) { return FogDepth(1.0); }
#endif

// The fog's optical depth in each channel along the straight stretch from a to b: the height
// fog's and the volumes'.
FogDepth fog_depth(vec3 a, vec3 b) {
    float reach = length(b - a);
    return height_fog_depth(a, b) + (reach > 0.0 ? volumes_along(a, (b - a) / reach, reach).depth : FogDepth(0.0));
}

// The air's density at ``x`` in each channel (per metre): what fog_depth sums along a stretch,
// and what a light shaft's march scatters and loses there.
FogDepth fog_extinction(vec3 x) {
#ifdef FOG_FALLOFF
    float height = fog.fog_params.x * exp(min(-fog.fog_params.y * (x.y - fog.fog_params.z), FOG_MAX_EXPONENT));
#else
    float height = fog.fog_params.x;
#endif
    return height + volumes_extinction(x);
}

#if defined(FOG_AERIAL) && !defined(FOG_SKY)
// The sky's cube map (the pass binds it on the sky's unit): Fog.aerial_perspective's colours
// (a shader that declares the sky's own sampler first names it FOG_SKY: one sampler, not two).
uniform samplerCube fog_sky_map;
#define FOG_SKY fog_sky_map
#endif

// The light the air scatters towards an eye looking along the unit direction ``dir``: the
// fog's colour (FOG_AERIAL: that far mixed towards the sky's along ``dir``, its cube map at
// the 8-texel level, as Godot's aerial perspective), and a glow towards the sun (max(cos,
// 0)^8 of the angle from it).
vec3 fog_light(vec3 dir) {
#ifdef FOG_AERIAL
    float blurred = log2(float(textureSize(FOG_SKY, 0).x)) - 3.0;
    vec3 base = mix(fog.fog_color.rgb, textureLod(FOG_SKY, dir, max(blurred, 0.0)).rgb, fog.fog_params.w);
#else
    vec3 base = fog.fog_color.rgb;
#endif
#ifdef FOG_GLOW
    float towards = max(dot(dir, fog.fog_sun.xyz), 0.0);
    towards *= towards;
    towards *= towards;
    return base + fog.fog_glow.rgb * (towards * towards);
#else
    return base;
#endif
}

// The stretch from a to b, seen looking along the unit direction ``dir``.
FogWay fog_way(vec3 a, vec3 b, vec3 dir) {
    float height = height_fog_depth(a, b);
    float reach = length(b - a);
    FogWay volumes = reach > 0.0 ? volumes_along(a, (b - a) / reach, reach) : FogWay(vec3(0.0), FogDepth(0.0));
    return FogWay(fog_light(dir) * height + volumes.light, height + volumes.depth);
}

// ``color`` seen through ``way`` (channel by channel, FOG_TINTED): where a depth is 0 the
// colour (the fog's colour there, 0 / tiny, is any finite number: mix by 1 takes none of it).
vec3 fog_over(vec3 color, FogWay way) {
    return mix(way.light / max(way.depth, FogDepth(1e-30)), color, exp(-way.depth));
}

// ``color`` seen along the unit direction ``dir`` through the height fog of optical depth ``depth``.
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
    return fog_over(color, fog_way(fog_start(eye, plane, p), p, normalize(p - eye)));
}

// The sky seen from ``a`` along the unit direction ``r``: its share (``fog_color.a``) of the
// height fog, and every volume the way passes through (a volume's far side is never the sky's).
vec3 fog_sky(vec3 color, vec3 a, vec3 r) {
    color = mix(color, fogged(color, height_fog_depth_to_sky(a, r), r), fog.fog_color.a);
#ifdef FOG_VOLUMES
    color = fog_over(color, volumes_along(a, r, 1e30));
#endif
    return color;
}
#else
struct FogWay {
    vec3 light;
    FogDepth depth;
};
FogDepth fog_depth(vec3 a, vec3 b) { return FogDepth(0.0); }
FogDepth fog_extinction(vec3 x) { return FogDepth(0.0); }
FogWay fog_way(vec3 a, vec3 b, vec3 dir) { return FogWay(vec3(0.0), FogDepth(0.0)); }
vec3 fog_over(vec3 color, FogWay way) { return color; }
vec3 fogged(vec3 color, float depth, vec3 dir) { return color; }
vec3 fog_view(vec3 color, vec3 eye, vec4 plane, vec3 p) { return color; }
vec3 fog_sky(vec3 color, vec3 a, vec3 r) { return color; }
FogDepth water_depth(vec3 x, vec3 r, float reach) { return FogDepth(0.0); }
FogDepth water_light(vec3 x, vec3 r, float reach) { return FogDepth(1.0); }
FogDepth water_skylight(vec3 x) { return FogDepth(1.0); }
#endif
