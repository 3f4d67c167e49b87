// What a shader writes into the HDR colour images (engine/render/targets.py HDR_FORMAT: half
// floats), kept within their range here, at the source.  Each input that lands there is at
// most 65504 (components.tracking HALF_MAX), but their sums and products are not (a lamp of
// that power that a light falls on too, a mirror tinted past 1).  How a half-float image
// stores a value past 65504 is left to the implementation (llvmpipe saturates; a correctly
// rounded conversion gives +inf), and an inf pixel breaks each blend over it (inf x 0 is NaN:
// a composite at weight 1, the still tree's refill), the exposure and the bloom.
const float HDR_MAX = 65504.0;  // the largest finite half float

vec3 hdr_store(vec3 c) {
    return min(c, vec3(HDR_MAX));
}
