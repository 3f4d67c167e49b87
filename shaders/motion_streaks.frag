#version 410 core
// Motion blur, step 1 (engine/render/motion_blur.py): each pixel's streak, the way the point it
// shows moved on screen since the last frame, ``shutter`` of it, at most ``max_pixels`` long.
// The point is where the light's way puts it (way.glsl: the eye along the pixel's ray for the
// way's length), so a reflection moves as its image behind the glass does; the sky (and a
// pixel nothing drew) as a direction, which only the camera's turn moves.  A point behind last
// frame's camera gets no streak from the camera.  With ``objects`` the seen image's motion
// channels add what the thing itself moved (seen_moved: its instance's motion as the view
// that drew it projects it).
#include "view_axis.glsl"
#include "way.glsl"

uniform usampler2D seen_image;   // the main view's seen image (entity, way, own motion)
uniform mat4 inv_view_proj;      // this frame's main view
uniform mat4 previous_view_proj; // last frame's (carried through a portal the camera crossed)
uniform vec3 eye;
uniform vec3 axis;               // an orthographic view's axis (view_axis.glsl); 0: perspective
uniform vec2 blur;               // x: the shutter's share, y: the longest streak in pixels
uniform vec2 image_size;         // the picture's (the seen image's, or larger after temporal upsampling)
uniform bool objects;            // the seen image holds each thing's own motion (b, a)

out vec4 out_streak;  // xy: the streak in pixels (its whole length, centred on the pixel), y up;
                      // z: the way's length (a half float: the sky's and anything past 60 km as 60 km)

void main() {
    vec2 size = image_size;
    vec2 uv = gl_FragCoord.xy / size;
    ivec2 px = ivec2(uv * vec2(textureSize(seen_image, 0)));
    vec4 near = inv_view_proj * vec4(uv * 2.0 - 1.0, -1.0, 1.0);
    vec4 far = inv_view_proj * vec4(uv * 2.0 - 1.0, 1.0, 1.0);
    vec3 start = near.xyz / near.w;
    vec3 dir = normalize(far.xyz / far.w - start);
    uvec4 seen = texelFetch(seen_image, px, 0);
    float way = uintBitsToFloat(seen.g);
    bool beyond = way_beyond(way);
    vec4 before = beyond ? previous_view_proj * vec4(dir, 0.0)
                         : previous_view_proj * vec4(ray_eye(eye, axis, start) + dir * way, 1.0);
    vec2 moved = before.w > 1e-6 ? uv - (before.xy / before.w * 0.5 + 0.5) : vec2(0.0);
    if (objects) moved += uintBitsToFloat(seen.ba);
    vec2 streak = moved * size * blur.x;  // pixels
    float length_px = length(streak);
    if (length_px > blur.y) streak *= blur.y / length_px;
    out_streak = vec4(streak, min(beyond ? SKY_WAY : way, 6.0e4), 0.0);
}
