#version 410 core
// Screen-space reflections' composite (engine/render/screen_reflections.py): each pixel
// whose surface reflects the sky or a probe, where its reflected ray meets what the view drew
// (screen_march.glsl), has what the view shows there put in place of the sky's or probe's
// reflection: colour + confidence x (W x found - W x radiance), with W and W x radiance as
// the scene pass wrote them (scene.frag, SCREEN_REFLECTION).  The HALF_RESOLUTION build reads
// the rays marched at half size (screen_reflection_trace.frag) instead of marching its own:
// the four about the pixel, by bilinear weight times how near their surface's depth is.
// The SHOW_FOUND build (the overlay's "SSR only") writes what the screen gave in place of the
// picture: the colour found times the confidence, black where nothing was found.  A
// reflection level's build (LEVEL_VIEWS) is drawn once a view of the level, over its
// rectangle, and composites only that view's pixels.
#include "screen_march.glsl"

uniform sampler2D scene_color;     // the main view's colour (a copy), with its mip chain
uniform sampler2D weight_map;      // rgb: W, a: roughness
uniform sampler2D added_map;       // rgb: W x the sky's or probe's radiance, a: entity bits 0-10
uniform usampler2D surface_map;    // the entity drawn at each pixel (last drawn: glass over it too)
uniform float max_roughness;       // ScreenReflections.max_roughness
uniform float top_lod;             // the colour's last mip level
#ifdef HALF_RESOLUTION
uniform sampler2D hits_map;        // xy: the pixel found, z: the confidence, w: the traced pixel's window depth (-1: none)
#endif

out vec4 out_color;

// The share of the screen's reflection a surface of this roughness takes: all of it up to
// three quarters of max_roughness, none past it.
float rough_share(float roughness) {
    return max_roughness > 0.0 ? 1.0 - smoothstep(0.75 * max_roughness, max_roughness, roughness)
                               : (roughness > 0.0 ? 0.0 : 1.0);
}

// What the view shows at ``found``, for a surface of ``roughness`` whose ray went from the
// pixel at ``from`` there.  A rough surface spreads its reflection over a cone about its
// ray: the level of the image as wide as the cone where it meets what it reflects (GGX's
// alpha, roughness squared, taken as the cone's half-width a unit of distance; the distance
// in pixels across the screen).  At the base level, the found pixel's own colour (no blend
// across its edge).
vec3 seen_at(vec2 found, vec2 from, float roughness) {
    float spread = roughness * roughness * 2.0 * length(found - from);
    float lod = clamp(log2(max(spread, 1.0)), 0.0, top_lod);
    vec2 at = lod > 0.0 ? found : floor(found) + 0.5;
    return textureLod(scene_color, at / depth_size, lod).rgb;
}

// The colour of the pixel at ``pixel`` (``base`` now) with the screen's reflection in place of
// the sky's or probe's, where its ray finds one (``base`` where it does not).
vec3 reflected(ivec2 pixel, vec3 base, vec4 weight, float share, float depth) {
    vec4 added = texelFetch(added_map, pixel, 0);
    vec4 normal = texelFetch(normal_map, pixel, 0);
    // Still the surface the weights were written for: nothing see-through drawn over it since.
    uint drawn = texelFetch(surface_map, pixel, 0).r;
    if (float(drawn & 2047u) != added.a || float((drawn >> 11u) & 2047u) != normal.a) return base;
#ifdef HALF_RESOLUTION
    // The four traced texels about the pixel, each by its bilinear weight times how near its
    // surface lies to this one (2% of the distance: another surface past it), and the
    // found ones' colours by their confidence too.
    float here = drawn_depth(gl_FragCoord.xy);
    vec2 at = gl_FragCoord.xy * 0.5 - 0.5;
    vec2 cell = floor(at);
    vec2 f = at - cell;
    ivec2 last = textureSize(hits_map, 0) - 1;
    float weights = 0.0, trusted = 0.0;
    vec3 radiance = vec3(0.0);
    for (int i = 0; i < 4; ++i) {
        ivec2 offset = ivec2(i & 1, i >> 1);
        vec4 hit = texelFetch(hits_map, clamp(ivec2(cell) + offset, ivec2(0), last), 0);
        if (hit.w < 0.0) continue;
        vec2 bilinear = mix(1.0 - f, f, vec2(offset));
        float there = unproject_z.y / (hit.w * 2.0 - 1.0 + unproject_z.x);
        float w = bilinear.x * bilinear.y * max(0.0, 1.0 - abs(there - here) / (0.02 * here));
        weights += w;
        if (hit.z > 0.0) {
            trusted += w * hit.z;
            radiance += w * hit.z * seen_at(hit.xy, gl_FragCoord.xy, weight.a);
        }
    }
    if (trusted <= 0.0) return base;
    radiance /= trusted;
    float confidence = share * trusted / weights;
#else
    vec2 found;
    float confidence = share * march(gl_FragCoord.xy, depth, normal.xyz, found);
    if (confidence <= 0.0) return base;
    vec3 radiance = seen_at(found, gl_FragCoord.xy, weight.a);
#endif
#ifdef SHOW_FOUND
    return min(confidence * radiance, vec3(65504.0));
#else
    return clamp(base + confidence * (weight.rgb * radiance - added.rgb), vec3(0.0), vec3(65504.0));
#endif
}

void main() {
    ivec2 pixel = ivec2(gl_FragCoord.xy);
#ifdef LEVEL_VIEWS
    if (node_at(gl_FragCoord.xy) != node) discard;  // another view's pixel (its own draw composites it)
#endif
    vec4 base = texelFetch(scene_color, pixel, 0);
#ifdef SHOW_FOUND
    out_color = vec4(0.0, 0.0, 0.0, base.a);
    base.rgb = vec3(0.0);
#else
    out_color = base;
#endif
    vec4 weight = texelFetch(weight_map, pixel, 0);
    float share = rough_share(weight.a);
    float depth = texelFetch(depth_map, pixel, 0).r;
    // Where nothing reflects, rougher than max_roughness, or the sky.  llvmpipe runs every
    // instruction of a branch for a group of pixels where one of them takes it, but skips a
    // loop's body where none of them has a turn left: the work is a loop run once or not
    // at all (run as a branch, the pixels without a reflection cost half the march's time).
    int todo = max(weight.r, max(weight.g, weight.b)) > 0.0 && share > 0.0 && depth < 1.0 ? 1 : 0;
    for (int once = 0; once < todo; ++once) out_color.rgb = reflected(pixel, base.rgb, weight, share, depth);
}
