// One reflection probe's lookup (engine/render/probes.py captures it): box projection and the
// mip level a roughness reads.  Functions only, no uniforms: shared by the scene shader's
// probes (probe.glsl) and the mirror composite's fallback (mirror_composite.frag).  Needs
// roughness_lod_bias (ggx.glsl).

// Box projection (parallax correction, as Unity's and Godot's probes do): follow the ray
// from the shaded point to the wall of the probe's box and look that point up from where
// the probe was captured (``centre``); without a box (box_min.w = 0), the ray's direction is
// looked up as it is.
vec3 box_projected(vec3 position, vec3 ray, vec3 centre, vec4 box_min, vec4 box_max) {
    if (box_min.w < 0.5) return ray;
    vec3 wall = mix(box_min.xyz, box_max.xyz, step(vec3(0.0), ray));
    vec3 t = (wall - position) / ray;
    return position + ray * min(min(t.x, t.y), t.z) - centre;
}

// The probe's mip level for a lookup.  A box-filtered chain (ggx_top = 0): the pixel's
// footprint level, blurred by the roughness bias (0 at roughness 0: a mirror-smooth surface
// samples its footprint's level).  A GGX-prefiltered chain (ggx_top = its top level): level
// L holds perceptual roughness L / ggx_top (engine/render/probes.py, cube_mip.frag), so the
// level is roughness x ggx_top and nothing else, as UE4's and three.js's prefiltered probes
// are read: roughness 0 reads level 0, the capture itself; a footprint raising it would read
// a level convolved for a rougher lobe and bleed colours across the image's edges.
float probe_level(float footprint_lod, float roughness, float ggx_top) {
    if (ggx_top > 0.0) return roughness * ggx_top;
    return footprint_lod + roughness_lod_bias(roughness);
}

vec3 probe_lookup(samplerCube map, vec4 position, vec4 box_min, vec4 box_max, vec3 p, vec3 ray,
                  float footprint_lod, float roughness) {
    return textureLod(map, box_projected(p, ray, position.xyz, box_min, box_max),
                      probe_level(footprint_lod, roughness, position.w)).rgb;
}
