// Subsurface scattering's diffuse light (Material.subsurface; engine/render/subsurface.py):
// pre-integrated over a sphere with Burley's diffusion profile, so where a surface curves the
// light it takes in spreads under it, each colour as far as its own distance: softer towards
// the terminator, past it, in the colour that travels furthest.  Only the SUBSURFACE builds hold
// it; needs lights.glsl, shadows.glsl and ambient.glsl (the table rides in the alpha of the
// environment BRDF's rows).
//
// The curvature is the mesh's own normal's change (interpolated: a normal map's bumps do not
// bend the light under them) over the position's across the pixel, taken once before any
// branch (derivatives stay within a triangle, so a flat face's is 0 up to its edges and a flat
// wall is lit as Lambert lights it).  Both ways on screen together: a sphere's 1 / r; less
// than the sharper of a candle's two curvatures.
//
// Shadows: the table already counts the sphere's own shadow (its far side takes no light), so
// past the terminator the scattered share is shadow-tested where the light enters the sphere
// curved as the surface is here: the point moved towards the light by that sphere's chord
// (subsurface_shadow_point; SUBSURFACE_CHORD times it, so a surface curved less one way than the
// other, whose chord is longer, is left too).  A caster between the light and the surface still
// shadows the light scattered from it; the surface's own body does not cut the wrapped light
// off (where a binary shadow began it would show as an edge across the glow).
#ifdef SUBSURFACE
const float SUBSURFACE_CHORD = 1.25;
uniform vec4 subsurface;  // rgb: each channel's profile distance d (metres), a: the share scattered (its weight)
float subsurface_curvature = 0.0;   // 1 / r here
vec3 subsurface_spread = vec3(0.0);  // each channel's d / r here

// From the mesh's normal and the position (before any branch: derivatives).
void subsurface_begin(vec3 normal, vec3 position) {
    vec3 nx = dFdx(normal), ny = dFdy(normal), px = dFdx(position), py = dFdy(position);
    subsurface_curvature = sqrt((dot(nx, nx) + dot(ny, ny)) / max(dot(px, px) + dot(py, py), 1e-24));
    subsurface_spread = subsurface.rgb * subsurface_curvature;
}

// Where the scattered share of the light from ``l`` is shadow-tested (and the normal there,
// ``at_normal``): the point where the light reaches it; past the terminator, where the light
// enters the sphere of radius 1 / curvature on its way to the point (the chord -2 r n.l along
// the light, its normal there the point's reflected about the light's plane), a little further
// (the point itself where the surface is flat: the table gives it nothing there).
vec3 subsurface_shadow_point(vec3 position, vec3 normal, vec3 l, out vec3 at_normal) {
    at_normal = normal;
    float nl = dot(normal, l);
    if (nl >= 0.0 || subsurface_curvature < 1e-6) return position;
    at_normal = normal - 2.0 * nl * l;
    return position + l * (-2.0 * nl * SUBSURFACE_CHORD / subsurface_curvature);
}

// The point lights' shadows (shadows.glsl's slots) for the scattered share: each slot's looked
// up at subsurface_shadow_point for its own light.
vec4 subsurface_point_shadows(vec3 position, vec3 normal) {
    vec3 at0 = position, at1 = position, n0 = normal, n1 = normal;
#ifdef POINT_SHADOWS
    int i0 = shadows.point_light[0];
    if (i0 >= 0) at0 = subsurface_shadow_point(position, normal, normalize(lights.point_pos[i0].xyz - position), n0);
#if POINT_SHADOWS > 1
    int i1 = shadows.point_light[1];
    if (i1 >= 0) at1 = subsurface_shadow_point(position, normal, normalize(lights.point_pos[i1].xyz - position), n1);
#endif
#endif
    return point_shadows_at(at0, n0, at1, n1);
}

// D(n.l, s) - max(n.l, 0) from the table: the columns n.l in two halves, so the kink at 0 is
// never filtered across; the rows s / (1 + s).
float subsurface_delta(float nl, float spread) {
    const float half_size = float(ENVIRONMENT_BRDF_SIZE / 2);
    float column = nl < 0.0 ? (nl + 1.0) * (half_size - 1.0)
                            : half_size + nl * (float(ENVIRONMENT_BRDF_SIZE) - half_size - 1.0);
    vec2 texel = vec2(column, spread / (1.0 + spread) * float(ENVIRONMENT_BRDF_SIZE - 1))
                 + vec2(0.5, 0.5 + float(MAX_IRRADIANCE_PROBES));
    return textureLod(irradiance_table, texel / vec2(textureSize(irradiance_table, 0)), 0.0).a;
}

// The light from all round, scattered (engine/render/subsurface.py: D's Legendre moments over
// Lambert's, r_1 and r_2 at s / (1 + s), in the column beside the table): every E(n) read
// between subsurface_bands_begin and subsurface_bands_end has its bands 1 and 2 weighed per
// channel, the share not scattered as Lambert (1), the rest by r_l at its channel's d / r.
vec2 subsurface_bands(float spread) {
    vec2 texel = vec2(float(SUBSURFACE_BANDS_COLUMN) + 0.5,
                      spread / (1.0 + spread) * float(ENVIRONMENT_BRDF_SIZE - 1) + 0.5 + float(MAX_IRRADIANCE_PROBES));
    return textureLod(irradiance_table, texel / vec2(textureSize(irradiance_table, 0)), 0.0).rg;
}

void subsurface_bands_begin() {
    vec2 r = subsurface_bands(subsurface_spread.r), g = subsurface_bands(subsurface_spread.g),
         b = subsurface_bands(subsurface_spread.b);
    sh_band1 = mix(vec3(1.0), vec3(r.x, g.x, b.x), subsurface.a);
    sh_band2 = mix(vec3(1.0), vec3(r.y, g.y, b.y), subsurface.a);
}

void subsurface_bands_end() {
    sh_band1 = vec3(1.0);
    sh_band2 = vec3(1.0);
}

// The diffuse light's weight per channel for a light at signed ``nl`` (the shading normal's
// cosine to it): Lambert's max(n.l, 0) x ``lit`` for the share not scattered, the table's
// D(n.l, d / r) x ``lit_beneath`` (its shadow looked up at subsurface_shadow_point) for the rest.
vec3 subsurface_diffuse(float nl, float lit, float lit_beneath) {
    float front = max(nl, 0.0);
    vec3 scattered = max(vec3(front) + vec3(subsurface_delta(nl, subsurface_spread.r),
                                            subsurface_delta(nl, subsurface_spread.g),
                                            subsurface_delta(nl, subsurface_spread.b)), vec3(0.0));
    return vec3((1.0 - subsurface.a) * front * lit) + (subsurface.a * lit_beneath) * scattered;
}
#endif
