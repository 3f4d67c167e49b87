"""The engine's limits on component values, one constant each: the components refuse a value
past them when it is given, and the systems that honour them read the same constant."""
from __future__ import annotations

# Views deep a mirror, portal or probe face sees into mirrors and portals (Mirror.max_depth,
# Portal.max_depth, ReflectionProbe.depth, the view tree's depth cap).  Each level is one more
# set of views drawn into one more level of targets; Valve's Portal stops at 10 views.
MAX_VIEW_DEPTH = 16
# Mirrors and portals in a row a light's light goes through (DirectionalLight.bounces,
# PointLight.bounces): each bounce is one more virtual light (a shadow map and a light's
# shading), and the shader tests one aperture a bounce (shaders/include/virtual_lights.glsl).
MAX_LIGHT_BOUNCES = 4

# Reflection layers (show/hide lists): an entity belongs to some of REFLECTION_LAYERS layers
# and a mirror, portal, probe or camera shows some of them; a view shows an entity when they
# share one.  16 layers keep the entity's bits exact in the float slot the scene pass reads.
REFLECTION_LAYERS = 16
ALL_LAYERS = (1 << REFLECTION_LAYERS) - 1
# The kinds of view an entity can be hidden in.  A view's kinds are those of the surfaces its
# chain of views passed through (the main camera's own view is DIRECT, a probe face's tree is
# PROBE throughout), so a vampire hidden in mirrors is hidden in a portal seen in a mirror too.
VIEW_DIRECT, VIEW_MIRROR, VIEW_PORTAL, VIEW_PROBE = 1, 2, 4, 8
VIEW_KINDS = 4         # bits 0-3 of a view mask; the layers it shows are bits 4-19
