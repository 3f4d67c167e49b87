#version 410 core
// The debug overlay's "AO only" view: the camera's ambient occlusion as grey, the share of
// the light from all round each pixel keeps (255: all of it), drawn in place of the picture
// (engine/render/present.py PresentPass.draw_occlusion).  The image may be half the output's
// size: read bilinearly.
uniform sampler2D occlusion_image;   // screen_occlusion's shares: r the light from all round's

in vec2 v_uv;
out vec4 out_color;

void main() {
    float share = textureLod(occlusion_image, v_uv, 0.0).r;
    out_color = vec4(vec3(share), 1.0);
}
