"""Text mesh files (OBJ and its MTL) read in any 8-bit encoding; binary garbage refused in one line.

trimesh decodes non-UTF-8 text through `charset_normalizer`, an optional package; here a text file is decoded
as UTF-8, else as Latin-1 (every byte is a character; OBJ keywords and numbers are ASCII, so only comments and
names can change), and handed to trimesh as UTF-8.
"""

from __future__ import annotations

import io
from pathlib import Path

TEXT_SUFFIXES = (".obj", ".mtl")
_ALLOWED_CONTROLS = frozenset("\t\n\r\f\v")
MAX_CONTROL_FRACTION = 0.001  # of the characters: more than this is not a text file


class MeshTextError(ValueError):
    """A text mesh file that holds binary data (the message is one line naming the file)."""


def decode_mesh_text(data: bytes, name: str) -> str:
    """Bytes of a text mesh file -> str; MeshTextError naming `name` and the first binary byte for garbage."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    controls = [i for i, ch in enumerate(text) if ch < " " and ch not in _ALLOWED_CONTROLS or ch == "\x7f"]
    if controls and ("\x00" in text or len(controls) > MAX_CONTROL_FRACTION * len(text)):
        raise MeshTextError(f"{name} is not a text {Path(name).suffix.upper().lstrip('.')} file (binary byte "
                         f"0x{ord(text[controls[0]]):02x} at character {controls[0]}); allowed: OBJ/MTL text "
                         f"in UTF-8 or any 8-bit encoding")
    return text


#: MTL colour statements: "K? r g b", "K? r" (grey: g and b default to r), "K? spectral file [factor]", "K? xyz x y z"
MTL_COLOURS = ("Ka", "Kd", "Ks", "Ke", "Tf")


def read_mtl(text: str) -> tuple[str, dict[str, tuple[float, float, float]]]:
    """An MTL file's text as trimesh reads it, and {material name: Kd (r, g, b), 0..1 sRGB} of the materials that
    state one. trimesh drops every material of a file that has a one-number colour ("Kd 0.3") or a spectral or
    xyz one: the first is written out in full here, the others (which the dome's channels cannot take) are left
    out, their material white. A material without Kd gets a diffuse of 0.4 in trimesh, so the Kd stated is
    kept here. MeshTextError for a colour that is none of these."""
    out, kd, name = [], {}, None
    for line in text.splitlines():
        words = line.split()
        if len(words) >= 2 and words[0] == "newmtl":
            name = " ".join(words[1:])
        elif words and words[0] in MTL_COLOURS:
            if words[1:2] in (["spectral"], ["xyz"]):
                out.append(f"# {line}")
                continue
            try:
                rgb = [float(w) for w in words[1:]]
            except ValueError:
                rgb = []
            if len(rgb) not in (1, 3):
                raise MeshTextError(f"material {name!r}: {line.strip()!r}; allowed: {words[0]} r g b, or "
                                    f"{words[0]} r (grey)")
            rgb = rgb * 3 if len(rgb) == 1 else rgb
            if words[0] == "Kd" and name is not None:
                kd[name] = tuple(rgb)
            line = f"{words[0]} {rgb[0]!r} {rgb[1]!r} {rgb[2]!r}"
        out.append(line)
    return "\n".join(out) + "\n", kd


def check_textures(mtl_text: str, get) -> None:
    """MeshTextError naming the first `map_Kd` texture of an MTL text that `get` (name -> bytes) cannot give
    as a whole image (trimesh would draw its material in Kd instead)."""
    from PIL import Image

    material = None
    for line in mtl_text.splitlines():
        words = line.split()
        if len(words) >= 2 and words[0] == "newmtl":
            material = " ".join(words[1:])
        elif len(words) >= 2 and words[0] == "map_Kd":
            try:
                with Image.open(io.BytesIO(get(words[-1]))) as image:
                    image.load()
            except Exception as exc:  # missing, truncated or not an image: PIL and the resolver raise many types
                raise MeshTextError(f"material {material!r}: cannot read its texture {words[-1]!r} "
                                    f"({type(exc).__name__}); allowed: an image file next to the MTL") from exc


def load_text_mesh(path: Path):
    """trimesh.Scene of an OBJ file, with its MTL files decoded the same way (resolved next to it) and read by
    `read_mtl` (MeshTextError naming the MTL file for a colour it refuses or a `map_Kd` texture it cannot read);
    each `o` object a geometry of its own (one per material where the file has several: `name_material`); the
    Kd of every material that states one in `scene.metadata["mtl_kd"]`."""
    import trimesh

    kd: dict[str, tuple[float, float, float]] = {}
    refused: list[MeshTextError] = []  # trimesh skips a material file whose reading raises: raised after it

    class _Utf8Resolver(trimesh.resolvers.FilePathResolver):
        def get(self, name: str) -> bytes:
            data = super().get(name)
            if Path(name).suffix.lower() in TEXT_SUFFIXES:
                try:
                    text = decode_mesh_text(data, name)
                    if Path(name).suffix.lower() == ".mtl":
                        try:
                            text, stated = read_mtl(text)
                            check_textures(text, super().get)
                        except MeshTextError as exc:
                            raise MeshTextError(f"{path.parent / name}: {exc}") from exc
                        kd.update(stated)
                except MeshTextError as exc:
                    refused.append(exc)
                    raise
                return text.encode("utf-8")
            return data

    text = decode_mesh_text(path.read_bytes(), str(path))
    scene = trimesh.load(io.BytesIO(text.encode("utf-8")), file_type=path.suffix.lower().lstrip("."),
                         resolver=_Utf8Resolver(str(path)), force="scene", process=False, split_objects=True)
    if refused:
        raise refused[0]
    scene.metadata["mtl_kd"] = kd
    return scene
