// Subsurface scattering's diffuse light (Material.subsurface; engine/render/subsurface.py):
// pre-integrated over a sphere with Burley's diffusion profile, so where a surface curves the
// light it takes in spreads under it, each colour as far as its own distance: softer towards
// the terminator, past it, in the colour that travels furthest.  Only the SUBSURFACE builds hold
// it; needs lights.glsl, shadows.glsl and ambient.glsl (the table rides in the alpha of the
// environment BRDF's rows).
//
// The curvature is the normal's change over the position's across the pixel (the mesh's own
// normal, interpolated: a normal map's bumps do not bend the light under them), found once
// before any branch; derivatives stay within a triangle, so a flat face's is 0 up to its edges
// and a flat wall is lit as Lambert lights it.
//
// Shadows: the table already counts the sphere's own shadow (its far side takes no light), so
// past the terminator the scattered share is shadow-tested where the light still reaches the
// sphere curved as the surface is here: the point moved along the surface towards the light,
// to that sphere's terminator (subsurface_shadow_point), at most ``subsurface_reach`` (twice the
// longest distance: the table's light past the terminator is nearly all within it), so a
// caster's shadow still falls on it and the surface's own does not cut the wrapped light off.
// Further round, the surface's own shadow falls.
#ifdef SUBSURFACE
uniform vec4 subsurface;  // rgb: each channel's profile distance d (metres), a: the share scattered (its weight)
vec3 subsurface_spread = vec3(0.0);  // each channel's d / r here (r: the radius of curvature)
float subsurface_curvature = 0.0;    // 1 / r here
float subsurface_reach = 0.0;        // how far (metres) its share's shadow is looked up towards a light behind it

// From the mesh's normal and the position (before any branch: derivatives).
void subsurface_begin(vec3 normal, vec3 position) {
    vec3 nx = dFdx(normal), ny = dFdy(normal), px = dFdx(position), py = dFdy(position);
    float curvature = sqrt((dot(nx, nx) + dot(ny, ny)) / max(dot(px, px) + dot(py, py), 1e-24));
    subsurface_curvature = curvature;
    subsurface_spread = subsurface.rgb * curvature;
    subsurface_reach = 2.0 * max(max(subsurface.r, subsurface.g), subsurface.b);
}

// Where the scattered share of the light coming from ``l`` is shadow-tested: the point where
// the light reaches it; past the terminator, moved along the surface towards the light by the
// arc to the terminator of the sphere of radius 1 / curvature, at most subsurface_reach.
vec3 subsurface_shadow_point(vec3 position, vec3 normal, vec3 l) {
    float nl = dot(normal, l);
    vec3 along = l - nl * normal;
    float across = length(along);
    if (nl >= 0.0 || across < 1e-4) return position;
    float arc = asin(min(-nl, 1.0)) / max(subsurface_curvature, 1e-6);
    return position + along * (min(arc, subsurface_reach) / across);
}

// The point lights' shadows (shadows.glsl's slots) for the scattered share: each slot's looked
// up at subsurface_shadow_point for its own light.
vec4 subsurface_point_shadows(vec3 position, vec3 normal) {
    vec3 at0 = position, at1 = position;
#ifdef POINT_SHADOWS
    int i0 = shadows.point_light[0];
    if (i0 >= 0) at0 = subsurface_shadow_point(position, normal, normalize(lights.point_pos[i0].xyz - position));
#if POINT_SHADOWS > 1
    int i1 = shadows.point_light[1];
    if (i1 >= 0) at1 = subsurface_shadow_point(position, normal, normalize(lights.point_pos[i1].xyz - position));
#endif
#endif
    return point_shadows_at(at0, at1, normal);
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
