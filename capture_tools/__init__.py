"""capture_tools: real RS-Art captures -> RS-Art object folders (docs/capture.md).

Modules: :mod:`.readers` (frame folders, colour video + depth) and :mod:`.bag` (RealSense .bag via rosbags),
:mod:`.recording` (``open_recording``: the reader for a path),
:mod:`.align` (depth to colour), :mod:`.chroma` (green-booth key), :mod:`.select` (frame selection),
:mod:`.sfm` (pycolmap SfM, metric scale), :mod:`.rgbd_ba` (RGB-D bundle adjustment), :mod:`.depth_align`
(depth ICP per view), :mod:`.board` (ChArUco), :mod:`.register` (pedestal plane, twin registration),
:mod:`.pipeline` (one state), :mod:`.joint` (one SfM over all states, tied by the static base),
:mod:`.assemble` (the object folder), :mod:`.raw_writer` (simulated raw captures), :mod:`.object_poses`
(SfM poses for ``rsart perturb --poses colmap``), :mod:`.pose_eval`,
:mod:`.cli` (``rsart capture``, entry point ``rsart.commands``). Depends on rsart, never the reverse.
"""
