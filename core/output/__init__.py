"""Output: image files, and the files that make a frame.

Owns EXR, PNG and spectral EXR writing and reading through OpenImageIO, atomically
(:mod:`.imageio`); a frame's file names, metadata, resume decision and writing
(:mod:`.frame_files`); contact sheets (:mod:`.contact`).

May import: :mod:`relray.core.render` (the film it writes), :mod:`relray.core.scene`,
:mod:`relray.core.physics`, :mod:`relray.core.errors`.
"""
