// Rectangle lights (PointLight.rectangle): a rectangle of even radiance lights a point with
// every part of it above the point's horizon; a tube (PointLight.length) is lit as one.  Its rows (light_rules.lamp_rectangle, carried
// through mirrors and portals by carried_rectangle): xyz its half sides U and V, the first
// row's w its front's sign over its area (0: no rectangle), so the front is sign x (U x V)
// and the radiance is the light's colour x intensity x |w|.
//
// - Diffuse: the polygon's form factor, the integral of n.l over the rectangle's solid angle
//   clipped to the horizon (Lambert's edge sum), exact.
// - Highlight: linearly transformed cosines (Heitz, Dupuy, Hill and Neubelt, "Real-Time
//   Polygonal-Light Shading with Linearly Transformed Cosines", 2016): GGX times n.l, for a
//   roughness and view angle, is close to a cosine lobe moved by a 3 x 3 matrix M; the
//   rectangle moved by M^-1 is then integrated as the diffuse one is, times the lobe's
//   magnitude and the Fresnel of the light's mean way in.  The matrices were fitted to this
//   engine's GGX (ggx.glsl) by engine/render/ltc_fit.py; they ride in rows of the irradiance
//   table below the environment BRDF's (engine/render/irradiance.py: no sampler of their own).
// - An image on its face (PointLight.cookie on a rectangle: a screen, a stained-glass window):
//   each integral times the image's colour its lobe sees, a 2 x 2 quadrature over the face's
//   quarters: each quarter's image prefiltered by the mip chain and read where the lobe's mean
//   way over it (its vector form factor) meets it, at the level of the lobe's footprint there
//   (Heitz et al. 2016, section 5, per quarter), weighted by its share of the integral (exact
//   for an even image).  In the PANEL_PICTURES builds, the image a layer of the cookie array
//   (the rows' v.w: -1 - layer).
// Needs ggx.glsl (PI) and ambient.glsl (irradiance_table).  Only the RECT_LIGHTS builds hold
// it (frames where a kept light is a rectangle).
#ifdef RECT_LIGHTS

// A rectangle light's corners as seen from a point, and its radiance there (0 behind it).
struct RectLight {
    vec3 corner[4];   // from the point to each corner, around the rectangle
    float radiance;   // |w| in front of it (times the light's colour x intensity), else 0
    bool shape;       // whether the light is a rectangle at all
    float face;       // the layer of the image on its face in the cookie array (-1: none)
};

// ``to_centre``: from the point to the rectangle's centre; ``u``, ``v``: its rows.  A tube
// (PointLight.length; v.w its radius R, u its half length along its axis, u.w one over its
// length x 2 R): the rectangle through its axis, 2 R wide, turned about the axis to face the
// point.  All of a thin Lambertian cylinder's elements and all of that rectangle's lie in the
// plane of the axis and the point, so each sends the point the same light along the same way
// (its projected width times sin of the way's angle from the axis): its light is the tube's.
RectLight rect_light(vec4 u, vec4 v, vec3 to_centre) {
    RectLight rect;
    rect.shape = u.w != 0.0;
    rect.face = v.w < 0.0 ? -v.w - 1.0 : -1.0;
    vec3 side = v.xyz;
    bool tube = v.w > 0.0;
    if (tube) {
        // Across the axis and the way to the point: the rectangle's front, cross(u, side), then
        // faces the point (u (u.c) - c |u|^2 against -c: |u|^2 |c|^2 - (u.c)^2 >= 0).
        vec3 across = cross(u.xyz, to_centre);
        float length2 = dot(across, across);
        vec3 any_way = abs(u.x) < 0.9 * length(u.xyz) ? vec3(1.0, 0.0, 0.0) : vec3(0.0, 1.0, 0.0);
        side = (length2 > 1e-12 ? across * inversesqrt(length2) : normalize(cross(u.xyz, any_way))) * v.w;
    }
    rect.corner[0] = to_centre - u.xyz - side;
    rect.corner[1] = to_centre + u.xyz - side;
    rect.corner[2] = to_centre + u.xyz + side;
    rect.corner[3] = to_centre - u.xyz + side;
    vec3 front = sign(u.w) * cross(u.xyz, side);
    rect.radiance = tube || dot(-to_centre, front) > 0.0 ? abs(u.w) : 0.0;
    return rect;
}

// acos(x) / sqrt(1 - x^2), an edge's angle over its sine from its cosine x: for x >= 0 a
// rational fit (least squares in relative error, fitted here: within 1.3e-6 of it from 0 to 1,
// and 1 at x = 1, so the tiny angles a far light's edges subtend lose nothing, where acos of
// a dot product near 1 would in float32), for x < 0 from pi / sin - the fit at -x.  Cheaper on
// llvmpipe than atan: a rectangle light's two integrals cost a quarter less.
float angle_over_sine(float x) {
    float y = abs(x);
    float f = (5.44874623 + (3.1331107 + 0.08964956 * y) * y) / (3.46878408 + (4.2027139 + y) * y);
    return x >= 0.0 ? f : PI * inversesqrt(max(1.0 - x * x, 1e-7)) - f;
}

// One edge's share of the integral below (unit ``a`` and ``b``): its angle times its plane's
// unit normal, i.e. a x b times the angle over its sine.
vec3 edge_share(vec3 a, vec3 b) {
    return cross(a, b) * angle_over_sine(dot(a, b));
}

// An edge of a polygon clipped to z >= 0 (unit corners): its share (0 below the horizon), and
// where it leaves the upper half (``exit``) or enters it (``entry``), if it does.  The cut of
// the chord is on the edge's great circle, so normalised it is the arc's.
vec3 clipped_edge(vec3 from, vec3 to, inout vec3 exit, inout vec3 entry) {
    bool from_up = from.z >= 0.0, to_up = to.z >= 0.0;
    vec3 cut = normalize(mix(from, to, from.z / (from.z - to.z + (from_up == to_up ? 1.0 : 0.0))));
    if (from_up && !to_up) exit = cut;
    if (!from_up && to_up) entry = cut;
    return from_up || to_up ? edge_share(from_up ? from : cut, to_up ? to : cut) : vec3(0.0);
}

// The vector form factor of the spherical polygon a, b, c, d (directions from the point, any
// length, in a frame whose z is the normal) clipped to z >= 0, over 2 pi: its z the integral of
// max(z, 0) / pi over it (Lambert's edge sum), its direction the light's mean way in.  Each
// edge's part above the horizon and, where the quad crosses it, the stretch of the horizon
// from where it leaves to where it comes back.  Straight-line code, no array: llvmpipe spills
// a clipped polygon's array to memory (the rectangle's light cost a frame 1.95 x its plain
// one, 1.56 x without).  Turned to z >= 0 (the winding's sign taken off: rect_light tells
// front from back).
vec3 clamped_cosine_vector(vec3 a, vec3 b, vec3 c, vec3 d) {
    a = normalize(a); b = normalize(b); c = normalize(c); d = normalize(d);
    vec3 exit = vec3(0.0, 0.0, 1.0), entry = vec3(0.0, 0.0, 1.0);
    vec3 sum = clipped_edge(a, b, exit, entry) + clipped_edge(b, c, exit, entry)
             + clipped_edge(c, d, exit, entry) + clipped_edge(d, a, exit, entry)
             + edge_share(exit, entry);   // (exit = entry, adding 0, where none crossed)
    return (sum.z < 0.0 ? -sum : sum) / (2.0 * PI);
}

// The colour of the image on a rectangle's face (rect.face) that a cosine lobe about z sees
// over the part of the face with corners ``a``, ``b``, ``d`` (corners 0, 1 and 3 of it, in the
// lobe's frame: a quarter of the face, or all of it) and ``towards`` that part's mean way in
// (clamped_cosine_vector): the image where that way meets the face (inside the part: a mean
// of directions to it), at the mip level as wide as the lobe's footprint there: 1.5 x the
// distance to the face's plane over the part's size (half a cosine lobe's weight on a plane
// at distance r falls within r of its foot; 1.5 fitted against the panel cut into patches,
// tests/test_rect_light_images.py), at most the level where the part is one texel.  The part
// is the image's square from ``offset`` to ``offset + scale`` (fractions of it, from corner 0).
// The image's right towards the entity's -X, its top towards +Y: it reads as a screen does
// from in front.  (PANEL_PICTURES builds: the image array is spot_cookie.glsl's.)
#ifdef PANEL_PICTURES
vec3 face_read(RectLight rect, vec3 a, vec3 b, vec3 d, vec3 towards, vec2 offset, float scale) {
    vec3 across = b - a, up = d - a;
    vec3 w = cross(across, up);
    float area = length(w);
    float reach = dot(w, a);   // the distance to the face's plane x its area
    float along = dot(w, towards);
    vec3 q = towards * (reach / (abs(along) > 1e-30 ? along : 1e-30)) - a;
    float aa = dot(across, across), au = dot(across, up), uu = dot(up, up);
    vec2 st = vec2(uu * dot(q, across) - au * dot(q, up), aa * dot(q, up) - au * dot(q, across))
              / max(aa * uu - au * au, 1e-30);
    float size = float(textureSize(spot_cookies, 0).x) * scale;   // the part's texels across
    float lod = clamp(log2(1.5 * abs(reach) / (area * sqrt(area)) * size), 0.0, log2(size));
    // (kept a texel of that level inside the part: past it lie the other parts' colours, and
    // the array wraps across for all-round lights' images)
    float margin = 0.5 * exp2(min(ceil(lod), log2(size))) / size;
    vec2 at = offset + scale * clamp(st, margin, 1.0 - margin);
    return textureLod(spot_cookies, vec3(1.0 - at.x, at.y, rect.face), lod).rgb;
}
#endif

// The colour of the image on a rectangle's face (rect.face; white without one) that a
// cosine lobe about z sees, the corners ``a``, ``b``, ``c``, ``d`` (rect_light's 0 to 3) in the
// lobe's frame and ``towards`` its mean way in over the whole face: a 2 x 2 quadrature of the
// lobe over the face's quarters, each quarter's colour (face_read at its own mean way in)
// weighted by its share of the integral.  One lookup for the whole face cannot weigh the
// image by the lobe's smooth falloff: a rough metal's lobe that takes in the whole panel read
// the side it leans to too strongly (0.12 of the red share in the median at roughness 0.5;
// the quarters' 0.026: tests/test_rect_light_images.py).  The quarters' vector form factors
// are Lambert's edge sums without the horizon's clipping (exact for a face above the
// horizon; below it they only weigh colours): twelve edges, each inner one shared by two
// quarters (four clipped integrals made the pictured panel's frame 3.8 x its point light's on
// llvmpipe, these 3.1 x).
vec3 rect_face(RectLight rect, vec3 a, vec3 b, vec3 c, vec3 d, vec3 towards) {
#ifdef PANEL_PICTURES
    if (rect.face >= 0.0) {
        vec3 ab = 0.5 * (a + b), bc = 0.5 * (b + c), cd = 0.5 * (c + d), da = 0.5 * (d + a);
        vec3 m = 0.25 * (a + b + c + d);
        vec3 na = normalize(a), nb = normalize(b), nc = normalize(c), nd = normalize(d);
        vec3 nab = normalize(ab), nbc = normalize(bc), ncd = normalize(cd), nda = normalize(da);
        vec3 nm = normalize(m);
        vec3 ab_m = edge_share(nab, nm), bc_m = edge_share(nbc, nm), cd_m = edge_share(ncd, nm);
        vec3 da_m = edge_share(nda, nm);
        vec3 q0 = edge_share(na, nab) + ab_m - da_m + edge_share(nda, na);
        vec3 q1 = edge_share(nab, nb) + edge_share(nb, nbc) + bc_m - ab_m;
        vec3 q2 = edge_share(nbc, nc) + edge_share(nc, ncd) + cd_m - bc_m;
        vec3 q3 = edge_share(ncd, nd) + edge_share(nd, nda) + da_m - cd_m;
        float turn = q0.z + q1.z + q2.z + q3.z < 0.0 ? -1.0 : 1.0;   // (the winding's sign off)
        q0 *= turn; q1 *= turn; q2 *= turn; q3 *= turn;
        float w0 = max(q0.z, 0.0), w1 = max(q1.z, 0.0), w2 = max(q2.z, 0.0), w3 = max(q3.z, 0.0);
        float weight = w0 + w1 + w2 + w3;
        if (weight > 1e-20) {
            return (face_read(rect, a, ab, da, q0, vec2(0.0, 0.0), 0.5) * w0
                  + face_read(rect, ab, b, m, q1, vec2(0.5, 0.0), 0.5) * w1
                  + face_read(rect, m, bc, cd, q2, vec2(0.5, 0.5), 0.5) * w2
                  + face_read(rect, da, m, d, q3, vec2(0.0, 0.5), 0.5) * w3) / weight;
        }
        return face_read(rect, a, b, d, towards, vec2(0.0), 1.0);
    }
#endif
    return vec3(1.0);
}

// The integral of max(n.l, 0) over the rectangle's solid angle (its irradiance per unit
// radiance): Lambertian light is the surface's diffuse colour x this x the radiance, times
// ``tint``, the colour its face's image gives that light (rect_face; white without one).
float rect_form_factor(RectLight rect, vec3 n, out vec3 tint) {
    vec3 t = abs(n.z) < 0.999 ? normalize(cross(n, vec3(0.0, 0.0, 1.0))) : vec3(1.0, 0.0, 0.0);
    mat3 to_frame = transpose(mat3(t, cross(n, t), n));
    vec3 a = to_frame * rect.corner[0], b = to_frame * rect.corner[1], c = to_frame * rect.corner[2];
    vec3 d = to_frame * rect.corner[3];
    vec3 f = clamped_cosine_vector(a, b, c, d);
    tint = rect_face(rect, a, b, c, d, f);
    return PI * f.z;
}

// The LTC table's entry at a roughness and n.v (ltc_fit.py's grid: roughness across,
// sqrt(1 - n.v) down), read between entries by bilinear filtering: M^-1 and the lobe's
// magnitude and Fresnel share.
void ltc_entry(float roughness, float nv, out mat3 inverse, out vec2 magnitude) {
    vec2 at = vec2(clamp(roughness, 0.0, 1.0), sqrt(clamp(1.0 - nv, 0.0, 1.0))) * float(LTC_SIZE - 1) + 0.5;
    vec2 size = vec2(textureSize(irradiance_table, 0));
    vec4 m = textureLod(irradiance_table, (at + vec2(0.0, float(LTC_ROW))) / size, 0.0);
    magnitude = textureLod(irradiance_table, (at + vec2(0.0, float(LTC_ROW + LTC_SIZE))) / size, 0.0).xy;
    inverse = mat3(vec3(m.x, 0.0, m.y), vec3(0.0, 1.0, 0.0), vec3(m.z, 0.0, m.w));  // (columns: ltc_fit.py's)
}

// The rectangle's GGX highlight per unit radiance towards ``v`` from a surface of normal
// ``n``, reflectance ``f0`` and ``roughness`` (ggx.glsl's), n.l included: the lobe's magnitude
// times the integral over the rectangle moved by M^-1, times Schlick's Fresnel at the half
// vector of the light's mean way in (the vector form factor taken back through M), not the
// lobe's average: at a grazing view the part of the lobe a light low over the horizon fills
// reflects several times the average (ltc_fit.py ltc_rect_specular's light_fresnel: a
// dielectric's highlight at views past 50 degrees within 9% at the 90th percentile, 64%
// with the average).
vec3 rect_highlight(RectLight rect, vec3 n, vec3 v, vec3 f0, float roughness) {
    float nv = clamp(dot(n, v), 1e-4, 1.0);
    vec3 t = v - n * dot(n, v);
    t = dot(t, t) > 1e-10 ? normalize(t) : (abs(n.z) < 0.999 ? normalize(cross(n, vec3(0.0, 0.0, 1.0)))
                                                               : vec3(1.0, 0.0, 0.0));
    mat3 inverse_m;
    vec2 magnitude;
    ltc_entry(roughness, nv, inverse_m, magnitude);
    mat3 frame = mat3(t, cross(n, t), n);
    mat3 to_lobe = inverse_m * transpose(frame);
    // (A tube's facing rectangle moved by M^-1 is the outline the moved tube shows from the
    // point too: the width its integral sees is along the moved plane's normal w', and M^-T w'
    // is across the axis and the way to the centre, as the world's rectangle's side is.)
    vec3 a = to_lobe * rect.corner[0], b = to_lobe * rect.corner[1], c = to_lobe * rect.corner[2];
    vec3 d = to_lobe * rect.corner[3];
    vec3 lobe = clamped_cosine_vector(a, b, c, d);
    vec3 mean = frame * (inverse(inverse_m) * lobe);   // the light's mean way in, in the world
    vec3 h = normalize(normalize(mean) + v);
    // (the face's image in the lobe's own space: the footprint of the cosine the lobe is there)
    return schlick_at(f0, dot(v, h)) * (magnitude.x * lobe.z) * rect_face(rect, a, b, c, d, lobe);
}
#endif
