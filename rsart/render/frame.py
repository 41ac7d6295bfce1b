"""Render one view of a posed twin: RGB, depth and part mask, pixel-aligned.

Depth and mask come from ray casting (:mod:`.raycast`, exact); RGB from the rasteriser or the
ray-cast shader (:mod:`.raster`) sampling the same pixel centres of the same meshes. Which
meshes: ``geometry="visual"`` (default) casts and rasterises each part's render meshes (its
textured visuals, or its geometry when it has none), so all three images show one surface;
``geometry="mesh"`` uses the watertight part meshes for both.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from ..camera import REALSENSE_D435_COLOR_640x480, Camera, Intrinsics
from ..errors import RsartError
from ..kinematics import Twin
from .booth import BACKGROUNDS, BoothSpec, booth_meshes, random_background
from .raster import Lighting, PyrenderRgb, RaycastShader, resolve_backend, shared_renderer
from .raycast import SCENE_LABEL, RayHits, build_scene
from .sensor import ColourSensorModel, DepthSensorModel, realsense_colour, realsense_depth


@dataclass(frozen=True)
class RenderOptions:
    """What to render and how; every field is recorded in the object's ``render.json``.

    ``background``: "booth" (green booth + pedestal; depth sees the booth), "plain" (``plain_colour``),
    "transparent" (RGBA PNG, alpha = coverage) or "random" (a random image per view).
    ``sensor``: apply the RealSense-like depth/colour model; the clean images are then kept in
    ``rgb_clean/`` and ``depth_clean/`` as ground truth.
    ``reconcile`` (without ``antialias``): where the rasteriser and the ray caster disagree about a
    pixel's coverage -- 0-2 pixels per 640x480 view, where a pixel centre grazes an edge or corner --
    the RGB follows the ray cast (that pixel is ray-shaded or made background), so RGB, depth and mask
    agree everywhere; ``Frame.reconciled`` counts such pixels.
    """

    intrinsics: Intrinsics = REALSENSE_D435_COLOR_640x480
    background: str = "booth"
    plain_colour: tuple[int, int, int] = (255, 255, 255)
    sensor: bool = False
    antialias: bool = False
    geometry: str = "visual"
    rgb_backend: str = "auto"
    lighting: Lighting = Lighting()
    booth: BoothSpec = BoothSpec()
    depth_model: DepthSensorModel = DepthSensorModel()
    colour_model: ColourSensorModel = ColourSensorModel()
    depth_scale: float = 0.001
    reconcile: bool = True

    def __post_init__(self) -> None:
        if self.background not in BACKGROUNDS:
            raise RsartError(f"background {self.background!r} is not one of {list(BACKGROUNDS)}")
        if self.geometry not in ("visual", "mesh"):
            raise RsartError(f"geometry {self.geometry!r} is not 'visual' or 'mesh'")
        if self.rgb_backend not in ("auto", "pyrender", "raycast"):
            raise RsartError(f"rgb backend {self.rgb_backend!r} is not auto|pyrender|raycast")

    def to_dict(self) -> dict:
        d = asdict(self)
        d["intrinsics"] = self.intrinsics.to_dict()
        return d


@dataclass
class Frame:
    """One rendered view. ``rgb`` (H, W, 3) uint8 (or (H, W, 4) with a transparent background);
    ``depth`` (H, W) float32 z-depth in metres (0 = none); ``mask`` (H, W) uint8 part index + 1;
    ``rgb_clean``/``depth_clean``: the noise-free images when a sensor model was applied."""

    rgb: np.ndarray
    depth: np.ndarray
    mask: np.ndarray
    hits: RayHits | None = field(default=None, repr=False)
    rgb_clean: np.ndarray | None = None
    depth_clean: np.ndarray | None = None
    reconciled: int = 0


class StateRenderer:
    """Renders views of ``twin`` posed at ``values``; scenes are built once and reused for every view.

    ``object_bounds`` (2, 3) and ``camera_radius`` place the booth (pass the same values for every
    state of an object so its booth does not move). ``nthreads``: ray-casting threads (0 = all).
    ``rgb_renderer``: a GL renderer to use instead of the process-wide one (:func:`shared_renderer`).
    """

    def __init__(self, twin: Twin, values: dict[str, float], options: RenderOptions,
                 object_bounds: np.ndarray, camera_radius: float, nthreads: int = 0,
                 rgb_renderer: PyrenderRgb | None = None) -> None:
        self.options = options
        if options.geometry == "visual":
            parts = twin.posed_visuals(values)
        else:
            parts = [[m] for m in twin.posed_meshes(values)]
        scene = booth_meshes(object_bounds, camera_radius, options.booth) if options.background == "booth" else []
        self.scene = build_scene(parts, scene, nthreads=nthreads)
        self.backend = resolve_backend(options.rgb_backend)
        # booth pixels are shaded from the ray-cast hits (flat green, no textures): rasterising the
        # full-screen booth doubled the GL time under llvmpipe; the object alone is rasterised
        self._shader = RaycastShader(options.lighting)
        self._shader.set_scene(self.scene.meshes)
        size = float(np.linalg.norm(np.ptp(object_bounds, axis=0)))
        # a near plane well in front of the object keeps 24-bit GL depth precise to ~1e-6 of the distance
        znear, zfar = 0.05 * camera_radius, 10 * (size + 4 * camera_radius)
        if self.backend == "raycast":
            self._raster = None
        else:
            intr = options.intrinsics
            self._raster = rgb_renderer or shared_renderer(intr.width, intr.height, self.backend.split("-", 1)[1],
                                                           options.lighting, options.antialias)
            self._gl_scene = self._raster.make_scene([m for ms in parts for m in ms], znear, zfar)

    def render(self, c2w: np.ndarray, rng: np.random.Generator) -> Frame:
        """Render the view with camera-to-world ``c2w`` (4, 4, OpenCV); ``rng`` drives backgrounds/noise."""
        opt = self.options
        cam = Camera(opt.intrinsics, c2w)
        hits = self.scene.cast(cam)
        mask = hits.part_mask()
        depth = hits.depth
        obj = hits.label >= 0
        reconciled = 0
        if self._raster is not None:
            rgb, alpha = self._raster.render(cam, self._gl_scene)
            if alpha is None:
                alpha = obj.astype(np.float32)
            elif opt.reconcile and not opt.antialias:
                rgb, alpha, reconciled = self._reconcile(rgb, alpha, hits, obj)
        else:
            rgb, alpha = self._shader.shade(hits, obj)
        rgb = self._background(rgb, alpha, hits, rng)
        frame = Frame(rgb, depth, mask, hits, reconciled=reconciled)
        if opt.sensor:
            frame.rgb_clean, frame.depth_clean = rgb, depth
            colour = realsense_colour(rgb[..., :3], rng, opt.colour_model)
            frame.rgb = np.concatenate([colour, rgb[..., 3:]], axis=-1) if rgb.shape[-1] == 4 else colour
            frame.depth = realsense_depth(depth, opt.intrinsics.fx, hits.cos_incidence(), rgb[..., :3], rng,
                                          opt.depth_model)
        return frame

    def _reconcile(self, rgb: np.ndarray, alpha: np.ndarray, hits: RayHits,
                   obj: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """Make GL coverage equal the ray-cast object pixels (see ``RenderOptions.reconcile``)."""
        gl_obj = alpha > 0.5
        bad = gl_obj != obj
        n = int(bad.sum())
        if n:
            rgb, alpha = rgb.copy(), alpha.copy()
            shaded, _ = self._shader.shade(hits, bad & obj)
            rgb[bad] = shaded[bad]  # ray-shaded where only the ray caster hit, black (= no cover) elsewhere
            alpha[bad] = obj[bad]
        return rgb, alpha, n

    def _background(self, rgb: np.ndarray, alpha: np.ndarray, hits: RayHits, rng: np.random.Generator) -> np.ndarray:
        """Put the premultiplied object ``rgb`` (coverage ``alpha``) over the chosen background."""
        opt = self.options
        H, W = alpha.shape
        if opt.background == "transparent":
            a = alpha[..., None]
            straight = np.where(a > 0, rgb.astype(np.float32) / np.maximum(a, 1e-6), 0)
            out = np.concatenate([np.clip(np.round(straight), 0, 255),
                                  np.round(a * 255)], axis=-1)
            return out.astype(np.uint8)
        if opt.background == "random":
            bg = random_background(H, W, rng)
        elif opt.background == "plain":
            bg = np.broadcast_to(np.asarray(opt.plain_colour, dtype=np.uint8), (H, W, 3))
        else:  # booth: shaded booth hits; the open top of the curtain (never in view at 30-60°) curtain-coloured
            booth = hits.label == SCENE_LABEL
            bg, _ = self._shader.shade(hits, booth)
            bg[~booth] = opt.booth.curtain_colour
        if not opt.antialias:  # coverage is 0 or 1: a selection, no blending arithmetic
            return np.where(alpha[..., None] > 0.5, rgb, bg)
        out = rgb.astype(np.float32) + bg.astype(np.float32) * (1 - alpha[..., None])
        return np.clip(np.round(out), 0, 255).astype(np.uint8)

    @property
    def raster(self) -> PyrenderRgb | None:
        """The GL renderer (None with the ray-cast backend); shared by every state of this process."""
        return self._raster

    def close(self) -> None:
        """Release this state's scenes (the process-wide GL renderer stays for the next state)."""
        self.scene = None
        self._shader = None
        self._gl_scene = None

