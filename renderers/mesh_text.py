"""Text mesh files (OBJ and its MTL) read in any 8-bit encoding; binary garbage refused in one line.

trimesh decodes non-UTF-8 text through `charset_normalizer`, an optional package; here a text file is decoded
as UTF-8, else as Latin-1 (every byte is a character; OBJ keywords and numbers are ASCII, so only comments and
names can change), and handed to trimesh as UTF-8.
"""

from __future__ import annotations

import io
import os
import re
from pathlib import Path

import numpy as np

TEXT_SUFFIXES = (".obj", ".mtl")
#: control characters that no text file holds (tab, line feed, vertical tab, form feed and return are allowed)
_CONTROLS = re.compile(r"[\x00-\x08\x0e-\x1f\x7f]")
MAX_CONTROL_FRACTION = 0.001  # of the characters: more than this is not a text file


class MeshTextError(ValueError):
    """A text mesh file that holds binary data (the message is one line naming the file)."""


def decode_mesh_text(data: bytes, name: str) -> str:
    """Bytes of a text mesh file -> str; MeshTextError naming `name` and the first binary byte for garbage."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    first = _CONTROLS.search(text)  # a regular expression: a Python loop took 60 s on a 3 M triangle OBJ
    if first and ("\x00" in text or len(_CONTROLS.findall(text)) > MAX_CONTROL_FRACTION * len(text)):
        raise MeshTextError(f"{name} is not a text {Path(name).suffix.upper().lstrip('.')} file (binary byte "
                            f"0x{ord(first.group()):02x} at character {first.start()}); allowed: OBJ/MTL text "
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


#: a face line of 4 or more corners (up to a comment) and a vertex line, each after a line feed (possessive: 1.6 s
#: over 113 MB of triangles, a backtracking pattern 11 s)
_POLYGON = re.compile(r"\nf([ \t]++[^\s#]++){3}[ \t]++[^\s#][^\n#]*")
_VERTEX = re.compile(r"\nv[ \t]++(\S++)[ \t]++(\S++)[ \t]++(\S++)")
_REF_TAIL = re.compile(r"/\S*|\nf")  # a face corner's texture and normal references, and the line's "f"


def ear_clip(points: np.ndarray) -> list[tuple[int, int, int]]:
    """Triangles (corner indices) of a simple polygon given by its (N, 3) float64 corners in order, N >= 3,
    by ear clipping in its plane (Newell's normal); the remainder as a fan where no ear is left (a polygon that
    crosses itself)."""
    normal = np.cross(points, np.roll(points, -1, axis=0)).sum(axis=0)
    drop = int(np.argmax(np.abs(normal)))  # project on the plane of the two other axes, kept counter-clockwise
    xy = np.delete(points, drop, axis=1) * [1.0, 1.0 if normal[drop] >= 0 else -1.0]
    xy = xy if drop != 1 else xy[:, ::-1]

    def cross(a, b, c) -> float:
        return (xy[b, 0] - xy[a, 0]) * (xy[c, 1] - xy[a, 1]) - (xy[b, 1] - xy[a, 1]) * (xy[c, 0] - xy[a, 0])

    ring, out = list(range(len(points))), []
    while len(ring) > 3:
        for k in range(1, len(ring) + 1):  # from corner 1: a convex polygon gives trimesh's fan from corner 0
            a, b, c = ring[k - 1], ring[k % len(ring)], ring[(k + 1) % len(ring)]
            inside = any(cross(a, b, q) >= 0 and cross(b, c, q) >= 0 and cross(c, a, q) >= 0
                         for q in ring if q not in (a, b, c))
            if cross(a, b, c) > 0 and not inside:
                out.append((a, b, c))
                ring.pop(k % len(ring))
                break
        else:
            break
    return out + [(ring[0], ring[k], ring[k + 1]) for k in range(1, len(ring) - 1)]


def triangulate_polygons(text: str) -> str:
    """OBJ text with each face of 4 or more corners that is not convex written as triangles (`ear_clip`):
    trimesh cuts every polygon into a fan from its first corner, which covers more than a non-convex polygon
    (an L-shaped wall drew across its notch). Convex polygons and triangles are left to trimesh."""
    text = "\n" + text
    found = list(_POLYGON.finditer(text))
    if not found:
        return text[1:]
    vertices = list(_VERTEX.finditer(text))
    v = np.array([m.groups() for m in vertices], dtype=np.float64).reshape(-1, 3)
    before = np.searchsorted(np.array([m.start() for m in vertices], dtype=np.int64),
                             [m.start() for m in found])  # the number of vertices defined before each face line
    groups: dict[int, list] = {}  # corner count: indices into found
    for i, m in enumerate(found):
        groups.setdefault(len(m.group().split()) - 1, []).append(i)
    out = []
    for count, rows in groups.items():  # vectorised: a loop per polygon took 15 s for a million quads
        refs = np.array(_REF_TAIL.sub(" ", "".join(found[i].group() for i in rows)).split(), dtype=np.int64)
        refs, defined = refs.reshape(len(rows), count), before[rows][:, None]
        corners = np.where(refs > 0, refs - 1, defined + refs)  # OBJ counts from 1, negative back from the line
        ok = np.flatnonzero(((corners >= 0) & (corners < defined)).all(axis=1))  # else trimesh names the bad index
        p = v[corners[ok]]  # (P, K, 3)
        edges = np.roll(p, -1, axis=1) - p
        normal = np.cross(p, np.roll(p, -1, axis=1)).sum(axis=1)  # Newell's
        turns = np.einsum("pkc,pc->pk", np.cross(np.roll(edges, 1, axis=1), edges), normal)
        for i in np.flatnonzero((turns < 0).any(axis=1)):  # a corner turning against the normal: not convex
            m = found[rows[ok[i]]]
            words = m.group().split()
            out.append((m.start(), m.end(), "\nf " + "\nf ".join(" ".join(words[1 + k] for k in t)
                                                                for t in ear_clip(p[i]))))
    done, pieces = 0, []
    for start, end, triangles in sorted(out):
        pieces += [text[done:start], triangles]
        done = end
    return "".join([*pieces, text[done:]])[1:]


def load_text_mesh(path: Path):
    """trimesh.Scene of an OBJ file, with its MTL files decoded the same way (resolved next to it) and read by
    `read_mtl` (MeshTextError naming the MTL file for a colour it refuses or a `map_Kd` texture it cannot read,
    or naming the OBJ for an MTL file that is missing);
    each `o` object a geometry of its own (one per material where the file has several: `name_material`); the
    Kd of every material that states one in `scene.metadata["mtl_kd"]`."""
    import trimesh

    kd: dict[str, tuple[float, float, float]] = {}
    refused: list[MeshTextError] = []  # trimesh skips a material file whose reading raises: raised after it

    class _Utf8Resolver(trimesh.resolvers.FilePathResolver):
        def raw(self, name: str) -> bytes:
            """The bytes of the file `name`, else of the file whose name is the bytes that `name` was read from
            as Latin-1 (an 8-bit, not UTF-8, name in an 8-bit text; `decode_mesh_text`)."""
            try:
                return super().get(name)
            except OSError:
                if name.isascii() or max(map(ord, name)) > 0xFF:  # no 8-bit name read as Latin-1
                    raise
                return super().get(os.fsdecode(name.encode("latin-1")))

        def get(self, name: str) -> bytes:
            try:
                data = self.raw(name)
            except OSError as exc:  # trimesh would draw the materials of a missing MTL grey, unsaid
                if Path(name).suffix.lower() == ".mtl":
                    refused.append(MeshTextError(f"{path}: cannot read its material file {name!r} "
                                                 f"({type(exc).__name__}); allowed: the MTL file that its mtllib "
                                                 f"names, next to the OBJ (or no mtllib line)"))
                raise
            if Path(name).suffix.lower() in TEXT_SUFFIXES:
                try:
                    text = decode_mesh_text(data, name)
                    if Path(name).suffix.lower() == ".mtl":
                        try:
                            text, stated = read_mtl(text)
                            check_textures(text, self.raw)
                        except MeshTextError as exc:
                            raise MeshTextError(f"{path.parent / name}: {exc}") from exc
                        kd.update(stated)
                except MeshTextError as exc:
                    refused.append(exc)
                    raise
                return text.encode("utf-8")
            return data

    text = triangulate_polygons(decode_mesh_text(path.read_bytes(), str(path)))
    scene = trimesh.load(io.BytesIO(text.encode("utf-8")), file_type=path.suffix.lower().lstrip("."),
                         resolver=_Utf8Resolver(str(path)), force="scene", process=False, split_objects=True)
    if refused:
        raise refused[0]
    scene.metadata["mtl_kd"] = kd
    return scene
