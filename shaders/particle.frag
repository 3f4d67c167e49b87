#version 410 core
// A particle's pixels (engine/render/particle_draw.py): its colour times its sprite (the
// texture's cell, or a round soft spot), premultiplied by its alpha.  ``coverage`` 1 (blend
// "alpha") writes that alpha, so it covers what is behind; 0 (blend "additive") writes alpha
// 0, so the premultiplied blend adds it.  Fogged as the glass is (scene.frag): the colour's
// light through the air, and the fog's own light by the alpha written.
#include "camera.glsl"
#include "view_axis.glsl"
#include "fog.glsl"
#include "hdr.glsl"

#ifdef MASKED
uniform usampler2D node_map;  // a reflection level's claims: only this view's pixels
#endif
#ifdef SPRITE
uniform sampler2D sprite_map;
#endif
uniform float coverage;

in vec2 v_uv;
in vec2 v_corner;
in vec3 v_world;
flat in vec4 v_color;
#ifdef LIT
flat in vec3 v_light;
#endif

layout(location = 0) out vec4 out_color;

void main() {
#ifdef MASKED
    if (texelFetch(node_map, ivec2(gl_FragCoord.xy), 0).r != camera.skip.w) discard;
#endif
#ifdef SPRITE
    vec4 sprite = texture(sprite_map, v_uv);
#else
    float round_spot = max(1.0 - dot(v_corner, v_corner), 0.0);
    vec4 sprite = vec4(1.0, 1.0, 1.0, round_spot * round_spot);
#endif
    float a = v_color.a * sprite.a;
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
    out_color = vec4(hdr_store(color), alpha);
}
