"""PyTorch view dataset for training code (imported lazily: torch is needed only here)."""
from __future__ import annotations

import numpy as np

from .extras import require

require("torch", "rsart's torch datasets")  # one line naming `pip install 'rsart[torch]'`, not an ImportError
import torch  # noqa: E402
from torch.utils.data import Dataset as _TorchDataset


class ViewDataset(_TorchDataset):
    """Views as dicts of tensors; see :meth:`rsart.dataset.RSArtObject.torch_dataset` for keys, shapes and units."""

    def __init__(self, views, size: tuple[int, int] | None = None, with_depth: bool = True, with_mask: bool = True):
        self.views = views  # list of (state_index, state_id, View[, object_id, object_index])
        self.size = size
        self.with_depth = with_depth
        self.with_mask = with_mask

    def __len__(self) -> int:
        return len(self.views)

    def __getitem__(self, i: int) -> dict:
        import cv2

        k, sid, v, *obj = self.views[i]
        cam = v.camera
        rgb = v.rgb
        depth = v.depth if self.with_depth and v.has_depth else None
        mask = v.mask if self.with_mask and v.has_mask else None
        if self.size is not None and (cam.width, cam.height) != tuple(self.size):
            w, h = self.size
            rgb = cv2.resize(rgb, (w, h), interpolation=cv2.INTER_AREA)
            if depth is not None:
                depth = cv2.resize(depth, (w, h), interpolation=cv2.INTER_NEAREST)
            if mask is not None:
                mask = cv2.resize(mask, (w, h), interpolation=cv2.INTER_NEAREST)
            cam = cam.scaled(w, h)
        item = {"image": torch.from_numpy(rgb.astype(np.float32) / 255.0),
                "K": torch.from_numpy(cam.K.astype(np.float32)),
                "c2w": torch.from_numpy(cam.c2w.astype(np.float32)),
                "state_index": torch.tensor(k, dtype=torch.int64), "state_id": sid, "view_id": v.id}
        if obj:
            item["object_id"], item["object_index"] = obj[0], torch.tensor(obj[1], dtype=torch.int64)
        if depth is not None:
            item["depth"] = torch.from_numpy(depth.astype(np.float32))
        if mask is not None:
            item["mask"] = torch.from_numpy(mask.astype(np.int64))
        return item
