"""Crease patterns to and from mesh files (trimesh: PLY, OBJ, GLB, STL, ...), creases drawn as coloured ribbons."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from warpworm.ids import MOUNTAIN, VALLEY
from warpworm.physics.crease.pattern import CreasePattern

# Crease colours as in the paper's Fig. 3 (RGBA uint8).
VALLEY_RGBA = np.array([220, 30, 30, 255], dtype=np.uint8)
MOUNTAIN_RGBA = np.array([30, 60, 220, 255], dtype=np.uint8)
SHEET_RGBA = np.array([235, 235, 225, 255], dtype=np.uint8)


def load_pattern(path, labels=None, **kwargs) -> CreasePattern:
    """Load a triangle mesh (PLY, OBJ, GLB, STL, ...) with trimesh, unprocessed, and make a crease pattern of it.

    ``labels`` as in :meth:`CreasePattern.from_trimesh` (None infers mountain / valley / flat from the geometry);
    ``kwargs`` go to it too. A GLB written by :func:`export_mesh` is read back from its ``surface`` node.
    """
    import trimesh  # start-up time: trimesh loads on first use

    loaded = trimesh.load(str(path), process=False)
    if isinstance(loaded, trimesh.Scene):
        geoms = loaded.geometry
        meshes = [name for name, g in geoms.items() if isinstance(g, trimesh.Trimesh)]
        if "surface" in geoms:
            name = "surface"
        elif len(meshes) == 1:
            name = meshes[0]
        else:
            raise ValueError(f"load_pattern: {path} holds {len(meshes)} meshes and none is named 'surface'")
        mesh = geoms[name].copy()
        # A glTF node may carry a transform: take the mesh in scene coordinates.
        nodes = loaded.graph.geometry_nodes.get(name, [])
        if nodes:
            mesh.apply_transform(loaded.graph[nodes[0]][0])
    else:
        mesh = loaded
    return CreasePattern.from_trimesh(mesh, labels, **kwargs)


def _crease_ribbons(x: np.ndarray, pattern: CreasePattern, mask: np.ndarray, width: float):
    """Thin triangular prisms along the masked hinges' creases, lifted slightly off the surface so a viewer shows
    them above the facets: (vertices (6C, 3), faces (8C, 3))."""
    h = pattern.hinges[mask]
    xi, xj, xk, xl = (x[h[:, c]] for c in range(4))
    e = xk - xj
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    n1 = np.cross(xj - xi, xk - xi)
    n2 = np.cross(xk - xl, xj - xl)
    nrm = n1 / np.linalg.norm(n1, axis=1, keepdims=True) + n2 / np.linalg.norm(n2, axis=1, keepdims=True)
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
    side = np.cross(e, nrm)
    off = [0.5 * width * nrm + 0.5 * width * side, 0.5 * width * nrm - 0.5 * width * side, 1.5 * width * nrm]
    v = np.concatenate([np.stack([xj + o for o in off], 1), np.stack([xk + o for o in off], 1)], axis=1)  # (C, 6, 3)
    base = 6 * np.arange(len(h))[:, None, None]
    f = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [2, 0, 3], [2, 3, 5], [0, 2, 1], [3, 4, 5]])
    return v.reshape(-1, 3), (base + f[None]).reshape(-1, 3)


def export_mesh(pattern: CreasePattern, path, positions: np.ndarray | None = None, *, creases: bool = True,
                crease_width: float | None = None) -> Path:
    """Write the pattern (at rest or at ``positions`` (V, 3)) with trimesh; the format follows the suffix.

    GLB / glTF: a scene with the node ``surface`` (the facets, paper-white; :func:`load_pattern` reads it back) and,
    with ``creases``, nodes ``valley`` (red) and ``mountain`` (blue): thin prisms along those creases, as in the
    paper's Fig. 3. Other formats (PLY, OBJ, ...) get one mesh: the surface first (its V vertices and T faces keep
    their order), then the crease prisms, with face colours; pass ``creases=False`` for a bare surface.
    ``crease_width`` [m] defaults to 0.4 % of the surface's bounding-box diagonal.
    """
    import trimesh  # start-up time: trimesh loads on first use

    path = Path(path)
    x = pattern.vertices if positions is None else np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    surface = trimesh.Trimesh(vertices=x, faces=pattern.triangles, process=False)
    surface.visual.face_colors = np.broadcast_to(SHEET_RGBA, (len(pattern.triangles), 4))
    if crease_width is None:
        crease_width = 0.004 * float(np.linalg.norm(np.ptp(x, axis=0)))
    parts = []
    if creases:
        for name, lab, rgba in (("valley", VALLEY, VALLEY_RGBA), ("mountain", MOUNTAIN, MOUNTAIN_RGBA)):
            mask = pattern.hinge_label == lab
            if not np.any(mask):
                continue
            v, f = _crease_ribbons(x, pattern, mask, crease_width)
            m = trimesh.Trimesh(vertices=v, faces=f, process=False)
            m.visual.face_colors = np.broadcast_to(rgba, (len(f), 4))
            parts.append((name, m))
    suffix = path.suffix.lower()
    path.parent.mkdir(parents=True, exist_ok=True)
    if suffix in (".glb", ".gltf"):
        scene = trimesh.Scene()
        scene.add_geometry(surface, geom_name="surface", node_name="surface")
        for name, m in parts:
            scene.add_geometry(m, geom_name=name, node_name=name)
        scene.export(str(path))
    else:
        mesh = trimesh.util.concatenate([surface] + [m for _, m in parts]) if parts else surface
        mesh.export(str(path))
    return path
