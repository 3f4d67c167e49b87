// Reflection probes as the scene shader samples them: engine/render/probes.py captures them,
// engine/rules/probe_rules.py says which probes an object samples and with what weight.
// Included by scene.frag after sky_map, sky_face_size, roughness_lod_bias (ggx.glsl) and
// sample_environment.
uniform samplerCube probe_map;  // the batch's reflection probe (the strongest, when it blends)
uniform float probe_face_size;
uniform vec4 probe_position;    // xyz: where the probe was captured; w: top level of a GGX-prefiltered chain (0: box mips)
uniform vec4 probe_box_min;     // xyz: its influence box; w = 1: box projection on
uniform vec4 probe_box_max;
#ifdef PROBE_BLEND
// Probe blending (Unity HDRP's and Bevy's weighted blending of influence volumes), built for
// a batch whose instances blend: a second probe with the same uniforms; the instance's
// v_reflect.z and v_reflect.w weigh the two probes and the sky takes what is left of 1
// (probe_rules.probe_blend).  A second cube-map unit, not a cube-map array (GL 4.1).
uniform samplerCube probe2_map;
uniform float probe2_face_size;
uniform vec4 probe2_position;
uniform vec4 probe2_box_min;
uniform vec4 probe2_box_max;
#ifdef PROBE_REST
// A curved object with a probe of its own where influence boxes hold it in part: its own
// probe takes what the boxes' weights leave, in place of the sky (probe_rules.probe_blend).
uniform samplerCube probe_rest_map;
uniform float probe_rest_face_size;
uniform vec4 probe_rest_position;
uniform vec4 probe_rest_box_min;
uniform vec4 probe_rest_box_max;
#endif
#endif

// Box projection, the level a roughness reads, one probe's lookup.
#include "probe_lookup.glsl"

// What the object's probes saw along ``ray`` from ``p``: ``footprint_lod`` is the ray's
// footprint level in texels of the first probe's faces (probe_face_size).  Blended, each
// probe and the sky are read at their own footprint level (their faces differ in size).
vec3 probe_radiance(vec3 p, vec3 ray, float footprint_lod, float roughness) {
    vec3 first = probe_lookup(probe_map, probe_position, probe_box_min, probe_box_max, p, ray,
                              footprint_lod, roughness);
#ifdef PROBE_BLEND
    vec3 second = probe_lookup(probe2_map, probe2_position, probe2_box_min, probe2_box_max, p, ray,
                               footprint_lod + log2(probe2_face_size / probe_face_size), roughness);
    float sky = max(1.0 - v_reflect.z - v_reflect.w, 0.0);
#ifdef PROBE_REST
    vec3 env = probe_lookup(probe_rest_map, probe_rest_position, probe_rest_box_min, probe_rest_box_max, p, ray,
                            footprint_lod + log2(probe_rest_face_size / probe_face_size), roughness);
#else
    vec3 env = sample_environment(ray, footprint_lod + log2(sky_face_size / probe_face_size), roughness);
#endif
    return first * v_reflect.z + second * v_reflect.w + env * sky;
#else
    return first;
#endif
}
