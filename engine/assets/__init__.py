"""Assets: meshes, textures, model files, level files and the few spawn helpers built on
them, on the CPU (no GL).  They import the engine core and components."""
