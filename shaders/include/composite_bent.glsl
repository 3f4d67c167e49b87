// Whether a build of the composite reads its view's image along a bent normal (the vertex
// stage passes the parent's projection of directions for it): a mirror with a normal map
// (COMPOSITE_BUMPY), and water while its ripples are alive (RIPPLES), even with no map.
#if defined(COMPOSITE_BUMPY) || (defined(COMPOSITE_WATER) && defined(RIPPLES))
#define COMPOSITE_BENT 1
#endif
