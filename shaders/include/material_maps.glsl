// Material maps beside the albedo and normal maps: Material.metallic_roughness_map,
// Material.emissive_map and Material.occlusion_map, as glTF 2.0 defines its
// metallicRoughnessTexture, emissiveTexture and occlusionTexture (Material.lightmap:
// lightmap.glsl).  Each is sampled only in a build of scene.frag for batches that have it
// (METALLIC_ROUGHNESS_MAP, EMISSIVE_MAP, OCCLUSION_MAP: engine/render/scene_programs.py);
// without the define these functions are the plain material's, and a map left out costs
// nothing.
// Included by scene.frag after its Surface struct; reads its v_uv, or where Material.second_uv_maps
// names the map its v_uv2 (MAP_UV: uv_sets.glsl).

#ifdef METALLIC_ROUGHNESS_MAP
uniform sampler2D metallic_roughness_map;  // linear: green = roughness, blue = metallic (red: a packed occlusion)
#endif
#ifdef EMISSIVE_MAP
uniform sampler2D emissive_map;            // sRGB colour, decoded to linear by the texture unit
#endif
#ifdef OCCLUSION_MAP
uniform sampler2D occlusion_map;           // linear: red = how much light from all round reaches
#endif
#if defined(OCCLUSION_MAP) || defined(OCCLUSION_PACKED)
uniform float occlusion_strength;          // Material.occlusion_strength (glTF's strength)
#endif

// The share of the light from all round (ambient light, sky and probe reflections) that
// reaches the surface: glTF's 1 + strength x (occlusion - 1); 1 without a map.  A light's
// own light is not scaled (glTF: occlusion is of indirect light only).
float material_occlusion() {
#if defined(OCCLUSION_MAP)
    return 1.0 + occlusion_strength * (MAP_TEXTURE(occlusion_map, UV_BIT_OCCLUSION_MAP).r - 1.0);
#elif defined(OCCLUSION_PACKED)
    // glTF's packed occlusion-roughness-metallic image: the occlusion in its red (one sampler)
    return 1.0 + occlusion_strength * (MAP_TEXTURE(metallic_roughness_map, UV_BIT_OCCLUSION_MAP).r - 1.0);
#else
    return 1.0;
#endif
}

// Scale the surface's metallic and roughness factors by the map (glTF: the factors multiply
// the texture's B and G channels).  Returns the texel's metallic share (1 without a map),
// which ``mapped_reflection`` weighs a sky or probe reflection by.
float apply_metallic_roughness(inout Surface s) {
#ifdef METALLIC_ROUGHNESS_MAP
    vec3 texel = MAP_TEXTURE(metallic_roughness_map, UV_BIT_METALLIC_ROUGHNESS_MAP).rgb;
    s.roughness *= texel.g;
    s.metallic *= texel.b;
    return texel.b;
#else
    return 1.0;
#endif
}

// The emitted colour an Emissive component's power multiplies: the emissive map's colour
// (glTF's emissiveFactor x emissiveTexture, the factor being the power), else the diffuse
// colour (the engine's Emissive without a map).
vec3 emitted_colour(Surface s) {
#ifdef EMISSIVE_MAP
    return MAP_TEXTURE(emissive_map, UV_BIT_EMISSIVE_MAP).rgb;
#else
    return s.albedo;
#endif
}

// A sky or probe reflection, ``reflected`` = mix(lit, environment, mix), weighed by the
// metallic-roughness map's metallic share: mix(lit, reflected, share) is the reflection with
// its mix scaled by the share, so what the map says is not metal keeps its own shading.
// Other reflect variants (a mirror's, a portal's) are left as they are.
vec3 mapped_reflection(uint variant, vec3 lit, vec3 reflected, float metal_share) {
#ifdef METALLIC_ROUGHNESS_MAP
    if (variant == REFLECT_SKYBOX || variant == REFLECT_CUBE) return mix(lit, reflected, metal_share);
#endif
    return reflected;
}
