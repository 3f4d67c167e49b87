"""Portal run: a first-person game of two portals and an exit out of reach on foot."""
from games.portal_run.game import LevelRulesError, PortalRun, RunEvent, levels

__all__ = ["LevelRulesError", "PortalRun", "RunEvent", "levels"]
