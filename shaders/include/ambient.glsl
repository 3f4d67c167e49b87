// Diffuse image lighting: the irradiance E(n) arriving at a surface from the sky (or the
// hemisphere fallback), the reflection probes whose influence boxes hold it and an irradiance
// volume's grid (IRRADIANCE_VOLUME builds), as order-2
// spherical harmonics (Ramamoorthi and Hanrahan 2001). The convention, the sources and why
// the boxes are weighed per pixel: engine/render/irradiance.py. Coefficients are the
// irradiance's, E_lm = A_l L_lm, in the order (0,0), (1,-1), (1,0), (1,1), (2,-2), (2,-1),
// (2,0), (2,1), (2,2); a Lambertian surface of albedo a reflects a E(n) / pi.
// Needs lights.glsl (lights.sky_sh).  MAX_IRRADIANCE_PROBES is engine/render/irradiance.py's,
// defined by the shader library.
layout(std140) uniform Irradiance {
    ivec4 count;                              // x: boxes, y: volumes (0, 0 while a probe is captured)
    vec4 centre[MAX_IRRADIANCE_PROBES];       // xyz: the box's centre; w: its blend distance
    vec4 half_size[MAX_IRRADIANCE_PROBES];    // xyz: half its size; w: its row of the table
    vec4 volume_low[MAX_IRRADIANCE_VOLUMES];  // xyz: a volume's lowest corner point; w: its blend distance
    vec4 volume_high[MAX_IRRADIANCE_VOLUMES]; // xyz: its highest; w: its normal bias
    ivec4 volume_points[MAX_IRRADIANCE_VOLUMES];  // xyz: its points along x, y, z; w: its first row
} irradiance;
uniform sampler2D irradiance_table;           // row r, texel i: coefficient i of the probe of row r

// The split-sum's environment BRDF (engine/render/environment_brdf.py): (A, B) at a roughness
// and n.v, so a surface of reflectance f0 reflects f0 A + B of light of 1 from all round.
// Its rows are the table's below the probes' (no sampler of its own: the fullest scene build
// holds 16), read between its entries by bilinear filtering.
// Blue: the sheen's albedo E(n.v) at the sheen's roughness (written once a sheen is drawn).
vec4 environment_brdf_rows(float roughness, float nv) {
    vec2 texel = vec2(nv, roughness) * float(ENVIRONMENT_BRDF_SIZE - 1) + vec2(0.5, 0.5 + float(MAX_IRRADIANCE_PROBES));
    return textureLod(irradiance_table, texel / vec2(textureSize(irradiance_table, 0)), 0.0);
}

vec2 environment_brdf(float roughness, float nv) {
    return environment_brdf_rows(roughness, nv).rg;
}

#ifdef SUBSURFACE
// Bands 1 and 2 of every E(n) weighed per channel: subsurface.glsl sets them about the light
// from all round on a surface that scatters it (subsurface_bands_begin), 1 elsewhere.
vec3 sh_band1 = vec3(1.0);
vec3 sh_band2 = vec3(1.0);
#endif

// E(n) = sum of E_lm Y_lm(n), the basis written out (an array and a loop cost llvmpipe a
// fifth of a frame of diffuse boxes; this costs next to nothing).
vec3 sh_irradiance(vec3 c0, vec3 c1, vec3 c2, vec3 c3, vec3 c4, vec3 c5, vec3 c6, vec3 c7, vec3 c8, vec3 n) {
    vec3 band1 = (c1 * n.y + c2 * n.z + c3 * n.x) * 0.4886025;
    vec3 band2 = (c4 * (n.x * n.y) + c5 * (n.y * n.z) + c7 * (n.x * n.z)) * 1.0925484
        + c6 * (0.3153916 * (3.0 * n.z * n.z - 1.0))
        + c8 * (0.5462742 * (n.x * n.x - n.y * n.y));
#ifdef SUBSURFACE
    band1 *= sh_band1;
    band2 *= sh_band2;
#endif
    return c0 * 0.2820948 + band1 + band2;
}

vec3 table_irradiance(int row, vec3 n) {
    return sh_irradiance(
        texelFetch(irradiance_table, ivec2(0, row), 0).rgb, texelFetch(irradiance_table, ivec2(1, row), 0).rgb,
        texelFetch(irradiance_table, ivec2(2, row), 0).rgb, texelFetch(irradiance_table, ivec2(3, row), 0).rgb,
        texelFetch(irradiance_table, ivec2(4, row), 0).rgb, texelFetch(irradiance_table, ivec2(5, row), 0).rgb,
        texelFetch(irradiance_table, ivec2(6, row), 0).rgb, texelFetch(irradiance_table, ivec2(7, row), 0).rgb,
        texelFetch(irradiance_table, ivec2(8, row), 0).rgb, n);
}

// A box's weight at p: probe_rules.probe_weight (0 outside, rising linearly from the nearest
// wall to 1 at the blend distance inside; 1 everywhere inside with none).
float box_weight(int i, vec3 p) {
    vec3 away = irradiance.half_size[i].xyz - abs(p - irradiance.centre[i].xyz);
    float inside = min(min(away.x, away.y), away.z);
    float blend = irradiance.centre[i].w;
    return inside < 0.0 ? 0.0 : (blend <= 0.0 ? 1.0 : min(1.0, inside / blend));
}

// The boxes lighting a point p: the two weighing most (ties: the nearest centre), weights
// normalised only when they sum past 1, the sky (lights.sky_sh) taking what is left of 1: the
// rule of probe_rules.probe_blend, at the shaded point.  Found once a pixel and read for the
// diffuse light (at the normal) and the environment's reflection (at the reflected ray).
// Written for llvmpipe, which runs every branch: scalars, not arrays (an array indexed by a
// variable is kept in memory), selects, not ifs, in the loop over the boxes.
struct AmbientBoxes {
    int found;        // boxes holding p: 0, 1 or 2
    int best0, best1; // their indices in the block
    float w0, w1;     // their weights, normalised
    float sky;        // the sky's share: 1 - w0 - w1 (- volume)
    float volume;     // the irradiance volume's weight (its grid takes it from the boxes and sky)
#ifdef IRRADIANCE_VOLUME
    // Its coefficients at the point, blended between the eight grid points about it.
    vec3 c0, c1, c2, c3, c4, c5, c6, c7, c8;
#endif
};

#ifdef IRRADIANCE_VOLUME
// Coefficient c of the volume at grid coordinates g (in points from its lowest corner): tile
// (c, y) of the table holds layer y, x across and z down (irradiance.VolumeGrid.texel), so
// bilinear filtering blends across x and z within a tile (g clamped to the grid: a lookup's
// footprint never leaves its tile) and a mix the two layers about g.y.
vec3 volume_coefficient(float c, vec2 at0, vec2 at1, float step, float fy, vec2 size) {
    vec2 across = vec2(c * step, 0.0);
    return mix(textureLod(irradiance_table, (at0 + across) / size, 0.0).rgb,
               textureLod(irradiance_table, (at1 + across) / size, 0.0).rgb, fy);
}

// Volume i's weight at p moved by its normal bias along n (0 outside its box, rising linearly
// from its walls to 1 at the blend distance inside, as a probe's box_weight).
float volume_weight(int i, vec3 p, vec3 n) {
    vec3 q = p + n * irradiance.volume_high[i].w;
    vec3 away = min(q - irradiance.volume_low[i].xyz, irradiance.volume_high[i].xyz - q);
    float inside = min(min(away.x, away.y), away.z);
    float blend = irradiance.volume_low[i].w;
    return inside < 0.0 ? 0.0 : (blend <= 0.0 ? 1.0 : min(1.0, inside / blend));
}

// The volume weighing most at p (the first of equals) and its coefficients there, read at p
// moved by its normal bias along n; where volumes overlap, the other's light is not blended in.
void volume_at(inout AmbientBoxes b, vec3 p, vec3 n) {
    int best = 0;
    float weight = 0.0;
    for (int i = 0; i < irradiance.count.y; ++i) {
        float w = volume_weight(i, p, n);
        best = w > weight ? i : best;
        weight = max(w, weight);
    }
    b.volume = weight;
    vec3 low = irradiance.volume_low[best].xyz, high = irradiance.volume_high[best].xyz;
    vec3 q = p + n * irradiance.volume_high[best].w;
    ivec3 count = max(irradiance.volume_points[best].xyz, ivec3(2));   // (none: a grid of 2 read, weighing 0)
    vec3 g = clamp((q - low) / max(high - low, vec3(1e-6)), 0.0, 1.0) * vec3(count - 1);
    float j0 = min(floor(g.y), float(count.y - 2));
    float fy = g.y - j0;
    vec2 size = vec2(textureSize(irradiance_table, 0));
    vec2 at0 = vec2(g.x + 0.5, float(irradiance.volume_points[best].w) + j0 * float(count.z) + g.z + 0.5);
    vec2 at1 = at0 + vec2(0.0, float(count.z));
    float step = float(count.x);
    b.c0 = volume_coefficient(0.0, at0, at1, step, fy, size);
    b.c1 = volume_coefficient(1.0, at0, at1, step, fy, size);
    b.c2 = volume_coefficient(2.0, at0, at1, step, fy, size);
    b.c3 = volume_coefficient(3.0, at0, at1, step, fy, size);
    b.c4 = volume_coefficient(4.0, at0, at1, step, fy, size);
    b.c5 = volume_coefficient(5.0, at0, at1, step, fy, size);
    b.c6 = volume_coefficient(6.0, at0, at1, step, fy, size);
    b.c7 = volume_coefficient(7.0, at0, at1, step, fy, size);
    b.c8 = volume_coefficient(8.0, at0, at1, step, fy, size);
}
#endif

AmbientBoxes ambient_boxes(vec3 p, vec3 n) {
    AmbientBoxes b;
    b.found = 0; b.best0 = 0; b.best1 = 0; b.w0 = 0.0; b.w1 = 0.0; b.sky = 1.0; b.volume = 0.0;
#ifdef AMBIENT_PROBES
    int best0 = 0, best1 = 0;
    float w0 = 0.0, w1 = 0.0, d0 = 0.0, d1 = 0.0;  // a weight of 0: no box yet
    for (int i = 0; i < irradiance.count.x; ++i) {
        float w = box_weight(i, p);
        vec3 v = p - irradiance.centre[i].xyz;
        float d = dot(v, v);
        bool first = w > 0.0 && (w > w0 || (w == w0 && d < d0));
        bool second = !first && w > 0.0 && (w > w1 || (w == w1 && d < d1));
        best1 = first ? best0 : (second ? i : best1);
        w1 = first ? w0 : (second ? w : w1);
        d1 = first ? d0 : (second ? d : d1);
        best0 = first ? i : best0;
        w0 = first ? w : w0;
        d0 = first ? d : d0;
    }
    float scale = 1.0 / max(1.0, w0 + w1);
    b.found = w1 > 0.0 ? 2 : (w0 > 0.0 ? 1 : 0);
    b.best0 = best0; b.best1 = best1;
    b.w0 = w0 * scale; b.w1 = w1 * scale;
    b.sky = max(1.0 - (w0 + w1) * scale, 0.0);
#endif
#ifdef IRRADIANCE_VOLUME
    // The volume takes its weight's share; the boxes and the sky keep what it leaves.
    volume_at(b, p, n);
    float rest = 1.0 - b.volume;
    b.w0 *= rest; b.w1 *= rest; b.sky *= rest;
#endif
    return b;
}

// The sky's irradiance E(n) (lights.sky_sh).
vec3 sky_irradiance(vec3 n) {
    return sh_irradiance(lights.sky_sh[0].rgb, lights.sky_sh[1].rgb, lights.sky_sh[2].rgb, lights.sky_sh[3].rgb,
                         lights.sky_sh[4].rgb, lights.sky_sh[5].rgb, lights.sky_sh[6].rgb, lights.sky_sh[7].rgb,
                         lights.sky_sh[8].rgb, n);
}

// The boxes' part of E(n): each box's irradiance times its weight (0 outside every box), and
// the volume's by its weight.
vec3 boxes_irradiance(AmbientBoxes b, vec3 n) {
    vec3 e = vec3(0.0);
#ifdef AMBIENT_PROBES
    // A loop as long as the boxes found: a quad outside every box reads no texel of the table.
    // (A box's row is one IrradianceTable._row_for gave, below MAX_IRRADIANCE_PROBES: inside.)
    for (int k = 0; k < b.found; ++k) {
        int box = k == 0 ? b.best0 : b.best1;
        e += table_irradiance(int(irradiance.half_size[box].w), n) * (k == 0 ? b.w0 : b.w1);
    }
#endif
#ifdef IRRADIANCE_VOLUME
    e += sh_irradiance(b.c0, b.c1, b.c2, b.c3, b.c4, b.c5, b.c6, b.c7, b.c8, n) * b.volume;
#endif
    return e;
}

// E(n) at the boxes' point: each box's irradiance by its weight, the sky's by its share.
vec3 ambient_irradiance(AmbientBoxes b, vec3 n) {
    return max(boxes_irradiance(b, n) + sky_irradiance(n) * b.sky, vec3(0.0));
}
