"""The capture simulator: RS-Art-style RGB-D captures of any twin (docs/render.md).

Modules: :mod:`.raycast` (exact depth + masks), :mod:`.raster` (RGB), :mod:`.booth` (surroundings),
:mod:`.paths` (camera paths), :mod:`.sensor` (RealSense-like noise), :mod:`.frame` (one view),
:mod:`.protocols` (which states and views), :mod:`.runner` (object folders, workers, resume),
:mod:`.contact_sheet` (pictures).
"""
