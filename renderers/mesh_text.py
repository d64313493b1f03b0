"""Text mesh files (OBJ and its MTL) read in any 8-bit encoding; binary garbage refused in one line.

trimesh decodes non-UTF-8 text through `charset_normalizer`, an optional package; here a text file is decoded
as UTF-8, else as Latin-1 (every byte is a character; OBJ keywords and numbers are ASCII, so only comments and
names can change), and handed to trimesh as UTF-8.
"""

from __future__ import annotations

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


def load_text_mesh(path: Path):
    """trimesh.Scene of an OBJ file, with its MTL files decoded the same way (resolved next to it)."""
    import io

    import trimesh

    class _Utf8Resolver(trimesh.resolvers.FilePathResolver):
        def get(self, name: str) -> bytes:
            data = super().get(name)
            if Path(name).suffix.lower() in TEXT_SUFFIXES:
                return decode_mesh_text(data, name).encode("utf-8")
            return data

    text = decode_mesh_text(path.read_bytes(), str(path))
    return trimesh.load(io.BytesIO(text.encode("utf-8")), file_type=path.suffix.lower().lstrip("."),
                        resolver=_Utf8Resolver(str(path)), force="scene", process=False)
