#version 410 core
// A particle a draw instance (engine/render/particle_draw.py): a square of its size about its
// centre, facing the view (its sides along the view's right and up, turned by its angle), made
// from gl_VertexID as a strip of four; nothing per vertex is read.
#include "camera.glsl"
#include "view_axis.glsl"
#ifdef LIT
#include "lights.glsl"
#include "shadows.glsl"
#include "ambient.glsl"
// (a water's body over the sheet: the light down through it, fog.glsl water_light)
#include "fog.glsl"
#endif
#ifdef CLOUD_SHADOWS
#include "clouds.glsl"
#endif
#include "virtual_light_ways.glsl"

in vec3 in_center;   // world
in float in_size;    // metres across
in vec4 in_color;    // linear colour, alpha
in float in_angle;   // radians, about the view's axis
in float in_frame;   // the flipbook's frame
in vec3 in_streak;   // world: its velocity x ParticleEmitter.stretch (0: a square)
#ifdef RIBBON
// A ribbon's segment (ParticleEmitter.ribbon: an instance a segment, from the point in_* to the
// point in_next_*; the points either side of them bend the band).  in_angle is a point's share
// of its life (the texture's u along the band), in_frame its portal crossings.
in vec3 in_prev_center;
in float in_prev_frame;
in vec3 in_next_center;
in float in_next_size;
in vec4 in_next_color;
in float in_next_angle;
in float in_next_frame;
in vec3 in_after_center;
in float in_after_frame;
#define SHADING_QUALIFIER   // (colour and light vary along the band)
#else
#define SHADING_QUALIFIER flat
#endif

uniform ivec2 sheet;  // the flipbook's columns and rows (1, 1: the whole texture)
#ifdef LIT
uniform float translucency;  // the share of its scattered light a particle lets through
#endif

out vec2 v_uv;        // the texture's, in the frame's cell
out vec2 v_corner;    // -1 to 1 across the square (the round spot's shape)
out vec3 v_world;
SHADING_QUALIFIER out vec4 v_color;
#ifdef LIT
SHADING_QUALIFIER out vec3 v_light;  // the light at its centre (a ribbon's: at its point), over pi: its colour is an albedo
#endif

#ifdef LIT
// Point light i's image along ``l`` (towards the light) as the particle's centre takes it: its
// cookie's colour there (spot_cookie.glsl, its finest level), a rectangle's picture's mean
// colour (PANEL_PICTURES), white without either.
vec3 lamp_image(int i, vec3 l) {
    vec3 image = vec3(1.0);
#ifdef SPOT_COOKIES
    image = cookie_light(cookie_place(lights.point_cookie_u[i], lights.point_cookie_v[i], lights.point_spot[i], l),
                         vec2(0.0), vec2(0.0));
#endif
#ifdef PANEL_PICTURES
    image *= face_mean(lights.point_rect_v[i]);
#endif
    return image;
}

// The light a thin sheet at ``p`` facing ``n`` scatters towards the viewer, over its albedo
// and pi: (1 - translucency) of what falls on its front, translucency of what falls on its
// back (scene.frag's diffuse transmission, Material.diffuse_transmission, for a sheet that
// faces the viewer), with the lights' shadows and cookies at its centre; light through mirrors
// and portals too (VIRTUAL_LIGHTS builds, while one shines).
vec3 sheet_light(vec3 p, vec3 n) {
    AmbientBoxes boxes = ambient_boxes(p, vec3(0.0));  // (no normal bias: a sheet has two sides)
    float front = 1.0 - translucency;
    // (the light from all round, and each light below, through a water's body on its way, as
    // scene.frag's; 1 but in FOG_WATER builds)
    vec3 e = (ambient_irradiance(boxes, n) * front + ambient_irradiance(boxes, -n) * translucency)
             * water_skylight(p);
    vec4 sun_front = directional_shadows(p, n);
    vec4 sun_back = directional_shadows(p, -n);
#ifdef SEE_THROUGH_SHADOWS   // (the share the see-through things over it let through)
    sun_front *= see_through_shadows(p, n);
    sun_back *= see_through_shadows(p, -n);
#endif
    for (int i = 0; i < lights.counts.x; ++i) {
        float nl = dot(n, -lights.directional_dir[i].xyz);
        float clouded = 1.0;   // a CloudLayer's shadow on the sun's and the moons' light (lights.glsl's w)
#ifdef CLOUD_SHADOWS
        if (lights.directional_dir[i].w != 0.0) clouded = cloud_shadow(p, -lights.directional_dir[i].xyz);
#endif
        e += lights.directional_color[i].rgb * water_light(p, -lights.directional_dir[i].xyz, 1e30) * clouded
             * (max(nl, 0.0) * front * sun_front[i] + max(-nl, 0.0) * translucency * sun_back[i]);
    }
    vec4 lamp_front = point_shadows(p, n);
    vec4 lamp_back = point_shadows(p, -n);
    for (int i = 0; i < lights.counts.y; ++i) {
        vec3 d = lights.point_pos[i].xyz - p;
        float dist = length(d);
        vec3 l = d / max(dist, 1e-4);
        float falloff = lamp_falloff(i, dist, l);
        float nl = dot(n, l);
        e += lamp_image(i, l) * lights.point_color[i].rgb * water_light(p, l, dist) * falloff
             * (max(nl, 0.0) * front * point_shadow(i, lamp_front)
                + max(-nl, 0.0) * translucency * point_shadow(i, lamp_back));
    }
#ifdef VIRTUAL_LIGHTS
    // Light through mirrors and portals (virtual_light_ways.glsl), onto whichever side it
    // reaches, shadowed as it is there.
    for (int i = 0; i < virtual_lights.virtual_count.x; ++i) {
        vec3 l;
        float dist;
        float falloff = virtual_falloff(i, p, l, dist);
        if (falloff <= 0.0 || !virtual_comes_through(i, p, l, dist)) continue;
        float nl = dot(n, l);
        vec3 side = nl >= 0.0 ? n : -n;
#ifdef SPOT_COOKIES
        vec3 cookie = cookie_light(cookie_place(virtual_lights.virtual_cookie_u[i], virtual_lights.virtual_cookie_v[i],
                                                virtual_lights.virtual_spot[i], l), vec2(0.0), vec2(0.0));
#else
        const vec3 cookie = vec3(1.0);
#endif
#ifdef PANEL_PICTURES
        cookie *= face_mean(virtual_lights.virtual_rect_v[i]);
#endif
        e += cookie * virtual_lights.virtual_color[i].rgb * virtual_kept(i, p, l, dist) * falloff * abs(nl)
             * (nl >= 0.0 ? front : translucency)
             * virtual_shadow(i, p, side, l, dist);
    }
#endif
    return e / 3.14159265;
}
#endif

#ifdef RIBBON
// A segment of a ribbon as a strip of four: vertices 0 and 1 either side of its start, 2 and 3
// either side of its end.  Across the band at a point is across the line through the points
// either side of it (the band bends through it with no gap or overlap between segments) and
// across the way to the view's eye from it (it faces the view); a segment between points carried through a
// portal between them (their crossings differ) has no area.
void main() {
    bool at_end = gl_VertexID >= 2;
    float side = (gl_VertexID & 1) == 0 ? -1.0 : 1.0;
    vec3 point = at_end ? in_next_center : in_center;
    vec3 before = at_end ? in_center : (in_prev_frame == in_frame ? in_prev_center : in_center);
    vec3 after = at_end ? (in_after_frame == in_next_frame ? in_after_center : in_next_center) : in_next_center;
    // (towards the view's eye from the point: a perspective view's rays fan out, so a band
    // seen along itself close up keeps its width; an orthographic view's, its axis)
    vec3 toward_viewer = ray_eye(camera.eye.xyz, view_axis(camera.view_proj), point) - point;
    toward_viewer *= inversesqrt(max(dot(toward_viewer, toward_viewer), 1e-24));
    vec3 across = cross(after - before, toward_viewer);
    float across_length = length(across);
    across = across_length > 1e-12 ? across / across_length : vec3(0.0);
    float size = at_end ? in_next_size : in_size;
    vec3 world = in_frame == in_next_frame ? point + across * (0.5 * size * side) : in_center;
    v_world = world;
    v_corner = vec2(0.0, side);  // (the untextured band: soft across, as the round spot is)
    v_uv = vec2(at_end ? in_next_angle : in_angle, 0.5 + 0.5 * side);
    v_color = at_end ? in_next_color : in_color;
#ifdef LIT
    v_light = sheet_light(point, toward_viewer);
#endif
    gl_Position = camera.view_proj * vec4(world, 1.0);
    gl_ClipDistance[CLIP_VIEW_PLANE] = dot(vec4(world, 1.0), camera.clip_plane);
}
#else
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
#endif
