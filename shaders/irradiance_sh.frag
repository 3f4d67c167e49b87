#version 410 core
// One probe's irradiance as nine spherical-harmonic coefficients (Ramamoorthi and Hanrahan
// 2001; the convention is engine/render/irradiance.py's): drawn over a row of nine texels of
// the irradiance table, texel i sums coefficient i over every texel of one level of the
// probe's cube map, each weighted by its solid angle, times the band's clamped-cosine
// factor. Read at texel centres of that exact level, a lookup returns the texel itself.
// An irradiance volume's point writes each coefficient in a tile of its own: one fragment a
// draw, its coefficient given.
#include "cube_faces.glsl"

uniform samplerCube source;
uniform float level;      // the level read (a 16-texel one: the mips are box averages)
uniform int level_size;   // its texels across a face
uniform int coefficient_index;  // the one this draw writes (-1: the fragment's column's, a probe's row)
out vec4 coefficient;

const float PI = 3.14159265358979;

// The solid angle of the face region from the centre to corner (s, t) (signed).
float corner_area(float s, float t) {
    return atan(s * t, sqrt(s * s + t * t + 1.0));
}

void main() {
    int i = coefficient_index < 0 ? int(gl_FragCoord.x) : coefficient_index;
    float n = float(level_size);
    vec3 sum = vec3(0.0);
    for (int face = 0; face < 6; ++face) {
        for (int y = 0; y < level_size; ++y) {
            float t0 = float(y) / n * 2.0 - 1.0, t1 = float(y + 1) / n * 2.0 - 1.0;
            for (int x = 0; x < level_size; ++x) {
                float s0 = float(x) / n * 2.0 - 1.0, s1 = float(x + 1) / n * 2.0 - 1.0;
                float area = corner_area(s1, t1) - corner_area(s0, t1) - corner_area(s1, t0) + corner_area(s0, t0);
                vec3 d = normalize(cube_face_direction(face, vec2(0.5 * (s0 + s1), 0.5 * (t0 + t1))));
                float basis[9] = float[9](
                    0.2820948, 0.4886025 * d.y, 0.4886025 * d.z, 0.4886025 * d.x,
                    1.0925484 * d.x * d.y, 1.0925484 * d.y * d.z, 0.3153916 * (3.0 * d.z * d.z - 1.0),
                    1.0925484 * d.x * d.z, 0.5462742 * (d.x * d.x - d.y * d.y));
                sum += textureLod(source, d, level).rgb * (basis[i] * area);
            }
        }
    }
    float band = i == 0 ? PI : (i < 4 ? 2.0 * PI / 3.0 : PI / 4.0);
    coefficient = vec4(sum * band, 1.0);
}
