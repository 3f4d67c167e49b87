"""The engine's limits on component values, one constant each: the components refuse a value
past them when it is given, and the systems that honour them read the same constant."""
from __future__ import annotations

# Views deep a mirror, portal or probe face sees into mirrors and portals (Mirror.max_depth,
# Portal.max_depth, ReflectionProbe.depth, the view tree's depth cap).  Each level is one more
# set of views drawn into one more level of targets; Valve's Portal stops at 10 views.
MAX_VIEW_DEPTH = 16
