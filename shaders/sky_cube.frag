#version 410 core
// A face of a generated sky's cube map (engine/render/sky_bake.py): the sky's function
// (include/sky_model.glsl) along the direction of each texel's centre, the face drawn into a
// 2D target the size of the face and copied into it.  Rows are the face's t axis, columns its
// s axis (GL's table: include/cube_faces.glsl), as the texels of engine/core/cube_faces.py's
// face_directions.
#include "cube_faces.glsl"
#include "hdr.glsl"
#include "sky_model.glsl"

uniform int face;          // 0-5: +X, -X, +Y, -Y, +Z, -Z
uniform float face_size;   // texels across the face

out vec4 out_color;

void main() {
    vec2 st = gl_FragCoord.xy / face_size * 2.0 - 1.0;
    out_color = vec4(hdr_store(generated_sky(normalize(cube_face_direction(face, st)))), 1.0);
}
