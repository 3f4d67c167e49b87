#version 410 core
#include "camera.glsl"

uniform samplerCube sky_map;

#ifdef LAYERED
in vec3 g_direction;  // sky_layered.geom: this face's world direction
#else
in vec2 v_ndc;
#endif
layout(location = 0) out vec4 out_color;
layout(location = 1) out uint out_surface;
layout(location = 2) out uint out_seen;
layout(location = 3) out uint out_node;

void main() {
#ifdef LAYERED
    vec3 direction = g_direction;
#else
    vec4 far_point = camera.inv_view_proj * vec4(v_ndc, 1.0, 1.0);
    vec3 direction = far_point.xyz / far_point.w - camera.eye.xyz;
#endif
    out_color = vec4(textureLod(sky_map, normalize(direction), 0.0).rgb, 1.0);
    out_surface = 0u;
    out_seen = 0u;
    out_node = 0u;
}
