// Show and hide in reflections (components/visibility.py).  An instance's code (tint.w,
// engine/render/instances.py visibility_code) holds the kinds of view it is hidden in (bits
// 0-3) and the reflection layers it belongs to (bits 4-19), an integer exact in a float; a
// view's mask (View.view_mask) holds the kinds of view it is (bits 0-3: direct, mirror,
// portal, probe, accumulated along its chain of surfaces) and the layers it shows (bits 4-19).
// The view leaves the instance out when it is of a kind the instance is hidden in, or when
// they share no layer.
#define VIEW_KIND_BITS 4u  // components/limits.py VIEW_KINDS

bool hidden_in_view(float instance_code, uint view_mask) {
    uint code = uint(instance_code + 0.5);
    uint kinds = (1u << VIEW_KIND_BITS) - 1u;
    return (code & view_mask & kinds) != 0u || ((code >> VIEW_KIND_BITS) & (view_mask >> VIEW_KIND_BITS)) == 0u;
}

// Hidden in every kind of view: drawn nowhere, so it casts no shadow either.
bool hidden_everywhere(float instance_code) {
    uint kinds = (1u << VIEW_KIND_BITS) - 1u;
    return (uint(instance_code + 0.5) & kinds) == kinds;
}
