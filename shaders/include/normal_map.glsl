// Tangent-space normal maps (Material.normal_map), OpenGL convention: RGB = n x 0.5 + 0.5, red
// towards +U, green towards +V, blue out of the surface; the texture is linear (not sRGB).
// Shared by the scene pass (a frame from screen derivatives) and the composite of a bumpy
// mirror (a frame from the mirror's UV mapping): both pass the unit directions in which U and
// V grow across the surface.
uniform sampler2D normal_map;

// The normal a texel ``texel`` of the map gives in the frame (t: +U, b: +V, n: out of the
// surface, all unit), its slope scaled by scale.
vec3 bent_by(vec3 t, vec3 b, vec3 n, vec3 texel, float scale) {
    vec3 m = texel * 2.0 - 1.0;
    return normalize((t * m.x + b * m.y) * scale + n * m.z);
}

// The map's normal at uv in the frame (t: +U, b: +V, n: out of the surface, all unit), its
// slope scaled by scale (glTF's normalTexture.scale; 0: n itself), filtered by the UVs'
// screen derivatives uv_dx and uv_dy: a caller takes them before anything may discard or
// branch by pixel, where GLSL still defines them (the composite leaves pixels out first;
// the scene pass's parallax builds read the map where the ray meets the heights).
vec3 bent_normal(vec3 t, vec3 b, vec3 n, vec2 uv, vec2 uv_dx, vec2 uv_dy, float scale) {
    return bent_by(t, b, n, textureGrad(normal_map, uv, uv_dx, uv_dy).xyz, scale);
}
