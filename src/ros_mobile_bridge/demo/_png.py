"""Tiny dependency-free PNG encoder and the demo robot's camera renderer.

Only the standard library (``zlib`` + ``struct``) is used, so the demo does not need Pillow.
"""

from __future__ import annotations

import math
import struct
import zlib

__all__ = ["CameraRenderer", "encode_png_rgb"]

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _chunk(kind: bytes, payload: bytes) -> bytes:
    crc = zlib.crc32(kind + payload) & 0xFFFFFFFF
    return struct.pack(">I", len(payload)) + kind + payload + struct.pack(">I", crc)


def encode_png_rgb(width: int, height: int, rgb: bytes | bytearray) -> bytes:
    """Encode an 8-bit RGB image as PNG.

    ``rgb`` holds ``height`` rows of ``width * 3`` bytes each, top row first, *without* PNG
    filter bytes. Raises :class:`ValueError` if the size does not match.
    """
    if width <= 0 or height <= 0:
        raise ValueError(f"image size must be positive, got {width}x{height}")
    stride = width * 3
    if len(rgb) != stride * height:
        raise ValueError(f"expected {stride * height} bytes of RGB data, got {len(rgb)}")
    raw = bytearray((stride + 1) * height)
    for row in range(height):
        start = row * (stride + 1)
        raw[start] = 0  # filter type: None
        raw[start + 1 : start + 1 + stride] = rgb[row * stride : (row + 1) * stride]
    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)  # 8-bit, truecolour RGB
    return b"".join(
        (
            _PNG_SIGNATURE,
            _chunk(b"IHDR", header),
            _chunk(b"IDAT", zlib.compress(bytes(raw), 6)),
            _chunk(b"IEND", b""),
        )
    )


class CameraRenderer:
    """Renders a top-down view of the robot: a grid (1 m spacing), the world axes, and a dot at
    the robot's position with a short line showing its heading.

    The view is centred on the world origin and spans ``width / pixels_per_m`` metres; a robot
    outside the view is drawn clamped to the border. Not thread-safe: one renderer per thread.
    """

    def __init__(self, width: int = 160, height: int = 120, pixels_per_m: float = 20.0) -> None:
        self.width = width
        self.height = height
        self.pixels_per_m = pixels_per_m
        self._background = self._draw_background()

    def _draw_background(self) -> bytearray:
        w, h, ppm = self.width, self.height, self.pixels_per_m
        img = bytearray(bytes((24, 28, 36)) * (w * h))
        cx, cy = w // 2, h // 2
        grid = (52, 58, 70)
        axis = (96, 104, 120)
        for px in range(w):
            if round(abs(px - cx) % ppm) in (0, round(ppm)):
                colour = axis if px == cx else grid
                for py in range(h):
                    self._put(img, px, py, colour)
        for py in range(h):
            if round(abs(py - cy) % ppm) in (0, round(ppm)):
                colour = axis if py == cy else grid
                for px in range(w):
                    self._put(img, px, py, colour)
        return img

    def _put(self, img: bytearray, px: int, py: int, colour: tuple[int, int, int]) -> None:
        if 0 <= px < self.width and 0 <= py < self.height:
            i = (py * self.width + px) * 3
            img[i : i + 3] = bytes(colour)

    def render(self, x: float, y: float, yaw: float, *, led: bool = False) -> bytes:
        """Return a PNG of the robot at world pose ``(x, y, yaw)`` (metres, radians).

        The dot is green when ``led`` is on, orange otherwise.
        """
        img = bytearray(self._background)
        cx = self.width / 2 + x * self.pixels_per_m
        cy = self.height / 2 - y * self.pixels_per_m  # image rows grow downwards
        cx = min(max(cx, 0.0), self.width - 1.0)
        cy = min(max(cy, 0.0), self.height - 1.0)
        colour = (60, 220, 90) if led else (255, 150, 40)
        radius = 4
        for dy in range(-radius, radius + 1):
            for dx in range(-radius, radius + 1):
                if dx * dx + dy * dy <= radius * radius:
                    self._put(img, round(cx) + dx, round(cy) + dy, colour)
        for step in range(radius, radius + 7):
            px = round(cx + step * math.cos(yaw))
            py = round(cy - step * math.sin(yaw))
            self._put(img, px, py, (240, 240, 240))
        return encode_png_rgb(self.width, self.height, img)
