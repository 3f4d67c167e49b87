// A baked lightmap (Material.lightmap; three.js's lightMap, Unity's and Godot's lightmaps):
// the light from all round as a bake saw it, in place of the sky's, a probe's and an
// irradiance volume's diffuse light (scene.frag direct_lighting).  Sampled only in the
// LIGHTMAP builds (engine/render/scene_programs.py); read on the UV set Material.second_uv_maps
// names for it (uv_sets.glsl's MAP_TEXTURE).  Needs ggx.glsl (PI).
#ifdef LIGHTMAP
uniform sampler2D lightmap;                // sRGB colour: what a white matte surface shows (Material.lightmap)
uniform float lightmap_intensity;          // Material.lightmap_intensity

// The irradiance the lightmap gives the surface (LIGHTMAP builds: in place of the sky's, a
// probe's and a volume's): pi x its colour x the intensity, so a matte surface of albedo a
// shows a x the map's colour x the intensity (Lambert's a / pi of it), as the bake saw it.
vec3 lightmap_irradiance() {
    return PI * lightmap_intensity * MAP_TEXTURE(lightmap, UV_BIT_LIGHTMAP).rgb;
}
#endif
