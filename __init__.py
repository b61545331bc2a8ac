"""relray: a special-relativistic spectral path tracer.

The repository root is both the Python distribution ``relray`` and the Blender
extension.  Blender calls :func:`register`/:func:`unregister`; everything that
needs ``bpy`` is imported lazily from :mod:`relblend`, so ``import relray.core``
works in a plain Python without Blender.
"""

__version__ = "0.1.0"

_STOP_SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP", "SIGBREAK")


def cli_main() -> int:
    """The ``relray`` command (console script and ``python -m relray``).

    Installs its signal handlers before anything heavy is imported: SIGINT, SIGTERM or
    SIGHUP during start-up (numpy, numba and Embree take a second or more to load) or
    during the run ends the command with "relray: interrupted" and exit code 130, and
    one arriving after the command has finished is ignored, so the process never dies
    by the signal. Everything else is :func:`relray.core.cli.main`.
    """
    import signal
    import sys

    finished = False

    def on_signal(signum, frame):
        if not finished:
            raise KeyboardInterrupt

    for name in _STOP_SIGNALS:
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), on_signal)
    try:
        from .core import cli

        code = cli.main()
    except KeyboardInterrupt:
        code = 130
        try:
            print("relray: interrupted", file=sys.stderr)
        except KeyboardInterrupt:
            pass
    finished = True
    return code


def register() -> None:
    from . import relblend

    relblend.register()


def unregister() -> None:
    from . import relblend

    relblend.unregister()
