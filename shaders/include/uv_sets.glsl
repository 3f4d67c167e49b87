// Which UV set each material map reads (Material.second_uv_maps).  A build of the scene
// shaders with SECOND_UV_MAPS (the maps' bits: UV_BIT_TEXTURE, UV_BIT_NORMAL_MAP, ... from
// engine/render/shader_library.py, components/rendering.py's second_uv_mask) reads the
// mesh's second set (Mesh.second_uvs: in_uv.zw, carried as v_uv2) for the maps it names;
// every other build reads v_uv alone.  The choice is a constant the compiler folds: no
// branch is left in the shader.
// Included by scene.frag after its v_uv (and v_uv2) inputs.

#ifdef SECOND_UV_MAPS
#define MAP_UV(bit) ((((SECOND_UV_MAPS) & (bit)) != 0) ? v_uv2 : v_uv)
#else
#define MAP_UV(bit) v_uv
#endif
