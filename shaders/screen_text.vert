#version 410 core
// Screen text and panels (engine/render/text.py): one unit quad drawn once a glyph or panel,
// placed in output pixels from the top-left (screen_rect) and reading its atlas cell
// (atlas_rect, texels; a panel's is one texel of the filled cell, size 0; a picture panel's
// its picture's index, 0, -1, 0).
in vec2 corner;        // (0, 0) top-left .. (1, 1) bottom-right
in vec4 screen_rect;   // x, y, w, h: pixels, y down
in vec4 atlas_rect;    // x, y, w, h: texels, rows from the top
in vec4 color;         // sRGB-encoded rgb, alpha

uniform vec2 output_size;

out vec2 v_texel;
out vec2 v_corner;   // (0, 0) top-left .. (1, 1): where in the quad (a picture panel reads by it)
flat out vec4 v_color;

void main() {
    vec2 pixel = screen_rect.xy + corner * screen_rect.zw;
    v_texel = atlas_rect.xy + corner * atlas_rect.zw;
    v_corner = corner;
    v_color = color;
    gl_Position = vec4(pixel.x / output_size.x * 2.0 - 1.0, 1.0 - pixel.y / output_size.y * 2.0, 0.0, 1.0);
}
