// Show and hide in reflections (components/visibility.py): the visibility rule of
// engine/rules/visibility_rules.py, its one owner (tests/test_one_owner.py runs these
// functions against its drawn_in and hidden_everywhere).  An instance's code (tint.w,
// entity_code) holds the kinds of view it is hidden in (the low VIEW_KIND_BITS bits) and the
// reflection layers it belongs to (the bits above), an integer exact in a float; a view's
// mask (View.view_mask) holds the kinds of view it is (direct, mirror, portal, probe,
// accumulated along its chain of surfaces) and the layers it shows, packed the same way.
// The view leaves the instance out when it is of a kind the instance is hidden in, or when
// they share no layer.  VIEW_KIND_BITS is defined by the shader library (engine_defines,
// from components/limits.py VIEW_KINDS).

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

// Left out of every light's shadow map: drawn nowhere, or drawn with MeshRef.casts_shadows
// off (NO_SHADOW_BIT, above the layers: no view's mask has it, so no view's test reads it).
bool casts_no_shadow(float instance_code) {
    return hidden_everywhere(instance_code) || (uint(instance_code + 0.5) & NO_SHADOW_BIT) != 0u;
}

// A portal's opening that carries light (Portal.carries_light: OPENING_CASTS_BIT, above
// NO_RECEIVE_BIT) casts a shadow: the light it takes in leaves by its partner.
bool opening_casts(float instance_code) {
    return (uint(instance_code + 0.5) & OPENING_CASTS_BIT) != 0u;
}

// Lit as though nothing stood in the lights' way: MeshRef.receives_shadows off (NO_RECEIVE_BIT,
// above NO_SHADOW_BIT): the scene shader looks up no shadow map for it.
bool receives_no_shadow(float instance_code) {
    return (uint(instance_code + 0.5) & NO_RECEIVE_BIT) != 0u;
}
