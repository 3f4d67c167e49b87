// Where an anisotropically filtered map is read with the derivatives the shader takes itself:
// through ``bounded_footprint``, which on a software rasteriser (BOUNDED_FOOTPRINT: the
// ShaderLibrary's driver defines, engine/render/gpu.py) holds the coordinates' spread across
// a 2 x 2 quad to at most one whole texture a pixel, and elsewhere passes them as they are.
//
// Why: llvmpipe (Mesa 22.3) filters anisotropically by an elliptical weighted average
// (Heckbert's EWA) that visits every texel of the ellipse's bounding box at the level it
// picks, with no cap on the box.  Where a pixel's footprint passes the whole texture (a
// surface seen nearly edge-on, a sprite under a pixel) the level stops at the last and the box
// grows with the derivatives: one textured, unevenly scaled sphere at 64 x 48 drew for 145 s
// (the draw's silhouette triangles, thousands of texture widths a pixel).  A GPU's filter
// takes at most its anisotropy's taps.  Past one texture a pixel every level but the last is
// finer than the footprint, and the last is the texture's mean wherever it is read; so the
// coordinates are scaled by the quad's own constant (the derivatives are the quad's, the same
// at its four pixels), which scales their derivatives to one texture a pixel and moves the
// read within a texture whose mean it already is.
#ifdef BOUNDED_FOOTPRINT
vec2 bounded_footprint(vec2 uv) {
    vec2 dx = dFdx(uv), dy = dFdy(uv);
    float widest = max(max(abs(dx.x), abs(dx.y)), max(abs(dy.x), abs(dy.y)));
    return widest > 1.0 ? uv / widest : uv;
}
#else
#define bounded_footprint(uv) (uv)
#endif
