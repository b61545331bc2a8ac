"""``output.view_transform``: checking an OpenColorIO display view before rendering.

The PNG of a frame can go through an OCIO display view (``imageio.display_codes``) as
Blender's colour management does (its config, display "sRGB", view "AgX" ...). This
module only checks, when the job is loaded, that the config loads and has the display,
the view of that display and the look, so a typo fails before the render with one line
naming the key (OpenImageIO's ``ColorConfig``)."""

from __future__ import annotations

from pathlib import Path

import OpenImageIO as oiio  # noqa: N813


def ocio_problem(config: Path, display: str, view: str, look: str) -> tuple[str, str] | None:
    """None when ``config`` loads and names ``display``, its ``view`` and ``look``; else
    (the key at fault, why)."""
    cc = oiio.ColorConfig(str(config))
    error = cc.geterror() if hasattr(cc, "geterror") else ""
    if error or cc.getNumColorSpaces() == 0:
        return "config", f"is not an OpenColorIO config OpenImageIO can load: {error}".strip()
    displays = list(cc.getDisplayNames())
    if display not in displays:
        return "display", f"'{display}' is not a display of the config ({', '.join(displays)})"
    views = list(cc.getViewNames(display))
    if view not in views:
        return "view", f"'{view}' is not a view of display '{display}' ({', '.join(views)})"
    looks = list(cc.getLookNames()) if hasattr(cc, "getLookNames") else []
    if look and look not in looks:
        return "look", f"'{look}' is not a look of the config ({', '.join(looks) or 'none'})"
    return None
