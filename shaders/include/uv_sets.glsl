// Which UV set each material map reads (Material.second_uv_maps).  A build of the scene
// shaders with SECOND_UV_MAPS (the maps' bits: UV_BIT_TEXTURE, UV_BIT_NORMAL_MAP, ... from
// engine/render/shader_library.py, components/rendering.py's second_uv_mask) reads the
// mesh's second set (Mesh.second_uvs: in_uv.zw, carried as v_uv2) for the maps it names;
// every other build reads v_uv alone.  The choice is a constant the compiler folds: no
// branch is left in the shader.
// Included by scene.frag after its v_uv (and v_uv2) inputs.

#ifdef PARALLAX
// Where the view ray meets the normal map's heights (parallax.glsl; scene.frag sets it before
// any map is read): every map is read there.
vec2 parallax_shift = vec2(0.0);
#define PARALLAX_SHIFT + parallax_shift
#else
#define PARALLAX_SHIFT
#endif
#ifdef SECOND_UV_MAPS
#define MAP_UV_PLAIN(bit) ((((SECOND_UV_MAPS) & (bit)) != 0) ? v_uv2 : v_uv)
#else
#define MAP_UV_PLAIN(bit) v_uv
#endif
#define MAP_UV(bit) (MAP_UV_PLAIN(bit) PARALLAX_SHIFT)
// A map's texel where it is read: with a parallax shift, filtered by the plain UVs' screen
// derivatives (the shifted UVs jump where the ray passes a height's edge: their own would
// pick the smallest mip there, a seam of sparkles).
// (bounded_footprint: footprint.glsl; a software rasteriser filters by the coordinates' own
// derivatives, the gradients given or not.)
#include "footprint.glsl"
#ifdef PARALLAX
#define MAP_TEXTURE(map, bit) textureGrad(map, bounded_footprint(MAP_UV(bit)), dFdx(MAP_UV_PLAIN(bit)), dFdy(MAP_UV_PLAIN(bit)))
#else
#define MAP_TEXTURE(map, bit) texture(map, bounded_footprint(MAP_UV(bit)))
#endif
