"""One textured mesh from several: how a part's visual meshes become one OBJ with one texture atlas.

Hand-written because ``trimesh.util.concatenate``'s packing (trimesh 5.2) loses colour: it drops each
material's diffuse factor and gives the packed material a 0.4 diffuse (a part of several meshes came out
darker than its source), it squeezes repeating UVs (PartNet-Mobility's metal and wood swatches repeat up to
~200 times over a part) into the wrong patch of the atlas, and it places the pixel of a colour-only
material outside the atlas. Here every mesh becomes a texture whose texels hold its final colours, with
UVs inside [0, 1]; the textures are stacked on shelves into one image, and the merged material is white.
"""
from __future__ import annotations

import numpy as np
import trimesh
from PIL import Image

MAX_TILED_SIDE = 1024  # px: a repeating texture is written out tiled up to this size, else as its mean colour
MAX_ATLAS_SIDE = 4096  # px: larger atlases are written with every texture scaled down alike
PAD = 2  # px of edge-replicated border around each texture in the atlas (no bleeding between neighbours)
WHITE = np.array([255, 255, 255, 255], dtype=np.uint8)


def material_factor(mat) -> np.ndarray:
    """(4,) RGBA colour factor of a trimesh material in [0, 1]: its PBR base colour factor or its diffuse
    (uint8 0-255, or floats in [0, 1]); white when it has neither."""
    f = getattr(mat, "baseColorFactor", None)
    if f is None:
        f = getattr(mat, "diffuse", None)
    if f is None:
        return np.ones(4)
    raw = np.asarray(f)
    vals = raw.astype(np.float64).reshape(-1)[:4]
    out = np.ones(4)  # a missing alpha is opaque
    out[:len(vals)] = vals / (255.0 if raw.dtype == np.uint8 or vals.max() > 1.0 else 1.0)
    return out


def material_image(visual):
    """The texture image (PIL) a texture-kind ``visual`` samples, or None: none without UVs (GL then draws
    the material's colour alone)."""
    mat = getattr(visual, "material", None)
    if mat is None or getattr(visual, "uv", None) is None:
        return None
    return getattr(mat, "image", None) or getattr(mat, "baseColorTexture", None)


def colour_texture(mesh: trimesh.Trimesh, face_rgba: np.ndarray) -> tuple[trimesh.Trimesh, np.ndarray, np.ndarray]:
    """Face colours as a texture -> (mesh with vertices unmerged, uv (3F, 2), image (1, n, 4) uint8 of the
    n distinct colours of ``face_rgba`` (F, 4) uint8), each face's UVs on its colour's texel."""
    colours, idx = np.unique(np.asarray(face_rgba, dtype=np.uint8), axis=0, return_inverse=True)
    flat = trimesh.Trimesh(mesh.vertices[mesh.faces].reshape(-1, 3), np.arange(3 * len(mesh.faces)).reshape(-1, 3),
                           process=False)
    u = (np.repeat(idx.reshape(-1), 3) + 0.5) / len(colours)
    return flat, np.stack([u, np.full_like(u, 0.5)], axis=1), colours[None]


def as_texture(mesh: trimesh.Trimesh, max_side: int = MAX_TILED_SIDE) -> tuple[trimesh.Trimesh, np.ndarray, np.ndarray]:
    """One mesh's appearance as (mesh, uv (V, 2) inside [0, 1], RGBA image (H, W, 4) uint8 of final colours).

    A texture is multiplied by its material's factor. Repeating UVs are shifted by whole tiles to start in
    the first one and the image is repeated as many times as they span (the same render); where that
    image would be larger than ``max_side`` px on a side the mesh gets the texture's mean colour: what a
    mip-mapped renderer shows where a tile covers a pixel or less. A texture-kind mesh without UVs or
    image takes its material's colour (as GL renders it); vertex colours are averaged per face.
    """
    vis = mesh.visual
    kind = getattr(vis, "kind", None)
    if kind == "face":
        return colour_texture(mesh, vis.face_colors)
    if kind == "vertex":
        vc = np.asarray(vis.vertex_colors, dtype=np.float64)
        return colour_texture(mesh, np.round(vc[mesh.faces].mean(axis=1)).astype(np.uint8))
    if kind != "texture":  # no colour at all: trimesh's default grey
        return colour_texture(mesh, np.tile(np.array([102, 102, 102, 255], np.uint8), (len(mesh.faces), 1)))
    f = material_factor(vis.material)
    img, uv = material_image(vis), getattr(vis, "uv", None)
    if img is None or len(uv) != len(mesh.vertices):
        return colour_texture(mesh, np.tile(np.round(f * 255).astype(np.uint8), (len(mesh.faces), 1)))
    rgba = np.asarray(img.convert("RGBA"), dtype=np.float64) * f
    uv = np.asarray(uv, dtype=np.float64)
    lo = np.floor(uv.min(axis=0)) if (uv.min() < 0.0 or uv.max() > 1.0) else np.zeros(2)
    reps = np.maximum(1, np.ceil(uv.max(axis=0) - lo)).astype(int)  # (u, v) tiles spanned
    h, w = rgba.shape[:2]
    if reps[0] * w > max_side or reps[1] * h > max_side:
        mean = np.round(rgba.reshape(-1, 4).mean(axis=0)).astype(np.uint8)
        return colour_texture(mesh, np.tile(mean, (len(mesh.faces), 1)))
    tiled = np.tile(np.round(rgba).astype(np.uint8), (reps[1], reps[0], 1))  # every tile alike: no flip needed
    return mesh, (uv - lo) / reps, tiled


def _pack(sizes: list[tuple[int, int]]) -> tuple[dict[int, tuple[int, int]], int, int]:
    """Shelf packing of (h, w) boxes, tallest first -> ({index: (row, col)}, atlas height, width)."""
    width = max(max(w for _, w in sizes), int(np.ceil(np.sqrt(sum(h * w for h, w in sizes)))))
    place, x, y, row_h = {}, 0, 0, 0
    for i in sorted(range(len(sizes)), key=lambda i: -sizes[i][0]):
        h, w = sizes[i]
        if x + w > width:
            x, y, row_h = 0, y + row_h, 0
        place[i] = (y, x)
        x, row_h = x + w, max(row_h, h)
    return place, y + row_h, width


def merge_visuals(meshes: list[trimesh.Trimesh], max_side: int = MAX_ATLAS_SIDE) -> trimesh.Trimesh:
    """Several visual meshes -> one mesh with one texture atlas (white material), the same colours.
    Identical textures share one place in the atlas; an atlas over ``max_side`` px on a side is made by
    scaling every texture down by the same factor (UVs are relative to each texture, so they still hold)."""
    parts = [as_texture(m) for m in meshes]
    slots: dict[tuple, int] = {}  # (h, w, hash of the texels) -> index in images
    images: list[np.ndarray] = []
    slot_of = []
    for _, _, img in parts:
        key = img.shape[:2] + (hash(img.tobytes()),)
        if key not in slots:
            slots[key] = len(images)
            images.append(img)
        slot_of.append(slots[key])
    scale = 1.0
    while True:
        tiles = [img if scale == 1.0 else np.asarray(Image.fromarray(img).resize(
            (max(1, round(img.shape[1] * scale)), max(1, round(img.shape[0] * scale))), Image.Resampling.BOX))
                 for img in images]
        place, height, width = _pack([(t.shape[0] + 2 * PAD, t.shape[1] + 2 * PAD) for t in tiles])
        if max(height, width) <= max_side or scale < 1e-3:
            break
        scale *= 0.9 * max_side / max(height, width)
    atlas = np.zeros((height, width, 4), np.uint8)
    for k, t in enumerate(tiles):
        y0, x0 = place[k]
        atlas[y0:y0 + t.shape[0] + 2 * PAD, x0:x0 + t.shape[1] + 2 * PAD] = np.pad(t, ((PAD, PAD), (PAD, PAD), (0, 0)),
                                                                                 mode="edge")
    uvs = []
    for (_, uv, _), k in zip(parts, slot_of):
        y0, x0 = place[k]
        h, w = tiles[k].shape[:2]
        # texel (row from the top r, column c) of the tile sits at atlas row y0 + PAD + r; UV v = 0 is the bottom
        u = (x0 + PAD + np.clip(uv[:, 0], 0, 1) * w) / width
        v = 1.0 - (y0 + PAD + (1.0 - np.clip(uv[:, 1], 0, 1)) * h) / height
        uvs.append(np.stack([u, v], axis=1))
    merged = trimesh.util.concatenate([trimesh.Trimesh(m.vertices, m.faces, process=False) for m, _, _ in parts])
    merged.visual = trimesh.visual.TextureVisuals(
        uv=np.concatenate(uvs), material=trimesh.visual.material.SimpleMaterial(image=Image.fromarray(atlas),
                                                                                diffuse=WHITE))
    return merged
