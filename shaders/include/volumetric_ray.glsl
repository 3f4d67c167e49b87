// A pixel's ray through the air, for the light shafts' march and their filter (components/fog.py
// VolumetricFog, engine/render/volumetric_fog.py): from the near plane through the pixel's
// centre to what the main view's depth image shows there, at most ``max_distance`` metres
// (the sky: that far along its direction).  Built from the near and far points the inverse
// projection gives, so an orthographic camera's parallel rays are right too.
uniform sampler2D depth_map;   // the main view's depth (a sampler that compares nothing)
uniform vec2 depth_size;       // its size in pixels
uniform mat4 inv_view_proj;    // the main view's, the view's pixels -> world
uniform float max_distance;    // VolumetricFog.distance

// The ray of ``pixel``: where it starts, its unit direction, and how far it goes.
void volumetric_ray(ivec2 pixel, out vec3 origin, out vec3 dir, out float reach) {
    float depth = texelFetch(depth_map, pixel, 0).r;
    vec2 ndc = (vec2(pixel) + 0.5) / depth_size * 2.0 - 1.0;
    vec4 near_point = inv_view_proj * vec4(ndc, -1.0, 1.0);
    bool sky = depth >= 1.0;
    vec4 far_point = inv_view_proj * vec4(ndc, sky ? 1.0 : depth * 2.0 - 1.0, 1.0);
    origin = near_point.xyz / near_point.w;
    vec3 way = far_point.xyz / far_point.w - origin;
    float span = length(way);
    dir = way / max(span, 1e-12);
    reach = sky ? max_distance : min(span, max_distance);
}
