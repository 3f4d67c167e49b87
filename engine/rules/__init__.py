"""Rules several systems must agree on, each defined once as pure functions over a world
(no GL): open portal pairs and the active camera, which probe an object samples and what a
probe face sees, the mirror-mesh invariant, ray casts."""
