"""Rules several systems must agree on, each defined once as pure functions over a world
(no GL): open portal pairs and the active camera, which probe an object samples and what a
probe face sees, the probes' schedule, the mirror-mesh and water invariants, shadow fitting
and virtual lights, where an entity is drawn (``visibility_rules``), ray casts."""
