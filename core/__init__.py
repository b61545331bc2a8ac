"""The standalone render core: numpy, embreex and numba, never bpy."""
