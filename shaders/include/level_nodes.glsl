// A reflection level's node image (engine/render/targets.py RenderTargets.node: which of the
// level's views drew each pixel), read by the screen passes a level's views are found or
// marched with (LEVEL_VIEWS builds: screen-space ambient occlusion's, screen reflections'),
// each drawn once a view: a sample on another view's pixel shows another world.  An image
// NODE_STEP times smaller each way than the level reads its every NODE_STEP-th pixel.
uniform usampler2D node_map;
#ifndef NODE_STEP
#define NODE_STEP 1
#endif

// Which of the level's views drew the pixel at `pixel` (of the image NODE_STEP times smaller).
uint node_at(vec2 pixel) {
    return texelFetch(node_map, ivec2(pixel) * NODE_STEP, 0).r;
}
