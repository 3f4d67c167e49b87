#version 410 core
// The editor's selection outline: an edge pass over the main view's seen-id image (the
// entity finally seen at each pixel, following reflections), so the selected entity is
// outlined wherever it shows, directly, in every mirror and through every portal, with
// no extra view drawn. A pixel is on the outline when it does not show the selection but
// one within RADIUS pixels (a square) does: a band just outside each of its shapes.

#ifndef RADIUS
#define RADIUS 1
#endif

uniform usampler2D seen_ids;   // the main view's seen-id image (RenderTargets.seen)
uniform uint selected;         // the selected entity
uniform vec4 outline_color;

in vec2 v_uv;
out vec4 out_color;

void main() {
    ivec2 size = textureSize(seen_ids, 0);
    ivec2 at = clamp(ivec2(v_uv * vec2(size)), ivec2(0), size - 1);
    if (texelFetch(seen_ids, at, 0).r == selected) {
        discard;
    }
    bool near = false;
    for (int dy = -RADIUS; dy <= RADIUS; ++dy) {
        for (int dx = -RADIUS; dx <= RADIUS; ++dx) {
            ivec2 p = at + ivec2(dx, dy);
            if (all(greaterThanEqual(p, ivec2(0))) && all(lessThan(p, size))) {
                near = near || texelFetch(seen_ids, p, 0).r == selected;
            }
        }
    }
    if (!near) {
        discard;
    }
    out_color = outline_color;
}
