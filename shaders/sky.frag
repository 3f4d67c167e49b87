#version 410 core
// The sky of a view: a generated Skybox evaluated along the pixel's ray (GENERATED_SKY:
// include/sky_model.glsl, sharp at any resolution), else the cube map (given faces, or no
// Skybox: the flat background).
#include "camera.glsl"
#include "view_axis.glsl"
#include "hdr.glsl"
#include "fog.glsl"
#include "way.glsl"

#ifdef GENERATED_SKY
#include "sky_model.glsl"
#else
uniform samplerCube sky_map;
#endif

#ifdef LAYERED
in vec3 g_direction;  // sky_layered.geom: this face's world direction
flat in vec3 g_eye;   // ... and its eye (the probe's centre)
#else
in vec2 v_ndc;
#endif
layout(location = 0) out vec4 out_color;
layout(location = 1) out uint out_surface;
layout(location = 2) out uvec4 out_seen;  // nothing, beyond everything (way.glsl)
layout(location = 3) out uint out_node;

void main() {
#ifdef LAYERED
    vec3 direction = normalize(g_direction);
    vec3 eye = g_eye;
#else
    vec4 far_point = camera.inv_view_proj * vec4(v_ndc, 1.0, 1.0);
    vec3 far = far_point.xyz / far_point.w;
    // (an orthographic view's rays are parallel, along its axis, from its eye's plane: view_axis.glsl)
    vec3 eye = ray_eye(camera.eye.xyz, view_axis(camera.view_proj), far);
    vec3 direction = normalize(far - eye);
#endif
#ifdef GENERATED_SKY
    vec3 sky = generated_sky(direction);
#else
    vec3 sky = textureLod(sky_map, direction, 0.0).rgb;
#endif
    // Its share of the fog along the ray, out from the eye (a root view: the main camera's
    // or a probe face's; reflection levels leave the sky to their composites).
    out_color = vec4(hdr_store(fog_sky(sky, eye, direction)), 1.0);
    out_surface = 0u;
    out_seen = seen_at(0u, SKY_WAY);
    out_node = 0u;
}
