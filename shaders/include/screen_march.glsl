// The march of screen-space reflections (engine/render/screen_reflections.py): a pixel's
// reflected ray followed across the main view's depth image to what the view drew there.
//
// The ray is stepped in screen space with perspective-correct depth, a stride of pixels a
// step (McGuire and Mara, "Efficient GPU Screen-Space Ray Tracing", JCGT 2014), comparing
// window depths (affine in 1 / depth, so linear along the screen: no division a sample).
// Where a step's end finds the ray behind what is drawn, the step is halved REFINE times to
// where it went behind, and taken if it lies there within ``thickness`` behind the surface;
// where the ray went behind the plane the last two steps' ends showed but is in front at the
// end (the surface ended within the step), the step is walked in SUBSTEPS parts.
// Needs STEPS, REFINE and SUBSTEPS defined; view_depth.glsl's uniforms are the view's.  A
// reflection level's build (LEVEL_VIEWS) marches the rays of one view of the level, `node`:
// a ray that comes to another view's pixels ends there, found nothing (as at the screen's edge).
#include "view_depth.glsl"
#ifdef LEVEL_VIEWS
#include "level_nodes.glsl"
uniform uint node;  // the view this draw marches
#endif

uniform sampler2D depth_map;       // the main view's depth (read through a sampler that compares nothing)
uniform sampler2D normal_map;      // rgb: the shading normal (world) the reflecting surfaces wrote, a: entity bits 11-21
uniform mat4 projection;           // the view's
uniform mat3 view_rotation;        // world -> view directions
uniform float near_plane;          // view depth of the near plane (> 0)
uniform float max_distance;        // ScreenReflections.max_distance
uniform float thickness;           // ScreenReflections.thickness
uniform float edge_fade;           // ScreenReflections.edge_fade

// The view depth (> 0) drawn at a pixel; the sky's is far beyond any ray.
float drawn_depth(vec2 pixel) {
    float depth = texelFetch(depth_map, ivec2(pixel), 0).r;
    return depth >= 1.0 ? 1e30 : -view_z(depth, floor(pixel) + 0.5);
}

// The screen position (pixels) of the view-space point p.
vec2 on_screen(vec3 p, out float k) {
    vec4 h = projection * vec4(p, 1.0);
    k = 1.0 / h.w;
    return (h.xy * k * 0.5 + 0.5) * depth_size;
}

// The ray's segment on the screen, from p0 to p1 (pixels), with q / k its view depth along
// it (q and k, as 1 / depth, are linear in screen space): main's, for the functions below.
vec2 p0, p1;
float q0, q1, k0, k1;

// The ray's view depth at parameter t of its segment.
float depth_along(float t) {
    return -mix(q0, q1, t) / mix(k0, k1, t);
}

// The ray's window depth at parameter t (what the depth image holds for a point there:
// 0.5 + 0.5 (P[3][2] k - P[2][2] + an oblique near plane's term), k = 1 / view depth, all
// linear along the screen): the march compares it with the image's texels as they are, no
// division a sample.
float window_along(float t) {
    return 0.5 + 0.5 * (unproject_z.y * mix(k0, k1, t) - unproject_z.x + oblique_at(mix(p0, p1, t)));
}

float drawn_window(vec2 pixel) {
    return texelFetch(depth_map, ivec2(pixel), 0).r;
}

// Where between lo (the ray in front of what is drawn) and hi (behind it) the ray goes
// behind, halved REFINE times into [lo, hi]; true if it lies there within the thickness
// behind the surface drawn (else it passed behind something: no hit there).
bool crossing(inout float lo, inout float hi) {
    for (int i = 0; i < REFINE; ++i) {
        float mid = 0.5 * (lo + hi);
        if (window_along(mid) >= drawn_window(mix(p0, p1, mid))) hi = mid; else lo = mid;
    }
    return depth_along(hi) - drawn_depth(mix(p0, p1, hi)) <= thickness;
}

// Whether the surface drawn at a pixel faces against the direction d (view space); an
// unlit mirror's (no normal written) is taken to.
bool faces(vec2 pixel, vec3 d) {
    vec3 n = texelFetch(normal_map, ivec2(pixel), 0).xyz;
    return dot(n, n) == 0.0 || dot(view_rotation * n, d) <= 0.0;
}

// The reflected ray of the surface drawn at ``pixel_centre`` (its window depth ``depth``, its
// world normal ``normal``) marched: where it meets what is drawn (``found``, pixels), and the
// confidence in that (0: nothing found), faded at the screen's edges, over the last quarter
// of max_distance and by how far behind the drawn surface the ray was found.
float march(vec2 pixel_centre, float depth, vec3 normal, out vec2 found) {
    found = vec2(0.0);
    vec3 origin = view_position(pixel_centre, depth);
    vec3 n = normalize(view_rotation * normal);
    vec3 r = normalize(reflect(normalize(origin), n));
    origin += n * (0.0002 * -origin.z);  // off the surface, as far as its depth's precision
    // The ray's far end: max_distance along it, or where it would cross the near plane.
    float length_ = (origin.z + r.z * max_distance > -near_plane) ? (-near_plane - origin.z) / r.z : max_distance;
    vec3 end = origin + r * length_;
    p0 = on_screen(origin, k0);
    p1 = on_screen(end, k1);
    // Cut the segment at the screen's edges (its parameter along the screen line).
    vec2 delta = p1 - p0;
    float cut = 1.0;
    for (int axis = 0; axis < 2; ++axis) {
        float d = delta[axis];
        if (abs(d) > 1e-6) {
            float limit = d > 0.0 ? depth_size[axis] - 0.5 : 0.5;
            cut = min(cut, max((limit - p0[axis]) / d, 0.0));
        }
    }
    // q / k is the view depth along the segment, linear in screen space (perspective-correct).
    q0 = origin.z * k0;
    q1 = end.z * k1;
    p1 = p0 + delta * cut;
    q1 = mix(q0, q1, cut);
    k1 = mix(k0, k1, cut);
    delta = p1 - p0;
    float span = max(abs(delta.x), abs(delta.y));
    if (span < 1.0) return 0.0;
    float stride = max(1.0, span / float(STEPS));
    float steps = min(float(STEPS), ceil(span / stride));
    float dt = stride / span;  // the segment's parameter a step

    // Where the ray is last known in front of what is drawn: a pixel out from its own (at
    // its own, a halving could settle on the surface it leaves, as depth's rounding goes).
    float t = 1.0 / span;
    float hi = -1.0;  // where the ray is first found behind what it meets (-1: nowhere)
    // What was drawn at the last two steps' ends (window depths, affine in 1 / depth): a
    // plane's is linear along the screen, so were the surface there to go on, this step's
    // end would show it at twice the last less the one before.  (At first: the pixel's own.)
    float drawn_before = depth, drawn_two_before = depth;
    float sub_steps = min(float(SUBSTEPS), ceil(stride));
    for (int i = 0; i < STEPS; ++i) {
        if (float(i) >= steps) break;
        float next = min(t + dt, 1.0);
#ifdef LEVEL_VIEWS
        if (node_at(mix(p0, p1, next)) != node) break;  // into another view's world
#endif
        float ray = window_along(next);
        float drawn_here = drawn_window(mix(p0, p1, next));
        if (ray >= drawn_here) {  // behind what is drawn at the step's end: where did it go behind?
            float a = t, b = next;
            if (crossing(a, b)) {
                hi = b;
                break;
            }
        } else if (i > 0 && ray > 2.0 * drawn_before - drawn_two_before) {
            // In front of what this end shows, but behind the surface the last two showed,
            // carried on to here: that surface ended within the step, maybe after the ray
            // met it (the corner of a box it skims past the top edge of).  Walk the step in parts.
            for (int j = 1; j < SUBSTEPS; ++j) {
                if (float(j) >= sub_steps) break;
                float at = t + dt * float(j) / sub_steps;
                if (window_along(at) >= drawn_window(mix(p0, p1, at))) {
                    float a = at - dt / sub_steps, b = at;
                    if (crossing(a, b)) hi = b;
                    break;
                }
            }
            if (hi >= 0.0) break;
        }
        drawn_two_before = drawn_before;
        drawn_before = drawn_here;
        t = next;
    }
    if (hi < 0.0) return 0.0;
    found = mix(p0, p1, hi);
    float found_depth = drawn_depth(found);
    if (found_depth > 1e29) return 0.0;
    // A surface the ray meets from behind (a table's top, over its underside) is not what it
    // would see there.  The pixel a step back along the ray counts too: at a silhouette the
    // hit pixel may show the face beyond the edge the ray met (a box's top over its front).
    vec2 back = found - normalize(p1 - p0);
    if (!faces(found, r) && !faces(back, r)) return 0.0;
    vec3 found_point = view_at(found, -found_depth);
    float travelled = length(found_point - origin);

    vec2 uv = found / depth_size;
    vec2 edge = min(uv, 1.0 - uv);
    // How far behind the drawn surface the ray is where it was found: about 0 where it
    // meets it, up to the thickness where it passes behind something (the underside of a
    // ball the view sees only the top of): those fade out over its last three quarters,
    // so what the view cannot show is not a hard-edged guess.
    float gap = depth_along(hi) - found_depth;
    return (edge_fade > 0.0 ? smoothstep(0.0, edge_fade, min(edge.x, edge.y)) : 1.0)
        * (1.0 - smoothstep(0.75 * max_distance, max_distance, travelled))
        * (1.0 - smoothstep(0.25 * thickness, thickness, gap));
}
