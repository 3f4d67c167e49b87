"""The engine core: the world (esper, change sets, resources), the game interface, the
frame's input and output, errors, and the math of reflections and portal pairs.  It
imports components and nothing else of the project."""
