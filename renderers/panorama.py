"""A distant panorama at infinity from an equirectangular image (OpenCV: PNG, JPEG, TIFF, HDR; OpenEXR: EXR).

Image convention: the centre column looks along azimuth 0 (+x), azimuth grows to the left (counter-
clockwise seen from above), the top row is the zenith. 8- and 16-bit images are sRGB-encoded and decoded at
full precision; float images (EXR, float TIFF) are linear radiance and keep their range (scaled by
`exposure`, clipped at the LEDs' maximum). Grey images (and grey + alpha) are spread to RGB(A). An alpha channel
makes pixels transparent (the sky shows through); an optional single-channel `uv` image is the explicit UV
layer, otherwise UV = uv_ratio * blue. The UV layer follows the image's rule by its own type: 8- or 16-bit
sRGB-decoded, float linear times `exposure`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from antarium.core.numbers import check_number

from .channels import DEFAULT_UV_RATIO, rgb_to_gbu, srgb_to_linear

#: Largest accepted image side in pixels (OpenCV and GL textures both handle it; larger is refused).
MAX_IMAGE_SIDE = 16384
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".exr", ".tif", ".tiff", ".hdr")


def _read_exr(data: bytes, path: Path) -> np.ndarray:
    """(H, W, C) float32 BGR(A) pixels of an OpenEXR file's bytes `data` (RGB, RGBA or luminance Y)."""
    import io

    import OpenEXR

    try:
        with OpenEXR.File(io.BytesIO(data)) as f:
            channels = {name: np.asarray(c.pixels) for name, c in f.channels().items()}
    except Exception as exc:  # the bindings raise RuntimeError/OSError for corrupt files
        raise ValueError(f"cannot decode EXR image {path}: {exc}") from exc
    for key in ("RGBA", "RGB"):
        if key in channels:
            rgb = channels[key].astype(np.float32)
            return rgb[:, :, [2, 1, 0, *range(3, rgb.shape[2])]]
    if all(k in channels for k in "RGB"):
        return np.stack([channels[k] for k in "BGR"], axis=2).astype(np.float32)
    if "Y" in channels:
        return channels["Y"].astype(np.float32)
    raise ValueError(f"EXR image {path} has no RGB or Y channels (found: {', '.join(channels)})")


def read_image(path: str | Path) -> tuple[np.ndarray, bool]:
    """(H, W, C) float64 values (integer images scaled to [0, 1]) and whether the image is float (linear)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"panorama image not found: {path}")
    if path.suffix.lower() not in IMAGE_SUFFIXES:
        raise ValueError(f"unsupported panorama format {path.suffix!r} ({path}); allowed: {', '.join(IMAGE_SUFFIXES)}")
    # the bytes are read here: OpenCV's imread of a name that is not UTF-8 ended the process (a segmentation
    # fault), OpenEXR refused it
    data = path.read_bytes()
    if path.suffix.lower() == ".exr":
        img = _read_exr(data, path)
    else:
        import cv2

        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED | cv2.IMREAD_ANYDEPTH |
                           cv2.IMREAD_ANYCOLOR) if data else None
        if img is None or img.size == 0:
            raise ValueError(f"cannot decode image {path} (corrupt, empty or unsupported by OpenCV)")
    if max(img.shape[:2]) > MAX_IMAGE_SIDE:
        raise ValueError(f"image {path} is {img.shape[1]}x{img.shape[0]} pixels; the largest side allowed is "
                         f"{MAX_IMAGE_SIDE}")
    if img.ndim == 2:
        img = img[:, :, None]
    # OpenCV gives BGR(A): reorder to RGB(A).
    if img.shape[2] >= 3:
        img = img[:, :, [2, 1, 0, *range(3, img.shape[2])]]
    is_float = img.dtype.kind == "f"
    if img.dtype == np.uint8:
        img = img / 255.0
    elif img.dtype == np.uint16:
        img = img / 65535.0
    elif not is_float:
        raise ValueError(f"image {path} has unsupported sample type {img.dtype}")
    img = np.asarray(img, dtype=np.float64)
    if not np.all(np.isfinite(img)):
        raise ValueError(f"image {path} contains NaN or infinite values")
    return img, is_float


def _as_rgba(img: np.ndarray, source) -> np.ndarray:
    """(H, W, 3 or 4) RGB(A) of an (H, W, C) image: grey (C = 1) and grey + alpha (C = 2) spread to RGB(A)."""
    channels = img.shape[2]
    if channels in (1, 2):
        return np.concatenate([np.repeat(img[:, :, :1], 3, axis=2), img[:, :, 1:]], axis=2)
    if channels not in (3, 4):
        raise ValueError(f"panorama {source} must be grey, grey + alpha, RGB or RGBA, got {channels} channels")
    return img


def equirect_lookup(image: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Bilinear lookup of an (H, W, C) equirectangular image at (N, 3) unit directions -> (N, C) float32."""
    import cv2

    h, w = image.shape[:2]
    az = np.arctan2(d[:, 1], d[:, 0])
    el = np.arcsin(np.clip(d[:, 2], -1.0, 1.0))
    mx = ((0.5 - az / (2 * np.pi)) * w - 0.5).astype(np.float32)
    my = np.clip((0.5 - el / np.pi) * h - 0.5, 0, h - 1).astype(np.float32)
    src = np.ascontiguousarray(image, dtype=np.float32)
    # cv2.remap needs maps smaller than SHRT_MAX on each side: lay the points out in rows of 1024
    n, cols = len(d), 1024
    rows = -(-n // cols)
    pad = rows * cols - n
    mx = np.concatenate([mx, np.zeros(pad, np.float32)]).reshape(rows, cols)
    my = np.concatenate([my, np.zeros(pad, np.float32)]).reshape(rows, cols)
    r = cv2.remap(src, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
    out = r.reshape(rows * cols, image.shape[2])[:n]
    return out


ASPECT_TOLERANCE = 0.01  # of the width: how far from 2:1 an equirectangular image may be


@dataclass
class Panorama:
    """Far-field panorama layer from an equirectangular image file or an (H, W[, 1 to 4]) array (sRGB in [0, 1]);
    `uv`: an image file or (H, W[, C]) array (its first channel) of the explicit UV layer, read by the same rule."""

    source: object
    uv: object = None
    exposure: float = 1.0
    uv_ratio: float = DEFAULT_UV_RATIO
    max_width: int = 4096
    yaw_rate = 0.0
    time_varying = False
    _gbua: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        if check_number("panorama exposure", self.exposure, 0.0) == 0:
            raise ValueError(f"panorama exposure must be > 0, got {self.exposure!r}")
        self.uv_ratio = check_number("panorama uv_ratio", self.uv_ratio, 0.0)
        name = self.source if isinstance(self.source, (str, Path)) else "array"
        if isinstance(self.source, (str, Path)):
            img, is_float = read_image(self.source)
        else:
            img, is_float = np.asarray(self.source, dtype=np.float64), False
            if img.ndim == 2:
                img = img[:, :, None]
            if img.ndim != 3 or not 1 <= img.shape[2] <= 4 or not np.all(np.isfinite(img)):
                raise ValueError(f"panorama array must be finite (H, W) or (H, W, 1 to 4), got shape {img.shape}")
        img = _as_rgba(img, self.source)
        h, w = img.shape[:2]
        if w < 8 or h < 4:
            raise ValueError(f"panorama {self.source} is too small ({w}x{h} pixels)")
        if abs(w - 2 * h) > max(1.0, ASPECT_TOLERANCE * 2 * h):
            raise ValueError(f"panorama {name} is {w}x{h} pixels: an equirectangular image spans 360 x 180 degrees, "
                             f"so its width must be twice its height (within {ASPECT_TOLERANCE:.0%})")
        rgb = self._linear(img[:, :, :3], is_float)
        uv = None
        if self.uv is not None:
            if isinstance(self.uv, (str, Path)):
                uv_img, uv_float = read_image(self.uv)
            else:
                uv_img, uv_float = np.asarray(self.uv, dtype=np.float64), False
            if uv_img.shape[:2] != (h, w):
                raise ValueError(f"UV layer {self.uv} is {uv_img.shape[1]}x{uv_img.shape[0]}, "
                                 f"the panorama {w}x{h}: they must match")
            uv = self._linear(uv_img.reshape(h, w, -1)[:, :, 0], uv_float)
            is_float = is_float or uv_float
        if self.exposure != 1.0 and not is_float:  # it would be ignored: only linear (float) images are scaled
            raise ValueError(f"panorama exposure scales float (linear) images only; {name} is an integer "
                             f"(sRGB) image, so exposure must be 1, got {self.exposure!r} (dim it with the brightness "
                             "or channel gains)")
        gbu = rgb_to_gbu(rgb, uv, self.uv_ratio)
        alpha = img[:, :, 3:4] if img.shape[2] == 4 else np.ones((h, w, 1))
        if not (alpha.min() >= 0.0 and alpha.max() <= 1.0):
            raise ValueError(f"panorama {name} alpha must be in [0, 1], got values from {alpha.min():g} to "
                             f"{alpha.max():g}")
        gbua = np.concatenate([np.clip(gbu, 0.0, 1.0), alpha], axis=2).astype(np.float32)
        if w > self.max_width:  # area-average down to what the cube map can resolve
            import cv2

            gbua = cv2.resize(gbua, (self.max_width, max(2, self.max_width * h // w)), interpolation=cv2.INTER_AREA)
        self._gbua = gbua

    def _linear(self, values: np.ndarray, is_float: bool) -> np.ndarray:
        """Linear radiance of image values (the colour image's and the UV layer's alike): float images are
        linear and scaled by `exposure`, integer images and arrays sRGB-encoded in [0, 1]."""
        return values * self.exposure if is_float else srgb_to_linear(values)

    @property
    def gbua(self) -> np.ndarray:
        """(H, W, 4) float32: the linear green, blue and UV radiance (0..1) and the alpha the renderer samples."""
        return self._gbua

    def supersample(self, step: float) -> int:
        """Sub-samples per axis: about one per image pixel inside a cell of `step` (rad)."""
        pixel = 2 * np.pi / self._gbua.shape[1]
        return int(min(8, max(1, round(step / pixel))))

    def evaluate(self, d, t=0.0):
        v = equirect_lookup(self._gbua, d)
        out = np.zeros((len(d), 5), dtype=np.float32)
        out[:, :3] = v[:, :3]
        out[:, 4] = v[:, 3]
        return out
