#version 410 core
// The last pass of a frame drawn at a render scale other than 1, or sharpened
// (engine/render/resample.py): the encoded picture (sRGB, after FXAA) resampled to the
// output's size and sharpened there.
//
// UPSCALE (a scale below 1): each output pixel reads the picture where its centre falls,
// through a Catmull-Rom spline (catmull_rom.glsl: sharper than a bilinear fetch, clamped to
// the picture's range).  DOWNSCALE (above 1, supersampling): the mean of the picture's texels
// under the pixel's footprint, each weighed by the share of it the footprint covers (an area
// box filter: at 2, the four texels of the pixel alike), in linear light (decoded from sRGB,
// averaged, encoded again: an edge's pixel takes its coverage's share of the light, as a
// resolve of samples after tone mapping does).  Neither: the picture is the output's size
// and the pixel's own texel is read.
//
// SHARPEN: contrast-adaptive sharpening (the idea of AMD's FidelityFX CAS, 2019, written
// anew): the pixel less a share of its four neighbours one picture texel away (an unsharp
// mask's cross), the share smaller where the neighbourhood already reaches towards black or
// white, so edges sharpen without ringing past the range and flat areas gain no noise.  The
// neighbours are read a picture texel away, so an upscaled picture is sharpened at the
// detail it was drawn with.  In the encoded (perceptual) values, as upscalers sharpen.
#include "catmull_rom.glsl"
#include "color.glsl"

uniform sampler2D frame;     // the encoded picture: linear filtered, clamped to the edge
uniform vec2 output_size;    // pixels
uniform float sharpness;     // Renderer.sharpness, (0, 1]

out vec4 out_color;

#ifdef DOWNSCALE
// The box filter over output pixel ``pixel``'s footprint (``pixel`` its centre, in output
// pixels): at most 3 x 3 texels up to a scale of 2.
vec3 box(vec2 pixel, vec2 size) {
    vec2 ratio = size / output_size;
    vec2 lo = (pixel - 0.5) * ratio, hi = (pixel + 0.5) * ratio;
    ivec2 first = ivec2(floor(lo)), last = ivec2(ceil(hi)) - 1;
    ivec2 edge = ivec2(size) - 1;
    vec3 sum = vec3(0.0);
    float total = 0.0;
    for (int y = first.y; y <= last.y; ++y) {
        for (int x = first.x; x <= last.x; ++x) {
            vec2 covered = min(hi, vec2(x + 1, y + 1)) - max(lo, vec2(x, y));
            float weight = max(covered.x, 0.0) * max(covered.y, 0.0);
            sum += weight * srgb_to_linear(texelFetch(frame, clamp(ivec2(x, y), ivec2(0), edge), 0).rgb);
            total += weight;
        }
    }
    return linear_to_srgb(sum / max(total, 1e-6));
}
#endif

void main() {
    vec2 size = vec2(textureSize(frame, 0));
    vec2 uv = gl_FragCoord.xy / output_size;
#ifdef UPSCALE
    vec3 c = clamp(catmull_rom(frame, uv, size), 0.0, 1.0);
#elif defined(DOWNSCALE)
    vec3 c = box(gl_FragCoord.xy, size);
#else
    vec3 c = texelFetch(frame, ivec2(gl_FragCoord.xy), 0).rgb;
#endif
#ifdef SHARPEN
#ifdef DOWNSCALE
    // (supersampled: the neighbours are the box filter's at the next output pixels)
    vec3 n = box(gl_FragCoord.xy + vec2(0.0, 1.0), size), s = box(gl_FragCoord.xy - vec2(0.0, 1.0), size);
    vec3 e = box(gl_FragCoord.xy + vec2(1.0, 0.0), size), w = box(gl_FragCoord.xy - vec2(1.0, 0.0), size);
#else
    vec2 texel = 1.0 / size;
    vec3 n = textureLod(frame, uv + vec2(0.0, texel.y), 0.0).rgb;
    vec3 s = textureLod(frame, uv - vec2(0.0, texel.y), 0.0).rgb;
    vec3 e = textureLod(frame, uv + vec2(texel.x, 0.0), 0.0).rgb;
    vec3 w = textureLod(frame, uv - vec2(texel.x, 0.0), 0.0).rgb;
#endif
    vec3 lo = min(c, min(min(n, s), min(e, w)));
    vec3 hi = max(c, max(max(n, s), max(e, w)));
    // How far the neighbourhood stays from the range's ends, over its brightest: 1 in a
    // middling, low-contrast area, 0 where it touches black or white.
    vec3 room = sqrt(clamp(min(lo, 1.0 - hi) / max(hi, 1e-5), 0.0, 1.0));
    vec3 lobe = -room * (0.2 * sharpness);   // each neighbour's weight (the pixel's is 1)
    c = clamp((c + lobe * (n + s + e + w)) / (1.0 + 4.0 * lobe), 0.0, 1.0);
#endif
    out_color = vec4(c, 1.0);
}
