"""The sample level; it grows as mirrors and portals land."""
from games.hall_of_mirrors.level import HallOfMirrors

__all__ = ["HallOfMirrors"]
