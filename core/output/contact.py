"""Contact sheets: a grid of an animation's PNG frames in one image (``make demo``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from ..errors import UserError
from .imageio import atomic_write, write_pixels


def read_png(path: Path) -> np.ndarray:
    """8-bit RGB(A) pixels of a PNG as uint8 (h, w, c), row 0 at the top."""
    buf = oiio.ImageBuf(str(path))
    if buf.has_error:
        raise UserError(f"cannot read image: {buf.geterror()}", file=path)
    return buf.get_pixels(oiio.UINT8)


def caption(image: np.ndarray, text: str) -> np.ndarray:
    """``image`` (uint8 h, w, 3) with ``text`` written in its top-left corner."""
    h, w, c = image.shape
    buf = oiio.ImageBuf(oiio.ImageSpec(w, h, c, oiio.UINT8))
    buf.set_pixels(oiio.ROI(0, w, 0, h, 0, 1, 0, c), np.ascontiguousarray(image))
    size = max(10, h // 16)
    oiio.ImageBufAlgo.render_text(buf, 4 + 1, size + 4 + 1, text, size, "", (0, 0, 0))
    oiio.ImageBufAlgo.render_text(buf, 4, size + 4, text, size, "", (1, 1, 1))
    return buf.get_pixels(oiio.UINT8)


def tile(images: list[np.ndarray], columns: int, gap: int = 2) -> np.ndarray:
    """Images of one size laid out row-major on a black canvas with ``gap`` pixels between."""
    h, w, c = images[0].shape
    rows = -(-len(images) // columns)
    cols = min(columns, len(images))
    sheet = np.zeros((rows * (h + gap) - gap, cols * (w + gap) - gap, c), np.uint8)
    for k, img in enumerate(images):
        r, q = divmod(k, columns)
        y, x = r * (h + gap), q * (w + gap)
        sheet[y:y + h, x:x + w] = img[:h, :w, :c]
    return sheet


def write_contact_sheet(frames: list[Path], out: Path, columns: int = 8,
                        captions: list[str] | None = None) -> Path:
    """Tile ``frames`` (PNG) into ``out`` (PNG), written atomically, optionally captioned."""
    images = [read_png(p)[..., :3] for p in frames]
    if captions is not None:
        images = [caption(im, text) for im, text in zip(images, captions, strict=True)]
    shapes = {im.shape for im in images}
    if len(shapes) != 1:
        raise UserError(f"frames differ in size: {sorted(shapes)}", file=frames[0].parent)
    sheet = tile(images, columns)
    out.parent.mkdir(parents=True, exist_ok=True)
    spec = oiio.ImageSpec(sheet.shape[1], sheet.shape[0], sheet.shape[2], oiio.UINT8)
    atomic_write(out, lambda tmp: write_pixels(tmp, out, sheet, spec))
    return out
