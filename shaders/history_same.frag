#version 410 core
// Whether the finished main image still changes from frame to frame while nothing it shows
// does (engine/render/end_images.py, EndImages.keep): a pixel bit for bit the one kept last
// frame is discarded, so the samples query around this pass counts the pixels that differ.
// End views repeat last frame's image, so a still view converges over frames; once it
// counts none, the next frame's tree would be drawn the same and the reflect stage keeps it.

uniform sampler2D image;    // this frame's finished main image
uniform sampler2D history;  // the image kept last frame, the same size

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    if (all(equal(floatBitsToUint(texelFetch(image, p, 0)), floatBitsToUint(texelFetch(history, p, 0))))) discard;
}
