"""Frame names: ``output.name`` formatted for one frame, without trusting the template.

``output.name`` is a :meth:`str.format` template whose only field is ``{frame}`` (the
frame number, an int), with an optional conversion (``!s``, ``!r``, ``!a``) and format
spec (``{frame:04d}``, ``{frame:x}``, ``{frame:_>6}``; a spec may nest ``{frame}`` once,
as Python allows). :func:`format_frame_name` formats it, refusing what
:meth:`str.format` would either reject or do at any cost:

- any other field (``{}``, ``{0}``, ``{name}``, ``{frame.real}``, ``{frame[0]}``);
- a width or precision above :data:`NAME_MAX_BYTES` (``{frame:>999999999}`` would build
  a gigabyte-long string before any name check could refuse it);
- a character code out of range for ``{frame:c}``.

Whether the result is a usable file name (one path component, no control character,
no Windows device name, distinct per frame ...) is checked for every frame by
:func:`relray.core.output.frame_files.check_frame_names`; this module only makes sure
formatting is cheap and fails as :class:`ValueError`.
"""

from __future__ import annotations

import re
import string

NAME_MAX_BYTES = 255
"""Longest file name (one path component, UTF-8 bytes) on Linux, macOS and Windows."""

_CONVERSIONS = {None: lambda v: v, "s": str, "r": repr, "a": ascii}
_NUMBER = re.compile(r"\d+")
_FORMATTER = string.Formatter()


def format_frame_name(template: str, frame: int, _depth: int = 0) -> str:
    """``template.format(frame=frame)``, or a :class:`ValueError` saying why not.

    Never builds a string longer than the template plus :data:`NAME_MAX_BYTES`
    characters per field, whatever the template.
    """
    if _depth > 1:
        raise ValueError("format specs nest {frame} at most once")
    out: list[str] = []
    for literal, field, spec, conversion in _FORMATTER.parse(template):
        out.append(literal)
        if field is None:
            continue
        if field != "frame":
            raise ValueError(f"unknown field {{{field}}}: the name may only use {{frame}}")
        if conversion not in _CONVERSIONS:
            raise ValueError(f"unknown conversion !{conversion}")
        if spec and "{" in spec:
            spec = format_frame_name(spec, frame, _depth + 1)
        for number in _NUMBER.findall(spec or ""):
            digits = number.lstrip("0")
            if len(digits) > 3 or int(digits or "0") > NAME_MAX_BYTES:
                raise ValueError(f"{number} in the format spec '{spec[:40]}' is more than "
                                 f"{NAME_MAX_BYTES} (the longest file name)")
        try:
            out.append(format(_CONVERSIONS[conversion](frame), spec or ""))
        except OverflowError as e:  # {frame:c} beyond U+10FFFF
            raise ValueError(str(e)) from None
    return "".join(out)
