#version 410 core
// An atmosphere's sky-view table on the GPU (engine/render/sky_view.py): the radiance the eye
// sees per unit of sunlight along each of the table's ways, a texel a way (rows: elevation,
// sqrt of it over 90 degrees; columns: azimuth from the sun's, 0 to 180 degrees), marched to
// the top of the air as engine/render/atmosphere.py's sky_view_table does (the reference this
// is held to): VIEW_STEPS steps finer near the eye, each step's Rayleigh and Mie single
// scattering of the sun's light through the transmittance table plus the multiple scattering
// table's, integrated over the step in closed form (Hillaire 2020, section 5.3).  The
// constants are that module's (glsl_defines); the two tables are its, uploaded once an air.

uniform sampler2D transmittance_table;   // rows: radius (Bruneton's x_r), columns: x_mu
uniform sampler2D scattering_table;      // rows: height 0..top, columns: the sun's cosine -1..1
uniform vec3 sun;                        // (cos elevation, sin elevation, 0)
uniform float rayleigh_scale;            // Air.rayleigh
uniform float haze_scale;                // Air.haze
uniform float multiple;                  // 1: count the multiple scattering (Air.multiple)
uniform float eye_km;                    // how high the eye stands over the ground (Air.eye_km: Skybox.altitude)

out vec4 out_color;

const float PI = 3.14159265;
const float HORIZON = sqrt((TOP_KM - GROUND_KM) * (TOP_KM + GROUND_KM));

// A table's texel-centre coordinates for fractions (0 the first entry, 1 the last).
vec3 table_at(sampler2D table, float column, float row) {
    vec2 size = vec2(textureSize(table, 0));
    vec2 at = clamp(vec2(column, row), 0.0, 1.0) * (size - 1.0) + 0.5;
    return textureLod(table, at / size, 0.0).rgb;
}

vec3 transmittance(float r, float mu) {
    r = clamp(r, GROUND_KM, TOP_KM);
    mu = clamp(mu, -1.0, 1.0);
    float above = (r - GROUND_KM) * (r + GROUND_KM);                 // r^2 - R^2, without cancellation
    float rho = sqrt(max(above, 0.0));
    float to_top = sqrt(max((TOP_KM - r) * (TOP_KM + r) + r * r * mu * mu, 0.0)) - r * mu;
    float d_min = TOP_KM - r, d_max = rho + HORIZON;
    vec3 through = table_at(transmittance_table, (to_top - d_min) / max(d_max - d_min, 1e-9), rho / HORIZON);
    return mu < 0.0 && r * r * mu * mu - above >= 0.0 ? vec3(0.0) : through;
}

float mie_phase(float nu) {
    float g2 = MIE_G * MIE_G;
    return 3.0 / (8.0 * PI) * (1.0 - g2) * (1.0 + nu * nu)
           / ((2.0 + g2) * pow(max(1.0 + g2 - 2.0 * MIE_G * nu, 1e-6), 1.5));
}

void main() {
    vec2 texel = gl_FragCoord.xy - 0.5;   // (column, row): the table's COLUMNS x ROWS
    float elevation = 0.5 * PI * pow(texel.y / float(ROWS - 1), 2.0);
    float azimuth = PI * texel.x / float(COLUMNS - 1);
    vec3 way = vec3(cos(elevation) * cos(azimuth), sin(elevation), cos(elevation) * sin(azimuth));
    float r0 = GROUND_KM + eye_km;
    float reach = sqrt(max((TOP_KM - r0) * (TOP_KM + r0) + r0 * r0 * way.y * way.y, 0.0)) - r0 * way.y;
    float nu = dot(way, sun);
    float rayleigh_shape = 3.0 / (16.0 * PI) * (1.0 + nu * nu), mie_shape = mie_phase(nu);
    vec3 light = vec3(0.0), through = vec3(1.0);
    for (int k = 0; k < VIEW_STEPS; k++) {
        float u0 = float(k) / float(VIEW_STEPS), u1 = float(k + 1) / float(VIEW_STEPS);
        float t = reach * 0.5 * (u0 * u0 + u1 * u1);
        float step = reach * (u1 * u1 - u0 * u0);
        vec3 point = vec3(0.0, r0, 0.0) + way * t;
        float radius = length(point);
        float height = max(radius - GROUND_KM, 0.0);
        float sun_cos = dot(point, sun) / radius;
        float rayleigh = rayleigh_scale * exp(-height / RAYLEIGH_HEIGHT_KM);
        float mie = haze_scale * exp(-height / MIE_HEIGHT_KM);
        float ozone = rayleigh_scale * max(0.0, 1.0 - abs(height - OZONE_CENTRE_KM) / OZONE_HALF_WIDTH_KM);
        vec3 scattered_r = rayleigh * RAYLEIGH_SCATTERING;
        vec3 scattered_m = vec3(mie * MIE_SCATTERING);
        vec3 extinction = scattered_r + mie * MIE_EXTINCTION + ozone * OZONE_ABSORPTION;
        vec3 source = (scattered_r * rayleigh_shape + scattered_m * mie_shape) * transmittance(radius, sun_cos);
        source += multiple * (scattered_r + scattered_m)
                  * table_at(scattering_table, sun_cos * 0.5 + 0.5, height / (TOP_KM - GROUND_KM));
        vec3 step_through = exp(-extinction * step);
        light += through * (source - source * step_through) / max(extinction, vec3(1e-12));
        through *= step_through;
    }
    out_color = vec4(light, through.g);   // (and what crosses the air from beyond it: a Skybox's space)
}
