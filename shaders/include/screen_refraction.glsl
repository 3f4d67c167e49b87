// Screen-space refraction (engine/render/screen_refraction.py): what the view drew behind a
// refracting surface (Refractive.screen), found along its refracted ray.
//
// The view's colour and window depth were copied (refraction_copy: rgb and a) after its
// opaque surfaces, sky, mirrors and portals and before the surfaces that refract them, so the
// ray can be followed past the surface it leaves.  Its segment (REFRACTION_REACH metres, cut
// short of the eye's plane) is stepped across the screen in at most REFRACTION_STEPS equal
// steps (a pixel each where it is shorter) with perspective-correct depth: the window depth
// and 1 / w are affine along the screen, so no division a sample (as the screen reflections'
// march, screen_march.glsl).  The first step whose end lies behind what is drawn is halved
// REFRACTION_REFINE times to where the ray goes behind, and taken where it lies there within
// REFRACTION_THICKNESS of the drawn surface (else it passed behind something: nothing found).
// A ray that comes to another view's pixels (the node image: a reflection level's views
// share one image) or leaves the view finds nothing.  A ray that stays in the view, in front
// of all it passes, and ends over the sky goes on to the sky: it finds the colour the view
// drew where the sky lies along it (its vanishing point, over sky all the way there:
// refraction_sky), the sky as the view drew it, its sun's disc as sharp, fog and clouds and
// all, which the probe's or the sky's cube (its texels, a probe's seen from its centre) is
// not.  A reflection level leaves its sky to its composite: where the ray's vanishing point
// lies over that, what the view drew there (see-through things, premultiplied, and how much
// of the pixel they cover: refraction_copy.frag) goes over the probe's or sky's image, as
// the level's composite lays its reflection over the environment (``uncovered``: the share
// of that image the find lets through).  Uses the Camera block (camera.glsl).
#define REFRACTION_STEPS 24
#define REFRACTION_REFINE 5
const float REFRACTION_REACH = 25.0;     // metres a refracted ray is followed (faded over its last quarter)
const float REFRACTION_THICKNESS = 0.5;  // metres behind a drawn surface a ray is still taken to meet it
const float REFRACTION_SPREAD = 4.0;     // copy pixels a pixel's rays may spread over at the find (faded from half)
const float REFRACTION_EDGE = 0.05;      // the share of the view's width and height a find fades out over at its edges

uniform sampler2D refraction_copy;  // rgb: the view's colour before its refracting surfaces, a: its window depth
                                    // (3 + coverage where a reflection level left its sky: refraction_copy.frag);
                                    // with its mips (a lod past the chain reads its last level)
#ifndef MASKED
uniform usampler2D node_map;        // which view of the level drew each pixel (a root's: all 0)
#endif

#define REFRACTION_SKY_CHECKS 4            // pixels between a ray's end and its vanishing point checked for sky
const float REFRACTION_SKY_ROUGHNESS = 0.1;  // a rougher surface's sky is its blurred cube's (faded from a tenth of it)

// Where the ray along unit ``direction`` that ended at pixel ``end`` over the sky reaches it:
// the view's colour at the ray's vanishing point, with its confidence (faded at the view's
// edges and as the surface roughens), where the pixels from the end to there all show the
// sky in this view; else nothing (a: 0).  ``uncovered``: the share of the probe's or sky's
// image to add under it (a reflection level's sky, left to its composite: 1 less what the
// level drew over it covers; 0 where the view drew its sky).
vec4 refraction_sky(vec2 end, vec3 direction, float roughness, vec2 corner, vec2 size, out float uncovered) {
    uncovered = 0.0;
    vec4 v = camera.view_proj * vec4(direction, 0.0);
    if (v.w <= 1e-6) return vec4(0.0);  // (away from the view, or across it in an orthographic one)
    vec2 vanishing = corner + (v.xy / v.w * 0.5 + 0.5) * size;
    if (any(lessThan(vanishing, corner + 0.5)) || any(greaterThan(vanishing, corner + size - 0.5))) return vec4(0.0);
    for (int i = 0; i <= REFRACTION_SKY_CHECKS; ++i) {
        ivec2 at = ivec2(mix(end, vanishing, float(i) / float(REFRACTION_SKY_CHECKS)));
        if (texelFetch(node_map, at, 0).r != node_index || texelFetch(refraction_copy, at, 0).a < 1.0)
            return vec4(0.0);
    }
    vec2 uv = (vanishing - corner) / size;
    vec2 edge = min(uv, 1.0 - uv);
    vec4 there = texelFetch(refraction_copy, ivec2(vanishing), 0);
    if (there.a > 1.5) uncovered = clamp(4.0 - there.a, 0.0, 1.0);  // (3 + its coverage: a level's sky)
    return vec4(there.rgb, smoothstep(0.0, REFRACTION_EDGE, min(edge.x, edge.y))
                * (1.0 - smoothstep(0.1 * REFRACTION_SKY_ROUGHNESS, REFRACTION_SKY_ROUGHNESS, roughness)));
}

// The world point the copy holds at a pixel (its window depth ``window``).
vec3 refraction_drawn_point(vec2 pixel, float window) {
    vec2 ndc = (pixel - camera.viewport.xy) / camera.viewport.zw * 2.0 - 1.0;
    vec4 world = camera.inv_view_proj * vec4(ndc, window * 2.0 - 1.0, 1.0);
    return world.xyz / world.w;
}

// What the view drew where the ray from ``origin`` (world) along the unit ``direction`` meets
// it (rgb, read at a mip level as wide as a lobe of ``roughness`` spreads there) and the
// confidence in it (a; 0: nothing found), faded at the view's edges, over the last quarter
// of the reach, by how far behind the drawn surface the ray was found, and where the rays of
// the pixel's neighbours land far apart: ``spread``, the radians the ray's direction turns
// from one pixel to the next (a curved surface's: a ball's reflection is a minified image of
// what is round it, most of all at its rim), times the way to the find, over more than
// REFRACTION_SPREAD of the copy's pixels (one texel read for a footprint that wide is noise:
// blocks and specks that change with every pixel's normal; the probe's or sky's image, read
// at a mip level for that footprint, says it instead, as the screen reflections' fade does).
vec4 screen_refraction(vec3 origin, vec3 direction, float roughness, float spread, out float uncovered) {
    uncovered = 0.0;
    vec4 h0 = camera.view_proj * vec4(origin, 1.0);
    float reach = REFRACTION_REACH;
    vec4 h1 = camera.view_proj * vec4(origin + direction * reach, 1.0);
    float w_least = 0.01 * h0.w;  // short of the eye's plane (w = 0), where the projection turns over
    if (h1.w < w_least) {
        reach *= (h0.w - w_least) / (h0.w - h1.w);
        h1 = camera.view_proj * vec4(origin + direction * reach, 1.0);
    }
    vec3 end = origin + direction * reach;
    vec2 corner = camera.viewport.xy, size = camera.viewport.zw;
    vec2 p0 = corner + (h0.xy / h0.w * 0.5 + 0.5) * size;
    vec2 p1 = corner + (h1.xy / h1.w * 0.5 + 0.5) * size;
    float z0 = 0.5 + 0.5 * h0.z / h0.w, z1 = 0.5 + 0.5 * h1.z / h1.w;  // window depths
    float k0 = 1.0 / h0.w, k1 = 1.0 / h1.w;
    float d0 = -(camera.view * vec4(origin, 1.0)).z * k0, d1 = -(camera.view * vec4(end, 1.0)).z * k1;
    // Cut the segment at the view's edges (its parameter along the screen line).
    vec2 delta = p1 - p0;
    float cut = 1.0;
    for (int axis = 0; axis < 2; ++axis) {
        float d = delta[axis];
        if (abs(d) > 1e-6) {
            float limit = d > 0.0 ? corner[axis] + size[axis] - 0.5 : corner[axis] + 0.5;
            cut = min(cut, max((limit - p0[axis]) / d, 0.0));
        }
    }
    p1 = mix(p0, p1, cut);
    z1 = mix(z0, z1, cut);
    k1 = mix(k0, k1, cut);
    d1 = mix(d0, d1, cut);
    float span = max(abs(p1.x - p0.x), abs(p1.y - p0.y));
    float steps = clamp(ceil(span), 1.0, float(REFRACTION_STEPS));  // (a ray along the eye's: one step, its own pixel)
    float lo = 0.0, hi = -1.0;
    bool stayed = true;  // in this view's pixels all the way
    for (int i = 1; i <= REFRACTION_STEPS; ++i) {
        if (float(i) > steps) break;
        float next = float(i) / steps;
        vec2 at = mix(p0, p1, next);
        if (texelFetch(node_map, ivec2(at), 0).r != node_index) {  // another view's pixels
            stayed = false;
            break;
        }
        if (mix(z0, z1, next) >= texelFetch(refraction_copy, ivec2(at), 0).a) {
            hi = next;
            break;
        }
        lo = next;
    }
    if (hi < 0.0) {
        // In front of all it passed: where it ends in the view over the sky, on to the sky.
        bool ended_over_sky = stayed && cut >= 1.0 && texelFetch(refraction_copy, ivec2(p1), 0).a >= 1.0;
        return ended_over_sky ? refraction_sky(p1, direction, roughness, corner, size, uncovered) : vec4(0.0);
    }
    for (int i = 0; i < REFRACTION_REFINE; ++i) {
        float mid = 0.5 * (lo + hi);
        if (mix(z0, z1, mid) >= texelFetch(refraction_copy, ivec2(mix(p0, p1, mid)), 0).a) hi = mid; else lo = mid;
    }
    // Where between them the ray meets what is drawn, by the secant of the two window-depth
    // gaps (a step a pixel long or less lies on one pixel's surface, but may span metres of
    // the ray: a ray along the eye's is one pixel from end to end).
    float before = texelFetch(refraction_copy, ivec2(mix(p0, p1, lo)), 0).a - mix(z0, z1, lo);
    float after = mix(z0, z1, hi) - texelFetch(refraction_copy, ivec2(mix(p0, p1, hi)), 0).a;
    hi = mix(lo, hi, clamp(before / max(before + after, 1e-12), 0.0, 1.0));
    vec2 found = mix(p0, p1, hi);
    float window = texelFetch(refraction_copy, ivec2(found), 0).a;
    if (window >= 1.0) return vec4(0.0);  // the far plane: the sky (the probe's or sky's image says it)
    vec3 point = refraction_drawn_point(floor(found) + 0.5, window);
    float drawn = -(camera.view * vec4(point, 1.0)).z;
    float gap = mix(d0, d1, hi) / mix(k0, k1, hi) - drawn;  // the ray's view depth there less the surface's
    if (gap > REFRACTION_THICKNESS) return vec4(0.0);
    float travelled = distance(point, origin);
    // Pixels a metre spans at the found depth (an orthographic view's, proj[3][3] 1: at any
    // depth); the lobe's width there (GGX's alpha radians).
    float pixels_a_metre = abs(camera.proj[1][1]) * 0.5 * size.y / mix(max(drawn, 1e-4), 1.0, camera.proj[3][3]);
    float lod = log2(max(roughness * roughness * travelled * pixels_a_metre, 1.0));  // (past its chain: its last level)
    vec2 uv = (found - corner) / size;
    vec2 edge = min(uv, 1.0 - uv);
    float confidence = smoothstep(0.0, REFRACTION_EDGE, min(edge.x, edge.y))
        * (1.0 - smoothstep(0.75 * REFRACTION_REACH, REFRACTION_REACH, travelled))
        * (1.0 - smoothstep(0.25 * REFRACTION_THICKNESS, REFRACTION_THICKNESS, gap))
        * (1.0 - smoothstep(0.5 * REFRACTION_SPREAD, REFRACTION_SPREAD, spread * travelled * pixels_a_metre));
    // (at the found pixel's centre: a ray along the eye's reads its own pixel, not a blend of its neighbours)
    return vec4(textureLod(refraction_copy, (floor(found) + 0.5) / vec2(textureSize(refraction_copy, 0)), lod).rgb,
                confidence);
}
