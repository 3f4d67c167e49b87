// An image between its texels by a Catmull-Rom spline, in five bilinear fetches (Jimenez's
// arrangement in "Filmic SMAA", 2016: the 4x4 taps' weights folded into the bilinear filter,
// the four corner taps, whose weights are smallest, left out and the rest renormalised).
// Sharper than one bilinear fetch: temporal AA's history (a bilinear fetch would soften it a
// little more every frame it is carried) and the spatial upscale (resample.frag) read through
// it.  ``image`` must be linear-filtered; ``size`` is its size in texels.  Overshoots at hard
// edges (the spline's negative lobes): callers clamp.
vec3 catmull_rom(sampler2D image, vec2 uv, vec2 size) {
    vec2 position = uv * size;
    vec2 centre = floor(position - 0.5) + 0.5;
    vec2 f = position - centre;
    vec2 f2 = f * f;
    vec2 f3 = f2 * f;
    vec2 w0 = -0.5 * f3 + f2 - 0.5 * f;
    vec2 w1 = 1.5 * f3 - 2.5 * f2 + 1.0;
    vec2 w2 = -1.5 * f3 + 2.0 * f2 + 0.5 * f;
    vec2 w3 = 0.5 * f3 - 0.5 * f2;
    vec2 w12 = w1 + w2;
    vec2 at12 = (centre + w2 / w12) / size;
    vec2 at0 = (centre - 1.0) / size;
    vec2 at3 = (centre + 2.0) / size;
    vec4 sum = vec4(textureLod(image, vec2(at12.x, at0.y), 0.0).rgb, 1.0) * (w12.x * w0.y)
             + vec4(textureLod(image, vec2(at0.x, at12.y), 0.0).rgb, 1.0) * (w0.x * w12.y)
             + vec4(textureLod(image, at12, 0.0).rgb, 1.0) * (w12.x * w12.y)
             + vec4(textureLod(image, vec2(at3.x, at12.y), 0.0).rgb, 1.0) * (w3.x * w12.y)
             + vec4(textureLod(image, vec2(at12.x, at3.y), 0.0).rgb, 1.0) * (w12.x * w3.y);
    return sum.rgb / sum.a;
}
