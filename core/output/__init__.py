"""Output: image files, and the files that make a frame.

Owns EXR, PNG and spectral EXR writing and reading through OpenImageIO, atomically
(:mod:`.imageio`); a frame's file names (checked for every frame), metadata, resume
decision and writing (:mod:`.frame_files`); the digest of what a frame's pixels depend
on, which resume compares (:mod:`.digest`); contact sheets (:mod:`.contact`).

May import: :mod:`relray.core.render` (the film it writes), :mod:`relray.core.scene`,
:mod:`relray.core.physics`, :mod:`relray.core.errors`, :mod:`relray.core.files`.
"""
