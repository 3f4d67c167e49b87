#version 410 core
// Depth of field at half size, the last step (engine/render/depth_of_field.py): each full-size
// pixel's layer behind is its own sharp colour where its disc is under a pixel or so, the
// half-size gather's (bilinear) where it is wider, blended between; the half-size layer in
// front (premultiplied by the share of the pixel it covers) is laid over it.

uniform sampler2D prepared;      // full size: rgb colour, a signed radius
uniform sampler2D back_layer;    // half size (dof_gather.frag SPLIT_LAYERS): rgb behind
uniform sampler2D front_layer;   // half size: rgb x share in front, a the share

out vec4 out_color;

void main() {
    vec4 own = texelFetch(prepared, ivec2(gl_FragCoord.xy), 0);
    vec2 uv = gl_FragCoord.xy / vec2(textureSize(prepared, 0));
    vec3 back = mix(own.rgb, textureLod(back_layer, uv, 0.0).rgb, smoothstep(1.0, 2.0, abs(own.a)));
    vec4 front = textureLod(front_layer, uv, 0.0);
    out_color = vec4(back * (1.0 - front.a) + front.rgb, 1.0);
}
