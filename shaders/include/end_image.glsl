// The seen id an end view writes where last frame's image holds nothing for a pixel (its
// ray's point on the surface was off that image, or behind its camera): the composite
// leaves such a pixel to its surface's fallback (the probe's or the sky's reflection), as
// where the surface was not seen last frame, rather than stretching the image's edge across
// it (end_image.frag, mirror_composite.frag).  No entity has this id.
const uint NO_END_IMAGE = 0xFFFFFFFFu;
