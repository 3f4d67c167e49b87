#version 410 core
// The last pass of a frame drawn at a render scale below 1, or sharpened
// (engine/render/resample.py): the encoded picture (sRGB, after FXAA) resampled to the
// output's size and sharpened there.
//
// UPSCALE: each output pixel reads the picture where its centre falls, through a Catmull-Rom
// spline (catmull_rom.glsl: sharper than a bilinear fetch, clamped to the picture's range);
// without it the picture is the output's size and the pixel's own texel is read.
//
// SHARPEN: contrast-adaptive sharpening (the idea of AMD's FidelityFX CAS, 2019, written
// anew): the pixel less a share of its four neighbours one picture texel away (an unsharp
// mask's cross), the share smaller where the neighbourhood already reaches towards black or
// white, so edges sharpen without ringing past the range and flat areas gain no noise.  The
// neighbours are read a picture texel away, so an upscaled picture is sharpened at the
// detail it was drawn with.  In the encoded (perceptual) values, as upscalers sharpen.
#include "catmull_rom.glsl"

uniform sampler2D frame;     // the encoded picture: linear filtered, clamped to the edge
uniform vec2 output_size;    // pixels
uniform float sharpness;     // Renderer.sharpness, (0, 1]

out vec4 out_color;

void main() {
    vec2 size = vec2(textureSize(frame, 0));
    vec2 uv = gl_FragCoord.xy / output_size;
#ifdef UPSCALE
    vec3 c = clamp(catmull_rom(frame, uv, size), 0.0, 1.0);
#else
    vec3 c = texelFetch(frame, ivec2(gl_FragCoord.xy), 0).rgb;
#endif
#ifdef SHARPEN
    vec2 texel = 1.0 / size;
    vec3 n = textureLod(frame, uv + vec2(0.0, texel.y), 0.0).rgb;
    vec3 s = textureLod(frame, uv - vec2(0.0, texel.y), 0.0).rgb;
    vec3 e = textureLod(frame, uv + vec2(texel.x, 0.0), 0.0).rgb;
    vec3 w = textureLod(frame, uv - vec2(texel.x, 0.0), 0.0).rgb;
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
