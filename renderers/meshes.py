"""Mesh worlds from files through trimesh (OBJ, PLY, GLB/GLTF, STL): metres, +z up.

Each geometry node becomes a named `SceneObject`: its position is the node's translation, its vertices the
rest of the node transform. Textures, vertex colours (OBJ, PLY) and OBJ's MTL Kd (of a material without a
texture) are sRGB; glTF's base colour factor and vertex colours (COLOR_0) are linear, as its specification says
(glTF 2.0, sections 3.9.2 and 3.7.2.1), its base colour texture sRGB. All map to G, B, UV by `channels`; meshes
without colour are mid-grey.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .channels import rgb_to_gbu, srgb_to_linear
from .mesh_text import TEXT_SUFFIXES, MeshTextError, load_text_mesh
from .scene import MAX_TEXTURE_SIDE, MeshData, SceneObject

MESH_SUFFIXES = (".obj", ".ply", ".glb", ".gltf", ".stl")
DEFAULT_GREY = 0.5
#: glTF is +y up (its specification): (X, Y, Z) glTF -> (X, -Z, Y) world. Other formats are taken as +z up.
GLTF_TO_WORLD = np.array([[1.0, 0, 0, 0], [0, 0, -1.0, 0], [0, 1.0, 0, 0], [0, 0, 0, 1.0]])


def texture_rgb(image) -> np.ndarray:
    """(H, W, 3) sRGB in [0, 1] of a PIL image, 16-bit greyscale (modes I;16*, I) at its full depth."""
    if image.mode.startswith("I"):
        grey = np.asarray(image, dtype=np.float64) / 65535.0
        return np.repeat(grey[..., None], 3, axis=2)
    return np.asarray(image.convert("RGB"), dtype=np.float64) / 255.0


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
        base = np.ones(3) if factor is None else np.asarray(factor, dtype=np.float64)[:3] / (
            255.0 if np.asarray(factor).dtype.kind in "iu" else 1.0)
        base = base if gltf else srgb_to_linear(base)
        if not textured:
            return np.repeat(rgb_to_gbu(base)[None, :], n, axis=0), None, None
        img = texture_rgb(image)
        if max(img.shape[:2]) > MAX_TEXTURE_SIDE:
            raise ValueError(f"texture of object {name!r} is {img.shape[1]}x{img.shape[0]} pixels; the largest "
                             f"side allowed is {MAX_TEXTURE_SIDE}")
        # the factor goes into the texture in linear RGB: the shader multiplies texture and vertex colour (white)
        texture = rgb_to_gbu(srgb_to_linear(img) * base)
        return np.ones((n, 3), np.float32), np.asarray(visual.uv, dtype=np.float32), texture
    if kind == "vertex" or kind == "face":
        rgb = np.asarray(visual.vertex_colors, dtype=np.float64)[:, :3] / 255.0
        return rgb_to_gbu(rgb if gltf else srgb_to_linear(rgb)), None, None
    return np.full((n, 3), DEFAULT_GREY, dtype=np.float32), None, None


def load_mesh_objects(path: str | Path) -> dict[str, SceneObject]:
    """Named objects of a mesh file. Raises FileNotFoundError or ValueError naming the file and the problem."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"mesh file not found: {path}")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise ValueError(f"unsupported mesh format {path.suffix!r} ({path}); allowed: {', '.join(MESH_SUFFIXES)}")
    import trimesh

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
    gltf = path.suffix.lower() in (".glb", ".gltf")
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
            t = np.asarray(transform, dtype=np.float64)
            if gltf:
                t = GLTF_TO_WORLD @ t
            local = np.asarray(geom.vertices, dtype=np.float64) @ t[:3, :3].T
            mesh = MeshData(local.astype(np.float32), np.asarray(geom.faces), colours, uv, texture)
            mesh.validate(name)
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from exc
        objects[name] = SceneObject(mesh, position=tuple(t[:3, 3]))
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
