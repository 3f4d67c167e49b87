// The Views block: a level's views drawn in one draw (engine/render/batched_mirrors.py
// views_block writes it, std140).  Read by the instanced-views build of scene.vert (view
// gl_InstanceID % view_count.x) and by the one-pass cube-map captures' geometry shaders
// (scene_batched.geom, sky_layered.geom: view gl_InvocationID).  Needs MAX_LEVEL_VIEWS.

struct MirrorView {
    mat4 view_proj;   // the view's camera: projection x view (a mirror's with its oblique near plane)
    vec4 clip_plane;  // world-space mirror or portal plane; geometry behind it is clipped
    vec4 eye;         // xyz: world-space eye; w: its way scale (view_axis.glsl), negative if
                      // mirrored (front faces clockwise)
    vec4 rect;        // the view's screen rectangle in NDC: x0, y0, x1, y1
    uvec4 node;       // x: the view's index in the node image; y: the entity it never draws (its surface);
                      // z: one no view of its tree draws (a probe's own object); 0: none;
                      // w: the view's kinds and the layers it shows (visibility.glsl)
};

layout(std140) uniform Views {
    ivec4 view_count;  // x: views in the draw
    MirrorView views[MAX_LEVEL_VIEWS];
};
