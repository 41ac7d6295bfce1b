"""RGB images of a posed twin: pyrender (EGL or OSMesa) when GL works, else open3d ray-cast shading.

Pixel convention: both backends sample the scene at pixel centres of the OpenCV camera
(:mod:`rsart.camera`: u = 0 is the centre of the first pixel). OpenGL puts pixel centres at
window coordinates i + 0.5, so the pyrender camera gets cx + 0.5, cy + 0.5. With
``antialias=False`` (default) the rasteriser takes one sample per pixel centre, so the RGB
silhouette equals the ray-cast mask pixel for pixel; ``antialias=True`` keeps pyrender's 4x
MSAA (realistic blended edges, silhouette within one pixel of the mask).

Backend choice (:func:`gl_platform`): ``$PYOPENGL_PLATFORM`` if set and working, else EGL,
else OSMesa, each probed once in a subprocess (the result is cached in ``$RSART_GL_PLATFORM``
so worker processes inherit it); with no working GL, :class:`RaycastShader` shades the
ray-cast hits (face normals + texture/vertex/face colours through barycentrics).
"""
from __future__ import annotations

import atexit
import os
import subprocess
import sys
from dataclasses import dataclass

import numpy as np
import trimesh

from ..atlas import material_factor, material_image
from ..camera import Camera
from .raycast import RayHits

GL_PLATFORMS = ("egl", "osmesa")
_PROBE = ("import pyrender; r = pyrender.OffscreenRenderer(8, 8); import trimesh; "
          "s = pyrender.Scene(); s.add(pyrender.Mesh.from_trimesh(trimesh.creation.box())); "
          "s.add(pyrender.IntrinsicsCamera(8, 8, 4, 4), pose=__import__('numpy').eye(4)); r.render(s); r.delete()")


@dataclass(frozen=True)
class Lighting:
    """Uniform ambient light (booth) plus a weak light at the camera (hand-held capture), both white."""

    ambient: float = 0.3
    headlight: float = 1.8


def _probe(platform: str) -> bool:
    env = dict(os.environ, PYOPENGL_PLATFORM=platform, MUJOCO_GL=platform)
    try:
        r = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return r.returncode == 0


def gl_platform() -> str | None:
    """The working headless GL platform ("egl" | "osmesa"), or None when no GL works here (cached)."""
    cached = os.environ.get("RSART_GL_PLATFORM")
    if cached is not None:
        return cached or None
    order = list(GL_PLATFORMS)
    pre = os.environ.get("PYOPENGL_PLATFORM")
    if pre in order:
        order.remove(pre)
        order.insert(0, pre)
    found = next((p for p in order if _probe(p)), None)
    os.environ["RSART_GL_PLATFORM"] = found or ""
    return found


def resolve_backend(backend: str = "auto") -> str:
    """"pyrender-egl" | "pyrender-osmesa" | "raycast" for a requested backend "auto" | "pyrender" | "raycast"."""
    if backend == "raycast":
        return "raycast"
    plat = gl_platform()
    if plat is None:
        if backend == "pyrender":
            from ..errors import RsartError
            raise RsartError("no headless OpenGL (EGL or OSMesa) works here; use --rgb-backend raycast")
        return "raycast"
    return f"pyrender-{plat}"


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] -> linear light (IEC 61966-2-1)."""
    x = np.asarray(x, dtype=np.float64)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """Linear light in [0, 1] -> sRGB-encoded values."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0, 1)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def _linear_colours(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """A copy of a face/vertex-coloured mesh with colours in linear light: pyrender shades vertex colours
    as linear values (textures it decodes from sRGB itself), then encodes its output as sRGB."""
    kind = getattr(mesh.visual, "kind", None)
    if kind not in ("face", "vertex"):
        return mesh
    out = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    if kind == "face":
        c = np.asarray(mesh.visual.face_colors, dtype=np.float64) / 255.0
        c[:, :3] = srgb_to_linear(c[:, :3])
        out.visual.face_colors = np.round(c * 255).astype(np.uint8)
    else:
        c = np.asarray(mesh.visual.vertex_colors, dtype=np.float64) / 255.0
        c[:, :3] = srgb_to_linear(c[:, :3])
        out.visual.vertex_colors = np.round(c * 255).astype(np.uint8)
    return out


# ----------------------------------------------------------------------------- pyrender
def _disable_msaa(pyrender_renderer_module) -> None:
    """Make pyrender sample once per pixel centre: it enables GL_MULTISAMPLE on every pass and allocates
    4-sample buffers, with no option against either, so its module-level ``glEnable`` (for that one
    capability) and ``glRenderbufferStorageMultisample`` (sample count) are wrapped. The flag
    ``_rsart_antialias`` on the module switches them (set per renderer before it allocates/renders)."""
    from OpenGL import GL

    mod = pyrender_renderer_module
    if getattr(mod, "_rsart_msaa_wrapped", False):
        return
    original = mod.glEnable

    def gl_enable(cap):
        if cap == GL.GL_MULTISAMPLE and not getattr(mod, "_rsart_antialias", True):
            GL.glDisable(GL.GL_MULTISAMPLE)
            return None
        return original(cap)

    storage = mod.glRenderbufferStorageMultisample

    def gl_storage(target, samples, fmt, width, height):
        # without antialiasing, single-sample buffers: llvmpipe then shades and resolves 4x fewer samples
        return storage(target, samples if getattr(mod, "_rsart_antialias", True) else 0, fmt, width, height)

    mod.glEnable = gl_enable
    mod.glRenderbufferStorageMultisample = gl_storage
    mod._rsart_msaa_wrapped = True


def _ordered_node(pr, seq: int, mesh):
    """A pyrender mesh node whose hash is ``seq``. pyrender keeps nodes in sets and draws them sorted by
    the distance of their (here all identity) poses, so with default id-based hashes the draw order -- and
    which of two coincident surfaces wins the depth test -- changed from run to run. Small-int hashes make
    the order the insertion order, so renders are reproducible byte for byte."""

    class OrderedNode(pr.Node):
        def __hash__(self) -> int:
            return seq

        def __eq__(self, other) -> bool:
            return self is other

    return OrderedNode(mesh=mesh, matrix=np.eye(4))


@dataclass
class GLScene:
    """A pyrender scene with its camera and headlight nodes (moved to each view's pose)."""

    scene: object
    cam: object
    cam_node: object
    light_node: object


class PyrenderRgb:
    """Rasterised RGB of a static mesh set with pyrender; one OpenGL context per instance."""

    def __init__(self, width: int, height: int, platform: str, lighting: Lighting = Lighting(),
                 antialias: bool = False) -> None:
        if "OpenGL" not in sys.modules:  # PyOpenGL fixes its platform at first import
            os.environ["PYOPENGL_PLATFORM"] = platform
        os.environ.setdefault("MUJOCO_GL", platform)
        import pyrender
        import pyrender.renderer

        _disable_msaa(pyrender.renderer)
        pyrender.renderer._rsart_antialias = antialias
        self._pr = pyrender
        self._module = pyrender.renderer
        self.name = f"pyrender-{os.environ['PYOPENGL_PLATFORM']}"
        self.width, self.height = width, height
        self.lighting = lighting
        self.antialias = antialias
        self._renderer = pyrender.OffscreenRenderer(width, height)

    def make_scene(self, meshes: list[trimesh.Trimesh], znear: float, zfar: float) -> "GLScene":
        """A scene of world-frame meshes (with their colours/textures), drawn in list order, clipped at
        ``znear``/``zfar``. Scenes are uploaded to GL when first rendered; rendering another scene
        releases the previous one's buffers (pyrender keeps one scene's meshes in the context)."""
        pr = self._pr
        a = self.lighting.ambient
        scene = pr.Scene(bg_color=[0.0, 0.0, 0.0, 0.0], ambient_light=[a, a, a])
        for i, m in enumerate(meshes):
            scene.add_node(_ordered_node(pr, i, pr.Mesh.from_trimesh(_linear_colours(m), smooth=False)))
        cam = pr.IntrinsicsCamera(1, 1, 0, 0, znear=znear, zfar=zfar)
        cam_node = scene.add(cam, pose=np.eye(4))
        light_node = scene.add(pr.DirectionalLight(color=np.ones(3), intensity=self.lighting.headlight),
                               pose=np.eye(4))
        return GLScene(scene, cam, cam_node, light_node)

    def render(self, camera: Camera, scene: "GLScene") -> tuple[np.ndarray, np.ndarray | None]:
        """(H, W, 3) uint8 RGB premultiplied over black and (H, W) float32 coverage in [0, 1]
        (None when the platform cannot read alpha back; the caller then uses the ray-cast coverage)."""
        intr = camera.intrinsics
        if (intr.width, intr.height) != (self.width, self.height):
            raise ValueError(f"renderer is {self.width}x{self.height}, camera is {intr.width}x{intr.height}")
        scene.cam.fx, scene.cam.fy = intr.fx, intr.fy
        scene.cam.cx, scene.cam.cy = intr.cx + 0.5, intr.cy + 0.5  # OpenGL pixel centres are at i + 0.5
        pose = camera.c2w_opengl()
        scene.scene.set_pose(scene.cam_node, pose)
        scene.scene.set_pose(scene.light_node, pose)
        self._module._rsart_antialias = self.antialias
        flags = self._pr.RenderFlags.RGBA | self._pr.RenderFlags.SKIP_CULL_FACES
        colour, _ = self._renderer.render(scene.scene, flags=flags)
        if colour.shape[-1] < 4:  # pyrender's OSMesa path reads back RGB only: no coverage available
            return np.ascontiguousarray(colour[..., :3]), None
        return np.ascontiguousarray(colour[..., :3]), colour[..., 3].astype(np.float32) / 255.0

    def close(self) -> None:
        self._renderer.delete()


_SHARED: dict[tuple[int, int, bool], PyrenderRgb] = {}


def shared_renderer(width: int, height: int, platform: str, lighting: Lighting = Lighting(),
                    antialias: bool = False) -> PyrenderRgb:
    """The process-wide renderer for this image size and antialiasing (created once, never deleted).

    pyrender's EGL platform terminates the process's shared EGL display when any renderer is deleted,
    which breaks every other live renderer; keeping one renderer per configuration avoids that.
    """
    key = (width, height, antialias)
    r = _SHARED.get(key)
    if r is None:
        if not _SHARED:
            atexit.register(_close_shared)
        r = _SHARED[key] = PyrenderRgb(width, height, platform, lighting, antialias)
    r.lighting = lighting
    return r


def _close_shared() -> None:
    """Delete the shared renderers before interpreter shutdown (pyrender's finalisers fail noisily after)."""
    while _SHARED:
        _, r = _SHARED.popitem()
        try:
            r.close()
        except Exception:  # the GL display may already be gone; nothing left to release
            pass


# ----------------------------------------------------------------------------- ray-cast shading
@dataclass
class Albedo:
    """Base colour of one mesh in [0, 1]: per-face, per-vertex, or a texture through per-vertex UVs."""

    faces: np.ndarray
    face_colour: np.ndarray | None = None
    vertex_colour: np.ndarray | None = None
    uv: np.ndarray | None = None
    texture: np.ndarray | None = None
    factor: np.ndarray | None = None

    @staticmethod
    def of(mesh: trimesh.Trimesh) -> "Albedo":
        vis = mesh.visual
        faces = np.asarray(mesh.faces)
        if getattr(vis, "kind", None) == "texture":  # without UVs only the material's colour applies (as in GL)
            img, f = material_image(vis), material_factor(vis.material)[:3]
            if img is not None:
                tex = np.asarray(img.convert("RGB"), dtype=np.uint8)
                return Albedo(faces, uv=np.asarray(vis.uv, dtype=np.float64), texture=tex, factor=f)
            return Albedo(faces, face_colour=np.tile(f, (len(faces), 1)))
        if getattr(vis, "kind", None) == "vertex":
            return Albedo(faces, vertex_colour=np.asarray(vis.vertex_colors)[:, :3] / 255.0)
        if getattr(vis, "kind", None) == "face":
            return Albedo(faces, face_colour=np.asarray(vis.face_colors)[:, :3] / 255.0)
        return Albedo(faces, face_colour=np.full((len(faces), 3), 0.7))

    def sample(self, prim: np.ndarray, bary: np.ndarray) -> np.ndarray:
        """(N, 3) colours at hits on triangles ``prim`` (N,) with open3d barycentrics ``bary`` (N, 2)."""
        if self.face_colour is not None:
            return self.face_colour[prim]
        w = np.stack([1 - bary[:, 0] - bary[:, 1], bary[:, 0], bary[:, 1]], axis=1)[..., None]
        tri = self.faces[prim]
        if self.vertex_colour is not None:
            return np.sum(self.vertex_colour[tri] * w, axis=1)
        uv = np.sum(self.uv[tri] * w, axis=1) % 1.0
        h, wd = self.texture.shape[:2]
        col = np.clip(np.round(uv[:, 0] * wd - 0.5), 0, wd - 1).astype(int)
        row = np.clip(np.round((1 - uv[:, 1]) * h - 0.5), 0, h - 1).astype(int)  # UV v=0 is the image bottom
        return self.texture[row, col] / 255.0 * self.factor


class RaycastShader:
    """RGB without GL: Lambert shading (ambient + headlight) of ray-cast hits; meshes in scene geometry order."""

    name = "raycast"

    def __init__(self, lighting: Lighting = Lighting()) -> None:
        self.lighting = lighting
        self._albedo: list[Albedo] = []

    def set_scene(self, meshes: list[trimesh.Trimesh]) -> None:
        """``meshes`` in the same order as the geometries of the :class:`RaycastScene` whose hits are shaded."""
        self._albedo = [Albedo.of(m) for m in meshes]
        # face-coloured geometries: every face gets an index into a palette of distinct colours, found
        # at offset[geometry] + triangle; shaded colours come from a (palette, 256 cos levels) table
        self._flat = np.array([a.face_colour is not None for a in self._albedo] + [False], dtype=bool)
        tables = [np.round(a.face_colour * 255).astype(np.uint8) if a.face_colour is not None
                  else np.zeros((0, 3), np.uint8) for a in self._albedo]
        self._offset = np.concatenate([[0], np.cumsum([len(t) for t in tables])]).astype(np.int64)
        allc = np.concatenate(tables + [np.zeros((1, 3), np.uint8)], axis=0)
        self._palette, self._colour_id = np.unique(allc, axis=0, return_inverse=True)
        self._colour_id = self._colour_id.reshape(-1).astype(np.int32)
        levels = np.arange(256, dtype=np.float32) / 255.0
        self._shaded = self._shade_linear(self._palette[:, None, :], levels[None, :]).reshape(-1, 3)

    def _shade_linear(self, srgb: np.ndarray, cos: np.ndarray) -> np.ndarray:
        """uint8 sRGB of uint8 sRGB base colours lit at incidence cosines ``cos`` (broadcast (..., 3) / (...))."""
        # in linear light like pyrender (diffuse BRDF albedo/pi times the light intensity), sRGB output
        lam = (self.lighting.ambient + self.lighting.headlight / np.pi * cos).astype(np.float32)
        lin = _SRGB_TO_LINEAR[srgb] * lam[..., None]
        return _LINEAR_TO_SRGB[np.minimum((lin * (_LUT_N - 1) + 0.5).astype(np.int32), _LUT_N - 1)]

    def shade(self, hits: RayHits, select: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(H, W, 3) uint8 RGB premultiplied over black and (H, W) float32 coverage (0 or 1).

        ``select`` (H, W) bool limits shading to those pixels (others count as not hit).
        Works on the hit pixels only, with look-up tables (this runs for every frame); face-coloured
        surfaces use incidence cosines quantised to 1/255 (at most one sRGB code value of difference).
        """
        H, W = hits.depth.shape
        hit = hits.hit if select is None else hits.hit & select
        idx = np.flatnonzero(hit)
        g = hits.geometry.reshape(-1)[idx]
        p = hits.primitive.reshape(-1)[idx]
        cos = hits.cos_incidence().reshape(-1)[idx]
        flat = self._flat[g]
        out = np.zeros((H * W, 3), dtype=np.uint8)
        if flat.all():
            cid = self._colour_id[self._offset[g] + p]
            out[idx] = self._shaded[cid * 256 + (cos * 255 + 0.5).astype(np.int32)]
        else:
            base = np.empty((len(idx), 3), dtype=np.uint8)
            fl = np.flatnonzero(flat)
            base[fl] = self._palette[self._colour_id[self._offset[g[fl]] + p[fl]]]
            rest = np.flatnonzero(~flat)
            b = hits.bary.reshape(-1, 2)[idx[rest]]
            gr, pr = g[rest], p[rest]
            for gi in np.unique(gr):
                sel = gr == gi
                col = self._albedo[gi].sample(pr[sel], b[sel])
                base[rest[sel]] = np.clip(np.round(col * 255), 0, 255).astype(np.uint8)
            out[idx] = self._shade_linear(base, cos)
        return out.reshape(H, W, 3), hit.astype(np.float32)


_LUT_N = 4096
_SRGB_TO_LINEAR = srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)
_LINEAR_TO_SRGB = np.round(linear_to_srgb(np.arange(_LUT_N) / (_LUT_N - 1)) * 255).astype(np.uint8)
