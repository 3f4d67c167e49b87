"""The engine core: the world (esper, change sets, resources), the game interface, the
frame's input and output, errors, and the math of reflections, portal pairs, world
matrices (``transforms``) and cube-map faces (``cube_faces``).  It imports components and
nothing else of the project."""
