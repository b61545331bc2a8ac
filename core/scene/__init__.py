"""Scenes: what is rendered, as described by the user, and its geometry.

Owns the scene description (:mod:`.description`, the in-memory contract the TOML job,
the glTF importer and the Blender exporter produce), the TOML job file's schema, declared
once (:mod:`.schema`: validation, the reference page, the JSON Schema) and its
validation (:mod:`.job`), glTF 2.0 import (:mod:`.gltf`), built-in shapes
(:mod:`.shapes`), the flat triangle soup the renderer consumes (:mod:`.geometry`), the
camera's path through an animation (:mod:`.motion`), the job's peak memory
(:mod:`.footprint`) and the frame-name template formatted safely (:mod:`.names`).

May import: :mod:`relray.core.physics`, :mod:`relray.core.errors`,
:mod:`relray.core.files`, :mod:`relray.core.resources`, :mod:`relray.core.jit`.
"""
