// Tone curves: linear HDR (Rec. 709 primaries, exposed) in, linear [0, 1] out; the sRGB
// encoding comes after (color.glsl).  TONEMAP_CURVE picks one at build time
// (components/post.py TONEMAP_CURVES: 0 none, 1 aces, 2 agx, 3 pbr_neutral, defined as
// TONEMAP_NONE and so on by the shader library from that tuple), so a frame runs one
// curve's code, not all four (llvmpipe runs every branch).
//
// GLSL matrices are built column by column: each vec3 below is a column of the matrix as
// its reference writes it in rows.

#ifndef TONEMAP_CURVE
#define TONEMAP_CURVE TONEMAP_NONE
#endif

// ACES: Stephen Hill's fit of the ACES reference rendering transform and sRGB output
// transform (BakingLab, ACES.hlsl, 2016): sRGB -> AP1 with the RRT's saturation, a rational
// fit of RRT + ODT per channel, back to sRGB with the ODT's saturation.  The input is
// scaled by 1 / 0.6 first, as three.js does (mrdoob/three.js#19621), so that exposure 0
// keeps middle grey near where the plain look has it (Hill's fit alone darkens 0.18 to 0.11).
vec3 tonemap_aces(vec3 c) {
    const mat3 to_ap1 = mat3(vec3(0.59719, 0.07600, 0.02840),
                             vec3(0.35458, 0.90834, 0.13383),
                             vec3(0.04823, 0.01566, 0.83777));
    const mat3 from_ap1 = mat3(vec3(1.60475, -0.10208, -0.00327),
                               vec3(-0.53108, 1.10813, -0.07276),
                               vec3(-0.07367, -0.00605, 1.07602));
    vec3 v = to_ap1 * (c / 0.6);
    vec3 a = v * (v + 0.0245786) - 0.000090537;
    vec3 b = v * (0.983729 * v + 0.4329510) + 0.238081;
    return clamp(from_ap1 * (a / b), 0.0, 1.0);
}

// AgX (Troy Sobotka), base transform with the default look (which changes nothing), as
// three.js r162+ writes it after Filament (google/filament#7236): to Rec. 2020, the AgX
// inset, log2 encoding over [-12.47393, 4.026069] EV about middle grey, the sigmoid
// (Benjamin Wrensch's 6th-order fit of the AgX base contrast, "minimal AgX"), the outset,
// the 2.2 power back to linear, back to Rec. 709, clamped.
vec3 agx_contrast(vec3 x) {
    vec3 x2 = x * x;
    vec3 x4 = x2 * x2;
    return 15.5 * x4 * x2 - 40.14 * x4 * x + 31.96 * x4 - 6.868 * x2 * x + 0.4298 * x2 + 0.1191 * x - 0.00232;
}

vec3 tonemap_agx(vec3 c) {
    // Rec. 709 <-> Rec. 2020 (ITU-R BT.2407's matrix, and its inverse to 12 digits).
    const mat3 to_2020 = mat3(vec3(0.627409440462, 0.069124839044, 0.016423358027),
                              vec3(0.329260252194, 0.919548613786, 0.088047847624),
                              vec3(0.04327189359, 0.011320766762, 0.895616713685));
    const mat3 from_2020 = mat3(vec3(1.6605, -0.1246, -0.0182),
                                vec3(-0.5876, 1.1329, -0.1006),
                                vec3(-0.0728, -0.0083, 1.1187));
    const mat3 inset = mat3(vec3(0.856627153315983, 0.137318972929847, 0.11189821299995),
                            vec3(0.0951212405381588, 0.761241990602591, 0.0767994186031903),
                            vec3(0.0482516061458583, 0.101439036467562, 0.811302368396859));
    // The inverse of Filament's AgXOutsetMatrixInv.
    const mat3 outset = mat3(vec3(1.127100581814, -0.141329763498, -0.141329763498),
                             vec3(-0.110606643097, 1.157823702216, -0.110606643097),
                             vec3(-0.016493938718, -0.016493938718, 1.251936406595));
    const float min_ev = -12.47393;  // log2(2^-10 * 0.18)
    const float max_ev = 4.026069;   // log2(2^6.5 * 0.18)
    vec3 v = max(to_2020 * c, 0.0);
    v = max(inset * v, 1e-10);
    v = clamp((log2(v) - min_ev) / (max_ev - min_ev), 0.0, 1.0);
    v = outset * agx_contrast(v);
    v = pow(max(v, 0.0), vec3(2.2));
    return clamp(from_2020 * v, 0.0, 1.0);
}

// Khronos PBR Neutral (KhronosGroup/ToneMapping, 2024): colours below 0.76 stay as they
// are (less a small offset that keeps blacks black), brighter ones are compressed toward 1
// and desaturated toward the compressed peak.
vec3 tonemap_pbr_neutral(vec3 c) {
    const float start_compression = 0.8 - 0.04;
    const float desaturation = 0.15;
    float x = min(c.r, min(c.g, c.b));
    float offset = x < 0.08 ? x - 6.25 * x * x : 0.04;
    c -= offset;
    float peak = max(c.r, max(c.g, c.b));
    if (peak < start_compression) return clamp(c, 0.0, 1.0);
    float d = 1.0 - start_compression;
    float new_peak = 1.0 - d * d / (peak + d - start_compression);
    c *= new_peak / peak;
    float g = 1.0 - 1.0 / (desaturation * (peak - new_peak) + 1.0);
    return clamp(mix(c, vec3(new_peak), g), 0.0, 1.0);
}

vec3 tone_map(vec3 c) {
#if TONEMAP_CURVE == TONEMAP_ACES
    return tonemap_aces(c);
#elif TONEMAP_CURVE == TONEMAP_AGX
    return tonemap_agx(c);
#elif TONEMAP_CURVE == TONEMAP_PBR_NEUTRAL
    return tonemap_pbr_neutral(c);
#else
    return c;   // none: linear_to_srgb clamps
#endif
}
