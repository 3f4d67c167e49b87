// Diffuse image lighting: the irradiance E(n) arriving at a surface from the sky (or the
// hemisphere fallback) and the reflection probes whose influence boxes hold it, as order-2
// spherical harmonics (Ramamoorthi and Hanrahan 2001). The convention, the sources and why
// the boxes are weighed per pixel: engine/render/irradiance.py. Coefficients are the
// irradiance's, E_lm = A_l L_lm, in the order (0,0), (1,-1), (1,0), (1,1), (2,-2), (2,-1),
// (2,0), (2,1), (2,2); a Lambertian surface of albedo a reflects a E(n) / pi.
// Needs lights.glsl (lights.sky_sh).
#define MAX_IRRADIANCE_PROBES 32
layout(std140) uniform Irradiance {
    ivec4 count;                              // x: boxes (0 while a probe is captured: sky only)
    vec4 centre[MAX_IRRADIANCE_PROBES];       // xyz: the box's centre; w: its blend distance
    vec4 half_size[MAX_IRRADIANCE_PROBES];    // xyz: half its size; w: its row of the table
} irradiance;
uniform sampler2D irradiance_table;           // row r, texel i: coefficient i of the probe of row r

// The order-2 basis Y_lm(n) (real, orthonormal).
void sh_basis(vec3 n, out float y[9]) {
    y[0] = 0.2820948;
    y[1] = 0.4886025 * n.y;
    y[2] = 0.4886025 * n.z;
    y[3] = 0.4886025 * n.x;
    y[4] = 1.0925484 * n.x * n.y;
    y[5] = 1.0925484 * n.y * n.z;
    y[6] = 0.3153916 * (3.0 * n.z * n.z - 1.0);
    y[7] = 1.0925484 * n.x * n.z;
    y[8] = 0.5462742 * (n.x * n.x - n.y * n.y);
}

// A box's weight at p: probe_rules.probe_weight (0 outside, rising linearly from the nearest
// wall to 1 at the blend distance inside; 1 everywhere inside with none).
float box_weight(int i, vec3 p) {
    vec3 away = irradiance.half_size[i].xyz - abs(p - irradiance.centre[i].xyz);
    float inside = min(min(away.x, away.y), away.z);
    if (inside < 0.0) return 0.0;
    float blend = irradiance.centre[i].w;
    return blend <= 0.0 ? 1.0 : min(1.0, inside / blend);
}

// E(n) at p: the two boxes weighing most (ties: the nearest centre), weights normalised only
// when they sum past 1, the sky (lights.sky_sh) taking what is left of 1: the rule of
// probe_rules.probe_blend, at the shaded point.
vec3 ambient_irradiance(vec3 p, vec3 n) {
    float y[9];
    sh_basis(n, y);
    int best[2] = int[2](-1, -1);
    float w[2] = float[2](0.0, 0.0);
    float dist[2] = float[2](0.0, 0.0);
    for (int i = 0; i < irradiance.count.x; ++i) {
        float weight = box_weight(i, p);
        if (weight <= 0.0) continue;
        float d = length(p - irradiance.centre[i].xyz);
        if (best[0] < 0 || weight > w[0] || (weight == w[0] && d < dist[0])) {
            best[1] = best[0]; w[1] = w[0]; dist[1] = dist[0];
            best[0] = i; w[0] = weight; dist[0] = d;
        } else if (best[1] < 0 || weight > w[1] || (weight == w[1] && d < dist[1])) {
            best[1] = i; w[1] = weight; dist[1] = d;
        }
    }
    int found = best[1] >= 0 ? 2 : (best[0] >= 0 ? 1 : 0);
    float scale = 1.0 / max(1.0, w[0] + w[1]);
    vec3 e = vec3(0.0);
    float sky = 1.0;
    // A loop as long as the boxes found: a quad outside every box reads no texel of the table.
    for (int k = 0; k < found; ++k) {
        int row = int(irradiance.half_size[best[k]].w);
        vec3 probe = vec3(0.0);
        for (int c = 0; c < 9; ++c) probe += texelFetch(irradiance_table, ivec2(c, row), 0).rgb * y[c];
        e += probe * (w[k] * scale);
        sky -= w[k] * scale;
    }
    vec3 from_sky = vec3(0.0);
    for (int c = 0; c < 9; ++c) from_sky += lights.sky_sh[c].rgb * y[c];
    return max(e + from_sky * max(sky, 0.0), vec3(0.0));
}
