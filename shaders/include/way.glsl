// What a pixel finally shows, as a level's seen image holds it (engine/render/targets.py,
// two uints): the entity (r) and the length of the light's way from the eye to it (g, the
// float's bits).  A mirror or portal view's camera is the eye carried through every surface
// before it (reflected, or moved to beyond the partner), so the distance from a view's eye
// to what it shows is the whole way's length: eye to the first surface, on through each.  It
// is the image's distance, which depth of field focuses by (engine/rules/lens_rules.py).
// The scene pass writes it for what it draws opaque (glass leaves it: what shows through
// keeps its way), the sky SKY_WAY (lens_rules), a composite its view's pair whole, and a
// surface with no view of its own (a fallback, an end image) the way to the surface itself.
uvec2 seen_at(uint entity, float way) {
    return uvec2(entity, floatBitsToUint(way));
}

// A view's seen pair as its composite carries it up: where the view drew nothing (its
// claim's (0, 0): a reflection level leaves the sky to its composite) the sky it puts there.
uvec2 carried_seen(uvec2 seen) {
    return seen.r == 0u ? seen_at(0u, SKY_WAY) : seen;
}
