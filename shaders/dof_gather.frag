#version 410 core
// Depth of field, step 4 (engine/render/depth_of_field.py): each pixel gathers the discs that
// cover it (scatter as gather), taps on a golden-angle spiral out to its reach (its own
// radius, or the largest of a nearer thing in the 3x3 tiles about it), about one a square
// pixel of that disc (8 to SAMPLES), each tap standing for an equal share of its area.  Two layers, as a camera sees them:
//   - behind: taps as far as the pixel or farther, each spread no wider than the pixel's own
//     disc (a blurred background does not spread over a sharp thing in front of it), averaged
//     with the pixel where their disc covers it;
//   - in front: taps nearer than the pixel whose disc covers it, each bringing the share of
//     its light its disc's area gives one pixel (its cell's area over the disc's), so a
//     blurred foreground's edge covers half of an in-focus pixel beside it, and all of one
//     well inside its disc; that share, at most 1, is laid over the layer behind.
// The signed radius orders taps by distance (lens_rules: it grows with the distance).
// POLYGON_BOKEH builds (DepthOfField.blades): a disc is the aperture's polygon, its corners on
// the disc's edge: whether it covers a tap is measured in the polygon's own distance.

uniform sampler2D prepared;      // dof_prepare.frag: rgb colour, a signed radius
uniform sampler2D near_tiles;    // dof_tiles.frag
uniform int tile;

#ifdef SPLIT_LAYERS
// At half size (DepthOfField.half_resolution) the two layers go out apart, for dof_compose.frag
// to put each full-size pixel's own sharp colour behind where its disc is narrow.
layout(location = 0) out vec4 out_back;    // rgb: the layer behind
layout(location = 1) out vec4 out_front;   // rgb: the layer in front x its share, a: the share
#else
out vec4 out_color;
#endif

#ifdef POLYGON_BOKEH
uniform vec3 bokeh;   // x: the blades, y: their turn (radians), z: the polygon's area over its circle's

// How far ``offset`` is in the polygon's measure: the radius of the polygon whose edge it lies on
// (its length where it points at a corner, more towards an edge's middle).
float bokeh_distance(vec2 offset) {
    if (offset == vec2(0.0)) return 0.0;   // (atan's angle is undefined there)
    float wedge = 6.28318531 / bokeh.x;
    float turned = mod(atan(offset.y, offset.x) - bokeh.y, wedge) - 0.5 * wedge;
    return length(offset) * cos(turned) / cos(0.5 * wedge);
}
#define BOKEH_AREA bokeh.z
#else
#define bokeh_distance(offset) length(offset)
#define BOKEH_AREA 1.0
#endif

const int SAMPLES = 48;
const float GOLDEN_ANGLE = 2.39996323;
const float NEARER = 0.5;        // pixels of radius: a tap this much nearer is in front

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    ivec2 last = textureSize(prepared, 0) - 1;
    vec4 centre = texelFetch(prepared, px, 0);
    float own = abs(centre.a);
    float reach = own;
    ivec2 at_tile = px / tile;
    ivec2 last_tile = textureSize(near_tiles, 0) - 1;
    for (int y = -1; y <= 1; ++y) {
        for (int x = -1; x <= 1; ++x) {
            reach = max(reach, texelFetch(near_tiles, clamp(at_tile + ivec2(x, y), ivec2(0), last_tile), 0).r);
        }
    }
    if (reach < 0.5) {  // nothing's disc reaches past its own pixel here
#ifdef SPLIT_LAYERS
        out_back = vec4(centre.rgb, 1.0);
        out_front = vec4(0.0);
#else
        out_color = vec4(centre.rgb, 1.0);
#endif
        return;
    }
    vec3 behind = centre.rgb;
    float behind_weight = 1.0;
    vec3 front = vec3(0.0);
    float front_share = 0.0;
    // As many taps as the disc needs, about one a square pixel of it (3 r^2 of its pi r^2), SAMPLES at most.
    int taps = int(clamp(ceil(reach * reach * 3.0), 8.0, float(SAMPLES)));
    float cell = reach * reach / float(taps);  // a tap's share of the disc, over pi
    for (int i = 0; i < SAMPLES; ++i) {
        if (i >= taps) break;
        float angle = float(i) * GOLDEN_ANGLE;
        ivec2 offset = ivec2(round(vec2(cos(angle), sin(angle)) * (reach * sqrt((float(i) + 0.5) / float(taps)))));
        float r = bokeh_distance(vec2(offset));  // (the pixel fetched: whether a disc covers this one is its distance)
        vec4 tap = texelFetch(prepared, clamp(px + offset, ivec2(0), last), 0);
        float size = abs(tap.a);
        if (tap.a < centre.a - NEARER) {
            float share = clamp(size - r + 0.5, 0.0, 1.0) * cell / max(size * size * BOKEH_AREA, 0.25);
            front += tap.rgb * share;
            front_share += share;
        } else {
            float covers = clamp(min(size, own) - r + 0.5, 0.0, 1.0);
            behind += tap.rgb * covers;
            behind_weight += covers;
        }
    }
    vec3 back = behind / behind_weight;
    vec3 near = front_share > 0.0 ? front / front_share : back;
    float share = min(front_share, 1.0);
#ifdef SPLIT_LAYERS
    out_back = vec4(back, 1.0);
    out_front = vec4(near * share, share);
#else
    out_color = vec4(mix(back, near, share), 1.0);
#endif
}
