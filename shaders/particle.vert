#version 410 core
// A particle a draw instance (engine/render/particle_draw.py): a square of its size about its
// centre, facing the view (its sides along the view's right and up, turned by its angle), made
// from gl_VertexID as a strip of four; nothing per vertex is read.
#include "camera.glsl"
#ifdef LIT
#include "lights.glsl"
#include "shadows.glsl"
#include "ambient.glsl"
#endif

in vec3 in_center;   // world
in float in_size;    // metres across
in vec4 in_color;    // linear colour, alpha
in float in_angle;   // radians, about the view's axis
in float in_frame;   // the flipbook's frame
in vec3 in_streak;   // world: its velocity x ParticleEmitter.stretch (0: a square)

uniform ivec2 sheet;  // the flipbook's columns and rows (1, 1: the whole texture)
#ifdef LIT
uniform float translucency;  // the share of its scattered light a particle lets through
#endif

out vec2 v_uv;        // the texture's, in the frame's cell
out vec2 v_corner;    // -1 to 1 across the square (the round spot's shape)
out vec3 v_world;
flat out vec4 v_color;
#ifdef LIT
flat out vec3 v_light;  // the light at its centre, over pi: its colour is an albedo
#endif

#ifdef LIT
// The light a thin sheet at ``p`` facing ``n`` scatters towards the viewer, over its albedo
// and pi: (1 - translucency) of what falls on its front, translucency of what falls on its
// back (scene.frag's diffuse transmission, Material.diffuse_transmission, for a sheet that
// faces the viewer), with the lights' shadows at its centre.
vec3 sheet_light(vec3 p, vec3 n) {
    AmbientBoxes boxes = ambient_boxes(p);
    float front = 1.0 - translucency;
    vec3 e = ambient_irradiance(boxes, n) * front + ambient_irradiance(boxes, -n) * translucency;
    vec4 sun_front = directional_shadows(p, n);
    vec4 sun_back = directional_shadows(p, -n);
    for (int i = 0; i < lights.counts.x; ++i) {
        float nl = dot(n, -lights.directional_dir[i].xyz);
        e += lights.directional_color[i].rgb
             * (max(nl, 0.0) * front * sun_front[i] + max(-nl, 0.0) * translucency * sun_back[i]);
    }
    vec4 lamp_front = point_shadows(p, n);
    vec4 lamp_back = point_shadows(p, -n);
    for (int i = 0; i < lights.counts.y; ++i) {
        vec3 d = lights.point_pos[i].xyz - p;
        float dist = length(d);
        vec3 l = d / max(dist, 1e-4);
        float fade = clamp(1.0 - pow(dist / lights.point_pos[i].w, 4.0), 0.0, 1.0);
        float falloff = fade * fade / (dist * dist + 1.0) * spot_factor(lights.point_spot[i], l);
        float nl = dot(n, l);
        e += lights.point_color[i].rgb * falloff
             * (max(nl, 0.0) * front * point_shadow(i, lamp_front)
                + max(-nl, 0.0) * translucency * point_shadow(i, lamp_back));
    }
    return e / 3.14159265;
}
#endif

void main() {
    vec2 corner = vec2((gl_VertexID & 1) == 0 ? -1.0 : 1.0, (gl_VertexID & 2) == 0 ? -1.0 : 1.0);
    float c = cos(in_angle), s = sin(in_angle);
    vec2 turned = vec2(c * corner.x - s * corner.y, s * corner.x + c * corner.y) * (0.5 * in_size);
    // A streak: its v along its flight as the view sees it (the streak in view space), its
    // size across and ahead of its centre, the streak's length behind.
    vec2 streak = (mat3(camera.view) * in_streak).xy;
    float streak_length = length(streak);
    if (streak_length > 1e-4 * in_size) {
        vec2 along = streak / streak_length;
        vec2 across = vec2(along.y, -along.x);
        turned = across * (corner.x * 0.5 * in_size)
                 + along * (corner.y * 0.5 * (in_size + streak_length) - 0.5 * streak_length);
    }
    // The view's right and up in the world: the rows of its rotation (a mirror's view too,
    // whose rows are its image camera's).
    vec3 right = normalize(vec3(camera.view[0][0], camera.view[1][0], camera.view[2][0]));
    vec3 up = normalize(vec3(camera.view[0][1], camera.view[1][1], camera.view[2][1]));
    vec3 world = in_center + right * turned.x + up * turned.y;
    v_world = world;
    v_corner = corner;
    // Frame f's cell: column f mod columns, row f / columns from the top (the texture's v
    // runs up: it is uploaded bottom row first).
    int frame = int(in_frame);
    vec2 cell = vec2(frame % sheet.x, frame / sheet.x);
    v_uv = vec2((cell.x + 0.5 + 0.5 * corner.x) / float(sheet.x),
                1.0 - (cell.y + 0.5 - 0.5 * corner.y) / float(sheet.y));
    v_color = in_color;
#ifdef LIT
    vec3 toward_viewer = normalize(vec3(camera.view[0][2], camera.view[1][2], camera.view[2][2]));
    v_light = sheet_light(in_center, toward_viewer);
#endif
    gl_Position = camera.view_proj * vec4(world, 1.0);
    // Behind the view's plane is clipped (a mirror's or portal's view: what is behind its surface).
    gl_ClipDistance[CLIP_VIEW_PLANE] = dot(vec4(world, 1.0), camera.clip_plane);
}
