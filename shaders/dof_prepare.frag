#version 410 core
// Depth of field, step 2 (engine/render/depth_of_field.py): each pixel's colour and the signed
// radius in pixels of the disc its lens images it as (engine/rules/lens_rules.py blur_radius,
// the thin lens: lens_scale x (1 - s / d) / (s - f), negative nearer than the focus s,
// positive beyond; at most max_radius), d the length of the light's way to what it shows.

uniform sampler2D hdr_image;
uniform usampler2D seen_image;
uniform sampler2D focus_state;   // 1x1: the focus distance (dof_focus.frag)
uniform vec3 lens;               // x: the focal length f (metres), y: lens_rules.lens_scale, z: max_radius

out vec4 out_prepared;           // rgb: the colour, a: the signed radius

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    // (The seen image is the drawn picture's size: smaller than this one after temporal
    // upsampling, engine/render/resample.py.)
    ivec2 seen_px = ivec2(gl_FragCoord.xy * vec2(textureSize(seen_image, 0)) / vec2(textureSize(hdr_image, 0)));
    float d = max(uintBitsToFloat(texelFetch(seen_image, seen_px, 0).g), 1e-6);
    float f = lens.x;
    float s = max(texelFetch(focus_state, ivec2(0), 0).r, f * NEAREST_FOCUS);
    float radius = clamp(lens.y * (1.0 - s / d) / (s - f), -lens.z, lens.z);
    out_prepared = vec4(texelFetch(hdr_image, px, 0).rgb, radius);
}
