"""Games and sample levels built on Speculum; each runs with ``python -m games.<name>``."""
