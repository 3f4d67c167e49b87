// Thin-film iridescence (Material.iridescence; glTF's KHR_materials_iridescence): a soap
// bubble's, an oil slick's or a beetle's colours, a film of index iridescence.y and
// iridescence.z nanometres over the surface.  Belcour and Barla, "A Practical Extension to
// Microfacet Theory for the Modeling of Varying Iridescence" (2017): the light reflected once
// at the film's top and after every round trip inside it (an Airy sum), each round trip
// delayed by the optical path 2 n d cos(theta) and shifted by the interfaces' phases; the
// spectrum that makes is integrated against the CIE colour-matching functions in closed
// form, their Gaussian fit in Fourier space (the paper's constants), keeping the first two
// orders, then XYZ to linear Rec.709.  The film's reflectance at the eye's angle is turned
// back into the F0 Schlick's form gives it there, so the lights' highlights and the split sum
// read it as any F0 (the glTF sample viewer's way).  Needs ggx.glsl (PI, schlick_at, f0_from_ior).
#ifdef IRIDESCENCE
uniform vec3 iridescence;  // x: its batch's Material.iridescence, y: the film's index, z: its thickness (nm)

// The XYZ colour of the cosine fringe of optical path difference ``opd`` (nm) and phase shift
// ``shift``, as linear Rec.709.
vec3 film_fringe(float opd, vec3 shift) {
    float k = 2.0 * PI * opd * 1.0e-9;  // the fringe's frequency in the spectrum's Fourier space
    vec3 height = vec3(5.4856e-13, 4.4201e-13, 5.2481e-13);
    vec3 centre = vec3(1.6810e+06, 1.7953e+06, 2.2084e+06);
    vec3 spread = vec3(4.3278e+09, 9.3046e+09, 6.6121e+09);
    vec3 xyz = height * sqrt(2.0 * PI * spread) * cos(centre * k + shift) * exp(-spread * k * k);
    xyz.x += 9.7470e-14 * sqrt(2.0 * PI * 4.5282e+09) * cos(2.2399e+06 * k + shift.x) * exp(-4.5282e+09 * k * k);
    xyz /= 1.0685e-7;
    // XYZ to linear Rec.709 (sRGB's primaries, D65), columns
    return mat3(3.2404542, -0.9692660, 0.0556434,
                -1.5371385, 1.8760108, -0.2040259,
                -0.4985314, 0.0415560, 1.0572252) * xyz;
}

// The film's reflectance seen at cos1 (the angle to the normal, in air) over a surface whose
// own F0 is base_f0.
vec3 film_reflectance(float cos1, vec3 base_f0) {
    float film = mix(1.0, iridescence.y, smoothstep(0.0, 0.03, iridescence.z));  // no film: air's index
    float sin2_squared = (1.0 - cos1 * cos1) / (film * film);
    if (sin2_squared >= 1.0) return vec3(1.0);  // total internal reflection inside the film
    float cos2 = sqrt(1.0 - sin2_squared);
    // Air to film: its reflectance, what it lets through both ways, and the phases.
    float r12 = schlick_at(vec3(f0_from_ior(film)), cos1).x;
    float t121 = 1.0 - r12;
    float phase21 = film < 1.0 ? 0.0 : PI;  // (the top's phase inside the film, on the way back out)
    // Film to surface: the surface's index from its F0 (air's Schlick inverted), its reflectance inside.
    vec3 root = sqrt(clamp(base_f0, 0.0, 0.9999));
    vec3 surface = (1.0 + root) / (1.0 - root);
    vec3 relative = surface / film;  // the surface's index against the film's
    vec3 r23 = schlick_at(vec3(f0_from_ior(relative.r), f0_from_ior(relative.g), f0_from_ior(relative.b)), cos2);
    vec3 phase23 = mix(vec3(0.0), vec3(PI), lessThan(surface, vec3(film)));
    float opd = 2.0 * film * iridescence.z * cos2;
    vec3 phase = phase21 + phase23;
    // The Airy sum: once off the top, then each round trip weaker by sqrt(r12 r23).
    vec3 r123 = clamp(r12 * r23, 1e-5, 0.9999);
    vec3 inside = t121 * t121 * r23 / (1.0 - r123);
    vec3 reflected = r12 + inside;
    vec3 order = inside - t121;
    for (int m = 1; m <= 2; ++m) {
        order *= sqrt(r123);
        reflected += order * 2.0 * film_fringe(float(m) * opd, float(m) * phase);
    }
    return max(reflected, vec3(0.0));
}

// The surface's F0 with the film on it, at n.v: the F0 whose Schlick curve passes through the
// film's reflectance there, mixed in by iridescence.x (and gone with the film's thickness:
// near grazing the inversion magnifies the sum's small terms, which a vanished film must not show).
vec3 iridescent_f0(vec3 f0, float nv) {
    float grazing = schlick_at(vec3(0.0), nv).x;  // (1 - n.v)^5
    vec3 film_f0 = clamp((film_reflectance(nv, f0) - grazing) / max(1.0 - grazing, 1e-4), 0.0, 1.0);
    return mix(f0, film_f0, iridescence.x * smoothstep(0.0, 0.03, iridescence.z));
}
#endif  // IRIDESCENCE
