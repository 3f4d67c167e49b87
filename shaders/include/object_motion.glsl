// Each moving instance's own motion since the last frame (engine/render/object_motion.py): a
// float texture holding, at texel 0, how many moved (x), then a record of four texels each,
// sorted by entity: the first three rows of the matrix taking where it is now to where it was
// (its last model matrix x the inverse of this one; the fourth row is 0, 0, 0, 1) and the
// entity (z and w of the fourth texel: its bits from 12 up and its low 12, each exact in a
// float, so every 32-bit id is told apart).  Records run on across rows of
// OBJECT_MOTION_WIDTH texels.  Found by a binary search (a frame's movers are few; an entity
// not among them did not move).  Only in OBJECT_MOTION builds.
#ifdef OBJECT_MOTION
uniform sampler2D object_motion;

vec4 motion_texel(int record, int texel) {
    int at = record * 4 + texel + 4;  // (record 0 starts after the count's texel's four)
    return texelFetch(object_motion, ivec2(at % OBJECT_MOTION_WIDTH, at / OBJECT_MOTION_WIDTH), 0);
}

// Where the point ``world`` of ``entity``'s instance was last frame (``world``: where this
// frame's matrix puts the vertex as last frame's pose had it).
vec3 world_before(uint entity, vec4 world) {
    int low = 0;
    int high = int(texelFetch(object_motion, ivec2(0, 0), 0).x) - 1;
    vec2 wanted = vec2(float(entity >> 12u), float(entity & 4095u));
    while (low <= high) {
        int middle = (low + high) / 2;
        vec2 found = motion_texel(middle, 3).zw;
        if (found == wanted) {
            return vec3(dot(motion_texel(middle, 0), world), dot(motion_texel(middle, 1), world),
                        dot(motion_texel(middle, 2), world));
        }
        if (found.x < wanted.x || (found.x == wanted.x && found.y < wanted.y)) {
            low = middle + 1;
        } else {
            high = middle - 1;
        }
    }
    return world.xyz;
}
#endif
