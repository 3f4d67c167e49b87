"""The engine core: the world (esper, change sets, resources), the game interface, the
frame's input and output, errors, the view budget and the order its spenders rank by
(``budget``), and the math of reflections, portal pairs, world matrices (``transforms``),
cube-map faces (``cube_faces``), material slots and sRGB (``color``).  It imports
components and nothing else of the project."""
