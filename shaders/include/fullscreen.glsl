// One triangle that covers the viewport; no vertex buffer needed (gl_VertexID only).
vec2 fullscreen_position() {
    return vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2)) * 2.0 - 1.0;
}
