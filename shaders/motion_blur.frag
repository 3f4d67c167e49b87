#version 410 core
// Camera motion blur (engine/render/motion_blur.py): each pixel smeared along the way the point
// it shows moved on screen since the last frame, ``shutter`` of it, at most ``max_pixels``
// long.  The point is where the light's way puts it (way.glsl: the eye along the pixel's ray
// for the way's length), so a reflection moves as its image behind the glass does; the sky (and
// a pixel nothing drew) as a direction, which only the camera's turn moves.  A point behind
// last frame's camera is not smeared.
#include "view_axis.glsl"

uniform sampler2D hdr_image;     // the finished picture (bilinear)
uniform usampler2D seen_image;   // the main view's seen pair (entity, way)
uniform mat4 inv_view_proj;      // this frame's main view
uniform mat4 previous_view_proj; // last frame's (carried through a portal the camera crossed)
uniform vec3 eye;
uniform vec3 axis;               // an orthographic view's axis (view_axis.glsl); 0: perspective
uniform vec2 blur;               // x: the shutter's share, y: the longest streak in pixels

layout(location = 0) out vec4 out_color;
layout(location = 1) out vec4 out_streak;  // xy: the streak in pixels (its whole length, centred on the pixel)

const int SAMPLES = 12;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec2 size = vec2(textureSize(hdr_image, 0));
    vec2 uv = gl_FragCoord.xy / size;
    vec4 near = inv_view_proj * vec4(uv * 2.0 - 1.0, -1.0, 1.0);
    vec4 far = inv_view_proj * vec4(uv * 2.0 - 1.0, 1.0, 1.0);
    vec3 start = near.xyz / near.w;
    vec3 dir = normalize(far.xyz / far.w - start);
    float way = uintBitsToFloat(texelFetch(seen_image, px, 0).g);
    bool beyond = way <= 0.0 || way >= 0.5 * SKY_WAY;
    vec4 before = beyond ? previous_view_proj * vec4(dir, 0.0)
                         : previous_view_proj * vec4(ray_eye(eye, axis, start) + dir * way, 1.0);
    vec3 centre = texelFetch(hdr_image, px, 0).rgb;
    out_streak = vec4(0.0);
    if (before.w <= 1e-6) {
        out_color = vec4(centre, 1.0);
        return;
    }
    vec2 streak = (uv - (before.xy / before.w * 0.5 + 0.5)) * size * blur.x;  // pixels
    float length_px = length(streak);
    if (length_px > blur.y) streak *= blur.y / length_px;
    out_streak = vec4(streak, 0.0, 0.0);
    if (length_px < 0.5) {
        out_color = vec4(centre, 1.0);
        return;
    }
    // (Taps past the picture's edge read its edge, not the far side: the image may repeat.)
    vec2 half_texel = 0.5 / size;
    vec3 sum = vec3(0.0);
    for (int i = 0; i < SAMPLES; ++i) {
        float t = (float(i) + 0.5) / float(SAMPLES) - 0.5;
        sum += textureLod(hdr_image, clamp(uv + streak * t / size, half_texel, 1.0 - half_texel), 0.0).rgb;
    }
    out_color = vec4(sum / float(SAMPLES), 1.0);
}
