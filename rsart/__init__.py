"""rsart: the dataset and benchmark toolkit for articulated-object reconstruction around RS-Art.

Start with :func:`rsart.load` (a dataset root or an object folder). Conventions: metres and
radians; world frame = the object's base frame; cameras OpenCV (x right, y down, z forward),
camera-to-world extrinsics; see docs/format.md.
"""
from .dataset import Dataset, RSArtObject, StateCapture, View, load
from .errors import Problem, RsartError, ValidationError

__version__ = "0.1.0"
__all__ = ["load", "Dataset", "RSArtObject", "StateCapture", "View", "RsartError", "ValidationError",
           "Problem", "__version__"]
