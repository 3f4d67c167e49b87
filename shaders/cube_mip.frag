#version 410 core
// A cube map's next mip level from the one above it (the 2x2 box filter glGenerateMipmap
// uses): each texel samples the level above bilinearly in the direction of its centre,
// which falls where the four texels it covers meet, so the four weigh a quarter each.
// Seamless cube filtering blends across face edges. The source is limited to the level
// above (base = max level), so the level written is never one being read.
#include "cube_faces.glsl"

uniform samplerCube source;
uniform float level_size;  // texels along a face at the level written

flat in int g_face;
out vec4 color;

void main() {
    vec2 st = gl_FragCoord.xy / level_size * 2.0 - 1.0;
    color = textureLod(source, cube_face_direction(g_face, st), 0.0);
}
