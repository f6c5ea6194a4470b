"""The emulated camera: a test picture with the stream time burned in, JPEG-encoded.

Each frame is drawn by Pillow: eight colour bars, a white bar that moves across the picture
once every :data:`SWEEP_S` seconds and the time ``t = 12.345 s`` written large in the
corner, so a viewer sees at once whether the picture is live and which moment it shows.
``fail`` makes :meth:`EmulatedCamera.frame` return nothing (camera loss, for tests and fault
injection)."""

from __future__ import annotations

import io

from PIL import Image, ImageDraw, ImageFont

from ucat_console.backend.camera.config import CameraConfig

#: seconds the moving bar takes to cross the picture
SWEEP_S = 4.0
_BARS = ((192, 192, 192), (192, 192, 0), (0, 192, 192), (0, 192, 0),
         (192, 0, 192), (192, 0, 0), (0, 0, 192), (16, 16, 16))


def bar_x(t: float, width: int) -> int:
    """The moving bar's left edge (px) at stream time ``t``."""
    return int((t % SWEEP_S) / SWEEP_S * width)


class EmulatedCamera:
    """Frames of the test picture at the size and quality of ``cfg``."""

    def __init__(self, cfg: CameraConfig) -> None:
        self.cfg = cfg
        self.fail = False  # True: no frames (a lost camera)
        w, h = cfg.width, cfg.height
        self._background = Image.new("RGB", (w, h))
        draw = ImageDraw.Draw(self._background)
        for i, colour in enumerate(_BARS):
            draw.rectangle((i * w // len(_BARS), 0, (i + 1) * w // len(_BARS), h), fill=colour)
        self._font = ImageFont.load_default(size=max(10, h // 8))

    @property
    def where(self) -> str:
        return "emulated"

    def picture(self, t: float) -> Image.Image:
        """The test picture at stream time ``t``."""
        w, h = self.cfg.width, self.cfg.height
        img = self._background.copy()
        draw = ImageDraw.Draw(img)
        x = bar_x(t, w)
        draw.rectangle((x, 0, x + max(2, w // 40), h), fill=(255, 255, 255))
        text = f"t = {t:.3f} s"
        box = draw.textbbox((8, 8), text, font=self._font)
        draw.rectangle((box[0] - 4, box[1] - 4, box[2] + 4, box[3] + 4), fill=(0, 0, 0))
        draw.text((8, 8), text, fill=(255, 255, 255), font=self._font)
        return img

    def frame(self, t: float) -> bytes | None:
        """The JPEG bytes of the test picture at ``t`` (None while ``fail``)."""
        if self.fail:
            return None
        return encode_jpeg(self.picture(t), self.cfg.jpeg_quality)

    def close(self) -> None:
        pass


def encode_jpeg(img: Image.Image, quality: int) -> bytes:
    """``img`` as JPEG bytes."""
    out = io.BytesIO()
    img.save(out, format="JPEG", quality=quality)
    return out.getvalue()
