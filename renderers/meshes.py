"""Mesh worlds from files through trimesh (OBJ, PLY, GLB/GLTF, STL): metres, +z up (a file in other units or
+y up is converted on load by its `scale` and `up`).

Each geometry node becomes a named `SceneObject`: its position is the node's translation, its vertices the
rest of the node transform (vertices far from the node's origin, as in georeferenced files, are recentred: their
middle moves into the position, see `recentring`). Textures, vertex colours (OBJ, PLY) and OBJ's MTL Kd (of a
material without a texture) are sRGB (float textures linear); glTF's base colour factor and vertex colours
(COLOR_0) are linear, as its specification says (glTF 2.0, sections 3.9.2 and 3.7.2.1), its base colour texture
sRGB. All map to G, B, UV by `channels`; meshes
without colour are mid-grey. A glTF material's alphaMode MASK cuts its texture out where the texture's alpha
(times the factor's) is below alphaCutoff; BLEND is drawn as MASK at 0.5 (`alpha_cutoff`); OBJ textures' alpha,
and alpha without a texture, are ignored.
"""

from __future__ import annotations

from pathlib import Path
from urllib.parse import unquote

import numpy as np

from antarium.core.numbers import as_real

from .channels import rgb_to_gbu, srgb_to_linear
from .mesh_text import TEXT_SUFFIXES, MeshTextError, load_text_mesh
from .scene import MAX_COORDINATE_M, MAX_TEXTURE_SIDE, MeshData, SceneObject

MESH_SUFFIXES = (".obj", ".ply", ".glb", ".gltf", ".stl")
DEFAULT_GREY = 0.5
#: Vertices whose middle lies farther than this (m) from their node's origin are stored relative to that middle.
RECENTRE_BEYOND_M = 1000.0
#: glTF is +y up (its specification): (X, Y, Z) glTF -> (X, -Z, Y) world. Other formats: +z up unless stated.
GLTF_TO_WORLD = np.array([[1.0, 0, 0, 0], [0, 0, -1.0, 0], [0, 1.0, 0, 0], [0, 0, 0, 1.0]])
#: a mesh file's up axis -> the 4 x 4 turn of its coordinates into the world's (+z up)
UP_AXES = {"z": np.eye(4), "y": GLTF_TO_WORLD}


def recentring(local: np.ndarray) -> np.ndarray:
    """(3,) float64 shift (m) from a node's origin to the middle of its (V, 3) float64 vertices, when that lies
    beyond RECENTRE_BEYOND_M (georeferenced files: coordinates of kilometres, whose millimetres float32 vertices
    would lose), else zeros. The shift moves into the object's position, which stays float64."""
    middle = (local.min(axis=0) + local.max(axis=0)) / 2
    return middle if np.abs(middle).max() > RECENTRE_BEYOND_M else np.zeros(3)


def texture_linear(image) -> np.ndarray:
    """(H, W, 3) linear RGB in [0, 1] of a PIL image. 8-bit, 16-bit greyscale (I;16*) and 32-bit integer (I, at
    its file's bit depth, 32 unless a TIFF states fewer) images are sRGB-encoded and decoded; float images (F) are
    linear and must lie in [0, 1]. Raises ValueError for values outside that range."""
    if image.mode == "F":
        grey = np.asarray(image, dtype=np.float64)
        if not (np.all(np.isfinite(grey)) and grey.min() >= 0.0 and grey.max() <= 1.0):
            raise ValueError(f"float texture values must be linear radiances in [0, 1], got {np.nanmin(grey):g} "
                             f"to {np.nanmax(grey):g}")
        return np.repeat(grey[..., None], 3, axis=2)
    if image.mode.startswith("I"):
        bits = 16 if image.mode.startswith("I;16") else _tiff_bits(image)
        grey = np.asarray(image, dtype=np.float64)
        if grey.min() < 0:
            raise ValueError(f"integer texture values must be >= 0, got {grey.min():g}")
        return np.repeat(srgb_to_linear(grey / (2.0**bits - 1))[..., None], 3, axis=2)
    return srgb_to_linear(np.asarray(image.convert("RGB"), dtype=np.float64) / 255.0)


def _tiff_bits(image) -> int:
    """Bits per sample of a 32-bit integer (mode I) PIL image: its TIFF's BitsPerSample (tag 258), else 32."""
    stated = getattr(image, "tag_v2", {}).get(258, (32,))
    return int(stated[0] if isinstance(stated, tuple) else stated)


def _unit(factor) -> np.ndarray:
    """A colour factor as float64 in [0, 1] (trimesh gives glTF's as uint8 0..255, MTL's as floats)."""
    f = np.asarray(factor)
    return f.astype(np.float64) / (255.0 if f.dtype.kind in "iu" else 1.0)


def alpha_cutoff(material) -> float | None:
    """The texture alpha below which a glTF material is not drawn: its alphaCutoff (0.5 by default) for alphaMode
    MASK; 0.5 for BLEND (drawn as a cut-out: the dome's meshes are not sorted back to front for blending); None
    for OPAQUE (alpha ignored)."""
    mode = str(getattr(material, "alphaMode", None) or "OPAQUE").upper()
    if mode == "MASK":
        cutoff = getattr(material, "alphaCutoff", None)
        return 0.5 if cutoff is None else float(cutoff)
    return 0.5 if mode == "BLEND" else None


def _colours_and_texture(geom, name: str, mtl_kd: dict, gltf: bool):
    """(V, 3) linear G, B, UV vertex colours, and (uv, texture) or (None, None); a texture carries the colour
    factor (multiplied in linear RGB), its vertices are white. gltf: the colour factor and the vertex colours
    are linear (else sRGB). mtl_kd: an OBJ's {material name: Kd}: the colour of a material drawn
    without a texture (with one, the texture alone gives the colour, as Blender's importer and the photogrammetry
    programs that write such files mean it; the MTL specification would multiply it by Kd, often a placeholder
    such as 0.8 there)."""
    n = len(geom.vertices)
    visual = getattr(geom, "visual", None)
    kind = getattr(visual, "kind", None)
    if kind == "texture":
        material = visual.material
        image = getattr(material, "baseColorTexture", None) or getattr(material, "image", None)
        textured = image is not None and visual.uv is not None and len(visual.uv) == n
        factor = getattr(material, "baseColorFactor", None)
        if not textured:
            factor = mtl_kd.get(getattr(material, "name", None), factor)
        base = np.ones(3) if factor is None else _unit(factor)[:3]
        base = base if gltf else srgb_to_linear(base)
        if not textured:
            return np.repeat(rgb_to_gbu(base)[None, :], n, axis=0), None, None
        try:
            img = texture_linear(image)
        except ValueError as exc:
            raise ValueError(f"texture of object {name!r}: {exc}") from exc
        if max(img.shape[:2]) > MAX_TEXTURE_SIDE:
            raise ValueError(f"texture of object {name!r} is {img.shape[1]}x{img.shape[0]} pixels; the largest "
                             f"side allowed is {MAX_TEXTURE_SIDE}")
        # the factor goes into the texture in linear RGB: the shader multiplies texture and vertex colour (white)
        texture = rgb_to_gbu(img * base)
        cutoff = alpha_cutoff(material) if gltf else None
        if cutoff is not None:
            alpha = np.asarray(image.convert("RGBA"), dtype=np.float64)[..., 3] / 255.0
            alpha *= 1.0 if factor is None or np.size(factor) < 4 else _unit(factor)[3]
            texture = np.concatenate([texture, (alpha >= cutoff)[..., None].astype(np.float32)], axis=2)
        return np.ones((n, 3), np.float32), np.asarray(visual.uv, dtype=np.float32), texture
    if kind == "vertex" or kind == "face":
        rgb = np.asarray(visual.vertex_colors, dtype=np.float64)[:, :3] / 255.0
        return rgb_to_gbu(rgb if gltf else srgb_to_linear(rgb)), None, None
    return np.full((n, 3), DEFAULT_GREY, dtype=np.float32), None, None


def gltf_json(path: Path) -> dict:
    """The JSON document of a .gltf file or of a .glb file's first chunk; ValueError naming the file if unreadable."""
    import json
    import struct

    data = path.read_bytes()
    try:
        if path.suffix.lower() == ".glb":
            length, kind = struct.unpack_from("<I4s", data, 12)
            if kind != b"JSON":
                raise ValueError("the first chunk is not JSON")
            data = data[20:20 + length]
        return json.loads(data)
    except (ValueError, struct.error) as exc:
        raise ValueError(f"cannot read glTF file {path}: {exc}") from exc


#: glTF extensions that a file may require and trimesh cannot decode (it loads their meshes as zeros, or drops
#: their textures): extension -> (what it is, the Python module that would decode it, or None)
UNDECODED_GLTF_EXTENSIONS = {
    "KHR_draco_mesh_compression": ("Draco mesh compression", "DracoPy"),
    "EXT_meshopt_compression": ("meshopt compression", None),
    "KHR_texture_basisu": ("KTX2/Basis Universal textures", None),
}


def check_gltf_extensions(path: Path) -> None:
    """ValueError naming the file and the first extension it requires (`extensionsRequired`) that is in
    UNDECODED_GLTF_EXTENSIONS and whose decoder is not installed."""
    from importlib.util import find_spec

    for name in gltf_json(path).get("extensionsRequired", []):
        what, module = UNDECODED_GLTF_EXTENSIONS.get(name, (None, None))
        if what is not None and (module is None or find_spec(module) is None):
            raise ValueError(f"{path} requires the glTF extension {name} ({what}), which cannot be decoded here; "
                             f"allowed: a file exported without it (e.g. Blender's glTF export with compression "
                             f"off)")


def check_gltf_textures(path: Path) -> None:
    """ValueError naming the file and the material whose base colour texture does not lead to an image: a texture
    or image index out of range, or an image file that is missing (trimesh drew such a material untextured)."""
    doc = gltf_json(path)
    textures, images = doc.get("textures", []), doc.get("images", [])
    for m, material in enumerate(doc.get("materials", [])):
        ref = material.get("pbrMetallicRoughness", {}).get("baseColorTexture")
        if ref is None:
            continue
        name = material.get("name", f"#{m}")
        index = ref.get("index")
        source = textures[index].get("source") if isinstance(index, int) and 0 <= index < len(textures) else None
        image = images[source] if isinstance(source, int) and 0 <= source < len(images) else None
        uri = unquote(image.get("uri", "")) if image is not None else ""
        if image is None or (uri and not uri.startswith("data:") and not (path.parent / uri).is_file()):
            what = f"image {uri!r} not found" if image is not None else f"texture {index!r} leads to no image"
            raise ValueError(f"{path}: material {name!r}: its base colour texture cannot be read ({what}); allowed: "
                             f"a texture index into textures whose source indexes images, the image file present")


def load_mesh_objects(path: str | Path, scale: float = 1.0, up: str | None = None,
                      origin=None) -> dict[str, SceneObject]:
    """Named objects of a mesh file in metres, +z up: `scale` metres per file unit (0.001: millimetres), `up` the
    file's up axis, "z" or "y" (default: "y" for GLB/GLTF, +y up by their specification, else "z"; GLB/GLTF take
    "y" only); `origin` (3,) m, the point (in the world's axes, after scale and up) that becomes (0, 0, 0), e.g. a
    georeferenced scan's ground under the start (the rig's eye stays within 1000 km of (0, 0), its height taken
    from z = 0); None: (0, 0, 0). Raises FileNotFoundError or ValueError naming the file and the problem."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"mesh file not found: {path}")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise ValueError(f"unsupported mesh format {path.suffix!r} ({path}); allowed: {', '.join(MESH_SUFFIXES)}")
    gltf = path.suffix.lower() in (".glb", ".gltf")
    if not gltf and path.name != path.name.encode("utf-8", "replace").decode("utf-8"):
        # trimesh names the objects of OBJ, PLY and STL files by the file's name and fails on one that is not UTF-8
        raise ValueError(f"mesh file name {ascii(path.name)} is not UTF-8 text (its bytes in another encoding); "
                         f"allowed: a file name in UTF-8 (rename the file)")
    up = ("y" if gltf else "z") if up is None else up
    if not isinstance(up, str) or up not in UP_AXES or (gltf and up != "y"):
        allowed = '"y" (GLB/GLTF are +y up by their specification)' if gltf else '"z" or "y"'
        raise ValueError(f"{path}: up must be the file's up axis, {allowed}; got {repr(up)[:60]}")
    if not (isinstance(scale, (int, float)) and not isinstance(scale, bool) and np.isfinite(scale) and scale > 0):
        raise ValueError(f"{path}: scale must be a positive number of metres per file unit (0.001: millimetres), "
                         f"got {repr(scale)[:60]}")
    moved = np.zeros(3) if origin is None else np.array(
        [as_real(v) for v in origin] if isinstance(origin, (list, tuple, np.ndarray)) else [np.nan])
    if moved.shape != (3,) or not np.all(np.abs(moved) <= MAX_COORDINATE_M):
        raise ValueError(f"{path}: origin must be 3 finite numbers (m) within {MAX_COORDINATE_M:g} m of (0, 0, 0), "
                         f"the file's point that becomes (0, 0, 0); got {repr(origin)[:60]}")
    to_world = UP_AXES[up] @ np.diag([scale, scale, scale, 1.0])
    import trimesh

    if gltf:
        check_gltf_extensions(path)
    try:
        if path.suffix.lower() in TEXT_SUFFIXES:
            loaded = load_text_mesh(path)
        else:
            loaded = trimesh.load(str(path), force="scene", process=False)
    except MeshTextError:
        raise
    except Exception as exc:  # trimesh raises many types for corrupt files
        raise ValueError(f"cannot read mesh file {path}: {type(exc).__name__}: {exc}") from exc
    objects: dict[str, SceneObject] = {}
    if gltf:
        check_gltf_textures(path)
    for node in loaded.graph.nodes_geometry:
        transform, geom_name = loaded.graph[node]
        geom = loaded.geometry[geom_name]
        if not isinstance(geom, trimesh.Trimesh) or len(geom.faces) == 0:
            continue
        name = str(node)
        if getattr(geom.visual, "kind", None) == "face":  # each face its own vertices: keeps its colour whole
            geom = geom.copy()
            geom.unmerge_vertices()
        try:
            colours, uv, texture = _colours_and_texture(geom, name, loaded.metadata.get("mtl_kd", {}), gltf)
            t = to_world @ np.asarray(transform, dtype=np.float64)
            local = np.asarray(geom.vertices, dtype=np.float64) @ t[:3, :3].T
            shift = recentring(local)
            mesh = MeshData((local - shift).astype(np.float32), np.asarray(geom.faces), colours, uv, texture)
            mesh.validate(name)
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from exc
        position = t[:3, 3] + shift - moved
        if not np.abs(position).max() <= MAX_COORDINATE_M:  # SceneObject would refuse it naming neither
            raise ValueError(f"{path}: object {name!r} lies at {np.round(position, 1).tolist()} m; allowed: within "
                             f"{MAX_COORDINATE_M:g} m of (0, 0, 0) (a file in millimetres: scale 0.001; a far point "
                             f"of the file to (0, 0, 0): origin)")
        objects[name] = SceneObject(mesh, position=tuple(position))
    if not objects:
        raise ValueError(f"mesh file {path} contains no triangles (empty or not a triangle mesh)")
    return objects


def save_glb(objects: dict[str, SceneObject], path: str | Path) -> Path:
    """Write named objects to a GLB file (+y up as glTF requires; linear vertex colours, as glTF's COLOR_0 is;
    node = position)."""
    import trimesh

    scene = trimesh.Scene()
    for name, obj in objects.items():
        m = obj.mesh
        # invert the G, B mapping approximately for viewers: R = G, G = G, B = B (UV is implied by B)
        lin = np.stack([m.colours[:, 0], m.colours[:, 0], m.colours[:, 1]], axis=1)
        rgba = np.concatenate([np.rint(np.clip(lin, 0, 1) * 255), np.full((len(lin), 1), 255)], axis=1).astype(np.uint8)
        c, s = np.cos(obj.yaw), np.sin(obj.yaw)
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) * obj.scale
        local = m.vertices.astype(np.float64) @ rot.T
        tm = trimesh.Trimesh(local, m.faces, vertex_colors=rgba, process=False)
        transform = np.eye(4)
        transform[:3, 3] = obj.position
        transform = GLTF_TO_WORLD.T @ transform
        scene.add_geometry(tm, node_name=name, geom_name=name, transform=transform)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = scene.export(file_type="glb")
    path.write_bytes(data)
    return path
