"""Mirror beam: a puzzle of turning mirrors so a beam of light reaches a target."""
from games.mirror_beam.game import BeamEvent, BeamState, LevelRulesError, MirrorBeam, levels

__all__ = ["BeamEvent", "BeamState", "LevelRulesError", "MirrorBeam", "levels"]
