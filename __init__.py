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

    Installs its signal handlers before anything heavy is imported. SIGINT, SIGTERM or
    SIGHUP during start-up (numpy, numba, OpenImageIO and Embree take a second or more to
    load) is held until the imports are done, because an exception raised inside an
    extension module's initialisation turns into an ImportError traceback, or leaves
    CPython's "unhandled KeyboardInterrupt" mark that makes it kill itself by SIGINT at
    exit; the command then ends with "relray: interrupted" and exit code 130. During the
    run the signal interrupts (130 again). A KeyboardInterrupt that a callback swallows
    (numba's JIT calls back into Python through ctypes, which can only print "Exception
    ignored") is kept silent, and the signal is still remembered: a run that then
    finishes ends "interrupted", 130. Once the command has finished the signals are
    ignored (SIG_IGN, which the interpreter's finalisation keeps), so the process never
    dies by one. Everything else is :func:`relray.core.cli.main`.

    The garbage collector stays off while the modules are imported. Their objects, and
    again all objects once the command has finished, are then frozen (``gc.freeze``):
    they live until the process ends, so no later collection walks them. numba's
    modules, type registries and lowering tables come to about 180 000 objects. Walking
    them took about a quarter of a warm ``relray render``'s first image (issue 12, the
    time to the first image): collections during the imports and the first kernel
    load, and above all the one the interpreter runs as it exits, after the files are
    written, which frees nothing the ending process needs. Files and atexit handlers
    are closed as before: frozen objects are only left out of the collector's search
    for cycles.
    """
    import gc

    gc.disable()  # the start-up's objects (the imports') live as long as the process
    import signal
    import sys

    phase = "start-up"
    held: list[int] = []

    def on_signal(signum, frame):
        if phase != "finished":
            held.append(signum)
        if phase == "run":
            raise KeyboardInterrupt

    unraisable = sys.unraisablehook

    def quiet_interrupts(info):
        if not issubclass(info.exc_type, KeyboardInterrupt):
            unraisable(info)

    sys.unraisablehook = quiet_interrupts

    stop_signals = [getattr(signal, n) for n in _STOP_SIGNALS if hasattr(signal, n)]
    for sig in stop_signals:
        signal.signal(sig, on_signal)
    try:
        try:
            from .core import cli
        finally:
            gc.freeze()
            gc.enable()
        phase = "run"
        if held:
            raise KeyboardInterrupt
        code = cli.main()
        if held and code != 130:  # the interrupt was swallowed by a callback
            raise KeyboardInterrupt
    except KeyboardInterrupt:
        code = 130
        try:
            print("relray: interrupted", file=sys.stderr)
        except KeyboardInterrupt:
            pass
    phase = "finished"
    for sig in stop_signals:
        signal.signal(sig, signal.SIG_IGN)
    gc.freeze()  # nothing for the exit's collection to walk (the docstring)
    return code


def register() -> None:
    from . import relblend

    relblend.register()


def unregister() -> None:
    from . import relblend

    relblend.unregister()
