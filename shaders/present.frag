#version 410 core
// Present: the linear HDR image, times exposure, encoded to sRGB.  With LUMA_IN_ALPHA (the
// frame the FXAA pass filters) alpha holds the pixel's luma, else 1.
//
// With POST (a camera with a Tonemap or a Bloom, components/post.py), in this order: the
// bloom mixed in (BLOOM: the mean of the mip chain's blurs, engine/render/bloom.py), the
// exposure (a linear scale; AUTO_EXPOSURE: times 2^EV from the adapted 1x1 exposure
// texture, engine/render/post.py, read on the GPU by present.vert), the tone curve
// (TONEMAP_CURVE, include/tonemap.glsl), then the sRGB encoding.  Without POST the
// code is the plain look's, unchanged.  With VIGNETTE the exposed image is darkened towards
// its edges (Vignette).  With GRADE (components/post.py ColorGrading) the
// exposed image is graded before the curve (grade()); with LUT the encoded picture is looked
// up in the grade's colour table.  With ABERRATION the red and blue images are read scaled
// about the middle (ChromaticAberration); with GRAIN film grain is added last (FilmGrain).
#include "color.glsl"
#include "tonemap.glsl"

uniform sampler2D hdr_image;
uniform float exposure;

#ifdef POST
#ifdef BLOOM
uniform sampler2D bloom_image;
uniform vec2 bloom_mix;   // (weight of the image, weight of the bloom image's sum of levels)
#endif
#ifdef LENS_FLARE
uniform sampler2D flare_image;   // the lens flare's ghosts (engine/render/lens_flare.py), the bloom image's size
#endif
#ifdef LENS_DIRT
uniform sampler2D dirt_map;      // Bloom.dirt: the lens's smudges, over the whole frame (sRGB, decoded)
uniform float dirt_intensity;
#endif
#ifdef AUTO_EXPOSURE
flat in float v_scale;   // exposure * 2^EV of the adapted 1x1 exposure texture (present.vert)
#endif
#ifdef VIGNETTE
uniform vec4 vignette_ray;    // ndc -> the ray's tangents from the view axis: xy scale, zw bias
uniform vec2 vignette;        // Vignette.intensity, Vignette.falloff

// A lens's natural vignetting (components/post.py Vignette): cos(theta) ** falloff, theta the
// angle of the pixel's ray from the view axis, mixed in by the intensity.
float vignette_factor(vec2 uv) {
    vec2 tangent = (uv * 2.0 - 1.0) * vignette_ray.xy + vignette_ray.zw;
    float cos_theta = inversesqrt(1.0 + dot(tangent, tangent));
    return 1.0 - vignette.x + vignette.x * pow(cos_theta, vignette.y);
}
#endif
#include "grade.glsl"
#ifdef ABERRATION
uniform float aberration;     // the red image's scale over the green's less 1 (the blue's: 1 less it)
#endif
#ifdef GRAIN
uniform vec4 grain;           // x: the spread (intensity x 0.1), y: response, z: a grain's size (pixels), w: the seed

// PCG's output permutation as a hash (Jarzynski and Olano, "Hash Functions for GPU Rendering",
// 2020): 32 well-mixed bits of one uint.
uint pcg_hash(uint v) {
    uint state = v * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// The grain at a pixel this frame: uniform in [-1, 1), the same within a grain's square.
float grain_noise(vec2 pixel, float seed) {
    uvec2 cell = uvec2(pixel / grain.z);
    uint h = pcg_hash(cell.x + pcg_hash(cell.y + pcg_hash(uint(seed))));
    return float(h >> 8u) * (2.0 / 16777216.0) - 1.0;
}
#endif
#endif

in vec2 v_uv;
out vec4 out_color;

void main() {
#ifdef POST
    // The image is the output's size: its texel, fetched (no filter to run); the bloom
    // image, smaller, through textureLod (no mipmaps, and a software rasteriser skips the
    // derivatives).  v_uv is below 1 at every pixel centre, so the texel is inside.
    vec3 hdr = texelFetch(hdr_image, ivec2(v_uv * vec2(textureSize(hdr_image, 0))), 0).rgb;
#ifdef ABERRATION
    // A lens's lateral chromatic aberration: the red image larger than the green, the blue
    // smaller, about the middle, so a pixel shows red from nearer the middle, blue from farther out.
    // (The blue is read from past the edge near it: the edge's texels, not the far side's.)
    vec2 from_middle = v_uv - 0.5;
    vec2 half_texel = 0.5 / vec2(textureSize(hdr_image, 0));
    hdr.r = textureLod(hdr_image, 0.5 + from_middle / (1.0 + aberration), 0.0).r;
    hdr.b = textureLod(hdr_image, clamp(0.5 + from_middle / (1.0 - aberration), half_texel, 1.0 - half_texel), 0.0).b;
#endif
#ifdef BLOOM
    vec3 lens_light = textureLod(bloom_image, v_uv, 0.0).rgb * bloom_mix.y;   // the light the lens spreads
#ifdef LENS_FLARE
    lens_light += textureLod(flare_image, v_uv, 0.0).rgb * bloom_mix.y;   // (over the bloom image's levels, as the bloom)
#endif
    hdr = hdr * bloom_mix.x + lens_light;
#ifdef LENS_DIRT
    hdr += lens_light * textureLod(dirt_map, v_uv, 0.0).rgb * dirt_intensity;   // the dirt lit where it falls
#endif
#endif
#ifdef AUTO_EXPOSURE
    float scale = v_scale;
#else
    float scale = exposure;
#endif
    vec3 exposed = hdr * scale;
#ifdef VIGNETTE
    exposed *= vignette_factor(v_uv);
#endif
#ifdef GRADE
    exposed = grade(exposed);
#endif
    vec3 srgb = linear_to_srgb(tone_map(exposed));
#ifdef LUT
    srgb = lut_graded(srgb);
#endif
#ifdef GRAIN
    // Film grain on the encoded picture, less on its bright parts by the response.
    float luma = dot(srgb, vec3(0.2126, 0.7152, 0.0722));
    srgb = max(srgb + grain_noise(gl_FragCoord.xy, grain.w) * grain.x * (1.0 - grain.y * clamp(luma, 0.0, 1.0)), 0.0);
#endif
#else
    vec3 srgb = linear_to_srgb(texture(hdr_image, v_uv).rgb * exposure);
#endif
#ifdef LUMA_IN_ALPHA
    out_color = vec4(srgb, dot(srgb, vec3(0.299, 0.587, 0.114)));
#else
    out_color = vec4(srgb, 1.0);
#endif
}
