"""The Blender add-on (see the add-on issue).  Nothing is registered yet."""


def register() -> None:
    raise RuntimeError("the relblend add-on is not built yet; see the add-on issue")


def unregister() -> None:
    pass
