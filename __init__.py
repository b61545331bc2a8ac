"""relray: a special-relativistic spectral path tracer.

The repository root is both the Python distribution ``relray`` and the Blender
extension.  Blender calls :func:`register`/:func:`unregister`; everything that
needs ``bpy`` is imported lazily from :mod:`relblend`, so ``import relray.core``
works in a plain Python without Blender.
"""

__version__ = "0.1.0"


def register() -> None:
    from . import relblend

    relblend.register()


def unregister() -> None:
    from . import relblend

    relblend.unregister()
