#version 410 core
// A particle's pixels (engine/render/particle_draw.py): its colour times its sprite (the
// texture's cell, or a round soft spot), premultiplied by its alpha.  ``coverage`` 1 (blend
// "alpha") writes that alpha, so it covers what is behind; 0 (blend "additive") writes alpha
// 0, so the premultiplied blend adds it.  Fogged as the glass is (scene.frag): the colour's
// light through the air, and the fog's own light by the alpha written.  REACTIVE: the
// main view's particles drawn again into temporal AA's reactive mask.
#include "camera.glsl"
#include "view_axis.glsl"
#include "fog.glsl"
#include "hdr.glsl"
#include "footprint.glsl"

#ifdef MASKED
uniform usampler2D node_map;  // a reflection level's claims: only this view's pixels
#endif
#ifdef SPRITE
uniform sampler2D sprite_map;
#endif
uniform float coverage;
#ifdef SOFT
uniform sampler2D scene_depth;  // a copy of the view's depth (RenderTargets.depth_copy)
uniform float softness;         // metres: fades in over that much room behind it
#endif

in vec2 v_uv;
in vec2 v_corner;
in vec3 v_world;
#ifdef RIBBON
#define SHADING_QUALIFIER   // (a ribbon's colour and light vary along it: particle.vert)
#else
#define SHADING_QUALIFIER flat
#endif
SHADING_QUALIFIER in vec4 v_color;
#ifdef LIT
SHADING_QUALIFIER in vec3 v_light;
#endif

layout(location = 0) out vec4 out_color;

void main() {
#ifdef SPRITE
    vec4 sprite = texture(sprite_map, bounded_footprint(v_uv));
#else
    float round_spot = max(1.0 - dot(v_corner, v_corner), 0.0);
    vec4 sprite = vec4(1.0, 1.0, 1.0, round_spot * round_spot);
#endif
#ifdef MASKED
    // (after the sprite's lookup: a discard leaves its quad's derivatives undefined, scene.frag)
    if (texelFetch(node_map, ivec2(gl_FragCoord.xy), 0).r != camera.skip.w) discard;
#endif
    float a = v_color.a * sprite.a;
#ifdef SOFT
    // Soft particles: what is behind this pixel, back in the world from the depth copy, and
    // the room along the pixel's ray between it and the particle; faded in over softness.
    vec2 ndc = gl_FragCoord.xy / camera.viewport.zw * 2.0 - 1.0;
    float depth = texelFetch(scene_depth, ivec2(gl_FragCoord.xy), 0).r;
    vec4 behind = camera.inv_view_proj * vec4(ndc, depth * 2.0 - 1.0, 1.0);
    vec3 start = ray_eye(camera.eye.xyz, view_axis(camera.view_proj), v_world);
    float room = distance(behind.xyz / behind.w, start) - distance(v_world, start);
    a *= clamp(room / softness, 0.0, 1.0);
#endif
    vec3 rgb = v_color.rgb * sprite.rgb;
#ifdef LIT
    rgb *= v_light;
#endif
    vec3 color = rgb * a;
    float alpha = a * coverage;
#ifdef FOG
    vec3 eye = ray_eye(camera.eye.xyz, view_axis(camera.view_proj), v_world);
    color = fog_view(color, eye, camera.clip_plane, v_world)
            - (1.0 - alpha) * fog_view(vec3(0.0), eye, camera.clip_plane, v_world);
#endif
#ifdef REACTIVE
    // Temporal AA's reactive mask (engine/render/temporal_aa.py): how much this particle
    // changes the pixel, its cover or its light, whichever is more, up to 1; blended as the
    // colour is (premultiplied), so overlapping particles unite.
    float reactive = clamp(max(alpha, max(max(color.r, color.g), color.b)), 0.0, 1.0);
    out_color = vec4(reactive);
#else
    out_color = vec4(hdr_store(color), alpha);
#endif
}
