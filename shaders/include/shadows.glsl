// Shadow maps, made once a frame (at most) and read by every view (engine/render/shadows.py).
// Directional lights: one depth atlas, a tile a light, each fitted to the whole level
// (engine/rules/shadow_rules.py), read with hardware depth comparison (sampler2DShadow:
// bilinear percentage-closer filtering per tap) at a grid of taps.  Point lights: a cube a
// light holding distance / range, compared by hand, or, for a spot no wider than
// light_rules.SPOT_MAP_MAX_ANGLE, a perspective depth map fitted to its cone (a tile of the
// spot atlas, read as the directional atlas is).  Bias is a normal offset (the point looked
// up is moved off the surface along its geometric normal, more at grazing light, by the
// texel's world size: Holbein's "normal offset shadows", 2011) plus the slope-scaled depth
// offset the caster pass draws with; nothing is offset along the light, so contact is kept.
// A sun's, a spot's map's and a lamp's cube's grid of taps compares each with the receiver's
// own plane (receiver-plane depth bias), so the push stays a texel whatever the softness (a
// push as wide as the filter moved a grazing light's shadow edges in by it).
// MAX_POINT_SHADOWS (the cube samplers below) and MAX_SHADOW_RINGS are engine/render/shadows.py's,
// defined by the shader library.  SHADOW_RINGS (the ring entries read) is compiled in while
// a light has cascades: rings about the camera in atlas tiles of their own, whose lookup
// takes the smallest ring holding the point (a view anywhere finds the same shadow there);
// SHADOW_RING_BLEND while a ring has a blend band (DirectionalLight.shadow_cascade_blend):
// there it fades into the next larger map's shadow, a second lookup.
//
// The lookups are compiled only into the program builds that need them
// (ShadowMaps.program_defines, engine/render/shadows.py; the scene pass builds with them):
// DIRECTIONAL_SHADOWS while a directional light casts (its value: how many of the first
// directional slots are read, the last casting one's index + 1), POINT_SHADOWS while a point
// light does (its value: how many cubes are read, the last used one's index + 1); without
// them a light's shadow is 1 and no map is read.  A GPU skips the lookup of a
// light that casts nothing at its ``params.w == 0`` test, but a software rasteriser (llvmpipe)
// runs every branch's code for every pixel, so there the lookups of a frame where nothing
// casts cost a third of it.  SHADOW_SINGLE_TAP (the "single" filter) is the one tap known
// when the program is built, not a loop over a count read from the block.
layout(std140) uniform Shadows {
    mat4 directional_matrix[MAX_DIRECTIONAL_LIGHTS];  // world -> atlas uv (xy) and depth (z), each in [0, 1]
    vec4 directional_params[MAX_DIRECTIONAL_LIGHTS];  // x: a texel's world size, y: softness (texels),
                                                      // z: one atlas texel in uv, w: taps a side (0: no shadow)
    ivec4 point_slot[MAX_POINT_LIGHTS / 4];           // per point light: its cube (0, 1) or -1
    vec4 point_params[MAX_POINT_SHADOWS];             // x: a texel's angular size (radians), y: softness
                                                      // (texels), z: range, w: taps a side
    ivec4 point_light;                                // per cube (0, 1): the point light it is, or -1
    // Cascades (rings about the camera, DirectionalLight.shadow_cascades), a light's outermost first;
    // a ring shares its light's space and depth with the level's map, so its square is that map's
    // atlas uv scaled and moved:
    vec4 ring_map[MAX_SHADOW_RINGS];                  // xy: scale, zw: offset (the level's uv -> the ring's square)
    vec4 ring_params[MAX_SHADOW_RINGS];               // x: a texel's world size, y: softness (texels),
                                                      // z: the blend band's width (square units; 0: none)
    vec4 ring_tile[MAX_SHADOW_RINGS];                 // xy: its tile's corner in the atlas (uv), z: the
                                                      // tile's side (uv), w: the filter's margin (square units)
    ivec4 ring_slot;                                  // per ring: the directional slot whose it is, or -1
    // Spot maps (a spot within light_rules.SPOT_MAP_MAX_ANGLE: a perspective map fitted to its
    // cone, a tile of the spot atlas, read in place of its cube; point_params' x is then a
    // texel's width over its distance on the axis, w the filter's taps a side):
    mat4 spot_matrix[MAX_POINT_SHADOWS];              // world -> atlas uv and depth (divide by w)
    vec4 spot_box[MAX_POINT_SHADOWS];                 // its map's uv corners in the atlas (x0, y0, x1, y1)
    vec4 point_size[MAX_POINT_SHADOWS];               // x: a cube's light's size, the radius of a disc as
                                                      // bright (metres; 0: a point: soft_cube_shadow);
                                                      // yzw: a rectangle's front (0: a sphere's, all round)
    vec4 directional_size[MAX_DIRECTIONAL_LIGHTS];    // x: its map's depth range (metres), y: 2 tan(half
                                                      // its angular diameter) (0: a hard edge: soft_sun_shadow)
    vec4 directional_tile[MAX_DIRECTIONAL_LIGHTS];    // its level map's tile in the atlas: corner (uv), side
    vec4 lamp_through[MAX_POINT_SHADOWS];             // per slot, its see-through tiles in the lamps' atlas (a
                                                      // row a slot, a tile a face): xy: 1 / the atlas's size,
                                                      // z: a face's side (texels; 0: none), w: the gutter round it
} shadows;

uniform sampler2DShadow shadow_atlas;
uniform samplerCube point_shadow0;
uniform samplerCube point_shadow1;

// Percentage-closer filtering of a depth atlas at ``p`` (uv, depth): a grid of n x n taps
// (engine/render/shadows.py ShadowMaps.filter), each a bilinear comparison of 2 x 2 texels,
// ``softness`` atlas texels (``texel``: one in uv, each way) across: 2 x 2 taps half a
// softness apart (a 3 x 3-texel tent at softness 1), 3 x 3 for wider edges; one tap on a
// software rasteriser (SHADOW_SINGLE_TAP: ``slope`` unused, so its making is compiled out).
// Each tap is compared with the receiver's own plane there (receiver-plane depth
// bias: ``slope``, its depth per uv of the atlas, held to a slope of 8), less a texel's
// worth of it (the 2 x 2 texels a bilinear comparison reads lie up to a texel off the tap):
// a surface does not shadow itself across the filter's width, so the point needs moving off
// it by no more than a texel, whatever the softness (a wider push moved a grazing light's
// shadow edges in: 3.9 texels at softness 1, the shadow gone at 4).  The suns' and the spots'
// grids.
float filtered_shadow(sampler2DShadow atlas, vec3 p, int n, vec2 texel, float softness, vec2 slope) {
#ifdef SHADOW_SINGLE_TAP
    return texture(atlas, p);
#else
    slope = clamp(slope, vec2(-8.0), vec2(8.0));
    vec2 step = n > 1 ? texel * softness / float(n - 1) : vec2(0.0);
    vec2 start = p.xy - 0.5 * step * float(n - 1);
    float z = p.z;
    float lit = 0.0;
    for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) {
            vec2 at = start + step * vec2(x, y);
            lit += texture(atlas, vec3(at, z + dot(slope, at - p.xy)));
        }
    return lit / float(n * n);
#endif
}

// The receiver's plane in a map that ``to_map`` carries the world into (a spot's perspective
// map, a light's image through mirrors and portals) at ``p`` (the point in the map, divided
// by its ``w``): its depth per atlas uv.  A projective map carries a plane to a plane (depth
// and all, the divide's too), so the map's derivative along two ways on the surface
// (``normal``'s tangents, each carried in as a direction: its change less ``p`` times its
// w's, over w, the 1 / w dropped as the ratio keeps none of it) spans it exactly
// (receiver-plane depth bias: filtered_shadow).
vec2 receiver_slope_in_map(mat4 to_map, vec3 p, vec3 normal) {
    vec3 t1 = normalize(cross(normal, abs(normal.y) < 0.9 ? vec3(0.0, 1.0, 0.0) : vec3(1.0, 0.0, 0.0)));
    vec4 a = to_map * vec4(t1, 0.0);
    vec4 b = to_map * vec4(cross(normal, t1), 0.0);
    vec3 m = cross(a.xyz - p * a.w, b.xyz - p * b.w);
    return -m.xy / (abs(m.z) > 1e-12 ? m.z : 1e-12);
}

#if (defined(SOFT_POINT_SHADOWS) || defined(SOFT_SUN_SHADOWS)) && !defined(SHADOW_SINGLE_TAP)
// The k-th of ``count`` taps on a Vogel disc (a golden-angle spiral) of radius 1, the same at
// every pixel: the soft shadows' blocker searches and filters.
vec2 vogel_tap(int k, int count) {
    float r = sqrt((float(k) + 0.5) / float(count));
    float a = float(k) * 2.39996323;
    return r * vec2(cos(a), sin(a));
}
#endif

#if defined(SOFT_SUN_SHADOWS) && !defined(SHADOW_SINGLE_TAP)
// A sun with a size (DirectionalLight.angular_diameter) by percentage-closer soft shadows
// (Fernando 2005), in whichever of its maps holds the point: the blockers' mean depth among
// SUN_SEARCH taps of the map read as it is (shadow_depths: the atlas through a sampler that
// compares nothing), within the widest penumbra a blocker up to the map's near side could
// cast (at most SUN_SEARCH_TEXELS of the light's level map's texels, whichever map: a
// cascade's finer texels do not narrow it), then SUN_TAPS comparisons over the penumbra the
// mean blocker casts: its depth gap to the point times ``size.x`` (metres over the map's
// depth) times ``size.y`` (2 tan of half the angle), across.  Each tap compared with the
// receiver's own plane there (``slope``: its depth per uv of this map, held to a slope of 8),
// less two texels of it, so a flat receiver does not shadow itself across the wide taps.
// Every tap is kept inside the map's tile (``tile``: its corner and side in the atlas, less
// half a texel): past it lie other maps, or texels no map wrote.
uniform sampler2D shadow_depths;
const int SUN_SEARCH = 12;
const int SUN_TAPS = 16;
const float SUN_SEARCH_TEXELS = 32.0;   // the search's and the penumbra's widest radius (level-map texels)

// ``p``: the point in the atlas (uv, depth); ``metres_per_uv``: this map's, along u and along
// v (a level not square in the sun's view has its map's texels longer one way: the disc of
// taps is round in metres, not in uv); ``texel``: the atlas's texel in uv; ``widest_metres``:
// the widest radius.
float soft_sun_shadow(vec3 p, vec2 metres_per_uv, float texel, float widest_metres, vec4 size, vec2 slope,
                      vec3 tile) {
    vec2 low = tile.xy + 0.5 * texel, high = tile.xy + tile.z - 0.5 * texel;
    vec2 spread = size.x * size.y / metres_per_uv;   // the penumbra's width (uv) a unit of depth gap
    vec2 widest = widest_metres / metres_per_uv;
    vec2 search = clamp(0.5 * p.z * spread, vec2(texel), widest);
    vec2 steepest = 8.0 * metres_per_uv / max(size.x, 1e-6);   // a slope of 8 in depth per uv
    slope = clamp(slope, -steepest, steepest);
    float bias = 2.0 * texel * (abs(slope.x) + abs(slope.y)) + 1e-5;
    float blockers = 0.0, found = 0.0;
    for (int k = 0; k < SUN_SEARCH; ++k) {
        vec2 o = vogel_tap(k, SUN_SEARCH) * search;
        float stored = texture(shadow_depths, clamp(p.xy + o, low, high)).r;
        if (stored < p.z + dot(slope, o) - bias) {
            blockers += stored;
            found += 1.0;
        }
    }
    if (found == 0.0) return 1.0;
    vec2 radius = clamp(0.5 * (p.z - blockers / found) * spread, vec2(0.5 * texel), widest);
    float lit = 0.0;
    for (int k = 0; k < SUN_TAPS; ++k) {
        vec2 o = vogel_tap(k, SUN_TAPS) * radius;
        lit += texture(shadow_atlas, vec3(clamp(p.xy + o, low, high), p.z + dot(slope, o) - bias));
    }
    return lit / float(SUN_TAPS);
}
#endif

// Whether atlas uv ``p`` lies outside ``tile`` (its corner and side, uv).
bool outside_tile(vec2 p, vec3 tile) {
    return any(lessThan(p, tile.xy)) || any(greaterThan(p, tile.xy + tile.z));
}

// Directional light i's lookup of its map at ``p`` (atlas uv, depth): its grid of taps, or a
// sun with a size's soft shadow (``scale``: the map's uv per the level map's, 1 for the level
// map, a ring's its own; ``slope``: the receiver's depth per level-map uv; ``tile``: the map's
// tile in the atlas, corner and side).
float directional_lookup(int i, vec3 p, vec4 params, vec2 scale, vec2 slope, vec3 tile) {
#if defined(SOFT_SUN_SHADOWS) && !defined(SHADOW_SINGLE_TAP)
    vec4 size = shadows.directional_size[i];
    if (size.y > 0.0) {
        // The level map's metres per uv along u and v (its matrix's first two rows: uv per
        // metre), this map's over its scale.
        mat4 m = shadows.directional_matrix[i];
        vec2 level = 1.0 / vec2(length(vec3(m[0][0], m[1][0], m[2][0])), length(vec3(m[0][1], m[1][1], m[2][1])));
        return soft_sun_shadow(p, level / scale, params.z, SUN_SEARCH_TEXELS * params.x, size, slope / scale, tile);
    }
#endif
    return filtered_shadow(shadow_atlas, p, int(params.w), vec2(params.z), params.y, slope / scale);
}

#ifdef SHADOW_RINGS
#if SHADOW_RINGS > 3
#error "directional_shadow reads three rings"
#endif
// Ring k's atlas coordinates of a point (``at`` and ``along``: the point and its normal in the
// level map's coordinates, offset by the ring's own texel) where ring k is light i's and holds
// it: then ``p`` becomes them, ``coarser`` what ``p`` was (the next larger map's) and ``fine``
// how far in the point is across the ring's blend band (0 at the square's usable edge, 1 past
// the band: cascade blending, SHADOW_RING_BLEND builds).  Else all three are left.  Called
// with a constant k: no array indexed by a variable, no loop (llvmpipe runs a loop's and an
// indexed read's code slower).
void ring_coordinates(int k, int i, vec3 at, vec3 along, float grazing, inout vec3 p, inout vec3 coarser,
                      inout float fine, inout vec2 scale, inout vec2 coarser_scale, inout vec3 map_tile,
                      inout vec3 coarser_tile) {
    vec3 q = at + along * (shadows.ring_params[k].x * grazing);
    vec4 map = shadows.ring_map[k];
    vec2 square = q.xy * map.xy + map.zw;
    vec4 tile = shadows.ring_tile[k];
    vec2 edge = min(square - tile.w, 1.0 - tile.w - square);   // in from the usable square's sides
    bool inside = shadows.ring_slot[k] == i && all(greaterThan(edge, vec2(0.0)));
    float band = shadows.ring_params[k].z;
    coarser = inside ? p : coarser;
    coarser_scale = inside ? scale : coarser_scale;
    coarser_tile = inside ? map_tile : coarser_tile;
    map_tile = inside ? tile.xyz : map_tile;
    fine = inside ? (band > 0.0 ? clamp(min(edge.x, edge.y) / band, 0.0, 1.0) : 1.0) : fine;
    p = inside ? vec3(tile.xy + square * tile.z, q.z) : p;
    scale = inside ? map.xy * tile.z : scale;   // (the ring's atlas uv per the level map's)
}
#endif

// Directional light i's shadow at a point whose coordinates in its level map are ``at``, moved
// off along ``along`` (a metre along the offset's way, in the same coordinates) by ``grazing``
// of the map's texels (``params``: the light's directional_params, its w not 0): the ring that
// holds the point read in place of the level's map, the map's filter, a ring's blend band.
// The scene pass's lookup (directional_shadow) and the light shafts' march
// (volumetric_fog.frag, which steps ``at`` along its ray) share it.
float directional_shadow_at(int i, vec4 params, vec3 at, vec3 along, float grazing, vec2 slope) {
    vec3 p = at + along * (params.x * grazing);
    vec3 coarser = p;   // the next larger map's coordinates (the level's, or a ring's)
    float fine = 1.0;   // the chosen ring's share, against the next larger map's (cascade blending)
    vec2 scale = vec2(1.0), coarser_scale = vec2(1.0);   // their uv per the level map's
    vec3 map_tile = shadows.directional_tile[i].xyz, coarser_tile = map_tile;   // their tiles in the atlas
#ifdef SHADOW_RINGS
    // The smallest of the light's rings that holds the point (outermost first: the last
    // holding it wins), read instead of the level's map; the coordinates chosen, one lookup
    // (two in a ring's blend band).
    ring_coordinates(0, i, at, along, grazing, p, coarser, fine, scale, coarser_scale, map_tile, coarser_tile);
#if SHADOW_RINGS > 1
    ring_coordinates(1, i, at, along, grazing, p, coarser, fine, scale, coarser_scale, map_tile, coarser_tile);
#endif
#if SHADOW_RINGS > 2
    ring_coordinates(2, i, at, along, grazing, p, coarser, fine, scale, coarser_scale, map_tile, coarser_tile);
#endif
#endif
    // Beside the map: no caster is between the point and the light (the map holds them all).
    // Its own square, not the atlas's: past it lie the other lights' maps and the rings'.
    if (outside_tile(p.xy, map_tile)) return 1.0;
    // Past its far side (what the map's fit leaves out: a particle below the level's last
    // caster) it is behind every caster over it: compared at the far side (the reference is
    // clamped so whatever the depth format; in front of the near side it is lit either way).
    p.z = clamp(p.z, 0.0, 1.0);
    float lit = directional_lookup(i, p, params, scale, slope, map_tile);
#ifdef SHADOW_RING_BLEND
    if (fine < 1.0) {   // in a ring's band: fade towards the next larger map's shadow
        bool off = outside_tile(coarser.xy, coarser_tile) || coarser.z < 0.0 || coarser.z > 1.0;
        float far_lit = off ? 1.0 : directional_lookup(i, coarser, params, coarser_scale, slope, coarser_tile);
        lit = mix(far_lit, lit, fine);
    }
#endif
    return lit;
}

// The same with no receiver's plane (the light shafts' points in the air).
float directional_shadow_at(int i, vec4 params, vec3 at, vec3 along, float grazing) {
    return directional_shadow_at(i, params, at, along, grazing, vec2(0.0));
}

// How much of directional light i reaches a point at ``position`` whose geometric normal
// (facing the viewer) is ``normal`` and for which the light comes from ``l``: 0 (shadowed) to 1.
float directional_shadow(int i, vec3 position, vec3 normal, vec3 l) {
#ifndef DIRECTIONAL_SHADOWS
    return 1.0;
#else
    vec4 params = shadows.directional_params[i];
    if (params.w == 0.0) return 1.0;
    float nl = clamp(dot(normal, l), 0.0, 1.0);
    // Off the surface by a texel, more as the light grazes it (the filter's taps follow the
    // receiver's plane: filtered_shadow).
    float grazing = 1.5 - nl;
    mat4 to_map = shadows.directional_matrix[i];
    vec3 at = (to_map * vec4(position, 1.0)).xyz;  // the point in the level map's coordinates
    vec3 along = mat3(to_map) * normal;            // ... and a metre along its normal
    // The receiver's plane in the map (receiver-plane depth bias, without screen derivatives).
    vec2 slope = receiver_slope_in_map(to_map, at, normal);
    return directional_shadow_at(i, params, at, along, grazing, slope);
#endif
}

// Every directional light's shadow at a surface point (``directional_shadow`` of slots 0 to
// DIRECTIONAL_SHADOWS - 1; 1 for the rest), one lookup a slot at the shader's top level, for
// the lights' loop to read (scene.frag direct_lighting), not made inside that loop: llvmpipe
// runs a texture lookup inside a loop at about twice its cost outside one (the lighting
// benchmark's still shadows frame: lookups in the loop 1.23x the frame without shadows,
// hoisted 1.17x).  The same value either way: a slot whose light does not reach the point
// (or that is no light) is not read by the loop.  Reads the Lights block (lights.glsl).
vec4 directional_shadows(vec3 position, vec3 normal) {
    vec4 lit = vec4(1.0);
#ifdef DIRECTIONAL_SHADOWS
#if MAX_DIRECTIONAL_LIGHTS > 4
#error "directional_shadows keeps a slot a component of a vec4"
#endif
    lit.x = directional_shadow(0, position, normal, -lights.directional_dir[0].xyz);
#if DIRECTIONAL_SHADOWS > 1
    lit.y = directional_shadow(1, position, normal, -lights.directional_dir[1].xyz);
#endif
#if DIRECTIONAL_SHADOWS > 2
    lit.z = directional_shadow(2, position, normal, -lights.directional_dir[2].xyz);
#endif
#if DIRECTIONAL_SHADOWS > 3
    lit.w = directional_shadow(3, position, normal, -lights.directional_dir[3].xyz);
#endif
#endif
    return lit;
}

#if defined(SEE_THROUGH_SHADOWS) || defined(VIRTUAL_SEE_THROUGH_SHADOWS)
// How much deeper than the nearest see-through caster a point lies before its light is
// dimmed (depth units: a half float's step near 1 and more, so a pane does not dim itself).
const float SEE_THROUGH_BIAS = 2e-3;

// The share let through to a point whose coordinates in a depth map (its atlas's uv, its
// depth) are ``p``, read from ``map``, the see-through map laid out as that atlas: where it
// lies deeper than the nearest see-through caster there, the share they let through.
float see_through_at(sampler2D map, vec3 p) {
    vec4 through = texture(map, p.xy);
    return p.z > through.a + SEE_THROUGH_BIAS ? through.r : 1.0;
}
#endif

#ifdef VIRTUAL_SEE_THROUGH_SHADOWS
// The lights through mirrors and portals' see-through maps (ShadowMaps.virtual_see_through_atlas),
// laid out as the virtual atlas: read in virtual_shadow (virtual_light_ways.glsl).  Red: the
// share the see-through things of the stretches before the last surface let through (every
// point the light reaches lies past them); green and alpha: the last stretch's share and its
// nearest see-through thing's depth, as a sun's map holds them (a pane over a floor mirror is
// met twice on one texel's line, on the way in and on the way out: a point between the glass
// and the pane takes its share once).
uniform sampler2D virtual_see_through_atlas;

float virtual_see_through_at(vec3 p) {
    vec4 through = texture(virtual_see_through_atlas, p.xy);
    return through.r * (p.z > through.a + SEE_THROUGH_BIAS ? through.g : 1.0);
}
#endif

#ifdef SEE_THROUGH_SHADOWS
// The suns' see-through maps (engine/render/shadows.py, ShadowMaps.see_through_atlas): each
// casting sun's level map has a tile of its own here, half its texels a side, laid out as the
// depth atlas's (the same uv), holding the share of the light the see-through things over a
// texel let through (red: the product of each one's 1 - alpha) and the nearest one's depth
// (alpha).  Filtered bilinearly: a soft edge, one lookup.
uniform sampler2D see_through_atlas;

// The share let through to a point whose coordinates in a sun's level map are ``p``.
float see_through_in_map(vec3 p) {
    return see_through_at(see_through_atlas, p);
}

// The share of sun i's light that the see-through things between it and a point let through
// (1 where none is, or the point lies in front of them): the point moved off its surface as
// the depth lookup moves it, twice as far (the map's texels are twice as big).
float see_through_shadow(int i, vec3 position, vec3 normal, vec3 l) {
    vec4 params = shadows.directional_params[i];
    if (params.w == 0.0) return 1.0;
    float nl = clamp(dot(normal, l), 0.0, 1.0);
    mat4 to_map = shadows.directional_matrix[i];
    vec3 p = (to_map * vec4(position, 1.0)).xyz + mat3(to_map) * normal * (2.0 * params.x * (1.5 - nl));
    vec3 tile = shadows.directional_tile[i].xyz;
    if (any(lessThan(p.xy, tile.xy)) || any(greaterThan(p.xy, tile.xy + tile.z))) return 1.0;
    return see_through_in_map(p);
}

// ``see_through_shadow`` for directional slots 0 to DIRECTIONAL_SHADOWS - 1 (as
// ``directional_shadows``: one lookup a slot, before the lights' loop).
vec4 see_through_shadows(vec3 position, vec3 normal) {
    vec4 through = vec4(1.0);
    through.x = see_through_shadow(0, position, normal, -lights.directional_dir[0].xyz);
#if DIRECTIONAL_SHADOWS > 1
    through.y = see_through_shadow(1, position, normal, -lights.directional_dir[1].xyz);
#endif
#if DIRECTIONAL_SHADOWS > 2
    through.z = see_through_shadow(2, position, normal, -lights.directional_dir[2].xyz);
#endif
#if DIRECTIONAL_SHADOWS > 3
    through.w = see_through_shadow(3, position, normal, -lights.directional_dir[3].xyz);
#endif
    return through;
}
#endif

#if defined(SOFT_POINT_SHADOWS) && !defined(SHADOW_SINGLE_TAP)
// The shadow of a light with a size (a sphere's radius, a rectangle's disc of the same area:
// ``size.x``, metres; a rectangle's front: ``size.yzw``) from its distance cube, by
// percentage-closer soft shadows (Fernando, "Percentage-Closer Soft Shadows", 2005): the
// blockers' mean distance found among
// SOFT_SEARCH taps where they may stand (the light's disc seen from the point, widened for
// blockers down to a quarter of the way to the light), the penumbra that disc casts past them
// (size x (point - blocker) / blocker, as an angle from the light), then SOFT_TAPS taps over
// it (at most 45 degrees about the point's direction: a caster at the light's own surface
// would spread it round the cube).  Its edge hardens where the caster meets the receiver and
// widens away from it, as an area light's does.  Taps on a Vogel disc (a golden-angle
// spiral), the same at every pixel.
const int SOFT_SEARCH = 12;
const int SOFT_TAPS = 16;


// Where the receiver's own plane (through ``p``, from the light, normal ``n``) lies along the
// direction ``t`` from the light, over the range, less a texel's worth of its slope there: a
// tap is a blocker only where the map holds something nearer than that, so a flat receiver
// does not shadow itself across the wide taps (receiver-plane depth bias, the map's texels
// sloped as the plane is); 1e9 where the direction misses the plane.
float receiver_at(vec3 p, vec3 n, vec3 t, float range, float texel_angle) {
    float c = dot(n, normalize(t));
    if (c > -1e-4) return 1e9;
    float at = dot(n, p) / c;
    float slope = min(sqrt(max(1.0 - c * c, 0.0)) / -c, 8.0);
    return at * (1.0 - texel_angle * (1.5 + slope)) / range;
}

float soft_cube_shadow(samplerCube cube, vec3 p, vec3 n, float d, vec4 size, float range, float texel_angle) {
    float dist = length(p);
    vec3 dir = p / dist;
    vec3 side = normalize(cross(dir, abs(dir.y) < 0.99 ? vec3(0.0, 1.0, 0.0) : vec3(1.0, 0.0, 0.0)));
    vec3 up = cross(dir, side);
    float search = clamp(3.0 * size.x / dist, texel_angle, 0.6);
    float blockers = 0.0, found = 0.0;
    for (int k = 0; k < SOFT_SEARCH; ++k) {
        vec2 o = vogel_tap(k, SOFT_SEARCH) * search;
        vec3 t = dir + side * o.x + up * o.y;
        float stored = texture(cube, t).r;
        // (a rectangle sheds no light behind its plane: what stands there, the ceiling it hangs
        // from, blocks none of it)
        if (dot(t, size.yzw) >= 0.0 && stored < min(d, receiver_at(p, n, t, range, texel_angle))) {
            blockers += stored;
            found += 1.0;
        }
    }
    if (found == 0.0) return 1.0;
    float blocker = max(blockers / found * range, 1e-3);
    float penumbra = clamp(size.x * (dist - blocker) / (blocker * dist), texel_angle, 1.0);
    float lit = 0.0, taps = 0.0;
    for (int k = 0; k < SOFT_TAPS; ++k) {
        vec2 o = vogel_tap(k, SOFT_TAPS) * penumbra;
        vec3 t = dir + side * o.x + up * o.y;
        float front = dot(t, size.yzw) >= 0.0 ? 1.0 : 0.0;
        lit += front * (texture(cube, t).r >= min(d, receiver_at(p, n, t, range, texel_angle)) ? 1.0 : 0.0);
        taps += front;
    }
    return taps > 0.0 ? lit / taps : 1.0;
}
#endif

#ifdef LAMP_SEE_THROUGH_SHADOWS
#include "cube_faces.glsl"
// The lamps' see-through maps (engine/render/shadows.py, ShadowMaps.lamp_see_through_atlas):
// a casting point light's six cube faces (a spot's map: the first), each a tile drawn as the
// face's view (CUBE_FACE_*: looking along its axis, up its t axis) widened over a gutter,
// half its map's texels a side, holding the share of the light the see-through things let
// through (red) and the nearest one's distance over the range (alpha).  Bilinear, one lookup.
uniform sampler2D lamp_see_through_atlas;
// How much farther than the nearest see-through caster (over the range) a point lies before
// its light is dimmed: a half float's step near 1 and more, so a pane does not dim itself.
const float LAMP_SEE_THROUGH_BIAS = 2e-3;

// The share let through at ``ndc`` (-1 to 1 across the face's view) of face ``face``'s tile of
// slot ``slot``, for a point ``d`` (distance over range) from the light.
float lamp_see_through_at(int slot, int face, vec2 ndc, float d) {
    vec4 tile = shadows.lamp_through[slot];
    if (tile.z == 0.0) return 1.0;
    float pitch = tile.z + 2.0 * tile.w;   // a tile's side, gutter and all (texels)
    vec2 texel = vec2(float(face), float(slot)) * pitch + tile.w + (clamp(ndc, -1.0, 1.0) * 0.5 + 0.5) * tile.z;
    vec4 through = texture(lamp_see_through_atlas, texel * tile.xy);
    return d > through.a + LAMP_SEE_THROUGH_BIAS ? through.r : 1.0;
}

// The share of slot ``slot``'s point light that reaches a point ``from_light`` from it (its
// geometric ``normal``, ``l`` towards the light) through the see-through things: moved off its
// surface as the cube's lookup moves it, twice as far (the tiles' texels are twice as big),
// and looked up in the face GL's cube-map selection takes (the largest axis).
float lamp_see_through_cube(int slot, vec3 from_light, vec3 normal, vec3 l) {
    vec4 params = shadows.point_params[slot];
    float nl = clamp(dot(normal, l), 0.0, 1.0);
    vec3 p = from_light + normal * (2.0 * params.x * length(from_light) * (1.5 - nl));
    vec2 st;
    int face = cube_face_of(p, st);
    return lamp_see_through_at(slot, face, st, length(p) / params.z);
}
#endif

#if !defined(SHADOW_SINGLE_TAP)
// How much farther than the point's (its distance times this) the receiver's own plane lies
// along a tap's way ``tap`` from the light: the plane through the point (``facing``: the
// cosine between its ``normal`` and the way to the point, below 0 where it faces the light)
// met along the tap, the ratio of the two ways' cosines, exact; at most ``widest`` (a tap whose
// way runs past the plane's edge meets it nowhere).  1 where the surface faces away.
float receiver_ratio(vec3 normal, float facing, vec3 tap, float widest) {
    if (facing > -1e-4) return 1.0;
    return facing / min(dot(normal, normalize(tap)), facing / widest);
}
#endif

#include "cube_faces.glsl"
// One bilinear percentage-closer comparison in a distance cube, by hand (it holds distances in
// a float colour channel, which the hardware's depth comparison does not take): the four
// texels bilinear filtering reads about the way ``tap``, each lit where ``d`` (distance over
// range) is no farther than it holds, weighed as bilinear filtering weighs them, so a straight
// edge ramps over a texel as a sun's map's does (nearest texels made a staircase of them).
// The four are gathered at their shared corner, half a texel from any other four whatever the
// rounding; a tap within half a texel of its face's edge takes the face's edge texels (as a
// map clamped to its edge does), so every gather stays in one face's texels.
float cube_bilinear_lit(samplerCube cube, vec3 tap, float d, float face_size) {
    vec2 st;
    cube_face_of(tap, st);
    vec2 texel = (st * 0.5 + 0.5) * face_size - 0.5;
    vec2 corner = max(min(floor(texel), vec2(face_size - 2.0)), vec2(0.0));   // (a 1-texel cube: 0)
    vec2 f = clamp(texel - corner, 0.0, 1.0);
    vec4 held = textureGather(cube, cube_face_point(tap, (corner + 1.0) / face_size * 2.0 - 1.0));
    vec4 lit = step(vec4(d), held);   // (x: texel (i0, j1), y: (i1, j1), z: (i1, j0), w: (i0, j0))
    return mix(mix(lit.w, lit.z, f.x), mix(lit.x, lit.y, f.x), f.y);
}

float point_cube_shadow(samplerCube cube, vec4 params, vec3 from_light, vec3 normal, vec3 l, vec4 size) {
    float dist = length(from_light);
    float nl = clamp(dot(normal, l), 0.0, 1.0);
    // The normal offset: a texel's world size at this distance (its angle x the distance),
    // more as the light grazes the surface; the taps follow the receiver's plane, so not the
    // filter's width (a push as wide as the filter moved a grazing lamp's shadow edges in by it).
    float texel = params.x * dist;
#if defined(SOFT_POINT_SHADOWS) && !defined(SHADOW_SINGLE_TAP)  // (the shafts' march: one tap)
    // A light with a size: its nearest-texel taps compare with the receiver's plane too
    // (receiver_at), pushed a mean texel.
    if (size.x > 0.0) {
        vec3 q = from_light + normal * texel * (1.5 - nl);
        return soft_cube_shadow(cube, q, normal, length(q) / params.z, size, params.z, params.x);
    }
#endif
    // A bilinear comparison reads texels up to one of its face's off its tap on each axis, and
    // a face's middle texel is 4 / pi (1.27) of the mean (params.x): pushed 1.5 mean texels,
    // a surface the light grazes does not shadow itself across them (a panel 16 degrees from
    // the light, pushed 1, 1.27 and 1.4 mean texels, kept 0.96, 0.968 and all of its light at
    // softness 4: tests/test_shadow_claims.py grazing).
    vec3 p = from_light + normal * (texel * 1.5 * (1.5 - nl));
    float d = length(p) / params.z;
    vec3 dir = normalize(p);
    float face_size = float(textureSize(cube, 0).x);
#ifdef SHADOW_SINGLE_TAP
    return cube_bilinear_lit(cube, dir, d, face_size);
#else
    // A grid of n x n taps (params.w a side) ``softness`` (params.y) of the cube's mean texel
    // angles (params.x) across, in the plane facing the light, each a bilinear comparison with
    // the receiver's own plane along its way (receiver-plane depth bias; its slope held to 8
    // across the grid): the suns' and the spots' grid (filtered_shadow), so an edge is
    // softness + 1 texels wide whatever the light.
    vec3 side = normalize(cross(dir, abs(dir.y) < 0.99 ? vec3(0.0, 1.0, 0.0) : vec3(1.0, 0.0, 0.0)));
    vec3 up = cross(dir, side);
    int n = int(params.w);
    float spread = params.x * params.y;
    float pitch = n > 1 ? spread / float(n - 1) : 0.0;
    float facing = dot(normal, dir);
    float widest = 1.0 + 8.0 * spread * 0.70710678;   // (a corner tap lies spread / sqrt(2) off the direction)
    float lit = 0.0;
    for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) {
            vec2 o = (vec2(x, y) - 0.5 * float(n - 1)) * pitch;
            vec3 tap = dir + side * o.x + up * o.y;
            lit += cube_bilinear_lit(cube, tap, d * receiver_ratio(normal, facing, tap, widest), face_size);
        }
    return lit / float(n * n);
#endif
}

// How much of the point light whose distances cube ``slot`` holds reaches ``position``
// (1 where the cube holds none).
float point_cube_light_shadow(int slot, samplerCube cube, vec3 position, vec3 normal) {
    int i = shadows.point_light[slot];
    if (i < 0) return 1.0;
    vec3 light_pos = lights.point_pos[i].xyz;
    vec3 d = light_pos - position;
    vec3 l = d / max(length(d), 1e-4);
    float lit = point_cube_shadow(cube, shadows.point_params[slot], position - light_pos, normal, l,
                                  shadows.point_size[slot]);
#ifdef LAMP_SEE_THROUGH_SHADOWS
    lit *= lamp_see_through_cube(slot, position - light_pos, normal, l);
#endif
    return lit;
}

#if defined(SPOT_MAP0) || defined(SPOT_MAP1)
// Spot maps: SPOT_MAPk is compiled in while slot k holds a spot's map rather than a cube
// (ShadowMaps.program_defines): a build reads one or the other for each slot, never both.
uniform sampler2DShadow spot_atlas;

// How much of the spot light whose map is tile ``slot`` of the spot atlas reaches
// ``position``: the normal offset (a texel's width at this distance, more as the light grazes
// the surface; the filter's taps follow the receiver's plane, so not the filter's width: a
// push as wide as the filter moved a grazing spot's shadow edges in by it), then a
// perspective lookup filtered as a directional map's (1 where the slot holds no light, and
// off the map: behind the spot, past its range or outside its cone, where it sheds no light).
float spot_map_light_shadow(int slot, vec3 position, vec3 normal) {
    int i = shadows.point_light[slot];
    if (i < 0) return 1.0;
    vec3 d = lights.point_pos[i].xyz - position;
    float dist = length(d);
    vec3 l = d / max(dist, 1e-4);
    vec4 params = shadows.point_params[slot];
    float nl = clamp(dot(normal, l), 0.0, 1.0);
    vec3 off = position + normal * (params.x * dist * (1.5 - nl));
    mat4 to_map = shadows.spot_matrix[slot];
    vec4 p = to_map * vec4(off, 1.0);
    if (p.w <= 0.0) return 1.0;
    p.xyz /= p.w;
    vec4 box = shadows.spot_box[slot];
    if (any(lessThan(p.xyz, vec3(box.xy, 0.0))) || any(greaterThan(p.xyz, vec3(box.zw, 1.0)))) return 1.0;
    vec2 texel = 1.0 / vec2(textureSize(spot_atlas, 0));
    float lit = filtered_shadow(spot_atlas, p.xyz, int(params.w), texel, params.y,
                                receiver_slope_in_map(to_map, p.xyz, normal));
#ifdef LAMP_SEE_THROUGH_SHADOWS
    // Its see-through tile is the map's view widened over the gutter: the map's square is the
    // tile's inside.  The point moved twice as far off its surface (the tiles' texels are twice
    // as big), as a sun's see-through lookup moves it.
    vec3 twice = position + normal * (2.0 * params.x * dist * (1.5 - nl));
    vec4 q = shadows.spot_matrix[slot] * vec4(twice, 1.0);
    if (q.w > 0.0) {
        vec2 ndc = ((q.xy / q.w - box.xy) / (box.zw - box.xy)) * 2.0 - 1.0;
        lit *= lamp_see_through_at(slot, 0, ndc, length(twice - lights.point_pos[i].xyz) / params.z);
    }
#endif
    return lit;
}
#endif

// Every shadowed point light's shadow at a point (slots 0 to POINT_SHADOWS - 1, each a cube or
// a spot's map; 1 for the rest), looked up before the lights' loop as directional_shadows is
// (one lookup a slot, not one a slot for every point light the loop visits).
// ``at0`` and ``at1``: where slot 0's and slot 1's light is looked up, ``n0`` and ``n1`` the
// normals there (point_shadows: both the point's; subsurface.glsl moves each towards its own light).
vec4 point_shadows_at(vec3 at0, vec3 n0, vec3 at1, vec3 n1) {
    vec4 lit = vec4(1.0);
#ifdef POINT_SHADOWS
#if MAX_POINT_SHADOWS > 2
#error "point_shadows reads two slots"
#endif
#ifdef SPOT_MAP0
    lit.x = spot_map_light_shadow(0, at0, n0);
#else
    lit.x = point_cube_light_shadow(0, point_shadow0, at0, n0);
#endif
#if POINT_SHADOWS > 1
#ifdef SPOT_MAP1
    lit.y = spot_map_light_shadow(1, at1, n1);
#else
    lit.y = point_cube_light_shadow(1, point_shadow1, at1, n1);
#endif
#endif
#endif
    return lit;
}

vec4 point_shadows(vec3 position, vec3 normal) {
    return point_shadows_at(position, normal, position, normal);
}

// How much of point light i reaches the point ``point_shadows`` gave ``lit`` for.
float point_shadow(int i, vec4 lit) {
#ifndef POINT_SHADOWS
    return 1.0;
#else
    int slot = shadows.point_slot[i / 4][i % 4];
    return slot == 0 ? lit.x : slot == 1 ? lit.y : 1.0;
#endif
}
