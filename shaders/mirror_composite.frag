#version 410 core
// Blends a mirror's reflection (or a portal's view) into the level above (the reflection mixed
// over the surface, weighted by the GGX specular term, blurred by a roughness mip bias). mirror_composite.vert sends the view.
//
// Built in three variants, one program each (MirrorPasses draws each level's views grouped
// by variant), so a pixel runs only its own path: a software rasteriser such as llvmpipe
// executes both sides of every branch, even one no pixel of the draw takes.
//   COMPOSITE_PORTAL: a plain window onto the view, the sky beyond the partner behind it
//                     (its row carries the carry's translation in the tile's slots, as a
//                     fallback's place does);
//   COMPOSITE_ROUGH:  a rough mirror, reading the blurred mips of its own atlas tile;
//   neither:          a sharp mirror, reading its level 1:1;
//   COMPOSITE_BUMPY:  (with or without ROUGH) a mirror with a normal map, which reads its
//                     image along the ray its bent normal reflects (below).
//   COMPOSITE_WATER:  (with or without BUMPY, never ROUGH) a water surface: the reflection
//                     weighted by Schlick's Fresnel for the water's F0 instead of the fixed
//                     reflect_rate, and with a map, rippled by two scrolling layers of it.
//                     Its row carries the waves' offset in the tile's x and y (v_eye.w,
//                     v_normal.w), the second layer's share in the tile scale (v_tint.a)
//                     and F0 in the roughness (v_params.y; negative on the row of a partly
//                     faded view, which blends over its fallback).  WATER_REFRACTION builds
//                     (a view's and a fallback's) write the pixel whole: the reflection by
//                     its weight over what lies below, bent (water_below); a partly faded
//                     view's composite blends over its fallback's (bent by the fallback).
//   RIPPLES:          (with WATER) the rippling waters' height fields tilt the normal too
//                     (ripples.glsl), bumpy or not: a still water then reads its image
//                     along the bent ray as a bumpy one does (composite_bent.glsl).
//   COMPOSITE_FALLBACK: (with PORTAL, BUMPY, WATER or none; ROUGH never: its roughness is a
//                     mip bias here) the fallback of a surface seen with no view of its own
//                     (cut by the view budget, faded, past the depth limit, a mirror switched
//                     off; an end view's pixels last frame's image did not hold): the same
//                     composite with an empty reflection, so what it shows is its environment,
//                     the probes whose influence boxes hold the surface blended by their
//                     weights and the sky taking the rest (probe_rules.surface_blend), where a
//                     drawn view shows the sky.  Its pixels are the parent view's own pixels of
//                     the surface (the parent level's node and surface images; no claim), its
//                     rectangle the parent's, in the parent's pixels (to_reflection = 1).  A
//                     partly faded mirror gets both: this first, weighted so that the view's
//                     composite over it gives rate x (fade x view + (1 - fade) x fallback).
#include "ggx.glsl"
#include "normal_map.glsl"
#include "water.glsl"
#include "ripples.glsl"
#include "composite_bent.glsl"
#include "end_image.glsl"
#include "probe_lookup.glsl"
#include "hdr.glsl"
uniform samplerCube sky_map;
#define FOG_SKY sky_map   // (Fog.aerial_perspective reads the sky's cube map through it: fog.glsl)
#include "fog.glsl"
#ifdef GENERATED_SKY
// A sharp mirror's or water's sky, drawn per pixel as the sky pass draws it.
#include "sky_model.glsl"
#endif
#include "view_axis.glsl"
#include "way.glsl"
#ifdef COMPOSITE_BENT
flat in mat3 v_project_dir;
#endif

uniform sampler2D reflection;        // premultiplied: alpha 0 where nothing was reflected
uniform usampler2D reflection_seen;
uniform usampler2D reflection_nodes;
uniform vec2 parent_size;            // pixels of the level composited into
uniform vec2 to_reflection;          // those pixels -> the reflection level's (resolution scales)
uniform bool fog_from_eye;           // the parent is a root view (its rays start at its eye): the fog's
#ifdef COMPOSITE_ROUGH
uniform sampler2D rough_atlas;       // rough views' own blur sources (engine/render/rough_atlas.py)
uniform vec2 atlas_size;
#endif

flat in vec4 v_rect;
flat in mat4 v_inv_view_proj;
flat in vec4 v_eye;        // w: tile x
flat in vec4 v_tint;       // a: tile scale
flat in vec4 v_params;
flat in vec4 v_normal;     // w: tile y
flat in mat3 v_carry;       // a bumpy mirror's UV map: columns u's gradient, v's, (u0, v0, map scale)
flat in uint v_view;       // fallback: the parent view's index (its pixels in the parent's node image)

#ifdef SURFACE_MOTION
// A view whose mirror or portal moved since the last frame (never a fallback's build:
// MirrorPasses.surface_motion): what it shows moved on the picture as the surface carried it,
// which its seen image's own motion (b, a) gains, as the way carries the camera's.
uniform mat4 parent_view_proj;   // the parent view's, as the scene pass drew it
uniform mat4 moved_view_proj;    // the same times the surface's motion (last frame's carry^-1 x this one's)

// The motion on the picture of what a pixel's ray from ``eye`` along ``dir`` shows ``way`` on
// (the sky, way_beyond: its direction): the point it is now, and where it was through the
// surface as it stood last frame, both as the parent projects this frame.
vec2 surface_moved(vec3 eye, vec3 dir, float way) {
    vec4 point = way_beyond(way) ? vec4(dir, 0.0) : vec4(eye + dir * way, 1.0);
    return picture_motion(parent_view_proj * point, moved_view_proj * point);
}
#endif

#ifdef COMPOSITE_FALLBACK
uniform usampler2D parent_nodes;     // the level composited into: which view drew each pixel
uniform usampler2D parent_surfaces;  // and the surface there
uniform vec2 to_child;               // its pixels -> the reflection level's (an end view's holes)
#ifdef FALLBACK_PROBES
// The draw's two probes (engine/render/probes.py; the sky where a row has fewer), as the
// scene shader's probe.glsl reads them.  A draw whose surfaces no influence box holds is a
// build without them (the sky alone: llvmpipe would look up both probes at weight 0).
uniform samplerCube probe_map;
uniform vec4 probe_position;
uniform vec4 probe_box_min;
uniform vec4 probe_box_max;
uniform samplerCube probe2_map;
uniform vec4 probe2_position;
uniform vec4 probe2_box_min;
uniform vec4 probe2_box_max;
#endif
flat in uvec4 v_ids;       // x: the surface's entity; y: its end view + 1 (0: not an end view)
flat in vec4 v_weights;    // x, y: the probes' weights (the sky has the rest); z: the fallback's share
flat in vec4 v_place;      // x: the plane's w; yzw: a portal's offset to beyond its partner
flat in float v_way_scale; // the parent view's metres in the root's (view_axis.glsl way_scale)

// The surface's environment along ``ray`` from ``p``: the probes by their weights and the sky
// (its share of the fog out from ``p``) taking what is left of 1, each read at its level for
// ``roughness`` (the scene shader's probe_radiance, with no pixel footprint: the composite
// reads its sky at level 0 too).
vec3 fallback_environment(vec3 p, vec3 ray, float roughness) {
    vec3 sky = fog_sky(textureLod(sky_map, ray, roughness_lod_bias(roughness)).rgb, p, ray);
#ifdef FALLBACK_PROBES
    vec3 first = probe_lookup(probe_map, probe_position, probe_box_min, probe_box_max, p, ray, 0.0, roughness);
    vec3 second = probe_lookup(probe2_map, probe2_position, probe2_box_min, probe2_box_max, p, ray, 0.0,
                               roughness);
    return first * v_weights.x + second * v_weights.y + sky * max(1.0 - v_weights.x - v_weights.y, 0.0);
#else
    return sky;
#endif
}

// The blend weight of the fallback under a reflection of weight ``rate`` (the reflect rate or
// Fresnel) that a view's composite will blend at rate x fade over it: rate x (1 - fade) /
// (1 - rate x fade), so the two leave rate x fade of the view, rate x (1 - fade) of the
// fallback and 1 - rate of the surface's own shading.  Share 1 (no view): the rate itself.
float fallback_alpha(float rate) {
    float share = v_weights.z;
    return rate * share / max(1.0 - rate * (1.0 - share), 1e-6);
}
#endif

#ifdef WATER_REFRACTION
#define WATER_REFRACTION_TURNS 3
// The band along the picture's edges, as a share of its smaller side, over which what is
// below fades from bent to unbent as the place read nears the edge (a screen-edge fade, as
// screen-space reflections fade): past the edge the copy holds nothing, and an abrupt switch
// to the unbent pixel drew a seam across a deep pool's floor, where the bent rays left it.
// Only a bend towards the edge fades (water_edge_share): a pixel at the edge whose bend runs
// along it keeps it.
#define WATER_EDGE_BAND 0.08
// How far along the bent ray the sky is looked for, seen from below (water_below), in metres:
// far enough that a point there projects as the direction does.
#define WATER_FAR_DEPTH 1.0e5
// What lies below a water surface, bent (components/water.py): the level this composite goes
// into, copied before its composites (rgb its colour, a its window depth; MirrorPasses.
// composite_level), read where the pixel's ray, refracted by the rippled surface (Snell's law,
// the index from F0), meets a floor as deep below the surface as the one drawn at the pixel
// (the planar proxy of HDRP's and Unity's water refraction): a still pond's floor seen
// shallower than it is, a rippled one's wavering.  Where that lands off the parent view's
// pixels, or on what lies above the water there (a post standing in it, the sky), or where
// nothing is drawn below, the pixel's own colour stays (what is below, unbent); near the
// picture's edge it fades to it (WATER_EDGE_BAND).
uniform sampler2D refraction_copy;
#ifndef COMPOSITE_FALLBACK
uniform usampler2D parent_nodes;  // the level composited into: which view drew each pixel
#endif

// The share of the bent colour read at ``there`` for the pixel ``here`` (both in pixels of a
// picture of ``size``): 1 where it lies WATER_EDGE_BAND in from every edge, or no nearer an
// edge than the pixel itself, falling to 0 at the edge, so the place crossing the edge blends
// into the unbent pixel the copy shows past it with no step.
float water_edge_share(vec2 here, vec2 there, vec2 size) {
    vec2 band = vec2(WATER_EDGE_BAND * min(size.x, size.y));
    vec2 low = clamp(there / max(min(band, here), vec2(0.5)), 0.0, 1.0);
    vec2 high = clamp((size - there) / max(min(band, size - here), vec2(0.5)), 0.0, 1.0);
    return min(min(low.x, low.y), min(high.x, high.y));
}

// The world point the copy holds at a pixel of the parent level.
vec3 copied_point(vec2 pixel, float window, vec2 size) {
    vec4 world = v_inv_view_proj * vec4(pixel / size * 2.0 - 1.0, window * 2.0 - 1.0, 1.0);
    return world.xyz / world.w;
}

// From below, where the pixel shows the sky: the first thing the bent ray passes behind, found
// by marching out along it (WATER_MARCH_STEPS places, each twice as far above the surface as
// the last, from WATER_MARCH_FIRST metres): a place whose pixel shows something no farther above
// the surface than the place, but farther than the last place was (so the ray crossed behind
// it between the two, not behind something standing nearer the eye), gives that thing's height
// to start the turns from; none: ``otherwise`` (the sky, far along the ray).  Without it, a
// thing over the pond near the eye, whose straight-line image lies elsewhere on the picture,
// was met only where the direction's far point happened to fall on it.
#define WATER_MARCH_STEPS 10
#define WATER_MARCH_FIRST 0.125
float water_march(vec3 at, vec3 bent, float down, vec3 plane_normal, mat4 view_proj, uint node, vec2 size,
                  float otherwise) {
    float last = 0.0;
    float height = WATER_MARCH_FIRST;
    for (int place = 0; place < WATER_MARCH_STEPS; ++place, height *= 2.0) {
        vec4 clip = view_proj * vec4(at + bent * (height / down), 1.0);
        if (clip.w <= 0.0) break;
        vec2 pixel = (clip.xy / clip.w * 0.5 + 0.5) * size;
        if (any(lessThan(pixel, vec2(0.0))) || any(greaterThanEqual(pixel, size))) break;
        ivec2 there = ivec2(pixel);
        if (texelFetch(parent_nodes, there, 0).r != node) break;
        vec4 found = texelFetch(refraction_copy, there, 0);
        if (found.a < 1.0) {
            float found_height = dot(at - copied_point(vec2(there) + 0.5, found.a, size), plane_normal);
            if (found_height > last && found_height <= height) return found_height;
        }
        last = height;
    }
    return otherwise;
}

// What the copy shows at a texel seen along ``ray`` from the surface point ``at``: its colour,
// or, where it holds the sky (far) and the view composited into drew none (a reflection
// level: its composite into its own parent adds the sky, and a pixel the water wrote would
// keep none), the sky along the ray, fogged from the surface on and by the parent's way to it.
vec3 copied_colour(vec4 texel, vec3 at, vec3 ray, FogWay parent_fog) {
    if (texel.a < 1.0 || fog_from_eye) return texel.rgb;   // (a root view drew its sky: fog_from_eye)
#ifdef GENERATED_SKY
    vec3 sky = generated_sky(ray);
#else
    vec3 sky = textureLod(sky_map, ray, 0.0).rgb;
#endif
    return fog_over(fog_sky(sky, at, ray), parent_fog);
}

// Seen from below (``underside``), what lies beyond is the air above, the ray bent away from
// the normal (index over 1): past the critical angle it does not leave the water (refract
// gives 0) and the reflection's weight is 1 (water_fresnel_inside), so the pixel keeps
// what the copy shows, unbent, under a full reflection.
vec3 water_below(vec3 at, vec3 view_dir, vec3 normal, vec3 plane_normal, float f0, bool underside,
                 FogWay parent_fog) {
    ivec2 here = ivec2(gl_FragCoord.xy);
    vec4 texel = texelFetch(refraction_copy, here, 0);
    vec4 unbent = vec4(copied_colour(texel, at, view_dir, parent_fog), texel.a);
    vec2 size = vec2(textureSize(refraction_copy, 0));
    // The far plane: from above, nothing below to bend; from below, the sky, and the bent ray
    // is followed to what the copy shows far along it (the sky there, or a thing it meets on
    // the way: a post standing in the pond seen squeezed towards the window's rim).
    bool far = unbent.a >= 1.0;
    if (far && !underside) return unbent.rgb;
    float root = sqrt(clamp(f0, 0.0, 0.98));
    float index_ratio = (1.0 - root) / (1.0 + root);  // 1 / the index: air into water
    vec3 bent = refract(view_dir, normal, underside ? 1.0 / index_ratio : index_ratio);
    float down = dot(bent, -plane_normal);
    if (down <= 1e-3) return unbent.rgb;
    mat4 view_proj = inverse(v_inv_view_proj);
    uint node = texelFetch(parent_nodes, here, 0).r;
    // The depth below the surface where the bent ray meets what was drawn, found by turns
    // (WATER_REFRACTION_TURNS): a floor as deep as the one at the last place found, then as
    // deep as the one at the place that gives: a step of a stone on the floor is met near
    // where it stands, not seen twice (once at its place, once where the floor's depth puts it).
    float depth = far ? WATER_FAR_DEPTH * down : dot(at - copied_point(gl_FragCoord.xy, unbent.a, size), plane_normal);
    if (far) depth = water_march(at, bent, down, plane_normal, view_proj, node, size, depth);
    vec3 colour = unbent.rgb;
    float kept = 0.0;  // the share of the bent colour (water_edge_share)
    for (int turn = 0; turn < WATER_REFRACTION_TURNS; ++turn) {
        if (depth <= 0.0) break;
        vec4 clip = view_proj * vec4(at + bent * (depth / down), 1.0);
        if (clip.w <= 0.0) break;
        vec2 pixel = (clip.xy / clip.w * 0.5 + 0.5) * size;
        if (any(lessThan(pixel, vec2(0.0))) || any(greaterThanEqual(pixel, size))) break;
        ivec2 there = ivec2(pixel);
        vec4 found = texelFetch(refraction_copy, there, 0);
        if (texelFetch(parent_nodes, there, 0).r != node) break;
        if (found.a >= 1.0) {  // the sky along the bent ray: from below, what is seen there (from
            if (underside) {       // above, nothing drawn below there: the pixel keeps what is below it)
                colour = copied_colour(found, at, bent, parent_fog);
                kept = water_edge_share(gl_FragCoord.xy, pixel, size);
            }
            break;
        }
        float found_depth = dot(at - copied_point(vec2(there) + 0.5, found.a, size), plane_normal);
        if (found_depth <= 0.0) break;  // what stands above the water there
        colour = found.rgb;
        depth = found_depth;
        kept = water_edge_share(gl_FragCoord.xy, pixel, size);
    }
    return mix(unbent.rgb, colour, kept);
}
#endif

layout(location = 0) out vec4 out_color;  // blended: rgb x reflect_rate + own x (1 - reflect_rate)
layout(location = 1) out uvec4 out_seen;  // the view's entity and way, carried up (way.glsl)

void main() {
    vec2 uv = gl_FragCoord.xy / parent_size;
    // A level drawn at the parent's resolution is read texel for texel where the pixel's own
    // texel is what it shows: a GPU's filter weights at a texel's centre are not exactly 0
    // (fixed point), so a bilinear read there pulls in a little of the texels beside it,
    // which may be pixels this view did not draw (the NVIDIA H200: a pane's edge in front of
    // a mirror showed a seam of what lay under it).  Scaled levels, and a bumpy mirror's bent
    // lookup, are filtered.
    bool texel_for_texel = to_reflection == vec2(1.0);
    // A point on the near plane along this pixel's ray (for an oblique projection that is
    // the parent mirror's plane: still in front of the eye, unlike its tilted far plane).
    vec4 near = v_inv_view_proj * vec4(uv * 2.0 - 1.0, -1.0, 1.0);
    // An orthographic parent's rays are parallel (its inverse affine too): along its axis (the
    // way only depth changes), each from its eye's plane (view_axis.glsl); a perspective
    // parent's from its eye.
    vec3 w_row = vec3(v_inv_view_proj[0][3], v_inv_view_proj[1][3], v_inv_view_proj[2][3]);
    bool parallel = dot(w_row, w_row) <= 1e-12 * v_inv_view_proj[3][3] * v_inv_view_proj[3][3];
    vec3 view_dir = parallel ? normalize((v_inv_view_proj * vec4(0.0, 0.0, 1.0, 0.0)).xyz)
                             : normalize(near.xyz / near.w - v_eye.xyz);
    vec3 eye = parallel ? ray_eye(v_eye.xyz, view_dir, near.xyz / near.w) : v_eye.xyz;
    // Where the pixel's ray meets the surface (what box projection starts from), and the air
    // before it in the parent view: from where the parent's rays enter it (its eye for a root
    // view, else the surface it looks out of: its oblique near plane) to the surface.
    vec3 at = eye + view_dir * (-(dot(v_normal.xyz, eye) + v_params.z) / dot(v_normal.xyz, view_dir));
#ifdef COMPOSITE_BENT
    vec3 flat_normal = v_normal.xyz;
#endif
#ifdef COMPOSITE_BUMPY
    // The mirror's UVs where the pixel's ray meets it, with their screen derivatives, taken
    // here, before a pixel is left out below: a discard leaves the derivatives of the rest of
    // its 2x2 quad undefined (GLSL 4.10, section 8.9), and the normal map's filter needs them
    // (bent_normal).
    vec2 mirror_uv = vec2(dot(v_carry[0], at), dot(v_carry[1], at)) + v_carry[2].xy;
    vec2 mirror_uv_dx = dFdx(mirror_uv), mirror_uv_dy = dFdy(mirror_uv);
#endif
    // Only this frame's claims wrote the node image, inside the views' rectangles.
    vec2 level_px = gl_FragCoord.xy * to_reflection;
    if (any(lessThan(level_px, v_rect.xy)) || any(greaterThanEqual(level_px, v_rect.zw))) discard;
    ivec2 px = ivec2(level_px);  // inside the level: a pixel centre scaled (mirror_claim.frag), in v_rect
#ifdef COMPOSITE_FALLBACK
    // The parent view's own pixels of the surface; for an end view, those of them its image
    // from last frame did not hold.
    if (texelFetch(parent_nodes, px, 0).r != v_view || texelFetch(parent_surfaces, px, 0).r != v_ids.x) discard;
    if (v_ids.y != 0u) {  // (an end view's: its level was drawn, so the child images are its, not blank)
        ivec2 child = ivec2(gl_FragCoord.xy * to_child);
        if (texelFetch(reflection_nodes, child, 0).r != v_ids.y - 1u
                || texelFetch(reflection_seen, child, 0).r != NO_END_IMAGE) discard;
    }
    // (its seen pair is written below, once the ray's point on the surface is known)
#else
    if (texelFetch(reflection_nodes, px, 0).r != v_view) discard;
#endif
    FogWay parent_fog = fog_way(fog_from_eye ? eye : near.xyz / near.w, at, view_dir);
#ifndef COMPOSITE_FALLBACK
    uvec4 seen_pair = texelFetch(reflection_seen, px, 0);
    if (seen_pair.r == NO_END_IMAGE) discard;  // an end view's pixel last frame's image did not hold
    out_seen = carried_seen(seen_pair);
#else
    out_seen = seen_at(v_ids.x, length(at - eye) * v_way_scale);  // nothing followed: the surface itself, as its scene pass wrote it
#endif
#ifdef COMPOSITE_PORTAL
#ifdef COMPOSITE_FALLBACK
    // What lies beyond the partner along the carried ray, from the probes there or the sky.
    out_color = vec4(hdr_store(fog_over(fallback_environment(v_carry * at + v_place.yzw, v_carry * view_dir, 0.0),
                                        parent_fog)), 1.0);
#else
    // The sky beyond the partner, fogged along the carried ray from where it comes out of the
    // partner (its row carries the carry's translation in the tile's slots: height fog and
    // fog volumes there are the far side's).
    vec4 through = texel_for_texel ? texelFetch(reflection, px, 0) : textureLod(reflection, uv, 0.0);
    vec3 carried = normalize(v_carry * view_dir);
    vec3 beyond = fog_sky(textureLod(sky_map, carried, 0.0).rgb, v_carry * at + vec3(v_eye.w, v_tint.a, v_normal.w),
                          carried);
    out_color = vec4(hdr_store(fog_over(through.rgb + beyond * (1.0 - through.a), parent_fog)), 1.0);
#endif
#else
    float reflect_rate = v_params.x;
    float roughness = abs(v_params.y);  // (water: F0, negative on a partly faded view's row)
    vec3 normal = v_normal.xyz;
#ifdef COMPOSITE_WATER
    // Water seen from below (the camera under it): its row's F0 plus WATER_UNDERSIDE
    // (mirror_passes.water_row_f0); its normal faces down, towards the eye.
    bool underside = roughness >= WATER_UNDERSIDE;
    if (underside) roughness -= WATER_UNDERSIDE;
#endif
#ifdef COMPOSITE_BENT
    // A normal map bends the mirror (seed 000's future work: the reflection texture stays as
    // it is, only its lookup moves), and so do a water's ripples.  The pixel's ray meets the
    // mirror's plane at p, whose UVs give the map's normal.  The bent reflected ray, carried
    // back through the flat mirror, is the direction the mirror's image shows it in: its
    // vanishing point in the parent view is where the image holds what lies far along it
    // (exact for distant things, overstated for near ones).  A lookup that leaves this view's
    // pixels keeps the flat one.
#ifdef COMPOSITE_WATER
    // (the waves' normal is the top's: from below it is that normal turned over)
    vec3 top = underside ? -flat_normal : flat_normal;
#ifdef COMPOSITE_BUMPY
    vec3 along_u = normalize(v_carry[0] - dot(v_carry[0], flat_normal) * flat_normal);
    vec3 along_v = normalize(v_carry[1] - dot(v_carry[1], flat_normal) * flat_normal);
    normal = water_normal(along_u, along_v, top, mirror_uv, mirror_uv_dx, mirror_uv_dy, vec2(v_eye.w, v_normal.w),
                          v_tint.a, v_carry[2].z);
#else
    normal = top;
#endif
#ifdef RIPPLES
    normal = rippled_normal(normal, at);
#endif
    if (underside) normal = -normal;
#else
    vec3 along_u = normalize(v_carry[0] - dot(v_carry[0], flat_normal) * flat_normal);
    vec3 along_v = normalize(v_carry[1] - dot(v_carry[1], flat_normal) * flat_normal);
    normal = bent_normal(along_u, along_v, flat_normal, mirror_uv, mirror_uv_dx, mirror_uv_dy, v_carry[2].z);
#endif
#ifndef COMPOSITE_FALLBACK  // (a fallback has no image to look up)
    vec3 seen_dir = reflect(reflect(view_dir, normal), flat_normal);
    vec3 clip = v_project_dir * seen_dir;
    if (clip.z > 1e-6) {
        vec2 bent_uv = clip.xy / clip.z * 0.5 + 0.5;
        vec2 bent_level_px = bent_uv * parent_size * to_reflection;
        ivec2 bent_px = ivec2(bent_level_px);
        // Inside the view's rectangle (outside it the node image is an older frame's), on a
        // pixel the view shows.  The rectangle lies inside the level (view_plan.level_rects),
        // so the bent fetches are tested in range before they are read (&& short-circuits).
        if (all(greaterThanEqual(bent_level_px, v_rect.xy)) && all(lessThan(bent_level_px, v_rect.zw))
                && texelFetch(reflection_nodes, bent_px, 0).r == v_view
                && texelFetch(reflection_seen, bent_px, 0).r != NO_END_IMAGE) {
            uv = bent_uv;
            texel_for_texel = false;
            level_px = bent_level_px;
            px = bent_px;
            out_seen = carried_seen(texelFetch(reflection_seen, px, 0));
        }
    }
#endif
#endif
    vec3 r = reflect(view_dir, normal);
#ifdef COMPOSITE_FALLBACK
    // No view: nothing reflected, so all of it is the environment (the probes' or the sky's).
    vec3 radiance = fallback_environment(at, r, roughness);
#else
#ifdef COMPOSITE_ROUGH
    // A rough mirror reads the blurred mips of its own tile (the level's would mix in its
    // neighbours' reflections).
    float lod = roughness_lod_bias(roughness);
    float scale = v_tint.a;
    float tile_lod = clamp(lod + log2(scale), 0.0, log2(ROUGH_TILE));
    float inset = 0.5 * exp2(ceil(tile_lod));  // keep every tap of that mip inside the tile
    vec2 local = clamp((level_px - v_rect.xy) * scale, vec2(inset), vec2(ROUGH_TILE - inset));
    vec4 seen = textureLod(rough_atlas, (vec2(v_eye.w, v_normal.w) + local) / atlas_size, tile_lod);
#else
    // A perfect mirror reads its image 1:1.
    float lod = 0.0;
    vec4 seen = texel_for_texel ? texelFetch(reflection, px, 0) : textureLod(reflection, uv, 0.0);
#endif
#if defined(GENERATED_SKY) && !defined(COMPOSITE_ROUGH)
    vec3 environment = fog_sky(generated_sky(r), at, r);
#else
    vec3 environment = fog_sky(textureLod(sky_map, r, lod).rgb, at, r);
#endif
    vec3 radiance = seen.rgb + environment * (1.0 - seen.a);
#endif
#ifdef COMPOSITE_WATER
    // Water: what is reflected (tinted) over the surface's own pixels, which show what lies
    // below, by the Fresnel reflectance at this pixel's angle (reflect_rate scales it).
    float weight = (underside ? water_fresnel_inside(normal, -view_dir, roughness)
                              : water_fresnel(normal, -view_dir, roughness)) * reflect_rate;
#else
    vec3 reflected = ggx_reflect(normal, r, -view_dir, radiance, v_tint.rgb, roughness);
    float weight = reflect_rate;
#endif
#ifdef COMPOSITE_FALLBACK
    weight = fallback_alpha(weight);
#endif
    // The parent's air over the reflection as a whole: blended over the surface's own pixels
    // (fogged by the same air in the parent's scene pass), the pixel is fogged all the way.
#if defined(COMPOSITE_WATER) && defined(WATER_REFRACTION)
    // (the reflection by its weight over what is below, bent: the pixel written whole)
#ifndef COMPOSITE_FALLBACK
    // A partly faded water's view blends over its fallback, which bent what is below and
    // wrote the pixel whole (a view's composite bending it again would bend the fallback's
    // reflection too, by the Fresnel weight of the pixel its ray lands on).
    if (v_params.y < 0.0)
        out_color = vec4(hdr_store(fog_over(radiance * v_tint.rgb, parent_fog)), weight);
    else
#endif
    out_color = vec4(hdr_store(mix(water_below(at, view_dir, normal, v_normal.xyz, roughness, underside, parent_fog),
                                   fog_over(radiance * v_tint.rgb, parent_fog), weight)), 1.0);
#elif defined(COMPOSITE_WATER)
    out_color = vec4(hdr_store(fog_over(radiance * v_tint.rgb, parent_fog)), weight);
#else
    out_color = vec4(hdr_store(fog_over(reflected, parent_fog)), weight);
#endif
#endif
#ifdef SURFACE_MOTION
    out_seen.ba = floatBitsToUint(uintBitsToFloat(out_seen.ba) + surface_moved(eye, view_dir, uintBitsToFloat(out_seen.g)));
#endif
}
