// What a pixel finally shows, as a level's seen image holds it (engine/render/targets.py):
// the entity (r) and the length of the light's way from the eye to it (g, the float's
// bits); where the active camera's motion blur streaks moving things (MotionBlur.objects,
// engine/render/object_motion.py) the image has two more, b and a: how far what it shows
// moved on the picture since the last frame by its own motion (float bits, in the
// picture's widths and heights: now less then), which a two-channel image drops.  A mirror or portal view's camera is the eye carried through every surface
// before it (reflected, or moved to beyond the partner), so the distance from a view's eye
// to what it shows is the whole way's length: eye to the first surface, on through each, in
// the root view's metres (beyond portals of two sizes a view's metres are their ratio's:
// view_axis.glsl way_scale).  It is the image's distance, which depth of field focuses by
// (engine/rules/lens_rules.py), and where motion blur and TAA find the point a pixel shows.
// The scene pass writes it for what it draws opaque (glass leaves it: what shows through
// keeps its way), the sky SKY_WAY (lens_rules), a composite its view's pair whole, and a
// surface with no view of its own (a fallback, an end image) the way to the surface itself.
uvec4 seen_at(uint entity, float way) {
    return uvec4(entity, floatBitsToUint(way), 0u, 0u);
}

// Whether a seen way holds no point (nothing drawn, 0, or the sky, SKY_WAY): what is there is a
// direction from the eye, not a point along it.
bool way_beyond(float way) {
    return way <= 0.0 || way >= 0.5 * SKY_WAY;
}

// How far a point moved on the picture since the last frame (``now`` and ``before``: clip
// space, as one projection puts it now and where it was): in the picture's widths and
// heights, now less then.  Last frame's point behind the eye: no motion.
vec2 picture_motion(vec4 now, vec4 before) {
    return before.w > 1e-6 ? 0.5 * (now.xy / now.w - before.xy / before.w) : vec2(0.0);
}

// The same for a point that was at ``before`` last frame (clip space, as this view projects
// it; ``now`` where it projects it this frame): its own motion on the picture.  A view's
// projection puts a point where the picture shows it (a mirror's view is the eye carried
// through the glass), so a thing moving in a mirror moves as its reflection does.  Last
// frame's point behind the eye: no motion.
uvec4 seen_moved(uint entity, float way, vec4 now, vec4 before) {
    return uvec4(entity, floatBitsToUint(way), floatBitsToUint(picture_motion(now, before)));
}

// A view's seen pair as its composite carries it up: where the view drew nothing (its
// claim's (0, 0): a reflection level leaves the sky to its composite) the sky it puts there.
uvec4 carried_seen(uvec4 seen) {
    return seen.r == 0u ? seen_at(0u, SKY_WAY) : seen;
}
